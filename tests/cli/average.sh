#!/usr/bin/env bash
# average.sh — end-to-end tests of `lumosaic average`: the bundled model averaged with itself is
# the same model (its reconstruction of a simulated frame is byte-identical), the output runs
# with infer and records its inputs, and bad input: exit status, one-line message, nothing
# written.
# usage: average.sh LUMOSAIC MAKE_CUBE CUBE_DIFF
source "$(dirname "$0")/lib.sh"
DIFF=$3
REPO=$(cd "$(dirname "$0")/../.." && pwd)
M1=$REPO/models/demo/tn160nc-lmmse.safetensors
M2=$REPO/models/demo/tn96nc-b2-lmmseb2.safetensors

"$LM" average --output "$T/self.safetensors" "$M1" "$M1" > "$T/log" 2>&1
check "average a model with itself: $(cat "$T/log")" [ $? -eq 0 ]
check "says what it wrote" grep -q "averaged 2 models into $T/self.safetensors" "$T/log"
# each input as path@iteration (a model that is itself an average has no iteration: path)
check "records its inputs" \
  grep -aqE '"average_of":"[^"]*tn160nc-lmmse.safetensors(@[0-9]+)?,' "$T/self.safetensors"
"$LM" simulate --input "$CAVE" --output "$T/sim" --crop > /dev/null 2>&1
F=$T/sim/frames/frame_0000.png
"$LM" infer --model "$M1" --input "$F" --output "$T/a" --threads 1 > /dev/null 2>&1
"$LM" infer --model "$T/self.safetensors" --input "$F" --output "$T/b" --threads 1 > /dev/null 2>&1
check "infer with the average" [ -s "$T/b/cube_0000.exr" ]
check "a model averaged with itself reconstructs the same cube" [ "$("$DIFF" "$T/a/cube_0000.exr" "$T/b/cube_0000.exr")" = 0 ]
check "help names the output" grep -q -- '--output FILE' <("$LM" average --help)

A="$LM average"
O=$T/o.safetensors
expect_error "one model" 2 "give at least two models" "$O" -- $A --output "$O" "$M1"
expect_error "no output" 2 "--output is required" "$O" -- $A "$M1" "$M1"
expect_error "output format" 2 "o.bin: the output is a .safetensors file" "$T/o.bin" -- $A --output "$T/o.bin" "$M1" "$M1"
expect_error "unknown option" 2 "unknown option '--weights'" "$O" -- $A --output "$O" --weights 1,2 "$M1" "$M1"
expect_error "other presets" 2 "only models of one preset" "$O" -- $A --output "$O" "$M1" "$M2"
expect_error "missing model" 2 "no such model" "$O" -- $A --output "$O" "$M1" "$T/nope"
expect_error "output folder missing" 1 "cannot write" "$T/no/o.safetensors" -- $A --output "$T/no/o.safetensors" "$M1" "$M1"
finish
