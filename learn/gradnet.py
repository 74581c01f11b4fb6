"""GradNet's pipeline: `python -m learn.gradnet {data,train,export}`.

    data      shards of gradient-domain patches (learn.gradnet_data) for scene seeds, through Dask;
              --reference-spp adds path-traced references (the validation scenes: for reporting only)
    train     train GradNet on the shards without ground truth (learn.gradnet_train; checkpoints every
              epoch, resumes, early stopping on the held-out scenes' loss)
    export    a run's best weights into tracer/weights/gradnet.{pt,json} with their manifest

The shipped model's data: `data --seeds 0:112`, then `data --seeds 360:400 --reference-spp 1024`
(train holds out the scenes with references).
"""
import os
import sys

from .shards import add_data_args, add_train_args, command_line, data_command, pipeline_parser

DATA = os.path.join("learn", "data", "gradnet")
RUNS = os.path.join("learn", "runs", "gradnet")


def main(argv=None):
    p, sub = pipeline_parser("python -m learn.gradnet", __doc__)
    d = sub.add_parser("data", help="generate shards")
    add_data_args(d, "0:112", DATA)
    d.add_argument("--size", type=int, default=None, help="film width and height")
    d.add_argument("--patch", type=int, default=None, help="patch side in pixels")
    d.add_argument("--patches", type=int, default=None, help="patches per scene")
    d.add_argument("--reference-spp", type=int, default=None, help="path-traced reference spp (0: none)")
    d.add_argument("--box", type=float, default=None, help="share of the scenes that are Cornell-like boxes (default 0)")
    d.add_argument("--spp", default=None, help="comma-separated spp, one drawn per scene (default 16,32,64,128,256)")
    t = sub.add_parser("train", help="train (resumes from the run's checkpoint)")
    add_train_args(t, DATA, os.path.join(RUNS, "w8"), width=8, epochs=35, patience=8, batch=8, lr=1e-3,
                   val_scenes=None)
    t.add_argument("--blocks", type=int, default=2, help="residual blocks at 1/8 resolution")
    t.add_argument("--layout", choices=("v2", "v2-l2", "v1", "paper"), default="v2",
                   help="v2: two full-resolution layers correct a shortened L1 solve, with the noise inputs "
                        "(default); v2-l2: the same correcting the L2 solution; "
                        "v1: one full-resolution layer corrects the base; paper: the paper's decoder")
    t.add_argument("--alpha", type=float, default=1.0, help="weight of the data term (eq. 7)")
    t.add_argument("--lambda-max", type=float, default=2.0, help="the cap of eq. 14's first-order weight (the paper's 2)")
    t.add_argument("--minutes", type=float, default=None, help="stop after this many minutes (resume later)")
    e = sub.add_parser("export", help="export a run's best weights into tracer/weights")
    e.add_argument("--run", default=os.path.join(RUNS, "w8"))
    e.add_argument("--out", default=None, help="weights folder (default: tracer/weights)")
    e.add_argument("--name", default=None, help="weights name (default: gradnet; the recon_weights setting)")
    a = p.parse_args(argv)
    if a.cmd == "data":
        from .gradnet_data import make_shard

        spp = None if a.spp is None else [int(v) for v in a.spp.split(",") if v.strip()]
        if spp is not None and (not spp or min(spp) < 1):
            p.error(f"--spp wants positive integers, got {a.spp!r}")
        cfg = {k: v for k, v in (("width", a.size), ("height", a.size), ("patch", a.patch), ("patches", a.patches),
                                 ("reference_spp", a.reference_spp), ("spp", spp), ("box", a.box)) if v is not None}
        return data_command(make_shard, a, cfg)
    from . import gradnet_train

    if a.cmd == "train":
        a.command = command_line("python -m learn.gradnet", argv)
        gradnet_train.train(a)
        return 0
    gradnet_train.export(a.run, a.out, a.name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
