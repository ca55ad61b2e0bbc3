#include "stability_track.hpp"

#include <algorithm>
#include <cmath>

namespace octocut::engine {

double hex_volume(const sim::Vec3* x) {
  // x(u) = sum_k N_k(u) x_k on the unit cube, N_k = prod_d (bit_d ? u_d : 1 - u_d); V = int det(dx/du) du.
  const double g[2] = {0.5 - 0.5 / std::sqrt(3.0), 0.5 + 0.5 / std::sqrt(3.0)};
  double v = 0.0;
  for (int a = 0; a < 8; ++a) {
    const double u[3] = {g[a & 1], g[(a >> 1) & 1], g[(a >> 2) & 1]};
    sim::Vec3 j[3] = {sim::Vec3::Zero(), sim::Vec3::Zero(), sim::Vec3::Zero()};  // columns dx/du_d
    for (int k = 0; k < 8; ++k) {
      const int b[3] = {k & 1, (k >> 1) & 1, (k >> 2) & 1};
      for (int d = 0; d < 3; ++d) {
        double w = b[d] ? 1.0 : -1.0;  // d N_k / d u_d
        for (int e = 0; e < 3; ++e)
          if (e != d) w *= b[e] ? u[e] : 1.0 - u[e];
        j[d] += w * x[k];
      }
    }
    v += 0.125 * j[0].dot(j[1].cross(j[2]));  // Gauss weights 1/2 per direction on [0, 1]
  }
  return v;
}

double deformed_material_volume(const sim::ObjectModel& model, const std::vector<sim::Vec3>& dof_positions) {
  std::vector<sim::Vec3> slots;  // 8 * num_elements, m
  model.dofs().prolong(dof_positions, slots);
  double v = 0.0;
  for (int e = 0; e < model.num_elements(); ++e)
    v += model.occupancy()[std::size_t(e)] * hex_volume(&slots[8 * std::size_t(e)]);
  return v;
}

double gravity_potential(const sim::ObjectModel& model, const std::vector<sim::Vec3>& x, const sim::Vec3& gravity) {
  double potential = 0.0;  // J
  for (int d = 0; d < model.num_dofs(); ++d) potential -= model.dof_mass()[std::size_t(d)] * gravity.dot(x[std::size_t(d)]);
  return potential;
}

double mechanical_energy(const sim::Simulator& sim, const sim::Vec3& gravity) {
  if (sim.empty()) return 0.0;
  return sim.kinetic_energy() + sim.elastic_energy() + gravity_potential(sim.model(), sim.state().x, gravity);
}

void StabilityTracker::start(const sim::Simulator& sim, const sim::Vec3& gravity) {
  m_gravity = gravity;
  m_track = {};
  m_track.enabled = true;
  m_first_volume = true;
  m_revision = -1;
  measure(sim);
}

void StabilityTracker::after_step(const sim::Simulator& sim, bool checked) {
  const double before = m_energy;
  measure(sim);
  // What rigid shapes put in through contact, and the energy their penalty springs took up (sim::ContactEnergy).
  const sim::ContactEnergy& c = sim.contact_energy();
  m_track.contact_work_j += c.work_j;
  m_track.energy_scale_j = std::max(m_track.energy_scale_j, std::abs(m_track.contact_work_j));
  if (!checked) return;
  ++m_track.energy_steps;
  m_track.energy_rise_j = std::max(m_track.energy_rise_j, m_energy + c.penalty_change_j - before - c.work_j);
}

void StabilityTracker::measure(const sim::Simulator& sim) {
  if (sim.empty()) {
    m_energy = 0.0;
    return;
  }
  const sim::ObjectModel& m = sim.model();
  if (m.revision() != m_revision) {
    // A new revision (a cut): its rest positions and rest volume.
    m_revision = m.revision();
    m_rest = sim::SimState::rest(m).x;
    m_rest_volume = deformed_material_volume(m, m_rest);
  }
  const std::vector<sim::Vec3>& x = sim.state().x;
  // Energy and its scale (kinetic + elastic + |gravitational|).
  const double kinetic = sim.kinetic_energy(), elastic = sim.elastic_energy();
  const double potential = gravity_potential(m, x, m_gravity);
  m_energy = kinetic + elastic + potential;
  m_track.energy_scale_j = std::max(m_track.energy_scale_j, kinetic + elastic + std::abs(potential));
  // Largest displacement; a non-finite one is kept as such (max ignores NaN, so test it).
  for (std::size_t d = 0; d < x.size(); ++d) {
    const double u = (x[d] - m_rest[d]).norm();
    if (!std::isfinite(u)) m_track.max_displacement_m = INFINITY;
    m_track.max_displacement_m = std::max(m_track.max_displacement_m, u);
  }
  // Deformed volume relative to rest.
  const double change = m_rest_volume > 0.0 ? deformed_material_volume(m, x) / m_rest_volume - 1.0 : 0.0;
  m_track.volume_change = change;
  m_track.min_volume_change = m_first_volume ? change : std::min(m_track.min_volume_change, change);
  m_track.max_volume_change = m_first_volume ? change : std::max(m_track.max_volume_change, change);
  m_first_volume = false;
}

}  // namespace octocut::engine
