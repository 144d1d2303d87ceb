#!/usr/bin/env python3
"""The sun's transmittance between lattice voxels where it falls steeply: a low sun grazing a
dense flat layer (1.7, 5 and 15 degrees over it; extinction 10, 1 for a thin one, and 50, three
mean free paths a voxel, at 5 degrees) and a
dense sphere seen against the sun (its lit rim) and from the side (extinctions 150 and 30). For
each, the `single` layer of the given bake methods against `pathtrace` with max_depth 1 (single
scattering only; 256 paths a pixel, cached under WORK/ref), 48x36 views: the ratio of the means
and the relative RMSE (`cloudbake compare`). docs/methods.md, "Low suns and hard rims".

Usage: /usr/bin/python3 bench/grazing_bench.py [--cloudbake PATH] [--methods single,photon]
           [--work DIR] [--threads 2]
"""
import argparse
import json
import math
import os
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def layer(elevation_deg, extinction=10.0):
    e = math.radians(elevation_deg)
    return {"version": 1, "name": "graze",
            "volume": {"box": {"min": [-4, -4, 0], "max": [4, 4, 0.3]}},
            "medium": {"extinction": extinction, "albedo": 0.9,
                       "phase": {"type": "hg", "g": 0.85}},
            "lighting": {"sun": {"direction": [math.cos(e), 0, math.sin(e)],
                                 "irradiance": [1, 1, 1]}},
            "views": [{"name": "above", "camera": {"type": "perspective",
                                                   "position": [0, -2.5, 2.5],
                                                   "look_at": [0, 0, 0.15], "fov_deg": 40,
                                                   "up": [0, 0, 1]}, "resolution": [48, 36]}],
            "bake": {}}


def sphere(extinction):
    return {"version": 1, "name": "rim",
            "volume": {"sphere": {"center": [0, 0, 0], "radius": 1}},
            "medium": {"extinction": extinction, "albedo": 0.9,
                       "phase": {"type": "hg", "g": 0.8}},
            "lighting": {"sun": {"direction": [1, 0, 0.3], "irradiance": [1, 1, 1]}},
            "views": [{"name": "back", "camera": {"type": "perspective",
                                                  "position": [-4, -1, -1], "look_at": [0, 0, 0],
                                                  "fov_deg": 30, "up": [0, 0, 1]},
                       "resolution": [48, 36]},
                      {"name": "side", "camera": {"type": "perspective",
                                                  "position": [0, -4, 0.5], "look_at": [0, 0, 0],
                                                  "fov_deg": 35, "up": [0, 0, 1]},
                       "resolution": [48, 36]}],
            "bake": {}}


def render(cloudbake, shot, bake, folder, threads):
    if os.path.exists(os.path.join(folder, "done")):
        return folder
    os.makedirs(folder, exist_ok=True)
    s = dict(shot, bake=bake)
    path = os.path.join(folder, "shot.json")
    with open(path, "w") as f:
        json.dump(s, f)
    subprocess.run([cloudbake, "render", path, "--out", folder, "--threads", str(threads),
                    "--quiet"], check=True, stdout=subprocess.DEVNULL)
    open(os.path.join(folder, "done"), "w").close()
    return folder


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cloudbake", default=os.path.join(ROOT, "build", "tools", "cloudbake",
                                                        "cloudbake"))
    ap.add_argument("--methods", default="single")
    ap.add_argument("--work", default="/tmp/grazing_bench")
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    scenes = [("layer 1.7 deg", layer(1.7), ["above"]), ("layer 5 deg", layer(5), ["above"]),
              ("layer 15 deg", layer(15), ["above"]),
              ("thin layer 1.7 deg", layer(1.7, 1.0), ["above"]),
              ("dense layer 5 deg", layer(5, 50.0), ["above"]),
              ("sphere 150", sphere(150), ["back", "side"]),
              ("sphere 30", sphere(30), ["back", "side"])]
    run = os.path.join(a.work, str(os.getpid()))
    print("| scene | view | method | single layer / reference | relative RMSE |")
    print("|---|---|---|---|---|")
    for i, (name, shot, views) in enumerate(scenes):
        ref = render(a.cloudbake, shot, {"method": "pathtrace", "max_depth": 1, "samples": 256,
                                         "seed": 1},
                     os.path.join(a.work, "ref", name.replace(" ", "_")),
                     a.threads)
        for m in a.methods.split(","):
            test = render(a.cloudbake, shot, {"method": m, "samples": 4},
                          os.path.join(run, "%d_%s" % (i, m)), a.threads)
            for v in views:
                out = subprocess.run([a.cloudbake, "compare", "--json",
                                      os.path.join(test, v + ".exr"),
                                      os.path.join(ref, v + ".exr")],
                                     capture_output=True, text=True, check=True).stdout
                s = json.loads(out)["single"]
                print("| %s | %s | %s | %.3f | %.3f |" % (
                    name, v, m, s["mean"] / max(1e-30, s["reference_mean"]), s["rel_rmse"]),
                    flush=True)


if __name__ == "__main__":
    main()
