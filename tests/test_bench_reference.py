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
