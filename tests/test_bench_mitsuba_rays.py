"""bench.mitsuba_rays' counter of the rays Mitsuba 3 hands its Embree, checked against counts that
Mitsuba's path integrator fixes by construction."""
import shutil

import pytest

from bench import mitsuba_rays, scenes

pytest.importorskip("mitsuba")
pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")


def test_the_counter_counts_every_ray_mitsuba_traces(tmp_path, monkeypatch):
    """At max_depth 1 Mitsuba's `path` traces the camera ray and nothing else: exactly one
    closest-hit ray a sample and no shadow ray. At max_depth 2 it adds one bounce ray and at most
    one shadow ray a sample (the open scene's camera rays that miss end at once). Detects a counter
    that misses an entry point (0 counted), counts calls of inactive lanes, or counts a call twice.
    (The scalar variant calls the one-ray entry points; the LLVM variant's 16-wide ones go through
    the same counting.)"""
    monkeypatch.setattr(scenes, "FOLDER", str(tmp_path))
    lib = mitsuba_rays.build(str(tmp_path))
    job = dict(spec=scenes.open_scene(1), spp=2, width=8, height=8, rr_depth=5, variant="scalar_rgb")
    n = 8 * 8 * 2

    def totals(max_depth):
        return mitsuba_rays.totals(mitsuba_rays.mitsuba_counts(lib, dict(job, max_depth=max_depth)))

    assert totals(1) == (n, 0)
    hits, shadows = totals(2)
    assert n < hits <= 2 * n and 0 < shadows <= n
