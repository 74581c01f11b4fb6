"""The sampler contract of DESIGN.md, for every registered guide, on a fixed map.

A guide's `fixed_state(map)` is a state whose space is one voxel holding that map. Its Numba
kernels must then: sample directions that the chi-square test accepts against their pdf; have a
pdf that integrates to 1; only sample where the pdf is positive, and return that pdf; give finite
outputs. The map has empty bins (the pdf must be 0 there and they must never be sampled), a
sharp peak and a smooth lobe.
"""
import math

import numpy as np
import pytest

from tracer.testing.chi2 import ChiSquareTest
from tracer.guiding import REGISTRY, make_guide
from tracer.guiding.directional import bin_of_batch
from tracer.guiding.spatial import guide_pdf_batch, guide_sample_batch

GUIDES = [name for name, (factory, _) in REGISTRY.items() if hasattr(factory, "fixed_state")]  # directional guides
H, W = 8, 16


def fixed_map():
    z = -1.0 + 2.0 * (np.arange(H) + 0.5) / H
    phi = -math.pi + 2.0 * math.pi * (np.arange(W) + 0.5) / W
    m = np.exp(3.0 * z)[:, None] * (1.2 + np.cos(phi))[None, :]
    m[:, 3:6] = 0.0  # a wedge of empty bins
    m[1, 10] = 40.0  # a sharp peak
    return m


def kernels(name):
    g = make_guide(name, map_width=W, map_height=H)
    gs = g.fixed_state(fixed_map())

    def args(n):
        x = np.zeros((n, 3))
        nrm = np.tile([0.0, 0.0, 1.0], (n, 1))
        return x, nrm

    def sample(u):
        x, nrm = args(u.shape[0])
        wi, pdf = guide_sample_batch(gs, x, nrm, nrm, np.ascontiguousarray(u[:, :2]))
        return np.where((pdf > 0)[:, None], wi, np.nan)

    def pdf(d):
        x, nrm = args(d.shape[0])
        return guide_pdf_batch(gs, x, nrm, np.ascontiguousarray(d, dtype=np.float64))

    return gs, sample, pdf, args


@pytest.mark.parametrize("name", GUIDES)
def test_chi_square_and_pdf_integrates_to_one(name):
    _, sample, pdf, _ = kernels(name)
    breaks = tuple(-1.0 + 2.0 * np.arange(1, H) / H)
    t = ChiSquareTest(sample, pdf, sample_dim=2, n=400_000, res=(31, 61), breaks=breaks, seed=11)
    assert t.run(ntests=len(GUIDES)), t.message
    assert abs(t.pdf_integral - 1.0) < max(5 * t.quad_error, 2e-3), t.message


@pytest.mark.parametrize("name", GUIDES)
def test_samples_in_support_and_finite(name):
    gs, _, pdf, args = kernels(name)
    rng = np.random.default_rng(5)
    u = rng.random((200_000, 2))
    u[:10] = [[0.0, 0.0], [1 - 1e-16, 1 - 1e-16], [0.5, 0.0], [0.0, 1 - 1e-16],
              [1 - 1e-16, 0.0], [0.25, 0.5], [0.75, 0.5], [1e-300, 0.5], [0.5, 1e-300], [0.999999, 0.1]]
    x, nrm = args(u.shape[0])
    wi, p = guide_sample_batch(gs, x, nrm, nrm, u)
    assert np.isfinite(wi).all() and np.isfinite(p).all()
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-9)
    assert (p > 0).all(), "a sample came with pdf 0"
    np.testing.assert_allclose(pdf(wi), p, rtol=1e-12)  # the pdf it returns is the one pdf() gives
    bins = bin_of_batch(wi, H, W)
    assert not np.isin(bins % W, [3, 4, 5]).any(), "sampled an empty bin"


@pytest.mark.parametrize("name", GUIDES)
def test_empty_map_gives_no_sampling(name):
    g = make_guide(name, map_width=W, map_height=H)
    gs = g.fixed_state(np.zeros((H, W)))
    x = np.zeros((4, 3))
    nrm = np.tile([0.0, 0.0, 1.0], (4, 1))
    _, p = guide_sample_batch(gs, x, nrm, nrm, np.full((4, 2), 0.5))
    assert (p == 0).all() and (guide_pdf_batch(gs, x, nrm, nrm) == 0).all()
    assert (gs.slot == -1).all()  # the integrator samples the BSDF alone there
