#pragma once
// The numeric Cholesky factorisation of the PCG preconditioner's lagged factor, in single precision, on CHOLMOD's
// supernodal symbolic structure (supernodal_solve.hpp); and in double precision for the small exact solves beside it
// (the contact region's and the cut bridge's, LocalSolve), with the solve that goes with it. Private to sim/src.
//
// The preconditioner reads its factor in single (or half) precision only, so it need not be computed in double:
// single precision halves the bytes the dense kernels move and doubles their vector width. The algorithm is the
// left-looking supernodal one that CHOLMOD uses (cholmod_super_numeric): supernodes in order; each gathers A's
// columns into its dense block, subtracts the updates of the descendants whose rows reach its columns (a SYRK and
// a GEMM per descendant, scattered through a row map), factorises its diagonal block and solves its rows below.
// The dense kernels are the BLAS's and LAPACK's (OpenBLAS: its single-precision kernels for this CPU) above a size
// where a call pays for itself, and plain loops below it. Deterministic: one thread, a fixed order of operations.
// On the meniscus (7k unknowns, 2.3e8 operations) it takes about 9.5 ms where CHOLMOD took 18-20 ms. On the small
// regions (a few hundred unknowns, every supernode below the BLAS's size) CHOLMOD's numeric factorisation costs
// mostly its fixed overhead (permuting A, workspaces, a call per supernode): 0.29 ms for 450 unknowns against 0.1.
#include <vector>

#include "octocut/sim/types.hpp"
#include "supernodal_solve.hpp"

namespace octocut::sim {

/// T: float (the lagged factor) or double (the small exact solves).
template <class T>
class SupernodalFactorizer {
 public:
  /// Factorises P A P^T = L L^T into `x` (CHOLMOD's layout: px[nsuper] values; each supernode a column-major
  /// nsrow x nscol block whose upper triangle is left as it was). A: n x n, both triangles stored (the lower one is
  /// read), compressed and sorted; perm: L's column k is A's column perm[k] (n). False, with x unspecified, when a
  /// pivot is not positive or anything is not finite (the matrix is not positive definite in T's precision), or
  /// when A has an entry outside L's pattern.
  bool factorize(const SupernodalStructure& L, const int* perm, const SpMat& A, std::vector<T>& x);
  /// Forgets the assembly planned for A's pattern: call when L's structure or ordering changes (a new analysis),
  /// since the plan is kept while A's pattern stays the same.
  void forget() {
    m_outer.clear();
    m_inner.clear();
    m_begin.clear();
    m_source.clear();
    m_dest.clear();
  }

 private:
  [[nodiscard]] bool same_pattern(const SpMat& A) const;
  bool plan_assembly(const SupernodalStructure& L, const SpMat& A);
  bool assemble(const SpMat& A, int s, T* x) const;
  void update(const SupernodalStructure& L, int s, int d, int pos1, int pos2, const T* x, T* block);
  void link(const SupernodalStructure& L, int d, int pos);

  const int* m_perm = nullptr;  ///< L's column k is A's column m_perm[k] (n; during factorize)
  std::vector<int> m_iperm;     ///< A's column j is L's column m_iperm[j] (n)
  std::vector<int> m_super_of;  ///< supernode of each column of L (n)
  std::vector<int> m_outer, m_inner;  ///< the pattern of A that the assembly was planned for
  // The assembly: supernode s takes A's values m_source[p] into L's values at m_dest[p] for p in
  // m_begin[s] .. m_begin[s + 1) (the entries on and below the diagonal of P A P^T in its columns).
  std::vector<int> m_begin;   ///< nsuper + 1
  std::vector<int> m_source;  ///< indices into A's values
  std::vector<long> m_dest;   ///< indices into L's values
  std::vector<int> m_map;       ///< row of L -> its place in the current supernode's rows, -1 elsewhere (n)
  std::vector<int> m_head;      ///< per supernode: the first descendant whose next update goes to it, or -1
  std::vector<int> m_next;      ///< per supernode: the next descendant in the same list
  std::vector<int> m_pos;       ///< per supernode: where its rows not yet used for updates begin
  std::vector<T> m_c;           ///< an update's dense block
  std::vector<int> m_relative;  ///< an update's rows' places in the updated supernode's rows
};

extern template class SupernodalFactorizer<float>;
extern template class SupernodalFactorizer<double>;

/// y = (P^T L L^T P)^-1 y in place (n), L's values `x` as SupernodalFactorizer<double> computed them, perm as given
/// to it; `work` (n) is scratch. Column by column, in double.
void supernodal_solve(const SupernodalStructure& L, const int* perm, const std::vector<double>& x, double* y,
                      std::vector<double>& work);

}  // namespace octocut::sim
