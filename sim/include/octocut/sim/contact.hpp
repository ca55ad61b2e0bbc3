#pragma once
// Tissue-side contact (SPEC §3 "Contact", issue 16): collision samples on S mapped to DOFs, and the abstract contact
// term that the implicit Euler step takes. No rigid-body library appears here: the engine finds the contacts (with
// Bullet) and hands them over as plain data; the simulator puts their penalty stiffness and damping into the system
// matrix, so that stiff contact is stable at the scene's dt, and returns the force each one exerted.
#include <vector>

#include "octocut/sim/object.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::sim {

class SurfaceEmbedding;

/// One DOF of a sample's row: the sample's position is the sum of weight * x[dof] over its row.
struct ContactDof {
  int dof = 0;
  double weight = 0.0;  ///< dimensionless
};

/// The collision samples of S for one model revision and one S: S's vertices, plus points on every face larger than
/// the contact resolution (so that the 12 triangles of a box primitive still collide in the middle of a face). Each
/// sample carries the area of S it stands for, so that a penalty pressure integrates to the same force whatever the
/// sampling.
struct ContactSamples {
  std::vector<Vec3> rest;            ///< rest positions, m (n)
  std::vector<double> area;          ///< area of S each sample stands for, m^2 (n); sums to S's area
  std::vector<int> begin;            ///< CSR over samples (n + 1)
  std::vector<ContactDof> dofs;      ///< rows: sample i is sum over [begin[i], begin[i+1]) (nnz)
  std::vector<int> face;             ///< the face a face point lies on, -1 for a vertex sample (n)
  [[nodiscard]] int size() const { return int(rest.size()); }
  /// Deformed position of sample i from DOF positions (num_dofs), m. Inline: the contact queries take every
  /// sample's position at every step.
  [[nodiscard]] Vec3 position(int i, const std::vector<Vec3>& x) const {
    Vec3 p = Vec3::Zero();
    for (int k = begin[std::size_t(i)]; k < begin[std::size_t(i) + 1]; ++k)
      p += dofs[std::size_t(k)].weight * x[std::size_t(dofs[std::size_t(k)].dof)];
    return p;
  }
  /// Velocity of sample i from DOF velocities (num_dofs), m/s.
  [[nodiscard]] Vec3 velocity(int i, const std::vector<Vec3>& v) const { return position(i, v); }
};

/// Builds the samples of `surface` (rest S, m) bound to `model` through `embedding` (S's composed DOF rows). A face
/// whose longest edge exceeds `resolution` (m) gets a barycentric grid of ceil(edge / resolution) divisions; its
/// area is lumped onto the grid points (corners: the vertex samples). Face points are embedded in the leaf that
/// holds them (model.embed), or, outside every leaf, as the barycentric blend of the corners' rows.
ContactSamples build_contact_samples(const ObjectModel& model, const TriMesh& surface,
                                     const SurfaceEmbedding& embedding, double resolution);

/// Below this tangential speed (m/s) a contact holds by static friction: Coulomb friction is regularised there as
/// an implicit viscous stick of coefficient friction * normal force / kStickSpeed, so a contact loaded inside the
/// friction cone creeps at most at this speed, and one loaded beyond it slides.
inline constexpr double kStickSpeed = 1e-4;

/// One active contact of a sample with a rigid shape, for one step. The penalty acts along `normal`; its stiffness
/// and damping enter the implicit system (the system matrix gets dt^2 K_c + dt C_c through the sample's row), so the
/// force is the one at the end of the step. Friction is Coulomb's, friction * k * penetration against the relative
/// tangential motion, put into the implicit system as a viscous force whose coefficient is that force over the
/// speed at the start of the step (at least kStickSpeed): a contact slower than kStickSpeed sticks.
struct Contact {
  std::vector<ContactDof> dofs;        ///< the sample's row (DOF weights)
  Vec3 normal = Vec3::UnitZ();         ///< unit, from the rigid shape into the tissue
  double penetration = 0.0;            ///< m, > 0, at the start of the step
  double stiffness = 0.0;              ///< N/m, normal penalty
  double damping = 0.0;                ///< N s/m, normal
  double friction = 0.0;               ///< Coulomb coefficient (static = sliding)
  Vec3 rigid_velocity = Vec3::Zero();  ///< velocity of the rigid surface point, m/s
};

/// What a contact did in the step that used it.
struct ContactOutcome {
  Vec3 force = Vec3::Zero();  ///< force on the tissue at the end of the step, N (the rigid body gets -force)
  double penetration = 0.0;   ///< m, at the end of the step (linearised); negative: separated
  bool sliding = false;       ///< it slid (else it stuck)
};

/// One 3 x 3 block of a system matrix: the rows of DOF `row` against the columns of DOF `col`.
struct SystemBlock {
  int row = 0;
  int col = 0;
  Mat3 value = Mat3::Zero();
};

/// The contact terms of the implicit Euler system of one attempt of length dt: A += dt^2 K_c + dt C_c through each
/// sample's row, appended to `blocks` as they enter A (blocks outside A's pattern `pattern` are lumped onto the two
/// diagonals, which keeps A symmetric positive definite), and rhs += dt (f_0 - (dt K_c + C_c)(v_sample - v_rigid)).
/// The blocks of contacts with the same list of DOFs (samples embedded in the same element) are summed per pair, in
/// the order of each list's first contact; rhs receives every contact's terms in the contacts' order.
/// Rows and columns of constrained DOFs are left alone (their coupling moves to rhs with the prescribed increments
/// dv_c). `pattern` is the system matrix's pattern (3 num_dofs square, both triangles), v the DOF velocities
/// (num_dofs).
void contact_system_terms(const std::vector<Contact>& contacts, double dt, const std::vector<Vec3>& v,
                          const std::vector<char>& constrained, const VecX& dv_c, const SpMat& pattern,
                          std::vector<SystemBlock>& blocks, VecX& rhs);
/// A += the blocks, each inside A's pattern (as contact_system_terms gives them for that pattern); blocks outside it
/// are left out. With `column_of` (per DOF: the column block of A that holds its columns, or -1), A holds only some
/// DOFs' columns (SystemOperator::columns) and a block goes to the columns of column_of[col], if any. Each entry
/// receives its blocks in the list's order.
void add_system_blocks(const std::vector<SystemBlock>& blocks, SpMat& A, const std::vector<int>* column_of = nullptr);
/// y += the blocks times x, in the blocks' order (3 num_dofs).
void add_block_products(const std::vector<SystemBlock>& blocks, const VecX& x, VecX& y);

/// The force of each contact at the end of an attempt that started at DOF velocities v (num_dofs) and took the
/// velocity increments dv (3 num_dofs).
std::vector<ContactOutcome> contact_outcomes(const std::vector<Contact>& contacts, double dt,
                                             const std::vector<Vec3>& v, const VecX& dv);

}  // namespace octocut::sim
