"""The library entry point: `render(scene, spp=..., guide="bsdf", ...) -> RenderResult`.

A render runs as passes over the whole image; each pass renders some samples per pixel
in waves of at most `wave_size` paths (memory stays flat with image size). Between passes a
callback may look at the film (guides learn there). With `time=S` the passes continue,
doubling in size, until the next one would not fit in the budget. Ctrl-C stops the render
between waves and returns what was rendered so far.
"""
import json
import math
import os
import time as _time
from dataclasses import dataclass, field

import numba
import numpy as np

from .bvh import make_accel
from .errors import SettingsError, unknown_name
from .film import Film
from .guiding import make_guide
from .integrator import Stats, WaveBuffers, trace_wave
from .lights import build_lights

DEFAULT_WAVE = 1 << 16
FILTERS = ("box", "point")


@dataclass
class RenderResult:
    """image (H,W,3) float32 mean radiance; variance (H,W,3) float32 variance of that mean;
    aovs {albedo (H,W,3), normal (H,W,3), depth (H,W,1)} float32; stats (dict, JSON-ready)."""

    image: np.ndarray
    variance: np.ndarray
    aovs: dict
    stats: dict
    film: Film = field(repr=False)

    def __repr__(self):
        s = self.stats
        return (f"RenderResult({self.image.shape[1]}x{self.image.shape[0]}, {s['spp']} spp, "
                f"{s['time_total']:.2f} s, {s['msamples_per_s']:.2f} Msamples/s)")


class _Context:
    """What the wave kernels need, gathered once per render."""

    def __init__(self, scene, accel, lights, seed, max_depth, rr_depth, pixel_filter, crop):
        self.scene, self.accel, self.lights = scene, accel, lights
        self.crop = np.asarray(crop, dtype=np.int64)
        self.jitter = pixel_filter == "box"
        tri = scene.tri
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.tri_normal = n / np.linalg.norm(n, axis=1, keepdims=True)  # (F,3) unit, CCW side
        self.cam = scene.camera.packed()
        self.seed = int(seed)
        self.max_depth = int(max_depth)
        self.rr_depth = int(rr_depth)
        # Ray offset: scaled to the scene, well above float32's resolution at its size
        extent = float(np.abs(scene.bounds).max())
        self.eps = 1e-5 * max(accel.scale, extent)


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
           guide_settings=None, pixel_filter="box", crop=None):
    """Render `scene` (from tracer.load_scene) and return a RenderResult.

    spp        samples per pixel (default: the scene's render.spp); ignored when `time` is given
    time       wall-clock budget in seconds for the whole render (instead of spp)
    guide      registered sampler name ("bsdf"); guide_settings: dict of its settings
    max_depth, rr_depth, seed: override the scene's render settings (Mitsuba conventions)
    accel      "embree" or "numba"; threads: worker threads (default: all cores)
    callback   f(pass_index, film, stats_dict) called after every pass; return False to stop
    pixel_filter  "box" (default: samples uniform over the pixel) or "point" (every sample
               through the pixel centre: no anti-aliasing, so a pixel never mixes two surfaces;
               for per-pixel regression tests and debugging)
    crop       (x0, y0, w, h): render only that window of the image (its pixels are the same
               samples as in the full render)
    """
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
    wave_size = _int_setting("wave_size", wave_size, 1)
    if time is None:
        spp = _int_setting("spp", rs.spp if spp is None else spp, 1)
    elif not (isinstance(time, (int, float)) and math.isfinite(time) and time > 0):
        raise SettingsError(f"time must be a positive number of seconds, got {time!r}")
    g = make_guide(guide, **(guide_settings or {}))
    if g is not None:  # no guide can be registered before the guiding framework lands
        raise SettingsError(f"guide {guide!r} is not supported by this integrator yet")
    if threads is not None:
        threads = _int_setting("threads", threads, 1)
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    n_threads = threads or numba.config.NUMBA_NUM_THREADS

    t_start = _time.perf_counter()
    acc = make_accel(accel, scene.tri, threads=n_threads)
    lights = build_lights(scene)
    t_setup = _time.perf_counter() - t_start
    ctx = _Context(scene, acc, lights, seed, max_depth, rr_depth, pixel_filter, crop)
    # Trace one throwaway path first: it compiles the kernels (or loads them from the cache), so
    # that neither the time budget nor the stats count Numba's compile.
    t0 = _time.perf_counter()
    trace_wave(ctx, WaveBuffers(1), Film(crop[2], crop[3]), 0, 0, 1, Stats())
    t_compile = _time.perf_counter() - t0
    t_start = _time.perf_counter() - t_setup  # the budget counts the scene set-up, not the compile
    film = Film(crop[2], crop[3])
    npix = film.n_pixels
    buf = WaveBuffers(min(wave_size, npix * (spp if time is None else 1024)))
    stats = Stats()
    passes = []
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=spp if time is None else None, unit="spp", desc="render", leave=False,
                   bar_format="{l_bar}{bar}| {n:.0f}/{total_fmt} spp [{elapsed}<{remaining}]"
                   if time is None else "{desc}: {n:.0f} spp [{elapsed}, budget %gs]" % time)
    settings = {"accel": acc.name, "threads": int(n_threads), "seed": int(seed), "max_depth": int(max_depth),
                "rr_depth": int(rr_depth), "guide": guide, "pixel_filter": pixel_filter, "crop": list(crop)}

    def snapshot():
        return _stats(scene, stats, passes, sample0, t_setup, t_render, settings, t_compile)

    interrupted = False
    sample0 = 0
    pass_spp = 1
    t_render = _time.perf_counter()
    try:
        for pass_index in range(1 << 30):  # bounded by spp or time below
            if time is None:
                if sample0 >= spp:
                    break
                pass_spp = min(pass_spp, spp - sample0)
            else:
                elapsed = _time.perf_counter() - t_start
                if passes:
                    per_spp = sum(p["time"] for p in passes) / sample0
                    fit = int((time - elapsed) / per_spp)
                    pass_spp = min(pass_spp, fit)
                    if pass_spp < 1:
                        break
            tp = _time.perf_counter()
            total = pass_spp * npix
            for g0 in range(0, total, buf.size):
                n = min(buf.size, total - g0)
                trace_wave(ctx, buf, film, sample0, g0, n, stats)
                if bar is not None:
                    bar.update(n / npix)
            sample0 += pass_spp
            passes.append({"spp": pass_spp, "time": _time.perf_counter() - tp})
            if callback is not None and callback(pass_index, film, snapshot()) is False:
                break
            pass_spp *= 2
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if bar is not None:
            bar.close()
    st = snapshot()
    st["interrupted"] = interrupted
    image = film.mean().astype(np.float32)
    variance = film.variance().astype(np.float32)
    return RenderResult(image, variance, film.aovs(), st, film)


def _stats(scene, stats, passes, spp, t_setup, t_render, settings, t_compile):
    elapsed = _time.perf_counter() - t_render
    samples = stats.samples
    rays = stats.rays + stats.shadow_rays
    return {
        "scene": os.path.abspath(scene.path),
        "width": settings["crop"][2],
        "height": settings["crop"][3],
        "spp": int(spp),
        "passes": list(passes),
        "samples": int(samples),
        "rays": int(rays),
        "camera_and_bounce_rays": int(stats.rays),
        "shadow_rays": int(stats.shadow_rays),
        "time_setup": t_setup,
        "time_compile": t_compile,
        "time_total": elapsed,
        "time_stages": dict(stats.time),
        "msamples_per_s": samples / elapsed / 1e6 if elapsed > 0 else 0.0,
        "mrays_per_s": rays / elapsed / 1e6 if elapsed > 0 else 0.0,
        "nonfinite_samples": int(stats.nonfinite),
        **settings,
        "guide_memory_bytes": 0,
        "guide_time_learning": 0.0,
    }


def write_outputs(result, path):
    """Write `path` (EXR, RGB), a PNG preview, `<name>.aovs.exr` (albedo, normal, depth) and a
    stats JSON beside it; returns the paths of the EXR, the PNG and the JSON."""
    from .imageio import write_image

    base, ext = os.path.splitext(os.fspath(path))
    if ext.lower() != ".exr":
        raise SettingsError(f"{path}: output must be an .exr file (a PNG and a JSON are written beside it)")
    write_image(path, result.image)
    png = base + ".png"
    write_image(png, result.image)
    a = result.aovs
    write_image(base + ".aovs.exr", np.concatenate([a["albedo"], a["normal"], a["depth"]], axis=2),
                channel_names=("albedo.R", "albedo.G", "albedo.B", "N.X", "N.Y", "N.Z", "Z"))
    js = base + ".json"
    with open(js, "w", encoding="utf-8") as f:
        json.dump(result.stats, f, indent=1)
    return path, png, js
