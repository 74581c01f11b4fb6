"""A sweep worker's resident memory, cell after cell: bench.convergence's cells (run_cell) on one
LocalCluster worker that is never restarted, each cell returning the worker's RSS after it.

    python -m bench.sweep_memory --scene ../shared/scenes-mitsuba/cornell-box/scene.xml --cells 400 \\
        --methods bsdf,photon,ppg,pss,odis,gpt-l2,auto,grid,bsdf+oidn,gpt-gradnet --time 0.5 --threads 2

The scene needs its reference (bench.reference; run_cell scores every cell against it). Methods
take turns, one cell each. Prints the RSS every len/12 cells, the peak and the growth per cell over
the four quarters after the first 20 cells (the warm-up, where each method's first cell loads its
kernels and models), and writes them to --out (JSON). --workers 0 runs the cells in this process.
"""
import argparse
import json
import os
import sys

from . import atomic, common, sweep


def _rss_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS"):
                return int(line.split()[1]) / 1024
    return float("nan")


def cell(c):
    """run_cell(c), then this process's resident memory (MB)."""
    from .convergence import run_cell

    run_cell(c)
    return _rss_mb()


def growth(rss, skip=20):
    """MB per cell over each quarter of the cells after the first `skip`."""
    tail = rss[skip:] if len(rss) > skip + 4 else rss
    q = [round(i * (len(tail) - 1) / 4) for i in range(5)]
    return [(tail[b] - tail[a]) / max(b - a, 1) for a, b in zip(q, q[1:])]


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.sweep_memory", description=__doc__.splitlines()[0])
    p.add_argument("--scene", required=True)
    p.add_argument("--methods", default="bsdf,photon,ppg,bsdf+oidn")
    p.add_argument("--cells", type=int, default=400)
    p.add_argument("--time", type=float, default=0.5, help="each cell's time budget (s)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--workers", type=int, default=1, help="1: one LocalCluster worker; 0: this process")
    p.add_argument("--out", default=os.path.join(common.ROOT, "bench", "results", "sweep_memory.json"))
    a = p.parse_args(argv)
    methods = a.methods.split(",")
    images = os.path.join(common.ROOT, "bench", "results", "sweep_memory_images")  # run_cell's images (not kept)
    cells = [{"scene": "s", "path": a.scene, "ref_dir": common.default_out(a.scene), "method": methods[i % len(methods)],
              "seed": i, "budget": "time", "threads": a.threads, "time_budget": a.time, "spp": None, "images": images}
             for i in range(a.cells)]
    got = {}
    sweep.run(cell, cells, lambda c, r: got.__setitem__(c["seed"], r), threads=a.threads, workers=a.workers,
              progress=True, desc="cells", fresh_after=0)
    rss = [got[i] for i in range(a.cells)]
    g = growth(rss)
    print(f"{a.cells} cells ({','.join(methods)}, {a.time:g} s each) on one worker, never restarted: RSS "
          f"{[round(x) for x in rss[::max(1, a.cells // 12)]]} MB; peak {max(rss):.0f} MB; growth per cell by "
          f"quarter after cell 20: {', '.join(f'{x * 1024:.0f} KB' for x in g)}")
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    atomic.write(a.out, atomic.text_writer(json.dumps({"command": "python -m bench.sweep_memory " + " ".join(
        argv if argv is not None else sys.argv[1:]), "rss_mb": rss, "peak_mb": max(rss), "growth_mb_per_cell": g})))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
