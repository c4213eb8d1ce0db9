#!/usr/bin/env bash
# gains.sh — a camera whose LED gains differ from a model's system (a calibrated system) is read
# by the model without retraining: `eval --system` and `infer --system` rescale each tile phase
# to the model's gains and say so in one line. On the bundled demo model and the CAVE scene
# balloons_crop100, gains perturbed by up to +-30 %: noise-free eval scores equal the model's
# own system's (0.01 dB); given as they are (--no-gain-remap) they lose over 1 dB; infer on
# frames simulated with the perturbed gains scores as on the bundled system's frames (0.1 dB),
# and over 1 dB lower without --system.
# Refused (one line, exit 2, nothing written): another tile map, another LED emission.
# usage: gains.sh LUMOSAIC MAKE_CUBE CUBE_PSNR
source "$(dirname "$0")/lib.sh"
PSNR=$3
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
MODEL=$ROOT/models/demo/rt16nc-lmmse.safetensors
# a copy of the bundled system (absolute CSV paths) with edits: gains x (1 + u), u in +-0.3
python3 - "$ROOT/data/systems/default.json" "$T" <<'PY'
import json, os, random, sys
src, T = sys.argv[1], sys.argv[2]
d = os.path.dirname(os.path.abspath(src))
def base():
    s = json.load(open(src))
    for l in s["leds"]:
        l["emission"]["csv"] = os.path.normpath(os.path.join(d, l["emission"]["csv"]))
    s["sensor"]["qe"]["csv"] = os.path.normpath(os.path.join(d, s["sensor"]["qe"]["csv"]))
    return s
random.seed(3)
u = [random.uniform(-0.3, 0.3) for _ in range(12)]
json.dump(base(), open(T + "/same.json", "w"))
s = base()
s["tile_map"][0][0], s["tile_map"][0][1] = s["tile_map"][0][1], s["tile_map"][0][0]
json.dump(s, open(T + "/swapped.json", "w"))
s = base()
s["leds"][4]["emission"]["column"] = "Blue"
json.dump(s, open(T + "/emission.json", "w"))
open(T + "/u.txt", "w").write(" ".join(str(x) for x in u))
PY
check "systems written" [ -s "$T/same.json" -a -s "$T/u.txt" ]
# the equal-white gains, resolved by the loader, times (1 + u)
"$LM" info --system "$ROOT/data/systems/default.json" > "$T/info"
python3 - "$T" <<'PY'
import json, sys
T = sys.argv[1]
s = json.load(open(T + "/same.json"))
names = [l["name"] for l in s["leds"]]
gain = {f[0]: float(f[6]) for f in (l.split() for l in open(T + "/info")) if len(f) == 7 and f[0] in names}
u = [float(x) for x in open(T + "/u.txt").read().split()]
s["gains"] = [gain[n] * (1 + x) for n, x in zip(names, u)]
json.dump(s, open(T + "/perturbed.json", "w"))
PY
check "perturbed system written" [ -s "$T/perturbed.json" ]

score() { "$LM" eval --model "$MODEL" "$CAVE" --split all --noise 0 --rainbow 0 --threads 2 "$@" \
  2> "$T/eval.err" | awk '$1 == "0" { print $2 }'; }
ref=$(score)
remapped=$(score --system "$T/perturbed.json")
check "eval --system perturbed says it rescales: $(cat "$T/eval.err")" \
  grep -q "^gains: .*perturbed.json has other LED gains than the model's system .*rescaled" "$T/eval.err"
plain=$(score --system "$T/perturbed.json" --no-gain-remap)
check "--no-gain-remap says so" grep -q "not applied (--no-gain-remap)" "$T/eval.err"
echo "eval PSNR: model's system $ref dB, perturbed gains rescaled $remapped dB, as they are $plain dB"
check "rescaled = the model's system ($remapped vs $ref dB)" \
  awk -v a="$remapped" -v b="$ref" 'BEGIN { d = a - b; exit !(a != "" && d < 0.01 && d > -0.01) }'
check "as they are: over 1 dB lost ($plain vs $ref dB)" \
  awk -v a="$plain" -v b="$ref" 'BEGIN { exit !(a != "" && a < b - 1) }'
same=$(score --system "$T/same.json")
check "the same system in another file: no remap line" bash -c "! grep -q '^gains:' '$T/eval.err'"
check "the same system in another file scores the same ($same dB)" [ "$same" = "$ref" ]

# infer: frames simulated with the perturbed gains, reconstructed with --system
"$LM" simulate --input "$CAVE" --output "$T/s0" --crop > /dev/null 2>&1
"$LM" simulate --input "$CAVE" --system "$T/perturbed.json" --output "$T/s1" --crop > /dev/null 2>&1
check "simulated" [ -s "$T/s0/frames/frame_0000.png" -a -s "$T/s1/frames/frame_0000.png" ]
"$LM" infer --model "$MODEL" --input "$T/s0/frames" --output "$T/i0" --threads 2 2> /dev/null
"$LM" infer --model "$MODEL" --input "$T/s1/frames" --system "$T/perturbed.json" \
  --output "$T/i1" --threads 2 2> "$T/err"
check "infer --system perturbed: $(cat "$T/err")" [ -s "$T/i1/cube_0000.exr" ]
check "infer says it rescales" grep -q "^gains: .*rescaled to the model's gains" "$T/err"
"$LM" infer --model "$MODEL" --input "$T/s1/frames" --output "$T/i2" --threads 2 2> /dev/null
p0=$("$PSNR" "$T/i0/cube_0000.exr" "$T/s0/gt/gt_0000.exr")
p1=$("$PSNR" "$T/i1/cube_0000.exr" "$T/s1/gt/gt_0000.exr")
echo "infer PSNR: model's system $p0 dB, perturbed gains with --system $p1 dB"
check "infer: perturbed + --system = the model's system ($p1 vs $p0 dB)" \
  awk -v a="$p1" -v b="$p0" 'BEGIN { d = a - b; exit !(d < 0.1 && d > -0.1) }'
p2=$("$PSNR" "$T/i2/cube_0000.exr" "$T/s1/gt/gt_0000.exr")
check "infer: perturbed without --system loses over 1 dB ($p2 vs $p0 dB)" \
  awk -v a="$p2" -v b="$p0" 'BEGIN { exit !(a < b - 1) }'

# refused: what cannot be rescaled
F=$T/s1/frames/frame_0000.png
expect_error "another tile map" 2 "another tile map: position (0, 0) holds Green" "$T/e1" -- \
  "$LM" infer --model "$MODEL" --input "$F" --system "$T/swapped.json" --output "$T/e1"
expect_error "another emission" 2 "LED 'Cyan' has another emission" "$T/e2" -- \
  "$LM" infer --model "$MODEL" --input "$F" --system "$T/emission.json" --output "$T/e2"
expect_error "eval: another tile map" 2 "model/system mismatch" "$T/e3" -- \
  "$LM" eval --model "$MODEL" "$CAVE" --split all --system "$T/swapped.json" --output "$T/e3"
finish
