#!/usr/bin/env bash
# A painting's fit as Slurm jobs on a one-node cluster started here (local_slurm.sh): `digitize
# tiles sbatch --submit` runs the tiles as a job array and the merge as a job that depends on it;
# the pack it merges must hold exactly the maps of the same plan run locally (`tiles run --all`).
# Exit 77 (ctest: skipped) only where slurm-wlm / munge are not installed.
#
#   slurm_tiles_test.sh DIGITIZE
set -euo pipefail
digitize="$1"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
source "$here/local_slurm.sh"

missing="$(local_slurm_missing)"
if [[ -n "$missing" ]]; then
  echo "SKIPPED: Slurm is not installed here (missing: $missing); tools/dev.sh test installs" \
    "Debian's slurm-wlm and munge" >&2
  exit 77
fi

work="$(mktemp -d /tmp/digitize_slurm_XXXXXX)"
cleanup() {
  local_slurm_stop "$work/cluster"
  rm -rf "$work"
}
trap cleanup EXIT
fail() {
  echo "FAILED: $*" >&2
  for log in "$work"/slurm.plan.tiles/logs/*.log "$work"/cluster/log/slurmctld.log; do
    [[ -f "$log" ]] && { echo "--- $log" >&2; tail -n 15 "$log" >&2; }
  done
  exit 1
}

local_slurm_start "$work/cluster" || fail "the local Slurm cluster did not start"
sinfo

# A framed painting at 2 mm a texel (200 x 149 texels), 16 photos: 12 tiles of 50.
"$digitize" synth -o "$work/synth" --resolution 160 --scan-size 400 400 --photos --lights 16 \
  > /dev/null
"$digitize" preprocess "$work/synth/scan.exr" -o "$work/canvas" --pitch-mm 2 > /dev/null
plan() {  # plan NAME
  "$digitize" tiles plan --canvas "$work/canvas" --photos "$work/synth/photos/calib.json" \
    -o "$work/$1.pack.exr" --plan "$work/$1.plan.json" --tile-size 50
}

plan local
"$digitize" tiles run "$work/local.plan.json" --all
"$digitize" tiles merge "$work/local.plan.json"

plan slurm
"$digitize" tiles sbatch "$work/slurm.plan.json" --cpus-per-task 1 --submit | tee "$work/submit.txt"
grep -q "12 tasks" "$work/submit.txt" || fail "submit.sh did not submit 12 tasks"
deadline=$((SECONDS + 300))
until [[ -f "$work/slurm.pack.exr" ]] && [[ -z "$(squeue -h -o %i)" ]]; do
  ((SECONDS < deadline)) || fail "the jobs did not finish within 300 s: $(squeue)"
  sleep 1
done
"$digitize" tiles status "$work/slurm.plan.json" || fail "tiles status: not every tile done"
tile_logs=("$work"/slurm.plan.tiles/logs/tile_*.log)
((${#tile_logs[@]} == 12)) || fail "expected 12 array task logs, found ${#tile_logs[@]}"
grep -q "fitted 1 tile" "${tile_logs[0]}" || fail "a tile task did not fit its tile"
[[ -f "$work/slurm.plan.tiles/logs/merge.log" ]] || fail "the merge job left no log"

for map in rho_d rho_s lobe fit_error; do
  idiff -fail 0 -warn 0 -a "$work/local.plan.tiles/fit/$map.exr" \
    "$work/slurm.plan.tiles/fit/$map.exr" > /dev/null || fail "$map.exr differs from the local run"
done
for map in fit_status model; do
  cmp "$work/local.plan.tiles/fit/$map.png" "$work/slurm.plan.tiles/fit/$map.png" ||
    fail "$map.png differs from the local run"
done
"$digitize" verify "$work/slurm.pack.exr" > /dev/null || fail "the merged pack does not verify"
# The packs differ only in their provenance (times, plan paths): every part's pixels are equal.
idiff -fail 0 -warn 0 -a "$work/local.pack.exr" "$work/slurm.pack.exr" > /dev/null ||
  fail "the merged pack's pixels differ from the local run's"
echo "slurm: 12 tiles as a job array + the merge after it; the merged maps equal the local run's"
