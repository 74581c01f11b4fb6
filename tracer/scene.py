"""Scenes: an OBJ + MTL (geometry through tracer.objread, or trimesh) and an optional JSON sidecar.

`load_scene(path, **overrides)` takes either `name.obj` (with `name.json` beside it if
present) or a JSON scene file that names its OBJ under the key `"obj"`. The sidecar says
what OBJ cannot (see README, "Scene files"):

    camera       {origin, target, up, fov (degrees), fov_axis: "x" | "y"}
    film         {width, height}
    render       {spp, max_depth, rr_depth, seed}
    environment  {radiance: [r, g, b]}  or  {map: file.exr, scale}
    materials    {mtl_name: {type, kd, ks, alpha, ior, emission}}

MTL statements map to BSDFs as `tracer.bsdfs` documents: `Kd` Lambertian; `Ke` one-sided
emission (every emissive triangle is an area light); `illum 4/6/7` + `Ni` smooth dielectric
(rough if `Pr` is given); `illum 3/5` mirror tinted by `Ks`; `Pr` + `Pm 1` rough metal with
GGX alpha = Pr^2; other `Ks` + `Ns` glossy plastic with alpha = sqrt(2 / (Ns + 2)).
Statements the tracer cannot honour are reported once per file, never silently dropped.
"""
import json
import logging
import math
import os
from dataclasses import dataclass, field

import numpy as np

from . import bsdfs
from .camera import Camera
from .errors import SceneError, SettingsError
from .framing import frame_camera, outside_view, view_axes
from .objread import read_obj, triangle_areas

log = logging.getLogger("tracer")

SIDECAR_KEYS = {
    "camera": {"origin", "target", "up", "fov", "fov_axis"},
    "film": {"width", "height"},
    "render": {"spp", "max_depth", "rr_depth", "seed"},
    "environment": {"radiance", "map", "scale"},
    "materials": None,  # keyed by material name
    "obj": None,  # only in a JSON scene file
}
MATERIAL_KEYS = {"type", "kd", "ks", "alpha", "ior", "emission"}
# Keyword overrides of load_scene and the sidecar section each one belongs to.
OVERRIDES = {
    "width": "film",
    "height": "film",
    "spp": "render",
    "max_depth": "render",
    "rr_depth": "render",
    "seed": "render",
    "fov": "camera",
}
RENDER_DEFAULTS = {"spp": 16, "max_depth": -1, "rr_depth": 5, "seed": 0}
_MTL_USED = {"newmtl", "Kd", "Ks", "Ke", "Ns", "Ni", "illum", "Pr", "Pm"}


@dataclass
class Materials:
    """Struct of arrays, one row per material (see `tracer.bsdfs` for the encoding)."""

    names: list
    type: np.ndarray  # (M,) int32, bsdfs.DIFFUSE ...
    param: np.ndarray  # (M, 8) float64: kd rgb, ks rgb, alpha, ior
    emission: np.ndarray  # (M, 3) float64 radiance, one-sided

    def __repr__(self):
        kinds = [bsdfs.TYPE_NAMES[t] for t in self.type]
        return "Materials(" + ", ".join(f"{n}: {k}" for n, k in zip(self.names, kinds)) + ")"


@dataclass
class Environment:
    """Light from infinitely far away: a constant radiance or an equirectangular map.

    Map convention (+y up): u = 0.5 + atan2(d.x, -d.z) / (2 pi), v = acos(d.y) / pi,
    row 0 of the image at v = 0 (straight up).
    """

    radiance: np.ndarray  # (3,) float64, constant term (zero when a map is used)
    image: np.ndarray | None = None  # (H, W, 3) float64 radiance (already scaled), or None
    path: str | None = None

    def __repr__(self):
        if self.image is not None:
            return f"Environment(map={self.path!r}, {self.image.shape[1]}x{self.image.shape[0]})"
        return f"Environment(radiance={self.radiance.tolist()})"


@dataclass
class RenderSettings:
    spp: int = 16
    max_depth: int = -1  # Mitsuba convention: 1 = emitters seen directly, 2 = direct light, -1 = unlimited
    rr_depth: int = 5  # Russian roulette from this depth on
    seed: int = 0


@dataclass
class Scene:
    """Everything a render needs, in flat arrays.

    tri          (F, 3, 3) float64  world-space triangle vertices (degenerate ones removed)
    tri_material (F,) int32         material index per triangle
    """

    path: str
    tri: np.ndarray
    tri_material: np.ndarray
    materials: Materials
    camera: Camera
    width: int
    height: int
    render: RenderSettings
    environment: Environment | None
    bounds: np.ndarray  # (2, 3) float64
    warnings: list = field(default_factory=list)
    framing: str = ""  # how a camera the scene did not give was chosen (tracer.framing); "" if it gave one

    @property
    def n_triangles(self):
        return int(self.tri.shape[0])

    @property
    def emissive(self):
        """(F,) bool: triangles whose material emits."""
        return np.any(self.materials.emission[self.tri_material] > 0.0, axis=1)

    def __repr__(self):
        return (
            f"Scene({os.path.basename(self.path)!r}, {self.n_triangles} triangles, "
            f"{len(self.materials.names)} materials, {int(self.emissive.sum())} emissive triangles, "
            f"{self.width}x{self.height}, env={self.environment!r})"
        )


# --- Reading files ---------------------------------------------------------------------------
def _warn(scene_warnings, msg, level=logging.WARNING):
    """Record `msg` in the scene's warnings and log it (at `level`: INFO for what changes no pixel,
    which the command line shows only with -v)."""
    scene_warnings.append(msg)
    log.log(level, msg)


def _read_json(path):
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except FileNotFoundError:
        raise SceneError(f"{path}: scene file not found") from None
    except json.JSONDecodeError as e:
        raise SceneError(f"{path}: malformed JSON at line {e.lineno}: {e.msg}") from None
    if not isinstance(data, dict):
        raise SceneError(f"{path}: a scene sidecar must be a JSON object")
    return data


def _check_keys(where, got, allowed):
    bad = sorted(set(got) - set(allowed))
    if bad:
        raise SceneError(f"{where}: unknown key {bad[0]!r}; valid: {', '.join(sorted(allowed))}")


def _vec3(where, value):
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        v = None
    if v is None or v.shape != (3,) or not np.all(np.isfinite(v)):
        raise SceneError(f"{where}: expected three finite numbers, got {value!r}")
    return v


def _number(where, value, kind=float, lo=None):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where}: expected a number, got {value!r}")
    if kind is int and value != int(value):
        raise SceneError(f"{where}: expected an integer, got {value!r}")
    value = kind(value)
    if not math.isfinite(value) or (lo is not None and value < lo):
        raise SceneError(f"{where}: expected a finite number >= {lo}, got {value!r}")
    return value


def _read_bytes(path, what):
    try:
        with open(path, "rb") as f:
            return f.read()
    except FileNotFoundError:
        raise SceneError(f"{path}: {what} file not found") from None
    except OSError as e:
        raise SceneError(f"{path}: cannot read {what} ({e.strerror})") from None


def _check_text(path, data, what):
    """`data` (a file's bytes), or SceneError unless it looks like text: a NUL byte in its first
    64 KiB (and no UTF-16 byte-order mark) means a binary file, e.g. a binary PLY or FBX named .obj."""
    head = data[:65536]
    nul = head.find(b"\x00")
    if nul >= 0 and not head.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise SceneError(f"{path}: not a text {what} file (it holds binary data: a zero byte at offset {nul})")
    return data


def read_text(path, what):
    """The text of an OBJ or MTL file: UTF-8 (with or without a BOM), else the encoding
    charset_normalizer finds most likely (a Latin-1 comment is common in exported files)."""
    data = _read_bytes(path, what)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        pass
    import charset_normalizer

    best = charset_normalizer.from_bytes(data).best()
    return str(best) if best is not None else data.decode("latin-1")


@dataclass
class ObjScan:
    """What scan_obj learned: the decoded text, the `mtllib` file names and the `usemtl` names
    (in order of first use)."""

    text: str
    mtllibs: list
    usemtl: list


def scan_obj(path):
    """Validate an OBJ line by line before trimesh reads it, so that errors name the line.

    Checks that `v` lines hold three finite numbers and `f` lines hold vertex indices that
    exist. Returns an ObjScan (text, `mtllib` file names, `usemtl` names).
    """
    text = read_text(path, "OBJ")
    mtllibs, usemtl = [], {}
    nv = 0
    for lineno, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        key = parts[0]
        if key == "v":
            try:
                xyz = [float(x) for x in parts[1:4]]
            except ValueError:
                xyz = []
            if len(xyz) != 3:
                raise SceneError(f"{path}:{lineno}: malformed vertex line {line.strip()!r}")
            if not all(math.isfinite(x) for x in xyz):
                raise SceneError(f"{path}:{lineno}: vertex is not finite: {line.strip()!r}")
            nv += 1
        elif key == "f":
            if len(parts) < 4:
                raise SceneError(f"{path}:{lineno}: a face needs at least 3 vertices: {line.strip()!r}")
            for item in parts[1:]:
                try:
                    idx = int(item.split("/")[0])
                except ValueError:
                    raise SceneError(f"{path}:{lineno}: malformed face line {line.strip()!r}") from None
                if idx == 0 or idx > nv or -idx > nv:
                    raise SceneError(
                        f"{path}:{lineno}: face refers to vertex {idx}, but {nv} vertices are defined"
                    )
        elif key == "mtllib":
            mtllibs.extend(parts[1:])
        elif key == "usemtl" and len(parts) > 1:
            usemtl.setdefault(" ".join(parts[1:]), None)
    return ObjScan(text, mtllibs, list(usemtl))


def parse_mtl(path, warnings):
    """Read an MTL file into {name: {statement: [floats]}}; report what is ignored."""
    mats = {}
    ignored = {}
    missing = {}  # texture file name -> first line that names it
    cur = None
    for lineno, line in enumerate(read_text(path, "MTL").splitlines(), 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        key, args = parts[0], parts[1:]
        if key == "newmtl":
            if not args:
                raise SceneError(f"{path}:{lineno}: newmtl without a name")
            cur = " ".join(args)
            mats[cur] = {}
            continue
        if cur is None:
            raise SceneError(f"{path}:{lineno}: {key!r} before any newmtl")
        if key.startswith("map_") or key in ("bump", "disp", "decal", "refl", "norm"):
            # textures are replaced by the constant whether or not their file exists
            if not args or not os.path.isfile(os.path.join(os.path.dirname(path), args[-1])):
                missing.setdefault(args[-1] if args else "", lineno)
            ignored.setdefault(key + " (textures are not supported; the constant is used)", set()).add(cur)
            continue
        if key not in _MTL_USED:
            ignored.setdefault(key, set()).add(cur)
            continue
        try:
            vals = [float(a) for a in args]
        except ValueError:
            raise SceneError(f"{path}:{lineno}: malformed {key} line {line.strip()!r}") from None
        if not vals or not all(math.isfinite(v) for v in vals):
            raise SceneError(f"{path}:{lineno}: malformed {key} line {line.strip()!r}")
        if key in ("Kd", "Ks", "Ke"):
            if len(vals) == 1:
                vals = vals * 3
            if len(vals) != 3 or min(vals) < 0.0:
                raise SceneError(f"{path}:{lineno}: {key} needs three non-negative numbers")
        mats[cur][key] = vals
    for key, names in sorted(ignored.items()):
        _warn(warnings, f"{path}: ignoring unsupported statement {key} in {len(names)} material(s)")
    if missing:
        files = ", ".join(f"{name!r} (line {line})" for name, line in list(missing.items())[:3])
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        _warn(warnings, f"{path}: texture file(s) not found: {files}{more}; the constant is used anyway")
    return mats


def material_from_mtl(name, st, where, warnings):
    """(type, param (8,), emission (3,)) for one MTL material's statements."""
    kd = np.array(st.get("Kd", [0.0, 0.0, 0.0] if "Ke" in st else [0.8, 0.8, 0.8]))
    ks_given = "Ks" in st
    ks = np.array(st.get("Ks", [0.0, 0.0, 0.0]))
    ke = np.array(st.get("Ke", [0.0, 0.0, 0.0]))
    illum = int(st.get("illum", [2])[0])
    pr = st.get("Pr", [None])[0]
    pm = st.get("Pm", [0.0])[0]
    ior = st.get("Ni", [1.5])[0]
    alpha = 0.0
    if illum in (4, 6, 7):
        if "Ni" not in st:
            _warn(warnings, f"{where}: material {name!r} is a dielectric without Ni; using 1.5")
        if ior <= 0.0:
            raise SceneError(f"{where}: material {name!r} has Ni {ior}, must be > 0")
        if pr is not None and pr > 0.0:
            mtype, alpha = bsdfs.ROUGH_DIELECTRIC, pr * pr
        else:
            mtype = bsdfs.DIELECTRIC
    elif illum in (3, 5):
        mtype = bsdfs.MIRROR
        ks = ks if ks_given else np.ones(3)
    elif pr is not None and pm >= 0.5:
        mtype, alpha = bsdfs.CONDUCTOR, pr * pr
        ks = ks if ks_given else kd
    elif ks_given and ks.max() > 0.0:
        mtype = bsdfs.PLASTIC
        alpha = bsdfs.ns_to_alpha(st.get("Ns", [0.0])[0])
        if np.any(kd + ks > 1.0):
            _warn(warnings, f"{where}: material {name!r} has Kd + Ks > 1 (reflects more than it receives)")
    else:
        mtype = bsdfs.DIFFUSE
    if pr is not None and mtype in (bsdfs.DIFFUSE, bsdfs.MIRROR, bsdfs.DIELECTRIC, bsdfs.PLASTIC) and pr > 0:
        _warn(warnings, f"{where}: material {name!r}: Pr without Pm 1 is ignored")
    if np.any(kd > 1.0) and mtype in (bsdfs.DIFFUSE, bsdfs.PLASTIC):
        _warn(warnings, f"{where}: material {name!r} has Kd > 1 (reflects more than it receives)")
    param = np.array([*kd, *ks, alpha, ior], dtype=np.float64)
    return mtype, param, ke.astype(np.float64)


def _material_override(name, spec, base, where):
    """Apply a sidecar `materials: {name: {...}}` entry to (type, param, emission)."""
    if not isinstance(spec, dict):
        raise SceneError(f"{where}: materials.{name} must be an object")
    _check_keys(f"{where}: materials.{name}", spec, MATERIAL_KEYS)
    mtype, param, emission = base
    param = param.copy()
    emission = emission.copy()
    if "type" in spec:
        if spec["type"] not in bsdfs.TYPE_NAMES:
            raise SceneError(
                f"{where}: materials.{name}.type {spec['type']!r} unknown; valid: {', '.join(bsdfs.TYPE_NAMES)}"
            )
        mtype = bsdfs.TYPE_NAMES.index(spec["type"])
    if "kd" in spec:
        param[0:3] = _vec3(f"{where}: materials.{name}.kd", spec["kd"])
    if "ks" in spec:
        param[3:6] = _vec3(f"{where}: materials.{name}.ks", spec["ks"])
    if "alpha" in spec:
        param[6] = _number(f"{where}: materials.{name}.alpha", spec["alpha"], lo=0.0)
    if "ior" in spec:
        param[7] = _number(f"{where}: materials.{name}.ior", spec["ior"], lo=1e-3)
    if "emission" in spec:
        emission = _vec3(f"{where}: materials.{name}.emission", spec["emission"])
    if param[:6].min() < 0.0 or emission.min() < 0.0:
        raise SceneError(f"{where}: materials.{name}: reflectances and emission must be >= 0")
    return mtype, param, emission


def _load_geometry(obj_path, scan):
    """Triangle soup (F,3,3) and [(usemtl name or None, face count)] through trimesh.

    trimesh reads the text scan_obj decoded, and instead of the OBJ's MTL files a stand-in that
    defines every `usemtl` name: trimesh forgets the name of a material its MTL lacks (and would
    load textures), while the tracer reads the MTL files itself."""
    import io

    import trimesh

    stand_in = "".join(f"newmtl {name}\nKd 0.8 0.8 0.8\n" for name in scan.usemtl).encode("utf-8")

    class _StandInMTL(trimesh.resolvers.FilePathResolver):
        def get(self, name):
            return stand_in

    try:
        text = "mtllib stand-in.mtl\n" + scan.text  # (trimesh reads the first mtllib, and none without one)
        tm = trimesh.load(io.BytesIO(text.encode("utf-8")), file_type="obj", process=False,
                          maintain_order=True, force="scene", resolver=_StandInMTL(obj_path))
    except Exception as e:  # trimesh raises many kinds; the pre-scan catches the common ones
        raise SceneError(f"{obj_path}: cannot read OBJ ({type(e).__name__}: {e})") from None
    tris, names = [], []
    for node in tm.graph.nodes_geometry:
        transform, gname = tm.graph[node]
        g = tm.geometry[gname]
        if not hasattr(g, "faces") or len(g.faces) == 0:
            continue
        v = np.asarray(g.vertices, dtype=np.float64)
        if not np.allclose(transform, np.eye(4)):
            v = v @ transform[:3, :3].T + transform[:3, 3]
        mat = getattr(getattr(g, "visual", None), "material", None)
        mname = getattr(mat, "name", None)
        tris.append(v[np.asarray(g.faces, dtype=np.int64)])
        names.append((mname, len(g.faces)))
    if not tris:
        raise SceneError(f"{obj_path}: the OBJ holds no faces")
    return np.concatenate(tris, axis=0), names


def read_geometry(obj_path):
    """(tri (F, 3, 3), [(usemtl name or None, face count)], mtllib names, usemtl names) of an
    OBJ: through the parallel reader (tracer.objread) when the file is made of the statements it
    reads, else checked line by line (errors name the line) and read by trimesh; both give the
    same triangles in the same order."""
    fast = read_obj(_check_text(obj_path, _read_bytes(obj_path, "OBJ"), "OBJ"))  # (it frees the bytes once parsed)
    if fast is not None:
        return fast
    scan = scan_obj(obj_path)
    tri, groups = _load_geometry(obj_path, scan)
    return tri, groups, scan.mtllibs, scan.usemtl


def load_scene(path, before_framing=None, **overrides):
    """Load a scene; keyword overrides replace sidecar values (width, height, spp, ...).

    Raises SceneError (one line, naming the file and the problem) for bad input. A scene without
    a camera is framed (tracer.framing: tiny renders, which compile the kernels on first use);
    before_framing(), if given, is called first (the command line's compile notice).
    """
    path = os.fspath(path)
    bad = sorted(set(overrides) - set(OVERRIDES))
    if bad:
        raise SettingsError(f"unknown scene override {bad[0]!r}; valid: {', '.join(sorted(OVERRIDES))}")
    warnings = []
    ext = os.path.splitext(path)[1].lower()
    if ext == ".json":
        sidecar_path = path
        sidecar = _read_json(path)
        if "obj" not in sidecar:
            raise SceneError(f"{path}: a JSON scene file must name its OBJ under the key 'obj'")
        obj_path = os.path.join(os.path.dirname(path), str(sidecar["obj"]))
    elif ext == ".obj":
        obj_path = path
        sidecar_path = os.path.splitext(path)[0] + ".json"
        sidecar = _read_json(sidecar_path) if os.path.isfile(sidecar_path) else {}
        if "obj" in sidecar:
            raise SceneError(f"{sidecar_path}: key 'obj' belongs in a JSON scene file, not in a sidecar")
    else:
        if not os.path.exists(path):
            raise SceneError(f"{path}: scene file not found")
        raise SceneError(f"{path}: not a scene file; give an .obj (with optional .json sidecar) or a .json")
    _check_keys(sidecar_path, sidecar, SIDECAR_KEYS)
    for section, allowed in SIDECAR_KEYS.items():
        if allowed is not None and section in sidecar:
            if not isinstance(sidecar[section], dict):
                raise SceneError(f"{sidecar_path}: '{section}' must be an object")
            _check_keys(f"{sidecar_path}: {section}", sidecar[section], allowed)

    # Geometry and materials
    tri, groups, mtllibs, usemtl = read_geometry(obj_path)
    mtl = {}
    for lib in mtllibs:
        mtl_path = os.path.join(os.path.dirname(obj_path), lib)
        if not os.path.isfile(mtl_path):
            raise SceneError(f"{obj_path}: MTL file {lib!r} not found (looked for {mtl_path})")
        mtl.update(parse_mtl(mtl_path, warnings))
    names = list(mtl)
    types, params, emissions = [], [], []
    for n in names:
        t, p, e = material_from_mtl(n, mtl[n], obj_path, warnings)
        types.append(t), params.append(p), emissions.append(e)
    # A usemtl name no MTL defines gets a material of its own (diffuse 0.8, which the sidecar may
    # override by that name); faces before any usemtl get "__default__".
    undefined = []
    tri_material = np.empty(tri.shape[0], dtype=np.int32)
    start = 0
    for mname, count in groups:
        if mname is None:
            mname = "__default__"
            if mname not in names:
                _warn(warnings, f"{obj_path}: faces without a material (no usemtl before them); using diffuse 0.8")
        elif mname not in mtl and mname not in undefined:
            undefined.append(mname)
        if mname not in names:
            names.append(mname)
            types.append(bsdfs.DIFFUSE)
            params.append(np.array([0.8, 0.8, 0.8, 0, 0, 0, 0, 1.5]))
            emissions.append(np.zeros(3))
        tri_material[start : start + count] = names.index(mname)
        start += count
    undefined = [n for n in usemtl if n in undefined]  # in the order the OBJ uses them
    libs = ", ".join(mtllibs)
    where = f"in {libs}" if libs else "(the OBJ names no MTL file)"
    overridden = set(sidecar.get("materials") or {})
    unreported = [n for n in undefined if n not in overridden]
    if unreported:
        listed = ", ".join(repr(n) for n in unreported[:5]) + (f" and {len(unreported) - 5} more" if len(unreported) > 5 else "")
        verb = "is" if len(unreported) == 1 else "are"
        _warn(warnings, f"{obj_path}: material{'s' if len(unreported) > 1 else ''} {listed} {verb} not defined {where}; "
                        "using diffuse 0.8")
    # Sidecar material overrides
    for name, spec in (sidecar.get("materials") or {}).items():
        if name not in names:
            raise SceneError(f"{sidecar_path}: materials.{name}: no such material; known: {', '.join(names)}")
        i = names.index(name)
        types[i], params[i], emissions[i] = _material_override(name, spec, (types[i], params[i], emissions[i]), sidecar_path)
    materials = Materials(
        names,
        np.asarray(types, dtype=np.int32),
        np.asarray(params, dtype=np.float64).reshape(-1, 8),
        np.asarray(emissions, dtype=np.float64).reshape(-1, 3),
    )

    # Degenerate triangles: counted, reported, skipped
    area2, bounds = triangle_areas(tri)
    keep = area2 > (1e-12 * float(np.linalg.norm(bounds[1] - bounds[0]))) ** 2
    del area2
    if not np.all(keep):
        _warn(warnings, f"{obj_path}: skipped {int((~keep).sum())} zero-area triangle(s)", logging.INFO)
        tri, tri_material = tri[keep], tri_material[keep]
        if tri.shape[0] == 0:
            raise SceneError(f"{obj_path}: every triangle has zero area")
        bounds = triangle_areas(tri)[1]

    # Film, render settings
    film = dict(sidecar.get("film") or {})
    render = dict(RENDER_DEFAULTS, **(sidecar.get("render") or {}))
    cam = dict(sidecar.get("camera") or {})
    for k, v in overrides.items():
        {"film": film, "render": render, "camera": cam}[OVERRIDES[k]][k] = v
    width = _number(f"{sidecar_path}: film.width", film.get("width", 256), int, lo=1)
    height = _number(f"{sidecar_path}: film.height", film.get("height", 256), int, lo=1)
    settings = RenderSettings(
        spp=_number(f"{sidecar_path}: render.spp", render["spp"], int, lo=1),
        max_depth=_number(f"{sidecar_path}: render.max_depth", render["max_depth"], int, lo=-1),
        rr_depth=_number(f"{sidecar_path}: render.rr_depth", render["rr_depth"], int, lo=1),
        seed=_number(f"{sidecar_path}: render.seed", render["seed"], int, lo=0),
    )
    if settings.max_depth == 0:
        raise SceneError(f"{sidecar_path}: render.max_depth must be -1 (unlimited) or >= 1")

    # Camera: from the sidecar, or framed (below, once the scene is known to have a light)
    fov = _number(f"{sidecar_path}: camera.fov", cam.get("fov", 45.0))
    if not 0.0 < fov < 180.0:
        raise SceneError(f"{sidecar_path}: camera: fov must be in (0, 180) degrees, got {fov}")
    fov_axis = cam.get("fov_axis", "x")
    framed = not ({"origin", "target"} & set(cam))
    up = _vec3(f"{sidecar_path}: camera.up", cam.get("up", [0.0, 1.0, 0.0]))
    if {"origin", "target"} <= set(cam):
        origin = _vec3(f"{sidecar_path}: camera.origin", cam["origin"])
        target = _vec3(f"{sidecar_path}: camera.target", cam["target"])
    elif not framed:
        raise SceneError(f"{sidecar_path}: camera needs both origin and target")
    else:  # the default view until framing (below) picks one
        origin, target = outside_view(bounds, fov, view_axes(up)[0][1])
    camera = Camera.look_at(origin, target, up, fov, fov_axis, width, height, where=f"{sidecar_path}: camera")

    environment = _load_environment(sidecar.get("environment"), sidecar_path)
    scene = Scene(
        path=obj_path if ext == ".obj" else path,
        tri=np.ascontiguousarray(tri),
        tri_material=tri_material,
        materials=materials,
        camera=camera,
        width=width,
        height=height,
        render=settings,
        environment=environment,
        bounds=bounds,
        warnings=warnings,
    )
    has_env = environment is not None and (environment.image is not None or environment.radiance.max() > 0)
    if not scene.emissive.any() and not has_env:
        hint = ""
        if undefined:  # its emitter may be among them (the warning is not shown when loading fails)
            hint = f" ({', '.join(repr(n) for n in undefined[:5])} not defined {where})"
        raise SceneError(
            f"{scene.path}: the scene has no light: no material with Ke > 0 and no environment in the sidecar{hint}"
        )
    if framed:
        if before_framing is not None:
            before_framing()
        (origin, target, view_up), scene.framing = frame_camera(scene, fov, fov_axis, up)
        scene.camera = Camera.look_at(origin, target, view_up, fov, fov_axis, width, height,
                                      where=f"{sidecar_path}: camera")
    return scene


def _load_environment(spec, where):
    from .imageio import read_image

    if spec is None:
        return None
    if "map" in spec:
        if "radiance" in spec:
            raise SceneError(f"{where}: environment takes either 'radiance' or 'map', not both")
        map_path = os.path.join(os.path.dirname(where), str(spec["map"]))
        if not os.path.isfile(map_path):
            raise SceneError(f"{where}: environment.map {spec['map']!r} not found (looked for "
                             f"{os.path.abspath(map_path)})")
        img = read_image(map_path, what="environment map").astype(np.float64)
        scale = _number(f"{where}: environment.scale", spec.get("scale", 1.0), lo=0.0)
        if img.shape[2] == 1:
            img = np.repeat(img, 3, axis=2)
        img = img[:, :, :3] * scale
        if not np.all(np.isfinite(img)) or img.min() < 0.0:
            raise SceneError(f"{map_path}: environment map has negative or non-finite pixels")
        return Environment(np.zeros(3), img, map_path)
    if "radiance" in spec:
        if "scale" in spec:
            raise SceneError(f"{where}: environment.scale goes with 'map'")
        rad = _vec3(f"{where}: environment.radiance", spec["radiance"])
        if rad.min() < 0.0:
            raise SceneError(f"{where}: environment.radiance must be >= 0")
        return Environment(rad)
    raise SceneError(f"{where}: environment needs 'radiance' or 'map'")
