#!/usr/bin/env bash
# render.sh — end-to-end tests of `lumosaic render`: a CAVE scene and a spectral EXR to sRGB PNG
# (exposure changes the image), and bad input: exit status, one-line message, nothing written.
# usage: render.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"

"$LM" render --input "$CAVE" --output "$T/a.png" > "$T/log" 2>&1
check "render CAVE: $(cat "$T/log")" [ $? -eq 0 ]
check "PNG written" grep -q 'PNG' <(head -c 8 "$T/a.png")
"$LM" render --input "$CAVE" --output "$T/b.png" --exposure 0.5 > /dev/null
check_not "exposure changes the image" cmp -s "$T/a.png" "$T/b.png"
"$LM" render --input "$CAVE" --output "$T/c.png" --exposure=1 --threads 1 > /dev/null
check "same input, same image" cmp -s "$T/a.png" "$T/c.png"
"$MK" "$T/good.exr" good 6 8 && "$MK" "$T/nan.exr" nan 3 4 && "$MK" "$T/b20.exr" bands20 3 4 || fail "fixtures"
"$LM" render --input "$T/good.exr" --output "$T/good.png" > /dev/null
check "render EXR" [ -s "$T/good.png" ]
check "help documents --exposure" grep -q -- '--exposure X' <("$LM" render --help)

R="$LM render"
expect_error missing 2 "$T/nope.exr: no such file" "$T/o.png" -- $R --input "$T/nope.exr" --output "$T/o.png"
expect_error nan 2 "nan.exr: band 4 (430.0 nm) has NaN" "$T/o.png" -- $R --input "$T/nan.exr" --output "$T/o.png"
expect_error "output format" 2 "o.jpg: unknown output format" "$T/o.jpg" -- $R --input "$CAVE" --output "$T/o.jpg"
expect_error "exposure range" 2 "--exposure: 0 is out of range" "$T/o.png" -- $R --input "$CAVE" --output "$T/o.png" --exposure 0
expect_error "unknown option" 2 "unknown option '--gamma'" "$T/o.png" -- $R --input "$CAVE" --output "$T/o.png" --gamma 2
expect_error "no output" 2 "--output is required" "$T/o.png" -- $R --input "$CAVE"
expect_error "output folder missing" 1 "$T/no/o.png" "$T/no/o.png" -- $R --input "$CAVE" --output "$T/no/o.png"
finish
