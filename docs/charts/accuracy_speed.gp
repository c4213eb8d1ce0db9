# accuracy_speed.gp — written by lumosaic study; run `gnuplot accuracy_speed.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "accuracy_speed.png"
set title "Accuracy against speed (dashed: Pareto front)"
set xlabel "seconds per 640 x 480 frame"
set ylabel "PSNR (dB)"
set grid
set key outside right top
set logscale x
set offsets graph 0.05, graph 0.15, graph 0.08, graph 0.08
plot "speed.dat" using 2:3 with points pt 7 ps 1.5 lc 1 title "noise 0 %", \
     "speed.dat" using 2:3:1 with labels offset 1,0.7 left tc lt 1 notitle, \
     "pareto_0.dat" using 1:2 with lines dt 2 lw 1.5 lc 1 title "Pareto front, noise 0 %", \
     "speed.dat" using 2:4 with points pt 9 ps 1.5 lc 2 title "noise 10 %", \
     "speed.dat" using 2:4:1 with labels offset 1,0.7 left tc lt 2 notitle, \
     "pareto_1.dat" using 1:2 with lines dt 2 lw 1.5 lc 2 title "Pareto front, noise 10 %"
set terminal svg size 960,640 dynamic noenhanced
set output "accuracy_speed.svg"
replot
set output
