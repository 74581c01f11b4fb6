"""Command line: `python -m tracer SCENE [options]` (also installed as `tracer`).

Writes OUT.exr (linear), OUT.png (sRGB preview) and OUT.json (statistics). User errors
print one line `tracer: ...` and exit with code 2.
"""
import argparse
import logging
import os
import sys

from .errors import TracerError


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise TracerError(f"{message} (see --help)")


def _parser():
    from .bvh import ACCELS
    from .guiding import guide_names

    p = _Parser(prog="tracer", description="Render an OBJ scene with a Numba + Embree path tracer.")
    p.add_argument("scene", help="scene.obj (with optional scene.json beside it) or a JSON scene file")
    p.add_argument("--guide", default="bsdf", help=f"bounce sampler: {', '.join(guide_names())} (default bsdf)")
    p.add_argument("--guide-opt", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting of the guide, repeatable (e.g. --guide-opt iterations=6); "
                        "an unknown key is an error that lists the valid ones")
    budget = p.add_mutually_exclusive_group()
    budget.add_argument("--spp", type=int, help="samples per pixel (default: the scene's render.spp)")
    budget.add_argument("--time", type=float, help="wall-clock budget in seconds instead of --spp")
    p.add_argument("--max-depth", type=int, help="-1 unlimited, 1 emitters only, 2 direct light, ...")
    p.add_argument("--rr-depth", type=int, help="Russian roulette from this depth on (default 5)")
    p.add_argument("--seed", type=int, help="random seed (default: the scene's, else 0)")
    p.add_argument("--width", type=int, help="image width (default: the scene's)")
    p.add_argument("--height", type=int, help="image height (default: the scene's)")
    p.add_argument("--accel", default="embree", help=f"ray queries: {' or '.join(ACCELS)} (default embree)")
    p.add_argument("--filter", default="box", help="pixel filter: box (default) or point (pixel centres)")
    p.add_argument("--crop", help="render only the window x0,y0,w,h of the image")
    p.add_argument("--threads", type=int, help="worker threads (default: all cores)")
    p.add_argument("--wave-size", type=int, default=None, help="paths per wave (memory vs overhead)")
    p.add_argument("-o", "--output", help="output EXR (default: <scene name>.exr in the current folder)")
    p.add_argument("--reference", help="reference EXR: print relMSE, MSE and 1-SSIM against it")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar, no summary")
    return p


def _crop(text):
    if text is None:
        return None
    try:
        return tuple(int(v) for v in text.split(","))
    except ValueError:
        raise TracerError(f"--crop takes x0,y0,w,h (four integers), got {text!r}") from None


def _run(argv):
    from . import metrics
    from .imageio import read_image
    from .render import DEFAULT_WAVE, render, write_outputs
    from .scene import load_scene

    args = _parser().parse_args(argv)
    overrides = {k: getattr(args, k) for k in ("width", "height") if getattr(args, k) is not None}
    for k in ("width", "height"):
        if k in overrides and overrides[k] < 1:
            raise TracerError(f"--{k} must be >= 1, got {overrides[k]}")
    out = args.output or os.path.splitext(os.path.basename(args.scene))[0] + ".exr"
    if not out.lower().endswith(".exr"):
        raise TracerError(f"{out}: output must be an .exr file (a PNG and a JSON are written beside it)")
    out_dir = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(out_dir) or not os.access(out_dir, os.W_OK):
        raise TracerError(f"{out}: cannot write output, folder {out_dir} is missing or not writable")
    ref = read_image(args.reference, what="reference image") if args.reference else None

    from .bvh import ACCELS
    from .errors import unknown_name
    from .guiding import make_guide

    if args.accel not in ACCELS:
        raise unknown_name("accel", args.accel, ACCELS)
    guide_settings = _guide_opts(args.guide_opt)
    make_guide(args.guide, **guide_settings)  # unknown names and settings fail here, before the scene loads
    scene = load_scene(args.scene, **overrides)
    if ref is not None and ref.shape[:2] != (scene.height, scene.width):
        raise TracerError(
            f"{args.reference}: reference is {ref.shape[1]}x{ref.shape[0]}, the render {scene.width}x{scene.height}"
        )
    if ref is not None and args.crop:
        x0, y0, w, h = _crop(args.crop)
        ref = ref[y0:y0 + h, x0:x0 + w]
    result = render(scene, spp=args.spp, time=args.time, guide=args.guide, guide_settings=guide_settings,
                    max_depth=args.max_depth,
                    rr_depth=args.rr_depth, seed=args.seed, accel=args.accel, threads=args.threads,
                    pixel_filter=args.filter, crop=_crop(args.crop),
                    wave_size=args.wave_size or DEFAULT_WAVE, progress=not args.quiet)
    if ref is not None:
        result.stats["metrics"] = metrics.all_metrics(result.image, ref[:, :, :3])
    exr, png, js = write_outputs(result, out)
    if not args.quiet:
        s = result.stats
        note = " (interrupted)" if s["interrupted"] else ""
        print(f"{exr}: {s['width']}x{s['height']}, {s['spp']} spp in {s['time_total']:.2f} s{note}, "
              f"{s['msamples_per_s']:.2f} Msamples/s, {s['mrays_per_s']:.2f} Mrays/s; preview {png}, stats {js}")
        if ref is not None:
            print("  ".join(f"{k} {v:.6g}" for k, v in s["metrics"].items()))
    return 0


def _guide_opts(items):
    """--guide-opt KEY=VALUE items as a dict; values parsed as int, float or left as text."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise TracerError(f"--guide-opt {item!r}: expected KEY=VALUE")
        for conv in (int, float):
            try:
                out[key] = conv(value)
                break
            except ValueError:
                continue
        else:
            out[key] = value
    return out


def main(argv=None):
    logging.basicConfig(format="tracer: warning: %(message)s", level=logging.WARNING, stream=sys.stderr)
    try:
        return _run(sys.argv[1:] if argv is None else argv)
    except TracerError as e:
        print(f"tracer: {e}", file=sys.stderr)
        return 2
