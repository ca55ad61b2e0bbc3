#pragma once
// The study's parts, private to engine/src/study: the plan (cases and their commands), running the cases, the
// accuracy and stability collectors, the CalculiX reference, and the plots.
#include <array>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "octocut/engine/scene/scene.hpp"

namespace octocut::engine::study {

using ojson = nlohmann::ordered_json;
namespace fs = std::filesystem;

/// One case: a self-contained `octocut run` of the scene with overrides.
struct Case {
  std::string id;                 ///< unique, file-name safe; its outputs go to cases/<id>/
  ojson params = ojson::object(); ///< its settings, for the tables (level, mesh, element, solver, ...)
  std::vector<std::string> sets;  ///< `--set` overrides after the study's own (`/json/pointer=value`)
};

/// A study: what it runs and how its results are judged.
struct Plan {
  std::string kind;                    ///< "accuracy" | "stability"
  std::string scene;                   ///< absolute scene path
  std::string executable;              ///< absolute octocut path
  std::vector<std::string> sets;       ///< the user's scene overrides (every case)
  ojson reference = ojson::object();   ///< accuracy: {kind: richardson|file|ccx, source, probes {name: [3]}}
  ojson settings = ojson::object();    ///< the sweep or matrix as planned (levels, elements, ...), and notes
  double object_size_m = 0.0;          ///< largest edge of the object's bounding box, m
  std::vector<Case> cases;
};

/// A probe's displacement, m.
using Vec3d = std::array<double, 3>;

// ---- plan (study_plan.cpp) ----
/// Plans the accuracy sweep of `scene` (loaded with the user's overrides); `study_sets` are the `/study/` keys.
Plan plan_accuracy(const Scene& scene, const std::map<std::string, ojson>& study_sets);
/// Plans the stability matrix of `scene`.
Plan plan_stability(const Scene& scene, const std::map<std::string, ojson>& study_sets);
/// The command that plans `plan` again, for the Markdown files: `octocut study KIND SCENE --out DIR`, the user's
/// scene overrides and the `/study/` keys as given.
std::string reproduce_command(const Plan& plan);
/// Splits `/study/KEY=JSON` entries off `sets` (the rest stay); throws std::invalid_argument for a bad value.
std::map<std::string, ojson> take_study_sets(std::vector<std::string>& sets);
/// The shell command line of case `c` writing into `out_dir/cases/<id>` (single-quoted arguments).
std::string case_command(const Plan& plan, const Case& c, const fs::path& out_dir);
/// The argument vector of that command (no shell).
std::vector<std::string> case_argv(const Plan& plan, const Case& c, const fs::path& out_dir);
ojson plan_json(const Plan& plan, const fs::path& out_dir);
Plan plan_from_json(const ojson& j, const std::string& file);
/// Largest edge of the object's bounding box (box, or the mesh's vertices times scale), m; and its bounds.
std::array<Vec3d, 2> object_bounds(const Scene& scene);
/// The `elements` a build knows: "trilinear" always, "bbar" when the schema has object.material.element.
std::vector<std::string> available_elements(const std::string& scene_path);

// ---- running (study_runner.cpp) ----
/// Runs the cases, `jobs` at a time, each as a child process; stdout and stderr go to cases/<id>/log.txt. Returns
/// the number of cases that exited with a code other than 0 and 1 (1: the run failed but wrote its report).
int run_cases(const Plan& plan, const fs::path& out_dir, int jobs, bool quiet);

// ---- reference (study_reference.cpp) ----
/// Reads an octocut reference file {"probes": {name: [ux, uy, uz]}}; every name must be a probe of `scene`.
ojson read_reference_file(const std::string& path, const Scene& scene);
/// Exports the scene as a CalculiX deck on the uniform mesh at `level`, runs ccx, and returns the probes'
/// displacements (trilinear interpolation in the C3D8 mesh). Throws std::invalid_argument when the scene is not a
/// static box scene on a grid-aligned box, std::runtime_error when ccx is missing or fails.
ojson ccx_reference(const Scene& scene, int level, const fs::path& work_dir);

// ---- collect (study_accuracy.cpp, study_stability.cpp) ----
int collect_accuracy(const Plan& plan, const std::vector<fs::path>& dirs, const fs::path& out, bool quiet);
int collect_stability(const Plan& plan, const std::vector<fs::path>& dirs, const fs::path& out, bool quiet);
/// The report of case `id` in the first dir that has one; null when none has it.
ojson find_report(const std::vector<fs::path>& dirs, const std::string& id, fs::path* case_dir = nullptr);
/// Vertices of a binary PLY written by encode_ply_binary (float32), m.
std::vector<Vec3d> read_ply_vertices(const fs::path& path);

// ---- output (study_output.cpp) ----
/// A CSV field: quoted when it holds a comma, quote or newline.
std::string csv_field(const std::string& s);
/// A number as the shortest text that reads back to it ("" for NaN).
std::string num_text(double v);
/// Runs gnuplot on `script` (written next to `png`); returns "" or a warning when no plotter ran.
std::string run_gnuplot(const std::string& script, const fs::path& png);
/// "cpu, N threads, calibration X ms" as `octocut bench` measures it.
ojson machine_json();

}  // namespace octocut::engine::study
