// `octocut run --check` and `--regenerate` end to end on a tiny box scene, and `octocut validate` with tools: good
// blades are listed, bad blade meshes exit 2 naming /tools/0/blade.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "common/cli_util.hpp"
#include "octocut/sim/primitives.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/engine/run/tool.hpp"
#include "common/temp_dir.hpp"

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using octocut::test::CommandResult;
using octocut::test::run_octocut;

/// A 1 cm box clamped at its bottom, two steps; `expected` is the text of its expected block ("" for none).
std::string box_scene(const std::string& expected) {
  std::string text = R"({
  "name": "box",
  "duration": 0.01,
  "solver": {"dt": 0.005, "threads": 1},
  "object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}},
             "octree": {"root": {"min": [0, 0, 0], "size": 0.016}, "base_level": 3},
             "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 1e-9]}}]})";
  if (!expected.empty()) text += ",\n  \"expected\": " + expected;
  return text + "\n}\n";
}

class CliExpectedTest : public octocut::test::TempDirTest {
 protected:

  fs::path write(const std::string& name, const std::string& text) const {
    const fs::path p = m_dir / name;
    std::ofstream(p) << text;
    return p;
  }

  static std::string read(const fs::path& p) {
    std::ifstream in(p);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }

  /// `octocut run SCENE --quiet --out DIR/out <flags>`.
  CommandResult run(const fs::path& scene, const std::string& flags) const {
    return run_octocut("run '" + scene.string() + "' --quiet --out '" + (m_dir / "out").string() + "' " + flags);
  }

};

TEST_F(CliExpectedTest, CheckPassesWhenEveryValueMatches) {
  const fs::path scene = write("box.json", box_scene(R"({"/status": "ok", "/steps": 2, "/sim_time_s": 0.01,
    "/counts/elements": {"min": 100, "max": 200}, "/stability/finite": true, "/counts/hanging_slots": {"max": 0}})"));
  const CommandResult r = run(scene, "--check");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("check: all 6 expected checks passed"), std::string::npos) << r.output;
}

TEST_F(CliExpectedTest, CheckFailsWithOneLinePerFailure) {
  const fs::path scene = write("box.json", box_scene(R"({"/status": "ok", "/steps": 3,
    "/counts/elements": {"min": 700, "max": 800}, "/counts/nothing": 1})"));
  const CommandResult r = run(scene, "--check");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("octocut: check failed: /steps: 2, expected 3\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("octocut: check failed: /counts/elements: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" not in [700, 800]\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("octocut: check failed: /counts/nothing: missing from the report\n"), std::string::npos);
  EXPECT_NE(r.output.find("3 of 4 expected checks failed"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("/status"), std::string::npos) << r.output;
  // The report was written all the same.
  EXPECT_TRUE(fs::exists(m_dir / "out/report.json"));
}

TEST_F(CliExpectedTest, CheckWithoutABlockPassesWithANote) {
  const fs::path scene = write("box.json", box_scene(""));
  const CommandResult r = run(scene, "--check");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("has no expected block; nothing to check"), std::string::npos) << r.output;
}

TEST_F(CliExpectedTest, CheckSeesOverriddenExpectations) {
  const fs::path scene = write("box.json", box_scene(R"({"/steps": 2})"));
  EXPECT_EQ(run(scene, "--check --set /expected/~1steps=5").exit_code, 1);
  EXPECT_EQ(run(scene, "--check --set /expected/~1steps=2").exit_code, 0);
}

TEST_F(CliExpectedTest, RegenerateRewritesOnlyTheBlockThenChecksPass) {
  const std::string block = R"({"/steps": 3, "/status": "failed",
    "/counts/elements": {"min": 700, "max": 800}, "/sim_time_s": {"value": 0.5, "rel": 0.01}})";
  const fs::path scene = write("box.json", box_scene(block));
  ASSERT_EQ(run(scene, "--check").exit_code, 1);

  // The run regenerates, then checks the new block.
  const CommandResult r = run(scene, "--regenerate");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("regenerate: rewrote the expected block of"), std::string::npos) << r.output;

  // Every byte before the block is kept, the block has the report's values in the same order and kinds.
  const std::string text = read(scene);
  const std::string before = box_scene(block).substr(0, box_scene(block).find("\"expected\": "));
  EXPECT_EQ(text.substr(0, before.size()), before);
  const json report = json::parse(read(m_dir / "out/report.json"));
  const long elements = report["counts"]["elements"].get<long>();
  // [700, 800] has the relative half-width 50/750 around its midpoint; around the new value it keeps it.
  const long lo = static_cast<long>(std::floor(elements - elements / 15.0));
  const long hi = static_cast<long>(std::ceil(elements + elements / 15.0));
  const std::string expected_block = "\"expected\": {\n    \"/steps\": 2,\n    \"/status\": \"ok\",\n"
                                     "    \"/counts/elements\": {\"min\": " + std::to_string(lo) +
                                     ", \"max\": " + std::to_string(hi) +
                                     "},\n    \"/sim_time_s\": {\"value\": 0.01, \"rel\": 0.01}\n  }\n}\n";
  EXPECT_EQ(text.substr(before.size()), expected_block);
  EXPECT_EQ(run(scene, "--check").exit_code, 0);
  // No temporary file is left behind.
  for (const auto& entry : fs::directory_iterator(m_dir)) {
    EXPECT_EQ(entry.path().filename().string().find(".tmp"), std::string::npos) << entry.path();
  }
}

TEST_F(CliExpectedTest, RegenerateWithoutABlockLeavesTheFileAlone) {
  const fs::path scene = write("box.json", box_scene(""));
  const CommandResult r = run(scene, "--regenerate");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("has no expected block"), std::string::npos) << r.output;
  EXPECT_EQ(read(scene), box_scene(""));
}

TEST_F(CliExpectedTest, CheckAndRegenerateExcludeEachOther) {
  const fs::path scene = write("box.json", box_scene(R"({"/steps": 2})"));
  EXPECT_EQ(run(scene, "--check --regenerate").exit_code, 2);
  const CommandResult help = run_octocut("run --help");
  EXPECT_NE(help.output.find("--check"), std::string::npos);
  EXPECT_NE(help.output.find("--regenerate"), std::string::npos);
}

// ---- validate with tools --------------------------------------------------------------------------------------------

/// The box scene with one tool whose blade is `blade` (a JSON value).
std::string tool_scene(const std::string& blade) {
  std::string text = box_scene("");
  text.insert(text.rfind('}'), R"(,  "tools": [{"name": "punch", "blade": )" + blade +
                                   R"(, "keyframes": [{"t": 0, "position": [0.005, 0.005, 0.01]}],
              "cuts": [{"t": 0.005}]}])");
  return text;
}

TEST_F(CliExpectedTest, ValidateListsEveryTool) {
  const fs::path scene = write("box.json", tool_scene(R"({"cylinder": {"radius": 0.001, "height": 0.02, "segments": 8}})"));
  const CommandResult r = run_octocut("validate '" + scene.string() + "'");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("tool punch: blade cylinder r=0.001 m h=0.02 m n=8 (18 vertices, 32 triangles"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("1 keyframes, 1 cuts"), std::string::npos) << r.output;
}

TEST_F(CliExpectedTest, ValidateRejectsBadBladesWithExitCode2) {
  namespace sim = octocut::sim;
  // Open: one triangle missing.
  octocut::sim::TriMesh open = sim::cylinder_mesh(1.0, 1.0, 8);
  open.triangles.pop_back();
  octocut::engine::save_mesh(m_dir / "open.ply", open);
  // Self-intersecting: two overlapping cylinders in one file.
  octocut::sim::TriMesh crossed = sim::cylinder_mesh(1.0, 1.0, 8);
  const auto n = static_cast<std::int32_t>(crossed.vertices.size());
  const octocut::sim::TriMesh other = sim::cylinder_mesh(1.0, 1.0, 8);
  for (const auto& v : other.vertices) crossed.vertices.push_back(v + octocut::sim::Vec3(0.5, 0.1, 0.2));
  for (const auto& t : other.triangles) crossed.triangles.push_back({t[0] + n, t[1] + n, t[2] + n});
  octocut::engine::save_mesh(m_dir / "crossed.ply", crossed);
  // NaN coordinates.
  octocut::sim::TriMesh nan = sim::cylinder_mesh(1.0, 1.0, 8);
  nan.vertices[5].z() = std::numeric_limits<double>::quiet_NaN();
  octocut::engine::save_mesh(m_dir / "nan.ply", nan);

  for (const std::string name : {"open.ply", "crossed.ply", "nan.ply"}) {
    const fs::path scene = write("box.json", tool_scene("\"" + name + "\""));
    const CommandResult r = run_octocut("validate '" + scene.string() + "'");
    EXPECT_EQ(r.exit_code, 2) << name << ": " << r.output;
    EXPECT_NE(r.output.find("octocut: " + scene.string() + ": /tools/0/blade: " + (m_dir / name).string() + ": "),
              std::string::npos)
        << r.output;
  }
}

}  // namespace
