"""Throughput: Msamples/s and Mrays/s per scene and accel, with wall time by stage.

    python -m bench.throughput                       # Cornell box, 256x256, max_depth 8, rr_depth 5
    python -m bench.throughput --scenes ../shared/scenes/veach-ajar/scene.obj --spp 16
    python -m bench.throughput --scenes open-1k,open-1m --accels embree --spp 64
    python -m bench.throughput --vs-mitsuba          # side by side with Mitsuba 3 (optional extra)
    python -m bench.throughput --vs-mitsuba --scenes staircase --width 320 --height 180 --path-loops thread,wave
    python -m bench.throughput --load                # load_scene of the 1.3M-triangle OBJ: time, peak RSS
    python -m bench.throughput --json out/throughput.json   # the records elsewhere

Scene names besides paths (bench.scenes, written on first use into bench/results/scenes):
`open-1k` and `open-1m` (an icosphere of 1280 or 1.31M triangles on a floor under a quad light),
`mitsuba-cornell` (Mitsuba's own Cornell box exported to OBJ; needs mitsuba) and `staircase` (the
shared Mitsuba scene XML, ../shared/scenes-mitsuba). `--path-loops thread,wave` measures our
renders through the per-thread loop and the wavefront (render(path_loop=...)); the per-thread
loop's time is split by step (intersect, shade, occluded, rest) from processor-cycle shares.

Each scene is rendered once untimed (compiles, warms caches), then timed `--repeat` times; the
fastest run is reported with the median beside it (shared 2-core machines vary by +-15% from
run to run). With --vs-mitsuba, each renderer (ours once per path loop) runs in a process of its
own (bench.throughput_worker), loads the scene and renders once untimed, then they alternate
`--repeat` times; the ratio is of the medians. Mitsuba's LLVM
backend needs a recent libLLVM (Dr.Jit aborts with LLVM 14 or 15): point DRJIT_LIBLLVM_PATH at one.

The records go to bench/results/throughput.json (with --vs-mitsuba throughput_vs_mitsuba.json,
with --load throughput_load.json), or to --json, written atomically.
"""
import argparse
import json
import os
import platform
import subprocess
import sys

import numba

import tracer

from . import atomic, scenes

NAMED = {"open-1k": lambda: scenes.open_scene(3), "open-1m": lambda: scenes.open_scene(8),
         "mitsuba-cornell": scenes.mitsuba_cornell,
         "staircase": lambda: {"obj": STAIRCASE, "parts": None}}

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "bench", "results")
CORNELL = os.path.join(ROOT, "scenes", "cornell", "cornell.obj")
STAIRCASE = os.path.join(os.path.dirname(ROOT), "shared", "scenes-mitsuba", "staircase", "scene.xml")


def scene_spec(name):
    """bench.scenes dict for a scene name or an OBJ/JSON path (parts: None)."""
    if name in NAMED:
        return NAMED[name]()
    return {"obj": name, "parts": None}


def measure(path, accel, spp, max_depth, rr_depth, width, height, threads, repeat, path_loop="lanes"):
    over = {}
    if width:
        over["width"] = width
    if height:
        over["height"] = height
    scene = tracer.load_scene(scene_spec(path)["obj"], **over)
    kw = dict(accel=accel, max_depth=max_depth, rr_depth=rr_depth, threads=threads, path_loop=path_loop)
    tracer.render(scene, spp=1, **kw)
    runs = [tracer.render(scene, spp=spp, **kw).stats for _ in range(max(1, repeat))]
    speeds = sorted(r["msamples_per_s"] for r in runs)
    s = max(runs, key=lambda r: r["msamples_per_s"])
    return {
        "scene": path if path in NAMED else os.path.relpath(path, ROOT), "accel": accel, "path_loop": path_loop,
        "width": scene.width, "height": scene.height,
        "triangles": scene.n_triangles, "spp": spp, "max_depth": max_depth, "rr_depth": rr_depth,
        "seconds": round(s["time_total"], 3), "msamples_per_s": round(s["msamples_per_s"], 3),
        "msamples_per_s_median": round(speeds[len(speeds) // 2], 3), "repeat": len(runs),
        "mrays_per_s": round(s["mrays_per_s"], 3), "rays_per_sample": round(s["rays"] / s["samples"], 2),
        "stages": {k: round(v, 3) for k, v in s["time_stages"].items()},
        "trace_parts": {k: round(v, 3) for k, v in s["time_trace_parts"].items()},
    }


class _Worker:
    """A bench.throughput_worker process: one renderer, its scene loaded and warmed up."""

    def __init__(self, side, job):
        self.proc = subprocess.Popen([sys.executable, "-m", "bench.throughput_worker", side, json.dumps(job)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT,
                                     env=dict(os.environ, PYTHONPATH=ROOT))
        self.info = self._read()["ready"]

    def _read(self):
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"throughput worker exited with code {self.proc.wait()}")
        return json.loads(line)

    def render(self, seed):
        self.proc.stdin.write(f"{seed}\n")
        self.proc.stdin.flush()
        return self._read()

    def close(self):
        self.proc.stdin.close()
        self.proc.wait()


def vs_mitsuba(names, spp, max_depth, rr_depth, threads, repeat, width=None, height=None, path_loops=("lanes",)):
    """Alternate our render (embree; one process per path loop) and Mitsuba's (its own process) on
    each scene; rows of Msamples/s, ours per path loop."""
    rows = []
    for name in names:
        job = dict(scene=name, spp=spp, max_depth=max_depth, rr_depth=rr_depth, width=width, height=height,
                   threads=threads)
        ours = {loop: _Worker("ours", dict(job, path_loop=loop)) for loop in path_loops}
        first = ours[path_loops[0]].info
        theirs = _Worker("mitsuba", dict(job, width=first["width"], height=first["height"]))
        runs = {loop: [] for loop in path_loops}
        b = []
        for r in range(max(1, repeat)):
            for loop in path_loops:
                runs[loop].append(ours[loop].render(r))
            m = theirs.render(r)
            b.append(m["samples"] / m["seconds"] / 1e6)
        for w in (*ours.values(), theirs):
            w.close()
        med = lambda x: sorted(x)[len(x) // 2]  # noqa: E731
        for loop in path_loops:
            a = [x["samples"] / x["seconds"] / 1e6 for x in runs[loop]]
            mid = runs[loop][a.index(med(a))]
            rows.append({"scene": name, "triangles": first["triangles"], "width": first["width"],
                         "height": first["height"], "spp": spp, "path_loop": loop, "ours": med(a), "mitsuba": med(b),
                         "ratio": med(a) / med(b), "ours_runs": a, "mitsuba_runs": b,
                         "rays_per_sample": round(mid["rays"] / mid["samples"], 3),
                         "stages": {k: round(v, 3) for k, v in mid["stages"].items()},
                         "trace_parts": {k: round(v, 3) for k, v in mid["trace_parts"].items()}})
            print(f"{name} ({first['triangles']} triangles, {first['width']}x{first['height']}, {spp} spp), "
                  f"path loop {loop}: ours {med(a):.2f} Msamples/s, Mitsuba {med(b):.2f}: {med(a) / med(b):.2f}x "
                  f"(medians of {len(a)} alternated runs in separate processes; ours {min(a):.2f}-{max(a):.2f}, "
                  f"Mitsuba {min(b):.2f}-{max(b):.2f})", flush=True)
    return rows


_LOAD_OURS = """
import json, resource, sys, time
import tracer
from tracer.bvh import make_accel
t0 = time.perf_counter(); s = tracer.load_scene(sys.argv[1]); t1 = time.perf_counter()
rss_load = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
acc = make_accel("embree", s.tri); t2 = time.perf_counter()
print(json.dumps({"load_s": t1 - t0, "bvh_s": t2 - t1, "peak_rss_mb_load": rss_load / 1024,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""
_LOAD_MITSUBA = """
import json, resource, sys, time
from bench import mitsuba_side
spec = json.loads(sys.argv[1])
t0 = time.perf_counter(); scene = mitsuba_side.load(spec, 1, 8, 5); t1 = time.perf_counter()
print(json.dumps({"load_s": t1 - t0, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def _child(code, *args):
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, cwd=ROOT,
                         env=dict(os.environ, PYTHONPATH=ROOT))
    if out.returncode != 0:
        raise RuntimeError(f"child failed: {out.stderr.strip().splitlines()[-1:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def load_times(name, repeat, mitsuba):
    """Fresh-process load of `name`: ours (load_scene, then the Embree build) and, with `mitsuba`,
    Mitsuba's load_dict of the same parts (which builds its BVH too); peak RSS of each process."""
    spec = scene_spec(name)
    rows = []
    for _ in range(max(1, repeat)):
        row = {"ours": _child(_LOAD_OURS, spec["obj"])}
        if mitsuba:
            row["mitsuba"] = _child(_LOAD_MITSUBA, json.dumps(spec))
        rows.append(row)
    best = min(rows, key=lambda r: r["ours"]["load_s"])
    o = best["ours"]
    print(f"{name}: load_scene {o['load_s']:.2f} s (peak RSS {o['peak_rss_mb_load']:.0f} MB), + Embree build "
          f"{o['bvh_s']:.2f} s (peak RSS {o['peak_rss_mb']:.0f} MB); best of {len(rows)} fresh processes")
    if mitsuba:
        m = min((r["mitsuba"] for r in rows), key=lambda r: r["load_s"])
        print(f"    Mitsuba load_dict {m['load_s']:.2f} s (with its BVH; peak RSS {m['peak_rss_mb']:.0f} MB): "
              f"load_scene {o['load_s'] / m['load_s']:.2f}x its time, RSS {o['peak_rss_mb_load'] / m['peak_rss_mb']:.2f}x "
              f"(with our BVH {o['peak_rss_mb'] / m['peak_rss_mb']:.2f}x)")
    return rows


def stage_table(rows):
    """Print rows (measure's or vs_mitsuba's) as one markdown table: seconds per stage of the best run."""
    if not rows:
        return
    stages = [k for k in rows[0]["stages"] if any(r["stages"].get(k, 0.0) > 0 for r in rows)]
    print("\n| scene | accel | path loop | Msamples/s | " + " | ".join(stages) + " |")
    print("|---" * (4 + len(stages)) + "|")
    for r in rows:
        ms = r.get("msamples_per_s", r.get("ours"))
        print(f"| {r['scene']} | {r.get('accel', 'embree')} | {r.get('path_loop', 'lanes')} | {ms:.2f} | "
              + " | ".join(f"{r['stages'].get(k, 0.0):.3f}" for k in stages) + " |")


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
    p.add_argument("--path-loops", default="lanes",
                   help="comma-separated: thread (per-thread loop), wave (wavefront), lanes (tracer.engine)")
    p.add_argument("--repeat", type=int, default=3, help="timed runs per scene and accel (best is reported)")
    p.add_argument("--json", default=None, help="write the records to this file (default: bench/results/"
                                                "throughput.json, throughput_vs_mitsuba.json or throughput_load.json)")
    p.add_argument("--vs-mitsuba", action="store_true",
                   help="render side by side with Mitsuba 3 (default scenes: mitsuba-cornell,open-1k,open-1m)")
    p.add_argument("--load", action="store_true", help="time load_scene of open-1m (and Mitsuba's load, if present)")
    a = p.parse_args(argv)
    rows = []
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, numba threads "
          f"{a.threads or numba.config.NUMBA_NUM_THREADS}")
    if a.vs_mitsuba or a.load:
        from . import mitsuba_side

        why = mitsuba_side.available()
        if why and a.vs_mitsuba:
            print(f"--vs-mitsuba needs mitsuba ({why}); pip install mitsuba==3.9.1", file=sys.stderr)
            return 2
        names = a.scenes.split(",") if a.scenes != CORNELL else (
            ["mitsuba-cornell", "open-1k", "open-1m"] if a.vs_mitsuba else ["open-1m"])
        if a.load:
            rows += [{"load": n, "runs": load_times(n, a.repeat, why is None)} for n in names]
        else:
            rows += vs_mitsuba(names, a.spp, a.max_depth, a.rr_depth, a.threads, a.repeat, a.width, a.height,
                               tuple(a.path_loops.split(",")))
            stage_table(rows)
        names = []
    else:
        names = a.scenes.split(",")
    cells = [(path, accel, loop) for path in names for accel in a.accels.split(",")
             for loop in (a.path_loops.split(",") if accel == "embree" else ["wave"])]
    for path, accel, loop in cells:
        row = measure(path, accel, a.spp, a.max_depth, a.rr_depth, a.width, a.height, a.threads, a.repeat, loop)
        rows.append(row)
        st = row["stages"]
        total = sum(st.values()) or 1.0
        parts = ", ".join(f"{k} {v:.2f}s ({100 * v / total:.0f}%)" for k, v in st.items() if v > 0)
        print(f"{row['scene']} [{accel}, {loop}] {row['width']}x{row['height']} {row['spp']} spp: "
              f"{row['msamples_per_s']:.3f} Msamples/s (median of {row['repeat']}: "
              f"{row['msamples_per_s_median']:.3f}), {row['mrays_per_s']:.2f} Mrays/s, "
              f"{row['rays_per_sample']} rays/sample, {row['seconds']:.2f} s")
        print(f"    {parts}")
        if st.get("trace", 0.0) > 0:
            print("    trace by step (cycle shares): "
                  + ", ".join(f"{k} {v:.2f}s" for k, v in row["trace_parts"].items()))
    stage_table([r for r in rows if "accel" in r])
    out = a.json or default_json(a)
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    atomic.write_json(out, rows, indent=1)  # a temporary file renamed into place
    print(f"records: {out}")
    return 0


def default_json(a):
    """Where the records of a run with arguments `a` go without --json: bench/results/, by mode."""
    name = "throughput_load" if a.load else "throughput_vs_mitsuba" if a.vs_mitsuba else "throughput"
    return os.path.join(RESULTS, name + ".json")


if __name__ == "__main__":
    raise SystemExit(main())
