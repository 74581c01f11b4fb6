"""Training data for GradNet: gradient-domain renders of procedural scenes, as patches.

For scene `seed` (learn.scenes, any material): one `--integrator gpt` render (hybrid shift, no
reconstruction) at an spp drawn from the config's `spp` (default SPP; `data --spp`), whose buffers
give, per pixel:

    indirect     the base image less its direct light (what the gradients describe: tracer's
                 gpt reconstructs the indirect light and adds the direct buffer back)
    dx, dy       forward-difference gradients of the indirect light (tracer.gradient.poisson)
    direct       the direct light, added back after the reconstruction
    albedo, normal (as (N + 1) / 2), depth (over the image's largest)   the 7 feature channels
    base_variance, dx_variance, dy_variance   the variance of each pixel's mean (of the base image,
                 whose noise is the indirect light's plus the direct light's, and of the gradients)

`patches` random square patches of `patch` pixels are cut from it (RGB kept; training takes one
colour channel per example). A patch with a non-finite value anywhere, or a negative value in
indirect or direct, is dropped and counted (`dropped`). No reference is used for training;
`reference_spp` > 0 also stores a path-traced reference of the same view (validation shards, for
reporting only).

The scene is learn.scenes' own pick for the seed, or with probability `box` (drawn from the seed)
its Cornell-like `box` kind.

A shard holds x (m, 28, P, P) float32: indirect (3), dx (3), dy (3), direct (3), features (7),
the variances base, dx, dy (3 each), where (m, 2) each patch's top-left pixel (y, x), spp, dropped, seed, config, and with a
reference, ref (m, 3, P, P).
"""
import json
import tempfile

import numpy as np

SPP = (16, 32, 64, 128, 256)
DEFAULTS = {"width": 128, "height": 128, "patch": 64, "patches": 8, "reference_spp": 0, "spp": list(SPP), "box": 0.0}
CHANNELS = ("indirect", "dx", "dy", "direct")
VARIANCES = ("base_variance", "dx_variance", "dy_variance")
N_CHANNELS = 28


def patch_stack(buffers):
    """(28, H, W) float32: the CHANNELS (3 each), the features (albedo, (normal + 1) / 2,
    depth) and the VARIANCES (3 each) of a gpt render's buffers."""
    parts = [buffers[c] for c in CHANNELS]
    parts += [buffers["albedo"], (buffers["normal"] + 1.0) * 0.5, buffers["depth"]]
    parts += [buffers[c] for c in VARIANCES]
    return np.concatenate([np.asarray(p, np.float32) for p in parts], axis=2).transpose(2, 0, 1).copy()


def legal(x):
    """Whether a (28, P, P) patch is usable: finite everywhere, indirect and direct not negative."""
    return bool(np.isfinite(x).all() and (x[0:3] >= 0).all() and (x[9:12] >= 0).all())


def shard_arrays(scene, seed, c):
    """The arrays of one shard (module docstring) for a loaded scene at its film size."""
    import tracer

    rng = np.random.default_rng([int(seed), 0x6D4E])
    spp = int(rng.choice(c.get("spp", SPP)))
    r = tracer.render(scene, spp=spp, seed=int(seed), integrator="gpt", recon="none")
    full = patch_stack(r.buffers)
    ref = None
    if c["reference_spp"] > 0:
        ref = tracer.render(scene, spp=int(c["reference_spp"]), seed=int(seed) + 7919).image.transpose(2, 0, 1)
    p = int(c["patch"])
    h, w = full.shape[1:]
    if p > h or p > w:
        raise ValueError(f"patch {p} larger than the film {w}x{h}")
    xs, refs, where, dropped = [], [], [], 0
    for _ in range(int(c["patches"])):
        y0, x0 = int(rng.integers(0, h - p + 1)), int(rng.integers(0, w - p + 1))
        x = full[:, y0:y0 + p, x0:x0 + p]
        if not legal(x):
            dropped += 1
            continue
        xs.append(x)
        where.append((y0, x0))
        if ref is not None:
            refs.append(ref[:, y0:y0 + p, x0:x0 + p])
    out = dict(x=np.array(xs, np.float32).reshape(-1, N_CHANNELS, p, p), where=np.array(where, np.int32).reshape(-1, 2),
               spp=np.int32(spp), dropped=np.int32(dropped),
               seed=np.int64(seed), config=json.dumps(c))
    if ref is not None:
        out["ref"] = np.array(refs, np.float32).reshape(-1, 3, p, p)
    return out


def make_shard(seed, path, **cfg):
    """Write the shard of scene `seed` to `path` (through a temporary file)."""
    import tracer

    from .scenes import make_scene
    from .shards import save_npz

    c = dict(DEFAULTS, **cfg)
    box = np.random.default_rng([int(seed), 0xB0C5]).random() < float(c.get("box", 0.0))
    with tempfile.TemporaryDirectory() as d:
        scene = tracer.load_scene(make_scene(seed, d, c["width"], c["height"], kind="box" if box else None))
    save_npz(path, **shard_arrays(scene, seed, c))
