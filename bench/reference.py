"""Reference images: plain path tracing at high spp, mean and variance, resumable.

    python -m bench.reference scenes/ajar/ajar.obj --time 600            # -> scenes/ajar/reference.*
    python -m bench.reference ../shared/scenes/veach-ajar/scene.obj --spp 4096 \\
        --out bench/results/references/veach-ajar
    python -m bench.reference scenes/ajar/ajar.obj --time 600 --append   # add more samples
    python -m bench.reference scenes/ajar/ajar.obj --time 600 --append --segments 4 --threads 1  # 4 seeds, Dask

Writes `<out>/reference.exr` with six channels (R, G, B, var.R, var.G, var.B: the mean and the
variance of that mean) and `<out>/reference.json`: spp, seconds, seeds, machine, and the
reference's own noise floor, the relMSE it is expected to have against the true image,
mean(var / (R^2 + 0.01)). A reference can judge errors down to about ten times that floor.

With --append, a new independent render (the next seed) is merged with the stored one, weighted
by spp, so a reference can be built over several sessions. Before merging, the new segment must
agree with the stored mean: per channel, the image mean of (new - stored) over its standard error
from both variances (bias_z; aggregated over pixels first) must stay below the two-sided 1%
threshold, Sidak-corrected over the three channels. A segment of a scene or renderer that has
changed since would otherwise bias the reference without a trace; when it fails, nothing is
written and the command exits naming the folder and the z-scores (`--force` merges anyway).

`--segments K` renders K segments (seeds) at once on Dask, a LocalCluster by default (each worker
pinned to its cores, as bench.convergence's sweep) or `--scheduler ADDRESS`, then merges them
into the reference in seed order, each through the same check. A finished segment waits in
`<out>/segments/` until it is merged, so a stopped run started again renders only the missing ones.

reference.json keeps `segments`, one per render merged in: seed, spp, seconds, the commit of this
repository (`-dirty` when tracked files differed from it), date, machine, command, and for appended ones
the z-scores of the check. A reference made before segments were recorded gets one segment
synthesized from its old fields (its `seeds`, commit and date "unknown").

The EXR, PNG and JSON are written to temporary files beside them and then renamed into place, so
a stopped run leaves the stored reference whole. The default output folder is the scene's own
folder for scenes inside this repository, and bench/results/references/<name> otherwise
(external scenes are never copied into the repository).
"""
import argparse
import json
import os
import platform
import sys
import time

import numpy as np

import tracer
from tracer.distributed import agreement, bias_z, merge  # noqa: F401 (bias_z: tests read it here)
from tracer.imageio import tonemap
from tracer.provenance import git_commit
from tracer.testing import z_critical

from . import atomic, sweep

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CHANNELS = ("R", "G", "B", "var.R", "var.G", "var.B")


def default_out(scene_path):
    p = os.path.abspath(scene_path)
    if p.startswith(os.path.join(ROOT, "scenes") + os.sep):
        return os.path.dirname(p)
    name = os.path.basename(os.path.dirname(p)) or os.path.splitext(os.path.basename(p))[0]
    if p.endswith(".xml"):  # a Mitsuba scene: kept apart from an OBJ version of the same scene
        name += "-mitsuba"
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


def z_threshold(tests, alpha=0.01):
    """|z| threshold of a two-sided test at family-wise level alpha over `tests` tests (Sidak)."""
    return z_critical(tests, alpha)


def segments_of(meta):
    """The segments of a stored reference's metadata; one synthesized from the old fields (all its
    seeds, spp and seconds; commit and date unknown) for a reference made before they were kept."""
    if "segments" in meta:
        return [dict(s) for s in meta["segments"]]
    return [{"seeds": list(meta["seeds"]), "spp": int(meta["spp"]), "seconds": meta["seconds"],
             "commit": "unknown", "date": "unknown", "command": meta.get("command", "unknown"),
             "synthesized": "from the fields of a reference made before segments were recorded"}]


def render_segment(cell):
    """One segment in a worker (or this process): render the scene at cell's size with cell's seed
    and budget, and store mean, variance and its record in cell["path"] (an .npz, written whole);
    returns the path."""
    scene = tracer.load_scene(cell["scene"], **cell["size"])
    commit, date = git_commit() or "unknown", time.strftime("%Y-%m-%d %H:%M")  # what renders the segment
    t0 = time.time()
    r = tracer.render(scene, spp=cell["spp"], time=cell["time"], seed=cell["seed"], progress=cell["progress"],
                      threads=cell["threads"])
    seconds = time.time() - t0
    segment = {"seed": int(cell["seed"]), "spp": int(r.stats["spp"]), "seconds": round(seconds, 1), "commit": commit,
               "date": date, "machine": f"{platform.machine()}, {os.cpu_count()} cores", "command": cell["command"],
               "accel": r.stats["accel"], "width": scene.width, "height": scene.height,
               "max_depth": scene.render.max_depth, "rr_depth": scene.render.rr_depth}
    atomic.save_npz(cell["path"], mean=r.image.astype(np.float64), var=r.variance.astype(np.float64),
                    segment=json.dumps(segment))
    return cell["path"]


def _read_segment(path):
    with np.load(path) as z:
        return z["mean"], z["var"], json.loads(str(z["segment"]))


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.reference", description=__doc__.splitlines()[0])
    p.add_argument("scene")
    budget = p.add_mutually_exclusive_group(required=True)
    budget.add_argument("--spp", type=int, help="samples per pixel of each segment")
    budget.add_argument("--time", type=float, help="seconds of rendering of each segment")
    p.add_argument("--seed", type=int, default=1000, help="seed of the first render (appends use the next)")
    p.add_argument("--segments", type=int, default=1, help="independent renders (seeds) to make and merge; "
                   "more than one run on Dask, one per worker at a time")
    p.add_argument("--threads", type=int, default=None, help="threads of each render (default: all cores, "
                   "shared among the segments rendered at once)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="a Dask scheduler for the segments "
                   "(default: a LocalCluster on this machine)")
    p.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default: cores // threads; "
                   "0: every segment in this process)")
    p.add_argument("--out", default=None)
    p.add_argument("--width", type=int, help="image width (default: the scene's)")
    p.add_argument("--height", type=int, help="image height (default: the scene's)")
    p.add_argument("--append", action="store_true", help="merge with the reference already in --out")
    p.add_argument("--force", action="store_true", help="with --append: merge even if the new segment "
                   "disagrees with the stored mean")
    a = p.parse_args(argv)
    if a.segments < 1:
        p.error("--segments must be >= 1")
    command = "python -m bench.reference " + " ".join(argv if argv is not None else sys.argv[1:])
    out = a.out or default_out(a.scene)
    os.makedirs(out, exist_ok=True)
    size = {k: v for k, v in (("width", a.width), ("height", a.height)) if v}
    stored = os.path.isfile(os.path.join(out, "reference.exr"))
    seed = max(load(out)[2]["seeds"]) + 1 if a.append and stored else a.seed
    # Each segment lands in out/segments/ first: a stopped run keeps the finished ones, and the next
    # run with the same seeds merges them without rendering them again.
    folder = os.path.join(out, "segments")
    cells = [{"scene": a.scene, "size": size, "spp": a.spp, "time": a.time, "seed": s, "command": command,
              "threads": a.threads, "progress": a.segments == 1,
              "path": os.path.join(folder, f"seed_{s}.npz")} for s in range(seed, seed + a.segments)]
    os.makedirs(folder, exist_ok=True)
    todo = [c for c in cells if not os.path.isfile(c["path"])]
    local = a.segments == 1 and a.scheduler is None
    threads = a.threads or (os.cpu_count() or 1) // (1 if local else min(a.segments, os.cpu_count() or 1))
    for c in todo:
        c["threads"] = max(1, threads)
    sweep.run(render_segment, todo, lambda c, path: None, threads=max(1, threads), scheduler=a.scheduler,
              workers=0 if local else a.workers, progress=not local, desc="segments")
    try:
        for i, c in enumerate(cells):  # merged in seed order, each checked against what is stored
            try:
                merge_segment(out, *_read_segment(c["path"]), append=stored or i > 0, force=a.force, scene=a.scene)
            finally:  # merged, or refused (a refused one is rendered again with --force)
                os.remove(c["path"])
    finally:
        if not os.listdir(folder):
            os.rmdir(folder)
    return 0


def merge_segment(out, mean, var, segment, append, force, scene):
    """Store a segment as the reference in `out`, or (append) merge it into the stored one after the
    z-check; SystemExit, nothing written, if it disagrees (unless force)."""
    spp, seeds, total_seconds = segment["spp"], [segment["seed"]], segment["seconds"]
    info = {k: segment.pop(k) for k in ("accel", "width", "height", "max_depth", "rr_depth")}
    segments = [segment]
    if append:
        om, ov, meta = load(out)
        if om.shape != mean.shape:
            raise SystemExit(f"{out}: stored reference is {om.shape[1]}x{om.shape[0]}, the scene renders "
                             f"{mean.shape[1]}x{mean.shape[0]}")
        ok, z, zc = agreement(mean, var, om, ov)
        zs = ", ".join(f"{v:+.2f}" for v in z)
        if not ok and not force:
            raise SystemExit(f"bench.reference: {out}: the new segment (seed {segment['seed']}, {spp} spp) disagrees "
                             f"with the stored mean: z (R, G, B) = {zs}, |z| must stay below {zc:.2f}; nothing "
                             f"written (--force merges anyway)")
        print(f"{out}: new segment against the stored mean: z (R, G, B) = {zs} (threshold {zc:.2f})"
              + ("" if ok else ": disagrees, merged because of --force"))
        segment["z"] = [round(float(v), 3) for v in z]
        if not ok:
            segment["forced"] = True
        segments = segments_of(meta) + segments
        mean, var = merge(om, ov, meta["spp"], mean, var, spp)
        spp += meta["spp"]
        seeds = meta["seeds"] + seeds
        total_seconds += meta["seconds"]
    meta = {
        "scene": os.path.relpath(os.path.abspath(scene), ROOT),
        "width": info["width"], "height": info["height"], "spp": int(spp), "seconds": round(total_seconds, 1),
        "seeds": seeds, "max_depth": info["max_depth"], "rr_depth": info["rr_depth"],
        "integrator": "path tracing, bsdf sampling + NEE (MIS)", "accel": info["accel"],
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "noise_floor_relmse": noise_floor(mean, var),
        "command": segment["command"],
        "segments": segments,
    }
    atomic.write_all([
        (os.path.join(out, "reference.exr"),
         atomic.image_writer(np.concatenate([mean, var], axis=2), channel_names=CHANNELS)),
        (os.path.join(out, "reference.png"), atomic.image_writer(tonemap(mean))),  # the preview, as the CLI
        (os.path.join(out, "reference.json"), atomic.text_writer(json.dumps(meta, indent=1))),
    ])
    print(f"{out}/reference.exr: {spp} spp, {total_seconds:.0f} s, noise floor relMSE {meta['noise_floor_relmse']:.3g}")


if __name__ == "__main__":
    raise SystemExit(main())
