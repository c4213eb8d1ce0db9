#!/usr/bin/env bash
# gri.sh — the guided interpolation end to end: train fits lmmse-7-ri11-b2 in closed form (a
# second fit writes the same weights), simulate --bucket0, infer against the ground truth and
# beside lmmse-7-b2 fitted the same way, patch-wise inference against strips, eval (both
# buckets simulated); bad input: an even or too large interpolation window, the model without
# bucket 0, photons for its closed-form fit; on OpenCL (host features, the rest on the device)
# the same cube and scores as on the CPU.
# usage: gri.sh LUMOSAIC MAKE_CUBE CUBE_PSNR
source "$(dirname "$0")/lib.sh"
PSNR=$3

FIT="--data $CAVE --fit-patches 64 --batch 16 --patch 24x32 --quiet"
G=$T/gri
"$LM" train --model lmmse-7-ri11-b2 $FIT --output "$G" > "$T/log" 2>&1
check "train the guided interpolation: $(cat "$T/log")" [ -s "$G/model.safetensors" ]
check "the run is lmmse-7-ri11-b2" grep -q '"model": "lmmse-7-ri11-b2"' "$G/config.json"
check "fit.json written" [ -s "$G/fit.json" ]
"$LM" train --model lmmse-7-ri11-b2 $FIT --output "$T/gri2" > "$T/log" 2>&1
check "a second fit: $(cat "$T/log")" cmp -s "$G/model.safetensors" "$T/gri2/model.safetensors"
L=$T/lin
"$LM" train --model lmmse-7-b2 $FIT --output "$L" > "$T/log" 2>&1
check "train lmmse-7-b2: $(cat "$T/log")" [ -s "$L/model.safetensors" ]
check "info lists lmmse-gri-b2" grep -q '^lmmse-gri-b2 ' <("$LM" info --list)
check "info names the riN form" grep -q 'lmmse-K-riN-b2' <("$LM" info --list)

S=$T/sim
"$LM" simulate --input "$CAVE" --output "$S" --crop --bucket0 > "$T/log" 2>&1
check "simulate --bucket0: $(cat "$T/log")" [ -s "$S/bucket0/frame_0000.png" ]
"$LM" infer --model "$G" --input "$S/frames" --output "$T/og" 2> "$T/err"
check "infer with the guided interpolation: $(cat "$T/err")" [ -s "$T/og/cube_0000.exr" ]
"$LM" infer --model "$L" --input "$S/frames" --output "$T/ol" 2> "$T/err"
check "infer lmmse-7-b2: $(cat "$T/err")" [ -s "$T/ol/cube_0000.exr" ]
pg=$("$PSNR" "$T/og/cube_0000.exr" "$S/gt/gt_0000.exr")
pl=$("$PSNR" "$T/ol/cube_0000.exr" "$S/gt/gt_0000.exr")
echo "PSNR against the ground truth: lmmse-7-ri11-b2 $pg dB, lmmse-7-b2 $pl dB"
check "guided interpolation PSNR $pg dB is sane (> 20 dB)" \
  awk -v p="$pg" 'BEGIN { exit !(p > 20 && p < 80) }'
check_not "the interpolation changes the cube" cmp -s "$T/og/cube_0000.exr" "$T/ol/cube_0000.exr"
# patch-wise against strips: the same cube away from the windows' blending
"$LM" infer --model "$G" --input "$S/frames" --output "$T/tiles" --tiles 2> "$T/err"
pt=$("$PSNR" "$T/tiles/cube_0000.exr" "$T/og/cube_0000.exr")
check "--tiles ~ strips ($pt dB): $(cat "$T/err")" awk -v p="$pt" 'BEGIN { exit !(p > 40) }'
"$LM" eval --model "$G" "$CAVE" --noise 0,10 --rainbow 0 --split all --output "$T/ev" > "$T/evlog" 2>&1
check "eval of the guided interpolation: $(cat "$T/evlog")" [ -s "$T/ev/eval.json" ]
e2=$(awk -F, 'NR == 2 { print $0 }' "$T/ev/eval.csv")
check "eval table has a row ($e2)" [ -n "$e2" ]

# ---- bad input ---------------------------------------------------------------------------
expect_error "even interpolation window" 2 "window N must be odd" "$T/e1" -- \
  "$LM" train --model lmmse-7-ri12-b2 $FIT --output "$T/e1"
expect_error "interpolation window too large" 2 "window N must be odd, 3..31" "$T/e2" -- \
  "$LM" train --model lmmse-7-ri33-b2 $FIT --output "$T/e2"
mkdir -p "$T/lone" && cp "$S/frames/frame_0000.png" "$T/lone/f.png"
expect_error "without bucket 0" 2 "give --bucket0" "$T/e3" -- \
  "$LM" infer --model "$G" --input "$T/lone/f.png" --output "$T/e3"
expect_error "photons for the closed-form fit" 2 "Gaussian noise only" "$T/e4" -- \
  "$LM" train --model lmmse-7-ri11-b2 $FIT --photons 1000 --output "$T/e4"
# on an OpenCL device (when a platform exists): the features on the host, the rest on the
# device; the same cube and the same scores as on the CPU
if ! command -v clinfo > /dev/null || clinfo -l 2> /dev/null | grep -q 'Platform'; then
  "$LM" infer --model "$G" --input "$S/frames" --output "$T/ocl" --device opencl 2> "$T/cl"
  check "infer on OpenCL: $(cat "$T/cl")" \
    bash -c "[ -s '$T/ocl/cube_0000.exr' ] && grep -q '^device: ' '$T/cl'"
  pc=$("$PSNR" "$T/ocl/cube_0000.exr" "$T/og/cube_0000.exr")
  check "OpenCL cube = CPU cube ($pc dB)" awk -v p="$pc" 'BEGIN { exit !(p > 80) }'
  # a residual network on the guided floor, scored on both devices
  "$LM" train --model rt-8-b2 --base "$G" --data "$CAVE" --iterations 2 --batch 2 \
    --patch 24x32 --val-patches 1 --quiet --output "$T/res" > "$T/log" 2>&1
  check "a residual on the guided floor: $(cat "$T/log")" [ -s "$T/res/model.safetensors" ]
  for d in cpu opencl; do
    "$LM" eval --model "$T/res" "$CAVE" --split all --noise 0,10 --rainbow 0 --device $d \
      --output "$T/ev_$d" > /dev/null 2> "$T/cl_$d"
    check "eval of the residual on $d: $(cat "$T/cl_$d")" [ -s "$T/ev_$d/eval.csv" ]
  done
  check "OpenCL scores = CPU scores: $(paste -d' ' "$T/ev_cpu/eval.csv" "$T/ev_opencl/eval.csv")" \
    awk -F, 'NR == FNR { p[FNR] = $3; next } FNR > 1 { d = $3 - p[FNR]; if (d < 0) d = -d;
             if (d > 0.001) bad = 1; n++ } END { exit bad || n != 4 }' \
    "$T/ev_cpu/eval.csv" "$T/ev_opencl/eval.csv"
fi
finish
