#!/usr/bin/env bash
# reliability.sh — end-to-end regression tests of issue 16 (reliability) at the command line:
# impossible options and config values (thread counts, integers that do not fit, non-finite or
# out-of-range numbers in flags, run and study configs and system files) are refused with one
# line on stderr that says the allowed range, exit 2 and no run folder left.
# usage: reliability.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
SRC=$(cd "$(dirname "$0")/../.." && pwd)

# a quick training run: linear, a few iterations of 2 patches (under a timeout: some of the
# values below made a run hang or train for ever)
TR="timeout 60 $LM train --model linear --data $CAVE --batch 2 --accum-steps 1 --synth-fraction 0 --val-patches 1 --quiet"

# ---- thread counts ------------------------------------------------------------------------
printf '{"version": 1, "threads": 100000}' > "$T/threads.json"
expect_error "train --threads 100000" 2 "'threads': 100000 is out of range (0..1024)" "$T/th1" -- \
  $TR --iterations 2 --threads 100000 --output "$T/th1"
expect_error "train config threads 100000" 2 "'threads': 100000 is out of range (0..1024)" "$T/th2" -- \
  $TR --iterations 2 --config "$T/threads.json" --output "$T/th2"
expect_error "infer --threads 100000" 2 "--threads: 100000 is out of range (1..1024)" "$T/th3" -- \
  "$LM" infer --model x --input y --output "$T/th3" --threads 100000

# ---- numbers: integers range-checked before they are converted, reals finite and in range --
printf '{"version": 1, "patch": [4294967362, 64]}' > "$T/patch.json"
printf '{"version": 1, "iterations": 9223372036854775807}' > "$T/iter.json"
expect_error "config patch [2^32 + 66, 64]" 2 "'patch': 4294967362 is out of range (1..4096)" \
  "$T/n1" -- $TR --iterations 2 --config "$T/patch.json" --output "$T/n1"
expect_error "--patch 4294967362x64" 2 "'patch': 4294967362 is out of range (1..4096)" "$T/n2" -- \
  $TR --iterations 2 --patch 4294967362x64 --output "$T/n2"
expect_error "--val-patches 2^31 - 1" 2 "'val_patches': 2147483647 is out of range (0..100000)" \
  "$T/n3" -- $TR --iterations 2 --val-patches 2147483647 --output "$T/n3"
expect_error "--lr 1e39" 2 "'lr': 1e+39 is out of range (0..10)" "$T/n4" -- \
  $TR --iterations 2 --lr 1e39 --output "$T/n4"
expect_error "--batch 2^64" 2 "'batch': must be an integer in 1..4096 (got '18446744073709551616')" \
  "$T/n5" -- $TR --iterations 2 --batch 18446744073709551616 --output "$T/n5"
expect_error "--noise 0,1e39" 2 "'noise': 1e+39 is out of range (0..1)" "$T/n6" -- \
  $TR --iterations 2 --noise 0,1e39 --output "$T/n6"
expect_error "config iterations 2^63 - 1" 2 "'iterations': 9223372036854775807 is out of range (1..1000000000)" \
  "$T/n7" -- $TR --config "$T/iter.json" --output "$T/n7"
printf '{"version": 1, "presets": ["linear"], "data": "%s", "eval_size": [4294967362, 64]}' \
  "$CAVE" > "$T/study.json"
expect_error "study eval_size [2^32 + 66, 64]" 2 "field 'eval_size': must be \"HxW\" or [H, W] (1..8192)" \
  "$T/n8" -- timeout 60 "$LM" study --config "$T/study.json" --output "$T/n8"
expect_error "simulate --frames x" 2 "--frames: 'x' is not an integer in 1..10000" "$T/n9" -- \
  "$LM" simulate --input "$CAVE" --crop --video --frames x --output "$T/n9"
expect_error "render --exposure 1e999" 2 "--exposure: '1e999' is not a finite number in 1e-12..1e+06" \
  "$T/n10.png" -- "$LM" render --input "$CAVE" --exposure 1e999 --output "$T/n10.png"
expect_error "calibrate --synth-size 4294967362x256" 2 \
  "--synth-size '4294967362x256': want HxW, from 66x64 to 4096x4096" "$T/n11.json" -- \
  "$LM" calibrate --models a --synth 1 --synth-size 4294967362x256 --output "$T/n11.json"
expect_error "simulate --motion rotate:1e300" 2 "every number in -1e6..1e6" "$T/n12" -- \
  "$LM" simulate --input "$CAVE" --crop --video --frames 2 --motion rotate:1e300 --output "$T/n12"
printf '{"version": 1, "measure": "grad", "window": [4294967362, 64], "stride": [30, 32], "edges": [], "windows": [1], "models": [{"model": "x", "cost_s_per_window": 1, "psnr": [30]}]}' > "$T/auto.json"
expect_error "auto.json window 2^32 + 66" 2 "window / stride [h, w] (integers in 1..4096)" "$T/n14" -- \
  "$LM" infer --model auto --auto "$T/auto.json" --input "$CAVE" --output "$T/n14"
# a system file whose gain overflows the responses to inf (every frame was zero, exit 0)
sed -e "s|\"\.\./spectra/|\"$SRC/data/spectra/|g" \
    -e 's|"gains": "equal_white"|"gains": [1e308, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1]|' \
    "$SRC/data/systems/default.json" > "$T/gains.json"
check "gains fixture" grep -q 1e308 "$T/gains.json"
expect_error "system gains[0] 1e308" 2 \
  "gains[0]: must be a non-negative number of at most 1e+12 (got 1e+308)" "$T/n13" -- \
  "$LM" simulate --input "$CAVE" --crop --system "$T/gains.json" --output "$T/n13"

# ---- resume of a run started with relative paths (the README's example) ------------------
# config.json stored --data as given (relative to the working directory) and resume read it
# relative to the run folder: resuming failed, from the same working directory or another.
mkdir -p "$T/wd1/scenes" "$T/wd2"
cp -r "$CAVE" "$T/wd1/scenes/"
RT="--model linear --batch 2 --accum-steps 1 --synth-fraction 0 --val-patches 1 --quiet"
(cd "$T/wd1" && "$LM" train $RT --data scenes/balloons_crop100 --iterations 2 \
  --output runs/rel > "$T/rel.log" 2>&1)
check "relative run: $(cat "$T/rel.log")" [ -s "$T/wd1/runs/rel/model.safetensors" ]
(cd "$T/wd1" && "$LM" train --resume runs/rel --iterations 3 > "$T/rel2.log" 2>&1)
check "resume from the same folder: $(cat "$T/rel2.log")" grep -q "for 3 iterations" "$T/rel2.log"
(cd "$T/wd2" && "$LM" train --resume ../wd1/runs/rel --iterations 4 > "$T/rel3.log" 2>&1)
check "resume from another folder: $(cat "$T/rel3.log")" grep -q "for 4 iterations" "$T/rel3.log"

finish
