#!/usr/bin/env python3
"""The trade, measured and drawn (issue 13): each method's error against its cost as its knobs
grow, on the five scenes of bench/photon_bench.py, with the Pareto front.

For each scene (both views, --res x 3/4 --res pixels) it renders a reference with `pathtrace`
twice (seeds 1 and 2, --ref-spp each, cached under WORK/ref/ with bench/photon_bench.py's names,
so the two benches share references and photon renders), then every configuration of CONFIGS
once (`pointcloud` at lattice 64 also with its views marched one lattice voxel a step, twice
the default's: the cheap end, where the views' march is most of a shot), and writes

- a markdown table: scene | method | quality | bake s | s/view | peak MiB | rel. RMSE (the
  cloud's own light, sun + sky layers, over the cloud's pixels, with one reference's own noise
  taken out in quadrature) | beauty rel. RMSE | bias of the sun, sky, single and multiple
  layers (mean / reference mean - 1) | s for 4 x 640x480;
- the shot cost of four 640x480 views, from the measured seconds: a bake's seconds plus its
  views' scaled to 1 ray per pixel at 640x480 (auto's rule; the measured views trace
  --view-samples rays per pixel, so their rendering's seconds scale by 640 x 480 / (pixels x
  samples) and their EXR writing's, timed apart, by 640 x 480 / pixels), the
  path tracer's views scaled by 640 x 480 / pixels at the same paths per pixel (the error per
  pixel is taken as the measured one: the assumption the extrapolation rests on, nearest to
  true where the measured views trace about a 640x480 image's rays, --res 256 --view-samples 6);
- per scene and requested error (2, 5, 10, 30 %): the fastest configuration that reaches it, and
  its speedup over the path tracer (whose paths per pixel for any error follow from its
  measured noise, which falls as 1 / sqrt(spp); its seconds are its rendering's, in proportion
  to the paths, plus its views' EXR writing, which is the same at any paths per pixel, plus
  the volume's building, which every method's shot pays once: a bake's "bake s" includes it,
  and the path tracer's "bake s" is that alone);
- with --plot-dir, one PNG per scene (named --plot-prefix + scene): rel. RMSE against seconds
  for four 640x480 views, log-log, one line per method, the Pareto front dashed
  (python3-matplotlib, deploy/bench-packages.txt);
- with --json-out, every point.

Usage: /usr/bin/python3 bench/trade_curve.py [--build build] [--threads 2] [--res 80]
           [--ref-spp 8192 | --ref-spp disney=16384,...,8192] [--view-samples 16]
           [--scenes perlin,bunny,disney,thin,cumulus] [--photon-sweep default[,fine]]
           [--methods pathtrace,single,pointcloud,photon] [--exr-compression zip]
           [--work DIR] [--plot-dir docs/images]
           [--json-out FILE]
References are cached under WORK/ref/ and reused: render them where cores are many with
bench/photon_bench.py's names (SCENE-RES-SPP-SEED), then point --work at them.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import photon_bench as pb  # noqa: E402  (scenes, renders, comparisons)

TARGETS = (0.02, 0.05, 0.10, 0.30)
FULL_PIXELS = 640 * 480
VIEWS = 4


def configs(samples, photon_sweeps=("default",)):
    """(method, quality, bake, output folder name); photon's names are photon_bench's. Views
    from a bake trace `samples` rays per pixel; photon runs photon_bench's `photon_sweeps`."""
    out = []
    for spp in (4, 16, 64, 256):
        out.append(("pathtrace", "%d spp" % spp, {"method": "pathtrace", "samples": spp,
                                                  "seed": 3}, "pt-%d" % spp))
    for lattice in (64, 128, 256):
        out.append(("single", "lattice %d" % lattice,
                    {"method": "single", "light_resolution": lattice, "samples": samples},
                    "single-%d" % lattice))
    # A coarser lattice halves the views' march step too: the cheap end for a loose tolerance.
    for points, lattice in ((4096, 64), (16384, 64), (16384, 128), (65536, 128)):
        out.append(("pointcloud", "%d points, lattice %d" % (points, lattice),
                    {"method": "pointcloud", "points": points, "light_resolution": lattice,
                     "samples": samples},
                    "pointcloud-%d" % points + ("" if lattice == 128 else "-%d" % lattice)))
    rungs = [r for name in photon_sweeps for r in pb.SWEEPS[name]]
    for photons, order, lattice, tally, zonal in rungs:
        out.append(("photon", "%d photons, order %d, %d/%d" % (photons, order, lattice, tally),
                    {"method": "photon", "photons": photons, "order": order,
                     "light_resolution": lattice, "tally_resolution": tally,
                     "zonal_order": zonal, "samples": samples},
                    "%d-%d-%d-%d-%d-%d" % (photons, order, lattice, tally, zonal, samples)))
    return out


def coarse_configs(cloudbake, shot, scene, args):
    """`pointcloud` at lattice 64 with its views marched at one lattice voxel a step, twice the
    default's: the cheap end of the curve, where a view's march is most of a shot's seconds
    (the `step` knob is in world units, so the voxel is read from the bake: bake-slice)."""
    out = os.path.join(args.work, scene, "lattice-64")
    info = os.path.join(out, "slice.json")
    if not os.path.exists(info):
        s = json.loads(json.dumps(shot))
        s["bake"] = {"method": "pointcloud", "points": 4096, "light_resolution": 64}
        s["views"] = []
        s["outputs"] = {"exr": False, "vdb": True}
        pb.render(cloudbake, s, out, args.threads)
        text = subprocess.run([cloudbake, "bake-slice", os.path.join(out, "bake.vdb"), "--grid",
                               "density", "--png", os.path.join(out, "slice.png")], check=True,
                              capture_output=True, text=True).stdout
        with open(info, "w") as f:
            f.write(text)
    with open(info) as f:
        voxel = json.load(f)["voxel_size"]
    return [("pointcloud", "%d points, lattice 64, step 1 voxel" % points,
             {"method": "pointcloud", "points": points, "light_resolution": 64, "step": voxel,
              "samples": args.view_samples}, "pointcloud-%d-64-step1" % points)
            for points in (4096, 16384)]


def layers_against(cloudbake, out, refs, views, alpha):
    """compare --json of each view against each reference, averaged: {layer: (rel_rmse, bias)}."""
    acc = {}
    for v in views:
        for r in refs:
            res = pb.compare_all(cloudbake, os.path.join(out, v + ".exr"),
                                 os.path.join(r, v + ".exr"), os.path.join(r, v + ".exr"),
                                 alpha)
            for layer, row in res.items():
                bias = row["mean"] / row["reference_mean"] - 1 if row["reference_mean"] else 0.0
                e = acc.setdefault(layer, [0.0, 0.0, 0])
                e[0] += row["rel_rmse"]
                e[1] += bias
                e[2] += 1
    return {k: (e[0] / e[2], e[1] / e[2]) for k, e in acc.items()}


def view_write_seconds(stats):
    """A view's mean seconds of writing its EXR (older binaries did not time it apart: 0)."""
    views = [s for s in stats["steps"] if s["step"] == "view"]
    return sum(s.get("write", 0.0) for s in views) / max(1, len(views))


def volume_seconds(stats):
    """Seconds of building the shot's volume (a mesh's voxelisation, a VDB's read), which every
    method pays once per shot, the path tracer included."""
    return sum(s["seconds"] for s in stats["steps"] if s["step"] == "volume")


def shot_seconds(method, stats, res, samples):
    """Seconds for four 640x480 views from the measured run (see the module's docstring); a
    bake's views traced `samples` rays per pixel. The middle value is what precedes the views:
    the volume, and for a bake the bake."""
    views = [s for s in stats["steps"] if s["step"] == "view"]
    view_s = sum(s["seconds"] for s in views) / max(1, len(views))
    write_s = view_write_seconds(stats)  # scales by pixels, not rays
    scale = FULL_PIXELS / float(res * (res * 3 // 4))
    if method == "pathtrace":
        volume_s = volume_seconds(stats)
        return volume_s + VIEWS * view_s * scale, volume_s, view_s
    bake_s = sum(s["seconds"] for s in stats["steps"]
                 if s["step"] in ("bake", "precompute", "light", "volume"))
    rays_ratio = 1.0 / samples  # -> 1 ray per pixel at 640x480 (auto's rule)
    render_s = view_s - write_s
    return bake_s + VIEWS * (render_s * rays_ratio + write_s) * scale, bake_s, view_s


def pareto(points):
    """The points no other point beats in both seconds and error, by seconds."""
    front, best = [], float("inf")
    for p in sorted(points, key=lambda p: (p["shot_s"], p["error"])):
        if p["error"] < best:
            front.append(p)
            best = p["error"]
    return front


def plot(scene, points, path, res):
    try:
        import matplotlib
    except ImportError:
        sys.exit("--plot-dir needs matplotlib: apt-get install python3-matplotlib, and run this "
                 "script with /usr/bin/python3 (Debian's modules load there)")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4.2), dpi=110)
    for method in ("pathtrace", "single", "pointcloud", "photon"):
        pts = sorted((p for p in points if p["method"] == method), key=lambda p: p["shot_s"])
        if pts:
            ax.plot([p["shot_s"] for p in pts], [p["error"] for p in pts], "o-", label=method)
    front = pareto(points)
    ax.step([p["shot_s"] for p in front], [p["error"] for p in front], "k--", where="post",
            alpha=0.6, label="Pareto front")
    for t in TARGETS:
        ax.axhline(t, color="grey", lw=0.5, alpha=0.5)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds for four 640x480 views (2 cores, from the measured runs)")
    ax.set_ylabel("rel. RMSE of the cloud's own light")
    ax.set_title("%s (%dx%d): error against cost" % (scene, res, res * 3 // 4))
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def fastest(points, pt_noise_1spp, pt_seconds, target):
    """(name, seconds, speedup over the path tracer) of the cheapest way to `target`;
    pt_seconds(spp) is the path tracer's shot at spp paths per pixel."""
    spp = max(1.0, (pt_noise_1spp / target) ** 2)
    pt_s = pt_seconds(spp)
    options = [(p["method"] + " " + p["quality"], p["shot_s"]) for p in points
               if p["method"] != "pathtrace" and p["error"] <= target]
    options.append(("pathtrace %d spp" % math.ceil(spp), pt_s))
    name, s = min(options, key=lambda o: o[1])
    return name, s, pt_s / s


def pathtrace_seconds(points, res):
    """The path tracer's shot seconds as a function of paths per pixel: its rendering scales
    by paths (seconds per path from the run with the most), its EXR writing does not (the
    mean of its runs' measured writes), both by pixels to four 640x480 views; and the volume,
    built once per shot (the mean of its runs'), as a bake's seconds count it."""
    pts = [p for p in points if p["method"] == "pathtrace"]
    longest = max(pts, key=lambda p: p["samples"])
    scale = FULL_PIXELS / float(res * (res * 3 // 4))
    render_per_spp = (longest["view_s"] - longest["write_s"]) / longest["samples"]
    write_s = sum(p["write_s"] for p in pts) / len(pts)
    volume_s = sum(p["bake_s"] for p in pts) / len(pts)
    return lambda spp: volume_s + VIEWS * scale * (render_per_spp * spp + write_s)


def ref_spp(spec, scene):
    """The reference's paths per pixel for `scene` from --ref-spp: "N" for every scene, or
    "scene=N,...,N" with the bare N for the scenes not named."""
    spp = {}
    for part in spec.split(","):
        name, _, value = part.rpartition("=")
        try:
            spp[name] = int(value)
        except ValueError:
            sys.exit("--ref-spp: %r is not N or scene=N" % part)
        if spp[name] < 1:
            sys.exit("--ref-spp: %r must be at least 1" % part)
        if name and name not in pb.SCENES:
            sys.exit("--ref-spp: %r names no scene (%s)" % (part, ", ".join(pb.SCENES)))
    if scene not in spp and "" not in spp:
        sys.exit("--ref-spp: no value for scene %s (add a bare N for the others)" % scene)
    return spp.get(scene, spp.get(""))


def measure_scene(cloudbake, scene, args):
    shot = pb.load_scene(scene, args.res)
    if shot is None:
        return None
    views = [v["name"] for v in shot["views"]]
    ref_args = argparse.Namespace(**vars(args))
    ref_args.ref_spp = ref_spp(args.ref_spp, scene)
    refs, ref_stats, diffs = pb.references(cloudbake, shot, scene, ref_args)
    ref_noise = sum(diffs) / len(diffs) / math.sqrt(2)  # one render's noise
    if args.references_only:
        print("%s: %d spp, reference noise %.4f per render, %.1f s per render" % (
            scene, ref_args.ref_spp, ref_noise, sum(st["seconds"] for st in ref_stats) / 2),
            flush=True)
        return None
    points = []
    if args.exr_compression:
        shot["outputs"]["exr_compression"] = args.exr_compression
    runs = configs(args.view_samples, args.photon_sweeps)
    if "pointcloud" in args.methods:
        runs += coarse_configs(cloudbake, shot, scene, args)
    for method, quality, bake, name in runs:
        if method not in args.methods:
            continue
        s = json.loads(json.dumps(shot))
        s["bake"] = bake
        if args.exr_compression and args.exr_compression != "zip":
            name += "-" + args.exr_compression  # the folders' stats are reused: one per kind
        out = os.path.join(args.work, scene, name)
        stats = pb.render(cloudbake, s, out, args.threads)
        layers = layers_against(cloudbake, out, refs, views, args.cloud_alpha)
        raw = layers["scattered"][0]
        shot_s, bake_s, view_s = shot_seconds(method, stats, args.res, args.view_samples)
        points.append({
            "scene": scene, "method": method, "quality": quality, "bake_s": bake_s,
            "view_s": view_s, "peak_mib": stats["peak_rss_mib"], "shot_s": shot_s,
            "error": math.sqrt(max(0.0, raw * raw - ref_noise * ref_noise)),
            "beauty_error": layers["beauty"][0],
            "bias": {k: layers[k][1] for k in ("sun", "sky", "single", "multiple")},
            "samples": bake.get("samples", 1), "write_s": view_write_seconds(stats)})
    return points, ref_noise


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default=os.path.join(pb.ROOT, "build"))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--res", type=int, default=80)
    ap.add_argument("--ref-spp", default="8192",
                    help="paths per pixel of each reference: N, or scene=N,...,N")
    # 16 at 80x60 (the rays of a quarter of a 640x480 image at 1 per pixel); 6 at 256x192 trace
    # about the rays of a 640x480 image.
    ap.add_argument("--view-samples", type=int, default=16,
                    help="rays per pixel of the views from a bake")
    ap.add_argument("--photon-sweep", default="default",
                    help="photon's rungs: photon_bench sweeps, comma-separated (default; "
                    "default,fine adds 16M photons for 2 %%)")
    ap.add_argument("--methods", default="pathtrace,single,pointcloud,photon",
                    help="the methods to run, comma-separated (pathtrace is always run: the "
                    "speed-ups are over it)")
    ap.add_argument("--exr-compression", default=None,
                    choices=["none", "rle", "zips", "zip", "piz"],
                    help="outputs.exr_compression of every shot (default: the shot's, zip); "
                    "the run folders get its name as a suffix")
    ap.add_argument("--cloud-alpha", type=float, default=0.05)
    ap.add_argument("--scenes", default="perlin,bunny,disney,thin,cumulus")
    ap.add_argument("--work", default=None)
    ap.add_argument("--references-only", action="store_true",
                    help="render (or find) the references, print their noise and stop")
    ap.add_argument("--plot-dir", default=None)
    ap.add_argument("--plot-prefix", default="trade_", help="PNG names: PREFIX + scene + .png")
    ap.add_argument("--json-out", default=None)
    args = ap.parse_args()
    if args.view_samples < 1:
        ap.error("--view-samples must be at least 1")
    args.photon_sweeps = tuple(args.photon_sweep.split(","))
    args.methods = set(args.methods.split(",")) | {"pathtrace"}
    unknown = args.methods - {"pathtrace", "single", "pointcloud", "photon"}
    if unknown:
        ap.error("--methods: %s is not pathtrace, single, pointcloud or photon"
                 % ", ".join(sorted(unknown)))
    for name in args.photon_sweeps:
        if name not in pb.SWEEPS:
            ap.error("--photon-sweep: %r is not one of %s" % (name, ", ".join(sorted(pb.SWEEPS))))
    args.work = args.work or tempfile.mkdtemp(prefix="trade_curve.")
    cloudbake = os.environ.get("CLOUDBAKE") or os.path.join(args.build, "tools", "cloudbake",
                                                            "cloudbake")
    if not args.references_only:
        print("| scene | method | quality | bake s | s/view | peak MiB | rel. RMSE | beauty | "
              "bias sun/sky/single/multiple | s, 4 x 640x480 |")
        print("|---|---|---|---|---|---|---|---|---|---|")
    all_points, summary = [], []
    for scene in args.scenes.split(","):
        measured = measure_scene(cloudbake, scene, args)
        if measured is None:
            continue
        points, ref_noise = measured
        all_points.extend(points)
        for p in points:
            b = p["bias"]
            print("| %s | %s | %s | %.2f | %.3f | %.0f | %.4f | %.4f | %+.3f/%+.3f/%+.3f/%+.3f | "
                  "%.1f |" % (scene, p["method"], p["quality"], p["bake_s"], p["view_s"],
                              p["peak_mib"], p["error"], p["beauty_error"], b["sun"], b["sky"],
                              b["single"], b["multiple"], p["shot_s"]), flush=True)
        # The path tracer's noise per path and seconds per path per pixel from its measured
        # points (least squares of error^2 x spp; seconds linear in spp).
        pts = [p for p in points if p["method"] == "pathtrace"]
        noise_1spp = math.sqrt(sum(p["error"] ** 2 * p["samples"] for p in pts) / len(pts))
        pt_seconds = pathtrace_seconds(points, args.res)
        for t in TARGETS:
            summary.append((scene, t) + fastest(points, noise_1spp, pt_seconds, t))
        print("%s: reference noise %.4f per render" % (scene, ref_noise), file=sys.stderr)
        if args.plot_dir:
            os.makedirs(args.plot_dir, exist_ok=True)
            plot(scene, points, os.path.join(args.plot_dir, "%s%s.png" % (args.plot_prefix, scene)),
                 args.res)
    if args.references_only:
        return
    print("\n| scene | requested error | fastest | s, 4 x 640x480 | x faster than pathtrace |")
    print("|---|---|---|---|---|")
    for scene, t, name, s, speedup in summary:
        print("| %s | %g | %s | %.1f | %.1f |" % (scene, t, name, s, speedup))
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(all_points, f, indent=1)
    print("work folder: %s" % args.work, file=sys.stderr)


if __name__ == "__main__":
    main()
