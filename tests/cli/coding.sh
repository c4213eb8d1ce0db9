#!/usr/bin/env bash
# coding.sh — `lumosaic coding` (issue 18, item 1) end to end on six real CAVE scenes (four
# train, one val, one test by the dataset's split): the learned allocation keeps the 158
# sub-frames (each LED >= 1), the learned map is a permutation of the 12 LEDs, neither scores
# worse than the paper's coding by the objective it optimised, both system files load in
# `simulate`, the report has every coding's val/test PSNR. Errors (one line, exit 2, nothing
# written): too few scenes for a test split, an even window, no --output.
# usage: coding.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
C256=$SHARED/data/cave-256
DATA=()
for s in cd clay egyptian_statue face fake_and_real_beers fake_and_real_food; do
  DATA+=(--data "$C256/${s}_256")
done
"$LM" coding "${DATA[@]}" --window 5 --adam-steps 40 --anneal 80 --rounds 1 --threads 2 \
  --quiet --output "$T/out" > "$T/table" 2> "$T/err"
check "coding: $(cat "$T/err")" [ $? -eq 0 -a -s "$T/out/allocation.json" -a -s "$T/out/tilemap.json" -a -s "$T/out/report.json" ]
check "the table names three codings" [ "$(grep -cE '^(paper|learned_allocation|learned_map) ' "$T/table")" -eq 3 ]
python3 - "$T" <<'PY'
import json, math, sys
T = sys.argv[1]
r = json.load(open(T + "/out/report.json"))
c = r["codings"]
assert set(c) == {"paper", "learned_allocation", "learned_map"}, c.keys()
for k, v in c.items():
    s = v["subframes"]
    assert sum(s.values()) == 158 and min(s.values()) >= 1, (k, s)
    names = [n for row in v["tile_map"] for n in row]
    assert sorted(names) == sorted(s), (k, names)
    assert math.isfinite(v["val_psnr"]) and math.isfinite(v["test_psnr"]), v
    assert len(v["scene_psnr"]) == 2, v["scene_psnr"]  # the val and the test scene
assert c["learned_allocation"]["proxy_psnr"] >= c["paper"]["proxy_psnr"] - 1e-9
assert c["learned_map"]["proxy_psnr"] >= c["learned_allocation"]["proxy_psnr"] - 1e-9
assert c["paper"]["subframes"]["Amber"] == 40
for f in ("allocation", "tilemap"):
    s = json.load(open(T + "/out/%s.json" % f))
    assert sum(l["subframes"] for l in s["leds"]) == 158 and s["subframes_total"] == 158
    assert len(s["gains"]) == 12 and "learned" in s["name"]
PY
check "report and system files" [ $? -eq 0 ]
"$LM" simulate --input "$C256/cd_256" --crop --system "$T/out/tilemap.json" --poisson 2000 \
  --read-noise 13 --output "$T/sim" > /dev/null 2> "$T/err"
check "simulate accepts the learned system: $(cat "$T/err")" [ $? -eq 0 -a -d "$T/sim/frames" ]
expect_error "three scenes: no test split" 2 "test scenes" "$T/e1" -- \
  "$LM" coding --data "$SHARED/data/cave" --output "$T/e1"
expect_error "even window" 2 "odd" "$T/e2" -- "$LM" coding "${DATA[@]}" --window 4 --output "$T/e2"
expect_error "no output" 2 "--output" "$T/e3" -- "$LM" coding "${DATA[@]}"
finish
