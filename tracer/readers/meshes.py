"""Mesh files of Mitsuba scenes: PLY (ASCII and binary) and Mitsuba's `.serialized` (versions 3, 4).

Each reader returns a Mesh: per-triangle corners (F, 3, 3), UVs (F, 3, 2) or None and vertex
normals (F, 3, 3) or None, in the file's object space. UVs are given in the tracer's convention
(OBJ's: v up the image), which is (u, 1 - v) of the UVs Mitsuba 3 keeps after loading: Mitsuba
reads a PLY's and a serialized file's texture coordinates as stored. Polygons are split into fans.
"""
import struct
import zlib
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError

PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
             "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
UV_NAMES = (("u", "v"), ("s", "t"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))
SERIALIZED_MAGIC = 0x041C


@dataclass
class Mesh:
    tri: np.ndarray  # (F, 3, 3) float64
    uv: np.ndarray | None  # (F, 3, 2) float64
    normals: np.ndarray | None  # (F, 3, 3) float64
    face_normals: bool = False  # the file asks for face normals (serialized flag 0x10)


def _triangles(path, pos, faces, uv=None, nrm=None):
    """Mesh of indexed vertices; faces is a list of int arrays (n, k) of k-gons, split into fans."""
    idx = []
    for f in faces:
        f = np.asarray(f, dtype=np.int64)
        for j in range(1, f.shape[1] - 1):
            idx.append(np.stack([f[:, 0], f[:, j], f[:, j + 1]], axis=1))
    idx = np.concatenate(idx) if idx else np.zeros((0, 3), np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= len(pos)):
        raise SceneError(f"{path}: a face refers to vertex {int(idx.max() if idx.max() >= len(pos) else idx.min())}, "
                         f"but the file has {len(pos)} vertices")
    take = lambda a: None if a is None else np.asarray(a, np.float64)[idx]
    t_uv = take(uv)
    if t_uv is not None:
        t_uv[..., 1] = 1.0 - t_uv[..., 1]
    return Mesh(take(pos), t_uv, take(nrm))


# --- PLY -------------------------------------------------------------------------------------------
def _ply_header(path, data):
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise SceneError(f"{path}: not a PLY file (no 'ply' ... 'end_header')")
    body = end + len(b"end_header")
    body += 2 if data[body:body + 2] == b"\r\n" else 1
    fmt, elements = None, []
    for line in data[:end].decode("ascii", "replace").splitlines()[1:]:
        w = line.split()
        if not w or w[0] in ("comment", "obj_info"):
            continue
        if w[0] == "format" and len(w) >= 2:
            fmt = w[1]
        elif w[0] == "element" and len(w) == 3:
            elements.append((w[1], int(w[2]), []))
        elif w[0] == "property" and elements:
            if w[1] == "list" and len(w) == 5 and w[2] in PLY_TYPES and w[3] in PLY_TYPES:
                elements[-1][2].append((w[4], PLY_TYPES[w[2]], PLY_TYPES[w[3]]))
            elif len(w) == 3 and w[1] in PLY_TYPES:
                elements[-1][2].append((w[2], PLY_TYPES[w[1]], None))
            else:
                raise SceneError(f"{path}: PLY header line {line.strip()!r} not understood")
        else:
            raise SceneError(f"{path}: PLY header line {line.strip()!r} not understood")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise SceneError(f"{path}: PLY format {fmt!r} unknown (ascii, binary_little_endian, binary_big_endian)")
    return fmt, elements, body


def _ply_binary(path, data, pos, count, props, order):
    """({name: array}, new position) of one binary element; lists of one length in one read."""
    if count == 0:
        return {}, pos
    lens = {}
    p = pos
    for name, t, it in props:  # the list lengths of the first record
        if it is None:
            p += np.dtype(t).itemsize
        else:
            n = int(np.frombuffer(data, order + t, 1, p)[0])
            lens[name] = n
            p += np.dtype(t).itemsize + n * np.dtype(it).itemsize
    fields = []
    for name, t, it in props:
        if it is None:
            fields.append((name, order + t))
        else:
            fields += [(name + "#n", order + t), (name, order + it, (lens[name],))]
    dt = np.dtype(fields)
    if pos + dt.itemsize * count <= len(data):
        rec = np.frombuffer(data, dt, count, pos)
        if all(np.all(rec[n + "#n"] == lens[n]) for n in lens):
            return {n: rec[n] for n, _, _ in props}, pos + dt.itemsize * count
    out = {n: [] for n, _, _ in props}  # lists of varying length: record by record
    for _ in range(count):
        for name, t, it in props:
            v = np.frombuffer(data, order + t, 1, pos)
            pos += np.dtype(t).itemsize
            if it is not None:
                n = int(v[0])
                v = np.frombuffer(data, order + it, n, pos)
                pos += n * np.dtype(it).itemsize
                out[name].append(v)
            else:
                out[name].append(v[0])
    return {n: (v if any(it for m, _, it in props if m == n) else np.array(v)) for n, v in out.items()}, pos


def _ply_ascii(path, words, i, count, props):
    """({name: array}, new word index) of one ASCII element."""
    if all(it is None for _, _, it in props):
        a = np.array(words[i:i + count * len(props)], dtype=np.float64).reshape(count, len(props))
        return {n: a[:, j] for j, (n, _, _) in enumerate(props)}, i + count * len(props)
    out = {n: [] for n, _, _ in props}
    for _ in range(count):
        for name, _, it in props:
            if it is None:
                out[name].append(float(words[i]))
                i += 1
            else:
                n = int(words[i])
                out[name].append(np.array(words[i + 1:i + 1 + n], dtype=np.int64))
                i += 1 + n
    return out, i


def read_ply(path):
    """The Mesh of a PLY file: vertex x, y, z (nx, ny, nz; u, v or s, t), faces vertex_indices."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise SceneError(f"{path}: cannot read ({e.strerror})") from None
    fmt, elements, pos = _ply_header(path, data)
    words = data[pos:].split() if fmt == "ascii" else None
    order = "<" if fmt == "binary_little_endian" else ">"
    got, wi = {}, 0
    try:
        for name, count, props in elements:
            if fmt == "ascii":
                got[name], wi = _ply_ascii(path, words, wi, count, props)
            else:
                got[name], pos = _ply_binary(path, data, pos, count, props, order)
    except (ValueError, IndexError, TypeError):
        raise SceneError(f"{path}: the PLY data is shorter than its header says or malformed") from None
    v, fc = got.get("vertex"), got.get("face")
    if v is None or not all(k in v for k in "xyz"):
        raise SceneError(f"{path}: PLY without vertex x, y, z")
    key = next((k for k in ("vertex_indices", "vertex_index") if fc is not None and k in fc), None)
    if key is None:
        raise SceneError(f"{path}: PLY without a face element with vertex_indices")
    pos3 = np.stack([np.asarray(v[k], np.float64) for k in "xyz"], axis=1)
    nrm = np.stack([np.asarray(v[k], np.float64) for k in ("nx", "ny", "nz")], axis=1) \
        if all(k in v for k in ("nx", "ny", "nz")) else None
    uv = next((np.stack([np.asarray(v[a], np.float64), np.asarray(v[b], np.float64)], axis=1)
               for a, b in UV_NAMES if a in v and b in v), None)
    f = fc[key]
    if isinstance(f, np.ndarray) and f.ndim == 2:
        groups = [f]
    else:  # faces of varying sizes: each split into its fan, in the file's order
        groups = [np.array([[row[0], row[j], row[j + 1]] for row in f for j in range(1, len(row) - 1)],
                           np.int64).reshape(-1, 3)]
    return _triangles(path, pos3, groups, uv, nrm)


# --- Mitsuba's serialized format -----------------------------------------------------------------
def read_serialized(path, index=0):
    """The Mesh of shape `index` of a Mitsuba .serialized file (versions 3 and 4: a zlib stream per
    shape; the file ends with the shapes' offsets and their count)."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise SceneError(f"{path}: cannot read ({e.strerror})") from None
    if len(data) < 8:
        raise SceneError(f"{path}: not a Mitsuba serialized file (too short)")
    magic, version = struct.unpack_from("<HH", data, 0)
    if magic != SERIALIZED_MAGIC:
        raise SceneError(f"{path}: not a Mitsuba serialized file (header {magic:#06x}, expected 0x041c)")
    if version not in (3, 4):
        raise SceneError(f"{path}: serialized version {version} is not supported (versions 3 and 4 are); "
                         f"convert the mesh to PLY")
    start = 0
    if index:
        count = struct.unpack_from("<I", data, len(data) - 4)[0]
        if not 0 <= index < count:
            raise SceneError(f"{path}: shape_index {index} out of range; the file holds {count} shapes")
        size = 8 if version == 4 else 4
        at = len(data) - 4 - size * (count - index)
        start = struct.unpack_from("<Q" if version == 4 else "<I", data, at)[0]
        if struct.unpack_from("<HH", data, start) != (SERIALIZED_MAGIC, version):
            raise SceneError(f"{path}: shape {index}'s offset does not point at a shape header")
    try:
        raw = zlib.decompressobj().decompress(data[start + 4:])
        flags = struct.unpack_from("<I", raw, 0)[0]
        at = 4
        if version == 4:
            at = raw.index(b"\0", at) + 1
        n_v, n_f = struct.unpack_from("<QQ", raw, at)
        at += 16
        ft = np.dtype("<f8" if flags & 0x2000 else "<f4")

        def take(k, dt=ft, n=n_v):
            nonlocal at
            a = np.frombuffer(raw, dt, n * k, at).reshape(n, k)
            at += a.nbytes
            return a.astype(np.float64) if dt is ft else a

        pos = take(3)
        nrm = take(3) if flags & 0x1 else None
        uv = take(2) if flags & 0x2 else None
        if flags & 0x8:
            take(3)  # vertex colours: not used
        faces = take(3, np.dtype("<u4" if n_v <= 2 ** 32 else "<u8"), n_f)
    except (zlib.error, struct.error, ValueError) as e:
        raise SceneError(f"{path}: shape {index} is truncated or corrupt ({e})") from None
    mesh = _triangles(path, pos, [faces], uv, nrm)
    mesh.face_normals = bool(flags & 0x10)
    return mesh
