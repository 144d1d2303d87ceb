#!/usr/bin/env python3
"""Two builds' bake methods side by side against the path tracer, layer by layer.

For each scene (bench/photon_bench.py's bunny, disney and cumulus, and bench/auto_bench.py's
held-out scenes, at --res x 3/4 --res pixels, both views) it renders each method at its
defaults with 16 rays a pixel, once with --old and once with --new, and prints per method

  scene | method | old: scattered, single (bias) | new: the same

- scattered: relative RMSE of the cloud's own light (sun + sky layers) over the cloud's pixels
  (reference alpha >= 0.05), averaged over the views and the two references;
- single, bias: the same of the `single` layer, and its mean bias.

The references (pathtrace, seeds 1 and 2) are those the two benches cache under their work
folders: --photon-work (8192 paths a pixel) and --auto-work (4096), rendered with --old when
absent. Used for render_from_bake 3's short characteristic (docs/methods.md, "The sun's
transmittance between voxels"):

  /usr/bin/python3 bench/layers_bench.py --old OLD/cloudbake --new build/tools/cloudbake/cloudbake \\
      --photon-work /tmp/pb --auto-work /tmp/ab8 --work /tmp/layers
"""
import argparse
import json
import os
import sys
import types

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import auto_bench  # noqa: E402
import photon_bench  # noqa: E402


def scenes(args):
    for name in ("bunny", "disney", "cumulus"):
        yield name, photon_bench.load_scene(name, args.res), args.photon_work, 8192
    for name in ("perlin_dense", "bunny_thin", "disney_top", "sphere", "layer_albedo"):
        base, change = auto_bench.HELD_OUT[name]
        shot = photon_bench.load_scene(base, args.res)
        change(shot)
        shot["name"] = name
        yield name, shot, args.auto_work, 4096


def errors(cloudbake, out, shot, refs):
    """Mean over views and references: scattered RMSE, single RMSE, single bias."""
    rows = []
    for view in shot["views"]:
        for ref in refs:
            r = os.path.join(ref, view["name"] + ".exr")
            c = photon_bench.compare_all(cloudbake, os.path.join(out, view["name"] + ".exr"), r,
                                         r, 0.05)
            single = c["single"]
            rows.append((c["scattered"]["rel_rmse"], single["rel_rmse"],
                         single["mean"] / single["reference_mean"] - 1))
    return [sum(col) / len(rows) for col in zip(*rows)]


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--old", required=True, help="the cloudbake executable before the change")
    p.add_argument("--new", required=True, help="the cloudbake executable after it")
    p.add_argument("--methods", default="single,pointcloud,photon")
    p.add_argument("--res", type=int, default=80)
    p.add_argument("--photon-work", required=True, help="bench/photon_bench.py's --work")
    p.add_argument("--auto-work", required=True, help="bench/auto_bench.py's --work")
    p.add_argument("--work", required=True, help="where the renders go")
    p.add_argument("--threads", type=int, default=2)
    args = p.parse_args()
    for name, shot, work, spp in scenes(args):
        ref_args = types.SimpleNamespace(work=work, ref_spp=spp, res=args.res,
                                         threads=args.threads, cloud_alpha=0.05)
        refs, _, _ = photon_bench.references(args.old, shot, name, ref_args)
        for method in args.methods.split(","):
            cells = []
            for tag, exe in (("old", args.old), ("new", args.new)):
                s = json.loads(json.dumps(shot))
                s["bake"] = {"method": method, "samples": 16}
                out = os.path.join(args.work, name, "%s-%s" % (method, tag))
                photon_bench.render(exe, s, out, args.threads)
                scattered, single, bias = errors(exe, out, shot, refs)
                cells.append("%s: scattered %.4f, single %.4f (%+.3f)" %
                             (tag, scattered, single, bias))
            print("| %s | %s | %s |" % (name, method, " | ".join(cells)), flush=True)


if __name__ == "__main__":
    main()
