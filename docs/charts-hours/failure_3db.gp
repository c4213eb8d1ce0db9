# failure_3db.gp — written by lumosaic study; run `gnuplot failure_3db.gp` in this folder.
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
    set terminal pngcairo size 960,640 noenhanced font "sans,11"
} else {
    set terminal png size 960,640 noenhanced
}
set output "failure_3db.png"
set title ""
set xlabel ""
set ylabel ""
set grid
set key outside right top
set datafile missing "NaN"
set style fill solid 0.5
set boxwidth 0.6
set xtics rotate by -30
set xlabel ""
set offsets 0.5, 0.5, graph 0.35, 0
unset key
set multiplot layout 2,3 title "Level at which each model loses 3 dB against its own clean PSNR (label '> x': never, up to the last level x)"
set title "photons"
set ylabel "photo-electrons at full scale (Poisson)"
set logscale y
set yrange [*:*]
plot "failure_photons.dat" using 1:3:xtic(2) with boxes fs solid 0.5 notitle, \
     "" using 1:3:4 with labels rotate by 90 left offset 0,0.4 font ",9" notitle
set title "saturation"
set ylabel "exposure (x, clipped at full well)"
unset logscale y
set yrange [0:*]
plot "failure_saturation.dat" using 1:3:xtic(2) with boxes fs solid 0.5 notitle, \
     "" using 1:3:4 with labels rotate by 90 left offset 0,0.4 font ",9" notitle
set title "led_gain"
set ylabel "LED gain error (+- %)"
unset logscale y
set yrange [0:*]
plot "failure_led_gain.dat" using 1:3:xtic(2) with boxes fs solid 0.5 notitle, \
     "" using 1:3:4 with labels rotate by 90 left offset 0,0.4 font ",9" notitle
set title "dead_pixels"
set ylabel "dead pixels (% of the frame)"
unset logscale y
set yrange [0:*]
plot "failure_dead_pixels.dat" using 1:3:xtic(2) with boxes fs solid 0.5 notitle, \
     "" using 1:3:4 with labels rotate by 90 left offset 0,0.4 font ",9" notitle
set title "motion"
set ylabel "motion (px/s)"
unset logscale y
set yrange [0:*]
plot "failure_motion.dat" using 1:3:xtic(2) with boxes fs solid 0.5 notitle, \
     "" using 1:3:4 with labels rotate by 90 left offset 0,0.4 font ",9" notitle
unset multiplot
set terminal svg size 960,640 dynamic noenhanced
set output "failure_3db.svg"
set multiplot layout 2,3 title "Level at which each model loses 3 dB against its own clean PSNR (label '> x': never, up to the last level x)"
set title "photons"
set ylabel "photo-electrons at full scale (Poisson)"
set logscale y
set yrange [*:*]
plot "failure_photons.dat" using 1:3:xtic(2) with boxes fs solid 0.5 notitle, \
     "" using 1:3:4 with labels rotate by 90 left offset 0,0.4 font ",9" notitle
set title "saturation"
set ylabel "exposure (x, clipped at full well)"
unset logscale y
set yrange [0:*]
plot "failure_saturation.dat" using 1:3:xtic(2) with boxes fs solid 0.5 notitle, \
     "" using 1:3:4 with labels rotate by 90 left offset 0,0.4 font ",9" notitle
set title "led_gain"
set ylabel "LED gain error (+- %)"
unset logscale y
set yrange [0:*]
plot "failure_led_gain.dat" using 1:3:xtic(2) with boxes fs solid 0.5 notitle, \
     "" using 1:3:4 with labels rotate by 90 left offset 0,0.4 font ",9" notitle
set title "dead_pixels"
set ylabel "dead pixels (% of the frame)"
unset logscale y
set yrange [0:*]
plot "failure_dead_pixels.dat" using 1:3:xtic(2) with boxes fs solid 0.5 notitle, \
     "" using 1:3:4 with labels rotate by 90 left offset 0,0.4 font ",9" notitle
set title "motion"
set ylabel "motion (px/s)"
unset logscale y
set yrange [0:*]
plot "failure_motion.dat" using 1:3:xtic(2) with boxes fs solid 0.5 notitle, \
     "" using 1:3:4 with labels rotate by 90 left offset 0,0.4 font ",9" notitle
unset multiplot
set output
