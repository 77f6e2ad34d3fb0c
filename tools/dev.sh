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
  # viewer (issue 5): GL loader, EGL surfaceless + Mesa's llvmpipe for headless, GLFW + ImGui window
  libepoxy-dev libegl-dev libegl-mesa0 libgl1-mesa-dri libglfw3-dev libimgui-dev libstb-dev
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

configure() {  # configure DIR [cmake args...]: each folder always gets the same arguments,
  # given explicitly every time so a cache left by an older configuration is corrected (a few
  # seconds when nothing changed).
  local dir=$1; shift
  cmake -S "$root" -B "$dir" -G Ninja -DDIGITIZE_BUILD_TESTS=ON "$@" > "$dir.configure.log" 2>&1 ||
    { cat "$dir.configure.log"; return 1; }
}

run_tests() {  # run_tests DIR LABEL
  echo "== tests ($2)"
  ctest --test-dir "$1" --output-on-failure --no-tests=error -j "$jobs" --timeout 900
}

cmd=${1:-}
case "$cmd" in
  build)
    install_packages
    configure build -DCMAKE_BUILD_TYPE=Release
    cmake --build build -j "$jobs"
    ;;
  demo)
    install_packages
    configure build -DCMAKE_BUILD_TYPE=Release
    cmake --build build -j "$jobs" --target digitize_cli  # the demo needs the tool only
    shift
    ./build/bin/digitize demo "$@"
    ;;
  test)
    install_packages
    configure build -DCMAKE_BUILD_TYPE=Release
    cmake --build build -j "$jobs"
    run_tests build "Release"
    # Sanitizers: RelWithDebInfo keeps the suite fast enough; halt on the first UBSan report.
    configure build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDIGITIZE_SANITIZE=ON -DDIGITIZE_BUILD_BENCH=OFF
    cmake --build build-asan -j "$jobs"
    ASAN_OPTIONS=detect_leaks=1:abort_on_error=0 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
      DIGITIZE_SANITIZED=1 run_tests build-asan "ASan+UBSan"
    ;;
  bench)
    install_packages
    configure build -DCMAKE_BUILD_TYPE=Release
    cmake --build build -j "$jobs"
    shift
    bash bench/run.sh "$@"
    ;;
  *)
    echo "usage: tools/dev.sh demo|test|build|bench" >&2
    exit 2
    ;;
esac
