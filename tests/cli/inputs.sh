#!/usr/bin/env bash
# inputs.sh — what every command does with its input paths and list options before any work:
# a FIFO, a device or a folder where a file is expected is refused at once (exit 2, one line
# naming it; nothing is opened, so nothing blocks), for frames, cubes, models, system files,
# configs, calibrations, DOE descriptions, spectra and wavelength sidecars; a wavelength sidecar
# that is a folder is an error too. Every list option is parsed strictly (no empty element, no
# hexadecimal); flags that contradict the preset and an output named for another format are
# one-line errors. Checks where a mistake was accepted: a 1-bit frame, buckets in two formats,
# an automatic calibration of one model, study --dry-run on missing data or a file as its
# output, duplicate keys in a JSON config, fit-auto onto a folder, a truncated .safetensors
# (the file's real size), a sidecar's bad token (named whole, no stray character). A DOE's grid
# is bounded by what finishes in reasonable time (8192 runs for minutes at ~1 GB).
# usage: inputs.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
MODEL=$(cd "$(dirname "$0")/../.." && pwd)/models/demo/rt16nc-lmmse.safetensors

# ---- FIFOs where a file is expected: refused without blocking -------------------------------
F=$T/fifo
mkdir -p "$F/frames" "$F/scene" "$F/data"
for f in f.png f.exr f.mat m.safetensors s.json c.json r.csv; do mkfifo "$F/$f"; done
mkfifo "$F/frames/frame_0000.png"
cp -r "$CAVE" "$F/scene/"
mkfifo "$F/scene/balloons_crop100.wavelengths.txt"
mkfifo "$F/data/x.exr"
ln -s /dev/null "$T/null.png"
# each under a timeout: a command blocking in open() fails its case instead of hanging
W="timeout -k 5 20"
expect_error "infer: a FIFO frame" 2 "f.png: is a FIFO, not a regular file" "$T/o1" -- \
  $W "$LM" infer --model "$MODEL" --input "$F/f.png" --output "$T/o1"
expect_error "infer: a FIFO in a frame folder" 2 "frame_0000.png: is a FIFO" "$T/o2" -- \
  $W "$LM" infer --model "$MODEL" --input "$F/frames" --output "$T/o2"
expect_error "infer: a FIFO model" 2 "m.safetensors: is a FIFO" "$T/o3" -- \
  $W "$LM" infer --model "$F/m.safetensors" --input "$F/f.png" --output "$T/o3"
expect_error "calibrate: a FIFO frame" 2 "f.png: is a FIFO" "$T/o4.json" -- \
  $W "$LM" calibrate "$F/f.png" --chart-corners 10,10,90,10,90,60,10,60 --output "$T/o4.json"
expect_error "calibrate: a FIFO reflectance table" 2 "r.csv: is a FIFO" "$T/o5.exr" -- \
  $W "$LM" calibrate --write-chart "$T/o5.exr" --reflectance "$F/r.csv"
expect_error "simulate: a FIFO .exr cube" 2 "f.exr: is a FIFO" "$T/o6" -- \
  $W "$LM" simulate --input "$F/f.exr" --output "$T/o6"
expect_error "render: a FIFO .mat cube" 2 "f.mat: is a FIFO" "$T/o7.png" -- \
  $W "$LM" render --input "$F/f.mat" --output "$T/o7.png"
expect_error "render: a FIFO wavelength sidecar" 2 "balloons_crop100.wavelengths.txt: is a FIFO" \
  "$T/o8.png" -- $W "$LM" render --input "$F/scene/balloons_crop100" --output "$T/o8.png"
expect_error "simulate: a FIFO system file" 2 "s.json: is a FIFO" "$T/o9" -- \
  $W "$LM" simulate --input "$CAVE" --crop --system "$F/s.json" --output "$T/o9"
expect_error "simulate: a FIFO DOE" 2 "s.json: is a FIFO" "$T/o10" -- \
  $W "$LM" simulate --input "$CAVE" --crop --doe "$F/s.json" --output "$T/o10"
expect_error "train: a FIFO config" 2 "c.json: is a FIFO" "$T/o11" -- \
  $W "$LM" train --config "$F/c.json" --output "$T/o11"
expect_error "train: a FIFO in the data" 2 "x.exr: is a FIFO" "$T/o12" -- \
  $W "$LM" train --model linear --data "$F/data" --iterations 1 --output "$T/o12"
expect_error "study: a FIFO config" 2 "c.json: is a FIFO" "$T/o13" -- \
  $W "$LM" study --config "$F/c.json" --output "$T/o13"
expect_error "infer: a FIFO auto calibration" 2 "c.json: is a FIFO" "$T/o14" -- \
  $W "$LM" infer --model auto --auto "$F/c.json" --input "$CAVE" --output "$T/o14"
expect_error "eval: a FIFO model" 2 "m.safetensors: is a FIFO" "$T/o15" -- \
  $W "$LM" eval --model "$F/m.safetensors" "$CAVE" --output "$T/o15"
expect_error "infer: a device as a frame" 2 "null.png: is a device, not a regular file" "$T/o16" -- \
  $W "$LM" infer --model "$MODEL" --input "$T/null.png" --output "$T/o16"

# ---- a sidecar path that is a folder -----------------------------------------------------------
mkdir -p "$T/sc2" && cp -r "$CAVE" "$T/sc2/" && mkdir "$T/sc2/balloons_crop100.wavelengths.txt"
expect_error "render: a folder as the wavelength sidecar" 2 \
  "balloons_crop100.wavelengths.txt: is a folder, expected a wavelength list" "$T/p1.png" -- \
  "$LM" render --input "$T/sc2/balloons_crop100" --output "$T/p1.png"

# ---- lists: strict, one parser ---------------------------------------------------------------
E="$LM eval --model $MODEL $CAVE --split all --rainbow 0"
expect_error "eval --noise '0,,5'" 2 "--noise '0,,5': element 2 is empty" "$T/l1" -- \
  $E --noise '0,,5' --output "$T/l1"
expect_error "eval --noise 0x5" 2 "--noise '0x5': '0x5' is not a decimal number" "$T/l2" -- \
  $E --noise 0x5 --output "$T/l2"
expect_error "eval --motion '0,,60'" 2 "--motion '0,,60': element 2 is empty" "$T/l3" -- \
  $E --noise 0 --motion '0,,60' --output "$T/l3"
expect_error "eval --motion '60,'" 2 "--motion '60,': element 2 is empty" "$T/l4" -- \
  $E --noise 0 --motion '60,' --output "$T/l4"
expect_error "eval --motion ',60'" 2 "--motion ',60': element 1 is empty" "$T/l5" -- \
  $E --noise 0 --motion ',60' --output "$T/l5"
expect_error "eval --motion 0x10" 2 "--motion '0x10': '0x10' is not a decimal number" "$T/l6" -- \
  $E --noise 0 --motion 0x10 --output "$T/l6"
expect_error "eval --noise inf" 2 "'inf' is not a decimal number" "$T/l7" -- \
  $E --noise inf --output "$T/l7"
expect_error "simulate --motion translate:0x10,0" 2 "every number in -1e6..1e6" "$T/l8" -- \
  "$LM" simulate --input "$CAVE" --crop --video --frames 2 --motion translate:0x10,0 --output "$T/l8"
expect_error "calibrate --chart-corners with an empty element" 2 "--chart-corners: need 8 numbers" \
  "$T/l9.json" -- "$LM" calibrate "$CAVE" --chart-corners 1,2,,3,4,5,6,7,8 --output "$T/l9.json"
expect_error "fit-auto --models 'a,,b'" 2 "--models 'x,,y': an empty element" "$T/l10.json" -- \
  "$LM" fit-auto --models 'x,,y' --synth 1 --output "$T/l10.json"
expect_error "fit-auto --test-tol '0,'" 2 "--test-tol '0,': element 2 is empty" "$T/l11.json" -- \
  "$LM" fit-auto --models "$MODEL,$MODEL" --synth 1 --test-tol '0,' --output "$T/l11.json"
expect_error "train --lr 0x1p-3" 2 "'lr': must be a finite number" "$T/l12" -- \
  "$LM" train --model linear --data "$CAVE" --lr 0x1p-3 --iterations 1 --output "$T/l12"
expect_error "train --snapshots '1,,2'" 2 "'snapshots': must be minutes separated by commas" \
  "$T/l13" -- "$LM" train --model linear --data "$CAVE" --snapshots '1,,2' --iterations 1 --output "$T/l13"

# ---- conflicting flags, an output named for another format --------------------------------
expect_error "train rt-8-b2 --buckets 1" 2 "'buckets' 1 conflicts with model rt-8-b2" "$T/c1" -- \
  "$LM" train --model rt-8-b2 --buckets 1 --data "$CAVE" --iterations 1 --output "$T/c1"
expect_error "train rt-8-mf3 --frames 1" 2 "'frames' 1 conflicts with model rt-8-mf3" "$T/c2" -- \
  "$LM" train --model rt-8-mf3 --frames 1 --data "$CAVE" --iterations 1 --output "$T/c2"
mkdir -p "$T/out"
expect_error "calibrate --write-chart chart.png" 2 "--write-chart $T/out/chart.png: the chart is a spectral OpenEXR cube; name it .exr" \
  "$T/out/chart.png" -- "$LM" calibrate --write-chart "$T/out/chart.png"

# ---- checks where a mistake was accepted ------------------------------------------------------
# png W H BITS FILE: a grey PNG of constant value 1 at BITS bits per sample
png() {
  python3 - "$@" <<'PY'
import struct, sys, zlib
w, h, bits, out = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
row = b'\x00' + (b'\xff' * ((w * bits + 7) // 8))
chunk = lambda t, d: struct.pack('>I', len(d)) + t + d + struct.pack('>I', zlib.crc32(t + d) & 0xffffffff)
data = b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', w, h, bits, 0, 0, 0, 0))
data += chunk(b'IDAT', zlib.compress(row * h)) + chunk(b'IEND', b'')
open(out, 'wb').write(data)
PY
}
"$LM" simulate --input "$CAVE" --crop --bucket0 --output "$T/sim" > /dev/null 2>&1
check "simulate fixture" [ -s "$T/sim/bucket0/frame_0000.png" ]
WH=$(python3 -c "import struct,sys; b=open(sys.argv[1],'rb').read(24); print(*struct.unpack('>II', b[16:24]))" "$T/sim/frames/frame_0000.png")
png $WH 1 "$T/one_bit.png"
png $WH 8 "$T/b0_8bit.png"
expect_error "infer: a 1-bit PNG frame" 2 "one_bit.png: a 1-bit image; a coded frame is 8- or 16-bit" \
  "$T/k1" -- "$LM" infer --model "$MODEL" --input "$T/one_bit.png" --output "$T/k1"
"$LM" train --model lmmse-b2 --data "$CAVE" --fit-patches 16 --batch 8 --val-patches 1 --quiet \
  --output "$T/b2" > /dev/null 2>&1
check "lmmse-b2 fixture" [ -s "$T/b2/model.safetensors" ]
expect_error "infer: an 8-bit bucket 0 with a 16-bit bucket 1" 2 \
  "b0_8bit.png: bucket 0 is 8-bit, bucket 1 ($T/sim/frames/frame_0000.png) 16-bit" "$T/k2" -- \
  "$LM" infer --model "$T/b2" --input "$T/sim/frames/frame_0000.png" --bucket0 "$T/b0_8bit.png" --output "$T/k2"
printf '{"version": 1, "measure": "grad", "window": [66, 64], "stride": [33, 32], "edges": [], "windows": [1], "models": [{"model": "%s", "cost_s_per_window": 1, "psnr": [30]}]}' \
  "$MODEL" > "$T/auto1.json"
expect_error "infer --auto with one model" 2 "missing or bad field: models (2..8 objects" "$T/k3" -- \
  "$LM" infer --model auto --auto "$T/auto1.json" --input "$T/sim/frames/frame_0000.png" --output "$T/k3"
touch "$T/afile"
printf '{"version": 1, "presets": ["linear"], "data": "%s/nowhere", "iterations": 2}' "$T" > "$T/st1.json"
printf '{"version": 1, "presets": ["linear"], "data": "%s", "iterations": 2}' "$CAVE" > "$T/st2.json"
expect_error "study --dry-run: missing data" 2 "data $T/nowhere: no such file or folder" "$T/k4" -- \
  "$LM" study --config "$T/st1.json" --output "$T/k4" --dry-run
expect_error "study --dry-run: a file as the output" 2 "output $T/afile: exists and is not a folder" \
  "$T/k5" -- "$LM" study --config "$T/st2.json" --output "$T/afile" --dry-run
printf '{"version": 1, "batch": 2, "batch": 4}' > "$T/dup.json"
expect_error "train: a duplicate key in the config" 2 "duplicate object key" "$T/k6" -- \
  "$LM" train --config "$T/dup.json" --model linear --data "$CAVE" --iterations 1 --output "$T/k6"
printf '{"version": 1, "presets": ["linear"], "presets": ["rt-8"], "data": "%s"}' "$CAVE" > "$T/dup2.json"
expect_error "study: a duplicate key in the config" 2 "duplicate object key" "$T/k7" -- \
  "$LM" study --config "$T/dup2.json" --output "$T/k7" --dry-run
mkdir -p "$T/outdir"
expect_error "fit-auto --output onto a folder: at once" 2 "--output $T/outdir: exists and is not a file" \
  "$T/none" -- timeout 10 "$LM" fit-auto --models "$MODEL,$MODEL" --synth 4 --output "$T/outdir"
head -c 3000 "$MODEL" > "$T/trunc.safetensors"
expect_error "a truncated .safetensors: the file's size" 2 "trunc.safetensors: truncated: tensor" "$T/k8" -- \
  "$LM" infer --model "$T/trunc.safetensors" --input "$T/sim/frames/frame_0000.png" --output "$T/k8"
expect_error "a truncated .safetensors: 3000 bytes" 2 "the file has 3000 bytes" "$T/k9" -- \
  "$LM" infer --model "$T/trunc.safetensors" --input "$T/sim/frames/frame_0000.png" --output "$T/k9"
mkdir -p "$T/sc3" && cp -r "$CAVE" "$T/sc3/"
printf '400 abc\n410\n' > "$T/sc3/balloons_crop100.wavelengths.txt"
expect_error "a sidecar's bad token, whole" 2 "balloons_crop100.wavelengths.txt: 'abc' is not a number" \
  "$T/k10.png" -- "$LM" render --input "$T/sc3/balloons_crop100" --output "$T/k10.png"

# ---- a DOE grid beyond what finishes in reasonable time ----------------------------------------
SRC=$(cd "$(dirname "$0")/../.." && pwd)
sed 's/"grid": 1536/"grid": 8192/' "$SRC/data/systems/qdo_default.json" > "$T/doe8192.json"
check "DOE fixture" grep -q '"grid": 8192' "$T/doe8192.json"
expect_error "simulate --doe with grid 8192: refused at once" 2 "grid: must be an integer in 16..4096" \
  "$T/d1" -- timeout -k 5 30 "$LM" simulate --input "$CAVE" --crop --doe "$T/doe8192.json" --threads 1 --output "$T/d1"

finish
