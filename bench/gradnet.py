"""GradNet against the screened Poisson solves and plain path tracing, on the same samples.

    python -m bench.gradnet --scenes cornell,ajar,glossy,veach-ajar,cornell-glass-sphere \\
        --scene-dir ../shared/scenes --spp 32,128,512 --seeds 3

For every scene, seed and spp: one `--integrator gpt --recon none` render, whose buffers are then
reconstructed every way (tracer.gradient.reconstruct_buffers on the float32 buffers, each timed): `gpt-l1`, `gpt-l2`
(screened Poisson, alpha 0.2), `gpt-gradnet` (with eq. 13's energy correction), `gpt-gradnet-raw`
(without), `gpt-base` (the noisy base image); and one `bsdf` path render at the same spp. A method's
time is the gpt render's plus its reconstruction's (bsdf: its own render). The same samples under
every reconstruction make the equal-spp comparison exact: the differences are the
reconstructions'. (bench.convergence runs the same methods as separate renders, `gpt-gradnet` among
them.)

Writes to --out (default bench/results/gradnet/): records.jsonl (one record per scene, seed, spp
and method: seconds, metrics against the reference of bench.reference) and summary.md: per scene
and spp the median over seeds of relMSE and 1-SSIM, the ratio of each method's relMSE to gpt-l1's
and to bsdf's; and at equal time, each method's relMSE interpolated (log-log, between its spp
points, medians over seeds) at the times gpt-l1 took, over gpt-l1's and over bsdf's (bsdf's
extrapolated as 1 / time beyond its longest run, which at equal spp is about 5x shorter). Cells
run the smallest spp of every scene first, and a rerun skips the cells records.jsonl holds (with
all of them there, it rewrites the summary without rendering).
"""
import argparse
import os

import numpy as np

import tracer
from tracer import gradient, metrics

from .cells import run_cells
from .reference import ROOT

RECONS = {"gpt-l1": ("l1", None), "gpt-l2": ("l2", None), "gpt-gradnet": ("gradnet", {"correction": 1}),
          "gpt-gradnet-raw": ("gradnet", {"correction": 0}),
          "gpt-gradnet-v2": ("gradnet", {"correction": 1, "weights": "gradnet_v2"}), "gpt-base": ("none", None)}
METHODS = tuple(RECONS) + ("bsdf",)
ALPHA = 0.2


def run_cell(scene, seed, spp, ref, weights="gradnet"):
    """The records of one scene, seed and spp: every reconstruction of one gpt render, and bsdf."""
    g = tracer.render(scene, spp=spp, seed=seed, integrator="gpt", recon="none")
    t_render = g.stats["time_total"]
    out = []
    for method, (recon, opts) in RECONS.items():
        if opts is not None:
            opts = dict({"weights": weights}, **opts)  # (a method that names its weights keeps them)
        image, secs = gradient.reconstruct_buffers(g.buffers, recon, ALPHA, opts)
        out.append({"method": method, "seed": seed, "spp": spp, "time_total": t_render + secs, "solve_s": secs,
                    "nonfinite_samples": g.stats["nonfinite_samples"], "finite": bool(np.isfinite(image).all()),
                    "metrics": metrics.all_metrics(image, ref)})
    p = tracer.render(scene, spp=spp, seed=seed)
    out.append({"method": "bsdf", "seed": seed, "spp": spp, "time_total": p.stats["time_total"], "solve_s": 0.0,
                "nonfinite_samples": p.stats["nonfinite_samples"], "finite": bool(np.isfinite(p.image).all()),
                "metrics": metrics.all_metrics(p.image, ref)})
    return out


def _median(records, method, spp, key):
    v = [r["metrics"][key] if key in r["metrics"] else r[key] for r in records
         if r["method"] == method and r["spp"] == spp]
    return float(np.median(v)) if v else float("nan")


def equal_time(records, method, t):
    """The method's median relMSE interpolated at time t (log-log between its spp points); beyond
    its longest run, bsdf's (unbiased Monte Carlo: error proportional to 1 / time) is extrapolated
    from that run; up to 5% beyond its longest run, that run's (a faster reconstruction of the same
    render); nan elsewhere outside the times the method reached."""
    spps = sorted({r["spp"] for r in records if r["method"] == method})
    ts = np.log([_median(records, method, s, "time_total") for s in spps])
    es = np.log([_median(records, method, s, "relMSE") for s in spps])
    order = np.argsort(ts)  # np.interp needs increasing times
    ts, es = ts[order], es[order]
    if len(ts) and method == "bsdf" and np.log(t) > ts[-1]:
        return float(np.exp(es[-1] + ts[-1] - np.log(t)))
    if len(ts) and ts[-1] < np.log(t) <= ts[-1] + np.log(1.05):
        return float(np.exp(es[-1]))  # a reconstruction a little faster than l1's: its longest run
    if not len(ts) or not ts[0] <= np.log(t) <= ts[-1]:
        return float("nan")
    return float(np.exp(np.interp(np.log(t), ts, es)))


def summary(records, meta):
    lines = [f"# GradNet against screened Poisson and path tracing ({meta['machine']})", "",
             f"Command: `{meta['command']}`. Medians over {meta['seeds']} seeds. Ratios are relMSE over gpt-l1's "
             "(`/l1`) and over bsdf's (`/bsdf`); time is the render's plus the reconstruction's, in seconds.", ""]
    for scene in sorted({r["scene"] for r in records}):
        rs = [r for r in records if r["scene"] == scene]
        spps = sorted({r["spp"] for r in rs})
        lines += [f"## {scene}", "", "| spp | method | time s | solve s | relMSE | /l1 | /bsdf | 1-SSIM |",
                  "|---|---|---|---|---|---|---|---|"]
        for spp in spps:
            l1, bsdf = _median(rs, "gpt-l1", spp, "relMSE"), _median(rs, "bsdf", spp, "relMSE")
            for m in METHODS:
                e = _median(rs, m, spp, "relMSE")
                ratio = lambda d: f"{e / d:.2f}" if d > 0 else "-"  # noqa: E731
                lines.append(f"| {spp} | {m} | {_median(rs, m, spp, 'time_total'):.2f} | {_median(rs, m, spp, 'solve_s'):.3f} "
                             f"| {e:.4g} | {ratio(l1)} | {ratio(bsdf)} | {_median(rs, m, spp, '1-SSIM'):.4f} |")
        lines += ["", "Equal time (relMSE interpolated at gpt-l1's times; bsdf extrapolated as 1 / time):", "",
                  "| time s | " + " | ".join(f"{m} /l1 | {m} /bsdf" for m in ("gpt-gradnet", "gpt-gradnet-v2", "gpt-l2", "gpt-base")) + " |",
                  "|---" * 9 + "|"]
        for spp in spps:
            t = _median(rs, "gpt-l1", spp, "time_total")
            l1, bsdf = equal_time(rs, "gpt-l1", t), equal_time(rs, "bsdf", t)
            cells = []
            for m in ("gpt-gradnet", "gpt-gradnet-v2", "gpt-l2", "gpt-base"):
                e = equal_time(rs, m, t)
                cells += [f"{e / l1:.2f}", f"{e / bsdf:.2f}"]
            lines.append(f"| {t:.1f} | " + " | ".join(c.replace("nan", "-") for c in cells) + " |")
        lines.append("")
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.gradnet", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default="cornell,ajar,glossy,veach-ajar,cornell-glass-sphere")
    p.add_argument("--scene-dir", default=None, help="folder of external scenes (<name>/scene.obj)")
    p.add_argument("--spp", default="32,128,512")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--weights", default="gradnet", help="GradNet weights name (tracer/weights)")
    p.add_argument("--out", default=os.path.join(ROOT, "bench", "results", "gradnet"))
    a = p.parse_args(argv)
    return run_cells("bench.gradnet", argv, a, lambda scene, seed, spp, ref: run_cell(scene, seed, spp, ref, a.weights),
                     lambda cell: ", ".join(f"{r['method']} {r['metrics']['relMSE']:.4g}" for r in cell), summary)


if __name__ == "__main__":
    raise SystemExit(main())
