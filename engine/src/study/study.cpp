// `octocut study`: plan, run (or emit) and collect.
#include "octocut/engine/study/study.hpp"

#include <cstdio>
#include <stdexcept>

#include "octocut/engine/io/io.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "study_internal.hpp"

namespace octocut::engine {

namespace {

using study::ojson;
namespace fs = std::filesystem;

// The accuracy study's reference, resolved when it is planned: a file's or ccx's probe values, or Richardson's
// (computed when collected).
ojson plan_reference(const std::string& reference, const Scene& scene, const study::Plan& plan, const fs::path& out) {
  if (reference.empty() || reference == "richardson")
    return {{"kind", "richardson"}, {"source", "the uniform sequence of this study"}};
  if (reference == "ccx") {
    const int level = plan.settings.at("levels").back();
    ojson probes = study::ccx_reference(scene, level, out / "ccx");
    return {{"kind", "ccx"}, {"source", (out / "ccx" / "deck.inp").string()}, {"level", level}, {"probes", probes}};
  }
  return {{"kind", "file"}, {"source", fs::absolute(reference).string()},
          {"probes", study::read_reference_file(reference, scene)}};
}

}  // namespace

int run_study(const StudyOptions& options) {
  if (options.kind != "accuracy" && options.kind != "stability")
    throw std::invalid_argument("unknown study '" + options.kind + "' (accuracy, stability, collect)");
  if (options.kind == "stability" && !options.reference.empty())
    throw std::invalid_argument("--reference: only the accuracy study has a reference");
  std::vector<std::string> sets = options.sets;
  const std::map<std::string, ojson> study_sets = study::take_study_sets(sets);
  const Scene scene = load_scene(options.scene, sets);
  study::Plan plan = options.kind == "accuracy" ? study::plan_accuracy(scene, study_sets)
                                                : study::plan_stability(scene, study_sets);
  plan.scene = fs::absolute(options.scene).lexically_normal().string();
  plan.executable = options.executable;
  plan.sets = sets;
  ojson given = ojson::object();  // the /study/ keys as given, for the files' "Reproduce" line
  for (const auto& [key, value] : study_sets) given[key] = value;
  plan.settings["study_sets"] = given;
  const fs::path out = fs::absolute(options.out_dir);
  fs::create_directories(out);
  if (plan.kind == "accuracy") plan.reference = plan_reference(options.reference, scene, plan, out);
  write_file_atomic(out / "study_plan.json", study::plan_json(plan, out).dump(2) + "\n");
  if (!options.emit_jobs.empty()) {
    // One self-contained command per line: GNU parallel runs the file as it is, a Slurm array runs line $TASK_ID.
    std::string lines;
    for (const study::Case& c : plan.cases) lines += study::case_command(plan, c, out) + "\n";
    write_file_atomic(options.emit_jobs, lines);
    if (!options.quiet)
      std::printf("study: wrote %zu commands to %s; run them, then `octocut study collect %s`\n", plan.cases.size(),
                  options.emit_jobs.c_str(), out.c_str());
    return 0;
  }
  const int broken = study::run_cases(plan, out, options.jobs, options.quiet);
  const int code = collect_study({out.string()}, options.quiet);
  return broken > 0 ? std::max(code, 1) : code;
}

int collect_study(const std::vector<std::string>& dirs, bool quiet) {
  if (dirs.empty()) throw std::invalid_argument("study collect: no directory given");
  std::vector<fs::path> paths;
  fs::path plan_dir;
  for (const std::string& d : dirs) {
    if (!fs::is_directory(d)) throw std::invalid_argument("study collect: " + d + ": not a directory");
    paths.push_back(fs::absolute(d));
    if (plan_dir.empty() && fs::exists(paths.back() / "study_plan.json")) plan_dir = paths.back();
  }
  if (plan_dir.empty()) throw std::invalid_argument("study collect: none of the directories holds study_plan.json");
  const fs::path plan_file = plan_dir / "study_plan.json";
  ojson j;
  try {
    j = ojson::parse(read_file(plan_file));
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(plan_file.string() + ": not JSON: " + e.what());
  }
  const study::Plan plan = study::plan_from_json(j, plan_file.string());
  return plan.kind == "accuracy" ? study::collect_accuracy(plan, paths, plan_dir, quiet)
                                 : study::collect_stability(plan, paths, plan_dir, quiet);
}

}  // namespace octocut::engine
