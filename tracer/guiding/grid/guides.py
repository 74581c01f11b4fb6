"""Histogram guides on the hierarchical grid: `grid` (fed by camera paths) and `photon` (fed by photons).

Both follow Algorithm 1 of Zhu et al. 2021 (Photon-Driven Neural Reconstruction for Path Guiding):

- pilot pass (iteration 0): 1 spp of unguided camera paths; their vertices give the bounds of a
  uniform grid (`resolution` cells along its diagonal) and make the cells they land in valid. The
  initial data (the pilot's photons, or the pilot's vertices for `grid`) is kept as points and
  splits the cells at the median point wherever a cell holds more than c of them.
- iteration t = 1, 2, ...: camera paths guided by the maps of iteration t - 1 render 2^t spp,
  make the voxels they visit valid and feed each voxel's mixing weight (eq. 14). Then the data of
  the iteration is binned into the valid voxels, voxels holding more than c sqrt(2^t) samples are
  split at the middle plane (at most 3 new levels), and every valid voxel's map is reconstructed
  (normalise, then the `reconstruct` filter; with `cnn`, only the maps that received data since
  the last update) and turned into a sampling table.
- `photon`: 2^t N_p photons per iteration (N_p = `photons_per_pixel` x pixels), their power
  binned by arrival direction (eq. 10); power maps accumulate over the iterations. With
  `light_guiding` p > 0 the photons are guided toward the camera's vertices (the paper's guided
  light tracing, its Fig. 13, after Vorba et al. 2014): each voxel also keeps an importance map,
  the directions from its camera vertices back to their paths' previous vertices, and a photon
  hitting a non-delta surface there samples that map with probability p, the BSDF otherwise, its
  weight f |cos| / the mixture's pdf (so the power maps' expectation does not change).
- `grid`: each camera vertex adds radiance |cos| / pdf along its sampled direction, cos to its
  facing normal (the estimate of the incident radiance times the cosine integrated over the bin:
  practical path guiding learns the radiance alone; why: docs/guiding.md);
  the maps are rebuilt from every iteration's vertices alone.

Splitting and the weight window (`split`, `window`, `window_low`; on for `photon`, for `grid` without NEE): the
final passes split overweight paths and roulette those expected to bring little
(tracer.splitting). For the window, each voxel learns from the training records the mean
radiance that camera paths arriving in it went on to collect (splitting.outgoing); the
render adds each pixel's value from the training passes' image.

Direct light: next-event estimation already samples the light that a vertex receives straight
from the emitters, so by default (`direct` 0) the maps learn the rest: photons deposit from their
second hit on, and a camera vertex's record leaves out the emission its direction hits. With
`direct` 1, or with next-event estimation off (Guide.records_direct), the maps learn the full
incident light, as in the paper.

Sides of surfaces (`normal_classes` 6, the default): a cell holds six trees, one per class of the
normal on the side of the surface that a camera path or photon arrives on (its dominant axis and
sign). A voxel's map then holds only the light that reaches surfaces facing one way: a wall's map
no longer holds the light on the floor beside it, nor, for a thin wall, the light on its other
side, both of which lie behind the wall and send guided samples where the BSDF is zero.
`normal_classes` 1 is the paper's one map per voxel.

The schedule is Algorithm 1 (tracer/guiding/grid/schedule.py); this module learns. Mixing weights
(the probability a of BSDF sampling, per voxel) start at 0.5 and stay in [alpha_min, alpha_max]:
- `mixing` eq14 (the paper's): once a voxel has `mis_min_samples` vertices of both strategies,
  a = mean L_bsdf / (mean L_bsdf + mean L_guide), L = radiance x |f cos| of each vertex's direction.
- `mixing` variance (default): once a voxel had `mis_min_samples` vertices in an iteration, a is
  the one of N_ALPHA evenly spaced candidates whose estimate has the least second moment,
  estimated from those vertices, with the direct light weighed against next-event estimation's
  density (tracer.guiding.mixing). Eq. 14 looks at means only: where a map misses light,
  BSDF-sampled directions carry weights up to 1/a, and along a path these multiply into heavy
  tails (docs/guiding.md).
- `switch_off` (with `mixing` variance): where the chosen weights are predicted to leave more than
  `switch_off` x the second moment of BSDF sampling alone, training ends and the final passes
  sample the BSDF alone (tracer.guiding.mixing; docs/guiding.md, "A guide that does not lose").
"""
import math
import time

import numpy as np

from numba import prange

from ..._jit import jit, kernel
from ...errors import SettingsError
from ...film import Film
from ...splitting import WINDOW_SPP, observe_outgoing, outgoing
from ..base import Guide, _float, _int, window_settings
from ..directional import build_tables
from .photons import env_aim, trace_photons
from .reconstruct import RECONSTRUCTORS, Gaussian, make_reconstructor
from .spatial import HierarchicalGrid
from ..contract import empty_state
from ..mixing import VarianceMixing

COMMON = {
    "iterations": 5,  # training iterations T after the pilot pass
    "spp_init": 1,  # N_c: iteration t renders 2^t N_c spp
    "resolution": 16,  # cells along the diagonal of the pilot bounds
    "map_width": 64,  # phi bins
    "map_height": 32,  # cos(theta) bins
    "reconstruct": "gaussian",  # gaussian | pullpush | none | cnn (photon only: the trained network)
    "sigma": 1.0,  # gaussian (and cnn's dense maps): standard deviation in bins
    "cnn_max_photons": 1000.0,  # cnn: maps holding at least this many photons take the gaussian filter
    "alpha_min": 0.2,
    "alpha_max": 0.8,
    "mis_min_samples": 32,  # Q_thr of eq. 14
    "max_levels": 3,  # new tree levels per iteration at most
    "direct": 0,  # 1: maps learn direct light too; 0: only what NEE does not sample (see below)
    "mixing": "variance",  # variance: least second moment; eq14: the paper's mean-contribution ratio
    "train_budget": 0.25,  # with a time budget: pilot and training iterations end within this share of it
    "normal_classes": 6,  # 6: a voxel keeps one map per side of its surfaces (see below); 1: one map
    "split": 0.0,  # > 0: final passes split paths whose throughput exceeds this (tracer.splitting); 0: off
    "window": 0.0,  # > 0: final passes' weight window splits paths expected to bring more than this x their pixel
    "window_low": 0.2,  # ... and rouletted those expected to bring less than this x their pixel
    "window_spp": WINDOW_SPP,  # ... once the training passes hold this many samples a pixel (0: always)
    "switch_off": 1.0,  # > 0: final passes sample the BSDF alone where the guide predicts less gain (see finish_training)
    "roulette": "auto",  # Russian roulette of the guide's passes (guiding.base.ROULETTES): auto, reference without NEE
    "records": "survivors",  # what a camera record holds past the roulette (guiding.base.RECORD_KINDS)
}
MIXING = ("eq14", "variance")


@jit
def _mis_stats(node, strategy, radiance, fcos, mis_sum, mis_n):
    for i in range(node.shape[0]):
        nd = node[i]
        s = strategy[i]
        if nd < 0 or s < 0:
            continue
        mis_sum[nd, s] += radiance[i] * fcos[i]
        mis_n[nd, s] += 1.0


@kernel
def _row_sums(a, rows):
    out = np.zeros(rows.shape[0])
    for i in prange(rows.shape[0]):
        t = 0.0
        for k in range(a.shape[1]):
            t += a[rows[i], k]
        out[i] = t
    return out


@kernel
def _normalised(a, rows, totals):
    """a[rows] (float32) with every row divided by its total (positive, from _row_sums)."""
    out = np.empty((rows.shape[0], a.shape[1]), np.float32)
    for i in prange(rows.shape[0]):
        for k in range(a.shape[1]):
            out[i, k] = a[rows[i], k] / totals[i]
    return out


class HistogramGuide(Guide):
    """Shared machinery of `grid` and `photon`: the Guide contract (prepare, state, observe, update,
    schedule) over a HierarchicalGrid of per-voxel directional histograms."""

    name = "histogram"
    learns = True
    neural_maps = False  # whether the maps are photon maps, which the network was trained on
    DEFAULTS = {}
    # memory per film pixel beyond the pilot's and training iterations' films (tracer.memory):
    # the vertex records and split plan; measured by bench.memory (grid 1159, photon 2037 B/px in
    # all with 4 iterations), less the films, plus 25% with the films
    extra_pixel_bytes = 320
    fixed_bytes = 64 << 20

    @property
    def pixel_bytes(self):
        return int(1.25 * ((1 + self.iterations) * Film.bytes_per_pixel() + self.extra_pixel_bytes))

    def __init__(self, **settings):
        s = dict(self.DEFAULTS, **settings)
        self.iterations = _int("iterations", s["iterations"], 0)
        self.spp_init = _int("spp_init", s["spp_init"], 1)
        self.resolution = _int("resolution", s["resolution"], 1)
        self.map_width = _int("map_width", s["map_width"], 2)
        self.map_height = _int("map_height", s["map_height"], 1)
        self.c = _float("split_c", s["split_c"], 1.0)
        self.alpha_min = _float("alpha_min", s["alpha_min"], 0.0, 1.0)
        self.alpha_max = _float("alpha_max", s["alpha_max"], self.alpha_min, 1.0)
        self.q_thr = _float("mis_min_samples", s["mis_min_samples"], 1.0)
        self.max_levels = _int("max_levels", s["max_levels"], 0)
        self.train_budget = _float("train_budget", s["train_budget"], 0.0, 1.0)
        self.splitting = window_settings(s)
        self.learn_direct = bool(_int("direct", s["direct"], 0))
        if s["direct"] not in (0, 1):
            raise SettingsError(f"guide setting direct must be 0 or 1, got {s['direct']!r}")
        if s["mixing"] not in MIXING:
            raise SettingsError(f"guide setting mixing: unknown {s['mixing']!r}; valid: " + ", ".join(MIXING))
        self.mixing = s["mixing"]
        if s["normal_classes"] not in (1, 6) or isinstance(s["normal_classes"], bool):
            raise SettingsError(f"guide setting normal_classes must be 1 or 6, got {s['normal_classes']!r}")
        self.n_class = int(s["normal_classes"])
        self.switch_off = _float("switch_off", s["switch_off"], 0.0)  # acts with mixing variance only
        if s["reconstruct"] not in RECONSTRUCTORS:
            raise SettingsError(f"guide setting reconstruct: unknown {s['reconstruct']!r}; valid: "
                                + ", ".join(sorted(RECONSTRUCTORS)))
        extra = {}
        if s["reconstruct"] in ("gaussian", "cnn"):
            extra["sigma"] = _float("sigma", s["sigma"], 0.0, 64.0)
        if s["reconstruct"] == "cnn":
            extra["max_photons"] = _float("cnn_max_photons", s["cnn_max_photons"], 0.0)
        self.reconstructor = make_reconstructor(s["reconstruct"], **extra)
        if self.reconstructor.neural:
            if not self.neural_maps:
                raise SettingsError(f"guide {self.name!r}: reconstruct {s['reconstruct']!r} is trained on photon maps; "
                                    "it goes with guide photon")
            self.reconstructor.check_map(self.map_height, self.map_width)
        self.roulette_settings(s)
        self.settings = s
        self.grid = None

    @property
    def time_inference(self):
        """Seconds of network inference (the reconstructor's own count; 0 without a network)."""
        return self.reconstructor.time_inference

    # --- the contract ----------------------------------------------------------------------------
    def prepare(self, scene, ctx):
        """Start learning for one render: ctx carries the accel, lights, seed, depths, film size."""
        self.ctx = ctx
        self.grid = None
        self.iteration = 0
        self._state = empty_state(self.map_height, self.map_width)
        self._pilot = []
        self.time_learning = 0.0  # observing records, photons, splits (update's first part)
        self.time_update = 0.0  # rebuilding the maps between passes: reconstruct, tables, weights
        self.reconstructor.time_inference = 0.0  # network inference (reconstruct cnn); not in time_update
        self.reconstructor.maps_inferred = 0
        self.peak_memory = 0
        self.info = {"photons": 0, "deposits": 0, "photon_rays": 0, "vertices": 0, "switched_off": False,
                     "roulette": self.resolve_roulette(ctx), "window_low": self.splitting.resolve(ctx.nee),
                     "window": self.splitting.window}
        self._mixing = VarianceMixing(self.alpha_min, self.alpha_max, self.q_thr, self.switch_off,
                                      self.records_direct(ctx))

    def state(self):
        return self.with_roulette(self._state, self.grid is not None and not self.info["switched_off"])

    def observe(self, rec):
        """Vertices of one wave of camera paths (a Records view)."""
        t0 = time.perf_counter()
        if self.grid is None:
            keep = rec.strategy >= 0
            self.info["vertices"] += int(keep.sum())
            self._pilot.append({f: np.array(getattr(rec, f)[keep]) for f in ("x", "n", "wi", "pdf", "radiance")})
        else:
            g = self.grid
            self.info["vertices"] += g.visit_records(rec, self.iteration)
            _mis_stats(rec.node, rec.strategy, rec.radiance, rec.fcos, g.mis_sum, g.mis_n)
            if self.splitting.window > 0.0:
                observe_outgoing(g, rec)
            if self.mixing == "variance":
                self._mixing.observe(rec, g.alpha)
            self._observe_data(rec)
        self.time_learning += time.perf_counter() - t0

    def update(self):
        """Between passes: learn from what was observed, rebuild the maps."""
        t0 = time.perf_counter()
        if self.grid is None:
            self._initialise()
        else:
            self.grid.recycle(self.iteration)
            if self.mixing == "variance":
                self._mixing.choose(self.grid.alpha)  # before the splits, which copy a voxel's weight to its children
            self._iterate_data()
            # c sqrt(2^t) after iteration t; a shortened last iteration's own spp (schedule._fit)
            n = 2.0 ** self.iteration if self.train_spp is None else self.train_spp / self.spp_init
            self.grid.split_mid(self.c * math.sqrt(n), self.max_levels)
        t1 = time.perf_counter()
        inf0 = self.time_inference
        self.time_learning += t1 - t0
        if self.grid is not None:
            self._reconstruct()
            self._update_alpha()
            self._after_reconstruct()
            self._state = self.grid.state()
            self.peak_memory = max(self.peak_memory, self.memory_bytes())
        self.time_update += time.perf_counter() - t1 - (self.time_inference - inf0)
        self.iteration += 1

    def training_done(self):
        """Training ends early where the guide clearly does not pay (guiding.mixing)."""
        return self._mixing.training_done()

    def finish_training(self):
        """Where the guide does not pay (guiding.mixing, `switch_off`), the final passes sample the
        BSDF alone, without map lookups or splitting (stats: switched_off)."""
        if self._mixing.switched_off():
            self.info["switched_off"] = True
            self._state = empty_state(self.map_height, self.map_width)
        return self.info["switched_off"]

    def split_plan(self, films, crop):
        return None if self.info["switched_off"] else super().split_plan(films, crop)

    def fixed_state(self, sampling_map):
        """A state whose whole space is one voxel holding `sampling_map` (n_theta, n_phi) as its
        (already reconstructed) map, for the sampler contract tests."""
        m = np.asarray(sampling_map, dtype=np.float32)
        if m.shape != (self.map_height, self.map_width):
            raise SettingsError(f"map must be {self.map_height}x{self.map_width}, got {m.shape}")
        g = HierarchicalGrid(-np.ones(3), np.ones(3), 1, self.map_height, self.map_width, self.n_class)
        g.visit(np.arange(g.n_cells), 0)
        g.set_maps(g.data_slot[: g.n_cells], build_tables(np.repeat(m[None], g.n_cells, axis=0)))
        return g.state()

    def window_estimates(self):
        """Per tree node, the outgoing radiance of the weight window (splitting.outgoing); None
        before there is a grid."""
        return outgoing(self.grid) if self.grid is not None else None


    def memory_bytes(self):
        return self.grid.memory_bytes() if self.grid is not None else 0

    def stats(self):
        g = self.grid
        out = dict(self.info, predicted_ratios=[round(r, 4) for r in self._mixing.ratios])
        out.update({"name": self.name, "iterations_done": self.iteration, "settings": dict(self.settings),
                    "reconstruct": self.reconstructor.describe(),
                    "maps_inferred": int(self.reconstructor.maps_inferred),
                    "window_held_back": bool(self.splitting.held_back)})
        if g is not None:
            leaves = g.leaves()
            out.update({"cells": int(g.n_cells), "nodes": int(g.n_nodes), "voxels": int(leaves.size),
                        "valid_voxels": int((g.data_slot[leaves] >= 0).sum()),
                        "voxels_with_map": int(g.map_ok[leaves].sum()),
                        "grid_res": [int(v) for v in g.res]})
        return out

    # --- steps -------------------------------------------------------------------------------------
    def _initialise(self):
        pilot = self._pilot
        self._pilot = []
        if not pilot:
            return
        pts = {f: np.concatenate([p[f] for p in pilot]) for f in pilot[0]}
        x = pts["x"].astype(np.float64)
        if x.shape[0] == 0:
            return  # no camera vertex: no grid, BSDF sampling everywhere
        lo, hi = x.min(axis=0), x.max(axis=0)
        pad = 1e-4 * max(float(np.linalg.norm(hi - lo)), 1e-6)
        g = self.grid = HierarchicalGrid(lo - pad, hi + pad, self.resolution, self.map_height, self.map_width,
                                         self.n_class, importance=self._importance_maps_wanted())
        g.visit(g.locate(x, pts["n"]), 0)
        self._initial_data(pts)

    def _normalised_maps(self, hist):
        """(slots, maps): the slots in use whose histogram rows in `hist` have a positive total,
        and those rows divided by it, as (n, map_height, map_width) float32."""
        slots = self.grid.slots_in_use()
        if slots.size == 0:
            return slots, None
        total = _row_sums(hist, slots)
        has = total > 0.0
        slots, total = slots[has], total[has]
        if slots.size == 0:
            return slots, None
        return slots, _normalised(hist, slots, total).reshape(-1, self.map_height, self.map_width)

    def _reconstruct(self):
        g = self.grid
        slots, maps = self._normalised_maps(g.power)
        if maps is None:
            return
        rc = self.reconstructor
        if rc.neural:  # only the maps that received data since the last update
            changed = np.any(g.count[slots] != g.pcount[slots], axis=1)
            slots, maps = slots[changed], maps[changed]
            if slots.size == 0:
                return
        shape = maps.shape
        counts = g.count[slots].reshape(shape)
        rec = rc.reconstruct(maps, counts, counts > 0, g.prev[slots].reshape(shape), g.pcount[slots].reshape(shape))
        g.set_maps(slots, build_tables(rec))
        g.prev[slots] = maps.reshape(slots.size, -1)
        g.pcount[slots] = counts.reshape(slots.size, -1)

    def _update_alpha(self):
        if self.mixing != "eq14":
            return
        g = self.grid
        n = g.n_nodes
        q = g.mis_n[:n]
        ok = (q[:, 0] >= self.q_thr) & (q[:, 1] >= self.q_thr)
        mean = g.mis_sum[:n][ok] / q[ok]
        tot = mean.sum(axis=1)
        a = np.where(tot > 0, mean[:, 0] / np.where(tot > 0, tot, 1.0), 0.5)
        g.alpha[:n][ok] = np.clip(a, self.alpha_min, self.alpha_max)

    # --- what the two guides do differently ----------------------------------------------------------
    def _importance_maps_wanted(self):
        return False

    def _initial_data(self, pilot):
        raise NotImplementedError

    def _observe_data(self, rec):
        pass

    def _iterate_data(self):
        pass

    def _after_reconstruct(self):
        pass


class GridGuide(HistogramGuide):
    """`--guide grid`: maps learned from camera-path vertices (radiance |cos| / pdf per direction bin)."""

    name = "grid"
    # coarser and smoother than the photon maps: camera-path estimates (radiance |cos| / pdf) are noisier
    DEFAULTS = dict(COMMON, split_c=4000.0, resolution=8, sigma=2.0, window="auto", window_low="auto")

    def _initial_data(self, pilot):
        g = self.grid
        g.split_median(pilot["x"].astype(np.float64), self.c, self.max_levels, pilot["n"])
        g.node_count[:] = 0.0
        g.splat(g.locate(pilot["x"], pilot["n"]), pilot["wi"], pilot["n"], pilot["pdf"], pilot["radiance"])

    def _observe_data(self, rec):
        self.grid.splat_records(rec)

    def _after_reconstruct(self):
        g = self.grid  # maps are rebuilt from each iteration's vertices alone
        g.power[:] = 0.0
        g.count[:] = 0.0
        g.node_count[:] = 0.0


class PhotonGuide(HistogramGuide):
    """`--guide photon`: maps from photon power binned by arrival direction (eq. 10)."""

    name = "photon"
    neural_maps = True
    extra_pixel_bytes = 1200
    # why each default: docs/guiding.md, "Defaults and where they were measured"
    # aim_env: environment photons start only where camera paths escaped (photons.EnvAim)
    DEFAULTS = dict(COMMON, split_c=4000.0, sigma=1.0, photons_per_pixel=2.0, light_guiding=0.0, split=2.0, window=3.0,
                    window_low="auto", aim_env=1, reference_photons=0.0, reference_sigma=0.0)
    REFERENCE_ITERATION = 1 << 20  # the photon keys' iteration of the reference maps (distinct from training)
    ESCAPES_PER_WAVE = 16384  # camera records a wave tests for escapes, at most
    ESCAPES_MAX = 200000  # escaped rays kept

    def __init__(self, **settings):
        super().__init__(**settings)
        self.photons_per_pixel = _float("photons_per_pixel", self.settings["photons_per_pixel"], 0.0, 1e6)
        self.light_guiding = _float("light_guiding", self.settings["light_guiding"], 0.0, 0.95)
        self.aim_env = bool(_int("aim_env", self.settings["aim_env"], 0))
        self.reference_photons = _float("reference_photons", self.settings["reference_photons"], 0.0, 1e6)
        self.reference_sigma = _float("reference_sigma", self.settings["reference_sigma"], 0.0, 64.0)

    def prepare(self, scene, ctx):
        super().prepare(scene, ctx)
        self.info.update(env_photons=0, env_photons_traced=0, env_photons_inside=0, escapes=0)
        self._escapes = []

    def observe(self, rec):
        super().observe(rec)
        t0 = time.perf_counter()
        self._collect_escapes(rec)
        self.time_learning += time.perf_counter() - t0

    def _collect_escapes(self, rec):
        """Camera vertices whose sampled direction leaves the scene: traced again here (at most
        ESCAPES_PER_WAVE a wave, ESCAPES_MAX in all), for aim_env."""
        ctx = self.ctx
        if not self.aim_env or not ctx.lights.p_env > 0.0 or self.info["escapes"] >= self.ESCAPES_MAX:
            return
        keep = np.flatnonzero(rec.strategy >= 0)
        keep = keep[:: max(1, -(-keep.size // self.ESCAPES_PER_WAVE))]
        if keep.size == 0:
            return
        x, n, w = rec.x[keep], rec.n[keep], rec.wi[keep]
        side = np.where(np.einsum("ij,ij->i", w, n) >= 0.0, 1.0, -1.0)
        eps = 1e-5 * float(np.linalg.norm(ctx.scene.bounds[1] - ctx.scene.bounds[0]))
        prim = ctx.accel.intersect(x + (side * eps)[:, None] * n, w)[1]
        out = prim < 0
        if out.any():
            self._escapes.append((x[out].copy(), w[out].copy()))
            self.info["escapes"] += int(out.sum())

    def _aim(self):
        """The EnvAim of the escapes seen so far, or None (no aiming, or no escape seen)."""
        if not self._escapes:
            return None
        sc = self.ctx.scene
        x = np.concatenate([e[0] for e in self._escapes])
        w = np.concatenate([e[1] for e in self._escapes])
        centre = 0.5 * (sc.bounds[0] + sc.bounds[1])
        radius = 0.5 * float(np.linalg.norm(sc.bounds[1] - sc.bounds[0])) * 1.01
        return env_aim(x, w / np.linalg.norm(w, axis=1, keepdims=True), centre, radius)

    def _n_photons(self, iteration):
        """photons_per_pixel x pixels x the spp of the iteration's camera pass (train_spp where the
        schedule set it, else 2^iteration N_c)."""
        spp = self.spp_init * 2 ** iteration if iteration == 0 or self.train_spp is None else self.train_spp
        return int(round(self.photons_per_pixel * self.ctx.n_pixels * spp))

    def min_last_spp(self, prev):
        """The maps keep every iteration's photons, so a shortened last iteration adds to them: it
        runs with half the previous iteration's spp or more (below that its update's fixed costs,
        the reconstruction of every map, outweigh what it adds)."""
        return max(1, prev // 2)

    def _trace(self, iteration, sink, guided=False, n_photons=None):
        """Trace `n_photons` (default: the iteration's count) photons into sink, counted in info."""
        g = self.grid
        imp = g.state(importance=True) if guided and self.light_guiding > 0.0 else None
        n_photons = self._n_photons(iteration) if n_photons is None else int(n_photons)
        n, dep, rays, ne, nt, ni = trace_photons(
            self.ctx, g.lookup_state(), g.data_slot[: g.n_nodes], n_photons, iteration, sink,
            first_hit=self.records_direct(self.ctx), imp=imp, p_imp=self.light_guiding, aim=self._aim())
        self.info["photons"] += n
        self.info["deposits"] += dep
        self.info["photon_rays"] += rays
        self.info["env_photons"] += ne
        self.info["env_photons_traced"] += nt
        self.info["env_photons_inside"] += ni

    def _initial_data(self, pilot):
        g = self.grid
        kept = []
        self._trace(0, lambda node, b, v, x, n: kept.append((b.copy(), v.copy(), x.copy(), n.copy())))
        if not kept:
            return
        bins, val, x, n = (np.concatenate([k[j] for k in kept]) for j in range(4))
        g.split_median(x, self.c, self.max_levels, n)
        g.node_count[:] = 0.0
        g.accumulate(g.locate(x, n), bins, val)

    def _importance_maps_wanted(self):
        return self.light_guiding > 0.0

    def finish_training(self):
        """As HistogramGuide's; then, with `reference_photons` > 0 (a diagnostic), the maps are
        replaced by reference maps."""
        off = super().finish_training()
        if not off and self.reference_photons > 0.0 and self.grid is not None:
            self._reference_maps()
        return off

    def _reference_maps(self):
        """Every voxel's map rebuilt from `reference_photons` x pixels fresh photons alone (the
        voxels, mixing weights and weight window stay those the training learned), filtered by a
        Gaussian of `reference_sigma` bins (0: none). The render then shows what near-converged
        maps would give, against the reconstructed ones (docs/photon_cnn.md). Voxels that the
        reference photons miss keep their trained map (stats: reference_voxels_missed)."""
        t0 = time.perf_counter()
        g = self.grid
        g.power[:] = 0.0
        g.count[:] = 0.0
        n = int(round(self.reference_photons * self.ctx.n_pixels))
        self._trace(self.REFERENCE_ITERATION, lambda node, b, v, x, nn: g.accumulate(node, b, v), n_photons=n)
        used = g.slots_in_use()
        slots, maps = self._normalised_maps(g.power)
        if maps is not None:
            g.set_maps(slots, build_tables(Gaussian(self.reference_sigma).reconstruct(maps, None, None)))
        self._state = g.state()
        self.info.update(reference_photons=n, reference_voxels_missed=int(used.size - slots.size),
                         reference_seconds=round(time.perf_counter() - t0, 3))
        self.time_learning += time.perf_counter() - t0

    def _observe_data(self, rec):
        if self.light_guiding > 0.0:
            self.grid.splat_importance(rec)

    def _importance_maps(self):
        """Guided light tracing: the importance maps (camera vertices by direction, accumulated
        over the iterations) normalised, filtered like the radiance maps, into sampling tables."""
        g = self.grid
        slots, maps = self._normalised_maps(g.ipower)
        if maps is None:
            return
        mask = maps > 0.0
        rc = self.reconstructor.dense if self.reconstructor.neural else self.reconstructor
        rec = rc.reconstruct(maps, mask.astype(np.float32), mask)  # the network knows radiance maps only
        g.set_maps(slots, build_tables(rec), importance=True)

    def _iterate_data(self):
        g = self.grid
        if self.light_guiding > 0.0:
            self._importance_maps()
        self._trace(self.iteration, lambda node, b, v, x, n: g.accumulate(node, b, v), guided=True)
