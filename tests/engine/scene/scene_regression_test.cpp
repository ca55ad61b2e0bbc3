// Scene regression (SPEC §10): every shipped scene carries an `expected` block, and a run without rendering passes
// it (`octocut run --check`). `octocut run SCENE --regenerate` rewrites a block deliberately. The same run's report
// says which subsystems were built, which must be exactly those the scene uses.
#include <gtest/gtest.h>

#include <cmath>
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
  // Volume bookkeeping (issue 18): for a box object from which no fragment went, the box's volume is the final rest
  // surface's plus what the cuts removed, to 1e-9 relative (the report's volumes are independent sums: the whole S by
  // the divergence theorem, each cut's changed faces by theirs).
  long fragments = 0;
  double removed = 0.0;  // m^3
  for (const auto& c : report.at("cuts")) {
    fragments += c.at("fragments_removed").get<long>();
    if (c.at("removed_volume_m3").is_number()) removed += c.at("removed_volume_m3").get<double>();
  }
  // The repeated and overlapping bites of issue 18 skip no cut (a re-punch is a cut or a no-op).
  if (GetParam().rfind("slab_punch", 0) == 0 || GetParam().rfind("meniscus_bites", 0) == 0) {
    for (const auto& c : report.at("cuts")) EXPECT_NE(c.at("status"), "skipped") << c.dump();
  }
  if (box && fragments == 0 && !report.at("surface").value("object_removed", false)) {
    const auto& b = j.at("object").at("surface").at("box");
    double v0 = 1.0;  // m^3
    for (int k = 0; k < 3; ++k) v0 *= b.at("max")[k].get<double>() - b.at("min")[k].get<double>();
    EXPECT_NEAR(report.at("surface").at("rest_volume_m3").get<double>() + removed, v0, 1e-9 * v0) << scene;
  }
  fs::remove_all(out);
}

// Every scene in assets/scenes is listed here: a new scene without a regression test fails ListsEveryScene. The
// contact scenes run for a minute or more each, so they are a separate test binary labelled `study`
// (engine_contact_scene_test, built from this file with OCTOCUT_CONTACT_SCENES).
const std::vector<std::string> kCi = {"cantilever",   "meniscus_rest", "meniscus_punch", "meniscus_punch_hd",
                                      "adaptive_cut", "uniform_cut",   "deformed_cut",   "folded_cut",
                                      "slab_punch_20"};
// The contact scenes, and the long cut scenes of issue 18 (100 punches at one spot, 30 overlapping bites at 10k and
// 50k): a minute or more each.
const std::vector<std::string> kContact = {"glass_press", "meniscus_probe", "slab_punch_100", "meniscus_bites",
                                           "meniscus_bites_hd"};

#ifdef OCTOCUT_CONTACT_SCENES
INSTANTIATE_TEST_SUITE_P(Contact, SceneRegression, ::testing::ValuesIn(kContact),
                         [](const auto& info) { return info.param; });
#else
INSTANTIATE_TEST_SUITE_P(Shipped, SceneRegression, ::testing::ValuesIn(kCi),
                         [](const auto& info) { return info.param; });

// Issue 20 asks for the shipped scenes' figures at their own settings with an error of at most 1 % against exact
// solves. `meniscus_punch` (contact, six bites, PCG at its shipped tolerance and factor lag) against the same scene
// with CHOLMOD solving every step exactly: every cut's removed volume and every probe's displacement within 1 %. Its
// later bites graze earlier holes, so what they remove is a steep function of where the tissue is: a solver or contact
// change that makes the run chaotic again fails here (before the pseudonormals the fourth and sixth bites were 51 %
// and 14 % off at tolerance 1e-4, 68 % and 3.5 % at 1e-3).
TEST(SceneAccuracy, MeniscusPunchFollowsExactSolvesWithinOnePercent) {
  const fs::path scene = kScenes / "meniscus_punch.json";
  nlohmann::json report[2];
  const std::string sets[2] = {"", " --set '/solver/linear_solver=\"cholmod\"'"};
  for (int k = 0; k < 2; ++k) {
    const fs::path out = fs::temp_directory_path() /
                         ("octocut_accuracy_" + std::to_string(k) + "_" + std::to_string(::getpid()));
    fs::remove_all(out);
    const auto r = test::run_octocut("run '" + scene.string() + "' --no-render --quiet" + sets[k] + " --out '" +
                                     out.string() + "'");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    std::ifstream in(out / "report.json");
    report[k] = nlohmann::json::parse(in);
    fs::remove_all(out);
  }
  const auto& cuts = report[0].at("cuts");
  const auto& exact_cuts = report[1].at("cuts");
  ASSERT_EQ(cuts.size(), 6u);
  ASSERT_EQ(exact_cuts.size(), cuts.size());
  for (std::size_t c = 0; c < cuts.size(); ++c) {
    const double v = cuts[c].at("removed_volume_m3").get<double>();
    const double exact = exact_cuts[c].at("removed_volume_m3").get<double>();  // m^3
    EXPECT_NEAR(v, exact, 0.01 * exact) << "cut " << c;
  }
  int probes = 0;
  for (const auto& [name, probe] : report[1].at("probes").items()) {
    const auto& d = report[0].at("probes").at(name).at("displacement");
    const auto& e = probe.at("displacement");  // m (3)
    double err = 0.0, norm = 0.0;
    for (int i = 0; i < 3; ++i) {
      err += std::pow(d[i].get<double>() - e[i].get<double>(), 2);
      norm += std::pow(e[i].get<double>(), 2);
    }
    EXPECT_LE(std::sqrt(err), 0.01 * std::sqrt(norm)) << "probe " << name;
    ++probes;
  }
  EXPECT_GE(probes, 2);
}

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
