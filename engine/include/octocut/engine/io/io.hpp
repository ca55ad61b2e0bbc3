#pragma once
// Small file helpers shared by the loader and the writers: whole-file reads and crash-safe (atomic) writes.
#include <filesystem>
#include <string>
#include <string_view>

namespace octocut::engine {

/// Writes `content` to `path` so that readers see either the old file or the complete new one, never a partial
/// file. The bytes go to a temporary file in the same directory (`.<name>.tmp.<pid>`), which is flushed to disk with
/// fsync and then renamed over `path`. Throws std::runtime_error naming `path` and the system's reason on failure;
/// the temporary file is removed on every failure path.
void write_file_atomic(const std::filesystem::path& path, std::string_view content);

/// Returns the whole content of the file at `path` as bytes. Throws std::runtime_error with the message
/// `<path>: cannot read: <reason>` when the file cannot be opened or read (missing, a directory, no permission).
std::string read_file(const std::filesystem::path& path);

}  // namespace octocut::engine
