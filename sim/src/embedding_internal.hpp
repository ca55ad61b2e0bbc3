#pragma once
// Private helpers of the surface embedding's source files (zcurve.cpp, embed_vertex.cpp, embedding.cpp,
// embedding_compose.cpp, embedding_update.cpp): input checks with the messages the public API documents. Defined in
// embedding.cpp.
#include <cstddef>
#include <span>
#include <string>

#include "octocut/sim/types.hpp"

namespace octocut::sim::detail {

/// "vertex 12 (nan, 0, 1)"-style description of point i of a list, for error messages; `what` names the list.
std::string describe_point(const char* what, std::size_t i, const Vec3& p);

/// Throws std::invalid_argument when an index list has an entry outside [0, n) or a duplicate; `what` names the list.
void check_index_list(std::span<const int> list, std::size_t n, const char* what);

/// Throws std::invalid_argument naming the first non-finite point; `what` names the list.
void check_finite(std::span<const Vec3> points, const char* what);

}  // namespace octocut::sim::detail
