"""Command line and bad input: one clear line naming the file and the problem, exit code 2.

Every render here is tiny (8-32 pixels a side, a few spp) and asserts that it met no non-finite
sample (the stats JSON's nonfinite_samples)."""
import datetime
import json
import os
import re
import select
import signal
import stat
import subprocess
import sys
import time

import numba
import numpy as np
import pytest

import tracer
from tracer import metrics
from tracer.cli import main
from tests import scenes

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORNELL = os.path.join(ROOT, "scenes", "cornell", "cornell.obj")


def run_cli(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def fails_with(capsys, args, *fragments):
    """The run exits with 2 and prints exactly one line on stderr, `tracer: ...`, holding every
    fragment (no warnings before it, no traceback)."""
    code, out, err = run_cli(capsys, *args)
    assert code == 2, (code, out, err)
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, f"stderr must be exactly one line, got {lines}"
    msg = lines[0]
    assert msg.startswith("tracer: "), msg
    assert "Traceback" not in err
    for frag in fragments:
        assert frag in msg, (frag, msg)
    return msg


def render_cli(capsys, tmp_path, name, *args, scene=CORNELL, size=16, spp=2, quiet=True):
    """Render `scene` through the CLI into tmp_path/name.exr; (image, stats JSON, stderr).
    Asserts exit 0 and no non-finite sample."""
    out = tmp_path / f"{name}.exr"
    opts = ["--width", size, "--height", size] if size else []
    opts += ["--spp", spp] if spp and "--time" not in args else []
    code, text, err = run_cli(capsys, scene, *opts, *args, "-o", out, *(["-q"] if quiet else []))
    assert code == 0, err
    stats = json.loads((tmp_path / f"{name}.json").read_text())
    assert stats["nonfinite_samples"] == 0
    return tracer.read_image(out), stats, err


@pytest.fixture
def all_threads():
    """--threads changes Numba's thread count for the rest of the process: put it back."""
    yield
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def test_render_writes_exr_png_json(tmp_path, capsys):
    out = tmp_path / "c.exr"
    code, text, err = run_cli(capsys, CORNELL, "--spp", 2, "--width", 32, "--height", 24, "-o", out, "-q")
    assert code == 0, err
    img = tracer.read_image(out)
    assert img.shape == (24, 32, 3) and np.all(np.isfinite(img)) and img.mean() > 0
    assert (tmp_path / "c.png").is_file()
    aovs = tracer.read_image(tmp_path / "c.aovs.exr")
    assert aovs.shape == (24, 32, 7) and np.all(np.isfinite(aovs))
    stats = json.loads((tmp_path / "c.json").read_text())
    assert stats["spp"] == 2 and stats["samples"] == 32 * 24 * 2 and stats["rays"] > 0
    assert stats["nonfinite_samples"] == 0 and stats["interrupted"] is False
    assert set(stats["time_stages"]) >= {"intersect", "shade", "occluded"}
    assert not (tmp_path / "c.variance.exr").exists()  # only with --variance
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.aovs.exr", "c.exr", "c.json", "c.png"]  # no temp files


def test_reference_prints_metrics(tmp_path, capsys):
    ref = tmp_path / "ref.exr"
    assert run_cli(capsys, CORNELL, "--spp", 4, "--width", 16, "--height", 16, "-o", ref, "-q")[0] == 0
    code, text, err = run_cli(capsys, CORNELL, "--spp", 1, "--width", 16, "--height", 16,
                              "-o", tmp_path / "x.exr", "--reference", ref, "-q")
    assert code == 0, err
    assert "relMSE" in text and "MSE" in text and "1-SSIM" in text  # -q hides the bar, not the summary
    assert not err
    stats = json.loads((tmp_path / "x.json").read_text())
    # the preview takes the reference's exposure (one exposure for every method), and says so
    from tracer.imageio import auto_exposure

    assert stats["preview_exposure"] == pytest.approx(np.log2(auto_exposure(tracer.read_image(ref))), rel=1e-9)
    assert f"exposure {stats['preview_exposure']:+.2f} EV, the reference's" in text
    m = stats["metrics"]
    assert m["relMSE"] > 0 and np.isfinite(m["1-SSIM"]) and stats["nonfinite_samples"] == 0


def test_reference_with_crop(tmp_path, capsys):
    """--reference with --crop compares the window of the reference (this crashed with a traceback
    for a crop of three numbers), and a window too small for SSIM fails before rendering."""
    ref = tmp_path / "ref.exr"
    render_cli(capsys, tmp_path, "ref", spp=4)
    img, stats, _ = render_cli(capsys, tmp_path, "x", "--crop", "2,3,8,6", "--reference", ref, spp=1)
    assert img.shape == (6, 8, 3)
    window = tracer.read_image(ref)[3:9, 2:10]
    assert stats["metrics"]["relMSE"] == pytest.approx(metrics.relmse(img, window), rel=1e-6)
    fails_with(capsys, [CORNELL, "--width", 16, "--height", 16, "--crop", "1,2,3", "--reference", ref,
                        "-o", tmp_path / "y.exr"], "--crop", "four integers", "'1,2,3'")
    fails_with(capsys, [CORNELL, "--width", 16, "--height", 16, "--crop", "0,0,2,2", "--reference", ref,
                        "-o", tmp_path / "y.exr"], "ref.exr", "too small", "1-SSIM")
    fails_with(capsys, [CORNELL, "--width", 16, "--height", 16, "--crop", "10,0,8,8", "--reference", ref,
                        "-o", tmp_path / "y.exr"], "crop 10,0,8,8", "16x16")
    assert not (tmp_path / "y.exr").exists()


def test_python_dash_m_entry_point(tmp_path):
    out = tmp_path / "m.exr"
    p = subprocess.run([sys.executable, "-m", "tracer", CORNELL, "--spp", "1", "--width", "8", "--height", "8",
                        "-o", str(out), "-q"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    assert out.is_file()
    stats = json.loads((tmp_path / "m.json").read_text())
    assert stats["nonfinite_samples"] == 0
    assert stats["command_line"][1:] == [CORNELL, "--spp", "1", "--width", "8", "--height", "8", "-o", str(out), "-q"]
    p = subprocess.run([sys.executable, "-m", "tracer", "nope.obj"], capture_output=True, text=True, cwd=ROOT,
                       timeout=300)
    assert p.returncode == 2 and p.stderr.strip().splitlines() == ["tracer: nope.obj: OBJ file not found"]


def test_missing_obj(tmp_path, capsys):
    fails_with(capsys, [tmp_path / "none.obj"], "none.obj", "not found")


def test_missing_mtl(tmp_path, capsys):
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    os.remove(tmp_path / "lamp.mtl")
    fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], "lamp.obj", "lamp.mtl", "not found")


def test_missing_texture_is_a_warning(tmp_path, capsys):
    """A missing texture is one warning naming the MTL line and the file, with the constant used
    instead: not an error."""
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    with open(tmp_path / "lamp.mtl", "a") as f:
        f.write("map_Kd wood.png\n")
    img, stats, err = render_cli(capsys, tmp_path, "o", scene=obj, size=None, spp=None)
    assert img.shape == (8, 8, 3) and img.min() > 0
    missing = [line for line in err.splitlines() if "wood.png" in line]
    assert len(missing) == 1 and missing[0].startswith("tracer: warning: ")
    assert "lamp.mtl" in missing[0] and "not found" in missing[0]


def test_undefined_material_without_light_names_the_cause(tmp_path, capsys):
    """A 0-byte MTL: the warning that 'lamp' is not defined comes first, and the error line (the
    last) says what the scene lacks and why."""
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    (tmp_path / "lamp.mtl").write_text("")
    code, out, err = run_cli(capsys, obj, "-o", tmp_path / "o.exr")
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 2, (code, lines)
    assert lines[0].startswith("tracer: warning: ") and "'lamp'" in lines[0]
    for frag in ("lamp.obj", "no light", "'lamp' not defined in lamp.mtl"):
        assert frag in lines[1], (frag, lines[1])


def test_warnings_print_before_the_failure_they_explain(tmp_path, capsys):
    """A Mitsuba scene lit by a `sunsky` emitter alone whose sun is below the horizon: the warning that
    it emits nothing comes on stderr before the error line "the scene has no light", which is the last line, and the
    run exits with 2. Detects held warnings dropped (or printed after the error) when a run fails."""
    xml = tmp_path / "sky.xml"
    xml.write_text("""<scene version="3.0.0">
        <sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/>
        </transform><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
        </sensor>
        <shape type="rectangle"/>
        <emitter type="sunsky"><vector name="sun_direction" x="0.3" y="0" z="-1"/></emitter>
    </scene>""")
    code, out, err = run_cli(capsys, xml, "-o", tmp_path / "o.exr")
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, (code, err)
    assert len(lines) == 2 and "Traceback" not in err, lines
    assert lines[0].startswith("tracer: warning: ") and "below the horizon" in lines[0]
    assert lines[1].startswith("tracer: ") and "sky.xml" in lines[1] and "no light" in lines[1]


@pytest.mark.parametrize("line,what", [("v 1 2\n", "malformed vertex"), ("v 1 nan 2\n", "not finite"),
                                        ("v 1 inf 2\n", "not finite"), ("f 1 2 99\n", "vertex 99"),
                                        ("f 1 x 2\n", "malformed face")])
def test_malformed_obj_line(tmp_path, capsys, line, what):
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    with open(obj, "a") as f:
        f.write(line)
    msg = fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], "lamp.obj:", what)
    assert ":8:" in msg or ":9:" in msg or ":10:" in msg  # names the line


def test_zero_area_triangles_are_counted_and_skipped(tmp_path, capsys):
    """Skipped zero-area triangles are in scene.warnings; the command line names them only with -v
    (they change no pixel, and a published scene would repeat the line on every run)."""
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    with open(obj, "a") as f:
        f.write("v 0 0 1\nv 1 1 1\nv 2 2 1\nf 5 6 7\nf 5 5 6\n")
    scene = tracer.load_scene(obj)
    assert scene.n_triangles == 2
    assert any("skipped 2 zero-area" in w for w in scene.warnings)
    for verbose in (False, True):
        _, _, err = render_cli(capsys, tmp_path, "z", *(["-v"] if verbose else []), scene=obj, size=8, spp=1)
        assert ("tracer: note:" in err and "skipped 2 zero-area" in err) == verbose, err


def test_no_light(tmp_path, capsys):
    v, f = scenes.box_faces((0, 0, 0), (1, 1, 1), inward=False)
    obj = scenes.write_scene(tmp_path, "dark", [("grey", v, f)], {"grey": "Kd 0.5 0.5 0.5"}, None)
    fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], "dark.obj", "no light")


def test_unknown_sidecar_key(tmp_path, capsys):
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    side = json.loads((tmp_path / "lamp.json").read_text())
    side["camera"]["zoom"] = 2
    (tmp_path / "lamp.json").write_text(json.dumps(side))
    fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], "lamp.json", "'zoom'", "fov")
    side["camera"].pop("zoom")
    side["lights"] = {}
    (tmp_path / "lamp.json").write_text(json.dumps(side))
    fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], "lamp.json", "'lights'", "environment")


def test_malformed_sidecar(tmp_path, capsys):
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    (tmp_path / "lamp.json").write_text("{\"film\": {\"width\": 8,}")
    fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], "lamp.json", "malformed JSON")


def test_unknown_guide_lists_valid(capsys):
    fails_with(capsys, [CORNELL, "--guide", "magic"], "unknown guide 'magic'", "bsdf")


def test_guide_settings(tmp_path, capsys):
    fails_with(capsys, [CORNELL, "--guide", "photon", "--guide-opt", "colour=red"],
               "no setting 'colour'", "photons_per_pixel", "iterations")
    fails_with(capsys, [CORNELL, "--guide", "grid", "--guide-opt", "iterations=2.5"], "iterations", "integer")
    fails_with(capsys, [CORNELL, "--guide", "grid", "--guide-opt", "iterations"], "KEY=VALUE")
    fails_with(capsys, [CORNELL, "--guide", "grid", "--guide-opt", "reconstruct=magic"], "magic", "gaussian")
    _, stats, err = render_cli(capsys, tmp_path, "g", "--guide", "photon", "--guide-opt", "iterations=2",
                               spp=12, quiet=False)
    assert stats["guide"] == "photon" and stats["guide_stats"]["settings"]["iterations"] == 2
    assert stats["guide_memory_bytes"] > 0 and stats["spp"] == 12
    kinds = [p["kind"] for p in stats["passes"]]
    assert kinds[:3] == ["pilot", "train", "train"] and set(kinds[3:]) == {"final"}
    # the progress bar names each phase
    for phase in ("pilot", "train 1/2", "train 2/2", "final"):
        assert f"{phase}:" in err, (phase, err)


def test_time_budget_guided(tmp_path, capsys):
    """--time stops near its budget (which includes the pilot and the training), and the bar names
    the phases of a guided render under a time budget too."""
    budget = 2.0
    _, stats, err = render_cli(capsys, tmp_path, "t", "--time", budget, "--guide", "grid", "--guide-opt",
                               "iterations=2", quiet=False)
    kinds = [p["kind"] for p in stats["passes"]]
    assert kinds[0] == "pilot" and "final" in kinds and stats["spp"] > 1
    assert 0.4 * budget < stats["time_total"] < 1.5 * budget + 0.5, stats["time_total"]
    assert "pilot:" in err and "final:" in err and "budget 2s" in err


def test_max_depth_1_shows_only_emitters(tmp_path, capsys):
    lit = {}
    for depth in (1, -1):
        img, stats, _ = render_cli(capsys, tmp_path, f"d{depth}", "--max-depth", depth, size=32)
        assert stats["max_depth"] == depth
        lit[depth] = (img.max(axis=2) > 0).mean()
    assert lit[1] < 0.05 and lit[-1] > 0.5, lit  # the light alone, then most of the box


def test_rr_depth(tmp_path, capsys):
    """Russian roulette from the first bounce on ends paths sooner: fewer rays, another image."""
    a, sa, _ = render_cli(capsys, tmp_path, "rr1", "--rr-depth", 1)
    b, sb, _ = render_cli(capsys, tmp_path, "rr5", "--rr-depth", 5)
    assert (sa["rr_depth"], sb["rr_depth"]) == (1, 5)
    assert sa["rays"] < 0.9 * sb["rays"] and not np.array_equal(a, b)


def test_seed(tmp_path, capsys):
    a, sa, _ = render_cli(capsys, tmp_path, "s1", "--seed", 1)
    b, _, _ = render_cli(capsys, tmp_path, "s1again", "--seed", 1)
    c, sc, _ = render_cli(capsys, tmp_path, "s2", "--seed", 2)
    assert sa["seed"] == 1 and sc["seed"] == 2
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_threads_wave_size_and_accel_keep_the_image(tmp_path, capsys, all_threads):
    """--threads, --wave-size and --accel numba change how the work is done, not the samples (the
    Numba BVH's wavefront draws the per-thread loop's random numbers, not the lanes')."""
    ref, _, _ = render_cli(capsys, tmp_path, "ref")
    img, stats, _ = render_cli(capsys, tmp_path, "t1", "--threads", 1)
    assert stats["threads"] == 1
    np.testing.assert_array_equal(img, ref)
    img, stats, _ = render_cli(capsys, tmp_path, "w37", "--wave-size", 37)
    assert stats["wave_size"] == 37
    np.testing.assert_array_equal(img, ref)
    ref, _, _ = render_cli(capsys, tmp_path, "thread", "--path-loop", "thread")
    img, stats, _ = render_cli(capsys, tmp_path, "nb", "--accel", "numba")
    assert stats["accel"] == "numba"
    np.testing.assert_allclose(img, ref, rtol=1e-4, atol=1e-6)


def test_point_filter(tmp_path, capsys):
    """With emitters only, a point-filtered pixel sees the light or not: two values; the box
    filter gives the light's edge pixels values in between."""
    point, stats, _ = render_cli(capsys, tmp_path, "pt", "--filter", "point", "--max-depth", 1, size=32, spp=4)
    box, _, _ = render_cli(capsys, tmp_path, "bx", "--max-depth", 1, size=32, spp=4)
    assert stats["pixel_filter"] == "point"
    assert len(np.unique(point[..., 0])) == 2 and len(np.unique(box[..., 0])) > 2


def test_crop_is_the_window_of_the_full_render(tmp_path, capsys):
    full, _, _ = render_cli(capsys, tmp_path, "full")
    img, stats, _ = render_cli(capsys, tmp_path, "crop", "--crop", "4,6,8,5")
    assert img.shape == (5, 8, 3) and (stats["width"], stats["height"]) == (8, 5) and stats["crop"] == [4, 6, 8, 5]
    np.testing.assert_array_equal(img, full[6:11, 4:12])


def test_exposure_changes_the_png_only(tmp_path, capsys):
    a, sa, _ = render_cli(capsys, tmp_path, "e0")
    b, sb, _ = render_cli(capsys, tmp_path, "e2", "--exposure", 2)
    np.testing.assert_array_equal(a, b)  # the EXR stays linear and untouched
    assert sb["preview_exposure"] == pytest.approx(sa["preview_exposure"] + 2)
    pa, pb = tracer.read_image(tmp_path / "e0.png"), tracer.read_image(tmp_path / "e2.png")
    assert pb.mean() > pa.mean() + 0.05 and (pb >= pa).all()


def test_variance_exr(tmp_path, capsys):
    """--variance writes the library's result.variance (of each pixel's mean) beside the image."""
    img, _, _ = render_cli(capsys, tmp_path, "v", "--variance", spp=4)
    var = tracer.read_image(tmp_path / "v.variance.exr")
    assert var.shape == img.shape and np.isfinite(var).all() and var.min() >= 0 and (var.max(axis=2) > 0).mean() > 0.5
    result = tracer.render(tracer.load_scene(CORNELL, width=16, height=16), spp=4)
    np.testing.assert_array_equal(var, result.variance)


def test_version_and_provenance(tmp_path, capsys):
    code, out, err = run_cli(capsys, "--version")
    assert code == 0 and out.strip() == f"tracer {tracer.__version__}" and not err
    _, stats, _ = render_cli(capsys, tmp_path, "p", size=8, spp=1)
    assert stats["tracer_version"] == tracer.__version__
    assert stats["command_line"] == sys.argv
    assert datetime.datetime.fromisoformat(stats["date"]).tzinfo is not None
    commit = stats["git_commit"]
    assert commit is None or re.fullmatch(r"[0-9a-f]{40}(-dirty)?", commit), commit


def test_list_guides(capsys):
    from tracer.guiding import guide_names, guide_settings

    code, out, err = run_cli(capsys, "--list-guides")
    assert code == 0 and not err
    blocks = {}
    for line in out.splitlines():
        if not line.startswith(" "):
            name = line.split(":")[0]
            blocks[name] = []
            assert line.endswith("."), f"{name}'s description is cut: {line!r}"  # the whole first paragraph
        else:
            blocks[name].append(line.strip())
    assert list(blocks) == list(guide_names())
    for name in guide_names():
        expected = [f"{k} = {v}" for k, v in sorted(guide_settings(name).items())] or ["(no settings)"]
        assert [re.split(r"\s{2,}", line)[0] for line in blocks[name]] == expected, name


@pytest.mark.parametrize("flag", ["--list-guides", "--list-integrators"])
def test_every_listed_setting_says_what_it_means(capsys, flag):
    """Each setting of every guide and integrator is printed with a line of meaning after its
    default, and tracer.setting_meanings names no setting that does not exist. Detects a setting
    added without its meaning (or a meaning left behind by a removed or renamed setting)."""
    from tracer import setting_meanings
    from tracer.guiding import REGISTRY as GUIDES, guide_settings
    from tracer.integrators import REGISTRY as INTEGRATORS, integrator_settings

    if flag == "--list-guides":
        table, settings = setting_meanings.GUIDES, {n: guide_settings(n) for n in GUIDES}
    else:
        table, settings = setting_meanings.INTEGRATORS, {n: integrator_settings(n) for n in INTEGRATORS}
    assert set(table) == set(settings)
    for name, defaults in settings.items():
        assert set(table[name]) == set(defaults), (name, set(table[name]) ^ set(defaults))
    code, out, err = run_cli(capsys, flag)
    assert code == 0 and not err
    rows = [re.split(r"\s{2,}", line.strip(), maxsplit=1) for line in out.splitlines()
            if line.startswith("  ") and "(no settings)" not in line]
    assert len(rows) == sum(len(d) for d in settings.values())
    assert all(len(r) == 2 and len(r[1]) > 10 for r in rows), [r for r in rows if len(r) < 2 or len(r[1]) <= 10]


def test_help_names_every_scene_format(capsys):
    """--help names Mitsuba XML beside OBJ and JSON, and a folder given as the scene gets an error
    that lists all three. Detects the help or the error leaving a format out."""
    with pytest.raises(SystemExit):
        main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "Render an OBJ or Mitsuba XML scene" in text and ".xml" in text and "scene.obj" in text
    msg = fails_with(capsys, [ROOT], "not a scene file")
    assert ".obj" in msg and ".json" in msg and ".xml" in msg


def _mitsuba_box(folder, width=40, height=16):
    """folder/scene.xml: a lit quad seen by a camera, a film of width x height."""
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, "scene.xml")
    with open(path, "w") as f:
        f.write(f"""<scene version="3.0.0">
            <sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0"
            up="0, 1, 0"/></transform><film type="hdrfilm"><integer name="width" value="{width}"/>
            <integer name="height" value="{height}"/></film></sensor>
            <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
        </scene>""")
    return path


def test_a_scene_called_scene_is_named_after_its_folder(tmp_path, capsys, monkeypatch):
    """Without -o, folder/scene.xml (every Bitterli scene) writes <folder>.exr in the current
    folder; other scenes keep their own name. Detects every Bitterli render writing scene.exr."""
    from tracer.cli import default_output

    assert default_output(os.path.join("..", "shared", "staircase", "scene.xml")) == "staircase.exr"
    assert default_output(os.path.join("scenes", "cornell", "cornell.obj")) == "cornell.exr"
    scene = _mitsuba_box(tmp_path / "lit-quad")
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(capsys, scene, "--spp", 1, "--width", 8, "-q")
    assert code == 0, err
    assert (tmp_path / "lit-quad.exr").is_file() and (tmp_path / "lit-quad.json").is_file()
    assert not (tmp_path / "scene.exr").exists()


@pytest.mark.parametrize("size,expected", [({"width": 10}, (10, 4)), ({"height": 5}, (13, 5)),
                                           ({"width": 1}, (1, 1)), ({"width": 9, "height": 9}, (9, 9))])
def test_width_or_height_alone_keeps_the_aspect_ratio(tmp_path, size, expected):
    """A 40x16 scene (OBJ with sidecar, and Mitsuba XML) given only a width or a height gets the
    other side from the scene's aspect ratio, rounded to the nearest pixel, at least 1; both given
    are taken as they are. Detects the other side kept at the scene's size (a 10x16 strip)."""
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=40, height=16)
    xml = _mitsuba_box(tmp_path / "xml")
    for path in (obj, xml):
        scene = tracer.load_scene(path, **size)
        assert (scene.width, scene.height) == expected, path


def test_cli_width_alone_keeps_the_aspect_ratio(tmp_path, capsys):
    """`--width 10` on a 40x16 Mitsuba scene writes a 10x4 image."""
    img, stats, _ = render_cli(capsys, tmp_path, "a", "--width", 10, scene=_mitsuba_box(tmp_path / "xml"), size=None,
                               spp=1)
    assert img.shape == (4, 10, 3) and (stats["width"], stats["height"]) == (10, 4)


def test_summary_says_when_a_guide_trained_fewer_iterations(tmp_path, capsys):
    """A grid render whose pilot uses up a tiny training share (train_budget 0.001 of --time 1)
    trains no iteration: the summary and the stats JSON say so and why, and the JSON's count of
    training passes agrees. A render that trains every iteration asked for says nothing. Detects
    a guide that stops training with no word. The progress bar shows the phase once, as `pilot: 0
    spp` (not `pilot: : 0 spp`)."""
    def run(name, *args, quiet=True):
        code, text, err = run_cli(capsys, CORNELL, "--width", 8, "--height", 8, *args, "-o", tmp_path / f"{name}.exr",
                                  *(["-q"] if quiet else []))
        assert code == 0, err
        assert ": :" not in err and (quiet or "pilot: 0 spp" in err), err
        return text, json.loads((tmp_path / f"{name}.json").read_text())

    text, stats = run("short", "--guide", "grid:train_budget=0.001", "--time", 1, quiet=False)
    training = stats["guide_stats"]["training"]
    assert training["stopped"] == "train_budget" and training["iterations"] == 5
    assert training["trained"] == sum(p["kind"] == "train" for p in stats["passes"]) == 0
    assert "grid trained 0 of 5 iterations after its pilot: the training share was used up" in text
    assert training["why"] in text
    text, stats = run("full", "--guide", "grid:iterations=1", "--spp", 8)
    assert stats["guide_stats"]["training"] == {"iterations": 1, "trained": 1, "spp": [2], "shortened": False,
                                                "stopped": None, "why": ""}
    assert sum(p["kind"] == "train" for p in stats["passes"]) == 1
    assert "trained" not in text, text


def test_unknown_accel_and_option(capsys):
    fails_with(capsys, [CORNELL, "--accel", "optix"], "unknown accel 'optix'", "embree", "numba")
    fails_with(capsys, [CORNELL, "--path-loop", "warp"], "unknown path loop 'warp'", "thread", "lanes")
    fails_with(capsys, [CORNELL, "--frobnicate"], "--frobnicate")


def test_path_loop_lanes(tmp_path, capsys):
    """--path-loop lanes reaches the render: the Cornell box's samples all run on the lanes."""
    _, stats, _ = render_cli(capsys, tmp_path, "lanes", "--path-loop", "lanes")
    assert stats["path_loop"] == "lanes" and stats["lane_samples"] == stats["samples"] > 0


def test_output_folder_is_created(tmp_path, capsys):
    img, _, _ = render_cli(capsys, tmp_path / "new" / "sub", "c", size=8, spp=1)
    assert img.shape == (8, 8, 3) and (tmp_path / "new" / "sub" / "c.png").is_file()
    # ... but not for a run that fails on its input
    fails_with(capsys, [tmp_path / "none.obj", "-o", tmp_path / "other" / "c.exr"], "none.obj", "not found")
    assert not (tmp_path / "other").exists()


def _unwritable_folder(tmp_path):
    """A folder that exists but where no file can be created, or None."""
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        return "/proc" if os.path.isdir("/proc/self") else None  # root may write anywhere but /proc
    if os.name != "posix":
        return None
    folder = tmp_path / "readonly"
    folder.mkdir()
    folder.chmod(stat.S_IRUSR | stat.S_IXUSR)
    return str(folder)


def test_unwritable_output(tmp_path, capsys):
    fails_with(capsys, [CORNELL, "-o", tmp_path / "x.png"], "x.png", ".exr")
    (tmp_path / "d.exr").mkdir()
    fails_with(capsys, [CORNELL, "-o", tmp_path / "d.exr"], "d.exr", "folder")
    folder = _unwritable_folder(tmp_path)
    if folder is None:
        pytest.skip("no folder here that exists but cannot be written")
    try:
        t0 = time.perf_counter()
        # a 60 s render that would only fail when it writes: the check must come before it
        fails_with(capsys, [CORNELL, "--time", 60, "--width", 8, "--height", 8, "-o", os.path.join(folder, "x.exr")],
                   "x.exr", "cannot write")
        assert time.perf_counter() - t0 < 30
    finally:
        if folder.startswith(str(tmp_path)):
            os.chmod(folder, stat.S_IRWXU)


def test_atomic_outputs_replace_the_old_ones(tmp_path, capsys, monkeypatch):
    """A run that fails while writing leaves the previous outputs whole and no temporary files."""
    render_cli(capsys, tmp_path, "c", size=8, spp=1)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}

    def fail(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", fail)
    fails_with(capsys, [CORNELL, "--width", 8, "--height", 8, "--spp", 1, "--seed", 5, "-o", tmp_path / "c.exr", "-q"],
               "c.exr", "No space left")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def _corrupt_exrs(tmp_path, name):
    """Files named `name`, one per folder: random bytes, a real EXR cut in half, and one cut in its
    header (for which OpenImageIO reports several lines)."""
    real = tmp_path / "real.exr"
    tracer.write_image(real, np.random.default_rng(1).random((32, 32, 3)))
    data = real.read_bytes()
    files = {"random": np.random.default_rng(2).bytes(4000), "half": data[: len(data) // 2], "header": data[:100]}
    for folder, content in files.items():
        (tmp_path / folder).mkdir()
        (tmp_path / folder / name).write_bytes(content)
    return [tmp_path / folder / name for folder in files]


def test_missing_or_corrupt_reference(tmp_path, capsys):
    fails_with(capsys, [CORNELL, "--reference", tmp_path / "gone.exr", "-o", tmp_path / "o.exr"],
               "gone.exr", "reference image not found")
    for bad in _corrupt_exrs(tmp_path, "ref.exr"):
        fails_with(capsys, [CORNELL, "--reference", bad, "-o", tmp_path / "o.exr"], str(bad), "cannot read reference")


def test_missing_environment_map(tmp_path, capsys):
    """The line names the sidecar, the map as the sidecar writes it, and the path looked for."""
    obj = scenes.sphere_under_sky(tmp_path, 0.5, 1.0, env={"map": "gone.exr"})
    fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], ".json", "'gone.exr' not found",
               f"looked for {tmp_path / 'gone.exr'}")


def test_binary_obj(tmp_path, capsys):
    """A binary file named .obj is called so, not 'an OBJ with no faces'."""
    obj = tmp_path / "mesh.obj"
    obj.write_bytes(b"ply\nformat binary_little_endian 1.0\n" + bytes(range(256)) * 4)
    fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], "mesh.obj", "not a text OBJ file", "binary")


def test_corrupt_environment_map(tmp_path, capsys):
    for bad in _corrupt_exrs(tmp_path, "sky.exr"):
        obj = scenes.sphere_under_sky(bad.parent, 0.5, 1.0, env={"map": "sky.exr"})
        fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], str(bad), "cannot read environment map")


@pytest.mark.parametrize("args,what", [(["--spp", 0], "--spp must be >= 1, got 0"),
                                       (["--time", 0], "--time must be a positive"),
                                       (["--time", "nan"], "--time must be a positive"),
                                       (["--max-depth", 0], "--max-depth"),
                                       (["--wave-size", 0], "--wave-size"),
                                       (["--exposure", "inf"], "--exposure")])
def test_bad_numbers(tmp_path, capsys, args, what):
    fails_with(capsys, [CORNELL, *args, "-o", tmp_path / "o.exr"], what)


def test_compile_notice(tmp_path, capsys, monkeypatch):
    """A render whose kernels are not cached says so before the ~30 s of compiling (not with -q)."""
    from tracer import _jit

    for cached, quiet in ((False, False), (True, False), (False, True)):
        monkeypatch.setattr(_jit, "kernels_cached", lambda *names: cached)
        _, _, err = render_cli(capsys, tmp_path, "n", size=8, spp=1, quiet=quiet)
        assert ("compiling the kernels" in err) == (not cached and not quiet), (cached, quiet, err)
    monkeypatch.undo()
    assert _jit.kernels_cached("thread_loop.trace_paths")  # after a render, in this cache
    assert not _jit.kernels_cached("integrator.no_such_kernel")


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")  # (the swallowed one)
def test_sigint_swallowed_by_a_c_callback_during_the_compile_still_stops(tmp_path, capsys, monkeypatch):
    """A Ctrl-C whose KeyboardInterrupt is raised inside a callback from C (as Numba's compile ends
    in llvmlite's object-cache callback, through ctypes, which prints and drops it) still stops
    the run before its passes: exit 130, no image. The warm-up here ends in such a callback that
    sends SIGINT to this process. Detects the lost Ctrl-C (the render ran to its end), and a
    handler that no longer raises at once while compiling (the first check: a plain SIGINT
    during the warm-up must end it there, before the callback)."""
    import ctypes
    import importlib

    render_mod = importlib.import_module("tracer.render")  # (tracer.render is also the function)

    warm_up, calls = render_mod._warm_up, []

    def interrupted_warm_up(*args):
        warm_up(*args)
        calls.append("warm")
        if len(calls) == 1:  # Python's own handler path: raises where it lands
            os.kill(os.getpid(), signal.SIGINT)
            calls.append("not raised")
        cb = ctypes.CFUNCTYPE(None)(lambda: [os.kill(os.getpid(), signal.SIGINT), sum(range(100))])
        cb()

    monkeypatch.setattr(render_mod, "_warm_up", interrupted_warm_up)
    saved = signal.signal(signal.SIGINT, signal.default_int_handler)  # (pytest started with nohup ignores it)
    try:
        code, _, err = run_cli(capsys, CORNELL, "--spp", 2, "--width", 8, "--height", 8, "-o", tmp_path / "a.exr",
                               "-q")
        assert code == 130 and calls == ["warm"] and not (tmp_path / "a.exr").exists(), (code, calls, err)
        calls.append("second")
        code, _, err = run_cli(capsys, CORNELL, "--spp", 2, "--width", 8, "--height", 8, "-o", tmp_path / "b.exr",
                               "-q")
    finally:
        signal.signal(signal.SIGINT, saved)
    assert code == 130 and "interrupted" in err and not (tmp_path / "b.exr").exists(), (code, err)


def test_sigint_writes_the_partial_image_and_exits_130(tmp_path):
    """Ctrl-C in the middle of a pass: exit 130, the EXR, PNG and JSON of what was rendered, and a
    summary whose spp is the one the progress bar showed last."""
    out = tmp_path / "i.exr"
    p = subprocess.Popen([sys.executable, "-m", "tracer", CORNELL, "--spp", "1000000", "--width", "32",
                          "--height", "32", "--wave-size", "4096", "-o", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT,
                         # a pytest started in the background (nohup ... &) ignores SIGINT, and its
                         # children would inherit that: give the CLI the default handling back
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    err = b""
    try:
        deadline = time.monotonic() + 300  # the first run after an edit compiles for ~30 s
        while time.monotonic() < deadline:  # until the bar shows samples: then it is rendering
            if select.select([p.stderr], [], [], 1.0)[0]:
                chunk = os.read(p.stderr.fileno(), 4096)
                assert chunk, f"tracer ended before rendering: {err.decode(errors='replace')}"
                err += chunk
                if any(int(n) >= 4 for n in re.findall(rb"(\d+)/1000000 spp", err)):
                    break
        else:
            pytest.fail(f"no progress within the deadline: {err.decode(errors='replace')}")
        p.send_signal(signal.SIGINT)
        stdout, rest = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
    err = (err + rest).decode(errors="replace")
    assert p.returncode == 130, err
    assert "Traceback" not in err
    stats = json.loads((tmp_path / "i.json").read_text())
    assert stats["interrupted"] is True and stats["nonfinite_samples"] == 0
    assert 4 <= stats["spp"] <= stats["spp_mean"] < 1000000
    img = tracer.read_image(out)
    assert img.shape == (32, 32, 3) and np.isfinite(img).all() and img.mean() > 0
    assert (tmp_path / "i.png").is_file()
    summary = re.search(r", ([\d.]+) spp \(interrupted(; every pixel has at least (\d+))?\)", stdout.decode())
    assert summary, stdout
    assert float(summary.group(1)) == round(stats["spp_mean"], 2)  # the JSON's figures, as they are there
    assert summary.group(3) is None or int(summary.group(3)) == stats["spp"]
    shown = re.findall(r"(\d+)/1000000 spp", err)
    assert shown and int(shown[-1]) == round(stats["spp_mean"]), (shown[-3:], stats["spp_mean"])
    cut = [p for p in stats["passes"] if p.get("interrupted")]  # the pass Ctrl-C stopped, with its paths
    assert len(cut) == 1 and cut[0]["partial"] and 0 <= cut[0]["paths"] < cut[0]["spp"] * 32 * 32
    assert stats["samples"] == sum(p.get("paths", p["spp"] * 32 * 32) for p in stats["passes"])


def test_sigint_while_pss_learns_writes_the_candidate_image(tmp_path):
    """Ctrl-C while pss trains its flow (the bar says `learn`): training stops at the next batch,
    the candidate pass is the image, exit 130. (Before, training ran on to its end, 60 s here, and
    no image was written.)"""
    out = tmp_path / "p.exr"
    p = subprocess.Popen([sys.executable, "-m", "tracer", CORNELL, "--guide", "pss", "--spp", "64", "--guide-opt",
                          "train_seconds=60", "--width", "24", "--height", "24", "-o", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    err = b""
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and b"learn" not in err:
            if select.select([p.stderr], [], [], 1.0)[0]:
                chunk = os.read(p.stderr.fileno(), 4096)
                assert chunk, f"tracer ended before learning: {err.decode(errors='replace')}"
                err += chunk
        assert b"candidates" in err and b"learn" in err, err.decode(errors="replace")  # the phases are shown
        time.sleep(0.5)
        p.send_signal(signal.SIGINT)
        stdout, rest = p.communicate(timeout=30)  # not the 60 s of training
    finally:
        if p.poll() is None:
            p.kill()
    err = (err + rest).decode(errors="replace")
    assert p.returncode == 130 and "Traceback" not in err, err
    stats = json.loads((tmp_path / "p.json").read_text())
    assert stats["interrupted"] is True and stats["nonfinite_samples"] == 0 and stats["spp"] == 8
    img = tracer.read_image(out)
    assert img.shape == (24, 24, 3) and np.isfinite(img).all() and img.mean() > 0


def test_library_errors_are_tracer_errors(tmp_path):
    with pytest.raises(tracer.SettingsError, match="valid: .*width"):
        tracer.load_scene(CORNELL, widht=3)
    scene = tracer.load_scene(CORNELL, width=8, height=8)
    with pytest.raises(tracer.SettingsError, match="unknown guide 'x'; valid: auto, bsdf"):
        tracer.render(scene, spp=1, guide="x")
    with pytest.raises(tracer.SettingsError, match="max_depth"):
        tracer.render(scene, spp=1, max_depth=0)
