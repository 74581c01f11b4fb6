"""Seconds a sample of each method's final passes, beside the first method's (the baseline).

    python -m bench.method_cost --scenes veach-ajar --scene-dir ../shared/scenes --width 320 --height 180 \\
        --methods "bsdf/path:nee=0,photon/path:nee=0,ppg/path:nee=0" --spp 64 --seeds 2
    python -m bench.method_cost --scenes cornell,veach-ajar --scene-dir ../shared/scenes --methods bsdf,gpt-l1

Issue 58's targets are ratios of these figures: a guide's final passes at most 1.2x bsdf's time a
sample, gpt's passes (a base path and its four offsets a sample) at most 3x. A method is a bench
method (bench.common.render_args: `photon`, `gpt-l1`, `photon/path:nee=0`, ...). Each method renders
once at 2 spp first (its kernels loaded, its pages touched), then once per seed at --spp. Only the
passes that make the image count: kind "final", or "gradient" (gpt). The figure is their seconds
over their spp; a guide's split copies are in its seconds. A guide's training, pilot and trial
passes are reported apart (`other_pass_seconds`), and so is the render's time outside its passes
(`time_between`: a guide's updates between passes, gpt's reconstruction after them). Prints a table
(min-max over the seeds) and writes the records to bench/results/method_cost.json.
"""
import argparse
import os
import sys
from statistics import median

import tracer

from . import atomic
from .common import check_method, render_args, scene_name, scene_path
from .reference import ROOT

OUT = os.path.join(ROOT, "bench", "results", "method_cost.json")
IMAGE_PASSES = ("final", "gradient")


def cost(stats):
    """(seconds, spp) of a render's passes that make its image, and the seconds of the others."""
    own = [p for p in stats["passes"] if p["kind"] in IMAGE_PASSES]
    other = sum(p["time"] for p in stats["passes"] if p["kind"] not in IMAGE_PASSES)
    return sum(p["time"] for p in own), sum(p["spp"] for p in own), other


def measure(scene, method, spp, seeds, threads=None):
    """One record per seed: the image passes' seconds and spp, seconds a spp, the other passes'
    seconds, the render's time outside its passes (a guide's updates, gpt's solve) and the render's
    own counters (rays, shadow rays, seconds by stage over every pass)."""
    args = render_args(method)
    tracer.render(scene, spp=2, seed=0, threads=threads, progress=False, **args)  # loaded and touched
    rows = []
    for seed in seeds:
        st = tracer.render(scene, spp=spp, seed=seed, threads=threads, progress=False, **args).stats
        seconds, own_spp, other = cost(st)
        passes = sum(p["time"] for p in st["passes"])
        rows.append({"method": method, "seed": seed, "spp": spp, "image_spp": own_spp, "image_seconds": seconds,
                     "seconds_per_spp": seconds / own_spp, "other_pass_seconds": other,
                     "time_between": max(st["time_render"] - passes, 0.0), "samples": st["samples"],
                     "nonfinite_samples": st["nonfinite_samples"], "threads": st["threads"],
                     "lane_samples": st["lane_samples"], "split_copies": st["split_copies"],
                     "rays": st["camera_and_bounce_rays"], "shadow_rays": st["shadow_rays"],
                     "time_stages": st["time_stages"]})
    return rows


def table(records, methods):
    """Markdown rows per scene and method: seconds a spp (min-max over seeds), its ratio to the
    baseline's (the first method's) medians, the other passes' seconds, the time between passes."""
    lines = ["| scene | method | image spp | s a spp | x baseline | other passes s | outside the passes s |",
             "|---|---|---|---|---|---|---|"]
    for scene in dict.fromkeys(r["scene"] for r in records):
        mine = [r for r in records if r["scene"] == scene]
        base = median([r["seconds_per_spp"] for r in mine if r["method"] == methods[0]])
        for m in methods:
            rows = [r for r in mine if r["method"] == m]
            s = [r["seconds_per_spp"] for r in rows]
            lines.append(f"| {scene} | {m} | {min(r['image_spp'] for r in rows)} | {min(s):.4f}-{max(s):.4f} | "
                         f"{median(s) / base:.2f} | {median([r['other_pass_seconds'] for r in rows]):.2f} | "
                         f"{median([r['time_between'] for r in rows]):.2f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.method_cost", description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="cornell", help="comma-separated scene names or files")
    ap.add_argument("--scene-dir", default=None, help="where external scene names are looked up")
    ap.add_argument("--methods", default="bsdf,photon,gpt-l1",
                    help="comma-separated bench methods; the first is the baseline")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--width", type=int, default=None)
    ap.add_argument("--height", type=int, default=None)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--json", default=OUT)
    a = ap.parse_args(argv)
    methods = [m for m in a.methods.split(",") if m]
    if a.spp < 2 or a.seeds < 1 or not methods:
        ap.error("--spp must be at least 2, --seeds at least 1, and --methods name one method or more")
    for m in methods:
        check_method(m)
    given = [s for s in a.scenes.split(",") if s]
    records = []
    for name, path in zip(map(scene_name, given), (scene_path(s, a.scene_dir) for s in given)):
        size = {k: v for k, v in (("width", a.width), ("height", a.height)) if v is not None}
        scene = tracer.load_scene(path, **size)
        for m in methods:
            for r in measure(scene, m, a.spp, range(a.seeds), a.threads):
                records.append(dict(r, scene=name, width=scene.width, height=scene.height))
                print(f"{name} {m} seed {r['seed']}: {r['seconds_per_spp']:.4f} s a spp over {r['image_spp']} spp",
                      flush=True)
    nonfinite = any(r["nonfinite_samples"] for r in records)
    if nonfinite:
        print("bench.method_cost: non-finite samples counted", file=sys.stderr)
    print(table(records, methods))
    atomic.write_json(a.json, records, indent=1)
    return 1 if nonfinite else 0


if __name__ == "__main__":
    sys.exit(main())
