"""Command line and bad input: one clear line naming the file and the problem, exit code 2."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import tracer
from tracer.cli import main
from tests import scenes

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORNELL = os.path.join(ROOT, "scenes", "cornell", "cornell.obj")


def run_cli(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def fails_with(capsys, args, *fragments):
    code, out, err = run_cli(capsys, *args)
    assert code == 2, (code, out, err)
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines, "no error message"
    msg = lines[-1]
    assert msg.startswith("tracer: "), msg
    assert "Traceback" not in err
    for frag in fragments:
        assert frag in msg, (frag, msg)
    return msg


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
    assert set(stats["time_stages"]) >= {"intersect", "shade", "occluded"}


def test_reference_prints_metrics(tmp_path, capsys):
    ref = tmp_path / "ref.exr"
    assert run_cli(capsys, CORNELL, "--spp", 4, "--width", 16, "--height", 16, "-o", ref, "-q")[0] == 0
    code, text, err = run_cli(capsys, CORNELL, "--spp", 1, "--width", 16, "--height", 16,
                              "-o", tmp_path / "x.exr", "--reference", ref)
    assert code == 0, err
    assert "relMSE" in text and "MSE" in text and "1-SSIM" in text
    m = json.loads((tmp_path / "x.json").read_text())["metrics"]
    assert m["relMSE"] > 0 and np.isfinite(m["1-SSIM"])


def test_python_dash_m_entry_point(tmp_path):
    out = tmp_path / "m.exr"
    p = subprocess.run([sys.executable, "-m", "tracer", CORNELL, "--spp", "1", "--width", "8", "--height", "8",
                        "-o", str(out), "-q"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    assert out.is_file()
    p = subprocess.run([sys.executable, "-m", "tracer", "nope.obj"], capture_output=True, text=True, cwd=ROOT,
                       timeout=300)
    assert p.returncode == 2 and p.stderr.strip().splitlines() == ["tracer: nope.obj: OBJ file not found"]


def test_missing_obj(tmp_path, capsys):
    fails_with(capsys, [tmp_path / "none.obj"], "none.obj", "not found")


def test_missing_mtl(tmp_path, capsys):
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    os.remove(tmp_path / "lamp.mtl")
    fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], "lamp.obj", "lamp.mtl", "not found")


def test_missing_texture(tmp_path, capsys):
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    with open(tmp_path / "lamp.mtl", "a") as f:
        f.write("map_Kd wood.png\n")
    fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], "lamp.mtl", "wood.png", "not found")


@pytest.mark.parametrize("line,what", [("v 1 2\n", "malformed vertex"), ("v 1 nan 2\n", "not finite"),
                                        ("v 1 inf 2\n", "not finite"), ("f 1 2 99\n", "vertex 99"),
                                        ("f 1 x 2\n", "malformed face")])
def test_malformed_obj_line(tmp_path, capsys, line, what):
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    with open(obj, "a") as f:
        f.write(line)
    msg = fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], "lamp.obj:", what)
    assert ":8:" in msg or ":9:" in msg or ":10:" in msg  # names the line


def test_zero_area_triangles_are_counted_and_skipped(tmp_path):
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    with open(obj, "a") as f:
        f.write("v 0 0 1\nv 1 1 1\nv 2 2 1\nf 5 6 7\nf 5 5 6\n")
    scene = tracer.load_scene(obj)
    assert scene.n_triangles == 2
    assert any("skipped 2 zero-area" in w for w in scene.warnings)


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
    out = tmp_path / "g.exr"
    code, _, err = run_cli(capsys, CORNELL, "--guide", "photon", "--guide-opt", "iterations=2", "--width", "16",
                           "--height", "16", "--spp", "12", "-o", out, "-q")
    assert code == 0, err
    stats = json.loads((tmp_path / "g.json").read_text())
    assert stats["guide"] == "photon" and stats["guide_stats"]["settings"]["iterations"] == 2
    assert stats["guide_memory_bytes"] > 0 and stats["spp"] == 12
    assert [p["kind"] for p in stats["passes"]][:3] == ["pilot", "train", "train"]


def test_unknown_accel_and_option(capsys):
    fails_with(capsys, [CORNELL, "--accel", "optix"], "unknown accel 'optix'", "embree", "numba")
    fails_with(capsys, [CORNELL, "--frobnicate"], "--frobnicate")


def test_unwritable_output(tmp_path, capsys):
    fails_with(capsys, [CORNELL, "-o", tmp_path / "no" / "such" / "dir.exr"], "dir.exr", "cannot write")
    fails_with(capsys, [CORNELL, "-o", tmp_path / "x.png"], "x.png", ".exr")


def test_missing_environment_map(tmp_path, capsys):
    obj = scenes.sphere_under_sky(tmp_path, 0.5, 1.0, env={"map": "gone.exr"})
    fails_with(capsys, [obj, "-o", tmp_path / "o.exr"], "gone.exr", "not found")


def test_library_errors_are_tracer_errors(tmp_path):
    with pytest.raises(tracer.SettingsError, match="valid: .*width"):
        tracer.load_scene(CORNELL, widht=3)
    scene = tracer.load_scene(CORNELL, width=8, height=8)
    with pytest.raises(tracer.SettingsError, match="unknown guide 'x'; valid: bsdf"):
        tracer.render(scene, spp=1, guide="x")
    with pytest.raises(tracer.SettingsError, match="max_depth"):
        tracer.render(scene, spp=1, max_depth=0)
