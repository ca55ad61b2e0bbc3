#pragma once
// Runs the octocut executable from the command-line tests.
#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace octocut::test {

/// The exit status and the combined stdout and stderr of one command.
struct CommandResult {
  int exit_code = -1;  ///< -1 when the process did not exit normally
  std::string output;
};

/// Runs `<env> octocut <arguments>` through the shell, capturing stderr with stdout; `env` holds optional
/// `NAME=value` assignments for the command.
inline CommandResult run_octocut(const std::string& arguments, const std::string& env = "") {
  const std::string command = env + " '" + std::string(OCTOCUT_EXE) + "' " + arguments + " 2>&1";
  CommandResult result;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) return result;
  char buffer[4096];
  while (const std::size_t count = std::fread(buffer, 1, sizeof buffer, pipe)) result.output.append(buffer, count);
  const int status = ::pclose(pipe);
  if (status != -1 && WIFEXITED(status)) result.exit_code = WEXITSTATUS(status);
  return result;
}

}  // namespace octocut::test
