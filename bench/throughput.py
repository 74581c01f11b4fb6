"""Throughput: Msamples/s and Mrays/s per scene and accel, with wall time by stage.

    python -m bench.throughput                       # Cornell box, 256x256, max_depth 8, rr_depth 5
    python -m bench.throughput --scenes ../shared/scenes/veach-ajar/scene.obj --spp 16
    python -m bench.throughput --json bench/results/throughput.json

Each scene is rendered once untimed (compiles, warms caches), then timed `--repeat` times; the
fastest run is reported with the median beside it (shared 2-core machines vary by +-15% from
run to run).
"""
import argparse
import os
import platform

import numba

import tracer

from . import atomic

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORNELL = os.path.join(ROOT, "scenes", "cornell", "cornell.obj")


def measure(path, accel, spp, max_depth, rr_depth, width, height, threads, repeat):
    over = {}
    if width:
        over["width"] = width
    if height:
        over["height"] = height
    scene = tracer.load_scene(path, **over)
    tracer.render(scene, spp=1, accel=accel, max_depth=max_depth, rr_depth=rr_depth, threads=threads)
    runs = [tracer.render(scene, spp=spp, accel=accel, max_depth=max_depth, rr_depth=rr_depth,
                          threads=threads).stats for _ in range(max(1, repeat))]
    speeds = sorted(r["msamples_per_s"] for r in runs)
    s = max(runs, key=lambda r: r["msamples_per_s"])
    return {
        "scene": os.path.relpath(path, ROOT), "accel": accel, "width": scene.width, "height": scene.height,
        "triangles": scene.n_triangles, "spp": spp, "max_depth": max_depth, "rr_depth": rr_depth,
        "seconds": round(s["time_total"], 3), "msamples_per_s": round(s["msamples_per_s"], 3),
        "msamples_per_s_median": round(speeds[len(speeds) // 2], 3), "repeat": len(runs),
        "mrays_per_s": round(s["mrays_per_s"], 3), "rays_per_sample": round(s["rays"] / s["samples"], 2),
        "stages": {k: round(v, 3) for k, v in s["time_stages"].items()},
    }


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.throughput", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default=CORNELL, help="comma-separated scene paths (default: the Cornell box)")
    p.add_argument("--accels", default="embree,numba")
    p.add_argument("--spp", type=int, default=32)
    p.add_argument("--max-depth", type=int, default=8)
    p.add_argument("--rr-depth", type=int, default=5)
    p.add_argument("--width", type=int, default=None, help="default: the scene's (256 for the Cornell box)")
    p.add_argument("--height", type=int, default=None)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--repeat", type=int, default=3, help="timed runs per scene and accel (best is reported)")
    p.add_argument("--json", default=None, help="also write the records to this file")
    a = p.parse_args(argv)
    rows = []
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, numba threads "
          f"{a.threads or numba.config.NUMBA_NUM_THREADS}")
    for path in a.scenes.split(","):
        for accel in a.accels.split(","):
            row = measure(path, accel, a.spp, a.max_depth, a.rr_depth, a.width, a.height, a.threads, a.repeat)
            rows.append(row)
            st = row["stages"]
            total = sum(st.values())
            parts = ", ".join(f"{k} {v:.2f}s ({100 * v / total:.0f}%)" for k, v in st.items())
            print(f"{row['scene']} [{accel}] {row['width']}x{row['height']} {row['spp']} spp: "
                  f"{row['msamples_per_s']:.3f} Msamples/s (median of {row['repeat']}: "
                  f"{row['msamples_per_s_median']:.3f}), {row['mrays_per_s']:.2f} Mrays/s, "
                  f"{row['rays_per_sample']} rays/sample, {row['seconds']:.2f} s")
            print(f"    {parts}")
    if a.json:
        os.makedirs(os.path.dirname(os.path.abspath(a.json)), exist_ok=True)
        atomic.write_json(a.json, rows, indent=1)  # a temporary file renamed into place
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
