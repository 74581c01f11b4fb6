"""bench.convergence end to end on a tiny scene: records, charts and the summary table."""
import json
import os

from bench import convergence, reference
from tests import scenes


def test_convergence_writes_records_charts_and_table(tmp_path, monkeypatch):
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=8, height=8)
    ref_dir = tmp_path / "ref"
    monkeypatch.setattr(reference, "default_out", lambda path: str(ref_dir))
    monkeypatch.setattr(convergence, "default_out", lambda path: str(ref_dir))
    assert reference.main([obj, "--spp", "64", "--out", str(ref_dir)]) == 0
    out = tmp_path / "conv"
    assert convergence.main(["--scenes", obj, "--time", "0.05,0.1", "--spp", "1,2", "--seeds", "2",
                             "--out", str(out)]) == 0
    recs = [json.loads(line) for line in open(out / "records.jsonl")]
    assert len(recs) == 2 * 2 + 2 * 2  # seeds x time budgets + seeds x spp budgets, one method
    r = recs[0]
    assert {"relMSE", "MSE", "MrSE", "1-SSIM"} <= set(r["metrics"]) and r["method"] == "bsdf"
    assert r["time_rendering"] <= r["time_total"] and r["guide_memory_bytes"] == 0
    assert r["scene"] == "box"
    assert os.path.isfile(out / "box_time.png") and os.path.isfile(out / "box_spp.png")
    table = (out / "summary.md").read_text()
    assert "| bsdf |" in table and "(1.00)" in table
    assert "## box" in table and "Reference: noise floor" in table


def test_reference_floor_check():
    recs = [{"metrics": {"relMSE": e}} for e in (0.5, 0.02, 0.3)]
    assert convergence.floor_check(recs, 0.001) == (True, 0.02)
    assert convergence.floor_check(recs, 0.005)[0] is False


def _box_run_at_one_time_budget(tmp_path, monkeypatch):
    """A 16-spp reference of a tiny closed box and a bsdf run at 0.05 s, 2 seeds: (out, ref_dir)."""
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=8, height=8)
    ref_dir = tmp_path / "ref"
    monkeypatch.setattr(convergence, "default_out", lambda path: str(ref_dir))
    assert reference.main([obj, "--spp", "16", "--out", str(ref_dir)]) == 0
    out = tmp_path / "conv"
    assert convergence.main(["--scenes", obj, "--time", "0.05", "--seeds", "2", "--out", str(out)]) == 0
    return out, ref_dir


def test_default_spp_budgets_do_not_rerun_bsdf(tmp_path, monkeypatch):
    """Without --spp the spp budgets are bsdf's own spp at each time budget: bsdf is not rendered
    again at them, its time runs are its points on the spp chart."""
    out, ref_dir = _box_run_at_one_time_budget(tmp_path, monkeypatch)
    recs = [json.loads(line) for line in open(out / "records.jsonl")]
    assert [r["budget"] for r in recs] == ["time", "time"]
    x, med, lo, hi = convergence._band(recs, "bsdf", "spp")
    assert x.tolist() == [float(sorted(r["spp"] for r in recs)[0] + sorted(r["spp"] for r in recs)[1]) / 2]
    assert lo[0] <= med[0] <= hi[0]
    assert os.path.isfile(out / "box_spp.png")


def test_method_specs_carry_guide_settings():
    assert convergence.method_spec("photon") == ("photon", {})
    assert convergence.method_spec("photon:mixing=variance,sigma=2") == ("photon", {"mixing": "variance", "sigma": 2})
    import pytest
    from tracer.errors import SettingsError
    with pytest.raises(SettingsError, match="no setting 'colour'"):
        convergence.main(["--scenes", "cornell", "--methods", "bsdf,photon:colour=red", "--out", "/nonexistent"])


def test_rescore_scores_the_stored_images_against_the_current_reference(tmp_path, monkeypatch):
    """--rescore renders nothing: it reads each run's stored image and scores it again, so a
    reference extended later judges the runs already made."""
    import numpy as np

    import tracer
    from tracer import metrics

    out, ref_dir = _box_run_at_one_time_budget(tmp_path, monkeypatch)
    before = [json.loads(line) for line in open(out / "records.jsonl")]
    # A different reference: twice the radiance, no variance
    data = tracer.read_image(str(ref_dir / "reference.exr")).astype(np.float64)
    data[:, :, :3] *= 2.0
    data[:, :, 3:] = 0.0
    tracer.write_image(str(ref_dir / "reference.exr"), data, channel_names=reference.CHANNELS)
    assert convergence.main(["--rescore", "--out", str(out)]) == 0
    after = [json.loads(line) for line in open(out / "records.jsonl")]
    assert len(after) == len(before)
    for b, a in zip(before, after):
        image = np.load(out / "images" / "box" / a["image"])
        assert a["metrics"] == metrics.all_metrics(image, data[:, :, :3])
        assert a["metrics"]["relMSE"] > b["metrics"]["relMSE"]  # the image is about half the new reference
        assert {k: v for k, v in a.items() if k != "metrics"} == {k: v for k, v in b.items() if k != "metrics"}
