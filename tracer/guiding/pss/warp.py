"""`--guide pss`: a Real NVP warp of the path prefix in primary sample space (Zheng & Zwicker 2019).

The schedule of a render:

1. Candidate pass (`candidates` spp, the camera with the ordinary stream): every sample's
   luminance is kept, and its primary sample y (the pixel position and the direction dims of the
   first two bounces, rng.pss_dims(2)) is recomputed from its key. This pass is a plain `bsdf`
   pass and stays in the image.
2. Learning (torch, CPU): the candidate set T is split 80/20 by sample, each part resampled in
   proportion to luminance into S (|T| = alpha |S|, systematic resampling), and Real NVP flows
   (tracer.guiding.pss.flow) are fitted by maximum likelihood (Adam) to S. With `m`, `layers` or
   `width` "auto", every candidate of M_CHOICES x SIZES trains for half the budget split among them,
   and the one of least validation NLL takes the other half.
3. Warped passes (the final passes): per wave, z uniform (a stream of its own), one sample in
   `defensive` keeps z as y (uniform), the others take y = Psi(z); every y gets the mixture density
   q(y) = (1 - e) p_warp(y) + e (p_warp through the inverse flow for the uniform ones) and the
   weight 1 / q(y), and enters the camera through the sample seam (sources, rng.draw).
   condition="image" warps the pixel position too (samples move between pixels; the film
   estimates each pixel as (P / N) x the sum of weight x value of the samples that landed in it),
   condition="pixel" warps the 2m direction dims given the pixel (the networks' context), and every
   pixel keeps its sample count.

A candidate set with no light (or too few lit samples), or no time left to learn, falls back to
uniform sampling: the final passes are plain camera passes, and stats say why.
"""
import copy
import math
import time as _time

import numba
import numpy as np

from ...errors import SettingsError, unknown_name
from ...film import Film
from ...lights import luminance
from ...rng import pss_dims, uniform_batch, primary_samples
from ...sources import CameraSource
from ..base import Guide, _float, _int

CONDITIONS = ("image", "pixel")
TARGETS = ("relative", "luminance")
M_CHOICES = (1, 2)
SIZES = ((4, 16), (4, 32), (8, 32))  # (coupling layers, width) tried by "auto"
MIN_LIT = 64  # fewer lit candidate samples than this: no warp
MIN_LEARN_S = 1.0  # with a time budget, less learning time than this: no warp
_LATENT_SALT = 0x707373  # "pss": the latent z and the mixture choice come from keys of their own


class _CountingFilm(Film):
    """A Film that counts samples of zero value and, with keep=True, keeps every sample's
    luminance (weight x value), in the order added."""

    def __init__(self, width, height, keep=False):
        super().__init__(width, height)
        self.zeros = 0
        self.added = 0
        self._lum = [] if keep else None

    def add(self, pixel, radiance, aov, weight=None, spread=False):
        super().add(pixel, radiance, aov, weight, spread)
        lum = luminance(radiance)
        if weight is not None:
            lum = lum * weight
        self.zeros += int(np.count_nonzero(lum == 0.0))
        self.added += int(lum.shape[0])
        if self._lum is not None:
            self._lum.append(lum.astype(np.float32))

    def luminance(self):
        return np.concatenate(self._lum) if self._lum else np.zeros(0, np.float32)


def _image_pixels(ctx, g, sample0):
    """(film pixel, image pixel, sample index) of camera paths g of a pass that starts at sample0."""
    x0, y0, cw, _ = (int(v) for v in ctx.crop)
    npix = ctx.n_pixels
    p = g % npix
    img = (y0 + p // cw) * ctx.scene.width + x0 + p % cw
    return p, img, sample0 + g // npix


def _pixel_xy(ctx, p):
    """(n, 2) centres of film pixels p in [0, 1]^2 of the crop window."""
    cw, ch = int(ctx.crop[2]), int(ctx.crop[3])
    return np.stack([(p % cw + 0.5) / cw, (p // cw + 0.5) / ch], axis=1)


def warped_columns(condition, m):
    """The columns of pss_dims(2)'s primary sample that a warp of m bounces covers: the pixel
    position and 2m direction dims (image), or the 2m direction dims alone (pixel)."""
    return slice(0 if condition == "image" else 2, 2 + 2 * m)


def mixture_density(logq, e):
    """q = (1 - e) p_warp + e from log p_warp; a log-density that is not a number counts as 0
    (the defensive part alone), so that q stays finite and >= e."""
    p = np.exp(np.minimum(np.nan_to_num(logq, nan=-np.inf), 700.0))
    return (1.0 - e) * p + e


def systematic_resample(weights, n, rng):
    """n indices drawn in proportion to weights (>= 0, positive sum), systematic resampling."""
    c = np.cumsum(weights, dtype=np.float64)
    u = (rng.random() + np.arange(n)) / n * c[-1]
    return np.minimum(np.searchsorted(c, u, side="right"), weights.shape[0] - 1)


class WarpSource(CameraSource):
    """The camera with a PSS warp: per wave, primary samples y of `dims` from the flow mixed with
    the uniform density, weights 1 / q(y) (see the module docstring). image: dims start with the
    pixel position and samples go anywhere in the film; else the flow is conditioned on the
    pixel. Counts inference seconds and samples in `time_inference` and `samples`."""

    weighted = True

    def __init__(self, flow, dims, image, defensive, seed):
        super().__init__()
        from . import flow as pss_flow

        self._pf = pss_flow
        self.flow = flow
        self.dims = np.asarray(dims, np.int64)
        self.image = bool(image)
        self.spread = self.image
        self.e = float(defensive)
        self.seed = int(seed) ^ _LATENT_SALT
        self.time_inference = 0.0
        self.samples = 0
        self._weight = None

    def count(self, ctx, spp):
        return spp * ctx.n_pixels

    def _whole_image(self):
        return self.image

    def primary(self, ctx, sample0, g0, n):
        """(y (n, D), weight (n,)) for paths g0 .. g0+n-1 of a pass starting at sample0."""
        t0 = _time.perf_counter()
        d = self.dims.shape[0]
        p, img, s = _image_pixels(ctx, np.arange(g0, g0 + n, dtype=np.int64), sample0)
        lat = uniform_batch(self.seed, img, s, np.arange(d + 1, dtype=np.int64))
        z = lat[:, :d]
        uni = lat[:, d] < self.e
        c = None if self.image else self._pf.context_features(_pixel_xy(ctx, p))
        y = z.copy()
        logq = np.empty(n)
        w = ~uni
        if w.any():
            y[w], logq[w] = self._pf.warp(self.flow, z[w], None if c is None else c[w])
        if uni.any():
            logq[uni] = self._pf.log_density(self.flow, z[uni], None if c is None else c[uni])
        q = mixture_density(logq, self.e)
        self.time_inference += _time.perf_counter() - t0
        self.samples += n
        return y, 1.0 / q

    def start(self, ctx, buf, sample0, g0, n):
        y, weight = self.primary(ctx, sample0, g0, n)
        self._ps = primary_samples(y, self.dims)
        ps = super().start(ctx, buf, sample0, g0, n)
        buf.weight[:n] = weight
        return ps

    def __repr__(self):
        return f"WarpSource({'image' if self.image else 'pixel'}, {self.dims.shape[0]} dims, e={self.e})"


class PSSGuide(Guide):
    """`--guide pss`: a Real NVP warp of the pixel position and the first bounces' directions in primary sample space, learned per scene (Zheng & Zwicker 2019)."""

    camera_paths = False  # the final passes draw from the learned warp (WarpSource)

    name = "pss"
    learns = False  # no vertex records: it learns from the candidate pass's samples
    # memory (tracer.memory): the candidate film and its samples' luminance; bench.memory measured
    # 509-570 B/px in all (290-350 beyond bsdf's), and 400 MB fixed (torch, the examples)
    pixel_bytes = 450
    fixed_bytes = 512 << 20
    DEFAULTS = {"condition": "pixel", "m": "auto", "layers": "auto", "width": "auto", "blocks": 1,
                "defensive": 0.1, "target": "relative", "candidates": 8, "alpha": 6.0, "share": 0.3, "train_seconds": 20.0,
                "epochs": 0, "batch": 1024, "lr": 1e-3, "max_examples": 1_000_000}

    def __init__(self, **settings):
        s = dict(self.DEFAULTS, **settings)
        if s["condition"] not in CONDITIONS:
            raise unknown_name("guide setting condition", s["condition"], CONDITIONS)
        self.condition = s["condition"]
        if s["target"] not in TARGETS:
            raise unknown_name("guide setting target", s["target"], TARGETS)
        self.target = s["target"]
        self.m = self._auto("m", s["m"], M_CHOICES)
        self.layers = self._auto("layers", s["layers"], None)
        self.width = self._auto("width", s["width"], None)
        self.blocks = _int("blocks", s["blocks"], 0)
        self.defensive = _float("defensive", s["defensive"], 1e-3, 1.0)
        self.candidates = _int("candidates", s["candidates"], 1)
        self.alpha = _float("alpha", s["alpha"], 1.0)
        self.share = _float("share", s["share"], 0.0, 1.0)
        self.train_seconds = _float("train_seconds", s["train_seconds"], 0.0)
        self.epochs = _int("epochs", s["epochs"], 0)
        self.batch = _int("batch", s["batch"], 16)
        self.lr = _float("lr", s["lr"], 1e-6, 1.0)
        self.max_examples = _int("max_examples", s["max_examples"], 100)
        self.flow = None
        self._stats = {}

    def prepare(self, scene, ctx):
        """A new render: forget the last render's flow and statistics."""
        self.flow = None
        self._stats = {}
        self.time_learning = self.time_inference = 0.0
        self.peak_memory = 0

    @staticmethod
    def _auto(name, v, choices):
        if v == "auto":
            return None
        if choices is not None:
            if v not in choices:
                raise SettingsError(f"guide setting {name} must be auto or one of {', '.join(map(str, choices))}, "
                                    f"got {v!r}")
            return int(v)
        return _int(name, v, 1)

    def warm_up(self, ctx):
        """Import torch (and the optimiser's lazy imports: 1.4 s the first time, which would
        otherwise come out of the learning share) and compile the camera kernels for external
        primary samples."""
        import torch

        torch.optim.Adam([torch.zeros(1, requires_grad=True)])

        from ...session import trace_source
        from ...sources import PrimarySampleSource

        dims = pss_dims(1)
        src = PrimarySampleSource(np.full((1, dims.shape[0]), 0.5), dims, whole_image=True)
        trace_source(ctx, src, Film(int(ctx.crop[2]), int(ctx.crop[3])))
        uniform_batch(int(ctx.seed), np.zeros(1, np.int64), np.zeros(1, np.int64), dims)  # the latents' kernel

    # the render's passes
    def schedule(self, session):
        ctx = session.ctx
        w, h = int(ctx.crop[2]), int(ctx.crop[3])
        n_c = self.candidates if session.time is not None else min(self.candidates, session.spp)
        film = _CountingFilm(w, h, keep=True)
        session.films.append((film, "train"))
        session.phase("candidates")
        sample0 = session.sample0
        # examples() pairs each candidate's value with its primary sample as tracer.rng draws it, so
        # the candidates take a loop that draws tracer.rng's numbers (the lanes draw their own)
        loop = "thread" if ctx.path_loop == "lanes" else None
        if session.time is None:
            session.run_pass(film, n_c, "train", path_loop=loop)
        else:  # 1 spp at a time, while within half the learning share of the budget
            for _ in range(n_c):
                session.run_pass(film, 1, "train", path_loop=loop)
                if session.elapsed() > 0.5 * self.share * session.time:
                    break
        t0 = _time.perf_counter()
        if session.time is not None:
            seconds = self.share * session.time - session.elapsed()
        else:
            seconds = self.train_seconds
        session.phase("learn")
        if session.time is None and session.sample0 >= session.spp:
            reason = "no samples left after the candidate pass"
        elif session.time is not None and seconds < MIN_LEARN_S:
            reason = f"too little time left to learn ({max(seconds, 0.0):.2f} s)"
        else:
            reason = self.learn(ctx, film, sample0, seconds, stop=session.interrupted)
        if session.interrupted():  # Ctrl-C while learning: the image is the candidate pass's
            raise KeyboardInterrupt
        self.peak_memory = self.memory_bytes()
        self.time_learning = _time.perf_counter() - t0
        self._stats.update(zero_share_uniform=film.zeros / max(film.added, 1), learning_s=self.time_learning,
                           fallback=reason)
        final = _CountingFilm(w, h)
        session.final = final
        source = None
        if self.flow is not None:
            dims = pss_dims(self._stats["m"])
            source = WarpSource(self.flow, dims[warped_columns(self.condition, self._stats["m"])],
                                self.condition == "image", self.defensive, ctx.seed)
        try:
            session.final_passes(source=source)
        finally:
            self._stats["zero_share_final"] = final.zeros / final.added if final.added else None
            if source is not None:
                self.time_inference = source.time_inference
                self._stats["inference_us_per_sample"] = 1e6 * source.time_inference / max(source.samples, 1)

    # learning
    def examples(self, ctx, film, sample0):
        """(y (n, 6) float64, pixel centre (n, 2), target (n,)) of the candidate pass (at most
        max_examples, a uniform subset): y is the primary sample over pss_dims(2) with the pixel
        position in the crop window, the target the sample's luminance (`target` relative: over
        its pixel's mean in the candidate pass)."""
        lum = film.luminance().astype(np.float64)
        g = np.arange(lum.shape[0], dtype=np.int64)
        rng = np.random.default_rng(ctx.seed + 7)
        if g.shape[0] > self.max_examples:
            g = np.sort(rng.choice(g.shape[0], self.max_examples, replace=False))
        p, img, s = _image_pixels(ctx, g, sample0)
        u = uniform_batch(int(ctx.seed), img, s, pss_dims(2))
        cw, ch = int(ctx.crop[2]), int(ctx.crop[3])
        # the position in the crop window; with the point filter the camera ignores the position
        # inside the pixel, and a flow fitted to pixel centres would grow spikes on the lattice
        u[:, 0] = (p % cw + u[:, 0]) / cw
        u[:, 1] = (p // cw + u[:, 1]) / ch
        f = lum[g]
        if self.target == "relative":  # f / the pixel's candidate mean: every lit pixel gets equal mass
            mean = (luminance(film.sum) / np.maximum(film.count, 1.0))[p]
            f = np.where(f > 0, f / np.where(mean > 0, mean, 1.0), 0.0)
        return u, _pixel_xy(ctx, p), f

    def learn(self, ctx, film, sample0, seconds, stop=None):
        """Fit the flow to the candidate pass; returns None, or why there is no warp. stop(), if
        given, is asked after every batch: True ends the training (Ctrl-C)."""
        from . import flow as pss_flow

        end = _time.perf_counter() + seconds  # the examples' preparation counts too
        self._stats.update(condition=self.condition, target=self.target, defensive=self.defensive)
        if seconds <= 0.0 and self.epochs == 0:
            return "no time left to learn"
        y, xy, f = self.examples(ctx, film, sample0)
        lit = int(np.count_nonzero(f > 0))
        self._stats.update(candidates=int(f.shape[0]), candidates_lit=lit)
        if lit < MIN_LIT:
            return f"{lit} lit candidate samples (fewer than {MIN_LIT})"
        import torch

        torch.set_num_threads(numba.get_num_threads())
        rng = np.random.default_rng(ctx.seed + 11)
        torch.manual_seed(ctx.seed + 13)
        order = rng.permutation(f.shape[0])
        n_val = max(1, f.shape[0] // 5)
        parts = {}
        for part, idx in (("val", order[:n_val]), ("train", order[n_val:])):
            fi = f[idx]
            if fi.sum() <= 0.0:
                return f"no lit sample in the {part} split"
            pick = idx[systematic_resample(fi, max(1, int(idx.shape[0] / self.alpha)), rng)]
            parts[part] = (y[pick], pss_flow.context_features(xy[pick]) if self.condition == "pixel" else None)
        self._stats.update(examples_train=int(parts["train"][0].shape[0]), examples_val=int(parts["val"][0].shape[0]))
        cands = [(m, L, W) for m in ([self.m] if self.m else M_CHOICES)
                 for L, W in [(self.layers or l, self.width or w) for l, w in SIZES]]
        cands = list(dict.fromkeys(cands))
        data = {}  # per warped-column slice and part: (logit targets, context, mean NLL constant), made once
        for m in dict.fromkeys(m for m, _, _ in cands):
            data[m] = {}
            for part, (yp, cp) in parts.items():
                b, const = pss_flow.prepare_targets(yp[:, warped_columns(self.condition, m)])
                data[m][part] = (b, None if cp is None else torch.from_numpy(cp), float(const[:65536].mean()))
        runs = [_Fit(self, m, L, W, data[m], stop) for m, L, W in cands]
        # half the time left (all with one candidate) trains the candidates, each a share of what
        # is left of that half, less the last validation's time: a run's epoch always ends with
        # one, so the learning ends near its deadline, not a validation per run past it
        share = 0.5 if len(runs) > 1 else 1.0
        phase_end = _time.perf_counter() + share * max(end - _time.perf_counter(), 0.0)
        val_s = 0.0
        for k, r in enumerate(runs):
            r.train(max((phase_end - _time.perf_counter()) / (len(runs) - k) - val_s, 0.0), self.epochs)
            val_s = r.val_seconds
        if not any(r.epochs_done for r in runs):
            return "no epoch fitted in the learning budget"
        finite = [r for r in runs if math.isfinite(r.best_nll)]
        if not finite:
            return "training diverged (validation NLL not finite)"
        best = min(finite, key=lambda r: r.best_nll)
        if len(runs) > 1:
            best.train(max(end - _time.perf_counter() - val_s, 0.0), self.epochs)
        best.restore()
        self.flow = best.flow
        self._stats.update(
            m=best.m, layers=best.layers, width=best.width, blocks=self.blocks,
            parameters=pss_flow.parameter_count(best.flow), flops_per_sample=pss_flow.flops_per_sample(best.flow),
            val_nll=best.best_nll, train_nll=best._val("train"), epochs=best.epochs_done,
            tried=[{"m": r.m, "layers": r.layers, "width": r.width, "val_nll": r.best_nll, "epochs": r.epochs_done}
                   for r in runs])
        self._stats["second_moment_ratio"] = self._second_moment(y[order[:n_val]], xy[order[:n_val]],
                                                                 f[order[:n_val]], best.m)
        return None

    def _second_moment(self, y, xy, f, m):
        """E[f^2 / q] / E[f^2] over the validation candidates (uniform samples), f the training target
        (`target`): the second moment per sample that the mixture promises over uniform sampling
        for that target (1: no gain)."""
        from . import flow as pss_flow

        sel = f > 0
        if not sel.any():
            return 1.0
        yy = y[sel, warped_columns(self.condition, m)]
        c = pss_flow.context_features(xy[sel]) if self.condition == "pixel" else None
        q = mixture_density(pss_flow.log_density(self.flow, yy, c), self.defensive)
        return float(np.sum(f[sel] ** 2 / q) / np.sum(f[sel] ** 2))

    def memory_bytes(self):
        if self.flow is None:
            return 0
        return sum(p.numel() * p.element_size() for p in self.flow.parameters())

    def stats(self):
        return dict(self._stats)


class _Fit:
    """One candidate flow trained by maximum likelihood on the resampled examples, with its best
    state by validation NLL."""

    def __init__(self, guide, m, layers, width, data, stop=None):
        import torch

        from . import flow as pss_flow

        self.torch, self.pf = torch, pss_flow
        self.m, self.layers, self.width = m, layers, width
        sl = warped_columns(guide.condition, m)
        ctx = guide.condition == "pixel"
        self.flow = pss_flow.PSSFlow(sl.stop - sl.start, layers, width, guide.blocks, context=ctx)
        self.opt = torch.optim.Adam(self.flow.parameters(), lr=guide.lr)
        self.batch = guide.batch
        self.data = data  # {"train" | "val": (logit targets, context or None, mean NLL constant)}
        self.best_nll = math.inf
        self.best_state = copy.deepcopy(self.flow.state_dict())  # the identity, until an epoch beats it
        self.epochs_done = 0
        self.gen = torch.Generator().manual_seed(1000 * m + 10 * layers + width)
        self.stop = stop if stop is not None else (lambda: False)
        self.val_seconds = 0.0  # the last validation's time

    def _val(self, part="val"):
        b, c, const = self.data[part]
        b, c = b[:65536], None if c is None else c[:65536]
        with self.torch.no_grad():
            tot = 0.0
            for i in range(0, b.shape[0], 8192):
                tot += float(self.flow.nll_terms(b[i:i + 8192], None if c is None else c[i:i + 8192]).sum())
        return tot / b.shape[0] + float(const)

    def train(self, seconds, epochs):
        """Train for `seconds` (epochs == 0) or `epochs` epochs; keep the best state by validation."""
        torch = self.torch
        b, c, _ = self.data["train"]
        n = b.shape[0]
        deadline = _time.perf_counter() + seconds
        done = 0
        self.flow.train()
        while ((epochs and done < epochs) or (not epochs and _time.perf_counter() < deadline)) and not self.stop():
            perm = torch.randperm(n, generator=self.gen)
            for i in range(0, n, self.batch):
                idx = perm[i:i + self.batch]
                loss = self.flow.nll_terms(b[idx], None if c is None else c[idx]).mean()
                self.opt.zero_grad()
                loss.backward()
                self.opt.step()
                if (not epochs and _time.perf_counter() >= deadline) or self.stop():
                    break
            done += 1
            self.epochs_done += 1
            tv = _time.perf_counter()
            v = self._val()
            self.val_seconds = _time.perf_counter() - tv
            if math.isfinite(v) and v < self.best_nll:
                self.best_nll = v
                self.best_state = copy.deepcopy(self.flow.state_dict())
        self.flow.eval()

    def restore(self):
        self.flow.load_state_dict(self.best_state)
        self.flow.eval()
