"""Replay a log through the filter: the job behind ``mcl run``.

Outputs, all in one folder and none left half-written under its final name:

- ``trajectory.tum``: one pose per scan, ``t x y 0 qx qy qz qw``: the estimate of each filter update, and for
  a scan that update gating skips (the robot moved less than ``update_min_d`` / ``update_min_a``) the last
  estimate moved by the odometry since;
- ``quality.csv``: one row per pose: whether the filter updated, the quality signal (``mcl.quality``: the
  fraction of beams matching the map at the estimate, and of beams contradicting it), the lost belief, the
  particle count and the cloud's spread;
- ``recording.rrd``: the Rerun recording (when ``rerun.mode`` is save, or spawn without a display);
- ``config.yaml``: the resolved config, enough to repeat the run exactly;
- ``summary.json``: counts, wall time per stage, and the ``mcl eval`` figures when a truth file is given.

An interrupted run (Ctrl-C, SIGTERM) keeps every pose written so far, closes
the recording and says ``"interrupted": true`` in the summary.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import json
import math
import os
import signal
import sys
import time
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path

import numpy as np

from mcl.config import Config, dump_config
from mcl.datasets import ScanMap
from mcl.datasets.carmen import Scan
from mcl.errors import ConfigError, DataError, MclError
from mcl.estimate import compose, inverse, wrap_angle  # noqa: F401  (compose, inverse: mcl.runner's too)
from mcl.parallel import numeric_platform


def _to_world(pose, points) -> np.ndarray:
    """(2, K) robot-frame points seen from ``pose`` (x, y, theta), in the world frame."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.vstack([pose[0] + c * points[0] - s * points[1], pose[1] + s * points[0] + c * points[1]])


def _spread(cov) -> float:
    """sqrt of the larger x/y variance of a 3x3 pose covariance: the cloud's spread in metres."""
    return float(math.sqrt(max(float(cov[0, 0]), float(cov[1, 1]), 0.0)))


def _fresh_dir(out: Path) -> Path:
    """``out`` made now, or the next name free (``default_out_dir``'s: NAME-2, NAME-3, ...): two runs without --out
    started in the same second both chose one folder (named before their data loaded), and the later deleted the
    earlier's outputs."""
    out.parent.mkdir(parents=True, exist_ok=True)
    stem, k = out.name, 1
    while True:
        try:
            out.mkdir()
            return out
        except FileExistsError:
            k += 1
            out = out.with_name(f"{stem}-{k}")


def default_out_dir(root: Path | None = None) -> Path:
    """The folder under runs/ named by the start time; ``run(..., fresh=True)`` makes it, or the next free name
    (``_fresh_dir``), when the outputs begin."""
    return (root or Path.cwd() / "runs") / datetime.now().strftime("%Y%m%d-%H%M%S")


# what a run writes into its folder (mcl.runner._run), and the partial files of its line writers
RUN_OUTPUTS = ("config.yaml", "trajectory.tum", "quality.csv", "summary.json", "recording.rrd", "estimate.bag",
               "estimate.db3", "estimate.mcap")
PARTIAL_RECORDING = "recording.partial.rrd"  # a recording cut short (mcl.viz.partial_recording)


def _json_ready(value):
    """``value`` with every float that is not finite as None, through dicts, lists and tuples: JSON has no NaN or
    Infinity, and a summary holding one (the odometry interval of a log of one scan) failed other tools' parsers."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    return value


def summary_json(summary: dict) -> str:
    """summary.json's text (and ``mcl run --json``'s): a value that is not finite written as null."""
    return json.dumps(_json_ready(summary), indent=2, allow_nan=False)


def check_out_dir(out: Path, flag: str = "--out", inputs: dict | None = None) -> None:
    """Before any work: ``out`` must be a folder mcl can create and write in, empty or holding a run's outputs
    alone (and ``PREVIOUS``; a run again into the same folder replaces them, ``_set_aside``). ConfigError naming ``flag`` otherwise: a file there,
    a folder holding other files (a user's trajectory.tum is not overwritten), no permission, or an input of the
    run (``inputs``: what it is -> its path) where the run writes an output (a config edited in place, `--truth
    r0/trajectory.tum --out r0`: both were written over)."""
    from mcl.trajectory import check_folder_holds, check_writable_folder

    out = Path(out)
    check_writable_folder(out, f"{flag} {out}")
    outputs = {(out / n).resolve() for n in RUN_OUTPUTS}
    for what, path in (inputs or {}).items():
        if path is not None and Path(path).resolve() in outputs:
            raise ConfigError(f"{flag} {out}: the run would write over its own {what}, {path}; choose another "
                              "folder")
    # a run's outputs are files: a folder named recording.rrd was a traceback after the earlier outputs were gone
    names = check_folder_holds(out, flag, lambda n: ((n.removesuffix(".partial") in RUN_OUTPUTS
                                                      or n == PARTIAL_RECORDING or _atomic_leftover(n))
                                                     and (out / n).is_file()) or (n == PREVIOUS and (out / n).is_dir()),
                               "a run's outputs")
    names = [n for n in names if n != PREVIOUS]
    if names and "config.yaml" not in names:  # a trajectory.tum of the user's own, say
        raise ConfigError(f"{flag} {out}: the folder holds {', '.join(names)} but no config.yaml: not an "
                          "mcl run's folder; choose a new or empty folder")


def _atomic_leftover(name: str) -> bool:
    """A temporary file of a run's atomic write (``mcl.trajectory.atomic_write_text``: ``.summary.json.XXXX.tmp``)
    left by a run killed while it wrote: a run's own, cleared by the next run (it refused the folder)."""
    if not (name.startswith(".") and name.endswith(".tmp")):
        return False
    return any(name.startswith(f".{output}.") for output in RUN_OUTPUTS)


def _failure_text(failure: BaseException, out_dir: Path | None = None) -> str:
    """What stopped a run, in one phrase: an output that could not be written as "FILE: cannot write: REASON"."""
    if isinstance(failure, OSError):
        return f"{failure.filename or out_dir}: cannot write: {failure.strerror or failure}"
    return str(failure)


def _lock_out_dir(out_dir: Path) -> int | None:
    """An exclusive lock on the run's folder for as long as the run writes there (``lock_folder``). Two runs into
    one folder would delete each other's recording and mix their config.yaml, trajectory and summary."""
    return lock_folder(out_dir, f"--out {out_dir}: another mcl run is writing in this folder now: wait for it to "
                                "end, or choose another folder")


def lock_folder(folder: Path, busy: str) -> int | None:
    """An exclusive lock on ``folder`` (flock on the folder itself: no lock file, released by the kernel if the
    process dies; the caller closes the returned descriptor when done; None where there is no flock). ConfigError
    ``busy`` when another process holds it."""
    try:
        import fcntl
    except ImportError:  # not POSIX
        return None
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise ConfigError(busy) from None
    return fd


@contextmanager
def folder_lock(folder: Path, busy: str):
    """``lock_folder`` held for a ``with`` block (or an ExitStack's life): released however the block ends."""
    fd = lock_folder(folder, busy)
    try:
        yield
    finally:
        if fd is not None:
            os.close(fd)


PREVIOUS = ".mcl-previous"  # a folder's earlier finished run, set aside while a new run replaces it


def _finished(out_dir: Path) -> bool:
    """Whether ``out_dir`` holds a run that went to its end (a summary.json neither interrupted nor failed)."""
    try:
        summary = json.loads((out_dir / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(summary, dict) and summary.get("interrupted") is False and "error" not in summary


def _run_files(out_dir: Path) -> list[Path]:
    """The files of a run's outputs in ``out_dir``: finished, partial, and atomic writes' leftovers."""
    names = [*RUN_OUTPUTS, *(f"{n}.partial" for n in RUN_OUTPUTS), PARTIAL_RECORDING]
    files = [out_dir / n for n in names if (out_dir / n).is_file()]
    return files + [p for p in out_dir.iterdir() if _atomic_leftover(p.name) and p.is_file()]


def _set_aside(out_dir: Path) -> Path | None:
    """A run into a folder that holds an earlier run: a finished one is moved into ``PREVIOUS`` (``_put_back``
    restores it if this run does not finish: an interrupted rerun had lost a complete run), anything else goes.
    A ``PREVIOUS`` left by a run that was killed is put back first. Returns ``PREVIOUS`` when it holds a run.

    Killed at any point, the folder stays one a run accepts and the earlier run is recovered: summary.json goes
    aside first (the folder is then no finished run) and config.yaml last (it stays an mcl run's folder), and
    ``_put_back`` brings summary.json back last."""
    import shutil

    stash = out_dir / PREVIOUS
    if stash.is_dir():  # a run killed mid-way (SIGKILL, a power cut) left the finished run aside
        if _finished(out_dir):  # killed as it deleted the stash of a run that finished
            shutil.rmtree(stash)
        else:
            _put_back(out_dir, stash)
    if not _finished(out_dir):
        _clear_run_outputs(out_dir)
        return None
    stash.mkdir()
    for p in sorted(_run_files(out_dir), key=lambda p: (p.name != "summary.json", p.name == "config.yaml")):
        os.replace(p, stash / p.name)
    return stash


def _put_back(out_dir: Path, stash: Path) -> None:
    """The earlier run in ``stash`` back in ``out_dir``, in place of whatever this run wrote: this run's files the
    earlier run had not go first, then the earlier run's files over this run's, summary.json last (killed part-way,
    the folder is still no finished run, and the next run puts back the rest). A stash without config.yaml (the
    last file set aside, the first put back) is a set-aside or put-back cut short: the folder's files are then the
    earlier run's own, and stay."""
    back = {p.name for p in stash.iterdir()}
    if "config.yaml" in back:
        for p in _run_files(out_dir):
            if p.name not in back:
                p.unlink()
    for name in sorted(back, key=lambda n: (n != "config.yaml", n == "summary.json")):
        os.replace(stash / name, out_dir / name)
    stash.rmdir()


def _clear_run_outputs(out_dir: Path) -> None:
    """A run into a folder that holds an earlier unfinished run's outputs: those go first (a recording left from a
    run with rerun.mode save beside the new run's trajectory would belong to another run; a finished run is set
    aside instead, ``_set_aside``)."""
    for p in _run_files(out_dir):
        p.unlink()


# frames of mcl's own code have a file name starting with one of these
_PACKAGE_DIR = tuple({str(Path(__file__).parent), str(Path(__file__).resolve().parent)})


class _Interrupts:
    """SIGINT and SIGTERM during a run, both handled as Ctrl-C.

    While loading (before any output exists) a signal raises KeyboardInterrupt at
    once. From :meth:`defer` on, a signal is only noted, except inside
    :meth:`live` (the filter loop), where it raises KeyboardInterrupt, and there
    not inside :meth:`held` blocks (one update's bookkeeping: the pose written
    and counted together), which raise it as they end. So the closing of the
    outputs and the summary are never cut short, and a second Ctrl-C is noted
    rather than raised.

    Inside :meth:`live` a signal that lands in another package's Python code
    (rerun-sdk's wrappers, a finaliser the garbage collector runs) is noted
    too, and raised as the next held block ends (within one update): an
    exception there can leave that library's native state half-updated (once
    in CI, SIGTERM during a recorded mit_csail run ended in a segfault, status
    -11, instead of a clean stop).
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.caught = False  # a signal arrived
        self._raise = True  # raise at once (else note it)
        self._pending = False  # noted inside a held() block, to raise as it ends
        self._live = False  # inside live(): the filter loop
        self._old: dict = {}

    def __enter__(self) -> "_Interrupts":
        try:
            for sig in self.SIGNALS:
                self._old[sig] = signal.signal(sig, self._handler)
        except ValueError:  # not the main thread: the default handling stays
            pass
        return self

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        self._old.clear()

    def _handler(self, signum, frame) -> None:
        first = not self.caught
        self.caught = True
        if self._raise and first:
            if self._live and frame is not None and not frame.f_code.co_filename.startswith(_PACKAGE_DIR):
                self._pending = True  # inside another package's code: raised as the next held() block ends
                return
            self._raise = False
            raise KeyboardInterrupt
        if first:
            self._pending = True

    def defer(self) -> None:
        """From now on only note signals (outside :meth:`live`)."""
        self._raise = False

    @contextmanager
    def live(self):
        """A block a signal stops with KeyboardInterrupt (at entry, if one came already)."""
        if self.caught:
            self._pending = False
            raise KeyboardInterrupt
        self._raise = True
        self._live = True
        try:
            yield
        finally:
            self._raise = False
            self._live = False

    @contextmanager
    def held(self):
        """Inside :meth:`live`, a block a signal does not cut: KeyboardInterrupt comes as it ends."""
        was, self._raise = self._raise, False
        try:
            yield
        finally:
            self._raise = was
        if was and self._pending:
            self._pending = False
            self._raise = False
            raise KeyboardInterrupt


class Truth:
    """Reference poses looked up at exact scan timestamps (within 1 ms)."""

    def __init__(self, t: np.ndarray, poses: np.ndarray):
        order = np.argsort(t, kind="stable")
        self.t, self.poses = t[order], poses[:, order]
        # as given, for the evaluation: a clock that steps back pairs its stretches by their order
        # (mcl.evaluate), and stamps given twice are said; sorted, the run scored such a log unlike mcl eval
        self.t_given, self.poses_given = t, poses
        self.spacing = float(np.median(np.diff(self.t))) if self.t.size > 1 else 0.0

    def at(self, t: float) -> np.ndarray | None:
        i = int(np.searchsorted(self.t, t))
        for j in (i - 1, i):
            if 0 <= j < self.t.size and abs(self.t[j] - t) <= 1e-3:
                return self.poses[:, j]
        return None

    def near(self, t: float) -> np.ndarray | None:
        """The reference at ``t``: ``at``, else interpolated between the two poses around ``t`` when they are at most
        1.5 of the reference's median spacing apart (a 10 Hz reference on its own clock; a gap in it is not
        bridged). For the recording: ``at`` alone left a reference not stamped at the scans, which the evaluation
        scores by interpolation, without truth in the recording."""
        exact = self.at(t)
        if exact is not None or self.t.size < 2:
            return exact
        i = int(np.searchsorted(self.t, t))
        if i == 0 or i == self.t.size:
            return None
        t0, t1 = self.t[i - 1], self.t[i]
        if not 0.0 < t1 - t0 <= 1.5 * self.spacing:
            return None
        from mcl.evaluate import interpolate_poses

        return interpolate_poses(self.t[i - 1:i + 1], self.poses[:, i - 1:i + 1], np.array([t]))[:, 0]


@contextmanager
def small_pages():
    """NumPy allocations without its transparent-huge-page advice, for a whole run (:func:`run`). Where the kernel
    compacts memory on a fault in an advised region (``defrag: madvise``, Debian's default), the half-dozen
    map-sized arrays of the default config (distance, depth, the map-rejection mask, the likelihood tables)
    stalled in compaction: the filter's set-up on a 250 m map took 1.7-1.9 s with the advice and 1.0 s without,
    the same arrays. The same holds for the map-sized masks made on first use in the loop (the known-cell mask of
    ``sensor.unmapped_unknown``: 147 ms with the advice, 25 ms without, on infinite_corridor). NumPy advises only
    allocations of 4 MiB or more, which the loop's own arrays are not (100,000 particles: 2.4 MB). A NumPy
    without the switch is left as it is."""
    try:
        from numpy._core import multiarray
    except ImportError:  # NumPy 1.x
        from numpy.core import multiarray
    switch = getattr(multiarray, "_set_madvise_hugepage", None)
    if switch is None:
        yield
        return
    previous = switch(False)
    try:
        yield
    finally:
        switch(previous)


def _choose_scans(log, laser: str):
    """The scans of a CARMEN log the run reads (config key ``laser``): :meth:`mcl.datasets.carmen.Log.laser_stream`
    (``auto``: a front and a rear laser fused, said in a note; else FLASER, else ROBOTLASER1, ...), a stream the log
    lacks named by the config key."""
    if laser != "auto":
        kinds = log.kinds()
        for kind in laser.split(","):
            if kind not in kinds:
                raise ConfigError(f"laser: the log {log.path} has no {kind} messages (it has "
                                  f"{', '.join(sorted(kinds)) or 'none'})")
    return log.laser_stream(laser)


STILL_ODOMETRY = 1e-6  # m or rad: odometry poses that never move farther than this from the first are no odometry
STILL_MATCHED = 0.1  # m or rad: ... unless the scans matched one to the next never move farther either (a robot parked)


def _still_odometry(log, scans, sensor_cfg, echo, progress) -> list:
    """``scans`` of a CARMEN log whose scans' odometry poses never move (a laser-only log, written with zeros; or
    its FLASER lines' pose fields left empty): paired with the ODOM lines where those move, else with laser
    odometry (``mcl.laser_odometry``, as a bag without odometry is), with a note. Such a log ran every scan gated
    at the start pose: 12-28 m off without a word."""
    poses = [s.odom for s in scans]
    if len(scans) < 10 or any(p is None for p in poses):
        return scans
    poses = np.asarray(poses, dtype=np.float64)
    if np.abs(poses - poses[0]).max() > STILL_ODOMETRY:
        return scans
    from mcl.datasets.rosbag import odometry_at

    odo = np.asarray(log.odometry, dtype=np.float64).reshape(-1, 6)
    odo = odo[np.argsort(odo[:, 0], kind="stable")]
    if odo.shape[0] >= 2 and np.abs(odo[:, 1:4] - odo[0, 1:4]).max() > STILL_ODOMETRY:
        echo(f"{log.path}: the scans' odometry poses never move; the ODOM lines do: each scan paired with the ODOM "
             "pose at its stamp")
        return [dataclasses.replace(s, odom=odometry_at(odo, s.t)[0]) for s in scans]
    from tqdm import tqdm

    from mcl.laser_odometry import laser_odometry
    from mcl.odomcheck import run_mount

    first = scans[0].kind
    one = [s for s in scans if s.kind == first]
    with tqdm(one, unit="scan", desc="laser odometry", leave=False, dynamic_ncols=True,
              disable=(None if progress is None else not progress)) as bar:
        rows, failed = laser_odometry(bar, run_mount(scans[0], sensor_cfg.laser_pose))
    rows = rows[np.argsort(rows[:, 0], kind="stable")]
    if np.abs(rows[:, 1:4] - rows[0, 1:4]).max() < STILL_MATCHED:  # the scans stood still too: a parked robot
        return scans
    log.odometry = rows  # the odometry the checks read too
    log.wheel_odometry = False
    echo(f"{log.path}: no odometry (every scan's pose and ODOM line is the same): replayed on laser odometry, "
         f"the {first} scans matched one to the next"
         + (f" ({failed} of {len(one)} matched no earlier one: their motion is the last step's, or none)"
            if failed > 0.05 * len(one) else ""))
    return [dataclasses.replace(s, odom=odometry_at(rows, s.t)[0]) for s in scans]


def _check_landmark_ids(landmark_map, marks, grid, echo) -> None:
    """Warn when the log's observations name ids the landmark map lacks (half or more of them: the map of another
    place, ids shifted), and when landmarks lie off the map (a mistyped coordinate). A map whose ids matched none ran
    as odometry alone, 5.2 m off, without a word."""
    ids = np.concatenate([np.asarray(m.ids, dtype=np.int64) for m in marks]) if marks else np.zeros(0, np.int64)
    if ids.size:
        missing = landmark_map.index_of(ids) < 0
        if missing.mean() >= 0.5:
            echo(f"mcl: warning: {landmark_map.path}: {int(missing.sum())} of the log's {ids.size} landmark "
                 f"observations name an id the map lacks (e.g. {int(ids[missing][0])}; the map's ids "
                 f"{int(landmark_map.ids.min())}..{int(landmark_map.ids.max())}): "
                 + ("the landmarks correct nothing" if missing.all() else "those correct nothing"))
    xy = landmark_map.xy
    off = ~grid.contains(*grid.world_to_cell(xy[0], xy[1]))
    if off.any():
        k = int(np.flatnonzero(off)[0])
        echo(f"mcl: warning: {landmark_map.path}: {int(off.sum())} landmark(s) off the map (id "
             f"{int(landmark_map.ids[k])} at ({xy[0, k]:g}, {xy[1, k]:g})): a coordinate mistyped?")


def _landmark_records(log, cfg: Config) -> list:
    """The log's LANDMARK records when ``landmarks.use`` is on (DataError if it has none), else []."""
    if not cfg.landmarks.use:
        return []
    if not log.landmarks:
        raise DataError(f"{log.path}: no LANDMARK lines, but landmarks.use is true")
    return list(log.landmarks)


class _Unpaired:
    """``(scan, None)`` for each scan of a sized iterable, without holding them (a bag's stream)."""

    def __init__(self, scans) -> None:
        self.scans = scans

    def __len__(self) -> int:
        return len(self.scans)

    def __iter__(self):
        return ((s, None) for s in self.scans)


def _retimed(s, odometry: np.ndarray, offset: float):
    """Scan ``s`` with its stamp moved by ``offset`` seconds (``sensor.time_offset``) and paired with the robot's
    odometry pose at the new stamp, interpolated in ``odometry`` (rows t, x, y, theta, tv, rv, time-sorted;
    ``mcl.datasets.rosbag.odometry_at``). Its own pose (a FLASER line's) is dropped; its velocities and laser
    mounting are kept."""
    from mcl.datasets.rosbag import odometry_at

    t = s.t + offset
    return dataclasses.replace(s, t=t, odom=odometry_at(odometry, t)[0])


def _odometry_rows(log, scans) -> tuple[np.ndarray, bool]:
    """The log's odometry as time-sorted rows (t, x, y, theta, tv, rv): its own stream (a CARMEN log's ODOM lines, a
    bag's odometry topic or transforms), or, for a CARMEN log without ODOM lines, ``scans``' own poses (then True)."""
    odometry = np.asarray(log.odometry, dtype=np.float64).reshape(-1, 6)
    from_scans = odometry.shape[0] == 0
    if from_scans:
        odometry = np.array([(s.t, *s.odom, s.tv, s.rv) for s in scans if s.odom is not None],
                            dtype=np.float64).reshape(-1, 6)
    return odometry[np.argsort(odometry[:, 0], kind="stable")], from_scans


def _retime(scans, log, offset: float, echo):
    """``scans`` with ``sensor.time_offset`` applied (``_retimed``, lazily), or as they are when it is 0. The
    odometry is the log's own stream (a CARMEN log's ODOM lines, a bag's odometry topic or transforms); a CARMEN
    log without ODOM lines interpolates its scans' own poses."""
    if offset == 0.0 or not len(scans):
        return scans
    odometry, from_scans = _odometry_rows(log, scans)
    what = "its scans' own odometry poses" if from_scans else "odometry"
    echo(f"{log.path}: sensor.time_offset {offset:+g} s: each scan paired with the {what} at its stamp "
         f"{'+' if offset > 0 else '-'} {abs(offset):g} s")
    if not hasattr(log, "stamps_checked"):  # a CARMEN log (a bag's stamps are checked when it opens)
        from mcl.datasets.rosbag import outside_span

        t = np.array([s.t for s in scans]) + offset
        early, late, (o0, o1) = outside_span(t, odometry[:, 0])
        inside = ~(early | late)
        if not inside.any():
            raise ConfigError(f"sensor.time_offset: {offset:+g} s moves every scan of {log.path} outside its "
                              f"odometry's time span ({o0:.3f}..{o1:.3f} s; the scans at {t.min():.3f}..{t.max():.3f} "
                              "s): the robot would look still")
        if not inside.all():
            echo(f"mcl: warning: sensor.time_offset: {int(np.count_nonzero(~inside))} of {t.size} scans of "
                 f"{log.path} lie outside its odometry's time span: their odometry is held at its end")
    return ScanMap(scans, functools.partial(_retimed, odometry=odometry, offset=float(offset)))


def _open_source(cfg: Config, echo, progress: bool | None = False):
    """The run's data: (log, grid, scans, landmark records, truth, initial pose from the bag or None).

    ``log`` carries ``path``, ``skipped``, ``warnings`` and ``notes``. A CARMEN log (``cfg.log``) is read whole; a
    ROS bag (``cfg.bag``, mcl.datasets.rosbag) is checked in one pass and its scans streamed; its map
    (``topics.map``) stands in for a missing ``cfg.map``, its truth topic for a missing ``cfg.truth``.
    """
    from mcl.deskew import deskew
    from mcl.maps import load_map
    from mcl.trajectory import read_tum

    if cfg.log is None and cfg.bag is None:
        raise ConfigError("log: no log given (set log or bag in the config, or pass --log or --bag)")
    if cfg.bag is None and cfg.map is None:
        raise ConfigError("map: no map given (set it in the config or pass --map)")
    initial = None
    if cfg.bag is not None:
        from mcl.datasets.rosbag import open_bag

        if cfg.landmarks.use:
            raise ConfigError("landmarks.use: a ROS bag carries no LANDMARK records")
        log = open_bag(cfg.bag, cfg.topics, cfg.frames, progress=progress, laser_pose=cfg.sensor.laser_pose)
        log.warnings.extend(log.stamps_checked(cfg.sensor.time_offset))
        if cfg.map is not None:
            grid = load_map(cfg.map)
        elif log.grid is not None:
            grid = log.grid
            echo(f"{cfg.bag}: map from {cfg.topics.map} ({grid.width} x {grid.height} cells, {grid.resolution} m)")
        else:
            raise ConfigError(f"map: no map given and no {cfg.topics.map or 'map topic'} in {cfg.bag} (pass --map)")
        scans = log.scans if cfg.sensor.use else []
        marks: list = []
        initial = log.initial_pose
        if cfg.truth is None and cfg.topics.truth is None and log.references:
            echo(f"{cfg.bag}: not scored: no reference given; the bag has {', '.join(log.references)} "
                 f"(--truth-topic {log.references[0]} scores the run against it)")
    else:
        from mcl.datasets.carmen import read_carmen

        grid = load_map(cfg.map)
        log = read_carmen(cfg.log)
        scans = _choose_scans(log, cfg.laser) if cfg.sensor.use else []
        scans = _still_odometry(log, scans, cfg.sensor, echo, progress)
        marks = _landmark_records(log, cfg)
    for w in log.warnings:
        echo(f"mcl: warning: {w}")
    for note in (*log.notes, *grid.notes):
        echo(note)
    if cfg.sensor.use:
        _check_map(grid, echo)
    if getattr(log, "wheel_odometry", True):
        from mcl.odomcheck import odometry_units

        for said in odometry_units(_odometry_rows(log, scans if isinstance(scans, list) else [])[0]):
            echo(f"mcl: warning: {log.path}: {said}: mend the log (the filter will be lost)")
    scans = _retime(scans, log, cfg.sensor.time_offset, echo)
    if cfg.sensor.use and cfg.sensor.upside_down and len(scans):
        from mcl.datasets import mirrored_scan

        again = sorted(getattr(getattr(log, "scans", None), "mirrored", ()))
        echo(f"{log.path}: sensor.upside_down: every scan read mirrored (the laser mounted upside down)"
             + (f"; the bag's /tf already mounts {', '.join(again)} so: mirrored back" if again else ""))
        scans = ScanMap(scans, mirrored_scan)
    scans = deskew(scans, log, cfg.sensor.sweep_time, echo, timed=cfg.bag is not None)
    if cfg.sensor.use and cfg.sensor.self_hit_skip:
        scans = _skip_self_hits(scans, log, cfg.sensor, echo)
    if cfg.sensor.use and len(scans) and getattr(log, "wheel_odometry", True):
        log.odometry_checks, log.left_out_lasers, log.turned_lasers = _check_odometry(scans, log, cfg.sensor, echo)
        first = log.odometry_checks[0]
        if first.verdict is None:  # the turns' timing means nothing while their sign is in doubt
            mounts = {c.laser: compose(np.asarray(c.mount), np.array([0.0, 0.0, log.turned_lasers.get(c.laser, 0.0)]))
                      for c in log.odometry_checks if c.verdict is None and c.laser not in log.left_out_lasers}
            log.time_offset_checks, log.stamp_offset = _check_time_offset(scans, log, cfg.sensor, mounts, echo)
            if log.stamp_offset is not None:  # sensor.stamp_offset: fit, said in the warning
                hits = getattr(scans, "self_hits", None)
                scans = _retime(scans, log, log.stamp_offset, lambda *_: None)
                if hits is not None:
                    scans.self_hits = hits
    if cfg.sensor.use and len(scans) and (cfg.motion.stalls == "fill" or cfg.motion.jumps == "match"
                                          or cfg.motion.slips == "match"):
        # where the odometry holds a pose while the scans move, jumps, or turns where they do not, their motion from
        # scan matching (mcl.odomstall)
        from mcl.odomcheck import run_mount
        from mcl.odomstall import StallFill

        f = cfg.filter
        filled = StallFill(scans, lambda s: run_mount(s, cfg.sensor.laser_pose), holds=cfg.motion.stalls == "fill",
                           jumps=((f.max_odom_step, f.max_odom_ratio, f.max_odom_speed)
                                  if cfg.motion.jumps == "match" else None), slips=cfg.motion.slips == "match")
        filled.self_hits = getattr(scans, "self_hits", None)
        scans = filled
    if cfg.truth:
        truth = Truth(*read_tum(cfg.truth))
        if not truth.t.size:
            raise DataError(f"{cfg.truth}: no poses (an empty trajectory): nothing to score the run against "
                            "(leave out --truth, or set truth: null)")
    elif cfg.bag is not None and log.truth is not None:
        truth = Truth(*log.truth)
    else:
        truth = None
    if truth is not None and truth.t.size and len(scans):
        stamps = getattr(log, "scan_stamps", None)  # a bag's, read in its first pass (its scans stream)
        stamps = (np.asarray([s.t for s in scans]) if stamps is None or not stamps.size
                  else stamps + cfg.sensor.time_offset)
        a, b = float(stamps.min()), float(stamps.max())
        if truth.t.max() < a or truth.t.min() > b:
            echo(f"mcl: warning: {cfg.truth or f'{cfg.bag}: {cfg.topics.truth}'}: no reference pose is stamped within "
                 f"the scans' time span (reference {truth.t.min():.3f}..{truth.t.max():.3f} s, scans {a:.3f}..{b:.3f}"
                 " s): the run will not be scored")
        else:
            _check_truth_motion(log, truth, cfg.truth or f"{cfg.bag}: {cfg.topics.truth}", echo)
    return log, grid, scans, marks, truth, initial


def _solid_map_note(cfg: Config, grid) -> str | None:
    """The note a run prints when the likelihood field's depth tolerance (``interior_tolerance: null``) is 0 because
    the map's walls are drawn solid (``mcl.sensors.drawn_solid``); None otherwise."""
    from mcl.sensors import solid_map_takes_tolerance_off

    s = cfg.sensor
    if not (s.use and s.model == "likelihood_field" and solid_map_takes_tolerance_off(s.likelihood_field, grid)):
        return None
    return (f"{grid.path}: walls drawn solid ({grid.solid_share:.0%} of the occupied cells deeper than one cell: a map "
            "drawn from geometry, not by SLAM): a return a cell inside a wall scores as one a cell short of it "
            "(sensor.likelihood_field.interior_tolerance null is 0 here, not 0.05 m)")


def _skip_self_hits(scans, log, sensor, echo):
    """``scans`` with the beams that read the robot itself left out (``mcl.datasets.selfhits``), each laser's own
    (fused lasers), said in one note a laser; as they are when there are none (with a warning when the robot turned
    too little to tell, but some beams look like it). The scans returned carry the findings as ``self_hits`` (a
    list, for summary.json)."""
    from mcl.datasets.selfhits import (MIN_TURNS, beam_constancies, self_hits_of, unconfirmed_self_hits,
                                       without_self_hits)

    found = []
    for c in beam_constancies(scans, sensor.range_min, sensor.range_max):
        hits = self_hits_of(c)
        if hits is not None:
            echo(f"{log.path}: {hits.kind}: {hits.describe()}: taken as the robot itself in the laser's view and left "
                 "out (sensor.self_hit_skip: false keeps them)")
            found.append(hits)
            continue
        maybe = unconfirmed_self_hits(c)
        if maybe is not None:
            cut = float(maybe.ranges.max()) + 0.05
            echo(f"mcl: warning: {log.path}: {maybe.kind}: {maybe.describe()}, but the robot turned too little "
                 f"({c.turns} turns of 0.5 rad in the first {c.scans:,} scans; {MIN_TURNS} needed) to tell the "
                 f"robot itself from a wall beside it: scored. If it is the robot, --set sensor.range_min={cut:.2f} "
                 "leaves them out")
    if not found:
        return scans
    out = ScanMap(scans, functools.partial(without_self_hits, hits=found))
    out.self_hits = found
    return out


def _choose_motion_model(cfg: Config, log, scans, echo) -> tuple[Config, float | None]:
    """(the config to run, the odometry's sideways share or None when not measured: ``motion.model: omni``): with
    ``motion.model: odometry`` and ``motion.sideways: omni``, an odometry whose travel goes across the robot's heading
    (``mcl.motion.sideways_share`` at or over ``SIDEWAYS_OMNI``: an omnidirectional base) is run with the omni
    model, with a warning that names the settings; with ``sideways: keep`` or the velocity model, a warning. Not
    measured on laser odometry."""
    from dataclasses import replace

    from mcl.motion import SIDEWAYS_OMNI, sideways_share

    if cfg.motion.model == "omni" or not getattr(log, "wheel_odometry", True):
        # laser odometry (a bag without odometry): its jitter reads as sideways travel (a differential drive's
        # scans matched at 20 Hz along a corridor: 0.19), so it tells nothing of the base
        return cfg, None
    share, travel = sideways_share(_odometry_rows(log, scans)[0][:, 1:4])
    if share < SIDEWAYS_OMNI:
        return cfg, share
    said = f"mcl: warning: {log.path}: {share:.0%} of the odometry's {travel:.0f} m goes across the robot's heading"
    if cfg.motion.model == "velocity":  # (v, w) along the heading: a strafe is not in it
        echo(f"{said} (an omnidirectional base?): the velocity model moves along the heading and has no strafe "
             "(--set motion.model=omni reads the odometry's steps as they are)")
        return cfg, share
    if cfg.motion.sideways != "omni":
        echo(f"{said} (an omnidirectional base?), and motion.sideways: keep leaves the odometry model on it: its rot1 "
             "noise turns every particle on a step sideways (--set motion.model=omni)")
        return cfg, share
    echo(f"{said}: an omnidirectional base (or an odometry that jitters across it, as laser or visual odometry "
         "does), run with motion.model omni (the odometry model's rot1 noise would turn every particle on a step "
         "sideways). --set motion.model=omni says so; motion.sideways: keep keeps odometry")
    return replace(cfg, motion=replace(cfg.motion, model="omni")), share


def _check_odometry(scans, log, sensor, echo):
    """``mcl.odomcheck.check_each_laser`` on the run's scans, each laser where the run puts it; a warning when the
    scans point to a fault (reversed turns, distances off by two, a laser turned from its mounting): one for the
    odometry when every laser says the same, else one for each laser at fault (``mcl.odomcheck.findings``). Returns
    (the checks, the first laser's first, for summary.json; the lasers to leave out of the run)."""
    from mcl.odomcheck import OdometryCheck, check_each_laser, findings, run_mount

    checks = list(check_each_laser(scans, lambda s: run_mount(s, sensor.laser_pose)).values()) or [OdometryCheck(0)]
    left_out, disagree, texts, turned = findings(checks, sensor)
    for c in checks if disagree else checks[:1]:  # the same for all: the odometry's (or every laser's), said once
        if c.laser in texts:
            named = disagree or (len(checks) > 1 and c.verdict is None)  # a fused laser's own turn: named
            echo(f"mcl: warning: {log.path}: {f'{c.laser}: ' if named else ''}{texts[c.laser]}")
    for c in checks[1:] if not disagree else []:  # no verdict anywhere: a fused laser turned a little, named
        if c.laser in texts and c.verdict is None:
            echo(f"mcl: warning: {log.path}: {c.laser}: {texts[c.laser]}")
    return checks, left_out, turned


def _check_time_offset(scans, log, sensor, mounts: dict, echo):
    """``mcl.latency.check_each_laser`` on the run's scans against the log's odometry stream, each laser of
    ``mounts`` ({laser: mount}, as the odometry check took it) on its own; a warning when the scans' turns fit the
    odometry of another moment than their stamps (``mcl.latency.findings``). Returns (the checks, for summary.json;
    the offset to pair every scan at, with ``sensor.stamp_offset: fit``, else None)."""
    from mcl.latency import check_each_laser, findings

    odometry, from_scans = _odometry_rows(log, [])  # the log's own stream; without one, the scans' own poses
    checks = check_each_laser(scans, None if from_scans else odometry, mounts)
    offset, texts = findings(checks, sensor.time_offset, sensor.stamp_offset == "fit")
    for text in texts.values():
        echo(f"mcl: warning: {log.path}: {text}")
    return checks, offset


def _check_truth_motion(log, truth, name: str, echo) -> None:
    """Warn when the reference does not move as the log's odometry does (``mcl.evaluate.motion_disagreement``):
    a trajectory of another run whose clock overlaps this one's would be scored as a lost run."""
    from mcl.evaluate import motion_disagreement

    # a CARMEN log without ODOM lines: every laser's poses (a bag always has an odometry stream)
    odometry, _ = _odometry_rows(log, log.scans if isinstance(getattr(log, "scans", None), list) else [])
    bad, n = motion_disagreement(odometry[:, 0], odometry[:, 1:4].T, truth.t, truth.poses)
    if n >= 10 and bad > n / 3:  # a run's own reference: at most 1 in 11 (the measurement in motion_disagreement)
        source = "laser odometry" if not getattr(log, "wheel_odometry", True) else "odometry"
        echo(f"mcl: warning: {name}: the reference does not move as the {source} does in {bad} of {n} stretches of "
             f"5 s (a trajectory of another run, or the {source} at fault: "
             + ("its matches" if source != "odometry" else "other units or scale, headings in degrees")
             + "): the run is scored against it all the same")


def _estimate_bag(cfg: Config, out_dir: Path, log):
    """``--write-bag``: an EstimateBag ``estimate.<bag|db3|mcap>`` of the input bag's kind in ``out_dir``. Its
    ``map -> odom`` names the frame the bag's odometry is in (``BagSource.odom_frame``: robot1/odom, odom_combined,
    an Odometry's header.frame_id) and is computed from the odometry as the bag records it, so that it joins the
    bag's own /tf tree; with laser odometry (no such frame), ``frames.odom``."""
    from mcl.datasets.bagwrite import EstimateBag
    from mcl.datasets.rosbag import bag_kind

    if cfg.bag is None:
        raise ConfigError("--write-bag: needs a bag input (bag)")
    kind = bag_kind(cfg.bag)
    ext = {"bag1": "bag", "db3": "db3", "mcap": "mcap"}[kind]
    return EstimateBag(out_dir / f"estimate.{ext}", kind, cfg.rerun.particles_max, log.odom_frame or cfg.frames.odom,
                       odometry=log.odom_recorded, namespace=log.tf_topic[: -len("/tf")])


def _updates(scans: list, marks: list) -> list[tuple]:
    """The filter updates in time order, as (scan, marks) pairs.

    A LANDMARK record within 1 ms of a scan joins that scan's update; one with
    no scan is an update of its own, given as ``(record, record)``: the record
    carries ``t``, ``odom``, ``tv``, ``rv`` like a Scan, so ``scan is marks``
    tells a landmark-only update. Scans with no landmarks come as ``(scan, None)``.
    """
    if not marks:
        return _Unpaired(scans)
    attached: dict[int, object] = {}
    alone = []
    st = np.array([s.t for s in scans])
    for m in marks:
        i = int(np.searchsorted(st, m.t)) if st.size else 0
        near = [j for j in (i - 1, i) if 0 <= j < st.size and abs(st[j] - m.t) <= 1e-3 and j not in attached]
        if near:
            attached[min(near, key=lambda j: abs(st[j] - m.t))] = m
        else:
            alone.append(m)
    out = [(s, attached.get(k)) for k, s in enumerate(scans)] + [(m, m) for m in alone]
    out.sort(key=lambda u: u[0].t)  # stable: file order at equal times
    return out


QUALITY_HEADER = "t,updated,match,contradiction,beams,lost,particles,spread_m"


def _quality_line(t: float, updated: bool, fit, lost: bool, particles: int, spread: float) -> str:
    """One row of quality.csv (mcl.quality): empty match/contradiction/beams for a pose without an update or
    without a laser scan."""
    if fit is None or fit.beams == 0:
        m = c = b = ""
    else:
        m, c, b = f"{fit.match:.4f}", f"{fit.contradiction:.4f}", str(fit.beams)
    return f"{t:.6f},{int(updated)},{m},{c},{b},{int(lost)},{particles},{spread:.4f}"


def _quality_summary(rows: list[tuple]) -> dict:
    """summary.json "quality": the fit at the estimate over the updates with a scan, and the lost belief."""
    if not rows:
        return {"updates": 0}
    a = np.array(rows, dtype=np.float64)
    lost = a[:, 2] > 0
    return {
        "updates": int(a.shape[0]),
        "match_mean": float(a[:, 0].mean()),
        "match_p5": float(np.percentile(a[:, 0], 5)),
        "match_min": float(a[:, 0].min()),
        "contradiction_mean": float(a[:, 1].mean()),
        "lost_updates": int(lost.sum()),
        "lost_fraction": float(lost.mean()),
        "lost_episodes": int(np.count_nonzero(np.diff(np.r_[0, lost.astype(np.int8)]) == 1)),
        "lost_at_end": bool(lost[-1]),
    }


def _particles_text(summary: dict) -> str:
    lo, hi = summary["particles_min"], summary["particles_max"]
    if lo == hi:
        return f"{hi} particles"
    return f"{summary['particles_mean']:.0f} particles on average, {lo}..{hi}"


def _kidnap(pf, truth, t: float, estimate, min_distance: float) -> dict:
    """Replace the particles by a cloud around a free pose >= min_distance from the truth at t (the estimate
    when there is no truth); the pose is the first of a batch of uniform free-space draws that is far enough.
    The draws come from a generator of their own, seeded by the config's seed: two configs run with the same seed
    are kidnapped to the same place, whatever their filters drew before (with the filter's generator a change that
    altered the particle counts sent the robot elsewhere, and a comparison of recovery times compared places)."""
    if truth is not None and truth.t.size:
        ref = np.array([np.interp(t, truth.t, truth.poses[0]), np.interp(t, truth.t, truth.poses[1])])
    elif estimate is not None:
        ref = np.asarray(estimate[:2])
    else:
        ref = np.zeros(2)
    rng = np.random.default_rng((int(pf.cfg.seed), 0x6B1D))  # "kidnap": not the filter's stream
    for _ in range(20):
        cand = pf.sample_uniform(512, rng)
        far = np.flatnonzero(np.hypot(cand[0] - ref[0], cand[1] - ref[1]) >= min_distance)
        if far.size:
            pose = cand[:, far[0]]
            pf.kidnap(pose, pf.cfg.filter.initial_std)
            return {"t": float(t), "to": [float(v) for v in pose], "from_xy": [float(v) for v in ref],
                    "distance_m": float(math.hypot(pose[0] - ref[0], pose[1] - ref[1]))}
    raise DataError(f"{pf.grid.path}: no free pose {min_distance:g} m away from ({ref[0]:.2f}, {ref[1]:.2f}) "
                    "to kidnap the filter to")


def run(cfg: Config, out_dir: Path, **kwargs) -> dict:
    """Localize `cfg.log` on `cfg.map`; write the outputs into `out_dir`; return the summary.

    Keywords: ``progress``, ``initial_pose_override``, ``echo``, ``fresh`` (``out_dir`` is a default name: made new,
    or the next free name), ``kidnap_filter_at``, ``write_bag``, ``compile_note``, ``on_update``, ``start_given_as`` (how
    the user gave the start pose, for its error line; see :func:`_run`). SIGINT and
    SIGTERM stop the run cleanly (see :class:`_Interrupts`): ``summary["interrupted"]`` is then true. A signal
    that came after the summary was made (the run is whole) sets ``summary["late_signal"]`` instead.
    """
    with _Interrupts() as signals, small_pages():
        try:
            summary = _run(cfg, out_dir, signals, **kwargs)
        except BaseException:
            # an error _run does not catch (an output that cannot be opened, the recording's server): an earlier
            # finished run set aside comes back (it stayed hidden in .mcl-previous)
            stash = Path(out_dir) / PREVIOUS
            if not kwargs.get("fresh") and stash.is_dir():
                try:
                    _put_back(Path(out_dir), stash)
                except OSError:
                    pass
            raise
        finally:
            if getattr(signals, "lock_fd", None) is not None:
                os.close(signals.lock_fd)
    # A signal noted after the summary was made (while it was written): the run is whole, but the caller must
    # still hear of the Ctrl-C (mcl eval and mcl tune run jobs in this process with --jobs 1).
    summary["late_signal"] = signals.caught and not summary["interrupted"]
    return summary


def _check_start_pose(grid, pose, where: str, echo) -> None:
    """A tracking start pose off the map is a mistake (another frame, x and y swapped): one error line naming
    ``where`` it came from, before anything is written. On the map but not on a free cell: a warning, and the
    filter starts there (its recovery searches if the scans disagree)."""
    x, y = float(pose[0]), float(pose[1])
    ix, iy = grid.world_to_cell(x, y)
    if not grid.contains(ix, iy):
        x0, y0 = grid.origin
        x1, y1 = x0 + grid.width * grid.resolution, y0 + grid.height * grid.resolution
        raise ConfigError(f"{where}: ({x:.3f}, {y:.3f}) lies outside the map {grid.path} "
                          f"(x {x0:.2f}..{x1:.2f} m, y {y0:.2f}..{y1:.2f} m)")
    if not grid.free[iy, ix]:
        what = "an occupied" if grid.occupied[iy, ix] else "an unknown"
        echo(f"mcl: warning: {where}: ({x:.3f}, {y:.3f}) lies on {what} cell of {grid.path}; tracking starts "
             "there")


ERROR_CODES_M = 0.02  # m: readings under this, 1 % of them or more, are a driver's error codes (no laser reads 2 cm)
MM_SUSPECT_M = 200.0  # m: first scans whose median reading lies farther are read in millimetres, most likely
FLOOR_INTERIOR = 0.6  # a floor's free cells with free neighbours on all four sides: 0.81-0.97 on every map measured


def _check_map(grid, echo) -> None:
    """A map read into something no laser can match, before the run: no occupied cell (an image of 0/254 walls read
    with ``mode: raw``, which takes 0 as free) is one error line; more occupied cells than free ones whose free
    space is thin strips (the walls: an image with ``negate`` the wrong way round) is a warning. ROS map_server
    reads both as they are, and the filter then searched a map of nothing, or of walls (ATE 5.6 and 9.5 m on the
    demo's log). A floor plan's black outside has more occupied than free cells too, but its floor is open."""
    occupied = int(np.count_nonzero(grid.occupied))
    free = int(np.count_nonzero(grid.free))
    if occupied == 0 and free > 0:  # (no free cell either: the filter's own line says there is nowhere to localize)
        raise DataError(f"{grid.path}: no occupied cell ({free} free, {grid.occupancy.size - free} unknown): nothing "
                        "for the laser to match (check mode, negate and occupied_thresh against the image)")
    f = grid.free
    if occupied <= free or free == 0:
        return
    inner = int(np.count_nonzero(f[1:-1, 1:-1] & f[:-2, 1:-1] & f[2:, 1:-1] & f[1:-1, :-2] & f[1:-1, 2:]))
    if inner < FLOOR_INTERIOR * free:
        echo(f"mcl: warning: {grid.path}: {occupied} occupied cells against {free} free, and the free space is thin "
             f"strips ({100.0 * inner / free:.0f}% of the free cells have free cells on all four sides; a floor's "
             f"{100 * FLOOR_INTERIOR:.0f}% or more): walls read as free? (negate, or an inverted image)")


MOUNT_WARN_M = 3.0  # m: a laser mounted farther than this from the robot's centre is a frame mistake, not a robot


def _check_first_scans(scans, sensor, echo, first: int = 200) -> float | None:
    """Warnings from the first ``first`` scans, before the run (a bag's scans are a stream: the first ones only,
    as for the recording), for settings that would leave the filter silently blind or wrong:

    - ``sensor.range_min`` / ``range_max`` leave (almost) none of their returns to score (a range_max in feet, a
      range_min above a short laser's reach): the run would only predict. A return is a finite reading above 0
      and under the scan's own no-return value; scans with none (open floor) say nothing either way. Under 1 %
      scored counts as none: a log's stray readings of a few centimetres are no laser.
    - the laser mounted more than ``MOUNT_WARN_M`` from the robot's centre (``sensor.laser_pose``, or the
      log's / bag's own mounting): a tf chain through the wrong frame, a pose given in the map frame;
    - readings in millimetres: a median over ``MM_SUSPECT_M``, or readings far beyond the laser's own maximum.

    Returns the ``sensor.range_min`` to run with when 1 % or more of the readings lie under ``ERROR_CODES_M`` (a
    driver's error codes; said in a note), else None."""
    from mcl.sensors import valid_returns

    lo, hi, returns, scored, beyond, mount = math.inf, -math.inf, 0, 0, 0, None
    readings, far, tiny, own, medians = 0, 0, 0, math.inf, []
    for s in itertools.islice(scans, first):
        offset = sensor.laser_pose if sensor.laser_pose is not None else getattr(s, "laser_offset", None)
        if offset is not None and mount is None and math.hypot(float(offset[0]), float(offset[1])) > MOUNT_WARN_M:
            mount = offset
        r = np.asarray(getattr(s, "ranges", ()), dtype=np.float64)
        with np.errstate(invalid="ignore"):
            positive = r[np.isfinite(r) & (r > 0.0)]
            ret = positive[(positive < float(s.max_range)) if s.max_range is not None else slice(None)]
        readings += positive.size
        tiny += int(np.count_nonzero(positive < ERROR_CODES_M))
        if s.max_range is not None and positive.size:
            own = min(own, float(s.max_range))
            far += int(np.count_nonzero(positive > 1.5 * float(s.max_range)))  # not a no-return marker's value
        if positive.size:
            medians.append(float(np.median(positive)))
        if ret.size:
            lo, hi = min(lo, float(ret.min())), max(hi, float(ret.max()))
            returns += ret.size
            scored += int(np.count_nonzero(valid_returns(ret, None, sensor)))
            beyond += int(np.count_nonzero(ret >= sensor.range_max))
    if mount is not None:
        where = "sensor.laser_pose" if sensor.laser_pose is not None else "the log's laser mounting"
        echo(f"mcl: warning: {where} puts the laser {math.hypot(float(mount[0]), float(mount[1])):.2f} m from the "
             f"robot's centre ({float(mount[0]):.3f}, {float(mount[1]):.3f}): a robot's laser sits within a metre or "
             "two; check the frames (a tf chain through the wrong frame, a pose in the map frame)")
    floor = None
    if readings and tiny >= 0.01 * readings and sensor.range_min < ERROR_CODES_M:
        # a Hokuyo URG driver's error codes (0-19 mm) written as metres: scored as returns at the laser, they made
        # a global search 6.7 m off (0.31 m with them left out)
        floor = ERROR_CODES_M
        echo(f"{tiny} of the first scans' {readings} readings lie under {100 * ERROR_CODES_M:g} cm (a laser's error "
             f"codes, as a Hokuyo URG driver writes them): taken as no returns (sensor.range_min {ERROR_CODES_M:g})")
    if medians and float(np.median(medians)) > MM_SUSPECT_M:
        echo(f"mcl: warning: the first scans' readings lie at {float(np.median(medians)):.0f} m (median): a laser in "
             "a building reads metres; readings in millimetres? (mcl reads ranges in metres)")
    if readings and returns < 0.01 * readings and far >= 0.5 * readings:
        # the readings far beyond the laser's own no-return range (a log's PARAM or its line's maximum), not at it
        # (open floor): a maximum in metres over readings in millimetres left the filter predicting, without a word
        echo(f"mcl: warning: {returns} of the first scans' {readings} readings lie under the laser's own no-return "
             f"range ({own:g} m, as the log gives it): the rest are no returns and the filter predicts (readings in "
             "millimetres?)")
        return floor
    if returns and scored >= 0.01 * returns and beyond >= max(20, 0.01 * returns):
        # a laser that reads farther than sensor.range_max (a 100 m lidar under the default 80 m): said, not dropped
        # in silence
        echo(f"{beyond} of the first scans' {returns} returns lie at or beyond sensor.range_max ({sensor.range_max:g} "
             f"m; they reach {hi:.2f} m): left out (a larger sensor.range_max scores them)")
    if returns == 0 or scored >= 0.01 * returns:
        return floor
    key = "sensor.range_max" if 2 * beyond >= returns - scored else "sensor.range_min"  # what cut most of them
    echo(f"mcl: warning: {key} ({sensor.range_min:g}..{sensor.range_max:g} m) leaves {scored} of the first scans' "
         f"{returns} returns to score (they lie at {lo:.2f}..{hi:.2f} m): the laser weighs (almost) nothing and the "
         "filter predicts")
    return floor


class _UpdateRecording:
    """One filter update into the Rerun recording (``viz.log_step``): the cloud, the estimate, the scan as used
    and the scan the map predicts at the estimate, the odometry and the truth, the update's figures as series;
    line features, landmark observations and depth planes when those are on."""

    def __init__(self, viz, cfg: Config, grid, truth, landmark_map, plane_sensor):
        self.viz, self.cfg, self.grid, self.truth = viz, cfg, grid, truth
        self.landmark_map, self.plane_sensor = landmark_map, plane_sensor
        self.odom_to_map = None  # the odometry frame in the map, fixed at the first update (its trail's anchor)

    def update(self, step: int, scan, no_scan: bool, pf, info, odom, laser_pose, marks, planes) -> None:
        from mcl.sensors import beam_endpoints, sweep_of

        cfg, viz = self.cfg, self.viz
        mean, cov = info.mean, info.cov
        if self.odom_to_map is None:
            self.odom_to_map = compose(mean, inverse(odom))
        ref = self.truth.near(scan.t) if self.truth is not None else None
        stats = {
            "ess": info.ess,
            # N weighted in this update, as quality.csv and the summary count it (pf.n, the set a re-seed grows at
            # its resample, said 10,000 where they said 5,000)
            "particles": float(info.particles),
            "inject_p": info.inject_p,
            "tries": info.tries,
            "spread/full": _spread(info.full_cov),
            "spread/estimate": _spread(cov),
            "clusters": float(info.clusters),
            "skipped_beams": float(info.skipped_beams),
            "quality/match": info.quality,
            "quality/contradiction": info.fit.contradiction if info.fit is not None else math.nan,
            "quality/lost": float(info.lost),
            **{f"time_ms/{k}": 1e3 * v for k, v in info.timings.items()},
        }
        if planes is not None:
            stats["planes/found"] = float(len(planes))
            stats["planes/walls"] = float(planes.vertical(cfg.planes.vertical_tol).size)
        if ref is not None:
            stats["error/position"] = float(math.hypot(mean[0] - ref[0], mean[1] - ref[1]))
            stats["error/heading"] = abs(float(wrap_angle(mean[2] - ref[2])))
        if pf.sweep_order is not None and sweep_of(scan) is not None:
            scan = pf.sweep_order.used(scan)  # the reading the filter uses (mcl.deskew)
        endpoints = (beam_endpoints(scan.ranges, scan.angles, scan.max_range, cfg.sensor, laser_pose, sweep_of(scan))
                     if not no_scan else np.zeros((2, 0)))
        scan_world = expected_world = None
        if cfg.rerun.scan and endpoints.shape[1]:
            scan_world = _to_world(mean, endpoints)
            # the scan the map predicts at the estimate (the beam model's z*), next to the measured one
            expected_world = viz.expected_scan(self.grid, mean, laser_pose, scan.angles,
                                               scan.max_range or cfg.sensor.range_max)
        # the set as this update weighted it: a re-seed resamples at once, and its prior (the kept track's heavy
        # particles among equal fresh ones) was drawn where the update's posterior belonged
        particles, weights = info.weighted if info.weighted is not None else (pf.particles, pf.weights)
        viz.log_step(
            step,
            scan.t,
            particles=particles,
            weights=weights,
            estimate=mean,
            cov=cov,
            scan_world=scan_world,
            skipped_world=(_to_world(mean, info.skipped_endpoints)
                           if cfg.rerun.scan and info.skipped_endpoints is not None else None),
            expected_world=expected_world,
            odom_pose=compose(self.odom_to_map, odom),
            truth_pose=ref,
            stats=stats,
        )
        if cfg.rerun.lines and not no_scan:
            from mcl.features import extract_scan_lines, line_segments_world
            from mcl.viz import log_line_features

            lines = extract_scan_lines(scan, max_range=scan.max_range or cfg.sensor.range_max)
            log_line_features(viz, line_segments_world(lines, mean, laser_pose))
        if self.landmark_map is not None:
            from mcl.viz import log_landmark_observations

            log_landmark_observations(viz, mean, marks, self.landmark_map)
        if planes is not None:
            from mcl.viz import log_planes

            log_planes(viz, mean, self.plane_sensor, planes)


def _run(
    cfg: Config,
    out_dir: Path,
    signals: _Interrupts,
    *,
    progress: bool | None = None,
    initial_pose_override: bool = False,
    echo=None,
    fresh: bool = False,
    kidnap_filter_at: tuple[float, float] | None = None,
    write_bag: bool = False,
    compile_note: bool = False,
    on_update=None,
    start_given_as: str | None = None,
) -> dict:
    """Localize `cfg.log` on `cfg.map`; write the outputs into `out_dir`; return the summary.

    The start: a bag's ``topics.initial_pose`` (its first message) unless ``initial_pose_override`` (the command
    line's --initial-pose or --global, a --set of filter.initial_pose or filter.global_localization, a suite's run)
    or the config tracks from its own ``filter.initial_pose`` (``global_localization: false``); then the config's.

    ``kidnap_filter_at=(t, d)`` (default: the config's ``eval.kidnap_at``, ``eval.kidnap_m``): at the first update
    at or after time t, the particles are replaced by a cloud (filter.initial_std) around a free pose at least d
    metres from the truth there (from the estimate without truth): a kidnapping test on a real log (``mcl eval
    --suite``).
    ``summary["kidnap"]`` says when, where to and how far.

    ``on_update(t, pf, info, ref)``, if given, is called after every filter update (not for gated scans) with the
    scan's time, the filter (its weighted set, before the resample that ``info`` describes was drawn when KLD
    sampling defers it to the next motion), the update's ``StepInfo`` and the reference pose at t (None without
    one): an instrument's hook (``scripts/truth_mass.py``); it must not change the filter.
    """
    # Heavy imports here so `mcl --help` stays fast.
    from tqdm import tqdm

    from mcl.datasets.selfhits import summary_of
    from mcl.odomcheck import summary_of as odometry_summary
    from mcl.latency import summary_of as time_summary
    from mcl.evaluate import evaluate, format_eval
    from mcl.filter import Control, ParticleFilter
    from mcl.motion import velocities_from_odometry
    from mcl.trajectory import LineWriter, TumWriter, atomic_write_text

    echo = echo or (lambda msg: print(msg, file=sys.stderr))
    wall0 = time.perf_counter()
    log, grid, scans, marks_all, truth, bag_initial = _open_source(cfg, echo, progress)
    cfg, sideways = _choose_motion_model(cfg, log, scans, echo)
    if not grid.free.any():
        raise DataError(f"{grid.path}: no free cell (occupied_thresh and free_thresh leave every cell occupied or "
                        "unknown): nowhere to localize")
    landmark_map = None
    if cfg.landmarks.use:
        from mcl.landmarks import load_landmarks

        landmark_map = load_landmarks(cfg.landmarks.map)
        _check_landmark_ids(landmark_map, marks_all, grid, echo)
    fc = cfg.filter
    own_start = not fc.global_localization and fc.initial_pose is not None  # the config tracks from its own pose
    from_bag = bag_initial is not None and not initial_pose_override and not own_start
    if bag_initial is not None and not from_bag:
        echo(f"{cfg.bag}: {cfg.topics.initial_pose} not used: "
             + ("tracking from filter.initial_pose" if own_start else "global localization")
             + (" as the command line says" if initial_pose_override else " as the config says"))
    if from_bag:
        _check_start_pose(grid, bag_initial[0], f"{cfg.bag}: {cfg.topics.initial_pose}", echo)
    elif not fc.global_localization and fc.initial_pose is not None:
        # named as the user gave it: `--initial-pose 1000 1000 0` was said to be filter.initial_pose's
        _check_start_pose(grid, fc.initial_pose, start_given_as or "filter.initial_pose", echo)
    b = cfg.sensor.beam
    if cfg.sensor.use and cfg.sensor.model == "beam" and b.z_max == 0 and b.z_rand == 0:
        echo("mcl: warning: sensor.beam: z_max and z_rand are both 0: a reading the map does not explain (no return, "
             "a person) has likelihood 0 at every pose, so one such beam leaves every particle at weight 0")
    lf = cfg.sensor.likelihood_field
    if cfg.sensor.use and cfg.sensor.model == "likelihood_field" and lf.z_rand == 0:
        echo(f"mcl: warning: sensor.likelihood_field.z_rand is 0: an endpoint {lf.likelihood_max_dist:g} m from every "
             f"wall (a person, a glass door) scores {0.5 * (lf.likelihood_max_dist / lf.sigma_hit) ** 2:.3g} nats "
             "below one on a wall, so a global search or a recovery settles on whatever place has no such beam (the "
             "demo's global start: 2.9 m off over 1-50 s, against 0.06 m)")
    if cfg.sensor.use:
        floor = _check_first_scans(scans, cfg.sensor, echo)
        if floor is not None:  # error codes taken as no returns (config.yaml says so: a repeat runs the same)
            cfg = dataclasses.replace(cfg, sensor=dataclasses.replace(cfg.sensor, range_min=floor))
    updates = _updates(scans, marks_all)
    plane_sensor = None
    if cfg.planes.use:
        from mcl.planes import PlaneSensor

        plane_sensor = PlaneSensor(cfg, grid, log.odometry, cfg.seed)
        updates = plane_sensor.attach(updates)
    load_time = time.perf_counter() - wall0
    solid = _solid_map_note(cfg, grid)  # once the start and the data checked out: an error stays one line
    if solid:
        echo(solid)
    if compile_note:  # `mcl run`: the data loaded, the filter's kernels are next (mcl.numba_cache)
        from mcl.numba_cache import cache_is_cold

        if cache_is_cold():
            echo("mcl: compiling kernels (once; cached for later runs)")

    pf = ParticleFilter(cfg, grid, landmark_map=landmark_map,
                        plane_model=plane_sensor.model if plane_sensor is not None else None)
    if pf.allowed is not None and not pf.allowed.any():  # map rejection with nowhere to stand
        widest = float(grid.distance[grid.free].max())
        raise ConfigError(f"motion.robot_radius: no cell of {grid.path} has {cfg.motion.robot_radius:g} m of "
                          f"clearance (the widest free space: {widest:.2f} m from the nearest obstacle)")
    if from_bag:  # the bag's /initialpose, covariance included
        mean0, cov0 = bag_initial
        if not np.any(cov0):  # no covariance given: filter.initial_std
            cov0 = np.diag(np.square(fc.initial_std))
        pf.init_gaussian_cov(mean0, cov0)
        echo(f"{cfg.bag}: tracking from {cfg.topics.initial_pose} ({mean0[0]:.3f}, {mean0[1]:.3f}, {mean0[2]:.3f})")
        mode = "tracking"
    elif fc.global_localization or fc.initial_pose is None:
        pf.init_global()
        mode = "global"
    else:
        pf.init_gaussian(fc.initial_pose, fc.initial_std)
        mode = "tracking"
    seed_from_landmarks = mode == "global" and landmark_map is not None  # at the first known landmark (Table 6.5)

    signals.defer()  # outputs from here on: a signal stops the loop only, and everything is closed
    out_dir = Path(out_dir)
    try:
        if fresh:  # a default folder (no --out): made new here, another run started in the same second takes the next
            out_dir = _fresh_dir(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        signals.lock_fd = _lock_out_dir(out_dir)  # released as run() returns
        previous = _set_aside(out_dir)
        atomic_write_text(out_dir / "config.yaml", dump_config(cfg))
    except OSError as e:
        raise DataError(f"{out_dir}: cannot write the run's outputs there: {e.strerror or e}") from None

    viz = None
    rrd_path = out_dir / "recording.rrd"
    if cfg.rerun.mode != "off":
        from mcl.viz import RerunLogger, particles_every_within, recording_floor_mb

        # the first scans tell the laser (a bag's scans are a stream: no slicing, and each pass reads the bag)
        beams = max((len(s.ranges) for s in itertools.islice(scans, 1000)), default=0)
        logged = min(cfg.rerun.particles_max, fc.particles)  # the cloud logged: at most the filter's (KLD's maximum)
        every = particles_every_within(cfg.rerun.budget_mb, len(updates), beams, logged,
                                       cfg.rerun.particles_every, cfg.rerun.scan)
        floor = recording_floor_mb(len(updates), beams, cfg.rerun.scan)
        if cfg.rerun.budget_mb > 0 and floor > cfg.rerun.budget_mb:
            # the estimates and scans alone are over: no thinning of the cloud keeps the budget; say so
            echo(f"mcl: warning: recording: the estimates and {beams}-beam scans of {len(updates)} scans alone take "
                 f"about {floor:.0f} MB, over rerun.budget_mb ({cfg.rerun.budget_mb:g} MB): the cloud is logged on the "
                 "first update only; rerun.scan: false or a larger budget")
        elif every > cfg.rerun.particles_every:
            echo(f"mcl: recording: the particle cloud on one update in {every}, to keep {len(updates)} scans near "
                 f"rerun.budget_mb ({cfg.rerun.budget_mb:g} MB)")
        viz = RerunLogger(
            cfg.rerun.mode,
            rrd_path,
            particles_max=cfg.rerun.particles_max,
            particles_every=every,
            log_scan=cfg.rerun.scan,
        )
        viz.log_map(grid)
        if viz.frame_note():  # a map far from (0, 0): the recording's own frame
            echo(viz.frame_note())
        if cfg.sensor.use:
            viz.log_likelihood_field(grid, cfg.sensor)
        if landmark_map is not None:
            from mcl.viz import log_landmark_map

            log_landmark_map(viz, landmark_map)
        if truth is not None:
            viz.log_truth_path(truth.poses, truth.t)
    recording = _UpdateRecording(viz, cfg, grid, truth, landmark_map, plane_sensor) if viz is not None else None

    stage_totals = {"predict": 0.0, "correct": 0.0, "estimate": 0.0, "resample": 0.0, "viz": 0.0}
    counts = {"updates": 0, "predicted": 0, "resamples": 0, "rejected": 0, "degenerate": 0}
    tries_sum = 0.0
    n_moved = 0
    spread_sum, spread_max, multimodal, skipped_beams = 0.0, 0.0, 0, 0
    n_used: list[int] = []  # particles weighted at each update (KLD sampling varies it)
    injected = 0
    reseeds = 0  # global re-seeds of lost recovery
    stall_reseeds = 0  # ... of them on a stalled estimate (filter.stall_*)
    fault_updates = 0  # updates whose motion allowed odometry faults (motion.fault_*)
    traj_t: list[float] = []
    traj_p: list[np.ndarray] = []
    interrupted = False
    failure = None  # the exception that stopped the loop, re-raised once the outputs are closed and summarised
    last_odom = None
    last_t = 0.0
    scan_t = None  # the previous scan's time, used or gated (Control.dt_scan)
    filled = False  # a scan since the last update had its odometry filled by scan matching (Control.filled)
    lasers: set = set()  # the scan sources (a bag's topics; a CARMEN log's one kind) seen to update so far
    left_out = getattr(log, "left_out_lasers", set())  # fused lasers whose mounting misfits (_check_odometry)
    turned = getattr(log, "turned_lasers", {})  # lasers mounted at the yaw their scans fit (_check_odometry)
    owed: set = set()  # ... that have not updated since the robot last moved (AMCL's lasers_update_ flags)
    writer = TumWriter(out_dir / "trajectory.tum")
    bag_out = _estimate_bag(cfg, out_dir, log) if write_bag else None
    if bag_out is not None:
        rivals = [p for p, c in log.tf_links if c == bag_out.odom_frame]
        if rivals:  # a localizer ran while the bag was recorded: its map -> odom is in the bag too
            echo(f"{cfg.bag}: {log.tf_topic} already holds {', '.join(f'{p} -> {bag_out.odom_frame}' for p in rivals)} "
                 f"(a localizer's, recorded): played beside {bag_out.out.path.name}, "
                 f"RViz receives two parents of {bag_out.odom_frame} and shows each in turn")
    quality_out = LineWriter(out_dir / "quality.csv", header=QUALITY_HEADER)
    quality_rows: list[tuple] = []  # (match, contradiction, lost) of each filter update, for the summary
    last_mean, last_lost, last_spread = None, False, math.nan
    if kidnap_filter_at is None and cfg.eval.kidnap_at is not None:
        kidnap_filter_at = (float(cfg.eval.kidnap_at), float(cfg.eval.kidnap_m))
    kidnap = None  # kidnap_filter_at: what was done
    bar = tqdm(total=len(updates), unit="scan", disable=(None if progress is None else not progress), leave=False, dynamic_ncols=True)
    loop0 = time.perf_counter()
    # the filter's tables, the search's, the recording's map: 23 of the 50 s before the first update on a 208 M-cell
    # map, which "load" + "loop" left out
    setup_time = loop0 - wall0 - load_time
    try:
        with signals.live():
            for scan, marks in updates:  # scan is marks: an update from a LANDMARK line alone
                bar.update(1)
                odom = scan.odom
                laser = scan.kind if isinstance(scan, Scan) else None  # which laser (None: landmarks, depth)
                filled = filled or getattr(scan, "filled", False)
                if last_odom is not None:
                    d = math.hypot(odom[0] - last_odom[0], odom[1] - last_odom[1])
                    a = abs(float(wrap_angle(odom[2] - last_odom[2])))
                    still = d < fc.update_min_d and a < fc.update_min_a
                    if not still:
                        owed = set(lasers)
                    # Each laser updates once after the robot moved, as AMCL's flags do: fused front and rear
                    # lasers both weigh in (the second, at the first's pose, would otherwise always be gated).
                    if (still and (laser is None or laser in lasers) and laser not in owed) or laser in left_out:
                        # Update gating (and a laser left out, sensor.misfit_laser): no filter update, but the
                        # trajectory still gets this scan's pose, the last estimate moved by the odometry since that
                        # update (one pose per scan).
                        pose = compose(last_mean, compose(inverse(last_odom), odom))
                        scan_t = scan.t
                        with signals.held():
                            writer.append(scan.t, pose[0], pose[1], pose[2])
                            quality_out.write_line(_quality_line(scan.t, False, None, last_lost, pf.n, last_spread))
                            traj_t.append(scan.t)
                            traj_p.append(pose)
                            counts["predicted"] += 1
                        continue
                laser_pose = (
                    np.asarray(cfg.sensor.laser_pose)
                    if cfg.sensor.laser_pose is not None
                    else (getattr(scan, "laser_offset", None) if getattr(scan, "laser_offset", None) is not None else np.zeros(3))
                )
                if laser in turned:  # sensor.mount_yaw: fit (_check_odometry): the yaw the scans fit best
                    laser_pose = compose(laser_pose, np.array([0.0, 0.0, turned[laser]]))
                frame = plane_sensor.frame_of(scan) if plane_sensor is not None else None
                no_scan = scan is marks or scan is frame  # an update from a LANDMARK line or a depth frame alone
                # None when unusable (or a laser left out: its first scan, before any update, only starts the filter)
                observation = pf.prepare(scan, laser_pose) if not no_scan and laser not in left_out else None
                planes = plane_sensor.observe(frame) if frame is not None else None
                control = None
                if last_odom is not None:
                    dt = scan.t - last_t
                    if not dt >= 0.0:  # time ran backwards (intel_lab: 4 times by < 1 s): counted, dt taken as 0
                        pf.time_backwards(dt)
                        dt = 0.0
                    v, w = scan.tv, scan.rv
                    if v == 0.0 and w == 0.0:  # no velocities in the log: from the odometry pair
                        v, w, dt = velocities_from_odometry(last_odom, odom, dt)
                    control = Control(last_odom, odom, dt=dt, v=v, w=w,
                                      dt_scan=scan.t - scan_t if scan_t is not None else None, filled=filled)
                if seed_from_landmarks and not pf.search.tempering:
                    # the laser settled the search first: its cloud stays (a late landmark observation, a false
                    # positive, re-drew a localized set 4 m off)
                    seed_from_landmarks = False
                if seed_from_landmarks and marks is not None and pf.init_from_landmarks(marks):
                    seed_from_landmarks, control = False, None  # particles drawn for this very time
                if kidnap_filter_at is not None and kidnap is None and scan.t >= kidnap_filter_at[0]:
                    kidnap = _kidnap(pf, truth, scan.t, last_mean, kidnap_filter_at[1])
                info = pf.step(control, observation, landmarks=marks, planes=planes)
                if laser is not None:
                    lasers.add(laser)
                    owed.discard(laser)
                if on_update is not None:
                    on_update(scan.t, pf, info, truth.at(scan.t) if truth is not None else None)
                last_odom, last_t, scan_t, filled = odom, scan.t, scan.t, False
                mean, cov = info.mean, info.cov
                spread_full = _spread(info.full_cov)
                last_mean, last_lost, last_spread = mean, info.lost, spread_full
                with signals.held():  # the pose in the file <=> counted in the summary <=> in the recording
                    writer.append(scan.t, mean[0], mean[1], mean[2])
                    quality_out.write_line(_quality_line(scan.t, True, info.fit, info.lost, info.particles,
                                                         spread_full))
                    traj_t.append(scan.t)
                    traj_p.append(mean)
                    counts["updates"] += 1
                    if info.fit is not None and info.fit.beams:
                        quality_rows.append((info.fit.match, info.fit.contradiction, info.lost))
                    if bag_out is not None:
                        bag_out.update(scan.t, mean, cov, odom, pf.particles)
                    counts["resamples"] += int(info.resampled)
                    counts["rejected"] += info.rejected
                    counts["degenerate"] += int(info.degenerate)
                    spread_sum += spread_full
                    spread_max = max(spread_max, spread_full)
                    multimodal += int(info.clusters > 1)
                    skipped_beams += info.skipped_beams
                    tries_sum += info.tries
                    n_moved += info.tries > 0.0  # an update with a prediction (the first has none)
                    n_used.append(info.particles)
                    injected += info.injected
                    reseeds += int(info.reseeded)
                    stall_reseeds += int(info.reseeded and info.stalled)
                    fault_updates += int(info.faults)
                    for k, v in info.timings.items():
                        stage_totals[k] += v
                    if recording is not None:
                        tv = time.perf_counter()
                        recording.update(counts["updates"] - 1, scan, no_scan, pf, info, odom, laser_pose, marks,
                                         planes)
                        stage_totals["viz"] += time.perf_counter() - tv
    except KeyboardInterrupt:
        interrupted = True
    except Exception as e:  # an input found bad mid-run: the poses so far are kept, the summary says why it stopped
        failure = e
    finally:
        bar.close()
        # each output is closed whatever another's close raised (a full disk): what could be written is kept
        for out_file in (writer, quality_out, bag_out, viz):
            if out_file is None:
                continue
            try:
                out_file.close()
            except (OSError, RuntimeError) as e:
                failure = failure if failure is not None else e
    loop_time = time.perf_counter() - loop0
    interrupted = interrupted or signals.caught  # also a signal while the outputs were closed

    n_up = max(counts["updates"], 1)
    # motion.stalls: fill, motion.jumps: match and motion.slips: match (mcl.odomstall): the holds, jumps and slips
    # it filled
    stalls = getattr(scans, "stalls", None) or []
    holds = [w for w in stalls if w.cause in ("hold", "hold+jump")]
    if holds:
        longest = max(holds, key=lambda w: w.t1 - w.t0)
        echo(f"mcl: warning: {log.path}: the odometry held its pose {len(holds)} time{'s' if len(holds) > 1 else ''} "
             f"while the scans showed the robot moving (the longest {longest.t1 - longest.t0:.1f} s from "
             f"t={longest.t0:.3f} s: {longest.matched:.2f} m by scan matching, {longest.odometry:.2f} m by the "
             "odometry): the motion there is the scans' (motion.stalls: keep leaves it as it was)")
    jumps = [w for w in stalls if w.cause in ("jump", "hold+jump")]
    if jumps:
        first = jumps[0]
        echo(f"mcl: warning: {log.path}: the odometry jumped {len(jumps)} time{'s' if len(jumps) > 1 else ''} (the "
             f"first at t={first.t1:.3f} s: {first.odometry:.2f} m by the odometry, {first.matched:.2f} m by scan "
             "matching; a driver that restarted, a glitch): the step there is the scans', and the odometry goes on "
             "from it (motion.jumps: hedge leaves it to the filter)")
    slips = [w for w in stalls if w.cause == "slip"]
    if slips:
        first = slips[0]
        echo(f"mcl: warning: {log.path}: the odometry turned more than the scans {len(slips)} "
             f"time{'s' if len(slips) > 1 else ''} (the first at t={first.t1:.3f} s: "
             f"{math.degrees(first.odometry_turn):.0f} degrees by the odometry, {math.degrees(first.matched_turn):.0f}"
             " by scan matching; a wheel that slips): the step there is the scans', and the odometry goes on from it "
             "(motion.slips: keep leaves it as it was)")
    summary: dict = {
        "mode": mode,
        "interrupted": interrupted,
        **({"error": f"stopped after {counts['updates']} updates: {_failure_text(failure)}"}
           if failure is not None else {}),
        "map": cfg.map,
        "log": cfg.log,
        "bag": cfg.bag,
        # what the run was scored against: a file, or a bag's topic (`--truth-topic`: cfg.truth is null then)
        "truth": cfg.truth or (f"{cfg.bag}: {cfg.topics.truth}" if cfg.bag is not None and truth is not None else None),
        "seed": cfg.seed,
        "scans": len(scans),
        "landmark_lines": len(marks_all),
        "updates": counts["updates"],
        "predicted_poses": counts["predicted"],
        "particles": pf.n,
        "particles_mean": float(np.mean(n_used)) if n_used else float(pf.n),
        "particles_min": int(min(n_used)) if n_used else pf.n,
        "particles_max": int(max(n_used)) if n_used else pf.n,
        "injected_particles": injected,
        "reseeds": reseeds,
        "stall_reseeds": stall_reseeds,
        "fault_updates": fault_updates,
        "blind_updates": pf.blind_updates,
        "floor_tempered_updates": pf.floor_tempered,
        **({"odometry_scale": pf.odom_scale.k} if pf.odom_scale is not None else {}),  # motion.scale_window's last
        **({"sweep_order": pf.sweep_order.summary()}
           if pf.sweep_order is not None and pf.sweep_order.scans else {}),
        **({"self_hits": summary_of(scans.self_hits)} if getattr(scans, "self_hits", None) else {}),
        **({"odometry_stalls": [w.summary() for w in stalls]} if stalls else {}),
        **({"odometry_check": odometry_summary(log.odometry_checks)} if getattr(log, "odometry_checks", None)
           else {}),
        **({"left_out_lasers": sorted(left_out)} if left_out else {}),
        **({"mount_yaw_fitted_deg": {k: round(math.degrees(v), 2) for k, v in sorted(turned.items())}} if turned
           else {}),
        **({"stamp_offset_fitted_s": round(log.stamp_offset, 4)} if getattr(log, "stamp_offset", None) is not None
           else {}),
        "motion_model": cfg.motion.model,  # as run: motion.sideways may have chosen omni
        **({"odometry_sideways": round(sideways, 4)} if sideways is not None else {}),
        **({"time_offset_check": time_summary(log.time_offset_checks)} if getattr(log, "time_offset_checks", None)
           else {}),
        "resamples": counts["resamples"],
        "mean_tries": tries_sum / max(n_moved, 1),  # over the updates that predicted: at least 1 when any did
        "rejected_particles": counts["rejected"],
        "degenerate_updates": counts["degenerate"],
        "events": dict(pf.events),
        "spread": {
            "full_mean_m": spread_sum / n_up,
            "full_max_m": spread_max,
            "multimodal_updates": multimodal,
        },
        "skipped_beams": skipped_beams,
        "quality": _quality_summary(quality_rows),
        **({"planes": plane_sensor.summary()} if plane_sensor is not None else {}),
        "skipped_messages": dict(log.skipped),
        "recording_particles_every": viz.particles_every if viz is not None else None,  # rerun.budget_mb may raise it
        "platform": numeric_platform(),  # the same seed on other numpy SIMD paths can give another trajectory
        "wall_time_s": {"load": load_time, "setup": setup_time, "loop": loop_time, **stage_totals},
        "ms_per_update": {k: 1e3 * v / n_up for k, v in stage_totals.items()},
        "outputs": {
            "trajectory": str(out_dir / "trajectory.tum"),
            "recording": str(viz.path) if (viz is not None and viz.path is not None and Path(viz.path).exists()) else None,
            "config": str(out_dir / "config.yaml"),
            "quality": str(out_dir / "quality.csv"),
            "bag": str(bag_out.out.path) if bag_out is not None else None,
        },
    }
    if kidnap is not None:
        summary["kidnap"] = kidnap
    if truth is not None and traj_t:
        from mcl.evaluate import time_warnings

        # a log whose scans repeat a stamp has two poses at it, each paired by time with the reference's: said, as
        # mcl eval says it (the run scored such a log 0.62 m where each pose was 0.08 m off, without a word)
        for kind, said in time_warnings(out_dir / "trajectory.tum", np.array(traj_t), np.array(traj_p).T):
            if kind == "twice":  # (a log whose clock steps back is said when it is read)
                echo(f"mcl: warning: {said}")
        try:
            summary["eval"] = evaluate(
                np.array(traj_t), np.array(traj_p).T, truth.t_given, truth.poses_given,
                converged_within=cfg.eval.converged_within
            )
        except DataError as e:
            summary["eval"] = {"error": str(e)}
    try:
        atomic_write_text(out_dir / "summary.json", summary_json(summary) + "\n")
    except OSError:
        if failure is None:
            raise
    kept = None  # the folder's earlier finished run, put back because this one did not finish
    if previous is not None:
        try:
            if failure is None and not interrupted:
                import shutil

                shutil.rmtree(previous)
            else:
                _put_back(out_dir, previous)
                kept = f"the earlier finished run in {out_dir} is kept (this run's outputs were discarded)"
                summary["outputs"] = {k: None for k in summary["outputs"]}
        except OSError as e:
            failure = failure if failure is not None else e
    if failure is not None:  # one error line from the caller; the folder holds the poses up to it, and says so
        if isinstance(failure, OSError):  # an output mcl could not write: named, with what is kept
            raise DataError(f"{_failure_text(failure, out_dir)} (stopped after {counts['updates']} updates; "
                            f"{kept or f'the poses written so far are in {out_dir}'})") from None
        if isinstance(failure, MclError):
            raise type(failure)(f"{failure} (stopped after {counts['updates']} updates; "
                                f"{kept or f'the poses so far and a summary.json that says so are in {out_dir}'})"
                                ) from None
        raise failure

    # The one-paragraph summary.
    ms = summary["ms_per_update"]
    text = (
        f"{'Interrupted after' if interrupted else 'Localized'} {counts['updates']} updates"
        + (f" of {len(scans)} scans" if len(scans) else "")  # none: landmarks or depth frames alone
        + f" ({mode}, {_particles_text(summary)}) in {loop_time:.1f} s: "
        f"{ms['predict']:.1f} ms predict (mean {summary['mean_tries']:.2f} tries), {ms['correct']:.1f} ms correct, "
        f"{ms['resample']:.1f} ms resample, {ms['viz']:.1f} ms rerun per update."
    )
    q = summary["quality"]
    if q.get("lost_updates"):  # the one sign a run without a reference gives that it lost the robot
        text += (f" Believed lost in {q['lost_updates']} of {q['updates']} updates ({q['lost_episodes']} episode"
                 f"{'s' if q['lost_episodes'] != 1 else ''}{', lost at the end' if q['lost_at_end'] else ''}"
                 f"{', a global search the first' if summary['mode'] == 'global' else ''}; quality.csv).")
    if "eval" in summary and "ate_rmse" in summary["eval"]:
        text += " " + format_eval(summary["eval"]) + "."
    elif "eval" in summary and "error" in summary["eval"]:
        text += f" Not scored: {summary['eval']['error']}."
    text += f" Outputs in {out_dir}." if kept is None else f" As it was interrupted, {kept}."
    if summary["outputs"]["recording"]:
        import shutil

        from mcl.viz import viewer_executable

        # `rerun` when it is on PATH, else the viewer beside this Python (a venv used without activating it)
        viewer = "rerun" if shutil.which("rerun") else (viewer_executable() or "rerun")
        text += f" Open the recording with: {viewer} {summary['outputs']['recording']}"
    summary["text"] = text
    echo(text)
    return summary
