"""TUM trajectory files (``t x y z qx qy qz qw``) and atomic file writes.

Planar poses are stored with z = 0 and the yaw as a quaternion about z
(qx = qy = 0, qz = sin(yaw/2), qw = cos(yaw/2)); reading takes
yaw = 2*atan2(qz, qw), wrapped to (-pi, pi].

Every file this module writes appears under its final name only when
complete: it is written to a temporary file in the same directory, flushed,
fsynced and renamed with ``os.replace`` (atomic on POSIX and Windows).
"""

from __future__ import annotations

import math
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from mcl.errors import DataError

__all__ = ["read_tum", "write_tum", "TumWriter", "atomic_write_text", "atomic_write_bytes", "atomic_writer"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_writer(path: str | os.PathLike, mode: str = "wb", encoding: str | None = None):
    """A file object whose contents appear at ``path`` only when the ``with`` block ends without an error (same-dir
    temp file, fsync, os.replace); on an error the temp file is removed and an OSError names ``path``. For outputs
    written in pieces (a long simulated log), where :func:`atomic_write_bytes` would need them whole in memory."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode, encoding=encoding) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        # mkstemp creates 0600; give the file the permissions open() would have.
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(e, OSError) and e.filename in (None, tmp):  # named by the user's path, not the temp file's
            raise OSError(e.errno, e.strerror or str(e), str(path)) from None
        raise


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (same-dir temp file, fsync, os.replace)."""
    with atomic_writer(path) as f:
        f.write(data)


def check_writable_folder(out: str | os.PathLike, what: str) -> None:
    """ConfigError naming ``what`` (``--out DIR``) unless ``out`` is a folder, or can be made one, that this process
    may write in: checked before any work, so a long run does not end on a permission error."""
    from mcl.errors import ConfigError

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{what}: exists and is not a folder")
    parent = out
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ConfigError(f"{what}: {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"{what}: cannot write in {parent} (permission denied)")


def check_folder_holds(out: Path, flag: str, ours, what: str) -> list[str]:
    """The names in ``out`` (sorted; none when it is no folder yet) when each is ``ours(name)``; ConfigError naming
    ``flag`` otherwise, listing the first four others: ``what`` (a run's outputs, an evaluation's) would be written
    over a user's files."""
    from mcl.errors import ConfigError

    if not out.is_dir():
        return []
    names = sorted(p.name for p in out.iterdir())
    other = [n for n in names if not ours(n)]
    if other:
        more = f", ... ({len(other)} in all)" if len(other) > 4 else ""
        raise ConfigError(f"{flag} {out}: the folder holds files that are not {what} ({', '.join(other[:4])}{more}): "
                          "choose a new or empty folder")
    return names


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write_bytes`)."""
    atomic_write_bytes(path, text.encode(encoding))


def _tum_line(t: float, x: float, y: float, theta: float) -> str:
    half = 0.5 * theta
    return f"{t:.6f} {x:.9f} {y:.9f} 0 0 0 {math.sin(half):.9f} {math.cos(half):.9f}\n"


def write_tum(path: str | os.PathLike, t, poses) -> None:
    """Write timestamps ``t`` (M,) and planar ``poses`` (3, M) as a TUM file, atomically."""
    t = np.asarray(t, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    if t.ndim != 1 or poses.shape != (3, t.shape[0]):
        raise ValueError(f"write_tum: expected t (M,) and poses (3, M), got {t.shape} and {poses.shape}")
    lines = [_tum_line(ti, xi, yi, thi) for ti, xi, yi, thi in zip(t.tolist(), *poses.tolist())]
    atomic_write_text(path, "".join(lines))


def read_tum(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory: returns ``t`` (M,) and planar poses (3, M) float64.

    Blank lines and ``#`` comments are skipped. A malformed line raises
    :class:`DataError` naming ``file:line``.
    """
    name = str(path)
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise DataError(f"{name}: cannot read: {e.strerror or e}") from None
    try:
        text = data.decode("utf-8-sig")  # a byte-order mark (Windows editors) is no field
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise DataError(f"{name}:{line}: not UTF-8 text") from None
    ts: list[float] = []
    rows: list[tuple[float, float, float]] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) != 8:
            raise DataError(f"{name}:{lineno}: TUM: expected 8 fields (t x y z qx qy qz qw), got {len(parts)}")
        try:
            v = [float(p) for p in parts]
        except ValueError:
            raise DataError(f"{name}:{lineno}: TUM: non-numeric field") from None
        if not all(math.isfinite(x) for x in v):
            raise DataError(f"{name}:{lineno}: TUM: non-finite value")
        qz, qw = v[6], v[7]
        if qz == 0.0 and qw == 0.0:
            raise DataError(f"{name}:{lineno}: TUM: zero quaternion")
        yaw = 2.0 * math.atan2(qz, qw)
        yaw = math.atan2(math.sin(yaw), math.cos(yaw))
        if yaw <= -math.pi:
            yaw = math.pi  # theta in (-pi, pi]
        ts.append(v[0])
        rows.append((v[1], v[2], yaw))
    t = np.array(ts, dtype=np.float64)
    poses = np.ascontiguousarray(np.array(rows, dtype=np.float64).reshape(-1, 3).T)
    return t, poses


class LineWriter:
    """Incremental text writer for long runs (one line per update).

    Lines go to ``<path>.partial`` (flushed after each line); :meth:`close`
    renames it to ``path``. Call ``close()`` also after an exception or an
    interrupt (the context manager does): every line written so far then
    lands under the final name, and the final name never holds a
    half-written file.
    """

    def __init__(self, path: str | os.PathLike, header: str | None = None):
        self.path = Path(path)
        self.partial = self.path.with_name(self.path.name + ".partial")
        self._f = open(self.partial, "w", encoding="utf-8")
        self.count = 0
        self._good = 0  # bytes of whole lines known to be in the file
        self._error: OSError | None = None
        if header is not None:
            self._put(header if header.endswith("\n") else header + "\n")

    def _named(self, e: OSError) -> OSError:
        return OSError(e.errno, e.strerror or str(e), str(self.path))

    def _put(self, text: str) -> None:
        try:
            self._f.write(text)
            self._f.flush()
        except OSError as e:  # a full disk, a file size limit: the lines before this one stay whole
            self._error = self._error or e
            raise self._named(e) from None
        self._good += len(text.encode("utf-8"))

    def write_line(self, line: str) -> None:
        if self._f is None:
            raise ValueError(f"{type(self).__name__}({self.path}): append after close")
        self._put(line if line.endswith("\n") else line + "\n")
        self.count += 1

    def close(self) -> None:
        """Flush, fsync and rename the partial file to the final name (idempotent). After a failed write the
        file is cut back to its last whole line and renamed all the same (the lines so far are kept), and the
        write's error is raised, named by the final path."""
        if self._f is None:
            return
        f, self._f = self._f, None
        error = self._error
        try:
            f.flush()
            os.fsync(f.fileno())
        except OSError as e:
            error = error or e
        finally:
            try:
                f.close()
            except OSError as e:  # the buffer's unwritten tail
                error = error or e
        if error is not None:
            os.truncate(self.partial, self._good)  # shrinking a file needs no space
        os.replace(self.partial, self.path)
        if error is not None:
            raise self._named(error) from None

    @property
    def closed(self) -> bool:
        return self._f is None

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()


class TumWriter(LineWriter):
    """Incremental TUM writer: ``append(t, x, y, theta)`` writes one pose (see :class:`LineWriter`)."""

    def __init__(self, path: str | os.PathLike):
        super().__init__(path)

    def append(self, t: float, x: float, y: float, theta: float) -> None:
        self.write_line(_tum_line(float(t), float(x), float(y), float(theta)))
