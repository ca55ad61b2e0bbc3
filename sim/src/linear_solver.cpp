#include "octocut/sim/linear_solver.hpp"

#include <cholmod.h>

#include <chrono>

#include "octocut/sim/hex_element.hpp"
#include "octocut/sim/parallel.hpp"
#include "supernodal_factor.hpp"
#include "supernodal_solve.hpp"

#include <algorithm>
#include <cmath>
#include <future>
#include <iterator>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>


namespace octocut::sim {

namespace {

// y = A x for a symmetric A stored with both triangles (the FEM system's: each pair of blocks is written from one
// element matrix and its transpose, in the same element order). Column i is read as row i, so each y_i is one dot
// product over a contiguous range (four partial sums, no scattered stores), split into row ranges on the executor's
// threads when one is given: the same sums in the same order whatever the thread count.
void symmetric_product(const SpMat& A, const VecX& x, VecX& y, Executor* executor) {
  const int n = int(A.cols());
  y.resize(n);
  const int* outer = A.outerIndexPtr();
  const int* inner = A.innerIndexPtr();
  const double* val = A.valuePtr();
  const double* xp = x.data();
  double* yp = y.data();
  const auto rows = [&](int b, int e) {
    for (int i = b; i < e; ++i) {
      double s[4] = {0.0, 0.0, 0.0, 0.0};
      int k = outer[i];
      const int end = outer[i + 1];
      for (; k + 4 <= end; k += 4) {
        s[0] += val[k] * xp[inner[k]];
        s[1] += val[k + 1] * xp[inner[k + 1]];
        s[2] += val[k + 2] * xp[inner[k + 2]];
        s[3] += val[k + 3] * xp[inner[k + 3]];
      }
      for (; k < end; ++k) s[0] += val[k] * xp[inner[k]];
      yp[i] = (s[0] + s[1]) + (s[2] + s[3]);
    }
  };
  if (executor == nullptr || executor->threads() <= 1 || n < 4096)
    rows(0, n);
  else
    executor->parallel_for(n, 2048, rows);
}

// A stored matrix as a SystemOperator: products by symmetric_product on the executor's threads.
class MatrixOperator final : public SystemOperator {
 public:
  void set(const SpMat& A, Executor* executor) {
    m_A = &A;
    m_executor = executor;
  }
  [[nodiscard]] Eigen::Index rows() const override { return m_A->rows(); }
  [[nodiscard]] Eigen::Index nonzeros() const override { return m_A->nonZeros(); }
  void product(const VecX& x, VecX& y) override { symmetric_product(*m_A, x, y, m_executor); }
  const SpMat& matrix() override { return *m_A; }

 private:
  const SpMat* m_A = nullptr;
  Executor* m_executor = nullptr;
};

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
    // The block analysis: AMD (or the better of AMD and nested dissection, thorough_ordering), weighted postorder,
    // supernodal.
    m_cb.supernodal = CHOLMOD_SUPERNODAL;
    m_cb.nmethods = 1;
    m_cb.method[0].ordering = CHOLMOD_AMD;
    m_cb.method[1].ordering = CHOLMOD_NESDIS;
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
    // AMD; with thorough_ordering also nested dissection (NESDIS), keeping the one whose triangular solves cost the
    // least on two threads: the entries of L in the top of the elimination tree, which one thread solves, plus those
    // of the larger of the two parts solved side by side (SupernodalSolvePlan). On the meniscus the two orderings
    // give L about as many entries (1.28 million with AMD, 1.33 with NESDIS), but AMD's tree ends in a chain of 14
    // supernodes that holds 41 % of them, NESDIS's in 2 that hold 21 %: 0.91 against 0.84 million entries on the
    // longer thread, and NESDIS's solves take 6 % less time per PCG iteration. The choice does not depend on the
    // thread count, so neither do the results. When one ordering's analysis fails, the other's stands.
    cholmod_factor* chosen = nullptr;
    double chosen_cost = 0.0;
    bool chosen_is_expanded = false;  // m_L holds the last ordering analysed
    int failure = CHOLMOD_OK;
    for (const int ordering : {CHOLMOD_AMD, CHOLMOD_NESDIS}) {
      if (ordering == CHOLMOD_NESDIS && !m_thorough) break;
      m_cb.nmethods = 1;
      m_cb.method[0].ordering = ordering;
      cholmod_factor* Lb = cholmod_analyze(&g, &m_cb);
      m_cb.method[0].ordering = CHOLMOD_AMD;
      if (Lb == nullptr || m_cb.status < CHOLMOD_OK || !Lb->is_super) {
        if (Lb) cholmod_free_factor(&Lb, &m_cb);
        failure = m_cb.status;
        continue;
      }
      free_factor();
      expand(*Lb, block, n);
      const std::array<double, 3> work = m_plan.work();
      const double cost = work[2] + std::max(work[0], work[1]);
      chosen_is_expanded = chosen == nullptr || cost < chosen_cost;
      if (chosen_is_expanded) {
        if (chosen) cholmod_free_factor(&chosen, &m_cb);
        chosen = Lb;
        chosen_cost = cost;
      } else {
        cholmod_free_factor(&Lb, &m_cb);
      }
    }
    if (chosen == nullptr) {
      free_factor();
      throw std::runtime_error("CHOLMOD symbolic analysis failed (status " + std::to_string(failure) + ")");
    }
    if (!chosen_is_expanded) {
      free_factor();
      expand(*chosen, block, n);
    }
    cholmod_free_factor(&chosen, &m_cb);
  }
  /// Takes the symbolic analysis of `other` when that holds no numeric factor in CHOLMOD's storage (a factor kept in
  /// single precision only): what analyze() would compute for the same pattern with the same settings, without the
  /// ordering (2.5-14 ms on the meniscus); else, or when CHOLMOD runs out of memory, is left without an analysis.
  void analyze_like(const CholmodFactor& other) {
    free_factor();
    if (other.m_L == nullptr || other.m_L->xtype != CHOLMOD_PATTERN) return;
    m_L = cholmod_copy_factor(other.m_L, &m_c);
    if (m_L == nullptr) return;
    m_block = other.m_block;
    m_factor_flops = other.m_factor_flops;
    m_factor_entries = other.m_factor_entries;
    m_plan = other.m_plan;
  }
  /// Numeric factorisation of A (pattern as analysed). False when A is not positive definite.
  /// With a single- or half-precision copy kept and single_factorization set (keep_single), the factor is
  /// computed in single precision (SupernodalFactorizer), unless that failed the probe earlier in this analysis; by
  /// CHOLMOD in double when it fails or fails the probe (solve() has a double factor only then).
  bool factorize(const SpMat& A) {
    if (m_L == nullptr) return false;
    m_have_double = false;
    serial_openmp_here();  // CHOLMOD's 4-thread OpenMP teams spin against the step on two cores
    if (m_keep_single && m_single_factorization && !m_double_only &&
        m_factorizer.factorize(structure(), static_cast<const int*>(m_L->Perm), A, m_xf)) {
      m_plan.pack(structure(), m_xf.data(), false, m_single);
      if (probe_error(A, true) <= m_single_probe) {
        if (m_plan.packed_size() > m_half_above) keep_copy(A, m_xf.data());
        return true;
      }
      m_double_only = true;  // this pattern's matrices need the digits: factorise them in double from now on
    }
    cholmod_sparse a = view(A);
    cholmod_factorize(&a, m_L, &m_c);
    const bool ok = m_c.status >= CHOLMOD_OK && m_L->minor == m_L->n;
    m_have_double = ok;
    if (ok && m_keep_single) keep_copy(A, static_cast<const double*>(m_L->x));
    return ok;
  }
  /// Forgets the analysis and the factor (analyzed() is false after).
  void clear() {
    free_factor();
    m_factor_flops = m_factor_entries = 0.0;
  }
  /// The next analyses order with the better of AMD and nested dissection (LinearSolverOptions::thorough_ordering).
  void thorough_ordering(bool thorough) { m_thorough = thorough; }
  /// Keeps a copy of each factor for solve_single: in single precision, or in half precision when it has more than
  /// `half_above` entries and passes the probe to `half_probe` (LinearSolverOptions::half_precision_entries).
  void keep_single(bool keep, std::size_t half_above, double half_probe) {
    m_keep_single = keep;
    m_half_above = half_above;
    m_half_probe = half_probe;
  }
  /// Computes the factor in single precision when it keeps a copy (LinearSolverOptions::single_precision_
  /// factorization), while the copy solves its own matrix to within `probe` on a smooth vector (probe_error).
  void single_factorization(bool on, double probe) {
    m_single_factorization = on;
    m_single_probe = probe;
  }
  /// x = (L L^T)^-1 b (in A's ordering) with the single- or half-precision copy of the last factor, in single
  /// arithmetic: the preconditioner of PCG. The solves run on two of the executor's threads (SupernodalSolvePlan;
  /// the same result with one). False without a copy.
  bool solve_single(const VecX& b, VecX& x, Executor* executor) {
    if (m_L == nullptr || m_single.size() != m_plan.packed_size() || b.size() != Eigen::Index(m_L->n)) return false;
    const int n = int(m_L->n);
    const int* perm = static_cast<const int*>(m_L->Perm);
    m_perm.resize(std::size_t(n));
    for (int k = 0; k < n; ++k) m_perm[std::size_t(k)] = float(b[perm[k]]);
    const SupernodalStructure L = structure();
    m_plan.forward(L, m_single, m_perm.data(), executor);
    m_plan.backward(L, m_single, m_perm.data(), executor);
    x.resize(n);
    for (int k = 0; k < n; ++k) x[perm[k]] = double(m_perm[std::size_t(k)]);
    return true;
  }
  /// x = A^-1 b with the last factor. False when CHOLMOD fails.
  bool solve(const VecX& b, VecX& x) {
    if (m_L == nullptr || !m_have_double) return false;
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
  /// Unknowns of the analysed pattern (0 before analyze).
  [[nodiscard]] std::size_t size() const { return m_L ? m_L->n : 0; }
  /// Whether a symbolic analysis is held (analyze succeeded).
  [[nodiscard]] bool analyzed() const { return m_L != nullptr; }
  /// Floating-point operations of one numeric factorisation, sum over columns of count^2 (0 before analyze).
  [[nodiscard]] double factor_flops() const { return m_factor_flops; }
  /// Entries of L, sum over columns of count (0 before analyze).
  [[nodiscard]] double factor_entries() const { return m_factor_entries; }
  /// The analysed supernodal structure and ordering (L's column k is A's column permutation()[k]), for a numeric
  /// factorisation of one's own (LocalSolve). Only while analyzed().
  [[nodiscard]] SupernodalStructure symbolic() const { return structure(); }
  [[nodiscard]] const int* permutation() const { return static_cast<const int*>(m_L->Perm); }

 private:
  void free_factor() {
    if (m_L) cholmod_free_factor(&m_L, &m_c);
    m_L = nullptr;
    // Emptied, its storage kept for the next analysis's factor (assign_with_room).
    m_single.values.clear();
    m_single.codes.clear();
    m_single.diag_inv.clear();
    m_single.scale.clear();
    m_have_double = m_double_only = false;
    m_factorizer.forget();  // its assembly plan is for this analysis
  }

  // Packs the factor's values x (CHOLMOD's layout) into the copy that solve_single reads: in half precision when
  // large and when that preconditions A well enough, else in single.
  template <class T>
  void keep_copy(const SpMat& A, const T* x) {
    const bool large = m_plan.packed_size() > m_half_above;
    m_plan.pack(structure(), x, large, m_single);
    if (large && !half_preconditions(A)) m_plan.pack(structure(), x, false, m_single);
  }
  // Whether the half-precision copy of the factor (m_single, just packed) preconditions its own matrix A well
  // enough: |z - v| / |v| <= m_half_probe for z = (L~ L~^T)^-1 A v, L~ the copy and v a fixed vector of entries in
  // [-1, 1). Half precision gives 5e-4 to 4e-3 on the meniscus (E = 2e5 Pa, nu = 0.45) and the cubes of `octocut
  // bench scaling`, but 0.015-16 on stiffer tissue (the meniscus at base level 6 with E = 1e6-1e9 Pa, nu =
  // 0.45-0.499), where it costs PCG up to 4.9 times the iterations of single precision (docs/RESULTS.md).
  bool half_preconditions(const SpMat& A) { return probe_error(A, false) <= m_half_probe; }
  // |z - v| / |v| for z = (L~ L~^T)^-1 A v, L~ the copy solve_single reads: v a fixed vector of entries in [-1, 1),
  // or a smooth one (every entry 1), which stresses the directions a single-precision factorisation resolves worst,
  // those of A's smallest eigenvalues (translations, which only the mass resists; near-incompressible modes).
  double probe_error(const SpMat& A, bool smooth) {
    const Eigen::Index n = A.cols();
    VecX v(n), z;
    for (Eigen::Index k = 0; k < n; ++k)
      v[k] = smooth ? 1.0 : double((std::uint32_t(k) * 2654435761u) >> 16) / 32768.0 - 1.0;
    const VecX b = A.selfadjointView<Eigen::Lower>() * v;  // A's lower triangle, as CHOLMOD reads it (stype -1)
    if (!solve_single(b, z, nullptr)) return std::numeric_limits<double>::infinity();
    const double e = (z - v).norm() / v.norm();
    return std::isfinite(e) ? e : std::numeric_limits<double>::infinity();
  }

  // The supernodal structure of the analysed factor.
  [[nodiscard]] SupernodalStructure structure() const { return supernodal_structure_of(*m_L); }

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
    m_plan.build(structure());
  }

  cholmod_common m_c{};   ///< the scalar factor's
  cholmod_common m_cb{};  ///< the block analysis'
  std::size_t m_default_nrelax[3] = {4, 16, 48};
  cholmod_factor* m_L = nullptr;
  bool m_keep_single = false;
  std::size_t m_half_above = 0;  ///< entries above which the copy is in half precision (keep_single)
  double m_half_probe = 0.0;     ///< the probe's tolerance (keep_single)
  PackedFactor m_single;         ///< L's values in single or half precision, when kept (m_plan's packed layout)
  std::vector<float> m_perm;    ///< solve_single's permuted right-hand side (n)
  SupernodalSolvePlan m_plan;   ///< how solve_single splits its triangular solves between two threads
  SupernodalFactorizer<float> m_factorizer;  ///< the numeric factorisation in single precision (keep_single)
  std::vector<float> m_xf;            ///< its values (CHOLMOD's layout)
  bool m_have_double = false;         ///< whether m_L holds a numeric factor (solve)
  bool m_single_factorization = false;  ///< factorise in single precision (single_factorization)
  double m_single_probe = 0.0;          ///< the copy's largest probe error for that
  bool m_double_only = false;           ///< a single-precision factorisation of this analysis failed its probe
  cholmod_dense* m_x = nullptr;  ///< solve2 workspaces, kept
  cholmod_dense* m_y = nullptr;
  cholmod_dense* m_e = nullptr;
  int m_block = 1;
  bool m_thorough = false;        ///< order with the better of AMD and NESDIS
  double m_factor_flops = 0.0;    ///< of one numeric factorisation
  double m_factor_entries = 0.0;  ///< nnz(L)
};

// A numeric factorisation running on a second thread: of its own copy of a matrix, into its own factor (which holds,
// or analyses first, the symbolic factorisation of that pattern).
struct BackgroundFactorization {
  SpMat A;                                ///< the matrix it factorises (a copy)
  std::unique_ptr<CholmodFactor> factor;  ///< where
  std::future<bool> done;                 ///< whether it succeeded
  int solves = 0;                         ///< solves begun since it started
  double iteration_flops = 0.0;           ///< PCG operations of those solves
  std::vector<int> fast;                  ///< the fast DOFs of A (set_fast_dofs)
  std::vector<Mat3> rotations;            ///< the DOFs' rotations at A (set_dof_rotations)
};

// Background factorisations whose solver no longer wants them (replaced after a cut, or refreshed at once) are kept
// here until they end, so that nobody waits for them: each retire() frees the ended ones, and the list's destruction
// at exit waits for the rest. reclaim() hands over the factor of one that has ended, for its storage: a cut that
// comes while a refresh runs leaves the new solver without a spare factor, and a new one's memory costs its first
// factorisation a page fault per 4 KiB (meniscus_punch_hd: 3.7 ms of packing against 0.9, 14.7 ms of factorisation
// against 10.4-12.2).
class RetiredFactorizations {
 public:
  static void retire(std::unique_ptr<BackgroundFactorization> f) {
    const std::lock_guard lock(s_mutex);
    std::erase_if(s_retired, [](const auto& r) { return ended(*r); });
    if (f) s_retired.push_back(std::move(f));
  }
  static std::unique_ptr<CholmodFactor> reclaim() {
    const std::lock_guard lock(s_mutex);
    for (auto it = s_retired.begin(); it != s_retired.end(); ++it) {
      if (!ended(**it) || !(*it)->factor) continue;
      std::unique_ptr<CholmodFactor> factor = std::move((*it)->factor);
      s_retired.erase(it);
      factor->clear();
      return factor;
    }
    return nullptr;
  }

 private:
  static bool ended(BackgroundFactorization& f) {
    return f.done.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
  }
  static inline std::mutex s_mutex;
  static inline std::vector<std::unique_ptr<BackgroundFactorization>> s_retired;
};

// Direct solver: supernodal LL^T; the symbolic analysis is reused until the pattern changes.
class CholmodSolver final : public LinearSolver {
 public:
  // A failed factorisation is reported through SolveInfo and counted by the caller, not printed by CHOLMOD.
  explicit CholmodSolver(bool thorough_ordering) {
    m_llt.thorough_ordering(thorough_ordering);
  }
  void analyze_pattern(const SpMat& A) override {
    m_ok = false;
    m_llt.analyze(A);
  }
  bool factorize(const SpMat& A) override {
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
  const SpMat* m_A = nullptr;
  bool m_ok = false;
};

// w = Q^T r per DOF (3 x 3 blocks Q_d; see PcgSolver's warp).
void warp_transpose(const std::vector<Mat3>& q, const VecX& r, VecX& w) {
  w.resize(r.size());
  for (std::size_t d = 0; d < q.size(); ++d)
    w.segment<3>(3 * Eigen::Index(d)).noalias() = q[d].transpose() * r.segment<3>(3 * Eigen::Index(d));
}
// The rotations of the old factor's matrix in the new numbering (T: new x old DOFs): each new DOF's old DOFs'
// rotations summed with |weights| and made a rotation again (a copied DOF keeps its own). Empty when `old` does not
// match T.
std::vector<Mat3> transferred_rotations(const std::vector<Mat3>& old, const SpMat& transfer) {
  if (old.empty() || Eigen::Index(old.size()) != transfer.cols()) return {};
  std::vector<Mat3> out(std::size_t(transfer.rows()), Mat3::Zero());
  for (Eigen::Index j = 0; j < transfer.cols(); ++j)
    for (SpMat::InnerIterator it(transfer, j); it; ++it)
      out[std::size_t(it.row())] += std::abs(it.value()) * old[std::size_t(j)];
  for (Mat3& r : out) r = gram_schmidt_rotation(r);
  return out;
}
// z = Q z in place per DOF.
void warp_in_place(const std::vector<Mat3>& q, VecX& z) {
  for (std::size_t d = 0; d < q.size(); ++d) {
    const Vec3 zd = z.segment<3>(3 * Eigen::Index(d));
    z.segment<3>(3 * Eigen::Index(d)).noalias() = q[d] * zd;
  }
}

// An exact solve on a region C of the DOFs, combined with a global preconditioner G multiplicatively and
// symmetrically (local, global, local: symmetric multiplicative Schwarz), with L = E_C A_CC^-1 E_C^T:
//   z1 = L r,  z2 = z1 + G (r - A z1),  z = z2 + L (r - A z2).
// Symmetric by construction; positive definite while G A's spectrum, on the vectors the local solves leave, stays
// within (0, 2), as it does when G is a (lagged) inverse of A wherever A changed only off C. The local products read
// A's columns of C only (A symmetric), taken from the operator at each build() (SystemOperator::columns: the FEM
// system computes them from the elements around C without assembling the rest), so an application costs one
// application of G, two small local solves and products with those columns. A_CC is factorised at each build(); its
// analysis is kept while C stays the same.
class LocalSolve {
 public:
  /// Takes A's columns of the DOFs `dofs` (ascending, 3 x 3 blocked A) and factorises A restricted to them. False
  /// when that fails (A_CC not positive definite, out of memory): then the region is empty.
  bool build(SystemOperator& A, std::vector<int> dofs) {
    if (dofs.empty()) {
      m_dofs.clear();
      return true;
    }
    try {
      SpMat columns = A.columns(dofs);
      m_columns.swap(columns);  // not assigned: Eigen's SparseMatrix copies on assignment, even from a temporary
      const SpMat Al = rows_of(m_columns, dofs, A.rows());
      if (dofs != m_dofs || !m_analysis.analyzed()) {
        m_analysis.analyze(Al);
        m_factorizer.forget();
      }
      m_dofs = std::move(dofs);
      if (m_factorizer.factorize(m_analysis.symbolic(), m_analysis.permutation(), Al, m_lx)) return true;
    } catch (const std::exception&) {
    }
    m_dofs.clear();
    m_analysis.clear();
    m_factorizer.forget();
    return false;
  }
  [[nodiscard]] bool empty() const { return m_dofs.empty(); }
  /// Whether any of `dofs` (ascending) lies in the region.
  [[nodiscard]] bool meets(const std::vector<int>& dofs) const {
    std::size_t i = 0, j = 0;
    while (i < m_dofs.size() && j < dofs.size()) {
      if (m_dofs[i] == dofs[j]) return true;
      (m_dofs[i] < dofs[j] ? i : j)++;
    }
    return false;
  }
  /// z = the combination applied to r (see the class comment); global(r, w) sets w = G r.
  template <class Global>
  void apply(const VecX& r, VecX& z, Global&& global) {
    // z1 = L r; r1 = r - A z1 (z1 lives on C: A's columns of C).
    gather_local(r, m_rl);
    solve_local(m_rl);
    z.setZero(r.size());
    m_r1 = r;
    for (std::size_t i = 0; i < m_dofs.size(); ++i)
      for (int c = 0; c < 3; ++c) {
        const Eigen::Index k = 3 * Eigen::Index(i) + c;
        const double v = m_zl[k];
        z[3 * Eigen::Index(m_dofs[i]) + c] = v;
        for (SpMat::InnerIterator it(m_columns, k); it; ++it) m_r1[it.row()] -= it.value() * v;
      }
    // z2 = z1 + G r1.
    global(m_r1, m_w);
    z += m_w;
    // z = z2 + L (r - A z2), where (r - A z2)_C = (r1 - A G r1)_C: A's columns of C against G r1.
    for (std::size_t i = 0; i < m_dofs.size(); ++i)
      for (int c = 0; c < 3; ++c) {
        const Eigen::Index k = 3 * Eigen::Index(i) + c;
        double aw = 0.0;
        for (SpMat::InnerIterator it(m_columns, k); it; ++it) aw += it.value() * m_w[it.row()];
        m_rl[k] = m_r1[3 * Eigen::Index(m_dofs[i]) + c] - aw;
      }
    solve_local(m_rl);
    for (std::size_t i = 0; i < m_dofs.size(); ++i)
      z.segment<3>(3 * m_dofs[i]) += m_zl.segment<3>(3 * Eigen::Index(i));
  }

 private:
  // rl = r restricted to C.
  void gather_local(const VecX& r, VecX& rl) const {
    rl.resize(3 * Eigen::Index(m_dofs.size()));
    for (std::size_t i = 0; i < m_dofs.size(); ++i) rl.segment<3>(3 * Eigen::Index(i)) = r.segment<3>(3 * m_dofs[i]);
  }
  // m_zl = A_CC^-1 rl.
  void solve_local(const VecX& rl) {
    m_zl = rl;
    supernodal_solve(m_analysis.symbolic(), m_analysis.permutation(), m_lx, m_zl.data(), m_work);
  }
  // The rows of the DOFs `dofs` (ascending) of A's columns of those DOFs: A_CC, both triangles, 3 x 3 blocked. The
  // columns' rows are sorted and the map is increasing, so each column's rows come out sorted.
  SpMat rows_of(const SpMat& columns, const std::vector<int>& dofs, Eigen::Index n) {
    m_row_of.assign(std::size_t(n), -1);  // each scalar row of C's DOFs: its row in A_CC
    for (std::size_t i = 0; i < dofs.size(); ++i)
      for (int c = 0; c < 3; ++c) m_row_of[3 * std::size_t(dofs[i]) + std::size_t(c)] = 3 * int(i) + c;
    const Eigen::Index m = columns.cols();
    SpMat out(m, m);
    out.resizeNonZeros(columns.nonZeros());  // at most
    int* o_outer = out.outerIndexPtr();
    int* o_inner = out.innerIndexPtr();
    double* o_val = out.valuePtr();
    const int* outer = columns.outerIndexPtr();
    const int* inner = columns.innerIndexPtr();
    const double* val = columns.valuePtr();
    int at = 0;
    for (Eigen::Index k = 0; k < m; ++k) {
      o_outer[k] = at;
      for (int p = outer[k]; p < outer[k + 1]; ++p) {
        const int j = m_row_of[std::size_t(inner[p])];
        if (j < 0) continue;
        o_inner[at] = j;
        o_val[at++] = val[p];
      }
    }
    o_outer[m] = at;
    out.resizeNonZeros(at);
    return out;
  }

  std::vector<int> m_dofs;   ///< the region C, ascending
  SpMat m_columns;           ///< A's columns of C (3 num_dofs x 3 |C|)
  // A_CC's factor: CHOLMOD's analysis (blocked AMD, supernodal), our numeric factorisation in double. CHOLMOD's
  // numeric one costs these few hundred unknowns mostly its overhead (permuting A_CC, workspaces, a call per
  // supernode): meniscus_punch's contact regions of 100-200 DOFs took 0.29 ms where this takes about 0.1.
  CholmodFactor m_analysis;
  SupernodalFactorizer<double> m_factorizer;
  std::vector<double> m_lx;  ///< L's values (CHOLMOD's layout)
  std::vector<double> m_work;  ///< work of the solves
  VecX m_rl, m_zl;           ///< work: r, z on C
  VecX m_r1, m_w;            ///< work: r - A z1, G r1 (3 num_dofs)
  std::vector<int> m_row_of;  ///< work: rows_of's map (3 num_dofs)
};

// The preconditioner of the solves right after a cut, before the new pattern has a factor of its own. Two parts:
// the old revision's lagged factor F_old, reached through the transfer T of DOF values from the old revision to the
// new (transfer_matrix), covers everything the old discretisation can represent: G = T F_old^-1 T^T; an exact solve on
// the cut's region C covers what the cut added there (refined DOFs, which no old DOF copies, and split ones, which
// share their old DOF, with the DOFs coupled to them in A), factorised at the bridge's first matrix. They are combined
// as LocalSolve does (local, global, local); every DOF off C is a plain copy of one old DOF, so G and L together
// reach every DOF. On the 50k meniscus after a punch PCG needs 4-7 iterations with it, where the earlier additive
// combination (G + L + block Jacobi) needed 13-22 and a factorisation costs about 58. Should the combination not be
// positive definite after all, PCG notices (non-positive curvature) and the solver falls back to a factor.
class CutBridge {
 public:
  CutBridge(std::unique_ptr<CholmodFactor> factor, SpMat transfer)
      : m_factor(std::move(factor)), m_transfer(std::move(transfer)) {}
  /// The old revision's factor (its operation counts price the new pattern's first factor until that is analysed).
  [[nodiscard]] const CholmodFactor& old_factor() const { return *m_factor; }
  /// Hands the old revision's factor over (the bridge is not to be applied after), for its storage.
  std::unique_ptr<CholmodFactor> release_factor() { return std::move(m_factor); }
  /// Prepares for A (3 x 3 blocked, new DOFs as T's rows), unless given its local solve already (set_local).
  /// False when it cannot: then nothing uses it.
  bool build(SystemOperator& A) {
    const Eigen::Index nb = A.rows() / 3;
    if (A.rows() % 3 != 0 || m_transfer.rows() != nb || !m_factor) return false;
    if (m_local_ready) return true;
    // False without its factor: G alone would miss the cut's new DOFs.
    return m_local->build(A, cut_region(m_transfer, A.pattern()));
  }
  /// The exact solve on the cut's region, built beforehand (from a system of the same pattern: prepare_bridge).
  void set_local(std::unique_ptr<LocalSolve> local) {
    m_local = std::move(local);
    m_local_ready = !m_local->empty();
  }
  /// Forgets a local solve built beforehand when any of the DOFs `fast` (ascending: those the current system's
  /// contact blocks reach) lies in its region: its columns, taken without contacts, would then differ from this
  /// system's, so build() takes them from this system. Otherwise they are the same, bit for bit.
  void drop_local_if_it_meets(const std::vector<int>& fast) {
    if (!m_local_ready || !m_local->meets(fast)) return;
    m_local = std::make_unique<LocalSolve>();
    m_local_ready = false;
  }
  /// The DOFs of the cut's region for transfer T (new x old DOFs) and the new system's pattern (see the class
  /// comment), ascending.
  static std::vector<int> cut_region(const SpMat& transfer, const SpMat& pattern);
  /// z = the bridge applied to r for the system matrix it was built for (see the class comment); F_old's
  /// triangular solves in single precision if asked, on the executor's threads; G warped by `warp` (Q G Q^T, new
  /// numbering) unless it is empty.
  void apply(const VecX& r, VecX& z, bool single, Executor* executor, const std::vector<Mat3>& warp) {
    const auto global = [&](const VecX& rr, VecX& w) {
      if (warp.empty()) {
        apply_global(rr, w, single, executor);
        return;
      }
      warp_transpose(warp, rr, m_warped);
      apply_global(m_warped, w, single, executor);
      warp_in_place(warp, w);
    };
    if (m_local->empty())
      global(r, z);
    else
      m_local->apply(r, z, global);
  }

 private:
  // w = G r = T F_old^-1 T^T r.
  void apply_global(const VecX& r, VecX& w, bool single, Executor* executor) {
    const Eigen::Index n_new = m_transfer.rows(), n_old = m_transfer.cols();
    m_rc.setZero(3 * n_old);
    for (Eigen::Index j = 0; j < n_old; ++j)  // T^T r; column j of T: the new DOFs old DOF j reaches
      for (SpMat::InnerIterator it(m_transfer, j); it; ++it)
        m_rc.segment<3>(3 * j) += it.value() * r.segment<3>(3 * it.row());
    if (!(single ? m_factor->solve_single(m_rc, m_zc, executor) : m_factor->solve(m_rc, m_zc))) m_zc.setZero(3 * n_old);
    w.setZero(3 * n_new);
    for (Eigen::Index j = 0; j < n_old; ++j)
      for (SpMat::InnerIterator it(m_transfer, j); it; ++it)
        w.segment<3>(3 * it.row()) += it.value() * m_zc.segment<3>(3 * j);
  }
  std::unique_ptr<CholmodFactor> m_factor;  ///< the old revision's lagged factor (3 old num_dofs)
  SpMat m_transfer;                         ///< new x old DOFs (transfer_matrix)
  /// The exact solve on the cut's region (at the bridge's first matrix, or at the state the cut carried over).
  std::unique_ptr<LocalSolve> m_local = std::make_unique<LocalSolve>();
  bool m_local_ready = false;  ///< m_local was given (set_local), not to be built
  VecX m_rc, m_zc;                          ///< work: T^T r, F_old^-1 T^T r (3 old num_dofs)
  VecX m_warped;                            ///< work: Q^T r (3 num_dofs)
};

// The cut's region: every new DOF that is not a plain copy of one old DOF which no other new DOF copies (refined
// DOFs and both halves of a split one), grown by the DOFs coupled to them in A's pattern.
std::vector<int> CutBridge::cut_region(const SpMat& transfer, const SpMat& pattern) {
  const Eigen::Index nb = transfer.rows();
  std::vector<int> reached(std::size_t(transfer.cols()), 0);  // new DOFs each old DOF feeds
  std::vector<int> source(std::size_t(nb), -1);                // the old DOF a copied new DOF takes, else -1
  std::vector<char> copied(std::size_t(nb), 0);
  for (Eigen::Index j = 0; j < transfer.cols(); ++j)
    for (SpMat::InnerIterator it(transfer, j); it; ++it) {
      ++reached[std::size_t(j)];
      const auto d = std::size_t(it.row());
      copied[d] = source[d] == -1 && it.value() == 1.0;
      source[d] = source[d] == -1 ? int(j) : -2;  // -2: reads several old DOFs
    }
  std::vector<char> in(std::size_t(nb), 0);
  for (Eigen::Index d = 0; d < nb; ++d) {
    const int j = source[std::size_t(d)];
    in[std::size_t(d)] = !(copied[std::size_t(d)] && j >= 0 && reached[std::size_t(j)] == 1);
  }
  std::vector<char> grown = in;  // and the DOFs coupled to those in A (its pattern)
  for (Eigen::Index k = 0; k < nb; ++k)
    if (in[std::size_t(k)])
      for (SpMat::InnerIterator it(pattern, 3 * k); it; ++it) grown[std::size_t(it.row() / 3)] = 1;
  std::vector<int> out;
  for (Eigen::Index k = 0; k < nb; ++k)
    if (grown[std::size_t(k)]) out.push_back(int(k));
  return out;
}

// Conjugate gradients, warm-started from x, with either a lagged Cholesky factor of an earlier system matrix or
// the diagonal as preconditioner. The lagged factor is refreshed by a rent-or-buy rule. The solve right after a
// factorisation converges in one iteration; the next one, a step later, takes the baseline: what one step's change
// of the matrix (the rotations) costs even with a fresh factor. Every iteration a later solve needs beyond the
// baseline (the fewest since the factorisation) is rent paid for the factor's age, priced in floating-point
// operations: two triangular solves with L, a product with A, five vector updates. A factorisation is the purchase:
// its operations divided by factor_flop_advantage, because its dense supernodal kernels do that many more operations
// per second than the triangular solves. Once the rent paid since the last factorisation reaches the purchase price,
// the factor is refreshed. When the iteration count grows linearly with the factor's age (an object that keeps
// rotating, contacts that keep changing) this period minimises the mean cost per step; an object whose iterations
// stay at the baseline never pays for a factorisation it would not gain from.
//
// The refresh runs in the background (factor_lag_solves > 0): the solve that finds the rent paid starts a
// factorisation of its own matrix on a second thread, into a second factor with the same symbolic analysis, and
// goes on with the old one; the solve factor_lag_solves later waits for it if need be and swaps it in. So the step
// that would have stalled on the factorisation takes no longer than its neighbours, while the two cores are shared
// between the step and the factorisation. The swap happens at a fixed solve, whatever the timing, and the factor is
// that of a fixed matrix, so the iterates stay deterministic. The first factor of a pattern, and the refresh after a
// solve that does not converge (or would pay more than a factorisation in iterations beyond the baseline), are
// computed at once: that solve then continues from x with the fresh factor. The rule counts iterations and
// operations only, so it is deterministic.
class PcgSolver final : public LinearSolver {
 public:
  explicit PcgSolver(const LinearSolverOptions& o)
      : m_opt(o), m_use_cholesky(o.preconditioner != "jacobi"), m_single(o.single_precision_factor) {
    if (o.preconditioner != "jacobi" && o.preconditioner != "cholesky")
      throw std::invalid_argument("unknown preconditioner '" + o.preconditioner + "'");
    if (o.factor_lag_solves < 0) throw std::invalid_argument("factor_lag_solves must be >= 0");
    if (!(o.half_precision_probe >= 0.0)) throw std::invalid_argument("half_precision_probe must be >= 0");
  }
  ~PcgSolver() override { drop_pending(); }  // a cut replaces the solver: it does not wait for the refresh
  PcgSolver(const PcgSolver&) = delete;
  PcgSolver& operator=(const PcgSolver&) = delete;

  // With factor_lag_solves > 0 the analysis is left to the first factorisation that needs it: after a cut that is
  // the background one the bridge starts (so the ordering of the new pattern, 2-3 ms on the 50k meniscus, leaves the
  // cut's critical path); a factorisation made at once (the first step, or when no bridge can be built) analyses
  // first.
  void analyze_pattern(const SpMat& A) override {
    drop_pending();
    m_pending_in = -1;
    if (m_use_cholesky) {
      configure(*m_front);
      if (m_opt.factor_lag_solves > 0)
        m_front->clear();
      else
        m_front->analyze(A);
      m_back.reset();  // a spare is analysed in the background, when first needed
    }
    m_have_factor = false;
  }
  bool factorize(const SpMat& A) override {
    m_stored.set(A, m_executor);
    return factorize_operator(m_stored);
  }
  bool factorize_operator(SystemOperator& A) override {
    m_A = &A;
    if (!m_use_cholesky) {
      m_inv_diag = A.matrix().diagonal();
      for (Eigen::Index i = 0; i < m_inv_diag.size(); ++i) {
        if (!(m_inv_diag[i] > 0.0)) return false;
        m_inv_diag[i] = 1.0 / m_inv_diag[i];
      }
      return true;
    }
    if (m_bridging) return true;  // until the background factor is in place
    if (!m_have_factor) return m_bridge ? start_bridge() : refactor();
    return true;
  }
  void prepare_bridge(SystemOperator& A, const SpMat& transfer) override {
    m_prepared_local.reset();
    if (!m_use_cholesky || m_opt.factor_lag_solves <= 0 || A.rows() % 3 != 0 || transfer.rows() * 3 != A.rows())
      return;
    auto local = std::make_unique<LocalSolve>();
    if (!local->build(A, CutBridge::cut_region(transfer, A.pattern())) || local->empty()) return;
    m_prepared_local = std::move(local);
    m_prepared_rows = transfer.rows();
  }
  void inherit(LinearSolver& previous, const SpMat& transfer) override {
    auto* old = dynamic_cast<PcgSolver*>(&previous);
    if (old == nullptr || !m_use_cholesky || m_opt.factor_lag_solves <= 0 || !old->m_use_cholesky ||
        !old->m_have_factor || transfer.cols() * 3 != Eigen::Index(old->m_front->size()))
      return;
    old->drop_pending();
    m_rotations_front = transferred_rotations(old->m_rotations_front, transfer);
    m_bridge = std::make_unique<CutBridge>(std::move(old->m_front), transfer);
    if (m_prepared_local && m_prepared_rows == transfer.rows()) m_bridge->set_local(std::move(m_prepared_local));
    m_prepared_local.reset();
    // Its spare matrix's storage, emptied (the pattern is the old one's), for the new pattern's first factor.
    m_spare_matrix.swap(old->m_spare_matrix);
    m_spare_matrix.resize(0, 0);  // keeps the allocation
    // And its spare factor's, emptied, for the same: the new pattern's first factor fills it in the background.
    if (old->m_back) {
      old->m_back->clear();
      m_back = std::move(old->m_back);
    }
    old->m_front = std::make_unique<CholmodFactor>();
    old->m_have_factor = false;
  }
  SolveInfo solve(const VecX& b, VecX& x) override {
    SolveInfo info;
    if (x.size() != b.size() || !x.allFinite()) x = VecX::Zero(b.size());
    bool own_factor = false;  // the factor is that of this solve's matrix
    if (m_use_cholesky) {
      if (m_pending && pending_due()) adopt_pending(info);
      if (m_pending_in >= 0 && m_pending_in-- == 0 && m_bridging && !m_pending) start_pending();
      if (!m_pending && m_rent >= purchase_price()) {
        if (m_opt.factor_lag_solves > 0) {
          start_pending();
        } else {
          if (!refactor()) return info;
          info.refactorized = own_factor = true;
        }
      }
    }
    // With a lagged factor, a solve that would pay more than a factorisation in iterations stops and buys one.
    // (Once the baseline is known: from the second solve after a factorisation on.)
    int cap = m_opt.max_iterations;
    if (m_bridging)
      cap = int(std::min<double>(cap, 1.0 + std::floor(purchase_price() / iteration_flops())));
    else if (m_use_cholesky && !own_factor && m_solves_since_factor >= 2)
      cap = int(std::min<double>(cap, m_baseline + 1.0 + std::floor(purchase_price() / iteration_flops())));
    VecX ax;
    prepare_solve(x, ax);
    run_pcg(b, x, ax, info, cap);
    if (!m_use_cholesky) return info;
    if (!m_pending)
      pay_rent(info.iterations);
    else
      m_pending->iteration_flops += double(info.iterations) * iteration_flops();
    if (info.ok || own_factor) return info;
    // Failed or too slow convergence: continue from x with a fresher factor: the background refresh in flight if
    // there is one, else (or when that does not do) one of the current matrix, computed now.
    for (const bool wait_pending : {true, false}) {
      if (wait_pending && !m_pending) continue;
      if (wait_pending) {
        adopt_pending(info);
      } else if (!refactor()) {
        return info;
      }
      info.refactorized = true;
      SolveInfo again;
      VecX ax;
      prepare_solve(x, ax);
      run_pcg(b, x, ax, again, m_opt.max_iterations);
      info.ok = again.ok;
      info.iterations += again.iterations;
      info.residual = again.residual;
      if (info.ok) break;
    }
    return info;
  }
  std::string name() const override { return "pcg"; }
  int ordering_block_size() const override { return m_use_cholesky ? m_front->block_size() : 0; }
  void set_executor(Executor* executor) override { m_executor = executor; }
  void set_fast_dofs(std::vector<int> dofs) override { m_fast_now = std::move(dofs); }
  void set_dof_rotations(std::vector<Mat3> rotations) override { m_rotations_now = std::move(rotations); }
  void set_reference_norm(double reference) override {
    m_reference = std::isfinite(reference) && reference > 0.0 ? reference : 0.0;
  }

 private:
  // The first factorize() of a pattern after a cut, with an inherited factor: the bridge preconditions the solves
  // until the new pattern's first factor, computed in the background from the next solve's matrix, is due
  // (factor_lag_solves solves after it started, as a refresh). Falls back to an inline factorisation when the bridge
  // cannot be built.
  bool start_bridge() {
    m_bridge->drop_local_if_it_meets(m_fast_now);
    if (!m_bridge->build(*m_A)) {
      m_bridge.reset();
      return refactor();
    }
    m_bridging = true;
    m_pending_in = 1;  // the first solve after a cut already builds the bridge: the next one starts the factor
    return true;
  }

  // Factorises the current matrix now, into the front factor (analysed first when it is not yet). Drops a background
  // refresh first: its factor would be older than this one.
  bool refactor() {
    drop_pending();
    m_pending_in = -1;
    if (!m_front->analyzed()) {
      try {
        m_front->analyze(m_A->matrix());
      } catch (const std::exception&) {
        return m_have_factor = false;
      }
    }
    m_have_factor = m_front->factorize(m_A->matrix());
    if (m_have_factor) {  // the solves use it from now on, also when they were bridged
      m_bridging = false;
      m_bridge.reset();
      m_fast_front = m_fast_now;
      m_rotations_front = m_rotations_now;
    }
    fresh_factor();
    return m_have_factor;
  }
  // The bookkeeping of a factor just put in place (of the matrix of the solve about to run, or of one
  // factor_lag_solves older).
  void fresh_factor() {
    m_rent = 0.0;
    m_solves_since_factor = 0;
  }
  // Gives a factor this solver's settings: the single- or half-precision copy, the single-precision
  // factorisation, the ordering.
  void configure(CholmodFactor& factor) const {
    factor.keep_single(m_single, m_opt.half_precision_entries, m_opt.half_precision_probe);
    factor.single_factorization(m_opt.single_precision_factorization, m_opt.tolerance);
    factor.thorough_ordering(m_opt.thorough_ordering);
  }
  // Starts factorising a copy of the current matrix into the back factor on a second thread (BLAS at one thread,
  // the step keeps the other core busy).
  void start_pending() {
    m_pending = std::make_unique<BackgroundFactorization>();
    // Assembled into the last refresh's storage (or the previous revision's, after a cut): fresh pages for a
    // matrix cost up to 2.7 ms, and assembling it into the step's storage first cost a copy (0.4 ms on the meniscus).
    m_pending->A.swap(m_spare_matrix);
    m_A->assemble_into(m_pending->A);
    m_pending->factor = m_back ? std::move(m_back) : RetiredFactorizations::reclaim();
    if (!m_pending->factor) m_pending->factor = std::make_unique<CholmodFactor>();
    configure(*m_pending->factor);
    // The spare of a new pattern takes the front factor's analysis, of the same pattern, rather than repeating it.
    if (!m_pending->factor->analyzed() && m_front->analyzed()) m_pending->factor->analyze_like(*m_front);
    m_pending->fast = m_fast_now;
    m_pending->rotations = m_rotations_now;
    CholmodFactor* factor = m_pending->factor.get();
    SpMat* A = &m_pending->A;
    m_pending->done = std::async(std::launch::async, [factor, A] {
      try {
        if (!factor->analyzed()) factor->analyze(*A);
        const bool ok = factor->factorize(*A);
        // Room for the next pattern's few more entries (a cut refines), so that the storage this matrix hands on
        // is not reallocated on the step's thread: the reallocation, when needed, happens here.
        A->data().reserve(A->nonZeros() / 8);
        return ok;
      } catch (const std::exception&) {
        return false;
      }
    });
  }
  // The solve at which a background refresh is due: waits for it and swaps its factor in. A failed one (the old
  // matrix was not positive definite, out of memory) leaves the old factor in place with its rent paid, so that the
  // next solve tries again.
  void adopt_pending(SolveInfo& info) {
    const bool ok = m_pending->done.get();
    std::unique_ptr<CholmodFactor> factor = std::move(m_pending->factor);
    std::vector<int> fast = std::move(m_pending->fast);
    std::vector<Mat3> rotations = std::move(m_pending->rotations);
    m_spare_matrix.swap(m_pending->A);
    m_pending.reset();
    if (!ok) {
      m_back = std::move(factor);
      m_rent = purchase_price();
      return;
    }
    // The spare is the old front; while bridging, that was never analysed, and the old revision's factor, which
    // the bridge no longer needs, takes its place, emptied, for its storage.
    m_back = m_bridging ? m_bridge->release_factor() : std::move(m_front);
    if (m_bridging) m_back->clear();
    m_front = std::move(factor);
    m_fast_front = std::move(fast);
    m_rotations_front = std::move(rotations);
    m_have_factor = true;
    m_bridging = false;
    m_bridge.reset();
    fresh_factor();
    info.refactorized = info.background = true;
  }
  // Counts the solve that begins, and says whether the refresh in flight is due: factor_lag_solves solves after it
  // started, or sooner, once the solves since have done as many operations as the factorisation's price (while the
  // iterations grow fast, the old factor costs more per step and the refresh has had as long as those solves took).
  bool pending_due() {
    ++m_pending->solves;
    return m_pending->solves >= m_opt.factor_lag_solves || m_pending->iteration_flops >= purchase_price();
  }
  // Forgets a background refresh without waiting for it (RetiredFactorizations keeps it until it ends).
  void drop_pending() {
    if (m_pending) RetiredFactorizations::retire(std::move(m_pending));
  }
  // Counts the solve's iterations beyond the baseline as rent (see the class comment).
  void pay_rent(int iterations) {
    ++m_solves_since_factor;
    if (m_solves_since_factor == 1) return;  // the first solve with a new factor
    if (m_solves_since_factor == 2 || iterations < m_baseline) m_baseline = iterations;
    m_rent += double(std::max(0, iterations - m_baseline)) * iteration_flops();
  }
  // Operations of one PCG iteration with the factor: solves with L and L^T, a product with A, five vector updates.
  [[nodiscard]] double iteration_flops() const {
    return 4.0 * priced().factor_entries() + 2.0 * double(m_A->nonzeros()) + 10.0 * double(m_A->rows());
  }
  // A factorisation's price in iteration operations (see the class comment).
  [[nodiscard]] double purchase_price() const { return priced().factor_flops() / m_opt.factor_flop_advantage; }
  // The factor whose operation counts price the iterations and the factorisation: the front one, or while the new
  // pattern is not analysed yet (bridging), the old revision's.
  [[nodiscard]] const CholmodFactor& priced() const {
    return !m_front->analyzed() && m_bridge ? m_bridge->old_factor() : *m_front;
  }
  void precondition(const VecX& r, VecX& z) {
    if (!m_use_cholesky)
      z = m_inv_diag.cwiseProduct(r);
    else if (!m_fast.empty())
      m_fast.apply(r, z, [&](const VecX& rr, VecX& w) { apply_factor(rr, w); });
    else
      apply_factor(r, z);
  }
  // z = the front factor's solve applied to r, or the bridge's while bridging (z = r when CHOLMOD fails, out of
  // memory: an unpreconditioned step).
  void apply_factor(const VecX& r, VecX& z) {
    if (m_bridging) {
      m_bridge->apply(r, z, m_single, m_executor, m_warp);
      return;
    }
    const bool warped = !m_warp.empty();
    if (warped) warp_transpose(m_warp, r, m_warped);  // z = Q F^-1 Q^T r (see set_dof_rotations)
    const VecX& rhs = warped ? m_warped : r;
    if (!(m_single ? m_front->solve_single(rhs, z, m_executor) : m_front->solve(rhs, z))) {
      z = r;
      return;
    }
    if (warped) warp_in_place(m_warp, z);
  }
  // The warp of the front factor (or, while bridging, of the bridge's old factor, its rotations carried through T by
  // inherit) for the solve about to run: Q_d = R_d R_d,factor^T for every DOF, or none (without a factor, without
  // rotations for both matrices, or while no DOF has turned by kWarpAngle since the factor's
  // matrix: then the rotations are no larger than their spread across each element, which the warp cannot follow
  // (Q differs between the corners of an element, so the warped element matrices no longer leave translations
  // free), and the unwarped factor does better: a clamped cube sagging under its weight, 1.36 against 2.09
  // iterations per step at tolerance 1e-6).
  void prepare_warp() {
    m_warp.clear();
    if (!m_use_cholesky || !(m_have_factor || m_bridging) || m_rotations_now.empty() ||
        m_rotations_now.size() != m_rotations_front.size() || 3 * Eigen::Index(m_rotations_now.size()) != m_A->rows())
      return;
    constexpr double kWarpAngle = 0.01;  // rad: element matrices change by about 1 % when turned so far
    const double trace_below = 1.0 + 2.0 * std::cos(kWarpAngle);  // tr Q = 1 + 2 cos(angle of Q)
    m_warp.resize(m_rotations_now.size());
    bool turned = false;
    for (std::size_t d = 0; d < m_warp.size(); ++d) {
      m_warp[d] = m_rotations_now[d] * m_rotations_front[d].transpose();
      turned = turned || m_warp[d].trace() < trace_below;
    }
    if (!turned) m_warp.clear();
  }
  // The fast region for the solve about to run (see set_fast_dofs): the fast DOFs of this solve's matrix and of the
  // front factor's (the two matrices differ there by more than the factor's age), solved exactly around the factor
  // (LocalSolve). While bridging, around the bridge, with this matrix's fast DOFs alone (the old factor's are in the
  // old revision's numbering, and the bridge's region covers the cut). When its factorisation fails, the factor
  // alone.
  std::vector<int> fast_region() {
    prepare_warp();
    std::vector<int> region;
    if (m_use_cholesky && m_bridging)
      region = m_fast_now;
    else if (m_use_cholesky && m_have_factor)
      std::set_union(m_fast_now.begin(), m_fast_now.end(), m_fast_front.begin(), m_fast_front.end(),
                     std::back_inserter(region));
    return region;
  }
  // The fast region for the solve about to run (fast_region; on failure it is empty: PCG checks A's definiteness
  // itself), and ax = A x, the product PCG's start needs: side by side on the executor's threads when there is a
  // region to factorise, as neither needs the other (meniscus_punch's contact steps: the region's columns and
  // factorisation about 0.45 ms, the product 0.2 ms, each on one thread while the other does the other). Each
  // gives what it gives alone, so the result is the same either way.
  void prepare_solve(const VecX& x, VecX& ax) {
    std::vector<int> region = fast_region();
    const auto build = [&] { m_fast.build(*m_A, std::move(region)); };
    const auto multiply = [&] { m_A->product(x, ax); };
    if (m_executor == nullptr || m_executor->threads() < 2 || region.empty()) {
      build();
      multiply();
      return;
    }
    (void)m_A->pattern();  // built here, if lazily, not by both tasks at once
    m_executor->parallel_for(2, 1, [&](int b, int e) {
      for (int k = b; k < e; ++k) k == 0 ? build() : multiply();
    });
  }
  // PCG from x, with ax = A x (prepare_solve; taken over as the residual's storage).
  void run_pcg(const VecX& b, VecX& x, VecX& ax, SolveInfo& info, int max_iterations) {
    const double b_norm = b.norm();
    if (!(b_norm > 0.0)) {
      x.setZero();
      info.ok = std::isfinite(b_norm);
      return;
    }
    const double bn = std::max(b_norm, m_reference);  // what the residual is measured against
    // The warm start x is first scaled by the a that minimises the error's A-norm along it, a = x^T b / x^T A x
    // (A x is needed for the residual anyway): a start that overshoots, as the extrapolated increments do when
    // contacts come and go, is then never worse than none (meniscus_punch's contact steps: 7.1 -> 6.3 iterations).
    VecX r;
    r.swap(ax);
    const double xAx = x.dot(r);
    if (xAx > 0.0 && std::isfinite(xAx)) {
      const double a = x.dot(b) / xAx;
      x *= a;
      r *= a;
    }
    r = b - r;
    double rn = r.norm();
    int it = 0;
    // A start that already meets the tolerance (a resting object: meniscus_punch_hd's steps between its cuts) needs
    // no preconditioner application, which would cost as much as an iteration's triangular solves.
    if (rn / bn > m_opt.tolerance && it < max_iterations) iterate(x, r, rn, bn, it, max_iterations);
    info.iterations = it;
    info.residual = rn / bn;
    info.ok = std::isfinite(info.residual) && info.residual <= m_opt.tolerance && x.allFinite();
  }
  // PCG's iterations from x with residual r = b - A x (|r| = rn; measured against bn), until the tolerance or
  // max_iterations (it counts them).
  void iterate(VecX& x, VecX& r, double& rn, double bn, int& it, int max_iterations) {
    SystemOperator& A = *m_A;
    VecX z, p, Ap;
    precondition(r, z);
    p = z;
    double rz = r.dot(z);
    while (rn / bn > m_opt.tolerance && it < max_iterations) {
      A.product(p, Ap);
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
  }

  LinearSolverOptions m_opt;
  bool m_use_cholesky;
  std::unique_ptr<CholmodFactor> m_front = std::make_unique<CholmodFactor>();  ///< the factor the solves use
  std::unique_ptr<CholmodFactor> m_back;      ///< the spare a background refresh fills (null while it runs)
  SpMat m_spare_matrix;                       ///< the last adopted refresh's matrix: the next one's storage
  std::unique_ptr<BackgroundFactorization> m_pending;  ///< the background refresh in flight, if any
  std::unique_ptr<CutBridge> m_bridge;        ///< an inherited factor, until this pattern's first one is in place
  std::unique_ptr<LocalSolve> m_prepared_local;  ///< the bridge's exact solve, from prepare_bridge (until inherit)
  Eigen::Index m_prepared_rows = 0;              ///< the rows (new DOFs) of the transfer it was prepared for
  bool m_bridging = false;                    ///< the solves are preconditioned through m_bridge
  /// While bridging: solves until the new pattern's first factor starts in the background (-1: none pending). The
  /// solve right after a cut builds the bridge, so the factor's assembly and copy wait for the next one.
  int m_pending_in = -1;
  bool m_single;  ///< the preconditioner solves with a single-precision copy of the factor
  bool m_have_factor = false;
  double m_rent = 0.0;  ///< iteration operations paid since the last factorisation
  int m_solves_since_factor = 0;
  int m_baseline = 0;   ///< fewest iterations of a solve one step or more after the factorisation
  VecX m_inv_diag;
  SystemOperator* m_A = nullptr;   ///< the matrix of the solves (factorize_operator)
  MatrixOperator m_stored;         ///< the operator of a matrix given to factorize()
  Executor* m_executor = nullptr;  ///< runs the products with A (null: the calling thread)
  double m_reference = 0.0;        ///< set_reference_norm (0: the residual is measured against |b| alone)
  std::vector<int> m_fast_now;     ///< the fast DOFs of the current matrix (set_fast_dofs)
  std::vector<int> m_fast_front;   ///< those of the matrix the front factor was computed from
  std::vector<Mat3> m_rotations_now;    ///< the DOFs' rotations at the current matrix (set_dof_rotations)
  std::vector<Mat3> m_rotations_front;  ///< those at the matrix the front factor was computed from
  std::vector<Mat3> m_warp;             ///< Q of the current solve (prepare_warp; empty: no warp)
  VecX m_warped;                        ///< work: Q^T r
  LocalSolve m_fast;               ///< the exact solve on the fast region of the current solve
};

}  // namespace

SpMat SystemOperator::columns(const std::vector<int>& dofs) {
  const SpMat& A = matrix();
  std::vector<Eigen::Triplet<double>> t;
  for (std::size_t i = 0; i < dofs.size(); ++i)
    for (int c = 0; c < 3; ++c)
      for (SpMat::InnerIterator it(A, 3 * Eigen::Index(dofs[i]) + c); it; ++it)
        t.emplace_back(int(it.row()), 3 * int(i) + c, it.value());
  SpMat out(A.rows(), 3 * Eigen::Index(dofs.size()));
  out.setFromTriplets(t.begin(), t.end());
  return out;
}

std::unique_ptr<LinearSolver> make_linear_solver(const std::string& name, const LinearSolverOptions& options) {
  if (name == "cholmod") return std::make_unique<CholmodSolver>(options.thorough_ordering);
  if (name == "pcg") return std::make_unique<PcgSolver>(options);
  throw std::invalid_argument("unknown linear solver '" + name + "'");
}

}  // namespace octocut::sim
