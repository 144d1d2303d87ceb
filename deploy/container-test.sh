#!/usr/bin/env bash
# Builds the container image from the Dockerfile with podman, runs cloudbake-server in it and
# checks it from the host as a farm would use it (docs/deployment.md, "Container"):
#   - every binary's shared libraries resolve inside the image (deploy/runtime-packages.txt);
#   - it runs as a non-root user and starts with no flags, its state on the image's volume;
#   - the standard gRPC health service answers SERVING;
#   - `cloudctl submit examples/perlin_cloud.json` from the host bakes through it, and the EXR and
#     VDB it downloads read back;
#   - the Prometheus endpoint reports the finished job;
#   - SIGTERM stops it with exit status 0 within the grace period, and a new container on the
#     same volume still knows the job.
# It prints the image's size, what dominates it, and the build time.
#
# No registry is needed: the Debian 12 base is bootstrapped with debootstrap and imported as
# localhost/debian:12 (kept in podman's store and as a tarball under $CONTAINER_CACHE, so later
# runs on the machine skip it). Skips, saying why, where podman cannot run containers at all;
# any failure after that is a failure. Uses the host's build of cloudctl and cloudbake
# (${BUILD_DIR:-build}). Needs root (rootful podman).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${BUILD_DIR:-$root/build}"
cache="${CONTAINER_CACHE:-/var/cache/cloudbake-container}"
image="${CONTAINER_IMAGE:-localhost/cloudbake:test}"
base="localhost/debian:12"
grace_s=10  # the server drains in about 3 s (docs/deployment.md); the pod spec allows 15 s
# runc, not crun ("cgroups in hybrid mode not supported" here); explicit limits, because
# podman's defaults ask for an RLIMIT_NPROC the kernel refuses.
opts=(--runtime /usr/sbin/runc --ulimit nofile=1024:1024 --ulimit nproc=1024:1024)

say() { echo "container-test: $*"; }
fail() {
  echo "container-test: FAILED: $*" >&2
  exit 1
}
skip() {
  say "SKIPPED: $*"
  exit 0
}

command -v podman >/dev/null || skip "podman is not installed (apt-get install podman runc debootstrap)"
[ -x /usr/sbin/runc ] || skip "/usr/sbin/runc is not installed (apt-get install runc)"
[ "$(id -u)" = 0 ] || skip "needs root for rootful podman"
for b in client/cloudctl tools/cloudbake/cloudbake; do
  [ -x "$build/$b" ] || fail "$build/$b is missing: build the project first (deploy/build.sh)"
done

ensure_base() {
  podman image exists "$base" && return 0
  local tarball="$cache/debian-12-minbase.tar"
  if [ ! -s "$tarball" ]; then
    command -v debootstrap >/dev/null || skip "debootstrap is not installed"
    mkdir -p "$cache"
    local rootfs
    rootfs="$(mktemp -d)"
    say "bootstrapping Debian 12 (minbase) into $rootfs"
    debootstrap --variant=minbase bookworm "$rootfs" http://deb.debian.org/debian >/dev/null
    rm -rf "$rootfs"/var/cache/apt/*.bin "$rootfs"/var/cache/apt/archives/*.deb \
      "$rootfs"/var/lib/apt/lists/*
    tar -C "$rootfs" -cf "$tarball.tmp" . && mv "$tarball.tmp" "$tarball"
    rm -rf "$rootfs"
  fi
  podman import "$tarball" "$base" >/dev/null
}
ensure_base
podman run --rm "${opts[@]}" --network=host "$base" true ||
  skip "podman cannot run a container on this machine (see the error above)"

say "building $image"
t0=$(date +%s)
podman build --pull=never "${opts[@]}" --network=host --build-arg "BASE=$base" -t "$image" \
  -f "$root/Dockerfile" "$root" >"${CONTAINER_BUILD_LOG:-/dev/null}" ||
  fail "podman build failed (set CONTAINER_BUILD_LOG=FILE to keep its output)"
build_s=$(($(date +%s) - t0))

tmp="$(mktemp -d)"
name="cloudbake-test-$$"
volume="cloudbake-test-$$"
cleanup() {
  podman rm -f "$name" "$name-2" >/dev/null 2>&1 || true
  podman volume rm -f "$volume" >/dev/null 2>&1 || true
  rm -rf "$tmp"
}
trap cleanup EXIT

in_image() { podman run --rm "${opts[@]}" --network=host --entrypoint /bin/sh "$image" -c "$1"; }

# Every binary's libraries resolve inside the image.
in_image 'for b in /opt/cloudbake/bin/*; do echo "== $b"; ldd "$b"; done' >"$tmp/ldd.txt"
if grep -q "not found" "$tmp/ldd.txt"; then
  grep -B50 "not found" "$tmp/ldd.txt" | grep -E "^==|not found" >&2
  fail "a binary's shared library is missing from the image: add its package to deploy/runtime-packages.txt"
fi
for bin in cloudbake-server cloudbake cloudctl; do
  grep -q "^== /opt/cloudbake/bin/$bin$" "$tmp/ldd.txt" || fail "the image has no $bin"
done
uid=$(in_image 'id -u')
[ "$uid" != 0 ] || fail "the image runs as root"
in_image 'command -v g++ c++ cmake >/dev/null' && fail "the runtime image holds a compiler"

# The server as documented: no flags; listen and metrics addresses from the environment (port 0:
# the server picks and logs them), the state on the image's volume.
start() {
  podman run -d --name "$1" "${opts[@]}" --network=host \
    -e CLOUDBAKE_LISTEN=127.0.0.1:0 -e CLOUDBAKE_METRICS_LISTEN=127.0.0.1:0 \
    -v "$volume:/var/lib/cloudbake" "$image" >/dev/null
  address=""
  for _ in $(seq 1 100); do
    address=$(podman logs "$1" 2>&1 | grep -o 'listening on 127\.0\.0\.1:[0-9]*' | head -1 |
      sed 's/listening on //') || true
    [ -n "$address" ] && break
    [ "$(podman inspect --format '{{.State.Running}}' "$1")" = true ] ||
      { podman logs "$1" >&2; fail "the server exited at start"; }
    sleep 0.2
  done
  [ -n "$address" ] || { podman logs "$1" >&2; fail "the server did not start"; }
  metrics=$(podman logs "$1" 2>&1 | grep -o 'metrics on http://[0-9.:]*/metrics' | head -1 |
    sed 's/metrics on //')
}
podman volume create "$volume" >/dev/null
start "$name"
say "server on $address, metrics on $metrics"
cloudctl=("$build/client/cloudctl" --server "$address" --timeout 10)
"${cloudctl[@]}" health >/dev/null || fail "the gRPC health service is not SERVING"

t0=$(date +%s.%N)
"${cloudctl[@]}" submit "$root/examples/perlin_cloud.json" --out "$tmp/out" >/dev/null \
  2>"$tmp/submit.err" || { cat "$tmp/submit.err" >&2; podman logs "$name" >&2; fail "cloudctl submit failed"; }
submit_s=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { print b - a }')
"$build/tools/cloudbake/cloudbake" preview "$tmp/out/side.exr" --out "$tmp/side.png" \
  >/dev/null || fail "side.exr does not read back"
"$build/tools/cloudbake/cloudbake" bake-slice "$tmp/out/bake.vdb" --grid density \
  --png "$tmp/slice.png" >/dev/null || fail "bake.vdb does not read back"

scrape="$(python3 -c 'import sys, urllib.request; print(urllib.request.urlopen(sys.argv[1], timeout=10).read().decode())' "$metrics")"
echo "$scrape" | grep -q '^cloudbake_jobs{state="SUCCEEDED"} 1$' ||
  fail "metrics do not count the succeeded job"
echo "$scrape" | grep -q '^cloudbake_job_seconds_count{method="pointcloud",outcome="SUCCEEDED"} 1$' ||
  fail "metrics have no job_seconds sample for the job"

t0=$(date +%s.%N)
podman kill --signal TERM "$name" >/dev/null
status=$(timeout "$grace_s" podman wait "$name") || fail "no exit within ${grace_s} s of SIGTERM"
stop_s=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { print b - a }')
[ "$status" = 0 ] || fail "exit status $status after SIGTERM"
podman logs "$name" 2>&1 | grep -q "cloudbake-server stopped" || fail "no graceful stop in the log"

start "$name-2"
job=$(grep -o 'job j[0-9a-f]* submitted' "$tmp/submit.err" | cut -d' ' -f2)
"$build/client/cloudctl" --server "$address" status "$job" | grep -q SUCCEEDED ||
  fail "a new container on the same volume does not know job $job"
podman kill --signal TERM "$name-2" >/dev/null
timeout "$grace_s" podman wait "$name-2" >/dev/null || fail "second container did not stop"

size=$(podman image inspect --format '{{.Size}}' "$image")
say "image $image: $((size / 1000000)) MB; built in ${build_s} s (layers cached by podman count as 0)"
say "submit through the container: $(printf %.1f "$submit_s") s; stop after SIGTERM: $(printf %.1f "$stop_s") s"
say "largest parts of the image (MB):"
in_image 'du -sm /usr/lib/x86_64-linux-gnu/* /opt/cloudbake /usr/share /var/lib/dpkg /usr/bin 2>/dev/null |
  sort -rn | head -8' | sed 's/^/  /'
say "passed"
