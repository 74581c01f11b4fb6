"""Reference pixels for the Cornell box regression tests.

Regenerate (about two minutes on 2 cores) with:

    .venv/bin/python -m tests.reference

For each configuration in CONFIGS it renders scenes/cornell at REF_SIZE x REF_SIZE with REF_SPP
samples per pixel and writes tests/data/cornell_<name>.exr with six channels, the mean (R, G, B)
and the variance of the mean (var.R, var.G, var.B), and a JSON beside it recording how.

- `d5`: max_depth 5, which with rr_depth 5 means no Russian roulette, and the point pixel filter
  (every sample through the pixel centre), so no pixel mixes two surfaces (an edge pixel that
  catches the light once in a thousand samples is a Poisson count, not a normal variable):
  per-pixel z-tests hold at a few hundred spp.
- `unlimited`: max_depth -1 (the scene's default). Roulette on max(throughput) gives the colour
  channels of saturated walls rare, very large samples (a red-wall pixel's green channel can see a
  sample 250 standard deviations out), so this one is used for image-level tests only.
"""
import json
import os
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
CORNELL = os.path.join(ROOT, "scenes", "cornell", "cornell.obj")
REF_SIZE = 48
REF_SPP = 16384
REF_SEED = 12345
CONFIGS = {"d5": {"max_depth": 5, "rr_depth": 5, "pixel_filter": "point"},
           "unlimited": {"max_depth": -1, "rr_depth": 5, "pixel_filter": "box"}}


def paths(name):
    base = os.path.join(HERE, "data", f"cornell_{name}")
    return base + ".exr", base + ".json"


def load(name):
    """(mean (H,W,3), variance of the mean (H,W,3)) float64, and the metadata dict."""
    import tracer

    exr, js = paths(name)
    data = tracer.read_image(exr).astype(np.float64)
    with open(js) as f:
        meta = json.load(f)
    return data[:, :, :3], data[:, :, 3:6], meta


def main():
    import tracer

    scene = tracer.load_scene(CORNELL, width=REF_SIZE, height=REF_SIZE)
    for name, cfg in CONFIGS.items():
        t0 = time.time()
        r = tracer.render(scene, spp=REF_SPP, seed=REF_SEED, progress=True, **cfg)
        seconds = time.time() - t0
        exr, js = paths(name)
        os.makedirs(os.path.dirname(exr), exist_ok=True)
        tracer.write_image(exr, np.concatenate([r.image, r.variance], axis=2),
                           channel_names=("R", "G", "B", "var.R", "var.G", "var.B"))
        meta = {"scene": "scenes/cornell/cornell.obj", "width": REF_SIZE, "height": REF_SIZE, "spp": REF_SPP,
                "seed": REF_SEED, **cfg, "seconds": round(seconds, 1), "command": "python -m tests.reference"}
        with open(js, "w") as f:
            json.dump(meta, f, indent=1)
        print(f"wrote {exr} ({REF_SPP} spp in {seconds:.1f} s)")


if __name__ == "__main__":
    main()
