# cond_photons.gp — written by lumosaic study; run `gnuplot cond_photons.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "cond_photons.png"
set title "PSNR under photons (crosses: 3 dB below the model's clean PSNR)"
set xlabel "photo-electrons at full scale (Poisson)"
set ylabel "PSNR (dB)"
set grid
set key outside right top
set logscale x
set xrange [*:*] reverse
set datafile missing "NaN"
plot "cond_photons_linear.dat" using 1:2 with linespoints lw 1.5 lc 1 title "linear", \
     "cond_photons_rt-8.dat" using 1:2 with linespoints lw 1.5 lc 2 title "rt-8", \
     "cond_photons_rt-16.dat" using 1:2 with linespoints lw 1.5 lc 3 title "rt-16", \
     "cond_photons_srnet-tiny.dat" using 1:2 with linespoints lw 1.5 lc 4 title "srnet-tiny", \
     "cond_photons_srnet.dat" using 1:2 with linespoints lw 1.5 lc 5 title "srnet", \
     "cond_photons_mcan-tiny.dat" using 1:2 with linespoints lw 1.5 lc 6 title "mcan-tiny", \
     "cond_photons_mcan.dat" using 1:2 with linespoints lw 1.5 lc 7 title "mcan", \
     "cond_photons_han-tiny.dat" using 1:2 with linespoints lw 1.5 lc 8 title "han-tiny", \
     "cond_photons_han-small.dat" using 1:2 with linespoints lw 1.5 lc 9 title "han-small", \
     "cond_photons_mst.dat" using 1:2 with linespoints lw 1.5 lc 10 title "mst"
set terminal svg size 960,640 dynamic noenhanced
set output "cond_photons.svg"
replot
set output
