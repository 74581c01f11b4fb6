"""The ODIS network's pipeline: `python -m learn.odis {data,train,export}`.

    data      shards of training data (learn.odis_data) for scene seeds, through Dask
    train     train OdisUNet on the shards (checkpoints every epoch, resumes, early stopping)
    export    a run's best weights into tracer/weights/odis.{pt,json} with their manifest

Defaults are the shipped model's; the manifest records the commands that made it.
"""
import os
import sys

from .shards import add_data_args, add_train_args, command_line, data_command, pipeline_parser

DATA = os.path.join("learn", "data", "odis")
RUNS = os.path.join("learn", "runs", "odis")


def main(argv=None):
    p, sub = pipeline_parser("python -m learn.odis", __doc__)
    d = sub.add_parser("data", help="generate shards")
    add_data_args(d, "0:400", DATA)
    d.add_argument("--size", type=int, default=None, help="film width and height")
    d.add_argument("--centres", type=int, default=None, help="maps per scene")
    d.add_argument("--per-bin", type=int, default=None, help="ground-truth probes per bin (a square)")
    d.add_argument("--initial-depth", type=int, default=None,
                   help="max_depth of the initial pass (3: direct plus one-bounce light; 0: no limit)")
    t = sub.add_parser("train", help="train (resumes from the run's checkpoint)")
    add_train_args(t, DATA, os.path.join(RUNS, "w4"), width=4, epochs=40, patience=5, batch=32, lr=1e-3,
                   val_scenes=0.1)
    t.add_argument("--loss", choices=("kl", "l1"), default="kl", help="kl: of the sampling mixture to the integrand; l1: the paper's, on mu-law maps")
    t.add_argument("--minutes", type=float, default=None, help="stop after this many minutes (resume later)")
    e = sub.add_parser("export", help="export a run's best weights into tracer/weights")
    e.add_argument("--run", default=os.path.join(RUNS, "w4"))
    e.add_argument("--out", default=None, help="weights folder (default: tracer/weights)")
    e.add_argument("--name", default=None, help="weights name (default: odis; the guide's weights setting)")
    a = p.parse_args(argv)
    if a.cmd == "data":
        from .odis_data import make_shard

        cfg = {k: v for k, v in (("width", a.size), ("height", a.size), ("centres", a.centres),
                                 ("per_bin", a.per_bin), ("initial_depth", a.initial_depth)) if v is not None}
        return data_command(make_shard, a, cfg)
    from . import odis_train

    if a.cmd == "train":
        a.command = command_line("python -m learn.odis", argv)
        odis_train.train(a)
        return 0
    odis_train.export(a.run, a.out, a.name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
