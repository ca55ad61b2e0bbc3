#include "octocut/sim/linear_solver.hpp"

#include <Eigen/CholmodSupport>

#include "octocut/sim/parallel.hpp"
#include <cmath>
#include <stdexcept>

namespace octocut::sim {

namespace {

using Cholmod = Eigen::CholmodSupernodalLLT<SpMat, Eigen::Lower>;

// CHOLMOD's default ordering tries AMD and then, for matrices with much fill (every 3D FEM matrix), METIS and
// NESDIS too, keeping the best: 9 ms of analysis for 9k unknowns, most of it in the orderings that lose. AMD alone
// is what octocut uses; the analysis runs after every cut (SPEC §4 stage 5), so its cost counts.
void use_amd_only(Cholmod& llt) {
  llt.cholmod().nmethods = 1;
  llt.cholmod().method[0].ordering = CHOLMOD_AMD;
  llt.cholmod().postorder = 1;
}

// Direct solver: supernodal LL^T; the symbolic analysis is reused until the pattern changes.
class CholmodSolver final : public LinearSolver {
 public:
  // A failed factorisation is reported through SolveInfo and counted by the caller, not printed by CHOLMOD.
  explicit CholmodSolver(int threads) : m_threads(threads) {
    m_llt.cholmod().print = 0;
    use_amd_only(m_llt);
  }
  void analyze_pattern(const SpMat& A) override { m_llt.analyzePattern(A); }
  bool factorize(const SpMat& A) override {
    const BlasThreadsScope blas(m_threads);
    m_llt.factorize(A);
    m_ok = m_llt.info() == Eigen::Success;
    m_A = &A;
    return m_ok;
  }
  SolveInfo solve(const VecX& b, VecX& x) override {
    SolveInfo info;
    info.refactorized = true;
    if (!m_ok) return info;
    x = m_llt.solve(b);
    const double bn = b.norm();
    info.residual = bn > 0.0 ? (b - (*m_A) * x).norm() / bn : 0.0;
    info.ok = x.allFinite() && info.residual < 1e-3;  // catches garbage, not round-off
    return info;
  }
  std::string name() const override { return "cholmod"; }

 private:
  Cholmod m_llt;
  int m_threads = 1;  ///< BLAS threads while factorising
  const SpMat* m_A = nullptr;
  bool m_ok = false;
};

// Conjugate gradients, warm-started from x, with either a lagged Cholesky factor of an earlier system matrix or
// the diagonal as preconditioner. The lagged factor is refreshed only when convergence slows down, so most steps
// pay a few triangular solves instead of a factorisation.
class PcgSolver final : public LinearSolver {
 public:
  explicit PcgSolver(const LinearSolverOptions& o) : m_opt(o), m_use_cholesky(o.preconditioner != "jacobi") {
    m_llt.cholmod().print = 0;
    use_amd_only(m_llt);
    if (o.preconditioner != "jacobi" && o.preconditioner != "cholesky")
      throw std::invalid_argument("unknown preconditioner '" + o.preconditioner + "'");
  }
  void analyze_pattern(const SpMat& A) override {
    if (m_use_cholesky) m_llt.analyzePattern(A);
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
    run_pcg(b, x, info);
    // Slow or failed convergence: refresh the lagged factor from the current matrix and continue from x.
    if (m_use_cholesky && (!info.ok || info.iterations > m_opt.refactor_iterations)) {
      if (!refactor()) return info;
      info.refactorized = true;
      SolveInfo again;
      run_pcg(b, x, again);
      info.ok = again.ok;
      info.iterations += again.iterations;
      info.residual = again.residual;
    }
    return info;
  }
  std::string name() const override { return "pcg"; }

 private:
  bool refactor() {
    const BlasThreadsScope blas(m_opt.threads);
    m_llt.factorize(*m_A);
    m_have_factor = m_llt.info() == Eigen::Success;
    return m_have_factor;
  }
  void precondition(const VecX& r, VecX& z) {
    if (m_use_cholesky)
      z = m_llt.solve(r);
    else
      z = m_inv_diag.cwiseProduct(r);
  }
  void run_pcg(const VecX& b, VecX& x, SolveInfo& info) {
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
    while (rn / bn > m_opt.tolerance && it < m_opt.max_iterations) {
      Ap.noalias() = A * p;
      const double pAp = p.dot(Ap);
      // A non-positive curvature means A (or the preconditioner) is not SPD.
      if (!(pAp > 0.0) || !std::isfinite(rz)) break;
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
  Cholmod m_llt;
  bool m_have_factor = false;
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
