// Tests for mesh files (SPEC §2.4): round trips through every format, inline files of each text format, welding,
// scale, node transforms, one validation error per defect class.
#include "octocut/engine/io/mesh_io.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <Eigen/Geometry>
#include <cstdint>
#include <limits>
#include <numbers>
#include <utility>
#include <random>
#include <string>
#include <vector>

#include "cutting/test_meshes.hpp"
#include "octocut/engine/io/io.hpp"
#include "common/temp_dir.hpp"

namespace octocut::engine {
namespace {

namespace fs = std::filesystem;
using test::grid_cube;
using test::octahedron;

/// Relative tolerance for data that went through float32 (PLY, OBJ, STL, glTF store single precision).
constexpr double kFloatTolerance = 1e-6;

/// Gives each test a fresh, empty directory, removed afterwards, and helpers to write and load files in it.
class MeshIoTest : public octocut::test::TempDirTest {
 protected:

  /// Writes `content` to `name` in the test directory and returns its path.
  fs::path write(const std::string& name, const std::string& content) const {
    const fs::path path = m_dir / name;
    std::ofstream(path, std::ios::binary) << content;
    return path;
  }

  /// The message of the MeshError that loading `path` throws, or "(no error)".
  static std::string load_error(const fs::path& path, const MeshLoadOptions& options = {}) {
    try {
      (void)load_mesh(path, options);
    } catch (const MeshError& error) {
      return error.what();
    }
    return "(no error)";
  }

};

/// True when `text` contains `part`.
bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

/// Expects the two vertex sets to match one to one within `tolerance` (brute-force nearest neighbour).
void expect_same_vertex_set(const std::vector<sim::Vec3>& expected, const std::vector<sim::Vec3>& actual,
                            double tolerance) {
  ASSERT_EQ(expected.size(), actual.size());
  std::vector<char> taken(actual.size(), 0);
  for (const sim::Vec3& p : expected) {
    std::size_t best = actual.size();
    double best_distance = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < actual.size(); ++i) {
      const double d = (actual[i] - p).norm();
      if (!taken[i] && d < best_distance) {
        best = i;
        best_distance = d;
      }
    }
    ASSERT_LT(best, actual.size());
    EXPECT_LE(best_distance, tolerance) << "no loaded vertex near (" << p.transpose() << ")";
    taken[best] = 1;
  }
}

// ---- round trips ---------------------------------------------------------------------------------------------------

TEST_F(MeshIoTest, RoundTripThroughEveryFormatKeepsVerticesTrianglesAndVolume) {
  // Off-lattice coordinates, so that float storage actually rounds.
  sim::TriMesh cube = grid_cube(3, 0.07, sim::Vec3(0.013, -0.021, 0.1));
  const std::vector<std::pair<std::string, sim::TriMesh>> meshes = {{"octahedron", octahedron(0.031)},
                                                                     {"cube", cube}};
  for (const std::string ext : {".ply", ".obj", ".stl", ".off", ".gltf", ".glb", ".PLY"}) {
    for (const auto& [name, mesh] : meshes) {
      SCOPED_TRACE(name + ext);
      const fs::path path = m_dir / (name + ext);
      save_mesh(path, mesh);
      const LoadedMesh loaded = load_mesh(path);
      EXPECT_TRUE(loaded.warnings.empty());
      EXPECT_EQ(loaded.mesh.num_triangles(), mesh.num_triangles());
      const double size = (sim::bounds(mesh).max - sim::bounds(mesh).min).norm();
      // Every format goes through float32 on the way (OFF is written with round-trip decimals, but assimp reads
      // coordinates as float).
      expect_same_vertex_set(mesh.vertices, loaded.mesh.vertices, kFloatTolerance * size);
      const double volume = sim::signed_volume(mesh);
      EXPECT_NEAR(sim::signed_volume(loaded.mesh), volume, 1e-5 * volume);
    }
  }
}

TEST_F(MeshIoTest, SavingIsDeterministicAndAtomic) {
  const sim::TriMesh mesh = grid_cube(2, 0.05);
  for (const std::string ext : {".ply", ".obj", ".stl", ".off", ".gltf", ".glb"}) {
    SCOPED_TRACE(ext);
    save_mesh(m_dir / ("a" + ext), mesh);
    save_mesh(m_dir / ("b" + ext), mesh);
    EXPECT_EQ(read_file(m_dir / ("a" + ext)), read_file(m_dir / ("b" + ext)));
  }
  // Only the finished files remain: no temporary files next to them.
  int entries = 0;
  for ([[maybe_unused]] const auto& entry : fs::directory_iterator(m_dir)) ++entries;
  EXPECT_EQ(entries, 12);
  // The PLY bytes are exactly the shared encoder's.
  EXPECT_EQ(read_file(m_dir / "a.ply"), encode_ply_binary(mesh));
}

TEST_F(MeshIoTest, SaveRejectsAnUnknownExtensionAndBadIndices) {
  try {
    save_mesh(m_dir / "mesh.xyz", octahedron());
    FAIL() << "no error";
  } catch (const MeshError& error) {
    EXPECT_TRUE(has(error.what(), "mesh.xyz")) << error.what();
    EXPECT_TRUE(has(error.what(), "unknown mesh extension '.xyz'")) << error.what();
  }
  sim::TriMesh broken = octahedron();
  broken.triangles[2][1] = 9;
  try {
    save_mesh(m_dir / "broken.ply", broken);
    FAIL() << "no error";
  } catch (const MeshError& error) {
    EXPECT_TRUE(has(error.what(), "broken.ply: cannot save: triangle 2 refers to vertex 9")) << error.what();
  }
  EXPECT_FALSE(fs::exists(m_dir / "mesh.xyz"));
  EXPECT_FALSE(fs::exists(m_dir / "broken.ply"));
}

// ---- inline text files ---------------------------------------------------------------------------------------------

/// The unit right tetrahedron, outward oriented: volume 1/6.
const char* const kTetraOff =
    "OFF\n"
    "4 4 0\n"
    "0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
    "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";

TEST_F(MeshIoTest, ReadsInlineOff) {
  const LoadedMesh loaded = load_mesh(write("tetra.off", kTetraOff));
  EXPECT_EQ(loaded.mesh.num_vertices(), 4u);
  EXPECT_EQ(loaded.mesh.num_triangles(), 4u);
  EXPECT_NEAR(sim::signed_volume(loaded.mesh), 1.0 / 6.0, 1e-15);
  expect_same_vertex_set({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, loaded.mesh.vertices, 0.0);
}

// A file is read only by the importers of its own extension: a valid OFF or ASCII PLY mesh named .gltf or .stl is
// refused with the file's name (assimp would otherwise try all its other importers on it, some of which crash on
// hostile input), and an extension octocut does not read is refused before any importer runs.
TEST_F(MeshIoTest, AFileIsReadOnlyAsTheFormatItsExtensionNames) {
  const std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
      "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
  EXPECT_EQ(load_mesh(write("tetra.ply", ply)).mesh.num_triangles(), 4u);
  EXPECT_EQ(load_mesh(write("tetra.off", kTetraOff)).mesh.num_triangles(), 4u);
  const std::string off = kTetraOff;
  for (const auto& [name, text] : {std::pair<std::string, std::string>{"disguised.gltf", ply},
                                   {"disguised.stl", off}, {"disguised2.gltf", off}}) {
    const fs::path file = write(name, text);
    try {
      (void)load_mesh(file);
      ADD_FAILURE() << name << " was read";
    } catch (const MeshError& e) {
      EXPECT_NE(std::string(e.what()).find(file.string()), std::string::npos) << e.what();
    }
  }
  try {
    (void)load_mesh(write("tetra.3ds", kTetraOff));
    ADD_FAILURE() << ".3ds was read";
  } catch (const MeshError& e) {
    EXPECT_NE(std::string(e.what()).find("unsupported mesh format '.3ds'"), std::string::npos) << e.what();
  }
}

// An OFF header that declares more vertices or faces than the file can hold is a clear error before any importer
// allocates them (the mesh fuzzer's input declared 4.6e37 vertices in 89 bytes).
TEST_F(MeshIoTest, OffCountsBeyondTheFileSizeAreRefusedBeforeImport) {
  // The last two: a count glued to text, and a count before a word that is none (the mesh fuzzer's input).
  for (const std::string header :
       {"OFF\n455555555555 4 5\n", "OFF 4 99999999 0\n", "# c\nOFF\n4555555555555555555555555 1 0\n",
        "OFF\n5555555555x 4 0\n", "OFF\n55555555555555555554 4Stexturectype I\n"}) {
    const fs::path file = write("big.off", header + "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n");
    const std::string message = load_error(file);
    EXPECT_TRUE(has(message, file.string() + ": malformed mesh: the OFF header declares")) << message;
  }
  EXPECT_EQ(load_mesh(write("tetra.off", kTetraOff)).mesh.num_triangles(), 4u);  // a true header passes
}

TEST_F(MeshIoTest, ReadsInlineObjWithQuadsAndTriangulatesThem) {
  // A unit cube of six quads (outward counter-clockwise), written with a comment and a group.
  const std::string obj =
      "# unit cube\n"
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
      "g cube\n"
      "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
  const LoadedMesh loaded = load_mesh(write("cube.obj", obj));
  EXPECT_EQ(loaded.mesh.num_vertices(), 8u);
  EXPECT_EQ(loaded.mesh.num_triangles(), 12u);
  EXPECT_NEAR(sim::signed_volume(loaded.mesh), 1.0, 1e-12);
  EXPECT_TRUE(loaded.warnings.empty());
}

TEST_F(MeshIoTest, ReadsInlineAsciiPly) {
  const std::string ply =
      "ply\nformat ascii 1.0\ncomment a tetrahedron\n"
      "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n2 0 0\n0 2 0\n0 0 2\n"
      "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
  const LoadedMesh loaded = load_mesh(write("tetra.ply", ply));
  EXPECT_EQ(loaded.mesh.num_vertices(), 4u);
  EXPECT_NEAR(sim::signed_volume(loaded.mesh), 8.0 / 6.0, 1e-12);
}

// A unit cube as 6 quads in ASCII PLY, with an extra per-vertex property and an edge element to read past: the
// quads fan into 12 triangles enclosing volume 1.
TEST_F(MeshIoTest, AsciiPlyQuadsAndExtraPropertiesAndElements) {
  const std::string ply =
      "ply\r\nformat ascii 1.0\r\nobj_info made by hand\r\n"
      "element vertex 8\nproperty double x\nproperty uchar red\nproperty double y\nproperty double z\n"
      "element face 6\nproperty uchar flags\nproperty list uchar uint vertex_index\n"
      "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"
      "0 9 0 0\n1 9 0 0\n1 9 1 0\n0 9 1 0\n0 9 0 1\n1 9 0 1\n1 9 1 1\n0 9 1 1\n\n"
      "7 4 0 3 2 1\n7 4 4 5 6 7\n7 4 0 1 5 4\n7 4 1 2 6 5\n7 4 2 3 7 6\n7 4 3 0 4 7\n"
      "0 1\n";
  const LoadedMesh loaded = load_mesh(write("cube.ply", ply));
  EXPECT_EQ(loaded.mesh.num_vertices(), 8u);
  EXPECT_EQ(loaded.mesh.num_triangles(), 12u);
  EXPECT_DOUBLE_EQ(sim::signed_volume(loaded.mesh), 1.0);
}

// Big-endian binary with double coordinates and short indices: the bytes are built by hand here.
TEST_F(MeshIoTest, BigEndianBinaryPlyReadsExactDoubles) {
  const sim::TriMesh tetra{{sim::Vec3(0.1, 0.2, 0.3), sim::Vec3(2.0 / 3.0, 0.2, 0.3), sim::Vec3(0.1, std::sqrt(2.0), 0.3),
                            sim::Vec3(0.1, 0.2, std::numbers::pi)},
                           {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}}};
  std::string bytes = "ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty float64 x\nproperty float64 y\n"
                      "property float64 z\nelement face 4\nproperty list uint8 int16 vertex_indices\nend_header\n";
  auto big = [&](const void* p, std::size_t n) {
    const auto* c = static_cast<const char*>(p);
    for (std::size_t i = n; i-- > 0;) bytes += c[i];
  };
  for (const sim::Vec3& v : tetra.vertices)
    for (int k = 0; k < 3; ++k) big(&v[k], 8);
  for (const auto& t : tetra.triangles) {
    bytes += char(3);
    for (int32_t v : t) {
      const auto s = std::int16_t(v);
      big(&s, 2);
    }
  }
  const LoadedMesh loaded = load_mesh(write("tetra.ply", bytes));
  ASSERT_EQ(loaded.mesh.num_vertices(), 4u);
  EXPECT_EQ(sim::signed_volume(loaded.mesh), sim::signed_volume(tetra));  // the same doubles, bit for bit
}

// Written as double PLY (the default) a mesh of awkward coordinates reads back bit for bit; as float PLY it does not.
TEST_F(MeshIoTest, DoublePlyRoundTripsBitForBit) {
  sim::TriMesh cube = grid_cube(3, 0.1);
  const Eigen::Matrix3d rot = Eigen::AngleAxisd(0.3, sim::Vec3(1, 1, 2).normalized()).toRotationMatrix();
  for (sim::Vec3& v : cube.vertices) v = rot * v + sim::Vec3(1.0 / 3.0, 1e-7, 0.0);
  save_mesh(m_dir / "exact.ply", cube);
  save_mesh(m_dir / "single.ply", cube, PlyPrecision::single);
  const sim::TriMesh exact = load_mesh(m_dir / "exact.ply").mesh;
  ASSERT_EQ(exact.triangles.size(), cube.triangles.size());
  for (std::size_t f = 0; f < cube.triangles.size(); ++f)
    for (int k = 0; k < 3; ++k)
      EXPECT_EQ(exact.vertices[std::size_t(exact.triangles[f][std::size_t(k)])], cube.vertices[std::size_t(cube.triangles[f][std::size_t(k)])]);
  const sim::TriMesh single = load_mesh(m_dir / "single.ply").mesh;
  EXPECT_NE(sim::signed_volume(single), sim::signed_volume(cube));
  EXPECT_LT(fs::file_size(m_dir / "single.ply"), fs::file_size(m_dir / "exact.ply"));
}

// Hostile PLY files are errors that name the file and what is wrong, never crashes or huge allocations.
TEST_F(MeshIoTest, HostilePlyFilesAreClearErrors) {
  const std::string header = "ply\nformat binary_little_endian 1.0\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n", "end_header"},
      {header + "element vertex 99999999999999\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
       "more than the file holds"},
      {"ply\nformat ascii 2.0\nend_header\n", "version"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n", "unknown property type"},
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
       "refers to vertex 7"},
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 1e300\n",
       "not a 32-bit integer"},
      {"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
       "0 0 0\n1 zero 0\n",
       "line 9"},
      {header + "element vertex 1\nproperty double x\nproperty double y\nproperty double z\nend_header\nshort",
       "file ends inside vertex 0"},
      {"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n3 0 1 2\n",
       "no vertex element"},
  };
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const fs::path file = write("bad" + std::to_string(i) + ".ply", cases[i].first);
    try {
      load_mesh(file);
      ADD_FAILURE() << "case " << i << " loaded";
    } catch (const MeshError& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.rfind(file.string(), 0), 0u) << what;
      EXPECT_NE(what.find(cases[i].second), std::string::npos) << "case " << i << ": " << what;
    }
  }
}

TEST_F(MeshIoTest, ReadsInlineAsciiStlAndWeldsItsCorners) {
  // STL stores three corners per facet and shares none: 12 corners weld to the tetrahedron's 4 vertices.
  const std::string stl =
      "solid tetra\n"
      "facet normal 0 0 -1\nouter loop\nvertex 0 0 0\nvertex 0 1 0\nvertex 1 0 0\nendloop\nendfacet\n"
      "facet normal 0 -1 0\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 0 1\nendloop\nendfacet\n"
      "facet normal -1 0 0\nouter loop\nvertex 0 0 0\nvertex 0 0 1\nvertex 0 1 0\nendloop\nendfacet\n"
      "facet normal 1 1 1\nouter loop\nvertex 1 0 0\nvertex 0 1 0\nvertex 0 0 1\nendloop\nendfacet\n"
      "endsolid tetra\n";
  const LoadedMesh loaded = load_mesh(write("tetra.stl", stl));
  EXPECT_EQ(loaded.mesh.num_vertices(), 4u);
  EXPECT_EQ(loaded.mesh.num_triangles(), 4u);
  EXPECT_NEAR(sim::signed_volume(loaded.mesh), 1.0 / 6.0, 1e-12);
}

TEST_F(MeshIoTest, BinaryStlWeldsToTheOriginalVertexCount) {
  // 6 * 4^2 + 2 = 98 shared vertices become 3 * 192 STL corners, and weld back to 98.
  const sim::TriMesh cube = grid_cube(4, 0.1);
  save_mesh(m_dir / "cube.stl", cube);
  EXPECT_EQ(fs::file_size(m_dir / "cube.stl"), 84u + 50u * cube.num_triangles());
  EXPECT_EQ(load_mesh(m_dir / "cube.stl").mesh.num_vertices(), 98u);
}

TEST_F(MeshIoTest, WeldingIsDeterministicAndDropsUnusedVertices) {
  // Vertex 4 is unused; the corners are renumbered in order of first use by the triangles.
  const std::string off =
      "OFF\n5 4 0\n"
      "0 0 0\n1 0 0\n0 1 0\n0 0 1\n7 7 7\n"
      "3 3 1 2\n3 2 1 0\n3 0 1 3\n3 0 3 2\n";
  const LoadedMesh loaded = load_mesh(write("unused.off", off));
  ASSERT_EQ(loaded.mesh.num_vertices(), 4u);
  EXPECT_EQ(loaded.mesh.vertices[0], sim::Vec3(0, 0, 1));
  EXPECT_EQ(loaded.mesh.vertices[1], sim::Vec3(1, 0, 0));
  EXPECT_EQ(loaded.mesh.vertices[2], sim::Vec3(0, 1, 0));
  EXPECT_EQ(loaded.mesh.vertices[3], sim::Vec3(0, 0, 0));
  EXPECT_EQ(loaded.mesh.triangles[0], (std::array<int32_t, 3>{0, 1, 2}));
  EXPECT_EQ(loaded.mesh.triangles[1], (std::array<int32_t, 3>{2, 1, 3}));
  EXPECT_TRUE(loaded.warnings.empty());
  const LoadedMesh again = load_mesh(m_dir / "unused.off");
  EXPECT_EQ(again.mesh.vertices, loaded.mesh.vertices);
  EXPECT_EQ(again.mesh.triangles, loaded.mesh.triangles);
}

TEST_F(MeshIoTest, ScaleMultipliesCoordinates) {
  save_mesh(m_dir / "oct.off", octahedron(2.0));
  MeshLoadOptions options;
  options.scale = 1e-3;
  const LoadedMesh loaded = load_mesh(m_dir / "oct.off", options);
  // Octahedron of radius 2 mm: volume 4 r^3 / 3.
  EXPECT_NEAR(sim::signed_volume(loaded.mesh), 4.0 / 3.0 * 8e-9, 1e-22);
  EXPECT_NEAR(sim::bounds(loaded.mesh).max.x(), 2e-3, 1e-18);
  options.scale = 0.0;
  EXPECT_TRUE(has(load_error(m_dir / "oct.off", options), "oct.off: scale must be finite and positive"));
}

/// Standard base64 with padding, for the inline glTF buffer.
std::string to_base64(const std::string& bytes) {
  static const char* alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned n = (unsigned char)bytes[i] << 16 | (unsigned char)bytes[i + 1] << 8 | (unsigned char)bytes[i + 2];
    for (int s = 18; s >= 0; s -= 6) out += alphabet[(n >> s) & 63];
  }
  if (i < bytes.size()) {
    unsigned n = (unsigned char)bytes[i] << 16;
    if (i + 1 < bytes.size()) n |= (unsigned char)bytes[i + 1] << 8;
    out += alphabet[(n >> 18) & 63];
    out += alphabet[(n >> 12) & 63];
    out += i + 1 < bytes.size() ? alphabet[(n >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

TEST_F(MeshIoTest, GltfNodesAreMergedWithTheirTransforms) {
  // One tetrahedron mesh (float32 positions, uint16 indices) instanced by three nodes: at the origin, at
  // (5, 0, 0) + a child's (0, 2, 0), and mirrored in x then moved to x = -3.
  const std::vector<float> positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  const std::vector<uint16_t> indices = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
  std::string buffer(reinterpret_cast<const char*>(positions.data()), positions.size() * 4);
  buffer.append(reinterpret_cast<const char*>(indices.data()), indices.size() * 2);
  const std::string gltf = R"({
  "asset": {"version": "2.0"},
  "scene": 0,
  "scenes": [{"nodes": [0, 1, 2]}],
  "nodes": [
    {"mesh": 0},
    {"translation": [5, 0, 0], "children": [3]},
    {"mesh": 0, "translation": [-3, 0, 0], "scale": [-1, 1, 1]},
    {"mesh": 0, "translation": [0, 2, 0]}
  ],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 4}]}],
  "buffers": [{"byteLength": 72, "uri": "data:application/octet-stream;base64,)" +
                           to_base64(buffer) + R"("}],
  "bufferViews": [
    {"buffer": 0, "byteOffset": 0, "byteLength": 48, "target": 34962},
    {"buffer": 0, "byteOffset": 48, "byteLength": 24, "target": 34963}
  ],
  "accessors": [
    {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 1]},
    {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"}
  ]
})";
  const LoadedMesh loaded = load_mesh(write("three.gltf", gltf));
  EXPECT_TRUE(loaded.warnings.empty());
  EXPECT_EQ(loaded.mesh.num_triangles(), 12u);
  // The mirrored instance keeps its outward orientation, so the volumes add up.
  EXPECT_NEAR(sim::signed_volume(loaded.mesh), 3.0 / 6.0, 1e-12);
  std::vector<sim::Vec3> expected;
  const std::vector<sim::Vec3> tetra = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (const sim::Vec3& p : tetra) expected.push_back(p);
  for (const sim::Vec3& p : tetra) expected.push_back(p + sim::Vec3(5, 2, 0));
  for (const sim::Vec3& p : tetra) expected.push_back(sim::Vec3(-p.x() - 3, p.y(), p.z()));
  expect_same_vertex_set(expected, loaded.mesh.vertices, 0.0);
}

// ---- validation: one error per defect class ------------------------------------------------------------------------

TEST_F(MeshIoTest, OpenMeshIsRejectedNamingAnEdgeAndTriangle) {
  sim::TriMesh mesh = octahedron();
  mesh.triangles.pop_back();
  save_mesh(m_dir / "open.off", mesh);
  const std::string message = load_error(m_dir / "open.off");
  EXPECT_TRUE(has(message, (m_dir / "open.off").string() + ": mesh is not closed: edge (")) << message;
  EXPECT_TRUE(has(message, "is used by no other triangle")) << message;
}

TEST_F(MeshIoTest, EdgeSharedByFourTrianglesIsNonManifold) {
  // Two tetrahedra that share only the edge (0, 1): that edge has four triangles, every other edge two.
  const std::string off =
      "OFF\n6 8 0\n"
      "0 0 0\n1 0 0\n0.5 1 0.2\n0.5 0.3 1\n0.5 -1 0.2\n0.5 -0.3 -1\n"
      "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"
      "3 0 1 4\n3 0 5 1\n3 0 4 5\n3 1 5 4\n";
  const std::string message = load_error(write("bowtie_edge.off", off));
  EXPECT_TRUE(has(message, "bowtie_edge.off: mesh is not manifold: edge (")) << message;
  EXPECT_TRUE(has(message, "is shared by 4 triangles")) << message;
}

TEST_F(MeshIoTest, InvertedMeshIsReorientedWithAWarning) {
  sim::TriMesh mesh = octahedron(0.5);
  for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
  ASSERT_LT(sim::signed_volume(mesh), 0.0);
  save_mesh(m_dir / "inverted.ply", mesh);
  const LoadedMesh loaded = load_mesh(m_dir / "inverted.ply");
  ASSERT_EQ(loaded.warnings.size(), 1u);
  EXPECT_TRUE(has(loaded.warnings[0], "inverted.ply: reoriented a consistently inverted mesh")) << loaded.warnings[0];
  EXPECT_NEAR(sim::signed_volume(loaded.mesh), 4.0 / 3.0 * 0.125, 1e-7);
}

TEST_F(MeshIoTest, InconsistentOrientationIsRejected) {
  sim::TriMesh mesh = octahedron();
  std::swap(mesh.triangles[0][1], mesh.triangles[0][2]);
  save_mesh(m_dir / "flipped_one.off", mesh);
  const std::string message = load_error(m_dir / "flipped_one.off");
  EXPECT_TRUE(has(message, "flipped_one.off: mesh is not consistently oriented: edge (")) << message;
  EXPECT_TRUE(has(message, "triangles 0 and")) << message;
}

TEST_F(MeshIoTest, NanCoordinateIsRejectedNamingTheVertex) {
  // Welding numbers the first triangle's corners 0, 1, 2, so its third corner becomes vertex 2.
  sim::TriMesh mesh = octahedron();
  mesh.vertices[static_cast<std::size_t>(mesh.triangles[0][2])].y() = std::numeric_limits<double>::quiet_NaN();
  save_mesh(m_dir / "nan.ply", mesh);
  const std::string message = load_error(m_dir / "nan.ply");
  EXPECT_TRUE(has(message, "nan.ply: vertex 2 has a non-finite coordinate")) << message;
}

TEST_F(MeshIoTest, DegenerateTrianglesAreRejectedNamingTheTriangle) {
  // A zero-area triangle: its third corner is the midpoint of the other two. It is triangle 8 after the octahedron's.
  const std::string off =
      "OFF\n7 9 0\n"
      "1 0 0\n0 1 0\n0 0 1\n-1 0 0\n0 -1 0\n0 0 -1\n0.5 0.5 0\n"
      "3 0 1 2\n3 1 3 2\n3 3 4 2\n3 4 0 2\n3 1 0 5\n3 3 1 5\n3 4 3 5\n3 0 4 5\n3 0 1 6\n";
  const std::string message = load_error(write("sliver.off", off));
  EXPECT_TRUE(has(message, "sliver.off: degenerate triangle 8 (vertices 0, 1, 6): zero area")) << message;

  // A repeated vertex index, through the public validator.
  sim::TriMesh mesh = octahedron();
  mesh.triangles[4] = {mesh.triangles[4][0], mesh.triangles[4][1], mesh.triangles[4][0]};
  try {
    (void)validate_mesh(mesh, "memory", false);
    FAIL() << "no error";
  } catch (const MeshError& error) {
    EXPECT_TRUE(has(error.what(), "memory: degenerate triangle 4")) << error.what();
    EXPECT_TRUE(has(error.what(), "a vertex is repeated")) << error.what();
  }
}

TEST_F(MeshIoTest, ZeroVolumeIsRejected) {
  // Two triangles back to back: closed, manifold and oriented, but flat.
  const std::string off = "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n";
  const std::string message = load_error(write("flat.off", off));
  EXPECT_TRUE(has(message, "flat.off: mesh encloses zero volume")) << message;
}

TEST_F(MeshIoTest, SelfIntersectingMeshIsRejectedNamingTwoTriangles) {
  // Two interpenetrating boxes in one file.
  const sim::TriMesh a = grid_cube(1);
  const sim::TriMesh two = test::merged(a, grid_cube(1, 1.0, sim::Vec3(0.5, 0.37, 0.21)));
  save_mesh(m_dir / "overlap.off", two);
  const std::string message = load_error(m_dir / "overlap.off");
  EXPECT_TRUE(has(message, "overlap.off: mesh self-intersects: triangle ")) << message;
  EXPECT_TRUE(has(message, " intersect")) << message;
  // The same file loads when the (costly) self-intersection check is switched off.
  MeshLoadOptions options;
  options.self_intersections = false;
  EXPECT_EQ(load_mesh(m_dir / "overlap.off", options).mesh.num_triangles(), 24u);
}

TEST_F(MeshIoTest, MissingEmptyAndGarbageFilesAreClearErrors) {
  EXPECT_TRUE(has(load_error(m_dir / "missing.obj"), "missing.obj: cannot read: no such file"));
  EXPECT_TRUE(has(load_error(write("empty.stl", "")), "empty.stl: empty file"));

  // Random bytes under a mesh extension and under none.
  std::mt19937 random(7);
  std::string garbage(4096, '\0');
  for (char& c : garbage) c = static_cast<char>(random() & 0xFF);
  for (const std::string name :
       {"garbage.ply", "garbage.glb", "garbage.gltf", "garbage.stl", "garbage.obj", "garbage.off"}) {
    const std::string message = load_error(write(name, garbage));
    EXPECT_TRUE(has(message, name + ": cannot read mesh (unknown format or corrupt file): ")) << message;
  }
  EXPECT_TRUE(has(load_error(write("garbage.bin", garbage)), "garbage.bin: unsupported mesh format '.bin'"));
}

TEST_F(MeshIoTest, IndicesThatTheImporterWouldRepairAreErrors) {
  // assimp's OFF reader clamps an out-of-range index to the last vertex (which here would still make a closed
  // tetrahedron) and drops a face without indices; OBJ's reader rejects a bad index itself. Each is a malformed
  // file, never a different mesh.
  const std::string out_of_range = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 99\n";
  std::string message = load_error(write("clamped.off", out_of_range));
  EXPECT_TRUE(has(message, "clamped.off: ")) << message;
  EXPECT_TRUE(has(message, "out of range")) << message;
  const std::string zero_face = std::string(kTetraOff).substr(0, std::string(kTetraOff).size() - 8) + "0\n";
  message = load_error(write("zero.off", zero_face));
  EXPECT_TRUE(has(message, "zero.off: ")) << message;
  const std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 9\n";
  message = load_error(write("bad.obj", obj));
  EXPECT_TRUE(has(message, "bad.obj: ")) << message;
  // A missing material library changes nothing in the geometry: the mesh loads.
  const std::string with_mtl = "mtllib missing.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
  EXPECT_NEAR(sim::signed_volume(load_mesh(write("mtl.obj", with_mtl)).mesh), 1.0 / 6.0, 1e-15);
}

TEST_F(MeshIoTest, FileWithoutTrianglesIsAnError) {
  const std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nl 2 3\n";
  const std::string message = load_error(write("lines.obj", obj));
  EXPECT_TRUE(has(message, "lines.obj: ")) << message;
  EXPECT_TRUE(has(message, "no triangles")) << message;
}

TEST(MeshValidation, TwoTetrahedraSharingOneVertexAreRejectedAsPinched) {
  // Vertex 0 is the apex of both: each edge is used twice, but the triangles around vertex 0 form two fans.
  sim::TriMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {-1, 0, 0}, {0, -1, 0}, {0, 0, -1}};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}, {0, 4, 5}, {0, 6, 4}, {0, 5, 6}, {4, 6, 5}};
  try {
    (void)validate_mesh(mesh, "pinched", false);
    FAIL() << "no error";
  } catch (const MeshError& error) {
    EXPECT_TRUE(has(error.what(), "pinched: mesh is not manifold at vertex 0: its triangles form 2 separate fans"))
        << error.what();
  }
}

}  // namespace
}  // namespace octocut::engine
