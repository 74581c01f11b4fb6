"""What limits `--guide odis`: the network, map quality, or guiding the first bounce only.

    python -m bench.odis_limits --scenes ajar,veach-ajar,cornell --scene-dir ../shared/scenes --spp 4,16

Per scene, at equal spp, trimmed MrSE and relMSE (mean over seeds, ratio to bsdf) of:
    bsdf                      BSDF sampling
    odis                      the shipped network's maps (weights auto: odis at max_depth 3,
                              odis_full at the scene's depth)
    odis:weights=odis_w8      the wider network
    odis:maps=reference       probe-traced maps at each centre (what the network is trained to
                              give, with 16 probes per bin; no network): the maps' ceiling
each rendered twice: with max_depth 3 (direct plus one-bounce light: the paper's renders, where
the first bounce's incident light is all there is to guide), against a bsdf reference of
`--ref-spp` spp rendered here at that depth (cached in --out); and at the scene's own depth,
against the scene's reference (bench.reference). Writes summary.md and records.jsonl to --out.
"""
import argparse
import os

import numpy as np

import tracer
from tracer import metrics
from tracer.guiding import make_guide

from . import atomic
from .common import method_spec, reference_for, scene_path
from .reference import ROOT

METHODS = ("bsdf", "odis", "odis:weights=odis_w8", "odis:maps=reference")
DEPTHS = (3, None)


def depth3_reference(scene, name, out, spp):
    path = os.path.join(out, f"ref3_{name}_{spp}.npy")
    if not os.path.exists(path):
        r = tracer.render(scene, spp=spp, max_depth=3, seed=12345)
        atomic.save_npy(path, r.image.astype(np.float32))
    return np.load(path)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.odis_limits", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default="ajar,veach-ajar,cornell")
    p.add_argument("--scene-dir", default=None)
    p.add_argument("--spp", default="4,16")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--ref-spp", type=int, default=2048, help="spp of the max_depth-3 references")
    p.add_argument("--depths", default="3,scene", help="which of the two renders: 3, scene or both (3,scene)")
    p.add_argument("--methods", default=";".join(METHODS))
    p.add_argument("--out", default=os.path.join(ROOT, "bench", "results", "odis_limits"))
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    methods = [m for m in a.methods.split(";") if m]
    spps = [int(s) for s in a.spp.split(",")]
    wanted = {d.strip() for d in a.depths.split(",")}
    if not wanted or wanted - {"3", "scene"}:
        p.error(f"--depths: expected 3, scene or 3,scene, got {a.depths!r}")
    depths = [d for d in DEPTHS if ("scene" if d is None else str(d)) in wanted]
    records = []
    lines = ["# What limits odis (equal spp; mean over seeds, ratio to bsdf in brackets)", ""]
    for name in a.scenes.split(","):
        path = scene_path(name, a.scene_dir)
        full = reference_for(path)[0]  # renders at the reference's resolution (a Mitsuba film may be larger)
        scene = tracer.load_scene(path, width=full.shape[1], height=full.shape[0])
        tracer.render(scene, spp=1)
        for depth in depths:
            ref = depth3_reference(scene, name, a.out, a.ref_spp) if depth == 3 else full
            rows = {}
            for m in methods:
                g_name, settings = method_spec(m)
                for n in spps:
                    e = []
                    for seed in range(a.seeds):
                        g = make_guide(g_name, **settings)
                        r = tracer.render(scene, spp=n, seed=seed, max_depth=depth, guide=g if g is not None else "bsdf")
                        mt = metrics.all_metrics(r.image, ref)
                        e.append((mt["MrSE"], mt["relMSE"]))
                        records.append({"scene": name, "max_depth": depth, "method": m, "spp": n, "seed": seed,
                                        "metrics": mt, "time_total": r.stats["time_total"],
                                        "fallback": g.stats().get("fallback") if g is not None else None})
                    rows[(m, n)] = np.mean(e, axis=0)
                    print(name, depth or "scene", m, n, "MrSE %.4g relMSE %.4g" % tuple(rows[(m, n)]), flush=True)
            lines += [f"## {name}, max_depth {depth or 'of the scene'}", "",
                      "| method | " + " | ".join(f"MrSE {n} spp | relMSE {n} spp" for n in spps) + " |",
                      "|---|" + "---|---|" * len(spps)]
            for m in methods:
                cells = []
                for n in spps:
                    for j in range(2):
                        v, b = rows[(m, n)][j], rows[("bsdf", n)][j]
                        cells.append(f"{v:.3g} ({v / b:.2f})")
                lines.append(f"| {m} | " + " | ".join(cells) + " |")
            lines.append("")
        atomic.write_jsonl(os.path.join(a.out, "records.jsonl"), records)
    text = "\n".join(lines) + "\n"
    atomic.write_text(os.path.join(a.out, "summary.md"), text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
