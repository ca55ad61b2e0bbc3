#pragma once
// The object model (MuJoCo's mjModel in spirit): octree, occupancy, DOF map, masses and handles. It changes only by
// producing a new revision (refinement, and from the cutting issue on, cuts); the simulation state lives apart in
// SimState.
#include <array>
#include <cstddef>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include "octocut/sim/disjoint_sets.hpp"
#include "octocut/sim/dof_map.hpp"
#include "octocut/sim/hex_element.hpp"
#include "octocut/sim/material.hpp"
#include "octocut/sim/material_graph.hpp"
#include "octocut/sim/octree.hpp"
#include "octocut/sim/pose.hpp"

namespace octocut::sim {

/// Isotropic linear elastic material with Rayleigh damping.
struct MaterialParams {
  double young_modulus = 1e5;      ///< E, Pa
  double poisson_ratio = 0.3;      ///< nu, dimensionless
  double density = 1000.0;         ///< rho, kg/m^3
  double rayleigh_mass = 0.0;      ///< alpha, 1/s
  double rayleigh_stiffness = 0.0; ///< beta, s
  HexFormulation element = HexFormulation::bbar;  ///< the hexahedron's strain interpolation (RESULTS: "B-bar by default")
};

/// A rest-space box whose DOFs follow a keyframed rigid motion (fixed without keyframes).
struct HandleSpec {
  Box3 box;  ///< rest-space box, m
  /// The motion, sorted by t: `position` is the translation of the box (of its centre), m, and `rotation_deg` the
  /// XYZ Euler angles of its rotation about the box centre, degrees.
  std::vector<PoseKeyframe> keyframes;

  /// Where rest point X (m) is at time t (s): c + R (X - c) + p for the box centre c and the pose (p, R) that
  /// interpolate_pose gives for the keyframes (translation linear, rotation slerp, held after the last keyframe).
  /// Before a first keyframe later than t = 0 the handle moves from its rest pose at t = 0, as if an identity
  /// keyframe were at t = 0.
  [[nodiscard]] Vec3 position(const Vec3& X, double t) const;
};

/// A static refinement region: leaves overlapping `box` with positive volume are refined to `level`.
struct RefineSpec {
  Box3 box;
  int level = 0;
};

/// Most elements one object may have (the assembly keeps about 6 KB per element); building a larger octree fails
/// with std::invalid_argument.
inline constexpr std::size_t kMaxElements = 1'000'000;

/// How to build an object's octree.
struct OctreeSpec {
  RootGeometry root;
  int base_level = 3;
  int max_level = 8;
  std::vector<RefineSpec> refine;
};

/// A point of rest space bound to a leaf by trilinear weights.
struct PointEmbedding {
  int leaf = -1;
  std::array<double, 8> weights{};  ///< trilinear weights of the leaf's 8 corners, sum 1
};

/// Constant description of one deformable object for one topology revision.
class ObjectModel {
 public:
  /// An empty model, the state of an object that cuts removed entirely: no leaves, elements, DOFs, slots or
  /// handles, and a material that holds none. Every accessor works on it; embed() finds nothing.
  ObjectModel();

  /// Builds the octree (uniform to base_level, then the refine regions), drops empty leaves, and builds the DOFs.
  static ObjectModel build(const OctreeSpec& octree, std::shared_ptr<const MaterialSource> material,
                           const MaterialParams& params, std::vector<HandleSpec> handles);

  /// A new revision in which each listed leaf (by index) is replaced by its non-empty children.
  [[nodiscard]] ObjectModel refined(const std::vector<int>& leaves) const;

  /// Refinement over several levels in one new revision: every leaf for which `split(leaf)` holds is replaced by its
  /// non-empty children, each non-empty child for which `split(child)` holds by its own non-empty children, and so
  /// on, never below max_level(). `split` must be a pure function of the cell (it may also be asked about children
  /// that turn out empty). The result equals repeated refined() calls, each on the leaves for which `split` holds,
  /// until none is left; the DOF map, masses and handles are built once. `refined`, when given, receives the number
  /// of leaves refined (what the repeated calls would refine in all). When no leaf is split the result is a copy of
  /// this model, revision included.
  [[nodiscard]] ObjectModel refined_where(const std::function<bool(const Cell&)>& split,
                                          int* refined = nullptr) const;

  /// refined_where(split) followed by with_material(material, changed), as one new revision (one above this
  /// model's): the same leaves, occupancy and DOF map, bit for bit. A new leaf that the changed boxes touch and
  /// that is not split further is measured once, in the new material (a leaf empty before the cut is empty after
  /// it, so the old measurement decides nothing), and the DOFs are updated once. `material` must hold material
  /// nowhere this model's material holds none (a cut only removes: MaterialGraph::without), and `changed` must
  /// cover every region where the two differ, as for with_material. Throws as with_material does.
  [[nodiscard]] ObjectModel refined_with_material(const std::function<bool(const Cell&)>& split,
                                                  std::shared_ptr<const MaterialSource> material,
                                                  const std::vector<Box3>& changed, int* refined = nullptr) const;

  /// A new revision with the same leaves and a new material (e.g. M after a cut removed tets), for cutting stage 4
  /// (SPEC §4). `changed` lists rest-space boxes, m, that cover every region where the material changed (their
  /// union must hold each removed tet). Only leaves whose closed box meets one of them may change: their occupancy
  /// is measured anew from `material`, those below kEmptyOccupancy are dropped, and the DOFs are rebuilt locally
  /// around them (update_dof_map), so nodes split where the material no longer connects. Every other leaf keeps
  /// its occupancy. The DOF map equals build_dof_map(tree(), root(), *material) of the result. With this model's
  /// own material nothing changes (its occupancy and DOFs already follow it): the result is a copy with the next
  /// revision number, as after refined_with_material. Throws
  /// std::invalid_argument for a null material or when no leaf would hold material. `*this` is left untouched.
  [[nodiscard]] ObjectModel with_material(std::shared_ptr<const MaterialSource> material,
                                          const std::vector<Box3>& changed) const;

  /// A new revision without the listed leaves (by index; repeats allowed), e.g. a fragment that a cut separated.
  /// The material is kept, the other leaves keep their occupancy, and the DOFs around the removed leaves are
  /// rebuilt locally. Throws std::out_of_range for a bad index and std::invalid_argument when every leaf would go.
  [[nodiscard]] ObjectModel without_leaves(const std::vector<int>& leaves) const;

  /// A new revision with the same leaves, occupancy and DOFs and new material parameters (E, nu, density, Rayleigh
  /// damping): the unit stiffness, the stiffness scales and the lumped masses follow them. A viewer edits the
  /// material of a running object through it. Throws std::invalid_argument for E <= 0, nu outside [0, 0.5),
  /// density <= 0, negative damping or a non-finite value. `*this` is left untouched.
  [[nodiscard]] ObjectModel with_params(const MaterialParams& params) const;

  /// A new revision without any leaf, for an object cut away entirely: the root, material, parameters, handles and
  /// max level are kept, and the model is empty as a default-constructed one is (no elements, no DOFs).
  [[nodiscard]] ObjectModel emptied() const;

  [[nodiscard]] const Octree& tree() const { return m_tree; }
  [[nodiscard]] const RootGeometry& root() const { return m_root; }
  [[nodiscard]] const DofMap& dofs() const { return m_dofs; }
  [[nodiscard]] const MaterialSource& material() const { return *m_material; }
  /// material() as the material graph M (SPEC §2.2) when it is one (a mesh object), else null (an exact box
  /// material). The model is M's one owner: the cut pipeline and the reports read M here.
  [[nodiscard]] const MaterialGraph* material_graph() const {
    return dynamic_cast<const MaterialGraph*>(m_material.get());
  }
  [[nodiscard]] const MaterialParams& params() const { return m_params; }
  [[nodiscard]] const std::vector<HandleSpec>& handles() const { return m_handles; }
  [[nodiscard]] int max_level() const { return m_max_level; }
  [[nodiscard]] int revision() const { return m_revision; }
  [[nodiscard]] int num_elements() const { return m_tree.size(); }  ///< 0 for an empty model
  [[nodiscard]] int num_dofs() const { return m_dofs.num_dofs; }

  [[nodiscard]] const std::vector<double>& occupancy() const { return m_occupancy; }  ///< (num_elements), [0,1]
  [[nodiscard]] const std::vector<double>& edge() const { return m_edge; }            ///< (num_elements), m
  [[nodiscard]] const std::vector<double>& dof_mass() const { return m_dof_mass; }    ///< lumped, kg (num_dofs)
  /// Handle index that drives each DOF, or -1 for a free DOF (num_dofs).
  [[nodiscard]] const std::vector<int>& dof_handle() const { return m_dof_handle; }
  /// Where a handle puts DOF `dof` at time t (s); its rest position when no handle drives it, m.
  [[nodiscard]] Vec3 handle_position(int dof, double t) const;
  /// Rest positions of every slot, m (8 * num_elements).
  [[nodiscard]] const std::vector<Vec3>& slot_rest() const { return m_slot_rest; }
  /// Unit-cube stiffness for this material's Poisson ratio (E = 1, h = 1).
  [[nodiscard]] const Mat24& unit_stiffness() const { return m_unit_k; }
  /// Stiffness scale E * occupancy * h of each element, N/m (num_elements).
  [[nodiscard]] const std::vector<double>& stiffness_scale() const { return m_k_scale; }
  /// Total material volume, m^3.
  [[nodiscard]] double volume() const;

  /// Binds a rest-space point to the leaf that contains it (on a shared boundary: the first leaf found). Nullopt
  /// when no leaf holds the point.
  [[nodiscard]] std::optional<PointEmbedding> embed(const Vec3& rest) const;
  /// Evaluates an embedded point from slot values (8 * num_elements).
  [[nodiscard]] Vec3 evaluate(const PointEmbedding& e, const std::vector<Vec3>& slots) const;

 private:
  // A leaf together with the material fraction it holds.
  struct OccupiedCell {
    Cell cell;
    double occupancy = 0.0;  // [0, 1]
  };
  // An empty model that carries this one's root, parameters, handles and unit stiffness, with the given material
  // and the next revision number.
  [[nodiscard]] ObjectModel next_revision(std::shared_ptr<const MaterialSource> material) const;
  // refined_where and refined_with_material: `material` null keeps this model's material.
  [[nodiscard]] ObjectModel refine_impl(const std::function<bool(const Cell&)>& split,
                                        std::shared_ptr<const MaterialSource> material,
                                        const std::vector<Box3>& changed, int* refined) const;
  // Sets the tree and the occupancy (sorted into Morton order together).
  void set_leaves(std::vector<OccupiedCell> cells);
  // Derived data of the leaves: geometry, stiffness scale, DOFs, masses and handles. With a previous revision the
  // DOF map is updated locally: around added and removed leaves, and at the cells in `material_changed`.
  void finish(const ObjectModel* previous, const std::vector<Cell>& material_changed);

  RootGeometry m_root;
  std::shared_ptr<const MaterialSource> m_material;
  MaterialParams m_params;
  std::vector<HandleSpec> m_handles;
  int m_max_level = 8;
  int m_revision = 0;
  Octree m_tree;
  DofMap m_dofs;
  Mat24 m_unit_k;
  std::vector<double> m_occupancy;   ///< (num_elements)
  std::vector<double> m_edge;        ///< (num_elements), m
  std::vector<double> m_k_scale;     ///< (num_elements), N/m
  std::vector<double> m_dof_mass;    ///< (num_dofs), kg
  std::vector<int> m_dof_handle;     ///< (num_dofs)
  std::vector<Vec3> m_slot_rest;     ///< (8 * num_elements), m
};

/// Connected components of the elements: two elements are connected when their rows of P share a DOF (directly,
/// or through a hard-bound slot). Returns comp (num_elements), comp[e] in [0, count), with components numbered in
/// the order of their smallest element index.
std::vector<int> element_components(const ObjectModel& model, int& count);

/// The same connectivity among the given elements only: element i of the result stands for elements[i], and two are
/// united when their rows of P share a DOF. The root of each set is its smallest index. Linear in their entries of P.
DisjointSets element_groups(const ObjectModel& model, const std::vector<int>& elements);

/// What one connected component of the elements holds.
struct ComponentInfo {
  double volume = 0.0;    ///< material volume, sum of occupancy * h^3 over its elements, m^3
  bool anchored = false;  ///< some DOF of its elements is driven by a handle
  int elements = 0;       ///< number of elements
};

/// Volume, anchoring and size of each component `comp` (num_elements) numbers in [0, count), as from
/// element_components. Returns (count).
std::vector<ComponentInfo> component_info(const ObjectModel& model, const std::vector<int>& comp, int count);

/// What changes from step to step (MuJoCo's mjData in spirit).
struct SimState {
  double t = 0.0;                  ///< simulated time, s
  std::vector<Vec3> x;             ///< DOF positions, m (num_dofs)
  std::vector<Vec3> v;             ///< DOF velocities, m/s (num_dofs)

  /// The rest state of a model: x = rest positions, v = 0.
  static SimState rest(const ObjectModel& model);
};

/// Carries a state over to a new revision of the model (refined, with_material, without_leaves, or a chain of
/// them): each new DOF takes the deformed position and velocity that the old model interpolates at its node inside
/// the old leaf that equals or contains the leaf of the DOF's own slot (DofMap::dof_slot). That leaf lies on the
/// DOF's side of every cut, so a DOF that a node split creates inherits the state of its parent (the old DOF, or
/// the old hard-bound slot value, of that leaf at that node) and never an average across the cut; refinement
/// never makes the object jump; and with the same leaves (with_material) every slot keeps its old position.
/// A new leaf that no old leaf contains (only a coarsening would make one) falls back to any old leaf at the node.
SimState transfer_state(const ObjectModel& from, const SimState& state, const ObjectModel& to);

/// The linear map transfer_state applies to positions, as a matrix: row d of `to`'s DOFs holds the weights of
/// `from`'s DOFs that DOF d interpolates (to.num_dofs() x from.num_dofs(), each row summing to 1; empty rows for the
/// DOFs transfer_state puts at rest). x_to = T x_from per coordinate, for positions expressed as DOF values.
SpMat transfer_matrix(const ObjectModel& from, const ObjectModel& to);

}  // namespace octocut::sim
