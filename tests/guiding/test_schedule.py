"""Algorithm 1's time-budget rule (tracer.guiding.grid.schedule._fit): how many spp a training
iteration runs, given the last pass's measured cost and the budget left. A fake session stands in
for the render, so the rule is checked without timing jitter."""
import pytest

from tracer.guiding import make_guide
from tracer.guiding.grid.schedule import _fit, training_record


class _Session:
    def __init__(self, time, elapsed, last):
        self.time, self._elapsed, self.passes = time, elapsed, [last]

    def elapsed(self):
        return self._elapsed


def _run(guide, time, elapsed, last, n, t=3):
    guide.training = training_record(guide.iterations)
    return _fit(_Session(time, elapsed, last), guide, t, n, last)


@pytest.mark.parametrize("name", ["grid", "photon", "ppg"])
def test_an_iteration_that_fits_runs_whole(name):
    """An iteration of n spp whose predicted cost (last pass's seconds and update per spp, times n)
    ends inside the training share runs whole, and training goes on."""
    g = make_guide(name, train_budget=0.25)
    last = {"spp": 4, "time": 1.0, "time_update": 0.6}  # 0.4 s per spp
    assert _run(g, 30.0, 3.0, last, 8) == (8, False)  # ends at 6.2 s of the 7.5-s share
    assert g.training["stopped"] is None


def test_an_iteration_that_does_not_fit_runs_the_spp_that_do():
    """The photon guide's maps keep every iteration's photons: an iteration past the share runs
    shortened to floor(room / cost per spp) spp, the last one, and the record says so. Room is
    the share left (7.5 - 4.79 s at 0.4 s per spp: 6 spp of 8). Detects the old all-or-nothing
    rule, which dropped the iteration."""
    g = make_guide("photon", train_budget=0.25)
    last = {"spp": 4, "time": 1.0, "time_update": 0.6}
    assert _run(g, 30.0, 4.79, last, 8) == (6, True)
    assert g.training["stopped"] == "train_budget" and g.training["shortened"]
    assert "ran 6 of its 8 spp" in g.training["why"]


@pytest.mark.parametrize("name, fit, runs", [("photon", 2, 2), ("photon", 1, 0), ("grid", 3, 0), ("ppg", 3, 0),
                                             ("grid", 4, 4)])
def test_a_shortened_iteration_runs_only_when_it_pays(name, fit, runs):
    """After a 4-spp iteration, a shortened one runs with at least 2 spp for photon (its maps add
    the photons up) and 4 for grid and ppg (whose maps the last iteration alone rebuilds), else
    training ends with the reason in words. `fit`: the spp that fit in the share."""
    g = make_guide(name, train_budget=0.25)
    last = {"spp": 4, "time": 1.0, "time_update": 0.6}
    elapsed = 7.5 - 0.4 * fit - 0.01
    n, final = _run(g, 30.0, elapsed, last, 8)
    assert (n, final) == (runs, True)
    assert g.training["stopped"] == "train_budget"
    if runs == 0:
        assert "the training share was used up" in g.training["why"] and "worth an update" in g.training["why"]


def test_the_final_passes_keep_at_least_as_long_as_training_takes():
    """With a training share of the whole budget, an iteration fits only while the final passes
    keep as long again: room (10 - 6) / 2 = 2 s at 0.4 s per spp is 5 spp of 8, stopped by `time`."""
    g = make_guide("photon", train_budget=1.0)
    last = {"spp": 4, "time": 1.0, "time_update": 0.6}
    assert _run(g, 10.0, 6.0, last, 8) == (5, True)
    assert g.training["stopped"] == "time"
