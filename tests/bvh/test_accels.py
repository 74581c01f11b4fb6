"""Both ray-query backends against the brute-force twin (tests/bvh/naive.py) and each other."""
import sys

import numpy as np
import pytest
import trimesh

from tracer.bvh import ACCELS, make_accel
from tracer.bvh.numba_bvh import NumbaBVH
from tracer.errors import SettingsError
from tests.bvh import naive

# Backends under test: "embree-f32" is Embree without the float64 refinement of closest hits,
# which checks Embree's own float32 answers (and the centre shift that keeps them precise).
BACKENDS = ["numba", "embree", "embree-f32"]
# Per backend: relative tolerance on t, and absolute tolerances (times the scene scale) on t
# and on how close to an edge a ray may pass and be decided either way.
TOL = {"numba": (1e-9, 1e-9, 1e-9), "embree": (1e-9, 1e-9, 1e-5),
       "embree-f32": (1e-4, 1e-5, 1e-5)}


def build(backend, tri, threads=None):
    if backend == "embree-f32":
        from tracer.bvh.embree import EmbreeAccel

        return EmbreeAccel(tri, threads=threads, refine=False)
    return make_accel(backend, tri, threads=threads)


# ---------------------------------------------------------------- scenes and rays

def random_soup(seed=0):
    """~380 triangles in [-1, 1]^3: large, tiny, an edge-sharing height field, and a few with
    zero area."""
    rng = np.random.default_rng(seed)
    large = rng.uniform(-1, 1, (150, 1, 3)) + rng.normal(0, 0.4, (150, 3, 3))
    tiny = rng.uniform(-1, 1, (100, 1, 3)) + rng.normal(0, 1e-3, (100, 3, 3))
    x, z = np.meshgrid(np.linspace(-1, 1, 9), np.linspace(-1, 1, 9), indexing="ij")
    grid = np.stack([x, 0.3 * np.sin(3 * x) * np.cos(2 * z), z], axis=-1)
    a, b, c, d = grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]
    field = np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3),
                            np.stack([a, c, d], -2).reshape(-1, 3, 3)])
    p = rng.uniform(-1, 1, (3, 3))
    degenerate = np.stack([np.stack([p[0], p[0], p[0]]),          # a point
                           np.stack([p[0], p[1], 2 * p[1] - p[0]]),  # collinear
                           np.stack([p[1], p[2], p[1]])])           # repeated vertex
    tri = np.concatenate([large, tiny, field, degenerate])
    return tri[rng.permutation(len(tri))]


def sphere_in_box():
    """An icosphere (320 triangles) inside a closed box (12 triangles)."""
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.0).triangles
    box = trimesh.creation.box(extents=(3.0, 3.0, 3.0)).triangles
    return np.concatenate([sphere, box])


SCENES = {"soup": random_soup, "sphere_in_box": sphere_in_box}


def random_rays(tri, n, seed=1):
    """n rays: half from inside the bounding box in random directions, half from a sphere far
    outside it aimed at random points of the box; directions not normalized."""
    rng = np.random.default_rng(seed)
    lo, hi = tri.reshape(-1, 3).min(0), tri.reshape(-1, 3).max(0)
    centre, radius = (lo + hi) / 2, np.linalg.norm(hi - lo)
    lo, hi = lo - 0.05 * radius, hi + 0.05 * radius  # no origins in a flat scene's plane
    m = n // 2
    org_in = rng.uniform(lo, hi, (m, 3))
    dir_in = rng.normal(size=(m, 3)) * rng.uniform(0.5, 2.0, (m, 1))
    u = rng.normal(size=(n - m, 3))
    org_out = centre + 1.5 * radius * u / np.linalg.norm(u, axis=1, keepdims=True)
    dir_out = rng.uniform(lo, hi, (n - m, 3)) - org_out
    return np.concatenate([org_in, org_out]), np.concatenate([dir_in, dir_out])


def scene_scale(tri):
    v = tri.reshape(-1, 3)
    return np.linalg.norm(v.max(0) - v.min(0))


# ---------------------------------------------------------------- checks

def check_hits(backend, tri, org, dirs, hits, min_hit=0.2):
    """Closest hits `hits` = (t, prim, b1, b2) against the brute-force twin, allowing rays that
    pass within the backend's edge tolerance of an edge to be decided either way."""
    t, prim, b1, b2 = hits
    rtol, atol_t, atol_edge = TOL[backend]
    scale = scene_scale(tri)
    atol_t, grow = atol_t * scale, atol_edge * scale
    T_loose = naive.hit_distances(org, dirs, tri, grow=grow)
    T_strict = naive.hit_distances(org, dirs, tri, grow=-grow)
    first_loose, first_strict = T_loose.min(axis=1), T_strict.min(axis=1)

    assert t.dtype == np.float64 and prim.dtype == np.int32
    assert b1.dtype == np.float64 and b2.dtype == np.float64
    hit = prim >= 0
    # A miss: no triangle is clearly hit.
    assert np.all(np.isinf(t[~hit]))
    assert np.all(np.isinf(first_strict[~hit])), "missed a triangle that is clearly hit"
    # A hit: its triangle is (at least loosely) hit at t, and nothing is clearly nearer.
    i, p = np.nonzero(hit)[0], prim[hit]
    dist = np.abs(dirs[i]).max(axis=1)  # t is in units of |dirs|
    tol = rtol * t[i] + atol_t / dist
    assert np.all(np.isfinite(T_loose[i, p])), "reported a triangle that the ray misses"
    np.testing.assert_array_less(np.abs(t[i] - T_loose[i, p]), tol + 1e-300)
    np.testing.assert_array_less(t[i] - tol, first_strict[i])
    np.testing.assert_array_less(first_loose[i] - tol, t[i])
    # Barycentrics reproduce the hit point.
    v = tri[p]
    q = (1 - b1[i, None] - b2[i, None]) * v[:, 0] + b1[i, None] * v[:, 1] + b2[i, None] * v[:, 2]
    x = org[i] + t[i, None] * dirs[i]
    np.testing.assert_allclose(q, x, rtol=0, atol=10 * (atol_t + grow))
    # Not vacuous: most rays are unambiguous, and there they agree exactly.
    clear = np.isinf(first_loose) == np.isinf(first_strict)
    assert clear.mean() > 0.97
    assert hit.mean() > min_hit


# ---------------------------------------------------------------- tests

@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.parametrize("backend", BACKENDS)
def test_intersect_matches_brute_force(backend, scene):
    tri = SCENES[scene]()
    org, dirs = random_rays(tri, 3000)
    accel = build(backend, tri)
    check_hits(backend, tri, org, dirs, accel.intersect(org, dirs))


@pytest.mark.parametrize("backend", BACKENDS)
def test_intersect_honours_tmax(backend):
    tri = random_soup()
    org, dirs = random_rays(tri, 2000, seed=3)
    t_ref, prim_ref = naive.intersect(org, dirs, tri)
    rng = np.random.default_rng(4)
    # Cut every ray clearly before or clearly after its first hit.
    tmax = np.where(rng.random(len(org)) < 0.5, 0.5, 1.5) * np.where(np.isinf(t_ref), 1, t_ref)
    t, prim, b1, b2 = build(backend, tri).intersect(org, dirs, tmax)
    cut = tmax < t_ref
    assert np.all(t[prim >= 0] < tmax[prim >= 0])
    t_cut, prim_cut = naive.intersect(org[cut], dirs[cut], tri, tmax[cut])
    agree = (prim[cut] == prim_cut) | np.isclose(t[cut], t_cut, rtol=1e-4)
    assert agree.mean() > 0.99
    kept = ~cut & np.isfinite(t_ref)
    assert (prim[kept] == prim_ref[kept]).mean() > 0.99


@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.parametrize("backend", BACKENDS)
def test_occluded_matches_brute_force(backend, scene):
    tri = SCENES[scene]()
    org, dirs = random_rays(tri, 3000, seed=5)
    rng = np.random.default_rng(6)
    rtol, atol_t, atol_edge = TOL[backend]
    scale = scene_scale(tri)
    t_first = naive.hit_distances(org, dirs, tri).min(axis=1)
    t_first = np.where(np.isinf(t_first), 1.0, t_first)
    kind = rng.integers(0, 4, len(org))
    tmax = np.select([kind == 0, kind == 1, kind == 2],
                     [t_first * rng.uniform(0.2, 2.0, len(org)),      # around the first hit
                      t_first * np.where(rng.random(len(org)) < 0.5, 1 - 1e-3, 1 + 1e-3),
                      np.full(len(org), np.inf)],
                     rng.uniform(0, 1, len(org)))                     # anywhere
    occ = build(backend, tri).occluded(org, dirs, tmax)
    assert occ.dtype == np.bool_ and occ.shape == (len(org),)
    # Occluded for sure: a triangle clearly hit clearly before tmax; free for sure: none
    # even loosely hit before tmax (plus tolerance). In between, either answer is right.
    slack = rtol * np.minimum(tmax, 1e30) + atol_t * scale / np.abs(dirs).max(axis=1)
    T_strict = naive.hit_distances(org, dirs, tri, grow=-atol_edge * scale)
    T_loose = naive.hit_distances(org, dirs, tri, grow=atol_edge * scale)
    must = (T_strict < (tmax - slack)[:, None]).any(axis=1)
    may = (T_loose < (tmax + slack)[:, None]).any(axis=1)
    assert np.all(occ[must])
    assert not np.any(occ[~may])
    assert must.mean() > 0.05 and (~may).mean() > 0.2


def test_backends_agree():
    """Embree and the Numba BVH on a bigger scene: same hits, same triangles but at ties."""
    rng = np.random.default_rng(7)
    sphere = trimesh.creation.icosphere(subdivisions=4).triangles          # 5120, shared edges
    soup = rng.uniform(-0.7, 0.7, (3000, 1, 3)) + rng.normal(0, 0.05, (3000, 3, 3))
    tri = np.concatenate([sphere, soup])
    org, dirs = random_rays(tri, 50_000, seed=8)
    a, b = make_accel("embree", tri), make_accel("numba", tri)
    t_a, p_a, u_a, v_a = a.intersect(org, dirs)
    t_b, p_b, u_b, v_b = b.intersect(org, dirs)
    assert (p_a >= 0).mean() > 0.5
    assert ((p_a >= 0) == (p_b >= 0)).mean() > 0.999
    both = (p_a >= 0) & (p_b >= 0)
    np.testing.assert_allclose(t_a[both], t_b[both], rtol=1e-4)
    same = p_a == p_b
    assert same.mean() > 0.999
    np.testing.assert_allclose(u_a[same & both], u_b[same & both], atol=1e-6)
    tmax = rng.uniform(0, 2, len(org))
    assert (a.occluded(org, dirs, tmax) == b.occluded(org, dirs, tmax)).mean() > 0.999


@pytest.mark.parametrize("backend", BACKENDS)
def test_far_from_origin(backend):
    """Geometry and rays offset by 1e4: Embree's float32 stays precise (centre shift)."""
    offset = np.array([1e4, -2e4, 1.5e4])
    tri = sphere_in_box() + offset
    org, dirs = random_rays(tri, 2000, seed=9)
    check_hits(backend, tri, org, dirs, build(backend, tri).intersect(org, dirs))


@pytest.mark.parametrize("backend", BACKENDS)
def test_threads_give_the_same_answer(backend):
    tri = random_soup()
    org, dirs = random_rays(tri, 60_000, seed=10)
    tmax = np.random.default_rng(11).uniform(0, 2, len(org))
    one, many = build(backend, tri, threads=1), build(backend, tri, threads=2)
    for x, y in zip(one.intersect(org, dirs), many.intersect(org, dirs)):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(one.occluded(org, dirs, tmax), many.occluded(org, dirs, tmax))


@pytest.mark.parametrize("backend", BACKENDS)
def test_empty_batch(backend):
    accel = build(backend, random_soup())
    t, prim, b1, b2 = accel.intersect(np.zeros((0, 3)), np.zeros((0, 3)))
    assert t.shape == prim.shape == b1.shape == b2.shape == (0,)
    assert accel.occluded(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)).shape == (0,)


@pytest.mark.parametrize("backend", BACKENDS)
def test_bad_rays_miss(backend):
    """Zero, NaN and inf directions or origins: a miss, never a crash; good rays unaffected."""
    tri = sphere_in_box()
    org = np.array([[0.1, 0.2, 0.0], [0.1, 0.2, 0.0], [np.nan, 0, 0], [0, 0, np.inf],
                    [0.1, 0.2, 0.0]])
    dirs = np.array([[0.0, 0.0, 0.0], [np.nan, 0, 1], [0, 0, 1], [0, 0, -1], [0.0, 0.0, 1.0]])
    accel = build(backend, tri)
    t, prim, b1, b2 = accel.intersect(org, dirs)
    assert np.all(prim[:4] == -1) and np.all(np.isinf(t[:4]))
    assert prim[4] >= 0 and abs(t[4] - naive.intersect(org[4:], dirs[4:], tri)[0][0]) < 1e-4
    occ = accel.occluded(org, dirs, np.full(5, np.inf))
    np.testing.assert_array_equal(occ, [False, False, False, False, True])


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("case", ["one", "same_centroid", "coplanar", "empty"])
def test_degenerate_inputs(backend, case):
    rng = np.random.default_rng(12)
    if case == "one":
        tri = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    elif case == "same_centroid":
        # 40 triangles, all with centroid (0.2, 0.1, 0): SAH cannot split them.
        off = rng.normal(size=(40, 3, 3))
        tri = off - off.mean(axis=1, keepdims=True) + [0.2, 0.1, 0.0]
    elif case == "coplanar":
        # A flat (zero-thickness) BVH: 200 triangles in the plane z = 0.5.
        tri = rng.uniform(-1, 1, (200, 1, 3)) + rng.normal(0, 0.1, (200, 3, 3))
        tri[..., 2] = 0.5
    else:
        tri = np.zeros((0, 3, 3))
    accel = build(backend, tri)
    repr(accel)
    if case == "empty":
        org, dirs = random_rays(np.ones((1, 3, 3)), 100)
        assert np.all(accel.intersect(org, dirs)[1] == -1)
        assert not accel.occluded(org, dirs, np.full(100, np.inf)).any()
        return
    org, dirs = random_rays(tri, 2000, seed=13)
    check_hits(backend, tri, org, dirs, accel.intersect(org, dirs), min_hit=0.05)


def test_numba_tree_invariants():
    tri = random_soup()
    bvh = NumbaBVH(tri)
    nodes, count = bvh.nodes, bvh.nodes[:, 7].astype(int)
    assert np.array_equal(np.sort(bvh.order), np.arange(len(tri)))
    assert count.max() <= 4 and count.sum() == len(tri)
    for node in np.nonzero(count == 0)[0]:
        for child in (node + 1, int(nodes[node, 6])):
            assert np.all(nodes[child, :3] >= nodes[node, :3])
            assert np.all(nodes[child, 3:6] <= nodes[node, 3:6])
    for node in np.nonzero(count > 0)[0]:
        first = int(nodes[node, 6])
        v = tri[bvh.order[first:first + count[node]]].reshape(-1, 3)
        assert np.all(v.min(0) >= nodes[node, :3]) and np.all(v.max(0) <= nodes[node, 3:6])


@pytest.mark.parametrize("backend", ACCELS)
def test_attributes(backend):
    tri = sphere_in_box()
    accel = make_accel(backend, tri, threads=2)
    assert accel.name == backend and accel.threads == 2
    np.testing.assert_allclose(accel.bounds, [[-1.5] * 3, [1.5] * 3])
    np.testing.assert_allclose(accel.scale, 3 * np.sqrt(3))
    text = repr(accel)
    assert backend in text and "triangles=332" in text and "threads=2" in text


def test_unknown_accel_is_a_settings_error():
    with pytest.raises(SettingsError, match="embree, numba"):
        make_accel("nope", random_soup())


def test_missing_embreex_is_a_settings_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "embreex", None)
    monkeypatch.delitem(sys.modules, "tracer.bvh.embree", raising=False)
    with pytest.raises(SettingsError, match="--accel numba"):
        make_accel("embree", random_soup())


def test_packets_with_invalid_lanes_and_ragged_tails():
    """Embree traces 16 rays a call: every packet here mixes bad rays (zero, NaN, negative tmax)
    with good ones, and batches of 1 to 40 rays end in partial packets. Each ray must get the
    answer it gets alone (a lane's result written to another lane, or a tail lane left stale,
    shows as a mismatch)."""
    from tracer.bvh.embree import EmbreeAccel

    tri = sphere_in_box()
    rng = np.random.default_rng(4)
    accel = EmbreeAccel(tri, threads=1)
    for n in (1, 15, 16, 17, 40):
        org = rng.uniform(-0.3, 0.3, (n, 3))
        dirs = rng.normal(size=(n, 3))
        tmax = rng.uniform(0.1, 3.0, n)
        bad = rng.uniform(size=n) < 0.3
        dirs[bad & (rng.uniform(size=n) < 0.5)] = 0.0
        org[bad & (rng.uniform(size=n) < 0.5), 0] = np.nan
        tmax[bad & (rng.uniform(size=n) < 0.3)] = -1.0
        t, prim, b1, b2 = accel.intersect(org, dirs)
        occ = accel.occluded(org, dirs, tmax)
        for i in range(n):
            ti, pi, _, _ = accel.intersect(org[i:i + 1], dirs[i:i + 1])
            assert prim[i] == pi[0] and (t[i] == ti[0] or np.isinf(t[i]) and np.isinf(ti[0]))
            assert occ[i] == accel.occluded(org[i:i + 1], dirs[i:i + 1], tmax[i:i + 1])[0]
        good = np.isfinite(org).all(axis=1) & (np.abs(dirs).sum(axis=1) > 0)
        want_p = naive.intersect(org[good], dirs[good], tri)[1]
        np.testing.assert_array_equal(prim[good], want_p)
        assert np.all(prim[~good] == -1)


def test_plane_tables_and_bounds_against_numpy():
    """The one-pass plane tables (v0, n, the dual vectors) and bounds equal a numpy twin bit for
    bit, degenerate and non-finite triangles included (any changed formula or summation order
    shows)."""
    from tracer.bvh import _bounds
    from tracer.bvh.embree import _plane_tables

    rng = np.random.default_rng(5)
    tri = rng.normal(size=(5000, 3, 3)) * 10.0 ** rng.integers(-4, 4, (5000, 1, 1)) + rng.normal(size=(5000, 1, 3))
    tri[3, 2] = tri[3, 0]
    tri[7, 1, 1] = np.nan
    tri[9, 0, 2] = np.inf
    v0 = tri[:, 0]
    with np.errstate(invalid="ignore"):  # the non-finite triangles
        e1, e2 = tri[:, 1] - v0, tri[:, 2] - v0
        n = np.cross(e1, e2)
        nn = np.einsum("ij,ij->i", n, n)
        ok = (nn > 0) & np.isfinite(nn)
        inv = np.where(ok, 1.0 / np.where(ok, nn, 1.0), 0.0)[:, None]
        want = np.concatenate([v0, n, np.cross(e2, n) * inv, np.cross(n, e1) * inv], axis=1)
    want[~ok] = 0.0
    np.testing.assert_array_equal(_plane_tables(tri), want)
    v = tri.reshape(-1, 3)
    v = v[np.isfinite(v).all(axis=1)]
    bounds, scale = _bounds(tri)
    np.testing.assert_array_equal(bounds, np.stack([v.min(0), v.max(0)]))
    assert scale == float(np.linalg.norm(bounds[1] - bounds[0]))
    empty_box, empty_scale = _bounds(np.full((2, 3, 3), np.nan))
    assert np.all(empty_box == 0.0) and empty_scale == 1.0
