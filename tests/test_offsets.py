"""Ray offsets (tracer.bvh.ray_offsets): a ray leaving a surface starts just off it, by an amount
fitted to the float32 coordinates the ray queries see at that triangle, not to the scene's extent.

A scene-scaled offset (1e-5 of the scene's size, as before) puts every secondary ray 0.03 units
off its surface when a 2000-unit floor is in the scene: mirror reflections move and thin walls
leak. These tests build such scenes and compare with answers worked out here.
"""
import math

import numpy as np
import pytest

import tracer
from tests import scenes
from tracer.testing.stats import assert_clean
from tracer.bvh import make_accel, ray_offsets

FLOOR = 1000.0  # half-width of the big floor
W = 64  # image size of the mirror test
FOV = 10.0  # degrees along x


def _floor(y):
    """A black (Kd 0) square floor 2000 units wide at height y, facing up: it only sets the scene's
    extent (and with it the float32 spacing far from the centre)."""
    v = np.array([[-FLOOR, y, -FLOOR], [FLOOR, y, -FLOOR], [FLOOR, y, FLOOR], [-FLOOR, y, FLOOR]])
    return ("floor", v, np.array([[0, 2, 1], [0, 3, 2]]))


def _mirror_scene(folder, with_floor):
    """A 1 x 1 mirror plate in the plane y = 0 (normal +y), a small spherical light L of radius 0.05
    at (0, 0.5, -0.866), and a camera at (0, 1, 1.732) looking at the plate's centre M: the camera
    sees the plate at 60 degrees from its normal, and the light's mirror image L' = (0, -0.5, -0.866)
    lies on its optical axis, 3 units away. The light itself is 19 degrees off axis, outside the 10
    degree field of view."""
    plate = np.array([[-0.5, 0, -0.5], [0.5, 0, -0.5], [0.5, 0, 0.5], [-0.5, 0, 0.5]])
    sv, sf = scenes.icosphere(4)
    groups = [("mirror", plate, np.array([[0, 2, 1], [0, 3, 2]])),
              ("lamp", sv * 0.05 + np.array([0.0, 0.5, -math.sqrt(3) / 2]), sf)]
    mats = {"mirror": "illum 3\nKs 1 1 1", "lamp": "Kd 0 0 0\nKe 10 10 10"}
    if with_floor:
        groups.append(_floor(-0.5))
        mats["floor"] = "Kd 0 0 0"
    return scenes.write_scene(
        folder, "mirror", groups, mats,
        {"camera": {"origin": [0, 1, math.sqrt(3)], "target": [0, 0, 0], "up": [0, 1, 0], "fov": FOV},
         "film": {"width": W, "height": W}, "render": {"spp": 64, "max_depth": -1}})


@pytest.mark.parametrize("with_floor", [False, True], ids=["alone", "beside-2000-unit-floor"])
def test_mirror_image_of_a_small_light_sits_where_the_mirror_puts_it(tmp_path, with_floor):
    """The light's mirror image lies on the optical axis, so its image is centred on the image
    centre (W/2, W/2) by symmetry (the icosphere's faceting moves the centroid by far less than
    0.01 pixel). The centroid of the rendered radiance must sit within 0.1 pixel of it.

    What it detects: a ray leaving the mirror displaced by d along the normal moves the reflection
    by d sin(60 deg) across the line of sight, 3 units away, where a pixel spans 0.0082 units: a
    shift of 0.1 pixel is d = 1e-3 units (5e-7 of the floor's extent). The scene-scaled offset of
    before (0.028 units with the floor) moved it by 2.9 pixels. Render noise moves the centroid by
    about 0.01 pixel at 64 spp."""
    scene = tracer.load_scene(_mirror_scene(tmp_path, with_floor))
    r = tracer.render(scene, spp=64, seed=1)
    assert_clean(r)
    lum = r.image.astype(np.float64).sum(axis=2)
    assert lum.sum() > 0.0 and lum[0].max() == 0.0 and lum[:, 0].max() == 0.0  # the blob is inside
    assert lum.max() == pytest.approx(30.0, rel=1e-6)  # Le x Ks (3 channels) where fully covered
    ys, xs = np.indices(lum.shape) + 0.5
    cx, cy = (lum * xs).sum() / lum.sum(), (lum * ys).sum() / lum.sum()
    assert abs(cx - W / 2) < 0.1 and abs(cy - W / 2) < 0.1, (cx, cy)


def _thin_wall_scene(folder, camera_side):
    """A 2 x 2 wall (face A at z = 0, diffuse Kd 0.5) with a glass pane (face B, smooth, index 1.5)
    1e-4 in front of it, inside a scene with a 2000-unit black floor; a 0.5 x 0.5 light at z = -0.5,
    behind the wall, faces it. The camera looks at the wall from the pane's side (z > 0) or from
    the lit side. A ray refracted by the pane must meet the wall 1e-4 further on; nothing on the
    pane's side reflects light and the gap is dark (the wall is opaque), so any radiance seen
    through the pane has come through the wall."""
    v0 = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    lamp = np.array([[-0.25, -0.25, -0.5], [0.25, -0.25, -0.5], [0.25, 0.25, -0.5], [-0.25, 0.25, -0.5]])
    z = 1.0 if camera_side == "dark" else -1.0
    return scenes.write_scene(
        folder, "wall", [("wall", v0, quad), ("pane", v0 + [0, 0, 1e-4], quad), ("lamp", lamp, quad),
                         _floor(-2.0)],
        {"wall": "Kd 0.5 0.5 0.5", "pane": "illum 7\nNi 1.5", "lamp": "Kd 0 0 0\nKe 5 5 5", "floor": "Kd 0 0 0"},
        {"camera": {"origin": [0, 0, 2 * z], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 30},
         "film": {"width": 16, "height": 16}, "render": {"spp": 16, "max_depth": -1}})


def test_thin_wall_does_not_leak(tmp_path):
    """Seen through the pane, the wall is exactly black: every ray the pane refracts starts less
    than 1e-4 off it and meets the wall. Seen from the lit side the wall is lit (so the light does
    reach it). What it detects: an offset of more than 1e-4 units at the pane (the scene-scaled
    one of before was 0.028: refracted rays started behind the wall and saw the light)."""
    dark = tracer.render(tracer.load_scene(_thin_wall_scene(tmp_path / "d", "dark")), spp=16, seed=2)
    lit = tracer.render(tracer.load_scene(_thin_wall_scene(tmp_path / "l", "lit")), spp=16, seed=2)
    assert_clean(dark)
    assert_clean(lit)
    assert lit.image.mean() > 0.1
    assert dark.image.max() == 0.0, f"light leaks through the wall: mean {dark.image.mean():.4g}"


def test_offsets_follow_the_coordinates_the_queries_see():
    """ray_offsets against its definition, computed here from the vertices: a unit triangle near the
    centre gets an offset of a few float32 spacings of 1 whatever the scene's extent; the same
    triangle 1000 units out gets hundreds of times more; a sliver gets more than a well-shaped triangle of
    the same size (Embree's arithmetic on its edges is ill-conditioned)."""
    unit = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0.2]])
    far = unit + 1000.0
    sliver = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 1e-3, 0.0]])
    tri = np.stack([unit, far, sliver])
    eps = ray_offsets(tri, np.zeros(3))

    def expected(t):
        cr = np.cross(t[1] - t[0], t[2] - t[0])
        n = np.abs(cr) / np.linalg.norm(cr)
        box = np.abs(t).max(axis=0)
        e = sorted(np.linalg.norm(t[(i + 1) % 3] - t[i]) for i in range(3))
        return 8.0 * 2.0**-24 * (n @ box + e[2] * e[2] * e[1] / np.linalg.norm(cr))

    np.testing.assert_allclose(eps, [expected(t) for t in tri], rtol=1e-12)
    assert 1e-7 < eps[0] < 2e-6 and 200 * eps[0] < eps[1] < 1000 * eps[0] and eps[2] > 100 * eps[0]
    np.testing.assert_array_equal(ray_offsets(np.zeros((1, 3, 3)), np.zeros(3)), [0.0])  # degenerate


@pytest.mark.parametrize("accel", ["embree", "numba"])
def test_spawned_rays_never_hit_their_own_triangle(accel):
    """Rays leaving random triangles (sizes 0.01 to 100, up to 1000 units from the scene's centre,
    slivers of aspect 1e-3; half of them within 0.06 degrees of grazing) from the point offset by
    ray_offsets to their side never hit the triangle they left. What it detects: with Embree, an
    offset of a tenth of ray_offsets lets 1.3% of these rays re-hit (none at a quarter: its factor
    8 has a margin of 4); the float64 Numba BVH needs far less and checks the same contract."""
    g = np.random.default_rng(5)
    tris = []
    for size, dist, aspect in [(0.01, 100.0, 1.0), (1.0, 0.0, 1.0), (1.0, 1000.0, 1.0), (100.0, 10.0, 1.0),
                               (1.0, 10.0, 1e-3)]:
        for _ in range(40):
            a = g.normal(size=3)
            a /= np.linalg.norm(a)
            b = g.normal(size=3)
            b -= a * (a @ b)
            b /= np.linalg.norm(b)
            pts = np.array([np.zeros(3), a * size, a * size * g.random() + b * size * aspect])
            c = g.normal(size=3)
            tris.append(pts - pts.mean(axis=0) + c / np.linalg.norm(c) * dist + g.uniform(-3, 3, 3) * size)
    tri = np.array(tris)
    acc = make_accel(accel, tri)
    eps = ray_offsets(tri, acc.centre)
    m = 200_000
    idx = g.integers(0, len(tri), m)
    u = g.random((m, 2))
    u[u.sum(axis=1) > 1] = 1 - u[u.sum(axis=1) > 1]
    x = (1 - u.sum(axis=1))[:, None] * tri[idx, 0] + u[:, :1] * tri[idx, 1] + u[:, 1:] * tri[idx, 2]
    n = np.cross(tri[idx, 1] - tri[idx, 0], tri[idx, 2] - tri[idx, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = g.normal(size=(m, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    graze = g.random(m) < 0.5
    d[graze] -= n[graze] * (d[graze] * n[graze]).sum(axis=1, keepdims=True) * 0.999
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    side = np.sign((d * n).sum(axis=1))
    o = x + (side * eps[idx])[:, None] * n
    _, prim, _, _ = acc.intersect(o, d)
    assert not np.any(prim == idx), f"{int((prim == idx).sum())} of {m} rays hit the triangle they left"
