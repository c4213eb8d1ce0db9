#!/usr/bin/env bash
# simulate_errors.sh — end-to-end tests of `lumosaic simulate` on bad input (missing, truncated
# and corrupt cubes, wrong band counts, NaN / negative values, unknown formats, invalid system
# files, sizes that are not a multiple of the tile, unknown options, out-of-range numbers, an
# unusable output): exit status 2 (1 for an output folder that cannot be created, as for every
# command), one line on stderr naming the file and problem, and no partial output left behind.
# usage: simulate_errors.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"

# ---- bad input ---------------------------------------------------------------------------
B=$T/bad
cp -r "$CAVE" "$T/trunc"; head -c 700 "$CAVE/balloons_crop100_ms_05.png" > "$T/trunc/balloons_crop100_ms_05.png"
cp -r "$CAVE" "$T/corrupt"; echo garbage > "$T/corrupt/balloons_crop100_ms_07.png"
cp -r "$CAVE" "$T/bands30"; rm "$T/bands30/balloons_crop100_ms_31.png"
echo garbage > "$T/garbage.exr"
echo hello > "$T/cube.xyz"
"$MK" "$T/nan.exr" nan 3 4 && "$MK" "$T/neg.exr" negative 3 4 && "$MK" "$T/b20.exr" bands20 3 4 \
  && "$MK" "$T/odd.exr" good 5 4 \
  && "$MK" "$T/tiny.exr" good 2 3 || fail "fixtures"
echo '{"version": 1,' > "$T/sys_syntax.json"
echo '{"version": 1, "subframe_us": 150}' > "$T/sys_field.json"

S="$LM simulate --output $B"
expect_error missing 2 "$T/nope: no such file" "$B" -- $S --input "$T/nope"
expect_error truncated 2 "ms_05.png: truncated" "$B" -- $S --input "$T/trunc" --crop
expect_error corrupt 2 "ms_07.png: cannot read image" "$B" -- $S --input "$T/corrupt" --crop
expect_error corrupt-exr 2 "garbage.exr: not a readable OpenEXR" "$B" -- $S --input "$T/garbage.exr"
expect_error "band count (CAVE)" 2 "found 30 of 31 bands" "$B" -- $S --input "$T/bands30" --crop
expect_error "band count (EXR)" 2 "b20.exr: covers 400-590 nm; resampling to 400-700 nm needs at least 420-680 nm" "$B" -- $S --input "$T/b20.exr"
expect_error nan 2 "nan.exr: band 4 (430.0 nm) has NaN" "$B" -- $S --input "$T/nan.exr"
expect_error negative 2 "neg.exr: band 6 (450.0 nm) has a negative value" "$B" -- $S --input "$T/neg.exr"
expect_error "unknown input format" 2 "cube.xyz: unknown cube format" "$B" -- $S --input "$T/cube.xyz"
expect_error "unknown frame format" 2 "--format: unknown value 'bmp'" "$B" -- $S --input "$CAVE" --format bmp
expect_error "system syntax" 2 "system file $T/sys_syntax.json" "$B" -- $S --input "$CAVE" --crop --system "$T/sys_syntax.json"
expect_error "system field" 2 "sys_field.json: sensor: missing" "$B" -- $S --input "$CAVE" --crop --system "$T/sys_field.json"
expect_error "system missing" 2 "system file $T/nope.json: cannot open" "$B" -- $S --input "$CAVE" --system "$T/nope.json"
expect_error "not a tile multiple" 2 "size 100 x 100 (H x W) is not a multiple of the 3 x 4 tile (--crop crops it to 99 x 100)" "$B" -- $S --input "$CAVE"
expect_error "smaller than a tile" 2 "smaller than the 3 x 4 tile" "$B" -- $S --input "$T/tiny.exr" --crop
expect_error "odd size" 2 "odd.exr: size 5 x 4" "$B" -- $S --input "$T/odd.exr"
expect_error "unknown option" 2 "unknown option '--bogus'" "$B" -- $S --input "$CAVE" --bogus
expect_error "noise range" 2 "--noise: 2 is out of range (0..1)" "$B" -- $S --input "$CAVE" --noise 2
expect_error "bits range" 2 "--bits: 30 is out of range (1..24)" "$B" -- $S --input "$CAVE" --bits 30
expect_error "seed range" 2 "--seed: -1 is out of range" "$B" -- $S --input "$CAVE" --seed -1
expect_error "frames range" 2 "--frames: 0 is out of range (1..10000)" "$B" -- $S --input "$CAVE" --video --frames 0
expect_error "poisson not a number" 2 "--poisson: 'lots' is not a finite number" "$B" -- $S --input "$CAVE" --poisson lots
expect_error "read noise nan" 2 "--read-noise: 'nan' is not a finite number" "$B" -- $S --input "$CAVE" --read-noise nan
expect_error "threads" 2 "--threads: 'abc' is not an integer" "$B" -- $S --input "$CAVE" --threads abc
expect_error "missing value" 2 "--seed needs a value" "$B" -- $S --input "$CAVE" --seed
expect_error "flag with value" 2 "--crop takes no value" "$B" -- $S --input "$CAVE" --crop=yes
expect_error "motion syntax" 2 "--motion: invalid 'spin:3'" "$B" -- $S --input "$CAVE" --video --motion spin:3
expect_error "zoom range" 2 "--motion: invalid 'zoom:-100'" "$B" -- $S --input "$CAVE" --video --motion zoom:-100
expect_error "region size" 2 "--motion: invalid 'region:rect,5,5,0,3,1,1'" "$B" -- $S --input "$CAVE" --video --motion region:rect,5,5,0,3,1,1
expect_error "motion without video" 2 "need --video" "$B" -- $S --input "$CAVE" --motion translate:1,2
expect_error "no input" 2 "--input is required" "$B" -- $S
expect_error "no output" 2 "--output is required" "$B" -- "$LM" simulate --input "$CAVE"
expect_error "output parent missing" 1 "cannot create a folder" "$T/no/such/dir" -- "$LM" simulate --input "$CAVE" --crop --output "$T/no/such/dir"
# an output that exists and is not empty is refused and left untouched
mkdir "$T/full" && echo keep > "$T/full/note.txt"
expect_error "output exists" 2 "full: output already exists" "$T/none" -- "$LM" simulate --input "$CAVE" --crop --output "$T/full"
wait
check "existing output untouched" [ "$(ls -A "$T/full")" = note.txt ]
finish
