#pragma once
// Cut-timing regression (SPEC §10): the cut benchmarks of one `octocut bench` run against a stored baseline. Both
// carry the time of the same calibration kernel, measured on their own machine in their own run; the baseline's
// times are scaled by the ratio of the two before they are compared, so that a baseline travels between faster and
// slower machines of one kind. Between kinds of CPU the balance of computation and memory differs, and stages that
// lean on memory can scale otherwise than the kernel: the comparison says so in a note when the CPU models differ,
// and such a machine should take its own baseline. On a shared host those stages also swing with the other tenants'
// load more than the kernel does (docs/RESULTS.md): compare on an idle machine.
//
// Baseline file (schema octocut.cut_baseline/1, JSON):
//   {schema, machine {cpu, threads, calibration_ms}, tolerance, slack_ms,
//    benchmarks: [ {name, cuts_ok, ms {back_transform, surface, material_graph, refine, node_split, embedding,
//                                      solver_update, total, latency}} ]}
// A stage regresses when its median is above  scale * (baseline_ms * (1 + tolerance) + slack_ms), with
// scale = calibration_ms of this run / calibration_ms of the baseline.
#include <array>
#include <string>
#include <vector>

#include "octocut/engine/run/report.hpp"

namespace octocut::engine {

/// What a cut baseline holds per cut benchmark: the stages of a cut and its total (kCutStageKeys), then the latency
/// (the cut plus the first step after it). Each is a `<key>_ms` metric of the cut benchmark. A baseline without a
/// latency compares the stages only.
inline constexpr std::array<const char*, kCutStageKeys.size() + 1> kCutBaselineKeys = {
    kCutStageKeys[0], kCutStageKeys[1], kCutStageKeys[2], kCutStageKeys[3], kCutStageKeys[4],
    kCutStageKeys[5], kCutStageKeys[6], kCutStageKeys[7], "latency"};

/// A parsed, checked baseline.
struct CutBaseline {
  struct Stage {
    std::string name;  ///< a key of SPEC §8 cuts[].ms, e.g. "surface"
    double ms = 0.0;   ///< median over the benchmark's ok cuts on the baseline machine, ms
  };
  struct Benchmark {
    std::string name;  ///< e.g. "cut/meniscus_punch"
    long cuts_ok = 0;  ///< ok cuts of the run the medians come from
    std::vector<Stage> stages;
  };
  std::string cpu;              ///< the baseline machine, for people
  double calibration_ms = 0.0;  ///< the calibration kernel on the baseline machine, ms
  double tolerance = 0.0;       ///< allowed relative slowdown of a stage (0.3 = 30 %)
  double slack_ms = 0.0;        ///< allowed absolute slowdown of a stage on the baseline machine, ms
  std::vector<Benchmark> benchmarks;
};

/// One compared stage.
struct BaselineRow {
  std::string benchmark;    ///< e.g. "cut/meniscus_punch"
  std::string stage;        ///< e.g. "surface"
  double baseline_ms = 0;   ///< stored median, ms on the baseline machine
  double expected_ms = 0;   ///< baseline_ms * scale: what this machine should take, ms
  double limit_ms = 0;      ///< scale * (baseline_ms * (1 + tolerance) + slack_ms), ms
  double measured_ms = 0;   ///< this run's median, ms
  bool regressed = false;   ///< measured_ms > limit_ms
};

/// The outcome of one comparison.
struct BaselineComparison {
  double scale = 1.0;                 ///< calibration_ms of this run / calibration_ms of the baseline
  std::vector<BaselineRow> rows;      ///< every compared stage, in baseline order
  std::vector<std::string> problems;  ///< one line per regressed stage or mismatched run (another count of ok cuts)
  std::vector<std::string> notes;     ///< baseline benchmarks this run did not include; another CPU model
  bool ok() const { return problems.empty(); }
};

/// Parses and checks a baseline's text. Throws std::invalid_argument naming `file` and the JSON pointer of the first
/// bad value (unknown keys, missing keys, non-finite or out-of-range numbers, duplicate names or stages).
CutBaseline parse_cut_baseline(const std::string& text, const std::string& file);

/// Throws std::invalid_argument unless tolerance lies in [0, 10] and slack_ms in [0, 1000] ms (the ranges a baseline
/// file may hold).
void check_baseline_allowances(double tolerance, double slack_ms);

/// A baseline (JSON text) from an octocut.bench/1 document: its cut/ benchmarks and its calibration.
/// Throws std::invalid_argument when the document has no cut benchmark or no calibration, or when tolerance or
/// slack_ms is out of range (check_baseline_allowances).
std::string make_cut_baseline(const std::string& bench_json, double tolerance, double slack_ms);

/// The same from several runs of the same benchmarks (`octocut bench --write-baseline F --repeat N`): each run's
/// times scaled to the runs' median calibration, then each stage's median over the runs (the middle value; the upper
/// one of two). The machine and calibration are the runs' (the median calibration). Throws std::invalid_argument as
/// above, when `bench_jsons` is empty, or when a cut benchmark of the first run is missing from another or has
/// another count of ok cuts there.
std::string make_cut_baseline(const std::vector<std::string>& bench_jsons, double tolerance, double slack_ms);

/// Compares the cut benchmarks of an octocut.bench/1 document with `baseline`. A compared stage without a measured
/// time is a problem. Throws std::invalid_argument when the document is not JSON or lacks its calibration.
BaselineComparison compare_cut_baseline(const std::string& bench_json, const CutBaseline& baseline);

/// The octocut.bench/1 document with the comparison added under the key "baseline": {file, status ("ok" or
/// "regressed"), scale, rows [ {benchmark, stage, baseline_ms, expected_ms, limit_ms, measured_ms, regressed} ],
/// problems, notes}.
std::string with_baseline_comparison(const std::string& bench_json, const BaselineComparison& comparison,
                                     const std::string& file);

/// The comparison as a table for people.
std::string baseline_comparison_table(const BaselineComparison& comparison);

}  // namespace octocut::engine
