#!/usr/bin/env bash
# readme_figure.sh — docs/img/lumosaic.png, the README's picture, made with the tool itself:
# a coded frame simulated from a test-split CAVE scene (1 % noise), its reconstruction by the
# demo model (sRGB preview), and the reconstructed spectra at three points against the truth.
# Needs build/ (with liblumosaic.so), ../shared/data, a C compiler and gnuplot (pngcairo).
# Usage: scripts/readme_figure.sh [OUTPUT.png]
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-docs/img/lumosaic.png}
shared=${LM_SHARED_DIR:-../shared}
scene=$shared/data/cave-256/cd_256
model=models/demo/tn160nc-lmmse.safetensors
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT

build/lumosaic simulate --input "$scene" --crop --noise 0.01 --output "$T/sim" --quiet 2>/dev/null ||
  build/lumosaic simulate --input "$scene" --crop --noise 0.01 --output "$T/sim" > /dev/null
build/lumosaic infer --model "$model" --input "$T/sim/frames" --output "$T/rec" > /dev/null
cc -O2 -Iinclude scripts/cube_spectrum.c -Lbuild -llumosaic -Wl,-rpath,"$PWD/build" -o "$T/spec"

# three points of the scene (column row), and their colours in the plot
pts=("75 92" "205 142" "150 60")
cols=("#d62728" "#2ca02c" "#1f77b4")
plot=""
for i in 0 1 2; do
  read -r x y <<< "${pts[$i]}"
  "$T/spec" "$T/sim/gt/gt_0000.exr" "$x" "$y" > "$T/gt$i.dat"
  "$T/spec" "$T/rec/cube_0000.exr" "$x" "$y" > "$T/rec$i.dat"
  plot+="'$T/gt$i.dat' w l lw 2 lc rgb '${cols[$i]}' dt 2 notitle, "
  plot+="'$T/rec$i.dat' w l lw 2 lc rgb '${cols[$i]}' notitle, "
done
# one picture, drawn by gnuplot: the coded frame (stretched x3 for display), the reconstruction
# with the three points marked, the spectra
marks=""
for i in 0 1 2; do
  read -r x y <<< "${pts[$i]}"
  marks+="set object $((i + 1)) circle at $x,$((255 - y)) size 7 front fs empty border lc rgb '${cols[$i]}' lw 2"$'\n'
done
mkdir -p "$(dirname "$out")"
gnuplot <<GP
set terminal pngcairo size 900,290 font "sans,9"
set output "$out"
set multiplot layout 1,3
set size ratio -1
unset key; unset tics; unset border
set xrange [0:255]; set yrange [0:254]
set title "coded frame (one exposure)"
plot "$T/sim/frames/frame_0000.png" binary filetype=png \\
     using (\$1*3 > 255 ? 255 : \$1*3):(\$2*3 > 255 ? 255 : \$2*3):(\$3*3 > 255 ? 255 : \$3*3) with rgbimage
set title "reconstruction (31 bands, shown in sRGB)"
$marks
plot "$T/rec/srgb_0000.png" binary filetype=png with rgbimage
unset object 1; unset object 2; unset object 3
set size noratio
set tics; set border 3; set xtics nomirror; set ytics nomirror
set title "reconstructed (solid), true (dashed)"
set xlabel "wavelength (nm)"; set ylabel "reflectance (scene max = 1)"
set xrange [400:700]; set yrange [0:*]
plot ${plot%, }
unset multiplot
GP
echo "wrote $out ($(du -k "$out" | cut -f1) KB)"
