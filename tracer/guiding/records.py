"""Path vertices recorded for guides that learn, and the radiance that came back along them.

With recording on, the shading kernel writes one record per surface vertex where a direction was
sampled (`record_emission`, `record_sampled` and `record_vectors`, from the wavefront's shade in
tracer.integrators.path and the lanes' listed and general kernels); once the path has ended,
`finalize_records` turns what the path gathered after the vertex into the radiance along the
vertex's direction. A guide receives the records of each wave in `observe(records)`.
"""
import math
from typing import NamedTuple

import numpy as np
from numba import prange

from .._jit import jit, kernel
from ..bsdfs import lum

RECORD_NONE = 0  # a bounce's record mode: no records
RECORD_ALL = 1  # records of the full incident radiance
RECORD_INDIRECT = 2  # records of the radiance less the emission the direction hits directly (NEE's part)


class Records(NamedTuple):
    """Path vertices of a wave (R entries; strategy -1 = unused entry)."""

    x: np.ndarray  # (R, 3) float32 world position
    n: np.ndarray  # (R, 3) float32 geometric normal, on the side the path arrived from
    wi: np.ndarray  # (R, 3) float32 sampled world direction
    pdf: np.ndarray  # (R,) float32 solid-angle density it was sampled with (the MIS mixture)
    fcos: np.ndarray  # (R,) float32 luminance of f(wo, wi) |cos|
    strategy: np.ndarray  # (R,) int8 0 = BSDF, 1 = guide, -1 = no record
    node: np.ndarray  # (R,) int32 guide voxel (-1: none)
    path: np.ndarray  # (R,) int64 path slot in the wave
    pixel: np.ndarray  # (R,) int64 film pixel of the path
    L0: np.ndarray  # (R, 3) float64 path radiance when the direction was sampled
    beta: np.ndarray  # (R, 3) float64 throughput after the vertex (0 if the path ended)
    pb: np.ndarray  # (R,) float32 the BSDF's own density of wi (pdf is the mixture's)
    radiance: np.ndarray  # (R,) float32 luminance of the radiance that came back along wi
    prev: np.ndarray  # (R,) int64 record of the path's previous vertex (-1: first hit, or after a delta vertex)
    direct: np.ndarray  # (R,) float32 luminance of the emission wi hits directly, without MIS weight (0: none)
    plight: np.ndarray  # (R,) float32 next-event estimation's solid-angle density of that emission (0: none)

    @staticmethod
    def allocate(size):
        f3 = lambda: np.zeros((size, 3), np.float32)  # noqa: E731
        return Records(x=f3(), n=f3(), wi=f3(), pdf=np.zeros(size, np.float32), fcos=np.zeros(size, np.float32),
                       strategy=np.full(size, -1, np.int8), node=np.full(size, -1, np.int32),
                       path=np.zeros(size, np.int64), pixel=np.zeros(size, np.int64), L0=np.zeros((size, 3)),
                       beta=np.zeros((size, 3)), pb=np.zeros(size, np.float32), radiance=np.zeros(size, np.float32),
                       prev=np.full(size, -1, np.int64), direct=np.zeros(size, np.float32),
                       plight=np.zeros(size, np.float32))

    def grown(self, size, used):
        """A larger Records holding the first `used` entries of this one."""
        new = Records.allocate(size)
        for a, b in zip(self, new):
            b[:used] = a[:used]
        return new

    def head(self, n):
        """A view of the first n entries."""
        return Records(*(a[:n] for a in self))


@kernel
def finalize_records(strategy, path, beta, L0, radiance, L):
    """Radiance along each record's direction once its path has ended: luminance of
    (L_end - L0) / beta per channel (0 where beta is 0, negative or not finite)."""
    for r in prange(strategy.shape[0]):
        if strategy[r] < 0:
            continue
        i = path[r]
        v = 0.0
        for c in range(3):
            b = beta[r, c]
            if b > 0.0:
                v += (0.2126, 0.7152, 0.0722)[c] * (L[i, c] - L0[r, c]) / b
        radiance[r] = v if (v > 0.0 and math.isfinite(v)) else 0.0
@jit(inline="always")
def record_emission(r, record, b, le, w, pdf, r_L0, r_direct, r_plight):
    """Emission le (MIS weight w) found along the direction of record r, sampled with density pdf,
    by a path of throughput b: RECORD_ALL counts it in full in the record's radiance,
    RECORD_INDIRECT not at all (its L0 takes what L gained); either way the record keeps its
    luminance (`direct`) and next-event estimation's density of it (`plight`, from the power
    heuristic's weight: w = pdf^2 / (pdf^2 + plight^2))."""
    x_le = -(1.0 - w) if record == RECORD_ALL else w
    for c in range(3):
        r_L0[r, c] += b[c] * le[c] * x_le
    r_direct[r] += lum(le)
    if w > 0.0:
        r_plight[r] = pdf * math.sqrt(max(1.0 - w, 0.0) / w)
    else:
        r_plight[r] = np.inf


@jit(inline="always")
def record_sampled(i, r, vx, prev_rec, pix, r_prev, r_strategy, r_node, r_path, r_pixel, r_pdf, r_pb, r_fcos,
                   r_direct, r_plight):
    """Path slot i sampled a direction at its vertex, shaded as record r: vx = (recorded, x, nf, wi,
    strategy, node, pdf_mix, pdf_bsdf, fcos, beta, L0) (engine.vertex.Vertex's fields of those
    names; L0 the path's radiance so far, the vertex's emission in, its NEE not). Where `recorded`
    (not a delta vertex) the vertex becomes record r and the path's last, its scalars written here
    and its vectors by record_vectors, which the caller calls where this returns True; else the
    path has no last record. The r_* arrays are Records' fields, passed one by one: a parallel
    loop loses writes made through a tuple of arrays (tests/test_seams.py)."""
    last = prev_rec[i]
    prev_rec[i] = -1
    if vx[0]:
        r_prev[r] = last
        prev_rec[i] = r
        r_strategy[r] = vx[4]
        r_node[r] = vx[5]
        r_path[r] = i
        r_pixel[r] = pix[i]
        r_pdf[r] = vx[6]
        r_pb[r] = vx[7]
        r_fcos[r] = vx[8]
        r_direct[r] = 0.0
        r_plight[r] = 0.0
    return vx[0]


@jit(inline="always")
def record_vectors(r, vx, r_x, r_n, r_wi, r_L0, r_beta):
    """The vectors of record r (record_sampled's vx): position, facing normal, direction, L0, beta."""
    for c in range(3):
        r_x[r, c] = vx[1][c]
        r_n[r, c] = vx[2][c]
        r_wi[r, c] = vx[3][c]
        r_L0[r, c] = vx[10][c]
        r_beta[r, c] = vx[9][c]


@jit(inline="always")
def vertex_record(v, L, i):
    """record_sampled's vx from the engine.vertex.Vertex v of path slot i (L0: its radiance L[i])."""
    return (v.recorded, v.x, v.nf, v.wi, v.strategy, v.node, v.pdf_mix, v.pdf_bsdf, v.fcos, v.beta,
            (L[i, 0], L[i, 1], L[i, 2]))


@jit
def record_vertex(v, L, i, r, record, prev_rec, pix, rec):
    """Write the records of path slot i's vertex, shaded by shade_vertex as v (engine.vertex.Vertex),
    as record r of Records rec: the emission it found into its path's last record, and the vertex
    itself where it sampled a direction. Called, not inlined: a parallel loop keeps the writes of a
    called function through a tuple of arrays (tests/test_seams.py), not of an inlined one."""
    r_L0 = rec.L0
    r_direct = rec.direct
    r_plight = rec.plight
    if v.found and prev_rec[i] >= 0:
        record_emission(prev_rec[i], record, v.b, v.le, v.w, v.pdf, r_L0, r_direct, r_plight)
    if v.sampled:
        vx = vertex_record(v, L, i)
        r_prev = rec.prev
        r_strategy = rec.strategy
        r_node = rec.node
        r_path = rec.path
        r_pixel = rec.pixel
        r_pdf = rec.pdf
        r_pb = rec.pb
        r_fcos = rec.fcos
        if record_sampled(i, r, vx, prev_rec, pix, r_prev, r_strategy, r_node, r_path, r_pixel, r_pdf, r_pb, r_fcos,
                          r_direct, r_plight):
            r_x = rec.x
            r_n = rec.n
            r_wi = rec.wi
            r_beta = rec.beta
            record_vectors(r, vx, r_x, r_n, r_wi, r_L0, r_beta)
