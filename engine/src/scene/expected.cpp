// Scene regression checks: the shape rules of an `expected` block, the checker, the regenerator, and the splice that
// puts a regenerated block back into a scene file without touching the rest of it.
#include "octocut/engine/scene/expected.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "scene/expected_shape.hpp"
#include "scene/scene_schema.hpp"

namespace octocut::engine {
namespace expected_detail {

std::optional<ShapeProblem> member_problem(const std::string& key, const nlohmann::json& value) {
  using nlohmann::json;
  // The key: a JSON pointer into the report, never the whole report.
  if (!key.starts_with('/')) return ShapeProblem{"", "key must be a JSON pointer into report.json starting with '/'"};
  try {
    json::json_pointer pointer(key);
  } catch (const json::exception&) {
    return ShapeProblem{"", "key is not a JSON pointer: '~' must be followed by '0' or '1'"};
  }

  // A finite number, for messages below.
  const auto number_problem = [](const json& v, const std::string& where) -> std::optional<ShapeProblem> {
    if (!v.is_number()) return ShapeProblem{where, std::string("expected a number, got ") + v.type_name()};
    if (!std::isfinite(v.get<double>())) {
      return ShapeProblem{where, "must be a finite number, got " + schema::format_number(v.get<double>())};
    }
    return std::nullopt;
  };

  // A bare value.
  if (value.is_string() || value.is_boolean()) return std::nullopt;
  if (value.is_number()) return number_problem(value, "");
  if (!value.is_object()) {
    return ShapeProblem{"", std::string("expected a string, boolean, number, {\"value\", \"rel\", \"abs\"} or "
                                        "{\"min\", \"max\"}, got ") +
                                value.type_name()};
  }

  // A check object: known keys only, each a finite number, of one kind.
  for (const auto& item : value.items()) {
    const std::string& k = item.key();
    if (k != "value" && k != "rel" && k != "abs" && k != "min" && k != "max") {
      return ShapeProblem{schema::join_pointer("", k), "unknown key (expected value, rel, abs, min or max)"};
    }
    if (auto problem = number_problem(item.value(), "/" + k)) return problem;
    if ((k == "rel" || k == "abs") && item.value().get<double>() < 0.0) {
      return ShapeProblem{"/" + k, "must be >= 0, got " + schema::format_number(item.value().get<double>())};
    }
  }
  const bool has_value = value.contains("value");
  const bool has_bound = value.contains("min") || value.contains("max");
  if (has_value && has_bound) {
    return ShapeProblem{value.contains("min") ? "/min" : "/max", "cannot be combined with \"value\""};
  }
  if (!has_value && !has_bound) return ShapeProblem{"", "needs \"value\", or \"min\" and/or \"max\""};
  if (has_bound && (value.contains("rel") || value.contains("abs"))) {
    return ShapeProblem{value.contains("rel") ? "/rel" : "/abs", "only goes with \"value\", not with min/max"};
  }
  if (value.contains("min") && value.contains("max") && value["max"].get<double>() < value["min"].get<double>()) {
    return ShapeProblem{"/max", "must be >= min (" + schema::format_number(value["min"].get<double>()) + "), got " +
                                    schema::format_number(value["max"].get<double>())};
  }
  return std::nullopt;
}

}  // namespace expected_detail

namespace {

using nlohmann::ordered_json;

/// Parses `text` as a JSON object, naming `what` in the error.
ordered_json parse_object(const std::string& text, const std::string& what) {
  ordered_json value;
  try {
    value = ordered_json::parse(text);
  } catch (const ordered_json::exception& error) {
    throw std::invalid_argument(what + ": not valid JSON: " + error.what());
  }
  if (!value.is_object()) throw std::invalid_argument(what + ": expected a JSON object, got " + value.type_name());
  return value;
}

/// Throws std::invalid_argument when a member of the block is malformed.
void check_shape(const std::string& key, const ordered_json& value) {
  // The shape rules take nlohmann::json; the block's values are small, so a round trip through text is cheap.
  if (const auto problem = expected_detail::member_problem(key, nlohmann::json::parse(value.dump()))) {
    throw std::invalid_argument("expected block: " + schema::join_pointer("", key) + problem->where + ": " +
                                problem->what);
  }
}

/// The report's value at `pointer`, or nullptr when the report has none.
const ordered_json* find(const ordered_json& report, const std::string& pointer) {
  try {
    const ordered_json::json_pointer p(pointer);
    if (!report.contains(p)) return nullptr;
    return &report.at(p);
  } catch (const ordered_json::exception&) {
    return nullptr;
  }
}

/// A number for messages: integers as written, others in the shortest round-trip form.
std::string text_of(const ordered_json& value) {
  return value.is_number_float() ? schema::format_number(value.get<double>()) : value.dump();
}

/// A derived number (a tolerance) for messages: 6 significant digits.
std::string six_digits(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", value);
  return text;
}

/// The failure of one check against report value `x`, or "" when it passes.
std::string failure(const ordered_json& check, const ordered_json& x) {
  // Bare strings and booleans: equal.
  if (check.is_string() || check.is_boolean()) {
    if (x == check) return "";
    const char* kind = check.is_string() ? "a string" : "a boolean";
    if (x.type() != check.type()) return x.dump() + " is not " + kind + " (expected " + check.dump() + ")";
    return x.dump() + ", expected " + check.dump();
  }
  if (!x.is_number()) return x.dump() + " is not a number";
  const double v = x.get<double>();

  // Bare integers: equal.
  if (check.is_number_integer()) {
    return v == check.get<double>() ? "" : text_of(x) + ", expected " + check.dump();
  }

  // Values with a tolerance: a bare float (rel 1e-9) or {"value", "rel", "abs"}.
  if (check.is_number_float() || check.contains("value")) {
    const double want = check.is_number() ? check.get<double>() : check["value"].get<double>();
    const double rel = check.is_number() ? k_expected_default_rel : check.value("rel", 0.0);
    const double abs = check.is_number() ? 0.0 : check.value("abs", 0.0);
    const double tolerance = std::max(abs, rel * std::fabs(want));
    if (std::fabs(v - want) <= tolerance) return "";
    return text_of(x) + " not within " + schema::format_number(want) + " ± " + six_digits(tolerance);
  }

  // Ranges.
  const bool has_min = check.contains("min"), has_max = check.contains("max");
  const bool below = has_min && !(v >= check["min"].get<double>());
  const bool above = has_max && !(v <= check["max"].get<double>());
  if (!below && !above) return "";
  if (has_min && has_max) {
    return text_of(x) + " not in [" + text_of(check["min"]) + ", " + text_of(check["max"]) + "]";
  }
  return text_of(x) + (has_min ? " not >= " + text_of(check["min"]) : " not <= " + text_of(check["max"]));
}

/// `x` rounded to the nearest 6 significant digits.
double round_six_digits(double x) {
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", x);
  return std::strtod(text, nullptr);
}

/// Returns `check` moved to the report value `x` (see regenerate_expected for the rules).
ordered_json regenerated(const ordered_json& check, const ordered_json& x) {
  // Bare values take the report's value when the kinds agree.
  if (check.is_string()) return x.is_string() ? x : check;
  if (check.is_boolean()) return x.is_boolean() ? x : check;
  if (!x.is_number()) return check;
  if (check.is_number()) return x;
  const double v = x.get<double>();

  // {"value", "rel", "abs"}: the new value, the same tolerances, the same key order.
  if (check.contains("value")) {
    ordered_json out = check;
    out["value"] = x;
    return out;
  }

  // One-sided bounds are limits, kept as they are.
  if (!check.contains("min") || !check.contains("max")) return check;

  // Two-sided: the same relative half-widths around the new value (absolute ones when the midpoint or x is 0).
  const double a = check["min"].get<double>(), b = check["max"].get<double>();
  const double m = 0.5 * (a + b);
  const double scale = (m != 0.0 && v != 0.0) ? std::fabs(v) / std::fabs(m) : 1.0;
  double lo = v - (m - a) * scale, hi = v + (b - m) * scale;
  ordered_json out = check;
  const bool integers = check["min"].is_number_integer() && check["max"].is_number_integer() && x.is_number_integer();
  if (integers) {
    out["min"] = static_cast<long long>(std::floor(lo));
    out["max"] = static_cast<long long>(std::ceil(hi));
    return out;
  }
  // Short bounds, unless rounding would leave the value outside.
  if (round_six_digits(lo) <= v) lo = round_six_digits(lo);
  if (round_six_digits(hi) >= v) hi = round_six_digits(hi);
  out["min"] = lo;
  out["max"] = hi;
  return out;
}

/// A check as one line: `{"value": 0.5, "rel": 0.01}`, scalars as nlohmann writes them.
std::string one_line(const ordered_json& value) {
  if (!value.is_object()) return value.dump();
  std::string text = "{";
  for (const auto& item : value.items()) {
    if (text.size() > 1) text += ", ";
    text += ordered_json(item.key()).dump() + ": " + item.value().dump();
  }
  return text + "}";
}

// ---- a minimal scanner over JSON text, for splicing --------------------------------------------------------------

std::size_t skip_space(const std::string& text, std::size_t i) {
  while (i < text.size() && (text[i] == ' ' || text[i] == '\t' || text[i] == '\n' || text[i] == '\r')) ++i;
  return i;
}

/// `text[i]` is '"': returns the index just past the closing quote.
std::size_t skip_string(const std::string& text, std::size_t i) {
  for (++i; i < text.size(); ++i) {
    if (text[i] == '\\') {
      ++i;
    } else if (text[i] == '"') {
      return i + 1;
    }
  }
  throw std::invalid_argument("scene file: unterminated string");
}

/// Returns the index just past the JSON value that starts at `i`.
std::size_t skip_value(const std::string& text, std::size_t i) {
  if (i >= text.size()) throw std::invalid_argument("scene file: unexpected end");
  if (text[i] == '"') return skip_string(text, i);
  if (text[i] == '{' || text[i] == '[') {
    int depth = 0;
    while (i < text.size()) {
      const char c = text[i];
      if (c == '"') {
        i = skip_string(text, i);
        continue;
      }
      if (c == '{' || c == '[') ++depth;
      if (c == '}' || c == ']') --depth;
      ++i;
      if (depth == 0) return i;
    }
    throw std::invalid_argument("scene file: unbalanced brackets");
  }
  // A number or a literal runs to the next delimiter.
  while (i < text.size() && text[i] != ',' && text[i] != '}' && text[i] != ']' && text[i] != ' ' && text[i] != '\n' &&
         text[i] != '\r' && text[i] != '\t') {
    ++i;
  }
  return i;
}

}  // namespace

std::vector<std::string> check_expected(const std::string& expected_json, const std::string& report_json) {
  const ordered_json block = parse_object(expected_json, "expected block");
  const ordered_json report = parse_object(report_json, "report");
  std::vector<std::string> failures;
  for (const auto& item : block.items()) {
    check_shape(item.key(), item.value());
    const ordered_json* x = find(report, item.key());
    if (x == nullptr) {
      failures.push_back(item.key() + ": missing from the report");
      continue;
    }
    if (std::string why = failure(item.value(), *x); !why.empty()) failures.push_back(item.key() + ": " + why);
  }
  return failures;
}

std::string regenerate_expected(const std::string& expected_json, const std::string& report_json) {
  const ordered_json block = parse_object(expected_json, "expected block");
  const ordered_json report = parse_object(report_json, "report");
  std::string text = "{";
  for (const auto& item : block.items()) {
    check_shape(item.key(), item.value());
    const ordered_json* x = find(report, item.key());
    const ordered_json check = x == nullptr ? item.value() : regenerated(item.value(), *x);
    text += (text.size() > 1 ? ",\n  " : "\n  ") + ordered_json(item.key()).dump() + ": " + one_line(check);
  }
  return text + (text.size() > 1 ? "\n}" : "}");
}

namespace {

/// Where the value of the top-level "expected" member lies in `scene_text`: [value_start, value_end), and where its
/// key starts; nullopt when there is no such member.
struct MemberSpan {
  std::size_t key_start = 0, value_start = 0, value_end = 0;
};

std::optional<MemberSpan> find_expected_member(const std::string& scene_text) {
  // Walk the top-level object's members until "expected".
  std::size_t i = skip_space(scene_text, 0);
  if (i >= scene_text.size() || scene_text[i] != '{') throw std::invalid_argument("scene file: not a JSON object");
  i = skip_space(scene_text, i + 1);
  while (i < scene_text.size() && scene_text[i] == '"') {
    const std::size_t key_start = i;
    const std::size_t key_end = skip_string(scene_text, i);
    const std::string key = nlohmann::json::parse(scene_text.substr(key_start, key_end - key_start));
    i = skip_space(scene_text, key_end);
    if (i >= scene_text.size() || scene_text[i] != ':') throw std::invalid_argument("scene file: expected ':'");
    const std::size_t value_start = skip_space(scene_text, i + 1);
    const std::size_t value_end = skip_value(scene_text, value_start);
    if (key == "expected") return MemberSpan{key_start, value_start, value_end};
    i = skip_space(scene_text, value_end);
    if (i < scene_text.size() && scene_text[i] == ',') i = skip_space(scene_text, i + 1);
  }
  return std::nullopt;
}

}  // namespace

std::size_t expected_check_count(const std::string& expected_json) {
  return parse_object(expected_json, "expected block").size();
}

std::string expected_block_text(const std::string& scene_text) {
  const auto span = find_expected_member(scene_text);
  return span ? scene_text.substr(span->value_start, span->value_end - span->value_start) : std::string();
}

std::string replace_expected_block(const std::string& scene_text, const std::string& expected_block) {
  const auto span = find_expected_member(scene_text);
  if (!span) throw std::invalid_argument("scene file: no top-level \"expected\" member");

  // The member's indentation, when its key starts a line; every new line of the block gets it.
  const std::size_t newline = scene_text.rfind('\n', span->key_start);
  const std::size_t line_start = newline == std::string::npos ? 0 : newline + 1;
  std::string indent = scene_text.substr(line_start, span->key_start - line_start);
  if (indent.find_first_not_of(" \t") != std::string::npos) indent.clear();
  std::string block;
  for (const char c : expected_block) {
    block += c;
    if (c == '\n') block += indent;
  }
  return scene_text.substr(0, span->value_start) + block + scene_text.substr(span->value_end);
}

}  // namespace octocut::engine
