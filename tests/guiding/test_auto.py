"""`--guide auto` (tracer.guiding.auto): the sampler that picks itself from a trial of each candidate."""
import numpy as np
import pytest

import tracer
from tests import scenes
from tests.guiding.test_guides import ROOT
from tracer.errors import SettingsError
from tracer.film import Film
from tracer.guiding import make_guide
from tracer.guiding.auto import EPS, trial_costs
from tracer.testing.stats import assert_clean, assert_z, image_mean


def test_trial_cost_is_relative_variance_per_sample_times_seconds_per_spp():
    """trial_costs on films of known per-sample spread: film a's samples are m +- s (each sign
    with probability 1/2: variance s^2), film b's m +- 2s, s = 0.3 m, with m a different constant
    in each channel (so the 3 x 3 blur of the stand-in reference leaves it unbiased); both took 4
    spp, a at 1 s per spp and b at 0.25. relvar must be the mean over channels of s^2 / (m^2 +
    EPS) (b's four times it), z-tested with the spread of the per-pixel terms; cost relvar x
    seconds per spp. Detects variance of the mean taken for the variance of a sample (4x too
    small), a wrong sample-variance denominator (n for n - 1: 25%), a reference that holds each
    pixel's own outliers (a plain per-pixel mean: relvar 6% off here), and seconds per pass taken for
    seconds per spp."""
    rng = np.random.default_rng(5)
    w, h, spp = 64, 32, 4
    m = np.tile([0.1, 0.5, 1.5], (h * w, 1))
    s = 0.3 * m
    films = {}
    for name, k in (("a", 1.0), ("b", 2.0)):
        f = films[name] = Film(w, h)
        for _ in range(spp):
            sign = rng.choice([-1.0, 1.0], m.shape)
            f.add(np.arange(h * w, dtype=np.int64), m + sign * k * s, np.zeros((h * w, f.aov.shape[1])))
    entries = {"a": {"spp": spp, "time": 4.0}, "b": {"spp": spp, "time": 1.0}}
    out = trial_costs(films, entries)
    for name, k, sec in (("a", 1.0, 1.0), ("b", 2.0, 0.25)):
        terms = (films[name].variance().reshape(-1, 3) * spp / (m * m + EPS)).ravel()
        expect = float(np.mean((k * s) ** 2 / (m * m + EPS)))
        assert_z(out[name]["relvar"], np.var(terms) / terms.size, expect, n_tests=2, what=f"relvar of film {name}")
        assert out[name]["seconds_per_spp"] == sec
        assert out[name]["cost"] == pytest.approx(out[name]["relvar"] * sec)


@pytest.mark.parametrize("bad", ["bsdf+foo", "grid+grid", "", "pss"])
def test_candidates_are_checked(bad):
    with pytest.raises(SettingsError, match="candidates must be distinct names from bsdf, grid, photon, ppg"):
        make_guide("auto", candidates=bad)


@pytest.mark.parametrize("in_image", [0, 1])
def test_auto_renders_with_the_candidate_its_trials_predict_and_keeps_the_mean(in_image):
    """On the ajar box: a pilot, a trial per candidate (bsdf 4 spp, each guide its iterations of 2
    and 4 spp), then the winner's Algorithm 1 from iteration 3 (a guide) or final passes (bsdf).
    The winner is the least predicted cost of the trials in the stats, the losers' trial films
    get no weight in the image (with trials_in_image 1 they do), and the image's mean agrees with
    a BSDF render's (z-test). Detects a winner other than the argmin, losers' films weighed in
    (or left out with trials_in_image), a guide restarting Algorithm 1 from its pilot, and a
    biased image."""
    scene = scenes.builtin(ROOT, "ajar", 48, 36)
    g = make_guide("auto", trials_in_image=in_image)
    r = tracer.render(scene, spp=96, guide=g, seed=303 + in_image)
    assert_clean(r, "auto on ajar")
    st = r.stats["guide_stats"]
    trials = st["trials"]
    assert list(trials) == ["bsdf", "grid", "photon", "ppg"]
    assert st["choice"] == min(trials, key=lambda n: trials[n]["cost"]), trials
    kinds = [p["kind"] for p in r.stats["passes"]]
    assert kinds[:8] == ["pilot"] + ["trial"] * 7 and kinds[-1] == "final"
    assert "pilot" not in kinds[1:] and [p["spp"] for p in r.stats["passes"][1:8]] == [4, 2, 4, 2, 4, 2, 4]
    weighted = [p for p in r.stats["passes"][1:8] if p.get("weight", 0) > 0]
    if st["choice"] != "bsdf":
        assert st["training"]["spp"][:2] == [2, 4] and st["training"]["trained"] >= 2
        assert kinds[8] == "train" or st["training"]["stopped"]
    if in_image and not st.get("chosen", {}).get("switched_off"):  # (switched off: training films all out)
        assert len(weighted) > 2, r.stats["passes"][1:8]
    else:
        assert len(weighted) <= (1 if st["choice"] == "bsdf" else 2), r.stats["passes"][1:8]
    assert r.stats["spp"] == 96
    b = tracer.render(scene, spp=96, seed=304)
    m_a, v_a = image_mean(r)
    m_b, v_b = image_mean(b)
    assert_z(m_a, v_a + v_b, m_b, n_tests=2, what="auto vs bsdf on ajar")


@pytest.mark.parametrize("candidates", ["photon", "bsdf+photon"])
def test_auto_with_one_guide_learns_from_the_pilot(candidates):
    """Each guide that auto may pick learns from the pilot and its own trial: with candidates
    bsdf+photon forced to photon (the only guide) its maps exist, it continued past its trial, and
    the mean holds (z-test against BSDF sampling). A single candidate runs as itself, no trial.
    Detects a guide that never saw the pilot's records (no maps) and a biased image."""
    scene = scenes.builtin(ROOT, "cornell", 32, 32)
    g = make_guide("auto", candidates=candidates)
    r = tracer.render(scene, spp=64, guide=g, seed=7)
    assert_clean(r, f"auto:{candidates}")
    st = r.stats["guide_stats"]
    kinds = [p["kind"] for p in r.stats["passes"]]
    if candidates == "photon":
        assert st["choice"] == "photon" and "trial" not in kinds and st["why"] == "the only candidate"
    else:
        assert kinds.count("trial") == 3
    if st["choice"] == "photon":
        assert st["chosen"]["voxels_with_map"] > 0
    b = tracer.render(scene, spp=64, seed=8)
    m_a, v_a = image_mean(r)
    m_b, v_b = image_mean(b)
    assert_z(m_a, v_a + v_b, m_b, n_tests=2, what=f"auto:{candidates} vs bsdf")


def test_too_few_spp_for_the_trials_render_bsdf_and_say_so():
    """8 spp cannot hold the pilot, the trials (4 + 3 x (2 + 4) spp) and a final pass of 8: auto
    renders BSDF sampling, final passes only, and says why."""
    scene = scenes.builtin(ROOT, "cornell", 16, 16)
    r = tracer.render(scene, spp=8, guide="auto", seed=1)
    st = r.stats["guide_stats"]
    assert st["choice"] == "bsdf" and "fewer than the 31" in st["why"]
    assert [p["kind"] for p in r.stats["passes"]] == ["final"] * len(r.stats["passes"])
    assert r.stats["spp"] == 8
