// What the study's collectors share: reports and surfaces of the cases, CSV text, the plotter, the machine.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <thread>

#include "octocut/engine/bench/bench.hpp"
#include "octocut/engine/io/io.hpp"
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
  // The header of encode_ply_binary: "element vertex N", float x y z, then the binary body.
  const std::string bytes = read_file(path);
  const std::size_t end = bytes.find("end_header\n");
  if (bytes.rfind("ply\n", 0) != 0 || end == std::string::npos)
    throw std::invalid_argument(path.string() + ": not a binary PLY written by octocut");
  const std::string header = bytes.substr(0, end);
  const std::size_t at = header.find("element vertex ");
  if (at == std::string::npos || header.find("property float x") == std::string::npos)
    throw std::invalid_argument(path.string() + ": no float vertex element");
  const std::size_t n = std::stoul(header.substr(at + 15));
  const std::size_t body = end + 11;
  if (bytes.size() < body + n * 12) throw std::invalid_argument(path.string() + ": truncated");
  std::vector<Vec3d> v(n);
  for (std::size_t i = 0; i < n; ++i) {
    float f[3];
    std::memcpy(f, bytes.data() + body + 12 * i, 12);  // little-endian float32, as the machines that write them
    v[i] = {double(f[0]), double(f[1]), double(f[2])};
  }
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
