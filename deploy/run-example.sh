#!/usr/bin/env bash
# The README's main job: install, build, start cloudbake-server on loopback, bake the bundled
# Perlin-cloud example shot with `cloudctl submit`, download the EXR and VDB, stop the server.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/deploy/install-deps.sh"
bash "$root/deploy/build.sh"
build="${BUILD_DIR:-$root/build}"
out="${OUT_DIR:-$root/out/perlin_cloud}"
state="${STATE_DIR:-$root/out/server-state}"
log="$root/out/server.log"
mkdir -p "$out" "$state" "$(dirname "$log")"

# Port 0: the OS picks a free port, which the server logs.
"$build/server/cloudbake-server" --listen 127.0.0.1:0 --cache-dir "$state" >"$log" 2>&1 &
server_pid=$!
trap 'kill "$server_pid" 2>/dev/null; wait "$server_pid" 2>/dev/null || true' EXIT
address=""
for _ in $(seq 1 100); do
  address=$(grep -o 'listening on 127\.0\.0\.1:[0-9]*' "$log" | head -1 | sed 's/listening on //') || true
  [ -n "$address" ] && break
  kill -0 "$server_pid" 2>/dev/null || { cat "$log" >&2; echo "run-example: server failed" >&2; exit 1; }
  sleep 0.1
done
[ -n "$address" ] || { cat "$log" >&2; echo "run-example: server did not start" >&2; exit 1; }
echo "run-example: cloudbake-server on $address (log: $log)"

"$build/client/cloudctl" --server "$address" submit "$root/examples/perlin_cloud.json" --out "$out"
"$build/tools/cloudbake/cloudbake" preview "$out/side.exr" --out "$out/side.png" >/dev/null
echo "run-example: outputs are in $out (side.exr: linear radiance, the cloud premultiplied over its"
echo "  background and beauty layers; bake.vdb: the baked light; side.png: a preview to look at)"
