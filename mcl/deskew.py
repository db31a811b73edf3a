"""Deskewing a spinning laser's scan (``sensor.sweep_time``).

A spinning laser takes its beams one after the other: an RPLidar or a TurtleBot's LDS 0.1-0.2 s a turn. While the
robot turns, the last beams look from a heading 0.1-0.3 rad on from the first, and a wall bends. Each beam's
endpoint is moved into the robot frame at the scan's stamp by the robot's motion since then
(``mcl.sensors.beam_endpoints``): the odometry over the sweep gives a velocity (vx, vy, omega) in the robot frame,
and beam j, taken tau_j after the stamp, is moved by (vx tau_j, vy tau_j, omega tau_j) (first order).

Which way the beams run in time is not always what the data says: ``rplidar_ros`` writes its beams against time
(``ranges[node_count-1-i]``) with a positive ``time_increment``. Deskewed the wrong way, the shear doubles.
:class:`SweepOrder` decides it from the scans themselves: until it has, the filter uses each scan as read (as if
every beam were taken at the stamp) and weighs three readings (as stamped, reversed, all at once: a driver that
deskews by itself) by the particle set's marginal likelihood of the scan, summed over the updates (a Bayes
factor); once one leads the others by ``DECIDE_NATS`` it is used from then on.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

DECIDE_NATS = 30.0  # log Bayes factor at which the beams' timing is decided (one scan moved it by 22 at most)


class Deskewed:
    """The scans of a sized iterable, each with the robot's velocity over its sweep (``Scan.twist``, robot frame at
    the stamp) from ``odometry`` (rows t, x, y, theta, tv, rv), so that the sensor model can move each beam's
    endpoint to where it would be had the beam been taken at the stamp (``mcl.sensors.beam_endpoints``).
    ``sweep``: "auto" keeps each scan's own beam times (a bag's time_increment), a number of seconds sets beam j of
    n at j / (n - 1) * sweep after the stamp. Lazy, so a bag's scans still stream."""

    def __init__(self, scans, odometry: np.ndarray, sweep) -> None:
        from mcl.datasets.rosbag import odometry_at

        self.scans, self.sweep, self.at = scans, sweep, odometry_at
        self.odometry = odometry[np.argsort(odometry[:, 0], kind="stable")]

    def __len__(self) -> int:
        return len(self.scans)

    def __iter__(self):
        return (self._twisted(s) for s in self.scans)

    def _twisted(self, s):
        from mcl.estimate import compose, inverse

        n = np.asarray(s.ranges).shape[0]
        t0, dt = (s.beam_t0, s.beam_dt) if self.sweep == "auto" else (0.0, float(self.sweep) / max(n - 1, 1))
        if dt == 0.0 or n < 2:
            return s
        ta, tb = s.t + min(t0, t0 + dt * (n - 1)), s.t + max(t0, t0 + dt * (n - 1))
        a, b = self.at(self.odometry, ta)[0], self.at(self.odometry, tb)[0]
        d = compose(inverse(a), b)  # the robot's motion over the sweep, in its frame at its start
        return dataclasses.replace(s, beam_t0=t0, beam_dt=dt, twist=d / (tb - ta))


def deskew(scans, log, sweep, echo, timed: bool):
    """``scans`` with the robot's velocity over each sweep (:class:`Deskewed`) when ``sensor.sweep_time`` asks for
    it and the input (``timed``: a bag) may say when its beams were taken; else as they are."""
    if sweep == 0 or not len(scans):
        return scans
    if sweep == "auto" and not timed:  # a CARMEN log does not say when its beams were taken
        return scans
    odometry = np.asarray(log.odometry, dtype=np.float64).reshape(-1, 6)
    if odometry.shape[0] < 2:
        odometry = np.array([(s.t, *s.odom, s.tv, s.rv) for s in scans], dtype=np.float64).reshape(-1, 6)
    if sweep != "auto":
        echo(f"{log.path}: sensor.sweep_time {float(sweep):g} s: each scan deskewed by the odometry's motion over it "
             "(which way its beams run in time is found from the scans)")
    else:
        swept = {t: v for t, v in getattr(log, "sweeps", {}).items() if v}
        if not swept:
            return scans  # no LaserScan says when its beams were taken
        said = ", ".join(f"{t} {v:.3g} s" for t, v in swept.items())
        echo(f"{log.path}: a laser sweep takes {said} (LaserScan time_increment): each scan deskewed by the "
             "odometry's motion over it (which way its beams run in time is found from the scans; "
             "sensor.sweep_time: 0 turns it off)")
    return Deskewed(scans, odometry, sweep)


def reversed_in_time(scan):
    """``scan`` with its beams' times the other way round: the last beam at the first one's time."""
    n = np.asarray(scan.ranges).shape[0]
    return dataclasses.replace(scan, beam_t0=scan.beam_t0 + scan.beam_dt * (n - 1), beam_dt=-scan.beam_dt)


class SweepOrder:
    """When a deskewed scan's beams were taken, decided by the scans (module doc): as stamped (+1), the other way
    round (-1), or all at once (0: a driver that deskews its scans itself, or a time_increment that is wrong).

    ``choose(scan)`` gives the scan the filter uses and, while undecided, the three readings to weigh;
    ``weigh(ev)`` adds one update's log evidence of each, ev[k] = log sum_i w_i p(z | x_i, reading k) with the
    particle set's prior weights w_i (a tracked set only: a search's spread set weighs places, not readings). The
    reading whose summed evidence leads the next by ``decide_nats`` is used from then on.
    """

    ORDERS = (1, 0, -1)
    NAMES = {1: "as stamped", 0: "all at once", -1: "reversed", None: "undecided"}

    def __init__(self, decide_nats: float = DECIDE_NATS) -> None:
        self.decide_nats = float(decide_nats)
        self.evidence = np.zeros(3)  # summed log evidence of ORDERS
        self.order: int | None = None
        self.weighed = 0  # updates that weighed the readings
        self.decided_at: int | None = None  # ... how many when it was decided

    def choose(self, scan):
        """(the scan to use, the three readings (as stamped, at once, reversed) to weigh, or None once decided)."""
        at_once = dataclasses.replace(scan, twist=None)
        if self.order is None:
            return at_once, (scan, at_once, reversed_in_time(scan))
        if self.order == 0:
            return at_once, None
        return (scan if self.order > 0 else reversed_in_time(scan)), None

    def weigh(self, ev) -> None:
        ev = np.asarray(ev, dtype=np.float64)
        if self.order is not None or not np.isfinite(ev).all():
            return
        self.evidence += ev - ev.max()
        self.weighed += 1
        first, second = np.sort(self.evidence)[::-1][:2]
        if first - second >= self.decide_nats:
            self.order = self.ORDERS[int(np.argmax(self.evidence))]
            self.decided_at = self.weighed

    def summary(self) -> dict:
        lead = self.evidence - self.evidence.max()
        return {"order": self.NAMES[self.order], "updates_weighed": self.weighed, "decided_after": self.decided_at,
                "log_evidence": {self.NAMES[o]: round(float(v), 3) for o, v in zip(self.ORDERS, lead)}}


def log_marginal(logw: np.ndarray, loglik: np.ndarray) -> float:
    """log sum_i exp(logw_i + loglik_i), -inf when every term is."""
    a = logw + loglik
    m = np.max(a) if a.size else -np.inf
    if not np.isfinite(m):
        return -math.inf
    return float(m + np.log(np.sum(np.exp(a - m))))
