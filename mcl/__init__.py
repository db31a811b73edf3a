"""mcl: Monte Carlo localization of 2D mobile robots (Probabilistic Robotics ch. 5-6).

Importing ``mcl`` compiles nothing and does not import rerun.
"""

from mcl.errors import ConfigError, DataError, MclError

__all__ = ["MclError", "ConfigError", "DataError"]


def __getattr__(name: str):
    if name == "__version__":  # one source of truth: pyproject.toml, through the installed metadata
        from mcl.cli import package_version

        return package_version()
    raise AttributeError(f"module 'mcl' has no attribute {name!r}")
