#!/usr/bin/env bash
# raw.sh — `lumosaic infer` on raw camera frames: 12-bit data in 16-bit PNG files LSB- and
# MSB-aligned (--bits 12 [--msb]; the same cube either way, within 12-bit quantisation of the
# 16-bit frame's), a black level, averaged dark frames (--dark), a white-target flat with per-pixel
# gains (--flat), the share of saturated pixels on every progress line and the optional mask
# (--saturation-mask). Frames derived from a simulated CAVE frame (balloons_crop100) with the
# bundled demo model; each corrected frame reconstructs as the clean frame does (PSNR between
# the cubes), and without the option it does not. Errors (one line, exit 2, nothing written):
# the wrong alignment, --msb alone, a dark frame of another size, --black-level with --dark.
# usage: raw.sh LUMOSAIC MAKE_CUBE CUBE_PSNR
source "$(dirname "$0")/lib.sh"
PSNR=$3
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
MODEL=$ROOT/models/demo/rt16nc-lmmse.safetensors
"$LM" simulate --input "$CAVE" --output "$T/sim" --crop > /dev/null 2>&1
F=$T/sim/frames/frame_0000.png
check "simulated" [ -s "$F" ]
mkdir -p "$T/f" "$T/dark" "$T/small"
# 16-bit grey PNG in/out (zlib, the five filters) and the derived frames
python3 - "$F" "$T" <<'PY'
import struct, sys, zlib
def rd(p):
    b = open(p, "rb").read(); i = 8; idat = b""; w = h = 0
    while i < len(b):
        n, t = struct.unpack(">I4s", b[i:i + 8]); d = b[i + 8:i + 8 + n]; i += 12 + n
        if t == b"IHDR": w, h, bd, ct = struct.unpack(">IIBB", d[:10]); assert bd == 16 and ct == 0
        elif t == b"IDAT": idat += d
    raw = zlib.decompress(idat); st = 2 * w; prev = bytearray(st); px = []
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
        px.append([line[2 * x] << 8 | line[2 * x + 1] for x in range(w)]); prev = line
    return w, h, px
def wr(p, w, h, px):
    raw = b"".join(b"\0" + b"".join(struct.pack(">H", max(0, min(65535, int(round(v))))) for v in row) for row in px)
    def chunk(t, d): return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    open(p, "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0)) +
                        chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
F, T = sys.argv[1], sys.argv[2]
w, h, px = rd(F)
X = [[v / 65535 for v in row] for row in px]
lsb = [[round(x * 4095) for x in row] for row in X]
wr(T + "/f/lsb.png", w, h, lsb)
wr(T + "/f/msb.png", w, h, [[c * 16 for c in row] for row in lsb])
wr(T + "/f/black.png", w, h, [[200 + round(x * 3895) for x in row] for row in X])
D = [[1500 + 40 * (x % 5) + 25 * (y % 7) for x in range(w)] for y in range(h)]
md = sum(map(sum, D)) / (w * h)
wr(T + "/dark/d_0.png", w, h, [[d - 60 for d in row] for row in D])
wr(T + "/dark/d_1.png", w, h, [[d + 60 for d in row] for row in D])
wr(T + "/f/dark.png", w, h, [[D[y][x] + X[y][x] * (65535 - md) for x in range(w)] for y in range(h)])
wr(T + "/small/d.png", 8, 12, [[1500] * 8 for _ in range(12)])
G = [[1.15 if (x + y) % 2 else 0.85 for x in range(w)] for y in range(h)]
wr(T + "/flat.png", w, h, [[40000 * g for g in row] for row in G])
wr(T + "/f/flat.png", w, h, [[65535 * 0.85 * X[y][x] * G[y][x] for x in range(w)] for y in range(h)])
wr(T + "/f/flat_ref.png", w, h, [[65535 * 0.85 * x for x in row] for row in X])  # the level it keeps
sat = [row[:] for row in lsb]; k = 0
for y in range(0, h, 7):
    for x in range(0, w, 5): sat[y][x] = 4095; k += 1
wr(T + "/f/sat.png", w, h, sat)
open(T + "/sat.txt", "w").write("%.3f" % (100.0 * k / (w * h)))
PY
check "raw frames written" [ -s "$T/f/sat.png" -a -s "$T/flat.png" ]

infer() { local out=$1; shift; "$LM" infer --model "$MODEL" --threads 2 --output "$out" "$@"; }
infer "$T/ref" --input "$F" 2> "$T/err"
check "reference: $(cat "$T/err")" [ -s "$T/ref/cube_0000.exr" ]
check "progress line: saturated 0.000 %" grep -q "^frame 1/1 .*; saturated 0.000 %$" "$T/err"
close() {  # close NAME OUT MIN_DB [MAX_DB]: OUT's cube against the reference
  local p
  p=$("$PSNR" "$2/cube_0000.exr" "$T/ref/cube_0000.exr")
  echo "$1: $p dB against the clean frame's cube"
  check "$1: $p dB (want > $3${4:+ and < $4})" awk -v p="$p" -v a="$3" -v b="${4:-1e9}" \
    'BEGIN { exit !(p > a && p < b) }'
}
infer "$T/lsb" --input "$T/f/lsb.png" --bits 12 2> "$T/err"
check "--bits 12: $(cat "$T/err")" [ -s "$T/lsb/cube_0000.exr" ]
close "12-bit LSB" "$T/lsb" 40
infer "$T/lsb0" --input "$T/f/lsb.png" 2> /dev/null
close "12-bit LSB read as 16-bit" "$T/lsb0" 0 25
infer "$T/msb" --input "$T/f/msb.png" --bits 12 --msb 2> "$T/err"
check "--bits 12 --msb: $(cat "$T/err")" cmp -s "$T/msb/cube_0000.exr" "$T/lsb/cube_0000.exr"
infer "$T/black" --input "$T/f/black.png" --bits 12 --black-level 200 2> /dev/null
close "black level 200" "$T/black" 40
infer "$T/black0" --input "$T/f/black.png" --bits 12 2> /dev/null
close "black level 200 not subtracted" "$T/black0" 0 30
infer "$T/o_dark" --input "$T/f/dark.png" --dark "$T/dark" 2> "$T/err"
check "--dark: $(cat "$T/err")" [ -s "$T/o_dark/cube_0000.exr" ]
close "two dark frames" "$T/o_dark" 45
infer "$T/dark0" --input "$T/f/dark.png" 2> /dev/null
close "dark not subtracted" "$T/dark0" 0 30
infer "$T/flat" --input "$T/f/flat.png" --flat "$T/flat.png" 2> "$T/err"
check "--flat: $(cat "$T/err")" [ -s "$T/flat/cube_0000.exr" ]
infer "$T/flat_ref" --input "$T/f/flat_ref.png" 2> /dev/null  # the same scene at the same level
p_flat=$("$PSNR" "$T/flat/cube_0000.exr" "$T/flat_ref/cube_0000.exr")
infer "$T/flat0" --input "$T/f/flat.png" 2> /dev/null
p_flat0=$("$PSNR" "$T/flat0/cube_0000.exr" "$T/flat_ref/cube_0000.exr")
echo "flat: $p_flat dB corrected, $p_flat0 dB not"
check "flat corrects the per-pixel gains ($p_flat dB, > 45)" \
  awk -v a="$p_flat" 'BEGIN { exit !(a > 45) }'
check "without --flat: below 35 dB ($p_flat0 dB)" awk -v a="$p_flat0" 'BEGIN { exit !(a < 35) }'
infer "$T/sat" --input "$T/f/sat.png" --bits 12 --saturation-mask 2> "$T/err"
want=$(cat "$T/sat.txt")
check "saturated share $want % reported: $(cat "$T/err")" grep -q "; saturated $want %$" "$T/err"
check "mask written" [ -s "$T/sat/saturated_0000.png" ]
n=$(python3 - "$T/sat/saturated_0000.png" <<'PY'
import sys, zlib, struct
b = open(sys.argv[1], "rb").read(); i = 8; idat = b""
while i < len(b):
    n, t = struct.unpack(">I4s", b[i:i + 8]); d = b[i + 8:i + 8 + n]; i += 12 + n
    if t == b"IHDR": w, h = struct.unpack(">II", d[:8])
    elif t == b"IDAT": idat += d
raw = zlib.decompress(idat); st = 2 * w + 1
prev = bytearray(2 * w); k = 0
for y in range(h):
    f = raw[y * st]; line = bytearray(raw[y * st + 1:(y + 1) * st])
    for x in range(2 * w):
        a = line[x - 2] if x >= 2 else 0; up = prev[x]; c = prev[x - 2] if x >= 2 else 0
        if f == 1: line[x] = (line[x] + a) & 255
        elif f == 2: line[x] = (line[x] + up) & 255
        elif f == 3: line[x] = (line[x] + (a + up) // 2) & 255
        elif f == 4:
            p = a + up - c; pa, pb, pc = abs(p - a), abs(p - up), abs(p - c)
            line[x] = (line[x] + (a if pa <= pb and pa <= pc else up if pb <= pc else c)) & 255
    k += sum(1 for x in range(w) if line[2 * x] or line[2 * x + 1]); prev = line
print(k)
PY
)
check "mask count matches the share" python3 -c "
import struct, sys
w, h = struct.unpack('>II', open(sys.argv[1], 'rb').read()[16:24])
sys.exit(abs(100.0 * int(sys.argv[2]) / (w * h) - float(sys.argv[3])) > 0.001)" "$F" "$n" "$want"
check_not "no mask without the option" [ -e "$T/lsb/saturated_0000.png" ]

expect_error "LSB declared, MSB data" 2 "add --msb" "$T/e1" -- \
  "$LM" infer --model "$MODEL" --input "$T/f/msb.png" --bits 12 --output "$T/e1"
expect_error "MSB declared, LSB data" 2 "drop --msb" "$T/e2" -- \
  "$LM" infer --model "$MODEL" --input "$T/f/lsb.png" --bits 12 --msb --output "$T/e2"
expect_error "--msb alone" 2 "--msb needs --bits" "$T/e3" -- \
  "$LM" infer --model "$MODEL" --input "$F" --msb --output "$T/e3"
expect_error "dark of another size" 2 "dark frame is 8 x 12" "$T/e4" -- \
  "$LM" infer --model "$MODEL" --input "$F" --dark "$T/small/d.png" --output "$T/e4"
expect_error "black level and dark" 2 "give one" "$T/e5" -- \
  "$LM" infer --model "$MODEL" --input "$F" --dark "$T/dark" --black-level 10 --output "$T/e5"
expect_error "--bits 17" 2 "--bits" "$T/e6" -- \
  "$LM" infer --model "$MODEL" --input "$F" --bits 17 --output "$T/e6"
finish
