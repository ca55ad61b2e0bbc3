#include "octocut/sim/fem_system.hpp"

#include <algorithm>
#include <span>

#include "element_kernels.hpp"
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

// Every element's gather list, in one array (the element loops walk them in order, with no pointer to follow per
// element): element e's entries are entries[begin[e] .. begin[e + 1]).
struct GatherLists {
  std::vector<GatherEntry> entries;
  std::vector<int> begin{0};  ///< num_elements + 1
  [[nodiscard]] std::size_t size() const { return begin.size() - 1; }
  [[nodiscard]] std::span<const GatherEntry> operator[](std::size_t e) const {
    return {entries.data() + begin[e], entries.data() + begin[e + 1]};
  }
};

// Positions of an element's 8 slots as a 24-vector and as a 3 x 8 matrix.
void element_slots(const std::vector<Vec3>& slots, int e, Vec24& xe, Eigen::Matrix<double, 3, 8>& xm) {
  for (int a = 0; a < 8; ++a) {
    const Vec3& p = slots[8 * std::size_t(e) + std::size_t(a)];
    xe.segment<3>(3 * a) = p;
    xm.col(a) = p;
  }
}

// The block structure of the system matrix (3 x 3 blocks of DOF pairs) in flat arrays. Every diagonal block is
// present, constrained DOFs included.
struct BlockPattern {
  std::vector<int> elem_ptr;  // start of each element's free DOFs in elem_dof (num_elements + 1)
  std::vector<int> elem_dof;  // the free DOFs each element couples, sorted and unique per element
  std::vector<int> col_ptr;   // start of each block column's rows in col_row (num_dofs + 1)
  std::vector<int> col_row;   // per block column the sorted block rows: the union of its elements' DOFs
};

// The free DOFs each element couples (elem_ptr, elem_dof), and how many elements couple each DOF, as the prefix
// sums dof_ptr (num_dofs + 1).
void element_free_dofs(const GatherLists& gather, const std::vector<char>& constrained,
                       int nd, BlockPattern& bp, std::vector<int>& dof_ptr) {
  const int ne = int(gather.size());
  bp.elem_ptr.assign(std::size_t(ne) + 1, 0);
  bp.elem_dof.clear();
  const std::size_t gathered = gather.entries.size();
  bp.elem_dof.reserve(gathered);
  dof_ptr.assign(std::size_t(nd) + 1, 0);
  for (int e = 0; e < ne; ++e) {
    const std::size_t b = bp.elem_dof.size();
    bp.elem_ptr[std::size_t(e)] = int(b);
    for (const GatherEntry& p : gather[std::size_t(e)])
      if (!constrained[std::size_t(p.dof)]) bp.elem_dof.push_back(p.dof);
    std::sort(bp.elem_dof.begin() + std::ptrdiff_t(b), bp.elem_dof.end());
    bp.elem_dof.erase(std::unique(bp.elem_dof.begin() + std::ptrdiff_t(b), bp.elem_dof.end()), bp.elem_dof.end());
    for (std::size_t i = b; i < bp.elem_dof.size(); ++i) ++dof_ptr[std::size_t(bp.elem_dof[i]) + 1];
  }
  bp.elem_ptr[std::size_t(ne)] = int(bp.elem_dof.size());
  for (int d = 0; d < nd; ++d) dof_ptr[std::size_t(d) + 1] += dof_ptr[std::size_t(d)];
}

// The block structure for the gather lists (num_elements) and the constrained flags (num_dofs).
BlockPattern block_pattern(const GatherLists& gather, const std::vector<char>& constrained,
                           int nd) {
  BlockPattern bp;
  std::vector<int> dof_ptr;
  element_free_dofs(gather, constrained, nd, bp, dof_ptr);
  const int ne = int(gather.size());

  // The elements of each DOF (dof_ptr, dof_elem).
  std::vector<int> dof_elem(bp.elem_dof.size());
  std::vector<int> fill(dof_ptr.begin(), dof_ptr.end() - 1);
  for (int e = 0; e < ne; ++e)
    for (int i = bp.elem_ptr[std::size_t(e)]; i < bp.elem_ptr[std::size_t(e) + 1]; ++i)
      dof_elem[std::size_t(fill[std::size_t(bp.elem_dof[std::size_t(i)])]++)] = e;

  // Per block column k: k itself and the DOFs of every element of k, sorted.
  bp.col_ptr.resize(std::size_t(nd) + 1);
  bp.col_row.reserve(bp.elem_dof.size() * 8 + std::size_t(nd));
  std::vector<int> mark(std::size_t(nd), -1);  // mark[j] == k: j is already a row of column k
  for (int k = 0; k < nd; ++k) {
    const std::size_t b = bp.col_row.size();
    bp.col_ptr[std::size_t(k)] = int(b);
    bp.col_row.push_back(k);
    mark[std::size_t(k)] = k;
    for (int t = dof_ptr[std::size_t(k)]; t < dof_ptr[std::size_t(k) + 1]; ++t) {
      const int e = dof_elem[std::size_t(t)];
      for (int i = bp.elem_ptr[std::size_t(e)]; i < bp.elem_ptr[std::size_t(e) + 1]; ++i) {
        const int j = bp.elem_dof[std::size_t(i)];
        if (mark[std::size_t(j)] != k) {
          mark[std::size_t(j)] = k;
          bp.col_row.push_back(j);
        }
      }
    }
    std::sort(bp.col_row.begin() + std::ptrdiff_t(b), bp.col_row.end());
  }
  bp.col_ptr[std::size_t(nd)] = int(bp.col_row.size());
  return bp;
}
}  // namespace

struct FemSystem::Impl {
  const ObjectModel* model_ptr;  // the model this system was built for (the simulator's, or a prepared one's)
  const ObjectModel& model() const { return *model_ptr; }
  Executor* executor_ptr;  // runs the element loops (the simulator's, or a serial one while prepared)
  GatherLists gather;  // per element: its slots' rows of P (num_elements)
  std::vector<Vec24> rest;                        // rest slot positions per element, m (num_elements)

  // Fixed sparse pattern of the system matrix, built on the first assemble_system call.
  bool have_pattern = false;
  SpMat pattern;                                  // the system matrix's pattern, values zero (3 num_dofs square)
  std::vector<char> pattern_constrained;          // constrained flags the pattern was built for (num_dofs)
  std::vector<int> pair_offsets;                  // per element, per (p, q) entry pair: 3 column offsets, or -1
  std::vector<std::size_t> pair_begin;            // start of each element's pair offsets (num_elements + 1)
  std::vector<int> diag_offsets;                  // per scalar DOF: offset of its diagonal entry (3 num_dofs)
  // The scatter's parts: part t owns the matrix columns (and coupling rows) of DOFs [part_dof[t], part_dof[t + 1]),
  // and lists, ascending, the elements that touch them. Rebuilt with the pattern or when the thread count changes.
  std::vector<int> part_dof;
  std::vector<std::vector<int>> part_elements;
  bool parts_stale = true;
  // The elements of each DOF (dof_element_ptr: num_dofs + 1, dof_element: ascending per DOF), built on first use.
  std::vector<int> dof_element_ptr, dof_element;

  // Builds dof_element_ptr and dof_element when not yet built.
  void ensure_dof_elements() {
    const int nd = model().num_dofs();
    if (int(dof_element_ptr.size()) == nd + 1) return;
    std::vector<int> ptr(std::size_t(nd) + 1, 0);
    for (const GatherEntry& p : gather.entries) ++ptr[std::size_t(p.dof) + 1];
    for (int d = 0; d < nd; ++d) ptr[std::size_t(d) + 1] += ptr[std::size_t(d)];
    dof_element.assign(std::size_t(ptr.back()), 0);
    std::vector<int> fill(ptr.begin(), ptr.end() - 1);
    for (int e = 0; e < int(gather.size()); ++e)
      for (const GatherEntry& p : gather[std::size_t(e)]) {
        int& at = fill[std::size_t(p.dof)];
        if (at == ptr[std::size_t(p.dof)] || dof_element[std::size_t(at) - 1] != e) dof_element[std::size_t(at++)] = e;
      }
    // A DOF that an element reaches through several corners is listed once: close the gaps.
    std::vector<int> compact;
    compact.reserve(dof_element.size());
    dof_element_ptr.assign(std::size_t(nd) + 1, 0);
    for (int d = 0; d < nd; ++d) {
      compact.insert(compact.end(), dof_element.begin() + ptr[std::size_t(d)],
                     dof_element.begin() + fill[std::size_t(d)]);
      dof_element_ptr[std::size_t(d) + 1] = int(compact.size());
    }
    dof_element = std::move(compact);
  }

  // Splits the DOFs into `parts` ranges and lists each range's elements (see part_dof).
  void build_parts(int parts) {
    const int nd = model().num_dofs();
    part_dof.resize(std::size_t(parts) + 1);
    for (int t = 0; t <= parts; ++t) part_dof[std::size_t(t)] = int(std::int64_t(nd) * t / parts);
    part_elements.assign(std::size_t(parts), {});
    for (int e = 0; e < int(gather.size()); ++e) {
      int last = -1;
      for (int t = 0; t < parts; ++t) {
        for (const GatherEntry& g : gather[std::size_t(e)]) {
          if (g.dof >= part_dof[std::size_t(t)] && g.dof < part_dof[std::size_t(t) + 1] && last != t) {
            part_elements[std::size_t(t)].push_back(e);
            last = t;
          }
        }
      }
    }
  }

  // Adds the rotated element matrices kc R K R^T (computed here, per element, into a buffer that stays in cache)
  // entries whose column DOF lies in [lo, hi) to A's values, and their prescribed-column terms whose row DOF lies
  // there to `coupling`, over `elements` in ascending order: every sum then runs in the same order as one serial
  // pass over all elements, whatever the parts.
  void scatter(const std::vector<int>& elements, int lo, int hi, double kc, const ElementFrame& frame,
               const std::vector<char>& constrained, const VecX& u, double* val, VecX& coupling) const {
    const Mat24& unit_k = model().unit_stiffness();
    const std::vector<double>& scale = model().stiffness_scale();
    Mat24 Ke;
    for (const int e : elements) {
      corotated_stiffness(unit_k, frame.rotation[std::size_t(e)], kc * scale[std::size_t(e)], Ke);
      const auto& g = gather[std::size_t(e)];
      const int* off = pair_offsets.data() + pair_begin[std::size_t(e)];
      for (const GatherEntry& p : g) {
        const bool row_here = p.dof >= lo && p.dof < hi;
        for (const GatherEntry& q : g) {
          const double w = p.w * q.w;
          if (off[0] >= 0) {
            if (q.dof >= lo && q.dof < hi) {
              for (int c = 0; c < 3; ++c) {
                double* dst = val + off[c];
                dst[0] += w * Ke(3 * p.corner + 0, 3 * q.corner + c);
                dst[1] += w * Ke(3 * p.corner + 1, 3 * q.corner + c);
                dst[2] += w * Ke(3 * p.corner + 2, 3 * q.corner + c);
              }
            }
          } else if (row_here && !constrained[std::size_t(p.dof)]) {
            // Free row, prescribed column: moves to the right-hand side.
            coupling.segment<3>(3 * p.dof) +=
                w * Ke.block<3, 3>(3 * p.corner, 3 * q.corner) * u.segment<3>(3 * q.dof);
          }
          off += 3;
        }
      }
    }
  }

  // The rotated element matrix kc R K R^T of element e applied to the element's slots of x, counting only the
  // entries of unconstrained DOFs (want_constrained false) or only those of constrained ones (true) (24).
  Vec24 element_product(int e, double kc, const ElementFrame& frame, const std::vector<char>& constrained,
                        bool want_constrained, const VecX& x) const {
    return rotated_apply(e, kc, frame.rotation[std::size_t(e)], element_vector(e, x, &constrained, want_constrained));
  }

  // kc R K R^T v for element e's slot vector v (24), applied block-wise without forming R K R^T.
  Vec24 rotated_apply(int e, double kc, const Mat3& R, const Vec24& v) const {
    Vec24 rv, kv, out;
    for (int a = 0; a < 8; ++a) rv.segment<3>(3 * a).noalias() = R.transpose() * v.segment<3>(3 * a);
    apply_stiffness24(model().unit_stiffness().data(), rv.data(), kv.data());
    kv *= kc * model().stiffness_scale()[std::size_t(e)];
    for (int a = 0; a < 8; ++a) out.segment<3>(3 * a).noalias() = R * kv.segment<3>(3 * a);
    return out;
  }

  // Adds kc K x~ (x~: x with the constrained DOFs' entries zero) to the rows of unconstrained DOFs in [lo, hi) of
  // y, over `elements` in ascending order (see scatter).
  void product_part(const std::vector<int>& elements, int lo, int hi, double kc, const ElementFrame& frame,
                    const std::vector<char>& constrained, const VecX& x, VecX& y) const {
    for (const int e : elements)
      add_product(e, lo, hi, constrained, element_product(e, kc, frame, constrained, false, x), y);
  }
  // The same sums from element products computed beforehand (ke: num_elements).
  void add_products(const std::vector<int>& elements, int lo, int hi, const std::vector<char>& constrained,
                    const std::vector<Vec24>& ke, VecX& y) const {
    for (const int e : elements) add_product(e, lo, hi, constrained, ke[std::size_t(e)], y);
  }
  // Adds element e's product ke to the rows of unconstrained DOFs in [lo, hi) of y, through P^T.
  void add_product(int e, int lo, int hi, const std::vector<char>& constrained, const Vec24& ke, VecX& y) const {
    for (const GatherEntry& g : gather[std::size_t(e)])
      if (g.dof >= lo && g.dof < hi && !constrained[std::size_t(g.dof)])
        y.segment<3>(3 * g.dof) += g.w * ke.segment<3>(3 * g.corner);
  }

  // Exchanges the pattern's storage and its assembly plan with `s` (release_storage, reuse_storage).
  void swap_storage(FemSystem::Storage& s) noexcept {
    pattern.swap(s.pattern);
    pair_offsets.swap(s.pair_offsets);
    diag_offsets.swap(s.diag_offsets);
    pair_begin.swap(s.pair_begin);
  }

  // The parts of the DOFs for the executor's threads (see part_dof), rebuilt when stale.
  int ensure_parts() {
    const int nd = model().num_dofs();
    const int parts = std::max(1, std::min(executor_ptr->threads(), nd));
    if (int(part_elements.size()) != parts || part_dof.back() != nd || parts_stale) {
      build_parts(parts);
      parts_stale = false;
    }
    return parts;
  }
  // Calls body(lo, hi, elements) for each part of the DOFs (see part_dof) on the executor's threads: the DOFs
  // [lo, hi) and, ascending, the elements that touch them. A part's rows are its own, and each of their sums can run
  // in element order, as in one serial pass, whatever the thread count.
  template <class Body>
  void for_each_part(Body&& body) {
    const int parts = ensure_parts();
    executor_ptr->parallel_for(parts, 1, [&](int tb, int te) {
      for (int t = tb; t < te; ++t)
        body(part_dof[std::size_t(t)], part_dof[std::size_t(t) + 1], part_elements[std::size_t(t)]);
    });
  }

  Impl(const ObjectModel& m, Executor& ex) : model_ptr(&m), executor_ptr(&ex) {
    const DofMap& dm = m.dofs();
    const int ne = m.num_elements();
    gather.begin.reserve(std::size_t(ne) + 1);
    gather.entries.reserve(dm.slot_begin.empty() ? 0 : std::size_t(dm.slot_begin.back()));
    rest.resize(std::size_t(ne));
    for (int e = 0; e < ne; ++e) {
      for (int a = 0; a < 8; ++a) {
        const int s = 8 * e + a;
        for (int i = dm.slot_begin[std::size_t(s)]; i < dm.slot_begin[std::size_t(s) + 1]; ++i)
          gather.entries.push_back({a, dm.slot_dof[std::size_t(i)], dm.slot_weight[std::size_t(i)]});
        rest[std::size_t(e)].segment<3>(3 * a) = m.slot_rest()[std::size_t(s)];
      }
      gather.begin.push_back(int(gather.entries.size()));
    }
  }

  Mat24 element_k(int e) const { return model().stiffness_scale()[std::size_t(e)] * model().unit_stiffness(); }

  // Adds the element vectors (num_elements x 24) into a DOF vector through P^T: each DOF's sum in element order, by
  // parts of the DOFs in parallel (see part_dof), so the sums do not depend on the parts.
  void gather_vectors(const std::vector<Vec24>& fe, VecX& f) {
    f.resize(3 * model().num_dofs());
    for_each_part([&](int lo, int hi, const std::vector<int>& elements) {
      f.segment(3 * lo, 3 * (hi - lo)).setZero();
      for (const int e : elements)
        for (const GatherEntry& g : gather[std::size_t(e)])
          if (g.dof >= lo && g.dof < hi) f.segment<3>(3 * g.dof) += g.w * fe[std::size_t(e)].segment<3>(3 * g.corner);
    });
  }

  // Element e's slots of (P v) (24), or, with a filter, of P v~ where v~ keeps the entries of the DOFs whose
  // constrained flag equals want_constrained. Each corner's entries follow one another, corners ascending (the
  // constructor): summed in registers.
  Vec24 element_vector(int e, const VecX& v, const std::vector<char>* constrained = nullptr,
                       bool want_constrained = false) const {
    Vec24 out;
    const std::span<const GatherEntry> g = gather[std::size_t(e)];
    std::size_t k = 0;
    for (int a = 0; a < 8; ++a) {
      Vec3 sum = Vec3::Zero();
      for (; k < g.size() && g[k].corner == a; ++k)
        if (constrained == nullptr || bool((*constrained)[std::size_t(g[k].dof)]) == want_constrained)
          sum += g[k].w * v.segment<3>(3 * g[k].dof);
      out.segment<3>(3 * a) = sum;
    }
    return out;
  }

  // The pattern, its diagonal offsets and the element pair offsets for the constrained flags (num_dofs).
  void build_pattern(const std::vector<char>& constrained) {
    const BlockPattern bp = block_pattern(gather, constrained, model().num_dofs());
    fill_scalar_pattern(bp);
    fill_pair_offsets(bp, constrained);
    pattern_constrained = constrained;
    have_pattern = true;
    parts_stale = true;
  }

  // Scalar CSC of the block pattern: column 3k + c holds rows 3j, 3j + 1, 3j + 2 for every block row j of block
  // column k; it starts at 9 col_ptr[k] + 3 c len(k). Filled in parallel by block column (disjoint ranges), with the
  // offset of each diagonal entry.
  void fill_scalar_pattern(const BlockPattern& bp) {
    const int nd = model().num_dofs();
    const std::size_t nnz = 9 * bp.col_row.size();
    // Resized in place: storage from an earlier revision (reuse_storage) is kept where it is large enough, and
    // grown with a quarter to spare (each cut adds a few per cent).
    if (pattern.rows() != 3 * nd || pattern.cols() != 3 * nd) pattern.resize(3 * nd, 3 * nd);
    pattern.data().resize(Eigen::Index(nnz), 0.25);
    int* outer = pattern.outerIndexPtr();
    int* inner = pattern.innerIndexPtr();
    double* values = pattern.valuePtr();
    diag_offsets.resize(3 * std::size_t(nd));
    executor_ptr->parallel_for(nd, 256, [&](int kb, int ke) {
      for (int k = kb; k < ke; ++k) {
        const int b = bp.col_ptr[std::size_t(k)], len = bp.col_ptr[std::size_t(k) + 1] - b;
        const int* rows = bp.col_row.data() + b;
        const int diag = 3 * int(std::lower_bound(rows, rows + len, k) - rows);
        int at = 9 * b;
        std::fill(values + at, values + at + 9 * len, 0.0);
        for (int c = 0; c < 3; ++c) {
          outer[3 * k + c] = at;
          diag_offsets[3 * std::size_t(k) + std::size_t(c)] = at + diag + c;
          for (int t = b; t < b + len; ++t) {
            const int j = bp.col_row[std::size_t(t)];
            inner[at++] = 3 * j;
            inner[at++] = 3 * j + 1;
            inner[at++] = 3 * j + 2;
          }
        }
      }
    });
    outer[3 * nd] = int(nnz);
  }

  // Offsets of each element's entry pairs in the pattern: the entry of block (j, k) in column 3k + c is
  // outer[3k + c] + 3 pos(j in column k). Positions come from one merge walk per (element, free DOF) instead of a
  // search per entry. Independent per element: parallel.
  void fill_pair_offsets(const BlockPattern& bp, const std::vector<char>& constrained) {
    const int ne = model().num_elements();
    const int* out_ptr = pattern.outerIndexPtr();
    pair_begin.resize(std::size_t(ne) + 1);
    std::size_t pairs = 0;
    for (int e = 0; e < ne; ++e) {
      pair_begin[std::size_t(e)] = pairs;
      pairs += 3 * gather[std::size_t(e)].size() * gather[std::size_t(e)].size();
    }
    pair_begin[std::size_t(ne)] = pairs;
    // Half again to spare for storage an earlier revision hands on (reuse_storage): refinement adds hanging nodes,
    // and with them entries per element (meniscus_punch_hd: 0.29 to 0.77 million over six punches).
    if (pair_offsets.capacity() < pairs) pair_offsets.reserve(pairs + pairs / 2);
    pair_offsets.resize(pairs);
    executor_ptr->parallel_for(ne, kGrain, [&](int eb, int ee) {
      std::vector<int> local;  // index in the element's DOF list of each gather entry, -1 when constrained
      std::vector<int> pos;    // pos[a * n + b]: position of DOF b in block column a (element-local indices)
      for (int e = eb; e < ee; ++e) {
        const auto& g = gather[std::size_t(e)];
        const int* u = bp.elem_dof.data() + bp.elem_ptr[std::size_t(e)];
        const std::size_t n = std::size_t(bp.elem_ptr[std::size_t(e) + 1] - bp.elem_ptr[std::size_t(e)]);
        pos.resize(n * n);
        for (std::size_t a2 = 0; a2 < n; ++a2) {
          const int* r = bp.col_row.data() + bp.col_ptr[std::size_t(u[a2])];
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
  }
};

FemSystem::FemSystem(const ObjectModel& model, Executor& executor)
    : m_impl(std::make_unique<Impl>(model, executor)) {}
FemSystem::~FemSystem() = default;

void FemSystem::rebind(const ObjectModel& model, Executor& executor) {
  m_impl->model_ptr = &model;
  m_impl->executor_ptr = &executor;
}

FemSystem::Storage FemSystem::release_storage() {
  Storage out;
  m_impl->swap_storage(out);
  m_impl->have_pattern = false;
  return out;  // NRVO, or Storage's swapping move
}

void FemSystem::reuse_storage(Storage&& storage) {
  if (!m_impl->have_pattern) m_impl->swap_storage(storage);
}

void FemSystem::prolong(const std::vector<Vec3>& dofs, std::vector<Vec3>& slots) const {
  const DofMap& dm = m_impl->model().dofs();
  slots.resize(std::size_t(dm.num_slots()));
  m_impl->executor_ptr->parallel_for(dm.num_slots(), 8 * kGrain,
                                     [&](int b, int e) { dm.prolong_range(dofs, slots, b, e); });
}

std::vector<Mat3> FemSystem::dof_rotations(const ElementFrame& frame) const {
  Impl& im = *m_impl;
  std::vector<Mat3> rotations(std::size_t(im.model().num_dofs()));
  // Each DOF's sum in element order (the gather lists are P's rows of each element's slots, in slot order), by
  // parts of the DOFs.
  im.for_each_part([&](int lo, int hi, const std::vector<int>& elements) {
    for (int d = lo; d < hi; ++d) rotations[std::size_t(d)].setZero();
    for (const int e : elements)
      for (const GatherEntry& g : im.gather[std::size_t(e)])
        if (g.dof >= lo && g.dof < hi) rotations[std::size_t(g.dof)] += std::abs(g.w) * frame.rotation[std::size_t(e)];
    for (int d = lo; d < hi; ++d) rotations[std::size_t(d)] = gram_schmidt_rotation(rotations[std::size_t(d)]);
  });
  return rotations;
}

void FemSystem::rotations(const std::vector<Vec3>& x, ElementFrame& frame) const {
  const ObjectModel& m = m_impl->model();
  std::vector<Vec3> slots;
  prolong(x, slots);
  frame.rotation.resize(std::size_t(m.num_elements()));
  frame.volume_ratio.resize(std::size_t(m.num_elements()));
  m_impl->executor_ptr->parallel_for(m.num_elements(), kGrain, [&](int b, int en) {
    Vec24 xe;
    Eigen::Matrix<double, 3, 8> xm;
    for (int e = b; e < en; ++e) {
      element_slots(slots, e, xe, xm);
      const Mat3 F = hex_center_gradient(xm, m.edge()[std::size_t(e)]);
      frame.rotation[std::size_t(e)] = polar_rotation(F);
      frame.volume_ratio[std::size_t(e)] = F.determinant();
    }
  });
}

void FemSystem::force_and_product(const std::vector<Vec3>& x, const ElementFrame& frame, const VecX& v, VecX& f,
                                  VecX& kv, double* energy) const {
  const ObjectModel& m = m_impl->model();
  const int ne = m.num_elements();
  std::vector<Vec3> slots;
  prolong(x, slots);
  const bool want_kv = v.size() == 3 * m.num_dofs();
  std::vector<Vec24> fe(static_cast<std::size_t>(ne)), kve(want_kv ? std::size_t(ne) : 0);
  std::vector<double> ee(energy != nullptr ? std::size_t(ne) : 0);  // J per element, summed in order below
  m_impl->executor_ptr->parallel_for(ne, kGrain, [&](int b, int en) {
    Vec24 xe;
    Eigen::Matrix<double, 3, 8> xm;
    for (int e = b; e < en; ++e) {
      element_slots(slots, e, xe, xm);
      const Mat3& R = frame.rotation[std::size_t(e)];
      const double s = m.stiffness_scale()[std::size_t(e)];  // K = s K_unit
      double* eu = energy != nullptr ? &ee[std::size_t(e)] : nullptr;  // u^T K_unit u / 2, scaled by s below
      fe[std::size_t(e)] = s * corotated_force(m.unit_stiffness(), R, xe, m_impl->rest[std::size_t(e)], eu);
      if (eu != nullptr) *eu *= s;
      if (want_kv) kve[std::size_t(e)] = m_impl->rotated_apply(e, 1.0, R, m_impl->element_vector(e, v));
    }
  });
  m_impl->gather_vectors(fe, f);
  if (want_kv) m_impl->gather_vectors(kve, kv);
  if (energy != nullptr) {
    *energy = 0.0;
    for (const double e : ee) *energy += e;
  }
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
  const int nd = m.num_dofs();
  if (!im.have_pattern || im.pattern_constrained != constrained) {
    im.build_pattern(constrained);
    A = im.pattern;
  }
  if (A.nonZeros() != im.pattern.nonZeros()) A = im.pattern;

  // Rotate and scatter, by parts of the DOFs in parallel, each part in ascending element order: the same sums, in
  // the same order, as one serial pass (bit-identical for any thread count). An element that touches two parts is
  // rotated by both: cheaper than a pass that stores every element's 24 x 24 matrix for the scatter to read back.
  double* val = A.valuePtr();
  std::fill(val, val + A.nonZeros(), 0.0);
  coupling.setZero(3 * nd);
  im.for_each_part([&](int lo, int hi, const std::vector<int>& elements) {
    im.scatter(elements, lo, hi, kc, frame, constrained, u, val, coupling);
  });

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

void FemSystem::system_product(double mc, double kc, const ElementFrame& frame, const std::vector<char>& constrained,
                               const VecX& x, VecX& y) {
  Impl& im = *m_impl;
  const ObjectModel& m = im.model();
  const int nd = m.num_dofs();
  // Each DOF's row: zero, the stiffness's terms in element order, then the lumped mass (or the identity for a
  // constrained DOF), by parts of the rows, in parallel (as the assembly's scatter).
  const auto finish_rows = [&](int lo, int hi) {
    for (int d = lo; d < hi; ++d) {
      if (constrained[std::size_t(d)])
        y.segment<3>(3 * d) = x.segment<3>(3 * d);
      else
        y.segment<3>(3 * d) += (mc * m.dof_mass()[std::size_t(d)]) * x.segment<3>(3 * d);
    }
  };
  if (nd == 0) {
    y.resize(0);
    return;
  }
  const int parts = im.ensure_parts();
  if (parts == 1) {
    y.setZero(3 * nd);
    im.product_part(im.part_elements[0], 0, nd, kc, frame, constrained, x, y);
    finish_rows(0, nd);
    return;
  }
  // With several parts, each element's product is computed once, on elements split evenly between the threads,
  // and the parts then add them up: a part's elements include those it shares with its neighbours (23 % of the
  // meniscus's), whose products the fused loop computed twice. The sums are product_part's, in its order.
  thread_local std::vector<Vec24> buffer;  // this thread's calls' (a lambda names the running thread's own)
  std::vector<Vec24>& ke = buffer;         // kc R K R^T x~ per element (num_elements)
  const int ne = m.num_elements();
  ke.resize(std::size_t(ne));
  y.resize(3 * nd);
  im.executor_ptr->parallel_for(ne, kGrain, [&](int b, int en) {
    for (int e = b; e < en; ++e) ke[std::size_t(e)] = im.element_product(e, kc, frame, constrained, false, x);
  });
  im.for_each_part([&](int lo, int hi, const std::vector<int>& elements) {
    y.segment(3 * lo, 3 * (hi - lo)).setZero();
    im.add_products(elements, lo, hi, constrained, ke, y);
    finish_rows(lo, hi);
  });
}

void FemSystem::system_coupling(double kc, const ElementFrame& frame, const std::vector<char>& constrained,
                                const VecX& u, VecX& coupling) const {
  const Impl& im = *m_impl;
  coupling.setZero(3 * im.model().num_dofs());
  // The elements with a constrained DOF, in ascending order: their matrices against u's constrained entries.
  for (int e = 0; e < int(im.gather.size()); ++e) {
    const auto& g = im.gather[std::size_t(e)];
    if (std::none_of(g.begin(), g.end(), [&](const GatherEntry& p) { return constrained[std::size_t(p.dof)]; }))
      continue;
    const Vec24 ke = im.element_product(e, kc, frame, constrained, true, u);
    for (const GatherEntry& p : g)
      if (!constrained[std::size_t(p.dof)]) coupling.segment<3>(3 * p.dof) += p.w * ke.segment<3>(3 * p.corner);
  }
}

SpMat FemSystem::system_columns(double mc, double kc, const ElementFrame& frame, const std::vector<char>& constrained,
                                const std::vector<int>& dofs) {
  Impl& im = *m_impl;
  const ObjectModel& m = im.model();
  const SpMat& pattern = system_pattern(constrained);
  im.ensure_dof_elements();
  const int* outer = pattern.outerIndexPtr();

  // The columns' pattern: A's, copied.
  SpMat out(pattern.rows(), 3 * Eigen::Index(dofs.size()));
  std::vector<int> local(std::size_t(m.num_dofs()), -1);  // index of each DOF in `dofs`, or -1
  std::size_t nnz = 0;
  for (std::size_t i = 0; i < dofs.size(); ++i) {
    local[std::size_t(dofs[i])] = int(i);
    nnz += std::size_t(outer[3 * dofs[i] + 3] - outer[3 * dofs[i]]);
  }
  out.resizeNonZeros(Eigen::Index(nnz));
  int* o_outer = out.outerIndexPtr();
  int at = 0;
  for (std::size_t i = 0; i < dofs.size(); ++i)
    for (int c = 0; c < 3; ++c) {
      const int col = 3 * dofs[i] + c;
      o_outer[3 * i + std::size_t(c)] = at;
      std::copy(pattern.innerIndexPtr() + outer[col], pattern.innerIndexPtr() + outer[col + 1],
                out.innerIndexPtr() + at);
      at += outer[col + 1] - outer[col];
    }
  o_outer[3 * dofs.size()] = at;
  double* val = out.valuePtr();
  std::fill(val, val + nnz, 0.0);

  // The elements around the DOFs, ascending: the blocks of their rotated matrices in the DOFs' columns, added as the
  // assembly adds them (pair_offsets); then the lumped mass, or the identity of a constrained DOF.
  std::vector<int> elements;
  for (const int q : dofs)
    elements.insert(elements.end(), im.dof_element.begin() + im.dof_element_ptr[std::size_t(q)],
                    im.dof_element.begin() + im.dof_element_ptr[std::size_t(q) + 1]);
  std::sort(elements.begin(), elements.end());
  elements.erase(std::unique(elements.begin(), elements.end()), elements.end());
  const Mat24& unit_k = m.unit_stiffness();
  // On the executor's threads, each writing the columns of its own range of `dofs` (every element is visited by
  // each, its blocks computed only for that thread's columns): each column's sum runs in element order, as on one
  // thread, so the result does not depend on the thread count.
  const int parts = std::max(1, std::min(im.executor_ptr->threads(), int(dofs.size())));
  im.executor_ptr->parallel_for(parts, 1, [&](int tb, int te) {
    for (int t = tb; t < te; ++t) {
      const int lo = int(std::int64_t(dofs.size()) * t / parts), hi = int(std::int64_t(dofs.size()) * (t + 1) / parts);
      for (const int e : elements) {
        const Mat3& R = frame.rotation[std::size_t(e)];
        const double ks = kc * m.stiffness_scale()[std::size_t(e)];
        const auto& g = im.gather[std::size_t(e)];
        const int* off = im.pair_offsets.data() + im.pair_begin[std::size_t(e)];
        for (std::size_t pi = 0; pi < g.size(); ++pi)
          for (std::size_t qi = 0; qi < g.size(); ++qi) {
            const int* o = off + 3 * (pi * g.size() + qi);
            const int i = local[std::size_t(g[qi].dof)];
            // Not a column asked for, or another thread's; or a constrained row or column.
            if (i < lo || i >= hi || o[0] < 0) continue;
            const Mat3 B = (ks * g[pi].w * g[qi].w) *
                           (R * unit_k.block<3, 3>(3 * g[pi].corner, 3 * g[qi].corner) * R.transpose());
            for (int c = 0; c < 3; ++c) {
              double* dst = val + o_outer[3 * i + c] + (o[c] - outer[3 * g[qi].dof + c]);
              for (int r = 0; r < 3; ++r) dst[r] += B(r, c);
            }
          }
      }
    }
  });
  for (std::size_t i = 0; i < dofs.size(); ++i) {
    const int q = dofs[i];
    const double diag = constrained[std::size_t(q)] ? 1.0 : mc * m.dof_mass()[std::size_t(q)];
    for (int c = 0; c < 3; ++c) {
      const int diag_in_column = im.diag_offsets[3 * std::size_t(q) + std::size_t(c)] - outer[3 * q + c];
      val[o_outer[3 * i + std::size_t(c)] + diag_in_column] += diag;
    }
  }
  return out;
}

}  // namespace octocut::sim
