"""Reconstruction of sampling maps from noisy, sparse histograms.

Every reconstructor implements one method,

    reconstruct(maps, counts, masks) -> maps

on a batch of S voxels at once: `maps` (S, n_theta, n_phi) float32, each map normalised to sum
to 1 (or all zero); `counts` (S, n_theta, n_phi) float32, how many samples (photons or path
vertices) landed in each bin; `masks` (S, n_theta, n_phi) bool, bins that hold data. It returns
non-negative maps of the same shape (any scale: the caller normalises). These are the inputs of
the paper's network (its S_t, P_t and B_t), so the neural reconstruction of a later issue plugs in
here, registered in RECONSTRUCTORS.

Maps are full-sphere cylindrical: rows are z = cos(theta), columns are phi (periodic). The
classical filters here respect that: phi wraps, z is mirrored at the poles.

- `gaussian`: separable Gaussian blur of `sigma` bins (default 1); it keeps each map's total.
- `pullpush`: pull-push (Gortler et al. 1996): empty bins are filled from a pyramid of
  count-weighted averages; bins with data keep their value.
- `none`: the histogram as it is.
"""
import numpy as np
from numba import prange

from .._jit import kernel
from ..errors import SettingsError, unknown_name


@kernel
def _blur(maps, offs, w, out):
    """Separable blur of every map (S, n_theta, n_phi) with taps (offs, w): phi periodic, z mirrored
    at the poles (symmetric taps: the blur keeps each map's total)."""
    S, nt, nphi = maps.shape
    for s in prange(S):
        tmp = np.zeros((nt, nphi))
        for i in range(nt):
            for j in range(nphi):
                acc = 0.0
                for k in range(offs.shape[0]):
                    jj = (j - offs[k]) % nphi
                    acc += w[k] * maps[s, i, jj]
                tmp[i, j] = acc
        for i in range(nt):
            for j in range(nphi):
                acc = 0.0
                for k in range(offs.shape[0]):
                    ii = i - offs[k]
                    if ii < 0:
                        ii = -ii - 1
                    if ii >= nt:
                        ii = 2 * nt - 1 - ii
                    ii = min(max(ii, 0), nt - 1)
                    acc += w[k] * tmp[ii, j]
                out[s, i, j] = acc


class Reconstructor:
    name = "none"

    def reconstruct(self, maps, counts, masks):
        return maps

    def describe(self):
        return self.name


class Gaussian(Reconstructor):
    name = "gaussian"

    def __init__(self, sigma=1.0):
        if not (sigma >= 0.0):
            raise SettingsError(f"gaussian reconstruction needs sigma >= 0, got {sigma!r}")
        self.sigma = float(sigma)

    def _taps(self):
        r = max(int(np.ceil(3.0 * self.sigma)), 0)
        x = np.arange(-r, r + 1, dtype=np.float64)
        w = np.exp(-0.5 * (x / max(self.sigma, 1e-12)) ** 2) if self.sigma > 0 else (x == 0).astype(float)
        return x.astype(int), (w / w.sum()).astype(np.float32)

    def reconstruct(self, maps, counts, masks):
        offs, w = self._taps()
        if offs.size == 1:
            return maps
        out = np.empty_like(maps, dtype=np.float32)
        _blur(np.ascontiguousarray(maps, dtype=np.float32), offs.astype(np.int64), w.astype(np.float64), out)
        return out

    def describe(self):
        return f"gaussian(sigma={self.sigma:g})"


class PullPush(Reconstructor):
    name = "pullpush"

    def __init__(self, levels=4):
        self.levels = int(levels)
        if self.levels < 1:
            raise SettingsError(f"pullpush reconstruction needs levels >= 1, got {levels!r}")

    def reconstruct(self, maps, counts, masks):
        vals = [maps.astype(np.float64)]
        wts = [masks.astype(np.float64)]
        for _ in range(self.levels):  # pull: 2x2 weighted averages, weights capped at 1
            v, w = vals[-1], wts[-1]
            s, h, wd = v.shape
            if h % 2 or wd % 2:
                break
            vw = (v * w).reshape(s, h // 2, 2, wd // 2, 2).sum(axis=(2, 4))
            ws = w.reshape(s, h // 2, 2, wd // 2, 2).sum(axis=(2, 4))
            vals.append(np.where(ws > 0, vw / np.maximum(ws, 1e-300), 0.0))
            wts.append(np.minimum(ws, 1.0))
        for lvl in range(len(vals) - 2, -1, -1):  # push: fill what a level lacks from the coarser one
            up = np.repeat(np.repeat(vals[lvl + 1], 2, axis=1), 2, axis=2)
            w = wts[lvl]
            vals[lvl] = w * vals[lvl] + (1.0 - w) * up
        return vals[0].astype(np.float32)

    def describe(self):
        return f"pullpush(levels={self.levels})"


RECONSTRUCTORS = {"gaussian": Gaussian, "pullpush": PullPush, "none": Reconstructor}


def make_reconstructor(name, **settings):
    if name not in RECONSTRUCTORS:
        raise unknown_name("reconstruction", name, RECONSTRUCTORS)
    try:
        return RECONSTRUCTORS[name](**settings)
    except TypeError as e:
        raise SettingsError(f"reconstruction {name!r}: {e}") from None
