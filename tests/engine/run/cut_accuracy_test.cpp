// How much material a cut removes, against the material that the blade covers in the deformed state. A cut maps the
// posed blade into rest space by one shape-matching affine map per touched component (SPEC §4, stage 1) and removes
// that rest-space blade from S exactly; the truth it approximates is the set of rest points X inside S whose deformed
// position phi(X) lies inside the posed blade, phi being the simulation's own trilinear field. Independent truth:
// that set's volume, sampled by Monte Carlo (points of S in no leaf, between S and the material graph's coarser
// edge, take the nearest leaf's field, extrapolated, as the surface embedding's fallback does).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "octocut/cutting/blade.hpp"
#include "octocut/engine/run/report.hpp"  // CutSummary
#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/sim/primitives.hpp"
#include "octocut/sim/simulator.hpp"

namespace octocut::engine {
namespace {

using sim::Vec3;

struct Sampled {
  double volume = 0.0;  // m^3
  double sigma = 0.0;   // its standard error, m^3
};

// phi(X) for a rest point X of the material: the leaf that holds X, or else the nearest leaf (by box distance).
Vec3 deformed(const sim::ObjectModel& model, const std::vector<Vec3>& slots, const Vec3& x) {
  if (const auto e = model.embed(x)) return model.evaluate(*e, slots);
  int best = -1;
  double nearest = std::numeric_limits<double>::infinity();  // m
  for (int l = 0; l < model.num_elements(); ++l) {
    const sim::Box3 b = model.root().cell_box(model.tree().leaf(l));
    const double d = (x.cwiseMax(b.min).cwiseMin(b.max) - x).norm();
    if (d < nearest) {
      nearest = d;
      best = l;
    }
  }
  const sim::Box3 b = model.root().cell_box(model.tree().leaf(best));
  sim::PointEmbedding pe;
  pe.leaf = best;
  pe.weights = sim::trilinear_weights((x - b.min).cwiseQuotient(b.max - b.min));
  return model.evaluate(pe, slots);
}

// The volume of {X in S : phi(X) in blade} (blade posed, m), sampled uniformly in a rest box that holds every such X:
// the rest boxes, grown by half their edge (for the points of S in no leaf beside them), of the leaves whose deformed
// corners' box, grown alike, meets the blade's.
Sampled material_in_blade(const World& world, const sim::TriMesh& blade, long samples) {
  const sim::ObjectModel& model = world.simulator().model();
  std::vector<Vec3> slots;
  model.dofs().prolong(world.simulator().state().x, slots);
  const cutting::BladeVolume in_blade(blade);
  const cutting::BladeVolume in_surface(world.rest_surface());
  const sim::Box3 reach = in_blade.bounds();
  sim::Box3 box{Vec3::Constant(INFINITY), Vec3::Constant(-INFINITY)};
  for (int e = 0; e < model.num_elements(); ++e) {
    sim::Box3 d{Vec3::Constant(INFINITY), Vec3::Constant(-INFINITY)};
    for (int k = 0; k < 8; ++k) {
      d.min = d.min.cwiseMin(slots[8 * std::size_t(e) + std::size_t(k)]);
      d.max = d.max.cwiseMax(slots[8 * std::size_t(e) + std::size_t(k)]);
    }
    const double h = model.edge()[std::size_t(e)];
    d.min.array() -= 0.5 * h;  // with the points of S in no leaf beside it, which extrapolate its field
    d.max.array() += 0.5 * h;
    if ((d.max.array() < reach.min.array()).any() || (d.min.array() > reach.max.array()).any()) continue;
    const sim::Box3 r = model.root().cell_box(model.tree().leaf(e));
    box.min = box.min.cwiseMin(r.min - Vec3::Constant(0.5 * h));
    box.max = box.max.cwiseMax(r.max + Vec3::Constant(0.5 * h));
  }
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  long in = 0;
  for (long k = 0; k < samples; ++k) {
    const Vec3 x = box.min + Vec3(u(rng), u(rng), u(rng)).cwiseProduct(box.max - box.min);
    if (in_surface.contains(x) && in_blade.contains(deformed(model, slots, x))) ++in;
  }
  const double v = (box.max - box.min).prod();
  return {v * double(in) / double(samples), v * std::sqrt(double(in)) / double(samples)};
}

// meniscus_bites: 2 mm punches biting along the inner rim of the sagging meniscus, each 0.5-0.7 mm beside the
// last, so that most of each blade lies in the last one's hole and the cut removes a crescent. Each of the first
// five bites removes the material inside the deformed blade to within 3 % (the sampling's own error added).
TEST(CutAccuracy, EachBiteRemovesTheMaterialInsideTheDeformedBlade) {
  Scene scene = load_scene(std::string(OCTOCUT_SOURCE_DIR) + "/assets/scenes/meniscus_bites.json");
  ToolSettings& punch = scene.tools.at(0);
  ASSERT_TRUE(punch.blade_is_cylinder);
  const std::vector<ToolCut> cuts(punch.cuts.begin(), punch.cuts.begin() + 5);
  punch.cuts.clear();  // cut by hand below, at the same steps
  WorldOptions options;
  options.render = false;
  options.cuttable = true;
  World world(scene, options);
  for (const ToolCut& c : cuts) {
    while (world.time() < c.t - 0.5 * scene.solver.dt) world.step();
    sim::TriMesh blade = sim::cylinder_mesh(punch.cylinder.radius, punch.cylinder.height, punch.cylinder.segments);
    const sim::Pose pose = world.tool_pose(0);
    for (Vec3& v : blade.vertices) v = pose.apply(v);
    const Sampled truth = material_in_blade(world, blade, 1000000);
    const CutSummary cut = world.cut_now(0);
    ASSERT_EQ(cut.status, "ok") << c.t;
    EXPECT_NEAR(cut.removed_volume_m3, truth.volume, 0.03 * truth.volume + 3.0 * truth.sigma) << "bite at " << c.t;
    EXPECT_GT(truth.volume, 30.0 * truth.sigma) << c.t;  // the sampling resolves the crescent
  }
}

}  // namespace
}  // namespace octocut::engine
