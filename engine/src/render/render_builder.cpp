#include "octocut/engine/render/render_builder.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "octocut/engine/run/tool.hpp"
#include "octocut/sim/pose.hpp"

namespace octocut::engine {

namespace {

Eigen::Vector3f to_float(const sim::Vec3& v) { return v.cast<float>(); }

}  // namespace

Eigen::Matrix4d prop_pose(const RenderProp& prop, double t) {
  return sim::interpolate_pose(pose_keyframes(prop.keyframes), t).matrix();
}

RenderMesh prop_mesh(const sim::TriMesh& mesh, const std::string& material) {
  RenderMesh out;
  out.material = material == "metal"    ? MaterialKind::metal
                 : material == "tissue" ? MaterialKind::tissue
                 : material == "glass"  ? MaterialKind::glass
                                        : MaterialKind::bone;
  out.positions.reserve(mesh.vertices.size());
  for (const sim::Vec3& p : mesh.vertices) out.positions.push_back(to_float(p));
  out.triangles = mesh.triangles;
  out.normals = mesh_normals(out.positions, out.triangles);
  return out;
}

EmbeddedSurface embed_surface(const sim::ObjectModel& model, sim::TriMesh rest) {
  EmbeddedSurface surface;
  const sim::Box3 b = sim::bounds(rest);
  const sim::Vec3 centre = 0.5 * (b.min + b.max);
  const double nudge = 1e-9 * model.root().size;
  surface.embedding.reserve(rest.vertices.size());
  for (std::size_t i = 0; i < rest.vertices.size(); ++i) {
    // The vertex itself, else a point a hair inside.
    const sim::Vec3& p = rest.vertices[i];
    auto e = model.embed(p);
    if (!e && (centre - p).norm() > 0.0) e = model.embed(p + nudge * (centre - p).normalized());
    if (!e)
      throw std::runtime_error("tissue surface: vertex " + std::to_string(i) + " lies outside the object's octree");
    surface.embedding.push_back(*e);
  }
  surface.rest = std::move(rest);
  return surface;
}

RenderMesh tissue_mesh(const sim::ObjectModel& model, const EmbeddedSurface& surface,
                       const std::vector<sim::Vec3>& slots) {
  RenderMesh mesh;
  mesh.material = MaterialKind::tissue;
  mesh.positions.reserve(surface.embedding.size());
  for (const sim::PointEmbedding& e : surface.embedding) mesh.positions.push_back(to_float(model.evaluate(e, slots)));
  mesh.triangles = surface.rest.triangles;
  mesh.normals = mesh_normals(mesh.positions, mesh.triangles);
  return mesh;
}

Camera make_camera(const CameraSettings& settings, const sim::Box3& bounds) {
  Camera camera;
  const sim::Vec3 centre = 0.5 * (bounds.min + bounds.max);
  const double radius = std::max(0.5 * (bounds.max - bounds.min).norm(), 1e-6);
  camera.fov_deg = settings.fov_deg;
  camera.up = Eigen::Vector3d(settings.up[0], settings.up[1], settings.up[2]);
  camera.target = settings.has_target ? Eigen::Vector3d(settings.target[0], settings.target[1], settings.target[2])
                                      : centre;
  if (settings.has_position) {
    camera.position = Eigen::Vector3d(settings.position[0], settings.position[1], settings.position[2]);
  } else {
    // Far enough that the bounding sphere fits the vertical field of view, with a margin.
    const double distance = 1.15 * radius / std::sin(0.5 * settings.fov_deg * std::numbers::pi / 180.0);
    Eigen::Vector3d direction(0.55, -1.0, 0.65);
    if (direction.normalized().cross(camera.up.normalized()).norm() < 1e-3) direction = Eigen::Vector3d(0.3, -1.0, 0.0);
    camera.position = camera.target + distance * direction.normalized();
  }
  const double reach = (camera.position - camera.target).norm() + (camera.target - centre).norm() + radius;
  camera.near = 1e-3 * reach;
  camera.far = 4.0 * reach;
  camera.arthroscope = settings.arthroscope;
  camera.mask = settings.mask;
  camera.mask_radius = 1.0;
  return camera;
}

void add_overlays(RenderScene& scene, const OverlaySettings& settings, const sim::ObjectModel& model,
                  const std::vector<sim::Vec3>& slots, const std::vector<sim::Vec3>& dofs) {
  // Octree: the 12 edges of every leaf, corners k and k ^ bit differ along one axis.
  if (settings.octree) {
    OverlayLines lines;
    lines.color = Eigen::Vector3f(0.25f, 0.85f, 0.95f);
    lines.endpoints.reserve(std::size_t(24) * model.num_elements());
    for (int leaf = 0; leaf < model.num_elements(); ++leaf) {
      for (int k = 0; k < 8; ++k) {
        for (const int bit : {1, 2, 4}) {
          if (k & bit) continue;
          lines.endpoints.push_back(to_float(slots[std::size_t(8 * leaf + k)]));
          lines.endpoints.push_back(to_float(slots[std::size_t(8 * leaf + (k | bit))]));
        }
      }
    }
    scene.lines.push_back(std::move(lines));
  }
  // DOFs.
  if (settings.dofs) {
    OverlayPoints points;
    points.color = Eigen::Vector3f(0.2f, 0.9f, 0.3f);
    points.size_px = 5.0f;
    for (const sim::Vec3& x : dofs) points.points.push_back(to_float(x));
    scene.points.push_back(std::move(points));
  }
  // Hanging slots: bound to a master leaf instead of being DOFs.
  if (settings.hanging) {
    OverlayPoints points;
    points.color = Eigen::Vector3f(1.0f, 0.8f, 0.1f);
    points.size_px = 5.0f;
    const std::vector<int>& master = model.dofs().slot_master;
    for (std::size_t s = 0; s < master.size() && s < slots.size(); ++s)
      if (master[s] >= 0) points.points.push_back(to_float(slots[s]));
    scene.points.push_back(std::move(points));
  }
}

void add_contact_overlay(RenderScene& scene, const OverlaySettings& settings, const std::vector<sim::Contact>& contacts,
                         const std::vector<sim::ContactOutcome>& outcomes, const std::vector<sim::Vec3>& dofs) {
  if (!settings.contacts || contacts.empty()) return;
  OverlayPoints points;
  points.color = Eigen::Vector3f(1.0f, 0.55f, 0.1f);
  points.size_px = 6.0f;
  OverlayLines lines;
  lines.color = Eigen::Vector3f(1.0f, 0.15f, 0.15f);
  lines.on_top = true;
  const bool forces = outcomes.size() == contacts.size();
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    sim::Vec3 p = sim::Vec3::Zero();
    for (const sim::ContactDof& d : contacts[i].dofs)
      if (d.dof >= 0 && std::size_t(d.dof) < dofs.size()) p += d.weight * dofs[std::size_t(d.dof)];
    points.points.push_back(to_float(p));
    if (!forces) continue;
    lines.endpoints.push_back(to_float(p));
    lines.endpoints.push_back(to_float(p + settings.contact_force_scale * outcomes[i].force));
  }
  scene.points.push_back(std::move(points));
  if (!lines.endpoints.empty()) scene.lines.push_back(std::move(lines));
}

}  // namespace octocut::engine
