"""bench.convergence end to end on a tiny scene: records, charts and the summary table."""
import json
import os

import pytest

from bench import common, convergence, reference
from tests import scenes


def test_convergence_writes_records_charts_and_table(tmp_path, monkeypatch):
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=8, height=8)
    ref_dir = tmp_path / "ref"
    monkeypatch.setattr(reference, "default_out", lambda path: str(ref_dir))
    monkeypatch.setattr(common, "default_out", lambda path: str(ref_dir))
    assert reference.main([obj, "--spp", "64", "--out", str(ref_dir)]) == 0
    out = tmp_path / "conv"
    assert convergence.main(["--scenes", obj, "--time", "0.05,0.1", "--spp", "1,2", "--seeds", "2",
                             "--out", str(out), "--workers", "0"]) == 0
    recs = [json.loads(line) for line in open(out / "records.jsonl")]
    assert len(recs) == 2 * 2 + 2 * 2  # seeds x time budgets + seeds x spp budgets, one method
    r = recs[0]
    assert {"relMSE", "MSE", "MrSE", "1-SSIM"} <= set(r["metrics"]) and r["method"] == "bsdf"
    assert r["time_rendering"] <= r["time_total"] and r["guide_memory_bytes"] == 0
    assert r["scene"] == "box"
    for r in recs:  # every camera sample of the 8 x 8 image is counted, and bsdf has no guide time
        if r["budget"] == "spp":
            assert r["samples"] == r["spp"] * 64
        else:  # spp is the least per pixel: a last pass cut at the deadline adds samples to some pixels
            assert r["spp"] * 64 <= r["samples"] < (r["spp"] + 64) * 64
        assert 0 < r["shade_s"] < r["time_total"]
        assert r["update_s"] == r["inference_s"] == r["time_learning"] == 0.0
    assert not [f for f in os.listdir(out) if ".tmp-" in f]  # every output renamed into place
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
    monkeypatch.setattr(common, "default_out", lambda path: str(ref_dir))
    assert reference.main([obj, "--spp", "16", "--out", str(ref_dir)]) == 0
    out = tmp_path / "conv"
    assert convergence.main(["--scenes", obj, "--time", "0.05", "--seeds", "2", "--out", str(out), "--workers", "0"]) == 0
    return out, ref_dir


def test_a_run_on_other_scenes_keeps_the_stored_records(tmp_path, monkeypatch):
    """A sweep given other --scenes than the records in --out already hold adds to them: the
    records of the scenes it was not given stay in records.jsonl (they were once dropped when
    the summary, which covers the given scenes only, was written)."""
    out, _ = _box_run_at_one_time_budget(tmp_path, monkeypatch)
    box = scenes.closed_box(tmp_path / "other", 0.5, 1.0, width=8, height=8)
    other = os.path.join(os.path.dirname(box), "other.obj")  # the same box under another name
    os.rename(box, other)
    assert convergence.main(["--scenes", other, "--time", "0.05", "--seeds", "1", "--out", str(out),
                             "--workers", "0"]) == 0
    recs = [json.loads(line) for line in open(out / "records.jsonl")]
    by_scene = {s: sum(r["scene"] == s for r in recs) for s in {r["scene"] for r in recs}}
    assert by_scene == {"box": 2, "other": 1}
    assert "## other" in (out / "summary.md").read_text()


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
    assert convergence.main(["--rescore", "--out", str(out), "--workers", "0"]) == 0
    after = [json.loads(line) for line in open(out / "records.jsonl")]
    assert len(after) == len(before)
    for b, a in zip(before, after):
        image = np.load(out / "images" / "box" / a["image"])
        assert a["metrics"] == metrics.all_metrics(image, data[:, :, :3])
        assert a["metrics"]["relMSE"] > b["metrics"]["relMSE"]  # the image is about half the new reference
        assert {k: v for k, v in a.items() if k != "metrics"} == {k: v for k, v in b.items() if k != "metrics"}


def test_update_time_is_the_maps_rebuild():
    """render()'s `guide_time_update` is the histogram guides' map rebuild between passes (part of
    each pass's `time_update`, the whole update call), and `guide_time_inference`, network
    inference, is 0 for them; bench.convergence records them as `update_s` and `inference_s`."""
    import tempfile

    import tracer

    with tempfile.TemporaryDirectory() as d:
        scene = tracer.load_scene(scenes.closed_box(d, 0.5, 1.0, width=8, height=8))
    r = tracer.render(scene, spp=8, guide="grid", seed=3)
    s = r.stats
    updates = sum(p.get("time_update", 0.0) for p in s["passes"])
    assert [p["kind"] for p in s["passes"] if "time_update" in p][:2] == ["pilot", "train"]
    assert 0.0 < s["guide_time_update"] <= updates
    assert s["guide_time_learning"] > 0.0 and s["guide_time_inference"] == 0.0
    # learning is what observe (inside the passes) and the first part of update cost
    assert s["guide_time_learning"] + s["guide_time_update"] <= updates + sum(p["time"] for p in s["passes"])
    assert "time_inference" not in s and tracer.render(scene, spp=2).stats["guide_time_update"] == 0.0


def _rec(method, t, seed, shade_ns=None, samples=10**6, **extra):
    r = {"scene": "s", "method": method, "seed": seed, "budget": "time", "time_budget": t, "spp": 100,
         "metrics": {"relMSE": 0.1}, "time_learning": 0.5, "guide_memory_bytes": 0, **extra}
    if shade_ns is not None:
        r.update(shade_s=shade_ns * 1e-9 * samples, samples=samples)
    return r


def test_summary_shows_the_guides_shading_cost_over_bsdf():
    """Per time budget: median over seeds of a guide's shade seconds per sample minus bsdf's
    median, in ns; bsdf's row its own; "-" where records lack the figures (runs made before)."""
    recs = [_rec("bsdf", 10, s, ns) for s, ns in enumerate((100, 120, 500))]
    recs += [_rec("grid", 10, s, ns, update_s=0.25, inference_s=0.0) for s, ns in enumerate((200, 210, 900))]
    recs += [_rec("bsdf", 20, 0, 110)]
    recs += [_rec("grid", 20, 0, time_inference=0.32)]  # a record made before update_s and shade_s
    table = convergence.summary_table(recs, ["s"], ["bsdf", "grid"], [10, 20], {"s": 1e-6})
    lines = table.splitlines()
    i = lines.index("| shade ns per sample | 10 s | 20 s |")
    # medians: bsdf 120, grid 210 (means 240 and 437 would give +197)
    assert lines[i + 2:i + 4] == ["| bsdf | 120 | 110 |", "| grid | +90 | - |"]
    assert "| method (at the largest time budget) | spp | learning s | update s | network inference s |" in table
    assert "| grid | 100 | 0.50 | 0.32 | - | 0 |" in table  # an old record's time_inference was its update time
    assert convergence.shade_overhead_ns(recs, "grid", 10) == pytest.approx(90.0)


def test_rescore_reads_records_made_before_update_and_shade_times(tmp_path, monkeypatch):
    """Records stored before `update_s`, `inference_s`, `shade_s` and `samples` existed (the update
    time under `time_inference`) are scored again; the figures they lack show as "-"."""
    out, _ = _box_run_at_one_time_budget(tmp_path, monkeypatch)
    recs = [json.loads(line) for line in open(out / "records.jsonl")]
    old = []
    for r in recs:
        for m in ("bsdf", "grid"):  # a guided method, so that the guide tables are made
            o = {k: v for k, v in r.items() if k not in ("update_s", "inference_s", "shade_s", "samples")}
            old.append(dict(o, method=m, time_inference=0.25))
    (out / "records.jsonl").write_text("".join(json.dumps(r) + "\n" for r in old))
    assert convergence.main(["--rescore", "--out", str(out), "--workers", "0"]) == 0
    table = (out / "summary.md").read_text()
    assert "| grid | - |" in table and "| bsdf | - |" in table  # shading cost unknown
    assert "| 0.25 | - |" in table  # update s from time_inference, network inference unknown
    after = [json.loads(line) for line in open(out / "records.jsonl")]
    assert [{k: v for k, v in a.items() if k != "metrics"} for a in after] == \
        [{k: v for k, v in o.items() if k != "metrics"} for o in old]
