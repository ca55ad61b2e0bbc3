// The procedural assets in assets/meshes/ (SPEC §9) and `octocut assets` (SPEC §7). Everything here is checked
// against independent truths: the committed files (byte-for-byte regeneration), a PLY reader, an edge-count
// topology check, exact integer predicates for degeneracy and triangle–triangle intersection, vertical ray casting
// for the meniscus' shape, and the analytic polygon areas of the blades. None of it uses the generator's code.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "common/cli_util.hpp"

namespace {

namespace fs = std::filesystem;
using Vec = std::array<double, 3>;
using IVec = std::array<int64_t, 3>;
using Tri = std::array<int32_t, 3>;
using i128 = __int128;

constexpr double k_pi = std::numbers::pi;
constexpr double k_grid = 65536.0;  ///< the assets' coordinate grid: 2^-16 mm

/// The files `octocut assets` writes.
const std::vector<std::string> k_files = {"meniscus_10k.ply",  "meniscus_50k.ply", "punch.ply",
                                          "blade_cyl2mm.ply",  "blade_star.ply",   "blade_cyl20mm.ply",
                                          "femur_condyle.ply", "tibia_plateau.ply"};

/// A mesh as read from a PLY file, mm.
struct Mesh {
  std::vector<Vec> v;  ///< positions, mm (|V|)
  std::vector<Tri> f;  ///< triangles (|F|)
};

std::string slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// Reads the binary little-endian PLY layout the assets use (float x y z; uchar count, int32 indices). Fails the
/// test with the file name on anything else.
Mesh read_ply(const fs::path& path) {
  const std::string bytes = slurp(path);
  Mesh mesh;
  const std::size_t end = bytes.find("end_header\n");
  EXPECT_NE(end, std::string::npos) << path;
  if (end == std::string::npos) return mesh;
  std::istringstream header(bytes.substr(0, end));
  std::string line, expected_props;
  std::size_t nv = 0, nf = 0;
  while (std::getline(header, line)) {
    if (line.rfind("format", 0) == 0) {
      EXPECT_EQ(line, "format binary_little_endian 1.0") << path;
    }
    if (line.rfind("element vertex ", 0) == 0) nv = std::stoul(line.substr(15));
    if (line.rfind("element face ", 0) == 0) nf = std::stoul(line.substr(13));
    if (line.rfind("property", 0) == 0) expected_props += line + ";";
  }
  EXPECT_EQ(expected_props,
            "property float x;property float y;property float z;property list uchar int vertex_indices;")
      << path;
  std::size_t pos = end + 11;
  EXPECT_EQ(bytes.size(), pos + nv * 12 + nf * 13) << path;
  if (bytes.size() != pos + nv * 12 + nf * 13) return mesh;
  for (std::size_t i = 0; i < nv; ++i) {
    float xyz[3];
    std::memcpy(xyz, bytes.data() + pos, 12);
    pos += 12;
    mesh.v.push_back({xyz[0], xyz[1], xyz[2]});
  }
  for (std::size_t i = 0; i < nf; ++i) {
    EXPECT_EQ(static_cast<unsigned char>(bytes[pos]), 3u) << path << ": face " << i;
    Tri t;
    std::memcpy(t.data(), bytes.data() + pos + 1, 12);
    pos += 13;
    mesh.f.push_back(t);
  }
  return mesh;
}

/// The committed mesh `name`, read once.
const Mesh& committed(const std::string& name) {
  static std::map<std::string, Mesh> cache;
  auto it = cache.find(name);
  if (it == cache.end()) {
    it = cache.emplace(name, read_ply(fs::path(OCTOCUT_SOURCE_DIR) / "assets" / "meshes" / name)).first;
  }
  return it->second;
}

/// Signed enclosed volume, mm^3 (sum of origin tetrahedra).
double volume(const Mesh& m) {
  double six = 0.0;
  for (const Tri& t : m.f) {
    const Vec &a = m.v[t[0]], &b = m.v[t[1]], &c = m.v[t[2]];
    six += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0]);
  }
  return six / 6.0;
}

/// Number of connected components (triangles joined through shared vertices).
int components(const Mesh& m) {
  std::vector<int> parent(m.v.size());
  for (std::size_t i = 0; i < parent.size(); ++i) parent[i] = static_cast<int>(i);
  const auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const Tri& t : m.f) {
    parent[find(t[1])] = find(t[0]);
    parent[find(t[2])] = find(t[0]);
  }
  int count = 0;
  for (std::size_t i = 0; i < parent.size(); ++i) count += find(static_cast<int>(i)) == static_cast<int>(i);
  return count;
}

/// Closed, edge-manifold and consistently oriented: every directed edge occurs exactly once and its reverse exactly
/// once. Also: indices in range, three distinct indices per triangle, every vertex used. Returns the first problem.
std::string topology_problem(const Mesh& m) {
  std::unordered_map<uint64_t, int> directed;
  std::vector<char> used(m.v.size(), 0);
  for (std::size_t i = 0; i < m.f.size(); ++i) {
    const Tri& t = m.f[i];
    for (int k = 0; k < 3; ++k) {
      if (t[k] < 0 || static_cast<std::size_t>(t[k]) >= m.v.size())
        return "triangle " + std::to_string(i) + ": index out of range";
      used[static_cast<std::size_t>(t[k])] = 1;
    }
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) return "triangle " + std::to_string(i) + ": repeated vertex";
    for (int k = 0; k < 3; ++k) {
      const uint64_t key = (static_cast<uint64_t>(t[k]) << 32) | static_cast<uint32_t>(t[(k + 1) % 3]);
      if (++directed[key] > 1)
        return "triangle " + std::to_string(i) + ": directed edge used twice (not manifold or flipped)";
    }
  }
  for (const auto& [key, count] : directed) {
    const uint64_t reverse = (key << 32) | (key >> 32);
    if (directed.find(reverse) == directed.end())
      return "boundary edge " + std::to_string(key >> 32) + "-" + std::to_string(key & 0xffffffffu);
  }
  for (std::size_t i = 0; i < used.size(); ++i) {
    if (!used[i]) return "vertex " + std::to_string(i) + " unused";
  }
  return {};
}

// ---- exact predicates on the 2^-16 mm integer grid ------------------------------------------------------------------

/// Integer coordinates in units of 2^-16 mm. The test fails if a coordinate is off that grid or |x| ≥ 256 mm, so that
/// all the determinants below are exact in 128-bit integers (|differences| < 2^25, triple products < 2^78).
std::vector<IVec> to_grid(const Mesh& m) {
  std::vector<IVec> out;
  out.reserve(m.v.size());
  for (std::size_t i = 0; i < m.v.size(); ++i) {
    IVec q{};
    for (int k = 0; k < 3; ++k) {
      const double s = m.v[i][static_cast<std::size_t>(k)] * k_grid;
      EXPECT_TRUE(s == std::floor(s) && std::abs(m.v[i][static_cast<std::size_t>(k)]) < 256.0)
          << "vertex " << i << " off the grid";
      q[static_cast<std::size_t>(k)] = static_cast<int64_t>(s);
    }
    out.push_back(q);
  }
  return out;
}

int sign(i128 x) { return (x > 0) - (x < 0); }

IVec sub(const IVec& a, const IVec& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }

std::array<i128, 3> cross(const IVec& u, const IVec& v) {
  return {i128(u[1]) * v[2] - i128(u[2]) * v[1], i128(u[2]) * v[0] - i128(u[0]) * v[2],
          i128(u[0]) * v[1] - i128(u[1]) * v[0]};
}

/// Sign of the volume of (a, b, c, d): positive when d is above the plane of the counter-clockwise triangle abc.
int orient3d(const IVec& a, const IVec& b, const IVec& c, const IVec& d) {
  const auto n = cross(sub(b, a), sub(c, a));
  const IVec e = sub(d, a);
  return sign(n[0] * e[0] + n[1] * e[1] + n[2] * e[2]);
}

/// The axis along which the normal of abc is largest (dropped to project onto a plane without degeneracy).
int drop_axis(const IVec& a, const IVec& b, const IVec& c) {
  const auto n = cross(sub(b, a), sub(c, a));
  int best = 0;
  for (int k = 1; k < 3; ++k) {
    if ((n[k] < 0 ? -n[k] : n[k]) > (n[best] < 0 ? -n[best] : n[best])) best = k;
  }
  return best;
}

/// Orientation of (a, b, c) projected by dropping `axis`.
int orient2d(const IVec& a, const IVec& b, const IVec& c, int axis) {
  const int i = (axis + 1) % 3, j = (axis + 2) % 3;
  return sign(i128(b[i] - a[i]) * (c[j] - a[j]) - i128(b[j] - a[j]) * (c[i] - a[i]));
}

/// Is c (collinear with ab) on the closed segment ab?
bool on_segment(const IVec& a, const IVec& b, const IVec& c) {
  for (int k = 0; k < 3; ++k) {
    if (c[k] < std::min(a[k], b[k]) || c[k] > std::max(a[k], b[k])) return false;
  }
  return true;
}

/// Do the closed coplanar segments ab and cd meet?
bool segments_meet_2d(const IVec& a, const IVec& b, const IVec& c, const IVec& d, int axis) {
  const int o1 = orient2d(a, b, c, axis), o2 = orient2d(a, b, d, axis);
  const int o3 = orient2d(c, d, a, axis), o4 = orient2d(c, d, b, axis);
  if (o1 * o2 < 0 && o3 * o4 < 0) return true;
  return (o1 == 0 && on_segment(a, b, c)) || (o2 == 0 && on_segment(a, b, d)) || (o3 == 0 && on_segment(c, d, a)) ||
         (o4 == 0 && on_segment(c, d, b));
}

/// Is p in the closed coplanar triangle abc?
bool in_triangle_2d(const IVec& p, const IVec& a, const IVec& b, const IVec& c, int axis) {
  const int s1 = orient2d(a, b, p, axis), s2 = orient2d(b, c, p, axis), s3 = orient2d(c, a, p, axis);
  return (s1 >= 0 && s2 >= 0 && s3 >= 0) || (s1 <= 0 && s2 <= 0 && s3 <= 0);
}

/// Does the closed segment ab meet the closed (non-degenerate) triangle pqr?
bool segment_meets_triangle(const IVec& a, const IVec& b, const IVec& p, const IVec& q, const IVec& r) {
  const int sa = orient3d(p, q, r, a), sb = orient3d(p, q, r, b);
  if (sa * sb > 0) return false;
  // Coplanar: a 2D test in the plane of the triangle.
  if (sa == 0 && sb == 0) {
    const int axis = drop_axis(p, q, r);
    return in_triangle_2d(a, p, q, r, axis) || in_triangle_2d(b, p, q, r, axis) || segments_meet_2d(a, b, p, q, axis) ||
           segments_meet_2d(a, b, q, r, axis) || segments_meet_2d(a, b, r, p, axis);
  }
  // The segment reaches the plane: the line ab must pass through the triangle (all three sides agree).
  const int s1 = orient3d(a, b, p, q), s2 = orient3d(a, b, q, r), s3 = orient3d(a, b, r, p);
  return (s1 >= 0 && s2 >= 0 && s3 >= 0) || (s1 <= 0 && s2 <= 0 && s3 <= 0);
}

/// Is direction x - v inside the closed cone at v spanned by a - v and b - v (all coplanar)?
bool in_cone_2d(const IVec& v, const IVec& a, const IVec& b, const IVec& x, int axis) {
  const int c = orient2d(v, a, b, axis);
  return orient2d(v, a, x, axis) * c >= 0 && orient2d(v, x, b, axis) * c >= 0;
}

/// Do two triangles of one mesh intersect other than in the vertices or the edge they share?
bool triangles_intersect(const std::vector<IVec>& g, const Tri& t1, const Tri& t2) {
  int shared = 0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) shared += t1[i] == t2[j];
  }
  const auto P = [&](int32_t i) -> const IVec& { return g[static_cast<std::size_t>(i)]; };
  if (shared >= 3) return true;
  if (shared == 0) {
    for (int k = 0; k < 3; ++k) {
      if (segment_meets_triangle(P(t1[k]), P(t1[(k + 1) % 3]), P(t2[0]), P(t2[1]), P(t2[2]))) return true;
      if (segment_meets_triangle(P(t2[k]), P(t2[(k + 1) % 3]), P(t1[0]), P(t1[1]), P(t1[2]))) return true;
    }
    return false;
  }
  // Rotate both triangles so that the shared vertex (or the first shared one) comes first.
  const auto rotate_to = [](Tri t, int32_t v) {
    while (t[0] != v) t = {t[1], t[2], t[0]};
    return t;
  };
  int32_t v = -1;
  for (int i = 0; i < 3 && v < 0; ++i) {
    for (int j = 0; j < 3; ++j) {
      if (t1[i] == t2[j]) v = t1[i];
    }
  }
  if (shared == 2) {
    // Shared edge: only a coplanar fold-over (both far vertices on the same side of the edge) overlaps.
    int32_t c1 = -1, c2 = -1, u = -1, w = -1;
    for (int i = 0; i < 3; ++i) {
      if (std::find(t2.begin(), t2.end(), t1[i]) == t2.end()) c1 = t1[i];
      if (std::find(t1.begin(), t1.end(), t2[i]) == t1.end()) c2 = t2[i];
    }
    for (int i = 0; i < 3; ++i) {
      if (t1[i] != c1) (u < 0 ? u : w) = t1[i];
    }
    if (orient3d(P(u), P(w), P(c1), P(c2)) != 0) return false;
    const int axis = drop_axis(P(u), P(w), P(c1));
    return orient2d(P(u), P(w), P(c1), axis) == orient2d(P(u), P(w), P(c2), axis);
  }
  // One shared vertex v: the opposite edges must miss the other triangle, and an edge from v may lie in the other
  // triangle's plane only if it points outside that triangle's corner at v.
  const Tri a = rotate_to(t1, v), b = rotate_to(t2, v);
  if (segment_meets_triangle(P(a[1]), P(a[2]), P(b[0]), P(b[1]), P(b[2]))) return true;
  if (segment_meets_triangle(P(b[1]), P(b[2]), P(a[0]), P(a[1]), P(a[2]))) return true;
  for (const auto& [s, o] : {std::pair<Tri, Tri>{a, b}, std::pair<Tri, Tri>{b, a}}) {
    const int axis = drop_axis(P(o[0]), P(o[1]), P(o[2]));
    for (int k = 1; k <= 2; ++k) {
      if (orient3d(P(o[0]), P(o[1]), P(o[2]), P(s[k])) == 0 && in_cone_2d(P(v), P(o[1]), P(o[2]), P(s[k]), axis))
        return true;
    }
  }
  return false;
}

/// Index of a triangle whose vertices are collinear (exactly), or -1.
long degenerate_triangle(const Mesh& m, const std::vector<IVec>& g) {
  for (std::size_t i = 0; i < m.f.size(); ++i) {
    const Tri& t = m.f[i];
    const auto n = cross(sub(g[t[1]], g[t[0]]), sub(g[t[2]], g[t[0]]));
    if (n[0] == 0 && n[1] == 0 && n[2] == 0) return static_cast<long>(i);
  }
  return -1;
}

/// Pairs of intersecting triangles (exact), found through a uniform grid over the triangles' bounding boxes. Each
/// candidate pair is tested once: in the cell that holds the low corner of the overlap of their boxes.
std::vector<std::pair<int, int>> self_intersections(const Mesh& m, const std::vector<IVec>& g, std::size_t limit = 10) {
  const std::size_t nf = m.f.size();
  std::vector<IVec> lo(nf), hi(nf);
  IVec bmin = g[0], bmax = g[0];
  double edge_sum = 0.0;
  for (std::size_t i = 0; i < nf; ++i) {
    for (int k = 0; k < 3; ++k) {
      lo[i][k] = std::min({g[m.f[i][0]][k], g[m.f[i][1]][k], g[m.f[i][2]][k]});
      hi[i][k] = std::max({g[m.f[i][0]][k], g[m.f[i][1]][k], g[m.f[i][2]][k]});
      bmin[k] = std::min(bmin[k], lo[i][k]);
      bmax[k] = std::max(bmax[k], hi[i][k]);
    }
    edge_sum += static_cast<double>(std::max({hi[i][0] - lo[i][0], hi[i][1] - lo[i][1], hi[i][2] - lo[i][2]}));
  }
  // Cell size: twice the mean box size, grown until the grid has at most 4M cells.
  double cell = std::max(1.0, 2.0 * edge_sum / static_cast<double>(nf));
  std::array<int64_t, 3> dims{};
  for (;;) {
    for (int k = 0; k < 3; ++k) dims[k] = static_cast<int64_t>((bmax[k] - bmin[k]) / cell) + 1;
    if (dims[0] * dims[1] * dims[2] <= 4'000'000) break;
    cell *= 1.5;
  }
  const auto cell_of = [&](int64_t x, int k) {
    return std::min<int64_t>(dims[k] - 1, static_cast<int64_t>((x - bmin[k]) / cell));
  };
  std::vector<std::vector<int>> cells(static_cast<std::size_t>(dims[0] * dims[1] * dims[2]));
  const auto id = [&](int64_t i, int64_t j, int64_t k) {
    return static_cast<std::size_t>((i * dims[1] + j) * dims[2] + k);
  };
  for (std::size_t t = 0; t < nf; ++t) {
    for (int64_t i = cell_of(lo[t][0], 0); i <= cell_of(hi[t][0], 0); ++i) {
      for (int64_t j = cell_of(lo[t][1], 1); j <= cell_of(hi[t][1], 1); ++j) {
        for (int64_t k = cell_of(lo[t][2], 2); k <= cell_of(hi[t][2], 2); ++k)
          cells[id(i, j, k)].push_back(static_cast<int>(t));
      }
    }
  }
  std::vector<std::pair<int, int>> hits;
  for (int64_t i = 0; i < dims[0]; ++i) {
    for (int64_t j = 0; j < dims[1]; ++j) {
      for (int64_t k = 0; k < dims[2]; ++k) {
        const auto& list = cells[id(i, j, k)];
        for (std::size_t x = 0; x < list.size(); ++x) {
          for (std::size_t y = x + 1; y < list.size(); ++y) {
            const int s = list[x], t = list[y];
            bool overlap = true;
            IVec corner{};
            for (int c = 0; c < 3; ++c) {
              overlap = overlap && lo[s][c] <= hi[t][c] && lo[t][c] <= hi[s][c];
              corner[c] = std::max(lo[s][c], lo[t][c]);
            }
            if (!overlap || cell_of(corner[0], 0) != i || cell_of(corner[1], 1) != j || cell_of(corner[2], 2) != k)
              continue;
            if (triangles_intersect(g, m.f[s], m.f[t])) {
              hits.emplace_back(s, t);
              if (hits.size() >= limit) return hits;
            }
          }
        }
      }
    }
  }
  return hits;
}

/// Pairs of intersecting triangles found by testing every pair whose bounding boxes overlap (no grid).
std::vector<std::pair<int, int>> brute_force_intersections(const Mesh& m, const std::vector<IVec>& g) {
  std::vector<std::pair<int, int>> hits;
  std::vector<std::array<IVec, 2>> boxes;
  for (const Tri& t : m.f) {
    std::array<IVec, 2> b{g[t[0]], g[t[0]]};
    for (int k = 1; k < 3; ++k) {
      for (int c = 0; c < 3; ++c) b[0][c] = std::min(b[0][c], g[t[k]][c]), b[1][c] = std::max(b[1][c], g[t[k]][c]);
    }
    boxes.push_back(b);
  }
  for (std::size_t s = 0; s < m.f.size(); ++s) {
    for (std::size_t t = s + 1; t < m.f.size(); ++t) {
      bool overlap = true;
      for (int c = 0; c < 3; ++c)
        overlap = overlap && boxes[s][0][c] <= boxes[t][1][c] && boxes[t][0][c] <= boxes[s][1][c];
      if (overlap && triangles_intersect(g, m.f[s], m.f[t]))
        hits.emplace_back(static_cast<int>(s), static_cast<int>(t));
    }
  }
  return hits;
}

/// All validity checks on one mesh: topology, exact non-degeneracy, positive volume, no self-intersection.
void expect_valid_solid(const std::string& name) {
  SCOPED_TRACE(name);
  const Mesh& m = committed(name);
  ASSERT_FALSE(m.f.empty());
  EXPECT_EQ(topology_problem(m), "");
  const std::vector<IVec> g = to_grid(m);
  EXPECT_EQ(degenerate_triangle(m, g), -1);
  EXPECT_GT(volume(m), 0.0);
  const auto hits = self_intersections(m, g);
  EXPECT_TRUE(hits.empty()) << "triangles " << (hits.empty() ? 0 : hits[0].first) << " and "
                            << (hits.empty() ? 0 : hits[0].second) << " intersect";
}

/// Bounding box {min, max} of a mesh, mm.
std::array<Vec, 2> box_of(const Mesh& m) {
  std::array<Vec, 2> b{m.v[0], m.v[0]};
  for (const Vec& p : m.v) {
    for (int k = 0; k < 3; ++k) {
      b[0][k] = std::min(b[0][k], p[k]);
      b[1][k] = std::max(b[1][k], p[k]);
    }
  }
  return b;
}

/// Vertical extent of the solid above (x, y), mm: the summed lengths of the inside intervals of the vertical line,
/// from the heights where the line crosses triangles (duplicates on shared edges merged).
class VerticalRays {
 public:
  explicit VerticalRays(const Mesh& m) : m_mesh(m), m_box(box_of(m)) {
    // Bin the triangles by their xy bounding boxes on a 0.5 mm grid.
    m_nx = static_cast<int>((m_box[1][0] - m_box[0][0]) / k_cell) + 1;
    m_ny = static_cast<int>((m_box[1][1] - m_box[0][1]) / k_cell) + 1;
    m_bins.resize(static_cast<std::size_t>(m_nx * m_ny));
    for (std::size_t t = 0; t < m.f.size(); ++t) {
      double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
      for (int k = 0; k < 3; ++k) {
        x0 = std::min(x0, m.v[m.f[t][k]][0]), x1 = std::max(x1, m.v[m.f[t][k]][0]);
        y0 = std::min(y0, m.v[m.f[t][k]][1]), y1 = std::max(y1, m.v[m.f[t][k]][1]);
      }
      for (int i = bin(x0, 0); i <= bin(x1, 0); ++i) {
        for (int j = bin(y0, 1); j <= bin(y1, 1); ++j)
          m_bins[static_cast<std::size_t>(i * m_ny + j)].push_back(static_cast<int>(t));
      }
    }
  }

  /// Summed inside length of the vertical line through (x, y), mm; 0 outside the footprint.
  [[nodiscard]] double thickness(double x, double y) const {
    if (x < m_box[0][0] || x > m_box[1][0] || y < m_box[0][1] || y > m_box[1][1]) return 0.0;
    std::vector<double> zs;
    for (int t : m_bins[static_cast<std::size_t>(bin(x, 0) * m_ny + bin(y, 1))]) {
      const Vec &a = m_mesh.v[m_mesh.f[t][0]], &b = m_mesh.v[m_mesh.f[t][1]], &c = m_mesh.v[m_mesh.f[t][2]];
      const double det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
      if (det == 0.0) continue;
      const double l1 = ((x - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (y - a[1])) / det;
      const double l2 = ((b[0] - a[0]) * (y - a[1]) - (x - a[0]) * (b[1] - a[1])) / det;
      if (l1 < 0.0 || l2 < 0.0 || l1 + l2 > 1.0) continue;
      zs.push_back(a[2] + l1 * (b[2] - a[2]) + l2 * (c[2] - a[2]));
    }
    std::sort(zs.begin(), zs.end());
    zs.erase(std::unique(zs.begin(), zs.end(), [](double p, double q) { return q - p < 1e-7; }), zs.end());
    double sum = 0.0;
    for (std::size_t k = 0; k + 1 < zs.size(); k += 2) sum += zs[k + 1] - zs[k];
    return sum;
  }

 private:
  static constexpr double k_cell = 0.5;  ///< bin size, mm
  [[nodiscard]] int bin(double v, int axis) const {
    const int n = axis == 0 ? m_nx : m_ny;
    return std::clamp(static_cast<int>((v - m_box[0][static_cast<std::size_t>(axis)]) / k_cell), 0, n - 1);
  }
  const Mesh& m_mesh;
  std::array<Vec, 2> m_box;
  int m_nx = 0, m_ny = 0;
  std::vector<std::vector<int>> m_bins;  ///< triangle ids per xy bin (nx · ny)
};

/// The wedge measured along one horizontal ray from `centre` at angle `theta`.
struct RadialProfile {
  double r_inner = 0.0;   ///< where the footprint starts, mm
  double r_outer = 0.0;   ///< where it ends, mm
  double r_peak = 0.0;    ///< where the thickness is largest, mm
  double peak = 0.0;      ///< largest thickness, mm
  std::vector<double> t;  ///< thickness every 0.05 mm from the centre, mm
};

RadialProfile radial_profile(const VerticalRays& rays, double cx, double cy, double theta) {
  RadialProfile p;
  constexpr double k_step = 0.05;
  bool inside = false;
  for (int i = 0; i * k_step < 40.0; ++i) {
    const double r = i * k_step;
    const double t = rays.thickness(cx + r * std::cos(theta), cy + r * std::sin(theta));
    p.t.push_back(t);
    if (t > 0.0 && !inside) p.r_inner = r, inside = true;
    if (t > 0.0) p.r_outer = r;
    if (t > p.peak) p.peak = t, p.r_peak = r;
  }
  return p;
}

double thickness_at(const RadialProfile& p, double r) { return p.t[static_cast<std::size_t>(std::lround(r / 0.05))]; }

/// Distance from p to triangle abc, mm (closest point by region, Ericson §5.1.5).
double point_triangle_distance(const Vec& p, const Vec& a, const Vec& b, const Vec& c) {
  const auto sub3 = [](const Vec& u, const Vec& v) { return Vec{u[0] - v[0], u[1] - v[1], u[2] - v[2]}; };
  const auto dot = [](const Vec& u, const Vec& v) { return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]; };
  const auto at = [&](double v, double w) {
    Vec q;
    for (int k = 0; k < 3; ++k) q[k] = a[k] + v * (b[k] - a[k]) + w * (c[k] - a[k]);
    const Vec d = sub3(p, q);
    return std::sqrt(dot(d, d));
  };
  const Vec ab = sub3(b, a), ac = sub3(c, a), ap = sub3(p, a);
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return at(0, 0);
  const Vec bp = sub3(p, b);
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return at(1, 0);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return at(d1 / (d1 - d3), 0);
  const Vec cp = sub3(p, c);
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return at(0, 1);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return at(0, d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return at(1 - w, w);
  }
  const double denom = 1.0 / (va + vb + vc);
  return at(vb * denom, vc * denom);
}

/// Smallest distance from any vertex of `from` to the surface of `to`, mm (triangles skipped by a box bound).
double min_vertex_distance(const Mesh& from, const Mesh& to) {
  std::vector<std::array<Vec, 2>> boxes;
  for (const Tri& t : to.f) {
    std::array<Vec, 2> b{to.v[t[0]], to.v[t[0]]};
    for (int k = 1; k < 3; ++k) {
      for (int c = 0; c < 3; ++c)
        b[0][c] = std::min(b[0][c], to.v[t[k]][c]), b[1][c] = std::max(b[1][c], to.v[t[k]][c]);
    }
    boxes.push_back(b);
  }
  double best = 1e30;
  for (const Vec& p : from.v) {
    for (std::size_t i = 0; i < to.f.size(); ++i) {
      double d2 = 0.0;
      for (int c = 0; c < 3; ++c) {
        const double e = std::max({boxes[i][0][c] - p[c], 0.0, p[c] - boxes[i][1][c]});
        d2 += e * e;
      }
      if (d2 >= best * best) continue;
      best = std::min(best, point_triangle_distance(p, to.v[to.f[i][0]], to.v[to.f[i][1]], to.v[to.f[i][2]]));
    }
  }
  return best;
}

/// The union of several meshes (vertex indices shifted).
Mesh merged(const std::vector<const Mesh*>& parts) {
  Mesh out;
  for (const Mesh* m : parts) {
    const auto offset = static_cast<int32_t>(out.v.size());
    out.v.insert(out.v.end(), m->v.begin(), m->v.end());
    for (const Tri& t : m->f) out.f.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  }
  return out;
}

// ---- tests ----------------------------------------------------------------------------------------------------------

/// A closed tetrahedron (outward oriented) with corner `o` and edge length `e`, mm.
Mesh tetrahedron(const Vec& o, double e) {
  Mesh m;
  m.v = {o, {o[0] + e, o[1], o[2]}, {o[0], o[1] + e, o[2]}, {o[0], o[1], o[2] + e}};
  m.f = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return m;
}

TEST(AssetsCheckers, DetectIntersectionsAndBrokenTopology) {
  // The checkers used above must be able to fail: a valid solid passes, overlapping and touching ones do not.
  const Mesh a = tetrahedron({0, 0, 0}, 4.0);
  EXPECT_EQ(topology_problem(a), "");
  EXPECT_GT(volume(a), 0.0);
  EXPECT_TRUE(self_intersections(a, to_grid(a)).empty());
  const Mesh far = tetrahedron({5, 0, 0}, 4.0), shifted = tetrahedron({1, 1, 1}, 4.0);
  const Mesh corner = tetrahedron({4, 0, 0}, 4.0), small = tetrahedron({0.25, 0.25, 0.25}, 1.0);
  const Mesh apart = merged({&a, &far});
  EXPECT_TRUE(self_intersections(apart, to_grid(apart)).empty());
  const Mesh overlapping = merged({&a, &shifted});
  EXPECT_FALSE(self_intersections(overlapping, to_grid(overlapping)).empty());
  const Mesh touching = merged({&a, &corner});  // corner on a's corner
  EXPECT_FALSE(self_intersections(touching, to_grid(touching)).empty());
  const Mesh nested = merged({&a, &small});  // inside, surfaces apart
  EXPECT_TRUE(self_intersections(nested, to_grid(nested)).empty());

  // A 4 mm cube is valid; with its corner (4, 4, 4) pushed through the bottom face it is not.
  Mesh cube;
  for (int i = 0; i < 8; ++i) cube.v.push_back({4.0 * (i & 1), 4.0 * ((i >> 1) & 1), 4.0 * ((i >> 2) & 1)});
  cube.f = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}, {0, 1, 5}, {0, 5, 4},
            {2, 6, 7}, {2, 7, 3}, {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
  EXPECT_EQ(topology_problem(cube), "");
  EXPECT_NEAR(volume(cube), 64.0, 1e-12);
  EXPECT_TRUE(self_intersections(cube, to_grid(cube)).empty());
  Mesh pierced = cube;
  pierced.v[7] = {2.0, 2.0, -1.0};
  EXPECT_FALSE(self_intersections(pierced, to_grid(pierced)).empty());
  EXPECT_EQ(self_intersections(pierced, to_grid(pierced), 1000), brute_force_intersections(pierced, to_grid(pierced)));

  // Coplanar fold-over across a shared edge, and coplanar overlap at a shared vertex.
  Mesh fold;
  fold.v = {{0, 0, 0}, {4, 0, 0}, {0, 4, 0}, {1, 3, 0}, {3, -1, 0}};
  fold.f = {{0, 1, 2}, {0, 1, 3}};
  EXPECT_FALSE(self_intersections(fold, to_grid(fold)).empty());
  fold.f = {{0, 1, 2}, {0, 4, 3}};
  EXPECT_FALSE(self_intersections(fold, to_grid(fold)).empty());
  fold.v[3] = {-1, -3, 0};  // now the shared-vertex pair meets only at vertex 0
  fold.v[4] = {-3, -1, 0};
  EXPECT_TRUE(self_intersections(fold, to_grid(fold)).empty());

  // Topology: a missing triangle leaves a boundary, a flipped one repeats a directed edge, a collinear one is
  // degenerate.
  Mesh open = a;
  open.f.pop_back();
  EXPECT_NE(topology_problem(open), "");
  Mesh flipped = a;
  std::swap(flipped.f[0][1], flipped.f[0][2]);
  EXPECT_NE(topology_problem(flipped), "");
  Mesh flat = a;
  flat.v[3] = {2.0, 2.0, 0.0};
  EXPECT_NE(degenerate_triangle(flat, to_grid(flat)), -1);
}

TEST(Assets, RegenerationIsByteIdenticalToCommittedFiles) {
  const fs::path dir = fs::temp_directory_path() / ("octocut_assets_test_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const auto result = octocut::test::run_octocut("assets --out '" + dir.string() + "'");
  ASSERT_EQ(result.exit_code, 0) << result.output;
  for (const std::string& name : k_files) {
    const std::string fresh = slurp(dir / name);
    const std::string stored = slurp(fs::path(OCTOCUT_SOURCE_DIR) / "assets" / "meshes" / name);
    EXPECT_FALSE(fresh.empty()) << name;
    EXPECT_TRUE(fresh == stored) << name << " differs from the committed file (run `octocut assets` and commit)";
    // The summary line names the file and its counts.
    const Mesh& m = committed(name);
    EXPECT_NE(result.output.find(name), std::string::npos) << result.output;
    EXPECT_NE(result.output.find(std::to_string(m.v.size())), std::string::npos) << name;
  }
  fs::remove_all(dir);
}

TEST(Assets, UnwritableOutputDirectoryIsAClearError) {
  // A directory below a regular file cannot be created.
  const fs::path file = fs::temp_directory_path() / ("octocut_assets_file_" + std::to_string(::getpid()));
  std::ofstream(file) << "x";
  const auto result = octocut::test::run_octocut("assets --out '" + (file / "sub").string() + "'");
  EXPECT_NE(result.exit_code, 0);
  EXPECT_NE(result.output.find((file / "sub").string()), std::string::npos) << result.output;
  fs::remove(file);
}

TEST(Assets, EveryMeshIsAClosedOrientedManifoldWithoutSelfIntersections) {
  for (const std::string& name : k_files) expect_valid_solid(name);
}

TEST(Assets, SmallMeshesAlsoPassABruteForceIntersectionTest) {
  // Every pair of triangles (boxes overlapping), without the grid.
  for (const char* name : {"punch.ply", "blade_cyl2mm.ply", "blade_star.ply", "blade_cyl20mm.ply", "femur_condyle.ply",
                           "tibia_plateau.ply"}) {
    const Mesh& m = committed(name);
    EXPECT_TRUE(brute_force_intersections(m, to_grid(m)).empty()) << name;
  }
}

TEST(Assets, MeniscusVertexCounts) {
  EXPECT_NEAR(static_cast<double>(committed("meniscus_10k.ply").v.size()), 10000.0, 1000.0);
  EXPECT_NEAR(static_cast<double>(committed("meniscus_50k.ply").v.size()), 50000.0, 5000.0);
  EXPECT_EQ(components(committed("meniscus_10k.ply")), 1);
  EXPECT_EQ(components(committed("meniscus_50k.ply")), 1);
}

/// The meniscus' shape against SPEC §9, measured by vertical ray casting: box, flat bottom, arc span, and the wedge
/// along radial rays (inner free edge thickness, peripheral height, concave top, posterior wider than anterior).
void expect_meniscus_shape(const std::string& name) {
  SCOPED_TRACE(name);
  const Mesh& m = committed(name);
  const auto box = box_of(m);
  // About 45 mm front to back (x), 27 mm across (y), flat bottom at z = 0, 6-8 mm tall.
  EXPECT_NEAR(box[1][0] - box[0][0], 45.0, 4.5);
  EXPECT_NEAR(box[1][1] - box[0][1], 27.0, 2.7);
  EXPECT_EQ(box[0][2], 0.0);
  EXPECT_GE(box[1][2], 6.0);
  EXPECT_LE(box[1][2], 8.0);
  const auto on_bottom = std::count_if(m.v.begin(), m.v.end(), [](const Vec& p) { return p[2] == 0.0; });
  EXPECT_GT(static_cast<double>(on_bottom), 0.15 * static_cast<double>(m.v.size()));

  // Arc span about the box centre: 360° minus the widest angular gap between vertices, about 300°.
  const double cx = 0.5 * (box[0][0] + box[1][0]), cy = 0.5 * (box[0][1] + box[1][1]);
  std::vector<double> angles;
  for (const Vec& p : m.v) angles.push_back(std::atan2(p[1] - cy, p[0] - cx));
  std::sort(angles.begin(), angles.end());
  double gap = angles.front() + 2.0 * k_pi - angles.back();
  for (std::size_t k = 1; k < angles.size(); ++k) gap = std::max(gap, angles[k] - angles[k - 1]);
  const double span_deg = 360.0 - gap * 180.0 / k_pi;
  EXPECT_NEAR(span_deg, 300.0, 20.0);
  std::printf("%s: box %.2f x %.2f x %.2f mm, arc span %.1f deg\n", name.c_str(), box[1][0] - box[0][0],
              box[1][1] - box[0][1], box[1][2], span_deg);
  // The opening faces +y (lateral): the centre's +y ray hits nothing.
  const VerticalRays rays(m);
  const RadialProfile lateral = radial_profile(rays, cx, cy, 0.5 * k_pi);
  EXPECT_EQ(lateral.peak, 0.0);

  // The wedge along rays through the posterior (-x), medial (-y) and anterior (+x) body.
  std::map<int, double> width;
  for (int deg = 150; deg <= 390; deg += 15) {
    SCOPED_TRACE("ray at " + std::to_string(deg) + " deg");
    const RadialProfile p = radial_profile(rays, cx, cy, deg * k_pi / 180.0);
    ASSERT_GT(p.peak, 0.0);
    width[deg] = p.r_outer - p.r_inner;
    std::printf(
        "  ray %3d deg: width %5.2f mm, peak %4.2f mm at %4.1f mm from the inner edge, thickness %4.2f / %4.2f mm "
        "at 0.5 / 1 mm from the inner edge\n",
        deg, width[deg], p.peak, p.r_peak - p.r_inner, thickness_at(p, p.r_inner + 0.5),
        thickness_at(p, p.r_inner + 1.0));
    if (deg < 165 || deg > 375) continue;  // the horns taper; the body checks below apply between them
    // About 10 mm wide; 6-8 mm tall near the periphery.
    EXPECT_GT(p.r_outer - p.r_inner, 7.0);
    EXPECT_LT(p.r_outer - p.r_inner, 15.0);
    EXPECT_GE(p.peak, 5.5);
    EXPECT_LE(p.peak, 8.0);
    EXPECT_GT(p.r_peak, p.r_outer - 3.0);
    // Rounded inner free edge, about 1 mm thick, never a knife edge.
    EXPECT_GE(thickness_at(p, p.r_inner + 0.5), 0.7);
    EXPECT_GE(thickness_at(p, p.r_inner + 1.0), 0.8);
    EXPECT_LE(thickness_at(p, p.r_inner + 1.0), 2.5);
    // Concave top: between the inner edge and the peak the top lies below the chord.
    const double r1 = p.r_inner + 1.0, r2 = p.r_peak - 1.0, rm = 0.5 * (r1 + r2);
    EXPECT_LT(thickness_at(p, rm), 0.5 * (thickness_at(p, r1) + thickness_at(p, r2)));
  }
  // The posterior part (-x) is wider than the anterior (+x).
  EXPECT_GT(width[180], width[360] + 1.0);
}

TEST(Assets, MeniscusShape10k) { expect_meniscus_shape("meniscus_10k.ply"); }

TEST(Assets, MeniscusShape50k) { expect_meniscus_shape("meniscus_50k.ply"); }

TEST(Assets, MeniscusResolutionsDescribeTheSameBody) {
  // Two samplings of one smooth body: volumes within 1 %.
  const double v10 = volume(committed("meniscus_10k.ply")), v50 = volume(committed("meniscus_50k.ply"));
  EXPECT_NEAR(v10 / v50, 1.0, 0.01);
}

TEST(Assets, CylinderBladesMatchTheirPolygonVolume) {
  // Polygonal cylinder: area n/2 · r² · sin(2π/n) times the height; every rim vertex at radius r.
  const struct {
    const char* file;
    double r, h;
    int n;
  } cases[] = {{"blade_cyl2mm.ply", 1.0, 12.0, 32}, {"blade_cyl20mm.ply", 20.0, 60.0, 64}};
  for (const auto& c : cases) {
    SCOPED_TRACE(c.file);
    const Mesh& m = committed(c.file);
    const double exact = 0.5 * c.n * c.r * c.r * std::sin(2.0 * k_pi / c.n) * c.h;
    EXPECT_NEAR(volume(m) / exact, 1.0, 5e-5);
    const auto box = box_of(m);
    EXPECT_NEAR(box[0][2], -0.5 * c.h, 1e-4);
    EXPECT_NEAR(box[1][2], 0.5 * c.h, 1e-4);
    int rim = 0;
    for (const Vec& p : m.v) {
      const double rad = std::hypot(p[0], p[1]);
      if (rad > 1e-9) {
        EXPECT_NEAR(rad, c.r, 1e-4);
        ++rim;
      }
    }
    EXPECT_EQ(rim, 2 * c.n);
  }
}

TEST(Assets, StarBladeMatchesItsPolygonVolume) {
  // 5-point star, tips at 3 mm and notches at 1.4 mm: area 5 · 3 · 1.4 · sin(π/5), height 12 mm.
  const Mesh& m = committed("blade_star.ply");
  const double exact = 5.0 * 3.0 * 1.4 * std::sin(k_pi / 5.0) * 12.0;
  EXPECT_NEAR(volume(m) / exact, 1.0, 5e-5);
  const auto box = box_of(m);
  EXPECT_NEAR(box[1][0], 3.0, 1e-4);
  EXPECT_NEAR(box[1][2] - box[0][2], 12.0, 1e-4);
}

TEST(Assets, PunchFrameAndShape) {
  const Mesh& m = committed("punch.ply");
  const auto box = box_of(m);
  // Tip at the origin, shaft along +x to 150 mm, Ø 3.5 mm.
  EXPECT_NEAR(box[0][0], 0.0, 0.02);
  EXPECT_NEAR(box[1][0], 150.0, 1e-4);
  double shaft_radius = 0.0, tip_top = -1e9, tip_bottom = 1e9;
  for (const Vec& p : m.v) {
    if (p[0] > 20.0) shaft_radius = std::max(shaft_radius, std::hypot(p[1], p[2]));
    if (p[0] < 3.0) tip_top = std::max(tip_top, p[2]), tip_bottom = std::min(tip_bottom, p[2]);
  }
  EXPECT_NEAR(shaft_radius, 1.75, 1e-3);
  // Two jaws, the upper one opened: near the tip the tool spans from below the axis to above the shaft.
  EXPECT_EQ(components(m), 2);
  EXPECT_LT(tip_bottom, -1.0);
  EXPECT_GT(tip_top, 1.75);
}

TEST(Assets, KneeContextFramesTheMeniscusWithAGap) {
  for (const char* meniscus_file : {"meniscus_10k.ply", "meniscus_50k.ply"}) {
    SCOPED_TRACE(meniscus_file);
    const Mesh& meniscus = committed(meniscus_file);
    const Mesh& femur = committed("femur_condyle.ply");
    const Mesh& tibia = committed("tibia_plateau.ply");
    const auto mb = box_of(meniscus), fb = box_of(femur), tb = box_of(tibia);
    // The condyle sits above the meniscus' base, the plateau under it, both covering its footprint in x.
    EXPECT_GT(fb[0][2], mb[0][2]);
    EXPECT_GT(fb[1][2], mb[1][2] + 10.0);
    EXPECT_LE(tb[1][2], mb[0][2] - 1.0);
    EXPECT_LT(tb[0][0], mb[0][0]);
    EXPECT_GT(tb[1][0], mb[1][0]);
    // At least 1 mm between the surfaces, both ways, and no intersection anywhere in the union.
    if (meniscus.v.size() < 20000) {
      const double mf = min_vertex_distance(meniscus, femur), fm = min_vertex_distance(femur, meniscus);
      const double mt = min_vertex_distance(meniscus, tibia), tm = min_vertex_distance(tibia, meniscus);
      std::printf("gaps: meniscus-condyle %.2f / %.2f mm, meniscus-plateau %.2f / %.2f mm\n", mf, fm, mt, tm);
      EXPECT_GE(mf, 1.0);
      EXPECT_GE(fm, 1.0);
      EXPECT_GE(mt, 1.0);
      EXPECT_GE(tm, 1.0);
    }
    const Mesh all = merged({&meniscus, &femur, &tibia});
    EXPECT_TRUE(self_intersections(all, to_grid(all), 1).empty());
  }
}

}  // namespace
