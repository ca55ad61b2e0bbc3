#pragma once
// The cut pipeline (SPEC §4) lands with the cutting issue. Until then this module only reports its stage names, so
// that the dependency chain app -> engine -> cutting -> sim exists from the start.
#include <array>
#include <string_view>

namespace octocut::cutting {

/// The stages of one cut, in order, as they are named in the report's `cuts[].ms` (SPEC §8).
inline constexpr std::array<std::string_view, 7> kStageNames = {
    "back_transform", "surface", "material_graph", "refine", "node_split", "embedding", "solver_update"};

/// True when this build contains the cut pipeline.
bool pipeline_available();

}  // namespace octocut::cutting
