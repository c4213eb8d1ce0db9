# motion.gp — written by lumosaic study; run `gnuplot motion.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "motion.png"
set title "PSNR against motion speed: with (solid) and without (dashed) temporal alignment"
set xlabel "speed (px/s)"
set ylabel "PSNR (dB)"
set grid
set key outside right top
plot "cond_motion_linear.dat" using 1:2 with linespoints lw 1.5 lc 1 title "linear aligned", \
     "cond_motion_linear.dat" using 1:5 with linespoints dt 2 lw 1.5 lc 1 title "linear unaligned", \
     "cond_motion_rt-8.dat" using 1:2 with linespoints lw 1.5 lc 2 title "rt-8 aligned", \
     "cond_motion_rt-8.dat" using 1:5 with linespoints dt 2 lw 1.5 lc 2 title "rt-8 unaligned", \
     "cond_motion_rt-16.dat" using 1:2 with linespoints lw 1.5 lc 3 title "rt-16 aligned", \
     "cond_motion_rt-16.dat" using 1:5 with linespoints dt 2 lw 1.5 lc 3 title "rt-16 unaligned", \
     "cond_motion_srnet-tiny.dat" using 1:2 with linespoints lw 1.5 lc 4 title "srnet-tiny aligned", \
     "cond_motion_srnet-tiny.dat" using 1:5 with linespoints dt 2 lw 1.5 lc 4 title "srnet-tiny unaligned", \
     "cond_motion_srnet.dat" using 1:2 with linespoints lw 1.5 lc 5 title "srnet aligned", \
     "cond_motion_srnet.dat" using 1:5 with linespoints dt 2 lw 1.5 lc 5 title "srnet unaligned", \
     "cond_motion_mcan-tiny.dat" using 1:2 with linespoints lw 1.5 lc 6 title "mcan-tiny aligned", \
     "cond_motion_mcan-tiny.dat" using 1:5 with linespoints dt 2 lw 1.5 lc 6 title "mcan-tiny unaligned", \
     "cond_motion_mcan.dat" using 1:2 with linespoints lw 1.5 lc 7 title "mcan aligned", \
     "cond_motion_mcan.dat" using 1:5 with linespoints dt 2 lw 1.5 lc 7 title "mcan unaligned", \
     "cond_motion_han-tiny.dat" using 1:2 with linespoints lw 1.5 lc 8 title "han-tiny aligned", \
     "cond_motion_han-tiny.dat" using 1:5 with linespoints dt 2 lw 1.5 lc 8 title "han-tiny unaligned", \
     "cond_motion_han-small.dat" using 1:2 with linespoints lw 1.5 lc 9 title "han-small aligned", \
     "cond_motion_han-small.dat" using 1:5 with linespoints dt 2 lw 1.5 lc 9 title "han-small unaligned"
set terminal svg size 960,640 dynamic noenhanced
set output "motion.svg"
replot
set output
