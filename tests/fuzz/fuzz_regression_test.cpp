// Replays the fuzz seed corpus and every crasher found so far through the fuzzed entry points, in CI, without
// libFuzzer: tests/fuzz/corpus/<target>/* and tests/fuzz/regressions/<target>/*. Each input must come back without a
// crash, an escaped exception or a sanitizer report (the ASan/UBSan build checks the latter).
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "fuzz/fuzz_targets.hpp"

namespace octocut::fuzz {
namespace {

namespace fs = std::filesystem;

class FuzzRegression : public ::testing::TestWithParam<std::string> {};

TEST_P(FuzzRegression, EveryStoredInputComesBackCleanly) {
  const Target target = fuzz::target(GetParam());
  ASSERT_NE(target, nullptr);
  int inputs = 0;
  for (const char* folder : {"corpus", "regressions"}) {
    const fs::path dir = fs::path(OCTOCUT_SOURCE_DIR) / "tests/fuzz" / folder / GetParam();
    if (!fs::is_directory(dir)) continue;
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(dir))
      if (e.is_regular_file()) files.push_back(e.path());
    std::sort(files.begin(), files.end());
    for (const fs::path& file : files) {
      std::ifstream in(file, std::ios::binary);
      const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      SCOPED_TRACE(file.string());
      EXPECT_NO_THROW(target(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()));
      ++inputs;
    }
  }
  EXPECT_GT(inputs, 0) << "no seed inputs for " << GetParam();
}

// Rounding never skips a cut (issue 18, item 4): the seed cut sequences (coplanar walls, overlapping bites, the same
// spot twice, blades through vertices and edges) cut without a skip. The truth is the count of skipped cuts, 0.
TEST(FuzzRegressionCuts, TheSeedCutSequencesSkipNoCut) {
  const fs::path dir = fs::path(OCTOCUT_SOURCE_DIR) / "tests/fuzz/corpus/cuts";
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  ASSERT_FALSE(files.empty());
  for (const fs::path& file : files) {
    std::ifstream in(file, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_EQ(cut_skips(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()), 0) << file.string();
  }
}

INSTANTIATE_TEST_SUITE_P(Targets, FuzzRegression, ::testing::Values("scene", "ply", "mesh", "cuts"),
                         [](const auto& info) { return info.param; });

}  // namespace
}  // namespace octocut::fuzz
