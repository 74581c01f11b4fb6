"""bench.robustness in a tiny configuration: passes on a correct render, fails on bias or NaN."""
import numpy as np
import pytest

import tracer
from bench import common, convergence, reference, robustness
from tests import scenes


@pytest.fixture()
def box(tmp_path, monkeypatch):
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=48, height=48)
    ref_dir = tmp_path / "ref"
    monkeypatch.setattr(common, "default_out", lambda path: str(ref_dir))
    assert reference.main([obj, "--spp", "256", "--out", str(ref_dir)]) == 0
    return obj, ref_dir


def test_correct_render_passes(box, capsys):
    obj, _ = box
    assert robustness.main(["--scenes", obj, "--methods", "bsdf", "--spp", "4", "--crop", "32"]) == 0
    out = capsys.readouterr().out
    assert "bsdf" in out and "<-" not in out


def test_biased_reference_is_caught(box, capsys):
    obj, ref_dir = box
    m, v, meta = reference.load(ref_dir)
    tracer.write_image(ref_dir / "reference.exr", np.concatenate([m * 1.05, v], axis=2))
    assert robustness.main(["--scenes", obj, "--methods", "bsdf", "--spp", "4", "--crop", "32"]) == 1
    assert "biased" in capsys.readouterr().out


def test_non_finite_pixels_are_caught(box, monkeypatch, capsys):
    obj, _ = box
    real = tracer.render

    def broken(*a, **k):
        r = real(*a, **k)
        r.image[0, 0, 0] = np.nan
        return r

    monkeypatch.setattr(tracer, "render", broken)
    assert robustness.main(["--scenes", obj, "--methods", "bsdf", "--spp", "4", "--crop", "32"]) == 1
    assert "<- NaN/inf pixels" in capsys.readouterr().out


def test_non_finite_samples_are_caught(box, monkeypatch, capsys):
    """The integrator zeroes a NaN/inf sample before the film, so the image stays finite: the
    render's `nonfinite_samples` count is what must fail the run, and it is the row's figure."""
    obj, _ = box
    real = tracer.render

    def counted(*a, **k):
        r = real(*a, **k)
        r.stats["nonfinite_samples"] = 3
        return r

    monkeypatch.setattr(tracer, "render", counted)
    row = robustness.check(obj, "bsdf", 4, 7, 32)
    assert row["nonfinite_samples"] == 3 and row["nonfinite_pixels"] == 0
    assert robustness.main(["--scenes", obj, "--methods", "bsdf", "--spp", "4", "--crop", "32"]) == 1
    lines = capsys.readouterr().out.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("scene"))
    assert "NaN/inf samples" in lines[head]
    cols = lines[head + 1].split()
    assert cols[1] == "bsdf" and cols[3] == "0" and cols[4] == "3"  # NaN/inf pixels, NaN/inf samples
    assert lines[head + 1].endswith("<- NaN/inf samples")


def test_a_method_that_loses_at_equal_time_fails_the_run(box, monkeypatch, capsys):
    """--time adds each method's mean relMSE at equal time; a method whose ratio to bsdf's is above
    --max-ratio fails the run and is named in the worst-ratio table (here the equal-time renders
    are stood in for: grid made 1.5x and photon 0.5x bsdf's error)."""
    obj, _ = box
    factor = {"bsdf": 1.0, "grid": 1.5, "photon": 0.5}

    def timed(scene_name, method, budget, seeds, scene_dir=None):
        assert budget == 2.0 and seeds == [7, 8]
        return {"relMSE_time": 0.01 * factor[method], "spp_time": 10.0, "nonfinite_time": 0}

    monkeypatch.setattr(robustness, "equal_time", timed)
    args = ["--scenes", obj, "--spp", "4", "--crop", "32", "--time", "2", "--seeds", "2"]
    assert robustness.main(args + ["--methods", "bsdf,photon"]) == 0
    assert "photon       0.50" in capsys.readouterr().out
    assert robustness.main(args + ["--methods", "bsdf,grid,photon"]) == 1
    out = capsys.readouterr().out
    assert "grid         1.50" in out and "<- loses to bsdf" in out
