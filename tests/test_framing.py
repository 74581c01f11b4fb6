"""A scene without a camera is framed so that the image shows lit surfaces, and a black image says so.

Each check is geometric (where the chosen camera stands: inside the closed room, on the open side
of the box) or counts lit pixels of a tiny render; none depends on the order the views are tried
in beyond the default +z view being kept where it already shows a lit scene."""
import json
import logging
import os
import shutil

import numpy as np

import tracer
from tracer.framing import choose_view
from tests import scenes
from tests.test_cli import render_cli

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def lit(image):
    return float((image.sum(axis=2) > 0).mean())


def test_bare_cornell_box_is_seen_through_its_open_side(tmp_path):
    """The Cornell box is open at z = 0 and closed at z = 0.56: its old framing (from +z) saw the
    back wall from behind, a black image. The camera must stand on the open side, outside."""
    for ext in ("obj", "mtl"):
        shutil.copy(os.path.join(ROOT, "scenes", "cornell", f"cornell.{ext}"), tmp_path)
    scene = tracer.load_scene(tmp_path / "cornell.obj", width=16, height=16)
    assert scene.framing
    assert scene.camera.origin[2] < 0.0 and scene.camera.forward[2] > 0.9, scene.camera
    r = tracer.render(scene, spp=4)
    assert r.stats["nonfinite_samples"] == 0
    assert lit(r.image) > 0.2 and r.image.mean() > 0


def closed_room(folder, sidecar=None):
    """A closed 4 x 3 x 4 room (walls, floor, ceiling diffuse 0.7), a 1 x 1 light on the ceiling
    facing down, and a 1 x 1 x 1 crate on the floor; no camera unless `sidecar` gives one."""
    room_v, room_f = scenes.box_faces((-2, 0, -2), (2, 3, 2), inward=True)
    crate_v, crate_f = scenes.box_faces((-0.5, 0, -0.5), (0.5, 1, 0.5), inward=False)
    lamp_v = np.array([[-0.5, 2.99, -0.5], [0.5, 2.99, -0.5], [0.5, 2.99, 0.5], [-0.5, 2.99, 0.5]])
    lamp_f = np.array([[0, 1, 2], [0, 2, 3]])  # CCW seen from below: emits down
    assert np.cross(lamp_v[1] - lamp_v[0], lamp_v[2] - lamp_v[0])[1] < 0
    return scenes.write_scene(folder, "room", [("wall", room_v, room_f), ("crate", crate_v, crate_f),
                                               ("lamp", lamp_v, lamp_f)],
                              {"wall": "Kd 0.7 0.7 0.7", "crate": "Kd 0.5 0.3 0.2", "lamp": "Kd 0 0 0\nKe 10 10 10"},
                              sidecar)


def test_closed_room_is_seen_from_inside(tmp_path):
    """From outside, a closed room is its walls' unlit backs: the camera must stand inside, and
    most of a small render must be lit."""
    scene = tracer.load_scene(closed_room(tmp_path), width=16, height=12)
    o = scene.camera.origin
    assert np.all(o > [-2, 0, -2]) and np.all(o < [2, 3, 2]), scene.camera
    assert not (np.all(o > [-0.5, 0, -0.5]) and np.all(o < [0.5, 1, 0.5])), "inside the crate"
    r = tracer.render(scene, spp=4)
    assert r.stats["nonfinite_samples"] == 0
    assert lit(r.image) > 0.9


def test_lit_open_scene_keeps_the_default_view(tmp_path):
    """A floor under a light, open to every side: the +z view sees it lit and is kept (the view a
    bare OBJ always had)."""
    floor_v = np.array([[-3, 0, -3], [3, 0, -3], [3, 0, 3], [-3, 0, 3]], dtype=float)
    floor_f = np.array([[0, 2, 1], [0, 3, 2]])
    lamp_v = floor_v * [0.2, 0, 0.2] + [0, 2, 0]
    obj = scenes.write_scene(tmp_path, "floor", [("floor", floor_v, floor_f), ("lamp", lamp_v, floor_f[:, ::-1])],
                             {"floor": "Kd 0.5 0.5 0.5", "lamp": "Kd 0 0 0\nKe 5 5 5"}, None)
    scene = tracer.load_scene(obj, width=8, height=8)
    np.testing.assert_allclose(scene.camera.forward, [0, 0, -1], atol=1e-12)


def test_choose_view_rules():
    """Outside views whose surfaces are mostly lit come first, by tier (the default within 1.25x),
    else the most lit view of all."""
    tiers = ([0, 1], [2])
    assert choose_view([0.5, 0.6, 0.8, 0.9], [1.0, 1.0, 1.0, 1.0], tiers) == 0
    assert choose_view([0.3, 0.6, 0.8, 0.9], [1.0, 1.0, 1.0, 1.0], tiers) == 1
    assert choose_view([0.3, 0.6, 0.8, 0.9], [0.1, 0.2, 1.0, 1.0], tiers) == 2
    assert choose_view([0.3, 0.6, 0.8, 0.9], [0.1, 0.2, 0.3, 1.0], tiers) == 3


def test_black_image_is_reported(tmp_path, capsys, caplog):
    """A camera that sees nothing lit: the render warns (library: the 'tracer' logger; command line:
    one warning line naming the likely cause) and records the lit share, 0."""
    obj = closed_room(tmp_path, {"camera": {"origin": [0, 1.5, 10], "target": [0, 1.5, 20]},
                                 "film": {"width": 8, "height": 8}})
    with caplog.at_level(logging.WARNING, logger="tracer"):
        r = tracer.render(tracer.load_scene(obj), spp=2)
    assert r.stats["lit_share"] == 0.0
    assert any("black" in rec.getMessage() for rec in caplog.records)
    _, stats, err = render_cli(capsys, tmp_path, "dark", scene=obj, size=None, spp=2)
    warn = [line for line in err.splitlines() if "black" in line]
    assert len(warn) == 1 and warn[0].startswith("tracer: warning: ") and "room.json" in warn[0], err
    assert stats["lit_share"] == 0.0
    # a lit render says nothing
    side = json.loads((tmp_path / "room.json").read_text())
    side["camera"] = {"origin": [0, 1.5, 1.9], "target": [0, 1.5, 0]}
    (tmp_path / "room.json").write_text(json.dumps(side))
    _, stats, err = render_cli(capsys, tmp_path, "lit", scene=obj, size=None, spp=2)
    assert "black" not in err and stats["lit_share"] > 0.9


def test_many_emitters_and_a_z_up_sidecar(tmp_path):
    """A room lit by an emissive sphere of 1280 triangles (more than the rays cast from the lights:
    each ray must start on its own triangle), in a scene whose sidecar says only that +z is up: the
    camera stands inside, its image up is +z, and it looks along a horizontal (x or y) axis."""
    room_v, room_f = scenes.box_faces((-2, -2, 0), (2, 2, 3), inward=True)
    ball_v, ball_f = scenes.icosphere(3)
    assert len(ball_f) > 512
    obj = scenes.write_scene(tmp_path, "zroom", [("wall", room_v, room_f), ("ball", 0.3 * ball_v + [0, 0, 2], ball_f)],
                             {"wall": "Kd 0.7 0.7 0.7", "ball": "Kd 0 0 0\nKe 5 5 5"},
                             {"camera": {"up": [0, 0, 1]}, "film": {"width": 12, "height": 12}})
    scene = tracer.load_scene(obj)
    o, f = scene.camera.origin, scene.camera.forward
    assert np.all(o > [-2, -2, 0]) and np.all(o < [2, 2, 3]), scene.camera
    assert abs(f[2]) < 1e-9 and scene.camera.up[2] > 0.99, scene.camera
    assert lit(tracer.render(scene, spp=2).image) > 0.9
