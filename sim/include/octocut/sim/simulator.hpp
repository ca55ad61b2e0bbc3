#pragma once
// The linearised implicit Euler step, the static Newton solve, and the step guards (SPEC §3), over the FEM system of
// fem_system.hpp.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "octocut/sim/contact.hpp"
#include "octocut/sim/fem_system.hpp"
#include "octocut/sim/linear_solver.hpp"
#include "octocut/sim/object.hpp"

namespace octocut::sim {

class Executor;
class FemSystem;
struct ElementFrame;

struct SimulatorOptions {
  bool dynamic = true;                         ///< false: static equilibrium solves
  double dt = 1e-3;                            ///< s
  Vec3 gravity = Vec3(0.0, 0.0, -9.81);        ///< m/s^2
  std::string linear_solver = "pcg";           ///< "cholmod" | "pcg"
  std::string preconditioner = "cholesky";     ///< pcg only: "cholesky" | "jacobi"
  double tolerance = 1e-6;                     ///< relative residual of linear solves and of the static Newton
  int max_iterations = 200;                    ///< pcg iterations per solve; Newton iterations per static solve
  int threads = 0;                             ///< 0 = hardware concurrency
  int factor_lag = 0;  ///< pcg: solves a background refresh of the lagged factor may take; 0 = refresh inline
  double max_speed = 100.0;                    ///< m/s; a faster DOF makes the step fail and roll back
  int max_halvings = 4;                        ///< retries with half the step before giving up on a step
  /// Energy guard, relative: an attempt in which no handle moves and whose kinetic + elastic energy rises by more than
  /// the work of gravity and the rigid shapes (less what the contact penalty springs take up), plus energy_guard times
  /// the largest of these energies, is rolled back and retried as two halves, except at the smallest dt. A gain below
  /// 1e-7 of that scale and of the largest kinetic + elastic energy since the last set_state is noise. An attempt
  /// it accepts that still gains energy beyond that has the gain taken out of its kinetic energy (the
  /// free DOFs' velocities scaled down), after shortening the step where the gain is beyond the tolerance (at the
  /// smallest dt) and the kinetic energy (StabilityStats::energy_projections). 0 turns both off.
  double energy_guard = 1e-3;
};

/// Counters of numerical trouble and recovery, reported in report.json `stability`.
struct StabilityStats {
  int recoveries = 0;        ///< steps that failed once and were retried with a halved dt
  int failed_steps = 0;      ///< steps that failed even at the smallest dt: velocities reset, positions kept
  int nonfinite = 0;         ///< attempts rejected for NaN/Inf
  int speed_limit = 0;       ///< attempts rejected for exceeding max_speed
  int solver_failures = 0;   ///< attempts rejected because the linear solve did not converge or A was not SPD
  int energy_rejections = 0;  ///< attempts rejected because the energy rose without work put in
  /// Accepted attempts whose energy gain (without work put in) was taken out of them, and the gains so removed, J;
  /// energy_unremoved_j is what was left: gains within the guard's tolerance beyond the kinetic energy (the corotated
  /// force is not quite the energy's gradient), and what a shortened attempt could not remove (moving contacts).
  int energy_projections = 0;
  int energy_shortened = 0;  ///< of those, attempts shortened first (a gain beyond the tolerance and the kinetic energy)
  double energy_removed_j = 0.0;
  double energy_unremoved_j = 0.0;
  int newton_unconverged = 0;  ///< static solves that stopped at max_iterations
  double max_speed = 0.0;    ///< largest DOF speed seen, m/s
  /// Smallest element volume ratio (det F at an element's centre, deformed over rest) at the start of a dynamic
  /// step or at the end of a static solve, dimensionless: near 0, an element crushed flat; negative, inverted.
  double min_volume_ratio = 1.0;
};

/// Where the time of the last step went, ms (dynamic steps).
struct StepProfile {
  double rotations = 0.0;  ///< polar decompositions
  double forces = 0.0;     ///< elastic force and K v
  double assembly = 0.0;   ///< rotated element stiffness and scatter into the system matrix
  double solve = 0.0;      ///< linear solve (factorisation or pcg)
  double contact = 0.0;    ///< contact terms added to the system and their forces afterwards (part of assembly)
};

/// The energy balance of the contacts over the last dynamic step (all its parts when it was split), for the check
/// that the tissue's energy never rises by more than the work put in (output.stability_track). Implicit Euler with
/// the contact force F at the end of a step obeys, per contact, F . (v_sample - v_rigid) dt <= -(V_end - V_start)
/// (the penalty potential V = k d~^2 / 2, d~ the penetration the step's linearised force acts on; damping and
/// friction only take energy out), so dE_tissue + penalty_change <= work: what moving rigid shapes put in.
struct ContactEnergy {
  double work_j = 0.0;            ///< sum over contacts and parts of F . v_rigid dt: work the rigid shapes did, J
  double penalty_change_j = 0.0;  ///< sum of V_end - V_start of the penalty springs over the parts, J
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
  /// Wall time spent preparing the first step's bridge solve (Simulator::prepare_model with spare time), ms; 0 when
  /// it was not prepared. That is work of the step after the cut, done ahead of it. Throws like model().
  [[nodiscard]] double bridge_ms() const;

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
  /// failed attempt is rolled back and retried with halved steps; the call itself never fails. With no object
  /// (empty()) only the time advances.
  void step();
  /// Solves for static equilibrium with the handles posed at time t. Returns true when converged (always when
  /// empty()).
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
  /// left to the next step, as in refresh_solver's callers. When `spare_time` is given and returns true once the
  /// analysis is done (the caller's other thread is still busy), it also does work of the first step after the
  /// switch (pcg with factor_lag: LinearSolver::prepare_bridge, at dt and the state carried over); whether it does
  /// changes no result, only when that work is done.
  [[nodiscard]] PreparedModel prepare_model(ObjectModel model, bool analyze,
                                            const std::function<bool()>& spare_time = {}) const;
  /// Switches to a prepared revision: afterwards the simulator is as set_model + refresh_solver would have left it.
  /// The state to carry over was taken when it was prepared: nothing may have stepped the simulator since.
  void adopt(PreparedModel prepared);
  /// The contacts the next step() uses (dynamic mode; a static solve ignores them), found by the caller at the
  /// current state. They act through the whole step; when the step is split after a failure, each part starts from
  /// the penetration and friction state the part before left. DOF indices refer to the current revision.
  void set_contacts(std::vector<Contact> contacts) { m_contacts = std::move(contacts); }
  /// What each contact of the last step did (same order as set_contacts; empty after a step that failed at the
  /// smallest dt, or without contacts).
  [[nodiscard]] const std::vector<ContactOutcome>& contact_outcomes() const { return m_outcomes; }
  /// The contacts' work and penalty energy change over the last step (zero without contacts, and after a step that
  /// failed at the smallest dt).
  [[nodiscard]] const ContactEnergy& contact_energy() const { return m_contact_energy; }

  /// Replaces the state (same revision).
  void set_state(SimState state);
  /// Drops the object, for a cut that removed every element: afterwards empty() holds, model() is the current
  /// model's emptied() revision (no elements, DOFs or leaves), the state keeps its time t and has no DOFs, and the
  /// solver holds nothing. A later step() only advances t by options.dt; set_model or adopt bring an object back.
  void remove_object();
  /// True when there is no object to simulate: the model has no elements (after remove_object, or built empty).
  [[nodiscard]] bool empty() const { return m_model.num_elements() == 0; }

  [[nodiscard]] const ObjectModel& model() const { return m_model; }
  /// The thread arena of the element loops (`threads` of the options). Other work may use it between steps, as a
  /// cut does for its surface embedding update.
  [[nodiscard]] Executor& executor() const { return *m_executor; }
  [[nodiscard]] const SimState& state() const { return m_state; }
  [[nodiscard]] const StabilityStats& stats() const { return m_stats; }
  [[nodiscard]] const SimulatorOptions& options() const { return m_options; }

  /// Kinetic energy 1/2 v^T M v, J (0 when empty()).
  [[nodiscard]] double kinetic_energy() const;
  /// Elastic energy at the current state, J (0 when empty()).
  [[nodiscard]] double elastic_energy() const;
  /// Current deformed position of an embedded rest point, m.
  [[nodiscard]] Vec3 position(const PointEmbedding& e) const;
  /// Largest DOF speed in the current state, m/s (0 when empty()).
  [[nodiscard]] double max_speed() const;
  /// Total iterations of the last linear solve (pcg) and whether it refactorised.
  [[nodiscard]] const SolveInfo& last_solve() const { return m_last_solve; }
  /// Time spent in the parts of the last dynamic step attempt.
  [[nodiscard]] const StepProfile& profile() const { return m_profile; }

 private:
  // One implicit Euler attempt of length dt; false (state untouched) when it fails a guard.
  // `may_reject`: the energy guard may reject the attempt (not at the smallest dt).
  bool try_dynamic_step(double dt, bool may_reject);
  // Whether the energy balance of an attempt with handle targets `target` can be checked (see energy_holds): no
  // handle moves and the start's energy is at hand.
  [[nodiscard]] bool energy_measurable(const std::vector<Vec3>& target) const;
  // The start's rotations, forces and energy where no earlier attempt computed them (see simulator.cpp).
  void ensure_start_energy();
  // The contacts' outcomes (m_outcomes) of an attempt of length dt from DOF velocities v0 (num_dofs) with increments
  // dv (3 num_dofs), the rigid shapes' work through them and the change of the penalty springs' energy, J.
  void contact_balance(double dt, const std::vector<Vec3>& v0, const VecX& dv, double& work, double& penalty);
  // The energy guard at the committed state. With `measured`, the balance against the start's energy e0 (J) and
  // positions x0 (num_dofs), with the rigid shapes' work and the penalty springs' change over the attempt (J): `gain`
  // is the energy gained beyond the work put in, J, and with `may_reject` a gain beyond the guard's tolerance fails
  // the attempt; `scale` is the largest of the energies compared, J. Keeps the new state's rotations, forces and
  // energy for the next step when it passes.
  bool energy_holds(bool measured, bool may_reject, double e0, const std::vector<Vec3>& x0, double work,
                    double penalty, double& gain, double& scale);
  // Takes an accepted attempt's energy gain (J, > 0) out of it (see simulator.cpp): from the free DOFs' kinetic
  // energy, after shortening the step when the gain is larger and `beyond` the guard's tolerance. dt, e0, x0 as for
  // energy_holds; v0 the start's velocities (num_dofs), dv the attempt's increments (3 num_dofs); work and penalty
  // follow a shortened step.
  void remove_energy_gain(double gain, bool beyond, double dt, double e0, const std::vector<Vec3>& x0,
                          const std::vector<Vec3>& v0, const VecX& dv, double& work, double& penalty);
  // Velocity increments (3 num_dofs) that take the handle DOFs to their pose at t + dt, held in `target` (num_dofs).
  [[nodiscard]] VecX prescribed_increments(double dt, std::vector<Vec3>& target) const;
  // Assembles and solves the implicit Euler system for the velocity increment dv (3 num_dofs).
  bool solve_increment(double dt, const VecX& dv_c, VecX& dv);
  // Checks the state that dv gives and commits it, advancing t by dt.
  bool commit_step(double dt, const VecX& dv, const std::vector<Vec3>& target);
  /// The free DOFs the current contacts' rows reach, ascending.
  [[nodiscard]] std::vector<int> contact_dofs() const;
  /// dv = the start of the solve of a step of dt (m/s, 3 num_dofs), from the last steps' increments.
  void warm_start(double dt, VecX& dv) const;
  void prepare_bridge(PreparedModel::Impl& p) const;
  // The defined reset after a step failed at the smallest dt, from the step's start state.
  void reset_failed_step(const SimState& start);
  // The linear solver's symbolic analysis of m_A, once per revision.
  void analyze_if_needed();
  // Static residual f_el(x) + f_ext with constrained rows zeroed (3 num_dofs), its norm returned; frame left at x.
  double static_residual(const std::vector<Vec3>& x, const VecX& f_ext, ElementFrame& frame, VecX& r) const;
  // Newton direction dx from the corotated tangent at `frame`; false when the solve fails.
  bool newton_direction(const ElementFrame& frame, const VecX& r, VecX& dx);
  // Damped step from x along dx (the natural monotonicity test on the factorised tangent): on a finite residual x, r
  // and frame move to the accepted point; a residual norm at most `done` (N) is accepted at once. Returns its norm.
  double line_search(std::vector<Vec3>& x, const VecX& dx, const VecX& f_ext, double done, ElementFrame& frame,
                     VecX& r);
  void rebuild();
  /// A solver for the current options; `initial`: for the model the simulator starts with (a thorough ordering,
  /// LinearSolverOptions::thorough_ordering), else for a revision a cut prepares.
  [[nodiscard]] std::unique_ptr<LinearSolver> make_solver(bool initial = true) const;

  ObjectModel m_model;
  SimulatorOptions m_options;
  SimState m_state;
  StabilityStats m_stats;
  SolveInfo m_last_solve;
  /// Counts the changes of m_state (each commit, rollback, reset, new model or state), so that what was computed from
  /// one state is reused only for that state.
  std::uint64_t m_state_version = 0;
  struct StepStart;  ///< what the energy guard computed at a state, for the step that starts from it (simulator.cpp)
  std::unique_ptr<StepStart> m_next_start;
  double m_energy = 0.0;  ///< J, kinetic + elastic energy of the state of version m_energy_version (energy guard)
  double m_energy_peak = 0.0;  ///< J, the largest of those since the last set_state: the guard's energy scale
  std::uint64_t m_energy_version = ~std::uint64_t(0);
  StepProfile m_profile;
  std::unique_ptr<Executor> m_executor;
  std::unique_ptr<FemSystem> m_fem;
  /// The storage of the revision before the current one's FEM system (FemSystem::release_storage), for the next
  /// revision's to reuse. Mutable: prepare_model takes it, on the cut's model thread, while nothing else runs.
  mutable FemSystem::Storage m_spare_storage;
  std::unique_ptr<LinearSolver> m_solver;
  std::vector<char> m_constrained;   ///< 1 for DOFs driven by a handle (num_dofs)
  SpMat m_A;                         ///< system matrix with the fixed pattern of this revision
  bool m_pattern_analyzed = false;
  VecX m_dv_prev;                    ///< last step's velocity increment, warm start (3 num_dofs)
  /// The increments of the two steps before the last (m/s, 3 num_dofs each) and how many of the last steps, up to
  /// 3, ran this revision at one Δt (m_history_dt, s) in a row: the warm start extrapolates along them.
  VecX m_dv_prev2, m_dv_prev3;
  int m_history = 0;
  double m_history_dt = 0.0;
  std::vector<Contact> m_contacts;   ///< contacts of the next (or current) step
  std::size_t m_contact_blocks = 0;  ///< system blocks of the last attempt's contacts (the next one reserves as many)
  std::vector<ContactOutcome> m_outcomes;  ///< what they did in the last step
  ContactEnergy m_contact_energy;          ///< their work and penalty energy change over the last step
};

}  // namespace octocut::sim
