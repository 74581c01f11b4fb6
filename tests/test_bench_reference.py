"""bench.reference: merging independent renders keeps the estimate unbiased and its variance right."""
import numpy as np

from bench import reference


def test_merge_weights_by_spp():
    m, v = reference.merge(np.array([1.0]), np.array([0.4]), 100, np.array([2.0]), np.array([0.1]), 300)
    np.testing.assert_allclose(m, [1.75])
    np.testing.assert_allclose(v, [0.25**2 * 0.4 + 0.75**2 * 0.1])


def test_merged_variance_matches_pooled_samples():
    g = np.random.default_rng(0)
    a, b = g.normal(3, 2, 1000), g.normal(3, 2, 3000)
    m, v = reference.merge(a.mean(), a.var(ddof=1) / a.size, a.size, b.mean(), b.var(ddof=1) / b.size, b.size)
    both = np.concatenate([a, b])
    np.testing.assert_allclose(m, both.mean())
    np.testing.assert_allclose(v, both.var(ddof=1) / both.size, rtol=0.05)


def test_append_run_end_to_end(tmp_path):
    import os

    scene = os.path.join(reference.ROOT, "scenes", "cornell", "cornell.obj")
    out = tmp_path / "ref"
    assert reference.main([scene, "--spp", "2", "--out", str(out)]) == 0
    m1, v1, meta1 = reference.load(out)
    assert reference.main([scene, "--spp", "2", "--out", str(out), "--append"]) == 0
    m2, v2, meta2 = reference.load(out)
    assert meta2["spp"] == 4 and meta2["seeds"] == [1000, 1001]
    assert meta2["noise_floor_relmse"] < meta1["noise_floor_relmse"]


def test_bias_z_is_the_channel_mean_over_its_standard_error():
    g = np.random.default_rng(1)
    ref = g.uniform(1, 2, (10, 20, 3))
    image = ref + np.array([0.01, 0.0, -0.1])
    var, ref_var = np.full_like(ref, 0.04), np.full_like(ref, 0.05)
    n = 200
    se = np.sqrt(n * (0.04 + 0.05)) / n  # the standard error of the mean over n pixels: 0.0212
    np.testing.assert_allclose(reference.bias_z(image, var, ref, ref_var), [0.01 / se, 0.0, -0.1 / se], atol=1e-9)
    # Sidak over 3 channels at 1%: each test at 1 - 0.99^(1/3), two-sided: |z| < 2.93
    from scipy import stats
    zc = stats.norm.isf((1 - 0.99 ** (1 / 3)) / 2)
    assert np.isclose(reference.z_threshold(3), zc)
    assert reference.agreement(image, var, ref, ref_var)[0] is False  # blue: z = -4.7
    image[..., 2] = ref[..., 2] - 0.06  # z = -2.83: inside
    ok, z, _ = reference.agreement(image, var, ref, ref_var)
    assert ok is True and np.isclose(z[2], -0.06 / se)


def _git(*args):
    import subprocess

    return subprocess.run(["git", "-C", reference.ROOT, *args], capture_output=True, text=True,
                          check=True).stdout.strip()


def _box_reference(tmp_path, emission=1.0, name="a"):
    from tests import scenes

    return scenes.closed_box(tmp_path / name, 0.5, emission, width=16, height=16)


def test_append_refuses_a_segment_that_disagrees_and_writes_nothing(tmp_path):
    """A segment of a changed scene (its light 5% brighter: about 11 standard errors on this box)
    is refused: exit with a one-line message naming the folder and the z-scores; the stored
    files are untouched, and no temporary file is left behind."""
    import os

    import pytest

    out = tmp_path / "ref"
    assert reference.main([_box_reference(tmp_path), "--spp", "16", "--out", str(out)]) == 0
    before = {f: (out / f).read_bytes() for f in os.listdir(out)}
    brighter = _box_reference(tmp_path, 1.05, "b")
    with pytest.raises(SystemExit) as e:
        reference.main([brighter, "--spp", "16", "--out", str(out), "--append"])
    msg = str(e.value.code)
    assert "\n" not in msg and str(out) in msg and "disagrees" in msg and "z (R, G, B) = +" in msg
    assert {f: (out / f).read_bytes() for f in os.listdir(out)} == before
    # --force merges it anyway and marks the segment
    assert reference.main([brighter, "--spp", "16", "--out", str(out), "--append", "--force"]) == 0
    seg = reference.load(out)[2]["segments"][-1]
    assert seg["forced"] is True and min(seg["z"]) > reference.z_threshold(3)


def test_append_accepts_a_segment_of_the_same_scene_and_records_the_segments(tmp_path):
    import json

    obj = _box_reference(tmp_path)
    out = tmp_path / "ref"
    assert reference.main([obj, "--spp", "16", "--out", str(out)]) == 0
    m1, v1, _ = reference.load(out)
    assert reference.main([obj, "--spp", "8", "--out", str(out), "--append"]) == 0
    m2, v2, meta = reference.load(out)
    segs = meta["segments"]
    assert [(s["seed"], s["spp"]) for s in segs] == [(1000, 16), (1001, 8)] and meta["spp"] == 24
    assert abs(sum(s["seconds"] for s in segs) - meta["seconds"]) <= 0.1
    # the commit of this repository, -dirty when tracked files differ from it
    dirty = bool(_git("--no-optional-locks", "status", "--porcelain", "--untracked-files=no"))
    assert all(s["commit"] == _git("rev-parse", "HEAD") + ("-dirty" if dirty else "") for s in segs)
    assert all(len(s["date"]) == len("2026-01-01 00:00") for s in segs)
    # the check's z-scores are kept and were below the threshold; the merge is the spp-weighted one
    z = np.array(segs[1]["z"])
    assert z.shape == (3,) and np.all(np.abs(z) < reference.z_threshold(3))
    new = (m2 * 24 - m1 * 16) / 8  # the appended segment's mean, recovered from the merge
    np.testing.assert_allclose(reference.bias_z(new, (v2 * 24**2 - v1 * 16**2) / 8**2, m1, v1), z, atol=2e-3)
    # a reference made before segments were kept: one segment synthesized from its old fields
    old = {k: v for k, v in meta.items() if k != "segments"}
    (out / "reference.json").write_text(json.dumps(old))
    assert reference.main([obj, "--spp", "8", "--out", str(out), "--append"]) == 0
    segs = reference.load(out)[2]["segments"]
    assert segs[0]["seeds"] == [1000, 1001] and segs[0]["spp"] == 24 and segs[0]["commit"] == "unknown"
    assert segs[1]["seed"] == 1002 and segs[1]["spp"] == 8 and reference.load(out)[2]["spp"] == 32


def test_segments_are_merged_in_seed_order_through_the_check(tmp_path):
    """--segments 3 (rendered in this process here, --workers 0; bench.sweep runs them on Dask
    otherwise): three seeds merged one by one, each z-checked against what was stored before it,
    into exactly the reference that three appends of one seed each make. Detects a segment merged
    twice or lost, a wrong weighting, a skipped check, and segment files left behind."""
    import os

    obj = _box_reference(tmp_path)
    a, b = tmp_path / "ref_a", tmp_path / "ref_b"
    assert reference.main([obj, "--spp", "4", "--out", str(a), "--segments", "3", "--workers", "0"]) == 0
    assert reference.main([obj, "--spp", "4", "--out", str(b)]) == 0
    for _ in range(2):
        assert reference.main([obj, "--spp", "4", "--out", str(b), "--append"]) == 0
    ma, va, meta_a = reference.load(a)
    mb, vb, meta_b = reference.load(b)
    np.testing.assert_array_equal(ma, mb)
    np.testing.assert_array_equal(va, vb)
    assert meta_a["seeds"] == meta_b["seeds"] == [1000, 1001, 1002] and meta_a["spp"] == 12
    assert [len(s.get("z", [])) for s in meta_a["segments"]] == [0, 3, 3]
    assert sorted(os.listdir(a)) == ["reference.exr", "reference.json", "reference.png"]
