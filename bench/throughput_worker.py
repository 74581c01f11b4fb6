"""One renderer in its own process for `bench.throughput --vs-mitsuba`: loads a scene once, then
renders it once per line read from stdin (the line is the seed) and prints one JSON line per
render. The parent alternates two such processes, ours and Mitsuba's, so that neither renderer's
threads share the machine with the other's (in one process Mitsuba's idle threads slowed ours by
up to 25%).

    python -m bench.throughput_worker ours '{"scene": ..., "spp": 64, ...}'
    python -m bench.throughput_worker mitsuba '{"scene": ..., "spp": 64, ...}'

The job: scene (a bench.throughput name or an OBJ/XML path), spp, max_depth, rr_depth, width and
height (None: the scene's), threads, path_loop (ours). It prints {"ready": ...} once loaded and
warmed up (one untimed render), then per seed {"seconds", "samples", "stages", "rays"}.
"""
import json
import os
import sys
import tempfile
import time


def _ours(job):
    import tracer

    from .throughput import scene_spec

    over = {k: job[k] for k in ("width", "height") if job.get(k)}
    scene = tracer.load_scene(scene_spec(job["scene"])["obj"], **over)
    kw = dict(spp=job["spp"], max_depth=job["max_depth"], rr_depth=job["rr_depth"], threads=job.get("threads"),
              path_loop=job.get("path_loop", "lanes"))

    def render(seed):
        st = tracer.render(scene, seed=seed, **kw).stats
        return {"seconds": st["time_render"], "samples": st["samples"], "stages": st["time_stages"],
                "trace_parts": st["time_trace_parts"], "rays": st["rays"], "shadow_rays": st["shadow_rays"]}

    return render, {"triangles": scene.n_triangles, "width": scene.width, "height": scene.height}


def _mitsuba(job):
    import mitsuba as mi

    from . import mitsuba_side
    from .throughput import scene_spec

    mi.set_variant(mitsuba_side.VARIANT)
    spec = scene_spec(job["scene"])
    if spec["obj"].endswith(".xml"):
        from .vs_mitsuba import mitsuba_copy

        folder = tempfile.mkdtemp()
        copy, _ = mitsuba_copy(spec["obj"], folder, size=(job["width"], job["height"]))
        mi.file_resolver().append(os.path.dirname(os.path.abspath(spec["obj"])))
        scene = mi.load_file(copy)
        integrator = mi.load_dict({"type": "path", "max_depth": int(job["max_depth"]), "rr_depth": int(job["rr_depth"])})
    else:
        scene = mitsuba_side.load(spec, job["spp"], job["max_depth"], job["rr_depth"], job.get("width"), job.get("height"))
        integrator = scene.integrator()
    w, h = scene.sensors()[0].film().size()

    def render(seed):
        import numpy as np

        t0 = time.perf_counter()
        img = mi.render(scene, spp=int(job["spp"]), seed=int(seed), integrator=integrator)
        np.asarray(img)
        return {"seconds": time.perf_counter() - t0, "samples": int(w) * int(h) * int(job["spp"])}

    return render, {"width": int(w), "height": int(h)}


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    side, job = argv[0], json.loads(argv[1])
    render, info = (_ours if side == "ours" else _mitsuba)(job)
    render(0)  # compiles, loads caches, warms the machine
    print(json.dumps({"ready": info}), flush=True)
    for line in sys.stdin:
        print(json.dumps(render(int(line))), flush=True)


if __name__ == "__main__":
    main()
