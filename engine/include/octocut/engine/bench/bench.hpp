#pragma once
// Built-in benchmarks, `octocut bench` (SPEC §7): results in the octocut.bench/1 JSON schema.
#include <cstdint>
#include <string>
#include <vector>

namespace octocut::engine {

/// The CPU's model name from /proc/cpuinfo ("unknown" when it has none).
std::string cpu_name();

/// Names of the benchmarks this build has, e.g. "step/cube10".
std::vector<std::string> benchmark_names();

/// One run of the calibration kernel: a fixed, single-threaded mix of the kinds of work a cut does (floating-point
/// orientation tests with data-dependent branches, sorting, gathers from a 16 MiB table). Its time measures the
/// machine's speed for cut timings (SPEC §10).
struct CalibrationSample {
  double ms = 0.0;        ///< wall time, ms
  uint64_t checksum = 0;  ///< a digest of the kernel's results (the same on every run and machine)
};
CalibrationSample calibration_kernel();

/// The calibration time, ms: the median of `runs` samples after one warm-up. A sample is the wall time of the kernel
/// run on two threads at once, as a cut runs on two.
double calibration_ms(int runs = 9);

/// Runs the benchmarks whose names start with one of `filters` (all when empty), prints a table to stdout, and
/// returns the octocut.bench/1 JSON text. `machine.calibration_ms` holds the calibration time, the median of the
/// kernel runs before and after the benchmarks. Throws std::invalid_argument when a filter matches nothing.
std::string run_benchmarks(const std::vector<std::string>& filters, bool quiet);

}  // namespace octocut::engine
