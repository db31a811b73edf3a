"""The project's own error types.

Every message names the file, the line or the config key it is about, so the
command line can print it as one line and exit with status 2.
"""


class MclError(Exception):
    """Base class of every error mcl reports to the user as one line."""


class ConfigError(MclError):
    """A config file or an override is wrong: unknown key, wrong type, out of range."""


class DataError(MclError):
    """A map, log or trajectory file is unreadable or malformed."""


class MclWarning(RuntimeWarning):
    """Input mcl can still use, but not as given (degenerate weights, NaN ranges, time running backwards).

    Library callers get an ordinary ``warnings.warn`` (a ``RuntimeWarning``); the command line prints each as
    one line, ``mcl: warning: <message>``, as it prints errors.
    """
