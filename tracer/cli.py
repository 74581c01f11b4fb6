"""Command line: `python -m tracer SCENE [options]` (also installed as `tracer`).

Writes OUT.exr (linear), OUT.png (tonemapped sRGB preview) and OUT.json (statistics). User
errors print one line `tracer: ...` and exit with code 2; Ctrl-C writes what was rendered and
exits with 130. Warnings found while the input is checked (a scene's unsupported features) are
held back until it has passed, so that they come after the compile notice; a run that then fails
prints them before its error line, which is the last line on stderr.
"""
import argparse
import logging
import os
import re
import sys
import tempfile

from .errors import TracerError

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, what shells report for a process stopped by Ctrl-C


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise TracerError(f"{message} (see --help)")


def _parser():
    from .bvh import ACCELS
    from .guiding import guide_names

    p = _Parser(prog="tracer", description="Render an OBJ or Mitsuba XML scene with a Numba + Embree path tracer.")
    p.add_argument("scene", nargs="?", help="scene.obj (with optional scene.json beside it), a JSON scene file, or a "
                                            "Mitsuba scene .xml (0.6 or 3)")
    p.add_argument("--guide", default="bsdf", help=f"bounce sampler: {', '.join(guide_names())} (default bsdf), "
                                                  "with settings as NAME:KEY=VALUE,... (e.g. photon:iterations=6)")
    p.add_argument("--guide-opt", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting of the guide, repeatable (e.g. --guide-opt iterations=6); "
                        "an unknown key is an error that lists the valid ones")
    p.add_argument("--integrator", default="path",
                   help="path (default) or gpt (gradient-domain path tracing, reconstructed by --recon), with "
                        "settings as NAME:KEY=VALUE,... (e.g. path:nee=0, gpt:shift=replay,recon=l1; "
                        "--list-integrators shows them)")
    p.add_argument("--shift", default=None,
                   help="gpt: the shift mapping of offset paths: hybrid (default: reconnection between rough "
                        "vertices, half-vector copy elsewhere) or replay (the same random numbers; works with guides)")
    p.add_argument("--shift-roughness", type=float, default=None, metavar="R",
                   help="gpt, hybrid shift: vertices rougher than R (GGX alpha) are reconnected (default 0.001)")
    p.add_argument("--recon", default=None, help="gpt: screened Poisson reconstruction l2 (default: keeps the "
                                                 "image mean), l1 (robust to outliers, darker at low spp), gradnet "
                                                 "(learned), or none (the base image)")
    p.add_argument("--recon-opt", action="append", default=[], metavar="KEY=VALUE",
                   help="gpt: a setting of the reconstruction, repeatable (gradnet: weights=NAME, correction=0|1)")
    p.add_argument("--recon-alpha", type=float, default=None, metavar="A",
                   help="gpt: weight of the base image in the reconstruction (default 0.2)")
    budget = p.add_mutually_exclusive_group()
    budget.add_argument("--spp", type=int, help="samples per pixel (default: the scene's render.spp)")
    budget.add_argument("--time", type=float, help="wall-clock budget in seconds instead of --spp")
    p.add_argument("--max-depth", type=int, help="-1 unlimited, 1 emitters only, 2 direct light, ...")
    p.add_argument("--rr-depth", type=int, help="Russian roulette from this depth on (default 5)")
    p.add_argument("--seed", type=int, help="random seed (default: the scene's, else 0)")
    p.add_argument("--width", type=int, help="image width (default: the scene's; alone, the height keeps the "
                                             "scene's aspect ratio)")
    p.add_argument("--height", type=int, help="image height (default: the scene's; alone, the width keeps the "
                                              "scene's aspect ratio)")
    p.add_argument("-D", "--define", action="append", default=[], metavar="NAME=VALUE",
                   help="set a Mitsuba scene XML's <default> NAME (as mitsuba -D); repeatable")
    p.add_argument("--allow-missing", action="store_true",
                   help="render a Mitsuba scene XML whose meshes or textures are partly absent (warnings)")
    p.add_argument("--accel", default="embree", help=f"ray queries: {' or '.join(ACCELS)} (default embree)")
    p.add_argument("--path-loop", metavar="LOOP",
                   help="lanes (default: float32 lanes, tracer.engine, for every pass, a guide's training and "
                        "final passes included), thread (each thread's packets of paths to their end; a guide's "
                        "training on the wavefront) or wave (one kernel per stage)")
    p.add_argument("--filter", default="box", help="pixel filter: box (default) or point (pixel centres)")
    p.add_argument("--crop", help="render only the window x0,y0,w,h of the image")
    p.add_argument("--threads", type=int, help="worker threads (default: all cores)")
    p.add_argument("--wave-size", type=int, default=None, help="paths per wave (memory vs overhead)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="split the render over N Dask worker processes on this machine (seeds seed..seed+N-1, "
                        "merged); needs the dask extra")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="split the render over the workers of this Dask scheduler (one segment each)")
    p.add_argument("--segments-dir", default=None, metavar="DIR",
                   help="with --workers or --scheduler: keep finished segments here, so that a run started again "
                        "renders only the missing ones (default: <output>.segments)")
    p.add_argument("-o", "--output", help="output EXR (default: <scene name>.exr in the current folder, a "
                                          "scene.xml taking its folder's name; a missing folder is created)")
    p.add_argument("--reference", help="reference EXR: print relMSE, MSE and 1-SSIM against it")
    p.add_argument("--exposure", type=float, default=0.0, metavar="EV",
                   help="stops added to the PNG preview's automatic exposure (default 0); the EXR is not changed")
    p.add_argument("--variance", action="store_true",
                   help="also write <name>.variance.exr, the variance of each pixel's mean")
    p.add_argument("--denoise", nargs="?", const="high", default=None, metavar="QUALITY",
                   help="also write <name>.denoised.exr and its PNG: Intel Open Image Denoise with the albedo "
                        "and normal buffers (quality high, the default, balanced or fast, as --denoise fast or "
                        "--denoise=fast; needs pip install -e \".[denoise]\")")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar and no compile notice (the summary line is still printed)")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="also show notes that change no pixel (e.g. zero-area triangles skipped)")
    p.add_argument("--list-guides", action="store_true", help="print the guides, their settings and defaults")
    p.add_argument("--list-integrators", action="store_true",
                   help="print the integrators, their settings and defaults")
    p.add_argument("--version", action="store_true", help="print the version and exit")
    return p


def _denoise_quality(argv):
    """argv with a bare `--denoise` (not followed by high, balanced or fast) written `--denoise=high`,
    so that the optional quality never takes the scene (`--denoise scene.xml`)."""
    from .denoise import QUALITIES

    argv = list(argv)
    end = argv.index("--") if "--" in argv else len(argv)
    for i in range(end):
        if argv[i] == "--denoise" and (i + 1 >= end or argv[i + 1] not in QUALITIES):
            argv[i] = "--denoise=high"
    return argv


def default_output(scene):
    """The EXR a render of `scene` writes without -o: <name>.exr in the current folder, where
    name is the scene file's, or its folder's when the file is called `scene` (every Bitterli
    scene is <name>/scene.xml)."""
    path = os.path.abspath(scene)
    name = os.path.splitext(os.path.basename(path))[0]
    if name == "scene":
        name = os.path.basename(os.path.dirname(path)) or name
    return name + ".exr"


def _crop(text):
    if text is None:
        return None
    try:
        crop = tuple(int(v) for v in text.split(","))
    except ValueError:
        crop = ()
    if len(crop) != 4:
        raise TracerError(f"--crop takes x0,y0,w,h (four integers), got {text!r}")
    return crop


def _check_numbers(args):
    """Options that are numbers out of range fail here, before anything is read or rendered."""
    import math

    checks = [("spp", 1), ("width", 1), ("height", 1), ("rr_depth", 1), ("seed", 0), ("threads", 1),
              ("wave_size", 1)]
    for name, lo in checks:
        v = getattr(args, name)
        if v is not None and v < lo:
            raise TracerError(f"--{name.replace('_', '-')} must be >= {lo}, got {v}")
    if args.max_depth is not None and args.max_depth < 1 and args.max_depth != -1:
        raise TracerError(f"--max-depth must be -1 (unlimited) or >= 1, got {args.max_depth}")
    if args.time is not None and not (math.isfinite(args.time) and args.time > 0):
        raise TracerError(f"--time must be a positive number of seconds, got {args.time}")
    if not math.isfinite(args.exposure):
        raise TracerError(f"--exposure must be a finite number of stops, got {args.exposure}")


def _output_paths(out, variance, extra=()):
    base = os.path.splitext(out)[0]
    return [out, base + ".png", base + ".aovs.exr", base + ".json"] + ([base + ".variance.exr"] if variance else []) + \
        [f"{base}.{name}.exr" for name in extra]


def _check_output(out, variance, extra=()):
    """Fail now, not after the render, if the outputs cannot be written: probe the folder (or,
    if it does not exist yet, the nearest folder above it, where it will be created) by creating
    and removing a file there; os.access says yes to root even where creating a file fails."""
    if not out.lower().endswith(".exr"):
        raise TracerError(f"{out}: output must be an .exr file (a PNG and a JSON are written beside it)")
    for path in _output_paths(out, variance, extra):
        if os.path.isdir(path):
            raise TracerError(f"{path}: cannot write output, a folder of that name exists")
    folder = os.path.dirname(os.path.abspath(out))
    probe = folder
    while not os.path.exists(probe):
        probe = os.path.dirname(probe)
    if not os.path.isdir(probe):
        raise TracerError(f"{out}: cannot write output, {probe} is not a folder")
    try:
        fd, tmp = tempfile.mkstemp(prefix=".tracer-probe-", dir=probe)
        os.close(fd)
        os.remove(tmp)
    except OSError as e:
        raise TracerError(f"{out}: cannot write output in {probe} ({e.strerror or e})") from None
    return folder


def _make_folder(folder, out):
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as e:
        raise TracerError(f"{out}: cannot create the folder {folder} ({e.strerror or e})") from None


def _read_reference(path):
    import numpy as np

    from .imageio import read_image

    ref = read_image(path, what="reference image")
    if ref.shape[2] < 3:
        raise TracerError(f"{path}: reference has {ref.shape[2]} channel(s), RGB needed")
    ref = ref[:, :, :3]
    if not np.isfinite(ref).all():
        raise TracerError(f"{path}: reference has non-finite pixels")
    return ref


def _list_methods(entries, flag, meanings):
    """Print each (name, class or None, doc if None, {setting: default}): the first paragraph of its
    docstring, and its settings with their defaults and what they mean (tracer.setting_meanings)."""
    from .setting_meanings import meaning

    for name, factory, doc, settings in entries:
        if factory is not None:
            doc = " ".join(line.strip() for line in re.split(r"\n\s*\n", (factory.__doc__ or "").strip())[0].splitlines())
        doc = re.sub(rf"^`--{flag} \w+`:\s*", "", doc)
        print(f"{name}: {doc}")
        if not settings:
            print("  (no settings)")
        rows = [(f"{key} = {value}", meaning(meanings, name, key)) for key, value in sorted(settings.items())]
        width = max((len(r[0]) for r in rows), default=0)
        for setting, text in rows:
            print(f"  {setting:<{width}}  {text}".rstrip())


def _list_guides():
    from .guiding import REGISTRY, guide_settings
    from .setting_meanings import GUIDES

    _list_methods([(name, factory, "BSDF importance sampling only (no guide).", guide_settings(name))
                   for name, (factory, _) in REGISTRY.items()], "guide", GUIDES)


def _list_integrators():
    from .integrators import REGISTRY, integrator_settings
    from .setting_meanings import INTEGRATORS

    _list_methods([(name, cls, "", integrator_settings(name)) for name, cls in REGISTRY.items()], "integrator",
                  INTEGRATORS)


def _compile_notice(guide, integ, accel, path_loop):
    """One line before a render whose kernels are not in Numba's cache yet (a guess; see
    _jit.kernels_cached and render.compile_plan), so that minutes of silence do not look like a
    hang. (render() logs the same line for a library user; the CLI drops that record.)"""
    from . import _jit
    from .guiding import REGISTRY
    from .render import COMPILE_NOTE, compile_plan

    cls = REGISTRY[guide][0] if guide in REGISTRY else None
    if not _jit.kernels_cached(*compile_plan(cls is not None, integ, accel, path_loop,
                                             wave_records=cls is not None and cls.records_loop == "wave")):
        _note(COMPILE_NOTE)


def _note(text):
    from tqdm import tqdm

    tqdm.write(f"tracer: {text}", file=sys.stderr)


class _Warnings(logging.Handler):
    """The tracer's warnings as `tracer: warning: ...` lines on stderr (with -v, its notes as
    `tracer: note: ...` too), held back while `hold` (until the input has been checked), and
    shown before the error line if the run then fails on bad input (what the scene lacked is often
    why it failed: an unsupported `point` emitter, then "the scene has no light")."""

    def __init__(self):
        super().__init__(logging.INFO)
        self.hold, self.held = True, []
        self.verbose = False

    def emit(self, record):
        if getattr(record, "compile_notice", False):  # render()'s, for a library user: said already
            return
        if self.hold:
            self.held.append(record)
        elif record.levelno >= logging.WARNING:
            _note(f"warning: {record.getMessage()}")
        elif self.verbose:
            _note(f"note: {record.getMessage()}")

    def show_held(self):  # (not `release`: logging.Handler's lock method)
        self.hold = False
        for record in self.held:
            self.emit(record)
        self.held = []


def _run(argv, warnings):
    from . import metrics
    from .render import DEFAULT_WAVE, PATH_LOOPS, _check_crop, check_memory, render, write_outputs
    from .scene import load_scene

    args = _parser().parse_args(_denoise_quality(argv))
    warnings.verbose = args.verbose
    if args.version:
        from . import __version__

        print(f"tracer {__version__}")
        return 0
    if args.list_guides:
        _list_guides()
        return 0
    if args.list_integrators:
        _list_integrators()
        return 0
    if args.scene is None:
        raise TracerError("the following arguments are required: scene (see --help)")
    _check_numbers(args)
    crop = _crop(args.crop)
    overrides = {k: getattr(args, k) for k in ("width", "height") if getattr(args, k) is not None}
    define = {}
    for d in args.define:
        name, eq, value = d.partition("=")
        if not eq or not name.strip():
            raise TracerError(f"--define {d!r}: expected NAME=VALUE")
        define[name.strip()] = value
    out = args.output or default_output(args.scene)
    from .bvh import ACCELS
    from .errors import unknown_name
    from .guiding import make_guide
    from .integrators import make_integrator
    from .methods import parse_settings, parse_spec

    if args.accel not in ACCELS:
        raise unknown_name("accel", args.accel, ACCELS)
    if args.path_loop is not None and args.path_loop not in PATH_LOOPS:
        raise unknown_name("path loop", args.path_loop, PATH_LOOPS)
    # unknown names and settings fail here, before the scene loads
    guide_name, guide_settings = parse_spec(args.guide)
    guide_settings.update(parse_settings(args.guide_opt, "--guide-opt"))
    guide = make_guide(guide_name, **guide_settings)
    flags = {k: v for k, v in (("shift", args.shift), ("roughness", args.shift_roughness), ("recon", args.recon),
                               ("recon_alpha", args.recon_alpha)) if v is not None}
    integ = make_integrator(args.integrator, **flags, **parse_settings(args.recon_opt, "--recon-opt"))
    integ.check_guide(guide, guide_name)
    if args.denoise is not None:
        from .denoise import require

        require(args.denoise)
    dask = args.workers is not None or args.scheduler is not None
    if dask:
        from .distributed import check_ready

        check_ready(args.workers)
        if integ.name != "path":
            raise TracerError(f"--integrator {integ.name} is not split over Dask workers (its reconstruction needs "
                              f"every sample in one place): render it without --workers or --scheduler")
    elif args.segments_dir is not None:
        raise TracerError("--segments-dir goes with --workers or --scheduler")
    out_dir = _check_output(out, args.variance, integ.outputs + (("denoised",) if args.denoise else ()))
    ref = _read_reference(args.reference) if args.reference else None
    notice = [not args.quiet]  # once: before framing a scene without a camera, or before the render

    def compile_notice():
        if notice[0]:
            _compile_notice(guide_name, integ, args.accel, args.path_loop)
            notice[0] = False

    scene = load_scene(args.scene, before_framing=compile_notice, define=define or None,
                       allow_missing=args.allow_missing, **overrides)
    crop = _check_crop(crop, scene.width, scene.height) if crop is not None else None
    if ref is not None:
        if ref.shape[:2] != (scene.height, scene.width):
            raise TracerError(
                f"{args.reference}: reference is {ref.shape[1]}x{ref.shape[0]}, the render {scene.width}x{scene.height}"
            )
        if crop is not None:
            x0, y0, w, h = crop
            ref = ref[y0:y0 + h, x0:x0 + w]
        if min(ref.shape[:2]) < 3:
            raise TracerError(f"{args.reference}: the {ref.shape[1]}x{ref.shape[0]} window is too small for "
                              "1-SSIM (at least 3x3)")
    check_memory(scene, _check_crop(crop, scene.width, scene.height), args.wave_size or DEFAULT_WAVE,
                 None if args.time is not None else (args.spp or scene.render.spp), guide, integ)
    _make_folder(out_dir, out)
    warnings.show_held()  # the input is good: show what loading it found
    compile_notice()
    result = render(scene, spp=args.spp, time=args.time, guide=guide_name, guide_settings=guide_settings,
                    max_depth=args.max_depth,
                    rr_depth=args.rr_depth, seed=args.seed, accel=args.accel, threads=args.threads,
                    pixel_filter=args.filter, crop=crop, path_loop=args.path_loop,
                    wave_size=args.wave_size or DEFAULT_WAVE, progress=not args.quiet, integrator=integ,
                    denoise=args.denoise or False, scheduler=args.scheduler, workers=args.workers,
                    segments_dir=(args.segments_dir or os.path.splitext(out)[0] + ".segments") if dask else None)
    if ref is not None:
        result.stats["metrics"] = metrics.all_metrics(result.image, ref)
    exr, png, js = write_outputs(result, out, exposure=args.exposure, variance=args.variance, reference=ref)
    s = result.stats
    print(f"{exr}: {s['width']}x{s['height']}, {_spp_text(s)} in {s['time_total']:.2f} s, "
          f"{s['msamples_per_s']:.2f} Msamples/s, {s['mrays_per_s']:.2f} Mrays/s; preview {png} "
          f"(exposure {s['preview_exposure']:+.2f} EV{', the reference' + chr(39) + 's' if ref is not None else ''}), stats {js}")
    training = s["guide_stats"].get("training") or {}
    if s["guide_stats"].get("choice"):  # --guide auto: which sampler it rendered with, and why
        guide_name = s["guide_stats"]["choice"]
        print(f"  auto chose {guide_name}: {s['guide_stats']['why']}")
    if training.get("stopped"):
        print(f"  {guide_name} trained {training['trained']} of {training['iterations']} iterations after its pilot: "
              f"{training['why']}")
    if s.get("segments"):
        seeds = [g["seed"] for g in s["segments"]]
        print(f"  {len(seeds)} segments (seeds {seeds[0]}..{seeds[-1]}) on {s['scheduler']}, merged in seed order")
        kept = os.path.splitext(out)[0] + ".segments" if args.segments_dir is None else args.segments_dir
        if s["interrupted"] and os.path.isdir(kept):
            print(f"  finished segments kept in {kept}: the same command renders only the others")
    if result.denoised is not None:
        base = os.path.splitext(exr)[0]
        print(f"  denoised (Open Image Denoise, {s['time_denoise']:.2f} s): {base}.denoised.exr, preview "
              f"{base}.denoised.png")
    if ref is not None:
        print("  ".join(f"{k} {v:.6g}" for k, v in s["metrics"].items()))
    return EXIT_INTERRUPTED if s["interrupted"] else 0


def _spp_text(s):
    """The summary's samples per pixel, as the stats JSON has them: spp_mean, and where a pass was
    cut (at the budget's end, or by Ctrl-C) the whole sweeps every pixel got (`spp`)."""
    parts = ["interrupted"] if s["interrupted"] else []
    if s["spp_mean"] != s["spp"]:
        parts.append(f"every pixel has at least {s['spp']}")
        text = f"{s['spp_mean']:.2f} spp"
    else:
        text = f"{s['spp']} spp"
    return text + (f" ({'; '.join(parts)})" if parts else "")


def main(argv=None):
    logging.basicConfig(format="tracer: warning: %(message)s", level=logging.WARNING, stream=sys.stderr)
    log = logging.getLogger("tracer")
    saved = log.propagate, log.level
    warnings = _Warnings()
    log.addHandler(warnings)
    log.propagate = False
    log.setLevel(logging.INFO)
    try:
        return _run(sys.argv[1:] if argv is None else argv, warnings)
    except TracerError as e:
        warnings.show_held()
        print(f"tracer: {e}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:  # stdout closed early (`tracer --list-guides | head`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except KeyboardInterrupt:  # before the passes began, or while writing (each file is whole or old)
        print("tracer: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    finally:
        log.removeHandler(warnings)
        log.propagate, log.level = saved
