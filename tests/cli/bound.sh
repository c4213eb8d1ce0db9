#!/usr/bin/env bash
# bound.sh — lumosaic bound on the real scenes: both maps scored on the test split with a
# plausible PSNR (the linear map within 3 dB of 44 dB, the clean oracle's figure), a noisier
# level scoring lower, one line per test scene whose mean is the table's; bad input: no DATA, a bad noise list, a missing path, a split without
# validation scenes to choose the ridge on.
# usage: bound.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
D=$SHARED/data
"$LM" bound "$D/cave" "$D/cave-256" --ridge 1e-7 --noise 0,20 > "$T/out" 2> "$T/err"
check "bound runs: $(cat "$T/err")" [ $? -eq 0 ]
cat "$T/out"
check "21 training scenes, 3 test scenes" grep -q "21 training scene(s).*3 test scene(s)" "$T/out"
lin0=$(awk '$1 == "linear" && $2 == 0 { print $3 }' "$T/out")
lin20=$(awk '$1 == "linear" && $2 == 20 { print $3 }' "$T/out")
quad0=$(awk '$1 == "quadratic" && $2 == 0 { print $3 }' "$T/out")
check "linear clean PSNR ${lin0:-none} dB near 44" awk -v p="${lin0:-0}" 'BEGIN { exit !(p > 41 && p < 47) }'
check "quadratic clean PSNR ${quad0:-none} dB plausible" awk -v p="${quad0:-0}" 'BEGIN { exit !(p > 38 && p < 50) }'
# each scored scene's line: the mean of their clean linear PSNR is the table's mean
scenes=$(grep -c '^  [a-z_0-9]*_256  .* / ' "$T/out")
check "3 per-scene lines, got $scenes" [ "$scenes" -eq 3 ]
mean=$(awk '/^per scene/ { on = 1; next } on && / \/ / { s += $2; n++ } END { if (n) printf "%.3f", s / n }' "$T/out")
check "per-scene mean ${mean:-none} = linear mean ${lin0:-none}" awk -v a="${mean:-0}" -v b="${lin0:-99}" 'BEGIN { d = a - b; exit !(d < 0.01 && d > -0.01) }'
check "noise lowers the bound (${lin20:-none} < ${lin0:-none})" awk -v a="${lin20:-99}" -v b="${lin0:-0}" 'BEGIN { exit !(a < b - 5) }'

expect_error "no DATA" 2 "no DATA given" "$T/none" -- "$LM" bound
expect_error "bad noise" 2 "--noise '5,x'" "$T/none" -- "$LM" bound "$D/cave" --noise 5,x
expect_error "missing path" 2 "no such file" "$T/none" -- "$LM" bound "$T/missing"
expect_error "no validation scenes" 2 "give --ridge" "$T/none" -- "$LM" bound "$D/cave"
finish
