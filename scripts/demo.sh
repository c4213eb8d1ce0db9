#!/usr/bin/env bash
# demo.sh — the README's main job on a small bundled default: simulate a short coded video
# (3 frames, the scene moving 60 px/s, 1 % noise; both buckets) from a real CAVE scene of the
# held-out test split in ../shared (never trained on), reconstruct it with temporal alignment
# with the two bundled models (models/demo/): the single-bucket model on bucket 1, the
# two-bucket model on both buckets; write spectral EXR cubes and sRGB pictures, then print
# both models' metrics side by side on the three test-split scenes (PSNR/SSIM/MAE/SAM at
# several noise levels) and their rainbow scene's peak-wavelength error.
# Usage: scripts/demo.sh [OUTPUT_DIR]   (default: demo_out; it is replaced)
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x build/lumosaic ] || scripts/setup.sh

out=${1:-demo_out}
shared=${LM_SHARED_DIR:-../shared}
scene="$shared/data/cave-256/cd_256"
model=models/demo/tn160nc-lmmse.safetensors
model_b2=models/demo/tn96nc-b2-lmmseb2.safetensors
[ -d "$scene" ] || { echo "demo: scene $scene not found (set LM_SHARED_DIR)" >&2; exit 2; }

rm -rf "$out"
mkdir -p "$out"
echo "== simulate: 3 coded frames of $(basename "$scene"), both buckets (moving, 1 % noise) -> $out/coded"
build/lumosaic simulate --input "$scene" --crop --output "$out/coded" --video --frames 3 \
    --motion translate:60,0 --noise 0.01 --seed 1 --bucket0
echo "== reconstruct bucket 1 with $model (aligned) -> $out/recon"
build/lumosaic infer --model "$model" --input "$out/coded/frames" --output "$out/recon"
echo "== reconstruct both buckets with $model_b2 (aligned) -> $out/recon_b2"
build/lumosaic infer --model "$model_b2" --input "$out/coded/frames" \
    --bucket0 "$out/coded/bucket0" --output "$out/recon_b2"
echo "== metrics on the test split (cd, fake_and_real_tomatoes, real_and_fake_apples)"
for m in "$model" "$model_b2"; do
  o="$out/eval"; [ "$m" = "$model_b2" ] && o="$out/eval_b2"
  build/lumosaic eval --model "$m" "$shared/data/cave" "$shared/data/cave-256" --split test \
      --noise 0,5,10,20 --rainbow 128 --output "$o" > "$o.txt" 2> "$o.log" ||
    { cat "$o.log" >&2; exit 1; }
done
# the two tables side by side: noise level, then PSNR / SSIM / SAM of each model
awk -F, 'NR == FNR && FNR > 1 && $1 == "mean" { a[$2] = sprintf("%7.2f %6.3f %6.1f", $3, $4, $6); next }
  FNR > 1 && $1 == "mean" { b[$2] = sprintf("%7.2f %6.3f %6.1f", $3, $4, $6); k[++n] = $2 }
  END { printf "%-8s | %-23s | %-23s\n", "", "one bucket", "two buckets";
        printf "%-8s | %7s %6s %6s | %7s %6s %6s\n", "noise %", "PSNR", "SSIM", "SAM", "PSNR", "SSIM", "SAM";
        for (i = 1; i <= n; i++) printf "%-8s | %s | %s\n", k[i], a[k[i]], b[k[i]] }' \
  "$out/eval/eval.csv" "$out/eval_b2/eval.csv"
for m in eval eval_b2; do grep "^rainbow" "$out/$m.txt" | sed "s/^/$m: /"; done
echo "== written: $out/recon/ and $out/recon_b2/: cube_000N.exr (31 bands, 400-700 nm), srgb_000N.png;"
echo "   ground truth: $out/coded/gt/; metrics: $out/eval*/eval.json, eval.csv"
