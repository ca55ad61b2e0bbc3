// The blade solid (SPEC §4 stages 1, 3, 4): inside tests, overlap tests and the inscribed radius against analytic
// truths: closed boxes and their separating axes, half-spaces of convex meshes, 2D point-in-polygon for a star
// prism, distances for a sphere mesh, clipped tet volumes, and the analytic inradii of cylinders, boxes and stars.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <optional>
#include <random>

#include "octocut/cutting/blade.hpp"
#include "../common/kuhn_grid.hpp"
#include "../common/shapes.hpp"
#include "octocut/sim/material_graph.hpp"
#include "test_meshes.hpp"

namespace octocut::cutting {
namespace {

using sim::Box3;
using sim::Mat3;
using sim::TriMesh;
using sim::Vec3;
using Vec2 = Eigen::Vector2d;
using Tet = std::array<Vec3, 4>;

// ---------------------------------------------------------------------------------------------------------------
// Meshes and analytic truths.

/// The prism over a polygon that is star-shaped about the origin (counter-clockwise, m) between z0 and z1 (m):
/// fan caps about the origin and a quad strip, outward oriented.
TriMesh prism(const std::vector<Vec2>& poly, double z0, double z1) {
  TriMesh m;
  const auto n = static_cast<int32_t>(poly.size());
  for (const Vec2& p : poly) m.vertices.emplace_back(p.x(), p.y(), z0);
  for (const Vec2& p : poly) m.vertices.emplace_back(p.x(), p.y(), z1);
  m.vertices.emplace_back(0, 0, z0);
  m.vertices.emplace_back(0, 0, z1);
  const int32_t cb = 2 * n, ct = 2 * n + 1;
  for (int32_t i = 0; i < n; ++i) {
    const int32_t j = (i + 1) % n;
    m.triangles.push_back({cb, j, i});
    m.triangles.push_back({ct, n + i, n + j});
    m.triangles.push_back({i, j, n + j});
    m.triangles.push_back({i, n + j, n + i});
  }
  return m;
}

/// Regular polygon of `segments` vertices on the circle of radius r (m); its inradius is r cos(π / segments).
std::vector<Vec2> regular_polygon(double r, int segments) {
  std::vector<Vec2> p;
  for (int k = 0; k < segments; ++k) {
    const double a = 2.0 * std::numbers::pi * k / segments;
    p.emplace_back(r * std::cos(a), r * std::sin(a));
  }
  return p;
}

/// Star polygon with `points` outer vertices at radius ro and inner vertices at radius ri between them (m).
std::vector<Vec2> star_polygon(double ro, double ri, int points) {
  std::vector<Vec2> p;
  for (int k = 0; k < 2 * points; ++k) {
    const double a = std::numbers::pi * k / points, r = (k % 2 == 0) ? ro : ri;
    p.emplace_back(r * std::cos(a), r * std::sin(a));
  }
  return p;
}

double segment_distance_2d(const Vec2& p, const Vec2& a, const Vec2& b) {
  const double t = std::clamp((p - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
  return (a + t * (b - a) - p).norm();
}

/// Crossing-number point-in-polygon test (generic points only).
bool in_polygon(const std::vector<Vec2>& poly, const Vec2& p) {
  bool in = false;
  for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const Vec2 &a = poly[i], &b = poly[j];
    if ((a.y() > p.y()) != (b.y() > p.y()) && p.x() < (b.x() - a.x()) * (p.y() - a.y()) / (b.y() - a.y()) + a.x())
      in = !in;
  }
  return in;
}

/// Distance from p to the segment ab, m.
double segment_distance(const Vec3& p, const Vec3& a, const Vec3& b) {
  const double t = std::clamp((p - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
  return (a + t * (b - a) - p).norm();
}

/// Distance from p to the solid tetrahedron, m: zero inside, else the nearest of its faces (plane or edges).
double tet_distance(const Vec3& p, const Tet& t) {
  const std::array<std::array<int, 3>, 4> faces{{{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}}};
  // Inside when p is on the side of every face plane that holds the opposite vertex.
  bool inside = true;
  double best = std::numeric_limits<double>::infinity();
  for (int f = 0; f < 4; ++f) {
    const Vec3 &a = t[std::size_t(faces[std::size_t(f)][0])], &b = t[std::size_t(faces[std::size_t(f)][1])],
               &c = t[std::size_t(faces[std::size_t(f)][2])];
    const Vec3 n = (b - a).cross(c - a).normalized();
    if (n.dot(p - a) * n.dot(t[std::size_t(f)] - a) < 0.0) inside = false;
    // The plane's foot point if it lies in the triangle, else the nearest edge.
    const Vec3 foot = p - n.dot(p - a) * n;
    const double s0 = (b - a).cross(foot - a).dot(n), s1 = (c - b).cross(foot - b).dot(n),
                 s2 = (a - c).cross(foot - c).dot(n);
    if ((s0 >= 0 && s1 >= 0 && s2 >= 0) || (s0 <= 0 && s1 <= 0 && s2 <= 0))
      best = std::min(best, std::abs(n.dot(p - a)));
    else
      best = std::min({best, segment_distance(p, a, b), segment_distance(p, b, c), segment_distance(p, c, a)});
  }
  return inside ? 0.0 : best;
}

/// Separation of two convex point sets along candidate axes: the largest gap between their projections over the
/// axes, in m (positive: separated by at least that much; not positive: no axis separates them).
template <std::size_t N, std::size_t M>
double sat_gap(const std::vector<Vec3>& axes, const std::array<Vec3, N>& a, const std::array<Vec3, M>& b) {
  double gap = -std::numeric_limits<double>::infinity();
  for (Vec3 u : axes) {
    if (u.norm() < 1e-9) continue;
    u.normalize();
    double amin = 1e300, amax = -1e300, bmin = 1e300, bmax = -1e300;
    for (const Vec3& p : a) amin = std::min(amin, u.dot(p)), amax = std::max(amax, u.dot(p));
    for (const Vec3& p : b) bmin = std::min(bmin, u.dot(p)), bmax = std::max(bmax, u.dot(p));
    gap = std::max(gap, std::max(amin - bmax, bmin - amax));
  }
  return gap;
}

std::array<Vec3, 8> box_corners(const Box3& b) {
  std::array<Vec3, 8> c{};
  for (int k = 0; k < 8; ++k)
    c[std::size_t(k)] = Vec3((k & 1) ? b.max.x() : b.min.x(), (k & 2) ? b.max.y() : b.min.y(),
                             (k & 4) ? b.max.z() : b.min.z());
  return c;
}

/// The separating-axis gap between two boxes with edge directions `ua` and `ub` (15 axes).
double box_box_gap(const std::array<Vec3, 8>& a, const Mat3& ua, const std::array<Vec3, 8>& b, const Mat3& ub) {
  std::vector<Vec3> axes;
  for (int i = 0; i < 3; ++i) {
    axes.push_back(ua.col(i));
    axes.push_back(ub.col(i));
    for (int j = 0; j < 3; ++j) axes.push_back(ua.col(i).cross(ub.col(j)));
  }
  return sat_gap(axes, a, b);
}

/// The separating-axis gap between an axis-aligned box and a tet (3 + 4 + 18 axes).
double box_tet_gap(const std::array<Vec3, 8>& box, const Tet& t) {
  std::vector<Vec3> axes;
  const std::array<Vec3, 6> e{t[1] - t[0], t[2] - t[0], t[3] - t[0], t[2] - t[1], t[3] - t[1], t[3] - t[2]};
  axes.push_back(e[0].cross(e[1]));
  axes.push_back(e[0].cross(e[2]));
  axes.push_back(e[1].cross(e[2]));
  axes.push_back(e[3].cross(e[4]));
  for (int a = 0; a < 3; ++a) {
    axes.push_back(Vec3::Unit(a));
    for (const Vec3& g : e) axes.push_back(Vec3::Unit(a).cross(g));
  }
  return sat_gap(axes, box, t);
}

TriMesh transformed(TriMesh m, const Mat3& R, const Vec3& t) {
  for (Vec3& v : m.vertices) v = R * v + t;
  return m;
}

Mat3 random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng)).normalized().toRotationMatrix();
}

Tet random_tet(std::mt19937& rng, const Vec3& centre, double size) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Tet t{};
  for (Vec3& p : t) p = centre + size * Vec3(u(rng), u(rng), u(rng));
  return t;
}

// ---------------------------------------------------------------------------------------------------------------
// contains

TEST(BladeContains, BoxLatticeThroughVerticesEdgesAndFaces) {
  // The box [-1, 1]^3 with every face cut into 4 x 4 squares. Probe points on a lattice of step 1/4 reach beyond
  // the box: many lie exactly on faces, edges and vertices (inside, closed) or line up with rows of vertices.
  const BladeVolume blade(test::grid_cube(4, 2.0, Vec3(-1, -1, -1)));
  int checked = 0;
  for (int i = -6; i <= 6; ++i)
    for (int j = -6; j <= 6; ++j)
      for (int k = -6; k <= 6; ++k) {
        const Vec3 p = 0.25 * Vec3(i, j, k);
        const bool truth = p.cwiseAbs().maxCoeff() <= 1.0;
        ASSERT_EQ(blade.contains(p), truth) << p.transpose();
        ++checked;
      }
  EXPECT_EQ(checked, 13 * 13 * 13);
  // Just off the faces, edges and corners.
  for (const Vec3& dir : {Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(1, 1, 1), Vec3(-1, 0.5, 0)}) {
    const Vec3 on = dir / dir.cwiseAbs().maxCoeff();
    EXPECT_TRUE(blade.contains(on));
    EXPECT_TRUE(blade.contains(on * (1.0 - 1e-7)));
    EXPECT_FALSE(blade.contains(on * (1.0 + 1e-7)));
  }
}

TEST(BladeContains, RaysAimedThroughVerticesAndEdgesAreRetried) {
  // Points placed so that the first parity ray of blade.cpp runs exactly through a vertex or the midpoint of an
  // edge of the octahedron; whatever the ray meets, the answer must be the analytic one, |x|_1 <= 1.
  const Vec3 d0 = Vec3(0.5377, 0.8346, 0.1184).normalized();
  const TriMesh oct = test::octahedron(1.0);
  const BladeVolume blade(oct);
  std::vector<Vec3> targets = oct.vertices;
  for (const auto& t : oct.triangles)
    for (int k = 0; k < 3; ++k)
      targets.push_back(0.5 * (oct.vertices[std::size_t(t[std::size_t(k)])] +
                               oct.vertices[std::size_t(t[std::size_t((k + 1) % 3)])]));
  int inside = 0, outside = 0;
  for (const Vec3& v : targets)
    for (double s : {0.1, 0.37, 0.5, 0.9, 1.3, 2.2}) {
      const Vec3 p = v - s * d0;
      const double l1 = p.cwiseAbs().sum();
      if (std::abs(l1 - 1.0) < 1e-9) continue;  // on the surface: covered elsewhere
      const bool truth = l1 < 1.0;
      EXPECT_EQ(blade.contains(p), truth) << p.transpose();
      (truth ? inside : outside)++;
    }
  EXPECT_GT(inside, 5);
  EXPECT_GT(outside, 5);
}

/// A convex UV sphere of radius r (m): its quads are isosceles trapezoids, hence planar, so every split is convex.
TriMesh uv_sphere(double r, int segments = 24, int rings = 12) {
  return test::ellipsoid_mesh(Vec3::Zero(), Vec3::Constant(r), segments, rings);
}

/// Distance from the origin to the nearest face plane of the mesh, m.
double nearest_plane(const TriMesh& m) {
  double r = std::numeric_limits<double>::infinity();
  for (const auto& t : m.triangles) {
    const Vec3& a = m.vertices[std::size_t(t[0])];
    const Vec3 n = (m.vertices[std::size_t(t[1])] - a).cross(m.vertices[std::size_t(t[2])] - a).normalized();
    r = std::min(r, std::abs(n.dot(a)));
  }
  return r;
}

TEST(BladeContains, ConvexSphereMeshMatchesHalfSpaces) {
  // A convex mesh is the intersection of its faces' inner half-spaces.
  const TriMesh sphere = uv_sphere(0.01);
  const BladeVolume blade(sphere);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.012, 0.012);
  int inside = 0;
  for (int n = 0; n < 4000; ++n) {
    const Vec3 p(u(rng), u(rng), u(rng));
    double worst = -1e300;
    for (const auto& t : sphere.triangles) {
      const Vec3& a = sphere.vertices[std::size_t(t[0])];
      const Vec3 nrm = (sphere.vertices[std::size_t(t[1])] - a).cross(sphere.vertices[std::size_t(t[2])] - a).normalized();
      worst = std::max(worst, nrm.dot(p - a));
    }
    if (std::abs(worst) < 1e-12) continue;
    EXPECT_EQ(blade.contains(p), worst < 0.0) << p.transpose();
    inside += worst < 0.0;
  }
  EXPECT_GT(inside, 1000);
  // The vertices are on the surface, hence inside; pushed out by 1e-6 they are outside.
  for (const Vec3& v : sphere.vertices) {
    EXPECT_TRUE(blade.contains(v));
    EXPECT_FALSE(blade.contains(v * (1.0 + 1e-6)));
  }
}

TEST(BladeContains, RotatedStarPrismMatchesPointInPolygon) {
  // A non-convex blade: a 5-pointed star prism, rotated and moved. Truth in the prism's own frame.
  const std::vector<Vec2> star = star_polygon(0.004, 0.0015, 5);
  std::mt19937 rng(11);
  const Mat3 R = random_rotation(rng);
  const Vec3 t(0.02, -0.01, 0.005);
  const BladeVolume blade(transformed(prism(star, -0.003, 0.003), R, t));
  EXPECT_GT(sim::signed_volume(blade.mesh()), 0.0);
  std::uniform_real_distribution<double> u(-0.0045, 0.0045);
  int inside = 0;
  for (int n = 0; n < 4000; ++n) {
    const Vec3 local(u(rng), u(rng), u(rng));
    const bool truth = std::abs(local.z()) < 0.003 && in_polygon(star, local.head<2>());
    EXPECT_EQ(blade.contains(R * local + t), truth) << local.transpose();
    inside += truth;
  }
  EXPECT_GT(inside, 400);
}

// ---------------------------------------------------------------------------------------------------------------
// overlaps_box / overlaps_tet / overlaps_hexahedron

TEST(BladeOverlaps, AxisAlignedBoxBladeAgainstBoxesTouchingCounts) {
  const Box3 solid{Vec3(-1, -1, -1), Vec3(1, 1, 1)};
  const BladeVolume blade(test::grid_cube(3, 2.0, solid.min));
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> c(-2.5, 2.5), e(0.01, 1.5);
  for (int n = 0; n < 3000; ++n) {
    const Vec3 lo(c(rng), c(rng), c(rng));
    const Box3 box{lo, lo + Vec3(e(rng), e(rng), e(rng))};
    const bool truth = (box.min.array() <= solid.max.array()).all() && (solid.min.array() <= box.max.array()).all();
    EXPECT_EQ(blade.overlaps_box(box), truth) << box.min.transpose() << " / " << box.max.transpose();
  }
  // Exactly touching along a face, an edge and a corner counts; a gap of 1e-9 does not.
  EXPECT_TRUE(blade.overlaps_box(Box3{Vec3(1, -0.5, -0.5), Vec3(2, 0.5, 0.5)}));
  EXPECT_TRUE(blade.overlaps_box(Box3{Vec3(1, 1, -0.5), Vec3(2, 2, 0.5)}));
  EXPECT_TRUE(blade.overlaps_box(Box3{Vec3(1, 1, 1), Vec3(2, 2, 2)}));
  EXPECT_FALSE(blade.overlaps_box(Box3{Vec3(1 + 1e-9, -0.5, -0.5), Vec3(2, 0.5, 0.5)}));
  // A box inside the blade, and a box around it, and a flat box (a face) through it.
  EXPECT_TRUE(blade.overlaps_box(Box3{Vec3::Constant(-0.1), Vec3::Constant(0.1)}));
  EXPECT_TRUE(blade.overlaps_box(Box3{Vec3::Constant(-5), Vec3::Constant(5)}));
  EXPECT_TRUE(blade.overlaps_box(Box3{Vec3(0.3, -3, -3), Vec3(0.3, 3, 3)}));
  EXPECT_FALSE(blade.overlaps_box(Box3{Vec3(1, 1, 1), Vec3(0, 0, 0)}));  // min > max: empty
}

TEST(BladeOverlaps, RotatedBoxBladeAgainstBoxesMatchesSeparatingAxes) {
  // An oriented box blade: truth by the 15-axis separating-axis theorem for two boxes, skipping near-contacts.
  std::mt19937 rng(17);
  const Mat3 R = random_rotation(rng);
  const Box3 local{Vec3(-0.002, -0.001, -0.003), Vec3(0.002, 0.001, 0.003)};
  const TriMesh unit = test::grid_cube(2, 1.0);
  TriMesh mesh = unit;
  for (Vec3& v : mesh.vertices) v = R * (local.min + v.cwiseProduct(local.max - local.min));
  const BladeVolume blade(mesh);
  std::array<Vec3, 8> obb = box_corners(local);
  for (Vec3& p : obb) p = R * p;
  std::uniform_real_distribution<double> c(-0.006, 0.004), e(0.0002, 0.003);
  int hits = 0, misses = 0;
  for (int n = 0; n < 4000; ++n) {
    const Vec3 lo(c(rng), c(rng), c(rng));
    const Box3 box{lo, lo + Vec3(e(rng), e(rng), e(rng))};
    const double gap = box_box_gap(obb, R, box_corners(box), Mat3::Identity());
    if (std::abs(gap) < 1e-12) continue;
    EXPECT_EQ(blade.overlaps_box(box), gap < 0.0);
    (gap < 0.0 ? hits : misses)++;
  }
  EXPECT_GT(hits, 300);
  EXPECT_GT(misses, 300);
}

TEST(BladeOverlaps, BoxBladeAgainstTetsMatchesClippedVolumeAndSeparatingAxes) {
  // Truth: a positive clipped volume (sim::clip_tet_box_volume) means overlap; a separating axis with a gap means
  // none. Tets around the blade, inside it, and exactly touching its faces are added.
  const Box3 solid{Vec3(-1, -1, -1), Vec3(1, 1, 1)};
  const BladeVolume blade(test::grid_cube(3, 2.0, solid.min));
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> c(-2.0, 2.0), s(0.05, 1.5);
  int hits = 0, misses = 0;
  for (int n = 0; n < 4000; ++n) {
    const Tet t = random_tet(rng, Vec3(c(rng), c(rng), c(rng)), s(rng));
    const double vol = std::abs((t[1] - t[0]).dot((t[2] - t[0]).cross(t[3] - t[0]))) / 6.0;
    const double gap = box_tet_gap(box_corners(solid), t);
    std::optional<bool> truth;
    if (sim::clip_tet_box_volume(t, solid) > 1e-9 * vol) truth = true;
    else if (gap > 1e-9) truth = false;
    if (!truth) continue;
    EXPECT_EQ(blade.overlaps_tet(t), *truth);
    (*truth ? hits : misses)++;
  }
  EXPECT_GT(hits, 300);
  EXPECT_GT(misses, 300);
  // Degenerate tets: flat (4th corner in the plane of the others) and needle-like (all on a line). Truth by the
  // separating axes alone, which are complete for these shapes too; near-contacts are skipped.
  int flat_hits = 0, flat_misses = 0;
  for (int n = 0; n < 3000; ++n) {
    Tet t = random_tet(rng, Vec3(c(rng), c(rng), c(rng)), s(rng));
    if (n % 3 == 0) t[3] = t[0] + 0.3 * (t[1] - t[0]) + 0.5 * (t[2] - t[0]);
    else if (n % 3 == 1) t[3] = t[0] + 1.7 * (t[1] - t[0]) - 0.4 * (t[2] - t[0]);
    else t[2] = t[0] + 0.4 * (t[1] - t[0]), t[3] = t[0] - 0.6 * (t[1] - t[0]);
    const double gap = box_tet_gap(box_corners(solid), t);
    if (std::abs(gap) < 1e-9) continue;
    EXPECT_EQ(blade.overlaps_tet(t), gap < 0.0) << "degenerate tet " << n;
    (gap < 0.0 ? flat_hits : flat_misses)++;
  }
  EXPECT_GT(flat_hits, 200);
  EXPECT_GT(flat_misses, 200);
  // A tet swallowing the blade (caught by the triangle test) and one inside it (caught by the inside test).
  EXPECT_TRUE(blade.overlaps_tet({Vec3(-10, -10, -10), Vec3(30, -10, -10), Vec3(-10, 30, -10), Vec3(-10, -10, 30)}));
  EXPECT_TRUE(blade.overlaps_tet({Vec3(0, 0, 0), Vec3(0.1, 0, 0), Vec3(0, 0.1, 0), Vec3(0, 0, 0.1)}));
  // Touching the face x = 1 with a vertex, with an edge, with a face; and 1e-9 away.
  EXPECT_TRUE(blade.overlaps_tet({Vec3(1, 0.2, 0.2), Vec3(2, 0, 0), Vec3(2, 1, 0), Vec3(2, 0, 1)}));
  EXPECT_TRUE(blade.overlaps_tet({Vec3(1, 0.2, 0.2), Vec3(1, 0.5, 0.1), Vec3(2, 1, 0), Vec3(2, 0, 1)}));
  EXPECT_TRUE(blade.overlaps_tet({Vec3(1, 0.2, 0.2), Vec3(1, 0.5, 0.1), Vec3(1, 0.1, 0.6), Vec3(2, 0, 1)}));
  EXPECT_FALSE(blade.overlaps_tet({Vec3(1 + 1e-9, 0.2, 0.2), Vec3(2, 0, 0), Vec3(2, 1, 0), Vec3(2, 0, 1)}));
}

TEST(BladeOverlaps, SphereMeshAgainstBoxesAndTetsByDistance) {
  // The mesh lies between its inscribed sphere (radius r_in) and its circumscribed one (R): a cell nearer than
  // r_in to the centre must overlap, one farther than R must not.
  const double R = 0.001;
  // (The bounds hold for any triangulation with vertices on the sphere, convex or not.)
  const TriMesh sphere = test::cube_sphere(5, R);
  const double r_in = nearest_plane(sphere);
  const BladeVolume blade(sphere);
  std::mt19937 rng(29);
  std::uniform_real_distribution<double> c(-0.0025, 0.0025), e(0.00005, 0.0015);
  int hits = 0, misses = 0;
  for (int n = 0; n < 3000; ++n) {
    const Vec3 lo(c(rng), c(rng), c(rng));
    const Box3 box{lo, lo + Vec3(e(rng), e(rng), e(rng))};
    const double d = box.min.cwiseMax(-box.max).cwiseMax(0.0).norm();  // from the origin to the box
    if (d < r_in) {
      EXPECT_TRUE(blade.overlaps_box(box));
      ++hits;
    }
    if (d > R) {
      EXPECT_FALSE(blade.overlaps_box(box));
      ++misses;
    }
    const Tet t = random_tet(rng, lo, e(rng));
    const double dt = tet_distance(Vec3::Zero(), t);
    if (dt < r_in) {
      EXPECT_TRUE(blade.overlaps_tet(t));
      ++hits;
    }
    if (dt > R) {
      EXPECT_FALSE(blade.overlaps_tet(t));
      ++misses;
    }
  }
  EXPECT_GT(hits, 500);
  EXPECT_GT(misses, 500);
}

TEST(BladeOverlaps, HexahedronOfABoxEqualsTheBoxAndDegenerateOnesAreSafe) {
  const BladeVolume blade(test::cube_sphere(4, 1.0));
  std::mt19937 rng(31);
  std::uniform_real_distribution<double> c(-1.8, 1.2), e(0.05, 0.8);
  for (int n = 0; n < 2000; ++n) {
    const Vec3 lo(c(rng), c(rng), c(rng));
    const Box3 box{lo, lo + Vec3(e(rng), e(rng), e(rng))};
    EXPECT_EQ(blade.overlaps_hexahedron(box_corners(box)), blade.overlaps_box(box));
  }
  // Mirrored (inverted) hexahedron: the same point set, the same answer.
  const Box3 box{Vec3(0.8, 0.1, 0.1), Vec3(1.4, 0.5, 0.3)};
  std::array<Vec3, 8> corners = box_corners(box);
  std::array<Vec3, 8> mirrored{};
  for (int k = 0; k < 8; ++k) mirrored[std::size_t(k)] = corners[std::size_t(k ^ 1)];
  EXPECT_TRUE(blade.overlaps_hexahedron(mirrored));
  // Collapsed to a point inside / outside, flattened to a square across the blade, and non-finite.
  std::array<Vec3, 8> point{};
  point.fill(Vec3(0.2, 0.1, 0.0));
  EXPECT_TRUE(blade.overlaps_hexahedron(point));
  point.fill(Vec3(2.0, 0.1, 0.0));
  EXPECT_FALSE(blade.overlaps_hexahedron(point));
  std::array<Vec3, 8> flat = box_corners(Box3{Vec3(-3, -3, 0.5), Vec3(3, 3, 0.5)});
  EXPECT_TRUE(blade.overlaps_hexahedron(flat));
  flat = box_corners(Box3{Vec3(-3, -3, 1.5), Vec3(3, 3, 1.5)});
  EXPECT_FALSE(blade.overlaps_hexahedron(flat));
  std::array<Vec3, 8> nan = corners;
  nan[3].x() = std::nan("");
  EXPECT_FALSE(blade.overlaps_hexahedron(nan));
  // A "bow-tie": the top face twisted by 180° about the vertical axis, so that the element passes through itself.
  std::array<Vec3, 8> twisted = box_corners(Box3{Vec3(-0.2, -0.2, -0.2), Vec3(0.2, 0.2, 0.2)});
  for (int k = 4; k < 8; ++k) twisted[std::size_t(k)].head<2>() *= -1.0;
  EXPECT_TRUE(blade.overlaps_hexahedron(twisted));
}

TEST(BladeVolume, RejectsBadMeshes) {
  TriMesh m = test::octahedron();
  m.vertices[2].y() = std::nan("");
  EXPECT_THROW(BladeVolume{m}, std::invalid_argument);
  m = test::octahedron();
  m.triangles[0][1] = 99;
  EXPECT_THROW(BladeVolume{m}, std::invalid_argument);
  EXPECT_THROW(BladeVolume{TriMesh{}}, std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------------------------
// inscribed_radius

struct InradiusCase {
  const char* name;
  TriMesh mesh;
  double truth;  // m
};

TEST(InscribedRadius, MatchesAnalyticValuesWithinOnePercent) {
  std::vector<InradiusCase> cases;
  const int seg = 48;
  const double cosn = std::cos(std::numbers::pi / seg);
  // Cylinders: a tall punch (radius wins) and a flat disc (half the height wins).
  cases.push_back({"tall cylinder", prism(regular_polygon(0.001, seg), -0.004, 0.004), 0.001 * cosn});
  cases.push_back({"flat disc", prism(regular_polygon(0.003, seg), 0.0, 0.002), 0.001});
  // A 1 x 2 x 3 mm box: half its smallest edge.
  TriMesh box = test::grid_cube(3, 1.0);
  for (Vec3& v : box.vertices) v = v.cwiseProduct(Vec3(0.002, 0.001, 0.003));
  cases.push_back({"box", box, 0.0005});
  // A convex UV sphere: its inscribed balls form a convex set invariant under the mesh's symmetries (rotation by
  // 2π/segments about z, reflection in z = 0), so the origin is a centre; the ball touches the nearest face plane.
  const TriMesh sphere = uv_sphere(0.002, 32, 16);
  cases.push_back({"sphere", sphere, nearest_plane(sphere)});
  // A tall star prism: the distance from the centre to the nearest edge of the star polygon.
  const std::vector<Vec2> star = star_polygon(0.004, 0.0015, 5);
  double r_star = 1.0;
  for (std::size_t i = 0; i < star.size(); ++i)
    r_star = std::min(r_star, segment_distance_2d(Vec2::Zero(), star[i], star[(i + 1) % star.size()]));
  cases.push_back({"star prism", prism(star, -0.005, 0.005), r_star});
  // A short star prism: half the height wins.
  cases.push_back({"short star prism", prism(star, 0.0, 0.0008), 0.0004});

  // Each also rotated and moved, so that no medial ridge lines up with the search lattice.
  std::mt19937 rng(41);
  const std::size_t n = cases.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Mat3 R = random_rotation(rng);
    cases.push_back({cases[i].name, transformed(cases[i].mesh, R, Vec3(0.01, 0.03, -0.02)), cases[i].truth});
  }
  for (const auto& c : cases) {
    ASSERT_GT(sim::signed_volume(c.mesh), 0.0) << c.name;
    const auto t0 = std::chrono::steady_clock::now();
    const double r = inscribed_radius(c.mesh);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    std::printf("inscribed_radius %-18s %3zu triangles: r = %.6g m, truth %.6g m, error %+.5f%%, %.1f ms\n", c.name,
                c.mesh.triangles.size(), r, c.truth, 100.0 * (r / c.truth - 1.0), ms);
    EXPECT_NEAR(r, c.truth, 0.01 * c.truth) << c.name;
    // The value is attained by a ball inside the solid, so it cannot exceed the truth (beyond the tolerance).
    EXPECT_LE(r, c.truth * (1.0 + 1e-8)) << c.name;
  }
}

// ---------------------------------------------------------------------------------------------------------------
// tets_touched and timings


TEST(TetsTouched, BoxBladeMatchesBruteForceTruth) {
  // M: 13^3 x 6 = 13182 tets over a 4 cm cube; the blade: a 3 x 2 x 5 mm box. Truth per tet from the clipped volume
  // and separating axes, as above; every tet must be classified.
  const sim::MaterialGraph graph(test::kuhn_box(Box3{Vec3::Zero(), Vec3::Constant(0.04)}, 13, 0.3, 5));
  ASSERT_EQ(graph.num_tets(), 13182);
  const Box3 solid{Vec3(0.0113, 0.0171, 0.0052), Vec3(0.0143, 0.0191, 0.0102)};
  TriMesh mesh = test::grid_cube(2, 1.0);
  for (Vec3& v : mesh.vertices) v = solid.min + v.cwiseProduct(solid.max - solid.min);
  const BladeVolume blade(mesh);
  std::vector<int> truth;
  int ambiguous = 0;
  for (int t = 0; t < graph.num_tets_total(); ++t) {
    const Tet p = graph.tet(t);
    if (sim::clip_tet_box_volume(p, solid) > 1e-9 * graph.tet_volume(t)) truth.push_back(t);
    else if (!(box_tet_gap(box_corners(solid), p) > 1e-12)) ++ambiguous;
  }
  EXPECT_EQ(ambiguous, 0);
  ASSERT_GT(truth.size(), 20u);
  EXPECT_EQ(tets_touched(graph, blade), truth);

  // Dead tets are not reported.
  const auto cut = graph.without(truth);
  EXPECT_TRUE(tets_touched(*cut, blade).empty());
}

TEST(TetsTouched, TimingOfATwoMillimetrePunch) {
  // A 2 mm cylinder of 50 segments (200 triangles) against the 1000 cells of a 10^3 grid of 0.3 mm cells around it
  // (as boxes and as hexahedra), 1000 tets (one per cell), and tets_touched on a 13k-tet M of 1.5 mm cells.
  // Timed loops; the thresholds are loose (shared 2-core machines), the printout is the measurement.
  const Vec3 centre = Vec3::Constant(0.02);
  const BladeVolume blade(transformed(prism(regular_polygon(0.001, 50), -0.001, 0.001), Mat3::Identity(), centre));
  ASSERT_EQ(blade.mesh().triangles.size(), 200u);
  std::mt19937 rng(43);
  std::vector<Box3> boxes;
  std::vector<Tet> tets;
  const double h = 0.0003;
  for (int k = 0; k < 10; ++k)
    for (int j = 0; j < 10; ++j)
      for (int i = 0; i < 10; ++i) {
        const Vec3 lo = centre + h * Vec3(i - 5, j - 5, k - 5);
        boxes.push_back(Box3{lo, lo + Vec3::Constant(h)});
        tets.push_back(random_tet(rng, lo + Vec3::Constant(0.5 * h), 0.5 * h));
      }
  // Each workload is timed 20 times and the fastest run is reported: the other builds on the machine only add.
  auto fastest_ms = [](auto&& work) {
    double best = std::numeric_limits<double>::infinity();
    for (int r = 0; r < 20; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      work();
      best = std::min(best, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    }
    return best;
  };
  int hits_box = 0, hits_tet = 0, hits_hex = 0;
  const double ms_box = fastest_ms([&] {
    hits_box = 0;
    for (const Box3& b : boxes) hits_box += blade.overlaps_box(b);
  });
  const double ms_tet = fastest_ms([&] {
    hits_tet = 0;
    for (const Tet& t : tets) hits_tet += blade.overlaps_tet(t);
  });
  const double ms_hex = fastest_ms([&] {
    hits_hex = 0;
    for (const Box3& b : boxes) hits_hex += blade.overlaps_hexahedron(box_corners(b));
  });
  const sim::MaterialGraph graph(test::kuhn_box(Box3{Vec3::Constant(0.01), Vec3::Constant(0.03)}, 13, 0.3, 7));
  std::size_t touched = 0;
  const double ms_touched = fastest_ms([&] { touched = tets_touched(graph, blade).size(); });
  std::printf("fastest of 20: 1000 overlaps_box %.3f ms (%d hits); 1000 overlaps_tet %.3f ms (%d hits); 1000 "
              "overlaps_hexahedron %.3f ms (%d hits); tets_touched on %d tets %.4f ms (%zu tets)\n",
              ms_box, hits_box, ms_tet, hits_tet, ms_hex, hits_hex, graph.num_tets(), ms_touched, touched);
  EXPECT_EQ(hits_hex, hits_box);
  EXPECT_GT(hits_box, 200);
  EXPECT_LT(hits_box, 800);
  EXPECT_GT(touched, 20u);
#ifdef NDEBUG  // optimised builds only: Debug and sanitizer builds are 10-100x slower
  EXPECT_LT(ms_box, 5.0);
  EXPECT_LT(ms_tet, 5.0);
  EXPECT_LT(ms_touched, 1.0);
#endif
}

}  // namespace
}  // namespace octocut::cutting
