"""Warps from the unit square and the tables they need, each as a set.

Every warp `sample_X(u...) -> point` has its density `X_pdf(point)` beside it (and an
inverse where one is needed), so tests can check that the two agree. Directions are
unit 3-tuples of float64; hemisphere warps work in a local frame whose z is the normal.
Densities of directions are per unit solid angle, of points on a surface per unit area.

Tables (1D and 2D piecewise-constant distributions) are built in NumPy and sampled in
Numba: a `Distribution1D` is the pair of arrays `(func, cdf)`; a 2D one is a marginal
over rows plus one conditional per row, stored as 2D arrays.
"""
import math

import numpy as np

from ._jit import jit

INV_PI = 1.0 / math.pi
INV_2PI = 0.5 / math.pi
INV_4PI = 0.25 / math.pi


# --- Vectors as 3-tuples ---------------------------------------------------------------
@jit
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@jit
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@jit
def normalize(a):
    n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    if n == 0.0:
        return (0.0, 0.0, 0.0)
    inv = 1.0 / n
    return (a[0] * inv, a[1] * inv, a[2] * inv)


@jit
def frame(n):
    """Orthonormal tangents (s, t) with s x t = n, for a unit normal n (Duff et al. 2017)."""
    sign = 1.0 if n[2] >= 0.0 else -1.0
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = (1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])
    t = (b, sign + n[1] * n[1] * a, -n[1])
    return s, t


@jit
def to_local(v, s, t, n):
    return (dot(v, s), dot(v, t), dot(v, n))


@jit
def to_world(v, s, t, n):
    return (
        v[0] * s[0] + v[1] * t[0] + v[2] * n[0],
        v[0] * s[1] + v[1] * t[1] + v[2] * n[1],
        v[0] * s[2] + v[1] * t[2] + v[2] * n[2],
    )


# --- Disk, hemisphere, sphere -------------------------------------------------------------
@jit
def sample_concentric_disk(u0, u1):
    """Shirley-Chiu concentric map of the unit square onto the unit disk (area-preserving)."""
    a = 2.0 * u0 - 1.0
    b = 2.0 * u1 - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0
    if abs(a) > abs(b):
        r = a
        phi = (math.pi / 4.0) * (b / a)
    else:
        r = b
        phi = (math.pi / 2.0) - (math.pi / 4.0) * (a / b)
    return r * math.cos(phi), r * math.sin(phi)


@jit
def sample_cosine_hemisphere(u0, u1):
    """Cosine-weighted direction about +z (Malley's method)."""
    x, y = sample_concentric_disk(u0, u1)
    z = math.sqrt(max(0.0, 1.0 - x * x - y * y))
    return (x, y, z)


@jit
def cosine_hemisphere_pdf(w):
    return w[2] * INV_PI if w[2] > 0.0 else 0.0


@jit
def sample_uniform_sphere(u0, u1):
    z = 1.0 - 2.0 * u0
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * math.pi * u1
    return (r * math.cos(phi), r * math.sin(phi), z)


@jit
def uniform_sphere_pdf(w):
    return INV_4PI


@jit
def sample_uniform_triangle(u0, u1):
    """Barycentrics (b1, b2) uniform over a triangle (Heitz 2019, low distortion)."""
    if u0 < u1:
        b1 = u0 / 2.0
        b2 = u1 - b1
    else:
        b2 = u1 / 2.0
        b1 = u0 - b2
    return b1, b2


@jit(inline="always")
def triangle_point(tri, p, b1, b2):
    """The point of triangle p (tri (F, 3, 3)) at barycentrics (b1, b2): on the triangle's plane."""
    b0 = 1.0 - b1 - b2
    return (b0 * tri[p, 0, 0] + b1 * tri[p, 1, 0] + b2 * tri[p, 2, 0],
            b0 * tri[p, 0, 1] + b1 * tri[p, 1, 1] + b2 * tri[p, 2, 1],
            b0 * tri[p, 0, 2] + b1 * tri[p, 1, 2] + b2 * tri[p, 2, 2])


# --- Multiple importance sampling ----------------------------------------------------------
@jit
def power_heuristic(pdf_a, pdf_b):
    """MIS weight of strategy a against b (power 2); 0 when both densities are 0.

    Written with the ratio of the two pdfs so that neither huge (1e200) nor tiny (1e-200)
    densities overflow or underflow when squared.
    """
    if pdf_a >= pdf_b:
        if pdf_a <= 0.0:
            return 0.0
        r = pdf_b / pdf_a if math.isfinite(pdf_a) else 0.0
        return 1.0 / (1.0 + r * r)
    r = pdf_a / pdf_b if math.isfinite(pdf_b) else 0.0
    return r * r / (1.0 + r * r)


# --- Piecewise-constant distributions -------------------------------------------------------
def build_distribution_1d(func):
    """Tables for sampling a piecewise-constant function on [0, 1) with `n = len(func)` bins.

    func : (n,) float, non-negative. Returns (func (n,) float64, cdf (n+1,) float64). A function
    that is zero everywhere becomes uniform, so sampling never fails.
    """
    f = np.asarray(func, dtype=np.float64).copy()
    if f.ndim != 1 or f.size == 0:
        raise ValueError("distribution needs a non-empty 1D array")
    if not np.all(np.isfinite(f)) or np.any(f < 0):
        raise ValueError("distribution values must be finite and non-negative")
    n = f.size
    cdf = np.zeros(n + 1)
    np.cumsum(f / n, out=cdf[1:])
    total = cdf[-1]
    if total <= 0.0:
        f[:] = 1.0
        cdf = np.linspace(0.0, 1.0, n + 1)
    else:
        cdf /= total
    cdf[-1] = 1.0
    return f, cdf


def build_distribution_2d(func):
    """Tables for sampling a piecewise-constant function on [0,1)^2 given as (rows, cols).

    Returns (cond_func (rows, cols), cond_cdf (rows, cols+1), marg_func (rows,), marg_cdf (rows+1,)).
    Row index is the second coordinate (v), column the first (u).
    """
    f = np.asarray(func, dtype=np.float64)
    rows, cols = f.shape
    cond_func = np.empty((rows, cols))
    cond_cdf = np.empty((rows, cols + 1))
    row_int = np.empty(rows)
    for r in range(rows):  # table build, once per map: not a hot path
        cf, cc = build_distribution_1d(f[r])
        cond_func[r] = cf
        cond_cdf[r] = cc
        row_int[r] = f[r].mean()
    marg_func, marg_cdf = build_distribution_1d(row_int)
    return cond_func, cond_cdf, marg_func, marg_cdf


@jit
def _find_interval(cdf, u):
    """Largest i with cdf[i] <= u, clamped to [0, len(cdf) - 2]."""
    lo = 0
    hi = cdf.shape[0] - 1
    while lo + 1 < hi:  # bounded: halves the interval each step
        mid = (lo + hi) // 2
        if cdf[mid] <= u:
            lo = mid
        else:
            hi = mid
    return lo


@jit
def sample_distribution_1d(func, cdf, u):
    """Sample x in [0,1). Returns (x, pdf w.r.t. x, bin index)."""
    n = func.shape[0]
    i = _find_interval(cdf, u)
    width = cdf[i + 1] - cdf[i]
    du = (u - cdf[i]) / width if width > 0.0 else 0.5
    du = min(max(du, 0.0), 1.0 - 1e-12)
    # pdf of bin i = func[i] / mean(func), which is the cdf step times n
    pdf = width * n
    x = (i + du) / n
    return x, pdf, i


@jit
def distribution_1d_pdf(func, cdf, x):
    n = func.shape[0]
    i = min(max(int(x * n), 0), n - 1)
    return (cdf[i + 1] - cdf[i]) * n


@jit
def sample_distribution_2d(cond_func, cond_cdf, marg_func, marg_cdf, u0, u1):
    """Sample (x, y) in [0,1)^2 (x along columns, y along rows). Returns (x, y, pdf)."""
    y, pdf_y, row = sample_distribution_1d(marg_func, marg_cdf, u1)
    x, pdf_x, col = sample_distribution_1d(cond_func[row], cond_cdf[row], u0)
    return x, y, pdf_x * pdf_y


@jit
def distribution_2d_pdf(cond_func, cond_cdf, marg_func, marg_cdf, x, y):
    rows = marg_func.shape[0]
    row = min(max(int(y * rows), 0), rows - 1)
    return distribution_1d_pdf(marg_func, marg_cdf, y) * distribution_1d_pdf(
        cond_func[row], cond_cdf[row], x
    )
