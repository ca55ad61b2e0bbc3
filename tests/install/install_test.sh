#!/usr/bin/env bash
# Installs a build tree into a temporary prefix, then configures, builds and runs tests/install/consumer against it
# (find_package(octocut CONFIG REQUIRED) + octocut::engine), as a simulator team's application would. Any failing
# step fails the test; the temporary folder is removed in every case.
# usage: install_test.sh BUILD_DIR SOURCE_DIR VERSION SCENE GENERATOR MAKE_PROGRAM CXX_COMPILER [LAUNCHER]
set -euo pipefail
build=$1 src=$2 version=$3 scene=$4 generator=$5 make_program=$6 cxx=$7 launcher=${8:-}

tmp=$(mktemp -d "${TMPDIR:-/tmp}/octocut-install-test.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
prefix=$tmp/prefix
fail() { echo "install test FAILED: $*" >&2; exit 1; }

echo "== cmake --install $build --prefix $prefix"
cmake --install "$build" --prefix "$prefix" >"$tmp/install.log" || { cat "$tmp/install.log"; fail "cmake --install"; }
for f in bin/octocut include/octocut/version.hpp include/octocut/sim/simulator.hpp include/octocut/cutting/cutting.hpp \
         include/octocut/engine/scene/scene_loader.hpp include/octocut/engine/run/world.hpp; do
  [ -f "$prefix/$f" ] || fail "$f not installed"
done
config=$(find "$prefix" -name octocutConfig.cmake)
[ -n "$config" ] || fail "octocutConfig.cmake not installed"
# The package must not point back into the build or source tree.
if grep -rn -e "$build" -e "$src" "$(dirname "$config")"; then fail "the installed package names the build or source tree"; fi

echo "== $prefix/bin/octocut --version"
got=$("$prefix/bin/octocut" --version) || fail "octocut --version exited non-zero"
[ "$got" = "octocut $version" ] || fail "octocut --version printed '$got', expected 'octocut $version'"

echo "== configure and build tests/install/consumer with CMAKE_PREFIX_PATH=$prefix"
args=(-G "$generator" -DCMAKE_MAKE_PROGRAM="$make_program" -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_BUILD_TYPE=Release
      -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_EXPORT_COMPILE_COMMANDS=ON)
[ -n "$launcher" ] && args+=(-DCMAKE_CXX_COMPILER_LAUNCHER="$launcher")
export CCACHE_BASEDIR=$tmp  # paths relative to the temporary folder: ccache hits across runs
cmake -S "$src/tests/install/consumer" -B "$tmp/build" "${args[@]}" || fail "configuring the consumer"
if grep -n -e "$build" -e "$src/[a-z]*/include" "$tmp/build/compile_commands.json"; then
  fail "the consumer compiles with the build or source tree's headers, not the installed ones"
fi
cmake --build "$tmp/build" || fail "building the consumer"

echo "== consumer $scene"
OCTOCUT_CACHE_DIR=$tmp/cache "$tmp/build/consumer" "$scene" 5 || fail "the consumer exited non-zero"
echo "install test passed"
