"""When a kernel runs on several threads (``mcl.kernels``: parallel kernels and their serial twins).

A parallel launch pays a fixed cost before any work is done: about 10 ms to
wake numba's threads after they idled (between two filter updates they do),
and, with another process busy on the second core, a wait for that core. A
whole update of 5,000 particles x 60 beams is about 1 ms of serial work, so
the filter launches threads only for work well above the wake-up:
``PARALLEL_MIN_WORK`` inner-loop steps (about 5-10 ms serial). ``--threads 1``
(``numba.set_num_threads``) makes every kernel serial.
"""

from __future__ import annotations

import numba

PARALLEL_MIN_WORK = 4_000_000  # particle-beam steps (likelihood field: ~10 ms serial on this machine)


def choose(parallel_kernel, serial_kernel, work: float):
    """The kernel to launch for ``work`` inner-loop steps: the parallel one only when it pays."""
    if work >= PARALLEL_MIN_WORK and numba.get_num_threads() > 1:
        return parallel_kernel
    return serial_kernel
