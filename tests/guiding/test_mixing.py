"""`mixing variance`: the per-voxel second moments behind the choice of the mixing weight a."""
import numpy as np
import pytest

from tracer.errors import SettingsError
from tracer.guiding import make_guide
from tracer.guiding.grid.guides import N_ALPHA, _mix_moments
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


def _moments(rec, a):
    mom, mom_n = np.zeros((1, N_ALPHA)), np.zeros(1)
    _mix_moments(rec["node"], rec["strategy"], rec["radiance"], rec["fcos"], rec["pdf"], rec["pb"],
                 np.array([a]), CAND, mom, mom_n)
    return mom[0], mom_n[0]


def test_second_moments_are_unbiased_for_every_candidate():
    rng = np.random.default_rng(3)
    K = 12
    F = rng.random(K) ** 3
    pb = rng.random(K) + 0.1
    pb /= pb.sum()
    pg = rng.random(K) ** 2
    pg /= pg.sum()
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
