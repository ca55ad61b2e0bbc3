// Deterministic binary PLY writer (the format of the committed assets and of surface outputs).
#include <bit>
#include <cstring>

#include "octocut/engine/io/mesh_io.hpp"

namespace octocut::engine {
namespace {

static_assert(std::endian::native == std::endian::little, "binary PLY output assumes a little-endian host");

template <typename T>
void append_raw(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

}  // namespace

std::string encode_ply_binary(const sim::TriMesh& mesh) {
  std::string out;
  out += "ply\nformat binary_little_endian 1.0\ncomment octocut\n";
  out += "element vertex " + std::to_string(mesh.vertices.size()) + "\n";
  out += "property float x\nproperty float y\nproperty float z\n";
  out += "element face " + std::to_string(mesh.triangles.size()) + "\n";
  out += "property list uchar int vertex_indices\nend_header\n";
  out.reserve(out.size() + mesh.vertices.size() * 12 + mesh.triangles.size() * 13);
  for (const sim::Vec3& p : mesh.vertices) {
    for (int k = 0; k < 3; ++k) append_raw(out, static_cast<float>(p[k]));
  }
  for (const auto& t : mesh.triangles) {
    append_raw(out, static_cast<unsigned char>(3));
    for (int k = 0; k < 3; ++k) append_raw(out, static_cast<std::int32_t>(t[k]));
  }
  return out;
}

}  // namespace octocut::engine
