# rainbow_peaks.gp — written by lumosaic study; run `gnuplot rainbow_peaks.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "rainbow_peaks.png"
set title "Rainbow scene: recovered against true peak wavelength per row"
set xlabel "true peak (nm)"
set ylabel "recovered peak (nm)"
set grid
set key outside right top
set xrange [400:700]
set yrange [380:720]
plot x with lines dt 2 lc rgb "gray40" title "ideal", \
     "rainbow_lmmse.dat" using 1:2 with lines lw 1.5 title "lmmse", \
     "rainbow_linear.dat" using 1:2 with lines lw 1.5 title "linear", \
     "rainbow_rt-8.dat" using 1:2 with lines lw 1.5 title "rt-8", \
     "rainbow_rt-8+lmmse.dat" using 1:2 with lines lw 1.5 title "rt-8+lmmse", \
     "rainbow_rt-16.dat" using 1:2 with lines lw 1.5 title "rt-16", \
     "rainbow_rt-16+lmmse.dat" using 1:2 with lines lw 1.5 title "rt-16+lmmse", \
     "rainbow_han-tiny.dat" using 1:2 with lines lw 1.5 title "han-tiny", \
     "rainbow_han-tiny+lmmse.dat" using 1:2 with lines lw 1.5 title "han-tiny+lmmse", \
     "rainbow_mcan-tiny.dat" using 1:2 with lines lw 1.5 title "mcan-tiny", \
     "rainbow_srnet-tiny.dat" using 1:2 with lines lw 1.5 title "srnet-tiny", \
     "rainbow_lmmse-rf.dat" using 1:2 with lines lw 1.5 title "lmmse-rf"
set terminal svg size 960,640 dynamic noenhanced
set output "rainbow_peaks.svg"
replot
set output
