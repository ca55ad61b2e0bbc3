#include "octocut/sim/linear_solver.hpp"

#include <cholmod.h>

#include "octocut/sim/parallel.hpp"
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace octocut::sim {

namespace {

// Supernodal LL^T through CHOLMOD, called directly so that the symbolic analysis can run on the block graph. The
// FEM system matrix is made of dense 3 x 3 blocks (one per pair of coupled DOFs). Its fill-reducing ordering (AMD)
// and its supernodal symbolic factorisation are computed on the graph of blocks (num_dofs nodes, 9x fewer entries
// than the scalar pattern) and then expanded: block column p becomes scalar columns 3p, 3p + 1, 3p + 2, every
// supernode keeps its blocks, every row index r becomes 3r, 3r + 1, 3r + 2. With dense blocks the scalar factor has
// exactly the expanded pattern, so the numeric factorisation and the solves are CHOLMOD's, unchanged. (The default
// analysis, on the scalar pattern with AMD, then METIS and NESDIS, took 9 ms for 9k unknowns; SPEC §4 stage 5 runs
// it after every cut.) A pattern that is not 3 x 3 blocked is analysed the same way with blocks of one.
class CholmodFactor {
 public:
  CholmodFactor() {
    for (cholmod_common* c : {&m_c, &m_cb}) {
      cholmod_start(c);
      c->print = 0;  // a failed factorisation is reported through SolveInfo and counted by the caller
    }
    // The block analysis: AMD, weighted postorder, supernodal.
    m_cb.supernodal = CHOLMOD_SUPERNODAL;
    m_cb.nmethods = 1;
    m_cb.method[0].ordering = CHOLMOD_AMD;
    m_cb.postorder = 1;
    m_default_nrelax[0] = m_cb.nrelax[0];
    m_default_nrelax[1] = m_cb.nrelax[1];
    m_default_nrelax[2] = m_cb.nrelax[2];
  }
  ~CholmodFactor() {
    free_factor();
    if (m_x) cholmod_free_dense(&m_x, &m_c);
    if (m_y) cholmod_free_dense(&m_y, &m_c);
    if (m_e) cholmod_free_dense(&m_e, &m_c);
    cholmod_finish(&m_cb);
    cholmod_finish(&m_c);
  }
  CholmodFactor(const CholmodFactor&) = delete;
  CholmodFactor& operator=(const CholmodFactor&) = delete;

  /// Orders and analyses the pattern of A (both triangles stored). Throws when CHOLMOD fails.
  void analyze(const SpMat& A) {
    free_factor();
    m_block = blocked3(A) ? 3 : 1;
    const int block = m_block;
    const int n = int(A.rows());
    const int nb = n / block;
    const int* p = A.outerIndexPtr();
    const int* i = A.innerIndexPtr();

    // Block pattern, both triangles: the block rows of block column k are every block-th row of scalar column
    // block k.
    std::vector<int> bp(static_cast<std::size_t>(nb) + 1), bi;
    bi.reserve(std::size_t(A.nonZeros()) / std::size_t(block * block));
    for (int k = 0; k < nb; ++k) {
      bp[std::size_t(k)] = int(bi.size());
      for (int t = p[block * k]; t < p[block * k + 1]; t += block) bi.push_back(i[t] / block);
    }
    bp[std::size_t(nb)] = int(bi.size());
    cholmod_sparse g = symmetric(nb, std::max<std::size_t>(bi.size(), 1), bp.data(), bi.data(), nullptr);

    // Ordering and supernodal symbolic factorisation of the block graph. Supernode amalgamation thresholds count
    // columns: scaled to blocks so that the scalar supernodes come out about as wide as a scalar analysis makes them.
    for (int r = 0; r < 3; ++r)
      m_cb.nrelax[r] = std::max<std::size_t>(1, m_default_nrelax[r] / std::size_t(block));
    cholmod_factor* Lb = cholmod_analyze(&g, &m_cb);
    if (Lb == nullptr || m_cb.status < CHOLMOD_OK || !Lb->is_super) {
      if (Lb) cholmod_free_factor(&Lb, &m_cb);
      throw std::runtime_error("CHOLMOD symbolic analysis failed (status " + std::to_string(m_cb.status) + ")");
    }
    expand(*Lb, block, n);
    cholmod_free_factor(&Lb, &m_cb);
  }
  /// Numeric factorisation of A (pattern as analysed). False when A is not positive definite.
  bool factorize(const SpMat& A) {
    if (m_L == nullptr) return false;
    cholmod_sparse a = view(A);
    cholmod_factorize(&a, m_L, &m_c);
    return m_c.status >= CHOLMOD_OK && m_L->minor == m_L->n;
  }
  /// x = A^-1 b with the last factor. False when CHOLMOD fails.
  bool solve(const VecX& b, VecX& x) {
    if (m_L == nullptr) return false;
    cholmod_dense bd{};
    bd.nrow = std::size_t(b.size());
    bd.ncol = 1;
    bd.nzmax = bd.nrow;
    bd.d = bd.nrow;
    bd.x = const_cast<double*>(b.data());
    bd.xtype = CHOLMOD_REAL;
    bd.dtype = CHOLMOD_DOUBLE;
    // The workspaces X, Y, E are kept between calls (no allocation per solve).
    if (!cholmod_solve2(CHOLMOD_A, m_L, &bd, nullptr, &m_x, nullptr, &m_y, &m_e, &m_c) || m_x == nullptr) return false;
    x = Eigen::Map<const VecX>(static_cast<const double*>(m_x->x), b.size());
    return true;
  }
  /// Block size of the graph the last ordering was computed on: 3 (FEM system) or 1 (scalar pattern).
  [[nodiscard]] int block_size() const { return m_block; }
  /// Floating-point operations of one numeric factorisation, sum over columns of count^2 (0 before analyze).
  [[nodiscard]] double factor_flops() const { return m_factor_flops; }
  /// Entries of L, sum over columns of count (0 before analyze).
  [[nodiscard]] double factor_entries() const { return m_factor_entries; }

 private:
  void free_factor() {
    if (m_L) cholmod_free_factor(&m_L, &m_c);
    m_L = nullptr;
  }

  // A square, compressed, sorted CSC matrix with int indices (n columns, nzmax entries) as a symmetric CHOLMOD
  // matrix whose lower triangle is read; a pattern when x is null.
  static cholmod_sparse symmetric(int n, std::size_t nzmax, const int* p, const int* i, const double* x) {
    cholmod_sparse a{};
    a.nrow = a.ncol = std::size_t(n);
    a.nzmax = nzmax;
    a.p = const_cast<int*>(p);
    a.i = const_cast<int*>(i);
    a.x = const_cast<double*>(x);
    a.stype = -1;
    a.itype = CHOLMOD_INT;
    a.xtype = x ? CHOLMOD_REAL : CHOLMOD_PATTERN;
    a.dtype = CHOLMOD_DOUBLE;
    a.sorted = 1;
    a.packed = 1;
    return a;
  }
  // A view of A (compressed, sorted, int indices, square).
  static cholmod_sparse view(const SpMat& A) {
    return symmetric(int(A.cols()), std::size_t(A.nonZeros()), A.outerIndexPtr(), A.innerIndexPtr(), A.valuePtr());
  }

  // True when A's pattern is made of full 3 x 3 blocks: columns 3k, 3k + 1, 3k + 2 hold the same rows, and these
  // come in runs 3j, 3j + 1, 3j + 2.
  static bool blocked3(const SpMat& A) {
    if (!A.isCompressed() || A.rows() != A.cols() || A.rows() % 3 != 0) return false;
    const int* p = A.outerIndexPtr();
    const int* i = A.innerIndexPtr();
    const int nb = int(A.cols() / 3);
    for (int k = 0; k < nb; ++k) {
      const int b = p[3 * k], len = p[3 * k + 1] - b;
      if (len % 3 != 0 || p[3 * k + 2] - p[3 * k + 1] != len || p[3 * k + 3] - p[3 * k + 2] != len) return false;
      for (int t = 0; t < len; t += 3)
        if (i[b + t] % 3 != 0 || i[b + t + 1] != i[b + t] + 1 || i[b + t + 2] != i[b + t] + 2) return false;
      if (!std::equal(i + b, i + b + len, i + b + len) || !std::equal(i + b, i + b + len, i + b + 2 * len))
        return false;
    }
    return true;
  }

  // Builds the scalar supernodal symbolic factor from the block one (see the class comment), the way
  // cholmod_super_symbolic fills it: Perm, ColCount, super, pi, px, s, maxcsize, maxesize.
  void expand(const cholmod_factor& Lb, int block, int n) {
    const int nsuper = int(Lb.nsuper);
    const int* bperm = static_cast<const int*>(Lb.Perm);
    const int* bsuper = static_cast<const int*>(Lb.super);
    const int* bpi = static_cast<const int*>(Lb.pi);
    const int* bs = static_cast<const int*>(Lb.s);
    m_L = cholmod_allocate_factor(std::size_t(n), &m_c);
    if (m_L == nullptr) throw std::runtime_error("CHOLMOD: out of memory in the symbolic analysis");
    std::size_t ssize = 0, xsize = 0;
    for (int s = 0; s < nsuper; ++s) {
      const std::size_t nscol = std::size_t(block) * std::size_t(bsuper[s + 1] - bsuper[s]);
      const std::size_t nsrow = std::size_t(block) * std::size_t(bpi[s + 1] - bpi[s]);
      ssize += nsrow;
      xsize += nscol * nsrow;
    }
    m_L->ordering = CHOLMOD_GIVEN;
    m_L->nsuper = std::size_t(nsuper);
    m_L->ssize = std::max<std::size_t>(1, ssize);
    m_L->xsize = std::max<std::size_t>(1, xsize);
    if (!cholmod_change_factor(CHOLMOD_PATTERN, 1, 1, 1, 1, m_L, &m_c) || !m_L->is_super) {
      free_factor();
      throw std::runtime_error("CHOLMOD: out of memory in the symbolic analysis");
    }
    int* perm = static_cast<int*>(m_L->Perm);
    int* count = static_cast<int*>(m_L->ColCount);
    int* super = static_cast<int*>(m_L->super);
    int* pi = static_cast<int*>(m_L->pi);
    int* px = static_cast<int*>(m_L->px);
    int* ls = static_cast<int*>(m_L->s);
    for (int q = 0; q < n / block; ++q)
      for (int c = 0; c < block; ++c) perm[block * q + c] = block * bperm[q] + c;
    std::vector<int> super_map(static_cast<std::size_t>(n));  // supernode of each scalar column
    int at = 0, xat = 0;
    m_factor_entries = m_factor_flops = 0.0;
    for (int s = 0; s < nsuper; ++s) {
      super[s] = block * bsuper[s];
      pi[s] = at;
      px[s] = xat;
      const int nscol = block * (bsuper[s + 1] - bsuper[s]);
      const int nsrow = block * (bpi[s + 1] - bpi[s]);
      for (int t = bpi[s]; t < bpi[s + 1]; ++t)
        for (int c = 0; c < block; ++c) ls[at++] = block * bs[t] + c;
      xat += nscol * nsrow;
      for (int j = super[s]; j < super[s] + nscol; ++j) {
        super_map[std::size_t(j)] = s;
        count[j] = nsrow - (j - super[s]);
        m_factor_entries += double(count[j]);
        m_factor_flops += double(count[j]) * double(count[j]);
      }
    }
    super[nsuper] = n;
    pi[nsuper] = at;
    px[nsuper] = xat;
    // Largest update matrix (rows below a descendant's columns times the rows that fall in one ancestor) and
    // largest off-diagonal row count, as cholmod_super_symbolic defines them.
    int maxcsize = 1, maxesize = 1;
    for (int d = 0; d < nsuper; ++d) {
      const int nscol = super[d + 1] - super[d];
      int q = pi[d] + nscol;
      int plast = q;
      const int pend = pi[d + 1];
      maxesize = std::max(maxesize, pend - q);
      int slast = q == pend ? -1 : super_map[std::size_t(ls[q])];
      for (; q <= pend; ++q) {
        const int s = q == pend ? -1 : super_map[std::size_t(ls[q])];
        if (s != slast) {
          maxcsize = std::max(maxcsize, (pend - plast) * (q - plast));
          plast = q;
          slast = s;
        }
      }
    }
    m_L->maxcsize = std::size_t(maxcsize);
    m_L->maxesize = std::size_t(maxesize);
  }

  cholmod_common m_c{};   ///< the scalar factor's
  cholmod_common m_cb{};  ///< the block analysis'
  std::size_t m_default_nrelax[3] = {4, 16, 48};
  cholmod_factor* m_L = nullptr;
  cholmod_dense* m_x = nullptr;  ///< solve2 workspaces, kept
  cholmod_dense* m_y = nullptr;
  cholmod_dense* m_e = nullptr;
  int m_block = 1;
  double m_factor_flops = 0.0;    ///< of one numeric factorisation
  double m_factor_entries = 0.0;  ///< nnz(L)
};

// Direct solver: supernodal LL^T; the symbolic analysis is reused until the pattern changes.
class CholmodSolver final : public LinearSolver {
 public:
  // A failed factorisation is reported through SolveInfo and counted by the caller, not printed by CHOLMOD.
  explicit CholmodSolver(int threads) : m_threads(threads) {}
  void analyze_pattern(const SpMat& A) override {
    m_ok = false;
    m_llt.analyze(A);
  }
  bool factorize(const SpMat& A) override {
    const BlasThreadsScope blas(m_threads);
    m_ok = m_llt.factorize(A);
    m_A = &A;
    return m_ok;
  }
  SolveInfo solve(const VecX& b, VecX& x) override {
    SolveInfo info;
    info.refactorized = true;
    if (!m_ok || !m_llt.solve(b, x)) return info;
    const double bn = b.norm();
    info.residual = bn > 0.0 ? (b - (*m_A) * x).norm() / bn : 0.0;
    info.ok = x.allFinite() && info.residual < 1e-3;  // catches garbage, not round-off
    return info;
  }
  std::string name() const override { return "cholmod"; }
  int ordering_block_size() const override { return m_llt.block_size(); }

 private:
  CholmodFactor m_llt;
  int m_threads = 1;  ///< BLAS threads while factorising
  const SpMat* m_A = nullptr;
  bool m_ok = false;
};

// Conjugate gradients, warm-started from x, with either a lagged Cholesky factor of an earlier system matrix or
// the diagonal as preconditioner. The lagged factor is refreshed by a rent-or-buy rule. The solve right after a
// factorisation converges in one iteration; the next one, a step later, takes the baseline: what one step's change
// of the matrix (the rotations) costs even with a fresh factor. Every iteration a later solve needs beyond the
// baseline (the fewest since the factorisation) is rent paid for the factor's age, priced in floating-point
// operations: two triangular solves with L, a product with A, five vector updates. A factorisation is the purchase:
// its operations divided by factor_flop_advantage, because its dense supernodal kernels do that many more operations
// per second than the triangular solves. Once the rent paid since the last factorisation reaches the purchase price,
// the next solve refactorises first. When the iteration count grows linearly with the factor's age (an object that
// keeps rotating, contacts that keep changing) this period minimises the mean cost per step; an object whose
// iterations stay at the baseline never pays for a factorisation it would not gain from. The rule counts iterations
// and operations only, so it is deterministic. A solve that does not converge, or would pay more than a
// factorisation in iterations beyond the baseline, refactorises at once and continues from x.
class PcgSolver final : public LinearSolver {
 public:
  explicit PcgSolver(const LinearSolverOptions& o) : m_opt(o), m_use_cholesky(o.preconditioner != "jacobi") {
    if (o.preconditioner != "jacobi" && o.preconditioner != "cholesky")
      throw std::invalid_argument("unknown preconditioner '" + o.preconditioner + "'");
  }
  void analyze_pattern(const SpMat& A) override {
    if (m_use_cholesky) m_llt.analyze(A);
    m_have_factor = false;
  }
  bool factorize(const SpMat& A) override {
    m_A = &A;
    if (!m_use_cholesky) {
      m_inv_diag = A.diagonal();
      for (Eigen::Index i = 0; i < m_inv_diag.size(); ++i) {
        if (!(m_inv_diag[i] > 0.0)) return false;
        m_inv_diag[i] = 1.0 / m_inv_diag[i];
      }
      return true;
    }
    if (!m_have_factor) return refactor();
    return true;
  }
  SolveInfo solve(const VecX& b, VecX& x) override {
    SolveInfo info;
    if (x.size() != b.size() || !x.allFinite()) x = VecX::Zero(b.size());
    if (m_use_cholesky && m_rent >= purchase_price()) {
      if (!refactor()) return info;
      info.refactorized = true;
    }
    // With a lagged factor, a solve that would pay more than a factorisation in iterations stops and buys one.
    // (Once the baseline is known: from the second solve after a factorisation on.)
    int cap = m_opt.max_iterations;
    if (m_use_cholesky && !info.refactorized && m_solves_since_factor >= 2)
      cap = int(std::min<double>(cap, m_baseline + 1.0 + std::floor(purchase_price() / iteration_flops())));
    run_pcg(b, x, info, cap);
    if (!m_use_cholesky) return info;
    pay_rent(info.iterations);
    // Failed or too slow convergence: refresh the lagged factor from the current matrix and continue from x.
    if (!info.ok && !info.refactorized) {
      if (!refactor()) return info;
      info.refactorized = true;
      SolveInfo again;
      run_pcg(b, x, again, m_opt.max_iterations);
      info.ok = again.ok;
      info.iterations += again.iterations;
      info.residual = again.residual;
    }
    return info;
  }
  std::string name() const override { return "pcg"; }
  int ordering_block_size() const override { return m_use_cholesky ? m_llt.block_size() : 0; }

 private:
  bool refactor() {
    const BlasThreadsScope blas(m_opt.threads);
    m_have_factor = m_llt.factorize(*m_A);
    m_rent = 0.0;
    m_solves_since_factor = 0;
    return m_have_factor;
  }
  // Counts the solve's iterations beyond the baseline as rent (see the class comment).
  void pay_rent(int iterations) {
    ++m_solves_since_factor;
    if (m_solves_since_factor == 1) return;  // solved with the factor of its own matrix, or the first solve
    if (m_solves_since_factor == 2 || iterations < m_baseline) m_baseline = iterations;
    m_rent += double(std::max(0, iterations - m_baseline)) * iteration_flops();
  }
  // Operations of one PCG iteration with the factor: solves with L and L^T, a product with A, five vector updates.
  [[nodiscard]] double iteration_flops() const {
    return 4.0 * m_llt.factor_entries() + 2.0 * double(m_A->nonZeros()) + 10.0 * double(m_A->rows());
  }
  // A factorisation's price in iteration operations (see the class comment).
  [[nodiscard]] double purchase_price() const { return m_llt.factor_flops() / m_opt.factor_flop_advantage; }
  void precondition(const VecX& r, VecX& z) {
    if (!m_use_cholesky)
      z = m_inv_diag.cwiseProduct(r);
    else if (!m_llt.solve(r, z))
      z = r;  // CHOLMOD failed (out of memory): an unpreconditioned step
  }
  void run_pcg(const VecX& b, VecX& x, SolveInfo& info, int max_iterations) {
    const SpMat& A = *m_A;
    const double bn = b.norm();
    if (!(bn > 0.0)) {
      x.setZero();
      info.ok = std::isfinite(bn);
      return;
    }
    VecX r = b - A * x;
    double rn = r.norm();
    VecX z, p, Ap;
    precondition(r, z);
    p = z;
    double rz = r.dot(z);
    int it = 0;
    while (rn / bn > m_opt.tolerance && it < max_iterations) {
      Ap.noalias() = A * p;
      const double pAp = p.dot(Ap);
      // A non-positive curvature means A (or the preconditioner) is not SPD.
      if (!(pAp > 0.0) || !(rz > 0.0) || !std::isfinite(rz)) break;
      const double alpha = rz / pAp;
      x.noalias() += alpha * p;
      r.noalias() -= alpha * Ap;
      rn = r.norm();
      ++it;
      if (rn / bn <= m_opt.tolerance) break;
      precondition(r, z);
      const double rz_new = r.dot(z);
      p = z + (rz_new / rz) * p;
      rz = rz_new;
    }
    info.iterations = it;
    info.residual = rn / bn;
    info.ok = std::isfinite(info.residual) && info.residual <= m_opt.tolerance && x.allFinite();
  }

  LinearSolverOptions m_opt;
  bool m_use_cholesky;
  CholmodFactor m_llt;
  bool m_have_factor = false;
  double m_rent = 0.0;  ///< iteration operations paid since the last factorisation
  int m_solves_since_factor = 0;
  int m_baseline = 0;   ///< fewest iterations of a solve one step or more after the factorisation
  VecX m_inv_diag;
  const SpMat* m_A = nullptr;
};

}  // namespace

std::unique_ptr<LinearSolver> make_linear_solver(const std::string& name, const LinearSolverOptions& options) {
  if (name == "cholmod") return std::make_unique<CholmodSolver>(options.threads);
  if (name == "pcg") return std::make_unique<PcgSolver>(options);
  throw std::invalid_argument("unknown linear solver '" + name + "'");
}

}  // namespace octocut::sim
