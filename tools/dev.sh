#!/usr/bin/env bash
# One entry point for people and CI. Installs what is missing (Debian 12 packages), builds, and runs.
#   tools/dev.sh demo    build, then run the whole pipeline on a synthetic painting (digitize demo)
#   tools/dev.sh test    check the formatting (clang-format-14, .clang-format), build, run the test
#                        suite, then again under ASan+UBSan, then the fuzzers for
#                        DIGITIZE_FUZZ_SECONDS each (default 30; 0: replay their corpus only)
#   tools/dev.sh format-check  only the formatting check (lists every file that drifts)
#   tools/dev.sh format  apply .clang-format to every C++ source
#   tools/dev.sh fuzz [SECONDS]  build the libFuzzer targets (clang, build-fuzz/) and run each for
#                        SECONDS (default DIGITIZE_FUZZ_SECONDS, else 60) from its seed corpus
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
  libopencv-contrib-dev     # surface_matching: the ICP that registers overlapping scans
  libembree-dev libcgal-dev libopenmesh-dev libtbb-dev libcli11-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev libbenchmark-dev gnuplot-nox
  clang libclang-rt-14-dev  # the fuzz targets: clang's libFuzzer + sanitizer runtimes
  clang-format-14           # the formatting check of tools/dev.sh test
  ccache                    # rebuilds of unchanged files (three builds: Release, ASan, fuzz)
  # viewer: GL loader, EGL surfaceless + Mesa's llvmpipe for headless, GLFW + ImGui window
  libepoxy-dev libegl-dev libegl-mesa0 libgl1-mesa-dri libglfw3-dev libimgui-dev libstb-dev
  slurm-wlm munge  # tiles as Slurm jobs: the test starts a one-node cluster on localhost
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
  local launcher=()
  if command -v ccache > /dev/null; then
    # Paths relative to the checkout, so another clone of the same sources hits the cache.
    export CCACHE_BASEDIR="$root"
    # The tests' precompiled header (tests/CMakeLists.txt): ccache caches files built with it
    # only when told to ignore the header's timestamps and defines it cannot see.
    export CCACHE_SLOPPINESS=pch_defines,time_macros,include_file_mtime,include_file_ctime
    # Without this, ccache puts the working directory into the hash of every compile that makes
    # debug info (the ASan and fuzz builds' -g1), so a clone elsewhere missed on all of them and
    # rebuilt both cold: most of a CI run. The cost: a hit's debug info may name the other
    # clone's build folder (file names in it are relative, through CCACHE_BASEDIR).
    export CCACHE_NOHASHDIR=1
    launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  fi
  cmake -S "$root" -B "$dir" -G Ninja -DDIGITIZE_BUILD_TESTS=ON "${launcher[@]}" "$@" > "$dir.configure.log" 2>&1 ||
    { cat "$dir.configure.log"; return 1; }
}

run_tests() {  # run_tests DIR LABEL [ctest args...]
  local dir=$1 label=$2
  shift 2
  echo "== tests ($label)"
  ctest --test-dir "$dir" --output-on-failure --no-tests=error -j "$jobs" --timeout 900 "$@"
}

# Left out of the sanitized run: accuracy tests that run code smaller tests also run under the
# sanitizers (the fit, the viewer-vs-Embree comparison), only on bigger inputs, the install
# test (packaging), and the tile runs that are timed kills or a Slurm cluster's jobs (the same
# commands run sanitized in the other TilesCli tests). They were ~510 of the sanitized suite's ~1600 CPU seconds (CI log, 2 cores);
# the Release run keeps them all.
asan_skip='^(ReflectanceFitGgx\.(NoiseFreeGgxPainting|DefaultNoiseLambertianStaysDiffuse)'
asan_skip+='|ReflectanceFitSynth\.(NoiseFreeHeldOutPsnrAtLeast40dB|DefaultNoiseHeldOutPsnr'
asan_skip+='|StressMaterials|MismatchedModelIsReported|RaySkippingChangesNothing)'
asan_skip+='|ViewerTest\.(MatchesEmbreeReferenceAtPaperViews|GgxPackMatchesEmbreeReferenceAtPaperViews)'
asan_skip+='|TilesCli\.ResumesAfterAKillAtSeveralMoments|install_consumer|slurm_tiles)$'

# Every C++ source and header of the project (tracked files in a git checkout, else the source
# folders), for the formatting check.
cxx_sources() {
  if git -C "$root" rev-parse --is-inside-work-tree > /dev/null 2>&1; then
    git -C "$root" ls-files --cached --others --exclude-standard -- '*.cpp' '*.h' |
      while IFS= read -r f; do [ -f "$f" ] && echo "$f"; done
  else
    find libdigitize tools viewer data_synthetic tests bench \( -name '*.cpp' -o -name '*.h' \) | sort
  fi
}

# The sources as .clang-format says (Debian 12's clang-format-14, so every machine agrees): lists
# the files that drift and fails; `tools/dev.sh format` rewrites them.
check_format() {
  echo "== format (clang-format-14 --dry-run --Werror)"
  local bad=() f
  while IFS= read -r f; do
    clang-format-14 --dry-run --Werror "$f" > /dev/null 2>&1 || bad+=("$f")
  done < <(cxx_sources)
  if [ ${#bad[@]} -gt 0 ]; then
    printf '  %s\n' "${bad[@]}"
    echo "== format: ${#bad[@]} file(s) differ from .clang-format (see: clang-format-14 --dry-run" \
         "FILE; fix all: tools/dev.sh format)"
    return 1
  fi
}

# The sanitized builds' optimisation and debug info (see the ASan build in `test`).
sanitized_flags=(-DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG")

# The libFuzzer targets (tests/fuzz/): clang, ASan+UBSan, only the library sources they need.
build_fuzzers() {
  CC=clang CXX=clang++ configure build-fuzz -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDIGITIZE_FUZZ=ON \
    "${sanitized_flags[@]}"
  cmake --build build-fuzz -j "$jobs"
}

# run_fuzzers SECONDS: every target with a corpus in tests/fuzz/corpus/<target>/, for SECONDS each,
# starting from a scratch copy of its corpus (the tree is not modified; what the fuzzer learns is
# thrown away). 0 seconds: replay the corpus only. Fails on any crash, leak, timeout or sanitizer
# report, and keeps the scratch folder with the reproducer (crash-*, leak-*, timeout-*) and log.
run_fuzzers() {
  local seconds=$1 scratch failed=0 corpus target dir
  scratch=$(mktemp -d "${TMPDIR:-/tmp}/digitize-fuzz.XXXXXX")
  for corpus in tests/fuzz/corpus/*/; do
    target=$(basename "$corpus")
    dir=$scratch/$target
    mkdir -p "$dir/corpus"
    cp "$corpus"* "$dir/corpus/"
    local args=(-timeout=10 -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$dir/")
    [ -f "tests/fuzz/$target.dict" ] && args+=(-dict="tests/fuzz/$target.dict")
    if [ "$seconds" -gt 0 ]; then args+=(-max_total_time="$seconds"); else args+=(-runs=0); fi
    echo "== fuzz $target (${seconds} s)"
    if UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
       LSAN_OPTIONS=suppressions="$root/tests/lsan.supp" \
       "build-fuzz/fuzz/$target" "${args[@]}" "$dir/corpus" > "$dir/log" 2>&1; then
      grep -a -E '^#[0-9]+[[:space:]].*cov: ' "$dir/log" | tail -n 1 || true
      grep -a -E 'stat::(number_of_executed_units|average_exec_per_sec)' "$dir/log" | tr '\n' ' ' || true
      echo
    else
      tail -n 80 "$dir/log"
      for f in "$dir"/crash-* "$dir"/leak-* "$dir"/timeout-* "$dir"/oom-*; do
        # In CI the scratch folder is gone afterwards: print small reproducers (base64 -d).
        [ -f "$f" ] && [ "$(stat -c %s "$f")" -le 65536 ] &&
          { echo "== $(basename "$f") (base64):"; base64 -w 0 "$f"; echo; }
      done
      echo "== fuzz $target FAILED: log and reproducer in $dir (fix the bug, then add the" \
           "reproducer to tests/fuzz/corpus/$target/ as crash_<what>)"
      failed=1
    fi
  done
  [ $failed -eq 0 ] && rm -rf "$scratch"
  return $failed
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
    # The tool, and the viewer the README's next commands open the demo's pack with.
    cmake --build build -j "$jobs" --target digitize_cli digitize_viewer_app
    shift
    ./build/bin/digitize demo "$@"
    ;;
  test)
    install_packages
    check_format
    configure build -DCMAKE_BUILD_TYPE=Release
    cmake --build build -j "$jobs"
    run_tests build "Release"
    # Sanitizers: optimised so the suite runs fast enough; halt on the first UBSan report.
    # -O1 -g1, not RelWithDebInfo's -O2 -g: UBSan's checks make GCC's -O2 and full debug info
    # the bulk of a cold build (scan_registration.cpp: 182 s at -O2 -g, 72 s at -O1 -g1; the
    # sanitized build was most of a 79-minute CI run after a header change). Line tables are all
    # the sanitizers' stack traces need.
    # At the x86-64 baseline (DIGITIZE_SIMD=NONE), where the Release build above takes this
    # machine's AVX2: the suite runs once at each SIMD level a user may build.
    configure build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDIGITIZE_SANITIZE=ON -DDIGITIZE_BUILD_BENCH=OFF \
      -DDIGITIZE_SIMD=NONE "${sanitized_flags[@]}"
    cmake --build build-asan -j "$jobs"
    # intercept_tls_get_addr=0: GCC 12's __tls_get_addr interceptor takes a dynamic TLS block that
    # happens to start 16 bytes past a page for a pre-2.25 glibc header and reads a bogus range;
    # LeakSanitizer's tracer then segfaults at exit ("Tracer caught signal 11", no leak reported).
    # Mesa's llvmpipe (dlopen'ed, dynamic TLS) makes that a 1-in-20 flake of the viewer tests.
    # tests/lsan.supp: leaks inside system libraries (Mesa's llvmpipe under load), said there.
    ASAN_OPTIONS=detect_leaks=1:abort_on_error=0:intercept_tls_get_addr=0 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
      LSAN_OPTIONS=suppressions="$root/tests/lsan.supp" DIGITIZE_SANITIZED=1 run_tests build-asan "ASan+UBSan" -E "$asan_skip"
    build_fuzzers
    run_fuzzers "${DIGITIZE_FUZZ_SECONDS:-30}"
    ;;
  format-check)
    install_packages
    check_format
    ;;
  format)
    install_packages
    cxx_sources | xargs -d '\n' clang-format-14 -i
    ;;
  fuzz)
    install_packages
    build_fuzzers
    run_fuzzers "${2:-${DIGITIZE_FUZZ_SECONDS:-60}}"
    ;;
  bench)
    install_packages
    configure build -DCMAKE_BUILD_TYPE=Release
    cmake --build build -j "$jobs"
    shift
    bash bench/run.sh "$@"
    ;;
  *)
    echo "usage: tools/dev.sh demo|test|build|bench|fuzz [SECONDS]|format-check|format" >&2
    exit 2
    ;;
esac
