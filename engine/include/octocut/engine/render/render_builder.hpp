#pragma once
// Builds render scenes from the simulation (rendering issue): the tissue surface embedded in the octree and moved
// with it, the camera from the scene settings, and the debug overlays. GL-free.
#include <vector>

#include "octocut/engine/render/render_scene.hpp"
#include "octocut/engine/scene/scene.hpp"
#include "octocut/sim/contact.hpp"
#include "octocut/sim/object.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::engine {

/// A rest-space surface bound to the octree: each vertex carries its trilinear embedding.
struct EmbeddedSurface {
  sim::TriMesh rest;                              ///< rest-space surface, m (|V|, |F|)
  std::vector<sim::PointEmbedding> embedding;     ///< one per rest vertex (|V|)
};

/// Embeds every vertex of `rest` in `model`. A vertex on the material's boundary that no leaf holds is moved inward
/// by 1e-9 of the octree size toward the surface's centre first. Throws std::runtime_error naming the first vertex
/// that cannot be embedded.
EmbeddedSurface embed_surface(const sim::ObjectModel& model, sim::TriMesh rest);

/// The deformed tissue: the embedded surface evaluated at the slot positions (8 * num_elements, m), with
/// normals from the deformed positions and no cut faces yet. Used for box primitives, drawn as a grid of their faces.
RenderMesh tissue_mesh(const sim::ObjectModel& model, const EmbeddedSurface& surface,
                       const std::vector<sim::Vec3>& slots);

/// The pose of a render prop at time t (s), as a model-to-world transform (m): sim::interpolate_pose of its
/// keyframes (position linear, rotation slerp, held at both ends); the identity without keyframes.
Eigen::Matrix4d prop_pose(const RenderProp& prop, double t);

/// A prop's or a rigid body's mesh in its own frame (m), shaded as `material` ("bone", "metal", "tissue" or "glass").
RenderMesh prop_mesh(const sim::TriMesh& mesh, const std::string& material);

/// The camera of the scene settings for an object with rest bounds `bounds` (m): a missing target is the centre of
/// the bounds, a missing position looks at the target from the front-right-above so that the bounds fill the view.
/// Near and far clip distances follow the scene's size.
Camera make_camera(const CameraSettings& settings, const sim::Box3& bounds);

/// Appends the debug overlays that `settings` asks for: the deformed octree leaves as lines, the DOFs and the
/// hanging slots as points. `slots` and `dofs` are the current positions (8 * num_elements and num_dofs, m).
void add_overlays(RenderScene& scene, const OverlaySettings& settings, const sim::ObjectModel& model,
                  const std::vector<sim::Vec3>& slots, const std::vector<sim::Vec3>& dofs);

/// Appends the contact overlay when `settings.contacts` is set: the collision samples of `contacts` at DOF positions
/// `dofs` (num_dofs, m) as orange points, and from each the force `outcomes` says its contact exerted on the tissue
/// (N, same order; none when empty, as after a failed step) as a red line `settings.contact_force_scale` m/N long,
/// drawn on top. Nothing without contacts.
void add_contact_overlay(RenderScene& scene, const OverlaySettings& settings, const std::vector<sim::Contact>& contacts,
                         const std::vector<sim::ContactOutcome>& outcomes, const std::vector<sim::Vec3>& dofs);

}  // namespace octocut::engine
