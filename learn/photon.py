"""The photon map network's pipeline: `python -m learn.photon {data,train,export,evaluate}`.

    data      shards of training data (learn.photon_data) for scene seeds, through Dask
    train     train PhotonUNet on the shards (checkpoints, resumes, early stopping)
    export    the best checkpoint into tracer/weights/photon_cnn.{pt,json} with its manifest
    evaluate  map quality on the validation shards: L1 to the ground truth for cnn, gaussian,
              pullpush and none, by photon-count range

Defaults are the shipped model's; the manifest records the commands that made it.
"""
import os
import sys

from .shards import add_data_args, add_train_args, command_line, data_command, pipeline_parser

DATA = os.path.join("learn", "data", "photon")
RUNS = os.path.join("learn", "runs", "photon")


def main(argv=None):
    p, sub = pipeline_parser("python -m learn.photon", __doc__)
    d = sub.add_parser("data", help="generate shards")
    add_data_args(d, "0:40", DATA)
    d.add_argument("--n-gt", type=int, default=None, help="ground-truth photons per scene")
    d.add_argument("--n0", type=int, default=None, help="input photons of iteration 0")
    d.add_argument("--size", type=int, default=None, help="image size of the guide's pilot")
    t = sub.add_parser("train", help="train (resumes from the run's checkpoint)")
    add_train_args(t, DATA, os.path.join(RUNS, "w4"), width=4, epochs=30, patience=4, batch=64, lr=1e-3,
                   val_scenes=0.15)
    t.add_argument("--lam", type=float, default=2.0, help="asymmetric loss weight lambda (eq. 13)")
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
        from .photon_data import make_shard

        cfg = {k: v for k, v in (("n_gt", a.n_gt), ("n0", a.n0), ("width", a.size), ("height", a.size)) if v}
        return data_command(make_shard, a, cfg)
    if a.cmd == "train":
        from .photon_train import train

        a.command = command_line("python -m learn.photon", argv)
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
