"""Training and export of GradNet (tracer.gradient.gradnet), without ground truth.

One example is one colour channel of a patch (learn.gradnet_data): the network sees the compressed
indirect light and the 7 features, and the compressed dx, dy (and, in the default layout `v2`,
the shortened L1 solution of the patch, which it corrects, and the standard errors of base and
gradients: GradNet.v2); its loss is eq. 7
(learn.gradnet_loss.total_loss: gradient L1 + alpha data L1 + lambda first-order term, lambda by
eq. 14's schedule), the G-branch's is eq. 11 with the base image. Both train in every step from
one backward pass of their sum: the G-branch's parameters get gradients from eq. 11 only (G enters
eq. 7 detached) and the network's from eq. 7 only, so the two updates are those of alternating
steps. Adam, betas (0.5, 0.999), the learning rate decayed by 0.95 every 2 epochs.

Validation holds out whole scenes: by default the shards with references (the last seeds), else
the last `val_scenes` share of the seeds. Its selection figure, which picks the best epoch and decides early stopping, is
eq. 7 on the held-out patches at the lambda the run ends with (lambda_schedule(epochs) of the
run's first start, kept on resume): the objective the schedule is heading for, the same function
at every epoch. The references are used
to report only: the relMSE of each epoch's reconstruction (plus the direct light) against them,
beside the relMSE of the L1 and L2 screened Poisson solves (alpha 0.2, tracer's default) of the
same patches and of the noisy base image. Augmentation: each training example under one of the
8 symmetries of the square (`dihedral`), drawn per epoch.

A run folder keeps `checkpoint.pt` (model, optimiser, epoch, history, best weights; written
through a temporary file each epoch) and `history.json`; training resumes from it.
"""
import os
import time

import numpy as np
import torch

from tracer import metrics
from tracer.gradient import gradnet, poisson
from tracer.gradient.gradnet import GradNet, expand, mu_law

from .gradnet_data import DEFAULTS as DATA_DEFAULTS, N_CHANNELS
from .gradnet_loss import first_order_loss, g_loss, grad_loss, data_loss, lambda_schedule, total_loss
from .shards import changed_options, list_shards, shard_config
from .photon_train import (_save, _write_json, best_model, end_epoch, epochs_left, open_run, optimiser_step,
                           start_training)

BETAS = (0.5, 0.999)
LR_DECAY, LR_EVERY = 0.95, 2
SOLVE_ALPHA = 0.2  # the screened Poisson baselines' weight on the base (tracer's default)
LAYOUTS = ("v2", "v2-l2", "v1", "paper")  # GradNet.v2 (v2-l2: correcting L2); v1: full_res, one head layer, base
# residual, no noise; the paper's


def build(layout, width, blocks):
    """The GradNet of a layout name (LAYOUTS)."""
    if layout in ("v2", "v2-l2"):
        return GradNet.v2(width, blocks, "l2" if layout == "v2-l2" else "l1")
    if layout not in LAYOUTS:
        raise ValueError(f"unknown layout {layout!r}; valid: " + ", ".join(LAYOUTS))
    return GradNet(width, blocks, layout == "v1")


def with_solutions(x):
    """x (m, 28, P, P) with the solutions a residual network corrects (gradnet.solution) of each
    patch's indirect light appended: L2 as channels 28:31, the shortened L1 as 31:34; float32."""
    sol = np.empty((x.shape[0], 6) + x.shape[2:], np.float32)
    for k in range(x.shape[0]):
        p = x[k].astype(np.float64).transpose(1, 2, 0)
        for j, residual in enumerate(("l2", "l1")):
            sol[k, 3 * j:3 * j + 3] = gradnet.solution(residual, p[..., 0:3], p[..., 3:6], p[..., 6:9]).transpose(2, 0, 1)
    return np.concatenate([x, sol], 1)


def load_shards(paths):
    """The shards concatenated: {x (m, 34, P, P) float32 (the shards' 28 channels and the L2 and
    L1 solutions: with_solutions), ref (m, 3, P, P) or None (when any shard has none), spp, scene per patch,
    dropped: patches dropped in all}."""
    xs, refs, spp, scene, dropped = [], [], [], [], 0
    for p in paths:
        with np.load(p) as z:
            m = z["x"].shape[0]
            if z["x"].shape[1] != N_CHANNELS:
                raise SystemExit(f"{p}: {z['x'].shape[1]} channels, not {N_CHANNELS} (a shard of an older "
                                 "format: make the data again with python -m learn.gradnet data)")
            xs.append(z["x"])
            refs.append(z["ref"] if "ref" in z.files else None)
            spp.append(np.full(m, int(z["spp"])))
            scene.append(np.full(m, int(z["seed"])))
            dropped += int(z["dropped"])
    cat = lambda v, shape: np.concatenate(v) if v else np.zeros(shape, np.float32)  # noqa: E731
    has_ref = bool(refs) and all(r is not None for r in refs)
    return {"x": with_solutions(cat(xs, (0, N_CHANNELS, 1, 1))), "ref": cat(refs, (0, 3, 1, 1)) if has_ref else None,
            "spp": cat(spp, (0,)), "scene": cat(scene, (0,)), "dropped": dropped}


def dihedral(x, k):
    """Patches x (B, 34, P, P) torch under symmetry k of the square (bit 0: transpose, bit 1: mirror
    left-right, bit 2: mirror top-bottom), with the gradients carried along: the forward
    differences of the transformed image are the transformed dx, dy (but in the last column of dx
    and the last row of dy, which the losses leave out); the gradients' variances (channels 22:25,
    25:28) move as the gradients do, without the sign."""
    if k & 1:
        x = x.transpose(-1, -2)
        x = torch.cat([x[:, 0:3], x[:, 6:9], x[:, 3:6], x[:, 9:22], x[:, 25:28], x[:, 22:25], x[:, 28:]], 1)
    if k & 2:
        x = x.flip(-1)
        x = torch.cat([x[:, 0:3], -torch.roll(x[:, 3:6], -1, -1), x[:, 6:22], torch.roll(x[:, 22:25], -1, -1),
                       x[:, 25:]], 1)
    if k & 4:
        x = x.flip(-2)
        x = torch.cat([x[:, 0:6], -torch.roll(x[:, 6:9], -1, -2), x[:, 9:25], torch.roll(x[:, 25:28], -1, -2),
                       x[:, 28:]], 1)
    return x


def reference_share(data):
    """The share of the shards in `data` that hold references, checked to be the last seeds (so
    that holding out that share holds out exactly them)."""
    paths = list_shards(data)
    has = []
    for p in paths:
        with np.load(p) as z:
            has.append("ref" in z.files)
    k = sum(has)
    if k == len(has):
        raise SystemExit(f"{data}: every shard has references: nothing would be left to train on "
                         "(make the training scenes without --reference-spp, or give --val-scenes)")
    if not k or not all(has[len(has) - k:]):
        raise SystemExit(f"{data}: the validation scenes are the shards with references, and they must be the "
                         "last seeds (python -m learn.gradnet data --seeds A:B --reference-spp N); or give --val-scenes")
    return k / len(paths)


def batch(x, idx, aug=None, model=None):
    """Tensors of the examples idx (patch idx // 3, colour idx % 3) of patches x (m, 34, P, P),
    each under the symmetry aug[i] (dihedral; None: as stored): (data (B, n_data, P, P), grads
    (B, n_grad, P, P): the inputs of `model` (GradNet.forward; None: the paper's 8 and 2); base,
    gx, gy (B, 1, P, P) linear; features (B, 7, P, P))."""
    p, c = idx // 3, idx % 3
    xb = torch.from_numpy(x[p])
    if aug is not None:
        xb = torch.cat([dihedral(xb[i:i + 1], int(k)) for i, k in enumerate(aug)])
    ar = torch.arange(len(idx))
    c = torch.from_numpy(c)
    base, gx, gy = xb[ar, c][:, None], xb[ar, 3 + c][:, None], xb[ar, 6 + c][:, None]
    feats = xb[:, 12:19]
    data, grads = [mu_law(base), feats], [mu_law(gx), mu_law(gy)]
    if model is not None and model.residual != "base":
        data.append(mu_law(xb[ar, (28 if model.residual == "l2" else 31) + c][:, None]))
    if model is not None and model.noise:
        data.append(gradnet.stderr(xb[ar, 19 + c][:, None]))
        grads += [gradnet.stderr(xb[ar, 22 + c][:, None]), gradnet.stderr(xb[ar, 25 + c][:, None])]
    return torch.cat(data, 1), torch.cat(grads, 1), base, gx, gy, feats


def losses(model, data, grads, base, gx, gy, feats, alpha, lam):
    """(eq. 7 for the network with G detached, eq. 11 for the G-branch, the network's output
    (linear), G)."""
    G = model.derivatives(data, grads)
    out = expand(model(data, grads))
    return total_loss(out, base, gx, gy, feats, G.detach(), alpha, lam), g_loss(base, feats, G), out, G


def set_lr(opt, lr, epoch):
    for g in opt.param_groups:
        g["lr"] = lr * LR_DECAY ** (epoch // LR_EVERY)
        g["betas"] = BETAS


def baselines(va):
    """Per validation patch, the relMSE (against the reference) of the L1 and L2 solves and of the
    noisy base image, each plus the direct light: {name: (m,) array}."""
    out = {"l1": [], "l2": [], "base": []}
    for k in range(va["x"].shape[0]):
        x = va["x"][k].astype(np.float64).transpose(1, 2, 0)
        direct, ref = x[..., 9:12], va["ref"][k].transpose(1, 2, 0)
        for name, method in (("l1", "l1"), ("l2", "l2"), ("base", "none")):
            img = poisson.reconstruct(method, x[..., 0:3], x[..., 3:6], x[..., 6:9], SOLVE_ALPHA) + direct
            out[name].append(metrics.relmse(img, ref))
    return {k: np.array(v) for k, v in out.items()}


def evaluate(model, va, alpha, lam_select, device, batch_size=48):
    """Validation figures of the model: the selection loss (eq. 7 at lam_select), its terms, eq. 11,
    and with references the mean relMSE of the reconstruction plus the direct light."""
    model.eval()
    n = 3 * va["x"].shape[0]
    sums = {"grad": 0.0, "data": 0.0, "first_order": 0.0, "g": 0.0}
    recon = np.empty((va["x"].shape[0], 3) + va["x"].shape[2:], np.float32)
    with torch.no_grad():
        for i in range(0, n, batch_size):
            idx = np.arange(i, min(i + batch_size, n))
            data, grads, base, gx, gy, feats = (t.to(device) for t in batch(va["x"], idx, model=model))
            G = model.derivatives(data, grads)
            out = expand(model(data, grads))
            w = len(idx)
            sums["grad"] += w * float(grad_loss(out, gx, gy))
            sums["data"] += w * float(data_loss(out, base))
            sums["first_order"] += w * float(first_order_loss(out, base, feats, G))
            sums["g"] += w * float(g_loss(base, feats, G))
            recon[idx // 3, idx % 3] = out[:, 0].cpu().numpy()
    model.train()
    ev = {"val_" + k: v / n for k, v in sums.items()}
    ev["val_select"] = ev["val_grad"] + alpha * ev["val_data"] + lam_select * ev["val_first_order"]
    if va.get("ref") is not None:
        img = recon + va["x"][:, 9:12]
        ev["val_relmse"] = float(np.mean([metrics.relmse(img[k].transpose(1, 2, 0), va["ref"][k].transpose(1, 2, 0))
                                          for k in range(img.shape[0])]))
    return ev


def train(a):
    """Train (or resume) the run in a.run; a resumed run keeps its scene split and settings (a
    differing one is an error); each epoch's shuffle is seeded by (seed, epoch)."""
    if a.val_scenes is None:
        a.val_scenes = reference_share(a.data)
    fixed = ("width", "blocks", "layout", "batch", "lr", "seed", "alpha", "lambda_max")
    device, ck, ck_path, cfg, tr_paths, va_paths = open_run(a, fixed, "python -m learn.gradnet data")
    cfg.setdefault("select_lambda", lambda_schedule(a.epochs, a.lambda_max))  # kept when a resumed run changes --epochs
    tr = load_shards(tr_paths)
    va = load_shards(va_paths) if va_paths else None
    n = 3 * tr["x"].shape[0]
    if n < a.batch:
        raise SystemExit(f"{a.data}: {n} training examples, fewer than one batch of {a.batch}")
    print(f"train: {tr['x'].shape[0]} patches ({n} examples) from {len(tr_paths)} scenes, {tr['dropped']} dropped; "
          f"validation: {0 if va is None else va['x'].shape[0]} patches from {len(va_paths)} scenes"
          f"{'' if va is None or va['ref'] is not None else ' (no references)'}; device {device}", flush=True)
    torch.manual_seed(a.seed)
    model = build(a.layout, a.width, a.blocks).to(device)
    opt, state = start_training(a, ck, ck_path, model, "loss")
    lam_select = cfg["select_lambda"]
    if va is not None and va["ref"] is not None and "baselines" not in state:
        state["baselines"] = {k: float(v.mean()) for k, v in baselines(va).items()}
    if "baselines" in state:
        print("validation relMSE: " + ", ".join(f"{k} {v:.4f}" for k, v in state["baselines"].items()), flush=True)
    for _ in epochs_left(a, state):
        t0 = time.perf_counter()
        set_lr(opt, a.lr, state["epoch"])
        lam = lambda_schedule(state["epoch"] + 1, a.lambda_max)
        rng = np.random.default_rng([a.seed, state["epoch"]])
        order = rng.permutation(n)
        turns = rng.integers(0, 8, n)
        steps, main_losses, g_losses = [], [], []
        for i in range(0, n - a.batch + 1, a.batch):
            tensors = (t.to(device) for t in batch(tr["x"], order[i:i + a.batch], turns[i:i + a.batch], model))
            main, lg, _, _ = losses(model, *tensors, a.alpha, lam)
            main_losses.append(main.item())
            g_losses.append(lg.item())
            if optimiser_step(a, opt, main + lg, state, steps):
                break
        ev = evaluate(model, va, a.alpha, lam_select, device) if va is not None else \
            {"val_select": float(np.mean(main_losses))}
        state["epoch"] += 1
        rec = dict(ev, epoch=state["epoch"], lam=lam, lr=opt.param_groups[0]["lr"],
                   train_loss=float(np.mean(main_losses)), train_g=float(np.mean(g_losses)),
                   seconds=time.perf_counter() - t0)
        end_epoch(a, state, model, opt, cfg, ck_path, rec, ev["val_select"], "best_val", best_eval=ev)
        rel = f"  relMSE {ev['val_relmse']:.4f}" if "val_relmse" in ev else ""
        print(f"epoch {state['epoch']}: lambda {lam:.3f}  train {rec['train_loss']:.4f} (G {rec['train_g']:.4f})  "
              f"validation {ev['val_select']:.4f}{rel}  ({rec['seconds']:.0f} s)", flush=True)
    return state


def check_input(h=20, w=28, seed=0):
    """A fixed input whose output the manifest stores: buffers of a smooth image with noise, sized
    not a multiple of 8, and its variance buffers. Returns the keyword arguments of
    gradnet.reconstruct less the model."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    img = np.stack([np.sin(4 * x + 2 * y) + 1.2, 0.5 + x, 0.8 + y * y], axis=2)
    noisy = np.maximum(img * rng.gamma(4.0, 0.25, img.shape), 0.0)
    feats = rng.random((h, w, 7))
    return {"indirect": noisy.astype(np.float32),
            "dx": (poisson.grad_x(img) + rng.normal(scale=0.05, size=img.shape)).astype(np.float32),
            "dy": (poisson.grad_y(img) + rng.normal(scale=0.05, size=img.shape)).astype(np.float32),
            "albedo": feats[..., 0:3].astype(np.float32), "normal": (2.0 * feats[..., 3:6] - 1.0).astype(np.float32),
            "depth": feats[..., 6:7].astype(np.float32),
            "variances": tuple((0.01 + 0.05 * rng.random(img.shape)).astype(np.float32) for _ in range(3))}


def seconds_per_image(model, h, w, repeats=3):
    """Median seconds of gradnet.reconstruct on an h x w image (this machine's threads)."""
    kw = check_input(h, w)
    gradnet.reconstruct(model, **kw)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        gradnet.reconstruct(model, **kw)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def seed_runs(names, flag):
    """[(first seed, last seed + 1, flag)] of the contiguous runs of seeds in the shard names."""
    seeds = sorted(int(f[6:11]) for f in names)
    runs = []
    for s in seeds:
        if runs and runs[-1][1] == s:
            runs[-1][1] = s + 1
        else:
            runs.append([s, s + 1])
    return [(lo, hi, flag) for lo, hi in runs]


def export(run, out=None, name=None):
    """The run's best weights into tracer/weights/<name>.pt (default gradnet) with the manifest
    <name>.json."""
    out = out or gradnet.WEIGHTS_DIR
    model, st, cfg = best_model(run, lambda c: build(c["layout"], c["width"], c["blocks"]))
    names = cfg["train_scenes"] + cfg["val_scenes_files"]
    data_cfg = shard_config(os.path.join(cfg["data"], names[0]), DATA_DEFAULTS)
    val_cfg = shard_config(os.path.join(cfg["data"], cfg["val_scenes_files"][0]), DATA_DEFAULTS)
    ref_opt = f" --reference-spp {val_cfg['reference_spp']}" if val_cfg["reference_spp"] else ""
    opts = changed_options(data_cfg, DATA_DEFAULTS, {"width": "--size", "patch": "--patch", "patches": "--patches",
                                                     "spp": "--spp", "box": "--box"})
    command = " && ".join(f"python -m learn.gradnet data --seeds {lo}:{hi}{opts}" + (ref_opt if val else "")
                          for lo, hi, val in (seed_runs(cfg["train_scenes"], False) + seed_runs(cfg["val_scenes_files"], True)))
    y = gradnet.reconstruct(model, **check_input())
    flops = gradnet.count_flops(model, lambda: model(torch.zeros(1, model.n_data, 64, 64),
                                                     torch.zeros(1, model.n_grad, 64, 64)))
    name = name or gradnet.NAME
    manifest = {
        "name": name, "model": model.config(),
        "data": {"command": command, "config": data_cfg, "train_scenes": len(cfg["train_scenes"]),
                 "validation_scenes": cfg["val_scenes_files"], "seed": cfg["seed"]},
        "train": {"command": cfg.get("command") or "python -m learn.gradnet train", "epochs": st["epoch"],
                  "best_epoch": st.get("best_epoch"), "batch": cfg["batch"], "lr": cfg["lr"], "alpha": cfg["alpha"],
                  "lambda_max": cfg.get("lambda_max", 2.0)},
        "validation": st.get("best_eval"), "validation_baselines": st.get("baselines"),
        "parameters": gradnet.parameter_count(model) - gradnet.parameter_count(model.g_branch),
        "parameters_g_branch": gradnet.parameter_count(model.g_branch),
        "flops_per_pixel": round(3 * flops / (64 * 64), 1),
        "seconds_256": round(seconds_per_image(model, 256, 256), 4),
        "seconds_1280x720": round(seconds_per_image(model, 720, 1280), 4),
        "seconds_machine": f"{os.cpu_count()} CPU threads, torch {torch.__version__}",
        "check": {"input": "learn.gradnet_train.check_input()", "output_sum": np.round(y.sum(axis=(0, 1)), 4).tolist(),
                  "output_row": np.round(y[10, :8], 6).tolist()},
    }
    os.makedirs(out, exist_ok=True)
    state = {k: v for k, v in st["best_state"].items()}
    _save(state, os.path.join(out, name + ".pt"))
    _write_json(manifest, os.path.join(out, name + ".json"))
    print(f"exported {run} -> {out}: {manifest['parameters']} parameters, validation {st['best']:.4f}, "
          f"{manifest['seconds_256']} s at 256x256, {manifest['seconds_1280x720']} s at 1280x720")
    return manifest
