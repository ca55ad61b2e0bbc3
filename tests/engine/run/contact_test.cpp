// Contact (issue 16) through engine::World, each against an independent truth: a block resting on a fixed floor
// (the floor carries m g), Coulomb friction on a tilted floor (sticks below atan mu, slides above), the energy of a
// dynamic sphere bouncing on tissue (never above its start), cutting while a body presses the object (finite, and the
// new cut faces collide), and a scene in which nothing collides (no Bullet world).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include "common/cli_util.hpp"
#include "common/temp_dir.hpp"
#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"

namespace octocut::engine {
namespace {

using sim::Vec3;

class ContactTest : public test::TempDirTest {
 public:
  Scene scene(const std::string& text, const std::vector<std::string>& sets = {}) {
    return load_scene(write("scene.json", text).string(), sets);
  }
};

// Mean position of the DOFs, weighted by their mass, m.
Vec3 centre_of_mass(const sim::Simulator& s) {
  Vec3 c = Vec3::Zero();
  double m = 0.0;
  for (int d = 0; d < s.model().num_dofs(); ++d) {
    c += s.model().dof_mass()[std::size_t(d)] * s.state().x[std::size_t(d)];
    m += s.model().dof_mass()[std::size_t(d)];
  }
  return c / m;
}

// A 2 cm soft block with no handles, its base on the top face (z = 0) of a fixed floor box.
const char* kBlock = R"({
  "duration": 0.4,
  "solver": {"dt": 0.002, "threads": 1},
  "object": {"surface": {"box": {"min": [-0.01, -0.01, 0], "max": [0.01, 0.01, 0.02]}},
             "material": {"young_modulus": 2e4, "poisson_ratio": 0.3, "density": 1000, "rayleigh_mass": 30},
             "octree": {"base_level": 2, "max_level": 2}},
  "rigid_bodies": [{"name": "floor", "shape": {"box": {"size": [0.2, 0.2, 0.02]}}, "motion": "fixed",
                    "position": [0, 0, -0.01]}],
  "contact": {"friction": 0.5}
})";

TEST_F(ContactTest, ABlockRestingOnAFloorLoadsItWithItsWeight) {
  World world(scene(kBlock), WorldOptions{.render = false});
  ASSERT_TRUE(world.has_contact());
  const double mass = 1000.0 * 0.02 * 0.02 * 0.02;  // kg
  const Vec3 c0 = centre_of_mass(world.simulator());
  while (!world.done()) world.step();
  const Report r = world.report();
  ASSERT_TRUE(r.contact.present);
  ASSERT_EQ(r.contact.bodies.size(), 1u);
  const auto& f = r.contact.bodies[0].force_n;
  // The floor carries the weight, straight down.
  EXPECT_NEAR(f[2], -mass * 9.81, 0.005 * mass * 9.81);
  EXPECT_LT(std::hypot(f[0], f[1]), 0.005 * mass * 9.81);
  // It penetrates by at most 1% of the block's height, and nothing drifts sideways.
  EXPECT_LE(r.contact.max_penetration_m, 0.01 * 0.02);
  const Vec3 c1 = centre_of_mass(world.simulator());
  EXPECT_LT(std::hypot(c1.x() - c0.x(), c1.y() - c0.y()), 1e-6);
  EXPECT_TRUE(r.finite);
  EXPECT_EQ(r.recoveries, 0);
  EXPECT_GT(r.contact.samples, 8);  // the box's faces are sampled, not only its 8 corners
}

// The floor box of kBlock's top 4 x 4 cm as a closed OBJ in m, its top face (z = 0) a grid of 1 mm squares split
// into 3,200 triangles, the rest fans onto the bottom's corners: a fine concave-query mesh whose surface is the
// primitive box's where the block stands.
std::string grid_floor_obj() {
  constexpr int kN = 40;       // squares per side of the top
  constexpr double kH = 0.02;  // m: half the side
  std::string s;
  const auto v = [&s](double x, double y, double z) {
    s += "v " + std::to_string(x) + " " + std::to_string(y) + " " + std::to_string(z) + "\n";
  };
  for (int j = 0; j <= kN; ++j)
    for (int i = 0; i <= kN; ++i) v(-kH + 2 * kH * i / kN, -kH + 2 * kH * j / kN, 0.0);
  const int b = (kN + 1) * (kN + 1) + 1;  // the bottom's corners b..b+3 (1-based): (-,-), (+,-), (+,+), (-,+)
  v(-kH, -kH, -0.02), v(kH, -kH, -0.02), v(kH, kH, -0.02), v(-kH, kH, -0.02);
  const auto top = [](int i, int j) { return 1 + j * (kN + 1) + i; };
  const auto f = [&s](int a, int c, int d) {
    s += "f " + std::to_string(a) + " " + std::to_string(c) + " " + std::to_string(d) + "\n";
  };
  for (int j = 0; j < kN; ++j)
    for (int i = 0; i < kN; ++i) {
      f(top(i, j), top(i + 1, j), top(i + 1, j + 1));
      f(top(i, j), top(i + 1, j + 1), top(i, j + 1));
    }
  f(b, b + 2, b + 1), f(b, b + 3, b + 2);  // the bottom, facing -z
  // Each side: a fan from one bottom corner over its top edge, then the triangle to the other bottom corner.
  for (int k = 0; k < kN; ++k) {
    f(b, top(k + 1, 0), top(k, 0));            // y = -kH, facing -y
    f(b + 1, top(kN, k + 1), top(kN, k));      // x = +kH, facing +x
    f(b + 2, top(kN - k - 1, kN), top(kN - k, kN));  // y = +kH, facing +y
    f(b + 3, top(0, kN - k - 1), top(0, kN - k));    // x = -kH, facing -x
  }
  f(b, b + 1, top(kN, 0)), f(b + 1, b + 2, top(kN, kN)), f(b + 2, b + 3, top(0, kN)), f(b + 3, b, top(0, 0));
  return s;
}

// The block of the test above on a floor that is a triangle mesh with 1 mm triangles under it (a concave collider:
// Bullet's box queries on the BVH and the closest point on each triangle), against the same block on the primitive
// box (Bullet's GJK/EPA): the floor is the same plane where the block stands, so the floor's force, the deepest
// penetration (9 um) and the block's centre of mass agree to rounding (1e-16 m seen).
TEST_F(ContactTest, AMeshFloorOfSmallTrianglesCarriesTheBlockAsThePrimitiveBoxDoes) {
  write("floor.obj", grid_floor_obj());
  std::string mesh_block = kBlock;
  const std::string box = R"("shape": {"box": {"size": [0.2, 0.2, 0.02]}}, "motion": "fixed",
                    "position": [0, 0, -0.01]})";
  const auto at = mesh_block.find(box);
  ASSERT_NE(at, std::string::npos);
  mesh_block.replace(at, box.size(), R"("shape": {"mesh": "floor.obj", "scale": 1.0}, "motion": "fixed",
                    "position": [0, 0, 0]})");
  // Dropped from 0.1 mm above the floor, so that every sample that touches it first is inside by that fall (a
  // sample exactly on the surface is inside or not by a rounding error, which differs between GJK/EPA and the mesh).
  const std::vector<std::string> lift = {"/object/surface/box/min=[-0.01, -0.01, 0.0001]",
                                         "/object/surface/box/max=[0.01, 0.01, 0.0201]"};
  World on_box(scene(kBlock, lift), WorldOptions{.render = false});
  World on_mesh(scene(mesh_block, lift), WorldOptions{.render = false});
  while (!on_box.done()) on_box.step();
  while (!on_mesh.done()) on_mesh.step();
  const Report a = on_box.report(), m = on_mesh.report();
  ASSERT_TRUE(a.contact.present && m.contact.present);
  const double weight = 1000.0 * 0.02 * 0.02 * 0.02 * 9.81;  // N
  for (int k = 0; k < 3; ++k)
    EXPECT_NEAR(m.contact.bodies[0].force_n[std::size_t(k)], a.contact.bodies[0].force_n[std::size_t(k)],
                1e-9 * weight);
  EXPECT_NEAR(m.contact.bodies[0].force_n[2], -weight, 0.005 * weight);
  EXPECT_NEAR(m.contact.max_penetration_m, a.contact.max_penetration_m, 1e-12);
  EXPECT_LT((centre_of_mass(on_mesh.simulator()) - centre_of_mass(on_box.simulator())).norm(), 1e-12);
  EXPECT_EQ(m.contact.samples, a.contact.samples);
  EXPECT_TRUE(m.finite);
  EXPECT_EQ(m.recoveries, 0);
}

// Mass-weighted mean velocity of the DOFs, m/s.
Vec3 mean_velocity(const sim::Simulator& s) {
  Vec3 c = Vec3::Zero();
  double m = 0.0;
  for (int d = 0; d < s.model().num_dofs(); ++d) {
    c += s.model().dof_mass()[std::size_t(d)] * s.state().v[std::size_t(d)];
    m += s.model().dof_mass()[std::size_t(d)];
  }
  return c / m;
}

// The block on a floor tilted by theta (gravity turned by theta about y), after it has settled from its drop onto
// the floor (0.15 s): its displacement and its gain in speed along the slope over the next 0.1 s, m and m/s.
std::pair<double, double> slide(ContactTest& t, double theta_deg) {
  const double th = theta_deg * std::numbers::pi / 180.0;
  const std::string g = "/solver/gravity=[" + std::to_string(9.81 * std::sin(th)) + ",0," +
                        std::to_string(-9.81 * std::cos(th)) + "]";
  // Stiffness-proportional damping instead of mass-proportional: the latter would resist the sliding as a drag.
  World world(t.scene(kBlock, {g, "/duration=0.25", "/object/material/rayleigh_mass=0",
                                  "/object/material/rayleigh_stiffness=0.01"}), WorldOptions{.render = false});
  while (world.time() < 0.15 - 1e-9) world.step();
  const double x0 = centre_of_mass(world.simulator()).x(), v0 = mean_velocity(world.simulator()).x();
  while (!world.done()) world.step();
  return {centre_of_mass(world.simulator()).x() - x0, mean_velocity(world.simulator()).x() - v0};
}

TEST_F(ContactTest, FrictionHoldsBelowTheFrictionAngleAndSlidesAbove) {
  // mu = 0.5: the friction angle is atan(0.5) = 26.57 degrees; 1.5 degrees either side.
  const double angle = std::atan(0.5) * 180.0 / std::numbers::pi;
  const auto [below_dx, below_dv] = slide(*this, angle - 1.5);
  const auto [above_dx, above_dv] = slide(*this, angle + 1.5);
  // Sliding, Coulomb: a = g (sin - mu cos); sticking: it stays.
  const double th = (angle + 1.5) * std::numbers::pi / 180.0;
  const double a = 9.81 * (std::sin(th) - 0.5 * std::cos(th));
  EXPECT_NEAR(above_dv, a * 0.1, 0.2 * a * 0.1) << "above: dx " << above_dx << " dv " << above_dv;
  EXPECT_GT(above_dx, 0.5 * a * 0.1 * 0.1);
  EXPECT_LT(std::abs(below_dx), 2e-5) << "below: dx " << below_dx << " dv " << below_dv;
  EXPECT_LT(std::abs(below_dv), 1e-3);
}

// A 4 cm block clamped at its base and a 5 g dynamic steel-like sphere dropped on it from 5 mm above.
const char* kDrop = R"({
  "duration": 0.2,
  "solver": {"dt": 0.001, "threads": 1},
  "object": {"surface": {"box": {"min": [-0.02, -0.02, 0], "max": [0.02, 0.02, 0.02]}},
             "material": {"young_modulus": 5e4, "poisson_ratio": 0.3, "density": 1000},
             "octree": {"base_level": 3, "max_level": 3},
             "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 0.001]}}]},
  "rigid_bodies": [{"name": "ball", "shape": {"sphere": {"radius": 0.006}}, "motion": "dynamic", "mass": 0.005,
                    "position": [0, 0, 0.031]}],
  "contact": {"friction": 0, "damping": 0}
})";

// Total energy: the tissue's kinetic, elastic and gravitational, and the ball's kinetic and gravitational, J.
double total_energy(const World& w) {
  const sim::Simulator& s = w.simulator();
  double pot = 0.0;
  for (int d = 0; d < s.model().num_dofs(); ++d)
    pot += s.model().dof_mass()[std::size_t(d)] * 9.81 * s.state().x[std::size_t(d)].z();
  return s.kinetic_energy() + s.elastic_energy() + pot + w.rigid_body_energy();
}

TEST_F(ContactTest, ADroppedSphereBouncesWithoutGainingEnergy) {
  World world(scene(kDrop), WorldOptions{.render = false});
  const double e0 = total_energy(world);
  const double drop = 0.005 * 9.81 * 0.005;  // the ball's energy above the tissue, J
  double worst = -1e300, lowest = 1e300, highest_after = -1e300;
  bool touched = false;
  while (!world.done()) {
    world.step();
    worst = std::max(worst, total_energy(world) - e0);
    const double z = world.report().contact.bodies[0].position[2];
    lowest = std::min(lowest, z);
    if (world.report().contact.bodies[0].force_n[2] != 0.0) touched = true;
    if (touched && world.report().contact.bodies[0].velocity_m_s[2] > 0.0) highest_after = std::max(highest_after, z);
  }
  EXPECT_TRUE(touched);
  EXPECT_LT(lowest, 0.026);       // it reached the tissue (top at z = 0.02, radius 6 mm)
  EXPECT_GT(highest_after, lowest);  // and came back up: a bounce
  EXPECT_LE(worst, 0.01 * drop) << "energy rose by " << worst << " J of " << drop;
  EXPECT_TRUE(world.report().finite);
}

// A 1 cm cube held at its base, a fixed plate pressing 0.2 mm into its top, a 2 mm punch through its centre at
// t = 10 ms, and a 1 mm rod (a kinematic body) in the punched hole that moves 1.5 mm sideways after the cut.
const char* kCutPressed = R"({
  "duration": 0.04,
  "solver": {"dt": 0.001, "gravity": [0, 0, 0], "threads": 1},
  "object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}},
             "material": {"young_modulus": 5e4, "poisson_ratio": 0.3, "rayleigh_mass": 50},
             "octree": {"root": {"min": [-0.001, -0.001, -0.001], "size": 0.012}, "base_level": 3, "max_level": 5},
             "material_graph": {"cell_size": 0.001},
             "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 0.0005]}}]},
  "tools": [{"name": "punch", "blade": {"cylinder": {"radius": 0.002, "height": 0.02, "segments": 32}},
             "keyframes": [{"t": 0, "position": [0.005, 0.005, 0.005]}], "cuts": [{"t": 0.01}]}],
  "rigid_bodies": [
    {"name": "plate", "shape": {"box": {"size": [0.004, 0.004, 0.002]}}, "motion": "fixed",
     "position": [0.0085, 0.0085, 0.0108]},
    {"name": "rod", "shape": {"cylinder": {"radius": 0.001, "height": 0.006}}, "motion": "kinematic",
     "keyframes": [{"t": 0.02, "position": [0.005, 0.005, 0.005]}, {"t": 0.03, "position": [0.0065, 0.005, 0.005]}]}
  ]
})";

TEST_F(ContactTest, CuttingWhileABodyPressesStaysFiniteAndTheCutFacesCollide) {
  World world(scene(kCutPressed), WorldOptions{.render = false});
  long samples_before = 0;
  double plate_force = 0.0, rod_before = 0.0;
  while (!world.done()) {
    const StepResult s = world.step();
    const Report r = world.report();
    ASSERT_TRUE(r.finite) << "t = " << s.t;
    if (s.t < 0.0095) samples_before = r.contact.samples;
    if (s.t < 0.0095) plate_force = r.contact.bodies[0].force_n[2];
    if (s.t > 0.0105 && s.t < 0.0195) rod_before = std::max(rod_before, std::abs(r.contact.bodies[1].force_n[0]));
  }
  const Report r = world.report();
  ASSERT_EQ(r.cuts.size(), 1u);
  EXPECT_EQ(r.cuts[0].status, "ok");
  EXPECT_GT(plate_force, 0.0);                     // the plate pressed (the tissue pushes it up)
  EXPECT_GT(r.contact.samples, samples_before);    // the cut faces are sampled
  EXPECT_EQ(rod_before, 0.0);                      // in the hole, touching nothing
  // Moved 0.5 mm into the hole's wall (+x): the wall pushes it back (-x).
  EXPECT_LT(r.contact.bodies[1].force_n[0], -1e-4);
  EXPECT_EQ(r.failed_steps, 0);
}

// The contact queries run on the simulator's threads in chunks of samples: with one thread and with two, the same
// scene (a plate pressing, a punch cutting, a rod in the hole) gives the same contact forces every step and the same
// final state, bit for bit.
TEST_F(ContactTest, ContactsAreTheSameOnOneAndTwoThreads) {
  std::vector<std::vector<double>> forces[2];
  std::vector<Vec3> final_x[2];
  long samples = 0;
  for (const int threads : {1, 2}) {
    World world(scene(kCutPressed, {"/solver/threads=" + std::to_string(threads)}), WorldOptions{.render = false});
    while (!world.done()) {
      world.step();
      const Report r = world.report();
      std::vector<double> f;
      for (const auto& b : r.contact.bodies) f.insert(f.end(), b.force_n.begin(), b.force_n.end());
      forces[threads - 1].push_back(f);
      samples = r.contact.samples;
    }
    final_x[threads - 1] = world.simulator().state().x;
  }
  EXPECT_GT(samples, 512);  // several chunks of samples
  ASSERT_EQ(forces[0].size(), forces[1].size());
  for (std::size_t k = 0; k < forces[0].size(); ++k) ASSERT_EQ(forces[0][k], forces[1][k]) << "step " << k;
  ASSERT_EQ(final_x[0].size(), final_x[1].size());
  for (std::size_t d = 0; d < final_x[0].size(); ++d) ASSERT_EQ(final_x[0][d], final_x[1][d]) << "DOF " << d;
}

TEST_F(ContactTest, RigidBodiesAreDrawnAtTheirPose) {
  // The block on its floor, rendered (the description only; no GL): the floor is drawn, a box at (0, 0, -0.01).
  World world(scene(kBlock, {"/render/enabled=true", "/duration=0.004"}), WorldOptions{.render = true});
  world.step();
  const RenderScene rs = world.render_scene();
  ASSERT_EQ(rs.meshes.size(), 2u);  // the tissue and the floor
  const RenderMesh& floor = rs.meshes[1];
  EXPECT_NEAR(floor.model(2, 3), -0.01, 1e-6);
  float zmin = 1e9f, zmax = -1e9f;
  for (const auto& p : floor.positions) {
    zmin = std::min(zmin, p.z());
    zmax = std::max(zmax, p.z());
  }
  EXPECT_NEAR(zmax - zmin, 0.02, 1e-6);  // the box's height, in the body frame
}

TEST_F(ContactTest, ASceneInWhichNothingCollidesBuildsNoBulletWorld) {
  const char* text = R"({"duration": 0.002, "solver": {"dt": 0.001},
    "object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}}, "octree": {"base_level": 1}},
    "tools": [{"name": "t", "blade": {"cylinder": {"radius": 0.001, "height": 0.01}},
               "keyframes": [{"t": 0, "position": [0, 0, 0]}]}]})";
  World world(scene(text), WorldOptions{.render = false});
  world.step();
  EXPECT_FALSE(world.has_contact());
  const Report r = world.report();
  EXPECT_FALSE(r.subsystems.contact);
  EXPECT_FALSE(r.contact.present);
  EXPECT_TRUE(world.contact_forces().empty());
  EXPECT_EQ(world.tool_contact_force(0), (std::array<double, 3>{0, 0, 0}));
  // The same scene with the tool colliding builds one.
  World colliding(scene(text, {"/tools/0/collide=true"}), WorldOptions{.render = false});
  EXPECT_TRUE(colliding.has_contact());
  EXPECT_TRUE(colliding.report().subsystems.contact);
}

}  // namespace
}  // namespace octocut::engine

namespace octocut::engine {
namespace {

// ---- bad input: exit 2 naming the file and the JSON pointer -------------------------------------------------------

const char* kBase = R"({"duration": 0.002, "solver": {"dt": 0.001},
  "object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}}, "octree": {"base_level": 1}},
  "rigid_bodies": [{"name": "b", "shape": {"sphere": {"radius": 0.01}}, "motion": "fixed", "position": [0, 0, 0.03]}]
})";

// The message of the SceneError that loading and building the scene with `sets` throws ("" when none).
std::string error_of(ContactTest& t, const std::vector<std::string>& sets, const std::string& text = kBase) {
  try {
    World world(t.scene(text, sets), WorldOptions{.render = false});
  } catch (const SceneError& e) {
    return e.what();
  }
  return "";
}

// A tetrahedron as OBJ text, offset by `dx`; without its last face when `open`.
std::string tet_obj(double dx, bool open, int first = 1) {
  std::string s;
  for (const auto& v : {std::array{0.0, 0.0, 0.0}, {0.01, 0.0, 0.0}, {0.0, 0.01, 0.0}, {0.0, 0.0, 0.01}})
    s += "v " + std::to_string(v[0] + dx) + " " + std::to_string(v[1]) + " " + std::to_string(v[2]) + "\n";
  const int a = first, b = first + 1, c = first + 2, d = first + 3;
  auto face = [](int i, int j, int k) {
    return "f " + std::to_string(i) + " " + std::to_string(j) + " " + std::to_string(k) + "\n";
  };
  s += face(a, c, b) + face(a, b, d) + face(b, c, d);
  if (!open) s += face(a, d, c);
  return s;
}

TEST_F(ContactTest, BadRigidBodiesAndColliderMeshesAreErrorsNamingFileAndPointer) {
  const std::string file = (m_dir / "scene.json").string();
  // An unknown shape.
  std::string e = error_of(*this, {"/rigid_bodies/0/shape={\"cone\": {\"radius\": 1}}"});
  EXPECT_NE(e.find(file + ": /rigid_bodies/0/shape/cone"), std::string::npos) << e;
  // No shape at all.
  e = error_of(*this, {"/rigid_bodies/0/shape={}"});
  EXPECT_NE(e.find(file + ": /rigid_bodies/0/shape"), std::string::npos) << e;
  // A dynamic body without a positive mass.
  e = error_of(*this, {"/rigid_bodies/0/motion=\"dynamic\"", "/rigid_bodies/0/mass=0"});
  EXPECT_NE(e.find(file + ": /rigid_bodies/0/mass"), std::string::npos) << e;
  e = error_of(*this, {"/rigid_bodies/0/motion=\"dynamic\""});
  EXPECT_NE(e.find(file + ": /rigid_bodies/0"), std::string::npos) << e;
  // Keyframes on a body that is not kinematic, and a kinematic body without any.
  e = error_of(*this, {"/rigid_bodies/0/keyframes=[{\"t\": 0}]"});
  EXPECT_NE(e.find(file + ": /rigid_bodies/0/keyframes"), std::string::npos) << e;
  e = error_of(*this, {"/rigid_bodies/0/motion=\"kinematic\""});
  EXPECT_NE(e.find(file + ": /rigid_bodies/0/keyframes"), std::string::npos) << e;
  // Not a number, and a negative friction.
  e = error_of(*this, {"/rigid_bodies/0/position=[0, NaN, 0]"});
  EXPECT_NE(e.find(file), std::string::npos) << e;
  EXPECT_FALSE(e.empty());
  e = error_of(*this, {"/contact/friction=-1"});
  EXPECT_NE(e.find(file + ": /contact/friction"), std::string::npos) << e;
  e = error_of(*this, {"/contact/stiffness=0"});
  EXPECT_NE(e.find(file + ": /contact/stiffness"), std::string::npos) << e;
  // A collider mesh that is open, or that intersects itself.
  write("open.obj", tet_obj(0.0, true));
  write("crossing.obj", tet_obj(0.0, false) + tet_obj(0.002, false, 5));
  e = error_of(*this, {"/rigid_bodies/0/shape={\"mesh\": \"open.obj\"}"});
  EXPECT_NE(e.find(file + ": /rigid_bodies/0/shape/mesh"), std::string::npos) << e;
  e = error_of(*this, {"/rigid_bodies/0/shape={\"mesh\": \"crossing.obj\"}"});
  EXPECT_NE(e.find(file + ": /rigid_bodies/0/shape/mesh"), std::string::npos) << e;
  EXPECT_NE(e.find("intersect"), std::string::npos) << e;
  e = error_of(*this, {"/render/props=[{\"name\": \"bone\", \"mesh\": \"open.obj\", \"collide\": true}]"});
  EXPECT_NE(e.find(file + ": /render/props/0/mesh"), std::string::npos) << e;
  // A closed collider mesh is fine.
  write("tet.obj", tet_obj(0.0, false));
  EXPECT_EQ(error_of(*this, {"/rigid_bodies/0/shape={\"mesh\": \"tet.obj\"}"}), "");
}

TEST_F(ContactTest, TheCommandLineExitsTwoForABadBody) {
  const std::filesystem::path p = write("scene.json", kBase);
  const test::CommandResult r =
      test::run_octocut("run '" + p.string() + "' --no-render --quiet --out '" + (m_dir / "out").string() +
                        "' --set /rigid_bodies/0/motion='\"dynamic\"' --set /rigid_bodies/0/mass=-1");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("/rigid_bodies/0/mass"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace octocut::engine
