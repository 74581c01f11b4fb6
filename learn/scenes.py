"""Procedural training scenes: rooms, corridors and open scenes, seeded and reproducible.

`make_scene(seed, folder)` writes `proc_<seed>.obj/.mtl/.json` into `folder` and returns the OBJ
path (load it with tracer.load_scene). Everything random comes from numpy's Generator seeded by
`seed`, so a seed always gives the same files.

- kind `room`: a closed box of random size; sometimes a partition wall with a door, the light
  behind it; sometimes a window in one wall, with the sky (and sometimes a lamp) outside.
- kind `corridor`: a long, narrow box, lights near one end or in a side niche.
- kind `open`: a floor under the sky, with a lamp or without.
- kind `box` (only when asked for, never drawn by the seed): a Cornell-like closed box, two
  side walls of saturated colours, a ceiling lamp, one to three blocks and sometimes a sphere,
  the camera near the front wall looking in; mostly Lambertian.
Contents: random boxes (turned about the vertical), spheres, thin panels and occluders. Materials
are Lambertian (most), glossy plastic, rough metal or glass. Area lights are quads, small or
large, one-sided, facing into the scene. The sky is a constant environment.

The built-in scenes (`scenes/`) and the shared ones (`../shared/scenes/`) are never used here:
they are the test set.
"""
import json
import math
import os

import numpy as np

KINDS = ("room", "corridor", "open", "box")
DRAWN = KINDS[:3]  # the kinds a seed picks by itself


def _box_faces(inward):
    """Triangles of a box whose 8 corners come in the order (0,0,0), (1,0,0), (1,1,0), (0,1,0), then
    the same at z = 1; counter-clockwise seen from outside, or with `inward` from inside."""
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (3, 7, 6, 2), (0, 4, 7, 3), (1, 2, 6, 5)]
    f = []
    for a, b, c, d in quads:
        f += [(a, c, b), (a, d, c)] if inward else [(a, b, c), (a, c, d)]
    return f


class _Builder:
    def __init__(self, rng):
        self.rng = rng
        self.groups = []  # (material name, vertices (n, 3), faces (m, 3))
        self.materials = {}
        self.diffuse_only = False  # every surface Lambertian (the kind is still drawn: same layout)

    def material(self, body):
        name = f"m{len(self.materials)}"
        self.materials[name] = body
        return name

    def add(self, mat, v, f):
        self.groups.append((mat, np.asarray(v, float), np.asarray(f, int)))

    def quad(self, mat, p, u, v):
        """The parallelogram p, p+u, p+u+v, p+v; its normal u x v is the lit side."""
        p, u, v = (np.asarray(a, float) for a in (p, u, v))
        if np.linalg.norm(np.cross(u, v)) <= 1e-9:
            return  # a wall piece of zero width (a hole at the wall's edge)
        self.add(mat, [p, p + u, p + u + v, p + v], [[0, 1, 2], [0, 2, 3]])

    def box(self, mat, lo, hi, yaw=0.0):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        c = 0.5 * (lo + hi)
        x0, y0, z0 = lo - c
        x1, y1, z1 = hi - c
        v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                      [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]])
        cs, sn = math.cos(yaw), math.sin(yaw)
        v = v @ np.array([[cs, 0, -sn], [0, 1, 0], [sn, 0, cs]]) + c
        self.add(mat, v, _box_faces(inward=False))

    def sphere(self, mat, centre, radius, subdiv=2):
        t = (1.0 + 5 ** 0.5) / 2.0
        v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
             (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
        f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
             (6, 2, 10), (8, 6, 7), (9, 8, 1)]
        v = [np.array(p, float) / np.linalg.norm(p) for p in v]
        for _ in range(subdiv):
            mid = {}
            nf = []
            for a, b, c in f:
                ids = []
                for i, j in ((a, b), (b, c), (c, a)):
                    k = (min(i, j), max(i, j))
                    if k not in mid:
                        m = v[i] + v[j]
                        v.append(m / np.linalg.norm(m))
                        mid[k] = len(v) - 1
                    ids.append(mid[k])
                ab, bc, ca = ids
                nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
            f = nf
        self.add(mat, np.array(v) * radius + np.asarray(centre, float), f)

    def wall(self, mat, p, u, v, hole=None):
        """A wall p + [0,1] u + [0,1] v, lit side u x v, with an optional rectangular hole
        (a0, a1, b0, b1) in its (u, v) fractions, built of the four quads around it."""
        p, u, v = (np.asarray(a, float) for a in (p, u, v))
        if hole is None:
            self.quad(mat, p, u, v)
            return
        a0, a1, b0, b1 = hole
        self.quad(mat, p, a0 * u, v)
        self.quad(mat, p + a1 * u, (1 - a1) * u, v)
        self.quad(mat, p + a0 * u, (a1 - a0) * u, b0 * v)
        self.quad(mat, p + a0 * u + b1 * v, (a1 - a0) * u, (1 - b1) * v)

    # --- random materials ---------------------------------------------------------------------
    def surface(self, glass_ok=True):
        r = self.rng
        kd = r.uniform(0.05, 0.85) * r.uniform(0.6, 1.0, 3)
        kind = r.choice(["diffuse", "glossy", "metal", "glass"], p=[0.6, 0.2, 0.1, 0.1] if glass_ok else
                        [0.67, 0.22, 0.11, 0.0])
        if kind == "diffuse" or self.diffuse_only:
            return self.material(f"Kd {kd[0]:.3f} {kd[1]:.3f} {kd[2]:.3f}")
        if kind == "glossy":
            ns = float(np.exp(r.uniform(np.log(10.0), np.log(2000.0))))
            ks = r.uniform(0.1, 0.5)
            kd = kd * min(1.0, (0.95 - ks) / kd.max())  # energy: kd + ks below 1
            return self.material(f"Kd {kd[0]:.3f} {kd[1]:.3f} {kd[2]:.3f}\nKs {ks:.3f} {ks:.3f} {ks:.3f}\nNs {ns:.1f}")
        if kind == "metal":
            ks = r.uniform(0.5, 0.95, 3)
            return self.material(f"Ks {ks[0]:.3f} {ks[1]:.3f} {ks[2]:.3f}\nPr {r.uniform(0.15, 0.6):.3f}\nPm 1")
        return self.material("Kd 0 0 0\nKs 1 1 1\nillum 7\nNi 1.5")

    def lamp(self, power):
        c = self.rng.uniform(0.7, 1.0, 3)
        c = c / c.max() * power
        return self.material(f"Kd 0 0 0\nKe {c[0]:.4g} {c[1]:.4g} {c[2]:.4g}")

    def write(self, folder, name, sidecar):
        os.makedirs(folder, exist_ok=True)
        lines = [f"mtllib {name}.mtl"]
        nv = 0
        for mat, v, f in self.groups:
            lines.append(f"usemtl {mat}")
            lines += [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in v]
            lines += [f"f {a + 1 + nv} {b + 1 + nv} {c + 1 + nv}" for a, b, c in f]
            nv += len(v)
        obj = os.path.join(folder, f"{name}.obj")
        with open(obj, "w") as fh:
            fh.write("\n".join(lines) + "\n")
        with open(os.path.join(folder, f"{name}.mtl"), "w") as fh:
            for m, body in self.materials.items():
                fh.write(f"newmtl {m}\n{body}\n\n")
        with open(os.path.join(folder, f"{name}.json"), "w") as fh:
            json.dump(sidecar, fh, indent=1)
        return obj


def _contents(b, lo, hi, n):
    """n random objects (boxes, spheres, panels, occluders) standing in the box lo..hi."""
    r = b.rng
    size = hi - lo
    for _ in range(n):
        kind = r.choice(["box", "sphere", "panel", "occluder"], p=[0.4, 0.3, 0.15, 0.15])
        mat = b.surface()
        x, z = r.uniform(lo[0] + 0.1 * size[0], hi[0] - 0.1 * size[0]), r.uniform(lo[2] + 0.1 * size[2], hi[2] - 0.1 * size[2])
        s = r.uniform(0.08, 0.3) * min(size[0], size[2])
        if kind == "box":
            h = r.uniform(0.3, 1.5) * s
            b.box(mat, (x - s / 2, lo[1], z - s / 2), (x + s / 2, lo[1] + h, z + s / 2), r.uniform(0, np.pi))
        elif kind == "sphere":
            rad = 0.5 * s
            y = lo[1] + rad if r.random() < 0.7 else r.uniform(lo[1] + rad, hi[1] - rad)
            b.sphere(mat, (x, y, z), rad)
        elif kind == "panel":  # thin vertical board
            h = r.uniform(0.3, 0.8) * size[1]
            b.box(mat, (x - s, lo[1], z - 0.01 * s), (x + s, lo[1] + h, z + 0.01 * s), r.uniform(0, np.pi))
        else:  # a floating slab that shadows what is below it
            y = r.uniform(lo[1] + 0.3 * size[1], hi[1] - 0.15 * size[1])
            b.box(mat, (x - s, y, z - s), (x + s, y + 0.03 * size[1], z + s), r.uniform(0, np.pi))


def _ceiling_lamp(b, lo, hi, power_scale=1.0):
    r = b.rng
    size = hi - lo
    frac = r.uniform(0.05, 0.5)  # small or large
    w, d = frac * size[0], frac * size[2]
    x = r.uniform(lo[0], hi[0] - w)
    z = r.uniform(lo[2], hi[2] - d)
    y = hi[1] - 1e-3 * size[1]
    power = power_scale * r.uniform(2.0, 8.0) / max(frac, 0.05) ** 1.5
    b.quad(b.lamp(power), (x, y, z), (w, 0, 0), (0, 0, d))  # (w,0,0) x (0,0,d) points down


def _camera(b, lo, hi, look_lo=None, look_hi=None):
    r = b.rng
    size = hi - lo
    o = lo + size * r.uniform([0.15, 0.3, 0.15], [0.85, 0.7, 0.85])
    a, c = (lo, hi) if look_lo is None else (look_lo, look_hi)
    t = a + (c - a) * r.uniform(0.1, 0.9, 3)
    if np.linalg.norm(t - o) < 1e-3:
        t = o + np.array([0.0, 0.0, 1.0])
    return {"origin": o.tolist(), "target": t.tolist(), "up": [0, 1, 0], "fov": float(r.uniform(40, 80))}


def _room(b):
    r = b.rng
    size = np.array([r.uniform(3, 8), r.uniform(2.4, 4), r.uniform(3, 8)])
    lo, hi = np.zeros(3), size
    walls = [b.surface(glass_ok=False) if r.random() < 0.3 else b.material(
        "Kd {0:.3f} {0:.3f} {0:.3f}".format(r.uniform(0.2, 0.85))) for _ in range(6)]
    window = r.random() < 0.35
    door = (not window) and r.random() < 0.4
    env = None
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    hole = None
    if window:
        a0 = r.uniform(0.1, 0.5)
        b0 = r.uniform(0.2, 0.5)
        hole = (a0, a0 + r.uniform(0.15, 0.4), b0, b0 + r.uniform(0.2, 0.4))
        env = {"radiance": [float(v) for v in r.uniform(0.5, 3.0) * r.uniform(0.7, 1.0, 3)]}
    # the lit side u x v of every wall faces the inside
    b.wall(walls[0], (x0, y0, z0), (0, y1, 0), (0, 0, z1))  # x = 0, faces +x
    b.wall(walls[1], (x1, y0, z0), (0, 0, z1), (0, y1, 0), hole=hole)  # x = x1, faces -x; hole (z, y)
    b.wall(walls[2], (x0, y0, z0), (0, 0, z1), (x1, 0, 0))  # floor, faces +y
    b.wall(walls[3], (x0, y1, z0), (x1, 0, 0), (0, 0, z1))  # ceiling, faces -y
    b.wall(walls[4], (x0, y0, z0), (x1, 0, 0), (0, y1, 0))  # z = 0, faces +z
    b.wall(walls[5], (x0, y0, z1), (0, y1, 0), (x1, 0, 0))  # z = z1, faces -z
    cam_hi = hi.copy()
    if door:  # a partition at x = xp with a door; the lamp behind it, the camera in front
        xp = r.uniform(0.55, 0.75) * size[0]
        dz0 = r.uniform(0.1, 0.7)
        dz1 = dz0 + r.uniform(0.12, 0.25)
        dy = r.uniform(0.6, 0.85)
        pmat = walls[int(r.integers(6))]
        b.wall(pmat, (xp, y0, z0), (0, 0, z1), (0, y1, 0), hole=(dz0, dz1, 0.0, dy))  # faces -x
        b.wall(pmat, (xp + 0.02, y0, z0), (0, y1, 0), (0, 0, z1), hole=(0.0, dy, dz0, dz1))  # faces +x
        _ceiling_lamp(b, np.array([xp + 0.05, y0, z0]), hi)
        cam_hi = np.array([xp - 0.05, y1, z1])
        _contents(b, lo, cam_hi, int(r.integers(1, 6)))
    else:
        if not window or r.random() < 0.5:
            _ceiling_lamp(b, lo, hi)
        if window and r.random() < 0.4:  # a lamp outside, facing the window
            c = np.array([x1 + r.uniform(0.5, 2.0), y1 * r.uniform(0.3, 0.8), z1 * r.uniform(0.2, 0.8)])
            w = r.uniform(0.5, 2.0)
            b.quad(b.lamp(r.uniform(5, 30)), c + (0, -w / 2, -w / 2), (0, 0, w), (0, w, 0))  # faces -x
        _contents(b, lo, hi, int(r.integers(2, 9)))
    return {"camera": _camera(b, lo, cam_hi)}, env


def _corridor(b):
    r = b.rng
    size = np.array([r.uniform(1.5, 3.0), r.uniform(2.4, 3.5), r.uniform(8, 16)])
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]) * size
    f = _box_faces(inward=True)
    b.add(b.material("Kd {0:.3f} {0:.3f} {0:.3f}".format(r.uniform(0.3, 0.85))), v, f)
    zl = r.uniform(0.7, 0.95) * size[2]
    _ceiling_lamp(b, np.array([0, 0, zl - 0.1 * size[2]]), np.array([size[0], size[1], zl]))
    if r.random() < 0.5:
        _ceiling_lamp(b, np.zeros(3), np.array([size[0], size[1], 0.3 * size[2]]), 0.3)
    _contents(b, np.zeros(3), size, int(r.integers(2, 7)))
    cam = _camera(b, np.array([0, 0, 0]), np.array([size[0], size[1], 0.3 * size[2]]),
                  np.array([0, 0, 0.5 * size[2]]), size)
    return {"camera": cam}, None


def _open(b):
    r = b.rng
    s = r.uniform(6, 20)
    fl = b.material("Kd {0:.3f} {0:.3f} {0:.3f}".format(r.uniform(0.2, 0.8)))
    b.quad(fl, (-s, 0, -s), (0, 0, 2 * s), (2 * s, 0, 0))  # faces +y
    lo, hi = np.array([-s / 3, 0, -s / 3]), np.array([s / 3, s / 4, s / 3])
    _contents(b, lo, hi, int(r.integers(3, 10)))
    if r.random() < 0.6:
        _ceiling_lamp(b, np.array([-s / 4, 0, -s / 4]), np.array([s / 4, s / 3, s / 4]))
    env = {"radiance": [float(v) for v in r.uniform(0.3, 2.0) * r.uniform(0.6, 1.0, 3)]}
    o = np.array([r.uniform(-s / 2, s / 2), r.uniform(0.5, s / 4), r.uniform(-s / 2, s / 2)])
    cam = {"origin": o.tolist(), "target": [float(r.uniform(-1, 1)), 0.3, float(r.uniform(-1, 1))],
           "up": [0, 1, 0], "fov": float(r.uniform(40, 70))}
    return {"camera": cam}, env


def _cornell_box(b):
    r = b.rng
    size = np.array([r.uniform(2, 4), r.uniform(2, 3.5), r.uniform(2, 4.5)])
    lo, hi = np.zeros(3), size
    grey = lambda: b.material("Kd {0:.3f} {0:.3f} {0:.3f}".format(r.uniform(0.4, 0.85)))  # noqa: E731

    def saturated():
        kd = r.uniform(0.03, 0.15, 3)
        kd[int(r.integers(3))] = r.uniform(0.4, 0.8)
        return b.material(f"Kd {kd[0]:.3f} {kd[1]:.3f} {kd[2]:.3f}")

    x1, y1, z1 = hi
    b.wall(saturated(), (0, 0, 0), (0, y1, 0), (0, 0, z1))  # x = 0, faces +x
    b.wall(saturated(), (x1, 0, 0), (0, 0, z1), (0, y1, 0))  # x = x1, faces -x
    b.wall(grey(), (0, 0, 0), (0, 0, z1), (x1, 0, 0))  # floor
    b.wall(grey(), (0, y1, 0), (x1, 0, 0), (0, 0, z1))  # ceiling
    b.wall(grey(), (0, 0, 0), (x1, 0, 0), (0, y1, 0))  # z = 0 (behind the camera), faces +z
    b.wall(grey(), (0, 0, z1), (0, y1, 0), (x1, 0, 0))  # z = z1 (the back), faces -z
    frac = r.uniform(0.1, 0.35)
    w, d = frac * x1, frac * z1
    x, z = r.uniform(0.3, 0.7) * (x1 - w), r.uniform(0.3, 0.7) * (z1 - d) + 0.2 * z1
    power = r.uniform(3.0, 10.0) / frac ** 1.5
    b.quad(b.lamp(power), (x, y1 - 1e-3 * y1, z), (w, 0, 0), (0, 0, d))
    for _ in range(int(r.integers(1, 4))):
        mat = b.surface(glass_ok=False) if r.random() < 0.2 else grey()
        s = r.uniform(0.15, 0.35) * min(x1, z1)
        cx, cz = r.uniform(0.2 * x1, 0.8 * x1), r.uniform(0.45 * z1, 0.85 * z1)
        h = r.uniform(0.5, 2.2) * s
        b.box(mat, (cx - s / 2, 0, cz - s / 2), (cx + s / 2, h, cz + s / 2), r.uniform(0, np.pi))
    if r.random() < 0.3:
        rad = r.uniform(0.08, 0.18) * min(x1, z1)
        b.sphere(b.surface(glass_ok=False), (r.uniform(0.3, 0.7) * x1, rad, r.uniform(0.4, 0.8) * z1), rad)
    o = np.array([x1 * r.uniform(0.4, 0.6), y1 * r.uniform(0.4, 0.6), z1 * r.uniform(0.02, 0.1)])
    t = np.array([x1 * r.uniform(0.4, 0.6), y1 * r.uniform(0.35, 0.55), z1])
    cam = {"origin": o.tolist(), "target": t.tolist(), "up": [0, 1, 0], "fov": float(r.uniform(45, 70))}
    return {"camera": cam}, None


def make_scene(seed, folder, width=64, height=64, kind=None, diffuse_only=False):
    """Write the procedural scene of `seed` into `folder`; returns the OBJ path. `kind` (one of
    KINDS) forces the layout; by default the seed picks it (rooms 50%, corridors 25%, open 25%; `box`
    only when asked for).
    `diffuse_only`: every surface Lambertian (the same layout and colours as without it)."""
    rng = np.random.default_rng([int(seed), 0x5CE4E])
    pick = rng.choice(DRAWN, p=[0.5, 0.25, 0.25])
    kind = kind or pick
    if kind not in KINDS:
        raise ValueError(f"unknown scene kind {kind!r}; valid: " + ", ".join(KINDS))
    b = _Builder(rng)
    b.diffuse_only = bool(diffuse_only)
    sidecar, env = {"room": _room, "corridor": _corridor, "open": _open, "box": _cornell_box}[kind](b)
    sidecar["film"] = {"width": int(width), "height": int(height)}
    sidecar["render"] = {"spp": 4, "max_depth": 8, "rr_depth": 5, "seed": int(seed)}
    if env is not None:
        sidecar["environment"] = env
    return b.write(folder, f"proc_{int(seed)}", sidecar)
