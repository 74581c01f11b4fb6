"""The per-thread path loop (tracer.integrators.thread_loop) against the wavefront it replaces.

The two walk the same paths with the same random numbers, each path adding its emission and its
NEE in the same order, so every output must match bit for bit: image, variance, AOVs and the ray
counts. A difference in any lane bookkeeping (a lane refilled with the wrong path, a shadow ray
credited to the wrong lane, a path dropped or traced twice, a stale hit read from a packet, a
shadow ray that is never traced) changes some pixel. The wavefront itself is checked against
analytic answers and Mitsuba 3 elsewhere (test_render_reference.py, test_mitsuba_files.py).
"""
import os

import numpy as np
import pytest

import tracer
from tracer.errors import SettingsError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(os.path.dirname(ROOT), "shared", "scenes-mitsuba")


def _scene(name):
    if name in ("cornell", "ajar"):
        return tracer.load_scene(os.path.join(ROOT, "scenes", name, f"{name}.obj"), width=48, height=48)
    path = os.path.join(SHARED, name, "scene.xml")
    if not os.path.exists(path):
        pytest.skip(f"{path} is not there (../shared beside the checkout)")
    return tracer.load_scene(path, width=64, height=36)


def _pair(scene, **kw):
    """The same render through the per-thread loop and through the wavefront."""
    a = tracer.render(scene, path_loop="thread", **kw)
    b = tracer.render(scene, path_loop="wave", **kw)
    return a, b


def _assert_same(a, b, learns=False):
    """a (thread) and b (wave) equal; a's passes all took the per-thread loop, or with `learns`
    (a guide's recorded passes take the wavefront) its final passes."""
    assert a.stats["nonfinite_samples"] == 0 and b.stats["nonfinite_samples"] == 0
    assert a.stats["time_stages"]["trace"] > 0.0, "the per-thread loop did not run"
    assert learns or a.stats["time_stages"]["intersect"] == 0.0, "some pass took the wavefront"
    assert b.stats["time_stages"]["trace"] == 0.0
    np.testing.assert_array_equal(a.image, b.image)
    np.testing.assert_array_equal(a.variance, b.variance)
    assert a.aovs.keys() == b.aovs.keys()
    for k in a.aovs:
        np.testing.assert_array_equal(a.aovs[k], b.aovs[k], err_msg=k)
    assert a.stats["rays"] == b.stats["rays"] and a.stats["shadow_rays"] == b.stats["shadow_rays"]


@pytest.mark.parametrize("name, kw", [
    ("cornell", dict(max_depth=8, rr_depth=2)),  # roulette from the second bounce: lanes refill at every depth
    ("ajar", dict(max_depth=-1)),  # unlimited depth, an area light behind a door
    ("ajar", dict(max_depth=2, integrator="path:nee=0")),  # emission found in full, no shadow rays
    ("staircase", dict(max_depth=6)),  # textures, shading normals, 774 meshes
    ("veach-mis", dict(max_depth=4)),  # glossy plates, four lights of different sizes
])
def test_images_equal_the_wavefronts_bit_for_bit(name, kw):
    """Every output of a plain path-traced render (wave of 97 paths: every pass spans several
    waves, the last one partial, and most of the 64 chunks hold one or two paths) equals the
    wavefront's, bit for bit, and so do the ray counts."""
    scene = _scene(name)
    a, b = _pair(scene, spp=3, seed=5, wave_size=97, **kw)
    _assert_same(a, b)


def test_a_guides_final_passes_equal_the_wavefronts():
    """odis renders its final passes from per-pixel maps (the guide state the loop must pass to
    every vertex): through the loop they equal the wavefront's bit for bit."""
    scene = _scene("cornell")
    a, b = _pair(scene, spp=6, seed=2, guide="odis")
    _assert_same(a, b, learns=True)


def test_split_final_passes_equal_the_wavefronts():
    """photon's final passes split paths and end some by the weight window; with room for every
    copy the loop makes the same copies with the same keys and adds them into their parents in
    the same order: bit for bit the wavefront's image. Detects a copy that starts from the wrong
    hit or state, a copy never traced or merged, or a window roulette applied twice."""
    scene = _scene("cornell")
    # (window_spp 0: the window from the first final pass, whatever the few training passes hold)
    a, b = _pair(scene, spp=12, seed=3, guide="photon", guide_settings={"window_spp": 0})
    assert a.stats["split_copies"] > 0 and a.stats["window_ended"] > 0
    assert a.stats["split_copies"] == b.stats["split_copies"] and a.stats["window_ended"] == b.stats["window_ended"]
    _assert_same(a, b, learns=True)


def test_split_final_passes_without_room_stay_unbiased():
    """With a wave of 97 paths the copies run out of room, each loop in its own way (the wavefront
    over the wave, the loop per chunk), so the images differ; both stay unbiased: their image
    means agree within a z-test of 4 standard errors (from each film's per-pixel variance of the
    mean). Detects a copy that is dropped without its parent keeping the weight (biased dark), or
    counted twice (bright), at the 4-sigma level of this render (about 2% of the mean)."""
    scene = _scene("cornell")
    kw = dict(spp=64, guide="photon", wave_size=97, max_depth=6)
    a = tracer.render(scene, path_loop="thread", seed=11, **kw)
    b = tracer.render(scene, path_loop="wave", seed=12, **kw)
    assert a.stats["nonfinite_samples"] == 0 and b.stats["nonfinite_samples"] == 0
    assert a.stats["split_copies"] > 0 and b.stats["split_copies"] > 0
    npix = a.image.shape[0] * a.image.shape[1]
    for ch in range(3):  # channel by channel: the channels of a pixel are correlated
        ma, mb = a.image[..., ch].mean(), b.image[..., ch].mean()
        se = np.sqrt(a.variance[..., ch].sum() + b.variance[..., ch].sum()) / npix
        assert abs(ma - mb) < 4.0 * se, (ch, ma, mb, se)


def test_an_unknown_path_loop_is_one_clear_error():
    """A misspelt path_loop names the valid ones, before anything renders."""
    scene = _scene("cornell")
    with pytest.raises(SettingsError, match="thread"):
        tracer.render(scene, spp=1, path_loop="threads")
