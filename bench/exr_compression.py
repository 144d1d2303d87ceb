#!/usr/bin/env python3
"""What `outputs.exr_compression` costs and saves: each scene of bench/photon_bench.py rendered at
640x480 with one method, once per compression, in turns (so a noisy machine slows all of them
alike), printing per view the seconds of writing its EXR (`write` in `--stats-json`, median of
--repeats) and the file's size. The pixels are the same whatever the compression; the script
checks that each file holds the same pixels as the `zip` one (`cloudbake compare`).

Usage: /usr/bin/python3 bench/exr_compression.py [--build build] [--threads 2] [--repeats 3]
           [--scenes thin,perlin,bunny] [--method pointcloud] [--compressions none,rle,zips,zip,piz]
           [--work DIR]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import photon_bench as pb  # noqa: E402  (scenes)


def run(cloudbake, shot, out_dir, threads):
    """Renders `shot` into out_dir (again: pb.render reuses a folder's stats); returns each
    view's seconds of writing its EXR."""
    stats_path = os.path.join(out_dir, "stats.json")
    if os.path.exists(stats_path):
        os.remove(stats_path)
    stats = pb.render(cloudbake, shot, out_dir, threads)
    return {s["view"]: s["write"] for s in stats["steps"] if s["step"] == "view"}


def same_pixels(cloudbake, a, b):
    """True when `compare` finds no difference in any layer's R, G, B (its relative RMSE is 0,
    or both means are 0). It does not read alpha; the exact equality of every channel is
    tests/core/io's ExrIo.EveryCompressionKeepsThePixels."""
    out = subprocess.run([cloudbake, "compare", a, b, "--json"], check=True,
                         capture_output=True, text=True).stdout
    return all(layer["rel_rmse"] == 0 or (layer["mean"] == 0 and layer["reference_mean"] == 0)
               for layer in json.loads(out).values())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build", default=os.path.join(pb.ROOT, "build"))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scenes", default="thin,perlin,bunny")
    ap.add_argument("--method", default="pointcloud")
    ap.add_argument("--compressions", default="none,rle,zips,zip,piz")
    ap.add_argument("--work", default=None)
    args = ap.parse_args()
    cloudbake = os.environ.get("CLOUDBAKE") or os.path.join(args.build, "tools", "cloudbake",
                                                            "cloudbake")
    work = args.work or tempfile.mkdtemp(prefix="exr-compression-")
    compressions = args.compressions.split(",")
    print("| scene | view | compression | write s (median of %d) | MB | same pixels as zip |"
          % args.repeats)
    print("|---|---|---|---|---|---|")
    for scene in args.scenes.split(","):
        shot = pb.load_scene(scene, 640)
        if shot is None:
            continue
        shot["bake"] = {"method": args.method, "samples": 1}
        writes = {c: {} for c in compressions}
        for r in range(args.repeats):
            for c in compressions:
                shot["outputs"] = {"exr": True, "vdb": False, "exr_compression": c}
                out = os.path.join(work, scene, c)
                for view, seconds in run(cloudbake, shot, out, args.threads).items():
                    writes[c].setdefault(view, []).append(seconds)
        for view in writes[compressions[0]]:
            for c in compressions:
                path = os.path.join(work, scene, c, view + ".exr")
                zip_path = os.path.join(work, scene, "zip", view + ".exr")
                same = same_pixels(cloudbake, path, zip_path) if "zip" in compressions else "-"
                print("| %s | %s | %s | %.3f | %.1f | %s |" % (
                    scene, view, c, statistics.median(writes[c][view]),
                    os.path.getsize(path) / 1e6, same))
    print("work: %s" % work, file=sys.stderr)


if __name__ == "__main__":
    main()
