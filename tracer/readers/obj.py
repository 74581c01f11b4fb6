"""The OBJ reader: an OBJ's triangles and its MTL materials as a scene spec's geometry and materials.

Geometry goes through the parallel reader (tracer.objread) when the file is made of the
statements it reads, else through its slow twin here: a line-by-line check that names the bad
line (scan_obj), then trimesh (_load_geometry); both give the same triangles in the same order
(tests/test_objread.py). MTL statements map to BSDFs as `tracer.bsdfs` documents: `Kd`
Lambertian; `Ke` one-sided emission (every emissive triangle is an area light); `illum 4/6/7` +
`Ni` smooth dielectric (rough if `Pr` is given); `illum 3/5` mirror tinted by `Ks`; `Pr` + `Pm 1`
rough metal with GGX alpha = Pr^2; other `Ks` + `Ns` glossy plastic with alpha = sqrt(2 / (Ns +
2)). Statements the tracer cannot honour are reported once per file, never silently dropped.
"""
import math
import os
from dataclasses import dataclass

import numpy as np

from .. import bsdfs
from ..errors import SceneError
from ..objread import read_obj
from .text import check_text, read_bytes, read_text, warn

_MTL_USED = {"newmtl", "Kd", "Ks", "Ke", "Ns", "Ni", "illum", "Pr", "Pm"}
DEFAULT_MATERIAL = (bsdfs.DIFFUSE, (0.8, 0.8, 0.8, 0, 0, 0, 0, 1.5), (0.0, 0.0, 0.0))  # (type, param, emission)


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
        warn(warnings, f"{path}: ignoring unsupported statement {key} in {len(names)} material(s)")
    if missing:
        files = ", ".join(f"{name!r} (line {line})" for name, line in list(missing.items())[:3])
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        warn(warnings, f"{path}: texture file(s) not found: {files}{more}; the constant is used anyway")
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
            warn(warnings, f"{where}: material {name!r} is a dielectric without Ni; using 1.5")
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
            warn(warnings, f"{where}: material {name!r} has Kd + Ks > 1 (reflects more than it receives)")
    else:
        mtype = bsdfs.DIFFUSE
    if pr is not None and mtype in (bsdfs.DIFFUSE, bsdfs.MIRROR, bsdfs.DIELECTRIC, bsdfs.PLASTIC) and pr > 0:
        warn(warnings, f"{where}: material {name!r}: Pr without Pm 1 is ignored")
    if np.any(kd > 1.0) and mtype in (bsdfs.DIFFUSE, bsdfs.PLASTIC):
        warn(warnings, f"{where}: material {name!r} has Kd > 1 (reflects more than it receives)")
    param = np.array([*kd, *ks, alpha, ior], dtype=np.float64)
    return mtype, param, ke.astype(np.float64)


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
    fast = read_obj(check_text(obj_path, read_bytes(obj_path, "OBJ"), "OBJ"))  # (it frees the bytes once parsed)
    if fast is not None:
        return fast
    scan = scan_obj(obj_path)
    tri, groups = _load_geometry(obj_path, scan)
    return tri, groups, scan.mtllibs, scan.usemtl


@dataclass
class ObjGeometry:
    """An OBJ's triangles with their materials: tri (F, 3, 3) float64; tri_material (F,) int32
    index into `materials` [(name, type, param (8,), emission (3,))]; `undefined`: usemtl names
    no MTL defines (given diffuse 0.8), in the order the OBJ uses them; `mtllibs`: its MTL files."""

    tri: np.ndarray
    tri_material: np.ndarray
    materials: list
    undefined: list
    mtllibs: list


def read_obj_scene(obj_path, warnings):
    """The geometry and materials of an OBJ and its MTL files (an ObjGeometry). A usemtl name no
    MTL defines gets a material of its own (diffuse 0.8; the sidecar may override it by that
    name); faces before any usemtl get "__default__"."""
    tri, groups, mtllibs, usemtl = read_geometry(obj_path)
    mtl = {}
    for lib in mtllibs:
        mtl_path = os.path.join(os.path.dirname(obj_path), lib)
        if not os.path.isfile(mtl_path):
            raise SceneError(f"{obj_path}: MTL file {lib!r} not found (looked for {mtl_path})")
        mtl.update(parse_mtl(mtl_path, warnings))
    materials = [(n, *material_from_mtl(n, mtl[n], obj_path, warnings)) for n in mtl]
    names = list(mtl)
    undefined = []
    tri_material = np.empty(tri.shape[0], dtype=np.int32)
    start = 0
    for mname, count in groups:
        if mname is None:
            mname = "__default__"
            if mname not in names:
                warn(warnings, f"{obj_path}: faces without a material (no usemtl before them); using diffuse 0.8")
        elif mname not in mtl and mname not in undefined:
            undefined.append(mname)
        if mname not in names:
            names.append(mname)
            t, p, e = DEFAULT_MATERIAL
            materials.append((mname, t, np.array(p, dtype=np.float64), np.array(e, dtype=np.float64)))
        tri_material[start : start + count] = names.index(mname)
        start += count
    undefined = [n for n in usemtl if n in undefined]  # in the order the OBJ uses them
    return ObjGeometry(tri, tri_material, materials, undefined, list(mtllibs))
