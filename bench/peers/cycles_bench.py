#!/usr/bin/env python3
"""The reference against the renderer a user would otherwise pick: Blender Cycles (issue 11).

Renders one scene in both: Disney's cloud (Walt Disney Animation Studios, CC-BY-SA 3.0; from
../shared/data), extinction 0.2 per world unit, albedo 1, HG g = 0.85 (Cycles has no Mie
table), the scene's sun as a delta light of the same irradiance, a constant sky, the same camera
and the same bounce cap; Cycles on the CPU, headless (`blender -b --factory-startup -P
bench/peers/cycles_scene.py`, which documents how the conventions are matched). Prints, per
renderer:

- samples per second (pixel samples, whole image, per second of the render itself);
- rel. noise: relative RMSE between two renders of different seeds over the cloud's pixels
  (alpha >= --cloud-alpha in cloudbake's render), / sqrt(2), of the beauty;
- the same noise scaled to an equal time of --equal-seconds (noise x sqrt(seconds / equal));
- efficiency = 1 / (noise^2 x seconds) and cloudbake's over Cycles';
- the mean over the cloud of each against cloudbake's converged render (--converged-spp): Cycles
  ray-marches heterogeneous volumes (a step of about one voxel, `volume_step_rate` 1), so a few
  percent of bias on its side is expected; cloudbake's own difference is its noise.

Usage: bench/peers/cycles_bench.py [--build build] [--res 256] [--ours-spp 64]
         [--cycles-spp 64] [--converged-spp 1024] [--bounces 1024] [--threads 2] [--work DIR]
"""
import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "client", "python"))
from cloudbake_shot_paths import path_slots  # noqa: E402


def scene(res, bounces):
    """The bench's shot: bench/scenes/disney_cloud.json made comparable with Cycles."""
    folder = os.path.join(ROOT, "bench", "scenes")
    with open(os.path.join(folder, "disney_cloud.json")) as f:
        shot = json.load(f)
    for container, key in path_slots(shot):
        container[key] = os.path.normpath(os.path.join(folder, container[key]))
        if not os.path.exists(container[key]):
            sys.exit("cycles_bench: %s not found (needs ../shared/data beside the checkout)" %
                     container[key])
    shot["medium"]["albedo"] = 1.0
    shot["medium"]["phase"] = {"type": "hg", "g": 0.85}
    shot["views"] = [dict(shot["views"][0], resolution=[res, res])]
    shot["outputs"] = {"exr": True, "vdb": False}
    shot["bake"] = {"method": "pathtrace", "max_depth": bounces}
    return shot


def ours(cloudbake, shot, spp, seed, out, threads):
    """Renders with cloudbake; returns (EXR path, seconds of the view)."""
    os.makedirs(out, exist_ok=True)
    s = json.loads(json.dumps(shot))
    s["bake"].update(samples=spp, seed=seed)
    path, stats = os.path.join(out, "shot.json"), os.path.join(out, "stats.json")
    with open(path, "w") as f:
        json.dump(s, f)
    subprocess.run([cloudbake, "render", path, "--out", out, "--threads", str(threads), "--quiet",
                    "--stats-json", stats], check=True, stdout=subprocess.DEVNULL)
    with open(stats) as f:
        st = json.load(f)
    view = shot["views"][0]["name"]
    secs = sum(x["seconds"] for x in st["steps"] if x["step"] == "view")
    return os.path.join(out, view + ".exr"), secs


def cycles(blender, shot, spp, seed, out, threads):
    """Renders with Cycles; returns (EXR path, seconds of the render)."""
    os.makedirs(out, exist_ok=True)
    view = shot["views"][0]
    cam = view["camera"]
    p = {
        "vdb": shot["volume"]["vdb"]["path"], "grid": shot["volume"]["vdb"].get("grid", "density"),
        "extinction": shot["medium"]["extinction"], "g": shot["medium"]["phase"]["g"],
        "sun_direction": shot["lighting"]["sun"]["direction"],
        "sun_irradiance": shot["lighting"]["sun"]["irradiance"],
        "sky_radiance": shot["lighting"]["sky"]["radiance"],
        "camera": {k: cam[k] for k in ("position", "look_at", "up", "fov_deg")},
        "resolution": view["resolution"], "samples": spp, "seed": seed,
        "bounces": min(1024, shot["bake"]["max_depth"]), "threads": threads,
        "out": os.path.join(out, "cycles.exr"), "stats": os.path.join(out, "stats.json"),
    }
    params = os.path.join(out, "params.json")
    with open(params, "w") as f:
        json.dump(p, f)
    subprocess.run([blender, "-b", "--factory-startup", "-P", os.path.join(HERE, "cycles_scene.py"),
                    "--", params], check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    with open(p["stats"]) as f:
        return p["out"], json.load(f)["seconds"]


def compare(cloudbake, a, b, mask, alpha):
    out = subprocess.run([cloudbake, "compare", a, b, "--json", "--cloud-alpha", str(alpha),
                          "--mask-from", mask], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)["beauty"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--blender", default=shutil.which("blender") or "blender")
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--ours-spp", type=int, default=64)
    ap.add_argument("--cycles-spp", type=int, default=64)
    ap.add_argument("--converged-spp", type=int, default=1024)
    ap.add_argument("--bounces", type=int, default=1024)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--cloud-alpha", type=float, default=0.05)
    ap.add_argument("--equal-seconds", type=float, default=60)
    ap.add_argument("--work", default=None)
    args = ap.parse_args()
    work = args.work or tempfile.mkdtemp(prefix="cycles_bench.")
    cloudbake = os.path.join(args.build, "tools", "cloudbake", "cloudbake")
    shot = scene(args.res, args.bounces)
    pixels = args.res * args.res

    conv, _ = ours(cloudbake, shot, args.converged_spp, 99, os.path.join(work, "converged"),
                   args.threads)
    rows = []
    for name, render, spp in (("cloudbake", ours, args.ours_spp),
                              ("cycles", cycles, args.cycles_spp)):
        tool = cloudbake if render is ours else args.blender
        a, ta = render(tool, shot, spp, 1, os.path.join(work, name, "1"), args.threads)
        b, tb = render(tool, shot, spp, 2, os.path.join(work, name, "2"), args.threads)
        secs = (ta + tb) / 2
        noise = compare(cloudbake, a, b, conv, args.cloud_alpha)["rel_rmse"] / math.sqrt(2)
        vs_conv = compare(cloudbake, a, conv, conv, args.cloud_alpha)
        rows.append((name, spp, secs, pixels * spp / secs, noise,
                     noise * math.sqrt(secs / args.equal_seconds), 1 / (noise * noise * secs),
                     vs_conv["mean"] / vs_conv["reference_mean"] - 1))
    print("scene: Disney cloud, HG 0.85, albedo 1, %dx%d, %d bounces, %d threads; converged: "
          "cloudbake %d spp" % (args.res, args.res, args.bounces, args.threads,
                                args.converged_spp))
    print("| renderer | spp | s | samples/s | rel. noise | noise at %g s | efficiency | "
          "mean vs converged |" % args.equal_seconds)
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print("| %s | %d | %.1f | %.3g | %.4f | %.4f | %.4g | %+.2f %% |" %
              (r[0], r[1], r[2], r[3], r[4], r[5], r[6], 100 * r[7]))
    print("efficiency ratio cloudbake / cycles: %.2f" % (rows[0][6] / rows[1][6]))
    print("work folder: %s" % work, file=sys.stderr)


if __name__ == "__main__":
    main()
