#!/usr/bin/env bash
# run_paths.sh — artefacts carry no path of the machine that made them: a run folder's
# config.json records its data, base and system relative to the run folder, so a checkout-like
# tree (repo/models/zoo/<run> with ../shared/data beside the repository) moved to another
# absolute location resumes and infers there; a checkpoint records the bundled system as ""
# and another one relative to its folder; the bundled demo model holds no absolute path;
# eval.json names its model and scenes by absolute paths.
# usage: run_paths.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
SRC=$(cd "$(dirname "$0")/../.." && pwd)

# the tree: $T/a/repo (the checkout) and $T/a/shared/data (the shared data beside it)
A=$T/a
mkdir -p "$A/repo/sys" "$A/shared/data"
cp -r "$CAVE" "$A/shared/data/"
sed -e "s|\"\.\./spectra/|\"$SRC/data/spectra/|g" -e 's|"equal_white"|[1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0.999]|' \
  "$SRC/data/systems/default.json" > "$A/repo/sys/custom.json"
Q="--batch 2 --accum-steps 1 --synth-fraction 0 --val-patches 1 --quiet"
(cd "$A/repo" &&
  "$LM" train --model lmmse --data ../shared/data/balloons_crop100 --fit-patches 32 --batch 8 \
    --val-patches 1 --quiet --output models/zoo/lmmse > "$T/l.log" 2>&1 &&
  "$LM" train --model rt-8 --base models/zoo/lmmse --data ../shared/data/balloons_crop100 $Q \
    --iterations 2 --output models/zoo/rt8 > "$T/r.log" 2>&1 &&
  "$LM" train --model linear --system sys/custom.json --data ../shared/data/balloons_crop100 $Q \
    --iterations 2 --output models/zoo/lin > "$T/s.log" 2>&1)
check "the runs: $(cat "$T/l.log" "$T/r.log" "$T/s.log")" [ -s "$A/repo/models/zoo/lin/model.safetensors" ]

# config.json: paths relative to the run folder, no absolute path
C=$A/repo/models/zoo/rt8/config.json
check "config.json: data relative to the run folder: $(grep -A2 '"data"' "$C")" \
  grep -q '"\.\./\.\./\.\./\.\./shared/data/balloons_crop100"' "$C"
check "config.json: base relative to the run folder: $(grep '"base"' "$C")" \
  grep -q '"base": "\.\./lmmse"' "$C"
check_not "config.json: no absolute path: $(grep -n '"/' "$C")" grep -q '"/' "$C"
check "config.json of a custom system: relative: $(grep '"system"' "$A/repo/models/zoo/lin/config.json")" \
  grep -q '"system": "\.\./\.\./\.\./sys/custom.json"' "$A/repo/models/zoo/lin/config.json"

# checkpoints: the bundled system as "", another relative to the checkpoint's folder
meta() { python3 -c "
import json, struct, sys
b = open(sys.argv[1], 'rb').read()
n = struct.unpack('<Q', b[:8])[0]
print(json.loads(b[8:8 + n])['__metadata__'].get(sys.argv[2], 'MISSING'))" "$1" "$2"; }
check "checkpoint: the bundled system recorded as '': '$(meta "$A/repo/models/zoo/rt8/model.safetensors" system)'" \
  [ -z "$(meta "$A/repo/models/zoo/rt8/model.safetensors" system)" ]
check "checkpoint: a custom system relative: '$(meta "$A/repo/models/zoo/lin/model.safetensors" system)'" \
  [ "$(meta "$A/repo/models/zoo/lin/model.safetensors" system)" = "../../../sys/custom.json" ]
check "the demo model records no absolute path: '$(meta "$SRC/models/demo/rt16nc-lmmse.safetensors" system)'" \
  [ -z "$(meta "$SRC/models/demo/rt16nc-lmmse.safetensors" system)" ]

# the tree moved to another absolute location: resume and infer there
mv "$A" "$T/b"
B=$T/b
(cd "$B/repo" && "$LM" train --resume models/zoo/rt8 --iterations 4 > "$T/m1.log" 2>&1)
check "moved: resumes from the checkout: $(cat "$T/m1.log")" grep -q "for 4 iterations" "$T/m1.log"
(cd "$T" && "$LM" train --resume b/repo/models/zoo/lin --iterations 3 > "$T/m2.log" 2>&1)
check "moved: resumes from elsewhere: $(cat "$T/m2.log")" grep -q "for 3 iterations" "$T/m2.log"
"$LM" simulate --input "$CAVE" --crop --system "$B/repo/sys/custom.json" --output "$T/frames" \
  > /dev/null 2>&1
(cd "$T" && "$LM" infer --model b/repo/models/zoo/lin --input frames/frames --output "$T/inf" \
  > "$T/m3.log" 2>&1)
check "moved: a model of a custom system infers: $(cat "$T/m3.log")" [ -s "$T/inf/cube_0000.exr" ]
# an old run folder with absolute paths still loads
sed -i "s|\"\.\./\.\./\.\./\.\./shared/data/balloons_crop100\"|\"$B/shared/data/balloons_crop100\"|" \
  "$B/repo/models/zoo/rt8/config.json"
"$LM" train --resume "$B/repo/models/zoo/rt8" --iterations 5 > "$T/m4.log" 2>&1
check "absolute paths in config.json still load: $(cat "$T/m4.log")" grep -q "for 5 iterations" "$T/m4.log"

# eval.json: the model and the scenes by absolute paths
(cd "$B" && "$LM" eval --model repo/models/zoo/rt8 shared/data/balloons_crop100 --split all \
  --noise 0 --rainbow 0 --output "$T/ev" > "$T/ev.log" 2>&1)
check "eval ran: $(cat "$T/ev.log")" [ -s "$T/ev/eval.json" ]
check "eval.json: the model by its absolute path: $(grep '"model"' "$T/ev/eval.json")" \
  grep -q "\"model\": \"$B/repo/models/zoo/rt8/model.safetensors\"" "$T/ev/eval.json"
check "eval.json: the scene by its absolute path: $(grep '"path"' "$T/ev/eval.json")" \
  grep -q "\"path\": \"$B/shared/data/balloons_crop100\"" "$T/ev/eval.json"

finish
