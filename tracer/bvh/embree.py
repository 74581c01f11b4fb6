"""Embree ray queries, called from Numba kernels.

The embreex wheel ships Intel's libembree4. Its Python API traces a batch one ray at a time in
a Cython loop behind float32 copies of the rays; here the scene is built through the library's
C API (ctypes, once per scene) and `rtcIntersect16` / `rtcOccluded16` are called directly from
`prange` kernels, 16 rays a call, the library's entry points passed in as addresses, so the
kernels stay cacheable. Numba's threads, not a Python thread pool, split the batch. On the
Cornell box's stage batches the packets take 56-58 ns per ray against 59-66 with one ray per
call (2 threads); Embree's own rate from C is in bench/summary/throughput.md.

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
from numba.core import cgutils
from numba.extending import intrinsic

from tracer._jit import jit, kernel
from tracer.bvh import _bounds, _check_rays, _check_tri, edge_cross
from tracer.bvh.numba_bvh import _NumbaThreads

# Embree 4 C API constants (rtcore_common.h, rtcore_geometry.h, rtcore_buffer.h)
_GEOMETRY_TYPE_TRIANGLE = 0
_BUFFER_TYPE_INDEX = 0
_BUFFER_TYPE_VERTEX = 1
_FORMAT_UINT3 = 0x5003
_FORMAT_FLOAT3 = 0x9003
_BUILD_QUALITY_MEDIUM = 1
# RTCRayHit16, structure of arrays, 16 lanes per field: ray org(0-2) tnear(3) dir(4-6) time(7)
# tfar(8) mask(9) id(10) flags(11); hit Ng(12-14) u(15) v(16) primID(17) geomID(18) instID(19)
# [instPrimID(20)]. Each chunk of a batch gets one 64-byte-aligned row of scratch: the packet
# in fields 0-21, then the 16 int32 valid flags at field _VALID.
_LANES = 16
_VALID = 22
_WORDS = (_VALID + 2) * _LANES
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
_INTERSECT16 = ctypes.cast(_LIB.rtcIntersect16, ctypes.c_void_p).value
_OCCLUDED16 = ctypes.cast(_LIB.rtcOccluded16, ctypes.c_void_p).value


@intrinsic
def cycles(typingctx):
    """The processor's cycle counter (llvm.readcyclecounter: rdtsc on x86), for per-stage shares."""
    sig = types.int64()

    def codegen(context, builder, signature, args):
        fnty = ir.FunctionType(ir.IntType(64), [])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.readcyclecounter")
        return builder.call(fn, [])

    return sig, codegen


@intrinsic
def call4(typingctx, fn, a, b, c, d):
    """Call the C function at address `fn` as void fn(void*, void*, void*, void*) with integers
    a, b, c, d."""
    sig = types.void(fn, a, b, c, d)

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fnty = ir.FunctionType(ir.VoidType(), [i64, i64, i64, i64])
        ptr = builder.inttoptr(args[0], fnty.as_pointer())
        builder.call(ptr, [args[1], args[2], args[3], args[4]])
        return context.get_dummy_value()

    return sig, codegen


@jit
def load_lane(buf, ib, k, org, dirs, i, centre, tfar):
    """Fill lane k of the packet in scratch row `buf` (ib: the same row as int32) with ray i and
    mark it valid; False (the lane untouched) if the ray is invalid."""
    ok = True
    for a in range(3):
        if not (math.isfinite(org[i, a]) and math.isfinite(dirs[i, a])):
            ok = False
    if not ok or (dirs[i, 0] == 0.0 and dirs[i, 1] == 0.0 and dirs[i, 2] == 0.0) or not (tfar >= 0.0):
        return False
    L = _LANES
    buf[k] = org[i, 0] - centre[0]
    buf[L + k] = org[i, 1] - centre[1]
    buf[2 * L + k] = org[i, 2] - centre[2]
    buf[3 * L + k] = 0.0
    buf[4 * L + k] = dirs[i, 0]
    buf[5 * L + k] = dirs[i, 1]
    buf[6 * L + k] = dirs[i, 2]
    buf[7 * L + k] = 0.0
    buf[8 * L + k] = tfar if tfar < 3.0e38 else np.inf
    ib[9 * L + k] = -1  # mask: every bit
    ib[10 * L + k] = 0
    ib[11 * L + k] = 0
    ib[_VALID * L + k] = -1
    return True


@kernel
def _plane_tables(tri):
    """(F, 12) float64 per triangle: v0, n = e1 x e2, and the duals a1 = (e2 x n) / |n|^2,
    a2 = (n x e1) / |n|^2, so that a point x of the plane has barycentrics
    b1 = (x - v0) . a1, b2 = (x - v0) . a2. Degenerate triangles get n = a1 = a2 = 0."""
    out = np.empty((tri.shape[0], 12))
    for i in prange(tri.shape[0]):
        e1, e2, n = edge_cross(tri, i)
        e1x, e1y, e1z = e1
        e2x, e2y, e2z = e2
        nx, ny, nz = n
        nn = (nx * nx + nz * nz) + ny * ny  # the order numpy's einsum("ij,ij->i") sums in
        if nn > 0.0 and math.isfinite(nn):
            inv = 1.0 / nn
            row = (tri[i, 0, 0], tri[i, 0, 1], tri[i, 0, 2], nx, ny, nz,
                   (e2y * nz - e2z * ny) * inv, (e2z * nx - e2x * nz) * inv, (e2x * ny - e2y * nx) * inv,
                   (ny * e1z - nz * e1y) * inv, (nz * e1x - nx * e1z) * inv, (nx * e1y - ny * e1x) * inv)
            for k in range(12):
                out[i, k] = row[k]
        else:
            for k in range(12):
                out[i, k] = 0.0
    return out


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


@jit(inline="always")
def clear_packet(ib):
    """Mark every lane of the packet in scratch row `ib` (int32 view) invalid, with no hit."""
    L = _LANES
    for k in range(L):
        ib[_VALID * L + k] = 0
        ib[17 * L + k] = -1  # primID, geomID (RTC_INVALID_GEOMETRY_ID until a hit), instID
        ib[18 * L + k] = -1
        ib[19 * L + k] = -1


@jit(inline="always")
def read_hit(buf, ib, k, refine, plane, org, dirs, t, prim, b1, b2, i):
    """Closest hit of lane k after rtcIntersect16, for ray i of org, dirs: into t, prim, b1, b2[i]
    (left as they are where the lane was invalid or missed), refined in float64 if `refine`."""
    L = _LANES
    if ib[_VALID * L + k] == 0 or ib[18 * L + k] == -1:
        return
    p = ib[17 * L + k]
    prim[i] = p
    t[i] = buf[8 * L + k]
    if refine:
        b1[i] = 1.0 / 3.0  # kept only if the float64 refinement fails (ray along the plane)
        b2[i] = 1.0 / 3.0
        _refine(plane, p, (org[i, 0], org[i, 1], org[i, 2]), (dirs[i, 0], dirs[i, 1], dirs[i, 2]), t, b1, b2, i)
    else:
        b1[i] = buf[15 * L + k]
        b2[i] = buf[16 * L + k]


@jit(inline="always")
def lane_occluded(buf, ib, k):
    """Whether lane k's shadow ray was blocked, after rtcOccluded16 (an invalid lane never is)."""
    # Embree sets tfar to -inf when something blocks the ray
    return ib[_VALID * _LANES + k] != 0 and buf[8 * _LANES + k] == -np.inf


@jit
def _fill_packet(buf, ib, org, dirs, tmax, has_tmax, base, m, centre):
    """Load rays base .. base+m-1 into the packet in scratch row `buf` (lanes past m, and invalid
    rays, left invalid; no hit recorded in any lane); True if any lane is valid."""
    clear_packet(ib)
    any_valid = False
    for k in range(m):
        i = base + k
        if load_lane(buf, ib, k, org, dirs, i, centre, tmax[i] if has_tmax else np.inf):
            any_valid = True
    return any_valid


@kernel
def _intersect(fn, scene, plane, centre, org, dirs, tmax, refine, scratch, t, prim, b1, b2):
    """Closest hits of a batch, 16 rays per rtcIntersect16 call, each chunk of the batch on one
    thread in its own scratch row."""
    n = org.shape[0]
    has_tmax = tmax.shape[0] == n
    nch = scratch.shape[0]
    L = _LANES
    for c in prange(nch):
        buf = scratch[c]
        ib = buf.view(np.int32)
        addr = buf.ctypes.data
        hi = (c + 1) * n // nch
        for base in range(c * n // nch, hi, L):
            m = min(L, hi - base)
            for i in range(base, base + m):
                t[i] = np.inf
                prim[i] = -1
                b1[i] = 0.0
                b2[i] = 0.0
            if not _fill_packet(buf, ib, org, dirs, tmax, has_tmax, base, m, centre):
                continue
            call4(fn, addr + 4 * _VALID * L, scene, addr, 0)
            for k in range(m):
                read_hit(buf, ib, k, refine, plane, org, dirs, t, prim, b1, b2, base + k)


@kernel
def _occluded(fn, scene, centre, org, dirs, tmax, scratch, out):
    """Any-hit queries of a batch, 16 rays per rtcOccluded16 call."""
    n = org.shape[0]
    nch = scratch.shape[0]
    L = _LANES
    for c in prange(nch):
        buf = scratch[c]
        ib = buf.view(np.int32)
        addr = buf.ctypes.data
        hi = (c + 1) * n // nch
        for base in range(c * n // nch, hi, L):
            m = min(L, hi - base)
            for i in range(base, base + m):
                out[i] = False
            if not _fill_packet(buf, ib, org, dirs, tmax, True, base, m, centre):
                continue
            call4(fn, addr + 4 * _VALID * L, scene, addr, 0)
            for k in range(m):
                out[base + k] = lane_occluded(buf, ib, k)


@jit
def _fill_listed(buf, ib, lane, q, hi, idx, per, todo, org, dirs, tmax, centre):
    """Fill the packet in scratch row `buf` (ib: the same row as int32) with the next flagged rows
    from position q (below hi) of a listed query: row j = idx[q // per] * per + q % per where
    todo[j], into lane[f] and packet lane f (left invalid where the ray is; tmax of none: inf).
    Returns (the position after the last row taken, lanes filled)."""
    clear_packet(ib)
    f = 0
    while q < hi and f < _LANES:
        j = idx[q // per] * per + q % per
        q += 1
        if todo[j]:
            lane[f] = j
            load_lane(buf, ib, f, org, dirs, j, centre, tmax[j] if tmax.shape[0] > 0 else np.inf)
            f += 1
    return q, f


@kernel
def intersect_listed(fn, scene, plane, centre, refine, scratch, idx, per, rays, hits):
    """Closest hits of the flagged rays of rows: ray j = idx[a] * per + o (a over idx, o in
    0 .. per-1) where todo[j], rays = (todo, org, dirs); into hits = (t, prim, b1, b2)[j], as
    EmbreeAccel.intersect answers them (t inf and prim -1 on a miss or an invalid ray; the others
    untouched). Each chunk of idx fills its packets with the next 16 flagged rays it finds.
    Returns how many were flagged."""
    todo = rays[0]
    org = rays[1]
    dirs = rays[2]
    t = hits[0]
    prim = hits[1]
    b1 = hits[2]
    b2 = hits[3]
    nch = scratch.shape[0]
    nq = idx.shape[0] * per
    flagged = 0
    for c in prange(nch):
        buf = scratch[c]
        ib = buf.view(np.int32)
        lane = np.empty(_LANES, np.int64)
        q = c * nq // nch
        hi = (c + 1) * nq // nch
        while q < hi:
            q, f = _fill_listed(buf, ib, lane, q, hi, idx, per, todo, org, dirs, t[:0], centre)
            if f > 0:
                call4(fn, buf.ctypes.data + 4 * _VALID * _LANES, scene, buf.ctypes.data, 0)
            for k in range(f):
                j = lane[k]
                t[j] = np.inf
                prim[j] = -1
                b1[j] = 0.0
                b2[j] = 0.0
                read_hit(buf, ib, k, refine, plane, org, dirs, t, prim, b1, b2, j)
            flagged += f
    return flagged


@kernel
def occluded_listed(fn, scene, centre, scratch, idx, per, rays, out, on_blocked, on_clear, keep_clear):
    """Any-hit queries of the flagged rays of rows (idx, per as intersect_listed; rays = (todo, org,
    dirs, tmax)): out[j] = on_blocked where ray j is blocked, else on_clear (left as it is if
    keep_clear). An invalid ray is clear, as in EmbreeAccel.occluded. Returns how many were
    flagged."""
    todo = rays[0]
    org = rays[1]
    dirs = rays[2]
    tmax = rays[3]
    nch = scratch.shape[0]
    nq = idx.shape[0] * per
    flagged = 0
    for c in prange(nch):
        buf = scratch[c]
        ib = buf.view(np.int32)
        lane = np.empty(_LANES, np.int64)
        q = c * nq // nch
        hi = (c + 1) * nq // nch
        while q < hi:
            q, f = _fill_listed(buf, ib, lane, q, hi, idx, per, todo, org, dirs, tmax, centre)
            if f > 0:
                call4(fn, buf.ctypes.data + 4 * _VALID * _LANES, scene, buf.ctypes.data, 0)
            for k in range(f):
                if lane_occluded(buf, ib, k):
                    out[lane[k]] = on_blocked
                elif not keep_clear:
                    out[lane[k]] = on_clear
            flagged += f
    return flagged


def _scratch():
    """(_CHUNKS, _WORDS) float32 rows, each 64-byte aligned (RTCRayHit16's alignment)."""
    raw = np.zeros(_CHUNKS * _WORDS + 16, np.float32)
    skip = (-raw.ctypes.data % 64) // 4
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
        self._rows = _scratch()  # the packets' scratch, reused by every query (one query at a time)
        lib = _LIB
        self._device = lib.rtcNewDevice(None)
        self._scene = lib.rtcNewScene(self._device)
        # Medium: the same ray rate as high on the benchmark scenes (from C, one thread: 67 vs 67
        # ns per ray on the Cornell box, 179 vs 177 at 1.3M triangles) for 0.42 s of build at
        # 1.3M triangles instead of 0.73 s (bench/summary/throughput.md)
        lib.rtcSetSceneBuildQuality(self._scene, _BUILD_QUALITY_MEDIUM)
        if self.n_triangles:
            geom = lib.rtcNewGeometry(self._device, _GEOMETRY_TYPE_TRIANGLE)
            nv = 3 * self.n_triangles
            vb = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_TYPE_VERTEX, 0, _FORMAT_FLOAT3, 12, nv)
            ib = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_TYPE_INDEX, 0, _FORMAT_UINT3, 12, self.n_triangles)
            # written in place into Embree's buffers: no float64 or float32 copy of the vertices
            _fill_buffers(tri, self.centre, _wrap(vb, nv * 3, np.float32), _wrap(ib, nv, np.uint32))
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
                _intersect(_INTERSECT16, self._scene, self._plane, self.centre, org, dirs,
                           np.empty(0) if tmax is None else tmax, self.refine, self._rows, t, prim, b1, b2)
        return t, prim, b1, b2

    def occluded(self, org, dirs, tmax):
        """(n,) bool: True where some triangle is hit with 0 <= t < tmax."""
        org, dirs, tmax = _check_rays(org, dirs, tmax, need_tmax=True)
        out = np.empty(org.shape[0], np.bool_)
        if org.shape[0]:
            with _NumbaThreads(self.threads):
                _occluded(_OCCLUDED16, self._scene, self.centre, org, dirs, tmax, self._rows, out)
        return out

    def packet_args(self):
        """(scene, plane table, centre, refine, scratch rows): what a kernel that makes its own
        rtcIntersect16 / rtcOccluded16 calls needs (tracer.integrators.thread_loop)."""
        return self._scene, self._plane, self.centre, self.refine, self._rows

    def __repr__(self):
        return (f"EmbreeAccel(name='embree', triangles={self.n_triangles}, "
                f"threads={self.threads}, scale={self.scale:.4g})")


def _wrap(address, n, dtype):
    """The n-element array of `dtype` at a C address (memory Embree owns)."""
    ctype = np.ctypeslib.as_ctypes_type(dtype)
    return np.ctypeslib.as_array(ctypes.cast(address, ctypes.POINTER(ctype)), shape=(n,))


@kernel
def _fill_buffers(tri, centre, vb, ib):
    """Embree's vertex buffer: triangle i's vertices less the centre, in float32 (a degenerate or
    non-finite triangle becomes one point at the centre: never hit); index buffer 0, 1, 2, ..."""
    for i in prange(tri.shape[0]):
        ok = True
        for k in range(3):
            for a in range(3):
                if not math.isfinite(tri[i, k, a]):
                    ok = False
        for k in range(3):
            for a in range(3):
                vb[9 * i + 3 * k + a] = np.float32(tri[i, k, a] - centre[a]) if ok else np.float32(0.0)
            ib[3 * i + k] = 3 * i + k


def _release(scene, device):
    _LIB.rtcReleaseScene(scene)
    _LIB.rtcReleaseDevice(device)
