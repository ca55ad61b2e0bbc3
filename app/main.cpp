// octocut: command-line parsing and subcommands only (SPEC §7). Exit codes: 0 success, 1 the run failed (report
// still written), 2 bad input or usage.
#include <CLI/CLI.hpp>
#include <unistd.h>

#include <climits>
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "octocut/engine/assets/procedural_meshes.hpp"
#include "octocut/engine/bench/bench.hpp"
#include "octocut/engine/bench/bench_baseline.hpp"
#include "octocut/engine/run/cut_command.hpp"
#include "octocut/engine/scene/expected.hpp"
#include "octocut/engine/io/io.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/engine/study/study.hpp"
#include "octocut/engine/run/tool.hpp"
#include "octocut/engine/run/run.hpp"
#include "octocut/engine/run/scene_object.hpp"
#include "octocut/engine/run/session.hpp"
#include "octocut/engine/view/viewer.hpp"
#include "octocut/version.hpp"

namespace {

using namespace octocut;

/// What `run` does with the scene's `expected` block after the run.
enum class ExpectedMode { none, check, regenerate };

/// Checks the report at `report_path` against the scene's `expected` block (as loaded, overrides included); prints
/// one line per failure. Returns 1 when a check fails, 0 otherwise (also when the scene has no block).
int check_report(const engine::Scene& scene, const std::string& report_path) {
  if (scene.expected_json.empty()) {
    std::printf("check: %s has no expected block; nothing to check\n", scene.file.c_str());
    return 0;
  }
  const std::vector<std::string> failures =
      engine::check_expected(scene.expected_json, engine::read_file(report_path));
  for (const std::string& f : failures) std::fprintf(stderr, "octocut: check failed: %s\n", f.c_str());
  const std::size_t total = engine::expected_check_count(scene.expected_json);
  if (!failures.empty()) {
    std::fprintf(stderr, "octocut: %zu of %zu expected checks failed\n", failures.size(), total);
    return 1;
  }
  std::printf("check: all %zu expected checks passed\n", total);
  return 0;
}

/// Rewrites the `expected` block of the scene file at `scene_path` with the values of the report at `report_path`,
/// atomically, keeping every other byte of the file; then checks the new block. Returns 1 when a check still fails.
int regenerate_report(const std::string& scene_path, const std::string& report_path) {
  // The block as written in the file, members in their order (overrides are not written back).
  const std::string text = engine::read_file(scene_path);
  const std::string block = engine::expected_block_text(text);
  if (block.empty()) {
    std::printf("regenerate: %s has no expected block; add one with the report pointers to track\n",
                scene_path.c_str());
    return 0;
  }
  const std::string report = engine::read_file(report_path);
  const std::string updated = engine::replace_expected_block(text, engine::regenerate_expected(block, report));
  engine::write_file_atomic(scene_path, updated);
  std::printf("regenerate: rewrote the expected block of %s\n", scene_path.c_str());
  return check_report(engine::load_scene(scene_path), report_path);
}

/// The session file of `--replay`, parsed and validated (SceneError naming the file and pointer, exit 2).
engine::Session read_session(const std::string& path) {
  std::string text;
  try {
    text = engine::read_file(path);
  } catch (const std::runtime_error& e) {
    throw engine::SceneError(path + ": cannot read the session file: " + e.what());
  }
  return engine::parse_session(text, path);
}

int cmd_run(const std::string& scene_path, std::vector<std::string> sets, const std::string& out,
            bool no_render, bool quiet, ExpectedMode expected, const std::string& replay_path) {
  // A replay runs with the overrides it was recorded with, then those given now.
  std::optional<engine::Session> session;
  if (!replay_path.empty()) {
    session = read_session(replay_path);
    sets.insert(sets.begin(), session->sets.begin(), session->sets.end());
  }
  const engine::Scene scene = engine::load_scene(scene_path, sets);
  if (session) engine::check_session_scene(*session, scene, replay_path);
  engine::RunOptions o;
  o.replay = session ? &*session : nullptr;
  o.out_dir = out;
  o.no_render = no_render;
  o.progress = !quiet;
  const engine::RunResult r = engine::run_scene(scene, o);
  if (r.exit_code != 0) {
    std::fprintf(stderr, "octocut: %s\n", r.error.c_str());
    if (r.report_written) std::fprintf(stderr, "octocut: report written to %s\n", r.report_path.c_str());
    // A failed run's report is still checked (its failures are worth seeing), but never becomes the reference.
    if (r.report_written && expected == ExpectedMode::check) check_report(scene, r.report_path);
    if (r.exit_code == 1 && expected == ExpectedMode::regenerate) {
      std::fprintf(stderr, "octocut: not regenerating the expected block from a failed run\n");
    }
    return r.exit_code;
  }
  if (!quiet) std::printf("report: %s\n", r.report_path.c_str());
  if (expected == ExpectedMode::check) return check_report(scene, r.report_path);
  if (expected == ExpectedMode::regenerate) return regenerate_report(scene_path, r.report_path);
  return 0;
}

int cmd_view(const std::string& scene_path, const std::vector<std::string>& sets, const engine::ViewOptions& options) {
  const engine::Scene scene = engine::load_scene(scene_path, sets);
  engine::ViewOptions o = options;
  o.sets = sets;
  const engine::ViewResult r = engine::run_viewer(scene, o);
  if (r.exit_code != 0) std::fprintf(stderr, "octocut: %s\n", r.error.c_str());
  return r.exit_code;
}

int cmd_validate(const std::string& scene_path, const std::vector<std::string>& sets) {
  const engine::Scene scene = engine::load_scene(scene_path, sets);
  const engine::SceneObject o = engine::build_scene_object(scene);
  const std::vector<sim::TriMesh> props = engine::load_render_props(scene);
  const sim::ObjectModel& m = o.model;
  std::printf("%s: ok (%d elements, %d DOFs, %d hanging slots; surface %zu vertices, %zu triangles; %d tets)\n",
              scene_path.c_str(), m.num_elements(), m.num_dofs(), m.dofs().hanging_slots, o.surface.num_vertices(),
              o.surface.num_triangles(), m.material_graph() ? m.material_graph()->num_tets() : 0);
  if (!props.empty()) std::printf("%s: %zu render props loaded\n", scene_path.c_str(), props.size());
  for (const engine::ToolSummary& t : engine::validate_tools(scene)) {
    std::printf("tool %s: blade %s (%zu vertices, %zu triangles, %.6g m^3); mesh %zu triangles; %zu keyframes, "
                "%zu cuts\n",
                t.name.c_str(), t.blade.c_str(), t.blade_vertices, t.blade_triangles, t.blade_volume_m3,
                t.mesh_triangles, t.keyframes, t.cuts);
    for (const std::string& w : t.warnings) std::printf("warning: %s\n", w.c_str());
  }
  for (const std::string& w : o.warnings) std::printf("warning: %s\n", w.c_str());
  return 0;
}

int cmd_assets(const std::string& dir) {
  // Regenerate every procedural mesh and list what was written.
  const std::vector<engine::AssetInfo> infos = engine::write_assets(dir);
  std::printf("%-20s %9s %9s %14s\n", "file", "vertices", "triangles", "volume_mm3");
  for (const engine::AssetInfo& a : infos) {
    std::printf("%-20s %9zu %9zu %14.3f\n", a.file.c_str(), a.vertices, a.triangles, a.volume_mm3);
  }
  std::printf("wrote %zu meshes (mm) to %s\n", infos.size(), dir.c_str());
  return 0;
}

struct BaselineOptions {
  std::string compare_path;  // --baseline
  std::string write_path;    // --write-baseline
  double tolerance = 0.3;    // relative
  double slack_ms = 0.25;    // ms on the baseline machine
  int repeat = 1;            // --repeat: runs a new baseline takes its medians over
};

// Runs the benchmarks; with a baseline, compares the cut timings with it (exit 1 on a regression, the JSON still
// written); with --write-baseline, stores the cut timings as a new baseline: with --repeat N, the benchmarks run N
// times and the baseline takes each stage's median over the runs (the comparison and the JSON are the last run's).
int cmd_bench(std::vector<std::string> names, const std::string& json_path, bool quiet, const BaselineOptions& b) {
  std::optional<engine::CutBaseline> baseline;
  if (!b.compare_path.empty()) {
    std::string text;
    try {
      text = engine::read_file(b.compare_path);
    } catch (const std::runtime_error& e) {
      throw std::invalid_argument(e.what());  // a missing or unreadable baseline is bad input (exit 2)
    }
    baseline = engine::parse_cut_baseline(text, b.compare_path);
    const std::vector<std::string> known = engine::benchmark_names();
    const bool run_the_baselines = names.empty();
    for (std::size_t i = 0; i < baseline->benchmarks.size(); ++i) {
      const std::string& name = baseline->benchmarks[i].name;
      if (std::find(known.begin(), known.end(), name) == known.end()) {
        throw std::invalid_argument(b.compare_path + ": /benchmarks/" + std::to_string(i) +
                                    "/name: this build has no benchmark '" + name + "'");
      }
      if (run_the_baselines) names.push_back(name);
    }
  }
  if (!b.write_path.empty()) {
    engine::check_baseline_allowances(b.tolerance, b.slack_ms);  // before the benchmarks run, not after
    if (names.empty()) names.push_back("cut");
  }
  if (b.repeat < 1 || b.repeat > 100) throw std::invalid_argument("--repeat must lie in [1, 100]");
  std::vector<std::string> runs;
  for (int r = 0; r < (b.write_path.empty() ? 1 : b.repeat); ++r) runs.push_back(engine::run_benchmarks(names, quiet));
  std::string doc = runs.back();
  int code = 0;
  if (baseline) {
    const engine::BaselineComparison c = engine::compare_cut_baseline(doc, *baseline);
    doc = engine::with_baseline_comparison(doc, c, b.compare_path);
    if (!quiet) std::printf("%s", engine::baseline_comparison_table(c).c_str());
    for (const std::string& p : c.problems) std::fprintf(stderr, "octocut: regression: %s\n", p.c_str());
    if (!c.ok()) code = 1;
  }
  if (!json_path.empty()) engine::write_file_atomic(json_path, doc);
  if (!b.write_path.empty())
    engine::write_file_atomic(b.write_path, engine::make_cut_baseline(runs, b.tolerance, b.slack_ms));
  return code;
}

// The cut-timing baseline options of `octocut bench`.
void add_baseline_options(CLI::App& bench, BaselineOptions& o) {
  bench.add_option("--baseline", o.compare_path,
                   "Compare the cut timings with this octocut.cut_baseline/1 file, normalised by the calibration "
                   "kernel; exit 1 on a regression (default names: the baseline's benchmarks)");
  auto* write_baseline = bench.add_option(
      "--write-baseline", o.write_path,
      "Store this run's cut timings and calibration as a baseline (default names: every cut/ benchmark)");
  bench.add_option("--tolerance", o.tolerance, "With --write-baseline: allowed relative slowdown of a stage")
      ->capture_default_str()
      ->needs(write_baseline);
  bench.add_option("--slack-ms", o.slack_ms,
                   "With --write-baseline: allowed absolute slowdown of a stage, ms on this machine")
      ->capture_default_str()
      ->needs(write_baseline);
  bench.add_option("--repeat", o.repeat,
                   "With --write-baseline: run the benchmarks this many times and store each stage's median over "
                   "the runs (each scaled to their median calibration)")
      ->capture_default_str()
      ->needs(write_baseline);
}

/// The absolute path of this executable (the cases of a study run it).
std::string self_executable(const char* argv0) {
  char buf[PATH_MAX];
  const ssize_t n = readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  return n > 0 ? std::string(buf, std::size_t(n)) : std::string(argv0);
}

// `octocut study accuracy|stability SCENE ...` and `octocut study collect DIR...`.
int cmd_study(engine::StudyOptions o, const std::vector<std::string>& args, bool out_given) {
  if (o.kind == "collect") {
    if (args.empty()) throw std::invalid_argument("study collect: give the directories to merge");
    return engine::collect_study(args, o.quiet);
  }
  if (o.kind != "accuracy" && o.kind != "stability")
    throw std::invalid_argument("unknown study '" + o.kind + "' (accuracy, stability, collect)");
  if (args.size() != 1) throw std::invalid_argument("study " + o.kind + ": give exactly one scene file");
  if (!out_given) throw std::invalid_argument("study " + o.kind + ": --out DIR is required");
  o.scene = args.front();
  return engine::run_study(o);
}

// `octocut study`: its options into `o`, its positional arguments into `args`; `out` is the --out option.
CLI::App* add_study_command(CLI::App& app, engine::StudyOptions& study_opts, std::vector<std::string>& study_args,
                            CLI::Option*& study_out) {
  auto* study = app.add_subcommand(
      "study", "Studies: `study accuracy SCENE --out DIR` (error against run time), `study stability SCENE --out DIR` "
               "(the stability matrix), `study collect DIR...` (merge cases that ran anywhere)");
  study->add_option("study", study_opts.kind, "accuracy | stability | collect")->required();
  study->add_option("args", study_args, "The scene (accuracy, stability) or the directories (collect)");
  study_out = study->add_option("--out", study_opts.out_dir, "Where the plan, the cases and the results go");
  study->add_option("--reference", study_opts.reference,
                    "accuracy: a JSON file {\"probes\": {NAME: [ux, uy, uz]}}, or `ccx` (CalculiX on the same "
                    "uniform mesh); default: Richardson extrapolation of the uniform sequence");
  study->add_option("--jobs", study_opts.jobs, "Cases run at once, each its own process")->capture_default_str();
  study->add_option("--emit-jobs", study_opts.emit_jobs,
                    "Write one self-contained `octocut run` command per line to this file and run nothing");
  study->add_option("--set", study_opts.sets,
                    "Scene override for every case (/json/pointer=value), or /study/KEY=JSON to narrow the sweep");
  study->add_flag("--quiet", study_opts.quiet, "No progress lines");

  return study;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"octocut: robust interactive cutting on an adaptive octree (Seiler et al. 2011)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("octocut ") + octocut::kVersion, "Print the version and exit");

  std::string scene_path, out = "out", json_path;
  std::vector<std::string> sets, names;
  bool no_render = false, quiet = false;

  auto* run = app.add_subcommand("run", "Run a scene and write DIR/report.json");
  run->add_option("scene", scene_path, "Scene file (JSON)")->required();
  run->add_option("--out", out, "Output directory")->capture_default_str();
  run->add_option("--set", sets, "Override a scene key: /json/pointer=value (repeatable)");
  run->add_flag("--no-render", no_render, "Never start EGL, whatever the scene asks");
  run->add_flag("--quiet", quiet, "No progress line");
  bool check = false, regenerate = false;
  auto* check_flag = run->add_flag(
      "--check", check,
      "After the run, compare report.json with the scene's `expected` block; print each failed check and exit 1 "
      "if any fails (a scene without the block passes with a note)");
  run->add_flag("--regenerate", regenerate,
                "After a successful run, rewrite the `expected` block of the scene file with the report's values "
                "(same pointers and kinds of tolerance; atomic; the rest of the file is kept byte for byte)")
      ->excludes(check_flag);

  std::string replay_path;
  run->add_option("--replay", replay_path,
                  "Replay a session recorded by `octocut view --record` instead of the scene's timeline (its inputs "
                  "at the steps they took effect; headless, deterministic)");

  auto* view = app.add_subcommand("view", "Open the interactive viewer: the scene running in real time, the first tool "
                                          "in the hand (needs a display)");
  engine::ViewOptions view_opts;
  std::string view_size;
  view->add_option("scene", scene_path, "Scene file (JSON)")->required();
  view->add_option("--set", sets, "Override a scene key: /json/pointer=value (repeatable)");
  view->add_option("--record", view_opts.record_path, "Write the session (every input with its step) here on exit");
  view->add_option("--out", view_opts.out_dir, "Write report.json here on exit; screenshots and frames go here too");
  view->add_option("--size", view_size, "Window size WIDTHxHEIGHT in pixels (default: the scene's render size)");
  view->add_option("--tool", view_opts.tool, "The tool in the hand, by name (default: the first)");

  auto* validate = app.add_subcommand("validate", "Load and check a scene, run nothing");
  validate->add_option("scene", scene_path, "Scene file (JSON)")->required();
  validate->add_option("--set", sets, "Override a scene key: /json/pointer=value (repeatable)");

  auto* bench = app.add_subcommand("bench", "Run the built-in benchmarks");
  bench->add_option("names", names, "Benchmark names or prefixes (default: all)");
  bench->add_option("--json", json_path, "Write the octocut.bench/1 JSON here");
  bench->add_flag("--quiet", quiet, "No table on stdout");
  bool list = false;
  bench->add_flag("--list", list, "List the benchmark names and exit");
  BaselineOptions baseline_opts;
  add_baseline_options(*bench, baseline_opts);

  auto* cut = app.add_subcommand("cut", "One rest-space cut of a surface by a blade (stages 2-3, fresh M)");
  engine::CutCommandOptions cut_opts;
  cut->add_option("--surface", cut_opts.surface_path, "Closed surface mesh")->required();
  cut->add_option("--blade", cut_opts.blade_path, "Closed, oriented blade mesh")->required();
  cut->add_option("--out", cut_opts.out_path, "Output mesh, metres; the format follows the extension")->required();
  cut->add_option("--scale", cut_opts.scale, "Multiplies both inputs' coordinates to get metres")->capture_default_str();
  cut->add_option("--report", cut_opts.report_path, "Write the octocut.cut/1 report here");
  cut->add_option("--cell-size", cut_opts.cell_size, "Material graph cell size, m (default 1 mm)");
  bool no_verify = false;
  cut->add_flag("--no-verify", no_verify, "Skip the local check of the result");
  cut->add_flag("--ply-float", cut_opts.ply_float, "Write a .ply output in float32 (default float64, exact)");

  engine::StudyOptions study_opts;
  std::vector<std::string> study_args;
  CLI::Option* study_out = nullptr;
  CLI::App* study = add_study_command(app, study_opts, study_args, study_out);

  auto* scene_doc = app.add_subcommand("scene-doc", "Print the scene-format documentation generated from the schema");

  auto* assets = app.add_subcommand("assets", "Regenerate the procedural meshes (binary PLY, millimetres)");
  std::string assets_dir = std::string(OCTOCUT_SOURCE_DIR) + "/assets/meshes";
  assets->add_option("--out", assets_dir, "Output directory")->capture_default_str();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }

  try {
    if (*run) {
      const ExpectedMode mode = check ? ExpectedMode::check : regenerate ? ExpectedMode::regenerate : ExpectedMode::none;
      return cmd_run(scene_path, sets, out, no_render, quiet, mode, replay_path);
    }
    if (*view) {
      if (!view_size.empty()) {
        int w = 0, h = 0;
        char tail = 0;
        if (std::sscanf(view_size.c_str(), "%dx%d%c", &w, &h, &tail) != 2 || w < 64 || h < 64 || w > 8192 || h > 8192)
          throw std::invalid_argument("--size " + view_size + ": expected WIDTHxHEIGHT, each in 64..8192 pixels");
        view_opts.width = w;
        view_opts.height = h;
      }
      return cmd_view(scene_path, sets, view_opts);
    }
    if (*validate) return cmd_validate(scene_path, sets);
    if (*bench && list) {
      for (const std::string& n : engine::benchmark_names()) std::printf("%s\n", n.c_str());
      return 0;
    }
    if (*bench) return cmd_bench(names, json_path, quiet, baseline_opts);
    if (*assets) return cmd_assets(assets_dir);
    if (*study) {
      study_opts.executable = self_executable(argv[0]);
      return cmd_study(study_opts, study_args, study_out->count() > 0);
    }
    if (*cut) {
      cut_opts.verify = !no_verify;
      const engine::CutCommandResult r = engine::run_cut_command(cut_opts);
      std::fprintf(r.exit_code == 0 ? stdout : stderr, "%s%s\n", r.exit_code == 0 ? "" : "octocut: ", r.message.c_str());
      return r.exit_code;
    }
    if (*scene_doc) {
      std::cout << engine::scene_format_markdown();
      return 0;
    }
  } catch (const engine::SceneError& e) {
    std::fprintf(stderr, "octocut: %s\n", e.what());
    return 2;
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "octocut: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "octocut: error: %s\n", e.what());
    return 1;
  }
  return 2;
}
