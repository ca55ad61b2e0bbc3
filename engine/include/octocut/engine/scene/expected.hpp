#pragma once
// Scene regression checks (SPEC §10): a scene's `expected` block maps JSON pointers into report.json to checks, and
// `octocut run SCENE --check` compares a run's report against them; `--regenerate` rewrites the block on purpose.
// The texts here are JSON; no JSON types appear in this header.
//
// The checks, one per member of the block (`"<pointer>": <check>`):
//   - a bare string or boolean: the report's value must be equal;
//   - a bare integer: the report's value must be a number equal to it;
//   - a bare non-integral number v: |x - v| <= 1e-9 |v|;
//   - {"value": v, "rel": r, "abs": a}: |x - v| <= max(a, r |v|) (r and a default to 0);
//   - {"min": a, "max": b}: a <= x <= b (either bound may be left out).
// A pointer that the report lacks is a failure.
#include <cstddef>
#include <string>
#include <vector>

namespace octocut::engine {

/// The relative tolerance of a bare non-integral number in an `expected` block.
inline constexpr double k_expected_default_rel = 1e-9;

/// Checks the report `report_json` (the text of report.json) against the block `expected_json` (the text of a JSON
/// object) and returns one line per failed check, in the block's order, for example
/// `/counts/elements: 812 not in [700, 800]`; empty when every check passes. Throws std::invalid_argument when
/// either text is not valid JSON or the block is malformed (the message names the member's pointer).
std::vector<std::string> check_expected(const std::string& expected_json, const std::string& report_json);

/// Returns the block `expected_json` with every check moved to the report's current value, the same pointers in the
/// same order, and the same kinds of tolerance:
///   - a bare value becomes the report's value;
///   - {"value", "rel", "abs"} gets the new value and keeps `rel` and `abs`;
///   - {"min": a, "max": b} is moved and scaled around the new value x: with the old midpoint m = (a + b) / 2, the
///     new bounds are x - (m - a) |x| / |m| and x + (b - m) |x| / |m| (the same relative half-widths), or
///     x - (m - a) and x + (b - m) when m or x is 0 (the same absolute half-widths). When a, b and x are all
///     integers the bounds are rounded outward to integers; otherwise each bound is rounded to 6 significant
///     digits unless that would leave x outside.
///   - a one-sided {"min"} or {"max"} is a limit rather than a measured value, and is kept as it is.
/// A check whose pointer the report lacks, or whose report value has the wrong type, is kept as it is (check_expected
/// then reports it). The text has one member per line, check objects on one line, 2-space indentation. Throws
/// std::invalid_argument like check_expected.
std::string regenerate_expected(const std::string& expected_json, const std::string& report_json);

/// The number of checks in the block `expected_json`. Throws std::invalid_argument when it is not a JSON object.
std::size_t expected_check_count(const std::string& expected_json);

/// The text of the value of the top-level "expected" member of the scene file text `scene_text`, exactly as written
/// (so its members keep their order); "" when there is none. Throws std::invalid_argument when `scene_text` is not a
/// JSON object.
std::string expected_block_text(const std::string& scene_text);

/// Returns `scene_text` with the value of its top-level "expected" member replaced by `expected_block` (a JSON
/// object's text), indented to the member's own indentation; every other byte of the file is kept. Throws
/// std::invalid_argument when `scene_text` is not a JSON object with an "expected" member.
std::string replace_expected_block(const std::string& scene_text, const std::string& expected_block);

}  // namespace octocut::engine
