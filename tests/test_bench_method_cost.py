"""bench.method_cost: seconds a sample of the passes that make each method's image."""
import json

import pytest

import tracer
from tracer.errors import SettingsError
from bench import method_cost
from tests.test_cli import CORNELL


def test_image_passes_are_told_from_training():
    """cost() keeps the final (or gpt's gradient) passes and leaves a guide's training passes out:
    checked on a photon render against the spp the render itself requested and the time of every
    pass. Detects a training pass counted in the figure (its spp would exceed the final passes')
    or a final pass left out (the spp would not add up)."""
    scene = tracer.load_scene(CORNELL, width=16, height=16)
    st = tracer.render(scene, spp=8, guide="photon", progress=False).stats
    seconds, spp, other = method_cost.cost(st)
    kinds = [p["kind"] for p in st["passes"]]
    assert "final" in kinds and len(set(kinds)) > 1, kinds  # the render has training passes to leave out
    final = [p for p in st["passes"] if p["kind"] == "final"]
    assert spp == sum(p["spp"] for p in final) and 0 < spp < 8
    assert sum(p["spp"] for p in st["passes"] if p["kind"] != "final") == 8 - spp
    assert seconds + other == pytest.approx(sum(p["time"] for p in st["passes"]))


def test_method_cost_table(tmp_path, capsys):
    """The command's records and table: plain path tracing and gpt count every pass (none trains),
    the baseline's ratio is 1, the other's is its figure over the baseline's. Detects a gradient
    pass left out (gpt's spp 0) and a ratio taken the wrong way round."""
    out = tmp_path / "cost.json"
    assert method_cost.main(["--scenes", CORNELL, "--width", "16", "--height", "16", "--spp", "4", "--seeds", "1",
                             "--methods", "bsdf,gpt-l1", "--json", str(out)]) == 0
    rows = json.loads(out.read_text())
    assert [r["method"] for r in rows] == ["bsdf", "gpt-l1"]
    assert all(r["image_spp"] == 4 and r["nonfinite_samples"] == 0 for r in rows)
    text = capsys.readouterr().out
    ratio = rows[1]["seconds_per_spp"] / rows[0]["seconds_per_spp"]
    assert "| cornell | bsdf | 4 |" in text and " | 1.00 | " in text
    assert f"| {ratio:.2f} |" in text


def test_unknown_method_fails_before_rendering(tmp_path):
    """A misspelt method stops the command before any render, naming the name."""
    with pytest.raises((SystemExit, SettingsError), match="nosuch"):
        method_cost.main(["--scenes", CORNELL, "--methods", "bsdf,nosuch", "--json", str(tmp_path / "x.json")])
    assert not (tmp_path / "x.json").exists()
