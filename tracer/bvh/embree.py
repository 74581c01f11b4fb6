"""Embree ray queries, called from Numba kernels.

The embreex wheel ships Intel's libembree4. Its Python API traces a batch one ray at a time in
a Cython loop behind float32 copies of the rays; here the scene is built through the library's
C API (ctypes, once per scene) and `rtcIntersect1` / `rtcOccluded1` are called directly from
`prange` kernels, the library's entry points passed in as addresses, so the kernels stay
cacheable. On the Cornell box this halves the time per ray against embreex's own loop (106 vs
175 ns on one core) and lets Numba's threads, not a Python thread pool, split the batch.

Embree works in float32. To keep precision far from the origin, vertices and ray origins are
shifted by the scene's bounding-box centre before the cast (as trimesh's ray_pyembree does).
Closest hits are then refined in float64: t is recomputed against the plane of the float64
triangle Embree reported, and the barycentrics from precomputed dual vectors of its edges, so
hit points lie on the float64 geometry (`refine=False`
keeps Embree's own float32 answers, for tests).

Unlike the Numba BVH (0 < t), Embree also reports a hit at t = 0 exactly (an origin lying on a
triangle); rays offset from their surface, as the integrator's are, never meet the difference.
Rays with a zero or non-finite origin or direction miss without reaching Embree.
"""
import ctypes
import glob
import math
import os
import weakref

import numba
import numpy as np
from llvmlite import ir
from numba import prange, types
from numba.extending import intrinsic

from tracer._jit import jit, kernel
from tracer.bvh import _bounds, _check_rays, _check_tri
from tracer.bvh.numba_bvh import _NumbaThreads

# Embree 4 C API constants (rtcore_common.h, rtcore_geometry.h, rtcore_buffer.h)
_GEOMETRY_TYPE_TRIANGLE = 0
_BUFFER_TYPE_INDEX = 0
_BUFFER_TYPE_VERTEX = 1
_FORMAT_UINT3 = 0x5003
_FORMAT_FLOAT3 = 0x9003
_BUILD_QUALITY_HIGH = 2
# RTCRayHit as 32-bit words: ray org(0-2) tnear(3) dir(4-6) time(7) tfar(8) mask(9) id(10)
# flags(11); hit Ng(12-14) u(15) v(16) primID(17) geomID(18) instID(19) [instPrimID(20)].
# Each chunk of a batch gets one 128-byte, 16-byte-aligned row of scratch to hold it.
_WORDS = 32
_CHUNKS = 64


def _load_library():
    """ctypes handle on the libembree4 that the embreex wheel installs."""
    import embreex  # noqa: F401  (ImportError here means: no embreex; make_accel reports it)

    here = os.path.dirname(embreex.__file__)
    found = sorted(glob.glob(os.path.join(here, "..", "embreex.libs", "libembree4*")))
    found += sorted(glob.glob(os.path.join(here, "libembree4*")))
    if not found:
        raise ImportError("embreex is installed but its libembree4 was not found", name="embreex")
    lib = ctypes.CDLL(found[0])
    vp, sz, uint = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_uint
    sigs = {
        "rtcNewDevice": (vp, [ctypes.c_char_p]),
        "rtcReleaseDevice": (None, [vp]),
        "rtcGetDeviceError": (ctypes.c_int, [vp]),
        "rtcNewScene": (vp, [vp]),
        "rtcReleaseScene": (None, [vp]),
        "rtcCommitScene": (None, [vp]),
        "rtcSetSceneBuildQuality": (None, [vp, ctypes.c_int]),
        "rtcNewGeometry": (vp, [vp, ctypes.c_int]),
        "rtcSetNewGeometryBuffer": (vp, [vp, ctypes.c_int, uint, ctypes.c_int, sz, sz]),
        "rtcCommitGeometry": (None, [vp]),
        "rtcAttachGeometry": (uint, [vp, vp]),
        "rtcReleaseGeometry": (None, [vp]),
    }
    for name, (res, args) in sigs.items():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = res, args
    return lib


_LIB = _load_library()
_INTERSECT1 = ctypes.cast(_LIB.rtcIntersect1, ctypes.c_void_p).value
_OCCLUDED1 = ctypes.cast(_LIB.rtcOccluded1, ctypes.c_void_p).value


@intrinsic
def _call3(typingctx, fn, a, b, c):
    """Call the C function at address `fn` as void fn(void*, void*, void*) with integers a, b, c."""
    sig = types.void(fn, a, b, c)

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fnty = ir.FunctionType(ir.VoidType(), [i64, i64, i64])
        ptr = builder.inttoptr(args[0], fnty.as_pointer())
        builder.call(ptr, [args[1], args[2], args[3]])
        return context.get_dummy_value()

    return sig, codegen


@jit
def _load_ray(buf, ib, o, d, centre, tfar):
    """Fill the RTCRay part of scratch row `buf` (ib: the same row as int32); False if invalid."""
    ok = True
    for a in range(3):
        if not (math.isfinite(o[a]) and math.isfinite(d[a])):
            ok = False
    if not ok or (d[0] == 0.0 and d[1] == 0.0 and d[2] == 0.0) or not (tfar >= 0.0):
        return False
    buf[0] = o[0] - centre[0]
    buf[1] = o[1] - centre[1]
    buf[2] = o[2] - centre[2]
    buf[3] = 0.0
    buf[4] = d[0]
    buf[5] = d[1]
    buf[6] = d[2]
    buf[7] = 0.0
    buf[8] = tfar if tfar < 3.0e38 else np.inf
    ib[9] = -1  # mask: every bit
    ib[10] = 0
    ib[11] = 0
    return True


def _plane_tables(tri):
    """(F, 12) float64 per triangle: v0, n = e1 x e2, and the duals a1 = (e2 x n) / |n|^2,
    a2 = (n x e1) / |n|^2, so that a point x of the plane has barycentrics
    b1 = (x - v0) . a1, b2 = (x - v0) . a2. Degenerate triangles get n = a1 = a2 = 0."""
    v0 = tri[:, 0]
    e1, e2 = tri[:, 1] - v0, tri[:, 2] - v0
    n = np.cross(e1, e2)
    nn = np.einsum("ij,ij->i", n, n)
    ok = (nn > 0) & np.isfinite(nn)
    inv = np.where(ok, 1.0 / np.where(ok, nn, 1.0), 0.0)[:, None]
    a1 = np.cross(e2, n) * inv
    a2 = np.cross(n, e1) * inv
    out = np.concatenate([v0, n, a1, a2], axis=1)
    out[~ok] = 0.0
    return np.ascontiguousarray(out)


@jit
def _refine(plane, p, o, d, t, b1, b2, i):
    """Recompute t, b1, b2 of ray i against the plane of triangle p in float64 (barycentrics
    clamped onto the triangle); keeps Embree's answer if the ray runs along the plane."""
    nx, ny, nz = plane[p, 3], plane[p, 4], plane[p, 5]
    den = d[0] * nx + d[1] * ny + d[2] * nz
    if not abs(den) > 0.0:
        return
    tt = ((plane[p, 0] - o[0]) * nx + (plane[p, 1] - o[1]) * ny + (plane[p, 2] - o[2]) * nz) / den
    if not (tt > 0.0 and tt < np.inf):
        return
    rx = o[0] + tt * d[0] - plane[p, 0]
    ry = o[1] + tt * d[1] - plane[p, 1]
    rz = o[2] + tt * d[2] - plane[p, 2]
    u1 = max(rx * plane[p, 6] + ry * plane[p, 7] + rz * plane[p, 8], 0.0)
    u2 = max(rx * plane[p, 9] + ry * plane[p, 10] + rz * plane[p, 11], 0.0)
    s = u1 + u2
    if s > 1.0:
        u1 /= s
        u2 /= s
    t[i] = tt
    b1[i] = u1
    b2[i] = u2


@kernel
def _intersect(fn, scene, plane, centre, org, dirs, tmax, refine, scratch, t, prim, b1, b2):
    n = org.shape[0]
    has_tmax = tmax.shape[0] == n
    nch = scratch.shape[0]
    for c in prange(nch):
        buf = scratch[c]
        ib = buf.view(np.int32)
        addr = buf.ctypes.data
        for i in range(c * n // nch, (c + 1) * n // nch):
            o = (org[i, 0], org[i, 1], org[i, 2])
            d = (dirs[i, 0], dirs[i, 1], dirs[i, 2])
            t[i] = np.inf
            prim[i] = -1
            b1[i] = 0.0
            b2[i] = 0.0
            if not _load_ray(buf, ib, o, d, centre, tmax[i] if has_tmax else np.inf):
                continue
            ib[17] = -1
            ib[18] = -1  # geomID: RTC_INVALID_GEOMETRY_ID until a hit
            ib[19] = -1
            _call3(fn, scene, addr, 0)
            if ib[18] == -1:
                continue
            p = ib[17]
            prim[i] = p
            t[i] = buf[8]
            if refine:
                b1[i] = 1.0 / 3.0  # kept only if the float64 refinement fails (ray along the plane)
                b2[i] = 1.0 / 3.0
                _refine(plane, p, o, d, t, b1, b2, i)
            else:
                b1[i] = buf[15]
                b2[i] = buf[16]


@kernel
def _occluded(fn, scene, centre, org, dirs, tmax, scratch, out):
    n = org.shape[0]
    nch = scratch.shape[0]
    for c in prange(nch):
        buf = scratch[c]
        ib = buf.view(np.int32)
        addr = buf.ctypes.data
        for i in range(c * n // nch, (c + 1) * n // nch):
            o = (org[i, 0], org[i, 1], org[i, 2])
            d = (dirs[i, 0], dirs[i, 1], dirs[i, 2])
            out[i] = False
            if not _load_ray(buf, ib, o, d, centre, tmax[i]):
                continue
            _call3(fn, scene, addr, 0)
            out[i] = buf[8] == -np.inf  # Embree sets tfar to -inf when something blocks the ray


def _scratch():
    """(_CHUNKS, _WORDS) float32 rows, each 16-byte aligned (RTCRayHit's alignment)."""
    raw = np.zeros(_CHUNKS * _WORDS + 16, np.float32)
    skip = (-raw.ctypes.data % 16) // 4
    return raw[skip : skip + _CHUNKS * _WORDS].reshape(_CHUNKS, _WORDS)


class EmbreeAccel:
    """Embree scene over triangles `tri` (F, 3, 3) float64.

    threads: how many Numba threads a batch query uses (default: Numba's current count).
    refine: recompute closest-hit t and barycentrics in float64 (cheap; default on).
    """

    name = "embree"

    def __init__(self, tri, threads=None, refine=True):
        tri = _check_tri(tri)
        self.tri = tri
        self.n_triangles = len(tri)
        self.bounds, self.scale = _bounds(tri)
        self.centre = self.bounds.mean(axis=0)
        limit = numba.config.NUMBA_NUM_THREADS
        self.threads = max(1, min(int(threads), limit) if threads else numba.get_num_threads())
        self.refine = bool(refine)
        self._plane = _plane_tables(tri)
        lib = _LIB
        self._device = lib.rtcNewDevice(None)
        self._scene = lib.rtcNewScene(self._device)
        lib.rtcSetSceneBuildQuality(self._scene, _BUILD_QUALITY_HIGH)  # static scene: best BVH
        # Degenerate or non-finite triangles become one point at the centre: never hit
        v = np.where(np.isfinite(tri).all(axis=(1, 2))[:, None, None], tri - self.centre, 0.0)
        v = np.ascontiguousarray(v.reshape(-1, 3), dtype=np.float32)
        if self.n_triangles:
            geom = lib.rtcNewGeometry(self._device, _GEOMETRY_TYPE_TRIANGLE)
            vb = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_TYPE_VERTEX, 0, _FORMAT_FLOAT3, 12, len(v))
            ib = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_TYPE_INDEX, 0, _FORMAT_UINT3, 12, self.n_triangles)
            ctypes.memmove(vb, v.ctypes.data, v.nbytes)
            idx = np.arange(len(v), dtype=np.uint32)
            ctypes.memmove(ib, idx.ctypes.data, idx.nbytes)
            lib.rtcCommitGeometry(geom)
            lib.rtcAttachGeometry(self._scene, geom)
            lib.rtcReleaseGeometry(geom)
        lib.rtcCommitScene(self._scene)
        err = lib.rtcGetDeviceError(self._device)
        if err != 0:
            raise RuntimeError(f"Embree could not build the scene (RTCError {err})")
        weakref.finalize(self, _release, self._scene, self._device)

    def intersect(self, org, dirs, tmax=None):
        """Closest hits: (t, prim, b1, b2), see `tracer.bvh`."""
        org, dirs, tmax = _check_rays(org, dirs, tmax)
        n = org.shape[0]
        t, prim, b1, b2 = np.empty(n), np.empty(n, np.int32), np.empty(n), np.empty(n)
        if n:
            with _NumbaThreads(self.threads):
                _intersect(_INTERSECT1, self._scene, self._plane, self.centre, org, dirs,
                           np.empty(0) if tmax is None else tmax, self.refine, _scratch(), t, prim, b1, b2)
        return t, prim, b1, b2

    def occluded(self, org, dirs, tmax):
        """(n,) bool: True where some triangle is hit with 0 <= t < tmax."""
        org, dirs, tmax = _check_rays(org, dirs, tmax, need_tmax=True)
        out = np.empty(org.shape[0], np.bool_)
        if org.shape[0]:
            with _NumbaThreads(self.threads):
                _occluded(_OCCLUDED1, self._scene, self.centre, org, dirs, tmax, _scratch(), out)
        return out

    def __repr__(self):
        return (f"EmbreeAccel(name='embree', triangles={self.n_triangles}, "
                f"threads={self.threads}, scale={self.scale:.4g})")


def _release(scene, device):
    _LIB.rtcReleaseScene(scene)
    _LIB.rtcReleaseDevice(device)
