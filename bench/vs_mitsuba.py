"""One Mitsuba scene XML rendered by the tracer and by Mitsuba 3 (`scalar_rgb`), compared.

    python -m bench.vs_mitsuba ../shared/scenes-mitsuba/veach-ajar/scene.xml --width 160 --height 90 --spp 1024

Both render at the same size and spp, with the box pixel filter (the scene's filter is replaced in
a copy of the XML, so that pixels mean the same thing), Mitsuba with `--seeds` independent seeds.
Printed: each renderer's image mean per channel with its standard error (ours from the film's
per-pixel variances, Mitsuba's from the spread of its seeds), the z-score of their difference,
and the relative MSE of our image against Mitsuba's mean image beside the relMSE of one Mitsuba
seed against the others' mean (the noise floor at this spp), plus both times. Needs mitsuba
(pip install -e ".[mitsuba]").
"""
import argparse
import os
import re
import sys
import tempfile
import time

import numpy as np

import tracer
from tracer.metrics import relmse


def mitsuba_render(path, width, height, spp, seeds):
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    text = open(path, encoding="utf-8").read()
    text = re.sub(r'<rfilter\s+type="[a-z]+"\s*/>', '<rfilter type="box"/>', text)
    folder = os.path.dirname(os.path.abspath(path))
    mi.file_resolver().append(folder)
    with tempfile.NamedTemporaryFile("w", suffix=".xml", delete=False) as f:
        f.write(text)
    try:
        t0 = time.perf_counter()
        scene = mi.load_file(f.name, resx=width, resy=height)
        imgs = [np.array(mi.render(scene, spp=spp, seed=s))[:, :, :3] for s in range(seeds)]
        return np.stack(imgs), time.perf_counter() - t0
    finally:
        os.unlink(f.name)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--height", type=int, default=90)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--seeds", type=int, default=4, help="Mitsuba renders (its standard error comes from their spread)")
    a = ap.parse_args(argv)
    scene = tracer.load_scene(a.scene, width=a.width, height=a.height)
    t0 = time.perf_counter()
    r = tracer.render(scene, spp=a.spp, seed=1, pixel_filter="box")
    t_ours = time.perf_counter() - t0
    mine = r.image.astype(np.float64)
    n = mine.shape[0] * mine.shape[1]
    m_ours = mine.reshape(-1, 3).mean(axis=0)
    se_ours = np.sqrt(r.variance.astype(np.float64).reshape(-1, 3).sum(axis=0)) / n
    theirs, t_mi = mitsuba_render(a.scene, a.width, a.height, a.spp, a.seeds)
    means = theirs.reshape(a.seeds, -1, 3).mean(axis=1)
    m_mi = means.mean(axis=0)
    se_mi = means.std(axis=0, ddof=1) / np.sqrt(a.seeds)
    z = (m_ours - m_mi) / np.sqrt(se_ours ** 2 + se_mi ** 2)
    ref = theirs.mean(axis=0)
    floor = np.mean([relmse(theirs[k], (ref * a.seeds - theirs[k]) / (a.seeds - 1)) for k in range(a.seeds)])
    print(f"{a.scene}: {a.width}x{a.height}, {a.spp} spp, {len(scene.warnings)} warnings")
    for name, m, se, t in (("tracer", m_ours, se_ours, t_ours), ("mitsuba", m_mi, se_mi, t_mi / a.seeds)):
        print(f"  {name:8s} mean {np.array2string(m, precision=5)} +- {np.array2string(se, precision=5)}  ({t:.1f} s per render)")
    print(f"  z per channel {np.array2string(z, precision=2)}; relative difference of the means "
          f"{np.array2string(m_ours / m_mi - 1, precision=4)}")
    print(f"  relMSE tracer vs Mitsuba's mean image {relmse(mine, ref):.4g}; one Mitsuba seed vs the rest {floor:.4g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
