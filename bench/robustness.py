"""Robustness: every method is finite, unbiased, and judged against bsdf at equal spp.

    python -m bench.robustness                                  # every built-in scene, every method
    python -m bench.robustness --scenes ajar --methods bsdf --spp 64
    python -m bench.robustness --spp 4 --crop 32                # the tiny configuration of the tests
    python -m bench.robustness --time 10 --seeds 3              # and at equal time: worst ratio to bsdf

Per scene x method it prints: non-finite samples (the render's `nonfinite_samples`: the
integrator zeroes a NaN or inf sample before the film sees it, so the image stays finite and this
count is what shows them) and non-finite pixels; a bias z-score per channel (bench.reference's
bias_z: the image mean of (I - R) over its standard error from the render's and the reference's
per-pixel variances: aggregating over pixels first keeps a pixel's noisy variance estimate from
biasing the score); and relMSE with its ratio to bsdf at the same spp. It exits with code 1 on
any non-finite sample or pixel or a significant bias (two-sided, Sidak-corrected at 1% over every
scene x method x channel). `--crop N` renders the N x N window at the image centre only.

With `--time SECONDS`, every method is also rendered at that budget with `--seeds` seeds (the same
seeds for every method) and the table gains 'vs bsdf (time)': the ratio of the methods' mean relMSE
over the seeds to bsdf's. A table below gives each method's worst such ratio over the scenes; the
bench then also exits 1 where one is above `--max-ratio` (1.1: a guide must not lose to BSDF
sampling). With 3 seeds a ratio's own noise is several percent (relMSE of one render is a mean
over pixels; fireflies make it heavier-tailed): a worst ratio near the bound is worth a rerun with
more seeds before it is believed.
"""
import argparse
import sys

import numpy as np

import tracer
from tracer import metrics
from tracer.guiding import guide_names

from .common import reference_for, scene_path
from .reference import bias_z, z_threshold

SCENES = ("cornell", "ajar", "glossy", "caustic", "manylights", "window", "spotlit")


def equal_time(scene_name, method, budget, seeds, scene_dir=None):
    """Mean relMSE over `seeds` of renders of `budget` seconds (full images), and their mean spp."""
    path = scene_path(scene_name, scene_dir)
    ref, _, _ = reference_for(path)
    scene = tracer.load_scene(path)
    errs, spp, bad = [], [], 0
    for s in seeds:
        r = tracer.render(scene, time=budget, guide=method, seed=s)
        errs.append(metrics.relmse(r.image, ref))
        spp.append(r.stats["spp"])
        bad += int(r.stats["nonfinite_samples"]) + int((~np.isfinite(r.image)).any(axis=2).sum())
    return {"relMSE_time": float(np.mean(errs)), "spp_time": float(np.mean(spp)), "nonfinite_time": bad}


def check(scene_name, method, spp, seed, crop, scene_dir=None):
    path = scene_path(scene_name, scene_dir)
    ref, ref_var, _ = reference_for(path)
    scene = tracer.load_scene(path)
    window = None
    if crop:
        c = min(crop, scene.width, scene.height)
        window = ((scene.width - c) // 2, (scene.height - c) // 2, c, c)
        x0, y0 = window[:2]
        ref, ref_var = ref[y0:y0 + c, x0:x0 + c], ref_var[y0:y0 + c, x0:x0 + c]
    r = tracer.render(scene, spp=spp, guide=method, seed=seed, crop=window)
    return {
        "scene": scene_name, "method": method, "spp": spp,
        "nonfinite_pixels": int((~np.isfinite(r.image)).any(axis=2).sum()),
        "nonfinite_samples": int(r.stats["nonfinite_samples"]),
        "bias_z": bias_z(r.image, r.variance, ref, ref_var),
        "relMSE": metrics.relmse(r.image, ref),
    }


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.robustness", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default=",".join(SCENES))
    p.add_argument("--methods", default=",".join(guide_names()))
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--crop", type=int, default=None, help="render only the central N x N window")
    p.add_argument("--scene-dir", default=None)
    p.add_argument("--time", type=float, default=0.0, help="also render each method for this many seconds")
    p.add_argument("--seeds", type=int, default=3, help="seeds per method at equal time")
    p.add_argument("--max-ratio", type=float, default=1.1, help="worst equal-time ratio to bsdf allowed")
    a = p.parse_args(argv)
    scenes = [s for s in a.scenes.split(",") if s]
    methods = [m for m in a.methods.split(",") if m]
    if "bsdf" not in methods:
        methods.insert(0, "bsdf")
    rows = [check(s, m, a.spp, a.seed, a.crop, a.scene_dir) for s in scenes for m in methods]
    if a.time > 0:
        seeds = [a.seed + k for k in range(a.seeds)]
        for r in rows:
            r.update(equal_time(r["scene"], r["method"], a.time, seeds, a.scene_dir))
    zc = z_threshold(3 * len(rows))
    base = {r["scene"]: r["relMSE"] for r in rows if r["method"] == "bsdf"}
    print(f"{'scene':<12} {'method':<8} {'spp':>5} {'NaN/inf px':>10} {'NaN/inf samples':>15} "
          f"{'bias z (R,G,B)':>22} {'relMSE':>10} {'vs bsdf':>8}"
          + (f" {'spp (time)':>10} {'vs bsdf (time)':>14}" if a.time > 0 else ""))
    base_t = {r["scene"]: r.get("relMSE_time", 0.0) for r in rows if r["method"] == "bsdf"}
    worst = {}
    failed = False
    for r in rows:
        biased = bool(np.any(np.abs(r["bias_z"]) >= zc))
        bad_px, bad_smp = r["nonfinite_pixels"] > 0, r["nonfinite_samples"] + r.get("nonfinite_time", 0) > 0
        failed |= biased or bad_px or bad_smp
        ratio = r["relMSE"] / base[r["scene"]] if base[r["scene"]] > 0 else float("nan")
        z = ", ".join(f"{v:+.2f}" for v in r["bias_z"])
        flags = [x for x, on in (("NaN/inf samples", bad_smp), ("NaN/inf pixels", bad_px), ("biased", biased)) if on]
        flag = "  <- " + ", ".join(flags) if flags else ""
        timed = ""
        if a.time > 0:
            rt = r["relMSE_time"] / base_t[r["scene"]] if base_t[r["scene"]] > 0 else float("nan")
            timed = f" {r['spp_time']:>10.0f} {rt:>14.2f}"
            if r["method"] != "bsdf" and not rt <= worst.get(r["method"], (-1.0, ""))[0]:
                worst[r["method"]] = (rt, r["scene"])
        print(f"{r['scene']:<12} {r['method']:<8} {r['spp']:>5} {r['nonfinite_pixels']:>10} "
              f"{r['nonfinite_samples']:>15} {z:>22} {r['relMSE']:>10.4g} {ratio:>8.2f}{timed}{flag}")
    print(f"bias threshold |z| < {zc:.2f} (1% family-wise over {3 * len(rows)} channel tests)")
    if a.time > 0:
        print(f"\nworst ratio to bsdf at equal time ({a.time:g} s, seeds {a.seed}..{a.seed + a.seeds - 1}; "
              f"must stay at most {a.max_ratio:g})")
        for m, (rt, sc) in worst.items():
            over = rt > a.max_ratio
            failed |= over
            print(f"{m:<10} {rt:>6.2f}  {sc}" + ("  <- loses to bsdf" if over else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
