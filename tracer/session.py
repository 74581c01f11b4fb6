"""A render's passes: what a method's schedule calls to render, learn and spend the budget.

render() makes a Session and hands it to the method: `guide.schedule(session)` (plain BSDF
sampling and guides that learn nothing run `session.final_passes()`). A schedule renders passes
with `run_pass` into films it opens with `new_film`, learns between them (run_pass with
learn=True calls the guide's observe and update), and ends with `final_passes`, which fills the
rest of the budget (spp or time) in doubling passes of the render's integrator
(tracer.integrators: the path tracer's passes into `final`, or gpt's base and offset paths).
The integrator then makes the image from the films (the path tracer combines them by inverse
variance, film.combine_films; pilot films are left out).
"""
import math
import time as _time

from .film import Film
from .integrators.path import trace_wave
from .sources import CameraSource
from .wave import Stats, WaveBuffers


def trace_source(ctx, source, sink, spp=1, sample0=0, buf=None, stats=None, observe=None, direct=True, split=None,
                 before_wave=None, after_wave=None, limit=None):
    """Trace every path of one pass of `source` (tracer.sources) into `sink` (a Film or a
    film.SampleSink), in waves of buf.size paths (buf: a wave.WaveBuffers, made for the pass if
    None). ctx: a RenderContext (render.make_context); spp: the pass's samples per pixel, for
    sources that count by it; sample0: the sample index it starts at. observe, direct, split: as
    integrator.trace_wave. before_wave(n) and after_wave(n), if given, are called before and after
    each wave of n paths (they may raise to stop). limit(n), if given, may cut the next wave to
    fewer paths, or end the pass early with 0 (a time budget's last wave). Returns the wave.Stats."""
    total = source.count(ctx, spp)
    buf = WaveBuffers(max(1, min(total, 1 << 16)), split=split is not None) if buf is None else buf
    stats = Stats() if stats is None else stats
    run_waves(total, buf.size, lambda g0, n: trace_wave(ctx, buf, source, sink, sample0, g0, n, stats,
                                                        observe=observe, direct=direct, split=split),
              before_wave, after_wave, limit)
    return stats


def run_waves(total, size, trace, before_wave=None, after_wave=None, limit=None):
    """Call trace(g0, n) for waves of at most `size` of `total` paths; before_wave, after_wave and
    limit as trace_source. Returns the paths traced."""
    g0 = 0
    while g0 < total:
        n = min(size, total - g0)
        if limit is not None:
            n = min(n, limit(n))
            if n <= 0:
                break
        if before_wave is not None:
            before_wave(n)
        trace(g0, n)
        if after_wave is not None:
            after_wave(n)
        g0 += n
    return g0


MIN_WAVE = 1024  # the shortest wave a time budget's end is cut to
MIN_SWEEPS = 2  # samples every pixel of a film gets before its pass may be cut at the deadline


class Stop(Exception):
    """A callback asked the render to stop."""


class Session:
    """The passes of one render.

    ctx: the RenderContext; guide: the method (None: BSDF sampling); integrator: the
    integrators.base.Integrator whose final passes these are; buf: the WaveBuffers;
    stats: the wave.Stats; spp: the target samples per pixel (time None) or None; time: the budget
    in seconds or None; t_start: perf_counter() the budget counts from; bar: a tqdm bar or None;
    callback(pass_index, film, stats) after each pass (False stops); snapshot(): the stats dict;
    interrupted(): whether Ctrl-C asked to stop (checked between waves).
    """

    def __init__(self, ctx, guide, buf, stats, spp, time, t_start, bar, callback, snapshot, interrupted, reserve=0.0,
                 integrator=None):
        from .integrators.path import PathIntegrator

        self.ctx, self.guide, self.buf, self.stats = ctx, guide, buf, stats
        self.integrator = PathIntegrator() if integrator is None else integrator
        self.spp, self.time, self.t_start = spp, time, t_start
        self.reserve = reserve  # seconds of the budget kept for the work after the last pass
        self.bar, self.callback, self.snapshot, self.interrupted = bar, callback, snapshot, interrupted
        self.films = []  # (film, kind) of every pass group: "pilot", "train", "final", "discard"
        self.passes = []  # one entry per pass: spp, time, kind, film index, time_update (partial, paths)
        self.sample0 = 0  # sample index the next pass starts at
        w, h = int(ctx.crop[2]), int(ctx.crop[3])
        self.final = Film(w, h)  # the final passes' film
        self.camera = CameraSource()
        self.out_of_time = False  # a pass was cut short at the end of the budget
        self._wave_t0 = 0.0
        self._rate = None  # seconds per path of the latest pass that traced a wave
        self._last_rate = 0.0  # and of its last wave
        self._pass_paths = 0
        self._pass_seconds = 0.0

    def elapsed(self):
        """Seconds of the budget spent so far."""
        return _time.perf_counter() - self.t_start

    def time_left(self):
        """Seconds of the budget left for passes (the reserve kept back); inf without a time budget."""
        return float("inf") if self.time is None else self.time - self.reserve - self.elapsed()

    def wave_limit(self, n, film=None, sweeps=MIN_SWEEPS):
        """How many of the next wave's n paths fit in the time left, at the seconds per path of the
        waves so far (this pass's, else the last pass's, or the last wave's if slower): n, or, when
        not all fit, those that fit in half the time left (at least MIN_WAVE), or 0 to end the pass.
        The waves shrink toward the deadline, so the budget ends within a wave of MIN_WAVE paths
        even when a wave runs up to twice as slow as measured. `film`,
        if given, is never cut before each of its pixels has `sweeps` samples (a film with fewer
        gets no weight in combine_films; a pixel with none would be black): the budget is then
        overrun by what those take."""
        if self._rate is None or self.time is None:
            return n
        fit = int(self.time_left() / max(self._rate, self._last_rate, 1e-12))
        if fit >= n or (film is not None and film.count.min() < sweeps):
            return n
        fit //= 2  # half the time left: a wave twice as slow as the last (a busy machine) still ends in time
        return fit if fit >= MIN_WAVE else 0

    def new_film(self, kind):
        """Open a film for a group of passes of `kind` ("pilot" films get no weight in the image
        when another film has 2 spp everywhere, "discard" films never)."""
        film = Film(int(self.ctx.crop[2]), int(self.ctx.crop[3]))
        self.films.append((film, kind))
        return film

    def leave_out_training(self):
        """The training films so far become pilots: no weight in the image while a final film has
        2 spp everywhere."""
        self.films = [(f, "pilot" if k == "train" else k) for f, k in self.films]

    def discard(self, films):
        """These films get no weight in the image (kind "discard"): e.g. the trials of the methods
        guiding.auto did not pick."""
        drop = {id(f) for f in films}
        self.films = [(f, "discard" if id(f) in drop else k) for f, k in self.films]

    def training_films(self):
        """The films rendered so far (what a guide's split plan estimates pixels from)."""
        return [f for f, _ in self.films]

    def phase(self, name):
        """Show `name` (pilot, train t/T, learn, final, ...) on the progress bar of a render with a
        guide (plain BSDF sampling keeps `render`)."""
        if self.bar is not None and self.guide is not None:
            self.bar.set_description_str(name)  # (set_description would add a colon to the bar's own)

    def run_pass(self, film, spp, kind, learn=False, source=None, split=None, deadline=False, wave=None,
                 sweeps=MIN_SWEEPS, path_loop=None):
        """Render `spp` more samples per pixel from `source` (default: the camera) into `film`, in
        waves; with `learn`, the guide observes the vertices and updates after the pass. split: a
        splitting.SplitPlan for the waves (final passes), or None. deadline: with a time budget,
        the pass ends when the budget does (wave_limit, never before every pixel of `film` has
        `sweeps` samples), its last sweep over the pixels partial (those pixels get one sample
        more than the rest; out_of_time is set). wave(sample0, g0, n), if given, traces each wave
        of the pass's spp x pixels paths instead of the path tracer (an integrator's own, e.g.
        gpt's base and offsets, which adds to `film` itself). path_loop: the loop this pass's waves
        take in place of the render's (ctx.path_loop), e.g. "thread" for a pass whose samples must
        be tracer.rng's (the lanes draw their own). Raises KeyboardInterrupt between waves after
        Ctrl-C, Stop when the callback returns False."""
        ctx, buf, g = self.ctx, self.buf, self.guide
        source = self.camera if source is None else source
        index = next((j for j, (f, _) in enumerate(self.films) if f is film), None)
        if index is None:
            raise ValueError("run_pass renders into a film opened with new_film (or the final film)")
        tp = _time.perf_counter()
        observe = g.observe if learn else None
        direct = g.records_direct(ctx) if g is not None else True
        self._pass_paths, self._pass_seconds = 0, 0.0
        self._pass_lanes = (self.stats.lane_general, self.stats.lane_listed)
        limit = (lambda n: self.wave_limit(n, film, sweeps)) if deadline and self.time is not None else None
        total = source.count(ctx, spp) if wave is None else spp * ctx.n_pixels
        loop = ctx.path_loop
        if path_loop is not None:
            ctx.path_loop = path_loop
        try:
            if wave is None:
                trace_source(ctx, source, film, spp, self.sample0, buf, self.stats, observe, direct, split,
                             self._before_wave, self._after_wave, limit)
            else:
                sample0 = self.sample0
                run_waves(total, buf.size, lambda g0, n: wave(sample0, g0, n), self._before_wave, self._after_wave,
                          limit)
        except KeyboardInterrupt:  # between waves: the waves traced are in the film, and in the stats' passes
            self._end_pass(spp, kind, index, tp, total, interrupted=True)
            raise
        finally:
            ctx.path_loop = loop
        entry = self._end_pass(spp, kind, index, tp, total)
        if learn:
            tl = _time.perf_counter()
            g.update()
            ctx.guide_state = g.state()
            entry["time_update"] = _time.perf_counter() - tl
        self.after_pass(film)

    def _end_pass(self, spp, kind, index, tp, total, interrupted=False):
        """Append the pass's entry to self.passes and advance sample0: by spp, or, for a pass cut at
        the budget's end (out_of_time) or by Ctrl-C, by the whole sweeps over the pixels it made
        (the entry then has partial and paths, and `interrupted` for Ctrl-C). The entry also counts
        the vertices the lanes' general and listed kernels shaded in the pass. Returns the entry."""
        entry = {"spp": spp, "time": _time.perf_counter() - tp, "kind": kind, "film": index,
                 "lane_general_vertices": int(self.stats.lane_general - self._pass_lanes[0]),
                 "lane_listed_vertices": int(self.stats.lane_listed - self._pass_lanes[1])}
        if self._pass_paths < total:
            entry.update(partial=True, paths=self._pass_paths)
            if interrupted:
                entry["interrupted"] = True
            else:
                self.out_of_time = True
            self.sample0 += self._pass_paths * spp // total
        else:
            self.sample0 += spp
        self.passes.append(entry)
        return entry

    def after_pass(self, film):
        """Call the callback with the pass just appended to self.passes and `film`; Stop if it
        returns False."""
        if self.callback is not None and self.callback(len(self.passes) - 1, film, self.snapshot()) is False:
            raise Stop

    def _before_wave(self, n):
        if self.interrupted():
            raise KeyboardInterrupt  # between waves: every finished wave is whole in the film
        self._wave_t0 = _time.perf_counter()

    def _after_wave(self, n):
        seconds = _time.perf_counter() - self._wave_t0
        self._pass_paths += n
        self._pass_seconds += seconds
        self._rate = self._pass_seconds / self._pass_paths
        self._last_rate = seconds / n
        if self.bar is not None:
            self.bar.update(n / self.ctx.n_pixels)

    def final_film(self):
        """The integrator's final film (self.final for the path tracer), registered in self.films
        (once) under the integrator's film kind."""
        it = self.integrator
        film = it.final_film(self)
        if not any(f is film for f, _ in self.films):
            self.films.append((film, it.film_kind))
        return film

    def final_passes(self, split=None, source=None):
        """Fill the rest of the budget with the integrator's final passes into its final film
        (self.final for the path tracer): each twice the last pass's spp (the first as many as the
        last pass, or 1), up to `spp` in all; or, with a time budget, each at most what the time
        left holds at the final passes' speed so far (rounded up), until the budget ends, the last
        pass cut at the deadline (run_pass). split: a splitting.SplitPlan; source: where the paths
        start (default: the camera; e.g. a guiding.pss.warp.WarpSource)."""
        it = self.integrator
        film = self.final_film()
        self.phase("final")
        passes = self.passes
        pass_spp = passes[-1]["spp"] if passes else 1
        first_final = len(passes)
        while True:
            if self.time is None:
                if self.sample0 >= self.spp:
                    break
                pass_spp = min(pass_spp, self.spp - self.sample0)
            else:
                left = self.time_left()
                if self.out_of_time or (left <= 0.0 and film.count.min() >= it.sweeps):
                    break  # (a final film gets its MIN_SWEEPS whatever the budget: see wave_limit)
                if passes[first_final:]:
                    ref = passes[first_final:]
                    per_spp = sum(p["time"] for p in ref) / sum(p.get("paths", p["spp"] * self.ctx.n_pixels)
                                                               / self.ctx.n_pixels for p in ref)
                    pass_spp = max(1, min(pass_spp, math.ceil(left / per_spp)))
            it.final_pass(self, film, pass_spp, split, source)
            pass_spp *= 2
