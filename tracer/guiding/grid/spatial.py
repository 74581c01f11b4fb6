"""The hierarchical grid of section 7.1: the spatial structure of the histogram guides (its state,
as the kernels read it, is guiding.contract.GuideState).

Space is a uniform grid of cubic cells over the bounds that the pilot pass's camera paths
reach; every cell is the root of a small binary tree whose leaves are the voxels. All nodes
live in flat arrays (node i of cell c is c itself for the roots; children are appended in
pairs, the right one right after the left one), so a lookup is O(1) for the cell plus a short
descent. A voxel holds a data slot (its histogram: power and counts per direction bin) only
while camera paths visit it, and a sampling map (weights and row sums, see `directional`) once its data
is reconstructed. Slots are recycled when a voxel goes unvisited for two iterations.

Splits alternate x, y, z with the depth below the cell. `split_median` splits at the median of
the points it is given (the initialisation phase, while points are kept), `split_mid` at the
middle plane (later iterations); a split's children inherit the parent's data halved, its map
and its mixing weight, and must be visited again to stay in use.
"""
import numpy as np
from numba import prange

from ..._jit import jit, kernel
from ..contract import GuideState, locate_batch, no_pixel_maps
from ..directional import direction_bin


@jit
def accumulate(node, bins, value, node_slot, power, count, node_count):
    """Histogram entries (node, bin, value) into the data slots of their nodes; entries whose node
    has no slot are dropped. Sequential: entries may share a bin."""
    kept = 0
    for i in range(node.shape[0]):
        nd = node[i]
        if nd < 0:
            continue
        s = node_slot[nd]
        if s < 0:
            continue
        power[s, bins[i]] += value[i]
        count[s, bins[i]] += 1.0
        node_count[nd] += 1.0
        kept += 1
    return kept


@jit
def _visit_records(node, strategy, iteration, last_visit, data_slot, missing):
    """Mark the leaves of the records (strategy >= 0) visited in `iteration`, and in `missing` those
    without a data slot. Returns the number of records."""
    n = 0
    for i in range(node.shape[0]):
        if strategy[i] < 0:
            continue
        n += 1
        nd = node[i]
        if nd < 0:
            continue
        last_visit[nd] = iteration
        if data_slot[nd] < 0:
            missing[nd] = True
    return n


@jit
def _splat_records(node, strategy, wi, n, pdf, radiance, n_theta, n_phi, data_slot, power, count, node_count):
    """radiance |cos| / pdf of every record into its leaf's histogram, in the bin of its direction
    (cos to the record's facing normal n: the map learns incident radiance times the cosine, the
    part of the integrand a diffuse vertex shares with the map, as photon maps do)."""
    for i in range(node.shape[0]):
        nd = node[i]
        if strategy[i] < 0 or nd < 0:
            continue
        s = data_slot[nd]
        if s < 0:
            continue
        b = direction_bin((float(wi[i, 0]), float(wi[i, 1]), float(wi[i, 2])), n_theta, n_phi)
        p = float(pdf[i])
        c = abs(float(wi[i, 0]) * n[i, 0] + float(wi[i, 1]) * n[i, 1] + float(wi[i, 2]) * n[i, 2])
        power[s, b] += radiance[i] * c / p if p > 0.0 else 0.0
        count[s, b] += 1.0
        node_count[nd] += 1.0


@jit
def _splat_importance(node, strategy, prev, x, n_theta, n_phi, data_slot, ipower):
    """For guided light tracing: every record whose path came from a recorded vertex adds 1 to
    its leaf's importance histogram, in the bin of the direction back to that vertex (where a
    photon leaving this voxel meets the camera vertices that queried a map)."""
    for i in range(node.shape[0]):
        nd = node[i]
        j = prev[i]
        if strategy[i] < 0 or nd < 0 or j < 0 or strategy[j] < 0:
            continue
        s = data_slot[nd]
        if s < 0:
            continue
        d0 = float(x[j, 0]) - float(x[i, 0])
        d1 = float(x[j, 1]) - float(x[i, 1])
        d2 = float(x[j, 2]) - float(x[i, 2])
        ln = (d0 * d0 + d1 * d1 + d2 * d2) ** 0.5
        if not ln > 0.0:
            continue
        ipower[s, direction_bin((d0 / ln, d1 / ln, d2 / ln), n_theta, n_phi)] += 1.0


# per data slot: histogram, counts, previous map and counts, sampling tables; the same for importance maps
SLOT_ARRAYS = ("power", "count", "prev", "pcount", "rowcum", "dens", "wsum", "pscale", "ipower", "irowcum", "idens", "iwsum",
               "ipscale")


@kernel
def _median_plan(points, node, todo, box_lo, box_hi, depth, threshold, max_levels):
    """The median splits of HierarchicalGrid.split_median, planned without touching the grid, the
    leaves `todo` in parallel (node: each point's leaf). Each leaf's splits form a heap (entry 1 the
    leaf, entries 2h and 2h + 1 the sides of entry h): an entry splits its points at their median
    along its depth's axis (at the mid-plane where the median leaves a side empty or lies on the
    box's face), and a side holding more than threshold points is an entry of the next level, up to
    max_levels levels. Returns, per leaf and heap entry: whether it splits, the plane, and the
    points left and right of it."""
    k = todo.shape[0]
    which = np.full(box_lo.shape[0], -1, np.int64)
    for i in range(k):
        which[todo[i]] = i
    start = np.zeros(k + 1, np.int64)
    for j in range(node.shape[0]):
        if node[j] >= 0 and which[node[j]] >= 0:
            start[which[node[j]] + 1] += 1
    for i in range(k):
        start[i + 1] += start[i]
    fill = start[:k].copy()
    xyz = np.empty((start[k], 3))  # the points by leaf; each split moves its left side's rows first
    for j in range(node.shape[0]):
        if node[j] >= 0 and which[node[j]] >= 0:
            t = which[node[j]]
            xyz[fill[t]] = points[j]
            fill[t] += 1
    n_heap = 1 << max_levels
    split = np.zeros((k, n_heap), np.bool_)
    value = np.zeros((k, n_heap))
    n_left = np.zeros((k, n_heap))
    n_right = np.zeros((k, n_heap))
    seg = np.zeros((k, n_heap, 2), np.int64)
    lo = np.zeros((k, n_heap, 3))
    hi = np.zeros((k, n_heap, 3))
    coord = np.empty(start[k])
    for i in prange(k):
        split[i, 1] = True
        seg[i, 1, 0] = start[i]
        seg[i, 1, 1] = start[i + 1]
        lo[i, 1] = box_lo[todo[i]]
        hi[i, 1] = box_hi[todo[i]]
        for h in range(1, n_heap):
            if not split[i, h]:
                continue
            lvl = 0
            while (h >> (lvl + 1)) > 0:
                lvl += 1
            a = (depth[todo[i]] + lvl) % 3
            s0 = seg[i, h, 0]
            cnt = seg[i, h, 1] - s0
            for j in range(s0, s0 + cnt):
                coord[j] = xyz[j, a]
            v = np.median(coord[s0:s0 + cnt])
            nr = 0
            for j in range(s0, s0 + cnt):
                if coord[j] >= v:
                    nr += 1
            if not (lo[i, h, a] < v < hi[i, h, a]) or nr == cnt or nr == 0:
                v = 0.5 * (lo[i, h, a] + hi[i, h, a])
            nl = 0  # rows below v to the front, swapped in place
            for j in range(s0, s0 + cnt):
                if xyz[j, a] < v:
                    for c in range(3):
                        xyz[s0 + nl, c], xyz[j, c] = xyz[j, c], xyz[s0 + nl, c]
                    nl += 1
            value[i, h] = v
            n_left[i, h] = nl
            n_right[i, h] = cnt - nl
            if 2 * h < n_heap:
                for side in range(2):
                    c0 = s0 if side == 0 else s0 + nl
                    c1 = s0 + nl if side == 0 else s0 + cnt
                    if c1 - c0 > threshold:
                        ch = 2 * h + side
                        split[i, ch] = True
                        seg[i, ch, 0] = c0
                        seg[i, ch, 1] = c1
                        lo[i, ch] = lo[i, h]
                        hi[i, ch] = hi[i, h]
                        if side == 0:
                            hi[i, ch, a] = v
                        else:
                            lo[i, ch, a] = v
    return split, value, n_left, n_right


class HierarchicalGrid:
    """Uniform cells, each the root of a binary tree; data slots for the visited voxels."""

    def __init__(self, lo, hi, resolution, n_theta, n_phi, n_class=1, importance=False):
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        ext = np.maximum(hi - lo, 1e-9)
        side = float(np.linalg.norm(ext)) / float(resolution)
        res = np.maximum(np.ceil(ext / side - 1e-9).astype(np.int64), 1)
        centre = 0.5 * (lo + hi)
        self.lo = centre - 0.5 * res * side
        self.side = side
        self.res = res
        self.n_theta, self.n_phi = int(n_theta), int(n_phi)
        self.K = self.n_theta * self.n_phi
        if n_class not in (1, 6):
            raise ValueError(f"n_class must be 1 or 6, got {n_class!r}")
        self.n_class = int(n_class)
        self.n_cells = int(np.prod(res)) * self.n_class  # roots: (cell, normal class)
        self.n_nodes = self.n_cells
        cap = max(2 * self.n_cells, 64)
        self.child = np.full(cap, -1, np.int32)
        self.axis = np.zeros(cap, np.int32)
        self.split = np.zeros(cap)
        self.depth = np.zeros(cap, np.int32)
        self.box_lo = np.zeros((cap, 3))
        self.box_hi = np.zeros((cap, 3))
        cell = np.arange(self.n_cells) // self.n_class
        ijk = np.stack(np.unravel_index(cell, tuple(res[::-1]))[::-1], axis=1)  # (x, y, z)
        self.box_lo[: self.n_cells] = self.lo + ijk * side
        self.box_hi[: self.n_cells] = self.lo + (ijk + 1) * side
        self.node_count = np.zeros(cap)  # samples (photons or path vertices) binned, halved on a split
        self.last_visit = np.full(cap, -(1 << 30), np.int32)  # iteration of the last camera vertex
        self.alpha = np.full(cap, 0.5)
        self.mis_sum = np.zeros((cap, 2))  # sum of L_b per strategy (0 BSDF, 1 guide), eq. 14
        self.mis_n = np.zeros((cap, 2))
        self.out_sum = np.zeros(cap)  # sum of camera paths' outgoing radiance at the leaf (luminance)
        self.out_n = np.zeros(cap)  # how many of them (see outgoing())
        self.data_slot = np.full(cap, -1, np.int32)  # histogram slot of a leaf
        self.map_ok = np.zeros(cap, np.bool_)  # the slot's CDF is usable
        self.imap_ok = np.zeros(cap, np.bool_)  # the slot's importance map is usable (guided light tracing)
        scap = 64
        self.power = np.zeros((scap, self.K), np.float32)
        self.count = np.zeros((scap, self.K), np.float32)
        self.prev = np.zeros((scap, self.K), np.float32)  # the previous iteration's normalised map
        self.pcount = np.zeros((scap, self.K), np.float32)  # ... and its counts
        self.rowcum = np.zeros((scap, self.n_theta + 1), np.uint32)
        self.dens = np.zeros((scap, self.K), np.uint16)
        self.wsum = np.ones(scap)
        self.pscale = np.zeros(scap)
        # importance maps, for guided light tracing: histogram and sampling tables, as above (empty
        # rows without `importance`)
        self.importance = bool(importance)
        ki, ri = (self.K, self.n_theta + 1) if self.importance else (0, 0)
        self.ipower = np.zeros((scap, ki), np.float32)
        self.irowcum = np.zeros((scap, ri), np.uint32)
        self.idens = np.zeros((scap, ki), np.uint16)
        self.iwsum = np.ones(scap)
        self.ipscale = np.zeros(scap)
        self.slot_node = np.full(scap, -1, np.int64)
        self.free = []
        self.n_slots = 0

    # --- storage ---------------------------------------------------------------------------
    def _grow_nodes(self, need):
        cap = self.child.shape[0]
        if need <= cap:
            return
        new = max(need, 2 * cap)
        for name in ("child", "axis", "split", "depth", "box_lo", "box_hi", "node_count", "last_visit",
                     "alpha", "mis_sum", "mis_n", "out_sum", "out_n", "data_slot", "map_ok", "imap_ok"):
            a = getattr(self, name)
            fill = {"child": -1, "data_slot": -1, "last_visit": -(1 << 30), "alpha": 0.5}.get(name, 0)
            b = np.full((new,) + a.shape[1:], fill, a.dtype)
            b[:cap] = a
            setattr(self, name, b)

    def _new_slots(self, nodes):
        """Data slots (zeroed, no usable map) for these nodes: freed ones first, then new rows."""
        nodes = np.asarray(nodes, np.int64)
        k = nodes.size
        take = min(k, len(self.free))
        reused = [self.free.pop() for _ in range(take)]
        fresh = np.arange(self.n_slots, self.n_slots + k - take, dtype=np.int64)
        self.n_slots += k - take
        cap = self.power.shape[0]
        if self.n_slots > cap:
            new = max(self.n_slots, 2 * cap)
            for name in SLOT_ARRAYS + ("slot_node",):
                a = getattr(self, name)
                b = np.full((new,) + a.shape[1:], -1 if name == "slot_node" else 0, a.dtype)
                b[:cap] = a
                setattr(self, name, b)
        s = np.concatenate([np.asarray(reused, np.int64), fresh])
        for name in SLOT_ARRAYS:
            getattr(self, name)[s] = 1.0 if name in ("wsum", "iwsum") else 0
        self.slot_node[s] = nodes
        self.data_slot[nodes] = s
        self.map_ok[nodes] = False
        self.imap_ok[nodes] = False
        return s

    def release(self, nodes):
        """Free the data slots of these nodes (those without one are skipped)."""
        nodes = np.atleast_1d(np.asarray(nodes, np.int64))
        nodes = nodes[self.data_slot[nodes] >= 0]
        s = self.data_slot[nodes]
        self.slot_node[s] = -1
        self.free.extend(int(v) for v in s)
        self.data_slot[nodes] = -1
        self.map_ok[nodes] = False
        self.imap_ok[nodes] = False

    def leaves(self):
        n = self.n_nodes
        return np.flatnonzero(self.child[:n] < 0)

    def slots_in_use(self):
        return np.flatnonzero(self.slot_node[: self.n_slots] >= 0)

    def _require_importance(self):
        if not self.importance:
            raise ValueError("this grid keeps no importance maps (HierarchicalGrid(..., importance=True))")

    def memory_bytes(self):
        arrays = (self.child, self.axis, self.split, self.depth, self.box_lo, self.box_hi, self.node_count,
                  self.last_visit, self.alpha, self.mis_sum, self.mis_n, self.out_sum, self.out_n, self.data_slot, self.map_ok, self.imap_ok,
                  self.slot_node) + tuple(getattr(self, name) for name in SLOT_ARRAYS)
        return int(sum(a.nbytes for a in arrays))

    # --- what the kernels read ---------------------------------------------------------------
    def state(self, importance=False):
        """The arrays the kernels read: the tree and, per leaf, its sampling map (slot -1 where it has
        none usable); with `importance`, the importance maps (guided light tracing) instead."""
        if importance:
            self._require_importance()
        p = "i" if importance else ""
        n = self.n_nodes
        ok = self.imap_ok if importance else self.map_ok
        slot = np.where(ok[:n], self.data_slot[:n], -1).astype(np.int32)
        m = max(self.n_slots, 1)
        tables = [getattr(self, p + name)[:m] for name in ("rowcum", "dens", "wsum", "pscale")]
        return GuideState(self.lo.copy(), np.full(3, 1.0 / self.side), self.res.astype(np.int64),
                          self.child[:n], self.axis[:n], self.split[:n], slot, self.alpha[:n],
                          *tables, self.n_theta, self.n_phi, self.n_class, *no_pixel_maps())

    def lookup_state(self):
        """A state for locating points only (no maps)."""
        s = self.state()
        return s._replace(slot=np.full(self.n_nodes, -1, np.int32))

    def locate(self, x, n=None):
        """Leaves of points x (m, 3) with facing normals n (m, 3; may be left out with one class)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        if n is None:
            if self.n_class != 1:
                raise ValueError("locate needs the facing normals when voxels are split by normal class")
            n = np.zeros_like(x)
        return locate_batch(self.lookup_state(), x, np.ascontiguousarray(n, dtype=np.float64))

    # --- visits, slots ------------------------------------------------------------------------
    def visit(self, nodes, iteration):
        """Camera vertices landed in these leaves (-1: none): they are valid now (slots for new ones)."""
        self._visit(nodes, np.zeros(nodes.shape[0], np.int8), iteration)

    def visit_records(self, rec, iteration):
        """visit() for the leaves of a wave's records (a Records view); returns how many records."""
        return self._visit(rec.node, rec.strategy, iteration)

    def _visit(self, nodes, strategy, iteration):
        missing = np.zeros(self.n_nodes, np.bool_)
        n = _visit_records(nodes, strategy, iteration, self.last_visit, self.data_slot, missing)
        self._new_slots(np.flatnonzero(missing))
        return n

    def set_maps(self, slots, tabs, importance=False):
        """The sampling tables (directional.MapTables) of the maps in these data slots (with
        `importance`, of their importance maps)."""
        p = "i" if importance else ""
        for name in ("rowcum", "dens", "wsum", "pscale"):
            getattr(self, p + name)[slots] = getattr(tabs, name)
        (self.imap_ok if importance else self.map_ok)[self.slot_node[slots]] = tabs.usable

    def splat_importance(self, rec):
        """The records' directions back to their paths' previous vertices into the importance maps."""
        self._require_importance()
        _splat_importance(rec.node, rec.strategy, rec.prev, rec.x, self.n_theta, self.n_phi, self.data_slot,
                          self.ipower)

    def splat_records(self, rec):
        """Each record's radiance |cos| / pdf into its leaf's histogram (the `grid` guide's data)."""
        self.splat(rec.node, rec.wi, rec.n, rec.pdf, rec.radiance, rec.strategy)

    def splat(self, nodes, wi, n, pdf, radiance, strategy=None):
        """splat_records() for vertices given as arrays (leaves `nodes`, -1 for none); strategy < 0
        marks entries to skip (none by default)."""
        if strategy is None:
            strategy = np.zeros(len(nodes), np.int8)
        nodes = np.asarray(nodes, np.int32)  # as records hold them: one compiled signature
        _splat_records(nodes, strategy, wi, n, pdf, radiance, self.n_theta, self.n_phi, self.data_slot, self.power,
                       self.count, self.node_count)

    def recycle(self, iteration, after=2):
        """Release the slots of leaves that no camera vertex visited in the last `after` iterations."""
        n = self.n_nodes
        stale = np.flatnonzero((self.data_slot[:n] >= 0) & (self.last_visit[:n] <= iteration - after))
        self.release(stale)
        return stale.size

    # --- splits -----------------------------------------------------------------------------
    def _split(self, nodes, values):
        """Split the leaves `nodes` (distinct) at `values` on their depth's axis; returns their left
        children (the right one of each follows it). A child inherits the parent's counts and
        statistics halved, its visit, mixing weight and map; the left one takes the parent's data
        slot, the right one a copy of it (both with the histogram halved); the parent keeps none."""
        nodes = np.asarray(nodes, np.int64)
        k = nodes.size
        self._grow_nodes(self.n_nodes + 2 * k)
        a = self.depth[nodes] % 3
        c = self.n_nodes + 2 * np.arange(k, dtype=np.int64)
        self.n_nodes += 2 * k
        self.child[nodes] = c
        self.axis[nodes] = a
        self.split[nodes] = values
        for j in (c, c + 1):
            self.child[j] = -1
            self.depth[j] = self.depth[nodes] + 1
            self.box_lo[j] = self.box_lo[nodes]
            self.box_hi[j] = self.box_hi[nodes]
            self.last_visit[j] = self.last_visit[nodes]
            self.alpha[j] = self.alpha[nodes]
            for name in ("node_count", "mis_sum", "mis_n", "out_sum", "out_n"):
                arr = getattr(self, name)
                arr[j] = 0.5 * arr[nodes]
        self.box_hi[c, a] = values
        self.box_lo[c + 1, a] = values
        has = self.data_slot[nodes] >= 0
        par, left = nodes[has], c[has]
        s = self.data_slot[par].astype(np.int64)
        for name in ("power", "count", "pcount", "ipower"):
            getattr(self, name)[s] *= 0.5
        self.data_slot[par] = -1
        self.data_slot[left] = s
        self.slot_node[s] = left
        s2 = self._new_slots(left + 1)
        for name in SLOT_ARRAYS:
            arr = getattr(self, name)
            arr[s2] = arr[s]
        for ok in (self.map_ok, self.imap_ok):
            ok[left] = ok[left + 1] = ok[par]
            ok[par] = False
        return c

    def split_mid(self, threshold, max_levels=3):
        """Split every leaf with a slot whose count exceeds threshold at its middle plane, again in
        the children (counts halved) up to max_levels new levels; a level at a time, every leaf
        of it in one batch. Returns the number of splits."""
        leaves = self.leaves()
        todo = leaves[(self.data_slot[leaves] >= 0) & (self.node_count[leaves] > threshold)]
        n_split = 0
        for _ in range(max_levels):
            if todo.size == 0:
                break
            a = self.depth[todo] % 3
            c = self._split(todo, 0.5 * (self.box_lo[todo, a] + self.box_hi[todo, a]))
            n_split += todo.size
            kids = np.concatenate([c, c + 1])
            todo = kids[self.node_count[kids] > threshold]
        return n_split

    def split_median(self, points, threshold, max_levels=3, normals=None):
        """Initialisation phase: split leaves with slots that hold more than threshold of `points`
        (m, 3, with their facing `normals`) at the median point (middle plane where the median
        cannot separate them), again in the children that hold more than threshold, up to
        max_levels new levels. The planes come from one jitted pass over the points
        (`_median_plan`); the splits are made a level at a time, every leaf of it in one batch.
        Returns the number of splits."""
        points = np.ascontiguousarray(points, dtype=np.float64)
        node = self.locate(points, normals)
        n = self.n_nodes
        todo = np.flatnonzero((np.bincount(node[node >= 0], minlength=n) > threshold) & (self.data_slot[:n] >= 0))
        if todo.size == 0:
            return 0
        split, value, n_left, n_right = _median_plan(points, node, todo, self.box_lo[:n], self.box_hi[:n],
                                                     self.depth[:n], float(threshold), max(int(max_levels), 1))
        left = np.zeros(split.shape, np.int64)  # each heap entry's left child, once split
        h0 = 1
        while h0 < split.shape[1]:  # a level at a time: heap entries h0 .. 2 h0 - 1
            i, h = np.nonzero(split[:, h0:2 * h0])
            if i.size == 0:
                break
            h += h0
            nodes = todo[i] if h0 == 1 else left[i, h >> 1] + (h & 1)
            left[i, h] = c = self._split(nodes, value[i, h])
            self.node_count[c] = n_left[i, h]
            self.node_count[c + 1] = n_right[i, h]
            h0 *= 2
        return int(split.sum())

    # --- data -----------------------------------------------------------------------------------
    def accumulate(self, nodes, bins, values):
        return accumulate(np.ascontiguousarray(nodes, dtype=np.int64), np.ascontiguousarray(bins, dtype=np.int64),
                          np.ascontiguousarray(values, dtype=np.float64), self.data_slot[: self.n_nodes],
                          self.power, self.count, self.node_count[: self.n_nodes])
