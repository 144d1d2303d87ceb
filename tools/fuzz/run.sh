#!/usr/bin/env bash
# Builds the libFuzzer targets of tests/fuzz (clang, ASan + UBSan) into ${FUZZ_BUILD_DIR:-build-fuzz}
# and runs each for SECONDS (default 60) from a seed corpus made here from the test assets: the
# example shots, small OBJ and PLY meshes, and a VDB and an EXR rendered by the main build's
# `cloudbake` (${BUILD_DIR:-build}). The corpus grows in BUILD/fuzz-work/corpus across runs.
# Prints runs, coverage and findings per target; exits 1 when any target found a crash, a
# sanitizer report, a leak, a timeout (10 s per input) or an input that needs over 2 GB
# (-rss_limit_mb; -malloc_limit_mb 1024 catches a single huge allocation). Reproduce a finding
# with `BUILD/tests/fuzz/fuzz_TARGET FILE`. CI runs it for 20 s a target.
#   Usage: tools/fuzz/run.sh [SECONDS]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
seconds="${1:-${FUZZ_SECONDS:-60}}"
build="${FUZZ_BUILD_DIR:-$root/build-fuzz}"
main_build="${BUILD_DIR:-$root/build}"
work="$build/fuzz-work"
targets=(fuzz_shot_parser fuzz_mesh_reader fuzz_vdb_reader fuzz_exr_reader)
[ -x "$main_build/tools/cloudbake/cloudbake" ] ||
  { echo "fuzz: $main_build/tools/cloudbake/cloudbake is missing: build first" >&2; exit 1; }

cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_COMPILER=clang++ -DCLOUDBAKE_FUZZ=ON -DCLOUDBAKE_BUILD_TESTS=OFF >/dev/null
cmake --build "$build" -j "${JOBS:-$(nproc)}" --target "${targets[@]}"

seeds="$work/seeds"
rm -rf "$seeds"
mkdir -p "$seeds"/{fuzz_shot_parser,fuzz_mesh_reader,fuzz_vdb_reader,fuzz_exr_reader} "$work/findings"
cp "$root"/examples/*.json "$seeds/fuzz_shot_parser/"
# Mesh seeds: the first byte picks the reader (odd: OBJ, even: PLY).
printf '1v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n' \
  >"$seeds/fuzz_mesh_reader/tetra.obj"
printf '0ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n3 0 2 3\n3 1 2 3\n' \
  >"$seeds/fuzz_mesh_reader/tetra.ply"
# A small VDB (the density of a sphere) and EXR, rendered by the main build.
cat >"$work/seed_shot.json" <<'JSON'
{"version": 1, "name": "seed",
 "volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}},
 "medium": {"extinction": 2, "albedo": 0.9, "phase": {"type": "hg", "g": 0.5}},
 "lighting": {"sun": {"direction": [0.3, 0, 1], "irradiance": [1, 1, 1]}},
 "bake": {"method": "pathtrace", "samples": 1, "seed": 1},
 "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 0],
   "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 2.5}, "resolution": [8, 8]}],
 "outputs": {"exr": true, "vdb": true, "vdb_voxel_size": 0.25}}
JSON
"$main_build/tools/cloudbake/cloudbake" render "$work/seed_shot.json" --out "$work/render" >/dev/null
cp "$work/render/bake.vdb" "$seeds/fuzz_vdb_reader/"
cp "$work/render/v.exr" "$seeds/fuzz_exr_reader/"

export LSAN_OPTIONS="suppressions=$root/tools/fuzz/lsan.supp:print_suppressions=0"
# A request beyond what the machine can give fails (std::bad_alloc, which the readers turn into
# InputError) as it would in the server, instead of ending the process.
export ASAN_OPTIONS="allocator_may_return_null=1"
failed=0
for t in "${targets[@]}"; do
  mkdir -p "$work/corpus/$t"
  log="$work/$t.log"
  set +e
  "$build/tests/fuzz/$t" -max_total_time="$seconds" -rss_limit_mb=2048 -malloc_limit_mb=1024 \
    -timeout=10 -print_final_stats=1 -artifact_prefix="$work/findings/$t-" \
    "$work/corpus/$t" "$seeds/$t" >"$log" 2>&1
  rc=$?
  set -e
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo 0)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*' || echo '?')
  corpus=$(ls "$work/corpus/$t" | wc -l)
  known=""
  if [ "$rc" -ne 0 ]; then
    while IFS=$'\t' read -r pattern what; do
      case "$pattern" in '#'* | '') continue ;; esac
      grep -qF "$pattern" "$log" && known="$what"
    done <"$root/tools/fuzz/known-third-party.txt"
  fi
  if [ -n "$known" ]; then
    echo "fuzz: $t: known third-party finding after $runs runs (not ours, not failing): $known"
  elif [ "$rc" -ne 0 ]; then
    failed=1
    echo "fuzz: $t: FINDING after $runs runs (exit $rc); log $log, input in $work/findings/"
    grep -E "ERROR|SUMMARY|==[0-9]+==|deadly|uncaught|Test unit written" "$log" | head -8 | sed 's/^/  /'
  else
    echo "fuzz: $t: $runs runs in ${seconds} s, coverage $cov, corpus $corpus inputs, no findings"
  fi
done
exit "$failed"
