"""A pure-Numba BVH over a triangle soup: binned-SAH build, stack traversal, float64 hits.

Layout (pbrt's LinearBVHNode, flattened to arrays, nodes numbered depth first):
    nodes   (N, 8) float64  per node: min corner (3), max corner (3), offset, count; one cache
                            line each. Interior (count 0): the first child is node + 1, offset is
                            the second child. Leaf: triangles order[offset : offset + count].
    order   (F,) int32      leaf position -> original triangle index
    tri_pre (F, 3, 3)       per leaf position, float64: v0, e1 = v1 - v0, e2 = v2 - v0

The build bins centroids into N_BINS slabs along each axis and takes the split of least surface
area heuristic cost; where no such split exists (all centroids equal, or deeper than SAH_DEPTH)
it splits at the object median. Hits use the Moller-Trumbore test in float64, two-sided,
accepting 0 < t < tmax.
"""
import numpy as np
import numba

from tracer._jit import jit, kernel
from tracer.bvh import _bounds, _check_rays, _check_tri

MAX_LEAF = 4          # most triangles in a leaf
N_BINS = 32           # SAH bins over the centroid bounds, per axis
TRAVERSAL_COST = 1.0  # SAH cost of visiting a node, relative to one triangle test
STACK_SIZE = 64       # traversal stack entries (one per tree level is enough)
SAH_DEPTH = 32        # deeper than this, nodes split at the object median: depth < 32 + 31
RAYS_PER_TASK = 256   # rays one prange iteration traces with one stack
_BOX_SLACK = 1.0 + 1e-12  # widens the slab test against rounding (pbrt's 1 + 2 gamma(3))


# ---------------------------------------------------------------- build

@jit
def _area(lo, hi):
    """Surface area of the box [lo, hi] (0 for an empty box)."""
    dx = hi[0] - lo[0]
    dy = hi[1] - lo[1]
    dz = hi[2] - lo[2]
    if dx < 0.0 or dy < 0.0 or dz < 0.0:
        return 0.0
    return 2.0 * (dx * dy + dy * dz + dz * dx)


@jit
def _bin_of(c, cmin, scale):
    """SAH bin of centroid coordinate c; the same formula for binning and partitioning."""
    b = int((c - cmin) * scale)
    if b >= N_BINS:
        b = N_BINS - 1
    if b < 0:
        b = 0
    return b


@jit
def _build(lo, hi, cen):
    """Build the BVH from triangle boxes lo, hi and centroids cen, each (F, 3) float64, F >= 1.

    Returns node_bounds (N, 2, 3), node_offset (N,), node_count (N,), order (F,) and depth
    (levels below the root); see the module docstring.
    """
    n_tri = lo.shape[0]
    order = np.arange(n_tri).astype(np.int32)
    max_nodes = 2 * n_tri - 1
    node_bounds = np.empty((max_nodes, 2, 3))
    node_offset = np.zeros(max_nodes, np.int32)
    node_count = np.zeros(max_nodes, np.int32)

    bin_count = np.zeros(N_BINS, np.int64)
    bin_lo = np.empty((N_BINS, 3))
    bin_hi = np.empty((N_BINS, 3))
    right_area = np.empty(N_BINS)
    right_count = np.empty(N_BINS, np.int64)
    acc_lo = np.empty(3)
    acc_hi = np.empty(3)
    box_lo = np.empty(3)
    box_hi = np.empty(3)
    cmin = np.empty(3)
    cmax = np.empty(3)

    # Work stack of (start, end, parent_to_link, depth): children are pushed second-then-first,
    # so nodes are numbered depth first and a first child is always its parent + 1; a second
    # child writes its own index into its parent's offset.
    work = np.empty((256, 4), np.int64)
    work[0, 0] = 0
    work[0, 1] = n_tri
    work[0, 2] = -1
    work[0, 3] = 0
    n_work = 1
    n_nodes = 0
    max_depth = 0
    for _ in range(max_nodes):
        if n_work == 0:
            break
        n_work -= 1
        start = work[n_work, 0]
        end = work[n_work, 1]
        parent = work[n_work, 2]
        depth = work[n_work, 3]
        node = n_nodes
        n_nodes += 1
        if parent >= 0:
            node_offset[parent] = node
        if depth > max_depth:
            max_depth = depth

        # Bounds of the triangles and of their centroids.
        for a in range(3):
            box_lo[a] = np.inf
            box_hi[a] = -np.inf
            cmin[a] = np.inf
            cmax[a] = -np.inf
        for k in range(start, end):
            i = order[k]
            for a in range(3):
                box_lo[a] = min(box_lo[a], lo[i, a])
                box_hi[a] = max(box_hi[a], hi[i, a])
                cmin[a] = min(cmin[a], cen[i, a])
                cmax[a] = max(cmax[a], cen[i, a])
        for a in range(3):
            node_bounds[node, 0, a] = box_lo[a]
            node_bounds[node, 1, a] = box_hi[a]
        count = end - start

        # Best binned-SAH split over all three axes.
        best_cost = np.inf
        best_axis = -1
        best_bin = -1
        node_area = _area(box_lo, box_hi)
        if count > 1 and depth < SAH_DEPTH and node_area > 0.0:
            for a in range(3):
                extent = cmax[a] - cmin[a]
                if not extent > 0.0:
                    continue
                scale = N_BINS / extent
                for b in range(N_BINS):
                    bin_count[b] = 0
                    for c in range(3):
                        bin_lo[b, c] = np.inf
                        bin_hi[b, c] = -np.inf
                for k in range(start, end):
                    i = order[k]
                    b = _bin_of(cen[i, a], cmin[a], scale)
                    bin_count[b] += 1
                    for c in range(3):
                        bin_lo[b, c] = min(bin_lo[b, c], lo[i, c])
                        bin_hi[b, c] = max(bin_hi[b, c], hi[i, c])
                # Sweep from the right: right_*[s] describe bins s..N_BINS-1.
                for c in range(3):
                    acc_lo[c] = np.inf
                    acc_hi[c] = -np.inf
                n_right = 0
                for s in range(N_BINS - 1, 0, -1):
                    n_right += bin_count[s]
                    for c in range(3):
                        acc_lo[c] = min(acc_lo[c], bin_lo[s, c])
                        acc_hi[c] = max(acc_hi[c], bin_hi[s, c])
                    right_count[s] = n_right
                    right_area[s] = _area(acc_lo, acc_hi)
                # Sweep from the left and cost each split "bins < s | bins >= s".
                for c in range(3):
                    acc_lo[c] = np.inf
                    acc_hi[c] = -np.inf
                n_left = 0
                for s in range(1, N_BINS):
                    n_left += bin_count[s - 1]
                    for c in range(3):
                        acc_lo[c] = min(acc_lo[c], bin_lo[s - 1, c])
                        acc_hi[c] = max(acc_hi[c], bin_hi[s - 1, c])
                    if n_left == 0 or right_count[s] == 0:
                        continue
                    cost = TRAVERSAL_COST + (
                        n_left * _area(acc_lo, acc_hi) + right_count[s] * right_area[s]
                    ) / node_area
                    if cost < best_cost:
                        best_cost = cost
                        best_axis = a
                        best_bin = s

        # A leaf when small enough and no split pays off.
        if count <= MAX_LEAF and (best_axis < 0 or count <= best_cost):
            node_offset[node] = start
            node_count[node] = count
            continue

        if best_axis >= 0:
            # Partition order[start:end] by SAH bin.
            scale = N_BINS / (cmax[best_axis] - cmin[best_axis])
            i0 = start
            i1 = end - 1
            for _k in range(count):
                if i0 > i1:
                    break
                if _bin_of(cen[order[i0], best_axis], cmin[best_axis], scale) < best_bin:
                    i0 += 1
                else:
                    tmp = order[i0]
                    order[i0] = order[i1]
                    order[i1] = tmp
                    i1 -= 1
            mid = i0
        else:
            # No SAH split (all centroids equal, zero-area node, or too deep): object median.
            axis = 0
            for a in range(1, 3):
                if cmax[a] - cmin[a] > cmax[axis] - cmin[axis]:
                    axis = a
            if cmax[axis] > cmin[axis]:
                keys = np.empty(count)
                for k in range(count):
                    keys[k] = cen[order[start + k], axis]
                perm = np.argsort(keys, kind="mergesort")
                seg = order[start:end].copy()
                for k in range(count):
                    order[start + k] = seg[perm[k]]
            mid = (start + end) // 2
        if mid <= start or mid >= end:  # cannot happen; keeps both children non-empty
            mid = (start + end) // 2

        node_count[node] = 0
        work[n_work, 0] = mid
        work[n_work, 1] = end
        work[n_work, 2] = node
        work[n_work, 3] = depth + 1
        work[n_work + 1, 0] = start
        work[n_work + 1, 1] = mid
        work[n_work + 1, 2] = -1
        work[n_work + 1, 3] = depth + 1
        n_work += 2

    return (node_bounds[:n_nodes].copy(), node_offset[:n_nodes].copy(),
            node_count[:n_nodes].copy(), order, max_depth)


# ---------------------------------------------------------------- traversal

@jit
def _hit_box(nodes, c, ox, oy, oz, ix, iy, iz, sx, sy, sz, tfar):
    """Entry distance of the ray o + t d, 0 <= t <= tfar, into node c's box; inf on a miss.

    ix, iy, iz: 1/d (inf for a zero component); sx, sy, sz: 1 where that inverse is negative
    (the near plane is the max corner), else 0. NaN slab distances (0 * inf, origin on the
    plane) are ignored, which keeps the test conservative.
    """
    tn = 0.0
    tf = tfar
    t0 = (nodes[c, 3 * sx] - ox) * ix
    t1 = (nodes[c, 3 - 3 * sx] - ox) * ix
    if t0 > tn:
        tn = t0
    if t1 < tf:
        tf = t1
    t0 = (nodes[c, 1 + 3 * sy] - oy) * iy
    t1 = (nodes[c, 4 - 3 * sy] - oy) * iy
    if t0 > tn:
        tn = t0
    if t1 < tf:
        tf = t1
    t0 = (nodes[c, 2 + 3 * sz] - oz) * iz
    t1 = (nodes[c, 5 - 3 * sz] - oz) * iz
    if t0 > tn:
        tn = t0
    if t1 < tf:
        tf = t1
    if tn <= tf * _BOX_SLACK:
        return tn
    return np.inf


@jit
def _hit_tri(pre, k, ox, oy, oz, dx, dy, dz):
    """Moller-Trumbore test of the ray against triangle tri_pre[k]: (t, b1, b2), t = inf on a
    miss (parallel ray or outside the triangle); t may be <= 0."""
    e1x = pre[k, 1, 0]
    e1y = pre[k, 1, 1]
    e1z = pre[k, 1, 2]
    e2x = pre[k, 2, 0]
    e2y = pre[k, 2, 1]
    e2z = pre[k, 2, 2]
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if not abs(det) > 0.0:
        return np.inf, 0.0, 0.0
    inv = 1.0 / det
    sx = ox - pre[k, 0, 0]
    sy = oy - pre[k, 0, 1]
    sz = oz - pre[k, 0, 2]
    b1 = (sx * px + sy * py + sz * pz) * inv
    if not (b1 >= 0.0 and b1 <= 1.0):
        return np.inf, 0.0, 0.0
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    b2 = (dx * qx + dy * qy + dz * qz) * inv
    if not (b2 >= 0.0 and b1 + b2 <= 1.0):
        return np.inf, 0.0, 0.0
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    return t, b1, b2


@jit
def _traverse(ox, oy, oz, dx, dy, dz, tmax, nodes, pre, any_hit, stack, stack_t):
    """Closest (or, with any_hit, the first found) triangle hit with 0 < t < tmax.

    Returns (t, k, b1, b2) with k the leaf position of the triangle, (inf, -1, 0, 0) on a miss.
    At an interior node both children's boxes are tested; the nearer is visited first and the
    other pushed with its entry distance, and popped only if still nearer than the best hit.
    """
    best_t = np.inf
    best_k = -1
    best_b1 = 0.0
    best_b2 = 0.0
    finite = ox + oy + oz + dx + dy + dz
    if not (finite - finite == 0.0) or (dx == 0.0 and dy == 0.0 and dz == 0.0):
        return best_t, best_k, best_b1, best_b2  # NaN or inf in the ray, or no direction
    ix = 1.0 / dx
    iy = 1.0 / dy
    iz = 1.0 / dz
    sx = 1 if ix < 0.0 else 0
    sy = 1 if iy < 0.0 else 0
    sz = 1 if iz < 0.0 else 0
    limit = tmax  # hits must be nearer than this
    if _hit_box(nodes, 0, ox, oy, oz, ix, iy, iz, sx, sy, sz, limit) == np.inf:
        return best_t, best_k, best_b1, best_b2
    sp = 0
    node = 0
    for _ in range(nodes.shape[0]):  # each node is visited at most once
        n = int(nodes[node, 7])
        if n > 0:
            # Leaf: test its triangles.
            first = int(nodes[node, 6])
            for k in range(first, first + n):
                t, b1, b2 = _hit_tri(pre, k, ox, oy, oz, dx, dy, dz)
                if t > 0.0 and t < limit:
                    limit = t
                    best_t = t
                    best_k = k
                    best_b1 = b1
                    best_b2 = b2
                    if any_hit:
                        return best_t, best_k, best_b1, best_b2
        else:
            # Interior: go to the nearer child that is hit, push the other.
            c0 = node + 1
            c1 = int(nodes[node, 6])
            t0 = _hit_box(nodes, c0, ox, oy, oz, ix, iy, iz, sx, sy, sz, limit)
            t1 = _hit_box(nodes, c1, ox, oy, oz, ix, iy, iz, sx, sy, sz, limit)
            if t0 < np.inf:
                if t1 < np.inf:
                    if t1 < t0:
                        stack[sp] = c0
                        stack_t[sp] = t0
                        node = c1
                    else:
                        stack[sp] = c1
                        stack_t[sp] = t1
                        node = c0
                    sp += 1
                else:
                    node = c0
                continue
            if t1 < np.inf:
                node = c1
                continue
        # Pop the nearest pending node that may still hold a nearer hit.
        node = -1
        while sp > 0:
            sp -= 1
            if stack_t[sp] <= limit * _BOX_SLACK:
                node = stack[sp]
                break
        if node < 0:
            break
    return best_t, best_k, best_b1, best_b2


@kernel
def _intersect_batch(org, dirs, tmax, nodes, pre, order, t, prim, b1, b2):
    """Closest hits of n rays into t, prim, b1, b2; tmax is (n,) or (0,) for no limit."""
    n = org.shape[0]
    has_tmax = tmax.shape[0] == n
    n_tasks = (n + RAYS_PER_TASK - 1) // RAYS_PER_TASK
    for task in numba.prange(n_tasks):
        stack = np.empty(STACK_SIZE, np.int64)
        stack_t = np.empty(STACK_SIZE)
        for i in range(task * RAYS_PER_TASK, min(n, (task + 1) * RAYS_PER_TASK)):
            tm = tmax[i] if has_tmax else np.inf
            th, k, u, v = _traverse(org[i, 0], org[i, 1], org[i, 2], dirs[i, 0], dirs[i, 1],
                                    dirs[i, 2], tm, nodes, pre, False, stack, stack_t)
            t[i] = th
            prim[i] = order[k] if k >= 0 else -1
            b1[i] = u
            b2[i] = v


@kernel
def _occluded_batch(org, dirs, tmax, nodes, pre, out):
    """Any-hit of n rays with 0 < t < tmax[i] into out (n,) bool."""
    n = org.shape[0]
    n_tasks = (n + RAYS_PER_TASK - 1) // RAYS_PER_TASK
    for task in numba.prange(n_tasks):
        stack = np.empty(STACK_SIZE, np.int64)
        stack_t = np.empty(STACK_SIZE)
        for i in range(task * RAYS_PER_TASK, min(n, (task + 1) * RAYS_PER_TASK)):
            k = _traverse(org[i, 0], org[i, 1], org[i, 2], dirs[i, 0], dirs[i, 1], dirs[i, 2],
                          tmax[i], nodes, pre, True, stack, stack_t)[1]
            out[i] = k >= 0


def _pack_nodes(node_bounds, node_offset, node_count):
    """Nodes as one (N, 8) float64 array, 64-byte aligned (one cache line per node):
    min corner, max corner, offset, count (offsets and counts are exact in float64)."""
    n = len(node_bounds)
    buf = np.empty(n * 8 + 8)
    skip = (-buf.ctypes.data % 64) // 8
    nodes = buf[skip:skip + n * 8].reshape(n, 8)
    nodes[:, 0:3] = node_bounds[:, 0]
    nodes[:, 3:6] = node_bounds[:, 1]
    nodes[:, 6] = node_offset
    nodes[:, 7] = node_count
    return nodes


class _NumbaThreads:
    """Context manager running Numba's parallel kernels on `n` threads, then restoring."""

    def __init__(self, n):
        self.n = n

    def __enter__(self):
        self.saved = numba.get_num_threads()
        if self.n != self.saved:
            numba.set_num_threads(self.n)

    def __exit__(self, *exc):
        if self.n != self.saved:
            numba.set_num_threads(self.saved)


class NumbaBVH:
    """Binned-SAH BVH over triangles `tri` (F, 3, 3) float64, traversed by Numba kernels.

    threads: how many Numba threads a batch query uses (default: Numba's current count).
    Attributes: nodes (N, 8), order (F,), tri_pre (F, 3, 3), depth (see the module docstring).
    """

    name = "numba"

    def __init__(self, tri, threads=None):
        tri = _check_tri(tri)
        self.n_triangles = len(tri)
        self.bounds, self.scale = _bounds(tri)
        self.centre = self.bounds.mean(axis=0)
        limit = numba.config.NUMBA_NUM_THREADS
        self.threads = max(1, min(int(threads), limit) if threads else numba.get_num_threads())
        self.depth = 0
        self.nodes = np.zeros((0, 8))
        self.order = np.zeros(0, np.int32)
        self.tri_pre = np.zeros((0, 3, 3))
        if self.n_triangles == 0:
            return
        lo = tri.min(axis=1)
        hi = tri.max(axis=1)
        cen = tri.mean(axis=1)
        # Triangles with NaN/inf vertices can never be hit: keep their boxes out of the tree's.
        bad = ~np.isfinite(tri).all(axis=(1, 2))
        if bad.any():
            lo[bad] = np.inf
            hi[bad] = -np.inf
            cen[bad] = self.bounds.mean(axis=0)
        node_bounds, node_offset, node_count, self.order, self.depth = _build(lo, hi, cen)
        if self.depth >= STACK_SIZE:
            raise RuntimeError(f"BVH depth {self.depth} exceeds the traversal stack")
        self.nodes = _pack_nodes(node_bounds, node_offset, node_count)
        v = tri[self.order]
        self.tri_pre = np.ascontiguousarray(
            np.stack([v[:, 0], v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]], axis=1))

    def intersect(self, org, dirs, tmax=None):
        """Closest hits: (t, prim, b1, b2), see `tracer.bvh`."""
        org, dirs, tmax = _check_rays(org, dirs, tmax)
        n = org.shape[0]
        if n == 0 or self.n_triangles == 0:
            return np.full(n, np.inf), np.full(n, -1, np.int32), np.zeros(n), np.zeros(n)
        t = np.empty(n)
        prim = np.empty(n, np.int32)
        b1 = np.empty(n)
        b2 = np.empty(n)
        with _NumbaThreads(self.threads):
            _intersect_batch(org, dirs, np.empty(0) if tmax is None else tmax,
                             self.nodes, self.tri_pre, self.order, t, prim, b1, b2)
        return t, prim, b1, b2

    def occluded(self, org, dirs, tmax):
        """(n,) bool: True where some triangle is hit with 0 < t < tmax."""
        org, dirs, tmax = _check_rays(org, dirs, tmax, need_tmax=True)
        n = org.shape[0]
        out = np.zeros(n, np.bool_)
        if n == 0 or self.n_triangles == 0:
            return out
        with _NumbaThreads(self.threads):
            _occluded_batch(org, dirs, tmax, self.nodes, self.tri_pre, out)
        return out

    def __repr__(self):
        return (f"NumbaBVH(name='numba', triangles={self.n_triangles}, nodes={len(self.nodes)}, "
                f"depth={self.depth}, threads={self.threads}, scale={self.scale:.4g})")
