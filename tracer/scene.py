"""Scenes: what a render reads (Scene), what a reader produces (SceneSpec), and the step between.

Loading is reader -> spec -> build. `load_scene(path, **overrides)` picks the reader by the
file's extension: `name.obj` (with `name.json` beside it if present) or a JSON scene file that
names its OBJ under the key "obj" (tracer.readers.obj: the OBJ and its MTL; readers.sidecar: the
JSON), or a Mitsuba scene `.xml` (tracer.readers.mitsuba, a subset for now). A reader fills a SceneSpec: triangles, their materials as (name, type, param, emission),
film size, render settings, a CameraSpec, the environment, warnings. `build_scene(spec)` owns
what every reader shares: the materials table, degenerate triangles (counted, reported,
skipped), the camera (look-at, a camera-to-world matrix, or framed by tracer.framing when the
scene gives none) and the check that the scene has a light.
"""
import logging
import math
import os
from dataclasses import dataclass, field, replace

import numpy as np

from . import bsdfs
from .camera import Camera
from .errors import SceneError, SettingsError
from .framing import frame_camera, outside_view, view_axes
from .material import N_TEX_SLOTS
from .objread import triangle_areas
from .textures import Textures, build_textures

log = logging.getLogger("tracer")


@dataclass
class Materials:
    """Struct of arrays, one row per material (see `tracer.bsdfs` for the encoding)."""

    names: list
    type: np.ndarray  # (M,) int32, bsdfs.DIFFUSE ...
    param: np.ndarray  # (M, bsdfs.N_PARAM) float64: kd rgb, ks rgb, alpha, ior, eta rgb, k rgb, flags
    emission: np.ndarray  # (M, 3) float64 radiance, one-sided
    tex: np.ndarray = None  # (M, N_TEX_SLOTS) int32 texture of each slot (kd, ks, bump; -1: none), tracer.material
    table: np.ndarray = None  # (M, coating.TABLE_RES) float64 COATED transmittance tables (tracer.coating.prepare)

    def __repr__(self):
        kinds = [bsdfs.TYPE_NAMES[t] for t in self.type]
        return "Materials(" + ", ".join(f"{n}: {k}" for n, k in zip(self.names, kinds)) + ")"


@dataclass
class Environment:
    """Light from infinitely far away: a constant radiance or an equirectangular map.

    A map is looked up by one of two conventions (tracer.lights: ENV_MAP, ENV_BILINEAR):
    "tracer" (OBJ sidecars), piecewise constant over texels, u = 0.5 + atan2(d.x, -d.z) / (2 pi),
    v = acos(d.y) / pi, row 0 of the image at v = 0 (straight up); "mitsuba" (a Mitsuba `envmap`),
    Mitsuba 3's: the direction turned into the map's frame by the inverse of `to_world`, there
    u = atan2(d.x, -d.z) / (2 pi), v = acos(d.y) / pi, bilinear between texels, column x centred at
    u = (x + 1/2) / W (periodic), row y at v = y / (H - 1) (rows from pole to pole).
    """

    radiance: np.ndarray  # (3,) float64, constant term (zero when a map is used)
    image: np.ndarray | None = None  # (H, W, 3) float64 radiance (already scaled), or None
    path: str | None = None
    convention: str = "tracer"  # how the map is looked up: "tracer" or "mitsuba" (above)
    to_world: np.ndarray | None = None  # (3, 3) rotation, map frame -> world ("mitsuba"; None: identity)
    sunsky: object = None  # the tracer.sunsky.SunSky the map was baked from, if any

    def __repr__(self):
        if self.image is not None:
            return f"Environment(map={self.path!r}, {self.image.shape[1]}x{self.image.shape[0]})"
        return f"Environment(radiance={self.radiance.tolist()})"


@dataclass
class DeltaLight:
    """A light of no extent, reached by next-event estimation alone (a path never hits it), as Mitsuba 3
    defines it: `point` (intensity I, W/sr: I / d^2 at distance d), `spot` (a point light whose
    intensity falls off linearly in angle from I inside the beam to 0 at the cutoff, about its
    +z axis, times an optional texture projected across the cone: for a local direction (x, y, z),
    uv = 1/2 + (x, y) / (2 z tan(cutoff)), looked up bilinearly with repeat, v = 0 the image's top
    row), `directional` (irradiance E arriving from one direction)."""

    kind: str  # "point", "spot" or "directional"
    intensity: np.ndarray  # (3,) W/sr (point, spot) or irradiance W/m^2 (directional)
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))  # point, spot
    direction: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))  # unit, world: the spot's
    # axis, the directional light's direction of travel
    cutoff: float = math.radians(20.0)  # spot: no light beyond this angle from the axis (radians)
    beam: float = math.radians(15.0)  # spot: full intensity within this angle (radians)
    frame: np.ndarray = field(default_factory=lambda: np.eye(3))  # spot: rows its local x, y, z axes in the world
    texture: np.ndarray | None = None  # spot: (H, W, 3) linear RGB projected across its cone (Mitsuba 3's)
    where: str = ""  # the file and line that declared it (messages)

    def __repr__(self):
        return f"DeltaLight({self.kind}, intensity={np.round(self.intensity, 4).tolist()})"


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
    tri_uv       (F, 3, 2) float64  corner UVs, or (0, 3, 2) when the scene has none
    tri_vn       (F, 3, 3) float64  corner normals (zero rows: flat triangles), or (0, 3, 3)
    textures     the Textures the materials' slots index
    delta_lights [DeltaLight]: point, spot and directional lights
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
    tri_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 2)))
    tri_vn: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    textures: Textures = field(default_factory=Textures)
    delta_lights: list = field(default_factory=list)  # [DeltaLight]

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
            f"{self.width}x{self.height}, env={self.environment!r}"
            + (f", {len(self.delta_lights)} delta lights)" if self.delta_lights else ")")
        )


@dataclass
class CameraSpec:
    """A camera as a reader gives it: `origin` and `target` (look-at, around `up`), or `matrix` (4x4
    camera-to-world, Mitsuba's toWorld: +z forward, +y up, +x to the image's left); neither: framed
    by tracer.framing around `up`. fov in degrees along fov_axis ("x" or "y"); `where` names the
    file and key in errors."""

    fov: float = 45.0
    fov_axis: str = "x"
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    origin: np.ndarray | None = None
    target: np.ndarray | None = None
    matrix: np.ndarray | None = None
    near: float = 0.0  # near clipping distance (Mitsuba's near_clip; 0: rays start at the eye)
    where: str = "camera"

    @property
    def framed(self):
        return self.matrix is None and self.origin is None


@dataclass
class SceneSpec:
    """What a reader produces and build_scene turns into a Scene.

    path          the scene's name in messages and results
    geometry_file the file the triangles came from (named in geometry errors)
    tri           (F, 3, 3) float64 world vertices; tri_material (F,) int32 index into materials
    uv, normals   (F, 3, 2) corner UVs and (F, 3, 3) corner normals (a zero row: a flat
                  triangle), or None
    materials     [(name, type (tracer.bsdfs), param (8,) or (N_PARAM,) float64 (zeros past the
                  eighth), emission (3,) float64[, tex])],
                  tex the index into `textures` of each texture slot (kd, ks, bump; -1 none)
    textures      [tracer.textures.TextureSpec]
    delta_lights  [DeltaLight]: point, spot and directional lights
    no_light      what a scene without light lacks, in the reader's terms (the error's text)
    """

    path: str
    geometry_file: str
    tri: np.ndarray
    tri_material: np.ndarray
    materials: list
    width: int = 256
    height: int = 256
    render: RenderSettings = field(default_factory=RenderSettings)
    camera: CameraSpec = field(default_factory=CameraSpec)
    environment: Environment | None = None
    warnings: list = field(default_factory=list)
    no_light: str = "no emitting material and no environment"
    uv: np.ndarray | None = None
    normals: np.ndarray | None = None
    textures: list = field(default_factory=list)
    delta_lights: list = field(default_factory=list)  # [DeltaLight]


def load_scene(path, before_framing=None, define=None, allow_missing=False, **overrides):
    """Load a scene; keyword overrides replace sidecar values (width, height, spp, ...: width or
    height alone keeps the scene's aspect ratio, the other side rounded, at least 1); `define`
    ({name: value}) overrides a Mitsuba scene XML's <default> values, as `mitsuba -D`;
    allow_missing: a Mitsuba scene's missing mesh or texture is a warning, not an error.

    Raises SceneError (one line, naming the file and the problem) for bad input. A scene without
    a camera is framed (tracer.framing: tiny renders, which compile the kernels on first use);
    before_framing(), if given, is called first (the command line's compile notice).
    """
    from .readers.obj import read_obj_scene
    from .readers.sidecar import OVERRIDES, override_materials, read_sidecar, sidecar_settings

    path = os.fspath(path)
    bad = sorted(set(overrides) - set(OVERRIDES))
    if bad:
        raise SettingsError(f"unknown scene override {bad[0]!r}; valid: {', '.join(sorted(OVERRIDES))}")
    size = _size_overrides(overrides)
    warnings = []
    ext = os.path.splitext(path)[1].lower()
    if ext == ".xml":
        return _load_mitsuba(path, before_framing, overrides, define, allow_missing, size)
    if define:
        raise SettingsError(f"{path}: define ({', '.join(define)}) is for Mitsuba scene XML files")
    if ext == ".json":
        sidecar_path = path
        sidecar = read_sidecar(path)
        if "obj" not in sidecar:
            raise SceneError(f"{path}: a JSON scene file must name its OBJ under the key 'obj'")
        obj_path = os.path.join(os.path.dirname(path), str(sidecar["obj"]))
    elif ext == ".obj":
        obj_path = path
        sidecar_path = os.path.splitext(path)[0] + ".json"
        sidecar = read_sidecar(sidecar_path, required=False)
        if "obj" in sidecar:
            raise SceneError(f"{sidecar_path}: key 'obj' belongs in a JSON scene file, not in a sidecar")
    else:
        if not os.path.exists(path):
            raise SceneError(f"{path}: scene file not found")
        raise SceneError(f"{path}: not a scene file; give an .obj (with optional .json sidecar), a .json "
                         "or a Mitsuba scene .xml")

    geo = read_obj_scene(obj_path, warnings)
    libs = ", ".join(geo.mtllibs)
    where = f"in {libs}" if libs else "(the OBJ names no MTL file)"
    overridden = set(sidecar.get("materials") or {})
    unreported = [n for n in geo.undefined if n not in overridden]
    if unreported:
        from .readers.text import warn

        listed = ", ".join(repr(n) for n in unreported[:5]) + (f" and {len(unreported) - 5} more" if len(unreported) > 5 else "")
        verb = "is" if len(unreported) == 1 else "are"
        warn(warnings, f"{obj_path}: material{'s' if len(unreported) > 1 else ''} {listed} {verb} not defined {where}; "
                       "using diffuse 0.8")
    override_materials(geo.materials, sidecar, sidecar_path)
    width, height, settings, camera, environment = sidecar_settings(sidecar, sidecar_path, overrides)
    hint = ""
    if geo.undefined:  # its emitter may be among them (the error then says so itself)
        hint = f" ({', '.join(repr(n) for n in geo.undefined[:5])} not defined {where})"
    spec = SceneSpec(path=obj_path if ext == ".obj" else path, geometry_file=obj_path, tri=geo.tri,
                     tri_material=geo.tri_material, materials=geo.materials, width=width, height=height,
                     render=settings, camera=camera, environment=environment, warnings=warnings,
                     no_light=f"no material with Ke > 0 and no environment in the sidecar{hint}",
                     uv=geo.uv, normals=geo.normals, textures=geo.textures or [])
    _resize(spec, size)
    return build_scene(spec, before_framing)


def _size_overrides(overrides):
    """Take width and height out of load_scene's `overrides` ({name: value}, changed in place):
    {"width": w, "height": h} of those given, each an integer >= 1 (SettingsError otherwise)."""
    size = {}
    for key in ("width", "height"):
        if key in overrides:
            v = overrides.pop(key)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise SettingsError(f"{key} must be an integer >= 1, got {v!r}")
            size[key] = int(v)
    return size


def _resize(spec, size):
    """Give `spec` the film size of `size` (from _size_overrides): one side alone keeps the
    spec's aspect ratio, the other side rounded to the nearest pixel, at least 1."""
    w, h = size.get("width"), size.get("height")
    if w is None and h is None:
        return
    if h is None:
        h = max(1, math.floor(spec.height * w / spec.width + 0.5))
    elif w is None:
        w = max(1, math.floor(spec.width * h / spec.height + 0.5))
    spec.width, spec.height = w, h


def _padded(param):
    """A material's parameters as the table's N_PARAM columns (zeros past those given)."""
    out = np.zeros(bsdfs.N_PARAM)
    p = np.asarray(param, dtype=np.float64).reshape(-1)
    out[: p.size] = p
    return out


def prepare_coats(materials, textures):
    """Fill the COATED rows' derived columns and tables (tracer.coating.prepare), sampling weights
    from the textured reflectances' means as Mitsuba computes them. build_scene calls it; call it
    again after changing a scene's materials or textures."""
    from .coating import TABLE_RES, prepare
    from .material import TEX_SLOT_KD, TEX_SLOT_KS

    coated = materials.type == bsdfs.COATED
    if not coated.any():
        materials.table = np.zeros((len(materials.type), TABLE_RES))
        return
    kd = materials.param[:, bsdfs.P_KD:bsdfs.P_KD + 3].mean(axis=1)
    ks = materials.param[:, bsdfs.P_KS:bsdfs.P_KS + 3].mean(axis=1)
    for m in np.flatnonzero(coated):
        if materials.tex[m, TEX_SLOT_KD] >= 0:
            kd[m] = textures.mean(materials.tex[m, TEX_SLOT_KD]).mean()
        if materials.tex[m, TEX_SLOT_KS] >= 0:
            ks[m] = textures.mean(materials.tex[m, TEX_SLOT_KS]).mean()
    materials.param, materials.table = prepare(materials.type, materials.param, kd, ks)


def _load_mitsuba(path, before_framing, overrides, define=None, allow_missing=False, size=None):
    """load_scene for a Mitsuba scene XML (tracer.readers.mitsuba), with the keyword overrides, the
    film size (_size_overrides) and the <default> values `define` replaces."""
    from .readers.mitsuba import read_mitsuba_scene

    if not os.path.exists(path):
        raise SceneError(f"{path}: scene file not found")
    spec = read_mitsuba_scene(path, {str(k): str(v) for k, v in (define or {}).items()}, allow_missing)
    for key, value in overrides.items():
        if key == "fov":
            spec.camera.fov = float(value)
        else:
            setattr(spec.render, key, int(value))
    _resize(spec, size or {})
    return build_scene(spec, before_framing)


def build_scene(spec, before_framing=None):
    """The Scene of a SceneSpec: the materials table, degenerate triangles skipped (reported at
    INFO), the camera (framed when the spec gives none: before_framing() is called first), and a
    SceneError if nothing emits light."""
    materials = Materials(
        [m[0] for m in spec.materials],
        np.asarray([m[1] for m in spec.materials], dtype=np.int32),
        np.asarray([_padded(m[2]) for m in spec.materials], dtype=np.float64).reshape(-1, bsdfs.N_PARAM),
        np.asarray([m[3] for m in spec.materials], dtype=np.float64).reshape(-1, 3),
        np.asarray([m[4] if len(m) > 4 else (-1,) * N_TEX_SLOTS for m in spec.materials],
                   dtype=np.int32).reshape(-1, N_TEX_SLOTS),
    )
    uv, vn = spec.uv, spec.normals
    tri, tri_material = spec.tri, spec.tri_material
    area2, bounds = triangle_areas(tri)
    keep = area2 > (1e-12 * float(np.linalg.norm(bounds[1] - bounds[0]))) ** 2
    del area2
    if not np.all(keep):
        from .readers.text import warn

        warn(spec.warnings, f"{spec.geometry_file}: skipped {int((~keep).sum())} zero-area triangle(s)", logging.INFO)
        tri, tri_material = tri[keep], tri_material[keep]
        uv = uv[keep] if uv is not None else None
        vn = vn[keep] if vn is not None else None
        if tri.shape[0] == 0:
            raise SceneError(f"{spec.geometry_file}: every triangle has zero area")
        bounds = triangle_areas(tri)[1]

    cs = spec.camera
    if cs.matrix is not None:
        camera = Camera.from_matrix(cs.matrix, cs.fov, cs.fov_axis, spec.width, spec.height, where=cs.where)
    else:
        origin, target = (cs.origin, cs.target) if not cs.framed else \
            outside_view(bounds, cs.fov, view_axes(cs.up)[0][1])  # the default view until framing picks one
        camera = Camera.look_at(origin, target, cs.up, cs.fov, cs.fov_axis, spec.width, spec.height, where=cs.where)
    camera = replace(camera, near=float(cs.near))
    scene = Scene(
        path=spec.path,
        tri=np.ascontiguousarray(tri),
        tri_material=tri_material,
        materials=materials,
        camera=camera,
        width=spec.width,
        height=spec.height,
        render=spec.render,
        environment=spec.environment,
        bounds=bounds,
        warnings=spec.warnings,
        tri_uv=np.ascontiguousarray(uv, dtype=np.float64) if uv is not None else np.zeros((0, 3, 2)),
        tri_vn=np.ascontiguousarray(vn, dtype=np.float64) if vn is not None else np.zeros((0, 3, 3)),
        textures=build_textures(spec.textures, spec.warnings),
        delta_lights=list(spec.delta_lights),
    )
    prepare_coats(scene.materials, scene.textures)
    env = spec.environment
    has_env = env is not None and (env.image is not None or env.radiance.max() > 0)
    if not scene.emissive.any() and not has_env and not any(d.intensity.max() > 0 for d in spec.delta_lights):
        raise SceneError(f"{scene.path}: the scene has no light: {spec.no_light}")
    if cs.framed:
        if before_framing is not None:
            before_framing()
        (origin, target, view_up), scene.framing = frame_camera(scene, cs.fov, cs.fov_axis, cs.up)
        scene.camera = replace(Camera.look_at(origin, target, view_up, cs.fov, cs.fov_axis, spec.width, spec.height,
                                              where=cs.where), near=float(cs.near))
    return scene
