"""Micro-benchmark of the ray-query backends: Mrays/s of closest-hit and occlusion queries.

    python -m bench.bvh_speed [--rays 1000000] [--repeat 3] [--scenes cbox,mesh]

Scenes: `cbox`, a closed Cornell-like box of 38 triangles (two blocks and a light), with rays
from random points inside it; `mesh`, ~100k triangles (a bumpy closed icosphere of 82k and 18k
small random triangles inside it), with rays from random points inside it. Directions are
uniform on the sphere (incoherent); occlusion rays get tmax uniform in [0, half the diagonal of
the box the origins are drawn from]. Prints the build time (compilation excluded) and the best
of `repeat` runs of each query, for embree on 1 and on all threads and for numba on all threads.
Numbers are only comparable on an otherwise idle machine.
"""
import argparse
import os
import time

import numpy as np
import trimesh

from tracer.bvh import make_accel


def cornell_box():
    """(38, 3, 3): the inside of a 2-unit box, a short and a tall block, a ceiling light."""
    walls = trimesh.creation.box(extents=(2.0, 2.0, 2.0)).triangles
    short = trimesh.creation.box(extents=(0.6, 0.6, 0.6)).triangles + [0.35, -0.7, 0.3]
    tall = trimesh.creation.box(extents=(0.6, 1.2, 0.6)).triangles + [-0.35, -0.4, -0.3]
    light = np.array([[[-0.25, 0.99, -0.25], [0.25, 0.99, -0.25], [0.25, 0.99, 0.25]],
                      [[-0.25, 0.99, -0.25], [0.25, 0.99, 0.25], [-0.25, 0.99, 0.25]]])
    return np.concatenate([walls, short, tall, light])


def bumpy_sphere(seed=0):
    """~82k triangles: an icosphere (6 subdivisions) with noisy radii, so the BVH is not trivial."""
    mesh = trimesh.creation.icosphere(subdivisions=6)
    rng = np.random.default_rng(seed)
    v = mesh.vertices * rng.uniform(0.9, 1.1, (len(mesh.vertices), 1))
    return v[mesh.faces]


def big_mesh(seed=0):
    """~100k triangles: the bumpy sphere plus 18k small random triangles inside it."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(-0.6, 0.6, (18_000, 1, 3))
    return np.concatenate([bumpy_sphere(seed), c + rng.normal(0, 0.02, (18_000, 3, 3))])


def rays(n, lo, hi, seed=1):
    rng = np.random.default_rng(seed)
    org = rng.uniform(lo, hi, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return org, d


def best_rate(fn, n, repeat):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return n / best / 1e6


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--scenes", default="cbox,mesh")
    args = ap.parse_args(argv)
    cores = os.cpu_count() or 1
    scenes = {"cbox": (cornell_box, 0.9), "mesh": (big_mesh, 0.7)}
    for name in args.scenes.split(","):
        make, half = scenes[name]
        tri = make()
        org, dirs = rays(args.rays, -half, half)
        tmax = np.random.default_rng(2).uniform(0, 1, args.rays) * np.sqrt(3) * half
        print(f"{name}: {len(tri)} triangles, {args.rays} rays")
        for accel, threads in (("embree", 1), ("embree", cores), ("numba", cores)):
            warm = make_accel(accel, tri[:8], threads=threads)  # compile (or load) the kernels
            warm.intersect(org[:8], dirs[:8])
            warm.occluded(org[:8], dirs[:8], tmax[:8])
            t0 = time.perf_counter()
            acc = make_accel(accel, tri, threads=threads)
            build = time.perf_counter() - t0
            hit = best_rate(lambda: acc.intersect(org, dirs), args.rays, args.repeat)
            occ = best_rate(lambda: acc.occluded(org, dirs, tmax), args.rays, args.repeat)
            print(f"  {accel:6s} threads={threads}: build {build:6.3f} s  "
                  f"intersect {hit:6.2f} Mrays/s  occluded {occ:6.2f} Mrays/s")


if __name__ == "__main__":
    main()
