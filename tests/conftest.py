"""Suite-wide set-up: the gradient-domain tracer's kernels compile in a second process while the
other tests run.

From an empty Numba cache the gpt kernels (the hybrid shift's) take about 7.5 min to compile on
one core of the 2-core VM, the path tracer's per-thread loop about 3.5 min and its wavefront 2.5
min on the other: compiling them at once uses both cores.
The tests that run gpt (their module is under tests/gradient or names gpt or tracer.gradient)
are moved to the end of the run and each waits for the compile to finish before it starts, so
they load the kernels from the cache; test_budget's timings are among them, so no timed test
shares the machine with the compile. With the kernels already cached, or no gpt test
selected, nothing is started. TRACER_TEST_WARM=0 turns it off."""
import os
import subprocess
import sys

import pytest

from tracer._jit import kernels_cached

_GPT_MARKERS = ("gpt", "tracer.gradient", "tests.gradient")
_module_uses_gpt = {}
_warm = None


def _uses_gpt(item):
    path = str(item.path)
    if path not in _module_uses_gpt:
        in_dir = os.sep + os.path.join("tests", "gradient") + os.sep in path
        with open(path, encoding="utf-8") as f:
            text = f.read()
        _module_uses_gpt[path] = in_dir or any(m in text for m in _GPT_MARKERS)
    return _module_uses_gpt[path]


def pytest_collection_modifyitems(session, config, items):
    global _warm
    gpt = [it for it in items if _uses_gpt(it)]
    if not gpt or len(gpt) == len(items):
        return
    items[:] = [it for it in items if not _uses_gpt(it)] + gpt
    if os.environ.get("TRACER_TEST_WARM", "1") == "0":
        return
    if kernels_cached("offset_shading.shade_hybrid", "offsets.shift_offsets", "offset_shading.add_next_event"):
        return
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    _warm = subprocess.Popen([sys.executable, "-m", "tests._warm"], cwd=root, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE)


@pytest.fixture(autouse=True)
def _gpt_kernels_compiled(request):
    """Before a gpt test: wait for the compiling process (its failure is reported, and the test
    then compiles what it needs itself)."""
    global _warm
    if _warm is not None and _uses_gpt(request.node):
        _, err = _warm.communicate()
        if _warm.returncode != 0:
            sys.stderr.write(f"tests/_warm.py failed ({_warm.returncode}): {err.decode(errors='replace')[-2000:]}\n")
        _warm = None
    yield


def pytest_unconfigure(config):
    if _warm is not None and _warm.poll() is None:
        _warm.kill()
