"""`--integrator gpt`: gradient-domain path tracing (tracer.gradient) as a registered integrator.

Its final passes render base and offset paths into GradientFilms (the hybrid shift, or random
replay), 1, 2, 4, ... spp through the Session like any method's final passes (budget, waves,
callback with the base film, Ctrl-C); its result reconstructs the image from the base and its
gradients (screened Poisson L1 or L2, GradNet, or none). A guide trains by its own schedule
before these passes; with the replay shift the base and offset paths then sample the guide's
mixture (each is a path-traced sample of its own pixel, so their difference estimates the
gradient without bias). The training passes' films are not part of the image.
"""
import time

import numpy as np

from .. import gradient
from ..errors import SettingsError
from ..result import RenderResult, report_dark
from .base import AFTER_PASSES_SECONDS, Integrator


# GradNet's seconds after a render's passes, by (recon, settings, alpha, width, height): the last call's
_AFTER_PASSES = {}


class GptIntegrator(Integrator):
    """`--integrator gpt`: gradient-domain path tracing, reconstructed by `recon`.

    shift        hybrid (reconnection between vertices rougher than `roughness`, half-vector copy
                 elsewhere; every offset with its own pixel's mixture density) or replay (the same
                 random numbers from the neighbouring pixel; the default for odis, whose per-pixel
                 first-bounce maps the hybrid shift does not shift)
    direct_roughness  hybrid: the light a first vertex smoother than this (GGX alpha) reflects joins
                 the direct buffer (added after the solve, no gradients), as the light seen directly
    recon        l2 (keeps the image mean), l1 (darker at low spp), gradnet (learned; `weights`,
                 `correction` 0/1) or none (the base image); recon_alpha: the base's weight
    nee          1: next-event estimation with MIS; 0: none (replay shift only)
    """

    name = "gpt"
    DEFAULTS = {"nee": 1, "shift": "hybrid", "roughness": gradient.ROUGHNESS,
                "direct_roughness": gradient.DIRECT_ROUGHNESS, "recon": "l2", "recon_alpha": 0.2,
                **{k: v for k, v in gradient.RECON_DEFAULTS["gradnet"].items()}}
    sweeps = 1
    film_kind = "gradient"
    outputs = ("base", "dx", "dy")

    def __init__(self, **settings):
        super().__init__(**settings)
        s = self.settings
        opts = {k: self.given[k] for k in gradient.RECON_DEFAULTS["gradnet"] if k in self.given}
        self.shift, self.recon, self.recon_alpha, self.roughness, self.recon_settings, self.direct_roughness = \
            gradient.check_settings(s["shift"], s["recon"], s["recon_alpha"], s["roughness"], opts,
                                    s["direct_roughness"])
        if not self.nee and self.shift == "hybrid":
            raise SettingsError("integrator gpt: nee=0 goes with shift=replay (the hybrid shift's weights "
                                "assume next-event estimation)")
        self.films = None

    def start(self):
        self.films = None
        self._solve_reserve = 0.0

    def check_guide(self, guide, guide_name):
        if guide is None:
            return
        if self.shift == "hybrid" and guide.pixel_maps:
            if "shift" in self.given:
                raise SettingsError(f"integrator gpt: the hybrid shift takes guides without per-pixel maps; with "
                                    f"--guide {guide_name} use gpt:shift=replay")
            self.shift = "replay"  # (the default shift for a guide with per-pixel maps)
        if not guide.camera_paths:
            raise SettingsError(f"integrator gpt traces its own camera paths; guide {guide_name!r} warps them "
                                "(use integrator path)")

    def wave_bytes(self, wave):
        if self.shift != "hybrid":
            return 0
        from ..gradient.offsets import HybridBuffers

        return HybridBuffers.bytes_for(wave)

    def memory(self):
        from .. import memory

        per = memory.GPT_PIXEL_BYTES.get(self.recon, max(memory.GPT_PIXEL_BYTES.values()))
        return per, memory.GPT_FIXED_BYTES.get(self.recon, 0)

    def warm_up(self, ctx):
        gradient.warm_up(ctx, self.shift, self.roughness, self.direct_roughness)

    def kernels(self):
        if self.shift == "hybrid":  # its own (the replay shift traces through the path tracer's)
            return ("offset_shading.shade_hybrid", "offsets.shift_offsets", "offset_shading.add_next_event")
        return super().kernels()

    def _reserve_key(self, width, height):
        return self.recon, repr(sorted(self.recon_settings.items())), self.recon_alpha, int(width), int(height)

    def reserve(self, width, height):
        """The solve's share of a budget. GradNet's: what its last call after a render's passes took
        at this size and these settings (its first call after the passes is slower than the timed
        estimate: the threads the passes left wake up), else the estimate plus AFTER_PASSES_SECONDS.
        (An L1 solve ends by its share of the budget, an L2 one takes ms.)"""
        last = _AFTER_PASSES.get(self._reserve_key(width, height)) if self.recon == "gradnet" else None
        if last is not None:
            self._solve_reserve = last
        else:
            self._solve_reserve = gradient.solve_time_estimate(self.recon, width, height, self.recon_alpha,
                                                               self.recon_settings)
            if self.recon == "gradnet":
                self._solve_reserve += AFTER_PASSES_SECONDS
        return self._solve_reserve

    def stats_settings(self):
        out = {"integrator": self.name, "nee": int(self.nee), "shift": self.shift, "recon": self.recon,
               "recon_alpha": self.recon_alpha, "recon_settings": self.recon_settings}
        if self.shift == "hybrid":
            out["shift_roughness"] = self.roughness
            out["direct_roughness"] = self.direct_roughness
        return out

    # the passes
    def final_film(self, session):
        if self.films is None:
            w, h = int(session.ctx.crop[2]), int(session.ctx.crop[3])
            self.films = gradient.GradientFilms(w, h)
            self._samples0 = session.stats.samples  # the samples of the passes before (a guide's training)
            if self.shift == "hybrid":
                from ..gradient.hybrid import HybridBuffers, trace_hybrid_wave

                hb = HybridBuffers(session.buf.size)
                self._wave = lambda ctx, buf, stats, sample0, g0, n: trace_hybrid_wave(
                    ctx, buf, hb, self.films, sample0, g0, n, stats, self.roughness, self.direct_roughness)
            else:
                from ..gradient.replay import trace_gradient_wave

                self._wave = lambda ctx, buf, stats, sample0, g0, n: trace_gradient_wave(
                    ctx, buf, self.films, sample0, g0, n, stats)
        return self.films.base

    def final_pass(self, session, film, spp, split=None, source=None):
        """One pass of base and offset paths (a guide's split plan is not used: gpt never splits)."""
        ctx, buf, stats = session.ctx, session.buf, session.stats
        session.run_pass(film, spp, "gradient", deadline=True, sweeps=self.sweeps,
                         wave=lambda sample0, g0, n: self._wave(ctx, buf, stats, sample0, g0, n))

    def result(self, session, interrupted, snapshot):
        films, stats = self.films, session.stats
        if films is None:  # stopped before the first gradient pass: an empty image
            self.final_film(session)
            films = self.films
        # samples: the base paths (each traced five paths), after the passes before
        stats.samples = int(self._samples0 + films.base.count.sum())
        # with a budget, the L1 solve fills its share of it and ends by it (what is kept back after
        # it: the denoiser)
        deadline = None if session.time is None else \
            session.t_start + session.time - (session.reserve - self._solve_reserve)
        info = {}
        t0 = time.perf_counter()
        image, buffers, t_solve = gradient.solve(films, self.recon, self.recon_alpha, self.recon_settings, deadline,
                                                 info)
        if self.recon == "gradnet":  # (the buffers' means and variances included)
            _AFTER_PASSES[self._reserve_key(films.base.width, films.base.height)] = time.perf_counter() - t0
        st = snapshot()
        st["interrupted"] = interrupted
        for p_entry in st["passes"]:
            p_entry["weight"] = 1.0 if session.films[p_entry.pop("film")][0] is films.base else 0.0
        st["time_solve"] = t_solve  # included in time_total
        if "reweights" in info:
            st["l1_reweights"] = info["reweights"]
        base_mean = float(np.mean(buffers["base"], dtype=np.float64))
        # what the reconstruction did to the image's mean (l2 keeps it; l1 tends toward the median of
        # the base's samples, darker at low spp: docs/gradient.md), and its negative pixels
        st["recon_mean_change"] = float(np.mean(image, dtype=np.float64)) / base_mean - 1.0 if base_mean > 0 else 0.0
        st["negative_pixel_share"] = float((image.min(axis=2) < 0.0).mean())
        if self.recon == "gradnet":
            st["time_inference"] = t_solve  # the network and its energy correction
        report_dark(session.ctx.scene, image, st)
        return RenderResult(image.astype(np.float32), buffers["base_variance"], films.base.aovs(), st, films.base,
                            buffers)
