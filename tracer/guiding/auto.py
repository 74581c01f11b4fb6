"""`--guide auto`: the render picks its own sampler from bsdf, grid, photon and ppg.

The schedule (AutoGuide.schedule):
1. a 1-spp pilot, unguided, that every guide candidate learns from (the path tracer's roulette;
   records past it as X / q where a candidate records so);
2. a trial per candidate: each guide runs the first `trial_iterations` training iterations of
   its Algorithm 1 (2 and 4 spp by default), bsdf one pass of 2^trial_iterations spp. Every
   trial runs on the wavefront (a guide's records need it) and its seconds leave out the time
   the guide spent observing, so the speeds compare. The last pass of each predicts what a
   second of its method buys: the mean over pixels and channels of (sample variance) /
   (m^2 + 0.01), m a stand-in for the reference (trial_costs), times its seconds per spp (the
   relMSE of bench's charts: a render of T seconds would score that over T). With a time budget
   a trial runs only while it fits in half of what is left; the choice is among those tried;
3. the candidate with the least goes on: a guide runs the rest of its Algorithm 1 (it may still
   switch itself off), bsdf the final passes alone.

Two iterations, not one: on Mitsuba's veach-ajar (NEE on, 320x180) the guides' first iteration,
guided by maps of the 1-spp pilot, predicted 1.6-2.4x bsdf's cost, the second 0.7x for photon,
which ended 5x better than bsdf (docs/guiding.md, "auto"). The films the choice was made from
(each candidate's last trial) get no weight in the image: picked for a small variance, the
winner's leans toward draws that missed the bright tails. The winner's earlier trial iterations
stay, as its Algorithm 1 weighs them; the losers' get no weight either (kind "discard"; with
`trials_in_image` 1 they count). stats.guide_stats says which won and why: each trial's spp,
seconds per spp, relative variance per sample and predicted cost.
"""
import time

import numpy as np

from ..errors import SettingsError
from .base import Guide, _int
from .contract import empty_state

CANDIDATES = ("bsdf", "grid", "photon", "ppg")
EPS = 0.01  # metrics.relmse's


def _summed(name):
    """A read-only property: the sum of attribute `name` over the candidate guides."""
    return property(lambda self: sum(getattr(g, name) for g in self.guides))


class AutoGuide(Guide):
    """The sampler that picks itself among `candidates` (names joined by "+") from a trial of each:
    the first training iterations of each guide, a short pass of BSDF sampling."""

    name = "auto"
    learns = True
    records_loop = "wave"
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
        most = min((g.iterations for g in self.guides), default=self.trial_iterations)
        if self.trial_iterations > most:
            raise SettingsError(f"guide setting trial_iterations must be at most {most} (the candidates' "
                                f"iterations), got {self.trial_iterations}")
        if len({g.learn_direct for g in self.guides}) > 1:
            raise SettingsError("guide auto: candidates disagree on what their records hold (direct)")
        self.active = None  # the candidate whose state the passes sample from (None: BSDF sampling)
        self._learners = []  # the guides that observe and update after a learning pass
        self._observed = 0.0  # seconds the learners spent observing in the current pass
        self.choice, self.why, self.trials = None, "", {}

    # --- what render(), the session and tracer.memory read: the candidates' together --------------
    @property
    def learn_direct(self):
        return all(g.learn_direct for g in self.guides)

    @learn_direct.setter
    def learn_direct(self, value):
        for g in self.guides:
            g.learn_direct = value

    # what the budget, memory and statistics count: every candidate's (all of them learned)
    pixel_bytes = _summed("pixel_bytes")
    fixed_bytes = _summed("fixed_bytes")
    peak_memory = _summed("peak_memory")
    time_learning = _summed("time_learning")
    time_update = _summed("time_update")
    time_inference = _summed("time_inference")

    @property
    def splits(self):
        """Whether the final passes may split paths: any candidate that might win may."""
        return any(g.splits for g in self.guides)

    def follow_nee(self, nee):
        for g in self.guides:
            g.follow_nee(nee)

    @property
    def training(self):
        """The winner's Algorithm 1 record (None before a guide has won, or where bsdf won)."""
        g = self.winner()
        return g.training if g is not None else None

    def winner(self):
        """The guide the last render chose (None: bsdf, or no render yet)."""
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

    def observe(self, records):
        t0 = time.perf_counter()
        for g in self._learners:
            g.observe(records)
        self._observed += time.perf_counter() - t0

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
        g = self.winner()
        if g is not None:
            out["chosen"] = g.stats()
        return out

    # --- the schedule ------------------------------------------------------------------------------
    def schedule(self, session):
        from .grid.schedule import algorithm1, training_record

        names, k = list(self.cands), self.trial_iterations
        fallback = "bsdf" if "bsdf" in self.cands else names[0]
        trial_spp = {n: [g.spp_init * 2 ** t for t in range(1, k + 1)] if g is not None else [2 ** k]
                     for n, g in self.cands.items()}
        need = 1 + sum(map(sum, trial_spp.values())) + 2 ** (k + 1)  # pilot, trials, a final pass
        if len(names) == 1 or (session.time is None and session.spp < need):
            self.choice = names[0] if len(names) == 1 else fallback
            self.why = ("the only candidate" if len(names) == 1 else
                        f"{session.spp} spp are fewer than the {need} that the pilot, the trials and a final pass take")
            return self._go_on(session, algorithm1, None)
        pilot = None
        if self.guides:
            session.phase("pilot")
            self._learners = list(self.guides)
            for g in self.guides:
                g.train_spp = 1
            session.ctx.guide_state = self._pilot_state()
            session.run_pass(session.new_film("pilot"), 1, "pilot", learn=True)
            pilot = session.passes[-1]
        films, entries, tried = {}, {}, []
        for n in names:
            if not self._trial_fits(session, pilot, entries, sum(trial_spp[n])):
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
                entries[n] = self._trial_pass(session, films[n][-1], spp, g)
                if g is not None:
                    g.training.update(trained=t, spp=g.training["spp"] + [spp])
            tried.append(n)
        if not tried:
            self.choice = fallback
            self.why = f"the {session.time:g}-s budget is too short for a trial"
            return self._go_on(session, algorithm1, pilot, start=1)
        more = [f for n in tried for f in films[n][:-1]] + [f for f, kind in session.films if kind == "pilot"]
        self.trials = trial_costs({n: films[n][-1] for n in tried}, entries, more)
        self.choice, self.why = _choose(self.trials, tried, fallback)
        if len(tried) < len(names):
            self.why += f"; {', '.join(n for n in names if n not in tried)} not tried: half the budget was spent"
        # the films the choice was made from get no weight (picked for a small variance, they lean
        # toward draws that missed the bright tails); the winner's earlier trial iterations keep theirs
        drop = [f for n in tried if n != self.choice for f in films[n]] if not self.trials_in_image else []
        session.discard(drop + [films[self.choice][-1]])
        return self._go_on(session, algorithm1, entries[self.choice], start=len(trial_spp[self.choice]) + 1)

    def _pilot_state(self):
        """The shared pilot's state: no maps, with the records past the roulette as X / q where a
        candidate records so (ppg's default), the path tracer's roulette."""
        rec_q = int(any(g.records == "unbiased" for g in self.guides))
        return empty_state()._replace(rec_q=rec_q)

    def _trial_fits(self, session, pilot, entries, spp):
        """Whether a trial of `spp` spp fits in half the budget left for passes (always with an spp
        budget), at the slowest seconds per spp of the trials so far (before any: twice the
        pilot's; with neither, it is tried)."""
        if session.time is None:
            return True
        rates = [e["time"] / e["spp"] for e in entries.values()]
        if not rates and pilot is not None:
            rates = [2.0 * pilot["time"] / pilot["spp"]]
        est = max(rates, default=0.0) * spp
        return session.elapsed() + est <= 0.5 * (session.time - session.reserve)

    def _trial_pass(self, session, film, spp, g):
        """Run one trial pass of candidate g (None: bsdf) into film; returns {spp, time}: the pass's
        seconds without the time the guide spent observing its records. Every trial runs on the
        wavefront (records_loop), bsdf's too, so that their speeds compare on one loop."""
        self._observed = 0.0
        session.run_pass(film, spp, "trial", learn=g is not None, path_loop=self.records_loop)
        e = session.passes[-1]
        return {"spp": e["spp"], "time": max(e["time"] - self._observed, 1e-9),
                "time_update": e.get("time_update", 0.0)}

    def _go_on(self, session, algorithm1, last, start=1):
        """Render the rest with the chosen candidate: a guide its Algorithm 1 from iteration `start`
        after `last` (the session's entry of its latest training pass or of the shared pilot;
        None: all of it, pilot first), bsdf the final passes alone."""
        g = self.winner()
        self.active, self._learners = g, [g] if g is not None else []
        if g is None:
            session.ctx.guide_state = empty_state()
            return session.final_passes(None)
        if last is None or start == 1:
            g.training = None
        session.ctx.guide_state = g.state()  # (the last pass sampled from the last candidate tried)
        return algorithm1(session, g, start=start, last=last)


def _choose(trials, tried, fallback):
    """(choice, why) from trial_costs' figures: the least cost; a trial with no variance at all saw
    nothing (a black image, or no light found) and wins only where every trial saw nothing."""
    cost = {n: trials[n]["cost"] if trials[n]["relvar"] > 0.0 else np.inf for n in tried}
    if not np.isfinite(min(cost.values())):
        return (fallback if fallback in tried else tried[0]), "no trial saw any light"
    choice = min(tried, key=cost.get)
    best = cost[choice]
    others = ", ".join(f"{n} {cost[n] / best:.2f}x" for n in tried if n != choice)
    return choice, (f"least predicted relMSE x seconds after the trials" + (f" ({others} of it)" if others else ""))


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
