"""The rays a sample costs in Mitsuba 3 and in ours, on the same scene and settings.

    python -m bench.mitsuba_rays                                # mitsuba-cornell, 256x256, 64 spp
    python -m bench.mitsuba_rays --scenes mitsuba-cornell,open-1k --spp 16

The scenes are bench.scenes' (mitsuba-cornell, open-1k, open-1m), which bench.mitsuba_side loads.

Mitsuba's side: bench/mitsuba_rays.c, built with gcc into a shared library and preloaded
(LD_PRELOAD) into a process that loads the scene with bench.mitsuba_side and renders it once
(`llvm_ad_rgb`, `path`, max_depth and rr_depth as given). The library stands in for the entry
points of Mitsuba's own libembree3 and counts each call, its active lanes and its coherent flag.
Ours: `tracer.render` at the same settings (the lanes), its closest-hit and shadow-ray counts.
Prints per scene and renderer the closest-hit and shadow rays per sample, and for Mitsuba the
active lanes per 16-wide call and the share of calls flagged coherent (the camera rays' packets).
Needs mitsuba, gcc and, for the LLVM backend, DRJIT_LIBLLVM_PATH (see bench.throughput).
"""
import argparse
import importlib.util
import json
import os
import subprocess
import sys
import tempfile

from . import common, mitsuba_side, throughput

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "bench", "results", "mitsuba_rays")

_MITSUBA_RENDER = """
import sys, json
import numpy as np
import mitsuba as mi
from bench import mitsuba_side
job = json.loads(sys.argv[1])
scene = mitsuba_side.load(job["spec"], job["spp"], job["max_depth"], job["rr_depth"], job["width"], job["height"],
                          variant=job["variant"])
np.asarray(mi.render(scene, spp=job["spp"], seed=0))
"""


def build(folder):
    """The counting library, built from bench/mitsuba_rays.c into `folder`."""
    lib = os.path.join(folder, "mitsuba_rays.so")
    subprocess.run(["gcc", "-O2", "-shared", "-fPIC", "-o", lib, os.path.join(ROOT, "bench", "mitsuba_rays.c"),
                    "-ldl"], check=True)
    return lib


def mitsuba_counts(lib, job):
    """{entry point: [calls, active lanes, coherent calls]} of one Mitsuba render of job's scene
    (job: spec, a bench.scenes dict; spp, width, height, max_depth, rr_depth; variant)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "counts.json")
        embree = os.path.join(os.path.dirname(importlib.util.find_spec("mitsuba").origin), "libembree3.so")
        env = dict(os.environ, LD_PRELOAD=lib, MITSUBA_RAYS_OUT=out, MITSUBA_EMBREE=embree, PYTHONPATH=ROOT)
        subprocess.run([sys.executable, "-c", _MITSUBA_RENDER, json.dumps(job)], check=True, env=env, cwd=ROOT)
        with open(out) as f:
            return json.load(f)


def totals(counts):
    """(closest-hit rays, shadow rays) of mitsuba_counts' counts, every width together."""
    return tuple(sum(counts[f"{kind}{w}"][1] for w in (1, 4, 8, 16)) for kind in ("intersect", "occluded"))


def our_counts(job):
    """(samples, closest-hit rays, shadow rays) of one of our renders of job's scene."""
    import tracer

    scene = tracer.load_scene(job["spec"]["obj"], width=job["width"], height=job["height"])
    st = tracer.render(scene, spp=job["spp"], seed=0, max_depth=job["max_depth"], rr_depth=job["rr_depth"]).stats
    return st["samples"], st["camera_and_bounce_rays"], st["shadow_rays"]


def rows(name, job, lib):
    """The table's rows for scene `name`: ours, then Mitsuba's."""
    n, rays, shadows = our_counts(job)
    out = [(name, "ours (lanes)", rays / n, shadows / n, "16 (packed)", "-")]
    c = mitsuba_counts(lib, job)
    samples = job["width"] * job["height"] * job["spp"]
    hits, shadow = totals(c)
    wide = [w for w in (16, 8, 4) if c[f"intersect{w}"][0]]
    w = wide[0] if wide else 1
    ic, il, ih = c[f"intersect{w}"]
    oc, ol, _ = c[f"occluded{w}"]
    lanes = f"{il / max(ic, 1):.1f} / {ol / max(oc, 1):.1f} of {w}"
    out.append((name, "Mitsuba 3", hits / samples, shadow / samples, lanes, f"{ih / max(ic, 1):.3f}"))
    return out


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.mitsuba_rays", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default="mitsuba-cornell")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--width", type=int, default=256)
    p.add_argument("--height", type=int, default=256)
    p.add_argument("--max-depth", type=int, default=8)
    p.add_argument("--rr-depth", type=int, default=5)
    a = p.parse_args(argv)
    names = a.scenes.split(",")
    for name in names:
        if name not in throughput.NAMED or name == "staircase":
            print(f"bench.mitsuba_rays: {name}: not one of bench.scenes' scenes (open-1k, open-1m, mitsuba-cornell)",
                  file=sys.stderr)
            return 2
    lib = common.built_with_gcc("bench.mitsuba_rays", "gcc to build bench/mitsuba_rays.c", OUT, build)
    if lib is None:
        return 2
    print("| scene | renderer | closest-hit rays / sample | shadow rays / sample | active lanes a call "
          "(closest-hit / shadow) | coherent share of closest-hit calls |")
    print("|---|---|---|---|---|---|")
    for name in names:
        job = {"spec": throughput.scene_spec(name), "spp": a.spp, "width": a.width, "height": a.height,
               "max_depth": a.max_depth, "rr_depth": a.rr_depth, "variant": mitsuba_side.VARIANT}
        for r in rows(name, job, lib):
            print(f"| {r[0]} | {r[1]} | {r[2]:.3f} | {r[3]:.3f} | {r[4]} | {r[5]} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
