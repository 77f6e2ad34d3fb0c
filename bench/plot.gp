# gnuplot script: docs/bench_preprocess.png from the CSVs written by preprocess_bench.
set datafile separator ","
set key autotitle columnhead
set terminal pngcairo size 1400,520 font "DejaVu Sans,11" noenhanced
set output "docs/bench_preprocess.png"
set multiplot layout 1,2
set title "Preprocess time per step vs scan size (2 cores)"
set xlabel "scan samples (millions)"
set ylabel "seconds"
set logscale xy
set key top left
set grid
plot for [c=5:9] "docs/bench_preprocess_sizes.csv" using ($1*$1/1e6):c with linespoints title columnhead(c), \
     "docs/bench_preprocess_sizes.csv" using ($1*$1/1e6):10 with linespoints lw 3 title "total", \
     1.0 with lines dt 2 lc "red" title "1 s target"
unset logscale
set title "Accuracy vs scan noise (1024 x 1024 scan)"
set xlabel "noise sigma (mm)"
set ylabel "height RMSE (mm)"
set y2label "canvas normal error (deg)"
set y2tics
set ytics nomirror
set key top left
plot "docs/bench_preprocess_noise.csv" using 2:16 with linespoints lw 2 title "height RMSE", \
     "docs/bench_preprocess_noise.csv" using 2:($2*2) with lines dt 2 title "2 x noise (target)", \
     "docs/bench_preprocess_noise.csv" using 2:13 axes x1y2 with linespoints title "normal error (deg)"
unset multiplot
