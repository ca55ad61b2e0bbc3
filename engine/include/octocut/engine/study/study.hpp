#pragma once
// `octocut study` (SPEC §7, §10): the accuracy study (error against run time, its Pareto front) and the stability
// matrix. A study is a plan of cases; each case is one self-contained `octocut run` command (the scene, --set
// overrides, --out), so the cases run in this process's children (--jobs N), under GNU parallel or a Slurm array
// (--emit-jobs FILE), or anywhere else, and `study collect` merges their reports into the study's tables, plots and
// Markdown. Every number of a study comes from the cases' report.json files and surfaces, so a study is the same
// whether it ran in one process or on many machines (timings aside).
#include <string>
#include <vector>

namespace octocut::engine {

/// The command line of `octocut study accuracy|stability`.
struct StudyOptions {
  std::string kind;                ///< "accuracy" | "stability"
  std::string scene;               ///< scene file
  std::string out_dir;             ///< where the plan, the cases and the results go
  std::string reference;           ///< accuracy: "" (Richardson extrapolation), "ccx", or an octocut.reference JSON file
  int jobs = 1;                    ///< cases run at once, as separate processes
  std::string emit_jobs;           ///< when set: write one command per line here and run nothing
  std::vector<std::string> sets;   ///< `/json/pointer=value`: scene overrides for every case; `/study/...` narrows
  std::string executable;          ///< the octocut executable the cases run (absolute)
  bool quiet = false;              ///< no progress lines
};

/// Plans the study, writes `out_dir/study_plan.json`, then either writes the job file (emit_jobs) or runs the cases
/// and collects them. Returns the exit code: 0, or 1 when cases failed to run (accuracy) or cells are not finite or
/// not bounded (stability). Throws std::invalid_argument (or SceneError) for bad input: an unknown study, a scene
/// without probes for accuracy, a reference naming an unknown probe, an unknown `/study/` key.
int run_study(const StudyOptions& options);

/// Merges the cases found under `dirs` (each holding `cases/<id>/report.json`; the plan is read from the first dir
/// that has `study_plan.json`) and writes the study's outputs into that dir. Returns the exit code as run_study.
int collect_study(const std::vector<std::string>& dirs, bool quiet);

}  // namespace octocut::engine
