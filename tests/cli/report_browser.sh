#!/usr/bin/env bash
# report_browser.sh — the page of `lumosaic report` in a real browser: headless Chromium
# (scripts/setup.sh installs it from Debian) loads an `eval --report` page and a page of a
# folder of known cubes (cli_make_cube), from file:// with no network, runs their script and
# dumps the DOM. Opened as report.html#click=X,Y the page dispatches a click on the
# reconstruction's preview at that pixel: the spectrum plot then names the pixel, and its
# reconstruction and truth polylines have 31 points whose values are the embedded cube's at
# that pixel (the known cubes: the values cli_make_cube wrote; a 280 x 200 cube embedded in
# 5 x 5 blocks: the clicked pixel's block mean); without #click no spectrum is drawn. The PSNR-per-noise plot holds eval.json's means, the PSNR-per-band plot 31 points,
# the rainbow plots one point per row. A screenshot is taken (a PNG of the window's size, not
# a blank page). Without Chromium the test is skipped (exit 77), except under CI=true, where
# it fails.
# usage: report_browser.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
PYLIB=$(cd "$(dirname "$0")" && pwd)

CHROME=$(command -v chromium || command -v chromium-browser || true)
if [ -z "$CHROME" ]; then
  if [ "${CI:-}" = true ]; then
    echo "FAIL: chromium is not installed (scripts/setup.sh installs it)" >&2
    exit 1
  fi
  echo "skipped: chromium is not installed (scripts/setup.sh installs it)"
  exit 77
fi
# chrome URL OUT.html|OUT.png: the DOM after the page's script ran, or a screenshot
chrome() {
  local args=(--headless --no-sandbox --disable-gpu --no-first-run --user-data-dir="$T/profile"
              --virtual-time-budget=10000)
  case $2 in
    *.png) timeout 180 "$CHROME" "${args[@]}" --window-size=1400,1800 --hide-scrollbars \
             "--screenshot=$2" "$1" > /dev/null 2> "$T/chrome.err" ;;
    *) timeout 180 "$CHROME" "${args[@]}" --dump-dom "$1" > "$2" 2> "$T/chrome.err" ;;
  esac
}

R=$T/run
"$LM" train --model linear --data "$CAVE" --iterations 60 --batch 4 --accum-steps 1 --lr 5e-3 \
  --synth-fraction 0 --noise 0,0 --val-patches 1 --output "$R" --quiet > "$T/log" 2>&1
check "train: $(cat "$T/log")" [ -s "$R/model.safetensors" ]
O=$T/ev
"$LM" eval --model "$R" "$CAVE" --split all --noise 0,10 --rainbow 96 --output "$O" --report \
  > /dev/null 2> "$T/err"
check "eval --report: $(cat "$T/err")" [ -s "$O/report.html" ]
mkdir "$T/known"
"$MK" "$T/known/cube_0000.exr" good 40 60
"$LM" report "$T/known" > /dev/null 2> "$T/err"
check "report of known cubes: $(cat "$T/err")" [ -s "$T/known/report.html" ]
mkdir "$T/big" # 280 x 200 shown 300 px wide (not a whole number of screen pixels per pixel),
"$MK" "$T/big/cube_0000.exr" good 200 280 # embedded as 56 x 40 blocks of 5 x 5
"$LM" report "$T/big" --max-side 64 > /dev/null 2> "$T/err"
check "report --max-side 64: $(cat "$T/err")" [ -s "$T/big/report.html" ]

chrome "file://$O/report.html#click=40,30" "$T/eval.dom"
check "chromium --dump-dom (eval page): $(tail -3 "$T/chrome.err")" [ -s "$T/eval.dom" ]
chrome "file://$O/report.html" "$T/noclick.dom"
chrome "file://$T/known/report.html#click=13,7" "$T/known.dom"
check "chromium --dump-dom (known cubes): $(tail -3 "$T/chrome.err")" [ -s "$T/known.dom" ]
chrome "file://$T/big/report.html#click=201,133" "$T/big.dom"
chrome "file://$O/report.html#click=40,30" "$T/shot.png"
check "chromium --screenshot: $(tail -3 "$T/chrome.err")" [ -s "$T/shot.png" ]

python3 - "$T" "$O" "$PYLIB" <<'PY'
import json, struct, sys
from html.parser import HTMLParser
sys.path.insert(0, sys.argv[3])
import report_data as rd
T, O = sys.argv[1], sys.argv[2]

class Elements(HTMLParser):  # id -> attributes, and the text of each id'd element
    def __init__(self):
        super().__init__()
        self.by_id, self.text, self.stack = {}, {}, []
    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        a["tag"] = tag
        if "id" in a:
            self.by_id[a["id"]] = a
        self.stack.append(a.get("id"))
    def handle_endtag(self, tag):
        if self.stack:
            self.stack.pop()
    def handle_data(self, data):
        for i in self.stack:
            if i:
                self.text[i] = self.text.get(i, "") + data

def parse(path):
    p = Elements()
    p.feed(open(path, encoding="utf-8").read())
    return p

def line(p, ident, n):
    a = p.by_id.get(ident)
    assert a and a["tag"] == "polyline", (ident, a)
    pts = a["points"].split()
    vals = [float(v) for v in a["data-values"].split()]
    assert int(a["data-n"]) == n and len(pts) == n and len(vals) == n, (ident, a["data-n"], len(pts))
    return vals

def close(got, want, tol):
    assert len(got) == len(want) and all(abs(g - w) <= tol + 1e-4 * abs(w) for g, w in zip(got, want)), \
        list(zip(got, want))

# the eval page, pixel (40, 30) clicked
d = rd.load(O + "/report.html")
ev = json.load(open(O + "/eval.json"))
p = parse(T + "/eval.dom")
spec = p.by_id["spectrum"]
assert spec.get("data-pixel") == "40,30" and spec.get("data-cube-pixel") == "40,30", spec
rec, tru = rd.cube(d, "recon"), rd.cube(d, "truth")
q = d["cube"]["scale"] / 65535
close(line(p, "spectrum-recon", 31), [rec[b][30][40] for b in range(31)], q)
close(line(p, "spectrum-truth", 31), [tru[b][30][40] for b in range(31)], q)
assert "pixel x 40, y 30" in p.text.get("cap-spec", ""), p.text.get("cap-spec")
close(line(p, "noise-psnr", 2), [m["psnr"] for m in ev["mean"]], 1e-3)
close(line(p, "band-psnr", 31), d["band_psnr"], 1e-3)
close(line(p, "rainbow-recovered", 96), d["rainbow_rows"]["recovered_nm"], 1e-2)
line(p, "rainbow-true", 96)
line(p, "rainbow-error", 96)
assert p.text.get("band-label") == "550 nm", p.text.get("band-label")
assert "balloons_crop100" in p.text.get("sample-kv", ""), p.text.get("sample-kv")
assert "%.2f" % ev["mean"][1]["psnr"] in p.text.get("tab-mean", ""), p.text.get("tab-mean")
for ident in ("sec-images", "sec-bands", "sec-metrics", "sec-rainbow", "fig-tru", "fig-berr"):
    assert "hidden" not in p.by_id[ident], ident

# without #click: no pixel, no spectrum
p = parse(T + "/noclick.dom")
assert "data-pixel" not in p.by_id["spectrum"] and "spectrum-recon" not in p.by_id

# the known cubes (tests/cli/make_cube.c), pixel (13, 7) of a 40 x 60 cube
d = rd.load(T + "/known/report.html")
p = parse(T + "/known.dom")
assert p.by_id["spectrum"].get("data-pixel") == "13,7", p.by_id["spectrum"]
value = lambda b, i: 0.05 + 0.9 * ((b * 7 + i * 13) % 101) / 100.0
close(line(p, "spectrum-recon", 31), [value(b, 7 * 60 + 13) for b in range(31)],
      d["cube"]["scale"] / 65535)
assert "spectrum-truth" not in p.by_id and "hidden" in p.by_id["fig-tru"]

# the 280 x 200 cube in 5 x 5 blocks: pixel (201, 133) is block (40, 26), its spectrum the
# block's mean
d = rd.load(T + "/big/report.html")
p = parse(T + "/big.dom")
assert p.by_id["spectrum"].get("data-pixel") == "201,133", p.by_id["spectrum"]
assert p.by_id["spectrum"].get("data-cube-pixel") == "40,26", p.by_id["spectrum"]
mean = [sum(value(b, y * 280 + x) for y in range(130, 135) for x in range(200, 205)) / 25
        for b in range(31)]
close(line(p, "spectrum-recon", 31), mean, d["cube"]["scale"] / 65535)
assert "mean of its 5 × 5 block" in p.text.get("cap-spec", ""), p.text.get("cap-spec")

# the screenshot: a PNG of the window, far from a blank page
png = open(T + "/shot.png", "rb").read()
assert png[:8] == b"\x89PNG\r\n\x1a\n", png[:8]
w, h = struct.unpack(">II", png[16:24])
assert (w, h) == (1400, 1800), (w, h)
assert len(png) > 60000, len(png)
print("browser checks passed; screenshot %d bytes" % len(png))
PY
check "the pages in Chromium: plots, clicked-pixel spectra, screenshot" [ $? -eq 0 ]
# keep the screenshot for a look when asked (LM_REPORT_SHOT=path)
[ -n "${LM_REPORT_SHOT:-}" ] && cp "$T/shot.png" "$LM_REPORT_SHOT"
finish
