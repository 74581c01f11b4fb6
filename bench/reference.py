"""Reference images: plain path tracing at high spp, mean and variance, resumable.

    python -m bench.reference scenes/ajar/ajar.obj --time 600            # -> scenes/ajar/reference.*
    python -m bench.reference ../shared/scenes/veach-ajar/scene.obj --spp 4096 \\
        --out bench/results/references/veach-ajar
    python -m bench.reference scenes/ajar/ajar.obj --time 600 --append   # add more samples

Writes `<out>/reference.exr` with six channels (R, G, B, var.R, var.G, var.B: the mean and the
variance of that mean) and `<out>/reference.json`: spp, seconds, seeds, machine, and the
reference's own noise floor, the relMSE it is expected to have against the true image,
mean(var / (R^2 + 0.01)). A reference can judge errors down to about ten times that floor.

With --append, a new independent render (the next seed) is merged with the stored one, weighted
by spp, so a reference can be built over several sessions. The default output folder is the
scene's own folder for scenes inside this repository, and bench/results/references/<name>
otherwise (external scenes are never copied into the repository).
"""
import argparse
import json
import os
import platform
import time

import numpy as np

import tracer

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CHANNELS = ("R", "G", "B", "var.R", "var.G", "var.B")


def default_out(scene_path):
    p = os.path.abspath(scene_path)
    if p.startswith(os.path.join(ROOT, "scenes") + os.sep):
        return os.path.dirname(p)
    name = os.path.basename(os.path.dirname(p)) or os.path.splitext(os.path.basename(p))[0]
    return os.path.join(ROOT, "bench", "results", "references", name)


def noise_floor(mean, var):
    """Expected relMSE of an estimate with per-pixel variance `var` around `mean`."""
    return float(np.mean(var / (mean.astype(np.float64) ** 2 + 0.01)))


def load(out):
    """(mean (H,W,3), variance of the mean (H,W,3), metadata) of the reference in folder `out`."""
    data = tracer.read_image(os.path.join(out, "reference.exr")).astype(np.float64)
    with open(os.path.join(out, "reference.json")) as f:
        meta = json.load(f)
    return data[:, :, :3], data[:, :, 3:6], meta


def merge(m1, v1, n1, m2, v2, n2):
    """Combine two independent estimates weighted by spp: mean and variance of the mean."""
    w1, w2 = n1 / (n1 + n2), n2 / (n1 + n2)
    return w1 * m1 + w2 * m2, w1 * w1 * v1 + w2 * w2 * v2


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.reference", description=__doc__.splitlines()[0])
    p.add_argument("scene")
    budget = p.add_mutually_exclusive_group(required=True)
    budget.add_argument("--spp", type=int)
    budget.add_argument("--time", type=float, help="seconds of rendering")
    p.add_argument("--seed", type=int, default=1000, help="seed of the first render (appends use the next)")
    p.add_argument("--out", default=None)
    p.add_argument("--append", action="store_true", help="merge with the reference already in --out")
    a = p.parse_args(argv)
    out = a.out or default_out(a.scene)
    os.makedirs(out, exist_ok=True)
    scene = tracer.load_scene(a.scene)
    old = None
    seed = a.seed
    if a.append and os.path.isfile(os.path.join(out, "reference.exr")):
        old = load(out)
        seed = max(old[2]["seeds"]) + 1
    t0 = time.time()
    r = tracer.render(scene, spp=a.spp, time=a.time, seed=seed, progress=True)
    seconds = time.time() - t0
    mean, var, spp = r.image.astype(np.float64), r.variance.astype(np.float64), r.stats["spp"]
    seeds, total_seconds = [seed], seconds
    if old is not None:
        om, ov, meta = old
        if om.shape != mean.shape:
            raise SystemExit(f"{out}: stored reference is {om.shape[1]}x{om.shape[0]}, the scene renders "
                             f"{mean.shape[1]}x{mean.shape[0]}")
        mean, var = merge(om, ov, meta["spp"], mean, var, spp)
        spp += meta["spp"]
        seeds = meta["seeds"] + seeds
        total_seconds += meta["seconds"]
    tracer.write_image(os.path.join(out, "reference.exr"), np.concatenate([mean, var], axis=2),
                       channel_names=CHANNELS)
    tracer.write_image(os.path.join(out, "reference.png"), mean)
    meta = {
        "scene": os.path.relpath(os.path.abspath(a.scene), ROOT),
        "width": scene.width, "height": scene.height, "spp": int(spp), "seconds": round(total_seconds, 1),
        "seeds": seeds, "max_depth": scene.render.max_depth, "rr_depth": scene.render.rr_depth,
        "integrator": "path tracing, bsdf sampling + NEE (MIS)", "accel": r.stats["accel"],
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "noise_floor_relmse": noise_floor(mean, var),
        "command": "python -m bench.reference " + " ".join(argv if argv is not None else __import__("sys").argv[1:]),
    }
    with open(os.path.join(out, "reference.json"), "w") as f:
        json.dump(meta, f, indent=1)
    print(f"{out}/reference.exr: {spp} spp, {total_seconds:.0f} s, noise floor relMSE {meta['noise_floor_relmse']:.3g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
