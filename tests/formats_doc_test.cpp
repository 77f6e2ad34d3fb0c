// docs/formats.md states defaults a user relies on; they are checked against the code here so
// that the document cannot drift from it again (it once said 10/6/5/6 for the quantised pack
// while the code used 8/5/4/6).
#include <gtest/gtest.h>

#include <fstream>
#include <regex>
#include <sstream>
#include <string>

#include "digitize/pack.h"
#include "test_paths.h"

namespace digitize {
namespace {

std::string ReadDoc(const std::string& name) {
  const std::string path = std::string(DIGITIZE_SOURCE_DIR) + "/docs/" + name;
  std::ifstream in(path);
  EXPECT_TRUE(in) << "cannot open " << path;
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(FormatsDocTest, QuantisedPackDefaultsAreTheCodes) {
  const std::string doc = ReadDoc("formats.md");
  // "(height, normals, rho, lobe;\ndefaults H, N, R, L)": the paragraph on the encodings.
  const std::regex defaults(
      R"(\(height, normals, rho, lobe;\s+defaults (\d+), (\d+), (\d+), (\d+)\))");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(doc, m, defaults))
      << "docs/formats.md no longer states the quantised defaults as "
         "\"(height, normals, rho, lobe; defaults H, N, R, L)\"";
  const PackQuantisation q;
  EXPECT_EQ(std::stoi(m[1]), q.height_bits) << "height_bits";
  EXPECT_EQ(std::stoi(m[2]), q.normal_bits) << "normal_bits";
  EXPECT_EQ(std::stoi(m[3]), q.rho_bits) << "rho_bits";
  EXPECT_EQ(std::stoi(m[4]), q.lobe_bits) << "lobe_bits";
}

}  // namespace
}  // namespace digitize
