# narrowband.gp — written by lumosaic study; run `gnuplot narrowband.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "narrowband.png"
set title "Rainbow accuracy of rt-8 against the synthetic share of training"
set xlabel "narrowband synthetic samples in training (%)"
set ylabel "rainbow mean peak error (nm)"
set grid
set key outside right top
set y2label "PSNR (dB)"
set y2tics
set ytics nomirror
set xrange [-5:105]
plot "narrowband.dat" using 1:2 with linespoints lw 2 pt 7 title "rainbow peak error", \
     "" using 1:3 axes x1y2 with linespoints dt 2 pt 5 title "rainbow PSNR", \
     "" using 1:4 axes x1y2 with linespoints dt 3 pt 9 title "held-out PSNR"
set terminal svg size 960,640 dynamic noenhanced
set output "narrowband.svg"
replot
set output
