"""The sampler contract, for every registered guide.

A guide whose maps are tables (grid, photon: `fixed_state(map)`, a state whose space is one voxel
holding that map; odis: `pixel_state(map)`, a first-bounce map for one film pixel) is queried
through the kernels' own contract (tracer.guiding.contract: locate, slot_sample, slot_pdf), which
must then: sample directions that the chi-square test accepts against their pdf; have a pdf
that integrates to 1; only sample where the pdf is positive, and return that pdf; give finite
outputs. The map has empty bins (the pdf must be 0 there and they must never be sampled), a
sharp peak and a smooth lobe. pss has no table: its warp's primary samples and their weights
1 / q are checked against the uniform measure instead (test_pss_weights_are_the_inverse_density).
"""
import math

import numpy as np
import pytest

from tracer.testing.chi2 import ChiSquareTest
from tracer.testing.stats import z_critical
from tracer.guiding import REGISTRY, guide_settings, make_guide
from tracer.guiding.directional import bin_of_batch
from tracer.guiding.contract import guide_pdf_batch, guide_sample_batch
from tests.test_cli import CORNELL

NO_TABLE = {"bsdf": "no guide", "pss": "a warp of primary samples (its own test below)",
            "auto": "renders with one of bsdf, grid, photon and ppg, each tested under its own name"}
GUIDES = [name for name in REGISTRY if name not in NO_TABLE]  # guides whose maps are tables
H, W = 8, 16


def fixed_map():
    z = -1.0 + 2.0 * (np.arange(H) + 0.5) / H
    phi = -math.pi + 2.0 * math.pi * (np.arange(W) + 0.5) / W
    m = np.exp(3.0 * z)[:, None] * (1.2 + np.cos(phi))[None, :]
    m[:, 3:6] = 0.0  # a wedge of empty bins
    m[1, 10] = 40.0  # a sharp peak
    return m


def table_state(name, sampling_map):
    """(state, pixel, depth): a state of guide `name` whose map for a vertex of film pixel `pixel`
    at bounce `depth` is `sampling_map`."""
    h, w = sampling_map.shape
    g = make_guide(name)
    if hasattr(g, "fixed_state"):
        size = {k: v for k, v in (("map_width", w), ("map_height", h)) if k in guide_settings(name)}
        return make_guide(name, **size).fixed_state(sampling_map), -1, 1
    if hasattr(g, "pixel_state"):
        return g.pixel_state(sampling_map), 0, 0
    raise AssertionError(f"guide {name!r} has neither fixed_state nor pixel_state: the contract cannot test it")


def test_every_registered_guide_is_covered():
    for name in REGISTRY:
        if name not in NO_TABLE:
            table_state(name, fixed_map())


def kernels(name):
    gs, pixel, depth = table_state(name, fixed_map())

    def args(n):
        x = np.zeros((n, 3))
        nrm = np.tile([0.0, 0.0, 1.0], (n, 1))
        return x, nrm

    def sample(u):
        x, nrm = args(u.shape[0])
        wi, pdf = guide_sample_batch(gs, x, nrm, nrm, np.ascontiguousarray(u[:, :2]), pixel, depth)
        return np.where((pdf > 0)[:, None], wi, np.nan)

    def pdf(d):
        x, nrm = args(d.shape[0])
        return guide_pdf_batch(gs, x, nrm, np.ascontiguousarray(d, dtype=np.float64), pixel, depth)

    return gs, sample, pdf, args, pixel, depth


@pytest.mark.parametrize("name", GUIDES)
def test_chi_square_and_pdf_integrates_to_one(name):
    _, sample, pdf, _, _, _ = kernels(name)
    breaks = tuple(-1.0 + 2.0 * np.arange(1, H) / H)
    t = ChiSquareTest(sample, pdf, sample_dim=2, n=400_000, res=(31, 61), breaks=breaks, seed=11)
    assert t.run(ntests=len(GUIDES)), t.message
    assert abs(t.pdf_integral - 1.0) < max(5 * t.quad_error, 2e-3), t.message


@pytest.mark.parametrize("name", GUIDES)
def test_samples_in_support_and_finite(name):
    gs, _, pdf, args, pixel, depth = kernels(name)
    rng = np.random.default_rng(5)
    u = rng.random((200_000, 2))
    u[:10] = [[0.0, 0.0], [1 - 1e-16, 1 - 1e-16], [0.5, 0.0], [0.0, 1 - 1e-16],
              [1 - 1e-16, 0.0], [0.25, 0.5], [0.75, 0.5], [1e-300, 0.5], [0.5, 1e-300], [0.999999, 0.1]]
    x, nrm = args(u.shape[0])
    wi, p = guide_sample_batch(gs, x, nrm, nrm, u, pixel, depth)
    assert np.isfinite(wi).all() and np.isfinite(p).all()
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-9)
    assert (p > 0).all(), "a sample came with pdf 0"
    np.testing.assert_allclose(pdf(wi), p, rtol=1e-12)  # the pdf it returns is the one pdf() gives
    bins = bin_of_batch(wi, H, W)
    assert not np.isin(bins % W, [3, 4, 5]).any(), "sampled an empty bin"


@pytest.mark.parametrize("name", GUIDES)
def test_empty_map_gives_no_sampling(name):
    gs, pixel, depth = table_state(name, np.zeros((H, W)))
    x = np.zeros((4, 3))
    nrm = np.tile([0.0, 0.0, 1.0], (4, 1))
    _, p = guide_sample_batch(gs, x, nrm, nrm, np.full((4, 2), 0.5), pixel, depth)
    assert (p == 0).all() and (guide_pdf_batch(gs, x, nrm, nrm, pixel, depth) == 0).all()
    assert (gs.slot == -1).all() and (gs.pixel_slot == -1).all()  # the integrator samples the BSDF alone there


def test_pss_weights_are_the_inverse_density():
    """pss's final passes draw primary samples y from its warp mixed with the uniform density and
    weight each by 1 / q(y). With q the density y is drawn from, E[w] = 1 and E[f(y) w] is the
    integral of f over the unit cube (1/2^k for f = y_0 ... y_{k-1}): z-tests over 200k samples
    of a random (untrained) flow over 4 dimensions, image-conditioned, and pixel-conditioned. A
    weight from another density than the sampled one (e.g. the warp's alone, without the
    defensive part) moves the means by many standard deviations."""
    import torch

    import tracer
    from tracer.guiding.pss import warp as pss
    from tracer.guiding.pss import flow as pss_flow
    from tracer.render import make_context

    torch.manual_seed(3)
    scene = tracer.load_scene(CORNELL, width=8, height=8)
    ctx = make_context(scene)
    for image, dims in ((True, 4), (False, 2)):
        flow = pss_flow.PSSFlow(dims, layers=2, width=8, context=not image)
        with torch.no_grad():
            for p in flow.parameters():
                p.add_(0.3 * torch.randn_like(p))  # away from the identity
        src = pss.WarpSource(flow, np.arange(dims), image, 0.2, seed=1)
        y, w = src.primary(ctx, 0, 0, 200_000)
        assert np.isfinite(w).all() and (w > 0).all() and ((y >= 0) & (y <= 1)).all()
        for f, expect in ((np.ones(len(y)), 1.0), (y[:, 0], 0.5), (y.prod(axis=1), 0.5 ** dims)):
            v = f * w
            z = (v.mean() - expect) / (v.std(ddof=1) / math.sqrt(len(v)))
            assert abs(z) < z_critical(6), (image, expect, v.mean(), z)
