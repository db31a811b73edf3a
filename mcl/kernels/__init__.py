"""Numba kernels: pure functions over arrays, one topic per module.

A kernel marked ``parallel=True`` spreads its ``prange`` loop over numba's
threads. That pays only for large work: a parallel launch after the threads
have idled costs about 10 ms of wake-up, and with another process busy on a
core every launch waits for it. So the large kernels also have a serial twin
(``serial_twin``: the same Python function compiled without ``parallel``),
and ``mcl.parallel.choose`` picks one by the size of the work. Both give the
same result (each particle's sum runs in the same order either way).
"""

import types

from numba import njit


def serial_twin(kernel):
    """The serial twin of a parallel kernel: its Python function compiled without ``parallel=True`` (``prange``
    runs as ``range``), under its own name so that each version has its own cache entry (umap compiles kernels
    both ways for the same reason)."""
    f = kernel.py_func
    g = types.FunctionType(f.__code__, f.__globals__, f.__name__ + "_serial", f.__defaults__, f.__closure__)
    g.__qualname__ = f.__qualname__ + "_serial"
    g.__doc__ = f.__doc__
    g.__module__ = f.__module__
    return njit(cache=True)(g)
