"""Writes the path-guiding test scenes: scenes/<name>/<name>.{obj,mtl,json} for each name.

Run: `python scenes/build_scenes.py [name ...]` (no name: all six). Everything is built
here with numpy (quads -> 2 triangles, boxes, a UV sphere); random placements use fixed
seeds, so every run writes the same files (sky.exr: same pixels; OpenImageIO stamps a
DateTime in its header). Units are metres, +y up. Emitters are
one-sided (`Ke`, counter-clockwise normal = emitting side; every emitter is checked against
the direction it should face); all other surfaces are two-sided. Each sidecar holds the
camera, a film whose longer side is 256 and the render defaults {spp 16, max_depth -1,
rr_depth 5}. The Cornell box is written by scenes/build_cornell.py.

ajar: a furnished room whose only light is a bright panel in a small closed corridor behind
a door left ajar by ~13 degrees; nearly all light enters through the narrow gap and reaches
the camera after two or more bounces. Stresses difficult visibility: next-event estimation
and BSDF sampling both rarely find the gap. Guiding that learns incident radiance (path
guiding, e.g. SD-trees / learned samplers) should help a lot; unguided BSDF sampling and
light sampling do badly.

glossy: a diffuse room with a mirror panel, two rough-metal boxes (GGX alpha 0.04 and 0.16)
and a glossy-plastic sphere under one ceiling light. Stresses product sampling: guiding that
ignores the BSDF (incident-radiance-only guiding) wastes samples on narrow lobes and should
lose to BSDF sampling there, while BSDF x radiance product guiding should help; mirror
paths break any method that guides at delta vertices.

caustic: a glass sphere (dielectric, IOR 1.5, ~2k triangles) on a small pedestal over a
diffuse floor in a box room, lit by one small ceiling light off to the side, so a focused
caustic forms on the floor. Light-source-to-specular-to-diffuse (LSDE) paths: next-event
estimation cannot reach the light through the glass and BSDF sampling rarely hits the small
light; guiding that learns the caustic direction should help dramatically, unguided paths
leave fireflies.

manylights: a 8 x 8 m room divided by partition walls into a 3 x 3 maze of compartments
linked by doorways, with 48 small emitters of varied colours and intensities (fixed seed)
spread over the compartments; the camera sees 2-3 compartments and most lights are
occluded from most points. Stresses light selection (uniform/power-based NEE wastes samples
on occluded lights); methods that learn which lights (or directions) matter per region
should help, a single global guiding distribution breaks.

window: a closed room whose only opening is a window, lit only by an HDR sky map (64 x 32,
sky ~1, a sun of ~1000 in a few pixels, written to scenes/window/sky.exr); the sun shines
through the window onto the floor. Stresses environment lighting through a small aperture:
importance sampling the map picks the sun and sky mostly behind walls; guiding that learns
the window direction (and the bright floor patch as a secondary source) should help.

spotlit: a dim room with a rough-metal floor (GGX alpha 0.09) and glossy plastic blocks,
lit only by 3 small emitters at the back of closed reflector boxes (two dark diffuse
inside, one mirror-lined) that point away from the camera toward the walls and ceiling;
light reaches the camera only via indirect paths. Stresses indirect-dominated glossy
transport: NEE almost always hits the reflector backs; guiding of secondary bounces toward
the lit patches should help, BSDF-only sampling on glossy surfaces is noisy.
"""
import json
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
RENDER = {"spp": 16, "max_depth": -1, "rr_depth": 5, "seed": 0}


# ----------------------------------------------------------------------------- geometry

def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def rect(center, u, v, facing=None):
    """Quad centre +- u +- v (half-extent vectors) as (4,3) vertices and 2 triangles.

    The CCW normal is u x v; if `facing` is given the winding is flipped as needed so the
    normal points along it.
    """
    c, u, v = (np.asarray(a, dtype=float) for a in (center, u, v))
    if facing is not None and np.dot(np.cross(u, v), facing) < 0:
        v = -v
    verts = np.array([c - u - v, c + u - v, c + u + v, c - u + v])
    return verts, np.array([[0, 1, 2], [0, 2, 3]])


def rect_span(o, a, b, a0, a1, b0, b1, facing):
    """Quad over [a0,a1] x [b0,b1] in the plane o + s*a + t*b (a, b unit vectors)."""
    o, a, b = (np.asarray(x, dtype=float) for x in (o, a, b))
    c = o + a * (a0 + a1) / 2 + b * (b0 + b1) / 2
    return rect(c, a * (a1 - a0) / 2, b * (b1 - b0) / 2, facing)


def wall_with_hole(o, a, b, width, height, hole, facing):
    """A width x height wall in plane o + s*a + t*b with a rectangular hole
    (s0, s1, t0, t1): up to 4 quads (below, above, left, right of the hole)."""
    s0, s1, t0, t1 = hole
    spans = [(0, width, 0, t0), (0, width, t1, height), (0, s0, t0, t1), (s1, width, t0, t1)]
    return [rect_span(o, a, b, *sp, facing) for sp in spans if sp[1] > sp[0] and sp[3] > sp[2]]


def box(lo, hi, inward=False, rot=None, origin=None, skip=()):
    """Axis-aligned box [lo, hi] (12 triangles), normals out (or in); then optionally
    x -> rot @ x + origin. `skip` drops faces by name: -x +x -y +y -z +z."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], dtype=float)
    quads = {"-z": (0, 3, 2, 1), "+z": (4, 5, 6, 7), "-y": (0, 1, 5, 4), "+y": (3, 7, 6, 2),
             "-x": (0, 4, 7, 3), "+x": (1, 2, 6, 5)}  # CCW seen from outside
    f = []
    for name, (a, b, c, d) in quads.items():
        if name not in skip:
            f += [(a, b, c), (a, c, d)]
    f = np.array(f)
    if inward:
        f = f[:, ::-1]
    if rot is not None:
        v = v @ np.asarray(rot, dtype=float).T
    if origin is not None:
        v = v + np.asarray(origin, dtype=float)
    return v, f


def rot_y(deg):
    """Rotation about +y taking +x toward +z by `deg` degrees (x -> (cos, 0, sin))."""
    t = math.radians(deg)
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])


def frame(w):
    """Orthonormal (u, v, w) columns with w = unit(w)."""
    w = unit(w)
    h = np.array([0.0, 1.0, 0.0]) if abs(w[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = unit(np.cross(h, w))
    v = np.cross(w, u)
    return np.stack([u, v, w], axis=1)


def uv_sphere(center, radius, n_lat=32, n_lon=32):
    """UV sphere with CCW normals outward: 2 * n_lon * (n_lat - 1) triangles."""
    verts = [[0.0, 1.0, 0.0]]
    for i in range(1, n_lat):
        th = math.pi * i / n_lat
        for j in range(n_lon):
            ph = 2 * math.pi * j / n_lon
            verts.append([math.sin(th) * math.cos(ph), math.cos(th), math.sin(th) * math.sin(ph)])
    verts.append([0.0, -1.0, 0.0])
    verts = np.array(verts)
    bottom = len(verts) - 1
    ring = lambda i, j: 1 + (i - 1) * n_lon + (j % n_lon)  # noqa: E731
    faces = []
    for j in range(n_lon):
        faces.append((0, ring(1, j + 1), ring(1, j)))
        faces.append((bottom, ring(n_lat - 1, j), ring(n_lat - 1, j + 1)))
    for i in range(1, n_lat - 1):
        for j in range(n_lon):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)
            faces += [(a, b, c), (a, c, d)]
    faces = np.array(faces)
    # orient outward (checked, not assumed)
    tri = verts[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    if np.mean(np.einsum("ij,ij->i", n, tri.mean(1))) < 0:
        faces = faces[:, ::-1]
    return verts * radius + np.asarray(center, dtype=float), faces


class Scene:
    def __init__(self, name):
        self.name = name
        self.groups = {}  # material -> list of (verts, faces)
        self.materials = {}

    def material(self, name, body):
        self.materials[name] = body.strip()

    def add(self, mat, *meshes):
        for v, f in meshes:
            self.groups.setdefault(mat, []).append((np.asarray(v, dtype=float), np.asarray(f)))

    def emitter(self, mat, center, u, v, facing):
        """A one-sided emissive quad whose CCW normal is `facing` (asserted)."""
        verts, faces = rect(center, u, v, facing)
        for a, b, c in faces:
            n = np.cross(verts[b] - verts[a], verts[c] - verts[a])
            assert np.dot(unit(n), unit(facing)) > 0.999, (self.name, mat)
        self.add(mat, (verts, faces))

    def triangle_count(self):
        return sum(len(f) for meshes in self.groups.values() for _, f in meshes)

    def write(self, sidecar, folder=None):
        folder = folder or os.path.join(HERE, self.name)
        os.makedirs(folder, exist_ok=True)
        lines = [f"# {self.name}: written by scenes/build_scenes.py", f"mtllib {self.name}.mtl"]
        nv = 0
        for mat, meshes in self.groups.items():
            lines += [f"o {mat}", f"usemtl {mat}"]
            for verts, faces in meshes:
                lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts]
                lines += [f"f {a + 1 + nv} {b + 1 + nv} {c + 1 + nv}" for a, b, c in faces]
                nv += len(verts)
        with open(os.path.join(folder, f"{self.name}.obj"), "w") as f:
            f.write("\n".join(lines) + "\n")
        with open(os.path.join(folder, f"{self.name}.mtl"), "w") as f:
            f.write(f"# {self.name} materials\n")
            for mname, body in self.materials.items():
                f.write(f"newmtl {mname}\n{body}\n\n")
        sidecar = dict(sidecar)
        sidecar.setdefault("render", dict(RENDER))
        with open(os.path.join(folder, f"{self.name}.json"), "w") as f:
            json.dump(sidecar, f, indent=1)
            f.write("\n")
        return folder


def room(s, mat, lo, hi, floor_mat=None, skip=()):
    """Closed room: six inward-facing quads (two triangles each); `skip` as in `box`."""
    v, f = box(lo, hi, inward=True, skip=skip)
    if floor_mat is None:
        s.add(mat, (v, f))
        return
    floor = box(lo, hi, inward=True, skip=[k for k in ("-x", "+x", "+y", "-z", "+z")] + list(skip))
    rest = box(lo, hi, inward=True, skip=["-y"] + list(skip))
    s.add(floor_mat, floor)
    s.add(mat, rest)


def camera(origin, target, fov=60.0):
    return {"origin": list(map(float, origin)), "target": list(map(float, target)),
            "up": [0, 1, 0], "fov": fov, "fov_axis": "x"}


# ----------------------------------------------------------------------------- scenes

def build_ajar():
    s = Scene("ajar")
    s.material("wall", "Kd 0.7 0.7 0.7")
    s.material("floor", "Kd 0.5 0.5 0.5")
    s.material("furniture", "Kd 0.6 0.45 0.3")
    s.material("door", "Kd 0.55 0.5 0.45")
    s.material("light", "Kd 0 0 0\nKe 250 230 190")
    W, H, D = 5.0, 2.6, 4.0  # room x, y, z; the door wall is z = D
    dx0, dx1, dh = 2.0, 2.9, 2.1  # door opening
    # room without its back wall, then the back wall with the door hole (facing -z, into the room)
    room(s, "wall", (0, 0, 0), (W, H, D), floor_mat="floor", skip=("+z",))
    s.add("wall", *wall_with_hole((0, 0, D), (1, 0, 0), (0, 1, 0), W, H, (dx0, dx1, 0, dh), (0, 0, -1)))
    # closed corridor behind the door wall (its -z side is the door wall itself)
    cx0, cx1, cz1 = 0.8, 4.2, D + 1.4
    room(s, "wall", (cx0, 0, D), (cx1, H, cz1), floor_mat="floor", skip=("-z",))
    # the light on the corridor's back wall, facing the door (-z)
    s.emitter("light", (2.45, 1.3, cz1 - 0.01), (0.4, 0, 0), (0, 0.4, 0), facing=(0, 0, -1))
    # door panel: hinged at the left jamb, swung 13 degrees into the corridor
    s.add("door", box((0, 0.01, 0), (dx1 - dx0 - 0.01, dh - 0.01, 0.04), rot=rot_y(13), origin=(dx0, 0, D)))
    # furniture
    s.add("furniture",
          box((0.6, 0, 1.6), (1.8, 0.75, 2.4)),       # table
          box((4.3, 0, 1.2), (4.95, 1.8, 2.4)),       # cabinet
          box((0.1, 0, 0.6), (0.8, 0.5, 1.4)),        # low chest
          box((3.2, 0, 3.3), (3.9, 1.0, 3.9)))        # sideboard by the door wall
    s.write({"camera": camera((2.5, 1.5, 0.25), (2.45, 1.0, D), 60),
             "film": {"width": 256, "height": 192}})
    return s


def build_glossy():
    s = Scene("glossy")
    s.material("wall", "Kd 0.7 0.7 0.7")
    s.material("floor", "Kd 0.5 0.5 0.5")
    s.material("red", "Kd 0.6 0.1 0.08")
    s.material("mirror", "illum 3\nKs 0.9 0.9 0.9")
    s.material("metal_smooth", "Kd 0.8 0.6 0.3\nKs 0.8 0.6 0.3\nPr 0.2\nPm 1")
    s.material("metal_rough", "Kd 0.8 0.8 0.8\nKs 0.8 0.8 0.8\nPr 0.4\nPm 1")
    s.material("plastic", "Kd 0.3 0.3 0.3\nKs 0.3 0.3 0.3\nNs 200")
    s.material("light", "Kd 0 0 0\nKe 15 14 12")
    room(s, "wall", (-2.5, 0, -2.5), (2.5, 3, 2.5), floor_mat="floor", skip=("-x",))
    s.add("red", rect((-2.5, 1.5, 0), (0, 1.5, 0), (0, 0, 2.5), facing=(1, 0, 0)))
    s.emitter("light", (0, 2.99, 0.3), (0.5, 0, 0), (0, 0, 0.5), facing=(0, -1, 0))
    # mirror panel on the back wall, slightly tilted
    m = rot_y(-15)
    mv, mf = rect((0, 0, 0), (0.9, 0, 0), (0, 0.8, 0), facing=(0, 0, -1))
    s.add("mirror", (mv @ m.T + np.array([0.6, 1.4, 2.45]), mf))
    s.add("metal_smooth", box((-0.35, 0, -0.35), (0.35, 0.9, 0.35), rot=rot_y(25), origin=(-1.3, 0, 0.9)))
    s.add("metal_rough", box((-0.3, 0, -0.3), (0.3, 0.5, 0.3), rot=rot_y(-20), origin=(1.4, 0, 0.2)))
    s.add("plastic", uv_sphere((0.0, 0.5, 0.3), 0.5, 24, 32))
    s.write({"camera": camera((0.2, 1.5, -2.3), (0.0, 0.8, 1.0), 60),
             "film": {"width": 256, "height": 192}})
    return s


def build_caustic():
    s = Scene("caustic")
    s.material("wall", "Kd 0.7 0.7 0.7")
    s.material("floor", "Kd 0.6 0.6 0.6")
    s.material("pedestal", "Kd 0.4 0.4 0.45")
    s.material("glass", "illum 7\nNi 1.5\nKs 1 1 1")
    s.material("light", "Kd 0 0 0\nKe 400 380 340")
    room(s, "wall", (-2, 0, -2), (2, 3, 2), floor_mat="floor")
    # small light (0.2 m = 5% of the ceiling width) above and to the side, facing down
    s.emitter("light", (-1.0, 2.99, 0.2), (0.1, 0, 0), (0, 0, 0.1), facing=(0, -1, 0))
    s.add("pedestal", box((-0.1, 0, -0.1), (0.1, 0.5, 0.1)))
    s.add("glass", uv_sphere((0, 1.08, 0), 0.6, 32, 32))
    s.write({"camera": camera((1.0, 2.5, -1.9), (0.2, 0.6, 0.3), 65),
             "film": {"width": 256, "height": 192}})
    return s


def build_manylights():
    s = Scene("manylights")
    rng = np.random.default_rng(48)
    s.material("wall", "Kd 0.7 0.7 0.7")
    s.material("floor", "Kd 0.5 0.5 0.5")
    s.material("partition", "Kd 0.65 0.6 0.55")
    L, H, n, t = 8.0, 2.5, 3, 0.1
    cell = L / n
    room(s, "wall", (0, 0, 0), (L, H, L), floor_mat="floor")
    # interior partition segments; a doorway (0.9 m) in some segments, solid elsewhere
    doors = rng.random((2, n - 1, n)) < 0.6
    doors[0, 0, 0] = doors[1, 0, 0] = True  # the camera's cell opens to its two neighbours
    for axis in range(2):  # 0: walls at x = k * cell (running along z); 1: at z = k * cell
        for k in range(1, n):
            for j in range(n):
                a0, a1 = j * cell, (j + 1) * cell
                pieces = [(a0, a1)]
                if doors[axis, k - 1, j]:
                    d0 = a0 + 0.3 + rng.random() * (cell - 1.5)
                    pieces = [(a0, d0), (d0 + 0.9, a1)]
                for p0, p1 in pieces:
                    c = k * cell
                    lo = (c - t / 2, 0, p0) if axis == 0 else (p0, 0, c - t / 2)
                    hi = (c + t / 2, H, p1) if axis == 0 else (p1, H, c + t / 2)
                    s.add("partition", box(lo, hi))
    # 48 small emitters, spread over the 9 cells, on the ceiling (down) or the floor (up)
    for i in range(48):
        cx, cz = i % 9 % n, i % 9 // n
        x = cx * cell + 0.35 + rng.random() * (cell - 0.7)
        z = cz * cell + 0.35 + rng.random() * (cell - 0.7)
        hue = rng.random()
        col = np.clip(np.abs((hue * 6 + np.array([0, 4, 2])) % 6 - 3) - 1, 0, 1) * 0.8 + 0.2
        power = math.exp(rng.uniform(math.log(5), math.log(60)))
        ke = col * power / col.mean()
        name = f"light{i:02d}"
        s.material(name, f"Kd 0 0 0\nKe {ke[0]:.3f} {ke[1]:.3f} {ke[2]:.3f}")
        size = 0.06 + 0.06 * rng.random()
        if rng.random() < 0.5:
            s.emitter(name, (x, H - 0.01, z), (size, 0, 0), (0, 0, size), facing=(0, -1, 0))
        else:
            s.emitter(name, (x, 0.01, z), (size, 0, 0), (0, 0, size), facing=(0, 1, 0))
    s.write({"camera": camera((0.4, 1.6, 0.4), (4.0, 1.0, 3.2), 70),
             "film": {"width": 256, "height": 192}})
    return s


def sky_map(sun_dir, w=64, h=32):
    """Equirectangular sky (README convention): blue-ish ~1 above the horizon, dim ground,
    a 2x2-pixel sun of ~1000 centred on `sun_dir`."""
    img = np.zeros((h, w, 3))
    v = (np.arange(h) + 0.5) / h
    y = np.cos(v * math.pi)
    up = y > 0
    # brighter toward the horizon, ~1 on average
    img[up] = np.array([0.45, 0.65, 1.0])[None, None, :] * (0.6 + 0.6 * (1 - y[up]))[:, None, None]
    img[~up] = np.array([0.25, 0.22, 0.18])
    d = unit(sun_dir)
    u = 0.5 + math.atan2(d[0], -d[2]) / (2 * math.pi)
    vv = math.acos(d[1]) / math.pi
    # the 2x2 block of pixels around (u, v)
    i0 = int(round(u * w - 1)) % w
    j0 = int(round(vv * h - 1))
    for j in (j0, j0 + 1):
        for i in (i0, (i0 + 1) % w):
            img[j, i] = np.array([1000.0, 950.0, 850.0])
    return img.astype(np.float32)


def build_window():
    s = Scene("window")
    s.material("wall", "Kd 0.7 0.7 0.7")
    s.material("floor", "Kd 0.5 0.45 0.4")
    s.material("furniture", "Kd 0.5 0.3 0.2")
    W, H = 4.0, 2.8
    # room x, z in [-2, 2]; the window wall is x = -2 (facing +x, into the room)
    room(s, "wall", (-2, 0, -2), (2, H, 2), floor_mat="floor", skip=("-x",))
    hole = (1.0, 2.4, 1.0, 2.2)  # z from -2: [-1.0, 0.4], y in [1.0, 2.2]
    s.add("wall", *wall_with_hole((-2, 0, -2), (0, 0, 1), (0, 1, 0), W, H, hole, (1, 0, 0)))
    s.add("furniture", box((0.8, 0, 0.6), (1.9, 0.8, 1.9)), box((-1.9, 0, 1.2), (-1.4, 0.5, 1.9)))
    # sun: 40 degrees up, outside the window (-x), a little toward -z
    az, el = math.radians(15), math.radians(40)
    sun = np.array([-math.cos(el) * math.cos(az), math.sin(el), -math.cos(el) * math.sin(az)])
    folder = s.write({"camera": camera((1.8, 1.6, -1.8), (-0.9, 0.6, 0.6), 65),
                      "film": {"width": 256, "height": 192},
                      "environment": {"map": "sky.exr", "scale": 1.0}})
    from tracer import write_image

    write_image(os.path.join(folder, "sky.exr"), sky_map(sun))
    return s


def reflector(s, inner, lamp, pos, direction, size=0.18, depth=0.35, ke_half=0.06):
    """A small box open on its +w side (w = direction) with an emitter at its closed back
    end facing out of the opening. `pos` is the centre of the closed end."""
    R = frame(direction)
    s.add(inner, box((-size, -size, 0), (size, size, depth), rot=R, origin=pos, skip=("+z",)))
    d = unit(direction)
    c = np.asarray(pos, dtype=float) + d * 0.01
    s.emitter(lamp, c, R[:, 0] * ke_half, R[:, 1] * ke_half, facing=d)


def build_spotlit():
    s = Scene("spotlit")
    s.material("wall", "Kd 0.6 0.6 0.6")
    s.material("floor", "Kd 0.6 0.6 0.6\nKs 0.7 0.7 0.7\nPr 0.3\nPm 1")
    s.material("plastic_blue", "Kd 0.1 0.2 0.5\nKs 0.3 0.3 0.3\nNs 300")
    s.material("plastic_white", "Kd 0.6 0.6 0.6\nKs 0.3 0.3 0.3\nNs 100")
    s.material("reflector", "Kd 0.1 0.1 0.1")
    s.material("reflector_mirror", "illum 3\nKs 0.9 0.9 0.9")
    s.material("lamp", "Kd 0 0 0\nKe 400 350 270")
    room(s, "wall", (-3, 0, -3), (3, 3, 3), floor_mat="floor")
    s.add("plastic_blue", box((-0.4, 0, -0.4), (0.4, 0.8, 0.4), rot=rot_y(30), origin=(-0.6, 0, 0.8)))
    s.add("plastic_white", box((-0.3, 0, -0.3), (0.3, 1.3, 0.3), rot=rot_y(-10), origin=(1.3, 0, 1.4)),
          box((-0.5, 0, -0.25), (0.5, 0.4, 0.25), rot=rot_y(5), origin=(0.5, 0, -0.6)))
    cam = np.array([0.0, 1.5, -2.7])
    spots = [("reflector", (-2.0, 0.5, 1.0), (-0.3, 0.7, 1.0)),   # toward the back wall / ceiling
             ("reflector", (2.2, 1.0, 0.0), (0.4, 0.6, 1.0)),     # toward the right back corner
             ("reflector_mirror", (0.0, 2.0, 1.8), (0.0, 0.8, 0.6))]  # toward the ceiling
    for inner, pos, d in spots:
        assert np.dot(unit(d), cam - np.asarray(pos)) < 0, "reflector opening faces the camera"
        reflector(s, inner, "lamp", pos, d)
    s.write({"camera": camera(cam, (0.0, 1.0, 1.5), 60),
             "film": {"width": 256, "height": 192}})
    return s


BUILDERS = {"ajar": build_ajar, "glossy": build_glossy, "caustic": build_caustic,
            "manylights": build_manylights, "window": build_window, "spotlit": build_spotlit}


def main(names=None):
    names = list(names) or list(BUILDERS)
    bad = [n for n in names if n not in BUILDERS]
    if bad:
        sys.exit(f"build_scenes.py: unknown scene {bad[0]!r}; known: {', '.join(BUILDERS)}")
    for name in names:
        s = BUILDERS[name]()
        print(f"{name}: {s.triangle_count()} triangles")


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(HERE))  # for `import tracer` (window's sky.exr)
    main(sys.argv[1:])
