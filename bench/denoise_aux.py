"""What Open Image Denoise's auxiliary buffers buy: the same low-spp renders denoised with no
buffers, with the render's albedo and normal as they are (`cleanAux` off), and with both
prefiltered first (tracer.denoise's choice), scored against each scene's reference.

    python -m bench.denoise_aux --scenes staircase,veach-ajar --scene-dir ../shared/scenes-mitsuba --spp 4,16 --seeds 3

Prints relMSE and 1-SSIM (mean over seeds) per scene, spp and variant, and the filter's seconds.
"""
import argparse
import time

import numpy as np

import tracer
from tracer import metrics
from tracer.denoise import Denoiser

from .common import reference_for, scene_path

VARIANTS = ("none", "raw aux", "prefiltered aux")


def variants(d, image, albedo, normal):
    """{variant: (denoised image, seconds)} of one render."""
    out = {}
    for name in VARIANTS:
        t0 = time.perf_counter()
        if name == "none":
            img = d(image)
        elif name == "prefiltered aux":
            img = d(image, albedo, normal)
        else:  # the buffers straight into the colour filter, cleanAux off
            img = np.empty_like(image)
            d.run_filter({"color": np.ascontiguousarray(image, np.float32),
                       "albedo": np.ascontiguousarray(np.clip(albedo, 0, 1), np.float32),
                       "normal": np.ascontiguousarray(np.clip(normal, -1, 1), np.float32), "output": img},
                      True, "denoising with raw buffers", clean_aux=False)
        out[name] = img, time.perf_counter() - t0
    return out


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.denoise_aux", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", required=True)
    p.add_argument("--scene-dir", default=None)
    p.add_argument("--spp", default="4,16")
    p.add_argument("--seeds", type=int, default=3)
    a = p.parse_args(argv)
    d = Denoiser()
    print("| scene | spp | variant | relMSE | 1-SSIM | filter s |\n|---|---|---|---|---|---|")
    for name in a.scenes.split(","):
        path = scene_path(name, a.scene_dir)
        ref, _, meta = reference_for(path)
        scene = tracer.load_scene(path, width=meta["width"], height=meta["height"])
        for spp in (int(s) for s in a.spp.split(",")):
            scores = {v: [] for v in VARIANTS}
            for seed in range(a.seeds):
                r = tracer.render(scene, spp=spp, seed=seed)
                for v, (img, secs) in variants(d, r.image, r.aovs["albedo"], r.aovs["normal"]).items():
                    m = metrics.all_metrics(img, ref)
                    scores[v].append((m["relMSE"], m["1-SSIM"], secs))
            raw = metrics.all_metrics(r.image, ref)
            print(f"| {name} | {spp} | raw image (last seed) | {raw['relMSE']:.4g} | {raw['1-SSIM']:.4g} | - |")
            for v in VARIANTS:
                e = np.mean(scores[v], axis=0)
                print(f"| {name} | {spp} | {v} | {e[0]:.4g} | {e[1]:.4g} | {e[2]:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
