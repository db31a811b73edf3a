"""When were the scans taken? Their time offset against the odometry, found from the robot's turns, before a run.

A laser driver can stamp its scans late or early (a ROS driver's ``time_offset``, a USB laser's buffering, two
clocks, a spinning laser's stamp at the end of its turn): each scan is then paired with the odometry of another
moment. While the robot turns at a steady rate that costs nothing (every scan is off by the same motion); when the
turn rate changes, the scan's heading is off the odometry's by the change times the offset. A generated drive
stamped 0.3 s late has 11 times the heading error (``tests/test_latency.py``), and nothing said why.

The check compares two measures of how far the robot turned between two scans ``GAP`` s apart:

- the scans' own: the second scan matched to the first (``mcl.laser_odometry.icp``, point to line; a turn is what a
  scan match pins best, whatever the scene), from the odometry's motion with its turn replaced by the best of a
  coarse search ``TURN_SEARCH`` either side (a late stamp puts the odometry's turn a change of rate x lag away);
- the odometry's, taken ``tau`` s after each stamp: theta(t_j + tau) - theta(t_i + tau), the log's odometry stream
  interpolated (its headings unwrapped; without a stream, the scans' own poses).

Over the pairs where the turn rate changes fastest (they alone tell an offset: the derivative of the odometry's turn
by ``tau`` is the change of rate), the offset is the ``tau`` on a grid of ``STEP`` s over ``-SPAN..SPAN`` that
minimises

    sum over pairs ( dtheta_scans - k dtheta_odometry(tau) )^2 ,

``k`` fitted with it in closed form (odometry that turns a few percent short or long, a skid-steer base, would
otherwise pull the offset). Pairs whose residual is over four robust sigmas (a failed match) are dropped and the fit
made again. Its standard error: the residual's sigma over sqrt(sum g^2), g the residual's derivative by tau.

How the pairs are chosen matters: by the odometry's own rate change over the pair, its noise there chose pairs
whose noise leans one way, and the fit followed (a drive stamped 0.1 s late read 0.02-0.03 s). They are chosen by
the rate's change over ``SELECT`` s either side of the pair instead, and ``GAP`` is long (0.8 s) so that a pair's
rate change outweighs the odometry's noise; what bias is left pulls the offset towards 0 (the noise is in the
regressor).

A ``sensor.time_offset`` is suggested (the offset plus the one the run has) when the offset is at least
``MIN_OFFSET`` s and one odometry step, ``MIN_SIGMAS`` standard errors, from ``MIN_PAIRS`` pairs or more, with the
scans' turns within ``TURN_SCALE`` times the odometry's. Odometry sampled more sparsely than ``MAX_INTERVAL`` is not
used at all: between two samples the turn is a straight line, and the fit prefers the samples' own times (fr079's
and mit_csail's poses come with their scans, 0.2 s apart; they fitted 0.11 s or 0.21 s by the pairs' spacing, and
the runs were no better with either).

Measured (2026-12-01; docs/measurements.md, "Forty-seventh session"): on 81 generated worlds as recorded (5-40 Hz
lasers, 10-40 Hz odometry) no verdict: |offset| at most 0.08 s on the 69 whose turns agree, and the 11 others
(7 corridors, fitted up to 1 s) held by ``TURN_SCALE``; on 15 generated 20 Hz drives and 12 default-rate
ones stamped 0.1-0.3 s late or 0.2 s early, the offset found is 67-127 % of the lag where it gives a verdict (all
but the 20 Hz corridor, whose turns the matches miss, and two 0.1 s lags at 10 Hz odometry, under one step). 0.15 s
a log.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from mcl.estimate import compose, inverse
from mcl.laser_odometry import Key, far_points, icp

__all__ = ["TimeOffsetCheck", "advice", "check_each_laser", "check_time_offset", "findings", "summary_of"]

GAP = 0.8  # s between the two scans of a pair
SPAN = 1.0  # s: offsets tried, -SPAN..SPAN ...
STEP = 0.005  # s ... this far apart (then refined by a parabola through the best three)
SELECT = 0.5  # s: see ``change`` in check_time_offset
PAIRS = 80  # pairs matched at most (those whose turn rate changed most)
MIN_CHANGE = 0.1  # rad/s: a pair's turn rate must change this much from one end to the other to be used
MIN_PAIRS = 20  # pairs needed for a verdict ...
MIN_OFFSET = 0.05  # s: ... an offset this large, and one odometry step (its median) or more ...
MIN_SIGMAS = 5.0  # ... this many standard errors from 0 ...
TURN_SCALE = (0.8, 1.25)  # ... and the scans' turns this times the odometry's (else the matches did not see the turns)
MIN_RANGE = 0.5  # m: nearer points are left out (the robot's own frame stays put while it turns)
MAX_INTERVAL = 0.1  # s: odometry sampled more sparsely (its median step) cannot time the scans (see the module doc)
MIN_POINTS = 30  # points a scan needs to take part
MAX_TURN = 1.0  # rad: pairs that turned more are not matched
MIN_PAIRED = 0.3  # a match pairing fewer of the second scan's points failed
TURN_SEARCH = 1.5  # rad: the match starts from the best of the odometry's turn +- this ...
TURN_STEP = 0.05  # rad ... in steps of this (a late stamp puts the odometry's turn a change of rate x lag away)
COARSE_POINTS = 90  # the search moves about this many of the points (every k-th)
TRUNCATE = 0.5  # m: a point farther than this from the other scan's counts as this far (the coarse search)


@dataclass
class TimeOffsetCheck:
    """The scans' time offset found (``offset``, s to add to each stamp: negative when they are stamped late; None
    when the drive does not tell: too few pairs whose turn rate changed), its standard error ``se``, the odometry's
    turn scale fitted with it (``turn_scale``: the scans turned this times the odometry), the pairs used, the RMS
    turn residual (rad) at the offset and at 0, and ``verdict``: whether a ``sensor.time_offset`` is suggested."""

    pairs: int = 0
    interval: float = math.nan
    offset: float | None = None
    se: float = math.inf
    turn_scale: float = 1.0
    rms: float = math.nan
    rms_at_zero: float = math.nan
    verdict: bool = False
    laser: str = ""  # the laser whose scans were timed (its kind: a bag's topic)

    def summary(self) -> dict:
        out = {"laser": self.laser, "pairs": self.pairs, "odometry_interval": round(self.interval, 4),
               "offset": self.offset, "verdict": self.verdict}
        if self.offset is not None:
            out.update(se=round(self.se, 4), turn_scale=round(self.turn_scale, 4), rms=round(self.rms, 5),
                       rms_at_zero=round(self.rms_at_zero, 5))
        return out

    def describe(self) -> str:
        """e.g. 'the scans' turns fit the odometry's 0.300 s earlier than their stamps (+- 0.004 s, 80 pairs of
        scans; RMS 0.004 rad against 0.031 as stamped)'."""
        if self.offset is None and self.interval > MAX_INTERVAL + 1e-6:
            return (f"no time offset found (the odometry comes every {self.interval:.3f} s; at most {MAX_INTERVAL:g} s "
                    "times the scans)")
        if self.offset is not None and not TURN_SCALE[0] <= self.turn_scale <= TURN_SCALE[1]:
            return (f"no time offset found (the scans' turns are {self.turn_scale:.2f} times the odometry's over "
                    f"{self.pairs} pairs of scans: the matches did not follow the turns)")
        if self.offset is None:
            return f"no time offset found ({self.pairs} pairs of scans where the turn rate changed; {MIN_PAIRS} needed)"
        when = "earlier than" if self.offset < 0 else "later than"
        return (f"the scans' turns fit the odometry's {abs(self.offset):.3f} s {when} their stamps (+- {self.se:.3f} "
                f"s, {self.pairs} pairs of scans; RMS {self.rms:.4f} rad against {self.rms_at_zero:.4f} as stamped)")


def advice(check: TimeOffsetCheck, current: float = 0.0, fitted: bool = False) -> str:
    """What a ``check`` with a verdict means and what to do, after its ``describe()``; ``current``: the run's
    ``sensor.time_offset`` (already in the stamps the check saw); ``fitted``: the run pairs each scan with the
    odometry at the time found (``sensor.stamp_offset: fit``)."""
    late = check.offset < 0
    head = (f"the scans seem stamped about {abs(check.offset):.2f} s {'late' if late else 'early'} (a laser driver's "
            f"time_offset or buffering, two clocks), or the odometry as much {'early' if late else 'late'} (the data "
            "cannot tell which)")
    total = f"sensor.time_offset={round(current + check.offset, 2) + 0.0:g}"
    if fitted:
        return (f"{head}: each scan paired with the odometry of when it was taken for this run, the trajectory "
                f"stamped so (sensor.stamp_offset: keep leaves the stamps as they are, right where the odometry is the "
                f"one off); to do so for good, --set {total}")
    return (f"{head}, and the filter's heading will lag in every turn; if so, --set {total} pairs each scan with the "
            "odometry of when it was taken")


AGREE = 0.02  # s: fused lasers' offsets agree within this plus three standard errors of their difference


def check_each_laser(scans, odometry, mounts: dict) -> list[TimeOffsetCheck]:
    """``check_time_offset`` for each laser of ``mounts`` ({laser: its mount (3,)}, in order; the lasers of a fused
    stream, ``Scan.kind``), each on its own scans (a pass of ``scans`` per laser)."""
    out = []
    for laser, mount in mounts.items():
        own = scans if len(mounts) == 1 else (s for s in scans if getattr(s, "kind", None) == laser)
        check = check_time_offset(own, odometry, np.asarray(mount, dtype=np.float64))
        check.laser = laser or ""
        out.append(check)
    return out


def findings(checks: list[TimeOffsetCheck], current: float = 0.0, fit: bool = True) -> tuple[float | None, dict]:
    """What a run does with ``checks`` (``check_each_laser``'s): (the offset it pairs every scan at, when
    ``fit`` and the lasers agree, else None; {laser: the line to say}). One laser, or fused lasers that all find
    the same offset (within ``AGREE`` s and three standard errors): that offset, said once (under the first laser).
    Fused lasers that disagree (one late, another not; two offsets): each laser's own line, naming it, and no offset
    fitted (``sensor.time_offset`` moves every laser alike: read one alone to set it)."""
    judged = [c for c in checks if c.verdict]
    if not judged:
        return None, {}
    first = checks[0]

    def agree(c: TimeOffsetCheck) -> bool:
        return c.verdict and abs(c.offset - first.offset) <= AGREE + 3.0 * math.hypot(c.se, first.se)

    if all(agree(c) for c in checks):
        return (first.offset if fit else None), {first.laser: f"{first.describe()}: {advice(first, current, fit)}"}
    texts = {}
    for c in judged:
        total = round(current + c.offset, 2) + 0.0
        texts[c.laser] = (f"{c.laser}: {c.describe()}: the fused lasers' stamps disagree, and no offset is fitted "
                          f"(sensor.time_offset moves every laser alike); read it alone: --set "
                          f"{'topics.scan' if c.laser.startswith('/') else 'laser'}={c.laser} --set "
                          f"sensor.time_offset={total:g}")
    return None, texts


def summary_of(checks: list[TimeOffsetCheck]) -> dict:
    """For summary.json and ``mcl bag info``: the first laser's ``summary()``, the others' in ``other_lasers``."""
    return {**checks[0].summary(), **({"other_lasers": [c.summary() for c in checks[1:]]} if len(checks) > 1 else {})}


def _coarse_turn(key: Key, pts: np.ndarray, guess: np.ndarray) -> np.ndarray:
    """``guess`` with its turn replaced by the best of the turns ``TURN_SEARCH`` either side (steps of
    ``TURN_STEP``): the one whose moved points lie nearest ``key``'s (mean squared distance, truncated)."""
    dth = np.arange(-TURN_SEARCH, TURN_SEARCH + TURN_STEP / 2, TURN_STEP)
    th = guess[2] + dth
    pts = pts[:, :: max(1, -(-pts.shape[1] // COARSE_POINTS))]
    c, s = np.cos(th)[:, None], np.sin(th)[:, None]
    x = c * pts[0] - s * pts[1] + guess[0]
    y = s * pts[0] + c * pts[1] + guess[1]
    d, _ = key.tree.query(np.column_stack((x.ravel(), y.ravel())), distance_upper_bound=TRUNCATE)
    score = np.minimum(d, TRUNCATE).reshape(th.size, -1) ** 2
    return np.array([guess[0], guess[1], th[int(np.argmin(score.mean(axis=1)))]])


def _fit(d_scan: np.ndarray, heading, t_i: np.ndarray, t_j: np.ndarray, taus: np.ndarray):
    """(cost per tau, k per tau) of the least squares of the module doc, k in closed form for each tau."""
    d_odom = heading(t_j[None, :] + taus[:, None]) - heading(t_i[None, :] + taus[:, None])  # (taus, pairs)
    den = np.einsum("ij,ij->i", d_odom, d_odom)
    k = np.where(den > 0, d_odom @ d_scan / np.where(den > 0, den, 1.0), 1.0)
    r = d_scan[None, :] - k[:, None] * d_odom
    return np.einsum("ij,ij->i", r, r), k, r


def _best(cost: np.ndarray, taus: np.ndarray) -> float:
    """The minimum of ``cost`` over ``taus``, refined by a parabola through it and its neighbours."""
    b = int(np.argmin(cost))
    if 0 < b < taus.size - 1:
        c0, c1, c2 = cost[b - 1], cost[b], cost[b + 1]
        den = c0 - 2.0 * c1 + c2
        if den > 0:
            return float(taus[b] + 0.5 * (c0 - c2) / den * (taus[1] - taus[0]))
    return float(taus[b])


def check_time_offset(scans, odometry=None, mount=None, *, max_read: int = 4000) -> TimeOffsetCheck:
    """The check of the module docstring on the first ``max_read`` scans of ``scans`` (records with t, ranges,
    angles, max_range, odom, in time order; the first scan's laser only), the laser at ``mount`` (3,) on the robot
    (None: at its centre; it moves the odometry's guess for the match, not the turn). A ``sensor.time_offset``
    already in the stamps: the offset found is what is left."""
    mount = np.zeros(3) if mount is None else np.asarray(mount, dtype=np.float64)
    t, th, recs = [], [], []
    kind = None
    for s in itertools.islice(scans, max_read):
        if s.odom is None or (kind is not None and getattr(s, "kind", None) != kind):
            continue
        kind = getattr(s, "kind", None)
        if t and s.t <= t[-1]:
            continue
        t.append(float(s.t))
        th.append(float(s.odom[2]))
        recs.append(s)
    out = TimeOffsetCheck()
    if len(t) < 3:
        return out
    t = np.asarray(t)
    if odometry is None:
        ot, oth = t, np.unwrap(np.asarray(th))
    else:
        odometry = np.asarray(odometry, dtype=np.float64)
        ot, oth = odometry[:, 0], np.unwrap(odometry[:, 3])
    out.interval = float(np.median(np.diff(ot))) if ot.size > 1 else math.inf
    if out.interval > MAX_INTERVAL + 1e-6:
        return out

    def heading(x):
        return np.interp(x, ot, oth)

    # each scan's partner GAP s later
    j = np.searchsorted(t, t + GAP)
    ok = (j < t.size) & (t > t[0] + SPAN) & (t + GAP + SPAN < t[-1])
    i = np.flatnonzero(ok)
    j = j[ok]
    ok = t[j] - t[i] < 2.0 * GAP  # not across a gap in the scans
    i, j = i[ok], j[ok]
    # chosen by how fast the turn rate changes around the pair, the rate over SELECT s either side: the odometry's
    # own noise between t_i and t_j (which the fit compares) does not choose the pairs, or the choice biases it
    mid = 0.5 * (t[i] + t[j])
    change = np.abs(heading(mid + SELECT) - 2.0 * heading(mid) + heading(mid - SELECT)) / SELECT * (t[j] - t[i]) / SELECT
    order = np.argsort(-change, kind="stable")
    order = order[change[order] >= MIN_CHANGE]
    chosen, used = [], set()
    for o in order:  # the pairs whose rate changed most, no scan in two pairs
        if len(chosen) >= PAIRS:
            break
        if i[o] in used or j[o] in used:
            continue
        chosen.append(o)
        used.update((i[o], j[o]))
    d_scan, ti, tj = [], [], []
    mount_inv = inverse(mount)
    for o in chosen:
        a, b = far_points(recs[i[o]], MIN_RANGE), far_points(recs[j[o]], MIN_RANGE)
        if a.shape[1] < MIN_POINTS or b.shape[1] < MIN_POINTS:
            continue
        d = compose(inverse(np.asarray(recs[i[o]].odom, dtype=np.float64)), np.asarray(recs[j[o]].odom, np.float64))
        if abs(d[2]) > MAX_TURN:
            continue
        guess = compose(compose(mount_inv, d), mount)
        key = Key(a)
        start = _coarse_turn(key, b, guess)
        rel, paired, _ = icp(key, b, start)
        if paired < MIN_PAIRED * b.shape[1]:
            continue
        d_scan.append(rel[2])
        ti.append(t[i[o]])
        tj.append(t[j[o]])
    out.pairs = len(d_scan)
    if out.pairs < MIN_PAIRS:
        return out
    d_scan, ti, tj = np.asarray(d_scan), np.asarray(ti), np.asarray(tj)
    taus = np.arange(-SPAN, SPAN + STEP / 2, STEP)
    for _ in range(2):  # fit, drop the pairs over four robust sigmas (failed matches), fit again
        cost, k, r = _fit(d_scan, heading, ti, tj, taus)
        b = int(np.argmin(cost))
        sigma = 1.4826 * float(np.median(np.abs(r[b])))
        keep = np.abs(r[b]) <= 4.0 * max(sigma, 1e-3)
        if keep.all():
            break
        d_scan, ti, tj = d_scan[keep], ti[keep], tj[keep]
    out.pairs = int(d_scan.size)
    if out.pairs < MIN_PAIRS:
        return out
    tau = _best(cost, taus)
    h = 1e-3  # the residual's derivative by tau, numerically
    cost_at, k_at, r_at = _fit(d_scan, heading, ti, tj, np.array([tau, 0.0, tau + h, tau - h]))
    g = (r_at[2] - r_at[3]) / (2 * h)
    n = out.pairs
    sigma = math.sqrt(float(cost_at[0]) / max(n - 2, 1))
    out.offset = round(tau, 4) + 0.0
    out.se = sigma / math.sqrt(max(float(g @ g), 1e-12))
    out.turn_scale = float(k_at[0])
    out.rms = math.sqrt(float(cost_at[0]) / n)
    out.rms_at_zero = math.sqrt(float(cost_at[1]) / n)
    out.verdict = (abs(tau) >= max(MIN_OFFSET, out.interval) and abs(tau) >= MIN_SIGMAS * out.se
                   and TURN_SCALE[0] <= out.turn_scale <= TURN_SCALE[1])
    return out
