// Hertz contact (issue 16): a rigid sphere (a kinematic body) pressed into an elastic block clamped at its base,
// refined under the sphere, against F = 4/3 E / (1 - nu^2) sqrt(R) d^(3/2) for d / R <= 0.1 (Johnson, Contact
// Mechanics, §4.2). The block is 6 contact radii deep and wide, so that it acts nearly as a half-space. A study
// (label `study`): about a minute.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "common/temp_dir.hpp"
#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"

namespace octocut::engine {
namespace {

class HertzTest : public test::TempDirTest {};

// E = 1e4 Pa, nu = 0.3; a 10 mm sphere moved down 0.5 mm by t = 0.15 s, held, then to 1 mm by t = 0.35 s, held.
// Leaves of 0.625 mm under the sphere: the contact radius sqrt(R d) is 2.2 and 3.2 mm.
const char* kHertz = R"({
  "duration": 0.5,
  "solver": {"dt": 0.002, "gravity": [0, 0, 0], "threads": 2, "linear_solver": "cholmod"},
  "object": {"surface": {"box": {"min": [-0.02, -0.02, 0], "max": [0.02, 0.02, 0.02]}},
             "material": {"young_modulus": 1e4, "poisson_ratio": 0.3, "density": 1000, "rayleigh_mass": 100},
             "octree": {"root": {"min": [-0.02, -0.02, -0.02], "size": 0.04}, "base_level": 3, "max_level": 6,
                        "refine": [{"box": {"min": [-0.007, -0.007, 0.014], "max": [0.007, 0.007, 0.02]}, "level": 6},
                                   {"box": {"min": [-0.012, -0.012, 0.008], "max": [0.012, 0.012, 0.02]}, "level": 5}]},
             "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 0.0005]}}]},
  "rigid_bodies": [{"name": "sphere", "shape": {"sphere": {"radius": 0.01}}, "motion": "kinematic",
                    "keyframes": [{"t": 0, "position": [0, 0, 0.03]}, {"t": 0.15, "position": [0, 0, 0.0295]},
                                  {"t": 0.25, "position": [0, 0, 0.0295]}, {"t": 0.35, "position": [0, 0, 0.029]}]}],
  "contact": {"stiffness": 1e9, "friction": 0}
})";

double hertz(double d) {
  const double E = 1e4, nu = 0.3, R = 0.01;
  return 4.0 / 3.0 * E / (1.0 - nu * nu) * std::sqrt(R) * std::pow(d, 1.5);
}

TEST_F(HertzTest, ASphereIndentsABlockAsHertzSays) {
  World world(load_scene(write("hertz.json", kHertz).string()), WorldOptions{.render = false});
  double f_quarter = 0.0;
  while (!world.done()) {
    world.step();
    if (std::abs(world.time() - 0.25) < 1e-6) f_quarter = world.contact_forces().at(0).force_n[2];
  }
  const double f_half = world.contact_forces().at(0).force_n[2];
  // d / R = 0.05 and 0.1; the tissue pushes the sphere up.
  EXPECT_NEAR(f_quarter, hertz(0.0005), 0.15 * hertz(0.0005));
  EXPECT_NEAR(f_half, hertz(0.001), 0.15 * hertz(0.001));
  const Report r = world.report();
  EXPECT_TRUE(r.finite);
  EXPECT_LT(r.contact.max_penetration_m, 0.01 * 0.001);
}

}  // namespace
}  // namespace octocut::engine
