#!/usr/bin/env bash
# Farm tasks on a real Slurm (issue 17; docs/deployment.md, "Farm"), run by .ci/run after ctest:
# a one-node cluster on localhost (deploy/slurm/local-cluster.sh), then
#   1. an endless animation split into 11 tasks over Slurm equals `cloudbake render` bit for bit;
#   2. a task killed with SIGKILL mid-way is retried and the result is still identical;
#   3. a cancelled plan leaves no task running;
#   4. a failing task fails the plan, and the report shows its log line;
#   5. cloudbake-server --executor slurm runs a job as farm tasks (identical files) and cancels one.
# Usage: tests/farm/slurm_test.sh [BUILD_DIR]. Needs root, slurm-wlm and munge; skips (exit 0,
# saying why) where they are absent.
set -euo pipefail

repo=$(cd "$(dirname "$0")/../.." && pwd)
build=$(realpath "${1:-$repo/build}")
cloudbake=$build/tools/cloudbake/cloudbake
submit=$repo/deploy/slurm/cloudbake-slurm
if [[ $(id -u) != 0 || ! -x /usr/sbin/slurmctld || ! -x /usr/sbin/munged ]]; then
  echo "slurm_test: SKIPPED: needs root and Debian's slurm-wlm and munge" \
    "(deploy/ci-packages.txt installs them)"
  exit 0
fi
[[ -x $cloudbake ]] || { echo "slurm_test: $cloudbake not built" >&2; exit 1; }

work=$(mktemp -d /tmp/cloudbake-slurm-test.XXXXXX)
cleanup() {
  "$repo/deploy/slurm/local-cluster.sh" stop "$work/cluster" || true
  rm -rf "$work"
}
trap cleanup EXIT
"$repo/deploy/slurm/local-cluster.sh" start "$work/cluster"
export SLURM_CONF=$work/cluster/slurm.conf

fail() { echo "slurm_test: FAILED: $*" >&2; exit 1; }
same_files() {  # every file of $1 is in $2 with the same bytes, and nothing more
  local a=$1 b=$2
  [[ $(ls "$a" | wc -l) == $(ls "$b" | wc -l) ]] || fail "$b has $(ls "$b" | wc -l) files, $a $(ls "$a" | wc -l)"
  for f in "$a"/*; do cmp -s "$f" "$b/$(basename "$f")" || fail "$(basename "$f") differs"; done
}
plan_logs() {  # the log folder of plan file $1
  echo "$work/shared/tasks/$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['id'])" "$1")/logs"
}
wait_for_task() {  # waits until a run-task process of task $1 runs; prints its pid
  for _ in $(seq 600); do
    local pid
    pid=$(pgrep -f "run-task .* $1 " | head -1 || true)
    [[ -n $pid ]] && { echo "$pid"; return 0; }
    sleep 0.1
  done
  fail "task $1 never started"
}

cat >"$work/anim.json" <<'EOF'
{"version": 1, "name": "anim",
 "volume": {"sequence": {"procedural": {"type": "perlin_cloud", "size": [2, 2, 1],
            "resolution": 24, "seed": 3}, "frames": 8, "time_step": 0.05}},
 "medium": {"extinction": 8, "albedo": 0.97, "phase": {"type": "hg", "g": 0.6}},
 "lighting": {"sun": {"direction": [0.3, 0.2, 1], "irradiance": [1, 1, 1]},
              "sky": {"radiance": [0.1, 0.15, 0.3]}},
 "bake": {"method": "precomputed", "light_resolution": 20, "sample_points": 512,
          "transfer_resolution": 10, "frames": 12, "dissolve": 2},
 "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 1],
            "look_at": [0, 0, 0.3], "up": [0, 0, 1], "width": 3}, "resolution": [48, 36]}],
 "outputs": {"exr": true, "vdb": false}}
EOF

echo "== 1. an endless animation in 11 tasks over Slurm equals the single-process run"
"$cloudbake" render "$work/anim.json" --out "$work/single" --quiet >/dev/null
"$cloudbake" plan "$work/anim.json" --tasks 4 --json >"$work/anim.plan.json"
tasks=$(python3 -c "import json,sys; print(len(json.load(open(sys.argv[1]))['tasks']))" "$work/anim.plan.json")
((tasks >= 8)) || fail "the plan has $tasks tasks, want at least 8"
t0=$(date +%s.%N)
"$submit" submit "$work/anim.plan.json" --cache-dir "$work/shared" --out "$work/split" \
  --cloudbake "$cloudbake" --cpus-per-task 1 --wait --timeout 300 >/dev/null
echo "   $tasks tasks in $(python3 -c "print(round($(date +%s.%N) - $t0, 1))") s"
same_files "$work/single" "$work/split"
"$submit" status "$work/anim.plan.json" --cache-dir "$work/shared" | tail -1

cat >"$work/views.json" <<'EOF'
{"version": 1, "name": "views",
 "volume": {"procedural": {"type": "perlin_cloud", "size": [2, 2, 1], "resolution": 32, "seed": 5}},
 "medium": {"extinction": 10, "albedo": 0.95, "phase": {"type": "hg", "g": 0.7}},
 "lighting": {"sun": {"direction": [0.5, 0.2, 1], "irradiance": [1, 1, 1]}},
 "bake": {"method": "pathtrace", "samples": 512, "seed": 2},
 "views": [
  {"name": "a", "camera": {"type": "orthographic", "position": [0, -5, 0.5], "look_at": [0, 0, 0.5], "up": [0, 0, 1], "width": 3}, "resolution": [80, 64]},
  {"name": "b", "camera": {"type": "orthographic", "position": [5, 0, 0.5], "look_at": [0, 0, 0.5], "up": [0, 0, 1], "width": 3}, "resolution": [80, 64]},
  {"name": "c", "camera": {"type": "orthographic", "position": [0, 5, 0.5], "look_at": [0, 0, 0.5], "up": [0, 0, 1], "width": 3}, "resolution": [80, 64]},
  {"name": "d", "camera": {"type": "orthographic", "position": [-5, 0, 0.5], "look_at": [0, 0, 0.5], "up": [0, 0, 1], "width": 3}, "resolution": [80, 64]}],
 "outputs": {"exr": true, "vdb": false}}
EOF

echo "== 2. a task killed mid-way is retried and gives the same result"
"$cloudbake" render "$work/views.json" --out "$work/views.single" --quiet >/dev/null
"$cloudbake" plan "$work/views.json" --tasks 2 --json >"$work/views.plan.json"
"$submit" submit "$work/views.plan.json" --cache-dir "$work/shared" --out "$work/views.split" \
  --cloudbake "$cloudbake" --cpus-per-task 1 >/dev/null
pid=$(wait_for_task render.001)
sleep 0.3
kill -9 "$pid"
echo "   killed run-task render.001 (pid $pid)"
"$submit" wait "$work/views.plan.json" --cache-dir "$work/shared" --timeout 300 >/dev/null ||
  fail "the plan did not finish after the kill"
log=$(plan_logs "$work/views.plan.json")/render.1.log
grep -q "attempt 2" "$log" || fail "render.001 was not retried (its log: $(cat "$log"))"
same_files "$work/views.single" "$work/views.split"

echo "== 3. a cancelled plan leaves no task running"
sed 's/"seed": 2/"seed": 3/' "$work/views.json" >"$work/cancel.json"
"$cloudbake" plan "$work/cancel.json" --tasks 2 --json >"$work/cancel.plan.json"
"$submit" submit "$work/cancel.plan.json" --cache-dir "$work/shared" --out "$work/cancel" \
  --cloudbake "$cloudbake" --cpus-per-task 1 >/dev/null
wait_for_task render.000 >/dev/null
"$submit" cancel "$work/cancel.plan.json" --cache-dir "$work/shared"
for _ in $(seq 100); do pgrep -f "run-task $work" >/dev/null || break; sleep 0.1; done
! pgrep -f "run-task $work" >/dev/null || fail "a task still runs 10 s after cancel"
[[ -z $(squeue -h) ]] || fail "squeue still lists jobs after cancel"

echo "== 4. a failing task fails the plan with its log line"
cat >"$work/density.json" <<'EOF'
{"version": 1, "name": "ball", "volume": {"sphere": {"center": [0, 0, 0], "radius": 1}},
 "medium": {"extinction": 3, "albedo": 0.9, "phase": {"type": "hg", "g": 0.6}},
 "lighting": {"sun": {"direction": [0.3, 0.2, 1], "irradiance": [1, 1, 1]}},
 "bake": {"method": "pathtrace", "samples": 1},
 "views": [{"name": "a", "camera": {"type": "orthographic", "position": [0, -5, 0], "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 3}, "resolution": [8, 8]}],
 "outputs": {"exr": false, "vdb": true, "vdb_voxel_size": 0.1}}
EOF
"$cloudbake" render "$work/density.json" --out "$work/density" --quiet >/dev/null
cp "$work/density/bake.vdb" "$work/moved.vdb"
sed 's|{"sphere": {"center": \[0, 0, 0\], "radius": 1}}|{"vdb": {"path": "moved.vdb"}}|; s/"exr": false, "vdb": true, "vdb_voxel_size": 0.1/"exr": true, "vdb": false/' \
  "$work/density.json" >"$work/uses_vdb.json"
"$cloudbake" plan "$work/uses_vdb.json" --tasks 1 --json >"$work/fails.plan.json"
rm "$work/moved.vdb"  # the asset moves after planning: every task fails, naming it
set +e
"$submit" submit "$work/fails.plan.json" --cache-dir "$work/shared" --out "$work/fails" \
  --cloudbake "$cloudbake" --cpus-per-task 1 --retries 1 --wait --timeout 120 >/dev/null 2>"$work/fails.err"
rc=$?
set -e
[[ $rc == 1 ]] || fail "a failing plan exited $rc, want 1"
grep -q "task render.000: failed" "$work/fails.err" || fail "no failed task reported: $(cat "$work/fails.err")"
grep -q "moved.vdb" "$work/fails.err" || fail "the report does not show the log line: $(cat "$work/fails.err")"
grep -q "attempt 2" "$(plan_logs "$work/fails.plan.json")/render.log" || fail "not retried"
echo "== 5. cloudbake-server --executor slurm runs each job as farm tasks"
port=$(python3 -c "import socket; s = socket.socket(); s.bind(('127.0.0.1', 0)); print(s.getsockname()[1])")
cloudctl=("$build/client/cloudctl" --server "127.0.0.1:$port" --timeout 300)
"$build/server/cloudbake-server" --listen "127.0.0.1:$port" --cache-dir "$work/server-state" \
  --shared-dir "$work/server-shared" --executor slurm --slurm-cloudbake "$cloudbake" \
  --slurm-tasks 4 --slurm-cpus-per-task 1 --log-level warn 2>"$work/server.log" &
server_pid=$!
trap 'kill $server_pid 2>/dev/null || true; cleanup' EXIT
"${cloudctl[@]}" --wait-for-server health >/dev/null
"${cloudctl[@]}" submit "$work/anim.json" --out "$work/server-out" --quiet >/dev/null ||
  fail "the server's Slurm job failed: $(tail -5 "$work/server.log")"
same_files "$work/single" "$work/server-out"
job=$("${cloudctl[@]}" submit "$work/cancel.json" --detach)
wait_for_task render.000 >/dev/null
"${cloudctl[@]}" cancel "$job" >/dev/null
for _ in $(seq 100); do
  [[ $("${cloudctl[@]}" --json status "$job" | python3 -c "import json,sys; print(json.load(sys.stdin)['state'])") == CANCELLED ]] && break
  sleep 0.1
done
"${cloudctl[@]}" --json status "$job" | grep -q '"CANCELLED"' || fail "the job was not cancelled"
for _ in $(seq 100); do pgrep -f "run-task $work/server-shared" >/dev/null || break; sleep 0.1; done
! pgrep -f "run-task $work/server-shared" >/dev/null || fail "a farm task still runs after the job's cancel"
kill "$server_pid"
wait "$server_pid" || fail "the server did not exit cleanly"
echo "slurm_test: all passed"
