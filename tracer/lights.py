"""Light sources for next-event estimation: emissive triangles and the environment.

Triangles are chosen in proportion to their power (luminance of Ke x area x pi), then a
point is drawn uniformly by area. The environment is one more light, chosen with a
probability in proportion to its power through the scene's bounding sphere; a constant
environment is sampled uniformly over the sphere, a map by luminance x sin(theta) (2D CDF).

Maps come in the two conventions of tracer.scene.Environment. ENV_MAP (the tracer's, OBJ
sidecars): radiance constant over each texel, sampled texel by texel. ENV_BILINEAR (Mitsuba 3's
`envmap`, from Mitsuba XML): the direction is turned into the map's frame (env_rot), the radiance
interpolated bilinearly between texel centres (columns periodic, rows from pole to pole), and
directions are sampled over the (H - 1) x W cells between those centres, each cell in proportion
to the mean luminance of its four corners x sin(theta) at its middle, uniformly in (u, v) within it.

Delta lights (tracer.scene.DeltaLight: point, spot, directional) join the triangles in the same
power-proportional choice, after them: entry li >= L of `func`/`cdf` is delta light li - L. They are
reached by next-event estimation alone; their "pdf" is the probability of choosing them, and
sample_light says which kind of light a sample came from by its last value (<= -2,
delta_light_of) so that callers give it MIS weight 1.

Emission is one-sided: a triangle emits from the side of its counter-clockwise normal.
All pdfs returned here are per unit solid angle at the receiving point, but for delta lights.

The kernels take the `Lights` tuple whole; its functions are inlined at the Numba level
(`inline="always"`), because a call that is not inlined copies the tuple of arrays by value
(measured: half of the shading kernel's time).
"""
import math
from typing import NamedTuple

import numpy as np

from ._jit import jit
from .sampling import (
    INV_4PI,
    build_distribution_1d,
    build_distribution_2d,
    distribution_2d_pdf,
    sample_distribution_1d,
    sample_distribution_2d,
    sample_uniform_sphere,
    sample_uniform_triangle,
)

ENV_NONE = 0
ENV_CONSTANT = 1
ENV_MAP = 2
ENV_BILINEAR = 3

DELTA_POINT = 1
DELTA_SPOT = 2
DELTA_DIRECTIONAL = 3
DELTA_KINDS = {"point": DELTA_POINT, "spot": DELTA_SPOT, "directional": DELTA_DIRECTIONAL}

# sample_light's last value when the light is not a triangle: LIGHT_ENV for the environment,
# LIGHT_ENV - 1 - j (<= -2) for delta light j (delta_light_of)
LIGHT_ENV = -1


class Lights(NamedTuple):
    """Arrays the kernels read. L emissive triangles, F triangles in all."""

    tri: np.ndarray  # (L,) int64 triangle index of each emissive triangle
    func: np.ndarray  # (L,) float64 selection weights (power)
    cdf: np.ndarray  # (L+1,) float64
    area: np.ndarray  # (L,) float64
    normal: np.ndarray  # (L, 3) float64 unit CCW normal
    radiance: np.ndarray  # (L, 3) float64 emitted radiance
    light_of_tri: np.ndarray  # (F,) int64: emissive index of a triangle, -1 if it does not emit
    p_env: float  # probability of choosing the environment
    env_type: int  # ENV_NONE, ENV_CONSTANT, ENV_MAP, ENV_BILINEAR
    env_const: np.ndarray  # (3,) constant radiance
    env_map: np.ndarray  # (H, W, 3) radiance, (1,1,3) zeros if no map
    env_rot: np.ndarray  # (3, 3) world -> map frame (ENV_BILINEAR; identity otherwise)
    env_cond_func: np.ndarray  # 2D distribution tables over the map's texels (ENV_MAP) or cells
    env_cond_cdf: np.ndarray
    env_marg_func: np.ndarray
    env_marg_cdf: np.ndarray
    delta_kind: np.ndarray  # (K,) int64 DELTA_POINT, DELTA_SPOT, DELTA_DIRECTIONAL
    delta_pos: np.ndarray  # (K, 3) position (point, spot)
    delta_dir: np.ndarray  # (K, 3) unit: the spot's axis, the directional light's direction of travel
    delta_value: np.ndarray  # (K, 3) intensity (point, spot) or irradiance (directional)
    delta_cone: np.ndarray  # (K, 4) spot: cos(cutoff), cutoff, cos(beam), 1 / (cutoff - beam) (radians)
    delta_frame: np.ndarray  # (K, 3, 3) spot: rows its local x, y, z axes (a projected texture's frame)
    delta_tex: np.ndarray  # (K, H, W, 3) spot: its projected texture, padded to the largest
    delta_tex_size: np.ndarray  # (K, 2) int64 (H, W) of each texture; (0, 0): none


def luminance(rgb):
    rgb = np.asarray(rgb)
    return 0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2]


def build_lights(scene):
    """Light tables for `scene` (a tracer.scene.Scene)."""
    tri = scene.tri
    emission = scene.materials.emission[scene.tri_material]
    emissive = np.flatnonzero(np.any(emission > 0.0, axis=1))
    cr = np.cross(tri[emissive, 1] - tri[emissive, 0], tri[emissive, 2] - tri[emissive, 0])
    area2 = np.linalg.norm(cr, axis=1)
    area = 0.5 * area2
    normal = cr / np.maximum(area2, 1e-300)[:, None]
    radiance = emission[emissive]
    power = luminance(radiance) * area * math.pi
    tri_power = float(power.sum())
    light_of_tri = np.full(tri.shape[0], -1, dtype=np.int64)
    light_of_tri[emissive] = np.arange(emissive.size)

    env = scene.environment
    env_type, env_power = ENV_NONE, 0.0
    env_const = np.zeros(3)
    env_map = np.zeros((1, 1, 3))
    env_rot = np.eye(3)
    tables = build_distribution_2d(np.ones((1, 1)))
    radius = 0.5 * float(np.linalg.norm(scene.bounds[1] - scene.bounds[0]))
    if env is not None and env.image is not None and env.convention == "mitsuba":
        env_type, env_map = ENV_BILINEAR, np.ascontiguousarray(env.image, dtype=np.float64)
        if env.to_world is not None:  # a rotation: its inverse is its transpose
            env_rot = np.ascontiguousarray(np.asarray(env.to_world, dtype=np.float64).T)
        cells = bilinear_cells(env_map)
        tables = build_distribution_2d(cells)
        h = env_map.shape[0]
        sin_mid = np.sin(np.pi * (np.arange(h - 1) + 0.5) / (h - 1))
        mean_rad = float(cells.sum() / max(sin_mid.sum() * env_map.shape[1], 1e-300))
        env_power = math.pi * radius * radius * math.pi * mean_rad
    elif env is not None and env.image is not None:
        env_type, env_map = ENV_MAP, np.ascontiguousarray(env.image, dtype=np.float64)
        h, w = env_map.shape[:2]
        sin_theta = np.sin(np.pi * (np.arange(h) + 0.5) / h)
        tables = build_distribution_2d(luminance(env_map) * sin_theta[:, None])
        mean_rad = float((luminance(env_map) * sin_theta[:, None]).sum() / max(sin_theta.sum() * w, 1e-300))
        env_power = math.pi * radius * radius * math.pi * mean_rad
    elif env is not None and env.radiance.max() > 0.0:
        env_type, env_const = ENV_CONSTANT, env.radiance.astype(np.float64)
        env_power = math.pi * radius * radius * math.pi * float(luminance(env_const))

    delta = delta_tables(scene.delta_lights)
    d_power = delta_power(delta, radius)
    fin_power = np.concatenate([power, d_power])
    if fin_power.size == 0:
        func, cdf = np.ones(1), np.array([0.0, 1.0])
        p_env = 1.0
    else:
        total = float(fin_power.sum())
        func, cdf = build_distribution_1d(fin_power if total > 0 else np.ones_like(fin_power))
        p_env = env_power / (env_power + total) if env_type != ENV_NONE else 0.0
        if env_type != ENV_NONE:
            p_env = min(max(p_env, 0.05), 0.95)  # neither strategy is ever starved
    return Lights(
        emissive.astype(np.int64),
        func,
        cdf,
        area if emissive.size else np.ones(1),
        normal if emissive.size else np.zeros((1, 3)),
        radiance if emissive.size else np.zeros((1, 3)),
        light_of_tri,
        float(p_env),
        int(env_type),
        env_const,
        env_map,
        env_rot,
        *tables,
        *delta,
    )


def delta_tables(delta_lights):
    """(kind, pos, dir, value, cone, frame, tex, tex_size) arrays of Lights for a list of
    tracer.scene.DeltaLight."""
    k = len(delta_lights)
    kind = np.array([DELTA_KINDS[d.kind] for d in delta_lights], dtype=np.int64)
    pos = np.array([d.position for d in delta_lights], dtype=np.float64).reshape(k, 3)
    axis = np.array([d.direction for d in delta_lights], dtype=np.float64).reshape(k, 3)
    axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-300)
    value = np.array([d.intensity for d in delta_lights], dtype=np.float64).reshape(k, 3)
    cone = np.zeros((k, 4))
    for i, d in enumerate(delta_lights):
        width = d.cutoff - d.beam
        cone[i] = math.cos(d.cutoff), d.cutoff, math.cos(d.beam), 1.0 / width if width > 0 else 1e300
    frame = np.array([np.asarray(d.frame, np.float64) for d in delta_lights]).reshape(k, 3, 3)
    texs = [d.texture if d.kind == "spot" and d.texture is not None else None for d in delta_lights]
    size = np.array([t.shape[:2] if t is not None else (0, 0) for t in texs], dtype=np.int64).reshape(k, 2)
    tex = np.zeros((k, max(1, int(size[:, 0].max(initial=0))), max(1, int(size[:, 1].max(initial=0))), 3))
    for i, t in enumerate(texs):
        if t is not None:
            tex[i, :t.shape[0], :t.shape[1]] = t
    return kind, pos, axis, value, cone, frame, tex, size


def delta_power(delta, radius):
    """(K,) luminance power of each delta light: 4 pi I a point, I times the spot's falloff integrated
    over the sphere (2 pi (1 - (sin c - sin b) / (c - b)) for cutoff c, beam b; times its projected
    texture's mean, an estimate: the power only weighs the choice of light), E pi R^2 a
    directional light through the scene's bounding sphere of radius R."""
    kind, _, _, value, cone, _, tex, size = delta
    lum = luminance(value)
    for i in range(kind.shape[0]):  # a projected texture: its mean (the cone's uv disc, roughly)
        if size[i, 0] > 0:
            lum[i] *= float(luminance(tex[i, :size[i, 0], :size[i, 1]]).mean())
    out = np.zeros(kind.shape[0])
    for i in range(kind.shape[0]):
        if kind[i] == DELTA_POINT:
            out[i] = 4.0 * math.pi * lum[i]
        elif kind[i] == DELTA_SPOT:
            c, b = cone[i, 1], math.acos(min(max(cone[i, 2], -1.0), 1.0))
            solid = 1.0 - math.cos(c) if c - b <= 1e-9 else 1.0 - (math.sin(c) - math.sin(b)) / (c - b)
            out[i] = 2.0 * math.pi * solid * lum[i]
        else:
            out[i] = math.pi * radius * radius * lum[i]
    return out


@jit(inline="always")
def spot_falloff(lt, j, d):
    """Spot light j's falloff (Mitsuba 3's, linear in angle) toward the unit world direction d it
    shines along: 1 within the beam, 0 past the cutoff."""
    c = d[0] * lt.delta_dir[j, 0] + d[1] * lt.delta_dir[j, 1] + d[2] * lt.delta_dir[j, 2]
    if not c > lt.delta_cone[j, 0]:
        return 0.0
    if c >= lt.delta_cone[j, 2]:
        return 1.0
    return (lt.delta_cone[j, 1] - math.acos(min(c, 1.0))) * lt.delta_cone[j, 3]


@jit(inline="always")
def spot_value(lt, j, d):
    """Spot light j's falloff times its projected texture (RGB) toward the unit world direction d it
    shines along (Mitsuba 3's: uv = 1/2 + (x, y) / (2 z tan(cutoff)) in the spot's frame, bilinear
    between texel centres, repeated, v = 0 the image's top row)."""
    f = spot_falloff(lt, j, d)
    h, w = lt.delta_tex_size[j, 0], lt.delta_tex_size[j, 1]
    if h == 0 or f == 0.0:
        return f, f, f
    fr = lt.delta_frame[j]
    lx = d[0] * fr[0, 0] + d[1] * fr[0, 1] + d[2] * fr[0, 2]
    ly = d[0] * fr[1, 0] + d[1] * fr[1, 1] + d[2] * fr[1, 2]
    lz = d[0] * fr[2, 0] + d[1] * fr[2, 1] + d[2] * fr[2, 2]
    if not lz > 0.0:  # (a cutoff of 90 degrees or more: the projection does not reach behind the spot)
        return 0.0, 0.0, 0.0
    k = 0.5 / (lz * math.tan(lt.delta_cone[j, 1]))
    x = (0.5 + lx * k) * w - 0.5
    y = (0.5 + ly * k) * h - 0.5
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    ix0, iy0 = int(x0) % w, int(y0) % h
    ix1, iy1 = (ix0 + 1) % w, (iy0 + 1) % h
    t = lt.delta_tex[j]
    w00, w01, w10, w11 = f * (1.0 - fy) * (1.0 - fx), f * (1.0 - fy) * fx, f * fy * (1.0 - fx), f * fy * fx
    return (w00 * t[iy0, ix0, 0] + w01 * t[iy0, ix1, 0] + w10 * t[iy1, ix0, 0] + w11 * t[iy1, ix1, 0],
            w00 * t[iy0, ix0, 1] + w01 * t[iy0, ix1, 1] + w10 * t[iy1, ix0, 1] + w11 * t[iy1, ix1, 1],
            w00 * t[iy0, ix0, 2] + w01 * t[iy0, ix1, 2] + w10 * t[iy1, ix0, 2] + w11 * t[iy1, ix1, 2])


@jit(inline="always")
def delta_light_of(t):
    """The delta light a sample_light result t <= -2 came from (-1 for any other light)."""
    return LIGHT_ENV - 1 - t if t < LIGHT_ENV else -1


@jit(inline="always")
def delta_arrival(lt, j, y):
    """(unit world direction from y toward delta light j, distance (inf: directional), value arriving
    at y (RGB): I falloff / d^2 or E)."""
    if lt.delta_kind[j] == DELTA_DIRECTIONAL:
        return ((-lt.delta_dir[j, 0], -lt.delta_dir[j, 1], -lt.delta_dir[j, 2]), np.inf,
                (lt.delta_value[j, 0], lt.delta_value[j, 1], lt.delta_value[j, 2]))
    dx, dy, dz = lt.delta_pos[j, 0] - y[0], lt.delta_pos[j, 1] - y[1], lt.delta_pos[j, 2] - y[2]
    d2 = dx * dx + dy * dy + dz * dz
    if not d2 > 0.0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0)
    dist = math.sqrt(d2)
    wi = (dx / dist, dy / dist, dz / dist)
    s = 1.0 / d2
    if lt.delta_kind[j] == DELTA_SPOT:
        f = spot_value(lt, j, (-wi[0], -wi[1], -wi[2]))
        return wi, dist, (lt.delta_value[j, 0] * s * f[0], lt.delta_value[j, 1] * s * f[1],
                          lt.delta_value[j, 2] * s * f[2])
    return wi, dist, (lt.delta_value[j, 0] * s, lt.delta_value[j, 1] * s, lt.delta_value[j, 2] * s)


def bilinear_cells(env_map):
    """(H - 1, W) sampling weights of an ENV_BILINEAR map (H, W, 3): the cell between rows y, y + 1
    and columns x, x + 1 (mod W) weighs the mean luminance of its four corners times sin(theta) at
    its middle; positive wherever the bilinear radiance is."""
    lum = luminance(env_map)
    h = lum.shape[0]
    corners = lum[:-1] + lum[1:]
    cells = 0.25 * (corners + np.roll(corners, -1, axis=1))
    return cells * np.sin(np.pi * (np.arange(h - 1) + 0.5) / (h - 1))[:, None]


# --- Environment directions <-> map coordinates -------------------------------------------
@jit(inline="always")
def env_uv(d):
    """Map coordinates (u, v) in [0,1)^2 of a world direction (+y up)."""
    u = 0.5 + math.atan2(d[0], -d[2]) * (0.5 / math.pi)
    v = math.acos(min(max(d[1], -1.0), 1.0)) / math.pi
    return u - math.floor(u), v


@jit(inline="always")
def env_dir(u, v):
    theta = math.pi * v
    phi = 2.0 * math.pi * (u - 0.5)
    st = math.sin(theta)
    return (st * math.sin(phi), math.cos(theta), -st * math.cos(phi))


@jit(inline="always")
def env_cell_uv(lt, d):
    """(u, v) of world direction d in an ENV_BILINEAR map's cell grid: u = 0 at the first column's
    centre (periodic, in [0, 1)), v = 0 at the top row (straight up in the map's frame)."""
    r = lt.env_rot
    x = r[0, 0] * d[0] + r[0, 1] * d[1] + r[0, 2] * d[2]
    y = r[1, 0] * d[0] + r[1, 1] * d[1] + r[1, 2] * d[2]
    z = r[2, 0] * d[0] + r[2, 1] * d[1] + r[2, 2] * d[2]
    n = math.sqrt(x * x + y * y + z * z)
    u = math.atan2(x, -z) * (0.5 / math.pi) - 0.5 / lt.env_map.shape[1]
    v = math.acos(min(max(y / n, -1.0), 1.0)) / math.pi if n > 0.0 else 0.0
    return u - math.floor(u), v


@jit(inline="always")
def env_cell_dir(lt, u, v):
    """The world direction of cell coordinates (u, v) (env_cell_uv's inverse)."""
    theta = math.pi * v
    phi = 2.0 * math.pi * (u + 0.5 / lt.env_map.shape[1])
    st = math.sin(theta)
    x, y, z = st * math.sin(phi), math.cos(theta), -st * math.cos(phi)
    r = lt.env_rot  # its transpose turns the map's frame back to the world
    return (r[0, 0] * x + r[1, 0] * y + r[2, 0] * z, r[0, 1] * x + r[1, 1] * y + r[2, 1] * z,
            r[0, 2] * x + r[1, 2] * y + r[2, 2] * z)


@jit(inline="always")
def env_radiance(lt, d):
    """Radiance arriving from direction d (a ray that left the scene along d)."""
    if lt.env_type == ENV_CONSTANT:
        return lt.env_const[0], lt.env_const[1], lt.env_const[2]
    if lt.env_type == ENV_BILINEAR:
        u, v = env_cell_uv(lt, d)
        h = lt.env_map.shape[0]
        w = lt.env_map.shape[1]
        x = u * w
        y = v * (h - 1)
        ix = min(int(x), w - 1)
        iy = min(int(y), h - 2)
        fx = x - ix
        fy = y - iy
        ix1 = ix + 1 if ix + 1 < w else 0
        m = lt.env_map
        w00, w01 = (1.0 - fy) * (1.0 - fx), (1.0 - fy) * fx
        w10, w11 = fy * (1.0 - fx), fy * fx
        return (w00 * m[iy, ix, 0] + w01 * m[iy, ix1, 0] + w10 * m[iy + 1, ix, 0] + w11 * m[iy + 1, ix1, 0],
                w00 * m[iy, ix, 1] + w01 * m[iy, ix1, 1] + w10 * m[iy + 1, ix, 1] + w11 * m[iy + 1, ix1, 1],
                w00 * m[iy, ix, 2] + w01 * m[iy, ix1, 2] + w10 * m[iy + 1, ix, 2] + w11 * m[iy + 1, ix1, 2])
    if lt.env_type == ENV_MAP:
        u, v = env_uv(d)
        h = lt.env_map.shape[0]
        w = lt.env_map.shape[1]
        x = min(int(u * w), w - 1)
        y = min(int(v * h), h - 1)
        return lt.env_map[y, x, 0], lt.env_map[y, x, 1], lt.env_map[y, x, 2]
    return 0.0, 0.0, 0.0


@jit(inline="always")
def env_pdf(lt, d):
    """Solid-angle pdf of choosing the environment and then direction d."""
    if lt.env_type == ENV_CONSTANT:
        return lt.p_env * INV_4PI
    if lt.env_type == ENV_MAP or lt.env_type == ENV_BILINEAR:
        if lt.env_type == ENV_MAP:
            u, v = env_uv(d)
        else:
            u, v = env_cell_uv(lt, d)
        st = math.sin(math.pi * v)
        if st <= 0.0:
            return 0.0
        p = distribution_2d_pdf(lt.env_cond_func, lt.env_cond_cdf, lt.env_marg_func, lt.env_marg_cdf, u, v)
        return lt.p_env * p / (2.0 * math.pi * math.pi * st)
    return 0.0


# --- Triangle lights ------------------------------------------------------------------------
@jit(inline="always")
def triangle_emission(lt, tri_index, wo_dot_n):
    """Radiance leaving emissive triangle `tri_index` toward a viewer with dot(w_to_viewer, n_ccw)."""
    li = lt.light_of_tri[tri_index]
    if li < 0 or wo_dot_n <= 0.0:
        return 0.0, 0.0, 0.0
    return lt.radiance[li, 0], lt.radiance[li, 1], lt.radiance[li, 2]


@jit(inline="always")
def triangle_light_pdf(lt, tri_index, dist2, cos_light):
    """Solid-angle pdf that NEE picks a point of triangle `tri_index` seen at dist^2, |cos|."""
    li = lt.light_of_tri[tri_index]
    if li < 0 or cos_light <= 0.0:
        return 0.0
    p_sel = (1.0 - lt.p_env) * (lt.cdf[li + 1] - lt.cdf[li])
    return p_sel * dist2 / (lt.area[li] * cos_light)


@jit(inline="always")
def sample_light(lt, tri, x, u_sel, u0, u1):
    """Pick a light and a point on it as seen from x.

    Returns (wi, dist, radiance rgb, pdf, t): wi the unit world direction from x, dist the
    distance to the point (np.inf for the environment), pdf per unit solid angle including
    the choice of light (0 when the sample carries no light: back side, degenerate), t the
    index of the triangle the point lies on (LIGHT_ENV for the environment). Delta light j gives
    t = -2 - j, the value arriving at x (delta_arrival) and pdf the probability of choosing it.
    """
    if u_sel < lt.p_env:
        # The environment
        if lt.env_type == ENV_CONSTANT:
            wi = sample_uniform_sphere(u0, u1)
            pdf = lt.p_env * INV_4PI
            return wi, np.inf, (lt.env_const[0], lt.env_const[1], lt.env_const[2]), pdf, -1
        su, sv, p = sample_distribution_2d(
            lt.env_cond_func, lt.env_cond_cdf, lt.env_marg_func, lt.env_marg_cdf, u0, u1
        )
        st = math.sin(math.pi * sv)
        if st <= 0.0 or p <= 0.0:
            return (0.0, 0.0, 1.0), np.inf, (0.0, 0.0, 0.0), 0.0, -1
        wi = env_dir(su, sv) if lt.env_type == ENV_MAP else env_cell_dir(lt, su, sv)
        rad = env_radiance(lt, wi)
        return wi, np.inf, rad, lt.p_env * p / (2.0 * math.pi * math.pi * st), -1
    # A triangle, by power, then a point by area
    u = (u_sel - lt.p_env) / (1.0 - lt.p_env)
    _, _, li = sample_distribution_1d(lt.func, lt.cdf, min(u, 1.0 - 1e-12))
    if li >= lt.tri.shape[0]:
        j = li - lt.tri.shape[0]
        wi, dist, val = delta_arrival(lt, j, x)
        return wi, dist, val, (1.0 - lt.p_env) * (lt.cdf[li + 1] - lt.cdf[li]), LIGHT_ENV - 1 - j
    t = lt.tri[li]
    b1, b2 = sample_uniform_triangle(u0, u1)
    b0 = 1.0 - b1 - b2
    py = b0 * tri[t, 0, 0] + b1 * tri[t, 1, 0] + b2 * tri[t, 2, 0]
    pyy = b0 * tri[t, 0, 1] + b1 * tri[t, 1, 1] + b2 * tri[t, 2, 1]
    pz = b0 * tri[t, 0, 2] + b1 * tri[t, 1, 2] + b2 * tri[t, 2, 2]
    dx, dy, dz = py - x[0], pyy - x[1], pz - x[2]
    d2 = dx * dx + dy * dy + dz * dz
    if d2 <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0, t
    dist = math.sqrt(d2)
    wi = (dx / dist, dy / dist, dz / dist)
    cos_l = -(wi[0] * lt.normal[li, 0] + wi[1] * lt.normal[li, 1] + wi[2] * lt.normal[li, 2])
    if cos_l <= 0.0:
        return wi, dist, (0.0, 0.0, 0.0), 0.0, t
    p_sel = (1.0 - lt.p_env) * (lt.cdf[li + 1] - lt.cdf[li])
    pdf = p_sel * d2 / (lt.area[li] * cos_l)
    return wi, dist, (lt.radiance[li, 0], lt.radiance[li, 1], lt.radiance[li, 2]), pdf, t
