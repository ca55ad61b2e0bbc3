// The report's stability.track (scene output.stability_track): the deformed volume against uniaxial compression
// without lateral contraction (nu = 0: the volume scales exactly with the height), the largest displacement against
// the handle's travel, the energy of a clamped cube under gravity that implicit Euler must never raise, and a
// report without the key that has no track.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "common/temp_dir.hpp"
#include "octocut/engine/run/report.hpp"
#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"

namespace octocut::engine {
namespace {

// A 1 cm cube, 4 x 4 x 4 elements, the bottom face fixed; overrides make it a compression or a sag.
const char* kCube = R"({
  "name": "track cube", "duration": 0.001,
  "solver": {"mode": "static", "dt": 0.001, "gravity": [0, 0, 0], "linear_solver": "cholmod", "tolerance": 1e-10,
             "max_iterations": 50, "threads": 1},
  "object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}},
             "material": {"young_modulus": 1e5, "poisson_ratio": 0.0},
             "octree": {"root": {"min": [0, 0, 0], "size": 0.01}, "base_level": 2, "max_level": 2, "uniform": true},
             "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 1e-9]}}]},
  "output": {"stability_track": true}
})";

class StabilityTrackTest : public test::TempDirTest {
 protected:
  Report run(const std::vector<std::string>& sets) {
    World world(load_scene(write("scene.json", kCube).string(), sets), WorldOptions{.render = false});
    while (!world.done()) world.step();
    return world.report();
  }
};

TEST_F(StabilityTrackTest, UniaxialCompressionWithoutContractionScalesTheVolumeWithTheHeight) {
  // The top face pushed down by 1 mm: with nu = 0 the strain is uniform, the sides stay put, V' / V = 0.9.
  const Report r = run({R"(/object/handles=[{"box": {"min": [-1, -1, -1], "max": [1, 1, 1e-9]}},
                           {"box": {"min": [-1, -1, 0.0099999], "max": [1, 1, 1]},
                            "keyframes": [{"t": 0.001, "translation": [0, 0, -0.001]}]}])"});
  ASSERT_TRUE(r.track.enabled);
  EXPECT_NEAR(r.track.volume_change, -0.1, 1e-8);
  EXPECT_NEAR(r.track.min_volume_change, -0.1, 1e-8);
  EXPECT_NEAR(r.track.max_volume_change, 0.0, 1e-12);  // the rest state, measured when the run starts
  EXPECT_NEAR(r.track.max_displacement_m, 0.001, 1e-12);
  EXPECT_EQ(r.track.energy_steps, 0);  // the handle moves during the step: work is put in
}

TEST_F(StabilityTrackTest, ImplicitEulerNeverRaisesTheEnergyOfAClampedCubeUnderGravity) {
  // 100 dynamic steps of a cube hanging from its bottom face... sideways gravity bends it; no work is put in.
  const Report r = run({"/solver/mode=\"dynamic\"", "/duration=0.1", "/solver/gravity=[9.81, 0, -9.81]",
                        "/object/material/poisson_ratio=0.3", "/object/material/young_modulus=1e4"});
  ASSERT_TRUE(r.track.enabled);
  EXPECT_EQ(r.track.energy_steps, 100);
  EXPECT_GT(r.track.energy_scale_j, 0.0);
  EXPECT_LE(r.track.energy_rise_j, 1e-9 * r.track.energy_scale_j);
  EXPECT_GT(r.track.max_displacement_m, 1e-6);  // it did move
  // A clamped cube bent by its weight keeps its volume to first order in the (small) strain.
  EXPECT_LT(std::abs(r.track.volume_change), 1e-2);
}

TEST_F(StabilityTrackTest, ReportsWithoutTheKeyHaveNoTrack) {
  const Report r = run({"/output/stability_track=false"});
  EXPECT_FALSE(r.track.enabled);
  EXPECT_EQ(report_json(r).find("\"track\""), std::string::npos);
  const Report t = run({});
  EXPECT_NE(report_json(t).find("\"track\""), std::string::npos);
}

}  // namespace
}  // namespace octocut::engine
