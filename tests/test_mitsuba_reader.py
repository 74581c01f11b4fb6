"""The Mitsuba scene XML reader (tracer.readers.mitsuba), on a small scene written here and on the
real Veach Ajar of ../shared/scenes-mitsuba (skipped without it). Where Mitsuba 3 can read the same
file, it is the oracle for the shapes' world-space vertices and the camera's rays."""
import os

import numpy as np
import pytest

import tracer
from tracer import bsdfs
from tracer.metals import METALS

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
AJAR = os.path.join(ROOT, "..", "shared", "scenes-mitsuba", "veach-ajar", "scene.xml")

SCENE = """<scene version="3.0.0">
    <default name="spp" value="8"/>
    <default name="res" value="24"/>
    <integrator type="path"><integer name="max_depth" value="6"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 1, 5" target="0, 0.5, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="16"/>
            <rfilter type="gaussian"/></film>
    </sensor>
    <bsdf type="twosided" id="Wood">
        <bsdf type="diffuse">
            <texture name="reflectance" type="bitmap"><string name="filename" value="wood.png"/></texture>
        </bsdf>
    </bsdf>
    <bsdf type="roughconductor" id="Gold">
        <string name="material" value="Au"/><float name="alpha" value="0.2"/>
        <string name="distribution" value="ggx"/>
        <texture name="specular_reflectance" type="checkerboard">
            <rgb name="color0" value="0.9, 0.9, 0.9"/><rgb name="color1" value="0.1, 0.1, 0.1"/>
            <transform name="to_uv"><scale x="4" y="2"/></transform>
        </texture>
    </bsdf>
    <shape type="obj">
        <string name="filename" value="box.obj"/>
        <transform name="to_world"><scale value="0.5"/><rotate y="1" angle="30"/><translate x="0.2" y="0.1"/></transform>
        <ref id="Wood"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="-90"/><scale value="3"/></transform>
        <ref id="Gold"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="90"/><translate y="3"/></transform>
        <emitter type="area"><rgb name="radiance" value="5, 5, 5"/></emitter>
    </shape>
    <emitter type="constant"/>
</scene>
"""


def _write(tmp_path):
    import OpenImageIO as oiio

    from tests.scenes import box_faces

    v, f = box_faces((-1, 0, -1), (1, 2, 1), inward=False)
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in v] + [f"vt {0.1 * k:.3g} {0.05 * k:.3g}" for k in range(8)]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in f]
    (tmp_path / "box.obj").write_text("\n".join(lines) + "\n")
    out = oiio.ImageOutput.create(str(tmp_path / "wood.png"))
    out.open(str(tmp_path / "wood.png"), oiio.ImageSpec(4, 4, 3, "uint8"))
    out.write_image(np.random.default_rng(0).integers(0, 256, (4, 4, 3), dtype=np.uint8))
    out.close()
    (tmp_path / "scene.xml").write_text(SCENE)
    return str(tmp_path / "scene.xml")


def test_reads_the_subset_and_names_what_it_leaves(tmp_path):
    """$-substitution from <default>, the integrator's max_depth, the sampler's spp, the film, a
    twosided diffuse with a bitmap, a one-sided named-metal roughconductor with a checkerboard
    (to_uv scale), an area light on a rectangle, the constant emitter as the environment; the gaussian
    rfilter is one warning naming its line."""
    scene = tracer.load_scene(_write(tmp_path))
    assert (scene.width, scene.height, scene.render.spp, scene.render.max_depth) == (24, 16, 8, 6)
    m = scene.materials
    wood, gold = m.names.index("Wood"), m.names.index("Gold")
    assert m.type[wood] == bsdfs.DIFFUSE and not int(m.param[wood, 14]) & bsdfs.ONE_SIDED and m.tex[wood, 0] >= 0
    assert m.type[gold] == bsdfs.METAL and int(m.param[gold, 14]) & bsdfs.ONE_SIDED and m.param[gold, 6] == 0.2
    np.testing.assert_array_equal(m.param[gold, 8:11], METALS["Au"][0])
    assert m.tex[gold, 1] >= 0 and scene.textures.info[m.tex[gold, 1], 0] == 2  # a checkerboard
    assert scene.emissive.sum() == 2 and scene.tri_uv.shape == (scene.n_triangles, 3, 2)
    lines = SCENE.splitlines()
    assert np.allclose(scene.environment.radiance, 1.0)  # <emitter type="constant"/>: Mitsuba's default 1
    for what in ("rfilter 'gaussian'",):
        hit = [w for w in scene.warnings if what in w]
        assert len(hit) == 1, (what, scene.warnings)
        line = int(hit[0].split(":")[1])
        assert what.split()[0].strip("<>'") in lines[line - 1]
    r = tracer.render(scene, spp=4, seed=1)
    assert r.stats["nonfinite_samples"] == 0 and r.image.mean() > 0


def test_shapes_and_camera_match_mitsuba(tmp_path):
    """Mitsuba 3 loads the same file: the OBJ's world-space vertices after the chained transform
    (scale, rotate, translate) and the rectangles' corners equal ours (as point sets, to float32
    precision), and the camera ray through the image centre agrees in direction (detects a chain
    applied in the wrong order, a lookat with a mirrored axis, a rectangle of the wrong size)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    path = _write(tmp_path)
    ours = tracer.load_scene(path)
    ref = mi.load_file(path)
    pts = []
    for shape in ref.shapes():
        params = mi.traverse(shape)
        if "vertex_positions" in params.keys():
            pts.append(np.array(params["vertex_positions"]).reshape(-1, 3))
        else:  # Mitsuba's rectangle: the corners (+-1, +-1, 0) under its to_world
            m = np.array(params["to_world"].matrix)
            corners = np.array([[-1, -1, 0, 1], [1, -1, 0, 1], [1, 1, 0, 1], [-1, 1, 0, 1]], float)
            pts.append((corners @ m.T)[:, :3])
    pts = np.concatenate(pts)
    mine = np.unique(np.round(ours.tri.reshape(-1, 3), 4), axis=0)
    theirs = np.unique(np.round(pts, 4), axis=0)
    assert mine.shape == theirs.shape and np.allclose(mine, theirs, atol=2e-4)
    ray, _ = ref.sensors()[0].sample_ray(0.0, 0.5, mi.Point2f(0.5, 0.5), mi.Point2f(0.5, 0.5))
    np.testing.assert_allclose(ours.camera.forward, np.array(ray.d), atol=1e-5)


@pytest.mark.skipif(not os.path.isfile(AJAR), reason="../shared/scenes-mitsuba not present")
def test_the_textured_veach_ajar_renders():
    """The real Veach Ajar (Mitsuba 3 dialect): its three bitmaps and the floor's checkerboard are
    read, the door handle is a Beckmann METAL, the only warning is the tent filter's, and a small
    render is finite and lit."""
    scene = tracer.load_scene(AJAR, width=64, height=36)
    kinds = sorted(int(k) for k in scene.textures.info[:, 0])
    assert kinds.count(1) == 3 and kinds.count(2) == 1
    handle = scene.materials.names.index("DoorHandleBSDF")
    assert scene.materials.type[handle] == bsdfs.METAL and int(scene.materials.param[handle, 14]) & bsdfs.BECKMANN
    said = [w for w in scene.warnings if "zero-area" not in w]
    assert len(said) == 1 and "rfilter 'tent'" in said[0]  # all else is read
    r = tracer.render(scene, spp=4, seed=1, max_depth=8)
    assert r.stats["nonfinite_samples"] == 0 and r.image.mean() > 0


PLASTICS = """<scene version="0.6.0">
    <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="toWorld"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <bsdf type="plastic" id="Shiny">
        <string name="intIOR" value="bk7"/><boolean name="nonlinear" value="true"/>
        <rgb name="diffuseReflectance" value="0.6, 0.3, 0.2"/>
    </bsdf>
    <bsdf type="twosided" id="Satin"><bsdf type="roughplastic">
        <float name="intIOR" value="1.6"/><string name="extIOR" value="water"/>
        <float name="alpha" value="0.15"/><string name="distribution" value="beckmann"/>
        <rgb name="specularReflectance" value="0.5, 0.5, 0.5"/>
    </bsdf></bsdf>
    <bsdf type="plastic" id="Odd"><string name="intIOR" value="unobtainium"/></bsdf>
    <shape type="rectangle"><ref id="Shiny"/></shape>
    <shape type="rectangle"><transform name="toWorld"><translate z="-1"/></transform><ref id="Satin"/></shape>
    <shape type="rectangle"><transform name="toWorld"><translate z="2"/></transform>
        <emitter type="area"><rgb name="radiance" value="1, 1, 1"/></emitter></shape>
</scene>
"""


def test_plastics_become_coated(tmp_path):
    """plastic / roughplastic (0.6 camelCase names) as COATED: the index ratio with Mitsuba's named
    media (bk7 over air; 1.6 over water), nonlinear, Beckmann, one-sided unless twosided, default
    reflectances (diffuse 0.5, specular 1), the specular sampling weight mean(ks) / (mean(kd) +
    mean(ks)) and the rough coat's table filled at build; an unknown medium name is one error line
    naming the file and line."""
    f = tmp_path / "scene.xml"
    f.write_text(PLASTICS.replace('<bsdf type="plastic" id="Odd"><string name="intIOR" value="unobtainium"/></bsdf>', ""))
    m = tracer.load_scene(str(f)).materials
    shiny, satin = m.names.index("Shiny"), m.names.index("Satin")
    assert m.type[shiny] == m.type[satin] == bsdfs.COATED
    ps, pt = m.param[shiny], m.param[satin]
    assert ps[bsdfs.P_IOR] == pytest.approx(1.5046 / 1.000277) and pt[bsdfs.P_IOR] == pytest.approx(1.6 / 1.333)
    assert int(ps[14]) == bsdfs.ONE_SIDED | bsdfs.NONLINEAR and int(pt[14]) == bsdfs.BECKMANN
    assert ps[bsdfs.P_ALPHA] == 0.0 and pt[bsdfs.P_ALPHA] == 0.15
    np.testing.assert_allclose(ps[0:6], [0.6, 0.3, 0.2, 1, 1, 1])
    np.testing.assert_allclose(pt[0:6], [0.5, 0.5, 0.5, 0.5, 0.5, 0.5])
    assert ps[bsdfs.P_SPEC_WEIGHT] == pytest.approx(1.0 / (1.0 + np.mean([0.6, 0.3, 0.2])))
    assert pt[bsdfs.P_SPEC_WEIGHT] == pytest.approx(0.5)
    assert np.all(m.table[shiny] == 0) and np.all((m.table[satin] > 0) & (m.table[satin] <= 1))
    f.write_text(PLASTICS.replace('<shape type="rectangle"><ref id="Shiny"/>', '<shape type="rectangle"><ref id="Odd"/>'))
    with pytest.raises(tracer.SceneError, match=r"scene.xml:\d+: int_ior 'unobtainium'"):
        tracer.load_scene(str(f))


WRAPPERS = """<scene version="0.6.0">
    <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="toWorld"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <bsdf type="mask" id="Leaf"><float name="opacity" value="0.25"/>
        <bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf>
    <bsdf type="mask" id="Rug">
        <texture name="opacity" type="bitmap"><string name="filename" value="wood.png"/></texture>
        <bsdf type="diffuse"/></bsdf>
    <bsdf type="bumpmap" id="Tiles">
        <texture name="map" type="bitmap"><string name="filename" value="wood.png"/></texture>
        <float name="scale" value="0.3"/>
        <bsdf type="twosided"><bsdf type="roughplastic"><float name="alpha" value="0.2"/></bsdf></bsdf>
    </bsdf>
    <shape type="rectangle"><ref id="Leaf"/></shape>
    <shape type="rectangle"><transform name="toWorld"><translate z="-1"/></transform><ref id="Rug"/></shape>
    <shape type="rectangle"><transform name="toWorld"><translate z="-2"/></transform><ref id="Tiles"/></shape>
    <shape type="rectangle"><transform name="toWorld"><translate z="2"/></transform>
        <emitter type="area"><rgb name="radiance" value="1, 1, 1"/></emitter></shape>
</scene>
"""


def test_mask_and_bumpmap_wrap_their_bsdf(tmp_path):
    """`mask` (opacity a number: params[P_CLEAR] = 1 - opacity; a texture: the opacity slot) and
    `bumpmap` (the height texture in the bump slot, `scale` its scale) around a nested BSDF keep
    the nested one's type and sidedness; the scene renders clean."""
    from tracer.material import P_BUMP_SCALE, TEX_SLOT_BUMP, TEX_SLOT_OPACITY

    _write(tmp_path)  # (writes wood.png)
    f = tmp_path / "wrap.xml"
    f.write_text(WRAPPERS)
    scene = tracer.load_scene(str(f))
    m = scene.materials
    leaf, rug, tiles = (m.names.index(n) for n in ("Leaf", "Rug", "Tiles"))
    assert m.type[leaf] == bsdfs.DIFFUSE and m.param[leaf, bsdfs.P_CLEAR] == 0.75
    assert not int(m.param[leaf, 14]) & bsdfs.ONE_SIDED and int(m.param[rug, 14]) & bsdfs.ONE_SIDED
    assert m.param[rug, bsdfs.P_CLEAR] == 0.0 and m.tex[rug, TEX_SLOT_OPACITY] >= 0
    assert m.type[tiles] == bsdfs.COATED and m.tex[tiles, TEX_SLOT_BUMP] >= 0 and m.param[tiles, P_BUMP_SCALE] == 0.3
    r = tracer.render(scene, spp=2, seed=1)
    assert r.stats["nonfinite_samples"] == 0 and r.image.mean() > 0


SHAPES = """<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="50"/><string name="fov_axis" value="$axis"/>
        <transform name="to_world"><lookat origin="1, 2, 9" target="0, 0.5, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="40"/><integer name="height" value="24"/></film>
    </sensor>
    <default name="axis" value="x"/>
    <bsdf type="diffuse" id="A"/><bsdf type="diffuse" id="B"/><bsdf type="diffuse" id="C"/><bsdf type="diffuse" id="D"/>
    <shape type="cube"><transform name="to_world"><scale value="0.5"/><rotate y="1" angle="25"/>
        <translate x="-1.5"/></transform><ref id="A"/></shape>
    <shape type="sphere"><point name="center" x="1.2" y="0.4" z="0.3"/><float name="radius" value="0.7"/>
        <ref id="B"/><emitter type="area"><rgb name="radiance" value="2, 2, 2"/></emitter></shape>
    <shape type="disk"><transform name="to_world"><scale value="0.8"/><rotate x="1" angle="-90"/>
        <translate y="-1"/></transform><ref id="C"/></shape>
    <shape type="cylinder"><point name="p0" x="0" y="-1" z="-2"/><point name="p1" x="0.5" y="1.5" z="-2"/>
        <float name="radius" value="0.3"/><ref id="D"/></shape>
    <emitter type="constant"><rgb name="radiance" value="0.25, 0.5, 0.75"/></emitter>
    <emitter type="sky"/>
</scene>
"""


@pytest.mark.parametrize("axis", ["x", "y", "diagonal", "smaller", "larger"])
def test_analytic_shapes_emitters_and_fov_axes_match_mitsuba(tmp_path, axis):
    """cube, sphere (center, radius), disk and cylinder (p0, p1, radius) tessellated: each shape's
    bounding box (to 1% of its size: the tessellation) and surface area (to 0.1%: the sphere,
    disk and cylinder keep their area by construction) against Mitsuba 3's own shapes; every
    triangle wound outward (the sphere's emission is one-sided); a constant emitter as the
    environment; 0.6's `sky` alone one warning line naming its line; the camera ray through the corner
    pixel against Mitsuba's for every fov_axis (detects a fov converted on the wrong axis)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    f = tmp_path / "shapes.xml"
    f.write_text(SHAPES)
    from tracer.readers.mitsuba import read_mitsuba_scene
    from tracer.scene import build_scene

    ours = build_scene(read_mitsuba_scene(str(f), {"axis": axis}))
    f2 = tmp_path / "for_mitsuba.xml"  # (Mitsuba 3 has no `sky`)
    f2.write_text(SHAPES.replace('    <emitter type="sky"/>\n', ""))
    ref = mi.load_file(str(f2), axis=axis)
    m = ours.materials
    assert np.allclose(ours.environment.radiance, [0.25, 0.5, 0.75])
    hit = [w for w in ours.warnings if "'sky'" in w]
    sun_line = 1 + next(i for i, ln in enumerate(SHAPES.splitlines()) if '"sky"' in ln)
    assert len(hit) == 1 and f"shapes.xml:{sun_line}:" in hit[0] and "not supported" in hit[0]
    centres = {"A": (-1.5, 0, 0), "B": (1.2, 0.4, 0.3), "D": (0.25, 0.25, -2)}
    mid = {n[0]: ours.tri[ours.tri_material == k].reshape(-1, 3).mean(0) for k, n in enumerate(m.names)}
    assert len(ref.shapes()) == 4
    for shape in ref.shapes():
        bb = shape.bbox()
        lo, hi = np.array(bb.min), np.array(bb.max)
        bid = min(mid, key=lambda b: np.linalg.norm(mid[b] - 0.5 * (lo + hi)))  # the shape of ours nearest
        k = next(i for i, n in enumerate(m.names) if n[0] == bid)
        tri = ours.tri[ours.tri_material == k]
        size = float(np.max(hi - lo))
        np.testing.assert_allclose(tri.reshape(-1, 3).min(0), lo, atol=0.01 * size, err_msg=bid)
        np.testing.assert_allclose(tri.reshape(-1, 3).max(0), hi, atol=0.01 * size, err_msg=bid)
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area = 0.5 * np.linalg.norm(n, axis=1).sum()
        np.testing.assert_allclose(area, shape.surface_area(), rtol=1e-3, err_msg=bid)
        if bid in centres:  # closed or tube shapes: every face points away from the axis/centre
            c = tri.mean(axis=1) - np.array(centres[bid])
            if bid == "D":
                ax = np.array([0.5, 2.5, 0.0]) / np.linalg.norm([0.5, 2.5, 0.0])
                c = c - np.outer(c @ ax, ax)
            assert np.all(np.einsum("ij,ij->i", n, c) > 0), bid
    from tracer.camera import camera_ray

    cam = ours.camera.packed()
    for px, py in ((0, 0), (39, 23)):
        o, d = camera_ray(cam, 40, 24, px, py, 0.5, 0.5)
        ray, _ = ref.sensors()[0].sample_ray(0.0, 0.5, mi.Point2f((px + 0.5) / 40, (py + 0.5) / 24), mi.Point2f(0.5, 0.5))
        np.testing.assert_allclose(d, np.array(ray.d), atol=1e-5, err_msg=f"{axis} {px} {py}")


def test_obj_without_normals_gets_mitsubas_smooth_normals(tmp_path):
    """An OBJ without vn (an icosphere, the OBJ writing each position once) and face_normals off:
    every corner's normal equals the vertex normal Mitsuba 3 computes for the same file (angle
    weighted, to float32 precision), and is close to the sphere's radial direction; with
    face_normals on, no normals (flat). Detects normals not smoothed, weighted otherwise (area or
    uniform weights move them by ~1e-2 on this mesh), or left in object space."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from tests.scenes import icosphere

    v, f = icosphere(1)
    (tmp_path / "ball.obj").write_text("\n".join([f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in v] +
                                                 [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]) + "\n")
    xml = """<scene version="3.0.0"><sensor type="perspective"><transform name="to_world">
        <lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform></sensor>
        <shape type="obj"><string name="filename" value="ball.obj"/>FACE
        <transform name="to_world"><scale x="2" y="1" z="1"/><rotate z="1" angle="30"/></transform>
        <emitter type="area"/></shape></scene>"""
    (tmp_path / "s.xml").write_text(xml.replace("FACE", ""))
    ours = tracer.load_scene(str(tmp_path / "s.xml"))
    ref = mi.load_file(str(tmp_path / "s.xml"))
    params = mi.traverse(ref.shapes()[0])
    pos = np.array(params["vertex_positions"]).reshape(-1, 3)
    nrm = np.array(params["vertex_normals"]).reshape(-1, 3)
    from scipy.spatial import cKDTree

    dist, idx = cKDTree(pos).query(ours.tri.reshape(-1, 3))
    assert dist.max() < 1e-5  # the same vertices
    np.testing.assert_allclose(ours.tri_vn.reshape(-1, 3), nrm[idx], atol=2e-5)
    (tmp_path / "s.xml").write_text(xml.replace("FACE", '<boolean name="face_normals" value="true"/>'))
    assert tracer.load_scene(str(tmp_path / "s.xml")).tri_vn.shape[0] == 0


def test_define_overrides_defaults_from_the_command_line(tmp_path, capsys):
    """`-D res=12 --define spp=2` replace the XML's <default> values (the film width, the sampler's
    spp) as `mitsuba -D` does; a define without '=' and a define on an OBJ scene are one error line
    each, exit 2."""
    from tests.test_cli import CORNELL, fails_with, run_cli
    from tracer.imageio import read_image

    path = _write(tmp_path)
    out = tmp_path / "o.exr"
    code, _, err = run_cli(capsys, path, "-D", "res=12", "--define", "spp=2", "-o", out, "--quiet")
    assert code == 0, err
    img = read_image(str(out))
    assert img.shape[:2] == (16, 12)
    fails_with(capsys, [path, "--define", "res"], "--define 'res'", "NAME=VALUE")
    fails_with(capsys, [CORNELL, "-D", "res=12"], "define", "Mitsuba scene XML")


def test_bitmap_gamma_and_raw(tmp_path):
    """A bitmap's 0.6 `gamma` (1: stored linear; 2.2: the power law; -1: sRGB) and Mitsuba 3's
    `raw` (no decoding) against the 8-bit texels decoded here; without either, sRGB."""
    import OpenImageIO as oiio

    px = np.random.default_rng(2).integers(0, 256, (4, 4, 3), dtype=np.uint8)
    out = oiio.ImageOutput.create(str(tmp_path / "t.png"))
    out.open(str(tmp_path / "t.png"), oiio.ImageSpec(4, 4, 3, "uint8"))
    out.write_image(px)
    out.close()
    kinds = {"G1": '<float name="gamma" value="1"/>', "G22": '<float name="gamma" value="2.2"/>',
             "GS": '<float name="gamma" value="-1"/>', "RAW": '<boolean name="raw" value="true"/>', "AUTO": ""}
    bsdfs_xml = "".join(f'<bsdf type="diffuse" id="{k}"><texture name="reflectance" type="bitmap">'
                        f'<string name="filename" value="t.png"/>{v}</texture></bsdf>' for k, v in kinds.items())
    shapes = "".join(f'<shape type="rectangle"><transform name="to_world"><translate z="{-i}"/></transform>'
                     f'<ref id="{k}"/></shape>' for i, k in enumerate(kinds))
    (tmp_path / "g.xml").write_text(f"""<scene version="0.6.0">{bsdfs_xml}{shapes}
        <shape type="rectangle"><transform name="toWorld"><translate z="3"/></transform>
        <emitter type="area"/></shape></scene>""")
    scene = tracer.load_scene(str(tmp_path / "g.xml"))
    v = px / 255.0
    srgb = np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)
    expect = {"G1": v, "G22": v ** 2.2, "GS": srgb, "RAW": v, "AUTO": srgb}
    m, tex = scene.materials, scene.textures
    for k, want in expect.items():
        row = tex.info[m.tex[m.names.index(k), 0]]
        o, w, h = (int(x) for x in row[1:4])
        got = tex.data[o:o + w * h * 3].reshape(h, w, 3)
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6, err_msg=k)
