// What the study's collectors share: reports and surfaces of the cases, CSV text, the plotter, the machine.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <thread>

#include "octocut/engine/bench/bench.hpp"
#include "octocut/engine/io/io.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "io/mesh_ply.hpp"
#include "study_internal.hpp"

namespace octocut::engine::study {

ojson find_report(const std::vector<fs::path>& dirs, const std::string& id, fs::path* case_dir) {
  for (const fs::path& d : dirs) {
    const fs::path dir = d / "cases" / id;
    if (!fs::exists(dir / "report.json")) continue;
    if (case_dir) *case_dir = dir;
    try {
      return ojson::parse(read_file(dir / "report.json"));
    } catch (const nlohmann::json::exception& e) {
      throw std::invalid_argument((dir / "report.json").string() + ": not JSON: " + e.what());
    }
  }
  return nullptr;
}

std::vector<Vec3d> read_ply_vertices(const fs::path& path) {
  // The vertices as written (octocut writes float64 PLY by default, so the field error has no float32 floor), in file
  // order: a case's rest and final surfaces share their vertex numbering.
  PlyContents ply;
  try {
    ply = decode_ply(read_file(path), path.string());
  } catch (const MeshError& e) {
    throw std::invalid_argument(e.what());
  }
  std::vector<Vec3d> v;
  v.reserve(ply.positions.size());
  for (const sim::Vec3& p : ply.positions) v.push_back({p.x(), p.y(), p.z()});
  return v;
}

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

std::string num_text(double v) {
  if (!std::isfinite(v)) return "";
  char b[32];
  for (int p = 6; p <= 17; ++p) {
    std::snprintf(b, sizeof b, "%.*g", p, v);
    if (std::strtod(b, nullptr) == v) break;
  }
  return b;
}

std::string run_gnuplot(const std::string& script, const fs::path& png) {
  const fs::path gp = png.parent_path() / (png.stem().string() + ".gp");
  write_file_atomic(gp, script);
  if (std::system("command -v gnuplot >/dev/null 2>&1") != 0)
    return "no plotter: gnuplot is not installed (Debian gnuplot-nox; scripts/setup installs it), so " +
           png.filename().string() + " was not drawn; its script is " + gp.filename().string();
  // gnuplot writes to a temporary file, renamed into place when it succeeded (outputs appear whole or not at all).
  const fs::path tmp = png.parent_path() / (png.filename().string() + ".tmp");
  const std::string cmd = "cd '" + png.parent_path().string() + "' && gnuplot -e \"out='" + tmp.filename().string() +
                          "'\" '" + gp.filename().string() + "' 2>'" + png.stem().string() + ".gnuplot.log'";
  if (std::system(cmd.c_str()) != 0 || !fs::exists(tmp))
    return "gnuplot failed on " + gp.filename().string() + " (see " + png.stem().string() + ".gnuplot.log); " +
           png.filename().string() + " was not drawn";
  fs::rename(tmp, png);
  fs::remove(png.parent_path() / (png.stem().string() + ".gnuplot.log"));
  return "";
}

ojson machine_json() {
  return {{"cpu", cpu_name()},
          {"threads", int(std::thread::hardware_concurrency())},
          {"calibration_ms", calibration_ms(9)},
          {"calibration_note", "the median wall time of octocut bench's calibration kernel (two threads), measured "
                               "when the study was collected; timings from another machine scale by the ratio"}};
}

}  // namespace octocut::engine::study
