"""bench.variance on a tiny scene: the per-sample relative variance it reports."""
import numpy as np

from bench import convergence, reference, variance
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
    monkeypatch.setattr(convergence, "default_out", lambda path: str(ref_dir))
    assert reference.main([obj, "--spp", "16", "--out", str(ref_dir)]) == 0
    assert variance.main(["--scenes", obj, "--methods", "photon", "--spp", "4", "--train-spp", "4",
                          "--seeds", "2", "--scale", "2"]) == 0
    lines = capsys.readouterr().out.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("scene"))
    rows = [line.split() for line in lines[head + 1:]]
    assert [r[1] for r in rows] == ["bsdf", "photon"]  # bsdf first, added when not asked for
    assert rows[0][3] == "1.00" and all(np.isfinite(float(r[2])) for r in rows)
    # seconds per spp, and the equal-time ratio (relative variance x seconds per spp) to bsdf
    assert rows[0][5] == "1.00" and all(float(r[4]) > 0 and np.isfinite(float(r[5])) for r in rows)
