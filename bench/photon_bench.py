#!/usr/bin/env python3
"""Method `photon` against the reference: its error as photons, order and lattice grow (issue 12).

For each scene (bench/scenes/*.json, both views, --res x 3/4 --res pixels) it renders a
reference with `pathtrace` twice (seeds 1 and 2, --ref-spp each, cached under WORK/ref/) and
each photon configuration once, and prints

  scene | photons | order | zonal | lattice | tally | bake s | s/view | peak MiB | rel. RMSE |
  bias | ref. noise | per view, less ref. noise

- rel. RMSE: of the cloud's own light (`scattered` = sun + sky layers) over the cloud's pixels
  (reference alpha >= --cloud-alpha), against the mean of the two references, averaged over the
  views (`cloudbake compare --json`);
- bias: (mean - reference mean) / reference mean of the same, averaged over the views;
- ref. noise: the references' own relative noise there, RMS difference / sqrt(2) of the two
  seeds, divided by sqrt(2) again for their mean;
- per view, less ref. noise: each view's rel. RMSE with one reference's own noise (RMS
  difference / sqrt(2)) removed in quadrature: the error of the photon view itself, since each
  rel. RMSE above is taken against one reference at a time;
- bake s, s/view, peak MiB: from each child's `cloudbake render --stats-json`.

Scenes: perlin, bunny, disney (Disney's cloud, Walt Disney Animation Studios, CC-BY-SA 3.0),
thin (an optically thin Perlin layer, seen from below against the sun and from above) and
cumulus (a dense Perlin cumulus lit from behind, seen against the sun and from its lit side); HG
0.85 as in bench/scenes. Not in the default list: droplet (the Perlin cloud with the real Mie
table, r_eff 10 um: side, against the sun and with the sun behind the camera; its references
need about 8x the paths of HG's for the same noise) and skyonly (the Perlin cloud under a uniform
sky and a black sun). The bunny and Disney scenes need ../shared/data and are skipped without.

Usage: bench/photon_bench.py [--build build] [--threads 2] [--res 160] [--ref-spp 1024]
                             [--samples 16] [--scenes perlin,bunny,disney,thin,cumulus]
                             [--sweep default|order|zonal|lattice|quick|far|fine] [--work DIR]
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

SCENES = {"perlin": "perlin_cloud.json", "bunny": "bunny_cloud.json",
          "disney": "disney_cloud.json", "thin": "thin_layer.json",
          "cumulus": "cumulus_backlit.json", "droplet": "perlin_droplet.json",
          "skyonly": "perlin_skyonly.json"}
# (photons, order, light_resolution, tally_resolution, zonal_order) per sweep: the knobs grow
# together along "default" (its second row is the method's defaults), the order alone along
# "order", the zonal terms alone along "zonal", the lattices alone along "lattice".
SWEEPS = {
    "default": [(1 << 17, 3, 64, 32, 24), (1 << 19, 3, 128, 48, 24), (1 << 21, 4, 192, 48, 24),
                (1 << 22, 4, 192, 48, 24)],
    "order": [(1 << 20, o, 64, 64, 0) for o in (1, 2, 3, 5, 8)],
    "zonal": [(1 << 18, 3, 64, 64, z) for z in (0, 8, 16, 32)],
    "lattice": [(1 << 20, 4, 96, 96, 24), (1 << 20, 4, 192, 96, 24), (1 << 20, 4, 192, 64, 24),
                (1 << 20, 4, 192, 48, 24), (1 << 20, 4, 192, 32, 24)],
    "quick": [(1 << 15, 2, 32, 32, 16), (1 << 17, 4, 64, 32, 24)],
    # Further along the curve, for the dense scenes (Disney, cumulus): a finer transmittance
    # lattice and tallies, then 4x the photons on them.
    "far": [(1 << 22, 4, 320, 96, 24), (1 << 24, 4, 320, 96, 24)],
    # Towards 2 % on the scenes whose error at 4M photons is mostly the tallies' noise (the thin
    # layer): 16M photons on the default ladder's last lattices, then on finer ones.
    "fine": [(1 << 24, 4, 192, 48, 24), (1 << 24, 4, 256, 64, 24)],
}


def load_scene(name, res):
    folder = os.path.join(ROOT, "bench", "scenes")
    with open(os.path.join(folder, SCENES[name])) as f:
        shot = json.load(f)
    for container, key in path_slots(shot):
        if not os.path.isabs(container[key]):
            container[key] = os.path.normpath(os.path.join(folder, container[key]))
            if not os.path.exists(container[key]):
                print("skipping %s: %s not found" % (name, container[key]), file=sys.stderr)
                return None
    for view in shot["views"]:
        view["resolution"] = [res, res * 3 // 4]
    shot["outputs"] = {"exr": True, "vdb": False}
    return shot


def render(cloudbake, shot, out_dir, threads):
    """Renders `shot` into out_dir unless its stats are there already; returns the stats."""
    stats_path = os.path.join(out_dir, "stats.json")
    if not os.path.exists(stats_path):
        os.makedirs(out_dir, exist_ok=True)
        shot_path = os.path.join(out_dir, "shot.json")
        with open(shot_path, "w") as f:
            json.dump(shot, f)
        subprocess.run([cloudbake, "render", shot_path, "--out", out_dir, "--threads",
                        str(threads), "--quiet", "--stats-json", stats_path], check=True,
                       stdout=subprocess.DEVNULL)
    with open(stats_path) as f:
        return json.load(f)


def compare_all(cloudbake, a, b, alpha_from, cloud_alpha):
    """Every layer of a against b over the pixels where alpha_from's alpha >= cloud_alpha."""
    out = subprocess.run([cloudbake, "compare", a, b, "--json", "--cloud-alpha", str(cloud_alpha),
                          "--mask-from", alpha_from], check=True, capture_output=True,
                         text=True).stdout
    return json.loads(out)


def compare(cloudbake, a, b, alpha_from, cloud_alpha):
    """`scattered` of a against b over the pixels where alpha_from's alpha >= cloud_alpha."""
    return compare_all(cloudbake, a, b, alpha_from, cloud_alpha)["scattered"]


def references(cloudbake, shot, scene, args):
    """The scene's two `pathtrace` references (seeds 1 and 2, args.ref_spp each), rendered once
    and cached under WORK/ref/ (shared by the benches); returns their folders, their stats and,
    per view, the relative RMS difference of their cloud's own light (sqrt 2 times one render's
    noise)."""
    refs, stats = [], []
    for seed in (1, 2):
        s = json.loads(json.dumps(shot))
        s["bake"] = {"method": "pathtrace", "samples": args.ref_spp, "seed": seed}
        out = os.path.join(args.work, "ref", "%s-%d-%d-%d" % (scene, args.res, args.ref_spp, seed))
        stats.append(render(cloudbake, s, out, args.threads))
        refs.append(out)
    diffs = []
    for v in shot["views"]:
        a, b = (os.path.join(r, v["name"] + ".exr") for r in refs)
        diffs.append(compare(cloudbake, a, b, a, args.cloud_alpha)["rel_rmse"])
    return refs, stats, diffs


def steps(stats, kind):
    return [s["seconds"] for s in stats["steps"] if s["step"] == kind]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--res", type=int, default=160)
    ap.add_argument("--ref-spp", type=int, default=1024)
    # Rays per pixel of the photon views: the reference averages over each pixel's area, so one
    # ray through its centre would count the aliasing of thin edges as error.
    # 16 leave the sub-pixel silver lining of views against the sun aliased: the backlit
    # cumulus' sun single scattering (method single, lattice 320, against pathtrace with
    # max_depth 1) measured 0.216, 0.067 and 0.052 at 16, 64 and 256 rays per pixel.
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--cloud-alpha", type=float, default=0.05)
    ap.add_argument("--scenes",
                    default=",".join(s for s in SCENES if s not in ("droplet", "skyonly")))
    ap.add_argument("--sweep", default="default", choices=sorted(SWEEPS))
    ap.add_argument("--work", default=None)
    args = ap.parse_args()
    args.work = args.work or tempfile.mkdtemp(prefix="photon_bench.")
    cloudbake = os.environ.get("CLOUDBAKE") or os.path.join(args.build, "tools", "cloudbake",
                                                            "cloudbake")
    print("| scene | photons | order | zonal | lattice | tally | bake s | s/view | peak MiB | "
          "rel. RMSE | bias | ref. noise | per view, less ref. noise |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for scene in args.scenes.split(","):
        shot = load_scene(scene, args.res)
        if shot is None:
            continue
        views = [v["name"] for v in shot["views"]]
        refs, _, diffs = references(cloudbake, shot, scene, args)
        ref_noise = [d / 2 for d in diffs]  # the noise of the two references' mean
        for photons, order, lattice, tally, zonal in SWEEPS[args.sweep]:
            s = json.loads(json.dumps(shot))
            s["bake"] = {"method": "photon", "photons": photons, "order": order,
                         "light_resolution": lattice, "tally_resolution": tally,
                         "zonal_order": zonal, "samples": args.samples}
            out = os.path.join(args.work, scene, "%d-%d-%d-%d-%d-%d" % (
                photons, order, lattice, tally, zonal, args.samples))
            stats = render(cloudbake, s, out, args.threads)
            errs, biases, own = [], [], []
            for v, diff in zip(views, diffs):
                # Against each reference, then the mean: the two differ only by their noise.
                rows = [compare(cloudbake, os.path.join(out, v + ".exr"),
                                os.path.join(r, v + ".exr"), os.path.join(r, v + ".exr"),
                                args.cloud_alpha) for r in refs]
                errs.append(sum(r["rel_rmse"] for r in rows) / 2)
                own.append(math.sqrt(max(0.0, errs[-1] ** 2 - diff ** 2 / 2)))
                biases.append(sum(r["mean"] / r["reference_mean"] - 1 for r in rows) / 2)
            view_s = steps(stats, "view")
            print("| %s | %d | %d | %d | %d | %d | %.2f | %.3f | %.0f | %.4f | %+.4f | %.4f | %s |" %
                  (scene, photons, order, zonal, lattice, tally, sum(steps(stats, "bake")),
                   sum(view_s) / max(1, len(view_s)), stats["peak_rss_mib"],
                   sum(errs) / len(errs), sum(biases) / len(biases),
                   sum(ref_noise) / len(ref_noise),
                   ", ".join("%s %.3f" % (v, e) for v, e in zip(views, own))), flush=True)
    print("work folder: %s" % args.work, file=sys.stderr)


if __name__ == "__main__":
    main()
