// The cut pipeline end to end (SPEC §4) on box objects whose material graph is a Kuhn tet grid: every check is
// against an independent truth (analytic volumes of polygonal prisms, an own edge count for watertightness, CGAL's
// exact self-intersection test, the Euler characteristic, and the invariants of P).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <random>

#include "octocut/cutting/cutting.hpp"
#include "octocut/cutting/mesh_check.hpp"
#include "octocut/sim/primitives.hpp"
#include "octocut/sim/surface_check.hpp"
#include "../common/shapes.hpp"
#include "test_meshes.hpp"
#include "watertight.hpp"

namespace octocut {
namespace {

using sim::Box3;
using sim::Vec3;

using test::expect_watertight;
using test::prism_area;

sim::TriMesh prism(const Vec3& c, double r, double h, int n) { return test::prism_mesh(c, r, h, n); }

sim::TriMesh box_mesh(const Box3& b) { return sim::closed_box_grid(b, 1); }

long euler_characteristic(const sim::TriMesh& m) {
  return long(m.vertices.size()) - long(m.triangles.size()) * 3 / 2 + long(m.triangles.size());
}

// A box object with its tet-grid M, a simulator and the embedding of its surface.
struct Object {
  cutting::CutObject cut;
  std::unique_ptr<sim::Simulator> sim;
  std::unique_ptr<sim::SurfaceEmbedding> emb;
};

Object make_object(const Box3& box, const sim::RootGeometry& root, int base, int max_level,
                   std::vector<sim::HandleSpec> handles, double cell = 0.001) {
  Object o;
  auto graph = std::make_shared<sim::MaterialGraph>(sim::box_tet_mesh(box, cell));
  o.cut.surface = sim::closed_box_grid(box, 16);
  o.cut.cut_faces.assign(o.cut.surface.triangles.size(), 0);
  sim::OctreeSpec spec;
  spec.root = root;
  spec.base_level = base;
  spec.max_level = max_level;
  sim::MaterialParams p;
  p.young_modulus = 1e5;
  p.poisson_ratio = 0.3;
  p.density = 1000.0;
  sim::ObjectModel model = sim::ObjectModel::build(spec, std::move(graph), p, std::move(handles));
  sim::SimulatorOptions so;
  so.dt = 1e-3;
  so.gravity = Vec3::Zero();
  so.threads = 1;
  o.sim = std::make_unique<sim::Simulator>(std::move(model), so);
  o.emb = std::make_unique<sim::SurfaceEmbedding>(o.sim->model(), o.cut.surface);
  return o;
}

// The embedding follows S, the CutObject's one copy: given S, it matches its sizes and equals a fresh embedding of S
// in the current model bit for bit, deformed positions and normals included.
void expect_embeds_surface(const Object& o) {
  ASSERT_TRUE(o.emb->matches(o.cut.surface));
  const sim::SurfaceEmbedding fresh(o.sim->model(), o.cut.surface);
  EXPECT_EQ(o.emb->zcurve().entries(), fresh.zcurve().entries());
  EXPECT_EQ(o.emb->embeddings(), fresh.embeddings());
  EXPECT_EQ(o.emb->dof_begin(), fresh.dof_begin());
  EXPECT_EQ(o.emb->dof_index(), fresh.dof_index());
  EXPECT_EQ(o.emb->dof_weight(), fresh.dof_weight());
  sim::Executor exec(1);
  std::vector<Vec3> pa, pb, na, nb;
  o.emb->deformed_positions(o.sim->state().x, pa, exec);
  fresh.deformed_positions(o.sim->state().x, pb, exec);
  EXPECT_EQ(pa, pb);
  o.emb->deformed_normals(o.cut.surface, pa, na, exec);
  fresh.deformed_normals(o.cut.surface, pb, nb, exec);
  EXPECT_EQ(na, nb);
}

cutting::CutOutcome cut(Object& o, const sim::TriMesh& blade, double r, cutting::CutOptions opt = {}) {
  cutting::CutRequest req{blade, r};
  return cutting::apply_cut(o.cut, *o.sim, *o.emb, req, opt);
}

// The slab of most tests: 40 x 40 x 4 mm, held along x < 5 mm.
const Box3 kSlab{Vec3(0, 0, 0), Vec3(0.04, 0.04, 0.004)};
const sim::RootGeometry kSlabRoot{Vec3(-0.002, -0.002, -0.02), 0.044};
sim::HandleSpec left_handle() { return {{Vec3(-1, -1, -1), Vec3(0.005, 1, 1)}, {}}; }
sim::HandleSpec right_handle() { return {{Vec3(0.035, -1, -1), Vec3(1, 1, 1)}, {}}; }

TEST(CutPipeline, PunchThroughASlabAtRest) {
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  const int elements0 = o.sim->model().num_elements();
  const double v0 = sim::signed_volume(o.cut.surface);
  const double r = 0.002;
  const int n = 32;
  const auto out = cut(o, prism(Vec3(0.02, 0.02, 0.002), r, 0.01, n), r * std::cos(std::numbers::pi / n));
  ASSERT_EQ(out.status, "ok") << out.reason;
  EXPECT_EQ(out.components, 1);
  EXPECT_EQ(out.restricted_components, 0);
  // The boolean is exact: the removed volume is the prism's area times the slab's thickness.
  const double expect = prism_area(r, n) * 0.004;
  EXPECT_NEAR(out.removed_volume, expect, 1e-9 * expect);
  EXPECT_NEAR(v0 - sim::signed_volume(o.cut.surface), out.removed_volume, 1e-12 * v0);
  expect_watertight(o.cut.surface, "surface");
  // One through-hole: genus 1, chi = 0.
  EXPECT_EQ(euler_characteristic(o.cut.surface), 0);
  EXPECT_GT(out.tets_removed, 0);
  EXPECT_GT(o.sim->model().num_elements(), elements0);
  EXPECT_EQ(o.sim->model().dofs().check_invariants(), "");
  EXPECT_EQ(o.cut.cut_faces.size(), o.cut.surface.triangles.size());
  EXPECT_GT(std::count(o.cut.cut_faces.begin(), o.cut.cut_faces.end(), 1), 0);
  // The refinement oracle: no leaf that meets the blade's rest volume is longer than r / sqrt(3), unless at max_level.
  const double le = r * std::cos(std::numbers::pi / n) / std::sqrt(3.0);
  const sim::ObjectModel& m = o.sim->model();
  for (int e = 0; e < m.num_elements(); ++e) {
    const Box3 b = m.root().cell_box(m.tree().leaf(e));
    // Distance in xy from the blade's axis to the box, against the polygon's inradius (a conservative meet test).
    const double dx = std::max({b.min.x() - 0.02, 0.0, 0.02 - b.max.x()});
    const double dy = std::max({b.min.y() - 0.02, 0.0, 0.02 - b.max.y()});
    if (std::hypot(dx, dy) < 0.9 * r * std::cos(std::numbers::pi / n)) {
      EXPECT_TRUE(m.edge()[std::size_t(e)] <= le * (1 + 1e-12) || m.tree().leaf(e).level == m.max_level()) << e;
    }
  }
  // The cut object keeps simulating.
  for (int i = 0; i < 5; ++i) o.sim->step();
  for (const Vec3& x : o.sim->state().x) ASSERT_TRUE(x.allFinite());
  EXPECT_EQ(o.sim->stats().failed_steps, 0);
}

// The grid over S lists exactly the triangles that a brute-force box test finds, for random boxes over the slab.
void expect_grid_lists_s(cutting::CutObject& object) {
  const sim::TriMesh& s = object.surface;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.005, 0.045), w(0.0, 0.01);
  for (int q = 0; q < 300; ++q) {
    const Vec3 lo(u(rng), u(rng), u(rng) * 0.2), hi = lo + Vec3(w(rng), w(rng), w(rng));
    std::vector<int32_t> truth;
    for (std::size_t f = 0; f < s.triangles.size(); ++f) {
      Vec3 a = s.vertices[std::size_t(s.triangles[f][0])], b = a;
      for (const int32_t v : s.triangles[f]) {
        a = a.cwiseMin(s.vertices[std::size_t(v)]);
        b = b.cwiseMax(s.vertices[std::size_t(v)]);
      }
      if ((a.array() <= hi.array()).all() && (b.array() >= lo.array()).all()) truth.push_back(int32_t(f));
    }
    ASSERT_EQ(object.grid.grid->query(s, lo, hi), truth) << "box " << q;
  }
}

TEST(CutPipeline, SurfaceGridFollowsSThroughCutsAndCopies) {
  // S is edited in place through its grid: after three punches (one of them through earlier cut walls) the grid
  // lists exactly the triangles a brute-force box test finds, S has no unused vertex, and the embedding holds S. A
  // copy of the object gets no grid of its own until it is cut, and cutting it leaves the original alone.
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  cutting::index_surface(o.cut);
  ASSERT_TRUE(cutting::surface_indexed(o.cut));
  const double r = 0.0015;
  for (const Vec3& c : {Vec3(0.02, 0.02, 0.002), Vec3(0.03, 0.021, 0.002), Vec3(0.022, 0.0205, 0.002)}) {
    const auto out = cut(o, prism(c, r, 0.01, 24), r * std::cos(std::numbers::pi / 24));
    ASSERT_EQ(out.status, "ok") << out.reason;
    ASSERT_TRUE(cutting::surface_indexed(o.cut));
  }
  const sim::TriMesh& s = o.cut.surface;
  expect_watertight(s, "surface");  // includes: no unused vertex
  expect_embeds_surface(o);
  EXPECT_EQ(o.cut.cut_faces.size(), s.triangles.size());
  expect_grid_lists_s(o.cut);

  const sim::TriMesh before = o.cut.surface;
  cutting::CutObject copied = o.cut;
  EXPECT_FALSE(cutting::surface_indexed(copied));
  sim::Simulator sim2(o.sim->model(), o.sim->options());
  sim::SurfaceEmbedding emb2(sim2.model(), copied.surface);
  const auto out = cutting::apply_cut(copied, sim2, emb2, {prism(Vec3(0.015, 0.03, 0.002), r, 0.01, 24), r * 0.9}, {});
  ASSERT_EQ(out.status, "ok") << out.reason;
  EXPECT_TRUE(cutting::surface_indexed(copied));
  EXPECT_EQ(o.cut.surface.vertices, before.vertices);
  EXPECT_EQ(o.cut.surface.triangles, before.triangles);
  expect_watertight(copied.surface, "copy");
}

TEST(CutPipeline, SurfaceBoundsFollowSThroughCuts) {
  // The grid keeps S's bounds from cut to cut once a blade that may snap needed them: a cavity keeps them (it removes
  // no vertex of S), a cut that takes off the slab's end drops them (its lost vertices lay on the bounds), and
  // whatever the grid holds equals a pass over S bit for bit. Without that drop the kept bounds would still end at
  // x = 40 mm.
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  cutting::index_surface(o.cut);
  const auto expect_exact = [&](const char* after) {
    if (!o.cut.grid.bounds) return;
    const Box3 truth = sim::bounds(o.cut.surface);
    EXPECT_EQ(o.cut.grid.bounds->min, truth.min) << after;
    EXPECT_EQ(o.cut.grid.bounds->max, truth.max) << after;
  };
  const double r = 0.0015;
  ASSERT_EQ(cut(o, prism(Vec3(0.02, 0.02, 0.002), r, 0.01, 24), r * 0.98).status, "ok");
  EXPECT_FALSE(o.cut.grid.bounds.has_value());  // no earlier blade to snap to: not needed yet
  const sim::TriMesh cavity = prism(Vec3(0.012, 0.03, 0.002), 0.001, 0.002, 16);
  ASSERT_EQ(cut(o, cavity, 0.0009).status, "ok");
  ASSERT_TRUE(o.cut.grid.bounds.has_value());  // computed for the cavity's blade, kept through its cut
  expect_exact("the cavity");
  const sim::TriMesh end = sim::closed_box_grid(Box3{Vec3(0.035, -0.01, -0.01), Vec3(0.05, 0.05, 0.02)}, 1);
  ASSERT_EQ(cut(o, end, 0.005).status, "ok");
  EXPECT_EQ(sim::bounds(o.cut.surface).max.x(), 0.035);
  expect_exact("the end cut off");
  ASSERT_EQ(cut(o, prism(Vec3(0.025, 0.01, 0.002), 0.001, 0.002, 16), 0.0009).status, "ok");
  ASSERT_TRUE(o.cut.grid.bounds.has_value());
  expect_exact("the second cavity");
  expect_watertight(o.cut.surface, "surface");
  expect_embeds_surface(o);
}

TEST(CutPipeline, BladeFlushWithTheSurfaceAndOnItsVertices) {
  // The slab's surface grid has lines every 2.5 mm in x and y and every 2 mm in z. A box blade from 15 to 25 mm in x
  // and y and from 2 to 4 mm in z has its top face in the slab's top face, its vertices on surface vertices and its
  // edges along surface edges: every degenerate contact at once. It removes exactly 10 x 10 x 2 mm.
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  const double v0 = sim::signed_volume(o.cut.surface);
  const auto out = cut(o, box_mesh({Vec3(0.015, 0.015, 0.002), Vec3(0.025, 0.025, 0.004)}), 0.001);
  ASSERT_EQ(out.status, "ok") << out.reason;
  const double expect = 0.01 * 0.01 * 0.002;
  EXPECT_NEAR(out.removed_volume, expect, 1e-9 * expect);
  EXPECT_NEAR(v0 - sim::signed_volume(o.cut.surface), expect, 1e-9 * expect);
  expect_watertight(o.cut.surface, "surface");
  EXPECT_EQ(euler_characteristic(o.cut.surface), 2);  // a pocket, no hole
  EXPECT_EQ(o.sim->model().dofs().check_invariants(), "");
  // A blade that only touches the top face from outside removes nothing.
  const auto touch = cut(o, box_mesh({Vec3(0.002, 0.002, 0.004), Vec3(0.008, 0.008, 0.006)}), 0.001);
  EXPECT_TRUE(touch.status == "no-op" || (touch.status == "ok" && touch.removed_volume == 0.0))
      << touch.status << " " << touch.reason;
  expect_watertight(o.cut.surface, "surface");
}

TEST(CutPipeline, BladeThatMissesIsANoOp) {
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  const sim::TriMesh s0 = o.cut.surface;
  const int e0 = o.sim->model().num_elements(), rev0 = o.sim->model().revision();
  const auto out = cut(o, prism(Vec3(0.02, 0.02, 0.02), 0.002, 0.004, 16), 0.0015);
  EXPECT_EQ(out.status, "no-op");
  EXPECT_FALSE(out.reason.empty());
  EXPECT_EQ(o.cut.surface.vertices, s0.vertices);
  EXPECT_EQ(o.cut.surface.triangles, s0.triangles);
  EXPECT_EQ(o.sim->model().num_elements(), e0);
  EXPECT_EQ(o.sim->model().revision(), rev0);
}

TEST(CutPipeline, BladeThatRemovesTheWholeObject) {
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  const auto out = cut(o, box_mesh({Vec3(-0.01, -0.01, -0.01), Vec3(0.05, 0.05, 0.02)}), 0.015);
  ASSERT_EQ(out.status, "ok") << out.reason;
  // Nothing left to simulate: the simulator holds an empty model, and stepping only advances time.
  EXPECT_TRUE(o.sim->empty());
  EXPECT_EQ(o.sim->model().num_elements(), 0);
  EXPECT_EQ(o.sim->model().num_dofs(), 0);
  EXPECT_TRUE(o.cut.surface.triangles.empty());
  const double t = o.sim->state().t;
  o.sim->step();
  EXPECT_DOUBLE_EQ(o.sim->state().t, t + o.sim->options().dt);
  // Further cuts are no-ops.
  EXPECT_EQ(cut(o, prism(Vec3(0.02, 0.02, 0.002), 0.002, 0.01, 16), 0.0015).status, "no-op");
}

TEST(CutPipeline, CavityUnderAnAffineStretchRemovesTheBackTransformedVolume) {
  // A block 20 x 20 x 10 mm, stretched by 1.25 along x (every DOF at F X): shape matching recovers F exactly, so a
  // blade inside the deformed block removes V(B) / det F of rest material.
  const Box3 block{Vec3(0, 0, 0), Vec3(0.02, 0.02, 0.01)};
  Object o = make_object(block, {Vec3(-0.001, -0.001, -0.006), 0.022}, 4, 7, {});
  sim::SimState st = o.sim->state();
  const sim::Mat3 F = Vec3(1.25, 1.0, 1.0).asDiagonal();
  for (std::size_t d = 0; d < st.x.size(); ++d) st.x[d] = F * o.sim->model().dofs().dof_rest[d];
  o.sim->set_state(st);
  const double v0 = sim::signed_volume(o.cut.surface);
  const sim::TriMesh blade = prism(Vec3(0.0125, 0.01, 0.005), 0.002, 0.004, 24);
  const auto out = cut(o, blade, 0.0015);
  ASSERT_EQ(out.status, "ok") << out.reason;
  const double expect = prism_area(0.002, 24) * 0.004 / 1.25;
  EXPECT_NEAR(out.removed_volume, expect, 1e-9 * expect);
  EXPECT_NEAR(v0 - sim::signed_volume(o.cut.surface), expect, 1e-9 * expect);
  expect_watertight(o.cut.surface, "surface");
  EXPECT_EQ(sim::check_surface(o.cut.surface).components, 2);  // the outer surface and the cavity
  EXPECT_EQ(euler_characteristic(o.cut.surface), 4);             // two spheres
  EXPECT_DOUBLE_EQ(out.max_blend, 0.0);
}

TEST(CutPipeline, FiftyPunchesAtOneSpotStayBounded) {
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  const sim::TriMesh blade = prism(Vec3(0.02, 0.02, 0.002), 0.002, 0.01, 32);
  long after_first = 0;
  for (int i = 0; i < 50; ++i) {
    const auto out = cut(o, blade, 0.0019);
    ASSERT_TRUE(out.status == "ok" || out.status == "no-op") << i << ": " << out.status << " " << out.reason;
    if (i == 0) {
      ASSERT_EQ(out.status, "ok");
      after_first = o.sim->model().num_elements();
    }
    o.sim->step();
  }
  EXPECT_LE(o.sim->model().num_elements(), 2 * after_first);
  expect_watertight(o.cut.surface, "surface");
  for (const Vec3& x : o.sim->state().x) ASSERT_TRUE(x.allFinite());
}

TEST(CutPipeline, PunchIntoInvertedElementsNeverCrashes) {
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  // Mirror the whole object through the plane z = 2 mm: every element is inverted (det F = -1).
  sim::SimState st = o.sim->state();
  for (sim::Vec3& x : st.x) x.z() = 0.004 - x.z();
  o.sim->set_state(st);
  const auto out = cut(o, prism(Vec3(0.02, 0.02, 0.002), 0.002, 0.01, 32), 0.0019);
  ASSERT_TRUE(out.status == "ok" || out.status == "skipped") << out.reason;
  expect_watertight(o.cut.surface, "surface");
  EXPECT_EQ(o.sim->model().dofs().check_invariants(), "");
  for (int i = 0; i < 3; ++i) o.sim->step();
  for (const Vec3& x : o.sim->state().x) ASSERT_TRUE(x.allFinite());
}

TEST(CutPipeline, FoldedSlabPunchedOnceShowsTwoHolesInRestSpace) {
  // An 80 x 30 x 4 mm slab folded about x = 40 mm: the right half rotated by 180 degrees about y and laid 6 mm
  // above the left half. One vertical punch at x = 20 mm goes through both layers: two components, two transforms,
  // two holes at rest x = 20 mm and x = 60 mm.
  const Box3 slab{Vec3(0, 0, 0), Vec3(0.08, 0.03, 0.004)};
  Object o = make_object(slab, {Vec3(-0.002, -0.027, -0.04), 0.084}, 5, 7, {});
  sim::SimState st = o.sim->state();
  for (std::size_t d = 0; d < st.x.size(); ++d) {
    const Vec3 X = o.sim->model().dofs().dof_rest[d];
    if (X.x() > 0.04) st.x[d] = Vec3(0.08 - X.x(), X.y(), 0.014 - X.z());
  }
  o.sim->set_state(st);
  const double r = 0.002;
  const auto out = cut(o, prism(Vec3(0.02, 0.015, 0.007), r, 0.03, 32), r * std::cos(std::numbers::pi / 32));
  ASSERT_EQ(out.status, "ok") << out.reason;
  EXPECT_EQ(out.components, 2);
  EXPECT_EQ(out.restricted_components, 0);  // each B'_i lies in its own half's rest place
  // Two booleans in turn, one embedding update: the embedding follows exactly the committed surface.
  expect_embeds_surface(o);
  const double expect = 2.0 * prism_area(r, 32) * 0.004;
  EXPECT_NEAR(out.removed_volume, expect, 1e-9 * expect);
  expect_watertight(o.cut.surface, "surface");
  EXPECT_EQ(euler_characteristic(o.cut.surface), -2);  // genus 2: two through-holes
  // The holes are where the back-transforms put them.
  int near20 = 0, near60 = 0;
  for (std::size_t f = 0; f < o.cut.surface.triangles.size(); ++f) {
    if (!o.cut.cut_faces[f]) continue;
    const double x = o.cut.surface.vertices[std::size_t(o.cut.surface.triangles[f][0])].x();
    near20 += std::abs(x - 0.02) <= r + 1e-9;
    near60 += std::abs(x - 0.06) <= r + 1e-9;
  }
  EXPECT_GT(near20, 0);
  EXPECT_GT(near60, 0);
}

TEST(CutPipeline, FailedStageLeavesEverythingAsItWas) {
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  const sim::TriMesh s0 = o.cut.surface;
  const int e0 = o.sim->model().num_elements(), d0 = o.sim->model().num_dofs();
  const std::vector<Vec3> x0 = o.sim->state().x;
  // An open blade (one triangle missing): the boolean refuses it, and the cut is skipped as a whole.
  sim::TriMesh blade = prism(Vec3(0.02, 0.02, 0.002), 0.002, 0.01, 16);
  blade.triangles.pop_back();
  const auto out = cut(o, blade, 0.0015);
  EXPECT_EQ(out.status, "skipped");
  EXPECT_FALSE(out.reason.empty());
  EXPECT_EQ(o.cut.surface.vertices, s0.vertices);
  EXPECT_EQ(o.cut.surface.triangles, s0.triangles);
  EXPECT_EQ(o.sim->model().num_elements(), e0);
  EXPECT_EQ(o.sim->model().num_dofs(), d0);
  EXPECT_EQ(o.sim->state().x, x0);
  EXPECT_EQ(o.emb->num_vertices(), int(s0.vertices.size()));
}

TEST(CutPipeline, FailedEmbeddingUpdateRestoresTheCompactedSurface) {
  // The embedding stage fails after S was compacted (here the embedding given is one of another surface, so its
  // update rejects S): the cut is skipped, and S, its grid and its cut faces are as they were. The same cut with the
  // right embedding then goes through, and it removes the top face's centre vertex: the failed cut had compacted S.
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  cutting::index_surface(o.cut);
  const sim::TriMesh s0 = o.cut.surface;
  const std::vector<char> faces0 = o.cut.cut_faces;
  const int rev0 = o.sim->model().revision();
  const Vec3 centre(0.02, 0.02, 0.004);
  ASSERT_EQ(std::count(s0.vertices.begin(), s0.vertices.end(), centre), 1);
  const sim::TriMesh blade = prism(Vec3(0.02, 0.02, 0.002), 0.004, 0.01, 32);
  sim::SurfaceEmbedding other(o.sim->model(), sim::closed_box_grid(kSlab, 32));
  ASSERT_GT(other.num_vertices(), int(s0.vertices.size()));
  const auto failed = cutting::apply_cut(o.cut, *o.sim, other, {blade, 0.0039}, {});
  EXPECT_EQ(failed.status, "skipped");
  EXPECT_NE(failed.reason.find("SurfaceEmbedding::update"), std::string::npos) << failed.reason;
  EXPECT_EQ(o.cut.surface.vertices, s0.vertices);
  EXPECT_EQ(o.cut.surface.triangles, s0.triangles);
  EXPECT_EQ(o.cut.cut_faces, faces0);
  ASSERT_TRUE(cutting::surface_indexed(o.cut));
  expect_grid_lists_s(o.cut);
  EXPECT_EQ(o.sim->model().revision(), rev0);
  expect_embeds_surface(o);

  const auto ok = cut(o, blade, 0.0039);
  ASSERT_EQ(ok.status, "ok") << ok.reason;
  EXPECT_EQ(std::count(o.cut.surface.vertices.begin(), o.cut.surface.vertices.end(), centre), 0);
  expect_watertight(o.cut.surface, "surface");
  expect_grid_lists_s(o.cut);
  expect_embeds_surface(o);
}

// A 12 mm-wide wall through the slab's whole width and thickness cuts it in two.
sim::TriMesh wall() { return box_mesh({Vec3(0.017, -0.01, -0.01), Vec3(0.023, 0.05, 0.014)}); }

TEST(CutPipeline, SlabCutInTwoKeepsBothHeldHalves) {
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle(), right_handle()});
  const auto out = cut(o, wall(), 0.003);
  ASSERT_EQ(out.status, "ok") << out.reason;
  EXPECT_EQ(out.fragments_removed, 0);
  int count = 0;
  sim::element_components(o.sim->model(), count);
  EXPECT_EQ(count, 2);
  EXPECT_EQ(sim::check_surface(o.cut.surface).components, 2);
  expect_watertight(o.cut.surface, "surface");
  const double expect = 0.006 * 0.04 * 0.004;
  EXPECT_NEAR(out.removed_volume, expect, 1e-9 * expect);
}

TEST(CutPipeline, LooseHalfIsRemovedAsAFragment) {
  for (const auto policy : {cutting::FragmentPolicy::all, cutting::FragmentPolicy::small, cutting::FragmentPolicy::none}) {
    Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
    cutting::CutOptions opt;
    opt.fragments = policy;
    opt.fragment_volume = 1e-6;  // m^3: the loose half (about 2.6e-6 m^3) is not small
    const auto out = cut(o, wall(), 0.003, opt);
    ASSERT_EQ(out.status, "ok") << out.reason;
    int count = 0;
    sim::element_components(o.sim->model(), count);
    if (policy == cutting::FragmentPolicy::all) {
      EXPECT_EQ(out.fragments_removed, 1);
      EXPECT_EQ(count, 1);
      EXPECT_EQ(sim::check_surface(o.cut.surface).components, 1);
      // The right half's material is gone from the simulation: about 17 x 40 x 4 mm (the M tets the wall touched
      // widen the gap by at most one 1 mm cell on each side).
      EXPECT_NEAR(out.fragment_volume, 0.017 * 0.04 * 0.004, 0.0015 * 0.04 * 0.004);
      expect_watertight(o.cut.surface, "surface");
      for (const Vec3& x : o.cut.surface.vertices) EXPECT_LT(x.x(), 0.0175);
      // The boolean and then the fragment's surface removal, one embedding update: it follows the committed
      // surface.
      expect_embeds_surface(o);
    } else {
      EXPECT_EQ(out.fragments_removed, 0);
      EXPECT_EQ(count, 2);
    }
  }
}

// Two 21 x 21 x 3 mm slabs of material in one object, 3 mm apart (z in [0, 3] and [6, 9] mm, one empty 3 mm cell
// layer between them), with `surface` as S, on 3 mm base cells; the upper slab is pushed 20 mm up.
void two_slabs(Object& o, const sim::TriMesh& surface) {
  const Box3 lower{Vec3(0, 0, 0), Vec3(0.021, 0.021, 0.003)};
  const Box3 upper{Vec3(0, 0, 0.006), Vec3(0.021, 0.021, 0.009)};
  sim::TetMesh tets = sim::box_tet_mesh(lower, 0.001);
  {
    const sim::TetMesh u = sim::box_tet_mesh(upper, 0.001);
    const auto offset = int32_t(tets.vertices.size());
    tets.vertices.insert(tets.vertices.end(), u.vertices.begin(), u.vertices.end());
    for (auto t : u.tets) {
      for (int32_t& v : t) v += offset;
      tets.tets.push_back(t);
    }
  }
  auto graph = std::make_shared<sim::MaterialGraph>(std::move(tets));
  o.cut.surface = surface;
  o.cut.cut_faces.assign(o.cut.surface.triangles.size(), 0);
  o.cut.surface_checked = true;
  sim::OctreeSpec spec;
  spec.root = {Vec3(-0.003, -0.003, -0.003), 0.024};
  spec.base_level = 3;  // 3 mm cells, their faces at z = 0, 3, 6, 9 mm
  spec.max_level = 5;
  sim::MaterialParams mp;
  mp.young_modulus = 1e5;
  mp.poisson_ratio = 0.3;
  mp.density = 1000.0;
  sim::SimulatorOptions so;
  so.dt = 1e-3;
  so.gravity = Vec3::Zero();
  so.threads = 1;
  o.sim = std::make_unique<sim::Simulator>(
      sim::ObjectModel::build(spec, std::move(graph), mp, {{{Vec3(-1, -1, -1), Vec3(0.004, 1, 1)}, {}}}), so);
  o.emb = std::make_unique<sim::SurfaceEmbedding>(o.sim->model(), o.cut.surface);
  int count = 0;
  sim::element_components(o.sim->model(), count);
  ASSERT_EQ(count, 2);
  sim::SimState st = o.sim->state();
  for (std::size_t d = 0; d < st.x.size(); ++d)
    if (o.sim->model().dofs().dof_rest[d].z() > 0.0045) st.x[d].z() += 0.02;
  o.sim->set_state(st);
}

// A 32-gon punch of circumradius 2 mm and height 10 mm, centred at (10.5, 10.5, z) mm, through the two slabs;
// loose pieces stay.
constexpr double kSlabPunchRadius = 0.002;  // m
constexpr int kSlabPunchSides = 32;
cutting::CutOutcome punch_slabs(Object& o, double z) {
  const double r = kSlabPunchRadius;
  const int n = kSlabPunchSides;
  cutting::CutOptions opt;
  opt.fragments = cutting::FragmentPolicy::none;
  return cut(o, prism(Vec3(0.0105, 0.0105, z), r, 0.01, n), r * std::cos(std::numbers::pi / n), opt);
}

TEST(CutPipeline, BladeCutsOnlyTheMaterialOfItsOwnComponent) {
  // Two 21 x 21 x 3 mm slabs in one object, 3 mm apart (z in [0, 3] and [6, 9] mm, one empty 3 mm cell layer
  // between them). The upper slab is pushed 20 mm up, and a punch from z = -2 to 8 mm goes through the lower slab
  // only. The lower slab is at rest, so its transform is the identity and B' reaches into the upper slab's rest
  // place: restricted to its component (SPEC §4 stage 2), the cut leaves the upper slab untouched.
  const Box3 lower{Vec3(0, 0, 0), Vec3(0.021, 0.021, 0.003)};
  const Box3 upper{Vec3(0, 0, 0.006), Vec3(0.021, 0.021, 0.009)};
  Object o;
  two_slabs(o, test::merged(sim::closed_box_grid(lower, 32), sim::closed_box_grid(upper, 32)));
  const sim::TriMesh s0 = o.cut.surface;
  const auto upper_tets = [&] {  // alive tets of the upper slab, in M as the model holds it
    const sim::MaterialGraph& graph = *o.sim->model().material_graph();
    int count = 0;
    for (int t = 0; t < graph.num_tets_total(); ++t) count += graph.alive(t) && graph.tet(t)[0].z() > 0.0045;
    return count;
  };
  const int upper_tets0 = upper_tets();

  const double r = kSlabPunchRadius;
  const int n = kSlabPunchSides;
  const auto out = punch_slabs(o, 0.003);
  ASSERT_EQ(out.status, "ok") << out.reason;
  EXPECT_EQ(out.components, 1);
  EXPECT_EQ(out.restricted_components, 1);
  // Only the lower slab's prism goes (unrestricted, 2 mm of the upper slab would go too).
  const double expect = prism_area(r, n) * 0.003;
  EXPECT_NEAR(out.removed_volume, expect, 1e-9 * expect);
  expect_watertight(o.cut.surface, "surface");
  EXPECT_EQ(euler_characteristic(o.cut.surface), 2);  // a torus (0) and the untouched upper box (2)
  for (std::size_t f = 0; f < o.cut.surface.triangles.size(); ++f) {
    if (!o.cut.cut_faces[f]) continue;
    for (int32_t v : o.cut.surface.triangles[f]) EXPECT_LT(o.cut.surface.vertices[std::size_t(v)].z(), 0.0045);
  }
  // The upper slab bounds the same solid as before (the boolean may split its faces along the blade's contour, but
  // keeps every piece), and its tets are all there.
  sim::TriMesh top;
  std::map<int32_t, int32_t> index;
  for (const auto& t : o.cut.surface.triangles) {
    if (o.cut.surface.vertices[std::size_t(t[0])].z() < 0.0045) continue;
    std::array<int32_t, 3> u{};
    for (int k = 0; k < 3; ++k) {
      const auto [it, added] = index.emplace(t[std::size_t(k)], int32_t(top.vertices.size()));
      if (added) top.vertices.push_back(o.cut.surface.vertices[std::size_t(t[std::size_t(k)])]);
      u[std::size_t(k)] = it->second;
    }
    top.triangles.push_back(u);
  }
  expect_watertight(top, "upper slab");
  EXPECT_NEAR(sim::signed_volume(top), 0.021 * 0.021 * 0.003, 1e-12 * 0.021 * 0.021 * 0.003);
  for (const Vec3& p : s0.vertices) {
    if (p.z() > 0.0045) {
      EXPECT_NE(std::find(top.vertices.begin(), top.vertices.end(), p), top.vertices.end());
    }
  }
  EXPECT_EQ(upper_tets(), upper_tets0);
  EXPECT_GT(out.tets_removed, 0);
  // The upper slab's leaves were not refined: none of them is finer than the base level.
  const sim::ObjectModel& m = o.sim->model();
  for (int e = 0; e < m.num_elements(); ++e) {
    if (m.root().cell_box(m.tree().leaf(e)).min.z() > 0.0045) {
      EXPECT_EQ(m.tree().leaf(e).level, 3);
    }
  }
  EXPECT_EQ(m.dofs().check_invariants(), "");
}

// A punch, then the slab bent under it (the punch's hole tilted by about 0.3 degrees and lowered by 50 um), then the
// same punch again: the leaves the re-cut touches line the hole's wall, one piece of material, so one component
// with one rest-space map (not one per patch of wall leaves that meet only through the leaves behind them), whose
// blade lies within min_feature of the first one's and keeps the sub-feature shell whole.
TEST(CutPipeline, ARecutBesideTheLastHoleIsOneComponent) {
  Object o = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  const double r = 0.002;
  const int n = 32;
  const sim::TriMesh blade = prism(Vec3(0.02, 0.02, 0.002), r, 0.01, n);
  const auto first = cut(o, blade, r * std::cos(std::numbers::pi / n));
  ASSERT_EQ(first.status, "ok") << first.reason;
  sim::SimState st = o.sim->state();
  for (std::size_t d = 0; d < st.x.size(); ++d) {
    const Vec3 X = o.sim->model().dofs().dof_rest[d];
    const double s = X.x() / 0.04;
    st.x[d] = X + Vec3(0.0, 0.0, -2e-4 * s * s);
  }
  o.sim->set_state(st);
  const auto second = cut(o, blade, r * std::cos(std::numbers::pi / n));
  EXPECT_EQ(second.components, 1);
  EXPECT_EQ(second.status, "no-op") << second.reason;
  expect_watertight(o.cut.surface, "surface");
  EXPECT_EQ(o.sim->model().dofs().check_invariants(), "");
}

// A blade that an earlier cut applied to all the material under it, cut again where it was (the slab at rest, so the
// rest-space blade is the same, bit for bit): S holds no material inside it any more, so the cut is a no-op and S
// stays as it was, whatever the blade: a scalpel thinner than 2 min_feature and a non-convex L, for which the
// sub-feature test does not decide, included.
TEST(CutPipeline, AnEarlierCutsBladeCutAgainIsANoOp) {
  sim::TriMesh l_blade;  // an L-shaped prism through the slab: arms 6 mm long and 2 mm thick
  {
    const std::array<std::array<double, 2>, 6> outline{{{0, 0}, {6, 0}, {6, 2}, {2, 2}, {2, 6}, {0, 6}}};
    for (const double z : {-0.003, 0.007})
      for (const auto& q : outline) l_blade.vertices.emplace_back(0.015 + 1e-3 * q[0], 0.015 + 1e-3 * q[1], z);
    for (const auto& f : std::array<std::array<int, 3>, 4>{{{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {0, 4, 5}}}) {
      l_blade.triangles.push_back({f[0], f[2], f[1]});
      l_blade.triangles.push_back({f[0] + 6, f[1] + 6, f[2] + 6});
    }
    for (int i = 0; i < 6; ++i) {
      const int j = (i + 1) % 6;
      l_blade.triangles.push_back({i, j, j + 6});
      l_blade.triangles.push_back({i, j + 6, i + 6});
    }
  }
  ASSERT_GT(sim::signed_volume(l_blade), 0.0);
  const sim::TriMesh scalpel = box_mesh({Vec3(0.02, 0.008, -0.003), Vec3(0.03, 0.0082, 0.007)});  // 0.2 mm thick
  for (const sim::TriMesh* blade : std::array<const sim::TriMesh*, 2>{&scalpel, &l_blade}) {
    // Leaves of 2.75 mm, coarser than the material graph's 1 mm tets: the leaves around the hole keep material,
    // so the second cut touches them and maps its blade back (at rest: the same blade).
    Object o = make_object(kSlab, kSlabRoot, 4, 4, {left_handle()});
    const auto first = cut(o, *blade, 1e-4);
    ASSERT_EQ(first.status, "ok") << first.reason;
    EXPECT_GT(first.removed_volume, 0.0);
    const sim::TriMesh before = o.cut.surface;
    const int elements = o.sim->model().num_elements();
    const auto again = cut(o, *blade, 1e-4);
    EXPECT_EQ(again.status, "no-op");
    EXPECT_GE(again.components, 1);
    EXPECT_EQ(again.reason, "the blade is an earlier cut's, which removed all the material under it");
    EXPECT_EQ(again.removed_volume, 0.0);
    EXPECT_EQ(o.cut.surface.vertices, before.vertices);
    EXPECT_EQ(o.cut.surface.triangles, before.triangles);
    EXPECT_EQ(o.sim->model().num_elements(), elements);
    expect_watertight(o.cut.surface, "surface");
  }
}

TEST(CutPipeline, RestrictionThatCannotCloseUpFallsBackToTheWholeBlade) {
  // The two slabs of material, but one closed box as S around both (z in [0, 9] mm): S claims the empty layer
  // between them. A punch from z = 2 to 12 mm touches the lower slab only (the upper one is pushed away), and its
  // rest image covers the upper slab's rest place. Restricted, the boolean would keep S's top face inside the blade
  // (foreign material) while the blade's wall, one region from z = 2 to 9 mm, starts in the lower slab: its pieces
  // cannot close up. The cut then goes through without the restriction, says so, and S stays watertight.
  Object o;
  two_slabs(o, sim::closed_box_grid({Vec3(0, 0, 0), Vec3(0.021, 0.021, 0.009)}, 32));
  const double r = kSlabPunchRadius;
  const int n = kSlabPunchSides;
  const auto out = punch_slabs(o, 0.007);
  ASSERT_EQ(out.status, "ok") << out.reason;
  EXPECT_EQ(out.components, 1);
  EXPECT_EQ(out.unrestricted, 1);
  EXPECT_EQ(out.restricted_components, 0);
  const double expect = prism_area(r, n) * 0.007;  // the blade's part inside the box, z from 2 to 9 mm
  EXPECT_NEAR(out.removed_volume, expect, 1e-9 * expect);
  expect_watertight(o.cut.surface, "surface");
  EXPECT_EQ(euler_characteristic(o.cut.surface), 2);  // a box with a blind hole
  EXPECT_EQ(o.sim->model().dofs().check_invariants(), "");
}

TEST(CutPipeline, CheckedSurfaceCutsAsAnUncheckedOne) {
  // An object whose S is known valid skips CGAL's own check of S; the results are the same, and a cut without
  // verification no longer vouches for S.
  Object checked = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  Object unchecked = make_object(kSlab, kSlabRoot, 4, 7, {left_handle()});
  checked.cut.surface_checked = true;
  const sim::TriMesh blade = prism(Vec3(0.02, 0.02, 0.002), 0.002, 0.01, 32);
  const auto a = cut(checked, blade, 0.0019);
  const auto b = cut(unchecked, blade, 0.0019);
  ASSERT_EQ(a.status, "ok") << a.reason;
  ASSERT_EQ(b.status, "ok") << b.reason;
  EXPECT_EQ(checked.cut.surface.vertices, unchecked.cut.surface.vertices);
  EXPECT_EQ(checked.cut.surface.triangles, unchecked.cut.surface.triangles);
  EXPECT_TRUE(checked.cut.surface_checked);
  EXPECT_FALSE(unchecked.cut.surface_checked);
  cutting::CutOptions no_verify;
  no_verify.verify = false;
  ASSERT_EQ(cut(checked, prism(Vec3(0.01, 0.02, 0.002), 0.002, 0.01, 32), 0.0019, no_verify).status, "ok");
  EXPECT_FALSE(checked.cut.surface_checked);
}

}  // namespace
}  // namespace octocut
