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
    seconds per spp. Detects variance of the mean taken for the variance of a sample (4x too small),
    a wrong sample-variance denominator (n for n - 1: 25%), a stand-in reference that holds the
    films' outliers (film c is exactly m but 1000 m in a hundredth of the pixels: a mean over the
    films instead of the median takes a's and b's relvar 9% low; the median of three, 0.4% high),
    and seconds per pass taken for seconds per spp."""
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
    c = films["c"] = Film(w, h)
    outlier = rng.random(h * w) < 0.01
    for _ in range(spp):
        c.add(np.arange(h * w, dtype=np.int64), np.where(outlier[:, None], 1000.0 * m, m),
              np.zeros((h * w, c.aov.shape[1])))
    entries = {"a": {"spp": spp, "time": 4.0}, "b": {"spp": spp, "time": 1.0}, "c": {"spp": spp, "time": 1.0}}
    out = trial_costs(films, entries)
    for name, k, sec in (("a", 1.0, 1.0), ("b", 2.0, 0.25)):
        terms = (films[name].variance().reshape(-1, 3) * spp / (m * m + EPS)).ravel()
        expect = float(np.mean((k * s) ** 2 / (m * m + EPS)))
        assert_z(out[name]["relvar"], np.var(terms) / terms.size, expect, n_tests=2, what=f"relvar of film {name}")
        assert out["c"]["relvar"] == 0.0
        assert out[name]["seconds_per_spp"] == sec
        assert out[name]["cost"] == pytest.approx(out[name]["relvar"] * sec)


@pytest.mark.parametrize("bad", ["bsdf+foo", "grid+grid", "", "pss"])
def test_candidates_are_checked(bad):
    with pytest.raises(SettingsError, match="candidates must be distinct names from bsdf, grid, photon, ppg"):
        make_guide("auto", candidates=bad)


def test_trial_iterations_are_at_most_the_candidates_iterations():
    with pytest.raises(SettingsError, match="trial_iterations must be at most 5"):
        make_guide("auto", trial_iterations=6)


@pytest.mark.parametrize("in_image", [0, 1])
def test_auto_renders_with_the_candidate_its_trials_predict_and_keeps_the_mean(in_image):
    """On the ajar box: a pilot, a trial per candidate (bsdf 4 spp, each guide its iterations of 2
    and 4 spp), then the winner's Algorithm 1 from iteration 3 (a guide) or final passes (bsdf).
    The winner is the least predicted cost of the trials in the stats, the films the choice was made
    from (each candidate's last trial) and the losers' other trial films get no weight (with
    trials_in_image 1 the losers' do), and the image's mean agrees with a BSDF render's (z-test).
    Detects a winner other than the argmin, losers' films weighed in (or left out with
    trials_in_image), a guide restarting Algorithm 1 from its pilot, and a biased image."""
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
    chosen_last = {"bsdf": 1, "grid": 3, "photon": 5, "ppg": 7}[st["choice"]]
    assert r.stats["passes"][chosen_last].get("weight") == 0.0
    if in_image and not st.get("chosen", {}).get("switched_off"):  # (switched off: training films all out)
        assert len(weighted) > 2, r.stats["passes"][1:8]
    else:
        assert len(weighted) <= (0 if st["choice"] == "bsdf" else 1), r.stats["passes"][1:8]
    assert r.stats["spp"] == 96
    b = tracer.render(scene, spp=96, seed=304)
    m_a, v_a = image_mean(r)
    m_b, v_b = image_mean(b)
    assert_z(m_a, v_a + v_b, m_b, n_tests=2, what="auto vs bsdf on ajar")


@pytest.mark.parametrize("candidates", ["photon", "grid+photon"])
def test_the_chosen_guide_learned_from_the_pilot_and_its_trials(candidates):
    """The guide auto goes on with has learned from every pass it should: the shared pilot, its own
    trials and its training iterations (iterations_done counts its updates), none of the other
    candidate's; and the mean holds (z-test against BSDF sampling). A single candidate runs as
    itself, without trials. Detects a guide that missed the pilot or learned from another's trial,
    and a biased image."""
    scene = scenes.builtin(ROOT, "cornell", 32, 32)
    g = make_guide("auto", candidates=candidates)
    r = tracer.render(scene, spp=64, guide=g, seed=7)
    assert_clean(r, f"auto:{candidates}")
    st = r.stats["guide_stats"]
    kinds = [p["kind"] for p in r.stats["passes"]]
    own_trials = 0 if candidates == "photon" else 2
    assert kinds.count("trial") == (0 if candidates == "photon" else 4)
    if candidates == "photon":
        assert st["choice"] == "photon" and st["why"] == "the only candidate"
    assert st["chosen"]["iterations_done"] == 1 + own_trials + kinds.count("train"), (kinds, st["chosen"])
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


def test_too_few_spp_without_bsdf_render_the_first_candidate():
    """With candidates grid+photon and too few spp for the trials, auto renders grid (the first
    candidate) with its own Algorithm 1, not bsdf, which the user left out."""
    scene = scenes.builtin(ROOT, "cornell", 16, 16)
    r = tracer.render(scene, spp=8, guide="auto:candidates=grid+photon", seed=1)
    st = r.stats["guide_stats"]
    assert st["choice"] == "grid" and [p["kind"] for p in r.stats["passes"]][0] == "pilot"


def test_a_budget_too_short_for_the_trials_renders_the_fallback():
    """A budget the pilot already spends leaves no trial: auto renders bsdf and says why, and the
    image has samples everywhere."""
    scene = scenes.builtin(ROOT, "cornell", 16, 16)
    r = tracer.render(scene, time=1e-3, guide="auto", seed=1)
    st = r.stats["guide_stats"]
    assert st["choice"] == "bsdf" and "too short for a trial" in st["why"]
    assert "trial" not in [p["kind"] for p in r.stats["passes"]] and r.film.count.min() >= 2


def test_choice_ignores_trials_that_saw_nothing():
    """A trial whose film has no variance at all (no light found, or a black image) is not the
    cheapest; where every trial saw nothing the fallback is taken."""
    from tracer.guiding.auto import _choose

    t = {"bsdf": {"relvar": 2.0, "cost": 1.0}, "grid": {"relvar": 0.0, "cost": 0.0},
         "photon": {"relvar": 1.0, "cost": 0.5}}
    assert _choose(t, ["bsdf", "grid", "photon"], "bsdf")[0] == "photon"
    dark = {n: {"relvar": 0.0, "cost": 0.0} for n in t}
    assert _choose(dark, ["bsdf", "grid", "photon"], "bsdf") == ("bsdf", "no trial saw any light")


def test_a_frozen_auto_is_the_guide_it_chose():
    scene = scenes.builtin(ROOT, "cornell", 16, 16)
    g = make_guide("auto", candidates="photon")
    tracer.render(scene, spp=16, guide=g, seed=1)
    from tracer.guiding import FrozenGuide

    assert FrozenGuide(g).name == "photon (frozen)"
    with pytest.raises(SettingsError, match="auto rendered with bsdf"):
        FrozenGuide(make_guide("auto", candidates="bsdf"))


def test_the_winner_samples_its_own_maps_after_the_trials(monkeypatch):
    """After the trials the passes sample from the winner's state, not from the last candidate
    tried: with candidates grid+photon and grid forced to win, every record grid observes lies in
    grid's own tree. Detects the state of the last trial (photon's, a finer tree) left in place,
    whose node indices grid would splat out of bounds."""
    import tracer.guiding.auto as auto
    from tracer.guiding.grid.guides import GridGuide

    monkeypatch.setattr(auto, "_choose", lambda trials, tried, fallback: ("grid", "forced"))
    seen = []
    observe = GridGuide.observe

    def checked(self, rec):
        if self.grid is not None:
            keep = rec.strategy >= 0
            seen.append((int(rec.node[keep].max(initial=-1)), int(self.grid.n_nodes)))
            assert seen[-1][0] < seen[-1][1], seen  # (before the splat, which would write out of bounds)
        observe(self, rec)

    monkeypatch.setattr(GridGuide, "observe", checked)
    scene = scenes.builtin(ROOT, "ajar", 48, 36)
    r = tracer.render(scene, spp=64, guide="auto:candidates=grid+photon", seed=5)
    assert r.stats["guide_stats"]["choice"] == "grid" and len(seen) > 3
    assert all(nd < n for nd, n in seen), seen
