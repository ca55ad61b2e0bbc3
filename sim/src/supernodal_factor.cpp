#include "supernodal_factor.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>

// The BLAS's and LAPACK's kernels in single and double precision (Fortran interface; the trailing arguments are the
// lengths of the character arguments, which gfortran's libraries expect and OpenBLAS ignores).
extern "C" {
void ssyrk_(const char* uplo, const char* trans, const int* n, const int* k, const float* alpha, const float* a,
            const int* lda, const float* beta, float* c, const int* ldc, std::size_t, std::size_t);
void sgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k, const float* alpha,
            const float* a, const int* lda, const float* b, const int* ldb, const float* beta, float* c,
            const int* ldc, std::size_t, std::size_t);
void spotrf_(const char* uplo, const int* n, float* a, const int* lda, int* info, std::size_t);
void strsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m, const int* n,
            const float* alpha, const float* a, const int* lda, float* b, const int* ldb, std::size_t, std::size_t,
            std::size_t, std::size_t);
void dsyrk_(const char* uplo, const char* trans, const int* n, const int* k, const double* alpha, const double* a,
            const int* lda, const double* beta, double* c, const int* ldc, std::size_t, std::size_t);
void dgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k, const double* alpha,
            const double* a, const int* lda, const double* b, const int* ldb, const double* beta, double* c,
            const int* ldc, std::size_t, std::size_t);
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info, std::size_t);
void dtrsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m, const int* n,
            const double* alpha, const double* a, const int* lda, double* b, const int* ldb, std::size_t, std::size_t,
            std::size_t, std::size_t);
}

namespace octocut::sim {
namespace {

// Multiply-adds below which a plain loop beats a call into the BLAS (its dispatch and packing cost about a
// microsecond).
constexpr double kBlasWork = 2048.0;

// The kernels by precision.
void syrk(const int* n, const int* k, const float* a, const int* lda, float* c, const int* ldc) {
  const float one = 1.0f, zero = 0.0f;
  ssyrk_("L", "N", n, k, &one, a, lda, &zero, c, ldc, 1, 1);
}
void syrk(const int* n, const int* k, const double* a, const int* lda, double* c, const int* ldc) {
  const double one = 1.0, zero = 0.0;
  dsyrk_("L", "N", n, k, &one, a, lda, &zero, c, ldc, 1, 1);
}
void gemm_nt(const int* m, const int* n, const int* k, const float* a, const int* lda, const float* b, const int* ldb,
             float* c, const int* ldc) {
  const float one = 1.0f, zero = 0.0f;
  sgemm_("N", "T", m, n, k, &one, a, lda, b, ldb, &zero, c, ldc, 1, 1);
}
void gemm_nt(const int* m, const int* n, const int* k, const double* a, const int* lda, const double* b,
             const int* ldb, double* c, const int* ldc) {
  const double one = 1.0, zero = 0.0;
  dgemm_("N", "T", m, n, k, &one, a, lda, b, ldb, &zero, c, ldc, 1, 1);
}
void potrf(const int* n, float* a, const int* lda, int* info) { spotrf_("L", n, a, lda, info, 1); }
void potrf(const int* n, double* a, const int* lda, int* info) { dpotrf_("L", n, a, lda, info, 1); }
void trsm_rlt(const int* m, const int* n, const float* a, const int* lda, float* b, const int* ldb) {
  const float one = 1.0f;
  strsm_("R", "L", "T", "N", m, n, &one, a, lda, b, ldb, 1, 1, 1, 1);
}
void trsm_rlt(const int* m, const int* n, const double* a, const int* lda, double* b, const int* ldb) {
  const double one = 1.0;
  dtrsm_("R", "L", "T", "N", m, n, &one, a, lda, b, ldb, 1, 1, 1, 1);
}

// X (m x n, leading dimension ld) := X D^-T, D (n x n, lower, leading dimension ld) the diagonal block above X.
template <class T>
void solve_below(const T* D, T* X, int m, int n, int ld) {
  if (m <= 0) return;
  if (double(m) * n * n < 2.0 * kBlasWork) {
    for (int j = 0; j < n; ++j) {
      T* xj = X + std::ptrdiff_t(j) * ld;
      for (int k = 0; k < j; ++k) {
        const T djk = D[j + std::ptrdiff_t(k) * ld];
        const T* xk = X + std::ptrdiff_t(k) * ld;
        for (int i = 0; i < m; ++i) xj[i] -= xk[i] * djk;
      }
      const T inv = T(1) / D[j + std::ptrdiff_t(j) * ld];
      for (int i = 0; i < m; ++i) xj[i] *= inv;
    }
    return;
  }
  trsm_rlt(&m, &n, D, &ld, X, &ld);
}

// D (n x n, lower, leading dimension ld) := its Cholesky factor in place; false when a pivot is not positive.
template <class T>
bool factor_diagonal(T* D, int n, int ld) {
  if (n >= 16) {
    int info = 0;
    potrf(&n, D, &ld, &info);
    return info == 0;
  }
  for (int j = 0; j < n; ++j) {
    T* dj = D + std::ptrdiff_t(j) * ld;
    for (int k = 0; k < j; ++k) {
      const T* dk = D + std::ptrdiff_t(k) * ld;
      const T djk = dk[j];
      for (int i = j; i < n; ++i) dj[i] -= dk[i] * djk;
    }
    if (!(dj[j] > T(0))) return false;
    const T root = std::sqrt(dj[j]);
    dj[j] = root;
    const T inv = T(1) / root;
    for (int i = j + 1; i < n; ++i) dj[i] *= inv;
  }
  return true;
}

}  // namespace

template <class T>
bool SupernodalFactorizer<T>::factorize(const SupernodalStructure& L, const int* perm, const SpMat& A,
                                        std::vector<T>& x) {
  const int n = L.n;
  if (A.rows() != n || A.cols() != n || !A.isCompressed()) return false;
  m_perm = perm;
  m_iperm.resize(std::size_t(n));
  m_super_of.resize(std::size_t(n));
  for (int k = 0; k < n; ++k) m_iperm[std::size_t(perm[k])] = k;
  for (int s = 0; s < L.nsuper; ++s)
    for (int k = L.super[s]; k < L.super[s + 1]; ++k) m_super_of[std::size_t(k)] = s;
  m_map.assign(std::size_t(n), -1);
  if (!same_pattern(A) && !plan_assembly(L, A)) return false;
  m_head.assign(std::size_t(L.nsuper), -1);
  m_next.assign(std::size_t(L.nsuper), -1);
  m_pos.assign(std::size_t(L.nsuper), 0);
  // Each supernode's block is zeroed when its turn comes (below): it is then in the cache for its assembly and
  // updates, where zeroing all of x first streamed it through memory once more.
  const auto size = std::size_t(L.px[L.nsuper]);
  reserve_with_room(x, size);
  x.resize(size);
  for (int s = 0; s < L.nsuper; ++s) {
    const int nscol = L.super[s + 1] - L.super[s], nsrow = L.pi[s + 1] - L.pi[s];
    const int* rows = L.rows + L.pi[s];
    T* block = x.data() + L.px[s];
    std::fill(block, block + std::ptrdiff_t(nscol) * nsrow, T(0));
    for (int i = 0; i < nsrow; ++i) m_map[std::size_t(rows[i])] = i;
    const bool ok = assemble(A, s, x.data());
    // The descendants whose next rows fall in this supernode's columns (each then moves on to its next ancestor).
    for (int d = m_head[std::size_t(s)]; ok && d >= 0;) {
      const int next = m_next[std::size_t(d)];
      const int nsrow_d = L.pi[d + 1] - L.pi[d];
      const int* rows_d = L.rows + L.pi[d];
      const int pos1 = m_pos[std::size_t(d)];
      int pos2 = pos1;
      while (pos2 < nsrow_d && rows_d[pos2] < L.super[s + 1]) ++pos2;
      update(L, s, d, pos1, pos2, x.data(), block);
      link(L, d, pos2);
      d = next;
    }
    for (int i = 0; i < nsrow; ++i) m_map[std::size_t(rows[i])] = -1;
    if (!ok) return false;
    // The diagonal block's Cholesky factor in place, then the rows below it.
    if (!factor_diagonal(block, nscol, nsrow)) return false;
    solve_below(block, block + nscol, nsrow - nscol, nscol, nsrow);
    // A non-finite entry below a diagonal reaches, squared, the diagonal of its row's column, where a later
    // supernode (or this one) finds it: checking the diagonals checks every entry.
    for (int j = 0; j < nscol; ++j)
      if (!(block[j + std::ptrdiff_t(j) * nsrow] > T(0)) || !std::isfinite(block[j + std::ptrdiff_t(j) * nsrow]))
        return false;
    m_head[std::size_t(s)] = -1;
    link(L, s, nscol);
  }
  return true;
}

// Whether A has the pattern that the assembly was planned for.
template <class T>
bool SupernodalFactorizer<T>::same_pattern(const SpMat& A) const {
  const std::size_t cols = std::size_t(A.cols()) + 1, nnz = std::size_t(A.nonZeros());
  return m_outer.size() == cols && m_inner.size() == nnz &&
         std::memcmp(m_outer.data(), A.outerIndexPtr(), cols * sizeof(int)) == 0 &&
         std::memcmp(m_inner.data(), A.innerIndexPtr(), nnz * sizeof(int)) == 0;
}

// Where each of A's entries on and below the diagonal of P A P^T goes in L's values, by supernode (m_begin,
// m_source, m_dest); false when an entry lies outside L's pattern.
template <class T>
bool SupernodalFactorizer<T>::plan_assembly(const SupernodalStructure& L, const SpMat& A) {
  const int* outer = A.outerIndexPtr();
  const int* inner = A.innerIndexPtr();
  m_outer.clear();
  m_inner.clear();
  m_begin.assign(std::size_t(L.nsuper) + 1, 0);
  m_source.clear();
  m_dest.clear();
  m_source.reserve(std::size_t(A.nonZeros()) / 2 + std::size_t(L.n));
  m_dest.reserve(m_source.capacity());
  for (int s = 0; s < L.nsuper; ++s) {
    const int k1 = L.super[s], nsrow = L.pi[s + 1] - L.pi[s];
    const int* rows = L.rows + L.pi[s];
    for (int i = 0; i < nsrow; ++i) m_map[std::size_t(rows[i])] = i;
    bool inside = true;
    for (int k = k1; k < L.super[s + 1]; ++k) {
      const int j = m_perm[k];
      for (int t = outer[j]; t < outer[j + 1]; ++t) {
        const int i = m_iperm[std::size_t(inner[t])];
        if (i < k) continue;
        const int at = m_map[std::size_t(i)];
        inside = inside && at >= 0;
        m_source.push_back(t);
        m_dest.push_back(long(L.px[s]) + long(k - k1) * nsrow + at);
      }
    }
    for (int i = 0; i < nsrow; ++i) m_map[std::size_t(rows[i])] = -1;
    if (!inside) return false;
    m_begin[std::size_t(s) + 1] = int(m_source.size());
  }
  assign_with_room(m_outer, outer, outer + A.cols() + 1);
  assign_with_room(m_inner, inner, inner + A.nonZeros());
  return true;
}

// Adds A's entries of supernode s's columns on and below the diagonal (of P A P^T) into L's values x (planned by
// plan_assembly); false for a non-finite one.
template <class T>
bool SupernodalFactorizer<T>::assemble(const SpMat& A, int s, T* x) const {
  const double* values = A.valuePtr();
  bool finite = true;
  for (int p = m_begin[std::size_t(s)]; p < m_begin[std::size_t(s) + 1]; ++p) {
    const double v = values[m_source[std::size_t(p)]];
    finite = finite && std::isfinite(v);
    x[m_dest[std::size_t(p)]] += T(v);
  }
  return finite;
}

// Subtracts descendant d's update of supernode s (whose rows m_map holds) from s's block: the rows of d
// from pos1 on times the rows pos1 .. pos2 (those in supernode s's columns), transposed.
template <class T>
void SupernodalFactorizer<T>::update(const SupernodalStructure& L, int s, int d, int pos1, int pos2, const T* x,
                                     T* block) {
  const int ndcol = L.super[d + 1] - L.super[d], nsrow_d = L.pi[d + 1] - L.pi[d];
  const int ndrow1 = pos2 - pos1, ndrow2 = nsrow_d - pos1, ndrow3 = ndrow2 - ndrow1;
  const int* rows = L.rows + L.pi[d] + pos1;
  const T* Ld = x + L.px[d] + pos1;  // rows pos1 .. of d's columns, leading dimension nsrow_d
  const int k1 = L.super[s], ld = L.pi[s + 1] - L.pi[s];  // the current supernode's first column, its rows
  if (double(ndrow1) * ndrow2 * ndcol < kBlasWork) {
    for (int j = 0; j < ndrow1; ++j) {
      T* target = block + std::ptrdiff_t(rows[j] - k1) * ld;
      for (int i = j; i < ndrow2; ++i) {
        T sum = T(0);
        for (int k = 0; k < ndcol; ++k)
          sum += Ld[i + std::ptrdiff_t(k) * nsrow_d] * Ld[j + std::ptrdiff_t(k) * nsrow_d];
        target[m_map[std::size_t(rows[i])]] -= sum;
      }
    }
    return;
  }
  m_c.resize(std::size_t(ndrow1) * std::size_t(ndrow2));
  syrk(&ndrow1, &ndcol, Ld, &nsrow_d, m_c.data(), &ndrow2);
  if (ndrow3 > 0) gemm_nt(&ndrow3, &ndrow1, &ndcol, Ld + ndrow1, &nsrow_d, Ld, &nsrow_d, m_c.data() + ndrow1, &ndrow2);
  m_relative.resize(std::size_t(ndrow2));
  for (int i = 0; i < ndrow2; ++i) m_relative[std::size_t(i)] = m_map[std::size_t(rows[i])];
  const int* relative = m_relative.data();
  for (int j = 0; j < ndrow1; ++j) {
    T* target = block + std::ptrdiff_t(rows[j] - k1) * ld;
    const T* c = m_c.data() + std::ptrdiff_t(j) * ndrow2;
    for (int i = j; i < ndrow2; ++i) target[relative[i]] -= c[i];
  }
}

// Puts supernode d in the list of the supernode that its rows from pos on reach first (none when it has none).
template <class T>
void SupernodalFactorizer<T>::link(const SupernodalStructure& L, int d, int pos) {
  m_pos[std::size_t(d)] = pos;
  if (pos >= L.pi[d + 1] - L.pi[d]) return;
  const int ancestor = m_super_of[std::size_t(L.rows[L.pi[d] + pos])];
  m_next[std::size_t(d)] = m_head[std::size_t(ancestor)];
  m_head[std::size_t(ancestor)] = d;
}

template class SupernodalFactorizer<float>;
template class SupernodalFactorizer<double>;

void supernodal_solve(const SupernodalStructure& L, const int* perm, const std::vector<double>& x, double* y,
                      std::vector<double>& work) {
  const int n = L.n;
  work.resize(std::size_t(n));
  double* w = work.data();
  for (int k = 0; k < n; ++k) w[k] = y[perm[k]];
  // L w = w: each column divided by its diagonal, then taken from the rows below.
  for (int s = 0; s < L.nsuper; ++s) {
    const int k1 = L.super[s], nscol = L.super[s + 1] - k1, nsrow = L.pi[s + 1] - L.pi[s];
    const int* rows = L.rows + L.pi[s];
    const double* block = x.data() + L.px[s];
    for (int j = 0; j < nscol; ++j) {
      const double* c = block + std::ptrdiff_t(j) * nsrow;
      const double v = w[k1 + j] / c[j];
      w[k1 + j] = v;
      for (int i = j + 1; i < nsrow; ++i) w[rows[i]] -= c[i] * v;
    }
  }
  // L^T w = w: each column's rows below taken off, then divided by its diagonal; supernodes and columns backwards.
  for (int s = L.nsuper - 1; s >= 0; --s) {
    const int k1 = L.super[s], nscol = L.super[s + 1] - k1, nsrow = L.pi[s + 1] - L.pi[s];
    const int* rows = L.rows + L.pi[s];
    const double* block = x.data() + L.px[s];
    for (int j = nscol - 1; j >= 0; --j) {
      const double* c = block + std::ptrdiff_t(j) * nsrow;
      double v = w[k1 + j];
      for (int i = j + 1; i < nsrow; ++i) v -= c[i] * w[rows[i]];
      w[k1 + j] = v / c[j];
    }
  }
  for (int k = 0; k < n; ++k) y[perm[k]] = w[k];
}

}  // namespace octocut::sim
