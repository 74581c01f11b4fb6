"""A time budget is kept by every method: learning, inference, the passes and gpt's solve end within
2% of it (equal-time comparisons assume each method spends the same time); a denoised render's
filter counts in it too.

time_total is the budget's clock (render(): from the accel's build to the finished image, the
kernels' compile left out). Before the last pass was cut at the deadline, photon and odis ended
6-9% past a 10 s budget and the others 1-3% short of it (the last pass was sized by an older pass's
speed, and the budget's end was never checked between waves). Measured here on the idle 2-core VM:
within 0.6% for every method at 5 s; at 2.5 s every method here stays within the 2%.

A method keeps its budget if one of TRIES renders ends within the 2%: a systematic miss (a last
pass sized wrong, a reserve too short for the work after the passes, as the 2.55-2.56 s GradNet
and 2.53-2.54 s denoised renders here were before AFTER_PASSES_SECONDS) misses in every render,
while a shared machine stalls one render now and then (two CI runs on a busy host ended one
render at 2.55-2.58 s). Two test runs at once oversubscribe Numba's threads on every render, and
fail it."""
import pytest

import tracer
from tracer import denoise
from tests.test_cli import CORNELL

BUDGET = 2.5
TRIES = 3  # renders a method gets to keep the budget once
# one method per way of spending a budget: grid runs photon's schedule, gpt-l2 reserves its solve as
# gpt-l1 does (bench/summary/all_methods/ shows every method's time at 2, 5 and 12 s)
METHODS = {"bsdf": {}, "photon": {"guide": "photon"}, "pss": {"guide": "pss"},
           "odis": {"guide": "odis"}, "ppg": {"guide": "ppg"},
           "gpt-l1": {"integrator": "gpt", "recon": "l1"}, "gpt-gradnet": {"integrator": "gpt", "recon": "gradnet"},
           "bsdf+oidn": {"denoise": True}}


@pytest.mark.parametrize("method", list(METHODS))
def test_time_budget_is_kept(method):
    if METHODS[method].get("denoise") and not denoise.available():
        pytest.skip("pyoidn (the denoise extra) is not installed")
    scene = tracer.load_scene(CORNELL, width=96, height=96)
    missed = []
    for _ in range(TRIES):
        r = tracer.render(scene, time=BUDGET, **METHODS[method])
        st = r.stats
        assert st["nonfinite_samples"] == 0 and not st["interrupted"]
        assert st["spp"] >= 1 and st["spp_mean"] >= st["spp"]
        if abs(st["time_total"] - BUDGET) <= 0.02 * BUDGET:
            return
        missed.append((st["time_total"], st["passes"][-3:]))
    raise AssertionError(f"{method} missed a {BUDGET} s budget by more than 2% in {TRIES} renders: {missed}")


def test_a_budget_too_short_still_gives_every_pixel_two_samples():
    """The deadline never cuts a final film before each pixel has 2 samples (a film with fewer gets
    no weight when the passes are combined, a pixel with none is black): a budget shorter than
    that overruns instead. gpt's base film gets at least one."""
    scene = tracer.load_scene(CORNELL, width=96, height=96)
    for kw, least in (({}, 2), ({"guide": "photon"}, 2), ({"integrator": "gpt"}, 1)):
        r = tracer.render(scene, time=1e-3, **kw)
        assert r.stats["spp"] >= least and r.film.count.min() >= least, (kw, r.stats["spp"])
        assert r.stats["nonfinite_samples"] == 0


def test_a_budget_the_denoiser_spends_is_named(caplog):
    """A budget shorter than the denoiser's time on the image says so before the passes (and that
    the render will overrun it), naming the denoiser's seconds; a budget far longer says nothing.
    Detects the silent 5x overrun of `--time 5 --denoise` on a 720x1280 image (its denoise alone
    took 11 s on the 2-core VM)."""
    if not denoise.available():
        pytest.skip("pyoidn (the denoise extra) is not installed")
    scene = tracer.load_scene(CORNELL, width=32, height=32)
    with caplog.at_level("WARNING", logger="tracer"):
        tracer.render(scene, time=1e-3, denoise=True)
    said = [r.getMessage() for r in caplog.records if "time budget" in r.getMessage()]
    assert len(said) == 1 and "the denoiser" in said[0] and "overrun" in said[0], said
    caplog.clear()
    with caplog.at_level("WARNING", logger="tracer"):
        r = tracer.render(scene, time=1.0, denoise=True)
    assert 2 * r.stats["time_denoise"] < 1.0  # (the denoiser's share of this budget is small)
    assert not [rec for rec in caplog.records if "time budget" in rec.getMessage()]
