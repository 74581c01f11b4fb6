"""The photon map network's pipeline: `python -m learn.photon {data,train,export,evaluate}`.

    data      shards of training data (learn.photon_data) for scene seeds, through Dask
    train     train PhotonUNet on the shards (checkpoints, resumes, early stopping)
    export    the best checkpoint into tracer/weights/photon_cnn.{pt,json} with its manifest
    evaluate  map quality on the validation shards: L1 to the ground truth for cnn, gaussian,
              pullpush and none, by photon-count range

Defaults are the shipped model's; the manifest records the commands that made it.
"""
import argparse
import os
import sys

DATA = os.path.join("learn", "data", "photon")
RUNS = os.path.join("learn", "runs", "photon")


def seed_range(text):
    a, _, b = text.partition(":")
    return list(range(int(a), int(b))) if b else [int(a)]


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m learn.photon", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("data", help="generate shards")
    d.add_argument("--seeds", type=seed_range, default=seed_range("0:40"), help="scene seeds a:b (default 0:40)")
    d.add_argument("--out", default=DATA)
    d.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default: one per core)")
    d.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler")
    d.add_argument("--n-gt", type=int, default=None, help="ground-truth photons per scene")
    d.add_argument("--n0", type=int, default=None, help="input photons of iteration 0")
    d.add_argument("--size", type=int, default=None, help="image size of the guide's pilot")
    t = sub.add_parser("train", help="train (resumes from the run's checkpoint)")
    t.add_argument("--data", default=DATA)
    t.add_argument("--run", default=os.path.join(RUNS, "w4"))
    t.add_argument("--width", type=int, default=4)
    t.add_argument("--epochs", type=int, default=30)
    t.add_argument("--patience", type=int, default=4)
    t.add_argument("--batch", type=int, default=64)
    t.add_argument("--lr", type=float, default=1e-3)
    t.add_argument("--lam", type=float, default=2.0, help="asymmetric loss weight lambda (eq. 13)")
    t.add_argument("--val-scenes", type=float, default=0.15, help="share of scenes held out for validation")
    t.add_argument("--max-steps", type=int, default=None, help="steps per epoch at most (tests)")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--device", default=None, help="torch device (default: cuda when available, else cpu)")
    e = sub.add_parser("export", help="export a run's best weights into tracer/weights")
    e.add_argument("--run", default=os.path.join(RUNS, "w4"))
    e.add_argument("--out", default=None, help="weights folder (default: tracer/weights)")
    e.add_argument("--testset", default=None, metavar="NPZ",
                   help="also store a small set of validation maps here (tests/data/photon_maps_val.npz)")
    e.add_argument("--data", default=DATA)
    v = sub.add_parser("evaluate", help="map quality of cnn and the filters on the validation scenes")
    v.add_argument("--data", default=DATA)
    v.add_argument("--run", default=None, help="a run's best checkpoint instead of the shipped weights")
    v.add_argument("--out", default=None, help="write the table (markdown) and JSON here")
    a = p.parse_args(argv)
    if a.cmd == "data":
        import functools

        from .photon_data import make_shard
        from .shards import run_shards

        cfg = {k: v for k, v in (("n_gt", a.n_gt), ("n0", a.n0), ("width", a.size), ("height", a.size)) if v}
        done = run_shards(functools.partial(make_shard, **cfg), a.seeds, a.out, workers=a.workers,
                          scheduler=a.scheduler)
        if done:
            print(f"{len(done)} shards, {sum(done.values()) / len(done):.1f} s each in a worker")
        return 0
    if a.cmd == "train":
        from .photon_train import train

        a.command = " ".join(["python -m learn.photon"] + list(argv if argv is not None else sys.argv[1:]))
        train(a)
        return 0
    if a.cmd == "export":
        from .photon_train import export

        from .photon_train import write_testset

        export(a.run, a.out)
        if a.testset:
            write_testset(a.data, a.run, a.testset)
        return 0
    from .photon_train import evaluate

    evaluate(a)
    return 0


if __name__ == "__main__":
    sys.exit(main())
