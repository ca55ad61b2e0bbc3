// libFuzzer entry point for one target of fuzz_targets.hpp, chosen at compile time (OCTOCUT_FUZZ_TARGET).
#include <cstdio>
#include <cstdlib>

#include "fuzz/fuzz_targets.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const octocut::fuzz::Target target = [] {
    const octocut::fuzz::Target t = octocut::fuzz::target(OCTOCUT_FUZZ_TARGET);
    if (t == nullptr) {
      std::fprintf(stderr, "no fuzz target named %s\n", OCTOCUT_FUZZ_TARGET);
      std::abort();
    }
    return t;
  }();
  return target(data, size);
}
