#!/usr/bin/env python3
"""What method `auto`'s cost model is fitted to (issue 13): on the five scenes of
bench/photon_bench.py, each scene's pilot (from `cloudbake render --dry-run` with `auto`) against
the seconds its bakes take, as the two constants of core/methods/auto_model.cpp and
core/methods/common.cpp that turn a scene into predicted seconds:

- lattice: a `single` bake's seconds over (1 or 2 with a sky) x 0.5 x resolution^3, the unit of
  `latticeSeconds` (common.cpp), at each --lattices resolution;
- photon/path: a `photon` bake's seconds, less its lattice's (the same scene's `single` bake at
  that resolution, or the fitted unit times the resolution's voxels between measured ones), over
  the photons traced (sun and sky) times the pilot's seconds per path through the cloud (its
  seconds per path per pixel over the cloud's share of the pixels): `kPhotonPerPath`
  (auto_model.cpp) at each --photons rung (photon_bench's default ladder).

It prints one row per scene and rung and the median and range of each ratio. Bakes run at
--threads (2: the machine the constants are for); the pilot is auto's own (64 pixels along each
view's longest side, 8 paths, two seeds). Views are rendered at 80x60 and ignored.

Usage: /usr/bin/python3 bench/auto_cost_fit.py [--build build] [--threads 2]
           [--scenes perlin,bunny,disney,thin,cumulus] [--lattices 64,128,256]
           [--photons 524288,2097152] [--work DIR]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import photon_bench as pb  # noqa: E402  (scenes, renders)


def pilot(cloudbake, shot, work):
    """auto.json's pilot and traits for `shot`, from a dry run."""
    s = json.loads(json.dumps(shot))
    s["bake"] = {"method": "auto", "tolerance": 0.3}
    path = os.path.join(work, "auto-shot.json")
    with open(path, "w") as f:
        json.dump(s, f)
    out = subprocess.run([cloudbake, "render", path, "--out", os.path.join(work, "dry"),
                          "--dry-run", "--quiet"], check=True, capture_output=True,
                         text=True).stdout
    for line in out.splitlines():
        if line.startswith("auto.json: "):
            record = json.loads(line[len("auto.json: "):])
            return record["pilot"], record["traits"]
    sys.exit("no auto.json line in the dry run of %s" % path)


def bake_seconds(cloudbake, shot, bake, out, threads):
    s = json.loads(json.dumps(shot))
    s["bake"] = bake
    stats = pb.render(cloudbake, s, out, threads)
    return sum(pb.steps(stats, "bake"))


def lattice_unit(res, sky):
    return (2.0 if sky else 1.0) * 0.5 * res ** 3


def measure(cloudbake, scene, args):
    shot = pb.load_scene(scene, 80)
    if shot is None:
        return []
    work = os.path.join(args.work, scene)
    os.makedirs(work, exist_ok=True)
    p, traits = pilot(cloudbake, shot, work)
    path_s = p["seconds_per_sample"] / max(p["cloud_fraction"], 0.02)
    emitters = (1 if traits["sun"] else 0) + (1 if traits["sky"] else 0)
    rows, lattice_s = [], {}
    for res in args.lattices:
        s = bake_seconds(cloudbake, shot, {"method": "single", "light_resolution": res,
                                           "samples": 1}, os.path.join(work, "single-%d" % res),
                         args.threads)
        lattice_s[res] = s
        rows.append((scene, "lattice", res, s, s / lattice_unit(res, traits["sky"])))
    units = [r[4] for r in rows]
    for photons in args.photons:
        rung = [r for r in pb.SWEEPS["default"] if r[0] == photons]
        if not rung:
            sys.exit("--photons: %d is not a rung of photon_bench's default ladder" % photons)
        _, order, res, tally, zonal = rung[0]
        s = bake_seconds(cloudbake, shot, {"method": "photon", "photons": photons, "order": order,
                                           "light_resolution": res, "tally_resolution": tally,
                                           "zonal_order": zonal, "samples": 1},
                         os.path.join(work, "photon-%d" % photons), args.threads)
        lat = lattice_s.get(res, statistics.median(units) * lattice_unit(res, traits["sky"]))
        ratio = max(0.0, s - lat) / (path_s * photons * emitters)
        rows.append((scene, "photon/path", photons, s, ratio))
    print("%s: pilot %.3f us per path per pixel, cloud %.3f of the pixels, %.3f us per path "
          "through the cloud" % (scene, 1e6 * p["seconds_per_sample"], p["cloud_fraction"],
                                 1e6 * path_s), flush=True)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default=os.path.join(pb.ROOT, "build"))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--scenes", default="perlin,bunny,disney,thin,cumulus")
    ap.add_argument("--lattices", default="64,128,256")
    ap.add_argument("--photons", default="524288,2097152")
    ap.add_argument("--work", default=None)
    args = ap.parse_args()
    args.lattices = [int(x) for x in args.lattices.split(",")]
    args.photons = [int(x) for x in args.photons.split(",")]
    for scene in args.scenes.split(","):
        if scene not in pb.SCENES:
            ap.error("--scenes: %r is not one of %s" % (scene, ", ".join(pb.SCENES)))
    args.work = args.work or tempfile.mkdtemp(prefix="auto_cost_fit.")
    cloudbake = os.environ.get("CLOUDBAKE") or os.path.join(args.build, "tools", "cloudbake",
                                                            "cloudbake")
    rows = []
    for scene in args.scenes.split(","):
        rows.extend(measure(cloudbake, scene, args))
    print("\n| scene | what | at | bake s | ratio |\n|---|---|---|---|---|")
    for scene, what, at, s, ratio in rows:
        print("| %s | %s | %d | %.2f | %.3g |" % (scene, what, at, s, ratio))
    for what in ("lattice", "photon/path"):
        r = [row[4] for row in rows if row[1] == what]
        if r:
            print("%s: median %.3g, range %.3g-%.3g over %d bakes" % (
                what, statistics.median(r), min(r), max(r), len(r)))
    print("work folder: %s" % args.work)


if __name__ == "__main__":
    main()
