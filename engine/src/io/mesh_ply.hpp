#pragma once
// octocut's own PLY reader (ASCII, binary little- and big-endian; any scalar type), so that a double-precision PLY
// reads back bit for bit (assimp stores coordinates as 32-bit floats). Private to the io folder.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "octocut/sim/types.hpp"

namespace octocut::engine {

/// What a PLY file holds: the vertex positions (x, y, z as written, in double) and its faces fan-triangulated
/// (indices checked against the vertex count).
struct PlyContents {
  std::vector<sim::Vec3> positions;
  std::vector<std::array<int64_t, 3>> triangles;
};

/// Parses the bytes of a PLY file. Throws MeshError naming `file` and the header line or the element that is wrong.
/// Never reads past the end and never allocates more than the file can hold.
PlyContents decode_ply(const std::string& bytes, const std::string& file);

}  // namespace octocut::engine
