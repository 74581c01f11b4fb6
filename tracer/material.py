"""The material at a hit: (triangle, barycentrics) -> the BSDF there and its shading frame.

`surface_at(surf, p, b1, b2)` is the one step every kernel that shades a point takes (the path
tracer's shade, NEE, the photon tracer's scatter, the gradient-domain offsets, the records and
AOVs): it evaluates the material's textures at the point's UV and builds the shading frame from
the interpolated vertex normals. It returns a Surface: the BSDF at the point, `bp = (type,
params)` as tracer.bsdfs takes it (with `table`, the scene's coat tables), and the frame (s, t, ns) in which its local directions live.

Normals: `ng` (the triangle's geometric normal, counter-clockwise side) decides sides (one-sided
emission, which side a ray is offset to, light leaks); `ns`, the interpolated vertex normal
turned into ng's hemisphere (as pbrt-v4 orients them), is the +z of the BSDF's local frame.
Without vertex normals ns is ng, bit for bit. `leak(ng, wo, wi, transmissive)` is the side test
a shading normal needs: a reflection whose two directions lie on opposite sides of the true
surface (or a refraction on one side) carries nothing. `adjoint_factor` is Veach's correction of
the BSDF for importance (photon) transport with shading normals (Veach 1997, section 5.3).

Textures (Textures, built by tracer.textures): one flat float32 RGB array for every image of
the scene and one row of `info` per texture:

    info[k] = [kind, offset, width, height, a, b, c, d, e, f, r0, g0, b0, r1, g1, b1]

kind TEX_CONSTANT (colour r0 g0 b0), TEX_BITMAP (width x height texels at `offset`, row 0 the
image's top, bilinear, repeat) or TEX_CHECKER (Mitsuba's checkerboard: colour 0 where the
fractional parts of u and v are both above or both below 1/2, colour 1 elsewhere); (u, v) is
first mapped by the affine (u', v') = (a u + b v + c, d u + e v + f). UVs follow the OBJ
convention: v grows upward in the image, so texel row = (1 - v') height.

`mat_tex[m]` names the texture of each slot of material m (TEX_SLOT_KD, TEX_SLOT_KS,
TEX_SLOT_BUMP, TEX_SLOT_OPACITY; -1: none): a kd or ks texture replaces the matching params, an
opacity texture (its Rec. 709 luminance, clamped to [0, 1]) sets params[P_CLEAR] = 1 - opacity
(tracer.bsdfs: the share that passes straight through); a bump texture is a
height field h(u, v) (its Rec. 709 luminance) that tilts the shading normal as Mitsuba 3's
`bumpmap` does: with g = params[P_BUMP_SCALE] x grad h, the surface's dp/du and dp/dv get g_u,
g_v as their components along the normal, and the new normal is their cross product, turned into
ng's hemisphere (`bump_normal`). A triangle without usable UVs keeps its normal.
"""
import math
from typing import NamedTuple

import numpy as np

from ._jit import jit
from .bsdfs import P_CLEAR, P_KD, P_KS, bsdf_at
from .sampling import dot, frame

TEX_CONSTANT, TEX_BITMAP, TEX_CHECKER = 0, 1, 2
TEX_SLOT_KD, TEX_SLOT_KS, TEX_SLOT_BUMP, TEX_SLOT_OPACITY = 0, 1, 2, 3
N_TEX_SLOTS = 4
P_BUMP_SCALE = 15  # the params column of a bump-mapped material's height scale
TEX_INFO_COLS = 16


class Surfaces(NamedTuple):
    """The scene's triangles and materials as the shading kernels read them (whole, read only)."""

    tri: np.ndarray  # (F, 3, 3) float64 world vertices
    normal: np.ndarray  # (F, 3) float64 unit geometric normal, counter-clockwise side
    material: np.ndarray  # (F,) material index of each triangle
    eps: np.ndarray  # (F,) float64 ray offset of each triangle (tracer.bvh.ray_offsets)
    mat_type: np.ndarray  # (M,) int32 material type (tracer.bsdfs)
    mat_param: np.ndarray  # (M, bsdfs.N_PARAM) float64 material parameters
    uv: np.ndarray  # (F, 3, 2) float64 corner UVs, or (0, 3, 2): none in the scene
    vn: np.ndarray  # (F, 3, 3) float64 corner normals (a zero row: flat), or (0, 3, 3): none
    mat_tex: np.ndarray  # (M, N_TEX_SLOTS) int32 texture of each slot (-1: none)
    tex_info: np.ndarray  # (T, TEX_INFO_COLS) float64, the module docstring's rows
    tex_data: np.ndarray  # (texels * 3,) float32 linear RGB of every bitmap
    mat_table: np.ndarray  # (M, coating.TABLE_RES) float64 the COATED materials' transmittance tables


class Surface(NamedTuple):
    """What surface_at returns."""

    bp: tuple  # the BSDF at the point, (type, params) as tracer.bsdfs takes it
    ns: tuple  # unit shading normal (+z of the local frame), in ng's hemisphere
    s: tuple  # unit tangents: (s, t, ns) is the local frame
    t: tuple
    uv: tuple  # the point's (u, v) (0, 0 without UVs)
    smooth: bool  # ns comes from vertex normals or a bump map (else it is ng: `crosses` is always False)


@jit
def _texel(tex_data, base, w, h, ix, iy):
    ix = ix % w
    iy = iy % h
    j = base + 3 * (iy * w + ix)
    return tex_data[j], tex_data[j + 1], tex_data[j + 2]


@jit
def texture_eval(tex_info, tex_data, k, u, v):
    """Texture k at (u, v): a linear RGB 3-tuple (the module docstring's kinds)."""
    kind = int(tex_info[k, 0])
    uu = tex_info[k, 4] * u + tex_info[k, 5] * v + tex_info[k, 6]
    vv = tex_info[k, 7] * u + tex_info[k, 8] * v + tex_info[k, 9]
    if kind == TEX_CHECKER:
        fu = uu - math.floor(uu)
        fv = vv - math.floor(vv)
        c = 10 if (fu > 0.5) == (fv > 0.5) else 13
        return tex_info[k, c], tex_info[k, c + 1], tex_info[k, c + 2]
    if kind != TEX_BITMAP:
        return tex_info[k, 10], tex_info[k, 11], tex_info[k, 12]
    base = int(tex_info[k, 1])
    w = int(tex_info[k, 2])
    h = int(tex_info[k, 3])
    x = uu * w - 0.5
    y = (1.0 - vv) * h - 0.5
    if not (math.isfinite(x) and math.isfinite(y)):
        return 0.0, 0.0, 0.0
    x0 = math.floor(x)
    y0 = math.floor(y)
    fx = x - x0
    fy = y - y0
    ix = int(x0 % w)
    iy = int(y0 % h)
    a = _texel(tex_data, base, w, h, ix, iy)
    b = _texel(tex_data, base, w, h, ix + 1, iy)
    c = _texel(tex_data, base, w, h, ix, iy + 1)
    d = _texel(tex_data, base, w, h, ix + 1, iy + 1)
    out0 = (1.0 - fy) * ((1.0 - fx) * a[0] + fx * b[0]) + fy * ((1.0 - fx) * c[0] + fx * d[0])
    out1 = (1.0 - fy) * ((1.0 - fx) * a[1] + fx * b[1]) + fy * ((1.0 - fx) * c[1] + fx * d[1])
    out2 = (1.0 - fy) * ((1.0 - fx) * a[2] + fx * b[2]) + fy * ((1.0 - fx) * c[2] + fx * d[2])
    return out0, out1, out2


@jit
def _lum(c):
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


@jit
def texture_grad(tex_info, tex_data, k, u, v):
    """(d/du, d/dv) of texture k's scalar value (luminance) at (u, v): the exact derivative of the
    bilinear bitmap in the cell holding the point; (0, 0) for constants and checkerboards."""
    if int(tex_info[k, 0]) != TEX_BITMAP:
        return 0.0, 0.0
    uu = tex_info[k, 4] * u + tex_info[k, 5] * v + tex_info[k, 6]
    vv = tex_info[k, 7] * u + tex_info[k, 8] * v + tex_info[k, 9]
    base = int(tex_info[k, 1])
    w = int(tex_info[k, 2])
    h = int(tex_info[k, 3])
    x = uu * w - 0.5
    y = (1.0 - vv) * h - 0.5
    if not (math.isfinite(x) and math.isfinite(y)):
        return 0.0, 0.0
    x0 = math.floor(x)
    y0 = math.floor(y)
    fx = x - x0
    fy = y - y0
    ix = int(x0 % w)
    iy = int(y0 % h)
    a = _lum(_texel(tex_data, base, w, h, ix, iy))
    b = _lum(_texel(tex_data, base, w, h, ix + 1, iy))
    c = _lum(_texel(tex_data, base, w, h, ix, iy + 1))
    d = _lum(_texel(tex_data, base, w, h, ix + 1, iy + 1))
    dx = (1.0 - fy) * (b - a) + fy * (d - c)  # per texel along x (u) and y (down the image)
    dy = (1.0 - fx) * (c - a) + fx * (d - b)
    gu = dx * w  # d/du' and d/dv' (v' up the image)
    gv = -dy * h
    return gu * tex_info[k, 4] + gv * tex_info[k, 7], gu * tex_info[k, 5] + gv * tex_info[k, 8]


@jit
def triangle_dpduv(tri, uv, p):
    """(dp/du, dp/dv, ok) of triangle p from its corners and corner UVs; ok False where its UVs
    are degenerate."""
    e1 = (tri[p, 1, 0] - tri[p, 0, 0], tri[p, 1, 1] - tri[p, 0, 1], tri[p, 1, 2] - tri[p, 0, 2])
    e2 = (tri[p, 2, 0] - tri[p, 0, 0], tri[p, 2, 1] - tri[p, 0, 1], tri[p, 2, 2] - tri[p, 0, 2])
    du1 = uv[p, 1, 0] - uv[p, 0, 0]
    dv1 = uv[p, 1, 1] - uv[p, 0, 1]
    du2 = uv[p, 2, 0] - uv[p, 0, 0]
    dv2 = uv[p, 2, 1] - uv[p, 0, 1]
    det = du1 * dv2 - dv1 * du2
    if not (det != 0.0 and math.isfinite(det)):
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), False
    inv = 1.0 / det
    dpdu = ((dv2 * e1[0] - dv1 * e2[0]) * inv, (dv2 * e1[1] - dv1 * e2[1]) * inv, (dv2 * e1[2] - dv1 * e2[2]) * inv)
    dpdv = ((du1 * e2[0] - du2 * e1[0]) * inv, (du1 * e2[1] - du2 * e1[1]) * inv, (du1 * e2[2] - du2 * e1[2]) * inv)
    return dpdu, dpdv, True


@jit
def bump_normal(n, ng, dpdu, dpdv, gu, gv):
    """The bump-mapped normal: dp/du, dp/dv with their components along n replaced by the height's
    gradient (gu, gv), crossed and normalised, in ng's hemisphere; n where that degenerates."""
    su = gu - dot(n, dpdu)
    sv = gv - dot(n, dpdv)
    a = (dpdu[0] + su * n[0], dpdu[1] + su * n[1], dpdu[2] + su * n[2])
    b = (dpdv[0] + sv * n[0], dpdv[1] + sv * n[1], dpdv[2] + sv * n[2])
    c = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    return _unit_toward(c, ng, n)


@jit
def _unit_toward(c, ng, fallback):
    """c normalised and turned into ng's hemisphere; fallback where c vanishes or is not finite."""
    c2 = dot(c, c)
    if not (c2 > 0.0 and math.isfinite(c2)):
        return fallback
    inv = 1.0 / math.sqrt(c2)
    if dot(c, ng) < 0.0:
        inv = -inv
    return (c[0] * inv, c[1] * inv, c[2] * inv)


@jit
def shading_normal(surf, p, b1, b2, ng):
    """Unit interpolated vertex normal of triangle p at (b1, b2), in ng's hemisphere; ng itself
    where the triangle has none (a zero corner) or the interpolation vanishes."""
    if surf.vn.shape[0] == 0:
        return ng
    b0 = 1.0 - b1 - b2
    vn = surf.vn
    n = (b0 * vn[p, 0, 0] + b1 * vn[p, 1, 0] + b2 * vn[p, 2, 0],
         b0 * vn[p, 0, 1] + b1 * vn[p, 1, 1] + b2 * vn[p, 2, 1],
         b0 * vn[p, 0, 2] + b1 * vn[p, 1, 2] + b2 * vn[p, 2, 2])
    return _unit_toward(n, ng, ng)


@jit
def surface_uv(surf, p, b1, b2):
    """(u, v) of triangle p at barycentrics (b1, b2); (0, 0) in a scene without UVs."""
    if surf.uv.shape[0] == 0:
        return 0.0, 0.0
    b0 = 1.0 - b1 - b2
    uv = surf.uv
    return (b0 * uv[p, 0, 0] + b1 * uv[p, 1, 0] + b2 * uv[p, 2, 0],
            b0 * uv[p, 0, 1] + b1 * uv[p, 1, 1] + b2 * uv[p, 2, 1])


@jit(inline="always")
def surface_at(surf, p, b1, b2):
    """The Surface of triangle p at barycentrics (b1, b2): its BSDF with textures evaluated, and
    its shading frame."""
    m = surf.material[p]
    bp = bsdf_at(surf.mat_type, surf.mat_param, m)
    ng = (surf.normal[p, 0], surf.normal[p, 1], surf.normal[p, 2])
    uv = (0.0, 0.0)
    textured = surf.tex_info.shape[0] > 0 and (surf.mat_tex[m, TEX_SLOT_KD] >= 0 or surf.mat_tex[m, TEX_SLOT_KS] >= 0
                                              or surf.mat_tex[m, TEX_SLOT_BUMP] >= 0
                                              or surf.mat_tex[m, TEX_SLOT_OPACITY] >= 0)
    if textured:
        uv = surface_uv(surf, p, b1, b2)
    if textured and (surf.mat_tex[m, TEX_SLOT_KD] >= 0 or surf.mat_tex[m, TEX_SLOT_KS] >= 0
                     or surf.mat_tex[m, TEX_SLOT_OPACITY] >= 0):
        t, prm = bp[0], bp[1]
        kd = (prm[0], prm[1], prm[2])
        ks = (prm[3], prm[4], prm[5])
        clear = prm[16]
        if surf.mat_tex[m, TEX_SLOT_KD] >= 0:
            kd = texture_eval(surf.tex_info, surf.tex_data, surf.mat_tex[m, TEX_SLOT_KD], uv[0], uv[1])
        if surf.mat_tex[m, TEX_SLOT_KS] >= 0:
            ks = texture_eval(surf.tex_info, surf.tex_data, surf.mat_tex[m, TEX_SLOT_KS], uv[0], uv[1])
        if surf.mat_tex[m, TEX_SLOT_OPACITY] >= 0:
            op = _lum(texture_eval(surf.tex_info, surf.tex_data, surf.mat_tex[m, TEX_SLOT_OPACITY], uv[0], uv[1]))
            clear = 1.0 - min(max(op, 0.0), 1.0)
        # (keep_surface keeps exactly these textured params: kd, ks, clear)
        bp = (t, (kd[0], kd[1], kd[2], ks[0], ks[1], ks[2], prm[6], prm[7], prm[8], prm[9], prm[10], prm[11],
                  prm[12], prm[13], prm[14], prm[15], clear))
    ns = shading_normal(surf, p, b1, b2, ng)
    smooth = surf.vn.shape[0] > 0
    if textured and surf.mat_tex[m, TEX_SLOT_BUMP] >= 0 and surf.uv.shape[0] > 0:
        dpdu, dpdv, ok = triangle_dpduv(surf.tri, surf.uv, p)
        if ok:
            gu, gv = texture_grad(surf.tex_info, surf.tex_data, surf.mat_tex[m, TEX_SLOT_BUMP], uv[0], uv[1])
            k = surf.mat_param[m, P_BUMP_SCALE] if surf.mat_param.shape[1] > P_BUMP_SCALE else 1.0
            ns = bump_normal(ns, ng, dpdu, dpdv, k * gu, k * gv)
            smooth = True
    s, tt = frame(ns)
    return Surface(bp, ns, s, tt, uv, smooth)


SURFACE_COLS = 13  # a kept Surface's floats: kd, ks, clear, ns, uv, smooth (keep_surface)


@jit
def costly_surfaces(surf):
    """Whether a Surface costs more to evaluate than to keep (vertex normals or textures)."""
    return surf.vn.shape[0] > 0 or surf.tex_info.shape[0] > 0


@jit
def keep_surface(rows, i, sf):
    """Keep in row i of rows (n, SURFACE_COLS) float64 what Surface sf holds beyond its material's
    table row: the (textured) reflectances and clearness, the shading normal, uv, smooth."""
    prm = sf.bp[1]
    for c in range(3):
        rows[i, c] = prm[P_KD + c]
        rows[i, 3 + c] = prm[P_KS + c]
        rows[i, 7 + c] = sf.ns[c]
    rows[i, 6] = prm[P_CLEAR]
    rows[i, 10] = sf.uv[0]
    rows[i, 11] = sf.uv[1]
    rows[i, 12] = 1.0 if sf.smooth else 0.0


@jit
def kept_surface(surf, rows, i, p):
    """The Surface of triangle p that keep_surface kept in row i, bit for bit as surface_at gave it."""
    r = rows[i]
    m = surf.material[p]
    q = surf.mat_param
    # params P_KD .. P_KS + 2 and P_CLEAR (the ones surface_at's textures replace) from the row, the
    # rest from the material's table
    bp = (surf.mat_type[m], (r[0], r[1], r[2], r[3], r[4], r[5], q[m, 6], q[m, 7], q[m, 8], q[m, 9], q[m, 10],
                             q[m, 11], q[m, 12], q[m, 13], q[m, 14], q[m, 15], r[6]))
    ns = (r[7], r[8], r[9])
    s, t = frame(ns)
    return Surface(bp, ns, s, t, (r[10], r[11]), r[12] != 0.0)


@jit
def barycentrics(tri, p, x):
    """(b1, b2) of the point x on triangle p's plane (the inverse of sampling.triangle_point)."""
    e1 = (tri[p, 1, 0] - tri[p, 0, 0], tri[p, 1, 1] - tri[p, 0, 1], tri[p, 1, 2] - tri[p, 0, 2])
    e2 = (tri[p, 2, 0] - tri[p, 0, 0], tri[p, 2, 1] - tri[p, 0, 1], tri[p, 2, 2] - tri[p, 0, 2])
    d = (x[0] - tri[p, 0, 0], x[1] - tri[p, 0, 1], x[2] - tri[p, 0, 2])
    a11 = dot(e1, e1)
    a12 = dot(e1, e2)
    a22 = dot(e2, e2)
    r1 = dot(d, e1)
    r2 = dot(d, e2)
    det = a11 * a22 - a12 * a12
    if not det > 0.0:
        return 0.0, 0.0
    return (a22 * r1 - a12 * r2) / det, (a11 * r2 - a12 * r1) / det


@jit(inline="always")
def surface_at_point(surf, p, x):
    """surface_at for a point x known by position only (the gradient-domain offsets)."""
    if surf.vn.shape[0] == 0 and surf.tex_info.shape[0] == 0:
        return surface_at(surf, p, 0.0, 0.0)
    b1, b2 = barycentrics(surf.tri, p, x)
    return surface_at(surf, p, b1, b2)


@jit(inline="always")
def crosses(sf, cos_o, ng, wo, wi, wiw):
    """True where a scattering wo -> wi (local to sf's frame; wiw is wi in world space) reflects in
    the shading frame and refracts through the true surface (normal ng, cos_o = the world wo's
    cosine with it), or the reverse: a light leak that only shading normals make possible. The
    BSDF is taken as zero there (eval, NEE and a sample alike). Always False where sf is flat."""
    if not sf.smooth:
        return False
    return (wo[2] * wi[2] > 0.0) != (cos_o * dot(wiw, ng) > 0.0)


@jit(inline="always")
def adjoint_factor(ng, ns, wo, wi):
    """Veach's correction of f for importance transport with shading normals:
    |wo.ns| |wi.ng| / (|wo.ng| |wi.ns|), wo toward where the particle came from, wi where it goes
    (1 where ns is ng); 0 where it is undefined."""
    den = abs(dot(wo, ng)) * abs(dot(wi, ns))
    if not den > 0.0:
        return 0.0
    return abs(dot(wo, ns)) * abs(dot(wi, ng)) / den
