"""mcl: Monte Carlo localization of 2D mobile robots (Probabilistic Robotics ch. 5-6).

Importing ``mcl`` compiles nothing and does not import rerun.
"""

from mcl.errors import ConfigError, DataError, MclError

__all__ = ["MclError", "ConfigError", "DataError"]
__version__ = "0.1.0"
