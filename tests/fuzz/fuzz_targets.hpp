#pragma once
// The fuzzed entry points (issue 18): each takes arbitrary bytes and must return without crashing, hanging or
// tripping a sanitizer, whatever the bytes. libFuzzer drives them in the `fuzz` build (tests/fuzz/fuzz_main.cpp,
// OCTOCUT_FUZZ=ON with clang); the CI test fuzz_regression_test replays the seed corpus and every crasher found so far
// (tests/fuzz/corpus/<target>/, tests/fuzz/regressions/<target>/) through the same functions.
#include <cstddef>
#include <cstdint>
#include <string>

namespace octocut::fuzz {

/// A scene file: load_scene on the bytes (validation errors are SceneError; nothing else may escape).
int scene(const std::uint8_t* data, std::size_t size);
/// A PLY file: octocut's own PLY reader on the bytes (errors are MeshError).
int ply(const std::uint8_t* data, std::size_t size);
/// Any mesh file: the first byte picks the extension (.obj, .stl, .off, .ply, .gltf), the rest is the file, loaded
/// and validated by load_mesh (assimp for all but PLY).
int mesh(const std::uint8_t* data, std::size_t size);
/// A cut sequence on a 1 cm box: every 6 bytes place a blade (cylinder or box prism, snapped to the surface's grid so
/// that walls land coplanar, coincident, through earlier holes and at vertices and edges) and cut now. After every
/// cut the state must stay finite and S closed, manifold and oriented; a violation aborts (a finding).
int cuts(const std::uint8_t* data, std::size_t size);
/// The cut sequence of `cuts`, returning how many of its cuts were skipped (a skip is no finding for the fuzzer, but
/// the seed corpus must cut without one: fuzz_regression_test).
int cut_skips(const std::uint8_t* data, std::size_t size);

/// The target named `name` ("scene", "ply", "mesh", "cuts"); nullptr for another name.
using Target = int (*)(const std::uint8_t*, std::size_t);
Target target(const std::string& name);

}  // namespace octocut::fuzz
