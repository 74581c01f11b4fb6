"""The render split over Dask workers (tracer.distributed): segments merged in seed order, resumed from a
folder, refused when they disagree or were rendered otherwise. Skipped without `distributed`."""
import os

import numpy as np
import pytest

import tracer
from tracer import distributed
from tracer.testing.stats import assert_clean, assert_z

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORNELL = os.path.join(ROOT, "scenes", "cornell", "cornell.obj")
SIZE, SPP, N = 24, 24, 4


def _in_process(scene, seeds, spp):
    """[(seed, segment)] rendered here, as the workers would: the same seeds and spp shares."""
    out = []
    for s, n in zip(seeds, distributed.split_spp(spp, len(seeds))):
        r = tracer.render(scene, spp=n, seed=s)
        out.append((s, {"image": r.image, "variance": r.variance, "aovs": r.aovs, "stats": r.stats}))
    return out


def test_merge_weights_by_spp_and_refuses_a_segment_that_disagrees():
    """merge_segments against formulas written here: the mean weighted by spp, the variance of the mean
    by the squared weights, the AOVs weighted as the mean; a segment brighter by 20 standard errors
    is refused naming its seed, and one within its noise is merged (with its z recorded)."""
    g = np.random.default_rng(2)
    h, w = 8, 6
    base = g.random((h, w, 3)) + 0.5
    var = np.full((h, w, 3), 1e-4)

    def seg(spp, shift=0.0):
        img = base + shift + g.normal(scale=np.sqrt(var))
        return {"image": img, "variance": var.copy(), "aovs": {"albedo": img * 0.5},
                "stats": {"spp": spp, "spp_mean": float(spp), "time_total": 1.0, "interrupted": False}}

    a, b = seg(4), seg(12)
    mean, v, aovs, recs = distributed.merge_segments([(7, b), (3, a)])
    np.testing.assert_allclose(mean, 0.25 * a["image"] + 0.75 * b["image"])
    np.testing.assert_allclose(v, 0.0625 * var + 0.5625 * var)
    np.testing.assert_allclose(aovs["albedo"], 0.25 * a["aovs"]["albedo"] + 0.75 * b["aovs"]["albedo"])
    assert [r["seed"] for r in recs] == [3, 7] and "z" in recs[1]
    se = np.sqrt(2 * 1e-4 / (h * w))
    with pytest.raises(distributed.SegmentError, match=r"segment seed 9 .* disagrees"):
        distributed.merge_segments([(3, a), (9, seg(4, shift=20 * se))])


@pytest.fixture(scope="module")
def cluster_run(tmp_path_factory):
    """One 4-worker LocalCluster render of the Cornell box (24x24, 24 spp) with a segments folder, and
    the scene."""
    pytest.importorskip("distributed")
    scene = tracer.load_scene(CORNELL, width=SIZE, height=SIZE)
    folder = tmp_path_factory.mktemp("dask") / "segments"
    r = tracer.render(scene, spp=SPP, seed=20, workers=N, segments_dir=str(folder))
    return scene, r, folder


def test_a_cluster_render_is_the_merge_of_the_same_seeds_rendered_here(cluster_run):
    """The 4-worker render equals, bit for bit, the merge of seeds 20..23 rendered in this process with
    the same spp shares (a render is a function of its settings), and its image mean equals a single
    24-spp render's with another seed (z-test per channel on both variances). Detects a segment
    rendered with the wrong seed or spp, merged out of order or with the wrong weights, a worker's
    settings lost on the way; its stats count every segment's samples, and the folder is gone."""
    scene, r, folder = cluster_run
    assert_clean(r, "dask")
    mean, var, aovs, recs = distributed.merge_segments(_in_process(scene, range(20, 20 + N), SPP))
    np.testing.assert_array_equal(r.image, mean.astype(np.float32))
    np.testing.assert_array_equal(r.variance, var.astype(np.float32))
    np.testing.assert_array_equal(r.aovs["albedo"], aovs["albedo"].astype(np.float32))
    assert [s["seed"] for s in r.stats["segments"]] == [20, 21, 22, 23]
    assert r.stats["spp"] == SPP and r.stats["samples"] == SPP * SIZE * SIZE and not r.stats["interrupted"]
    one = tracer.render(scene, spp=SPP, seed=99)
    npix = SIZE * SIZE
    d = r.image.reshape(-1, 3).mean(axis=0) - one.image.reshape(-1, 3).mean(axis=0)
    v = (r.variance.reshape(-1, 3).sum(axis=0) + one.variance.reshape(-1, 3).sum(axis=0)) / npix ** 2
    assert_z(d, v, np.zeros(3), n_tests=3, what="cluster - single render, image mean")
    assert not folder.exists()


def test_a_stopped_run_resumes_from_its_segments(cluster_run, tmp_path, caplog):
    """Two of the four segments left in the folder by a run that was stopped (written as the client
    writes them): the next run renders the other two only and gives the same image as the whole run;
    a stored segment rendered with another spp is one error naming its file and the setting."""
    scene, r, _ = cluster_run
    folder = tmp_path / "segments"
    folder.mkdir()
    kept = _in_process(scene, [20, 21, 22, 23], SPP)[:2]
    for (s, seg), n in zip(kept, distributed.split_spp(SPP, N)):
        key = _key(scene, s, n)
        distributed._store(str(folder), key, seg)
    with caplog.at_level("INFO", logger="tracer"):
        again = tracer.render(scene, spp=SPP, seed=20, workers=N, segments_dir=str(folder))
    assert any("2 of 4 segments already rendered" in m for m in caplog.messages), caplog.messages
    np.testing.assert_array_equal(again.image, r.image)
    assert not folder.exists()
    folder.mkdir()
    distributed._store(str(folder), _key(scene, 20, 5), kept[0][1])
    with pytest.raises(distributed.SegmentError, match=r"seed_20\.npz: rendered with other settings: spp 5"):
        tracer.render(scene, spp=SPP, seed=20, workers=N, segments_dir=str(folder))


def _key(scene, seed, spp):
    """The settings a segment of render(scene, spp=SPP, seed=20, workers=N) is stored with."""
    return {"scene": os.path.abspath(scene.path), "width": scene.width, "height": scene.height, "spp": spp,
            "time": None, "seed": seed, "guide": "bsdf{}", "integrator": "path", "max_depth": None,
            "rr_depth": None, "pixel_filter": "box", "crop": None}


def test_settings_that_cannot_be_split_are_one_error():
    """gpt, a callback, fewer samples than workers and a bad worker count are refused before any
    cluster starts."""
    pytest.importorskip("distributed")
    scene = tracer.load_scene(CORNELL, width=8, height=8)
    for kw, what in ((dict(integrator="gpt"), "gpt is not split"), (dict(callback=lambda *a: True), "callback"),
                     (dict(workers=0), "workers must be a whole number"), (dict(workers=9), "8 spp cannot be split")):
        with pytest.raises(tracer.SettingsError, match=what):
            tracer.render(scene, spp=8, **dict(dict(workers=2), **kw))


def test_ctrl_c_writes_the_merged_image_so_far(tmp_path):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it) during a 2-worker CLI render: the
    workers stop after their pass in flight, the client merges what they return and writes it (exit
    130, stats interrupted, both segments with fewer spp than asked), and no stopped segment is kept
    for a resume (the folder is gone). Detects a Ctrl-C that kills the workers (no image), or one
    that stores a cut segment as finished."""
    import json
    import re
    import select
    import signal
    import subprocess
    import sys
    import time

    pytest.importorskip("distributed")
    out = tmp_path / "k.exr"
    p = subprocess.Popen([sys.executable, "-m", "tracer", CORNELL, "--spp", "200000", "--width", "32", "--height", "32",
                          "--workers", "2", "-o", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT,
                         start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    err = b""
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:  # until the bar counts samples from both workers
            if select.select([p.stderr], [], [], 1.0)[0]:
                chunk = os.read(p.stderr.fileno(), 4096)
                assert chunk, f"tracer ended before rendering: {err.decode(errors='replace')}"
                err += chunk
                if any(int(n) >= 8 for n in re.findall(rb"(\d+)/200000 spp", err)):
                    break
        else:
            pytest.fail(f"no progress within the deadline: {err.decode(errors='replace')}")
        os.killpg(p.pid, signal.SIGINT)
        _, rest = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    err = (err + rest).decode(errors="replace")
    assert p.returncode == 130 and "Traceback" not in err and (tmp_path / "k.json").is_file(), err
    stats = json.loads((tmp_path / "k.json").read_text())
    assert stats["interrupted"] is True and stats["nonfinite_samples"] == 0
    assert [s["seed"] for s in stats["segments"]] == [0, 1] and all(s["interrupted"] for s in stats["segments"])
    assert 8 <= stats["spp"] < 200000 and stats["samples"] >= stats["spp"] * 32 * 32
    img = tracer.read_image(out)
    assert img.shape == (32, 32, 3) and np.isfinite(img).all() and img.mean() > 0
    assert not (tmp_path / "k.segments").exists()


def test_local_cluster_workers_keep_this_process_malloc_settings():
    """A worker of distributed.local_cluster has this process's MALLOC_TRIM_THRESHOLD_ (normally
    none), not the 65536 Dask's nanny sets by default, which turns off glibc's dynamic mmap
    threshold and made gpt-l1's solve 2.3x slower in a worker. Detects a cluster made without
    local_cluster's setting (or a Dask release that sets it some other way)."""
    pytest.importorskip("distributed")
    from distributed import Client

    own = os.environ.get("MALLOC_TRIM_THRESHOLD_")  # (a nanny sets it here too as it spawns a worker)
    with distributed.local_cluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0") as c, \
            Client(c) as client:
        seen = client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))
    assert list(seen.values()) == [own], seen
