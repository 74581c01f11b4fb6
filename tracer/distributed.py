"""A render split over Dask workers: independent segments (seeds), merged into one image.

    render(scene, spp=4096, workers=4)                      # a LocalCluster on this machine
    render(scene, spp=4096, scheduler="tcp://host:8786")    # any Dask cluster
    python -m tracer scene.xml --spp 4096 --workers 4 [--segments-dir DIR]

Segment k renders with seed `seed + k`, spp // K samples per pixel (the first spp % K segments one
more), or with `time` the whole budget each. The segments are merged in seed order as
bench.reference merges its own: each weighted by its spp (mean and the variance of the mean), each
checked first against the merge so far (per channel, the image mean of their difference over its
standard error, below the two-sided 1% threshold Sidak-corrected over the channels): a segment
rendered by other code or settings is refused with one line naming it, and nothing is merged.

With a segments folder (`segments_dir`, the CLI's `--segments-dir`, default `<output>.segments`),
each finished segment is written there as it arrives (seed_<s>.npz, atomically, with the settings it
was rendered with); a run started again with the same settings renders only the missing ones, and a
file rendered with other settings is one error naming it. The folder is removed once the image is
written.

A guide trains on each worker apart (one guide per segment, from that segment's own samples: a
warning says so). The progress bar counts the samples of every segment. Ctrl-C asks every worker to
stop after its pass in flight and merges what they return ("the image so far", stats interrupted);
a second Ctrl-C stops waiting and merges the segments already finished. gpt is not split (its
reconstruction needs every sample in one place). Needs `distributed` (pip install -e ".[dask]").
"""
import json
import logging
import os
import signal
import threading
import time as _time
import uuid

import numpy as np

from .errors import SettingsError, TracerError

log = logging.getLogger("tracer")

class SegmentError(TracerError):
    """A segment disagrees with the others, or a stored one was rendered with other settings."""


def local_cluster(**kwargs):
    """dask.distributed's LocalCluster(**kwargs), its workers spawned with glibc's own malloc
    settings. Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in its workers' environment, and
    setting the trim threshold turns off glibc's dynamic mmap threshold (mallopt(3)): every numpy
    array of 128 KiB or more is then mapped and unmapped afresh. An L1 Poisson solve of a 256 x 256
    image took 2.3x as long in such a worker as in a plain process (gpt-l1 at a 2-s budget kept
    1.2 s for it and rendered 1 spp instead of 8)."""
    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}):
        return LocalCluster(**kwargs)


def _client(scheduler, workers):
    """(Client, the ExitStack that closes it, worker count, Numba threads per worker: None on a
    scheduler's workers, which keep their machine's default) of a scheduler address or a
    LocalCluster of `workers` processes sharing this machine's cores."""
    import contextlib

    check_ready(workers)
    from distributed import Client

    stack = contextlib.ExitStack()
    quiet = logging.getLogger("distributed")  # its INFO lines would reach the CLI's warning handler
    stack.callback(quiet.setLevel, quiet.level)
    quiet.setLevel(logging.ERROR)
    if scheduler is not None:
        client = stack.enter_context(Client(scheduler))
        return client, stack, max(1, len(client.scheduler_info()["workers"])), None
    threads = max(1, (os.cpu_count() or 1) // workers)
    cluster = stack.enter_context(local_cluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                dashboard_address=":0", silence_logs=logging.ERROR,
                                                env={"OMP_NUM_THREADS": str(threads)}))
    client = stack.enter_context(Client(cluster))
    client.run(_ignore_sigint)  # Ctrl-C reaches the workers too (one process group): the client handles it
    return client, stack, workers, threads


def _ignore_sigint():
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def check_ready(workers=None):
    """SettingsError, before any work, when a Dask render cannot run here (no `distributed`, a bad
    worker count)."""
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise SettingsError(f"workers must be a whole number >= 1, got {workers!r}")
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise SettingsError("rendering on Dask (--workers, --scheduler) needs the `distributed` package: "
                            "pip install -e \".[dask]\"") from None


def _segment(scene, cell, queue_name, stop_name):
    """One segment on a worker: tracer.render with the cell's seed and spp, reporting each pass to the
    queue and stopping when the event is set. Returns {image, variance, aovs, stats}."""
    from distributed import Event, Queue

    from .render import render

    queue, stop = Queue(queue_name), Event(stop_name)
    seen = [0.0]

    def callback(i, film, stats):
        done = float(stats["spp_mean"])
        try:
            queue.put((cell["seed"], done - seen[0]))
        except Exception:  # the client has gone: the segment still finishes
            pass
        seen[0] = done
        return not stop.is_set()

    r = render(scene, callback=callback, **cell["render"])
    if stop.is_set():  # stopped short by the client's Ctrl-C: an image so far, never stored for a resume
        r.stats["interrupted"] = True
    return {"image": r.image, "variance": r.variance, "aovs": r.aovs, "stats": r.stats}


def _store(folder, key, seg):
    """Write a finished segment into `folder` (seed_<s>.npz, whole or not at all)."""
    from .imageio import temp_path

    path = os.path.join(folder, f"seed_{key['seed']}.npz")
    tmp = temp_path(path)
    try:
        with open(tmp, "wb") as f:
            np.savez(f, image=seg["image"], variance=seg["variance"],
                     **{f"aov_{k}": v for k, v in seg["aovs"].items()},
                     key=json.dumps(key), stats=json.dumps(seg["stats"]))
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def _load(folder, key):
    """The segment stored for key's seed, or None; SegmentError if it was rendered otherwise."""
    path = os.path.join(folder, f"seed_{key['seed']}.npz")
    if not os.path.isfile(path):
        return None
    try:
        with np.load(path) as z:
            stored = json.loads(str(z["key"]))
            seg = {"image": z["image"], "variance": z["variance"], "stats": json.loads(str(z["stats"])),
                   "aovs": {k[4:]: z[k] for k in z.files if k.startswith("aov_")}}
    except Exception as e:
        raise SegmentError(f"{path}: not a readable segment ({type(e).__name__}: {e}); remove it") from None
    if stored != key:
        diff = ", ".join(f"{k} {stored.get(k)!r} (now {key[k]!r})" for k in key if stored.get(k) != key[k])
        raise SegmentError(f"{path}: rendered with other settings: {diff}; remove the folder or render as it was")
    return seg


def merge(m1, v1, n1, m2, v2, n2):
    """Two independent estimates weighted by their spp: (mean, variance of the mean)."""
    w1, w2 = n1 / (n1 + n2), n2 / (n1 + n2)
    return w1 * m1 + w2 * m2, w1 * w1 * v1 + w2 * w2 * v2


def bias_z(image, variance, ref, ref_var):
    """Per channel: the image mean of (image - ref) over its standard error, from the per-pixel
    variances of both means (summed over pixels first, so that a pixel's noisy variance estimate
    does not bias the score); 0 where that error is 0."""
    d = (np.asarray(image, np.float64) - ref).reshape(-1, ref.shape[-1])
    v = (np.asarray(variance, np.float64) + ref_var).reshape(-1, ref.shape[-1])
    se = np.sqrt(v.sum(axis=0)) / d.shape[0]
    return np.where(se > 0, d.mean(axis=0) / np.where(se > 0, se, 1.0), 0.0)


def agreement(mean, var, ref, ref_var, alpha=0.01):
    """(agrees, z per channel, threshold): bias_z against the two-sided alpha threshold, Sidak-
    corrected over the channels."""
    from .testing import z_critical

    z = bias_z(mean, var, ref, ref_var)
    zc = z_critical(z.size, alpha)
    return bool(np.all(np.abs(z) < zc)), z, zc


def merge_segments(segments):
    """(image, variance, aovs, [per-segment record]) of [(seed, segment)] merged in seed order, each
    checked against the merge so far (SegmentError where one disagrees)."""
    mean = var = aovs = None
    n = 0
    records = []
    for seed, seg in sorted(segments, key=lambda s: s[0]):
        spp = float(seg["stats"]["spp_mean"])
        rec = {"seed": int(seed), "spp": seg["stats"]["spp"], "spp_mean": spp,
               "seconds": round(float(seg["stats"]["time_total"]), 2), "interrupted": bool(seg["stats"]["interrupted"])}
        m, v = np.asarray(seg["image"], np.float64), np.asarray(seg["variance"], np.float64)
        if not spp > 0:
            continue
        if mean is None:
            mean, var, n = m, v, spp
            aovs = {k: np.asarray(a, np.float64) for k, a in seg["aovs"].items()}
        else:
            ok, z, zc = agreement(m, v, mean, var)
            rec["z"] = [round(float(x), 3) for x in z]
            if not ok:
                raise SegmentError(f"segment seed {seed} ({spp:g} spp) disagrees with the merge of seeds "
                                   f"{[r['seed'] for r in records]}: z (R, G, B) = "
                                   f"{', '.join(f'{x:+.2f}' for x in z)}, |z| must stay below {zc:.2f}; "
                                   f"nothing merged")
            w = spp / (n + spp)
            for k in aovs:
                aovs[k] = (1.0 - w) * aovs[k] + w * np.asarray(seg["aovs"][k], np.float64)
            mean, var = merge(mean, var, n, m, v, spp)
            n += spp
        records.append(rec)
    return mean, var, aovs, records


def render_on_dask(scene, render_kw, scheduler=None, workers=None, segments_dir=None, progress=False):
    """tracer.render(scene, **render_kw) split over Dask (module docstring): a RenderResult whose
    stats are the first segment's with the totals of all (samples, rays, spp), the slowest segment's
    time_total and time_render (Msamples/s: all samples over that time_render), time_wall (the
    whole call: cluster start, the workers' imports and compile, transfers), and stats["segments"]
    (seed, spp, seconds, z of each)."""
    from .film import Film
    from .result import RenderResult

    integ = _name(render_kw.get("integrator", "path"))
    if integ.split(":")[0] != "path":
        raise SettingsError("gpt is not split over Dask workers (its reconstruction needs every sample in one "
                            "place): render it without --workers or --scheduler")
    if scheduler is None and workers is None:
        raise SettingsError("render_on_dask needs a scheduler address or a number of workers")
    denoise = render_kw.pop("denoise", False)
    spp, budget, seed = render_kw.pop("spp", None), render_kw.pop("time", None), render_kw.pop("seed", None)
    if budget is None:
        spp = int(scene.render.spp if spp is None else spp)
    seed = int(scene.render.seed if seed is None else seed)
    guide = render_kw.get("guide", "bsdf")
    if budget is None and workers is not None and spp < workers:
        raise SettingsError(f"{spp} spp cannot be split over {workers} workers (at least one sample each)")
    t0 = _time.perf_counter()
    client, stack, n, threads = _client(scheduler, workers)
    with stack:
        if budget is None and spp < n:
            raise SettingsError(f"{spp} spp cannot be split over {n} workers (at least one sample each)")
        if guide not in (None, "bsdf") and not (isinstance(guide, str) and guide.startswith("bsdf:")):
            log.warning(f"guide {guide!r} trains on each of the {n} workers apart: {n} guides, each from its own "
                        f"segment's samples")
        cells = []
        shares = split_spp(spp, n) if budget is None else [None] * n
        for k in range(n):
            kw = dict(render_kw, seed=seed + k, time=budget, spp=shares[k])
            kw.pop("progress", None)
            kw.pop("callback", None)
            if threads is not None:
                kw["threads"] = threads
            key = {"scene": os.path.abspath(scene.path), "width": scene.width, "height": scene.height,
                   "spp": shares[k], "time": budget, "seed": seed + k,
                   "guide": _name(guide) + json.dumps(render_kw.get("guide_settings") or {}, sort_keys=True),
                   "integrator": integ, "max_depth": render_kw.get("max_depth"), "rr_depth": render_kw.get("rr_depth"),
                   "pixel_filter": render_kw.get("pixel_filter", "box"),
                   "crop": list(render_kw["crop"]) if render_kw.get("crop") is not None else None}
            cells.append({"seed": seed + k, "render": kw, "key": key})
        done = {}
        if segments_dir is not None:
            os.makedirs(segments_dir, exist_ok=True)
            for c in cells:
                seg = _load(segments_dir, c["key"])
                if seg is not None:
                    done[c["seed"]] = seg
            if done:
                log.info(f"{segments_dir}: {len(done)} of {n} segments already rendered; rendering the others")
        interrupted = _run(client, scene, [c for c in cells if c["seed"] not in done], done, segments_dir, progress)
        wall = _time.perf_counter() - t0
    if not done:
        raise KeyboardInterrupt  # stopped before any segment returned
    image, variance, aovs, records = merge_segments(list(done.items()))
    stats = dict(done[min(done)]["stats"])
    segs = [done[s]["stats"] for s in sorted(done)]
    total = lambda k: sum(s[k] for s in segs)  # noqa: E731
    npix = image.shape[0] * image.shape[1]
    t_render = max(s["time_render"] for s in segs)
    stats.update({
        "seed": seed, "spp": int(total("spp")), "spp_mean": total("samples") / npix, "samples": int(total("samples")),
        "rays": int(total("rays")), "camera_and_bounce_rays": int(total("camera_and_bounce_rays")),
        "shadow_rays": int(total("shadow_rays")), "nonfinite_samples": int(total("nonfinite_samples")),
        # the budget's clock and the passes' as one render's (the slowest segment's); time_wall adds
        # the cluster's start, the workers' imports and compile, and the transfers
        "time_total": max(s["time_total"] for s in segs), "time_render": t_render, "time_wall": wall,
        "msamples_per_s": total("samples") / t_render / 1e6 if t_render > 0 else 0.0,
        "mrays_per_s": total("rays") / t_render / 1e6 if t_render > 0 else 0.0,
        "interrupted": bool(interrupted or len(done) < n or any(s["interrupted"] for s in segs)),
        "segments": records, "workers": n, "scheduler": scheduler or f"LocalCluster({n} workers)",
        "threads": threads,
    })
    result = RenderResult(image.astype(np.float32), variance.astype(np.float32),
                          {k: a.astype(np.float32) for k, a in aovs.items()}, stats, Film(1, 1))
    if denoise:
        from .denoise import Denoiser, apply

        apply(result, Denoiser.shared(None, denoise if isinstance(denoise, str) else "high"))
    if segments_dir is not None:  # done with: removed; an interrupted run keeps its finished ones
        for c in cells if not result.stats["interrupted"] else ():
            path = os.path.join(segments_dir, f"seed_{c['seed']}.npz")
            if os.path.exists(path):
                os.remove(path)
        if os.path.isdir(segments_dir) and not os.listdir(segments_dir):
            os.rmdir(segments_dir)
    return result


def _run(client, scene, cells, done, segments_dir, progress):
    """Submit the cells, collect their results into `done` (storing each in segments_dir), feed the
    progress bar; returns whether Ctrl-C stopped the render."""
    from distributed import Event, Queue, wait
    from tqdm import tqdm

    if not cells:
        return False
    name = uuid.uuid4().hex
    queue, stop = Queue(f"tracer-progress-{name}", client=client), Event(f"tracer-stop-{name}", client=client)
    scene_f = client.scatter(scene, broadcast=True)
    futs = {client.submit(_segment, scene_f, c, f"tracer-progress-{name}", f"tracer-stop-{name}", pure=False): c
            for c in cells}
    left = set(futs)
    timed = cells[0]["render"]["spp"] is None
    bar = tqdm(total=None if timed else sum(c["render"]["spp"] for c in cells), unit="spp", desc="render",
               leave=False, disable=not progress,
               bar_format="{desc}: {n:.0f} spp [{elapsed}]" if timed else
               "{l_bar}{bar}| {n:.0f}/{total_fmt} spp [{elapsed}<{remaining}]")
    sigints = []  # Ctrl-C in the client: counted by a handler, so that no KeyboardInterrupt lands mid-step
    restore = None
    if threading.current_thread() is threading.main_thread() and \
            signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        restore = signal.signal(signal.SIGINT, lambda signum, frame: sigints.append(1))
    try:
        while left:
            if len(sigints) > 1:  # the second Ctrl-C: stop waiting for the segments still out
                for f in left:
                    f.cancel()
                break
            if sigints and not stop.is_set():
                stop.set()  # the first: every segment ends after its pass in flight
            try:
                finished, _ = wait(list(left), timeout=0.5, return_when="FIRST_COMPLETED")
            except TimeoutError:
                finished = set()
            for f in finished:
                left.discard(f)
                c = futs[f]
                seg = f.result()
                done[c["seed"]] = seg
                if segments_dir is not None and not seg["stats"]["interrupted"]:
                    _store(segments_dir, c["key"], seg)
            try:
                for _, step in queue.get(batch=True):
                    bar.update(step)
            except Exception:  # the queue is a convenience: a lost update only slows the bar
                pass
    finally:
        if restore is not None:
            signal.signal(signal.SIGINT, restore)
        bar.close()
    interrupted = bool(sigints)
    return interrupted


def split_spp(spp, n):
    """The spp of each of n segments: spp // n, the first spp % n one more."""
    return [spp // n + (1 if k < spp % n else 0) for k in range(n)]


def _name(x):
    """A guide's or integrator's name and settings as text (a name, a spec or an object)."""
    if x is None or isinstance(x, str):
        return str(x)
    return f"{getattr(x, 'name', type(x).__name__)}:{json.dumps(getattr(x, 'settings', {}), sort_keys=True, default=str)}"
