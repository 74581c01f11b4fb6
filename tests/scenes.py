"""Small analytic scenes written to a temporary folder for tests.

Each builder writes `name.obj`, `name.mtl` and `name.json` and returns the OBJ path.
"""
import json
import os

import numpy as np


def write_scene(folder, name, groups, materials, sidecar):
    """groups: [(material, vertices (n,3), faces (m,3) 0-based)]; materials: {name: mtl text}."""
    os.makedirs(folder, exist_ok=True)
    lines = [f"mtllib {name}.mtl"]
    nv = 0
    for mat, verts, faces in groups:
        lines.append(f"usemtl {mat}")
        lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in np.asarray(verts, dtype=float)]
        lines += [f"f {a + 1 + nv} {b + 1 + nv} {c + 1 + nv}" for a, b, c in np.asarray(faces)]
        nv += len(verts)
    obj = os.path.join(folder, f"{name}.obj")
    with open(obj, "w") as f:
        f.write("\n".join(lines) + "\n")
    with open(os.path.join(folder, f"{name}.mtl"), "w") as f:
        for mname, body in materials.items():
            f.write(f"newmtl {mname}\n{body.strip()}\n\n")
    if sidecar is not None:
        with open(os.path.join(folder, f"{name}.json"), "w") as f:
            json.dump(sidecar, f)
    return obj


def box_faces(lo, hi, inward):
    """Vertices (8,3) and 12 triangles of an axis-aligned box; CCW normals in or out."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], dtype=float)
    # outward-facing (CCW seen from outside)
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (3, 7, 6, 2), (0, 4, 7, 3), (1, 2, 6, 5)]
    faces = []
    for a, b, c, d in quads:
        faces += [(a, b, c), (a, c, d)]
    f = np.array(faces)
    if inward:
        f = f[:, ::-1]
    return v, f


def closed_box(folder, albedo, emission, width=16, height=16, spp=16, max_depth=-1):
    """A closed box whose six walls have Kd = albedo and emit Ke = emission inward.

    The camera sits inside, so every pixel reads Le * sum_k albedo^k over the depths allowed.
    """
    v, f = box_faces((-1, -1, -1), (1, 1, 1), inward=True)
    return write_scene(
        folder, "box", [("wall", v, f)],
        {"wall": f"Kd {albedo} {albedo} {albedo}\nKe {emission} {emission} {emission}"},
        {"camera": {"origin": [0, 0, 0.5], "target": [0, 0, -1], "up": [0, 1, 0], "fov": 90},
         "film": {"width": width, "height": height},
         "render": {"spp": spp, "max_depth": max_depth, "rr_depth": 5}},
    )


def icosphere(subdiv=2):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdiv)
    return np.asarray(m.vertices), np.asarray(m.faces)


def sphere_under_sky(folder, albedo, radiance, env=None, width=24, height=24):
    """A convex diffuse sphere of Kd = albedo under a constant sky (or `env` dict)."""
    v, f = icosphere(2)
    return write_scene(
        folder, "sky", [("ball", v, f)], {"ball": f"Kd {albedo} {albedo} {albedo}"},
        {"camera": {"origin": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 35},
         "film": {"width": width, "height": height},
         "environment": env if env is not None else {"radiance": [radiance] * 3},
         "render": {"spp": 16, "max_depth": -1}},
    )


def light_quad(folder, radiance, width=8, height=8):
    """The camera looks straight at a large one-sided emitter facing it."""
    v = np.array([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], dtype=float)
    f = np.array([[0, 1, 2], [0, 2, 3]])  # CCW seen from +z: faces the camera
    return write_scene(
        folder, "lamp", [("lamp", v, f)], {"lamp": f"Kd 0 0 0\nKe {radiance[0]} {radiance[1]} {radiance[2]}"},
        {"camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 30},
         "film": {"width": width, "height": height}, "render": {"spp": 4, "max_depth": 1}},
    )


def textured(scene):
    """`scene` (a loaded Scene, changed in place and returned) with what the material step reads:
    planar UVs, a checkerboard (two colours, 4 x 4 per unit of UV) on the kd of every diffuse
    material, materials named floor and furniture made Mitsuba's smooth and rough plastic (COATED,
    textured), and corner normals tilted off the face normals by up to ~10 degrees, varying
    smoothly with position (shading normals: the light-leak mask and the photons' adjoint factor
    act)."""
    from tracer import bsdfs
    from tracer.material import N_TEX_SLOTS
    from tracer.scene import prepare_coats
    from tracer.textures import TextureSpec, build_textures

    tri = scene.tri
    uv = 0.37 * np.stack([tri[..., 0] + tri[..., 2], tri[..., 1]], axis=-1)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    tilt = 0.17 * np.sin(np.stack([2.1 * tri[..., 1] + 0.3, 1.7 * tri[..., 2] + 1.1, 1.3 * tri[..., 0] + 2.0], -1))
    vn = n[:, None, :] + tilt
    vn /= np.linalg.norm(vn, axis=2, keepdims=True)
    scene.tri_uv = np.ascontiguousarray(uv)
    scene.tri_vn = np.ascontiguousarray(vn)
    scene.textures = build_textures([TextureSpec("checker", color0=(0.8, 0.35, 0.2), color1=(0.25, 0.6, 0.75),
                                                 uv=(4.0, 0.0, 0.0, 0.0, 4.0, 0.0))], [])
    mats = scene.materials
    mats.tex = np.full((len(mats.names), N_TEX_SLOTS), -1, np.int32)
    mats.tex[mats.type == bsdfs.DIFFUSE, 0] = 0
    # ajar's floor: Mitsuba's smooth plastic (a delta lobe beside the diffuse one); its furniture:
    # a rough GGX plastic (both textured)
    for name, alpha in (("floor", 0.0), ("furniture", 0.2)):
        if name in mats.names:
            m = mats.names.index(name)
            mats.type[m] = bsdfs.COATED
            mats.param[m, bsdfs.P_KS:bsdfs.P_KS + 3] = 1.0
            mats.param[m, bsdfs.P_ALPHA] = alpha
            mats.param[m, bsdfs.P_IOR] = 1.5
    prepare_coats(mats, scene.textures)
    return scene


def builtin(root, name, width, height):
    """A built-in scene by name at width x height; `NAME-textured` is NAME through textured(),
    `NAME-black` NAME through blackened()."""
    import tracer

    base, _, variant = name.partition("-")
    scene = tracer.load_scene(os.path.join(root, "scenes", base, f"{base}.obj"), width=width, height=height)
    return {"": lambda s: s, "textured": textured, "black": blackened}[variant](scene)


def blackened(scene, names=("red",)):
    """`scene` (changed in place and returned) with the diffuse materials `names` black (Kd 0): a
    path that reaches them has throughput 0 from there on."""
    from tracer import bsdfs

    mats = scene.materials
    for name in names:
        m = mats.names.index(name)
        mats.param[m, bsdfs.P_KD:bsdfs.P_KD + 3] = 0.0
    return scene
