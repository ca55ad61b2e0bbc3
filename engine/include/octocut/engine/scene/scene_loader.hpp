#pragma once
// Scene loading (SPEC §5): reads a JSON scene file, applies command-line overrides, validates the document against
// the schema in scene_schema.cpp, fills in defaults and returns the plain `Scene` struct.
#include <stdexcept>
#include <string>
#include <vector>

#include "octocut/engine/scene/scene.hpp"

namespace octocut::engine {

/// Bad input: an unreadable or malformed scene file, a value the schema rejects, or a malformed override. The
/// message names the file and the JSON pointer (`<file>: <pointer>: <what>`), or the file, line and column for
/// malformed JSON (`<file>:<line>:<column>: malformed JSON: <detail>`). The command line turns it into exit code 2.
class SceneError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Loads, validates and completes the scene at `path`. Each entry of `overrides` has the form
/// `/json/pointer=value` and replaces (or creates) that key in the parsed document before validation; the value is
/// parsed as JSON when it is valid JSON and taken as a string otherwise. Mesh paths are resolved against the scene
/// file's directory and must exist. Throws SceneError on any bad input.
Scene load_scene(const std::string& path, const std::vector<std::string>& overrides = {});

/// Returns the Markdown reference of the scene format, generated from the schema: a title, a short introduction
/// and one table row per key (pointer, type, range, default, description). `docs/scene-format.md` holds its output
/// and a test checks that the two agree.
std::string scene_format_markdown();

}  // namespace octocut::engine
