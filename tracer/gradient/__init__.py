"""Gradient-domain path tracing (`render(..., integrator="gpt")`): a base image and its
horizontal and vertical gradients from correlated offset paths (the hybrid shift: hybrid.py; random
replay: replay.py), reconstructed by screened Poisson (poisson.py)."""
import time as _time

import numpy as np

from ..errors import SettingsError, unknown_name
from . import poisson
from .replay import GradientFilms, gradient_passes  # noqa: F401

SHIFTS = ("hybrid", "replay")
ROUGHNESS = 0.001  # the hybrid shift reconnects between vertices rougher than this
INTEGRATORS = ("path", "gpt")


def check_settings(shift, recon, alpha, roughness=ROUGHNESS):
    """(shift, recon, alpha, roughness) checked: one clear error for each bad value."""
    if shift not in SHIFTS:
        raise unknown_name("shift", shift, SHIFTS)
    if isinstance(roughness, bool) or not isinstance(roughness, (int, float)) or not roughness >= 0:
        raise SettingsError(f"shift_roughness must be a number >= 0 (inf: never reconnect), got {roughness!r}")
    if recon not in poisson.RECONSTRUCTIONS:
        raise unknown_name("reconstruction", recon, poisson.RECONSTRUCTIONS)
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)) or not (np.isfinite(alpha) and alpha > 0):
        raise SettingsError(f"recon_alpha must be a positive number, got {alpha!r}")
    return shift, recon, float(alpha), float(roughness)


def warm_up(ctx, shift, roughness):
    """Compile (or load from the cache) the kernels of `shift` before a render's clock starts."""
    if shift == "hybrid":
        from ..wave import WaveBuffers
        from . import hybrid

        hybrid.warm_up(ctx, WaveBuffers(1), roughness)


def solve_time_estimate(recon, width, height, alpha):
    """Seconds a `recon` solve of a width x height RGB image will take: the solve of a noisy 64 x 64
    image (a smooth image, noise 0.3 on the base and 0.05 on the gradients) timed here, scaled by
    the pixel count (the solvers' iteration counts are bounded; their DCTs grow as N log N)."""
    if recon == "none":
        return 0.0
    y, x = np.mgrid[0:64, 0:64] / 64.0
    img = np.repeat((np.sin(5 * x + 3 * y) + 1.5 + (x > 0.5))[:, :, None], 3, axis=2)
    rng = np.random.default_rng(0)
    b = img + rng.normal(scale=0.3, size=img.shape)
    gx = poisson.grad_x(img) + rng.normal(scale=0.05, size=img.shape)
    gy = poisson.grad_y(img) + rng.normal(scale=0.05, size=img.shape)
    poisson.reconstruct(recon, b, gx, gy, alpha)  # the first call pays for scipy's set-up
    t0 = _time.perf_counter()
    poisson.reconstruct(recon, b, gx, gy, alpha)
    return (_time.perf_counter() - t0) * (width * height) / (64.0 * 64.0)


def solve(films, recon, alpha):
    """Reconstruct from GradientFilms: (image (H,W,3) float64, the reconstruction of the indirect
    light plus the direct buffer; buffers {name: float32 (H,W,3), depth (H,W,1)}: base,
    base_variance, dx, dx_variance, dy, dy_variance, direct, indirect, and the features of a
    learned reconstruction: albedo (at the first vertex that is not a delta BSDF), normal, depth
    (divided by the largest, so in [0, 1]); seconds the solve took)."""
    t0 = _time.perf_counter()
    indirect, dx, dy = films.indirect.mean(), films.dx.mean(), films.dy.mean()
    image = poisson.reconstruct(recon, indirect, dx, dy, alpha) + films.direct.mean()
    t_solve = _time.perf_counter() - t0
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    buffers = {"base": f32(films.base.mean()), "base_variance": f32(films.base.variance()),
               "dx": f32(dx), "dx_variance": f32(films.dx.variance()), "dy": f32(dy),
               "dy_variance": f32(films.dy.variance()), "direct": f32(films.direct.mean()),
               "indirect": f32(indirect)}
    aovs = films.base.aovs()
    depth = aovs["depth"].astype(np.float64)
    finite = depth[np.isfinite(depth)]
    top = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
    buffers.update(albedo=aovs["albedo"], normal=aovs["normal"],
                   depth=f32(np.clip(np.where(np.isfinite(depth), depth, top) / top, 0.0, 1.0)))
    return image, buffers, t_solve
