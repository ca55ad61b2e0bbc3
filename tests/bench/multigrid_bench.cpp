// What the geometric multigrid that issue 20 names would cost against the lagged Cholesky factor that octocut uses,
// on the best case for multigrid: `octocut bench scaling`'s clamped soft cube (E = 5e4 Pa, nu = 0.45, B-bar
// hexahedra, 1 mm leaves, rho = 1000 kg/m^3, implicit Euler at dt = 1 ms: A = M + dt^2 K, the bottom face clamped),
// on a uniform grid whose levels coarsen by two exactly. Not a solver octocut ships: a measurement (label bench).
//
// Per size it prints the multigrid's set-up (Galerkin products), the cost of one V-cycle and of one PCG iteration
// with it, its PCG iterations from a zero start to a relative residual of 1e-2 and 1e-4 (right-hand side: one step's
// gravity impulse dt M g), and the same for octocut's `pcg` with its lagged factor (a fresh factor: the best case a
// step sees), with the factorisation's time. The V-cycle: Chebyshev smoothing of degree K (2) on the Jacobi-scaled
// operator before and after, trilinear prolongation P, Galerkin coarse operators P^T A P, a sparse Cholesky on the
// coarsest level (<= 5^3 nodes). Threads: the products run on an octocut Executor over the machine's cores.
//
// Usage: bench_multigrid [--degree K] [--ratio R] [n ...]   (n: leaves per side, even; default 8 12 16 20 24 32)
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "octocut/sim/hex_element.hpp"
#include "octocut/sim/linear_solver.hpp"
#include "octocut/sim/parallel.hpp"

namespace {

using octocut::sim::SpMat;
using octocut::sim::VecX;
using RowMat = Eigen::SparseMatrix<double, Eigen::RowMajor, int>;
using Clock = std::chrono::steady_clock;

int g_degree = 2;       // the Chebyshev smoother's degree (--degree)
double g_ratio = 10.0;  // lambda_max over the smoothed interval's lower end (--ratio)

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// The machine's cores, for the products here and for octocut's solver (as the simulator gives its solver).
octocut::sim::Executor& cores() {
  static octocut::sim::Executor executor(0);
  return executor;
}

/// y = A x on the cores (A row-major).
void product(const RowMat& A, const VecX& x, VecX& y) {
  y.resize(A.rows());
  cores().parallel_for(int(A.rows()), 2048, [&](int begin, int end) {
    for (int i = begin; i < end; ++i) {
      double s = 0.0;
      for (RowMat::InnerIterator it(A, i); it; ++it) s += it.value() * x[it.index()];
      y[i] = s;
    }
  });
}

/// The grid of n^3 leaves of edge h: node (i, j, k) has index i + (n+1) (j + (n+1) k); DOF 3 node + d. The bottom
/// face (k = 0) is clamped and eliminated: `free_of[dof]` is its row in the system, or -1.
struct Grid {
  int n = 0;
  std::vector<int> free_of;  // (n+1)^3 * 3
  int free_count = 0;
  [[nodiscard]] int node(int i, int j, int k) const { return i + (n + 1) * (j + (n + 1) * k); }
  explicit Grid(int leaves) : n(leaves) {
    const int nodes = (n + 1) * (n + 1) * (n + 1);
    free_of.assign(std::size_t(3 * nodes), -1);
    for (int k = 1; k <= n; ++k)
      for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i)
          for (int d = 0; d < 3; ++d) free_of[std::size_t(3 * node(i, j, k) + d)] = free_count++;
  }
};

/// A = M + dt^2 K on the free DOFs (both triangles), and the gravity impulse b = dt M g.
void assemble(const Grid& g, double h, SpMat& A, VecX& b) {
  const double E = 5e4, nu = 0.45, rho = 1000.0, dt = 1e-3;
  const octocut::sim::Mat24 K = (dt * dt * E * h) * octocut::sim::unit_hex_stiffness_bbar(nu);
  const double corner_mass = rho * h * h * h / 8.0;  // kg, lumped
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(std::size_t(g.n) * g.n * g.n * 24 * 24);
  b = VecX::Zero(g.free_count);
  for (int k = 0; k < g.n; ++k)
    for (int j = 0; j < g.n; ++j)
      for (int i = 0; i < g.n; ++i) {
        int dof[24];
        for (int c = 0; c < 8; ++c)
          for (int d = 0; d < 3; ++d)
            dof[3 * c + d] = g.free_of[std::size_t(3 * g.node(i + (c & 1), j + (c >> 1 & 1), k + (c >> 2 & 1)) + d)];
        for (int r = 0; r < 24; ++r) {
          if (dof[r] < 0) continue;
          t.emplace_back(dof[r], dof[r], corner_mass);
          if (r % 3 == 2) b[dof[r]] += dt * corner_mass * -9.81;
          for (int c = 0; c < 24; ++c)
            if (dof[c] >= 0) t.emplace_back(dof[r], dof[c], K(r, c));
        }
      }
  A.resize(g.free_count, g.free_count);
  A.setFromTriplets(t.begin(), t.end());
}

/// Trilinear prolongation from the grid of n/2 leaves to that of n leaves (free DOFs to free DOFs).
SpMat prolongation(const Grid& fine, const Grid& coarse) {
  std::vector<Eigen::Triplet<double>> t;
  const int n = fine.n;
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        const int f = fine.node(i, j, k);
        if (fine.free_of[std::size_t(3 * f)] < 0) continue;
        // Each fine coordinate is a coarse node (even) or halfway between two (odd).
        for (int c = 0; c < 8; ++c) {
          const int ci = (i + (c & 1)) / 2, cj = (j + (c >> 1 & 1)) / 2, ck = (k + (c >> 2 & 1)) / 2;
          if (((c & 1) && i % 2 == 0) || ((c >> 1 & 1) && j % 2 == 0) || ((c >> 2 & 1) && k % 2 == 0)) continue;
          const double w = (i % 2 ? 0.5 : 1.0) * (j % 2 ? 0.5 : 1.0) * (k % 2 ? 0.5 : 1.0);
          const int cn = coarse.node(ci, cj, ck);
          for (int d = 0; d < 3; ++d) {
            const int col = coarse.free_of[std::size_t(3 * cn + d)];
            if (col >= 0) t.emplace_back(fine.free_of[std::size_t(3 * f + d)], col, w);
          }
        }
      }
  SpMat P(fine.free_count, coarse.free_count);
  P.setFromTriplets(t.begin(), t.end());
  return P;
}

/// One level of the hierarchy: its operator, the Jacobi scaling, the Chebyshev interval, and P to the next.
struct Level {
  RowMat A;
  VecX inverse_diagonal;
  double lambda_max = 1.0;  // of D^-1 A, estimated
  RowMat P, R;              // to / from the next coarser level
  VecX r, tmp;              // work vectors
};

class Multigrid {
 public:
  Multigrid(const SpMat& A, int n, double* setup_ms) {
    const Clock::time_point t0 = Clock::now();
    SpMat current = A;
    int leaves = n;
    for (;;) {
      Level level;
      level.A = current;
      level.inverse_diagonal = current.diagonal().cwiseInverse();
      level.lambda_max = estimate_lambda_max(level);
      const bool coarsest = leaves % 2 != 0 || leaves <= 4;
      if (coarsest) {
        m_coarse.compute(current);
        m_levels.push_back(std::move(level));
        break;
      }
      const SpMat P = prolongation(Grid(leaves), Grid(leaves / 2));
      const SpMat R = P.transpose();
      level.P = P;
      level.R = R;
      current = SpMat(R * current) * P;
      m_levels.push_back(std::move(level));
      leaves /= 2;
    }
    *setup_ms = ms_since(t0);
  }

  [[nodiscard]] int levels() const { return int(m_levels.size()); }
  [[nodiscard]] Eigen::Index coarsest_rows() const { return m_levels.back().A.rows(); }

  /// z = V-cycle(r) (symmetric: usable as a PCG preconditioner).
  void apply(const VecX& r, VecX& z) { cycle(0, r, z); }

 private:
  static double estimate_lambda_max(Level& level) {
    VecX v = VecX::Ones(level.A.rows()), w;
    double lambda = 1.0;
    for (int it = 0; it < 15; ++it) {
      product(level.A, v, w);
      w = w.cwiseProduct(level.inverse_diagonal);
      lambda = w.norm() / v.norm();
      v = w / w.norm();
    }
    return 1.1 * lambda;
  }

  /// x += p(D^-1 A) D^-1 (b - A x): Chebyshev of degree g_degree on [lambda_max / g_ratio, lambda_max].
  void smooth(Level& L, const VecX& b, VecX& x) {
    const double hi = L.lambda_max, lo = hi / g_ratio;
    const double theta = 0.5 * (hi + lo), delta = 0.5 * (hi - lo);
    const double sigma = theta / delta;
    double rho = 1.0 / sigma;
    product(L.A, x, L.tmp);
    L.r = b - L.tmp;
    VecX d = L.r.cwiseProduct(L.inverse_diagonal) / theta;
    for (int k = 0; k < g_degree; ++k) {
      x += d;
      if (k + 1 == g_degree) break;
      product(L.A, d, L.tmp);
      L.r -= L.tmp;
      const double rho_next = 1.0 / (2.0 * sigma - rho);
      d = (rho_next * rho) * d + (2.0 * rho_next / delta) * L.r.cwiseProduct(L.inverse_diagonal);
      rho = rho_next;
    }
  }

  void cycle(std::size_t l, const VecX& b, VecX& x) {
    Level& L = m_levels[l];
    if (l + 1 == m_levels.size()) {
      x = m_coarse.solve(b);
      return;
    }
    x = VecX::Zero(b.size());
    smooth(L, b, x);
    product(L.A, x, L.tmp);
    L.r = b - L.tmp;
    VecX rc, xc;
    product(L.R, L.r, rc);
    cycle(l + 1, rc, xc);
    product(L.P, xc, L.tmp);
    x += L.tmp;
    smooth(L, b, x);
  }

  std::vector<Level> m_levels;
  Eigen::SimplicialLLT<SpMat> m_coarse;
};

struct PcgResult {
  int iterations_1e2 = -1, iterations_1e4 = -1;
  double ms = 0.0;
};

/// PCG from x = 0 to |r| <= 1e-4 |b|, recording when 1e-2 was reached.
template <class Precondition>
PcgResult pcg(const RowMat& A, const VecX& b, Precondition&& precondition) {
  const Clock::time_point t0 = Clock::now();
  PcgResult out;
  VecX x = VecX::Zero(b.size()), r = b, z, p, q;
  precondition(r, z);
  p = z;
  double rz = r.dot(z);
  const double bn = b.norm();
  for (int it = 1; it <= 500; ++it) {
    product(A, p, q);
    const double alpha = rz / p.dot(q);
    x += alpha * p;
    r -= alpha * q;
    const double rel = r.norm() / bn;
    if (out.iterations_1e2 < 0 && rel <= 1e-2) out.iterations_1e2 = it;
    if (rel <= 1e-4) {
      out.iterations_1e4 = it;
      break;
    }
    precondition(r, z);
    const double rz_next = r.dot(z);
    p = z + (rz_next / rz) * p;
    rz = rz_next;
  }
  out.ms = ms_since(t0);
  return out;
}

template <class F>
double median_ms(int repeats, F&& f) {
  std::vector<double> t;
  for (int i = 0; i < repeats; ++i) {
    const Clock::time_point t0 = Clock::now();
    f();
    t.push_back(ms_since(t0));
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

void run(int n) {
  const double h = 0.001;  // m
  const Grid grid(n);
  SpMat A;
  VecX b;
  assemble(grid, h, A, b);
  const RowMat Ar = A;

  double setup_ms = 0.0;
  Multigrid mg(A, n, &setup_ms);
  VecX z;
  const double vcycle_ms = median_ms(9, [&] { mg.apply(b, z); });
  const double product_ms = median_ms(9, [&] { product(Ar, b, z); });
  const PcgResult with_mg = pcg(Ar, b, [&](const VecX& r, VecX& out) { mg.apply(r, out); });

  // octocut's pcg with a fresh lagged factor (single precision, its own kernels), from x = 0.
  octocut::sim::LinearSolverOptions options;
  options.tolerance = 1e-4;
  options.thorough_ordering = true;  // as the simulator asks for the model it starts with
  const std::unique_ptr<octocut::sim::LinearSolver> solver = octocut::sim::make_linear_solver("pcg", options);
  solver->set_executor(&cores());
  const Clock::time_point f0 = Clock::now();
  solver->analyze_pattern(A);
  solver->factorize(A);
  const double factor_ms = ms_since(f0);
  octocut::sim::SolveInfo info;
  const double solve_ms = median_ms(9, [&] {
    VecX x = VecX::Zero(b.size());
    info = solver->solve(b, x);
  });
  std::printf("%5d %8d %8lld %3d %7lld %9.2f %8.3f %9.3f %6d %6d %9.2f | %9.2f %8.3f %5d\n", n * n * n,
              int(A.rows()), (long long)A.nonZeros(), mg.levels(), (long long)mg.coarsest_rows(), setup_ms, product_ms,
              vcycle_ms, with_mg.iterations_1e2, with_mg.iterations_1e4, with_mg.ms, factor_ms, solve_ms,
              info.iterations);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> sizes;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--degree" && i + 1 < argc) {
      g_degree = std::max(1, std::atoi(argv[++i]));
    } else if (a == "--ratio" && i + 1 < argc) {
      g_ratio = std::max(1.5, std::atof(argv[++i]));
    } else {
      sizes.push_back(std::atoi(argv[i]));
    }
  }
  if (sizes.empty()) sizes = {8, 12, 16, 20, 24, 32};
  std::printf("# multigrid (V-cycle, Chebyshev %d+%d on [lambda_max/%g, lambda_max], Galerkin) against octocut's pcg"
              " with a fresh lagged factor\n", g_degree, g_degree, g_ratio);
  std::printf("# elems     dofs      nnz lev coarse  setup_ms  Ax_ms  vcycle_ms  it1e-2 it1e-4  mgpcg_ms |"
              " factor_ms solve_ms iters\n");
  for (const int n : sizes) {
    if (n < 2 || n % 2 != 0) {
      std::fprintf(stderr, "bench_multigrid: n must be even and >= 2, got %d\n", n);
      return 2;
    }
    run(n);
  }
  return 0;
}
