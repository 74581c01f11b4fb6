"""A camera for a scene that gives none: the view, among a few, whose tiny preview is most lit.

A bare OBJ has no camera. Framing its bounding box from outside shows a closed room from
behind its walls, or an open box from its closed side: a black image. `frame_camera` instead
renders a tiny preview (FRAME_SIZE pixels on the long side, FRAME_SPP samples) from each of
these views and picks by how many of its pixels received light:

- from outside, on each side of the bounding box (+z first: the view a bare OBJ always had),
  far enough back that the whole box fits the field of view, looking at its centre;
- from inside, near the centre of the light's reach: rays cast from the emitters' lit sides stop
  at the first surface; the midpoint of each such segment is empty space the light crosses, and
  their median is the anchor. From the anchor the camera backs away along each horizontal axis
  (up to the wall behind it, or half the lit region's extent), looking through the anchor. The
  bounding box's centre is a second anchor (a scene lit by an environment has no emitters).

An outside view shows the whole scene: one from the sides whose visible surfaces are mostly lit
wins (the +z one unless another lights KEEP_DEFAULT times as many pixels, so a scene that framed
well before keeps its view), else such a view from above or below; only when none is (a closed
room seen from outside) does the most lit view win, usually one from inside. Image up is the
scene's up (+y, the OBJ convention, unless the sidecar gives camera.up), whose nearest coordinate
axis decides which views are horizontal. Returns the camera's (origin, target, up) and a one-line
description of the view.
"""
import dataclasses
import math

import numpy as np

FRAME_SIZE = 32  # preview pixels on the image's long side
FRAME_SPP = 4
FRAME_DEPTH = 8  # longest preview path (the scene's own limit when smaller)
KEEP_DEFAULT = 1.25  # another view must light this many times the default's pixels to replace it
LIGHT_RAYS = 512  # rays cast from the emitters to find the light's reach


def view_axes(up=(0.0, 1.0, 0.0)):
    """[(name, direction (3,), image up (3,))] of the six axis views: the four horizontal ones
    first (+z, -z, +x, -x when `up` is +y, the default view first), then the two along the
    coordinate axis nearest to `up`. A direction is the side the camera stands on; a horizontal
    view's image up is `up`, a vertical one's the first horizontal axis."""
    up = np.asarray(up, dtype=np.float64)
    u = int(np.argmax(np.abs(up)))
    sign = 1.0 if up[u] >= 0.0 else -1.0
    horizontal = [a for a in (2, 0, 1) if a != u]
    views = []
    for a in horizontal:
        for s_ in (1.0, -1.0):
            d = np.zeros(3)
            d[a] = s_
            views.append((f"{'+' if s_ > 0 else '-'}{'xyz'[a]}", d, up))
    for s_ in (1.0, -1.0):
        d = np.zeros(3)
        d[u] = s_ * sign
        v_up = np.zeros(3)
        v_up[horizontal[0]] = -s_
        views.append((f"{'+' if s_ * sign > 0 else '-'}{'xyz'[u]}", d, v_up))
    return views


def outside_view(bounds, fov, d=(0.0, 0.0, 1.0)):
    """(origin, target) on side `d` (a unit axis) of the bounding box, at the distance where a
    sphere around the box fits the field of view `fov` (degrees), looking at the box's centre."""
    centre = 0.5 * (bounds[0] + bounds[1])
    extent = bounds[1] - bounds[0]
    d = np.asarray(d, dtype=np.float64)
    dist = 0.5 * float(np.linalg.norm(extent)) / math.tan(math.radians(fov) / 2.0)
    origin = centre + d * (0.5 * float(np.abs(d) @ extent) + dist)
    return origin, centre


def _light_reach(scene, accel, rng):
    """(anchor (3,), lit bounds (2, 3)) from rays cast off the emitters' lit sides, or None when
    the scene has no emitter or no such ray hits anything."""
    from .bvh import ray_offsets

    emissive = np.flatnonzero(scene.emissive)
    if emissive.size == 0:
        return None
    tri = scene.tri[emissive]
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cr, axis=1)
    power = area2 * scene.materials.emission[scene.tri_material[emissive]].sum(axis=1)
    pick = rng.choice(emissive.size, size=LIGHT_RAYS, p=power / power.sum())
    u, v = rng.random(LIGHT_RAYS), rng.random(LIGHT_RAYS)
    flip = u + v > 1.0
    u, v = np.where(flip, 1.0 - u, u), np.where(flip, 1.0 - v, v)
    t = tri[pick]
    p = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    n = cr[pick] / area2[pick, None]
    # cosine-distributed directions about n (the counter-clockwise side, the one that emits)
    r1, r2 = rng.random(LIGHT_RAYS), rng.random(LIGHT_RAYS)
    a = np.where(np.abs(n[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    b1 = np.cross(n, a)
    b1 /= np.linalg.norm(b1, axis=1, keepdims=True)
    b2 = np.cross(n, b1)
    s, phi = np.sqrt(r1), 2.0 * np.pi * r2
    d = b1 * (s * np.cos(phi))[:, None] + b2 * (s * np.sin(phi))[:, None] + n * np.sqrt(1.0 - r1)[:, None]
    org = p + n * ray_offsets(t, accel.centre)[:, None]
    dist, _, _, _ = accel.intersect(org, d)
    hit = np.isfinite(dist)
    if not hit.any():
        return None
    ends = org[hit] + d[hit] * dist[hit, None]
    mids = 0.5 * (org[hit] + ends)
    lit = np.concatenate([ends, p[hit]])
    return np.median(mids, axis=0), np.percentile(lit, [5.0, 95.0], axis=0)


def _inside_views(anchor, reach, accel, axes):
    """(origin, target, up, name) backing away from `anchor` along each horizontal axis of `axes`
    (view_axes), looking through it."""
    views = []
    extent = reach[1] - reach[0]
    for name, side, up in axes[:4]:
        d = -side  # the viewing direction
        back, _, _, _ = accel.intersect(anchor[None], side[None])
        step = min(0.9 * float(back[0]), 0.5 * float(np.abs(d) @ extent))
        if not step > 0.0:
            continue
        views.append((anchor - d * step, anchor + d, up, f"inside, looking {'-+'[name[0] == '-']}{name[1]}"))
    return views


def lit_share(image):
    """Share of an image's pixels ((..., 3)) whose luminance is above zero."""
    from .lights import luminance

    return float((luminance(image) > 0.0).mean())


def frame_camera(scene, fov, fov_axis="x", up=(0.0, 1.0, 0.0)):
    """((origin, target, up), description) of the view of `scene` (a Scene whose camera is
    ignored) whose preview lights the most pixels, `up` being the scene's up; see the module
    docstring."""
    from .bvh import make_accel
    from .camera import Camera
    from .context import RenderContext
    from .errors import SettingsError
    from .film import Film
    from .lights import build_lights
    from .session import trace_source
    from .sources import CameraSource
    from .wave import WaveBuffers

    bounds = scene.bounds
    try:
        accel = make_accel("embree", scene.tri)
    except SettingsError:  # no embreex: the Numba BVH answers the same queries
        accel = make_accel("numba", scene.tri)
    axes = view_axes(up)
    views = [(*outside_view(bounds, fov, d), v_up, f"outside, from {name}") for name, d, v_up in axes]
    reach = _light_reach(scene, accel, np.random.default_rng(0))
    anchors = [] if reach is None else [reach]
    anchors.append((0.5 * (bounds[0] + bounds[1]), bounds))
    for anchor, box in anchors:
        views += _inside_views(anchor, box, accel, axes)

    aspect = scene.width / scene.height
    w = FRAME_SIZE if aspect >= 1.0 else max(1, round(FRAME_SIZE * aspect))
    h = max(1, round(FRAME_SIZE / aspect)) if aspect >= 1.0 else FRAME_SIZE
    small = dataclasses.replace(scene, width=w, height=h)
    depth = FRAME_DEPTH if scene.render.max_depth < 0 else min(scene.render.max_depth, FRAME_DEPTH)
    ctx = RenderContext(small, accel, build_lights(scene), 0, depth, scene.render.rr_depth, "box", (0, 0, w, h))
    buf = WaveBuffers(w * h * FRAME_SPP)
    lit, seen = [], []
    for origin, target, up, _ in views:
        ctx.cam = Camera.look_at(origin, target, up, fov, fov_axis, w, h).packed()
        film = Film(w, h)
        trace_source(ctx, CameraSource(), film, FRAME_SPP, buf=buf)
        image, hit = film.mean(), film.aovs()["depth"][:, :, 0] > 0.0
        lit.append(lit_share(image))
        seen.append(lit_share(image[hit]) if hit.any() else 0.0)
    best = choose_view(lit, seen, tiers=([0, 1, 2, 3], [4, 5]))  # from the sides first, then from above or below
    origin, target, up, name = views[best]
    return (origin, target, up), f"{name} ({lit[best]:.0%} of a {w}x{h} preview lit)"


def choose_view(lit, seen, tiers):
    """Index of the chosen view, given each view's share of lit pixels (`lit`) and share of lit
    pixels among those that hit a surface (`seen`). `tiers` lists groups of outside views (view 0,
    the default, in the first): the first group with a view whose surfaces are mostly lit
    (seen >= 0.5) gives the most lit of those, the default unless another lights KEEP_DEFAULT
    times its pixels. With none (a closed room seen from outside), the view with the most lit
    pixels of all."""
    for tier in tiers:
        good = [i for i in tier if seen[i] >= 0.5 and lit[i] > 0.0]
        if good:
            best = max(good, key=lambda i: lit[i])
            return 0 if 0 in good and lit[0] * KEEP_DEFAULT >= lit[best] else best
    return int(np.argmax(lit))
