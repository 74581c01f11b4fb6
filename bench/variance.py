"""Relative variance per sample of what each method learned, at equal spp, without timing noise.

    python -m bench.variance --scenes ajar,cornell --methods bsdf,photon,photon:mixing=variance
    python -m bench.variance --scenes veach-ajar --scene-dir ../shared/scenes --scale 2 --seeds 5
    python -m bench.variance --scenes veach-ajar --scene-dir ../shared/scenes-mitsuba --scale 1 \
        --methods "bsdf/path:nee=0;photon/path:nee=0;photon:reference_photons=500/path:nee=0"

Per scene, each guide is trained once (`--train-spp`, seed 99), then frozen
(tracer.guiding.FrozenGuide) and rendered `--seeds` times at `--spp`; `bsdf` is rendered the same
way (the first method whose guide is bsdf is the baseline; a method may name its integrator
after a slash, e.g. `photon/path:nee=0`). The figure is the relative variance of one sample,
averaged over pixels: mean(var_of_mean x spp / (R^2 + 0.01)), R the scene's reference
(box-downsampled by `--scale`), i.e. the relMSE one sample would have; the lower, the better the learned sampling. It isolates
the maps from learning cost and scheduling, which bench.convergence measures.

Per method the table gives the mean of that figure over seeds, the standard error of that mean
(sample standard deviation over seeds / sqrt(seeds); "-" with one seed), its min and max, and
every seed's figure. The mean, not the median: a heavy-tailed estimator shows itself by a rare
seed with a large variance, which the median would hide and an equal-time render would not.
Beside it, the ratio of the means to bsdf's, the render time per spp (median over seeds) and the
"efficiency" ratio to bsdf, mean relative variance x time per spp: the relMSE ratio the frozen
maps would reach at equal time, learning not counted.
"""
import argparse

import numpy as np

import tracer
from tracer.guiding import FrozenGuide, make_guide

from .common import check_method, reference_for, render_args, scene_path


def relative_variance(film, ref, spp):
    """Mean over pixels of the one-sample variance over (R^2 + 0.01), from a film of `spp` spp."""
    v = film.variance().mean(axis=-1) * spp
    return float((v / (ref.mean(axis=-1) ** 2 + 0.01)).mean())


def downsample(img, s):
    h, w = img.shape[0] // s, img.shape[1] // s
    return img[: h * s, : w * s].reshape(h, s, w, s, -1).mean(axis=(1, 3))


def measure(scene, ref, method, spp, seeds, train_spp, path_loop="lanes"):
    """Per-seed (relative variance, render seconds per spp) of `method` (GUIDE[:K=V,...][/INTEGRATOR
    [:K=V,...]], bench.common.render_args) on `scene`, frozen after training if a guide."""
    args = render_args(method)
    name, settings = args.pop("guide"), args.pop("guide_settings") or {}
    guide = "bsdf"
    if name != "bsdf":
        g = make_guide(name, **settings)
        tracer.render(scene, spp=train_spp, guide=g, seed=99, **args)
        guide = FrozenGuide(g)
    out = []
    for s in range(seeds):
        r = tracer.render(scene, spp=spp, guide=guide, seed=1000 + s, path_loop=path_loop, **args)
        out.append((relative_variance(r.film, ref, spp), r.stats["time_total"] / spp))
    return out


def summarise(vals):
    """(mean, standard error of the mean, min, max) of the per-seed figures; the standard error is
    nan with one seed."""
    v = np.asarray(vals, dtype=np.float64)
    sem = float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else float("nan")
    return float(v.mean()), sem, float(v.min()), float(v.max())


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.variance", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", required=True)
    p.add_argument("--methods", default="bsdf,photon,grid")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--train-spp", type=int, default=64, help="spp of the render that trains each guide")
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--scale", type=int, default=2, help="render at 1/scale of the scene's resolution")
    p.add_argument("--scene-dir", default=None)
    p.add_argument("--path-loop", default="lanes", help="the frozen renders' path loop: lanes, thread or wave (render())")
    a = p.parse_args(argv)
    methods = [m.strip() for m in a.methods.split(";" if ";" in a.methods else ",") if m.strip()]
    base_method = next((m for m in methods if m.partition("/")[0] == "bsdf"), None)
    if base_method is None:
        base_method = "bsdf"
        methods.insert(0, base_method)
    methods.sort(key=lambda m: m != base_method)  # bsdf first: the ratios are against it
    for m in methods:
        check_method(m)
    print(f"relative variance of one sample (mean over pixels of var / (R^2 + 0.01)); {a.spp} spp x "
          f"{a.seeds} seeds, guides trained at {a.train_spp} spp then frozen, 1/{a.scale} resolution; "
          f"mean over seeds, its standard error and min/max; ratio and efficiency from the means")
    print(f"{'scene':22s} {'method':28s} {'mean':>9s} {'+-sem':>9s} {'min':>9s} {'max':>9s} {'vs bsdf':>8s} "
          f"{'s/spp':>7s} {'eff vs bsdf':>11s}  per seed")
    for given in [s.strip() for s in a.scenes.split(",") if s.strip()]:
        path = scene_path(given, a.scene_dir)
        full = reference_for(path)[0]  # the reference's resolution (a Mitsuba scene's film may be larger)
        ref = downsample(full, a.scale)
        scene = tracer.load_scene(path, width=full.shape[1] // a.scale, height=full.shape[0] // a.scale)
        base = base_t = None
        for m in methods:
            vals, secs = zip(*measure(scene, ref, m, a.spp, a.seeds, a.train_spp, a.path_loop))
            mean, sem, lo, hi = summarise(vals)
            t = float(np.median(secs))
            if m == base_method:
                base, base_t = mean, t
            ratio = f"{mean / base:8.2f}" if base else f"{'-':>8s}"
            eff = f"{mean * t / (base * base_t):11.2f}" if base else f"{'-':>11s}"
            sem_s = f"{sem:9.3g}" if np.isfinite(sem) else f"{'-':>9s}"
            print(f"{given:22s} {m:28s} {mean:9.4g} {sem_s} {lo:9.4g} {hi:9.4g} {ratio} {t:7.4f} {eff}  "
                  + " ".join(f"{v:.3g}" for v in vals), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
