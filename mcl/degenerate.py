"""Degenerate input: what the filter does with data it cannot use as given.

Degenerate input never puts a NaN into the particles. Each kind warns once
(``MclWarning``, a ``RuntimeWarning``) and is counted in ``InputGuard.events`` (summary.json
``events``):

* ``nan_ranges``: a scan with NaN or infinite readings (those beams are dropped);
* ``empty_scans``: a scan with no usable reading (zero beams, or none finite
  and positive): the update only predicts;
* ``time_backwards``: a control with dt < 0 (or not finite): dt is taken as 0;
  the odometry step itself is still applied (the odometry model does not use dt);
* ``odometry_jumps``: an odometry step longer than ``filter.max_odom_step`` and
  than ``filter.max_odom_ratio`` times the longest of the last ``JUMP_HISTORY``
  steps taken, or not finite. A long step may be a glitch or real motion: logs
  with a scan every metre of travel make steps of 2-4 m at their turns
  (Radish's orebro), hence the relative bound. A longer step is still motion
  when its speed since the last scan is at most ``filter.max_odom_speed``
  or ``max_odom_ratio`` times the fastest of the last steps' (a laser silent
  for seconds: the next scan comes metres on at the robot's speed; a glitch
  moves metres in a scan period). A step longer than ``filter.max_odom_step``
  that ends within ``RESTART_M`` of the odometry's origin is a jump whatever
  its speed and the recent steps: a base driver that restarted from 0 0 0 while
  the scans were seconds apart (a sparse log) steps as slowly as a drive.
  Else the filter hedges: every other particle takes the step (the motion
  model's noise grows with it), the others are re-spread by
  ``filter.respread_std`` where they were (poses off
  the allowed map are drawn again), and the scan decides. Non-finite odometry
  is only re-spread. With ``motion.jumps: match`` a jump faster than 5 m/s, or
  one the scans do not overlap at (a driver that restarted from 0 0 0), is
  taken from scan matching before the filter sees it (``mcl.odomstall``);
* ``degenerate_weights``: every weight is zero after the correction (no pose
  explains the scan): the filter re-spreads the particles around the last
  estimate moved by the odometry step, twice wider each consecutive time, and
  reinitialises globally after three consecutive failures (``ParticleFilter``).
"""

from __future__ import annotations

import collections
import dataclasses
import math
import warnings

import numpy as np

from mcl.errors import MclWarning
from mcl.estimate import wrap_angle

EVENT_KINDS = ("degenerate_weights", "nan_ranges", "odometry_jumps", "time_backwards", "empty_scans")


class InputGuard:
    """Checks scans and controls before the filter uses them; counts and warns once per kind."""

    JUMP_HISTORY = 20  # odometry steps taken whose longest sets the relative jump bound

    MIN_SPEED_DT = 0.02  # s: a step over less time has no speed to go by (stamps equal or a few ms apart)

    # m: a long step that ends this near the odometry's origin is a restart from 0 0 0 (the reading after it holds the
    # motion since; 0.5 m is a second and more at an indoor robot's speed), whatever its speed. A drive that returns so
    # near its odometry's start over a scan gap is hedged instead of taken, and the scan decides
    RESTART_M = 0.5

    def __init__(self, max_odom_step: float, max_odom_ratio: float = 0.0, max_odom_speed: float = 0.0):
        self.max_odom_step = float(max_odom_step)
        self.max_odom_ratio = float(max_odom_ratio)
        self.max_odom_speed = float(max_odom_speed)
        self._steps: collections.deque[float] = collections.deque(maxlen=self.JUMP_HISTORY)
        self._speeds: collections.deque[float] = collections.deque(maxlen=self.JUMP_HISTORY)
        self.events = dict.fromkeys(EVENT_KINDS, 0)
        self._warned: set[str] = set()
        self._step: list[str] = []  # kinds seen in the current update

    def event(self, kind: str, message: str) -> None:
        """Count one event; warn the first time of each kind."""
        self.events[kind] += 1
        self._step.append(kind)
        if kind not in self._warned:
            self._warned.add(kind)
            warnings.warn(f"{message} (warned once; summary.json counts every {kind} event)", MclWarning,
                          stacklevel=4)

    def take_step_events(self) -> tuple[str, ...]:
        """The kinds seen since the last call (one update's events)."""
        out, self._step = tuple(self._step), []
        return out

    def usable_scan(self, scan) -> bool:
        """Whether ``scan`` has a usable reading; counts ``nan_ranges`` and ``empty_scans``."""
        r = np.asarray(scan.ranges, dtype=np.float64)
        finite = np.isfinite(r)
        if not finite.all():
            self.event("nan_ranges", f"a scan at t={scan.t} has NaN or infinite ranges; those beams are ignored")
        if not np.any(finite & (r > 0.0)):
            self.event("empty_scans", f"a scan at t={scan.t} has no usable reading; the update only predicts")
            return False
        return True

    def time_backwards(self, dt: float) -> None:
        """Count (and warn once about) time running backwards between updates, dt < 0 or not finite."""
        self.event("time_backwards", f"time ran backwards (dt = {dt:.3f} s); dt taken as 0, the odometry step "
                   "still applied")

    def jump_bound(self) -> float:
        """m: the longest odometry step taken as motion now: max(max_odom_step, max_odom_ratio * the longest of
        the last JUMP_HISTORY steps taken)."""
        if self.max_odom_ratio <= 0.0 or not self._steps:
            return self.max_odom_step
        return max(self.max_odom_step, self.max_odom_ratio * max(self._steps))

    def speed_bound(self) -> float:
        """m/s: the fastest a step longer than ``jump_bound`` may be and still be taken as motion: max(max_odom_speed,
        max_odom_ratio * the fastest of the last JUMP_HISTORY steps taken); 0 when max_odom_speed is 0 (off)."""
        if self.max_odom_speed <= 0.0:
            return 0.0
        recent = self.max_odom_ratio * max(self._speeds) if self._speeds else 0.0
        return max(self.max_odom_speed, recent)

    def at_origin(self, pose) -> bool:
        """Whether the odometry ``pose`` lies within ``RESTART_M`` of its origin (where a restart leaves it)."""
        return math.hypot(float(pose[0]), float(pose[1])) <= self.RESTART_M

    def observe(self, step: float, dt: float, end) -> bool:
        """Whether an odometry step of ``step`` m over ``dt`` s is a jump: longer than ``jump_bound`` and, when it is
        timed (dt at least MIN_SPEED_DT), faster than ``speed_bound``; or longer than ``max_odom_step`` and ending
        (``end``, the odometry pose it reaches) within ``RESTART_M`` of the odometry's origin (a restart:
        a sparse log's steps make ``jump_bound`` metres long). A step within ``jump_bound`` joins the
        histories; a longer one at the robot's speed is motion (the scans stopped for a while) but stays out of them:
        the next steps are measured against the scans' own, not against the gap's."""
        timed = dt >= self.MIN_SPEED_DT
        if step > self.max_odom_step and self.at_origin(end):
            return True  # a restart from 0 0 0, however long the recent steps were
        if step > self.jump_bound():
            return not (timed and step <= self.speed_bound() * dt)
        self._steps.append(step)
        if timed:
            self._speeds.append(step / dt)
        return False

    def check_control(self, control):
        """(control to apply, odometry step in the robot frame (3,)): dt < 0 made 0; (control, None) for an
        odometry jump (a glitch or real motion: the filter hedges), (None, None) for non-finite odometry."""
        a = np.asarray(control.odom_prev, dtype=np.float64)[:3]
        b = np.asarray(control.odom_now, dtype=np.float64)[:3]
        if not (np.isfinite(a).all() and np.isfinite(b).all()):
            self.event("odometry_jumps", "odometry is not finite; the step is not applied, the particles are re-spread")
            return None, None
        if not control.dt >= 0.0:
            self.time_backwards(control.dt)
            control = dataclasses.replace(control, dt=0.0)
        step = math.hypot(b[0] - a[0], b[1] - a[1])
        bound = self.jump_bound()
        dt = float(control.dt if control.dt_scan is None else control.dt_scan)
        if self.observe(step, dt, b):
            if self.at_origin(b):
                speed = f"; to within {self.RESTART_M} m of the odometry's origin, a restart from 0 0 0"
            elif dt >= self.MIN_SPEED_DT and self.max_odom_speed > 0.0:
                speed = (f"; {step / dt:.2f} m/s over {dt:.2f} s, faster than filter.max_odom_speed "
                         f"{self.max_odom_speed} m/s and max_odom_ratio times the fastest recent step")
            else:
                speed = ""
            self.event("odometry_jumps", f"odometry jumped {step:.2f} m in one update (> {bound:.2f} m: "
                       f"filter.max_odom_step {self.max_odom_step} m, or max_odom_ratio {self.max_odom_ratio} "
                       f"times the longest recent step{speed}): a glitch or real motion; half the particles take "
                       "the step, the others are re-spread where they were, and the scan decides")
            return control, None
        c, s = math.cos(a[2]), math.sin(a[2])
        dx, dy = b[0] - a[0], b[1] - a[1]
        return control, np.array([c * dx + s * dy, -s * dx + c * dy, float(wrap_angle(b[2] - a[2]))])


class ZeroWeights:
    """``degenerate_weights``: what the filter does after a correction that left every weight zero. Re-spread
    around the last estimate (moved by the odometry step) with ``respread_std`` times 2^(k-1) on the k-th such
    update in a row; after ``MAX_RUN`` in a row (``respread`` returns None) reinitialise globally. A scan no pose
    explains is far more often a bad scan or a short glitch than a kidnapping (recovery handles that), and a
    global reinitialisation throws away a good track."""

    MAX_RUN = 3  # consecutive all-zero updates before a global reinitialisation

    def __init__(self, respread_std):
        self.std = np.asarray(respread_std, dtype=np.float64)
        self.run = 0  # consecutive updates where every weight was zero

    def respread(self) -> np.ndarray | None:
        """Another all-zero update: the std (x, y, theta) to re-spread with, or None to reinitialise globally
        (the run then starts again)."""
        self.run += 1
        if self.run > self.MAX_RUN:
            self.run = 0
            return None
        return self.std * 2.0 ** (self.run - 1)

    def ok(self) -> None:
        """An update with weight: the run ends."""
        self.run = 0
