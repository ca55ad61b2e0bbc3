#pragma once
// Built-in benchmarks, `octocut bench` (SPEC §7): results in the octocut.bench/1 JSON schema.
#include <string>
#include <vector>

namespace octocut::engine {

/// Names of the benchmarks this build has, e.g. "step/cube10".
std::vector<std::string> benchmark_names();

/// Runs the benchmarks whose names start with one of `filters` (all when empty), prints a table to stdout, and
/// returns the octocut.bench/1 JSON text. Throws std::invalid_argument when a filter matches nothing.
std::string run_benchmarks(const std::vector<std::string>& filters, bool quiet);

}  // namespace octocut::engine
