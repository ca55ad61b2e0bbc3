// The stability matrix's collector: per cell finite, bounded, energy, recoveries, volume under the crush, cuts
// skipped; stability.csv, stability.json (octocut.stability/1), stability.png (one heatmap per scenario) and
// stability.md. Exit 1 lists the cells that are not finite or not bounded.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "octocut/engine/io/io.hpp"
#include "study_internal.hpp"

namespace octocut::engine::study {

namespace {

// Verdicts, worst last; the heatmap's colours follow this order.
const std::vector<std::string> kVerdicts = {"ok",           "recovered",  "failed steps", "energy rises",
                                            "not bounded", "not finite", "missing"};

// A relative rise of the energy below this (times its scale) is round-off, not a rise.
constexpr double kEnergyRelTol = 1e-6;

struct Cell {
  const Case* c = nullptr;
  std::string status = "missing";
  bool finite = false, bounded = false, energy_ok = true;
  double max_displacement_m = NAN, energy_rise_j = NAN, energy_scale_j = NAN, volume_change = NAN;
  double min_volume_change = NAN, ms_per_step = NAN, contact_work_j = NAN;
  long energy_steps = 0, recoveries = 0, failed_steps = 0, cuts_ok = 0, cuts_skipped = 0, cuts_noop = 0;
  int verdict = 6;
};

double num_or_nan(const ojson& j) { return j.is_number() ? j.get<double>() : NAN; }

// Judges one cell from its report.
Cell judge(const Case& c, const ojson& rep, double size) {
  Cell k;
  k.c = &c;
  if (rep.is_null()) return k;
  k.status = rep.at("status");
  const ojson& st = rep.at("stability");
  const ojson& tr = st.value("track", ojson::object());
  k.max_displacement_m = num_or_nan(tr.value("max_displacement_m", ojson(nullptr)));
  k.energy_rise_j = num_or_nan(tr.value("energy_rise_j", ojson(nullptr)));
  k.energy_scale_j = num_or_nan(tr.value("energy_scale_j", ojson(nullptr)));
  k.energy_steps = tr.value("energy_steps", 0L);
  k.contact_work_j = num_or_nan(tr.value("contact_work_j", ojson(nullptr)));
  k.volume_change = num_or_nan(tr.value("volume_change", ojson(nullptr)));
  k.min_volume_change = num_or_nan(tr.value("min_volume_change", ojson(nullptr)));
  k.recoveries = st.at("recoveries");
  k.failed_steps = st.at("failed_steps");
  k.ms_per_step = rep.at("timing_ms").at("step").at("median");
  bool probes_finite = true;
  for (const auto& [name, p] : rep.at("probes").items())
    for (const ojson& x : p.at("displacement")) probes_finite = probes_finite && x.is_number();
  k.finite = st.at("finite").get<bool>() && probes_finite && std::isfinite(k.max_displacement_m) &&
             std::isfinite(k.energy_scale_j);
  k.bounded = k.finite && k.max_displacement_m <= 2.0 * size;
  k.energy_ok = !k.finite || k.energy_rise_j <= kEnergyRelTol * k.energy_scale_j + 1e-15;
  for (const ojson& cut : rep.at("cuts")) {
    const std::string s = cut.at("status");
    (s == "ok" ? k.cuts_ok : s == "skipped" ? k.cuts_skipped : k.cuts_noop) += 1;
  }
  k.verdict = !k.finite ? 5 : !k.bounded ? 4 : !k.energy_ok ? 3 : k.failed_steps > 0 ? 2 : k.recoveries > 0 ? 1 : 0;
  return k;
}

ojson nj(double v) { return std::isfinite(v) ? ojson(v) : ojson(nullptr); }

ojson cell_json(const Cell& k) {
  ojson c = {{"id", k.c->id}};
  for (const auto& [key, v] : k.c->params.items()) c[key] = v;
  return {{"case", c},
          {"status", k.status},
          {"verdict", kVerdicts[std::size_t(k.verdict)]},
          {"finite", k.finite},
          {"bounded", k.bounded},
          {"max_displacement_m", nj(k.max_displacement_m)},
          {"energy", {{"ok", k.energy_ok}, {"rise_j", nj(k.energy_rise_j)}, {"scale_j", nj(k.energy_scale_j)},
                      {"steps_checked", k.energy_steps}, {"contact_work_j", nj(k.contact_work_j)}}},
          {"recoveries", k.recoveries},
          {"failed_steps", k.failed_steps},
          {"volume_change", nj(k.volume_change)},
          {"min_volume_change", nj(k.min_volume_change)},
          {"cuts", {{"ok", k.cuts_ok}, {"skipped", k.cuts_skipped}, {"no_op", k.cuts_noop}}},
          {"ms_per_step", nj(k.ms_per_step)}};
}

std::string csv_text(const std::vector<Cell>& cells) {
  std::ostringstream s;
  s << "case,scenario,young_modulus,poisson_ratio,dt,status,verdict,finite,bounded,max_displacement_m,energy_ok,"
       "energy_rise_j,energy_scale_j,contact_work_j,recoveries,failed_steps,volume_change,min_volume_change,cuts_ok,cuts_skipped,"
       "cuts_no_op,ms_per_step\n";
  for (const Cell& k : cells) {
    const ojson& p = k.c->params;
    s << csv_field(k.c->id) << ',' << p["scenario"].get<std::string>() << ',' << num_text(p["young_modulus"]) << ','
      << num_text(p["poisson_ratio"]) << ',' << num_text(p["dt"]) << ',' << k.status << ','
      << csv_field(kVerdicts[std::size_t(k.verdict)]) << ',' << k.finite << ',' << k.bounded << ','
      << num_text(k.max_displacement_m) << ',' << k.energy_ok << ',' << num_text(k.energy_rise_j) << ','
      << num_text(k.energy_scale_j) << ',' << num_text(k.contact_work_j) << ',' << k.recoveries << ',' << k.failed_steps << ','
      << num_text(k.volume_change) << ',' << num_text(k.min_volume_change) << ',' << k.cuts_ok << ','
      << k.cuts_skipped << ',' << k.cuts_noop << ',' << num_text(k.ms_per_step) << '\n';
  }
  return s.str();
}

// Index of `v` in the plan's list `key`.
int index_of(const ojson& list, const ojson& v) {
  for (std::size_t i = 0; i < list.size(); ++i)
    if (list[i] == v) return int(i);
  return -1;
}

// A modulus as 1e+04.
std::string exp_text(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.0e", v);
  return b;
}

// The heatmaps: one panel per scenario, (E, nu) across, dt up; data files stability_<scenario>.dat.
std::string plot_script(const Plan& plan, const std::vector<Cell>& cells, const fs::path& out) {
  const ojson& s = plan.settings;
  const ojson &E = s["young_modulus"], &nu = s["poisson_ratio"], &dt = s["dt"], &scen = s["scenarios"];
  const int nx = int(E.size() * nu.size());
  for (const ojson& sc : scen) {
    std::ostringstream d;
    for (const Cell& k : cells) {
      if (k.c->params["scenario"] != sc) continue;
      const int x = index_of(E, k.c->params["young_modulus"]) * int(nu.size()) + index_of(nu, k.c->params["poisson_ratio"]);
      d << x << ' ' << index_of(dt, k.c->params["dt"]) << ' ' << k.verdict << '\n';
    }
    write_file_atomic(out / ("stability_" + sc.get<std::string>() + ".dat"), d.str());
  }
  std::ostringstream g;
  g << "set terminal pngcairo size 1400," << 150 + 260 * scen.size() << " font 'sans,10'\nset output out\n"
    << "set multiplot layout " << scen.size() << ",1 title \"Stability matrix: " << fs::path(plan.scene).stem().string()
    << " (level " << s["level"] << ", " << num_text(s["duration"]) << " s per cell)\" font 'sans,13' noenhanced\n"
    << "set palette defined (0 '#228833', 1 '#99cc66', 2 '#ccbb44', 3 '#ee7733', 4 '#cc3311', 5 '#661100', 6 '#bbbbbb')\n"
    << "set palette maxcolors 7\nset cbrange [-0.5:6.5]\nset cbtics (";
  for (std::size_t v = 0; v < kVerdicts.size(); ++v) g << (v ? ", " : "") << "'" << kVerdicts[v] << "' " << v;
  g << ")\nset xrange [-0.5:" << nx - 0.5 << "]\nset yrange [-0.5:" << dt.size() - 0.5 << "]\nset xtics (";
  for (std::size_t i = 0; i < E.size(); ++i)
    for (std::size_t j = 0; j < nu.size(); ++j)
      g << (i + j ? ", " : "") << "'E " << exp_text(E[i]) << " Pa, ν " << num_text(nu[j]) << "' " << i * nu.size() + j;
  g << ") rotate by 35 right font 'sans,7'\nset ytics (";
  for (std::size_t i = 0; i < dt.size(); ++i) g << (i ? ", " : "") << "'" << num_text(dt[i]) << "' " << i;
  g << ")\nset ylabel 'time step Δt (s)'\nset xlabel 'Young modulus E (Pa) and Poisson ratio ν'\nunset key\n";
  for (const ojson& sc : scen)
    g << "set title 'scenario: " << sc.get<std::string>() << "'\nplot 'stability_" << sc.get<std::string>()
      << ".dat' using 1:2:3 with image title '" << sc.get<std::string>() << "'\n";
  g << "unset multiplot\n";
  (void)cells;
  return g.str();
}

std::string markdown(const Plan& plan, const std::vector<Cell>& cells, const std::vector<const Cell*>& broken,
                     const ojson& machine, const std::vector<std::string>& warnings) {
  const ojson& s = plan.settings;
  std::ostringstream m;
  m << "# Stability matrix: " << fs::path(plan.scene).filename().string() << "\n\n"
    << "Uniform octree level " << s["level"] << ", " << num_text(s["duration"]) << " s simulated per cell (handles move "
    << "over the first half, then hold), dynamic. Object size (largest bounding-box edge) "
    << num_text(plan.object_size_m) << " m.";
  if (s.contains("element"))  // plans written before the key have none
    m << " Hexahedra: **" << (s["element"] == "trilinear" ? "trilinear" : "B-bar") << "** (`object.material.element` "
      << s["element"].dump() << ").";
  m << "\n\n";
  if (!plan.sets.empty()) {
    m << "Scene overrides (`--set`), in every cell:";
    for (const std::string& set : plan.sets) m << " `" << set << "`";
    m << ".\n\n";
  }
  m << "Scenarios: **sag** (clamped at x min, gravity), **crush** (z max pushed down by 95% of the height, z min "
       "fixed), **twist** (z max turned 360° about z, z min fixed), **punch** (100 cylinder bites at one spot, each "
       "0.5% of the height deeper), **press** (a kinematic rigid plate wider than the object, from touching the top face "
       "down by 50% of the height, z min fixed; penalty contact with the scene's friction; contact starts in the "
       "first step in which the plate penetrates). ";
  for (const auto& [name, why] : s["skipped_scenarios"].items())
    m << "Not run: **" << name << "**: " << why.get<std::string>() << ". ";
  m << "\n\nPer cell: **finite** (state, probes, energy); **bounded** (largest DOF displacement over the run ≤ 2× the "
       "object's size); **energy** (over a step in which no handle moves and no cut runs, the total mechanical "
       "energy, kinetic + elastic + gravitational, plus the energy the contacts' penalty springs take up, never rises "
       "by more than the work the rigid shapes put in through contact, the sum of F · v_rigid Δt over the contacts, "
       "plus " << kEnergyRelTol << " of its scale); "
       "**recovered** (steps retried with a halved Δt), **failed steps** (reset after the smallest Δt failed); "
       "volume change of the deformed material (crush); cuts skipped. The verdict is the worst that applies, in the "
       "order ok < recovered < failed steps < energy rises < not bounded < not finite.\n\n"
    << "**Machine:** " << machine["cpu"].get<std::string>() << ", calibration kernel " << machine["calibration_ms"].get<double>()
    << " ms.\n\n![stability heatmaps](stability.png)\n\n";
  // Counts per scenario and verdict.
  m << "| scenario |";
  for (const std::string& v : kVerdicts) m << " " << v << " |";
  m << "\n|---|";
  for (std::size_t i = 0; i < kVerdicts.size(); ++i) m << "---:|";
  m << "\n";
  for (const ojson& sc : s["scenarios"]) {
    m << "| " << sc.get<std::string>() << " |";
    for (std::size_t v = 0; v < kVerdicts.size(); ++v)
      m << " " << std::count_if(cells.begin(), cells.end(), [&](const Cell& k) {
        return k.c->params["scenario"] == sc && k.verdict == int(v);
      }) << " |";
    m << "\n";
  }
  m << "\n**Cells not finite or not bounded:** " << (broken.empty() ? "none." : "") << "\n";
  for (const Cell* k : broken) m << "- `" << k->c->id << "`: " << kVerdicts[std::size_t(k->verdict)] << "\n";
  m << "\n## Every cell\n\n| cell | verdict | max |u| (m) | energy rise (J) | recoveries | failed | volume change | cuts "
       "skipped | ms/step |\n|---|---|---:|---:|---:|---:|---:|---:|---:|\n";
  auto f = [](double v) {
    if (!std::isfinite(v)) return std::string("—");
    char b[32];
    std::snprintf(b, sizeof b, "%.3g", v);
    return std::string(b);
  };
  for (const Cell& k : cells)
    m << "| `" << k.c->id << "` | " << kVerdicts[std::size_t(k.verdict)] << " | " << f(k.max_displacement_m) << " | "
      << f(k.energy_rise_j) << " | " << k.recoveries << " | " << k.failed_steps << " | " << f(k.volume_change) << " | "
      << k.cuts_skipped << " | " << f(k.ms_per_step) << " |\n";
  if (!warnings.empty()) {
    m << "\n**Warnings:**\n";
    for (const std::string& w : warnings) m << "- " << w << "\n";
  }
  m << "\nReproduce: `" << reproduce_command(plan) << "`; each cell's command is in `study_plan.json`.\n";
  return m.str();
}

}  // namespace

int collect_stability(const Plan& plan, const std::vector<fs::path>& dirs, const fs::path& out, bool quiet) {
  std::vector<Cell> cells;
  for (const Case& c : plan.cases) cells.push_back(judge(c, find_report(dirs, c.id), plan.object_size_m));
  std::vector<const Cell*> broken;
  std::vector<std::string> warnings;
  for (const Cell& k : cells) {
    if (k.verdict >= 4) broken.push_back(&k);
    if (k.status == "missing") warnings.push_back("cell " + k.c->id + ": no report found");
  }
  const std::string plot_warning = run_gnuplot(plot_script(plan, cells, out), out / "stability.png");
  if (!plot_warning.empty()) {
    warnings.push_back(plot_warning);
    std::fprintf(stderr, "octocut: warning: %s\n", plot_warning.c_str());
  }
  const ojson machine = machine_json();
  ojson j;
  j["schema"] = "octocut.stability/1";
  j["kind"] = "stability";
  j["scene"] = plan.scene;
  j["sets"] = plan.sets;
  j["settings"] = plan.settings;
  j["object_size_m"] = plan.object_size_m;
  j["criteria"] = {{"bounded", "max displacement <= 2 x object_size_m"},
                   {"energy", "over a step without handle motion or cut: rise of kinetic + elastic + gravitational + contact "
                              "penalty energy - contact work of the rigid shapes <= 1e-6 x energy scale + 1e-15 J"},
                   {"verdicts", kVerdicts}};
  j["machine"] = machine;
  j["rows"] = ojson::array();
  for (const Cell& k : cells) j["rows"].push_back(cell_json(k));
  j["not_finite_or_not_bounded"] = ojson::array();
  for (const Cell* k : broken) j["not_finite_or_not_bounded"].push_back(k->c->id);
  j["warnings"] = warnings;
  write_file_atomic(out / "stability.json", j.dump(2) + "\n");
  write_file_atomic(out / "stability.csv", csv_text(cells));
  write_file_atomic(out / "stability.md", markdown(plan, cells, broken, machine, warnings));
  for (const Cell* k : broken)
    std::fprintf(stderr, "octocut: stability: %s is %s\n", k->c->id.c_str(), kVerdicts[std::size_t(k->verdict)].c_str());
  if (!quiet) std::printf("stability: %zu cells, %zu not finite or not bounded; wrote %s\n", cells.size(), broken.size(),
                          (out / "stability.md").c_str());
  return broken.empty() ? 0 : 1;
}

}  // namespace octocut::engine::study
