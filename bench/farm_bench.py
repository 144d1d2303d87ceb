#!/usr/bin/python3
"""Farm benchmark (issue 17; docs/deployment.md, "Farm"): a shot's plan run over Slurm.

    sudo bench/farm_bench.py [--shot bench/endless_300.json] [--tasks 8] [--build build]

Starts a one-node Slurm cluster on localhost (deploy/slurm/local-cluster.sh; needs root, slurm-wlm
and munge) unless SLURM_CONF is set, renders the shot once in one process (`cloudbake render
--stats-json`), then plans it, runs the plan with cloudbake-slurm (one CPU per task) and prints:
- per task: its own seconds, the bytes it read and wrote (run-task's /proc/self/io counts: on a
  farm, mostly the shared folder) and its wait, the time from when it could start (submission,
  or its stage's dependencies done) to when it started; a stage's first task measures Slurm's
  overhead (submission or dependency to start), later ones also wait for a free CPU;
- the split run's output against the single-process run (bit-identical EXRs);
- a model on paper, stated as such: the shot at 300 basic volumes and 1000 frames on 10 and 100
  nodes of this machine's kind, from the measured per-unit times and per-task overheads.
"""

import argparse
import glob
import json
import os
import re
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run(cmd, **kw):
    return subprocess.run(cmd, check=True, **kw)


def task_logs(folder):
    """task id -> {start, end, seconds, read, wrote} from cloudbake-slurm's logs."""
    out = {}
    for path in glob.glob(os.path.join(folder, "logs", "*.log")):
        text = open(path, errors="replace").read()
        for m in re.finditer(r"task (\S+), attempt \d+ on \S+ at ([\d.]+)", text):
            out.setdefault(m.group(1), {})["start"] = float(m.group(2))
        for m in re.finditer(r"task (\S+) done at ([\d.]+)", text):
            out.setdefault(m.group(1), {})["end"] = float(m.group(2))
        for m in re.finditer(r"^(\S+): done in ([\d.]+) s; read (\d+) bytes, wrote (\d+) bytes",
                             text, re.M):
            out.setdefault(m.group(1), {}).update(
                seconds=float(m.group(2)), read=int(m.group(3)), wrote=int(m.group(4)))
    return out


def single_run(cloudbake, shot, out):
    stats = out + ".stats.json"
    t0 = time.time()
    run([cloudbake, "render", shot, "--out", out, "--quiet", "--stats-json", stats],
        stdout=subprocess.DEVNULL)
    wall = time.time() - t0
    s = json.load(open(stats))
    per = {}
    for st in s["steps"]:
        per.setdefault(st["step"], []).append(st["seconds"])
    return wall, per


def farm_run(cloudbake, shot, tasks, work):
    plan_path = os.path.join(work, "plan.json")
    with open(plan_path, "w") as f:
        run([cloudbake, "plan", shot, "--tasks", str(tasks), "--json"], stdout=f)
    plan = json.load(open(plan_path))
    t0 = time.time()
    run([os.path.join(ROOT, "deploy", "slurm", "cloudbake-slurm"), "submit", plan_path,
         "--cache-dir", os.path.join(work, "shared"), "--out", os.path.join(work, "split"),
         "--cloudbake", cloudbake, "--cpus-per-task", "1", "--wait"], stdout=subprocess.DEVNULL)
    wall = time.time() - t0
    folder = os.path.join(work, "shared", "tasks", plan["id"])
    submitted = json.load(open(os.path.join(folder, "slurm.json")))["submitted"]
    return plan, wall, task_logs(folder), submitted


def waits(plan, logs, submitted):
    """Seconds each task waited once it could start (its dependencies done)."""
    out = {}
    for t in plan["tasks"]:
        ready = max([submitted] + [logs[a]["end"] for a in t["after"] if "end" in logs.get(a, {})])
        out[t["id"]] = logs[t["id"]]["start"] - ready
    return out


def same_outputs(work, single):
    differ = 0
    for name in os.listdir(single):
        if name.endswith(".exr") or name.endswith(".json"):
            a = open(os.path.join(single, name), "rb").read()
            b = open(os.path.join(work, "split", name), "rb").read()
            differ += a != b
    return differ


def model(plan, logs, per, shot):
    """Seconds of the shot scaled to 300 basic volumes and 1000 frames on `nodes` nodes."""
    cfg = json.load(open(shot))
    basic = cfg["volume"]["sequence"]["frames"] if "sequence" in cfg["volume"] else 1
    frames = cfg["bake"].get("frames", basic)
    kinds = {}
    for t in plan["tasks"]:
        kinds.setdefault(t["kind"], []).append(logs[t["id"]]["seconds"])
    precompute_per_volume = sum(kinds.get("precompute", [0])) / basic
    frame_seconds = (sum(per.get("light", [0])) + sum(per.get("view", [0]))) / frames
    render = kinds["render"]
    render_fixed = max(0.0, (sum(render) - frames * frame_seconds) / len(render))
    return {
        "precompute_per_volume": precompute_per_volume,
        "frame": frame_seconds,
        "render_task_fixed": render_fixed,
        "layout_per_volume": sum(kinds.get("layout", [0])) / basic,
        "bake_per_volume": sum(kinds.get("bake", [0])) / basic,
        "gather": sum(kinds.get("gather", [0])),
    }


def predict(m, overhead, nodes, cores=2, volumes=300, frames=1000):
    slots = nodes * cores
    precompute = -(-volumes // slots) * m["precompute_per_volume"]
    render = -(-frames // slots) * m["frame"] + m["render_task_fixed"]
    serial = volumes * (m["layout_per_volume"] + m["bake_per_volume"]) + m["gather"]
    return serial + precompute + render + 5 * overhead


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--shot", default=os.path.join(ROOT, "bench", "endless_300.json"))
    p.add_argument("--tasks", type=int, default=8)
    p.add_argument("--build", default=os.path.join(ROOT, "build"))
    args = p.parse_args()
    cloudbake = os.path.join(os.path.abspath(args.build), "tools", "cloudbake", "cloudbake")
    work = tempfile.mkdtemp(prefix="cloudbake-farm-bench.")
    started = "SLURM_CONF" not in os.environ
    if started:
        run([os.path.join(ROOT, "deploy", "slurm", "local-cluster.sh"), "start",
             os.path.join(work, "cluster")], stdout=subprocess.DEVNULL)
        os.environ["SLURM_CONF"] = os.path.join(work, "cluster", "slurm.conf")
    try:
        single_wall, per = single_run(cloudbake, args.shot, os.path.join(work, "single"))
        plan, farm_wall, logs, submitted = farm_run(cloudbake, args.shot, args.tasks, work)
    finally:
        if started:
            run([os.path.join(ROOT, "deploy", "slurm", "local-cluster.sh"), "stop",
                 os.path.join(work, "cluster")])
    wait = waits(plan, logs, submitted)
    print(f"shot {args.shot}: {len(plan['tasks'])} tasks; single process {single_wall:.1f} s, "
          f"over Slurm (one node, 2 CPUs, one per task) {farm_wall:.1f} s")
    print(f"{'task':16} {'seconds':>8} {'read MB':>9} {'wrote MB':>9} {'wait s':>7}")
    for t in plan["tasks"]:
        r = logs[t["id"]]
        print(f"{t['id']:16} {r['seconds']:8.2f} {r['read'] / 1e6:9.1f} {r['wrote'] / 1e6:9.1f} "
              f"{wait[t['id']]:7.2f}")
    # A stage's first task waits only for Slurm (later ones also for a free CPU of this node).
    first = {}
    for t in plan["tasks"]:
        first[t["kind"]] = min(first.get(t["kind"], 1e9), wait[t["id"]])
    overhead = sorted(first.values())[len(first) // 2]
    print("first wait per stage (s): " + ", ".join(f"{k} {v:.2f}" for k, v in first.items()))
    print(f"median of them (Slurm's overhead per stage): {overhead:.2f} s; "
          f"EXRs and JSON differing from the single-process run: "
          f"{same_outputs(work, os.path.join(work, 'single'))}")
    m = model(plan, logs, per, args.shot)
    print("per unit: " + ", ".join(f"{k} {v:.4f} s" for k, v in m.items()))
    print("model on paper (not measured): 300 basic volumes and 1000 frames of this shot, one "
          "task per core on 2-core nodes, per-stage overhead as measured:")
    for nodes in (1, 10, 100):
        print(f"  {nodes:3d} node(s): {predict(m, overhead, nodes):8.1f} s")


if __name__ == "__main__":
    sys.exit(main())
