"""A parallel OBJ reader for the common statements, giving what trimesh gives.

`read_obj(data)` reads OBJ bytes made of `v x y z`, `vt u [v [w]]`, `vn x y z`, `f` (indices `a`,
`a/b`, `a//c` or `a/b/c`, one pattern in the whole file, any number of vertices), `usemtl`,
`mtllib`, `o`, `g`, `s`, comments and blank lines, in Numba kernels over the lines (no Python loop over vertices or faces). It returns the
triangles and material groups in the order trimesh's loader produces them (materials in reverse
order of their first face, faces in file order within each; an all-quad group split as
[a b c] for every quad, then [c d a] for every quad; mixed groups quad by quad, larger polygons
as fans), so that the scene, and every image rendered from it, is the same whichever reader ran.

It returns None where it cannot promise that: another statement, a negative index, a vertex
line that is not three plain numbers, a face line it cannot parse or with an index that is not
yet defined, a group of polygons of one size above four, or text that is not UTF-8. The caller
then goes the slow way (tracer.readers.obj: a line-by-line check that names the bad line, and trimesh).

Numbers are parsed exactly: a decimal with at most 18 significant digits and a power of ten
within 10^+-22 is m * 10^e or m / 10^-e in one correctly rounded float64 operation (Clinger's
fast path, exact when m < 2^53); any other is handed to the C library's strtod (correctly
rounded in glibc, as Python's float() is).
"""
import ctypes
from typing import NamedTuple

import numpy as np
from llvmlite import ir
from numba import prange, types
from numba.extending import intrinsic

from ._jit import jit, kernel
from .bvh import _bounds, edge_cross

SKIP, VERT, FACE, USEMTL, MTLLIB, OTHER, TEXCOORD, NORMAL = 0, 1, 2, 3, 4, 5, 6, 7
_STRTOD = ctypes.cast(ctypes.CDLL(None).strtod, ctypes.c_void_p).value
_POW10 = np.array([10.0 ** k for k in range(23)])


@intrinsic
def _strtod(typingctx, fn, addr):
    """double strtod(const char *addr, NULL) called at the address `fn`."""
    sig = types.float64(fn, addr)

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fnty = ir.FunctionType(ir.DoubleType(), [i64, i64])
        ptr = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(ptr, [args[1], ir.Constant(i64, 0)])

    return sig, codegen


@jit
def _space(c):
    return c == 32 or c == 9 or c == 13


@jit
def _key(buf, s, e, word):
    """Whether line [s, e) starts with `word` followed by a space or the line's end."""
    n = len(word)
    if e - s < n:
        return False
    for j in range(n):
        if buf[s + j] != word[j]:
            return False
    return s + n == e or buf[s + n] == 32


@kernel
def classify(buf, starts, ends, kinds):
    """kinds[l]: the statement of line l (SKIP, VERT, TEXCOORD, NORMAL, FACE, USEMTL, MTLLIB, or
    OTHER)."""
    for ln in prange(starts.shape[0]):
        s = starts[ln]
        e = ends[ln]
        k = OTHER
        if s == e:
            k = SKIP
        else:
            c0 = buf[s]
            c1 = buf[s + 1] if e - s > 1 else 0
            if _space(c0):
                k = SKIP
                for j in range(s, e):
                    if not _space(buf[j]):
                        k = OTHER
                        break
            elif c0 == 35:  # '#'
                k = SKIP
            elif c0 == 118:  # 'v'
                if c1 == 32:
                    k = VERT
                elif (c1 == 110 or c1 == 116) and (e - s == 2 or buf[s + 2] == 32):  # vn, vt
                    k = NORMAL if c1 == 110 else TEXCOORD
            elif c0 == 102 and c1 == 32:  # 'f '
                k = FACE
            elif (c0 == 111 or c0 == 103 or c0 == 115) and (e - s == 1 or c1 == 32):  # o, g, s
                k = SKIP
            elif _key(buf, s, e, np.array([117, 115, 101, 109, 116, 108], np.uint8)):  # usemtl
                k = USEMTL
            elif _key(buf, s, e, np.array([109, 116, 108, 108, 105, 98], np.uint8)):  # mtllib
                k = MTLLIB
        kinds[ln] = k


@jit
def _digits(buf, i, e, m, digits):
    """The run of decimal digits at buf[i] (line end e), appended to m while it holds at most 18
    significant digits (so that m stays below 2^63): (index after the run, m, significant digits
    in m, digits appended, digits dropped)."""
    kept = 0
    dropped = 0
    while i < e and 48 <= buf[i] <= 57:
        if digits < 18:
            if m > 0 or buf[i] != 48:
                digits += 1
            m = m * 10 + (buf[i] - 48)
            kept += 1
        else:
            dropped += 1
        i += 1
    return i, m, digits, kept, dropped


@jit
def _number(buf, j, e, addr, strtod):
    """Parse the decimal at buf[j] (line end e; the buffer's address addr, strtod's address
    strtod): (value, index after it, ok)."""
    i = j
    neg = False
    if i < e and (buf[i] == 45 or buf[i] == 43):
        neg = buf[i] == 45
        i += 1
    i, m, digits, kept, drop = _digits(buf, i, e, 0, 0)  # the integer part
    frac = 0  # digits after the point kept in m
    hard = drop > 0
    seen = kept + drop > 0
    if i < e and buf[i] == 46:  # '.'
        i, m, digits, frac, fdrop = _digits(buf, i + 1, e, m, digits)
        hard = hard or fdrop > 0
        seen = seen or frac + fdrop > 0
    if not seen:
        return 0.0, i, False
    ex = 0
    if i < e and (buf[i] == 101 or buf[i] == 69):  # e, E
        i += 1
        eneg = False
        if i < e and (buf[i] == 45 or buf[i] == 43):
            eneg = buf[i] == 45
            i += 1
        if not (i < e and 48 <= buf[i] <= 57):
            return 0.0, i, False
        while i < e and 48 <= buf[i] <= 57:
            if ex < 100000:
                ex = ex * 10 + (buf[i] - 48)
            i += 1
        if eneg:
            ex = -ex
    if i < e and not _space(buf[i]):
        return 0.0, i, False
    p = ex - frac + drop
    if hard or m > (1 << 53) or p > 22 or p < -22:
        v = _strtod(strtod, addr + j)
        return v, i, True
    v = float(m)
    if p >= 0:
        v = v * _POW10[p]
    else:
        v = v / _POW10[-p]
    return (-v if neg else v), i, True


@kernel
def parse_vertices(buf, starts, ends, lines, skip, lo, hi, out, strtod):
    """out[r] = the numbers of line lines[r] after its first `skip` characters (the statement):
    between lo and hi plain decimals, the first out.shape[1] kept (missing ones 0). strtod: the C
    function's address, an argument so that the cached kernel holds no address of this process.
    Returns how many lines were not lo to hi plain decimals."""
    addr = buf.ctypes.data
    bad = 0
    for r in prange(lines.shape[0]):
        ln = lines[r]
        e = ends[ln]
        j = starts[ln] + skip
        ok = True
        count = 0
        for q in range(out.shape[1]):
            out[r, q] = 0.0
        for q in range(hi):
            while j < e and _space(buf[j]):
                j += 1
            if j >= e:
                break
            v, j, good = _number(buf, j, e, addr, strtod)
            ok = ok and good
            if q < out.shape[1]:
                out[r, q] = v
            count += 1
        while j < e and _space(buf[j]):
            j += 1
        if not ok or j != e or count < lo:
            bad += 1
    return bad


@jit
def _index(buf, i, e):
    """Unsigned integer at buf[i]: (value, index after it); value -1 if no digit."""
    v = 0
    seen = False
    while i < e and 48 <= buf[i] <= 57:
        if v < (1 << 40):
            v = v * 10 + (buf[i] - 48)
        i += 1
        seen = True
    return (v if seen else -1), i


@jit
def _face_line(buf, s, e, limit, limit_t, limit_n, out, o):
    """Walk the face line [s, e): write its (position, texture, normal) indices (0-based; -1 where
    the pattern has none) to rows out[o:] if out is long enough; returns (vertex count, pattern,
    ok). Pattern: 1 a, 2 a/b, 3 a//c, 4 a/b/c, -1 mixed. ok is False on a malformed token or an
    index outside 1..limit (1..limit_t, 1..limit_n for the others)."""
    j = s + 1
    nvert = 0
    pattern = 0
    ok = True
    while True:
        while j < e and _space(buf[j]):
            j += 1
        if j >= e:
            break
        a, j = _index(buf, j, e)
        b = 0
        c = 0
        pat = 1
        if j < e and buf[j] == 47:  # '/'
            j += 1
            b, j = _index(buf, j, e)
            pat = 2
            if j < e and buf[j] == 47:
                j += 1
                c, j = _index(buf, j, e)
                if c < 0 or c > limit_n:
                    ok = False
                pat = 4 if b >= 0 else 3
            elif b < 0:
                ok = False
            if b > limit_t:
                ok = False
        if j < e and not _space(buf[j]):
            ok = False
            break
        if a < 1 or a > limit:
            ok = False
        if pattern == 0:
            pattern = pat
        elif pattern != pat:
            pattern = -1
        if o + nvert < out.shape[0]:
            out[o + nvert, 0] = a - 1
            out[o + nvert, 1] = b - 1 if b > 0 else -1
            out[o + nvert, 2] = c - 1 if c > 0 else -1
        nvert += 1
    return nvert, pattern, ok


@kernel
def face_counts(buf, starts, ends, lines, vbefore, tbefore, nbefore, counts, patterns):
    """counts[r], patterns[r] of face line lines[r]; returns how many lines are malformed or
    name a vertex (texture coordinate, normal) not defined before them (vbefore[r], tbefore[r],
    nbefore[r] are how many there are)."""
    bad = 0
    empty = np.empty((0, 3), np.int64)
    for r in prange(lines.shape[0]):
        ln = lines[r]
        n, pat, ok = _face_line(buf, starts[ln], ends[ln], vbefore[r], tbefore[r], nbefore[r], empty, 0)
        counts[r] = n
        patterns[r] = pat
        if not ok or n < 3:
            bad += 1
    return bad


@kernel
def face_indices(buf, starts, ends, lines, offsets, out):
    """The 0-based (position, texture, normal) indices of every face line, at rows
    out[offsets[r]:offsets[r + 1]]."""
    for r in prange(lines.shape[0]):
        ln = lines[r]
        _face_line(buf, starts[ln], ends[ln], 1 << 62, 1 << 62, 1 << 62, out[: offsets[r + 1]], offsets[r])


def _triangles(idx, offsets, counts):
    """Triangles (T, 3, K) of the faces idx[offsets[r]:offsets[r] + counts[r]] (rows of K indices),
    in trimesh's order; None for a group of polygons of one size above four."""
    if counts.size == 0:
        return np.zeros((0, 3, idx.shape[1]), np.int64)
    if counts.min() == counts.max():
        c = int(counts[0])
        rows = idx[offsets[:-1, None] + np.arange(c)] if c <= 4 else None
        if c == 3:
            return rows
        if c == 4:
            return np.concatenate([rows[:, [0, 1, 2]], rows[:, [2, 3, 0]]])
        return None
    ntri = counts - 2
    face = np.repeat(np.arange(counts.size), ntri)
    j = np.arange(face.size) - np.repeat(np.cumsum(ntri) - ntri, ntri)  # triangle j of its face
    base = offsets[:-1][face]
    quad = counts[face] == 4
    a = np.where(quad & (j == 1), 2, 0)
    b = np.where(quad & (j == 1), 3, j + 1)
    c = np.where(quad & (j == 1), 0, j + 2)
    return np.stack([idx[base + a], idx[base + b], idx[base + c]], axis=1)


class ObjMesh(NamedTuple):
    """What read_obj returns: tri (F, 3, 3) float64; groups [(usemtl name or None, face count)] in
    triangle order; mtllibs; usemtl names in order of first use; uv (F, 3, 2) float64 corner
    texture coordinates, or None where the faces name none; normals (F, 3, 3) float64 corner
    normals as the file gives them, or None."""

    tri: np.ndarray
    groups: list
    mtllibs: list
    usemtl: list
    uv: np.ndarray | None = None
    normals: np.ndarray | None = None


def assemble(idx, offsets, counts, face_mat, used):
    """Triangles (F, 3, K) of the faces (rows idx[offsets[r]:offsets[r + 1]] of K indices each,
    face r of material face_mat[r], an index into `used`, -1 for none) and their groups, in
    trimesh's order: the groups in reverse order of their first face, faces in file order within
    each (one stable sort). None where a group is of polygons of one size above four."""
    by_mat = np.argsort(face_mat, kind="stable")
    mats, start = np.unique(face_mat[by_mat], return_index=True)
    bounds = np.append(start, by_mat.size)
    tris, groups = [], []
    for j in np.argsort(by_mat[start])[::-1]:
        sel = by_mat[bounds[j]: bounds[j + 1]]
        c = counts[sel]
        o = np.zeros(sel.size + 1, np.int64)
        np.cumsum(c, out=o[1:])
        gidx = idx if sel.size == counts.size else idx[np.repeat(offsets[sel] - o[:-1], c) + np.arange(o[-1])]
        t = _triangles(gidx, o, c)
        if t is None:
            return None
        tris.append(t)
        groups.append((used[mats[j]] if mats[j] >= 0 else None, len(t)))
    if not tris:
        return None
    return (np.concatenate(tris) if len(tris) > 1 else tris[0]), groups


def read_obj(data):
    """OBJ bytes -> ObjMesh, or None (see the module docstring)."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    if not data.isascii():
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            return None
    buf = np.frombuffer(data if data.endswith(b"\n") else data + b"\n", np.uint8)
    ends = np.flatnonzero(buf == 10)
    starts = np.empty_like(ends)
    starts[0] = 0
    starts[1:] = ends[:-1] + 1
    kinds = np.empty(ends.size, np.int8)
    classify(buf, starts, ends, kinds)
    if (kinds == OTHER).any():
        return None
    vlines = np.flatnonzero(kinds == VERT)
    tlines = np.flatnonzero(kinds == TEXCOORD)
    nlines = np.flatnonzero(kinds == NORMAL)
    flines = np.flatnonzero(kinds == FACE)
    verts = np.empty((vlines.size, 3))
    if parse_vertices(buf, starts, ends, vlines, 1, 3, 3, verts, _STRTOD):
        return None
    texcoords = np.empty((tlines.size, 2))
    if parse_vertices(buf, starts, ends, tlines, 2, 1, 3, texcoords, _STRTOD):
        return None
    normals = np.empty((nlines.size, 3))
    if parse_vertices(buf, starts, ends, nlines, 2, 3, 3, normals, _STRTOD):
        return None
    # what is defined before each face line
    vbefore, tbefore, nbefore = (np.searchsorted(x, flines) for x in (vlines, tlines, nlines))
    counts = np.empty(flines.size, np.int64)
    patterns = np.empty(flines.size, np.int8)
    if face_counts(buf, starts, ends, flines, vbefore, tbefore, nbefore, counts, patterns):
        return None
    if patterns.size and (patterns.min() < 1 or patterns.min() != patterns.max()):
        return None
    offsets = np.zeros(flines.size + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    idx = np.empty((offsets[-1], 3), np.int64)
    face_indices(buf, starts, ends, flines, offsets, idx)
    pattern = int(patterns[0]) if patterns.size else 1

    # usemtl and mtllib lines are few: read them in Python
    names, mtllibs = [], []
    mlines = np.flatnonzero(kinds == USEMTL)
    mtl_lines = np.flatnonzero(kinds == MTLLIB)
    for ln in mlines:
        name = data[starts[ln] + 6 : ends[ln]].decode("utf-8").strip()
        if not name or name != " ".join(name.split()):
            return None  # trimesh and tracer.readers.obj would name it differently
        names.append(name)
    for ln in mtl_lines:
        mtllibs.extend(data[starts[ln] + 6 : ends[ln]].decode("utf-8").split())
    del data, buf, starts, ends, kinds  # the text's memory, before the triangles take theirs
    used = list(dict.fromkeys(names))  # the usemtl names in order of first use
    # material of each face line: that of the last usemtl line before it (-1: none)
    uniq = {n: k for k, n in enumerate(used)}
    mat_of_line = np.array([uniq[n] for n in names] + [-1], np.int64)
    face_mat = mat_of_line[np.searchsorted(mlines, flines) - 1]  # -1 picks the trailing -1
    got = assemble(idx, offsets, counts, face_mat, used)
    if got is None:
        return None  # no faces (the slow path reports it), or polygons trimesh splits otherwise
    t, groups = got
    uv = texcoords[t[:, :, 1]] if pattern in (2, 4) else None
    nrm = normals[t[:, :, 2]] if pattern in (3, 4) else None
    return ObjMesh(verts[t[:, :, 0]], groups, mtllibs, used, uv, nrm)


@kernel
def _areas(tri, area2):
    for i in prange(tri.shape[0]):
        n = edge_cross(tri, i)[2]
        area2[i] = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])


def triangle_areas(tri):
    """(|e1 x e2| per triangle (F,), bounds (2, 3): min and max corner) of triangles (F, 3, 3)
    with finite vertices, in parallel passes without temporaries."""
    area2 = np.empty(tri.shape[0])
    _areas(tri, area2)
    return area2, _bounds(tri)[0]
