"""Scene loading: MTL mapping, sidecar keys and overrides, camera conventions."""
import json
import math

import numpy as np
import pytest

import tracer
from tracer import bsdfs
from tracer.errors import SceneError
from tests import scenes
from tracer.testing.stats import assert_clean

MTL_CASES = {
    "matte": ("Kd 0.5 0.4 0.3\nillum 1", bsdfs.DIFFUSE, dict(kd=[0.5, 0.4, 0.3])),
    "glass": ("Ni 1.33\nillum 7", bsdfs.DIELECTRIC, dict(ior=1.33)),
    "frosted": ("Ni 1.5\nPr 0.5\nillum 7", bsdfs.ROUGH_DIELECTRIC, dict(ior=1.5, alpha=0.25)),
    "mirror": ("Ks 0.9 0.8 0.7\nillum 3", bsdfs.MIRROR, dict(ks=[0.9, 0.8, 0.7])),
    "metal": ("Kd 0 0 0\nKs 0.5 0.6 0.7\nPr 0.3\nPm 1\nillum 2", bsdfs.CONDUCTOR, dict(ks=[0.5, 0.6, 0.7], alpha=0.09)),
    "metal_kd": ("Kd 0.2 0.3 0.4\nPr 0.5\nPm 1", bsdfs.CONDUCTOR, dict(ks=[0.2, 0.3, 0.4], alpha=0.25)),
    "plastic": ("Kd 0.5 0.5 0.5\nKs 0.2 0.2 0.2\nNs 98\nillum 2", bsdfs.PLASTIC,
                dict(kd=[0.5] * 3, ks=[0.2] * 3, alpha=math.sqrt(2 / 100))),
}


def _mtl_scene(tmp_path):
    groups, mats = [], {}
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    for i, (name, (body, _, _)) in enumerate(MTL_CASES.items()):
        groups.append((name, v + [0, 0, i], [[0, 1, 2]]))
        mats[name] = body
    groups.append(("lamp", v + [0, 0, -1], [[0, 1, 2]]))
    mats["lamp"] = "Kd 0 0 0\nKe 1 1 1"
    return scenes.write_scene(tmp_path, "mats", groups, mats, None)


def test_mtl_statements_map_to_bsdfs(tmp_path):
    scene = tracer.load_scene(_mtl_scene(tmp_path))
    m = scene.materials
    cols = dict(kd=slice(0, 3), ks=slice(3, 6), alpha=6, ior=7)
    for name, (_, mtype, params) in MTL_CASES.items():
        i = m.names.index(name)
        assert m.type[i] == mtype, name
        for key, val in params.items():
            np.testing.assert_allclose(m.param[i, cols[key]], val, rtol=1e-9, err_msg=f"{name}.{key}")
    i = m.names.index("lamp")
    np.testing.assert_array_equal(m.emission[i], [1, 1, 1])
    assert scene.emissive.sum() == 1


def test_unsupported_statements_are_reported_once(tmp_path, caplog):
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    with open(tmp_path / "lamp.mtl", "a") as f:
        f.write("Ka 0.1 0.1 0.1\nd 0.5\nnewmtl other\nKa 1 1 1\n")
    scene = tracer.load_scene(obj)
    reported = [w for w in scene.warnings if "unsupported" in w]
    assert len(reported) == 2 and any("Ka in 2 material" in w for w in reported)


def test_sidecar_material_override_and_json_scene_file(tmp_path):
    scenes.light_quad(tmp_path, (1, 1, 1))
    side = json.loads((tmp_path / "lamp.json").read_text())
    side["obj"] = "lamp.obj"
    side["materials"] = {"lamp": {"emission": [4, 5, 6]}}
    (tmp_path / "other.json").write_text(json.dumps(side))
    scene = tracer.load_scene(tmp_path / "other.json")
    np.testing.assert_array_equal(scene.materials.emission[0], [4, 5, 6])
    side["materials"] = {"lamp": {"type": "velvet"}}
    (tmp_path / "other.json").write_text(json.dumps(side))
    with pytest.raises(tracer.SceneError, match="velvet.*valid: diffuse"):
        tracer.load_scene(tmp_path / "other.json")


def test_overrides_replace_sidecar_values(tmp_path):
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    scene = tracer.load_scene(obj, width=20, height=10, spp=3, max_depth=7, rr_depth=2, seed=9)
    assert (scene.width, scene.height) == (20, 10)
    assert (scene.render.spp, scene.render.max_depth, scene.render.rr_depth, scene.render.seed) == (3, 7, 2, 9)
    # fov along x is kept; the vertical one follows the aspect ratio
    assert scene.camera.tan_x == pytest.approx(math.tan(math.radians(15)))
    assert scene.camera.tan_y == pytest.approx(scene.camera.tan_x / 2)


def test_image_right_is_cross_forward_up(tmp_path):
    # A lamp at +x, camera looking down -z with up +y: the lamp must be in the right half.
    v = np.array([[0.5, -0.2, 0], [1.0, -0.2, 0], [1.0, 0.2, 0], [0.5, 0.2, 0]], float)
    obj = scenes.write_scene(tmp_path, "side", [("lamp", v, [[0, 1, 2], [0, 2, 3]])],
                             {"lamp": "Kd 0 0 0\nKe 1 1 1"},
                             {"camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 60},
                              "film": {"width": 32, "height": 16}})
    r = tracer.render(tracer.load_scene(obj), spp=1)
    assert_clean(r)
    lit = r.image[:, :, 0] > 0
    assert lit[:, 16:].sum() > 10 and lit[:, :16].sum() == 0
    # with up = -y, right = cross(forward, up) is -x: the lamp moves to the left half
    scene = tracer.load_scene(obj)
    from tracer.camera import Camera

    scene.camera = Camera.look_at([0, 0, 3], [0, 0, 0], [0, -1, 0], 60, "x", 32, 16)
    r2 = tracer.render(scene, spp=1)
    assert_clean(r2)
    lit2 = r2.image[:, :, 0] > 0
    assert lit2[:, :16].sum() > 10 and lit2[:, 16:].sum() == 0


def test_bare_obj_is_framed(tmp_path):
    v, f = scenes.box_faces((10, 10, 10), (12, 13, 11), inward=False)
    obj = scenes.write_scene(tmp_path, "bare", [("lamp", v, f)], {"lamp": "Kd 0 0 0\nKe 1 1 1"}, None)
    r = tracer.render(tracer.load_scene(obj, width=32, height=32), spp=1)
    assert_clean(r)
    lit = (r.image[:, :, 0] > 0).mean()
    assert 0.05 < lit < 0.95  # the object is in view and does not fill it


def test_scene_repr_is_readable():
    import os

    scene = tracer.load_scene(os.path.join(os.path.dirname(__file__), "..", "scenes", "cornell", "cornell.obj"))
    text = repr(scene)
    assert "cornell.obj" in text and "32 triangles" in text and "256x256" in text


def test_latin1_obj_and_mtl_load_and_render(tmp_path):
    """An OBJ with a Latin-1 comment and a Latin-1 material name (in the OBJ and the MTL): read
    in the same encoding, so the material is found (this failed with ModuleNotFoundError:
    charset_normalizer in trimesh)."""
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    for name in ("lamp.obj", "lamp.mtl"):
        text = (tmp_path / name).read_text().replace("lamp\n", "lampé\n")
        (tmp_path / name).write_bytes(("# exporté par Blender\n" + text).encode("latin-1"))
    scene = tracer.load_scene(obj)
    assert scene.materials.names == ["lampé"] and not scene.warnings
    r = tracer.render(scene, spp=1)
    assert_clean(r)
    np.testing.assert_allclose(r.image, 1.0)


def test_undefined_material_is_named(tmp_path):
    """A 0-byte MTL: the warning names the material the OBJ uses and the MTL it looked in; the
    material is diffuse 0.8 under its own name, so that the sidecar can override it."""
    obj = scenes.sphere_under_sky(tmp_path, 0.5, 1.0)
    (tmp_path / "sky.mtl").write_text("")
    scene = tracer.load_scene(obj)
    assert scene.warnings == [f"{obj}: material 'ball' is not defined in sky.mtl; using diffuse 0.8"]
    i = scene.materials.names.index("ball")
    assert scene.materials.type[i] == bsdfs.DIFFUSE
    np.testing.assert_array_equal(scene.materials.param[i, :3], 0.8)
    side = json.loads((tmp_path / "sky.json").read_text())
    side["materials"] = {"ball": {"kd": [0.2, 0.3, 0.4]}}
    (tmp_path / "sky.json").write_text(json.dumps(side))
    scene = tracer.load_scene(obj)
    assert scene.warnings == []  # defined by the sidecar
    np.testing.assert_array_equal(scene.materials.param[scene.materials.names.index("ball"), :3], [0.2, 0.3, 0.4])


def test_undefined_materials_keep_their_faces(tmp_path):
    """Faces of a material the MTL lacks keep that material, in an OBJ that uses it twice between
    others (trimesh groups faces by material and forgets the names of undefined ones)."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    groups = [("lamp", v, [[0, 1, 2]]), ("wall", v + [0, 0, 1], [[0, 1, 2]]), ("floor", v + [0, 0, 2], [[0, 1, 2]]),
              ("lamp", v + [0, 0, 3], [[0, 1, 2]]), ("wall", v + [0, 0, 4], [[0, 1, 2]])]
    obj = scenes.write_scene(tmp_path, "m", groups, {"lamp": "Kd 0 0 0\nKe 1 1 1"}, None)
    scene = tracer.load_scene(obj)
    names = [scene.materials.names[i] for i in scene.tri_material]
    by_z = dict(zip(scene.tri[:, 0, 2], names))
    assert by_z == {0.0: "lamp", 1.0: "wall", 2.0: "floor", 3.0: "lamp", 4.0: "wall"}
    assert scene.warnings == [f"{obj}: materials 'wall', 'floor' are not defined in m.mtl; using diffuse 0.8"]


def test_usemtl_without_mtllib(tmp_path):
    obj = scenes.sphere_under_sky(tmp_path, 0.5, 1.0)
    text = (tmp_path / "sky.obj").read_text()
    (tmp_path / "sky.obj").write_text(text.replace("mtllib sky.mtl\n", ""))
    scene = tracer.load_scene(obj)
    assert scene.materials.names == ["ball"]
    assert scene.warnings == [f"{obj}: material 'ball' is not defined (the OBJ names no MTL file); using diffuse 0.8"]


def _mitsuba_look_at(origin, target, up):
    """Mitsuba's look_at as a 4x4 camera-to-world matrix: columns left, up, direction, origin."""
    d = np.asarray(target, float) - np.asarray(origin, float)
    d /= np.linalg.norm(d)
    left = np.cross(up, d)
    left /= np.linalg.norm(left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(d, left), d, origin
    return m


def test_camera_from_a_mitsuba_matrix_is_the_look_at_camera():
    """Camera.from_matrix on Mitsuba's look_at matrix (built here from its definition) gives the
    look_at camera; a scaled matrix the same; a matrix mirrored in x the mirrored image."""
    from tracer.camera import Camera

    o, t, up = [1.0, 2.0, 3.0], [0.5, 1.0, -2.0], [0.0, 1.0, 0.2]
    ref = Camera.look_at(o, t, up, 40.0, "y", 64, 32)
    m = _mitsuba_look_at(o, t, up)
    for mat in (m, m @ np.diag([2.0, 2.0, 2.0, 1.0])):
        cam = Camera.from_matrix(mat, 40.0, "y", 64, 32)
        np.testing.assert_allclose(cam.packed(), ref.packed(), atol=1e-12)
    mirrored = Camera.from_matrix(m @ np.diag([-1.0, 1.0, 1.0, 1.0]), 40.0, "y", 64, 32)
    np.testing.assert_allclose(mirrored.right, -ref.right, atol=1e-12)
    np.testing.assert_allclose(mirrored.up, ref.up, atol=1e-12)
    with pytest.raises(SceneError, match="singular"):
        Camera.from_matrix(np.diag([1.0, 0.0, 1.0, 1.0]), 40.0, "y", 64, 32)


def test_build_scene_takes_a_spec_from_any_reader():
    """A SceneSpec made by hand (as a reader other than the OBJ one would): a floor under a
    downward-facing emitter, seen through a camera matrix, renders lit and the right way up;
    without the emitter the error says what the spec says is missing."""
    from tracer.scene import CameraSpec, SceneSpec, build_scene

    floor = np.array([[[-1, 0, -1], [1, 0, 1], [1, 0, -1]], [[-1, 0, -1], [-1, 0, 1], [1, 0, 1]]], float)
    light = np.array([[[-0.2, 1, -0.2], [0.2, 1, -0.2], [0.2, 1, 0.2]], [[-0.2, 1, -0.2], [0.2, 1, 0.2],
                                                                           [-0.2, 1, 0.2]]], float)
    mats = [("white", 0, np.array([0.8, 0.8, 0.8, 0, 0, 0, 0, 1.5]), np.zeros(3)),
            ("lamp", 0, np.zeros(8), np.array([5.0, 5.0, 5.0]))]
    cam = CameraSpec(fov=60.0, matrix=_mitsuba_look_at([0, 0.5, 3], [0, 0, 0], [0, 1, 0]), where="spec: camera")
    spec = SceneSpec(path="hand-made", geometry_file="hand-made", tri=np.concatenate([floor, light]),
                     tri_material=np.array([0, 0, 1, 1], np.int32), materials=mats, width=16, height=16,
                     camera=cam, no_light="the spec has no emitter")
    scene = build_scene(spec)
    r = tracer.render(scene, spp=4)
    # the emitter above the centre (Mitsuba's +y up), the lit floor below it
    assert r.image[:8].max() == 5.0 and 0.0 < r.image[8:].max() < 1.0 and r.stats["nonfinite_samples"] == 0
    spec.tri_material = np.array([0, 0, 0, 0], np.int32)
    with pytest.raises(SceneError, match="hand-made: the scene has no light: the spec has no emitter"):
        build_scene(spec)
