// Cut-timing regression against a stored baseline (SPEC §10): the comparison on synthetic benchmark results whose
// numbers are chosen by hand, so that the expected verdict and limits follow from the formula in bench_baseline.hpp.
#include "octocut/engine/bench/bench_baseline.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>

#include "octocut/engine/bench/bench.hpp"
#include "octocut/engine/run/world.hpp"

namespace octocut::engine {
namespace {

using json = nlohmann::ordered_json;

// An octocut.bench/1 document with one cut benchmark: stage k takes (k + 1) * unit_ms, total 10 * unit_ms.
json bench_doc(double calibration_ms, double unit_ms, long ok = 6, const std::string& name = "cut/demo") {
  json metrics = json::object();
  for (std::size_t k = 0; k < kCutBaselineKeys.size(); ++k) {
    const std::string key = std::string(kCutBaselineKeys[k]) + "_ms";
    metrics[key] = std::string(kCutBaselineKeys[k]) == "total" ? 10.0 * unit_ms : double(k + 1) * unit_ms;
  }
  metrics["elements_after"] = 100;
  json doc;
  doc["schema"] = "octocut.bench/1";
  doc["machine"] = {{"cpu", "test"}, {"threads", 2}, {"calibration_ms", calibration_ms}};
  doc["benchmarks"] = json::array();
  doc["benchmarks"].push_back({{"name", name},
                               {"runs", ok},
                               {"median_ms", 10.0 * unit_ms},
                               {"p95_ms", 12.0 * unit_ms},
                               {"params", {{"ok", ok}, {"skipped", 0}, {"no_op", 0}}},
                               {"metrics", metrics}});
  doc["benchmarks"].push_back({{"name", "step/cube10"}, {"runs", 3}, {"median_ms", 1.0}, {"p95_ms", 1.0},
                               {"params", json::object()}, {"metrics", json::object()}});
  return doc;
}

CutBaseline baseline_from(const json& doc, double tolerance, double slack_ms) {
  return parse_cut_baseline(make_cut_baseline(doc.dump(), tolerance, slack_ms), "base.json");
}

TEST(CutBaseline, MadeFromResultsHoldsTheirCutStagesAndCalibration) {
  const CutBaseline b = baseline_from(bench_doc(4.0, 0.5), 0.3, 0.25);
  EXPECT_EQ(b.calibration_ms, 4.0);
  EXPECT_EQ(b.tolerance, 0.3);
  EXPECT_EQ(b.slack_ms, 0.25);
  ASSERT_EQ(b.benchmarks.size(), 1u);  // the step benchmark is not a cut benchmark
  EXPECT_EQ(b.benchmarks[0].name, "cut/demo");
  EXPECT_EQ(b.benchmarks[0].cuts_ok, 6);
  ASSERT_EQ(b.benchmarks[0].stages.size(), kCutBaselineKeys.size());
  EXPECT_EQ(b.benchmarks[0].stages[1].name, "surface");
  EXPECT_EQ(b.benchmarks[0].stages[1].ms, 1.0);
  EXPECT_EQ(b.benchmarks[0].stages[kCutStageKeys.size() - 1].name, "total");
  EXPECT_EQ(b.benchmarks[0].stages[kCutStageKeys.size() - 1].ms, 5.0);
  EXPECT_EQ(b.benchmarks[0].stages.back().name, "latency");
  EXPECT_EQ(b.benchmarks[0].stages.back().ms, 4.5);
}

TEST(CutBaseline, TheSameRunOnAFasterOrSlowerMachineIsNoRegression) {
  // A machine k times slower takes k times as long for the kernel and for every stage: the normalised times agree.
  const CutBaseline b = baseline_from(bench_doc(4.0, 0.5), 0.0, 0.0);  // no allowance at all
  for (const double k : {0.25, 1.0, 3.7}) {
    const BaselineComparison c = compare_cut_baseline(bench_doc(4.0 * k, 0.5 * k).dump(), b);
    EXPECT_NEAR(c.scale, k, 1e-15);
    EXPECT_TRUE(c.ok()) << "k = " << k << ": " << (c.problems.empty() ? "" : c.problems[0]);
    ASSERT_EQ(c.rows.size(), kCutBaselineKeys.size());
    for (const BaselineRow& r : c.rows) EXPECT_NEAR(r.expected_ms, r.measured_ms, 1e-12 * r.measured_ms);
  }
}

TEST(CutBaseline, AStageAboveItsLimitRegressesAndOneAtItsLimitDoesNot) {
  // Baseline: surface 1.0 ms at calibration 4 ms; tolerance 0.5, slack 0.25 ms. On a machine twice as slow
  // (calibration 8 ms) the surface limit is 2 * (1.0 * 1.5 + 0.25) = 3.5 ms.
  const CutBaseline b = baseline_from(bench_doc(4.0, 0.5), 0.5, 0.25);
  json now = bench_doc(8.0, 1.0);
  now["benchmarks"][0]["metrics"]["surface_ms"] = 3.5;
  BaselineComparison c = compare_cut_baseline(now.dump(), b);
  EXPECT_TRUE(c.ok());
  EXPECT_DOUBLE_EQ(c.rows[1].limit_ms, 3.5);
  EXPECT_DOUBLE_EQ(c.rows[1].expected_ms, 2.0);

  now["benchmarks"][0]["metrics"]["surface_ms"] = 3.5 * (1.0 + 1e-9);
  c = compare_cut_baseline(now.dump(), b);
  ASSERT_EQ(c.problems.size(), 1u);
  EXPECT_NE(c.problems[0].find("cut/demo: surface"), std::string::npos) << c.problems[0];
  EXPECT_TRUE(c.rows[1].regressed);
  EXPECT_FALSE(c.rows[0].regressed);

  // A stage that became NaN never passes.
  now["benchmarks"][0]["metrics"]["surface_ms"] = 1.0;
  now["benchmarks"][0]["metrics"]["refine_ms"] = std::numeric_limits<double>::quiet_NaN();  // dumps as null
  c = compare_cut_baseline(now.dump(), b);
  ASSERT_EQ(c.problems.size(), 1u);
  EXPECT_EQ(c.problems[0], "cut/demo: refine has no measured time");
}

TEST(CutBaseline, AnotherCountOfOkCutsIsAProblemAndAMissingBenchmarkANote) {
  const CutBaseline b = baseline_from(bench_doc(4.0, 0.5), 0.3, 0.25);
  BaselineComparison c = compare_cut_baseline(bench_doc(4.0, 0.5, 5).dump(), b);
  ASSERT_EQ(c.problems.size(), 1u);
  EXPECT_NE(c.problems[0].find("5 ok cuts, the baseline has 6"), std::string::npos) << c.problems[0];
  EXPECT_TRUE(c.rows.empty());

  c = compare_cut_baseline(bench_doc(4.0, 0.5, 6, "cut/other").dump(), b);
  EXPECT_TRUE(c.ok());
  ASSERT_EQ(c.notes.size(), 1u);
  EXPECT_NE(c.notes[0].find("cut/demo: not run"), std::string::npos);
}

TEST(CutBaseline, ResultsWithoutCalibrationCannotBeCompared) {
  const CutBaseline b = baseline_from(bench_doc(4.0, 0.5), 0.3, 0.25);
  json now = bench_doc(4.0, 0.5);
  now["machine"].erase("calibration_ms");
  EXPECT_THROW(compare_cut_baseline(now.dump(), b), std::invalid_argument);
  EXPECT_THROW(make_cut_baseline(now.dump(), 0.3, 0.25), std::invalid_argument);
  now["machine"]["calibration_ms"] = 0.0;
  EXPECT_THROW(compare_cut_baseline(now.dump(), b), std::invalid_argument);
}

TEST(CutBaseline, MakingOneNeedsACutBenchmarkAndSaneAllowances) {
  json no_cut = bench_doc(4.0, 0.5);
  no_cut["benchmarks"].erase(0);
  EXPECT_THROW(make_cut_baseline(no_cut.dump(), 0.3, 0.25), std::invalid_argument);
  EXPECT_THROW(make_cut_baseline(bench_doc(4.0, 0.5, 0).dump(), 0.3, 0.25), std::invalid_argument);  // no ok cut
  EXPECT_THROW(make_cut_baseline(bench_doc(4.0, 0.5).dump(), -0.1, 0.25), std::invalid_argument);
  EXPECT_THROW(make_cut_baseline(bench_doc(4.0, 0.5).dump(), 0.3, std::nan("")), std::invalid_argument);
  EXPECT_THROW(make_cut_baseline(bench_doc(4.0, 0.5).dump(), 11.0, 0.25), std::invalid_argument);
}

// The message of the error that parsing `doc` gives ("" when it parses).
std::string parse_error(const json& doc) {
  try {
    parse_cut_baseline(doc.dump(), "base.json");
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(CutBaseline, BadFilesNameTheFileAndTheJsonPointer) {
  const json good = json::parse(make_cut_baseline(bench_doc(4.0, 0.5).dump(), 0.3, 0.25));
  ASSERT_EQ(parse_error(good), "");
  struct Case {
    const char* pointer;
    json value;
    const char* message;  // the expected error starts "base.json: <message>"
  };
  const Case cases[] = {
      {"/schema", "octocut.bench/1", "/schema: must be one of \"octocut.cut_baseline/1\", got \"octocut.bench/1\""},
      {"/tolerance", -0.5, "/tolerance: must be >= 0, got -0.5"},
      {"/tolerance", "0.3", "/tolerance: expected a number"},
      {"/slack_ms", 1e9, "/slack_ms: must be <= 1000"},
      {"/machine/calibration_ms", 0.0, "/machine/calibration_ms: must be > 0"},
      {"/machine/speed", 1.0, "/machine/speed: unknown key"},
      {"/benchmarks/0/name", "step/cube10", "/benchmarks/0/name: expected the name of a cut benchmark"},
      {"/benchmarks/0/cuts_ok", 2.5, "/benchmarks/0/cuts_ok: expected an integer"},
      {"/benchmarks/0/ms/sufrace", 1.0, "/benchmarks/0/ms/sufrace: unknown key (expected one of back_transform, "},
      {"/benchmarks/0/ms/surface", -1.0, "/benchmarks/0/ms/surface: must be >= 0"},
      {"/benchmarks/0/ms/surface", nullptr, "/benchmarks/0/ms/surface: expected a number"},
      {"/benchmarks/1", nullptr, "/benchmarks/1: expected an object"},
  };
  for (const Case& c : cases) {
    json doc = good;
    doc[json::json_pointer(c.pointer)] = c.value;
    EXPECT_EQ(parse_error(doc).rfind(std::string("base.json: ") + c.message, 0), 0u)
        << c.pointer << ": " << parse_error(doc);
  }
  json doc = good;
  doc["benchmarks"].push_back(doc["benchmarks"][0]);
  EXPECT_NE(parse_error(doc).find("/benchmarks/1/name: benchmark 'cut/demo' listed twice"), std::string::npos);
  doc = good;
  doc.erase("tolerance");
  EXPECT_NE(parse_error(doc).find("base.json: /tolerance: required key missing"), std::string::npos) << parse_error(doc);
  doc = good;
  doc["benchmarks"] = json::array();
  EXPECT_NE(parse_error(doc).find("/benchmarks: must have at least 1 item"), std::string::npos);
  try {
    parse_cut_baseline("{\"schema\": ,}", "base.json");
    ADD_FAILURE() << "not JSON was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("base.json: not JSON"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("line 1"), std::string::npos) << e.what();
  }
}

TEST(CutBaseline, TheComparisonGoesIntoTheResultsDocument) {
  const CutBaseline b = baseline_from(bench_doc(4.0, 0.5), 0.0, 0.0);
  const std::string now = bench_doc(4.0, 0.6).dump();  // every stage 20 % slower
  const BaselineComparison c = compare_cut_baseline(now, b);
  EXPECT_EQ(c.problems.size(), kCutBaselineKeys.size());
  const json doc = json::parse(with_baseline_comparison(now, c, "base.json"));
  EXPECT_EQ(doc["schema"], "octocut.bench/1");
  EXPECT_EQ(doc["baseline"]["file"], "base.json");
  EXPECT_EQ(doc["baseline"]["status"], "regressed");
  EXPECT_EQ(doc["baseline"]["rows"].size(), kCutBaselineKeys.size());
  EXPECT_DOUBLE_EQ(doc["baseline"]["rows"][1]["measured_ms"].get<double>(), 1.2);
  EXPECT_NE(baseline_comparison_table(c).find("REGRESSED"), std::string::npos);
}

TEST(CutBaseline, FromSeveralRunsEachStageTakesTheMedianOfTheRunsScaledToTheirMedianCalibration) {
  // Calibrations 4, 5 and 8 ms (median 5): the runs' stages scaled by 5/4, 1 and 5/8 are 1.25 * 0.4, 0.5 and
  // 0.625 * 1.6 units, i.e. 0.5, 0.5 and 1.0: the median is the middle run's 0.5, whatever the order of the runs.
  const std::vector<std::string> runs = {bench_doc(8.0, 1.6).dump(), bench_doc(4.0, 0.4).dump(),
                                         bench_doc(5.0, 0.5).dump()};
  const CutBaseline b = parse_cut_baseline(make_cut_baseline(runs, 0.3, 0.25), "base.json");
  EXPECT_EQ(b.calibration_ms, 5.0);
  ASSERT_EQ(b.benchmarks.size(), 1u);
  EXPECT_EQ(b.benchmarks[0].cuts_ok, 6);
  for (std::size_t k = 0; k < b.benchmarks[0].stages.size(); ++k) {
    const CutBaseline::Stage& s = b.benchmarks[0].stages[k];
    const double units = s.name == "total" ? 10.0 : double(k + 1);
    EXPECT_DOUBLE_EQ(s.ms, 0.5 * units) << s.name;
  }
  // One run gives what the one-run form gives, bit for bit.
  EXPECT_EQ(make_cut_baseline(std::vector<std::string>{runs[0]}, 0.3, 0.25), make_cut_baseline(runs[0], 0.3, 0.25));
  // Runs whose medians cover other cuts do not mix; a benchmark missing from a later run is named.
  EXPECT_THROW(make_cut_baseline({bench_doc(4.0, 0.5).dump(), bench_doc(4.0, 0.5, 5).dump()}, 0.3, 0.25),
               std::invalid_argument);
  try {
    make_cut_baseline({bench_doc(4.0, 0.5).dump(), bench_doc(4.0, 0.5, 6, "cut/other").dump()}, 0.3, 0.25);
    ADD_FAILURE() << "a run without cut/demo was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("cut/demo: not in run 2"), std::string::npos) << e.what();
  }
  EXPECT_THROW(make_cut_baseline(std::vector<std::string>{}, 0.3, 0.25), std::invalid_argument);
}

TEST(CutBaseline, AnotherCpuModelIsNotedWithoutChangingTheVerdict) {
  const CutBaseline b = baseline_from(bench_doc(4.0, 0.5), 0.3, 0.0);
  json other = bench_doc(4.0, 0.5);
  other["machine"]["cpu"] = "another";
  const BaselineComparison c = compare_cut_baseline(other.dump(), b);
  EXPECT_TRUE(c.ok());
  ASSERT_EQ(c.notes.size(), 1u);
  EXPECT_NE(c.notes[0].find("'test'"), std::string::npos);
  EXPECT_NE(c.notes[0].find("'another'"), std::string::npos);
  EXPECT_NE(baseline_comparison_table(c).find("note: the baseline was taken on"), std::string::npos);
  // The same model: no note.
  EXPECT_TRUE(compare_cut_baseline(bench_doc(4.0, 0.5).dump(), b).notes.empty());
}

TEST(CalibrationKernel, DoesTheSameWorkEveryRun) {
  const CalibrationSample a = calibration_kernel();
  const CalibrationSample b = calibration_kernel();
  EXPECT_EQ(a.checksum, b.checksum);
  EXPECT_GT(a.ms, 0.0);
  EXPECT_GT(b.ms, 0.0);
  const double ms = calibration_ms(3);
  EXPECT_TRUE(std::isfinite(ms) && ms > 0.0);
  EXPECT_THROW(calibration_ms(0), std::invalid_argument);
}

}  // namespace
}  // namespace octocut::engine
