// The CPU check of a build whose code uses AVX2 and FMA (DIGITIZE_SIMD, CMakeLists.txt): on a CPU
// without them the first such instruction kills the program with SIGILL and no word of why (a
// cluster node older than the machine that built it). This file is compiled for the x86-64
// baseline whatever the build's level, and its check runs before the program's own static
// initialisers (constructor priority 101), so it can still say what is wrong.
// With DIGITIZE_SIMD_PROBE it is the configure-time probe instead: exit 0 where the CPU has them.
#include <cstdio>
#include <cstdlib>

static bool CpuHasX86_64_V3() {
#if defined(__x86_64__)
  __builtin_cpu_init();
#if defined(__clang__)  // clang 14 knows no level names: the features the kernels use
  return __builtin_cpu_supports("avx") && __builtin_cpu_supports("avx2") &&
         __builtin_cpu_supports("fma") && __builtin_cpu_supports("bmi") &&
         __builtin_cpu_supports("bmi2") && __builtin_cpu_supports("popcnt");
#else
  return __builtin_cpu_supports("x86-64-v3");
#endif
#else
  return false;
#endif
}

#if defined(DIGITIZE_SIMD_PROBE)
int main() { return CpuHasX86_64_V3() ? 0 : 1; }
#elif defined(DIGITIZE_SIMD_X86_64_V3)
__attribute__((constructor(101))) static void RefuseCpuWithoutX86_64_V3() {
  // The variable plays an older CPU, for the test of this message (CliTest).
  if (CpuHasX86_64_V3() && !std::getenv("DIGITIZE_TEST_CPU_WITHOUT_X86_64_V3")) return;
  std::fputs(
      "digitize: this build runs AVX2 and FMA instructions (x86-64-v3: CMake DIGITIZE_SIMD, chosen "
      "on the machine that built it), and this CPU lacks them. Build again on this machine, or "
      "configure with -DDIGITIZE_SIMD=NONE for every x86-64 CPU (docs/benchmarks.md: the fit is "
      "about 1.5x slower there).\n",
      stderr);
  std::_Exit(1);
}
#endif
