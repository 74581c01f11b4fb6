"""The photon map network (tracer.guiding.grid.photon_cnn) and its shipped weights.

- Masked convolution: the output's gradient with respect to every data channel is exactly zero
  at bins outside the mask B_t, and changing those values leaves the output bit-identical (detects
  a layer that reads the data unmasked). A fully masked input gives a finite, uniform map
  (detects padding or pooling that breaks the symmetry, or a division by the empty mask).
- The shipped weights load, their manifest describes them (parameter count, map size), and the
  stored outputs on a fixed input are reproduced (detects weights and manifest out of step).
- On held-out validation maps (tests/data/photon_maps_val.npz: scenes the network never trained
  on, though they chose its epoch and width),
  the network's L1 distance to the dense ground truth is below the Gaussian filter's (the
  guide's default, sigma 1) by a paired one-sided z-test at 1% (detects a network no better
  than the filter it replaces).
- The sampling tables built from a network's map pass the chi-square test of the sampler contract.
"""
import math
import os

import numpy as np
import pytest
import torch

from tracer.testing.chi2 import ChiSquareTest
from tracer.errors import SettingsError
from tracer.guiding import make_guide
from tracer.guiding.grid import photon_cnn
from tracer.guiding.grid.reconstruct import make_reconstructor
from tracer.guiding.contract import guide_pdf_batch, guide_sample_batch

DATA = os.path.join(os.path.dirname(os.path.dirname(__file__)), "data", "photon_maps_val.npz")
H, W = 32, 64


def _sparse(seed, n=4):
    rng = np.random.default_rng(seed)
    counts = rng.poisson(rng.gamma(0.2, 1.0, (n, H, W))).astype(np.float32)
    power = counts * rng.uniform(0.2, 2.0, counts.shape).astype(np.float32)
    maps = power / power.sum(axis=(1, 2), keepdims=True)
    return maps, counts


@pytest.fixture(scope="module")
def shipped():
    return photon_cnn.load()


@pytest.mark.parametrize("which", ["random", "shipped"])
def test_bins_outside_the_mask_never_reach_the_output(which, shipped):
    torch.manual_seed(3)
    model = photon_cnn.PhotonUNet(6).eval() if which == "random" else shipped[0]
    maps, counts = _sparse(1)
    x = torch.from_numpy(photon_cnn.features(maps, counts, maps * 0.5, counts // 2))
    masked = (x[:, 4] == 0)
    assert masked.float().mean() > 0.3, "the input is hardly masked: the test would test little"
    x.requires_grad_(True)
    y = model(x)
    w = torch.randn_like(y)
    (y * w).sum().backward()
    g = x.grad[:, :4].abs()
    assert float(g.permute(1, 0, 2, 3)[:, masked].max()) == 0.0
    assert float(g.permute(1, 0, 2, 3)[:, ~masked].max()) > 0.0, "no gradient at all: the check would be empty"
    x2 = x.detach().clone()
    noise = torch.rand_like(x2[:, :4]) * 5.0
    x2[:, :4] = torch.where(masked[:, None], noise, x2[:, :4])
    with torch.inference_mode():
        assert torch.equal(model(x.detach()), model(x2))


@pytest.mark.parametrize("which", ["random", "shipped"])
def test_fully_masked_input_gives_a_uniform_map(which, shipped):
    torch.manual_seed(4)
    model = photon_cnn.PhotonUNet(6).eval() if which == "random" else shipped[0]
    z = np.zeros((2, H, W), np.float32)
    y = photon_cnn.infer(model, photon_cnn.features(z, z))
    assert np.all(np.isfinite(y))
    np.testing.assert_allclose(y, 1.0, rtol=1e-5)


def test_shipped_weights_match_their_manifest(shipped):
    from learn.photon_train import check_input

    model, man = shipped
    assert man["parameters"] == photon_cnn.parameter_count(model)
    assert man["model"]["width"] == model.width and tuple(man["map"]) == (H, W)
    assert man["flops_per_map"] == photon_cnn.flops_per_map(model, H, W)
    for key in ("data", "train", "validation_l1", "ms_per_1000_maps"):
        assert key in man, f"manifest lacks {key}"
    y = photon_cnn.infer(model, check_input(H, W))
    want = np.asarray(man["check"]["output"], np.float32)
    np.testing.assert_allclose(y, want, rtol=1e-4, atol=1e-5)


def test_network_beats_the_gaussian_filter_on_held_out_maps(shipped):
    d = np.load(DATA)
    raw = d["inputs"].astype(np.float32)
    k = H * W
    maps, counts = raw[:, 0] / k, raw[:, 2]
    target = d["target"].astype(np.float64) / k

    def l1(rec):
        rec = rec.astype(np.float64)
        rec = rec / rec.sum(axis=(1, 2), keepdims=True)
        return np.abs(rec - target).sum(axis=(1, 2))

    e_cnn = l1(make_reconstructor("cnn").reconstruct(maps, counts, counts > 0, raw[:, 1] / k, raw[:, 3]))
    e_gauss = l1(make_reconstructor("gaussian", sigma=1.0).reconstruct(maps, counts, counts > 0))
    diff = e_gauss - e_cnn
    z = diff.mean() / (diff.std(ddof=1) / math.sqrt(diff.size))
    assert z > 2.326, (f"cnn L1 {e_cnn.mean():.4f} vs gaussian {e_gauss.mean():.4f} over {diff.size} maps: "
                       f"z = {z:.2f}")


def test_tables_from_a_network_map_pass_the_chi_square_test(shipped):
    """The contract test's chi-square on the tables of a map the network made. The network is
    convolutional, so it runs here on an 8x16 map: the quadrature of the test resolves the jumps
    of 16 phi bins, not of 64."""
    h, w = 8, 16
    rng = np.random.default_rng(7)
    counts = rng.poisson(rng.gamma(0.3, 2.0, (1, h, w))).astype(np.float32)
    maps = counts / counts.sum()
    rec = photon_cnn.infer(shipped[0], photon_cnn.features(maps, counts))[0]
    gs = make_guide("photon", map_width=w, map_height=h).fixed_state(rec)

    def sample(u):
        n = u.shape[0]
        x, nrm = np.zeros((n, 3)), np.tile([0.0, 0.0, 1.0], (n, 1))
        wi, pdf = guide_sample_batch(gs, x, nrm, nrm, np.ascontiguousarray(u[:, :2]))
        return np.where((pdf > 0)[:, None], wi, np.nan)

    def pdf(dirs):
        n = dirs.shape[0]
        return guide_pdf_batch(gs, np.zeros((n, 3)), np.tile([0.0, 0.0, 1.0], (n, 1)),
                               np.ascontiguousarray(dirs, dtype=np.float64))

    t = ChiSquareTest(sample, pdf, sample_dim=2, n=400_000, res=(31, 61), breaks=tuple(-1.0 + 2.0 * np.arange(1, h) / h),
                      seed=12)
    assert t.run(ntests=1), t.message
    assert abs(t.pdf_integral - 1.0) < max(5 * t.quad_error, 2e-3), t.message


def test_cnn_settings_are_checked():
    with pytest.raises(SettingsError, match="trained on 32x64"):
        make_guide("photon", reconstruct="cnn", map_width=32, map_height=16)
    with pytest.raises(SettingsError, match="goes with guide photon"):
        make_guide("grid", reconstruct="cnn")
