"""The material at the hit (tracer.material): textures, UVs, shading normals, and MTL's maps.

Checked against what the test computes itself: the texture image decoded from sRGB and filtered
bilinearly with NumPy, the analytic normal field of a sphere, the glTF meaning of the PBR
statements."""
import importlib
import json
import math

import numpy as np
import pytest
from numba import njit

import tracer
from tracer import bsdfs
from tracer.camera import camera_ray
from tracer.material import SURFACE_COLS, costly_surfaces, keep_surface, kept_surface, surface_at

W = H = 16


def _write_png(path, rgb8):
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(rgb8.shape[1], rgb8.shape[0], 3, "uint8")
    assert out.open(str(path), spec)
    out.write_image(rgb8)
    out.close()


def _srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _bilinear_repeat(img, u, v):
    """The texture lookup written out here: texel centres at (i + 1/2) / size, rows from the top,
    v upward, wrapping."""
    h, w, _ = img.shape
    x = u * w - 0.5
    y = (1.0 - v) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    x0, y0 = x0.astype(int) % w, y0.astype(int) % h
    x1, y1 = (x0 + 1) % w, (y0 + 1) % h
    return ((1 - fy) * ((1 - fx) * img[y0, x0] + fx * img[y0, x1]) + fy * ((1 - fx) * img[y1, x0] + fx * img[y1, x1]))


def _textured_quad(tmp_path, map_line, image):
    _write_png(tmp_path / "tex.png", image)
    obj = ["mtllib q.mtl", "usemtl tex", "v -1 -1 0", "v 1 -1 0", "v 1 1 0", "v -1 1 0",
           "vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1", "f 1/1 2/2 3/3 4/4"]
    (tmp_path / "q.obj").write_text("\n".join(obj) + "\n")
    (tmp_path / "q.mtl").write_text(f"newmtl tex\n{map_line}\n")
    (tmp_path / "q.json").write_text(json.dumps({
        "camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 30},
        "film": {"width": W, "height": H}, "environment": {"radiance": [1, 1, 1]}}))
    return str(tmp_path / "q.obj")


def _pixel_uv(scene):
    """(u, v) where each pixel centre's camera ray meets the quad z = 0 spanning [-1, 1]^2."""
    cam = scene.camera.packed()
    uv = np.empty((H, W, 2))
    for py in range(H):
        for px in range(W):
            o, d = camera_ray(cam, W, H, px, py, 0.5, 0.5)
            t = -o[2] / d[2]
            uv[py, px] = ((o[0] + t * d[0] + 1) / 2, (o[1] + t * d[1] + 1) / 2)
    return uv


@pytest.mark.parametrize("map_line,scale", [("map_Kd tex.png", (1, 1)), ("map_Kd -s 2 3 1 -o 0.25 0 tex.png", (2, 3))])
def test_textured_quad_under_a_constant_sky(tmp_path, map_line, scale):
    """A diffuse quad whose Kd is an 8 x 8 sRGB PNG, under a sky of radiance 1, direct light only:
    each pixel (point filter) is the texture's linear value at its UV, here decoded from sRGB and
    filtered bilinearly with repeat by NumPy (with the map's -s/-o). z-test of every pixel against
    the render's own variance, |z| < 5 over 768 channel values, and chi-square of their mean
    square; detects a texture read without sRGB decoding (2x off in the mid-tones), flipped v, a
    texel offset of half a texel, nearest instead of bilinear filtering, an ignored scale or
    offset."""
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, size=(8, 8, 3), dtype=np.uint8)
    scene = tracer.load_scene(_textured_quad(tmp_path, map_line, image))
    assert scene.textures.info.shape[0] == 1 and scene.tri_uv.shape == (2, 3, 2)
    r = tracer.render(scene, spp=256, max_depth=2, seed=1, pixel_filter="point")
    assert r.stats["nonfinite_samples"] == 0
    uv = _pixel_uv(scene)
    u = scale[0] * uv[..., 0] + (0.25 if scale[0] == 2 else 0.0)
    v = scale[1] * uv[..., 1]
    ref = _bilinear_repeat(_srgb_to_linear(image / 255.0), u, v)
    z = (r.image - ref) / np.sqrt(np.maximum(r.variance, 1e-12))  # variance of the mean
    assert np.abs(z).max() < 5.0, np.abs(z).max()
    assert abs(np.mean(z ** 2) - 1.0) < 5 * math.sqrt(2.0 / z.size)
    # the albedo AOV is the textured albedo
    np.testing.assert_allclose(r.aovs["albedo"], ref, rtol=1e-5, atol=1e-6)
    # the stats count the texture's memory: 8 x 8 RGB float32 texels and one info row
    assert r.stats["texture_memory_bytes"] == 8 * 8 * 3 * 4 + scene.textures.info.nbytes


def _sphere(n_theta, n_phi, radius=1.0):
    """Vertices on the unit sphere (UV tessellation) and its triangles, counter-clockwise outside."""
    verts = [(0.0, radius, 0.0)]
    for i in range(1, n_theta):
        th = math.pi * i / n_theta
        for j in range(n_phi):
            ph = 2 * math.pi * j / n_phi
            verts.append((radius * math.sin(th) * math.cos(ph), radius * math.cos(th), -radius * math.sin(th) * math.sin(ph)))
    verts.append((0.0, -radius, 0.0))
    ring = lambda i, j: 1 + (i - 1) * n_phi + j % n_phi  # noqa: E731
    faces = [(0, ring(1, j), ring(1, j + 1)) for j in range(n_phi)]
    for i in range(1, n_theta - 1):
        for j in range(n_phi):
            faces += [(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)), (ring(i, j), ring(i + 1, j + 1), ring(i, j + 1))]
    last = len(verts) - 1
    faces += [(ring(n_theta - 1, j), last, ring(n_theta - 1, j + 1)) for j in range(n_phi)]
    return np.array(verts), np.array(faces)


def _sphere_scene(tmp_path, smooth):
    v, f = _sphere(24, 48)
    lines = ["mtllib s.mtl", "usemtl white"] + ["v %.17g %.17g %.17g" % tuple(p) for p in v]
    if smooth:
        lines += ["vn %.17g %.17g %.17g" % tuple(p) for p in v]
        lines += ["f " + " ".join(f"{i + 1}//{i + 1}" for i in tri) for tri in f]
    else:
        lines += ["f " + " ".join(str(i + 1) for i in tri) for tri in f]
    (tmp_path / "s.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "s.mtl").write_text("newmtl white\nKd 0.5 0.5 0.5\n")
    (tmp_path / "s.json").write_text(json.dumps({
        "camera": {"origin": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 35},
        "film": {"width": 48, "height": 48}, "environment": {"radiance": [1, 1, 1]}}))
    return tracer.load_scene(str(tmp_path / "s.obj"))


def _analytic_normals(scene, w, h):
    """The unit sphere's normal where each pixel centre's ray meets it (NaN: a miss)."""
    cam = scene.camera.packed()
    out = np.full((h, w, 3), np.nan)
    for py in range(h):
        for px in range(w):
            o, d = map(np.array, camera_ray(cam, w, h, px, py, 0.5, 0.5))
            b = o @ d
            disc = b * b - (o @ o - 1.0)
            if disc > 0:
                out[py, px] = o + (-b - math.sqrt(disc)) * d
    return out


def test_smooth_shading_follows_the_sphere_normal_field(tmp_path):
    """A 24 x 48 tessellated unit sphere with its exact vertex normals: the normal AOV at each
    pixel centre (point filter) is the interpolated normal, within the tessellation's O(h^2)
    error of the analytic normal where the ray meets the true sphere (pixels well inside the
    silhouette), while the flat-shaded sphere is off by the O(h) facet angle. Detects vertex
    normals ignored or read from the wrong corner (errors of the facet size or larger)."""
    ang = {}
    for smooth in (False, True):
        scene = _sphere_scene(tmp_path, smooth)
        assert (scene.tri_vn.shape[0] > 0) == smooth
        r = tracer.render(scene, spp=1, max_depth=1, seed=0, pixel_filter="point")
        ref = _analytic_normals(scene, 48, 48)
        n = r.aovs["normal"]
        inside = np.isfinite(ref[..., 0]) & (ref[..., 2] > 0.5)
        cosang = np.clip(np.sum(n[inside] * ref[inside], axis=1), -1, 1)
        ang[smooth] = np.degrees(np.arccos(cosang))
    h = 180.0 / 24  # the tessellation's step in degrees
    assert ang[False].mean() > 0.15 * h  # flat facets: a good share of the step
    assert ang[True].max() < 0.1 * h and ang[True].mean() < 0.25 * ang[False].mean()


def _one_material(tmp_path, body):
    from tracer.readers.obj import material_from_mtl, parse_mtl

    (tmp_path / "m.mtl").write_text("newmtl m\n" + body + "\n")
    warnings, textures = [], []
    st = parse_mtl(str(tmp_path / "m.mtl"), warnings)["m"]
    return material_from_mtl("m", st, "m.obj", warnings, textures), warnings, textures


def test_pbr_statements_mean_what_gltf_means():
    """Blender's gold (illum 3, Kd base colour, Pm 1, Pr 0.2): a conductor with F0 = Kd and alpha
    = Pr^2, not a grey mirror; the built-in scenes' metals (black Kd, F0 in Ks) keep F0 = Ks; Pr
    without Pm: a plastic with F0 from Ni and alpha = Pr^2."""
    import pathlib
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        d = pathlib.Path(d)
        (t, p, e, tex), w, _ = _one_material(d, "Kd 1 0.77 0.34\nKs 0.5 0.5 0.5\nPm 1\nPr 0.2\nillum 3")
        assert t == bsdfs.CONDUCTOR and np.allclose(p[3:6], [1, 0.77, 0.34]) and np.isclose(p[6], 0.04)
        assert tex == (-1,) * len(tex) and not w
        (t, p, e, tex), w, _ = _one_material(d, "Kd 0 0 0\nKs 0.9 0.9 0.9\nPr 0.5\nPm 1\nillum 2")
        assert t == bsdfs.CONDUCTOR and np.allclose(p[3:6], 0.9) and np.isclose(p[6], 0.25)
        (t, p, e, tex), w, _ = _one_material(d, "Kd 0.2 0.4 0.6\nKs 0.5 0.5 0.5\nPr 0.3\nNi 1.5\nillum 2")
        assert t == bsdfs.PLASTIC and np.allclose(p[:3], [0.2, 0.4, 0.6]) and np.allclose(p[3:6], 0.04)
        assert np.isclose(p[6], 0.09)


def test_a_missing_texture_is_a_warning_with_its_fallback(tmp_path):
    """map_Kd naming a file that does not exist: one warning naming the file and the constant used
    (Kd), and the render reads that constant (albedo AOV)."""
    obj = _textured_quad(tmp_path, "Kd 0.25 0.5 0.75\nmap_Kd missing.png", np.zeros((2, 2, 3), np.uint8))
    scene = tracer.load_scene(obj)
    msgs = [m for m in scene.warnings if "missing.png" in m]
    assert len(msgs) == 1 and "0.25, 0.5, 0.75" in msgs[0]
    r = tracer.render(scene, spp=1, max_depth=1, seed=0, pixel_filter="point")
    np.testing.assert_allclose(r.aovs["albedo"], np.broadcast_to([0.25, 0.5, 0.75], (H, W, 3)))


def test_sidecar_makes_a_named_metal(tmp_path):
    """materials.NAME {type metal, metal Au, one_sided}: the table row holds Au's complex index from
    tracer.metals and the ONE_SIDED flag; an unknown metal is one error listing the names."""
    from tracer.errors import SceneError
    from tracer.metals import METALS

    obj = _textured_quad(tmp_path, "Kd 0.5 0.5 0.5", np.zeros((2, 2, 3), np.uint8))
    side = json.loads((tmp_path / "q.json").read_text())
    side["materials"] = {"tex": {"type": "metal", "metal": "Au", "alpha": 0.1, "one_sided": True}}
    (tmp_path / "q.json").write_text(json.dumps(side))
    scene = tracer.load_scene(obj)
    row = scene.materials.param[scene.materials.names.index("tex")]
    assert scene.materials.type[scene.materials.names.index("tex")] == bsdfs.METAL
    np.testing.assert_array_equal(row[8:11], METALS["Au"][0])
    np.testing.assert_array_equal(row[11:14], METALS["Au"][1])
    assert int(row[14]) & bsdfs.ONE_SIDED and row[6] == 0.1
    side["materials"]["tex"]["metal"] = "Unobtainium"
    (tmp_path / "q.json").write_text(json.dumps(side))
    with pytest.raises(SceneError, match="Unobtainium.*valid: .*Au"):
        tracer.load_scene(obj)


def _bilinear_grad(img, u, v):
    """(d/du, d/dv) of the bilinear lookup of the grey image img (H, W) at (u, v), written out here:
    the derivative within the texel cell, times the texels per unit of u (and minus those of v:
    rows run down the image while v runs up)."""
    h, w = img.shape
    x = u * w - 0.5
    y = (1.0 - v) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0, y0 = x0.astype(int) % w, y0.astype(int) % h
    x1, y1 = (x0 + 1) % w, (y0 + 1) % h
    a, b, c, d = img[y0, x0], img[y0, x1], img[y1, x0], img[y1, x1]
    return ((1 - fy) * (b - a) + fy * (d - c)) * w, -((1 - fx) * (c - a) + fx * (d - b)) * h


def test_bump_map_tilts_the_normal_as_mitsubas_bumpmap(tmp_path):
    """`bump -bm 0.05 h.png` on the quad: the normal AOV at each pixel centre is Mitsuba's bumpmap
    normal, cross(dp/du + n (s h_u), dp/dv + n (s h_v)) normalised, with the height's gradient
    (h_u, h_v) from the NumPy bilinear derivative of the sRGB-decoded image and dp/du = (2, 0, 0),
    dp/dv = (0, 2, 0) for this quad. Detects a gradient off by the texel count, a flipped v, a
    missing scale, or a bump that is not applied."""
    rng = np.random.default_rng(4)
    grey = rng.integers(0, 256, size=(8, 8), dtype=np.uint8)
    obj = _textured_quad(tmp_path, "Kd 0.5 0.5 0.5\nbump -bm 0.05 h.png", np.zeros((2, 2, 3), np.uint8))
    _write_png(tmp_path / "h.png", np.repeat(grey[:, :, None], 3, axis=2))
    scene = tracer.load_scene(obj)
    assert not [w for w in scene.warnings if "bump" in w]
    r = tracer.render(scene, spp=1, max_depth=1, seed=0, pixel_filter="point")
    uv = _pixel_uv(scene)
    gu, gv = _bilinear_grad(_srgb_to_linear(grey / 255.0), uv[..., 0], uv[..., 1])
    a = np.stack([np.full_like(gu, 2.0), np.zeros_like(gu), 0.05 * gu], axis=-1)
    b = np.stack([np.zeros_like(gv), np.full_like(gv, 2.0), 0.05 * gv], axis=-1)
    n = np.cross(a, b)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    assert np.degrees(np.arccos(np.clip(n[..., 2], -1, 1))).max() > 5.0  # the bump tilts it noticeably
    np.testing.assert_allclose(r.aovs["normal"], n, atol=2e-5)


def test_bump_map_without_uvs_is_a_warning(tmp_path):
    """A bump map on faces without vt: one warning naming the OBJ and the material; the scene
    renders flat."""
    (tmp_path / "q.obj").write_text("mtllib q.mtl\nusemtl b\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nf 1 2 3\n")
    (tmp_path / "q.mtl").write_text("newmtl b\nKd 0.5 0.5 0.5\nbump h.png\n")
    _write_png(tmp_path / "h.png", np.zeros((2, 2, 3), np.uint8))
    (tmp_path / "q.json").write_text(json.dumps({"environment": {"radiance": [1, 1, 1]}}))
    scene = tracer.load_scene(str(tmp_path / "q.obj"))
    msgs = [w for w in scene.warnings if "bump" in w]
    assert len(msgs) == 1 and "q.obj" in msgs[0] and "'b'" in msgs[0]


def test_a_see_through_material_names_the_sidecar_fix():
    """`d 0.4` on an illum 2 material (how exporters write glass they cannot describe): rendered
    with opacity 0.4 (`Tr` is 1 - d), and one warning naming materials.NAME.type; `d 1` (every
    Blender material) says nothing."""
    import pathlib
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        d = pathlib.Path(d)
        (t, p, _, _), w, _ = _one_material(d, "Kd 0.8 0.8 0.8\nNi 1.45\nd 0.4\nillum 2")
        assert t == bsdfs.DIFFUSE and len(w) == 1 and 'materials.m.type to "dielectric"' in w[0] and "d 0.4" in w[0]
        assert p[bsdfs.P_CLEAR] == pytest.approx(0.6)  # rendered with opacity 0.4
        (t, p, _, _), w, _ = _one_material(d, "Kd 0.8 0.8 0.8\nTr 0.25")
        assert p[bsdfs.P_CLEAR] == pytest.approx(0.25)
        (t, _, _, _), w, _ = _one_material(d, "Kd 0.8 0.8 0.8\nNi 1.45\nd 1.0\nillum 2")
        assert not w


@pytest.mark.parametrize("mtl,sky", [("Kd 0 0 0\nmap_d op.png", 1.0), ("Kd 0 0 0\nd 0.3", 1.0),
                                     ("Kd 0.5 0.5 0.5\nd 0.3", 0.0)])
def test_opacity_lets_the_sky_through(tmp_path, mtl, sky):
    """A quad with an opacity (MTL map_d: an 8 x 8 grey sRGB PNG, or d 0.3) in front of the
    camera. Black (Kd 0) under a sky of radiance 1: each pixel (point filter) is 1 - opacity,
    the opacity decoded from sRGB and filtered bilinearly by NumPy here. Kd 0.5 lit by a one-sided
    lamp behind the camera facing it, no sky: the quad reflects opacity x Kd / pi x the lamp's
    irradiance (the same test through the BSDF part). z-test of every pixel and a chi-square of
    their mean square; detects an opacity inverted, ignored, read without decoding, or applied to
    the wrong share. (Under the sky each sample is 0 or 1: the test uses the binomial variance.)"""
    rng = np.random.default_rng(8)
    grey = rng.integers(0, 256, size=(8, 8, 1), dtype=np.uint8)
    _write_png(tmp_path / "op.png", np.repeat(grey, 3, axis=2))
    obj = ["mtllib q.mtl", "usemtl tex", "v -1 -1 0", "v 1 -1 0", "v 1 1 0", "v -1 1 0",
           "vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1", "f 1/1 2/2 3/3 4/4"]
    side = {"camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 30},
            "film": {"width": W, "height": H}}
    if sky:
        side["environment"] = {"radiance": [sky] * 3}
    else:  # a large lamp at z = 20 facing -z (toward the quad); the camera sits in front of it
        obj += ["usemtl lamp", "v -40 -40 20", "v 40 -40 20", "v 40 40 20", "v -40 40 20", "f 5 7 6", "f 5 8 7"]
    (tmp_path / "q.obj").write_text("\n".join(obj) + "\n")
    (tmp_path / "q.mtl").write_text(f"newmtl tex\n{mtl}\nnewmtl lamp\nKd 0 0 0\nKe 1 1 1\n")
    (tmp_path / "q.json").write_text(json.dumps(side))
    scene = tracer.load_scene(str(tmp_path / "q.obj"))
    r = tracer.render(scene, spp=256, max_depth=3, seed=2, pixel_filter="point")
    assert r.stats["nonfinite_samples"] == 0
    if "map_d" in mtl:
        uv = _pixel_uv(scene)
        op = _bilinear_repeat(_srgb_to_linear(np.repeat(grey, 3, axis=2) / 255.0), uv[..., 0], uv[..., 1])
    else:
        op = np.full((H, W, 3), 0.3)
    var = r.variance
    if sky:
        ref = 1.0 - op
        var = np.maximum(op * (1.0 - op) / 256, 1e-12)  # each sample passes (1) or not (0): binomial
    else:
        # irradiance at the quad's centre region from the 80 x 80 lamp 20 away, per pixel's point
        x = (_pixel_uv(scene) * 2.0 - 1.0)
        e = np.zeros((H, W))
        g = (np.arange(400) + 0.5) / 400 * 80 - 40  # midpoint rule over the lamp
        lx, ly = np.meshgrid(g, g)
        for py in range(H):
            for px in range(W):
                dx, dy = lx - x[py, px, 0], ly - x[py, px, 1]
                d2 = dx * dx + dy * dy + 400.0
                e[py, px] = np.sum(400.0 / (d2 * d2)) * (80 / 400) ** 2
        ref = op * 0.5 / np.pi * e[..., None]
    z = (r.image - ref) / np.sqrt(var)
    assert np.abs(z).max() < 5.0, np.abs(z).max()
    assert abs(np.mean(z ** 2) - 1.0) < 5 * math.sqrt(2.0 / z.size)


def test_sidecar_makes_a_coated_material_and_glass_drops_opacity(tmp_path):
    """materials.NAME {type coated, alpha, ior, nonlinear, opacity}: a COATED row with the flag,
    1 - opacity in P_CLEAR and its table and sampling weight filled at build; `type: dielectric` on
    a material with `d 0.4` (the sidecar fix the warning names) drops the opacity; opacity outside
    [0, 1] is one error."""
    from tracer.errors import SceneError

    obj = _textured_quad(tmp_path, "Kd 0.5 0.5 0.5\nd 0.4", np.zeros((2, 2, 3), np.uint8))
    side = json.loads((tmp_path / "q.json").read_text())
    side["materials"] = {"tex": {"type": "coated", "alpha": 0.1, "ior": 1.5, "nonlinear": True, "opacity": 0.8}}
    (tmp_path / "q.json").write_text(json.dumps(side))
    m = tracer.load_scene(obj).materials
    k = m.names.index("tex")
    assert m.type[k] == bsdfs.COATED and int(m.param[k, 14]) & bsdfs.NONLINEAR
    assert m.param[k, bsdfs.P_CLEAR] == pytest.approx(0.2) and m.param[k, bsdfs.P_SPEC_WEIGHT] > 0
    assert np.all(m.table[k] > 0)
    side["materials"] = {"tex": {"type": "dielectric", "ior": 1.5}}
    (tmp_path / "q.json").write_text(json.dumps(side))
    m = tracer.load_scene(obj).materials
    assert m.param[m.names.index("tex"), bsdfs.P_CLEAR] == 0.0
    side["materials"] = {"tex": {"opacity": 1.5}}
    (tmp_path / "q.json").write_text(json.dumps(side))
    with pytest.raises(SceneError, match="opacity must be in"):
        tracer.load_scene(obj)


@njit(cache=True)
def _kept_and_evaluated(surf, p, b1, b2):
    """Per point: surface_at's Surface and the one keep_surface / kept_surface give back, flat."""
    n = p.shape[0]
    rows = np.zeros((n, SURFACE_COLS))
    out = np.zeros((2, n, 30))
    for k in range(n):
        sf = surface_at(surf, p[k], b1[k], b2[k])
        keep_surface(rows, k, sf)
        for j, s in enumerate((sf, kept_surface(surf, rows, k, p[k]))):
            out[j, k, 0] = s.bp[0]
            for c in range(17):
                out[j, k, 1 + c] = s.bp[1][c]
            for c in range(3):
                out[j, k, 18 + c] = s.ns[c]
                out[j, k, 21 + c] = s.s[c]
                out[j, k, 24 + c] = s.t[c]
            out[j, k, 27] = s.uv[0]
            out[j, k, 28] = s.uv[1]
            out[j, k, 29] = 1.0 if s.smooth else 0.0
    return out


def test_a_kept_surface_is_the_evaluated_one_bit_for_bit(tmp_path):
    """keep_surface / kept_surface (what gpt's offsets keep from one bounce to the next instead of
    evaluating a Surface twice) against surface_at itself, at 64 random points of a quad with a
    diffuse texture, a bump map, an opacity map and tilted vertex normals, and of an untextured
    plastic: every field equal bit for bit. The textured fields vary over the points, so a kept
    surface that fell back to the material's table row, dropped the bump, the clearness or the
    smooth flag, or rebuilt a frame other than surface_at's would fail."""
    rng = np.random.default_rng(5)
    _write_png(tmp_path / "tex.png", rng.integers(0, 256, size=(8, 8, 3), dtype=np.uint8))
    obj = ["mtllib q.mtl", "v -1 -1 0", "v 1 -1 0", "v 1 1 0", "v -1 1 0",
           "vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1", "vn 0.3 0 1", "vn 0 0.4 1", "vn -0.2 -0.1 1", "vn 0.1 0.2 1",
           "usemtl tex", "f 1/1/1 2/2/2 3/3/3", "usemtl glossy", "f 1/1/1 3/3/3 4/4/4"]
    (tmp_path / "q.obj").write_text("\n".join(obj) + "\n")
    (tmp_path / "q.mtl").write_text("newmtl tex\nKd 0.5 0.5 0.5\nmap_Kd tex.png\nbump -bm 0.05 tex.png\n"
                                    "map_d tex.png\nnewmtl glossy\nKd 0.3 0.2 0.1\nKs 0.4 0.4 0.4\nNs 200\n")
    (tmp_path / "q.json").write_text(json.dumps({
        "camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 30},
        "film": {"width": W, "height": H}, "environment": {"radiance": [1, 1, 1]}}))
    scene = tracer.load_scene(str(tmp_path / "q.obj"))
    surf = importlib.import_module("tracer.render").make_context(scene).surfaces
    assert costly_surfaces(surf)
    n = 64
    p = np.arange(n) % 2
    b1, b2 = rng.random(n), rng.random(n)
    flip = b1 + b2 > 1.0
    b1[flip], b2[flip] = 1.0 - b1[flip], 1.0 - b2[flip]
    evaluated, kept = _kept_and_evaluated(surf, p, b1, b2)
    assert np.array_equal(evaluated, kept)
    tex = evaluated[surf.mat_tex[surf.material[p], 0] >= 0]
    assert len(tex) == n // 2
    for col in (1, 16 + 1, 18, 21):  # kd, clearness, the bumped normal and its frame vary over the quad
        assert np.ptp(tex[:, col]) > 1e-3, col
    assert evaluated[:, 29].all()  # smooth: vertex normals
