"""When a kernel runs on several threads (``mcl.kernels``: parallel kernels and their serial twins).

A parallel launch pays a fixed cost before any work is done: about 10 ms to
wake numba's threads after they idled (between two filter updates they do),
and, with another process busy on the second core, a wait for that core. A
whole update of 5,000 particles x 60 beams is about 1 ms of serial work, so
the filter launches threads only for work well above the wake-up:
``PARALLEL_MIN_WORK`` inner-loop steps (about 5-10 ms serial). ``--threads 1``
(``numba.set_num_threads``) makes every kernel serial.

A seed gives the same trajectory whatever the thread count; on another machine it can differ
(``numeric_platform``).
"""

from __future__ import annotations

import numba
import numpy as np

PARALLEL_MIN_WORK = 4_000_000  # particle-beam steps (likelihood field: ~10 ms serial on this machine)


def choose(parallel_kernel, serial_kernel, work: float):
    """The kernel to launch for ``work`` inner-loop steps: the parallel one only when it pays."""
    if work >= PARALLEL_MIN_WORK and numba.get_num_threads() > 1:
        return parallel_kernel
    return serial_kernel


def numpy_umath():
    """numpy's C core module, which holds its SIMD dispatch tables (``__cpu_dispatch__``, ``__cpu_features__``)."""
    try:
        from numpy._core import _multiarray_umath as umath
    except ImportError:  # numpy 1.x
        from numpy.core import _multiarray_umath as umath
    return umath


def numeric_platform() -> dict:
    """What a run's arithmetic depends on besides its config and seed: the versions of numpy, numba and llvmlite
    and the SIMD code numpy dispatches to on this CPU (its ``__cpu_dispatch__`` targets that are on).

    numpy runs other SIMD code on other CPUs (AVX-512, AVX2, SSE): its float64 ``exp``, ``log``, ``arctan2`` and
    ``power`` differ in the last bit between them now and then, and its ``argpartition`` and unstable ``argsort``
    pick differently among equal values. The filter takes no pick of the second kind (``mcl.filter.top_k``, stable
    sorts: ``suites/synthetic.yaml``'s global and kidnapped runs are the same on all three); the first could still
    move a run that hangs on a knife's edge. Reported in ``summary.json`` (``platform``) and part of ``mcl eval``'s
    resume fingerprint."""
    import platform

    import llvmlite
    import numpy as np

    umath = numpy_umath()
    on = getattr(umath, "__cpu_features__", {})
    return {
        "machine": platform.machine(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "llvmlite": llvmlite.__version__,
        "numpy_simd": [t for t in getattr(umath, "__cpu_dispatch__", []) if on.get(t)],
    }


def check_out(out, shape) -> None:
    """ValueError unless ``out`` is a writeable C-contiguous float64 array of ``shape``: the kernels write into it
    unchecked (a buffer reused after KLD sampling changed N was written past its end: a segfault)."""
    if not (isinstance(out, np.ndarray) and out.dtype == np.float64 and out.shape == tuple(shape)
            and out.flags.c_contiguous and out.flags.writeable):
        got = f"{out.dtype} {out.shape}" if isinstance(out, np.ndarray) else type(out).__name__
        raise ValueError(f"out: expected a writeable C-contiguous float64 array of shape {tuple(shape)}, got {got}")
