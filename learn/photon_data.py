"""Training data for the photon map network: sparse photon histograms and their dense ground truth.

One shard per procedural scene (learn.scenes). For scene seed s:
1. The photon guide runs its pilot and two training iterations on the scene at a small image
   size, with `resolution` r_init drawn from 10..200 (the paper's section 8: cells of side
   diagonal / r_init); the voxels its camera paths made valid, with the tree splits it made, are the
   voxels of the shard (at most `max_voxels`, drawn at random).
2. An input photon stream traced as the guide's iterations would be: iteration i = 0..t_max
   traces n0 2^i photons, accumulated. Each voxel draws its iteration t in 1..t_max; its input is
   the accumulated histogram after iteration t (S_t, P_t) and after t - 1 (S_{t-1}, P_{t-1}).
3. The ground truth from an independent, dense stream of `n_gt` photons (others than the
   input's, so that its noise is not the input's), normalised.
Photons deposit from their second hit on, as the guide's default (`direct` 0) does, and in the
voxels' normal classes as the guide's do.

A sample is kept when its input holds a photon and its ground truth holds at least
max(gt_min, gt_ratio x the input's) photons; at most `keep` per shard. Stored: `inputs`
(N, 4, H, W) float32: S_t and S_{t-1} normalised to mean 1, P_t and P_{t-1} counts; `target`
(N, H, W) float16, normalised to mean 1; per sample `t`, `n_in` (photons in S_t), `n_gt`; `r_init`;
`config`, the settings as JSON. (The shipped network's shards kept `inputs` in float16.)

Known limits (docs/findings.md): with the defaults, iteration 12's input (3.3 M photons) is more
than a quarter of the ground truth's 12 M, so its samples survive only where the input fell
short; no sample has an empty history (t = 0), which the guide's first update and new voxels
present.
"""
import json
import tempfile

import numpy as np

DEFAULTS = dict(width=64, height=64, n0=400, t_max=12, n_gt=12_000_000, max_voxels=2500, keep=600, gt_min=2000,
                gt_ratio=4.0, r_min=10, r_max=200)


def _trace_into(ctx, gs, node_slot, n, key, power, count, node_count):
    from tracer.guiding.grid.photons import trace_photons
    from tracer.guiding.grid.spatial import accumulate

    def sink(node, b, v, x, nrm):  # node, b int64 and v float64 already (PhotonBuffers)
        accumulate(node, b, v, node_slot, power, count, node_count)

    trace_photons(ctx, gs, node_slot, n, key, sink, first_hit=False)


def _normalised(power, k):
    tot = power.sum(axis=1, keepdims=True)
    return np.where(tot > 0, power / np.where(tot > 0, tot, 1.0) * k, 0.0)


def make_shard(seed, path, **cfg):
    """Write the shard of scene `seed` to `path` (through a temporary file)."""
    import numba

    import tracer
    from tracer.guiding import make_guide
    from tracer.render import make_context

    from .scenes import make_scene
    from .shards import save_npz

    c = dict(DEFAULTS, **cfg)
    rng = np.random.default_rng([int(seed), 0xDA7A])
    with tempfile.TemporaryDirectory() as d:
        scene = tracer.load_scene(make_scene(seed, d, c["width"], c["height"]))
    r_init = int(rng.integers(c["r_min"], c["r_max"] + 1))
    threads = numba.get_num_threads()
    guide = make_guide("photon", resolution=r_init, iterations=2, split=0.0, window=0.0)
    tracer.render(scene, spp=1, guide=guide, seed=int(seed), threads=threads)
    g = guide.grid
    H, W = guide.map_height, guide.map_width
    K = H * W
    empty = dict(inputs=np.zeros((0, 4, H, W), np.float32), config=json.dumps(c), target=np.zeros((0, H, W), np.float16),
                 t=np.zeros(0, np.int16), n_in=np.zeros(0, np.float32), n_gt=np.zeros(0, np.float32),
                 r_init=np.int32(r_init), seed=np.int64(seed))
    if g is None:
        save_npz(path, **empty)
        return
    nodes = np.flatnonzero(g.data_slot[: g.n_nodes] >= 0)
    if nodes.size > c["max_voxels"]:
        nodes = np.sort(rng.choice(nodes, c["max_voxels"], replace=False))
    nv = nodes.size
    node_slot = np.full(g.n_nodes, -1, np.int32)
    node_slot[nodes] = np.arange(nv, dtype=np.int32)
    ctx = make_context(scene, seed=int(seed), threads=threads)
    gs = g.lookup_state()
    t = rng.integers(1, c["t_max"] + 1, nv)
    power = np.zeros((nv, K), np.float32)
    count = np.zeros((nv, K), np.float32)
    ncount = np.zeros(g.n_nodes)
    s_t, p_t, s_p, p_p = (np.zeros((nv, K), np.float32) for _ in range(4))
    for i in range(c["t_max"] + 1):
        _trace_into(ctx, gs, node_slot, int(c["n0"] * 2 ** i), 1000 + i, power, count, ncount)
        now, before = t == i, t - 1 == i
        s_t[now], p_t[now] = _normalised(power[now], K), count[now]
        s_p[before], p_p[before] = _normalised(power[before], K), count[before]
    gp = np.zeros((nv, K), np.float32)
    gc = np.zeros((nv, K), np.float32)
    chunk = 4_000_000
    for j, g0 in enumerate(range(0, c["n_gt"], chunk)):
        _trace_into(ctx, gs, node_slot, min(chunk, c["n_gt"] - g0), 5000 + j, gp, gc, ncount)
    n_in, n_gt = p_t.sum(axis=1), gc.sum(axis=1)
    ok = np.flatnonzero((n_in > 0) & (n_gt >= np.maximum(c["gt_min"], c["gt_ratio"] * n_in)))
    if ok.size > c["keep"]:
        ok = np.sort(rng.choice(ok, c["keep"], replace=False))
    inputs = np.stack([s_t[ok], s_p[ok], p_t[ok], p_p[ok]], axis=1).reshape(-1, 4, H, W)
    save_npz(path, inputs=inputs.astype(np.float32), config=json.dumps(c), target=_normalised(gp[ok], K).reshape(-1, H, W).astype(np.float16),
             t=t[ok].astype(np.int16), n_in=n_in[ok].astype(np.float32), n_gt=n_gt[ok].astype(np.float32),
             r_init=np.int32(r_init), seed=np.int64(seed))


def shard_config(path):
    """The settings a shard was made with (DEFAULTS for shards that predate the `config` entry)."""
    with np.load(path) as d:
        return json.loads(str(d["config"])) if "config" in d.files else dict(DEFAULTS)


def load_shards(paths):
    """Concatenate shards: dict of inputs, target, t, n_in, n_gt, `scene` (the seed per sample) and
    `config`. Shards made with different settings are an error."""
    parts = [dict(np.load(p)) for p in paths]
    configs = [shard_config(p) for p in paths]
    if any(c != configs[0] for c in configs):
        bad = next(p for p, c in zip(paths, configs) if c != configs[0])
        raise ValueError(f"{bad}: made with other settings than {paths[0]}")
    out = {k: np.concatenate([p[k] for p in parts]) for k in ("inputs", "target", "t", "n_in", "n_gt")}
    out["scene"] = np.concatenate([np.full(p["t"].shape[0], int(p["seed"])) for p in parts])
    out["config"] = configs[0] if configs else dict(DEFAULTS)
    return out
