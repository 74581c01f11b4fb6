"""One place that sets the Numba options every kernel in the tracer uses.

`jit` compiles a scalar helper (inlined into callers by LLVM), `kernel` a batch kernel
that runs its `prange` loops over all threads. Both cache their machine code on disk
(`cache=True`) so that a second process does not pay the compile again.
"""
from numba import njit

_OPTIONS = dict(cache=True, nogil=True, error_model="numpy", fastmath=False)


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
