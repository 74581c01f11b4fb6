"""The JSON sidecar (or JSON scene file) of an OBJ: what OBJ cannot say (see README, "Scene files").

    camera       {origin, target, up, fov (degrees), fov_axis: "x" | "y"}
    film         {width, height}
    render       {spp, max_depth, rr_depth, seed}
    environment  {radiance: [r, g, b]}  or  {map: file.exr, scale}
    materials    {mtl_name: {type, kd, ks, alpha, ior, emission}}
    obj          the OBJ's path (only in a JSON scene file)

read_sidecar checks its keys; sidecar_settings turns it (with load_scene's keyword overrides)
into the spec's film size, render settings, camera and environment; override_materials applies
its materials section to the OBJ's.
"""
import os

import numpy as np

from .. import bsdfs
from ..errors import SceneError
from ..scene import CameraSpec, Environment, RenderSettings
from .text import check_keys, number, read_json, vec3

SIDECAR_KEYS = {
    "camera": {"origin", "target", "up", "fov", "fov_axis"},
    "film": {"width", "height"},
    "render": {"spp", "max_depth", "rr_depth", "seed"},
    "environment": {"radiance", "map", "scale"},
    "materials": None,  # keyed by material name
    "obj": None,  # only in a JSON scene file
}
MATERIAL_KEYS = {"type", "kd", "ks", "alpha", "ior", "emission", "metal", "eta", "k", "one_sided", "opacity",
                 "nonlinear"}
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


def read_sidecar(path, required=True):
    """The sidecar at `path` as a dict, its sections checked ({} if it does not exist and not
    `required`)."""
    if not required and not os.path.isfile(path):
        return {}
    sidecar = read_json(path)
    check_keys(path, sidecar, SIDECAR_KEYS)
    for section, allowed in SIDECAR_KEYS.items():
        if allowed is not None and section in sidecar:
            if not isinstance(sidecar[section], dict):
                raise SceneError(f"{path}: '{section}' must be an object")
            check_keys(f"{path}: {section}", sidecar[section], allowed)
    return sidecar


def override_materials(materials, sidecar, sidecar_path):
    """The sidecar's `materials` entries applied to `materials` [(name, type, param, emission)], in place."""
    names = [m[0] for m in materials]
    for name, spec in (sidecar.get("materials") or {}).items():
        if name not in names:
            raise SceneError(f"{sidecar_path}: materials.{name}: no such material; known: {', '.join(names)}")
        i = names.index(name)
        materials[i] = (name, *material_override(name, spec, materials[i][1:], sidecar_path))


def sidecar_settings(sidecar, sidecar_path, overrides):
    """(width, height, RenderSettings, CameraSpec, Environment or None) from the sidecar, with
    load_scene's keyword overrides (OVERRIDES) in place of its values."""
    film = dict(sidecar.get("film") or {})
    render = dict(RENDER_DEFAULTS, **(sidecar.get("render") or {}))
    cam = dict(sidecar.get("camera") or {})
    for k, v in overrides.items():
        {"film": film, "render": render, "camera": cam}[OVERRIDES[k]][k] = v
    width = number(f"{sidecar_path}: film.width", film.get("width", 256), int, lo=1)
    height = number(f"{sidecar_path}: film.height", film.get("height", 256), int, lo=1)
    settings = RenderSettings(
        spp=number(f"{sidecar_path}: render.spp", render["spp"], int, lo=1),
        max_depth=number(f"{sidecar_path}: render.max_depth", render["max_depth"], int, lo=-1),
        rr_depth=number(f"{sidecar_path}: render.rr_depth", render["rr_depth"], int, lo=1),
        seed=number(f"{sidecar_path}: render.seed", render["seed"], int, lo=0),
    )
    if settings.max_depth == 0:
        raise SceneError(f"{sidecar_path}: render.max_depth must be -1 (unlimited) or >= 1")
    fov = number(f"{sidecar_path}: camera.fov", cam.get("fov", 45.0))
    if not 0.0 < fov < 180.0:
        raise SceneError(f"{sidecar_path}: camera: fov must be in (0, 180) degrees, got {fov}")
    camera = CameraSpec(fov=fov, fov_axis=cam.get("fov_axis", "x"),
                        up=vec3(f"{sidecar_path}: camera.up", cam.get("up", [0.0, 1.0, 0.0])),
                        where=f"{sidecar_path}: camera")
    if {"origin", "target"} <= set(cam):
        camera.origin = vec3(f"{sidecar_path}: camera.origin", cam["origin"])
        camera.target = vec3(f"{sidecar_path}: camera.target", cam["target"])
    elif {"origin", "target"} & set(cam):
        raise SceneError(f"{sidecar_path}: camera needs both origin and target")
    environment = read_environment(sidecar.get("environment"), sidecar_path)
    return width, height, settings, camera, environment


def material_override(name, spec, base, where):
    """Apply a sidecar `materials: {name: {...}}` entry to (type, param, emission[, tex])."""
    if not isinstance(spec, dict):
        raise SceneError(f"{where}: materials.{name} must be an object")
    check_keys(f"{where}: materials.{name}", spec, MATERIAL_KEYS)
    mtype, param, emission = base[:3]
    tex = list(base[3]) if len(base) > 3 else None
    param = np.zeros(bsdfs.N_PARAM)
    param[: len(base[1])] = base[1]
    emission = emission.copy()
    if "type" in spec:
        if spec["type"] not in bsdfs.TYPE_NAMES:
            raise SceneError(
                f"{where}: materials.{name}.type {spec['type']!r} unknown; valid: {', '.join(bsdfs.TYPE_NAMES)}"
            )
        was = mtype
        mtype = bsdfs.TYPE_NAMES.index(spec["type"])
        if mtype == bsdfs.COATED and was != bsdfs.COATED:
            param[3:6] = 1.0  # the coat's specular reflectance (Mitsuba's default; `ks` below may set it)
            if tex:
                tex[1] = -1
    if "kd" in spec:
        param[0:3] = vec3(f"{where}: materials.{name}.kd", spec["kd"])
        if tex:
            tex[0] = -1  # a constant given here replaces the MTL's texture
    if "ks" in spec:
        param[3:6] = vec3(f"{where}: materials.{name}.ks", spec["ks"])
        if tex:
            tex[1] = -1
    if "alpha" in spec:
        param[6] = number(f"{where}: materials.{name}.alpha", spec["alpha"], lo=0.0)
    if "ior" in spec:
        param[7] = number(f"{where}: materials.{name}.ior", spec["ior"], lo=1e-3)
    if "metal" in spec:
        from ..metals import METALS

        if spec["metal"] not in METALS:
            raise SceneError(f"{where}: materials.{name}.metal {spec['metal']!r} unknown; valid: {', '.join(METALS)}")
        param[8:11], param[11:14] = METALS[spec["metal"]]
    if "eta" in spec:
        param[8:11] = vec3(f"{where}: materials.{name}.eta", spec["eta"])
    if "k" in spec:
        param[11:14] = vec3(f"{where}: materials.{name}.k", spec["k"])
    if mtype in (bsdfs.DIELECTRIC, bsdfs.ROUGH_DIELECTRIC, bsdfs.THIN_DIELECTRIC):
        param[bsdfs.P_CLEAR] = 0.0  # glass: the MTL's opacity (d, map_d) meant its transparency
        if tex:
            tex[3] = -1
    if "opacity" in spec:
        op = number(f"{where}: materials.{name}.opacity", spec["opacity"], lo=0.0)
        if op > 1.0:
            raise SceneError(f"{where}: materials.{name}.opacity must be in [0, 1], got {op}")
        param[bsdfs.P_CLEAR] = 1.0 - op
        if tex:
            tex[3] = -1
    if "nonlinear" in spec:
        param[14] = (int(param[14]) & ~bsdfs.NONLINEAR) | (bsdfs.NONLINEAR if spec["nonlinear"] else 0)
    if "one_sided" in spec:
        flags = int(param[14]) & ~bsdfs.ONE_SIDED
        param[14] = flags | (bsdfs.ONE_SIDED if spec["one_sided"] else 0)
    if "emission" in spec:
        emission = vec3(f"{where}: materials.{name}.emission", spec["emission"])
    if param[:6].min() < 0.0 or emission.min() < 0.0:
        raise SceneError(f"{where}: materials.{name}: reflectances and emission must be >= 0")
    if tex is None:
        return mtype, param, emission
    return mtype, param, emission, tuple(tex)


def read_environment(spec, where):
    from ..imageio import read_image

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
        scale = number(f"{where}: environment.scale", spec.get("scale", 1.0), lo=0.0)
        if img.shape[2] == 1:
            img = np.repeat(img, 3, axis=2)
        img = img[:, :, :3] * scale
        if not np.all(np.isfinite(img)) or img.min() < 0.0:
            raise SceneError(f"{map_path}: environment map has negative or non-finite pixels")
        return Environment(np.zeros(3), img, map_path)
    if "radiance" in spec:
        if "scale" in spec:
            raise SceneError(f"{where}: environment.scale goes with 'map'")
        rad = vec3(f"{where}: environment.radiance", spec["radiance"])
        if rad.min() < 0.0:
            raise SceneError(f"{where}: environment.radiance must be >= 0")
        return Environment(rad)
    raise SceneError(f"{where}: environment needs 'radiance' or 'map'")
