// libFuzzer target: the viewer's load path without GL (viewer_contract.h): a pack file through
// LoadPackForViewer (ReadPack), PreparePainting (what Renderer::AddPainting checks and derives
// before uploading) and the gallery's set-up (HangPaintings, MakeGallery). The aim: no pack a
// reader accepts can abort the viewer (a forged pitch_mm = 1e308 did, in Renderer::Render).
// Seed corpus: corpus/fuzz_viewer_load/ (tests/fuzz_corpus_test.cpp, DISABLED_WritePackSeeds,
// writes it). Each input is written to a scratch file first, as in fuzz_pack.
#include <OpenImageIO/imageio.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "fuzz_check.h"
#include "viewer_contract.h"

extern "C" int LLVMFuzzerInitialize(int* /*argc*/, char*** /*argv*/) {
  OIIO::attribute("threads", 1);
  OIIO::attribute("exr_threads", 1);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  digitize::fuzz::CheckThroughScratchFile(data, size, "viewer", [](const std::filesystem::path& p) {
    return digitize::fuzz::CheckViewerLoadFile(p);
  });
  return 0;
}
