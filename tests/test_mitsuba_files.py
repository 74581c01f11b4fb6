"""The Mitsuba scene XML reader's files and structure: transforms, PLY and serialized meshes (written
here, byte by byte, from the formats' descriptions), `<include>`, the 0.6 and 3 dialects, envmap,
near_clip, the warnings for what it does not use, and bad input as one line (exit 2)."""
import os
import struct
import zlib

import numpy as np
import pytest
from numba import njit

import tracer
from tracer.errors import SceneError
from tracer.lights import env_radiance
from tracer.readers.mitsuba import read_mitsuba_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(ROOT, "..", "shared", "scenes-mitsuba")

CAMERA = """<sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 6" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/></film>
    </sensor>"""
LIGHT = """<shape type="rectangle"><transform name="to_world"><translate z="3"/></transform>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>"""


def _scene(tmp_path, body, name="scene.xml", camera=CAMERA, light=LIGHT):
    path = tmp_path / name
    path.write_text(f'<scene version="3.0.0">\n    {camera}\n    {light}\n    {body}\n</scene>\n')
    return str(path)


def _tri_set(tri):
    """Triangles as a sorted (F, 9) array, for comparing meshes whatever their order and first corner."""
    t = np.round(np.asarray(tri).reshape(-1, 3, 3), 5)
    rolled = [np.roll(t, k, axis=1).reshape(-1, 9) for k in range(3)]  # the corner order, up to rotation
    canon = np.array([min(map(tuple, r)) for r in zip(*rolled)])
    return canon[np.lexsort(canon.T[::-1])]


# --- transforms ------------------------------------------------------------------------------------
def _rot(axis, deg):
    """Rotation matrix from a unit quaternion (written independently of the reader's Rodrigues)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    h = np.radians(deg) / 2
    w, (x, y, z) = np.cos(h), np.sin(h) * a
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def test_transforms_compose_in_order_as_numpy(tmp_path):
    """A rectangle under matrix, translate, rotate (a skew axis), non-uniform scale and lookat, in
    that order (each applied after the ones before it: M = L S R T A), has the corners NumPy's
    product of the five matrices gives (detects a chain composed the wrong way round, a rotation of
    the wrong sign or axis, a matrix read transposed, a lookat with a mirrored axis). The rotation
    axis is not unit length: it is normalised, with a warning."""
    A = np.array([[1, 0.2, 0, 0.5], [0, 1, 0, -1], [0.1, 0, 2, 0], [0, 0, 0, 1]])
    T = np.eye(4)
    T[:3, 3] = (1, 2, 3)
    R = np.eye(4)
    R[:3, :3] = _rot((1, 2, 0.5), 37)
    S = np.diag([2.0, 0.5, 3.0, 1.0])
    o, tg, up = np.array([1.0, 2, 3]), np.array([0.0, 0, -1]), np.array([0.0, 1, 0])
    f = (tg - o) / np.linalg.norm(tg - o)
    x = np.cross(up, f) / np.linalg.norm(np.cross(up, f))  # Mitsuba's look_at: +x = up x forward
    L = np.eye(4)
    L[:3, 0], L[:3, 1], L[:3, 2], L[:3, 3] = x, np.cross(f, x), f, o
    M = L @ S @ R @ T @ A
    body = f"""<shape type="rectangle"><transform name="to_world">
        <matrix value="{' '.join(f'{v:.17g}' for v in A.reshape(-1))}"/>
        <translate x="1" y="2" z="3"/><rotate x="1" y="2" z="0.5" angle="37"/>
        <scale x="2" y="0.5" z="3"/><lookat origin="1, 2, 3" target="0, 0, -1" up="0, 1, 0"/>
    </transform></shape>"""
    spec = read_mitsuba_scene(_scene(tmp_path, body, light=""), None)
    assert len(spec.warnings) == 1 and "normalised" in spec.warnings[0]  # (Mitsuba 3 does not normalise)
    corners = np.array([[-1, -1, 0, 1], [1, -1, 0, 1], [1, 1, 0, 1], [-1, 1, 0, 1]], float) @ M.T
    got = np.unique(np.round(spec.tri.reshape(-1, 3), 9), axis=0)
    np.testing.assert_allclose(got, np.unique(np.round(corners[:, :3], 9), axis=0), atol=1e-8)


# --- mesh files -----------------------------------------------------------------------------------
def _pyramid():
    """A pyramid: a quad base and four triangles; positions, faces (quad first), uvs, normals."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1], [0.5, 1, 0.5]], float)
    uv = np.array([[0.1, 0.2], [0.9, 0.2], [0.9, 0.8], [0.1, 0.8], [0.5, 0.5]])
    nrm = pos - (0.5, 0.3, 0.5)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return pos, [[0, 1, 2, 3], [0, 4, 1], [1, 4, 2], [2, 4, 3], [3, 4, 0]], uv, nrm


def _triangulated(faces):
    return np.array([[f[0], f[j], f[j + 1]] for f in faces for j in range(1, len(f) - 1)])


def write_ply(path, pos, faces, uv=None, nrm=None, fmt="binary_little_endian"):
    """A PLY file: vertex x y z [nx ny nz] [u v] as float, face list uchar int."""
    names = ["x", "y", "z"] + (["nx", "ny", "nz"] if nrm is not None else []) + (["u", "v"] if uv is not None else [])
    cols = np.hstack([a for a in (pos, nrm, uv) if a is not None])
    head = ["ply", f"format {fmt} 1.0", "comment written by a test", f"element vertex {len(pos)}"]
    head += [f"property float {n}" for n in names] + [f"element face {len(faces)}",
                                                       "property list uchar int vertex_indices", "end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(head) + "\n").encode())
        if fmt == "ascii":
            f.write("".join(" ".join(f"{v:.9g}" for v in row) + "\n" for row in cols).encode())
            f.write("".join(f"{len(fc)} " + " ".join(map(str, fc)) + "\n" for fc in faces).encode())
            return
        e = "<" if fmt == "binary_little_endian" else ">"
        f.write(cols.astype(e + "f4").tobytes())
        for fc in faces:
            f.write(struct.pack(e + "B" + "i" * len(fc), len(fc), *fc))


def write_serialized(path, meshes, version=4, double=False):
    """Mitsuba's serialized format: per mesh the header (0x041C, version), then a zlib stream of
    flags, (v4: a name), counts, positions, normals, uvs, faces; at the end the offsets and count."""
    out, offsets = bytearray(), []
    ft = "<f8" if double else "<f4"
    for pos, faces, uv, nrm in meshes:
        offsets.append(len(out))
        out += struct.pack("<HH", 0x041C, version)
        flags = (0x2000 if double else 0x1000) | (0x1 if nrm is not None else 0) | (0x2 if uv is not None else 0)
        body = struct.pack("<I", flags) + (b"part\0" if version == 4 else b"")
        body += struct.pack("<QQ", len(pos), len(faces)) + np.asarray(pos, ft).tobytes()
        body += (np.asarray(nrm, ft).tobytes() if nrm is not None else b"")
        body += (np.asarray(uv, ft).tobytes() if uv is not None else b"") + np.asarray(faces, "<u4").tobytes()
        out += zlib.compress(body)
    out += np.array(offsets, "<u8" if version == 4 else "<u4").tobytes() + struct.pack("<I", len(meshes))
    with open(path, "wb") as f:
        f.write(bytes(out))


@pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian", "ascii"])
def test_ply_with_a_quad_and_normals(tmp_path, fmt):
    """A PLY pyramid (a quad split into a fan, four triangles) under a to_world: the world corners,
    the UVs (the tracer's (u, 1 - v) of the stored ones, which Mitsuba 3 keeps as stored) and the
    normals (by the inverse transpose) equal those computed here (detects a wrong byte order, a quad
    dropped or split wrongly, uvs not flipped, normals transformed as points)."""
    pos, faces, uv, nrm = _pyramid()
    write_ply(tmp_path / "p.ply", pos, faces, uv, nrm, fmt)
    body = """<shape type="ply"><string name="filename" value="p.ply"/>
        <transform name="to_world"><scale x="2" y="1" z="1"/><translate x="1"/></transform></shape>"""
    spec = read_mitsuba_scene(_scene(tmp_path, body, light=""), None)
    M = np.diag([2.0, 1, 1])
    idx = _triangulated(faces)
    assert spec.tri.shape == (6, 3, 3) and not spec.warnings
    np.testing.assert_allclose(spec.tri, pos[idx] @ M.T + (1, 0, 0), atol=1e-6)
    np.testing.assert_allclose(spec.uv, np.stack([uv[idx][..., 0], 1 - uv[idx][..., 1]], -1), atol=1e-6)
    n = nrm[idx] @ np.linalg.inv(M)
    np.testing.assert_allclose(spec.normals / np.linalg.norm(spec.normals, axis=-1, keepdims=True),
                               n / np.linalg.norm(n, axis=-1, keepdims=True), atol=1e-6)


@pytest.mark.parametrize("version,double", [(3, False), (4, False), (4, True)])
def test_serialized_shape_index_and_precision(tmp_path, version, double):
    """A serialized file with two meshes: shape_index 1 is the second (through the offsets at the end
    of the file, 32-bit in version 3, 64-bit in 4), in single or double precision, its UVs flipped to
    the tracer's convention; shape_index 2 is one line naming the count; Mitsuba 3, where installed,
    loads the same file to the same world-space vertices."""
    pos, faces, uv, nrm = _pyramid()
    tris = _triangulated(faces)
    other = (pos[:3] + 5.0, np.array([[0, 1, 2]]), None, None)
    write_serialized(tmp_path / "m.serialized", [other, (pos, tris, uv, nrm)], version, double)
    shape = """<shape type="serialized"><string name="filename" value="m.serialized"/>
        <integer name="shape_index" value="{}"/><transform name="to_world"><translate y="-1"/></transform></shape>"""
    path = _scene(tmp_path, shape.format(1))
    spec = read_mitsuba_scene(path, None)
    mine = spec.tri[spec.tri_material == spec.tri_material[-1]]
    np.testing.assert_allclose(mine, pos[tris] - (0, 1, 0), atol=1e-6)
    np.testing.assert_allclose(spec.uv[-6:, :, 1], 1 - uv[tris][..., 1], atol=1e-6)
    with pytest.raises(SceneError, match="shape_index 2 out of range; the file holds 2"):
        read_mitsuba_scene(_scene(tmp_path, shape.format(2), name="bad.xml"), None)
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    ref = mi.load_file(path)
    theirs = [np.array(mi.traverse(s)["vertex_positions"]).reshape(-1, 3) for s in ref.shapes()
              if "vertex_positions" in mi.traverse(s)]
    np.testing.assert_allclose(np.unique(np.round(theirs[0], 4), axis=0),
                               np.unique(np.round(mine.reshape(-1, 3), 4), axis=0), atol=2e-4)


# --- structure -------------------------------------------------------------------------------------
def test_include_splices_files_and_a_cycle_is_one_line(tmp_path, capsys):
    """<include> brings another file's BSDFs and shapes in (its mesh path relative to it); a file
    that includes itself through another is one line naming the file, the line and the cycle, exit 2."""
    from tests.test_cli import fails_with

    os.makedirs(tmp_path / "parts")
    write_ply(tmp_path / "parts" / "p.ply", *_pyramid()[:2])
    (tmp_path / "parts" / "more.xml").write_text("""<scene version="3.0.0">
    <bsdf type="diffuse" id="Red"><rgb name="reflectance" value="0.8, 0.1, 0.1"/></bsdf>
    <shape type="ply"><string name="filename" value="p.ply"/><ref id="Red"/></shape>
</scene>""")
    spec = read_mitsuba_scene(_scene(tmp_path, '<include filename="parts/more.xml"/>'), None)
    red = [m[0] for m in spec.materials].index("Red")
    assert (spec.tri_material == red).sum() == 6 and np.allclose(spec.materials[red][2][:3], (0.8, 0.1, 0.1))
    (tmp_path / "a.xml").write_text('<scene version="3.0.0">\n<include filename="b.xml"/>\n</scene>')
    (tmp_path / "b.xml").write_text('<scene version="3.0.0">\n\n<include filename="a.xml"/>\n</scene>')
    path = _scene(tmp_path, '<include filename="a.xml"/>', name="cyc.xml")
    fails_with(capsys, [path, "--quiet"], "b.xml:3:", "include cycle (a.xml -> b.xml -> a.xml)")


DIALECT_06 = """<scene version="0.6.0">
    <integrator type="path"><integer name="maxDepth" value="7"/><integer name="rrDepth" value="3"/></integrator>
    <sensor type="perspective"><float name="fov" value="35"/><string name="fovAxis" value="y"/>
        <float name="nearClip" value="0.5"/>
        <transform name="toWorld"><lookAt origin="1, 2, 6" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sampleCount" value="12"/></sampler>
        <film type="hdrfilm"><integer name="width" value="10"/><integer name="height" value="7"/></film>
    </sensor>
    <bsdf type="roughplastic" id="P"><float name="intIOR" value="1.6"/><float name="extIOR" value="1.1"/>
        <srgb name="diffuseReflectance" value="0.5, 0.25, 0.125"/><float name="alpha" value="0.2"/>
        <spectrum name="specularReflectance" value="0.7"/></bsdf>
    <shape type="serialized"><string name="filename" value="m.serialized"/><integer name="shapeIndex" value="0"/>
        <boolean name="faceNormals" value="true"/><ref id="P"/></shape>
    <shape type="rectangle"><boolean name="flipNormals" value="true"/>
        <transform name="toWorld"><translate z="3"/></transform>
        <emitter type="area"><spectrum name="radiance" value="2"/></emitter></shape>
</scene>"""


def test_the_0_6_and_3_dialects_give_the_same_spec(tmp_path):
    """The same scene in 0.6's camelCase (maxDepth, rrDepth, fovAxis, nearClip, lookAt, sampleCount,
    intIOR, srgb, shapeIndex, faceNormals, flipNormals) and in Mitsuba 3's snake_case (its sRGB
    colour written out linear here) reads to the same spec, with no warning: triangles, normals,
    materials, film, render settings and camera."""
    pos, faces, uv, nrm = _pyramid()
    write_serialized(tmp_path / "m.serialized", [(pos, _triangulated(faces), uv, nrm)])
    srgb = np.array([0.5, 0.25, 0.125])
    lin = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    v3 = DIALECT_06.replace('version="0.6.0"', 'version="3.0.0"').replace("lookAt", "lookat")
    for a, b in (("maxDepth", "max_depth"), ("rrDepth", "rr_depth"), ("fovAxis", "fov_axis"), ("nearClip", "near_clip"),
                 ("toWorld", "to_world"), ("sampleCount", "sample_count"), ("intIOR", "int_ior"), ("extIOR", "ext_ior"),
                 ("diffuseReflectance", "diffuse_reflectance"), ("specularReflectance", "specular_reflectance"),
                 ("shapeIndex", "shape_index"), ("faceNormals", "face_normals"), ("flipNormals", "flip_normals")):
        v3 = v3.replace(f'"{a}"', f'"{b}"')
    v3 = v3.replace('<srgb name="diffuse_reflectance" value="0.5, 0.25, 0.125"/>',
                    f'<rgb name="diffuse_reflectance" value="{", ".join(f"{c:.17g}" for c in lin)}"/>')
    (tmp_path / "a.xml").write_text(DIALECT_06)
    (tmp_path / "b.xml").write_text(v3)
    old, new = (read_mitsuba_scene(str(tmp_path / n), None) for n in ("a.xml", "b.xml"))
    assert not old.warnings and not new.warnings, (old.warnings, new.warnings)
    for key in ("tri", "tri_material", "uv", "normals"):
        a, b = getattr(old, key), getattr(new, key)
        assert (a is None) == (b is None) and (a is None or np.array_equal(a, b)), key
    assert (old.width, old.height, old.render) == (new.width, new.height, new.render)
    assert (old.render.max_depth, old.render.rr_depth, old.render.spp) == (7, 3, 12)
    assert (old.camera.fov, old.camera.fov_axis, old.camera.near) == (new.camera.fov, new.camera.fov_axis, 0.5)
    assert np.array_equal(old.camera.matrix, new.camera.matrix)
    for ma, mb in zip(old.materials, new.materials):
        assert ma[0] == mb[0] and ma[1] == mb[1] and np.allclose(ma[2], mb[2], rtol=1e-12) and np.array_equal(ma[3], mb[3])
    assert np.allclose(old.materials[0][2][:3], lin, rtol=1e-12) and old.materials[0][2][7] == pytest.approx(1.6 / 1.1)


def test_near_clip_starts_camera_rays_on_the_near_plane(tmp_path):
    """near_clip 2.5 hides a wall 2 units in front of the camera (at distance 2 < 2.5 along the
    axis) and shows the light behind it; without near_clip the wall blocks the view (the image
    mean drops to the wall's reflected light)."""
    wall = """<shape type="rectangle"><transform name="to_world"><scale value="5"/><translate z="4"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf></shape>"""
    light = """<shape type="rectangle"><transform name="to_world"><scale value="9"/></transform>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>"""
    cam = CAMERA.replace('<float name="fov" value="40"/>', '<float name="fov" value="40"/>{}')
    means = []
    for near in ("", '<float name="near_clip" value="2.5"/>'):
        path = _scene(tmp_path, wall, name=f"n{len(near)}.xml", camera=cam.format(near), light=light)
        r = tracer.render(tracer.load_scene(path), spp=1, seed=0, max_depth=1)
        means.append(float(r.image.mean()))
    assert means == [0.0, 1.0]


ENV = """<emitter type="envmap"><string name="filename" value="env.exr"/><float name="scale" value="2"/>
        <transform name="to_world"><rotate x="0.957826285" y="0.287347886" angle="70"/></transform></emitter>"""


@njit(cache=True)
def _env_radiance_batch(lt, d):
    out = np.zeros((d.shape[0], 3))
    for i in range(d.shape[0]):
        out[i] = env_radiance(lt, (d[i, 0], d[i, 1], d[i, 2]))
    return out


def test_envmap_rotation_and_scale_against_mitsuba(tmp_path):
    """A smooth lat-long map under a to_world rotation and scale 2: the tracer's environment
    radiance along 500 random directions (between texel centres, and 100 more near the poles and
    the map's seam) equals Mitsuba 3's envmap eval along them to float32 precision. Detects a
    lookup that is not Mitsuba's bilinear one between texel centres (piecewise constant texels
    differ by about 1% here), the half-turn between the two conventions, rows placed pole to pole
    or centred wrongly, a rotation applied the wrong way, the scale dropped."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from tracer.imageio import write_image
    from tracer.lights import build_lights

    h, w = 64, 128
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    img = np.stack([1 + 0.5 * np.sin(2 * np.pi * u), 1 + np.cos(np.pi * v), 1 + 0.3 * np.sin(4 * np.pi * u) * v], -1)
    write_image(str(tmp_path / "env.exr"), img.astype(np.float32))
    path = _scene(tmp_path, ENV)
    lt = build_lights(tracer.load_scene(path))
    emitter = mi.load_file(path).emitters()[0]
    rng = np.random.default_rng(1)
    d = rng.normal(size=(600, 3))
    d[500:550, 1] = 40.0 * np.sign(d[500:550, 1])  # near the poles
    r = np.array(emitter.world_transform().matrix)[:3, :3]
    d[550:] = (r @ np.array([np.sin(2 * np.pi * 1e-4 * rng.normal(size=50)), rng.uniform(-0.9, 0.9, 50),
                             -np.ones(50)])).T  # across the seam u = 0 of the map's frame
    d /= np.linalg.norm(d, axis=1)[:, None]
    ours = _env_radiance_batch(lt, d)
    si = mi.SurfaceInteraction3f()
    theirs = []
    for x in d:
        si.wi = mi.Vector3f(*(-x))
        theirs.append(np.array(emitter.eval(si)))
    np.testing.assert_allclose(ours, np.array(theirs), rtol=2e-5)


def test_an_8_bit_envmap_is_decoded_from_srgb_as_mitsuba_does(tmp_path):
    """An envmap stored as an 8-bit PNG: the tracer's radiance along 200 random directions equals
    Mitsuba 3's eval (which decodes 8-bit images from sRGB, as for textures). Detects the encoded
    values taken as linear radiance (about 30% too bright in the mid-tones)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from tracer.lights import build_lights

    tracer.write_image(str(tmp_path / "env.png"), np.random.default_rng(2).uniform(0.02, 1.0, (8, 16, 3)))
    path = _scene(tmp_path, ENV.replace("env.exr", "env.png"))
    lt = build_lights(tracer.load_scene(path))
    emitter = mi.load_file(path).emitters()[0]
    d = np.random.default_rng(3).normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    si = mi.SurfaceInteraction3f()
    theirs = []
    for x in d:
        si.wi = mi.Vector3f(*(-x))
        theirs.append(np.array(emitter.eval(si)))
    np.testing.assert_allclose(_env_radiance_batch(lt, d), np.array(theirs), rtol=2e-5)


# --- what it does not read, and bad input --------------------------------------------------------
def test_unused_properties_and_plugins_are_one_line_each(tmp_path):
    """A property nothing reads is one warning naming its file and line (three shapes with it: one
    line, 'and 2 more'); an unknown shape plugin, 0.6's `sky` alone and a projector emitter one line each."""
    body = "".join(f"""<shape type="rectangle"><float name="bogus" value="{k}"/>
        <transform name="to_world"><translate x="{k}"/></transform></shape>\n""" for k in range(3))
    body += """<shape type="hair"/>\n<emitter type="sky"/>\n<emitter type="projector"/>"""
    path = _scene(tmp_path, body)
    spec = read_mitsuba_scene(path, None)
    lines = (tmp_path / "scene.xml").read_text().splitlines()
    said = {k: [w for w in spec.warnings if k in w] for k in ("'bogus'", "'hair'", "'sky'", "'projector'")}
    assert all(len(v) == 1 for v in said.values()), spec.warnings
    assert "and 2 more" in said["'bogus'"][0] and "alone is not supported" in said["'sky'"][0]
    for k, (w,) in said.items():
        file, line = w.split(":")[:2]
        assert file == path and k.strip("'") in lines[int(line) - 1], (w, lines[int(line) - 1])


BAD = {
    "malformed": ('<shape type="rectangle"><bsdf type="diffuse"></shape>', "not valid XML"),
    "mesh": ('<shape type="ply"><string name="filename" value="gone.ply"/></shape>',
             "shape file 'gone.ply' not found"),
    "texture": ('<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" type="bitmap">'
                '<string name="filename" value="gone.png"/></texture></bsdf></shape>',
                "texture 'gone.png' not found"),
    "ref": ('<shape type="rectangle"><ref id="Nowhere"/></shape>', "no bsdf with id 'Nowhere'"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, case):
    """Malformed XML, a missing mesh or texture, a ref to nothing: one line on stderr naming the file
    and line, exit 2, before any rendering. --allow-missing renders past a missing mesh, warning."""
    from tests.test_cli import fails_with, run_cli

    body, what = BAD[case]
    path = _scene(tmp_path, body)
    line = (tmp_path / "scene.xml").read_text().splitlines().index(f"    {body}") + 1
    fails_with(capsys, [path, "--quiet"], f"scene.xml:{line}:", what)
    if case == "mesh":
        code, _, err = run_cli(capsys, path, "--allow-missing", "--spp", "1", "-o", tmp_path / "o.exr", "--quiet")
        assert code == 0 and "gone.ply" in err, err


@pytest.mark.skipif(not os.path.isdir(SHARED), reason="../shared/scenes-mitsuba not present")
def test_a_shared_0_6_scene_loads_and_renders():
    """The bathroom (0.6 dialect, 850 OBJ files, plastics, a mask, bitmaps) loads with no error and
    no warning but the trilinear filter's, and renders 1 spp at 32 x 18 finite and lit."""
    scene = tracer.load_scene(os.path.join(SHARED, "bathroom", "scene.xml"), width=32, height=18)
    said = [w for w in scene.warnings if "zero-area" not in w]
    assert len(said) == 1 and "trilinear" in said[0], said
    r = tracer.render(scene, spp=1, seed=0)
    assert r.stats["nonfinite_samples"] == 0 and r.image.mean() > 0


@pytest.mark.skipif(not os.path.isdir(SHARED), reason="../shared/scenes-mitsuba not present")
def test_mitsuba_loads_the_copies_of_the_shared_0_6_scenes(tmp_path):
    """bench.vs_mitsuba's copy of a 0.6 scene (which Mitsuba 3 rejects as published) loads in
    Mitsuba 3 at the size asked for, and its conductors' eta and k (extEta folded in) are the values
    the tracer's reader gives the same BSDFs (detects the two sides reading a scene differently)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    import xml.etree.ElementTree as ET

    from bench.vs_mitsuba import mitsuba_copy
    from tracer import bsdfs

    for name in ("spaceship",):  # (bench.vs_mitsuba loads all three; one here keeps the suite short)
        path = os.path.join(SHARED, name, "scene.xml")
        copy, notes = mitsuba_copy(path, str(tmp_path), size=(40, 30))
        assert "conductor extEta folded into eta and k" in notes
        assert list(mi.load_file(copy).sensors()[0].film().size()) == [40, 30]
        spec = read_mitsuba_scene(path, None)
        ours = {m[0]: m[2] for m in spec.materials if m[1] == bsdfs.METAL}
        checked = 0
        for top in ET.parse(copy).getroot().findall("bsdf"):
            el = next((c for c in top.iter("bsdf") if c.get("type") in ("conductor", "roughconductor")), None)
            eta = [c for c in el if c.get("name") == "eta"] if el is not None else []
            k = [c for c in el if c.get("name") == "k"] if el is not None else []
            if eta and k and top.get("id") in ours:  # (a conductor given by its material name is not rewritten)
                got = [float(x) for x in (eta[0].get("value") + ", " + k[0].get("value")).split(",")]
                np.testing.assert_allclose(got, ours[top.get("id")][8:14], rtol=1e-6)
                checked += 1
        assert checked >= 1, name
