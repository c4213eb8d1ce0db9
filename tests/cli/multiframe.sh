#!/usr/bin/env bash
# multiframe.sh — the multi-frame input end to end: train a "-mf3" model a
# few iterations (train --frames 3 picks rt-8-mf3; the run and its weights record 3 frames),
# simulate a translating 3-frame video, infer every frame (the ends included; aligned and
# --no-align give different cubes), eval with motion rows at two noise levels, info lists the
# presets. Bad input, one line on stderr and exit 2, nothing written: a single frame for a
# multi-frame model, a model without a multi-frame form, frames 3 with both buckets, spectral
# augmentation of multi-frame samples or of a closed-form fit, a tilt out of range, a bucket-0
# noise ratio for SGD training or a one-bucket floor.
# usage: multiframe.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"

TR="--data $CAVE --patch 24x32 --batch 2 --iterations 3 --val-patches 2 --threads 1 --quiet"
R=$T/run
"$LM" train --model rt-8 --frames 3 --motion-fraction 0.5 $TR --output "$R" > "$T/log" 2>&1
check "train --frames 3: $(cat "$T/log")" [ -s "$R/model.safetensors" ]
check "the run is rt-8-mf3" grep -q '"model": "rt-8-mf3"' "$R/config.json"
check "config records frames 3" grep -q '"frames": 3' "$R/config.json"
check "weights record frames 3" grep -q '"frames":"3"' <(head -c 4000 "$R/model.safetensors")

S=$T/vid
"$LM" simulate --input "$CAVE" --output "$S" --crop --video --frames 3 \
  --motion translate:240,180 > "$T/log" 2>&1
check "simulate --video: $(cat "$T/log")" [ -s "$S/frames/frame_0002.png" ]
"$LM" infer --model "$R" --input "$S/frames" --output "$T/o" --threads 1 2> "$T/err"
check "infer a 3-frame sequence: $(cat "$T/err")" [ -s "$T/o/cube_0000.exr" ] && \
  [ -s "$T/o/cube_0001.exr" ] && [ -s "$T/o/cube_0002.exr" ]
check "alignment is timed per frame" grep -q 'alignment [0-9.]* s' "$T/err"
"$LM" infer --model "$R" --input "$S/frames" --output "$T/u" --no-align --threads 1 2> "$T/err"
check "infer --no-align: $(cat "$T/err")" [ -s "$T/u/cube_0001.exr" ]
check_not "aligned and recorded stacks give different cubes" \
  cmp -s "$T/o/cube_0001.exr" "$T/u/cube_0001.exr"
"$LM" eval --model "$R" "$CAVE" --split all --noise 0 --rainbow 0 --motion 0,240 \
  --motion-noise 0,10 --threads 1 --output "$T/ev" > "$T/evlog" 2>&1
check "eval of the multi-frame model: $(cat "$T/evlog")" [ -s "$T/ev/eval_motion.csv" ]
check "four motion rows per scene and mean" \
  [ "$(grep -cE '^(balloons_crop100|mean),(0|240),' "$T/ev/eval_motion.csv")" -eq 8 ]
check "info lists the -mf3 presets" grep -q '^rt-16-mf3 ' <("$LM" info --list)

# ---- bad input ---------------------------------------------------------------------------
expect_error "one frame for a multi-frame model" 2 "reads three frames" "$T/e1" -- \
  "$LM" infer --model "$R" --input "$S/frames/frame_0001.png" --output "$T/e1"
expect_error "no multi-frame form" 2 "no multi-frame form" "$T/e2" -- \
  "$LM" train --model lmmse --frames 3 --data "$CAVE" --output "$T/e2"
expect_error "frames 3 with both buckets" 2 "no two-bucket form" "$T/e3" -- \
  "$LM" train --model rt-8-mf3 --buckets 2 $TR --output "$T/e3"
expect_error "augmentation of multi-frame samples" 2 "without augmentation" "$T/e4" -- \
  "$LM" train --model rt-8-mf3 --illum-jitter 0.3 $TR --output "$T/e4"
expect_error "augmentation for a closed-form fit" 2 "reads the scenes as they are" "$T/e5" -- \
  "$LM" train --model lmmse --gain-jitter 0.05 --data "$CAVE" --output "$T/e5"
expect_error "illumination tilt out of range" 2 "illum-jitter" "$T/e6" -- \
  "$LM" train --model rt-8 --illum-jitter 5 --data "$CAVE" --output "$T/e6"
expect_error "bucket-0 noise ratio for SGD training" 2 "not of SGD training" "$T/e7" -- \
  "$LM" train --model rt-8 --fit-b0-noise 0.3 --data "$CAVE" --output "$T/e7"
expect_error "bucket-0 noise ratio for a one-bucket floor" 2 "bucket-0 noise ratio" "$T/e8" -- \
  "$LM" train --model lmmse --fit-b0-noise 0.3 --data "$CAVE" --fit-patches 16 --output "$T/e8"
expect_error "zoom of multi-frame samples" 2 "without zoom, transposition or collage" "$T/e9" -- \
  "$LM" train --model rt-8-mf3 --scale-jitter 0.3 $TR --output "$T/e9"
expect_error "transposition of moving samples" 2 "without zoom, transposition or collage" "$T/e10" -- \
  "$LM" train --model rt-8 --motion-fraction 0.5 --transpose 1 --data "$CAVE" --output "$T/e10"
expect_error "zoom out of range" 2 "scale-jitter" "$T/e11" -- \
  "$LM" train --model rt-8 --scale-jitter 2 --data "$CAVE" --output "$T/e11"
expect_error "collage of multi-frame samples" 2 "without zoom, transposition or collage" "$T/e12" -- \
  "$LM" train --model rt-8-mf3 --collage 0.3 $TR --output "$T/e12"
expect_error "collage share out of range" 2 "collage" "$T/e13" -- \
  "$LM" train --model rt-8 --collage 1.5 --data "$CAVE" --output "$T/e13"
expect_error "synthetic shares over 1" 2 "fine_fraction" "$T/e14" -- \
  "$LM" train --model rt-8 --synth-fraction 0.5 --procedural-fraction 0.3 --fine-fraction 0.3 \
  --data "$CAVE" --output "$T/e14"
finish
