// libFuzzer target: the viewer's load path without GL (viewer_contract.h): a pack file through
// LoadPackForViewer (ReadPack), PreparePainting (what Renderer::AddPainting checks and derives
// before uploading) and the gallery's set-up (HangPaintings, MakeGallery). The aim: no pack a
// reader accepts can abort the viewer (issue 10: pitch_mm = 1e308 did, in Renderer::Render).
// Seed corpus: corpus/fuzz_viewer_load/ (tests/fuzz_corpus_test.cpp, DISABLED_WritePackSeeds,
// writes it). Each input is written to a scratch file first, as in fuzz_pack.
#include <OpenImageIO/imageio.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "fuzz_check.h"
#include "viewer_contract.h"

namespace {

namespace fs = std::filesystem;

const fs::path& ScratchFile() {
  static const fs::path path = [] {
    const fs::path shm = "/dev/shm";
    std::error_code ec;
    const fs::path dir = fs::is_directory(shm, ec) ? shm : fs::temp_directory_path();
    return dir / ("digitize_fuzz_viewer_" + std::to_string(::getpid()) + ".exr");
  }();
  return path;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int* /*argc*/, char*** /*argv*/) {
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
  const std::string broken = digitize::fuzz::CheckViewerLoadFile(ScratchFile());
  std::error_code ec;
  fs::remove(ScratchFile(), ec);
  digitize::fuzz::AbortUnless(broken);
  return 0;
}
