"""What each setting of the registered guides and integrators means, one line each: what
`--list-guides` and `--list-integrators` print beside the defaults. Every registered setting has
a line here (tests/test_cli.py checks it); the method notes in docs/ say why each default."""

# Algorithm 1's schedule (guiding.grid.schedule): grid, photon, ppg
_ALGORITHM1 = {
    "iterations": "training iterations after the pilot pass",
    "spp_init": "N_c: training iteration t renders 2^t x this spp",
    "train_budget": "with --time: the share of the budget within which the pilot and training end",
    "roulette": "Russian roulette: path (before the sampled ray), late (after it, once its emission is "
                "counted), reference (late, survival 0.1-0.99 before the maps, 0.99 after: PPG's reference), "
                "auto (reference with NEE off, else path)",
    "records": "a camera record past the roulette: survivors (X, 0 when killed: learns q L_i) or unbiased (X / q)",
}

# the BSDF/guide mixing learned per voxel or leaf (guiding.mixing): grid, photon, ppg
_MIXING = {
    "alpha_min": "least probability of BSDF sampling a learned mixing gives",
    "alpha_max": "greatest probability of BSDF sampling a learned mixing gives",
    "mis_min_samples": "samples a voxel needs before its mixing weight is learned (Q_thr of eq. 14)",
    "switch_off": "final passes sample the BSDF alone where the guide predicts more than this x BSDF "
                  "sampling's second moment (0: never)",
    "direct": "1: the maps learn the direct light too; 0: only what next-event estimation does not sample",
}

# the histogram guides on a hierarchical grid (guiding.grid.guides): grid, photon
_WINDOW = {  # the splitting and weight-window settings of every guide that plays them (tracer.splitting)
    "split": "final passes split paths whose throughput exceeds this (0: off)",
    "window": "weight window: final passes split paths expected to bring more than this x their pixel "
              "(0: off; auto: 3 without NEE, off with)",
    "window_low": "weight window: roulette paths expected to bring less than this x their pixel "
                  "(auto: 0.2 without NEE, 0.05 with)",
    "window_spp": "weight window: final passes play it once the training passes hold this many samples a "
                  "pixel (0: always)",
}

_HISTOGRAM = {
    **_ALGORITHM1,
    **_MIXING,
    "resolution": "grid cells along the diagonal of the pilot's bounds",
    "split_c": "a voxel splits once it holds more than c sqrt(2^t) samples in iteration t",
    "max_levels": "new grid levels per iteration, at most",
    "map_width": "directional bins in phi",
    "map_height": "directional bins in cos(theta)",
    "normal_classes": "6: a voxel keeps one map per side of its surfaces; 1: one map per voxel",
    "reconstruct": "map filter: gaussian, pullpush, none (photon also cnn: the shipped network)",
    "sigma": "width of the Gaussian filter in bins",
    "cnn_max_photons": "reconstruct=cnn: maps of at least this many photons take the Gaussian instead",
    "mixing": "how the mixing weight is learned per voxel: variance (least second moment) or eq14",
    **_WINDOW,
}

GUIDES = {
    "bsdf": {},
    "grid": _HISTOGRAM,
    "photon": {
        **_HISTOGRAM,
        "photons_per_pixel": "photons of iteration t: 2^t x spp_init x this x pixels",
        "light_guiding": "probability that a photon samples its voxel's importance map (0: emitted freely)",
        "aim_env": "1: environment photons start only where camera paths escaped; 0: from the whole disk",
        "reference_photons": "diagnostic: after training, maps replaced by histograms of this x pixels "
                             "fresh photons (0: off)",
        "reference_sigma": "diagnostic: the Gaussian filter's width in bins for those maps (0: none)",
    },
    "pss": {
        "condition": "pixel: warp the directions given the pixel; image: the pixel position too",
        "target": "what the flow learns: relative (contribution / its pixel's mean) or luminance",
        "m": "bounces whose directions are warped (auto: chosen by validation NLL)",
        "layers": "coupling layers of the flow (auto: by validation NLL)",
        "width": "hidden width of the coupling networks (auto: by validation NLL)",
        "blocks": "residual blocks per coupling network",
        "defensive": "share of samples drawn from the uniform density",
        "candidates": "spp of the candidate pass the flow learns from",
        "alpha": "candidates per training example",
        "share": "with --time: the share of the budget for the candidates and learning",
        "train_seconds": "with --spp: seconds of learning",
        "epochs": "> 0: epochs per model instead of a time limit",
        "batch": "training batch size",
        "lr": "Adam's learning rate",
        "max_examples": "training examples at most (a uniform subset of the candidates)",
    },
    "odis": {
        "initial": "spp of the initial pass the maps are made from",
        "reuse": "1: the initial pass is the image's first spp at the render's depth; 0: the paper's "
                 "depth-3 pass, discarded",
        "k": "gather window in pixels, odd (auto: 21 below 8 initial spp, else 11)",
        "stride": "network inference at every stride-th pixel in x and y, bilinear in between",
        "alpha": "probability of BSDF sampling at the first bounce (auto: 0.5 to max depth 3, else 0.7)",
        "weights": "shipped weights (auto: odis to max depth 3, else odis_full; odis_w8: wider)",
        "maps": "network, or reference: probe-traced maps (a slow diagnostic)",
        "reference_per_bin": "maps=reference: probes per directional bin",
        "batch": "maps per torch call",
    },
    "auto": {
        "candidates": "the samplers tried, names joined by + (from bsdf, grid, photon, ppg); the render goes on "
                      "with the one whose trial predicts the least relMSE x seconds",
        "trial_iterations": "training iterations of Algorithm 1 each guide runs before the choice (bsdf: 2^this spp)",
        "trials_in_image": "1: the other candidates' trial films count in the image too (weighted by inverse variance)",
    },
    "ppg": {
        **_ALGORITHM1,
        **_MIXING,
        "split_c": "a spatial leaf splits once its records of an iteration of n spp exceed c sqrt(n / split_spp)",
        "split_spp": "2: the reference's threshold c sqrt(2^(k+1)) after iteration k of 4 x 2^k spp; 4: c sqrt(n / 4)",
        "image": "all: the image weighs every training iteration and the final passes by inverse variance; "
                 "final: the final passes alone (the reference keeps its last iteration)",
        "empty": "a spatial leaf whose tree has no energy samples: bsdf (alone), or uniform (mixed, the reference's)",
        **_WINDOW,
        "rho": "a directional quadrant splits when it holds more than this share of its tree's energy",
        "max_depth": "directional quadtree levels, at most (20 at most)",
        "alpha": "learn_alpha=0: the probability of BSDF sampling everywhere",
        "learn_alpha": "1: the probability of BSDF sampling learned per spatial leaf; 0: alpha",
        "spatial_filter": "nearest, or stochastic: each record jittered within its leaf's box",
        "directional_filter": "nearest, or box: a record's energy shared over the quadtree leaves a "
                              "square of its leaf's size overlaps",
    },
}

INTEGRATORS = {
    "path": {"nee": "1: next-event estimation with MIS; 0: none (emission found by a path counts in full)"},
    "gpt": {
        "nee": "1: next-event estimation with MIS; 0: none (goes with shift=replay)",
        "shift": "how offset paths are made: hybrid (reconnect rough vertices) or replay (the same random numbers)",
        "roughness": "hybrid: vertices rougher than this (GGX alpha) reconnect",
        "direct_roughness": "hybrid: the light a first vertex smoother than this (GGX alpha) reflects joins the "
                            "direct buffer, added after the solve and left out of the gradients (0: off)",
        "recon": "the image from base and gradients: l2 (keeps the mean), l1, gradnet, or none (the base)",
        "recon_alpha": "l1, l2: the weight of the base image in the screened Poisson solve",
        "weights": "gradnet: the shipped weights (gradnet, gradnet_v2)",
        "correction": "gradnet: 1 applies eq. 13's energy correction, 0 not",
    },
}


def meaning(table, method, setting):
    """The line for `setting` of `method` in GUIDES or INTEGRATORS (`table`), or "" if none."""
    return table.get(method, {}).get(setting, "")
