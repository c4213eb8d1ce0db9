#!/usr/bin/env bash
# auto_b2.sh — a calibrated `--model auto` of two-bucket models end to end: fit two two-bucket
# floors (lmmse-3-b2, lmmse-5-b2), calibrate them by noise level with fit-auto (their frames
# simulated with bucket 0); with the calibration forced to one model per noise bin, infer
# --model auto sends a clean two-bucket frame to the one and a noisy one to the other, each cube
# equal to that model's own patch-wise cube (both read bucket 0: a wrong bucket 0 changes the
# cube; on an OpenCL device the same cube), the summary line names both buckets; eval --model auto scores clean frames as the one
# and noisy frames as the other. Bad input, one line on stderr and exit 2, nothing written: a
# one-bucket and a two-bucket model in one fit-auto, a calibration that mixes them, a
# two-bucket calibration without bucket 0, a one-bucket calibration given --bucket0.
# usage: auto_b2.sh LUMOSAIC MAKE_CUBE CUBE_DIFF CUBE_PSNR
source "$(dirname "$0")/lib.sh"
DIFF=$3
PSNR=$4

FIT="--data $CAVE --fit-patches 64 --batch 16 --patch 24x32 --quiet"
for k in 3 5; do
  "$LM" train --model lmmse-$k --buckets 2 $FIT --output "$T/b2k$k" > "$T/log" 2>&1
  check "train lmmse-$k --buckets 2: $(cat "$T/log")" [ -s "$T/b2k$k/model.safetensors" ]
done
"$LM" train --model lmmse-3 $FIT --output "$T/b1" > "$T/log" 2>&1
check "train lmmse-3 (one bucket): $(cat "$T/log")" [ -s "$T/b1/model.safetensors" ]
"$LM" simulate --input "$CAVE" --output "$T/s0" --crop --bucket0 > "$T/log" 2>&1
check "simulate --bucket0: $(cat "$T/log")" [ -s "$T/s0/bucket0/frame_0000.png" ]
"$LM" simulate --input "$CAVE" --output "$T/s10" --crop --bucket0 --noise 0.1 > "$T/log" 2>&1
check "simulate --bucket0 at 10 %: $(cat "$T/log")" [ -s "$T/s10/bucket0/frame_0000.png" ]
# same A B: the cubes are equal (largest difference 0)
same() { local d; d=$("$DIFF" "$1" "$2") && awk -v d="$d" 'BEGIN { exit !(d == 0) }'; }

# ---- fit-auto on two-bucket models ------------------------------------------------------
"$LM" fit-auto --models "$T/b2k3,$T/b2k5" --synth 2 --synth-size 132x128 --bins 2 \
  --measure noise --noise 0,10 --threads 1 --output "$T/a.json" > "$T/table" 2> "$T/err"
check "fit-auto two-bucket models: $(cat "$T/err")" [ $? -eq 0 ]
cat "$T/table"
python3 - "$T/a.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
assert [m["preset"] for m in j["models"]] == ["lmmse-3-b2", "lmmse-5-b2"], j["models"]
assert len(j["edges"]) == 1 and 0.005 < j["edges"][0] < 0.08, j["edges"]
assert j["windows"] == [24, 24], j["windows"]
for m in j["models"]:
    assert 10 < m["psnr"][0] < 100 and m["psnr"][1] < m["psnr"][0], m
    m["psnr"] = [40.0, 20.0] if m["preset"] == "lmmse-3-b2" else [20.0, 40.0]
json.dump(j, open(sys.argv[1].replace(".json", "_x.json"), "w"))
PY
check "two-bucket calibration fields" [ $? -eq 0 ]

# ---- infer --model auto: bucket 0 beside frames/, the model per frame ---------------------
"$LM" infer --model auto --auto "$T/a_x.json" --auto-tol 0 --input "$T/s0/frames" \
  --output "$T/i0" > "$T/sum0" 2> "$T/err"
check "auto b2, clean frame: $(cat "$T/err")" grep -q " lmmse-3-b2 100.0%" "$T/sum0"
check "the summary line says both buckets" grep -q '^auto: .* of [0-9]* windows (both buckets)' \
  "$T/err"
"$LM" infer --model "$T/b2k3" --tiles --input "$T/s0/frames" --output "$T/r0" 2> /dev/null
check "clean frame = lmmse-3-b2's patch-wise cube" same "$T/i0/cube_0000.exr" "$T/r0/cube_0000.exr"
"$LM" infer --model auto --auto "$T/a_x.json" --auto-tol 0 --input "$T/s10/frames/frame_0000.png" \
  --bucket0 "$T/s10/bucket0/frame_0000.png" --output "$T/i1" > "$T/sum1" 2> "$T/err"
check "auto b2, noisy frame: $(cat "$T/err")" grep -q " lmmse-5-b2 100.0%" "$T/sum1"
"$LM" infer --model "$T/b2k5" --tiles --input "$T/s10/frames" --output "$T/r1" 2> /dev/null
check "noisy frame = lmmse-5-b2's patch-wise cube" same "$T/i1/cube_0000.exr" "$T/r1/cube_0000.exr"
# on an OpenCL device (when a platform exists): the same cube
if ! command -v clinfo > /dev/null || clinfo -l 2> /dev/null | grep -q 'Platform'; then
  "$LM" infer --model auto --auto "$T/a_x.json" --auto-tol 0 --input "$T/s0/frames" \
    --output "$T/icl" --device opencl > /dev/null 2> "$T/err"
  pc=$("$PSNR" "$T/icl/cube_0000.exr" "$T/i0/cube_0000.exr")
  check "OpenCL ~ CPU ($pc dB): $(cat "$T/err")" awk -v p="$pc" 'BEGIN { exit !(p > 80) }'
fi
# bucket 0 is read: bucket 1 given as bucket 0 gives another cube
"$LM" infer --model auto --auto "$T/a_x.json" --auto-tol 0 --input "$T/s0/frames/frame_0000.png" \
  --bucket0 "$T/s0/frames/frame_0000.png" --output "$T/iw" > /dev/null 2> "$T/err"
check "wrong bucket 0 runs: $(cat "$T/err")" [ -s "$T/iw/cube_0000.exr" ]
check_not "a wrong bucket 0 changes the cube" same "$T/iw/cube_0000.exr" "$T/i0/cube_0000.exr"

# ---- eval --model auto on two-bucket frames -----------------------------------------------
EV="$CAVE --split all --noise 0,10 --rainbow 0 --threads 1"
"$LM" eval --model auto --auto "$T/a_x.json" --auto-tol 0 $EV --output "$T/eva" \
  > "$T/evlog" 2>&1
check "eval --model auto (two buckets): $(cat "$T/evlog")" [ -s "$T/eva/eval.csv" ]
"$LM" eval --model "$T/b2k3" $EV --output "$T/ev3" > /dev/null 2>&1
"$LM" eval --model "$T/b2k5" $EV --output "$T/ev5" > /dev/null 2>&1
check_auto_split "$T/eva" "$T/ev3" lmmse-3-b2 "$T/ev5" lmmse-5-b2

# ---- bad input ---------------------------------------------------------------------------
python3 - "$T/a.json" "$T/mixed.json" "$T/b1/model.safetensors" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
j["models"][1]["model"] = sys.argv[3]
json.dump(j, open(sys.argv[2], "w"))
PY
expect_error "fit-auto one- and two-bucket models" 2 "does not take the same coded frames" \
  "$T/e1.json" -- "$LM" fit-auto --models "$T/b2k3,$T/b1" --synth 1 --output "$T/e1.json"
expect_error "a calibration mixing bucket counts" 2 "read the same buckets" "$T/e2" -- \
  "$LM" infer --model auto --auto "$T/mixed.json" --input "$T/s0/frames" --output "$T/e2"
cp "$T/s0/frames/frame_0000.png" "$T/lone.png" # no bucket0/ folder beside it
expect_error "two-bucket calibration without bucket 0" 2 "give --bucket0" "$T/e3" -- \
  "$LM" infer --model auto --auto "$T/a_x.json" --input "$T/lone.png" --output "$T/e3"
"$LM" fit-auto --models "$T/b1,$T/b1" --synth 1 --synth-size 66x64 --bins 1 --threads 1 \
  --output "$T/one.json" > /dev/null 2> "$T/err"
check "fit-auto one-bucket models: $(cat "$T/err")" [ -s "$T/one.json" ]
expect_error "one-bucket calibration with --bucket0" 2 "reads bucket 1 only" "$T/e4" -- \
  "$LM" infer --model auto --auto "$T/one.json" --input "$T/s0/frames/frame_0000.png" \
  --bucket0 "$T/s0/bucket0/frame_0000.png" --output "$T/e4"
finish
