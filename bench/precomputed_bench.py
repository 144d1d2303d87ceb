#!/usr/bin/env python3
"""Method precomputed (seed 002, issue 4 section 4): precompute cost, frame cost, blending error.

1. Precompute per basic volume on a 64^3 and a 128x128x64 lattice (a Perlin cloud) for
   K = 2^12 .. 2^17 sample points: seconds, MiB kept per basic volume, peak resident MiB.
2. One frame of the 128x128x64 cloud at 640x480: seconds to light it from the precompute
   (sun sweep, SHEXP of the blended SH, multiple-scattering orders) and to render the view.
3. Blending error: an endless animation of 8 basic volumes; a cross-dissolved frame (0 < w < 1,
   lit from the two basic volumes' precomputes: Eq. 6, 9) against the same method run from
   scratch on that frame's blended density, and both against the path tracer on that density.

Every run is a `cloudbake render` child process (peak memory is its own). Prints markdown.
Usage: bench/precomputed_bench.py [--build build] [--threads 2] [--kmax 17] [--ref-spp 256]
                                  [--quick]
"""
import argparse
import json
import os
import subprocess
import sys

from trade_bench import render as run  # a child render: its --stats-json (docs/cli.md)
from trade_bench import steps  # the stats' steps of some kinds

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

CLOUD = {"type": "perlin_cloud", "seed": 7, "cover": 0.55, "sharpness": 0.8, "density": 1.0,
         "octaves": 5, "frequency": 3.0, "persistence": 0.5}
MEDIUM = {"extinction": 12.0, "albedo": 0.99, "phase": {"type": "hg", "g": 0.8}}
LIGHTING = {"sun": {"direction": [0.9, 0.3, 0.25], "irradiance": [3.0, 2.8, 2.5]},
            "sky": {"zenith": [0.12, 0.2, 0.45], "horizon": [0.35, 0.4, 0.5],
                    "ground": [0.08, 0.08, 0.08]}}


def view(w, h):
    return [{"name": "side", "resolution": [w, h],
             "camera": {"type": "perspective", "fov_deg": 40, "position": [0.6, -3.0, 0.35],
                        "look_at": [0, 0, 0.5], "up": [0, 0, 1]}}]


def compare(cloudbake, test, ref):
    out = subprocess.run([cloudbake, "compare", test, ref, "--json"], check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--kmax", type=int, default=17, help="largest K = 2^kmax")
    ap.add_argument("--ref-spp", type=int, default=256)
    ap.add_argument("--quick", action="store_true", help="smoke run: small lattices and K")
    a = ap.parse_args()
    cloudbake = os.path.join(a.build, "tools", "cloudbake", "cloudbake")
    if not os.access(cloudbake, os.X_OK):
        sys.exit("precomputed_bench: %s not found; build first (deploy/build.sh)" % cloudbake)
    work = os.path.join(a.build, "bench_precomputed" + ("_quick" if a.quick else ""))

    # 1. Precompute per basic volume.
    lattices = [("64^3", [2, 2, 2], 64), ("128x128x64", [2, 2, 1], 128)]
    ks = [12, 13, 14, 15, 16, 17]
    if a.quick:
        lattices, ks = [("24^3", [2, 2, 2], 24)], [10, 11]
    ks = [k for k in ks if k <= a.kmax]
    print("## Precompute per basic volume (threads: %d)\n" % a.threads)
    print("| lattice | K | precompute s | MiB kept | peak MiB | frame light s | orders |")
    print("|---|---|---|---|---|---|---|")
    for name, size, res in lattices:
        for k in ks:
            shot = {"version": 1, "name": "pre",
                    "volume": {"procedural": dict(CLOUD, center=[0, 0, 0.5], size=size,
                                                  resolution=res)},
                    "medium": MEDIUM, "lighting": LIGHTING,
                    "bake": {"method": "precomputed", "light_resolution": res,
                             "sample_points": 2 ** k},
                    "views": [], "outputs": {"exr": False, "vdb": False}}
            print("precomputed_bench: %s K=2^%d..." % (name, k), file=sys.stderr)
            stats = run(cloudbake, shot, os.path.join(work, "pre_%d_%d" % (res, k)), a.threads)
            pre = steps(stats, "precompute")[0]
            lit = steps(stats, "light")[0]
            print("| %s | 2^%d | %.2f | %.1f | %.0f | %.2f | %d |" % (
                name, k, pre["seconds"], pre["mib_per_basic_volume"], stats["peak_rss_mib"],
                lit["seconds"], lit["orders"]), flush=True)

    # 2. A 640x480 frame of the largest lattice.
    name, size, res = lattices[-1]
    w, h = (160, 120) if a.quick else (640, 480)
    shot = {"version": 1, "name": "frame",
            "volume": {"procedural": dict(CLOUD, center=[0, 0, 0.5], size=size, resolution=res)},
            "medium": MEDIUM, "lighting": LIGHTING,
            "bake": {"method": "precomputed", "light_resolution": res, "sample_points": 4096,
                     "frames": 3},
            "views": view(w, h), "outputs": {"exr": True, "vdb": False}}
    stats = run(cloudbake, shot, os.path.join(work, "frame"), a.threads)
    peak = stats["peak_rss_mib"]
    lit = [st["seconds"] for st in steps(stats, "light")]  # one per frame
    ren = [st["seconds"] for st in steps(stats, "view") if st["view"] == "side"]
    print("\n## One frame of the %s cloud at %dx%d, K 4096\n" % (name, w, h))
    print("light from the precompute: %.2f s per frame (mean of %d); render: %.2f s per view; "
          "peak %.0f MiB" % (sum(lit) / len(lit), len(lit), sum(ren) / len(ren), peak))

    # 3. Blending error.
    seq_res = 24 if a.quick else 64
    base = {"version": 1, "name": "blend", "medium": MEDIUM, "lighting": LIGHTING,
            "views": view(160, 120)}
    anim = dict(base, volume={"sequence": {
        "procedural": dict(CLOUD, center=[0, 0, 0.5], size=[2, 2, 1], resolution=seq_res),
        "frames": 8, "time_step": 0.05}},
        bake={"method": "precomputed", "light_resolution": seq_res, "sample_points": 4096,
              "frames": 12, "dissolve": 3},
        outputs={"exr": True, "vdb": True})
    d_anim = os.path.join(work, "blend_anim")
    run(cloudbake, anim, d_anim, a.threads)
    with open(os.path.join(d_anim, "animation.json")) as f:
        frames = json.load(f)["frames"]
    pick = next((i for i, fr in enumerate(frames) if 0.3 <= fr["w"] <= 0.7 and fr["a"] != fr["b"]),
                None)
    if pick is None:
        pick = next(i for i, fr in enumerate(frames) if 0 < fr["w"] < 1)
    fr = frames[pick]
    vdb = os.path.join(d_anim, "bake.%04d.vdb" % pick)
    static = dict(base, volume={"vdb": {"path": vdb, "grid": "density"}},
                  outputs={"exr": True, "vdb": False})
    d_scratch = os.path.join(work, "blend_scratch")
    run(cloudbake, dict(static, bake={"method": "precomputed", "light_resolution": seq_res,
                                      "sample_points": 4096}), d_scratch, a.threads)
    d_ref = os.path.join(work, "blend_ref")
    ref_spp = 16 if a.quick else a.ref_spp
    run(cloudbake, dict(static, bake={"method": "pathtrace", "samples": ref_spp}), d_ref,
        a.threads)
    blended = os.path.join(d_anim, "side.%04d.exr" % pick)
    scratch = os.path.join(d_scratch, "side.0000.exr")
    ref = os.path.join(d_ref, "side.exr")
    print("\n## Blending error: frame %d = %.2f x basic volume %d + %.2f x basic volume %d\n"
          % (pick, fr["w"], fr["a"], 1 - fr["w"], fr["b"]))
    print("| test | reference | beauty rel. RMSE | beauty mean / ref | sun mean / ref | "
          "multiple mean / ref |")
    print("|---|---|---|---|---|---|")
    for tname, test, rname, r in (("blended (Eq. 6, 9)", blended, "from scratch", scratch),
                                  ("blended (Eq. 6, 9)", blended, "path tracer %d spp" % ref_spp,
                                   ref),
                                  ("from scratch", scratch, "path tracer %d spp" % ref_spp, ref)):
        c = compare(cloudbake, test, r)
        ratio = {k: c[k]["mean"] / c[k]["reference_mean"] for k in ("beauty", "sun", "multiple")}
        print("| %s | %s | %.4f | %.3f | %.3f | %.3f |" % (
            tname, rname, c["beauty"]["rel_rmse"], ratio["beauty"], ratio["sun"],
            ratio["multiple"]))


if __name__ == "__main__":
    main()
