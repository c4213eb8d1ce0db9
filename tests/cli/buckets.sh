#!/usr/bin/env bash
# buckets.sh — both buckets end to end (issue 18, item 3): fit a two-bucket lmmse (train
# --buckets 2 picks lmmse-3-b2; the run records the bucket count), simulate a frame with
# --bucket0, reconstruct it with infer --bucket0 (and with bucket0/ found beside frames/: the
# same cube; patch-wise and on OpenCL: close to it), against the simulated ground truth; a
# wrong bucket 0 changes the cube (the model
# reads it); eval of the two-bucket model (both buckets simulated). Bad input, one line on
# stderr and exit 2, nothing written: no bucket 0 for a two-bucket model, --bucket0 for a
# one-bucket model, a missing bucket-0 file, a bucket-0 frame of another size or count, a
# model without a two-bucket form.
# usage: buckets.sh LUMOSAIC MAKE_CUBE CUBE_PSNR
source "$(dirname "$0")/lib.sh"
PSNR=$3

FIT="--data $CAVE --fit-patches 64 --batch 16 --patch 24x32 --quiet"
R2=$T/run2
"$LM" train --model lmmse-3 --buckets 2 $FIT --output "$R2" > "$T/log" 2>&1
check "train --buckets 2: $(cat "$T/log")" [ -s "$R2/model.safetensors" ]
check "the run is lmmse-3-b2" grep -q '"model": "lmmse-3-b2"' "$R2/config.json"
check "config records buckets 2" grep -q '"buckets": 2' "$R2/config.json"
check "weights record buckets 2" grep -q '"buckets":"2"' <(head -c 4000 "$R2/model.safetensors")
R1=$T/run1
"$LM" train --model lmmse-3 $FIT --output "$R1" > "$T/log" 2>&1
check "train one bucket: $(cat "$T/log")" [ -s "$R1/model.safetensors" ]
check "one-bucket weights record buckets 1" grep -q '"buckets":"1"' <(head -c 4000 "$R1/model.safetensors")

S=$T/sim
"$LM" simulate --input "$CAVE" --output "$S" --crop --bucket0 > "$T/log" 2>&1
check "simulate --bucket0: $(cat "$T/log")" [ -s "$S/bucket0/frame_0000.png" ]

# ---- happy path ------------------------------------------------------------------------
"$LM" infer --model "$R2" --input "$S/frames/frame_0000.png" --bucket0 "$S/bucket0/frame_0000.png" \
  --output "$T/o2" 2> "$T/err"
check "infer --bucket0: $(cat "$T/err")" [ -s "$T/o2/cube_0000.exr" ]
p2=$("$PSNR" "$T/o2/cube_0000.exr" "$S/gt/gt_0000.exr")
"$LM" infer --model "$R1" --input "$S/frames/frame_0000.png" --output "$T/o1" 2> "$T/err"
check "infer one bucket: $(cat "$T/err")" [ -s "$T/o1/cube_0000.exr" ]
p1=$("$PSNR" "$T/o1/cube_0000.exr" "$S/gt/gt_0000.exr")
echo "PSNR against the ground truth: two buckets $p2 dB, bucket 1 alone $p1 dB"
check "two-bucket PSNR $p2 dB is sane (> 20 dB)" awk -v p="$p2" 'BEGIN { exit !(p > 20 && p < 80) }'
# bucket0/ beside frames/: found without --bucket0, the same cube
"$LM" infer --model "$R2" --input "$S/frames" --output "$T/auto" 2> "$T/err"
check "bucket0/ found beside frames/: $(cat "$T/err")" cmp -s "$T/o2/cube_0000.exr" "$T/auto/cube_0000.exr"
"$LM" infer --model "$R2" --input "$S/frames/frame_%04d.png" --output "$T/pat" 2> "$T/err"
check "a pattern under frames/ too: $(cat "$T/err")" cmp -s "$T/o2/cube_0000.exr" "$T/pat/cube_0000.exr"
# patch-wise (--tiles) against whole-frame strips of both planes: the same cube away from the
# windows' blending (the PSNR between them is high)
"$LM" infer --model "$R2" --input "$S/frames" --output "$T/tiles" --tiles 2> "$T/err"
pt=$("$PSNR" "$T/tiles/cube_0000.exr" "$T/o2/cube_0000.exr")
check "--tiles ~ strips ($pt dB): $(cat "$T/err")" awk -v p="$pt" 'BEGIN { exit !(p > 45) }'
# on an OpenCL device (when a platform exists): the same cube
if ! command -v clinfo > /dev/null || clinfo -l 2> /dev/null | grep -q 'Platform'; then
  "$LM" infer --model "$R2" --input "$S/frames" --output "$T/cl" --device opencl 2> "$T/err"
  pc=$("$PSNR" "$T/cl/cube_0000.exr" "$T/o2/cube_0000.exr")
  check "OpenCL ~ CPU ($pc dB): $(cat "$T/err")" awk -v p="$pc" 'BEGIN { exit !(p > 80) }'
fi
# bucket 1 given as bucket 0: another cube, further from the truth
"$LM" infer --model "$R2" --input "$S/frames/frame_0000.png" --bucket0 "$S/frames/frame_0000.png" \
  --output "$T/wrong" 2> "$T/err"
check "wrong bucket 0 runs: $(cat "$T/err")" [ -s "$T/wrong/cube_0000.exr" ]
check_not "a wrong bucket 0 changes the cube" cmp -s "$T/o2/cube_0000.exr" "$T/wrong/cube_0000.exr"
pw=$("$PSNR" "$T/wrong/cube_0000.exr" "$S/gt/gt_0000.exr")
check "wrong bucket 0 is worse ($pw < $p2 dB)" awk -v a="$pw" -v b="$p2" 'BEGIN { exit !(a < b - 1) }'
# eval simulates both buckets
"$LM" eval --model "$R2" "$CAVE" --noise 0,0.1 --rainbow 0 --split all --output "$T/ev" > "$T/evlog" 2>&1
check "eval of the two-bucket model: $(cat "$T/evlog")" [ -s "$T/ev/eval.json" ]
e2=$(awk -F, 'NR == 2 { print $0 }' "$T/ev/eval.csv")
check "eval table has a row ($e2)" [ -n "$e2" ]
check "info lists the -b2 presets" grep -q '^rt-8-b2 ' <("$LM" info --list)

# ---- bad input ---------------------------------------------------------------------------
mkdir -p "$T/lone" && cp "$S/frames/frame_0000.png" "$T/lone/f.png"
expect_error "two-bucket model without bucket 0" 2 "give --bucket0" "$T/e1" -- \
  "$LM" infer --model "$R2" --input "$T/lone/f.png" --output "$T/e1"
expect_error "--bucket0 for a one-bucket model" 2 "reads bucket 1 only" "$T/e2" -- \
  "$LM" infer --model "$R1" --input "$S/frames/frame_0000.png" --bucket0 "$S/bucket0/frame_0000.png" \
  --output "$T/e2"
expect_error "missing bucket-0 file" 2 "nope.png" "$T/e3" -- \
  "$LM" infer --model "$R2" --input "$S/frames/frame_0000.png" --bucket0 "$T/nope.png" --output "$T/e3"
"$MK" "$T/small.exr" good 72 72 && "$LM" simulate --input "$T/small.exr" --output "$T/small" --crop \
  --bucket0 > /dev/null 2>&1 || fail "small fixture"
expect_error "bucket 0 of another size" 2 "bucket 0 is 72 x 72" "$T/e4" -- \
  "$LM" infer --model "$R2" --input "$S/frames/frame_0000.png" \
  --bucket0 "$T/small/bucket0/frame_0000.png" --output "$T/e4"
"$LM" simulate --input "$CAVE" --output "$T/two" --crop --bucket0 --video --frames 2 > /dev/null 2>&1
expect_error "bucket 0 with another frame count" 2 "1 frames, the input has 2" "$T/e5" -- \
  "$LM" infer --model "$R2" --input "$T/two/frames" --bucket0 "$S/bucket0" --output "$T/e5"
expect_error "no two-bucket form" 2 "no two-bucket form" "$T/e6" -- \
  "$LM" train --model han-tiny --buckets 2 $FIT --output "$T/e6"
expect_error "buckets out of range" 2 "buckets" "$T/e7" -- \
  "$LM" train --model lmmse-3 --buckets 3 $FIT --output "$T/e7"
finish
