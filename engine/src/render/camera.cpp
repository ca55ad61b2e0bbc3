#include "octocut/engine/render/camera.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace octocut::engine {

Eigen::Matrix4d look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Vector3d& up) {
  // Orthonormal eye frame: f forward, s right, u up.
  const Eigen::Vector3d forward = target - eye;
  if (!(forward.norm() > 0.0)) throw std::invalid_argument("camera: position and target coincide");
  const Eigen::Vector3d f = forward.normalized();
  const Eigen::Vector3d side = f.cross(up);
  if (!(side.norm() > 1e-9 * up.norm()) || !(up.norm() > 0.0))
    throw std::invalid_argument("camera: up is zero or parallel to the view direction");
  const Eigen::Vector3d s = side.normalized();
  const Eigen::Vector3d u = s.cross(f);

  // Rows are the eye axes; the translation moves the eye to the origin.
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.block<1, 3>(0, 0) = s.transpose();
  m.block<1, 3>(1, 0) = u.transpose();
  m.block<1, 3>(2, 0) = -f.transpose();
  m(0, 3) = -s.dot(eye);
  m(1, 3) = -u.dot(eye);
  m(2, 3) = f.dot(eye);
  return m;
}

Eigen::Matrix4d perspective(double fov_deg, double aspect, double near, double far) {
  if (!(fov_deg > 0.0 && fov_deg < 180.0)) throw std::invalid_argument("camera: fov_deg must be in (0, 180)");
  if (!(aspect > 0.0)) throw std::invalid_argument("camera: aspect must be > 0");
  if (!(near > 0.0 && far > near)) throw std::invalid_argument("camera: need 0 < near < far");
  // gluPerspective: cot(fov/2) scales, depth maps [near, far] to [-1, 1].
  const double c = 1.0 / std::tan(0.5 * fov_deg * std::numbers::pi / 180.0);
  Eigen::Matrix4d p = Eigen::Matrix4d::Zero();
  p(0, 0) = c / aspect;
  p(1, 1) = c;
  p(2, 2) = (far + near) / (near - far);
  p(2, 3) = 2.0 * far * near / (near - far);
  p(3, 2) = -1.0;
  return p;
}

Eigen::Matrix4d view_matrix(const Camera& camera) { return look_at(camera.position, camera.target, camera.up); }

Eigen::Matrix4d projection_matrix(const Camera& camera, int width, int height) {
  if (width <= 0 || height <= 0) throw std::invalid_argument("camera: image size must be positive");
  return perspective(camera.fov_deg, double(width) / double(height), camera.near, camera.far);
}

Eigen::Vector3d project_to_pixel(const Camera& camera, int width, int height, const Eigen::Vector3d& world) {
  // Clip space, then normalised device coordinates, then the viewport with y flipped to point down.
  const Eigen::Vector4d clip = projection_matrix(camera, width, height) * view_matrix(camera) * world.homogeneous();
  const Eigen::Vector3d ndc = clip.head<3>() / clip.w();
  if (!(clip.w() > 0.0)) return Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  return {0.5 * (ndc.x() + 1.0) * width, 0.5 * (1.0 - ndc.y()) * height, 0.5 * (ndc.z() + 1.0)};
}

void follow_tool(Camera& camera, const Eigen::Vector3d& tool_tip) {
  // Translate eye and target together.
  const Eigen::Vector3d offset = camera.position - camera.target;
  camera.target = tool_tip;
  camera.position = tool_tip + offset;
}

}  // namespace octocut::engine
