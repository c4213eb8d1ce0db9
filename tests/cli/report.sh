#!/usr/bin/env bash
# report.sh — end-to-end tests of `lumosaic report` and `eval --report` (without a browser; the
# page in Chromium: report_browser.sh). A linear model trained briefly on balloons_crop100 is
# evaluated with --report (noise 0,10, rainbow 96): eval writes report.html, sample_recon.exr,
# sample_truth.exr, sample.json and rainbow.csv; the sample's metrics equal eval.json's row of
# that scene at 10 % (the same reconstruction), rainbow.csv has one row per rainbow row whose
# mean error is eval.json's; the page loads nothing from a network and embeds the eval results,
# both previews (PNGs of the scene's size), the cubes (PSNR of the embedded cubes = the one
# the per-band PSNRs give) and the rainbow rows; `lumosaic report DIR` writes the same bytes
# (deterministic); --max-side 32 box-averages the cube to 25 x 25; --report-noise 0 shows the
# 0 % row's reconstruction and --rainbow 0 leaves out rainbow.csv; an infer folder (simulate +
# infer) and a folder of known cubes (cli_make_cube: the embedded values are the cube's,
# --frame picks the file); bad input: no DIR, missing folder, neither kind of folder, corrupt
# eval.json, a sample file missing, a corrupt rainbow.csv, --max-side out of range, --frame
# missing or given for an eval folder, a non-.html output, an output folder that does not
# exist; eval --report without --output, --report-noise not a level — one line on stderr, the
# exit status, nothing left.
# usage: report.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
PYLIB=$(cd "$(dirname "$0")" && pwd)

R=$T/run
"$LM" train --model linear --data "$CAVE" --iterations 60 --batch 4 --accum-steps 1 --lr 5e-3 \
  --synth-fraction 0 --noise 0,0 --val-patches 1 --output "$R" --quiet > "$T/log" 2>&1
check "train: $(cat "$T/log")" [ -s "$R/model.safetensors" ]

# ---- eval --report -------------------------------------------------------------------------
O=$T/ev
"$LM" eval --model "$R" "$CAVE" --split all --noise 0,10 --rainbow 96 --output "$O" --report \
  > "$T/table" 2> "$T/err"
check "eval --report: $(cat "$T/err")" [ $? -eq 0 ]
for f in eval.json eval.csv report.html sample.json sample_recon.exr sample_truth.exr rainbow.csv; do
  check "eval --report wrote $f" [ -s "$O/$f" ]
done
check "no staging folder left" no_output "$O.tmp"
python3 - "$O" "$PYLIB" <<'PY'
import csv, json, math, sys
sys.path.insert(0, sys.argv[2])
import report_data as rd
O = sys.argv[1]
ev = json.load(open(O + "/eval.json"))
smp = json.load(open(O + "/sample.json"))
assert smp["scene"] == "balloons_crop100" and smp["noise_percent"] == 10, smp
row = [r for r in ev["scenes"][0]["results"] if r["noise_percent"] == 10][0]
for k in ("psnr", "ssim", "mae", "sam"):
    assert abs(smp["metrics"][k] - row[k]) <= 1e-5 * max(1, abs(row[k])), (k, smp, row)
rows = list(csv.DictReader(open(O + "/rainbow.csv")))
assert len(rows) == 96 and [int(r["row"]) for r in rows] == list(range(96)), len(rows)
err = [abs(float(r["recovered_nm"]) - float(r["true_nm"])) for r in rows]
assert abs(sum(err) / 96 - ev["rainbow"]["peak_error_mean_nm"]) < 0.01, (sum(err) / 96, ev["rainbow"])
assert abs(max(err) - ev["rainbow"]["peak_error_max_nm"]) < 0.01
assert float(rows[0]["true_nm"]) == 700 and abs(float(rows[95]["true_nm"]) - 400) < 1e-3

html = open(O + "/report.html", encoding="utf-8").read()
assert rd.no_network(html) is None, rd.no_network(html)
d = rd.load(O + "/report.html")
def same(a, b):  # the page keeps 7 significant digits
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(map(same, a, b))
    if isinstance(a, float) or isinstance(b, float):
        return abs(a - b) <= 1e-6 * max(1, abs(b))
    return a == b
assert d["kind"] == "eval" and same(d["eval"], ev) and same(d["sample"], smp), d.keys()
H, W = ev["scenes"][0]["height"], ev["scenes"][0]["width"]
assert (d["width"], d["height"]) == (W, H), (d["width"], d["height"])
assert rd.png_size(d["srgb"]) == (W, H) and rd.png_size(d["srgb_truth"]) == (W, H)
c = d["cube"]
assert c["block"] == 1 and (c["w"], c["h"]) == (W, H) and c["wl"] == list(range(400, 701, 10)), c["wl"]
rec, tru = rd.cube(d, "recon"), rd.cube(d, "truth")
bp = d["band_psnr"]
assert len(bp) == 31 and all(5 < p < 100 for p in bp), bp
# the embedded (16-bit) cubes give the PSNR that the per-band PSNRs (full precision) give
mse = [sum((rec[b][y][x] - tru[b][y][x]) ** 2 for y in range(H) for x in range(W)) / (H * W)
       for b in range(31)]
for b in (0, 15, 30):
    assert abs(-10 * math.log10(mse[b]) - bp[b]) < 0.02, (b, mse[b], bp[b])
total = -10 * math.log10(sum(10 ** (-p / 10) for p in bp) / 31)
assert total >= smp["metrics"]["psnr"] - 1e-6, (total, smp)  # negatives clamped: never worse
assert max(max(max(r) for r in band) for band in tru) > 0.99  # the scene normalised to max 1
rr = d["rainbow_rows"]
assert len(rr["true_nm"]) == 96 and abs(rr["recovered_nm"][5] - float(rows[5]["recovered_nm"])) < 1e-3
print("eval report: %d bytes, cube %d x %d" % (len(html), c["w"], c["h"]))
PY
check "eval --report: files agree with eval.json, page embeds them" [ $? -eq 0 ]

# ---- lumosaic report on the same folder: the same page ----------------------------------------
"$LM" report "$O" --output "$T/again.html" > "$T/out" 2> "$T/err"
check "report DIR: $(cat "$T/err")" [ $? -eq 0 ]
check "report prints what it wrote" grep -q "^report: $T/again.html (.* kB, .* s): eval scores, balloons_crop100 100 x 99 (cube 100 x 99) with truth, rainbow 96 rows$" "$T/out"
check "report DIR = eval --report's page (deterministic)" cmp -s "$O/report.html" "$T/again.html"
"$LM" report "$O" --max-side 32 --output "$T/small.html" > /dev/null 2> "$T/err"
python3 - "$T/small.html" "$PYLIB" <<'PY'
import sys
sys.path.insert(0, sys.argv[2])
import report_data as rd
d = rd.load(sys.argv[1])
c = d["cube"]
assert (c["block"], c["w"], c["h"]) == (4, 25, 25), (c["block"], c["w"], c["h"])
assert rd.png_size(d["srgb"]) == (100, 99)  # previews keep the full size
rd.cube(d, "truth")
PY
check "--max-side 32: a 25 x 25 cube of 4 x 4 blocks" [ $? -eq 0 ]
check "--max-side: a smaller page" [ "$(stat -c %s "$T/small.html")" -lt "$(stat -c %s "$T/again.html")" ]
# eval without --report: no sample, the page still shows the scores and the rainbow summary
"$LM" eval --model "$R" "$CAVE" --split all --noise 0,5 --rainbow 0 --output "$T/plain" \
  > /dev/null 2>&1
"$LM" report "$T/plain" > "$T/out" 2> "$T/err"
check "report of a plain eval folder: $(cat "$T/err")" grep -q "eval scores$" "$T/out"
check "no sample files without --report" [ ! -e "$T/plain/sample.json" ] && [ ! -e "$T/plain/rainbow.csv" ]

# --report-noise 0 and --rainbow 0: the sample at 0 %, no rainbow.csv
"$LM" eval --model "$R" "$CAVE" --split all --noise 0,5 --rainbow 0 --output "$T/ev0" --report \
  --report-noise 0 > /dev/null 2> "$T/err"
check "eval --report --report-noise 0: $(cat "$T/err")" [ -s "$T/ev0/report.html" ]
check "--rainbow 0: no rainbow.csv" [ ! -e "$T/ev0/rainbow.csv" ]
python3 - "$T/ev0" "$PYLIB" <<'PY'
import json, sys
sys.path.insert(0, sys.argv[2])
import report_data as rd
ev = json.load(open(sys.argv[1] + "/eval.json"))
smp = json.load(open(sys.argv[1] + "/sample.json"))
assert smp["noise_percent"] == 0 and abs(smp["metrics"]["psnr"] - ev["mean"][0]["psnr"]) < 1e-5, smp
d = rd.load(sys.argv[1] + "/report.html")
assert "rainbow_rows" not in d and "rainbow" not in d["eval"], d.keys()
PY
check "--report-noise 0: the sample is the 0 % row" [ $? -eq 0 ]

# ---- an infer folder, and a folder of known cubes ---------------------------------------------
"$LM" simulate --input "$CAVE" --output "$T/sim" --crop > /dev/null 2>&1
"$LM" infer --model "$R" --input "$T/sim/frames/frame_0000.png" --output "$T/inf" > /dev/null 2>&1
"$LM" report "$T/inf" > "$T/out" 2> "$T/err"
check "report of an infer folder: $(cat "$T/err")" grep -q "reconstruction, cube_0000.exr 100 x 99" "$T/out"
python3 - "$T/inf/report.html" "$PYLIB" <<'PY'
import sys
sys.path.insert(0, sys.argv[2])
import report_data as rd
html = open(sys.argv[1], encoding="utf-8").read()
assert rd.no_network(html) is None
d = rd.load(sys.argv[1])
assert d["kind"] == "infer" and "truth" not in d["cube"] and "srgb_truth" not in d, d.keys()
assert d["frame"] == {"file": "cube_0000.exr", "number": 0, "frames": 1}, d["frame"]
assert rd.png_size(d["srgb"]) == (100, 99)
PY
check "infer page: one frame, no truth" [ $? -eq 0 ]
mkdir "$T/known"
"$MK" "$T/known/cube_0003.exr" good 40 60 && "$MK" "$T/known/cube_0012.exr" good 20 24
"$LM" report "$T/known" --frame 12 --output "$T/known12.html" > /dev/null 2> "$T/err"
check "--frame 12: $(cat "$T/err")" [ $? -eq 0 ]
"$LM" report "$T/known" > /dev/null 2> "$T/err"
python3 - "$T" "$PYLIB" <<'PY'
import sys
sys.path.insert(0, sys.argv[2])
import report_data as rd
T = sys.argv[1]
value = lambda b, i: 0.05 + 0.9 * ((b * 7 + i * 13) % 101) / 100.0  # tests/cli/make_cube.c
for page, H, W, name in ((T + "/known/report.html", 40, 60, "cube_0003.exr"),
                         (T + "/known12.html", 20, 24, "cube_0012.exr")):
    d = rd.load(page)
    assert d["frame"]["file"] == name and d["frame"]["frames"] == 2, d["frame"]
    c = rd.cube(d, "recon")
    q = d["cube"]["scale"] / 65535
    worst = max(abs(c[b][y][x] - value(b, y * W + x)) for b in range(31) for y in range(H)
                for x in range(W))
    assert worst <= q, (page, worst, q)
PY
check "known cubes: the embedded values are the cube's, --frame picks the file" [ $? -eq 0 ]

# ---- bad input -----------------------------------------------------------------------------
cp -r "$O" "$T/badjson" && rm "$T/badjson/report.html" && echo '{"mean": [' > "$T/badjson/eval.json"
cp -r "$O" "$T/nosample" && rm "$T/nosample/report.html" "$T/nosample/sample_truth.exr"
cp -r "$O" "$T/badrb" && rm "$T/badrb/report.html" && echo 'row,true_nm,recovered_nm,error_nm
0,700,x,1' > "$T/badrb/rainbow.csv"
expect_error "no DIR" 2 "no DIR given" "$T/x.html" -- "$LM" report --output "$T/x.html"
expect_error "two DIRs" 2 "one DIR only" "$T/x.html" -- "$LM" report "$O" "$O" --output "$T/x.html"
expect_error "missing folder" 2 "$T/none: No such file or directory" "$T/none" -- "$LM" report "$T/none"
expect_error "not an output folder" 2 "neither an eval folder" "$R/report.html" -- "$LM" report "$R"
expect_error "corrupt eval.json" 2 "badjson/eval.json: line" "$T/badjson/report.html" -- "$LM" report "$T/badjson"
expect_error "sample file missing" 2 "sample_truth.exr is missing" "$T/nosample/report.html" -- "$LM" report "$T/nosample"
expect_error "corrupt rainbow.csv" 2 "rainbow.csv: line 2" "$T/badrb/report.html" -- "$LM" report "$T/badrb"
expect_error "--max-side 8" 2 "--max-side" "$T/x.html" -- "$LM" report "$O" --max-side 8 --output "$T/x.html"
expect_error "--frame missing" 2 "no cube_0005.exr (--frame 5)" "$T/x.html" -- "$LM" report "$T/known" --frame 5 --output "$T/x.html"
expect_error "--frame on an eval folder" 2 "an eval folder (--frame is for infer folders)" "$T/x.html" -- "$LM" report "$O" --frame 0 --output "$T/x.html"
expect_error "not .html" 2 "written as .html" "$T/x.txt" -- "$LM" report "$O" --output "$T/x.txt"
expect_error "output folder missing" 1 "$T/nodir/x.html: cannot write" "$T/nodir" -- "$LM" report "$O" --output "$T/nodir/x.html"
expect_error "unknown option" 2 "--bogus" "$T/x.html" -- "$LM" report "$O" --bogus --output "$T/x.html"
expect_error "eval --report without --output" 2 "--report needs --output" "$T/x" -- "$LM" eval --model "$R" "$CAVE" --split all --report
expect_error "eval --report-noise not a level" 2 "--report-noise 5 is not one of the --noise levels" "$T/x" -- "$LM" eval --model "$R" "$CAVE" --split all --noise 0,10 --report --report-noise 5 --output "$T/x"
finish
