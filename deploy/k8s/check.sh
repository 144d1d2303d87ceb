#!/usr/bin/env bash
# Validates deploy/k8s/base offline (deploy/k8s/check/check.cjs): the Kubernetes API schema
# (npm kubernetes-models, installed once into $K8S_CHECK_CACHE) and cloudbake's own rules:
# probes on the server's port, every flag variable known to `cloudbake-server --help`, the image
# tag equal to the server's version, resources matching --threads, non-root and read-only root.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
build="${BUILD_DIR:-$root/build}"
cache="${K8S_CHECK_CACHE:-/var/cache/cloudbake-k8s-check}"
server="$build/server/cloudbake-server"
[ -x "$server" ] || { echo "k8s check: $server is missing: build first" >&2; exit 1; }
command -v node >/dev/null && command -v npm >/dev/null ||
  { echo "k8s check: needs node and npm (apt-get install nodejs npm)" >&2; exit 1; }
mkdir -p "$cache"
if ! cmp -s "$root/deploy/k8s/check/package.json" "$cache/package.json" ||
  [ ! -d "$cache/node_modules/kubernetes-models" ]; then
  cp "$root/deploy/k8s/check/package.json" "$cache/package.json"
  (cd "$cache" && npm install --no-audit --no-fund --loglevel=error >/dev/null)
fi
help="$(mktemp)"
trap 'rm -f "$help"' EXIT
"$server" --help >"$help"
version="$("$server" --version | awk '{print $2}')"
NODE_PATH="$cache/node_modules" node "$root/deploy/k8s/check/check.cjs" \
  "$root/deploy/k8s/base" "$help" "$version"
# The farm's Indexed Jobs, generated from a plan of the bundled endless animation.
farm="$(mktemp -d)"
trap 'rm -f "$help"; rm -rf "$farm"' EXIT
"$build/tools/cloudbake/cloudbake" plan "$root/examples/endless_cloud.json" --tasks 4 --json \
  >"$farm/plan.json"
python3 "$root/deploy/k8s/farm/plan-to-jobs" "$farm/plan.json" --out "$farm/jobs" >/dev/null
NODE_PATH="$cache/node_modules" node "$root/deploy/k8s/check/farm.cjs" "$farm/jobs" "$farm/plan.json"
