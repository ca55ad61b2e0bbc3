#include "octocut/sim/simulator.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <stdexcept>

#include "octocut/sim/fem_system.hpp"
#include "octocut/sim/parallel.hpp"
#include "octocut/sim/timing.hpp"

namespace octocut::sim {

namespace {
// 1 for the DOFs a handle drives (num_dofs).
std::vector<char> constrained_flags(const ObjectModel& m) {
  std::vector<char> c(std::size_t(m.num_dofs()), 0);
  for (int d = 0; d < m.num_dofs(); ++d) c[std::size_t(d)] = m.dof_handle()[std::size_t(d)] >= 0;
  return c;
}

// The vectors (n) as one vector (3 n).
VecX flatten(const std::vector<Vec3>& v) {
  VecX out(3 * Eigen::Index(v.size()));
  for (std::size_t i = 0; i < v.size(); ++i) out.segment<3>(3 * Eigen::Index(i)) = v[i];
  return out;
}

// The norm of f (3 n) over the DOFs no handle drives (constrained: n flags).
double free_norm(const VecX& f, const std::vector<char>& constrained) {
  double sum = 0.0;
  for (std::size_t d = 0; d < constrained.size(); ++d)
    if (!constrained[d]) sum += f.segment<3>(3 * Eigen::Index(d)).squaredNorm();
  return std::sqrt(sum);
}

// The implicit Euler system of one attempt, A = m M + k K + the contact blocks (constrained rows and columns
// identity), as the solver's operator: its products apply the element matrices and the blocks directly
// (FemSystem::system_product), and it is assembled into `storage` only when the solver asks for its entries (to
// factorise it, or to solve the contacts' region exactly). A step whose solver needs neither skips the assembly.
class StepSystem final : public SystemOperator {
 public:
  /// The system of a step of dt (s) with Rayleigh damping C = alpha M + beta K: M + dt C + dt^2 K, so m = 1 + dt alpha
  /// and k = dt beta + dt^2 (the one place both the step and the bridge prepared for it take them from).
  StepSystem(FemSystem& fem, const ElementFrame& frame, double dt, const MaterialParams& params,
             const std::vector<char>& constrained, SpMat& storage)
      : m_fem(fem), m_frame(frame), m_m(1.0 + dt * params.rayleigh_mass),
        m_k(dt * params.rayleigh_stiffness + dt * dt), m_constrained(constrained), m_storage(storage),
        m_nonzeros(fem.system_pattern(constrained).nonZeros()) {}
  std::vector<SystemBlock> contact;  ///< the contacts' blocks (contact_system_terms)

  /// k, the stiffness's coefficient.
  [[nodiscard]] double stiffness_coefficient() const { return m_k; }
  [[nodiscard]] Eigen::Index rows() const override { return 3 * Eigen::Index(m_constrained.size()); }
  [[nodiscard]] Eigen::Index nonzeros() const override { return m_nonzeros; }
  void product(const VecX& x, VecX& y) override {
    m_fem.system_product(m_m, m_k, m_frame, m_constrained, x, y);
    add_block_products(contact, x, y);
  }
  const SpMat& matrix() override {
    if (!m_assembled) {
      assemble(m_storage);
      m_assembled = true;
    }
    return m_storage;
  }
  void assemble_into(SpMat& out) override {
    if (m_assembled)
      out = m_storage;
    else
      assemble(out);
  }
  const SpMat& pattern() override { return m_fem.system_pattern(m_constrained); }
  SpMat columns(const std::vector<int>& dofs) override {
    SpMat out = m_fem.system_columns(m_m, m_k, m_frame, m_constrained, dofs);
    std::vector<int> local(m_constrained.size(), -1);  // index of each DOF in `dofs`, or -1
    for (std::size_t i = 0; i < dofs.size(); ++i) local[std::size_t(dofs[i])] = int(i);
    add_system_blocks(contact, out, &local);  // the contact blocks in these columns
    return out;
  }

 private:
  void assemble(SpMat& out) {
    VecX coupling;  // the step took it from FemSystem::system_coupling
    m_fem.assemble_system(m_m, m_k, m_frame, m_constrained, VecX::Zero(rows()), out, coupling);
    add_system_blocks(contact, out);
  }

  FemSystem& m_fem;
  const ElementFrame& m_frame;
  double m_m, m_k;  // the mass's and the stiffness's coefficients
  const std::vector<char>& m_constrained;
  SpMat& m_storage;
  Eigen::Index m_nonzeros;
  bool m_assembled = false;
};

// Milliseconds since t0, and t0 moved on to now: the times of stages run one after another.
double lap(Clock::time_point& t0) {
  const double ms = ms_since(t0);
  t0 = Clock::now();
  return ms;
}
}  // namespace

// The state a step starts from as the energy guard left it (energy_holds): valid while m_state_version == version.
struct Simulator::StepStart {
  std::uint64_t version = 0;
  ElementFrame frame;  ///< the elements' rotations at x
  VecX f_el, kv;       ///< elastic force at x and K v (3 num_dofs)
};

Simulator::Simulator(ObjectModel model, const SimulatorOptions& options)
    : m_model(std::move(model)), m_options(options) {
  if (!(options.dt > 0.0)) throw std::invalid_argument("Simulator: dt must be positive");
  m_executor = std::make_unique<Executor>(options.threads);
  m_solver = make_solver();
  m_state = SimState::rest(m_model);
  ++m_state_version;
  rebuild();
}

Simulator::~Simulator() = default;

void Simulator::rebuild() {
  FemSystem::Storage storage = m_fem ? m_fem->release_storage() : std::move(m_spare_storage);
  m_fem = std::make_unique<FemSystem>(m_model, *m_executor);
  m_fem->reuse_storage(std::move(storage));
  m_constrained = constrained_flags(m_model);
  m_A = SpMat();
  m_pattern_analyzed = false;
  m_dv_prev = VecX::Zero(3 * m_model.num_dofs());
  m_history = 0;
}

void Simulator::set_model(ObjectModel model) {
  SimState s = transfer_state(m_model, m_state, model);
  m_model = std::move(model);
  m_state = std::move(s);
  ++m_state_version;
  rebuild();
}

void Simulator::refresh_solver() {
  if (m_model.num_dofs() == 0) return;
  // The pattern is all the symbolic analysis needs. m_A stays empty: the next step's assembly copies the pattern
  // into it with the values.
  m_solver->analyze_pattern(m_fem->system_pattern(m_constrained));
  m_pattern_analyzed = true;
}

std::unique_ptr<LinearSolver> Simulator::make_solver(bool initial) const {
  LinearSolverOptions lo;
  lo.thorough_ordering = initial;  // the model a run starts with keeps its pattern longest
  lo.tolerance = m_options.tolerance;
  lo.max_iterations = m_options.max_iterations;
  lo.preconditioner = m_options.preconditioner;
  lo.factor_lag_solves = m_options.factor_lag;
  std::unique_ptr<LinearSolver> solver = make_linear_solver(m_options.linear_solver, lo);
  solver->set_executor(m_executor.get());  // its solves run in the step, like the element loops
  return solver;
}

struct PreparedModel::Impl {
  // One thread for the element loops of the preparation: it runs beside the cut's surface stage, which keeps the
  // other core busy. adopt() hands the system the simulator's executor.
  std::unique_ptr<Executor> serial = std::make_unique<Executor>(1);
  std::unique_ptr<ObjectModel> model;  // on the heap: the FEM system points to it, and adopt() moves it
  SimState state;
  std::unique_ptr<FemSystem> fem;
  std::vector<char> constrained;       // 1 for DOFs driven by a handle (num_dofs)
  std::unique_ptr<LinearSolver> solver;
  bool analyzed = false;
  SpMat transfer;  // DOF values old revision -> this one (num_dofs x old num_dofs), for the solver's inherit()
  double bridge_ms = 0.0;  // wall time of prepare_bridge, ms; 0 when it did not run
};

PreparedModel::PreparedModel() = default;
PreparedModel::PreparedModel(PreparedModel&&) noexcept = default;
PreparedModel& PreparedModel::operator=(PreparedModel&&) noexcept = default;
PreparedModel::~PreparedModel() = default;
const ObjectModel& PreparedModel::model() const {
  if (!m_impl) throw std::logic_error("PreparedModel::model: empty");
  return *m_impl->model;
}
double PreparedModel::bridge_ms() const {
  if (!m_impl) throw std::logic_error("PreparedModel::bridge_ms: empty");
  return m_impl->bridge_ms;
}

PreparedModel Simulator::prepare_model(ObjectModel model, bool analyze, const std::function<bool()>& spare_time) const {
  PreparedModel out;
  out.m_impl = std::make_unique<PreparedModel::Impl>();
  PreparedModel::Impl& p = *out.m_impl;
  p.state = transfer_state(m_model, m_state, model);
  p.model = std::make_unique<ObjectModel>(std::move(model));
  p.fem = std::make_unique<FemSystem>(*p.model, *p.serial);
  p.fem->reuse_storage(std::move(m_spare_storage));
  p.constrained = constrained_flags(*p.model);
  p.solver = make_solver(false);
  if (analyze && p.model->num_dofs() > 0) {
    try {
      p.solver->analyze_pattern(p.fem->system_pattern(p.constrained));
      p.analyzed = true;
      if (m_options.factor_lag > 0 && m_options.linear_solver == "pcg") {
        p.transfer = transfer_matrix(m_model, *p.model);
        if (m_options.dynamic && spare_time && spare_time()) {
          const auto t0 = Clock::now();
          prepare_bridge(p);
          p.bridge_ms = ms_since(t0);
        }
      }
    } catch (const std::exception&) {
      // The next step analyses the pattern again, and its guards handle a solver failure.
    }
  }
  return out;
}

// The system of the first step after the cut (at dt, at the state carried over, without contacts) for the new
// solver's prepare_bridge, here on the cut's model thread: the first step then starts with the bridge's exact solve
// on the cut's region factorised (meniscus_punch_hd: 1.7 ms of that step's 6-7 ms).
void Simulator::prepare_bridge(PreparedModel::Impl& p) const {
  ElementFrame frame;
  p.fem->rotations(p.state.x, frame);
  SpMat storage;  // assembled only if the solver asks (it asks for columns)
  StepSystem system(*p.fem, frame, m_options.dt, p.model->params(), p.constrained, storage);
  p.solver->prepare_bridge(system, p.transfer);
}

void Simulator::adopt(PreparedModel prepared) {
  if (!prepared.m_impl) throw std::invalid_argument("Simulator::adopt: empty PreparedModel");
  PreparedModel::Impl& p = *prepared.m_impl;
  if (int(p.state.x.size()) != p.model->num_dofs())
    throw std::invalid_argument("Simulator::adopt: the prepared state does not match its model");
  VecX dv_prev = VecX::Zero(3 * p.model->num_dofs());  // the one allocation, before anything changes
  // Nothing below throws (moves), so the simulator is either unchanged or fully switched.
  m_model = std::move(*p.model);
  m_state = std::move(p.state);
  ++m_state_version;
  if (m_fem) m_spare_storage = m_fem->release_storage();  // for the next revision's pattern
  m_fem = std::move(p.fem);
  m_fem->rebind(m_model, *m_executor);
  m_constrained = std::move(p.constrained);
  if (p.analyzed && p.transfer.size() > 0 && m_solver) p.solver->inherit(*m_solver, p.transfer);
  m_solver = std::move(p.solver);
  m_A = SpMat();
  m_pattern_analyzed = p.analyzed;
  m_dv_prev = std::move(dv_prev);
  m_history = 0;
}

void Simulator::set_state(SimState state) {
  if (int(state.x.size()) != m_model.num_dofs() || state.v.size() != state.x.size())
    throw std::invalid_argument("Simulator::set_state: state does not match the model");
  m_state = std::move(state);
  ++m_state_version;
  m_history = 0;  // the increments no longer lead up to this state
  m_energy_peak = 0.0;
}

void Simulator::remove_object() {
  m_model = m_model.emptied();
  SimState none;  // no DOFs
  none.t = m_state.t;
  m_state = std::move(none);
  ++m_state_version;
  m_solver = make_solver();
  rebuild();
}

void Simulator::analyze_if_needed() {
  // The symbolic analysis is reused for the whole revision.
  if (m_pattern_analyzed) return;
  m_solver->analyze_pattern(m_fem->system_pattern(m_constrained));
  m_pattern_analyzed = true;
}

VecX Simulator::prescribed_increments(double dt, std::vector<Vec3>& target) const {
  const int nd = m_model.num_dofs();
  const double t1 = m_state.t + dt;
  VecX dv_c = VecX::Zero(3 * nd);
  target.resize(std::size_t(nd));
  for (int d = 0; d < nd; ++d) {
    if (!m_constrained[std::size_t(d)]) continue;
    target[std::size_t(d)] = m_model.handle_position(d, t1);
    const Vec3 vn = (target[std::size_t(d)] - m_state.x[std::size_t(d)]) / dt;
    dv_c.segment<3>(3 * d) = vn - m_state.v[std::size_t(d)];
  }
  return dv_c;
}

bool Simulator::solve_increment(double dt, const VecX& dv_c, VecX& dv) {
  const ObjectModel& m = m_model;
  const int nd = m.num_dofs();
  const double alpha = m.params().rayleigh_mass, beta = m.params().rayleigh_stiffness;
  const VecX v = flatten(m_state.v);

  // Forces at x: elastic, K v, gravity.
  auto t0 = Clock::now();
  // The rotations and forces at x: those the energy guard computed at the end of the last step when the state is the
  // one it ended with (try_dynamic_step), else computed now.
  ElementFrame frame;
  VecX f_el, kv;
  const bool ready = m_next_start && m_next_start->version == m_state_version;
  if (ready) {
    frame = std::move(m_next_start->frame);
    f_el = std::move(m_next_start->f_el);
    kv = std::move(m_next_start->kv);
  } else {
    m_fem->rotations(m_state.x, frame);
  }
  m_next_start.reset();
  for (const double r : frame.volume_ratio) m_stats.min_volume_ratio = std::min(m_stats.min_volume_ratio, r);
  m_profile.rotations = lap(t0);
  if (!ready) m_fem->force_and_product(m_state.x, frame, v, f_el, kv);
  m_profile.forces = lap(t0);

  // (M + dt C + dt^2 K) dv = dt (f_ext + f_el - C v - dt K v), with C = alpha M + beta K.
  VecX rhs(3 * nd);
  for (int d = 0; d < nd; ++d) {
    const double md = m.dof_mass()[std::size_t(d)];
    const Vec3 f = md * m_options.gravity + f_el.segment<3>(3 * d) - alpha * md * v.segment<3>(3 * d) -
                   (beta + dt) * kv.segment<3>(3 * d);
    rhs.segment<3>(3 * d) = dt * f;
  }
  // The system as an operator (assembled only if the solver asks), and the prescribed DOFs' coupling.
  StepSystem system(*m_fem, frame, dt, m.params(), m_constrained, m_A);
  VecX coupling;
  m_fem->system_coupling(system.stiffness_coefficient(), frame, m_constrained, dv_c, coupling);
  rhs -= coupling;
  m_profile.assembly = lap(t0);
  // Contact: penalty stiffness and damping in the system matrix, so stiff contact is stable at dt.
  if (!m_contacts.empty()) {
    system.contact.reserve(m_contact_blocks);
    contact_system_terms(m_contacts, dt, m_state.v, m_constrained, dv_c, m_fem->system_pattern(m_constrained),
                         system.contact, rhs);
    m_contact_blocks = system.contact.size();
  }
  for (int d = 0; d < nd; ++d)
    if (m_constrained[std::size_t(d)]) rhs.segment<3>(3 * d) = dv_c.segment<3>(3 * d);
  m_profile.contact = lap(t0);

  // Solve, warm-started from the last increments; the contacts' DOFs change fast (set_fast_dofs).
  analyze_if_needed();
  m_solver->set_fast_dofs(contact_dofs());
  m_solver->set_dof_rotations(m_fem->dof_rotations(frame));
  if (!m_solver->factorize_operator(system)) {
    ++m_stats.solver_failures;
    return false;
  }
  warm_start(dt, dv);
  // The residual is measured against the larger of rhs and the elastic impulse dt f_el the step balances: near
  // equilibrium (an object at rest under gravity, a tool pressed into it) the right-hand side is the small remainder
  // of forces that cancel, and resolving that remainder to the tolerance of itself costs iterations without moving
  // the result (meniscus_punch: 6.4 -> 4.8 iterations per contact step; docs/RESULTS.md).
  m_solver->set_reference_norm(dt * free_norm(f_el, m_constrained));
  m_last_solve = m_solver->solve(rhs, dv);
  m_profile.solve = lap(t0);
  if (!m_last_solve.ok) {
    ++m_stats.solver_failures;
    return false;
  }
  if (!dv.allFinite()) {
    ++m_stats.nonfinite;
    return false;
  }
  return true;
}

bool Simulator::commit_step(double dt, const VecX& dv, const std::vector<Vec3>& target) {
  const int nd = m_model.num_dofs();
  std::vector<Vec3> xn(static_cast<std::size_t>(nd)), vn(static_cast<std::size_t>(nd));
  double vmax = 0.0;
  for (int d = 0; d < nd; ++d) {
    vn[std::size_t(d)] = m_state.v[std::size_t(d)] + dv.segment<3>(3 * d);
    xn[std::size_t(d)] = m_constrained[std::size_t(d)] ? target[std::size_t(d)]
                                                       : Vec3(m_state.x[std::size_t(d)] + dt * vn[std::size_t(d)]);
    if (!m_constrained[std::size_t(d)]) vmax = std::max(vmax, vn[std::size_t(d)].norm());
    if (!xn[std::size_t(d)].allFinite() || !vn[std::size_t(d)].allFinite()) {
      ++m_stats.nonfinite;
      return false;
    }
  }
  if (vmax > m_options.max_speed) {
    ++m_stats.speed_limit;
    return false;
  }
  m_stats.max_speed = std::max(m_stats.max_speed, vmax);
  m_state.x = std::move(xn);
  m_state.v = std::move(vn);
  m_state.t += dt;
  ++m_state_version;
  m_history = m_history > 0 && m_history_dt == dt ? std::min(m_history + 1, 3) : 1;
  m_history_dt = dt;
  std::swap(m_dv_prev3, m_dv_prev2);
  std::swap(m_dv_prev2, m_dv_prev);
  m_dv_prev = dv;
  return true;
}

std::vector<int> Simulator::contact_dofs() const {
  std::vector<int> out;
  for (const Contact& c : m_contacts)
    for (const ContactDof& d : c.dofs)
      if (!m_constrained[std::size_t(d.dof)]) out.push_back(d.dof);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

void Simulator::warm_start(double dt, VecX& dv) const {
  // PCG starts from the increments of the last steps extrapolated along a parabola (three steps of this Δt in a row
  // on this revision) or a line (two), else from the last one: on a smooth motion the start is then off by the
  // third difference of the increments instead of the first. (meniscus_rest: 4.4 -> 2.6 iterations per step at its
  // tolerance, 18 -> 12 refactorisations in 490 steps; docs/RESULTS.md.) Only the start changes: every solve still
  // meets the tolerance.
  const int n = m_history_dt == dt ? m_history : std::min(m_history, 1);
  if (n >= 3)
    dv = 3.0 * (m_dv_prev - m_dv_prev2) + m_dv_prev3;
  else if (n == 2)
    dv = 2.0 * m_dv_prev - m_dv_prev2;
  else
    dv = m_dv_prev;
}

// Whether the energy balance of an attempt with handle targets `target` can be checked: not when a handle moves (its
// work is not measured), and only when the start's energy is at hand (kept from the step that ended there, or from the
// attempt rolled back to it): the first step after a cut, a reset or a new state is not checked.
bool Simulator::energy_measurable(const std::vector<Vec3>& target) const {
  if (!(m_options.energy_guard > 0.0) || m_energy_version != m_state_version) return false;
  for (int d = 0; d < m_model.num_dofs(); ++d)
    if (m_constrained[std::size_t(d)] && target[std::size_t(d)] != m_state.x[std::size_t(d)]) return false;
  return true;
}

bool Simulator::try_dynamic_step(double dt, bool may_reject) {
  std::vector<Vec3> target;  // handle DOFs' positions at t + dt (num_dofs)
  const VecX dv_c = prescribed_increments(dt, target);
  VecX dv;
  ensure_start_energy();
  const bool measured = energy_measurable(target);
  const std::vector<Vec3> v0 = m_contacts.empty() && !measured ? std::vector<Vec3>() : m_state.v;
  const double e0 = m_energy;                                                // J, kinetic + elastic at the start
  const std::vector<Vec3> x0 = measured ? m_state.x : std::vector<Vec3>();  // for the work gravity does
  if (!solve_increment(dt, dv_c, dv) || !commit_step(dt, dv, target)) return false;
  double work = 0.0, penalty = 0.0;  // J: the rigid shapes' work through the contacts, the penalty springs' change
  contact_balance(dt, v0, dv, work, penalty);
  if (m_options.energy_guard > 0.0) {
    double gain = 0.0, scale = 0.0;  // J
    if (!energy_holds(measured, may_reject, e0, x0, work, penalty, gain, scale)) {
      ++m_stats.energy_rejections;
      return false;
    }
    if (gain > 0.0)
      remove_energy_gain(gain, gain > m_options.energy_guard * scale, dt, e0, x0, v0, dv, work, penalty);
  }
  if (!m_contacts.empty()) {
    // Where the next part starts from.
    m_contact_energy.work_j += work;
    m_contact_energy.penalty_change_j += penalty;
    for (std::size_t i = 0; i < m_contacts.size(); ++i) m_contacts[i].penetration = m_outcomes[i].penetration;
  }
  return true;
}

// The start's rotations, forces and energy (m_next_start, m_energy) where no earlier attempt left them (the first
// step, after a cut, a reset or a new state): the step needs the rotations and forces anyway, so the energy guard
// checks those steps too for the cost of the elastic energy's sum.
void Simulator::ensure_start_energy() {
  if (!(m_options.energy_guard > 0.0) || m_energy_version == m_state_version) return;
  auto start = std::make_unique<StepStart>();
  m_fem->rotations(m_state.x, start->frame);
  double elastic = 0.0;  // J
  m_fem->force_and_product(m_state.x, start->frame, flatten(m_state.v), start->f_el, start->kv, &elastic);
  start->version = m_state_version;
  m_next_start = std::move(start);
  m_energy = kinetic_energy() + elastic;
  m_energy_version = m_state_version;
}

void Simulator::contact_balance(double dt, const std::vector<Vec3>& v0, const VecX& dv, double& work,
                                double& penalty) {
  work = penalty = 0.0;
  if (m_contacts.empty()) return;
  // The forces of this (part of the) step, and what they did.
  const auto t0 = Clock::now();
  m_outcomes = sim::contact_outcomes(m_contacts, dt, v0, dv);
  for (std::size_t i = 0; i < m_contacts.size(); ++i) {
    // The normal force is k (d_end - d_start + max(d_start, 0)) (contact.cpp): its potential is k d~^2 / 2 with
    // d~ = d - d_start + max(d_start, 0).
    const Contact& c = m_contacts[i];
    const double d0 = std::max(c.penetration, 0.0), d1 = m_outcomes[i].penetration - c.penetration + d0;
    work += dt * m_outcomes[i].force.dot(c.rigid_velocity);
    penalty += 0.5 * c.stiffness * (d1 * d1 - d0 * d0);
  }
  m_profile.contact += ms_since(t0);
}

// The energy guard at the state just committed: the kinetic + elastic energy e1 may exceed the start's e0 (J) by no
// more than the work of gravity (from the start's positions x0) and of the rigid shapes, less what the penalty springs
// took up, plus energy_guard times the largest of these terms (checked only when `measured` and `may_reject`); `gain`
// is what it exceeds them by (J; 0 unless measured). The rotations, forces and K v it computes at the new state are
// the next step's start (solve_increment), so the guard costs the elastic energy's few operations per element, not
// another pass.
bool Simulator::energy_holds(bool measured, bool may_reject, double e0, const std::vector<Vec3>& x0, double work,
                             double penalty, double& gain, double& scale) {
  // Timed as this attempt's rotations and forces: the next step finds them done.
  auto t0 = Clock::now();
  auto next = std::make_unique<StepStart>();
  m_fem->rotations(m_state.x, next->frame);
  m_profile.rotations += lap(t0);
  double elastic = 0.0;
  m_fem->force_and_product(m_state.x, next->frame, flatten(m_state.v), next->f_el, next->kv, &elastic);
  m_profile.forces += lap(t0);
  const double e1 = kinetic_energy() + elastic;
  gain = scale = 0.0;
  if (measured) {
    double gravity_work = 0.0;
    for (int d = 0; d < m_model.num_dofs(); ++d)
      gravity_work +=
          m_model.dof_mass()[std::size_t(d)] * m_options.gravity.dot(m_state.x[std::size_t(d)] - x0[std::size_t(d)]);
    scale = std::max({e0, e1, std::abs(work), std::abs(gravity_work), std::abs(penalty)});
    gain = e1 + penalty - e0 - work - gravity_work;
    // Below this the gain is the noise of the energy sums and of a corotated force that is not quite the energy's
    // gradient (meniscus_punch_hd at rest: 1e-13 to 2e-9 of the scale); left alone. The study's criterion is 1e-6.
    // Noise is measured against the run's energy too, the largest since the state was set: a system come to rest
    // holds energies at the rounding floor of its positions (1e-30 of its start's), whose step-to-step noise would
    // otherwise be rejected and halved down to the smallest dt, step after step.
    constexpr double kEnergyNoise = 1e-7;
    m_energy_peak = std::max({m_energy_peak, e0, e1});
    if (gain <= kEnergyNoise * std::max(scale, m_energy_peak)) gain = 0.0;
    if (may_reject && gain > m_options.energy_guard * scale) return false;
  }
  next->version = m_state_version;
  m_next_start = std::move(next);
  m_energy = e1;
  m_energy_version = m_state_version;
  return true;
}

// An accepted attempt that gained energy without work put in. Implicit Euler takes energy out of a system, so a gain
// is an error of the step: one linearisation of the corotated forces through a configuration that turns or inverts
// fast, or a near-incompressible element that locks; or the corotated force itself, which is not the gradient of the
// corotated energy (RESULTS.md: 1-8 % off on twisted boxes), so that a stretched bar held still creeps up by a few 1e-6
// of its energy per step as it settles. A gain within the guard's tolerance is taken out of the free DOFs' kinetic
// energy, their velocities scaled by one factor, and what exceeds that kinetic energy stays (energy_unremoved_j):
// moving the positions against the force would keep such a bar from its equilibrium. A gain beyond the tolerance
// (`beyond`: at the smallest dt, where halving cannot help) is a failed linearisation: the step is shortened first,
// the free DOFs' end velocity v1 becoming theta v1 (so x = x0 + dt theta v1, as implicit Euler would commit it),
// theta = 1/2, 1/4, ... 1/64, 0, until the kinetic energy can take the rest; theta = 0 is the start's positions at
// rest, whose energy is at most e0. Counted in StabilityStats.
void Simulator::remove_energy_gain(double gain, bool beyond, double dt, double e0, const std::vector<Vec3>& x0,
                                   const std::vector<Vec3>& v0, const VecX& dv, double& work, double& penalty) {
  const int nd = m_model.num_dofs();
  const auto free_kinetic = [&] {
    double k = 0.0;  // J
    for (int d = 0; d < nd; ++d)
      if (!m_constrained[std::size_t(d)])
        k += 0.5 * m_model.dof_mass()[std::size_t(d)] * m_state.v[std::size_t(d)].squaredNorm();
    return k;
  };
  ++m_stats.energy_projections;
  const double gained = gain;  // J
  if (beyond && gain > free_kinetic()) {
    const std::vector<Vec3> v1 = m_state.v;
    VecX dv_theta = dv;
    for (int halvings = 1; halvings <= 7 && gain > free_kinetic(); ++halvings) {
      const double theta = halvings == 7 ? 0.0 : std::ldexp(1.0, -halvings);  // 1/2 ... 1/64, then 0
      for (int d = 0; d < nd; ++d) {
        if (m_constrained[std::size_t(d)]) continue;
        m_state.v[std::size_t(d)] = theta * v1[std::size_t(d)];
        m_state.x[std::size_t(d)] = x0[std::size_t(d)] + dt * m_state.v[std::size_t(d)];
        dv_theta.segment<3>(3 * d) = m_state.v[std::size_t(d)] - v0[std::size_t(d)];
      }
      ++m_state_version;
      contact_balance(dt, v0, dv_theta, work, penalty);
      double scale = 0.0;
      energy_holds(true, false, e0, x0, work, penalty, gain, scale);
    }
    m_dv_prev = dv_theta;
    ++m_stats.energy_shortened;
  }
  if (!(gain > 0.0)) {
    m_stats.energy_removed_j += gained;
    return;
  }
  const double k = free_kinetic();
  // v -> s v on the free DOFs: their kinetic energy becomes s^2 of it. K v (the next step's start) follows; the
  // handles' velocities (zero: no handle moves in a measured attempt) are unchanged.
  const double s = gain >= k ? 0.0 : std::sqrt(1.0 - gain / k);
  const double kinetic_before = kinetic_energy();
  for (int d = 0; d < nd; ++d)
    if (!m_constrained[std::size_t(d)]) m_state.v[std::size_t(d)] *= s;
  if (m_next_start) m_next_start->kv *= s;
  m_energy += kinetic_energy() - kinetic_before;
  m_stats.energy_removed_j += gained - std::max(0.0, gain - k);
  m_stats.energy_unremoved_j += std::max(0.0, gain - k);
}

void Simulator::reset_failed_step(const SimState& start) {
  // Positions of the step's start, velocities zero, handles at their pose at t + dt.
  ++m_stats.failed_steps;
  m_state = start;
  ++m_state_version;
  m_state.t = start.t + m_options.dt;
  for (int d = 0; d < m_model.num_dofs(); ++d) {
    m_state.v[std::size_t(d)].setZero();
    if (m_constrained[std::size_t(d)]) m_state.x[std::size_t(d)] = m_model.handle_position(d, m_state.t);
  }
}

void Simulator::step() {
  const double dt = m_options.dt;
  m_outcomes.clear();
  m_contact_energy = {};
  if (empty()) {
    m_state.t += dt;  // nothing to simulate; time still runs
    ++m_state_version;
    m_contacts.clear();
    return;
  }
  if (!m_options.dynamic) {
    if (!solve_static(m_state.t + dt)) ++m_stats.newton_unconverged;  // sets t
    return;
  }
  const SimState start = m_state;
  // An attempt that fails is rolled back and its interval retried as two halves, each of which may halve again,
  // down to dt / 2^max_halvings.
  std::function<bool(double, int)> advance = [&](double h, int depth) {
    const SimState before = m_state;
    const std::uint64_t version_before = m_state_version;
    const ContactEnergy energy_before = m_contact_energy;
    if (try_dynamic_step(h, depth < m_options.max_halvings)) return true;
    m_state = before;
    m_state_version = version_before;  // the same state: what was computed from it (m_energy) holds again
    m_contact_energy = energy_before;
    m_dv_prev.setZero();
    m_history = 0;
    if (depth >= m_options.max_halvings) return false;
    return advance(0.5 * h, depth + 1) && advance(0.5 * h, depth + 1);
  };
  const auto rejected = [&] {  // attempts rejected so far, for any cause
    return m_stats.nonfinite + m_stats.speed_limit + m_stats.solver_failures + m_stats.energy_rejections;
  };
  const int failures_before = rejected();
  const bool ok = advance(dt, 0);
  m_contacts.clear();  // found anew by the caller for the next step
  if (ok) {
    if (rejected() > failures_before) ++m_stats.recoveries;
    return;
  }
  m_outcomes.clear();
  m_contact_energy = {};
  reset_failed_step(start);
}

double Simulator::static_residual(const std::vector<Vec3>& x, const VecX& f_ext, ElementFrame& frame,
                                  VecX& r) const {
  // r = f_el(x) + f_ext on free DOFs, zero on constrained ones; the frame is left at x.
  m_fem->rotations(x, frame);
  m_fem->elastic_force(x, frame, r);
  r += f_ext;
  for (int d = 0; d < m_model.num_dofs(); ++d)
    if (m_constrained[std::size_t(d)]) r.segment<3>(3 * d).setZero();
  return r.norm();
}

bool Simulator::newton_direction(const ElementFrame& frame, const VecX& r, VecX& dx) {
  // The corotated tangent K dx = r (constrained rows identity, dx_c = 0).
  const VecX zero = VecX::Zero(3 * m_model.num_dofs());
  VecX coupling;
  m_fem->assemble_system(0.0, 1.0, frame, m_constrained, zero, m_A, coupling);
  analyze_if_needed();
  dx = VecX::Zero(3 * m_model.num_dofs());
  m_solver->set_reference_norm(0.0);  // Newton's own scale decides when to stop (static_solve)
  return m_solver->factorize(m_A) && (m_last_solve = m_solver->solve(r, dx)).ok && dx.allFinite();
}

double Simulator::line_search(std::vector<Vec3>& x, const VecX& dx, const VecX& f_ext, double done,
                              ElementFrame& frame, VecX& r) {
  // Damping by Deuflhard's natural monotonicity test (affine covariant): a trial x + s dx is accepted when its
  // simplified Newton correction K^-1 r(x + s dx), with the tangent K already factorised, is shorter than
  // (1 - s/4) |dx|. The residual norm is no merit function here: near incompressibility a full step that is right
  // to second order raises it by orders of magnitude (the bulk modulus times the second-order volume change of
  // rotating elements; a 20 x 4 x 4 cantilever at nu = 0.499: 440 times), and backtracking on it crept forward by
  // 1/256 of a step per iteration and stopped far from equilibrium. A trial whose residual is at most `done` (the
  // convergence threshold) is taken as it is.
  const double dn = dx.norm();
  double step = 1.0;
  std::vector<Vec3> xt(x.size());
  VecX rt, bar;
  double rtn = 0.0;
  for (int ls = 0; ls < 8; ++ls, step *= 0.5) {
    for (std::size_t d = 0; d < x.size(); ++d) xt[d] = x[d] + step * dx.segment<3>(3 * Eigen::Index(d));
    rtn = static_residual(xt, f_ext, frame, rt);
    if (!std::isfinite(rtn)) continue;
    if (rtn <= done) break;
    bar = VecX::Zero(rt.size());
    if (m_solver->solve(rt, bar).ok && bar.allFinite() && bar.norm() <= (1.0 - 0.25 * step) * dn) break;
  }
  if (std::isfinite(rtn)) {
    x = std::move(xt);
    r = std::move(rt);
  }
  return rtn;
}

bool Simulator::solve_static(double t) {
  if (empty()) {
    m_state.t = t;
    ++m_state_version;
    return true;
  }
  const ObjectModel& m = m_model;
  const int nd = m.num_dofs();
  // Handle DOFs at their pose at t; gravity on the free ones.
  std::vector<Vec3> x = m_state.x;
  VecX f_ext = VecX::Zero(3 * nd);
  for (int d = 0; d < nd; ++d) {
    if (m_constrained[std::size_t(d)]) x[std::size_t(d)] = m.handle_position(d, t);
    else f_ext.segment<3>(3 * d) = m.dof_mass()[std::size_t(d)] * m_options.gravity;
  }

  // Newton iterations, damped (line_search).
  ElementFrame frame;
  VecX r;
  double rn = static_residual(x, f_ext, frame, r);
  const double scale = std::max({f_ext.norm(), rn, 1e-300});
  bool converged = false;
  for (int it = 0; it < m_options.max_iterations; ++it) {
    if (!(rn / scale > m_options.tolerance)) {
      converged = std::isfinite(rn);
      break;
    }
    VecX dx;
    if (!newton_direction(frame, r, dx)) {
      ++m_stats.solver_failures;
      break;
    }
    const double rtn = line_search(x, dx, f_ext, m_options.tolerance * scale, frame, r);
    if (!std::isfinite(rtn)) {
      ++m_stats.nonfinite;
      break;
    }
    rn = rtn;
  }
  if (converged || std::isfinite(rn)) {
    m_state.x = x;
    for (auto& vv : m_state.v) vv.setZero();
    // frame is at x (static_residual and line_search leave it at the accepted point).
    for (const double ratio : frame.volume_ratio) m_stats.min_volume_ratio = std::min(m_stats.min_volume_ratio, ratio);
  }
  m_state.t = t;
  ++m_state_version;
  return converged;
}

double Simulator::kinetic_energy() const {
  double e = 0.0;
  for (int d = 0; d < m_model.num_dofs(); ++d)
    e += 0.5 * m_model.dof_mass()[std::size_t(d)] * m_state.v[std::size_t(d)].squaredNorm();
  return e;
}

double Simulator::elastic_energy() const {
  ElementFrame frame;
  m_fem->rotations(m_state.x, frame);
  return m_fem->elastic_energy(m_state.x, frame);
}

Vec3 Simulator::position(const PointEmbedding& e) const {
  Vec3 p = Vec3::Zero();
  const DofMap& dm = m_model.dofs();
  for (int k = 0; k < 8; ++k) {
    const int s = 8 * e.leaf + k;
    for (int i = dm.slot_begin[std::size_t(s)]; i < dm.slot_begin[std::size_t(s) + 1]; ++i)
      p += e.weights[std::size_t(k)] * dm.slot_weight[std::size_t(i)] * m_state.x[std::size_t(dm.slot_dof[std::size_t(i)])];
  }
  return p;
}

double Simulator::max_speed() const {
  double v = 0.0;
  for (const Vec3& s : m_state.v) v = std::max(v, s.norm());
  return v;
}

}  // namespace octocut::sim
