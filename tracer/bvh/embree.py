"""Embree ray queries through embreex, on a persistent thread pool.

Embree works in float32. To keep precision far from the origin, vertices and ray origins are
shifted by the scene's bounding-box centre before the cast (as trimesh's ray_pyembree does).
Closest hits are then refined in float64: t and the barycentrics are recomputed against the
float64 triangle Embree reported, so hit points lie on the float64 geometry.

embreex releases the GIL while it traces, so a large batch is split into up to `threads` spans
that run at once (the calling thread takes the first span); small batches run on the caller alone.

Unlike the Numba BVH (0 < t), Embree also reports a hit at t = 0 exactly (an origin lying on a
triangle); rays offset from their surface, as the integrator's are, never meet the difference.
"""
import os
import weakref
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from embreex import mesh_construction, rtcore_scene

from tracer._jit import jit
from tracer.bvh import _bounds, _check_rays, _check_tri

MIN_RAYS_PER_THREAD = 4096  # a batch uses one thread per this many rays, up to `threads`


@jit
def _prepare(org, dirs, tmax, centre, o32, d32, tfar):
    """Float32 rays for Embree: origins shifted by -centre, tfar = tmax (inf where tmax is
    (0,), i.e. no limit)."""
    n = org.shape[0]
    has_tmax = tmax.shape[0] == n
    for i in range(n):
        for a in range(3):
            o32[i, a] = org[i, a] - centre[a]
            d32[i, a] = dirs[i, a]
        tfar[i] = tmax[i] if has_tmax else np.inf


@jit
def _finish(org, dirs, tri, tfar, prim_id, u, v, refine, t, prim, b1, b2):
    """Embree's float32 closest hits into the float64 outputs t, prim, b1, b2; with `refine`,
    t, b1, b2 are recomputed in float64 against triangle prim (Moller-Trumbore without the
    inside test; barycentrics clamped onto the triangle)."""
    for i in range(org.shape[0]):
        p = prim_id[i]
        if p < 0:
            t[i] = np.inf
            prim[i] = -1
            b1[i] = 0.0
            b2[i] = 0.0
            continue
        prim[i] = p
        t[i] = tfar[i]
        if not refine:
            b1[i] = u[i]
            b2[i] = v[i]
            continue
        b1[i] = 1.0 / 3.0  # kept only if the float64 refinement below fails (degenerate ray)
        b2[i] = 1.0 / 3.0
        e1x = tri[p, 1, 0] - tri[p, 0, 0]
        e1y = tri[p, 1, 1] - tri[p, 0, 1]
        e1z = tri[p, 1, 2] - tri[p, 0, 2]
        e2x = tri[p, 2, 0] - tri[p, 0, 0]
        e2y = tri[p, 2, 1] - tri[p, 0, 1]
        e2z = tri[p, 2, 2] - tri[p, 0, 2]
        dx = dirs[i, 0]
        dy = dirs[i, 1]
        dz = dirs[i, 2]
        px = dy * e2z - dz * e2y
        py = dz * e2x - dx * e2z
        pz = dx * e2y - dy * e2x
        det = e1x * px + e1y * py + e1z * pz
        if not abs(det) > 0.0:
            continue
        inv = 1.0 / det
        sx = org[i, 0] - tri[p, 0, 0]
        sy = org[i, 1] - tri[p, 0, 1]
        sz = org[i, 2] - tri[p, 0, 2]
        qx = sy * e1z - sz * e1y
        qy = sz * e1x - sx * e1z
        qz = sx * e1y - sy * e1x
        tt = (e2x * qx + e2y * qy + e2z * qz) * inv
        if not (tt > 0.0 and tt < np.inf):
            continue
        u1 = max((sx * px + sy * py + sz * pz) * inv, 0.0)
        u2 = max((dx * qx + dy * qy + dz * qz) * inv, 0.0)
        s = u1 + u2
        if s > 1.0:
            u1 /= s
            u2 /= s
        t[i] = tt
        b1[i] = u1
        b2[i] = u2


class EmbreeAccel:
    """Embree scene over triangles `tri` (F, 3, 3) float64.

    threads: how many threads a large batch query uses (default: os.cpu_count()).
    refine: recompute closest-hit t and barycentrics in float64 (cheap; default on).
    """

    name = "embree"

    def __init__(self, tri, threads=None, refine=True):
        tri = _check_tri(tri)
        self.tri = tri
        self.n_triangles = len(tri)
        self.bounds, self.scale = _bounds(tri)
        self.centre = self.bounds.mean(axis=0)
        self.threads = max(1, int(threads or os.cpu_count() or 1))
        self.refine = bool(refine)
        self._scene = rtcore_scene.EmbreeScene()
        self._mesh = None
        if self.n_triangles:
            self._mesh = mesh_construction.TriangleMesh(
                self._scene, (tri - self.centre).astype(np.float32))
        # embreex commits the scene on its first query, which is not safe to race: do it now.
        self._scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=1)
        self._pool = None

    def _spans(self, n):
        """Split n rays into contiguous spans, one per thread that is worth using."""
        k = min(self.threads, max(1, n // MIN_RAYS_PER_THREAD))
        edges = np.linspace(0, n, k + 1).astype(np.int64)
        return list(zip(edges[:-1], edges[1:]))

    def _run(self, fn, n, *args):
        """Call fn(lo, hi, *args) over the spans of n rays, in parallel when there are several."""
        spans = self._spans(n)
        if len(spans) == 1:
            fn(0, n, *args)
            return
        if self._pool is None:
            self._pool = ThreadPoolExecutor(self.threads, thread_name_prefix="embree")
            weakref.finalize(self, self._pool.shutdown, wait=False)
        futures = [self._pool.submit(fn, lo, hi, *args) for lo, hi in spans[1:]]
        fn(*spans[0], *args)
        for f in futures:
            f.result()

    def _rays32(self, org, dirs, tmax):
        """Float32 origins (shifted), directions and tfar for one span."""
        n = org.shape[0]
        o32 = np.empty((n, 3), np.float32)
        d32 = np.empty((n, 3), np.float32)
        tfar = np.empty(n, np.float32)
        _prepare(org, dirs, tmax, self.centre, o32, d32, tfar)
        return o32, d32, tfar

    def _intersect_span(self, lo, hi, org, dirs, tmax, t, prim, b1, b2):
        o, d = org[lo:hi], dirs[lo:hi]
        o32, d32, tfar = self._rays32(o, d, tmax[lo:hi] if len(tmax) else tmax)
        # With `dists` given, embreex writes each ray's final tfar back into it. When the hit is
        # refined in float64 anyway, ask for the triangle ids alone (no per-call output dict).
        if self.refine:
            ids = self._scene.run(o32, d32, dists=tfar, query="INTERSECT")
            _finish(o, d, self.tri, tfar, ids, tfar, tfar, True,
                    t[lo:hi], prim[lo:hi], b1[lo:hi], b2[lo:hi])
            return
        r = self._scene.run(o32, d32, dists=tfar, query="INTERSECT", output=1)
        _finish(o, d, self.tri, tfar, r["primID"], r["u"], r["v"], False,
                t[lo:hi], prim[lo:hi], b1[lo:hi], b2[lo:hi])

    def _occluded_span(self, lo, hi, org, dirs, tmax, out):
        o32, d32, tfar = self._rays32(org[lo:hi], dirs[lo:hi], tmax[lo:hi])
        # OCCLUDED answers int32 per ray: -1 when nothing blocks it.
        hit = self._scene.run(o32, d32, dists=tfar, query="OCCLUDED")
        np.not_equal(hit, -1, out=out[lo:hi])

    def intersect(self, org, dirs, tmax=None):
        """Closest hits: (t, prim, b1, b2), see `tracer.bvh`."""
        org, dirs, tmax = _check_rays(org, dirs, tmax)
        n = org.shape[0]
        t = np.empty(n)
        prim = np.empty(n, np.int32)
        b1 = np.empty(n)
        b2 = np.empty(n)
        if n:
            self._run(self._intersect_span, n, org, dirs,
                      np.empty(0) if tmax is None else tmax, t, prim, b1, b2)
        return t, prim, b1, b2

    def occluded(self, org, dirs, tmax):
        """(n,) bool: True where some triangle is hit with 0 < t < tmax."""
        org, dirs, tmax = _check_rays(org, dirs, tmax, need_tmax=True)
        n = org.shape[0]
        out = np.empty(n, np.bool_)
        if n:
            self._run(self._occluded_span, n, org, dirs, tmax, out)
        return out

    def __repr__(self):
        return (f"EmbreeAccel(name='embree', triangles={self.n_triangles}, "
                f"threads={self.threads}, scale={self.scale:.4g})")
