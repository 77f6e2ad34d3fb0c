// Scan and image files: round trips in every supported format, hostile files, atomic writes.
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "digitize/image_io.h"
#include "digitize/scan_io.h"
#include "test_support.h"

// OpenImageIO 2.4's PNG reader fetches an error string (ImageInput::geterror) in its libpng read
// callback, then libpng longjmps past its destructor: a truncated PNG leaks ~30 bytes inside the
// library. LeakSanitizer reads this hook in the sanitizer build; elsewhere it is never called.
extern "C" const char* __lsan_default_suppressions() {
  return "leak:OpenImageIO_v2_4::ImageInput::geterror\n";
}

namespace digitize {
namespace {

namespace fs = std::filesystem;

class IoTest : public test::ScratchDirTest {
 protected:
  IoTest() : ScratchDirTest("digitize_io_test") {}

  // Everything in the test directory, for "no file / no temp file left behind" checks.
  std::vector<std::string> Listing() const {
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(dir_)) {
      names.push_back(entry.path().filename().string());
    }
    std::sort(names.begin(), names.end());
    return names;
  }
};

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

// Bad input must come back as an Error naming the file and saying what is wrong.
void ExpectErrorAbout(const std::string& message, const fs::path& file, const std::string& word) {
  EXPECT_NE(message.find(file.filename().string()), std::string::npos)
      << "message does not name " << file.filename() << ": " << message;
  EXPECT_NE(Lower(message).find(Lower(word)), std::string::npos)
      << "message does not say '" << word << "': " << message;
}
template <class T>
void ExpectErrorAbout(const Result<T>& result, const fs::path& file, const std::string& word) {
  ASSERT_FALSE(result.ok()) << "expected an error about " << word << " for " << file;
  ExpectErrorAbout(result.error().message, file, word);
}

Scan MakeScan(int width, int height, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-300.f, 300.f);
  Scan scan;
  scan.source = "made-up";
  scan.xyz_mm = Grid<Vec3f>(width, height, Vec3f::Constant(kMissing));
  for (auto& p : scan.xyz_mm.data) p = Vec3f(u(rng), u(rng), 1000.f + u(rng));
  return scan;
}

// Writes interleaved float pixels with any channel count (what our writers refuse to make).
void WriteRawFloat(const fs::path& path, int width, int height, int channels) {
  std::vector<float> pixels(static_cast<size_t>(width) * height * channels, 1.5f);
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  OIIO::ImageSpec spec(width, height, channels, OIIO::TypeDesc::FLOAT);
  ASSERT_TRUE(out->open(path.string(), spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, pixels.data()));
  ASSERT_TRUE(out->close());
}

void WriteUint16(const fs::path& path, const Grid<uint16_t>& counts) {
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  OIIO::ImageSpec spec(counts.width, counts.height, 1, OIIO::TypeDesc::UINT16);
  ASSERT_TRUE(out->open(path.string(), spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT16, counts.data.data()));
  ASSERT_TRUE(out->close());
}

void Truncate(const fs::path& path) {
  const std::string bytes = test::ReadFileBytes(path);
  test::WriteFileBytes(path, bytes.substr(0, bytes.size() / 2));
}

bool SameBits(float a, float b) { return std::memcmp(&a, &b, sizeof(float)) == 0; }

// ----------------------------------------------------------------------------------------------
// Round trips

// 23 rows are one band of the reader (scan_io.cpp reads XYZ images 256 rows at a time), 600
// three: each band lands in its own rows.
TEST_F(IoTest, ScanExrRoundTripIsBitExactIncludingNaN) {
  for (int height : {23, 600}) {
    Scan scan = MakeScan(37, height, 1);
    scan.xyz_mm(0, 0) = Vec3f::Constant(kMissing);
    scan.xyz_mm(5, 7).y() = kMissing;  // partial NaN survives as stored
    scan.xyz_mm(36, height - 1) = Vec3f(-0.f, std::numeric_limits<float>::denorm_min(), 1e-30f);
    const fs::path path = Path("scan.exr");
    ASSERT_TRUE(WriteScanExr(path, scan).ok());
    EXPECT_EQ(Listing(), std::vector<std::string>{"scan.exr"});  // no temp file left

    auto read = ReadScan(path, {});
    ASSERT_TRUE(read.ok()) << read.error().message;
    ASSERT_EQ(read->xyz_mm.width, 37);
    ASSERT_EQ(read->xyz_mm.height, height);
    EXPECT_EQ(read->source, path.string());
    for (size_t i = 0; i < scan.xyz_mm.size(); ++i) {
      for (int c = 0; c < 3; ++c) {
        ASSERT_TRUE(SameBits(read->xyz_mm.data[i][c], scan.xyz_mm.data[i][c]))
            << "sample " << i << " of " << height << " rows";
      }
    }
  }
}

// ReadImageInBands: the bands, in order and of the rows asked for (whole rows of tiles for a
// tiled file), put together are ReadImage's pixels bit for bit; an error from the consumer stops
// the read and is returned.
TEST_F(IoTest, BandsOfAnImageAreTheImage) {
  const int width = 45, height = 301;
  std::vector<float> pixels(static_cast<size_t>(width) * height * 3);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-5.f, 5.f);
  for (float& v : pixels) v = u(rng);
  for (const bool tiled : {false, true}) {
    const fs::path path = Path(tiled ? "tiled.exr" : "lines.exr");
    auto out = OIIO::ImageOutput::create(path.string());
    ASSERT_TRUE(out);
    OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::FLOAT);
    if (tiled) spec.tile_width = spec.tile_height = 32;
    ASSERT_TRUE(out->open(path.string(), spec)) << out->geterror();
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, pixels.data())) << out->geterror();
    ASSERT_TRUE(out->close());
    const auto whole = ReadImage(path);
    ASSERT_TRUE(whole.ok()) << whole.error().message;

    std::vector<float> joined;
    std::vector<int> starts;
    const Status read =
        ReadImageInBands(path, size_t{1} << 20, 50, [&](const FloatImage& band, int y0) {
          EXPECT_EQ(band.width, width);
          EXPECT_EQ(band.channels, 3);
          EXPECT_EQ(band.channel_names, whole->channel_names);
          starts.push_back(y0);
          joined.insert(joined.end(), band.pixels.begin(), band.pixels.end());
          return Status::Ok();
        });
    ASSERT_TRUE(read.ok()) << read.message();
    const std::vector<int> expected = tiled ? std::vector<int>{0, 64, 128, 192, 256}
                                            : std::vector<int>{0, 50, 100, 150, 200, 250, 300};
    EXPECT_EQ(starts, expected) << path;
    ASSERT_EQ(joined.size(), whole->pixels.size()) << path;
    EXPECT_EQ(std::memcmp(joined.data(), whole->pixels.data(), joined.size() * sizeof(float)), 0)
        << path;

    int calls = 0;
    const Status stopped = ReadImageInBands(path, size_t{1} << 20, 50, [&](const FloatImage&, int) {
      ++calls;
      return Status(Error{"enough"});
    });
    EXPECT_FALSE(stopped.ok());
    EXPECT_EQ(stopped.message(), "enough");
    EXPECT_EQ(calls, 1);
    const Status too_large =
        ReadImageInBands(path, 1000, 50, [](const FloatImage&, int) { return Status::Ok(); });
    ASSERT_FALSE(too_large.ok());
    ExpectErrorAbout(too_large.message(), path, "too large");
  }
}

TEST_F(IoTest, ExrKeepsChannelNamesAndMetadata) {
  const fs::path path = Path("scan.exr");
  ASSERT_TRUE(WriteScanExr(path, MakeScan(4, 3, 2)).ok());
  auto image = ReadImage(path);
  ASSERT_TRUE(image.ok()) << image.error().message;
  EXPECT_EQ(image->format, "openexr");
  EXPECT_EQ(image->channels, 3);
  EXPECT_FALSE(image->integer_samples);
  EXPECT_EQ(image->bits_per_sample, 32);
  std::vector<std::string> names = image->channel_names;
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"X", "Y", "Z"}));
  EXPECT_EQ(image->metadata["digitize:units"], "mm");
  EXPECT_EQ(image->metadata["compression"], "zip");
}

TEST_F(IoTest, DepthExrWithPitchBuildsCentredOrthographicGrid) {
  const double pitch_mm = 0.25;
  Grid<float> depth(5, 4);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 5; ++x) depth(x, y) = 100.f + 0.5f * x - 0.25f * y;
  depth(2, 1) = kMissing;
  const fs::path path = Path("depth.exr");
  ASSERT_TRUE(WriteFloatExr(path, depth, "Z").ok());

  ExpectErrorAbout(ReadScan(path, {}), path, "pixel_pitch_mm");
  ScanReadOptions options;
  options.pixel_pitch_mm = pitch_mm;
  auto scan = ReadScan(path, options);
  ASSERT_TRUE(scan.ok()) << scan.error().message;
  for (int y = 0; y < 4; ++y) {
    for (int x = 0; x < 5; ++x) {
      const Vec3f p = scan->xyz_mm(x, y);
      if (x == 2 && y == 1) {
        EXPECT_FALSE(IsValid(p));
        EXPECT_TRUE(std::isnan(p.x()) && std::isnan(p.y()) && std::isnan(p.z()));
        continue;
      }
      EXPECT_FLOAT_EQ(p.x(), static_cast<float>((x - 2.0) * pitch_mm));
      EXPECT_FLOAT_EQ(p.y(), static_cast<float>((y - 1.5) * pitch_mm));
      EXPECT_EQ(p.z(), depth(x, y));  // float -> float, no conversion
    }
  }
}

TEST_F(IoTest, Png16WithScaleIsWithinHalfAStep) {
  const double scale_mm = 0.002, offset_mm = -10;
  // Quantisation error of round(): at most half a count; the float result adds ~1e-6 mm.
  const double tolerance_mm = 0.5 * scale_mm + 1e-5;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-9.9, 100.0);
  Grid<double> truth(31, 17);
  Grid<uint16_t> counts(31, 17);
  for (size_t i = 0; i < truth.size(); ++i) {
    truth.data[i] = u(rng);
    counts.data[i] = static_cast<uint16_t>(std::lround((truth.data[i] - offset_mm) / scale_mm));
  }
  counts.data[7] = 0;  // missing
  counts.data[8] = 65535;
  truth.data[8] = 65535 * scale_mm + offset_mm;
  for (const char* name : {"height.png", "height.tif"}) {
    const fs::path path = Path(name);
    WriteUint16(path, counts);
    ScanReadOptions options;
    options.pixel_pitch_mm = 0.1;
    ExpectErrorAbout(ReadScan(path, options), path, "height_scale_mm");
    options.height_scale_mm = scale_mm;
    options.height_offset_mm = offset_mm;
    auto scan = ReadScan(path, options);
    ASSERT_TRUE(scan.ok()) << scan.error().message;
    for (size_t i = 0; i < truth.size(); ++i) {
      if (i == 7) {
        EXPECT_FALSE(IsValid(scan->xyz_mm.data[i]));
        continue;
      }
      ASSERT_NEAR(scan->xyz_mm.data[i].z(), truth.data[i], tolerance_mm) << name << " " << i;
    }
    auto image = ReadImage(path);
    ASSERT_TRUE(image.ok());
    EXPECT_EQ(image->bits_per_sample, 16);
    EXPECT_TRUE(image->integer_samples);
  }
}

TEST_F(IoTest, FloatTiffXyzIsRead) {
  const fs::path path = Path("scan.tif");
  WriteRawFloat(path, 6, 5, 3);
  auto scan = ReadScan(path, {});
  ASSERT_TRUE(scan.ok()) << scan.error().message;
  EXPECT_EQ(scan->xyz_mm(5, 4), Vec3f(1.5f, 1.5f, 1.5f));
}

TEST_F(IoTest, PlyGridRoundTrip) {
  const fs::path path = Path("grid.ply");
  std::string text =
      "ply\nformat ascii 1.0\ncomment written by hand\ncomment grid 4 3\n"
      "element vertex 12\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 4; ++x)
      text += std::to_string(x * 0.5) + " " + std::to_string(y * 0.5) + " " +
              std::to_string(200 + x + 10 * y) + "\n";
  test::WriteFileBytes(path, text);
  auto scan = ReadScan(path, {});
  ASSERT_TRUE(scan.ok()) << scan.error().message;
  ASSERT_EQ(scan->xyz_mm.width, 4);
  ASSERT_EQ(scan->xyz_mm.height, 3);
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 4; ++x)
      EXPECT_EQ(scan->xyz_mm(x, y), Vec3f(x * 0.5f, y * 0.5f, 200.f + x + 10 * y));

  // The same grid given through the options instead of the comment.
  const fs::path bare = Path("bare.ply");
  std::string bare_text = text;
  bare_text.erase(bare_text.find("comment grid 4 3\n"), 17);
  test::WriteFileBytes(bare, bare_text);
  ExpectErrorAbout(ReadScan(bare, {}), bare, "grid");
  ScanReadOptions options;
  options.grid_width = 4;
  options.grid_height = 3;
  auto from_options = ReadScan(bare, options);
  ASSERT_TRUE(from_options.ok()) << from_options.error().message;
  EXPECT_EQ(from_options->xyz_mm.data, scan->xyz_mm.data);
  options.grid_width = 3;
  options.grid_height = 4;
  ExpectErrorAbout(ReadScan(path, options), path, "disagrees");
}

TEST_F(IoTest, BinaryPlyKeepsNaN) {
  const fs::path path = Path("grid.ply");
  std::string bytes =
      "ply\nformat binary_little_endian 1.0\ncomment grid 2 2\nelement vertex 4\n"
      "property float x\nproperty float y\nproperty float z\nend_header\n";
  const float values[12] = {0, 0, 5, 1, 0, 6, 0, 1, kMissing, 1, 1, 8};
  bytes.append(reinterpret_cast<const char*>(values), sizeof(values));
  test::WriteFileBytes(path, bytes);
  auto scan = ReadScan(path, {});
  ASSERT_TRUE(scan.ok()) << scan.error().message;
  EXPECT_EQ(scan->xyz_mm(1, 0), Vec3f(1, 0, 6));
  EXPECT_FALSE(IsValid(scan->xyz_mm(0, 1)));
  EXPECT_EQ(scan->xyz_mm(1, 1), Vec3f(1, 1, 8));
}

// OpenMesh's ASCII reader turns "nan" and everything after it into zeros; ours must not.
TEST_F(IoTest, AsciiPlyKeepsNaNAndExtraProperties) {
  const fs::path path = Path("grid.ply");
  test::WriteFileBytes(
      path,
      "ply\r\nformat ascii 1.0\r\ncomment grid 2 2\r\nelement vertex 4\r\n"
      "property double z\r\nproperty float x\r\nproperty float nx\r\nproperty float y\r\n"
      "element face 0\r\nproperty list uchar int vertex_indices\r\nend_header\r\n"
      "5 0 0.1 0\r\nnan 1 0.2 0\r\n+7e0 0 0.3 1\r\n  8\t1 0.4 1  \r\n");
  auto scan = ReadScan(path, {});
  ASSERT_TRUE(scan.ok()) << scan.error().message;
  EXPECT_EQ(scan->xyz_mm(0, 0), Vec3f(0, 0, 5));
  EXPECT_TRUE(std::isnan(scan->xyz_mm(1, 0).z()));
  EXPECT_EQ(scan->xyz_mm(0, 1), Vec3f(0, 1, 7));
  EXPECT_EQ(scan->xyz_mm(1, 1), Vec3f(1, 1, 8));
}

TEST_F(IoTest, CorruptAsciiPly) {
  const std::string header =
      "ply\nformat ascii 1.0\ncomment grid 2 2\nelement vertex 4\nproperty float x\n"
      "property float y\nproperty float z\nend_header\n";
  const fs::path bad_number = Path("bad_number.ply");
  test::WriteFileBytes(bad_number, header + "0 0 1\n1 0 abc\n0 1 1\n1 1 1\n");
  ExpectErrorAbout(ReadScan(bad_number, {}), bad_number, "not a number");
  const fs::path short_line = Path("short_line.ply");
  test::WriteFileBytes(short_line, header + "0 0 1\n1 0\n0 1 1\n1 1 1\n");
  ExpectErrorAbout(ReadScan(short_line, {}), short_line, "2 values");
  const fs::path cut = Path("cut.ply");
  test::WriteFileBytes(cut, header + "0 0 1\n1 0 1\n");
  ExpectErrorAbout(ReadScan(cut, {}), cut, "truncated");
  const fs::path no_z = Path("no_z.ply");
  test::WriteFileBytes(no_z,
                       "ply\nformat ascii 1.0\ncomment grid 1 1\nelement vertex 1\n"
                       "property float x\nproperty float y\nend_header\n0 0\n");
  ExpectErrorAbout(ReadScan(no_z, {}), no_z, "no x, y and z");
}

TEST_F(IoTest, MaskMarksMissingSamples) {
  const fs::path path = Path("scan.exr"), mask_path = Path("mask.png");
  ASSERT_TRUE(WriteScanExr(path, MakeScan(6, 4, 4)).ok());
  Grid<uint8_t> mask(6, 4, 255);
  mask(1, 2) = 0;
  ASSERT_TRUE(WritePng8(mask_path, mask).ok());
  ScanReadOptions options;
  options.mask = mask_path;
  auto scan = ReadScan(path, options);
  ASSERT_TRUE(scan.ok()) << scan.error().message;
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 6; ++x) EXPECT_EQ(IsValid(scan->xyz_mm(x, y)), !(x == 1 && y == 2));
}

TEST_F(IoTest, PngWritersRoundTrip) {
  Grid<uint8_t> mask(5, 3);
  for (size_t i = 0; i < mask.size(); ++i) mask.data[i] = static_cast<uint8_t>(i * 17);
  Grid<std::array<uint8_t, 3>> rgb(2, 2, {10, 20, 30});
  ASSERT_TRUE(WritePng8(Path("mask.png"), mask).ok());
  ASSERT_TRUE(WritePngRgb8(Path("rgb.png"), rgb).ok());
  auto grey = ReadImage(Path("mask.png"));
  ASSERT_TRUE(grey.ok());
  EXPECT_EQ(grey->bits_per_sample, 8);
  for (size_t i = 0; i < mask.size(); ++i) EXPECT_FLOAT_EQ(grey->pixels[i] * 255.f, mask.data[i]);
  auto colour = ReadImage(Path("rgb.png"));
  ASSERT_TRUE(colour.ok());
  EXPECT_EQ(colour->channels, 3);
  EXPECT_FLOAT_EQ(colour->pixels[2] * 255.f, 30.f);
  EXPECT_EQ(Listing(), (std::vector<std::string>{"mask.png", "rgb.png"}));
}

// Photos are decoded as their codes: 8- and 16-bit PNGs give back exactly the codes written
// (16-bit: values above 255, where reading 8 bits would lose them), the buffer is reused from one
// image to the next, and a float image comes back as "not codes" (max_code 0) for ReadImage.
TEST_F(IoTest, IntegerImagesReadBackAsTheirCodes) {
  const int w = 7, h = 3;
  std::vector<uint8_t> codes8(static_cast<size_t>(w) * h * 3);
  std::vector<uint16_t> codes16(codes8.size());
  for (size_t i = 0; i < codes8.size(); ++i) {
    codes8[i] = static_cast<uint8_t>((i * 37) % 256);
    codes16[i] = static_cast<uint16_t>((i * 4099) % 65536);
  }
  ASSERT_TRUE(WriteSrgbPng(Path("p8.png"), w, h, 8, codes8.data()).ok());
  ASSERT_TRUE(WriteSrgbPng(Path("p16.png"), w, h, 16, codes16.data()).ok());
  CodeImage image;
  ASSERT_TRUE(ReadImageCodes(Path("p16.png"), size_t{1} << 20, image).ok());
  EXPECT_EQ(image.max_code, 65535);
  EXPECT_EQ(image.width, w);
  EXPECT_EQ(image.channels, 3);
  EXPECT_EQ(image.codes16, codes16);
  ASSERT_TRUE(ReadImageCodes(Path("p8.png"), size_t{1} << 20, image).ok());
  EXPECT_EQ(image.max_code, 255);
  EXPECT_EQ(image.height, h);
  EXPECT_EQ(image.codes8, codes8);

  Grid<float> depth(4, 2, 0.5f);
  ASSERT_TRUE(WriteFloatExr(Path("depth.exr"), depth, "Y").ok());
  ASSERT_TRUE(ReadImageCodes(Path("depth.exr"), size_t{1} << 20, image).ok());
  EXPECT_EQ(image.max_code, 0);
  EXPECT_EQ(image.width, 0);
  // The pixel limit and a missing file are errors that name the file, as for ReadImage.
  const Status small = ReadImageCodes(Path("p8.png"), 10, image);
  ASSERT_FALSE(small.ok());
  EXPECT_NE(small.message().find("p8.png"), std::string::npos);
  EXPECT_FALSE(ReadImageCodes(Path("missing.png"), size_t{1} << 20, image).ok());
}

TEST_F(IoTest, WriteTextFileReplacesContent) {
  const fs::path path = Path("report.json");
  ASSERT_TRUE(WriteTextFile(path, "old").ok());
  ASSERT_TRUE(WriteTextFile(path, "{\"new\": 1}\n").ok());
  EXPECT_EQ(test::ReadFileBytes(path), "{\"new\": 1}\n");
  EXPECT_EQ(Listing(), std::vector<std::string>{"report.json"});
}

// ----------------------------------------------------------------------------------------------
// Atomic writes

TEST_F(IoTest, FailingWriterLeavesNoFileAndNoTemp) {
  const fs::path path = Path("out.exr");
  fs::path seen_temp;
  const Status status = WriteAtomically(path, [&](const fs::path& temp) -> Status {
    seen_temp = temp;
    test::WriteFileBytes(temp, "half a file");
    return Error{"out.exr: disk full (simulated)"};
  });
  EXPECT_FALSE(status.ok());
  EXPECT_EQ(status.message(), "out.exr: disk full (simulated)");
  EXPECT_EQ(seen_temp.parent_path(), dir_);
  EXPECT_EQ(seen_temp.extension(), ".exr");  // OIIO may pick the format from the name
  EXPECT_TRUE(Listing().empty());
}

TEST_F(IoTest, FailingWriterLeavesExistingTargetUntouched) {
  const fs::path path = Path("report.json");
  test::WriteFileBytes(path, "the old report");
  const Status failed = WriteAtomically(path, [&](const fs::path& temp) -> Status {
    test::WriteFileBytes(temp, "partial");
    return Error{"report.json: simulated failure"};
  });
  EXPECT_FALSE(failed.ok());
  const Status threw = WriteAtomically(path, [&](const fs::path& temp) -> Status {
    test::WriteFileBytes(temp, "partial");
    throw std::runtime_error("writer crashed");
  });
  ExpectErrorAbout(threw.message(), path, "writer crashed");
  EXPECT_EQ(test::ReadFileBytes(path), "the old report");
  EXPECT_EQ(Listing(), std::vector<std::string>{"report.json"});
}

TEST_F(IoTest, WriterThatWritesNothingIsAnError) {
  const fs::path path = Path("nothing.txt");
  const Status status = WriteAtomically(path, [](const fs::path&) { return Status::Ok(); });
  ExpectErrorAbout(status.message(), path, "no file");
  EXPECT_TRUE(Listing().empty());
}

TEST_F(IoTest, WritingIntoAMissingDirectoryFails) {
  const fs::path path = Path("no/such/dir/height.exr");
  ExpectErrorAbout(WriteFloatExr(path, Grid<float>(2, 2, 1.f), "Y").message(), path,
                   "does not exist");
  ExpectErrorAbout(WriteScanExr(Path("empty.exr"), Scan{}).message(), Path("empty.exr"), "empty");
  EXPECT_TRUE(Listing().empty());
}

// ----------------------------------------------------------------------------------------------
// Hostile files: each an Error naming the file and the problem, never a crash.

TEST_F(IoTest, MissingFile) {
  for (const char* name : {"absent.exr", "absent.png", "absent.ply"}) {
    ExpectErrorAbout(ReadScan(Path(name), {}), Path(name), "no such file");
  }
}

TEST_F(IoTest, EmptyFile) {
  for (const char* name : {"empty.exr", "empty.png", "empty.ply"}) {
    test::WriteFileBytes(Path(name), "");
    ExpectErrorAbout(ReadScan(Path(name), {}), Path(name), "empty");
  }
}

TEST_F(IoTest, TruncatedExr) {
  const fs::path path = Path("cut.exr");
  ASSERT_TRUE(WriteScanExr(path, MakeScan(64, 64, 5)).ok());
  Truncate(path);
  auto scan = ReadScan(path, {});
  ASSERT_FALSE(scan.ok());
  ExpectErrorAbout(scan, path, "corrupt");
}

TEST_F(IoTest, TruncatedPng) {
  Grid<uint16_t> counts(64, 64);
  std::mt19937 rng(6);  // noise so that the compressed data is long enough to cut in half
  for (auto& c : counts.data) c = static_cast<uint16_t>(rng());
  const fs::path path = Path("cut.png");
  WriteUint16(path, counts);
  Truncate(path);
  ScanReadOptions options;
  options.pixel_pitch_mm = 0.1;
  options.height_scale_mm = 0.001;
  ExpectErrorAbout(ReadScan(path, options), path, "corrupt");
}

TEST_F(IoTest, GarbageWithExrExtension) {
  const fs::path path = Path("garbage.exr");
  std::mt19937 rng(7);
  std::string bytes(4096, '\0');
  for (auto& b : bytes) b = static_cast<char>(rng());
  test::WriteFileBytes(path, bytes);
  ExpectErrorAbout(ReadScan(path, {}), path, "unreadable");
  // The real EXR magic followed by garbage: the header parser itself gets hostile bytes.
  bytes[0] = 0x76, bytes[1] = 0x2f, bytes[2] = 0x31, bytes[3] = 0x01;
  test::WriteFileBytes(path, bytes);
  ASSERT_FALSE(ReadScan(path, {}).ok());
}

TEST_F(IoTest, WrongChannelCounts) {
  for (int channels : {2, 4}) {
    const fs::path path = Path("scan" + std::to_string(channels) + ".exr");
    WriteRawFloat(path, 8, 8, channels);
    ExpectErrorAbout(ReadScan(path, {}), path, std::to_string(channels) + " channels");
  }
}

TEST_F(IoTest, EightBitPngIsNotADepthMap) {
  const fs::path path = Path("height8.png");
  ASSERT_TRUE(WritePng8(path, Grid<uint8_t>(8, 8, 100)).ok());
  ScanReadOptions options;
  options.pixel_pitch_mm = 0.1;
  options.height_scale_mm = 0.01;
  ExpectErrorAbout(ReadScan(path, options), path, "8-bit");
}

TEST_F(IoTest, IntegerXyzIsRefused) {
  const fs::path path = Path("photo.png");
  ASSERT_TRUE(WritePngRgb8(path, Grid<std::array<uint8_t, 3>>(4, 4, {1, 2, 3})).ok());
  ExpectErrorAbout(ReadScan(path, {}), path, "float");
}

TEST_F(IoTest, MaskOfWrongSize) {
  const fs::path path = Path("scan.exr"), mask_path = Path("mask.png");
  ASSERT_TRUE(WriteScanExr(path, MakeScan(6, 4, 8)).ok());
  ASSERT_TRUE(WritePng8(mask_path, Grid<uint8_t>(4, 6, 1)).ok());
  ScanReadOptions options;
  options.mask = mask_path;
  ExpectErrorAbout(ReadScan(path, options), mask_path, "wrong size");
  options.mask = Path("absent_mask.png");
  ExpectErrorAbout(ReadScan(path, options), options.mask, "no such file");
}

TEST_F(IoTest, PlyWithWrongVertexCount) {
  const fs::path path = Path("short.ply");
  test::WriteFileBytes(
      path,
      "ply\nformat ascii 1.0\ncomment grid 3 3\nelement vertex 8\nproperty float x\n"
      "property float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n2 0 0\n0 1 0\n"
      "1 1 0\n2 1 0\n0 2 0\n1 2 0\n");
  ExpectErrorAbout(ReadScan(path, {}), path, "vertex count");
  // The header promises 9 vertices, the body holds 4: truncated.
  const fs::path cut = Path("cut.ply");
  test::WriteFileBytes(cut,
                       "ply\nformat binary_little_endian 1.0\ncomment grid 3 3\nelement vertex 9\n"
                       "property float x\nproperty float y\nproperty float z\nend_header\n" +
                           std::string(4 * 12, '\0'));
  ASSERT_FALSE(ReadScan(cut, {}).ok());
  const fs::path not_ply = Path("text.ply");
  test::WriteFileBytes(not_ply, "hello\nworld\n");
  ExpectErrorAbout(ReadScan(not_ply, {}), not_ply, "not a PLY");
  const fs::path no_end = Path("no_end.ply");
  test::WriteFileBytes(no_end, "ply\nformat ascii 1.0\nelement vertex 4\n");
  ExpectErrorAbout(ReadScan(no_end, {}), no_end, "end_header");
}

TEST_F(IoTest, AbsurdSizesAreRefusedBeforeAllocating) {
  const fs::path path = Path("scan.exr");
  ASSERT_TRUE(WriteScanExr(path, MakeScan(40, 30, 9)).ok());
  ScanReadOptions options;
  options.max_samples = 1000;
  ExpectErrorAbout(ReadScan(path, options), path, "too large");
  ExpectErrorAbout(ReadImage(path, 1199), path, "too large");
  EXPECT_TRUE(ReadImage(path, 1200).ok());
  // A PLY header claiming 10^15 vertices must not be believed.
  const fs::path huge = Path("huge.ply");
  test::WriteFileBytes(huge,
                       "ply\nformat binary_little_endian 1.0\ncomment grid 1000000000 1000000\n"
                       "element vertex 1000000000000000\nproperty float x\nproperty float y\n"
                       "property float z\nend_header\n");
  ExpectErrorAbout(ReadScan(huge, {}), huge, "too large");
}

TEST_F(IoTest, AbsurdOptionsAreRefused) {
  const fs::path path = Path("scan.exr");
  ScanReadOptions options;
  options.pixel_pitch_mm = -1;
  ExpectErrorAbout(ReadScan(path, options), path, "pixel_pitch_mm");
  options = {};
  options.height_scale_mm = std::numeric_limits<double>::quiet_NaN();
  ExpectErrorAbout(ReadScan(path, options), path, "height_scale_mm");
  options = {};
  options.grid_width = 5;
  ExpectErrorAbout(ReadScan(path, options), path, "grid_height");
  options = {};
  options.max_samples = 0;
  ExpectErrorAbout(ReadScan(path, options), path, "max_samples");
}

TEST_F(IoTest, DirectoryIsNotAnImage) {
  fs::create_directories(Path("folder.exr"));
  ExpectErrorAbout(ReadScan(Path("folder.exr"), {}), Path("folder.exr"), "directory");
}

}  // namespace
}  // namespace digitize
