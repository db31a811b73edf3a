"""Run a line of Python in two processes, with one OpenBLAS thread and with two: a result that depends on how BLAS
splits a sum over its threads (np.dot above about 10,000 values) prints differently. The same for numpy's SIMD code:
each level of it this CPU has (AVX-512, AVX2, SSE4.2 on this machine), as on CPUs that lack the better ones."""

from __future__ import annotations

import os
import subprocess
import sys


def outputs_by_blas_threads(code: str) -> set[str]:
    """The distinct stdouts of ``python -c code`` with OPENBLAS_NUM_THREADS (and OMP_NUM_THREADS) 1 and 2."""
    return {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                           env={**os.environ, "OPENBLAS_NUM_THREADS": t, "OMP_NUM_THREADS": t}).stdout for t in "12"}


def outputs_by_numpy_simd(code: str) -> set[str]:
    """The distinct stdouts of ``python -c code`` on each level of SIMD code numpy has on this CPU: as is, then with
    the best target switched off, then the two best, ... down to none (NPY_DISABLE_CPU_FEATURES, read when numpy is
    imported), as on CPUs that lack them (on an AVX-512 machine: AVX-512, AVX2, SSE4.2)."""
    from mcl.parallel import numeric_platform

    simd = numeric_platform()["numpy_simd"]
    envs = [{**os.environ, "NPY_DISABLE_CPU_FEATURES": " ".join(simd[i:])} for i in range(len(simd) + 1)]
    return {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout
            for env in envs}
