// Tests for the file helpers: whole-file reads and atomic writes, including their failure messages and clean-up.
#include "octocut/engine/io/io.hpp"
#include "common/temp_dir.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace octocut::engine {
namespace {

namespace fs = std::filesystem;

/// Gives each test a fresh, empty directory, removed afterwards.
class IoTest : public octocut::test::TempDirTest {
 protected:

  /// The names of the entries of `directory`, hidden files included, sorted.
  static std::vector<std::string> list(const fs::path& directory) {
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(directory)) names.push_back(entry.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  }

  /// The message of the std::runtime_error that `action` throws, or "(no error)".
  template <typename Action>
  static std::string error_of(Action action) {
    try {
      action();
    } catch (const std::runtime_error& error) {
      return error.what();
    }
    return "(no error)";
  }

};

TEST_F(IoTest, ReadFileReturnsEveryByte) {
  const std::string content("line one\nline two\0with a NUL\n", 29);
  std::ofstream(m_dir / "data.bin", std::ios::binary) << content;
  EXPECT_EQ(read_file(m_dir / "data.bin"), content);
}

TEST_F(IoTest, ReadFileOfMissingFileNamesThePathAndReason) {
  const fs::path path = m_dir / "missing.json";
  EXPECT_EQ(error_of([&] { read_file(path); }), path.string() + ": cannot read: No such file or directory");
}

TEST_F(IoTest, ReadFileOfDirectoryFails) {
  EXPECT_EQ(error_of([&] { read_file(m_dir); }), m_dir.string() + ": cannot read: Is a directory");
}

TEST_F(IoTest, WriteFileAtomicCreatesThenReplacesAndLeavesNoTemporaryFile) {
  // Create.
  const fs::path path = m_dir / "report.json";
  write_file_atomic(path, "{\"first\": true}\n");
  EXPECT_EQ(read_file(path), "{\"first\": true}\n");

  // Replace with shorter content: nothing of the old file may remain.
  write_file_atomic(path, "{}");
  EXPECT_EQ(read_file(path), "{}");

  // Empty content is a valid file too.
  write_file_atomic(path, "");
  EXPECT_EQ(read_file(path), "");
  EXPECT_EQ(list(m_dir), std::vector<std::string>{"report.json"});
}

TEST_F(IoTest, WriteFileAtomicWithRelativePathWritesInCurrentDirectory) {
  const fs::path previous = fs::current_path();
  fs::current_path(m_dir);
  write_file_atomic("plain.txt", "text");
  fs::current_path(previous);
  EXPECT_EQ(read_file(m_dir / "plain.txt"), "text");
  EXPECT_EQ(list(m_dir), std::vector<std::string>{"plain.txt"});
}

TEST_F(IoTest, WriteFileAtomicIntoMissingDirectoryThrowsWithThePath) {
  const fs::path path = m_dir / "no_such_dir" / "report.json";
  EXPECT_EQ(error_of([&] { write_file_atomic(path, "{}"); }),
            path.string() + ": cannot write: No such file or directory");
  EXPECT_TRUE(list(m_dir).empty());
}

TEST_F(IoTest, WriteFileAtomicRemovesTemporaryFileWhenRenameFails) {
  // A non-empty directory cannot be replaced by a file, so the write fails after the temporary file exists.
  const fs::path path = m_dir / "target";
  fs::create_directories(path / "occupied");
  const std::string message = error_of([&] { write_file_atomic(path, "content"); });
  EXPECT_TRUE(message.starts_with(path.string() + ": cannot write: ")) << message;
  EXPECT_EQ(list(m_dir), std::vector<std::string>{"target"});
  EXPECT_EQ(list(path), std::vector<std::string>{"occupied"});
}

}  // namespace
}  // namespace octocut::engine
