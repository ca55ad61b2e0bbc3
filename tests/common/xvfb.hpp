#pragma once
// Child processes and an X server of the test's own, for the viewer's tests under Xvfb: every process is killed
// (SIGTERM, then SIGKILL) when its handle goes out of scope, also when the test fails.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace octocut::test {

// A child process, killed (SIGTERM, then SIGKILL) when it goes out of scope unless it has exited.
class Child {
 public:
  // Runs `argv` with `env` added to the environment, stdout and stderr into `log`; `keep_fd` stays open in the child.
  Child(const std::vector<std::string>& argv, const std::vector<std::string>& env, const std::filesystem::path& log, int keep_fd = -1) {
    m_pid = fork();
    if (m_pid == 0) {
      const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      dup2(fd, 1);
      dup2(fd, 2);
      for (const std::string& e : env) putenv(const_cast<char*>(e.c_str()));
      std::vector<char*> args;
      for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
      args.push_back(nullptr);
      execvp(args[0], args.data());
      _exit(127);
    }
  }
  ~Child() { kill_now(); }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  // Waits up to `timeout` for the exit; its exit code, or -1 when it did not exit in time (then killed).
  int wait_exit(std::chrono::milliseconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
      int status = 0;
      if (waitpid(m_pid, &status, WNOHANG) == m_pid) {
        m_pid = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    kill_now();
    return -1;
  }
  [[nodiscard]] bool running() {
    int status = 0;
    return m_pid > 0 && waitpid(m_pid, &status, WNOHANG) == 0;
  }

 private:
  void kill_now() {
    if (m_pid <= 0) return;
    kill(m_pid, SIGTERM);
    for (int i = 0; i < 50; ++i) {
      int status = 0;
      if (waitpid(m_pid, &status, WNOHANG) == m_pid) {
        m_pid = -1;
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    kill(m_pid, SIGKILL);
    waitpid(m_pid, nullptr, 0);
    m_pid = -1;
  }
  pid_t m_pid = -1;
};

// An X server of its own: Xvfb on the first free display (-displayfd), killed with the test.
class Xvfb {
 public:
  // `screen`: WIDTHxHEIGHTxDEPTH of screen 0.
  explicit Xvfb(const std::filesystem::path& log, const std::string& screen = "1024x768x24") {
    int fds[2];
    if (pipe(fds) != 0) return;
    m_server = std::make_unique<Child>(
        std::vector<std::string>{"Xvfb", "-displayfd", std::to_string(fds[1]), "-screen", "0", screen,
                                 "-nolisten", "tcp"},
        std::vector<std::string>{}, log, fds[1]);
    close(fds[1]);
    pollfd p{fds[0], POLLIN, 0};
    std::string number;
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (std::chrono::steady_clock::now() < end && poll(&p, 1, 100) >= 0) {
      char c = 0;
      if ((p.revents & POLLIN) && read(fds[0], &c, 1) == 1) {
        if (c == '\n') break;
        number += c;
      } else if (p.revents & (POLLHUP | POLLERR)) {
        break;
      }
    }
    close(fds[0]);
    if (!number.empty()) m_display = ":" + number;
  }
  [[nodiscard]] const std::string& display() const { return m_display; }

 private:
  std::unique_ptr<Child> m_server;
  std::string m_display;
};

}  // namespace octocut::test
