"""Independent bench cells on Dask: a LocalCluster sized so that no two timed renders share a core,
or any cluster's scheduler (`--scheduler ADDRESS`).

A cell is a dict naming one render (bench.convergence: scene, method, seed, budget); `run(fn,
cells, ...)` submits `fn(cell)` for each and hands each result to `done` in the calling process as
it arrives, so the caller can store it at once (atomically): a sweep that is killed keeps every
finished cell, and `todo(cells, records, key)` leaves those out when it is started again.

On the default LocalCluster each worker is one process running one cell at a time with `threads`
Numba threads, and there are cores // threads workers; a worker's first cell pins the worker to
its own `threads` cores (os.sched_setaffinity; the render's thread pools, made after it, inherit
the set), so equal-time comparisons stay fair however many cells run at once. On a cluster of
your own, give each worker one task slot (`--nthreads 1`) and no more renders per machine than
its cores allow.
"""
import contextlib
import os

WORKER_ENV = "BENCH_SWEEP_CORES"  # set in a LocalCluster worker: "c0,c1,..." the cores it pins to


def todo(cells, records, key):
    """The cells whose key(cell) no record has (key(record) equal) yet, in order."""
    have = {key(r) for r in records}
    return [c for c in cells if key(c) not in have]


def _pin():
    """Pin this worker (a LocalCluster's) to its cores, once: from the task thread, before any
    render starts its thread pools."""
    from distributed import get_worker

    w = get_worker()
    if getattr(w, "_bench_pinned", False) or not hasattr(os, "sched_setaffinity"):
        return
    w._bench_pinned = True
    per = int(os.environ.get(WORKER_ENV, "0") or 0)
    if per <= 0:
        return
    idx = int(w.name) if str(w.name).isdigit() else 0
    cores = sorted(os.sched_getaffinity(0))
    mine = cores[idx * per:(idx + 1) * per]
    if len(mine) == per:
        os.sched_setaffinity(0, mine)


def _call(fn, cell, pin):
    if pin:
        _pin()
    return fn(cell)


def local_workers(threads):
    """Workers of the default LocalCluster: one per `threads` cores, at least one."""
    return max(1, (os.cpu_count() or 1) // max(1, threads))


FRESH_AFTER = 40  # LocalCluster: cells per worker between restarts of its processes (see run)


def run(fn, cells, done, threads=1, scheduler=None, workers=None, progress=True, desc="cells", fresh_after=None):
    """fn(cell) for every cell on Dask (fn importable by the workers: a module-level function);
    done(cell, result) in this process as each finishes. scheduler: a Dask scheduler address (None:
    a LocalCluster of `workers` processes, default local_workers(threads), each pinned to its
    cores; workers 0: no Dask, the cells in this process in order).

    On the LocalCluster the cells go in batches of fresh_after (default FRESH_AFTER; 0: one batch)
    per worker, the worker processes
    restarted between batches: a worker's resident memory grew by 40-200 MB per cell over a
    594-cell sweep (to 20 GB on the 24 GB VM), which a plain loop of the same renders in one process
    does not do (docs/findings.md, 2026-11-27). A restart costs the worker's imports and its
    first render of each scene, outside every budget."""
    if not cells:
        return
    if workers == 0 and scheduler is None:  # in this process, one after the other (no Dask)
        for c in cells:
            done(c, fn(c))
        return
    from dask.distributed import Client, as_completed
    from tqdm import tqdm

    from tracer.distributed import local_cluster

    with contextlib.ExitStack() as stack:
        pin = scheduler is None
        if pin:
            n = min(workers or local_workers(threads), len(cells))
            pinned = n * threads <= (os.cpu_count() or 1)
            env = {WORKER_ENV: str(threads if pinned else 0), "OMP_NUM_THREADS": str(threads)}
            cluster = stack.enter_context(local_cluster(n_workers=n, threads_per_worker=1, processes=True,
                                                        dashboard_address=None, silence_logs=40, env=env))
            client = stack.enter_context(Client(cluster))
        else:
            client = stack.enter_context(Client(scheduler))
        bar = stack.enter_context(tqdm(total=len(cells), desc=desc, unit="cell", disable=not progress))
        every = FRESH_AFTER if fresh_after is None else fresh_after
        step = every * n if pin and every > 0 else len(cells)
        for b in range(0, len(cells), step):
            if b > 0:
                client.restart()
            batch = cells[b:b + step]
            futs = {client.submit(_call, fn, c, pin, pure=False, priority=-i): c for i, c in enumerate(batch)}
            for fut in as_completed(futs):
                done(futs[fut], fut.result())
                bar.update(1)
