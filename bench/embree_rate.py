"""Embree's own rate on the rays of a render, from C: the floor our ray queries are measured against.

    python -m bench.embree_rate                       # mitsuba-cornell, open-1k, open-1m
    python -m bench.embree_rate --scenes open-1k --spp 1
    python -m bench.embree_rate --path-loop lanes      # the rays as the lane engine issues them

Renders each scene once at `--spp` (after an untimed render), capturing every batch the accel is
asked (closest hits and shadow rays) and the scene's triangles (float32, less the accel's centre),
into bench/results/embree_rate/. Then it builds bench/embree_rate.c with gcc (-O2 -march=native
-fopenmp) against the libembree4 that embreex installs, and runs it: ns per ray with one ray, 8 and
16 per call on one thread, and with 16 per call on 2 threads.
"""
import argparse
import os
import subprocess

import numpy as np

import tracer
from tracer.bvh import embree

from . import common, throughput

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "bench", "results", "embree_rate")


def capture(name, spp, folder, path_loop="thread"):
    """Write NAME.hdr (NAME: `label`; vertex, bounce-ray, shadow-ray counts), .v, .ray (origin, direction) and
    .shadow (origin, direction, tmax), float32, coordinates less the accel's centre. With
    path_loop "lanes", the rays the lane engine issues, in its order (capture_lanes)."""
    if path_loop == "lanes":
        return capture_lanes(name, spp, folder)
    scene = tracer.load_scene(throughput.scene_spec(name)["obj"])
    calls = {"i": [], "o": []}
    inter, occ = embree.EmbreeAccel.intersect, embree.EmbreeAccel.occluded

    def record_i(self, o, d, tmax=None):
        calls["i"].append((np.array(o), np.array(d)))
        return inter(self, o, d, tmax)

    def record_o(self, o, d, tmax):
        calls["o"].append((np.array(o), np.array(d), np.array(tmax)))
        return occ(self, o, d, tmax)

    tracer.render(scene, spp=1, max_depth=8, rr_depth=5)
    embree.EmbreeAccel.intersect, embree.EmbreeAccel.occluded = record_i, record_o
    try:
        tracer.render(scene, spp=spp, max_depth=8, rr_depth=5)
    finally:
        embree.EmbreeAccel.intersect, embree.EmbreeAccel.occluded = inter, occ
    c = 0.5 * (scene.bounds[0] + scene.bounds[1])  # the accel's centre
    ray = np.concatenate([np.hstack([o - c, d]) for o, d in calls["i"][1:]])  # [0]: the warm-up path
    sh = np.concatenate([np.hstack([o - c, d, t[:, None]]) for o, d, t in calls["o"]])
    v = (scene.tri - c).astype(np.float32).reshape(-1, 3)
    return _write(folder, name, v, ray, sh)


def label(name):
    """The files' stem in the capture folder for a scene name or path: its last component."""
    return os.path.basename(name)


def _write(folder, name, v, ray, sh):
    base = os.path.join(folder, label(name))
    np.array([len(v), len(ray), len(sh), 0], np.int64).tofile(base + ".hdr")
    v.tofile(base + ".v")
    ray.astype(np.float32).tofile(base + ".ray")
    sh.astype(np.float32).tofile(base + ".shadow")
    return len(ray), len(sh)


def capture_lanes(name, spp, folder):
    """capture for render(path_loop="lanes"): each bounce's closest-hit rays as the lanes hold them
    (lanes 0 .. m-1 in order, packed 16 to a call), and its shadow rays in lane order (occlude packs
    the next 16 lanes that have one)."""
    from tracer.engine import lanes
    from tracer.engine.rows import DX, OX, SDX, SHADOW, SOX, TMAX

    scene = tracer.load_scene(throughput.scene_spec(name)["obj"])
    calls = {"i": [], "o": []}
    inter, occ = lanes.intersect, lanes.occlude

    def record_i(fn, sc, scratch, lf, n, hit, prim):
        calls["i"].append(np.vstack([lf[OX:OX + 3, :n], lf[DX:DX + 3, :n]]).T.copy())
        return inter(fn, sc, scratch, lf, n, hit, prim)

    def record_o(fn, sc, scratch, n, sh, flags, *rest):
        on = flags[SHADOW, :n] != 0
        calls["o"].append(np.vstack([sh[SOX:SOX + 3, :n], sh[SDX:SDX + 3, :n], sh[TMAX:TMAX + 1, :n]]).T[on].copy())
        return occ(fn, sc, scratch, n, sh, flags, *rest)

    tracer.render(scene, spp=1, max_depth=8, rr_depth=5, path_loop="lanes")
    lanes.intersect, lanes.occlude = record_i, record_o
    try:
        st = tracer.render(scene, spp=spp, max_depth=8, rr_depth=5, path_loop="lanes").stats
    finally:
        lanes.intersect, lanes.occlude = inter, occ
    c = 0.5 * (scene.bounds[0] + scene.bounds[1])  # the accel's centre (the lanes' rays are relative to it)
    v = (scene.tri - c).astype(np.float32).reshape(-1, 3)
    # the render's warm-up traces a throwaway path before its passes: the passes' calls are the last ones
    ray = _last(calls["i"], st["camera_and_bounce_rays"])
    return _write(folder, name, v, ray, _last(calls["o"], st["shadow_rays"]))


def _last(chunks, total):
    """The rows of the shortest run of chunks at the end of `chunks` that holds `total` rows."""
    n = 0
    for j in range(len(chunks) - 1, -1, -1):
        n += len(chunks[j])
        if n == total:
            return np.concatenate(chunks[j:])
    if total == 0:
        return np.zeros((0, chunks[0].shape[1] if chunks else 7), np.float32)
    raise RuntimeError(f"the captured calls hold no run of {total} rays at their end")


def build(folder):
    lib = embree._LIB._name
    exe = os.path.join(folder, "embree_rate")
    subprocess.run(["gcc", "-O2", "-march=native", "-fopenmp", "-o", exe, os.path.join(ROOT, "bench", "embree_rate.c"),
                    lib, f"-Wl,-rpath,{os.path.dirname(lib)}", "-lm"], check=True)
    return exe


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.embree_rate", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default="mitsuba-cornell,open-1k,open-1m")
    p.add_argument("--spp", type=int, default=1)
    p.add_argument("--quality", type=int, default=1, help="RTC build quality (0 low, 1 medium, 2 high)")
    p.add_argument("--path-loop", default="thread", choices=("thread", "lanes"),
                   help="whose rays: the per-thread loop's batches as the accel is asked, or the lanes' packets")
    a = p.parse_args(argv)
    exe = common.built_with_gcc("bench.embree_rate", "gcc (with OpenMP) to build bench/embree_rate.c", OUT, build)
    if exe is None:
        return 2
    for name in a.scenes.split(","):
        n, ns = capture(name, a.spp, OUT, a.path_loop)
        print(f"# {name}: {n} closest-hit rays, {ns} shadow rays at {a.spp} spp", flush=True)
        subprocess.run([exe, OUT, label(name), str(a.quality)], check=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
