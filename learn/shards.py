"""Datasets as independent shards, one per scene seed, generated in parallel through Dask.

`run_shards(make, seeds, out_dir, ...)` calls `make(seed, path)` for every seed whose shard
`out_dir/shard_<seed>.npz` does not exist yet (finished shards are skipped, so a killed run
resumes where it stopped). `make` must write the file through `save_npz` (temporary file, then
renamed into place), so a shard is either whole or absent. Shards run on a Dask LocalCluster on
this machine (one single-threaded worker process per core by default), or on an existing
cluster with `scheduler="tcp://host:port"`: the same code path either way. A progress bar counts
finished shards.
"""
import contextlib
import hashlib
import os
import time

import numpy as np

from tracer.imageio import replace_atomically


def pipeline_parser(prog, doc):
    """(parser, its subparsers) of a `python -m learn.<net>` command, described by doc's first line."""
    import argparse

    p = argparse.ArgumentParser(prog=prog, description=doc.splitlines()[0])
    return p, p.add_subparsers(dest="cmd", required=True)


def command_line(prog, argv):
    """The command as typed: prog and argv (sys.argv's arguments when None)."""
    import sys

    return " ".join([prog] + list(argv if argv is not None else sys.argv[1:]))


def data_command(make_shard, a, cfg):
    """The `data` command: the missing shards of a.seeds into a.out, make_shard(seed, path, **cfg)
    on Dask (a.workers, a.scheduler); prints their count and mean time. Returns 0."""
    import functools

    done = run_shards(functools.partial(make_shard, **cfg), a.seeds, a.out, workers=a.workers,
                      scheduler=a.scheduler)
    if done:
        print(f"{len(done)} shards, {sum(done.values()) / len(done):.1f} s each in a worker")
    return 0


def seed_range(text):
    """'a:b' -> [a, ..., b - 1]; 'a' -> [a]."""
    a, _, b = text.partition(":")
    return list(range(int(a), int(b))) if b else [int(a)]


def add_data_args(parser, seeds, out):
    """The `data` command's common options: --seeds, --out, --workers, --scheduler."""
    parser.add_argument("--seeds", type=seed_range, default=seed_range(seeds), help=f"scene seeds a:b (default {seeds})")
    parser.add_argument("--out", default=out)
    parser.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default: one per core)")
    parser.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler")


def add_train_args(parser, data, run, width, epochs, patience, batch, lr, val_scenes):
    """The `train` command's common options (defaults given)."""
    parser.add_argument("--data", default=data)
    parser.add_argument("--run", default=run)
    parser.add_argument("--width", type=int, default=width)
    parser.add_argument("--epochs", type=int, default=epochs)
    parser.add_argument("--patience", type=int, default=patience)
    parser.add_argument("--batch", type=int, default=batch)
    parser.add_argument("--lr", type=float, default=lr)
    parser.add_argument("--val-scenes", type=float, default=val_scenes, help="share of scenes held out for validation")
    parser.add_argument("--max-steps", type=int, default=None, help="steps per epoch at most (tests)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--device", default=None, help="torch device (default: cuda when available, else cpu)")


def shard_path(out_dir, seed):
    return os.path.join(out_dir, f"shard_{int(seed):05d}.npz")


def save_npz(path, **arrays):
    """np.savez_compressed into `path` through a temporary file renamed into place."""
    replace_atomically(path, lambda tmp: np.savez_compressed(tmp, **arrays))


def changed_options(cfg, defaults, flags):
    """The command-line options, as text, that remake a data config `cfg`: ` FLAG VALUE` for each
    key of `flags` ({config key: flag}) whose value differs from `defaults` (lists comma-joined)."""
    text = lambda v: ",".join(str(x) for x in v) if isinstance(v, (list, tuple)) else str(v)  # noqa: E731
    return "".join(f" {flag} {text(cfg[k])}" for k, flag in flags.items() if cfg.get(k, defaults[k]) != defaults[k])


def shard_config(path, defaults):
    """The data config the shard at `path` was made with, over `defaults` (all of them where the
    shard is gone or predates a key)."""
    import json

    cfg = dict(defaults)
    if os.path.exists(path):
        with np.load(path) as z:
            if "config" in z.files:
                cfg.update(json.loads(str(z["config"])))
    return cfg


def list_shards(out_dir):
    """Paths of the finished shards in out_dir, by seed."""
    if not os.path.isdir(out_dir):
        return []
    return sorted(os.path.join(out_dir, f) for f in os.listdir(out_dir)
                  if f.startswith("shard_") and f.endswith(".npz") and ".tmp" not in f)


def _work(make, seed, path, threads):
    """One shard in a worker: the process's Numba threads capped at `threads` first."""
    import numba

    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    t0 = time.perf_counter()
    make(seed, path)
    return seed, time.perf_counter() - t0


def run_shards(make, seeds, out_dir, workers=None, scheduler=None, threads_per_worker=1, progress=True):
    """Generate the missing shards of `seeds` into out_dir; returns {seed: seconds} of those run.
    `make(seed, path)` must be importable by the workers (a module-level function)."""
    from dask.distributed import Client, as_completed
    from tqdm import tqdm

    from tracer.distributed import local_cluster

    os.makedirs(out_dir, exist_ok=True)
    todo = [int(s) for s in seeds if not os.path.exists(shard_path(out_dir, s))]
    if not todo:
        return {}
    tag = hashlib.sha1(os.path.abspath(out_dir).encode()).hexdigest()[:8]  # keys unique per dataset
    with contextlib.ExitStack() as stack:
        if scheduler is None:
            n = workers or os.cpu_count() or 1
            cluster = stack.enter_context(local_cluster(n_workers=min(n, len(todo)), threads_per_worker=1,
                                                        processes=True, dashboard_address=None, silence_logs=40))
            client = stack.enter_context(Client(cluster))
        else:
            client = stack.enter_context(Client(scheduler))
        futs = [client.submit(_work, make, s, shard_path(out_dir, s), threads_per_worker, key=f"shard-{tag}-{s}",
                              pure=False) for s in todo]
        bar = stack.enter_context(tqdm(total=len(todo), desc="shards", unit="shard", disable=not progress))
        done = {}
        for fut in as_completed(futs):
            seed, secs = fut.result()
            done[seed] = secs
            bar.update(1)
    return done
