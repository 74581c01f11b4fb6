"""The loop of the benchmarks that render one cell per scene, spp and seed (bench.gradnet,
bench.recon_bias): records in <out>/records.jsonl, a rerun skipping the cells it holds, every
scene at the smallest spp first, and <out>/summary.md at the end."""
import json
import os
import platform
import sys

import tracer

from . import atomic
from .common import reference_for, scene_path


def run_cells(prog, argv, a, run_cell, describe, summary):
    """Run run_cell(scene, seed, spp, reference) -> [record] for every cell of a.scenes (names, with
    a.scene_dir), a.spp (comma-separated) and range(a.seeds) not in a.out's records yet; print
    describe(records of the cell) after each; write and print summary(records, meta). Returns 0."""
    os.makedirs(a.out, exist_ok=True)
    path = os.path.join(a.out, "records.jsonl")
    records = []
    if os.path.exists(path):  # resume: keep what an earlier run of the same command finished
        with open(path) as f:
            records = [json.loads(line) for line in f if line.strip()]
    meta = {"command": f"python -m {prog} " + " ".join(argv if argv is not None else sys.argv[1:]),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores", "seeds": a.seeds}
    scenes = {}
    for name in a.scenes.split(","):
        obj = scene_path(name, a.scene_dir)
        ref = reference_for(obj)[0]  # rendered at the reference's resolution (a Mitsuba scene's film may differ)
        scenes[name] = (tracer.load_scene(obj, width=ref.shape[1], height=ref.shape[0]), ref)
    for spp in (int(s) for s in a.spp.split(",")):
        for name, (scene, ref) in scenes.items():
            for seed in range(a.seeds):
                if any(r["scene"] == name and r["spp"] == spp and r["seed"] == seed for r in records):
                    continue
                cell = [dict(r, scene=name) for r in run_cell(scene, seed, spp, ref)]
                records += cell
                atomic.write_jsonl(path, records)
                print(f"{name} spp {spp} seed {seed}: {describe(cell)}", flush=True)
    text = summary(records, meta)
    atomic.write_text(os.path.join(a.out, "summary.md"), text + "\n")
    print(text)
    return 0
