# train_loss.gp — written by lumosaic study; run `gnuplot train_loss.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "train_loss.png"
set title "Training loss (L1, 33 channels); moving average over ~1 % of the run"
set xlabel "iteration"
set ylabel "loss"
set grid
set key outside right top
set logscale y
plot "loss_lmmse.dat" using 1:3 with lines lw 1.5 title "lmmse", \
     "loss_linear.dat" using 1:3 with lines lw 1.5 title "linear", \
     "loss_rt-8.dat" using 1:3 with lines lw 1.5 title "rt-8", \
     "loss_rt-8+lmmse.dat" using 1:3 with lines lw 1.5 title "rt-8+lmmse", \
     "loss_rt-16.dat" using 1:3 with lines lw 1.5 title "rt-16", \
     "loss_rt-16+lmmse.dat" using 1:3 with lines lw 1.5 title "rt-16+lmmse", \
     "loss_han-tiny.dat" using 1:3 with lines lw 1.5 title "han-tiny", \
     "loss_han-tiny+lmmse.dat" using 1:3 with lines lw 1.5 title "han-tiny+lmmse", \
     "loss_mcan-tiny.dat" using 1:3 with lines lw 1.5 title "mcan-tiny", \
     "loss_srnet-tiny.dat" using 1:3 with lines lw 1.5 title "srnet-tiny", \
     "loss_lmmse-rf.dat" using 1:3 with lines lw 1.5 title "lmmse-rf"
set terminal svg size 960,640 dynamic noenhanced
set output "train_loss.svg"
replot
set output
