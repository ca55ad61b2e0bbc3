// Running a study's cases: each one a child process (`octocut run ...`), `jobs` of them at a time.
#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <map>

#include "octocut/sim/timing.hpp"
#include "study_internal.hpp"

namespace octocut::engine::study {

namespace {

// Starts case `c` with its output into cases/<id>/log.txt; returns the child's pid (-1 when fork failed).
pid_t start_case(const Plan& plan, const Case& c, const fs::path& out_dir) {
  const fs::path dir = out_dir / "cases" / c.id;
  fs::create_directories(dir);
  const std::vector<std::string> args = case_argv(plan, c, out_dir);
  const std::string log = (dir / "log.txt").string();
  const pid_t pid = fork();
  if (pid != 0) return pid;
  // The child: its output to the log, then the command (nothing but async-signal-safe calls until exec).
  const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd >= 0) {
    dup2(fd, STDOUT_FILENO);
    dup2(fd, STDERR_FILENO);
    close(fd);
  }
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  execv(argv[0], argv.data());
  _exit(127);
}

}  // namespace

int run_cases(const Plan& plan, const fs::path& out_dir, int jobs, bool quiet) {
  jobs = std::max(1, jobs);
  std::map<pid_t, std::size_t> running;  // pid -> case index
  std::size_t next = 0, done = 0;
  int broken = 0;
  const auto t0 = sim::Clock::now();
  while (done < plan.cases.size()) {
    // Keep `jobs` children running; then wait for one to finish.
    while (running.size() < std::size_t(jobs) && next < plan.cases.size()) {
      const pid_t pid = start_case(plan, plan.cases[next], out_dir);
      if (pid < 0) throw std::runtime_error("study: could not start a case (fork failed)");
      running[pid] = next++;
    }
    int status = 0;
    const pid_t pid = waitpid(-1, &status, 0);
    if (pid < 0) throw std::runtime_error("study: waitpid failed");
    const auto it = running.find(pid);
    if (it == running.end()) continue;
    const Case& c = plan.cases[it->second];
    running.erase(it);
    ++done;
    const int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    if (code != 0 && code != 1) {
      ++broken;
      std::fprintf(stderr, "octocut: study: case %s exited with %d (see %s)\n", c.id.c_str(), code,
                   (out_dir / "cases" / c.id / "log.txt").c_str());
    }
    if (!quiet)
      std::fprintf(stderr, "study: %zu/%zu cases done (%.0f s), last %s%s\n", done, plan.cases.size(),
                   sim::ms_since(t0) / 1000.0, c.id.c_str(), code == 0 ? "" : code == 1 ? " (run failed)" : " (broken)");
  }
  return broken;
}

}  // namespace octocut::engine::study
