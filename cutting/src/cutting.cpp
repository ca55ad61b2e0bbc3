#include "octocut/cutting/cutting.hpp"

namespace octocut::cutting {

bool pipeline_available() { return false; }

}  // namespace octocut::cutting
