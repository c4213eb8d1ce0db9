#!/usr/bin/env bash
# auto_bundled.sh — `infer --model auto` without a calibration picks a bundled model
# (models/demo/): the two-bucket one when bucket 0 is there (a bucket0/ folder beside frames/,
# or --bucket0), else the single-bucket one; one line names the model and what it read; a
# missing bundled model is one line, exit 2, nothing written. The bundled pairs
# (models/demo/auto-noise.json, one bucket; auto-noise-b2.json, two): a clean frame goes to the
# clean specialist, a frame at 10 % to the bundled network, each pair reading its buckets.
# usage: auto_bundled.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
REPO=$(cd "$(dirname "$0")/../.." && pwd)

"$LM" simulate --input "$CAVE" --output "$T/sim" --crop --bucket0 --noise 0.02 > "$T/log" 2>&1
check "simulate --bucket0: $(cat "$T/log")" [ -s "$T/sim/bucket0/frame_0000.png" ]
"$LM" simulate --input "$CAVE" --output "$T/one" --crop --noise 0.02 > "$T/log1" 2>&1

"$LM" infer --model auto --input "$T/sim/frames" --output "$T/a2" --threads 1 > "$T/o2" 2>&1
check "bucket0/ beside frames/: the two-bucket model: $(head -1 "$T/o2")" \
  grep -q "^model tn-96-nc-b2+lmmse-b2 (.*tn96nc-b2-lmmseb2.safetensors, picked by --model auto): both buckets$" "$T/o2"
check "two-bucket cube written" [ -s "$T/a2/cube_0000.exr" ]

"$LM" infer --model auto --input "$T/one/frames" --output "$T/a1" --threads 1 > "$T/o1" 2>&1
check "no bucket 0: the single-bucket model: $(head -1 "$T/o1")" \
  grep -q "^model tn-160-nc+lmmse (.*tn160nc-lmmse.safetensors, picked by --model auto): bucket 1$" "$T/o1"

"$LM" infer --model auto --input "$T/one/frames" --bucket0 "$T/sim/bucket0" --output "$T/a3" \
  --threads 1 > "$T/o3" 2>&1
check "--bucket0 given: the two-bucket model: $(head -1 "$T/o3")" grep -q "both buckets$" "$T/o3"

"$LM" infer --model "$REPO/models/demo/rt16nc-lmmse.safetensors" --input "$T/one/frames" \
  --output "$T/a4" --threads 1 > "$T/o4" 2>&1
check "a named model: the line without 'picked': $(head -1 "$T/o4")" \
  grep -q "^model rt-16-nc+lmmse ($REPO/models/demo/rt16nc-lmmse.safetensors): bucket 1$" "$T/o4"

# the bundled pairs, chosen by the frame's noise level
"$LM" simulate --input "$CAVE" --output "$T/n10" --crop --bucket0 --noise 0.1 > "$T/log" 2>&1
check "simulate at 10 %: $(cat "$T/log")" [ -s "$T/n10/bucket0/frame_0000.png" ]
"$LM" simulate --input "$CAVE" --output "$T/n0" --crop --bucket0 > "$T/log" 2>&1
pair() { # pair CALIBRATION INPUT OUT: the summary line
  "$LM" infer --model auto --auto "$REPO/models/demo/$1" --input "$2" --output "$T/$3" \
    --threads 1 2>&1 | grep '^auto: '
}
check "one-bucket pair, clean frame: the clean specialist" \
  grep -q '^auto: tn-160-nc+lmmse 100% tn-96-nc+lmmse 0% of [0-9]* windows (bucket 1)$' \
  <(pair auto-noise.json "$T/n0/frames/frame_0000.png" p1)
check "one-bucket pair, 10 %: the bundled network" \
  grep -q '^auto: tn-160-nc+lmmse 0% tn-96-nc+lmmse 100% of [0-9]* windows (bucket 1)$' \
  <(pair auto-noise.json "$T/n10/frames/frame_0000.png" p2)
check "two-bucket pair, clean frame: the clean specialist" \
  grep -q '^auto: tn-160-nc-b2+lmmse-11-ri15-b2 100% tn-96-nc-b2+lmmse-b2 0% of [0-9]* windows (both buckets)$' \
  <(pair auto-noise-b2.json "$T/n0/frames" p3)
check "two-bucket pair, 10 %: the bundled network" \
  grep -q '^auto: tn-160-nc-b2+lmmse-11-ri15-b2 0% tn-96-nc-b2+lmmse-b2 100% of [0-9]* windows (both buckets)$' \
  <(pair auto-noise-b2.json "$T/n10/frames" p4)

expect_error "bundled model missing" 2 "the bundled single-bucket model is missing" "$T/e1" -- \
  env LM_MODELS_DIR="$T/nowhere" "$LM" infer --model auto --input "$T/one/frames" --output "$T/e1"
finish
