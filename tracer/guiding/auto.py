"""`--guide auto`: the render picks its own sampler from bsdf, grid, photon and ppg.

The schedule (AutoGuide.schedule):
1. a 1-spp pilot, unguided; every guide candidate learns from its vertices (as in Algorithm 1);
2. a trial per candidate: each guide runs the first `trial_iterations` training iterations of
   its Algorithm 1 (2 and 4 spp by default), bsdf one pass of 2^trial_iterations spp. The last
   pass of each predicts what a second of its method buys: the mean over pixels and channels of
   (sample variance) / (m^2 + 0.01), m the pixel's median over the trials' means, times
   its seconds per spp (the relMSE of bench's charts: a render of T seconds would score that over
   T), with m a robust stand-in for the reference (trial_costs);
3. the candidate with the least goes on: a guide runs the rest of its Algorithm 1 (it may still
   switch itself off), bsdf the final passes alone.

Two iterations, not one: on Mitsuba's veach-ajar (NEE on, 320x180) the guides' first iteration,
guided by maps of the 1-spp pilot, predicted 1.6-2.4x bsdf's cost, the second 0.7x for photon,
which ended 5x better than bsdf (docs/guiding.md, "auto"). The winner's trial films are its
training iterations and stay in the image as Algorithm 1 weighs them; the other candidates' trial
films get no weight (kind "discard": guides that lose may lose to heavy tails their few spp
missed, and their films would then weigh in too much). stats.guide_stats says which won and why:
each trial's spp, seconds per spp, relative variance per sample and predicted cost.
"""
import numpy as np

from ..errors import SettingsError
from .base import Guide, _int
from .contract import empty_state

CANDIDATES = ("bsdf", "grid", "photon", "ppg")
EPS = 0.01  # metrics.relmse's


class AutoGuide(Guide):
    """The sampler that picks itself among `candidates` (names joined by "+") from a trial of each:
    the first training iterations of each guide, a short pass of BSDF sampling."""

    name = "auto"
    learns = True
    DEFAULTS = {"candidates": "+".join(CANDIDATES), "trial_iterations": 2, "trials_in_image": 0}

    def __init__(self, **settings):
        from . import make_guide

        s = dict(self.DEFAULTS, **settings)
        names = str(s["candidates"]).split("+")
        bad = [n for n in names if n not in CANDIDATES]
        if bad or not names or len(set(names)) != len(names):
            raise SettingsError(f"guide setting candidates must be distinct names from {', '.join(CANDIDATES)} "
                                f"joined by +, got {s['candidates']!r}")
        self.trial_iterations = _int("trial_iterations", s["trial_iterations"], 1)
        self.trials_in_image = bool(_int("trials_in_image", s["trials_in_image"], 0))
        self.settings = s
        self.cands = {n: make_guide(n) for n in names}
        self.guides = [g for g in self.cands.values() if g is not None]
        if len({g.learn_direct for g in self.guides}) > 1:
            raise SettingsError("guide auto: candidates disagree on what their records hold (direct)")
        self.active = None  # the candidate whose state the passes sample from (None: BSDF sampling)
        self._learners = []  # the guides that observe and update after a learning pass
        self.choice, self.why, self.trials = None, "", {}

    # --- what render(), the session and tracer.memory read: the candidates' together --------------
    @property
    def learn_direct(self):
        return all(g.learn_direct for g in self.guides)

    @learn_direct.setter
    def learn_direct(self, value):
        for g in self.guides:
            g.learn_direct = value

    @property
    def splits(self):
        """Whether the final passes may split paths: any candidate that might win may."""
        return any(g.splits for g in self.guides)

    @property
    def pixel_bytes(self):
        return sum(g.pixel_bytes for g in self.guides)

    @property
    def fixed_bytes(self):
        return sum(g.fixed_bytes for g in self.guides)

    @property
    def peak_memory(self):
        return sum(g.peak_memory for g in self.guides)

    @property
    def time_learning(self):
        return sum(g.time_learning for g in self.guides)

    @property
    def time_update(self):
        return sum(g.time_update for g in self.guides)

    @property
    def time_inference(self):
        return sum(g.time_inference for g in self.guides)

    @property
    def training(self):
        """The winner's Algorithm 1 record (None before a guide has won, or where bsdf won)."""
        g = self._winner()
        return g.training if g is not None else None

    def _winner(self):
        return self.cands.get(self.choice) if self.choice is not None else None

    # --- the contract ------------------------------------------------------------------------------
    def prepare(self, scene, ctx):
        self.ctx = ctx
        for g in self.guides:
            g.prepare(scene, ctx)
        self.active, self._learners = None, []
        self.choice, self.why, self.trials = None, "", {}

    def warm_up(self, ctx):
        for g in self.guides:
            g.warm_up(ctx)

    def state(self):
        return self.active.state() if self.active is not None else empty_state()

    def records_direct(self, ctx):
        return self.learn_direct or not ctx.nee

    def observe(self, records):
        for g in self._learners:
            g.observe(records)

    def update(self):
        for g in self._learners:
            g.update()

    def split_plan(self, films, crop):
        return self.active.split_plan(films, crop) if self.active is not None else None

    def memory_bytes(self):
        return sum(g.memory_bytes() for g in self.guides)

    def stats(self):
        out = {"name": self.name, "settings": dict(self.settings), "choice": self.choice, "why": self.why,
               "trials": self.trials}
        g = self._winner()
        if g is not None:
            out["chosen"] = g.stats()
        return out

    # --- the schedule ------------------------------------------------------------------------------
    def schedule(self, session):
        from .grid.schedule import algorithm1, training_record

        names, k = list(self.cands), self.trial_iterations
        trial_spp = {n: [g.spp_init * 2 ** t for t in range(1, k + 1)] if g is not None else [2 ** k]
                     for n, g in self.cands.items()}
        need = 1 + sum(map(sum, trial_spp.values())) + 2 ** (k + 1)  # pilot, trials, a final pass
        if len(names) == 1 or (session.time is None and session.spp < need):
            self.choice = names[0] if len(names) == 1 else "bsdf"
            self.why = ("the only candidate" if len(names) == 1 else
                        f"{session.spp} spp are fewer than the {need} that the pilot, the trials and a final pass take")
            return self._go_on(session, algorithm1, None)
        if self.guides:
            session.phase("pilot")
            self._learners = list(self.guides)
            for g in self.guides:
                g.train_spp = 1
            session.run_pass(session.new_film("pilot"), 1, "pilot", learn=True)
        films, entries, tried = {}, {}, []
        for n in names:
            if tried and session.time is not None and session.elapsed() > 0.5 * session.time:
                break  # (a budget too short for every trial: the choice is among those tried)
            g = self.cands[n]
            self.active, self._learners = g, [g] if g is not None else []
            films[n] = []
            if g is not None:
                g.training = training_record(g.iterations)
            for t, spp in enumerate(trial_spp[n], 1):
                session.ctx.guide_state = self.state()
                session.phase(f"trial {n} {t}/{k}" if g is not None else "trial bsdf")
                films[n].append(session.new_film("train"))
                if g is not None:
                    g.train_spp = spp
                session.run_pass(films[n][-1], spp, "trial", learn=g is not None)
                if g is not None:
                    g.training.update(trained=t, spp=g.training["spp"] + [spp])
            entries[n] = session.passes[-1]
            tried.append(n)
        more = [f for n in tried for f in films[n][:-1]] + [f for f, kind in session.films if kind == "pilot"]
        self.trials = trial_costs({n: films[n][-1] for n in tried}, entries, more)
        self.choice = min(tried, key=lambda n: self.trials[n]["cost"])
        best = self.trials[self.choice]["cost"]
        others = ", ".join(f"{n} {self.trials[n]['cost'] / best:.2f}x" for n in tried if n != self.choice)
        self.why = (f"least predicted relMSE x seconds after {k} training iteration(s) of each guide ({others} "
                    f"of it)" + ("" if len(tried) == len(names) else
                                 f"; {', '.join(n for n in names if n not in tried)} not tried: half the budget was spent"))
        if not self.trials_in_image:
            session.discard([f for n in tried if n != self.choice for f in films[n]])
        return self._go_on(session, algorithm1, entries[self.choice])

    def _go_on(self, session, algorithm1, last):
        """Render the rest with the chosen candidate: its Algorithm 1 after its trial iterations (all
        of it where no trial ran), or for bsdf the final passes alone."""
        g = self._winner()
        self.active, self._learners = g, [g] if g is not None else []
        if g is None:
            session.ctx.guide_state = empty_state()
            return session.final_passes(None)
        if last is None:
            return algorithm1(session, g)
        return algorithm1(session, g, start=self.trial_iterations + 1, last=last)


def trial_costs(films, entries, more=()):
    """{name: {spp, seconds_per_spp, relvar, cost}} of the trial films (name -> Film, each
    candidate's last trial pass) and their passes (name -> the session's pass entry): relvar the
    mean over pixels and channels of one sample's variance over (m^2 + EPS), cost relvar x seconds
    per spp, the relMSE x seconds a render with that candidate is predicted to reach.

    m stands in for the reference: the per-pixel median of the means of these films and of
    `more` (the pilot's and the earlier trial passes' films), blurred over 3 x 3 pixels. A plain
    mean over the films would hold each film's own bright outliers, which then divide themselves
    away (on veach-ajar it ranked photon 2.5x worse than bsdf, where against the reference it is
    0.75x; the median and blur gave 0.78x)."""
    means = np.array([f.mean() for f in list(films.values()) + list(more)])
    m = _box3(np.median(means, axis=0))
    out = {}
    for n, f in films.items():
        e = entries[n]
        spp = f.count.reshape(m.shape[:2])[..., None]
        rel = float(np.mean(f.variance() * spp / (m * m + EPS)))
        sec = e["time"] / e["spp"]
        out[n] = {"spp": int(e["spp"]), "seconds_per_spp": round(sec, 5), "relvar": rel, "cost": rel * sec}
    return out


def _box3(img):
    """(H, W, C) averaged over each pixel's 3 x 3 neighbourhood (edges: the pixels inside)."""
    h, w = img.shape[:2]
    pad = np.pad(img, ((1, 1), (1, 1), (0, 0)))
    ones = np.pad(np.ones((h, w, 1)), ((1, 1), (1, 1), (0, 0)))
    total = sum(pad[i:i + h, j:j + w] for i in range(3) for j in range(3))
    count = sum(ones[i:i + h, j:j + w] for i in range(3) for j in range(3))
    return total / count
