"""Directional quadtrees (tracer.guiding.quadtree, Practical Path Guiding's D-trees) against a slow
twin written here: a tree as a flat list of leaf squares with their energies, the density of a
direction found by containment (energy share / (4 pi area)), refinement by recursion over squares.
"""
import math

import numpy as np
import pytest

from tracer.guiding.quadtree import UNIFORM_DEPTH, qt_pdf_batch, qt_sample_batch, refine, splat, splat_box, sums
from tracer.testing.chi2 import histogram_test

# --- the twin: leaves (u0, v0, size, energy) -----------------------------------------------------


def random_leaves(rng, max_depth, p_split=0.6, p_empty=0.15):
    """A random quadtree as its leaves: squares (u0, v0, size) and energies (some zero)."""
    out = []

    def grow(u0, v0, size, depth):
        if depth < max_depth and rng.random() < (0.95 if depth < 2 else p_split):
            h = size / 2
            for du, dv in ((0, 0), (h, 0), (0, h), (h, h)):  # quadrant i = (u >= 1/2) + 2 (v >= 1/2)
                grow(u0 + du, v0 + dv, h, depth + 1)
        else:
            out.append([u0, v0, size, 0.0 if rng.random() < p_empty else rng.gamma(0.5)])

    grow(0.0, 0.0, 1.0, 0)
    return np.array(out)


def to_arrays(leaves):
    """(child, value, root) of the tree whose leaves are `leaves` (interior values: subtree sums)."""
    child, value = [], []

    def node(u0, v0, size):
        k = len(child)
        child.append([-1] * 4)
        value.append([0.0] * 4)
        h = size / 2
        for i, (du, dv) in enumerate(((0, 0), (h, 0), (0, h), (h, h))):
            a, b = u0 + du, v0 + dv
            inside = (leaves[:, 0] >= a - 1e-15) & (leaves[:, 0] < a + h - 1e-15) & \
                     (leaves[:, 1] >= b - 1e-15) & (leaves[:, 1] < b + h - 1e-15)
            if np.isclose(leaves[inside, 2], h).all() and inside.sum() == 1:
                value[k][i] = float(leaves[inside, 3][0])
            else:
                c = node(a, b, h)
                child[k][i] = c
                value[k][i] = float(np.sum(value[c]))
        return k

    node(0.0, 0.0, 1.0)
    return np.array(child, np.int32), np.array(value), 0


def to_uv(d):
    return (d[:, 2] + 1) / 2, (np.arctan2(d[:, 1], d[:, 0]) + math.pi) / (2 * math.pi)


def twin_pdf(leaves, d):
    """Density by containment: the leaf's energy share over its solid angle 4 pi size^2."""
    u, v = to_uv(d)
    inside = (u[:, None] >= leaves[None, :, 0]) & (u[:, None] < leaves[None, :, 0] + leaves[None, :, 2]) & \
             (v[:, None] >= leaves[None, :, 1]) & (v[:, None] < leaves[None, :, 1] + leaves[None, :, 2])
    k = np.argmax(inside, axis=1)
    share = leaves[k, 3] / leaves[:, 3].sum()
    return share / (4 * math.pi * leaves[k, 2] ** 2)


def random_dirs(rng, n):
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pdf_equals_the_twins_containment_density(seed):
    """At 20,000 random directions the tree's density equals the twin's energy share over solid
    angle (detects a quadrant numbered the other way, a level's factor 4 lost, the u/v halves
    swapped, the projection not area-preserving)."""
    rng = np.random.default_rng(seed)
    leaves = random_leaves(rng, max_depth=9)
    child, value, root = to_arrays(leaves)
    d = random_dirs(rng, 20_000)
    np.testing.assert_allclose(qt_pdf_batch(child, value, root, d), twin_pdf(leaves, d), rtol=1e-10)


def test_sampling_matches_its_density_chi_square():
    """Directions drawn from an irregular tree (depth up to 5, empty leaves; 400,000 samples)
    follow the twin's distribution: chi-square over the 64 x 64 squares of the (u, v) projection
    (area-preserving, so a leaf's share spreads evenly over the squares it covers: the expected
    counts are exact); each sample's density is the one qt_pdf gives and is never zero (no sample
    in an empty leaf). Detects a wrong branch probability, a uniform drawn badly inside a leaf (a
    leaf covers at least 2 x 2 squares), a quadrant numbered the other way."""
    rng = np.random.default_rng(7)
    leaves = random_leaves(rng, max_depth=5)
    child, value, root = to_arrays(leaves)
    n, r = 400_000, 64
    d, p = qt_sample_batch(child, value, root, np.random.default_rng(3).random((n, 2)))
    u, v = to_uv(d)
    observed = np.bincount(np.minimum((u * r).astype(int), r - 1) * r + np.minimum((v * r).astype(int), r - 1),
                           minlength=r * r).astype(float)
    expected = np.zeros((r, r))
    for u0, v0, size, e in leaves:
        a, b, k = int(round(u0 * r)), int(round(v0 * r)), int(round(size * r))
        expected[a:a + k, b:b + k] += e / leaves[:, 3].sum() / (k * k) * n
    ok, msg = histogram_test(observed, expected.ravel())
    assert ok, msg
    u = rng.random((50_000, 2))
    u[:4] = [[0.0, 0.0], [1 - 1e-16, 1 - 1e-16], [1e-300, 0.5], [0.5, 1 - 1e-16]]
    d, p = qt_sample_batch(child, value, root, u)
    assert (p > 0).all() and np.isfinite(d).all()
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(qt_pdf_batch(child, value, root, d), p, rtol=1e-12)
    assert (twin_pdf(leaves, d) > 0).all()


def twin_refine(leaves, rho, max_depth):
    """PPG's rebuild, by recursion over squares: a quadrant splits while it holds more than rho of
    the energy (and is above max_depth); a former leaf's energy is shared evenly by its parts."""
    total = leaves[:, 3].sum()
    out = []

    def energy(u0, v0, size):
        """The square's energy: its leaves inside, or its share of the leaf that contains it."""
        inside = (leaves[:, 0] >= u0 - 1e-15) & (leaves[:, 0] + leaves[:, 2] <= u0 + size + 1e-15) & \
                 (leaves[:, 1] >= v0 - 1e-15) & (leaves[:, 1] + leaves[:, 2] <= v0 + size + 1e-15)
        if inside.any():
            return leaves[inside, 3].sum()
        k = np.flatnonzero((leaves[:, 0] <= u0) & (leaves[:, 0] + leaves[:, 2] >= u0 + size) &
                           (leaves[:, 1] <= v0) & (leaves[:, 1] + leaves[:, 2] >= v0 + size))[0]
        return leaves[k, 3] * (size / leaves[k, 2]) ** 2

    def visit(u0, v0, size, depth):
        h = size / 2
        for du, dv in ((0, 0), (h, 0), (0, h), (h, h)):
            e = energy(u0 + du, v0 + dv, h)
            if e > rho * total and depth < max_depth:
                visit(u0 + du, v0 + dv, h, depth + 1)
            else:
                out.append([u0 + du, v0 + dv, h, e])

    visit(0.0, 0.0, 1.0, 1)
    return np.array(out)


def leaves_of(child, value, root):
    """The leaves of a flat tree as (u0, v0, size, energy), sorted."""
    out = []

    def walk(n, u0, v0, size):
        h = size / 2
        for i, (du, dv) in enumerate(((0, 0), (h, 0), (0, h), (h, h))):
            if child[n, i] >= 0:
                walk(child[n, i], u0 + du, v0 + dv, h)
            else:
                out.append([u0 + du, v0 + dv, h, value[n, i]])

    walk(root, 0.0, 0.0, 1.0)
    a = np.array(out)
    return a[np.lexsort((a[:, 2], a[:, 1], a[:, 0]))]


@pytest.mark.parametrize("rho,max_depth", [(0.01, 20), (0.05, 5)])
def test_splat_sums_and_refine_match_the_twin(rho, max_depth):
    """Records splatted into a tree (nearest leaf), summed and refined give the leaves the twin's
    recursion gives: the same squares (split at more than rho of the energy, no deeper than
    max_depth; a hot former leaf splits over several levels at once) with the same energies."""
    rng = np.random.default_rng(11)
    leaves = random_leaves(rng, max_depth=5)
    leaves[:, 3] = 0.0
    child, value, root = to_arrays(leaves)
    value[:] = 0.0
    d = random_dirs(rng, 5000)
    d[:2000] = np.array([0.3, -0.2, 0.93]) / np.linalg.norm([0.3, -0.2, 0.93])  # a hot spot
    e = rng.gamma(1.0, size=5000)
    roots = np.full(5000, root, np.int64)
    roots[::7] = -1  # records without a tree are skipped
    splat(child, value, roots, d, e)
    e[::7] = 0.0
    sums(child, value, root)
    u, v = to_uv(d)
    for L in leaves:  # the twin's leaf energies, by containment
        inside = (u >= L[0]) & (u < L[0] + L[2]) & (v >= L[1]) & (v < L[1] + L[2])
        L[3] = e[inside].sum()
    np.testing.assert_allclose(leaves_of(child, value, root), leaves[np.lexsort((leaves[:, 2], leaves[:, 1],
                                                                                 leaves[:, 0]))], rtol=1e-10)
    assert value[root].sum() == pytest.approx(e.sum(), rel=1e-12)
    c2, v2 = refine(child, value, root, rho, max_depth, 1 << 16)
    want = twin_refine(leaves, rho, max_depth)
    got = leaves_of(c2, v2, 0)
    want = want[np.lexsort((want[:, 2], want[:, 1], want[:, 0]))]
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    assert got[:, 2].min() >= 0.5 ** max_depth


def test_box_splat_shares_each_record_by_overlap_as_the_twin_does():
    """The box filter: each record's energy is shared among the leaves that a square of its own
    leaf's size, centred on it and clipped to the unit square, overlaps, in proportion to the
    overlap area (the twin: rectangle intersections with every leaf square). Detects a box of the
    wrong size or centre, a missed or double-counted leaf, energy lost at the square's edges, and
    a quadrant index with u and v swapped (the hot spot sits off the diagonal)."""
    rng = np.random.default_rng(5)
    leaves = random_leaves(rng, max_depth=6)
    child, value, root = to_arrays(leaves)
    value[:] = 0.0
    n = 3000
    d = random_dirs(rng, n)
    d[:500] = np.array([0.3, -0.2, 0.93]) / np.linalg.norm([0.3, -0.2, 0.93])
    d[500:520] = [0.0, 0.0, 1.0]  # u = 1: the square clipped at the edge
    e = rng.gamma(1.0, size=n)
    roots = np.full(n, root, np.int64)
    roots[::11] = -1
    splat_box(child, value, roots, d, e)
    sums(child, value, root)
    e[::11] = 0.0
    u, v = to_uv(d)
    want = np.zeros(len(leaves))
    for k in range(n):
        mine = (u[k] >= leaves[:, 0]) & (u[k] < leaves[:, 0] + leaves[:, 2]) & \
               (v[k] >= leaves[:, 1]) & (v[k] < leaves[:, 1] + leaves[:, 2])
        if not mine.any():  # u or v exactly 1: the last leaf along that side
            uk, vk = min(u[k], 1 - 1e-15), min(v[k], 1 - 1e-15)
            mine = (uk >= leaves[:, 0]) & (uk < leaves[:, 0] + leaves[:, 2]) & \
                   (vk >= leaves[:, 1]) & (vk < leaves[:, 1] + leaves[:, 2])
        h = leaves[np.argmax(mine), 2] / 2
        a0, a1, b0, b1 = max(u[k] - h, 0), min(u[k] + h, 1), max(v[k] - h, 0), min(v[k] + h, 1)
        ou = np.clip(np.minimum(a1, leaves[:, 0] + leaves[:, 2]) - np.maximum(a0, leaves[:, 0]), 0, None)
        ov = np.clip(np.minimum(b1, leaves[:, 1] + leaves[:, 2]) - np.maximum(b0, leaves[:, 1]), 0, None)
        want += e[k] * ou * ov / ((a1 - a0) * (b1 - b0))
    leaves[:, 3] = want
    np.testing.assert_allclose(leaves_of(child, value, root), leaves[np.lexsort((leaves[:, 2], leaves[:, 1],
                                                                                 leaves[:, 0]))], rtol=1e-9, atol=1e-12)
    assert value[root].sum() == pytest.approx(e.sum(), rel=1e-12)


def test_an_empty_tree_refines_to_the_uniform_tree():
    """A tree without energy becomes the uniform tree of UNIFORM_DEPTH levels (PPG's start): 4^4
    leaves of one size, density 1 / (4 pi) everywhere, and every sample drawn from it uniform."""
    child = np.full((1, 4), -1, np.int32)
    value = np.zeros((1, 4))
    c, v = refine(child, value, 0, 0.01, 20, 1 << 16)
    got = leaves_of(c, v, 0)
    assert len(got) == 4 ** UNIFORM_DEPTH and np.allclose(got[:, 2], 0.5 ** UNIFORM_DEPTH)
    d = random_dirs(np.random.default_rng(0), 1000)
    np.testing.assert_allclose(qt_pdf_batch(c, v, 0, d), 1 / (4 * math.pi), rtol=1e-12)
