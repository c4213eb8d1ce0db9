#!/usr/bin/env bash
# names.sh — model names as the README and results tables write them: every preset-like name in
# the README (`rt-16`, `han-tiny+lmmse`, ...) is one `info --model` describes (NET+BASE: NET as a
# residual on BASE, the base's parameters counted); `info --list` gives every preset a purpose;
# `train --model NET+BASE` says how to train it (one line, exit 2); eval.json names the bundled
# demo residual "rt-16-nc+lmmse".
# usage: names.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
names=$(grep -oE '`(linear|lmmse|han|mcan|srnet|mst|qdo|rt|tn)[a-z0-9+-]*`' "$ROOT/README.md" |
        tr -d '`' | sort -u)
check "the README names presets" [ -n "$names" ]
for n in $names; do
  "$LM" info --model "$n" > "$T/info" 2> "$T/err"
  check "README's $n: $(cat "$T/err")" [ $? -eq 0 ]
done
"$LM" info --list > "$T/list"
check "every listed preset has a purpose" awk 'NF == 0 { exit } NF < 3 { bad = 1 } END { exit bad }' "$T/list"
check "the list names NET+BASE" grep -q 'NET+BASE (e.g. tn-160-nc+lmmse' "$T/list"
total() { "$LM" info --model "$1" | awk '/model parameters:/ {
  for (i = 2; i <= NF; i++) if ($(i - 1) == "model" && $i == "parameters:") print $(i + 1) }'; }
net=$(total rt-16-nc)
res=$(total rt-16-nc+lmmse)
base=$(total lmmse)
check "rt-16-nc+lmmse counts the base's parameters ($net + $base = $res)" [ -n "$res" ] && \
  [ "$((net + base))" -le "$((res))" ] && [ "$res" -le $((net + base + 64)) ]
expect_error "train NET+BASE" 2 "--model rt-16-nc --base RUN" "$T/e1" -- \
  "$LM" train --model rt-16-nc+lmmse --data "$CAVE" --iterations 1 --output "$T/e1"
"$LM" eval --model "$ROOT/models/demo/rt16nc-lmmse.safetensors" "$CAVE" --split all --noise 0 \
  --rainbow 0 --output "$T/ev" > /dev/null 2> "$T/err"
check "eval: $(cat "$T/err")" [ -s "$T/ev/eval.json" ]
check "eval.json names the residual" grep -q '"preset": "rt-16-nc+lmmse"' "$T/ev/eval.json"
finish
