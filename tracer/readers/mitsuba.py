"""Mitsuba scene XML (the dialects of Mitsuba 3 and, by its camelCase names, 0.6) as a SceneSpec.

The subset the field's scenes use most, for now: `<default>` and `$name`; `<bsdf>` by id and
`<ref>`, nested in `twosided` (Mitsuba's BSDFs are one-sided otherwise: the ONE_SIDED flag);
`diffuse`, `conductor`/`roughconductor` (METAL: `eta`/`k`, a named `material`, GGX or Beckmann,
`specular_reflectance`), `dielectric`, `roughdielectric` (GGX), `thindielectric`, `plastic` and
`roughplastic` (COATED, `nonlinear`; indices as numbers or Mitsuba's named media), `mask` (an
opacity value or texture: params[P_CLEAR]) and `bumpmap` (a height texture and its scale) around
any of them; textures `bitmap` (0.6's `gamma`, 3's `raw`) and `checkerboard` with a `to_uv` scale/translate/matrix; shapes
`obj` (with `to_world`, `face_normals`, `flip_normals`; without vn, Mitsuba's smooth normals),
`rectangle`, `cube`, `sphere`, `disk`, `cylinder` (tessellated, area exact), an `area` emitter on
a shape, `constant`, `envmap` and `sunsky` emitters, `point`, `spot` and `directional` lights; the `perspective` sensor (`fov`, `fov_axis` x, y, diagonal,
smaller, larger, `to_world` as a matrix or lookat), the film's size, the integrator's `max_depth`
and the sampler's `sample_count`. Everything else is one warning naming the file and line (a
shape or BSDF it cannot read is left out or replaced, as the warning says).

UVs: the OBJ reader keeps OBJ's v (up the image); Mitsuba's textures read (u, 1 - v), so a
texture's `to_uv` is composed with that flip here, and a rectangle's UVs are given in OBJ's
convention.
"""
import math
import os
import re
from xml.parsers import expat

import numpy as np

from .. import bsdfs
from ..errors import SceneError
from ..material import (
    N_TEX_SLOTS,
    P_BUMP_SCALE,
    TEX_SLOT_BUMP,
    TEX_SLOT_KD,
    TEX_SLOT_KS,
    TEX_SLOT_OPACITY,
)
from ..metals import METALS
from ..scene import CameraSpec, DeltaLight, Environment, RenderSettings, SceneSpec
from ..textures import TextureSpec, srgb_decode
from .meshes import read_ply, read_serialized
from .obj import read_geometry
from .text import warn

_CAMEL = {"toWorld": "to_world", "faceNormals": "face_normals", "flipNormals": "flip_normals", "maxDepth": "max_depth",
          "sampleCount": "sample_count", "intIOR": "int_ior", "extIOR": "ext_ior", "fovAxis": "fov_axis",
          "specularReflectance": "specular_reflectance", "diffuseReflectance": "diffuse_reflectance",
          "toUV": "to_uv", "filterType": "filter_type", "shapeIndex": "shape_index", "nearClip": "near_clip",
          "farClip": "far_clip", "rrDepth": "rr_depth", "hideEmitters": "hide_emitters", "extEta": "ext_eta",
          "flipTexCoords": "flip_tex_coords", "focalLength": "focal_length", "strictNormals": "strict_normals",
          "maxSmoothAngle": "max_smooth_angle", "samplingWeight": "sampling_weight",
          "cutoffAngle": "cutoff_angle", "beamWidth": "beam_width", "sunDirection": "sun_direction",
          "skyScale": "sky_scale", "sunScale": "sun_scale", "sunRadiusScale": "sun_radius_scale"}
# film properties that only shape the output file (its format, an LDR gamma; no pixel value changes): not warned
FILM_OUTPUT = {"gamma", "pixel_format", "file_format", "component_format", "banner", "high_quality_edges", "attach_log",
               "pixelFormat", "fileFormat", "componentFormat", "highQualityEdges", "attachLog"}


# Mitsuba's named indices of refraction (include/mitsuba/render/ior.h)
IORS = {"vacuum": 1.0, "helium": 1.000036, "hydrogen": 1.000132, "air": 1.000277, "carbon dioxide": 1.00045,
        "water": 1.3330, "acetone": 1.36, "ethanol": 1.361, "carbon tetrachloride": 1.461, "glycerol": 1.4729,
        "benzene": 1.501, "silicone oil": 1.52045, "bromine": 1.661, "water ice": 1.31, "fused quartz": 1.458,
        "pyrex": 1.470, "acrylic glass": 1.49, "polypropylene": 1.49, "bk7": 1.5046, "sodium chloride": 1.544,
        "amber": 1.55, "pet": 1.5750, "diamond": 2.419}

SPHERE_RINGS = 96  # a sphere: 96 rings x 192 segments (36,864 triangles; area within 0.02%)
DISK_SEGMENTS = 192  # a disk's or cylinder's segments (area within 0.02%)


def vertex_normals(tri):
    """Smooth corner normals (F, 3, 3) of a triangle soup, as Mitsuba 3 computes them for a mesh
    without normals: corners at the same position share one, the sum of their faces' unit normals
    weighted by each corner's interior angle (Thuermer and Wuethrich 1998). A corner whose sum
    vanishes keeps its face's normal (zero for a degenerate face: flat)."""
    f = tri.shape[0]
    _, inv = np.unique(tri.reshape(-1, 3), axis=0, return_inverse=True)
    inv = inv.reshape(f, 3)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)
    acc = np.zeros((int(inv.max()) + 1 if f else 0, 3))
    for k in range(3):
        a = tri[:, (k + 1) % 3] - tri[:, k]
        b = tri[:, (k + 2) % 3] - tri[:, k]
        la = np.linalg.norm(a, axis=1)
        lb = np.linalg.norm(b, axis=1)
        ok = (la > 0) & (lb > 0)
        c = np.einsum("ij,ij->i", a, b) / np.where(ok, la * lb, 1.0)
        ang = np.where(ok, np.arccos(np.clip(c, -1.0, 1.0)), 0.0)
        np.add.at(acc, inv[:, k], n * ang[:, None])
    la = np.linalg.norm(acc, axis=1, keepdims=True)
    acc = np.divide(acc, la, out=np.zeros_like(acc), where=la > 0)
    out = acc[inv]
    bad = np.linalg.norm(out, axis=2) == 0
    out[bad] = np.broadcast_to(n[:, None, :], out.shape)[bad]
    return out


def _cube():
    """Mitsuba's cube [-1, 1]^3: two triangles per face, wound outward, per-face UVs."""
    tris, uvs = [], []
    for axis in range(3):
        for sgn in (-1.0, 1.0):
            a, b = (axis + 1) % 3, (axis + 2) % 3
            q = np.zeros((4, 3))
            q[:, axis] = sgn
            q[:, a] = [-1, 1, 1, -1]
            q[:, b] = [-1, -1, 1, 1]
            if sgn < 0:
                q = q[::-1]
            tris += [q[[0, 1, 2]], q[[0, 2, 3]]]
            uvs += [np.array([[0, 0], [1, 0], [1, 1]], float), np.array([[0, 0], [1, 1], [0, 1]], float)]
    return np.array(tris), np.array(uvs), None


def _grid(n_u, n_v, point, normal):
    """Triangles of a (u, v) grid of n_u x n_v cells: point(u, v) and normal(u, v) on [0, 1]^2,
    corners (u, v) as UVs in Mitsuba's (u, 1 - v) convention."""
    u, v = np.meshgrid(np.linspace(0, 1, n_u + 1), np.linspace(0, 1, n_v + 1), indexing="ij")
    P, N = point(u, v), normal(u, v)
    i, j = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="ij")
    i, j = i.ravel(), j.ravel()
    quads = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
    tri_idx = [(quads[0], quads[1], quads[2]), (quads[0], quads[2], quads[3])]
    tris = np.concatenate([np.stack([P[a] for a in t], 1) for t in tri_idx])
    nrm = np.concatenate([np.stack([N[a] for a in t], 1) for t in tri_idx])
    uv = np.concatenate([np.stack([np.stack([u[a], 1.0 - v[a]], -1) for a in t], 1) for t in tri_idx])
    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    keep = area > 1e-14
    return tris[keep], uv[keep], nrm[keep]


def _sphere(rings):
    """The unit sphere, counter-clockwise seen from outside, smooth normals; its radius raised so
    that the triangles' area is the sphere's (an emitting sphere keeps its power)."""
    def pt(u, v):
        th, ph = np.pi * v, 2.0 * np.pi * u
        return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    tris, uv, nrm = _grid(2 * rings, rings, pt, pt)
    tris = tris[:, ::-1]  # outward: (u, v) runs clockwise seen from outside
    uv, nrm = uv[:, ::-1], nrm[:, ::-1]
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum()
    return tris * np.sqrt(4.0 * np.pi / area), uv, nrm


def _disk(segments):
    """The unit disk in z = 0, normal +z (Mitsuba's disk)."""
    def pt(u, v):
        return np.stack([v * np.cos(2 * np.pi * u), v * np.sin(2 * np.pi * u), 0.0 * u], -1)
    tris, uv, _ = _grid(segments, 1, pt, lambda u, v: np.stack([0 * u, 0 * u, 1 + 0 * u], -1))
    if tris.shape[0] and np.cross(tris[0, 1] - tris[0, 0], tris[0, 2] - tris[0, 0])[2] < 0:
        tris, uv = tris[:, ::-1], uv[:, ::-1]
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum()
    return tris * np.sqrt(np.pi / area), uv, None


def _cylinder(segments):
    """The open unit cylinder from z = 0 to 1, radius 1, normals outward (Mitsuba's cylinder)."""
    def pt(u, v):
        return np.stack([np.cos(2 * np.pi * u), np.sin(2 * np.pi * u), v], -1)
    def nr(u, v):
        return np.stack([np.cos(2 * np.pi * u), np.sin(2 * np.pi * u), 0 * v], -1)
    tris, uv, nrm = _grid(segments, 1, pt, nr)
    c = tris.mean(axis=1)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    if np.sum(n[:, :2] * c[:, :2]) < 0:
        tris, uv, nrm = tris[:, ::-1], uv[:, ::-1], nrm[:, ::-1]
    k = np.sqrt(2.0 * np.pi / (np.linalg.norm(n, axis=1).sum() * 0.5))  # the lateral area 2 pi
    tris = tris * np.array([k, k, 1.0])
    return tris, uv, nrm


def _frame_to(p0, p1, r):
    """4x4 taking the unit cylinder (z from 0 to 1, radius 1) to the one from p0 to p1 of radius r."""
    d = p1 - p0
    h = float(np.linalg.norm(d))
    if not h > 0.0:
        raise SceneError("cylinder: p0 and p1 coincide")
    z = d / h
    a = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    out = np.eye(4)
    out[:3, 0], out[:3, 1], out[:3, 2], out[:3, 3] = r * x, r * y, h * z, p0
    return out


class _Node:
    """An XML element: tag, attributes (get), children (iteration), its file and line."""

    def __init__(self, tag, attrib, path, line):
        self.tag, self.attrib, self.path, self.line, self.children = tag, attrib, path, line, []

    def get(self, key, default=None):
        return self.attrib.get(key, default)

    def __iter__(self):
        return iter(self.children)

    def iter(self):
        yield self
        for c in self.children:
            yield from c.iter()


def _parse(path):
    """The root _Node of an XML file; SceneError naming the file (and line) if it cannot be read."""
    parser = expat.ParserCreate()
    stack, roots = [], []

    def start(tag, attrib):
        node = _Node(tag, attrib, path, parser.CurrentLineNumber)
        (stack[-1].children if stack else roots).append(node)
        stack.append(node)

    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: stack.pop()
    try:
        with open(path, "rb") as f:
            parser.Parse(f.read(), True)
    except OSError as e:
        raise SceneError(f"{path}: cannot read ({e.strerror})") from None
    except expat.ExpatError as e:
        raise SceneError(f"{path}:{e.lineno}: not valid XML ({expat.ErrorString(e.code)})") from None
    return roots[0]


class _Props(dict):
    """{property name: element}; remembers which names were asked for (the rest are unused)."""

    def __init__(self, items):
        super().__init__(items)
        self.used = set()

    def __contains__(self, key):
        self.used.add(key)
        return super().__contains__(key)

    def __getitem__(self, key):
        self.used.add(key)
        return super().__getitem__(key)

    def get(self, key, default=None):
        self.used.add(key)
        return super().get(key, default)


class _Reader:
    def __init__(self, path, defines, allow_missing=False):
        self.path = path
        self.allow_missing = allow_missing
        self.unused = {}  # (tag, type, property) -> [first element, count]
        self.said = set()
        self.folder = os.path.dirname(os.path.abspath(path))
        self.defaults = dict(defines or {})
        self.defines = dict(defines or {})
        self.warnings = []
        self.ids = {}
        self.textures = []
        self.materials = []  # (name, type, param, emission, tex)
        self.by_name = {}  # material name -> index (a BSDF shared by shapes is one material)
        self.tris, self.mats, self.uvs, self.normals = [], [], [], []
        self.environment = None  # a constant emitter
        self.version = "3"  # the <scene version="..."> attribute: 0.x reads 0.6's defaults
        self.delta_lights = []  # point, spot and directional lights

    # --- values ------------------------------------------------------------------------------
    def where(self, el):
        return f"{getattr(el, 'path', self.path)}:{getattr(el, 'line', '?')}"

    def file(self, el, value):
        """The path of a file property: relative to the file that names it, then to the scene's."""
        here = os.path.join(os.path.dirname(os.path.abspath(getattr(el, "path", self.path))), value)
        return here if os.path.exists(here) else os.path.join(self.folder, value)

    def missing(self, el, what, file, then):
        """A file the scene names is absent: an error, or (allow_missing) a warning saying `then`."""
        msg = f"{self.where(el)}: {what} {os.path.relpath(file, self.folder)!r} not found"
        if not self.allow_missing:
            raise SceneError(f"{msg} (--allow-missing renders without it)")
        self.warn(el, f"{what} {os.path.relpath(file, self.folder)!r} not found; {then}")

    def done(self, el, p, ignore=()):
        """Note the properties of el that nothing read (one warning per kind, at the end)."""
        for k, c in dict.items(p):
            if k not in p.used and k not in ignore:
                key = (el.tag, self.attr(el, "type"), k)
                if key in self.unused:
                    self.unused[key][1] += 1
                else:
                    self.unused[key] = [c, 1]

    def warn_unused(self):
        for (tag, kind, k), (c, n) in self.unused.items():
            more = f" (and {n - 1} more like it)" if n > 1 else ""
            self.warn(c, f"property {k!r} of <{tag} type={kind!r}> is not used by the tracer{more}")

    def warn(self, el, msg):
        warn(self.warnings, f"{self.where(el)}: {msg}")

    def attr(self, el, key, default=None):
        v = el.get(key, default)
        if isinstance(v, str) and "$" in v:
            def sub(m):
                name = m.group(1)
                if name not in self.defaults:
                    raise SceneError(f"{self.where(el)}: ${name} is not defined (no <default name=\"{name}\">)")
                return self.defaults[name]
            v = re.sub(r"\$([A-Za-z_][A-Za-z0-9_]*)", sub, v)
        return v

    def name(self, el):
        n = self.attr(el, "name", "")
        return _CAMEL.get(n, n)

    def props(self, el):
        """{name: element} of el's children that carry a name (a _Props: see done())."""
        return _Props({self.name(c): c for c in el if c.get("name") is not None})

    def number(self, el):
        try:
            return float(self.attr(el, "value"))
        except (TypeError, ValueError):
            raise SceneError(f"{self.where(el)}: {self.name(el)!r} needs a number, got {el.get('value')!r}") from None

    def ior(self, p, name, default):
        """An index of refraction: a number, or one of Mitsuba's named media (IORS)."""
        if name not in p:
            return IORS[default]
        v = (p[name].get("value") or "").strip()
        try:
            return float(v)
        except ValueError:
            if v.lower() in IORS:
                return IORS[v.lower()]
        raise SceneError(f"{self.where(p[name])}: {name} {v!r} is neither a number nor a known medium; "
                         f"valid: {', '.join(IORS)}")

    def point(self, el):
        """A <point> (x, y, z attributes, or value "x, y, z")."""
        if el.get("value") is not None:
            v = [float(x) for x in re.split(r"[,\s]+", self.attr(el, "value").strip()) if x]
            if len(v) == 3:
                return tuple(v)
            raise SceneError(f"{self.where(el)}: a point needs three numbers")
        try:
            return tuple(float(self.attr(el, k, "0")) for k in ("x", "y", "z"))
        except ValueError:
            raise SceneError(f"{self.where(el)}: malformed point") from None

    def emitter(self, el):
        """A top-level emitter: `constant` or `envmap` as the scene's environment, `point`, `spot` and
        `directional` as delta lights; the others one line each."""
        kind = self.attr(el, "type")
        p = self.props(el)
        if kind in ("constant", "envmap", "sunsky") and self.environment is not None:
            self.warn(el, "a second environment emitter; ignored")
            return
        if kind == "constant":
            rad = np.asarray(self.rgb(p["radiance"]) if "radiance" in p else (1.0, 1.0, 1.0), float)
            self.environment = Environment(rad)
        elif kind == "envmap":
            self.environment = self.envmap(el, p)
        elif kind in ("point", "spot", "directional"):
            self.delta_lights.append(self.delta_light(el, kind, p))
        elif kind == "sunsky":
            self.environment = self.sunsky(el, p)
        elif kind in ("sky", "sun"):
            self.warn(el, f"0.6's emitter {kind!r} alone is not supported (`sunsky` is); the scene renders without it")
            return
        else:
            self.warn(el, f"emitter {kind!r} is not supported (no next-event estimation for it yet); the scene "
                          f"renders without it")
            return
        self.done(el, p)

    def delta_light(self, el, kind, p):
        """A `point` (intensity; position or to_world), `spot` (intensity, cutoff_angle and beam_width
        in degrees, to_world: at its origin, shining along its +z) or `directional` (irradiance;
        direction or to_world's +z, the direction the light travels) as a tracer.scene.DeltaLight."""
        m = self.matrix(p["to_world"]) if "to_world" in p else np.eye(4)
        name = "irradiance" if kind == "directional" else "intensity"
        value = np.asarray(self.rgb(p[name]) if name in p else (1.0, 1.0, 1.0), float)
        if not np.all(np.isfinite(value)) or value.min() < 0.0:
            raise SceneError(f"{self.where(el)}: {kind} light's {name} must be finite and >= 0, got {value.tolist()}")
        axis = m[:3, :3] @ np.array([0.0, 0.0, 1.0])
        if kind == "directional" and "direction" in p:
            axis = np.asarray(self.point(p["direction"]), float)
        if not np.linalg.norm(axis) > 0.0:
            raise SceneError(f"{self.where(el)}: {kind} light has no direction (a zero vector)")
        light = DeltaLight(kind, value, np.asarray(m[:3, 3], float), axis / np.linalg.norm(axis), where=self.where(el))
        if kind == "point" and "position" in p:
            light.position = np.asarray(self.point(p["position"]), float)
        if kind == "spot":
            cutoff = self.number(p["cutoff_angle"]) if "cutoff_angle" in p else 20.0
            beam = self.number(p["beam_width"]) if "beam_width" in p else 0.75 * cutoff
            if not 0.0 <= beam <= cutoff <= 180.0:
                raise SceneError(f"{self.where(el)}: a spot light needs 0 <= beam_width <= cutoff_angle <= 180 "
                                 f"(degrees), got beam_width {beam:g}, cutoff_angle {cutoff:g}")
            light.cutoff, light.beam = math.radians(cutoff), math.radians(beam)
            frame = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
            light.frame = np.ascontiguousarray(frame.T)
            if "texture" in p:
                light.texture = self.spot_texture(p["texture"])
        return light

    def spot_texture(self, el):
        """The (H, W, 3) image a spot light projects: a `bitmap` (as Mitsuba 3 decodes it; its
        `to_uv` and filter are not read: bilinear, repeat), or None with a warning."""
        from ..textures import read_texture

        if el.tag == "ref":
            el = self.ids.get(self.attr(el, "id"), el)
        q = self.props(el)
        if el.tag != "texture" or self.attr(el, "type") != "bitmap" or "filename" not in q:
            self.warn(el, "a spot light's texture must be a bitmap (as in Mitsuba 3); the spot renders without it")
            return None
        file = self.file(el, self.attr(q["filename"], "value"))
        if not os.path.isfile(file):
            self.missing(el, "spot light texture", file, "the spot renders without it")
            return None
        raw = "raw" in q and self.attr(q["raw"], "value", "false").lower() == "true"
        img = read_texture(file, gamma=1.0 if raw else 0.0, what="spot light texture").astype(np.float64)
        if not np.all(np.isfinite(img)) or img.min() < 0.0:
            raise SceneError(f"{file}: a spot light's texture has negative or non-finite pixels")
        for k in ("to_uv", "filter_type", "wrap_mode"):
            if k in q:
                self.warn(q[k], f"a spot light texture's {k} is not read (bilinear, repeat)")
        return img

    def sunsky(self, el, p):
        """A `sunsky` emitter (sunsky_model) baked into an Environment; None with a warning when the
        sun is below the horizon (it then emits nothing)."""
        from .. import sunsky

        s = self.sunsky_model(el, p)
        if s.elevation < 0.0:
            self.warn(el, f"sunsky: the sun is {-math.degrees(s.elevation):.1f} degrees below the horizon, so the "
                          f"sun and sky emit nothing (as in Mitsuba 3); the scene renders without them")
            return None
        img, negative = sunsky.bake(s)
        if negative:
            self.warn(el, f"sunsky: {negative} texels of the baked map had a negative RGB channel (the sun is low: "
                          f"{math.degrees(s.elevation):.1f} degrees), set to 0")
        return Environment(np.zeros(3), img, f"sunsky at {self.where(el)}", convention="tracer", sunsky=s)

    def sunsky_model(self, el, p):
        """The tracer.sunsky.SunSky of a `sunsky` emitter as Mitsuba 3 defines it: Mitsuba 3's names
        and 0.6's (sunDirection, skyScale, sunScale, sunRadiusScale, scale; albedo 0.15 by default in
        a 0.x file); the sun from `sun_direction` or from the date, time and place; 0.6's frame has +y
        up (3's +z). What has no counterpart is one warning."""
        from .. import sunsky

        old = self.version.startswith("0.")
        m = self.matrix(p["to_world"]) if "to_world" in p else np.eye(4)
        rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
        up_y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # 0.6's (x, y, z) -> 3's (x, -z, y)
        w2l = up_y @ rot.T if old else rot.T
        when = [k for k in ("year", "month", "day", "hour", "minute", "second", "latitude", "longitude", "timezone")
                if k in p]
        if "sun_direction" in p:
            if when:
                raise SceneError(f"{self.where(el)}: sunsky takes sun_direction or a date, time and place "
                                 f"({', '.join(when)}), not both")
            sun = w2l @ np.asarray(self.point(p["sun_direction"]), float)
        else:
            kw = {k: self.number(p[k]) for k in when}
            for k in ("year", "month", "day"):
                if k in kw:
                    kw[k] = int(kw[k])
            zenith, azimuth = sunsky.sun_angles(**kw)
            st = math.sin(zenith)
            if old:  # 0.6's toSphere in its +y-up frame, then into 3's
                sun = up_y @ np.array([math.sin(azimuth) * st, math.cos(zenith), -math.cos(azimuth) * st])
            else:  # 3's sph_to_dir(theta, azimuth - pi)
                sun = np.array([-math.cos(azimuth) * st, -math.sin(azimuth) * st, math.cos(zenith)])
        if not np.linalg.norm(sun) > 0.0:
            raise SceneError(f"{self.where(el)}: sunsky sun_direction is a zero vector")
        scale = self.number(p["scale"]) if old and "scale" in p else 1.0
        aperture = (sunsky.SUN_APERTURE_DEG * self.number(p["sun_radius_scale"]) if old and "sun_radius_scale" in p
                    else self.number(p["sun_aperture"]) if "sun_aperture" in p else sunsky.SUN_APERTURE_DEG)
        if aperture <= 0.0:  # 0.6's sunRadiusScale 0: a directional sun
            raise SceneError(f"{self.where(el)}: sunsky with a sun of size 0 (0.6's sunRadiusScale 0, a directional "
                             f"sun) is not supported")
        albedo = self.rgb(p["albedo"]) if "albedo" in p else (0.15,) * 3 if old else (0.3,) * 3
        s = sunsky.SunSky(sun / np.linalg.norm(sun), w2l, self.number(p["turbidity"]) if "turbidity" in p else 3.0,
                          np.asarray(albedo, float),
                          self.number(p["sky_scale"]) if "sky_scale" in p else scale,
                          self.number(p["sun_scale"]) if "sun_scale" in p else scale,
                          math.radians(0.5 * aperture), self.where(el))
        s.check()
        unmapped = [k for k in ("stretch", "resolution", "extend", "complex_sun") if k in p]
        if old or unmapped:
            what = "Mitsuba 3's sun and sky model (Hosek-Wilkie, RGB), not 0.6's (Preetham's sun, its units)"
            self.warn(el, f"sunsky renders {what if old else 'as Mitsuba 3 does'}"
                          + (f"; {', '.join(unmapped)} not mapped" if unmapped else ""))
        return s

    def envmap(self, el, p):
        """An `envmap` emitter as the tracer's Environment in Mitsuba 3's convention (looked up as
        Mitsuba 3 does, tracer.scene.Environment): the image (8- and 16-bit files decoded from
        sRGB) times `scale`, and `to_world`'s rotation (its columns normalised)."""
        from ..textures import read_texture

        if "filename" not in p:
            raise SceneError(f"{self.where(el)}: envmap without a filename")
        file = self.file(el, self.attr(p["filename"], "value"))
        if not os.path.isfile(file):
            self.missing(el, "environment map", file, "the scene renders without it")
            return None
        # as Mitsuba 3 converts it: 8- and 16-bit images decoded from sRGB, grey to RGB, alpha dropped
        img = read_texture(file, what="environment map").astype(np.float64)
        img = img * (self.number(p["scale"]) if "scale" in p else 1.0)
        if not np.all(np.isfinite(img)) or img.min() < 0.0:
            raise SceneError(f"{file}: environment map has negative or non-finite pixels")
        if img.shape[0] < 3 or img.shape[1] < 2:
            raise SceneError(f"{file}: an environment map needs at least 2x3 pixels (Mitsuba 3's limit), "
                             f"got {img.shape[1]}x{img.shape[0]}")
        m = self.matrix(p["to_world"]) if "to_world" in p else np.eye(4)
        rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
        return Environment(np.zeros(3), img, file, convention="mitsuba", to_world=rot)

    def rgb(self, el):
        if el.tag == "float":
            return (self.number(el),) * 3
        if el.tag in ("rgb", "spectrum", "color", "srgb"):
            text = self.attr(el, "value", "").strip()
            if el.tag == "spectrum" and ":" in text:  # wavelength:value pairs: their mean, grey
                try:
                    vals = [float(w.split(":")[1]) for w in re.split(r"[,\s]+", text) if w]
                except (IndexError, ValueError):
                    raise SceneError(f"{self.where(el)}: malformed spectrum {text!r}") from None
                self.warn(el, "a sampled spectrum is read as the grey of its mean value")
                return (float(np.mean(vals)),) * 3
            try:
                vals = [float(x) for x in re.split(r"[,\s]+", text) if x]
            except ValueError:
                raise SceneError(f"{self.where(el)}: {self.name(el)!r} needs numbers, got {text!r}") from None
            if len(vals) == 1:
                vals = vals * 3
            if len(vals) != 3:
                raise SceneError(f"{self.where(el)}: {self.name(el)!r} needs 1 or 3 numbers")
            if el.tag == "srgb":  # 0.6's sRGB-encoded colour, decoded
                vals = srgb_decode(vals, np.float64).tolist()
            return tuple(vals)
        raise SceneError(f"{self.where(el)}: {self.name(el)!r} must be a colour here, not <{el.tag}>")

    def color_or_texture(self, el, default):
        """(rgb constant, TextureSpec or None) of a reflectance property (None: the default)."""
        if el is None:
            return default, None
        if el.tag == "ref":
            found = self.ids.get(self.attr(el, "id"))
            if found is None:
                raise SceneError(f"{self.where(el)}: no texture with id {el.get('id')!r}")
            el = found
        if el.tag == "texture":
            return default, self.texture(el)
        return self.rgb(el), None

    def matrix(self, el):
        """The 4x4 of a <transform>: its children applied in order."""
        m = np.eye(4)
        for c in el:
            if c.tag == "matrix":
                vals = [float(x) for x in re.split(r"[,\s]+", self.attr(c, "value").strip()) if x]
                if len(vals) == 16:
                    t = np.array(vals).reshape(4, 4)
                elif len(vals) == 9:
                    t = np.eye(4)
                    t[:3, :3] = np.array(vals).reshape(3, 3)
                else:
                    raise SceneError(f"{self.where(c)}: a matrix needs 9 or 16 numbers")
            elif c.tag in ("translate", "scale"):
                if "value" in c.attrib:
                    v = [float(x) for x in re.split(r"[,\s]+", self.attr(c, "value").strip()) if x]
                    v = v * 3 if len(v) == 1 else v
                else:
                    d = 0.0 if c.tag == "translate" else 1.0
                    v = [float(self.attr(c, k, d)) for k in ("x", "y", "z")]
                t = np.eye(4)
                if c.tag == "translate":
                    t[:3, 3] = v
                else:
                    t[0, 0], t[1, 1], t[2, 2] = v
            elif c.tag == "rotate":
                axis = np.array([float(self.attr(c, k, 0.0)) for k in ("x", "y", "z")])
                ang = np.radians(float(self.attr(c, "angle", 0.0)))
                n = np.linalg.norm(axis)
                if n == 0:
                    raise SceneError(f"{self.where(c)}: rotate needs a non-zero axis")
                if abs(n - 1.0) > 1e-6:
                    self.warn_once(c, f"rotate axis {tuple(float(x) for x in axis)} is normalised (Mitsuba 3 uses "
                                      f"an axis as written, which scales as well as turns)")
                a = axis / n
                k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
                t = np.eye(4)
                t[:3, :3] = np.eye(3) + np.sin(ang) * k + (1 - np.cos(ang)) * k @ k
            elif c.tag in ("lookat", "lookAt"):
                o = np.array([float(x) for x in re.split(r"[,\s]+", self.attr(c, "origin").strip()) if x])
                tg = np.array([float(x) for x in re.split(r"[,\s]+", self.attr(c, "target").strip()) if x])
                up = np.array([float(x) for x in re.split(r"[,\s]+", self.attr(c, "up", "0 1 0").strip()) if x])
                f = (tg - o) / np.linalg.norm(tg - o)
                left = np.cross(up, f)
                left /= np.linalg.norm(left)
                t = np.eye(4)
                t[:3, 0], t[:3, 1], t[:3, 2], t[:3, 3] = left, np.cross(f, left), f, o
            else:
                self.warn(c, f"transform <{c.tag}> is not supported; ignored")
                continue
            m = t @ m
        return m

    # --- textures and BSDFs ----------------------------------------------------------------------
    def texture(self, el):
        kind = self.attr(el, "type")
        p = self.props(el)
        uv = np.eye(3)
        if "to_uv" in p:
            t = self.matrix(p["to_uv"])
            uv = np.array([[t[0, 0], t[0, 1], t[0, 3]], [t[1, 0], t[1, 1], t[1, 3]], [0, 0, 1]])
        s_o = [self.number(p[k]) if k in p else d for k, d in (("uscale", 1.0), ("vscale", 1.0), ("uoffset", 0.0),
                                                                ("voffset", 0.0))]  # 0.6's scale and offset
        uv = np.array([[s_o[0], 0, s_o[2]], [0, s_o[1], s_o[3]], [0, 0, 1]]) @ uv
        # Mitsuba reads the texture at (u, 1 - v) of our UVs
        flip = np.array([[1.0, 0, 0], [0, -1.0, 1.0], [0, 0, 1]])
        m = uv @ flip
        if kind == "bitmap":
            m = flip @ m  # our bitmap lookup flips v back (rows from the top at v' = 1)
            if "filename" not in p:
                raise SceneError(f"{self.where(el)}: bitmap without a filename")
            file = self.file(el, self.attr(p["filename"], "value"))
            if not os.path.isfile(file):
                self.missing(el, "texture", file, "its constant 0.5 is used")
            gamma = self.number(p["gamma"]) if "gamma" in p else 0.0  # 0.6: 1 linear, -1 sRGB
            if "raw" in p and self.attr(p["raw"], "value") == "true":  # Mitsuba 3: no sRGB decoding
                gamma = 1.0
            filt = self.attr(p["filter_type"], "value") if "filter_type" in p else "bilinear"
            if filt != "bilinear":
                self.warn_once(p["filter_type"], f"bitmap filter_type {filt!r} is read as bilinear (no mip maps)")
            wrap = self.attr(p["wrap_mode"], "value") if "wrap_mode" in p else "repeat"
            if wrap != "repeat":
                self.warn_once(p["wrap_mode"], f"bitmap wrap_mode {wrap!r} is read as repeat")
            self.done(el, p)
            return TextureSpec("bitmap", file, uv=tuple(m[:2].reshape(-1)),
                               fallback=(0.5, 0.5, 0.5), where=self.where(el), gamma=gamma)
        if kind == "checkerboard":
            c0 = self.rgb(p["color0"]) if "color0" in p else (0.4, 0.4, 0.4)
            c1 = self.rgb(p["color1"]) if "color1" in p else (0.2, 0.2, 0.2)
            self.done(el, p)
            return TextureSpec("checker", color0=c0, color1=c1, uv=tuple(m[:2].reshape(-1)), where=self.where(el))
        self.warn(el, f"texture type {kind!r} is not supported; its constant 0.5 is used")
        return None

    def warn_once(self, el, msg):
        """A warning shown once per message (the first place it applies)."""
        if msg not in self.said:
            self.said.add(msg)
            self.warn(el, msg)

    def add_texture(self, spec):
        if spec is None:
            return -1
        self.textures.append(spec)
        return len(self.textures) - 1

    def bsdf(self, el, one_sided=True):
        """(type, param (N_PARAM,), tex (N_TEX_SLOTS,)) of a <bsdf>."""
        kind = self.attr(el, "type")
        p = self.props(el)
        param = np.zeros(bsdfs.N_PARAM)
        tex = [-1] * N_TEX_SLOTS
        flags = bsdfs.ONE_SIDED if one_sided else 0
        if kind in ("twosided", "mask", "bumpmap"):
            inner = [c for c in el if c.tag in ("bsdf", "ref")]
            if not inner:
                raise SceneError(f"{self.where(el)}: {kind} without a nested bsdf")
            child = inner[0] if inner[0].tag == "bsdf" else self.ids.get(self.attr(inner[0], "id"))
            if child is None:
                raise SceneError(f"{self.where(inner[0])}: no bsdf with id {inner[0].get('id')!r}")
            mtype, param, tex = self.bsdf(child, one_sided=one_sided and kind != "twosided")
            if kind == "mask":  # opacity: a number or a texture (its luminance), 0.5 by default
                op, t = self.color_or_texture(p.get("opacity"), (0.5, 0.5, 0.5))
                param[bsdfs.P_CLEAR] = 1.0 - min(max(float(np.mean(op)), 0.0), 1.0)
                if t is not None:
                    param[bsdfs.P_CLEAR] = 0.0
                    t.fallback = (1.0, 1.0, 1.0)  # an unreadable mask: opaque
                    tex[TEX_SLOT_OPACITY] = self.add_texture(t)
            elif kind == "bumpmap":  # the height texture (any name), its scale
                hs = [c for c in el if c.tag in ("texture", "ref") and c is not inner[0]]
                if not hs:
                    raise SceneError(f"{self.where(el)}: bumpmap without a height texture")
                _, t = self.color_or_texture(hs[0], (0.0, 0.0, 0.0))
                if t is None:
                    raise SceneError(f"{self.where(hs[0])}: bumpmap's height must be a texture")
                tex[TEX_SLOT_BUMP] = self.add_texture(t)
                param[P_BUMP_SCALE] = self.number(p["scale"]) if "scale" in p else 1.0
                inner = inner + hs
            self.done(el, p, ignore={self.name(c) for c in inner})
            return mtype, param, list(tex)
        mtype, param, tex = self.leaf_bsdf(el, kind, p, param, tex, flags)
        self.done(el, p, ignore={"sample_visible", "sampleVisible"})
        return mtype, param, tex

    def leaf_bsdf(self, el, kind, p, param, tex, flags):
        """(type, param, tex) of a BSDF that wraps no other."""
        alpha = self.number(p["alpha"]) if kind.startswith("rough") and "alpha" in p else 0.1
        dist = self.attr(p["distribution"], "value") if kind.startswith("rough") and "distribution" in p \
            else "beckmann"
        coat = kind in ("plastic", "roughplastic")
        glass = kind in ("dielectric", "roughdielectric", "thindielectric")
        ior_in = self.ior(p, "int_ior", "polypropylene" if coat else "bk7") if coat or glass else 1.0
        ior_out = self.ior(p, "ext_ior", "air") if coat or glass else 1.0
        if kind in ("diffuse", "roughdiffuse"):
            if kind == "roughdiffuse":
                self.warn(el, "roughdiffuse is rendered as diffuse (as Mitsuba 3 does)")
            kd, t = self.color_or_texture(p.get("reflectance"), (0.5, 0.5, 0.5))
            param[0:3] = kd
            tex[TEX_SLOT_KD] = self.add_texture(t)
            param[14] = flags
            return bsdfs.DIFFUSE, param, tex
        if kind in ("conductor", "roughconductor"):
            ks, t = self.color_or_texture(p.get("specular_reflectance"), (1.0, 1.0, 1.0))
            param[3:6] = ks
            tex[TEX_SLOT_KS] = self.add_texture(t)
            metal = self.attr(p["material"], "value") if "material" in p else "Cu"
            if metal not in METALS:
                raise SceneError(f"{self.where(el)}: conductor material {metal!r} unknown; valid: {', '.join(METALS)}")
            eta, k = METALS[metal]
            if "eta" in p:
                eta = self.rgb(p["eta"])
            if "k" in p:
                k = self.rgb(p["k"])
            ext = self.number(p["ext_eta"]) if "ext_eta" in p else 1.0
            param[8:11] = np.asarray(eta) / ext
            param[11:14] = np.asarray(k) / ext
            param[6] = alpha if kind == "roughconductor" else 0.0
            if kind == "roughconductor" and dist == "beckmann":
                flags |= bsdfs.BECKMANN
            param[14] = flags
            return bsdfs.METAL, param, tex
        if kind in ("dielectric", "roughdielectric", "thindielectric"):
            param[7] = ior_in / ior_out
            if kind == "roughdielectric":
                if dist != "ggx":
                    self.warn(el, "roughdielectric with the Beckmann distribution is rendered with GGX")
                param[6] = alpha
                return bsdfs.ROUGH_DIELECTRIC, param, tex
            return (bsdfs.THIN_DIELECTRIC if kind == "thindielectric" else bsdfs.DIELECTRIC), param, tex
        if coat:
            kd, t = self.color_or_texture(p.get("diffuse_reflectance"), (0.5, 0.5, 0.5))
            param[0:3] = kd
            tex[TEX_SLOT_KD] = self.add_texture(t)
            ks, t = self.color_or_texture(p.get("specular_reflectance"), (1.0, 1.0, 1.0))
            param[3:6] = ks
            tex[TEX_SLOT_KS] = self.add_texture(t)
            param[6] = alpha if kind == "roughplastic" else 0.0
            param[7] = ior_in / ior_out
            if kind == "roughplastic" and dist == "beckmann":
                flags |= bsdfs.BECKMANN
            if "nonlinear" in p and self.attr(p["nonlinear"], "value") == "true":
                flags |= bsdfs.NONLINEAR
            param[14] = flags
            return bsdfs.COATED, param, tex
        self.warn(el, f"bsdf type {kind!r} is not supported; rendered as diffuse 0.5")
        p.used.update(p)
        param[0:3] = 0.5
        return bsdfs.DIFFUSE, param, tex

    # --- shapes -------------------------------------------------------------------------------
    def shape(self, el):
        kind = self.attr(el, "type")
        p = self.props(el)
        smooth = False
        m = self.matrix(p["to_world"]) if "to_world" in p else np.eye(4)
        if kind in ("obj", "ply", "serialized"):
            if "filename" not in p:
                raise SceneError(f"{self.where(el)}: shape {kind!r} without a filename")
            file = self.file(el, self.attr(p["filename"], "value"))
            if not os.path.isfile(file):
                self.missing(el, "shape file", file, "the shape is left out")
                p.used.update(p)
                return
            if kind == "obj":
                mesh = read_geometry(file, self.warnings)
            elif kind == "ply":
                mesh = read_ply(file)
                if "flip_tex_coords" in p and self.attr(p["flip_tex_coords"], "value") == "true" \
                        and mesh.uv is not None:
                    mesh.uv[..., 1] = 1.0 - mesh.uv[..., 1]
            else:
                mesh = read_serialized(file, int(self.number(p["shape_index"])) if "shape_index" in p else 0)
            tri, uv, nrm = mesh.tri, mesh.uv, mesh.normals
            face = self.attr(p["face_normals"], "value") == "true" if "face_normals" in p \
                else getattr(mesh, "face_normals", False)
            if face:
                nrm = None
            elif nrm is None:  # Mitsuba computes smooth normals for a mesh without them, in world space
                smooth = True
        elif kind == "rectangle":
            tri = np.array([[[-1, -1, 0], [1, -1, 0], [1, 1, 0]], [[-1, -1, 0], [1, 1, 0], [-1, 1, 0]]], float)
            uv = np.array([[[0, 1], [1, 1], [1, 0]], [[0, 1], [1, 0], [0, 0]]], float)  # Mitsuba's (u, 1 - v)
            nrm = None
        elif kind == "cube":
            tri, uv, nrm = _cube()
        elif kind == "sphere":
            c = np.asarray(self.point(p["center"]) if "center" in p else (0.0, 0.0, 0.0))
            r = self.number(p["radius"]) if "radius" in p else 1.0
            tri, uv, nrm = _sphere(SPHERE_RINGS)
            m = m @ np.array([[r, 0, 0, c[0]], [0, r, 0, c[1]], [0, 0, r, c[2]], [0, 0, 0, 1]])
        elif kind == "disk":
            tri, uv, nrm = _disk(DISK_SEGMENTS)
        elif kind == "cylinder":
            p0 = np.asarray(self.point(p["p0"]) if "p0" in p else (0.0, 0.0, 0.0))
            p1 = np.asarray(self.point(p["p1"]) if "p1" in p else (0.0, 0.0, 1.0))
            r = self.number(p["radius"]) if "radius" in p else 1.0
            tri, uv, nrm = _cylinder(DISK_SEGMENTS)
            m = m @ _frame_to(p0, p1, r)
        else:
            self.warn(el, f"shape type {kind!r} is not supported; the shape is left out")
            p.used.update(p)
            return
        flip = "flip_normals" in p and self.attr(p["flip_normals"], "value") == "true"
        tri = tri @ m[:3, :3].T + m[:3, 3]  # (the winding, and so the normal, of the world-space corners)
        if flip:
            tri = tri[:, ::-1]
            uv = uv[:, ::-1] if uv is not None else None
            nrm = nrm[:, ::-1] if nrm is not None else None
        if nrm is not None:
            nrm = nrm @ np.linalg.inv(m[:3, :3])  # normals by the inverse transpose
            if flip:
                nrm = -nrm
        elif smooth:
            nrm = vertex_normals(tri)
        # material: the shape's BSDF (a shared one is one material), with its emission if any
        b = [c for c in el if c.tag in ("bsdf", "ref")]
        bel = None
        name = f"{kind}@{getattr(el, 'line', '?')}"
        if b:
            bel = b[0] if b[0].tag == "bsdf" else self.ids.get(self.attr(b[0], "id"))
            if bel is None:
                raise SceneError(f"{self.where(b[0])}: no bsdf with id {b[0].get('id')!r}")
            name = bel.get("id") or f"bsdf@{getattr(bel, 'line', '?')}"
        emission = np.zeros(3)
        for e in (c for c in el if c.tag == "emitter"):
            if self.attr(e, "type") != "area":
                self.warn(e, f"emitter type {self.attr(e, 'type')!r} on a shape is not supported; ignored")
                continue
            ep = self.props(e)
            emission = np.asarray(self.rgb(ep["radiance"]) if "radiance" in ep else (1.0, 1.0, 1.0))
            self.done(e, ep)
            name = f"{name}+emitter@{e.line}"
        if name not in self.by_name:
            if bel is not None:
                mtype, param, tex = self.bsdf(bel)
            else:  # Mitsuba's default: diffuse 0.5, one-sided
                mtype, param, tex = bsdfs.DIFFUSE, np.zeros(bsdfs.N_PARAM), [-1] * N_TEX_SLOTS
                param[0:3] = 0.5
                param[14] = bsdfs.ONE_SIDED
            self.by_name[name] = len(self.materials)
            self.materials.append((name, mtype, param, emission, tuple(tex)))
        n = tri.shape[0]
        self.tris.append(tri)
        self.mats.append(np.full(n, self.by_name[name], np.int32))
        self.uvs.append(uv if uv is not None else np.zeros((n, 3, 2)))
        self.normals.append(nrm if nrm is not None else np.zeros((n, 3, 3)))
        self.done(el, p)

    def include(self, node, chain):
        """Replace node's <include> children by the children of the files they name (recursively;
        a file that includes itself, directly or not, is an error naming the cycle)."""
        out = []
        for c in node.children:
            if c.tag != "include":
                self.include(c, chain)
                out.append(c)
                continue
            name = self.attr(c, "filename")
            if not name:
                raise SceneError(f"{self.where(c)}: include without a filename")
            file = os.path.abspath(self.file(c, name))
            if file in chain:
                cycle = " -> ".join(os.path.basename(f) for f in chain[chain.index(file):] + [file])
                raise SceneError(f"{self.where(c)}: include cycle ({cycle})")
            if not os.path.isfile(file):
                raise SceneError(f"{self.where(c)}: included file {name!r} not found")
            root = _parse(file)
            if root.tag != "scene":
                raise SceneError(f"{file}: the root element is <{root.tag}>, not <scene>")
            self.include(root, chain + [file])
            out.extend(root.children)
        node.children = out

    # --- the scene ------------------------------------------------------------------------------
    def read(self):
        root = _parse(self.path)
        if root.tag != "scene":
            raise SceneError(f"{self.path}: the root element is <{root.tag}>, not <scene>")
        self.include(root, [os.path.abspath(self.path)])
        self.version = root.get("version", "3")
        for el in root:
            if el.tag == "default":
                self.defaults.setdefault(el.get("name"), el.get("value"))
        for el in root.iter():
            if el.get("id") is not None and el.tag in ("bsdf", "texture"):
                self.ids[el.get("id")] = el
        spec_cam, width, height, render = CameraSpec(where=f"{self.path}: sensor"), 768, 576, RenderSettings()
        for el in root:
            tag = el.tag
            if tag in ("default", "bsdf", "texture"):
                continue
            if tag == "integrator":
                p = self.props(el)
                kind = self.attr(el, "type")
                if kind not in ("path", "volpath", "direct"):
                    self.warn(el, f"integrator {kind!r}: the tracer renders with its own path tracer "
                                  f"(or the method chosen); its max_depth is kept")
                if "max_depth" in p:
                    render.max_depth = int(self.number(p["max_depth"]))
                if kind == "direct":
                    render.max_depth = 2
                if "rr_depth" in p:
                    render.rr_depth = int(self.number(p["rr_depth"]))
                self.done(el, p)
            elif tag == "sensor":
                spec_cam, width, height, spp = self.sensor(el, spec_cam)
                if spp:
                    render.spp = spp
            elif tag == "shape":
                self.shape(el)
            elif tag == "emitter":
                self.emitter(el)
            else:
                self.warn(el, f"<{tag}> is not supported yet; ignored")
        self.warn_unused()
        if not self.tris:
            raise SceneError(f"{self.path}: no shape the tracer can read")
        has_uv = any(np.any(u) for u in self.uvs)
        has_n = any(np.any(n) for n in self.normals)
        return SceneSpec(path=self.path, geometry_file=self.path, tri=np.concatenate(self.tris),
                         tri_material=np.concatenate(self.mats), materials=self.materials, width=width,
                         height=height, render=render, camera=spec_cam, warnings=self.warnings,
                         no_light="no area emitter on any shape, no environment and no point, spot or "
                                  "directional light",
                         environment=self.environment, uv=np.concatenate(self.uvs) if has_uv else None,
                         normals=np.concatenate(self.normals) if has_n else None, textures=self.textures,
                         delta_lights=self.delta_lights)

    def sensor(self, el, cam):
        if self.attr(el, "type") not in ("perspective", "thinlens"):
            raise SceneError(f"{self.where(el)}: sensor type {self.attr(el, 'type')!r} is not supported")
        if self.attr(el, "type") == "thinlens":
            self.warn(el, "thinlens is rendered as a pinhole (perspective)")
        p = self.props(el)
        cam.fov = self.number(p["fov"]) if "fov" in p else 45.0
        axis = self.attr(p["fov_axis"], "value") if "fov_axis" in p else "x"
        if axis not in ("x", "y", "diagonal", "smaller", "larger"):
            raise SceneError(f"{self.where(p['fov_axis'])}: fov_axis {axis!r} unknown; valid: x, y, diagonal, "
                             f"smaller, larger")
        cam.fov_axis = axis
        if "to_world" in p:
            cam.matrix = self.matrix(p["to_world"])
        if "near_clip" in p:
            cam.near = self.number(p["near_clip"])
            if cam.near < 0.0:
                raise SceneError(f"{self.where(p['near_clip'])}: near_clip must be >= 0")
        far = p.get("far_clip")  # (Mitsuba's default 1e4; a nearer one is not applied)
        if far is not None and self.number(far) < 1e4:
            self.warn(far, "far_clip is not applied (the tracer's rays are unbounded)")
        if self.attr(el, "type") == "thinlens":
            p.used.update({"aperture_radius", "focus_distance", "apertureRadius", "focusDistance"})
        width, height, spp = 768, 576, 0
        for c in el:
            if c.tag == "film":
                fp = self.props(c)
                width = int(self.number(fp["width"])) if "width" in fp else width
                height = int(self.number(fp["height"])) if "height" in fp else height
                for f in c:
                    if f.tag == "rfilter" and self.attr(f, "type") != "box":
                        self.warn(f, f"rfilter {self.attr(f, 'type')!r} is rendered with the box filter")
                self.done(c, fp, ignore=FILM_OUTPUT)
            elif c.tag == "sampler":
                sp = self.props(c)
                spp = int(self.number(sp["sample_count"])) if "sample_count" in sp else 0
                self.done(c, sp, ignore={"seed"})
        self.done(el, p)
        if cam.fov_axis in ("diagonal", "smaller", "larger"):  # as the horizontal fov Mitsuba means
            t = math.tan(math.radians(cam.fov) / 2.0)
            if cam.fov_axis == "diagonal":
                t *= width / math.hypot(width, height)
            elif (cam.fov_axis == "smaller") == (height < width):
                t *= width / height  # the fov is the vertical one
            cam.fov, cam.fov_axis = math.degrees(2.0 * math.atan(t)), "x"
        return cam, width, height, spp


def read_sunsky(path, defines=None):
    """The tracer.sunsky.SunSky of the first top-level `sunsky` emitter of a scene file (None if it
    has none), without reading the rest of the scene."""
    r = _Reader(path, defines)
    root = _parse(path)
    r.version = root.get("version", "3")
    for el in root:
        if el.tag == "default":
            r.defaults.setdefault(el.get("name"), el.get("value"))
    for el in root:
        if el.tag == "emitter" and r.attr(el, "type") == "sunsky":
            return r.sunsky_model(el, r.props(el))
    return None


def read_mitsuba_scene(path, defines=None, allow_missing=False):
    """The SceneSpec of a Mitsuba scene XML (see the module docstring); `defines` override its
    <default> values as `mitsuba -D name=value` does; allow_missing turns a missing mesh, texture
    or environment map into a warning (the shape left out, the texture a constant)."""
    return _Reader(path, defines, allow_missing).read()

