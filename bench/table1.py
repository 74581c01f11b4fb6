"""The seed paper's Table 1 layout (Zhu et al. 2021) from a bench.convergence run.

    python -m bench.table1 RUN_DIR [--out FILE]

RUN_DIR holds the records.jsonl of a `bench.convergence --time T` run whose methods include
`bsdf/path:nee=0` (PT with NEE off, the paper's protocol), the guides with `/path:nee=0`, and
optionally the same guides with NEE on. Writes one markdown file (default RUN_DIR/table1.md): per
scene, each NEE-off method's relMSE as a ratio PT / method (> 1: the method is better, as the paper
gives it) beside the paper's ratio; the same for NEE on against `bsdf`; and what each method costs
per sample and in memory (spp reached in the budget, learning seconds, guide memory).
"""
import argparse
import json
import os
import sys

import numpy as np

from bench import atomic

PT_OFF = "bsdf/path:nee=0"
# Zhu et al. 2021, Table 1: relMSE of PT over the method's (NEE off, equal time)
PAPER = {
    "photon/path:nee=0": ("Gauss-Best", {"veach-ajar": 65, "staircase": 4.3, "bathroom": 2.7, "spaceship": 2.5}),
    "photon:reconstruct=cnn/path:nee=0": ("Ours", {"veach-ajar": 335, "staircase": 13.5, "bathroom": 12, "spaceship": 16}),
    "ppg/path:nee=0": ("Müller 2017", {"veach-ajar": 50, "staircase": 3.9, "bathroom": 2.4, "spaceship": 3.1}),
}


def load(run_dir):
    with open(os.path.join(run_dir, "records.jsonl")) as f:
        return [json.loads(line) for line in f if line.strip()]


def cells(records):
    """{(scene, method): dict(relmse (mean over seeds), seeds (list), spp, learning, memory)} of the
    time-budget records."""
    out = {}
    for r in records:
        if r["budget"] != "time":
            continue
        c = out.setdefault((r["scene"], r["method"]), {"seeds": [], "spp": [], "learning": [], "memory": []})
        c["seeds"].append(r["metrics"]["relMSE"])
        c["spp"].append(r["spp"])
        c["learning"].append(r["time_learning"] + r["update_s"] + r["inference_s"])
        c["memory"].append(r["guide_memory_bytes"])
    for c in out.values():
        c["relmse"] = float(np.mean(c["seeds"]))
    return out


def _ratio_table(scenes, methods, cell, base):
    head = "| scene | " + " | ".join(f"`{m}`" for m in methods) + " |"
    lines = [head, "|---" * (len(methods) + 1) + "|"]
    for s in scenes:
        row = [s]
        for m in methods:
            c, b = cell.get((s, m)), cell.get((s, base))
            if c is None or b is None:
                row.append("-")
                continue
            txt = f"{b['relmse'] / c['relmse']:.2f}"
            if m in PAPER and s in PAPER[m][1]:
                txt += f" ({PAPER[m][1][s]:g})"
            row.append(txt)
        lines.append("| " + " | ".join(row) + " |")
    return lines


def table(records):
    cell = cells(records)
    scenes = list(dict.fromkeys(r["scene"] for r in records))
    methods = list(dict.fromkeys(r["method"] for r in records))
    budgets = sorted({r["time_budget"] for r in records if r["budget"] == "time"})
    seeds = sorted({r["seed"] for r in records})
    off = [m for m in methods if m.endswith("/path:nee=0") and m != PT_OFF]
    on = [m for m in methods if "/" not in m and m != "bsdf"]
    out = [f"Equal time ({', '.join(f'{b:g} s' for b in budgets)}), seeds {seeds[0]}-{seeds[-1]}, mean relMSE over "
           "the seeds. Ratios are PT's relMSE over the method's (> 1: the method is better).", ""]
    if off and any((s, PT_OFF) in cell for s in scenes):
        out += ["NEE off (the paper's protocol), against PT with NEE off; the paper's ratio in brackets ("
                + ", ".join(f"`{m}`: {PAPER[m][0]}" for m in off if m in PAPER) + "):", ""]
        out += _ratio_table(scenes, off, cell, PT_OFF) + [""]
    if on and any((s, "bsdf") in cell for s in scenes):
        out += ["NEE on (the tracer's default), against `bsdf` with NEE on:", ""]
        out += _ratio_table(scenes, on, cell, "bsdf") + [""]
    out += ["relMSE per seed, spp reached in the budget, seconds spent learning (learning, updates, inference), "
            "guide memory (MB, peak):", "",
            "| scene | method | relMSE (seeds) | spp | learning s | memory MB |", "|---|---|---|---|---|---|"]
    for s in scenes:
        for m in methods:
            c = cell.get((s, m))
            if c is None:
                continue
            out.append(f"| {s} | `{m}` | {c['relmse']:.4g} ({', '.join(f'{v:.4g}' for v in c['seeds'])}) | "
                       f"{np.median(c['spp']):.0f} | {np.median(c['learning']):.1f} | {max(c['memory']) / 2**20:.1f} |")
    return "\n".join(out) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.table1", description=__doc__.splitlines()[0])
    p.add_argument("run_dir")
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    if not os.path.isfile(os.path.join(a.run_dir, "records.jsonl")):
        print(f"bench.table1: {a.run_dir}/records.jsonl does not exist", file=sys.stderr)
        return 2
    text = table(load(a.run_dir))
    atomic.write_text(a.out or os.path.join(a.run_dir, "table1.md"), text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
