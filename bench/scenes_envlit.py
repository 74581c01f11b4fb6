"""An environment-lit interior in Mitsuba 3 XML, written on demand (not kept in the repository),
in variants that add one feature at a time, for bench.vs_mitsuba and tests/test_envlit.py.

    write(folder, variant, width=64, height=48, spp=32, max_depth=6) -> path of scene.xml
    python -m bench.scenes_envlit room    # bench/results/scenes/envlit-room: `env` at 320 x 240, unbounded depth
    python -m bench.scenes_envlit dining-room    # bench/results/scenes/dining-room-sky (classroom too)

`envlit-room` is the guides' environment-lit interior (bench.schedule, bench.convergence with
`--scene-dir bench/results/scenes`). `dining-room-sky` and `classroom-sky` are Bitterli's sun-lit
scenes of ../shared/scenes-mitsuba with their `sunsky` emitter replaced by an envmap of the same
sun direction and size (sky_image: a sky gradient and a sun disk, not Mitsuba's sunsky model,
which the originals now render with: tracer.sunsky),
at 320 x 180; their meshes and textures are read from the shared folder. The references are in
bench/results/references/<name>-mitsuba.

The room is x in [-2, 2], y in [0, 2.5], z in [-8, 0], closed but for its openings: a window in the
back wall (z = -8) that the camera sees straight through, two windows in the left wall (x = -2)
that let the sun in onto the floor, and a skylight in the ceiling. The camera stands low near the
front wall (eye height 0.45) looking down the room, so the floor is seen at grazing angles and up
to 8 units away. Light comes only from an `envmap`: a 32 x 16 EXR of lognormal noise, independent
from texel to texel (so that any two ways of looking it up between texel centres differ), on a
sky gradient, with a 2 x 2-texel sun aimed through the left windows. Walls are diffuse, one-sided
(their inner side faces the room) or `twosided`; OBJ meshes with face normals and UVs.

Variants (each holds the features of the one before it):

    env        the envmap through the openings, plain diffuse walls (to_world identity)
    bilinear   + a 16 x 16 8-bit sRGB texture of random texels on the floor, `bilinear`, repeated
               4 x 8 times (many texels to a pixel far away, stretched at grazing angles)
    trilinear  + a 32 x 32 texture of stripes and noise, `trilinear`, on the ceiling and right wall
    mask       + a `mask` screen standing in the room (opacity a 16 x 16 grey PNG of holes, over a
               `twosided` diffuse) and a masked curtain over the first left window (one-sided diffuse)
    all        + `roughdiffuse` on the right wall and the envmap turned by a to_world rotation
"""
import os

import numpy as np

from . import atomic

VARIANTS = ("env", "bilinear", "trilinear", "mask", "all")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FOLDER = os.path.join(ROOT, "bench", "results", "scenes")
SUN = np.array([-1.0, 0.75, 0.35])  # world direction toward the sun: in through the left windows
ENV_W, ENV_H = 32, 16
ENV_ROT_Y = 25.0  # degrees, the `all` variant's envmap rotation about +y


def _feature(variant, name):
    return VARIANTS.index(variant) >= VARIANTS.index(name)


def _wall(origin, eu, ev, size_u, size_v, holes, uv_scale=(1.0, 1.0)):
    """Quads covering the rectangle origin + s eu + t ev (s in [0, size_u], t in [0, size_v]) but
    its holes [(s0, s1, t0, t1)]; (vertices (V, 3), uvs (V, 2), faces (F, 3)). Faces wind
    counter-clockwise seen from the side eu x ev points to; UVs are (s, t) over the sizes times
    uv_scale."""
    ss = sorted({0.0, size_u, *(h[0] for h in holes), *(h[1] for h in holes)})
    ts = sorted({0.0, size_v, *(h[2] for h in holes), *(h[3] for h in holes)})
    o, eu, ev = (np.asarray(a, float) for a in (origin, eu, ev))
    verts, uvs, faces = [], [], []
    for s0, s1 in zip(ss[:-1], ss[1:]):
        for t0, t1 in zip(ts[:-1], ts[1:]):
            sm, tm = 0.5 * (s0 + s1), 0.5 * (t0 + t1)
            if any(h[0] <= sm <= h[1] and h[2] <= tm <= h[3] for h in holes):
                continue
            k = len(verts)
            for s, t in ((s0, t0), (s1, t0), (s1, t1), (s0, t1)):
                verts.append(o + s * eu + t * ev)
                uvs.append((s / size_u * uv_scale[0], t / size_v * uv_scale[1]))
            faces += [(k, k + 1, k + 2), (k, k + 2, k + 3)]
    return np.array(verts), np.array(uvs), np.array(faces)


def _obj_text(verts, uvs, faces):
    lines = [f"v {x:.7g} {y:.7g} {z:.7g}\n" for x, y, z in verts]
    lines += [f"vt {u:.7g} {v:.7g}\n" for u, v in uvs]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}\n" for a, b, c in faces]
    return "".join(lines)


def _write_text(path, text):
    atomic.write(path, lambda tmp: open(tmp, "w").write(text))


def _rot_y(deg):
    a = np.radians(deg)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def envmap_image(rot_y=0.0, seed=7):
    """(ENV_H, ENV_W, 3) float32 radiance: a sky gradient times lognormal texel noise, the ground
    dim, and a 2 x 2-texel sun (radiance 150) in the direction SUN after a to_world rotation of
    rot_y degrees about +y (Mitsuba 3's lat-long convention: local direction (sin phi sin theta,
    cos theta, -cos phi sin theta), phi = 2 pi u, columns centred at u = (x + 1/2) / W, rows at
    v = y / (H - 1))."""
    rng = np.random.default_rng(seed)
    y = np.arange(ENV_H)[:, None] / (ENV_H - 1)
    sky = np.where(y < 0.5, 0.6 + 1.4 * y, 0.15)  # brighter toward the horizon, a dim ground
    tint = np.array([0.8, 0.9, 1.2])
    img = sky[..., None] * tint * rng.lognormal(0.0, 1.0, (ENV_H, ENV_W, 3))
    d = _rot_y(rot_y).T @ (SUN / np.linalg.norm(SUN))
    u = (np.arctan2(d[0], -d[2]) / (2 * np.pi)) % 1.0
    v = np.arccos(d[1]) / np.pi
    x0, y0 = int(np.floor(u * ENV_W - 0.5)), int(np.floor(v * (ENV_H - 1)))
    for dy in (0, 1):
        for dx in (0, 1):
            img[y0 + dy, (x0 + dx) % ENV_W] = (150.0, 140.0, 120.0)
    return img.astype(np.float32)


def textures(seed=11):
    """{name: linear image} of the variants' bitmaps: `floor` (16, 16, 3) random texels in
    [0.04, 0.9]; `stripes` (32, 32, 3) stripes times noise; `holes` (16, 16) opacity, 0 or 1 in
    most texels and 0.5 in some."""
    rng = np.random.default_rng(seed)
    floor = rng.uniform(0.04, 0.9, (16, 16, 3))
    x = np.arange(32)
    stripes = (0.15 + 0.7 * ((x[None, :] // 3) % 2))[..., None] * rng.uniform(0.5, 1.0, (32, 32, 3))
    holes = (rng.uniform(size=(16, 16)) < 0.55).astype(float)
    holes[rng.uniform(size=(16, 16)) < 0.15] = 0.5
    return {"floor": floor, "stripes": stripes, "holes": holes}


def write(folder, variant, width=64, height=48, spp=32, max_depth=6):
    """Write the scene `variant` (VARIANTS) with its meshes and images into `folder`; return the
    path of its scene.xml (written last, atomically)."""
    from tracer.imageio import write_image

    if variant not in VARIANTS:
        raise ValueError(f"unknown envlit variant {variant!r}; valid: {', '.join(VARIANTS)}")
    os.makedirs(folder, exist_ok=True)
    rot = ENV_ROT_Y if _feature(variant, "all") else 0.0
    write_image(os.path.join(folder, "sky.exr"), envmap_image(rot))
    for name, img in textures().items():
        write_image(os.path.join(folder, f"{name}.png"), img)
    W, H, D = 4.0, 2.5, 8.0
    meshes = {  # name: (origin, eu, ev, size_u, size_v, holes, uv scale); eu x ev points into the room
        "floor": ((-2, 0, 0), (1, 0, 0), (0, 0, -1), W, D, [], (4.0, 8.0)),
        "ceiling": ((-2, H, -D), (1, 0, 0), (0, 0, 1), W, D, [(1.5, 2.5, 3.0, 5.0)], (2.0, 4.0)),
        "left": ((-2, 0, 0), (0, 0, -1), (0, 1, 0), D, H, [(1.0, 2.5, 0.8, 2.0), (4.0, 5.5, 0.8, 2.0)], (1.0, 1.0)),
        "right": ((2, 0, -D), (0, 0, 1), (0, 1, 0), D, H, [], (4.0, 1.0)),
        "back": ((-2, 0, -D), (1, 0, 0), (0, 1, 0), W, H, [(1.0, 3.0, 0.7, 1.9)], (1.0, 1.0)),
        "front": ((2, 0, 0), (-1, 0, 0), (0, 1, 0), W, H, [], (1.0, 1.0)),
        "screen": ((-1.8, 0, -4.5), (1, 0, 0), (0, 1, 0), 1.3, 2.0, [], (2.0, 3.0)),
        "curtain": ((-1.9, 0.7, -0.9), (0, 0, -1), (0, 1, 0), 1.7, 1.4, [], (1.5, 1.0)),
    }
    for name, (o, eu, ev, su, sv, holes, sc) in meshes.items():
        _write_text(os.path.join(folder, f"{name}.obj"), _obj_text(*_wall(o, eu, ev, su, sv, holes, sc)))

    def bitmap(file, filt, name="reflectance"):
        return (f'<texture type="bitmap" name="{name}"><string name="filename" value="{file}"/>'
                f'<string name="filter_type" value="{filt}"/></texture>')

    wall = '<bsdf type="diffuse" id="{id}"><rgb name="reflectance" value="{rgb}"/></bsdf>'
    bsdfs = [wall.format(id="plain", rgb="0.62, 0.58, 0.52"), wall.format(id="front", rgb="0.5, 0.5, 0.55")]
    floor = (f'<bsdf type="diffuse" id="floor">{bitmap("floor.png", "bilinear")}</bsdf>'
             if _feature(variant, "bilinear") else wall.format(id="floor", rgb="0.45, 0.4, 0.35"))
    bsdfs.append(floor)
    if _feature(variant, "trilinear"):
        bsdfs.append(f'<bsdf type="twosided" id="striped"><bsdf type="diffuse">{bitmap("stripes.png", "trilinear")}'
                     f'</bsdf></bsdf>')
        kind = "roughdiffuse" if _feature(variant, "all") else "diffuse"
        alpha = '<float name="alpha" value="0.4"/>' if kind == "roughdiffuse" else ""
        bsdfs.append(f'<bsdf type="{kind}" id="right">{bitmap("stripes.png", "trilinear")}{alpha}</bsdf>')
    if _feature(variant, "mask"):
        bsdfs.append(f'<bsdf type="mask" id="screen">{bitmap("holes.png", "bilinear", "opacity")}'
                     f'<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.6, 0.25"/>'
                     f'</bsdf></bsdf></bsdf>')
        bsdfs.append(f'<bsdf type="mask" id="curtain">{bitmap("holes.png", "bilinear", "opacity")}'
                     f'<bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.75, 0.6"/></bsdf></bsdf>')
    use = {"floor": "floor", "ceiling": "plain", "left": "plain", "right": "plain", "back": "plain", "front": "front"}
    if _feature(variant, "trilinear"):
        use.update(ceiling="striped", right="right")
    if _feature(variant, "mask"):
        use.update(screen="screen", curtain="curtain")
    shapes = [f'<shape type="obj"><string name="filename" value="{name}.obj"/><boolean name="face_normals" '
              f'value="true"/><ref id="{b}"/></shape>' for name, b in use.items()]
    env_rot = f'<transform name="to_world"><rotate y="1" angle="{rot:g}"/></transform>' if rot else ""
    xml = f"""<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="{max_depth}"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="75"/>
        <transform name="to_world"><lookat origin="0.3, 0.45, -0.4" target="-0.2, 0.75, -8" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
        <film type="hdrfilm"><integer name="width" value="{width}"/><integer name="height" value="{height}"/>
            <rfilter type="box"/></film>
    </sensor>
    <emitter type="envmap"><string name="filename" value="sky.exr"/>{env_rot}</emitter>
    {chr(10).join('    ' + b for b in bsdfs).strip()}
    {chr(10).join('    ' + s for s in shapes).strip()}
</scene>
"""
    path = os.path.join(folder, "scene.xml")
    _write_text(path, xml)
    return path


def scene(variant, **kw):
    """write() into bench/results/scenes/envlit-<variant>; the path of its scene.xml."""
    return write(os.path.join(FOLDER, f"envlit-{variant}"), variant, **kw)


SUN_RADIUS_DEG = 0.5358  # Mitsuba 0.6's sun: its angular radius, times sunRadiusScale
SUN_TO_SKY = 5.0  # the sun's irradiance (at normal incidence) over the sky's on a horizontal plane
SKY_W, SKY_H = 1024, 512


def sky_image(sun_dir, sun_radius_deg, sky_scale=1.0):
    """(SKY_H, SKY_W, 3) float32: a stand-in for a sunsky emitter, in the lat-long convention of
    envmap_image: a blue sky brightening toward the horizon (radiance sky_scale / 6 at the zenith),
    a dim ground, and a sun disk of the given angular radius toward sun_dir whose irradiance at
    normal incidence is SUN_TO_SKY x the sky's on a horizontal plane. Not Mitsuba's sunsky model
    (issue 59 builds that): a sky of the same layout, for the guides' tests."""
    x = (np.arange(SKY_W) + 0.5) / SKY_W
    v = np.arange(SKY_H) / (SKY_H - 1)
    phi, theta = 2 * np.pi * x[None, :], np.pi * v[:, None]
    d = np.stack(np.broadcast_arrays(np.sin(phi) * np.sin(theta), np.cos(theta) + 0 * phi,
                                     -np.cos(phi) * np.sin(theta)), axis=-1)
    up = d[..., 1]
    zen = sky_scale / 6.0
    sky = np.where(up >= 0.0, zen * (1.0 + 2.0 * (1.0 - up) ** 3), 0.3 * zen)[..., None]
    img = sky * np.where(up[..., None] >= 0.0, np.array([0.55, 0.75, 1.2]), np.array([0.5, 0.45, 0.4]))
    # the sky's irradiance on a horizontal plane, by the map's own quadrature (texel solid angles)
    d_omega = (2 * np.pi / SKY_W) * (np.pi / (SKY_H - 1)) * np.sin(theta) * np.ones_like(phi)
    e_sky = float((img.mean(axis=-1) * np.maximum(up, 0.0) * d_omega).sum())
    s = np.asarray(sun_dir, float) / np.linalg.norm(sun_dir)
    inside = d @ s >= np.cos(np.radians(sun_radius_deg))
    omega = float((d_omega * inside).sum())
    tint = np.array([1.0, 0.95, 0.85])
    img[inside] = SUN_TO_SKY * e_sky / omega * tint / tint.mean()  # irradiance by the channels' mean
    return img.astype(np.float32)


def with_sky(src, dst, width=320, height=180):
    """Write dst/scene.xml: the Mitsuba 0.6 scene src/scene.xml with its `sunsky` emitter replaced by
    an `envmap` of sky_image() (its sunDirection, sunRadiusScale and skyScale), file names made
    absolute (the meshes and textures stay in src), and the film set to width x height. The path
    of the new scene.xml."""
    import re
    from tracer.imageio import write_image

    text = open(os.path.join(src, "scene.xml")).read()
    m = re.search(r'<emitter type="sunsky"\s*>(.*?)</emitter>', text, re.S)
    if m is None:
        raise ValueError(f"{src}/scene.xml: no sunsky emitter")
    body = m.group(1)

    def num(name, default):
        f = re.search(rf'name="{name}"\s+value="([^"]+)"', body)
        return float(f.group(1)) if f else default

    v = re.search(r'name="sunDirection"\s+x="([^"]+)"\s+y="([^"]+)"\s+z="([^"]+)"', body)
    sun = [float(v.group(i)) for i in (1, 2, 3)]
    os.makedirs(dst, exist_ok=True)
    write_image(os.path.join(dst, "sky.exr"), sky_image(sun, SUN_RADIUS_DEG * num("sunRadiusScale", 1.0),
                                                        num("skyScale", 1.0)))
    text = text[: m.start()] + '<emitter type="envmap"><string name="filename" value="sky.exr"/></emitter>' + \
        text[m.end():]
    src = os.path.abspath(src)
    text = re.sub(r'(name="filename"\s+value=")(?!sky\.exr)([^"]+)"',
                  lambda f: f'{f.group(1)}{os.path.join(src, f.group(2))}"', text)
    text = re.sub(r'(name="width"\s+value=")\d+"', rf'\g<1>{width}"', text)
    text = re.sub(r'(name="height"\s+value=")\d+"', rf'\g<1>{height}"', text)
    path = os.path.join(dst, "scene.xml")
    _write_text(path, text)
    return path


ROOM = dict(variant="env", width=320, height=240, max_depth=-1)  # the guides' environment-lit interior


def main(argv=None):
    import argparse

    p = argparse.ArgumentParser(prog="python -m bench.scenes_envlit", description="write a generated scene")
    p.add_argument("name", choices=("room", "classroom", "dining-room") + VARIANTS,
                   help="room (envlit-room), a shared sun-lit scene with a sky map for its sunsky (<name>-sky), "
                        "or a variant (envlit-<variant>)")
    p.add_argument("--shared", default=os.path.join(os.path.dirname(ROOT), "shared", "scenes-mitsuba"))
    a = p.parse_args(argv)
    if a.name in ("classroom", "dining-room"):
        print(with_sky(os.path.join(a.shared, a.name), os.path.join(FOLDER, f"{a.name}-sky")))
    elif a.name == "room":
        print(write(os.path.join(FOLDER, "envlit-room"), **ROOM))
    else:
        print(scene(a.name))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
