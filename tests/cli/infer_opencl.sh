#!/usr/bin/env bash
# infer_opencl.sh — `lumosaic infer` and `lumosaic eval` with --device opencl against the CPU:
# a briefly trained linear model, a few-iteration rt-8 (whole frame in strips, and windows with
# --tiles) and mcan-tiny (convolutions, attention; windows) each reconstruct the same simulated
# frame on both devices — the cubes agree (max abs difference <= 1e-4), and so does
# `--model auto` over the three; LM_DEVICE=opencl selects the device without the option (a "device:" line names
# it); eval's metrics agree (PSNR within 1e-3 dB, incl. a --motion row); an unknown device is
# refused (one line, exit 2, no output left). Exits 77 (skipped) only when no OpenCL platform
# exists (`clinfo -l` lists none).
# usage: infer_opencl.sh LUMOSAIC MAKE_CUBE CUBE_DIFF
if command -v clinfo > /dev/null && ! clinfo -l 2> /dev/null | grep -q 'Platform'; then
  echo "no OpenCL platform: skipped"
  exit 77
fi
source "$(dirname "$0")/lib.sh"
DIFF=$3

"$LM" simulate --input "$CAVE" --output "$T/sim" --crop > "$T/log" 2>&1
check "simulate: $(cat "$T/log")" [ -s "$T/sim/frames/frame_0000.png" ]
F=$T/sim/frames/frame_0000.png

# linear and rt-8 run on the whole frame in strips (infer/whole.c) on both devices, and also
# in windows with --tiles; mcan-tiny (global attention) runs in windows
for m in linear mcan-tiny rt-8; do
  it=60; [ $m = linear ] || it=3
  "$LM" train --model $m --data "$CAVE" --iterations $it --batch 2 --accum-steps 1 --lr 5e-3 \
    --synth-fraction 0 --noise 0,0 --val-patches 1 --output "$T/run_$m" --quiet > "$T/log" 2>&1
  check "train $m: $(cat "$T/log")" [ -s "$T/run_$m/model.safetensors" ]
  for tiles in "" --tiles; do
    [ -n "$tiles" ] && [ $m = mcan-tiny ] && continue
    "$LM" infer --model "$T/run_$m" --input "$F" --output "$T/cpu_$m$tiles" --device cpu $tiles \
      2> "$T/err"
    check "$m infer cpu $tiles: $(cat "$T/err")" [ $? -eq 0 ]
    "$LM" infer --model "$T/run_$m" --input "$F" --output "$T/cl_$m$tiles" --device opencl \
      $tiles 2> "$T/err"
    check "$m infer opencl $tiles: $(cat "$T/err")" [ $? -eq 0 ]
    check "$m: opencl names its device" grep -q '^device: ' "$T/err"
    d=$("$DIFF" "$T/cpu_$m$tiles/cube_0000.exr" "$T/cl_$m$tiles/cube_0000.exr")
    echo "$m $tiles: max |cpu - opencl| = $d"
    check "$m $tiles: cpu and opencl cubes agree (max abs diff $d <= 1e-4)" \
      awk -v d="$d" 'BEGIN { exit !(d != "" && d <= 1e-4) }'
  done
done
# the strips really ran on the device: the whole-frame and window results differ (window
# borders), and the device matched the cpu's whole-frame result above
d=$("$DIFF" "$T/cpu_rt-8/cube_0000.exr" "$T/cpu_rt-8--tiles/cube_0000.exr")
check "rt-8: strips and windows differ ($d), so opencl ran strips" \
  awk -v d="$d" 'BEGIN { exit !(d != "" && d > 1e-3) }'

# --model auto on both devices: every model's parameters on the device, windows per model
"$LM" fit-auto --models "$T/run_linear,$T/run_mcan-tiny,$T/run_rt-8" --synth 2 \
  --synth-size 132x128 --bins 2 --threads 1 --output "$T/auto.json" > /dev/null 2> "$T/err"
check "fit-auto: $(cat "$T/err")" [ $? -eq 0 ]
for dev in cpu opencl; do
  "$LM" infer --model auto --auto "$T/auto.json" --auto-tol 0 --input "$F" \
    --output "$T/auto_$dev" --device $dev > /dev/null 2> "$T/err"
  check "infer --model auto --device $dev: $(cat "$T/err")" [ $? -eq 0 ]
done
d=$("$DIFF" "$T/auto_cpu/cube_0000.exr" "$T/auto_opencl/cube_0000.exr")
echo "auto: max |cpu - opencl| = $d"
check "auto: cpu and opencl cubes agree (max abs diff $d <= 1e-4)" \
  awk -v d="$d" 'BEGIN { exit !(d != "" && d <= 1e-4) }'

# LM_DEVICE picks the device when --device is not given
LM_DEVICE=opencl "$LM" infer --model "$T/run_linear" --input "$F" --output "$T/env" 2> "$T/err"
check "LM_DEVICE=opencl: $(cat "$T/err")" grep -q '^device: ' "$T/err"
d=$("$DIFF" "$T/cpu_linear/cube_0000.exr" "$T/env/cube_0000.exr")
check "LM_DEVICE=opencl cube agrees ($d)" awk -v d="$d" 'BEGIN { exit !(d != "" && d <= 1e-4) }'

# eval on both devices: the same metrics
for dev in cpu opencl; do
  "$LM" eval --model "$T/run_linear" "$CAVE" --split all --noise 0,10 --rainbow 96 --motion 120 \
    --device $dev --output "$T/ev_$dev" > /dev/null 2> "$T/err"
  check "eval --device $dev: $(cat "$T/err")" [ $? -eq 0 ]
done
python3 - "$T/ev_cpu/eval.json" "$T/ev_opencl/eval.json" <<'PY'
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
for ra, rb in zip(a["mean"], b["mean"]):
    assert abs(ra["psnr"] - rb["psnr"]) < 1e-3 and abs(ra["sam"] - rb["sam"]) < 1e-2, (ra, rb)
ma, mb = a["motion_mean"][0], b["motion_mean"][0]
for k in ("psnr_aligned", "psnr_unaligned"):
    assert abs(ma[k] - mb[k]) < 1e-3, (ma, mb)
assert abs(a["rainbow"]["psnr"] - b["rainbow"]["psnr"]) < 1e-3, (a["rainbow"], b["rainbow"])
print("eval cpu vs opencl: PSNR(0) %.4f / %.4f dB, motion aligned %.4f / %.4f dB"
      % (a["mean"][0]["psnr"], b["mean"][0]["psnr"], ma["psnr_aligned"], mb["psnr_aligned"]))
PY
check "eval metrics agree between cpu and opencl" [ $? -eq 0 ]

expect_error "unknown device" 2 "device" "$T/e1" -- "$LM" infer --model "$T/run_linear" --input "$F" --output "$T/e1" --device gpu9
expect_error "eval unknown device" 2 "device" "$T/e2" -- "$LM" eval --model "$T/run_linear" "$CAVE" --split all --device gpu9 --output "$T/e2"
finish
