// The contact overlay (render.overlays.contacts) of World::render_scene, GL-free: a block resting on a fixed floor,
// its contacts drawn as points on the floor and their forces as lines. Independent truths: Newton's third law (the
// forces drawn, summed, are the opposite of the force World reports on the floor), the floor's plane (every contact
// point lies on it, within the penetration), the scale the scene asks for, and no overlay at all unless asked.
#include <gtest/gtest.h>

#include <array>
#include <string>

#include "common/temp_dir.hpp"
#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"

namespace octocut::engine {
namespace {

// A 2 cm block with no handles, its base on the top face (z = 0) of a fixed floor box, drawn.
const char* kBlock = R"({
  "duration": 0.4,
  "solver": {"dt": 0.002, "threads": 1},
  "object": {"surface": {"box": {"min": [-0.01, -0.01, 0], "max": [0.01, 0.01, 0.02]}},
             "material": {"young_modulus": 2e4, "poisson_ratio": 0.3, "density": 1000, "rayleigh_mass": 30},
             "octree": {"base_level": 2, "max_level": 2}},
  "rigid_bodies": [{"name": "floor", "shape": {"box": {"size": [0.2, 0.2, 0.02]}}, "motion": "fixed",
                    "position": [0, 0, -0.01]}],
  "render": {"enabled": true}
})";

class ContactOverlayTest : public test::TempDirTest {
 public:
  World world(const std::vector<std::string>& sets) {
    return World(load_scene(write("scene.json", kBlock).string(), sets), WorldOptions{.render = true});
  }
};

TEST_F(ContactOverlayTest, PointsOnTheFloorAndForcesThatBalanceTheFloors) {
  const double scale = 0.01;  // m/N
  World w = world({"/render/overlays/contacts=true", "/render/overlays/contact_force_scale=" + std::to_string(scale)});
  for (int i = 0; i < 50; ++i) w.step();
  const RenderScene rs = w.render_scene();
  ASSERT_EQ(rs.points.size(), 1u);
  ASSERT_EQ(rs.lines.size(), 1u);
  const OverlayPoints& points = rs.points[0];
  const OverlayLines& lines = rs.lines[0];
  EXPECT_TRUE(lines.on_top);  // forces lie inside the tissue or the floor: drawn over the meshes
  ASSERT_GT(points.points.size(), 8u);
  ASSERT_EQ(lines.endpoints.size(), 2 * points.points.size());
  const double penetration = w.report().contact.max_penetration_m;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < points.points.size(); ++i) {
    EXPECT_NEAR(points.points[i].z(), 0.0, penetration + 1e-6) << i;           // on the floor's top face
    EXPECT_TRUE(lines.endpoints[2 * i].isApprox(points.points[i])) << i;  // each line starts at its point
    sum += (lines.endpoints[2 * i + 1] - lines.endpoints[2 * i]).cast<double>() / scale;  // N
  }
  const std::vector<ContactForce> forces = w.contact_forces();
  ASSERT_EQ(forces.size(), 1u);
  const Eigen::Vector3d floor(forces[0].force_n[0], forces[0].force_n[1], forces[0].force_n[2]);
  ASSERT_LT(floor.z(), -1e-3);  // the block weighs on the floor
  // The forces on the tissue, drawn, are the floor's reaction (float endpoints: 1e-5 relative).
  EXPECT_NEAR(sum.x(), -floor.x(), 1e-5 * floor.norm());
  EXPECT_NEAR(sum.y(), -floor.y(), 1e-5 * floor.norm());
  EXPECT_NEAR(sum.z(), -floor.z(), 1e-5 * floor.norm());
}

TEST_F(ContactOverlayTest, NothingIsAddedUnlessAsked) {
  World w = world({});
  for (int i = 0; i < 5; ++i) w.step();
  const RenderScene rs = w.render_scene();
  EXPECT_TRUE(rs.points.empty());
  EXPECT_TRUE(rs.lines.empty());
  // Asked for later (the viewer's toggle): drawn from the next step on.
  OverlaySettings o;
  o.contacts = true;
  w.set_overlays(o);
  EXPECT_TRUE(w.render_scene().points.empty());
  w.step();
  EXPECT_EQ(w.render_scene().points.size(), 1u);
}

}  // namespace
}  // namespace octocut::engine
