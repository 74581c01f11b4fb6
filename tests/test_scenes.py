"""The built-in scenes in scenes/ load, have a light, a 256-pixel film, and render to a
finite, non-black image at low resolution (regenerate with scenes/build_scenes.py)."""
import json
import os

import pytest

import tracer
from tracer.testing.stats import assert_clean

SCENES_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes")
NAMES = ["cornell", "ajar", "glossy", "caustic", "manylights", "window", "spotlit"]
# scenes lit only through gaps or by indirect light need a few samples for anything to arrive
SPP = {"ajar": 4, "spotlit": 4}


def obj_path(name):
    return os.path.join(SCENES_DIR, name, f"{name}.obj")


@pytest.mark.parametrize("name", NAMES)
def test_scene_loads_and_renders(name):
    scene = tracer.load_scene(obj_path(name))
    emissive = scene.materials.emission[scene.tri_material].max(axis=1) > 0
    env = scene.environment
    has_env = env is not None and (env.image is not None or env.radiance.max() > 0)
    assert emissive.any() or has_env, "no light"
    assert max(scene.width, scene.height) == 256
    assert min(scene.width, scene.height) >= 1

    with open(os.path.join(SCENES_DIR, name, f"{name}.json")) as f:
        film = json.load(f)["film"]
    height = max(1, round(64 * film["height"] / film["width"]))
    small = tracer.load_scene(obj_path(name), width=64, height=height)
    r = tracer.render(small, spp=SPP.get(name, 1))
    assert_clean(r, name)
    image = r.image
    assert image.shape == (height, 64, 3)
    assert image.max() > 0
