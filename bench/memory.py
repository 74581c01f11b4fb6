"""Peak memory per film pixel of every method, measured, beside the estimate render() checks against.

    python -m bench.memory [--sizes 256,768] [--spp 64] [--methods bsdf,grid,...]

Each method renders the Cornell box through the command line at two square sizes in fresh
processes (after a tiny render that fills Numba's cache: a compile peaks higher than a render); the peak resident set (os.wait4's ru_maxrss) at the larger size less the smaller's,
over the difference in pixels, is the memory the method needs per pixel (the process, the scene
and the wave buffers cancel). `--spp 64` runs the histogram guides' pilot and four training
iterations, so that all their films are held. Printed beside tracer.memory's per-pixel estimate;
the estimate should be the larger. Writes bench/results/memory.json and memory.md (keeping the rows
of methods not run this time from an earlier run of the same sizes and spp).
"""
import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile

from . import atomic
from .reference import ROOT

METHODS = {"bsdf": [], "grid": ["--guide", "grid"], "photon": ["--guide", "photon"], "pss": ["--guide", "pss"],
           "odis": ["--guide", "odis"], "gpt-l1": ["--integrator", "gpt", "--recon", "l1"],
           "gpt-l2": ["--integrator", "gpt", "--recon", "l2"],
           "gpt-gradnet": ["--integrator", "gpt", "--recon", "gradnet"],
           "gpt-gradnet-v2": ["--integrator", "gpt", "--recon", "gradnet", "--recon-opt", "weights=gradnet_v2"]}


def peak_rss(args):
    """Peak resident bytes of `python -m tracer args` (which must succeed)."""
    p = subprocess.Popen([sys.executable, "-m", "tracer", *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                         cwd=ROOT)
    _, status, usage = os.wait4(p.pid, 0)
    err = p.stderr.read().decode()
    p.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"bench.memory: tracer {' '.join(args)} failed: {err.strip()}")
    return usage.ru_maxrss * 1024


def estimated_per_pixel(method):
    from tracer import memory
    from tracer.guiding import make_guide

    if method.startswith("gpt-"):
        return memory.GPT_PIXEL_BYTES[method[4:].split("-")[0]]  # (gpt-gradnet-v2: weights of gradnet)
    g = make_guide(method)
    return memory.PATH_PIXEL_BYTES + (g.pixel_bytes if g is not None else 0)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.memory", description=__doc__.splitlines()[0])
    p.add_argument("--sizes", default="256,768")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--methods", default=",".join(METHODS))
    a = p.parse_args(argv)
    small, large = (int(v) for v in a.sizes.split(","))
    scene = os.path.join(ROOT, "scenes", "cornell", "cornell.obj")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for m in a.methods.split(","):
            # first a tiny render, so that no measured run compiles kernels (which peaks higher)
            peak_rss([scene, "--width", "16", "--height", "16", "--spp", "1", "-q", "-o", os.path.join(tmp, "w.exr"),
                      *METHODS[m]])
            peaks = [peak_rss([scene, "--width", str(s), "--height", str(s), "--spp", str(a.spp), "-q",
                               "-o", os.path.join(tmp, "m.exr"), *METHODS[m]]) for s in (small, large)]
            measured = (peaks[1] - peaks[0]) / (large * large - small * small)
            est = estimated_per_pixel(m)
            rows.append({"method": m, "measured_bytes_per_pixel": measured, "estimated_bytes_per_pixel": est,
                         "peak_rss_small": peaks[0], "peak_rss_large": peaks[1]})
            print(f"{m:12s} measured {measured:6.0f} B/px  estimated {est:6d} B/px  ({est / measured:.2f}x)  "
                  f"peak RSS {peaks[0] / 2**20:.0f} MiB at {small}^2, {peaks[1] / 2**20:.0f} MiB at {large}^2",
                  flush=True)
    out = os.path.join(ROOT, "bench", "results")
    os.makedirs(out, exist_ok=True)
    try:  # the rows of methods not run this time, from a run of the same sizes and spp
        with open(os.path.join(out, "memory.json")) as f:
            old = json.load(f)
        if old["sizes"] == [small, large] and old["spp"] == a.spp:
            ran = {r["method"] for r in rows}
            rows = [r for r in old["rows"] if r["method"] not in ran] + rows
            rows.sort(key=lambda r: list(METHODS).index(r["method"]))
    except (OSError, ValueError, KeyError):
        pass
    meta = {"command": "python -m bench.memory " + " ".join(argv if argv is not None else sys.argv[1:]),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores", "date": datetime.date.today().isoformat(),
            "sizes": [small, large], "spp": a.spp}
    atomic.write_json(os.path.join(out, "memory.json"), dict(meta, rows=rows), indent=1)
    lines = [f"# Memory per film pixel ({meta['machine']}, {meta['date']})", "",
             f"Command: `{meta['command']}`. Measured: the peak resident set at {large}x{large} less the one at "
             f"{small}x{small}, over the difference in pixels ({a.spp} spp, the Cornell box). Estimated: what "
             "render() checks against the available memory (tracer.memory), per pixel.", "",
             "| method | measured B/px | estimated B/px | estimate / measured | peak RSS small | peak RSS large |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['method']} | {r['measured_bytes_per_pixel']:.0f} | {r['estimated_bytes_per_pixel']} | "
                     f"{r['estimated_bytes_per_pixel'] / r['measured_bytes_per_pixel']:.2f} | "
                     f"{r['peak_rss_small'] / 2**20:.0f} MiB | {r['peak_rss_large'] / 2**20:.0f} MiB |")
    atomic.write_text(os.path.join(out, "memory.md"), "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
