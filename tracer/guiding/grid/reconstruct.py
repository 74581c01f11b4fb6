"""Reconstruction of sampling maps from noisy, sparse histograms.

Every reconstructor implements one method,

    reconstruct(maps, counts, masks, prev=None, prev_counts=None) -> maps

on a batch of S voxels at once: `maps` (S, n_theta, n_phi) float32, each map normalised to sum
to 1 (or all zero); `counts` (S, n_theta, n_phi) float32, how many samples (photons or path
vertices) landed in each bin; `masks` (S, n_theta, n_phi) bool, bins that hold data; `prev` and
`prev_counts` the same voxels' maps and counts at the previous update (None: not known). It
returns non-negative maps of the same shape (any scale: the caller normalises). These are the
inputs of the paper's network (S_t, S_{t-1}, P_t, P_{t-1}, B_t of equation 11).

Maps are full-sphere cylindrical: rows are z = cos(theta), columns are phi (periodic). The
classical filters here respect that: phi wraps, z is mirrored at the poles.

- `gaussian`: separable Gaussian blur of `sigma` bins (default 1); it keeps each map's total.
- `pullpush`: pull-push (Gortler et al. 1996): empty bins are filled from a pyramid of
  count-weighted averages; bins with data keep their value.
- `none`: the histogram as it is.
- `cnn`: the photon map network (tracer.guiding.grid.photon_cnn) with the shipped weights
  (tracer/weights/photon_cnn.*), trained offline by learn/ on procedural scenes, for the maps
  holding fewer than `max_photons` photons (the Gaussian filter for the others); one batched
  torch pass per update, under torch.inference_mode(). Its time is kept in `time_inference`.
"""
import time

import numba
import numpy as np
from numba import prange

from ..._jit import kernel
from ...errors import SettingsError, unknown_name


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
    neural = False  # a network: it has `dense`, the classical filter used for what it was not trained on
    time_inference = 0.0  # seconds spent in network inference (neural reconstructors)
    maps_inferred = 0  # maps the network reconstructed

    def reconstruct(self, maps, counts, masks, prev=None, prev_counts=None):
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

    def reconstruct(self, maps, counts, masks, prev=None, prev_counts=None):
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

    def reconstruct(self, maps, counts, masks, prev=None, prev_counts=None):
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


class CNN(Reconstructor):
    """The photon map network: S_d = F(S_t, S_{t-1}, P_t, P_{t-1}, B_t), for maps holding fewer than
    `max_photons` photons; denser maps take the Gaussian filter of `sigma` bins (`dense`), within
    3.4% of the network's L1 there where the training data reach (docs/photon_cnn.md) and far
    cheaper. Loads the shipped weights on first use (or `weights`, a folder holding photon_cnn.pt
    and .json)."""

    name = "cnn"
    neural = True

    def __init__(self, weights=None, max_photons=1000.0, sigma=1.0, batch=64):
        if not (max_photons >= 0.0):
            raise SettingsError(f"cnn reconstruction needs max_photons >= 0, got {max_photons!r}")
        self.weights = weights
        self.max_photons = float(max_photons)
        self.dense = Gaussian(sigma)
        self.batch = int(batch)
        self.model = self.manifest = None
        self.time_inference = 0.0
        self.maps_inferred = 0

    def load(self):
        if self.model is None:
            from . import photon_cnn

            try:
                self.model, self.manifest = (photon_cnn.load() if self.weights is None
                                             else photon_cnn.load(folder=self.weights))
            except FileNotFoundError as e:
                raise SettingsError(f"reconstruction cnn: {e}") from None
        return self.model

    def check_map(self, n_theta, n_phi):
        """The network was trained on one map size: others are an error."""
        self.load()
        want = tuple(self.manifest["map"])
        if (n_theta, n_phi) != want:
            raise SettingsError(f"reconstruction cnn was trained on {want[0]}x{want[1]} maps (map_height x "
                                f"map_width); got {n_theta}x{n_phi}")

    def reconstruct(self, maps, counts, masks, prev=None, prev_counts=None):
        import torch

        from . import photon_cnn

        model = self.load()
        out = np.empty(maps.shape, np.float32)
        sparse = counts.reshape(counts.shape[0], -1).sum(axis=1) < self.max_photons
        if not sparse.all():
            d = ~sparse
            out[d] = self.dense.reconstruct(maps[d], counts[d], masks[d])
        if sparse.any():
            t0 = time.perf_counter()
            torch.set_num_threads(max(1, numba.get_num_threads()))
            take = (lambda a: None if a is None else a[sparse])
            x = photon_cnn.features(maps[sparse], counts[sparse], take(prev), take(prev_counts))
            out[sparse] = photon_cnn.infer(model, x, self.batch)
            self.time_inference += time.perf_counter() - t0
            self.maps_inferred += int(sparse.sum())
        return out

    def describe(self):
        return (f"cnn({self.weights or 'shipped weights'}, max_photons={self.max_photons:g}, "
                f"dense: {self.dense.describe()})")


RECONSTRUCTORS = {"gaussian": Gaussian, "pullpush": PullPush, "none": Reconstructor, "cnn": CNN}


def make_reconstructor(name, **settings):
    if name not in RECONSTRUCTORS:
        raise unknown_name("reconstruction", name, RECONSTRUCTORS)
    try:
        return RECONSTRUCTORS[name](**settings)
    except TypeError as e:
        raise SettingsError(f"reconstruction {name!r}: {e}") from None
