"""The mixing weight a (probability of BSDF sampling) per guide node, learned by least second
moment, and the guide's switch-off where BSDF sampling alone is predicted better.

Each node takes the one of N_ALPHA evenly spaced candidates in [alpha_min, alpha_max] whose
estimate has the least second moment, estimated from the node's vertices of the last iteration by
importance reweighting (`_mix_moments`). The same sums give, for BSDF sampling alone (a = 1, kept
as an extra last candidate that is never chosen), the second moment the guide would leave; their
ratio over all nodes is the iteration's `predicted_ratio`. Where it is above `switch_off` the
guide does not pay: training ends (early where EARLY_ITERATIONS iterations in a row predict more
than SWITCH_OFF_EARLY x switch_off) and the final
passes sample the BSDF alone, without map lookups or splitting. Why and what it measured:
docs/guiding.md, "A guide that does not lose".
"""
import numpy as np

from .._jit import jit

N_ALPHA = 7  # candidate mixing weights, evenly spaced over [alpha_min, alpha_max]
SWITCH_OFF_EARLY = 1.1  # training ends early where iterations predict this x switch_off ...
EARLY_ITERATIONS = 3  # ... this many in a row


@jit
def _mix_moments(node, strategy, radiance, direct, plight, full, fcos, pdf, pb, alpha, cand, mom, mom_n):
    """Per node and candidate weight c, the second moment of the vertex's estimate under the
    mixture p_c = c p_bsdf + (1 - c) p_guide, estimated from the vertices sampled with the current
    mixture p (weight alpha[node]) by importance reweighting (E_p[g / p] = integral of g).

    A vertex's light splits into the emission its direction hits directly (D, luminance, found
    by next-event estimation too, with density p_l) and the rest (I: the whole rest of the path,
    so heavy tails that the maps cause further down count too); with F = |f cos|, the integrand is
    (I F)^2 / p_c + (D F)^2 / (p_c + p_l): the second moment of the direction sample for I, and of
    the balance-heuristic combination of the direction sample with next-event estimation's for D
    (Veach 1997, 9.2.2). Where the light is one that next-event estimation finds poorly (small
    lights seen in near-specular lobes: p_l << p_bsdf) the weight thus sees that BSDF sampling
    finds it, although maps without the direct light do not hold it. `full`: the records'
    radiance includes D (RECORD_ALL), else it is I alone."""
    for i in range(node.shape[0]):
        nd = node[i]
        if nd < 0 or strategy[i] < 0:
            continue
        a = alpha[nd]
        p = pdf[i]
        if a >= 1.0 or not p > 0.0:
            continue
        pg = max((p - a * pb[i]) / (1.0 - a), 0.0)
        d = direct[i] * fcos[i]
        f = (max(radiance[i] - direct[i], 0.0) if full else radiance[i]) * fcos[i]
        mom_n[nd] += 1.0
        if not (f > 0.0 or d > 0.0):
            continue
        pl = plight[i]
        for k in range(cand.shape[0]):
            pc = cand[k] * pb[i] + (1.0 - cand[k]) * pg
            v = 0.0
            if f > 0.0:
                v += f * f / pc if pc > 0.0 else np.inf
            if d > 0.0:
                v += d * d / (pc + pl) if pc + pl > 0.0 else np.inf
            mom[nd, k] += v / p


class VarianceMixing:
    """Learns a guide's per-node mixing weights from its records (see the module docstring).

    observe(rec, alpha) adds a wave's records, sampled with the per-node weights `alpha`;
    choose(alpha) sets, in place, the weight of every node with at least `min_samples` vertices
    since the last choose() and records the iteration's predicted ratio; training_done() and
    switched_off() are the guide's answers to the schedule."""

    def __init__(self, alpha_min, alpha_max, min_samples, switch_off, full):
        self.candidates = np.append(np.linspace(alpha_min, alpha_max, N_ALPHA), 1.0)
        self.min_samples = float(min_samples)
        self.switch_off = float(switch_off)
        self.full = bool(full)
        self.ratios = []  # predicted_ratio of each iteration
        self._mom = self._n = None

    def observe(self, rec, alpha):
        if self._mom is None or self._mom.shape[0] < alpha.shape[0]:
            mom, n = np.zeros((alpha.shape[0], N_ALPHA + 1)), np.zeros(alpha.shape[0])
            if self._mom is not None:  # nodes added since (a split): their sums start at 0
                mom[: self._mom.shape[0]] = self._mom
                n[: self._n.shape[0]] = self._n
            self._mom, self._n = mom, n
        _mix_moments(rec.node, rec.strategy, rec.radiance, rec.direct, rec.plight, self.full, rec.fcos, rec.pdf,
                     rec.pb, alpha, self.candidates, self._mom, self._n)

    def choose(self, alpha):
        if self._mom is None:
            return
        ok = np.flatnonzero(self._n >= self.min_samples)
        mom = self._mom[ok]
        best = np.argmin(mom[:, :N_ALPHA], axis=1)
        alpha[ok] = self.candidates[best]
        chosen, bsdf = float(mom[np.arange(ok.size), best].sum()), float(mom[:, N_ALPHA].sum())
        if ok.size and np.isfinite(chosen) and bsdf > 0.0:
            self.ratios.append(chosen / bsdf if np.isfinite(bsdf) else 0.0)
        self._mom = self._n = None

    @property
    def predicted_ratio(self):
        """The last iteration's sum over nodes of the chosen weights' second moments over BSDF
        sampling's alone (None before one had enough vertices)."""
        return self.ratios[-1] if self.ratios else None

    def training_done(self):
        """Whether the last EARLY_ITERATIONS iterations all predicted more than SWITCH_OFF_EARLY x
        switch_off (the first ones learn from few vertices: one alone does not end training)."""
        last = self.ratios[-EARLY_ITERATIONS:]
        return (self.switch_off > 0.0 and len(last) == EARLY_ITERATIONS
                and min(last) > SWITCH_OFF_EARLY * self.switch_off)

    def switched_off(self):
        r = self.predicted_ratio
        return self.switch_off > 0.0 and r is not None and r > self.switch_off
