"""The lane engine (tracer.engine, render(path_loop="lanes")) against the per-thread loop.

The lanes draw other random numbers than the per-thread loop (a 32-bit hash), so their images
agree in expectation, not bit for bit: z-tests of the image mean and of 6x6-pixel block means,
each side's variance from its own film. They detect a bias of about 4 standard errors of a block
mean (a few percent at 64 spp) anywhere in the image, and far smaller ones in the whole image's
mean: a missing cosine or MIS weight, a light chosen with another probability than its pdf says,
a shadow ray credited to the wrong lane, a lane lost or traced twice by the compaction. The
per-thread loop itself is checked against the wavefront bit for bit (test_thread_loop.py) and
the wavefront against analytic answers and Mitsuba 3.
"""
import json
import logging
import math
import os

import numpy as np
import pytest

import tracer
from tests.scenes import textured
from tracer.engine.lanes import alias_table
from tracer.testing.stats import assert_clean, assert_z, image_mean

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BLOCK = 6


def _scene(name, size=48):
    if name in ("bathroom", "veach-ajar"):
        path = os.path.join(os.path.dirname(ROOT), "shared", "scenes-mitsuba", name, "scene.xml")
        if not os.path.exists(path):
            pytest.skip(f"{path} is not there (../shared beside the checkout)")
        return tracer.load_scene(path, width=size, height=size * 9 // 16)
    return tracer.load_scene(os.path.join(ROOT, "scenes", name, f"{name}.obj"), width=size, height=size)


def _smooth_sphere_scene(folder, size=48):
    """A coarse sphere with corner normals (smooth shading) on a floor, under a quad light, all
    diffuse: written to `folder` as OBJ, MTL and sidecar JSON, and loaded."""
    nu, nv, r, c = 8, 5, 0.5, (0.0, 0.5, 0.0)
    v, vn, f = [], [], []
    for j in range(nv + 1):
        th = math.pi * j / nv
        for i in range(nu):
            ph = 2.0 * math.pi * i / nu
            n = (math.sin(th) * math.cos(ph), math.cos(th), math.sin(th) * math.sin(ph))
            v.append(tuple(c[k] + r * n[k] for k in range(3)))
            vn.append(n)
    for j in range(nv):
        for i in range(nu):
            a, b = j * nu + i + 1, j * nu + (i + 1) % nu + 1
            a2, b2 = a + nu, b + nu
            f += [(a, b, b2), (a, b2, a2)]
    lines = ["mtllib scene.mtl"] + [f"v {x} {y} {z}" for x, y, z in v] + [f"vn {x} {y} {z}" for x, y, z in vn]
    lines += ["usemtl ball"] + [f"f {a}//{a} {b}//{b} {d}//{d}" for a, b, d in f if len({a, b, d}) == 3]
    k = len(v)
    lines += [f"v {x} 0 {z}" for x, z in ((-2, -2), (2, -2), (2, 2), (-2, 2))]
    lines += ["usemtl floor", f"f {k + 1} {k + 3} {k + 2}", f"f {k + 1} {k + 4} {k + 3}"]
    lines += [f"v {x} 2 {z}" for x, z in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5))]
    lines += ["usemtl light", f"f {k + 5} {k + 6} {k + 7}", f"f {k + 5} {k + 7} {k + 8}"]
    (folder / "scene.obj").write_text("\n".join(lines) + "\n")
    (folder / "scene.mtl").write_text("newmtl ball\nKd 0.7 0.6 0.5\nnewmtl floor\nKd 0.5 0.5 0.5\n"
                                      "newmtl light\nKd 0 0 0\nKe 8 8 8\n")
    (folder / "scene.json").write_text(json.dumps({"camera": {"origin": [0.0, 1.2, -2.2], "target": [0.0, 0.5, 0.0],
                                                              "up": [0, 1, 0], "fov": 40}}))
    return tracer.load_scene(str(folder / "scene.obj"), width=size, height=size)


def _blocks(a):
    """Means over BLOCK x BLOCK pixels, (H/BLOCK * W/BLOCK, 3)."""
    h, w = a.shape[0] // BLOCK, a.shape[1] // BLOCK
    return a[: h * BLOCK, : w * BLOCK].reshape(h, BLOCK, w, BLOCK, 3).mean(axis=(1, 3)).reshape(-1, 3)


def _lanes_and_thread(scene, **kw):
    """The same render on the lanes (seed 1) and on the per-thread loop (seed 2: independent), each
    checked free of non-finite samples."""
    a = tracer.render(scene, seed=1, path_loop="lanes", **kw)
    b = tracer.render(scene, seed=2, path_loop="thread", **kw)
    assert_clean(a, "lanes")
    assert_clean(b, "thread")
    return a, b


def _assert_same_image(a, b, what, lit_share=0.0):
    """z-tests of the image means of renders a and b (independent seeds) and of their BLOCK x BLOCK
    block means, each side's variance from its own film (a block mean's: its pixels' mean variance
    over BLOCK^2); blocks with no variance on either side are left out, at most 1 - lit_share of
    them."""
    ma, va = image_mean(a)
    mb, vb = image_mean(b)
    assert_z(ma, va + vb, mb, what=f"{what}: image mean")
    var = (_blocks(a.variance.astype(np.float64)) + _blocks(b.variance.astype(np.float64))) / (BLOCK * BLOCK)
    keep = var > 0
    assert keep.sum() > lit_share * keep.size
    assert_z(_blocks(a.image.astype(np.float64))[keep], var[keep], _blocks(b.image.astype(np.float64))[keep],
             what=f"{what}: {BLOCK}x{BLOCK} block means")


@pytest.mark.parametrize("name, kw, general", [
    ("cornell", dict(max_depth=8, rr_depth=2), False),  # roulette from the second bounce: compaction at every depth
    ("ajar", dict(max_depth=-1), False),  # unlimited depth, an area light behind a door
    ("manylights", dict(max_depth=4), False),  # 48 lights of different powers: the alias table
    ("cornell", dict(max_depth=3, integrator="path:nee=0"), False),  # emission found in full, no shadow rays
    ("glossy", dict(max_depth=6), True),  # a mirror and metals beside diffuse walls: both classes in one path
    ("window", dict(max_depth=5), True),  # an environment: every vertex general
    ("spotlit", dict(max_depth=4), True),  # point and spot lights
    ("bathroom", dict(max_depth=5), True),  # Mitsuba XML: smooth diffuse, plastics, metals, glass, a mask
])
def test_lanes_equal_the_per_thread_loop_in_expectation(name, kw, general):
    """Image mean and block means of the lanes against the per-thread loop (independent seeds)."""
    scene = _scene(name)
    a, b = _lanes_and_thread(scene, spp=64, **kw)
    assert a.stats["lane_samples"] == a.stats["samples"] > 0, "some pass did not run on the lanes"
    assert b.stats["lane_samples"] == 0
    assert (a.stats["lane_general_vertices"] > 0) == general
    _assert_same_image(a, b, f"{name}, lanes against thread", lit_share=0.5)


@pytest.mark.parametrize("guide", ["grid:iterations=2", "ppg:iterations=2,window=0", "photon:iterations=2",
                                   "grid:iterations=2,split=1.5"])
def test_a_guides_final_passes_run_on_the_lanes(guide):
    """A guide's passes run on the lanes: its final passes with every vertex through the listed
    kernel (the guide's mixture) while the guide has maps, splitting and the weight window by
    split_lanes (photon's defaults: split 2, window 3); its training passes, which record, through
    the listed kernel too (its records). The images agree with the
    per-thread loop's in expectation (each render trains its own maps from its own seed: both
    estimate the same image without bias)."""
    scene = _scene("ajar", 32)
    kw = dict(spp=48, guide=guide, max_depth=6)
    a, b = _lanes_and_thread(scene, **kw)
    assert a.stats["lane_samples"] == a.stats["samples"] > 0
    # ajar's vertices are all of the diffuse class: the listed kernel shades them in the training
    # passes (and records them there), and in the final passes under the guide's maps; none goes to
    # the general kernel
    final = [p for p in a.stats["passes"] if p["kind"] == "final"]
    train = [p for p in a.stats["passes"] if p["kind"] != "final"]
    assert final and train
    assert a.stats["lane_general_vertices"] == 0
    assert all(p["lane_listed_vertices"] > 0 for p in train)
    assert a.stats["guide_stats"]["switched_off"] or all(p["lane_listed_vertices"] > 0 for p in final)
    if "split" in guide or guide.startswith("photon"):
        assert (a.stats["split_copies"] > 0) != a.stats["guide_stats"]["switched_off"]
    ma, va = image_mean(a)
    mb, vb = image_mean(b)
    assert_z(ma, va + vb, mb, what=f"{guide}: image mean, lanes against thread")



@pytest.mark.parametrize("name", ["ajar", "glossy"])
def test_lanes_record_what_the_wavefront_records(name):
    """One trained photon guide, fixed, and a recording pass of it on the lanes and on the
    wavefront (independent seeds): the share of records whose direction brought nothing back
    (radiance exactly 0; two-proportion z-test) and the mean radiance of a record (z-test, each
    side's variance from its records) agree. A record's radiance is the difference of its path's
    radiance at the end and at the vertex: kept in float32 lane rows, it came out tiny and positive
    where it should be 0, which the weight window took for a voxel's outgoing radiance (a share of
    zeros 0.4 points low on ajar, z 7.4; 3.4 points on glossy, z 52). ajar's vertices are the
    listed kernel's alone, glossy's both kernels'. Detects too a record credited to the wrong lane or vertex (its NEE or
    emission subtracted from another's), which moves the mean."""
    from tracer.film import Film
    from tracer.guiding import make_guide
    from tracer.render import make_context
    from tracer.session import trace_source
    from tracer.sources import CameraSource

    scene = _scene(name, 32)
    g = make_guide("photon", iterations=2)
    tracer.render(scene, spp=8, guide=g, max_depth=6, seed=3)
    out = {}
    for seed, loop in ((1, "lanes"), (2, "wave")):
        ctx = make_context(scene, seed=seed, max_depth=6)
        ctx.guide_state = g.state()
        ctx.path_loop = loop
        got = []
        st = trace_source(ctx, CameraSource(), Film(32, 32), spp=192, direct=g.records_direct(ctx),
                          observe=lambda rec: got.append(np.array(rec.radiance[rec.strategy >= 0], np.float64)))
        assert (st.lane_samples > 0) == (loop == "lanes")
        out[loop] = np.concatenate(got)
    a, b = out["lanes"], out["wave"]
    assert a.size > 50000 and b.size > 50000
    za, zb = (a == 0).mean(), (b == 0).mean()
    p = ((a == 0).sum() + (b == 0).sum()) / (a.size + b.size)
    assert 0.05 < p < 0.95
    assert_z(za, p * (1 - p) * (1 / a.size + 1 / b.size), zb, what=f"{name}: share of records with radiance 0")
    assert_z(a.mean(), a.var() / a.size + b.var() / b.size, b.mean(), what=f"{name}: mean record radiance")

def test_smooth_shading_on_the_fast_class(tmp_path):
    """A sphere of 80 triangles with corner normals: the fast class shades it in the interpolated
    normal's frame (no general vertex), and its image equals the per-thread loop's in expectation.
    Shading with the true normals instead makes the facets' brightness differ by up to ~20% between
    neighbours, which the block means see."""
    scene = _smooth_sphere_scene(tmp_path)
    assert scene.tri_vn.shape[0] > 0
    kw = dict(spp=96, max_depth=5)
    a, b = _lanes_and_thread(scene, **kw)
    assert a.stats["lane_general_vertices"] == 0 and a.stats["lane_samples"] == a.stats["samples"]
    _assert_same_image(a, b, "smooth sphere")
    a4, b4 = (tracer.render(scene, spp=4, seed=3, path_loop=loop, max_depth=2) for loop in ("lanes", "thread"))
    np.testing.assert_allclose(a4.aovs["normal"], b4.aovs["normal"], atol=2e-6)


def _texture_the_walls(scene):
    """`scene` (the Cornell box, changed in place and returned) with planar UVs that run negative
    and over several periods, and its diffuse materials' reflectance textured in turn by a 5 x 3
    bitmap of random texels (a width and height that are not powers of two: the wrap), a
    checkerboard and a constant."""
    from tracer.material import N_TEX_SLOTS, TEX_BITMAP, TEX_CHECKER, TEX_CONSTANT
    from tracer.textures import Textures

    tri = scene.tri
    scene.tri_uv = np.ascontiguousarray(0.9 * np.stack([tri[..., 0] - tri[..., 2], tri[..., 1] + tri[..., 2]], -1) - 0.7)
    w, h = 5, 3
    data = np.random.default_rng(7).uniform(0.05, 0.95, w * h * 3).astype(np.float32)
    info = np.zeros((3, 16))
    info[0, :10] = (TEX_BITMAP, 0, w, h, 1.3, 0.2, 0.1, -0.1, 1.1, 0.3)
    info[1, :16] = (TEX_CHECKER, 0, 0, 0, 3.0, 0, 0, 0, 3.0, 0, 0.8, 0.3, 0.2, 0.2, 0.6, 0.7)
    info[2, [0, 4, 8, 10, 11, 12]] = (TEX_CONSTANT, 1, 1, 0.3, 0.5, 0.7)
    scene.textures = Textures(info, data, ["bitmap", "checker", "constant"])
    mats = scene.materials
    mats.tex = np.full((len(mats.names), N_TEX_SLOTS), -1, np.int32)
    diffuse = [m for m in range(len(mats.names)) if mats.type[m] == 0 and not np.any(mats.emission[m] > 0)]
    for j, m in enumerate(diffuse):
        mats.tex[m, 0] = j % 3
    return scene


def test_textured_diffuse_on_the_fast_class():
    """The Cornell box with its walls' reflectance textured (_texture_the_walls): the fast class
    shades every vertex, its albedo AOV (the texture at the camera ray's hit, float32) equals the
    per-thread loop's (same seed, same camera rays) to float32 precision, and its image equals the
    per-thread loop's in expectation. A texel off by one, a flipped v, a lost UV offset or a wrong
    wrap changes many albedo pixels by far more than the tolerance."""
    scene = _texture_the_walls(_scene("cornell", 32))
    a = tracer.render(scene, spp=4, seed=3, path_loop="lanes", max_depth=3)
    b = tracer.render(scene, spp=4, seed=3, path_loop="thread", max_depth=3)
    assert a.stats["lane_general_vertices"] == 0 and a.stats["lane_samples"] == a.stats["samples"]
    assert np.ptp(b.aovs["albedo"]) > 0.3  # the textures vary over the image
    np.testing.assert_allclose(a.aovs["albedo"], b.aovs["albedo"], atol=2e-5)
    kw = dict(spp=64, max_depth=4)
    a, b = _lanes_and_thread(scene, **kw)
    _assert_same_image(a, b, "textured box")


GLOSSY = {  # material name -> (type, alpha) for _glossy_box
    "coats": {"white": ("COATED", 0.05), "red": ("COATED", 0.0)},
    "metals": {"white": ("METAL", 0.15), "red": ("METAL", 0.0)},
}


@pytest.mark.parametrize("guide", ["photon:iterations=2,switch_off=0", "ppg:iterations=2,window=0,switch_off=0",
                                   "grid:iterations=2,switch_off=0"])
def test_guided_vertices_of_every_class_on_the_lanes(guide):
    """The `glossy` scene (diffuse walls, rough and smooth metals, a mirror: the listed kernel's
    diffuse and glossy vertices and the general kernel's in one path) under a guide: its final
    passes on the lanes against the per-thread loop's, image and 6x6 block means (independent
    seeds, so independent maps: both estimate the image without bias whatever their maps). photon
    splits and plays the window (split_lanes reads the PathState the listed kernel keeps), ppg
    draws its roulette at the next vertex (GuideState.rr_late) against beta / gain and samples
    quadtrees, grid samples histograms. Checked by mutation: a guided direction weighted by the
    BSDF's density instead of the mixture's fails photon (image mean z 18.7) and grid (z 3.8), not
    ppg, whose learned weights guide little here. The guide's density left out of the light
    sample's MIS weight passes: NEE dominates on this scene's large light."""
    scene = _scene("glossy", 36)
    kw = dict(spp=64, guide=guide, max_depth=6)
    a, b = _lanes_and_thread(scene, **kw)
    assert not a.stats["guide_stats"]["switched_off"]
    assert a.stats["lane_listed_vertices"] > 0 and a.stats["lane_general_vertices"] > 0
    _assert_same_image(a, b, f"glossy under {guide}, lanes against thread", lit_share=0.5)


def _glossy_box(size, kind):
    """The Cornell box with its light grown to most of the ceiling, through scenes.textured
    (checkerboard reflectances, tilted corner normals), its white walls and red wall made the
    GLOSSY[kind] materials: coats (Mitsuba's plastic, index 2.5: a strong specular lobe, so that light
    samples and BSDF samples both find the light and their MIS weights matter; the rough one
    textured) or metals (gold's complex index; the rough one's specular reflectance textured)."""
    from tracer import bsdfs
    from tracer.material import TEX_SLOT_KD, TEX_SLOT_KS
    from tracer.scene import prepare_coats

    scene = _scene("cornell", size)
    mats = scene.materials
    lit = scene.tri_material == mats.names.index("light")
    c = scene.tri[lit].reshape(-1, 3).mean(axis=0)
    scene.tri[lit] = c + (scene.tri[lit] - c) * np.array([2.5, 1.0, 2.5])
    scene = textured(scene)
    for name, (kind_name, alpha) in GLOSSY[kind].items():
        m = mats.names.index(name)
        mats.type[m] = getattr(bsdfs, kind_name)
        mats.param[m, bsdfs.P_KS:bsdfs.P_KS + 3] = 1.0
        mats.param[m, bsdfs.P_ALPHA] = alpha
        if kind_name == "COATED":
            mats.param[m, bsdfs.P_IOR] = 2.5
        else:
            mats.param[m, bsdfs.P_ETA:bsdfs.P_ETA + 3] = (0.18, 0.42, 1.37)
            mats.param[m, bsdfs.P_K:bsdfs.P_K + 3] = (3.42, 2.35, 1.77)
            mats.tex[m, TEX_SLOT_KS] = mats.tex[m, TEX_SLOT_KD] if alpha > 0.0 else -1
            mats.tex[m, TEX_SLOT_KD] = -1
    prepare_coats(mats, scene.textures)
    return scene


@pytest.mark.parametrize("kind", ["coats", "metals"])
def test_glossy_materials_on_their_own_kernel(kind):
    """_glossy_box: the glossy kernel shades the COATED or METAL vertices, the fast kernel the rest,
    none goes to the general kernel; with the same seed the AOV albedo equals the per-thread loop's
    (a metal's: its colour times its Fresnel at normal incidence; behind a smooth metal, a delta
    BSDF, the next vertex's), and the image equals the per-thread loop's in
    expectation. It detects the light sample's MIS weight left out (+6% on the coats' image, +5%
    on the metals'), a mirror bounce not flagged delta (its emission then MIS-weighted against a
    light sample that cannot find it: -3%, -10%), or the colour left untextured (the coats' image,
    the metals' AOV); not the light-leak rule dropped (the normals' tilts of ~10 degrees leave too
    few such directions)."""
    scene = _glossy_box(32, kind)
    a = tracer.render(scene, spp=4, seed=3, path_loop="lanes", max_depth=3)
    b = tracer.render(scene, spp=4, seed=3, path_loop="thread", max_depth=3)
    np.testing.assert_allclose(a.aovs["albedo"], b.aovs["albedo"], rtol=2e-5, atol=2e-6)
    kw = dict(spp=96, max_depth=6)
    a, b = _lanes_and_thread(scene, **kw)
    assert a.stats["lane_samples"] == a.stats["samples"]
    assert a.stats["lane_general_vertices"] == 0 and a.stats["lane_listed_vertices"] > 0
    _assert_same_image(a, b, f"glossy box ({kind})")


def test_lanes_aovs_are_the_first_hits():
    """With the same seed the camera rays are the same on both loops, so the AOVs are equal to the
    lanes' float32: the reflectance as stored, the normal and distance of Embree's hit (no float64
    refinement on the lanes). A hit on another triangle changes some albedo by far more."""
    scene = _scene("cornell", 32)
    a = tracer.render(scene, spp=4, seed=3, path_loop="lanes", max_depth=3)
    b = tracer.render(scene, spp=4, seed=3, path_loop="thread", max_depth=3)
    np.testing.assert_allclose(a.aovs["albedo"], b.aovs["albedo"], rtol=1e-6)
    np.testing.assert_allclose(a.aovs["normal"], b.aovs["normal"], atol=1e-6)
    np.testing.assert_allclose(a.aovs["depth"], b.aovs["depth"], rtol=1e-4)


def test_a_render_the_lanes_cannot_take_runs_on_the_other_loops(caplog):
    """The Numba BVH (the lanes trace through Embree): one warning names the gap, and the image is
    the wavefront's bit for bit."""
    scene = _scene("cornell", 24)
    with caplog.at_level(logging.WARNING, logger="tracer"):
        a = tracer.render(scene, spp=2, path_loop="lanes", max_depth=3, accel="numba")
    b = tracer.render(scene, spp=2, path_loop="wave", max_depth=3, accel="numba")
    gaps = [r.getMessage() for r in caplog.records if "path_loop lanes" in r.getMessage()]
    assert len(gaps) == 1 and "numba accel" in gaps[0], gaps
    assert a.stats["lane_samples"] == 0
    np.testing.assert_array_equal(a.image, b.image)


def test_alias_table_keeps_the_distribution():
    """Column j keeps itself with prob[j] and else gives its alias: each outcome's total over the
    uniform column choice is its probability, to rounding (written out here, not sampled)."""
    rng = np.random.default_rng(5)
    for n in (1, 2, 7, 300):
        p = rng.random(n) ** 3
        p /= p.sum()
        prob, alias = alias_table(p)
        got = np.zeros(n)
        np.add.at(got, np.arange(n), prob / n)
        np.add.at(got, alias, (1.0 - prob) / n)
        np.testing.assert_allclose(got, p, rtol=1e-9, atol=1e-15)
        assert np.all((prob >= 0.0) & (prob <= 1.0 + 1e-12))
