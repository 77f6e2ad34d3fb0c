# gnuplot script: docs/bench_viewer.png from docs/bench_viewer_table1.csv and
# docs/bench_viewer_table2.csv (written by viewer_bench). Table 1 rows come 10 per view (the
# technique order of viewer_bench), views in the order close/framed/far x face/grazing.
set datafile separator ","
set datafile columnheaders
set terminal pngcairo size 1800,560 font "DejaVu Sans,11" noenhanced
set output "docs/bench_viewer.png"
set multiplot layout 1,3
t1 = "docs/bench_viewer_table1.csv"
views = "close-face close-grazing framed-face framed-grazing far-face far-grazing"
set grid
set xtics rotate by -30
set key bottom left font ",9"

set title "Table 1: frame time by technique x view (llvmpipe, 2 cores)"
set ylabel "ms per frame (Draw + glFinish, min of 7)"
set logscale y
plot for [v=0:5] t1 every ::(10*v)::(10*v+9) using 0:3:xtic(2) with linespoints pt 7 \
     title word(views, v + 1)
unset logscale y

set title "Table 1: image error vs the Embree reference (4x4 box-filtered)"
set ylabel "PSNR (dB), peak = paper white"
set yrange [15:*]
plot for [v=0:5] t1 every ::(10*v)::(10*v+9) using 0:8:xtic(2) with linespoints pt 7 \
     title word(views, v + 1), \
     35 with lines dt 2 lc rgb "black" title "35 dB"
set autoscale y

set title "Table 2: hybrid+adaptive by box size n (framed view)"
set xtics norotate
set xlabel "box size n (texels)"
set ylabel "ms per frame"
set yrange [0:*]
set y2range [0:*]
set logscale x
set y2label "boxes drawn"
set y2tics
plot "docs/bench_viewer_table2.csv" every 2::0 using 1:5 with linespoints pt 7 title "face, ms", \
     "" every 2::1 using 1:5 with linespoints pt 7 title "grazing, ms", \
     "" every 2::0 using 1:4 axes x1y2 with linespoints dt 2 pt 6 title "face, boxes drawn", \
     "" every 2::1 using 1:4 axes x1y2 with linespoints dt 2 pt 6 title "grazing, boxes drawn"
unset multiplot
