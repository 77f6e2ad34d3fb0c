#!/usr/bin/env bash
# Canvas size against wall time and peak memory, per stage, for the untiled fit and for tile jobs
# (docs/benchmarks.md, "Tiles"). Peak RSS is the kernel's (GNU time's %M: the process's maximum
# resident set), so it counts everything: photos, canvas, tracer, OIIO's cache, the allocator.
#   bench/tiles_bench.sh [SIZE ...]   texels along the canvas's longer side (default 1024 2048)
# Env: CACHE_MB (the tile jobs' image cache, default 256), BIN (the digitize executable, default build/bin/digitize), TILE (tile side, default 512), LIGHTS (photos, default 16), WORK (scratch folder, default a
# new one under /tmp, removed after), CSV (default docs/bench_tiles.csv).
# Each tile runs as its own process (`tiles run --index I`), as a Slurm array task would, so its
# peak RSS is the job's. The merged maps are compared with the untiled fit's (idiff -fail 0).
# A second plan with a tiled pack (PACK_TILE, default 256; 0 skips it) measures the streamed merge
# (no whole-canvas maps); its pack is checked with `digitize verify` (tests/tiles_test.cpp asserts
# it equals `digitize pack --pack-tile-size` of the untiled fit, tile for tile).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
root=$PWD
bin=${BIN:-$root/build/bin/digitize}
sizes=("$@")
[ ${#sizes[@]} -gt 0 ] || sizes=(1024 2048)
tile=${TILE:-512}
cache=${CACHE_MB:-256}
lights=${LIGHTS:-16}
pack_tile=${PACK_TILE:-256}
csv=${CSV:-$root/docs/bench_tiles.csv}
own_work=0
if [ -z "${WORK:-}" ]; then
  WORK=$(mktemp -d /tmp/tiles_bench.XXXXXX)
  own_work=1
fi
trap '[ $own_work = 1 ] && rm -rf "$WORK"' EXIT

# measure CMD...: runs CMD (its output to $WORK/last.log), prints "seconds peak_kB".
measure() {
  /usr/bin/time -o "$WORK/time" -f '%e %M' "$@" > "$WORK/last.log" 2>&1 ||
    { cat "$WORK/last.log" >&2; echo "failed: $*" >&2; exit 1; }
  tail -1 "$WORK/time"
}

echo "size,texels,photos,stage,seconds,peak_rss_mb,identical" > "$csv"
printf '%-6s %-10s %-14s %9s %12s\n' size texels stage seconds peak_MB
for n in "${sizes[@]}"; do
  d=$WORK/s$n
  rm -rf "$d"
  mkdir -p "$d"
  row() {  # stage seconds kB [identical]
    local mb=$(( $3 / 1024 ))
    printf '%-6s %-10s %-14s %9.1f %12d\n' "$n" "$texels" "$1" "$2" "$mb"
    echo "$n,$texels,$lights,$1,$2,$mb,${4:-}" >> "$csv"
  }
  texels=0
  # The painting's 400 mm at n texels; the scan samples it 1.5 x as densely (frame and margin).
  pitch=$(awk -v n="$n" 'BEGIN {print 400 / n}')
  read -r s kb < <(measure "$bin" synth -o "$d/synth" --resolution "$n" --photos --lights "$lights" \
                     --scan-size $((n * 3 / 2)) $((n * 9 / 8)))
  row synth "$s" "$kb"
  read -r s kb < <(measure "$bin" preprocess "$d/synth/scan.exr" -o "$d/canvas" --pitch-mm "$pitch")
  texels=$(oiiotool --info "$d/canvas/height.exr" |
             sed -E 's/.*: *([0-9]+) x +([0-9]+),.*/\1 \2/' | awk '{print $1 * $2}')
  row preprocess "$s" "$kb"
  read -r s kb < <(measure "$bin" fit --canvas "$d/canvas" --photos "$d/synth/photos/calib.json" \
                     -o "$d/fit")
  row fit_untiled "$s" "$kb"
  read -r s kb < <(measure "$bin" tiles plan --canvas "$d/canvas" \
                     --photos "$d/synth/photos/calib.json" --plan "$d/plan.json" \
                     --out "$d/tiled.pack.exr" --tile-size "$tile")
  row tiles_plan "$s" "$kb"
  count=$("$bin" tiles status "$d/plan.json" 2>&1 | grep -oE '[0-9]+ of [0-9]+ tiles' |
          head -1 | awk '{print $3}') || true
  total=0 peak=0
  for ((i = 0; i < count; ++i)); do
    read -r s kb < <(measure "$bin" tiles run "$d/plan.json" --index "$i" --cache-mb "$cache")
    total=$(awk -v a="$total" -v b="$s" 'BEGIN {print a + b}')
    [ "$kb" -gt "$peak" ] && peak=$kb
  done
  row "tile_jobs_x$count" "$total" "$peak"
  read -r s kb < <(measure "$bin" tiles merge "$d/plan.json")
  same=yes
  for f in "$d"/fit/*.exr; do
    idiff -fail 0 -warn 0 -a "$f" "$d/plan.tiles/fit/$(basename "$f")" > /dev/null || same=no
  done
  row tiles_merge "$s" "$kb" "$same"
  if [ "$pack_tile" -gt 0 ]; then
    "$bin" tiles plan --canvas "$d/canvas" --photos "$d/synth/photos/calib.json" \
      --plan "$d/plan_tiled.json" --out "$d/tiled_$pack_tile.pack.exr" --tile-size "$tile" \
      --pack-tile-size "$pack_tile" > "$WORK/last.log" 2>&1
    "$bin" tiles run "$d/plan_tiled.json" --all --cache-mb "$cache" > "$WORK/last.log" 2>&1
    read -r s kb < <(measure "$bin" tiles merge "$d/plan_tiled.json")
    verified=no
    "$bin" verify "$d/tiled_$pack_tile.pack.exr" > /dev/null 2>&1 && verified=verified
    row "tiles_merge_streamed_$pack_tile" "$s" "$kb" "$verified"
  fi
  rm -rf "$d"
done
echo "wrote $csv"
