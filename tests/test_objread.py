"""The parallel OBJ reader (tracer.objread) against its slow twin, the line-by-line check plus
trimesh (tracer.readers.obj.scan_obj and _load_geometry), and its number parser against Python's
float(). The twin comparison can detect a triangle out of order, a wrong triangulation, a
material group in the wrong place, a vertex off by one ulp, or a wrong mtllib/usemtl list."""
import glob
import os

import numpy as np
import pytest

from tracer import scene as S
from tracer.readers import obj as O
from tracer.errors import SceneError
from tracer.objread import read_obj, triangle_areas

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHIPPED = sorted(glob.glob(os.path.join(ROOT, "scenes", "*", "*.obj")))
SHARED = sorted(glob.glob(os.path.join(ROOT, "..", "shared", "scenes", "*", "*.obj")))


def _slow(path):
    scan = O.scan_obj(path)
    tri, groups = O._load_geometry(path, scan)
    warnings = []
    uv, normals = O._corner_attributes(path, scan, tri, groups, warnings)
    assert not warnings
    return tri, groups, scan.mtllibs, scan.usemtl, uv, normals


def _same(path):
    with open(path, "rb") as f:
        fast = read_obj(f.read())
    assert fast is not None, f"{path}: the fast reader declined"
    slow = _slow(path)
    assert fast[0].shape == slow[0].shape
    assert np.array_equal(fast[0], slow[0])  # bit for bit, in the same order
    assert tuple(fast[1:4]) == slow[1:4]
    for a, b in zip(fast[4:], slow[4:]):  # corner UVs and normals, bit for bit
        assert (a is None) == (b is None)
        if a is not None:
            assert np.array_equal(a, b)
    return fast


@pytest.mark.parametrize("path", SHIPPED + SHARED, ids=lambda p: os.path.basename(os.path.dirname(p)))
def test_scene_files_match_trimesh(path):
    _same(path)


def _vertex(p, style):
    if style == 0:
        return "v %.7g %.7g %.7g" % tuple(p)
    if style == 1:
        return "v %r %r %r" % tuple(float(x) for x in p)  # 17 significant digits: strtod
    if style == 2:
        return "v %.6e\t%.6e  %.3E " % tuple(p)  # exponents, a tab, double and trailing spaces
    return "v %.17g %.17g %.17g" % tuple(p * 1e-30)  # powers of ten beyond 10^22


def _token(i, pattern):
    return {1: f"{i}", 2: f"{i}/{i}", 3: f"{i}//{i}", 4: f"{i}/{i}/{i}"}[pattern]


def _face(ids, pattern):
    return "f " + " ".join(_token(i, pattern) for i in ids)


@pytest.mark.filterwarnings("ignore:All-NaN slice:RuntimeWarning", "ignore:invalid value:RuntimeWarning")
@pytest.mark.parametrize("pattern", [1, 2, 3, 4])
@pytest.mark.parametrize("style", [0, 1, 2, 3])
def test_statements_match_trimesh(tmp_path, pattern, style):
    """Every index pattern and number style; triangles, quads and a pentagon mixed in one group,
    all-quad groups, faces before any usemtl, a material used twice apart, o/g/s/vn/vt lines,
    blank lines, CRLF line ends (odd styles) and a final line without a newline."""
    rng = np.random.default_rng(style * 10 + pattern)
    v = rng.normal(size=(30, 3)) * 10.0 ** rng.integers(-3, 4, size=(30, 1))
    lines = ["# made by the test", "mtllib m.mtl"] + [_vertex(p, style) for p in v]
    lines += ["vn %.17g %.17g %.17g" % tuple(n) for n in rng.normal(size=(30, 3))]
    lines += ["vt %.17g %.17g" % tuple(t) for t in rng.random((29, 2))] + ["vt 0.5"]  # v defaults to 0
    lines += [_face((1, 2, 3), pattern), "usemtl light", "o part", "s off",
              _face((1, 2, 3, 4), pattern), _face((4, 5, 6, 7, 8), pattern), _face((9, 10, 11), pattern),
              "usemtl B", "g grp", _face((5, 6, 7, 8), pattern), _face((9, 10, 11, 12), pattern),
              "usemtl C", _face((1, 5, 9), pattern), "", "   ", "usemtl light", _face((13, 14, 15), pattern),
              "usemtl B", _face((20, 21, 22, 23), pattern), "usemtl D", _face((24, 25, 26), pattern)]
    end = "\r\n" if style % 2 else "\n"
    (tmp_path / "m.mtl").write_text("newmtl light\nKe 1 1 1\nnewmtl B\nKd 0.5 0.5 0.5\n")
    path = tmp_path / "s.obj"
    path.write_bytes(end.join(lines).encode())
    mesh = _same(str(path))
    assert (mesh.uv is not None) == (pattern in (2, 4)) and (mesh.normals is not None) == (pattern in (3, 4))


def test_numbers_are_parsed_as_float_does():
    """Random doubles in five notations (fast path and strtod) equal Python's float() bit for bit."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=3000) * 10.0 ** rng.integers(-40, 40, size=3000)
    texts = []
    for k, value in enumerate(x.tolist()):
        fmt = ("%.7g", "%r", "%.3e", "%.17g", "%.0f")[k % 5]
        texts.append(fmt % value)
    texts += ["0", "-0", "0.0000000000000000000001", "123456789012345678901234", "+1.5", "-.5", "7.", "1e5",
              "2.5E-3", "9007199254740993", "0.1"]
    texts = texts[: len(texts) // 3 * 3]
    text = "".join(f"v {a} {b} {c}\n" for a, b, c in zip(texts[0::3], texts[1::3], texts[2::3])) + "f 1 2 3\n"
    tri = read_obj(text.encode())[0]
    got = tri.reshape(-1)[: 9].tolist()
    assert got == [float(t) for t in texts[:9]]
    verts = np.array([float(t) for t in texts]).reshape(-1, 3)
    full = read_obj((text + "".join(f"f {i} {i} {i}\n" for i in range(1, len(verts) + 1))).encode())[0]
    assert np.array_equal(full[1:, 0].view(np.int64), verts.view(np.int64))  # same bits, signed zeros too


@pytest.mark.parametrize("text", [
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n",                  # relative indices: trimesh's way
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nf 1 2 3\n",              # a statement it does not read
    "v 0 0 0 1\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",                   # a fourth coordinate
    "v 0 0 0\nv 1 0 0\nv 0 1 0\n  f 1 2 3\n",                   # indented statement
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl  two  spaces\nf 1 2 3\n",  # a name the two readers space differently
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 1 1 1\nf 1 2 3 4 5\n",  # a group of pentagons only
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2 3\n",                   # mixed index patterns
])
def test_declines_what_it_cannot_match(text):
    assert read_obj(text.encode()) is None


@pytest.mark.parametrize("text,message", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 nan\nf 1 2 3\n", ":3: vertex is not finite"),
    ("v 0 0 0\nv 1 0 x\nf 1 2 3\n", ":2: malformed vertex line"),
    ("v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n", ":3: face refers to vertex 3, but 2 vertices are defined"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", ":4: a face needs at least 3 vertices"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", ":4: face refers to vertex 0"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n", ":5: face refers to texture coordinate 2"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//2\n", ":5: face refers to normal 2"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0\nf 1//1 2//1 3//1\n", ":4: malformed vn line"),
])
def test_bad_lines_are_named_by_the_slow_check(tmp_path, text, message):
    """The fast reader declines a bad file; load_scene's error then names the line."""
    assert read_obj(text.encode()) is None
    path = tmp_path / "bad.obj"
    path.write_text(text)
    with pytest.raises(SceneError, match=message):
        S.load_scene(str(path))


def test_triangle_areas_against_numpy():
    rng = np.random.default_rng(5)
    tri = rng.normal(size=(1001, 3, 3)) * 3.0 + 7.0
    tri[5, 2] = tri[5, 0]  # a degenerate one
    area2, bounds = triangle_areas(tri)
    want = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert np.array_equal(area2, want)
    assert np.array_equal(bounds, np.stack([tri.reshape(-1, 3).min(0), tri.reshape(-1, 3).max(0)]))


def test_uvs_and_normals_through_the_slow_path(tmp_path):
    """A line statement sends a file down the slow path (scan + trimesh); its corner UVs and normals
    must equal the fast reader's on the same file without it (detects texture or normal indices
    resolved against the wrong list, or corners matched to the wrong triangle)."""
    rng = np.random.default_rng(7)
    head = "".join("v %.17g %.17g %.17g\n" % tuple(p) for p in rng.normal(size=(6, 3)))
    head += "".join("vt %.17g %.17g\n" % tuple(t) for t in rng.random((6, 2)))
    head += "".join("vn %.17g %.17g %.17g\n" % tuple(n) for n in rng.normal(size=(6, 3)))
    faces = [(1, 2, 3, 4), (4, 5, 6)]
    absolute = head + "".join("f " + " ".join(f"{i}/{7 - i}/{i}" for i in f) + "\n" for f in faces)
    relative = head + "l 1 2\n" + "".join("f " + " ".join(f"{i}/{7 - i}/{i}" for i in f) + "\n" for f in faces)
    fast = read_obj(absolute.encode())
    assert read_obj(relative.encode()) is None
    path = tmp_path / "rel.obj"
    path.write_text(relative)
    slow = O.read_geometry(str(path), [])
    assert np.array_equal(slow.tri, fast.tri)
    assert np.array_equal(slow.uv, fast.uv) and np.array_equal(slow.normals, fast.normals)
