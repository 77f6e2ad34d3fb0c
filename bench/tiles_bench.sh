#!/usr/bin/env bash
# Canvas size against wall time and peak memory, per stage, for the untiled fit and for tile jobs
# (docs/benchmarks.md, "Tiles"). Peak RSS is the kernel's (GNU time's %M: the process's maximum
# resident set), so it counts everything: photos, canvas, tracer, OIIO's cache, the allocator.
#   bench/tiles_bench.sh [SIZE ...]   texels along the canvas's longer side (default 1024 2048)
# Env: CACHE_MB (the tile jobs' image cache, default 256), BIN (the digitize executable, default
# build/bin/digitize), TILE (tile side, default 512), LIGHTS (lights per camera position, default
# 16), ENCODING (photo files, default jpeg), UNTILED_MAX (largest size whose untiled fit is also run
# and compared, default 2048: it holds every photo whole), WORK (scratch folder, default a new one
# under /tmp, removed after), CSV (default docs/bench_tiles.csv), SCAN_SCALE (scan samples per
# texel along each side, in tenths, default 15: a 1.5 n x 1.125 n scan; the 16384 row used 10, since
# the generator holds ~14 bytes a scan sample beside the painting), PREPROCESS_TILE (preprocess in
# tiles of this side, `--tile-texels`; default 0: whole).
# The photos are a tiled set, as a large painting is photographed: a grid of camera positions
# straight above cells of about 2048 x 2048 texels (1 x 1 up to 2048, 2 x 2 at 4096, 4 x 3 at
# 8192), each cell's image grown by 10 % of a cell on every side, each under its own LIGHTS lights
# (`digitize synth --camera-grid`), so a texel is seen by the photos of one to four positions.
# Each tile runs as its own process (`tiles run --index I`), as a Slurm array task would, so its
# peak RSS is the job's. The merged maps are compared with the untiled fit's (idiff -fail 0).
# A second plan with a tiled pack (PACK_TILE, default 256; 0 skips it) measures the streamed merge
# (no whole-canvas maps); its pack is checked with `digitize verify` (tests/tiles_test.cpp asserts
# it equals `digitize pack --pack-tile-size` of the untiled fit, tile for tile).
# `tiles plan` copies the JPEGs into tiled TIFFs (photo_cache/, its time is the plan's row); with
# COMPARE_CACHE=1 (default) every tile job also runs from a plan made with --no-photo-cache, just
# before the cached one, and the two jobs' maps are compared (the row's "identical").
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

untiled_max=${UNTILED_MAX:-2048}
scan_scale=${SCAN_SCALE:-15}
compare_cache=${COMPARE_CACHE:-1}
encoding=${ENCODING:-jpeg}
echo "size,texels,grid,photos,photo_mpx,stage,seconds,peak_rss_mb,identical" > "$csv"
printf '%-6s %-10s %-14s %9s %12s\n' size texels stage seconds peak_MB
for n in "${sizes[@]}"; do
  d=$WORK/s$n
  rm -rf "$d"
  mkdir -p "$d"
  row() {  # stage seconds kB [identical]
    local mb=$(( $3 / 1024 ))
    printf '%-6s %-10s %-14s %9.1f %12d\n' "$n" "$texels" "$1" "$2" "$mb"
    echo "$n,$texels,$grid,$photos,$mpx,$1,$2,$mb,${4:-}" >> "$csv"
  }
  texels=0 photos=0 mpx=0
  # The painting's 400 x 300 mm at n texels; the scan samples it 1.5 x as densely (frame and
  # margin); camera cells of about 2048 texels a side.
  pitch=$(awk -v n="$n" 'BEGIN {print 400 / n}')
  cols=$(( (n + 2047) / 2048 )) rows=$(( (n * 3 / 4 + 2047) / 2048 ))
  grid="${cols}x$rows"
  read -r s kb < <(measure "$bin" synth -o "$d/synth" --resolution "$n" --photos --lights "$lights" \
                     --camera-grid "$cols" "$rows" --photo-encoding "$encoding" \
                     --held-out-lights 0 --scan-size $((n * scan_scale / 10)) \
                     $((n * scan_scale * 3 / 40)))
  photos=$((cols * rows * lights))
  mpx=$(grep -oE '[0-9.]+ Mpx' "$WORK/last.log" | head -1 | awk '{print $1}')
  echo "  photo set: $(grep -oE 'photo set: [^;]*;[^;]*' "$WORK/last.log" | head -1)," \
       "$(du -sh "$d/synth/photos/images" | cut -f1) on disk"
  synth_s=$s synth_kb=$kb
  preprocess_tile=()
  [ "${PREPROCESS_TILE:-0}" -gt 0 ] && preprocess_tile=(--tile-texels "$PREPROCESS_TILE")
  read -r s kb < <(measure "$bin" preprocess "$d/synth/scan.exr" -o "$d/canvas" --pitch-mm "$pitch" \
                     --max-scan-samples 4294967296 "${preprocess_tile[@]}")
  texels=$(oiiotool --info "$d/canvas/height.exr" |
             sed -E 's/.*: *([0-9]+) x +([0-9]+),.*/\1 \2/' | awk '{print $1 * $2}')
  row synth "$synth_s" "$synth_kb"  # after preprocess, which tells the canvas's texels
  row preprocess "$s" "$kb"
  untiled=0
  if [ "$n" -le "$untiled_max" ]; then
    untiled=1
    read -r s kb < <(measure "$bin" fit --canvas "$d/canvas" --photos "$d/synth/photos/calib.json" \
                       -o "$d/fit")
    row fit_untiled "$s" "$kb"
  fi
  # Above UNTILED_MAX the plan writes the tiled pack straight away (its merge streams; the
  # whole-map merge is what does not scale); at or below it, a single-grid pack plan first, compared
  # with the untiled fit, then the tiled-pack plan's streamed merge.
  plans=()
  [ "$untiled" = 1 ] && plans+=(0)
  [ "$pack_tile" -gt 0 ] && plans+=("$pack_tile")
  for pt in "${plans[@]}"; do
    plan=$d/plan_$pt.json
    read -r s kb < <(measure "$bin" tiles plan --canvas "$d/canvas" \
                       --photos "$d/synth/photos/calib.json" --plan "$plan" \
                       --out "$d/tiled_$pt.pack.exr" --tile-size "$tile" --pack-tile-size "$pt")
    count=$("$bin" tiles status "$plan" 2>&1 | grep -oE '[0-9]+ of [0-9]+ tiles' |
            head -1 | awk '{print $3}') || true
    if [ "$pt" = 0 ] || [ "$untiled" = 0 ]; then
      row tiles_plan "$s" "$kb"  # with the photos' tiled copies (photo_cache/)
      if [ "$compare_cache" = 1 ]; then
        "$bin" tiles plan --canvas "$d/canvas" --photos "$d/synth/photos/calib.json" \
          --plan "$d/direct_$pt.json" --out "$d/direct_$pt.pack.exr" --tile-size "$tile" \
          --pack-tile-size "$pt" --no-photo-cache > /dev/null
      fi
      # Each tile its own process, as an array task: its peak RSS is the job's. With
      # COMPARE_CACHE, the same tile read from the photos themselves runs just before it (the same
      # machine state for both), and its maps are compared.
      total=0 peak=0 direct_total=0 direct_peak=0 same=yes
      for ((i = 0; i < count; ++i)); do
        if [ "$compare_cache" = 1 ]; then
          read -r s kb < <(measure "$bin" tiles run "$d/direct_$pt.json" --index "$i" \
                             --cache-mb "$cache")
          direct_total=$(awk -v a="$direct_total" -v b="$s" 'BEGIN {print a + b}')
          [ "$kb" -gt "$direct_peak" ] && direct_peak=$kb
        fi
        read -r s kb < <(measure "$bin" tiles run "$plan" --index "$i" --cache-mb "$cache")
        total=$(awk -v a="$total" -v b="$s" 'BEGIN {print a + b}')
        [ "$kb" -gt "$peak" ] && peak=$kb
        echo "  tile $i of $count: ${s} s, $((kb / 1024)) MB" >> "$WORK/tiles.log"
        if [ "$compare_cache" = 1 ]; then
          t=$(printf 'tile_%05d' "$i")
          for f in "$d/plan_$pt.tiles/$t"/*.exr; do
            idiff -fail 0 -warn 0 -a "$f" "$d/direct_$pt.tiles/$t/$(basename "$f")" > /dev/null ||
              same=no
          done
        fi
      done
      [ "$compare_cache" = 1 ] && row "tile_jobs_uncached_x$count" "$direct_total" "$direct_peak"
      row "tile_jobs_x$count" "$total" "$peak" "$([ "$compare_cache" = 1 ] && echo "$same")"
    else
      "$bin" tiles run "$plan" --all --cache-mb "$cache" > "$WORK/last.log" 2>&1
    fi
    read -r s kb < <(measure "$bin" tiles merge "$plan")
    if [ "$pt" = 0 ]; then
      same=yes
      for f in "$d"/fit/*.exr; do
        idiff -fail 0 -warn 0 -a "$f" "$d/plan_0.tiles/fit/$(basename "$f")" > /dev/null || same=no
      done
      row tiles_merge "$s" "$kb" "$same"
    else
      verified=no
      if "$bin" verify "$d/tiled_$pt.pack.exr" > "$WORK/verify.log" 2>&1; then
        verified=verified
      else  # the pack is removed with its folder below: say why now
        echo "  verify failed: $(tail -1 "$WORK/verify.log")" >&2
      fi
      row "tiles_merge_streamed_$pt" "$s" "$kb" "$verified"
    fi
  done
  rm -rf "$d"
done
echo "wrote $csv"
