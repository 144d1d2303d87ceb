#!/usr/bin/env bash
# Configures and builds cloudbake (Release) into ${BUILD_DIR:-build}. Extra args go to cmake.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${BUILD_DIR:-$root/build}"
jobs="${JOBS:-$(nproc)}"
gen=()
command -v ninja >/dev/null && gen=(-G Ninja)
# Warnings are errors in every build (CLOUDBAKE_WERROR=OFF to relax): the README's main job and
# its test command then share one build instead of rebuilding everything for a changed flag.
cmake -S "$root" -B "$build" "${gen[@]}" -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-Release}" \
  -DCLOUDBAKE_WERROR="${CLOUDBAKE_WERROR:-ON}" "$@"
cmake --build "$build" -j "$jobs"
