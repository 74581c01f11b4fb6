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
    (to_uv scale), an area light on a rectangle; the gaussian rfilter and the constant emitter are
    one warning each, naming the line."""
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
    for what in ("rfilter 'gaussian'", "<emitter> is not supported"):
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
