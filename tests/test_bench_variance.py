"""bench.variance on a tiny scene: the per-sample relative variance it reports."""
import numpy as np

from bench import common, convergence, reference, variance
from tests import scenes
from tracer.film import N_AOV, Film


def test_relative_variance_is_the_one_sample_relmse():
    f = Film(2, 1)
    # pixel 0: samples 1 and 3 (sample variance 2); pixel 1: 0 and 0
    f.add(np.array([0, 0, 1, 1]), np.array([[1.0] * 3, [3.0] * 3, [0.0] * 3, [0.0] * 3]), np.zeros((4, N_AOV)))
    ref = np.array([[[2.0] * 3, [0.0] * 3]])
    assert np.isclose(variance.relative_variance(f, ref, 2), (2.0 / 4.01 + 0.0) / 2)


def test_variance_bench_runs_bsdf_and_a_frozen_guide(tmp_path, monkeypatch, capsys):
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=8, height=8)
    ref_dir = tmp_path / "ref"
    monkeypatch.setattr(common, "default_out", lambda path: str(ref_dir))
    assert reference.main([obj, "--spp", "16", "--out", str(ref_dir)]) == 0
    assert variance.main(["--scenes", obj, "--methods", "photon", "--spp", "4", "--train-spp", "4",
                          "--seeds", "2", "--scale", "2"]) == 0
    rows = _rows(capsys.readouterr().out)
    assert [r[1] for r in rows] == ["bsdf", "photon"]  # bsdf first, added when not asked for
    for r in rows:  # mean, standard error, min, max of the two seeds' figures (printed to 3 digits)
        seeds = np.array([float(v) for v in r[9:]])
        assert len(seeds) == 2 and np.all(np.isfinite(seeds))
        np.testing.assert_allclose([float(v) for v in r[2:6]],
                                   [seeds.mean(), seeds.std(ddof=1) / np.sqrt(2), seeds.min(), seeds.max()],
                                   rtol=0.01, atol=1e-3 * seeds.mean())
    assert rows[0][6] == "1.00"  # ratio to bsdf
    # seconds per spp, and the equal-time ratio (relative variance x seconds per spp) to bsdf
    assert rows[0][8] == "1.00" and all(float(r[7]) > 0 and np.isfinite(float(r[8])) for r in rows)


def _rows(out):
    lines = out.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("scene"))
    assert lines[head].split()[2:9] == ["mean", "+-sem", "min", "max", "vs", "bsdf", "s/spp"]
    return [line.split() for line in lines[head + 1:]]


def test_summarise_is_the_mean_with_its_standard_error():
    mean, sem, lo, hi = variance.summarise([1.0, 1.0, 1.0, 1.0, 11.0])
    assert (mean, lo, hi) == (3.0, 1.0, 11.0)  # the median, 1, would hide the heavy seed
    assert np.isclose(sem, np.sqrt((4 * 2.0**2 + 8.0**2) / 4) / np.sqrt(5))  # = 2
    assert np.isnan(variance.summarise([0.5])[1])


def test_ratio_and_efficiency_come_from_the_means(tmp_path, monkeypatch, capsys):
    """A method with one heavy seed: its median beats bsdf, its mean does not. The table's ratio
    and efficiency must be those of the means."""
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=8, height=8)
    ref_dir = tmp_path / "ref"
    monkeypatch.setattr(common, "default_out", lambda path: str(ref_dir))
    assert reference.main([obj, "--spp", "4", "--out", str(ref_dir)]) == 0
    figures = {"bsdf": [(1.0, 0.01)] * 4, "photon": [(0.5, 0.02)] * 3 + [(4.5, 0.02)]}
    monkeypatch.setattr(variance, "measure", lambda scene, ref, m, *a: figures[m])
    assert variance.main(["--scenes", obj, "--methods", "photon", "--seeds", "4"]) == 0
    bsdf, photon = _rows(capsys.readouterr().out)
    assert bsdf[2:9] == ["1", "0", "1", "1", "1.00", "0.0100", "1.00"]
    # photon: mean 1.5 (median 0.5), standard error sd 2 / sqrt(4) = 1; ratio 1.5; x 2 the time: 3
    assert photon[2:9] == ["1.5", "1", "0.5", "4.5", "1.50", "0.0200", "3.00"]
    assert photon[9:] == ["0.5", "0.5", "0.5", "4.5"]
