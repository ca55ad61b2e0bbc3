// Scene regression (SPEC §10): every shipped scene carries an `expected` block, and a run without rendering passes
// it (`octocut run --check`). `octocut run SCENE --regenerate` rewrites a block deliberately. The same run's report
// says which subsystems were built, which must be exactly those the scene uses.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "common/cli_util.hpp"

namespace octocut {
namespace {

namespace fs = std::filesystem;

const fs::path kScenes = fs::path(OCTOCUT_SOURCE_DIR) / "assets" / "scenes";

class SceneRegression : public ::testing::TestWithParam<std::string> {};

TEST_P(SceneRegression, PassesItsExpectedBlock) {
  const fs::path scene = kScenes / (GetParam() + ".json");
  std::ifstream in(scene);
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_TRUE(j.contains("expected")) << scene << " has no expected block";
  EXPECT_GE(j["expected"].size(), 5u) << "too few checks in " << scene;
  const fs::path out = fs::temp_directory_path() / ("octocut_regression_" + GetParam() + "_" + std::to_string(::getpid()));
  fs::remove_all(out);
  const auto r = test::run_octocut("run '" + scene.string() + "' --no-render --quiet --check --out '" + out.string() + "'");
  EXPECT_EQ(r.exit_code, 0) << r.output;

  // Subsystems: nothing built that the scene does not use. With --no-render there is no renderer and no frame
  // writer; the cut index exists exactly when a tool has cut events; M comes from a box, or for a mesh surface from
  // the cache or the mesher; contact is not built.
  std::ifstream report_file(out / "report.json");
  const nlohmann::json report = nlohmann::json::parse(report_file);
  const nlohmann::json& sub = report.at("subsystems");
  bool cuts = false;
  for (const auto& tool : j.value("tools", nlohmann::json::array())) cuts = cuts || !tool.value("cuts", nlohmann::json::array()).empty();
  const bool box = j.at("object").at("surface").contains("box");
  EXPECT_EQ(sub.at("renderer"), false);
  EXPECT_EQ(sub.at("frame_writer"), false);
  EXPECT_EQ(sub.at("contact"), false);
  EXPECT_EQ(sub.at("cut_index"), cuts) << scene;
  if (box) {
    EXPECT_EQ(sub.at("material_graph"), "box") << scene;
  } else {
    EXPECT_TRUE(sub.at("material_graph") == "cache" || sub.at("material_graph") == "meshed") << sub.dump();
  }
  fs::remove_all(out);
}

// Every scene in assets/scenes is listed here: a new scene without a regression test fails ListsEveryScene.
const std::vector<std::string> kAll = {"cantilever",   "meniscus_rest", "meniscus_punch", "meniscus_punch_hd",
                                       "adaptive_cut", "uniform_cut",   "deformed_cut",   "folded_cut"};

INSTANTIATE_TEST_SUITE_P(Shipped, SceneRegression, ::testing::ValuesIn(kAll),
                         [](const auto& info) { return info.param; });

TEST(SceneRegressionList, ListsEveryScene) {
  std::vector<std::string> found;
  for (const auto& e : fs::directory_iterator(kScenes))
    if (e.path().extension() == ".json") found.push_back(e.path().stem().string());
  std::sort(found.begin(), found.end());
  std::vector<std::string> all = kAll;
  std::sort(all.begin(), all.end());
  EXPECT_EQ(found, all);
}

}  // namespace
}  // namespace octocut
