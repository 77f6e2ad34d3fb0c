// libFuzzer target: the texture pack reader (ReadPack and InspectPack: our raw pre-scan of the
// OpenEXR headers, then OpenImageIO/OpenEXR, then every digitize:* attribute, part, channel set,
// size, value and box; docs/formats.md, "Texture packs"). Every input must keep the contract of
// parser_contract.h. Seed corpus: corpus/fuzz_pack/ (small packs written by WritePack, and broken
// ones: tests/fuzz_corpus_test.cpp, DISABLED_WritePackSeeds, writes them).
//
// The reader takes a path (OpenImageIO opens the file itself), so each input is written to a
// scratch file first, on a RAM disk when there is one.
#include <OpenImageIO/imageio.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "fuzz_check.h"
#include "parser_contract.h"

namespace {

namespace fs = std::filesystem;

const fs::path& ScratchFile() {
  static const fs::path path = [] {
    const fs::path shm = "/dev/shm";
    std::error_code ec;
    const fs::path dir = fs::is_directory(shm, ec) ? shm : fs::temp_directory_path();
    return dir / ("digitize_fuzz_pack_" + std::to_string(::getpid()) + ".exr");
  }();
  return path;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int* /*argc*/, char*** /*argv*/) {
  // One thread: deterministic runs, and no pool to start for inputs of a few KB.
  OIIO::attribute("threads", 1);
  OIIO::attribute("exr_threads", 1);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  {
    std::ofstream out(ScratchFile(), std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
    if (!out) {
      std::fprintf(stderr, "cannot write %s\n", ScratchFile().c_str());
      std::abort();
    }
  }
  const std::string broken = digitize::fuzz::CheckPackFile(ScratchFile());
  // Removed after every input: libFuzzer ends with _Exit, which runs no atexit handler, and a
  // RAM disk must not keep one file per run.
  std::error_code ec;
  fs::remove(ScratchFile(), ec);
  digitize::fuzz::AbortUnless(broken);
  return 0;
}
