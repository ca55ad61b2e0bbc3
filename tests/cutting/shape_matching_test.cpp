// Shape matching for the back-transform (SPEC §4 stage 1, paper §4.1): exact recovery of known affine maps, the
// blend towards the rotation against closed-form blend factors, and the rejection of degenerate input.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <cmath>
#include <random>

#include "octocut/cutting/shape_matching.hpp"
#include "octocut/sim/hex_element.hpp"
#include "test_meshes.hpp"

namespace octocut::cutting {
namespace {

using sim::Mat3;
using sim::Vec3;

Mat3 random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng)).normalized().toRotationMatrix();
}

double cond(const Mat3& A) {
  const Vec3 s = Eigen::JacobiSVD<Mat3>(A).singularValues();
  return s[0] / s[2];
}

/// Rest points of a 2 x 2 x 2 block of hexahedra (27 slots) of edge h around `origin`, jittered, and weights.
struct PointSet {
  std::vector<Vec3> rest;      // m
  std::vector<double> weight;  // kg
};

PointSet block(std::mt19937& rng, const Vec3& origin, double h) {
  std::uniform_real_distribution<double> j(-0.1, 0.1), w(0.5, 2.0);
  PointSet s;
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k)
      for (int l = 0; l < 3; ++l) {
        s.rest.push_back(origin + h * Vec3(i + j(rng), k + j(rng), l + j(rng)));
        s.weight.push_back(w(rng));
      }
  return s;
}

std::vector<Vec3> mapped(const std::vector<Vec3>& rest, const Mat3& A, const Vec3& t) {
  std::vector<Vec3> out;
  for (const Vec3& q : rest) out.push_back(A * q + t);
  return out;
}

TEST(ShapeMatching, RecoversAWellConditionedAffineMapExactly) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> sv(0.4, 3.0), tr(-0.05, 0.05);
  for (int trial = 0; trial < 50; ++trial) {
    // A = R1 diag(s) R2 with cond < 10 and det > 0, and a random translation.
    Vec3 s(sv(rng), sv(rng), sv(rng));
    if (s.maxCoeff() / s.minCoeff() >= 9.9) continue;
    const Mat3 A = random_rotation(rng) * s.asDiagonal() * random_rotation(rng);
    const Vec3 t(tr(rng), tr(rng), tr(rng));
    const PointSet p = block(rng, Vec3(0.01, -0.02, 0.03), 0.004);
    const std::vector<Vec3> x = mapped(p.rest, A, t);
    const ShapeMatch m = shape_match(p.rest, x, p.weight);
    EXPECT_LT((m.A - A).norm(), 1e-10 * A.norm()) << "trial " << trial;
    EXPECT_EQ(m.blend, 0.0);
    EXPECT_NEAR(m.condition, s.maxCoeff() / s.minCoeff(), 1e-8);
    // The map sends the rest centroid to the deformed one, and to_rest inverts it at every point.
    EXPECT_LT((A * m.c_rest + t - m.c_deformed).norm(), 1e-14);
    for (std::size_t i = 0; i < x.size(); ++i) EXPECT_LT((to_rest(m, x[i]) - p.rest[i]).norm(), 1e-13);
  }
}

TEST(ShapeMatching, PureRotationGivesTheRotation) {
  std::mt19937 rng(2);
  const Mat3 R = random_rotation(rng);
  const PointSet p = block(rng, Vec3::Zero(), 0.01);
  const ShapeMatch m = shape_match(p.rest, mapped(p.rest, R, Vec3(1, 2, 3)), p.weight);
  EXPECT_LT((m.A - R).norm(), 1e-12);
  EXPECT_NEAR(m.condition, 1.0, 1e-12);
  EXPECT_EQ(m.blend, 0.0);
}

TEST(ShapeMatching, NearFlatteningIsBlendedTowardsItsRotationMinimally) {
  // A = R diag(1.5, 1, 0.01): cond 150. Blended: cond exactly 10 at the smallest blend, det > 0, the same rotation.
  std::mt19937 rng(3);
  const Mat3 R = random_rotation(rng), V = random_rotation(rng);
  const Mat3 A = R * Vec3(1.5, 1.0, 0.01).asDiagonal() * V;
  const PointSet p = block(rng, Vec3(0.1, 0.1, 0.1), 0.003);
  const ShapeMatch m = shape_match(p.rest, mapped(p.rest, A, Vec3::Zero()), p.weight);
  EXPECT_NEAR(m.condition, 150.0, 1e-6);
  EXPECT_GT(m.blend, 0.0);
  EXPECT_LT(m.blend, 1.0);
  EXPECT_LE(cond(m.A), 10.0);
  EXPECT_NEAR(cond(m.A), 10.0, 1e-6);
  EXPECT_GT(m.A.determinant(), 0.0);
  // The blend is (1 − β) A + β R_A, and no smaller β would do.
  const Mat3 RA = sim::polar_rotation(A);
  EXPECT_LT((m.A - ((1.0 - m.blend) * A + m.blend * RA)).norm(), 1e-12);
  EXPECT_GT(cond((1.0 - (m.blend - 1e-6)) * A + (m.blend - 1e-6) * RA), 10.0);
  // The rotation is kept: the polar rotation of the result is that of the fit, R V.
  EXPECT_LT((sim::polar_rotation(m.A) - R * V).norm(), 1e-9);
}

TEST(ShapeMatching, ExactFlatteningBlendsByTheClosedFormFactor) {
  // Deformed points on a plane: A = R diag(2, 1, 0) V, cond = inf. The blend's singular values are
  // 2(1 − β) + β, (1 − β) + β = 1 and β; cond 10 needs (2 − β) = 10 β, so β = 2/11.
  std::mt19937 rng(4);
  const Mat3 R = random_rotation(rng), V = random_rotation(rng);
  const Mat3 A = R * Vec3(2.0, 1.0, 0.0).asDiagonal() * V;
  const PointSet p = block(rng, Vec3::Zero(), 0.01);
  const ShapeMatch m = shape_match(p.rest, mapped(p.rest, A, Vec3(0.5, 0, 0)), p.weight);
  EXPECT_TRUE(std::isinf(m.condition) || m.condition > 1e12);
  EXPECT_NEAR(m.blend, 2.0 / 11.0, 1e-8);
  EXPECT_LE(cond(m.A), 10.0);
  EXPECT_GT(m.A.determinant(), 0.0);
  EXPECT_LT((Eigen::JacobiSVD<Mat3>(m.A).singularValues() - Vec3(20.0 / 11.0, 1.0, 2.0 / 11.0)).norm(), 1e-8);
}

TEST(ShapeMatching, CollapseToAPointUsesThePureRotation) {
  // Every deformed point in one place: A = 0 up to rounding has no shape to keep; the result is a rotation, blend 1.
  std::mt19937 rng(5);
  const PointSet p = block(rng, Vec3::Zero(), 0.01);
  const std::vector<Vec3> x(p.rest.size(), Vec3(0.3, 0.2, 0.1));
  const ShapeMatch m = shape_match(p.rest, x, p.weight);
  EXPECT_EQ(m.blend, 1.0);
  EXPECT_LT((m.A.transpose() * m.A - Mat3::Identity()).norm(), 1e-14);
  EXPECT_NEAR(m.A.determinant(), 1.0, 1e-14);
  EXPECT_LT((to_rest(m, Vec3(0.3, 0.2, 0.1)) - m.c_rest).norm(), 1e-15);
  // Collapsed by a factor of 1e12 (beyond any physical compression): the same.
  const std::vector<Vec3> tiny = mapped(p.rest, 1e-12 * Mat3::Identity(), Vec3(0.3, 0.2, 0.1));
  const ShapeMatch mt = shape_match(p.rest, tiny, p.weight);
  EXPECT_EQ(mt.blend, 1.0);
  EXPECT_NEAR(mt.A.determinant(), 1.0, 1e-14);
}

TEST(ShapeMatching, InvertedFitsComeOutPositive) {
  std::mt19937 rng(6);
  const PointSet p = block(rng, Vec3::Zero(), 0.01);
  const Mat3 R = random_rotation(rng), V = random_rotation(rng);
  // A reflection, s = (1, 1, −1): (1 − β)(−1) + β = 1/10 gives β = 0.55.
  ShapeMatch m = shape_match(p.rest, mapped(p.rest, R * Vec3(1, 1, -1).asDiagonal() * V, Vec3::Zero()), p.weight);
  EXPECT_NEAR(m.blend, 0.55, 1e-8);
  EXPECT_GT(m.A.determinant(), 0.0);
  EXPECT_LE(cond(m.A), 10.0);
  // A mildly inverted fit, s = (2, 1, −0.5): (1 − β) 2 + β = 10 ((1 − β)(−0.5) + β) gives β = 7/16.
  m = shape_match(p.rest, mapped(p.rest, R * Vec3(2, 1, -0.5).asDiagonal() * V, Vec3::Zero()), p.weight);
  EXPECT_NEAR(m.condition, 4.0, 1e-9);  // well conditioned, blended only for the sign
  EXPECT_NEAR(m.blend, 7.0 / 16.0, 1e-8);
  EXPECT_GT(m.A.determinant(), 0.0);
  EXPECT_LE(cond(m.A), 10.0);
}

TEST(ShapeMatching, BladeMappedToRestKeepsOrientationAndScalesVolume) {
  // B' = A^-1 (B − c_p) + c_q: an outward mesh stays outward and its volume divides by det A.
  std::mt19937 rng(7);
  const Mat3 A = random_rotation(rng) * Vec3(1.3, 0.9, 0.6).asDiagonal() * random_rotation(rng);
  const PointSet p = block(rng, Vec3::Zero(), 0.01);
  const ShapeMatch m = shape_match(p.rest, mapped(p.rest, A, Vec3(0.01, 0.02, 0.0)), p.weight);
  const sim::TriMesh blade = test::cube_sphere(3, 0.002);
  const sim::TriMesh rest = to_rest(m, blade);
  EXPECT_NEAR(sim::signed_volume(rest), sim::signed_volume(blade) / A.determinant(),
              1e-10 * sim::signed_volume(blade));
  for (std::size_t i = 0; i < blade.vertices.size(); ++i)
    EXPECT_LT((rest.vertices[i] - to_rest(m, blade.vertices[i])).norm(), 1e-15);
}

TEST(ShapeMatching, DegenerateInputIsRejectedWithAReason) {
  std::mt19937 rng(8);
  const PointSet p = block(rng, Vec3::Zero(), 0.01);
  const std::vector<Vec3>& q = p.rest;
  const std::vector<double>& w = p.weight;
  auto throws_with = [](auto&& f, const std::string& what) {
    try {
      f();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what()).find(what) != std::string::npos;
    }
    return false;
  };
  // Three points, coplanar points, all weights zero, a NaN, sizes that differ, a negative weight.
  const std::vector<Vec3> three(q.begin(), q.begin() + 3);
  EXPECT_TRUE(throws_with([&] { (void)shape_match(three, three, std::vector<double>(3, 1.0)); }, "fewer than 4"));
  std::vector<Vec3> flat = q;
  for (Vec3& v : flat) v.z() = 0.0;
  EXPECT_TRUE(throws_with([&] { (void)shape_match(flat, flat, w); }, "do not span 3D"));
  EXPECT_TRUE(throws_with([&] { (void)shape_match(q, q, std::vector<double>(q.size(), 0.0)); }, "sum to zero"));
  std::vector<Vec3> nan = q;
  nan[4].y() = std::nan("");
  EXPECT_TRUE(throws_with([&] { (void)shape_match(q, nan, w); }, "not finite"));
  EXPECT_TRUE(throws_with([&] { (void)shape_match(q, three, w); }, "deformed points"));
  std::vector<double> neg = w;
  neg[2] = -1.0;
  EXPECT_TRUE(throws_with([&] { (void)shape_match(q, q, neg); }, "negative"));
  // Weights that leave only a coplanar subset in play (one layer of the block, flattened) are as degenerate.
  std::vector<Vec3> layered = q;
  std::vector<double> layer_weight(q.size(), 0.0);
  for (std::size_t i = 0; i < q.size(); i += 3) {
    layered[i].z() = 0.0;
    layer_weight[i] = 1.0;
  }
  EXPECT_TRUE(throws_with([&] { (void)shape_match(layered, layered, layer_weight); }, "do not span 3D"));
}

}  // namespace
}  // namespace octocut::cutting
