#pragma once
// Linear solvers behind one interface (SPEC §3): analyze_pattern once per sparsity pattern, factorize per matrix,
// solve per right-hand side.
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "octocut/sim/types.hpp"

namespace octocut::sim {

class Executor;

/// What one solve did.
struct SolveInfo {
  bool ok = false;         ///< converged (pcg) or factor valid (cholmod)
  int iterations = 0;      ///< pcg iterations (0 for a direct solve)
  double residual = 0.0;   ///< final relative residual |b - A x| / |b|
  bool refactorized = false;  ///< a new factor was put in place during this call
  bool background = false;    ///< pcg: that factor was computed by a background refresh, not by this call
};

/// A symmetric positive definite system matrix that a solver can apply without its entries, and whose entries are
/// assembled only when a solver asks for them (to factorise it, or to solve a region of it exactly). The FEM system
/// applies its element matrices directly (FemSystem::system_product), so a step whose solver needs no entries skips
/// the assembly.
class SystemOperator {
 public:
  virtual ~SystemOperator() = default;
  /// Rows (and columns) of A.
  [[nodiscard]] virtual Eigen::Index rows() const = 0;
  /// Entries of A's pattern (what a product with the assembled A reads; prices a PCG iteration).
  [[nodiscard]] virtual Eigen::Index nonzeros() const = 0;
  /// y = A x (rows()).
  virtual void product(const VecX& x, VecX& y) = 0;
  /// A with both triangles stored, assembled on the first call. The reference stays valid while the operator does.
  virtual const SpMat& matrix() = 0;
  /// Writes A with both triangles into `out`, reusing out's storage where it is large enough (a background
  /// factorisation's own copy). By default a copy of matrix(); the FEM system assembles straight into `out`, so that
  /// its own storage is neither filled nor copied.
  virtual void assemble_into(SpMat& out) { out = matrix(); }
  /// A's sparsity pattern (the values are not to be read): which DOFs A couples, without assembling it.
  virtual const SpMat& pattern() { return matrix(); }
  /// A's columns of the DOFs `dofs` (ascending; columns 3 i, 3 i + 1, 3 i + 2 are those of dofs[i]), with all their
  /// rows (rows() x 3 |dofs|). By default taken from matrix(); the FEM system computes them from the elements
  /// around the DOFs.
  virtual SpMat columns(const std::vector<int>& dofs);
};

/// A solver for symmetric positive definite systems A x = b (A given with both triangles stored).
class LinearSolver {
 public:
  virtual ~LinearSolver() = default;
  /// Symbolic analysis of A's pattern. Call again whenever the pattern changes.
  virtual void analyze_pattern(const SpMat& A) = 0;
  /// Makes the solver ready for the numeric values of A (same pattern as analysed). Returns false when A is not
  /// positive definite.
  virtual bool factorize(const SpMat& A) = 0;
  /// Like factorize(), for a matrix given as an operator: pcg applies it without its entries and assembles it only
  /// when it factorises or solves a region exactly; the others factorise its assembled matrix. The operator must
  /// outlive the solves that follow.
  virtual bool factorize_operator(SystemOperator& A) { return factorize(A.matrix()); }
  /// Solves A x = b for the A last given to factorize(). x holds the warm start on entry (pcg).
  virtual SolveInfo solve(const VecX& b, VecX& x) = 0;
  [[nodiscard]] virtual std::string name() const = 0;
  /// Block size of the graph the last fill-reducing ordering was computed on: 3 when A is made of 3 x 3 blocks (the
  /// FEM system: one node per DOF), 1 for a scalar pattern, 0 when the solver does not factorise.
  [[nodiscard]] virtual int ordering_block_size() const { return 0; }
  /// Called on the solver of a new revision (after analyze_pattern, before the first factorize) with the solver of
  /// the revision it replaces and the transfer T of DOF values from the old revision to the new (new x old DOFs, per
  /// coordinate; see transfer_matrix). pcg with factor_lag_solves > 0 takes over the old lagged factor and
  /// preconditions its first solves with it through T while the new pattern's first factor is computed in the
  /// background; the others ignore it. `previous` is then left without a factor.
  virtual void inherit(LinearSolver& previous, const SpMat& transfer) {}
  /// Called on the solver of a new revision before inherit(), where the revision is prepared (off the step's
  /// thread), with its system at the state carried over (without contacts) and the transfer T: pcg with
  /// factor_lag_solves > 0 factorises there the exact solve on the cut's region that its first solves combine with
  /// the inherited factor, so that the first step after a cut does not. The others ignore it.
  virtual void prepare_bridge(SystemOperator& A, const SpMat& transfer) {}
  /// The executor whose threads the solver may use for its products with A (pcg), or null for the calling thread
  /// alone. The executor must outlive the solver or be replaced first.
  virtual void set_executor(Executor* executor) {}
  /// The DOFs (ascending) whose rows of A change fast from one solve to the next, such as those of the contact
  /// samples: pcg with the lagged Cholesky factor then solves them, and those of the matrix its factor was computed
  /// from, exactly at every solve, combined with the factor as symmetric multiplicative Schwarz (docs/architecture.md,
  /// "Linear solvers"); the others ignore it. Call before factorize(); empty (the default) turns it off.
  virtual void set_fast_dofs(std::vector<int> dofs) {}
  /// The rotation of each DOF's neighbourhood in the current configuration (num_dofs; the corotational frames of
  /// the elements around it, averaged): pcg warps its lagged factor by how far each DOF has turned since the factor's
  /// matrix, Q F^-1 Q^T with Q_d = R_d R_d,factor^T, so that a factor stays as good under rotation as the rotated
  /// matrix Q A_factor Q^T is close to A (docs/architecture.md, "Linear solvers"); the others ignore it. Call before
  /// factorize(); empty (the default) turns it off.
  virtual void set_dof_rotations(std::vector<Mat3> rotations) {}
  /// The norm a solve's residual is measured against where it exceeds |b|: pcg stops once
  /// |b - A x| <= tolerance * max(|b|, reference) and reports that ratio as SolveInfo::residual; the others ignore
  /// it. The simulator passes the norm of the elastic forces its step balances (Simulator::solve_increment), so that
  /// a step near equilibrium, whose out-of-balance right-hand side is orders of magnitude below those forces, is not
  /// resolved to the tolerance of that small remainder. 0 (the default): |b| alone. Holds for the solves that follow.
  virtual void set_reference_norm(double reference) {}
};

struct LinearSolverOptions {
  double tolerance = 1e-6;     ///< pcg: relative residual target (of |b|, or set_reference_norm's norm)
  int max_iterations = 200;    ///< pcg: iteration cap
  /// pcg with the lagged Cholesky preconditioner: how many more floating-point operations per second the supernodal
  /// factorisation does than the triangular solves of a PCG iteration. The factor is refreshed once the iterations
  /// paid for its age cost as much as a factorisation (see make_linear_solver). Measured on the meniscus (7k
  /// unknowns, 2.3e8 operations per factorisation, 5.5e6 per iteration with the single-precision factor): the
  /// single-precision factorisation takes 9.5-10.5 ms on one thread (23 GFlop/s), an iteration 0.35 ms without
  /// contact and 0.6 ms with it (9-16 GFlop/s), so 1.5-2.5; the refresh runs on the second core beside the step, and
  /// `meniscus_punch` runs fastest at 3-4 (real-time factor, median of five runs: 0.379 at 0.75, 0.409 at 3, 0.406
  /// at 4, 0.361 at 6; docs/RESULTS.md). With CHOLMOD's double factorisation (49 ms on two threads then) it was 0.75.
  double factor_flop_advantage = 3.0;
  /// pcg with the lagged Cholesky preconditioner: solve with a single-precision copy of the factor (in single
  /// precision: the triangular solves read L once per iteration, and this halves its bytes). Rounded from CHOLMOD's
  /// double factor, it converges in the same number of iterations; it is computed in single precision itself where
  /// single_precision_factorization allows.
  bool single_precision_factor = true;
  /// pcg with that copy: compute the factor in single precision too (sim/src/supernodal_factor.hpp), about twice
  /// as fast as CHOLMOD's double factorisation, so that the lagged factor can be refreshed twice as often for the
  /// same time on the second core. Its backward error is single precision's, which the smallest eigenvalues' modes
  /// feel most: each such factor is checked on a smooth vector (the copy must solve its own matrix to within
  /// `tolerance` there, so that PCG with a fresh factor still converges at once), and one that fails is replaced by
  /// CHOLMOD's, which then factorises every later matrix of the same pattern.
  bool single_precision_factorization = true;
  /// pcg with that copy: a factor with more entries than this (in the solves' padded layout) is copied in half
  /// precision instead, each column scaled by a power of two (11 significant bits; sim/src/supernode_kernels.hpp),
  /// which halves the bytes each triangular solve streams once the factor no longer fits the caches: at the
  /// meniscus's base level 6 (13.6 million entries) a preconditioner application takes 0.97 instead of 1.37 ms, and
  /// the 30k-element cube of `octocut bench scaling` steps in 41 instead of 49 ms (docs/RESULTS.md). Below the
  /// threshold the factor fits the caches and half precision saves nothing. The copy is kept in half precision only
  /// when it solves its own matrix to within `half_precision_probe` (relative error on a fixed vector); otherwise, as
  /// for stiff nearly incompressible tissue whose factor needs more digits, in single precision.
  std::size_t half_precision_entries = std::size_t(1) << 21;
  double half_precision_probe = 0.01;
  /// pcg with the lagged Cholesky preconditioner: a refresh of the factor runs on a second thread and is swapped in
  /// this many solves after it started (the solve then waits for it if need be); 0 refreshes at once, stalling that
  /// solve. The first factor of a pattern, and the refresh after a solve that fails to converge, are always at once.
  int factor_lag_solves = 0;
  std::string preconditioner = "cholesky";  ///< pcg: "cholesky" (lagged factor) | "jacobi"
  /// Cholesky factors: order with the better of AMD and CHOLMOD's nested dissection instead of AMD alone: the one
  /// whose triangular solves cost less on two threads (the entries of L in the top of the elimination tree, solved by
  /// one thread, plus those of the larger of the two parts solved side by side). The analysis then takes 5-10 ms more
  /// (at a few thousand nodes); a blocky 3D mesh gets a factor with 20-25 % fewer entries and half the operations (a
  /// 10^3 cube), steps 10-30 % faster at 1k-30k elements; the thin meniscus gets as many entries, but half as many in
  /// the serial top (6 % less time per PCG iteration). Worth it where a pattern is used for long: the simulator asks
  /// for it for the model it starts with, not for the revisions a cut prepares (their analysis is on the cut's path
  /// or in the background).
  bool thorough_ordering = false;
};

/// Creates "cholmod" (supernodal LL^T, exact every call) or "pcg" (warm-started conjugate gradients preconditioned
/// by a lagged CHOLMOD factorisation, refreshed once the extra iterations it has cost since it was computed add up to
/// the cost of a factorisation, or at once when a solve fails to converge). Throws on an unknown name.
std::unique_ptr<LinearSolver> make_linear_solver(const std::string& name, const LinearSolverOptions& options);

}  // namespace octocut::sim
