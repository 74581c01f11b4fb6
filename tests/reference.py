"""Reference pixels for the Cornell box regression test.

Regenerate (about a minute on 2 cores) with:

    .venv/bin/python -m tests.reference

It renders scenes/cornell at REF_SIZE with REF_SPP samples per pixel and writes
tests/data/cornell_ref.exr with six channels: the mean (R, G, B) and the variance of the
mean (R, G, B), plus tests/data/cornell_ref.json recording how it was made.
"""
import json
import os
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
CORNELL = os.path.join(ROOT, "scenes", "cornell", "cornell.obj")
REF_EXR = os.path.join(HERE, "data", "cornell_ref.exr")
REF_JSON = os.path.join(HERE, "data", "cornell_ref.json")
REF_SIZE = 48
REF_SPP = 16384
REF_SEED = 12345


def load():
    """(mean (H,W,3), variance of the mean (H,W,3)) float64, and the metadata dict."""
    import tracer

    data = tracer.read_image(REF_EXR).astype(np.float64)
    with open(REF_JSON) as f:
        meta = json.load(f)
    return data[:, :, :3], data[:, :, 3:6], meta


def main():
    import tracer

    scene = tracer.load_scene(CORNELL, width=REF_SIZE, height=REF_SIZE)
    t0 = time.time()
    r = tracer.render(scene, spp=REF_SPP, seed=REF_SEED, progress=True)
    seconds = time.time() - t0
    os.makedirs(os.path.dirname(REF_EXR), exist_ok=True)
    tracer.write_image(REF_EXR, np.concatenate([r.image, r.variance], axis=2),
                       channel_names=("R", "G", "B", "var.R", "var.G", "var.B"))
    meta = {"scene": "scenes/cornell/cornell.obj", "width": REF_SIZE, "height": REF_SIZE, "spp": REF_SPP,
            "seed": REF_SEED, "max_depth": scene.render.max_depth, "rr_depth": scene.render.rr_depth,
            "seconds": round(seconds, 1), "command": "python -m tests.reference"}
    with open(REF_JSON, "w") as f:
        json.dump(meta, f, indent=1)
    print(f"wrote {REF_EXR} ({REF_SPP} spp in {seconds:.1f} s)")


if __name__ == "__main__":
    main()
