// Tests for the scene loader: defaults, every class of bad input with its exact message, overrides, and the
// generated documentation staying in sync with the schema.
#include "octocut/engine/scene/scene_loader.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "octocut/engine/io/io.hpp"
#include "common/temp_dir.hpp"

namespace octocut::engine {
namespace {

namespace fs = std::filesystem;

/// The smallest valid scene: a 1 cm box and nothing else.
constexpr const char* k_minimal_scene =
    R"({"object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}}}})";

/// Gives each test a fresh directory for its scene files, removed afterwards.
class SceneLoaderTest : public octocut::test::TempDirTest {
 protected:

  /// Writes `text` to `name` inside the test directory and returns the file's path.
  std::string write(const std::string& name, const std::string& text) const {
    const fs::path path = m_dir / name;
    fs::create_directories(path.parent_path());
    std::ofstream(path, std::ios::binary) << text;
    return path.string();
  }

  /// Writes a scene whose `object` is the minimal box plus `object_extra` (JSON members, may be empty) and whose
  /// top level also holds `top_extra`.
  std::string write_scene(const std::string& top_extra, const std::string& object_extra = "") const {
    std::string text = R"({"object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}})";
    if (!object_extra.empty()) text += ", " + object_extra;
    text += "}";
    if (!top_extra.empty()) text += ", " + top_extra;
    return write("scene.json", text + "}");
  }

  /// The message of the SceneError that loading `path` throws, or "(no error)".
  static std::string error_of(const std::string& path, const std::vector<std::string>& overrides = {}) {
    try {
      load_scene(path, overrides);
    } catch (const SceneError& error) {
      return error.what();
    }
    return "(no error)";
  }

};

// ---- valid scenes ---------------------------------------------------------------------------------------------------

TEST_F(SceneLoaderTest, MinimalSceneGetsEveryDefault) {
  const std::string path = write("minimal.json", k_minimal_scene);
  const Scene scene = load_scene(path);
  const Scene defaults;

  // Top level: the name is the file stem.
  EXPECT_EQ(scene.file, path);
  EXPECT_EQ(scene.name, "minimal");
  EXPECT_EQ(scene.duration, defaults.duration);
  EXPECT_EQ(scene.seed, defaults.seed);

  // Solver: the schema's defaults agree with the struct's.
  EXPECT_EQ(scene.solver.mode, defaults.solver.mode);
  EXPECT_EQ(scene.solver.dt, defaults.solver.dt);
  EXPECT_EQ(scene.solver.gravity, defaults.solver.gravity);
  EXPECT_EQ(scene.solver.linear_solver, defaults.solver.linear_solver);
  EXPECT_EQ(scene.solver.tolerance, defaults.solver.tolerance);
  EXPECT_EQ(scene.solver.max_iterations, defaults.solver.max_iterations);
  EXPECT_EQ(scene.solver.threads, defaults.solver.threads);
  EXPECT_EQ(scene.solver.max_speed, defaults.solver.max_speed);

  // Object.
  const ObjectSettings& object = scene.object;
  EXPECT_TRUE(object.surface_is_box);
  EXPECT_EQ(object.surface_box.min, (std::array<double, 3>{0, 0, 0}));
  EXPECT_EQ(object.surface_box.max, (std::array<double, 3>{0.01, 0.01, 0.01}));
  EXPECT_TRUE(object.surface_path.empty());
  EXPECT_EQ(object.scale, defaults.object.scale);
  EXPECT_EQ(object.material.young_modulus, defaults.object.material.young_modulus);
  EXPECT_EQ(object.material.poisson_ratio, defaults.object.material.poisson_ratio);
  EXPECT_EQ(object.material.density, defaults.object.material.density);
  EXPECT_EQ(object.material.rayleigh_mass, defaults.object.material.rayleigh_mass);
  EXPECT_EQ(object.material.rayleigh_stiffness, defaults.object.material.rayleigh_stiffness);
  EXPECT_FALSE(object.octree.has_root);
  EXPECT_EQ(object.octree.base_level, defaults.object.octree.base_level);
  EXPECT_EQ(object.octree.max_level, defaults.object.octree.max_level);
  EXPECT_EQ(object.octree.uniform, defaults.object.octree.uniform);
  EXPECT_TRUE(object.octree.refine.empty());
  EXPECT_EQ(object.material_graph_cell_size, defaults.object.material_graph_cell_size);
  EXPECT_TRUE(object.handles.empty());

  // The rest.
  EXPECT_TRUE(scene.probes.empty());
  EXPECT_EQ(scene.render.enabled, defaults.render.enabled);
  EXPECT_EQ(scene.output.frames, defaults.output.frames);
  EXPECT_EQ(scene.output.surface_final, defaults.output.surface_final);
  EXPECT_EQ(scene.output.surface_every, defaults.output.surface_every);
}

TEST_F(SceneLoaderTest, FullSceneIsReadIntoEveryField) {
  write("meshes/liver.obj", "v 0 0 0\n");
  const std::string path = write("scenes/full.json", R"({
    "name": "full", "duration": 2.5, "seed": 42,
    "solver": {"mode": "static", "dt": 0.01, "gravity": [0, -9.81, 0], "linear_solver": "cholmod",
               "tolerance": 1e-8, "max_iterations": 50, "threads": 2, "max_speed": 10},
    "object": {
      "surface": "../meshes/liver.obj", "scale": 0.001,
      "material": {"young_modulus": 3e4, "poisson_ratio": 0.45, "density": 1060, "rayleigh_mass": 0.1,
                   "rayleigh_stiffness": 0.01},
      "octree": {"root": {"min": [-1, -1, -1], "size": 2}, "base_level": 2, "max_level": 6, "uniform": true,
                 "refine": [{"box": {"min": [0, 0, 0], "max": [1, 1, 1]}, "level": 5}]},
      "material_graph": {"cell_size": 0.002},
      "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, -0.9]}},
                  {"box": {"min": [-1, -1, 0.9], "max": [1, 1, 1]},
                   "keyframes": [{"t": 0}, {"t": 1, "translation": [0, 0, 0.01], "rotation_deg": [0, 0, 90]}]}]
    },
    "probes": [{"name": "tip", "point": [0, 0, 1]}],
    "render": {"enabled": true},
    "output": {"frames": true, "surface_final": true, "surface_every": 10}
  })");
  const Scene scene = load_scene(path);

  // Top level and solver.
  EXPECT_EQ(scene.name, "full");
  EXPECT_EQ(scene.duration, 2.5);
  EXPECT_EQ(scene.seed, 42u);
  EXPECT_EQ(scene.solver.mode, "static");
  EXPECT_EQ(scene.solver.dt, 0.01);
  EXPECT_EQ(scene.solver.gravity, (std::array<double, 3>{0, -9.81, 0}));
  EXPECT_EQ(scene.solver.linear_solver, "cholmod");
  EXPECT_EQ(scene.solver.tolerance, 1e-8);
  EXPECT_EQ(scene.solver.max_iterations, 50);
  EXPECT_EQ(scene.solver.threads, 2);
  EXPECT_EQ(scene.solver.max_speed, 10.0);

  // Object: the mesh path is resolved against the scene file's directory.
  const ObjectSettings& object = scene.object;
  EXPECT_FALSE(object.surface_is_box);
  EXPECT_EQ(object.surface_path, (m_dir / "meshes" / "liver.obj").string());
  EXPECT_EQ(object.scale, 0.001);
  EXPECT_EQ(object.material.young_modulus, 3e4);
  EXPECT_EQ(object.material.poisson_ratio, 0.45);
  EXPECT_EQ(object.material.density, 1060.0);
  EXPECT_EQ(object.material.rayleigh_mass, 0.1);
  EXPECT_EQ(object.material.rayleigh_stiffness, 0.01);
  EXPECT_TRUE(object.octree.has_root);
  EXPECT_EQ(object.octree.root_min, (std::array<double, 3>{-1, -1, -1}));
  EXPECT_EQ(object.octree.root_size, 2.0);
  EXPECT_EQ(object.octree.base_level, 2);
  EXPECT_EQ(object.octree.max_level, 6);
  EXPECT_TRUE(object.octree.uniform);
  ASSERT_EQ(object.octree.refine.size(), 1u);
  EXPECT_EQ(object.octree.refine[0].box.max, (std::array<double, 3>{1, 1, 1}));
  EXPECT_EQ(object.octree.refine[0].level, 5);
  EXPECT_EQ(object.material_graph_cell_size, 0.002);

  // Handles: keyframe defaults are filled per item.
  ASSERT_EQ(object.handles.size(), 2u);
  EXPECT_TRUE(object.handles[0].keyframes.empty());
  EXPECT_EQ(object.handles[0].box.max, (std::array<double, 3>{1, 1, -0.9}));
  ASSERT_EQ(object.handles[1].keyframes.size(), 2u);
  EXPECT_EQ(object.handles[1].keyframes[0].t, 0.0);
  EXPECT_EQ(object.handles[1].keyframes[0].translation, (std::array<double, 3>{0, 0, 0}));
  EXPECT_EQ(object.handles[1].keyframes[1].t, 1.0);
  EXPECT_EQ(object.handles[1].keyframes[1].translation, (std::array<double, 3>{0, 0, 0.01}));
  EXPECT_EQ(object.handles[1].keyframes[1].rotation_deg, (std::array<double, 3>{0, 0, 90}));

  // Probes, render, output.
  ASSERT_EQ(scene.probes.size(), 1u);
  EXPECT_EQ(scene.probes[0].name, "tip");
  EXPECT_EQ(scene.probes[0].point, (std::array<double, 3>{0, 0, 1}));
  EXPECT_TRUE(scene.render.enabled);
  EXPECT_TRUE(scene.output.frames);
  EXPECT_TRUE(scene.output.surface_final);
  EXPECT_EQ(scene.output.surface_every, 10);
}

TEST_F(SceneLoaderTest, IntegralFloatIsAcceptedForInteger) {
  const std::string path = write_scene(R"("solver": {"max_iterations": 1e3}, "seed": 7.0)");
  const Scene scene = load_scene(path);
  EXPECT_EQ(scene.solver.max_iterations, 1000);
  EXPECT_EQ(scene.seed, 7u);
}

// ---- malformed files ------------------------------------------------------------------------------------------------

TEST_F(SceneLoaderTest, MissingSceneFile) {
  const std::string path = (m_dir / "nowhere.json").string();
  EXPECT_EQ(error_of(path), path + ": cannot read: No such file or directory");
}

TEST_F(SceneLoaderTest, MalformedJsonNamesLineAndColumn) {
  // A trailing comma: the '}' on line 3, column 3 is where a key was expected.
  const std::string path = write("bad.json", "{\n  \"duration\": 1,\n  }\n");
  EXPECT_EQ(error_of(path),
            path +
                ":3:3: malformed JSON: syntax error while parsing object key - unexpected '}'; expected string "
                "literal");
}

TEST_F(SceneLoaderTest, MalformedJsonAtEndOfInput) {
  const std::string path = write("truncated.json", "{\"object\": {\n");
  EXPECT_EQ(error_of(path),
            path +
                ":2:1: malformed JSON: syntax error while parsing object key - unexpected end of input; expected "
                "string literal");
}

TEST_F(SceneLoaderTest, NumberOverflowInFileIsMalformedJsonWithPosition) {
  const std::string path = write("huge.json", "{\n  \"duration\": 1e999\n}\n");
  EXPECT_EQ(error_of(path), path + ":2:15: malformed JSON: number overflow parsing '1e999'");
}

TEST_F(SceneLoaderTest, DuplicateKey) {
  const std::string path = write_scene(R"("solver": {"dt": 0.1, "gravity": [0, 0, 0], "dt": 0.2})");
  EXPECT_EQ(error_of(path), path + ": /solver/dt: duplicate key");
}

TEST_F(SceneLoaderTest, DocumentMustBeAnObject) {
  const std::string path = write("array.json", "[1, 2]");
  EXPECT_EQ(error_of(path), path + ": expected a JSON object, got array");
}

// ---- schema violations ----------------------------------------------------------------------------------------------

TEST_F(SceneLoaderTest, UnknownKeyAtTopLevel) {
  const std::string path = write_scene(R"("durration": 2)");
  EXPECT_EQ(error_of(path), path + ": /durration: unknown key");
}

TEST_F(SceneLoaderTest, UnknownKeyNested) {
  const std::string path = write_scene("", R"("materail": {"density": 1000})");
  EXPECT_EQ(error_of(path), path + ": /object/materail: unknown key");
}

TEST_F(SceneLoaderTest, UnknownKeyInsideArrayItem) {
  const std::string path = write_scene("", R"("handles": [{"box": {"min": [0, 0, 0], "max": [1, 1, 1]},
                          "keyframes": [{"t": 0}, {"t": 1, "translaton": [0, 0, 1]}]}])");
  EXPECT_EQ(error_of(path), path + ": /object/handles/0/keyframes/1/translaton: unknown key");
}

TEST_F(SceneLoaderTest, UnknownKeyInsideSurfaceObject) {
  const std::string path = write("scene.json", R"({"object": {"surface": {"sphere": {"radius": 1}}}})");
  EXPECT_EQ(error_of(path), path + ": /object/surface/sphere: unknown key");
}

TEST_F(SceneLoaderTest, UnknownKeyWithPointerEscapes) {
  const std::string path = write_scene(R"("a/b~c": 1)");
  EXPECT_EQ(error_of(path), path + ": /a~1b~0c: unknown key");
}

TEST_F(SceneLoaderTest, WrongTypes) {
  EXPECT_EQ(error_of(write_scene(R"("solver": {"dt": "fast"})")),
            (m_dir / "scene.json").string() + ": /solver/dt: expected a number, got string");
  const std::string path = (m_dir / "scene.json").string();
  EXPECT_EQ(error_of(write_scene(R"("render": {"enabled": 1})")),
            path + ": /render/enabled: expected a boolean, got number");
  EXPECT_EQ(error_of(write_scene(R"("name": null)")), path + ": /name: expected a string, got null");
  EXPECT_EQ(error_of(write_scene(R"("solver": {"max_iterations": 1.5})")),
            path + ": /solver/max_iterations: expected an integer, got 1.5");
  EXPECT_EQ(error_of(write_scene(R"("solver": {"mode": "quasi"})")),
            path + R"(: /solver/mode: must be one of "dynamic", "static", got "quasi")");
  EXPECT_EQ(error_of(write_scene(R"("solver": [])")), path + ": /solver: expected an object, got array");
  EXPECT_EQ(error_of(write_scene(R"("probes": {})")), path + ": /probes: expected an array of objects, got object");
  EXPECT_EQ(error_of(write_scene(R"("probes": [3])")), path + ": /probes/0: expected an object, got number");
  EXPECT_EQ(error_of(write_scene(R"("solver": {"gravity": [0, "down", 0]})")),
            path + ": /solver/gravity/1: expected a number, got string");
  EXPECT_EQ(error_of(write("scene.json", R"({"object": {"surface": 5}})")),
            path + ": /object/surface: expected a mesh path (string) or an object, got number");
}

TEST_F(SceneLoaderTest, OutOfRange) {
  const std::string path = (m_dir / "scene.json").string();
  EXPECT_EQ(error_of(write_scene(R"("solver": {"dt": -1})")), path + ": /solver/dt: must be > 0, got -1");
  EXPECT_EQ(error_of(write_scene(R"("solver": {"dt": 1.5})")), path + ": /solver/dt: must be <= 1, got 1.5");
  EXPECT_EQ(error_of(write_scene(R"("solver": {"threads": 300})")),
            path + ": /solver/threads: must be <= 256, got 300");
  EXPECT_EQ(error_of(write_scene(R"("seed": -3)")), path + ": /seed: must be >= 0, got -3");
  EXPECT_EQ(error_of(write_scene("", R"("material": {"poisson_ratio": 0.5})")),
            path + ": /object/material/poisson_ratio: must be < 0.5, got 0.5");
  EXPECT_EQ(error_of(write_scene("", R"("material": {"young_modulus": 2e12})")),
            path + ": /object/material/young_modulus: must be <= 1e+12, got 2e+12");
  EXPECT_EQ(error_of(write_scene("", R"("octree": {"base_level": 21})")),
            path + ": /object/octree/base_level: must be <= 20, got 21");
}

// Physical parameters far outside what any tissue, instrument or planet has: a clear error at load, not a run in which
// every step fails or a static solve returns displacements of 1e300 m.
TEST_F(SceneLoaderTest, PhysicalParametersOutOfRange) {
  const std::string path = (m_dir / "scene.json").string();
  struct Case {
    const char* top;     // keys beside "object"
    const char* object;  // keys of "object" beside "surface"
    const char* error;   // after the path
  };
  const Case cases[] = {
      {"", R"("material": {"young_modulus": 1e-300})", ": /object/material/young_modulus: must be >= 1, got 1e-300"},
      {"", R"("material": {"density": 1e300})", ": /object/material/density: must be <= 100000, got 1e+300"},
      {"", R"("material": {"rayleigh_mass": 1e7})", ": /object/material/rayleigh_mass: must be <= 1e+06, got 1e+07"},
      {"", R"("material": {"rayleigh_stiffness": 11})", ": /object/material/rayleigh_stiffness: must be <= 10, got 11"},
      {R"("solver": {"gravity": [0, 0, -2147483648]})", "", ": /solver/gravity/2: must be >= -10000, got -2147483648"},
      {R"("contact": {"friction": 1e300})", "", ": /contact/friction: must be <= 10, got 1e+300"},
      {R"("contact": {"damping": 2})", "", ": /contact/damping: must be <= 1, got 2"},
  };
  for (const Case& c : cases) EXPECT_EQ(error_of(write_scene(c.top, c.object)), path + c.error);
}

TEST_F(SceneLoaderTest, NonFiniteNumberFromOverride) {
  const std::string path = write("scene.json", k_minimal_scene);
  EXPECT_EQ(error_of(path, {"/solver/dt=1e999"}), path + ": /solver/dt: must be a finite number, got inf");
  EXPECT_EQ(error_of(path, {"/solver/gravity=[0, -1e999, 0]"}),
            "override \"/solver/gravity=[0, -1e999, 0]\": number overflow parsing '-1e999'");
  EXPECT_EQ(error_of(path, {"/solver/gravity/2=-1e999"}),
            path + ": /solver/gravity/2: must be a finite number, got -inf");
  EXPECT_EQ(error_of(path, {"/solver/max_iterations=1e999"}),
            path + ": /solver/max_iterations: must be a finite number, got inf");
}

TEST_F(SceneLoaderTest, MissingRequiredKeys) {
  const std::string path = (m_dir / "scene.json").string();
  EXPECT_EQ(error_of(write("scene.json", "{}")), path + ": /object: required key missing");
  EXPECT_EQ(error_of(write("scene.json", R"({"object": {"scale": 2}})")),
            path + ": /object/surface: required key missing");
  EXPECT_EQ(error_of(write("scene.json", R"({"object": {"surface": {"box": {"min": [0, 0, 0]}}}})")),
            path + ": /object/surface/box/max: required key missing");
  EXPECT_EQ(error_of(write_scene(R"("probes": [{"point": [0, 0, 0]}])")),
            path + ": /probes/0/name: required key missing");
  EXPECT_EQ(error_of(write_scene("", R"("octree": {"root": {"min": [0, 0, 0]}})")),
            path + ": /object/octree/root/size: required key missing");
}

TEST_F(SceneLoaderTest, WrongArrayLength) {
  const std::string path = (m_dir / "scene.json").string();
  EXPECT_EQ(error_of(write_scene(R"("solver": {"gravity": [0, -9.81]})")),
            path + ": /solver/gravity: expected 3 numbers, got an array of 2");
  EXPECT_EQ(error_of(write_scene(R"("probes": [{"name": "p", "point": 1}])")),
            path + ": /probes/0/point: expected 3 numbers, got number");
}

TEST_F(SceneLoaderTest, MissingMeshFile) {
  const std::string path = write("scenes/mesh.json", R"({"object": {"surface": "../meshes/absent.stl"}})");
  EXPECT_EQ(error_of(path), path + ": /object/surface: file not found: " + (m_dir / "meshes/absent.stl").string());
}

// ---- rules across keys ----------------------------------------------------------------------------------------------

TEST_F(SceneLoaderTest, UnsortedKeyframes) {
  const std::string path = write_scene("", R"("handles": [{"box": {"min": [0, 0, 0], "max": [1, 1, 1]}},
                         {"box": {"min": [0, 0, 0], "max": [1, 1, 1]},
                          "keyframes": [{"t": 0}, {"t": 0.5}, {"t": 0.4}]}])");
  EXPECT_EQ(error_of(path),
            path + ": /object/handles/1/keyframes/2/t: must be > the previous keyframe's t (0.5), got 0.4");
}

TEST_F(SceneLoaderTest, EqualKeyframeTimesAreRejected) {
  const std::string path = write_scene(
      "", R"("handles": [{"box": {"min": [0, 0, 0], "max": [1, 1, 1]}, "keyframes": [{"t": 1}, {"t": 1}]}])");
  EXPECT_EQ(error_of(path), path + ": /object/handles/0/keyframes/1/t: must be > the previous keyframe's t (1), got 1");
}

TEST_F(SceneLoaderTest, OctreeLevelsMustNest) {
  const std::string path = (m_dir / "scene.json").string();
  EXPECT_EQ(error_of(write_scene("", R"("octree": {"base_level": 5, "max_level": 4})")),
            path + ": /object/octree/max_level: must be >= base_level (5), got 4");
  EXPECT_EQ(error_of(write_scene("", R"("octree": {"max_level": 6, "refine": [
                                          {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}, "level": 7}]})")),
            path + ": /object/octree/refine/0/level: must be <= max_level (6), got 7");
}

TEST_F(SceneLoaderTest, BoxMaxMustExceedMin) {
  const std::string path =
      write("scene.json", R"({"object": {"surface": {"box": {"min": [0, 0, 0.1], "max": [1, 1, 0]}}}})");
  EXPECT_EQ(error_of(path), path +
                                ": /object/surface/box/max: must be > min in every component, got max[2] = 0 <= "
                                "min[2] = 0.1");
}

TEST_F(SceneLoaderTest, ProbeNamesMustBeUnique) {
  const std::string path =
      write_scene(R"("probes": [{"name": "tip", "point": [0, 0, 0]}, {"name": "tip", "point": [1, 0, 0]}])");
  EXPECT_EQ(error_of(path), path + ": /probes/1/name: duplicate probe name \"tip\"");
}

// ---- tools, cutting, expected -------------------------------------------------------------------------------------

TEST_F(SceneLoaderTest, ToolsCuttingAndExpectedDefaults) {
  const Scene scene = load_scene(write_scene(R"("tools": [{"name": "punch",
      "blade": {"cylinder": {"radius": 0.001, "height": 0.01}}, "keyframes": [{"t": 0}]}])"));
  const Scene defaults;
  ASSERT_EQ(scene.tools.size(), 1u);
  const ToolSettings& tool = scene.tools[0];
  const ToolSettings tool_defaults;
  EXPECT_EQ(tool.name, "punch");
  EXPECT_TRUE(tool.mesh_path.empty());
  EXPECT_EQ(tool.scale, tool_defaults.scale);
  EXPECT_EQ(tool.scale, 1.0);
  EXPECT_TRUE(tool.blade_is_cylinder);
  EXPECT_EQ(tool.cylinder.radius, 0.001);
  EXPECT_EQ(tool.cylinder.height, 0.01);
  EXPECT_EQ(tool.cylinder.segments, CylinderBlade{}.segments);
  EXPECT_EQ(tool.cylinder.segments, 32);
  EXPECT_TRUE(tool.blade_path.empty());
  EXPECT_EQ(tool.collide, tool_defaults.collide);
  EXPECT_FALSE(tool.collide);
  ASSERT_EQ(tool.keyframes.size(), 1u);
  EXPECT_EQ(tool.keyframes[0].t, 0.0);
  EXPECT_EQ(tool.keyframes[0].position, (std::array<double, 3>{0, 0, 0}));
  EXPECT_EQ(tool.keyframes[0].rotation_deg, (std::array<double, 3>{0, 0, 0}));
  EXPECT_TRUE(tool.cuts.empty());
  // The schema's defaults agree with the struct's.
  EXPECT_EQ(scene.cutting.remove_fragments, defaults.cutting.remove_fragments);
  EXPECT_EQ(scene.cutting.remove_fragments, "all");
  EXPECT_EQ(scene.cutting.fragment_volume, defaults.cutting.fragment_volume);
  EXPECT_EQ(scene.cutting.fragment_volume, 1e-9);
  EXPECT_EQ(scene.cutting.verify, defaults.cutting.verify);
  EXPECT_TRUE(scene.cutting.verify);
  EXPECT_TRUE(scene.expected_json.empty());
  EXPECT_TRUE(load_scene(write("minimal.json", k_minimal_scene)).tools.empty());
}

TEST_F(SceneLoaderTest, ToolsCuttingAndExpectedAreReadIntoEveryField) {
  write("meshes/blade.stl", "solid x\nendsolid x\n");
  write("meshes/punch.obj", "v 0 0 0\n");
  const std::string path = write("scenes/tools.json", R"({
    "duration": 2,
    "object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}}},
    "tools": [
      {"name": "punch", "mesh": "../meshes/punch.obj", "scale": 0.001, "blade": "../meshes/blade.stl",
       "collide": true,
       "keyframes": [{"t": 0, "position": [0.1, 0.2, 0.3], "rotation_deg": [10, 20, 30]}, {"t": 1.5}],
       "cuts": [{"t": 0}, {"t": 0.5}, {"t": 2}]},
      {"name": "probe", "blade": {"cylinder": {"radius": 0.002, "height": 0.03, "segments": 1024}},
       "keyframes": [{"t": 0.25}]}
    ],
    "cutting": {"remove_fragments": "small", "fragment_volume": 2e-9, "verify": false},
    "render": {"camera": {"follow_tool": "probe"}},
    "expected": {"/status": "ok", "/counts/elements": {"min": 700, "max": 800},
                 "/cuts/0/removed_volume_m3": {"value": 1e-7, "rel": 0.05, "abs": 1e-9}, "/steps": 10,
                 "/stability/finite": true, "/a~1b": {"max": 1}}
  })");
  const Scene scene = load_scene(path);
  ASSERT_EQ(scene.tools.size(), 2u);
  const ToolSettings& punch = scene.tools[0];
  EXPECT_EQ(punch.name, "punch");
  EXPECT_EQ(punch.mesh_path, (m_dir / "meshes" / "punch.obj").string());
  EXPECT_EQ(punch.scale, 0.001);
  EXPECT_FALSE(punch.blade_is_cylinder);
  EXPECT_EQ(punch.blade_path, (m_dir / "meshes" / "blade.stl").string());
  EXPECT_TRUE(punch.collide);
  ASSERT_EQ(punch.keyframes.size(), 2u);
  EXPECT_EQ(punch.keyframes[0].position, (std::array<double, 3>{0.1, 0.2, 0.3}));
  EXPECT_EQ(punch.keyframes[0].rotation_deg, (std::array<double, 3>{10, 20, 30}));
  EXPECT_EQ(punch.keyframes[1].t, 1.5);
  ASSERT_EQ(punch.cuts.size(), 3u);
  EXPECT_EQ(punch.cuts[1].t, 0.5);
  EXPECT_EQ(punch.cuts[2].t, 2.0);
  const ToolSettings& probe = scene.tools[1];
  EXPECT_TRUE(probe.blade_is_cylinder);
  EXPECT_EQ(probe.cylinder.radius, 0.002);
  EXPECT_EQ(probe.cylinder.height, 0.03);
  EXPECT_EQ(probe.cylinder.segments, 1024);
  EXPECT_EQ(probe.keyframes[0].t, 0.25);
  EXPECT_EQ(scene.cutting.remove_fragments, "small");
  EXPECT_EQ(scene.cutting.fragment_volume, 2e-9);
  EXPECT_FALSE(scene.cutting.verify);
  EXPECT_EQ(scene.render.camera.follow_tool, "probe");
  // The block is kept as compact JSON text with its keys sorted.
  EXPECT_EQ(scene.expected_json,
            R"({"/a~1b":{"max":1},"/counts/elements":{"max":800,"min":700},)"
            R"("/cuts/0/removed_volume_m3":{"abs":1e-09,"rel":0.05,"value":1e-07},"/stability/finite":true,)"
            R"("/status":"ok","/steps":10})");
}

TEST_F(SceneLoaderTest, ToolErrorsNameThePointer) {
  const std::string path = (m_dir / "scene.json").string();
  const std::string cylinder = R"("blade": {"cylinder": {"radius": 0.001, "height": 0.01}})";
  const auto tools = [&](const std::string& items) { return error_of(write_scene(R"("tools": [)" + items + "]")); };
  // Required keys, and at least one keyframe.
  EXPECT_EQ(tools(R"({"blade": "b.ply", "keyframes": [{"t": 0}]})"), path + ": /tools/0/name: required key missing");
  EXPECT_EQ(tools(R"({"name": "p", "keyframes": [{"t": 0}]})"), path + ": /tools/0/blade: required key missing");
  EXPECT_EQ(tools(R"({"name": "p", )" + cylinder + "}"), path + ": /tools/0/keyframes: required key missing");
  EXPECT_EQ(tools(R"({"name": "p", )" + cylinder + R"(, "keyframes": []})"),
            path + ": /tools/0/keyframes: must have at least 1 item, got 0");
  EXPECT_EQ(tools(R"({"name": "p", )" + cylinder + R"(, "keyframes": [{"position": [0, 0, 0]}]})"),
            path + ": /tools/0/keyframes/0/t: required key missing");
  // Blade shapes and ranges.
  EXPECT_EQ(tools(R"({"name": "p", "blade": {}, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/blade/cylinder: required key missing");
  EXPECT_EQ(tools(R"({"name": "p", "blade": {"sphere": {}}, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/blade/sphere: unknown key");
  EXPECT_EQ(tools(R"({"name": "p", "blade": 3, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/blade: expected a mesh path (string) or an object, got number");
  EXPECT_EQ(tools(R"({"name": "p", "blade": {"cylinder": {"radius": 0, "height": 1}}, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/blade/cylinder/radius: must be > 0, got 0");
  EXPECT_EQ(tools(R"({"name": "p", "blade": {"cylinder": {"radius": 1, "height": -1}}, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/blade/cylinder/height: must be > 0, got -1");
  EXPECT_EQ(tools(R"({"name": "p", "blade": {"cylinder": {"radius": 1}}, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/blade/cylinder/height: required key missing");
  EXPECT_EQ(tools(R"({"name": "p", "blade": {"cylinder": {"radius": 1, "height": 1, "segments": 2}},
                      "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/blade/cylinder/segments: must be >= 3, got 2");
  EXPECT_EQ(tools(R"({"name": "p", "blade": {"cylinder": {"radius": 1, "height": 1, "segments": 1025}},
                      "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/blade/cylinder/segments: must be <= 1024, got 1025");
  EXPECT_EQ(tools(R"({"name": "p", "blade": {"cylinder": {"radius": 1, "height": 1, "segments": 3.5}},
                      "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/blade/cylinder/segments: expected an integer, got 3.5");
  EXPECT_EQ(tools(R"({"name": "p", "blade": "absent.ply", "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/blade: file not found: " + (m_dir / "absent.ply").string());
  EXPECT_EQ(tools(R"({"name": "p", "mesh": "absent.obj", )" + cylinder + R"(, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/mesh: file not found: " + (m_dir / "absent.obj").string());
  EXPECT_EQ(tools(R"({"name": "p", "mesh": 1, )" + cylinder + R"(, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/mesh: expected a string, got number");
  // Other keys' types and ranges.
  EXPECT_EQ(tools(R"({"name": "p", "scale": 0, )" + cylinder + R"(, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/scale: must be > 0, got 0");
  EXPECT_EQ(tools(R"({"name": "p", "collide": "yes", )" + cylinder + R"(, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/collide: expected a boolean, got string");
  EXPECT_EQ(tools(R"({"name": "p", "knife": 1, )" + cylinder + R"(, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/knife: unknown key");
  EXPECT_EQ(tools(R"({"name": "p", )" + cylinder + R"(, "keyframes": [{"t": -1}]})"),
            path + ": /tools/0/keyframes/0/t: must be >= 0, got -1");
  EXPECT_EQ(tools(R"({"name": "p", )" + cylinder + R"(, "keyframes": [{"t": 0, "position": [0, 0]}]})"),
            path + ": /tools/0/keyframes/0/position: expected 3 numbers, got an array of 2");
  EXPECT_EQ(tools(R"({"name": "p", )" + cylinder + R"(, "keyframes": [{"t": 0}], "cuts": [{"t": -0.5}]})"),
            path + ": /tools/0/cuts/0/t: must be >= 0, got -0.5");
  EXPECT_EQ(tools(R"({"name": "p", )" + cylinder + R"(, "keyframes": [{"t": 0}], "cuts": [{}]})"),
            path + ": /tools/0/cuts/0/t: required key missing");
  // Rules across keys: names, sorted times. A cut after the duration is allowed (the run reports it never happened).
  EXPECT_EQ(tools(R"({"name": "", )" + cylinder + R"(, "keyframes": [{"t": 0}]})"),
            path + ": /tools/0/name: must not be empty");
  EXPECT_EQ(tools(R"({"name": "p", )" + cylinder + R"(, "keyframes": [{"t": 0}]}, {"name": "p", )" + cylinder +
                  R"(, "keyframes": [{"t": 0}]})"),
            path + ": /tools/1/name: duplicate tool name \"p\"");
  EXPECT_EQ(tools(R"({"name": "p", )" + cylinder + R"(, "keyframes": [{"t": 0.5}, {"t": 0.5}]})"),
            path + ": /tools/0/keyframes/1/t: must be > the previous keyframe's t (0.5), got 0.5");
  EXPECT_EQ(tools(R"({"name": "p", )" + cylinder + R"(, "keyframes": [{"t": 0}], "cuts": [{"t": 0.5}, {"t": 0.2}]})"),
            path + ": /tools/0/cuts/1/t: must be > the previous cut's t (0.5), got 0.2");
  EXPECT_EQ(tools(R"({"name": "p", )" + cylinder + R"(, "keyframes": [{"t": 0}], "cuts": [{"t": 1.5}]})"), "(no error)");
  EXPECT_EQ(error_of(write_scene(R"("tools": {})")), path + ": /tools: expected an array of objects, got object");
}

TEST_F(SceneLoaderTest, CuttingErrorsNameThePointer) {
  const std::string path = (m_dir / "scene.json").string();
  EXPECT_EQ(error_of(write_scene(R"("cutting": {"remove_fragments": "some"})")),
            path + R"(: /cutting/remove_fragments: must be one of "all", "small", "none", got "some")");
  EXPECT_EQ(error_of(write_scene(R"("cutting": {"fragment_volume": 0})")),
            path + ": /cutting/fragment_volume: must be > 0, got 0");
  EXPECT_EQ(error_of(write_scene(R"("cutting": {"verify": 1})")),
            path + ": /cutting/verify: expected a boolean, got number");
  EXPECT_EQ(error_of(write_scene(R"("cutting": {"verfy": true})")), path + ": /cutting/verfy: unknown key");
  EXPECT_EQ(error_of(write_scene(R"("cutting": [])")), path + ": /cutting: expected an object, got array");
}

TEST_F(SceneLoaderTest, FollowToolNamesAToolOrAProp) {
  const std::string path = (m_dir / "scene.json").string();
  EXPECT_EQ(error_of(write_scene(R"("render": {"camera": {"follow_tool": "punch"}})")),
            path + ": /render/camera/follow_tool: no tool or prop named \"punch\"");
  EXPECT_EQ(error_of(write_scene(R"("render": {"camera": {"follow_tool": "punch"}}, "tools": [{"name": "probe",
      "blade": {"cylinder": {"radius": 1, "height": 1}}, "keyframes": [{"t": 0}]}])")),
            path + ": /render/camera/follow_tool: no tool or prop named \"punch\"");
  write("shaft.obj", "v 0 0 0\n");
  EXPECT_EQ(load_scene(write_scene(R"("render": {"camera": {"follow_tool": "shaft"},
                                                   "props": [{"name": "shaft", "mesh": "shaft.obj"}]})"))
                .render.camera.follow_tool,
            "shaft");
}

TEST_F(SceneLoaderTest, ExpectedBlockShapeErrorsNameThePointer) {
  const std::string path = (m_dir / "scene.json").string();
  const auto expected = [&](const std::string& block) { return error_of(write_scene(R"("expected": )" + block)); };
  EXPECT_EQ(expected("[]"), path + ": /expected: expected an object (JSON pointer -> check), got array");
  EXPECT_EQ(expected(R"({"counts/elements": 1})"),
            path + ": /expected/counts~1elements: key must be a JSON pointer into report.json starting with '/'");
  EXPECT_EQ(expected(R"({"": 1})"),
            path + ": /expected/: key must be a JSON pointer into report.json starting with '/'");
  EXPECT_EQ(expected(R"({"/a~2": 1})"),
            path + ": /expected/~1a~02: key is not a JSON pointer: '~' must be followed by '0' or '1'");
  EXPECT_EQ(expected(R"({"/a": null})"),
            path + ": /expected/~1a: expected a string, boolean, number, {\"value\", \"rel\", \"abs\"} or "
                   "{\"min\", \"max\"}, got null");
  EXPECT_EQ(expected(R"({"/a": [1, 2]})"),
            path + ": /expected/~1a: expected a string, boolean, number, {\"value\", \"rel\", \"abs\"} or "
                   "{\"min\", \"max\"}, got array");
  EXPECT_EQ(expected(R"({"/a": {"value": 1, "tol": 2}})"),
            path + ": /expected/~1a/tol: unknown key (expected value, rel, abs, min or max)");
  EXPECT_EQ(expected(R"({"/a": {"value": "x"}})"), path + ": /expected/~1a/value: expected a number, got string");
  EXPECT_EQ(expected(R"({"/a": {"value": 1, "rel": -0.1}})"), path + ": /expected/~1a/rel: must be >= 0, got -0.1");
  EXPECT_EQ(expected(R"({"/a": {"value": 1, "abs": -1}})"), path + ": /expected/~1a/abs: must be >= 0, got -1");
  EXPECT_EQ(expected(R"({"/a": {"rel": 0.1}})"), path + ": /expected/~1a: needs \"value\", or \"min\" and/or \"max\"");
  EXPECT_EQ(expected(R"({"/a": {}})"), path + ": /expected/~1a: needs \"value\", or \"min\" and/or \"max\"");
  EXPECT_EQ(expected(R"({"/a": {"value": 1, "max": 2}})"),
            path + ": /expected/~1a/max: cannot be combined with \"value\"");
  EXPECT_EQ(expected(R"({"/a": {"min": 1, "abs": 2}})"),
            path + ": /expected/~1a/abs: only goes with \"value\", not with min/max");
  EXPECT_EQ(expected(R"({"/a": {"min": 3, "max": 2}})"), path + ": /expected/~1a/max: must be >= min (3), got 2");
  EXPECT_EQ(error_of(write_scene(R"("expected": {"/a": 1})"), {"/expected/~1a=1e999"}),
            path + ": /expected/~1a: must be a finite number, got inf");
  // A valid block, and one built from overrides.
  EXPECT_EQ(load_scene(write_scene(R"("expected": {"/a": {"min": 1}, "/b": "x", "/c": false, "/d": 1.5})")).expected_json,
            R"({"/a":{"min":1},"/b":"x","/c":false,"/d":1.5})");
  EXPECT_EQ(load_scene(write("minimal.json", k_minimal_scene), {"/expected={\"/steps\": 3}"}).expected_json,
            R"({"/steps":3})");
}

// ---- overrides ------------------------------------------------------------------------------------------------------

TEST_F(SceneLoaderTest, OverridesReplaceAndCreateKeys) {
  const std::string path = write("scene.json", k_minimal_scene);
  const std::vector<std::string> overrides = {
      "/solver/dt=0.01",                                    // a number
      "/solver/mode=static",                                // bare text: a string
      "/name=\"quoted name\"",                              // a JSON string
      "/render/enabled=true",                               // a boolean, creating "render"
      "/solver/gravity=[0, 0, -1]",                         // an array
      "/object/octree/root/size=0.5",                       // creates "octree" and "root"
      "/object/octree/root/min=[0,0,0]",                    // the root's other key
      "/probes/-={\"name\": \"p\", \"point\": [1, 2, 3]}",  // creates "probes" as [] and appends
      "/probes/0/name=renamed",                             // an array element's key
  };
  const Scene scene = load_scene(path, overrides);
  EXPECT_EQ(scene.solver.dt, 0.01);
  EXPECT_EQ(scene.solver.mode, "static");
  EXPECT_EQ(scene.name, "quoted name");
  EXPECT_TRUE(scene.render.enabled);
  EXPECT_EQ(scene.solver.gravity, (std::array<double, 3>{0, 0, -1}));
  EXPECT_TRUE(scene.object.octree.has_root);
  EXPECT_EQ(scene.object.octree.root_size, 0.5);
  ASSERT_EQ(scene.probes.size(), 1u);
  EXPECT_EQ(scene.probes[0].name, "renamed");
  EXPECT_EQ(scene.probes[0].point, (std::array<double, 3>{1, 2, 3}));
}

TEST_F(SceneLoaderTest, OverrideValuesAreValidated) {
  const std::string path = write("scene.json", k_minimal_scene);
  EXPECT_EQ(error_of(path, {"/solver/dt=-0.5"}), path + ": /solver/dt: must be > 0, got -0.5");
  EXPECT_EQ(error_of(path, {"/solver/dt=fast"}), path + ": /solver/dt: expected a number, got string");
}

TEST_F(SceneLoaderTest, OverrideOfUnknownKeyIsAnError) {
  const std::string path = write("scene.json", k_minimal_scene);
  EXPECT_EQ(error_of(path, {"/solver/dtt=0.1"}), path + ": /solver/dtt: unknown key");
  EXPECT_EQ(error_of(path, {"/object/materail/density=1"}), path + ": /object/materail: unknown key");
}

TEST_F(SceneLoaderTest, MalformedOverrides) {
  const std::string path = write("scene.json", k_minimal_scene);
  EXPECT_EQ(error_of(path, {"solver/dt=1"}), "override \"solver/dt=1\": expected /json/pointer=value");
  EXPECT_EQ(error_of(path, {"/solver/dt"}), "override \"/solver/dt\": expected /json/pointer=value");
  EXPECT_EQ(error_of(path, {"/a~2=1"}), "override \"/a~2=1\": escape character '~' must be followed with '0' or '1'");
  EXPECT_EQ(error_of(path, {"/probes/0/name=x"}), "override \"/probes/0/name=x\": /probes has no element 0");
  EXPECT_EQ(error_of(path, {"/solver/dt=1", "/solver/dt/x=1"}),
            "override \"/solver/dt/x=1\": /solver/dt is a number, not an object or array");
}

// ---- generated documentation ----------------------------------------------------------------------------------------

TEST(SceneFormatDocs, CheckedInFileMatchesSchema) {
  const std::string generated = scene_format_markdown();
  const std::string checked_in = read_file(std::string(OCTOCUT_SOURCE_DIR) + "/docs/scene-format.md");
  EXPECT_TRUE(checked_in == generated) << "docs/scene-format.md is stale; regenerate it from the schema with\n"
                                          "  build/bin/octocut scene-doc > docs/scene-format.md";
}

TEST(SceneFormatDocs, EveryKeyHasARow) {
  const std::string markdown = scene_format_markdown();
  for (const char* key : {"`/name`", "`/solver/dt`", "`/object/surface/box/min`", "`/object/octree/root/size`",
                          "`/object/octree/refine/[]/level`", "`/object/handles/[]/keyframes/[]/rotation_deg`",
                          "`/probes/[]/point`", "`/output/surface_every`", "`/tools/[]/blade/cylinder/segments`",
                          "`/tools/[]/keyframes/[]/rotation_deg`", "`/tools/[]/cuts/[]/t`", "`/tools/[]/collide`",
                          "`/cutting/remove_fragments`", "`/cutting/fragment_volume`", "`/cutting/verify`",
                          "`/expected`"}) {
    EXPECT_NE(markdown.find(std::string("| ") + key + " |"), std::string::npos) << key;
  }
  EXPECT_NE(markdown.find("| `/solver/dt` | number | (0, 1] | `0.001` | Time step, s. |"), std::string::npos);
  EXPECT_NE(markdown.find("| `/tools/[]/keyframes` | array of objects | at least 1 item | required |"), std::string::npos);
  EXPECT_NE(markdown.find("| `/cutting/fragment_volume` | number | > 0 | `1e-09` |"), std::string::npos);
}

}  // namespace
}  // namespace octocut::engine
