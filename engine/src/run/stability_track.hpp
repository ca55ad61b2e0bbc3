#pragma once
// Stability tracked every step (scene `output.stability_track`, report `stability.track`): the total mechanical
// energy over steps without work put in, the largest displacement, and the deformed material volume. Used by
// `octocut study stability`; off by default, because it costs an energy evaluation per step.
#include "octocut/engine/run/report.hpp"
#include "octocut/sim/simulator.hpp"

namespace octocut::engine {

/// Deformed volume of the trilinear hexahedron with corners `x` (8, corner k at bits (k&1, k>>1&1, k>>2&1) along
/// x, y, z), m^3: the integral of det J over the unit cube by 2 x 2 x 2 Gauss points, exact for a trilinear map.
double hex_volume(const sim::Vec3* x);

/// Material volume of the model deformed to `dof_positions` (num_dofs, m): sum over elements of occupancy times
/// the deformed hexahedron's volume, m^3.
double deformed_material_volume(const sim::ObjectModel& model, const std::vector<sim::Vec3>& dof_positions);

/// Gravity's potential -sum_i m_i g . x_i of the DOFs at `x` (num_dofs, m), J (zero at the origin).
double gravity_potential(const sim::ObjectModel& model, const std::vector<sim::Vec3>& x, const sim::Vec3& gravity);

/// Total mechanical energy of the simulator's state, J: kinetic + elastic - sum_i m_i g . x_i (gravity's potential,
/// zero at the origin).
double mechanical_energy(const sim::Simulator& sim, const sim::Vec3& gravity);

/// Accumulates StabilityTrack over the steps of one run.
class StabilityTracker {
 public:
  StabilityTracker() = default;
  /// Starts tracking: the energy and rest volume of the current (rest) state.
  void start(const sim::Simulator& sim, const sim::Vec3& gravity);
  /// After a step: `checked` when no handle moved during it and no cut ran. The energy of such a step must not rise
  /// by more than the work that rigid shapes put in through contact (sim::Simulator::contact_energy: the energy
  /// compared is the tissue's plus its contacts' penalty energy, the work is the sum of F . v_rigid dt).
  void after_step(const sim::Simulator& sim, bool checked);
  /// The tracked values (enabled set).
  [[nodiscard]] StabilityTrack result() const { return m_track; }

 private:
  void measure(const sim::Simulator& sim);
  sim::Vec3 m_gravity = sim::Vec3::Zero();  ///< m/s^2
  double m_energy = 0.0;                    ///< E after the last step, J
  double m_rest_volume = 0.0;               ///< m^3 of the current model revision at rest
  int m_revision = -1;                      ///< model revision whose rest data is cached
  std::vector<sim::Vec3> m_rest;            ///< rest DOF positions of that revision, m (num_dofs)
  StabilityTrack m_track;
  bool m_first_volume = true;
};

}  // namespace octocut::engine
