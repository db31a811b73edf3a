"""Deskewing a spinning laser's scan (``sensor.sweep_time``).

A spinning laser takes its beams one after the other: an RPLidar or a TurtleBot's LDS 0.1-0.2 s a turn. While the
robot turns, the last beams look from a heading 0.1-0.3 rad on from the first, and a wall bends. Each beam's
endpoint is moved into the robot frame at the scan's stamp by the robot's motion since then
(``mcl.sensors.beam_endpoints``): the odometry over the sweep gives a velocity (vx, vy, omega) in the robot frame,
and beam j, taken tau_j after the stamp, is moved by (vx tau_j, vy tau_j, omega tau_j) (first order).

Which way the beams run in time is not always what the data says: ``rplidar_ros`` and the TurtleBot's LDS driver
write their beams against time (``ranges[node_count-1-i]``, ``ranges[359-index]``) with a positive
``time_increment``. Deskewed the wrong way, the shear doubles.
:class:`SweepOrder` decides it from the scans themselves: until it has, the filter uses each scan as read (as if
every beam were taken at the stamp) and, on scans taken while the robot turns (``MIN_TURN``), weighs three readings
(as stamped, reversed, all at once: a driver that deskews by itself) each at its own best pose: scan-matched to
the map from the estimate, by the laser log-likelihood there, summed over the updates (a profile likelihood
ratio); once one leads the others by ``DECIDE_NATS`` it is used from then on. (Weighed at the particles, "all at
once" wins: the set was corrected with it.) The reversed reading is centred on the stamp (``reversed_in_time``).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from mcl.datasets import ScanMap

# s of odometry before and after a sweep that its velocity is averaged over: an odometry pose's noise between two
# ticks 0.1 s apart is a velocity error as large as the turn (generated drives: alphas 0.05 in the variance form);
# at the truth, the deskewed scans fit the map better with 0.2 on the four spinning-lidar worlds than with 0
# (a 12 m laser in a corridor: worse than not deskewing at all with 0)
TWIST_MARGIN = 0.2
# rad the robot must turn over a sweep for the scan to weigh the readings: driving straight, the three differ by
# the translation over the sweep only, a few centimetres along the robot's heading, which the map's fit cannot
# tell from the estimate's own error (a 12 m laser in a 120 m corridor: "reversed" led by 100 nats after 17 s of
# straight driving, and "as stamped" won at the first turn); 0.02 and 0.04 decided the six drives measured alike
MIN_TURN = 0.04
DECIDE_NATS = 20.0  # summed log-likelihood lead that decides the timing (a wrong reading led by 0.6 at most)


def deskewed(s, odometry: np.ndarray, sweep):
    """Scan ``s`` with the robot's velocity over its sweep (``Scan.twist``, robot frame at the stamp; averaged over
    the sweep and ``TWIST_MARGIN`` s either side) from ``odometry`` (rows t, x, y, theta, tv, rv, time-sorted), so
    that the sensor model can move each beam's endpoint to where it would be had the beam been taken at the stamp
    (``mcl.sensors.beam_endpoints``).
    ``sweep``: "auto" keeps the scan's own beam times (a bag's time_increment), a number of seconds sets beam j of
    n at j / (n - 1) * sweep after the stamp."""
    from mcl.datasets.rosbag import odometry_at
    from mcl.estimate import compose, inverse

    n = np.asarray(s.ranges).shape[0]
    t0, dt = (s.beam_t0, s.beam_dt) if sweep == "auto" else (0.0, float(sweep) / max(n - 1, 1))
    if dt == 0.0 or n < 2:
        return s
    ta = s.t + min(t0, t0 + dt * (n - 1)) - TWIST_MARGIN
    tb = s.t + max(t0, t0 + dt * (n - 1)) + TWIST_MARGIN
    a, b = odometry_at(odometry, ta)[0], odometry_at(odometry, tb)[0]
    d = compose(inverse(a), b)  # the robot's motion over the sweep and the margins, in its frame at the start
    return dataclasses.replace(s, beam_t0=t0, beam_dt=dt, twist=d / (tb - ta))


def deskew(scans, log, sweep, echo, timed: bool):
    """``scans`` with the robot's velocity over each sweep (``deskewed``, lazily) when ``sensor.sweep_time`` asks for
    it and the input (``timed``: a bag) may say when its beams were taken; else as they are."""
    if sweep == 0 or not len(scans):
        return scans
    swept = {t: v for t, v in getattr(log, "sweeps", {}).items() if v} if timed else {}
    if sweep == "auto" and not swept:  # a CARMEN log, or a bag none of whose LaserScans says when beams were taken
        return scans
    odometry = np.asarray(log.odometry, dtype=np.float64).reshape(-1, 6)
    if odometry.shape[0] < 2:
        odometry = np.array([(s.t, *s.odom, s.tv, s.rv) for s in scans], dtype=np.float64).reshape(-1, 6)
    if sweep != "auto":
        echo(f"{log.path}: sensor.sweep_time {float(sweep):g} s: each scan deskewed by the odometry's motion over it "
             "(which way its beams run in time is found from the scans)")
    else:
        said = ", ".join(f"{t} {v:.3g} s" for t, v in swept.items())
        echo(f"{log.path}: a laser sweep takes {said} (LaserScan time_increment): each scan deskewed by the "
             "odometry's motion over it (which way its beams run in time is found from the scans; "
             "sensor.sweep_time: 0 turns it off)")
    odometry = odometry[np.argsort(odometry[:, 0], kind="stable")]
    return ScanMap(scans, functools.partial(deskewed, odometry=odometry, sweep=sweep))


def reversed_in_time(scan):
    """``scan`` with its beams' times the other way round, centred on the stamp: beam j at
    t0 + ((n - 1) / 2 - j) dt. A driver that writes its beams against time stamps either the first beam taken
    (``rplidar_ros``: its last array beam) or the last (the TurtleBot's LDS driver stamps when the turn is done: its
    first array beam); the scans' shapes are the same, so they cannot tell which. Centred, the times are half a
    sweep off either way: the mean time error of the scan read as is, without its shear."""
    n = np.asarray(scan.ranges).shape[0]
    return dataclasses.replace(scan, beam_t0=scan.beam_t0 + scan.beam_dt * (n - 1) / 2, beam_dt=-scan.beam_dt)


class SweepOrder:
    """When a deskewed scan's beams were taken, decided by the scans (module doc): as stamped (+1), the other way
    round (-1), or all at once (0: a driver that deskews its scans itself, or a time_increment that is wrong).

    ``choose(scan)`` gives the scan the filter uses and, while undecided, the three readings to weigh;
    ``weigh(ev)`` adds one update's evidence of each, ev[k] = log p(z | x_k, reading k) at that reading's best
    pose x_k (``ParticleFilter._weigh_sweep_orders``: a tracked set only, a search weighs places, not readings).
    The reading whose summed evidence leads the next by ``decide_nats`` is used from then on.
    """

    ORDERS = (1, 0, -1)
    NAMES = {1: "as stamped", 0: "all at once", -1: "reversed", None: "undecided"}

    def __init__(self, decide_nats: float = DECIDE_NATS) -> None:
        self.decide_nats = float(decide_nats)
        self.evidence = np.zeros(3)  # summed log evidence of ORDERS
        self.order: int | None = None
        self.weighed = 0  # updates that weighed the readings
        self.scans = 0  # scans prepared while undecided
        self.decided_at: int | None = None  # weighed updates when it was decided

    def choose(self, scan):
        """(the scan to use, the three readings (as stamped, at once, reversed) to weigh, or None: decided, or the
        robot turned less than ``MIN_TURN`` over the sweep)."""
        use = self.used(scan)
        if self.order is not None:
            return use, None
        self.scans += 1
        turn = abs(float(scan.twist[2]) * float(scan.beam_dt)) * (np.asarray(scan.ranges).shape[0] - 1)
        return use, ((scan, use, reversed_in_time(scan)) if turn >= MIN_TURN else None)

    def used(self, scan):
        """The reading of ``scan`` in use: as read until decided, then the decided one."""
        if self.order is None or self.order == 0:
            return dataclasses.replace(scan, twist=None)
        return scan if self.order > 0 else reversed_in_time(scan)

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
                "decided_after_scans": self.scans if self.order is not None else None,
                "log_evidence": {self.NAMES[o]: round(float(v), 3) for o, v in zip(self.ORDERS, lead)}}
