#!/usr/bin/env bash
# auto.sh — end-to-end tests of `lumosaic fit-auto` and `lumosaic infer --model auto`: train a
# linear and an mcan-tiny model briefly, calibrate them on procedural held-out scenes (auto.json
# has the fields, one PSNR per bin and model, positive costs, the table is printed); with
# --test-synth 2 the test table and the "test" object (a row per fixed model and per tolerance,
# shares summing to 1, positive times, a huge tolerance = the cheapest model's PSNR with all its
# windows, tolerance 0 = the best model per bin; infer --model auto still reads the file); infer
# --model auto with tolerance 0 and a huge tolerance (every window on one model: the summary
# says so and the cube equals that model's patch-wise cube, cli_cube_diff); the noise measure
# (calibrated at two noise levels: one bin each, a clean frame to one model, a noisy one to the
# other; calibrated on clipped 16-bit frames with --clip --bits 16; eval --model auto scores
# clean frames as the one and noisy frames as the other); the linear model runs on the whole
# frame by default and agrees with --tiles (PSNR between them > 40 dB); bad input: missing /
# broken calibration, --auto without auto, one model, no scenes, bad --split / --measure /
# --noise / --bits / --test-synth / --test-tol — one line on stderr, exit 2, no output left.
# usage: auto.sh LUMOSAIC MAKE_CUBE CUBE_PSNR CUBE_DIFF
source "$(dirname "$0")/lib.sh"
PSNR=$3
DIFF=$4

"$LM" train --model linear --data "$CAVE" --iterations 40 --batch 4 --accum-steps 1 --lr 5e-3 \
  --synth-fraction 0.5 --noise 0,0 --val-patches 1 --output "$T/lin" --quiet > "$T/log" 2>&1
check "train linear: $(cat "$T/log")" [ -s "$T/lin/model.safetensors" ]
"$LM" train --model mcan-tiny --data "$CAVE" --iterations 20 --batch 2 --accum-steps 1 \
  --lr 2e-3 --synth-fraction 0.5 --noise 0,0 --val-patches 1 --output "$T/mc" --quiet \
  > "$T/log" 2>&1
check "train mcan-tiny: $(cat "$T/log")" [ -s "$T/mc/model.safetensors" ]
"$LM" simulate --input "$CAVE" --output "$T/sim" --crop > "$T/log" 2>&1
check "simulate: $(cat "$T/log")" [ -s "$T/sim/frames/frame_0000.png" ]
F=$T/sim/frames/frame_0000.png
# same A B: the cubes are equal (largest difference 0)
same() { local d; d=$("$DIFF" "$1" "$2") && awk -v d="$d" 'BEGIN { exit !(d == 0) }'; }

# ---- fit-auto ---------------------------------------------------------------------------
"$LM" fit-auto --models "$T/lin,$T/mc" --synth 2 --synth-size 132x128 --bins 3 \
  --output "$T/auto.json" > "$T/table" 2> "$T/err"
check "fit-auto: $(cat "$T/err")" [ $? -eq 0 ]
cat "$T/table"
check "table has a row per bin" [ "$(grep -cE '^\[' "$T/table")" -eq 3 ]
python3 - "$T/auto.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
assert j["version"] == 1 and j["measure"] == "grad" and j["window"] == [66, 64], j
assert len(j["edges"]) == 2 and j["edges"][0] < j["edges"][1], j
assert sum(j["windows"]) == 2 * 12, j  # 132 x 128: rows 0, 30, 60, 66; columns 0, 32, 64
assert [m["preset"] for m in j["models"]] == ["linear", "mcan-tiny"], j
# models beside the calibration are named relative to its folder (infer finds them from there)
assert [m["model"] for m in j["models"]] == ["lin/model.safetensors", "mc/model.safetensors"], j
for m in j["models"]:
    assert m["cost_s_per_window"] > 0 and len(m["psnr"]) == 3, m
    assert all(5 < p < 100 for p in m["psnr"]), m
assert j["models"][0]["macs_per_window"] < j["models"][1]["macs_per_window"]
assert "test" not in j, j  # only with --test-synth
PY
check "auto.json fields" [ $? -eq 0 ]

# ---- fit-auto --test-synth: auto against the fixed models on other scenes -----------------
"$LM" fit-auto --models "$T/lin,$T/mc" --synth 2 --synth-size 132x128 --bins 3 \
  --test-synth 2 --test-tol 0,0.5,1000 --threads 1 --output "$T/autot.json" > "$T/ttable" \
  2> "$T/err"
check "fit-auto --test-synth: $(cat "$T/err")" [ $? -eq 0 ]
cat "$T/ttable"
check "test table: a row per fixed model" \
  [ "$(grep -cE '^(linear|mcan-tiny) ' "$T/ttable")" -eq 2 ]
check "test table: a row per tolerance" [ "$(grep -cE '^auto tol ' "$T/ttable")" -eq 3 ]
check "test header" grep -q '^test: 2 procedural scene(s) of 132x128 .* 24 windows; 285 windows' \
  "$T/ttable"
python3 - "$T/auto.json" "$T/autot.json" <<'PY'
import json, sys
a, j = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
# the same calibration scenes and models: the fit is the same as without --test-synth
assert j["edges"] == a["edges"] and j["windows"] == a["windows"], (a, j)
t = j["test"]
assert t["scenes"] == 2 and t["size"] == [132, 128] and t["windows"] == 24, t
assert t["windows_per_640x480"] == 285 and t["threads"] == 1, t
rows = t["rows"]
assert [r["kind"] for r in rows] == ["fixed"] * 2 + ["auto"] * 3, rows
assert [r.get("model") for r in rows[:2]] == ["linear", "mcan-tiny"], rows
assert [r.get("tol_db") for r in rows[2:]] == [0, 0.5, 1000], rows
ms = j["models"]
for r in rows:
    assert len(r["share"]) == 2 and abs(sum(r["share"]) - 1) < 1e-9, r
    assert r["est_s_per_frame"] > 0 and r["measured_s"] > 0 and r["measured_s_per_frame"] > 0, r
    assert 5 < r["psnr_db"] < 100 and r["speedup_est"] > 0, r
    assert len(r["choice"]) == 3, r
for m in range(2):
    assert rows[m]["share"][m] == 1 and rows[m]["choice"] == [m] * 3, rows[m]
    est = ms[m]["cost_s_per_window"] * 285
    assert abs(rows[m]["est_s_per_frame"] - est) <= 1e-6 * est, (rows[m], est)
best = max(range(2), key=lambda m: rows[m]["psnr_db"])
assert t["best"] == ms[best]["preset"] and rows[best]["psnr_vs_best_db"] == 0, t
# huge tolerance: every window on the cheapest model, its PSNR
cheap = min(range(2), key=lambda m: ms[m]["cost_s_per_window"])
huge = rows[4]
assert huge["share"][cheap] == 1 and huge["choice"] == [cheap] * 3, huge
assert abs(huge["psnr_db"] - rows[cheap]["psnr_db"]) < 1e-6, (huge, rows[cheap])
# tolerance 0: the best model of each bin (lm_auto_choose)
for b, c in enumerate(rows[2]["choice"]):
    assert ms[c]["psnr"][b] == max(x["psnr"][b] for x in ms), (b, c, ms)
PY
check "autot.json test fields" [ $? -eq 0 ]
"$LM" infer --model auto --auto "$T/autot.json" --input "$T/sim/frames/frame_0000.png" \
  --output "$T/at" > /dev/null 2> "$T/err"
check "infer --model auto reads a file with \"test\": $(cat "$T/err")" \
  [ -s "$T/at/cube_0000.exr" ]

# ---- infer --model auto ------------------------------------------------------------------
# the cost order comes from the measurement: find the cheaper and the better model per file
read cheap best < <(python3 - "$T/auto.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))["models"]
c = min(range(2), key=lambda m: j[m]["cost_s_per_window"])
# tol 0 picks the best in every bin; make the best model the same in every bin for the test
print(j[c]["preset"], j[1 - c]["preset"])
PY
)
"$LM" infer --model auto --auto "$T/auto.json" --auto-tol 1000 --input "$F" --output "$T/a1" \
  > "$T/sum1" 2> "$T/err"
check "infer auto huge tol: $(cat "$T/err")" [ $? -eq 0 ]
check "huge tol: every window on the cheapest ($cheap)" grep -q " $cheap 100.0%" "$T/sum1"
dir_of() { [ "$1" = linear ] && echo "$T/lin" || echo "$T/mc"; }
"$LM" infer --model "$(dir_of "$cheap")" --tiles --input "$F" --output "$T/c1" 2> /dev/null
check "huge tol = the cheapest model's patch-wise cube" \
  same "$T/a1/cube_0000.exr" "$T/c1/cube_0000.exr"
# tol 0: per bin the best model; force one best everywhere by making it win every bin
python3 - "$T/auto.json" "$T/auto_best.json" "$best" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
for m in j["models"]:
    m["psnr"] = [40.0 if m["preset"] == sys.argv[3] else 20.0 for _ in m["psnr"]]
json.dump(j, open(sys.argv[2], "w"))
PY
"$LM" infer --model auto --auto "$T/auto_best.json" --auto-tol 0 --input "$F" \
  --output "$T/a0" > "$T/sum0" 2> "$T/err"
check "infer auto tol 0: $(cat "$T/err")" [ $? -eq 0 ]
check "tol 0: every window on the best ($best)" grep -q " $best 100.0%" "$T/sum0"
"$LM" infer --model "$(dir_of "$best")" --tiles --input "$F" --output "$T/b0" 2> /dev/null
check "tol 0 = the best model's patch-wise cube" \
  same "$T/a0/cube_0000.exr" "$T/b0/cube_0000.exr"
check "progress line has the share per model" grep -q '^auto: .* of [0-9]* windows' "$T/err"

# ---- the noise measure: one choice per frame, by its estimated noise level -----------------
"$LM" fit-auto --models "$T/lin,$T/mc" --synth 2 --synth-size 132x128 --bins 2 \
  --measure noise --noise 0,10 --threads 1 --output "$T/autn.json" > "$T/ntable" 2> "$T/err"
check "fit-auto --measure noise: $(cat "$T/err")" [ $? -eq 0 ]
check "table: scenes at 2 noise levels" grep -q 'from 2 scene(s) at 2 noise level(s); measure noise' \
  "$T/ntable"
python3 - "$T/autn.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
assert j["measure"] == "noise" and j["noise_percent"] == [0, 10], j
# the clean frames read about 0, those at 10 % about 0.1: the one edge lies between them and
# each bin holds one level's windows
assert len(j["edges"]) == 1 and 0.005 < j["edges"][0] < 0.08, j["edges"]
assert j["windows"] == [24, 24], j["windows"]
for m in j["models"]:
    m["psnr"] = [40.0, 20.0] if m["preset"] == "linear" else [20.0, 40.0]
json.dump(j, open(sys.argv[1].replace(".json", "_x.json"), "w"))
PY
check "noise calibration fields" [ $? -eq 0 ]
# calibrated on the frames a 16-bit file holds: clipped at 0 and quantised; the table and the file
# say so, and the noisy bin's expected PSNR differs from the unclipped calibration's (the same
# scenes and noise draws), the clean bin's by quantisation only
"$LM" fit-auto --models "$T/lin,$T/mc" --synth 2 --synth-size 132x128 --bins 2 \
  --measure noise --noise 0,10 --clip --bits 16 --threads 1 --output "$T/autc.json" \
  > "$T/ctable" 2> "$T/err"
check "fit-auto --clip --bits 16: $(cat "$T/err")" [ $? -eq 0 ]
check "table: clipped, 16 bits" grep -q 'measure noise; frames clipped to \[0, 1\]; frames quantised to 16 bits$' \
  "$T/ctable"
python3 - "$T/autn.json" "$T/autc.json" <<'PY'
import json, sys
n, c = (json.load(open(f)) for f in sys.argv[1:])
assert n["clip"] is False and n["bits"] == 0, n
assert c["clip"] is True and c["bits"] == 16, c
assert c["windows"] == n["windows"], (c["windows"], n["windows"])
for mn, mc in zip(n["models"], c["models"]):
    assert abs(mn["psnr"][0] - mc["psnr"][0]) < 0.5, (mn["psnr"], mc["psnr"])  # 16-bit steps
    assert abs(mn["psnr"][1] - mc["psnr"][1]) > 1e-3, (mn["psnr"], mc["psnr"])  # clipped noise
PY
check "clipped calibration fields" [ $? -eq 0 ]
"$LM" simulate --input "$CAVE" --output "$T/sim10" --crop --noise 0.1 > "$T/log" 2>&1
check "simulate at 10 %: $(cat "$T/log")" [ -s "$T/sim10/frames/frame_0000.png" ]
"$LM" infer --model auto --auto "$T/autn_x.json" --auto-tol 0 --input "$F" --output "$T/n0" \
  > "$T/sumn0" 2> "$T/err"
check "noise auto, clean frame: $(cat "$T/err")" grep -q " linear 100.0%" "$T/sumn0"
"$LM" infer --model auto --auto "$T/autn_x.json" --auto-tol 0 \
  --input "$T/sim10/frames/frame_0000.png" --output "$T/n1" > "$T/sumn1" 2> "$T/err"
check "noise auto, noisy frame: $(cat "$T/err")" grep -q " mcan-tiny 100.0%" "$T/sumn1"
# eval --model auto: each frame as infer reconstructs it, so clean frames score as linear and
# noisy ones as mcan-tiny (the same scenes, noise draws and windows)
EV="$CAVE --split all --noise 0,10 --rainbow 0 --threads 1"
"$LM" eval --model auto --auto "$T/autn_x.json" --auto-tol 0 $EV --output "$T/eva" \
  > "$T/evlog" 2>&1
check "eval --model auto: $(cat "$T/evlog")" [ -s "$T/eva/eval.csv" ]
check "eval names the model per bin" grep -q 'the model per noise bin:.* linear,.* mcan-tiny' \
  "$T/evlog"
"$LM" eval --model "$T/lin" $EV --output "$T/evl" > /dev/null 2>&1
"$LM" eval --model "$T/mc" $EV --output "$T/evm" > /dev/null 2>&1
check_auto_split "$T/eva" "$T/evl" linear "$T/evm" mcan-tiny
check "eval.json records the calibration" \
  python3 -c "import json,sys; j=json.load(open(sys.argv[1])); assert j['preset']=='auto' \
and len(j['auto_models'])==2 and j['auto_choice']==[0,1], j" "$T/eva/eval.json"

# ---- whole frame vs windows for the linear model -----------------------------------------
"$LM" infer --model "$T/lin" --input "$F" --output "$T/w" 2> /dev/null
"$LM" infer --model "$T/lin" --tiles --input "$F" --output "$T/t" 2> /dev/null
p=$("$PSNR" "$T/w/cube_0000.exr" "$T/t/cube_0000.exr")
echo "whole frame vs windows (linear): $p dB"
check "whole frame agrees with windows ($p dB > 40)" awk -v p="$p" 'BEGIN { exit !(p > 40) }'
check_not "whole frame is not the window path bit for bit" \
  cmp -s "$T/w/cube_0000.exr" "$T/t/cube_0000.exr"

# ---- bad input ---------------------------------------------------------------------------
echo '{"version": 1}' > "$T/broken.json"
expect_error "missing calibration" 2 "cannot open calibration" "$T/e1" -- \
  "$LM" infer --model auto --auto "$T/none.json" --input "$F" --output "$T/e1"
expect_error "broken calibration" 2 "missing or bad field" "$T/e2" -- \
  "$LM" infer --model auto --auto "$T/broken.json" --input "$F" --output "$T/e2"
expect_error "--auto without auto" 2 "only for --model auto" "$T/e4" -- \
  "$LM" infer --model "$T/lin" --auto "$T/auto.json" --input "$F" --output "$T/e4"
expect_error "negative tol" 2 "--auto-tol" "$T/e5" -- \
  "$LM" infer --model auto --auto "$T/auto.json" --auto-tol -1 --input "$F" --output "$T/e5"
expect_error "fit-auto one model" 2 "at least 2 models" "$T/e6.json" -- \
  "$LM" fit-auto --models "$T/lin" --synth 1 --output "$T/e6.json"
expect_error "fit-auto no scenes" 2 "no scenes" "$T/e7.json" -- \
  "$LM" fit-auto --models "$T/lin,$T/mc" --output "$T/e7.json"
expect_error "fit-auto bad split" 2 "--split" "$T/e8.json" -- \
  "$LM" fit-auto --models "$T/lin,$T/mc" --synth 1 --split x --output "$T/e8.json"
expect_error "fit-auto bad measure" 2 "--measure" "$T/e9.json" -- \
  "$LM" fit-auto --models "$T/lin,$T/mc" --synth 1 --measure fft --output "$T/e9.json"
expect_error "fit-auto missing model" 2 "nope" "$T/e10.json" -- \
  "$LM" fit-auto --models "$T/lin,$T/nope" --synth 1 --output "$T/e10.json"
expect_error "fit-auto negative --test-synth" 2 "--test-synth" "$T/e11.json" -- \
  "$LM" fit-auto --models "$T/lin,$T/mc" --synth 1 --test-synth -1 --output "$T/e11.json"
expect_error "fit-auto bad --test-tol" 2 "--test-tol" "$T/e12.json" -- \
  "$LM" fit-auto --models "$T/lin,$T/mc" --synth 1 --test-synth 1 --test-tol 0,x \
  --output "$T/e12.json"
expect_error "fit-auto negative --test-tol" 2 "--test-tol" "$T/e13.json" -- \
  "$LM" fit-auto --models "$T/lin,$T/mc" --synth 1 --test-synth 1 --test-tol -0.5 \
  --output "$T/e13.json"
expect_error "fit-auto bad --noise" 2 "--noise '0,x'" "$T/e15.json" -- \
  "$LM" fit-auto --models "$T/lin,$T/mc" --synth 1 --noise 0,x --output "$T/e15.json"
expect_error "fit-auto nine --noise levels" 2 "--noise" "$T/e16.json" -- \
  "$LM" fit-auto --models "$T/lin,$T/mc" --synth 1 --noise 0,1,2,3,4,5,6,7,8 \
  --output "$T/e16.json"
expect_error "eval auto without --auto" 2 "needs --auto FILE" "$T/e17" -- \
  "$LM" eval --model auto $EV --output "$T/e17"
expect_error "eval --auto without auto" 2 "only for --model auto" "$T/e18" -- \
  "$LM" eval --model "$T/lin" --auto "$T/autn.json" $EV --output "$T/e18"
expect_error "eval --auto with --noise-oracle" 2 "--noise-oracle with --auto" "$T/e19" -- \
  "$LM" eval --model auto --auto "$T/autn.json" --noise-oracle $EV --output "$T/e19"
expect_error "fit-auto bad --bits" 2 "--bits" "$T/e20.json" -- \
  "$LM" fit-auto --models "$T/lin,$T/mc" --synth 1 --bits 25 --output "$T/e20.json"
expect_error "fit-auto empty --test-tol" 2 "--test-tol" "$T/e14.json" -- \
  "$LM" fit-auto --models "$T/lin,$T/mc" --synth 1 --test-tol , --output "$T/e14.json"
finish
