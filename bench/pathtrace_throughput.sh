#!/usr/bin/env bash
# Path-tracer throughput of the product (`cloudbake render`) on a shot, at 1 and 2 threads.
# Usage: bench/pathtrace_throughput.sh [SHOT] [SIZE] [SPP]
#   default: examples/disney_cloud.json (needs ../shared beside the repo) at 512x512, 64 spp.
# Prints wall and user-CPU seconds, pixel samples per second and peak memory per thread count
# (CPU seconds close to wall seconds at 2 threads mean another process held the other core).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
shot="${1:-$root/examples/disney_cloud.json}"
size="${2:-512}"
spp="${3:-64}"
bin="${BUILD_DIR:-$root/build}/tools/cloudbake/cloudbake"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
# Same shot at the requested resolution; written beside the original so relative paths resolve.
variant="$(dirname "$shot")/.bench_$(basename "$shot")"
trap 'rm -rf "$tmp" "$variant"' EXIT
/usr/bin/python3 - "$shot" "$variant" "$size" <<'PY'
import json, sys
shot = json.load(open(sys.argv[1]))
for v in shot["views"]:
    v["resolution"] = [int(sys.argv[3]), int(sys.argv[3])]
json.dump(shot, open(sys.argv[2], "w"))
PY
echo "shot: $shot, ${size}x${size}, $spp spp, $(nproc) cores"
printf "%-8s %10s %10s %16s %14s\n" threads wall_s cpu_s "pixel_samples/s" peak_rss_MiB
for t in 1 2; do
  /usr/bin/time -f "%e %U %M" -o "$tmp/time" "$bin" render "$variant" --out "$tmp/out" \
    --threads "$t" --samples "$spp" --quiet >/dev/null
  read -r wall cpu rss < "$tmp/time"
  python3 -c "import sys; w=float(sys.argv[1]); n=int(sys.argv[2])**2*int(sys.argv[3]); \
print('%-8s %10.2f %10.2f %16.3g %14.0f' % (sys.argv[4], w, float(sys.argv[6]), n/w, int(sys.argv[5])/1024))" \
    "$wall" "$size" "$spp" "$t" "$rss" "$cpu"
done
