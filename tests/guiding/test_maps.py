"""Directional maps, their sampling tables, the reconstruction filters and the hierarchical grid."""
import math

import numpy as np
import pytest

from tracer.testing.chi2 import histogram_test
from tracer.testing.stats import assert_z
from tracer.errors import SettingsError
from tracer.guiding.directional import bin_of_batch, build_tables, map_pdf_batch, map_sample_batch, probabilities
from tracer.guiding.grid.reconstruct import make_reconstructor
from tracer.guiding.grid.spatial import HierarchicalGrid

H, W = 8, 16


def test_bins_round_trip_and_cover_equal_solid_angles():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(200_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    counts = np.bincount(bin_of_batch(d, H, W), minlength=H * W)
    # uniform directions fill equal-area bins equally
    passed, msg = histogram_test(counts, np.full(H * W, d.shape[0] / (H * W)))
    assert passed, msg


def test_fast_bins_are_the_atan2_bins():
    """direction_bin's fast atan2 never moves a direction to another column than libm's atan2:
    random directions, the axes (signed zeros included) and points 1e-9 of a bin from its edges."""
    rng = np.random.default_rng(4)
    d = rng.normal(size=(500_000, 3))
    axes = np.array([[1, 0, 0], [-1, 0, 0], [-1, -0.0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1],
                     [1, 1, 0], [-1, 1, 0], [-1, -1, 0], [1, -1, 0]], float)
    phi = -np.pi + 2 * np.pi * np.repeat(np.arange(W + 1), 3) / W + np.tile([-1e-9, 0.0, 1e-9], W + 1)
    edges = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=1)
    d = np.concatenate([d / np.linalg.norm(d, axis=1, keepdims=True), axes / np.linalg.norm(axes, axis=1, keepdims=True), edges])
    row = np.clip(((d[:, 2] + 1) * 0.5 * H).astype(np.int64), 0, H - 1)
    col = np.clip(((np.array([math.atan2(y, x) for x, y in d[:, :2]]) + np.pi) * (0.5 / np.pi) * W).astype(np.int64), 0, W - 1)
    np.testing.assert_array_equal(bin_of_batch(d, H, W), row * W + col)


def test_sampling_table_realises_the_map():
    rng = np.random.default_rng(1)
    maps = rng.random((5, H, W)) ** 4
    maps[1, :, :5] = 0.0
    maps[2] = 0.0
    maps[3, 2, 3] = 1e6  # one dominant bin
    maps[4, 3] = 0.0  # an empty row
    tabs = build_tables(maps)
    prob = probabilities(tabs)
    usable = tabs.usable
    assert list(usable) == [True, True, False, True, True]
    # the sampler realises w / W exactly: bin k owns the integers [C_k, C_k + w_k) of [0, W), C the
    # weights before it; a u0 at the first and at the last integer of every bin lands in that bin
    for s in np.flatnonzero(usable):
        w = tabs.dens[s].astype(np.int64)
        Wt = int(tabs.wsum[s])
        assert Wt == int(w.sum())
        np.testing.assert_array_equal(tabs.rowcum[s], np.concatenate([[0], np.cumsum(w.reshape(H, W).sum(1))]))
        C = np.concatenate([[0], np.cumsum(w)[:-1]])
        k = np.flatnonzero(w > 0)
        for first in (True, False):
            j = C[k] if first else C[k] + w[k] - 1
            u = np.stack([(j + 0.5) / Wt, np.full(k.size, 0.5)], axis=1)
            d, p = map_sample_batch(tabs, s, H, W, u)
            np.testing.assert_array_equal(bin_of_batch(d, H, W), k)
            np.testing.assert_allclose(p, w[k] / Wt * H * W / (4 * np.pi), rtol=1e-12)
    # quantised to 16 bits of the largest bin
    target = maps.reshape(5, -1) / np.maximum(maps.reshape(5, -1).sum(axis=1, keepdims=True), 1e-300)
    err = np.abs(prob - target)[usable]
    assert (err <= 2.0 / 65535 * target[usable].max(axis=1, keepdims=True)).all(), err.max()
    assert (prob[1].reshape(H, W)[:, :5] == 0).all() and (prob[2] == 0).all()
    # sampling frequencies per bin match prob (chi-square), and the pdf matches the bin
    u = rng.random((400_000, 2))
    for slot in (0, 1, 3):
        d, p = map_sample_batch(tabs, slot, H, W, u)
        b = bin_of_batch(d, H, W)
        passed, msg = histogram_test(np.bincount(b, minlength=H * W), prob[slot] * u.shape[0], ntests=3)
        assert passed, msg
        np.testing.assert_allclose(p, prob[slot, b] * H * W / (4 * np.pi), rtol=1e-12)
        np.testing.assert_allclose(map_pdf_batch(tabs, slot, H, W, d), p, rtol=1e-12)


def test_gaussian_keeps_mass_and_pullpush_fills_holes():
    rng = np.random.default_rng(2)
    maps = np.zeros((3, 32, 64), np.float32)
    maps[:, 5, 7] = 1.0
    maps[:, 31, 63] = 2.0  # at a pole and at the phi seam
    counts = (maps > 0).astype(np.float32)
    g = make_reconstructor("gaussian", sigma=1.5).reconstruct(maps, counts, counts > 0)
    np.testing.assert_allclose(g.sum(axis=(1, 2)), maps.sum(axis=(1, 2)), rtol=1e-5)
    assert g[0, 31, 0] > 0  # wrapped across the seam
    noisy = rng.random((2, 32, 64)).astype(np.float32)
    mask = rng.random((2, 32, 64)) < 0.3
    pp = make_reconstructor("pullpush", levels=4).reconstruct(np.where(mask, noisy, 0), mask.astype(np.float32), mask)
    np.testing.assert_allclose(pp[mask], noisy[mask], rtol=1e-6)  # data kept
    assert (pp[~mask] > 0).all()  # holes filled
    with pytest.raises(SettingsError, match="valid: cnn, gaussian, none, pullpush"):
        make_reconstructor("median")


@pytest.mark.parametrize("n_class", [1, 6])
def test_grid_lookup_matches_the_boxes_after_splits(n_class):
    rng = np.random.default_rng(3)
    g = HierarchicalGrid(np.zeros(3), np.array([4.0, 2.0, 3.0]), 6, 4, 8, n_class)
    pts = rng.random((20_000 * n_class, 3)) * [4.0, 2.0, 3.0]  # as many per tree either way
    nrm = rng.normal(size=pts.shape)
    g.visit(g.locate(pts, nrm), 0)
    n_med = g.split_median(pts, threshold=300, max_levels=3, normals=nrm)
    g.node_count[:] = 1e9  # everything over the threshold: mid-plane splits, 3 levels at most
    depth0 = g.depth[: g.n_nodes].copy()
    n_mid = g.split_mid(threshold=10, max_levels=3)
    assert n_med > 0 and n_mid > 0
    assert g.depth[: g.n_nodes].max() <= depth0.max() + 3
    leaf = g.locate(pts, nrm)
    assert (g.child[leaf] < 0).all()
    lo, hi = g.box_lo[leaf], g.box_hi[leaf]
    assert ((pts >= lo - 1e-12) & (pts <= hi + 1e-12)).all()
    # every leaf that had data kept a slot (split children inherit); slots are distinct
    slots = g.data_slot[g.leaves()]
    used = slots[slots >= 0]
    assert used.size == np.unique(used).size and used.size > 0
    assert g.locate(np.array([[-1.0, 0.5, 0.5], [2.0, 9.0, 1.0]]), nrm[:2]).tolist() == [-1, -1]
    # the tree a point descends is the one of its cell and of its normal's class (axis, sign)
    root = leaf.copy()
    parent = np.full(g.n_nodes, -1)
    inner = np.flatnonzero(g.child[: g.n_nodes] >= 0)
    parent[g.child[inner]] = inner
    parent[g.child[inner] + 1] = inner
    while (parent[root] >= 0).any():
        root = np.where(parent[root] >= 0, parent[root], root)
    ax = np.argmax(np.abs(nrm), axis=1)
    cls = 2 * ax + (nrm[np.arange(len(ax)), ax] < 0) if n_class == 6 else 0
    ijk = np.floor((pts - g.lo) / g.side).astype(int)
    cell = (ijk[:, 2] * g.res[1] + ijk[:, 1]) * g.res[0] + ijk[:, 0]
    assert (root == cell * n_class + cls).all()


def _split_median_one_leaf_at_a_time(g, points, threshold, max_levels, normals):
    """The slow twin of HierarchicalGrid.split_median: a leaf at a time, depth first, np.median."""
    nodes = g.locate(points, normals)
    todo = [(nd, points[nodes == nd], 0) for nd in np.unique(nodes[nodes >= 0])
            if (nodes == nd).sum() > threshold and g.data_slot[nd] >= 0]
    while todo:
        nd, pts, lvl = todo.pop()
        a = int(g.depth[nd] % 3)
        lo, hi = g.box_lo[nd, a], g.box_hi[nd, a]
        v = float(np.median(pts[:, a]))
        right = pts[:, a] >= v
        if not (lo < v < hi) or right.all() or not right.any():
            v = 0.5 * (lo + hi)
            right = pts[:, a] >= v
        c = int(g._split(np.array([nd]), np.array([v]))[0])
        g.node_count[c], g.node_count[c + 1] = (~right).sum(), right.sum()
        if lvl + 1 < max_levels:
            todo += [(j, sub, lvl + 1) for j, sub in ((c, pts[~right]), (c + 1, pts[right])) if len(sub) > threshold]


def _leaf_table(g):
    """The leaves as sorted rows (box corners, count, has a slot): the tree's shape whatever its
    node numbering."""
    leaves = g.leaves()
    rows = np.column_stack([g.box_lo[leaves], g.box_hi[leaves], g.node_count[leaves], g.data_slot[leaves] >= 0])
    return rows[np.lexsort(rows.T[::-1])]


@pytest.mark.parametrize("levels", [1, 3])
def test_median_splits_in_batches_match_one_leaf_at_a_time(levels):
    """split_median splits a level's leaves in one batch; the tree it builds has the leaves (boxes,
    counts, slots) of the leaf-at-a-time twin, on clustered points, a cell whose points all
    coincide (the mid-plane fallback), ties on the median and an even count's mean. Detects a
    wrong median (e.g. the upper middle point of an even count), a missed fallback, wrong counts
    handed to the children, or a level too many or too few."""
    rng = np.random.default_rng(5)
    box = np.array([4.0, 2.0, 3.0])
    pts = np.concatenate([rng.random((6000, 3)) * box, 0.4 + 0.05 * rng.random((6000, 3)),  # a cluster
                          np.tile([[1.3269, 1.5, 1.5]], (3000, 1)),  # coincident at their cell's low x: fallback
                          np.round(rng.random((2000, 3)) * box, 1)])  # ties
    nrm = rng.normal(size=pts.shape)
    grids = [HierarchicalGrid(np.zeros(3), box, 4, 4, 8, 6) for _ in range(2)]
    unvisited = rng.random(pts.shape[0]) < 0.1  # some leaves hold points but no slot
    for g in grids:
        g.visit(g.locate(pts[~unvisited], nrm[~unvisited]), 0)
    n = grids[0].split_median(pts, threshold=100, max_levels=levels, normals=nrm)
    _split_median_one_leaf_at_a_time(grids[1], pts, 100, levels, nrm)
    assert n > 6 * levels and n == (grids[1].n_nodes - grids[1].n_cells) // 2
    np.testing.assert_array_equal(_leaf_table(grids[0]), _leaf_table(grids[1]))
    assert grids[0].depth[: grids[0].n_nodes].max() == levels


def test_mid_plane_splits_pass_each_voxels_data_to_its_children():
    """split_mid splits a level at a time in batches: every leaf whose count c exceeds the
    threshold T becomes 2^L leaves, L = min(max_levels, the least k with c / 2^k <= T), that tile
    its box, each with its histogram, counts and statistics divided by 2^L (halving is exact in
    binary floating point, so they are compared exactly) and its map flag; leaves at or below
    T keep theirs; freed slots are taken before new rows. Detects a child that loses or doubles its
    parent's data, a wrong split count or level, a child box outside its parent's, a slot shared by
    two leaves (a freed slot handed out twice), and freed slots left unused."""
    rng = np.random.default_rng(7)
    g = HierarchicalGrid(np.zeros(3), np.ones(3), 3, 4, 8)
    g.visit(g.locate(rng.random((4000, 3))), 0)
    leaves0 = g.leaves()
    leaves0 = leaves0[g.data_slot[leaves0] >= 0]
    slots0 = g.data_slot[leaves0]
    g.power[slots0] = rng.random((slots0.size, g.K)).astype(np.float32)
    g.count[slots0] = rng.integers(0, 9, (slots0.size, g.K)).astype(np.float32)
    counts = rng.choice([3.0, 10.0, 25.0, 70.0, 500.0], leaves0.size)
    g.node_count[leaves0] = counts
    g.out_sum[leaves0] = rng.random(leaves0.size)
    g.map_ok[leaves0] = rng.random(leaves0.size) < 0.5
    freed = leaves0[counts == 3.0][:5]  # their slots go to the free list, for the splits to reuse
    g.release(freed)
    keep = ~np.isin(leaves0, freed)
    leaves0, counts = leaves0[keep], counts[keep]
    slots_before = g.n_slots
    before = {int(nd): (g.power[g.data_slot[nd]].copy(), g.count[g.data_slot[nd]].copy(), g.out_sum[nd],
                        bool(g.map_ok[nd]), g.box_lo[nd].copy(), g.box_hi[nd].copy()) for nd in leaves0}
    T, levels = 12.0, 3
    expect_levels = [0 if c <= T else min(levels, int(np.ceil(np.log2(c / T)))) for c in counts]
    n_split = g.split_mid(T, levels)
    assert n_split == sum(2 ** L - 1 for L in expect_levels) and n_split > freed.size > 0
    assert g.n_slots == slots_before + n_split - freed.size  # each split takes a slot, freed ones first
    parent = np.full(g.n_nodes, -1)
    inner = np.flatnonzero(g.child[: g.n_nodes] >= 0)
    parent[g.child[inner]] = inner
    parent[g.child[inner] + 1] = inner
    leaves = g.leaves()
    root = leaves.copy()
    while (parent[root] >= 0).any():
        root = np.where(parent[root] >= 0, parent[root], root)
    slots = g.data_slot[leaves[np.isin(root, leaves0)]]
    assert (slots >= 0).all() and np.unique(slots).size == slots.size
    for nd, L in zip(leaves0, expect_levels):
        kids = leaves[root == nd]
        p, c, o, ok, lo, hi = before[int(nd)]
        assert kids.size == 2 ** L
        np.testing.assert_array_equal(g.power[g.data_slot[kids]], np.tile(p / 2 ** L, (kids.size, 1)))
        np.testing.assert_array_equal(g.count[g.data_slot[kids]], np.tile(c / 2 ** L, (kids.size, 1)))
        assert (g.out_sum[kids] == o / 2 ** L).all()
        assert (g.map_ok[kids] == ok).all() and (g.depth[kids] == g.depth[nd] + L).all()
        assert (g.box_lo[kids] >= lo).all() and (g.box_hi[kids] <= hi).all()
        assert np.isclose(np.prod(g.box_hi[kids] - g.box_lo[kids], axis=1).sum(), np.prod(hi - lo))


def test_grid_recycles_unvisited_voxels():
    g = HierarchicalGrid(np.zeros(3), np.ones(3), 4, 4, 8)
    pts = np.random.default_rng(4).random((1000, 3))
    g.visit(g.locate(pts[:500]), 0)
    n0 = g.slots_in_use().size
    g.visit(g.locate(pts[:10]), 1)
    g.visit(g.locate(pts[:10]), 2)
    freed = g.recycle(2, after=2)
    assert freed > 0 and g.slots_in_use().size == n0 - freed
    g.visit(g.locate(pts[500:]), 3)  # freed slots are reused
    assert g.n_slots <= n0 + g.slots_in_use().size


def test_grid_records_estimate_radiance_times_cosine_per_bin():
    """The `grid` guide's data: a record adds radiance |cos| / pdf to the bin of its direction
    (cos to its facing normal), so a bin's mean over N records estimates the integral of L |cos|
    over the bin. Uniform directions on the sphere (pdf 1 / 4 pi) under L = 1 with the normal +z:
    every bin's mean is z-tested against the integral of |z| over the bin, 2 pi / n_phi |z1^2 -
    z0^2| / 2 for a row [z0, z1]; the sum over bins against 2 pi."""
    from tracer.guiding.records import Records

    rng = np.random.default_rng(11)
    n = 200_000
    g = HierarchicalGrid(np.zeros(3), np.ones(3), 1, H, W)
    g.visit(np.zeros(1, np.int64), 0)
    rec = Records.allocate(n)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rec.wi[:] = d
    rec.n[:] = (0.0, 0.0, 1.0)
    rec.x[:] = 0.5
    rec.pdf[:] = 1.0 / (4.0 * math.pi)
    rec.radiance[:] = 1.0
    rec.strategy[:] = 0
    rec.node[:] = 0
    g.splat_records(rec)
    s = g.data_slot[0]
    bins = bin_of_batch(d, H, W)
    val = np.abs(d[:, 2]) * 4.0 * math.pi
    # the slow twin: the same sums by NumPy
    assert np.allclose(g.power[s], np.bincount(bins, weights=val, minlength=H * W), rtol=1e-5)
    assert np.array_equal(g.count[s], np.bincount(bins, minlength=H * W))
    z = np.linspace(-1.0, 1.0, H + 1)
    exact = np.repeat(np.abs(z[1:] * np.abs(z[1:]) - z[:-1] * np.abs(z[:-1])) / 2.0 * 2.0 * math.pi / W, W)
    mean = g.power[s] / n
    var = np.array([np.var(np.where(bins == k, val, 0.0)) for k in range(H * W)]) / n
    assert_z(mean, var, exact, what="bin integral of L |cos|")
    assert_z(mean.sum(), np.var(val) / n, 2.0 * math.pi, what="integral of L |cos| over the sphere")
