// Core types every stage relies on: grids, transforms, results, and the all-or-nothing output
// folder.
#include "digitize/core.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "digitize/output_dir.h"
#include "test_support.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;

TEST(Grid, CellsStartAtZeroForEigenAndPlainTypes) {
  // Eigen's T{} leaves vectors uninitialised; a grid must not.
  const Grid<Vec3f> v(17, 5);
  for (const Vec3f& p : v.data) EXPECT_EQ(p, Vec3f::Zero());
  const Grid<float> f(3, 4);
  for (float x : f.data) EXPECT_EQ(x, 0.0f);
  const Grid<std::array<uint8_t, 3>> rgb(2, 2);
  for (const auto& c : rgb.data) EXPECT_EQ(c, (std::array<uint8_t, 3>{0, 0, 0}));
  EXPECT_EQ(v.size(), 85u);
  EXPECT_TRUE(v.Contains(16, 4));
  EXPECT_FALSE(v.Contains(17, 0));
  EXPECT_FALSE(v.Contains(0, -1));
  EXPECT_THROW(Grid<float>(-1, 2), InvariantError);
}

TEST(RigidTransform, InverseAndCompositionAreExact) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0, 1);
  for (int i = 0; i < 20; ++i) {
    RigidTransform t;
    t.rotation = Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng)).normalized().toRotationMatrix();
    t.translation = Vec3d(n(rng), n(rng), n(rng)) * 100;
    const Vec3d p(n(rng), n(rng), n(rng));
    // Tolerance: a few ulps of 100 mm coordinates.
    EXPECT_LT((t.Inverse().Apply(t.Apply(p)) - p).norm(), 1e-12);
    EXPECT_LT(((t * t.Inverse()).Apply(p) - p).norm(), 1e-12);
    EXPECT_LT(((t * t).Apply(p) - t.Apply(t.Apply(p))).norm(), 1e-12);
  }
}

TEST(AngleDeg, RobustNearZeroAndOpposite) {
  EXPECT_NEAR(AngleDeg(Vec3d::UnitZ(), Vec3d::UnitZ()), 0.0, 1e-12);
  EXPECT_NEAR(AngleDeg(Vec3d::UnitZ(), -Vec3d::UnitZ()), 180.0, 1e-12);
  EXPECT_NEAR(AngleDeg(Vec3d(1, 0, 0), Vec3d(1, 1e-9, 0)), 1e-9 * 180 / 3.14159265358979, 1e-15);
}

TEST(Result, ValueOrErrorNeverBoth) {
  Result<int> ok = 5;
  EXPECT_TRUE(ok.ok());
  EXPECT_EQ(*ok, 5);
  Result<int> bad = Error{"scan.exr: broken"};
  EXPECT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().message, "scan.exr: broken");
  EXPECT_THROW(bad.value(), std::logic_error);
  EXPECT_EQ(FormatNumber(0.25), "0.25");
}

const FolderOutput kOutput{"test", "test", {}};

class OutputDirTest : public test::ScratchDirTest {
 protected:
  OutputDirTest() : ScratchDirTest("digitize_core_test", true, false) {}
  size_t Entries() const {
    return static_cast<size_t>(
        std::distance(fs::directory_iterator(dir_), fs::directory_iterator()));
  }
};

TEST_F(OutputDirTest, SuccessReplacesAFailureKeepsTheOldSet) {
  const fs::path out = dir_ / "out";
  auto write = [](const std::string& text) {
    return [text](const fs::path& dir) {
      std::ofstream(dir / "a.txt") << text;
      return Status::Ok();
    };
  };
  ASSERT_TRUE(WriteDirectoryAtomically(out, kOutput, write("first")).ok());
  ASSERT_TRUE(WriteDirectoryAtomically(out, kOutput, write("second")).ok());
  std::string content;
  std::getline(std::ifstream(out / "a.txt"), content);
  EXPECT_EQ(content, "second");

  const Status failed = WriteDirectoryAtomically(out, kOutput, [](const fs::path& dir) {
    std::ofstream(dir / "a.txt") << "partial";
    return Status(Error{"b.txt: disk full"});
  });
  EXPECT_FALSE(failed.ok());
  EXPECT_EQ(failed.message(), "b.txt: disk full");
  std::getline(std::ifstream(out / "a.txt"), content);
  EXPECT_EQ(content, "second") << "the previous complete output survives";
  EXPECT_EQ(Entries(), 1u) << "no temporary folder left behind";
  EXPECT_TRUE(fs::is_regular_file(out / kOutputMarkerName)) << "the marker of the complete set";
}

TEST_F(OutputDirTest, AFileInTheWayIsNotReplaced) {
  const fs::path out = dir_ / "taken";
  std::ofstream(out) << "keep";
  const Status s =
      WriteDirectoryAtomically(out, kOutput, [](const fs::path&) { return Status::Ok(); });
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("taken"), std::string::npos) << s.message();
  EXPECT_TRUE(fs::is_regular_file(out));
  EXPECT_EQ(Entries(), 1u);
}

}  // namespace
}  // namespace digitize
