"""The ODIS network's input: initial samples gathered around a pixel and binned into its map
(Bako et al. 2019, sections 3.3 and 4.1).

An initial sample is one first-bounce direction of a camera path with what came back along it and
the two hits' features (`initial_samples` takes them from a wave's records). For a map centred at film pixel c, every sample of the k x k pixels around
c (clipped to the film) goes to the bin of its world-space direction on the full sphere
(tracer.guiding.directional: n_theta rows uniform in z, n_phi columns uniform in phi, so every bin
covers the same solid angle), without warping for the change of position. Each bin holds the mean
of its samples' 9 channels:

    0        incident radiance (the guide's records give luminance; RGB input is averaged)
    1        depth of the first hit (camera to hit)
    2, 3, 4  shading normal at the first hit
    5        depth of the second hit (first hit to second; 0 where the direction escaped)
    6, 7, 8  shading normal at the second hit (0 where it escaped)

and two masks: `sampled` (the bin received a sample) and `valid` (some corner or the centre of
the bin lies above the surface whose normal is the mean of c's own first-hit normals; all 0 when c
has no sample, so that pixel takes BSDF sampling alone).
"""
import numpy as np
from numba import prange

from ..._jit import jit, kernel
from ..directional import bin_direction, direction_bin

N_CHANNELS = 9


_CORNERS = ((0.0, 0.0), (0.0, 1.0), (1.0, 0.0), (1.0, 1.0), (0.5, 0.5))


@jit
def _bin_points(n_theta, n_phi, out):
    for b in range(n_theta * n_phi):
        for j in range(5):
            d = bin_direction(b, n_theta, n_phi, _CORNERS[j][0], _CORNERS[j][1])
            out[b, j, 0] = d[0]
            out[b, j, 1] = d[1]
            out[b, j, 2] = d[2]


def bin_points(n_theta=32, n_phi=32):
    """(K, 5, 3) directions of each bin's four corners and centre (directional.bin_direction, so
    1e-9 of a bin inside it): the points that decide whether a bin lies above a surface."""
    out = np.empty((n_theta * n_phi, 5, 3))
    _bin_points(n_theta, n_phi, out)
    return out


def first_sample(pix, n_pixels):
    """(n_pixels,) index of each pixel's first sample in pix (-1 where it has none)."""
    first = np.full(n_pixels, -1, np.int64)
    first[pix[::-1]] = np.arange(pix.shape[0])[::-1]
    return first


def pixel_order(pix, n_pixels):
    """(order, start): samples sorted by pixel (stable), and start (n_pixels + 1,) with the samples
    of pixel p at order[start[p]:start[p + 1]]."""
    pix = np.asarray(pix, dtype=np.int64)
    order = np.argsort(pix, kind="stable")
    start = np.zeros(n_pixels + 1, np.int64)
    np.cumsum(np.bincount(pix, minlength=n_pixels), out=start[1:])
    return order, start


@kernel
def _gather(order, start, dirs, chans, width, height, centres, k, n_theta, n_phi, points, feats, sampled, valid):
    n_bins = n_theta * n_phi
    r = k // 2
    for m in prange(centres.shape[0]):
        c = centres[m]
        cx = c % width
        cy = c // width
        sums = np.zeros((N_CHANNELS, n_bins))
        count = np.zeros(n_bins)
        for y in range(max(cy - r, 0), min(cy + r + 1, height)):
            for x in range(max(cx - r, 0), min(cx + r + 1, width)):
                p = y * width + x
                for j in range(start[p], start[p + 1]):
                    s = order[j]
                    b = direction_bin((dirs[s, 0], dirs[s, 1], dirs[s, 2]), n_theta, n_phi)
                    count[b] += 1.0
                    for ch in range(N_CHANNELS):
                        sums[ch, b] += chans[s, ch]
        for b in range(n_bins):
            if count[b] > 0.0:
                sampled[m, b] = 1
                for ch in range(N_CHANNELS):
                    feats[m, ch, b] = sums[ch, b] / count[b]
        nx = 0.0
        ny = 0.0
        nz = 0.0
        for j in range(start[c], start[c + 1]):
            s = order[j]
            nx += chans[s, 2]
            ny += chans[s, 3]
            nz += chans[s, 4]
        if start[c + 1] > start[c] and nx * nx + ny * ny + nz * nz > 0.0:
            for b in range(n_bins):
                above = False
                for j in range(5):
                    if points[b, j, 0] * nx + points[b, j, 1] * ny + points[b, j, 2] * nz > 0.0:
                        above = True
                valid[m, b] = 1 if above else 0


_POINTS = {}


def _points(n_theta, n_phi):
    if (n_theta, n_phi) not in _POINTS:
        _POINTS[(n_theta, n_phi)] = bin_points(n_theta, n_phi)
    return _POINTS[(n_theta, n_phi)]


def gather(pix, dirs, radiance, depth1, normal1, depth2, normal2, width, height, centres, k=11, n_theta=32,
           n_phi=32):
    """Bin the initial samples around each centre pixel (see the module docstring).

    pix (n,) film pixel of each sample; dirs (n, 3) unit world direction of the first bounce;
    radiance (n, 3) or (n,); depth1, depth2 (n,); normal1, normal2 (n, 3); centres (m,) film
    pixels; k odd window size. Returns (features (m, 9, n_theta, n_phi) float32, sampled and valid
    (m, n_theta, n_phi) uint8)."""
    if k < 1 or k % 2 == 0:
        raise ValueError(f"k must be odd and >= 1, got {k}")
    n = np.asarray(pix).shape[0]
    rad = np.asarray(radiance, dtype=np.float64)
    rad = rad.mean(axis=1) if rad.ndim == 2 else rad
    chans = np.empty((n, N_CHANNELS))
    chans[:, 0] = rad
    chans[:, 1] = depth1
    chans[:, 2:5] = normal1
    chans[:, 5] = depth2
    chans[:, 6:9] = normal2
    order, start = pixel_order(pix, width * height)
    centres = np.asarray(centres, dtype=np.int64)
    m = centres.shape[0]
    feats = np.zeros((m, N_CHANNELS, n_theta * n_phi), np.float32)
    sampled = np.zeros((m, n_theta * n_phi), np.uint8)
    valid = np.zeros((m, n_theta * n_phi), np.uint8)
    _gather(order, start, np.ascontiguousarray(dirs, dtype=np.float64), chans, int(width), int(height), centres,
            int(k), int(n_theta), int(n_phi), _points(n_theta, n_phi), feats, sampled, valid)
    shape = (m, n_theta, n_phi)
    return feats.reshape(m, N_CHANNELS, n_theta, n_phi), sampled.reshape(shape), valid.reshape(shape)


def initial_samples(records, n, origin):
    """The initial samples of one wave of n camera paths, from its records (traced with observe, no
    splitting): {pix, x, dirs, radiance, depth1, normal1, depth2, normal2} for the paths whose first hit
    sampled a direction (not a delta BSDF, not an emitter that ended the path); x is the first hit.

    Records [0, n) are the wave's first hits (integrator.trace_wave: bounce 0 reserves one entry per
    path); a first hit's second vertex is the record whose `prev` is it. depth1 is the distance from
    `origin` (the camera's position), depth2 the distance between the two hits (0 with normal2 0
    where the direction escaped or ended on a delta BSDF). radiance is the luminance that came back
    along the direction (with the render's max_depth 3: the second hit's emission and its direct
    light, i.e. direct plus one-bounce indirect seen from the first hit). The arrays are copies: the
    records are the wave buffer's and the next wave overwrites them."""
    first = records.strategy[:n] >= 0
    nxt = np.full(n, -1, np.int64)
    later = np.arange(n, records.strategy.shape[0])
    pv = records.prev[n:]
    link = (pv >= 0) & (pv < n) & (records.strategy[n:] >= 0)
    nxt[pv[link]] = later[link]
    idx = np.nonzero(first)[0]
    x0 = records.x[idx].astype(np.float64)
    j = nxt[idx]
    has2 = j >= 0
    x1 = np.where(has2[:, None], records.x[np.maximum(j, 0)].astype(np.float64), x0)
    n1 = np.where(has2[:, None], records.n[np.maximum(j, 0)].astype(np.float64), 0.0)
    return {"pix": records.pixel[idx].copy(), "x": x0, "dirs": records.wi[idx].astype(np.float64),
            "radiance": records.radiance[idx].astype(np.float64),
            "depth1": np.linalg.norm(x0 - np.asarray(origin, dtype=np.float64), axis=1),
            "normal1": records.n[idx].astype(np.float64), "depth2": np.linalg.norm(x1 - x0, axis=1), "normal2": n1}
