"""bench.scenes' open scene and bench.throughput's per-stage run on it."""
import json

import numpy as np

import tracer
import tracer.readers.obj
from bench import scenes, throughput


def test_open_scene_files(tmp_path, monkeypatch):
    """The open scene at 1 subdivision: 80 sphere triangles plus floor and light; the one-material
    parts (Mitsuba's input) hold the same triangles as the scene OBJ; the light
    faces down and the camera sees the sphere (a render's mean is positive and finite)."""
    monkeypatch.setattr(scenes, "FOLDER", str(tmp_path))
    spec = scenes.open_scene(1)
    scene = tracer.load_scene(spec["obj"], width=24, height=24)
    assert scene.n_triangles == 84
    parts = [tracer.readers.obj.read_geometry(p)[0] for p, _, _ in spec["parts"]]
    # the scene's material groups come in reverse order of first use (tracer.objread)
    np.testing.assert_array_equal(np.concatenate(parts[::-1]), scene.tri)
    light = scene.tri[scene.emissive]
    n = np.cross(light[:, 1] - light[:, 0], light[:, 2] - light[:, 0])
    assert np.all(n[:, 1] < 0)
    r = tracer.render(scene, spp=4, max_depth=8, rr_depth=5)
    assert r.stats["nonfinite_samples"] == 0 and 0 < r.image[..., :3].mean() < np.inf
    assert scenes.open_scene(1) == spec  # the second call reuses the files


def test_throughput_rows(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(scenes, "FOLDER", str(tmp_path))
    monkeypatch.setitem(throughput.NAMED, "open-tiny", lambda: scenes.open_scene(1))
    out = tmp_path / "rows.json"
    assert throughput.main(["--scenes", "open-tiny", "--accels", "embree", "--spp", "1", "--repeat", "1",
                            "--width", "16", "--height", "16", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "open-tiny [embree] 16x16 1 spp" in text
    assert "| open-tiny | embree |" in text  # the per-stage table
    rows = json.loads(out.read_text())
    assert rows[0]["triangles"] == 84 and rows[0]["rays_per_sample"] >= 1.0
