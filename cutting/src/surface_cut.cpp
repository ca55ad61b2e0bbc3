// The local surface boolean S \ B' (SPEC §4 stage 2): the public entry points, and the sequence of its phases
// (surface_cut_phases.hpp). No CGAL here.
//
//  1. find_patch: the faces of S near the blade, from S's FaceGrid (surface_cut_patch.cpp);
//  2. make_exact_blade, faces_inside_blade, corefine_and_classify: the patch corefined with the blade, the pieces
//     classified (surface_cut_corefine.cpp, CGAL);
//  3. write_back: the kept pieces written into S in place, journaled (surface_cut_write_back.cpp);
//  4. verify_result: the local checks of the result (surface_cut_verify.cpp, CGAL predicates).
// Nothing is a pass over S: every phase takes the faces it needs from the grid.
#include "octocut/cutting/surface_cut.hpp"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <iterator>
#include <limits>
#include <numbers>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "surface_cut_phases.hpp"
#include "octocut/sim/timing.hpp"

namespace octocut::cutting {
namespace {

using namespace surface_cut_detail;  // NOLINT(google-build-using-namespace): the phases of this file
using sim::Vec3;

// Checks coordinates and indices of a mesh; throws CutFailure naming the first offender.
void check_input(const sim::TriMesh& mesh, const char* name) {
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
    if (!finite(mesh.vertices[v])) {
      throw CutFailure{std::string(name) + " vertex " + std::to_string(v) + " has a non-finite coordinate"};
    }
  }
  const auto nv = static_cast<int64_t>(mesh.vertices.size());
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (const int32_t v : mesh.triangles[f]) {
      if (v < 0 || v >= nv) {
        throw CutFailure{std::string(name) + " triangle " + std::to_string(f) + " has vertex index " +
                         std::to_string(v) + ", outside [0, " + std::to_string(nv) + ")"};
      }
    }
  }
}

// The faces that change: the patch and the faces that go whole (which have no pieces), with their open fans.
ChangingFaces changing_faces(const sim::TriMesh& surface, Patch&& patch, std::vector<int32_t>&& gone) {
  ChangingFaces changing;
  changing.patch_vertices = std::move(patch.vertices);
  changing.arcs = std::move(patch.arcs);
  if (gone.empty()) {
    changing.faces = std::move(patch.faces);
  } else {
    changing.faces.reserve(patch.faces.size() + gone.size());
    std::merge(patch.faces.begin(), patch.faces.end(), gone.begin(), gone.end(), std::back_inserter(changing.faces));
    changing.arcs = open_fans(surface, changing.faces);
  }
  changing.gone = std::move(gone);
  return changing;
}

// The smallest angle and the shortest edge among the triangles the cut made (written.changed, not kept whole).
void new_triangle_quality(const sim::TriMesh& out, const WrittenPatch& written, SurfaceEditResult& result) {
  double min_angle = std::numbers::pi;                        // rad
  double min_edge2 = std::numeric_limits<double>::infinity();  // m^2
  int n = 0;
  for (std::size_t i = 0; i < written.changed.size(); ++i) {
    if (written.changed_whole[i]) continue;
    const Tri& t = out.triangles[static_cast<std::size_t>(written.changed[i])];
    const auto corner = [&](int k) -> const Vec3& { return out.vertices[static_cast<std::size_t>(t[k])]; };
    for (int k = 0; k < 3; ++k) min_edge2 = std::min(min_edge2, (corner((k + 1) % 3) - corner(k)).squaredNorm());
    min_angle = std::min(min_angle, smallest_angle(corner(0), corner(1), corner(2)));
    ++n;
  }
  result.new_triangles = n;
  if (n == 0) return;
  result.min_edge = std::sqrt(min_edge2);
  result.min_angle_deg = min_angle * 180.0 / std::numbers::pi;
}

// The whole cut, phase after phase; throws CutFailure (or a CGAL exception). S is edited from write_back on.
void cut(SurfaceEditor& editor, const sim::TriMesh& blade, const SurfaceCutOptions& options,
         SurfaceEditResult& result) {
  const sim::TriMesh& surface = editor.mesh();
  FaceGrid& grid = editor.grid();
  if (!grid.built()) throw CutFailure{"the surface has no face grid"};
  check_input(blade, "blade");
  if (blade.triangles.empty()) throw CutFailure{"blade has no triangles"};
  const auto nv = static_cast<int32_t>(surface.vertices.size());
  const ExactBladePtr exact = make_exact_blade(blade, options);
  const BladeBox g = grown_blade_box(blade, options.margin);

  Patch patch = find_patch(surface, grid, blade, g);
  result.patch_triangles = static_cast<int>(patch.faces.size());
  std::vector<int32_t> gone = faces_inside_blade(surface, patch.clear, *exact, options);
  const Corefinement core = corefine_and_classify(surface, grid, blade, *exact, patch, g, options);
  if (!core.changes && gone.empty()) {
    result.status = SurfaceCutStatus::no_op;
    result.reason = "blade does not remove material from the surface (it misses it or only touches it)";
    return;
  }

  const ChangingFaces changing = changing_faces(surface, std::move(patch), std::move(gone));
  const WrittenPatch written =
      write_back(editor, changing, core, blade.vertices.size(), g.centre, options.verify, options.verify,
                 options.tiny_edge, result);
  if (options.verify) verify_result(editor.mesh(), grid, written, changing.arcs, nv);
  new_triangle_quality(editor.mesh(), written, result);
  result.status = SurfaceCutStatus::ok;
}

}  // namespace

SurfaceEditResult cut_surface_in_place(SurfaceEditor& editor, const sim::TriMesh& blade,
                                       const SurfaceCutOptions& options) {
  const auto start = sim::Clock::now();
  const std::size_t mark = editor.mark();
  SurfaceEditResult result;
  result.first_inserted = static_cast<int32_t>(editor.mesh().vertices.size());
  const auto fail = [&](std::string reason) {
    editor.rollback(mark);
    const int patch = result.patch_triangles;
    const int32_t first = result.first_inserted;
    result = SurfaceEditResult{};
    result.status = SurfaceCutStatus::failed;
    result.reason = std::move(reason);
    result.patch_triangles = patch;
    result.first_inserted = first;
  };
  try {
    cut(editor, blade, options, result);
  } catch (const CutFailure& e) {
    fail(e.reason);
  } catch (const std::exception& e) {
    fail(std::string("CGAL: ") + e.what());
  } catch (...) {
    fail("unknown exception");
  }
  result.ms = sim::ms_since(start);
  return result;
}

namespace {

constexpr int kBladeShiftAttempts = 3;

// Moves a blade by blade_shift_fraction(attempt) of its bounding-box diagonal along a fixed generic direction.
sim::TriMesh perturbed(const sim::TriMesh& blade, int attempt) {
  const sim::Box3 bb = sim::bounds(blade);
  const Vec3 direction = Vec3(0.5377, 0.8314, 0.1410).normalized();
  const Vec3 shift = blade_shift_fraction(attempt) * (bb.max - bb.min).norm() * direction;  // m
  sim::TriMesh moved = blade;
  for (Vec3& p : moved.vertices) p += shift;
  return moved;
}

// The retries of cut_surface_perturbing around any cut function of a blade.
template <class Result, class Cut>
std::pair<Result, int> perturbing(sim::TriMesh& blade, Cut&& cut_with) {
  Result first = cut_with(blade);
  if (first.status != SurfaceCutStatus::failed || blade.vertices.empty()) return {std::move(first), 0};
  for (int attempt = 1; attempt <= kBladeShiftAttempts; ++attempt) {
    sim::TriMesh moved = perturbed(blade, attempt);
    Result again = cut_with(moved);
    if (again.status != SurfaceCutStatus::failed) {
      blade = std::move(moved);
      again.ms += first.ms;
      return {std::move(again), attempt};
    }
    first.ms += again.ms;
  }
  first.reason += " (also with the blade moved by 1e-9, 1e-7 and 1e-5 of its size)";
  return {std::move(first), 0};
}

}  // namespace

double blade_shift_fraction(int attempt) {
  // The third shift (0.1 um on a 1 cm punch) gets a re-cut away from walls it meets exactly, where the two smaller
  // ones leave a configuration the rounding repair cannot mend (one bite of 8,000 in the stability matrix once; the
  // repair has mended that one since, and the matrix uses no third shift).
  constexpr double kShift[kBladeShiftAttempts + 1] = {0.0, 1e-9, 1e-7, 1e-5};
  return attempt >= 0 && attempt <= kBladeShiftAttempts ? kShift[attempt] : 0.0;
}

std::pair<SurfaceEditResult, int> cut_surface_in_place_perturbing(SurfaceEditor& editor, sim::TriMesh& blade,
                                                                  const SurfaceCutOptions& options) {
  return perturbing<SurfaceEditResult>(
      blade, [&](const sim::TriMesh& b) { return cut_surface_in_place(editor, b, options); });
}

SurfaceCutResult cut_surface(const sim::TriMesh& surface, const sim::TriMesh& blade, const SurfaceCutOptions& options) {
  const auto start = sim::Clock::now();
  SurfaceCutResult result;
  const auto elapsed = [&] {
    return sim::ms_since(start);
  };
  // A copy of S with its grid (whose build checks S's coordinates and indices), edited in place, then compacted.
  sim::TriMesh work = surface;
  FaceGrid grid;
  try {
    grid.build(work);
  } catch (const std::invalid_argument& e) {
    result.status = SurfaceCutStatus::failed;
    result.reason = e.what();
    result.ms = elapsed();
    return result;
  }
  std::vector<int32_t> origin(surface.triangles.size());
  std::iota(origin.begin(), origin.end(), 0);
  SurfaceEditor editor(work, grid, nullptr, &origin);
  SurfaceEditResult e = cut_surface_in_place(editor, blade, options);
  result.status = e.status;
  result.reason = std::move(e.reason);
  result.removed_volume = e.removed_volume;
  result.patch_triangles = e.patch_triangles;
  result.blade_triangles_kept = e.blade_triangles_kept;
  result.new_triangles = e.new_triangles;
  result.min_angle_deg = e.min_angle_deg;
  result.min_edge = e.min_edge;
  result.collapses = e.collapses;
  if (e.status == SurfaceCutStatus::no_op) {
    result.mesh = surface;
    result.triangle_origin = std::move(origin);
  } else if (e.status == SurfaceCutStatus::ok) {
    result.removed_vertices.assign(e.removed_vertices.begin(), e.removed_vertices.end());
    std::vector<int32_t> old_to_new(work.vertices.size(), -1);
    std::size_t r = 0;
    int32_t next = 0;
    for (std::size_t v = 0; v < work.vertices.size(); ++v) {
      if (r < e.removed_vertices.size() && e.removed_vertices[r] == static_cast<int32_t>(v)) {
        ++r;
        continue;
      }
      old_to_new[v] = next++;
      result.mesh.vertices.push_back(work.vertices[v]);
    }
    result.inserted_vertices.assign(work.vertices.begin() + e.first_inserted, work.vertices.end());
    result.mesh.triangles = std::move(work.triangles);
    for (Tri& t : result.mesh.triangles) {
      for (int32_t& v : t) v = old_to_new[static_cast<std::size_t>(v)];
    }
    result.triangle_origin = std::move(origin);
  }
  result.ms = elapsed();
  return result;
}

std::pair<SurfaceCutResult, int> cut_surface_perturbing(const sim::TriMesh& surface, sim::TriMesh& blade,
                                                        const SurfaceCutOptions& options) {
  return perturbing<SurfaceCutResult>(blade, [&](const sim::TriMesh& b) { return cut_surface(surface, b, options); });
}

}  // namespace octocut::cutting
