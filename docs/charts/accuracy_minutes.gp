# accuracy_minutes.gp — written by lumosaic study; run `gnuplot accuracy_minutes.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "accuracy_minutes.png"
set title "Held-out accuracy against training time (solid: noise 0 %, dashed: 10 %)"
set xlabel "CPU minutes of training (this machine)"
set ylabel "PSNR (dB)"
set grid
set key outside right top
set logscale x
plot "minutes_lmmse.dat" using 1:2 with linespoints lw 1.5 pt 7 lc 1 title "lmmse", \
     "minutes_lmmse.dat" using 1:3 with linespoints dt 2 pt 6 lc 1 notitle, \
     "minutes_linear.dat" using 1:2 with linespoints lw 1.5 pt 7 lc 2 title "linear", \
     "minutes_linear.dat" using 1:3 with linespoints dt 2 pt 6 lc 2 notitle, \
     "minutes_rt-8.dat" using 1:2 with linespoints lw 1.5 pt 7 lc 3 title "rt-8", \
     "minutes_rt-8.dat" using 1:3 with linespoints dt 2 pt 6 lc 3 notitle, \
     "minutes_rt-8+lmmse.dat" using 1:2 with linespoints lw 1.5 pt 7 lc 4 title "rt-8+lmmse", \
     "minutes_rt-8+lmmse.dat" using 1:3 with linespoints dt 2 pt 6 lc 4 notitle, \
     "minutes_rt-16.dat" using 1:2 with linespoints lw 1.5 pt 7 lc 5 title "rt-16", \
     "minutes_rt-16.dat" using 1:3 with linespoints dt 2 pt 6 lc 5 notitle, \
     "minutes_rt-16+lmmse.dat" using 1:2 with linespoints lw 1.5 pt 7 lc 6 title "rt-16+lmmse", \
     "minutes_rt-16+lmmse.dat" using 1:3 with linespoints dt 2 pt 6 lc 6 notitle, \
     "minutes_han-tiny.dat" using 1:2 with linespoints lw 1.5 pt 7 lc 7 title "han-tiny", \
     "minutes_han-tiny.dat" using 1:3 with linespoints dt 2 pt 6 lc 7 notitle, \
     "minutes_han-tiny+lmmse.dat" using 1:2 with linespoints lw 1.5 pt 7 lc 8 title "han-tiny+lmmse", \
     "minutes_han-tiny+lmmse.dat" using 1:3 with linespoints dt 2 pt 6 lc 8 notitle, \
     "minutes_mcan-tiny.dat" using 1:2 with linespoints lw 1.5 pt 7 lc 9 title "mcan-tiny", \
     "minutes_mcan-tiny.dat" using 1:3 with linespoints dt 2 pt 6 lc 9 notitle, \
     "minutes_srnet-tiny.dat" using 1:2 with linespoints lw 1.5 pt 7 lc 10 title "srnet-tiny", \
     "minutes_srnet-tiny.dat" using 1:3 with linespoints dt 2 pt 6 lc 10 notitle, \
     "minutes_lmmse-rf.dat" using 1:2 with linespoints lw 1.5 pt 7 lc 11 title "lmmse-rf", \
     "minutes_lmmse-rf.dat" using 1:3 with linespoints dt 2 pt 6 lc 11 notitle
set terminal svg size 960,640 dynamic noenhanced
set output "accuracy_minutes.svg"
replot
set output
