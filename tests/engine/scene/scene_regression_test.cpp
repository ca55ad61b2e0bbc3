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
  // the cache or the mesher; a contact world exactly when a tool or prop collides or there are rigid bodies.
  std::ifstream report_file(out / "report.json");
  const nlohmann::json report = nlohmann::json::parse(report_file);
  const nlohmann::json& sub = report.at("subsystems");
  bool cuts = false;
  for (const auto& tool : j.value("tools", nlohmann::json::array())) cuts = cuts || !tool.value("cuts", nlohmann::json::array()).empty();
  const bool box = j.at("object").at("surface").contains("box");
  bool collides = !j.value("rigid_bodies", nlohmann::json::array()).empty();
  for (const auto& tool : j.value("tools", nlohmann::json::array())) collides = collides || tool.value("collide", false);
  if (j.contains("render"))
    for (const auto& prop : j["render"].value("props", nlohmann::json::array()))
      collides = collides || prop.value("collide", false);
  EXPECT_EQ(sub.at("renderer"), false);
  EXPECT_EQ(sub.at("frame_writer"), false);
  EXPECT_EQ(sub.at("contact"), collides) << scene;
  EXPECT_EQ(sub.at("cut_index"), cuts) << scene;
  if (box) {
    EXPECT_EQ(sub.at("material_graph"), "box") << scene;
  } else {
    EXPECT_TRUE(sub.at("material_graph") == "cache" || sub.at("material_graph") == "meshed") << sub.dump();
  }
  fs::remove_all(out);
}

// Every scene in assets/scenes is listed here: a new scene without a regression test fails ListsEveryScene. The
// contact scenes run for a minute or more each, so they are a separate test binary labelled `study`
// (engine_contact_scene_test, built from this file with OCTOCUT_CONTACT_SCENES).
const std::vector<std::string> kCi = {"cantilever",   "meniscus_rest", "meniscus_punch", "meniscus_punch_hd",
                                      "adaptive_cut", "uniform_cut",   "deformed_cut",   "folded_cut"};
const std::vector<std::string> kContact = {"glass_press", "meniscus_probe"};

#ifdef OCTOCUT_CONTACT_SCENES
INSTANTIATE_TEST_SUITE_P(Contact, SceneRegression, ::testing::ValuesIn(kContact),
                         [](const auto& info) { return info.param; });
#else
INSTANTIATE_TEST_SUITE_P(Shipped, SceneRegression, ::testing::ValuesIn(kCi),
                         [](const auto& info) { return info.param; });

TEST(SceneRegressionList, ListsEveryScene) {
  std::vector<std::string> found;
  for (const auto& e : fs::directory_iterator(kScenes))
    if (e.path().extension() == ".json") found.push_back(e.path().stem().string());
  std::sort(found.begin(), found.end());
  std::vector<std::string> all = kCi;
  all.insert(all.end(), kContact.begin(), kContact.end());
  std::sort(all.begin(), all.end());
  EXPECT_EQ(found, all);
}
#endif

}  // namespace
}  // namespace octocut
