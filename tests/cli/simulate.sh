#!/usr/bin/env bash
# simulate.sh — end-to-end tests of `lumosaic simulate` on the real CAVE scene balloons_crop100,
# the happy path: static with bucket 0, every frame format, video, determinism per seed, the
# written ground truth reproduces the frame, a still video equals the static frame, an empty
# output folder is filled (bad input: simulate_errors.sh).
# usage: simulate.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"

# ---- happy path ------------------------------------------------------------------------
O=$T/static
"$LM" simulate --input "$CAVE" --output "$O" --crop --bucket0 > "$T/log" 2>&1
check "static run: $(cat "$T/log")" [ $? -eq 0 ]
for f in frames/frame_0000.png bucket0/frame_0000.png gt/gt_0000.exr gt/gt_0000.png simulate.json; do
  check "static: $f written" [ -s "$O/$f" ]
done
check "static: no staging folder left" no_output "$O.tmp"
check "static: summary has the cropped size" grep -qz '"size_hw": \[\s*99,\s*100\s*\]' "$O/simulate.json"
check "static: summary names the frame" grep -q '"coded": "frames/frame_0000.png"' "$O/simulate.json"
check "static: summary has the seed" grep -q '"seed": 1,' "$O/simulate.json"
# the ground truth EXR is the cropped scene: simulating it again gives the same coded frame
"$LM" simulate --input "$O/gt/gt_0000.exr" --output "$T/again" > /dev/null
check "gt reproduces the frame" cmp -s "$O/frames/frame_0000.png" "$T/again/frames/frame_0000.png"
check "the preview is an 8-bit RGB PNG" grep -q 'PNG' <(head -c 8 "$O/gt/gt_0000.png")

# noise: the same seed gives the same frame, another seed another one
"$LM" simulate --input "$CAVE" --output "$T/n1" --crop --noise 0.05 --poisson 2000 --seed 7 > /dev/null
"$LM" simulate --input "$CAVE" --output "$T/n2" --crop --noise 0.05 --poisson 2000 --seed 7 --threads 1 > /dev/null
"$LM" simulate --input "$CAVE" --output "$T/n3" --crop --noise 0.05 --poisson 2000 --seed 8 > /dev/null
check "same seed, same noise" cmp -s "$T/n1/frames/frame_0000.png" "$T/n2/frames/frame_0000.png"
check_not "other seed, other noise" cmp -s "$T/n1/frames/frame_0000.png" "$T/n3/frames/frame_0000.png"
check_not "noise changes the frame" cmp -s "$T/n1/frames/frame_0000.png" "$O/frames/frame_0000.png"

for fmt in tiff:tif exr:exr; do
  "$LM" simulate --input "$CAVE" --output "$T/f_${fmt%%:*}" --crop --format="${fmt%%:*}" > /dev/null
  check "format ${fmt%%:*}" [ -s "$T/f_${fmt%%:*}/frames/frame_0000.${fmt##*:}" ]
done

# video: numbered frames, the scene moves, and a still video equals the static frame
V=$T/video
"$LM" simulate --input "$CAVE" --output "$V" --crop --video --frames 3 --samples 2 \
  --motion translate:300,-100 --motion region:ellipse,50,50,30,20,0,400 > "$T/log" 2>&1
check "video run: $(cat "$T/log")" [ $? -eq 0 ]
for i in 0 1 2; do
  check "video frame $i" [ -s "$V/frames/frame_000$i.png" ] && check "video gt $i" [ -s "$V/gt/gt_000$i.exr" ]
done
check_not "video: the scene moves" cmp -s "$V/frames/frame_0000.png" "$V/frames/frame_0002.png"
check "video: ground-truth times recorded" grep -q '"gt_time_us": 45033' "$V/simulate.json"
"$LM" simulate --input "$CAVE" --output "$T/still" --crop --video --frames 2 > /dev/null
check "still video = static" cmp -s "$T/still/frames/frame_0001.png" "$O/frames/frame_0000.png"
check "help documents --motion" grep -q -- '--motion SPEC' <("$LM" simulate --help)

# an empty output folder may be used
mkdir "$T/empty"
"$LM" simulate --input "$CAVE" --output "$T/empty" --crop > /dev/null
check "empty output folder filled" [ -s "$T/empty/frames/frame_0000.png" ]

finish
