"""`--guide odis`: offline deep importance sampling of the first bounce (Bako et al. 2019).

The schedule of a render:

1. Initial pass (`initial` spp of plain BSDF-sampled camera paths). Each first hit's sampled
   direction, the radiance that came back along it and both hits' depth and normal are kept
   (odis_input.initial_samples). With `reuse` (the default, path tracer only) the pass renders
   the image's first spp, at the render's depth, into the final film. Otherwise (and under gpt)
   it is the paper's (section 3.3): max_depth 3, so that what comes back along a first-bounce
   direction is direct plus one-bounce indirect light (the weights' manifest may ask for another
   depth, what their training data was rendered with), into a film of kind "discard" whose
   samples never enter the image.
2. Maps: at every `stride`-th pixel in x and y (the centres), the samples of the k x k pixels
   around it are binned into its 32 x 32 world-space sphere grid (odis_input.gather), and the
   network (odis_net, shipped weights; `auto`: `odis` up to max_depth 3, `odis_full` beyond,
   weights_for) reconstructs the map of every bin, in one batched torch
   call (`maps reference`: probe-traced maps instead, a diagnostic). Each film pixel's map is the
   bilinear blend of its four nearest centres' maps, cut to the hemisphere above its own mean
   first-hit normal, quantised straight into sampling tables (the `directional` layout, one
   fused kernel).
3. Final passes: at the first bounce, one-sample MIS between the pixel's map (probability
   1 - alpha) and the BSDF (alpha; `auto`: 0.5 up to max_depth 3, 0.7 beyond, alpha_for): the
   integrator's per-pixel maps (GuideState.pixel_slot), so the estimate stays unbiased wherever
   the map is wrong. Later bounces sample the BSDF alone.

A pixel with no initial sample of its own (its camera ray escaped, or met a delta BSDF or an
emitter that ended the path) or whose map is zero samples the BSDF alone. If no initial sample
brought light back, or no sample is left after the initial pass, the final passes are plain
BSDF passes, and stats say why (`fallback`).
"""
import copy
import math
import time as _time

import numpy as np
from numba import prange

from ..._jit import jit, kernel
from ...errors import SettingsError, unknown_name
from ..base import Guide, _float, _int
from ..directional import FOUR_PI, MapTables, build_tables, quantised_weight
from .features import _points, first_sample, gather, initial_samples
from ..contract import empty_state

N_THETA = N_PHI = 32
INITIAL_DEPTH = 3  # direct plus one-bounce indirect light at the first hit (weights trained so)
ALPHA_SHALLOW, ALPHA_DEEP = 0.5, 0.7  # alpha auto (OdisGuide.alpha_for); why: docs/odis.md
# weights auto (OdisGuide.weights_for): trained on direct plus one-bounce light, and on all of it
WEIGHTS_SHALLOW, WEIGHTS_DEEP = "odis", "odis_full"
MAPS = ("network", "reference")
CENTRE_CHUNK = 4096  # centres gathered and inferred at a time
SMALL_K, LARGE_K = 11, 21  # the gather window (section 4.3): the larger one below 8 initial spp
SAME_NORMAL = 0.9999  # a pixel whose four centres' normals are this close to its own keeps their masks


BIN_POINTS = _points(N_THETA, N_PHI)


def centre_axis(size, stride):
    """Film coordinates of the centres along one axis: stride // 2, then every `stride`, the last
    one clipped to the film."""
    return np.minimum(np.arange(0, size, stride) + stride // 2, size - 1).astype(np.int64)


@jit(inline="always")
def _blend(cmaps, c, wt, b, same, points, n0, n1, n2):
    """Bin b of the blend of the four centre maps c with weights wt, 0 where the bin lies wholly
    below the plane of normal (n0, n1, n2) (not tested when `same`)."""
    v = wt[0] * cmaps[c[0], b] + wt[1] * cmaps[c[1], b] + wt[2] * cmaps[c[2], b] + wt[3] * cmaps[c[3], b]
    if v > 0.0 and not same:
        for s in range(5):
            if points[b, s, 0] * n0 + points[b, s, 1] * n1 + points[b, s, 2] * n2 > 0.0:
                return v
        return 0.0
    return v


@jit
def _corners(cx, cy, x, y):
    """The four centres around film pixel (x, y) (flat indices into the centre grid) and their
    bilinear weights; clamped at the grid's edges."""
    nx = cx.shape[0]
    ny = cy.shape[0]
    i0 = 0
    tx = 0.0
    if nx > 1:
        i0 = min(max((x - cx[0]) // max(cx[1] - cx[0], 1), 0), nx - 2)
        tx = min(max((x - cx[i0]) / max(cx[i0 + 1] - cx[i0], 1), 0.0), 1.0)
    j0 = 0
    ty = 0.0
    if ny > 1:
        j0 = min(max((y - cy[0]) // max(cy[1] - cy[0], 1), 0), ny - 2)
        ty = min(max((y - cy[j0]) / max(cy[j0 + 1] - cy[j0], 1), 0.0), 1.0)
    i1 = min(i0 + 1, nx - 1)
    j1 = min(j0 + 1, ny - 1)
    c = (j0 * nx + i0, j0 * nx + i1, j1 * nx + i0, j1 * nx + i1)
    wt = ((1.0 - tx) * (1.0 - ty), tx * (1.0 - ty), (1.0 - tx) * ty, tx * ty)
    return c, wt


@jit(inline="always")
def _facing(cnormal, c, n0, n1, n2):
    return cnormal[c, 0] * n0 + cnormal[c, 1] * n1 + cnormal[c, 2] * n2 >= SAME_NORMAL


@jit(inline="always")
def _same_plane(cnormal, c, n0, n1, n2):
    """Whether the four centres' normals all equal (n0, n1, n2) within SAME_NORMAL."""
    return (_facing(cnormal, c[0], n0, n1, n2) and _facing(cnormal, c[1], n0, n1, n2)
            and _facing(cnormal, c[2], n0, n1, n2) and _facing(cnormal, c[3], n0, n1, n2))


@kernel
def _pixel_maps(cmaps, cx, cy, cnormal, width, p0, normal, has, points, out):
    """Maps of film pixels p0 .. p0 + out.shape[0] - 1 (float32, for tests and inspection): the
    bilinear blend of the reconstructed maps cmaps (len(cy) * len(cx), K) at the centres
    (cx[i], cy[j]), zero where the bin lies wholly below the pixel's own normal (unless all four
    centres' normals equal the pixel's: their maps are already cut to that hemisphere). Pixels
    without a sample of their own (`has` false) get zero maps."""
    K = cmaps.shape[1]
    for q in prange(out.shape[0]):
        p = p0 + q
        if not has[p]:
            for b in range(K):
                out[q, b] = 0.0
            continue
        c, wt = _corners(cx, cy, p % width, p // width)
        n0, n1, n2 = normal[p, 0], normal[p, 1], normal[p, 2]
        same = _same_plane(cnormal, c, n0, n1, n2)
        for b in range(K):
            out[q, b] = _blend(cmaps, c, wt, b, same, points, n0, n1, n2)


@kernel
def _pixel_tables(cmaps, cx, cy, cnormal, width, normal, has, points, n_theta, rowcum, dens, wsum, pscale, usable):
    """The sampling tables (directional.MapTables' arrays, one row per film pixel) of the maps
    _pixel_maps gives, without storing them: each pixel's blend is computed twice, once for its
    largest bin and once to quantise (directional.quantised_weight)."""
    K = cmaps.shape[1]
    n_phi = K // n_theta
    for p in prange(dens.shape[0]):
        if not has[p]:
            for b in range(K):
                dens[p, b] = 0
            for r in range(n_theta + 1):
                rowcum[p, r] = 0
            wsum[p] = 0.0
            pscale[p] = 0.0
            usable[p] = False
            continue
        c, wt = _corners(cx, cy, p % width, p // width)
        n0, n1, n2 = normal[p, 0], normal[p, 1], normal[p, 2]
        same = _same_plane(cnormal, c, n0, n1, n2)
        mx = 0.0
        for b in range(K):
            v = _blend(cmaps, c, wt, b, same, points, n0, n1, n2)
            if v > mx and math.isfinite(v):
                mx = v
        total = 0
        rowcum[p, 0] = 0
        for r in range(n_theta):
            for col in range(n_phi):
                b = r * n_phi + col
                w = quantised_weight(_blend(cmaps, c, wt, b, same, points, n0, n1, n2), mx)
                dens[p, b] = w
                total += w
            rowcum[p, r + 1] = total
        wsum[p] = total
        pscale[p] = K / (FOUR_PI * total) if total > 0 else 0.0
        usable[p] = total > 0


def pixel_normals(pix, normal1, n_pixels):
    """(normals (P, 3) unit mean first-hit normal per film pixel, has (P,) bool)."""
    s = np.zeros((n_pixels, 3))
    for c in range(3):
        s[:, c] = np.bincount(pix, weights=normal1[:, c], minlength=n_pixels)
    norm = np.linalg.norm(s, axis=1)
    has = norm > 0.0
    s[has] /= norm[has, None]
    return s, has


class _LuminanceSink:
    """A sample sink that sums each probe's luminance x weight into out[row]."""

    def __init__(self, n):
        self.out = np.zeros(n)

    def add(self, pixel, radiance, aov, weight=None, spread=False):
        # lights.luminance's weights, as a product: the shipped training data was made so, and
        # a different rounding would change its bits
        lum = radiance @ np.array([0.2126, 0.7152, 0.0722])
        if weight is not None:
            lum = lum * weight
        np.add.at(self.out, pixel, lum)


def probe_directions(rng, normal, per_bin, n_theta=N_THETA, n_phi=N_PHI):
    """(directions (n, 3), bin (n,), per): per = s^2 (s = round(sqrt(per_bin))) directions
    stratified and jittered in every bin, those above the plane of `normal` only."""
    K = n_theta * n_phi
    s = max(int(round(np.sqrt(per_bin))), 1)
    g = (np.arange(s) + 0.5) / s
    ss, tt = np.meshgrid(g, g, indexing="ij")
    jitter = rng.random((K, s * s, 2)) - 0.5
    u = np.clip(ss.ravel()[None] + jitter[..., 0] / s, 0, 1)
    v = np.clip(tt.ravel()[None] + jitter[..., 1] / s, 0, 1)
    k = np.arange(K)[:, None]
    z = -1.0 + ((k // n_phi) + u) * (2.0 / n_theta)
    phi = -np.pi + ((k % n_phi) + v) * (2.0 * np.pi / n_phi)
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1).reshape(-1, 3)
    b = np.repeat(np.arange(K), s * s)
    up = d @ normal > 1e-6
    return d[up], b[up], s * s


def reference_maps(ctx, points, normals, per_bin, rng, seed):
    """Incident radiance maps (m, N_THETA, N_PHI) at surface points (m, 3) with unit normals (m, 3):
    per bin, the mean luminance that per_bin probe rays (stratified in the bin, above the surface;
    bins below it read 0) bring back, each a path of ctx's max_depth from the point (tracer.sources.
    ProbeSource; ctx.max_depth 2: the first hit's emission and its direct light). Probes start
    16 x the median ray offset above the surface. rng (a numpy Generator) jitters the directions;
    the probes' keys derive from `seed` and the point's index."""
    from ...session import trace_source
    from ...sources import ProbeSource
    from ...wave import WaveBuffers

    eps = 16.0 * float(np.median(ctx.tri_eps))
    out = np.zeros((points.shape[0], N_THETA * N_PHI), np.float32)
    buf = WaveBuffers(1 << 15)
    for m in range(points.shape[0]):
        nrm = normals[m]
        dirs, bins, per = probe_directions(rng, nrm, per_bin)
        o = np.repeat((points[m] + eps * nrm)[None], dirs.shape[0], axis=0)
        with np.errstate(over="ignore"):  # the keys wrap around 2^64 on purpose
            keys = (np.uint64(int(seed) * 1_000_003 + m) * np.uint64(0x9E3779B97F4A7C15)
                    + np.arange(dirs.shape[0], dtype=np.uint64))
        sink = _LuminanceSink(dirs.shape[0])
        trace_source(ctx, ProbeSource(o, dirs, keys), sink, buf=buf)
        out[m] = np.bincount(bins, weights=sink.out, minlength=N_THETA * N_PHI) / per
    return out.reshape(-1, N_THETA, N_PHI)


class OdisGuide(Guide):
    """`--guide odis`: the first bounce sampled from incident-radiance maps that a network trained
    offline reconstructs from an initial pass (Bako et al. 2019)."""

    pixel_maps = True

    name = "odis"
    learns = False  # the initial pass records vertices, but nothing is learned per scene
    # the initial pass records on the wavefront: reused in the image, its samples are then a plain
    # render's with tracer.rng's numbers, bit for bit (tests/guiding/test_odis.py)
    records_loop = "wave"
    # memory (tracer.memory): the per-pixel sampling tables (32 x 32 uint16 densities and row sums,
    # 2.2 KB), the initial pass's film and samples; bench.memory measured 2662-2791 B/px in all
    # (2380-2570 beyond bsdf's), and 250 MB fixed (torch, the network)
    pixel_bytes = 3300
    fixed_bytes = 384 << 20
    DEFAULTS = {"initial": 1, "k": "auto", "stride": 8, "alpha": "auto", "weights": "auto", "batch": 128,
                "maps": "network", "reference_per_bin": 16, "reuse": 1}

    def __init__(self, **settings):
        s = dict(self.DEFAULTS, **settings)
        self.initial = _int("initial", s["initial"], 1)
        if s["k"] == "auto":
            self.k = None
        else:
            self.k = _int("k", s["k"], 1)
            if self.k % 2 == 0:
                raise SettingsError(f"guide setting k must be odd, got {self.k}")
        self.stride = _int("stride", s["stride"], 1)
        # > 0: the BSDF covers what the map cuts; auto: ALPHA_SHALLOW or ALPHA_DEEP (alpha_for)
        self.alpha = None if s["alpha"] == "auto" else _float("alpha", s["alpha"], 1e-3, 1.0)
        if not isinstance(s["weights"], str) or not s["weights"]:
            raise SettingsError(f"guide setting weights must be the name of shipped weights, got {s['weights']!r}")
        self.weights = s["weights"]
        self.batch = _int("batch", s["batch"], 1)
        if s["maps"] not in MAPS:
            raise unknown_name("guide setting maps", s["maps"], MAPS)
        self.maps = s["maps"]
        self.reference_per_bin = _int("reference_per_bin", s["reference_per_bin"], 1)
        if s["reuse"] not in (0, 1) or isinstance(s["reuse"], bool):
            raise SettingsError(f"guide setting reuse must be 0 or 1, got {s['reuse']!r}")
        self.reuse = bool(s["reuse"])
        self.settings = s
        self.model = None
        self._loaded = None  # (name, model) of the weights _load loaded (a model set from outside is kept)
        self._render_depth = -1
        self._state = empty_state(N_THETA, N_PHI)
        self._stats = {}

    # the contract
    def prepare(self, scene, ctx):
        """A new render: forget the last render's maps and statistics."""
        self.ctx = ctx
        self._render_depth = ctx.max_depth
        self._state = empty_state(N_THETA, N_PHI)
        self._samples = []
        self._waves = []
        self._stats = {}
        self.time_learning = self.time_inference = 0.0
        self.peak_memory = 0

    def warm_up(self, ctx):
        """Load the network and compile the gather and map kernels (outside the render's clock)."""
        self.ctx = ctx
        self._render_depth = ctx.max_depth
        self._load()
        rng = np.random.default_rng(0)
        d = rng.normal(size=(4, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        s = {"pix": np.array([0, 1, 2, 3]), "x": np.zeros((4, 3)), "dirs": d, "radiance": np.ones(4), "depth1": np.ones(4),
             "normal1": np.tile([0.0, 0.0, 1.0], (4, 1)), "depth2": np.ones(4), "normal2": -d}
        self._maps(s, 2, 2)

    def state(self):
        return self._state

    def pixel_state(self, sampling_map, n_pixels=1):
        """A state in which each of n_pixels film pixels samples its first bounce from
        `sampling_map` (n_theta, n_phi) with this guide's alpha, and nothing else is guided (for
        the sampler contract tests)."""
        m = np.asarray(sampling_map, dtype=np.float64)
        t = build_tables(m[None])
        slot = np.zeros(n_pixels, np.int32) if t.usable[0] else np.full(n_pixels, -1, np.int32)
        return empty_state(m.shape[0], m.shape[1])._replace(
            rowcum=t.rowcum, dens=t.dens, wsum=t.wsum, pscale=t.pscale, pixel_slot=slot,
            pixel_alpha=np.full(n_pixels, self.alpha_for(INITIAL_DEPTH)))

    def weights_for(self, max_depth):
        """The shipped weights a render of `max_depth` uses: the setting, or with `auto`
        WEIGHTS_SHALLOW up to INITIAL_DEPTH (trained on direct plus one-bounce light) and
        WEIGHTS_DEEP beyond it and at no limit (trained on initial passes and probes of the scene's
        whole depth)."""
        if self.weights != "auto":
            return self.weights
        return WEIGHTS_SHALLOW if 0 < max_depth <= INITIAL_DEPTH else WEIGHTS_DEEP

    def _load(self):
        """The network for the current render's depth (loaded once per weights; a model set from
        outside, with its manifest, is kept)."""
        name = self.weights_for(self._render_depth)
        own = self._loaded is not None and self._loaded[1] is self.model
        if self.model is None or (own and self._loaded[0] != name):
            from . import net as odis_net

            self.model, self.manifest = odis_net.load(name)
            self._loaded = (name, self.model)
        return self.model

    def initial_depth(self):
        """The initial pass's max_depth: what the weights were trained on (their manifest's
        data config; 0: the render's own)."""
        self._load()
        return int(self.manifest.get("data", {}).get("config", {}).get("initial_depth", INITIAL_DEPTH))

    def alpha_for(self, max_depth):
        """The probability of BSDF sampling at the first bounce of a render of `max_depth`: the
        setting, or with `auto` ALPHA_SHALLOW up to the network's INITIAL_DEPTH (its maps hold all
        the light there is) and ALPHA_DEEP beyond it (the light of later bounces, which the
        network never saw, is left more to the BSDF)."""
        if self.alpha is not None:
            return self.alpha
        return ALPHA_SHALLOW if 0 < max_depth <= INITIAL_DEPTH else ALPHA_DEEP

    def reuses(self, session):
        """Whether the initial pass renders into the image (`reuse`, with the path tracer's own
        final film): it then traces the render's own paths, to the render's depth, and the maps
        are reconstructed from all the light those paths bring back along their first bounce."""
        return self.reuse and session.integrator.film_kind == "final"  # the path tracer's film (not gpt's)

    def window_size(self):
        """The gather window k: the setting, or by the initial spp (section 4.3)."""
        if self.k is not None:
            return self.k
        return LARGE_K if self.initial < 8 else SMALL_K

    def schedule(self, session):
        ctx = session.ctx
        n0 = self.initial if session.time is not None else min(self.initial, session.spp - 1)
        reason = None
        if n0 < 1:
            reason = "no samples left for an initial pass"
        else:
            session.phase("initial")
            total = ctx.n_pixels * n0
            size = session.buf.size
            self._waves = [min(size, total - g0) for g0 in range(0, total, size)]
            saved = self._render_depth = ctx.max_depth
            reuse = self.reuses(session)
            if reuse:  # the render's own paths: their samples are the image's
                film = session.final_film()
            else:
                film = session.new_film("discard")
                depth = self.initial_depth()
                ctx.max_depth = saved if depth <= 0 else depth if saved < 0 else min(saved, depth)
            self._stats["initial_reused"] = reuse
            try:
                # observe, then update builds the maps
                session.run_pass(film, n0, "initial", learn=True, path_loop=self.records_loop)
            finally:
                ctx.max_depth = saved
            reason = self._stats.get("fallback")
        self._stats["fallback"] = reason
        session.final_passes()  # (at least 2 spp, even when the initial pass took the whole budget)

    def observe(self, rec):
        """The first hits of one wave of the initial pass (copied: the buffer is reused)."""
        t0 = _time.perf_counter()
        n = self._waves.pop(0)  # this wave's paths: trace_source's split of the pass, predicted in schedule
        head = rec.strategy[:n] >= 0
        if n > rec.strategy.shape[0] or np.any(rec.path[:n][head] != np.flatnonzero(head)):
            raise RuntimeError("odis: the initial pass's waves are out of step with its records")
        self._samples.append(initial_samples(rec, n, self.ctx.scene.camera.origin))
        self.time_learning += _time.perf_counter() - t0

    def update(self):
        """After the initial pass: gather, infer, and build every pixel's sampling table."""
        t0 = _time.perf_counter()
        inf0 = self.time_inference
        parts, self._samples = [p for p in self._samples if p["pix"].shape[0]], []
        if not parts:
            self._stats["fallback"] = "no initial sample sampled a direction"
            return
        s = {f: np.concatenate([p[f] for p in parts]) for f in parts[0]}
        self._stats.update(initial_samples=int(s["pix"].shape[0]),
                           initial_lit=int(np.count_nonzero(s["radiance"] > 0)))
        if not np.any(s["radiance"] > 0):
            self._stats["fallback"] = "no initial sample brought light back"
            return
        w, h = int(self.ctx.crop[2]), int(self.ctx.crop[3])
        tables, usable = self._maps(s, w, h)
        slot = np.where(usable, np.arange(w * h), -1).astype(np.int32)
        self._state = empty_state(N_THETA, N_PHI)._replace(
            rowcum=tables.rowcum, dens=tables.dens, wsum=tables.wsum, pscale=tables.pscale, pixel_slot=slot,
            pixel_alpha=np.full(w * h, self.alpha_for(self._render_depth)))
        self.peak_memory = self.memory_bytes()
        self._stats.update(pixels_guided=int(usable.sum()), pixels=w * h)
        self.time_learning += _time.perf_counter() - t0 - (self.time_inference - inf0)

    def _maps(self, s, w, h):
        """(MapTables of the P = w h film pixels, usable (P,)) from the initial samples s."""
        from . import net as odis_net

        model = self._load()
        cx, cy = centre_axis(w, self.stride), centre_axis(h, self.stride)
        centres = (cy[:, None] * w + cx[None, :]).ravel()
        cmaps = np.empty((centres.size, N_THETA, N_PHI), np.float32)
        filled = total = 0
        for c0 in range(0, centres.size, CENTRE_CHUNK):  # bounded memory: 76 KB of input per centre
            c = centres[c0:c0 + CENTRE_CHUNK]
            feats, sampled, valid = gather(s["pix"], s["dirs"], s["radiance"], s["depth1"], s["normal1"],
                                           s["depth2"], s["normal2"], w, h, c, k=self.window_size(),
                                           n_theta=N_THETA, n_phi=N_PHI)
            filled += int(((sampled > 0) & (valid > 0)).sum())
            total += int(valid.sum())
            t0 = _time.perf_counter()
            if self.maps == "network":
                cmaps[c0:c0 + c.size] = odis_net.radiance_maps(model, odis_net.features(feats, sampled, valid), valid,
                                                               batch=self.batch)
            else:
                cmaps[c0:c0 + c.size] = self._reference(s, c, w * h, c0) * valid
            self.time_inference += _time.perf_counter() - t0
        self._stats.update(centres=int(centres.size), window=self.window_size(),
                           centre_sparsity=float(filled / max(total, 1)))
        normal, has = pixel_normals(s["pix"], s["normal1"], w * h)
        cmaps = np.ascontiguousarray(cmaps.reshape(centres.size, -1), np.float32)
        P = w * h
        out = MapTables(np.empty((P, N_THETA + 1), np.uint32), np.empty((P, N_THETA * N_PHI), np.uint16),
                        np.empty(P), np.empty(P), np.empty(P, np.bool_))
        _pixel_tables(cmaps, cx, cy, np.ascontiguousarray(normal[centres]), w, normal, has, BIN_POINTS, N_THETA,
                      *out)
        return out, out.usable

    def _reference(self, s, centres, n_pixels, c0=0):
        """`maps reference`: probe-traced incident radiance at one first hit of each centre (the
        ground truth the network learns, at the render's depth less one: a diagnostic of what
        perfect maps would give; zero at centres without a sample)."""
        j = first_sample(s["pix"], n_pixels)[centres]
        ok = j >= 0
        pctx = copy.copy(self.ctx)
        depth = self._render_depth
        pctx.max_depth = depth - 1 if depth > 1 else -1
        out = np.zeros((centres.size, N_THETA, N_PHI), np.float32)
        seed = self.ctx.seed * 4099 + c0  # distinct probes for every chunk of centres
        out[ok] = reference_maps(pctx, s["x"][j[ok]], s["normal1"][j[ok]], self.reference_per_bin,
                                 np.random.default_rng(seed), seed)
        return out

    def memory_bytes(self):
        st = self._state
        return int(st.rowcum.nbytes + st.dens.nbytes + st.wsum.nbytes + st.pscale.nbytes + st.pixel_slot.nbytes
                   + st.pixel_alpha.nbytes)

    def stats(self):
        out = dict(self._stats)
        out.update(name=self.name, settings=dict(self.settings), inference_s=self.time_inference)
        if self.model is not None:
            out["parameters"] = int(self.manifest.get("parameters", 0))
            out["weights"] = self.manifest.get("name")
        return out
