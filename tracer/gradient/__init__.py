"""Gradient-domain path tracing (`render(..., integrator="gpt")`, tracer.integrators.gpt): a base image and its
horizontal and vertical gradients from correlated offset paths (the hybrid shift: hybrid.py; random
replay: replay.py), reconstructed by screened Poisson (poisson.py) or by GradNet (gradnet.py, whose
settings are RECON_DEFAULTS["gradnet"]: weights, the name of the shipped weights; correction, 1 to
apply eq. 13's energy correction, 0 not to)."""
import functools
import re
import time as _time

import numpy as np

from ..errors import SettingsError, unknown_name
from . import poisson
from .films import GradientFilms

SHIFTS = ("hybrid", "replay")
ROUGHNESS = 0.001  # the hybrid shift reconnects between vertices rougher than this
DIRECT_ROUGHNESS = 0.01  # the light a first vertex smoother than this reflects is the direct buffer's
RECONSTRUCTIONS = poisson.RECONSTRUCTIONS + ("gradnet",)
RECON_DEFAULTS = {"gradnet": {"weights": "gradnet", "correction": 1}}


@functools.lru_cache(maxsize=4)
def gradnet_model(name):
    """The GradNet weights `name` (tracer/weights/<name>.pt), loaded once per process."""
    from . import gradnet

    return gradnet.load(name)[0]


def recon_settings(recon, opts=None):
    """The settings of reconstruction `recon`: its defaults updated by opts, checked (GradNet's
    weights are loaded here, so that a missing file fails before the render)."""
    defaults = RECON_DEFAULTS.get(recon, {})
    opts = dict(opts or {})
    bad = sorted(set(opts) - set(defaults))
    if bad:
        raise SettingsError(f"reconstruction {recon!r} has no setting {bad[0]!r}; valid: "
                            + (", ".join(sorted(defaults)) or "none"))
    s = dict(defaults, **opts)
    if recon == "gradnet":
        if s["correction"] not in (0, 1) or isinstance(s["correction"], float):
            raise SettingsError(f"recon setting correction must be 0 or 1, got {s['correction']!r}")
        s["correction"] = int(s["correction"])
        if not (isinstance(s["weights"], str) and re.fullmatch(r"[A-Za-z0-9_.-]+", s["weights"])):
            raise SettingsError(f"recon setting weights must be the name of shipped weights, got {s['weights']!r}")
        try:
            gradnet_model(s["weights"])
        except FileNotFoundError as e:
            raise SettingsError(str(e) if ".json" in str(e) else f"weights {s['weights']!r}: {e}") from None
        except Exception as e:  # another network's weights, or a damaged file
            raise SettingsError(f"weights {s['weights']!r} are not GradNet weights that load "
                                f"({type(e).__name__}: {str(e).splitlines()[0][:120]})") from None
    return s


def check_settings(shift, recon, alpha, roughness=ROUGHNESS, recon_opts=None, direct_roughness=DIRECT_ROUGHNESS):
    """(shift, recon, alpha, roughness, recon's settings, direct_roughness) checked: one clear error
    for each bad value."""
    if shift not in SHIFTS:
        raise unknown_name("shift", shift, SHIFTS)
    if isinstance(roughness, bool) or not isinstance(roughness, (int, float)) or not roughness >= 0:
        raise SettingsError(f"shift_roughness must be a number >= 0 (inf: never reconnect), got {roughness!r}")
    if isinstance(direct_roughness, bool) or not isinstance(direct_roughness, (int, float)) or \
            not direct_roughness >= 0:
        raise SettingsError(f"direct_roughness must be a number >= 0 (0: only light seen directly is direct), "
                            f"got {direct_roughness!r}")
    if recon not in RECONSTRUCTIONS:
        raise unknown_name("reconstruction", recon, RECONSTRUCTIONS)
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)) or not (np.isfinite(alpha) and alpha > 0):
        raise SettingsError(f"recon_alpha must be a positive number, got {alpha!r}")
    return (shift, recon, float(alpha), float(roughness), recon_settings(recon, recon_opts),
            float(direct_roughness))


def warm_up(ctx, shift, roughness, direct_roughness=DIRECT_ROUGHNESS, n=4):
    """Compile (or load from the cache) the kernels of `shift` before a render's clock starts:
    each hybrid kernel on an empty wave, then a wave of n real paths into throwaway films (the
    camera's, the films' and the other kernels only a real path reaches: without it a cold first
    pass compiled them on the budget's clock, 11 s of a 12 s pass)."""
    from ..wave import Stats, WaveBuffers

    films = GradientFilms(int(ctx.crop[2]), int(ctx.crop[3]))
    if shift == "hybrid":
        from . import hybrid

        hybrid.warm_up(ctx, WaveBuffers(1), roughness, direct_roughness)
        hybrid.trace_hybrid_wave(ctx, WaveBuffers(n), hybrid.HybridBuffers(n), films, 0, 0, n, Stats(), roughness,
                                 direct_roughness)
    else:
        from .replay import trace_gradient_wave

        trace_gradient_wave(ctx, WaveBuffers(n), films, 0, 0, n, Stats())


def _noisy_buffers(n):
    """{indirect, dx, dy}: an n x n smooth RGB image with an edge, noise 0.3 on it and 0.05 on its
    gradients (float64)."""
    y, x = np.mgrid[0:n, 0:n] / float(n)
    img = np.repeat((np.sin(5 * x + 3 * y) + 1.5 + (x > 0.5))[:, :, None], 3, axis=2)
    rng = np.random.default_rng(0)
    return {"indirect": img + rng.normal(scale=0.3, size=img.shape),
            "dx": poisson.grad_x(img) + rng.normal(scale=0.05, size=img.shape),
            "dy": poisson.grad_y(img) + rng.normal(scale=0.05, size=img.shape)}


def solve_time_estimate(recon, width, height, alpha, opts=None):
    """Seconds a `recon` solve of a width x height RGB image will take: solves of noisy 64 x 64 and
    128 x 128 images (a smooth image, noise 0.3 on the base and 0.05 on the gradients) timed here,
    and a line through the two (a fixed cost per solve, the solvers' bounded iterations, and a cost
    per pixel; the DCTs' log N is left out). Scaling the 64 x 64 solve alone overestimated a
    256 x 192 L1 solve 2.5x and left 4% of a 10 s budget unused. For gradnet, the same line through
    its inference and energy correction (and the solve it corrects, for weights that correct one)
    on the two noisy images, with variance buffers: scaling the 128 x 128 one alone by the pixel
    count took its fixed cost 3.5 times at 320 x 180 (1.3 s kept for a 0.42 s inference)."""
    if recon == "none":
        return 0.0
    times = []
    for n in (64, 128):
        if recon == "gradnet":
            s = recon_settings(recon, opts)
            b = _noisy_buffers(n)
            z = np.zeros_like(b["indirect"])
            v = np.full_like(z, 0.01)
            b.update(direct=z, albedo=z + 0.5, normal=z, depth=z[..., :1] + 0.5, base_variance=v, dx_variance=v,
                     dy_variance=v)
            if n == 64:
                reconstruct_buffers(b, recon, alpha, s)  # the first call loads the weights
            times.append(reconstruct_buffers(b, recon, alpha, s)[1])
            continue
        nb = _noisy_buffers(n)
        b, gx, gy = nb["indirect"], nb["dx"], nb["dy"]
        if n == 64:
            poisson.reconstruct(recon, b, gx, gy, alpha)  # the first call pays for scipy's set-up
        t0 = _time.perf_counter()
        poisson.reconstruct(recon, b, gx, gy, alpha)
        times.append(_time.perf_counter() - t0)
    # (at least half the 128 x 128 solve's time per pixel: timing noise must not make a large
    # image's solve look as cheap as a small one's)
    per_pixel = max((times[1] - times[0]) / (128 * 128 - 64 * 64), 0.5 * times[1] / (128 * 128))
    return max(times[0] + per_pixel * (width * height - 64 * 64), 0.0)


def reconstruct_buffers(buffers, recon, alpha, opts=None, deadline=None, info=None):
    """(image (H,W,3) float64: the reconstruction of buffers["indirect"] from it and its gradients
    buffers["dx"], ["dy"] (and, for gradnet, the features albedo, normal, depth, and the variance
    buffers base_variance, dx_variance, dy_variance where the network reads them) plus
    buffers["direct"]; seconds the solve or the network's inference with its energy correction
    took). The buffers are those of a gpt render (solve's), so that one render can be
    reconstructed every way. deadline (time.perf_counter seconds): the time the L1 solve fills
    and ends by; info (a dict): gets the L1 solve's "reweights" (poisson.solve_l1)."""
    t0 = _time.perf_counter()
    if recon == "gradnet":
        from . import gradnet

        import numba
        import torch

        s = recon_settings(recon, opts)
        b = buffers
        torch.set_num_threads(numba.get_num_threads())  # the render's thread count (render(threads=...))
        variances = tuple(b.get(k) for k in ("base_variance", "dx_variance", "dy_variance"))
        rec = gradnet.reconstruct(gradnet_model(s["weights"]), b["indirect"], b["dx"], b["dy"], b["albedo"],
                                  b["normal"], b["depth"], None if any(v is None for v in variances) else variances)
        if s["correction"]:
            rec = gradnet.energy_correction(rec, b["indirect"])
        image = rec.astype(np.float64)
    else:
        image = poisson.reconstruct(recon, buffers["indirect"], buffers["dx"], buffers["dy"], alpha, deadline, info)
    t_solve = _time.perf_counter() - t0
    return image + buffers["direct"], t_solve


def solve(films, recon, alpha, opts=None, deadline=None, info=None):
    """Reconstruct from GradientFilms: (image (H,W,3) float64, the reconstruction of the indirect
    light plus the direct buffer; buffers {name: float32 (H,W,3), depth (H,W,1)}: base,
    base_variance, dx, dx_variance, dy, dy_variance, direct, indirect, and the features of a
    learned reconstruction: albedo (at the first vertex that is not a delta BSDF), normal, depth
    (divided by the largest, so in [0, 1]); seconds the solve (or the network's inference, with
    its energy correction) took). deadline, info: reconstruct_buffers'."""
    indirect, dx, dy = films.indirect.mean(), films.dx.mean(), films.dy.mean()
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    aovs = films.base.aovs()
    depth = aovs["depth"].astype(np.float64)
    finite = depth[np.isfinite(depth)]
    top = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
    features = dict(albedo=aovs["albedo"], normal=aovs["normal"],
                    depth=f32(np.clip(np.where(np.isfinite(depth), depth, top) / top, 0.0, 1.0)))
    variances = {"base_variance": f32(films.base.variance()), "dx_variance": f32(films.dx.variance()),
                 "dy_variance": f32(films.dy.variance())}
    image, t_solve = reconstruct_buffers(dict(features, **variances, indirect=indirect, dx=dx, dy=dy,
                                              direct=films.direct.mean()), recon, alpha, opts, deadline, info)
    buffers = {"base": f32(films.base.mean()), "dx": f32(dx), "dy": f32(dy), "direct": f32(films.direct.mean()),
               "indirect": f32(indirect), **variances, **features}
    return image, buffers, t_solve
