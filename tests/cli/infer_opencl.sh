#!/usr/bin/env bash
# infer_opencl.sh — `lumosaic infer` and `lumosaic eval` with --device opencl against the CPU:
# a briefly trained linear model and a few-iteration mcan-tiny (convolutions, attention) each
# reconstruct the same simulated frame on both devices — the cubes agree (max abs difference
# <= 1e-4); LM_DEVICE=opencl selects the device without the option (a "device:" line names
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

for m in linear mcan-tiny; do
  it=60; [ $m = linear ] || it=3
  "$LM" train --model $m --data "$CAVE" --iterations $it --batch 2 --accum-steps 1 --lr 5e-3 \
    --synth-fraction 0 --noise 0,0 --val-patches 1 --output "$T/run_$m" --quiet > "$T/log" 2>&1
  check "train $m: $(cat "$T/log")" [ -s "$T/run_$m/model.safetensors" ]
  # --tiles: on the cpu, linear would run on the whole frame (infer/whole.c, host-only); the
  # device runs windows, so compare window against window
  "$LM" infer --model "$T/run_$m" --input "$F" --output "$T/cpu_$m" --device cpu --tiles 2> "$T/err"
  check "$m infer cpu: $(cat "$T/err")" [ $? -eq 0 ]
  "$LM" infer --model "$T/run_$m" --input "$F" --output "$T/cl_$m" --device opencl 2> "$T/err"
  check "$m infer opencl: $(cat "$T/err")" [ $? -eq 0 ]
  check "$m: opencl names its device" grep -q '^device: ' "$T/err"
  d=$("$DIFF" "$T/cpu_$m/cube_0000.exr" "$T/cl_$m/cube_0000.exr")
  echo "$m: max |cpu - opencl| = $d"
  check "$m: cpu and opencl cubes agree (max abs diff $d <= 1e-4)" \
    awk -v d="$d" 'BEGIN { exit !(d != "" && d <= 1e-4) }'
done

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
