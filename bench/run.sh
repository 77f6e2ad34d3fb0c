#!/usr/bin/env bash
# Runs the benchmarks and redraws the plots in docs/. Extra arguments go to preprocess_bench
# (e.g. --sizes=512,2048 for a quick run). Run on an otherwise idle machine: ratios and times
# are only comparable within one run.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
./build/bin/preprocess_bench --csv-dir=docs "$@" | tee docs/bench_preprocess.txt
gnuplot bench/plot.gp && echo "wrote docs/bench_preprocess.png"
./build/bin/registration_bench --csv-dir=docs | tee docs/bench_registration.txt
./build/bin/brdf_fit_bench --csv-dir=docs | tee docs/bench_brdf_fit.txt
./build/bin/fit_bench --csv-dir=docs | tee docs/bench_fit.txt
gnuplot bench/plot_fit.gp && echo "wrote docs/bench_fit.png"
./build/bin/pack_bench --csv-dir=docs | tee docs/bench_pack.txt
gnuplot bench/plot_pack.gp && echo "wrote docs/bench_pack.png"
./build/bin/viewer_bench --csv-dir=docs | tee docs/bench_viewer.txt
gnuplot bench/plot_viewer.gp && echo "wrote docs/bench_viewer.png"
./build/bin/style_bench --csv-dir=docs | tee docs/bench_style.txt
# The real RTI capture: PTM / HSH2 / HSH3 and digitize's fit, held-out 8-bit sRGB PSNR and time.
if [ -d ../shared/data/rti_icon ]; then
  ./build/bin/rti_bench --data=../shared/data/rti_icon --csv-dir=docs
else
  echo "rti_bench skipped: ../shared/data/rti_icon is not here"
fi
./build/bin/photometric_stereo_bench | tee docs/bench_photometric_stereo.txt
