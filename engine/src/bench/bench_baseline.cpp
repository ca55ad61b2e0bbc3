#include "octocut/engine/bench/bench_baseline.hpp"

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "scene/scene_schema.hpp"

namespace octocut::engine {

namespace {

using json = nlohmann::ordered_json;
using schema::join_pointer;

constexpr const char* kSchema = "octocut.cut_baseline/1";
constexpr const auto& kBaselineKeys = kCutBaselineKeys;
constexpr double kMaxTolerance = 10.0;
constexpr double kMaxSlackMs = 1000.0;

[[noreturn]] void bad(const std::string& file, const std::string& pointer, const std::string& what) {
  throw std::invalid_argument(file + ": " + (pointer.empty() ? std::string("/") : pointer) + ": " + what);
}

// The format of a baseline file, in the scene schema's terms (one validator for every input document).
const schema::Entry& baseline_schema() {
  using namespace schema;
  static const Entry entry = [] {
    std::vector<std::string> stages(kBaselineKeys.begin(), kBaselineKeys.end());
    Entry benchmarks = object_array(
        "benchmarks",
        {required(string("name", "The cut benchmark, \"cut/<scene>\".")),
         required(integer("cuts_ok", std::nullopt, closed(1, 1e9), "Ok cuts the medians are taken over.")),
         required(number_map("ms", stages, closed(0, 1e9), 1, "Median ms of each stage, and of the latency (the cut plus the first step after it), on the baseline machine."))},
        "The benchmarks and their stage medians.");
    benchmarks = required(benchmarks);
    benchmarks.min_items = 1;
    return object(
        "",
        {required(choice("schema", {kSchema}, kSchema, "The format.")),
         required(object("machine",
                         {optional(string("cpu", "The CPU model.")),
                          optional(integer("threads", std::nullopt, closed(0, 1e6), "Hardware threads.")),
                          required(number("calibration_ms", std::nullopt, open_closed(0, 1e6),
                                          "The calibration kernel's median on the baseline machine, ms."))},
                         "The machine the baseline was taken on.")),
         required(number("tolerance", std::nullopt, closed(0, kMaxTolerance), "Relative allowance.")),
         required(number("slack_ms", std::nullopt, closed(0, kMaxSlackMs), "Absolute allowance, ms.")),
         benchmarks},
        "A cut-timing baseline.");
  }();
  return entry;
}

// The bench document's calibration, ms.
double calibration_of(const json& bench) {
  const auto m = bench.find("machine");
  if (m == bench.end() || !m->is_object() || !m->contains("calibration_ms") || !(*m)["calibration_ms"].is_number())
    throw std::invalid_argument("the benchmark results carry no machine/calibration_ms");
  const double c = (*m)["calibration_ms"].get<double>();
  if (!std::isfinite(c) || c <= 0.0) throw std::invalid_argument("the benchmark results' calibration_ms is not positive");
  return c;
}

// The benchmark named `name` in a bench document, or null when it did not run (the last entry of that name).
const json* find_benchmark(const json& bench, const std::string& name) {
  const json* run = nullptr;
  if (bench.contains("benchmarks") && bench["benchmarks"].is_array())
    for (const json& b : bench["benchmarks"])
      if (b.is_object() && b.value("name", "") == name) run = &b;
  return run;
}

json parse_bench(const std::string& bench_json) {
  try {
    return json::parse(bench_json);
  } catch (const json::parse_error& e) {
    throw std::invalid_argument(std::string("benchmark results are not JSON: ") + e.what());
  }
}

}  // namespace

CutBaseline parse_cut_baseline(const std::string& text, const std::string& file) {
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    throw std::invalid_argument(file + ": not JSON: " + e.what());
  }
  // The document's shape, by the schema validator; then what the schema cannot say.
  try {
    schema::validate(doc, baseline_schema(), "", file);
  } catch (const SceneError& e) {
    throw std::invalid_argument(e.what());
  }
  CutBaseline b;
  b.cpu = doc["machine"].value("cpu", std::string());
  b.calibration_ms = doc["machine"]["calibration_ms"].get<double>();
  b.tolerance = doc["tolerance"].get<double>();
  b.slack_ms = doc["slack_ms"].get<double>();
  std::set<std::string> names;
  for (std::size_t i = 0; i < doc["benchmarks"].size(); ++i) {
    const nlohmann::json& e = doc["benchmarks"][i];
    const std::string at = join_pointer("/benchmarks", i);
    CutBaseline::Benchmark bm;
    bm.name = e["name"].get<std::string>();
    if (!bm.name.starts_with("cut/")) bad(file, at + "/name", "expected the name of a cut benchmark (\"cut/...\")");
    if (!names.insert(bm.name).second) bad(file, at + "/name", "benchmark '" + bm.name + "' listed twice");
    bm.cuts_ok = static_cast<long>(e["cuts_ok"].get<std::int64_t>());
    // Stages in the report's order, then the latency (the schema allows only these names).
    for (const char* stage : kBaselineKeys)
      if (e["ms"].contains(stage)) bm.stages.push_back({stage, e["ms"][stage].get<double>()});
    b.benchmarks.push_back(std::move(bm));
  }
  return b;
}

void check_baseline_allowances(double tolerance, double slack_ms) {
  if (!(tolerance >= 0.0 && tolerance <= kMaxTolerance)) throw std::invalid_argument("--tolerance must lie in [0, 10]");
  if (!(slack_ms >= 0.0 && slack_ms <= kMaxSlackMs)) throw std::invalid_argument("--slack-ms must lie in [0, 1000]");
}

std::string make_cut_baseline(const std::string& bench_json, double tolerance, double slack_ms) {
  return make_cut_baseline(std::vector<std::string>{bench_json}, tolerance, slack_ms);
}

std::string make_cut_baseline(const std::vector<std::string>& bench_jsons, double tolerance, double slack_ms) {
  check_baseline_allowances(tolerance, slack_ms);
  if (bench_jsons.empty()) throw std::invalid_argument("a baseline needs the results of at least one run");
  std::vector<json> runs;
  std::vector<double> calibrations;  // ms, per run
  for (const std::string& text : bench_jsons) {
    runs.push_back(parse_bench(text));
    calibrations.push_back(calibration_of(runs.back()));
  }
  // Each run's stage times are scaled to the runs' median calibration (by exactly 1 for the run that has it), then
  // each stage takes the median over the runs: a slow moment of the machine in one run moves neither.
  const double calibration = TimingSummary::of(calibrations).median;
  const json& first = runs.front();
  json doc;
  doc["schema"] = kSchema;
  doc["machine"] = {{"cpu", first["machine"].value("cpu", "unknown")},
                    {"threads", first["machine"].value("threads", 0)},
                    {"calibration_ms", calibration}};
  doc["tolerance"] = tolerance;
  doc["slack_ms"] = slack_ms;
  doc["benchmarks"] = json::array();
  for (const json& b : first.value("benchmarks", json::array())) {
    const std::string name = b.value("name", "");
    if (!name.starts_with("cut/")) continue;
    long ok = -1;
    std::vector<std::vector<double>> ms(kBaselineKeys.size());  // per stage, per run
    for (std::size_t r = 0; r < runs.size(); ++r) {
      const json* run = find_benchmark(runs[r], name);
      if (run == nullptr) throw std::invalid_argument(name + ": not in run " + std::to_string(r + 1));
      const long run_ok = run->contains("params") ? (*run)["params"].value("ok", 0L) : 0L;
      if (run_ok < 1) throw std::invalid_argument(name + ": no ok cut to take a baseline from");
      if (ok >= 0 && run_ok != ok)
        throw std::invalid_argument(name + ": " + std::to_string(run_ok) + " ok cuts in run " + std::to_string(r + 1) +
                                    ", " + std::to_string(ok) + " in the first (medians over other cuts do not mix)");
      ok = run_ok;
      const double factor = calibration / calibrations[r];
      for (std::size_t k = 0; k < kBaselineKeys.size(); ++k) {
        const std::string key = std::string(kBaselineKeys[k]) + "_ms";
        if (!run->contains("metrics") || !(*run)["metrics"].contains(key) || !(*run)["metrics"][key].is_number())
          throw std::invalid_argument(name + ": the results lack metrics/" + key);
        ms[k].push_back((*run)["metrics"][key].get<double>() * factor);
      }
    }
    json stages = json::object();
    for (std::size_t k = 0; k < kBaselineKeys.size(); ++k) stages[kBaselineKeys[k]] = TimingSummary::of(ms[k]).median;
    doc["benchmarks"].push_back({{"name", name}, {"cuts_ok", ok}, {"ms", stages}});
  }
  if (doc["benchmarks"].empty()) throw std::invalid_argument("no cut benchmark ran: a baseline needs at least one");
  return doc.dump(2) + "\n";
}

BaselineComparison compare_cut_baseline(const std::string& bench_json, const CutBaseline& baseline) {
  const json bench = parse_bench(bench_json);
  BaselineComparison out;
  out.scale = calibration_of(bench) / baseline.calibration_ms;
  // The scale corrects for a machine's speed at the kernel's mix of work, not for the balance of that work: on another
  // kind of CPU the stages that lean on memory bandwidth (the embedding update, the solver's preparation) can scale
  // otherwise (an AMD EPYC baseline flagged them on an Intel Xeon, 1.1-1.3 times its scale, docs/RESULTS.md).
  const std::string cpu = bench["machine"].value("cpu", std::string());  // calibration_of checked "machine"
  if (!baseline.cpu.empty() && !cpu.empty() && cpu != baseline.cpu)
    out.notes.push_back("the baseline was taken on '" + baseline.cpu + "', this machine is '" + cpu +
                        "': the calibration scale corrects for speed, not for the balance between computation and "
                        "memory; a stage that leans on memory may exceed its limit on another kind of CPU without a "
                        "change in the code (take a baseline here: --write-baseline F --repeat 5)");
  for (const CutBaseline::Benchmark& bm : baseline.benchmarks) {
    const json* run = find_benchmark(bench, bm.name);
    if (run == nullptr) {
      out.notes.push_back(bm.name + ": not run, not compared");
      continue;
    }
    const long ok = run->contains("params") ? (*run)["params"].value("ok", 0L) : 0L;
    if (ok != bm.cuts_ok) {
      // Medians over other sets of cuts are not comparable.
      out.problems.push_back(bm.name + ": " + std::to_string(ok) + " ok cuts, the baseline has " +
                             std::to_string(bm.cuts_ok) + " (timings not compared)");
      continue;
    }
    for (const CutBaseline::Stage& s : bm.stages) {
      const std::string key = s.name + "_ms";
      if (!run->contains("metrics") || !(*run)["metrics"].contains(key) || !(*run)["metrics"][key].is_number()) {
        // A stage without a number (a NaN time is written as null) cannot pass.
        out.problems.push_back(bm.name + ": " + s.name + " has no measured time");
        continue;
      }
      BaselineRow row;
      row.benchmark = bm.name;
      row.stage = s.name;
      row.baseline_ms = s.ms;
      row.expected_ms = out.scale * s.ms;
      row.limit_ms = out.scale * (s.ms * (1.0 + baseline.tolerance) + baseline.slack_ms);
      row.measured_ms = (*run)["metrics"][key].get<double>();
      // NaN never passes.
      row.regressed = !(row.measured_ms <= row.limit_ms);
      if (row.regressed) {
        char line[256];
        std::snprintf(line, sizeof line, "%s: %s took %.3f ms, above the limit of %.3f ms (baseline %.3f ms x %.3f)",
                      bm.name.c_str(), s.name.c_str(), row.measured_ms, row.limit_ms, s.ms, out.scale);
        out.problems.emplace_back(line);
      }
      out.rows.push_back(row);
    }
  }
  return out;
}

std::string with_baseline_comparison(const std::string& bench_json, const BaselineComparison& c,
                                     const std::string& file) {
  json bench = parse_bench(bench_json);
  json doc;
  doc["file"] = file;
  doc["status"] = c.ok() ? "ok" : "regressed";
  doc["scale"] = c.scale;
  doc["rows"] = json::array();
  for (const BaselineRow& r : c.rows) {
    doc["rows"].push_back({{"benchmark", r.benchmark},
                           {"stage", r.stage},
                           {"baseline_ms", r.baseline_ms},
                           {"expected_ms", r.expected_ms},
                           {"limit_ms", r.limit_ms},
                           {"measured_ms", r.measured_ms},
                           {"regressed", r.regressed}});
  }
  doc["problems"] = c.problems;
  doc["notes"] = c.notes;
  bench["baseline"] = std::move(doc);
  return bench.dump(2) + "\n";
}

std::string baseline_comparison_table(const BaselineComparison& c) {
  std::string out;
  char line[256];
  std::snprintf(line, sizeof line, "baseline comparison (calibration scale %.3f)\n", c.scale);
  out += line;
  std::snprintf(line, sizeof line, "%-24s %-15s %11s %11s %11s %11s\n", "benchmark", "stage", "baseline_ms",
                "expected_ms", "limit_ms", "measured_ms");
  out += line;
  for (const BaselineRow& r : c.rows) {
    std::snprintf(line, sizeof line, "%-24s %-15s %11.3f %11.3f %11.3f %11.3f%s\n", r.benchmark.c_str(),
                  r.stage.c_str(), r.baseline_ms, r.expected_ms, r.limit_ms, r.measured_ms,
                  r.regressed ? "  REGRESSED" : "");
    out += line;
  }
  for (const std::string& n : c.notes) out += "note: " + n + "\n";
  for (const std::string& p : c.problems) out += "regression: " + p + "\n";
  out += c.ok() ? "no regression\n" : std::to_string(c.problems.size()) + " regression(s)\n";
  return out;
}

}  // namespace octocut::engine
