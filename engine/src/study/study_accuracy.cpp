// The accuracy study's collector: probe and field errors of every case against the reference, cost, the Pareto
// front; study.csv, study.json (octocut.study/1), pareto.png and study.md.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "octocut/engine/io/io.hpp"
#include "study_internal.hpp"

namespace octocut::engine::study {

namespace {

// One case as collected.
struct Row {
  const Case* c = nullptr;
  std::string status = "missing";       // "ok" | "failed" | "missing" (no report found)
  std::map<std::string, Vec3d> probes;  // displacement, m
  std::vector<Vec3d> field;             // displacement of S's rest vertices, m (|V|); empty without surfaces
  double ms_per_step = NAN, wall_s = NAN;
  long elements = 0, dofs = 0;
  std::map<std::string, double> error;  // per probe, relative
  double error_max = NAN, field_l2 = NAN;
  bool pareto = false;
};

double norm(const Vec3d& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }
Vec3d sub(const Vec3d& a, const Vec3d& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3d as_vec(const ojson& j) {
  Vec3d v{};
  for (std::size_t d = 0; d < 3; ++d) v[d] = j.at(d).is_number() ? j.at(d).get<double>() : NAN;
  return v;
}

// Reads every case's report and surfaces.
std::vector<Row> load_rows(const Plan& plan, const std::vector<fs::path>& dirs) {
  std::vector<Row> rows;
  for (const Case& c : plan.cases) {
    Row r;
    r.c = &c;
    fs::path dir;
    const ojson rep = find_report(dirs, c.id, &dir);
    if (!rep.is_null()) {
      r.status = rep.at("status");
      for (const auto& [name, p] : rep.at("probes").items()) r.probes[name] = as_vec(p.at("displacement"));
      r.ms_per_step = rep.at("timing_ms").at("step").at("median");
      r.wall_s = rep.at("wall_time_s");
      r.elements = rep.at("counts").at("elements");
      r.dofs = rep.at("counts").at("dofs");
      if (fs::exists(dir / "surface_final.ply") && fs::exists(dir / "surface_rest.ply")) {
        const std::vector<Vec3d> rest = read_ply_vertices(dir / "surface_rest.ply");
        const std::vector<Vec3d> fin = read_ply_vertices(dir / "surface_final.ply");
        if (rest.size() == fin.size())
          for (std::size_t i = 0; i < rest.size(); ++i) r.field.push_back(sub(fin[i], rest[i]));
      }
    }
    rows.push_back(std::move(r));
  }
  return rows;
}

// The uniform, direct-solver, scene-dt cases of `element` with a report, by level.
std::vector<const Row*> uniform_sequence(const std::vector<Row>& rows, const std::string& element) {
  std::vector<const Row*> seq;
  for (const Row& r : rows) {
    const ojson& p = r.c->params;
    if (r.status == "ok" && p["mesh"] == "uniform" && p["element"] == element && p["solver"] == "cholmod" &&
        r.c->id.find("-dt") == std::string::npos)
      seq.push_back(&r);
  }
  std::sort(seq.begin(), seq.end(), [](const Row* a, const Row* b) { return a->c->params["level"] < b->c->params["level"]; });
  return seq;
}

// Richardson extrapolation of one element's uniform sequence (the finest three levels u0, u1, u2, h halving each
// level), per probe. With d1 = u1 - u0 and d2 = u2 - u1, the sequence converges monotonically when the two changes
// point the same way (d1 . d2 > 0) and shrink (|d1| > |d2|): then p = log2(|d1| / |d2|) and u = u2 + d2 / (2^p - 1),
// and the estimated error of u2 is |u - u2| / |u|. Otherwise (the changes point opposite ways: the sequence
// oscillates, and extrapolating along d2 would move away from the limit; or they grow) extrapolation is refused:
// the finest run is the reference, and its estimated error is the last refinement's change |d2| / |u2| (zero only
// when the finest two runs agree exactly).
// With two levels p = 2 is assumed; with one the finest run is the reference and the error is unknown (null).
// Returns the reference entry; "extrapolated" counts the probes that were.
ojson richardson(const std::vector<const Row*>& seq, const std::string& element) {
  ojson ref = {{"kind", "richardson"}, {"element", element}, {"levels", ojson::array()}, {"probes", ojson::object()},
               {"order", ojson::object()}, {"estimated_error", ojson::object()}, {"notes", ojson::array()},
               {"extrapolated", 0}};
  if (seq.empty()) {
    ref["notes"].push_back("no uniform run of element " + element + " finished; no reference");
    return ref;
  }
  const std::size_t n = seq.size(), k0 = n >= 3 ? n - 3 : 0;
  for (std::size_t k = k0; k < n; ++k) ref["levels"].push_back(seq[k]->c->params["level"]);
  int extrapolated = 0;
  for (const auto& [name, u2] : seq.back()->probes) {
    Vec3d u = u2;
    double p = NAN, error = NAN;
    if (n >= 2) {
      const Vec3d d2 = sub(u2, seq[n - 2]->probes.at(name));
      p = 2.0;
      if (n >= 3) {
        const Vec3d d1 = sub(seq[n - 2]->probes.at(name), seq[n - 3]->probes.at(name));
        const double same_way = d1[0] * d2[0] + d1[1] * d2[1] + d1[2] * d2[2];
        const double ratio = norm(d1) / norm(d2);
        p = same_way > 0.0 && std::isfinite(ratio) && ratio > 1.0 ? std::clamp(std::log2(ratio), 0.5, 6.0) : NAN;
        if (norm(d2) == 0.0)
          ref["notes"].push_back("probe " + name + ": the " + element +
                                 " sequence's finest two runs agree exactly; the finest run is the reference");
        else if (!std::isfinite(p))
          ref["notes"].push_back(
              "probe " + name + ": the " + element + " sequence " +
              (same_way <= 0.0 ? "oscillates (its last two changes point opposite ways)"
                               : "does not converge (its last change is not the smaller)") +
              "; Richardson extrapolation is refused: the finest run is the reference, its estimated error the last "
              "refinement's change");
      }
      if (std::isfinite(p)) {
        for (std::size_t d = 0; d < 3; ++d) u[d] = u2[d] + d2[d] / (std::pow(2.0, p) - 1.0);
        error = norm(sub(u, u2)) / norm(u);
        ++extrapolated;
      } else {
        error = norm(d2) == 0.0 ? 0.0 : norm(d2) / norm(u2);
      }
    }
    if (n == 2) ref["notes"].push_back("two uniform levels only: order 2 assumed for probe " + name);
    if (n == 1) ref["notes"].push_back("one uniform level only: the finest run is the reference for " + name);
    ref["probes"][name] = u;
    ref["order"][name] = std::isfinite(p) ? ojson(p) : ojson(nullptr);
    ref["estimated_error"][name] = std::isfinite(error) ? ojson(error) : ojson(nullptr);
  }
  ref["extrapolated"] = extrapolated;
  return ref;
}

// The reference of the study: the plan's (a file or ccx), or the Richardson reference of the element whose worst
// estimated error (over the probes) is the smallest: the one that converged best. `finest` receives the finest run of
// the reference's element, against which the field error is measured.
ojson resolve_reference(const Plan& plan, const std::vector<Row>& rows, const Row*& finest) {
  const std::vector<std::string> elements = plan.settings.at("elements");
  ojson ref = plan.reference;
  std::string element = elements.front();
  if (ref.at("kind") == "richardson") {
    ojson best;
    double best_err = INFINITY;
    ojson all = ojson::object();
    for (const std::string& e : elements) {
      ojson r = richardson(uniform_sequence(rows, e), e);
      double worst = 0.0;
      for (const auto& [name, v] : r["estimated_error"].items())
        worst = v.is_number() ? std::max(worst, v.get<double>()) : INFINITY;
      if (!r["probes"].empty() && worst < best_err) {
        best_err = worst;
        best = r;
        element = e;
      }
      all[e] = r;
    }
    ref = best.is_null() ? all[elements.front()] : best;
    ref["by_element"] = all;
  }
  const std::vector<const Row*> seq = uniform_sequence(rows, element);
  finest = seq.empty() ? nullptr : seq.back();
  ref["field_reference"] = finest ? ojson(finest->c->id) : ojson(nullptr);
  return ref;
}

// Probe errors and the field error of every row; then the Pareto front of (error_max, ms_per_step).
void compute_errors(std::vector<Row>& rows, const ojson& ref, const Row* finest) {
  for (Row& r : rows) {
    if (r.status == "missing") continue;
    double worst = 0.0;
    for (const auto& [name, v] : ref.at("probes").items()) {
      const Vec3d u_ref = as_vec(v);
      const auto it = r.probes.find(name);
      const double e = it == r.probes.end() ? NAN : norm(sub(it->second, u_ref)) / norm(u_ref);
      r.error[name] = e;
      worst = std::isfinite(e) && std::isfinite(worst) ? std::max(worst, e) : NAN;
    }
    r.error_max = ref.at("probes").empty() ? NAN : worst;
    if (finest && r.field.size() == finest->field.size() && !r.field.empty()) {
      double num = 0.0, den = 0.0;
      for (std::size_t i = 0; i < r.field.size(); ++i) {
        num += std::pow(norm(sub(r.field[i], finest->field[i])), 2);
        den += std::pow(norm(finest->field[i]), 2);
      }
      r.field_l2 = std::sqrt(num / den);
    }
  }
  for (Row& a : rows) {
    if (!std::isfinite(a.error_max) || !std::isfinite(a.ms_per_step)) continue;
    a.pareto = std::none_of(rows.begin(), rows.end(), [&](const Row& b) {
      return &b != &a && std::isfinite(b.error_max) && b.error_max <= a.error_max && b.ms_per_step <= a.ms_per_step &&
             (b.error_max < a.error_max || b.ms_per_step < a.ms_per_step);
    });
  }
}

ojson num_json(double v) { return std::isfinite(v) ? ojson(v) : ojson(nullptr); }

ojson row_json(const Row& r) {
  ojson c = {{"id", r.c->id}};
  for (const auto& [k, v] : r.c->params.items()) c[k] = v;
  ojson probes = ojson::object();
  for (const auto& [name, e] : r.error) probes[name] = num_json(e);
  return {{"case", c},
          {"status", r.status},
          {"error", {{"probes", probes}, {"max", num_json(r.error_max)}, {"field_l2", num_json(r.field_l2)}}},
          {"ms_per_step", num_json(r.ms_per_step)},
          {"wall_s", num_json(r.wall_s)},
          {"elements", r.elements},
          {"dofs", r.dofs},
          {"pareto", r.pareto}};
}

std::string csv_text(const std::vector<Row>& rows, const std::vector<std::string>& probe_names) {
  std::ostringstream s;
  s << "case,mesh,level,element,solver,tolerance,dt,status,elements,dofs,ms_per_step,wall_s,error_max,field_l2";
  for (const std::string& n : probe_names) s << ",error_" << csv_field(n);
  s << ",pareto\n";
  for (const Row& r : rows) {
    const ojson& p = r.c->params;
    s << csv_field(r.c->id) << ',' << p["mesh"].get<std::string>() << ',' << p["level"].get<int>() << ','
      << p["element"].get<std::string>() << ',' << p["solver"].get<std::string>() << ','
      << (p["tolerance"].is_null() ? "" : num_text(p["tolerance"])) << ',' << num_text(p["dt"]) << ',' << r.status
      << ',' << r.elements << ',' << r.dofs << ',' << num_text(r.ms_per_step) << ',' << num_text(r.wall_s) << ','
      << num_text(r.error_max) << ',' << num_text(r.field_l2);
    for (const std::string& n : probe_names) s << ',' << (r.error.count(n) ? num_text(r.error.at(n)) : "");
    s << ',' << (r.pareto ? "true" : "false") << '\n';
  }
  return s.str();
}

// The reference as one sentence for the Markdown and the plot.
std::string reference_sentence(const ojson& ref) {
  const std::string kind = ref.at("kind");
  if (kind == "file") return "the probe displacements in " + ref.at("source").get<std::string>() + " (another code)";
  if (kind == "ccx")
    return "CalculiX (ccx) C3D8 on the same uniform mesh, level " + std::to_string(ref.at("level").get<int>()) +
           ", with the same clamps and loads";
  std::string levels;
  for (const ojson& l : ref.at("levels")) levels += (levels.empty() ? "" : ", ") + std::to_string(l.get<int>());
  const std::string element = ref.at("element");
  const int extrapolated = ref.value("extrapolated", 0), probes = int(ref.at("probes").size());
  const std::string how = extrapolated == probes ? "Richardson extrapolation of the uniform " + element + " sequence"
                          : extrapolated == 0
                              ? "the finest uniform " + element + " run: its sequence converges monotonically at "
                                "no probe, so Richardson extrapolation is refused"
                              : "Richardson extrapolation of the uniform " + element + " sequence at " +
                                    std::to_string(extrapolated) + " of " + std::to_string(probes) +
                                    " probes, the finest run at the others";
  return how + " (levels " + levels + ", h halving per level; of the elements, the one whose estimated error is the "
         "smallest), not an independent solution";
}

// The reference in a few words, for the plot's title.
std::string reference_title(const ojson& ref) {
  if (ref.at("kind") != "richardson") return ref.at("kind");
  const int extrapolated = ref.value("extrapolated", 0), probes = int(ref.at("probes").size());
  const std::string element = ref.at("element");
  return extrapolated == probes ? "Richardson extrapolation (" + element + ")"
         : extrapolated == 0    ? "finest uniform " + element + " run (Richardson refused)"
                                : "Richardson extrapolation (" + element + ") at " + std::to_string(extrapolated) +
                                   " of " + std::to_string(probes) + " probes";
}

std::string plot_script(const ojson& ref, const std::string& name, const std::vector<Row>& rows) {
  // Room on the right and above for the labels (log axes: factors).
  double lo = INFINITY, hi = 0.0, elo = INFINITY, ehi = 0.0;
  for (const Row& r : rows) {
    if (!std::isfinite(r.error_max) || r.error_max <= 0.0 || !std::isfinite(r.ms_per_step)) continue;
    lo = std::min(lo, r.ms_per_step), hi = std::max(hi, r.ms_per_step);
    elo = std::min(elo, r.error_max), ehi = std::max(ehi, r.error_max);
  }
  std::ostringstream g;
  if (hi > 0.0) g << "set xrange [" << lo / 2 << ":" << hi * 8 << "]\nset yrange [" << elo / 2 << ":" << ehi * 3 << "]\n";
  g << "set terminal pngcairo size 1280,860 font 'sans,10'\nset output out\n"
    << "set title \"Accuracy against cost: " << name << "\\nreference: "
    << reference_title(ref)
    << "\" noenhanced\nset logscale xy\nset grid\nset key top right\n"
    << "set xlabel 'median wall time per step (ms)'\n"
    << "set ylabel 'relative probe error |u - u_{ref}| / |u_{ref}| (max over probes)'\n"
    << "set datafile separator ','\n"
    << "plot 'pareto.dat' using 1:2 with points pt 7 ps 1.2 lc rgb '#4477aa' title 'case', \\\n"
    << "     'pareto_front.dat' using 1:2 with linespoints pt 6 ps 2.2 lw 2 lc rgb '#cc3311' title 'Pareto front', \\\n"
    << "     'pareto.dat' using 1:2:3 with labels font 'sans,7' offset 0.6,0.5 left rotate by 20 noenhanced notitle\n";
  return g.str();
}

std::string markdown(const Plan& plan, const std::vector<Row>& rows, const ojson& ref, const ojson& machine,
                     const std::vector<std::string>& probe_names, const std::vector<std::string>& warnings) {
  auto f = [](double v, const char* fmt) {
    if (!std::isfinite(v)) return std::string("—");
    char b[32];
    std::snprintf(b, sizeof b, fmt, v);
    return std::string(b);
  };
  std::ostringstream m;
  m << "# Accuracy study: " << fs::path(plan.scene).filename().string() << "\n\n"
    << "Scene `" << plan.scene << "`";
  for (const std::string& s : plan.sets) m << ", `--set " << s << "`";
  m << ".\n\n**Reference:** " << reference_sentence(ref) << ".\n\n";
  for (const ojson& n : ref.value("notes", ojson::array())) m << "- " << n.get<std::string>() << "\n";
  if (ref.contains("by_element")) {
    // Every element's Richardson entry: the reference's, and the others' as a check on it.
    m << "\n| element | probe | order p | estimated error of the finest run | reference displacement (m) |\n"
         "|---|---|---:|---:|---|\n";
    for (const auto& [element, r] : ref.at("by_element").items())
      for (const auto& [name, u] : r.at("probes").items()) {
        const ojson& p = r.at("order").at(name);
        const ojson& e = r.at("estimated_error").at(name);
        m << "| " << element << (element == ref.at("element") ? " (reference)" : "") << " | " << name << " | "
          << (p.is_number() ? f(p.get<double>(), "%.2f") : "refused") << " | "
          << (e.is_number() ? f(e.get<double>(), "%.3g") : "unknown") << " | [" << f(u.at(0).get<double>(), "%.6g")
          << ", " << f(u.at(1).get<double>(), "%.6g") << ", " << f(u.at(2).get<double>(), "%.6g") << "] |\n";
      }
  }
  m << "\n**Error:** per probe, |u - u_ref| / |u_ref| of its displacement vector; `error_max` is the largest over the "
       "probes (the Pareto front's error). `field_l2` is the root-mean-square difference of the displacement over "
       "S's rest vertices against the finest run (`"
    << (ref["field_reference"].is_null() ? "none" : ref["field_reference"].get<std::string>())
    << "`), divided by that run's RMS displacement (surfaces are float64 PLY, read back exactly).\n\n"
    << "**Machine:** " << machine["cpu"].get<std::string>() << ", " << machine["threads"].get<int>()
    << " hardware threads; calibration kernel " << f(machine["calibration_ms"], "%.3g") << " ms (`octocut bench`'s; "
    << "divide ms/step by it to compare machines).\n\n";
  m << "| case | elements | DOFs | ms/step | wall s | error_max | field_l2 |";
  for (const std::string& n : probe_names) m << " " << n << " |";
  m << " front |\n|---|---:|---:|---:|---:|---:|---:|";
  for (std::size_t i = 0; i < probe_names.size(); ++i) m << "---:|";
  m << ":-:|\n";
  for (const Row& r : rows) {
    m << "| `" << r.c->id << "`" << (r.status == "ok" ? "" : " (" + r.status + ")") << " | " << r.elements << " | "
      << r.dofs << " | " << f(r.ms_per_step, "%.3g") << " | " << f(r.wall_s, "%.3g") << " | "
      << f(r.error_max, "%.3g") << " | " << f(r.field_l2, "%.3g") << " |";
    for (const std::string& n : probe_names) m << " " << f(r.error.count(n) ? r.error.at(n) : NAN, "%.3g") << " |";
    m << (r.pareto ? " ★ |" : " |") << "\n";
  }
  m << "\n**Pareto front** (no other case is both faster per step and more accurate):";
  for (const Row& r : rows)
    if (r.pareto) m << " `" << r.c->id << "`";
  m << "\n\n![error against time per step](pareto.png)\n";
  if (!warnings.empty()) {
    m << "\n**Warnings:**\n";
    for (const std::string& w : warnings) m << "- " << w << "\n";
  }
  m << "\nReproduce: `" << reproduce_command(plan) << "`; the cases' commands are in `study_plan.json`.\n";
  return m.str();
}

}  // namespace

int collect_accuracy(const Plan& plan, const std::vector<fs::path>& dirs, const fs::path& out, bool quiet) {
  std::vector<Row> rows = load_rows(plan, dirs);
  const Row* finest = nullptr;
  const ojson ref = resolve_reference(plan, rows, finest);
  compute_errors(rows, ref, finest);
  std::vector<std::string> probe_names, warnings;
  for (const auto& [name, v] : ref.at("probes").items()) probe_names.push_back(name);
  int missing = 0;
  for (const Row& r : rows) {
    if (r.status == "missing") ++missing;
    if (r.status != "ok") warnings.push_back("case " + r.c->id + ": " + r.status);
  }
  // The plot's data: every case with a positive error, and the front sorted by time.
  std::ostringstream dat, front;
  std::vector<const Row*> on_front;
  for (const Row& r : rows) {
    if (std::isfinite(r.error_max) && r.error_max > 0.0 && std::isfinite(r.ms_per_step))
      dat << num_text(r.ms_per_step) << ',' << num_text(r.error_max) << ',' << r.c->id << '\n';
    if (r.pareto && r.error_max > 0.0) on_front.push_back(&r);
  }
  std::sort(on_front.begin(), on_front.end(), [](const Row* a, const Row* b) { return a->ms_per_step < b->ms_per_step; });
  for (const Row* r : on_front) front << num_text(r->ms_per_step) << ',' << num_text(r->error_max) << '\n';
  if (std::any_of(rows.begin(), rows.end(), [](const Row& r) { return r.error_max == 0.0; }))
    warnings.push_back("cases with zero error (the reference run itself) are left off the log-log plot");
  write_file_atomic(out / "pareto.dat", dat.str());
  write_file_atomic(out / "pareto_front.dat", front.str());
  const std::string name = fs::path(plan.scene).stem().string();
  const std::string plot_warning = run_gnuplot(plot_script(ref, name, rows), out / "pareto.png");
  if (!plot_warning.empty()) {
    warnings.push_back(plot_warning);
    std::fprintf(stderr, "octocut: warning: %s\n", plot_warning.c_str());
  }
  const ojson machine = machine_json();
  // study.json, study.csv, study.md.
  ojson j;
  j["schema"] = "octocut.study/1";
  j["kind"] = "accuracy";
  j["scene"] = plan.scene;
  j["sets"] = plan.sets;
  j["reference"] = ref;
  j["settings"] = plan.settings;
  j["machine"] = machine;
  j["rows"] = ojson::array();
  for (const Row& r : rows) j["rows"].push_back(row_json(r));
  j["front"] = ojson::array();
  for (const Row& r : rows)
    if (r.pareto) j["front"].push_back(r.c->id);
  j["warnings"] = warnings;
  write_file_atomic(out / "study.json", j.dump(2) + "\n");
  write_file_atomic(out / "study.csv", csv_text(rows, probe_names));
  write_file_atomic(out / "study.md", markdown(plan, rows, ref, machine, probe_names, warnings));
  if (!quiet) std::printf("study: %zu cases, %d missing; wrote %s\n", rows.size(), missing, (out / "study.md").c_str());
  return missing > 0 ? 1 : 0;
}

}  // namespace octocut::engine::study
