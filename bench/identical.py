"""Bit-identity check for refactors: render fixed cases and compare every output array exactly.

    python -m bench.identical --save /tmp/ident-before     # on the old code
    python -m bench.identical --check /tmp/ident-before    # on the new code: exit 1 on any difference

Cases: `bsdf`, `grid`, `photon`, `pss` (2 epochs per model: deterministic), `odis` and
gradient-domain path tracing with `l1` and `l2` on the built-in `cornell` and `ajar`, full
resolution, fixed seeds, 16 spp (so that the guides run their pilot, training passes and a final
pass with splitting and the weight window), on the Embree accel and, for `bsdf` on cornell, the
Numba BVH. Saved per case: image, variance and AOVs (an .npz). A difference is reported per case
with the number of differing pixels and the largest difference. `--cases` picks cases by name.
"""
import argparse
import os
import sys

import numpy as np

import tracer

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = {"cornell": os.path.join(ROOT, "scenes", "cornell", "cornell.obj"),
          "ajar": os.path.join(ROOT, "scenes", "ajar", "ajar.obj")}
METHODS = {"bsdf": {}, "grid": {"guide": "grid"}, "photon": {"guide": "photon"},
           "pss": {"guide": "pss", "guide_settings": {"epochs": 2}}, "odis": {"guide": "odis"},
           "gpt-l1": {"integrator": "gpt", "recon": "l1"}, "gpt-l2": {"integrator": "gpt", "recon": "l2"}}
CASES = [(s, g, "embree") for s in SCENES for g in METHODS] + [("cornell", "bsdf", "numba")]


def render_case(scene_name, method, accel, spp, seed):
    scene = tracer.load_scene(SCENES[scene_name])
    r = tracer.render(scene, spp=spp, accel=accel, seed=seed, max_depth=8, **METHODS[method])
    out = {"image": r.image, "variance": r.variance}
    out.update({f"aov_{k}": v for k, v in r.aovs.items()})
    return out, r.stats


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    mode = ap.add_mutually_exclusive_group(required=True)
    mode.add_argument("--save", metavar="DIR", help="render the cases and save them to DIR")
    mode.add_argument("--check", metavar="DIR", help="render the cases and compare with DIR")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--cases", help="comma-separated case names (scene-method-accel), default all")
    args = ap.parse_args(argv)
    folder = args.save or args.check
    os.makedirs(folder, exist_ok=True)
    failed = 0
    cases = [c for c in CASES if args.cases is None or "-".join(c) in args.cases.split(",")]
    for scene_name, guide, accel in cases:
        name = f"{scene_name}-{guide}-{accel}"
        arrays, stats = render_case(scene_name, guide, accel, args.spp, args.seed)
        path = os.path.join(folder, name + ".npz")
        if args.save:
            np.savez(path, **arrays)
            print(f"{name}: saved ({stats['time_total']:.1f} s, nonfinite {stats['nonfinite_samples']})")
            continue
        with np.load(path) as old:
            diffs = []
            for k, v in arrays.items():
                o = old[k]
                if o.shape != v.shape or o.dtype != v.dtype:
                    diffs.append(f"{k}: shape/dtype {o.shape}/{o.dtype} -> {v.shape}/{v.dtype}")
                elif not np.array_equal(o, v, equal_nan=True):
                    bad = o != v
                    diffs.append(f"{k}: {int(bad.sum())} values differ, max |diff| "
                                 f"{float(np.abs(o.astype(np.float64) - v)[bad].max()):.3g}")
        if diffs:
            failed += 1
            print(f"{name}: DIFFERENT: " + "; ".join(diffs))
        else:
            print(f"{name}: identical ({stats['time_total']:.1f} s)")
    if args.check:
        print("all identical" if not failed else f"{failed} of {len(cases)} cases differ")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
