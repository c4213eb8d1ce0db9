#!/usr/bin/env bash
# calibrate.sh — `lumosaic calibrate`, the NNLS LED-gain calibration (issue 14, item 1), end to
# end: a ColorChecker scene (--write-chart) simulated with the bundled system calibrates to its
# own gains; simulated with gains perturbed by up to +-30 % and 1 % Gaussian noise (3 frames,
# averaged) the calibrated gains match the true ones within 2 % (one common factor aside: gains
# are relative), the written system loads and `simulate` accepts it; --offset recovers a dark
# level added to the frames; the report has a gain per LED and a residual per patch. Errors (one
# line, exit 2, no system or report written): a patch outside the frame, frames of another
# sensor size, frames of another tile map (the fit's error), the old --models usage.
# usage: calibrate.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
CORNERS=160,144,480,144,480,336,160,336
"$LM" calibrate --write-chart "$T/chart.exr" > "$T/out" 2> "$T/err"
check "write-chart: $(cat "$T/err")" [ $? -eq 0 -a -s "$T/chart.exr" ]
check "write-chart names the corners" grep -q "160.0,144.0 480.0,144.0" "$T/out"
"$LM" simulate --input "$T/chart.exr" --output "$T/s0" > /dev/null 2> "$T/err"
check "simulate the chart: $(cat "$T/err")" [ $? -eq 0 ]
"$LM" calibrate "$T/s0/frames" --chart-corners $CORNERS --output "$T/sys0.json" > "$T/out" \
  2> "$T/err"
check "calibrate: $(cat "$T/err")" [ $? -eq 0 -a -s "$T/sys0.json" -a -s "$T/sys0.report.json" ]
python3 - "$T" <<'PY'
import json, random, sys
T = sys.argv[1]
r = json.load(open(T + "/sys0.report.json"))
assert len(r["leds"]) == 12 and len(r["patches"]) == 24 and r["relative_error"] < 1e-3, r["relative_error"]
for l in r["leds"]:  # noise-free, the bundled system: its own gains back
    assert abs(l["gain"] / l["gain_before"] - 1) < 1e-3, l
s = json.load(open(T + "/sys0.json"))
assert "calibrated" in s["name"] and all(l["emission"]["csv"].startswith("/") for l in s["leds"])
random.seed(5)
s["gains"] = [g * (1 + random.uniform(-0.3, 0.3)) for g in s["gains"]]
json.dump(s, open(T + "/true.json", "w"))
PY
check "noise-free self-calibration; a perturbed system" [ $? -eq 0 ]
mkdir -p "$T/s1"
for i in 1 2 3; do
  "$LM" simulate --input "$T/chart.exr" --system "$T/true.json" --noise 0.01 --seed $i \
    --output "$T/s1/$i" > /dev/null 2> "$T/err" || fail "simulate perturbed $i: $(cat "$T/err")"
done
"$LM" calibrate "$T/s1/1/frames" "$T/s1/2/frames" "$T/s1/3/frames" --chart-corners $CORNERS \
  --output "$T/cal.json" > "$T/out" 2> "$T/err"
check "calibrate perturbed: $(cat "$T/err")" [ $? -eq 0 ]
check "3 frames averaged" grep -q "from 3 frame(s)" "$T/out"
gains_match() { python3 - "$1" "$2" "$3" <<'PY'
import json, sys
t = json.load(open(sys.argv[1]))["gains"]; c = json.load(open(sys.argv[2]))["gains"]
r = [a / b for a, b in zip(c, t)]; m = sum(r) / len(r)
worst = max(abs(x / m - 1) for x in r)
print(f"worst relative gain error {worst:.4f}")
sys.exit(worst > float(sys.argv[3]))
PY
}
check "gains within 2 % at 1 % noise ($(gains_match "$T/true.json" "$T/cal.json" 0.02))" \
  gains_match "$T/true.json" "$T/cal.json" 0.02
"$LM" simulate --input "$T/chart.exr" --system "$T/cal.json" --output "$T/s2" > /dev/null \
  2> "$T/err"
check "simulate accepts the calibrated system: $(cat "$T/err")" [ $? -eq 0 ]
# a dark level of 0.02 added to the (noise-free) frame: --offset finds it, the gains stay right
python3 - "$T/s0/frames/frame_0000.png" "$T/dark.png" <<'PY'
import sys, zlib, struct
def rd(p):
    b = open(p, "rb").read(); i = 8; idat = b""; w = h = 0
    while i < len(b):
        n, t = struct.unpack(">I4s", b[i:i + 8]); d = b[i + 8:i + 8 + n]; i += 12 + n
        if t == b"IHDR": w, h, bd, ct = struct.unpack(">IIBB", d[:10]); assert bd == 16 and ct == 0
        elif t == b"IDAT": idat += d
    raw = zlib.decompress(idat); st = 2 * w; rows = []; prev = bytearray(st)
    for y in range(h):
        f = raw[y * (st + 1)]; line = bytearray(raw[y * (st + 1) + 1:(y + 1) * (st + 1)])
        for x in range(st):
            a = line[x - 2] if x >= 2 else 0; up = prev[x]; c = prev[x - 2] if x >= 2 else 0
            if f == 1: line[x] = (line[x] + a) & 255
            elif f == 2: line[x] = (line[x] + up) & 255
            elif f == 3: line[x] = (line[x] + (a + up) // 2) & 255
            elif f == 4:
                p = a + up - c; pa, pb, pc = abs(p - a), abs(p - up), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else up if pb <= pc else c)) & 255
        rows.append(line); prev = line
    return w, h, rows
w, h, rows = rd(sys.argv[1]); off = round(0.02 * 65535); out = b""
for line in rows:
    v = [min(65535, (line[2 * x] << 8 | line[2 * x + 1]) + off) for x in range(w)]
    out += b"\0" + b"".join(struct.pack(">H", x) for x in v)
def chunk(t, d): return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
open(sys.argv[2], "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0))
                              + chunk(b"IDAT", zlib.compress(out)) + chunk(b"IEND", b""))
PY
"$LM" calibrate "$T/dark.png" --offset --chart-corners $CORNERS --output "$T/dark.json" \
  --report "$T/dark-report.json" > /dev/null 2> "$T/err"
check "calibrate --offset: $(cat "$T/err")" [ $? -eq 0 ]
check "--offset: the dark level and the gains" python3 - "$T/dark-report.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
assert abs(r["offset"] - 0.02) < 5e-4 and r["offset_fitted"], r["offset"]
assert all(abs(l["gain"] / l["gain_before"] - 1) < 0.01 for l in r["leds"]), r["leds"]
PY
"$LM" calibrate "$T/dark.png" --chart-corners $CORNERS --output "$T/nodark.json" > "$T/out" \
  2> /dev/null
check "without --offset the dark level shows in the error" \
  python3 -c "import json,sys; sys.exit(json.load(open('$T/nodark.report.json'))['relative_error'] < 0.01)"

# errors: one line, exit 2, nothing written
expect_error "patch outside the frame" 2 "is not inside the 640 x 480 frame" "$T/e1.json" -- \
  "$LM" calibrate "$T/s0/frames" --chart-corners 160,144,700,144,700,336,160,336 \
  --output "$T/e1.json"
"$LM" simulate --input "$CAVE" --crop --output "$T/cave" > /dev/null 2>&1
expect_error "frames of another sensor size" 2 "frames of another system" "$T/e2.json" -- \
  "$LM" calibrate "$T/cave/frames" --chart-corners 20,20,80,20,80,60,20,60 --output "$T/e2.json"
python3 - "$T/sys0.json" "$T/other.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
s["tile_map"] = [row[::-1] for row in s["tile_map"][::-1]]  # LEDs at other mosaic phases
json.dump(s, open(sys.argv[2], "w"))
PY
"$LM" simulate --input "$T/chart.exr" --system "$T/other.json" --output "$T/s3" > /dev/null 2>&1
expect_error "frames of another tile map" 2 "relative error" "$T/e3.json" -- \
  "$LM" calibrate "$T/s3/frames" --chart-corners $CORNERS --output "$T/e3.json"
expect_error "the old usage" 2 "lumosaic fit-auto" "$T/e4.json" -- \
  "$LM" calibrate --models a,b --synth 1 --output "$T/e4.json"
expect_error "no patch regions" 2 "--patches or --chart-corners" "$T/e5.json" -- \
  "$LM" calibrate "$T/s0/frames" --output "$T/e5.json"
echo '{"patches": [[0, 0, 8, 8]]}' > "$T/few.json"
expect_error "patches file with one rectangle" 2 "24 rectangles" "$T/e6.json" -- \
  "$LM" calibrate "$T/s0/frames" --patches "$T/few.json" --output "$T/e6.json"
for f in e1 e2 e3 e6; do check "$f: no report" [ ! -e "$T/$f.report.json" ]; done
finish
