#include "octocut/cutting/surface_editor.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace octocut::cutting {

using sim::Vec3;
using Tri = std::array<int32_t, 3>;

namespace {

void triangle_box(const sim::TriMesh& mesh, const Tri& t, Vec3& lo, Vec3& hi) {
  const Vec3& a = mesh.vertices[static_cast<std::size_t>(t[0])];
  const Vec3& b = mesh.vertices[static_cast<std::size_t>(t[1])];
  const Vec3& c = mesh.vertices[static_cast<std::size_t>(t[2])];
  lo = a.cwiseMin(b).cwiseMin(c);
  hi = a.cwiseMax(b).cwiseMax(c);
}

void face_box(const sim::TriMesh& mesh, int32_t f, Vec3& lo, Vec3& hi) {
  triangle_box(mesh, mesh.triangles[static_cast<std::size_t>(f)], lo, hi);
}

}  // namespace

void FaceGrid::build(const sim::TriMesh& mesh) {
  const auto nv = mesh.vertices.size();
  for (std::size_t v = 0; v < nv; ++v) {
    if (!mesh.vertices[v].allFinite()) {
      throw std::invalid_argument("surface vertex " + std::to_string(v) + " has a non-finite coordinate");
    }
  }
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (const int32_t v : mesh.triangles[f]) {
      if (v < 0 || static_cast<std::size_t>(v) >= nv) {
        throw std::invalid_argument("surface triangle " + std::to_string(f) + " has vertex index " +
                                    std::to_string(v) + ", outside [0, " + std::to_string(nv) + ")");
      }
    }
  }
  // The box of the vertices and the mean box edge of the triangles.
  Vec3 lo = Vec3::Zero(), hi = Vec3::Zero();
  if (nv > 0) {
    lo = hi = mesh.vertices[0];
    for (const Vec3& p : mesh.vertices) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  }
  double mean_edge = 0.0;  // m
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    Vec3 a, b;
    face_box(mesh, static_cast<int32_t>(f), a, b);
    mean_edge += (b - a).maxCoeff();
  }
  const double nf = static_cast<double>(std::max<std::size_t>(mesh.triangles.size(), 1));
  mean_edge /= nf;
  const Vec3 extent = hi - lo;
  double cell = std::max(2.0 * mean_edge, 1e-12 * std::max(1.0, extent.maxCoeff()));
  // At most about one cell per two triangles (and at least one cell).
  const auto cells_for = [&](double h) {
    double n = 1.0;
    for (int k = 0; k < 3; ++k) n *= std::floor(extent[k] / h) + 1.0;
    return n;
  };
  while (cells_for(cell) > 0.5 * nf + 64.0) cell *= 1.25;
  m_origin = lo;
  m_cell = cell;
  for (int k = 0; k < 3; ++k) m_dims[static_cast<std::size_t>(k)] = static_cast<int>(std::floor(extent[k] / cell)) + 1;
  m_cells.assign(static_cast<std::size_t>(m_dims[0]) * static_cast<std::size_t>(m_dims[1]) *
                     static_cast<std::size_t>(m_dims[2]),
                 {});
  m_stamp.assign(mesh.triangles.size(), 0);
  m_query = 0;
  // Counted first, so that each cell is allocated once.
  std::vector<uint32_t> count(m_cells.size(), 0);
  const auto index = [&](const std::vector<int32_t>& cell) { return static_cast<std::size_t>(&cell - m_cells.data()); };
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    Vec3 a, b;
    face_box(mesh, static_cast<int32_t>(f), a, b);
    for_cells(a, b, [&](std::vector<int32_t>& cell) { ++count[index(cell)]; });
  }
  for (std::size_t c = 0; c < m_cells.size(); ++c) m_cells[c].reserve(count[c]);
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) insert(mesh, static_cast<int32_t>(f));
}

std::array<int, 3> FaceGrid::cell_of(const Vec3& p) const {
  // (p - origin) / cell, truncated: monotone in p, which is all that insert, erase and query need to agree.
  std::array<int, 3> c{};
  const double inverse = 1.0 / m_cell;  // 1/m
  for (int k = 0; k < 3; ++k) {
    const double x = (p[k] - m_origin[k]) * inverse;
    const int n = m_dims[static_cast<std::size_t>(k)];
    // NaN and anything below 1 land in cell 0 (positions are finite here; a query may pass infinities).
    c[static_cast<std::size_t>(k)] = !(x >= 1.0) ? 0 : (x >= static_cast<double>(n - 1) ? n - 1 : static_cast<int>(x));
  }
  return c;
}

template <class Visit>
void FaceGrid::for_cells(const Vec3& lo, const Vec3& hi, Visit&& visit) {
  const std::array<int, 3> a = cell_of(lo), b = cell_of(hi);
  for (int z = a[2]; z <= b[2]; ++z) {
    for (int y = a[1]; y <= b[1]; ++y) {
      for (int x = a[0]; x <= b[0]; ++x) {
        visit(m_cells[(static_cast<std::size_t>(z) * static_cast<std::size_t>(m_dims[1]) + static_cast<std::size_t>(y)) *
                          static_cast<std::size_t>(m_dims[0]) +
                      static_cast<std::size_t>(x)]);
      }
    }
  }
}

void FaceGrid::insert(const sim::TriMesh& mesh, int32_t f) {
  Vec3 lo, hi;
  face_box(mesh, f, lo, hi);
  for_cells(lo, hi, [f](std::vector<int32_t>& cell) { cell.push_back(f); });
  if (static_cast<std::size_t>(f) >= m_stamp.size()) m_stamp.resize(static_cast<std::size_t>(f) + 1, 0);
}

void FaceGrid::erase(const sim::TriMesh& mesh, int32_t f) {
  Vec3 lo, hi;
  face_box(mesh, f, lo, hi);
  for_cells(lo, hi, [f](std::vector<int32_t>& cell) {
    const auto it = std::find(cell.begin(), cell.end(), f);
    if (it != cell.end()) {
      *it = cell.back();
      cell.pop_back();
    }
  });
}

void FaceGrid::rename(const sim::TriMesh& mesh, const Tri& t, int32_t from, int32_t to) {
  Vec3 lo, hi;
  triangle_box(mesh, t, lo, hi);
  for_cells(lo, hi, [from, to](std::vector<int32_t>& cell) {
    const auto it = std::find(cell.begin(), cell.end(), from);
    if (it != cell.end()) *it = to;
  });
  if (static_cast<std::size_t>(to) >= m_stamp.size()) m_stamp.resize(static_cast<std::size_t>(to) + 1, 0);
}

std::vector<int32_t> FaceGrid::query(const sim::TriMesh& mesh, const Vec3& lo, const Vec3& hi) {
  std::vector<int32_t> out;
  if (m_cells.empty()) return out;
  if (++m_query == 0) {  // the stamps wrapped around: start again
    std::fill(m_stamp.begin(), m_stamp.end(), 0);
    m_query = 1;
  }
  for_cells(lo, hi, [&](const std::vector<int32_t>& cell) {
    for (const int32_t f : cell) {
      uint32_t& s = m_stamp[static_cast<std::size_t>(f)];
      if (s == m_query) continue;
      s = m_query;
      Vec3 a, b;
      face_box(mesh, f, a, b);
      if ((a.array() <= hi.array()).all() && (b.array() >= lo.array()).all()) out.push_back(f);
    }
  });
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<int32_t> FaceGrid::around(const sim::TriMesh& mesh, int32_t v) {
  const Vec3& p = mesh.vertices[static_cast<std::size_t>(v)];
  std::vector<int32_t> out = query(mesh, p, p);
  std::erase_if(out, [&](int32_t f) {
    const Tri& t = mesh.triangles[static_cast<std::size_t>(f)];
    return t[0] != v && t[1] != v && t[2] != v;
  });
  return out;
}

SurfaceEditor::SurfaceEditor(sim::TriMesh& mesh, FaceGrid& grid, std::vector<char>* cut, std::vector<int32_t>* origin)
    : m_mesh(mesh), m_grid(grid), m_cut(cut), m_origin(origin) {
  // Values missing at the end count as 0 (cut) and -1 (origin).
  if (m_cut != nullptr) m_cut->resize(m_mesh.triangles.size(), 0);
  if (m_origin != nullptr) m_origin->resize(m_mesh.triangles.size(), -1);
}

FaceAttributes SurfaceEditor::attributes(int32_t f) const {
  FaceAttributes a;
  if (m_cut != nullptr && static_cast<std::size_t>(f) < m_cut->size()) a.cut = (*m_cut)[static_cast<std::size_t>(f)];
  if (m_origin != nullptr && static_cast<std::size_t>(f) < m_origin->size()) {
    a.origin = (*m_origin)[static_cast<std::size_t>(f)];
  }
  return a;
}

int32_t SurfaceEditor::add_vertex(const Vec3& p) {
  m_mesh.vertices.push_back(p);
  m_journal.push_back({Op::add_vertex, -1, {}, {}});
  return static_cast<int32_t>(m_mesh.vertices.size() - 1);
}

void SurfaceEditor::write_face(int32_t f, const Tri& t, FaceAttributes a) {
  m_grid.erase(m_mesh, f);
  m_mesh.triangles[static_cast<std::size_t>(f)] = t;
  if (m_cut != nullptr) (*m_cut)[static_cast<std::size_t>(f)] = a.cut;
  if (m_origin != nullptr) (*m_origin)[static_cast<std::size_t>(f)] = a.origin;
  m_grid.insert(m_mesh, f);
}

void SurfaceEditor::push_face(const Tri& t, FaceAttributes a) {
  m_mesh.triangles.push_back(t);
  if (m_cut != nullptr) m_cut->push_back(a.cut);
  if (m_origin != nullptr) m_origin->push_back(a.origin);
  m_grid.insert(m_mesh, static_cast<int32_t>(m_mesh.triangles.size() - 1));
}

void SurfaceEditor::pop_face() {
  m_grid.erase(m_mesh, static_cast<int32_t>(m_mesh.triangles.size() - 1));
  m_mesh.triangles.pop_back();
  if (m_cut != nullptr) m_cut->pop_back();
  if (m_origin != nullptr) m_origin->pop_back();
}

void SurfaceEditor::set_face(int32_t f, const Tri& t, FaceAttributes a) {
  m_journal.push_back({Op::set_face, f, m_mesh.triangles[static_cast<std::size_t>(f)], attributes(f)});
  write_face(f, t, a);
}

int32_t SurfaceEditor::add_face(const Tri& t, FaceAttributes a) {
  push_face(t, a);
  m_journal.push_back({Op::add_face, -1, {}, {}});
  return static_cast<int32_t>(m_mesh.triangles.size() - 1);
}

int32_t SurfaceEditor::remove_face(int32_t f) {
  const auto last = static_cast<int32_t>(m_mesh.triangles.size() - 1);
  if (f == last) {
    m_journal.push_back({Op::remove_last_face, last, m_mesh.triangles[static_cast<std::size_t>(last)], attributes(last)});
    pop_face();
    return -1;
  }
  // The last triangle takes f's place: in the grid it only changes its name.
  m_journal.push_back({Op::move_last_face, f, m_mesh.triangles[static_cast<std::size_t>(f)], attributes(f)});
  m_grid.erase(m_mesh, f);
  const Tri moved = m_mesh.triangles[static_cast<std::size_t>(last)];
  m_grid.rename(m_mesh, moved, last, f);
  m_mesh.triangles[static_cast<std::size_t>(f)] = moved;
  m_mesh.triangles.pop_back();
  if (m_cut != nullptr) {
    (*m_cut)[static_cast<std::size_t>(f)] = (*m_cut)[static_cast<std::size_t>(last)];
    m_cut->pop_back();
  }
  if (m_origin != nullptr) {
    (*m_origin)[static_cast<std::size_t>(f)] = (*m_origin)[static_cast<std::size_t>(last)];
    m_origin->pop_back();
  }
  return last;
}

void SurfaceEditor::remove_faces(std::span<const int32_t> ascending) {
  for (auto it = ascending.rbegin(); it != ascending.rend(); ++it) remove_face(*it);
}

void SurfaceEditor::rollback(std::size_t mark) {
  while (m_journal.size() > mark) {
    const Entry e = m_journal.back();
    m_journal.pop_back();
    switch (e.op) {
      case Op::set_face: write_face(e.face, e.old, e.old_attributes); break;
      case Op::add_face: pop_face(); break;
      case Op::remove_last_face: push_face(e.old, e.old_attributes); break;
      case Op::move_last_face: {
        // The triangle now at e.face goes back to the end, and e.face gets its old triangle.
        const Tri moved = m_mesh.triangles[static_cast<std::size_t>(e.face)];
        const FaceAttributes a = attributes(e.face);
        const auto last = static_cast<int32_t>(m_mesh.triangles.size());
        m_mesh.triangles.push_back(moved);
        if (m_cut != nullptr) m_cut->push_back(a.cut);
        if (m_origin != nullptr) m_origin->push_back(a.origin);
        m_grid.rename(m_mesh, moved, e.face, last);
        m_mesh.triangles[static_cast<std::size_t>(e.face)] = e.old;
        if (m_cut != nullptr) (*m_cut)[static_cast<std::size_t>(e.face)] = e.old_attributes.cut;
        if (m_origin != nullptr) (*m_origin)[static_cast<std::size_t>(e.face)] = e.old_attributes.origin;
        m_grid.insert(m_mesh, e.face);
        break;
      }
      case Op::add_vertex: m_mesh.vertices.pop_back(); break;
    }
  }
}

}  // namespace octocut::cutting
