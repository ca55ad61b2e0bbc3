#pragma once
// `octocut cut` (SPEC §7): one rest-space cut of a surface by a blade, stages 2–3 of the pipeline with a fresh
// material graph, and its report (schema octocut.cut/1).
#include <string>

namespace octocut::engine {

struct CutCommandOptions {
  std::string surface_path;   ///< closed surface mesh (any format load_mesh reads)
  std::string blade_path;     ///< closed, oriented, non-self-intersecting blade mesh
  std::string out_path;       ///< S' is written here, in metres, in the format of the extension
  std::string report_path;    ///< optional octocut.cut/1 report
  double scale = 1.0;         ///< multiplies both inputs' coordinates to get metres
  double cell_size = 0.0;     ///< M's cell size, m; 0 = 1 mm, raised when the object would need more than 2e5 cells
  bool verify = true;         ///< check S' locally after the boolean
  bool ply_float = false;     ///< a .ply output in float32 instead of float64
};

/// What the command did. exit_code: 0 ok or no-op, 1 the cut failed (report written, no mesh), 2 bad input (nothing
/// written).
struct CutCommandResult {
  int exit_code = 0;
  std::string message;  ///< one line for stderr or stdout
};

CutCommandResult run_cut_command(const CutCommandOptions& options);

}  // namespace octocut::engine
