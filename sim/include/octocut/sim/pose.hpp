#pragma once
// Keyframed rigid poses: the one interpolation used by tools, render props and handles (position linear, rotation
// quaternion slerp along the shorter arc).
#include <span>

#include "octocut/sim/types.hpp"

namespace octocut::sim {

/// A rigid transform: x_world = rotation * x_local + position.
struct Pose {
  Vec3 position = Vec3::Zero();      ///< the local origin in world coordinates, m (3)
  Mat3 rotation = Mat3::Identity();  ///< proper rotation, local axes as columns (3 x 3)

  /// The point x (local coordinates, m) in world coordinates, m.
  [[nodiscard]] Vec3 apply(const Vec3& x) const { return rotation * x + position; }
  /// The pose as a 4 x 4 homogeneous matrix.
  [[nodiscard]] Eigen::Matrix4d matrix() const;
};

/// One keyframe of a rigid motion.
struct PoseKeyframe {
  double t = 0.0;                    ///< time, s
  Vec3 position = Vec3::Zero();      ///< m (3)
  Vec3 rotation_deg = Vec3::Zero();  ///< XYZ Euler angles, degrees (3): R = Rz(z) Ry(y) Rx(x)
};

/// The rotation of XYZ Euler angles in degrees: first about the fixed x axis, then y, then z, R = Rz(z) Ry(y) Rx(x).
Eigen::Quaterniond euler_xyz_quaternion(const Vec3& degrees);
/// The same rotation as a matrix (3 x 3).
Mat3 euler_xyz_deg(const Vec3& degrees);

/// The pose at time t (s) of keyframes sorted by t: between keyframes k and k+1, with s = (t - t_k) / (t_{k+1} - t_k),
/// the position is (1 - s) p_k + s p_{k+1} and the rotation is the quaternion slerp of the keyframes' rotations
/// (the shorter arc). Held at the first keyframe before it and at the last one after it. No keyframes: identity.
Pose interpolate_pose(std::span<const PoseKeyframe> keyframes, double t);

}  // namespace octocut::sim
