"""The contract between the integrator's kernels and a guide: the state they read and the three
questions they ask at a vertex.

    locate(state, x, n, pixel, depth) -> (node, slot, a)   where the vertex's map is, and the
                                                            probability a of BSDF sampling
    slot_sample(state, slot, u0, u1) -> (wi, pdf)          a world direction from that map
    slot_pdf(state, slot, wi) -> pdf                       its solid-angle density

The integrator samples the one-sample MIS mixture a p_bsdf + (1 - a) p_guide (tracer.shading)
and never reads anything else of a guide. Space and direction are apart: `locate` finds a map
by position (the voxels of a guide's spatial structure, find_voxel) or by film pixel (a first
bounce's per-pixel map), and a map is a row of the directional tables (guiding.directional:
a theta-phi histogram with its sampling tables, family TABLES), or a directional quadtree
(guiding.quadtree, family QUADTREE: Practical Path Guiding's). Another family (e.g. a mixture of
lobes) adds its arrays to GuideState and its branch to slot_sample and slot_pdf, and nothing
else in the kernels changes. A guide
builds the state in `Guide.state()`; `empty_state()` is no guide at all. guide_sample,
guide_pdf and their batches are the contract tests' view (tests/guiding/test_contract.py).
"""
from typing import NamedTuple

import numpy as np
from numba import prange

from .._jit import jit, kernel
from .directional import map_pdf, map_sample
from .quadtree import qt_pdf, qt_sample

TABLES, QUADTREE = 0, 1  # GuideState.family: what a slot indexes
# the quadtree arrays of a state without quadtrees (read-only; the same dtypes and layout as real ones)
_NO_QT_CHILD = np.full((1, 4), -1, np.int32)
_NO_QT_VALUE = np.zeros((1, 4))
_NO_QT_ROOT = np.zeros(1, np.int32)


class GuideState(NamedTuple):
    """Arrays the integrator's kernels read; `empty_state()` is 'no guide'."""

    lo: np.ndarray  # (3,) float64 grid origin
    inv_cell: np.ndarray  # (3,) float64 1 / cell side
    res: np.ndarray  # (3,) int64 cells per axis; (0, 0, 0) = no grid
    child: np.ndarray  # (N,) int32 left child of a node (right = left + 1), -1 at leaves
    axis: np.ndarray  # (N,) int32 split axis
    split: np.ndarray  # (N,) float64 split plane (x[axis] >= split goes right)
    slot: np.ndarray  # (N,) int32 sampling map of a leaf, -1 where it has none
    alpha: np.ndarray  # (N,) float64 probability of BSDF sampling at a leaf with a map
    rowcum: np.ndarray  # (S, n_theta + 1) uint32 cumulative row sums of the maps' weights (see directional)
    dens: np.ndarray  # (S, K) uint16 integer weights of the maps' bins
    wsum: np.ndarray  # (S,) float64 their totals
    pscale: np.ndarray  # (S,) float64 density per unit weight of each map, K / (4 pi total)
    n_theta: int
    n_phi: int
    n_class: int  # trees per cell: 1, or 6 (one per facing-normal class, see normal_class)
    pixel_slot: np.ndarray  # (P,) int32 per film pixel, the map its first bounce samples (-1: the voxel's); (0,): none
    pixel_alpha: np.ndarray  # (P,) float64 per film pixel, the mixing weight that goes with it
    family: int = TABLES  # TABLES: a slot is a row of rowcum/dens; QUADTREE: the tree at qt_root[slot]
    qt_child: np.ndarray = _NO_QT_CHILD  # (Q, 4) int32 quadtree nodes' children (-1: leaf quadrant)
    qt_value: np.ndarray = _NO_QT_VALUE  # (Q, 4) float64 their quadrants' energy
    qt_root: np.ndarray = _NO_QT_ROOT  # (S,) int32 the root node of each slot's tree
    # Russian roulette (tracer.shading.next_bounce, tracer.integrators.path.shade_vertex): survival
    # clamp(max(beta) / gain, rr_min, rr_max); rr_late 0 draws it before the sampled ray is traced
    # (Mitsuba 3's order), 1 after, once the emission the ray hits is counted, and never after a
    # delta bounce (Practical Path Guiding's reference); rec_q 1 makes a record's throughput the
    # one before the roulette, so that its radiance is X / q and its expectation L_i (0: X, q L_i)
    rr_late: int = 0
    rr_min: float = 0.0
    rr_max: float = 0.95
    rec_q: int = 0


def empty_state(n_theta=2, n_phi=2):
    """A state with no grid: every lookup misses, so every vertex samples its BSDF."""
    return GuideState(np.zeros(3), np.ones(3), np.zeros(3, np.int64), np.full(1, -1, np.int32),
                      np.zeros(1, np.int32), np.zeros(1), np.full(1, -1, np.int32), np.ones(1),
                      np.zeros((1, n_theta + 1), np.uint32), np.zeros((1, n_theta * n_phi), np.uint16),
                      np.ones(1), np.zeros(1), int(n_theta), int(n_phi), 1, *no_pixel_maps())


def no_pixel_maps():
    """(pixel_slot, pixel_alpha) of a state without per-pixel first-bounce maps."""
    return np.zeros(0, np.int32), np.zeros(0)


@jit(inline="always")
def normal_class(n_class, n):
    """Class of a facing normal n (the side of the surface a path or photon arrives on): its
    dominant axis and sign, 0..5 (0 when there is one class)."""
    if n_class == 1:
        return 0
    ax = 0
    m = abs(n[0])
    if abs(n[1]) > m:
        ax = 1
        m = abs(n[1])
    if abs(n[2]) > m:
        ax = 2
    return 2 * ax + (1 if n[ax] < 0.0 else 0)


@jit(inline="always")
def find_voxel(gs, x, n):
    """Leaf node holding point x on a surface whose side facing the arriving path or photon has
    normal n, or -1 outside the grid (or without a grid)."""
    if gs.res[0] == 0:
        return -1
    c0 = int(np.floor((x[0] - gs.lo[0]) * gs.inv_cell[0]))
    c1 = int(np.floor((x[1] - gs.lo[1]) * gs.inv_cell[1]))
    c2 = int(np.floor((x[2] - gs.lo[2]) * gs.inv_cell[2]))
    if c0 < 0 or c1 < 0 or c2 < 0 or c0 >= gs.res[0] or c1 >= gs.res[1] or c2 >= gs.res[2]:
        return -1
    node = ((c2 * gs.res[1] + c1) * gs.res[0] + c0) * gs.n_class + normal_class(gs.n_class, n)
    while gs.child[node] >= 0:  # bounded by the tree depth
        a = gs.axis[node]
        node = gs.child[node] + (1 if x[a] >= gs.split[node] else 0)
    return node


# --- Locate, then sample: what the integrator asks of a guide at a vertex ---------------------------
@jit(inline="always")
def locate(gs, x, n, pixel, depth):
    """Where the guide keeps the map for a vertex at x (world) with facing normal n, on a path of
    film pixel `pixel` (-1: none) at bounce `depth` (0: the first hit): (node, slot, a). node is
    the voxel (leaf, -1 outside the grid), slot the sampling map to draw from (-1: none, sample the
    BSDF), a the probability of BSDF sampling in the one-sample MIS mixture (1 where slot is -1).
    A per-pixel map (gs.pixel_slot, e.g. a first-bounce map per pixel) takes precedence at depth
    0; node is then -1, so that the voxel's statistics do not count samples of the pixel's map."""
    if depth == 0 and 0 <= pixel < gs.pixel_slot.shape[0]:
        s = gs.pixel_slot[pixel]
        if s >= 0:
            return -1, s, gs.pixel_alpha[pixel]
    node = find_voxel(gs, x, n)
    if node >= 0:
        s = gs.slot[node]
        if s >= 0:
            return node, s, gs.alpha[node]
    return node, -1, 1.0


@jit(inline="always")
def slot_sample(gs, slot, u0, u1):
    """(world direction, solid-angle pdf) from sampling map `slot` (>= 0) for u0, u1 in [0, 1)."""
    if gs.family == QUADTREE:
        return qt_sample(gs.qt_child, gs.qt_value, gs.qt_root[slot], u0, u1)
    return map_sample(gs.rowcum, gs.dens, gs.wsum, gs.pscale, slot, gs.n_theta, gs.n_phi, u0, u1)


@jit(inline="always")
def slot_pdf(gs, slot, d):
    """Solid-angle density of world direction d under sampling map `slot` (>= 0)."""
    if gs.family == QUADTREE:
        return qt_pdf(gs.qt_child, gs.qt_value, gs.qt_root[slot], d)
    return map_pdf(gs.dens, gs.pscale, slot, gs.n_theta, gs.n_phi, d)


# --- The sampler contract as the tests use it: sample(state, x, n, wo, u), pdf(state, x, n, wi) ----
@jit(inline="always")
def guide_sample(gs, x, n, wo, u0, u1, pixel, depth):
    """Sample a world direction from the guide's map for a vertex at x, n (the normal on the side
    of wo) of film pixel `pixel` at bounce `depth`: (wi, pdf); pdf 0 where there is no map."""
    _, slot, _ = locate(gs, x, n, pixel, depth)
    if slot < 0:
        return (0.0, 0.0, 1.0), 0.0
    return slot_sample(gs, slot, u0, u1)


@jit(inline="always")
def guide_pdf(gs, x, n, wi, pixel, depth):
    """The density guide_sample draws wi with (0 where there is no map)."""
    _, slot, _ = locate(gs, x, n, pixel, depth)
    if slot < 0:
        return 0.0
    return slot_pdf(gs, slot, wi)


@kernel
def guide_sample_batch(gs, x, n, wo, u, pixel=-1, depth=1):
    """Batch guide_sample: x, n, wo (m, 3), u (m, 2) -> (wi (m, 3), pdf (m,)); every vertex of film
    pixel `pixel` at bounce `depth` (the defaults: no pixel, past the first bounce)."""
    m = x.shape[0]
    wi = np.empty((m, 3))
    pdf = np.empty(m)
    for i in prange(m):
        d, p = guide_sample(gs, (x[i, 0], x[i, 1], x[i, 2]), (n[i, 0], n[i, 1], n[i, 2]),
                            (wo[i, 0], wo[i, 1], wo[i, 2]), u[i, 0], u[i, 1], pixel, depth)
        wi[i, 0], wi[i, 1], wi[i, 2] = d
        pdf[i] = p
    return wi, pdf


@kernel
def guide_pdf_batch(gs, x, n, wi, pixel=-1, depth=1):
    """Batch guide_pdf (pixel and depth as guide_sample_batch)."""
    m = x.shape[0]
    pdf = np.empty(m)
    for i in prange(m):
        pdf[i] = guide_pdf(gs, (x[i, 0], x[i, 1], x[i, 2]), (n[i, 0], n[i, 1], n[i, 2]),
                           (wi[i, 0], wi[i, 1], wi[i, 2]), pixel, depth)
    return pdf


@kernel
def locate_batch(gs, x, n):
    """Leaf node of every point x (m, 3) with facing normal n (m, 3), -1 outside the grid."""
    m = x.shape[0]
    out = np.empty(m, np.int64)
    for i in prange(m):
        out[i] = find_voxel(gs, (x[i, 0], x[i, 1], x[i, 2]), (n[i, 0], n[i, 1], n[i, 2]))
    return out
