#!/usr/bin/env bash
# guide.sh — the panchromatic guide end to end: train fits lmmse-7-g3-b2 in closed form (a
# second fit writes the same weights), simulate --bucket0, infer against the ground truth and
# beside lmmse-7-b2 fitted the same way, eval (both buckets simulated); bad input: a guide
# window too large or even, the guide without bucket 0, the guide on OpenCL, photons for its
# closed-form fit.
# usage: guide.sh LUMOSAIC MAKE_CUBE CUBE_PSNR
source "$(dirname "$0")/lib.sh"
PSNR=$3

FIT="--data $CAVE --fit-patches 64 --batch 16 --patch 24x32 --quiet"
G=$T/guide
"$LM" train --model lmmse-7-g3-b2 $FIT --output "$G" > "$T/log" 2>&1
check "train the guide: $(cat "$T/log")" [ -s "$G/model.safetensors" ]
check "the run is lmmse-7-g3-b2" grep -q '"model": "lmmse-7-g3-b2"' "$G/config.json"
check "fit.json written" [ -s "$G/fit.json" ]
"$LM" train --model lmmse-7-g3-b2 $FIT --output "$T/guide2" > "$T/log" 2>&1
check "a second fit: $(cat "$T/log")" cmp -s "$G/model.safetensors" "$T/guide2/model.safetensors"
L=$T/lin
"$LM" train --model lmmse-7-b2 $FIT --output "$L" > "$T/log" 2>&1
check "train lmmse-7-b2: $(cat "$T/log")" [ -s "$L/model.safetensors" ]
check "info lists the guide" grep -q '^lmmse-guide-b2 ' <("$LM" info --list)

S=$T/sim
"$LM" simulate --input "$CAVE" --output "$S" --crop --bucket0 > "$T/log" 2>&1
check "simulate --bucket0: $(cat "$T/log")" [ -s "$S/bucket0/frame_0000.png" ]
"$LM" infer --model "$G" --input "$S/frames" --output "$T/og" 2> "$T/err"
check "infer with the guide: $(cat "$T/err")" [ -s "$T/og/cube_0000.exr" ]
"$LM" infer --model "$L" --input "$S/frames" --output "$T/ol" 2> "$T/err"
check "infer lmmse-7-b2: $(cat "$T/err")" [ -s "$T/ol/cube_0000.exr" ]
pg=$("$PSNR" "$T/og/cube_0000.exr" "$S/gt/gt_0000.exr")
pl=$("$PSNR" "$T/ol/cube_0000.exr" "$S/gt/gt_0000.exr")
echo "PSNR against the ground truth: lmmse-7-g3-b2 $pg dB, lmmse-7-b2 $pl dB"
check "guide PSNR $pg dB is sane (> 20 dB)" awk -v p="$pg" 'BEGIN { exit !(p > 20 && p < 80) }'
check_not "the guide changes the cube" cmp -s "$T/og/cube_0000.exr" "$T/ol/cube_0000.exr"
# patch-wise against strips: the same cube away from the windows' blending
"$LM" infer --model "$G" --input "$S/frames" --output "$T/tiles" --tiles 2> "$T/err"
pt=$("$PSNR" "$T/tiles/cube_0000.exr" "$T/og/cube_0000.exr")
check "--tiles ~ strips ($pt dB): $(cat "$T/err")" awk -v p="$pt" 'BEGIN { exit !(p > 40) }'
"$LM" eval --model "$G" "$CAVE" --noise 0,10 --rainbow 0 --split all --output "$T/ev" > "$T/evlog" 2>&1
check "eval of the guide: $(cat "$T/evlog")" [ -s "$T/ev/eval.json" ]
e2=$(awk -F, 'NR == 2 { print $0 }' "$T/ev/eval.csv")
check "eval table has a row ($e2)" [ -n "$e2" ]

# ---- bad input ---------------------------------------------------------------------------
expect_error "guide window too large" 2 "unknown preset 'lmmse-7-g9-b2'" "$T/e1" -- \
  "$LM" train --model lmmse-7-g9-b2 $FIT --output "$T/e1"
expect_error "even guide window" 2 "unknown preset 'lmmse-7-g2-b2'" "$T/e2" -- \
  "$LM" train --model lmmse-7-g2-b2 $FIT --output "$T/e2"
mkdir -p "$T/lone" && cp "$S/frames/frame_0000.png" "$T/lone/f.png"
expect_error "the guide without bucket 0" 2 "give --bucket0" "$T/e3" -- \
  "$LM" infer --model "$G" --input "$T/lone/f.png" --output "$T/e3"
expect_error "photons for the closed-form fit" 2 "Gaussian noise only" "$T/e4" -- \
  "$LM" train --model lmmse-7-g3-b2 $FIT --photons 1000 --output "$T/e4"
finish
