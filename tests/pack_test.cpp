// Texture packs: round trips (bit-exact in half mode, within the stated bound when quantised),
// the size budget, and every way a pack file can be wrong -- truncated, bit-flipped, a forged
// oversized header, a newer version, a plain EXR, values beyond half -- refused with an error
// naming the file, never a crash, never a partial file.
#include "digitize/pack.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "digitize/image_io.h"
#include "digitize/normals.h"
#include "digitize/pack_tiled.h"
#include "digitize/relief.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/truth_pack.h"
#include "pack_forge.h"
#include "test_support.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;

#define ASSERT_OK(status_expr)                      \
  do {                                              \
    const Status status_ = (status_expr);           \
    ASSERT_TRUE(status_.ok()) << status_.message(); \
  } while (0)

fs::path TempDir(const std::string& name) {
  return test::FreshScratchDir("digitize_pack_test_" + name);
}

std::vector<char> ReadBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void WriteBytes(const fs::path& p, const std::vector<char>& bytes) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// A painting-like pack: an impasto bump with noise on a canvas with an outside border, relief
// boxes from ClassifyRelief, reflectance drawn from the ranges the fit produces (k from 1 to
// 1000 log-uniform, rho_s up to ~k / 2 pi), every fit status present.
Pack MakeTestPack(int w, int h, uint32_t seed, bool with_relief = true) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  Pack p;
  p.field.pitch_mm = 0.125;
  p.field.height_mm = Grid<float>(w, h, 0.0f);
  p.field.state = Grid<TexelState>(w, h, TexelState::kMeasured);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool border = x == 0 || y == 0 || x == w - 1 || y == h - 1;
      if (border) {
        p.field.state(x, y) = TexelState::kOutside;
        continue;
      }
      const float dx = (x - 0.4f * w) / (0.15f * w), dy = (y - 0.5f * h) / (0.2f * h);
      const float bump = with_relief ? 1.5f * std::exp(-(dx * dx + dy * dy)) : 0.0f;
      p.field.height_mm(x, y) = bump + 0.01f * u01(rng);
      if (u01(rng) < 0.02f) p.field.state(x, y) = TexelState::kFilled;
    }
  p.normals = ComputeNormals(p.field);
  ReliefOptions ro;
  ro.cell_px = 8;
  const ReliefResult relief = ClassifyRelief(p.field, ro);
  p.delta0_mm = relief.delta0_mm;
  p.max_height_mm = relief.max_height_mm;
  p.cell_px = relief.cell_px;
  p.boxes = relief.boxes;
  p.maps = ReflectanceMaps::Zeros(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (p.field.state(x, y) == TexelState::kOutside) continue;
      LafortuneParams lp;
      lp.rho_d = Vec3f(u01(rng), u01(rng), u01(rng)) * 0.3f;
      lp.k = std::pow(10.0f, 3.0f * u01(rng));
      lp.rho_s = Vec3f(u01(rng), u01(rng), u01(rng)) * (lp.k + 2) / 6.3f;
      lp.cx = -1.0f - 0.2f * u01(rng);
      lp.cy = -1.0f + 0.3f * u01(rng);
      lp.cz = 1.0f;
      p.maps.Set(x, y, lp);
      p.maps.status(x, y) = static_cast<TexelFitStatus>(rng() % kTexelFitStatusCount);
      p.maps.fit_error(x, y) = 0.01f * u01(rng);
    }
  p.canvas_from_scan.rotation =
      Eigen::AngleAxisd(0.3, Vec3d(0.2, 0.5, 1).normalized()).toRotationMatrix();
  p.canvas_from_scan.translation = Vec3d(-12.5, 3.25, 100.0);
  p.provenance.tool_version = "digitize test";
  p.provenance.created_utc = "2026-11-30T00:00:00Z";
  p.provenance.fit_brief = "97.8 % converged; 1 s";
  p.provenance.options_json = R"({"fit":{"k_max":5000}})";
  p.provenance.inputs = {{"scan.exr", "0123456789abcdef0123456789abcdef01234567", 1234}};
  return p;
}

// MakeTestPack with the right half of the canvas GGX (reflectance_maps.h): a varnish (F0 0.04,
// alpha 0.05 .. 0.3) over the diffuse colour, and every third row gold (F0 (1, 0.78, 0.34), rho_d
// 0); the extremes of the ranges on a few texels (alpha kGgxMinAlpha and 1, F0 1), where rounding
// could leave the valid range.
Pack MakeGgxTestPack(int w, int h, uint32_t seed) {
  Pack p = MakeTestPack(w, h, seed);
  for (int y = 0; y < h; ++y)
    for (int x = w / 2; x < w; ++x) {
      if (p.field.state(x, y) == TexelState::kOutside) continue;
      GgxParams g;
      g.rho_d = p.maps.rho_d(x, y);
      g.f0 = Vec3f::Constant(0.04f);
      g.alpha = 0.05f + 0.25f * float(x - w / 2) / float(w - w / 2);
      if (y % 3 == 0) {
        g.rho_d = Vec3f::Zero();
        g.f0 = Vec3f(1.0f, 0.78f, 0.34f);
      }
      if (x == w / 2) g.alpha = y % 2 ? kGgxMinAlpha : kGgxMaxAlpha;
      p.maps.SetGgx(x, y, g);
    }
  return p;
}

template <class T>
bool SameBits(const Grid<T>& a, const Grid<T>& b) {
  return a.width == b.width && a.height == b.height &&
         std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(T)) == 0;
}

// Everything a pack carries, compared bit for bit (fit_error is not stored: the reader returns 0).
void ExpectIdentical(const Pack& a, const Pack& b) {
  EXPECT_TRUE(SameBits(a.field.height_mm, b.field.height_mm));
  EXPECT_TRUE(SameBits(a.field.state, b.field.state));
  EXPECT_EQ(a.field.pitch_mm, b.field.pitch_mm);
  EXPECT_TRUE(SameBits(a.normals, b.normals));
  EXPECT_TRUE(SameBits(a.maps.rho_d, b.maps.rho_d));
  EXPECT_TRUE(SameBits(a.maps.rho_s, b.maps.rho_s));
  EXPECT_TRUE(SameBits(a.maps.lobe, b.maps.lobe));
  EXPECT_TRUE(SameBits(a.maps.status, b.maps.status));
  EXPECT_TRUE(SameBits(a.maps.model, b.maps.model));
  EXPECT_EQ(a.delta0_mm, b.delta0_mm);
  EXPECT_EQ(a.max_height_mm, b.max_height_mm);
  EXPECT_EQ(a.cell_px, b.cell_px);
  ASSERT_EQ(a.boxes.size(), b.boxes.size());
  for (size_t i = 0; i < a.boxes.size(); ++i) {
    EXPECT_EQ(a.boxes[i].x0, b.boxes[i].x0);
    EXPECT_EQ(a.boxes[i].y0, b.boxes[i].y0);
    EXPECT_EQ(a.boxes[i].width, b.boxes[i].width);
    EXPECT_EQ(a.boxes[i].height, b.boxes[i].height);
    EXPECT_EQ(a.boxes[i].h_max_mm, b.boxes[i].h_max_mm);
    EXPECT_EQ(a.boxes[i].u_max, b.boxes[i].u_max);
    EXPECT_EQ(a.boxes[i].v_max, b.boxes[i].v_max);
  }
  EXPECT_TRUE(a.canvas_from_scan.rotation == b.canvas_from_scan.rotation);
  EXPECT_TRUE(a.canvas_from_scan.translation == b.canvas_from_scan.translation);
  EXPECT_EQ(a.provenance.tool_version, b.provenance.tool_version);
  EXPECT_EQ(a.provenance.fit_brief, b.provenance.fit_brief);
  ASSERT_EQ(a.provenance.inputs.size(), b.provenance.inputs.size());
  for (size_t i = 0; i < a.provenance.inputs.size(); ++i) {
    EXPECT_EQ(a.provenance.inputs[i].name, b.provenance.inputs[i].name);
    EXPECT_EQ(a.provenance.inputs[i].sha1, b.provenance.inputs[i].sha1);
    EXPECT_EQ(a.provenance.inputs[i].bytes, b.provenance.inputs[i].bytes);
  }
}

TEST(Pack, TestPackIsValidAndHasBoxes) {
  const Pack p = MakeTestPack(64, 48, 1);
  ASSERT_TRUE(p.Validate().ok()) << p.Validate().message();
  EXPECT_GT(p.boxes.size(), 3u);  // the bump rises above delta0 in several 8x8 cells
  EXPECT_GT(p.delta0_mm, 0.0);
}

TEST(Pack, HalfRoundTripIsBitExact) {
  const fs::path dir = TempDir("half");
  const Pack p = MakeTestPack(64, 48, 2);
  ASSERT_OK(WritePack(dir / "p.pack.exr", p));
  auto r = ReadPack(dir / "p.pack.exr");
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectIdentical(EncodePackValues(p, {}), *r);
  // Writing what was read gives the same values again (a stable fixed point).
  ASSERT_OK(WritePack(dir / "q.pack.exr", *r));
  auto r2 = ReadPack(dir / "q.pack.exr");
  ASSERT_TRUE(r2.ok());
  ExpectIdentical(*r, *r2);
  fs::remove_all(dir);
}

// Half keeps 11 significant bits: round to nearest is within 2^-11 relative (normal numbers;
// values below 2^-14 are subnormal and within 2^-25 absolute).
TEST(Pack, HalfEncodingErrorIsHalfRounding) {
  const Pack p = MakeTestPack(40, 30, 3);
  const Pack e = EncodePackValues(p, {});
  auto within = [](float a, float b) {
    return std::abs(a - b) <= std::ldexp(1.0f, -11) * std::abs(b) + std::ldexp(1.0f, -25);
  };
  for (size_t i = 0; i < p.field.height_mm.size(); ++i) {
    ASSERT_TRUE(within(e.field.height_mm.data[i], p.field.height_mm.data[i]));
    for (int c = 0; c < 3; ++c) {
      ASSERT_TRUE(within(e.maps.rho_d.data[i][c], p.maps.rho_d.data[i][c]));
      ASSERT_TRUE(within(e.maps.rho_s.data[i][c], p.maps.rho_s.data[i][c]));
    }
    ASSERT_TRUE(within(e.maps.lobe.data[i][3], p.maps.lobe.data[i][3]));
    // nz is recomputed from the stored (nx, ny): the normal moves by about the rounding of nx, ny.
    ASSERT_LT((e.normals.data[i] - p.normals.data[i]).norm(), 2e-3f);
    ASSERT_NEAR(e.normals.data[i].norm(), 1.0f, 1e-6f);
  }
}

TEST(Pack, QuantisedRoundTripIsWithinTheStatedBound) {
  const fs::path dir = TempDir("quant");
  const Pack p = MakeTestPack(64, 48, 4);
  PackWriteOptions o;
  o.encoding = PackEncoding::kQuantised;
  o.quantisation = {8, 6, 5, 6};
  ASSERT_OK(WritePack(dir / "q.pack.exr", p, o));
  auto r = ReadPack(dir / "q.pack.exr");
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectIdentical(EncodePackValues(p, o), *r);
  // Stated bound: 2^-(bits+1) relative for the kept mantissa, after the half rounding 2^-11.
  auto bound = [](int bits) { return std::ldexp(1.0f, -(bits + 1)) + std::ldexp(1.0f, -11); };
  for (size_t i = 0; i < p.field.height_mm.size(); ++i) {
    ASSERT_LE(std::abs(r->field.height_mm.data[i] - p.field.height_mm.data[i]),
              bound(8) * std::abs(p.field.height_mm.data[i]) + 1e-7f);
    for (int c = 0; c < 3; ++c)
      ASSERT_LE(std::abs(r->maps.rho_s.data[i][c] - p.maps.rho_s.data[i][c]),
                bound(5) * p.maps.rho_s.data[i][c] + 1e-7f);
    ASSERT_LE(std::abs(r->maps.lobe.data[i][3] - p.maps.lobe.data[i][3]),
              bound(6) * p.maps.lobe.data[i][3] + 1e-7f);
  }
  auto s = InspectPack(dir / "q.pack.exr");
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->encoding, PackEncoding::kQuantised);
  EXPECT_EQ(s->quantisation.rho_bits, 5);
  fs::remove_all(dir);
}

// The paper's budget: 26 bytes per texel before compression; compression must help.
TEST(Pack, SizeBudget) {
  const fs::path dir = TempDir("size");
  const Pack p = MakeTestPack(128, 96, 5);
  ASSERT_OK(WritePack(dir / "h.pack.exr", p));
  PackWriteOptions o;
  o.encoding = PackEncoding::kQuantised;
  ASSERT_OK(WritePack(dir / "q.pack.exr", p, o));
  auto h = InspectPack(dir / "h.pack.exr");
  auto q = InspectPack(dir / "q.pack.exr");
  ASSERT_TRUE(h.ok() && q.ok());
  EXPECT_EQ(h->raw_bytes_per_texel, 26);
  EXPECT_LT(h->BytesPerTexel(), 26.0);
  // Random reflectance is the worst case for a compressor; dropping mantissa bits still shrinks it.
  EXPECT_LT(q->BytesPerTexel(), h->BytesPerTexel() * 0.9);
  EXPECT_EQ(h->width, 128);
  EXPECT_EQ(h->box_count, p.boxes.size());
  EXPECT_EQ(h->provenance.inputs.size(), 1u);
  fs::remove_all(dir);
}

TEST(Pack, FlatCanvasWithoutBoxesRoundTrips) {
  const fs::path dir = TempDir("flat");
  const Pack p = MakeTestPack(33, 17, 6, /*with_relief=*/false);
  ASSERT_TRUE(p.boxes.empty());
  ASSERT_OK(WritePack(dir / "f.pack.exr", p));
  auto r = ReadPack(dir / "f.pack.exr");
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectIdentical(EncodePackValues(p, {}), *r);
  auto v = VerifyPack(dir / "f.pack.exr");
  EXPECT_TRUE(v.ok()) << v.error().message;
  fs::remove_all(dir);
}

TEST(Pack, VerifyPassesAGoodPackAndCatchesAWrongBox) {
  const fs::path dir = TempDir("verify");
  Pack p = MakeTestPack(64, 48, 7);
  ASSERT_OK(WritePack(dir / "good.pack.exr", p));
  auto v = VerifyPack(dir / "good.pack.exr");
  ASSERT_TRUE(v.ok()) << v.error().message;
  EXPECT_GE(v->checks.size(), 4u);
  // A box whose h_max is not its cell's peak: still a valid pack, but not a consistent one.
  ASSERT_FALSE(p.boxes.empty());
  p.boxes[0].h_max_mm = static_cast<float>(p.delta0_mm);
  ASSERT_OK(WritePack(dir / "bad.pack.exr", p));
  EXPECT_TRUE(ReadPack(dir / "bad.pack.exr").ok());
  auto bad = VerifyPack(dir / "bad.pack.exr");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("box 0"), std::string::npos) << bad.error().message;
  fs::remove_all(dir);
}

TEST(Pack, WriteRefusesInvalidPacksAndLeavesTheOldFile) {
  const fs::path dir = TempDir("refuse");
  const fs::path path = dir / "p.pack.exr";
  const Pack good = MakeTestPack(32, 24, 8);
  ASSERT_OK(WritePack(path, good));
  const auto before = ReadBytes(path);

  Pack nan = good;
  nan.maps.rho_d(5, 6) = Vec3f(std::nanf(""), 0, 0);
  Status s = WritePack(path, nan);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("p.pack.exr"), std::string::npos) << s.message();

  Pack huge = good;
  huge.maps.rho_s(7, 8) = Vec3f(1e6f, 0, 0);  // beyond half: would read back as Inf
  s = WritePack(path, huge);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("rho_s at texel 7, 8"), std::string::npos) << s.message();

  Pack outside_box = good;
  ASSERT_FALSE(outside_box.boxes.empty());
  outside_box.boxes[0].u_max = outside_box.boxes[0].x0 + outside_box.boxes[0].width;
  EXPECT_FALSE(WritePack(path, outside_box).ok());

  PackWriteOptions o;
  o.encoding = PackEncoding::kQuantised;
  o.quantisation.rho_bits = 11;
  s = WritePack(path, good, o);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("rho_bits"), std::string::npos);

  EXPECT_EQ(ReadBytes(path), before);  // untouched
  int files = 0;
  for (auto& e : fs::directory_iterator(dir)) files += e.is_regular_file();
  EXPECT_EQ(files, 1);  // no temporary left behind
  fs::remove_all(dir);
}

// Every prefix of a pack is refused (the header scan, the OpenEXR reader or the checksum),
// naming the file.
TEST(Pack, TruncatedPacksAreRefused) {
  const fs::path dir = TempDir("trunc");
  ASSERT_OK(WritePack(dir / "p.pack.exr", MakeTestPack(32, 24, 9)));
  const auto bytes = ReadBytes(dir / "p.pack.exr");
  const fs::path cut = dir / "cut.pack.exr";
  for (size_t len : {size_t{0}, size_t{4}, size_t{8}, size_t{100}, bytes.size() / 4,
                     bytes.size() / 2, bytes.size() - 100, bytes.size() - 1}) {
    WriteBytes(cut, std::vector<char>(bytes.begin(), bytes.begin() + static_cast<long>(len)));
    auto r = ReadPack(cut);
    ASSERT_FALSE(r.ok()) << "length " << len;
    EXPECT_NE(r.error().message.find("cut.pack.exr"), std::string::npos) << r.error().message;
  }
  fs::remove_all(dir);
}

// A flipped bit anywhere is either refused or harmless (an attribute nobody reads): the reader
// never returns values other than the ones written.
TEST(Pack, BitFlippedPacksAreRefusedOrHarmless) {
  const fs::path dir = TempDir("flip");
  const Pack p = MakeTestPack(32, 24, 10);
  ASSERT_OK(WritePack(dir / "p.pack.exr", p));
  const Pack expected = EncodePackValues(p, {});
  const auto bytes = ReadBytes(dir / "p.pack.exr");
  const fs::path flipped = dir / "f.pack.exr";
  std::mt19937 rng(11);
  int refused = 0, harmless = 0;
  for (int trial = 0; trial < 150; ++trial) {
    auto b = bytes;
    const size_t at = rng() % b.size();
    b[at] = static_cast<char>(b[at] ^ (1 << (rng() % 8)));
    WriteBytes(flipped, b);
    auto r = ReadPack(flipped);
    if (!r.ok()) {
      ++refused;
      EXPECT_NE(r.error().message.find("f.pack.exr"), std::string::npos) << r.error().message;
      continue;
    }
    ++harmless;
    SCOPED_TRACE("byte " + std::to_string(at));
    ExpectIdentical(expected, *r);
    if (::testing::Test::HasFailure()) break;
  }
  EXPECT_GT(refused, 100);  // almost every byte is pixel data, guarded by the checksum
  std::printf("bit flips: %d refused, %d harmless\n", refused, harmless);
  fs::remove_all(dir);
}

// Patches the first occurrence of `from` (same length as `to`) in the file.
bool Patch(std::vector<char>& bytes, const std::string& from, const std::string& to) {
  const auto it = std::search(bytes.begin(), bytes.end(), from.begin(), from.end());
  if (it == bytes.end()) return false;
  std::copy(to.begin(), to.end(), it);
  return true;
}

TEST(Pack, NewerVersionIsRefused) {
  const fs::path dir = TempDir("version");
  ASSERT_OK(WritePack(dir / "p.pack.exr", MakeTestPack(16, 16, 12)));
  auto bytes = ReadBytes(dir / "p.pack.exr");
  // digitize:version is a 1-character string attribute: name, type, size 1 (little endian), "2".
  const std::string attr = std::string("digitize:version") + '\0' + "string" + '\0' +
                           std::string("\x01\x00\x00\x00", 4) + std::to_string(kPackVersion);
  std::string newer = attr;
  newer.back() = '7';
  ASSERT_TRUE(Patch(bytes, attr, newer));
  WriteBytes(dir / "v7.pack.exr", bytes);
  auto r = ReadPack(dir / "v7.pack.exr");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("version 7 is newer"), std::string::npos) << r.error().message;
  EXPECT_FALSE(InspectPack(dir / "v7.pack.exr").ok());
  fs::remove_all(dir);
}

// A forged data window claiming 2^30 x 2^30 pixels is refused before anything is allocated.
TEST(Pack, OversizedHeaderIsRefusedBeforeAllocation) {
  const fs::path dir = TempDir("oversize");
  ASSERT_OK(WritePack(dir / "p.pack.exr", MakeTestPack(16, 16, 13)));
  auto bytes = ReadBytes(dir / "p.pack.exr");
  const std::string window = std::string("dataWindow") + '\0' + "box2i" + '\0' +
                             std::string("\x10\x00\x00\x00", 4) + std::string(8, '\0') +
                             std::string("\x0f\x00\x00\x00\x0f\x00\x00\x00", 8);
  const std::string forged =
      window.substr(0, window.size() - 8) + std::string("\xff\xff\xff\x3f\xff\xff\xff\x3f", 8);
  ASSERT_TRUE(Patch(bytes, window, forged));
  WriteBytes(dir / "big.pack.exr", bytes);
  auto r = ReadPack(dir / "big.pack.exr");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("-texel limit"), std::string::npos) << r.error().message;
  // A caller's tighter bound applies too.
  PackReadOptions tight;
  tight.max_texels = 100;
  auto t = ReadPack(dir / "p.pack.exr", tight);
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.error().message.find("100-texel limit"), std::string::npos) << t.error().message;
  fs::remove_all(dir);
}

TEST(Pack, OtherFilesAreNotPacks) {
  const fs::path dir = TempDir("other");
  ASSERT_TRUE(WriteFloatExr(dir / "plain.exr", Grid<float>(8, 8, 1.0f), "Y").ok());
  auto r = ReadPack(dir / "plain.exr");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("plain.exr"), std::string::npos);
  EXPECT_NE(r.error().message.find("single-part"), std::string::npos) << r.error().message;
  WriteBytes(dir / "text.pack.exr", {'h', 'e', 'l', 'l', 'o', ' ', 'w', 'o', 'r', 'l', 'd'});
  r = ReadPack(dir / "text.pack.exr");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("not an OpenEXR file"), std::string::npos) << r.error().message;
  r = ReadPack(dir / "missing.pack.exr");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("no such file"), std::string::npos);
  r = ReadPack(dir);
  ASSERT_FALSE(r.ok());
  fs::remove_all(dir);
}

// The generator's painting (impasto, paint regions matte to varnish, its relief boxes): half is
// bit-exact, quantised reads back exactly the encoded values, and the quantised file is smaller.
TEST(Pack, SyntheticPaintingRoundTrips) {
  const fs::path dir = TempDir("painting");
  synth::PaintingOptions po;
  po.resolution_px = 200;
  const Pack p = synth::MakeTruthPack(synth::MakePainting(po));
  ASSERT_TRUE(p.Validate().ok()) << p.Validate().message();
  ASSERT_FALSE(p.boxes.empty());
  ASSERT_OK(WritePack(dir / "h.pack.exr", p));
  auto h = ReadPack(dir / "h.pack.exr");
  ASSERT_TRUE(h.ok()) << h.error().message;
  ExpectIdentical(EncodePackValues(p, {}), *h);
  PackWriteOptions q;
  q.encoding = PackEncoding::kQuantised;
  ASSERT_OK(WritePack(dir / "q.pack.exr", p, q));
  auto r = ReadPack(dir / "q.pack.exr");
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectIdentical(EncodePackValues(p, q), *r);
  EXPECT_LT(fs::file_size(dir / "q.pack.exr"), fs::file_size(dir / "h.pack.exr"));
  EXPECT_TRUE(VerifyPack(dir / "h.pack.exr").ok());
  EXPECT_TRUE(VerifyPack(dir / "q.pack.exr").ok());
  fs::remove_all(dir);
}

// A pack is shared between institutions: its checksum can be recomputed by anyone (an integrity
// check, not authentication), so physically absurd metadata must be refused on its own, by the
// reader, InspectPack and VerifyPack alike, naming the file and the attribute.
TEST(Pack, ForgedAbsurdMetadataIsRefused) {
  const fs::path dir = TempDir("forged");
  const Pack p = MakeTestPack(64, 48, 15);  // pitch 0.125 mm: 8 x 6 mm
  ASSERT_OK(WritePack(dir / "good.pack.exr", p));
  // The forgery itself is sound: unchanged attributes and a recomputed checksum read back.
  ASSERT_EQ(forge::ForgePack(dir / "good.pack.exr", dir / "resealed.pack.exr", {}), "");
  auto same = VerifyPack(dir / "resealed.pack.exr");
  ASSERT_TRUE(same.ok()) << same.error().message;
  const std::string rotation = R"("rotation":[[1,0,0],[0,1,0],[0,0,1]])";
  struct Case {
    const char* name;
    std::map<std::string, std::string> attributes;
    const char* expect;  // in the message, after the file name
  };
  const std::vector<Case> cases = {
      {"pitch_1e308", {{"digitize:pitch_mm", "1e308"}}, "digitize:pitch_mm 1e+308 x 64 texels"},
      {"pitch_tiny",
       {{"digitize:pitch_mm", "1e-300"}},
       "digitize:pitch_mm 1e-300 is not a texel pitch"},
      // 2 m texels: 128 m wide, with a size_mm that agrees, so the bound is what refuses it.
      {"pitch_2000",
       {{"digitize:pitch_mm", "2000"}, {"digitize:size_mm", "128000 x 96000"}},
       "digitize:pitch_mm 2000 x 64 texels = 128000 mm, beyond the 100 m"},
      {"max_height",
       {{"digitize:max_height_mm", "1e30"}},
       "digitize:max_height_mm 1e+30 is outside"},
      {"delta0", {{"digitize:delta0_mm", "-1"}}, "digitize:delta0_mm -1 is not in"},
      {"size_mm", {{"digitize:size_mm", "800 x 600"}}, "digitize:size_mm 800 x 600 mm disagrees"},
      {"size_mm_text",
       {{"digitize:size_mm", "big"}},
       "header attribute digitize:size_mm = \"big\" is not"},
      {"translation",
       {{"digitize:canvas_from_scan", "{" + rotation + R"(,"translation_mm":[0,0,1e12]})"}},
       "digitize:canvas_from_scan translation (0, 0, 1e+12) mm is farther than 100 m"},
      {"rotation",
       {{"digitize:canvas_from_scan",
         R"({"rotation":[[2,0,0],[0,2,0],[0,0,2]],"translation_mm":[0,0,0]})"}},
       "digitize:canvas_from_scan rotation is not a rotation"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const fs::path forged = dir / (std::string(c.name) + ".pack.exr");
    ASSERT_EQ(forge::ForgePack(dir / "good.pack.exr", forged, c.attributes), "");
    const std::string want = forged.string() + ": " + c.expect;
    auto read = ReadPack(forged);
    ASSERT_FALSE(read.ok());
    EXPECT_NE(read.error().message.find(want), std::string::npos) << read.error().message;
    auto inspect = InspectPack(forged);
    ASSERT_FALSE(inspect.ok());
    EXPECT_EQ(inspect.error().message, read.error().message);
    auto verify = VerifyPack(forged);
    ASSERT_FALSE(verify.ok());
    EXPECT_EQ(verify.error().message, read.error().message);
  }
  fs::remove_all(dir);
}

// The same bounds in memory: the writer refuses what the reader would, so no tool writes a pack
// that no reader opens.
TEST(Pack, ValidateAppliesThePhysicalBounds) {
  const Pack good = MakeTestPack(32, 24, 16);
  ASSERT_OK(good.Validate());
  auto refused = [](Pack p, auto edit, const std::string& expect) {
    edit(p);
    const Status s = p.Validate();
    EXPECT_FALSE(s.ok()) << expect;
    EXPECT_NE(s.message().find(expect), std::string::npos) << s.message();
  };
  refused(
      good, [](Pack& p) { p.field.pitch_mm = 1e308; }, "pitch_mm 1e+308 x 32 texels");
  refused(
      good, [](Pack& p) { p.field.pitch_mm = 1e-9; }, "is not a texel pitch");
  refused(
      good, [](Pack& p) { p.field.pitch_mm = kMaxPackExtentMm / 31; }, "beyond the 100 m");
  refused(
      good, [](Pack& p) { p.field.height_mm(3, 4) = 2000.0f; }, "height at texel 3, 4 = 2000");
  refused(
      good, [](Pack& p) { p.max_height_mm = 5000; }, "max_height_mm 5000 is outside");
  refused(
      good, [](Pack& p) { p.canvas_from_scan.translation.x() = 2e5; }, "farther than 100 m");
  refused(
      good, [](Pack& p) { p.canvas_from_scan.rotation *= 1.01; }, "is not a rotation");
  // At the bounds themselves: accepted (100 m exactly, heights of 1 m).
  Pack edge = good;
  edge.field.pitch_mm = kMaxPackExtentMm / 32;
  EXPECT_TRUE(edge.Validate().ok()) << edge.Validate().message();
  const fs::path dir = TempDir("bounds");
  Pack absurd = good;
  absurd.field.pitch_mm = 1e308;
  const Status s = WritePack(dir / "absurd.pack.exr", absurd);
  ASSERT_FALSE(s.ok());
  EXPECT_FALSE(fs::exists(dir / "absurd.pack.exr"));
  fs::remove_all(dir);
}

// Provenance names inputs relative to a folder (the calibration file's), never as absolute paths
// of the machine that made the pack.
TEST(Pack, ProvenanceInputsAreRelative) {
  const fs::path dir = TempDir("provenance");
  fs::create_directories(dir / "capture" / "images");
  fs::create_directories(dir / "scans");
  for (const fs::path& f : {dir / "capture" / "calib.json", dir / "capture" / "images" / "a.png",
                            dir / "scans" / "scan.exr"})
    WriteBytes(f, {'x'});
  PackProvenance p;
  ASSERT_OK(AddProvenanceInputs(p,
                                {dir / "scans" / "scan.exr", dir / "capture" / "calib.json",
                                 dir / "capture" / "images" / "a.png"},
                                dir / "capture"));
  ASSERT_EQ(p.inputs.size(), 3u);
  EXPECT_EQ(p.inputs[0].name, "../scans/scan.exr");
  EXPECT_EQ(p.inputs[1].name, "calib.json");
  EXPECT_EQ(p.inputs[2].name, "images/a.png");
  PackProvenance plain;
  ASSERT_OK(AddProvenanceInputs(plain, {fs::absolute(dir / "scans" / "scan.exr")}));
  EXPECT_EQ(plain.inputs[0].name, "scan.exr");
  for (const PackInput& in : p.inputs) EXPECT_EQ(in.name.find(dir.string()), std::string::npos);
  fs::remove_all(dir);
}

TEST(Pack, AssembleChecksGridSizes) {
  const Pack p = MakeTestPack(20, 10, 14);
  PreprocessedCanvas c;
  c.field = p.field;
  c.normals = p.normals;
  c.delta0_mm = p.delta0_mm;
  c.max_height_mm = p.max_height_mm;
  c.cell_px = p.cell_px;
  c.boxes = p.boxes;
  auto ok = AssemblePack(c, p.maps, p.provenance);
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  auto bad = AssemblePack(c, ReflectanceMaps::Zeros(10, 10), {});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("another canvas"), std::string::npos);
}

// --- reflectance models (version 2) -----------------------------------------------------------

int64_t CountGgx(const Pack& p) {
  return std::count(p.maps.model.data.begin(), p.maps.model.data.end(), ReflectanceModel::kGgx);
}

// A pack file whose part `part` has `channel` of texel (x, y) set to `value`, resealed.
std::string ForgeTexel(const fs::path& from, const fs::path& to, int part,
                       const std::string& channel, int x, int y, float value) {
  return forge::ForgePack(from, to, {}, {},
                          [&](int p, const OIIO::ImageSpec& spec, std::vector<char>& pixels) {
                            if (p == part) {
                              EXPECT_TRUE(forge::SetHalf(spec, pixels, channel, x, y, value));
                            }
                          });
}

// GGX texels keep their model and their values through a file, bit for bit in half; inspect,
// verify and `inspect --json` count the texels of each model.
TEST(Pack, GgxTexelsRoundTripWithTheirModel) {
  const fs::path dir = TempDir("ggx");
  const Pack p = MakeGgxTestPack(64, 48, 21);
  ASSERT_OK(p.Validate());
  const int64_t ggx = CountGgx(p);
  ASSERT_GT(ggx, 64 * 48 / 3);
  ASSERT_OK(WritePack(dir / "g.pack.exr", p));
  auto r = ReadPack(dir / "g.pack.exr");
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectIdentical(EncodePackValues(p, {}), *r);
  EXPECT_EQ(CountGgx(*r), ggx);
  // The texels shade as they were written (half rounding of F0 and alpha: 2^-11 relative; the
  // peak D ~ 1 / alpha^2 doubles it, the Fresnel and G terms are smooth: 1e-2 is generous).
  const Vec3f v = Vec3f(0.3f, -0.2f, 1.0f).normalized(), l = Vec3f(-0.25f, 0.2f, 1.0f).normalized();
  for (int y = 0; y < p.height(); ++y)
    for (int x = p.width() / 2; x < p.width(); ++x) {
      const Vec3f a = p.maps.Evaluate(x, y, v, l), b = r->maps.Evaluate(x, y, v, l);
      ASSERT_LE((a - b).norm(), 1e-2f * a.norm() + 1e-6f) << x << ", " << y;
    }

  auto s = InspectPack(dir / "g.pack.exr");
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ(s->version, kPackVersion);
  EXPECT_EQ(s->texels_by_model[size_t(ReflectanceModel::kGgx)], ggx);
  EXPECT_EQ(s->texels_by_model[size_t(ReflectanceModel::kLafortune)], 64 * 48 - ggx);
  EXPECT_EQ(s->raw_bytes_per_texel, 26);  // the model shares M: no channel added
  const nlohmann::json j = nlohmann::json::parse(PackSummaryJson("g.pack.exr", *s));
  EXPECT_EQ(j["models"]["ggx"], ggx);
  EXPECT_EQ(j["models"]["lafortune"], 64 * 48 - ggx);
  auto verified = VerifyPack(dir / "g.pack.exr");
  ASSERT_TRUE(verified.ok()) << verified.error().message;
  const std::string want = "models: " + std::to_string(64 * 48 - ggx) + " lafortune, " +
                           std::to_string(ggx) + " ggx texels (as digitize:models)";
  EXPECT_EQ(std::count_if(verified->checks.begin(), verified->checks.end(),
                          [&](const std::string& c) { return c.rfind(want, 0) == 0; }),
            1)
      << want;
  fs::remove_all(dir);
}

// Quantisation rounds to nearest, which could take alpha below kGgxMinAlpha (0 lobe bits:
// 0.005 -> 0.0039); F0 must stay <= 1 (0.78 with 0 rho bits rounds to 1, never above). Every
// encoding leaves a valid pack with the models unchanged, and the file reads back exactly that.
TEST(Pack, QuantisedGgxTexelsStayValid) {
  const fs::path dir = TempDir("ggx_quant");
  const Pack p = MakeGgxTestPack(40, 30, 22);
  for (const int lobe_bits : {0, 1, 3, 6, 10}) {
    for (const int rho_bits : {0, 4}) {
      SCOPED_TRACE("lobe_bits " + std::to_string(lobe_bits) + ", rho_bits " +
                   std::to_string(rho_bits));
      PackWriteOptions o;
      o.encoding = PackEncoding::kQuantised;
      o.quantisation = {8, 5, rho_bits, lobe_bits};
      const Pack e = EncodePackValues(p, o);
      ASSERT_OK(e.Validate());
      ASSERT_TRUE(SameBits(e.maps.model, p.maps.model));
      const float bound = std::ldexp(1.0f, -(lobe_bits + 1)) + std::ldexp(1.0f, -11);
      for (size_t i = 0; i < e.maps.model.size(); ++i) {
        if (e.maps.model.data[i] != ReflectanceModel::kGgx) continue;
        const auto& lobe = e.maps.lobe.data[i];
        const float alpha = lobe[3], want = p.maps.lobe.data[i][3];
        ASSERT_GE(alpha, kGgxMinAlpha);
        ASSERT_LE(alpha, kGgxMaxAlpha);
        ASSERT_EQ(lobe[0], 0.0f);
        ASSERT_EQ(lobe[1], 0.0f);
        // Within the stated bound, or raised to the first kept value above kGgxMinAlpha.
        if (std::abs(alpha - want) > bound * want) {
          ASSERT_LT(want, 2.0f * kGgxMinAlpha);
        }
        ASSERT_LE(e.maps.rho_s.data[i].maxCoeff(), 1.0f);
      }
      ASSERT_OK(WritePack(dir / "q.pack.exr", p, o));
      auto r = ReadPack(dir / "q.pack.exr");
      ASSERT_TRUE(r.ok()) << r.error().message;
      ExpectIdentical(e, *r);
    }
  }
  fs::remove_all(dir);
}

// What version 1 writers put in the header (before models): their gauge and units, no
// digitize:models. M was state + 4 x status, which is version 2's code for a Lafortune texel.
const std::map<std::string, std::string> kVersion1Header = {
    {"digitize:version", "1"},
    {"digitize:gauge",
     "lafortune1: f = rho_d + rho_s max(0, cx vx lx + cy vy ly + vz lz)^k, cz = 1, v and l in "
     "the texel's tangent frame (tangent_frame.h)"},
    {"digitize:units",
     "H mm above the canvas plane; NX NY unit normal (nz = sqrt(1 - nx^2 - ny^2)); M = texel "
     "state + 4 x fit status; rho_d rho_s 1/sr; boxes: h_max mm, u/v_max texels from the cell "
     "corner"}};

// Packs written before models existed still read: every texel Lafortune, the values as written.
TEST(Pack, VersionOnePacksReadAsLafortune) {
  const fs::path dir = TempDir("v1");
  const Pack p = MakeTestPack(32, 24, 23);
  ASSERT_OK(WritePack(dir / "v2.pack.exr", p));
  ASSERT_EQ(forge::ForgePack(dir / "v2.pack.exr", dir / "v1.pack.exr", kVersion1Header,
                             {"digitize:models"}),
            "");
  auto r = ReadPack(dir / "v1.pack.exr");
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectIdentical(EncodePackValues(p, {}), *r);
  EXPECT_EQ(CountGgx(*r), 0);
  auto s = InspectPack(dir / "v1.pack.exr");
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ(s->version, 1);
  EXPECT_EQ(s->texels_by_model[size_t(ReflectanceModel::kLafortune)], 32 * 24);
  EXPECT_EQ(s->texels_by_model[size_t(ReflectanceModel::kGgx)], 0);
  auto verified = VerifyPack(dir / "v1.pack.exr");
  ASSERT_TRUE(verified.ok()) << verified.error().message;
  // A version 1 M with a model term is not a version 1 code.
  ASSERT_EQ(ForgeTexel(dir / "v1.pack.exr", dir / "v1_m.pack.exr", 0, "M", 3, 2, 65.0f), "");
  auto bad = ReadPack(dir / "v1_m.pack.exr");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().message,
            (dir / "v1_m.pack.exr").string() +
                ": texel 3, 2: M = 65 is not a texel state + 4 x fit status (version 1)");
  // A version 2 pack without its model counts is refused.
  ASSERT_EQ(
      forge::ForgePack(dir / "v2.pack.exr", dir / "v2_no_models.pack.exr", {}, {"digitize:models"}),
      "");
  auto missing = InspectPack(dir / "v2_no_models.pack.exr");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().message, (dir / "v2_no_models.pack.exr").string() +
                                         ": header attribute digitize:models is missing");
  fs::remove_all(dir);
}

// The model is untrusted input: an unknown model value, a GGX texel out of its ranges, counts
// that disagree with the texels -- each refused naming the file (and the texel).
TEST(Pack, UnknownOrInvalidModelsAreRefused) {
  const fs::path dir = TempDir("models_bad");
  const Pack p = MakeGgxTestPack(32, 24, 24);
  const fs::path good = dir / "g.pack.exr";
  ASSERT_OK(WritePack(good, p));
  ASSERT_EQ(p.maps.model(28, 4), ReflectanceModel::kGgx);
  ASSERT_EQ(p.maps.model(5, 4), ReflectanceModel::kLafortune);
  struct Case {
    const char* name;
    int part;
    const char* channel;
    int x, y;
    float value;
    std::string expect;  // the message after "FILE: "
  };
  const std::vector<Case> cases = {
      {"model2", 0, "M", 5, 4, 2 * 64 + 1,
       "texel 5, 4: M = 129 names reflectance model 2, which this reader does not know "
       "(lafortune = 0, ggx = 1)"},
      {"model31", 0, "M", 5, 4, 31 * 64,
       "texel 5, 4: M = 1984 names reflectance model 31, which this reader does not know "
       "(lafortune = 0, ggx = 1)"},
      {"status", 0, "M", 5, 4, 1 + 4 * 15,
       "texel 5, 4: M = 61 is not a texel state + 4 x fit status + 64 x reflectance model"},
      {"f0", 1, "rho_s.G", 28, 4, 1.5f, "texel 28, 4: a GGX texel's F0 (rho_s) exceeds 1"},
      {"alpha", 1, "lobe.k", 28, 4, 0.001f,
       "texel 28, 4: a GGX texel's alpha (lobe.k) 0.0010004 is outside [0.005, 1]"},
      {"cx", 1, "lobe.cx", 28, 4, -1.0f, "texel 28, 4: a GGX texel's lobe.cx, lobe.cy must be 0"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const fs::path forged = dir / (std::string(c.name) + ".pack.exr");
    ASSERT_EQ(ForgeTexel(good, forged, c.part, c.channel, c.x, c.y, c.value), "");
    auto r = ReadPack(forged);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message, forged.string() + ": " + c.expect);
    auto v = VerifyPack(forged);
    ASSERT_FALSE(v.ok());
    EXPECT_EQ(v.error().message, r.error().message);
  }
  // Header counts that add up but disagree with the texels.
  const int64_t ggx = CountGgx(p), laf = 32 * 24 - ggx;
  const fs::path moved = dir / "counts.pack.exr";
  ASSERT_EQ(forge::ForgePack(good, moved,
                             {{"digitize:models", "lafortune=" + std::to_string(laf + 1) +
                                                      ",ggx=" + std::to_string(ggx - 1)}}),
            "");
  auto r = ReadPack(moved);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().message,
            moved.string() + ": the texels are lafortune=" + std::to_string(laf) +
                ",ggx=" + std::to_string(ggx) + ", the header's digitize:models says lafortune=" +
                std::to_string(laf + 1) + ",ggx=" + std::to_string(ggx - 1));
  for (const std::string& text :
       {std::string("ggx=3"), std::string("lafortune=1,ggx=2,x=1"),
        std::string("lafortune=-1,ggx=769"), std::string("lafortune=768,ggx=1")}) {
    SCOPED_TRACE(text);
    const fs::path forged = dir / "models_text.pack.exr";
    ASSERT_EQ(forge::ForgePack(good, forged, {{"digitize:models", text}}), "");
    auto s = InspectPack(forged);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().message.rfind(forged.string() + ": ", 0), 0u) << s.error().message;
    EXPECT_NE(s.error().message.find("digitize:models"), std::string::npos) << s.error().message;
  }
  fs::remove_all(dir);
}

// --- version 3: tiled, multi-resolution packs (pack_tiled.h) ---------------------------------

// A pack of the encoded values of a level (what a tiled pack of `options` stores at that level).
Pack EncodedLevel(const PackLevel& level, const Pack& like, const PackWriteOptions& options) {
  Pack p;
  p.field = level.field;
  p.normals = level.normals;
  p.maps = level.maps;
  p.delta0_mm = like.delta0_mm;
  p.max_height_mm = like.max_height_mm;
  p.cell_px = like.cell_px;
  return EncodePackValues(p, options);
}

// Level 0 of a tiled pack holds exactly the single-grid pack's values (bit for bit, half and
// quantised), on a size that is no multiple of the tile (300 x 170 in 64-texel tiles: clipped
// tiles on two sides), with GGX and Lafortune texels and relief boxes.
TEST(TiledPack, LevelZeroIsTheSingleGridPack) {
  const fs::path dir = TempDir("tiled_level0");
  const Pack p = MakeGgxTestPack(300, 170, 21);
  ASSERT_FALSE(p.boxes.empty());
  for (PackEncoding e : {PackEncoding::kHalf, PackEncoding::kQuantised}) {
    PackWriteOptions o;
    o.encoding = e;
    o.tile_size = 64;
    const fs::path file = dir / (std::string(ToString(e)) + ".pack.exr");
    ASSERT_OK(WritePack(file, p, o));
    auto s = InspectPack(file);
    ASSERT_TRUE(s.ok()) << s.error().message;
    EXPECT_EQ(s->version, kTiledPackVersion);
    EXPECT_EQ(s->tile_size, 64);
    ASSERT_EQ(s->levels.size(), 10u);  // 300 x 170 ... 2 x 1, 1 x 1
    EXPECT_EQ(s->levels[1][0], 150);
    EXPECT_EQ(s->levels[2][1], 43);
    EXPECT_EQ(s->levels.back()[0], 1);
    EXPECT_EQ(s->texels_by_model, HeaderOf(p).texels_by_model);
    auto r = ReadPack(file);
    ASSERT_TRUE(r.ok()) << r.error().message;
    ExpectIdentical(EncodePackValues(p, o), *r);
    auto v = VerifyPack(file);
    EXPECT_TRUE(v.ok()) << v.error().message;
  }
  fs::remove_all(dir);
}

// Every level's tiles hold the prefilter (pack_pyramid.h) of the whole level above, encoded:
// the writer filters each band of tile_size rows as it comes (and gathers the filtered rows into
// bands of the next level), and this asserts the bands change nothing -- texel for texel, bit
// for bit, on every level down to 1 x 1 (333 x 201 texels in 64-row bands leave odd rows and
// columns at several levels, and a last band of 9 rows).
TEST(TiledPack, EveryLevelIsThePrefilterOfTheWholeLevelAbove) {
  const fs::path dir = TempDir("tiled_levels");
  const Pack p = MakeGgxTestPack(333, 201, 22);
  PackWriteOptions o;
  o.tile_size = 64;
  ASSERT_OK(WritePack(dir / "p.pack.exr", p, o));
  auto reader = TiledPackReader::Open(dir / "p.pack.exr");
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  const PackSummary& s = (*reader)->summary();
  PackLevel level = BaseLevel(p.field, p.normals, p.maps);
  int64_t compared = 0;
  for (size_t l = 0; l < s.levels.size(); ++l) {
    if (l > 0) level = PrefilterLevel(level);
    ASSERT_EQ(level.field.width(), s.levels[l][0]);
    ASSERT_EQ(level.field.height(), s.levels[l][1]);
    const Pack want = EncodedLevel(level, p, o);
    for (int ty = 0; ty * 64 < want.height(); ++ty)
      for (int tx = 0; tx * 64 < want.width(); ++tx) {
        auto tile = (*reader)->ReadTile(static_cast<int>(l), tx, ty);
        ASSERT_TRUE(tile.ok()) << tile.error().message;
        const PackLevel& t = tile->texels;
        EXPECT_DOUBLE_EQ(t.field.pitch_mm, p.field.pitch_mm * std::ldexp(1.0, int(l)));
        for (int y = 0; y < t.field.height(); ++y)
          for (int x = 0; x < t.field.width(); ++x) {
            const int X = tile->x0 + x, Y = tile->y0 + y;
            ASSERT_EQ(t.field.height_mm(x, y), want.field.height_mm(X, Y))
                << l << ": " << X << "," << Y;
            ASSERT_EQ(t.field.state(x, y), want.field.state(X, Y));
            ASSERT_EQ(t.normals(x, y), want.normals(X, Y));
            ASSERT_EQ(t.maps.rho_d(x, y), want.maps.rho_d(X, Y));
            ASSERT_EQ(t.maps.rho_s(x, y), want.maps.rho_s(X, Y));
            ASSERT_EQ(t.maps.lobe(x, y), want.maps.lobe(X, Y));
            ASSERT_EQ(t.maps.model(x, y), want.maps.model(X, Y));
            ASSERT_EQ(t.maps.status(x, y), want.maps.status(X, Y));
            ++compared;
          }
      }
  }
  // Level 0 and everything below it (about a third more): each texel once.
  EXPECT_GT(compared, 333 * 201 * 4 / 3 - 10);
  fs::remove_all(dir);
}

// Tiles read from two threads at once are the tiles read one by one.
TEST(TiledPack, TilesReadFromTwoThreadsAreTheSame) {
  const fs::path dir = TempDir("tiled_threads");
  PackWriteOptions o;
  o.tile_size = 64;
  ASSERT_OK(WritePack(dir / "p.pack.exr", MakeTestPack(256, 192, 23), o));
  auto reader = TiledPackReader::Open(dir / "p.pack.exr");
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  std::vector<float> one, two[2];
  for (int ty = 0; ty < 3; ++ty)
    for (int tx = 0; tx < 4; ++tx)
      one.push_back((*reader)->ReadTile(0, tx, ty)->texels.field.height_mm(5, 7));
  std::vector<std::thread> threads;
  for (int k = 0; k < 2; ++k)
    threads.emplace_back([&, k] {
      for (int ty = 0; ty < 3; ++ty)
        for (int tx = 0; tx < 4; ++tx) {
          auto t = (*reader)->ReadTile(0, tx, ty);
          two[k].push_back(t.ok() ? t->texels.field.height_mm(5, 7) : -1.0f);
        }
    });
  for (auto& t : threads) t.join();
  EXPECT_EQ(one, two[0]);
  EXPECT_EQ(one, two[1]);
  auto bad = (*reader)->ReadTile(0, 4, 0);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("no tile 4, 0"), std::string::npos) << bad.error().message;
  EXPECT_FALSE((*reader)->ReadTile(9, 0, 0).ok());
  EXPECT_FALSE((*reader)->ReadTile(-1, 0, 0).ok());
  fs::remove_all(dir);
}

// The writer asks for level 0 a band of tile_size rows at a time, top to bottom; a band source
// that fails mid-way fails the write with its own message and leaves the old file as it was.
TEST(TiledPack, StreamsBandsAndAFailedWriteLeavesTheOldFile) {
  const fs::path dir = TempDir("tiled_bands");
  const Pack p = MakeTestPack(200, 150, 24);
  PackWriteOptions o;
  o.tile_size = 64;
  std::vector<std::pair<int, int>> asked;
  ASSERT_OK(WriteTiledPack(dir / "p.pack.exr", HeaderOf(p), o,
                           [&](int y0, int rows) -> Result<PackLevel> {
                             asked.emplace_back(y0, rows);
                             return PackRows(p, y0, rows);
                           }));
  const std::vector<std::pair<int, int>> want = {{0, 64}, {64, 64}, {128, 22}};
  EXPECT_EQ(asked, want);
  auto r = ReadPack(dir / "p.pack.exr");
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectIdentical(EncodePackValues(p, {}), *r);
  const auto before = ReadBytes(dir / "p.pack.exr");
  Status s = WriteTiledPack(dir / "p.pack.exr", HeaderOf(p), o,
                            [&](int y0, int rows) -> Result<PackLevel> {
                              if (y0 >= 64) return Error{"tile folder 3: gone"};
                              return PackRows(p, y0, rows);
                            });
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("tile folder 3: gone"), std::string::npos) << s.message();
  EXPECT_EQ(ReadBytes(dir / "p.pack.exr"), before);
  // A band of the wrong size, and texels whose models disagree with the header's counts.
  s = WriteTiledPack(dir / "p.pack.exr", HeaderOf(p), o,
                     [&](int y0, int rows) -> Result<PackLevel> {
                       return PackRows(p, y0, std::max(1, rows - 1));
                     });
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("rows 0..63: the band is 200x63"), std::string::npos) << s.message();
  PackHeader lying = HeaderOf(p);
  lying.texels_by_model[0] -= 1;
  lying.texels_by_model[1] += 1;
  s = WriteTiledPack(dir / "p.pack.exr", lying, o,
                     [&](int y0, int rows) -> Result<PackLevel> { return PackRows(p, y0, rows); });
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("the header said"), std::string::npos) << s.message();
  // A NaN in the last band is refused, named in level 0's rows.
  Pack nan = p;
  nan.maps.rho_d(7, 140) = Vec3f(std::nanf(""), 0, 0);
  s = WriteTiledPack(
      dir / "p.pack.exr", HeaderOf(nan), o,
      [&](int y0, int rows) -> Result<PackLevel> { return PackRows(nan, y0, rows); });
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("level 0, rows 128..149"), std::string::npos) << s.message();
  EXPECT_EQ(ReadBytes(dir / "p.pack.exr"), before);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()),
            1);  // no temporary
  fs::remove_all(dir);
}

TEST(TiledPack, TileSizesOutsideTheFormatAreRefused) {
  const fs::path dir = TempDir("tiled_sizes");
  const Pack p = MakeTestPack(40, 30, 25);
  for (int t : {1, 32, 100, 8192}) {
    PackWriteOptions o;
    o.tile_size = t;
    const Status s = WritePack(dir / "p.pack.exr", p, o);
    ASSERT_FALSE(s.ok()) << t;
    EXPECT_NE(s.message().find("power of two in [64, 4096]"), std::string::npos) << s.message();
  }
  EXPECT_FALSE(fs::exists(dir / "p.pack.exr"));
  // A pack smaller than one tile: one tile a level.
  PackWriteOptions o;
  o.tile_size = 64;
  ASSERT_OK(WritePack(dir / "p.pack.exr", p, o));
  auto r = ReadPack(dir / "p.pack.exr");
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectIdentical(EncodePackValues(p, {}), *r);
  fs::remove_all(dir);
}

// The tile description is untrusted: a forged 1 x 1 tile (OpenEXR would size its offset tables by
// it), a mode other than mip-mapped, a tiled pack claiming version 2 and a flipped bit in the
// pixel data of any tile are refused, naming the file.
// `digitize verify` reads a tiled pack a tile at a time: a 16319 x 12159 pack (the 16384 bench)
// is beyond a whole read's limit and was refused. Small limits stand in for it here; the boxes
// are still checked against every level-0 tile's heights.
TEST(TiledPack, VerifyReadsATileAtATimeAndStillChecksTheBoxes) {
  const fs::path dir = TempDir("tiled_verify");
  Pack p = MakeGgxTestPack(300, 170, 21);
  ASSERT_GE(p.boxes.size(), 2u);
  PackWriteOptions o;
  o.tile_size = 64;
  ASSERT_OK(WritePack(dir / "good.pack.exr", p, o));
  PackReadOptions small;
  small.max_texels = 128 * 128;  // below 300 x 170: no whole read
  auto whole = ReadPack(dir / "good.pack.exr", small);
  ASSERT_FALSE(whole.ok());
  EXPECT_NE(whole.error().message.find("read its tiles instead"), std::string::npos)
      << whole.error().message;
  auto v = VerifyPack(dir / "good.pack.exr", small);
  ASSERT_TRUE(v.ok()) << v.error().message;
  auto v_default = VerifyPack(dir / "good.pack.exr");
  ASSERT_TRUE(v_default.ok()) << v_default.error().message;
  EXPECT_EQ(v->checks, v_default->checks);
  bool tiles_line = false;
  for (const std::string& line : v->checks)
    tiles_line = tiles_line || line.find("read a tile at a time") != std::string::npos;
  EXPECT_TRUE(tiles_line);
  // The last box lies below the first row of tiles: its h_max lowered to the bump plane.
  const size_t last = p.boxes.size() - 1;
  ASSERT_GE(p.boxes[last].y0, 64);
  p.boxes[last].h_max_mm = static_cast<float>(p.delta0_mm);
  ASSERT_OK(WritePack(dir / "bad.pack.exr", p, o));
  auto bad = VerifyPack(dir / "bad.pack.exr", small);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("bad.pack.exr: box " + std::to_string(last)),
            std::string::npos)
      << bad.error().message;
  fs::remove_all(dir);
}

TEST(TiledPack, ForgedOrCorruptTiledPacksAreRefused) {
  const fs::path dir = TempDir("tiled_forged");
  const Pack p = MakeTestPack(130, 70, 26);
  PackWriteOptions o;
  o.tile_size = 64;
  ASSERT_OK(WritePack(dir / "p.pack.exr", p, o));
  const auto bytes = ReadBytes(dir / "p.pack.exr");
  const std::string tiles = std::string("tiles") + '\0' + "tiledesc" + '\0' +
                            std::string("\x09\x00\x00\x00", 4) +
                            std::string("\x40\x00\x00\x00\x40\x00\x00\x00\x11", 9);
  auto forge = [&](const std::string& from, const std::string& to, const std::string& name) {
    auto b = bytes;
    EXPECT_TRUE(Patch(b, from, to)) << name;
    WriteBytes(dir / name, b);
    auto r = ReadPack(dir / name);
    EXPECT_FALSE(r.ok()) << name;
    EXPECT_FALSE(TiledPackReader::Open(dir / name).ok()) << name;
    return r.ok() ? std::string() : r.error().message;
  };
  std::string m = forge(
      tiles,
      tiles.substr(0, tiles.size() - 9) + std::string("\x01\x00\x00\x00\x01\x00\x00\x00\x11", 9),
      "one.pack.exr");
  EXPECT_NE(m.find("one.pack.exr: part 0 has 1 x 1 tiles"), std::string::npos) << m;
  m = forge(tiles, tiles.substr(0, tiles.size() - 1) + std::string(1, '\0'), "mode.pack.exr");
  EXPECT_NE(m.find("tile mode 0"), std::string::npos) << m;
  const std::string version = std::string("digitize:version") + '\0' + "string" + '\0' +
                              std::string("\x01\x00\x00\x00", 4) + "3";
  m = forge(version, version.substr(0, version.size() - 1) + "2", "v2.pack.exr");
  EXPECT_NE(m.find("4 parts; a version 2 pack has 3"), std::string::npos) << m;
  // Bit flips past the headers (tiles' data, the offset tables, the checksums part): verify reads
  // every tile of every level and refuses them; ReadPack reads level 0 alone, and returns its
  // values or an error.
  const size_t headers = bytes.size() / 8;  // the headers take well under an eighth here
  std::mt19937 rng(27);
  int refused = 0;
  for (int trial = 0; trial < 60; ++trial) {
    auto b = bytes;
    const size_t at = headers + rng() % (b.size() - headers);
    b[at] = static_cast<char>(b[at] ^ (1 << (rng() % 8)));
    WriteBytes(dir / "f.pack.exr", b);
    auto v = VerifyPack(dir / "f.pack.exr");
    if (!v.ok()) {
      ++refused;
      EXPECT_NE(v.error().message.find("f.pack.exr"), std::string::npos) << v.error().message;
    }
    auto r = ReadPack(dir / "f.pack.exr");
    if (r.ok()) {
      SCOPED_TRACE("byte " + std::to_string(at));
      ExpectIdentical(EncodePackValues(p, {}), *r);
    }
  }
  EXPECT_GT(refused, 50);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace digitize
