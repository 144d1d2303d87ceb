#!/usr/bin/env bash
# The README's main job: install, build, and render the bundled Perlin-cloud example shot.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/deploy/install-deps.sh"
bash "$root/deploy/build.sh"
out="${OUT_DIR:-$root/out/perlin_cloud}"
"${BUILD_DIR:-$root/build}/tools/cloudbake/cloudbake" render "$root/examples/perlin_cloud.json" \
  --out "$out"
echo "run-example: outputs are in $out"
