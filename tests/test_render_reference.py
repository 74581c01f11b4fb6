"""Renders against answers computed in NumPy (tests/microfacet.py), beyond the Lambertian ones of
test_integrator.py: an environment map lighting a tilted diffuse plate, the same map seen by the
camera, and a rough conductor sphere under a constant sky.

z-tests use the render's own variance estimate (tracer/testing/stats.py), Sidak-corrected over the tests
of each test function (tracer.testing.ALPHA is the family-wise level of one function).
Sensitivities quoted in the docstrings come from perturbing the reference (or the tracer, in a
copy) against the same renders.
"""
import math

import numpy as np
import pytest

import tracer
from tests import microfacet as M
from tests import scenes
from tracer.testing.stats import ALPHA, assert_clean, assert_z, image_mean

# The map: black but for one bright square above the horizon, off every axis and symmetry plane
ENV_H, ENV_W = 32, 64
ROWS, COLS = slice(8, 12), slice(40, 46)  # v in [0.25, 0.375), u in [0.625, 0.719)
SQUARE_RGB = (4.0, 2.0, 1.0)
SCALE = 2.5  # environment.scale in the sidecar
PLATE_KD = np.array([0.5, 0.6, 0.7])


def env_image():
    img = np.zeros((ENV_H, ENV_W, 3), np.float32)
    img[ROWS, COLS] = SQUARE_RGB
    return img


def square_centre():
    """World direction of the square's centre (row 10, column 43), by the README's convention."""
    theta, phi = math.pi * 10 / ENV_H, 2 * math.pi * (43 / ENV_W - 0.5)
    return M.env_direction(np.array(theta), np.array(phi))


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


# Plate normals: one tilted toward the square (n.w > 0 over all of it), one for which the square
# straddles the horizon (n.w = 0.05 at its centre); neither is +y
PLATES = {
    "toward": unit(square_centre() + [-0.3, 0.2, 0.4]),
    "grazing": unit(unit(np.cross(square_centre(), [0.3, 0.2, 0.9])) + 0.05 * square_centre()),
}


def camera_rays(cam, width, height):
    """Unit world directions (H, W, 3) through the pixel centres of the look-at camera `cam` (the
    sidecar's dict; fov along x): image right is forward x up, row 0 at the top."""
    o = np.asarray(cam["origin"], float)
    f = unit(np.asarray(cam["target"], float) - o)
    r = unit(np.cross(f, cam["up"]))
    u = np.cross(r, f)
    tx = math.tan(math.radians(cam["fov"]) / 2)
    ty = tx * height / width
    px, py = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    sx, sy = 2 * px / width - 1, 1 - 2 * py / height
    d = f + (sx * tx)[..., None] * r + (sy * ty)[..., None] * u
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def plate(normal, size, centre=(0.0, 0.0, 0.0)):
    """A square (4, 3) of side `size` facing `normal` (counter-clockwise), its two triangles, and
    an in-plane axis to use as the camera's up."""
    t1 = unit(np.cross(normal, [0.2, 0.3, 0.5]))
    t2 = np.cross(normal, t1)
    v = np.array([-t1 - t2, t1 - t2, t1 + t2, -t1 + t2]) * 0.5 * size + centre
    return v, np.array([[0, 1, 2], [0, 2, 3]]), t2


def plate_scene(folder, normal):
    """A 1 x 1 diffuse plate filling the view of a camera on its front side, lit only by the map."""
    tracer.write_image(folder / "env.exr", env_image())
    v, f, up = plate(normal, 1.0)
    return scenes.write_scene(
        folder, "plate", [("plate", v, f)], {"plate": "Kd %g %g %g" % tuple(PLATE_KD)},
        {"camera": {"origin": list(3.0 * normal), "target": [0, 0, 0], "up": list(up), "fov": 15},
         "film": {"width": 16, "height": 16},
         "environment": {"map": "env.exr", "scale": SCALE},
         "render": {"spp": 256, "max_depth": 2}})


@pytest.mark.parametrize("name", list(PLATES))
def test_environment_map_lights_tilted_plate(tmp_path, name):
    """A Lambertian plate lit only by the map reads kd / pi x scale x integral of L(w) max(0, n.w)
    over the sphere, the integral done pixel by pixel of the map in NumPy from the README's
    (u, v) convention (16 x 16 panels of 4 x 4 Gauss points per map pixel: agrees with 32 x 32 to
    4e-8 relative, where the plate's horizon cuts the square). Direct light only (max_depth 2): NEE samples the map by luminance x sin theta
    and BSDF-sampled rays that escape read `env_radiance`, MIS-weighted with `env_pdf`, so a pdf
    that does not match the sampling biases the sum.

    65k samples per plate: relative standard error 3e-4 ("toward") and 4e-3 ("grazing").
    Sensitivity (the reference with the map transformed, against the same render): u flipped
    (x -> -x) moves the expected radiance by -86% / -100%, v flipped (rows upside down) by
    -99% / +1050%, u shifted by half a turn by -85% / -100%, z mirrored (atan2(x, z) for
    atan2(x, -z)) by +0.9% / -24% (27 and 57 standard errors), scale ignored by -60%; a scale 1%
    off is 32 standard errors on "toward" (3.4 on "grazing"). Mutating the tracer (in a copy):
    u flipped in both env_uv and env_dir, which test_lights.py's unbiasedness test cannot see,
    fails both plates and the test below; so does a scale the loader drops; env_pdf without its
    1 / sin theta (MIS weights that no longer sum to 1) fails "toward"."""
    normal = PLATES[name]
    scene = tracer.load_scene(plate_scene(tmp_path, normal))
    r = tracer.render(scene, pixel_filter="point")
    assert_clean(r)
    albedo = r.aovs["albedo"].reshape(-1, 3)
    assert np.allclose(albedo, PLATE_KD, atol=1e-6), "every pixel must see the plate"
    expected = PLATE_KD / math.pi * SCALE * M.env_irradiance(env_image().astype(np.float64), normal)
    assert expected.min() > 0.0
    mean, var = image_mean(r)
    assert_z(mean, var, expected, n_tests=3, what=f"plate {name}")


def test_environment_map_seen_directly(tmp_path):
    """Camera rays that leave the scene read the map at their direction, scaled: every pixel equals
    scale x map[v(d), u(d)] with (u, v) from the README's convention applied in NumPy to the pixel
    centre's direction d (pixels within 1e-6 of a map-pixel boundary left out). One sample per
    pixel through its centre, so there is no noise: any flip, shift or transposition of the map,
    or a wrong scale, fails."""
    tracer.write_image(tmp_path / "env.exr", env_image())
    d_sq = square_centre()
    v, f, _ = plate(-d_sq, 0.1, centre=-5.0 * d_sq)  # something to load, behind the camera
    cam = {"origin": [0, 0, 0], "target": list(d_sq + [0.1, -0.2, 0.1]), "up": [0, 1, 0], "fov": 70}
    w, h = 48, 32
    obj = scenes.write_scene(
        tmp_path, "sky", [("dot", v, f)], {"dot": "Kd 0.5 0.5 0.5"},
        {"camera": cam, "film": {"width": w, "height": h},
         "environment": {"map": "env.exr", "scale": SCALE}, "render": {"spp": 1, "max_depth": 1}})
    r = tracer.render(tracer.load_scene(obj), pixel_filter="point")
    assert_clean(r)
    d = camera_rays(cam, w, h)
    u = (0.5 + np.arctan2(d[..., 0], -d[..., 2]) / (2 * math.pi)) % 1.0
    vv = np.arccos(np.clip(d[..., 1], -1, 1)) / math.pi
    clear = ((np.abs(u * ENV_W - np.round(u * ENV_W)) > 1e-6)
             & (np.abs(vv * ENV_H - np.round(vv * ENV_H)) > 1e-6))
    expected = SCALE * M.env_lookup(env_image(), d).astype(np.float64)
    lit = expected[..., 0] > 0
    assert clear.mean() > 0.99 and 20 < (lit & clear).sum() < 0.8 * clear.sum()
    np.testing.assert_allclose(r.image[clear], expected[clear], rtol=1e-6, atol=0.0)


def test_rough_conductor_sphere_under_constant_sky(tmp_path):
    """A convex rough conductor with F = 1 (MTL Ks 1, Pr 0.8, Pm 1: alpha 0.64) under a constant
    sky L sees only the sky, so a pixel whose centre ray meets a facet at cosine mu reads
    L x E(mu), E the white-furnace albedo by quadrature of D G2 / (4 mu) (tests/microfacet.py),
    Chebyshev-interpolated in mu (error < 1e-6, checked). The icosphere is flat-shaded and every
    sample goes through the pixel centre, so a pixel sees one facet: mu from the normal AOV and
    the pixel's ray. Per-pixel z-tests (Sidak over the sphere's 290 pixels, 512 spp) and a z-test
    of their mean share the level (half each); sky pixels read L exactly.

    The mean over the sphere has a relative standard error of 1.6e-3. Sensitivity (perturbing the
    reference, against the same render): E 1% too small everywhere is z = 5.3 on the mean (limit
    2.8); the separable G1 G1 for G2 moves the mean by 3.0% (z 18; worst pixel z 14); D with alpha
    5% too large by 1.2% (z 6.5); E read at 1 - mu by 15%. A Lambda 1% too large moves it by only
    0.3% (1.9 standard errors): the BSDF tests catch that one. With the tracer's G2 made
    separable (in a copy) a pixel fails at z = 13.6."""
    L, pr, w, h = 1.5, 0.8, 24, 24
    alpha = pr * pr
    cam = {"origin": [0.3, 0.5, 4.0], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 35}
    v, f = scenes.icosphere(2)
    obj = scenes.write_scene(
        tmp_path, "ball", [("ball", v, f)], {"ball": f"Ks 1 1 1\nPr {pr}\nPm 1"},
        {"camera": cam, "film": {"width": w, "height": h}, "environment": {"radiance": [L] * 3},
         "render": {"spp": 512, "max_depth": -1}})
    scene = tracer.load_scene(obj)
    r = tracer.render(scene, pixel_filter="point")
    assert_clean(r)
    albedo = r.aovs["albedo"][..., 0]
    ball, sky = albedo == 1.0, albedo == 0.0  # the conductor's albedo AOV is Ks
    assert ball.sum() > 250 and sky.sum() > 100 and (ball | sky).all()
    np.testing.assert_array_equal(r.image[sky], L)
    normal = r.aovs["normal"][ball].astype(np.float64)
    assert np.allclose(np.linalg.norm(normal, axis=1), 1.0, atol=1e-6)  # one facet per pixel
    mu = -np.sum(camera_rays(cam, w, h)[ball] * normal, axis=1)
    assert mu.min() > 0.02
    e = albedo_interpolant(alpha, 0.02)
    expected = L * e(mu)
    img, var = r.image[ball][:, 0].astype(np.float64), r.variance[ball][:, 0].astype(np.float64)
    n = img.size
    assert_z(img, var, expected, n_tests=n, alpha=ALPHA / 2, what="sphere pixels")
    assert_z(img.mean(), var.sum() / n**2, expected.mean(), alpha=ALPHA / 2, what="sphere mean")


def albedo_interpolant(alpha, mu_lo, k=32):
    """E(mu) of the F = 1 conductor on [mu_lo, 1]: Chebyshev interpolation of the quadrature at k
    nodes, checked against the quadrature at three other points."""
    x = np.cos(math.pi * (np.arange(k) + 0.5) / k)

    def to_x(mu):
        return 2.0 * (np.asarray(mu) - mu_lo) / (1.0 - mu_lo) - 1.0

    nodes = mu_lo + (1.0 - mu_lo) * (x + 1.0) / 2.0
    values = [M.conductor_albedo(alpha, m)[0] for m in nodes]
    coef = np.polynomial.chebyshev.chebfit(x, values, k - 1)

    def e(mu):
        return np.polynomial.chebyshev.chebval(to_x(mu), coef)

    for m in (mu_lo + 1e-3, 0.137, 0.61):
        assert abs(e(m) - M.conductor_albedo(alpha, m)[0]) < 1e-6
    return e
