// The viewer's camera controls and the tool in the hand. See view_controls.hpp.
#include "view/view_controls.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "octocut/engine/run/tool.hpp"

namespace octocut::engine {

namespace {

constexpr double kDegree = std::numbers::pi / 180.0;

Eigen::Vector3d forward(const Camera& c) { return (c.target - c.position).normalized(); }
Eigen::Vector3d right(const Camera& c) { return forward(c).cross(c.up).normalized(); }

}  // namespace

void orbit(Camera& camera, double dx, double dy) {
  const Eigen::Vector3d up = camera.up.normalized();
  Eigen::Vector3d offset = camera.position - camera.target;
  offset = Eigen::AngleAxisd(-0.005 * dx, up) * offset;
  const Eigen::Vector3d turned = Eigen::AngleAxisd(-0.005 * dy, right(camera)) * offset;
  // Keep away from the poles, where up and the view direction become parallel.
  if (std::abs(turned.normalized().dot(up)) < std::cos(5.0 * kDegree)) offset = turned;
  camera.position = camera.target + offset;
}

void pan(Camera& camera, double dx, double dy, int height) {
  const double distance = (camera.position - camera.target).norm();
  const double metres_per_pixel = 2.0 * distance * std::tan(0.5 * camera.fov_deg * kDegree) / std::max(height, 1);
  const Eigen::Vector3d r = right(camera), u = r.cross(forward(camera));
  const Eigen::Vector3d shift = metres_per_pixel * (-dx * r + dy * u);
  camera.position += shift;
  camera.target += shift;
}

void zoom(Camera& camera, double steps) {
  const Eigen::Vector3d offset = camera.position - camera.target;
  camera.position = camera.target + offset * std::pow(0.85, steps);
}

void frame_object(Camera& camera, const RenderScene& scene) {
  for (const RenderMesh& mesh : scene.meshes) {
    if (mesh.material != MaterialKind::tissue || mesh.positions.empty()) continue;
    Eigen::Vector3f lo = mesh.positions.front(), hi = lo;
    for (const Eigen::Vector3f& p : mesh.positions) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    const Eigen::Vector3d centre = (0.5f * (lo + hi)).cast<double>();
    const double radius = std::max(0.5 * double((hi - lo).norm()), 1e-6);
    const double distance = 1.15 * radius / std::sin(0.5 * camera.fov_deg * kDegree);
    camera.position = centre - distance * forward(camera);
    camera.target = centre;
    camera.far = std::max(camera.far, 4.0 * (distance + radius));
    return;
  }
}

Ray pixel_ray(const Camera& camera, double x, double y, int width, int height) {
  const double ndc_x = 2.0 * x / std::max(width, 1) - 1.0, ndc_y = 1.0 - 2.0 * y / std::max(height, 1);
  const double tan_half = std::tan(0.5 * camera.fov_deg * kDegree);
  const double aspect = double(width) / double(std::max(height, 1));
  const Eigen::Vector3d f = forward(camera), r = right(camera), u = r.cross(f);
  return {camera.position, (f + ndc_x * tan_half * aspect * r + ndc_y * tan_half * u).normalized()};
}

std::optional<double> intersect(const Ray& ray, const RenderMesh& mesh) {
  // Moller-Trumbore against every triangle, in the mesh's model space.
  const Eigen::Matrix4d to_model = mesh.model.cast<double>().inverse();
  const Eigen::Vector3d o = (to_model * ray.origin.homogeneous()).head<3>();
  const Eigen::Vector3d d = to_model.topLeftCorner<3, 3>() * ray.direction;
  std::optional<double> best;
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.positions[std::size_t(t[0])].cast<double>();
    const Eigen::Vector3d e1 = mesh.positions[std::size_t(t[1])].cast<double>() - a;
    const Eigen::Vector3d e2 = mesh.positions[std::size_t(t[2])].cast<double>() - a;
    const Eigen::Vector3d p = d.cross(e2);
    const double det = e1.dot(p);
    if (std::abs(det) < 1e-300) continue;
    const Eigen::Vector3d s = o - a;
    const double u = s.dot(p) / det;
    if (u < 0.0 || u > 1.0) continue;
    const Eigen::Vector3d q = s.cross(e1);
    const double v = d.dot(q) / det;
    if (v < 0.0 || u + v > 1.0) continue;
    const double hit = e2.dot(q) / det;
    if (hit > 0.0 && (!best || hit < *best)) best = hit;
  }
  return best;
}

HandTool::HandTool(const Scene& scene, std::size_t index) {
  if (index >= scene.tools.size()) return;
  const ToolSettings& tool = scene.tools[index];
  m_name = tool.name;
  m_collides = tool.collide;
  const double t = tool.cuts.empty() ? tool.keyframes.front().t : tool.cuts.front().t;
  m_pose = tool_pose(tool, t);
  m_base = m_pose.rotation;
}

void HandTool::adjust(double depth_steps, double roll_steps) {
  m_depth_steps += depth_steps;
  m_roll_deg += 5.0 * roll_steps;
}

std::optional<sim::Pose> HandTool::follow(const Camera& camera, const RenderScene& frame, double x, double y,
                                          int width, int height) {
  const Ray ray = pixel_ray(camera, x, y, width, height);
  const double step = 0.01 * (camera.target - camera.position).norm();
  std::optional<double> hit;
  if (!m_collides || !m_placed) {
    for (const RenderMesh& mesh : frame.meshes)
      if (mesh.material == MaterialKind::tissue) {
        hit = intersect(ray, mesh);
        break;
      }
  }
  // The depth offset the view plane already holds: all of it for a tool that snaps (the plane is through the last
  // position, offset included); for a colliding tool in the plane, what was applied before (the rest is added now).
  double applied = m_depth_steps;
  if (hit) {
    applied = 0.0;
  } else {
    // Off the tissue, or a colliding tool once placed: the view plane through the last position (or the target).
    const Eigen::Vector3d f = forward(camera);
    const Eigen::Vector3d anchor = m_placed ? m_pose.position : camera.target;
    const double along = ray.direction.dot(f);
    if (along <= 1e-9) return std::nullopt;
    if (m_collides && m_placed) applied = m_plane_depth;
    hit = (anchor - ray.origin).dot(f) / along - applied * step;
  }
  m_pose.position = ray.origin + (*hit + m_depth_steps * step) * ray.direction;
  m_plane_depth = m_depth_steps;
  m_pose.rotation = m_base * Eigen::AngleAxisd(m_roll_deg * kDegree, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  m_placed = true;
  return m_pose;
}

}  // namespace octocut::engine
