// Command-line smoke tests for bad scenes (SPEC §7): `octocut validate` exits with 2 and prints the file and the
// JSON pointer of the problem; a valid scene exits with 0.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "common/cli_util.hpp"
#include "common/temp_dir.hpp"

namespace {

namespace fs = std::filesystem;

using octocut::test::CommandResult;
using octocut::test::run_octocut;

/// Gives each test a fresh directory for its scene files, removed afterwards.
class CliSceneErrorsTest : public octocut::test::TempDirTest {
 protected:

  /// Writes `text` to `name` in the test directory and returns the path.
  std::string write(const std::string& name, const std::string& text) const {
    const fs::path path = m_dir / name;
    std::ofstream(path, std::ios::binary) << text;
    return path.string();
  }

  /// Runs `octocut validate` on `path`.
  static CommandResult validate(const std::string& path) { return run_octocut("validate '" + path + "'"); }

};

TEST_F(CliSceneErrorsTest, ValidBoxSceneExitsZero) {
  const std::string path =
      write("box.json", R"({"object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}}}})");
  const CommandResult result = validate(path);
  EXPECT_EQ(result.exit_code, 0) << result.output;
}

TEST_F(CliSceneErrorsTest, MalformedJsonExitsTwoWithLineAndColumn) {
  const std::string path = write("malformed.json", "{\n  \"duration\": 1,\n  }\n");
  const CommandResult result = validate(path);
  EXPECT_EQ(result.exit_code, 2) << result.output;
  EXPECT_NE(result.output.find(path + ":3:3: malformed JSON"), std::string::npos) << result.output;
}

TEST_F(CliSceneErrorsTest, UnknownKeyExitsTwoWithPointer) {
  const std::string path = write(
      "unknown.json", R"({"object": {"surface": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}}, "materail": {}}})");
  const CommandResult result = validate(path);
  EXPECT_EQ(result.exit_code, 2) << result.output;
  EXPECT_NE(result.output.find(path + ": /object/materail: unknown key"), std::string::npos) << result.output;
}

TEST_F(CliSceneErrorsTest, OutOfRangeExitsTwoWithPointer) {
  const std::string path = write(
      "range.json", R"({"solver": {"dt": -1}, "object": {"surface": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}}}})");
  const CommandResult result = validate(path);
  EXPECT_EQ(result.exit_code, 2) << result.output;
  EXPECT_NE(result.output.find(path + ": /solver/dt: must be > 0, got -1"), std::string::npos) << result.output;
}

TEST_F(CliSceneErrorsTest, MissingSceneFileExitsTwo) {
  const std::string path = (m_dir / "absent.json").string();
  const CommandResult result = validate(path);
  EXPECT_EQ(result.exit_code, 2) << result.output;
  EXPECT_NE(result.output.find(path + ": cannot read"), std::string::npos) << result.output;
}

TEST_F(CliSceneErrorsTest, MissingMeshFileExitsTwoWithPointer) {
  const std::string path = write("mesh.json", R"({"object": {"surface": "absent.obj"}})");
  const CommandResult result = validate(path);
  EXPECT_EQ(result.exit_code, 2) << result.output;
  EXPECT_NE(result.output.find(path + ": /object/surface: file not found: " + (m_dir / "absent.obj").string()),
            std::string::npos)
      << result.output;
}

TEST_F(CliSceneErrorsTest, WrongTypeExitsTwoWithPointer) {
  const std::string path = write(
      "type.json", R"({"solver": {"dt": "fast"}, "object": {"surface": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}}}})");
  const CommandResult result = validate(path);
  EXPECT_EQ(result.exit_code, 2) << result.output;
  EXPECT_NE(result.output.find(path + ": /solver/dt: "), std::string::npos) << result.output;
  EXPECT_NE(result.output.find("number"), std::string::npos) << result.output;
}

TEST_F(CliSceneErrorsTest, NonFiniteNumberExitsTwoWithPointer) {
  const std::string path =
      write("inf.json", R"({"duration": 1e999, "object": {"surface": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}}}})");
  const CommandResult result = validate(path);
  EXPECT_EQ(result.exit_code, 2) << result.output;
  EXPECT_NE(result.output.find(path + ":"), std::string::npos) << result.output;
  // The same through an override names the pointer.
  const std::string ok = write("ok.json", R"({"object": {"surface": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}}}})");
  const CommandResult over = run_octocut("validate '" + ok + "' --set /solver/dt=1e999");
  EXPECT_EQ(over.exit_code, 2) << over.output;
  EXPECT_NE(over.output.find("/solver/dt: must be a finite number"), std::string::npos) << over.output;
}

}  // namespace
