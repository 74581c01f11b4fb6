"""Mitsuba 3 (`pip install mitsuba==3.9.1`, optional) on the benchmark scenes of bench.scenes:
the same triangles (one OBJ per material), reflectances, light, camera and film, integrator
`path` with the same max_depth and rr_depth, box filter, independent sampler, variant
`llvm_ad_rgb` (Dr.Jit's LLVM backend on every core)."""
import time

import numpy as np

VARIANT = "llvm_ad_rgb"


def available():
    """The reason Mitsuba cannot run, or None."""
    try:
        import mitsuba as mi

        mi.set_variant(VARIANT)
    except Exception as e:  # ImportError, or a variant its build lacks (no LLVM)
        return f"{type(e).__name__}: {e}"
    return None


def load(spec, spp, max_depth, rr_depth, width=None, height=None, variant=VARIANT):
    """A mitsuba Scene for a bench.scenes dict, in `variant`."""
    import mitsuba as mi

    mi.set_variant(variant)
    cam = spec["camera"]
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": int(max_depth), "rr_depth": int(rr_depth)},
        "sensor": {
            "type": "perspective", "fov": float(cam["fov"]), "fov_axis": cam["fov_axis"],
            "to_world": mi.ScalarTransform4f().look_at(origin=cam["origin"], target=cam["target"], up=cam["up"]),
            "sampler": {"type": "independent", "sample_count": int(spp)},
            "film": {"type": "hdrfilm", "width": int(width or spec["width"]), "height": int(height or spec["height"]),
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        },
    }
    for i, (path, kd, ke) in enumerate(spec["parts"]):
        shape = {"type": "obj", "filename": path, "face_normals": True,
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(kd)}}}
        if ke is not None:
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": list(ke)}}
        d[f"shape{i}"] = shape
    return mi.load_dict(d)


def render_seconds(scene, spp, seed=0):
    """Wall time of one `mi.render` at `spp`, the image evaluated (copied to numpy)."""
    import mitsuba as mi

    t0 = time.perf_counter()
    img = mi.render(scene, spp=int(spp), seed=int(seed))
    np.asarray(img)
    return time.perf_counter() - t0


def mean_image(scene, spp, seed=0):
    """The rendered image as a numpy array (for a sanity check of the two renderers' means)."""
    import mitsuba as mi

    return np.asarray(mi.render(scene, spp=int(spp), seed=int(seed)), dtype=np.float64)
