#!/usr/bin/env bash
# One entry point for people and CI. Installs what is missing (Debian 12 packages), builds, and runs.
#   tools/dev.sh demo    build, then run the whole pipeline on a synthetic painting (digitize demo)
#   tools/dev.sh test    build, run the test suite, then again under ASan+UBSan
#   tools/dev.sh build   install + build only (Release, in build/)
#   tools/dev.sh bench   build, then run the benchmarks (writes CSV + plots into docs/)
# Idempotent: installed packages and an up-to-date build are left alone.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
jobs=$(nproc 2>/dev/null || echo 2)

packages=(
  build-essential cmake ninja-build pkg-config git
  libeigen3-dev libopencv-dev libceres-dev libopenimageio-dev openimageio-tools
  libembree-dev libcgal-dev libopenmesh-dev libtbb-dev libcli11-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev libbenchmark-dev gnuplot-nox
)

install_packages() {
  local missing=()
  for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "== installing: ${missing[*]}"
  local sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -q
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends "${missing[@]}"
}

build() {  # build DIR [cmake args...]
  local dir=$1; shift
  if [ ! -f "$dir/build.ninja" ]; then
    cmake -S "$root" -B "$dir" -G Ninja "$@"
  fi
  cmake --build "$dir" -j "$jobs"
}

run_tests() {  # run_tests DIR LABEL
  echo "== tests ($2)"
  ctest --test-dir "$1" --output-on-failure -j "$jobs" --timeout 900
}

cmd=${1:-}
case "$cmd" in
  build)
    install_packages
    build build -DCMAKE_BUILD_TYPE=Release
    ;;
  demo)
    install_packages
    build build -DCMAKE_BUILD_TYPE=Release -DDIGITIZE_BUILD_TESTS=OFF -DDIGITIZE_BUILD_BENCH=OFF
    shift
    ./build/bin/digitize demo "$@"
    ;;
  test)
    install_packages
    build build -DCMAKE_BUILD_TYPE=Release
    run_tests build "Release"
    # Sanitizers: RelWithDebInfo keeps the suite fast enough; halt on the first UBSan report.
    build build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDIGITIZE_SANITIZE=ON -DDIGITIZE_BUILD_BENCH=OFF
    ASAN_OPTIONS=detect_leaks=1:abort_on_error=0 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
      DIGITIZE_SANITIZED=1 run_tests build-asan "ASan+UBSan"
    ;;
  bench)
    install_packages
    build build -DCMAKE_BUILD_TYPE=Release
    shift
    bash bench/run.sh "$@"
    ;;
  *)
    echo "usage: tools/dev.sh demo|test|build|bench" >&2
    exit 2
    ;;
esac
