#!/usr/bin/env bash
# demo.sh — the README's main job on a small bundled default: simulate a short coded video
# (3 frames, the scene moving 60 px/s, 1 % noise) from a real CAVE scene of the held-out test split
# in ../shared (never trained on), reconstruct it with the bundled demo model (models/demo/) with
# temporal alignment, write spectral EXR cubes and sRGB pictures, then print the model's metrics
# on the three test-split scenes (PSNR/SSIM/MAE/SAM at several noise levels) and the rainbow
# scene's peak-wavelength error.
# Usage: scripts/demo.sh [OUTPUT_DIR]   (default: demo_out; it is replaced)
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x build/lumosaic ] || scripts/setup.sh

out=${1:-demo_out}
shared=${LM_SHARED_DIR:-../shared}
scene="$shared/data/cave-256/cd_256"
model=models/demo/rt16nc-lmmse.safetensors
[ -d "$scene" ] || { echo "demo: scene $scene not found (set LM_SHARED_DIR)" >&2; exit 2; }

rm -rf "$out"
mkdir -p "$out"
echo "== simulate: 3 coded frames of $(basename "$scene") (moving, 1 % noise) -> $out/coded"
build/lumosaic simulate --input "$scene" --crop --output "$out/coded" --video --frames 3 \
    --motion translate:60,0 --noise 0.01 --seed 1
echo "== reconstruct with $model (aligned) -> $out/recon"
build/lumosaic infer --model "$model" --input "$out/coded/frames" --output "$out/recon"
echo "== metrics of $model on the test split (cd, fake_and_real_tomatoes, real_and_fake_apples)"
build/lumosaic eval --model "$model" "$shared/data/cave" "$shared/data/cave-256" --split test \
    --noise 0,5,10,20 --rainbow 128 --output "$out/eval"
echo "== written: $out/recon/cube_000N.exr (31 bands, 400-700 nm), $out/recon/srgb_000N.png;"
echo "   ground truth: $out/coded/gt/; metrics: $out/eval/eval.json, eval.csv"
