#!/usr/bin/env python3
"""The trade benchmark (issue 3, section 4): every bake method against the converged path tracer.

For each scene in bench/scenes/ and each method/quality it renders the scene's views with
`cloudbake render` (a child process per configuration, so peak memory is that configuration's
own) and prints a markdown table:

  scene | method | quality | bake s | render s/view | peak MiB | rel. RMSE

- bake s: the seconds of the run's bake, precompute and light steps (0 for pathtrace, which
  bakes nothing), from the child's `--stats-json` (docs/cli.md);
- render s/view: mean of its view steps' seconds (the whole path trace for pathtrace);
- peak MiB: the child's peak resident set size (the stats' peak_rss_mib);
- rel. RMSE: sqrt(mean over pixels and RGB of (x - r)^2) / mean(r) of the beauty image against the
  reference (pathtrace at --ref-spp), averaged over the scene's views (`cloudbake compare`).
The reference's own noise is printed per scene: an independent render at ref_spp/4 differs from
it by sigma * sqrt(1 + 4), so its RMSE / sqrt(5) estimates the reference's noise floor.
References are cached under WORK/ref/ by scene, spp and seed.

Usage: bench/trade_bench.py [--build build] [--threads 2] [--ref-spp 1024] [--scenes a,b]
                            [--methods m1,m2] [--work DIR] [--quick]
"""
import argparse
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "client", "python"))
from cloudbake_shot_paths import path_slots  # noqa: E402  (the keys of a shot that name files)


def methods(quick):
    pts = [2048, 8192, 32768] if quick else [16384, 65536, 262144]
    return [
        ("single", "lattice 128", {"method": "single", "light_resolution": 128}),
        ("pointcloud", "%d points" % pts[0], {"method": "pointcloud", "points": pts[0]}),
        ("pointcloud", "%d points" % pts[1], {"method": "pointcloud", "points": pts[1]}),
        ("pointcloud", "%d points" % pts[2], {"method": "pointcloud", "points": pts[2]}),
        ("pointcloud paper", "%d points, Eq. 2" % pts[1],
         {"method": "pointcloud", "points": pts[1], "rule": "paper", "output_mapping": True}),
        ("precomputed", "K %d" % (pts[0] // 4), {"method": "precomputed", "light_resolution": 128,
                                                   "sample_points": pts[0] // 4}),
        ("precomputed", "K %d" % (pts[1] // 4), {"method": "precomputed", "light_resolution": 128,
                                                   "sample_points": pts[1] // 4}),
        ("pathtrace", "16 spp", {"method": "pathtrace", "samples": 16, "seed": 3}),
    ]


def absolutise(shot, folder):
    """Relative asset paths resolve against the scene file's folder (as the parser does);
    returns the first that does not exist, or None."""
    for container, key in path_slots(shot):
        if not os.path.isabs(container[key]):
            container[key] = os.path.normpath(os.path.join(folder, container[key]))
            if not os.path.exists(container[key]):
                return container[key]
    return None


def render(cloudbake, shot, out_dir, threads):
    """Renders `shot` in a child `cloudbake render`; returns its `--stats-json` (docs/cli.md:
    seconds, peak_rss_mib, counters, steps, seconds_by_step)."""
    os.makedirs(out_dir, exist_ok=True)
    shot_path = os.path.join(out_dir, "shot.json")
    stats_path = os.path.join(out_dir, "stats.json")
    with open(shot_path, "w") as f:
        json.dump(shot, f, indent=1)
    proc = subprocess.run([cloudbake, "render", shot_path, "--out", out_dir, "--threads",
                           str(threads), "--quiet", "--stats-json", stats_path],
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if proc.returncode != 0:
        raise RuntimeError("cloudbake render failed (%d):\n%s"
                           % (proc.returncode, proc.stderr[-2000:]))
    with open(stats_path) as f:
        return json.load(f)


def steps(stats, *names):
    """The run's steps of the kinds `names` ("bake", "precompute", "light", "view", ...), in
    order."""
    return [s for s in stats["steps"] if s["step"] in names]


def run(cloudbake, shot, out_dir, threads):
    """Renders `shot`; returns (bake_s, [view seconds], peak MiB, run s)."""
    stats = render(cloudbake, shot, out_dir, threads)
    # precomputed: the precompute, plus lighting its one frame from it (a static volume).
    bake = [s["seconds"] for s in steps(stats, "bake", "precompute", "light")]
    views = [s["seconds"] for s in steps(stats, "view")]
    if shot["bake"]["method"] == "precomputed":
        for v in shot["views"]:  # frame 0 of its frame sequence is the view
            os.replace(os.path.join(out_dir, v["name"] + ".0000.exr"),
                       os.path.join(out_dir, v["name"] + ".exr"))
    return sum(bake), views, stats["peak_rss_mib"], stats["seconds"]


def rel_rmse(cloudbake, test, ref):
    out = subprocess.run([cloudbake, "compare", test, ref, "--json"], check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out)["beauty"]["rel_rmse"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--scenes", default="perlin_cloud,bunny_cloud,disney_cloud")
    ap.add_argument("--work", default=None, help="outputs and cached references "
                    "(default BUILD/bench_trade)")
    ap.add_argument("--methods", default=None,
                    help="only these methods, comma-separated (e.g. precomputed)")
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: 64x48 views, reference 64 spp, few points")
    a = ap.parse_args()
    cloudbake = os.path.join(a.build, "tools", "cloudbake", "cloudbake")
    if not os.access(cloudbake, os.X_OK):
        sys.exit("trade_bench: %s not found; build first (deploy/build.sh)" % cloudbake)
    work = a.work or os.path.join(a.build, "bench_trade" + ("_quick" if a.quick else ""))
    ref_spp = 64 if a.quick else a.ref_spp
    rows, notes = [], []
    for scene in a.scenes.split(","):
        path = os.path.join(ROOT, "bench", "scenes", scene + ".json")
        with open(path) as f:
            base = json.load(f)
        missing = absolutise(base, os.path.dirname(path))
        if missing:
            print("trade_bench: skipping %s: %s is missing (the shared data folder beside the "
                  "repository)" % (scene, missing), file=sys.stderr)
            continue
        if a.quick:
            for v in base["views"]:
                v["resolution"] = [64, 48]
        names = [v["name"] for v in base["views"]]

        def shot_with(bake):
            s = json.loads(json.dumps(base))
            s["bake"] = bake
            return s

        refs = {}
        for tag, spp, seed in (("a", ref_spp, 1), ("b", max(1, ref_spp // 4), 2)):
            d = os.path.join(work, "ref", "%s_%d_%d" % (scene, spp, seed))
            if not all(os.path.exists(os.path.join(d, n + ".exr")) for n in names):
                print("trade_bench: %s reference %d spp (seed %d)..." % (scene, spp, seed),
                      file=sys.stderr)
                _, views, _, wall = run(cloudbake, shot_with(
                    {"method": "pathtrace", "samples": spp, "seed": seed}), d, a.threads)
                notes.append("%s: reference %d spp rendered in %.0f s" % (scene, spp, wall))
            refs[tag] = d
        floor = sum(rel_rmse(cloudbake, os.path.join(refs["b"], n + ".exr"),
                             os.path.join(refs["a"], n + ".exr")) for n in names) / len(names)
        notes.append("%s: reference noise floor (rel. RMSE of the %d-spp reference) ~ %.4f"
                     % (scene, ref_spp, floor / 5 ** 0.5))
        for method, quality, bake in methods(a.quick):
            if a.methods and method not in a.methods.split(","):
                continue
            d = os.path.join(work, scene, (method + "_" + quality).replace(" ", "_"))
            print("trade_bench: %s %s %s..." % (scene, method, quality), file=sys.stderr)
            bake_s, views, peak, _ = run(cloudbake, shot_with(bake), d, a.threads)
            err = sum(rel_rmse(cloudbake, os.path.join(d, n + ".exr"),
                               os.path.join(refs["a"], n + ".exr")) for n in names) / len(names)
            rows.append((scene, method, quality, bake_s, sum(views) / max(1, len(views)), peak,
                         err))
            print("  bake %.2f s, render %.3f s/view, peak %.0f MiB, rel. RMSE %.3f"
                  % rows[-1][3:], file=sys.stderr)
    print("Views: %s; reference: pathtrace %d spp; threads: %d; phase HG g=0.85 (the real Mie "
          "table makes a converged reference far costlier)." % (
              "64x48" if a.quick else "160x120, 2 per scene", ref_spp, a.threads))
    print("rel. RMSE = sqrt(mean over pixels and RGB of (x - r)^2) / mean(r), beauty, mean over "
          "the views.\n")
    print("| scene | method | quality | bake s | render s/view | peak MiB | rel. RMSE |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print("| %s | %s | %s | %.2f | %.3f | %.0f | %.3f |" % r)
    print()
    for n in notes:
        print("- " + n)


if __name__ == "__main__":
    main()
