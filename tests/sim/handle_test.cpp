// Handle motion (HandleSpec::position): the keyframed pose of sim/pose.hpp about the box centre, checked against
// rotations written out by hand.
#include <numbers>

#include "test_util.hpp"

namespace octocut::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// A handle on the unit box [0, 2]^3 (centre (1, 1, 1)).
HandleSpec handle(std::vector<PoseKeyframe> keys) { return {{Vec3::Zero(), Vec3::Constant(2.0)}, std::move(keys)}; }

// The handle's rotation at t, read off from where it moves the centre and the unit steps along the axes.
Mat3 rotation_at(const HandleSpec& h, double t) {
  const Vec3 c = 0.5 * (h.box.min + h.box.max);
  Mat3 R;
  for (int i = 0; i < 3; ++i) R.col(i) = h.position(c + Vec3::Unit(i), t) - h.position(c, t);
  return R;
}

TEST(Handle, TwoAxisRotationIsInterpolatedAboutOneFixedAxis) {
  // Euler (90, 90, 0) degrees: R = Ry(90) Rx(90), a rotation by 120 degrees about (1, 1, -1) / sqrt 3.
  const HandleSpec h = handle({{1.0, Vec3::Zero(), Vec3(90, 90, 0)}});
  Mat3 R1;
  R1 << 0, 1, 0,  //
      0, 0, -1,   //
      -1, 0, 0;
  EXPECT_TRUE(rotation_at(h, 1.0).isApprox(R1, test::kExact)) << rotation_at(h, 1.0);
  const Vec3 axis = Vec3(1, 1, -1).normalized();
  ASSERT_TRUE((R1 * axis).isApprox(axis, test::kExact));
  ASSERT_NEAR(std::acos(0.5 * (R1.trace() - 1.0)), 120.0 * kDeg, 1e-12);

  // Halfway, half the angle about the same axis; a quarter of the way, a quarter of it.
  const Mat3 half = Eigen::AngleAxisd(60.0 * kDeg, axis).toRotationMatrix();
  const Mat3 quarter = Eigen::AngleAxisd(30.0 * kDeg, axis).toRotationMatrix();
  EXPECT_TRUE(rotation_at(h, 0.5).isApprox(half, test::kExact)) << rotation_at(h, 0.5);
  EXPECT_TRUE(rotation_at(h, 0.25).isApprox(quarter, test::kExact)) << rotation_at(h, 0.25);
  // Linear interpolation of the Euler angles, Euler (45, 45, 0), is a different rotation: the check tells them apart.
  EXPECT_GT((euler_xyz_deg(Vec3(45, 45, 0)) - half).norm(), 0.1);
}

TEST(Handle, SingleAxisRotationAndTranslationMatchTheAnalyticMotion) {
  // 90 degrees about z and 0.1 m along x by t = 2, from the rest pose at t = 0 (no keyframe there).
  const HandleSpec h = handle({{2.0, Vec3(0.1, 0, 0), Vec3(0, 0, 90)}});
  const Vec3 c(1, 1, 1), X(2, 1, 0.5);
  for (double t : {-1.0, 0.0, 0.5, 1.0, 1.5, 2.0, 3.0}) {
    const double s = std::clamp(t / 2.0, 0.0, 1.0);
    const double a = s * 90.0 * kDeg;
    Mat3 Rz;
    Rz << std::cos(a), -std::sin(a), 0,  //
        std::sin(a), std::cos(a), 0,      //
        0, 0, 1;
    const Vec3 expected = c + Rz * (X - c) + Vec3(0.1 * s, 0, 0);
    EXPECT_TRUE(h.position(X, t).isApprox(expected, test::kExact)) << "t = " << t << ": " << h.position(X, t).transpose();
  }
}

TEST(Handle, FirstKeyframeAtZeroHoldsItsPoseBefore) {
  // With a keyframe at t = 0 there is no implicit rest pose: the handle sits at the first keyframe before it.
  const HandleSpec h = handle({{0.0, Vec3(0, 0.2, 0), Vec3(0, 0, 0)}, {1.0, Vec3(0, 0.4, 0), Vec3(0, 0, 0)}});
  const Vec3 X(0.5, 0.5, 0.5);
  EXPECT_TRUE(h.position(X, -1.0).isApprox(X + Vec3(0, 0.2, 0), test::kExact));
  EXPECT_TRUE(h.position(X, 0.5).isApprox(X + Vec3(0, 0.3, 0), test::kExact));
  EXPECT_TRUE(h.position(X, 5.0).isApprox(X + Vec3(0, 0.4, 0), test::kExact));
}

TEST(Handle, QuarterTurnKeyframesMakeAFullTurn) {
  // The rotation takes the shorter arc between keyframes, so a full turn is written as quarter turns.
  const HandleSpec h = handle({{1.0, Vec3::Zero(), Vec3(0, 0, 90)},
                               {2.0, Vec3::Zero(), Vec3(0, 0, 180)},
                               {3.0, Vec3::Zero(), Vec3(0, 0, 270)},
                               {4.0, Vec3::Zero(), Vec3(0, 0, 360)}});
  for (double t = 0.0; t <= 4.0; t += 0.25) {
    const Mat3 expected = Eigen::AngleAxisd(t * 90.0 * kDeg, Vec3::UnitZ()).toRotationMatrix();
    EXPECT_TRUE(rotation_at(h, t).isApprox(expected, test::kExact)) << "t = " << t;
  }
}

TEST(Handle, WithoutKeyframesTheHandleIsFixed) {
  const HandleSpec h = handle({});
  const Vec3 X(0.3, 1.7, 2.0);
  EXPECT_EQ(h.position(X, 0.0), X);
  EXPECT_EQ(h.position(X, 10.0), X);
}

}  // namespace
}  // namespace octocut::sim
