#!/usr/bin/env bash
# inputs.sh — what every command does with its input paths and list options before any work:
# a FIFO, a device or a folder where a file is expected is refused at once (exit 2, one line
# naming it; nothing is opened, so nothing blocks), for frames, cubes, models, system files,
# configs, calibrations, DOE descriptions, spectra and wavelength sidecars; a wavelength sidecar
# that is a folder is an error too. Every list option is parsed strictly (no empty element, no
# hexadecimal); flags that contradict the preset and an output named for another format are
# one-line errors.
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
# each under a timeout: before, each of these blocked in open() for ever
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

finish
