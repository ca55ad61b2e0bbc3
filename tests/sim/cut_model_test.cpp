// The object-model side of a cut (SPEC §4 stage 4 and fragment removal, paper §4.4.2-4.4.3): a new material with
// the same leaves (with_material), components and fragments, removal of leaves, and the state carried across a
// node split. Materials are tet meshes of a slab on a regular grid, so every count and volume is known by hand.
#include <gtest/gtest.h>

#include <functional>
#include <map>
#include <random>
#include <set>
#include <string>
#include <thread>

#include "octocut/sim/dof_map.hpp"
#include "../common/kuhn_grid.hpp"
#include "octocut/sim/material_graph.hpp"
#include "octocut/sim/contact.hpp"
#include "octocut/sim/simulator.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

// Tet grid: cubes of edge 1/16 over [0,1] x [0,1] x [0, 1/4] (16 x 16 x 4 cubes), 6 Kuhn tets per cube.
constexpr int kNx = 16, kNy = 16, kNz = 4;
constexpr double kCube = 1.0 / 16.0;  // m
constexpr double kSlabVolume = 0.25;  // m^3

// The slab's tets in the cubes (i, j, k) that `keep` accepts, as a material graph.
std::shared_ptr<MaterialGraph> slab(const std::function<bool(int, int, int)>& keep) {
  return std::make_shared<MaterialGraph>(
      octocut::test::kuhn_grid(Vec3::Zero(), Vec3::Constant(kCube), {kNx, kNy, kNz}, keep));
}

// Rest-space box of the cubes [i0, i1) x [j0, j1) x [0, kNz): what a cut that removes them changed.
Box3 cubes_box(int i0, int i1, int j0, int j1) {
  return {kCube * Vec3(i0, j0, 0), kCube * Vec3(i1, j1, kNz)};
}

// An L-shaped slit two cubes wide (so that it takes material from both sides of the leaf faces x, y = 3/4): the
// cubes i in {11, 12}, j >= 11 and j in {11, 12}, i >= 11. It frees the corner [13/16, 1] x [13/16, 1] x [0, 1/4].
bool in_l_slit(int i, int j) { return ((i == 11 || i == 12) && j >= 11) || ((j == 11 || j == 12) && i >= 11); }

// The uncut slab in the unit root cube, uniform at level 3 (h = 1/8): 8 x 8 x 2 leaves, 9 x 9 x 3 nodes.
ObjectModel slab_model(std::vector<HandleSpec> handles = {}, std::vector<RefineSpec> refine = {}) {
  OctreeSpec spec;
  spec.root = {Vec3::Zero(), 1.0};
  spec.base_level = 3;
  spec.max_level = 6;
  spec.refine = std::move(refine);
  return ObjectModel::build(spec, slab([](int, int, int) { return true; }), {}, std::move(handles));
}

using test::expect_same;

// The DOFs that the slots of element e reference.
std::set<int> element_dofs(const ObjectModel& m, int e) {
  std::set<int> out;
  const DofMap& dm = m.dofs();
  for (int i = dm.slot_begin[8 * std::size_t(e)]; i < dm.slot_begin[8 * std::size_t(e) + 8]; ++i)
    out.insert(dm.slot_dof[std::size_t(i)]);
  return out;
}

Vec3 centre(const ObjectModel& m, int e) {
  const Box3 b = m.root().cell_box(m.tree().leaf(e));
  return 0.5 * (b.min + b.max);
}

double total_mass(const ObjectModel& m) {
  double s = 0.0;
  for (double v : m.dof_mass()) s += v;
  return s;
}

TEST(CutModel, SlabCutFullyInTwoSplitsEveryNodeOnThePlane) {
  const ObjectModel m = slab_model();
  ASSERT_EQ(m.num_elements(), 128);
  ASSERT_EQ(m.num_dofs(), 9 * 9 * 3);

  // Remove the full-thickness layer x in [7/16, 9/16]: the leaves on either side of x = 1/2 lose half their
  // material and no longer connect across that plane.
  const auto cut = slab([](int i, int, int) { return i != 7 && i != 8; });
  const ObjectModel c = m.with_material(cut, {cubes_box(7, 9, 0, kNy)});

  // The model it came from is untouched; the new one is the next revision.
  EXPECT_EQ(m.num_dofs(), 9 * 9 * 3);
  EXPECT_EQ(m.material().occupancy(cubes_box(7, 9, 0, kNy)), 1.0);
  EXPECT_NEAR(m.volume(), kSlabVolume, 1e-12 * kSlabVolume);
  EXPECT_EQ(c.revision(), m.revision() + 1);
  EXPECT_EQ(c.num_elements(), 128);
  EXPECT_EQ(c.dofs().check_invariants(), "");

  // Every one of the 9 x 3 nodes on the plane x = 1/2 is duplicated; no other node changes.
  EXPECT_EQ(c.num_dofs(), 9 * 9 * 3 + 9 * 3);
  int on_plane = 0;
  for (const Vec3& X : c.dofs().dof_rest) on_plane += X.x() == 0.5 ? 1 : 0;
  EXPECT_EQ(on_plane, 2 * 9 * 3);

  // Two components, one per side, and no DOF is shared between an element left and one right of the plane.
  int count = 0;
  const std::vector<int> comp = element_components(c, count);
  EXPECT_EQ(count, 2);
  std::set<int> left, right;
  for (int e = 0; e < c.num_elements(); ++e) {
    const bool is_left = centre(c, e).x() < 0.5;
    EXPECT_EQ(comp[std::size_t(e)], is_left ? comp[0] : 1 - comp[0]);
    for (int d : element_dofs(c, e)) (is_left ? left : right).insert(d);
  }
  for (int d : left) EXPECT_EQ(right.count(d), 0u) << "DOF " << d << " is shared across the cut";
  EXPECT_EQ(int(left.size() + right.size()), c.num_dofs());

  // The local update equals the global construction on the new material.
  expect_same(c.dofs(), build_dof_map(c.tree(), c.root(), *cut));

  // Volume and mass: the remaining material, 14/16 of the slab, and density times it.
  const double v = kSlabVolume * 14.0 / 16.0;
  EXPECT_NEAR(c.volume(), v, 1e-12 * v);
  EXPECT_NEAR(cut->volume(), v, 1e-12 * v);
  EXPECT_NEAR(total_mass(c), c.params().density * v, 1e-12 * c.params().density * v);
}

TEST(CutModel, OnlyLeavesMeetingTheChangedBoxesChange) {
  const ObjectModel m = slab_model();
  const auto cut = slab([](int i, int, int) { return i != 7 && i != 8; });
  // Without naming the changed region nothing is redone: the leaves keep their occupancy and the DOFs.
  const ObjectModel same = m.with_material(cut, {});
  EXPECT_EQ(same.occupancy(), m.occupancy());
  EXPECT_EQ(same.num_dofs(), m.num_dofs());
  // Named, exactly the two columns of leaves that meet the layer change occupancy, to 1/2.
  const ObjectModel c = m.with_material(cut, {cubes_box(7, 9, 0, kNy)});
  int halves = 0;
  for (int e = 0; e < c.num_elements(); ++e) {
    const double x = centre(c, e).x();
    const double expected = (x > 3.0 / 8.0 && x < 5.0 / 8.0) ? 0.5 : 1.0;
    EXPECT_NEAR(c.occupancy()[std::size_t(e)], expected, 1e-12);
    halves += expected == 0.5 ? 1 : 0;
  }
  EXPECT_EQ(halves, 2 * 8 * 2);
}

TEST(CutModel, ARevisionWithNothingChangedEqualsItsModelFieldByField) {
  // with_material and without_leaves build the next revision from parts (not by copying the model), so every
  // field must come across: the same material with nothing changed, or no leaf removed, is the same model.
  HandleSpec handle;
  handle.box = {Vec3(-1, -1, -1), Vec3(0.05, 2, 2)};
  handle.keyframes = {{1.0, Vec3(0.01, 0, 0), Vec3(0, 0, 10)}};
  MaterialParams params;
  params.young_modulus = 3e4;
  params.poisson_ratio = 0.42;
  params.density = 1100.0;
  params.rayleigh_mass = 0.1;
  params.rayleigh_stiffness = 0.01;
  OctreeSpec spec;
  spec.root = {Vec3(-0.1, -0.1, -0.1), 1.2};
  spec.base_level = 3;
  spec.max_level = 7;
  spec.refine = {{Box3{Vec3(0.5, 0.5, 0), Vec3(0.6, 0.6, 0.1)}, 5}};
  const auto material = slab([](int, int, int) { return true; });
  const ObjectModel m = ObjectModel::build(spec, material, params, {handle});
  for (const ObjectModel& r : {m.with_material(material, {}), m.without_leaves({})}) {
    EXPECT_EQ(r.revision(), m.revision() + 1);
    EXPECT_EQ(&r.material(), &m.material());
    EXPECT_EQ(r.root().min, m.root().min);
    EXPECT_EQ(r.root().size, m.root().size);
    EXPECT_EQ(r.max_level(), m.max_level());
    EXPECT_EQ(r.params().young_modulus, m.params().young_modulus);
    EXPECT_EQ(r.params().poisson_ratio, m.params().poisson_ratio);
    EXPECT_EQ(r.params().density, m.params().density);
    EXPECT_EQ(r.params().rayleigh_mass, m.params().rayleigh_mass);
    EXPECT_EQ(r.params().rayleigh_stiffness, m.params().rayleigh_stiffness);
    ASSERT_EQ(r.handles().size(), 1u);
    EXPECT_EQ(r.handles()[0].keyframes.size(), 1u);
    EXPECT_EQ(r.handle_position(0, 1.0), m.handle_position(0, 1.0));
    EXPECT_EQ(r.tree().leaves(), m.tree().leaves());
    EXPECT_EQ(r.occupancy(), m.occupancy());
    EXPECT_EQ(r.edge(), m.edge());
    EXPECT_EQ(r.stiffness_scale(), m.stiffness_scale());
    EXPECT_EQ(r.dof_mass(), m.dof_mass());
    EXPECT_EQ(r.dof_handle(), m.dof_handle());
    EXPECT_EQ(r.slot_rest(), m.slot_rest());
    EXPECT_EQ(r.unit_stiffness(), m.unit_stiffness());
    expect_same(r.dofs(), m.dofs());
  }
}

TEST(CutModel, NewParamsEqualAModelBuiltWithThem) {
  // A running object's material edited (the viewer): the same leaves and DOFs, and every quantity that depends on
  // the parameters as a model built from scratch with the new ones has it.
  HandleSpec handle;
  handle.box = {Vec3(-1, -1, -1), Vec3(0.05, 2, 2)};
  OctreeSpec spec;
  spec.root = {Vec3(-0.1, -0.1, -0.1), 1.2};
  spec.base_level = 3;
  spec.max_level = 6;
  spec.refine = {{Box3{Vec3(0.5, 0.5, 0), Vec3(0.6, 0.6, 0.1)}, 5}};
  const auto material = slab([](int, int, int) { return true; });
  MaterialParams before, after;
  before.young_modulus = 3e4;
  before.poisson_ratio = 0.3;
  after.young_modulus = 7e4;
  after.poisson_ratio = 0.45;
  after.density = 1100.0;
  after.rayleigh_mass = 2.0;
  after.rayleigh_stiffness = 0.01;
  const ObjectModel m = ObjectModel::build(spec, material, before, {handle});
  const ObjectModel edited = m.with_params(after);
  const ObjectModel fresh = ObjectModel::build(spec, material, after, {handle});
  EXPECT_EQ(edited.revision(), m.revision() + 1);
  EXPECT_EQ(edited.tree().leaves(), fresh.tree().leaves());
  expect_same(edited.dofs(), m.dofs());
  EXPECT_EQ(edited.params().rayleigh_mass, 2.0);
  EXPECT_TRUE(edited.unit_stiffness().isApprox(fresh.unit_stiffness(), 1e-14));
  ASSERT_EQ(edited.stiffness_scale().size(), fresh.stiffness_scale().size());
  for (std::size_t e = 0; e < fresh.stiffness_scale().size(); ++e)
    EXPECT_NEAR(edited.stiffness_scale()[e], fresh.stiffness_scale()[e], 1e-12 * fresh.stiffness_scale()[e]);
  ASSERT_EQ(edited.dof_mass().size(), fresh.dof_mass().size());
  for (std::size_t d = 0; d < fresh.dof_mass().size(); ++d)
    EXPECT_NEAR(edited.dof_mass()[d], fresh.dof_mass()[d], 1e-12 * fresh.dof_mass()[d]);
  EXPECT_EQ(edited.dof_handle(), fresh.dof_handle());
  // Out of range: refused, the model untouched.
  for (const auto& bad : {MaterialParams{0.0, 0.3, 1000, 0, 0}, MaterialParams{1e4, 0.5, 1000, 0, 0},
                          MaterialParams{1e4, 0.3, 0.0, 0, 0}, MaterialParams{1e4, 0.3, 1000, -1, 0},
                          MaterialParams{1e4, 0.3, 1000, 0, NAN}})
    EXPECT_THROW((void)m.with_params(bad), std::invalid_argument);
  EXPECT_EQ(m.params().young_modulus, 3e4);
}

TEST(CutModel, LeavesThatLoseAllMaterialAreDropped) {
  const ObjectModel m = slab_model();
  // Remove x in [1/4, 1/2) entirely: the two columns of leaves there empty out.
  const auto cut = slab([](int i, int, int) { return i < 4 || i >= 8; });
  const ObjectModel c = m.with_material(cut, {cubes_box(4, 8, 0, kNy)});
  EXPECT_EQ(c.num_elements(), 128 - 2 * 8 * 2);
  EXPECT_EQ(c.dofs().check_invariants(), "");
  expect_same(c.dofs(), build_dof_map(c.tree(), c.root(), *cut));
  // The gap leaves no node shared: 3 x 9 x 3 nodes left, 5 x 9 x 3 right.
  EXPECT_EQ(c.num_dofs(), (3 + 5) * 9 * 3);
  int count = 0;
  element_components(c, count);
  EXPECT_EQ(count, 2);
  const double v = kSlabVolume * 12.0 / 16.0;
  EXPECT_NEAR(c.volume(), v, 1e-12 * v);
  EXPECT_NEAR(total_mass(c), c.params().density * v, 1e-12 * c.params().density * v);
}

TEST(CutModel, PartialSlitSplitsOnlyTheNodesAlongIt) {
  // Paper Fig. 4: a slit at x = 1/2 from y = 0 to y = 1/2 (full thickness) stops mid-slab.
  const ObjectModel m = slab_model();
  const auto cut = slab([](int i, int j, int) { return !((i == 7 || i == 8) && j < 8); });
  const ObjectModel c = m.with_material(cut, {cubes_box(7, 9, 0, 8)});
  EXPECT_EQ(c.dofs().check_invariants(), "");
  expect_same(c.dofs(), build_dof_map(c.tree(), c.root(), *cut));

  // Nodes on x = 1/2 with y in {0, 1/8, 2/8, 3/8} split in two (4 x 3 nodes); the slit's tip y = 1/2 and
  // beyond keep one DOF, since material goes round the tip.
  std::map<std::pair<double, double>, int> per_node;  // (y, z) on the plane -> DOFs
  for (const Vec3& X : c.dofs().dof_rest)
    if (X.x() == 0.5) ++per_node[{X.y(), X.z()}];
  ASSERT_EQ(per_node.size(), 9u * 3u);
  for (const auto& [yz, n] : per_node) EXPECT_EQ(n, yz.first < 0.5 ? 2 : 1) << "y " << yz.first;
  EXPECT_EQ(c.num_dofs(), 9 * 9 * 3 + 4 * 3);
  int count = 0;
  element_components(c, count);
  EXPECT_EQ(count, 1);
}

// An adaptive slab: level 1 at x < 1/2 would be too coarse for the slab, so use a block instead: the coarse leaf
// C = [0, 1/2]^3 next to the x > 1/2 half refined to `fine` (level 2 or 3).
ObjectModel block_model(const std::shared_ptr<const MaterialSource>& material, int fine) {
  OctreeSpec spec;
  spec.root = {Vec3::Zero(), 1.0};
  spec.base_level = 1;
  spec.max_level = 4;
  spec.refine = {RefineSpec{{Vec3(0.5, 0, 0), Vec3(1, 0.5, 0.5)}, fine}};
  return ObjectModel::build(spec, material, {}, {});
}

TEST(CutModel, HangingSlotsNeverBindAcrossACut) {
  const Box3 block{Vec3::Zero(), Vec3(1, 0.5, 0.5)};
  for (int fine : {2, 3}) {
    const double h = 1.0 / double(1 << fine);
    const ObjectModel m = block_model(std::make_shared<BoxMaterial>(block), fine);
    const int coarse = m.embed(Vec3(0.25, 0.25, 0.25))->leaf;
    ASSERT_EQ(m.tree().leaf(coarse).level, 1);
    // The fine leaf whose corner 6 (-x, +y, +z) is the point (1/2, 1/4, 1/4), inside the coarse leaf's +x face.
    const int f = m.embed(Vec3(0.5 + h / 2, 0.25 - h / 2, 0.25 - h / 2))->leaf;
    ASSERT_EQ(m.tree().leaf(f).level, fine);
    const std::size_t slot = 8 * std::size_t(f) + 6;
    ASSERT_EQ(m.slot_rest()[slot], Vec3(0.5, 0.25, 0.25));
    const std::set<int> coarse_dofs = element_dofs(m, coarse);

    // Control, material connected: the slot hangs on the coarse leaf and interpolates its face corners.
    EXPECT_EQ(m.dofs().slot_master[slot], coarse);
    for (int i = m.dofs().slot_begin[slot]; i < m.dofs().slot_begin[slot + 1]; ++i)
      EXPECT_EQ(coarse_dofs.count(m.dofs().slot_dof[std::size_t(i)]), 1u);
    int count = 0;
    element_components(m, count);
    EXPECT_EQ(count, 1);

    // Remove the layer x in [0.49, 0.51] across the face (material that merely touches the face from one side
    // still connects it, SPEC §2.2): the face no longer connects.
    const Box3 removed{Vec3(0.49, 0, 0), Vec3(0.51, 0.5, 0.5)};
    const auto cut = std::make_shared<BoxSetMaterial>(
        std::vector<Box3>{{Vec3::Zero(), Vec3(0.49, 0.5, 0.5)}, {Vec3(0.51, 0, 0), Vec3(1, 0.5, 0.5)}});
    const ObjectModel c = m.with_material(cut, {removed});
    ASSERT_EQ(c.num_elements(), m.num_elements());
    ASSERT_EQ(c.tree().leaf(f), m.tree().leaf(f));
    EXPECT_EQ(c.dofs().check_invariants(), "");
    expect_same(c.dofs(), build_dof_map(c.tree(), c.root(), *cut));
    EXPECT_EQ(c.dofs().slot_master[slot], -1);
    const std::set<int> cut_coarse = element_dofs(c, coarse);
    // No slot of any fine leaf references a DOF of the coarse leaf, the bound slot above included.
    for (int e = 0; e < c.num_elements(); ++e) {
      if (e == coarse) continue;
      for (int d : element_dofs(c, e)) EXPECT_EQ(cut_coarse.count(d), 0u) << "element " << e << " DOF " << d;
    }
    EXPECT_EQ(c.dofs().hanging_slots, 0);
    element_components(c, count);
    EXPECT_EQ(count, 2);
    // The fine side's (1/2 / h + 1)^3 nodes are all DOFs of their own; the coarse leaf keeps its 8 corners.
    const int side = int(0.5 / h) + 1;
    EXPECT_EQ(c.num_dofs(), 8 + side * side * side);
  }
}

TEST(CutModel, FragmentWithoutHandleIsFoundAndRemoved) {
  // A handle holds the slab's x < 0.05 end; the L-shaped slit frees a corner of the slab.
  HandleSpec handle;
  handle.box = {Vec3(-1, -1, -1), Vec3(0.05, 2, 2)};
  const ObjectModel m = slab_model({handle});
  const auto cut = slab([](int i, int j, int) { return !in_l_slit(i, j); });
  const ObjectModel c = m.with_material(cut, {cubes_box(11, 13, 11, 16), cubes_box(11, 16, 11, 13)});
  EXPECT_EQ(c.dofs().check_invariants(), "");
  expect_same(c.dofs(), build_dof_map(c.tree(), c.root(), *cut));

  int count = 0;
  const std::vector<int> comp = element_components(c, count);
  ASSERT_EQ(count, 2);
  const std::vector<ComponentInfo> info = component_info(c, comp, count);
  ASSERT_EQ(info.size(), 2u);
  // Component 0 holds element 0 (at the origin, by the handle); the fragment is component 1.
  EXPECT_TRUE(info[0].anchored);
  EXPECT_FALSE(info[1].anchored);
  const double fragment = (3 * kCube) * (3 * kCube) * 0.25;
  const double slit_volume = 16 * kCube * kCube * 0.25;  // 10 + 10 - 4 cubes of the slit, full thickness
  EXPECT_NEAR(info[1].volume, fragment, 1e-12 * fragment);
  EXPECT_EQ(info[1].elements, 2 * 2 * 2);
  EXPECT_EQ(info[0].elements + info[1].elements, c.num_elements());
  EXPECT_NEAR(info[0].volume, kSlabVolume - fragment - slit_volume, 1e-12);
  EXPECT_NEAR(info[0].volume + info[1].volume, cut->volume(), 1e-12 * kSlabVolume);

  // Without the fragment's leaves: a valid model with exactly the fragment's volume less.
  std::vector<int> loose;
  for (int e = 0; e < c.num_elements(); ++e)
    if (comp[std::size_t(e)] == 1) loose.push_back(e);
  const ObjectModel r = c.without_leaves(loose);
  EXPECT_EQ(r.revision(), c.revision() + 1);
  EXPECT_EQ(r.num_elements(), c.num_elements() - 8);
  EXPECT_EQ(r.dofs().check_invariants(), "");
  expect_same(r.dofs(), build_dof_map(r.tree(), r.root(), r.material()));
  EXPECT_NEAR(r.volume(), c.volume() - fragment, 1e-12 * kSlabVolume);
  EXPECT_NEAR(total_mass(r), r.params().density * r.volume(), 1e-12 * total_mass(r));
  element_components(r, count);
  EXPECT_EQ(count, 1);
  // The fragment's leaves are the 2 x 2 x 2 in [3/4, 1]^2 x [0, 1/4]; their 3 x 3 x 3 nodes are gone with them.
  EXPECT_EQ(r.num_dofs(), c.num_dofs() - 27);
  // The handle still drives the 9 x 3 DOFs of the x = 0 face.
  EXPECT_EQ(std::count(r.dof_handle().begin(), r.dof_handle().end(), 0), 9 * 3);

  EXPECT_THROW((void)c.without_leaves({c.num_elements()}), std::out_of_range);
  EXPECT_THROW((void)c.without_leaves({-1}), std::out_of_range);
}

// Affine deformation used for the transfer tests.
const Mat3 kF = (Mat3() << 1.1, 0.2, -0.1, 0.05, 0.95, 0.1, -0.2, 0.1, 1.2).finished();
const Vec3 kT(0.01, -0.02, 0.03);
const Mat3 kG = (Mat3() << 0.3, -0.1, 0.0, 0.2, 0.1, 0.4, 0.0, -0.5, 0.2).finished();
const Vec3 kW(-0.1, 0.2, 0.05);

SimState affine_state(const ObjectModel& m) {
  SimState s = SimState::rest(m);
  for (int d = 0; d < m.num_dofs(); ++d) {
    const Vec3& X = m.dofs().dof_rest[std::size_t(d)];
    s.x[std::size_t(d)] = kF * X + kT;
    s.v[std::size_t(d)] = kG * X + kW;
  }
  return s;
}

// Elements of m whose box meets the plane x = 1/2 (from either side).
std::vector<int> at_plane(const ObjectModel& m) {
  std::vector<int> out;
  for (int e = 0; e < m.num_elements(); ++e) {
    const Box3 b = m.root().cell_box(m.tree().leaf(e));
    if (b.min.x() == 0.5 || b.max.x() == 0.5) out.push_back(e);
  }
  return out;
}

TEST(CutModel, TransferAcrossASplitKeepsAnAffineFieldExactly) {
  const ObjectModel m = slab_model();
  const SimState s = affine_state(m);
  const auto cut = slab([](int i, int, int) { return i != 7 && i != 8; });
  // The cut as it stands (nodes on x = 1/2 split in two), and the cut pipeline that first refines the leaves at
  // the cut (the half-empty children are dropped); the state goes across both revisions at once.
  for (const bool refine : {false, true}) {
    const ObjectModel c =
        (refine ? m.refined(at_plane(m)) : m).with_material(cut, {cubes_box(7, 9, 0, kNy)});
    ASSERT_GT(c.num_dofs(), m.num_dofs());
    const SimState t = transfer_state(m, s, c);
    ASSERT_EQ(int(t.x.size()), c.num_dofs());
    for (int d = 0; d < c.num_dofs(); ++d) {
      const Vec3& X = c.dofs().dof_rest[std::size_t(d)];
      EXPECT_LT((t.x[std::size_t(d)] - (kF * X + kT)).norm(), 1e-14) << "DOF " << d << " refine " << refine;
      EXPECT_LT((t.v[std::size_t(d)] - (kG * X + kW)).norm(), 1e-14) << "DOF " << d << " refine " << refine;
    }
  }
}

// transfer_matrix is the linear map transfer_state applies: T x_old equals the transferred positions, per
// coordinate, and each row of T sums to 1.
TEST(CutModel, TransferMatrixIsWhatTransferStateApplies) {
  const ObjectModel m = slab_model();
  const SimState s = affine_state(m);
  const auto cut = slab([](int i, int, int) { return i != 7 && i != 8; });
  const ObjectModel c = m.refined(at_plane(m)).with_material(cut, {cubes_box(7, 9, 0, kNy)});
  const SpMat T = transfer_matrix(m, c);
  ASSERT_EQ(T.rows(), c.num_dofs());
  ASSERT_EQ(T.cols(), m.num_dofs());
  const SimState t = transfer_state(m, s, c);
  Eigen::MatrixXd X(m.num_dofs(), 3);
  for (int d = 0; d < m.num_dofs(); ++d) X.row(d) = s.x[std::size_t(d)].transpose();
  const Eigen::MatrixXd Y = T * X;
  const VecX row_sums = T * VecX::Ones(T.cols());
  for (int d = 0; d < c.num_dofs(); ++d) {
    EXPECT_LT((Y.row(d).transpose() - t.x[std::size_t(d)]).norm(), 1e-14) << "DOF " << d;
    EXPECT_NEAR(row_sums[d], 1.0, 1e-14) << "DOF " << d;
  }
}

// With solver.factor_lag > 0, the solves after a cut need no inline factorisation: the old revision's factor,
// through the transfer, and an exact solve on the cut's region precondition them while the new pattern's factor is
// computed in the background and put in place at a fixed solve. The trajectory equals the one with an inline
// factorisation up to the solver tolerance, and a second run is bit-identical.
TEST(CutModel, SolverBridgesACutWithoutAnInlineFactorisation) {
  const auto cut = slab([](int i, int, int) { return i != 7 && i != 8; });
  struct Run {
    std::vector<Vec3> x;
    int inline_after_cut = 0, background_after_cut = 0;
  };
  auto run = [&](int lag) {
    SimulatorOptions o;
    o.dt = 1e-3;
    o.tolerance = 1e-9;
    o.threads = 2;
    o.factor_lag = lag;
    Simulator sim(slab_model({HandleSpec{{Vec3(-1, -1, -1), Vec3(0.13, 2, 2)}, {}}}), o);
    for (int i = 0; i < 5; ++i) sim.step();
    const ObjectModel& now = sim.model();
    sim.adopt(sim.prepare_model(now.refined(at_plane(now)).with_material(cut, {cubes_box(7, 9, 0, kNy)}), true));
    Run r;
    for (int i = 0; i < 10; ++i) {
      sim.step();
      EXPECT_TRUE(sim.last_solve().ok);
      r.inline_after_cut += sim.last_solve().refactorized && !sim.last_solve().background ? 1 : 0;
      r.background_after_cut += sim.last_solve().background ? 1 : 0;
    }
    EXPECT_EQ(sim.stats().solver_failures, 0);
    r.x = sim.state().x;
    return r;
  };
  const Run inline_run = run(0), a = run(3), b = run(3);
  EXPECT_EQ(a.inline_after_cut, 0);
  EXPECT_GE(a.background_after_cut, 1);
  ASSERT_EQ(a.x.size(), inline_run.x.size());
  // Deviation against the largest displacement since rest (the slab sags under gravity).
  const ObjectModel rest = slab_model().refined(at_plane(slab_model())).with_material(cut, {cubes_box(7, 9, 0, kNy)});
  double dev = 0.0, moved = 0.0;
  for (std::size_t d = 0; d < a.x.size(); ++d) {
    dev = std::max(dev, (a.x[d] - inline_run.x[d]).norm());
    moved = std::max(moved, (inline_run.x[d] - rest.dofs().dof_rest[d]).norm());
    EXPECT_TRUE(a.x[d] == b.x[d]) << "DOF " << d;
  }
  EXPECT_GT(moved, 1e-6);
  EXPECT_LT(dev, 1e-6 * moved);
}

TEST(CutModel, ACutAloneMovesNoSlot) {
  // With the same leaves, a new material only splits and unbinds: every slot must start where it was, whatever
  // the state (here random), in the partial slit and in the L-shaped slit that frees a fragment.
  const ObjectModel m = slab_model();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.1, 0.1);
  SimState s = SimState::rest(m);
  for (std::size_t d = 0; d < s.x.size(); ++d) {
    s.x[d] += Vec3(u(rng), u(rng), u(rng));
    s.v[d] = Vec3(u(rng), u(rng), u(rng));
  }
  std::vector<Vec3> xs, vs;
  m.dofs().prolong(s.x, xs);
  m.dofs().prolong(s.v, vs);
  const std::vector<ObjectModel> cuts = {
      m.with_material(slab([](int i, int j, int) { return !((i == 7 || i == 8) && j < 8); }),
                      {cubes_box(7, 9, 0, 8)}),
      m.with_material(slab([](int i, int j, int) { return !in_l_slit(i, j); }),
                      {cubes_box(11, 13, 11, 16), cubes_box(11, 16, 11, 13)})};
  for (const ObjectModel& c : cuts) {
    ASSERT_EQ(c.num_elements(), m.num_elements());
    ASSERT_GT(c.num_dofs(), m.num_dofs());
    const SimState t = transfer_state(m, s, c);
    std::vector<Vec3> xt, vt;
    c.dofs().prolong(t.x, xt);
    c.dofs().prolong(t.v, vt);
    for (std::size_t k = 0; k < xt.size(); ++k) {
      EXPECT_EQ(xt[k], xs[k]) << "slot " << k;
      EXPECT_EQ(vt[k], vs[k]) << "slot " << k;
    }
  }
}

TEST(CutModel, TransferKeepsEachSideOfASplitApart) {
  const ObjectModel m = slab_model();
  const auto cut = slab([](int i, int, int) { return i != 7 && i != 8; });
  const ObjectModel c = m.with_material(cut, {cubes_box(7, 9, 0, kNy)});

  // After the split, open the cut: the right side's DOFs move by `gap` and get velocity `vr`, the left side's
  // stay affine. The two DOFs of a plane node now hold different values.
  const Vec3 gap(0.02, 0.01, -0.03), vr(0.5, 0.0, -0.25);
  int count = 0;
  const std::vector<int> comp = element_components(c, count);
  ASSERT_EQ(count, 2);
  const int right_comp = comp[std::size_t(c.embed(Vec3(0.9, 0.5, 0.1))->leaf)];
  // Side of each DOF: the component of the element that owns its own slot.
  auto side_of = [](const ObjectModel& mm, const std::vector<int>& cc, int d) {
    return cc[std::size_t(mm.dofs().dof_slot[std::size_t(d)] / 8)];
  };
  SimState s = affine_state(c);
  for (int d = 0; d < c.num_dofs(); ++d)
    if (side_of(c, comp, d) == right_comp) {
      s.x[std::size_t(d)] += gap;
      s.v[std::size_t(d)] += vr;
    }
  auto expect_sides = [&](const ObjectModel& next, const SimState& t) {
    int n = 0;
    const std::vector<int> cn = element_components(next, n);
    ASSERT_EQ(n, 2);
    const int rn = cn[std::size_t(next.embed(Vec3(0.9, 0.5, 0.1))->leaf)];
    for (int d = 0; d < next.num_dofs(); ++d) {
      const Vec3& X = next.dofs().dof_rest[std::size_t(d)];
      const bool right = side_of(next, cn, d) == rn;
      const Vec3 x = kF * X + kT + (right ? gap : Vec3::Zero());
      const Vec3 v = kG * X + kW + (right ? vr : Vec3::Zero());
      EXPECT_LT((t.x[std::size_t(d)] - x).norm(), 1e-14) << "DOF " << d << " at " << X.transpose();
      EXPECT_LT((t.v[std::size_t(d)] - v).norm(), 1e-14) << "DOF " << d << " at " << X.transpose();
    }
  };

  // Further revision 1: refine every leaf at the cut, on both sides (new DOFs on the plane come from each side).
  const ObjectModel r = c.refined(at_plane(c));
  ASSERT_GT(r.num_dofs(), c.num_dofs());
  expect_sides(r, transfer_state(c, s, r));

  // Further revision 2: a notch next to the cut (the cubes i = 6, j < 4, k = 0) redoes the nodes of the leaves
  // around it, the split ones on x = 1/2 included, and splits nothing more.
  const auto notched = slab([](int i, int j, int k) { return i != 7 && i != 8 && !(i == 6 && j < 4 && k == 0); });
  const ObjectModel w = c.with_material(notched, {{kCube * Vec3(6, 0, 0), kCube * Vec3(7, 4, 1)}});
  EXPECT_EQ(w.num_dofs(), c.num_dofs());
  expect_same(w.dofs(), build_dof_map(w.tree(), w.root(), *notched));
  expect_sides(w, transfer_state(c, s, w));

  // Further revision 3: a leaf far from the cut goes (a bite out of the right side's far corner).
  const ObjectModel b = c.without_leaves({c.embed(Vec3(0.95, 0.95, 0.2))->leaf});
  expect_sides(b, transfer_state(c, s, b));
}

TEST(CutModel, TransferWhereAHangingSlotBecomesADof) {
  // Before the cut the fine slots on x = 1/2 hang on the coarse leaf; after it they are DOFs of their own and must
  // start where the hanging slot was (the coarse face's interpolation), not at some average across the cut.
  const Box3 block{Vec3::Zero(), Vec3(1, 0.5, 0.5)};
  const ObjectModel m = block_model(std::make_shared<BoxMaterial>(block), 3);
  SimState s = affine_state(m);
  // A non-affine touch: the coarse leaf's DOFs get an extra offset, so the hanging values are its interpolation.
  const int coarse = m.embed(Vec3(0.25, 0.25, 0.25))->leaf;
  const Vec3 bump(0.0, 0.0, 0.05);
  const std::set<int> coarse_dofs = element_dofs(m, coarse);
  for (int d : coarse_dofs) {
    const Vec3& X = m.dofs().dof_rest[std::size_t(d)];
    s.x[std::size_t(d)] += bump * (X.y() * 2.0);  // varies along y over the face
  }
  std::vector<Vec3> slots;
  m.dofs().prolong(s.x, slots);

  const auto cut = std::make_shared<BoxSetMaterial>(
      std::vector<Box3>{{Vec3::Zero(), Vec3(0.49, 0.5, 0.5)}, {Vec3(0.51, 0, 0), Vec3(1, 0.5, 0.5)}});
  const ObjectModel c = m.with_material(cut, {{Vec3(0.49, 0, 0), Vec3(0.51, 0.5, 0.5)}});
  const SimState t = transfer_state(m, s, c);
  // Every slot of every fine leaf (unchanged leaves) keeps its old position; the coarse leaf too.
  std::vector<Vec3> after;
  c.dofs().prolong(t.x, after);
  ASSERT_EQ(c.num_elements(), m.num_elements());
  for (std::size_t k = 0; k < after.size(); ++k) EXPECT_LT((after[k] - slots[k]).norm(), 1e-14) << "slot " << k;
}

TEST(CutModel, ComponentsOfAnUncutModelAndBadArguments) {
  const ObjectModel m = slab_model();
  int count = -1;
  const std::vector<int> comp = element_components(m, count);
  EXPECT_EQ(count, 1);
  EXPECT_TRUE(std::all_of(comp.begin(), comp.end(), [](int c) { return c == 0; }));
  const auto info = component_info(m, comp, count);
  EXPECT_FALSE(info[0].anchored);
  EXPECT_EQ(info[0].elements, 128);
  EXPECT_NEAR(info[0].volume, kSlabVolume, 1e-12 * kSlabVolume);
  EXPECT_THROW((void)component_info(m, {0, 0}, 1), std::invalid_argument);
  EXPECT_THROW((void)m.with_material(nullptr, {}), std::invalid_argument);
  // A material that leaves nothing where the leaves are cannot become a model.
  const auto elsewhere = std::make_shared<BoxMaterial>(Box3{Vec3(2, 2, 2), Vec3(3, 3, 3)});
  EXPECT_THROW((void)m.with_material(elsewhere, {{Vec3::Zero(), Vec3::Ones()}}), std::invalid_argument);
}

// With spare time (Simulator::prepare_model's spare_time), the preparation also factorises the exact solve on the
// cut's region that pcg's first solves after the cut combine with the inherited factor; the first step otherwise
// does. The choice changes no result: the trajectories after the cut are the same bit for bit, without contacts and
// with a contact on DOFs of the cut's region (whose blocks the prepared solve, taken without contacts, lacks: the
// first step then builds it itself) or off it.
TEST(CutModel, BridgePreparedWithTheRevisionGivesTheSameSteps) {
  const auto cut = slab([](int i, int, int) { return i != 7 && i != 8; });
  HandleSpec handle{{Vec3(-1, -1, -1), Vec3(0.13, 2, 2)}, {}};
  // A contact pressing up on the DOF nearest `at` (rest position), for every step after the cut.
  const auto contact_at = [](const ObjectModel& m, const Vec3& at) {
    int best = 0;
    for (int d = 0; d < m.num_dofs(); ++d)
      if ((m.dofs().dof_rest[std::size_t(d)] - at).norm() < (m.dofs().dof_rest[std::size_t(best)] - at).norm())
        best = d;
    Contact c;
    c.dofs = {{best, 1.0}};
    c.normal = Vec3::UnitZ();
    c.penetration = 1e-4;
    c.stiffness = 1e6;
    c.damping = 10.0;
    c.friction = 0.3;
    return std::vector<Contact>{c};
  };
  const Vec3 in_region(0.5, 0.5, 0.0), off_region(0.97, 0.03, 0.0);  // at the cut; far from it
  for (int contact = 0; contact < 3; ++contact) {
    std::vector<std::vector<Vec3>> runs;
    for (const bool spare : {false, true}) {
      SimulatorOptions o;
      o.dt = 1e-3;
      o.tolerance = 1e-6;
      o.threads = 2;
      o.factor_lag = 4;
      Simulator sim(slab_model({handle}), o);
      for (int i = 0; i < 5; ++i) sim.step();
      const ObjectModel& now = sim.model();
      ObjectModel next = now.refined(at_plane(now)).with_material(cut, {cubes_box(7, 9, 0, kNy)});
      PreparedModel prepared = sim.prepare_model(std::move(next), true, [spare] { return spare; });
      // The preparation's time for the bridge is counted apart (the cut's report puts it in bridge_ms, outside
      // solver_update): there only when it ran.
      if (spare)
        EXPECT_GT(prepared.bridge_ms(), 0.0);
      else
        EXPECT_EQ(prepared.bridge_ms(), 0.0);
      sim.adopt(std::move(prepared));
      for (int i = 0; i < 6; ++i) {
        if (contact > 0) sim.set_contacts(contact_at(sim.model(), contact == 1 ? in_region : off_region));
        sim.step();
        ASSERT_TRUE(sim.last_solve().ok);
      }
      runs.push_back(sim.state().x);
    }
    ASSERT_EQ(runs[0].size(), runs[1].size());
    for (std::size_t d = 0; d < runs[0].size(); ++d) ASSERT_EQ(runs[0][d], runs[1][d]) << "contact " << contact;
  }
}

// A revision prepared on another thread and adopted (what a cut does) leaves the simulator exactly as set_model and
// refresh_solver do: the same state after the switch and, bit for bit, after steps of the dynamics.
TEST(CutModel, PreparedRevisionAdoptedEqualsSetModel) {
  HandleSpec handle;
  handle.box = {Vec3(-1, -1, -1), Vec3(0.05, 2, 2)};
  const ObjectModel uncut = slab_model({handle});
  // The revision: the L-shaped slit cut out, with the leaves at the slit refined once.
  const auto cut = slab([](int i, int j, int) { return !in_l_slit(i, j); });
  const ObjectModel next = uncut.with_material(cut, {cubes_box(11, 16, 11, 16)});
  for (const std::string solver : {"pcg", "cholmod"}) {
    SimulatorOptions o;
    o.dt = 1e-3;
    o.linear_solver = solver;
    o.threads = 2;
    Simulator a(uncut, o), b(uncut, o);
    for (int k = 0; k < 5; ++k) {
      a.step();
      b.step();
    }
    a.set_model(next);
    a.refresh_solver();
    PreparedModel prepared;
    std::thread([&] { prepared = b.prepare_model(next, true); }).join();
    EXPECT_EQ(b.model().num_dofs(), uncut.num_dofs()) << "preparing must not change the simulator";
    EXPECT_EQ(prepared.model().num_dofs(), next.num_dofs());
    b.adopt(std::move(prepared));
    ASSERT_EQ(a.model().num_dofs(), b.model().num_dofs());
    for (int k = 0; k < 5; ++k) {
      a.step();
      b.step();
    }
    ASSERT_EQ(a.state().x.size(), b.state().x.size());
    for (std::size_t d = 0; d < a.state().x.size(); ++d) {
      ASSERT_EQ(a.state().x[d], b.state().x[d]) << solver << " DOF " << d;
      ASSERT_EQ(a.state().v[d], b.state().v[d]) << solver << " DOF " << d;
    }
    EXPECT_THROW(b.adopt(PreparedModel{}), std::invalid_argument);
  }
}

}  // namespace
}  // namespace octocut::sim
