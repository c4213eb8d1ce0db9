# train_val_psnr.gp — written by lumosaic study; run `gnuplot train_val_psnr.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "train_val_psnr.png"
set title "Validation PSNR during training"
set xlabel "iteration"
set ylabel "PSNR (dB)"
set grid
set key outside right top
plot "val_lmmse.dat" using 1:2 with linespoints lw 1.5 title "lmmse", \
     "val_linear.dat" using 1:2 with linespoints lw 1.5 title "linear", \
     "val_rt-8.dat" using 1:2 with linespoints lw 1.5 title "rt-8", \
     "val_rt-8+lmmse.dat" using 1:2 with linespoints lw 1.5 title "rt-8+lmmse", \
     "val_rt-16.dat" using 1:2 with linespoints lw 1.5 title "rt-16", \
     "val_rt-16+lmmse.dat" using 1:2 with linespoints lw 1.5 title "rt-16+lmmse", \
     "val_han-tiny.dat" using 1:2 with linespoints lw 1.5 title "han-tiny", \
     "val_han-tiny+lmmse.dat" using 1:2 with linespoints lw 1.5 title "han-tiny+lmmse", \
     "val_mcan-tiny.dat" using 1:2 with linespoints lw 1.5 title "mcan-tiny", \
     "val_srnet-tiny.dat" using 1:2 with linespoints lw 1.5 title "srnet-tiny", \
     "val_lmmse-rf.dat" using 1:2 with linespoints lw 1.5 title "lmmse-rf"
set terminal svg size 960,640 dynamic noenhanced
set output "train_val_psnr.svg"
replot
set output
