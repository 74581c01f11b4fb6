"""Gradient-domain path tracing (`render(..., integrator="gpt")`): a base image and its
horizontal and vertical gradients from correlated offset paths (replay.py), reconstructed by
screened Poisson (poisson.py)."""
import time as _time

import numpy as np

from ..errors import SettingsError, unknown_name
from . import poisson
from .replay import GradientFilms, gradient_passes  # noqa: F401

SHIFTS = ("replay",)
INTEGRATORS = ("path", "gpt")


def check_settings(shift, recon, alpha):
    """(shift, recon, alpha) checked: one clear error for each bad value."""
    if shift not in SHIFTS:
        raise unknown_name("shift", shift, SHIFTS)
    if recon not in poisson.RECONSTRUCTIONS:
        raise unknown_name("reconstruction", recon, poisson.RECONSTRUCTIONS)
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)) or not (np.isfinite(alpha) and alpha > 0):
        raise SettingsError(f"recon_alpha must be a positive number, got {alpha!r}")
    return shift, recon, float(alpha)


def solve_time_estimate(recon, width, height, alpha):
    """Seconds a `recon` solve of a width x height RGB image will take: a 64 x 64 solve of noise
    timed here, scaled by the pixel count (measured on this 2-core VM, L1 of noise: 0.10 s at 64^2,
    1.8 s at 256^2, 9.4 s at 512^2; of a 256^2 render, about 1 s)."""
    if recon == "none":
        return 0.0
    z = np.random.default_rng(0).random((3, 64, 64, 3))
    poisson.reconstruct(recon, z[0], z[1], z[2], alpha)  # the first call pays for scipy's set-up
    t0 = _time.perf_counter()
    poisson.reconstruct(recon, z[0], z[1], z[2], alpha)
    return (_time.perf_counter() - t0) * (width * height) / (64.0 * 64.0)


def solve(films, recon, alpha):
    """Reconstruct from GradientFilms: (image (H,W,3) float64, the reconstruction of the indirect
    light plus the direct buffer; buffers {name: (H,W,3) float32}; seconds the solve took)."""
    t0 = _time.perf_counter()
    indirect, dx, dy = films.indirect.mean(), films.dx.mean(), films.dy.mean()
    image = poisson.reconstruct(recon, indirect, dx, dy, alpha) + films.direct.mean()
    t_solve = _time.perf_counter() - t0
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    buffers = {"base": f32(films.base.mean()), "base_variance": f32(films.base.variance()),
               "dx": f32(dx), "dx_variance": f32(films.dx.variance()), "dy": f32(dy),
               "dy_variance": f32(films.dy.variance()), "direct": f32(films.direct.mean()),
               "indirect": f32(indirect)}
    return image, buffers, t_solve
