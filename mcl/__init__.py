"""mcl: Monte Carlo localization of 2D mobile robots (Probabilistic Robotics ch. 5-6).

Importing ``mcl`` compiles nothing and does not import rerun.
"""

from mcl.errors import ConfigError, DataError, MclError
from mcl.numba_cache import configure as _configure_numba_cache

_configure_numba_cache()  # a read-only install caches the kernels in a user folder (before numba is imported)

__all__ = ["MclError", "ConfigError", "DataError"]


def __getattr__(name: str):
    if name == "__version__":  # one source of truth: pyproject.toml, through the installed metadata
        from mcl.cli import package_version

        return package_version()
    raise AttributeError(f"module 'mcl' has no attribute {name!r}")
