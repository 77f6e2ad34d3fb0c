// What a fuzz target does with a broken contract (parser_contract.h): print it and abort, which
// libFuzzer reports as a crash and saves the input as crash-<sha1>.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace digitize::fuzz {

inline void AbortUnless(const std::string& broken) {
  if (broken.empty()) return;
  std::fprintf(stderr, "parser contract broken: %s\n", broken.c_str());
  std::abort();
}

// For readers that take a path (OpenImageIO opens the file itself): writes the input to a scratch
// file named after `tag` (on a RAM disk when there is one), runs check(path), and removes the file
// after every input -- libFuzzer ends with _Exit, which runs no atexit handler, and a RAM disk must
// not keep one file per run. Aborts on a broken contract, as AbortUnless.
template <typename Check>
void CheckThroughScratchFile(const uint8_t* data, size_t size, const char* tag, Check check) {
  static const std::filesystem::path path = [tag] {
    std::error_code ec;
    const std::filesystem::path shm = "/dev/shm";
    const auto dir =
        std::filesystem::is_directory(shm, ec) ? shm : std::filesystem::temp_directory_path();
    return dir / ("digitize_fuzz_" + std::string(tag) + "_" + std::to_string(::getpid()) + ".exr");
  }();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
    if (!out) {
      std::fprintf(stderr, "cannot write %s\n", path.c_str());
      std::abort();
    }
  }
  const std::string broken = check(path);
  std::error_code ec;
  std::filesystem::remove(path, ec);
  AbortUnless(broken);
}

}  // namespace digitize::fuzz
