// The tissue side of contact (sim/contact.hpp), without any rigid-body library: the collision samples against exact
// areas and the embedding, and a block resting on the plane z = 0 whose contacts the test finds itself, against
// m g, also with a penalty far too stiff for any explicit step (the stiffness is in the implicit system).
#include <gtest/gtest.h>

#include <cmath>

#include "octocut/sim/contact.hpp"
#include "octocut/sim/embedding.hpp"
#include "octocut/sim/primitives.hpp"
#include "octocut/sim/simulator.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

const Box3 kBox{Vec3(0, 0, 0), Vec3(0.01, 0.01, 0.01)};

MaterialParams soft() {
  MaterialParams p;
  p.young_modulus = 2e4;
  p.poisson_ratio = 0.3;
  p.density = 1000.0;
  return p;
}

TEST(ContactSamples, CoverTheSurfaceAreaAndFollowTheEmbedding) {
  const ObjectModel m = test::box_model(kBox, Vec3(0, 0, 0), 0.01, 2, {}, {}, soft());
  const TriMesh s = box_face_grids(kBox, 1);
  const SurfaceEmbedding e(m, s);
  const ContactSamples samples = build_contact_samples(m, s, e, 0.0025);
  // The box's 6 faces of 1 cm^2, whatever the sampling.
  double area = 0.0;
  for (double a : samples.area) area += a;
  EXPECT_NEAR(area, 6e-4, 1e-15);
  EXPECT_GT(samples.size(), int(s.num_vertices()));  // faces larger than the resolution get points
  // At rest every sample is where it was put (the embedding reproduces positions).
  const SimState rest = SimState::rest(m);
  for (int i = 0; i < samples.size(); ++i)
    EXPECT_LT((samples.position(i, rest.x) - samples.rest[std::size_t(i)]).norm(), 1e-12) << i;
  // Without subdivision only the vertices remain.
  EXPECT_EQ(build_contact_samples(m, s, e, 1.0).size(), int(s.num_vertices()));
}

// Steps the block on the plane z = 0 (contacts found here: every sample below it) for `seconds`; returns the total
// contact force of the last step, N, and in `deepest` the deepest sample at its start, m.
Vec3 rest_on_plane(double stiffness, double dt, double seconds, StabilityStats& stats, double& deepest) {
  const ObjectModel m = test::box_model(kBox, Vec3(0, 0, 0), 0.01, 2, {}, {}, soft());
  const TriMesh s = box_face_grids(kBox, 4);
  const SurfaceEmbedding e(m, s);
  const ContactSamples samples = build_contact_samples(m, s, e, 0.0025);
  SimulatorOptions o;
  o.dt = dt;
  o.threads = 1;
  o.linear_solver = "cholmod";
  Simulator sim(m, o);
  Vec3 total = Vec3::Zero();
  deepest = 0.0;
  for (int step = 0; step * dt < seconds; ++step) {
    std::vector<Contact> contacts;
    deepest = 0.0;
    for (int i = 0; i < samples.size(); ++i) {
      const Vec3 p = samples.position(i, sim.state().x);
      if (!(p.z() < 0.0)) continue;
      Contact c;
      c.dofs.assign(samples.dofs.begin() + samples.begin[std::size_t(i)],
                    samples.dofs.begin() + samples.begin[std::size_t(i) + 1]);
      c.normal = Vec3::UnitZ();
      c.penetration = -p.z();
      c.stiffness = stiffness * samples.area[std::size_t(i)];
      c.damping = 1e-3 * c.stiffness;
      c.friction = 0.5;
      deepest = std::max(deepest, c.penetration);
      contacts.push_back(std::move(c));
    }
    sim.set_contacts(std::move(contacts));
    sim.step();
    total.setZero();
    for (const ContactOutcome& oc : sim.contact_outcomes()) total += oc.force;
  }
  stats = sim.stats();
  return total;
}

TEST(ContactTerm, ABlockOnAPlaneCarriesItsWeight) {
  StabilityStats stats;
  double deepest = 0.0;
  const Vec3 f = rest_on_plane(2e8, 0.002, 0.4, stats, deepest);
  const double weight = 1000.0 * 1e-6 * 9.81;  // N
  EXPECT_NEAR(f.z(), weight, 0.005 * weight);
  EXPECT_LT(std::hypot(f.x(), f.y()), 1e-3 * weight);
  EXPECT_LT(deepest, 0.01 * 0.01);
  EXPECT_EQ(stats.recoveries, 0);
}

// A 3 x 3 blocked matrix of nd DOFs whose block (i, j) is in the pattern when |i - j| <= 2, entry (row, col) being
// value(row, col).
template <class Value>
SpMat band_blocks(int nd, const Value& value) {
  std::vector<Eigen::Triplet<double>> t;
  for (int i = 0; i < nd; ++i)
    for (int j = std::max(0, i - 2); j <= std::min(nd - 1, i + 2); ++j)
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) t.emplace_back(3 * i + r, 3 * j + c, value(3 * i + r, 3 * j + c));
  SpMat A(3 * nd, 3 * nd);
  A.setFromTriplets(t.begin(), t.end());
  A.makeCompressed();
  return A;
}

// The contacts' system blocks (add_system_blocks) against a dense sum: into a 3 x 3 blocked matrix, and into the
// columns of a region of DOFs (what the contact's exact solve takes), each entry receiving its blocks in the list's
// order; blocks outside the pattern, or whose column is not in the region, are left out.
TEST(ContactTerm, SystemBlocksAddToTheMatrixAndToARegionsColumns) {
  const int nd = 12;
  const SpMat A = band_blocks(nd, [](int row, int col) { return 0.01 * row - 0.003 * col; });
  std::vector<SystemBlock> blocks;
  std::uint32_t seed = 12345u;
  const auto next = [&seed] { return (seed = seed * 1664525u + 1013904223u) >> 8; };
  for (int k = 0; k < 400; ++k) {
    SystemBlock b;
    b.row = int(next() % nd);
    b.col = int(next() % nd);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) b.value(r, c) = double(next() % 2001) / 1000.0 - 1.0;
    blocks.push_back(b);
  }
  // The truth: the blocks in the pattern summed densely in the list's order.
  Eigen::MatrixXd want(A);
  int outside = 0;
  for (const SystemBlock& b : blocks) {
    if (std::abs(b.row - b.col) > 2) {
      ++outside;
      continue;
    }
    for (int c = 0; c < 3; ++c)
      for (int r = 0; r < 3; ++r) want(3 * b.row + r, 3 * b.col + c) += b.value(r, c);
  }
  ASSERT_GT(outside, 50);
  SpMat whole = A;
  add_system_blocks(blocks, whole);
  EXPECT_TRUE(Eigen::MatrixXd(whole) == want);
  // The columns of the DOFs 1, 4, 5, 9 (and their rows of every DOF).
  const std::vector<int> region = {1, 4, 5, 9};
  std::vector<int> local(std::size_t(nd), -1);
  SpMat cols(3 * nd, 3 * Eigen::Index(region.size()));
  std::vector<Eigen::Triplet<double>> ct;
  for (std::size_t i = 0; i < region.size(); ++i) {
    local[std::size_t(region[i])] = int(i);
    for (int c = 0; c < 3; ++c)
      for (SpMat::InnerIterator it(A, 3 * region[i] + c); it; ++it)
        ct.emplace_back(int(it.row()), 3 * int(i) + c, it.value());
  }
  cols.setFromTriplets(ct.begin(), ct.end());
  cols.makeCompressed();
  add_system_blocks(blocks, cols, &local);
  for (std::size_t i = 0; i < region.size(); ++i)
    for (int c = 0; c < 3; ++c)
      EXPECT_TRUE(VecX(Eigen::MatrixXd(cols).col(3 * Eigen::Index(i) + c)) == VecX(want.col(3 * region[i] + c)))
          << "DOF " << region[i] << ", column " << c;
}

// Contacts whose samples share their DOFs (embedded in the same element) enter the system summed: one block per pair
// of their DOF list, in the order of each list's first contact. Against the same contacts passed one at a time (no
// list to share): the matrix to rounding, the right-hand side bit for bit, with blocks in the band pattern, lumped
// ones outside it (DOFs 0 and 7) and a constrained DOF (5) whose column moves to the right-hand side.
TEST(ContactTerm, ContactsSharingTheirDofsEnterTheSystemAsOneBlockPerPair) {
  const int nd = 12;
  const SpMat pattern = band_blocks(nd, [](int, int) { return 0.0; });
  const std::vector<std::vector<int>> lists = {{1, 2, 3}, {0, 7}, {4, 5, 6}};
  std::vector<Contact> contacts;
  for (int k = 0; k < 12; ++k) {
    Contact c;
    const std::vector<int>& list = lists[std::size_t(k % 3)];
    for (std::size_t i = 0; i < list.size(); ++i) c.dofs.push_back({list[i], 0.2 + 0.05 * double((k + int(i)) % 5)});
    c.normal = Vec3(0.1 * k, 1.0, -0.2).normalized();
    c.penetration = 1e-4 * (1 + k);
    c.stiffness = 1e3 * (1 + k % 4);
    c.damping = 0.01 * c.stiffness;
    c.friction = 0.3;
    c.rigid_velocity = Vec3(0.01 * k, 0.0, -0.02);
    contacts.push_back(c);
  }
  std::vector<Vec3> v(static_cast<std::size_t>(nd), Vec3::Zero());
  for (int d = 0; d < nd; ++d) v[std::size_t(d)] = Vec3(0.001 * d, -0.002, 0.0005 * d);
  std::vector<char> constrained(std::size_t(nd), 0);
  constrained[5] = 1;
  const VecX dv_c = VecX::Constant(3 * nd, 1e-3);
  const double dt = 2e-3;
  std::vector<SystemBlock> grouped, single;
  VecX rhs_grouped = VecX::Zero(3 * nd), rhs_single = VecX::Zero(3 * nd);
  contact_system_terms(contacts, dt, v, constrained, dv_c, pattern, grouped, rhs_grouped);
  for (const Contact& c : contacts)
    contact_system_terms({c}, dt, v, constrained, dv_c, pattern, single, rhs_single);
  EXPECT_LT(grouped.size(), single.size() / 3);
  for (Eigen::Index i = 0; i < rhs_single.size(); ++i) ASSERT_TRUE(rhs_grouped[i] == rhs_single[i]) << "row " << i;
  SpMat with_grouped = pattern, with_single = pattern;
  add_system_blocks(grouped, with_grouped);
  add_system_blocks(single, with_single);
  const Eigen::MatrixXd a(with_grouped), b(with_single);
  ASSERT_GT(b.norm(), 0.0);
  EXPECT_LT((a - b).norm(), 1e-13 * b.norm());
  EXPECT_LT((a - a.transpose()).norm(), 1e-13 * a.norm()) << "the summed blocks keep A symmetric";
}

TEST(ContactTerm, APenaltyFarTooStiffForAnExplicitStepIsStable) {
  // k = 1e12 Pa/m: a sample of 6 mm^2 and 0.1 g would need dt < 2 sqrt(m / k) = 8 us explicitly; here dt = 2 ms.
  StabilityStats stats;
  double deepest = 0.0;
  const Vec3 f = rest_on_plane(1e12, 0.002, 0.2, stats, deepest);
  const double weight = 1000.0 * 1e-6 * 9.81;
  EXPECT_EQ(stats.recoveries, 0);
  EXPECT_EQ(stats.failed_steps, 0);
  EXPECT_TRUE(std::isfinite(f.z()));
  EXPECT_NEAR(f.z(), weight, 0.02 * weight);
  EXPECT_LT(deepest, 1e-6);
}

TEST(ContactTerm, AContactThatBlowsUpIsRolledBackAndCounted) {
  // Every sample of the block 5 mm deep in a 1e12 Pa/m penalty: the step would fling it off far above the speed
  // guard, so the attempt is rejected, retried with halved steps (each half from the penetration the last left),
  // and counted; the state stays finite.
  const ObjectModel m = test::box_model(kBox, Vec3(0, 0, 0), 0.01, 2, {}, {}, soft());
  const TriMesh s = box_face_grids(kBox, 2);
  const SurfaceEmbedding e(m, s);
  const ContactSamples samples = build_contact_samples(m, s, e, 0.0025);
  SimulatorOptions o;
  o.dt = 0.002;
  o.threads = 1;
  o.linear_solver = "cholmod";
  o.max_speed = 1.0;
  Simulator sim(m, o);
  std::vector<Contact> contacts;
  for (int i = 0; i < samples.size(); ++i) {
    Contact c;
    c.dofs.assign(samples.dofs.begin() + samples.begin[std::size_t(i)],
                  samples.dofs.begin() + samples.begin[std::size_t(i) + 1]);
    c.normal = Vec3::UnitZ();
    c.penetration = 0.005;
    c.stiffness = 1e12 * samples.area[std::size_t(i)];
    contacts.push_back(std::move(c));
  }
  sim.set_contacts(contacts);
  sim.step();
  EXPECT_GT(sim.stats().speed_limit, 0);
  EXPECT_EQ(sim.stats().recoveries + sim.stats().failed_steps, 1);
  for (const Vec3& v : sim.state().v) EXPECT_TRUE(v.allFinite());
  EXPECT_NEAR(sim.state().t, 0.002, 1e-15);
}

}  // namespace
}  // namespace octocut::sim
