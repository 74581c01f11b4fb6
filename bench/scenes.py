"""Benchmark scenes written on demand into bench/results/scenes (not kept in the repository).

    open_scene(subdiv)   an icosphere of radius 1 (20 * 4^subdiv triangles: 3 -> 1280, 8 -> 1.31M)
                         resting on a 20 x 20 floor (y = -1) under a 2 x 2 quad light facing down
                         (y = 3, radiance 10); camera at (0, 1.5, 5) looking at the origin, fov 45
                         along x, 256 x 256. The sphere (diffuse 0.7) and the floor (diffuse 0.5)
                         are open to the black sky, so most paths end early.
    mitsuba_cornell()    Mitsuba 3's own `mi.cornell_box()` (needs mitsuba) exported to OBJ + MTL +
                         sidecar: the same triangles, reflectances, light and camera.

Each returns a dict: `obj` (our scene file, one OBJ with usemtl groups) and `parts`, a list of
(part OBJ, reflectance, radiance or None) holding the same geometry one material per file, for
Mitsuba's OBJ loader. Files are written once (to a temporary name, then renamed) and reused.
"""
import os

import numpy as np

from . import atomic

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FOLDER = os.path.join(ROOT, "bench", "results", "scenes")
CAMERA = {"origin": [0.0, 1.5, 5.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov": 45.0, "fov_axis": "x"}


def _obj_text(groups):
    """OBJ text for [(material name, vertices (V, 3), faces (F, 3) 0-based)]."""
    out = ["mtllib scene.mtl\n"]
    base = 1
    for name, v, f in groups:
        out.append(f"usemtl {name}\n")
        out.append(_block("v", v, "%.7g"))
        out.append(_block("f", np.asarray(f) + base, "%d"))
        base += len(v)
    return "".join(out)


def _block(key, a, fmt):
    a = np.asarray(a)
    line = f"{key} {fmt} {fmt} {fmt}\n"
    return "".join(line % tuple(r) for r in a.tolist())


def _write_text(path, text):
    atomic.write(path, lambda tmp: open(tmp, "w").write(text))


def _write(folder, groups, materials, sidecar):
    """Write scene.obj/.mtl/.json and one part_<name>.obj per group; return the scene dict."""
    os.makedirs(folder, exist_ok=True)
    obj = os.path.join(folder, "scene.obj")
    parts = []
    for name, v, f in groups:
        part = os.path.join(folder, f"part_{name}.obj")
        if not os.path.isfile(part):
            _write_text(part, _block("v", v, "%.7g") + _block("f", np.asarray(f) + 1, "%d"))
        kd, ke = materials[name]
        parts.append((part, kd, ke))
    if not os.path.isfile(obj):
        mtl = "".join(f"newmtl {n}\nKd {kd[0]} {kd[1]} {kd[2]}\n" + (f"Ke {ke[0]} {ke[1]} {ke[2]}\n" if ke else "")
                      for n, (kd, ke) in materials.items())
        _write_text(os.path.join(folder, "scene.mtl"), mtl)
        atomic.write_json(os.path.join(folder, "scene.json"), sidecar, indent=1)
        _write_text(obj, _obj_text(groups))  # last: its presence means the set is complete
    return {"obj": obj, "parts": parts, "camera": sidecar["camera"], "width": sidecar["film"]["width"],
            "height": sidecar["film"]["height"]}


def _quad(p, u, v):
    p, u, v = (np.asarray(a, float) for a in (p, u, v))
    return np.array([p, p + u, p + u + v, p + v]), np.array([[0, 1, 2], [0, 2, 3]])


def open_scene(subdiv):
    """The open scene with an icosphere of `subdiv` subdivisions (see the module docstring)."""
    import trimesh

    sph = trimesh.creation.icosphere(subdivisions=subdiv, radius=1.0)
    floor = _quad((-10, -1, 10), (20, 0, 0), (0, 0, -20))  # counter-clockwise seen from above: faces up
    light = _quad((-1, 3, -1), (2, 0, 0), (0, 0, 2))  # faces down
    groups = [("sphere", np.asarray(sph.vertices), np.asarray(sph.faces)), ("floor", *floor), ("light", *light)]
    materials = {"sphere": ([0.7] * 3, None), "floor": ([0.5] * 3, None), "light": ([0.0] * 3, [10.0] * 3)}
    sidecar = {"camera": CAMERA, "film": {"width": 256, "height": 256}, "render": {"max_depth": 8, "rr_depth": 5}}
    return _write(os.path.join(FOLDER, f"open-{len(sph.faces)}"), groups, materials, sidecar)


def mitsuba_cornell():
    """Mitsuba's `cornell_box()` exported (needs mitsuba; any variant)."""
    import mitsuba as mi

    if mi.variant() is None:
        mi.set_variant("scalar_rgb")
    d = mi.cornell_box()
    scene = mi.load_dict(d)
    groups, materials = [], {}
    for i, sh in enumerate(scene.shapes()):
        v = np.array(sh.vertex_positions_buffer(), dtype=np.float64).reshape(-1, 3)
        f = np.array(sh.faces_buffer(), dtype=np.int64).reshape(-1, 3)
        name = sh.id() or f"shape{i}"
        kd = [float(x) for x in np.array(sh.bsdf().eval_diffuse_reflectance(mi.SurfaceInteraction3f())).ravel()[:3]]
        ke = None
        if sh.emitter() is not None:
            ke = [float(x) for x in d["light"]["emitter"]["radiance"]["value"]]
        groups.append((name, v, f))
        materials[name] = (kd, ke)
    m = np.array(d["sensor"]["to_world"].matrix, dtype=np.float64)
    origin = m[:3, 3]
    camera = {"origin": origin.tolist(), "target": (origin + m[:3, 2]).tolist(), "up": m[:3, 1].tolist(),
              "fov": float(d["sensor"]["fov"]), "fov_axis": "x"}  # 'smaller' is x on a square film
    sidecar = {"camera": camera, "film": {"width": 256, "height": 256}, "render": {"max_depth": 8, "rr_depth": 5}}
    return _write(os.path.join(FOLDER, "mitsuba-cornell"), groups, materials, sidecar)
