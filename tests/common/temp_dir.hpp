#pragma once
// The one temporary-directory fixture of the test suite: a fresh, empty folder per test, removed afterwards.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace octocut::test {

/// A fixture whose m_dir is a new empty directory named after the test binary's process and the running test
/// (so that tests running in parallel never share one), removed again at the end of the test.
class TempDirTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = std::string(info->test_suite_name()) + "_" + info->name();
    for (char& c : name)
      if (c == '/') c = '_';  // parameterised tests
    m_dir = std::filesystem::temp_directory_path() / ("octocut_" + std::to_string(::getpid()) + "_" + name);
    std::filesystem::remove_all(m_dir);
    std::filesystem::create_directories(m_dir);
  }
  void TearDown() override { std::filesystem::remove_all(m_dir); }

  /// Writes `text` into m_dir / name and returns the path.
  std::filesystem::path write(const std::string& name, const std::string& text) const {
    const std::filesystem::path p = m_dir / name;
    std::ofstream(p) << text;
    return p;
  }

  std::filesystem::path m_dir;
};

}  // namespace octocut::test
