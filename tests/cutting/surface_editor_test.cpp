// The face grid and the journaled in-place editor behind the pipeline's local surface cut (SPEC §4 stage 2). The
// truths: a brute-force box test over every triangle, a copy of the mesh taken before the edits, the divergence
// theorem over the whole edited mesh, and an own watertightness check.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <array>
#include <cstdint>
#include <random>
#include <vector>

#include "octocut/cutting/surface_cut.hpp"
#include "octocut/cutting/surface_editor.hpp"
#include "../common/shapes.hpp"
#include "test_meshes.hpp"
#include "watertight.hpp"

namespace octocut {
namespace {

using cutting::FaceAttributes;
using cutting::FaceGrid;
using cutting::SurfaceEditor;
using sim::TriMesh;
using sim::Vec3;
using Tri = std::array<int32_t, 3>;

// The triangles whose bounding boxes meet [lo, hi], by testing every one.
std::vector<int32_t> brute_query(const TriMesh& m, const Vec3& lo, const Vec3& hi) {
  std::vector<int32_t> out;
  for (std::size_t f = 0; f < m.triangles.size(); ++f) {
    const Tri& t = m.triangles[f];
    Vec3 a = m.vertices[std::size_t(t[0])], b = a;
    for (const int32_t v : t) {
      a = a.cwiseMin(m.vertices[std::size_t(v)]);
      b = b.cwiseMax(m.vertices[std::size_t(v)]);
    }
    if ((a.array() <= hi.array()).all() && (b.array() >= lo.array()).all()) out.push_back(int32_t(f));
  }
  return out;
}

// Random boxes around and beyond the mesh (some degenerate to points, some reaching past the grid) against the brute
// force; and the triangles around random vertices.
void expect_grid_matches(FaceGrid& grid, const TriMesh& m, std::mt19937& rng, const std::string& what) {
  const sim::Box3 b = sim::bounds(m);
  const Vec3 size = b.max - b.min;
  std::uniform_real_distribution<double> u(-0.2, 1.2), w(0.0, 0.3);
  for (int q = 0; q < 200; ++q) {
    Vec3 lo, hi;
    for (int k = 0; k < 3; ++k) {
      lo[k] = b.min[k] + u(rng) * size[k];
      hi[k] = lo[k] + (q % 4 == 0 ? 0.0 : w(rng) * size[k]);
    }
    ASSERT_EQ(grid.query(m, lo, hi), brute_query(m, lo, hi)) << what << ": box " << q;
  }
  std::uniform_int_distribution<int32_t> pick(0, int32_t(m.vertices.size()) - 1);
  for (int q = 0; q < 50; ++q) {
    const int32_t v = pick(rng);
    std::vector<int32_t> expected;
    for (std::size_t f = 0; f < m.triangles.size(); ++f) {
      const Tri& t = m.triangles[f];
      if (t[0] == v || t[1] == v || t[2] == v) expected.push_back(int32_t(f));
    }
    ASSERT_EQ(grid.around(m, v), expected) << what << ": vertex " << v;
  }
}

TEST(FaceGrid, QueriesMatchABruteForceBoxTest) {
  std::mt19937 rng(7);
  const TriMesh cube = test::grid_cube(12, 0.01);
  FaceGrid grid;
  grid.build(cube);
  EXPECT_GT(grid.dims()[0] * grid.dims()[1] * grid.dims()[2], 1);
  expect_grid_matches(grid, cube, rng, "cube");
  // A thin, tilted ellipsoid: triangles of very different sizes and boxes spanning many cells.
  const TriMesh e = test::ellipsoid_mesh(Vec3(0.1, -0.2, 0.05), Vec3(0.03, 0.002, 0.01), 48, 24);
  grid.build(e);
  expect_grid_matches(grid, e, rng, "ellipsoid");
}

TEST(FaceGrid, BuildRejectsBadSurfaces) {
  TriMesh m = test::octahedron();
  m.vertices[2].y() = std::nan("");
  FaceGrid grid;
  EXPECT_THROW(grid.build(m), std::invalid_argument);
  m = test::octahedron();
  m.triangles[5][1] = 6;
  EXPECT_THROW(grid.build(m), std::invalid_argument);
}

TEST(SurfaceEditor, EditsKeepTheGridExactAndRollBackBitForBit) {
  std::mt19937 rng(11);
  TriMesh m = test::grid_cube(10, 0.01);
  const TriMesh original = m;
  FaceGrid grid;
  grid.build(m);
  std::vector<char> cut(m.triangles.size(), 0);
  std::vector<int32_t> origin(m.triangles.size());
  for (std::size_t f = 0; f < origin.size(); ++f) origin[f] = int32_t(f);
  const std::vector<char> cut0 = cut;
  const std::vector<int32_t> origin0 = origin;
  SurfaceEditor editor(m, grid, &cut, &origin);

  // Random edits: new vertices, overwritten, appended and removed triangles (not a valid surface; the grid does not
  // care), checked against the brute force after each batch.
  std::size_t middle = 0;
  TriMesh at_middle;
  std::vector<char> cut_middle;
  std::vector<int32_t> origin_middle;
  for (int batch = 0; batch < 6; ++batch) {
    for (int k = 0; k < 40; ++k) {
      std::uniform_int_distribution<int32_t> vertex(0, int32_t(m.vertices.size()) - 1);
      std::uniform_int_distribution<int32_t> face(0, int32_t(m.triangles.size()) - 1);
      const Tri t{vertex(rng), vertex(rng), vertex(rng)};
      switch (rng() % 4) {
        case 0: editor.add_vertex(m.vertices[std::size_t(vertex(rng))] + Vec3(1e-4, -2e-4, 3e-4)); break;
        case 1: editor.set_face(face(rng), t, FaceAttributes{1, -1}); break;
        case 2: {
          const int32_t added = editor.add_face(t, FaceAttributes{1, 7});
          EXPECT_EQ(added, int32_t(m.triangles.size()) - 1);
          EXPECT_EQ(m.triangles.back(), t);
          break;
        }
        default: {
          const int32_t f = face(rng);
          const int32_t last = int32_t(m.triangles.size()) - 1;
          const Tri moved = m.triangles[std::size_t(last)];
          const int32_t from = editor.remove_face(f);
          EXPECT_EQ(from, f == last ? -1 : last);
          if (f != last) {
            EXPECT_EQ(m.triangles[std::size_t(f)], moved);
          }
        }
      }
      ASSERT_EQ(cut.size(), m.triangles.size());
      ASSERT_EQ(origin.size(), m.triangles.size());
    }
    expect_grid_matches(grid, m, rng, "batch " + std::to_string(batch));
    if (batch == 2) {
      middle = editor.mark();
      at_middle = m;
      cut_middle = cut;
      origin_middle = origin;
    }
  }
  // Back to the middle, then to the start: exactly as they were, and the grid with them.
  editor.rollback(middle);
  EXPECT_EQ(m.vertices, at_middle.vertices);
  EXPECT_EQ(m.triangles, at_middle.triangles);
  EXPECT_EQ(cut, cut_middle);
  EXPECT_EQ(origin, origin_middle);
  expect_grid_matches(grid, m, rng, "middle");
  editor.rollback(0);
  EXPECT_EQ(m.vertices, original.vertices);
  EXPECT_EQ(m.triangles, original.triangles);
  EXPECT_EQ(cut, cut0);
  EXPECT_EQ(origin, origin0);
  expect_grid_matches(grid, m, rng, "start");
}

// The used vertices of m, renumbered in order (the owner's compaction, done here independently).
TriMesh without_unused(const TriMesh& m) {
  std::vector<int32_t> index(m.vertices.size(), -1);
  for (const Tri& t : m.triangles)
    for (const int32_t v : t) index[std::size_t(v)] = 0;
  TriMesh out;
  for (std::size_t v = 0; v < m.vertices.size(); ++v) {
    if (index[v] < 0) continue;
    index[v] = int32_t(out.vertices.size());
    out.vertices.push_back(m.vertices[v]);
  }
  for (const Tri& t : m.triangles) out.triangles.push_back({index[std::size_t(t[0])], index[std::size_t(t[1])],
                                                            index[std::size_t(t[2])]});
  return out;
}

TEST(SurfaceCutInPlace, PunchesEditSInPlaceAndRollBack) {
  // A 10 mm cube, two 1 mm-radius, 16-sided punches through it one after the other, then one partly in. Each leaves
  // a watertight S whose volume drops by the prism's (the divergence theorem over the edited mesh: unused vertices do
  // not count); the unused vertices are exactly those no triangle uses; the grid follows.
  std::mt19937 rng(3);
  const double e = 0.01, r = 0.001;
  TriMesh s = test::grid_cube(8, e);
  const TriMesh original = s;
  FaceGrid grid;
  grid.build(s);
  std::vector<char> cut(s.triangles.size(), 0);
  SurfaceEditor editor(s, grid, &cut);
  const double v0 = sim::signed_volume(s);
  const double prism = test::prism_area(r, 16) * e;
  double expected = v0;
  std::vector<int32_t> unused;
  int step = 0;
  for (const Vec3& c : {Vec3(0.0033, 0.0047, 0.005), Vec3(0.0071, 0.0052, 0.005), Vec3(0.0052, 0.0021, 0.009)}) {
    const std::size_t vertices_before = s.vertices.size();
    const TriMesh blade = test::prism_mesh(c, r, 0.014, 16);
    const cutting::SurfaceEditResult res = cutting::cut_surface_in_place(editor, blade);
    ASSERT_EQ(res.status, cutting::SurfaceCutStatus::ok) << res.reason;
    EXPECT_EQ(res.first_inserted, int32_t(vertices_before));
    const double removed = step < 2 ? prism : test::prism_area(r, 16) * (e - (c.z() - 0.007));
    expected -= removed;
    EXPECT_NEAR(res.removed_volume, removed, 1e-9 * prism) << step;
    EXPECT_NEAR(sim::signed_volume(s), expected, 1e-9 * v0) << step;
    // Cut faces: exactly the triangles on the blades' walls and caps.
    for (std::size_t f = 0; f < s.triangles.size(); ++f) {
      const Vec3 mid = (s.vertices[std::size_t(s.triangles[f][0])] + s.vertices[std::size_t(s.triangles[f][1])] +
                        s.vertices[std::size_t(s.triangles[f][2])]) / 3.0;
      const bool inside_box = (mid.array() > 1e-12).all() && (mid.array() < e - 1e-12).all();
      EXPECT_EQ(cut[f] != 0, inside_box) << step << ": triangle " << f;
    }
    unused.insert(unused.end(), res.removed_vertices.begin(), res.removed_vertices.end());
    std::sort(unused.begin(), unused.end());
    std::vector<int32_t> truth;
    std::vector<char> used(s.vertices.size(), 0);
    for (const Tri& t : s.triangles)
      for (const int32_t v : t) used[std::size_t(v)] = 1;
    for (std::size_t v = 0; v < used.size(); ++v)
      if (!used[v]) truth.push_back(int32_t(v));
    EXPECT_EQ(unused, truth) << step;
    test::expect_watertight(without_unused(s), "step " + std::to_string(step));
    expect_grid_matches(grid, s, rng, "step " + std::to_string(step));
    ++step;
  }
  // A blade that misses: no_op, nothing written.
  const TriMesh before = s;
  const auto miss = cutting::cut_surface_in_place(editor, test::prism_mesh(Vec3(0.05, 0.05, 0.05), r, 0.004, 16));
  EXPECT_EQ(miss.status, cutting::SurfaceCutStatus::no_op);
  EXPECT_EQ(s.triangles, before.triangles);
  EXPECT_EQ(s.vertices, before.vertices);
  // An open blade fails and leaves S as it was.
  TriMesh open = test::prism_mesh(Vec3(0.005, 0.005, 0.005), r, 0.014, 16);
  open.triangles.pop_back();
  EXPECT_EQ(cutting::cut_surface_in_place(editor, open).status, cutting::SurfaceCutStatus::failed);
  EXPECT_EQ(s.triangles, before.triangles);
  EXPECT_EQ(s.vertices, before.vertices);
  // The whole journal undone: the original cube, bit for bit, and its grid.
  editor.rollback(0);
  EXPECT_EQ(s.vertices, original.vertices);
  EXPECT_EQ(s.triangles, original.triangles);
  EXPECT_TRUE(std::all_of(cut.begin(), cut.end(), [](char c) { return c == 0; }));
  expect_grid_matches(grid, s, rng, "rolled back");
}

TEST(SurfaceCutInPlace, FarAwayPartsStayUntouched) {
  // The same punch into the cube alone and into the cube with 30 far-away copies of itself: the same patch, the
  // same edit (relative to the cube's triangles), the same volume, and the copies never written. (The time is for
  // the benchmarks: bench_surface_cut's padded mesh.)
  const double e = 0.01;
  const TriMesh one = test::grid_cube(8, e);
  TriMesh many = one;
  for (int k = 1; k <= 30; ++k) {
    const auto offset = int32_t(many.vertices.size());
    for (const Vec3& p : one.vertices) many.vertices.push_back(p + Vec3(0.05 * k, 0.0, 0.0));
    for (const Tri& t : one.triangles) many.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  }
  const TriMesh far = many;
  const TriMesh blade = test::prism_mesh(Vec3(0.0043, 0.0047, 0.005), 0.001, 0.014, 16);
  const auto run = [&](TriMesh& m) {
    FaceGrid grid;
    grid.build(m);
    SurfaceEditor editor(m, grid);
    return cutting::cut_surface_in_place(editor, blade);
  };
  TriMesh a = one;
  const auto ra = run(a);
  const auto rb = run(many);
  ASSERT_EQ(ra.status, cutting::SurfaceCutStatus::ok) << ra.reason;
  ASSERT_EQ(rb.status, cutting::SurfaceCutStatus::ok) << rb.reason;
  EXPECT_EQ(ra.patch_triangles, rb.patch_triangles);
  EXPECT_EQ(ra.removed_volume, rb.removed_volume);
  EXPECT_EQ(ra.removed_vertices, rb.removed_vertices);
  // The copies are untouched (their triangles, as a multiset: a removed slot may have taken one of them), and the
  // cube's part is the edit made on the cube alone (new vertices shifted by the copies' vertices).
  const auto nv1 = int32_t(one.vertices.size()), shift = int32_t(far.vertices.size()) - nv1;
  std::vector<Tri> copies_before, copies_after, cube_alone(a.triangles.begin(), a.triangles.end()), cube_in_many;
  for (const Tri& t : far.triangles)
    if (t[0] >= nv1) copies_before.push_back(t);
  for (Tri t : many.triangles) {
    if (t[0] >= nv1 && t[0] < int32_t(far.vertices.size())) {
      copies_after.push_back(t);
      continue;
    }
    for (int32_t& v : t)
      if (v >= int32_t(far.vertices.size())) v -= shift;
    cube_in_many.push_back(t);
  }
  std::sort(copies_before.begin(), copies_before.end());
  std::sort(copies_after.begin(), copies_after.end());
  EXPECT_EQ(copies_after, copies_before);
  std::sort(cube_alone.begin(), cube_alone.end());
  std::sort(cube_in_many.begin(), cube_in_many.end());
  EXPECT_EQ(cube_in_many, cube_alone);
  EXPECT_EQ(std::vector<Vec3>(many.vertices.begin(), many.vertices.begin() + far.vertices.size()), far.vertices);
}

}  // namespace
}  // namespace octocut
