#include "octocut/sim/simulator.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <chrono>
#include <chrono>
#include <cmath>
#include <functional>
#include <stdexcept>

#include "octocut/sim/parallel.hpp"

namespace octocut::sim {

namespace {
constexpr int kGrain = 64;  // elements per parallel chunk

// One entry of an element's gather list: corner a of the element feeds DOF `dof` with weight w.
struct GatherEntry {
  int corner;
  int dof;
  double w;
};

// Positions of an element's 8 slots as a 24-vector and as a 3 x 8 matrix.
void element_slots(const std::vector<Vec3>& slots, int e, Vec24& xe, Eigen::Matrix<double, 3, 8>& xm) {
  for (int a = 0; a < 8; ++a) {
    const Vec3& p = slots[8 * std::size_t(e) + std::size_t(a)];
    xe.segment<3>(3 * a) = p;
    xm.col(a) = p;
  }
}
}  // namespace

// ---- FemSystem -------------------------------------------------------------------------------------------------------

struct FemSystem::Impl {
  const ObjectModel* model_ptr;  // the model this system was built for (the simulator's, or a prepared one's)
  const ObjectModel& model() const { return *model_ptr; }
  Executor* executor_ptr;  // runs the element loops (the simulator's, or a serial one while prepared)
  std::vector<std::vector<GatherEntry>> gather;  // per element: its slots' rows of P (num_elements)
  std::vector<Vec24> rest;                        // rest slot positions per element, m (num_elements)

  // Fixed sparse pattern of the system matrix, built on the first assemble_system call.
  bool have_pattern = false;
  std::vector<char> pattern_constrained;          // constrained flags the pattern was built for (num_dofs)
  std::vector<int> pair_offsets;                  // per element, per (p, q) entry pair: 3 column offsets, or -1
  std::vector<std::size_t> pair_begin;            // start of each element's pair offsets (num_elements + 1)
  std::vector<int> diag_offsets;                  // per scalar DOF: offset of its diagonal entry (3 num_dofs)
  std::vector<double> rotated;                    // per element R K R^T, scaled (num_elements x 576)

  Impl(const ObjectModel& m, Executor& ex) : model_ptr(&m), executor_ptr(&ex) {
    const DofMap& dm = m.dofs();
    const int ne = m.num_elements();
    gather.resize(std::size_t(ne));
    rest.resize(std::size_t(ne));
    for (int e = 0; e < ne; ++e) {
      for (int a = 0; a < 8; ++a) {
        const int s = 8 * e + a;
        for (int i = dm.slot_begin[std::size_t(s)]; i < dm.slot_begin[std::size_t(s) + 1]; ++i)
          gather[std::size_t(e)].push_back({a, dm.slot_dof[std::size_t(i)], dm.slot_weight[std::size_t(i)]});
        rest[std::size_t(e)].segment<3>(3 * a) = m.slot_rest()[std::size_t(s)];
      }
    }
  }

  Mat24 element_k(int e) const { return model().stiffness_scale()[std::size_t(e)] * model().unit_stiffness(); }

  // Adds the element vectors (num_elements x 24) into a DOF vector through P^T, in a fixed order.
  void gather_vectors(const std::vector<Vec24>& fe, VecX& f) const {
    f.setZero(3 * model().num_dofs());
    for (std::size_t e = 0; e < gather.size(); ++e)
      for (const GatherEntry& g : gather[e]) f.segment<3>(3 * g.dof) += g.w * fe[e].segment<3>(3 * g.corner);
  }

  // Scatters a DOF vector to element slots: v_e = (P v) restricted to element e.
  Vec24 element_vector(int e, const VecX& v) const {
    Vec24 out = Vec24::Zero();
    for (const GatherEntry& g : gather[std::size_t(e)]) out.segment<3>(3 * g.corner) += g.w * v.segment<3>(3 * g.dof);
    return out;
  }

  void build_pattern(const std::vector<char>& constrained) {
    const int nd = model().num_dofs();
    const int ne = model().num_elements();
    // Block structure first (3 x 3 blocks of DOF pairs), in flat arrays: the free DOFs each element couples, sorted
    // and unique (elem_ptr, elem_dof), the elements of each DOF (dof_ptr, dof_elem), and per block column the sorted
    // block rows (col_ptr, col_row), the union of its elements' DOFs. Every diagonal block is present, constrained
    // DOFs included.
    std::vector<int> elem_ptr(std::size_t(ne) + 1), elem_dof;
    std::size_t gathered = 0;
    for (const auto& g : gather) gathered += g.size();
    elem_dof.reserve(gathered);
    std::vector<int> dof_ptr(std::size_t(nd) + 1, 0);
    for (int e = 0; e < ne; ++e) {
      const std::size_t b = elem_dof.size();
      elem_ptr[std::size_t(e)] = int(b);
      for (const GatherEntry& p : gather[std::size_t(e)])
        if (!constrained[std::size_t(p.dof)]) elem_dof.push_back(p.dof);
      std::sort(elem_dof.begin() + std::ptrdiff_t(b), elem_dof.end());
      elem_dof.erase(std::unique(elem_dof.begin() + std::ptrdiff_t(b), elem_dof.end()), elem_dof.end());
      for (std::size_t i = b; i < elem_dof.size(); ++i) ++dof_ptr[std::size_t(elem_dof[i]) + 1];
    }
    elem_ptr[std::size_t(ne)] = int(elem_dof.size());
    for (int d = 0; d < nd; ++d) dof_ptr[std::size_t(d) + 1] += dof_ptr[std::size_t(d)];
    std::vector<int> dof_elem(elem_dof.size());
    {
      std::vector<int> fill(dof_ptr.begin(), dof_ptr.end() - 1);
      for (int e = 0; e < ne; ++e)
        for (int i = elem_ptr[std::size_t(e)]; i < elem_ptr[std::size_t(e) + 1]; ++i)
          dof_elem[std::size_t(fill[std::size_t(elem_dof[std::size_t(i)])]++)] = e;
    }
    std::vector<int> col_ptr(std::size_t(nd) + 1), col_row;
    col_row.reserve(elem_dof.size() * 8 + std::size_t(nd));
    {
      std::vector<int> mark(std::size_t(nd), -1);  // mark[j] == k: j is already a row of column k
      for (int k = 0; k < nd; ++k) {
        const std::size_t b = col_row.size();
        col_ptr[std::size_t(k)] = int(b);
        col_row.push_back(k);
        mark[std::size_t(k)] = k;
        for (int t = dof_ptr[std::size_t(k)]; t < dof_ptr[std::size_t(k) + 1]; ++t) {
          const int e = dof_elem[std::size_t(t)];
          for (int i = elem_ptr[std::size_t(e)]; i < elem_ptr[std::size_t(e) + 1]; ++i) {
            const int j = elem_dof[std::size_t(i)];
            if (mark[std::size_t(j)] != k) {
              mark[std::size_t(j)] = k;
              col_row.push_back(j);
            }
          }
        }
        std::sort(col_row.begin() + std::ptrdiff_t(b), col_row.end());
      }
      col_ptr[std::size_t(nd)] = int(col_row.size());
    }
    // Scalar CSC: column 3k + c holds rows 3j, 3j + 1, 3j + 2 for every block row j of block column k; it starts at
    // 9 col_ptr[k] + 3 c len(k). Filled in parallel by block column (disjoint ranges).
    const std::size_t nnz = 9 * col_row.size();
    if (pattern.rows() != 3 * nd || pattern.cols() != 3 * nd) pattern = SpMat(3 * nd, 3 * nd);
    pattern.resizeNonZeros(Eigen::Index(nnz));
    int* outer = pattern.outerIndexPtr();
    int* inner = pattern.innerIndexPtr();
    double* values = pattern.valuePtr();
    diag_offsets.resize(3 * std::size_t(nd));
    executor_ptr->parallel_for(nd, 256, [&](int kb, int ke) {
      for (int k = kb; k < ke; ++k) {
        const int b = col_ptr[std::size_t(k)], len = col_ptr[std::size_t(k) + 1] - b;
        const int* rows = col_row.data() + b;
        const int diag = 3 * int(std::lower_bound(rows, rows + len, k) - rows);
        int at = 9 * b;
        std::fill(values + at, values + at + 9 * len, 0.0);
        for (int c = 0; c < 3; ++c) {
          outer[3 * k + c] = at;
          diag_offsets[3 * std::size_t(k) + std::size_t(c)] = at + diag + c;
          for (int t = b; t < b + len; ++t) {
            const int j = col_row[std::size_t(t)];
            inner[at++] = 3 * j;
            inner[at++] = 3 * j + 1;
            inner[at++] = 3 * j + 2;
          }
        }
      }
    });
    outer[3 * nd] = int(nnz);

    // Offsets: the entry of block (j, k) in column 3k + c is outer[3k + c] + 3 pos(j in column k). Positions come
    // from one merge walk per (element, free DOF) instead of a search per entry. Independent per element: parallel.
    const int* out_ptr = pattern.outerIndexPtr();
    pair_begin.resize(std::size_t(ne) + 1);
    std::size_t pairs = 0;
    for (int e = 0; e < ne; ++e) {
      pair_begin[std::size_t(e)] = pairs;
      pairs += 3 * gather[std::size_t(e)].size() * gather[std::size_t(e)].size();
    }
    pair_begin[std::size_t(ne)] = pairs;
    pair_offsets.resize(pairs);
    executor_ptr->parallel_for(ne, kGrain, [&](int eb, int ee) {
      std::vector<int> local;  // index in the element's DOF list of each gather entry, -1 when constrained
      std::vector<int> pos;    // pos[a * n + b]: position of DOF b in block column a (element-local indices)
      for (int e = eb; e < ee; ++e) {
        const auto& g = gather[std::size_t(e)];
        const int* u = elem_dof.data() + elem_ptr[std::size_t(e)];
        const std::size_t n = std::size_t(elem_ptr[std::size_t(e) + 1] - elem_ptr[std::size_t(e)]);
        pos.resize(n * n);
        for (std::size_t a2 = 0; a2 < n; ++a2) {
          const int* r = col_row.data() + col_ptr[std::size_t(u[a2])];
          std::size_t i = 0;
          for (std::size_t b2 = 0; b2 < n; ++b2) {
            while (r[i] < u[b2]) ++i;
            pos[a2 * n + b2] = int(i);
          }
        }
        local.resize(g.size());
        for (std::size_t i = 0; i < g.size(); ++i)
          local[i] = constrained[std::size_t(g[i].dof)] ? -1 : int(std::lower_bound(u, u + n, g[i].dof) - u);
        int* off = pair_offsets.data() + pair_begin[std::size_t(e)];
        for (std::size_t pi = 0; pi < g.size(); ++pi)
          for (std::size_t qi = 0; qi < g.size(); ++qi, off += 3) {
            if (local[pi] < 0 || local[qi] < 0) {
              off[0] = off[1] = off[2] = -1;
              continue;
            }
            const int k = g[qi].dof;
            const int p3 = 3 * pos[std::size_t(local[qi]) * n + std::size_t(local[pi])];
            for (int c = 0; c < 3; ++c) off[c] = out_ptr[3 * k + c] + p3;
          }
      }
    });
    pattern_constrained = constrained;
    have_pattern = true;
  }

  SpMat pattern;
};

FemSystem::FemSystem(const ObjectModel& model, Executor& executor)
    : m_impl(std::make_unique<Impl>(model, executor)) {}
FemSystem::~FemSystem() = default;

void FemSystem::rebind(const ObjectModel& model, Executor& executor) {
  m_impl->model_ptr = &model;
  m_impl->executor_ptr = &executor;
}

void FemSystem::prolong(const std::vector<Vec3>& dofs, std::vector<Vec3>& slots) const {
  m_impl->model().dofs().prolong(dofs, slots);
}

void FemSystem::rotations(const std::vector<Vec3>& x, ElementFrame& frame) const {
  const ObjectModel& m = m_impl->model();
  std::vector<Vec3> slots;
  prolong(x, slots);
  frame.rotation.resize(std::size_t(m.num_elements()));
  m_impl->executor_ptr->parallel_for(m.num_elements(), kGrain, [&](int b, int en) {
    Vec24 xe;
    Eigen::Matrix<double, 3, 8> xm;
    for (int e = b; e < en; ++e) {
      element_slots(slots, e, xe, xm);
      frame.rotation[std::size_t(e)] = polar_rotation(hex_center_gradient(xm, m.edge()[std::size_t(e)]));
    }
  });
}

void FemSystem::force_and_product(const std::vector<Vec3>& x, const ElementFrame& frame, const VecX& v, VecX& f,
                                  VecX& kv) const {
  const ObjectModel& m = m_impl->model();
  const int ne = m.num_elements();
  std::vector<Vec3> slots;
  prolong(x, slots);
  const bool want_kv = v.size() == 3 * m.num_dofs();
  std::vector<Vec24> fe(static_cast<std::size_t>(ne)), kve(want_kv ? std::size_t(ne) : 0);
  m_impl->executor_ptr->parallel_for(ne, kGrain, [&](int b, int en) {
    Vec24 xe;
    Eigen::Matrix<double, 3, 8> xm;
    for (int e = b; e < en; ++e) {
      element_slots(slots, e, xe, xm);
      const Mat3& R = frame.rotation[std::size_t(e)];
      const Mat24 K = m_impl->element_k(e);
      fe[std::size_t(e)] = corotated_force(K, R, xe, m_impl->rest[std::size_t(e)]);
      if (want_kv) {
        // K_rot v = R K R^T v, applied block-wise without forming K_rot.
        const Vec24 ve = m_impl->element_vector(e, v);
        Vec24 local;
        for (int a = 0; a < 8; ++a) local.segment<3>(3 * a) = R.transpose() * ve.segment<3>(3 * a);
        const Vec24 kl = K * local;
        for (int a = 0; a < 8; ++a) kve[std::size_t(e)].segment<3>(3 * a) = R * kl.segment<3>(3 * a);
      }
    }
  });
  m_impl->gather_vectors(fe, f);
  if (want_kv) m_impl->gather_vectors(kve, kv);
}

void FemSystem::elastic_force(const std::vector<Vec3>& x, const ElementFrame& frame, VecX& f) const {
  VecX none, kv;
  force_and_product(x, frame, none, f, kv);
}

double FemSystem::elastic_energy(const std::vector<Vec3>& x, const ElementFrame& frame) const {
  const ObjectModel& m = m_impl->model();
  std::vector<Vec3> slots;
  prolong(x, slots);
  double energy = 0.0;
  Vec24 xe;
  Eigen::Matrix<double, 3, 8> xm;
  for (int e = 0; e < m.num_elements(); ++e) {
    element_slots(slots, e, xe, xm);
    const Mat3& R = frame.rotation[std::size_t(e)];
    const Vec24 u = corotated_displacement(R, xe, m_impl->rest[std::size_t(e)]);
    energy += 0.5 * u.dot(m_impl->element_k(e) * u);
  }
  return energy;
}

SpMat FemSystem::stiffness(const ElementFrame& frame) const {
  const ObjectModel& m = m_impl->model();
  std::vector<Eigen::Triplet<double>> t;
  for (int e = 0; e < m.num_elements(); ++e) {
    const Mat24 Ke = corotated_stiffness(m_impl->element_k(e), frame.rotation[std::size_t(e)]);
    for (const GatherEntry& p : m_impl->gather[std::size_t(e)])
      for (const GatherEntry& q : m_impl->gather[std::size_t(e)])
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c)
            t.emplace_back(3 * p.dof + r, 3 * q.dof + c, p.w * q.w * Ke(3 * p.corner + r, 3 * q.corner + c));
  }
  SpMat K(3 * m.num_dofs(), 3 * m.num_dofs());
  K.setFromTriplets(t.begin(), t.end());
  return K;
}

void FemSystem::stiffness_product(const ElementFrame& frame, const VecX& v, VecX& out) const {
  const ObjectModel& m = m_impl->model();
  std::vector<Vec24> ke(std::size_t(m.num_elements()));
  m_impl->executor_ptr->parallel_for(m.num_elements(), kGrain, [&](int b, int en) {
    for (int e = b; e < en; ++e)
      ke[std::size_t(e)] =
          corotated_stiffness(m_impl->element_k(e), frame.rotation[std::size_t(e)]) * m_impl->element_vector(e, v);
  });
  m_impl->gather_vectors(ke, out);
}

const SpMat& FemSystem::system_pattern(const std::vector<char>& constrained) {
  Impl& im = *m_impl;
  if (!im.have_pattern || im.pattern_constrained != constrained) im.build_pattern(constrained);
  return im.pattern;
}

void FemSystem::assemble_system(double mc, double kc, const ElementFrame& frame,
                                const std::vector<char>& constrained, const VecX& u, SpMat& A, VecX& coupling) {
  Impl& im = *m_impl;
  const ObjectModel& m = im.model();
  const int ne = m.num_elements();
  const int nd = m.num_dofs();
  if (!im.have_pattern || im.pattern_constrained != constrained) {
    im.build_pattern(constrained);
    A = im.pattern;
  }
  if (A.nonZeros() != im.pattern.nonZeros()) A = im.pattern;

  // Rotated element stiffness, in parallel (independent per element).
  im.rotated.resize(std::size_t(ne) * 576);
  im.executor_ptr->parallel_for(ne, kGrain, [&](int b, int en) {
    for (int e = b; e < en; ++e) {
      Eigen::Map<Mat24> out(im.rotated.data() + 576 * std::size_t(e));
      out = corotated_stiffness(kc * im.element_k(e), frame.rotation[std::size_t(e)]);
    }
  });

  // Scatter in a fixed element order: deterministic sums.
  double* val = A.valuePtr();
  std::fill(val, val + A.nonZeros(), 0.0);
  coupling.setZero(3 * nd);
  for (int e = 0; e < ne; ++e) {
    const Eigen::Map<const Mat24> Ke(im.rotated.data() + 576 * std::size_t(e));
    const auto& g = im.gather[std::size_t(e)];
    const int* off = im.pair_offsets.data() + im.pair_begin[std::size_t(e)];
    for (const GatherEntry& p : g) {
      for (const GatherEntry& q : g) {
        const double w = p.w * q.w;
        if (off[0] >= 0) {
          for (int c = 0; c < 3; ++c) {
            double* dst = val + off[c];
            dst[0] += w * Ke(3 * p.corner + 0, 3 * q.corner + c);
            dst[1] += w * Ke(3 * p.corner + 1, 3 * q.corner + c);
            dst[2] += w * Ke(3 * p.corner + 2, 3 * q.corner + c);
          }
        } else if (!constrained[std::size_t(p.dof)]) {
          // Free row, prescribed column: moves to the right-hand side.
          coupling.segment<3>(3 * p.dof) +=
              w * Ke.block<3, 3>(3 * p.corner, 3 * q.corner) * u.segment<3>(3 * q.dof);
        }
        off += 3;
      }
    }
  }

  // Lumped mass on the diagonal; identity rows for constrained DOFs.
  for (int d = 0; d < nd; ++d) {
    for (int c = 0; c < 3; ++c) {
      const int i = 3 * d + c;
      if (constrained[std::size_t(d)]) {
        val[im.diag_offsets[std::size_t(i)]] = 1.0;
      } else {
        val[im.diag_offsets[std::size_t(i)]] += mc * m.dof_mass()[std::size_t(d)];
      }
    }
  }
}

// ---- Simulator -------------------------------------------------------------------------------------------------------

namespace {
// 1 for the DOFs a handle drives (num_dofs).
std::vector<char> constrained_flags(const ObjectModel& m) {
  std::vector<char> c(std::size_t(m.num_dofs()), 0);
  for (int d = 0; d < m.num_dofs(); ++d) c[std::size_t(d)] = m.dof_handle()[std::size_t(d)] >= 0;
  return c;
}
}  // namespace

Simulator::Simulator(ObjectModel model, const SimulatorOptions& options)
    : m_model(std::move(model)), m_options(options) {
  if (!(options.dt > 0.0)) throw std::invalid_argument("Simulator: dt must be positive");
  m_executor = std::make_unique<Executor>(options.threads);
  m_solver = make_solver();
  m_state = SimState::rest(m_model);
  rebuild();
}

Simulator::~Simulator() = default;

void Simulator::rebuild() {
  m_fem = std::make_unique<FemSystem>(m_model, *m_executor);
  m_constrained = constrained_flags(m_model);
  m_A = SpMat();
  m_pattern_analyzed = false;
  m_dv_prev = VecX::Zero(3 * m_model.num_dofs());
}

void Simulator::set_model(ObjectModel model) {
  SimState s = transfer_state(m_model, m_state, model);
  m_model = std::move(model);
  m_state = std::move(s);
  rebuild();
}

void Simulator::refresh_solver() {
  if (m_model.num_dofs() == 0) return;
  // The pattern is all the symbolic analysis needs. m_A stays empty: the next step's assembly copies the pattern
  // into it with the values.
  m_solver->analyze_pattern(m_fem->system_pattern(m_constrained));
  m_pattern_analyzed = true;
}

std::unique_ptr<LinearSolver> Simulator::make_solver() const {
  LinearSolverOptions lo;
  lo.tolerance = m_options.tolerance;
  lo.max_iterations = m_options.max_iterations;
  lo.preconditioner = m_options.preconditioner;
  lo.threads = m_executor->threads();
  return make_linear_solver(m_options.linear_solver, lo);
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
};

PreparedModel::PreparedModel() = default;
PreparedModel::PreparedModel(PreparedModel&&) noexcept = default;
PreparedModel& PreparedModel::operator=(PreparedModel&&) noexcept = default;
PreparedModel::~PreparedModel() = default;
const ObjectModel& PreparedModel::model() const {
  if (!m_impl) throw std::logic_error("PreparedModel::model: empty");
  return *m_impl->model;
}

PreparedModel Simulator::prepare_model(ObjectModel model, bool analyze) const {
  PreparedModel out;
  out.m_impl = std::make_unique<PreparedModel::Impl>();
  PreparedModel::Impl& p = *out.m_impl;
  p.state = transfer_state(m_model, m_state, model);
  p.model = std::make_unique<ObjectModel>(std::move(model));
  p.fem = std::make_unique<FemSystem>(*p.model, *p.serial);
  p.constrained = constrained_flags(*p.model);
  p.solver = make_solver();
  if (analyze && p.model->num_dofs() > 0) {
    try {
      p.solver->analyze_pattern(p.fem->system_pattern(p.constrained));
      p.analyzed = true;
    } catch (const std::exception&) {
      // The next step analyses the pattern again, and its guards handle a solver failure.
    }
  }
  return out;
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
  m_fem = std::move(p.fem);
  m_fem->rebind(m_model, *m_executor);
  m_constrained = std::move(p.constrained);
  m_solver = std::move(p.solver);
  m_A = SpMat();
  m_pattern_analyzed = p.analyzed;
  m_dv_prev = std::move(dv_prev);
}

void Simulator::set_state(SimState state) {
  if (int(state.x.size()) != m_model.num_dofs() || state.v.size() != state.x.size())
    throw std::invalid_argument("Simulator::set_state: state does not match the model");
  m_state = std::move(state);
}

namespace {
VecX flatten(const std::vector<Vec3>& v) {
  VecX out(3 * Eigen::Index(v.size()));
  for (std::size_t i = 0; i < v.size(); ++i) out.segment<3>(3 * Eigen::Index(i)) = v[i];
  return out;
}
}  // namespace

bool Simulator::try_dynamic_step(double dt) {
  const ObjectModel& m = m_model;
  const int nd = m.num_dofs();
  const double t1 = m_state.t + dt;
  const double alpha = m.params().rayleigh_mass, beta = m.params().rayleigh_stiffness;

  // Prescribed velocity increments of handle DOFs, so that they reach the handle pose at t + dt.
  VecX v = flatten(m_state.v);
  VecX dv_c = VecX::Zero(3 * nd);
  std::vector<Vec3> target(static_cast<std::size_t>(nd));
  for (int d = 0; d < nd; ++d) {
    if (!m_constrained[std::size_t(d)]) continue;
    target[std::size_t(d)] = m.handle_position(d, t1);
    const Vec3 vn = (target[std::size_t(d)] - m_state.x[std::size_t(d)]) / dt;
    dv_c.segment<3>(3 * d) = vn - m_state.v[std::size_t(d)];
  }

  // Forces at x: elastic, K v, gravity.
  using Clock = std::chrono::steady_clock;
  auto lap = [t = Clock::now()]() mutable {
    const auto now = Clock::now();
    const double ms = std::chrono::duration<double, std::milli>(now - t).count();
    t = now;
    return ms;
  };
  ElementFrame frame;
  m_fem->rotations(m_state.x, frame);
  m_profile.rotations = lap();
  VecX f_el, kv;
  m_fem->force_and_product(m_state.x, frame, v, f_el, kv);
  m_profile.forces = lap();

  // (M + dt C + dt^2 K) dv = dt (f_ext + f_el - C v - dt K v), with C = alpha M + beta K.
  VecX rhs(3 * nd);
  for (int d = 0; d < nd; ++d) {
    const double md = m.dof_mass()[std::size_t(d)];
    const Vec3 f = md * m_options.gravity + f_el.segment<3>(3 * d) - alpha * md * v.segment<3>(3 * d) -
                   (beta + dt) * kv.segment<3>(3 * d);
    rhs.segment<3>(3 * d) = dt * f;
  }
  VecX coupling;
  m_fem->assemble_system(1.0 + dt * alpha, dt * beta + dt * dt, frame, m_constrained, dv_c, m_A, coupling);
  rhs -= coupling;
  for (int d = 0; d < nd; ++d)
    if (m_constrained[std::size_t(d)]) rhs.segment<3>(3 * d) = dv_c.segment<3>(3 * d);
  m_profile.assembly = lap();

  // Solve; the symbolic analysis is reused for the whole revision.
  if (!m_pattern_analyzed) {
    m_solver->analyze_pattern(m_A);
    m_pattern_analyzed = true;
  }
  if (!m_solver->factorize(m_A)) {
    ++m_stats.solver_failures;
    return false;
  }
  VecX dv = m_dv_prev;
  m_last_solve = m_solver->solve(rhs, dv);
  m_profile.solve = lap();
  if (!m_last_solve.ok) {
    ++m_stats.solver_failures;
    return false;
  }
  if (!dv.allFinite()) {
    ++m_stats.nonfinite;
    return false;
  }

  // New state, checked before it is committed.
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
  m_state.t = t1;
  m_dv_prev = dv;
  return true;
}

void Simulator::step() {
  const double dt = m_options.dt;
  if (!m_options.dynamic) {
    if (!solve_static(m_state.t + dt)) ++m_stats.newton_unconverged;  // sets t
    return;
  }
  const SimState start = m_state;
  // An attempt that fails is rolled back and its interval retried as two halves, each of which may halve again,
  // down to dt / 2^max_halvings.
  std::function<bool(double, int)> advance = [&](double h, int depth) {
    const SimState before = m_state;
    if (try_dynamic_step(h)) return true;
    m_state = before;
    m_dv_prev.setZero();
    if (depth >= m_options.max_halvings) return false;
    return advance(0.5 * h, depth + 1) && advance(0.5 * h, depth + 1);
  };
  const int failures_before = m_stats.nonfinite + m_stats.speed_limit + m_stats.solver_failures;
  if (advance(dt, 0)) {
    if (m_stats.nonfinite + m_stats.speed_limit + m_stats.solver_failures > failures_before) ++m_stats.recoveries;
    return;
  }
  // Defined reset: positions of the step's start, velocities zero, handles at their pose at t + dt.
  ++m_stats.failed_steps;
  m_state = start;
  m_state.t = start.t + dt;
  for (int d = 0; d < m_model.num_dofs(); ++d) {
    m_state.v[std::size_t(d)].setZero();
    if (m_constrained[std::size_t(d)]) {
      m_state.x[std::size_t(d)] = m_model.handle_position(d, m_state.t);
    }
  }
}

bool Simulator::solve_static(double t) {
  const ObjectModel& m = m_model;
  const int nd = m.num_dofs();
  std::vector<Vec3> x = m_state.x;
  for (int d = 0; d < nd; ++d) {
    if (!m_constrained[std::size_t(d)]) continue;
    x[std::size_t(d)] = m.handle_position(d, t);
  }
  VecX f_ext = VecX::Zero(3 * nd);
  for (int d = 0; d < nd; ++d)
    if (!m_constrained[std::size_t(d)]) f_ext.segment<3>(3 * d) = m.dof_mass()[std::size_t(d)] * m_options.gravity;

  // Residual r = f_el(x) + f_ext on free DOFs.
  ElementFrame frame;
  auto residual = [&](const std::vector<Vec3>& xs, VecX& r) {
    m_fem->rotations(xs, frame);
    m_fem->elastic_force(xs, frame, r);
    r += f_ext;
    for (int d = 0; d < nd; ++d)
      if (m_constrained[std::size_t(d)]) r.segment<3>(3 * d).setZero();
    return r.norm();
  };
  VecX r;
  double rn = residual(x, r);
  const double scale = std::max({f_ext.norm(), rn, 1e-300});
  const VecX zero = VecX::Zero(3 * nd);
  bool converged = false;
  int allowance = 2;
  for (int it = 0; it < m_options.max_iterations; ++it) {
    if (!(rn / scale > m_options.tolerance)) {
      converged = std::isfinite(rn);
      break;
    }
    // Newton direction with the corotated tangent K dx = r (constrained rows identity, dx_c = 0).
    VecX coupling;
    m_fem->assemble_system(0.0, 1.0, frame, m_constrained, zero, m_A, coupling);
    if (!m_pattern_analyzed) {
      m_solver->analyze_pattern(m_A);
      m_pattern_analyzed = true;
    }
    VecX dx = VecX::Zero(3 * nd);
    if (!m_solver->factorize(m_A) || !(m_last_solve = m_solver->solve(r, dx)).ok || !dx.allFinite()) {
      ++m_stats.solver_failures;
      break;
    }
    // Backtracking on the residual norm: the tangent ignores dR/dx, so a full step may overshoot.
    double step = 1.0;
    std::vector<Vec3> xt(x.size());
    VecX rt;
    double rtn = 0.0;
    for (int ls = 0; ls < 8; ++ls, step *= 0.5) {
      for (int d = 0; d < nd; ++d) xt[std::size_t(d)] = x[std::size_t(d)] + step * dx.segment<3>(3 * d);
      rtn = residual(xt, rt);
      // Accept a decrease; allow a bounded number of moderate increases, since the corotated tangent omits the
      // geometric stiffness and a correct full step may raise the residual of a stiff, loaded body.
      if (std::isfinite(rtn) && rtn < rn) break;
      if (std::isfinite(rtn) && rtn < 4.0 * rn && allowance > 0) {
        --allowance;
        break;
      }
    }
    if (!std::isfinite(rtn)) {
      ++m_stats.nonfinite;
      break;
    }
    x = xt;
    r = rt;
    rn = rtn;
  }
  if (converged || std::isfinite(rn)) {
    m_state.x = x;
    for (auto& vv : m_state.v) vv.setZero();
  }
  m_state.t = t;
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
