# gnuplot script: docs/bench_pack.png from docs/bench_pack.csv (written by pack_bench).
set datafile separator ","
set datafile columnheaders
set terminal pngcairo size 900,560 font "DejaVu Sans,11" noenhanced
set output "docs/bench_pack.png"
set title "Pack size vs held-out relighting PSNR (read back from the pack)"
set xlabel "bytes per texel (file size / texels, after ZIP)"
set ylabel "held-out PSNR (dB)"
set grid
set key bottom right
stats "docs/bench_pack.csv" using 12 nooutput
float_psnr = STATS_max
set arrow from graph 0, first float_psnr to graph 1, first float_psnr nohead dt 2 lc rgb "gray40"
set arrow from graph 0, first float_psnr - 1 to graph 1, first float_psnr - 1 nohead dt 3 lc rgb "red"
set arrow from 10, graph 0 to 10, graph 1 nohead dt 3 lc rgb "red"
sweep(s, y) = (strcol(2) eq "sweep") ? y : NaN
single(s, y) = (strcol(2) eq "one group") ? y : NaN
plot "docs/bench_pack.csv" using 7:(sweep(0, $10)) with linespoints pt 7 ps 1.3 lc rgb "#1f77b4" title "half, then fewer bits in every group", \
     "" using 7:(sweep(0, $10)):1 with labels offset 0.8,0.7 left notitle, \
     "" using 7:(single(0, $10)) with points pt 6 ps 1.3 lc rgb "#ff7f0e" title "one group quantised alone", \
     "" using 7:(single(0, $10)):1 with labels offset 0.8,-0.7 left tc rgb "#ff7f0e" notitle, \
     NaN with lines dt 2 lc rgb "gray40" title "float maps (no pack)", \
     NaN with lines dt 3 lc rgb "red" title "targets: <= 10 bytes/texel, loss <= 1 dB"
