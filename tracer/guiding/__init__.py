"""Directional samplers for the bounce direction, registered by name.

`bsdf` is plain BSDF importance sampling (no guide). `grid` and `photon` are histogram guides on
a hierarchical grid (tracer/guiding/grid/guides.py), learned from camera paths and from photons;
`ppg` is Practical Path Guiding's SD-tree (tracer/guiding/ppg.py); `auto` picks one of bsdf,
grid, photon and ppg from a short trial of each (tracer/guiding/auto.py).
Each guide is built from a settings dict; unknown names or settings are errors that list the
valid ones. A guide is a `base.Guide`: `prepare(scene, ctx)`, `state()` (the arrays the
integrator's kernels read, a `contract.GuideState`), `observe(records)` (the vertices of a wave of
camera paths), `update()` (between passes), `schedule(session)` (its passes), plus
`memory_bytes()` and `stats()`; docs/architecture.md shows where each is called.
"""
import copy

from ..errors import SettingsError, unknown_name
from .auto import AutoGuide
from .base import Guide
from .grid.guides import GridGuide, PhotonGuide
from .odis.guide import OdisGuide
from .ppg import PPGGuide
from .pss.warp import PSSGuide

# name -> (factory or None for plain BSDF sampling, {setting: default})
REGISTRY = {
    "bsdf": (None, {}),
    "grid": (GridGuide, GridGuide.DEFAULTS),
    "photon": (PhotonGuide, PhotonGuide.DEFAULTS),
    "pss": (PSSGuide, PSSGuide.DEFAULTS),
    "odis": (OdisGuide, OdisGuide.DEFAULTS),
    "ppg": (PPGGuide, PPGGuide.DEFAULTS),
    "auto": (AutoGuide, AutoGuide.DEFAULTS),
}


def guide_names():
    return tuple(REGISTRY)


def guide_settings(name):
    """{setting: default} of guide `name`."""
    if name not in REGISTRY:
        raise unknown_name("guide", name, REGISTRY)
    return dict(REGISTRY[name][1])


def make_guide(name, **settings):
    """Build the guide registered as `name`; None means plain BSDF sampling."""
    if name not in REGISTRY:
        raise unknown_name("guide", name, REGISTRY)
    factory, defaults = REGISTRY[name]
    bad = sorted(set(settings) - set(defaults))
    if bad:
        valid = ", ".join(sorted(defaults)) or "none"
        raise SettingsError(f"guide {name!r} has no setting {bad[0]!r}; valid: {valid}")
    if factory is None:
        return None
    return factory(**dict(defaults, **settings))


def warm_up_guides(ctx):
    """Compile (or load from the cache) the kernels guides run, before a render's clock starts."""
    import numpy as np

    from .directional import bin_of_batch, build_tables
    from .grid.photons import trace_photons
    from .grid.spatial import HierarchicalGrid
    from .contract import empty_state

    trace_photons(ctx, empty_state(), np.full(1, -1, np.int32), 1, 0, lambda *a: None, wave_size=1)
    grid = HierarchicalGrid(np.zeros(3), np.ones(3), 2, 2, 2, 6)
    grid.visit(grid.locate(np.full((1, 3), 0.5), np.array([[0.0, 0.0, 1.0]])), 0)
    grid.accumulate(np.zeros(1, np.int64), bin_of_batch(np.array([[0.0, 0.0, 1.0]]), 2, 2), np.ones(1))
    build_tables(grid.power[:1].reshape(1, 2, 2))
    from .records import Records

    rec = Records.allocate(1)
    grid.visit_records(rec, 0)
    grid.splat_records(rec)
    from .grid.guides import _mis_stats, _normalised, _row_sums

    _normalised(grid.power, np.zeros(1, np.int64), _row_sums(grid.power, np.zeros(1, np.int64)) + 1.0)
    from .grid.reconstruct import Gaussian

    Gaussian(1.0).reconstruct(np.zeros((1, 4, 4), np.float32), None, None)
    _mis_stats(np.zeros(1, np.int32), np.zeros(1, np.int8), np.zeros(1, np.float32), np.zeros(1, np.float32),
               np.zeros((1, 2)), np.zeros((1, 2)))
    from .mixing import _mix_moments

    f32 = np.zeros(1, np.float32)
    _mix_moments(np.zeros(1, np.int32), np.zeros(1, np.int8), f32, f32, f32, False, f32, f32, f32, np.ones(1),
                 np.ones(1), np.zeros((1, 1)), np.zeros(1))
    # the pilot's median splits: four points in one visited leaf, over a threshold of one
    grid = HierarchicalGrid(np.zeros(3), np.ones(3), 2, 2, 2, 6)
    points, normals = np.full((4, 3), 0.3), np.tile(np.array([0.0, 0.0, 1.0]), (4, 1))
    grid.visit(grid.locate(points, normals), 0)
    grid.split_median(points, 1.0, 2, normals)


class FrozenGuide(Guide):
    """What a trained guide learned, fixed: a render samples from its maps and learns nothing (no
    pilot, no training passes). For equal-spp comparisons of the maps themselves, e.g.
    `g = make_guide("photon"); tracer.render(scene, spp=64, guide=g)` to train, then
    `tracer.render(scene, spp=256, guide=FrozenGuide(g))`. The scene must be the one it learned."""

    learns = False
    iterations = 0
    spp_init = 1

    def __init__(self, guide):
        if isinstance(guide, AutoGuide):  # the guide it chose
            if guide.winner() is None:
                raise SettingsError("FrozenGuide: auto rendered with bsdf (or has not rendered): no maps to freeze")
            guide = guide.winner()
        if guide is None or getattr(guide, "grid", None) is None:
            raise SettingsError("FrozenGuide needs a guide that has learned (render with it first)")
        self.guide = guide
        self.name = guide.name + " (frozen)"
        self.splitting = copy.copy(guide.splitting)  # with the pixel estimate of its training passes
        self._outgoing = guide.window_estimates()
        self._state = guide.state()
        self.peak_memory = guide.memory_bytes()
        self.time_learning = self.time_update = self.time_inference = 0.0

    def state(self):
        return self._state

    def window_estimates(self):
        return self._outgoing

    def memory_bytes(self):
        return self.peak_memory

    def stats(self):
        return dict(self.guide.stats(), frozen=True)
