// libFuzzer target: the texture pack reader (ReadPack and InspectPack: our raw pre-scan of the
// OpenEXR headers, then OpenImageIO/OpenEXR, then every digitize:* attribute, part, channel set,
// size, value and box; docs/formats.md, "Texture packs"). Every input must keep the contract of
// parser_contract.h. Seed corpus: corpus/fuzz_pack/ (small packs written by WritePack, and broken
// ones: tests/fuzz_corpus_test.cpp, DISABLED_WritePackSeeds, writes them).
//
// The reader takes a path (OpenImageIO opens the file itself), so each input is written to a
// scratch file first, on a RAM disk when there is one.
#include <OpenImageIO/imageio.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "fuzz_check.h"
#include "parser_contract.h"

extern "C" int LLVMFuzzerInitialize(int* /*argc*/, char*** /*argv*/) {
  // One thread: deterministic runs, and no pool to start for inputs of a few KB.
  OIIO::attribute("threads", 1);
  OIIO::attribute("exr_threads", 1);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  digitize::fuzz::CheckThroughScratchFile(data, size, "pack", [](const std::filesystem::path& p) {
    return digitize::fuzz::CheckPackFile(p);
  });
  return 0;
}
