"""Where numba caches the compiled kernels, and whether that cache is still cold.

The kernels are ``@njit(cache=True)``: the first run compiles them (about 8 s for the demo) and later runs load
them. numba caches next to the source (``mcl/kernels/__pycache__``) when it can write there. In a read-only
site-packages, mcl points ``NUMBA_CACHE_DIR`` at a user cache folder, ``$XDG_CACHE_HOME/mcl/numba`` (default
``~/.cache/mcl/numba``), before numba is imported (``mcl/__init__.py`` calls :func:`configure`); a
``NUMBA_CACHE_DIR`` the user set is kept. No numba import here: this runs on ``import mcl``. ``mcl run`` says once when it
is about to fill a cold cache (:func:`cache_is_cold`).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Mapping, MutableMapping
from pathlib import Path

KERNELS = Path(os.path.abspath(__file__)).parent / "kernels"


def _writable(folder: Path) -> bool:
    """Whether numba could write its in-tree cache (``folder/__pycache__``)."""
    pycache = folder / "__pycache__"
    return os.access(pycache if pycache.is_dir() else folder, os.W_OK)


def user_cache_dir(environ: Mapping[str, str] = os.environ) -> Path:
    """``$XDG_CACHE_HOME/mcl/numba``, ``~/.cache/mcl/numba`` when XDG_CACHE_HOME is unset or empty."""
    base = environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "mcl" / "numba"


def choose_cache_dir(environ: Mapping[str, str] = os.environ, kernels: Path = KERNELS,
                     writable: Callable[[Path], bool] | None = None) -> Path | None:
    """The NUMBA_CACHE_DIR to use: the user's own if set, None (numba's in-tree cache) when the package folder
    is writable, else the user cache folder."""
    if environ.get("NUMBA_CACHE_DIR"):
        return Path(environ["NUMBA_CACHE_DIR"])
    if (writable or _writable)(kernels):
        return None
    return user_cache_dir(environ)


def configure(environ: MutableMapping[str, str] | None = None) -> None:
    """Set NUMBA_CACHE_DIR (in ``environ``, default the process's) for a read-only install; call before numba
    is imported."""
    environ = os.environ if environ is None else environ
    d = choose_cache_dir(environ)
    if d is not None and not environ.get("NUMBA_CACHE_DIR"):
        environ["NUMBA_CACHE_DIR"] = str(d)


def kernels_cache_folder(environ: Mapping[str, str] = os.environ, kernels: Path = KERNELS) -> Path:
    """The folder numba writes the kernels' index files (.nbi) to: ``kernels/__pycache__``, or under
    NUMBA_CACHE_DIR the ``<folder name>_<sha1 of its path>`` subfolder numba's locators use."""
    if environ.get("NUMBA_CACHE_DIR"):
        folder = os.path.abspath(kernels)
        sub = "_".join([os.path.basename(folder), hashlib.sha1(folder.encode()).hexdigest()])
        return Path(environ["NUMBA_CACHE_DIR"]) / sub
    return kernels / "__pycache__"


RUN_KERNELS = ("likelihood", "motion", "resample")  # kernel modules every default run compiles


def cache_is_cold(environ: Mapping[str, str] = os.environ, kernels: Path = KERNELS,
                  modules: tuple[str, ...] = RUN_KERNELS) -> bool:
    """True when one of ``modules`` has no cache index (.nbi) yet: this run compiles its kernels."""
    folder = kernels_cache_folder(environ, kernels)
    return not all(next(folder.glob(f"{m}.*.nbi"), None) is not None for m in modules)
