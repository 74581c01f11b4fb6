"""The contract between the render and a directional guide: the `Guide` base class.

A guide is a Python object that render() drives, and a GuideState its Numba kernels read. What
render() and the integrator ask of it:

    prepare(scene, ctx)    start of a render (ctx: tracer.context.RenderContext)
    warm_up(ctx)           before the clock starts: compile what its passes need
    state()                the GuideState the kernels sample from (tracer.guiding.contract): they
                           locate a vertex's map (`contract.locate(state, x, n, pixel, depth)`, a
                           voxel's map, or a per-pixel map at the first bounce), then draw from it
                           and evaluate it (`slot_sample`, `slot_pdf`)
    observe(records)       the vertices of a wave of camera paths (guiding.records), in passes run
                           with learn=True
    update()               between passes: learn from what was observed, rebuild the maps
    training_done()        before each training iteration (Algorithm 1): True ends training early
    finish_training()      after the last training pass, before the final passes (Algorithm 1)
    schedule(session)      the passes of the render (tracer.session.Session): by default the final
                           passes alone; guides that learn run their own (e.g. Algorithm 1)
    split_plan(films, crop)   the splitting.SplitPlan of the final passes, or None
    memory_bytes(), stats()   for the render's statistics

and the attributes below. A guide need not learn: one that returns a fixed state renders with it
from the first sample (e.g. FrozenGuide, or a per-pixel map computed once).
"""
import math

import numpy as np

from ..errors import SettingsError
from ..splitting import WeightWindow
from .contract import empty_state


# Russian roulette a guide's passes play (its `roulette` setting; GuideState.rr_late, rr_min, rr_max):
# "path" the path tracer's, drawn before the sampled ray is traced, survival min(max(beta) / gain,
# 0.95); "late" the same survival drawn after the ray, once the emission it hits is counted, and not
# after a delta bounce; "reference" as late with Practical Path Guiding's reference survival,
# clamped to [0.1, 0.99] until the guide has maps and 0.99 after (guided_path.cpp); "auto" reference
# with next-event estimation off, path with it on (docs/ppg.md, "Faithful to the reference")
ROULETTES = ("auto", "path", "late", "reference")
# What a camera record holds past the roulette (its `records` setting; GuideState.rec_q): "survivors"
# the radiance X that came back on a surviving path, 0 on a killed one (expectation q L_i), "unbiased"
# X / q (expectation L_i). With a late roulette a record's own emission comes before the draw.
RECORD_KINDS = ("survivors", "unbiased")


def _choice(name, v, allowed):
    if v not in allowed:
        raise SettingsError(f"guide setting {name} must be one of {', '.join(allowed)}, got {v!r}")
    return v


def _int(name, v, lo):
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
        raise SettingsError(f"guide setting {name} must be an integer >= {lo}, got {v!r}")
    return int(v)


def _float(name, v, lo, hi=math.inf):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not (lo <= v <= hi):
        raise SettingsError(f"guide setting {name} must be a number in [{lo}, {hi}], got {v!r}")
    return float(v)


def window_settings(s):
    """The splitting.WeightWindow of the settings dict s (`split`; `window`, `window_low`: a number or
    "auto"; `window_spp`)."""
    hi, low = (v if isinstance(v, str) and v == "auto" else _float(k, v, 0.0)
               for k, v in (("window", s["window"]), ("window_low", s["window_low"])))
    return WeightWindow(_float("split", s["split"], 0.0), hi, low, _float("window_spp", s["window_spp"], 0.0))


class Guide:
    """Base class of directional guides; the defaults describe a guide that learns nothing."""

    name = "guide"
    learns = False  # passes record vertices for observe() (the pilot and training passes)
    learn_direct = True  # records count the emission their direction hits directly (else NEE's part is left out)
    iterations = 0  # training iterations of Algorithm 1 (schedules that use it)
    spp_init = 1  # Algorithm 1's N_c: iteration t renders 2^t N_c spp
    train_budget = 1.0  # with a time budget: share of it that learning may take
    training = None  # Algorithm 1's schedules: how training went (grid.schedule.training_record)
    train_spp = None  # Algorithm 1's schedules: spp of the training pass being run (the pilot's: 1)
    splitting = None  # splitting.WeightWindow, or None (never splits)
    camera_paths = True  # final passes start at the camera (False: from the guide's own source, e.g. pss's warp)
    pixel_maps = False  # the state holds per-pixel first-bounce maps (GuideState.pixel_slot)
    time_learning = 0.0  # seconds spent observing and learning
    time_update = 0.0  # seconds spent rebuilding maps between passes
    time_inference = 0.0  # seconds of network inference
    peak_memory = 0  # bytes
    # memory the method holds beyond the final film and the result (tracer.memory): bytes per film
    # pixel (its training films, per-pixel maps), and bytes that do not grow with the image
    pixel_bytes = 0
    fixed_bytes = 0

    training_in_image = True  # Algorithm 1's image weighs the training iterations in (False: final passes alone)
    roulette = "path"  # ROULETTES
    records_loop = None  # the path loop its recording passes take (None: the render's; "wave": the wavefront)
    records = "survivors"  # RECORD_KINDS
    roulette_used = "path"  # the roulette of this render ("auto" resolved by resolve_roulette)

    def roulette_settings(self, s):
        """Read the `roulette` and `records` settings from the dict s."""
        self.roulette = _choice("roulette", s["roulette"], ROULETTES)
        self.records = _choice("records", s["records"], RECORD_KINDS)
        self.roulette_used = "path" if self.roulette == "auto" else self.roulette

    def resolve_roulette(self, ctx):
        """At prepare: the roulette this render plays ("auto": reference without NEE, else path)."""
        if self.roulette == "auto":
            self.roulette_used = "path" if ctx.nee else "reference"
        return self.roulette_used

    def with_roulette(self, state, maps):
        """state with this guide's roulette (roulette_used) and records (ROULETTES, RECORD_KINDS);
        maps: whether the guide has maps yet (the reference roulette's clamp)."""
        rec_q = int(self.records == "unbiased")
        if self.roulette_used == "path":
            return state._replace(rec_q=rec_q) if rec_q else state
        if self.roulette_used == "late":
            return state._replace(rr_late=1, rec_q=rec_q)
        return state._replace(rr_late=1, rr_min=0.99 if maps else 0.1, rr_max=0.99, rec_q=rec_q)

    @property
    def splits(self):
        """Whether final passes may split paths (the wave buffers then need room for copies)."""
        return self.splitting is not None and self.splitting.active

    def follow_nee(self, nee):
        """Settle the settings that follow next-event estimation (the window's "auto" bounds) before
        the render sizes its buffers and compiles its kernels."""
        if self.splitting is not None:
            self.splitting.resolve(nee)

    def records_direct(self, ctx):
        """Whether this render's records (and photon maps) carry the emission a direction hits
        directly: with `learn_direct`, or with next-event estimation off (nothing else samples it)."""
        return self.learn_direct or not ctx.nee

    def prepare(self, scene, ctx):
        pass

    def warm_up(self, ctx):
        """Before the clock starts: compile (or load from the cache) what this guide's passes run
        beyond the guides' common kernels (render() calls it after guiding.warm_up_guides)."""

    def state(self):
        return empty_state()

    def observe(self, records):
        pass

    def update(self):
        pass

    def min_last_spp(self, prev):
        """The fewest spp worth running a shortened last training iteration for, after one of
        `prev` spp (grid.schedule): as many as the last, for guides whose maps each iteration's
        data rebuild alone."""
        return prev

    def training_done(self):
        """Before each training iteration of Algorithm 1: whether to end training now."""
        return False

    def finish_training(self):
        """After the last training pass: what the final passes sample from is settled here. Returns
        True where the guide switched itself off (the final passes sample the BSDF alone)."""
        return False

    def schedule(self, session):
        """Run the render's passes: Algorithm 1 (guiding.grid.schedule) for a guide that learns, else the
        final passes alone, with this guide's split plan."""
        if self.learns:
            from .grid.schedule import algorithm1

            algorithm1(session, self)
        else:
            session.final_passes(self.split_plan(session.training_films(), session.ctx.crop))

    def split_plan(self, films, crop):
        """The SplitPlan of the final passes from the training passes' films, or None."""
        if not self.splits:
            return None
        return self.splitting.plan(self.window_estimates(), films, crop)

    def window_estimates(self):
        """Per guide node, the weight window's outgoing radiance estimate, or None."""
        return None

    def memory_bytes(self):
        return 0

    def stats(self):
        return {}

    def __repr__(self):
        return f"{type(self).__name__}({self.name!r})"
