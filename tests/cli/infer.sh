#!/usr/bin/env bash
# infer.sh — end-to-end tests of `lumosaic infer`: train a linear model briefly on the CAVE scene
# balloons_crop100, simulate its coded frame, reconstruct it (cube EXR + sRGB PNG written, PSNR
# against the simulated ground truth well above an untrained model's ~11 dB), a frame sequence
# (folder) with a progress line per frame, batch size does not change the output; temporal
# alignment of a sequence (on by default, timed in the progress line, off with --no-align or for
# a single frame; a still video is unchanged by it; on a translating video the aligned middle
# frame's cube is closer to the cube reconstructed from the still scene at its lime time, i.e.
# simulated from its ground truth, than the unaligned one; a frame's result depends only on
# its neighbours); bad input:
# missing model, not a model, model/system mismatch, frame too small, corrupt frame, used output
# folder, unknown option — one line on stderr, exit 2, no output left.
# usage: infer.sh LUMOSAIC MAKE_CUBE CUBE_PSNR
source "$(dirname "$0")/lib.sh"
PSNR=$3

R=$T/run
"$LM" train --model linear --data "$CAVE" --iterations 60 --batch 4 --accum-steps 1 --lr 5e-3 \
  --synth-fraction 0 --noise 0,0 --val-patches 1 --output "$R" --quiet > "$T/log" 2>&1
check "train: $(cat "$T/log")" [ -s "$R/model.safetensors" ]
"$LM" simulate --input "$CAVE" --output "$T/sim" --crop > "$T/log" 2>&1
check "simulate: $(cat "$T/log")" [ -s "$T/sim/frames/frame_0000.png" ]

# ---- happy path ------------------------------------------------------------------------
O=$T/out
"$LM" infer --model "$R" --input "$T/sim/frames/frame_0000.png" --output "$O" 2> "$T/err"
check "infer run: $(cat "$T/err")" [ $? -eq 0 ]
check "cube written" [ -s "$O/cube_0000.exr" ]
check "preview written" grep -q 'PNG' <(head -c 8 "$O/srgb_0000.png")
check "one progress line" [ "$(grep -c '^frame 1/1' "$T/err")" -eq 1 ]
check "no staging folder left" no_output "$O.tmp"
p=$("$PSNR" "$O/cube_0000.exr" "$T/sim/gt/gt_0000.exr")
echo "PSNR of the briefly trained linear model: $p dB"
check "PSNR $p dB is sane (> 18 dB)" awk -v p="$p" 'BEGIN { exit !(p > 18 && p < 80) }'
# the spectral EXR is readable by the cube reader and renders
"$LM" render --input "$O/cube_0000.exr" --output "$T/r.png" > /dev/null 2>&1
check "cube EXR reads back" [ -s "$T/r.png" ]
# the model file itself, batch 1: the same cube bit for bit
"$LM" infer --model "$R/model.safetensors" --input "$T/sim/frames/frame_0000.png" \
  --output "$T/b1" --batch 1 --no-align 2> /dev/null
check "batch 1 = batch 8" cmp -s "$O/cube_0000.exr" "$T/b1/cube_0000.exr"

# a sequence (folder of two frames)
"$LM" simulate --input "$CAVE" --output "$T/vid" --crop --video --frames 2 > /dev/null 2>&1
"$LM" infer --model "$R" --input "$T/vid/frames" --output "$T/seq" 2> "$T/err"
check "sequence run: $(cat "$T/err")" [ $? -eq 0 ]
for i in 0000 0001; do
  check "sequence cube $i" [ -s "$T/seq/cube_$i.exr" ] && check "sequence srgb $i" [ -s "$T/seq/srgb_$i.png" ]
done
check "progress line per frame" [ "$(grep -c '^frame [12]/2' "$T/err")" -eq 2 ]
check "sequence progress lines time the alignment" [ "$(grep -c '^frame [12]/2 .*(alignment [0-9.]* s,' "$T/err")" -eq 2 ]
check "single frame: no alignment" grep -q '^frame 1/1 .*(alignment off,' <(
  "$LM" infer --model "$R" --input "$T/sim/frames/frame_0000.png" --output "$T/single" 2>&1)
check "help describes alignment" grep -q 'lime-LED' <("$LM" infer --help)
"$LM" infer --model "$R" --input "$T/vid/frames" --output "$T/seqn" --no-align 2> "$T/err"
check "--no-align sequence: $(cat "$T/err")" [ $? -eq 0 ]
check "--no-align progress lines" [ "$(grep -c '^frame [12]/2 .*(alignment off,' "$T/err")" -eq 2 ]
for i in 0000 0001; do  # the simulator's default video is still: alignment changes ~nothing
  p=$("$PSNR" "$T/seq/cube_$i.exr" "$T/seqn/cube_$i.exr")
  check "still video $i: aligned ~ unaligned ($p dB)" awk -v p="$p" 'BEGIN { exit !(p > 60) }'
done

# temporal alignment on a translating scene (~5 px right, 2 px up per frame)
"$LM" simulate --input "$CAVE" --output "$T/mv" --crop --video --frames 3 \
  --motion translate:150,-60 > /dev/null 2>&1
"$LM" infer --model "$R" --input "$T/mv/frames" --output "$T/mva" 2> "$T/err"
check "moving sequence aligned: $(cat "$T/err")" [ $? -eq 0 ]
"$LM" infer --model "$R" --input "$T/mv/frames" --output "$T/mvn" --no-align 2> /dev/null
# the reference: frame 1's ground truth (the scene at its lime time) coded and reconstructed
"$LM" simulate --input "$T/mv/gt/gt_0001.exr" --output "$T/mvr" > /dev/null 2>&1
"$LM" infer --model "$R" --input "$T/mvr/frames/frame_0000.png" --output "$T/mvrc" 2> /dev/null
pa=$("$PSNR" "$T/mva/cube_0001.exr" "$T/mvrc/cube_0000.exr")
pn=$("$PSNR" "$T/mvn/cube_0001.exr" "$T/mvrc/cube_0000.exr")
echo "moving frame 1 vs lime-time reconstruction: aligned $pa dB, unaligned $pn dB"
check "alignment brings frame 1 closer ($pa vs $pn dB)" \
  awk -v a="$pa" -v n="$pn" 'BEGIN { exit !(a > n + 1) }'
# the sliding window of frames i-1, i, i+1: frame 3 of a 5-frame video aligned in the full
# sequence is bit-identical to the middle one of frames 2-4 on their own
"$LM" simulate --input "$CAVE" --output "$T/v5" --crop --video --frames 5 \
  --motion translate:150,-60 > /dev/null 2>&1
mkdir -p "$T/v3" && cp "$T"/v5/frames/frame_000[123].png "$T/v3/"
"$LM" infer --model "$R" --input "$T/v5/frames" --output "$T/v5o" 2> /dev/null
"$LM" infer --model "$R" --input "$T/v3" --output "$T/v3o" 2> /dev/null
check "5-frame sequence, frame 2 = middle of frames 1-3" cmp -s "$T/v5o/cube_0002.exr" "$T/v3o/cube_0001.exr"

# ---- noisy frames clipped at 0 -----------------------------------------------------------
# a 16-bit PNG of a noisy frame is clipped at 0: a model that records unclipped training
# samples gets one warning per run; not for a clean PNG, a float EXR (negatives kept), or a
# model trained on clipped samples too
"$LM" simulate --input "$CAVE" --output "$T/noisy" --crop --noise 0.1 > /dev/null 2>&1
"$LM" simulate --input "$CAVE" --output "$T/noisyx" --crop --noise 0.1 --format exr > /dev/null 2>&1
cp "$T/noisy/frames/frame_0000.png" "$T/noisy/frames/frame_0001.png"
"$LM" infer --model "$R" --input "$T/noisy/frames" --output "$T/cl" 2> "$T/err"
check "clipped noisy frames: one warning, the model named: $(cat "$T/err")" \
  [ "$(grep -c 'clipped at 0.*model linear was trained on unclipped samples' "$T/err")" -eq 1 ]
"$LM" infer --model "$R" --input "$T/sim/frames/frame_0000.png" --output "$T/cl2" 2> "$T/err"
check "clean frame: no clip warning" bash -c "! grep -q 'clipped at 0' '$T/err'"
"$LM" infer --model "$R" --input "$T/noisyx/frames/frame_0000.exr" --output "$T/cl3" 2> "$T/err"
check "float frame with negatives: no clip warning" bash -c "! grep -q 'clipped at 0' '$T/err'"
"$LM" train --model linear --data "$CAVE" --iterations 4 --batch 4 --accum-steps 1 \
  --synth-fraction 0 --clip-fraction 0.5 --val-patches 1 --output "$T/runc" --quiet > "$T/log" 2>&1
check "train --clip-fraction: $(cat "$T/log")" [ -s "$T/runc/model.safetensors" ]
"$LM" infer --model "$T/runc" --input "$T/noisy/frames/frame_0000.png" --output "$T/cl4" 2> "$T/err"
check "model trained on clipped samples: no clip warning" bash -c "! grep -q 'clipped at 0' '$T/err'"

# ---- bad input ---------------------------------------------------------------------------
F=$T/sim/frames/frame_0000.png
expect_error "missing model" 2 "no such model" "$T/e1" -- "$LM" infer --model "$T/nope" --input "$F" --output "$T/e1"
echo "not safetensors" > "$T/bogus.safetensors"
expect_error "not a model" 2 "bogus.safetensors" "$T/e2" -- "$LM" infer --model "$T/bogus.safetensors" --input "$F" --output "$T/e2"
SYS=$(grep -o '"path": "[^"]*default.json"' "$T/sim/simulate.json" | head -1 | cut -d'"' -f4)
python3 - "$SYS" "$T/other.json" <<'PY'  # another tile map: cannot be mapped onto the model's
import json, os, sys
d = os.path.dirname(os.path.abspath(sys.argv[1])); s = json.load(open(sys.argv[1]))
for l in s["leds"]: l["emission"]["csv"] = os.path.join(d, l["emission"]["csv"])
s["sensor"]["qe"]["csv"] = os.path.join(d, s["sensor"]["qe"]["csv"])
s["tile_map"][0][0], s["tile_map"][0][1] = s["tile_map"][0][1], s["tile_map"][0][0]
json.dump(s, open(sys.argv[2], "w"))
PY
expect_error "model/system mismatch" 2 "model/system mismatch" "$T/e3" -- "$LM" infer --model "$R" --input "$F" --system "$T/other.json" --output "$T/e3"
"$MK" "$T/small.exr" good 60 60
"$LM" simulate --input "$T/small.exr" --output "$T/small" > /dev/null 2>&1
"$LM" infer --model "$R" --input "$T/small/frames/frame_0000.png" --output "$T/s60" 2> "$T/err"
check "a 60 x 60 frame (below the 66 x 64 window): $(cat "$T/err")" [ -s "$T/s60/cube_0000.exr" ]
"$MK" "$T/tiny.exr" good 6 60
"$LM" simulate --input "$T/tiny.exr" --output "$T/tiny" > /dev/null 2>&1
check "a 6-row frame simulated" [ -s "$T/tiny/frames/frame_0000.png" ]
expect_error "frame too small" 2 "smaller than 3 x 3 mosaic tiles" "$T/e4" -- "$LM" infer --model "$R" --input "$T/tiny/frames/frame_0000.png" --output "$T/e4"
head -c 300 "$F" > "$T/corrupt.png"
expect_error "corrupt frame" 2 "corrupt.png" "$T/e5" -- "$LM" infer --model "$R" --input "$T/corrupt.png" --output "$T/e5"
expect_error "missing frames" 2 "nothing_here" "$T/e6" -- "$LM" infer --model "$R" --input "$T/nothing_here.png" --output "$T/e6"
expect_error "missing --model" 2 "--model is required" "$T/e7" -- "$LM" infer --input "$F" --output "$T/e7"
expect_error "unknown option" 2 "unknown option" "$T/e8" -- "$LM" infer --model "$R" --input "$F" --output "$T/e8" --bogus
expect_error "bad batch" 2 "--batch" "$T/e9" -- "$LM" infer --model "$R" --input "$F" --output "$T/e9" --batch 0
mkdir -p "$T/used" && touch "$T/used/x"
"$LM" infer --model "$R" --input "$F" --output "$T/used" > /dev/null 2> "$T/err"
check "used output folder refused (exit 2)" [ $? -eq 2 ]
check "used output folder untouched" [ "$(ls "$T/used")" = x ]

finish
