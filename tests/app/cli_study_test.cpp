// `octocut study` end to end on tiny studies (CI): the tables' columns, the errors recomputed from the cases' own
// reports (a reference file, Richardson, CalculiX), the PNGs decoded, the same study from --jobs and from
// --emit-jobs + collect, the stability matrix's verdicts, and bad input exiting 2.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>

#include "common/cli_util.hpp"
#include "common/report_util.hpp"
#include "common/temp_dir.hpp"
#include "octocut/engine/io/io.hpp"
#include "octocut/engine/render/frame_writer.hpp"

namespace {

namespace fs = std::filesystem;
using octocut::test::read_json;
using nlohmann::json;
using octocut::test::run_octocut;

const std::string kCantilever = std::string(OCTOCUT_SOURCE_DIR) + "/assets/scenes/cantilever.json";
const std::string kCube = std::string(OCTOCUT_SOURCE_DIR) + "/docs/studies/cube_1cm.json";
// A tiny sweep: uniform levels 3-5 with CHOLMOD, two PCG tolerances at level 4 (trilinear only: 5 cases, ~2 s).
const std::string kTinySweep =
    " --set '/study/levels=[3,4,5]' --set '/study/tolerances=[1e-2,1e-6]' --set '/study/elements=[\"trilinear\"]'";

using Vec = std::array<double, 3>;
Vec vec(const json& j) { return {j[0].get<double>(), j[1].get<double>(), j[2].get<double>()}; }
double norm(const Vec& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }
Vec sub(const Vec& a, const Vec& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }

// The first line of a CSV file, split at commas.
std::vector<std::string> csv_header(const fs::path& p) {
  std::ifstream in(p);
  std::string line, field;
  std::getline(in, line);
  std::vector<std::string> out;
  std::istringstream s(line);
  while (std::getline(s, field, ',')) out.push_back(field);
  return out;
}

// A PNG that starts with the signature and decodes (libpng, the project's reader) to a non-empty image.
void expect_png(const fs::path& p) {
  ASSERT_TRUE(fs::exists(p)) << p;
  const std::string bytes = octocut::engine::read_file(p);
  ASSERT_GE(bytes.size(), 8u);
  EXPECT_EQ(bytes.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
  const octocut::engine::Image image = octocut::engine::decode_png(bytes, p.string());
  EXPECT_GT(image.width, 100);
  EXPECT_GT(image.height, 100);
}

// Every row's probe errors, recomputed from the case's own report against `reference` (name -> [3]).
void expect_errors_match_reports(const fs::path& dir, const json& study, const json& reference) {
  for (const json& row : study["rows"]) {
    const json report = read_json(dir / "cases" / row["case"]["id"].get<std::string>() / "report.json");
    double worst = 0.0;
    for (const auto& [name, ref] : reference.items()) {
      const Vec u = vec(report["probes"][name]["displacement"]);
      const double e = norm(sub(u, vec(ref))) / norm(vec(ref));
      EXPECT_NEAR(row["error"]["probes"][name].get<double>(), e, 1e-12 * (1.0 + e)) << row["case"]["id"] << " " << name;
      worst = std::max(worst, e);
    }
    EXPECT_NEAR(row["error"]["max"].get<double>(), worst, 1e-12 * (1.0 + worst));
    EXPECT_EQ(row["ms_per_step"].get<double>(), report["timing_ms"]["step"]["median"].get<double>());
    EXPECT_EQ(row["elements"], report["counts"]["elements"]);
    EXPECT_EQ(row["dofs"], report["counts"]["dofs"]);
  }
}

class CliStudyTest : public octocut::test::TempDirTest {};

TEST_F(CliStudyTest, AccuracyWithAReferenceFileRecomputesFromTheReports) {
  const fs::path ref = write("ref.json", R"({"probes": {"tip": [0, 0, -3.9e-4], "mid": [0, 0, -1.4e-4]}})");
  const fs::path out = m_dir / "acc";
  const auto r = run_octocut("study accuracy '" + kCantilever + "' --out '" + out.string() + "' --reference '" +
                             ref.string() + "' --jobs 2 --quiet" + kTinySweep);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json study = read_json(out / "study.json");
  EXPECT_EQ(study["schema"], "octocut.study/1");
  EXPECT_EQ(study["reference"]["kind"], "file");
  ASSERT_EQ(study["rows"].size(), 5u);
  for (const json& row : study["rows"]) {
    for (const char* key : {"case", "error", "ms_per_step", "elements", "dofs", "pareto"}) EXPECT_TRUE(row.contains(key)) << key;
    EXPECT_TRUE(row["error"].contains("probes"));
    EXPECT_TRUE(row["error"].contains("field_l2"));
  }
  expect_errors_match_reports(out, study, json::parse(octocut::engine::read_file(ref))["probes"]);
  // The field error is measured against the finest uniform run, which has none.
  EXPECT_EQ(study["reference"]["field_reference"], "uniform-L5-trilinear-cholmod");
  for (const json& row : study["rows"]) {
    if (row["case"]["id"] == "uniform-L5-trilinear-cholmod") EXPECT_EQ(row["error"]["field_l2"].get<double>(), 0.0);
    else EXPECT_GT(row["error"]["field_l2"].get<double>(), 0.0);
  }
  // The Pareto front: no case on it is dominated, and every case off it is.
  for (const json& a : study["rows"]) {
    bool dominated = false;
    for (const json& b : study["rows"])
      dominated |= b["error"]["max"] <= a["error"]["max"] && b["ms_per_step"] <= a["ms_per_step"] &&
                   (b["error"]["max"] < a["error"]["max"] || b["ms_per_step"] < a["ms_per_step"]);
    EXPECT_EQ(a["pareto"].get<bool>(), !dominated) << a["case"]["id"];
  }
  const std::vector<std::string> cols = csv_header(out / "study.csv");
  for (const char* c : {"case", "mesh", "level", "element", "solver", "tolerance", "dt", "elements", "dofs",
                        "ms_per_step", "wall_s", "error_max", "field_l2", "error_tip", "error_mid", "pareto"})
    EXPECT_NE(std::find(cols.begin(), cols.end(), c), cols.end()) << c;
  expect_png(out / "pareto.png");
  const std::string md = octocut::engine::read_file(out / "study.md");
  EXPECT_NE(md.find("**Reference:** the probe displacements in"), std::string::npos);
  EXPECT_NE(md.find("calibration kernel"), std::string::npos);
}

TEST_F(CliStudyTest, RichardsonReferenceIsTheExtrapolationOfTheUniformRuns) {
  const fs::path out = m_dir / "acc";
  const auto r = run_octocut("study accuracy '" + kCantilever + "' --out '" + out.string() + "' --quiet" + kTinySweep +
                             " --set '/study/tolerances=[]'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json study = read_json(out / "study.json");
  ASSERT_EQ(study["reference"]["kind"], "richardson");
  EXPECT_EQ(study["reference"]["levels"], json({3, 4, 5}));
  // Richardson from the three reports: p = log2(|u4 - u3| / |u5 - u4|), u = u5 + (u5 - u4) / (2^p - 1).
  auto u = [&](int level, const std::string& probe) {
    const json rep = read_json(out / "cases" / ("uniform-L" + std::to_string(level) + "-trilinear-cholmod") / "report.json");
    return vec(rep["probes"][probe]["displacement"]);
  };
  json expected = json::object();
  for (const std::string probe : {"tip", "mid"}) {
    const Vec u3 = u(3, probe), u4 = u(4, probe), u5 = u(5, probe);
    const double p = std::log2(norm(sub(u4, u3)) / norm(sub(u5, u4)));
    ASSERT_GT(p, 0.5);
    ASSERT_LT(p, 6.0);
    Vec x{};
    for (int d = 0; d < 3; ++d) x[d] = u5[d] + (u5[d] - u4[d]) / (std::pow(2.0, p) - 1.0);
    const Vec got = vec(study["reference"]["probes"][probe]);
    EXPECT_LT(norm(sub(got, x)), 1e-12 * norm(x)) << probe;
    expected[probe] = {x[0], x[1], x[2]};
  }
  expect_errors_match_reports(out, study, expected);
  EXPECT_NE(octocut::engine::read_file(out / "study.md").find("Richardson extrapolation"), std::string::npos);
}

// The Richardson reference refuses to extrapolate a sequence that oscillates or does not converge, and then says how
// far its finest run moved at the last refinement instead of claiming no error. The cases' reports are written by
// hand (probe values chosen for each kind of sequence) and collected as if they had run elsewhere.
TEST_F(CliStudyTest, RichardsonRefusesSequencesThatOscillateOrDiverge) {
  const fs::path dir = m_dir / "acc";
  const auto e = run_octocut("study accuracy '" + kCantilever + "' --out '" + dir.string() + "' --emit-jobs '" +
                             (m_dir / "jobs.txt").string() + "' --quiet" + kTinySweep + " --set '/study/tolerances=[]'");
  ASSERT_EQ(e.exit_code, 0) << e.output;
  // z displacements (m) of the probes at levels 3, 4, 5.
  auto collect = [&](const std::array<double, 3>& tip, const std::array<double, 3>& mid) {
    for (int k = 0; k < 3; ++k) {
      const json report = {
          {"status", "ok"},
          {"probes", {{"tip", {{"displacement", {0.0, 0.0, tip[std::size_t(k)]}}}},
                      {"mid", {{"displacement", {0.0, 0.0, mid[std::size_t(k)]}}}}}},
          {"timing_ms", {{"step", {{"median", 1.0 + k}}}}},
          {"wall_time_s", 1.0},
          {"counts", {{"elements", 10 << (3 * k)}, {"dofs", 30 << (3 * k)}}}};
      const fs::path c = dir / "cases" / ("uniform-L" + std::to_string(3 + k) + "-trilinear-cholmod");
      fs::create_directories(c);
      std::ofstream(c / "report.json") << report.dump();
    }
    const auto r = run_octocut("study collect '" + dir.string() + "' --quiet");
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return read_json(dir / "study.json")["reference"];
  };
  // tip oscillates (down 0.3 mm, then up 0.05 mm); mid converges monotonically with order 2.
  json ref = collect({-1.0e-3, -1.3e-3, -1.25e-3}, {-1.0e-4, -1.2e-4, -1.25e-4});
  EXPECT_EQ(ref["extrapolated"], 1);
  EXPECT_EQ(ref["probes"]["tip"], json({0.0, 0.0, -1.25e-3}));  // the finest run
  EXPECT_TRUE(ref["order"]["tip"].is_null());
  EXPECT_NEAR(ref["estimated_error"]["tip"].get<double>(), 0.05 / 1.25, 1e-12);
  EXPECT_NEAR(ref["order"]["mid"].get<double>(), 2.0, 1e-9);
  const double mid = -1.25e-4 - 0.05e-4 / 3.0;
  EXPECT_NEAR(ref["probes"]["mid"][2].get<double>(), mid, 1e-12 * 1.25e-4);
  EXPECT_NEAR(ref["estimated_error"]["mid"].get<double>(), (0.05e-4 / 3.0) / -mid, 1e-9);
  bool said = false;
  for (const json& n : ref["notes"]) said |= n.get<std::string>().find("probe tip") != std::string::npos &&
                                            n.get<std::string>().find("oscillates") != std::string::npos;
  EXPECT_TRUE(said) << ref["notes"];
  const std::string md = octocut::engine::read_file(dir / "study.md");
  EXPECT_NE(md.find("at 1 of 2 probes, the finest run at the others"), std::string::npos) << md;
  // The line that plans the study again names the /study/ keys it was planned with.
  EXPECT_NE(md.find("Reproduce: `octocut study accuracy " + kCantilever + " --out DIR --set '/study/elements=[\"trilinear"
                    "\"]' --set '/study/levels=[3,4,5]' --set '/study/tolerances=[]'`"),
            std::string::npos)
      << md;
  const json rows = read_json(dir / "study.json")["rows"];
  EXPECT_EQ(rows[2]["error"]["probes"]["tip"].get<double>(), 0.0);
  EXPECT_NEAR(rows[2]["error"]["probes"]["mid"].get<double>(), (0.05e-4 / 3.0) / -mid, 1e-9);
  // tip's finest two runs agree exactly: the finest run, with no error, and said so.
  ref = collect({-1.0e-3, -1.25e-3, -1.25e-3}, {-1.0e-4, -1.2e-4, -1.25e-4});
  EXPECT_EQ(ref["extrapolated"], 1);
  EXPECT_EQ(ref["estimated_error"]["tip"].get<double>(), 0.0);
  said = false;
  for (const json& n : ref["notes"]) said |= n.get<std::string>().find("agree exactly") != std::string::npos;
  EXPECT_TRUE(said) << ref["notes"];
  // Both grow: no extrapolation anywhere, and the estimated errors are the last changes.
  ref = collect({-1.0e-3, -1.1e-3, -1.3e-3}, {-1.0e-4, -1.05e-4, -1.2e-4});
  EXPECT_EQ(ref["extrapolated"], 0);
  EXPECT_NEAR(ref["estimated_error"]["tip"].get<double>(), 0.2 / 1.3, 1e-12);
  EXPECT_NEAR(ref["estimated_error"]["mid"].get<double>(), 0.15 / 1.2, 1e-12);
  EXPECT_NE(octocut::engine::read_file(dir / "study.md").find("converges monotonically at no probe"), std::string::npos);
}

TEST_F(CliStudyTest, EmittedJobsAndCollectGiveTheSameStudyAsJobs) {
  const fs::path a = m_dir / "a", b = m_dir / "b", jobs = m_dir / "jobs.txt";
  const std::string sweep = kTinySweep + " --set '/study/tolerances=[]' --quiet";
  ASSERT_EQ(run_octocut("study accuracy '" + kCantilever + "' --out '" + a.string() + "' --jobs 2" + sweep).exit_code, 0);
  const auto e = run_octocut("study accuracy '" + kCantilever + "' --out '" + b.string() + "' --emit-jobs '" +
                             jobs.string() + "'" + sweep);
  ASSERT_EQ(e.exit_code, 0) << e.output;
  // One self-contained command per line; run them as a cluster would (here: the file by sh), then collect.
  std::ifstream in(jobs);
  std::string line;
  int lines = 0;
  while (std::getline(in, line)) {
    ++lines;
    EXPECT_EQ(line.rfind("'" + std::string(OCTOCUT_EXE) + "' 'run' '" + kCantilever + "'", 0), 0u) << line;
    EXPECT_NE(line.find("'--out' '" + (b / "cases").string()), std::string::npos) << line;
  }
  EXPECT_EQ(lines, 3);
  ASSERT_EQ(std::system(("sh '" + jobs.string() + "' >/dev/null 2>&1").c_str()), 0);
  ASSERT_EQ(run_octocut("study collect '" + b.string() + "' --quiet").exit_code, 0);
  const json ja = read_json(a / "study.json"), jb = read_json(b / "study.json");
  EXPECT_EQ(ja["reference"]["probes"], jb["reference"]["probes"]);
  ASSERT_EQ(ja["rows"].size(), jb["rows"].size());
  for (std::size_t i = 0; i < ja["rows"].size(); ++i) {
    EXPECT_EQ(ja["rows"][i]["case"], jb["rows"][i]["case"]);
    EXPECT_EQ(ja["rows"][i]["error"], jb["rows"][i]["error"]);  // bit for bit: the cases are deterministic
  }
}

TEST_F(CliStudyTest, DefaultSweepCoversLevelsAdaptivitySolversTimeStepsAndElements) {
  // Planned only (--emit-jobs runs nothing): the static cantilever and the dynamic meniscus.
  auto plan = [&](const std::string& scene, const std::string& name) {
    const fs::path out = m_dir / name;
    const auto r = run_octocut("study accuracy '" + scene + "' --out '" + out.string() + "' --emit-jobs '" +
                               (m_dir / (name + ".txt")).string() + "' --quiet");
    EXPECT_EQ(r.exit_code, 0) << r.output;
    std::set<std::string> ids;
    const json j = read_json(out / "study_plan.json");
    for (const json& c : j["cases"]) ids.insert(c["id"].get<std::string>());
    return ids;
  };
  const std::set<std::string> c = plan(kCantilever, "cantilever");
  for (const std::string e : {"trilinear", "bbar"}) {
    for (const std::string l : {"5", "6", "7"}) EXPECT_TRUE(c.count("uniform-L" + l + "-" + e + "-cholmod")) << l << e;
    for (const std::string s : {"0", "1"}) EXPECT_TRUE(c.count("adaptive+" + s + "-" + e + "-cholmod")) << s << e;
  }
  for (const std::string t : {"0.01", "0.0001", "1e-06", "1e-08"})
    EXPECT_TRUE(c.count("uniform-L6-trilinear-pcg-" + t)) << t;
  EXPECT_EQ(c.size(), 14u);  // static: no time steps
  const std::set<std::string> m = plan(std::string(OCTOCUT_SOURCE_DIR) + "/assets/scenes/meniscus_rest.json", "men");
  for (const std::string dt : {"0.004", "0.002", "0.0005"})
    EXPECT_TRUE(m.count("uniform-L6-trilinear-cholmod-dt" + dt)) << dt;
}

TEST_F(CliStudyTest, CalculixReferenceAgreesWithTheTrilinearHexOnTheSameMesh) {
  if (std::system("command -v ccx >/dev/null 2>&1") != 0) GTEST_SKIP() << "ccx (calculix-ccx) is not installed";
  const fs::path out = m_dir / "acc";
  const auto r = run_octocut("study accuracy '" + kCantilever + "' --out '" + out.string() +
                             "' --reference ccx --quiet --set '/study/levels=[5]' --set '/study/tolerances=[]' "
                             "--set '/study/elements=[\"trilinear\"]'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json study = read_json(out / "study.json");
  ASSERT_EQ(study["reference"]["kind"], "ccx");
  EXPECT_TRUE(fs::exists(out / "ccx" / "deck.inp"));
  // C3D8 and our trilinear hexahedron on the same 20 x 4 x 4 mesh: the same element, lumped against consistent
  // gravity loads; the tip deflections agree to a few per mille.
  const json& row = study["rows"][0];
  ASSERT_EQ(row["case"]["id"], "uniform-L5-trilinear-cholmod");
  EXPECT_LT(row["error"]["probes"]["tip"].get<double>(), 0.01);
  EXPECT_LT(study["reference"]["probes"]["tip"][2].get<double>(), -1e-4);  // it bends down
  // Without ccx the study says so and runs nothing.
  const auto m = run_octocut("study accuracy '" + kCantilever + "' --out '" + (m_dir / "none").string() +
                             "' --reference ccx --quiet", "PATH=/nonexistent");
  EXPECT_EQ(m.exit_code, 1) << m.output;
  EXPECT_NE(m.output.find("`ccx` is not installed (Debian package calculix-ccx)"), std::string::npos) << m.output;
  EXPECT_FALSE(fs::exists(m_dir / "none" / "cases"));
}

TEST_F(CliStudyTest, StabilityMatrixJudgesEveryCell) {
  const fs::path out = m_dir / "stab";
  const auto r = run_octocut("study stability '" + kCube + "' --out '" + out.string() +
                             "' --jobs 2 --quiet --set '/study/young_modulus=[1e5]' --set '/study/poisson_ratio=[0.3]' "
                             "--set '/study/dt=[1e-2]' --set '/study/scenarios=[\"sag\",\"crush\",\"twist\",\"press\"]' "
                             "--set /study/duration=0.1 --set /solver/threads=1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json s = read_json(out / "stability.json");
  EXPECT_EQ(s["schema"], "octocut.stability/1");
  ASSERT_EQ(s["rows"].size(), 4u);
  for (const json& row : s["rows"]) {
    const json rep = read_json(out / "cases" / row["case"]["id"].get<std::string>() / "report.json");
    const json& track = rep["stability"]["track"];
    EXPECT_EQ(row["finite"], rep["stability"]["finite"]);
    EXPECT_EQ(row["max_displacement_m"], track["max_displacement_m"]);
    EXPECT_EQ(row["bounded"].get<bool>(), track["max_displacement_m"].get<double>() <= 2 * 0.01);
    EXPECT_EQ(row["volume_change"], track["volume_change"]);
    EXPECT_EQ(row["recoveries"], rep["stability"]["recoveries"]);
  }
  // The crush moves the top face down by 95% of the height: the largest displacement is at least that.
  EXPECT_GE(s["rows"][1]["max_displacement_m"].get<double>(), 0.95 * 0.01 - 1e-12);
  // The press pushes through contact: the plate put work in, the top sank by most of the plate's travel (half the
  // height, less the penalty's give), and the energy check counted that work.
  const json& press = s["rows"][3];
  EXPECT_EQ(press["case"]["scenario"], "press");
  EXPECT_GT(press["energy"]["contact_work_j"].get<double>(), 0.0);
  EXPECT_GT(press["max_displacement_m"].get<double>(), 0.4 * 0.01);
  EXPECT_LT(press["max_displacement_m"].get<double>(), 0.6 * 0.01);
  EXPECT_TRUE(press["energy"]["ok"].get<bool>());
  EXPECT_EQ(press["energy"]["steps_checked"], 10);
  const std::vector<std::string> cols = csv_header(out / "stability.csv");
  for (const char* c : {"case", "scenario", "young_modulus", "poisson_ratio", "dt", "verdict", "finite", "bounded",
                        "max_displacement_m", "energy_ok", "contact_work_j", "recoveries", "failed_steps", "volume_change", "cuts_skipped"})
    EXPECT_NE(std::find(cols.begin(), cols.end(), c), cols.end()) << c;
  expect_png(out / "stability.png");
  const std::string md = octocut::engine::read_file(out / "stability.md");
  EXPECT_NE(md.find("press"), std::string::npos);
  // The scene overrides are stated at the top, not only in the Reproduce line at the end.
  EXPECT_LT(md.find("Scene overrides (`--set`), in every cell: `/solver/threads=1`."), md.find("Scenarios:"));
  // So is the element every cell ran with (the scene's, after the overrides: the default B-bar here).
  EXPECT_LT(md.find("Hexahedra: **B-bar** (`object.material.element` \"bbar\")."), md.find("Scenarios:"));
  // Without a plotter the tables are still written, with a warning.
  fs::remove(out / "stability.png");
  fs::remove(out / "stability.csv");
  const auto c = run_octocut("study collect '" + out.string() + "' --quiet", "PATH=/nonexistent");
  EXPECT_EQ(c.exit_code, 0) << c.output;
  EXPECT_NE(c.output.find("gnuplot is not installed"), std::string::npos) << c.output;
  EXPECT_FALSE(fs::exists(out / "stability.png"));
  EXPECT_TRUE(fs::exists(out / "stability.csv"));
  EXPECT_NE(octocut::engine::read_file(out / "stability.md").find("gnuplot is not installed"), std::string::npos);
}

TEST_F(CliStudyTest, BadInputExits2) {
  const std::string out = " --out '" + (m_dir / "o").string() + "'";
  auto r = run_octocut("study sensitivity '" + kCantilever + "'" + out);
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("unknown study 'sensitivity'"), std::string::npos) << r.output;
  r = run_octocut("study accuracy '" + kCantilever + "'" + out + " --set '/probes=[]'");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("needs at least one probe"), std::string::npos) << r.output;
  const fs::path ref = write("ref.json", R"({"probes": {"tip": [0, 0, -1e-4], "nose": [0, 0, 1]}})");
  r = run_octocut("study accuracy '" + kCantilever + "'" + out + " --reference '" + ref.string() + "'");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("/probes/nose"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("no probe 'nose'"), std::string::npos) << r.output;
  r = run_octocut("study accuracy '" + kCantilever + "'" + out + " --set '/study/levls=[3]'");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  r = run_octocut("study collect '" + m_dir.string() + "'");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_FALSE(fs::exists(m_dir / "o" / "cases"));  // nothing ran
}

}  // namespace
