"""Practical Path Guiding's SD-tree: a spatial binary tree whose leaves each hold directional
quadtrees (tracer.guiding.quadtree), learned over the iterations of a render.

The spatial tree covers the scene's bounding box made a cube. A node splits at its middle, its
children cycling through the axes x, y, z (as GuideState's trees: `child` is the left child, the
right one follows it; a point with x[axis] >= split goes right). Each leaf keeps two D-trees in
two pools: the *sampling* tree (what guides the current iteration) and the *building* tree (what
the iteration's records fill), and the number of records it received (`weight`).

Between iterations (`step`):
1. build: the building trees' interior values are summed; they become the sampling trees;
2. refine space: a leaf whose weight exceeds `threshold` splits, its children copying its trees and
   each taking half its weight, until no leaf exceeds it (PPG: threshold = c sqrt(2^k spp / 4));
3. reset: each leaf's next building tree is refined from its sampling tree by energy (quadtree.
   refine: quadrants above rho of the energy split) with its values zeroed, and the weights start
   again from 0.

`export()` gives the arrays a GuideState needs for the spatial tree and the sampling pool.

Filters (Müller's 2019 notes), both off by default: `spatial_filter` "stochastic" moves each record
by a uniform offset within a box the size of its leaf before it is located (a record near a
leaf's face may land in the neighbour), `directional_filter` "box" shares a record's energy over
the quadtree leaves that a square the size of its own leaf overlaps (quadtree.splat_box).
"""
import numpy as np

from .._jit import jit
from .quadtree import MAX_DEPTH, refine, splat, splat_box, sums


@jit
def locate_points(child, axis, split, x):
    """Leaf node of every point x (m, 3) (points outside the cube go to the nearest leaf)."""
    out = np.empty(x.shape[0], np.int64)
    for k in range(x.shape[0]):
        n = 0
        while child[n] >= 0:
            a = axis[n]
            n = child[n] + (1 if x[k, a] >= split[n] else 0)
        out[k] = n
    return out


def _pool(trees):
    """One pool (child, value, roots) from a list of (child, value) trees rooted at their node 0."""
    sizes = np.array([c.shape[0] for c, _ in trees], np.int64)
    offs = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    child = np.concatenate([np.where(c >= 0, c + o, -1) for (c, _), o in zip(trees, offs)]).astype(np.int32)
    value = np.concatenate([v for _, v in trees])
    return child, value, offs.astype(np.int64)


def _tree(child, value, root):
    """The tree at `root` of a pool as its own arrays (rooted at node 0), in breadth-first order."""
    order = [root]
    i = 0
    while i < len(order):
        order.extend(int(c) for c in child[order[i]] if c >= 0)
        i += 1
    order = np.array(order, np.int64)
    remap = np.full(child.shape[0], -1, np.int64)
    remap[order] = np.arange(order.size)
    c = child[order]
    return np.where(c >= 0, remap[np.maximum(c, 0)], -1).astype(np.int32), value[order].copy()


class SDTree:
    """The SD-tree of one render (see the module docstring)."""

    def __init__(self, lo, hi, rho=0.01, max_depth=MAX_DEPTH, max_nodes=1 << 16, spatial_filter="nearest",
                 directional_filter="nearest", seed=0):
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        self.spatial_filter, self.directional_filter = spatial_filter, directional_filter
        self._rng = np.random.default_rng(seed)
        side = float(np.max(hi - lo))
        self.lo, self.side = lo, max(side, 1e-12)
        self.rho, self.max_depth, self.max_nodes = float(rho), int(max_depth), int(max_nodes)
        self.child = np.full(1, -1, np.int32)
        self.axis = np.zeros(1, np.int32)
        self.split = np.zeros(1)
        self.box_lo = self.lo[None].copy()
        self.depth = np.zeros(1, np.int64)
        empty = (np.full((1, 4), -1, np.int32), np.zeros((1, 4)))
        uniform = refine(empty[0], empty[1], 0, self.rho, self.max_depth, self.max_nodes)
        # per node (meaningful at leaves): its sampling and building trees, its record weight
        self.sampling = [empty]
        self.building = [(uniform[0], np.zeros_like(uniform[1]))]
        self.weight = np.zeros(1)
        self._pool = None

    @property
    def leaves(self):
        return np.flatnonzero(self.child < 0)

    def locate(self, x):
        return locate_points(self.child, self.axis, self.split, np.ascontiguousarray(x, dtype=np.float64))

    def leaf_size(self, nodes):
        """Edge lengths (m, 3) of the boxes of `nodes` (axes x, y, z split in turn from the root)."""
        d = self.depth[nodes][:, None]
        return self.side * 0.5 ** ((d + 2 - np.arange(3)[None, :]) // 3)

    def record(self, x, dirs, energy):
        """Splat records: points x (m, 3), directions dirs (m, 3), energy (m,) into the building
        trees of their leaves (after the filters); each record adds 1 to its leaf's weight."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        if self.spatial_filter == "stochastic" and x.shape[0]:
            x = x + (self._rng.random(x.shape) - 0.5) * self.leaf_size(self.locate(x))
            x = np.clip(x, self.lo, self.lo + self.side)
        leaf = self.locate(x)
        if self._pool is None:
            self._pool = _pool([self.building[i] if self.child[i] < 0 else (np.full((1, 4), -1, np.int32),
                                                                            np.zeros((1, 4)))
                                for i in range(self.child.size)])
        child, value, roots = self._pool
        fn = splat_box if self.directional_filter == "box" else splat
        fn(child, value, roots[leaf], np.ascontiguousarray(dirs, dtype=np.float64),
           np.ascontiguousarray(energy, dtype=np.float64))
        self.weight += np.bincount(leaf, minlength=self.child.size)

    def _unpool(self):
        if self._pool is not None:
            child, value, roots = self._pool
            for i in self.leaves:
                self.building[i] = _tree(child, value, roots[i])
            self._pool = None

    def step(self, threshold):
        """End of an iteration: build, refine space above `threshold` records, reset (see above)."""
        self._unpool()
        for i in self.leaves:
            c, v = self.building[i]
            sums(c, v, 0)
            self.sampling[i] = (c, v)
        stack = list(self.leaves)
        while stack:
            i = stack.pop()
            if self.weight[i] > threshold:
                stack.extend(self._subdivide(i))
        for i in self.leaves:
            c, v = self.sampling[i]
            nc, nv = refine(c, v, 0, self.rho, self.max_depth, self.max_nodes)
            self.building[i] = (nc, np.zeros_like(nv))
        self.weight[:] = 0.0

    def _subdivide(self, i):
        """Split leaf i at its middle; its children copy its trees and take half its weight each."""
        n = self.child.size
        a = int(self.depth[i] % 3)
        size = self.side * 0.5 ** (self.depth[i] // 3)
        self.child[i], self.axis[i] = n, a
        self.split[i] = self.box_lo[i, a] + 0.5 * size
        right = self.box_lo[i].copy()
        right[a] += 0.5 * size
        self.child = np.append(self.child, [-1, -1]).astype(np.int32)
        self.axis = np.append(self.axis, [0, 0]).astype(np.int32)
        self.split = np.append(self.split, [0.0, 0.0])
        self.box_lo = np.vstack([self.box_lo, self.box_lo[i], right])
        self.depth = np.append(self.depth, [self.depth[i] + 1] * 2)
        self.weight = np.append(self.weight, [0.5 * self.weight[i]] * 2)
        self.sampling += [self.sampling[i]] * 2  # the trees are not changed in place: shared
        self.building += [self.building[i]] * 2
        return [n, n + 1]

    def export(self, empty_uniform=False):
        """(child, axis, split, slot, qt_child, qt_value, qt_root): the spatial tree with each
        node's sampling tree (slot, -1 at inner nodes, and at leaves whose tree holds no energy
        unless empty_uniform: those then sample the uniform density 1 / 4 pi, as the reference's
        empty trees) and the pool of those trees, for a GuideState."""
        uniform = (np.full((1, 4), -1, np.int32), np.ones((1, 4)))
        leaves = [i for i in self.leaves if empty_uniform or self.sampling[i][1][0].sum() > 0.0]
        slot = np.full(self.child.size, -1, np.int32)
        slot[leaves] = np.arange(len(leaves), dtype=np.int32)
        trees = [self.sampling[i] if self.sampling[i][1][0].sum() > 0.0 else uniform for i in leaves]
        trees = trees or [(np.full((1, 4), -1, np.int32), np.zeros((1, 4)))]
        qc, qv, roots = _pool(trees)
        return self.child.copy(), self.axis.copy(), self.split.copy(), slot, qc, qv, roots.astype(np.int32)
