# noise_sam.gp — written by lumosaic study; run `gnuplot noise_sam.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "noise_sam.png"
set title "SAM (degrees) against noise, held-out scenes"
set xlabel "noise (% of the largest clean value)"
set ylabel "SAM (degrees)"
set grid
set key outside right top
plot "noise_lmmse.dat" using 1:5 with linespoints lw 1.5 title "lmmse", \
     "noise_linear.dat" using 1:5 with linespoints lw 1.5 title "linear", \
     "noise_rt-8.dat" using 1:5 with linespoints lw 1.5 title "rt-8", \
     "noise_rt-8+lmmse.dat" using 1:5 with linespoints lw 1.5 title "rt-8+lmmse", \
     "noise_rt-16.dat" using 1:5 with linespoints lw 1.5 title "rt-16", \
     "noise_rt-16+lmmse.dat" using 1:5 with linespoints lw 1.5 title "rt-16+lmmse", \
     "noise_han-tiny.dat" using 1:5 with linespoints lw 1.5 title "han-tiny", \
     "noise_han-tiny+lmmse.dat" using 1:5 with linespoints lw 1.5 title "han-tiny+lmmse", \
     "noise_mcan-tiny.dat" using 1:5 with linespoints lw 1.5 title "mcan-tiny", \
     "noise_srnet-tiny.dat" using 1:5 with linespoints lw 1.5 title "srnet-tiny", \
     "noise_lmmse-rf.dat" using 1:5 with linespoints lw 1.5 title "lmmse-rf"
set terminal svg size 960,640 dynamic noenhanced
set output "noise_sam.svg"
replot
set output
