#include "octocut/sim/pose.hpp"

#include <algorithm>
#include <numbers>

namespace octocut::sim {

Eigen::Matrix4d Pose::matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = rotation;
  m.topRightCorner<3, 1>() = position;
  return m;
}

Eigen::Quaterniond euler_xyz_quaternion(const Vec3& degrees) {
  const Vec3 r = degrees * (std::numbers::pi / 180.0);
  return Eigen::AngleAxisd(r.z(), Vec3::UnitZ()) * Eigen::AngleAxisd(r.y(), Vec3::UnitY()) *
         Eigen::AngleAxisd(r.x(), Vec3::UnitX());
}

Mat3 euler_xyz_deg(const Vec3& degrees) { return euler_xyz_quaternion(degrees).toRotationMatrix(); }

Pose interpolate_pose(std::span<const PoseKeyframe> keys, double t) {
  Pose pose;
  if (keys.empty()) return pose;
  // The keyframe interval holding t, and the fraction s along it; held at both ends.
  std::size_t i = 0;
  while (i + 1 < keys.size() && t > keys[i + 1].t) ++i;
  const PoseKeyframe& a = keys[i];
  const PoseKeyframe& b = i + 1 < keys.size() ? keys[i + 1] : keys[i];
  const double s = b.t > a.t ? std::clamp((t - a.t) / (b.t - a.t), 0.0, 1.0) : 0.0;
  // Position linear, rotation slerp.
  pose.position = (1.0 - s) * a.position + s * b.position;
  pose.rotation = euler_xyz_quaternion(a.rotation_deg).slerp(s, euler_xyz_quaternion(b.rotation_deg)).toRotationMatrix();
  return pose;
}

}  // namespace octocut::sim
