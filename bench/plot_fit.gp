# gnuplot script: docs/bench_fit.png from docs/bench_fit.csv (written by fit_bench).
set datafile separator ","
set datafile columnheaders
set terminal pngcairo size 1400,520 font "DejaVu Sans,11" noenhanced
set output "docs/bench_fit.png"
set multiplot layout 1,2
set title "Fit time per texel vs held-out PSNR, same 128x128 crop (2 cores)"
set xlabel "fit time per texel (us, wall, 2 threads)"
set ylabel "held-out PSNR (dB)"
set logscale x
set grid
set key bottom right
set yrange [30:45]
set xrange [1:10000]
plot "docs/bench_fit.csv" every ::4::5 using 13:14:1 with labels point pt 7 ps 1.5 offset 1,0.6 left notitle
unset logscale
set autoscale
set title "Where the time goes, 1 Mtexel x 64 photos"
set style data histograms
set style histogram rowstacked
set style fill solid 0.8 border -1
set boxwidth 0.6
set ylabel "seconds"
set xlabel ""
set key top right
set xtics rotate by -20
plot "docs/bench_fit.csv" every ::0::3 using 8:xtic(1) title "load photos", \
     "" every ::0::3 using 9 title "samples + rays", \
     "" every ::0::3 using 10 title "fit", \
     "" every ::0::3 using 11 title "write maps"
unset multiplot
