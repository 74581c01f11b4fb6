"""The film: per-pixel sums in float64, from which the mean and its variance follow.

With the box filter each sample lands in its own pixel. The film keeps, per pixel,
the sample count n, the sum and the sum of squares of the radiance samples (RGB), and
sums of the AOVs (albedo at the first vertex that is not a delta BSDF; normal facing the camera and
depth at the first hit). Samples are added in
sample-index order, so the float64 sums, and the image, do not depend on wave size or
thread count.
"""
import math

import numba
import numpy as np
from numba import prange

from ._jit import kernel

AOV_NAMES = ("albedo.R", "albedo.G", "albedo.B", "N.X", "N.Y", "N.Z", "Z")
N_AOV = len(AOV_NAMES)


class Film:
    """Accumulates radiance samples and AOVs for a width x height image (without AOVs if `aovs` is
    False: films whose AOVs nobody reads, e.g. a gradient film, save 56 of their 112 bytes a pixel)."""

    def __init__(self, width, height, aovs=True):
        self.width = int(width)
        self.height = int(height)
        n = self.width * self.height
        self.count = np.zeros(n, dtype=np.float64)  # samples per pixel
        self.sum = np.zeros((n, 3), dtype=np.float64)
        self.sumsq = np.zeros((n, 3), dtype=np.float64)
        self.aov = np.zeros((n, N_AOV if aovs else 0), dtype=np.float64)

    @staticmethod
    def bytes_per_pixel(aovs=True):
        """The film's memory per pixel: count, sum, sum of squares and (if aovs) the AOV sums."""
        return 8 * (1 + 3 + 3 + (N_AOV if aovs else 0))

    @property
    def n_pixels(self):
        return self.width * self.height

    def add(self, pixel, radiance, aov, weight=None, spread=False):
        """Add samples, in order: pixel (n,) int64, radiance (n,3) float64, aov (n, N_AOV) float64,
        weight (n,) float64 or None (1): each sample's value is weight x radiance. The sink
        interface of tracer.integrator.trace_wave. spread: the samples were placed over the whole
        image (sources.PrimarySampleSource, whole_image): each counts toward every pixel's sample
        count, and adds P x its value (and AOVs) to the pixel it landed in, so that a pixel's mean
        is (P / N) x the sum of the values that landed there. A pixel outside the film is an error."""
        if spread:
            w = np.ones(pixel.shape[0]) if weight is None else weight
            _accumulate_weighted(self.count, self.sum, self.sumsq, self.aov, pixel, radiance, aov,
                                 w * float(self.n_pixels), float(self.n_pixels), 0.0)
            self.count += pixel.shape[0]
        elif weight is None:
            _accumulate(self.count, self.sum, self.sumsq, self.aov, pixel, radiance, aov)
        else:
            _accumulate_weighted(self.count, self.sum, self.sumsq, self.aov, pixel, radiance, aov, weight, 1.0, 1.0)

    def mean(self):
        """(H, W, 3) float64 per-pixel mean (0 where no sample yet)."""
        n = np.maximum(self.count, 1.0)[:, None]
        return (self.sum / n).reshape(self.height, self.width, 3)

    def variance(self):
        """(H, W, 3) float64 variance of the per-pixel mean (sample variance / n), computed in place
        in two (N, 3) arrays."""
        n = self.count[:, None]
        safe = np.maximum(n, 2.0)
        m = self.sum / np.maximum(n, 1.0)
        var = n * m
        var *= m
        np.subtract(self.sumsq, var, out=var)
        del m
        np.maximum(var, 0.0, out=var)
        var /= safe - 1.0
        var /= safe
        var[self.count < 2.0] = 0.0
        return var.reshape(self.height, self.width, 3)

    def aovs(self):
        """{name: (H, W, k) float32}: albedo, normal, depth (means over samples)."""
        return aovs_of([self])

    def __repr__(self):
        return f"Film({self.width}x{self.height}, {int(self.count.sum())} samples)"


def aovs_of(films):
    """{name: (H, W, k) float32}: albedo, normal, depth, the means over the samples of every film
    (all of one size, with AOVs)."""
    f0 = films[0]
    count, aov = f0.count, f0.aov
    if len(films) > 1:
        count, aov = np.zeros_like(count), np.zeros_like(aov)
        for f in films:
            count += f.count
            aov += f.aov
    n = np.maximum(count, 1.0)[:, None]
    a = (aov / n).reshape(f0.height, f0.width, N_AOV).astype(np.float32)
    return {"albedo": a[:, :, 0:3], "normal": a[:, :, 3:6], "depth": a[:, :, 6:7]}


def combine_films(films, kinds=None):
    """One image from independent renders of the same pixels, weighted by the inverse of each
    film's mean pixel variance (Mueller 2019), with the weights of a pixel taken from the other
    half of the pixels: pixels split as a checkerboard, the films of a white pixel are weighted by
    their mean variance over the black pixels and the other way round. A pixel's own samples then
    never enter its weights; weights from a film's own variance favour the films whose samples
    happened to fall low (a high sample raises a film's mean and its variance together), which
    darkened guided renders 3% (NEE on) and 20-66% (NEE off) on `ajar` (docs/findings.md).
    Films with fewer than 2 spp in some pixel are left out unless nothing else has samples; films of
    kind "discard" never count (e.g. ODIS's initial pass, rendered at another depth), "pilot" films
    only when nothing else is usable. Returns (image (H,W,3), variance of it, weights: per film,
    the mean of its two halves' weights)."""
    kinds = kinds or ["final"] * len(films)
    keep = [i for i, k in enumerate(kinds) if k != "discard"]
    if len(keep) < len(films):
        if not keep:
            raise ValueError("combine_films: every film is of kind discard")
        image, variance, w = combine_films([films[i] for i in keep], [kinds[i] for i in keep])
        weights = [0.0] * len(films)
        for j, i in enumerate(keep):
            weights[i] = w[j]
        return image, variance, weights
    usable = [f.count.size and f.count.min() >= 2 for f in films]
    if not any(usable):  # e.g. a 1-spp render: the films are summed sample by sample
        total = Film(films[0].width, films[0].height)
        for f in films:
            total.count += f.count
            total.sum += f.sum
            total.sumsq += f.sumsq
        return total.mean(), total.variance(), [1.0 if f.count.max() > 0 else 0.0 for f in films]
    used = [f for f, ok, kind in zip(films, usable, kinds) if ok and not (kind == "pilot" and sum(usable) > 1)]
    if len(used) == 1:
        f = used[0]
        return f.mean(), f.variance(), [1.0 if g is f else 0.0 for g in films]
    h, w = used[0].height, used[0].width
    white = (np.add.outer(np.arange(h), np.arange(w)) % 2).astype(bool)
    halves = (white, ~white) if white.any() and (~white).any() else (white | True, white | True)
    # mv[k, q]: film k's mean pixel variance over half q; the pixels of half q take 1 / mv[k, 1 - q]
    mv = np.empty((len(used), 2))
    for k, f in enumerate(used):  # one film's variance at a time (memory), computed again below
        v = f.variance()
        mv[k] = [v[halves[0]].mean(), v[halves[1]].mean()]
    wq = np.empty((len(used), 2))
    for q in range(2):
        other = mv[:, 1 - q]
        if np.all(other > 0):
            wq[:, q] = 1.0 / other
        else:  # noiseless films (a black image): by samples instead
            wq[:, q] = [float(f.count.sum()) for f in used]
        wq[:, q] /= wq[:, q].sum()
    shape = (h, w, 3)
    image, variance = np.zeros(shape), np.zeros(shape)
    for k, f in enumerate(used):
        wmap = np.where(halves[0], wq[k, 0], wq[k, 1])[:, :, None]
        image += wmap * f.mean()
        variance += wmap * wmap * f.variance()
    mean_w = {id(f): float(wq[k].mean()) for k, f in enumerate(used)}
    return image, variance, [mean_w.get(id(f), 0.0) for f in films]


def _check_pixels(pixel, n):
    if pixel.shape[0] and (pixel.min() < 0 or pixel.max() >= n):
        raise IndexError("a sample's pixel is outside the film")


def _accumulate(count, s, sq, aov, pixel, radiance, aovs):
    _check_pixels(pixel, count.shape[0])
    _accumulate_parts(count, s, sq, aov, pixel, radiance, aovs, np.empty(0), 1.0, 1.0, numba.get_num_threads())


def _accumulate_weighted(count, s, sq, aov, pixel, radiance, aovs, weight, aov_scale, count_add):
    """_accumulate with value weight x radiance, AOVs x aov_scale, and count_add per sample."""
    _check_pixels(pixel, count.shape[0])
    _accumulate_parts(count, s, sq, aov, pixel, radiance, aovs, weight, aov_scale, count_add,
                      numba.get_num_threads())


@kernel
def _accumulate_parts(count, s, sq, aov, pixel, radiance, aovs, weight, aov_scale, count_add, parts):
    """Add samples (value weight x radiance, 1 x radiance where weight is empty) into their pixels.
    The pixels are split into `parts` ranges, one per thread; each thread scans every sample and
    adds those of its range, so each pixel receives its samples in sample order (the sums are
    those of a sequential loop, bit for bit, whatever the thread count)."""
    npix = count.shape[0]
    weighted = weight.shape[0] == pixel.shape[0]
    for part in prange(parts):
        lo = part * npix // parts
        hi = (part + 1) * npix // parts
        for i in range(pixel.shape[0]):
            p = pixel[i]
            if p < lo or p >= hi:
                continue
            count[p] += count_add
            for c in range(3):
                r = weight[i] * radiance[i, c] if weighted else radiance[i, c]
                s[p, c] += r
                sq[p, c] += r * r
            for c in range(aov.shape[1]):
                aov[p, c] += aov_scale * aovs[i, c]


class SampleSink:
    """A sink that keeps the samples instead of accumulating them: after a render of a source,
    `samples()` gives (index (n,) int64, weight (n,) float64, radiance (n,3) float64, aov (n, N_AOV)
    float64) in the order they were traced. The index is the source's sink index (the film pixel
    for camera sources, the ray's row for ProbeSource); the weights are not multiplied in."""

    def __init__(self):
        self._parts = []

    def add(self, pixel, radiance, aov, weight=None, spread=False):
        w = np.ones(pixel.shape[0]) if weight is None else np.array(weight, dtype=np.float64)
        self._parts.append((np.array(pixel), w, np.array(radiance), np.array(aov)))

    def samples(self):
        if not self._parts:
            return np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3)), np.zeros((0, N_AOV))
        return tuple(np.concatenate([p[j] for p in self._parts]) for j in range(4))

    def __repr__(self):
        return f"SampleSink({sum(p[0].shape[0] for p in self._parts)} samples)"
