"""Ray queries against a triangle soup: an Embree backend and a pure-Numba BVH.

Both backends are built from `tri`, a (F, 3, 3) float64 array of world-space triangles
(triangle i has vertices tri[i, 0], tri[i, 1], tri[i, 2]), and answer the same batch queries:

    intersect(org, dirs, tmax=None) -> (t, prim, b1, b2)
        org, dirs : (n, 3) float64, world space; dirs need not be unit length
        tmax      : (n,) float64 or None (= inf)
        t         : (n,) float64, hit distance in units of |dirs| (np.inf on a miss)
        prim      : (n,) int32, triangle index (-1 on a miss)
        b1, b2    : (n,) float64 barycentrics (0 on a miss):
                    hit = (1 - b1 - b2) * tri[prim, 0] + b1 * tri[prim, 1] + b2 * tri[prim, 2]
    occluded(org, dirs, tmax) -> (n,) bool, True where some triangle is hit with 0 < t < tmax

Hits are two-sided and tnear is 0: callers offset their origins by an epsilon scaled with
`accel.scale` (the bounding-box diagonal). Rays with a zero direction miss. Every backend also
has `name`, `threads`, `scale`, `bounds` ((2, 3) float64: min and max corner) and a `repr`.
"""
import numpy as np

from tracer.errors import SettingsError, unknown_name

ACCELS = ("embree", "numba")


def make_accel(name, tri, threads=None):
    """Build the ray-query backend `name` ("embree" or "numba") over triangles `tri` (F, 3, 3).

    `threads` is how many threads a batch query may use (default: every core).
    """
    if name == "embree":
        try:
            from tracer.bvh.embree import EmbreeAccel
        except ImportError as err:
            if not (err.name or "").startswith("embreex"):
                raise
            raise SettingsError(
                f"accel 'embree' needs the embreex package, which cannot be imported ({err}); "
                "install embreex or use --accel numba"
            ) from None
        return EmbreeAccel(tri, threads=threads)
    if name == "numba":
        from tracer.bvh.numba_bvh import NumbaBVH

        return NumbaBVH(tri, threads=threads)
    raise unknown_name("accel", name, ACCELS)


def _check_tri(tri):
    """`tri` as a C-contiguous (F, 3, 3) float64 array; ValueError on any other shape."""
    tri = np.ascontiguousarray(tri, dtype=np.float64)
    if tri.ndim != 3 or tri.shape[1:] != (3, 3):
        raise ValueError(f"triangles must have shape (F, 3, 3), got {tri.shape}")
    return tri


def _bounds(tri):
    """Bounding box (2, 3) of the triangles' finite vertices and its diagonal length (the scene
    scale, 1.0 for an empty or point-like scene)."""
    v = tri.reshape(-1, 3)
    v = v[np.isfinite(v).all(axis=1)]
    if len(v) == 0:
        return np.zeros((2, 3)), 1.0
    bounds = np.stack([v.min(axis=0), v.max(axis=0)])
    scale = float(np.linalg.norm(bounds[1] - bounds[0]))
    return bounds, (scale if scale > 0.0 else 1.0)


def _check_rays(org, dirs, tmax, need_tmax=False):
    """Rays as C-contiguous float64 arrays: org, dirs (n, 3), tmax (n,) or None."""
    org = np.ascontiguousarray(org, dtype=np.float64)
    dirs = np.ascontiguousarray(dirs, dtype=np.float64)
    if org.ndim != 2 or org.shape[1] != 3 or dirs.shape != org.shape:
        raise ValueError(f"ray origins and directions must both be (n, 3), got {org.shape} "
                         f"and {dirs.shape}")
    if tmax is None:
        if need_tmax:
            raise ValueError("occluded() needs tmax, an (n,) array (np.inf for no limit)")
        return org, dirs, None
    tmax = np.ascontiguousarray(tmax, dtype=np.float64)
    if tmax.shape != (org.shape[0],):
        raise ValueError(f"tmax must have shape ({org.shape[0]},), got {tmax.shape}")
    return org, dirs, tmax
