"""bench.sweep_memory: the worker's RSS per cell and its growth per quarter."""
import json
import os

import numpy as np

from bench import sweep_memory

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_growth_is_the_slope_of_each_quarter_after_the_warm_up():
    """growth() against slopes computed here: 20 warm-up cells left out, then four quarters of a
    list whose slope changes at known cells. Detects a warm-up counted in (its 500 MB jump) or a
    quarter's slope divided by the wrong count."""
    rss = [100.0] * 5 + [600.0] * 15 + list(600.0 + np.concatenate([np.arange(41) * 1.0, 40 + np.arange(1, 41) * 0.5]))
    g = sweep_memory.growth(rss)
    np.testing.assert_allclose(g, [1.0, 1.0, 0.5, 0.5])


def test_a_run_in_this_process_writes_one_rss_per_cell(tmp_path):
    """Three cells (bsdf, photon, bsdf) on the Cornell box against its reference, in this process:
    the JSON holds three resident sizes (MB, finite, above 50: a Python with the tracer loaded)."""
    out = tmp_path / "m.json"
    assert sweep_memory.main(["--scene", os.path.join(ROOT, "scenes", "cornell", "cornell.obj"), "--methods",
                              "bsdf,photon", "--cells", "3", "--time", "0.3", "--workers", "0", "--out", str(out)]) == 0
    rec = json.loads(out.read_text())
    assert len(rec["rss_mb"]) == 3 and all(np.isfinite(rec["rss_mb"])) and min(rec["rss_mb"]) > 50
    assert rec["peak_mb"] == max(rec["rss_mb"]) and len(rec["growth_mb_per_cell"]) == 4
