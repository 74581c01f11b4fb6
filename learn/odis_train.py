"""Training and export of the ODIS network (tracer.guiding.odis.net).

Loss (`loss`): `l1`, section 4.2 without the GAN term: the L1 distance between the network's output
and the reference map, both range-compressed (odis_net.target: the reference over its mean on the
valid bins, mu-law), averaged over the valid bins. `kl` (the default, chosen by the validation
figure below, docs/odis.md): the KL divergence from the first bounce's integrand to the sampling
mixture the guide uses (kl_loss). Augmentation: a rotation of the world about the map's
pole by a multiple of 90 degrees (the columns rolled by a quarter, the normals' x, y rotated).

Validation holds out whole scenes (the last `val_scenes` share of the seeds) and decides early
stopping by the training loss on them. It also reports what the maps are for, the first bounce's variance: on each
validation map, with the reference radiance L and the cosine of the bin centre to the centre's
normal, the second moment sum_b (L_b cos_b)^2 / p_b of the one-sample estimate under the 50/50
mixture of the predicted map and cosine (BSDF) sampling, over the same under cosine sampling
alone; the mean of these ratios over the maps with light (`second_moment_ratio`), beside the same
for the raw sparse input as the map and for the reference itself (the ceiling).

A run folder keeps `checkpoint.pt` (model, optimiser, epoch, history, best weights; written
through a temporary file each epoch) and `history.json`; training resumes from it.
"""
import math
import os
import time

import numpy as np
import torch

from tracer.guiding.odis import net as odis_net
from tracer.guiding.odis.features import bin_points
from tracer.guiding.odis.net import OdisUNet, features, target

from .odis_data import DEFAULTS as DATA_DEFAULTS
from .odis_data import load_shards
from .shards import changed_options, shard_config
from .photon_train import (_save, _write_json, best_model, end_epoch, epochs_left, open_run, optimiser_step,
                           start_training)


def prepare(data):
    """(x (m, 10, H, W) float32, y (m, H, W) compressed target, valid (m, H, W) float32)."""
    x = features(data["feats"].astype(np.float32), data["sampled"], data["valid"])
    return x, target(data["gt"], data["valid"]), data["valid"].astype(np.float32)


def rotate(x, y, v, k):
    """The world turned by k quarter turns about the pole: columns rolled by k n_phi / 4, the normal
    channels' (x, y) rotated by k x 90 degrees (torch tensors, in place of copies)."""
    if k % 4 == 0:
        return x, y, v
    s = k * x.shape[-1] // 4
    x, y, v = torch.roll(x, s, -1), torch.roll(y, s, -1), torch.roll(v, s, -1)
    x = x.clone()
    for cx, cy in ((2, 3), (6, 7)):
        a, b = x[:, cx].clone(), x[:, cy].clone()
        for _ in range(k % 4):
            a, b = -b, a
        x[:, cx], x[:, cy] = a, b
    return x, y, v


def rotate_normals(n, k):
    """Normals (B, 3) turned by k quarter turns about z, as `rotate` turns the maps."""
    a, b = n[:, 0].clone(), n[:, 1].clone()
    for _ in range(k % 4):
        a, b = -b, a
    return torch.stack([a, b, n[:, 2]], 1)


def predict(model, x, v, device, batch=512):
    out = []
    model.eval()
    with torch.inference_mode():
        for i in range(0, x.shape[0], batch):
            out.append(model(torch.from_numpy(x[i:i + batch]).to(device), torch.from_numpy(v[i:i + batch]).to(device)).cpu())
    model.train()
    return torch.cat(out).numpy() if out else np.zeros((0,) + x.shape[2:], np.float32)


_CENTRES = None


def kl_loss(out, gt, normal, mix=0.5):
    """The KL loss: minus the f-weighted mean log density of the first bounce's sampling mixture,
    mix x cosine + (1 - mix) x the predicted map (normalised), per bin, with f = L cos the reference
    radiance times the cosine to the centre's normal (the integrand of a diffuse surface's first
    bounce); maps without light are left out. out (B, H, W) the network's output, gt (B, H, W)
    reference radiance, normal (B, 3)."""
    global _CENTRES
    if _CENTRES is None:
        _CENTRES = torch.from_numpy(bin_points()[:, 4].astype(np.float32))
    cos = (normal @ _CENTRES.T.to(normal.device)).clamp(min=0.0)  # (B, K)
    f = gt.reshape(gt.shape[0], -1) * cos
    tot = f.sum(1)
    lit = tot > 0
    if not bool(lit.any()):
        return out.sum() * 0.0
    m = odis_net.expand(out).reshape(out.shape[0], -1) * (cos > 0)
    q = m / m.sum(1, keepdim=True).clamp(min=1e-12)
    pc = cos / cos.sum(1, keepdim=True).clamp(min=1e-12)
    p = mix * pc + (1.0 - mix) * q
    w = f[lit] / tot[lit, None]
    return -(w * torch.log(p[lit].clamp(min=1e-12))).sum(1).mean()


def l1(pred, y, v):
    """Per map, the mean |pred - y| over the valid bins."""
    return (np.abs(pred - y) * v).sum(axis=(1, 2)) / np.maximum(v.sum(axis=(1, 2)), 1.0)


def second_moment_ratio(maps, gt, normal, mix=0.5):
    """Per map with light, the second moment of the first bounce's one-sample estimate (integrand
    L cos, one direction per bin centre) under mix x cosine + (1 - mix) x the normalised map, over
    the same under cosine sampling alone (see the module docstring). maps, gt (m, H, W)."""
    pts = bin_points()[:, 4]  # bin centres (K, 3)
    cos = np.maximum(normal @ pts.T, 0.0)  # (m, K)
    f = gt.reshape(gt.shape[0], -1).astype(np.float64) * cos
    p_bsdf = cos / np.maximum(cos.sum(axis=1, keepdims=True), 1e-30)
    q = np.maximum(maps.reshape(maps.shape[0], -1).astype(np.float64), 0.0) * (cos > 0)
    tot = q.sum(axis=1, keepdims=True)
    q = np.where(tot > 0, q / np.where(tot > 0, tot, 1.0), p_bsdf)
    p = mix * p_bsdf + (1.0 - mix) * q
    lit = f.sum(axis=1) > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        m_mix = np.where(f > 0, f * f / p, 0.0).sum(axis=1)
        m_bsdf = np.where(f > 0, f * f / p_bsdf, 0.0).sum(axis=1)
    return m_mix[lit] / m_bsdf[lit]


def evaluate(model, va, device):
    """{val_l1, second_moment_ratio (network, raw input, reference)} on the validation data."""
    x, y, v = va["x"], va["y"], va["v"]
    pred = predict(model, x, v, device)
    out = {"val_l1": float(l1(pred, y, v).mean())}
    with torch.inference_mode():
        out["val_kl"] = float(kl_loss(torch.from_numpy(pred), torch.from_numpy(va["gt"]),
                                      torch.from_numpy(va["normal"].astype(np.float32))))
    nrm = va["normal"]
    out["second_moment_ratio"] = float(second_moment_ratio(odis_net.expand(pred), va["gt"], nrm).mean())
    raw = va["feats"][:, 0].astype(np.float32) * (va["sampled"] > 0)
    out["second_moment_ratio_input"] = float(second_moment_ratio(raw, va["gt"], nrm).mean())
    out["second_moment_ratio_reference"] = float(second_moment_ratio(va["gt"], va["gt"], nrm).mean())
    return out


def train(a):
    """Train (or resume) the run in a.run; a resumed run keeps its scene split and settings (a
    differing one is an error), and each epoch's shuffle and rotations are seeded by (seed, epoch)."""
    fixed = ("width", "batch", "lr", "seed", "loss")
    device, ck, ck_path, cfg, tr_paths, va_paths = open_run(a, fixed, "python -m learn.odis data", {"loss": "l1"})
    tr = load_shards(tr_paths)
    tx, ty, tv = prepare(tr)
    tg, tn = tr["gt"].astype(np.float32), tr["normal"].astype(np.float32)
    va = load_shards(va_paths) if va_paths else None
    if va is not None:
        va["x"], va["y"], va["v"] = prepare(va)
    n = tx.shape[0]
    if n < a.batch:
        raise SystemExit(f"{a.data}: {n} training maps, fewer than one batch of {a.batch}")
    print(f"train: {n} maps from {len(tr_paths)} scenes; validation: "
          f"{0 if va is None else va['x'].shape[0]} maps from {len(va_paths)} scenes; device {device}", flush=True)
    torch.manual_seed(a.seed)
    model = OdisUNet(a.width).to(device)
    opt, state = start_training(a, ck, ck_path, model, a.loss)
    for _ in epochs_left(a, state):
        t0 = time.perf_counter()
        rng = np.random.default_rng([a.seed, state["epoch"]])
        order = rng.permutation(n)
        losses = []
        for i in range(0, n - a.batch + 1, a.batch):
            idx = order[i:i + a.batch]
            turn = int(rng.integers(4))
            x, y, v = rotate(torch.from_numpy(tx[idx]), torch.from_numpy(ty[idx]), torch.from_numpy(tv[idx]), turn)
            x, y, v = x.to(device), y.to(device), v.to(device)
            out = model(x, v)
            if a.loss == "l1":
                loss = ((out - y).abs() * v).sum() / v.sum().clamp(min=1.0)
            else:
                g = torch.roll(torch.from_numpy(tg[idx]), turn * tg.shape[-1] // 4, -1).to(device)
                loss = kl_loss(out, g, rotate_normals(torch.from_numpy(tn[idx]), turn).to(device))
            if optimiser_step(a, opt, loss, state, losses):
                break
        ev = evaluate(model, va, device) if va is not None else {"val_l1": float(np.mean(losses)),
                                                                  "val_kl": float(np.mean(losses))}
        val = ev["val_" + a.loss]
        state["epoch"] += 1
        rec = dict(ev, epoch=state["epoch"], train_loss=float(np.mean(losses)), seconds=time.perf_counter() - t0)
        end_epoch(a, state, model, opt, cfg, ck_path, rec, val, "best_val", best_eval=ev)
        print(f"epoch {state['epoch']}: train {rec['train_loss']:.4f}  validation {a.loss} {val:.4f}  second moment "
              f"{ev.get('second_moment_ratio', math.nan):.3f} (input {ev.get('second_moment_ratio_input', math.nan):.3f}, "
              f"reference {ev.get('second_moment_ratio_reference', math.nan):.3f})  ({rec['seconds']:.0f} s)", flush=True)
    return state


def check_input(n=3, seed=0):
    """A fixed input (sparse random samples) whose outputs the manifest stores: (x, valid)."""
    rng = np.random.default_rng(seed)
    feats = rng.gamma(0.5, 1.0, (n, 9, 32, 32)).astype(np.float32)
    sampled = (rng.random((n, 32, 32)) < 0.3).astype(np.uint8)
    valid = np.zeros((n, 32, 32), np.uint8)
    valid[:, 16:] = 1
    return features(feats, sampled, valid), valid.astype(np.float32)


def inference_ms_per_1000(model, n=1024):
    x, v = check_input(n)
    odis_net.radiance_maps(model, x[:64], v[:64])
    t0 = time.perf_counter()
    odis_net.radiance_maps(model, x, v)
    return 1000.0 * (time.perf_counter() - t0) / n * 1000.0


DATA_FLAGS = {"width": "--size", "centres": "--centres", "per_bin": "--per-bin", "initial_depth": "--initial-depth"}


def export(run, out=None, name=None):
    """The run's best weights into tracer/weights/<name>.pt (default odis) with the manifest
    <name>.json."""
    out = out or odis_net.WEIGHTS_DIR
    model, st, cfg = best_model(run, lambda c: OdisUNet(c["width"]))
    names = cfg["train_scenes"] + cfg["val_scenes_files"]
    seeds = sorted(int(f[6:11]) for f in names)
    x, v = check_input()
    y = odis_net.radiance_maps(model, x, v)
    data_cfg = shard_config(os.path.join(cfg["data"], names[0]), DATA_DEFAULTS)
    manifest = {
        "name": odis_net.NAME, "model": {"width": cfg["width"]}, "map": [32, 32],
        "data": {"command": (f"python -m learn.odis data --seeds {seeds[0]}:{seeds[-1] + 1}" + changed_options(data_cfg, DATA_DEFAULTS, DATA_FLAGS)
                            + (f" --out {cfg['data']}" if os.path.normpath(cfg["data"]) != os.path.join("learn", "data", "odis") else "")),
                 "config": data_cfg, "train_scenes": len(cfg["train_scenes"]),
                 "validation_scenes": cfg["val_scenes_files"], "seed": cfg["seed"]},
        "train": {"command": cfg.get("command") or "python -m learn.odis train", "epochs": st["epoch"],
                  "best_epoch": st.get("best_epoch"), "batch": cfg["batch"], "lr": cfg["lr"]},
        "loss": cfg.get("loss", "l1"),
        "validation": st.get("best_eval"),
        "parameters": odis_net.parameter_count(model),
        "flops_per_map": odis_net.flops_per_map(model),
        "ms_per_1000_maps": round(inference_ms_per_1000(model), 1),
        "ms_per_1000_maps_machine": f"{os.cpu_count()} CPU threads, torch {torch.__version__}",
        "check": {"input": "learn.odis_train.check_input()", "output_sum": np.round(y.sum(axis=(1, 2)), 4).tolist(),
                  "output_row": np.round(y[:, 20, :8], 6).tolist()},
    }
    os.makedirs(out, exist_ok=True)
    name = name or odis_net.NAME
    manifest["name"] = name
    _save(st["best_state"], os.path.join(out, name + ".pt"))
    _write_json(manifest, os.path.join(out, name + ".json"))
    print(f"exported {run} -> {out}: {manifest['parameters']} parameters, validation {manifest['loss']} {st['best']:.4f}, "
          f"{manifest['ms_per_1000_maps']} ms per 1000 maps")
    return manifest
