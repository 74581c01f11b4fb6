"""Ray sources: where the paths of a wave start (tracer.integrator.trace_wave's `source`).

A source fills, for the wave's paths g0 .. g0+n-1, the path slots 0 .. n-1 of a WaveBuffers:
the film pixel (or, for probe rays, the caller's row), the random-stream key, the first ray,
a per-path weight, and the reset path state; it returns the wave's PrimarySamples (the sample
seam, tracer.rng.draw). Sources:

    CameraSource()                    the camera: path g is sample sample0 + g // P of film pixel g % P
    CameraSource(shift=(dx, dy))      the same keys and pixel positions, each ray through the
                                      neighbouring pixel (x + dx, y + dy): gradient-domain random replay
    PrimarySampleSource(u, dims, weight)  the camera with external primary samples u for
                                      dimensions dims (rng.pss_dims(m)) and a weight per path
    ProbeSource(origins, directions, keys)  given rays with given keys; pixel = the ray's row

A source's `count(spp)` is the number of paths of a pass of spp samples per pixel; `weighted`
says whether the sink must multiply the weights in, `spread` whether every sample counts toward
every pixel (a warp of the whole image plane).
"""
import numpy as np
from numba import prange

from ._jit import jit, kernel
from .camera import camera_ray
from .film import N_AOV
from .rng import DIM_PIXEL, draw, no_primary_samples, path_key, primary_samples

_CHUNKS = 256  # camera_paths: chunks of a wave, each on one thread


@jit(inline="always")
def _reset(i, beta, L, depth, prev_pdf, prev_delta, aov, aov_open, prev_rec, gain):
    for c in range(3):
        beta[i, c] = 1.0
        L[i, c] = 0.0
    depth[i] = 0
    prev_pdf[i] = 0.0
    prev_delta[i] = False
    prev_rec[i] = -1
    gain[i] = 1.0
    for c in range(N_AOV):
        aov[i, c] = 0.0
    aov_open[i] = True


@kernel
def camera_paths(cam, width, height, crop, jitter, seed, sample0, g0, shift, whole_image, ps, state, index, ray_o, ray_d):
    """Camera rays for global path indices g0 .. g0+n-1 of a pass (sample-major order).

    crop = (x0, y0, w, h): the film covers that window of the width x height image; pix[i] is the
    film pixel, while the random stream is keyed by the image pixel, so a cropped render
    reproduces the same window of the full one exactly. jitter: True for the box filter (the
    position inside the pixel from dimensions DIM_PIXEL, DIM_PIXEL + 1), False for the point
    filter (the pixel centre). shift = (dx, dy): the ray goes through pixel (x + dx, y + dy) at the
    same position inside it, with the key and film pixel of (x, y). whole_image: the two pixel
    dimensions place the sample anywhere in the crop window (its film pixel follows; inside the
    pixel at its centre with the point filter), for a warp of the whole image plane; else inside
    the path's own pixel. index[i] = pix[i]: the sink's index is the film pixel. state: the
    wave.PathState of the wave's first n paths (pix, key and the rest set here).
    """
    pix = state.pix
    key = state.key
    beta = state.beta
    L = state.L
    depth = state.depth
    prev_pdf = state.prev_pdf
    prev_delta = state.prev_delta
    aov = state.aov
    aov_open = state.aov_open
    prev_rec = state.prev_rec
    gain = state.gain
    n = pix.shape[0]
    cw = crop[2]
    npix = crop[2] * crop[3]
    for c in prange(_CHUNKS):
        # the pixel and sample of the chunk's first path by division, then counted on (a division
        # per path cost about as much as the rest of the camera together)
        i0 = c * n // _CHUNKS
        g = g0 + i0
        s = sample0 + g // npix
        p = g % npix
        qx = p % cw
        qy = p // cw
        for i in range(i0, (c + 1) * n // _CHUNKS):
            if i > i0:
                p += 1
                qx += 1
                if qx == cw:
                    qx = 0
                    qy += 1
                if p == npix:
                    p = 0
                    qx = 0
                    qy = 0
                    s += 1
            px = crop[0] + qx
            py = crop[1] + qy
            k = path_key(seed, py * width + px, s)
            jx = draw(ps, k, i, DIM_PIXEL) if jitter or whole_image else 0.5
            jy = draw(ps, k, i, DIM_PIXEL + 1) if jitter or whole_image else 0.5
            f = p
            if whole_image:
                fx = min(jx * cw, cw - 1e-9)
                fy = min(jy * crop[3], crop[3] - 1e-9)
                wx = int(fx)
                wy = int(fy)
                jx = fx - wx if jitter else 0.5
                jy = fy - wy if jitter else 0.5
                f = wy * cw + wx
                px = crop[0] + wx
                py = crop[1] + wy
            pix[i] = f
            index[i] = f
            key[i] = k
            o, d = camera_ray(cam, width, height, px + shift[0], py + shift[1], jx, jy)
            for q in range(3):
                ray_o[i, q] = o[q]
                ray_d[i, q] = d[q]
            _reset(i, beta, L, depth, prev_pdf, prev_delta, aov, aov_open, prev_rec, gain)


@kernel
def probe_paths(origins, directions, keys, g0, state, index, ray_o, ray_d):
    """Paths from given rays g0 .. g0+n-1: index[i] = g0 + i (the row, for the sink), no film pixel
    (pix -1: no per-pixel guide map, no weight window), key and ray as given; state: the
    wave.PathState of the wave's first n paths."""
    pix = state.pix
    key = state.key
    beta = state.beta
    L = state.L
    depth = state.depth
    prev_pdf = state.prev_pdf
    prev_delta = state.prev_delta
    aov = state.aov
    aov_open = state.aov_open
    prev_rec = state.prev_rec
    gain = state.gain
    for i in prange(pix.shape[0]):
        g = g0 + i
        pix[i] = -1
        index[i] = g
        key[i] = keys[g]
        for c in range(3):
            ray_o[i, c] = origins[g, c]
            ray_d[i, c] = directions[g, c]
        _reset(i, beta, L, depth, prev_pdf, prev_delta, aov, aov_open, prev_rec, gain)


class CameraSource:
    """Camera rays through every pixel of the film (see camera_paths); shift=(dx, dy) sends each
    ray through the neighbouring pixel with the base pixel's key and film pixel (at the image's
    border, through a pixel outside the image: the camera extends past it)."""

    weighted = False
    spread = False

    def __init__(self, shift=(0, 0)):
        self.shift = np.asarray(shift, dtype=np.int64)
        if self.shift.shape != (2,):
            raise ValueError(f"shift must be (dx, dy), got {shift!r}")
        self._ps = no_primary_samples()

    def count(self, ctx, spp):
        return spp * ctx.n_pixels

    def _primary(self, g0, n):
        return self._ps

    def start(self, ctx, buf, sample0, g0, n):
        ps = self._primary(g0, n)
        camera_paths(ctx.cam, ctx.scene.width, ctx.scene.height, ctx.crop, ctx.jitter, ctx.seed, sample0, g0,
                     self.shift, self._whole_image(), ps, buf.path_state(n), buf.index[:n], buf.ray_o[:n],
                     buf.ray_d[:n])
        return ps

    def _whole_image(self):
        return False

    def __repr__(self):
        return "CameraSource()" if not self.shift.any() else f"CameraSource(shift={tuple(int(v) for v in self.shift)})"


class PrimarySampleSource(CameraSource):
    """The camera with external primary samples: u (N, D) in [0, 1) supplies dimensions `dims`
    (e.g. rng.pss_dims(m)) of paths 0 .. N-1 of the pass, weight (N,) finite and >= 0 multiplies
    each path's value (e.g. 1 / the warp's density over the supplied dimensions). whole_image: dims
    0 and 1 place the sample anywhere in the film (a warp of the whole image plane), and the film
    estimates each pixel as (P / N) x the sum of weight x value of the samples that landed in it
    (`spread`: every sample counts toward every pixel's sample count); else inside the path's own
    pixel, each pixel the mean of its own samples. A pass renders N paths (count ignores spp)."""

    weighted = True

    def __init__(self, u, dims, weight=None, whole_image=False):
        super().__init__()
        self._all = primary_samples(u, dims)
        n = self._all.u.shape[0]
        self.weight = np.ones(n) if weight is None else np.ascontiguousarray(weight, dtype=np.float64)
        if self.weight.shape != (n,):
            raise ValueError(f"weight must be ({n},), got {self.weight.shape}")
        if not (np.isfinite(self.weight).all() and (self.weight >= 0.0).all()):
            raise ValueError("weight must be finite and >= 0 (a sample drawn where the density is 0 cannot be)")
        self.whole_image = bool(whole_image)
        self.spread = self.whole_image

    def count(self, ctx, spp):
        return self._all.u.shape[0]

    def _primary(self, g0, n):
        return self._all._replace(u=self._all.u[g0:g0 + n])

    def _whole_image(self):
        return self.whole_image

    def start(self, ctx, buf, sample0, g0, n):
        if not ctx.jitter and not self.whole_image and (self._all.col[:2] >= 0).any():
            raise ValueError("the point filter puts every sample at its pixel's centre: supplied pixel dimensions "
                             "would be ignored while their density is in the weights")
        ps = super().start(ctx, buf, sample0, g0, n)
        buf.weight[:n] = self.weight[g0:g0 + n]
        return ps

    def __repr__(self):
        return f"PrimarySampleSource({self._all.u.shape[0]} paths, {self._all.u.shape[1]} dims)"


class ProbeSource:
    """Given rays: origins, directions (N, 3) float64 world (unit directions), keys (N,) uint64 (e.g.
    rng.path_key(seed, i, 0)). Path g starts at ray g; its sample goes to sink index g (use a
    film.SampleSink, or a Film of at least N pixels); it has no film pixel, so per-pixel guide maps
    and the weight window do not apply. The first hit is bounce 0 (what it emits counts in full).
    A pass renders the N rays (count ignores spp)."""

    weighted = False
    spread = False

    def __init__(self, origins, directions, keys):
        self.origins = np.ascontiguousarray(origins, dtype=np.float64)
        self.directions = np.ascontiguousarray(directions, dtype=np.float64)
        self.keys = np.ascontiguousarray(keys, dtype=np.uint64)
        n = self.origins.shape[0]
        if self.origins.shape != (n, 3) or self.directions.shape != (n, 3) or self.keys.shape != (n,):
            raise ValueError(f"origins and directions must be (n, 3) and keys (n,), got {self.origins.shape}, "
                             f"{self.directions.shape}, {self.keys.shape}")
        self._ps = no_primary_samples()

    def count(self, ctx, spp):
        return self.origins.shape[0]

    def start(self, ctx, buf, sample0, g0, n):
        probe_paths(self.origins, self.directions, self.keys, g0, buf.path_state(n), buf.index[:n], buf.ray_o[:n],
                    buf.ray_d[:n])
        return self._ps

    def __repr__(self):
        return f"ProbeSource({self.origins.shape[0]} rays)"
