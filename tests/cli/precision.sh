#!/usr/bin/env bash
# precision.sh — mixed precision in training: han-tiny (16-channel 3x3 convolutions on the
# Winograd path) trained 80 updates from the same seed in fp32 and in bf16; the run records its
# precision; the bf16 losses track the fp32 ones (mean of the last 20 within 10 %, both well
# below the first 10); a checkpoint trained in bf16 resumes in fp32 (fp32 weights); the fp32
# checkpoint scored by eval and run by infer in bf16 says which path it took, records it, and
# scores within 0.1 dB of fp32; a bad precision is one line, exit 2.
# usage: precision.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"

TR="--model han-tiny --data $CAVE --patch 24x32 --batch 2 --iterations 80 --val-patches 2 \
--threads 1 --seed 3 --lr 2e-3 --quiet"
for p in fp32 bf16; do
  "$LM" train $TR --precision $p --output "$T/$p" > "$T/log_$p" 2>&1
  check "train --precision $p: $(cat "$T/log_$p")" [ -s "$T/$p/model.safetensors" ]
  check "config records $p" grep -q "\"precision\": \"$p\"" "$T/$p/config.json"
done
# losses: rows with an iteration and a loss (validation rows too; their loss is the update's)
mean() { awk -F, -v a="$2" -v b="$3" 'NR > 1 && $1 >= a && $1 <= b { s += $2; n++ }
  END { if (n) printf "%.6f", s / n; else print "nan" }' "$1"; }
f_end=$(mean "$T/fp32/log.csv" 61 80); b_end=$(mean "$T/bf16/log.csv" 61 80)
f_start=$(mean "$T/fp32/log.csv" 1 10)
check "bf16 losses track fp32 (last 20: $b_end vs $f_end; first 10 $f_start)" \
  awk -v f="$f_end" -v b="$b_end" -v s="$f_start" \
  'BEGIN { d = b - f; if (d < 0) d = -d; exit !(d <= 0.1 * f && b < 0.8 * s && f < 0.8 * s) }'
check_not "bf16 and fp32 runs differ" cmp -s "$T/fp32/model.safetensors" "$T/bf16/model.safetensors"
"$LM" train --resume "$T/bf16" --precision fp32 --iterations 90 --quiet > "$T/log_r" 2>&1
check "a bf16 run resumes in fp32: $(cat "$T/log_r")" grep -q 'for 90 iterations' "$T/log_r"

for p in fp32 bf16; do
  "$LM" eval --model "$T/fp32" "$CAVE" --split all --noise 0,10 --rainbow 0 --threads 1 \
    --precision $p --output "$T/ev_$p" > "$T/ev_$p.log" 2>&1
  check "eval --precision $p: $(tail -1 "$T/ev_$p.log")" grep -q "\"precision\": \"$p\"" "$T/ev_$p/eval.json"
done
check "eval in bf16 says which path" grep -q "^precision: bf16 (" "$T/ev_bf16.log"
psnr() { awk -F, -v k="$2" 'NR > 1 && $1 == "mean" && $2 == k { print $3 }' "$1/eval.csv"; }
for k in 0 10; do
  pf=$(psnr "$T/ev_fp32" $k); pb=$(psnr "$T/ev_bf16" $k)
  check "eval at $k %: bf16 $pb dB within 0.1 dB of fp32 $pf dB" \
    awk -v f="$pf" -v b="$pb" 'BEGIN { d = b - f; if (d < 0) d = -d; exit !(f != "" && d <= 0.1) }'
done
"$LM" simulate --input "$CAVE" --output "$T/sim" --crop > "$T/sim.log" 2>&1
"$LM" infer --model "$T/fp32" --input "$T/sim/frames" --output "$T/inf" --threads 1 \
  --precision bf16 > "$T/inf.log" 2>&1
check "infer --precision bf16: $(tail -1 "$T/inf.log")" [ -s "$T/inf/cube_0000.exr" ]
check "infer says which path" grep -q "^precision: bf16 (" "$T/inf.log"
expect_error "infer: bad precision" 2 "--precision" "$T/e2" -- \
  "$LM" infer --model "$T/fp32" --input "$T/sim/frames" --output "$T/e2" --precision fp16

expect_error "bad precision" 2 "'precision': must be fp32 or bf16" "$T/e1" -- \
  "$LM" train $TR --precision fp16 --output "$T/e1"
finish
