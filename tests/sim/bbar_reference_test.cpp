// Reruns the independent reference of the B-bar cantilever tests (CalculiX, tests/sim/reference/cantilever_ccx.py)
// and checks the converged deflections stored in sim/reference/cantilever_reference.hpp. Label `study`: it needs
// python3 and ccx (Debian calculix-ccx) and takes about a minute of CPU time.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "sim/reference/cantilever_reference.hpp"

namespace {

// The stdout of `command`, or an empty string when it could not run.
std::string run(const std::string& command) {
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(command.c_str(), "r"), pclose);
  if (!pipe) return {};
  std::string out;
  char buf[4096];
  while (std::fgets(buf, sizeof buf, pipe.get())) out += buf;
  return out;
}

// The number after `"key": ` in the script's JSON output, or -1.
double value(const std::string& json, const std::string& key) {
  const std::size_t at = json.find("\"" + key + "\": ");
  return at == std::string::npos ? -1.0 : std::atof(json.c_str() + at + key.size() + 4);
}

TEST(CantileverReference, CalculiXGivesTheStoredDeflections) {
  if (std::system("command -v ccx > /dev/null 2>&1") != 0) GTEST_SKIP() << "ccx (calculix-ccx) is not installed";
  const std::string out = run("python3 '" OCTOCUT_SOURCE_DIR
                              "/tests/sim/reference/cantilever_ccx.py' --meshes 60x12x12 --nu 0.3,0.49");
  const double nu03 = value(out, "nu=0.3 C3D20R 60x12x12"), nu049 = value(out, "nu=0.49 C3D20R 60x12x12");
  EXPECT_NEAR(nu03, octocut::test::kCantileverTipNu03, 1e-6 * octocut::test::kCantileverTipNu03) << out;
  EXPECT_NEAR(nu049, octocut::test::kCantileverTipNu049, 1e-6 * octocut::test::kCantileverTipNu049) << out;
}

}  // namespace
