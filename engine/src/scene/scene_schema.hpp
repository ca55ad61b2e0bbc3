#pragma once
// Private to the engine: the scene schema as data (one Entry per key), the validator that checks a parsed document
// against it and fills in defaults, and the message helpers shared with the loader.
#include <array>
#include <cstddef>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace octocut::engine::schema {

/// The JSON shape an entry accepts.
enum class Type {
  number,        ///< a finite JSON number
  integer,       ///< a JSON integer (a float with an integral value is accepted too)
  boolean,       ///< true or false
  string,        ///< any string
  enumeration,   ///< one of the strings in `choices`
  number_array,  ///< exactly `length` finite numbers
  object,        ///< an object whose keys are `children`
  object_array,  ///< an array of objects whose keys are `children`
  box_or_path,   ///< a mesh path (string), or an object whose keys are `children`
  checks,        ///< a free-form object: JSON pointer into report.json -> check (the `expected` block, expected.hpp)
  number_map,    ///< an object of finite numbers in `range`, its keys among `choices`, at least `min_items` of them
};

/// Bounds on a number or integer. Each bound is optional and inclusive unless marked exclusive.
struct Range {
  std::optional<double> min;
  bool min_exclusive = false;
  std::optional<double> max;
  bool max_exclusive = false;
};

/// One key of the scene format, with everything the validator and the documentation need.
struct Entry {
  std::string key;  ///< key inside the parent object (empty for the document)
  Type type = Type::object;
  std::string doc;                              ///< one-sentence description, with units
  bool required = false;                        ///< absence is an error
  std::optional<nlohmann::json> default_value;  ///< inserted when the key is absent; none: the key stays absent
  std::string default_doc;                      ///< default column text when the loader computes the default
  Range range;                                  ///< number, integer, and each element of a number_array
  std::vector<std::string> choices;             ///< enumeration
  std::size_t length = 0;                       ///< number_array
  std::size_t min_items = 0;                    ///< object_array: fewest items allowed
  std::vector<Entry> children;  ///< object keys; keys of each object_array item; box_or_path's object form
};

// ---- building schemas (the scene's, and other documents' such as the cut-timing baseline) ---------------------------

Range make_range(std::optional<double> min, bool min_exclusive, std::optional<double> max, bool max_exclusive);
Range greater_than(double min);                ///< (min, inf)
Range at_least(double min);                    ///< [min, inf)
Range closed(double min, double max);          ///< [min, max]
Range open_closed(double min, double max);     ///< (min, max]
Range open(double min, double max);            ///< (min, max)
Range closed_open(double min, double max);     ///< [min, max)

Entry make_entry(std::string key, Type type, std::string doc);
Entry number(std::string key, std::optional<double> default_value, Range range, std::string doc);
Entry integer(std::string key, std::optional<long long> default_value, Range range, std::string doc);
Entry boolean(std::string key, bool default_value, std::string doc);
Entry string(std::string key, std::string doc);
Entry choice(std::string key, std::vector<std::string> choices, std::string default_value, std::string doc);
Entry vec3(std::string key, std::optional<std::array<double, 3>> default_value, std::string doc);
/// An object that defaults to `{}`, so that its own children's defaults get filled in.
Entry object(std::string key, std::vector<Entry> children, std::string doc);
/// An array of objects that defaults to `[]`; `item` lists the keys of each element.
Entry object_array(std::string key, std::vector<Entry> item, std::string doc);
/// A mesh path or an object with the keys `children`.
Entry box_or_path(std::string key, std::vector<Entry> children, std::string doc);
/// An object of numbers in `range` whose keys are among `keys`, with at least `min_items` of them.
Entry number_map(std::string key, std::vector<std::string> keys, Range range, std::size_t min_items, std::string doc);
/// The entry, required: absence is an error, and it has no default.
Entry required(Entry entry);
/// An optional key with no default: when absent it stays absent.
Entry optional(Entry entry);
/// The entry with its numbers (each element of a number array) in `range`.
Entry ranged(Entry entry, Range range);

/// Returns the schema of a whole scene document: an object entry with an empty key.
const Entry& scene_schema();

/// Checks `value`, found at JSON pointer `pointer` of scene file `file`, against `entry` and its children, and
/// inserts the default of every absent key that has one. Throws SceneError at the first violation.
void validate(nlohmann::json& value, const Entry& entry, const std::string& pointer, const std::string& file);

/// Throws SceneError with the message `<file>: <pointer>: <what>` (`<file>: <what>` for the document itself).
[[noreturn]] void fail(const std::string& file, const std::string& pointer, const std::string& what);

/// Returns the JSON pointer of key `key` of the value at `parent`, escaping '~' as "~0" and '/' as "~1".
std::string join_pointer(const std::string& parent, const std::string& key);

/// Returns the JSON pointer of element `index` of the array at `parent`.
std::string join_pointer(const std::string& parent, std::size_t index);

/// Formats a number for messages and documentation: integral values below 1e6 without a fraction, everything else
/// in the shortest form that reads back to the same double ("0.001", "1e+12", "inf").
std::string format_number(double value);

}  // namespace octocut::engine::schema
