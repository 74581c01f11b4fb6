"""Directional quadtrees (Practical Path Guiding's D-trees): adaptive, full-sphere, world-space.

A direction d maps to the unit square by the cylindrical (area-preserving) projection of
tracer.guiding.directional: u = (d.z + 1) / 2, v = (atan2(d.y, d.x) + pi) / (2 pi), so a region
of the square with area A covers the solid angle 4 pi A. A quadtree splits the square into four
equal quadrants per node: quadrant i = (u >= 1/2) + 2 (v >= 1/2) of a node, recursively.

A forest of trees lives in flat arrays (one node a row):

    child (Q, 4) int32    the node of quadrant i, or -1 where the quadrant is a leaf
    value (Q, 4) float64  the energy in quadrant i (for sampling: the sum over the quadrant's leaves)
    root  (T,) int32      the first node of each tree

Sampling picks a quadrant per level with probability value / sum of the node's values (first the
u-half, then the v-half within it, each with one of the two uniforms, rescaled), and places the
direction uniformly in the leaf's square with what is left of them. The density of direction d is
the product over the levels of 4 value[i] / sum(value), over 4 pi: piecewise constant per leaf.

qt_sample and qt_pdf are not inlined into the kernels that call them: inlined into every shading
kernel, their loops added about 100 s to the test suite's compiles.

Learning (PPG section 3.3): records splat their energy into the leaf holding their direction, each
into the tree of its spatial leaf (`splat`), or over the leaves a box of that leaf's size around it
overlaps (`splat_box`, the 2019 notes' directional filter); `refine` then builds the next tree from
the filled one, splitting every quadrant that holds more than `rho` of the tree's energy, down to
`max_depth` levels (a quadrant that was a leaf and still holds much energy splits at once over
several levels, its energy shared evenly), and an empty tree becomes the uniform tree of depth 4
(the paper's start).
"""
import math

import numpy as np

from .._jit import jit, kernel

FOUR_PI = 4.0 * math.pi
MAX_DEPTH = 20  # PPG's limit on a D-tree's levels
UNIFORM_DEPTH = 4  # an empty tree restarts as the uniform tree of this depth (16 x 16 leaves)


@jit(inline="always")
def dir_to_uv(d):
    """(u, v) in [0, 1]^2 of a unit direction (libm atan2: exact enough for depth-20 leaves)."""
    u = 0.5 * (min(max(d[2], -1.0), 1.0) + 1.0)
    v = (math.atan2(d[1], d[0]) + math.pi) * (0.5 / math.pi)
    return min(u, 1.0), min(max(v, 0.0), 1.0)


@jit(inline="always")
def uv_to_dir(u, v):
    z = 2.0 * u - 1.0
    s = math.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * math.pi * v - math.pi
    return (s * math.cos(phi), s * math.sin(phi), z)


@jit
def qt_pdf(child, value, root, d):
    """Density per unit solid angle of the tree at `root` in direction d (0 where it has no energy)."""
    u, v = dir_to_uv(d)
    n = root
    p = 1.0
    for _ in range(64):
        tot = value[n, 0] + value[n, 1] + value[n, 2] + value[n, 3]
        if not tot > 0.0:
            return 0.0
        hu = u >= 0.5
        hv = v >= 0.5
        i = (1 if hu else 0) + (2 if hv else 0)
        if not value[n, i] > 0.0:
            return 0.0
        p *= 4.0 * value[n, i] / tot
        c = child[n, i]
        if c < 0:
            break
        u = 2.0 * u - (1.0 if hu else 0.0)
        v = 2.0 * v - (1.0 if hv else 0.0)
        n = c
    return p / FOUR_PI


@jit
def qt_sample(child, value, root, u0, u1):
    """(direction, density) drawn from the tree at `root` with the uniforms u0, u1; the density is
    qt_pdf's of the returned direction. ((0, 0, 1), 0) for a tree without energy."""
    n = root
    lo_u = 0.0
    lo_v = 0.0
    size = 1.0
    for _ in range(64):
        v0, v1, v2, v3 = value[n, 0], value[n, 1], value[n, 2], value[n, 3]
        tot = v0 + v1 + v2 + v3
        if not tot > 0.0:
            return (0.0, 0.0, 1.0), 0.0
        left = v0 + v2  # the u < 1/2 half
        x = u0 * tot
        if x < left or v1 + v3 <= 0.0:
            bu = 0
            u0 = min(x / left, 1.0)
            a, b = v0, v2
        else:
            bu = 1
            u0 = min((x - left) / (v1 + v3), 1.0)
            a, b = v1, v3
        y = u1 * (a + b)
        if y < a or b <= 0.0:
            bv = 0
            u1 = min(y / a, 1.0)
        else:
            bv = 1
            u1 = min((y - a) / b, 1.0)
        size *= 0.5
        lo_u += bu * size
        lo_v += bv * size
        c = child[n, bu + 2 * bv]
        if c < 0:
            break
        n = c
    # inside the leaf, kept a hair from its edges so that the direction maps back into it
    m = 1e-9
    uu = lo_u + size * min(max(u0, m), 1.0 - m)
    vv = lo_v + size * min(max(u1, m), 1.0 - m)
    d = uv_to_dir(uu, vv)
    return d, qt_pdf(child, value, root, d)


@kernel
def qt_pdf_batch(child, value, root, dirs):
    out = np.zeros(dirs.shape[0])
    for k in range(dirs.shape[0]):
        out[k] = qt_pdf(child, value, root, (dirs[k, 0], dirs[k, 1], dirs[k, 2]))
    return out


@kernel
def qt_sample_batch(child, value, root, u):
    dirs = np.zeros((u.shape[0], 3))
    pdf = np.zeros(u.shape[0])
    for k in range(u.shape[0]):
        d, p = qt_sample(child, value, root, u[k, 0], u[k, 1])
        dirs[k, 0], dirs[k, 1], dirs[k, 2] = d
        pdf[k] = p
    return dirs, pdf


@jit
def splat(child, value, roots, dirs, energy):
    """Add energy[k] to the leaf quadrant holding dirs[k] of the tree at roots[k] (-1: skipped;
    nearest filter; the interior nodes' values are left to `sums`). Sequential: the order of the
    additions, and so the result, does not depend on the thread count."""
    for k in range(dirs.shape[0]):
        if roots[k] < 0:
            continue
        u, v = dir_to_uv((dirs[k, 0], dirs[k, 1], dirs[k, 2]))
        n = roots[k]
        for _ in range(64):
            hu = u >= 0.5
            hv = v >= 0.5
            i = (1 if hu else 0) + (2 if hv else 0)
            c = child[n, i]
            if c < 0:
                value[n, i] += energy[k]
                break
            u = 2.0 * u - (1.0 if hu else 0.0)
            v = 2.0 * v - (1.0 if hv else 0.0)
            n = c


@jit
def splat_box(child, value, roots, dirs, energy):
    """Add energy[k] over the leaf quadrants that a square around dirs[k] overlaps, in proportion
    to the overlap (the 2019 notes' box filter): the square is the size of the leaf holding dirs[k],
    centred on it and clipped to the unit square, and its whole energy is shared among the leaves
    it covers. roots[k] -1: skipped; the interior values are left to `sums`; sequential."""
    stack_n = np.empty(4 * 64 + 8, np.int64)
    stack_u = np.empty(4 * 64 + 8)
    stack_v = np.empty(4 * 64 + 8)
    stack_s = np.empty(4 * 64 + 8)
    for k in range(dirs.shape[0]):
        if roots[k] < 0:
            continue
        u, v = dir_to_uv((dirs[k, 0], dirs[k, 1], dirs[k, 2]))
        n = roots[k]  # the size of the leaf holding (u, v)
        size = 1.0
        uu, vv = u, v
        for _ in range(64):
            hu = uu >= 0.5
            hv = vv >= 0.5
            size *= 0.5
            c = child[n, (1 if hu else 0) + (2 if hv else 0)]
            if c < 0:
                break
            uu = 2.0 * uu - (1.0 if hu else 0.0)
            vv = 2.0 * vv - (1.0 if hv else 0.0)
            n = c
        a0, a1 = max(u - 0.5 * size, 0.0), min(u + 0.5 * size, 1.0)
        b0, b1 = max(v - 0.5 * size, 0.0), min(v + 0.5 * size, 1.0)
        area = (a1 - a0) * (b1 - b0)  # > 0: the square's centre is in the unit square
        stack_n[0], stack_u[0], stack_v[0], stack_s[0] = roots[k], 0.0, 0.0, 1.0
        top = 1
        while top > 0:
            top -= 1
            n, lo_u, lo_v, half = stack_n[top], stack_u[top], stack_v[top], 0.5 * stack_s[top]
            for i in range(4):
                qu = lo_u + (i & 1) * half
                qv = lo_v + (i >> 1) * half
                ou = min(a1, qu + half) - max(a0, qu)
                ov = min(b1, qv + half) - max(b0, qv)
                if not (ou > 0.0 and ov > 0.0):
                    continue
                c = child[n, i]
                if c < 0:
                    value[n, i] += energy[k] * (ou * ov / area)
                else:
                    stack_n[top], stack_u[top], stack_v[top], stack_s[top] = c, qu, qv, half
                    top += 1


@jit
def sums(child, value, root):
    """Set every interior quadrant's value to the sum of its subtree's leaves (children after
    parents in the arrays: the order `refine` writes)."""
    stack = np.empty(4 * 64 + 8, np.int32)  # a depth-first stack: at most 3 per level
    order = []
    stack[0] = root
    top = 1
    while top > 0:
        top -= 1
        n = stack[top]
        order.append(n)
        for i in range(4):
            if child[n, i] >= 0:
                stack[top] = child[n, i]
                top += 1
    for j in range(len(order) - 1, -1, -1):
        n = order[j]
        for i in range(4):
            c = child[n, i]
            if c >= 0:
                value[n, i] = value[c, 0] + value[c, 1] + value[c, 2] + value[c, 3]


@jit
def refine(child, value, root, rho, max_depth, max_nodes):
    """The next tree of a filled one (values summed): (child, value) of a tree rooted at node 0
    whose quadrants split while they hold more than rho of the energy (at most max_depth levels,
    max_nodes nodes); its values are the energy each quadrant held, shared evenly below a former
    leaf. An empty tree gives the uniform tree of UNIFORM_DEPTH levels (values equal)."""
    total = value[root, 0] + value[root, 1] + value[root, 2] + value[root, 3]
    cap = max(max_nodes, 1)
    out_c = np.full((cap, 4), -1, np.int32)
    out_v = np.zeros((cap, 4))
    # work items: (new node, old node or -1, energy share of the new node when old is -1, depth)
    q_new = np.empty(cap, np.int64)
    q_old = np.empty(cap, np.int64)
    q_e = np.empty(cap)
    q_d = np.empty(cap, np.int64)
    q_new[0], q_old[0], q_e[0], q_d[0] = 0, root, total, 1
    head, count = 0, 1
    empty = not total > 0.0
    while head < count:
        nn, on, e, depth = q_new[head], q_old[head], q_e[head], q_d[head]
        head += 1
        for i in range(4):
            if on >= 0:
                ei = value[on, i]
                oc = child[on, i]
            else:
                ei = 0.25 * e
                oc = -1
            if empty:
                ei = 1.0 / 4.0 ** depth
            out_v[nn, i] = ei
            split = (depth < UNIFORM_DEPTH) if empty else (ei > rho * total)
            if split and depth < max_depth and count < cap:
                out_c[nn, i] = count
                q_new[count], q_old[count], q_e[count], q_d[count] = count, oc, ei, depth + 1
                count += 1
    return out_c[:count].copy(), out_v[:count].copy()
