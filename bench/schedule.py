"""relMSE of guided renders against the scene's reference, with the training schedule each got.

    python -m bench.schedule --scene veach-ajar --scene-dir ../shared/scenes-mitsuba --time 30 \
        --methods "photon/path:nee=0;photon:split_c=1000/path:nee=0;photon:split_c=1000,train_budget=0.4/path:nee=0"
    python -m bench.schedule --scene veach-ajar --scene-dir ../shared/scenes-mitsuba --spp 220 \
        --methods "photon:iterations=3/path:nee=0;photon:iterations=4/path:nee=0"

Per method (bench.common's GUIDE[:KEY=VALUE,...][/INTEGRATOR] grammar) and seed: relMSE, spp, the
training passes' spp (pilot first), their update seconds, and the final passes' seconds; then
the mean and median relMSE over seeds. It shows what bench.convergence's figures hide: how many
training iterations a time budget let each method run, and what its updates cost.
"""
import argparse

import numpy as np

import tracer
from tracer import metrics

from .common import check_method, reference_for, render_args, scene_path


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.schedule", description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="veach-ajar")
    p.add_argument("--scene-dir", default=None)
    p.add_argument("--methods", default="photon/path:nee=0")
    p.add_argument("--seeds", type=int, default=3)
    budget = p.add_mutually_exclusive_group(required=True)
    budget.add_argument("--time", type=float, help="seconds per render")
    budget.add_argument("--spp", type=int, help="samples per pixel per render")
    a = p.parse_args(argv)
    methods = [m for m in a.methods.split(";") if m]
    for m in methods:
        check_method(m)
    path = scene_path(a.scene, a.scene_dir)
    ref = reference_for(path)[0]
    scene = tracer.load_scene(path, width=ref.shape[1], height=ref.shape[0])
    for m in methods:  # compile outside the clock
        tracer.render(scene, spp=2, progress=False, **render_args(m))
    for m in methods:
        errs = []
        for seed in range(a.seeds):
            r = tracer.render(scene, spp=a.spp, time=a.time, seed=seed, progress=False, **render_args(m))
            if r.stats["nonfinite_samples"]:
                raise SystemExit(f"bench.schedule: {m} seed {seed}: {r.stats['nonfinite_samples']} non-finite samples")
            passes = r.stats["passes"]
            train = [p for p in passes if p["kind"] in ("pilot", "train", "initial")]
            errs.append(metrics.relmse(r.image, ref))
            print(f"{m} seed {seed}: relMSE {errs[-1]:.4g}, {r.stats['spp']} spp, training spp "
                  f"{[p['spp'] for p in train]}, updates {[round(p.get('time_update', 0.0), 2) for p in train]} s, "
                  f"final passes {sum(p['time'] for p in passes if p not in train):.1f} s"
                  + (f", chose {r.stats['guide_stats']['choice']}" if r.stats["guide_stats"].get("choice") else ""),
                  flush=True)
        print(f"{m}: relMSE mean {np.mean(errs):.4g}, median {np.median(errs):.4g}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
