"""Test-session settings.

Under ``pytest -n 2`` (pyproject's addopts) each of the two worker processes keeps a core busy, so a parallel kernel's
second thread would only wait for the other worker's core: each worker runs its kernels on one thread. Tests that
compare thread counts set them themselves (``numba.set_num_threads``), and subprocess runs get numba's default.
"""

import os

import numba


def pytest_configure(config):
    if os.environ.get("PYTEST_XDIST_WORKER"):
        numba.set_num_threads(1)
