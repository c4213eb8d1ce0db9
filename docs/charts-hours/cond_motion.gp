# cond_motion.gp — written by lumosaic study; run `gnuplot cond_motion.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "cond_motion.png"
set title "PSNR under motion (crosses: 3 dB below the model's clean PSNR)"
set xlabel "motion (px/s)"
set ylabel "PSNR (dB)"
set grid
set key outside right top
set datafile missing "NaN"
plot "cond_motion_linear.dat" using 1:2 with linespoints lw 1.5 lc 1 title "linear", \
     "cond_motion_rt-8.dat" using 1:2 with linespoints lw 1.5 lc 2 title "rt-8", \
     "cond_motion_rt-16.dat" using 1:2 with linespoints lw 1.5 lc 3 title "rt-16", \
     "cond_motion_srnet-tiny.dat" using 1:2 with linespoints lw 1.5 lc 4 title "srnet-tiny", \
     "cond_motion_srnet.dat" using 1:2 with linespoints lw 1.5 lc 5 title "srnet", \
     "cond_motion_mcan-tiny.dat" using 1:2 with linespoints lw 1.5 lc 6 title "mcan-tiny", \
     "cond_motion_mcan.dat" using 1:2 with linespoints lw 1.5 lc 7 title "mcan", \
     "cond_motion_han-tiny.dat" using 1:2 with linespoints lw 1.5 lc 8 title "han-tiny", \
     "cond_motion_han-small.dat" using 1:2 with linespoints lw 1.5 lc 9 title "han-small"
set terminal svg size 960,640 dynamic noenhanced
set output "cond_motion.svg"
replot
set output
