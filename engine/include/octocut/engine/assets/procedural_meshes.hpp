#pragma once
// Procedural meshes shipped in assets/meshes/ (SPEC §9, `octocut assets` in SPEC §7): the medial meniscus, the
// arthroscopic punch, the blades and the render-only knee context. Every mesh is a closed, edge-manifold, outward
// oriented triangle mesh in MILLIMETRES (scenes load them with "scale": 0.001). Every vertex coordinate is snapped to
// a multiple of 2^-16 mm, so that the float32 values in the PLY files are exact and the files are bit-identical on
// every run.
//
// Meniscus frame (the knee context shares it): z = 0 is the flat bottom of the meniscus, +z superior (up); +x
// anterior, -x posterior; -y medial (the convex periphery of the C), +y lateral (the C opens towards +y, the
// intercondylar side). This is the medial meniscus of a left knee. The origin is the centre of the elliptical inner
// rim curve.
#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "octocut/sim/surface.hpp"

namespace octocut::engine {

/// Spacing of the coordinate grid that every generated vertex is snapped to, mm (2^-16 mm).
inline constexpr double k_asset_grid_mm = 1.0 / 65536.0;

/// The medial meniscus with about `target_vertices` vertices (within one profile ring: 10022 for 10000, 50050 for
/// 50000). A closed wedge-shaped profile (a cubic B-spline outline: flat bottom at z = 0, near-vertical periphery,
/// concave top, rounded inner free edge) is swept along the elliptical inner rim curve (the spine, semi-axes 12.75 ×
/// 6 mm) over 284° of ellipse angle, tapered at both horns and closed by rounded caps. The profile
/// lies on the outward side of the spine in the spine's normal plane; because the outward normal rays of a strictly
/// convex curve never meet, the swept body cannot intersect itself (the caps extend straight along the end tangents
/// into the opening). Measured (tests/engine/assets/assets_test.cpp): 45.0 × 26.5 × 7.1 mm, arc span about 300° around the box
/// centre, wedge 8-12 mm wide (posterior wider than anterior), 6.0-6.9 mm tall at the periphery of the body, 1.0-1.3
/// mm thick 0.5 mm from the inner edge, about 2510 mm³. Throws std::invalid_argument for target_vertices < 1000.
sim::TriMesh make_meniscus(int target_vertices);

/// sim::cylinder_mesh (radius `radius_mm`, height `height_mm`, about the z axis, centred at the origin, flat caps
/// fanned around a centre vertex, 2·segments + 2 vertices) snapped to the asset grid. Throws std::invalid_argument for a non-positive size or fewer than 3 segments.
sim::TriMesh make_cylinder(double radius_mm, double height_mm, int segments);

/// A star prism around the z axis centred at the origin: `points` tips at `outer_radius_mm` (the first on +x)
/// alternating with notches at `inner_radius_mm`, extruded over `height_mm` (z from -h/2 to h/2), flat caps fanned
/// around a centre vertex. Cross-section area: points · outer · inner · sin(π / points). Throws
/// std::invalid_argument for points < 3, a non-positive size or inner ≥ outer.
sim::TriMesh make_star_prism(int points, double outer_radius_mm, double inner_radius_mm, double height_mm);

/// The arthroscopic duckbill punch, render-only. Tool frame: the tip (between the closed jaw tips) at the origin, the
/// shaft (Ø 3.5 mm) along +x up to x = 150 mm, the jaws open towards +z. Two closed components that do not touch: the
/// shaft with the fixed lower jaw (flat top at z = -0.15 mm), and the upper jaw (flat bottom at z = +0.15 mm before
/// it is opened by 14° about its hinge at x = 9.5 mm).
sim::TriMesh make_punch();

/// The distal femoral medial condyle, render-only, in the meniscus frame: a smooth egg-shaped body (a lower
/// half-ellipsoid of semi-axes 22 × 14 × 18 mm under an upper one 30 mm tall) above the meniscus, lowered into the
/// meniscus' concave top until it keeps a clearance of about 2.5 mm to every meniscus vertex (measured: 2.49 mm).
/// `meniscus` is the mesh it is placed against (make_meniscus output).
sim::TriMesh make_femoral_condyle(const sim::TriMesh& meniscus);

/// The medial tibial plateau, render-only, in the meniscus frame: a rounded block (superellipsoid, exponent 4,
/// 64 × 50 × 12 mm) under the meniscus, its top at z = -1.5 mm.
sim::TriMesh make_tibial_plateau(const sim::TriMesh& meniscus);

/// What write_assets wrote for one file.
struct AssetInfo {
  std::string file;           ///< file name inside the output directory
  std::size_t vertices = 0;   ///< number of vertices
  std::size_t triangles = 0;  ///< number of triangles
  double volume_mm3 = 0.0;    ///< enclosed volume, mm^3
};

/// Generates every procedural mesh and writes it as binary PLY (engine::encode_ply_binary, written atomically) into
/// `dir`, which is created when missing: meniscus_10k.ply, meniscus_50k.ply, punch.ply, blade_cyl2mm.ply,
/// blade_star.ply, blade_cyl20mm.ply, femur_condyle.ply, tibia_plateau.ply. Deterministic: the same bytes every run.
/// Throws std::runtime_error naming the file when a write fails.
std::vector<AssetInfo> write_assets(const std::filesystem::path& dir);

}  // namespace octocut::engine
