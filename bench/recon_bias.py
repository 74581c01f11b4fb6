"""How far each screened Poisson reconstruction moves the image mean, and why: the estimator or the solve.

    python -m bench.recon_bias --scenes ajar,cornell,veach-ajar --scene-dir ../shared/scenes \\
        --spp 4,16,64,256 --seeds 2

For every scene, seed and spp: one `--integrator gpt --recon none` render, whose buffers are
reconstructed four ways: `l2` (exact), `l1` (the shipped IRLS: 20 reweightings of at most 10 CG
steps, float32), `l1-long` (float64, 40 reweightings of at most 100 CG steps to relative residual
1e-7: the L1 minimiser as closely as this solver gets) and `l1-mean` (`l1` shifted by a constant
to the base image's mean). For each: the image mean over the reference's (`mean/ref`) and over the
base image's (`mean/base`), the L1 objective (poisson.l1_objective; lower is a better L1 solve),
relMSE and the most negative pixel. If `l1` and `l1-long` have the same mean shift, the shift is
the L1 estimator's (its level is the median of the base's heavy-tailed noise, not its mean), not
an unconverged solve's.

Writes records.jsonl and summary.md to --out (default bench/results/recon_bias/); a rerun skips
the cells records.jsonl holds.
"""
import argparse
import os
import time

import numpy as np

import tracer
from tracer import metrics
from tracer.gradient import poisson

from .cells import run_cells
from .reference import ROOT

ALPHA = 0.2
LONG = {"reweights": 40, "cg_iterations": 100, "cg_rtol": 1e-7, "dtype": np.float64}
METHODS = ("l2", "l1", "l1-long", "l1-mean")


def reconstructions(b, alpha=ALPHA):
    """{method: (indirect reconstruction (H,W,3) float64, seconds)} of one render's buffers."""
    ind, dx, dy = (np.asarray(b[k], dtype=np.float64) for k in ("indirect", "dx", "dy"))
    out = {}
    for name, solve in (("l2", lambda: poisson.solve_l2(ind, dx, dy, alpha)),
                        ("l1", lambda: poisson.solve_l1(ind, dx, dy, alpha)),
                        ("l1-long", lambda: poisson.solve_l1(ind, dx, dy, alpha, **LONG))):
        t0 = time.perf_counter()
        img = solve()
        out[name] = (img, time.perf_counter() - t0)
    l1, secs = out["l1"]
    out["l1-mean"] = (l1 + (ind.mean() - l1.mean()), secs)
    return out


def run_cell(scene, seed, spp, ref):
    g = tracer.render(scene, spp=spp, seed=seed, integrator="gpt", recon="none")
    b = g.buffers
    ind, dx, dy = (np.asarray(b[k], dtype=np.float64) for k in ("indirect", "dx", "dy"))
    base_mean = float(np.mean(b["base"], dtype=np.float64))
    ref_mean = float(np.mean(ref, dtype=np.float64))
    out = []
    for method, (rec, secs) in reconstructions(b).items():
        image = rec + b["direct"]
        out.append({"method": method, "seed": seed, "spp": spp, "solve_s": secs,
                    "render_s": g.stats["time_total"], "mean": float(image.mean()),
                    "mean_ref": float(image.mean()) / ref_mean, "mean_base": float(image.mean()) / base_mean,
                    "objective": poisson.l1_objective(rec, ind, dx, dy, ALPHA),
                    "min": float(image.min()), "negative_share": float((image.min(axis=2) < 0).mean()),
                    "nonfinite_samples": g.stats["nonfinite_samples"], "metrics": metrics.all_metrics(image, ref)})
    return out


def _median(rs, method, spp, key):
    v = [r["metrics"][key] if key in r["metrics"] else r[key] for r in rs if r["method"] == method and r["spp"] == spp]
    return float(np.median(v)) if v else float("nan")


def summary(records, meta):
    lines = [f"# Mean shift of the screened Poisson reconstructions ({meta['machine']})", "",
             f"Command: `{meta['command']}`. Medians over {meta['seeds']} seeds. `mean/ref`: image mean over the "
             "reference's; `mean/base`: over the base image's (the path-traced samples' own mean); `objective`: "
             "the L1 objective over l2's (lower: closer to the L1 minimiser); `min`: most negative pixel; "
             "`neg`: share of pixels with a negative channel.", ""]
    for scene in sorted({r["scene"] for r in records}):
        rs = [r for r in records if r["scene"] == scene]
        lines += [f"## {scene}", "", "| spp | method | mean/ref | mean/base | objective | relMSE | min | neg | solve s |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for spp in sorted({r["spp"] for r in rs}):
            l2obj = _median(rs, "l2", spp, "objective")
            for m in METHODS:
                lines.append(
                    f"| {spp} | {m} | {_median(rs, m, spp, 'mean_ref'):.3f} | {_median(rs, m, spp, 'mean_base'):.3f} "
                    f"| {_median(rs, m, spp, 'objective') / l2obj:.4f} | {_median(rs, m, spp, 'relMSE'):.4g} "
                    f"| {_median(rs, m, spp, 'min'):.3g} | {_median(rs, m, spp, 'negative_share'):.3f} "
                    f"| {_median(rs, m, spp, 'solve_s'):.2f} |")
        lines.append("")
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.recon_bias", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default="ajar,cornell,veach-ajar")
    p.add_argument("--scene-dir", default=None, help="folder of external scenes (<name>/scene.obj)")
    p.add_argument("--spp", default="4,16,64,256")
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--out", default=os.path.join(ROOT, "bench", "results", "recon_bias"))
    a = p.parse_args(argv)
    return run_cells("bench.recon_bias", argv, a, run_cell,
                     lambda cell: ", ".join(f"{r['method']} mean/ref {r['mean_ref']:.3f}" for r in cell), summary)


if __name__ == "__main__":
    raise SystemExit(main())
