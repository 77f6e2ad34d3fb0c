#!/usr/bin/env bash
# `digitize preprocess` whole against in tiles (--tile-texels), canvas size against wall time and
# peak RSS (GNU time's %M: the kernel's maximum resident set), and how far the tiled canvas is
# from the whole one (docs/benchmarks.md, "Tiles").
#   bench/preprocess_tiled_bench.sh [SIZE ...]   texels along the canvas's longer side
#                                                (default 4096 8192)
# Env: BIN (default build/bin/digitize), TILE (default 2048), SCAN_SCALE (scan samples per texel
# along each side, in tenths, default 10: an n x 0.75 n scan), WHOLE_MAX (largest size also
# preprocessed whole and compared, default 16384), WORK (scratch folder, default a new one under
# /tmp, removed after), CSV (default docs/bench_preprocess_tiled.csv).
# The painting is 400 x 300 mm at n texels (pitch 400 / n mm), scanned only (no photos). The
# tiled run's canvas pass reads every k-th sample (k: at most 2^24 samples), so its frame is not
# the whole run's to the bit: heights are compared by idiff (RMS and largest difference, texels
# over 0.01 mm), the mask by the texels that differ.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
root=$PWD
bin=${BIN:-$root/build/bin/digitize}
sizes=("$@")
[ ${#sizes[@]} -gt 0 ] || sizes=(4096 8192)
tile=${TILE:-2048}
scan_scale=${SCAN_SCALE:-10}
whole_max=${WHOLE_MAX:-16384}
csv=${CSV:-$root/docs/bench_preprocess_tiled.csv}
own_work=0
if [ -z "${WORK:-}" ]; then
  WORK=$(mktemp -d /tmp/preprocess_tiled_bench.XXXXXX)
  own_work=1
fi
trap '[ $own_work = 1 ] && rm -rf "$WORK"' EXIT

measure() {  # measure CMD...: prints "seconds peak_kB"
  /usr/bin/time -o "$WORK/time" -f '%e %M' "$@" > "$WORK/last.log" 2>&1 ||
    { cat "$WORK/last.log" >&2; echo "failed: $*" >&2; exit 1; }
  tail -1 "$WORK/time"
}

echo "size,scan_samples,texels,run,seconds,peak_rss_mb,height_rms_mm,height_max_mm,texels_over_0.01mm,mask_texels_differ" > "$csv"
printf '%-6s %-7s %9s %10s %12s %12s %10s\n' size run seconds peak_MB height_RMS height_max mask_diff
for n in "${sizes[@]}"; do
  d=$WORK/s$n
  rm -rf "$d"
  mkdir -p "$d"
  sw=$((n * scan_scale / 10)) sh=$((n * scan_scale * 3 / 40))
  pitch=$(awk -v n="$n" 'BEGIN {print 400 / n}')
  measure "$bin" synth -o "$d/synth" --resolution "$n" --scan-size "$sw" "$sh" > /dev/null
  rm -f "$d"/synth/truth_*  # only the scan is read
  read -r ts tkb < <(measure "$bin" preprocess "$d/synth/scan.exr" -o "$d/tiled" --pitch-mm "$pitch" \
                       --tile-texels "$tile")
  texels=$(oiiotool --info "$d/tiled/height.exr" |
             sed -E 's/.*: *([0-9]+) x +([0-9]+),.*/\1 \2/' | awk '{print $1 * $2}')
  rms="" max="" over="" mask=""
  if [ "$n" -le "$whole_max" ]; then
    read -r ws wkb < <(measure "$bin" preprocess "$d/synth/scan.exr" -o "$d/whole" --pitch-mm "$pitch" \
                         --max-scan-samples 4294967296)
    diff=$(idiff -fail 0.01 -failpercent 100 "$d/whole/height.exr" "$d/tiled/height.exr" 2>&1 || true)
    rms=$(echo "$diff" | sed -nE 's/.*RMS error = ([0-9.eE+-]+).*/\1/p' | head -1)
    max=$(echo "$diff" | sed -nE 's/.*Max error *= ([0-9.eE+-]+).*/\1/p' | head -1)
    over=$(echo "$diff" | sed -nE 's/.* ([0-9]+) pixels .* over 0.01.*/\1/p' | head -1)
    mdiff=$(idiff -fail 0.001 -failpercent 100 "$d/whole/mask.png" "$d/tiled/mask.png" 2>&1 || true)
    mask=$(echo "$mdiff" | sed -nE 's/.* ([0-9]+) pixels .* over .*/\1/p' | head -1)
    echo "$n,$((sw * sh)),$texels,whole,$ws,$((wkb / 1024)),,,," >> "$csv"
    printf '%-6s %-7s %9.1f %10d\n' "$n" whole "$ws" "$((wkb / 1024))"
  fi
  echo "$n,$((sw * sh)),$texels,tiled_$tile,$ts,$((tkb / 1024)),$rms,$max,${over:-0},${mask:-0}" >> "$csv"
  printf '%-6s %-7s %9.1f %10d %12s %12s %10s\n' "$n" "tiled" "$ts" "$((tkb / 1024))" "$rms" "$max" \
    "${mask:-0}"
  rm -rf "$d"
done
echo "wrote $csv"
