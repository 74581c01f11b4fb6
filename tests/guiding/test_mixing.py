"""`mixing variance` (tracer.guiding.mixing): the per-node second moments behind the choice of the
mixing weight a, and the switch-off they predict."""
import numpy as np
import pytest

from tracer.errors import SettingsError
from tracer.guiding import make_guide
from tracer.guiding.mixing import EARLY_ITERATIONS, N_ALPHA, SWITCH_OFF_EARLY, VarianceMixing, _mix_moments
from tracer.guiding.records import Records
from tracer.testing import z_critical

CAND = np.linspace(0.2, 0.8, N_ALPHA)


def _draw(rng, n, F, pb, pg, a):
    """n vertices of one voxel whose directions (K discrete bins) come from a pb + (1-a) pg."""
    p = a * pb + (1 - a) * pg
    k = rng.choice(F.size, size=n, p=p)
    from_guide = rng.random(n) >= a  # which strategy drew it does not change the mixture density
    return dict(node=np.zeros(n, np.int32), strategy=from_guide.astype(np.int8),
                radiance=F[k].astype(np.float32), fcos=np.ones(n, np.float32), pdf=p[k].astype(np.float32),
                pb=pb[k].astype(np.float32)), k


def _random_densities(rng, K):
    """A BSDF density over K bins bounded away from 0, and a guide's that may be near 0."""
    pb = rng.random(K) + 0.1
    pg = rng.random(K) ** 2
    return pb / pb.sum(), pg / pg.sum()


def _moments(rec, a, full=False):
    mom, mom_n = np.zeros((1, N_ALPHA)), np.zeros(1)
    zero = np.zeros(rec["node"].size, np.float32)
    _mix_moments(rec["node"], rec["strategy"], rec["radiance"], rec.get("direct", zero), rec.get("plight", zero),
                 full, rec["fcos"], rec["pdf"], rec["pb"], np.array([a]), CAND, mom, mom_n)
    return mom[0], mom_n[0]


def test_second_moments_are_unbiased_for_every_candidate():
    rng = np.random.default_rng(3)
    K = 12
    F = rng.random(K) ** 3
    pb, pg = _random_densities(rng, K)
    a, n = 0.5, 200_000
    rec, k = _draw(rng, n, F, pb, pg, a)
    mom, mom_n = _moments(rec, a)
    assert mom_n == n
    p = (a * pb + (1 - a) * pg)[k]
    for j, c in enumerate(CAND):
        pc = c * pb + (1 - c) * pg
        exact = np.sum(F ** 2 / pc)  # the second moment of F / p_c under p_c
        v = F[k] ** 2 / (pc[k] * p)  # what each vertex adds
        se = v.std(ddof=1) / np.sqrt(n)
        # z-test per candidate, Sidak-corrected over the candidates at 1e-3 family-wise
        assert abs(mom[j] / n - exact) < z_critical(len(CAND), 1e-3) * se, (c, mom[j] / n, exact, se)


def _with_direct(rec, k, D, pl, full):
    """rec's vertices given direct emission D[k] found along their bins, with next-event density
    pl[k]; with `full` the radiance holds it too (records of `direct` 1)."""
    rec = dict(rec, direct=D[k].astype(np.float32), plight=pl[k].astype(np.float32))
    if full:
        rec["radiance"] = (rec["radiance"] + D[k]).astype(np.float32)
    return rec


@pytest.mark.parametrize("full", [False, True])
def test_direct_light_counts_against_next_event_density(full):
    """The second moment with direct light D (next-event density p_l) is the integral of
    I^2 / p_c + D^2 / (p_c + p_l): z-tested per candidate against that sum written here. Detects
    direct light left out, counted twice (records that hold it, `full`), or weighed without p_l."""
    rng = np.random.default_rng(5)
    K = 10
    F = rng.random(K) ** 2
    D = np.where(rng.random(K) < 0.4, 3.0 * rng.random(K), 0.0)
    pl = np.where(D > 0, rng.random(K) * 0.3, 0.0)
    pb, pg = _random_densities(rng, K)
    a, n = 0.4, 200_000
    rec, k = _draw(rng, n, F, pb, pg, a)
    mom, _ = _moments(_with_direct(rec, k, D, pl, full), a, full)
    p = (a * pb + (1 - a) * pg)[k]
    for j, c in enumerate(CAND):
        pc = c * pb + (1 - c) * pg
        exact = np.sum(F ** 2 / pc + D ** 2 / (pc + pl))
        v = (F ** 2 / pc + D ** 2 / (pc + pl))[k] / p
        se = v.std(ddof=1) / np.sqrt(n)
        assert abs(mom[j] / n - exact) < z_critical(len(CAND), 1e-3) * se, (c, mom[j] / n, exact, se)


def test_light_that_next_event_estimation_misses_keeps_bsdf_sampling():
    """A guide that holds the indirect light well but not a small light in the BSDF's lobe, which
    next-event estimation finds poorly (p_l << p_bsdf): the most BSDF sampling allowed wins; with
    next-event estimation that finds the light well (p_l >> p_bsdf), the least."""
    rng = np.random.default_rng(6)
    K = 16
    F = np.zeros(K)
    F[8:] = 0.1
    D = np.zeros(K)
    D[0] = 40.0  # the light, in the lobe
    pb = np.full(K, 0.02)
    pb[0] = 1.0 - 0.02 * (K - 1)
    pg = np.where(F > 0, 1.0 / 8, 0.0)
    for pl0, best in ((0.01, N_ALPHA - 1), (50.0, 0)):
        pl = np.where(D > 0, pl0, 0.0)
        rec, k = _draw(rng, 20_000, F, pb, pg, 0.5)
        assert np.argmin(_moments(_with_direct(rec, k, D, pl, False), 0.5)[0]) == best, pl0


def test_choice_follows_the_data():
    rng = np.random.default_rng(4)
    K = 16
    F = np.zeros(K)
    F[:4] = 1.0
    pb = np.full(K, 1.0 / K)
    # a guide proportional to F: the least second moment is at the smallest BSDF share
    good = F / F.sum()
    rec, _ = _draw(rng, 20_000, F, pb, good, 0.5)
    assert np.argmin(_moments(rec, 0.5)[0]) == 0
    # a guide with no mass where the light is: the most BSDF sampling allowed
    bad = np.zeros(K)
    bad[8:] = 1.0 / 8
    rec, _ = _draw(rng, 20_000, F, pb, bad, 0.5)
    assert np.argmin(_moments(rec, 0.5)[0]) == N_ALPHA - 1


def test_vertices_without_a_map_or_record_are_skipped():
    rec = dict(node=np.array([-1, 0, 0], np.int32), strategy=np.array([0, -1, 0], np.int8),
               radiance=np.ones(3, np.float32), fcos=np.ones(3, np.float32), pdf=np.ones(3, np.float32),
               pb=np.ones(3, np.float32))
    mom, n = _moments(rec, 1.0)  # a = 1: the voxel has no map, nothing to weigh
    assert n == 0 and (mom == 0).all()
    mom, n = _moments(rec, 0.5)
    assert n == 1 and np.isfinite(mom).all() and (mom > 0).all()


def test_unknown_mixing_is_an_error():
    with pytest.raises(SettingsError, match="mixing.*eq14, variance"):
        make_guide("photon", mixing="median")


def _records(rec):
    """A Records holding the vertices of a _draw dict (one node)."""
    n = rec["node"].size
    r = Records.allocate(n)
    for f in ("node", "strategy", "radiance", "fcos", "pdf", "pb"):
        getattr(r, f)[:] = rec[f]
    return r


@pytest.mark.parametrize("where", ["on the light", "off the light"])
def test_predicted_ratio_and_switch_off(where):
    """The predicted ratio is the chosen weight's second moment over BSDF sampling's alone: z-tested
    against the two exact sums written here (delta method), for a guide whose map holds the light
    (ratio below 1: it stays on) and one whose map misses it (above 1: the guide switches off, and
    with a ratio above SWITCH_OFF_EARLY training ends early). Detects a ratio against the wrong
    yardstick, the BSDF's candidate chosen, or the switch acting the wrong way."""
    rng = np.random.default_rng(7)
    K = 16
    F = np.zeros(K)
    F[:3] = 1.0
    pb = np.full(K, 1.0 / K)
    pg = F / F.sum() if where == "on the light" else np.where(np.arange(K) >= 8, 1.0 / 8, 0.0)
    n, a = 100_000, 0.5
    rec, k = _draw(rng, n, F, pb, pg, a)
    m, never = VarianceMixing(0.2, 0.8, 32, 1.0, False), VarianceMixing(0.2, 0.8, 32, 0.0, False)
    for x in (m, never):
        x.observe(_records(rec), np.array([a]))
        alpha = np.array([a])
        x.choose(alpha)
    c = alpha[0]
    assert c in CAND
    pc = c * pb + (1 - c) * pg
    exact = np.sum(F ** 2 / pc) / np.sum(F ** 2 / pb)
    p = (a * pb + (1 - a) * pg)[k]
    u, v = (F ** 2 / pc)[k] / p, (F ** 2 / pb)[k] / p
    r = u.mean() / v.mean()
    se = np.std(u - r * v, ddof=1) / np.sqrt(n) / v.mean()
    # (+ float32 rounding: with the map proportional to F every vertex gives the same ratio, se 0)
    assert abs(m.predicted_ratio - exact) < 4.0 * se + 1e-6 * exact, (m.predicted_ratio, exact, se)
    if where == "on the light":
        assert exact < 1.0 and not m.switched_off() and not m.training_done()
    else:
        assert exact > SWITCH_OFF_EARLY and m.switched_off()
        for _ in range(EARLY_ITERATIONS - 1):  # training ends after EARLY_ITERATIONS such iterations
            assert not m.training_done()
            m.observe(_records(rec), np.array([a]))
            m.choose(np.array([a]))
        assert m.training_done()
    assert not never.switched_off() and not never.training_done()  # switch_off 0: never


def test_too_few_vertices_predict_nothing():
    """Nodes below min_samples keep their weight and give no prediction (nothing switches off)."""
    rng = np.random.default_rng(8)
    F = np.ones(4)
    pb = np.full(4, 0.25)
    rec, _ = _draw(rng, 10, F, pb, pb, 0.5)
    m = VarianceMixing(0.2, 0.8, 32, 1.0, False)
    m.observe(_records(rec), np.array([0.5]))
    alpha = np.array([0.5])
    m.choose(alpha)
    assert alpha[0] == 0.5 and m.predicted_ratio is None and not m.switched_off()
