"""`ppg`: Practical Path Guiding (Müller, Gross and Novák 2017), the baseline guiding papers compare
against: an SD-tree (tracer.guiding.sdtree) learned from camera paths over iterations of doubling
spp (the schedule of tracer.guiding.grid.schedule), sampled one-sample-MIS with the BSDF.

Each camera vertex splats its incident radiance estimate L_i / pdf (luminance) into the D-tree of
its spatial leaf, at its sampled direction (nearest filters by default; `spatial_filter`
"stochastic" and `directional_filter` "box" are the 2019 notes' filters, tracer.guiding.sdtree).
After each iteration the trees are built and become the sampling trees, spatial leaves holding more
than c sqrt(spp / split_spp) records split (spp: the iteration's samples per pixel; split_spp 2 is
the reference's c sqrt(2^(k+1)) after its iteration k of 4 x 2^k spp), and the next building trees
are refined where a quadrant holds more than `rho` of its tree's energy. A leaf whose tree holds no
energy samples the uniform density (`empty` uniform, the reference's) or the BSDF alone (`empty`
bsdf). The BSDF's probability is learned per leaf (`learn_alpha`, guiding.mixing) or `alpha`
everywhere (0.8: the paper's 0.5 makes fireflies here, docs/ppg.md).

With NEE off, Russian roulette is the reference's (`roulette` auto, guiding.base): drawn after
the sampled ray, once the emission it hits is counted, surviving with 0.99 once the trees exist;
the path tracer's roulette starves the trees of the long paths that carry light (docs/ppg.md,
"Faithful to the reference"). With NEE on it is the path tracer's. The final passes play the
weight window (`window` 3, `window_low` auto; tracer.splitting) with each leaf's outgoing radiance,
and may split by throughput (`split`). The image
weighs every iteration in by inverse variance (`image` all) or is the final passes alone (`image`
final, as the reference keeps its last iteration). With `direct` 0 (NEE on, the default) the
records leave out the emission their direction hits (NEE samples it), PPG's "always" mode; with
NEE off they carry it all. docs/ppg.md.
"""
import math
import time

import numpy as np

from ..errors import SettingsError
from ..film import Film
from ..splitting import WINDOW_SPP, observe_outgoing, outgoing
from .base import Guide, _float, _int, window_settings
from .contract import QUADTREE, empty_state
from .mixing import VarianceMixing
from .sdtree import SDTree


class PPGGuide(Guide):
    """Practical Path Guiding (Müller et al. 2017): an SD-tree of directional quadtrees learned from
    camera paths over iterations of doubling spp, mixed with the BSDF (probability alpha)."""

    name = "ppg"
    learns = True
    # learn_alpha 1: per spatial leaf, the weight of least second moment in [alpha_min, alpha_max]
    # (guiding.mixing, as the histogram guides'; the 2019 notes' learned fraction); 0: alpha everywhere
    DEFAULTS = {"iterations": 12, "spp_init": 1, "train_budget": 0.5, "split_c": 12000.0, "rho": 0.01,
                "max_depth": 20, "alpha": 0.8, "direct": 0, "learn_alpha": 1, "alpha_min": 0.2, "alpha_max": 0.8,
                "mis_min_samples": 32, "switch_off": 1.0, "spatial_filter": "nearest", "directional_filter": "nearest",
                "roulette": "auto", "records": "unbiased", "split_spp": 2, "image": "all", "empty": "uniform",
                "split": 0.0, "window": 3.0, "window_low": "auto", "window_spp": WINDOW_SPP}
    FILTERS = {"spatial_filter": ("nearest", "stochastic"), "directional_filter": ("nearest", "box"),
               "image": ("all", "final"), "empty": ("bsdf", "uniform")}
    fixed_bytes = 64 << 20

    @property
    def pixel_bytes(self):
        """The training iterations' films and the vertex records (as the histogram guides)."""
        return int(1.25 * ((1 + self.iterations) * Film.bytes_per_pixel() + 320))

    def __init__(self, **settings):
        s = dict(self.DEFAULTS, **settings)
        self.iterations = _int("iterations", s["iterations"], 0)
        self.spp_init = _int("spp_init", s["spp_init"], 1)
        self.train_budget = _float("train_budget", s["train_budget"], 0.0, 1.0)
        self.c = _float("split_c", s["split_c"], 1.0)
        self.rho = _float("rho", s["rho"], 0.0, 1.0)
        self.max_depth = _int("max_depth", s["max_depth"], 1)
        if self.max_depth > 20:
            raise SettingsError(f"guide setting max_depth must be at most 20, got {self.max_depth}")
        self.alpha = _float("alpha", s["alpha"], 0.0, 1.0)
        if s["direct"] not in (0, 1) or isinstance(s["direct"], bool):
            raise SettingsError(f"guide setting direct must be 0 or 1, got {s['direct']!r}")
        self.learn_direct = bool(s["direct"])
        if s["learn_alpha"] not in (0, 1) or isinstance(s["learn_alpha"], bool):
            raise SettingsError(f"guide setting learn_alpha must be 0 or 1, got {s['learn_alpha']!r}")
        self.learn_alpha = bool(s["learn_alpha"])
        self.alpha_min = _float("alpha_min", s["alpha_min"], 0.0, 1.0)
        self.alpha_max = _float("alpha_max", s["alpha_max"], self.alpha_min, 1.0)
        self.q_thr = _float("mis_min_samples", s["mis_min_samples"], 1.0)
        self.switch_off = _float("switch_off", s["switch_off"], 0.0)
        for key, allowed in self.FILTERS.items():
            if s[key] not in allowed:
                raise SettingsError(f"guide setting {key} must be one of {', '.join(allowed)}, got {s[key]!r}")
        self.split_spp = _float("split_spp", s["split_spp"], 1.0)
        self.splitting = window_settings(s)
        self.roulette_settings(s)
        self.settings = s
        self.grid = None

    def prepare(self, scene, ctx):
        self.bounds = np.asarray(scene.bounds, np.float64)
        self._seed = ctx.seed
        self.grid = None  # the SD-tree, once a record arrived
        self.iteration = 0
        self._spp = 1  # samples per pixel of the pass being recorded (the pilot's)
        self._state = empty_state()
        self.time_learning = self.time_update = 0.0
        self.peak_memory = 0
        self.info = {"vertices": 0, "switched_off": False, "roulette": self.resolve_roulette(ctx), "records": [],
                     "window_low": self.splitting.resolve(ctx.nee)}
        self._alpha = np.full(1, self.alpha)  # per SD-tree node
        self._out = _Outgoing()  # per SD-tree node, the weight window's outgoing radiance
        self._mixing = (VarianceMixing(self.alpha_min, self.alpha_max, self.q_thr, self.switch_off,
                                       self.records_direct(ctx))
                        if self.learn_alpha else None)

    def warm_up(self, ctx):
        t = SDTree(np.zeros(3), np.ones(3), self.rho, self.max_depth,
                   directional_filter=self.settings["directional_filter"])
        t.record(np.full((1, 3), 0.5), np.array([[0.0, 0.0, 1.0]]), np.ones(1))
        t.step(0.5)
        self._export(t)

    def state(self):
        return self.with_roulette(self._state, self.grid is not None and not self.info["switched_off"])

    @property
    def training_in_image(self):
        """Whether the image weighs the training iterations in (`image` all) or is made of the final
        passes alone (`image` final)."""
        return self.settings["image"] == "all"

    def observe(self, rec):
        t0 = time.perf_counter()
        keep = (rec.strategy >= 0) & (rec.pdf > 0)
        if keep.any():
            if self.grid is None:
                lo, hi = self.bounds
                pad = 1e-4 * max(float(np.linalg.norm(hi - lo)), 1e-6)
                self.grid = SDTree(lo - pad, hi + pad, self.rho, self.max_depth,
                                   spatial_filter=self.settings["spatial_filter"],
                                   directional_filter=self.settings["directional_filter"], seed=self._seed)
            energy = rec.radiance[keep].astype(np.float64) / rec.pdf[keep].astype(np.float64)
            per = self.info["records"]  # per pass recorded (the pilot first): records, and those that carry light
            while len(per) <= self.iteration:
                per.append([0, 0])
            per[self.iteration][0] += int(energy.size)
            per[self.iteration][1] += int((energy > 0.0).sum())
            self.grid.record(rec.x[keep].astype(np.float64), rec.wi[keep].astype(np.float64), energy)
            self.info["vertices"] += int(keep.sum())
            if self._mixing is not None:
                self._mixing.observe(rec, self._alpha)
            if self.splitting.window > 0.0:
                observe_outgoing(self._out, rec)
        self.time_learning += time.perf_counter() - t0

    def update(self):
        t0 = time.perf_counter()
        if self.grid is not None:
            if self._mixing is not None:
                self._alpha = _grown(self._alpha, self.grid.child.size, self.alpha)
                self._mixing.choose(self._alpha)  # before the split: children take their parent's weight
            old = self.grid.child.size
            spp = self._spp if self.train_spp is None else self.train_spp  # the schedule's, where it ran one
            self.grid.step(self.c * math.sqrt(spp / self.split_spp))
            self._alpha = _inherited(_grown(self._alpha, self.grid.child.size, self.alpha), self.grid.child, old)
            self._out.grow(self.grid.child, old)
            self._state = self._export(self.grid, self._alpha)
            self.peak_memory = max(self.peak_memory, self.memory_bytes())
        self.iteration += 1
        self._spp = self.spp_init * 2 ** self.iteration  # the next training iteration's spp
        self.time_update += time.perf_counter() - t0

    def training_done(self):
        """Training ends early where the guide clearly does not pay (guiding.mixing)."""
        return self._mixing is not None and self._mixing.training_done()

    def finish_training(self):
        """Where the guide does not pay (guiding.mixing, `switch_off`), the final passes sample the
        BSDF alone (stats: switched_off)."""
        if self._mixing is not None and self._mixing.switched_off():
            self.info["switched_off"] = True
            self._state = empty_state()
        return self.info["switched_off"]

    def window_estimates(self):
        """Per SD-tree node, the weight window's outgoing radiance (splitting.outgoing); None
        before there is a tree."""
        return outgoing(self._out) if self.grid is not None else None

    def split_plan(self, films, crop):
        return None if self.info["switched_off"] else super().split_plan(films, crop)

    def _export(self, tree, alpha=None, empty=None):
        empty = self.settings["empty"] if empty is None else empty
        child, axis, split, slot, qc, qv, roots = tree.export(empty == "uniform")
        s = 1.0 / tree.side
        alpha = np.full(child.size, self.alpha) if alpha is None else np.ascontiguousarray(alpha[: child.size])
        return empty_state()._replace(
            lo=tree.lo.copy(), inv_cell=np.full(3, s), res=np.ones(3, np.int64), child=child, axis=axis, split=split,
            slot=slot, alpha=alpha, family=QUADTREE, qt_child=np.ascontiguousarray(qc),
            qt_value=np.ascontiguousarray(qv), qt_root=np.ascontiguousarray(roots))

    def fixed_state(self, sampling_map):
        """A state whose whole space (the cube [-1, 1]^3) is one leaf whose tree holds the map
        (n_theta, n_phi), both powers of two, rows in z and columns in phi as guiding.directional's,
        for the sampler contract tests (an all-zero map is no map, whatever `empty` says)."""
        m = np.asarray(sampling_map, dtype=np.float64)
        h, w = m.shape
        if h & (h - 1) or w & (w - 1):
            raise SettingsError(f"ppg's fixed map needs power-of-two sides, got {m.shape}")
        r = max(h, w)
        leaves = np.repeat(np.repeat(m, r // h, axis=0), r // w, axis=1) / (r * r)  # (u index, v index)
        child, value = [], []

        def node(a, b, size):  # the square [a, a + size) x [b, b + size) in leaf units
            k = len(child)
            child.append([-1] * 4)
            value.append([0.0] * 4)
            h2 = size // 2
            for i, (da, db) in enumerate(((0, 0), (h2, 0), (0, h2), (h2, h2))):
                if h2 == 1:
                    value[k][i] = float(leaves[a + da, b + db])
                else:
                    c = node(a + da, b + db, h2)
                    child[k][i] = c
                    value[k][i] = float(np.sum(value[c]))
            return k

        node(0, 0, r)
        tree = SDTree(-np.ones(3), np.ones(3), self.rho, self.max_depth)
        tree.sampling[0] = (np.array(child, np.int32), np.array(value))
        return self._export(tree, empty="bsdf")  # an all-zero map is no map

    def memory_bytes(self):
        t = self.grid
        if t is None:
            return 0
        trees = {id(c): c.nbytes + v.nbytes for c, v in t.sampling + t.building}
        return int(sum(trees.values()) + t.child.nbytes * 6)

    def stats(self):
        out = dict(self.info)
        out.update({"name": self.name, "iterations_done": self.iteration, "settings": dict(self.settings),
                    "lit_share": [round(lit / max(n, 1), 5) for n, lit in self.info["records"]],
                    "window_held_back": bool(self.splitting.held_back)})
        if self._mixing is not None:
            out["predicted_ratios"] = [round(r, 4) for r in self._mixing.ratios]
        t = self.grid
        if t is not None:
            slot = t.export()[3]
            leaves = t.leaves
            out.update({"voxels": int(leaves.size), "voxels_with_map": int((slot[leaves] >= 0).sum()),
                        "dtree_nodes": int(sum(t.sampling[i][0].shape[0] for i in leaves))})
        return out


class _Outgoing:
    """What splitting.observe_outgoing and splitting.outgoing read, per SD-tree node: the sum and
    count of the radiance camera paths arriving in a leaf went on to collect."""

    def __init__(self):
        self.out_sum, self.out_n, self.n_nodes = np.zeros(1), np.zeros(1), 1

    def grow(self, child, old):
        """Extend to the tree's nodes; each node made by the last split (index `old` on) takes half
        its parent's sum and count (the same mean)."""
        n = child.size
        if n <= self.n_nodes:
            return
        self.out_sum = _inherited(_grown(self.out_sum, n, 0.0), child, old, 0.5)
        self.out_n = _inherited(_grown(self.out_n, n, 0.0), child, old, 0.5)
        self.n_nodes = n


def _grown(alpha, n, fill):
    """alpha (per SD-tree node) extended to n nodes with `fill`."""
    return alpha if alpha.size >= n else np.concatenate([alpha, np.full(n - alpha.size, fill)])


def _inherited(values, child, old, share=1.0):
    """`values` (per SD-tree node) with the nodes made by the last split (index `old` on) given
    `share` times their parent's value (children are appended after their parent, so one pass in
    index order reaches grandchildren)."""
    out = values.copy()
    for i in np.flatnonzero(child >= 0):
        c = child[i]
        if c >= old:
            out[c] = out[c + 1] = share * out[i]
    return out
