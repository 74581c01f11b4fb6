"""Training, export and evaluation of the photon map network (tracer.guiding.grid.photon_cnn).

Loss (section 6.1): the asymmetric L1 of equation 13, |S_d - S~| (1 + (lambda - 1) H), H = 1
where the output and the input S_t lie on different sides of the ground truth, on every decoder
level (deep supervision; the ground truth and the input average-pooled to the level), the levels
weighted equally. Maps are compared normalised to mean 1, so the mean absolute difference
is the L1 distance between the two sampling densities (twice their total variation).

Validation holds out whole scenes (the last `val_scenes` share of the seeds), reports the L1
of the finest map, and decides early stopping. A run folder keeps `checkpoint.pt` (model,
optimiser, epoch, history, best weights; written through a temporary file each epoch) and
`history.json`; training resumes from it.
"""
import json
import math
import os
import time

import numpy as np
import torch
import torch.nn.functional as F

from tracer.guiding.grid import photon_cnn
from tracer.guiding.grid.photon_cnn import PhotonUNet, features
from tracer.guiding.grid.reconstruct import make_reconstructor
from tracer.imageio import replace_atomically

from .photon_data import DEFAULTS as DATA_DEFAULTS
from .photon_data import load_shards, shard_config
from .shards import list_shards

RANGES = ((0, 100), (100, 500), (500, math.inf))  # photons in the input map (the paper's experts)


def split_scenes(paths, val_share):
    """(train paths, validation paths): the last val_share of the shards (by seed) validate."""
    n_val = max(1, int(round(val_share * len(paths)))) if len(paths) > 1 else 0
    return paths[: len(paths) - n_val], paths[len(paths) - n_val:]


def batch_features(data, idx):
    raw = data["inputs"][idx].astype(np.float32)
    k = raw.shape[2] * raw.shape[3]
    x = features(raw[:, 0] / k, raw[:, 2], raw[:, 1] / k, raw[:, 3])
    return torch.from_numpy(x), torch.from_numpy(data["target"][idx].astype(np.float32)), \
        torch.from_numpy(raw[:, 0])


def loss_fn(outs, target, s_in, lam):
    total = 0.0
    for o in outs:
        f = target.shape[-1] // o.shape[-1]
        g = F.avg_pool2d(target[:, None], f)[:, 0] if f > 1 else target
        s = F.avg_pool2d(s_in[:, None], f)[:, 0] if f > 1 else s_in
        h = ((o - g) * (s - g) < 0).to(o.dtype)
        total = total + ((o - g).abs() * (1.0 + (lam - 1.0) * h)).mean()
    return total / len(outs)


def validate(model, data, device, batch=256):
    """Mean L1 of the finest map to the ground truth (mean-1 maps) per sample."""
    model.eval()
    out = []
    with torch.inference_mode():
        for i in range(0, data["target"].shape[0], batch):
            x, y, _ = batch_features(data, np.arange(i, min(i + batch, data["target"].shape[0])))
            out.append((model(x.to(device)).cpu() - y).abs().mean(dim=(1, 2)).numpy())
    model.train()
    return np.concatenate(out) if out else np.zeros(0)


def open_run(a, fixed, data_command, defaults=None):
    """Start or resume the run in a.run: (device, checkpoint or None, its path, config, training
    shard paths, validation shard paths). A resumed run keeps its scene split; a setting in
    `fixed` that differs from the checkpoint's is an error (a key it lacks reads as defaults[key])."""
    device = a.device or ("cuda" if torch.cuda.is_available() else "cpu")
    os.makedirs(a.run, exist_ok=True)
    ck_path = os.path.join(a.run, "checkpoint.pt")
    ck = torch.load(ck_path, map_location=device, weights_only=False) if os.path.exists(ck_path) else None
    defaults = defaults or {}
    if ck is not None:
        cfg = ck["config"]
        changed = [k for k in fixed if cfg.get(k, defaults.get(k)) != getattr(a, k)]
        if changed:
            raise SystemExit(f"{ck_path}: trained with " + ", ".join(f"{k}={cfg.get(k, defaults.get(k))}" for k in changed)
                             + "; resume with the same settings or use another --run")
        tr_paths = [os.path.join(a.data, f) for f in cfg["train_scenes"]]
        va_paths = [os.path.join(a.data, f) for f in cfg["val_scenes_files"]]
        missing = [p for p in tr_paths + va_paths if not os.path.exists(p)]
        if missing:
            raise SystemExit(f"{ck_path}: its shards are gone from {a.data} ({os.path.basename(missing[0])}, ...)")
    else:
        paths = list_shards(a.data)
        if not paths:
            raise SystemExit(f"{a.data}: no shards ({data_command} --out {a.data})")
        tr_paths, va_paths = split_scenes(paths, a.val_scenes)
        cfg = {k: getattr(a, k) for k in fixed + ("val_scenes", "data")}
        cfg["command"] = getattr(a, "command", None)
        cfg["train_scenes"] = [os.path.basename(p) for p in tr_paths]
        cfg["val_scenes_files"] = [os.path.basename(p) for p in va_paths]
    return device, ck, ck_path, cfg, tr_paths, va_paths


def start_training(a, ck, ck_path, model, label):
    """(Adam over model at a.lr, the training state), both restored from the checkpoint ck (and the
    model's weights with them) when resuming."""
    opt = torch.optim.Adam(model.parameters(), lr=a.lr)
    state = {"epoch": 0, "history": [], "best": math.inf, "best_state": None, "bad": 0, "steps": 0}
    if ck is not None:
        model.load_state_dict(ck["model"])
        opt.load_state_dict(ck["opt"])
        state = ck["state"]
        print(f"resumed {ck_path} at epoch {state['epoch']} (best validation {label} {state['best']:.4f})")
    return opt, state


def epochs_left(a, state):
    """Yields once per epoch while the run has epochs (a.epochs), patience (a.patience) and, with
    a.minutes, time left (counted from the first call)."""
    t_start = time.perf_counter()
    while state["epoch"] < a.epochs and state["bad"] < a.patience:
        if getattr(a, "minutes", None) is not None and time.perf_counter() - t_start > 60.0 * a.minutes:
            print(f"stopped after {a.minutes} minutes; run again to resume")
            return
        yield state["epoch"]


def optimiser_step(a, opt, loss, state, losses):
    """One Adam step on `loss`, counted in state and losses; True when a.max_steps are done."""
    opt.zero_grad()
    loss.backward()
    opt.step()
    losses.append(loss.item())
    state["steps"] += 1
    return a.max_steps is not None and len(losses) >= a.max_steps


def end_epoch(a, state, model, opt, cfg, ck_path, rec, val, best_key, **best_extra):
    """After an epoch whose record is rec and validation figure val (lower is better): history,
    best weights (with best_extra in state when they improve) or one more bad epoch, the
    checkpoint and history.json (the best figure under best_key), both written atomically."""
    state["history"].append(rec)
    if val < state["best"]:
        state["best"], state["bad"] = val, 0
        state["best_state"] = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
        state["best_epoch"] = state["epoch"]
        state.update(best_extra)
    else:
        state["bad"] += 1
    _save({"model": model.state_dict(), "opt": opt.state_dict(), "state": state, "config": cfg}, ck_path)
    _write_json({"config": cfg, "history": state["history"], best_key: state["best"],
                 "best_epoch": state.get("best_epoch")}, os.path.join(a.run, "history.json"))


def _save(obj, path):
    replace_atomically(path, lambda tmp: torch.save(obj, tmp))


def _write_text(text, path):
    def write(tmp):
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
    replace_atomically(path, write)


def _write_json(obj, path):
    _write_text(json.dumps(obj, indent=1), path)


def train(a):
    """Train (or resume) the run in a.run. A resumed run keeps the scene split, width, batch, lr and
    loss of its checkpoint (a differing setting is an error); each epoch's shuffle is seeded by
    (seed, epoch), so a resumed run takes the same steps as one that never stopped."""
    fixed = ("width", "batch", "lr", "lam", "seed")
    device, ck, ck_path, cfg, tr_paths, va_paths = open_run(a, fixed, "python -m learn.photon data")
    tr, va = load_shards(tr_paths), load_shards(va_paths) if va_paths else None
    n = tr["target"].shape[0]
    if n < a.batch:
        raise SystemExit(f"{a.data}: {n} training maps, fewer than one batch of {a.batch}")
    print(f"train: {n} maps from {len(tr_paths)} scenes; validation: "
          f"{0 if va is None else va['target'].shape[0]} maps from {len(va_paths)} scenes; device {device}")
    torch.manual_seed(a.seed)
    model = PhotonUNet(a.width).to(device)
    opt, state = start_training(a, ck, ck_path, model, "L1")
    config = cfg
    while state["epoch"] < a.epochs and state["bad"] < a.patience:
        t0 = time.perf_counter()
        order = np.random.default_rng([a.seed, state["epoch"]]).permutation(n)
        losses = []
        for i in range(0, n - a.batch + 1, a.batch):
            x, y, s = batch_features(tr, order[i:i + a.batch])
            loss = loss_fn(model(x.to(device), heads=True), y.to(device), s.to(device), a.lam)
            if optimiser_step(a, opt, loss, state, losses):
                break
        val = float(validate(model, va, device).mean()) if va is not None else float(np.mean(losses))
        state["epoch"] += 1
        rec = {"epoch": state["epoch"], "train_loss": float(np.mean(losses)), "val_l1": val,
               "seconds": time.perf_counter() - t0}
        end_epoch(a, state, model, opt, config, ck_path, rec, val, "best_val_l1")
        print(f"epoch {state['epoch']}: train {rec['train_loss']:.4f}  validation L1 {val:.4f}  "
              f"({rec['seconds']:.0f} s)", flush=True)
    return state


def inference_ms_per_1000(model, n_theta, n_phi, n=2048):
    x = np.zeros((n, 5, n_theta, n_phi), np.float32)
    photon_cnn.infer(model, x[:64])
    t0 = time.perf_counter()
    photon_cnn.infer(model, x)
    return 1000.0 * (time.perf_counter() - t0) / n * 1000.0


def check_input(n_theta, n_phi, n=3, seed=0):
    """A fixed input (sparse random photons) whose outputs the manifest stores."""
    rng = np.random.default_rng(seed)
    counts = rng.poisson(rng.gamma(0.3, 1.0, (n, n_theta, n_phi))).astype(np.float32)
    power = counts * rng.uniform(0.5, 1.5, counts.shape).astype(np.float32)
    maps = power / np.maximum(power.sum(axis=(1, 2), keepdims=True), 1e-30)
    return features(maps, counts, maps, np.floor(counts / 2))


def best_model(run, build):
    """(model with the run's best weights, in eval mode; the training state; the run's config) from
    run/checkpoint.pt, the model made by build(config); torch on every core, for the export's timings."""
    ck = torch.load(os.path.join(run, "checkpoint.pt"), map_location="cpu", weights_only=False)
    st, cfg = ck["state"], ck["config"]
    model = build(cfg)
    model.load_state_dict(st["best_state"])
    model.eval()
    torch.set_num_threads(os.cpu_count() or 1)
    return model, st, cfg


def export(run, out=None):
    """The run's best weights into tracer/weights/photon_cnn.pt with the manifest photon_cnn.json."""
    out = out or photon_cnn.WEIGHTS_DIR
    model, st, cfg = best_model(run, lambda c: PhotonUNet(c["width"]))
    shards = [os.path.join(cfg["data"], f) for f in cfg["train_scenes"] + cfg["val_scenes_files"]]
    data_cfg = shard_config(shards[0]) if os.path.exists(shards[0]) else dict(DATA_DEFAULTS)
    seeds = sorted(int(os.path.basename(f)[6:11]) for f in shards)
    h, w = 32, 64
    x = check_input(h, w)
    y = photon_cnn.infer(model, x)
    manifest = {
        "name": photon_cnn.NAME, "model": {"width": cfg["width"]}, "map": [h, w],
        "data": {"command": f"python -m learn.photon data --seeds {seeds[0]}:{seeds[-1] + 1}", "config": data_cfg,
                 "train_scenes": cfg["train_scenes"], "validation_scenes": cfg["val_scenes_files"],
                 "seed": cfg["seed"]},
        "train": {"command": cfg.get("command") or "python -m learn.photon train", "epochs": st["epoch"],
                  "best_epoch": st.get("best_epoch"), "batch": cfg["batch"], "lr": cfg["lr"], "lambda": cfg["lam"]},
        "validation_l1": st["best"],
        "parameters": photon_cnn.parameter_count(model),
        "flops_per_map": photon_cnn.flops_per_map(model, h, w),
        "ms_per_1000_maps": round(inference_ms_per_1000(model, h, w), 1),
        "ms_per_1000_maps_machine": f"{os.cpu_count()} CPU threads, torch {torch.__version__}",
        "check": {"input": "learn.photon_train.check_input(32, 64)", "output": np.round(y, 6).tolist()},
    }
    os.makedirs(out, exist_ok=True)
    _save(st["best_state"], os.path.join(out, photon_cnn.NAME + ".pt"))
    _write_json(manifest, os.path.join(out, photon_cnn.NAME + ".json"))
    print(f"exported {run} -> {out}: {manifest['parameters']} parameters, validation L1 {st['best']:.4f}, "
          f"{manifest['ms_per_1000_maps']} ms per 1000 maps")
    return manifest


def validation_paths(data_dir, run=None):
    """The validation shards of a run (its checkpoint), or of the shipped weights (their manifest)."""
    if run:
        names = torch.load(os.path.join(run, "checkpoint.pt"), map_location="cpu",
                           weights_only=False)["config"]["val_scenes_files"]
    else:
        names = photon_cnn.load()[1]["data"]["validation_scenes"]
    return [os.path.join(data_dir, f) for f in names]


def write_testset(data_dir, run, path, n=96, seed=0):
    """A small stored set of the run's validation maps (scenes it never trained on; they chose its
    epoch) for the tests: n samples, a third from each photon-count range."""
    from .shards import save_npz

    d = load_shards(validation_paths(data_dir, run))
    rng = np.random.default_rng(seed)
    pick = []
    for lo, hi in RANGES:
        idx = np.flatnonzero((d["n_in"] >= lo) & (d["n_in"] < hi))
        pick.append(rng.choice(idx, min(n // len(RANGES), idx.size), replace=False))
    idx = np.sort(np.concatenate(pick))
    save_npz(path, inputs=d["inputs"][idx], target=d["target"][idx], n_in=d["n_in"][idx], scene=d["scene"][idx])
    print(f"{path}: {idx.size} validation maps from scenes {sorted(set(d['scene'][idx].tolist()))}")


def reconstruct_l1(name, data, model=None, **settings):
    """Per sample, the L1 distance of the method's reconstruction of S_t to the ground truth."""
    raw = data["inputs"].astype(np.float32)
    k = raw.shape[2] * raw.shape[3]
    maps, counts = raw[:, 0] / k, raw[:, 2]
    if name == "cnn":
        rec = photon_cnn.infer(model, features(maps, counts, raw[:, 1] / k, raw[:, 3]))
    else:
        rec = make_reconstructor(name, **settings).reconstruct(maps, counts, counts > 0)
    rec = rec.astype(np.float64)
    tot = rec.sum(axis=(1, 2), keepdims=True)
    rec = np.where(tot > 0, rec / np.where(tot > 0, tot, 1.0), 1.0 / k)
    return np.abs(rec - data["target"].astype(np.float64) / k).sum(axis=(1, 2))


def evaluate(a):
    va_paths = validation_paths(a.data, a.run)
    data = load_shards(va_paths)
    if a.run:
        ck = torch.load(os.path.join(a.run, "checkpoint.pt"), map_location="cpu", weights_only=False)
        model = PhotonUNet(ck["config"]["width"])
        model.load_state_dict(ck["state"]["best_state"])
        model.eval()
    else:
        model, _ = photon_cnn.load()
    methods = {"cnn": ("cnn", {}), "gaussian(sigma=1)": ("gaussian", {"sigma": 1.0}),
               "gaussian(sigma=2)": ("gaussian", {"sigma": 2.0}), "gaussian(sigma=3)": ("gaussian", {"sigma": 3.0}),
               "pullpush": ("pullpush", {}), "none": ("none", {})}
    err = {m: reconstruct_l1(name, data, model, **s) for m, (name, s) in methods.items()}
    n_in = data["n_in"]
    rows = []
    for lo, hi in RANGES + ((0, math.inf),):
        sel = (n_in >= lo) & (n_in < hi)
        rows.append({"range": f"[{lo}, {hi})" if hi < math.inf else (f"[{lo}, inf)" if lo else "all"),
                     "maps": int(sel.sum()), **{m: float(e[sel].mean()) if sel.any() else None for m, e in err.items()}})
    lines = ["| photons in S_t | maps | " + " | ".join(methods) + " |", "|---" * (len(methods) + 2) + "|"]
    for r in rows:
        lines.append(f"| {r['range']} | {r['maps']} | " + " | ".join(
            "-" if r[m] is None else f"{r[m]:.3f}" for m in methods) + " |")
    table = "\n".join(lines)
    print(table)
    if a.out:
        os.makedirs(a.out, exist_ok=True)
        _write_json({"validation_scenes": [os.path.basename(p) for p in va_paths], "rows": rows},
                    os.path.join(a.out, "map_quality.json"))
        _write_text(table + "\n", os.path.join(a.out, "map_quality.md"))
    return rows
