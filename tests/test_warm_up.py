"""No kernel compiles inside a render's passes.

render() traces throwaway paths and calls the guides' and the lanes' warm-ups before its clock
starts, so that Numba's compile (or a load from its cache: minutes on a new install) counts neither
in a time budget nor in the stats. A kernel first dispatched after the warm-up would be compiled
inside the passes. Each case runs in a process of its own (in this one, earlier tests have
dispatched every kernel already) and lists the jitted functions of the `tracer` modules whose
compiled signatures grew after the warm-up; the list must be empty.

What it can detect: a class kernel of the lanes left to its first call (the glossy scene has all
three classes: diffuse walls, metals, a mirror), split_lanes without a warm-up (a guide's window
without NEE), the pilot's median splits (split_c small enough that the pilot splits), the
wavefront's shadow-ray step (a guide's recording passes with NEE: the throwaway paths may trace
no shadow ray; it listed embree._occluded and add_unoccluded before warm_up_shadows) and a kernel
called with argument types other than the warm-up's (grid's splats of int32 records and int64
pilot leaves compiled two signatures)."""
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GLOSSY = os.path.join(ROOT, "scenes", "glossy", "glossy.obj")

SCRIPT = r"""
import sys

import tracer
from numba.core.dispatcher import Dispatcher

R = sys.modules["tracer.render"]


def dispatchers():
    out = {}
    for name, mod in list(sys.modules.items()):
        if name == "tracer" or name.startswith("tracer."):
            for attr, v in list(vars(mod).items()):
                if isinstance(v, Dispatcher):
                    out[f"{name}.{attr}"] = v
    return out


seen = {}
warm_up = R._warm_up


def counted(*a, **k):
    warm_up(*a, **k)
    seen.update({n: len(d.signatures) for n, d in dispatchers().items()})


R._warm_up = counted
scene = tracer.load_scene(sys.argv[1], width=32, height=32)
r = tracer.render(scene, spp=16, guide=sys.argv[2], integrator=sys.argv[3], seed=1)
assert seen, "the warm-up did not run"
late = sorted(n for n, d in dispatchers().items() if len(d.signatures) > seen.get(n, 0))
print("LATE", " ".join(late))
print("LANES", r.stats["lane_samples"], r.stats["samples"], r.stats["nonfinite_samples"])
"""


@pytest.mark.parametrize("guide, integrator", [("bsdf", "path"), ("photon:split_c=20", "path:nee=0"),
                                               ("grid", "path:nee=0"), ("photon", "path")])
def test_no_kernel_compiles_after_the_warm_up(guide, integrator):
    """The plain render, and a guide's pilot, training and splitting final passes, dispatch no
    kernel for the first time after render()'s warm-up; the final passes ran on the lanes."""
    out = subprocess.run([sys.executable, "-c", SCRIPT, GLOSSY, guide, integrator], cwd=ROOT, capture_output=True,
                         text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    lines = dict(line.split(" ", 1) for line in out.stdout.splitlines() if line.startswith(("LATE", "LANES")))
    assert lines["LATE"].split() == [], f"compiled inside the passes: {lines['LATE']}"
    lane, total, bad = (int(v) for v in lines["LANES"].split())
    assert 0 < lane <= total and bad == 0, lines["LANES"]


def test_the_set_up_seconds_leave_out_numbas_compile():
    """render's set-up steps (accel, lights, the lanes' tables) count against a time budget, but
    on a new install their jitted helpers compile there: _set_up returns the step's seconds less
    the compile inside it, and the compile's seconds. A function compiled inside the step shows as
    compile (detects the compile counted as set-up); a step that only waits is set-up and nothing
    else; a second call, compiled already, compiles nothing."""
    import time

    from numba import njit

    from tracer.render import _set_up

    @njit(cache=False)
    def f(x):
        return x * 2.0 + 1.0

    out, t, c = _set_up(lambda: f(1.0))
    assert out == 3.0 and c > 0.0 and t < 0.5 * c, (t, c)
    _, t, c = _set_up(lambda: (f(2.0), time.sleep(0.05)))
    assert c == 0.0 and t >= 0.05
