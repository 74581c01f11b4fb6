"""Mitsuba 3's `sunsky` emitter in RGB: the Hosek-Wilkie sky (2012) and the sun as a disc of
constant radiance, baked into an environment map (tracer.scene.Environment, the tracer's
piecewise-constant convention) that the renderer samples and looks up like any other map.

The model, as Mitsuba 3.9.1 evaluates it (include/mitsuba/render/sunsky.h), in the emitter's local
frame (+z the zenith): for a direction at angle theta from the zenith and gamma from the sun,

    sky = sky_scale * (1 + A exp(B / (cos theta + 0.01)))
          * (C + D exp(E gamma) + F cos^2 gamma + G (1 + cos^2 gamma) / (1 + I^2 - 2 I cos gamma)^1.5
             + H sqrt(cos theta)) * R / 106.75026

per channel, zero below the horizon; A..I and R interpolated linearly in turbidity and ground
albedo, then by a quintic Bezier curve in (2 elevation / pi)^(1/3) of the sun's elevation. The sun
adds sun_scale * E / (2 pi (1 - cos a)) within half-aperture a of its direction, E its RGB
irradiance interpolated in turbidity and elevation. The tables (tracer/data/sunsky_rgb.npz) are
written from Mitsuba's own data by bench.sunsky_tables.

Baking: each texel holds the radiance at its centre, or its mean over the texel from 8 x 8 samples where
the horizon crosses it and 16 x 16 near the sun; the sun's texels are then scaled so that the disc's
solid angle is exact, so the map delivers the model's irradiance (the sun's shape is kept to a texel).
"""
import math
import os
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .errors import SceneError

TABLES = os.path.join(os.path.dirname(__file__), "data", "sunsky_rgb.npz")
CIE_Y_NORMALIZATION = 1.0 / 106.7502593994140625  # Mitsuba 3's MI_CIE_Y_NORMALIZATION (the sky, in RGB)
SUN_APERTURE_DEG = 0.5358  # Mitsuba's default apparent diameter of the sun (degrees)
BEZIER = np.array([1.0, 5.0, 10.0, 10.0, 5.0, 1.0])


@dataclass
class SunSky:
    """A sun and sky: `sun` the unit direction toward the sun's centre and `world_to_local` the
    rotation into the emitter's frame (+z up), both as Mitsuba 3 defines them."""

    sun: np.ndarray  # (3,) unit, in the emitter's local frame
    world_to_local: np.ndarray = field(default_factory=lambda: np.eye(3))
    turbidity: float = 3.0
    albedo: np.ndarray = field(default_factory=lambda: np.full(3, 0.3))
    sky_scale: float = 1.0
    sun_scale: float = 1.0
    sun_half_aperture: float = math.radians(0.5 * SUN_APERTURE_DEG)
    where: str = ""

    @property
    def elevation(self):
        """The sun's elevation above the horizon (radians)."""
        return math.asin(min(max(float(self.sun[2]), -1.0), 1.0))

    def check(self):
        """SceneError naming `where` for a value outside the model's range."""
        if not 1.0 <= self.turbidity <= 10.0:
            raise SceneError(f"{self.where}: sunsky turbidity must lie in [1, 10], got {self.turbidity:g}")
        if not np.all((self.albedo >= 0.0) & (self.albedo <= 1.0)):
            raise SceneError(f"{self.where}: sunsky albedo must lie in [0, 1], got {self.albedo.tolist()}")
        if not (self.sky_scale >= 0.0 and self.sun_scale >= 0.0):
            raise SceneError(f"{self.where}: sunsky sky_scale and sun_scale must be >= 0")
        if not 0.0 < self.sun_half_aperture < 0.5 * math.pi:
            raise SceneError(f"{self.where}: sunsky sun_aperture must lie in (0, 180) degrees, got "
                             f"{math.degrees(2 * self.sun_half_aperture):g}")


@lru_cache(maxsize=1)
def tables():
    """(sky_params (10, 2, 6, 3, 9), sky_rad (10, 2, 6, 3), sun_rgb (10, 30, 3), elevations (30,))."""
    with np.load(TABLES) as d:
        return d["sky_params"], d["sky_rad"], d["sun_rgb"], d["elevations"]


def _lerp_index(x, n):
    """(i, f): x in [0, n - 1] as the pair of grid points i, i + 1 and the weight f of the second."""
    x = min(max(float(x), 0.0), n - 1.0)
    i = min(int(x), n - 2)
    return i, x - i


def sky_coefficients(s):
    """(params (3, 9), rad (3,)) of the sky model for sunsky s (module docstring)."""
    params, rad, _, _ = tables()
    i, f = _lerp_index(s.turbidity - 1.0, params.shape[0])
    a = np.asarray(s.albedo, np.float64)
    out = []
    x = min(math.pow(2.0 / math.pi * max(s.elevation, 0.0), 1.0 / 3.0), 1.0 - 2.0 ** -24)
    bezier = BEZIER * x ** np.arange(6) * (1.0 - x) ** (5 - np.arange(6))
    out = []
    for t, shape in ((params, (3, 1)), (rad, (3,))):
        t = (1.0 - f) * t[i] + f * t[i + 1]  # turbidity: (2 albedos, 6 control points, 3 channels[, 9])
        t = (1.0 - a.reshape(shape)) * t[0] + a.reshape(shape) * t[1]  # albedo, per channel
        out.append(np.tensordot(bezier, t, axes=1))
    return out[0], out[1]


def sun_radiance(s):
    """The sun disc's RGB radiance (Mitsuba 3: its irradiance over the disc's solid angle)."""
    _, _, sun, elev = tables()
    i, f = _lerp_index(s.turbidity - 1.0, sun.shape[0])
    e = (1.0 - f) * sun[i] + f * sun[i + 1]
    j, g = _lerp_index((math.degrees(s.elevation) - elev[0]) / (elev[1] - elev[0]), e.shape[0])
    irradiance = (1.0 - g) * e[j] + g * e[j + 1]
    return s.sun_scale * irradiance / (2.0 * math.pi * (1.0 - math.cos(s.sun_half_aperture)))


def sky_radiance(s, local, coefficients=None):
    """(N, 3) radiance of the sky alone toward unit local directions (N, 3)."""
    p, r = coefficients if coefficients is not None else sky_coefficients(s)
    cos_t = local[:, 2:3]
    cos_g = np.clip(local @ s.sun, -1.0, 1.0)[:, None]
    gamma = np.arccos(cos_g)
    ct = np.maximum(cos_t, 0.0)
    c1 = 1.0 + p[:, 0] * np.exp(p[:, 1] / (ct + 0.01))
    chi = (1.0 + cos_g * cos_g) / (1.0 + p[:, 8] ** 2 - 2.0 * p[:, 8] * cos_g) ** 1.5
    c2 = p[:, 2] + p[:, 3] * np.exp(p[:, 4] * gamma) + p[:, 5] * cos_g * cos_g + p[:, 6] * chi + p[:, 7] * np.sqrt(ct)
    out = (s.sky_scale * CIE_Y_NORMALIZATION) * c1 * c2 * r
    return np.where(cos_t >= 0.0, out, 0.0)


def radiance(s, local):
    """(N, 3) radiance toward unit local directions (N, 3): sky plus sun, as Mitsuba 3 evaluates it."""
    out = sky_radiance(s, local)
    in_sun = (local @ s.sun >= math.cos(s.sun_half_aperture)) & (local[:, 2] >= 0.0)
    return out + np.where(in_sun[:, None], sun_radiance(s), 0.0)


def map_height(s):
    """Rows of the baked map: a texel no taller than a third of the sun's radius, 512 to 2048 rows."""
    need = 3.0 * math.pi / s.sun_half_aperture
    return int(min(max(2 ** math.ceil(math.log2(need)), 512), 2048))


def _texel_dirs(rows, cols, n, h, w):
    """World directions (len(rows), n * n, 3) and their sin(theta) weights of n x n stratified
    samples in texels (rows, cols) of an h x w map in the tracer's convention (tracer.lights.env_dir)."""
    k = (np.arange(n) + 0.5) / n
    shape = (len(rows), n, n)
    v = np.broadcast_to((rows[:, None, None] + k[None, :, None]) / h, shape).reshape(len(rows), -1)
    u = np.broadcast_to((cols[:, None, None] + k[None, None, :]) / w, shape).reshape(len(rows), -1)
    theta, phi = math.pi * v, 2.0 * math.pi * (u - 0.5)
    st = np.sin(theta)
    d = np.stack([st * np.sin(phi), np.cos(theta), -st * np.cos(phi)], axis=-1)
    return d, st


def _mean_over(s, rows, cols, n, h, w, coefficients):
    """(sky mean (m, 3), sun coverage (m,)) of texels (rows, cols), from n x n samples each."""
    d, st = _texel_dirs(rows, cols, n, h, w)
    local = (d.reshape(-1, 3) @ s.world_to_local.T)
    local /= np.linalg.norm(local, axis=1, keepdims=True)
    sky = sky_radiance(s, local, coefficients).reshape(len(rows), n * n, 3)
    in_sun = ((local @ s.sun >= math.cos(s.sun_half_aperture)) & (local[:, 2] >= 0.0)).reshape(len(rows), n * n)
    wsum = np.maximum(st.sum(axis=1), 1e-300)
    return (sky * st[..., None]).sum(axis=1) / wsum[:, None], (in_sun * st).sum(axis=1) / wsum


def bake(s, height=None):
    """(H, 2H, 3) float64 texel means of the radiance in world directions (module docstring), and
    the number of texels whose value was negative in some channel (set to 0). Works a band of 128
    rows at a time: beside the map, it holds a band's directions (at 2048 rows, 12 MB each)."""
    h = int(height or map_height(s))
    w = 2 * h
    coeff = sky_coefficients(s)
    img = np.zeros((h, w, 3))
    cov = np.zeros((h, w))
    cols = np.arange(w)
    theta = math.pi * np.arange(h + 1) / h
    phi = 2.0 * math.pi * (np.arange(w + 1) / w - 0.5)
    up = s.world_to_local[2] / np.linalg.norm(s.world_to_local[2])
    sun_w = s.world_to_local.T @ s.sun
    sun_w /= np.linalg.norm(sun_w)
    reach = s.sun_half_aperture + 2.0 * math.pi / h  # a texel's diagonal is at most pi sqrt(2) / h
    fine = {8: [], 16: []}  # texels the horizon crosses (corners on both sides), texels near the sun
    for y0 in range(0, h, 128):
        y1 = min(y0 + 128, h)
        ys = np.arange(y0, y1)
        rows, cc = np.repeat(ys, w), np.tile(cols, len(ys))
        # the sky: its value at each texel's centre
        sky, c = _mean_over(s, rows, cc, 1, h, w, coeff)
        img[rows, cc], cov[rows, cc] = sky, c
        st = np.sin(theta[y0:y1 + 1])[:, None]
        corners = np.stack([st * np.sin(phi)[None, :],
                            np.broadcast_to(np.cos(theta[y0:y1 + 1])[:, None], (y1 - y0 + 1, w + 1)),
                            -st * np.cos(phi)[None, :]], axis=-1)
        above = corners @ up >= 0.0
        horizon = ((above[:-1, :-1] != above[1:, :-1]) | (above[:-1, :-1] != above[:-1, 1:])
                   | (above[:-1, :-1] != above[1:, 1:]))
        centre, _ = _texel_dirs(rows, cc, 1, h, w)
        near_sun = np.arccos(np.clip(centre.reshape(y1 - y0, w, 3) @ sun_w, -1.0, 1.0)) <= reach
        for mask, n in ((horizon & ~near_sun, 8), (near_sun, 16)):
            yy, xx = np.nonzero(mask)
            fine[n].append((yy + y0, xx))
    # those texels sampled finely, in 4096s
    for n, parts in fine.items():
        ys = np.concatenate([p[0] for p in parts])
        xs = np.concatenate([p[1] for p in parts])
        for k in range(0, len(ys), 4096):
            sky, c = _mean_over(s, ys[k:k + 4096], xs[k:k + 4096], n, h, w, coeff)
            img[ys[k:k + 4096], xs[k:k + 4096]], cov[ys[k:k + 4096], xs[k:k + 4096]] = sky, c
    solid = (2.0 * math.pi / w) * (np.cos(theta[:-1]) - np.cos(theta[1:]))  # per texel of each row
    cone = 2.0 * math.pi * (1.0 - math.cos(s.sun_half_aperture))
    got = float((cov * solid[:, None]).sum())
    if s.elevation > s.sun_half_aperture and got > 0.0:  # the whole disc above the horizon
        cov *= cone / got
    rad = sun_radiance(s)
    for c in range(3):
        img[..., c] += cov * rad[c]
    negative = int(np.count_nonzero((img < 0.0).any(axis=-1)))
    return np.maximum(img, 0.0, out=img), negative


# --- the sun's position from a date, time and place (Blanco-Muriel et al. 2001, as Mitsuba) -------
def sun_angles(year=2010, month=7, day=10, hour=15.0, minute=0.0, second=0.0, latitude=35.6894,
               longitude=139.6917, timezone=9.0):
    """(zenith angle, azimuth) of the sun in radians ("Computing the Solar Vector", Solar Energy
    70(5), 2001, with its parallax correction), as Mitsuba 0.6 and 3 compute it."""
    dec_hours = hour - timezone + (minute + second / 60.0) / 60.0
    a1 = int((month - 14) / 12)
    a2 = (int(1461 * (year + 4800 + a1) / 4) + int(367 * (month - 2 - 12 * a1) / 12)
          - int(3 * int((year + 4900 + a1) / 100) / 4) + day - 32075)
    n = a2 - 0.5 + dec_hours / 24.0 - 2451545.0
    omega = 2.1429 - 0.0010394594 * n
    mean_longitude = 4.8950630 + 0.017202791698 * n
    anomaly = 6.2400600 + 0.0172019699 * n
    ecl_long = (mean_longitude + 0.03341607 * math.sin(anomaly) + 0.00034894 * math.sin(2 * anomaly)
                - 0.0001134 - 0.0000203 * math.sin(omega))
    ecl_obl = 0.4090928 - 6.2140e-9 * n + 0.0000396 * math.cos(omega)
    sl = math.sin(ecl_long)
    ra = math.atan2(math.cos(ecl_obl) * sl, math.cos(ecl_long))
    ra += 2 * math.pi if ra < 0 else 0.0
    decl = math.asin(math.sin(ecl_obl) * sl)
    gmst = 6.6974243242 + 0.0657098283 * n + dec_hours
    lmst = math.radians(gmst * 15 + longitude)
    lat = math.radians(latitude)
    hour_angle = lmst - ra
    zenith = math.acos(math.cos(lat) * math.cos(hour_angle) * math.cos(decl) + math.sin(decl) * math.sin(lat))
    azimuth = math.atan2(-math.sin(hour_angle), math.tan(decl) * math.cos(lat) - math.sin(lat) * math.cos(hour_angle))
    azimuth += 2 * math.pi if azimuth < 0 else 0.0
    zenith += (6371.01 / 149597890.0) * math.sin(zenith)
    return zenith, azimuth
