#pragma once
// Mesh files (SPEC §2.4): import through assimp with welding and validation, export by file extension.
// No assimp types appear here.
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "octocut/sim/surface.hpp"

namespace octocut::engine {

/// A mesh file that cannot be read or fails validation. what() names the file and the first offending element.
class MeshError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Coordinates of a written PLY file: double (the default: a surface read back is the surface written, bit for bit)
/// or single (float32, half the size, for renderers and viewers that want it).
enum class PlyPrecision { double_, single };

/// How a mesh file is loaded.
struct MeshLoadOptions {
  double scale = 1.0;             ///< multiplies file coordinates to get metres
  bool validate = true;           ///< run validate_mesh (closed, manifold, oriented, finite, non-degenerate, ...)
  bool self_intersections = true; ///< also reject self-intersecting meshes (CGAL; costs time on big meshes)
};

/// A loaded mesh and what the loader had to say about it.
struct LoadedMesh {
  sim::TriMesh mesh;                  ///< welded, scaled to metres, outward oriented
  std::vector<std::string> warnings;  ///< for example "reoriented a consistently inverted mesh"
};

/// Loads OBJ, PLY (ASCII and binary), STL (ASCII and binary), OFF, glTF and GLB. Throws MeshError. PLY is read by
/// octocut's own reader in double precision (a double PLY reads back bit for bit); the other formats through assimp,
/// whose coordinates are 32-bit floats.
LoadedMesh load_mesh(const std::filesystem::path& path, const MeshLoadOptions& options = {});

/// Writes a mesh by extension: .ply (binary little-endian, `ply` precision), .obj and .off (shortest round-trip
/// decimals), .stl (binary, float32 by the format), .gltf, .glb. The write is atomic. Throws MeshError for an unknown
/// extension or a write failure.
void save_mesh(const std::filesystem::path& path, const sim::TriMesh& mesh,
               PlyPrecision ply = PlyPrecision::double_);

/// Validates `mesh` as a solid's surface (SPEC §2.4) and returns its warnings. Checks, in this order: vertex indices in
/// range, finite coordinates, no degenerate triangle (a repeated vertex index, or twice the area at most 1e-12 times
/// the squared bounding-box diagonal), closed (no edge used by one triangle only), edge-manifold (no edge used by more
/// than two), vertex-manifold (the triangles around each vertex form one fan), consistent orientation (each edge used
/// once in each direction), non-zero volume (|V| above 1e-12 times the cubed diagonal), and, when
/// `self_intersections`, no two triangles intersecting other than through shared vertices or edges. A mesh with
/// negative signed volume is turned inside out in place (every triangle flipped) with the warning
/// "<file>: reoriented a consistently inverted mesh ...". Throws MeshError, whose message starts with `file` and names
/// the first offending vertex, triangle or edge.
std::vector<std::string> validate_mesh(sim::TriMesh& mesh, const std::string& file, bool self_intersections);

/// The bytes of a binary little-endian PLY file (x y z as float64 or float32, uchar/int32 vertex_indices).
/// Deterministic: the same mesh always gives the same bytes, with no timestamps or tool versions in the header.
std::string encode_ply_binary(const sim::TriMesh& mesh, PlyPrecision precision = PlyPrecision::double_);

}  // namespace octocut::engine
