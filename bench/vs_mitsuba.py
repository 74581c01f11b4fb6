"""Mitsuba scene XML files rendered by the tracer and by Mitsuba 3 (`scalar_rgb`), compared.

    python -m bench.vs_mitsuba --scene-dir ../shared/scenes-mitsuba --scenes cornell-box,veach-mis \\
        --width 320 --height 180 --spp 64 --seeds 4 --out bench/summary/mitsuba_scenes/table.md
    python -m bench.vs_mitsuba path/to/scene.xml --spp 256
    python -m bench.vs_mitsuba --scene-dir ../shared/scenes-mitsuba --scenes bathroom --path-loop lanes
    python -m bench.vs_mitsuba envlit --width 64 --height 48 --spp 32 --seeds 4   # or envlit-mask, ...
    python -m bench.vs_mitsuba delta --width 64 --height 48 --spp 64 --seeds 4    # or delta-spot, ...

A scene argument that is not a file names a generated scene: `envlit` (every variant of
bench.scenes_envlit, the environment-lit interior, one feature added at a time) or `envlit-<variant>`;
`delta` (bench.scenes_delta: a room lit by a point, a spot or a directional light) or `delta-<kind>`;
`sunsky` (bench.scenes_sunsky: the room lit by a sun and sky) or `sunsky-<variant>`.

Mitsuba 3 renders a copy of each file that it can load (`mitsuba_copy`: what it rejects is dropped
or mapped the way the tracer reads it, e.g. 0.6's `extEta` folded into eta and k, `gamma` on a
bitmap to `raw`, `roughdiffuse` to diffuse, trilinear filtering to bilinear, a rotation axis
normalised, the pixel filter set to box on both sides). Both render at the same size, spp and
depth, each with `--seeds` independent seeds. Printed per scene: each renderer's image mean per
channel with its standard error (from the spread of the seeds), the z-score of the difference and
the relative difference; and the per-pixel excess: relMSE between the two renderers' mean images
over the relMSE their own noise explains (each pixel's variance of the mean, from its seeds), so
1 is agreement and 1.3 is 30% more error than noise. Needs mitsuba (pip install -e ".[mitsuba]").
"""
import argparse
import os
import sys
import tempfile
import time
import xml.etree.ElementTree as ET

import numpy as np

import tracer
from bench import scenes_delta, scenes_envlit, scenes_sunsky
from bench.atomic import write_text
from tracer.metals import METALS
from tracer.textures import srgb_decode

EPS = 0.01  # relMSE's epsilon (tracer.metrics.relmse)


def _named(el, *names):
    return [c for c in el if c.get("name") in names]


def mitsuba_copy(path, folder, allow_missing=False, size=None):
    """Write a copy of the scene XML `path` that Mitsuba 3 loads into `folder`; return its path and
    the list of changes. Relative file names are made absolute (the copy lives elsewhere); size
    (width, height) replaces the film's."""
    src = os.path.dirname(os.path.abspath(path))
    tree = ET.parse(path)
    root = tree.getroot()
    notes = []
    parent = {c: p for p in root.iter() for c in p}

    def note(msg):
        if msg not in notes:
            notes.append(msg)

    for inc in root.iter("include"):
        note("an <include> is kept as is (its file is not rewritten)")
    for s in list(root.iter("string")):
        if s.get("name") == "filename" and not os.path.isabs(s.get("value", "")) and "$" not in s.get("value", ""):
            file = os.path.join(src, s.get("value"))
            s.set("value", file)
            owner = parent[s]
            if not os.path.exists(file) and allow_missing:
                if owner.tag == "shape":  # the tracer leaves the shape out
                    parent[owner].remove(owner)
                    note("shapes whose mesh file is absent are left out")
                elif owner.tag == "texture":  # the tracer reads the constant 0.5
                    up = parent[owner]
                    i = list(up).index(owner)
                    up.remove(owner)
                    up.insert(i, ET.Element("rgb", name=owner.get("name", "reflectance"), value="0.5"))
                    note("absent textures are the constant 0.5")
    old = root.get("version", "3").startswith("0.")
    for el in root.iter():
        kind = el.get("type")
        if el.tag == "emitter" and kind == "sunsky" and old:
            _sunsky_06(el, path)
            note("0.6 sunsky in 3's names: sunRadiusScale as sun_aperture, albedo 0.15, +y up as a to_world, "
                 "the sun (a direction or a date and time) as sun_direction")
        if el.tag == "film":
            for c in _named(el, "width", "height"):
                if size:
                    c.set("value", str(size[0] if c.get("name") == "width" else size[1]))
            for c in _named(el, "gamma"):
                el.remove(c)
                note("film gamma dropped")
            for f in el.findall("rfilter"):
                el.remove(f)
            el.append(ET.Element("rfilter", type="box"))
        if el.tag == "texture" and kind == "bitmap":
            for c in _named(el, "gamma"):
                el.remove(c)
                g = float(c.get("value"))
                if g == 1.0:
                    el.append(ET.Element("boolean", name="raw", value="true"))
                note("bitmap gamma 1 as raw, -1 as sRGB (Mitsuba 3's default)")
            for c in _named(el, "filterType", "filter_type"):
                if c.get("value") not in ("bilinear", "nearest"):
                    c.set("value", "bilinear")
                    note("bitmap filtering trilinear/ewa as bilinear")
        if el.tag == "bsdf" and kind in ("conductor", "roughconductor"):
            ext = _named(el, "extEta", "ext_eta")
            if ext:
                e = float(ext[0].get("value"))
                el.remove(ext[0])
                mat = _named(el, "material")
                eta_k = METALS[mat[0].get("value") if mat else "Cu"]
                for j, key in enumerate(("eta", "k")):
                    prop = _named(el, key)
                    vals = np.array([float(x) for x in prop[0].get("value").replace(",", " ").split()]) \
                        if prop else np.asarray(eta_k[j])
                    vals = np.broadcast_to(vals, (3,)) / e
                    for p in prop:
                        el.remove(p)
                    el.append(ET.Element("rgb", name=key, value=", ".join(f"{v:.9g}" for v in vals)))
                for m in mat:
                    el.remove(m)
                note("conductor extEta folded into eta and k")
        if el.tag == "bsdf" and kind == "roughdiffuse":
            el.set("type", "diffuse")
            for c in _named(el, "alpha", "useFastApprox", "use_fast_approx"):
                el.remove(c)
            note("roughdiffuse as diffuse")
        if el.tag == "integrator" and kind not in ("path", "volpath", "direct") and "$" not in (kind or ""):
            el.set("type", "path")
            note(f"integrator {kind} as path")
        if el.tag == "rotate":
            a = np.array([float(el.get(k, 0)) for k in "xyz"])
            if abs(np.linalg.norm(a) - 1) > 1e-6:
                for k, v in zip("xyz", a / np.linalg.norm(a)):
                    el.set(k, f"{v:.12g}")
                note("rotation axes normalised")
        if el.tag == "srgb":
            v = np.array([float(x) for x in el.get("value").replace(",", " ").split()])
            el.tag = "rgb"
            el.set("value", ", ".join(f"{x:.9g}" for x in srgb_decode(v, np.float64)))
    out = os.path.join(folder, os.path.basename(path))
    tree.write(out)
    return out, notes


def _sunsky_06(el, path):
    """Rewrite a 0.6 `sunsky` element in place into Mitsuba 3's terms, as tracer.readers.mitsuba
    reads it: sunRadiusScale as sun_aperture, 0.6's albedo default, `scale` into both scales, 0.6's
    +y-up frame as a to_world, a date/time/place as the sun's direction (0.6's formula). The
    reader's warnings are not logged here: the tracer's own load of the scene logs them once."""
    import logging

    from tracer.readers.mitsuba import read_sunsky

    log = logging.getLogger("tracer")
    was = log.disabled
    log.disabled = True
    try:
        sky = read_sunsky(path)
    finally:
        log.disabled = was
    names = {c.get("name"): c for c in el if c.get("name") is not None}
    keep = {"turbidity", "skyScale", "sunScale", "albedo"}
    scale = names.get("scale")
    for k, c in names.items():
        if k not in keep:
            el.remove(c)
    for k in ("skyScale", "sunScale"):
        if k not in names and scale is not None:
            el.append(ET.Element("float", name=k, value=scale.get("value")))
    if "albedo" not in names:
        el.append(ET.Element("float", name="albedo", value="0.15"))
    l2w = np.linalg.inv(sky.world_to_local)
    sun = l2w @ sky.sun
    el.append(ET.Element("vector", name="sun_direction", x=f"{sun[0]:.9g}", y=f"{sun[1]:.9g}", z=f"{sun[2]:.9g}"))
    el.append(ET.Element("float", name="sun_aperture", value=f"{np.degrees(2 * sky.sun_half_aperture):.9g}"))
    t = ET.SubElement(el, "transform", name="to_world")
    m = np.eye(4)
    m[:3, :3] = l2w
    ET.SubElement(t, "matrix", value=" ".join(f"{v:.12g}" for v in m.ravel()))


def mitsuba_render(path, width, height, spp, seeds, allow_missing=False):
    """(seeds, H, W, 3) Mitsuba 3 images of the scene's copy, total seconds, the copy's notes."""
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    with tempfile.TemporaryDirectory() as d:
        copy, notes = mitsuba_copy(path, d, allow_missing, (width, height))
        mi.file_resolver().append(os.path.dirname(os.path.abspath(path)))
        t0 = time.perf_counter()
        scene = mi.load_file(copy)
        imgs = [np.array(mi.render(scene, spp=spp, seed=s))[:, :, :3] for s in range(seeds)]
    return np.stack(imgs).astype(np.float64), time.perf_counter() - t0, notes


def compare(ours, theirs):
    """{mean_*, se_*, z, rel, relmse, expected, excess} of two stacks of seed images."""
    s = ours.shape[0]
    out = {}
    for name, st in (("ours", ours), ("mi", theirs)):
        means = st.reshape(st.shape[0], -1, 3).mean(axis=1)
        out[f"mean_{name}"] = means.mean(axis=0)
        out[f"se_{name}"] = means.std(axis=0, ddof=1) / np.sqrt(st.shape[0])
    out["z"] = (out["mean_ours"] - out["mean_mi"]) / np.sqrt(out["se_ours"] ** 2 + out["se_mi"] ** 2)
    out["rel"] = out["mean_ours"] / out["mean_mi"] - 1
    mo, mm = ours.mean(axis=0), theirs.mean(axis=0)
    ref2 = mm * mm + EPS
    var = ours.var(axis=0, ddof=1) / s + theirs.var(axis=0, ddof=1) / theirs.shape[0]
    out["relmse"] = float(np.mean((mo - mm) ** 2 / ref2))
    out["expected"] = float(np.mean(var / ref2))
    out["excess"] = out["relmse"] / out["expected"]
    return out


def scene_paths(name):
    """The scene XML files an argument names: a file itself, or a generated scene (module docstring),
    written into bench/results/scenes."""
    if os.path.isfile(name):
        return [name]
    if name == "envlit":
        return [scenes_envlit.scene(v) for v in scenes_envlit.VARIANTS]
    if name.startswith("envlit-") and name[len("envlit-"):] in scenes_envlit.VARIANTS:
        return [scenes_envlit.scene(name[len("envlit-"):])]
    if name == "sunsky":
        return [scenes_sunsky.scene(v) for v in scenes_sunsky.VARIANTS]
    if name.startswith("sunsky-") and name[len("sunsky-"):] in scenes_sunsky.VARIANTS:
        return [scenes_sunsky.scene(name[len("sunsky-"):])]
    if name == "delta":
        return [scenes_delta.scene(k) for k in scenes_delta.KINDS]
    if name.startswith("delta-") and name[len("delta-"):] in scenes_delta.KINDS:
        return [scenes_delta.scene(name[len("delta-"):])]
    raise SystemExit(f"bench.vs_mitsuba: {name}: no such file, nor a generated scene (envlit, "
                     f"{', '.join('envlit-' + v for v in scenes_envlit.VARIANTS)}, delta, "
                     f"{', '.join('delta-' + k for k in scenes_delta.KINDS)}, sunsky, "
                     f"{', '.join('sunsky-' + v for v in scenes_sunsky.VARIANTS)})")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="*", help="scene XML files, or generated scenes by name (envlit, envlit-mask, ...)")
    ap.add_argument("--scene-dir", help="a folder of <name>/scene.xml")
    ap.add_argument("--scenes", help="comma-separated names under --scene-dir (default: all)")
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=180)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=4, help="renders per side (standard errors from their spread)")
    ap.add_argument("--out", help="write the table (markdown) here")
    ap.add_argument("--path-loop", default="lanes", help="our renders' path loop (render(path_loop=...))")
    a = ap.parse_args(argv)
    paths = [p for name in a.scene for p in scene_paths(name)]
    if a.scene_dir:
        names = a.scenes.split(",") if a.scenes else sorted(
            n for n in os.listdir(a.scene_dir) if os.path.isfile(os.path.join(a.scene_dir, n, "scene.xml")))
        paths += [os.path.join(a.scene_dir, n, "scene.xml") for n in names]
    rows = []
    for path in paths:
        name = os.path.basename(os.path.dirname(os.path.abspath(path)))
        scene = tracer.load_scene(path, width=a.width, height=a.height, allow_missing=True)
        t0 = time.perf_counter()
        ours = np.stack([tracer.render(scene, spp=a.spp, seed=100 + k, pixel_filter="box", path_loop=a.path_loop).image
                         for k in range(a.seeds)]).astype(np.float64)
        t_ours = (time.perf_counter() - t0) / a.seeds
        theirs, t_mi, notes = mitsuba_render(path, a.width, a.height, a.spp, a.seeds, allow_missing=True)
        c = compare(ours, theirs)
        ok = bool(np.all((np.abs(c["rel"]) <= 0.005) | (np.abs(c["z"]) <= 4)) and c["excess"] <= 1.3)
        rows.append((name, c, t_ours, t_mi / a.seeds, notes, ok, scene.render.max_depth))
        print(f"{name}: {a.width}x{a.height}, {a.spp} spp x {a.seeds} seeds, max_depth {scene.render.max_depth}")
        for who in ("ours", "mi"):
            print(f"  {who:4s} mean {np.array2string(c['mean_' + who], precision=5)} "
                  f"+- {np.array2string(c['se_' + who], precision=5)}")
        print(f"  z {np.array2string(c['z'], precision=2)}, relative difference "
              f"{np.array2string(c['rel'] * 100, precision=3)} %")
        print(f"  relMSE of the means {c['relmse']:.4g}, explained by noise {c['expected']:.4g}: "
              f"excess {c['excess']:.3f}  ({'agrees' if ok else 'DIFFERS'}); {t_ours:.1f} s vs "
              f"{t_mi / a.seeds:.1f} s per render")
        for n in notes:
            print(f"  copy for Mitsuba: {n}")
        sys.stdout.flush()
    if a.out:
        lines = [f"Tracer (path loop {a.path_loop}) vs Mitsuba 3.9.1 `scalar_rgb` on the same scene files: "
                 f"{a.width}x{a.height}, {a.spp} spp, "
                 f"{a.seeds} seeds per side, box filter. Command: `python -m bench.vs_mitsuba "
                 f"{' '.join(argv if argv is not None else sys.argv[1:])}`.", "",
                 "| scene | max depth | mean, ours (rgb) | mean, Mitsuba | difference % | z | excess | agrees | "
                 "s/render ours, Mitsuba | Mitsuba's copy |",
                 "|---|---|---|---|---|---|---|---|---|---|"]
        f3 = lambda v, p=4: " ".join(f"{x:.{p}f}" for x in v)  # noqa: E731
        for name, c, t_o, t_m, notes, ok, depth in rows:
            lines.append(f"| {name} | {depth} | {f3(c['mean_ours'])} | {f3(c['mean_mi'])} | {f3(c['rel'] * 100, 2)} | "
                         f"{f3(c['z'], 1)} | {c['excess']:.3f} | {'yes' if ok else 'no'} | {t_o:.1f}, {t_m:.1f} | "
                         f"{'; '.join(notes) or '-'} |")
        os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
        write_text(a.out, "\n".join(lines) + "\n")
    return 0 if all(r[5] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
