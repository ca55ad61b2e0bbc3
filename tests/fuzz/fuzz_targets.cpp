#include "fuzz/fuzz_targets.hpp"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "io/mesh_ply.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"

namespace octocut::fuzz {

namespace fs = std::filesystem;

namespace {

// A per-process scratch folder for the files the loaders read.
const fs::path& scratch() {
  static const fs::path dir = [] {
    fs::path d = fs::temp_directory_path() / ("octocut_fuzz_" + std::to_string(::getpid()));
    fs::create_directories(d);
    return d;
  }();
  return dir;
}

fs::path write(const std::string& name, const std::uint8_t* data, std::size_t size) {
  const fs::path file = scratch() / name;
  std::ofstream(file, std::ios::binary).write(reinterpret_cast<const char*>(data), std::streamsize(size));
  return file;
}

[[noreturn]] void finding(const std::string& what) {
  std::fprintf(stderr, "octocut fuzz finding: %s\n", what.c_str());
  std::abort();
}

// The box the cut sequences work on, and three tools: a 32-gon of 2 mm, a square prism of 1 mm, a triangle of 0.5 mm.
constexpr const char* kCutScene = R"({
  "name": "fuzz cuts", "duration": 1.0,
  "solver": {"dt": 0.001, "threads": 1},
  "object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}},
             "material": {"young_modulus": 5e4, "poisson_ratio": 0.45},
             "octree": {"root": {"min": [-0.001, -0.001, -0.001], "size": 0.012}, "base_level": 3, "max_level": 5},
             "material_graph": {"cell_size": 0.001},
             "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 0.0005]}}]},
  "tools": [
    {"name": "p2", "blade": {"cylinder": {"radius": 0.002, "height": 0.03, "segments": 32}}, "keyframes": [{"t": 0, "position": [0.05, 0.05, 0.05]}]},
    {"name": "p1", "blade": {"cylinder": {"radius": 0.001, "height": 0.03, "segments": 4}}, "keyframes": [{"t": 0, "position": [0.05, 0.05, 0.05]}]},
    {"name": "p05", "blade": {"cylinder": {"radius": 0.0005, "height": 0.03, "segments": 3}}, "keyframes": [{"t": 0, "position": [0.05, 0.05, 0.05]}]}
  ]
})";

}  // namespace

int scene(const std::uint8_t* data, std::size_t size) {
  const fs::path file = write("scene.json", data, size);
  try {
    (void)engine::load_scene(file.string());
  } catch (const engine::SceneError&) {
    // Bad input, reported: what the loader must do.
  }
  return 0;
}

int ply(const std::uint8_t* data, std::size_t size) {
  try {
    (void)engine::decode_ply(std::string(reinterpret_cast<const char*>(data), size), "fuzz.ply");
  } catch (const engine::MeshError&) {
  }
  return 0;
}

int mesh(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  static const char* kExtensions[] = {".obj", ".stl", ".off", ".ply", ".gltf"};
  const fs::path file = write(std::string("mesh") + kExtensions[data[0] % 5], data + 1, size - 1);
  try {
    (void)engine::load_mesh(file, engine::MeshLoadOptions{1.0, true, true});
  } catch (const engine::MeshError&) {
  }
  return 0;
}

int cuts(const std::uint8_t* data, std::size_t size) {
  (void)cut_skips(data, size);
  return 0;
}

int cut_skips(const std::uint8_t* data, std::size_t size) {
  int skipped = 0;
  static const fs::path file = [] {
    const fs::path f = scratch() / "cuts.json";
    std::ofstream(f) << kCutScene;
    return f;
  }();
  engine::World world(engine::load_scene(file.string()), engine::WorldOptions{.render = false, .cuttable = true});
  const double cell = 0.01 / 32.0;  // positions on a 1/32 grid of the box: walls land on walls, edges and vertices
  for (std::size_t i = 0; i + 6 <= size && i < 6 * 8; i += 6) {
    const std::uint8_t* b = data + i;
    const std::size_t tool = b[0] % 3;
    sim::Pose pose;
    pose.position = sim::Vec3((b[1] % 33) * cell, (b[2] % 33) * cell, (b[3] % 33) * cell);
    // Axis tilts in steps of 45 degrees, roll in steps of 15: coplanar and coincident walls come up often.
    const double tilt = (b[4] % 8) * 45.0, roll = (b[5] % 24) * 15.0;
    pose.rotation = (Eigen::AngleAxisd(tilt * M_PI / 180.0, (b[4] & 8) ? sim::Vec3::UnitX() : sim::Vec3::UnitY()) *
                     Eigen::AngleAxisd(roll * M_PI / 180.0, sim::Vec3::UnitZ()))
                        .toRotationMatrix();
    world.set_tool_pose(tool, pose);
    const engine::CutSummary c = world.cut_now(tool);
    if (std::getenv("OCTOCUT_FUZZ_VERBOSE")) std::fprintf(stderr, "cut %zu: %s %s\n", i / 6, c.status.c_str(), c.reason.c_str());
    if (c.status == "skipped") ++skipped;
    if (b[0] & 0x80) world.step();
    const engine::Report r = world.report();
    if (!r.finite) finding("the state is not finite after cut " + std::to_string(i / 6));
    if (!r.object_removed && !r.surface_closed)
      finding("S is not closed, manifold and oriented after cut " + std::to_string(i / 6) + " (" + c.status + ")");
  }
  return skipped;
}

Target target(const std::string& name) {
  if (name == "scene") return scene;
  if (name == "ply") return ply;
  if (name == "mesh") return mesh;
  if (name == "cuts") return cuts;
  return nullptr;
}

}  // namespace octocut::fuzz
