// Procedural meshes for assets/meshes/ (SPEC §9). See assets.hpp for the frames and conventions. Every generator is
// a pure function of its arguments (no randomness, fixed iteration orders), so the written files are bit-identical
// from run to run.
#include "octocut/engine/assets/procedural_meshes.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <numbers>
#include <stdexcept>
#include <utility>

#include "octocut/engine/io/io.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/sim/primitives.hpp"

namespace octocut::engine {
namespace {

using sim::TriMesh;
using sim::Vec3;

constexpr double k_pi = std::numbers::pi;

/// One closed ring of a loft: the same number of points in every ring (|ring|).
using Ring = std::vector<Vec3>;

/// Hermite smoothstep on [0, 1], clamped outside.
double smoothstep(double x) {
  const double c = std::clamp(x, 0.0, 1.0);
  return c * c * (3.0 - 2.0 * c);
}

/// Snaps every coordinate to the 2^-16 mm grid (exact in float32 for |x| < 256 mm) and turns -0 into +0.
void snap_to_grid(TriMesh& mesh) {
  for (Vec3& p : mesh.vertices) {
    for (int k = 0; k < 3; ++k) {
      const double q = std::round(p[k] / k_asset_grid_mm) * k_asset_grid_mm;
      p[k] = q == 0.0 ? 0.0 : q;
    }
  }
}

/// Reverses every triangle when the enclosed volume is negative, so that normals point out.
void orient_outward(TriMesh& mesh) {
  if (sim::signed_volume(mesh) >= 0.0) return;
  for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
}

/// Appends `part` to `mesh` (a union of disjoint closed components).
void append(TriMesh& mesh, const TriMesh& part) {
  const auto offset = static_cast<int32_t>(mesh.vertices.size());
  mesh.vertices.insert(mesh.vertices.end(), part.vertices.begin(), part.vertices.end());
  for (const auto& t : part.triangles) mesh.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
}

/// A closed tube through `rings` (each of the same size, at least 3), closed by a fan around `start_pole` before the
/// first ring and around `end_pole` after the last. Oriented outward.
TriMesh loft(const std::vector<Ring>& rings, const Vec3& start_pole, const Vec3& end_pole) {
  TriMesh mesh;
  const auto m = static_cast<int32_t>(rings.front().size());
  const auto r = static_cast<int32_t>(rings.size());
  // Vertices: the start pole, every ring in order, the end pole.
  mesh.vertices.push_back(start_pole);
  for (const Ring& ring : rings) mesh.vertices.insert(mesh.vertices.end(), ring.begin(), ring.end());
  mesh.vertices.push_back(end_pole);
  const auto at = [m](int32_t ring, int32_t k) { return 1 + ring * m + (k % m); };
  const int32_t end = 1 + r * m;
  // Fan at the start pole, quad strips between consecutive rings, fan at the end pole (one consistent winding).
  for (int32_t k = 0; k < m; ++k) mesh.triangles.push_back({0, at(0, k + 1), at(0, k)});
  for (int32_t j = 0; j + 1 < r; ++j) {
    for (int32_t k = 0; k < m; ++k) {
      mesh.triangles.push_back({at(j, k), at(j, k + 1), at(j + 1, k + 1)});
      mesh.triangles.push_back({at(j, k), at(j + 1, k + 1), at(j + 1, k)});
    }
  }
  for (int32_t k = 0; k < m; ++k) mesh.triangles.push_back({end, at(r - 1, k), at(r - 1, k + 1)});
  orient_outward(mesh);
  return mesh;
}

// ---- meniscus ------------------------------------------------------------------------------------------------------

constexpr double k_rim_a = 12.75;                         ///< inner rim ellipse semi-axis along x, mm
constexpr double k_rim_b = 6.0;                           ///< inner rim ellipse semi-axis along y, mm
constexpr double k_gap = 76.0 * k_pi / 180.0;             ///< angular opening of the C (in the ellipse angle), rad
constexpr double k_psi_start = 0.5 * k_pi + 0.5 * k_gap;  ///< posterior horn end (x < 0, y > 0)
constexpr double k_psi_end = 2.5 * k_pi - 0.5 * k_gap;    ///< anterior horn end (x > 0, y > 0)
constexpr double k_inner_thickness = 1.2;                 ///< control thickness of the inner free edge, mm
constexpr double k_top_exponent = 1.5;                    ///< top height grows like (u / W)^p: a concave (bowl) top
constexpr double k_horn_fraction = 0.15;                  ///< spine fraction over which each horn tapers

/// Point of the inner rim ellipse, mm.
Vec3 rim_point(double psi) { return {k_rim_a * std::cos(psi), k_rim_b * std::sin(psi), 0.0}; }

/// Unit tangent of the rim ellipse in the direction of increasing angle.
Vec3 rim_tangent(double psi) { return Vec3(-k_rim_a * std::sin(psi), k_rim_b * std::cos(psi), 0.0).normalized(); }

/// Unit outward normal of the rim ellipse (in the xy plane).
Vec3 rim_normal(double psi) { return Vec3(k_rim_b * std::cos(psi), k_rim_a * std::sin(psi), 0.0).normalized(); }

/// Radial width W of the wedge before the horn taper, mm: 11.5 posterior (x < 0), 8 anterior, 9.75 medial.
double body_width(double psi) { return 9.75 - 1.75 * std::cos(psi); }

/// Peripheral height H of the wedge before the horn taper, mm: 7.75 posterior, 6.75 anterior (the spline rounding
/// lowers the measured peak by about 0.6 mm).
double body_height(double psi) { return 7.25 - 0.5 * std::cos(psi); }

/// Horn taper factor in [0, 1]: 0 at a horn end, 1 on the body.
double horn_blend(double s) { return smoothstep(std::min(s, 1.0 - s) / k_horn_fraction); }

/// Point of a closed uniform cubic B-spline with control points `p` (cyclic): segment `i`, local parameter t ∈ [0, 1].
std::array<double, 2> bspline(const std::vector<std::array<double, 2>>& p, int i, double t) {
  const int n = static_cast<int>(p.size());
  const double w0 = (1.0 - t) * (1.0 - t) * (1.0 - t) / 6.0;
  const double w1 = (3.0 * t * t * t - 6.0 * t * t + 4.0) / 6.0;
  const double w2 = (-3.0 * t * t * t + 3.0 * t * t + 3.0 * t + 1.0) / 6.0;
  const double w3 = t * t * t / 6.0;
  std::array<double, 2> out{0.0, 0.0};
  const double w[4] = {w0, w1, w2, w3};
  for (int k = 0; k < 4; ++k) {
    const auto& c = p[static_cast<std::size_t>(((i - 1 + k) % n + n) % n)];
    out[0] += w[k] * c[0];
    out[1] += w[k] * c[1];
  }
  return out;
}

/// The closed wedge cross-section in profile coordinates (u outward from the inner rim, mm; z up, mm), as `count`
/// points at equal arc length, counter-clockwise, starting at the inner free edge. W: radial width, H: peripheral
/// height. The outline is a cubic B-spline of a control polygon with a flat bottom (z = 0 exactly: the bottom
/// control points all have z = 0), a vertical periphery, a concave top z = t + (H - t)(u / W)^p and a blunt inner
/// end of thickness t, which the spline rounds. All points have u > 0.
std::vector<std::array<double, 2>> wedge_profile(double width, double height, int count) {
  // Control polygon, counter-clockwise: inner top corner, inner bottom corner, bottom, periphery, top.
  std::vector<std::array<double, 2>> ctrl;
  ctrl.push_back({0.0, k_inner_thickness});
  ctrl.push_back({0.0, 0.0});
  for (int i = 1; i <= 5; ++i) ctrl.push_back({width * i / 6.0, 0.0});
  ctrl.push_back({width, 0.0});
  ctrl.push_back({width, 0.5 * height});
  ctrl.push_back({width, height});
  for (int k = 1; k <= 7; ++k) {
    const double u = width * (1.0 - k / 8.0);
    ctrl.push_back({u, k_inner_thickness + (height - k_inner_thickness) * std::pow(u / width, k_top_exponent)});
  }
  const int n = static_cast<int>(ctrl.size());
  // Dense polyline from the middle of the inner-edge segment (segment 0, t = 0.5) once around.
  constexpr int k_samples = 64;
  std::vector<std::array<double, 2>> dense;
  dense.reserve(static_cast<std::size_t>(n * k_samples + 1));
  for (int k = 0; k <= n * k_samples; ++k) {
    const double tau = 0.5 + static_cast<double>(k) / k_samples;
    const int seg = static_cast<int>(std::floor(tau));
    dense.push_back(bspline(ctrl, seg % n, tau - seg));
  }
  // Cumulative arc length of the polyline.
  std::vector<double> length(dense.size(), 0.0);
  for (std::size_t k = 1; k < dense.size(); ++k) {
    length[k] = length[k - 1] + std::hypot(dense[k][0] - dense[k - 1][0], dense[k][1] - dense[k - 1][1]);
  }
  // Resample at equal arc length (linear interpolation keeps flat-bottom points exactly at z = 0).
  std::vector<std::array<double, 2>> out;
  out.reserve(static_cast<std::size_t>(count));
  std::size_t seg = 1;
  for (int m = 0; m < count; ++m) {
    const double target = length.back() * m / count;
    while (seg + 1 < length.size() && length[seg] < target) ++seg;
    const double span = length[seg] - length[seg - 1];
    const double f = span > 0.0 ? (target - length[seg - 1]) / span : 0.0;
    const auto& a = dense[seg - 1];
    const auto& b = dense[seg];
    out.push_back({a[0] + f * (b[0] - a[0]), a[1] == 0.0 && b[1] == 0.0 ? 0.0 : a[1] + f * (b[1] - a[1])});
  }
  return out;
}

/// Perimeter of a closed polygon in the plane, mm.
double perimeter(const std::vector<std::array<double, 2>>& pts) {
  double sum = 0.0;
  for (std::size_t k = 0; k < pts.size(); ++k) {
    const auto& a = pts[k];
    const auto& b = pts[(k + 1) % pts.size()];
    sum += std::hypot(b[0] - a[0], b[1] - a[1]);
  }
  return sum;
}

/// Maps a spine parameter s ∈ [0, 1] (arc length of the mid-wedge curve, normalised) to the ellipse angle.
class SpineParam {
 public:
  SpineParam() {
    // Tabulate the arc length of the curve through the middle of the wedge, rim + W/2 · normal.
    constexpr int k_steps = 8192;
    m_psi.resize(k_steps + 1);
    m_length.resize(k_steps + 1);
    Vec3 prev = mid_point(k_psi_start);
    for (int k = 0; k <= k_steps; ++k) {
      const double psi = k_psi_start + (k_psi_end - k_psi_start) * k / k_steps;
      const Vec3 p = mid_point(psi);
      m_psi[static_cast<std::size_t>(k)] = psi;
      m_length[static_cast<std::size_t>(k)] =
          k == 0 ? 0.0 : m_length[static_cast<std::size_t>(k - 1)] + (p - prev).norm();
      prev = p;
    }
  }

  /// Total length of the mid-wedge curve, mm.
  [[nodiscard]] double length() const { return m_length.back(); }

  /// Ellipse angle at normalised arc length s.
  [[nodiscard]] double psi(double s) const {
    const double target = std::clamp(s, 0.0, 1.0) * m_length.back();
    const auto it = std::lower_bound(m_length.begin(), m_length.end(), target);
    if (it == m_length.begin()) return m_psi.front();
    if (it == m_length.end()) return m_psi.back();
    const auto k = static_cast<std::size_t>(it - m_length.begin());
    const double span = m_length[k] - m_length[k - 1];
    const double f = span > 0.0 ? (target - m_length[k - 1]) / span : 0.0;
    return m_psi[k - 1] + f * (m_psi[k] - m_psi[k - 1]);
  }

 private:
  static Vec3 mid_point(double psi) { return rim_point(psi) + 0.5 * body_width(psi) * rim_normal(psi); }

  std::vector<double> m_psi;     ///< ellipse angles, rad (steps + 1)
  std::vector<double> m_length;  ///< arc length up to each angle, mm (steps + 1)
};

/// The wedge dimensions at spine parameter s: {W, H}, mm.
std::array<double, 2> wedge_size(double s, double psi) {
  const double blend = horn_blend(s);
  return {body_width(psi) * (0.55 + 0.45 * blend), body_height(psi) * (0.6 + 0.4 * blend)};
}

/// Rings of a rounded cap beyond a horn end: the end profile shrinks towards its area centroid (u_c, z_c) while
/// advancing along `dir`, like a half ellipsoid of length L = W / 2, and closes in a pole at the centroid. Returns
/// the rings (nearest the body first) and the pole.
std::pair<std::vector<Ring>, Vec3> horn_cap(const Vec3& rim, const Vec3& normal, const Vec3& dir, double width,
                                            const std::vector<std::array<double, 2>>& profile, int cap_rings) {
  // Area centroid of the profile polygon (shoelace).
  double area2 = 0.0, cu = 0.0, cz = 0.0;
  for (std::size_t k = 0; k < profile.size(); ++k) {
    const auto& a = profile[k];
    const auto& b = profile[(k + 1) % profile.size()];
    const double w = a[0] * b[1] - b[0] * a[1];
    area2 += w;
    cu += (a[0] + b[0]) * w;
    cz += (a[1] + b[1]) * w;
  }
  const double u_c = cu / (3.0 * area2), z_c = cz / (3.0 * area2);
  const double cap_length = 0.5 * width;
  // Rings at equal angles of the quarter ellipse (scale cos θ, advance L sin θ).
  std::vector<Ring> rings;
  for (int k = 1; k < cap_rings; ++k) {
    const double theta = 0.5 * k_pi * k / cap_rings;
    const double sigma = std::cos(theta);
    const Vec3 origin = rim + cap_length * std::sin(theta) * dir;
    Ring ring;
    ring.reserve(profile.size());
    for (const auto& q : profile) {
      ring.push_back(origin + (u_c + sigma * (q[0] - u_c)) * normal + Vec3(0, 0, z_c + sigma * (q[1] - z_c)));
    }
    rings.push_back(std::move(ring));
  }
  return {rings, rim + cap_length * dir + u_c * normal + Vec3(0, 0, z_c)};
}

// ---- star-shaped bodies (cube sphere) ------------------------------------------------------------------------------

/// A closed star-shaped body: the surface of a cube with `n` × `n` quads per face, its points pushed along their
/// directions d from `center` to the distance radius(d). The cube grid is warped by tan for even spacing. Because
/// every triangle stays inside the cone of its own three directions and those cones tile space, the result cannot
/// intersect itself for any positive radius function.
TriMesh radial_body(int n, const Vec3& center, const std::function<double(const Vec3&)>& radius) {
  TriMesh mesh;
  const int side = n + 1;
  std::vector<int32_t> index(static_cast<std::size_t>(side * side * side), -1);
  const auto lattice = [side](int i, int j, int k) { return static_cast<std::size_t>((i * side + j) * side + k); };
  const auto warp = [n](int i) { return std::tan(0.25 * k_pi * (2.0 * i / n - 1.0)); };
  // Vertices: every lattice point on the cube surface, in lattice order.
  for (int i = 0; i <= n; ++i) {
    for (int j = 0; j <= n; ++j) {
      for (int k = 0; k <= n; ++k) {
        if (i != 0 && i != n && j != 0 && j != n && k != 0 && k != n) continue;
        const Vec3 d = Vec3(warp(i), warp(j), warp(k)).normalized();
        index[lattice(i, j, k)] = static_cast<int32_t>(mesh.vertices.size());
        mesh.vertices.push_back(center + radius(d) * d);
      }
    }
  }
  // Faces: for each axis a and each side, the grid quads in the two other axes (b, c) = (a+1, a+2), counter-clockwise
  // about +a, reversed on the low side.
  for (int a = 0; a < 3; ++a) {
    for (int face_side : {0, n}) {
      const auto id = [&](int u, int v) {
        std::array<int, 3> c{};
        c[static_cast<std::size_t>(a)] = face_side;
        c[static_cast<std::size_t>((a + 1) % 3)] = u;
        c[static_cast<std::size_t>((a + 2) % 3)] = v;
        return index[lattice(c[0], c[1], c[2])];
      };
      for (int u = 0; u < n; ++u) {
        for (int v = 0; v < n; ++v) {
          const int32_t p00 = id(u, v), p10 = id(u + 1, v), p11 = id(u + 1, v + 1), p01 = id(u, v + 1);
          if (face_side == n) {
            mesh.triangles.push_back({p00, p10, p11});
            mesh.triangles.push_back({p00, p11, p01});
          } else {
            mesh.triangles.push_back({p00, p11, p10});
            mesh.triangles.push_back({p00, p01, p11});
          }
        }
      }
    }
  }
  orient_outward(mesh);
  return mesh;
}

}  // namespace

sim::TriMesh make_meniscus(int target_vertices) {
  if (target_vertices < 1000) throw std::invalid_argument("make_meniscus: target_vertices must be at least 1000");
  const SpineParam spine;
  // Sampling: equal spacing h along the spine and around the profile, V ≈ (spine length / h)(profile perimeter / h).
  const double mid_perimeter = perimeter(wedge_profile(body_width(1.5 * k_pi), body_height(1.5 * k_pi), 256));
  const double h = std::sqrt(spine.length() * mid_perimeter / target_vertices);
  const int m = std::max(16, 4 * static_cast<int>(std::lround(mid_perimeter / h / 4.0)));
  const int cap_rings = std::max(6, m / 8);
  const int main_rings =
      static_cast<int>(std::lround(static_cast<double>(target_vertices - 2) / m)) - 2 * (cap_rings - 1);
  if (main_rings < 8) throw std::invalid_argument("make_meniscus: target_vertices too small for the profile");

  // Main rings: the wedge profile placed in the normal plane of the rim at each spine station.
  std::vector<Ring> body;
  body.reserve(static_cast<std::size_t>(main_rings));
  std::vector<std::array<double, 2>> first_profile, last_profile;
  for (int j = 0; j < main_rings; ++j) {
    const double s = static_cast<double>(j) / (main_rings - 1);
    const double psi = spine.psi(s);
    const auto [width, height] = wedge_size(s, psi);
    const auto profile = wedge_profile(width, height, m);
    const Vec3 c = rim_point(psi);
    const Vec3 nrm = rim_normal(psi);
    Ring ring;
    ring.reserve(static_cast<std::size_t>(m));
    for (const auto& q : profile) ring.push_back(c + q[0] * nrm + Vec3(0, 0, q[1]));
    body.push_back(std::move(ring));
    if (j == 0) first_profile = profile;
    if (j == main_rings - 1) last_profile = profile;
  }

  // Rounded caps at the posterior (s = 0) and anterior (s = 1) horns, continuing along the end tangents.
  const double psi0 = spine.psi(0.0), psi1 = spine.psi(1.0);
  const auto [cap0, pole0] = horn_cap(rim_point(psi0), rim_normal(psi0), -rim_tangent(psi0), wedge_size(0.0, psi0)[0],
                                      first_profile, cap_rings);
  const auto [cap1, pole1] =
      horn_cap(rim_point(psi1), rim_normal(psi1), rim_tangent(psi1), wedge_size(1.0, psi1)[0], last_profile, cap_rings);
  std::vector<Ring> rings(cap0.rbegin(), cap0.rend());
  rings.insert(rings.end(), body.begin(), body.end());
  rings.insert(rings.end(), cap1.begin(), cap1.end());

  TriMesh mesh = loft(rings, pole0, pole1);
  snap_to_grid(mesh);
  return mesh;
}

sim::TriMesh make_cylinder(double radius_mm, double height_mm, int segments) {
  if (!(radius_mm > 0.0) || !(height_mm > 0.0) || segments < 3) {
    throw std::invalid_argument("make_cylinder: radius and height must be positive and segments at least 3");
  }
  TriMesh mesh = sim::cylinder_mesh(radius_mm, height_mm, segments);
  snap_to_grid(mesh);
  return mesh;
}

sim::TriMesh make_star_prism(int points, double outer_radius_mm, double inner_radius_mm, double height_mm) {
  if (points < 3 || !(inner_radius_mm > 0.0) || !(outer_radius_mm > inner_radius_mm) || !(height_mm > 0.0)) {
    throw std::invalid_argument("make_star_prism: need points >= 3 and 0 < inner radius < outer radius, height > 0");
  }
  // Two star rings (tips and notches alternating) closed by flat fans around the axis.
  std::vector<Ring> rings(2);
  for (int r = 0; r < 2; ++r) {
    const double z = r == 0 ? -0.5 * height_mm : 0.5 * height_mm;
    for (int k = 0; k < 2 * points; ++k) {
      const double phi = k_pi * k / points;
      const double rad = k % 2 == 0 ? outer_radius_mm : inner_radius_mm;
      rings[static_cast<std::size_t>(r)].push_back(Vec3(rad * std::cos(phi), rad * std::sin(phi), z));
    }
  }
  TriMesh mesh = loft(rings, Vec3(0, 0, -0.5 * height_mm), Vec3(0, 0, 0.5 * height_mm));
  snap_to_grid(mesh);
  return mesh;
}

sim::TriMesh make_punch() {
  constexpr int k_segments = 32;                  // points around each ring
  constexpr int k_nose_rings = 6;                 // rings of each rounded end
  constexpr double k_radius = 1.75;               // shaft radius, mm
  constexpr double k_jaw_radius = 1.6;            // jaw half-ellipse height, mm
  constexpr double k_half_gap = 0.15;             // half the gap between the closed jaws, mm
  constexpr double k_nose = 1.5;                  // length of the rounded jaw nose, mm
  constexpr double k_jaw_end = 10.5;              // the lower jaw turns into the shaft from here, mm
  constexpr double k_shaft_start = 12.5;          // full round shaft from here, mm
  constexpr double k_shaft_end = 150.0;           // proximal end of the shaft, mm
  constexpr double k_hinge = 9.5;                 // proximal end of the upper jaw and its hinge, mm
  constexpr double k_open = 14.0 * k_pi / 180.0;  // opening angle of the upper jaw, rad

  // Cross-section ring at x: a half ellipse of height `low` under z_c and one of height `up` above, width 2·r_y,
  // all scaled by sigma about (0, z_c).
  const auto section = [](double x, double z_c, double low, double up, double sigma) {
    Ring ring;
    for (int k = 0; k < k_segments; ++k) {
      const double phi = 2.0 * k_pi * k / k_segments;
      const double s = std::sin(phi);
      ring.push_back(Vec3(x, sigma * k_radius * std::cos(phi), z_c + sigma * (s >= 0.0 ? up * s : low * s)));
    }
    return ring;
  };

  // Shaft with the fixed lower jaw: rounded nose, flat-topped jaw, blend into the round shaft, flat proximal end.
  std::vector<Ring> lower;
  for (int k = 1; k <= k_nose_rings; ++k) {
    const double theta = 0.5 * k_pi * k / k_nose_rings;
    lower.push_back(section(k_nose * (1.0 - std::cos(theta)), -k_half_gap, k_jaw_radius, 0.0, std::sin(theta)));
  }
  for (int k = 1; k <= 12; ++k) {
    lower.push_back(section(k_nose + (k_jaw_end - k_nose) * k / 12.0, -k_half_gap, k_jaw_radius, 0.0, 1.0));
  }
  for (int k = 1; k <= 8; ++k) {
    const double x = k_jaw_end + (k_shaft_start - k_jaw_end) * k / 8.0;
    const double b = smoothstep(static_cast<double>(k) / 8.0);
    lower.push_back(
        section(x, -k_half_gap * (1.0 - b), k_jaw_radius + (k_radius - k_jaw_radius) * b, k_radius * b, 1.0));
  }
  for (const double x : {15.0, 20.0, 30.0, 45.0, 60.0, 75.0, 90.0, 105.0, 120.0, 135.0, k_shaft_end}) {
    lower.push_back(section(x, 0.0, k_radius, k_radius, 1.0));
  }
  TriMesh mesh = loft(lower, Vec3(0, 0, -k_half_gap), Vec3(k_shaft_end, 0, 0));

  // Upper jaw: flat bottom at +gap/2, half-ellipse top, rounded at both ends.
  std::vector<Ring> upper;
  constexpr double k_heel = 1.0;  // length of the rounded proximal end, mm
  for (int k = 1; k <= k_nose_rings; ++k) {
    const double theta = 0.5 * k_pi * k / k_nose_rings;
    upper.push_back(section(k_nose * (1.0 - std::cos(theta)), k_half_gap, 0.0, k_jaw_radius, std::sin(theta)));
  }
  for (int k = 1; k < 10; ++k) {
    upper.push_back(section(k_nose + (k_hinge - k_heel - k_nose) * k / 10.0, k_half_gap, 0.0, k_jaw_radius, 1.0));
  }
  for (int k = 0; k < k_nose_rings; ++k) {
    const double theta = 0.5 * k_pi * k / k_nose_rings;
    upper.push_back(
        section(k_hinge - k_heel + k_heel * std::sin(theta), k_half_gap, 0.0, k_jaw_radius, std::cos(theta)));
  }
  TriMesh jaw = loft(upper, Vec3(0, 0, k_half_gap), Vec3(k_hinge, 0, k_half_gap));

  // Open the upper jaw: rotate about the hinge axis (parallel to y through (k_hinge, ·, gap/2)) so the tip rises.
  for (Vec3& p : jaw.vertices) {
    const double dx = p.x() - k_hinge, dz = p.z() - k_half_gap;
    p = Vec3(k_hinge + dx * std::cos(k_open) + dz * std::sin(k_open), p.y(),
             k_half_gap - dx * std::sin(k_open) + dz * std::cos(k_open));
  }
  append(mesh, jaw);
  snap_to_grid(mesh);
  return mesh;
}

sim::TriMesh make_femoral_condyle(const sim::TriMesh& meniscus) {
  constexpr double k_a = 22.0, k_b = 14.0, k_c_low = 18.0, k_c_up = 30.0;  // semi-axes, mm
  constexpr double k_clearance = 2.5;  // inflation of the semi-axes used for placement, mm
  const double cx = 0.0, cy = -1.0;
  // Is every meniscus vertex outside the inflated body centred at height z0?
  const auto clear = [&](double z0) {
    for (const Vec3& p : meniscus.vertices) {
      const double dz = p.z() - z0;
      const double c = (dz < 0.0 ? k_c_low : k_c_up) + k_clearance;
      const double f = std::pow((p.x() - cx) / (k_a + k_clearance), 2) +
                       std::pow((p.y() - cy) / (k_b + k_clearance), 2) + std::pow(dz / c, 2);
      if (f < 1.0) return false;
    }
    return true;
  };
  // Lower it by bisection until it (nearly) touches the inflated clearance; never below 0.5 mm above z = 0.
  double lo = k_c_low + 0.5, hi = k_c_low + 60.0;
  if (!clear(lo)) {
    for (int it = 0; it < 60; ++it) {
      const double mid = 0.5 * (lo + hi);
      (clear(mid) ? hi : lo) = mid;
    }
    lo = hi;
  }
  const double z0 = lo;
  TriMesh mesh = radial_body(24, Vec3(cx, cy, z0), [&](const Vec3& d) {
    const double c = d.z() < 0.0 ? k_c_low : k_c_up;
    return 1.0 / std::sqrt(std::pow(d.x() / k_a, 2) + std::pow(d.y() / k_b, 2) + std::pow(d.z() / c, 2));
  });
  snap_to_grid(mesh);
  return mesh;
}

sim::TriMesh make_tibial_plateau(const sim::TriMesh& meniscus) {
  constexpr double k_half[3] = {32.0, 25.0, 6.0};  // half extents, mm
  constexpr double k_top = -1.5;                   // top of the plateau, mm
  const sim::Box3 box = sim::bounds(meniscus);
  const Vec3 center(0.5 * (box.min.x() + box.max.x()), 0.5 * (box.min.y() + box.max.y()), k_top - k_half[2]);
  TriMesh mesh = radial_body(24, center, [&](const Vec3& d) {
    double sum = 0.0;
    for (int k = 0; k < 3; ++k) sum += std::pow(std::abs(d[k]) / k_half[k], 4.0);
    return std::pow(sum, -0.25);
  });
  snap_to_grid(mesh);
  return mesh;
}

std::vector<AssetInfo> write_assets(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw std::runtime_error(dir.string() + ": cannot create directory: " + ec.message());
  // Generate in dependency order: the knee context is placed against the 10k meniscus.
  const TriMesh meniscus = make_meniscus(10000);
  std::vector<std::pair<std::string, TriMesh>> meshes;
  meshes.emplace_back("meniscus_10k.ply", meniscus);
  meshes.emplace_back("meniscus_50k.ply", make_meniscus(50000));
  meshes.emplace_back("punch.ply", make_punch());
  meshes.emplace_back("blade_cyl2mm.ply", make_cylinder(1.0, 12.0, 32));
  meshes.emplace_back("blade_star.ply", make_star_prism(5, 3.0, 1.4, 12.0));
  meshes.emplace_back("blade_cyl20mm.ply", make_cylinder(20.0, 60.0, 64));
  meshes.emplace_back("femur_condyle.ply", make_femoral_condyle(meniscus));
  meshes.emplace_back("tibia_plateau.ply", make_tibial_plateau(meniscus));
  // Encode and write each file atomically, in float32: the committed assets were made so, and every shipped scene's
  // material graph cache and expected block depends on their exact bytes.
  std::vector<AssetInfo> infos;
  for (const auto& [name, mesh] : meshes) {
    engine::write_file_atomic(dir / name, engine::encode_ply_binary(mesh, engine::PlyPrecision::single));
    infos.push_back({name, mesh.num_vertices(), mesh.num_triangles(), sim::signed_volume(mesh)});
  }
  return infos;
}

}  // namespace octocut::engine
