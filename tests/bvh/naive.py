"""Slow, obviously correct twin of the ray-query backends: every ray against every triangle.

It uses a different formula from the backends (ray-plane distance, then barycentrics of the
plane point from the normal equations) so that a shared mistake is unlikely. `grow` moves each
triangle's edges outwards (> 0) or inwards (< 0) by that distance within its plane, which brackets
the answer of a backend whose rounding decides rays that pass within `grow` of an edge.
"""
import numpy as np


def hit_distances(org, dirs, tri, grow=0.0):
    """(n, F) float64: distance t > 0 along ray i to triangle j (grown by `grow`), inf if none.

    org, dirs: (n, 3) float64 rays (dirs need not be unit length); tri: (F, 3, 3) float64.
    """
    org = np.asarray(org, np.float64)
    dirs = np.asarray(dirs, np.float64)
    v0, v1, v2 = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = v1 - v0, v2 - v0
    normal = np.cross(e1, e2)                                  # (F, 3), length 2 * area
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        denom = dirs @ normal.T                                # (n, F)
        t = (np.sum(v0 * normal, axis=1)[None, :] - org @ normal.T) / denom
        p = org[:, None, :] + t[:, :, None] * dirs[:, None, :]  # plane points (n, F, 3)
        w = p - v0[None]
        d00 = np.sum(e1 * e1, axis=1)
        d01 = np.sum(e1 * e2, axis=1)
        d11 = np.sum(e2 * e2, axis=1)
        d20 = np.sum(w * e1[None], axis=2)
        d21 = np.sum(w * e2[None], axis=2)
        den = d00 * d11 - d01 * d01
        b1 = (d11 * d20 - d01 * d21) / den
        b2 = (d00 * d21 - d01 * d20) / den
        b0 = 1.0 - b1 - b2
        # Barycentric k times the altitude onto vertex k is the distance to the opposite edge.
        area2 = np.linalg.norm(normal, axis=1)
        h0 = area2 / np.linalg.norm(v2 - v1, axis=1)
        h1 = area2 / np.linalg.norm(e2, axis=1)
        h2 = area2 / np.linalg.norm(e1, axis=1)
        inside = (b0 * h0 >= -grow) & (b1 * h1 >= -grow) & (b2 * h2 >= -grow)
        ok = inside & (t > 0) & np.isfinite(t) & (area2 > 0)
    return np.where(ok, t, np.inf)


def intersect(org, dirs, tri, tmax=None):
    """Closest hits (t, prim) by brute force, as the backends define them (0 < t < tmax)."""
    T = hit_distances(org, dirs, tri)
    if tmax is not None:
        T = np.where(T < np.asarray(tmax)[:, None], T, np.inf)
    prim = np.argmin(T, axis=1).astype(np.int32) if T.shape[1] else np.zeros(len(T), np.int32)
    t = T[np.arange(len(T)), prim] if T.shape[1] else np.full(len(T), np.inf)
    prim[~np.isfinite(t)] = -1
    return t, prim
