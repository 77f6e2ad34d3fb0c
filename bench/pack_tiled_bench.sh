#!/usr/bin/env bash
# Tiled (version 3) against single-grid (version 2) packs as the painting grows: write time, peak
# RSS, file size and the largest relative error read back (docs/benchmarks.md, "Tiled packs").
# Each write is its own process (build/bin/pack_tiled_bench), so its peak RSS is that write's.
#   bench/pack_tiled_bench.sh [SIZE ...]   texels a side (default 1024 2048 4096 8192)
# Env: TILE (default 256), SINGLE_MAX (largest size also written as one grid, default 8192),
# CSV (default docs/bench_pack_tiled.csv), OUT (scratch pack file, default under /tmp).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
sizes=("$@")
[ ${#sizes[@]} -gt 0 ] || sizes=(1024 2048 4096 8192)
tile=${TILE:-256}
single_max=${SINGLE_MAX:-8192}
csv=${CSV:-docs/bench_pack_tiled.csv}
out=${OUT:-$(mktemp -u /tmp/pack_tiled_bench.XXXXXX).pack.exr}
echo "size,tile,levels,write_s,peak_rss_mb,file_mb,max_rel_error" > "$csv"
for n in "${sizes[@]}"; do
  forms=("$tile")
  [ "$n" -le "$single_max" ] && forms=(0 "$tile")
  for t in "${forms[@]}"; do
    line=$(./build/bin/pack_tiled_bench --size "$n" --tile "$t" --out "$out")
    echo "$line" | tee -a "$csv"
  done
done
echo "wrote $csv"
