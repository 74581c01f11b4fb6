"""Practical Path Guiding's SD-tree (tracer.guiding.sdtree): the spatial tree tiles the cube and
locates points in their boxes; leaves split as PPG's rule says (halving their weight until it is at
most the threshold); records land in the directional leaf that holds them, per spatial leaf."""
import math

import numpy as np

from tests.guiding.test_quadtree import leaves_of, random_dirs, to_uv
from tracer.guiding.quadtree import UNIFORM_DEPTH, qt_pdf_batch
from tracer.guiding.sdtree import SDTree


def _boxes(t):
    """Each leaf's box (lo, size per axis), from the split planes: computed here by walking down."""
    out = {}

    def walk(n, lo, size):
        if t.child[n] < 0:
            out[n] = (lo, size)
            return
        a = t.axis[n]
        half = size.copy()
        half[a] = size[a] / 2
        assert math.isclose(t.split[n], lo[a] + half[a])  # the middle of the box
        walk(t.child[n], lo, half)
        right = lo.copy()
        right[a] += half[a]
        walk(t.child[n] + 1, right, half)

    walk(0, t.lo.copy(), np.full(3, t.side))
    return out


def test_space_splits_by_ppgs_rule_and_tiles_the_cube():
    """20,000 records, a quarter of them in one corner: after a step with threshold 1000 every leaf
    that had weight w > 1000 became 2^ceil(log2(w / 1000)) leaves (PPG halves the weight per split),
    the leaves tile the cube (volumes sum to it), and every point is located in its leaf's box."""
    rng = np.random.default_rng(0)
    t = SDTree(np.zeros(3), np.array([2.0, 1.0, 1.0]))
    x = rng.random((20_000, 3)) * [2.0, 2.0, 2.0]
    x[:5000] *= 0.1
    t.record(x, random_dirs(rng, 20_000), np.ones(20_000))
    assert t.weight.sum() == 20_000 and t.leaves.tolist() == [0]
    t.step(1000.0)
    assert len(t.leaves) == 2 ** math.ceil(math.log2(20_000 / 1000))
    # a second iteration: only the corner's leaves are above the threshold
    x2 = rng.random((8000, 3)) * 0.2
    before = {int(i): float(w) for i, w in zip(t.leaves, np.bincount(t.locate(x2), minlength=t.child.size)[t.leaves])}
    t.record(x2, random_dirs(rng, 8000), np.ones(8000))
    n_before = len(t.leaves)
    t.step(1000.0)
    want = sum(2 ** math.ceil(math.log2(w / 1000)) if w > 1000 else 1 for w in before.values())
    assert len(t.leaves) == want and want > n_before
    boxes = _boxes(t)
    assert math.isclose(sum(np.prod(s) for _, s in boxes.values()), 8.0)
    leaves = np.array(sorted(boxes))
    np.testing.assert_allclose(t.leaf_size(leaves), [boxes[int(i)][1] for i in leaves])
    pts = rng.random((5000, 3)) * 2.0
    for p, leaf in zip(pts, t.locate(pts)):
        lo, size = boxes[int(leaf)]
        assert np.all(p >= lo) and np.all(p <= lo + size)


def test_records_become_the_next_iterations_sampling_trees():
    """Records (energy, direction) splatted in iteration 0 fill the uniform depth-4 building tree;
    after the step each leaf's exported sampling tree holds, in each 1/16 x 1/16 square, the energy of
    that leaf's records whose direction falls there (counted here), its density is energy share over
    solid angle; a split leaf's children both keep its tree; a tree without records has no map
(slot -1)."""
    rng = np.random.default_rng(1)
    t = SDTree(np.zeros(3), np.ones(3))
    x = rng.random((6000, 3))
    x[:, 0] *= 0.5  # nothing in x >= 0.5
    d = random_dirs(rng, 6000)
    d[:2000] = [0.0, 0.6, 0.8]
    e = rng.gamma(1.0, size=6000)
    t.record(x, d, e)
    t.step(4000.0)  # 6000 > 4000: one split along x
    child, axis, split, slot, qc, qv, roots = t.export()
    assert list(t.leaves) == [1, 2] and slot[0] == -1 and slot[1] >= 0 and slot[2] >= 0
    got = leaves_of(qc, qv, roots[slot[1]])
    np.testing.assert_array_equal(leaves_of(qc, qv, roots[slot[2]]), got)  # a split copies the parent's tree
    r = 2 ** UNIFORM_DEPTH
    assert len(got) == r * r
    u, v = to_uv(d)
    counts = np.zeros((r, r))
    np.add.at(counts, (np.minimum((u * r).astype(int), r - 1), np.minimum((v * r).astype(int), r - 1)), e)
    mine = np.zeros((r, r))
    mine[np.round(got[:, 0] * r).astype(int), np.round(got[:, 1] * r).astype(int)] = got[:, 3]
    np.testing.assert_allclose(mine, counts, rtol=1e-9)
    probe = random_dirs(rng, 500)
    pu, pv = to_uv(probe)
    share = counts[np.minimum((pu * r).astype(int), r - 1), np.minimum((pv * r).astype(int), r - 1)] / e.sum()
    np.testing.assert_allclose(qt_pdf_batch(qc, qv, roots[slot[1]], probe), share * r * r / (4 * np.pi), rtol=1e-9)
    # the next building tree refines the hot direction's square (a third of the energy > rho)
    nc, nv = t.building[1]
    assert leaves_of(nc, np.ones_like(nv), 0)[:, 2].min() < 0.5 ** UNIFORM_DEPTH and not nv.any()
    assert (SDTree(np.zeros(3), np.ones(3)).export()[3] == -1).all()  # no records yet: no map anywhere


def test_the_stochastic_spatial_filter_moves_records_within_their_leafs_box():
    """With spatial_filter "stochastic" a record lands where a uniform offset within a box of its
    leaf's size takes it: from x = 0.45 in the left half (box 0.5 wide along x), 40% land in the
    right leaf (a binomial z-test at 4 sigma over 20,000 records; no filter gives 0%, a box of the
    cube's size 45%, one of half the size 30%); the nearest filter moves nothing."""
    rng = np.random.default_rng(2)
    for f in ("stochastic", "nearest"):
        t = SDTree(np.zeros(3), np.ones(3), spatial_filter=f, seed=7)
        t.record(rng.random((6000, 3)), random_dirs(rng, 6000), np.ones(6000))
        t.step(4000.0)  # one split along x at 0.5
        assert t.leaves.tolist() == [1, 2] and t.split[0] == 0.5
        m = 20_000
        t.record(np.tile([0.45, 0.5, 0.98], (m, 1)), random_dirs(rng, m), np.ones(m))
        share = t.weight[2] / m
        if f == "nearest":
            assert share == 0.0
        else:
            assert abs(share - 0.4) < 4 * math.sqrt(0.4 * 0.6 / m), share
        assert t.weight.sum() == m
