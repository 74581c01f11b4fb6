"""The environment-lit interior of bench.scenes_envlit (an envmap seen through openings, bilinear and
trilinear textures at grazing angles and far away, masked surfaces, roughdiffuse) rendered by the
tracer and by Mitsuba 3 (`scalar_rgb`, through bench.vs_mitsuba's copy of the file): the image
means agree. Skipped without mitsuba."""
import numpy as np
import pytest

import tracer
from bench import scenes_envlit
from tracer.testing.stats import assert_clean, z_critical

W, H, SPP, MI_SEEDS = 24, 18, 48, 8


def _mitsuba_mean(path):
    """Image mean (rgb) of Mitsuba 3's render of the scene's copy, MI_SEEDS seeds of SPP spp, and
    the variance of that mean (each pixel's variance across the seeds, over pixels)."""
    from bench.vs_mitsuba import mitsuba_render

    imgs = mitsuba_render(path, W, H, SPP, MI_SEEDS)[0].reshape(MI_SEEDS, -1, 3)
    npix = imgs.shape[1]
    return imgs.mean(axis=(0, 1)), imgs.var(axis=0, ddof=1).sum(axis=0) / (MI_SEEDS * npix * npix)


@pytest.mark.parametrize("variant", ["env", "all"])
def test_envlit_interior_image_mean_agrees_with_mitsuba(tmp_path, variant):
    """The tracer's image mean of the `env` (envmap through openings, plain walls) and `all`
    variants (every feature) at 24x18, 48 spp, equals Mitsuba 3's (8 seeds of 48 spp) per channel,
    by z-test on both renderers' estimated variances (Sidak over 2 variants x 3 channels). What it
    detects: a difference of about 2.5% of a channel's mean (the standard error of the difference
    is about 0.75%): the envmap looked up as piecewise-constant texels resampled onto the tracer's
    grid, rather than bilinearly between Mitsuba's texel centres, gives +5.1% green on `env` here
    (z = 6.6); a texture filter, wrap, mask or roughdiffuse read unlike Mitsuba's would show too."""
    pytest.importorskip("mitsuba")
    path = scenes_envlit.write(str(tmp_path), variant, width=W, height=H, spp=SPP)
    scene = tracer.load_scene(path)
    r = tracer.render(scene, spp=SPP * MI_SEEDS // 2, seed=3, pixel_filter="box")
    assert_clean(r, f"envlit-{variant}")
    img, var = r.image.reshape(-1, 3).astype(np.float64), r.variance.reshape(-1, 3).astype(np.float64)
    ours, var_ours = img.mean(axis=0), var.sum(axis=0) / img.shape[0] ** 2
    theirs, var_theirs = _mitsuba_mean(path)
    z = (ours - theirs) / np.sqrt(var_ours + var_theirs)
    zc = z_critical(2 * 3)
    assert np.all(np.abs(z) < zc), (f"envlit-{variant}: tracer {ours}, Mitsuba {theirs}, z {z} "
                                    f"(|z| < {zc:.2f} needed)")



def _nearest_texel(img, d):
    """img's texels (lat-long, the convention of bench.scenes_envlit.envmap_image) nearest to unit
    directions d (N, 3), by luminance."""
    h, w = img.shape[:2]
    theta, phi = np.arccos(np.clip(d[:, 1], -1, 1)), np.arctan2(d[:, 0], -d[:, 2]) % (2 * np.pi)
    y = np.clip(np.rint(theta / np.pi * (h - 1)).astype(int), 0, h - 1)
    x = np.clip((phi / (2 * np.pi) * w).astype(int), 0, w - 1)
    return img.mean(axis=-1)[y, x], (y, x)


def test_sky_map_sun_and_sky_irradiance():
    """bench.scenes_envlit.sky_image, the stand-in for a `sunsky` emitter: the sun disk's irradiance
    at normal incidence over the sky's on a horizontal plane is SUN_TO_SKY, both integrated here by
    Monte Carlo over the map's texels (nearest lookup): the sky over uniform directions, the sun over
    a cone of 1.5x its radius about sun_dir, which also places it. What it detects: a sun of the
    wrong power, size or place, or a sky integral unlike the generator's, by more than 4 standard
    errors of the ratio (about 2%)."""
    sun = np.array([0.88698, 0.288862, 0.360313])
    sun /= np.linalg.norm(sun)
    r = np.radians(2.0)
    img = scenes_envlit.sky_image(sun, np.degrees(r), sky_scale=30.0).astype(np.float64)
    peak = img.mean(axis=-1).max()
    rng = np.random.default_rng(5)
    n = 200_000
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    lum, _ = _nearest_texel(img, d)
    sky = np.where(lum >= 0.999 * peak, 0.0, lum) * np.maximum(d[:, 1], 0.0) * 4 * np.pi
    # the cone about the sun: cos uniform in [cos 1.5r, 1], phi uniform, in the sun's frame
    c = 1 - rng.uniform(size=n) * (1 - np.cos(1.5 * r))
    a = rng.uniform(size=n) * 2 * np.pi
    t = np.cross(sun, [0.0, 1.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(sun, t)
    sn = np.sqrt(1 - c * c)
    dc = c[:, None] * sun + (sn * np.cos(a))[:, None] * t + (sn * np.sin(a))[:, None] * b
    lum_c, _ = _nearest_texel(img, dc)
    disk = np.where(lum_c >= 0.999 * peak, lum_c, 0.0) * 2 * np.pi * (1 - np.cos(1.5 * r))
    e_sky, e_sun = sky.mean(), disk.mean()
    rel_se = np.hypot(sky.std(ddof=1) / np.sqrt(n) / e_sky, disk.std(ddof=1) / np.sqrt(n) / e_sun)
    ratio = e_sun / e_sky
    assert abs(ratio / scenes_envlit.SUN_TO_SKY - 1) <= 4 * rel_se, (ratio, rel_se)
