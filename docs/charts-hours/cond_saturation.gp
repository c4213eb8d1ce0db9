# cond_saturation.gp — written by lumosaic study; run `gnuplot cond_saturation.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "cond_saturation.png"
set title "PSNR under saturation (crosses: 3 dB below the model's clean PSNR)"
set xlabel "exposure (x, clipped at full well)"
set ylabel "PSNR (dB)"
set grid
set key outside right top
set datafile missing "NaN"
plot "cond_saturation_linear.dat" using 1:2 with linespoints lw 1.5 lc 1 title "linear", \
     "cond_saturation_rt-8.dat" using 1:2 with linespoints lw 1.5 lc 2 title "rt-8", \
     "cond_saturation_rt-16.dat" using 1:2 with linespoints lw 1.5 lc 3 title "rt-16", \
     "cond_saturation_srnet-tiny.dat" using 1:2 with linespoints lw 1.5 lc 4 title "srnet-tiny", \
     "cond_saturation_srnet.dat" using 1:2 with linespoints lw 1.5 lc 5 title "srnet", \
     "cond_saturation_mcan-tiny.dat" using 1:2 with linespoints lw 1.5 lc 6 title "mcan-tiny", \
     "cond_saturation_mcan.dat" using 1:2 with linespoints lw 1.5 lc 7 title "mcan", \
     "cond_saturation_han-tiny.dat" using 1:2 with linespoints lw 1.5 lc 8 title "han-tiny", \
     "cond_saturation_han-small.dat" using 1:2 with linespoints lw 1.5 lc 9 title "han-small", \
     "cond_saturation_mst.dat" using 1:2 with linespoints lw 1.5 lc 10 title "mst", \
     "fail_saturation.dat" using 1:2 with points pt 2 ps 2 lw 2 lc rgb "black" title "3-dB point"
set terminal svg size 960,640 dynamic noenhanced
set output "cond_saturation.svg"
replot
set output
