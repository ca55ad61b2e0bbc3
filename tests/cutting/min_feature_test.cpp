// The minimum feature size of cuts (cutting.min_feature, removes_only_subfeature): a blade that would shave only a
// shell thinner than min_feature off S is recognised before any exact arithmetic, and never one that removes more.
// The independent truth is the exact boolean (cut_surface) and the geometry of the configurations: a re-punch of a
// hole removes nothing; one shifted by d removes a crescent at most d thick, whose volume is below min_feature times
// the blade's wall inside the material; a blade shifted by more, a blade deep in the material or thinner than
// 2 min_feature removes real material.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <set>

#include "octocut/cutting/surface_cut.hpp"
#include "octocut/cutting/surface_editor.hpp"
#include "octocut/sim/primitives.hpp"
#include "octocut/sim/surface.hpp"
#include "../common/shapes.hpp"

namespace octocut::cutting {
namespace {

using sim::TriMesh;
using sim::Vec3;

constexpr double kRadius = 1e-3;      // the punch, m
constexpr double kThickness = 4e-3;   // the slab, m
constexpr double kFeature = 1e-4;     // min_feature, m
const Vec3 kAxis(0.0101, 0.0103, 0.002);  // the punch's centre, m

// The 2 x 2 x 0.4 cm slab with one 2 mm punch hole through it (the exact boolean of the punch).
class MinFeature : public ::testing::Test {
 protected:
  void SetUp() override {
    const TriMesh slab = sim::closed_box_grid({Vec3::Zero(), Vec3(0.02, 0.02, kThickness)}, 8);
    const SurfaceCutResult first = cut_surface(slab, punch(Vec3::Zero()));
    ASSERT_EQ(first.status, SurfaceCutStatus::ok) << first.reason;
    holed = first.mesh;
    grid.build(holed);
  }
  static TriMesh punch(const Vec3& shift, double height = 0.02) {
    return test::prism_mesh(kAxis + shift, kRadius, height, 32);
  }
  bool subfeature(const TriMesh& blade, double min_feature = kFeature) {
    return removes_only_subfeature(holed, grid, blade, min_feature);
  }
  TriMesh holed;
  FaceGrid grid;
};

TEST_F(MinFeature, ARepunchOfTheHoleIsAShellAndTheExactBooleanAgrees) {
  EXPECT_TRUE(subfeature(punch(Vec3::Zero())));
  EXPECT_EQ(cut_surface(holed, punch(Vec3::Zero())).status, SurfaceCutStatus::no_op);
  // Off: never.
  EXPECT_FALSE(subfeature(punch(Vec3::Zero()), 0.0));
}

TEST_F(MinFeature, ARepunchBesideTheHoleBySubFeatureDistancesIsAShellWithinTheTolerance) {
  for (const double d : {1e-9, 3e-6, 3e-5, 9e-5}) {
    const Vec3 shift = d * Vec3(0.6, 0.8, 0.0);
    EXPECT_TRUE(subfeature(punch(shift))) << d;
    // What the exact boolean would remove: a crescent at most d thick, within the documented tolerance (min_feature
    // times the blade's wall inside the material, 2 pi r h).
    const SurfaceCutResult exact = cut_surface(holed, punch(shift));
    ASSERT_EQ(exact.status, SurfaceCutStatus::ok) << d << ": " << exact.reason;
    EXPECT_GT(exact.removed_volume, 0.0) << d;
    EXPECT_LE(exact.removed_volume, kFeature * 2.0 * std::numbers::pi * kRadius * kThickness) << d;
    EXPECT_LE(exact.removed_volume, 2.0 * kRadius * d * kThickness * 1.01) << d;  // the lune of two circles, ~2 r d h
  }
}

TEST_F(MinFeature, ABiteDeeperThanTheFeatureSizeIsACut) {
  for (const double d : {1.2e-4, 3e-4, 1e-3}) {
    EXPECT_FALSE(subfeature(punch(d * Vec3(0.6, 0.8, 0.0)))) << d;
  }
  // A fresh punch elsewhere, and a blade buried in the material (a cavity), remove real material.
  EXPECT_FALSE(subfeature(punch(Vec3(0.005, 0.0, 0.0))));
  EXPECT_FALSE(subfeature(test::prism_mesh(Vec3(0.005, 0.005, 0.002), kRadius, 2e-3, 32)));
}

TEST_F(MinFeature, ABladeInTheAirIsAShell) {
  const TriMesh air = test::prism_mesh(Vec3(0.01, 0.01, 0.01), kRadius, 2e-3, 32);
  EXPECT_TRUE(subfeature(air));
  EXPECT_EQ(cut_surface(holed, air).status, SurfaceCutStatus::no_op);
}

TEST_F(MinFeature, ThinAndNonConvexBladesAreNeverShells) {
  // A slice 0.15 mm thick (less than 2 min_feature) through the slab: a real cut.
  TriMesh slice = sim::closed_box_grid({Vec3(0.004, -0.001, -0.001), Vec3(0.00415, 0.021, 0.005)}, 1);
  EXPECT_FALSE(subfeature(slice));
  EXPECT_GT(cut_surface(holed, slice).removed_volume, 0.0);
  // Two punches in one blade (not convex), both exactly on the hole: not tested, so not a shell.
  TriMesh two = punch(Vec3::Zero());
  const TriMesh other = punch(Vec3(0.0, 0.0, 0.03));
  const auto shift = static_cast<int32_t>(two.vertices.size());
  two.vertices.insert(two.vertices.end(), other.vertices.begin(), other.vertices.end());
  for (auto t : other.triangles) two.triangles.push_back({t[0] + shift, t[1] + shift, t[2] + shift});
  EXPECT_FALSE(subfeature(two));
}

// The quality figures of the new triangles (the report's cuts[].min_angle_deg and min_edge_m), recomputed from the
// result: the triangles of S' whose vertex positions are not those of a face of S.
TEST_F(MinFeature, NewTriangleQualityMatchesTheResult) {
  const TriMesh blade = punch(Vec3(4e-4, 0.0, 0.0));
  const SurfaceCutResult r = cut_surface(holed, blade);
  ASSERT_EQ(r.status, SurfaceCutStatus::ok) << r.reason;
  std::set<std::array<std::array<double, 3>, 3>> old_faces;
  const auto key = [](const TriMesh& m, const std::array<int32_t, 3>& t) {
    std::array<std::array<double, 3>, 3> k;
    for (int i = 0; i < 3; ++i) {
      const Vec3& p = m.vertices[static_cast<std::size_t>(t[static_cast<std::size_t>(i)])];
      k[static_cast<std::size_t>(i)] = {p.x(), p.y(), p.z()};
    }
    std::sort(k.begin(), k.end());
    return k;
  };
  for (const auto& t : holed.triangles) old_faces.insert(key(holed, t));
  int n = 0;
  double min_angle = 180.0, min_edge = 1.0;
  for (const auto& t : r.mesh.triangles) {
    if (old_faces.count(key(r.mesh, t)) != 0) continue;
    ++n;
    for (int k = 0; k < 3; ++k) {
      const Vec3& a = r.mesh.vertices[static_cast<std::size_t>(t[static_cast<std::size_t>(k)])];
      const Vec3& b = r.mesh.vertices[static_cast<std::size_t>(t[static_cast<std::size_t>((k + 1) % 3)])];
      const Vec3& c = r.mesh.vertices[static_cast<std::size_t>(t[static_cast<std::size_t>((k + 2) % 3)])];
      min_edge = std::min(min_edge, (b - a).norm());
      min_angle = std::min(min_angle, std::atan2((b - a).cross(c - a).norm(), (b - a).dot(c - a)) * 180.0 /
                                          std::numbers::pi);
    }
  }
  ASSERT_GT(n, 0);
  EXPECT_EQ(r.new_triangles, n);
  EXPECT_NEAR(r.min_edge, min_edge, 1e-12 * min_edge);
  EXPECT_NEAR(r.min_angle_deg, min_angle, 1e-9 * std::max(1.0, min_angle));
}

}  // namespace
}  // namespace octocut::cutting
