"""What the benches share: scene names to paths, references, and method specs to render() arguments."""
import os
import shutil
import sys

from tracer.guiding import make_guide
from tracer.integrators import make_integrator
from tracer.methods import parse_spec

from .reference import ROOT, default_out, load


def scene_path(name, scene_dir=None):
    """Path of the scene file for a scene name (built-in first, then scene_dir/<name>/scene.obj or
    scene_dir/<name>/scene.xml, a Mitsuba scene)."""
    if name.endswith((".obj", ".json", ".xml")):
        return name
    own = os.path.join(ROOT, "scenes", name, f"{name}.obj")
    if os.path.isfile(own):
        return own
    if scene_dir:
        for file in ("scene.obj", "scene.xml"):
            ext = os.path.join(scene_dir, name, file)
            if os.path.isfile(ext):
                return ext
    raise SystemExit(f"bench.convergence: no scene {name!r} in scenes/"
                     + (f" or {scene_dir}" if scene_dir else " (external scenes need --scene-dir)"))


def scene_name(given):
    """A scene's name in records and charts: the name given, or a file's stem (its folder's name for
    the shared scenes' scene.obj and scene.xml)."""
    if not given.endswith((".obj", ".json", ".xml")):
        return given
    stem = os.path.splitext(os.path.basename(given))[0]
    return os.path.basename(os.path.dirname(os.path.abspath(given))) if stem == "scene" else stem


def reference_for(path):
    out = default_out(path)
    if not os.path.isfile(os.path.join(out, "reference.exr")):
        raise SystemExit(f"bench.convergence: no reference for {path}: run "
                         f"python -m bench.reference {os.path.relpath(path, ROOT)} --time SECONDS")
    return load(out)


# gradient-domain methods: render() arguments (the default shift is hybrid)
GRADIENT_METHODS = {
    "gpt-l1": {"integrator": "gpt:recon=l1"},
    "gpt-l2": {"integrator": "gpt:recon=l2"},
    "gpt-replay-l1": {"integrator": "gpt:shift=replay,recon=l1"},
    "gpt-gradnet": {"integrator": "gpt:recon=gradnet"},
    "gpt-gradnet-raw": {"integrator": "gpt:recon=gradnet,correction=0"},
}


def method_spec(method):
    """'photon' or 'photon:mixing=variance,sigma=2' -> (guide name, settings) (tracer.methods)."""
    return parse_spec(method)


DENOISED = "+oidn"  # a method with this suffix: its final image denoised (render(denoise=True))


def render_args(method):
    """render() keyword arguments of a bench method: a named gradient-domain one (GRADIENT_METHODS),
    or GUIDE[:KEY=VALUE,...][/INTEGRATOR[:KEY=VALUE,...]] (tracer.methods' spec grammar, e.g.
    'photon', 'photon:sigma=2/gpt:shift=replay', 'bsdf/path:nee=0'); either with `+oidn` after it
    ('bsdf+oidn', 'gpt-l1+oidn'): the same, denoised by Open Image Denoise in its time budget."""
    if method.endswith(DENOISED):
        return dict(render_args(method[:-len(DENOISED)]), denoise=True)
    if method in GRADIENT_METHODS:
        return {k: (dict(v) if isinstance(v, dict) else v) for k, v in GRADIENT_METHODS[method].items()}
    guide, _, integrator = method.partition("/")
    name, settings = method_spec(guide)
    args = {"guide": name, "guide_settings": settings or None}
    if integrator:
        args["integrator"] = integrator
    return args


def check_method(method):
    """Fail before rendering on an unknown method, guide, integrator or setting, or a guide the
    integrator cannot run with."""
    if method.endswith(DENOISED):
        from tracer.denoise import available

        if not available():
            raise SystemExit(f"bench: {method} needs Intel Open Image Denoise: pip install -e \".[denoise]\"")
        method = method[:-len(DENOISED)]
    if method.startswith("gpt") and method not in GRADIENT_METHODS:
        raise SystemExit(f"bench: unknown gradient method {method!r}; valid: " + ", ".join(GRADIENT_METHODS)
                         + " (or GUIDE/gpt:KEY=VALUE,...)")
    args = render_args(method)
    integ = make_integrator(args.get("integrator", "path"))
    name = args.get("guide", "bsdf")
    integ.check_guide(make_guide(name, **(args.get("guide_settings") or {})), name)


def built_with_gcc(prog, needs, folder, build):
    """build(folder) (a C program or library built with gcc into `folder`, made if missing), or None
    with one line on stderr where gcc is missing: "<prog> needs <needs>"."""
    if shutil.which("gcc") is None:
        print(f"{prog} needs {needs}", file=sys.stderr)
        return None
    os.makedirs(folder, exist_ok=True)
    return build(folder)
