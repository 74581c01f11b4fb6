"""`ppg` (Practical Path Guiding) beyond the contract and unbiasedness tests every guide runs
(tests/guiding/test_contract.py, test_guides.py): it learns where the light comes from."""
import os

import numpy as np

import tracer
from tests import scenes
from tracer.guiding import make_guide
from tracer.guiding.contract import guide_pdf_batch

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_ppg_learns_where_the_light_comes_from():
    """After a 64-spp render of the Cornell box with NEE off (the records then carry the light
    their directions hit, PPG's own setting), the learned density, evaluated at the camera
    vertices' recorded directions and weighted by the light each brought back, is several times
    the uniform density 1 / 4 pi, and several times its value at random directions from the same
    vertices (a tree that learned nothing, or learned directions in another frame, is near 1 / 4 pi
    there); the spatial tree split and every iteration ran."""
    scene = scenes.builtin(ROOT, "cornell", 48, 48)
    g = make_guide("ppg", switch_off=0)  # the learned trees themselves, whatever they predict
    seen = []
    observe = g.observe

    def keep(rec):
        ok = (rec.strategy >= 0) & (rec.radiance > 0)
        seen.append([np.array(a[ok], np.float64) for a in (rec.x, rec.n, rec.wi, rec.radiance, rec.pdf)])
        observe(rec)

    g.observe = keep
    r = tracer.render(scene, spp=64, guide=g, integrator="path:nee=0", seed=4)
    assert r.stats["nonfinite_samples"] == 0
    st = g.stats()
    assert st["voxels"] > 1 and st["voxels_with_map"] > 0 and st["iterations_done"] >= 4, st
    x, n, wi, rad, pdf = (np.concatenate(a) for a in zip(*seen))
    w = rad / pdf
    gs = g.state()
    p_rec = np.sum(w * guide_pdf_batch(gs, x, n, wi)) / w.sum()
    d = np.random.default_rng(0).normal(size=wi.shape)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    p_rand = np.sum(w * guide_pdf_batch(gs, x, n, d)) / w.sum()
    assert p_rec > 3.0 / (4 * np.pi) and p_rec > 3.0 * p_rand, (p_rec, p_rand, st)


def test_filter_settings_are_checked():
    """An unknown filter, image, empty-leaf, roulette or records name is a SettingsError naming
    the setting and the allowed values."""
    import pytest

    from tracer.errors import SettingsError

    for key, bad in (("spatial_filter", "box"), ("directional_filter", "gaussian"), ("image", "last"),
                     ("empty", "zero"), ("roulette", "none"), ("records", "all")):
        with pytest.raises(SettingsError, match=f"{key} must be one of"):
            make_guide("ppg", **{key: bad})
