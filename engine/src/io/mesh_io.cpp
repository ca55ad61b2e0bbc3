// Mesh files (SPEC §2.4): import through assimp, deterministic welding, validation, and export by extension.
// assimp is confined to this file.
#include <assimp/BaseImporter.h>
#include <assimp/DefaultLogger.hpp>
#include <assimp/Exporter.hpp>
#include <assimp/Importer.hpp>
#include <assimp/LogStream.hpp>
#include <assimp/importerdesc.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <memory>
#include <mutex>
#include <new>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>

#include "octocut/cutting/mesh_check.hpp"
#include "octocut/engine/io/io.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/sim/surface_check.hpp"
#include "io/mesh_ply.hpp"

namespace octocut::engine {
namespace {

namespace fs = std::filesystem;

/// The first error-level message of an assimp import. Some importers repair malformed input silently and only log
/// an error: OFF clamps an out-of-range vertex index to the last vertex and drops faces without indices, OBJ skips
/// bad indices. Such a file is rejected rather than loaded as a different mesh.
class ImportErrors : public Assimp::LogStream {
 public:
  void write(const char* message) override {
    if (!first_.empty() || message == nullptr) return;
    std::string m(message);
    // Missing or unsupported materials and textures do not change the geometry.
    for (const char* benign : {"material", "Material", "texture", "Texture", "illumination"}) {
      if (m.find(benign) != std::string::npos) return;
    }
    while (!m.empty() && (m.back() == '\n' || m.back() == '\r')) m.pop_back();
    // assimp prefixes "Error, T<thread>: ".
    if (const auto colon = m.find(": "); m.rfind("Error", 0) == 0 && colon != std::string::npos) m.erase(0, colon + 2);
    first_ = m;
  }
  [[nodiscard]] const std::string& first() const { return first_; }

 private:
  std::string first_;
};

/// Serialises every use of assimp in this file: an import replaces assimp's process-wide logger for its duration
/// (CaptureImportErrors), and an export on another thread must not log into one being destroyed.
std::mutex& assimp_mutex() {
  static std::mutex m;
  return m;
}

/// Attaches an ImportErrors stream to assimp's (process-wide) logger for the lifetime of the object, holding
/// assimp_mutex.
class CaptureImportErrors {
 public:
  CaptureImportErrors() : lock_(assimp_mutex()) {
    Assimp::DefaultLogger::create("", Assimp::Logger::NORMAL, 0);  // no default streams (no file, no console)
    Assimp::DefaultLogger::get()->attachStream(&errors_, Assimp::Logger::Err);
  }
  ~CaptureImportErrors() {
    Assimp::DefaultLogger::get()->detachStream(&errors_, Assimp::Logger::Err);  // gives the stream back
    Assimp::DefaultLogger::kill();
  }
  CaptureImportErrors(const CaptureImportErrors&) = delete;
  CaptureImportErrors& operator=(const CaptureImportErrors&) = delete;
  [[nodiscard]] const std::string& first() const { return errors_.first(); }

 private:
  std::lock_guard<std::mutex> lock_;
  ImportErrors errors_;
};

/// An affine transform in double precision: x' = linear * x + offset.
struct Affine {
  sim::Mat3 linear = sim::Mat3::Identity();  ///< rotation, scale and shear
  sim::Vec3 offset = sim::Vec3::Zero();      ///< translation, file units
};

/// The affine part of an assimp node transform (row-major a1..d4; the projective row is ignored).
Affine to_affine(const aiMatrix4x4& m) {
  Affine a;
  a.linear << m.a1, m.a2, m.a3, m.b1, m.b2, m.b3, m.c1, m.c2, m.c3;
  a.offset = sim::Vec3(m.a4, m.b4, m.c4);
  return a;
}

/// The composition parent ∘ child.
Affine compose(const Affine& parent, const Affine& child) {
  return {parent.linear * child.linear, parent.linear * child.offset + parent.offset};
}

/// Formats a number for messages and text files: the shortest text that reads back to the same double.
std::string format_number(double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

/// A vertex as "(x, y, z)" for messages.
std::string format_point(const sim::Vec3& p) {
  return "(" + format_number(p.x()) + ", " + format_number(p.y()) + ", " + format_number(p.z()) + ")";
}

/// Appends every triangle of the scene's node tree to `positions` (file units, node transforms applied) and
/// `triangles` (indices into `positions`). Nodes are visited depth first in child order; a node whose transform
/// mirrors space gets its triangles reversed so that they keep their outward orientation.
void gather_triangles(const aiScene& scene, const std::string& file, std::vector<sim::Vec3>& positions,
                      std::vector<std::array<int64_t, 3>>& triangles) {
  // An explicit stack, so that a maliciously deep node tree cannot overflow the call stack.
  std::vector<std::pair<const aiNode*, Affine>> stack;
  if (scene.mRootNode != nullptr) stack.emplace_back(scene.mRootNode, to_affine(scene.mRootNode->mTransformation));
  while (!stack.empty()) {
    const auto [node, transform] = stack.back();
    stack.pop_back();
    const bool mirrored = transform.linear.determinant() < 0.0;

    // Transform this node's meshes into the file's world frame.
    for (unsigned k = 0; k < node->mNumMeshes; ++k) {
      const unsigned mesh_index = node->mMeshes[k];
      if (mesh_index >= scene.mNumMeshes || scene.mMeshes[mesh_index] == nullptr) {
        throw MeshError(file + ": node '" + node->mName.C_Str() + "' refers to missing mesh " +
                        std::to_string(mesh_index));
      }
      const aiMesh& mesh = *scene.mMeshes[mesh_index];
      const auto base = static_cast<int64_t>(positions.size());
      for (unsigned v = 0; v < mesh.mNumVertices; ++v) {
        const aiVector3D& p = mesh.mVertices[v];
        positions.push_back(transform.linear * sim::Vec3(p.x, p.y, p.z) + transform.offset);
      }
      // Keep triangles only: after aiProcess_Triangulate, faces with fewer corners are points or lines.
      for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
        const aiFace& face = mesh.mFaces[f];
        if (face.mNumIndices != 3) continue;
        std::array<int64_t, 3> t{};
        for (int c = 0; c < 3; ++c) {
          const unsigned index = face.mIndices[c];
          if (index >= mesh.mNumVertices) {
            throw MeshError(file + ": mesh " + std::to_string(mesh_index) + " face " + std::to_string(f) +
                            " refers to missing vertex " + std::to_string(index));
          }
          t[static_cast<std::size_t>(c)] = base + index;
        }
        if (mirrored) std::swap(t[1], t[2]);
        triangles.push_back(t);
      }
    }

    // Children go on the stack in reverse so that they come off in file order.
    for (unsigned c = node->mNumChildren; c-- > 0;) {
      const aiNode* child = node->mChildren[c];
      if (child != nullptr) stack.emplace_back(child, compose(transform, to_affine(child->mTransformation)));
    }
  }
}

/// Welds vertices with exactly equal positions and drops unused ones. New indices follow the order in which the
/// triangles first use the vertices, so the result depends only on the input order, never on a hash or an address.
/// Non-finite positions are never welded (they are reported by validation under their own index).
sim::TriMesh weld(const std::vector<sim::Vec3>& positions, const std::vector<std::array<int64_t, 3>>& triangles) {
  // Sort the finite positions lexicographically (ties by index); each run of equal positions maps to its first index.
  const std::size_t n = positions.size();
  std::vector<std::size_t> canonical(n);
  std::iota(canonical.begin(), canonical.end(), std::size_t{0});
  std::vector<std::size_t> order;
  order.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (positions[i].allFinite()) order.push_back(i);
  }
  const auto less = [&](std::size_t a, std::size_t b) {
    const sim::Vec3& p = positions[a];
    const sim::Vec3& q = positions[b];
    if (p.x() != q.x()) return p.x() < q.x();
    if (p.y() != q.y()) return p.y() < q.y();
    if (p.z() != q.z()) return p.z() < q.z();
    return a < b;
  };
  std::sort(order.begin(), order.end(), less);
  for (std::size_t k = 1; k < order.size(); ++k) {
    if (positions[order[k]] == positions[order[k - 1]]) canonical[order[k]] = canonical[order[k - 1]];
  }

  // Number the canonical vertices in order of first use by the triangles.
  sim::TriMesh mesh;
  std::vector<int64_t> new_index(n, -1);
  mesh.triangles.reserve(triangles.size());
  for (const auto& t : triangles) {
    std::array<int32_t, 3> out{};
    for (std::size_t c = 0; c < 3; ++c) {
      const std::size_t r = canonical[static_cast<std::size_t>(t[c])];
      if (new_index[r] < 0) {
        new_index[r] = static_cast<int64_t>(mesh.vertices.size());
        mesh.vertices.push_back(positions[r]);
      }
      out[c] = static_cast<int32_t>(new_index[r]);
    }
    mesh.triangles.push_back(out);
  }
  return mesh;
}

/// "(a, b)" for an edge in messages.
std::string format_edge(const std::array<int32_t, 2>& e) {
  return "(" + std::to_string(e[0]) + ", " + std::to_string(e[1]) + ")";
}

/// "triangle f (vertices a, b, c)" for messages.
std::string format_triangle(const sim::TriMesh& mesh, std::size_t f) {
  const auto& t = mesh.triangles[f];
  return "triangle " + std::to_string(f) + " (vertices " + std::to_string(t[0]) + ", " + std::to_string(t[1]) + ", " +
         std::to_string(t[2]) + ")";
}

/// Lower-case extension of `path`, with the dot (".ply").
std::string lower_extension(const fs::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

/// An OFF file with shortest round-trip decimal coordinates (assimp 5.2 has no OFF exporter).
std::string encode_off(const sim::TriMesh& mesh) {
  std::string out = "OFF\n" + std::to_string(mesh.num_vertices()) + " " + std::to_string(mesh.num_triangles()) + " 0\n";
  for (const sim::Vec3& p : mesh.vertices) {
    out += format_number(p.x()) + " " + format_number(p.y()) + " " + format_number(p.z()) + "\n";
  }
  for (const auto& t : mesh.triangles) {
    out += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + "\n";
  }
  return out;
}

/// An OBJ file (vertices and triangles, 1-based) with shortest round-trip decimal coordinates: assimp's exporter
/// writes 32-bit floats.
std::string encode_obj(const sim::TriMesh& mesh) {
  std::string out = "# octocut\n";
  for (const sim::Vec3& p : mesh.vertices)
    out += "v " + format_number(p.x()) + " " + format_number(p.y()) + " " + format_number(p.z()) + "\n";
  for (const auto& t : mesh.triangles)
    out += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " + std::to_string(t[2] + 1) + "\n";
  return out;
}

/// A one-mesh, one-material assimp scene holding `mesh` (single precision, as assimp stores it).
std::unique_ptr<aiScene> to_assimp_scene(const sim::TriMesh& mesh) {
  auto scene = std::make_unique<aiScene>();
  scene->mMaterials = new aiMaterial*[1]{new aiMaterial()};
  scene->mNumMaterials = 1;

  // One triangle mesh; the scene's destructor frees every array below.
  auto* out = new aiMesh();
  scene->mMeshes = new aiMesh*[1]{out};
  scene->mNumMeshes = 1;
  out->mName = aiString("surface");
  out->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
  out->mMaterialIndex = 0;
  out->mNumVertices = static_cast<unsigned>(mesh.num_vertices());
  out->mVertices = new aiVector3D[mesh.num_vertices()];
  for (std::size_t v = 0; v < mesh.num_vertices(); ++v) {
    const sim::Vec3& p = mesh.vertices[v];
    out->mVertices[v] =
        aiVector3D(static_cast<ai_real>(p.x()), static_cast<ai_real>(p.y()), static_cast<ai_real>(p.z()));
  }
  out->mNumFaces = static_cast<unsigned>(mesh.num_triangles());
  out->mFaces = new aiFace[mesh.num_triangles()];
  for (std::size_t f = 0; f < mesh.num_triangles(); ++f) {
    aiFace& face = out->mFaces[f];
    face.mNumIndices = 3;
    face.mIndices = new unsigned[3];
    for (std::size_t c = 0; c < 3; ++c) face.mIndices[c] = static_cast<unsigned>(mesh.triangles[f][c]);
  }

  // A root node that instantiates the mesh with the identity transform.
  scene->mRootNode = new aiNode("root");
  scene->mRootNode->mMeshes = new unsigned[1]{0};
  scene->mRootNode->mNumMeshes = 1;
  return scene;
}

/// The base name that Assimp::Exporter::ExportToBlob gives the files it writes into memory (AI_BLOBIO_MAGIC).
constexpr const char* kBlobBaseName = "$blobfile";

/// Standard base64 (RFC 4648, with padding) of `size` bytes at `data`.
std::string base64(const unsigned char* data, std::size_t size) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((size + 2) / 3 * 4);
  // Each group of three bytes becomes four characters; a short last group is padded with '='.
  for (std::size_t i = 0; i < size; i += 3) {
    const std::size_t n = std::min<std::size_t>(3, size - i);
    uint32_t group = uint32_t(data[i]) << 16;
    if (n > 1) group |= uint32_t(data[i + 1]) << 8;
    if (n > 2) group |= uint32_t(data[i + 2]);
    out += kAlphabet[(group >> 18) & 63];
    out += kAlphabet[(group >> 12) & 63];
    out += n > 1 ? kAlphabet[(group >> 6) & 63] : '=';
    out += n > 2 ? kAlphabet[group & 63] : '=';
  }
  return out;
}

/// The bytes of a blob chain entry.
std::string blob_bytes(const aiExportDataBlob& blob) {
  return std::string(static_cast<const char*>(blob.data), blob.size);
}

/// Exports through assimp into memory. For glTF the external buffer (".bin" blob) is embedded as a base64 data URI,
/// so that one file holds the whole mesh and one atomic write suffices.
std::string export_with_assimp(const fs::path& path, const sim::TriMesh& mesh, const char* format_id) {
  const std::unique_ptr<aiScene> scene = to_assimp_scene(mesh);
  const std::lock_guard<std::mutex> lock(assimp_mutex());
  Assimp::Exporter exporter;
  const aiExportDataBlob* blob = exporter.ExportToBlob(scene.get(), format_id);
  if (blob == nullptr) {
    throw MeshError(path.string() + ": cannot export as " + format_id + ": " + exporter.GetErrorString());
  }
  std::string bytes = blob_bytes(*blob);
  if (std::string(format_id) == "gltf2") {
    // Replace each external buffer reference "<blob name>.bin" by the buffer's bytes as a data URI.
    for (const aiExportDataBlob* extra = blob->next; extra != nullptr; extra = extra->next) {
      const std::string reference = std::string(kBlobBaseName) + "." + extra->name.C_Str();
      const std::string quoted = "\"" + reference + "\"";
      const std::size_t at = bytes.find(quoted);
      if (at == std::string::npos) {
        throw MeshError(path.string() + ": cannot embed glTF buffer '" + reference + "': not referenced");
      }
      const std::string data_uri = "\"data:application/octet-stream;base64," +
                                   base64(static_cast<const unsigned char*>(extra->data), extra->size) + "\"";
      bytes.replace(at, quoted.size(), data_uri);
    }
  } else if (blob->next != nullptr) {
    throw MeshError(path.string() + ": exporter " + format_id + " produced more than one file");
  }
  return bytes;
}

}  // namespace

std::vector<std::string> validate_mesh(sim::TriMesh& mesh, const std::string& file, bool self_intersections) {
  std::vector<std::string> warnings;
  if (mesh.triangles.empty()) throw MeshError(file + ": mesh has no triangles");

  // Vertex indices in range (check_surface would reject them too, without the file name).
  const auto nv = static_cast<int64_t>(mesh.num_vertices());
  for (std::size_t f = 0; f < mesh.num_triangles(); ++f) {
    for (const int32_t v : mesh.triangles[f]) {
      if (v < 0 || v >= nv) {
        throw MeshError(file + ": triangle " + std::to_string(f) + " refers to vertex " + std::to_string(v) +
                        ", but the mesh has " + std::to_string(nv) + " vertices");
      }
    }
  }

  // Finite coordinates.
  for (std::size_t v = 0; v < mesh.num_vertices(); ++v) {
    if (!mesh.vertices[v].allFinite()) {
      throw MeshError(file + ": vertex " + std::to_string(v) + " has a non-finite coordinate " +
                      format_point(mesh.vertices[v]));
    }
  }

  // Degenerate triangles: a repeated index, or an area that is zero relative to the mesh size.
  const sim::Box3 box = sim::bounds(mesh);
  const double diagonal = (box.max - box.min).norm();
  for (std::size_t f = 0; f < mesh.num_triangles(); ++f) {
    const auto& t = mesh.triangles[f];
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
      throw MeshError(file + ": degenerate " + format_triangle(mesh, f) + ": a vertex is repeated");
    }
    const sim::Vec3& a = mesh.vertices[static_cast<std::size_t>(t[0])];
    const sim::Vec3 twice_area = (mesh.vertices[static_cast<std::size_t>(t[1])] - a)
                                     .cross(mesh.vertices[static_cast<std::size_t>(t[2])] - a);
    if (twice_area.norm() <= 1e-12 * diagonal * diagonal) {
      throw MeshError(file + ": degenerate " + format_triangle(mesh, f) + ": zero area");
    }
  }

  // Topology: closed, edge-manifold, vertex-manifold, consistently oriented.
  const sim::SurfaceCheck check = sim::check_surface(mesh);
  if (check.boundary_edge.found()) {
    throw MeshError(file + ": mesh is not closed: edge " + format_edge(check.boundary_edge.edge) + " of triangle " +
                    std::to_string(check.boundary_edge.triangle) + " is used by no other triangle");
  }
  if (check.nonmanifold_edge.found()) {
    throw MeshError(file + ": mesh is not manifold: edge " + format_edge(check.nonmanifold_edge.edge) +
                    " is shared by " + std::to_string(check.nonmanifold_edge.uses) + " triangles (first triangles " +
                    std::to_string(check.nonmanifold_edge.triangle) + " and " +
                    std::to_string(check.nonmanifold_edge.other_triangle) + ")");
  }
  if (!check.vertex_manifold) {
    throw MeshError(file + ": mesh is not manifold at vertex " + std::to_string(check.nonmanifold_vertex) +
                    ": its triangles form " + std::to_string(check.nonmanifold_vertex_fans) + " separate fans");
  }
  if (check.misoriented_edge.found()) {
    throw MeshError(file + ": mesh is not consistently oriented: edge " + format_edge(check.misoriented_edge.edge) +
                    " runs the same way in triangles " + std::to_string(check.misoriented_edge.triangle) + " and " +
                    std::to_string(check.misoriented_edge.other_triangle));
  }

  // Volume: zero is an error; negative means consistently inside out, which is repaired with a warning.
  const double volume = sim::signed_volume(mesh);
  if (!(std::abs(volume) > 1e-12 * diagonal * diagonal * diagonal)) {
    throw MeshError(file + ": mesh encloses zero volume (" + format_number(volume) + " m^3)");
  }
  if (volume < 0.0) {
    for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
    warnings.push_back(file + ": reoriented a consistently inverted mesh (signed volume " + format_number(volume) +
                       " m^3)");
  }

  // Self-intersections, exact predicates in the cutting module.
  if (self_intersections) {
    std::optional<std::array<int, 2>> pair;
    try {
      pair = cutting::find_self_intersection(mesh);
    } catch (const std::invalid_argument& error) {
      throw MeshError(file + ": " + error.what());
    }
    if (pair) {
      throw MeshError(file + ": mesh self-intersects: " + format_triangle(mesh, static_cast<std::size_t>((*pair)[0])) +
                      " and " + format_triangle(mesh, static_cast<std::size_t>((*pair)[1])) + " intersect");
    }
  }
  return warnings;
}

void read_with_assimp(const fs::path& path, const std::string& file, std::vector<sim::Vec3>& positions,
                      std::vector<std::array<int64_t, 3>>& triangles);

LoadedMesh load_mesh(const fs::path& path, const MeshLoadOptions& options) {
  const std::string file = path.string();
  if (!std::isfinite(options.scale) || options.scale <= 0.0) {
    throw MeshError(file + ": scale must be finite and positive, got " + format_number(options.scale));
  }

  // The file must exist, be a regular file and hold something.
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (ec || !fs::exists(status)) throw MeshError(file + ": cannot read: no such file");
  if (!fs::is_regular_file(status)) throw MeshError(file + ": cannot read: not a regular file");
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) throw MeshError(file + ": cannot read: " + ec.message());
  if (size == 0) throw MeshError(file + ": empty file");

  // PLY with our own reader (double precision); the rest: assimp parses and triangulates. Welding and validation are
  // ours.
  std::vector<sim::Vec3> positions;
  std::vector<std::array<int64_t, 3>> triangles;
  if (lower_extension(path) == ".ply") {
    PlyContents ply = decode_ply(read_file(path), file);
    positions = std::move(ply.positions);
    triangles = std::move(ply.triangles);
  } else {
    read_with_assimp(path, file, positions, triangles);
  }
  if (triangles.empty()) throw MeshError(file + ": no triangles in the file");
  if (positions.size() > static_cast<std::size_t>(INT32_MAX)) throw MeshError(file + ": too many vertices");
  for (sim::Vec3& p : positions) p *= options.scale;
  LoadedMesh loaded;
  loaded.mesh = weld(positions, triangles);
  if (options.validate) loaded.warnings = validate_mesh(loaded.mesh, file, options.self_intersections);
  return loaded;
}

namespace {
// Leaves `importer` with only the importers that claim the file's extension, and returns the others (to delete once
// the import is done). Assimp tries every other importer on a file that its own refuses, and some of those crash on
// hostile input: fuzzing found its binary PLY reader reading out of bounds on a PLY file named .gltf.
std::vector<std::unique_ptr<Assimp::BaseImporter>> keep_importers_of(Assimp::Importer& importer, const std::string& ext) {
  std::vector<std::unique_ptr<Assimp::BaseImporter>> dropped;
  const std::string want = ext.substr(1);  // without the dot
  for (std::size_t i = importer.GetImporterCount(); i-- > 0;) {
    const aiImporterDesc* desc = importer.GetImporterInfo(i);
    bool claims = false;
    if (desc != nullptr && desc->mFileExtensions != nullptr) {
      const std::string list = std::string(" ") + desc->mFileExtensions + " ";
      claims = list.find(" " + want + " ") != std::string::npos;
    }
    if (claims) continue;
    Assimp::BaseImporter* other = importer.GetImporter(i);
    if (other != nullptr && importer.UnregisterLoader(other) == aiReturn_SUCCESS) dropped.emplace_back(other);
  }
  return dropped;
}
}  // namespace

namespace {
// An OFF file's header counts against its size: assimp allocates the declared vertices and faces before it reads
// them, so a header that declares billions made it ask for tens of gigabytes (found by the mesh fuzzer). Every vertex
// takes at least 6 bytes ("0 0 0\n") and every face at least 8 ("3 0 1 2\n"); throws when the file is too short.
void check_off_counts(const fs::path& path, const std::string& file) {
  const std::string text = read_file(path);
  std::size_t at = 0;
  std::vector<std::string> words;  // the magic and the counts, comments and blank space skipped
  while (at < text.size() && words.size() < 4) {
    if (text[at] == '#') {
      while (at < text.size() && text[at] != '\n') ++at;
      continue;
    }
    if (std::isspace(static_cast<unsigned char>(text[at]))) {
      ++at;
      continue;
    }
    std::size_t end = at;
    while (end < text.size() && !std::isspace(static_cast<unsigned char>(text[end])) && text[end] != '#') ++end;
    std::string word = text.substr(at, end - at);
    // "OFF" may be glued to the counts' line or stand alone; "OFF3 4 ..." is not a form octocut reads anyway.
    words.push_back(std::move(word));
    at = end;
  }
  if (words.empty() || words[0].find("OFF") == std::string::npos) return;  // not OFF: assimp says what it is
  long double needed = 0.0L;
  for (std::size_t k = 1; k < 3 && k < words.size(); ++k) {
    long double count = 0.0L;
    const char* b = words[k].data();
    const char* e = b + words[k].size();
    std::uint64_t n = 0;
    const std::errc ec = std::from_chars(b, e, n).ec;
    // A word's leading digits are what assimp's reader takes as the count ("4Stexture" reads as 4), so they are
    // what is checked; a word without any ends the counts (assimp reports the malformed header), and the counts
    // before it are still checked (found by the mesh fuzzer: a 20-digit vertex count before such a word).
    if (ec == std::errc::result_out_of_range)
      count = 1e30L;
    else if (ec == std::errc())
      count = static_cast<long double>(n);
    else
      break;
    needed += count * (k == 1 ? 6.0L : 8.0L);
  }
  if (needed > static_cast<long double>(text.size()))
    throw MeshError(file + ": malformed mesh: the OFF header declares " + words[1] + " vertices and " +
                    (words.size() > 2 ? words[2] : std::string("?")) + " faces, more than its " +
                    std::to_string(text.size()) + " bytes can hold");
}
}  // namespace

void read_with_assimp(const fs::path& path, const std::string& file, std::vector<sim::Vec3>& positions,
                      std::vector<std::array<int64_t, 3>>& triangles) {
  const std::string ext = lower_extension(path);
  if (ext == ".off") check_off_counts(path, file);
  if (ext != ".obj" && ext != ".stl" && ext != ".off" && ext != ".gltf" && ext != ".glb")
    throw MeshError(file + ": unsupported mesh format '" + ext + "' (use .ply, .obj, .stl, .off, .gltf or .glb)");
  Assimp::Importer importer;
  const std::vector<std::unique_ptr<Assimp::BaseImporter>> others = keep_importers_of(importer, ext);
  const CaptureImportErrors errors;
  const aiScene* scene = nullptr;
  try {
    scene = importer.ReadFile(file, aiProcess_Triangulate | aiProcess_ValidateDataStructure);
  } catch (const std::bad_alloc&) {
    throw MeshError(file + ": cannot read mesh: it declares more data than memory holds");
  }
  if (scene == nullptr) {
    throw MeshError(file + ": cannot read mesh (unknown format or corrupt file): " + importer.GetErrorString());
  }
  if (!errors.first().empty()) throw MeshError(file + ": malformed mesh: " + errors.first());

  // Merge every mesh of the node tree.
  gather_triangles(*scene, file, positions, triangles);
}

void save_mesh(const fs::path& path, const sim::TriMesh& mesh, PlyPrecision ply) {
  const std::string file = path.string();

  // Refuse meshes whose indices would make a broken file.
  const auto nv = static_cast<int64_t>(mesh.num_vertices());
  for (std::size_t f = 0; f < mesh.num_triangles(); ++f) {
    for (const int32_t v : mesh.triangles[f]) {
      if (v < 0 || v >= nv) {
        throw MeshError(file + ": cannot save: triangle " + std::to_string(f) + " refers to vertex " +
                        std::to_string(v) + ", but the mesh has " + std::to_string(nv) + " vertices");
      }
    }
  }

  // Encode by extension.
  const std::string ext = lower_extension(path);
  std::string bytes;
  if (ext == ".ply") {
    bytes = encode_ply_binary(mesh, ply);
  } else if (ext == ".off") {
    bytes = encode_off(mesh);
  } else if (ext == ".obj") {
    bytes = encode_obj(mesh);
  } else if (ext == ".stl") {
    bytes = export_with_assimp(path, mesh, "stlb");
  } else if (ext == ".gltf") {
    bytes = export_with_assimp(path, mesh, "gltf2");
  } else if (ext == ".glb") {
    bytes = export_with_assimp(path, mesh, "glb2");
  } else {
    throw MeshError(file + ": cannot save: unknown mesh extension '" + path.extension().string() +
                    "' (use .ply, .obj, .stl, .off, .gltf or .glb)");
  }

  // One atomic write.
  try {
    write_file_atomic(path, bytes);
  } catch (const std::runtime_error& error) {
    throw MeshError(error.what());
  }
}

}  // namespace octocut::engine
