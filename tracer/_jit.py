"""One place that sets the Numba options every kernel in the tracer uses.

`jit` compiles a scalar helper (inlined into callers by LLVM), `kernel` a batch kernel
that runs its `prange` loops over all threads. Both cache their machine code on disk
(`cache=True`) so that a second process does not pay the compile again.

Numba keys a cached kernel on its own source file only: edit a helper in another module
(a BSDF, a light) and the kernels that inlined it would load stale code. So the cache lives
in a folder named by a digest of every source file of the package,
`$XDG_CACHE_HOME/tracer/numba/<digest>` (default `~/.cache/...`; `TRACER_CACHE_DIR`
replaces the base, and a `NUMBA_CACHE_DIR` set by the user is left alone).
"""
import hashlib
import os
from contextlib import contextmanager

import numba
from numba import njit
from numba.core import event


def _source_digest():
    """Digest of every .py file of the tracer package (paths and contents)."""
    root = os.path.dirname(os.path.abspath(__file__))
    h = hashlib.sha1()
    for folder, dirs, files in os.walk(root):
        dirs.sort()
        for name in sorted(files):
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                h.update(os.path.relpath(path, root).encode())
                with open(path, "rb") as f:
                    h.update(f.read())
    return h.hexdigest()[:16]


if not os.environ.get("NUMBA_CACHE_DIR"):
    _base = os.environ.get("TRACER_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "tracer", "numba")
    numba.config.CACHE_DIR = os.path.join(_base, _source_digest())

_OPTIONS = dict(cache=True, nogil=True, error_model="numpy", fastmath=False)


@contextmanager
def compile_clock():
    """Seconds Numba spends compiling jitted functions, or loading them from its cache, inside the
    block (a compile inside a compile counted once): yields a one-item list that the block's end
    sets."""
    spent = [0.0]

    def done(seconds):
        spent[0] = seconds

    with event.install_timer("numba:compile", done):
        yield spent


def jit(fn=None, **extra):
    """Decorator for scalar njit helpers (no parallelism)."""
    opts = dict(_OPTIONS, **extra)
    if fn is None:
        return lambda f: njit(**opts)(f)
    return njit(**opts)(fn)


def kernel(fn=None, **extra):
    """Decorator for batch kernels: `parallel=True`, loops written with `prange`."""
    opts = dict(_OPTIONS, parallel=True, **extra)
    if fn is None:
        return lambda f: njit(**opts)(f)
    return njit(**opts)(fn)


def kernels_cached(*names):
    """Whether Numba's cache holds an index for each kernel `module.function` named (e.g.
    "path.shade"): a cheap guess that a render will load its kernels rather than compile
    them for ~30 s (an index made from other sources, or for other types, still compiles)."""
    import glob

    root = numba.config.CACHE_DIR
    if not root or not os.path.isdir(root):
        return False
    return all(glob.glob(os.path.join(glob.escape(root), "**", f"{name}-*.nbi"), recursive=True) for name in names)
