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
                            "--width", "16", "--height", "16", "--path-loops", "thread,wave", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "open-tiny [embree, thread] 16x16 1 spp" in text and "open-tiny [embree, wave] 16x16 1 spp" in text
    assert "| open-tiny | embree | thread |" in text  # the per-stage table
    rows = json.loads(out.read_text())
    assert [r["path_loop"] for r in rows] == ["thread", "wave"]
    assert rows[0]["triangles"] == 84 and rows[0]["rays_per_sample"] >= 1.0
    # the same paths either way: the same rays per sample; each loop leaves the other's stages at 0
    assert rows[0]["rays_per_sample"] == rows[1]["rays_per_sample"]
    assert rows[0]["stages"]["intersect"] == 0 and rows[0]["stages"]["shade"] == 0
    assert rows[1]["stages"]["trace"] == 0


def test_throughput_writes_its_records_without_json(tmp_path, monkeypatch, capsys):
    """Without --json the records go to bench/results/throughput.json (here a temporary RESULTS),
    whole, and the run says where. Detects a run that writes nothing unless asked."""
    monkeypatch.setattr(scenes, "FOLDER", str(tmp_path / "scenes"))
    monkeypatch.setattr(throughput, "RESULTS", str(tmp_path / "results"))
    monkeypatch.setitem(throughput.NAMED, "open-tiny", lambda: scenes.open_scene(1))
    assert throughput.main(["--scenes", "open-tiny", "--accels", "embree", "--spp", "1", "--repeat", "1",
                            "--width", "8", "--height", "8"]) == 0
    out = tmp_path / "results" / "throughput.json"
    assert f"records: {out}" in capsys.readouterr().out
    rows = json.loads(out.read_text())
    assert len(rows) == 1 and rows[0]["width"] == 8 and rows[0]["spp"] == 1
    assert [f.name for f in out.parent.iterdir()] == ["throughput.json"]  # no temporary file left


def test_worker_renders_in_its_own_process(tmp_path, monkeypatch):
    """bench.throughput --vs-mitsuba's worker protocol, our side: the child loads the scene, says
    it is ready with the scene's size, then renders once per seed sent, and each reply counts
    the samples the job asked for (16 x 16 x 2) and the rays its render traced."""
    monkeypatch.setattr(scenes, "FOLDER", str(tmp_path))
    spec = scenes.open_scene(1)
    job = dict(scene=spec["obj"], spp=2, max_depth=4, rr_depth=3, width=16, height=16, threads=1, path_loop="thread")
    w = throughput._Worker("ours", job)
    try:
        assert (w.info["width"], w.info["height"], w.info["triangles"]) == (16, 16, 84)
        for seed in (0, 1):
            r = w.render(seed)
            assert r["samples"] == 16 * 16 * 2 and r["rays"] >= r["samples"] and r["seconds"] > 0
            assert r["stages"]["trace"] > 0 and r["stages"]["intersect"] == 0
    finally:
        w.close()


def test_embree_rate_captures_the_lanes_rays(tmp_path, monkeypatch):
    """bench.embree_rate --path-loop lanes: the capture holds every ray the lane engine traced (as
    many closest-hit and shadow rays as the same render counts in its stats), unit directions, and
    origins inside the scene's bounds less the accel's centre. Detects a capture that falls out of
    step with the kernels' signatures (it wraps lanes.intersect and lanes.occlude), loses rays, or
    keeps the ray of the render's warm-up path (one closest-hit ray too many)."""
    from bench import embree_rate

    monkeypatch.setattr(scenes, "FOLDER", str(tmp_path))
    spec = scenes.open_scene(1)
    n, ns = embree_rate.capture(spec["obj"], 1, str(tmp_path), "lanes")
    scene = tracer.load_scene(spec["obj"])
    st = tracer.render(scene, spp=1, max_depth=8, rr_depth=5, path_loop="lanes").stats
    assert (n, ns) == (st["camera_and_bounce_rays"], st["shadow_rays"]) and ns > 0
    name = embree_rate.label(spec["obj"])
    ray = np.fromfile(tmp_path / f"{name}.ray", np.float32).reshape(-1, 6)
    sh = np.fromfile(tmp_path / f"{name}.shadow", np.float32).reshape(-1, 7)
    assert len(ray) == n and len(sh) == ns
    np.testing.assert_allclose(np.linalg.norm(ray[:, 3:], axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(sh[:, 3:6], axis=1), 1.0, atol=1e-5)
    c = 0.5 * (scene.bounds[0] + scene.bounds[1])
    lo, hi = scene.bounds[0] - c - 1e-3, scene.bounds[1] - c + 1e-3
    inside = np.all((sh[:, :3] >= lo) & (sh[:, :3] <= hi), axis=1)
    assert inside.all() and np.all(sh[:, 6] > 0)
