// Tissue-side contact: collision samples on S and the contact term of the implicit step. See contact.hpp.
#include "octocut/sim/contact.hpp"

#include <algorithm>
#include <cmath>
#include <map>

#include "octocut/sim/embedding.hpp"

namespace octocut::sim {

namespace {

// Adds `w` times the row [b, e) of `src` to `row`, merging equal DOFs.
void add_row(std::map<int, double>& row, const std::vector<int>& dof, const std::vector<double>& weight, int b, int e,
             double w) {
  for (int i = b; i < e; ++i) row[dof[std::size_t(i)]] += w * weight[std::size_t(i)];
}

// The composed DOF row of a point embedded in a leaf: trilinear weights through the leaf's 8 rows of P.
void leaf_row(const ObjectModel& model, const PointEmbedding& e, std::map<int, double>& row) {
  const DofMap& dm = model.dofs();
  for (int k = 0; k < 8; ++k) {
    const double w = e.weights[std::size_t(k)];
    if (w == 0.0) continue;
    const int s = 8 * e.leaf + k;
    add_row(row, dm.slot_dof, dm.slot_weight, dm.slot_begin[std::size_t(s)], dm.slot_begin[std::size_t(s) + 1], w);
  }
}

// Appends one sample.
void push_sample(ContactSamples& out, const Vec3& rest, double area, int face, const std::map<int, double>& row) {
  out.rest.push_back(rest);
  out.area.push_back(area);
  out.face.push_back(face);
  for (const auto& [d, w] : row)
    if (w != 0.0) out.dofs.push_back({d, w});
  out.begin.push_back(int(out.dofs.size()));
}

// The offset of entry (r, c) in A's pattern, or -1.
std::ptrdiff_t entry(const SpMat& A, int r, int c) {
  const int* outer = A.outerIndexPtr();
  const int* inner = A.innerIndexPtr();
  const int* b = inner + outer[c];
  const int* e = inner + outer[c + 1];
  const int* it = std::lower_bound(b, e, r);
  return (it != e && *it == r) ? it - inner : -1;
}

// Whether block (i, j) is in A's pattern (blocks are dense: its first entry decides).
bool has_block(const SpMat& A, int i, int j) { return entry(A, 3 * i, 3 * j) >= 0; }

// The stiffness K and damping C (3x3) of one contact and its force f0 before the velocity terms, for the relative
// velocity `rel` (sample minus rigid point) at the start of the step. Returns true when it slides.
bool contact_terms(const Contact& c, const Vec3& rel, Mat3& K, Mat3& C, Vec3& f0) {
  const Mat3 nn = c.normal * c.normal.transpose();
  const double fn = c.stiffness * std::max(0.0, c.penetration);  // normal force at the start, N
  K = c.stiffness * nn;
  C = c.damping * nn;
  f0 = fn * c.normal;
  const Vec3 rel_t = rel - c.normal.dot(rel) * c.normal;
  const double speed = rel_t.norm();
  if (c.friction <= 0.0) return false;
  // Coulomb's force friction * fn against the tangential motion, as an implicit viscous force whose coefficient is
  // taken at the start speed (at least kStickSpeed): exact while the speed holds, and it can slow the motion to a
  // stop but never reverse it within a step.
  C += (c.friction * fn / std::max(speed, kStickSpeed)) * (Mat3::Identity() - nn);
  return speed >= kStickSpeed;
}

Vec3 row_value(const std::vector<ContactDof>& row, const std::vector<Vec3>& x) {
  Vec3 p = Vec3::Zero();
  for (const ContactDof& d : row) p += d.weight * x[std::size_t(d.dof)];
  return p;
}

}  // namespace

// function-length: one pass over S's vertices and faces, each a few lines
ContactSamples build_contact_samples(const ObjectModel& model, const TriMesh& surface,
                                     const SurfaceEmbedding& embedding, double resolution) {
  ContactSamples out;
  out.begin.push_back(0);
  const std::size_t nv = surface.vertices.size();
  // Divisions per face, and the area each vertex gets from the faces that are not subdivided.
  std::vector<int> divisions(surface.triangles.size(), 1);
  std::vector<double> vertex_area(nv, 0.0);
  for (std::size_t f = 0; f < surface.triangles.size(); ++f) {
    const auto& t = surface.triangles[f];
    const Vec3 a = surface.vertices[std::size_t(t[0])], b = surface.vertices[std::size_t(t[1])],
               c = surface.vertices[std::size_t(t[2])];
    const double area = 0.5 * (b - a).cross(c - a).norm();
    const double edge = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int n = resolution > 0.0 ? std::clamp(int(std::ceil(edge / resolution - 1e-9)), 1, 256) : 1;
    divisions[f] = n;
    // Each of the n^2 sub-triangles lumps a third of its area on each of its corners; the face's own corners
    // belong to one sub-triangle each.
    for (int k = 0; k < 3; ++k) vertex_area[std::size_t(t[std::size_t(k)])] += area / (3.0 * n * n);
  }
  const std::vector<int>& vb = embedding.dof_begin();
  const std::vector<int>& vd = embedding.dof_index();
  const std::vector<double>& vw = embedding.dof_weight();
  for (std::size_t v = 0; v < nv; ++v) {
    std::map<int, double> row;
    add_row(row, vd, vw, vb[v], vb[v + 1], 1.0);
    push_sample(out, surface.vertices[v], vertex_area[v], -1, row);
  }
  for (std::size_t f = 0; f < surface.triangles.size(); ++f) {
    const int n = divisions[f];
    if (n == 1) continue;
    const auto& t = surface.triangles[f];
    const Vec3 a = surface.vertices[std::size_t(t[0])], b = surface.vertices[std::size_t(t[1])],
               c = surface.vertices[std::size_t(t[2])];
    const double sub = 0.5 * (b - a).cross(c - a).norm() / double(n * n);  // area of one sub-triangle, m^2
    for (int i = 0; i <= n; ++i) {
      for (int j = 0; i + j <= n; ++j) {
        const int k = n - i - j;
        if (i == n || j == n || k == n) continue;  // the face's corners: vertex samples
        // Sub-triangles meeting at the grid point: 6 inside, 3 on an edge.
        const bool on_edge = i == 0 || j == 0 || k == 0;
        const double area = (on_edge ? 3.0 : 6.0) * sub / 3.0;
        const double l0 = double(k) / n, l1 = double(i) / n, l2 = double(j) / n;
        const Vec3 p = l0 * a + l1 * b + l2 * c;
        std::map<int, double> row;
        if (const auto e = model.embed(p)) {
          leaf_row(model, *e, row);
        } else {
          const double l[3] = {l0, l1, l2};
          for (int q = 0; q < 3; ++q) {
            const std::size_t vq = std::size_t(t[std::size_t(q)]);
            add_row(row, vd, vw, vb[vq], vb[vq + 1], l[q]);
          }
        }
        push_sample(out, p, area, int(f), row);
      }
    }
  }
  return out;
}

void contact_system_terms(const std::vector<Contact>& contacts, double dt, const std::vector<Vec3>& v,
                          const std::vector<char>& constrained, const VecX& dv_c, const SpMat& pattern,
                          std::vector<SystemBlock>& blocks, VecX& rhs) {
  // The contacts of samples embedded in the same element share their DOFs (meniscus_punch: 80 contacts a step, 20
  // lists of DOFs): their blocks are summed per list and pair before they enter `blocks`, in the order of each list's
  // first contact (5,100 blocks a step become about 1,300, which the products with A and the region's columns read).
  struct Group {
    const std::vector<ContactDof>* dofs;  // the first contact's
    std::vector<Mat3> sum;                // per pair (p, q) of the list: the blocks, or the lumped block
    std::vector<signed char> kind;        // per pair: 0 none (a constrained row or column), 1 block, 2 lumped
    int next = -1;                        // the next group whose list starts with the same DOF
  };
  // Reused, so that their storage stays allocated between steps: the groups, and per DOF the first group whose list
  // starts with it (-1 between calls), so that finding a contact's group compares only lists with its first DOF.
  thread_local std::vector<Group> groups;
  thread_local std::vector<int> starting;
  starting.resize(constrained.size(), -1);
  std::size_t used = 0;
  struct Reset {  // back to -1 on every way out, a throw included
    const std::size_t& used;
    ~Reset() {
      for (std::size_t g = 0; g < used; ++g) starting[std::size_t(groups[g].dofs->front().dof)] = -1;
    }
  } reset{used};
  const auto same_dofs = [](const std::vector<ContactDof>& a, const std::vector<ContactDof>& b) {
    const auto same = [](const ContactDof& x, const ContactDof& y) { return x.dof == y.dof; };
    return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), same);
  };
  for (const Contact& c : contacts) {
    if (c.dofs.empty()) continue;  // a sample with no row moves nothing
    Mat3 K, C;
    Vec3 f0;
    const Vec3 rel = row_value(c.dofs, v) - c.rigid_velocity;
    contact_terms(c, rel, K, C, f0);
    const Mat3 S = dt * dt * K + dt * C;  // the system matrix block of a unit row
    const Vec3 f = dt * (f0 - (dt * K + C) * rel);
    int& first = starting[std::size_t(c.dofs.front().dof)];
    int found = first;
    while (found >= 0 && !same_dofs(*groups[std::size_t(found)].dofs, c.dofs)) found = groups[std::size_t(found)].next;
    const std::size_t n = c.dofs.size();
    if (found < 0) {  // a new list: which of its pairs enter A, and how (counted in `used` once complete)
      if (groups.size() == used) groups.emplace_back();
      Group& group = groups[used];
      group.dofs = &c.dofs;
      group.sum.assign(n * n, Mat3::Zero());
      group.kind.assign(n * n, 0);
      for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = 0; j < n; ++j) {
          const int p = c.dofs[i].dof, q = c.dofs[j].dof;
          if (constrained[std::size_t(p)] || constrained[std::size_t(q)]) continue;
          group.kind[i * n + j] = has_block(pattern, p, q) ? 1 : 2;
        }
      group.next = first;
      found = first = int(used++);
    }
    Group& group = groups[std::size_t(found)];
    for (std::size_t i = 0; i < n; ++i) {
      const ContactDof& p = c.dofs[i];
      if (constrained[std::size_t(p.dof)]) continue;
      rhs.segment<3>(3 * p.dof) += p.weight * f;
      for (std::size_t j = 0; j < n; ++j) {
        const ContactDof& q = c.dofs[j];
        const signed char kind = group.kind[i * n + j];
        if (kind == 1) {
          group.sum[i * n + j] += (p.weight * q.weight) * S;
        } else if (kind == 2) {
          // Outside the pattern (a row that spans leaves, as a vertex outside every leaf has): lumped onto the two
          // diagonals with |w_p w_q|. With the mirrored pair this adds |w_p w_q| (e_p -+ e_q)(e_p -+ e_q)^T (x) S
          // >= 0 to the exact term, so A stays symmetric positive definite whatever the weights' signs.
          group.sum[i * n + j] += (0.5 * std::abs(p.weight * q.weight)) * S;
        } else if (constrained[std::size_t(q.dof)]) {
          // Free row, prescribed column: to the right-hand side.
          rhs.segment<3>(3 * p.dof) -= ((p.weight * q.weight) * S) * dv_c.segment<3>(3 * q.dof);
        }
      }
    }
  }
  for (std::size_t g = 0; g < used; ++g) {
    const Group& group = groups[g];
    const std::size_t n = group.dofs->size();
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = 0; j < n; ++j) {
        const int p = (*group.dofs)[i].dof, q = (*group.dofs)[j].dof;
        const Mat3& B = group.sum[i * n + j];
        if (group.kind[i * n + j] == 1) {
          blocks.push_back({p, q, B});
        } else if (group.kind[i * n + j] == 2) {
          blocks.push_back({p, p, B});
          blocks.push_back({q, q, B});
        }
      }
  }
}

void add_system_blocks(const std::vector<SystemBlock>& blocks, SpMat& A, const std::vector<int>* column_of) {
  if (blocks.empty()) return;
  double* val = A.valuePtr();
  const int* outer = A.outerIndexPtr();
  const int* inner = A.innerIndexPtr();
  // Each block's column block of A (-1: none).
  const auto target = [&](const SystemBlock& b) {
    if (column_of == nullptr) return b.col;
    return std::size_t(b.col) < column_of->size() ? (*column_of)[std::size_t(b.col)] : -1;
  };
  const int nc = int(A.cols() / 3);
  // The blocks by column block, each column's in the blocks' order (a counting sort), so that every entry receives
  // its blocks in the same order as one pass over the list would add them.
  std::vector<int> start(std::size_t(nc) + 1, 0);
  for (const SystemBlock& b : blocks)
    if (const int k = target(b); k >= 0 && k < nc) ++start[std::size_t(k) + 1];
  for (int k = 0; k < nc; ++k) start[std::size_t(k) + 1] += start[std::size_t(k)];
  std::vector<int> order(std::size_t(start.back())), fill(start.begin(), start.end() - 1);
  for (std::size_t i = 0; i < blocks.size(); ++i)
    if (const int k = target(blocks[i]); k >= 0 && k < nc) order[std::size_t(fill[std::size_t(k)]++)] = int(i);
  // Per column block: where each row block starts in its first column (rows 3 r, 3 r + 1, 3 r + 2 are adjacent in
  // the pattern), looked up instead of searched; columns 3 k + 1 and 3 k + 2 hold the same rows when the blocks are
  // dense (checked: a pattern whose columns differ within the block is searched).
  std::vector<int> at_row(std::size_t(A.rows() / 3) + 1, -1);
  for (int k = 0; k < nc; ++k) {
    if (start[std::size_t(k)] == start[std::size_t(k) + 1]) continue;
    const int col = 3 * k;
    for (int p = outer[col]; p < outer[col + 1]; ++p)
      if (inner[p] % 3 == 0) at_row[std::size_t(inner[p] / 3)] = p - outer[col];
    for (int j = start[std::size_t(k)]; j < start[std::size_t(k) + 1]; ++j) {
      const SystemBlock& b = blocks[std::size_t(order[std::size_t(j)])];
      if (b.row < 0 || 3 * Eigen::Index(b.row) >= A.rows()) continue;
      const int in_column = at_row[std::size_t(b.row)];
      if (in_column < 0) continue;  // not for this pattern
      for (int c = 0; c < 3; ++c) {
        std::ptrdiff_t at_c = outer[col + c] + in_column;
        if (at_c >= outer[col + c + 1] || inner[at_c] != 3 * b.row) {
          at_c = entry(A, 3 * b.row, col + c);
          if (at_c < 0) continue;
        }
        for (int r = 0; r < 3; ++r) val[at_c + r] += b.value(r, c);
      }
    }
    for (int p = outer[col]; p < outer[col + 1]; ++p)
      if (inner[p] % 3 == 0) at_row[std::size_t(inner[p] / 3)] = -1;
  }
}

void add_block_products(const std::vector<SystemBlock>& blocks, const VecX& x, VecX& y) {
  for (const SystemBlock& b : blocks) y.segment<3>(3 * b.row) += b.value * x.segment<3>(3 * b.col);
}

std::vector<ContactOutcome> contact_outcomes(const std::vector<Contact>& contacts, double dt,
                                             const std::vector<Vec3>& v, const VecX& dv) {
  std::vector<ContactOutcome> out(contacts.size());
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const Contact& c = contacts[i];
    Mat3 K, C;
    Vec3 f0;
    const Vec3 rel0 = row_value(c.dofs, v) - c.rigid_velocity;
    out[i].sliding = contact_terms(c, rel0, K, C, f0);
    Vec3 dv_s = Vec3::Zero();
    for (const ContactDof& d : c.dofs) dv_s += d.weight * dv.segment<3>(3 * d.dof);
    const Vec3 rel = rel0 + dv_s;  // at the end of the step
    out[i].force = f0 - (dt * K + C) * rel;
    out[i].penetration = c.penetration - dt * c.normal.dot(rel);
  }
  return out;
}

}  // namespace octocut::sim
