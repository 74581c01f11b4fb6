"""Splitting and the weight window: where a guided path goes on as several copies, or ends early.

A guide makes overweight paths: its mixture weighs a BSDF-sampled direction p_bsdf / p_mixture,
up to 1 / a, where the map is thin, and these factors multiply along the path (BSDF sampling alone
keeps beta <= 1 / 0.95). At each surface hit after the first bounce of a final pass, a `SplitPlan`
(the one channel from a method to tracer.integrator.trace_wave) decides how many copies a path
goes on as:

- The weight window (Vorba and Krivanek 2016, adjoint-driven Russian roulette and splitting),
  where the guide's voxel has an estimate `outgoing` of the radiance a path arriving there goes on
  to collect: the path's expected share of its pixel's value `pixel_est` is q = lum(beta) outgoing
  / pixel_est. Above `hi` it splits into ceil(q / hi) copies (SPLIT_MAX at most), below `low` it
  survives a roulette with probability max(q / low, WINDOW_MIN_SURVIVAL).
- Throughput splitting, where there is no window estimate: a path whose throughput (max channel)
  exceeds `threshold` goes on as min(ceil(max beta), SPLIT_MAX) copies.

A path split into k copies gives each throughput beta / k and its own key (rng.split_key); each
samples its own rest of the path, and their radiance adds up to the path's one sample. Whether a
path splits or survives never depends on its own future, so the estimate stays unbiased. Copies
are made only where the wave buffer has room.

`WeightWindow` is the part a guide owns: the settings, the outgoing statistics per voxel
(learned from the training passes' records), the pixel estimate (from the training passes'
image), and `plan()`, which makes the SplitPlan of the final passes.
"""
import math
from typing import NamedTuple

import numpy as np
from numba import prange

from ._jit import jit, kernel
from .errors import SettingsError
from .film import combine_films
from .guiding.contract import find_voxel
from .lights import luminance
from .rng import split_key, uniform
from .sampling import triangle_point

OUT_MIN_SAMPLES = 8  # camera vertices a leaf needs before its outgoing mean is trusted
# the largest relative standard error of a pixel estimate the window trusts: a pixel whose few
# training samples missed the light (estimate far too low) would split every path into SPLIT_MAX
# copies, one whose samples held a firefly would roulette them (photon on `ajar` at 5 s, training
# films of 2 + 2 spp: relMSE 0.58-2.18 with the window, 0.12-0.14 without, 0.08-0.17 with the
# reference image as the pixel estimate); such pixels' paths get no window
PIXEL_REL_ERR = 0.5
# window_spp's default: the final passes play the window only once the training passes (pilot
# included) hold this many samples a pixel. On ajar at 5 s photon's films hold 1-4 and the window
# loses to none (relMSE 0.36-0.46 against 0.12-0.14); with no window below 8, 0.13-0.17 at 5 s,
# while at 12 s (12-15 spp of films) ajar keeps the window's gain (0.038-0.042 against bsdf's 0.054)
WINDOW_SPP = 8.0


SPLIT_MAX = 8  # copies a path is split into at most
WINDOW_MIN_SURVIVAL = 0.05  # the weight window's roulette keeps a path with at least this probability
# window_low "auto", by whether the render uses next-event estimation (docs/guiding.md, "The weight
# window"). With NEE, pixels lit mostly directly make every indirect path look worth little, and a
# high bound ends too many of them (Cornell box, staircase); without NEE every path's value is in
# what it goes on to hit, and 0.2 ends the dim ones sooner: photon's relMSE at equal time 0.75-0.81x
# that of 0.05 on NEE-off veach-ajar and classroom-sky, 0.99x on dining-room-sky.
WINDOW_LOW = {True: 0.05, False: 0.2}
WINDOW_AUTO = {True: 0.0, False: 3.0}  # window "auto" (grid): on without NEE only


@jit(inline="always")
def split_count(k, active, ray_d, hit, geo, beta, gain, path, gs, window):
    """split_counts for entry k; after the window's roulette it divides its path's beta and gain
    (the arrays it writes). Read-only tuples: hit = (prim, b1, b2) of the entries, geo = (tri,
    tri_normal), path = (depth, pix, key) of the paths, window = the SplitPlan's (outgoing,
    pixel_est, hi, low, threshold); callers build them at the call, never as a kernel's bound name."""
    prim, b1, b2 = hit
    tri, tri_normal = geo
    depth, pix, key = path
    outgoing, pixel_est, hi, low, threshold = window
    i = active[k]
    p = prim[k]
    if p < 0 or depth[i] < 1:
        return 1
    if hi > 0.0:
        x = triangle_point(tri, p, b1[k], b2[k])
        ng = (tri_normal[p, 0], tri_normal[p, 1], tri_normal[p, 2])
        arriving = -(ray_d[k, 0] * ng[0] + ray_d[k, 1] * ng[1] + ray_d[k, 2] * ng[2]) >= 0.0
        nf = ng if arriving else (-ng[0], -ng[1], -ng[2])
        node = find_voxel(gs, x, nf)
        if node >= 0 and outgoing[node] > 0.0 and pix[i] >= 0 and pixel_est[pix[i]] > 0.0:
            q = (0.2126 * beta[i, 0] + 0.7152 * beta[i, 1] + 0.0722 * beta[i, 2]) * outgoing[node] / pixel_est[pix[i]]
            if q > hi:
                return min(int(math.ceil(q / hi)), SPLIT_MAX)
            if q < low:
                ps = max(q / low, WINDOW_MIN_SURVIVAL)
                if uniform(split_key(key[i], depth[i], 0), 0) >= ps:
                    return 0
                for c in range(3):
                    beta[i, c] /= ps
                gain[i] /= ps
            return 1
    if threshold > 0.0:
        bm = max(beta[i, 0], max(beta[i, 1], beta[i, 2]))
        if bm > threshold:
            return min(int(math.ceil(bm)), SPLIT_MAX)
    return 1


@kernel
def split_counts(active, ray_d, hits, tri, tri_normal, state, gs, plan, ks):
    """ks[k]: how many copies entry k's path goes on as (0: it ends here), for a path that hit a
    surface after its first bounce; 1 elsewhere. hits = (t, prim, b1, b2) of the entries; state:
    the wave.PathState; plan: the SplitPlan.

    Weight window (plan.hi > 0), where the guide's voxel has an outgoing radiance estimate Lo and
    the path's pixel an estimate I (pixel_est, 0 where unknown): the
    path's expected share of its pixel is q = lum(beta) Lo / I (I = pixel_est of its pixel). Above
    hi it splits into min(ceil(q / hi), SPLIT_MAX) copies; below low it survives a roulette with
    probability max(q / low, WINDOW_MIN_SURVIVAL), its beta and gain divided by that (here, in
    place). Elsewhere (no window, or no estimate): throughput splitting, min(ceil(max beta),
    SPLIT_MAX) copies where max beta > threshold > 0. Returns (sum of ks, entries with ks 0)."""
    prim = hits[1]
    b1 = hits[2]
    b2 = hits[3]
    beta = state.beta
    gain = state.gain
    depth = state.depth
    pix = state.pix
    key = state.key
    outgoing = plan.outgoing
    pixel_est = plan.pixel_est
    hi = plan.hi
    low = plan.low
    threshold = plan.threshold
    wanted = 0
    ended = 0
    for k in prange(active.shape[0]):
        m = split_count(k, active, ray_d, (prim, b1, b2), (tri, tri_normal), beta, gain, (depth, pix, key), gs,
                        (outgoing, pixel_est, hi, low, threshold))
        ks[k] = m
        wanted += m
        if m == 0:
            ended += 1
    return wanted, ended


@jit(inline="always")
def _copy_entry(k, e, t, prim, b1, b2, t2, prim2, b12, b22, ray_o, ray_d):
    """Wave entry k's hit (t, prim, b1, b2) to entry e of (t2, prim2, b12, b22), and its ray."""
    t2[e] = t[k]
    prim2[e] = prim[k]
    b12[e] = b1[k]
    b22[e] = b2[k]
    for c in range(3):
        ray_o[e, c] = ray_o[k, c]
        ray_d[e, c] = ray_d[k, c]


@jit(inline="always")
def make_copy(i, s, j, beta, gain, L, depth, prev_pdf, prev_delta, key, pix, prev_rec, parent):
    """Path slot s becomes copy j (>= 1) of path i, at its current vertex: i's throughput and gain
    (already divided among the copies), no radiance yet, its own key, and parent i."""
    for c in range(3):
        beta[s, c] = beta[i, c]
        L[s, c] = 0.0
    gain[s] = gain[i]
    depth[s] = depth[i]
    prev_pdf[s] = prev_pdf[i]
    prev_delta[s] = prev_delta[i]
    key[s] = split_key(key[i], depth[i], j)
    pix[s] = pix[i]
    prev_rec[s] = -1
    parent[s] = i


@jit
def split_paths(active, ks, hits, hits2, ray_o, ray_d, state, parent, n_slots, capacity):
    """Apply split_counts: entries with ks 0 leave the wave (their paths end; what they gathered
    stays in L); entry k's path becomes ks[k] copies with beta / ks[k] and gain / ks[k] each (so
    Russian roulette, which looks at beta / gain, treats them as it would the path), fewer where
    fewer than ks[k] - 1 path slots or wave entries are left below `capacity`. The kept entries'
    rays and hits (hits = (t, prim, b1, b2) into hits2, which has room for the copies) move
    to the front; copies take path slots from n_slots on and the entries after the kept ones, with
    the entry's ray and hit, L = 0, a key of their own, and parent = the path whose sample they add
    to. Returns (entries, path slots) in use. Sequential: slots are handed out in order, so a render
    does not depend on the thread count. state: the wave.PathState."""
    t = hits[0]
    prim = hits[1]
    b1 = hits[2]
    b2 = hits[3]
    t2 = hits2[0]
    prim2 = hits2[1]
    b12 = hits2[2]
    b22 = hits2[3]
    beta = state.beta
    gain = state.gain
    L = state.L
    depth = state.depth
    prev_pdf = state.prev_pdf
    prev_delta = state.prev_delta
    key = state.key
    pix = state.pix
    prev_rec = state.prev_rec
    n_active = ks.shape[0]
    e = 0
    for k in range(n_active):
        if ks[k] == 0:
            continue
        active[e] = active[k]
        ks[e] = ks[k]
        _copy_entry(k, e, t, prim, b1, b2, t2, prim2, b12, b22, ray_o, ray_d)
        e += 1
    kept = e
    s = n_slots
    for k in range(kept):
        m = min(ks[k], capacity - s + 1, capacity - e + 1)
        if m <= 1:
            continue
        i = active[k]
        for c in range(3):
            beta[i, c] /= m
        gain[i] /= m
        for j in range(1, m):
            active[e] = s
            _copy_entry(k, e, t2, prim2, b12, b22, t2, prim2, b12, b22, ray_o, ray_d)
            make_copy(i, s, j, beta, gain, L, depth, prev_pdf, prev_delta, key, pix, prev_rec, parent)
            e += 1
            s += 1
    return e, s


@jit
def merge_copies(L, parent, n, n_slots):
    """Add the radiance of copies (slots n .. n_slots - 1) into the paths they were split from, the
    latest first (a copy may be the parent of a later one)."""
    for j in range(n_slots - 1, n - 1, -1):
        p = parent[j]
        for c in range(3):
            L[p, c] += L[j, c]


class SplitPlan(NamedTuple):
    """What the final passes split by (see the module docstring); trace_wave's `split`."""

    threshold: float  # throughput splitting above this max(beta) (0: off)
    outgoing: np.ndarray  # (N,) float64 per guide node, the window's outgoing radiance (0: unknown)
    pixel_est: np.ndarray  # (P,) float64 per film pixel, its estimated value (0: unknown, no window)
    hi: float  # window: split above this share of the pixel (0: no window)
    low: float  # window: roulette below this share


def throughput_plan(threshold):
    """A SplitPlan of throughput splitting alone."""
    return SplitPlan(float(threshold), np.zeros(1), np.ones(1), 0.0, 0.0)


@jit
def _outgoing_stats(node, strategy, prev, radiance, out_sum, out_n):
    for r in range(node.shape[0]):
        nd = node[r]
        p = prev[r]
        if nd < 0 or strategy[r] < 0 or p < 0:
            continue
        out_sum[nd] += radiance[p]
        out_n[nd] += 1.0


def observe_outgoing(grid, rec):
    """Add a wave's records (a Records view) to the leaves' outgoing radiance (grid.out_sum,
    grid.out_n, which split with the tree): a record's vertex sent back the radiance that its
    path's previous record received along its direction."""
    _outgoing_stats(rec.node, rec.strategy, rec.prev, rec.radiance, grid.out_sum, grid.out_n)


def outgoing(grid, min_samples=OUT_MIN_SAMPLES):
    """(n_nodes,) float64: per leaf of `grid`, the mean luminance of the radiance that camera paths
    arriving there went on to collect, where at least `min_samples` arrived; else 0 (unknown)."""
    n = grid.n_nodes
    c = grid.out_n[:n]
    return np.where(c >= min_samples, grid.out_sum[:n] / np.maximum(c, 1.0), 0.0)


class WeightWindow:
    """A guide's splitting settings and what its window learns.

    split: throughput splitting threshold (0 off, else >= 1); window, window_low: the window's
    bounds hi and low as shares of the pixel (window 0: off); "auto" for either is resolved by
    resolve() for the render (WINDOW_AUTO, WINDOW_LOW; until then an auto window counts as on, so
    that wave buffers sized before it keep room for copies). `pixel_est` is set by plan() from the
    training passes' image and kept, so that a frozen copy of the guide can plan final passes
    without training passes of its own. window_spp: the samples a pixel the training passes must
    hold before the final passes play the window (fewer: no window, `held_back` set by plan())."""

    def __init__(self, split=0.0, window=0.0, window_low=0.0, window_spp=WINDOW_SPP):
        self.split = float(split)
        self.window_spp = float(window_spp)
        self.held_back = False
        self.window_auto = window == "auto"
        self.window = WINDOW_AUTO[False] if self.window_auto else float(window)
        self.low_auto = window_low == "auto"
        self.window_low = WINDOW_LOW[True] if self.low_auto else float(window_low)
        if 0.0 < self.split < 1.0:
            raise SettingsError(f"guide setting split must be 0 (off) or at least 1, got {split!r}")
        lows = WINDOW_LOW.values() if self.low_auto else (self.window_low,)
        if self.window > 0.0 and not all(w < self.window for w in lows):
            raise SettingsError(f"guide setting window_low ({window_low!r}"
                                + (f": {' or '.join(map(str, lows))}" if self.low_auto else "")
                                + f") must be below window ({window!r})")
        self.pixel_est = None

    def resolve(self, nee):
        """For a render with (nee True) or without next-event estimation: window "auto" becomes
        WINDOW_AUTO[nee], window_low "auto" WINDOW_LOW[nee]; the window_low in use."""
        if self.window_auto:
            self.window = WINDOW_AUTO[bool(nee)]
        if self.low_auto:
            self.window_low = WINDOW_LOW[bool(nee)]
        return self.window_low

    @property
    def active(self):
        """Whether final passes may split (the wave buffers then need room for copies)."""
        return self.split > 0.0 or self.window > 0.0

    def plan(self, outgoing_est, films, crop):
        """The SplitPlan of the final passes, or None (nothing to split by). outgoing_est: the
        guide's per-node outgoing radiance (outgoing()), or None; films: the training passes'
        films, whose combined image becomes the pixel estimate (pixel_estimate) once they hold
        window_spp samples a pixel; with fewer the plan has no window (the throughput plan of
        `split`, if on). No films (a frozen copy): the estimate kept from the last plan."""
        if not self.active:
            return None
        w, h = int(crop[2]), int(crop[3])
        window = None
        if self.window > 0.0 and outgoing_est is not None and (outgoing_est > 0.0).any():
            held = sum(float(f.count.sum()) for f in films) / (w * h)  # samples a pixel
            if held > 0.0:
                self.held_back = held < self.window_spp
                self.pixel_est = None if self.held_back else pixel_estimate(films, w, h)
            if self.pixel_est is not None and self.pixel_est.shape[0] == w * h:
                window = (np.ascontiguousarray(outgoing_est, dtype=np.float64), self.pixel_est)
        if window is None:
            return throughput_plan(self.split) if self.split > 0.0 else None
        return SplitPlan(self.split, window[0], window[1], self.window, self.window_low)


def pixel_estimate(films, w, h):
    """The window's pixel estimate from the training passes' films (w x h pixels): per pixel the
    3x3 box mean of the combined image's luminance, at least 1% of the image's mean, so that pixels
    that happened to get no light yet do not ask for every path to split; 0 (unknown: the pixel's
    paths get no window) where the box mean's standard error exceeds PIXEL_REL_ERR of it, the
    channels' errors taken as fully correlated. None where the image is black."""
    image, var, _ = combine_films(films, ["train"] * len(films))
    lum = luminance(image[..., :3])
    lum = np.where(np.isfinite(lum), np.maximum(lum, 0.0), 0.0)
    sd = luminance(np.sqrt(np.where(np.isfinite(var[..., :3]), np.maximum(var[..., :3], 0.0), np.inf)))
    floor = 0.01 * float(lum.mean())
    if not floor > 0.0:
        return None

    def box(a):
        padded = np.pad(a, 1, mode="edge")
        return sum(padded[1 + dy: 1 + dy + h, 1 + dx: 1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1)) / 9.0

    est = np.maximum(box(lum), floor)
    err = np.sqrt(box(sd * sd) / 9.0)  # standard error of the box mean of independent pixels
    return np.where(err <= PIXEL_REL_ERR * est, est, 0.0).ravel()


def split_wave(buf, active, n_active, n_slots, hits, rd, ctx, plan, stats):
    """Apply `plan` to the entries of one bounce: returns (active entries, path slots in use, hit
    arrays (t, prim, b1, b2) of the kept entries and copies). Unchanged when nothing splits or ends."""
    t, prim, b1, b2 = hits
    ks = buf.ks[:n_active]
    wanted, ended = split_counts(active[:n_active], rd, hits, ctx.scene.tri, ctx.tri_normal, buf.path_state(),
                                 ctx.guide_state, plan, ks)
    if wanted == n_active and ended == 0:
        return n_active, n_slots, hits
    hit2 = buf.copy_hits(t, prim, b1, b2)
    n_e, n_s = split_paths(active, ks, hits, hit2, buf.ray_o, buf.ray_d, buf.path_state(), buf.parent, n_slots,
                           buf.capacity)
    stats.split_copies += n_s - n_slots
    stats.window_ended += ended
    return n_e, n_s, tuple(a[:n_e] for a in hit2)


def warm_up_plan():
    """A SplitPlan that splits and plays the window: the types every plan has, for warm-ups."""
    return SplitPlan(1.0, np.zeros(1), np.ones(1), 1.0, 0.1)


def warm_up_splitting(ctx):
    """Compile (or load from the cache) the splitting kernels on a tiny wave of ctx's scene."""
    from .wave import WaveBuffers

    buf = WaveBuffers(1, split=True)
    ks = buf.ks[:1]
    e = (np.zeros(1), np.full(1, -1, np.int32), np.zeros(1), np.zeros(1))
    split_counts(buf.active[:1], buf.ray_d[:1], e, ctx.scene.tri, ctx.tri_normal, buf.path_state(), ctx.guide_state,
                 warm_up_plan(), ks)
    split_paths(buf.active, ks, e, e, buf.ray_o, buf.ray_d, buf.path_state(), buf.parent, 1, buf.capacity)
    merge_copies(buf.L, buf.parent, 1, 1)
    _outgoing_stats(np.zeros(1, np.int32), np.zeros(1, np.int8), np.zeros(1, np.int64), np.zeros(1, np.float32),
                    np.zeros(1), np.zeros(1))
