#include "octocut/engine/io/io.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <system_error>

namespace octocut::engine {
namespace {

/// Builds the error for a failed operation on `path`, with the reason taken from `error` (an errno value).
std::runtime_error file_error(const std::filesystem::path& path, const char* action, int error) {
  return std::runtime_error(path.string() + ": " + action + ": " + std::strerror(error));
}

/// Owns a POSIX file descriptor and closes it on scope exit unless released.
class FileDescriptor {
 public:
  explicit FileDescriptor(int fd) : m_fd(fd) {}
  FileDescriptor(const FileDescriptor&) = delete;
  FileDescriptor& operator=(const FileDescriptor&) = delete;
  ~FileDescriptor() {
    if (m_fd >= 0) ::close(m_fd);
  }

  /// Returns the descriptor, or -1 when opening failed.
  int get() const { return m_fd; }

  /// Closes the descriptor now and returns 0, or the errno value of a failed close (which can report a late write
  /// error on some file systems).
  int close() {
    const int result = ::close(m_fd);
    m_fd = -1;
    return result == 0 ? 0 : errno;
  }

 private:
  int m_fd = -1;
};

/// Writes all of `content` to `fd`, retrying partial writes and interrupted calls. Returns 0 or an errno value.
int write_all(int fd, std::string_view content) {
  while (!content.empty()) {
    const ssize_t written = ::write(fd, content.data(), content.size());
    if (written < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    content.remove_prefix(static_cast<std::size_t>(written));
  }
  return 0;
}

}  // namespace

void write_file_atomic(const std::filesystem::path& path, std::string_view content) {
  // The temporary file sits next to the target so that the final rename stays within one file system.
  const std::filesystem::path directory = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  std::string temporary_name = ".";
  temporary_name += path.filename().string();
  temporary_name += ".tmp.";
  temporary_name += std::to_string(::getpid());
  const std::filesystem::path temporary = directory / temporary_name;

  // Create the temporary file; nothing needs cleaning up if this fails.
  FileDescriptor file(::open(temporary.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666));
  if (file.get() < 0) throw file_error(path, "cannot write", errno);

  // Write, flush to disk and close, removing the temporary file if any step fails.
  int error = write_all(file.get(), content);
  if (error == 0 && ::fsync(file.get()) != 0) error = errno;
  const int close_error = file.close();
  if (error == 0) error = close_error;
  if (error != 0) {
    ::unlink(temporary.c_str());
    throw file_error(path, "cannot write", error);
  }

  // Replace the target in one step.
  std::error_code rename_error;
  std::filesystem::rename(temporary, path, rename_error);
  if (rename_error) {
    ::unlink(temporary.c_str());
    throw std::runtime_error(path.string() + ": cannot write: " + rename_error.message());
  }

  // Make the rename itself durable; the new content is already visible, so a failure here is not reported.
  FileDescriptor directory_fd(::open(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (directory_fd.get() >= 0) ::fsync(directory_fd.get());
}

std::string read_file(const std::filesystem::path& path) {
  // Open; a directory opens fine on Linux and fails at the first read with EISDIR.
  FileDescriptor file(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (file.get() < 0) throw file_error(path, "cannot read", errno);

  // Read until end of file in fixed-size chunks.
  std::string content;
  char buffer[1 << 16];
  while (true) {
    const ssize_t count = ::read(file.get(), buffer, sizeof buffer);
    if (count < 0) {
      if (errno == EINTR) continue;
      throw file_error(path, "cannot read", errno);
    }
    if (count == 0) break;
    content.append(buffer, static_cast<std::size_t>(count));
  }
  return content;
}

}  // namespace octocut::engine
