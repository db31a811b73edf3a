"""Run a line of Python in two processes, with one OpenBLAS thread and with two: a result that depends on how BLAS
splits a sum over its threads (np.dot above about 10,000 values) prints differently."""

from __future__ import annotations

import os
import subprocess
import sys


def outputs_by_blas_threads(code: str) -> set[str]:
    """The distinct stdouts of ``python -c code`` with OPENBLAS_NUM_THREADS (and OMP_NUM_THREADS) 1 and 2."""
    return {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                           env={**os.environ, "OPENBLAS_NUM_THREADS": t, "OMP_NUM_THREADS": t}).stdout for t in "12"}
