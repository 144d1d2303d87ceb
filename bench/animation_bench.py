#!/usr/bin/env python3
"""A `precomputed` animation's frames: what an endless walk costs per frame, lit and rendered,
and how many of its frames show a blend (a, b, w) an earlier frame showed, whose light and views
are then reused (docs/methods.md, "Frames the walk shows again").

Renders bench/speed/animation.json (frames.json's cloud, 8 basic volumes, 48 frames of 640x480,
dissolves of 3) with `cloudbake render --stats-json` and prints the frames, the blends lit, the
views replayed, the seconds of the frames (their `light` and `view` steps, EXR writing included)
and of the database's precompute. --cloudbake names another build's binary (for an A/B).

Usage: /usr/bin/python3 bench/animation_bench.py [--build build] [--cloudbake PATH]
           [--threads 2] [--shot bench/speed/animation.json] [--work DIR]
"""
import argparse
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from trade_bench import render, steps  # noqa: E402  (a child render and its steps)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--cloudbake", default=None)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--shot", default=os.path.join(ROOT, "bench", "speed", "animation.json"))
    ap.add_argument("--work", default=None)
    a = ap.parse_args()
    cloudbake = a.cloudbake or os.path.join(a.build, "tools", "cloudbake", "cloudbake")
    with open(a.shot) as f:
        shot = json.load(f)
    work = a.work or tempfile.mkdtemp(prefix="animation_bench_")
    stats = render(cloudbake, shot, work, a.threads)
    light = steps(stats, "light")
    views = steps(stats, "view")
    frames = len(light)
    lit = sum(1 for s in light if not s.get("repeated"))
    replayed = sum(1 for s in views if s.get("repeated"))
    seconds = sum(s["seconds"] for s in light + views)
    precompute = sum(s["seconds"] for s in steps(stats, "precompute"))
    print("frames %d, blends lit %d, views replayed %d of %d" % (frames, lit, replayed, len(views)))
    print("frames: %.2f s, %.3f s a frame (%.2f frames per second), lit and rendered, EXRs "
          "written; precompute %.2f s; whole run %.2f s at %d threads"
          % (seconds, seconds / max(frames, 1), frames / max(seconds, 1e-9), precompute,
             stats["seconds"], a.threads))


if __name__ == "__main__":
    main()
