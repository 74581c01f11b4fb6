"""Training data for the ODIS network: one shard per procedural scene (learn.scenes, diffuse only).

For scene `seed`:
1. An initial pass of n0 spp (drawn from INITIAL_SPP) of camera paths with max_depth
   `initial_depth` (3, as the guide renders it; 0: no limit), the first hits' directions, what
   came back (with depth 3: direct plus one-bounce light), both hits' depth and normal
   (tracer.guiding.odis.features.initial_samples).
2. `centres` film pixels drawn among those whose own first hits all lie on one plane (normals
   within 1e-3), each gathered into its 32 x 32 map with the guide's window for n0 (odis_input.gather).
3. Ground truth at each centre, at the first hit of one of its own initial samples: `per_bin`
   probe rays in every bin above the surface, stratified inside the bin, each a path of
   max_depth initial_depth - 1 from that point (with 2: its first hit's emission plus the light
   it receives directly, i.e. direct plus one-bounce light seen from the centre), through
   tracer.guiding.odis.guide.reference_maps; the bin's value is the mean luminance. Bins below the
   surface are 0.

A shard holds feats (m, 9, 32, 32) float16, sampled and valid (m, 32, 32) uint8, gt (m, 32, 32)
float32, normal (m, 3) the centre's mean normal, n0 (the initial spp), k and the config.
"""
import json
import tempfile

import numpy as np

DEFAULTS = {"width": 128, "height": 128, "centres": 64, "per_bin": 64, "initial_depth": 3}
INITIAL_SPP = (1, 2, 4, 8)


def make_shard(seed, path, **cfg):
    """Write the shard of scene `seed` to `path` (through a temporary file)."""
    import tracer

    from .scenes import make_scene
    from .shards import save_npz

    c = dict(DEFAULTS, **cfg)
    with tempfile.TemporaryDirectory() as d:
        scene = tracer.load_scene(make_scene(seed, d, c["width"], c["height"], diffuse_only=True))
    save_npz(path, **shard_arrays(scene, seed, c))


def shard_arrays(scene, seed, c):
    """The arrays of one shard (module docstring) for a loaded scene rendered at its film size;
    c: the config (DEFAULTS' keys)."""
    import numba

    from tracer.film import Film
    from tracer.guiding.odis.guide import LARGE_K, SMALL_K, pixel_normals, reference_maps
    from tracer.guiding.odis.features import first_sample, gather, initial_samples
    from tracer.render import make_context
    from tracer.session import trace_source
    from tracer.sources import CameraSource
    from tracer.wave import WaveBuffers

    rng = np.random.default_rng([int(seed), 0x0D15])
    threads = numba.get_num_threads()
    w, h = scene.width, scene.height
    n0 = int(rng.choice(INITIAL_SPP))
    k = LARGE_K if n0 < 8 else SMALL_K
    depth = int(c["initial_depth"])
    ctx = make_context(scene, seed=int(seed), max_depth=depth if depth > 0 else -1, threads=threads)
    origin = scene.camera.origin
    parts, sizes = [], []
    trace_source(ctx, CameraSource(), Film(w, h), spp=n0, buf=WaveBuffers(1 << 15),
                 observe=lambda rec: parts.append(initial_samples(rec, sizes[-1], origin)), before_wave=sizes.append)
    empty = dict(feats=np.zeros((0, 9, 32, 32), np.float16), sampled=np.zeros((0, 32, 32), np.uint8),
                 valid=np.zeros((0, 32, 32), np.uint8), gt=np.zeros((0, 32, 32), np.float32),
                 normal=np.zeros((0, 3)), n0=np.int32(n0), k=np.int32(k), config=json.dumps(c), seed=np.int64(seed))
    if not parts:
        return empty
    s = {f: np.concatenate([p[f] for p in parts]) for f in parts[0]}
    normal, has = pixel_normals(s["pix"], s["normal1"], w * h)
    # pixels whose own first hits all lie on one plane
    agree = np.ones(w * h, bool)
    np.logical_and.at(agree, s["pix"], np.einsum("ij,ij->i", s["normal1"], normal[s["pix"]]) > 0.999)
    cand = np.flatnonzero(has & agree)
    if cand.size == 0 or not np.any(s["radiance"] > 0):
        return empty
    centres = np.sort(rng.choice(cand, min(c["centres"], cand.size), replace=False))
    feats, sampled, valid = gather(s["pix"], s["dirs"], s["radiance"], s["depth1"], s["normal1"], s["depth2"],
                                   s["normal2"], w, h, centres, k=k)
    # ground truth at one of each centre's own first hits
    j = first_sample(s["pix"], w * h)[centres]
    pctx = make_context(scene, seed=int(seed) + 1, max_depth=max(depth - 1, -1) if depth > 0 else -1,
                        threads=threads)
    gt = reference_maps(pctx, s["x"][j], s["normal1"][j], c["per_bin"], rng, int(seed))
    return dict(feats=feats.astype(np.float16), sampled=sampled, valid=valid, gt=gt,
                normal=normal[centres], n0=np.int32(n0), k=np.int32(k), config=json.dumps(c), seed=np.int64(seed))


def load_shards(paths):
    """The shards concatenated: {feats float32, sampled, valid, gt, normal, n0 per map, scene per map}."""
    out = {f: [] for f in ("feats", "sampled", "valid", "gt", "normal", "n0", "scene")}
    for p in paths:
        with np.load(p) as z:
            m = z["gt"].shape[0]
            for f in ("feats", "sampled", "valid", "gt", "normal"):
                out[f].append(z[f])
            out["n0"].append(np.full(m, int(z["n0"])))
            out["scene"].append(np.full(m, int(z["seed"])))
    return {f: np.concatenate(v) if v else np.zeros(0) for f, v in out.items()}
