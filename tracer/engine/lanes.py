"""A wave of paths as float32 lanes: rows of float32 and int32 matrices, [field, lane].

The lane state is declared once (engine.rows: FLOAT_ROWS, INT_ROWS, FLAG_ROWS): `LaneBuffers`
allocates it from the declaration, and `compact` copies a lane by copying every row, so a new
field is one name there. A bounce runs these kernels over lanes 0 .. m-1:

- `intersect`: closest hits, 16 lanes to one rtcIntersect16 (Embree's float32 hit, no float64
  refinement: the hit point is rebuilt from the barycentrics, on the triangle's plane);
- `split_lanes` (a guide's final passes with splitting or the weight window): copies appended
  as new lanes, lanes the window ended marked;
- `classify`: each lane's class, from its triangle's (fast_triangles, in a scene lit by
  triangles only): the diffuse class (diffuse, its reflectance possibly a texture, flat or with
  corner normals; or an escape with no environment), the glossy class (opaque coats and metals
  that do not emit), or general; the AOVs and L_cam of the first two at the camera ray's hit; the
  general lanes listed, and the listed kernel's (the glossy ones; under a guide the diffuse ones
  too);
- `reflectance` (`flat_reflectance` where no fast triangle is textured): each fast lane's colour,
  its texture evaluated;
- `shade`: the diffuse class, one `prange` over the lanes that LLVM packs 8 or 16 to an
  instruction (the body holds no helper that takes arrays and no `and` chain, integers stay
  32-bit: docs/throughput.md; the other lanes keep what the other kernels read): emission with
  its MIS weight, a light sample with MIS (alias table, a point uniform on the triangle), a cosine
  bounce, the roulette; `albedo_aov` its lanes' AOV albedo;
- `shade_listed` (engine.listed): the glossy lanes, and under a guide the diffuse ones too, each
  in float64 through its BSDF's own functions and the guide's contract;
- `shade_general` (engine.general): the general lanes, each through engine.vertex.shade_vertex in
  float64 (every material, texture and light), its results written into the lanes;
- `occlude`: the shadow rays of all three, packed 16 to one rtcOccluded16, adding the unblocked
  ones;
- `compact`: the ended paths' radiance out to the wave's path slots (float64), and the lanes
  that go on moved into the holes they left, so that lanes 0 .. m-1 hold the m paths left.

Positions are relative to the accel's centre, as Embree holds the scene. The diffuse and glossy
classes draw their random numbers from a 32-bit hash of the path's key folded to 32 bits and the
dimension (tracer.rng's layout of a bounce's dimensions), the general kernel from the key itself
as the other path loops do: the images agree with theirs in expectation, not bit for bit
(tests/test_engine.py z-tests them).

What a wave needs to run here (`usable`): Embree, and a pass that takes no external primary
samples. A guide's final passes run here too: under its maps, its roulette or its splitting
(`fast_allowed`) the diffuse lanes go to the listed kernel with the glossy ones, which samples
the guide's mixture; the general lanes to the general kernel, which does too. So do its passes
that record: the listed and general kernels write each vertex's record as the wavefront does
(guiding.records), and `occlude` adds a vertex's own NEE to its record's L0.
"""
import math
import time

import numpy as np
from numba import prange

from .._jit import jit, kernel
from ..bsdfs import COATED, DIFFUSE, METAL, ONE_SIDED, P_CLEAR, P_FLAGS, P_KD, P_KS
from ..bvh.embree import _INTERSECT16, _LANES, _OCCLUDED16, _VALID, call4
from ..bvh.numba_bvh import _NumbaThreads
from ..guiding.records import RECORD_NONE
from ..lights import ENV_NONE
from ..rng import no_primary_samples
from ..material import TEX_BITMAP, TEX_CONSTANT, TEX_SLOT_BUMP, TEX_SLOT_KD, TEX_SLOT_KS, TEX_SLOT_OPACITY
from ..splitting import make_copy, merge_copies, split_count
from ..wave import TRACE_PARTS
from .general import shade_general
from .listed import corner_normal, shade_listed
from .rows import (ALIVE, BB, BG, BR, DELTA, DEPTH, DX, DY, DZ, FLAG_ROWS, FLOAT_ROWS, G_N, G_UV, G_VN, HIT_ROWS, H_T,
                   INT_ROWS, KEY, LB, LG, LR, L_LIGHTS, L_MAX, L_NEE, L_RR, OX, OY, OZ, PAD, PDF, SB, SDX, SDY, SDZ, SG,
                   SHADOW, SHADOW_ROWS, SLOT, SOX, SOY, SOZ, SR, TL_AREA, TL_EMIT, TL_EPS, TL_FAST, TL_KD, TL_ONE_SIDED,
                   TL_ROWS, TL_SEL, TL_TEX, TMAX, _rows)
from .sampling32 import (BIG, BLOCK, BOUNCE, D_COIN, D_DIR, D_LIGHT, D_POS, D_RR, F, HALF, INV_PI, ONE, RR_MAX,
                         SHORT, TINY, ZERO, alias_column, alias_thresholds, floor32, hash32, rand32, sincos2pi)
from .vertex import MAX_BOUNCES

_CHUNKS = 64  # compaction: chunks counted, then written at their offsets
# a vertex's class (LaneBuffers.fast, tl[:, TL_FAST]): the general kernel's, the fast kernel's (diffuse), the glossy
# kernel's (engine.glossy: coated plastics and metals)
GENERAL, DIFFUSE_CLASS, GLOSSY_CLASS = 0, 1, 2


class LaneBuffers:
    """The lanes of waves of up to `size` paths, made from the declaration: the state (f, i), a
    bounce's hits and shadow rays, the compaction's scratch."""

    def __init__(self, size):
        self.size = size
        self.f = _rows(len(FLOAT_ROWS), size, F)
        self.i = _rows(len(INT_ROWS), size, np.int32)
        self.hole = np.zeros(size, np.int32)
        self.mover = np.zeros(size, np.int32)
        self.hit = _rows(len(HIT_ROWS), size, F)
        self.prim = np.zeros(size, np.int32)
        self.flags = _rows(len(FLAG_ROWS), size, np.int32)
        self.shadow = _rows(len(SHADOW_ROWS), size, F)
        self.kd = _rows(3, size, F)  # the fast class's reflectance at the vertex
        self.fast = np.zeros(size, np.int32)  # the lane's vertex is of the fast class
        self.lists = np.zeros((2, size), np.int32)  # the lanes the general kernel shades, the listed kernel's
        self.ks = np.ones(size, np.int64)  # split_lanes: copies of each lane (0: the window ended it)


def _per_triangle(a, width):
    """The (rows, n) array `a` as float32 (n + PAD, width): one row per triangle, holding its
    values in the first `rows` columns, 64-byte aligned (a width of 16 floats keeps a triangle in
    one cache line, 24 or 32 in two)."""
    n = a.shape[1] + PAD
    buf = np.zeros(n * width + 16, F)
    off = (-buf.ctypes.data % 64) // 4
    out = buf[off:off + n * width].reshape(n, width)
    out[:a.shape[1], :a.shape[0]] = a.T
    return out


class LaneScene:
    """The scene as the lanes read it, float32, one row per triangle (_per_triangle: a kernel that
    reads a hit's fields reads one or two cache lines, where a matrix of fields by triangle took
    one line a field; engine.rows names the columns): geo (21 columns, 27 with UVs) v0 - centre,
    e1, e2, the unit geometric normal, the three corner normals (zero: none), the corner UVs where
    a fast triangle is textured (columns G_*); tl (TL_ROWS)
    NEE's probability of choosing the triangle, its area, its ray offset, 1 if one-sided, its
    vertices' class (fast_triangles), its colour's texture (-1: none), its colour (a metal's
    specular reflectance, else its diffuse reflectance) and emitted radiance (columns TL_*); the
    textures the classes read: tinfo (T, 16)
    float32 the rows of tracer.material's texture table, tint (T, 3) int32 their texel offset,
    width and height, tdata the texels (one constant row when the scene has none); the alias table
    over the emissive triangles (alias_t: column j keeps its own triangle where a 32-bit hash is
    below alias_t[j], sampling32.alias_thresholds; alias_i (2, columns): column j's triangle and
    its alias's); escape_fast: an escaped path ends with nothing to add (no environment)."""

    def __init__(self, scene, surf, lt, centre):
        v = surf.tri - centre
        nf = v.shape[0]
        vn = surf.vn if surf.vn.shape[0] else np.zeros_like(v)
        fast, tex = fast_triangles(scene, lt)
        rows = [v[:, 0].T, (v[:, 1] - v[:, 0]).T, (v[:, 2] - v[:, 0]).T, surf.normal.T, vn[:, 0].T, vn[:, 1].T,
                vn[:, 2].T]
        self.textured = bool(np.any(tex >= 0))  # some fast triangle's reflectance is a texture
        if self.textured:
            uv = surf.uv if surf.uv.shape[0] else np.zeros((nf, 3, 2))
            rows.append(uv.reshape(nf, 6).T)
        geo = np.concatenate(rows)
        self.geo = _per_triangle(geo, 24 if geo.shape[0] <= 24 else 32)
        param = surf.mat_param[surf.material]
        tl = np.zeros((TL_ROWS, nf), F)
        tl[TL_EPS] = surf.eps
        tl[TL_ONE_SIDED] = (param[:, P_FLAGS].astype(np.int64) & ONE_SIDED) != 0
        tl[TL_FAST] = fast
        tl[TL_TEX] = tex
        metal = (surf.mat_type[surf.material] == METAL)[:, None]
        tl[TL_KD:TL_KD + 3] = np.where(metal, param[:, P_KS:P_KS + 3], param[:, P_KD:P_KD + 3]).T
        if surf.tex_info.shape[0]:
            self.tinfo = surf.tex_info.astype(F)
            self.tint = surf.tex_info[:, 1:4].astype(np.int32)
            self.tdata = surf.tex_data
        else:
            self.tinfo = np.zeros((1, surf.tex_info.shape[1]), F)
            self.tint = np.zeros((1, 3), np.int32)
            self.tdata = np.zeros(3, F)
        self.escape_fast = lt.env_type == ENV_NONE
        self.all_fast = bool(np.all(fast == DIFFUSE_CLASS)) and self.escape_fast  # every vertex the fast kernel's
        self.classes = frozenset(int(c) for c in np.unique(fast))  # the classes of the scene's triangles
        self.smooth = surf.vn.shape[0] > 0
        e = lt.tri
        sel = (1.0 - lt.p_env) * np.diff(lt.cdf)
        tl[TL_EMIT:TL_EMIT + 3, e] = lt.radiance.T
        tl[TL_SEL, e] = sel
        tl[TL_AREA, e] = lt.area
        self.tl = _per_triangle(tl, 16)
        self.n_lights = int(e.shape[0])
        if self.n_lights:
            prob, alias = alias_table(sel / sel.sum())
            self.alias_t = alias_thresholds(prob)
            self.alias_i = np.stack([e, e[alias]]).astype(np.int32)
        else:
            self.alias_t = np.zeros(1, np.uint32)
            self.alias_i = np.zeros((2, 1), np.int32)


@jit
def alias_table(p):
    """Vose's alias table of the distribution p: (probability of keeping column j, alias of j)."""
    n = p.shape[0]
    scaled = p * n
    prob = np.ones(n)
    alias = np.arange(n)
    small = np.empty(n, np.int64)
    large = np.empty(n, np.int64)
    ns = 0
    nl = 0
    for i in range(n):
        if scaled[i] < 1.0:
            small[ns] = i
            ns += 1
        else:
            large[nl] = i
            nl += 1
    while ns > 0 and nl > 0:
        ns -= 1
        nl -= 1
        s = small[ns]
        g = large[nl]
        prob[s] = scaled[s]
        alias[s] = g
        scaled[g] -= 1.0 - scaled[s]
        if scaled[g] < 1.0:
            small[ns] = g
            ns += 1
        else:
            large[nl] = g
            nl += 1
    return prob, alias


def fast_triangles(scene, lights):
    """((F,) int32, (F,) int32): each triangle's class (GENERAL, DIFFUSE_CLASS, GLOSSY_CLASS) and
    the texture of its colour (-1: none). In a scene lit by triangles only (the classes' NEE samples
    nothing else) whose texels the lanes' 32-bit indices reach, opaque materials with no bump
    texture: DIFFUSE ones (the colour is the reflectance); and on triangles that do not emit,
    COATED ones (the colour is the diffuse reflectance; no specular texture) and METAL ones (the
    colour is the specular reflectance; no diffuse texture). Every other triangle is GENERAL."""
    m = scene.materials
    nf = scene.tri.shape[0]
    none = np.full(nf, -1, np.int32)
    if lights.env_type != ENV_NONE or lights.delta_kind.shape[0] or scene.textures.data.shape[0] >= 2 ** 31:
        return np.zeros(nf, np.int32), none
    mat = scene.tri_material
    opaque = m.param[:, P_CLEAR] == 0.0
    metal = m.type == METAL
    glossy = (m.type == COATED) | metal
    cls = np.where((m.type == DIFFUSE) & opaque, DIFFUSE_CLASS,
                   np.where(glossy & opaque, GLOSSY_CLASS, GENERAL)).astype(np.int32)
    colour = np.full(cls.shape[0], -1, np.int32)
    if m.tex is not None and m.tex.shape[0]:
        other = np.where(metal, TEX_SLOT_KD, TEX_SLOT_KS)  # the slot that must be empty
        rows = np.arange(cls.shape[0])
        bad = (m.tex[rows, other] >= 0) | (m.tex[:, TEX_SLOT_BUMP] >= 0) | (m.tex[:, TEX_SLOT_OPACITY] >= 0)
        cls[bad] = GENERAL
        slot = np.where(metal, TEX_SLOT_KS, TEX_SLOT_KD)
        colour = np.where(cls != GENERAL, m.tex[rows, slot], -1).astype(np.int32)
    tri_cls = cls[mat]
    tri_cls[(tri_cls == GLOSSY_CLASS) & np.any(m.emission[mat] > 0.0, axis=1)] = GENERAL
    return tri_cls, colour[mat]


def usable(ctx, record, ps):
    """Whether a wave can run on the lanes: render(path_loop="lanes"), Embree, no primary samples.
    (A guide's maps and roulette are the listed and general kernels', fast_allowed; its splitting
    is split_lanes'; its records, with `record`, the listed and general kernels'.)"""
    if ctx.path_loop != "lanes" or ctx.accel.name != "embree":
        return False
    return ps is None or not np.any(ps.col >= 0)


def _limits(ctx, ls):
    """The class kernels' `lim` (int32, rows L_*): rr_depth, max_depth, nee, the emissive triangles'
    count, whether the scene has corner normals."""
    return np.array([ctx.rr_depth, ctx.max_depth, int(ctx.nee), ls.n_lights, int(ls.smooth)], np.int32)


def _general_limits(ctx, record, rec_base):
    """The general kernel's `limits`: (max_depth, rr_depth, nee, record mode, first record)."""
    return int(ctx.max_depth), int(ctx.rr_depth), bool(ctx.nee), int(record), int(rec_base)


def class_kernels(ctx, guided):
    """The shading kernels ("module.function") a render of ctx's scene may run on the lanes:
    `lanes.shade` where a vertex or an escape may be of the diffuse class, `listed.shade_listed`
    where a triangle is glossy, or under a guide (`guided`) where one is diffuse,
    `general.shade_general` where one is general or an environment or a point light lights the
    scene (every vertex general); `lanes.classify` always."""
    ls = _lane_scene(ctx)
    names = ["lanes.classify"]
    diffuse = ls.escape_fast or DIFFUSE_CLASS in ls.classes
    if diffuse:
        names.append("lanes.shade")
    if GLOSSY_CLASS in ls.classes or (guided and diffuse):
        names.append("listed.shade_listed")
    if GENERAL in ls.classes or not ls.escape_fast:
        names.append("general.shade_general")
    return names


def _colours(ls, lanes, m):
    """The colour rows (lanes.kd) of the classed lanes 0 .. m-1: reflectance, or flat_reflectance
    where no classed triangle is textured."""
    if ls.textured:
        reflectance(m, lanes.hit, lanes.prim, lanes.fast, ls.geo, ls.tl, ls.tinfo, ls.tint, ls.tdata, lanes.kd)
    else:
        flat_reflectance(m, lanes.prim, lanes.fast, ls.tl, lanes.kd)


def warm_up(ctx, buf, names, split=None):
    """Compile (or load from the cache) the shading kernels among `names` (class_kernels') and,
    given a splitting.SplitPlan, split_lanes, each run on zero lanes with the argument types of
    run()'s calls (buf: a wave.WaveBuffers, made with split=True for split), so that none compiles
    inside a render's passes and its time budget."""
    ls = _lane_scene(ctx)
    lanes = LaneBuffers(buf.capacity)
    lf, li, flags = lanes.f, lanes.i, lanes.flags
    lim = _limits(ctx, ls)
    state = buf.path_state(0)
    if "lanes.shade" in names or "listed.shade_listed" in names:
        _colours(ls, lanes, 0)
        albedo_aov(li, 0, lanes.kd, lanes.prim, lanes.fast, state)
    if "lanes.shade" in names:
        shade(lf, li, 0, lanes.hit, lanes.prim, lanes.shadow, flags, lanes.fast, ls.geo, ls.tl, lanes.kd, ls.alias_t,
              ls.alias_i, lim)
    if "listed.shade_listed" in names:
        shade_listed(lf, li, lanes.hit, lanes.prim, lanes.shadow, flags, lanes.lists[1, :0], (ls.geo, ls.tl, lanes.kd),
                     (ls.alias_t, ls.alias_i), lim, ctx.surfaces, state, ctx.guide_state, ctx.accel.centre,
                     buf.records, (0, 0))
    if "general.shade_general" in names:
        shade_general(lf, li, lanes.hit, lanes.prim, lanes.shadow, flags, lanes.lists[0, :0], ctx.accel.centre,
                      ctx.surfaces, ctx.lights, ctx.guide_state, no_primary_samples(), _general_limits(ctx, 0, 0),
                      state, buf.records)
    if split is not None:
        split_lanes(lf, li, 0, lanes.hit, lanes.prim, ctx.surfaces.tri, ctx.tri_normal, state, ctx.guide_state, split,
                    lanes.ks, buf.parent, 0, buf.capacity)


def fast_allowed(gs):
    """Whether the fast class may shade under the GuideState gs: no maps, and the path tracer's own
    roulette (survival min(max(beta), 0.95), drawn before the sampled ray), which it hard-codes.
    (Else the listed kernel takes the diffuse lanes.)"""
    return (gs.res[0] == 0 and gs.pixel_slot.shape[0] == 0 and gs.rr_late == 0 and gs.rr_min == 0.0
            and gs.rr_max == RR_MAX)


@jit
def _fold(k):
    """The lanes' 32-bit key of a path's 64-bit one."""
    k = np.uint64(k)
    return np.int32(np.uint32((k ^ (k >> np.uint64(32))) & np.uint64(0xFFFFFFFF)))


@kernel
def split_lanes(lf, li, m, hit, prim, tri, tri_normal, state, gs, plan, ks, parent, n_slots, capacity):
    """The splitting and weight window of a guide's final passes (splitting.SplitPlan `plan`) on
    lanes 0 .. m-1 after their hits, as splitting.split_counts and split_paths do it on the
    wavefront. ks[k] gets lane k's copies from split_count: 0 where the window ended the path
    (classify then leaves the lane unshaded and compact sends its radiance out), its throughput
    and gain divided where the window's roulette kept it. A lane split in c copies takes c - 1
    new lanes from m on and path slots from n_slots on, in lane order (fewer where fewer are left
    below `capacity`, or lanes below lf's width), each with the lane's rows and hit, its own key
    (rng.split_key), no radiance and parent = the slot it adds into (ks 1); the throughputs and
    gains are divided by c. The wave's PathState `state` must hold the lanes' throughput, gain and
    depth (every vertex general: shade_general keeps them). Returns (lanes, path slots, ended)."""
    beta = state.beta
    gain = state.gain
    L = state.L
    depth = state.depth
    prev_pdf = state.prev_pdf
    prev_delta = state.prev_delta
    key = state.key
    pix = state.pix
    prev_rec = state.prev_rec
    outgoing = plan.outgoing
    pixel_est = plan.pixel_est
    hi = plan.hi
    low = plan.low
    threshold = plan.threshold
    slot = li[SLOT, :m]
    ray_d = lf[DX:DZ + 1, :m].T
    b1 = hit[1, :m]
    b2 = hit[2, :m]
    counts = np.zeros((_CHUNKS + 1, 2), np.int64)  # per chunk: copies wanted, lanes ended
    for c in prange(_CHUNKS):
        want = 0
        gone = 0
        for k in range(c * m // _CHUNKS, (c + 1) * m // _CHUNKS):
            cnt = split_count(k, slot, ray_d, (prim, b1, b2), (tri, tri_normal), beta, gain, (depth, pix, key), gs,
                              (outgoing, pixel_est, hi, low, threshold))
            ks[k] = cnt
            i = slot[k]
            for q in range(3):
                lf[BR + q, k] = beta[i, q]  # as the window's roulette left it
            if cnt > 1:
                want += cnt - 1
            elif cnt == 0:
                gone += 1
        counts[c + 1, 0] = want
        counts[c + 1, 1] = gone
    for c in range(_CHUNKS):
        counts[c + 1, 0] += counts[c, 0]
        counts[c + 1, 1] += counts[c, 1]
    room = min(capacity - n_slots, lf.shape[1] - PAD - m, counts[_CHUNKS, 0])
    nf = lf.shape[0]
    ni = li.shape[0]
    for c in prange(_CHUNKS):
        off = counts[c, 0]  # copies wanted by the lanes before this one
        for k in range(c * m // _CHUNKS, (c + 1) * m // _CHUNKS):
            want = ks[k] - 1
            if want <= 0:
                continue
            made = min(want, max(room - off, 0))
            first = off
            off += want
            if made == 0:
                continue
            i = slot[k]
            share = made + 1
            for q in range(3):
                beta[i, q] /= share
                lf[BR + q, k] = beta[i, q]
            gain[i] /= share
            for j in range(1, share):
                e = m + first + j - 1
                s = n_slots + first + j - 1
                for r in range(nf):
                    lf[r, e] = lf[r, k]
                for r in range(ni):
                    li[r, e] = li[r, k]
                for r in range(3):
                    hit[r, e] = hit[r, k]
                    lf[LR + r, e] = 0.0
                prim[e] = prim[k]
                ks[e] = 1
                make_copy(i, s, j, beta, gain, L, depth, prev_pdf, prev_delta, key, pix, prev_rec, parent)
                li[SLOT, e] = s
                li[KEY, e] = _fold(key[s])
    made_all = min(room, counts[_CHUNKS, 0])
    return m + made_all, n_slots + made_all, counts[_CHUNKS, 1]


def _lane_scene(ctx):
    """ctx's LaneScene, made once."""
    if not hasattr(ctx, "_lanes"):
        ctx._lanes = LaneScene(ctx.scene, ctx.surfaces, ctx.lights, ctx.accel.centre)
    return ctx._lanes


@kernel
def start(ray_o, ray_d, centre, state, lf, li):
    """Lanes 0 .. n-1 from the wave's paths 0 .. n-1 (their camera rays and wave.PathState)."""
    beta = state.beta
    depth = state.depth
    prev_delta = state.prev_delta
    key = state.key
    for i in prange(ray_o.shape[0]):
        lf[OX, i] = F(ray_o[i, 0] - centre[0])
        lf[OY, i] = F(ray_o[i, 1] - centre[1])
        lf[OZ, i] = F(ray_o[i, 2] - centre[2])
        lf[DX, i] = F(ray_d[i, 0])
        lf[DY, i] = F(ray_d[i, 1])
        lf[DZ, i] = F(ray_d[i, 2])
        lf[BR, i] = F(beta[i, 0])
        lf[BG, i] = F(beta[i, 1])
        lf[BB, i] = F(beta[i, 2])
        lf[LR, i] = ZERO
        lf[LG, i] = ZERO
        lf[LB, i] = ZERO
        lf[PDF, i] = ZERO
        li[SLOT, i] = np.int32(i)
        li[DEPTH, i] = np.int32(depth[i])
        li[DELTA, i] = np.int32(1) if prev_delta[i] else np.int32(0)
        li[KEY, i] = _fold(key[i])


@jit(inline="always")
def put_ray(buf, ib, k, rows, o, d, i, tfar):
    """Lane k of the packet in scratch row `buf` (ib: the same row as int32): the ray of lane i of
    `rows`, its origin in rows o .. o+2 and its direction in d .. d+2, from 0 to tfar; valid."""
    L = _LANES
    for q in range(3):
        buf[q * L + k] = rows[o + q, i]
        buf[(4 + q) * L + k] = rows[d + q, i]
    buf[3 * L + k] = 0.0
    buf[7 * L + k] = 0.0
    buf[8 * L + k] = tfar
    ib[9 * L + k] = -1
    ib[10 * L + k] = 0
    ib[11 * L + k] = 0
    ib[_VALID * L + k] = -1


@kernel
def intersect(fn, scene, scratch, lf, n, hit, prim):
    """Closest hits of lanes 0 .. n-1 into hit (t, b1, b2) and prim (-1: none), 16 lanes to one
    rtcIntersect16 (fn), each chunk of packets on one thread in its scratch row."""
    L = _LANES
    nch = scratch.shape[0]
    npk = (n + L - 1) // L
    for c in prange(nch):
        buf = scratch[c]
        ib = buf.view(np.int32)
        addr = buf.ctypes.data
        for pk in range(c * npk // nch, (c + 1) * npk // nch):
            base = pk * L
            m = min(L, n - base)
            for k in range(L):
                ib[17 * L + k] = -1
                ib[18 * L + k] = -1
                ib[_VALID * L + k] = 0
            for k in range(m):
                put_ray(buf, ib, k, lf, OX, DX, base + k, np.float32(np.inf))
            call4(fn, addr + 4 * _VALID * L, scene, addr, 0)
            for k in range(m):
                i = base + k
                if ib[18 * L + k] == -1:
                    prim[i] = -1
                else:
                    prim[i] = ib[17 * L + k]
                    hit[0, i] = buf[8 * L + k]
                    hit[1, i] = buf[15 * L + k]
                    hit[2, i] = buf[16 * L + k]


@kernel
def classify(lf, li, n, hit, prim, tl, geo, list_diffuse, escape_fast, state, ks, flags, fast_lane, lists):
    """Mark each lane 0 .. n-1 with its vertex's class (fast_lane: a hit's triangle's tl[p, TL_FAST],
    an escape DIFFUSE_CLASS where escape_fast, else GENERAL), and list the GENERAL lanes in order in
    lists[0], the listed kernel's in lists[1] (the GLOSSY_CLASS ones, and with list_diffuse the
    DIFFUSE_CLASS ones too); returns how many of each. A lane with ks 0
    (split_lanes: the weight window ended its path) is in none: flags say it ends and has no shadow
    ray. For the lanes of the two classes it writes what shade_vertex writes into the
    wave's PathState `state` besides the path: at the camera ray's hit the AOVs' shading normal
    (on the camera's side of the surface) and distance and L_cam, the light the camera sees (the
    albedo is albedo_aov's, after shade)."""
    aov = state.aov
    L_cam = state.L_cam
    counts = np.zeros((_CHUNKS + 1, 2), np.int64)
    for c in prange(_CHUNKS):
        g = 0
        h = 0
        for k in range(c * n // _CHUNKS, (c + 1) * n // _CHUNKS):
            p = prim[k]
            cls = GENERAL
            if p >= 0:
                cls = np.int32(tl[p, TL_FAST])
            elif escape_fast:
                cls = DIFFUSE_CLASS
            fast_lane[k] = cls
            if ks[k] == 0:
                flags[ALIVE, k] = 0
                flags[SHADOW, k] = 0
                continue
            if cls == GENERAL:
                g += 1
                continue
            if cls == GLOSSY_CLASS or list_diffuse:
                h += 1
            i = li[SLOT, k]
            first = li[DEPTH, k] == 0
            if p < 0:
                if first:
                    for q in range(3):
                        L_cam[i, q] = 0.0
                continue
            if first:
                cos_o = -(lf[DX, k] * geo[p, G_N] + lf[DY, k] * geo[p, G_N + 1] + lf[DZ, k] * geo[p, G_N + 2])
                sgn = 1.0 if cos_o >= 0.0 else -1.0
                lit = 1.0 if cos_o > 0.0 else 0.0
                ns = corner_normal(geo, p, np.float64(hit[1, k]), np.float64(hit[2, k]))
                for q in range(3):
                    aov[i, 3 + q] = sgn * ns[q]
                for q in range(3):
                    L_cam[i, q] = lf[BR + q, k] * tl[p, TL_EMIT + q] * lit
                aov[i, 6] = hit[H_T, k]
        counts[c + 1, 0] = g
        counts[c + 1, 1] = h
    for c in range(_CHUNKS):
        counts[c + 1, 0] += counts[c, 0]
        counts[c + 1, 1] += counts[c, 1]
    for c in prange(_CHUNKS):
        j = counts[c, 0]
        jc = counts[c, 1]
        for k in range(c * n // _CHUNKS, (c + 1) * n // _CHUNKS):
            if ks[k] == 0:
                continue
            if fast_lane[k] == GENERAL:
                lists[0, j] = k
                j += 1
            elif fast_lane[k] == GLOSSY_CLASS or list_diffuse:
                lists[1, jc] = k
                jc += 1
    return counts[_CHUNKS, 0], counts[_CHUNKS, 1]


@kernel
def albedo_aov(li, n, kd, prim, fast_lane, state):
    """The AOV albedo of each path whose diffuse-class vertex in lanes 0 .. n-1 is its first that is
    not a delta BSDF (aov_open): its reflectance (kd, reflectance's). (The glossy kernel writes its
    own lanes'.)"""
    aov = state.aov
    aov_open = state.aov_open
    for k in prange(n):
        i = li[SLOT, k]
        if fast_lane[k] == DIFFUSE_CLASS and prim[k] >= 0 and aov_open[i]:
            for q in range(3):
                aov[i, q] = kd[q, k]
            aov_open[i] = False


@kernel
def flat_reflectance(n, prim, fast_lane, tl, kd):
    """reflectance in a scene whose fast triangles hold no texture: each fast lane's material's
    reflectance into kd."""
    for k in prange(n):
        p = prim[k]
        pc = p if (p >= 0) & (fast_lane[k] != 0) else 0
        kd[0, k] = tl[pc, TL_KD]
        kd[1, k] = tl[pc, TL_KD + 1]
        kd[2, k] = tl[pc, TL_KD + 2]


@kernel(fastmath={"arcp", "contract", "nsz"})
def reflectance(n, hit, prim, fast_lane, geo, tl, tinfo, tint, tdata, kd):
    """The diffuse reflectance at the vertex of each fast lane 0 .. n-1 into kd (3 rows): its
    triangle's texture (tl[p, TL_TEX]) at the hit's UV, as material.texture_eval (constant,
    checkerboard, or bilinear and repeating; black where the texel's coordinate is not finite), or
    its material's reflectance; tinfo, tint, tdata: LaneScene's textures."""
    for k in prange(n):
        p = prim[k]
        pc = p if (p >= 0) & (fast_lane[k] != 0) else 0
        b1, b2 = hit[1, k], hit[2, k]
        b0 = ONE - b1 - b2
        tx = tl[pc, TL_TEX]
        textured = tx >= ZERO
        kt = np.int32(tx) if textured else np.int32(0)
        pt = pc if textured else 0
        ru = np.int32(G_UV) if textured else np.int32(0)  # geo has UV rows only if some fast triangle is textured
        u = b0 * geo[pt, ru] + b1 * geo[pt, ru + 2] + b2 * geo[pt, ru + 4]
        v = b0 * geo[pt, ru + 1] + b1 * geo[pt, ru + 3] + b2 * geo[pt, ru + 5]
        uu = tinfo[kt, 4] * u + tinfo[kt, 5] * v + tinfo[kt, 6]
        vv = tinfo[kt, 7] * u + tinfo[kt, 8] * v + tinfo[kt, 9]
        kind = tinfo[kt, 0]
        first = ((uu - floor32(uu)) > HALF) == ((vv - floor32(vv)) > HALF)  # the checkerboard's colour 0
        tw = tint[kt, 1]
        th = tint[kt, 2]
        wf, hf = F(tw), F(th)
        x = uu * wf - HALF
        y = (ONE - vv) * hf - HALF
        finite = (x > -BIG) & (x < BIG) & (y > -BIG) & (y < BIG)
        x = x if finite else ZERO
        y = y if finite else ZERO
        x0 = floor32(x)
        y0 = floor32(y)
        fx = x - x0
        fy = y - y0
        xm = x0 - wf * floor32(x0 / wf)  # x0 mod w, integer-valued, put in [0, w) below
        xm = xm + wf if xm < ZERO else (xm - wf if xm >= wf else xm)
        ym = y0 - hf * floor32(y0 / hf)
        ym = ym + hf if ym < ZERO else (ym - hf if ym >= hf else ym)
        ix = np.int32(xm)
        iy = np.int32(ym)
        ix1 = ix + np.int32(1) if ix + np.int32(1) < tw else np.int32(0)
        iy1 = iy + np.int32(1) if iy + np.int32(1) < th else np.int32(0)
        bitmap = textured & (kind == F(TEX_BITMAP))
        row0 = tint[kt, 0] + np.int32(3) * iy * tw if bitmap else np.int32(0)
        row1 = tint[kt, 0] + np.int32(3) * iy1 * tw if bitmap else np.int32(0)
        j00, j01 = row0 + np.int32(3) * ix, row0 + np.int32(3) * ix1
        j10, j11 = row1 + np.int32(3) * ix, row1 + np.int32(3) * ix1
        j00 = j00 if bitmap else np.int32(0)
        j01 = j01 if bitmap else np.int32(0)
        j10 = j10 if bitmap else np.int32(0)
        j11 = j11 if bitmap else np.int32(0)
        w00, w01 = (ONE - fy) * (ONE - fx), (ONE - fy) * fx
        w10, w11 = fy * (ONE - fx), fy * fx
        ar = tl[pc, TL_KD]
        ag = tl[pc, TL_KD + 1]
        ab = tl[pc, TL_KD + 2]
        c0 = np.int32(10) if first | (kind == F(TEX_CONSTANT)) else np.int32(13)  # colour 0 or 1
        ar = ar if not textured else tinfo[kt, c0]
        ag = ag if not textured else tinfo[kt, c0 + 1]
        ab = ab if not textured else tinfo[kt, c0 + 2]
        tr = w00 * tdata[j00] + w01 * tdata[j01] + w10 * tdata[j10] + w11 * tdata[j11]
        tg = w00 * tdata[j00 + 1] + w01 * tdata[j01 + 1] + w10 * tdata[j10 + 1] + w11 * tdata[j11 + 1]
        tb = w00 * tdata[j00 + 2] + w01 * tdata[j01 + 2] + w10 * tdata[j10 + 2] + w11 * tdata[j11 + 2]
        ar = (tr if finite else ZERO) if bitmap else ar
        ag = (tg if finite else ZERO) if bitmap else ag
        ab = (tb if finite else ZERO) if bitmap else ab
        kd[0, k] = ar
        kd[1, k] = ag
        kd[2, k] = ab


@kernel(fastmath={"arcp", "contract", "nsz"})
def shade(lf, li, n, hit, prim, sh, flags, fast_lane, geo, tl, kd, alias_t, alias_i, lim):
    """Shade the vertex each lane 0 .. n-1 of the fast class (fast_lane) hit (prim -1: escaped, the
    path ends): emission with its MIS weight (full without NEE or after a delta bounce) into the
    lane's radiance; with NEE (lim[L_NEE]) a light sample with MIS into the shadow rows
    (flags[SHADOW]); the cosine-sampled next ray, the throughput and depth after it, and the
    roulette from lim[L_RR] (flags[ALIVE]). The other lanes keep the rows shade_general reads (the
    direction, throughput, density, depth, delta flag: written back as loaded, since a store under a
    branch, or a load after a store, keeps LLVM from packing the loop); their other rows are
    scratch until shade_general, which runs next, writes them. lim: int32
    rr_depth, max_depth (< 0: none), nee, the emissive triangles' count; the scene's tables as
    LaneScene's. With corner normals the vertex is shaded in the frame of the interpolated normal,
    and a direction on the other side of the true surface than wo gets nothing (a light leak only
    shading normals make possible, as material.crosses)."""
    rr_depth = lim[L_RR]
    max_depth = lim[L_MAX]
    nee = lim[L_NEE] != 0
    n_lights = lim[L_LIGHTS]
    nl = alias_t.shape[0]
    for k in prange(n):
        fast = fast_lane[k] == DIFFUSE_CLASS
        p = prim[k]
        hit_ok = p >= 0
        pc = p if hit_ok else 0
        dx, dy, dz = lf[DX, k], lf[DY, k], lf[DZ, k]
        t, b1, b2 = hit[0, k], hit[1, k], hit[2, k]
        x0 = geo[pc, 0] + b1 * geo[pc, 3] + b2 * geo[pc, 6]
        x1 = geo[pc, 1] + b1 * geo[pc, 4] + b2 * geo[pc, 7]
        x2 = geo[pc, 2] + b1 * geo[pc, 5] + b2 * geo[pc, 8]
        nx, ny, nz = geo[pc, G_N], geo[pc, G_N + 1], geo[pc, G_N + 2]
        cos_o = -(dx * nx + dy * ny + dz * nz)
        sgn = ONE if cos_o >= ZERO else -ONE
        fx, fy, fz = nx * sgn, ny * sgn, nz * sgn  # the true normal on the side the path arrived
        # the shading normal: the corner normals interpolated, in ng's hemisphere (ng where they vanish)
        b0 = ONE - b1 - b2
        snx = b0 * geo[pc, G_VN] + b1 * geo[pc, G_VN + 3] + b2 * geo[pc, G_VN + 6]
        sny = b0 * geo[pc, G_VN + 1] + b1 * geo[pc, G_VN + 4] + b2 * geo[pc, G_VN + 7]
        snz = b0 * geo[pc, G_VN + 2] + b1 * geo[pc, G_VN + 5] + b2 * geo[pc, G_VN + 8]
        c2 = snx * snx + sny * sny + snz * snz
        has_n = (c2 > ZERO) & (c2 < F(np.inf))
        inv_n = ONE / math.sqrt(c2 if has_n else ONE)
        inv_n = -inv_n if (snx * nx + sny * ny + snz * nz) < ZERO else inv_n
        snx = snx * inv_n if has_n else nx
        sny = sny * inv_n if has_n else ny
        snz = snz * inv_n if has_n else nz
        wo_z = -(dx * snx + dy * sny + dz * snz)
        ssg = ONE if wo_z >= ZERO else -ONE
        sx, sy, sz = snx * ssg, sny * ssg, snz * ssg  # the shading normal on wo's side
        black = (tl[pc, TL_ONE_SIDED] > ZERO) & (wo_z <= ZERO)  # a one-sided surface seen from behind
        ar = ZERO if black else kd[0, k]
        ag = ZERO if black else kd[1, k]
        ab = ZERO if black else kd[2, k]
        br, bg, bb = lf[BR, k], lf[BG, k], lf[BB, k]
        prev_pdf = lf[PDF, k]
        depth = li[DEPTH, k]
        delta = li[DELTA, k]
        key = li[KEY, k]
        base = BOUNCE + BLOCK * depth
        on = hit_ok & ((max_depth < 0) | (depth + 1 < max_depth))  # the path may go on past this vertex

        # emission (one-sided), MIS-weighted against the light sample that could have found it
        lit = fast & hit_ok & (cos_o > ZERO)
        pl = tl[pc, TL_SEL] * t * t / max(tl[pc, TL_AREA] * cos_o, TINY)
        pp = prev_pdf * prev_pdf
        w_mis = pp / max(pp + pl * pl, TINY)
        w_e = ZERO if not lit else (w_mis if nee & (depth > 0) & (delta == 0) else ONE)
        lf[LR, k] += br * tl[pc, TL_EMIT] * w_e
        lf[LG, k] += bg * tl[pc, TL_EMIT + 1] * w_e
        lf[LB, k] += bb * tl[pc, TL_EMIT + 2] * w_e

        # a light sample: an emissive triangle from the alias table, a point uniform on it
        j = alias_column(key, base + D_LIGHT, nl)
        lj = alias_i[0, j] if hash32(key, base + D_COIN) < alias_t[j] else alias_i[1, j]
        su = math.sqrt(rand32(key, base + D_POS))
        lb1 = ONE - su
        lb2 = rand32(key, base + D_POS + 1) * su
        lx0 = geo[lj, 0] + lb1 * geo[lj, 3] + lb2 * geo[lj, 6]  # the light point
        lx1 = geo[lj, 1] + lb1 * geo[lj, 4] + lb2 * geo[lj, 7]
        lx2 = geo[lj, 2] + lb1 * geo[lj, 5] + lb2 * geo[lj, 8]
        wx, wy, wz = lx0 - x0, lx1 - x1, lx2 - x2
        d2 = max(wx * wx + wy * wy + wz * wz, TINY)
        inv_d = ONE / math.sqrt(d2)
        wx, wy, wz = wx * inv_d, wy * inv_d, wz * inv_d
        cos_l = -(wx * geo[lj, G_N] + wy * geo[lj, G_N + 1] + wz * geo[lj, G_N + 2])
        cos_s = wx * sx + wy * sy + wz * sz
        same_side = (wx * fx + wy * fy + wz * fz) > ZERO
        ok = on & nee & (n_lights > 0) & (cos_l > ZERO) & (cos_s > ZERO) & same_side
        pls = tl[lj, TL_SEL] * d2 / max(tl[lj, TL_AREA] * cos_l, TINY)
        pb = cos_s * INV_PI
        g = (pb * pls / max(pls * pls + pb * pb, TINY)) if ok else ZERO  # f cos / p_light x the power heuristic
        eps = tl[pc, TL_EPS]
        ox, oy, oz = x0 + fx * eps, x1 + fy * eps, x2 + fz * eps
        # the shadow ray: from the offset origin to the light point pushed off its triangle, toward
        # x, by the light's own offset (as shading.shadow_ray)
        el = tl[lj, TL_EPS]
        ex = lx0 + el * geo[lj, G_N] - ox
        ey = lx1 + el * geo[lj, G_N + 1] - oy
        ez = lx2 + el * geo[lj, G_N + 2] - oz
        e2 = max(ex * ex + ey * ey + ez * ez, TINY)
        inv_e = ONE / math.sqrt(e2)
        sr = br * ar * tl[lj, TL_EMIT] * g
        sg = bg * ag * tl[lj, TL_EMIT + 1] * g
        sb = bb * ab * tl[lj, TL_EMIT + 2] * g
        sh[SOX, k], sh[SOY, k], sh[SOZ, k] = ox, oy, oz
        sh[SDX, k], sh[SDY, k], sh[SDZ, k] = ex * inv_e, ey * inv_e, ez * inv_e
        sh[TMAX, k] = e2 * inv_e * SHORT
        sh[SR, k], sh[SG, k], sh[SB, k] = sr, sg, sb
        flags[SHADOW, k] = np.int32(1) if (sr + sg + sb) > ZERO else np.int32(0)

        # the cosine bounce, in the frame of the shading normal on wo's side (Duff et al. 2017)
        u2 = rand32(key, base + D_DIR)
        c, s = sincos2pi(rand32(key, base + D_DIR + 1))
        r = math.sqrt(u2)
        lx, ly = r * c, r * s
        lz = math.sqrt(max(ZERO, ONE - u2))
        sg_z = ONE if sz >= ZERO else -ONE
        a = -ONE / (sg_z + sz)
        bq = sx * sy * a
        wix = (ONE + sg_z * sx * sx * a) * lx + bq * ly + sx * lz
        wiy = sg_z * bq * lx + (sg_z + sy * sy * a) * ly + sy * lz
        wiz = -sg_z * sx * lx - sy * ly + sz * lz
        leaves = (wix * fx + wiy * fy + wiz * fz) > ZERO  # on the side of the true surface it arrived
        nbr, nbg, nbb = br * ar, bg * ag, bb * ab
        nmax = max(nbr, max(nbg, nbb))

        # the roulette of the new bounce, and the bounce cap
        qq = min(nmax, F(RR_MAX)) if depth + 1 >= rr_depth else ONE
        go = on & (lz > ZERO) & leaves & (nmax > ZERO) & (rand32(key, base + D_RR) < qq) & (depth + 1 < MAX_BOUNCES)
        inv_q = ONE / max(qq, TINY)
        lf[OX, k], lf[OY, k], lf[OZ, k] = ox, oy, oz
        lf[DX, k] = wix if fast else dx
        lf[DY, k] = wiy if fast else dy
        lf[DZ, k] = wiz if fast else dz
        lf[BR, k] = nbr * inv_q if fast else br
        lf[BG, k] = nbg * inv_q if fast else bg
        lf[BB, k] = nbb * inv_q if fast else bb
        lf[PDF, k] = lz * INV_PI if fast else prev_pdf
        li[DEPTH, k] = np.int32(depth + 1) if fast else depth
        li[DELTA, k] = np.int32(0) if fast else delta
        flags[ALIVE, k] = np.int32(1) if go else np.int32(0)


@kernel
def occlude(fn, scene, scratch, n, sh, flags, lf, r_L0, rec_base):
    """Trace the shadow rays of lanes 0 .. n-1 that have one, 16 to one rtcOccluded16 (fn: each
    chunk of lanes fills its packets with the next 16 it finds), and add the value of each
    unblocked one to its lane's radiance, and where rec_base >= 0 to the L0 of lane k's record
    rec_base + k too (r_L0: guiding.records.Records.L0), so that the radiance recorded along the
    vertex's sampled direction leaves out the vertex's own NEE. Returns how many were traced."""
    L = _LANES
    nch = scratch.shape[0]
    traced = 0
    for c in prange(nch):
        buf = scratch[c]
        ib = buf.view(np.int32)
        addr = buf.ctypes.data
        lane = np.empty(L, np.int64)
        f = 0  # lanes in the packet
        hi = (c + 1) * n // nch
        for i in range(c * n // nch, hi + 1):
            if i < hi and flags[SHADOW, i] != 0:
                put_ray(buf, ib, f, sh, SOX, SDX, i, sh[TMAX, i])
                lane[f] = i
                f += 1
            if f == L or (i == hi and f > 0):
                for k in range(f, L):
                    ib[_VALID * L + k] = 0
                call4(fn, addr + 4 * _VALID * L, scene, addr, 0)
                for k in range(f):
                    if buf[8 * L + k] != -np.inf:  # Embree sets tfar to -inf when blocked
                        j = lane[k]
                        lf[LR, j] += sh[SR, j]
                        lf[LG, j] += sh[SG, j]
                        lf[LB, j] += sh[SB, j]
                        if rec_base >= 0:
                            r_L0[rec_base + j, 0] += sh[SR, j]
                            r_L0[rec_base + j, 1] += sh[SG, j]
                            r_L0[rec_base + j, 2] += sh[SB, j]
                traced += f
                f = 0
    return traced


@kernel
def compact(lf, li, n, flags, L, hole, mover):
    """Keep the lanes 0 .. n-1 that go on (flags[ALIVE]) in lanes 0 .. m-1 and return m: the radiance
    of every other lane is added to its path slot's row of L (float64, which holds what the general
    kernel added there), and each lane that goes on from
    m or past moves, every row, into a hole that an ended one left below m, the k-th mover into the
    k-th hole (hole, mover: int32 scratch of n). The lanes' order changes; what moves is one lane
    per path that ended."""
    counts = np.zeros((_CHUNKS + 1, 2), np.int64)
    for c in prange(_CHUNKS):
        a = 0
        for k in range(c * n // _CHUNKS, (c + 1) * n // _CHUNKS):
            if flags[ALIVE, k] != 0:
                a += 1
            else:
                s = li[SLOT, k]
                L[s, 0] += lf[LR, k]
                L[s, 1] += lf[LG, k]
                L[s, 2] += lf[LB, k]
        counts[c + 1, 0] = a
    for c in range(_CHUNKS):
        counts[c + 1, 0] += counts[c, 0]
    m = counts[_CHUNKS, 0]
    for c in prange(_CHUNKS):
        h = 0
        v = 0
        for k in range(c * n // _CHUNKS, (c + 1) * n // _CHUNKS):
            if k < m:
                h += 1 - flags[ALIVE, k]
            else:
                v += flags[ALIVE, k]
        counts[c + 1, 0] = h
        counts[c + 1, 1] = v
    counts[0, 0] = 0
    for c in range(_CHUNKS):
        counts[c + 1, 0] += counts[c, 0]
        counts[c + 1, 1] += counts[c, 1]
    for c in prange(_CHUNKS):
        h = counts[c, 0]
        v = counts[c, 1]
        for k in range(c * n // _CHUNKS, (c + 1) * n // _CHUNKS):
            if k < m:
                if flags[ALIVE, k] == 0:
                    hole[h] = k
                    h += 1
            elif flags[ALIVE, k] != 0:
                mover[v] = k
                v += 1
    nf = lf.shape[0]
    ni = li.shape[0]
    for r in prange(counts[_CHUNKS, 0]):
        k = mover[r]
        j = hole[r]
        for q in range(nf):
            lf[q, j] = lf[q, k]
        for q in range(ni):
            li[q, j] = li[q, k]
    return m


def run(ctx, buf, n, ps, stats, split=None, record=RECORD_NONE):
    """Trace the n paths the source started in `buf` (wave.WaveBuffers; ps: the source's
    rng.PrimarySamples, supplying none) to their end on the lanes: each path's radiance into
    buf.L, its AOVs and L_cam, as the other path loops leave them; split: a splitting.SplitPlan
    (buf made with split=True) or None. With `record` (guiding.records' RECORD_ALL or
    RECORD_INDIRECT; not with split) the diffuse lanes go to the listed kernel with the glossy
    ones, and the listed and general kernels write the records into buf.records (grown as needed),
    a bounce's m lanes taking m entries as the wavefront's m paths do; returns how many entries
    were used (0 without records).
    stats.trace_parts gets the seconds of the ray queries, the shading (both classes) and the rest;
    stats.lane_samples the paths, stats.lane_general the vertices the general kernel shaded,
    stats.lane_listed the listed kernel's."""
    t0 = time.perf_counter()
    ls = _lane_scene(ctx)
    lanes = getattr(buf, "_lanes", None)
    if lanes is None or lanes.size < buf.capacity:
        lanes = buf._lanes = LaneBuffers(buf.capacity)
    accel = ctx.accel
    scene, _, centre, _, scratch = accel.packet_args()
    lim = _limits(ctx, ls)
    state = buf.path_state(n)
    splitting = split is not None and buf.capacity > buf.size and record == RECORD_NONE
    # the fast kernel leaves the PathState behind, which split_lanes reads, and writes no records
    use_fast = fast_allowed(ctx.guide_state) and not splitting and record == RECORD_NONE
    rec = buf.records
    n_rec = 0
    n_slots = n
    rays = shadows = general = listed = ended = 0
    surf = ctx.surfaces
    part = dict.fromkeys(TRACE_PARTS, 0.0)  # seconds of each step
    clock = time.perf_counter
    lf, li, flags = lanes.f, lanes.i, lanes.flags
    if not splitting:
        lanes.ks[:n] = 1  # no lane ends by the window
    with _NumbaThreads(accel.threads):
        t = clock()
        start(buf.ray_o[:n], buf.ray_d[:n], centre, state, lf, li)
        m = n
        first = True
        while m > 0:
            t1 = clock()
            part["rest"] += t1 - t
            intersect(_INTERSECT16, scene, scratch, lf, m, lanes.hit, lanes.prim)
            rays += m
            t2 = clock()
            part["intersect"] += t2 - t1
            if splitting:
                m, n_slots, e = split_lanes(lf, li, m, lanes.hit, lanes.prim, ctx.surfaces.tri, ctx.tri_normal, state,
                                            ctx.guide_state, split, lanes.ks, buf.parent, n_slots, buf.capacity)
                ended += e
                t = clock()
                part["rest"] += t - t2
                t2 = t
            if record != RECORD_NONE and n_rec + m > rec.strategy.shape[0]:
                rec = buf.records = rec.grown(max(2 * rec.strategy.shape[0], n_rec + m, 4 * n), n_rec)
            ng = nc = 0
            classified = first or not (ls.all_fast and use_fast)
            if classified:  # else only the camera rays' hits (AOVs) need it
                ng, nc = classify(lf, li, m, lanes.hit, lanes.prim, ls.tl, ls.geo, not use_fast, ls.escape_fast,
                                  state, lanes.ks, flags, lanes.fast, lanes.lists)
                ng, nc = int(ng), int(nc)
                first = False
            if ng < m:
                _colours(ls, lanes, m)
                if use_fast:
                    shade(lf, li, m, lanes.hit, lanes.prim, lanes.shadow, flags, lanes.fast, ls.geo, ls.tl, lanes.kd,
                          ls.alias_t, ls.alias_i, lim)
                if nc:
                    shade_listed(lf, li, lanes.hit, lanes.prim, lanes.shadow, flags, lanes.lists[1, :nc],
                                 (ls.geo, ls.tl, lanes.kd), (ls.alias_t, ls.alias_i), lim, surf, state,
                                 ctx.guide_state, centre, rec, (record, n_rec))
                    listed += nc
                if classified:
                    albedo_aov(li, m, lanes.kd, lanes.prim, lanes.fast, state)
            if ng:
                shade_general(lf, li, lanes.hit, lanes.prim, lanes.shadow, flags, lanes.lists[0, :ng], centre,
                              surf, ctx.lights, ctx.guide_state, ps,
                              _general_limits(ctx, record, n_rec), state, rec)
                general += ng
            t3 = clock()
            part["shade"] += t3 - t2
            shadows += occlude(_OCCLUDED16, scene, scratch, m, lanes.shadow, flags, lf, rec.L0,
                               n_rec if record != RECORD_NONE else -1)
            if record != RECORD_NONE:
                n_rec += m
            t = clock()
            part["occluded"] += t - t3
            m = int(compact(lf, li, m, flags, buf.L, lanes.hole, lanes.mover))
        part["rest"] += clock() - t
    if n_slots > n:
        merge_copies(buf.L, buf.parent, n, n_slots)
    stats.split_copies += n_slots - n
    stats.window_ended += ended
    stats.rays += rays
    stats.shadow_rays += shadows
    stats.lane_samples += n
    stats.lane_general += general
    stats.lane_listed += listed
    for name, sec in part.items():
        stats.trace_parts[name] += sec
    stats.tick("trace", t0)
    return n_rec
