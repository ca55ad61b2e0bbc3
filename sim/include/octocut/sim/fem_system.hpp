#pragma once
// The corotational hex FEM of one model revision (SPEC §3): element rotations, elastic forces and energy, and the
// corotated stiffness gathered through the DOF map P, assembled into the implicit Euler system matrix.
#include <memory>
#include <vector>

#include "octocut/sim/object.hpp"

namespace octocut::sim {

class Executor;

/// Per-element corotational data at one configuration.
struct ElementFrame {
  std::vector<Mat3> rotation;  ///< R of each element (num_elements)
  /// det F at each element's centre: deformed over rest volume there, dimensionless (num_elements). Near 0: the
  /// element is crushed flat; negative: inverted.
  std::vector<double> volume_ratio;
};

/// The FEM assembly for one model revision: forces and the corotated stiffness gathered through P.
class FemSystem {
 public:
  FemSystem(const ObjectModel& model, Executor& executor);
  ~FemSystem();

  /// Slot positions P x from DOF positions, m.
  void prolong(const std::vector<Vec3>& dofs, std::vector<Vec3>& slots) const;
  /// Element rotations at the configuration x (num_dofs).
  void rotations(const std::vector<Vec3>& x, ElementFrame& frame) const;
  /// Each DOF's rotation at `frame` (num_dofs): its elements' rotations summed with the weights of P (|w|: a hanging
  /// corner's share) and orthonormalised. What the lagged factor is warped by (LinearSolver::set_dof_rotations).
  [[nodiscard]] std::vector<Mat3> dof_rotations(const ElementFrame& frame) const;
  /// Elastic restoring force P^T f_e (3 num_dofs), N, with rotations taken from `frame`.
  void elastic_force(const std::vector<Vec3>& x, const ElementFrame& frame, VecX& f) const;
  /// Elastic energy 1/2 sum (R^T x - X)^T K (R^T x - X), J.
  double elastic_energy(const std::vector<Vec3>& x, const ElementFrame& frame) const;
  /// Corotated stiffness P^T R K R^T P (3 num_dofs square, both triangles), N/m.
  SpMat stiffness(const ElementFrame& frame) const;
  /// K v for the corotated stiffness, without assembling it (3 num_dofs).
  void stiffness_product(const ElementFrame& frame, const VecX& v, VecX& out) const;

  /// Assembles A = m M + k K with the rows and columns of constrained DOFs (per node, num_dofs) replaced by
  /// identity, into `A` (its pattern is built on first use and then kept), and returns in `coupling` the product
  /// A_fc u_c of the unconstrained rows with the prescribed values u (only entries of constrained DOFs are read).
  void assemble_system(double m, double k, const ElementFrame& frame, const std::vector<char>& constrained,
                       const VecX& u, SpMat& A, VecX& coupling);
  /// y = A x for the A assemble_system(m, k, frame, constrained, ...) would assemble, without assembling it: the
  /// element matrices applied one by one (3 num_dofs). Each entry sums its elements in ascending order, as the
  /// assembly does, on the executor's threads (bit-identical whatever their count).
  void system_product(double m, double k, const ElementFrame& frame, const std::vector<char>& constrained,
                      const VecX& x, VecX& y);
  /// The coupling assemble_system returns (A_fc u_c: the unconstrained rows against the prescribed values u, of
  /// which only the constrained DOFs' entries are read), without assembling A (3 num_dofs).
  void system_coupling(double k, const ElementFrame& frame, const std::vector<char>& constrained, const VecX& u,
                       VecX& coupling) const;
  /// The columns of the DOFs `dofs` (ascending) of the A assemble_system(m, k, frame, constrained, ...) would
  /// assemble, with A's pattern in those columns (3 num_dofs x 3 |dofs|; columns 3 i + c are column c of dofs[i]):
  /// computed from the elements around those DOFs alone, without assembling the rest of A.
  SpMat system_columns(double m, double k, const ElementFrame& frame, const std::vector<char>& constrained,
                       const std::vector<int>& dofs);
  /// The fixed sparsity pattern of the system matrix for the constrained flags (num_dofs), values zero; built once
  /// per flags and kept.
  const SpMat& system_pattern(const std::vector<char>& constrained);
  /// Points the system at `model`, which must be the model it was built for, moved to another address, and runs its
  /// element loops on `executor` from now on.
  void rebind(const ObjectModel& model, Executor& executor);

  /// The storage of the system's pattern and its assembly plan (values meaningless), handed from a system that is
  /// done with it to a new one, which fills it instead of fresh allocations: a cut's new revision then writes its
  /// pattern into memory the process already touched (on the 50k meniscus 5-9 MB whose page faults cost 2-4 ms of
  /// the cut's model thread). Move-only.
  struct Storage {
    SpMat pattern;
    std::vector<int> pair_offsets, diag_offsets;
    std::vector<std::size_t> pair_begin;

    Storage() = default;
    // Moves swap: Eigen's SparseMatrix has no move assignment, so a defaulted one would copy the pattern.
    Storage(Storage&& other) noexcept { swap(other); }
    Storage& operator=(Storage&& other) noexcept {
      swap(other);
      return *this;
    }
    Storage(const Storage&) = delete;
    Storage& operator=(const Storage&) = delete;
    void swap(Storage& other) noexcept {
      pattern.swap(other.pattern);
      pair_offsets.swap(other.pair_offsets);
      diag_offsets.swap(other.diag_offsets);
      pair_begin.swap(other.pair_begin);
    }
  };
  /// Gives up this system's storage: it must not be used again but to destroy it.
  [[nodiscard]] Storage release_storage();
  /// Takes storage to build the pattern in (before it is built; system_pattern and the first assembly build it).
  void reuse_storage(Storage&& storage);
  /// Like elastic_force, and also the product K v of the corotated stiffness with v (both 3 num_dofs); with
  /// `energy`, also the elastic energy at x (J, as elastic_energy gives it, summed in element order).
  void force_and_product(const std::vector<Vec3>& x, const ElementFrame& frame, const VecX& v, VecX& f, VecX& kv,
                         double* energy = nullptr) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

}  // namespace octocut::sim
