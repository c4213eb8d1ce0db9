#!/usr/bin/env bash
# convert.sh — end-to-end tests of `lumosaic convert`: the bundled model stored as fp16 is half
# the file, keeps its metadata, reconstructs a simulated frame within fp16's rounding of the
# fp32 model's cube (and not bit for bit: the weights did change), and converts back and forth
# without drifting; bad input: exit status, one-line message, nothing written.
# usage: convert.sh LUMOSAIC MAKE_CUBE CUBE_PSNR
source "$(dirname "$0")/lib.sh"
PSNR=$3
REPO=$(cd "$(dirname "$0")/../.." && pwd)
M1=$REPO/models/demo/tn160nc-lmmse.safetensors

"$LM" convert --output "$T/h.safetensors" "$M1" > "$T/log" 2>&1
check "convert to fp16: $(cat "$T/log")" [ $? -eq 0 ]
check "says what it wrote" grep -q "wrote $T/h.safetensors (f16, " "$T/log"
check "reports the rounding" grep -qE 'largest relative change of a tensor [0-9.]+e-0[45]' "$T/log"
s32=$(stat -c %s "$M1") s16=$(stat -c %s "$T/h.safetensors")
half=$((s16 * 2 > s32 && s16 * 2 < s32 + 8192))
check "fp16 is about half the file ($s16 of $s32 bytes)" [ "$half" = 1 ]
check "tensors are F16" grep -aq '"dtype":"F16"' "$T/h.safetensors"
check_not "no F32 tensor left" grep -aq '"dtype":"F32"' "$T/h.safetensors"
for key in '"preset":"tn-160-nc"' '"base_preset":"lmmse' '"train_scenes":"'; do
  check "keeps $key" grep -aqF "$key" "$T/h.safetensors"
done
"$LM" convert --dtype f32 --output "$T/back.safetensors" "$T/h.safetensors" > /dev/null 2>&1
check "back to fp32: the training format's size" [ "$(stat -c %s "$T/back.safetensors")" = "$s32" ]
"$LM" convert --output "$T/again.safetensors" "$T/back.safetensors" > /dev/null 2>&1
check "fp16 -> fp32 -> fp16 is the same file" cmp -s "$T/h.safetensors" "$T/again.safetensors"

"$LM" simulate --input "$CAVE" --output "$T/sim" --crop > /dev/null 2>&1
F=$T/sim/frames/frame_0000.png
"$LM" infer --model "$M1" --input "$F" --output "$T/a" --threads 1 > /dev/null 2>&1
"$LM" infer --model "$T/h.safetensors" --input "$F" --output "$T/b" --threads 1 > "$T/ilog" 2>&1
check "infer with the fp16 model: $(tail -1 "$T/ilog")" [ -s "$T/b/cube_0000.exr" ]
p=$("$PSNR" "$T/b/cube_0000.exr" "$T/a/cube_0000.exr")
check "fp16's cube is the fp32 model's within rounding (PSNR $p dB between them, want > 70)" \
  awk -v p="$p" 'BEGIN { exit !(p > 70) }'
check "and not bit for bit (the weights changed)" awk -v p="$p" 'BEGIN { exit !(p < 200) }'
check "help names the storage types" grep -q -- '--dtype T' <("$LM" convert --help)
check "listed among the commands" grep -q '^  convert ' <("$LM" --help)

C="$LM convert"
O=$T/o.safetensors
cp "$M1" "$T/self.safetensors"
expect_error "no output" 2 "--output is required" "$O" -- $C "$M1"
expect_error "no model" 2 "give the model to convert" "$O" -- $C --output "$O"
expect_error "two models" 2 "one model at a time" "$O" -- $C --output "$O" "$M1" "$M1"
expect_error "output format" 2 "o.bin: the output is a .safetensors file" "$T/o.bin" -- $C --output "$T/o.bin" "$M1"
expect_error "bad dtype" 2 "--dtype" "$O" -- $C --output "$O" --dtype bf16 "$M1"
expect_error "unknown option" 2 "unknown option '--half'" "$O" -- $C --output "$O" --half "$M1"
expect_error "missing model" 2 "no such model" "$O" -- $C --output "$O" "$T/nope"
expect_error "output folder missing" 1 "cannot write" "$T/no/o.safetensors" -- $C --output "$T/no/o.safetensors" "$M1"
wait
"$LM" convert --output "$T/self.safetensors" "$T/self.safetensors" > /dev/null 2> "$T/self.err"
rc=$?
check "over its own input: refused, exit 2 ($rc: $(cat "$T/self.err"))" [ "$rc" -eq 2 ]
check "over its own input: says why" grep -q "is the model being converted" "$T/self.err"
check "the input is left as it was" cmp -s "$M1" "$T/self.safetensors"
finish
