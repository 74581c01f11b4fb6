"""The library entry point: `render(scene, spp=..., guide="bsdf", ...) -> RenderResult`.

A render runs as passes over the whole image, in the order the method's schedule gives
(tracer.session); each pass renders some samples per pixel in waves of at most `wave_size`
paths (memory stays flat with image size). Between passes a callback may look at the film
(guides learn there). With `time=S` the final passes continue, doubling in size, until the next
one would not fit in the budget. Ctrl-C stops the render between waves and returns what was
rendered so far (see render()). `make_context` and session.trace_source trace any ray source
(tracer.sources) outside a render.
"""
import json
import logging
import math
import os
import signal
import threading
import time as _time

import numba
import numpy as np

from . import _jit, memory
from .bvh import make_accel
from .bvh.numba_bvh import _NumbaThreads
from .context import RenderContext
from .errors import SettingsError, unknown_name
from .film import Film
from .guiding import make_guide, warm_up_guides
from .guiding.base import Guide
from .integrators import make_integrator
from .integrators.base import AFTER_PASSES_SECONDS
from .integrators.path import engine, trace_wave, warm_up_shadows
from .methods import parse_spec
from .lights import build_lights
from .provenance import provenance
from .result import RenderResult  # noqa: F401  (tracer.render.RenderResult)
from .session import Session, Stop
from .sources import CameraSource
from .splitting import warm_up_plan, warm_up_splitting
from .wave import Stats, WaveBuffers

DEFAULT_WAVE = 1 << 16
log = logging.getLogger("tracer")
FILTERS = ("box", "point")
PATH_LOOPS = ("thread", "wave", "lanes")


def _check_crop(crop, width, height):
    """(x0, y0, w, h) inside the image; None means the whole image."""
    if crop is None:
        return (0, 0, width, height)
    try:
        x0, y0, w, h = (int(v) for v in crop)
    except (TypeError, ValueError):
        raise SettingsError(f"crop must be four integers x0, y0, w, h, got {crop!r}") from None
    if w < 1 or h < 1 or x0 < 0 or y0 < 0 or x0 + w > width or y0 + h > height:
        raise SettingsError(f"crop {x0},{y0},{w},{h} is not inside the {width}x{height} image")
    return (x0, y0, w, h)


def _int_setting(name, value, lo):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
        raise SettingsError(f"{name} must be an integer >= {lo}, got {value!r}")
    return int(value)


def render(scene, spp=None, time=None, guide="bsdf", max_depth=None, rr_depth=None, seed=None,
           accel="embree", threads=None, wave_size=DEFAULT_WAVE, progress=False, callback=None,
           guide_settings=None, pixel_filter="box", crop=None, integrator="path", integrator_settings=None,
           shift=None, recon=None, recon_alpha=None, shift_roughness=None, recon_settings=None, path_loop=None,
           denoise=False, scheduler=None, workers=None, segments_dir=None):
    """Render `scene` (from tracer.load_scene) and return a RenderResult.

    spp        samples per pixel (default: the scene's render.spp); ignored when `time` is given
    time       wall-clock budget in seconds (instead of spp): the accel's build, learning,
               inference, the passes and gpt's solve, not the kernels' compile; the last pass is
               cut at the deadline (stats: time_total, the budget's clock; time_render, the passes')
    guide      registered sampler name (tracer.guiding.guide_names()) or spec ("photon:iterations=6",
               tracer.methods); guide_settings: dict of its settings (an unknown one is an error
               listing the valid ones). A guide object (e.g. tracer.guiding.make_guide("photon",
               ...)) is accepted too, and can be inspected after.
    max_depth, rr_depth, seed: override the scene's render settings (Mitsuba conventions)
    accel      "embree" or "numba"; threads: worker threads (default: all cores)
    path_loop  "lanes" (the default, None: the same, without a warning where the accel is not Embree
               and the wavefront runs instead): every pass (a guide's training and final passes
               included) runs on the float32 lanes of tracer.engine (Embree only): diffuse, textured
               diffuse, plastic and metal vertices under triangle lights in class kernels, every other
               vertex through the general one; a pss warp's passes take the per-thread loop, auto's
               trials the wavefront. "thread": passes that record and split nothing trace each
               thread's paths to their end in packets of 16 (tracer.integrators.thread_loop; Embree
               only); "wave": every pass runs the wavefront, one kernel per stage. "thread" and "wave"
               give the same image bit for bit; "lanes" one equal in expectation, with other random
               numbers.
    denoise    True (or a quality: "high", the default, "balanced", "fast"): Intel Open Image Denoise
               on the final image with its albedo and normal (tracer.denoise; needs the `denoise`
               extra) into result.denoised; its time counts in time_total and in a time budget
    callback   f(pass_index, film, stats_dict) called after every pass; return False to stop
    pixel_filter  "box" (default: samples uniform over the pixel) or "point" (every sample
               through the pixel centre: no anti-aliasing, so a pixel never mixes two surfaces;
               for per-pixel regression tests and debugging)
    crop       (x0, y0, w, h): render only that window of the image (its pixels are the same
               samples as in the full render)
    integrator registered name or spec (tracer.integrators): "path" (unidirectional path tracing;
               "path:nee=0" without next-event estimation) or "gpt" (gradient-domain path tracing,
               tracer.gradient), e.g. "gpt:shift=replay,recon=l1"; integrator_settings: a dict of
               its settings (an Integrator object is accepted too). gpt's settings: shift "hybrid"
               (reconnecting vertices rougher than `roughness`; with grid and photon each offset
               takes its own pixel's mixture density) or "replay" (the default with odis, whose
               per-pixel maps the hybrid shift does not shift); recon "l2" (the
               default) or "l1" (screened Poisson, with weight recon_alpha on the base; l1 is
               darker at low spp), "gradnet" (the learned reconstruction; `weights`, the name of
               shipped weights, `correction` 0 or 1) or "none" (the base image); nee 0 or 1. The
               keywords shift, recon, recon_alpha, shift_roughness (roughness) and recon_settings
               (weights, correction) are the same settings. The result's image is then the
               reconstruction, its variance the base image's, and result.buffers holds base, dx, dy
               (with variances), direct, indirect, albedo, normal and depth; stats time the passes
               and the solve (time_solve) and give recon_mean_change (the image mean over the
               base's, less 1) and negative_pixel_share. `callback` gets the base image's film
               after each of gpt's passes. A guide trains by its own schedule before gpt's passes.

    The method runs its own schedule of passes (guide.schedule(session), tracer.session): BSDF
    sampling and guides that learn nothing render final passes alone; `grid` and `photon` run
    Algorithm 1 of Zhu et al. 2021 (tracer.guiding.grid.schedule): a 1-spp pilot, training iterations
    of 2^t spp, then final guided passes; the image combines the films of the passes weighted by
    the inverse of each one's mean pixel variance (the pilot is not used).

    Ctrl-C (SIGINT, when render runs in the main thread) stops the render before the next wave:
    the wave in flight finishes, and a second Ctrl-C stops at once. The result then has
    stats["interrupted"] True, and the waves finished in the unfinished pass stay in the image:
    each pixel is the mean of the samples it got, so some pixels have one more than others.
    stats["spp"] counts the finished passes (every pixel has at least that many samples),
    stats["spp_mean"] all samples / pixels (what the progress bar shows). A film that some
    pixel has fewer than 2 samples of gets no weight when films are combined (combine_films).

    stats also records tracer_version, git_commit (HEAD of the package's checkout, "-dirty" with
    changes to tracked files, None without git), command_line (sys.argv) and date (ISO 8601).

    scheduler, workers: split the render over Dask (a scheduler's address, or a LocalCluster of
               `workers` processes): segment k renders with seed + k and its share of spp (or the
               whole `time` each), and the segments are merged in seed order, each z-checked against
               the rest (tracer.distributed); segments_dir keeps finished segments so that a run
               started again renders only the missing ones. stats["segments"] lists them.

    Determinism: a render is a function of its settings, bit for bit, whatever the thread count.
    The wave size does not change it either, except where a guide splits paths (`split`, `window`):
    copies are made only into free room of the wave's buffer, so a smaller wave makes fewer of them
    (each choice is unbiased; tests/guiding/test_guides.py).
    """
    if scheduler is not None or workers is not None:
        from .distributed import render_on_dask

        kw = dict(spp=spp, time=time, guide=guide, max_depth=max_depth, rr_depth=rr_depth, seed=seed, accel=accel,
                  threads=threads, wave_size=wave_size, guide_settings=guide_settings, pixel_filter=pixel_filter,
                  crop=crop, integrator=integrator, integrator_settings=integrator_settings, shift=shift, recon=recon,
                  recon_alpha=recon_alpha, shift_roughness=shift_roughness, recon_settings=recon_settings,
                  path_loop=path_loop, denoise=denoise)
        if callback is not None:
            raise SettingsError("a callback sees one process's passes: not with scheduler or workers")
        return render_on_dask(scene, kw, scheduler=scheduler, workers=workers, segments_dir=segments_dir,
                              progress=progress)
    if threads is not None:
        threads = _int_setting("threads", threads, 1)
    n_threads = min(threads or numba.config.NUMBA_NUM_THREADS, numba.config.NUMBA_NUM_THREADS)
    with _NumbaThreads(n_threads):  # every kernel of this render on n_threads, restored after
        return _render(scene, spp, time, guide, max_depth, rr_depth, seed, accel, n_threads, wave_size, progress,
                       callback, guide_settings, pixel_filter, crop, path_loop, _denoise_quality(denoise),
                       _integrator(integrator, integrator_settings, shift, recon, recon_alpha, shift_roughness,
                                   recon_settings))


def _denoise_quality(denoise):
    """render()'s `denoise` as a quality name, None for no denoising (checked: pyoidn installed)."""
    if denoise is False or denoise is None:
        return None
    quality = "high" if denoise is True else denoise
    if not isinstance(quality, str):
        raise SettingsError(f"denoise must be True, False or a quality name, got {denoise!r}")
    from .denoise import require

    require(quality)
    return quality


def _integrator(spec, settings, shift, recon, recon_alpha, shift_roughness, recon_settings):
    """The Integrator of render()'s arguments: the spec, its settings dict, and the keywords that
    name gpt's settings (an integrator without them says so)."""
    if settings is not None and not isinstance(settings, dict):
        raise SettingsError(f"integrator_settings must be a dict, got {type(settings).__name__}")
    if recon_settings is not None and not isinstance(recon_settings, dict):
        raise SettingsError(f"recon_settings must be a dict, got {type(recon_settings).__name__}")
    kw = {k: v for k, v in (("shift", shift), ("recon", recon), ("recon_alpha", recon_alpha),
                            ("roughness", shift_roughness)) if v is not None}
    return make_integrator(spec, **dict(settings or {}, **kw, **(recon_settings or {})))


def check_memory(scene, crop, wave_size, spp, guide, integrator=None):
    """SettingsError (naming the scene, what the render needs and what the machine has) if a render
    of the crop window (x0, y0, w, h) would not fit in memory (tracer.memory); else the wave size
    the render will use. spp None: a time budget; integrator: an Integrator (None: the path
    tracer). Called before anything is allocated."""
    npix = crop[2] * crop[3]
    wave = min(wave_size, npix * (spp if spp is not None else 1024))
    wave_bytes = WaveBuffers.bytes_for(wave, split=guide is not None and guide.splits)
    if integrator is not None:
        wave_bytes += integrator.wave_bytes(wave)
    env = scene.environment
    texels = env.image.shape[0] * env.image.shape[1] if env is not None and env.image is not None else 0
    try:
        memory.check(crop[2], crop[3], memory.estimate(npix, scene.n_triangles, wave_bytes, guide, integrator, texels))
    except SettingsError as e:
        raise SettingsError(f"{scene.path}: {e}") from None
    return wave


def _path_settings(scene, max_depth, rr_depth, seed, pixel_filter, crop):
    """(max_depth, rr_depth, seed, crop) checked, the scene's render settings where None."""
    rs = scene.render
    max_depth = rs.max_depth if max_depth is None else max_depth
    rr_depth = rs.rr_depth if rr_depth is None else rr_depth
    seed = rs.seed if seed is None else seed
    if isinstance(max_depth, bool) or not isinstance(max_depth, (int, np.integer)) or (max_depth < 1 and max_depth != -1):
        raise SettingsError(f"max_depth must be -1 (unlimited) or >= 1, got {max_depth!r}")
    rr_depth = _int_setting("rr_depth", rr_depth, 1)
    crop = _check_crop(crop, scene.width, scene.height)
    if pixel_filter not in FILTERS:
        raise unknown_name("pixel filter", pixel_filter, FILTERS)
    seed = _int_setting("seed", seed, 0)
    return max_depth, rr_depth, seed, crop


def make_context(scene, accel="embree", seed=None, max_depth=None, rr_depth=None, pixel_filter="box", crop=None,
                 threads=None, nee=True):
    """A RenderContext for tracing sources outside render() (session.trace_source): probe rays for
    training data or ground truth, a method's own passes. Settings as render(); threads: the
    accel's worker threads (Numba's kernels use the process's thread count); nee: next-event
    estimation on."""
    max_depth, rr_depth, seed, crop = _path_settings(scene, max_depth, rr_depth, seed, pixel_filter, crop)
    if threads is not None:
        threads = _int_setting("threads", threads, 1)
    acc = make_accel(accel, scene.tri, threads=threads or numba.config.NUMBA_NUM_THREADS)
    return RenderContext(scene, acc, build_lights(scene), seed, max_depth, rr_depth, pixel_filter, crop, nee)


def _render(scene, spp, time, guide, max_depth, rr_depth, seed, accel, n_threads, wave_size, progress, callback,
            guide_settings, pixel_filter, crop, path_loop, denoise, integ):
    """render() on n_threads Numba threads, with the Integrator `integ`."""
    rs = scene.render
    max_depth, rr_depth, seed, crop = _path_settings(scene, max_depth, rr_depth, seed, pixel_filter, crop)
    wave_size = _int_setting("wave_size", wave_size, 1)
    explicit = path_loop is not None
    path_loop = "lanes" if path_loop is None else path_loop
    if path_loop not in PATH_LOOPS:
        raise unknown_name("path loop", path_loop, PATH_LOOPS)
    if time is None:
        spp = _int_setting("spp", rs.spp if spp is None else spp, 1)
    elif not (isinstance(time, (int, float)) and math.isfinite(time) and time > 0):
        raise SettingsError(f"time must be a positive number of seconds, got {time!r}")
    if isinstance(guide, str):
        guide, spec_settings = parse_spec(guide)
        g = make_guide(guide, **dict(spec_settings, **(guide_settings or {})))
    else:  # a guide object (for experiments): a tracer.guiding.base.Guide
        if not isinstance(guide, Guide):
            raise SettingsError(f"guide must be a name or a tracer.guiding.base.Guide, got {type(guide).__name__}")
        g, guide = guide, guide.name
        if guide_settings:
            raise SettingsError("guide_settings go with a guide name, not with a guide object")

    integ.check_guide(g, guide)
    if scene.delta_lights and not integ.nee:
        kinds = ", ".join(sorted({d.kind for d in scene.delta_lights}))
        raise SettingsError(f"{scene.path}: its {kinds} light(s) are reached by next-event estimation alone; "
                            f"without it (nee=0) they would add nothing: render with NEE on")
    integ.start()
    if g is not None and not integ.nee:
        g.learn_direct = True  # without NEE, the direct light is the guide's to find too
    if g is not None:
        g.follow_nee(integ.nee)
    npix = crop[2] * crop[3]
    wave = check_memory(scene, crop, wave_size, spp if time is None else None, g, integ)

    (acc, lights), t_setup, c_setup = _set_up(lambda: (make_accel(accel, scene.tri, threads=n_threads),
                                                         build_lights(scene)))
    ctx = RenderContext(scene, acc, lights, seed, max_depth, rr_depth, pixel_filter, crop, integ.nee)
    ctx.path_loop = path_loop
    if explicit and path_loop == "lanes" and (gaps := engine_gaps(acc.name)):
        log.warning("path_loop lanes: not with %s; the render runs on the other path loops", ", ".join(gaps))
    lane_kernels = None
    if path_loop == "lanes" and engine is not None and acc.name == "embree":
        # makes the lanes' scene tables: set-up time
        lane_kernels, dt, dc = _set_up(lambda: engine.class_kernels(ctx, g is not None))
        t_setup, c_setup = t_setup + dt, c_setup + dc
    # Trace throwaway paths first: they compile the kernels the render will run (or load them from
    # the cache), so that neither the time budget nor the stats count Numba's compile. The passes
    # run on the lanes (a guide's recorded paths too), or the loop path_loop
    # names; a render that runs neither (gpt's hybrid shift without a guide) compiles neither.
    kernels = compile_plan(g is not None, integ, acc.name, path_loop, lane_kernels,
                           g is not None and g.records_loop == "wave")
    if not _jit.kernels_cached(*kernels):
        log.warning(COMPILE_NOTE, extra={"compile_notice": True})
    t0 = _time.perf_counter()
    splits = g is not None and g.splits
    sigint = _Sigint()
    sigint.install(compiling=True)
    try:
        _warm_up(ctx, g, splits, integ, kernels, crop)
    finally:
        sigint.restore()
    if sigint.requested:  # a Ctrl-C whose KeyboardInterrupt a callback from C swallowed (Numba's)
        raise KeyboardInterrupt
    denoiser = den_reserve = None
    if denoise is not None:  # the device made, its weights loaded and its time measured off the clock
        from .denoise import Denoiser, reserve_seconds

        denoiser = Denoiser.shared(n_threads, denoise)
        den_reserve = denoiser.after_passes.get((crop[2], crop[3]))  # the last budget's call at this size
        if den_reserve is None:
            den_reserve = reserve_seconds(denoiser, crop[2], crop[3]) + AFTER_PASSES_SECONDS
    t_compile = _time.perf_counter() - t0 + c_setup
    t_start = _time.perf_counter() - t_setup  # the budget counts the scene set-up, not the compile
    if g is not None:
        g.prepare(scene, ctx)
        ctx.guide_state = g.state()
    buf = WaveBuffers(wave, split=splits)
    stats = Stats()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=spp if time is None else None, unit="spp", desc="render", leave=False,
                   bar_format="{l_bar}{bar}| {n:.0f}/{total_fmt} spp [{elapsed}<{remaining}]"
                   if time is None else "{desc}: {n:.0f} spp [{elapsed}, budget %gs]" % time)
    settings = {"accel": acc.name, "threads": int(n_threads), "seed": int(seed), "max_depth": int(max_depth),
                "rr_depth": int(rr_depth), "guide": guide, "pixel_filter": pixel_filter, "crop": list(crop),
                "wave_size": int(wave_size), "path_loop": path_loop, **integ.stats_settings(), **provenance()}

    def snapshot():
        return _stats(scene, stats, session.passes, session.sample0, t_setup, t_start, t_render, settings, t_compile,
                      g)

    reserve = integ.reserve(crop[2], crop[3]) + (den_reserve or 0.0) if time is not None else 0.0
    if time is not None and reserve >= 0.5 * time:
        log.warning(f"a time budget of {time:g} s: "
                    f"{_reserve_text(integ.name, reserve - (den_reserve or 0.0), den_reserve)} on a "
                    f"{crop[2]}x{crop[3]} image here, {reserve / time:.0%} of it"
                    + (", so the render will overrun it (each pixel gets 2 samples first)" if reserve >= time else ""))
    session = Session(ctx, g, buf, stats, spp if time is None else None, time, t_start, bar, callback, snapshot,
                      lambda: sigint.requested, reserve=reserve, integrator=integ)
    interrupted = False
    t_render = _time.perf_counter()
    try:
        sigint.install()
        if g is None:
            session.final_passes()
        else:
            g.schedule(session)
    except (KeyboardInterrupt, Stop) as e:
        interrupted = isinstance(e, KeyboardInterrupt)
    finally:
        sigint.restore()
        interrupted = interrupted or sigint.requested  # also when Ctrl-C came during the last wave
        if bar is not None:
            bar.n = stats.samples / npix  # what it showed, to the last wave, as stats["spp_mean"]
            bar.refresh()
            bar.close()
    result = integ.result(session, interrupted, snapshot)
    session.snapshot = None  # the one cycle (snapshot reads the session): the accel's C memory goes with the frame
    if denoiser is not None:
        from .denoise import apply

        result.stats["denoise"] = denoise
        apply(result, denoiser)
    return result


COMPILE_NOTE = ("compiling the kernels this render runs, once per install or update of the tracer (on a 2-core VM: "
                "about 0.5 min for the path tracer, 2 where a material or light needs the lanes' general kernel, "
                "4.5 with a guide, 8 for gpt) ...")


def _reserve_text(integrator, solve, den):
    parts = ([f"{integrator}'s solve takes {solve:.2f} s"] if solve > 0 else []) + \
        ([f"the denoiser {den:.2f} s"] if den else [])
    return " and ".join(parts)


def _set_up(step):
    """(step(), its seconds less Numba's compile inside it, that compile's seconds): on a new install
    the set-up's own jitted helpers (the lights' tables, the lanes' alias table) compile there,
    which a time budget, counting the set-up, should not."""
    t = _time.perf_counter()
    with _jit.compile_clock() as spent:
        out = step()
    return out, _time.perf_counter() - t - spent[0], spent[0]


def _warm_up(ctx, g, splits, integ, kernels, crop):
    """Trace throwaway paths through each kernel of `kernels` (compile_plan's) and the guide's and
    integrator's own warm-ups."""
    if g is not None:  # recorded paths: on the render's loop, and on the wavefront where the plan holds it
        render_loop = ctx.path_loop
        try:
            for loop in dict.fromkeys([render_loop] + (["wave"] if "path.shade" in kernels else [])):
                ctx.path_loop = loop
                trace_wave(ctx, WaveBuffers(1), CameraSource(), Film(crop[2], crop[3]), 0, 0, 1, Stats(),
                           observe=lambda rec: None)
        finally:
            ctx.path_loop = render_loop
    lanes = "lanes.classify" in kernels
    if g is not None or lanes or "thread_loop.trace_paths" in kernels or "path.shade" in kernels:
        trace_wave(ctx, WaveBuffers(1), CameraSource(), Film(crop[2], crop[3]), 0, 0, 1, Stats())
    if "path.shade" in kernels and ctx.nee:
        warm_up_shadows(ctx)
    if lanes:
        engine.warm_up(ctx, WaveBuffers(1, split=splits), kernels, warm_up_plan() if splits else None)
    if g is not None:
        warm_up_guides(ctx)
        g.warm_up(ctx)
    if splits:
        warm_up_splitting(ctx)
    integ.warm_up(ctx)


def engine_gaps(accel):
    """What keeps a render's passes off the lanes of tracer.engine (path_loop="lanes"): short reasons.
    (Passes that take external primary samples, pss's, take the other loops without a word: the
    render's stats say how many samples the lanes traced.)"""
    return [f"the {accel} accel (the lanes need Embree)"] if accel != "embree" else []


def compile_plan(guided, integ, accel, path_loop="lanes", lane_kernels=None, wave_records=False):
    """The kernels ("module.function") a render's warm-up compiles: the integrator's, the lanes'
    in place of the per-thread loop under path_loop "lanes" (lane_kernels: the scene's,
    engine.lanes.class_kernels; None: a guess without the scene), the wavefront's where the lanes cannot run (another accel,
    path_loop="wave" or "thread" under a guide) or the guide records on it (wave_records: its
    records_loop), and the guides' photon tracer. What _jit.kernels_cached checks before a render,
    to say that a compile is coming."""
    path_loop = path_loop or "lanes"
    names = list(integ.kernels())
    plain = "thread_loop.trace_paths" in names  # the path tracer's passes
    lanes = plain and path_loop == "lanes" and accel == "embree"
    if guided or lanes or (plain and (accel != "embree" or path_loop == "wave")):
        names = [n for n in names if n != "thread_loop.trace_paths"]
        if lanes:
            names += (list(lane_kernels) if lane_kernels is not None else
                      ["lanes.classify"] + (["listed.shade_listed"] if guided else []))
        if not lanes or (guided and wave_records):
            names.append("path.shade")
        if guided and accel == "embree" and path_loop == "thread":
            names.append("thread_loop.trace_paths")
        if guided:
            names.append("photons.scatter")
    if accel == "numba":
        names.append("numba_bvh._intersect_batch")
    return tuple(names)


class _Sigint:
    """Ctrl-C during the passes: the first SIGINT sets `requested` (the render stops before its
    next wave), and puts Python's handler back, so that a second one interrupts at once. While
    compiling (install(compiling=True)) it also raises KeyboardInterrupt at once, as Python's
    handler does, and `requested` keeps the Ctrl-C that a callback from C swallows: Numba's
    machine-code generation calls back into Python when it ends (llvmlite's object cache, through
    ctypes, which prints an exception raised there and drops it), so a Ctrl-C that came during it
    was lost and the render ran to its end. Only in the main thread, and only over Python's
    default handler (a program's own is left alone)."""

    def __init__(self):
        self.requested = False
        self._installed = False
        self._compiling = False

    def install(self, compiling=False):
        self.requested, self._compiling = False, compiling
        if threading.current_thread() is threading.main_thread() and \
                signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, self._handle)
            self._installed = True

    def _handle(self, signum, frame):
        self.requested = True
        signal.signal(signal.SIGINT, signal.default_int_handler)
        if self._compiling:
            raise KeyboardInterrupt

    def restore(self):
        if self._installed:
            signal.signal(signal.SIGINT, signal.default_int_handler)
            self._installed = False


def _stats(scene, stats, passes, spp, t_setup, t_start, t_render, settings, t_compile, guide=None):
    now = _time.perf_counter()
    elapsed = now - t_render
    samples = stats.samples
    rays = stats.rays + stats.shadow_rays
    return {
        "scene": os.path.abspath(scene.path),
        "width": settings["crop"][2],
        "height": settings["crop"][3],
        "spp": int(spp),
        "spp_mean": samples / (settings["crop"][2] * settings["crop"][3]),
        "passes": [dict(p) for p in passes],
        "samples": int(samples),
        "rays": int(rays),
        "camera_and_bounce_rays": int(stats.rays),
        "shadow_rays": int(stats.shadow_rays),
        "time_setup": t_setup,
        "time_compile": t_compile,
        "time_total": now - t_start,  # what a time budget counts: set-up, learning, passes, solve
        "time_render": elapsed,  # from the first pass on (what Msamples/s divide by)
        "time_stages": dict(stats.time),
        "time_trace_parts": dict(stats.trace_parts),
        "msamples_per_s": samples / elapsed / 1e6 if elapsed > 0 else 0.0,
        "mrays_per_s": rays / elapsed / 1e6 if elapsed > 0 else 0.0,
        "nonfinite_samples": int(stats.nonfinite),
        "split_copies": int(stats.split_copies),
        "lane_samples": int(stats.lane_samples),
        "lane_general_vertices": int(stats.lane_general),
        "lane_listed_vertices": int(stats.lane_listed),
        "window_ended": int(stats.window_ended),
        **settings,
        "texture_memory_bytes": scene.textures.nbytes if len(scene.textures) else 0,
        "guide_memory_bytes": int(guide.peak_memory) if guide is not None else 0,
        "guide_time_learning": float(guide.time_learning) if guide is not None else 0.0,
        # the maps' rebuild between passes, and network inference (0 for guides without a network)
        "guide_time_update": float(getattr(guide, "time_update", 0.0)) if guide is not None else 0.0,
        "guide_time_inference": float(getattr(guide, "time_inference", 0.0)) if guide is not None else 0.0,
        "guide_stats": dict(guide.stats(), **({"training": dict(guide.training)} if guide.training else {}))
        if guide is not None else {},
    }


def write_outputs(result, path, exposure=0.0, variance=False, reference=None):
    """Write `path` (EXR, RGB, linear), a PNG preview, `<name>.aovs.exr` (albedo, normal, depth),
    for a denoised render `<name>.denoised.exr` and `.denoised.png`, with `variance` `<name>.variance.exr` (result.variance, the variance of each pixel's mean), for
    a gradient-domain render `<name>.base.exr`, `.dx.exr`, `.dy.exr`, and a stats JSON beside it;
    returns the paths of the EXR, the PNG and the JSON. A missing folder is created.

    The PNG is imageio.tonemap: automatic exposure (imageio.auto_exposure: the log-average of block
    means to middle grey) of the image, or of `reference` (an (H, W, 3) image of the same scene)
    when given, so that previews of several methods share one exposure; plus `exposure` stops, the
    ACES filmic curve, sRGB. The stops applied go to result.stats["preview_exposure"] and the JSON.
    Each file is written under a temporary name and renamed into place."""
    from .imageio import auto_exposure, preview, replace_atomically, write_image

    base, ext = os.path.splitext(os.fspath(path))
    if ext.lower() != ".exr":
        raise SettingsError(f"{path}: output must be an .exr file (a PNG and a JSON are written beside it)")
    folder = os.path.dirname(os.path.abspath(path))
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as e:
        raise SettingsError(f"{path}: cannot create the folder {folder} ({e.strerror or e})") from None
    write_image(path, result.image)
    png = base + ".png"
    stops = float(exposure) + math.log2(auto_exposure(result.image if reference is None else reference))
    write_image(png, preview(result.image, stops))
    a = result.aovs
    write_image(base + ".aovs.exr", np.concatenate([a["albedo"], a["normal"], a["depth"]], axis=2),
                channel_names=("albedo.R", "albedo.G", "albedo.B", "N.X", "N.Y", "N.Z", "Z"))
    if variance:
        write_image(base + ".variance.exr", result.variance)
    if result.denoised is not None:  # render(denoise=...): OIDN's image, its preview at the same exposure
        write_image(base + ".denoised.exr", result.denoised)
        write_image(base + ".denoised.png", preview(result.denoised, stops))
    for name in ("base", "dx", "dy"):  # integrator gpt: the buffers the reconstruction came from
        if name in result.buffers:
            write_image(f"{base}.{name}.exr", result.buffers[name])
    js = base + ".json"
    result.stats["preview_exposure"] = stops
    text = json.dumps(result.stats, indent=1)

    def write_json(tmp):
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)

    replace_atomically(js, write_json)
    return path, png, js
