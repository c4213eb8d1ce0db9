#!/usr/bin/env bash
# readers.sh — end-to-end tests of cubes on other wavelength grids (docs/guide/training.md "Readers that
# resample"): a KAUST-like .mat (34 bands of 12-bit counts), a 61-band 5 nm EXR and a .mat with
# two cube variables go through `simulate` and `render`; --mat-key picks a variable, a wrong key
# lists the file's variables, a cube narrower than 420-680 nm and a bad sidecar are refused
# (exit 2, one line, nothing written); train reads them as scenes, and train and eval document
# --mat-key.
# usage: readers.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"

"$MK" "$T/kaust.mat" kaust 6 8 && "$MK" "$T/five.exr" fivenm 6 8 && "$MK" "$T/two.mat" twokeys 6 8 \
  && "$MK" "$T/good.exr" good 6 8 && "$MK" "$T/b20.exr" bands20 3 4 || fail "fixtures"

"$LM" simulate --input "$T/kaust.mat" --output "$T/sim_kaust" > "$T/log" 2>&1
check "simulate KAUST .mat: $(cat "$T/log")" [ -s "$T/sim_kaust/gt/gt_0000.exr" ]
"$LM" simulate --input "$T/five.exr" --output "$T/sim_five" > "$T/log" 2>&1
check "simulate 5 nm EXR: $(cat "$T/log")" [ -s "$T/sim_five/frames/frame_0000.png" ]
"$LM" render --input "$T/two.mat" --output "$T/cube.png" > /dev/null 2>&1
"$LM" render --input "$T/two.mat" --mat-key alt --output "$T/alt.png" > "$T/log" 2>&1
check "render --mat-key alt: $(cat "$T/log")" [ -s "$T/alt.png" ]
check_not "--mat-key alt reads the other variable" cmp -s "$T/cube.png" "$T/alt.png"
# train: a .mat variable chosen by --mat-key and a 5 nm EXR as scenes (at least one patch)
"$MK" "$T/two66.mat" twokeys 66 64 && "$MK" "$T/five66.exr" fivenm 66 64 || fail "fixtures (train)"
"$LM" train --data "$T/two66.mat" --data "$T/five66.exr" --mat-key alt --model linear \
  --iterations 1 --val-interval 0 --val-patches 2 --threads 1 --output "$T/run" > "$T/log" 2>&1
check "train on resampled scenes: $(tail -1 "$T/log")" [ -s "$T/run/model.safetensors" ]
check "config.json records mat_key" grep -q '"mat_key": "alt"' "$T/run/config.json"
expect_error "wrong key (train)" 2 "two66.mat: no variable 'nope'; the file holds: cube, alt" "$T/run2" \
  -- "$LM" train --data "$T/two66.mat" --mat-key nope --model linear --iterations 1 --output "$T/run2"
for c in simulate render eval train; do
  check "$c --help documents --mat-key" grep -q -- '--mat-key' <("$LM" $c --help)
done

expect_error "wrong key (render)" 2 "no variable 'nope'; the file holds: cube, alt" "$T/o.png" \
  -- "$LM" render --input "$T/two.mat" --mat-key nope --output "$T/o.png"
expect_error "wrong key (simulate)" 2 "no variable 'nope'; the file holds: cube, alt" "$T/o" \
  -- "$LM" simulate --input "$T/two.mat" --mat-key nope --output "$T/o"
expect_error narrow 2 "b20.exr: covers 400-590 nm; resampling to 400-700 nm needs at least 420-680 nm" \
  "$T/o.png" -- "$LM" render --input "$T/b20.exr" --output "$T/o.png"
cp "$T/good.exr" "$T/side.exr"
printf '400 410 420\n' > "$T/side.exr.wavelengths.txt"
expect_error "sidecar count" 2 "side.exr: its wavelength sidecar lists 3 wavelengths but the cube has 31 bands" \
  "$T/o.png" -- "$LM" render --input "$T/side.exr" --output "$T/o.png"
cp "$T/good.exr" "$T/dec.exr"
seq 700 -10 400 > "$T/dec.exr.wavelengths.txt"
expect_error "sidecar decreasing" 2 "dec.exr.wavelengths.txt: wavelengths are not increasing" \
  "$T/o.png" -- "$LM" render --input "$T/dec.exr" --output "$T/o.png"
finish
