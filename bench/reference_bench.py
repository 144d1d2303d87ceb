#!/usr/bin/env python3
"""Efficiency of the reference path tracer, per variance-reduction technique (issue 11).

For each scene (bench/scenes/*.json, both of its views: the sun beside the cloud and the sun
behind it, at --res x --res) and each configuration of `pathtrace`'s knobs, it renders the
shot twice with different seeds and prints

  scene | view | config | spp | s/view | rel. noise | single | multiple | efficiency | x off

- rel. noise: the relative RMSE between the two renders of the cloud's own light (`scattered`
  = sun + sky layers) over the cloud's pixels (reference alpha >= --cloud-alpha), divided by
  sqrt(2): the noise of one render relative to its mean;
- single, multiple: the same for the light scattered once and more than once, each relative to
  its own mean: which part of the transport a technique must reduce (in views towards the sun
  the multiple layer's, docs/methods.md);
- s/view: the view's seconds from `cloudbake render --stats-json` (the path trace alone; the
  scene and phase table are built once per run and not counted), mean of the two seeds;
- efficiency = 1 / (rel. noise^2 x s/view), the quantity variance reduction buys: a render with
  twice the efficiency reaches the same noise in half the time;
- x off: efficiency over that of the configuration with every technique off, same scene and
  view, measured in the same run.

Scenes: disney_mie (Disney's cloud, Walt Disney Animation Studios, CC-BY-SA 3.0, with the
tabulated Lorenz-Mie phase of r_eff 10 um, v_eff 0.1), disney_hg (the same with HG 0.85), bunny,
perlin. The Disney and bunny scenes need ../shared/data beside the checkout and are skipped
without it.

With --trade-floor SPP it measures instead the noise floor of bench/trade_bench.py's reference
for each configuration: the scenes' views at 160x120, beauty over all pixels as that bench
compares them, a render at SPP against an independent one at SPP/4 (rel. RMSE / sqrt(5), as
trade_bench.py estimates it), with the floor scaled to trade_bench.py's 1024 spp
(x sqrt(SPP / 1024)) and the seconds that reference would take.

CLOUDBAKE=PATH picks the cloudbake binary (default: BUILD/tools/cloudbake/cloudbake), e.g. a copy
that a rebuild cannot replace mid-run.

Usage: bench/reference_bench.py [--build build] [--threads 2] [--res 256] [--spp 16]
                                [--scenes a,b] [--configs off,guide,split,all,default]
                                [--work DIR]
                                [--trade-floor SPP]
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "client", "python"))
from cloudbake_shot_paths import path_slots  # noqa: E402  (the keys of a shot that name files)

MIE = {"type": "mie", "effective_radius_um": 10, "effective_variance": 0.1}
SCENES = {
    "disney_mie": ("disney_cloud.json", MIE),
    "disney_hg": ("disney_cloud.json", None),
    "bunny": ("bunny_cloud.json", None),
    "perlin": ("perlin_cloud.json", None),
}
# Knob settings of `pathtrace` per configuration; an absent knob takes its default, so "guide"
# is the lobe at its default probability and "default" is what a shot gets without knobs.
# "off" is the version 1 tracer (every technique off), "v2" version 2's defaults (delta and
# ratio tracking on the density's 8^3-voxel majorants), "decomp" decomposition tracking alone.
CONFIGS = {
    "off": {"sun_guiding": 0, "sun_split_max": 1, "tracking": "delta"},
    "guide": {"sun_split_max": 1, "tracking": "delta"},
    "split": {"sun_guiding": 0, "sun_split_max": 8, "tracking": "delta"},
    "all": {"sun_split_max": 8, "tracking": "delta"},
    "v2": {"tracking": "delta"},
    "decomp": {"sun_guiding": 0, "sun_split_max": 1},
    "split8": {"sun_split_max": 8},
    "default": {},
}


def load_scene(name, res):
    """The scene's shot with its views at res x res, asset paths made absolute; None if an asset
    is missing."""
    file, phase = SCENES[name]
    folder = os.path.join(ROOT, "bench", "scenes")
    with open(os.path.join(folder, file)) as f:
        shot = json.load(f)
    for container, key in path_slots(shot):
        if not os.path.isabs(container[key]):
            container[key] = os.path.normpath(os.path.join(folder, container[key]))
            if not os.path.exists(container[key]):
                print("skipping %s: %s not found" % (name, container[key]), file=sys.stderr)
                return None
    if phase:
        shot["medium"]["phase"] = phase
    for view in shot["views"]:
        view["resolution"] = [res, res]
    shot["outputs"] = {"exr": True, "vdb": False}
    return shot


def render(cloudbake, shot, out_dir, threads):
    """Renders `shot`; returns its stats JSON."""
    os.makedirs(out_dir, exist_ok=True)
    shot_path = os.path.join(out_dir, "shot.json")
    stats_path = os.path.join(out_dir, "stats.json")
    with open(shot_path, "w") as f:
        json.dump(shot, f)
    subprocess.run([cloudbake, "render", shot_path, "--out", out_dir, "--threads", str(threads),
                    "--quiet", "--stats-json", stats_path], check=True,
                   stdout=subprocess.DEVNULL)
    with open(stats_path) as f:
        return json.load(f)


def view_seconds(stats, view):
    return sum(s["seconds"] for s in stats["steps"] if s["step"] == "view" and
               s.get("view") == view)


def relative_noise(cloudbake, a, b, cloud_alpha, layers=("scattered",)):
    """One render's relative noise per layer (of `layers`), from two renders a and b."""
    out = subprocess.run([cloudbake, "compare", a, b, "--json", "--cloud-alpha", str(cloud_alpha)],
                         check=True, capture_output=True, text=True).stdout
    rows = json.loads(out)
    noise = [rows[layer]["rel_rmse"] / math.sqrt(2) for layer in layers]
    return noise[0] if len(noise) == 1 else noise


def measure(args, cloudbake, scene, shot, config):
    """Per view: (seconds, [relative noise of scattered, single, multiple]) of one
    configuration."""
    runs = []
    for seed in (1, 2):
        s = json.loads(json.dumps(shot))
        s["bake"] = dict({"method": "pathtrace", "samples": args.spp, "seed": seed},
                         **CONFIGS[config])
        out = os.path.join(args.work, scene, config, "seed%d" % seed)
        runs.append((out, render(cloudbake, s, out, args.threads)))
    rows = {}
    for view in [v["name"] for v in shot["views"]]:
        secs = sum(view_seconds(st, view) for _, st in runs) / 2
        noise = relative_noise(cloudbake, os.path.join(runs[0][0], view + ".exr"),
                               os.path.join(runs[1][0], view + ".exr"), args.cloud_alpha,
                               ("scattered", "single", "multiple"))
        rows[view] = (secs, noise)
    return rows


def trade_floor(args, cloudbake, configs):
    """The noise floor of trade_bench.py's reference, per scene and configuration."""
    print("| scene | config | floor at %d spp | floor at 1024 spp | s per 1024-spp view |" %
          args.trade_floor)
    print("|---|---|---|---|---|")
    for scene in args.scenes.split(","):
        shot = load_scene(scene, 160)
        if shot is None:
            continue
        for view in shot["views"]:
            view["resolution"] = [160, 120]
        for config in configs:
            renders, secs = [], 0
            for tag, spp, seed in (("a", args.trade_floor, 1), ("b", args.trade_floor // 4, 2)):
                s = json.loads(json.dumps(shot))
                s["bake"] = dict({"method": "pathtrace", "samples": spp, "seed": seed},
                                 **CONFIGS[config])
                out = os.path.join(args.work, "floor", scene, config, tag)
                stats = render(cloudbake, s, out, args.threads)
                renders.append(out)
                if tag == "a":
                    secs = sum(st["seconds"] for st in stats["steps"] if st["step"] == "view")
            floors = []
            for view in [v["name"] for v in shot["views"]]:
                out = subprocess.run([cloudbake, "compare", os.path.join(renders[1], view + ".exr"),
                                      os.path.join(renders[0], view + ".exr"), "--json"],
                                     check=True, capture_output=True, text=True).stdout
                floors.append(json.loads(out)["beauty"]["rel_rmse"] / math.sqrt(5))
            floor = sum(floors) / len(floors)
            views = len(shot["views"])
            print("| %s | %s | %.4f | %.4f | %.1f |" %
                  (scene, config, floor, floor * math.sqrt(args.trade_floor / 1024),
                   secs / views * 1024 / args.trade_floor), flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--cloud-alpha", type=float, default=0.05)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--configs", default="off,guide,split,all")
    ap.add_argument("--work", default=None)
    ap.add_argument("--trade-floor", type=int, default=0)
    args = ap.parse_args()
    args.work = args.work or tempfile.mkdtemp(prefix="reference_bench.")
    cloudbake = os.environ.get("CLOUDBAKE") or os.path.join(args.build, "tools", "cloudbake",
                                                            "cloudbake")
    configs = args.configs.split(",")
    for c in configs:
        if c not in CONFIGS:
            sys.exit("--configs: unknown '%s' (known: %s)" % (c, ", ".join(CONFIGS)))
    if args.trade_floor:
        trade_floor(args, cloudbake, configs)
        return
    print("| scene | view | config | spp | s/view | rel. noise | single | multiple | efficiency | "
          "x off |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for scene in args.scenes.split(","):
        if scene not in SCENES:
            sys.exit("--scenes: unknown '%s' (known: %s)" % (scene, ", ".join(SCENES)))
        shot = load_scene(scene, args.res)
        if shot is None:
            continue
        base = {}
        for config in configs:
            for view, (secs, layers) in measure(args, cloudbake, scene, shot, config).items():
                noise = layers[0]
                eff = 1 / (noise * noise * secs) if noise > 0 and secs > 0 else float("nan")
                if config == "off":
                    base[view] = eff
                ratio = eff / base[view] if view in base else float("nan")
                print("| %s | %s | %s | %d | %.2f | %.4f | %.4f | %.4f | %.4g | %.2f |" %
                      (scene, view, config, args.spp, secs, noise, layers[1], layers[2], eff,
                       ratio), flush=True)
    print("work folder: %s" % args.work, file=sys.stderr)


if __name__ == "__main__":
    main()
