#pragma once
// Private to the engine: the rigid side of contact (issue 16), a Bullet world behind a pointer. Bullet types appear
// only in contact_world.cpp. The world holds the kinematic tools that collide, the props that are static colliders
// and the rigid bodies (dynamic ones integrated by Bullet); it finds the contacts of S's collision samples with them
// (Bullet's GJK/EPA signed distance for convex shapes, its BVH triangle queries for concave meshes) and returns them
// as sim::Contact, the abstract contact term the simulator takes.
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "octocut/engine/scene/scene.hpp"
#include "octocut/sim/contact.hpp"
#include "octocut/sim/parallel.hpp"
#include "octocut/sim/pose.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::engine {

/// True when a scene needs a contact world: a tool or prop collides, or it has rigid bodies.
bool scene_collides(const Scene& scene);

/// The default penalty stiffness `contact.stiffness`, Pa/m: 10 E / h_min, with h_min the finest leaf's edge. A
/// layer of one finest leaf pressed by p shortens by p h_min / E; the penalty then adds a tenth of that.
double default_contact_stiffness(double young_modulus, double finest_leaf);

/// One collider as the report and contact_forces.csv see it.
struct ColliderState {
  std::string name;
  enum class Kind { tool, prop, body } kind = Kind::tool;
  std::size_t index = 0;                  ///< into scene.tools, scene.render.props or scene.rigid_bodies
  std::array<double, 3> force{};          ///< force the tissue exerts on it in the last step, N (3)
  double max_penetration = 0.0;           ///< deepest sample in it at the start of the last step, m
  double max_force = 0.0;                 ///< largest |force| so far, N
  sim::Pose pose;                         ///< now (bodies: Bullet's)
  std::array<double, 3> velocity{};       ///< bodies: linear velocity of the centre of mass, m/s (3)
};

/// Where the time of contact went in the last step, ms.
struct ContactProfile {
  double queries = 0.0;  ///< sample positions, the prefilter and Bullet's distance queries
  double rigid = 0.0;    ///< forces onto the bodies and Bullet's step
  long searched = 0;     ///< samples whose distance the last find() took from Bullet's box queries
  long certified = 0;    ///< samples whose nearest triangle it took from their last query's certificate instead
  long triangles = 0;    ///< triangles of mesh colliders those queries and certificates tested for the nearest point
};

/// For each rest position of `after` (m), the index of the same position in `before` (bit for bit), or -1.
std::vector<int> same_rest_positions(const std::vector<sim::Vec3>& before, const std::vector<sim::Vec3>& after);

class ContactWorld {
 public:
  /// Builds the Bullet world of `scene`: the colliding tools (mesh, or else blade: `tool_shapes[i]` in tool
  /// coordinates, m; empty for a tool that does not collide or has a cylinder blade and no mesh), the colliding
  /// props and the rigid bodies. `stiffness` is the penalty in Pa/m; samples within `search_depth` (m) of a
  /// concave surface are queried. Throws SceneError for a bad collider mesh (open, self-intersecting), naming the
  /// file and JSON pointer.
  ContactWorld(const Scene& scene, const std::vector<sim::TriMesh>& tool_shapes, double stiffness,
               double search_depth);
  ~ContactWorld();
  ContactWorld(const ContactWorld&) = delete;
  ContactWorld& operator=(const ContactWorld&) = delete;

  /// The contacts of the coming step [t, t + dt] for samples at DOF positions x (num_dofs), with
  /// the tools at `tool_now` (t) and `tool_next` (t + dt) (poses per scene tool). Keeps which collider each contact
  /// is with. The samples are queried on the executor's threads when one is given (the same contacts, in the same
  /// order, whatever the threads).
  std::vector<sim::Contact> find(const sim::ContactSamples& samples, const std::vector<sim::Vec3>& x, double t, double dt,
                                 const std::vector<sim::Pose>& tool_now, const std::vector<sim::Pose>& tool_next,
                                 sim::Executor* executor = nullptr);
  /// After the step: each collider's force (the opposite of its contacts' forces on the tissue), applied to the
  /// dynamic bodies (two-way coupling), and Bullet stepped to t + dt with the
  /// kinematic bodies and tools at their poses there.
  void finish(const std::vector<sim::ContactOutcome>& outcomes, double t, double dt,
              const std::vector<sim::Pose>& tool_next);
  /// Forgets the per-sample query cache.
  void reset_samples();
  /// After a cut changed the samples: keeps the query cache of each new sample i that an old sample old_of_new[i]
  /// stands at (same_rest_positions), and starts the others (old_of_new[i] < 0) without one, as a first query does.
  /// The cache is of positions in the colliders' frames (where a sample was last queried, the distance known free of
  /// the surface around there, its depth there, the nearest triangles there), so any sample may take it; a cut that
  /// forgot it made the step after it query every sample in a collider's box anew.
  void remap_samples(const std::vector<int>& old_of_new);

  [[nodiscard]] const std::vector<ColliderState>& colliders() const;
  [[nodiscard]] const ContactProfile& profile() const;
  /// Deepest penetration of any sample at the start of any step so far, m.
  [[nodiscard]] double max_penetration() const;
  /// Kinetic plus gravitational potential energy of the dynamic bodies (potential relative to z = 0 along
  /// gravity), J.
  [[nodiscard]] double rigid_energy() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> m;
};

}  // namespace octocut::engine
