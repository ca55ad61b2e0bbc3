// `octocut bench --write-baseline / --baseline` (SPEC §10 cut-timing regression) from the command line: a baseline
// written by one run, then edited so that the verdict is known whatever this machine's speed (its times multiplied
// by 100 cannot regress, divided by 1000 with no allowance must), and bad baselines that exit 2 before anything runs.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "common/cli_util.hpp"
#include "common/temp_dir.hpp"

namespace octocut {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;
using test::CommandResult;
using test::run_octocut;

struct BenchCli : test::TempDirTest {
  const fs::path& dir = m_dir;
  std::string p(const std::string& name) const { return "'" + (dir / name).string() + "'"; }
  json read(const std::string& name) const {
    std::ifstream in(dir / name);
    return json::parse(in);
  }
  void write(const std::string& name, const json& doc) const { std::ofstream(dir / name) << doc.dump(2); }
};

TEST_F(BenchCli, ABaselineWrittenByOneRunJudgesTheNext) {
  // The adaptive bar: one cut, about a second.
  CommandResult r = run_octocut("bench cut/adaptive_cut --quiet --write-baseline " + p("base.json") +
                                " --tolerance 0.5 --slack-ms 0.1 --json " + p("first.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json base = read("base.json");
  const json first = read("first.json");
  EXPECT_EQ(base["schema"], "octocut.cut_baseline/1");
  EXPECT_EQ(base["tolerance"], 0.5);
  EXPECT_EQ(base["slack_ms"], 0.1);
  EXPECT_EQ(base["machine"]["calibration_ms"], first["machine"]["calibration_ms"]);
  ASSERT_EQ(base["benchmarks"].size(), 1u);
  EXPECT_EQ(base["benchmarks"][0]["name"], "cut/adaptive_cut");
  EXPECT_EQ(base["benchmarks"][0]["cuts_ok"], first["benchmarks"][0]["params"]["ok"]);
  EXPECT_EQ(base["benchmarks"][0]["ms"]["surface"], first["benchmarks"][0]["metrics"]["surface_ms"]);
  EXPECT_GT(first["machine"]["calibration_ms"].get<double>(), 0.0);

  // Times 100 times the first run's: no machine noise makes this run regress. Without names, the run does the
  // baseline's benchmarks.
  json slow = base;
  for (auto& [stage, ms] : slow["benchmarks"][0]["ms"].items()) ms = 100.0 * ms.get<double>() + 1.0;
  write("slow.json", slow);
  r = run_octocut("bench --quiet --baseline " + p("slow.json") + " --json " + p("second.json"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  json second = read("second.json");
  ASSERT_EQ(second["benchmarks"].size(), 1u);
  EXPECT_EQ(second["benchmarks"][0]["name"], "cut/adaptive_cut");
  EXPECT_EQ(second["baseline"]["status"], "ok");
  EXPECT_EQ(second["baseline"]["rows"].size(), 9u);  // the 7 stages, the total and the latency

  // A thousandth of them, with no allowance: every stage regresses; exit 1, and the results are still written.
  json fast = base;
  for (auto& [stage, ms] : fast["benchmarks"][0]["ms"].items()) ms = 1e-3 * ms.get<double>();
  fast["tolerance"] = 0.0;
  fast["slack_ms"] = 0.0;
  write("fast.json", fast);
  r = run_octocut("bench --quiet --baseline " + p("fast.json") + " --json " + p("third.json"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("regression: cut/adaptive_cut: total took"), std::string::npos) << r.output;
  const json third = read("third.json");
  EXPECT_EQ(third["baseline"]["status"], "regressed");
  EXPECT_GE(third["baseline"]["problems"].size(), 1u);
}

TEST_F(BenchCli, BadBaselinesExitTwoNamingTheFileAndPointerBeforeAnythingRuns) {
  json bad = {{"schema", "octocut.cut_baseline/1"},
              {"machine", {{"cpu", "x"}, {"threads", 2}, {"calibration_ms", 5.0}}},
              {"tolerance", 0.3},
              {"slack_ms", 0.25},
              {"benchmarks", {{{"name", "cut/adaptive_cut"}, {"cuts_ok", 1}, {"ms", {{"surface", "fast"}}}}}}};
  write("bad.json", bad);
  CommandResult r = run_octocut("bench --quiet --baseline " + p("bad.json") + " --json " + p("out.json"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("bad.json: /benchmarks/0/ms/surface: expected a number"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "out.json"));

  std::ofstream(dir / "garbage.json") << "{\"schema\": \"octocut.cut_baseline/1\",\n  \"tolerance\": }";
  r = run_octocut("bench --quiet --baseline " + p("garbage.json"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("garbage.json: not JSON"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("line 2"), std::string::npos) << r.output;

  r = run_octocut("bench --quiet --baseline " + p("missing.json"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("missing.json"), std::string::npos) << r.output;

  bad["benchmarks"][0]["ms"]["surface"] = 1.0;
  bad["benchmarks"][0]["name"] = "cut/no_such_scene";
  write("unknown.json", bad);
  r = run_octocut("bench --quiet --baseline " + p("unknown.json"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("unknown.json: /benchmarks/0/name: this build has no benchmark 'cut/no_such_scene'"),
            std::string::npos)
      << r.output;

  // The allowances belong to a baseline being written.
  EXPECT_EQ(run_octocut("bench cut/adaptive_cut --quiet --tolerance 0.5").exit_code, 2);

  r = run_octocut("bench cut/adaptive_cut --quiet --write-baseline " + p("b.json") + " --tolerance -1");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--tolerance"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "b.json"));

  r = run_octocut("bench cut/adaptive_cut --quiet --write-baseline " + p("b.json") + " --repeat 0");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--repeat"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "b.json"));
  EXPECT_EQ(run_octocut("bench cut/adaptive_cut --quiet --repeat 3").exit_code, 2);  // needs --write-baseline
}

TEST_F(BenchCli, ABaselineFromRepeatedRunsTakesTheirMedians) {
  // Three runs of the adaptive bar's one cut through the command line (the medians themselves are checked on
  // numbers chosen by hand in CutBaseline.FromSeveralRuns...): the options reach the baseline, whose file the
  // comparison then reads.
  const CommandResult r = run_octocut("bench cut/adaptive_cut --quiet --write-baseline " + p("base.json") +
                                      " --repeat 3 --json " + p("last.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json base = read("base.json");
  const json last = read("last.json");
  ASSERT_EQ(base["benchmarks"].size(), 1u);
  EXPECT_EQ(base["benchmarks"][0]["cuts_ok"], last["benchmarks"][0]["params"]["ok"]);
  EXPECT_GT(base["machine"]["calibration_ms"].get<double>(), 0.0);
  for (const auto& [stage, ms] : base["benchmarks"][0]["ms"].items()) {
    EXPECT_TRUE(ms.is_number() && ms.get<double>() >= 0.0) << stage;
  }
  // A valid baseline file (exit 2 would be a bad file; 0 or 1 is the verdict, which this machine's noise decides).
  const CommandResult again = run_octocut("bench --quiet --baseline " + p("base.json"));
  EXPECT_NE(again.exit_code, 2) << again.output;
}

}  // namespace
}  // namespace octocut
