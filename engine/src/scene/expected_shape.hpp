#pragma once
// Private to the engine: the shape rules of one member of a scene's `expected` block, shared by the scene schema
// (which rejects a malformed block at load time) and the checker in expected.cpp (which must agree with it).
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

namespace octocut::engine::expected_detail {

/// What is wrong with one member of an `expected` block: `where` is the JSON pointer below the member's own ("" for
/// the member itself, "/rel" for its `rel` key), `what` the problem.
struct ShapeProblem {
  std::string where;
  std::string what;
};

/// Checks one member `key: value` of an `expected` block. The key must be a JSON pointer into report.json (it starts
/// with '/', and '~' is followed by '0' or '1'). The value is a bare string, boolean or finite number; or
/// {"value": v, "rel": r, "abs": a} with a finite number v and optional finite r, a >= 0; or {"min": a, "max": b}
/// with at least one finite bound and a <= b. Returns nullopt when the member is well-formed.
std::optional<ShapeProblem> member_problem(const std::string& key, const nlohmann::json& value);

}  // namespace octocut::engine::expected_detail
