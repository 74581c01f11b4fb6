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
import logging
import math
import os
from dataclasses import dataclass

import numpy as np

from .. import bsdfs
from ..errors import SceneError
from ..material import N_TEX_SLOTS, P_BUMP_SCALE, TEX_SLOT_BUMP, TEX_SLOT_KD, TEX_SLOT_KS, TEX_SLOT_OPACITY
from ..textures import TextureSpec
from ..objread import ObjMesh, assemble, read_obj
from .text import check_text, read_bytes, read_text, warn

_MTL_USED = {"newmtl", "Kd", "Ks", "Ke", "Ns", "Ni", "illum", "Pr", "Pm", "d", "Tr", "Tf"}
# the texture maps the tracer reads, and their slots (tracer.material)
_MTL_MAPS = {"map_Kd": TEX_SLOT_KD, "map_Ks": TEX_SLOT_KS, "bump": TEX_SLOT_BUMP, "map_bump": TEX_SLOT_BUMP,
             "map_d": TEX_SLOT_OPACITY}
# options of a map statement and how many numbers each takes at most
_MAP_OPTIONS = {"-blendu": 1, "-blendv": 1, "-bm": 1, "-boost": 1, "-cc": 1, "-clamp": 1, "-imfchan": 1, "-mm": 2,
                "-o": 3, "-s": 3, "-t": 3, "-texres": 1, "-type": 1}
DEFAULT_MATERIAL = (bsdfs.DIFFUSE, (0.8, 0.8, 0.8, 0, 0, 0, 0, 1.5), (0.0, 0.0, 0.0))  # (type, param, emission)


@dataclass
class ObjScan:
    """What scan_obj learned: the decoded text, the `mtllib` file names and the `usemtl` names
    (in order of first use); and, for the faces' texture coordinates and normals, every face
    corner's 0-based (position, texture, normal) indices (-1: none) as rows of `corners`, each
    face's corner count and material (index into usemtl, -1: none), the `vt` (u, v) and `vn`
    values."""

    text: str
    mtllibs: list
    usemtl: list
    corners: list = None
    counts: list = None
    face_mat: list = None
    texcoords: list = None
    normals: list = None
    positions: list = None


def scan_obj(path):
    """Validate an OBJ line by line before trimesh reads it, so that errors name the line.

    Checks that `v` lines hold three finite numbers and `f` lines hold vertex indices that
    exist. Returns an ObjScan (text, `mtllib` file names, `usemtl` names).
    """
    text = read_text(path, "OBJ")
    mtllibs, usemtl = [], {}
    corners, counts, face_mat, vts, vns, positions = [], [], [], [], [], []
    cur = -1
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
            positions.append(xyz)
            nv += 1
        elif key == "f":
            if len(parts) < 4:
                raise SceneError(f"{path}:{lineno}: a face needs at least 3 vertices: {line.strip()!r}")
            for item in parts[1:]:
                fields = item.split("/")
                try:
                    idx = int(fields[0])
                    rest = [int(x) if x else 0 for x in fields[1:3]] + [0, 0]
                except ValueError:
                    raise SceneError(f"{path}:{lineno}: malformed face line {line.strip()!r}") from None
                if idx == 0 or idx > nv or -idx > nv:
                    raise SceneError(
                        f"{path}:{lineno}: face refers to vertex {idx}, but {nv} vertices are defined"
                    )
                row = [idx - 1 if idx > 0 else nv + idx]
                for k, (j, n) in enumerate(zip(rest[:2], (len(vts), len(vns)))):
                    if j > n or -j > n:
                        what = ("texture coordinate", "normal")[k]
                        raise SceneError(f"{path}:{lineno}: face refers to {what} {j}, but {n} are defined")
                    row.append(j - 1 if j > 0 else (n + j if j < 0 else -1))
                corners.append(row)
            counts.append(len(parts) - 1)
            face_mat.append(cur)
        elif key in ("vt", "vn"):
            try:
                vals = [float(x) for x in parts[1:4]]
            except ValueError:
                vals = []
            if len(vals) < (1 if key == "vt" else 3) or not all(math.isfinite(x) for x in vals):
                raise SceneError(f"{path}:{lineno}: malformed {key} line {line.strip()!r}")
            if key == "vt":
                vts.append((vals + [0.0])[:2])
            else:
                vns.append(vals)
        elif key == "mtllib":
            mtllibs.extend(parts[1:])
        elif key == "usemtl" and len(parts) > 1:
            name = " ".join(parts[1:])
            usemtl.setdefault(name, None)
            cur = list(usemtl).index(name)
    return ObjScan(text, mtllibs, list(usemtl), corners, counts, face_mat, vts, vns, positions)


def parse_map(path, lineno, args):
    """(file path, uv affine (a, b, c, d, e, f), bump multiplier) of a map statement's arguments:
    its options (`-s` scale and `-o` offset honoured: u' = s_u u + o_u, v' = s_v v + o_v; `-bm`
    the bump multiplier, 1 by default; the others skipped) and the file name, relative to the
    MTL's folder."""
    scale, offset, bm = [1.0, 1.0], [0.0, 0.0], 1.0
    k = 0
    while k < len(args) and args[k] in _MAP_OPTIONS:
        opt = args[k]
        k += 1
        vals = []
        while k < len(args) and len(vals) < _MAP_OPTIONS[opt]:
            try:
                vals.append(float(args[k]))
            except ValueError:
                if opt not in ("-o", "-s", "-t") or not vals:
                    vals.append(args[k])  # a word argument (-clamp on, -imfchan l, -type sphere)
                    k += 1
                break
            k += 1
        if opt == "-s" and vals:
            scale = [float(vals[0]), float(vals[1]) if len(vals) > 1 else 1.0]
        elif opt == "-o" and vals:
            offset = [float(vals[0]), float(vals[1]) if len(vals) > 1 else 0.0]
        elif opt == "-bm" and vals and not isinstance(vals[0], str):
            bm = float(vals[0])
    name = " ".join(args[k:])
    if not name:
        raise SceneError(f"{path}:{lineno}: map statement without a file name")
    return os.path.join(os.path.dirname(path), name), (scale[0], 0.0, offset[0], 0.0, scale[1], offset[1]), bm


def parse_mtl(path, warnings):
    """Read an MTL file into {name: {statement: [floats], map: (file, uv, bump multiplier, "mtl:line")}};
    report what is ignored."""
    mats = {}
    ignored = {}
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
        if key in _MTL_MAPS:
            mats[cur][key] = (*parse_map(path, lineno, args), f"{path}:{lineno}")
            continue
        if key.startswith("map_") or key in ("disp", "decal", "refl", "norm"):
            ignored.setdefault(f"{key} (this map is not supported yet; ignored)", set()).add(cur)
            continue
        if key in ("d", "Tf") and args and args[0] in ("-halo", "xyz", "spectral"):
            ignored.setdefault(f"{key} {args[0]}", set()).add(cur)  # forms the tracer does not read
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
        if key in ("Kd", "Ks", "Ke", "Tf"):
            if len(vals) == 1:
                vals = vals * 3
            if len(vals) != 3 or min(vals) < 0.0:
                raise SceneError(f"{path}:{lineno}: {key} needs three non-negative numbers")
        mats[cur][key] = vals
    for key, names in sorted(ignored.items()):
        warn(warnings, f"{path}: ignoring unsupported statement {key} in {len(names)} material(s)")
    return mats


def material_from_mtl(name, st, where, warnings, textures=None):
    """(type, param (N_PARAM,), emission (3,), tex (N_TEX_SLOTS,)) for one MTL material's statements;
    its maps are appended to `textures` (TextureSpecs) and tex holds their indices (-1: none).

    The PBR extension (`Pm`, `Pr`, as Blender and other exporters write it) is read the way glTF's
    metallic-roughness model means it and takes precedence over `illum` (except a dielectric's
    `illum 4/6/7`): `Pm` >= 0.5 is a conductor whose F0 is the base colour `Kd` (or `Ks` where `Kd`
    is black or absent, the convention of the built-in scenes), alpha = Pr^2; otherwise `Pr` makes
    a glossy plastic over `Kd` with specular F0 from `Ni` ((n - 1)^2 / (n + 1)^2, 0.04 without
    `Ni`), alpha = Pr^2."""
    kd_given = "Kd" in st
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
    elif pm >= 0.5:
        mtype, alpha = bsdfs.CONDUCTOR, (pr or 0.0) ** 2
        base_black = not kd_given or kd.max() <= 0.0
        ks = ks if ks_given and base_black else kd
        if alpha <= 0.0:
            mtype = bsdfs.MIRROR
    elif pr is not None and pr > 0.0 and illum not in (3, 5):
        mtype, alpha = bsdfs.PLASTIC, pr * pr
        f0 = ((ior - 1.0) / (ior + 1.0)) ** 2 if "Ni" in st and ior > 0.0 else 0.04
        ks = np.full(3, f0)
    elif illum in (3, 5):
        mtype = bsdfs.MIRROR
        ks = ks if ks_given else np.ones(3)
    elif ks_given and ks.max() > 0.0:
        mtype = bsdfs.PLASTIC
        alpha = bsdfs.ns_to_alpha(st.get("Ns", [0.0])[0])
        if np.any(kd + ks > 1.0):
            warn(warnings, f"{where}: material {name!r} has Kd + Ks > 1 (reflects more than it receives)")
    else:
        mtype = bsdfs.DIFFUSE
    if pr is not None and pr > 0 and mtype in (bsdfs.MIRROR, bsdfs.DIELECTRIC):
        warn(warnings, f"{where}: material {name!r}: Pr is ignored by its illum {illum}")
    glass = mtype in (bsdfs.DIELECTRIC, bsdfs.ROUGH_DIELECTRIC)
    opacity = st["d"][0] if "d" in st else 1.0 - st.get("Tr", [0.0])[0]
    opacity = min(max(opacity, 0.0), 1.0)
    tf = st.get("Tf", [0.0])
    said = " ".join(f"{k} {' '.join(f'{v:g}' for v in st[k])}" for k in ("d", "Tr", "Tf") if k in st)
    fix = f"if it is glass, set materials.{name}.type to \"dielectric\" (and ior) in the sidecar"
    if not glass and (opacity < 1.0 or "map_d" in st):
        warn(warnings, f"{where}: material {name!r} has an opacity ({said or 'map_d'}): rendered as a cut-out, "
                       f"the rest of the light passing straight through without refraction; {fix}", logging.INFO
             if "map_d" in st and opacity == 1.0 else logging.WARNING)
    elif not glass and "Tf" in st and max(tf) > 0.0 and tf != [1.0, 1.0, 1.0]:
        warn(warnings, f"{where}: material {name!r} is partly transparent ({said}) but renders opaque "
                       f"(illum {illum}: Tf is not a transmission the tracer reads); {fix}")
    if np.any(kd > 1.0) and mtype in (bsdfs.DIFFUSE, bsdfs.PLASTIC):
        warn(warnings, f"{where}: material {name!r} has Kd > 1 (reflects more than it receives)")
    param = np.zeros(bsdfs.N_PARAM)
    param[:8] = [*kd, *ks, alpha, ior]
    if not glass:
        param[bsdfs.P_CLEAR] = 1.0 - opacity
    tex = [-1] * N_TEX_SLOTS
    for key, slot in _MTL_MAPS.items():
        if key not in st or textures is None or tex[slot] >= 0:
            continue
        file, uv, bm, line = st[key]
        if mtype == bsdfs.CONDUCTOR and key == "map_Kd" and slot == TEX_SLOT_KD:
            slot = TEX_SLOT_KS  # a metal's base colour is its F0
        if glass and slot != TEX_SLOT_BUMP:
            warn(warnings, f"{where}: material {name!r} is a dielectric: its {key} is ignored")
            continue
        base = (0.0, 0.0, 0.0) if slot == TEX_SLOT_BUMP else (opacity,) * 3 if slot == TEX_SLOT_OPACITY else \
            tuple(param[3 * slot: 3 * slot + 3])
        if slot == TEX_SLOT_OPACITY:
            param[bsdfs.P_CLEAR] = 0.0  # the texture gives it (map_d replaces d)
        textures.append(TextureSpec("bitmap", file, uv=uv, fallback=base, where=f"{line} ({name!r}, {key})"))
        tex[slot] = len(textures) - 1
        if slot == TEX_SLOT_BUMP:
            param[P_BUMP_SCALE] = bm
    return mtype, param, ke.astype(np.float64), tuple(tex)


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
        if mname not in scan.usemtl:
            mname = None  # faces before any usemtl (trimesh names them "material_0" when vt is given)
        tris.append(v[np.asarray(g.faces, dtype=np.int64)])
        names.append((mname, len(g.faces)))
    if not tris:
        raise SceneError(f"{obj_path}: the OBJ holds no faces")
    return np.concatenate(tris, axis=0), names


def read_geometry(obj_path, warnings=None):
    """The ObjMesh of an OBJ (tracer.objread: triangles, groups, mtllib and usemtl names, corner
    UVs and normals): through the parallel reader when the file is made of the statements it
    reads, else checked line by line (errors name the line) and read by trimesh, with the UVs and
    normals from the line-by-line scan, in the order tracer.objread.assemble gives (checked against
    trimesh's triangles; where they differ, the UVs and normals are dropped with a warning). Both
    give the same triangles in the same order."""
    fast = read_obj(check_text(obj_path, read_bytes(obj_path, "OBJ"), "OBJ"))  # (it frees the bytes once parsed)
    if fast is not None:
        return fast
    scan = scan_obj(obj_path)
    tri, groups = _load_geometry(obj_path, scan)
    uv, normals = _corner_attributes(obj_path, scan, tri, groups, warnings)
    return ObjMesh(tri, groups, scan.mtllibs, scan.usemtl, uv, normals)


def _corner_attributes(obj_path, scan, tri, groups, warnings):
    """(uv, normals) of the slow path's triangles from the scan's face corners, or Nones."""
    idx = np.asarray(scan.corners, dtype=np.int64).reshape(-1, 3)
    has_t, has_n = bool((idx[:, 1] >= 0).any()), bool((idx[:, 2] >= 0).any())
    if not (has_t or has_n):
        return None, None
    counts = np.asarray(scan.counts, dtype=np.int64)
    offsets = np.zeros(counts.size + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    got = assemble(idx, offsets, counts, np.asarray(scan.face_mat, dtype=np.int64), scan.usemtl)
    verts = np.asarray(scan.positions, dtype=np.float64).reshape(-1, 3)
    if got is None or got[1] != groups or not np.array_equal(verts[got[0][:, :, 0]], tri):
        if warnings is not None:
            warn(warnings, f"{obj_path}: its polygons are split in an order the reader cannot follow; "
                           "texture coordinates and vertex normals are ignored")
        return None, None
    t = got[0]
    uv = nrm = None
    if has_t:
        table = np.vstack([np.asarray(scan.texcoords, dtype=np.float64).reshape(-1, 2), np.zeros((1, 2))])
        uv = table[t[:, :, 1]]  # -1 (a face without vt) picks the zero row
    if has_n:
        table = np.vstack([np.asarray(scan.normals, dtype=np.float64).reshape(-1, 3), np.zeros((1, 3))])
        nrm = table[t[:, :, 2]]  # a zero row: a flat triangle
    return uv, nrm


@dataclass
class ObjGeometry:
    """An OBJ's triangles with their materials: tri (F, 3, 3) float64; tri_material (F,) int32
    index into `materials` [(name, type, param (8,), emission (3,), tex)]; `undefined`: usemtl names
    no MTL defines (given diffuse 0.8), in the order the OBJ uses them; `mtllibs`: its MTL files."""

    tri: np.ndarray
    tri_material: np.ndarray
    materials: list
    undefined: list
    mtllibs: list
    uv: np.ndarray | None = None  # (F, 3, 2) corner UVs, or None
    normals: np.ndarray | None = None  # (F, 3, 3) corner normals, or None
    textures: list = None  # [TextureSpec] the materials' tex entries index


def read_obj_scene(obj_path, warnings):
    """The geometry and materials of an OBJ and its MTL files (an ObjGeometry). A usemtl name no
    MTL defines gets a material of its own (diffuse 0.8; the sidecar may override it by that
    name); faces before any usemtl get "__default__"."""
    mesh = read_geometry(obj_path, warnings)
    tri, groups, mtllibs, usemtl = mesh.tri, mesh.groups, mesh.mtllibs, mesh.usemtl
    mtl = {}
    for lib in mtllibs:
        mtl_path = os.path.join(os.path.dirname(obj_path), lib)
        if not os.path.isfile(mtl_path):
            raise SceneError(f"{obj_path}: MTL file {lib!r} not found (looked for {mtl_path})")
        mtl.update(parse_mtl(mtl_path, warnings))
    textures = []
    materials = [(n, *material_from_mtl(n, mtl[n], obj_path, warnings, textures)) for n in mtl]
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
    if textures and mesh.uv is None:
        used = [materials[k] for k in np.unique(tri_material) if len(materials[k]) > 4]
        named = [m[0] for m in used if max(m[4][:TEX_SLOT_BUMP]) >= 0]
        bumped = [m[0] for m in used if m[4][TEX_SLOT_BUMP] >= 0]
        if named:
            warn(warnings, f"{obj_path}: the faces have no texture coordinates (vt): the textures of "
                           f"{', '.join(repr(n) for n in named[:3])} are read at uv (0, 0)")
        if bumped:
            warn(warnings, f"{obj_path}: the faces have no texture coordinates (vt): the bump maps of "
                           f"{', '.join(repr(n) for n in bumped[:3])} are ignored")
    return ObjGeometry(tri, tri_material, materials, undefined, list(mtllibs), mesh.uv, mesh.normals, textures)
