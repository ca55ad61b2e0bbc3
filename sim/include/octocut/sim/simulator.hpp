#pragma once
// Corotational FEM, the linearised implicit Euler step, the static Newton solve, and the step guards (SPEC §3).
#include <memory>
#include <string>
#include <vector>

#include "octocut/sim/linear_solver.hpp"
#include "octocut/sim/object.hpp"

namespace octocut::sim {

class Executor;

struct SimulatorOptions {
  bool dynamic = true;                         ///< false: static equilibrium solves
  double dt = 1e-3;                            ///< s
  Vec3 gravity = Vec3(0.0, 0.0, -9.81);        ///< m/s^2
  std::string linear_solver = "pcg";           ///< "cholmod" | "pcg"
  std::string preconditioner = "cholesky";     ///< pcg only: "cholesky" | "jacobi"
  double tolerance = 1e-6;                     ///< relative residual of linear solves and of the static Newton
  int max_iterations = 200;                    ///< pcg iterations per solve; Newton iterations per static solve
  int threads = 0;                             ///< 0 = hardware concurrency
  double max_speed = 100.0;                    ///< m/s; a faster DOF makes the step fail and roll back
  int max_halvings = 4;                        ///< retries with half the step before giving up on a step
};

/// Counters of numerical trouble and recovery, reported in report.json `stability`.
struct StabilityStats {
  int recoveries = 0;        ///< steps that failed once and were retried with a halved dt
  int failed_steps = 0;      ///< steps that failed even at the smallest dt: velocities reset, positions kept
  int nonfinite = 0;         ///< attempts rejected for NaN/Inf
  int speed_limit = 0;       ///< attempts rejected for exceeding max_speed
  int solver_failures = 0;   ///< attempts rejected because the linear solve did not converge or A was not SPD
  int newton_unconverged = 0;  ///< static solves that stopped at max_iterations
  double max_speed = 0.0;    ///< largest DOF speed seen, m/s
};

/// Where the time of the last step went, ms (dynamic steps).
struct StepProfile {
  double rotations = 0.0;  ///< polar decompositions
  double forces = 0.0;     ///< elastic force and K v
  double assembly = 0.0;   ///< rotated element stiffness and scatter into the system matrix
  double solve = 0.0;      ///< linear solve (factorisation or pcg)
};

/// Per-element corotational data at one configuration.
struct ElementFrame {
  std::vector<Mat3> rotation;  ///< R of each element (num_elements)
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
  /// The fixed sparsity pattern of the system matrix for the constrained flags (num_dofs), values zero; built once
  /// per flags and kept.
  const SpMat& system_pattern(const std::vector<char>& constrained);
  /// Points the system at `model`, which must be the model it was built for, moved to another address, and runs its
  /// element loops on `executor` from now on.
  void rebind(const ObjectModel& model, Executor& executor);
  /// Like elastic_force, and also the product K v of the corotated stiffness with v (both 3 num_dofs).
  void force_and_product(const std::vector<Vec3>& x, const ElementFrame& frame, const VecX& v, VecX& f,
                         VecX& kv) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

/// A model revision made ready off to the side by Simulator::prepare_model: the state carried over, the FEM system,
/// and optionally the system pattern with the linear solver's symbolic analysis. Move-only.
class PreparedModel {
 public:
  PreparedModel();
  PreparedModel(PreparedModel&&) noexcept;
  PreparedModel& operator=(PreparedModel&&) noexcept;
  ~PreparedModel();
  /// The prepared revision. Throws std::logic_error when empty (default-constructed or moved from).
  [[nodiscard]] const ObjectModel& model() const;

 private:
  friend class Simulator;
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

/// Runs one object: owns its model, state, solver and counters.
class Simulator {
 public:
  Simulator(ObjectModel model, const SimulatorOptions& options);
  ~Simulator();
  Simulator(const Simulator&) = delete;
  Simulator& operator=(const Simulator&) = delete;

  /// Advances by options.dt: an implicit Euler step (dynamic) or a static solve at the handles' pose at t + dt. A
  /// failed attempt is rolled back and retried with halved steps; the call itself never fails.
  void step();
  /// Solves for static equilibrium with the handles posed at time t. Returns true when converged.
  bool solve_static(double t);

  /// Replaces the model (a new revision) and carries the state over.
  void set_model(ObjectModel model);
  /// Builds the system matrix pattern of the current revision and runs the linear solver's symbolic analysis now,
  /// instead of in the next step (a cut calls it, so that its cost is counted where the topology changed).
  void refresh_solver();
  /// Builds what set_model followed by refresh_solver (when `analyze`) would, without changing the simulator: the
  /// state carried over from the current one, the FEM system of `model`, and the symbolic analysis of its system
  /// pattern in a new linear solver. Const and touching no shared state but the executor, so a cut can run it on
  /// another thread while the simulator is not stepped (and nothing else uses the executor). A failed analysis is
  /// left to the next step, as in refresh_solver's callers.
  [[nodiscard]] PreparedModel prepare_model(ObjectModel model, bool analyze) const;
  /// Switches to a prepared revision: afterwards the simulator is as set_model + refresh_solver would have left it.
  /// The state to carry over was taken when it was prepared: nothing may have stepped the simulator since.
  void adopt(PreparedModel prepared);
  /// Replaces the state (same revision).
  void set_state(SimState state);

  [[nodiscard]] const ObjectModel& model() const { return m_model; }
  [[nodiscard]] const SimState& state() const { return m_state; }
  [[nodiscard]] const StabilityStats& stats() const { return m_stats; }
  [[nodiscard]] const SimulatorOptions& options() const { return m_options; }
  [[nodiscard]] FemSystem& fem() { return *m_fem; }

  /// Kinetic energy 1/2 v^T M v, J.
  [[nodiscard]] double kinetic_energy() const;
  /// Elastic energy at the current state, J.
  [[nodiscard]] double elastic_energy() const;
  /// Current deformed position of an embedded rest point, m.
  [[nodiscard]] Vec3 position(const PointEmbedding& e) const;
  /// Largest DOF speed in the current state, m/s.
  [[nodiscard]] double max_speed() const;
  /// Total iterations of the last linear solve (pcg) and whether it refactorised.
  [[nodiscard]] const SolveInfo& last_solve() const { return m_last_solve; }
  /// Time spent in the parts of the last dynamic step attempt.
  [[nodiscard]] const StepProfile& profile() const { return m_profile; }

 private:
  bool try_dynamic_step(double dt);
  void rebuild();
  [[nodiscard]] std::unique_ptr<LinearSolver> make_solver() const;

  ObjectModel m_model;
  SimulatorOptions m_options;
  SimState m_state;
  StabilityStats m_stats;
  SolveInfo m_last_solve;
  StepProfile m_profile;
  std::unique_ptr<Executor> m_executor;
  std::unique_ptr<FemSystem> m_fem;
  std::unique_ptr<LinearSolver> m_solver;
  std::vector<char> m_constrained;   ///< 1 for DOFs driven by a handle (num_dofs)
  SpMat m_A;                         ///< system matrix with the fixed pattern of this revision
  bool m_pattern_analyzed = false;
  VecX m_dv_prev;                    ///< last step's velocity increment, warm start (3 num_dofs)
};

}  // namespace octocut::sim
