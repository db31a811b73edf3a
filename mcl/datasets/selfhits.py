"""Find the beams a laser spends on the robot itself.

A laser mounted on a robot often sees part of it: a wheel or a bumper corner at the edge of a 270-degree scan, the
posts of a mast in a 360-degree lidar's view, a cart the robot pushes. Those beams read a short range on every
scan, wherever the robot is. The likelihood field scores them as endpoints a few decimetres from the laser, which
fit the map only where a wall stands that close: every such beam pulls the cloud towards walls (on the eight
shared logs with 15 degrees at each edge of the scan blocked at 0.22 m, ``scripts/degrade_laser.py --body``, the
default lost four of eight tracks). ROS users mask them with a laser filter; mcl finds them itself.

A return fixed to the robot keeps its beam and its range while the robot turns; a wall's moves to other beams. A
robot driving straight down a corridor sees its side walls at one range on every scan, so constancy alone does not
tell a wall from the robot: the turns do. So, for each laser (fused lasers, an AGV's front and rear, each have
their own view of the robot) from its scans of one geometry (beam count and angles):

1. keep a scan each time the odometry has moved ``step`` m or turned ``step`` rad since the last one kept (a robot
   standing still says nothing), up to ``max_scans``, among the first ``max_read`` scans;
2. *turning pairs*: each kept scan with the first later one whose heading differs by ``turn`` rad or more, the
   robot having driven at most ``turn_travel`` m in between (a turn, not a loop around the building);
3. a beam is the robot's when its median reading ``m`` is at most ``reach`` m and it reads within
   its tolerance of ``m`` (``tol_sigmas`` robust standard deviations of its readings, 1.4826 times their median
   absolute deviation, kept within ``tol``..``tol_max``: a cheap lidar's 2 cm noise at 0.2 m and a SICK's 5 mm
   alike) on at least ``min_share`` of the kept scans *and* at both ends of at least
   ``min_turned`` of the turning pairs;
4. no verdict (None) without ``min_scans`` kept scans and ``min_turns`` turning pairs, or when the rule would take
   half the beams or more (a robot parked in a tight spot, not a body). A robot that moved but turned too little
   gets a warning instead when beams read one range under 0.5 m on 90 % of the scans
   (``unconfirmed_self_hits``): they are left in, and ``sensor.range_min`` can drop them.

Measured (2026-12-01) on 134 logs without a body: the eight shared logs (no beam's median under ``reach``) and 126
generated worlds (``suites/synthetic.yaml``'s with the laser 0.15 m ahead, ``suites/laser-mount.yaml``'s, the smoke
suite's, ``suites/self-hits.yaml``'s clear twins). The corridors' side walls read within the tolerance on up to 97 %
of the scans; among the logs with ``min_turns`` turning pairs or more, such a beam held through 30 % of the pairs at
most (``corridor-short-range-01``, 43 pairs). Below that, no verdict: two corridor worlds with 14 and 10 pairs reach
86 % and 70 % (a dead end's walls as far as its sides while the robot turns round in it). Bodies hold 98 % or more
(``suites/self-hits.yaml``: 2 cm noise at 0.15-0.3 m; ``scripts/degrade_laser.py --body``: 1 cm). No beam of the 134
logs is taken; every body beam of the 8 real logs with a body and of 12 of the 14 generated worlds with one is (the
other two, a corridor world's, turn 0 and 14 times: no verdict).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["BeamConstancy", "SelfHits", "beam_constancies", "beam_constancy", "detect_self_hits", "self_hits_of",
           "summary_of", "unconfirmed_self_hits", "without_self_hits"]


@dataclass(frozen=True, eq=False)
class SelfHits:
    """The beams of scans of one geometry (``n`` beams from ``angle_min`` by ``angle_increment``) that read the
    robot itself (``detect_self_hits``)."""

    beams: np.ndarray  # (K,) int64, ascending
    ranges: np.ndarray  # (K,) their median readings (m)
    n: int
    angle_min: float
    angle_increment: float
    share: float  # the least share of the kept scans on which one of the beams read its median
    scans: int  # kept scans looked at
    turns: int  # turning pairs among them
    kind: str = ""  # the laser's: FLASER, a bag's scan topic

    def matches(self, scan) -> bool:
        """Whether ``scan`` is of this laser and geometry (its beams are the same directions)."""
        return _same_geometry(scan, self.kind, self.n, self.angle_min, self.angle_increment)

    def summary(self) -> dict:
        """For summary.json: the laser, the beams (indices and angles in rad), their median readings, the
        evidence."""
        return {"laser": self.kind, "beams": [int(b) for b in self.beams],
                "angles_rad": [round(self.angle_min + self.angle_increment * int(b), 6) for b in self.beams],
                "ranges_m": [round(float(r), 4) for r in self.ranges], "of_beams": self.n,
                "least_share": round(self.share, 4), "scans": self.scans, "turns": self.turns}

    def describe(self) -> str:
        """e.g. 'beams 0-14 and 165-179 of 180 (-90.0..-76.0 and 75.0..89.0 degrees) read 0.22 m on at least 98 % of
        910 scans, also across 449 turns' (the turns left out below ``MIN_TURNS``: no verdict)."""
        runs, start = [], int(self.beams[0])
        for a, b in zip(self.beams[:-1], self.beams[1:]):
            if b != a + 1:
                runs.append((start, int(a)))
                start = int(b)
        runs.append((start, int(self.beams[-1])))
        deg = [(math.degrees(self.angle_min + self.angle_increment * a),
                math.degrees(self.angle_min + self.angle_increment * b)) for a, b in runs]
        idx = " and ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs)
        ang = " and ".join(f"{a:.1f}" if a == b else f"{min(a, b):.1f}..{max(a, b):.1f}" for a, b in deg)
        lo, hi = f"{float(self.ranges.min()):.2f}", f"{float(self.ranges.max()):.2f}"
        at = f"{lo} m" if lo == hi else f"{lo}-{hi} m"
        word = "beam" if self.beams.size == 1 else "beams"
        turns = f", also across {self.turns:,} turns" if self.turns >= MIN_TURNS else ""
        on = (f"on all {self.scans:,} scans" if self.share >= 1.0
              else f"on at least {math.floor(100.0 * self.share)} % of {self.scans:,} scans")
        return f"{word} {idx} of {self.n} ({ang} degrees) read {at} {on}{turns}"


@dataclass(frozen=True, eq=False)
class BeamConstancy:
    """Per beam of scans of one geometry: how often it reads its median, over the kept scans and across turns
    (``beam_constancy``)."""

    median: np.ndarray  # (n,) m; +inf for a beam with no reading that counts
    share: np.ndarray  # (n,) share of the kept scans reading within the tolerance of the median
    turned: np.ndarray  # (n,) share of the turning pairs reading so at both ends
    geometry: tuple[str, int, float, float]  # the laser (kind), n, angle_min, angle_increment
    scans: int
    turns: int


def beam_constancy(scans, range_min: float, range_max: float, **kw) -> BeamConstancy | None:
    """Steps 1 and 2 of the module docstring's rule and each beam's shares for the first scan's laser (its
    ``kind``: a bag's topic) and geometry, from ``scans``; None without a scan that has odometry. ``kw`` as
    ``beam_constancies``'."""
    each = beam_constancies(scans, range_min, range_max, **kw)
    return each[0] if each else None


def beam_constancies(scans, range_min: float, range_max: float, *, step: float = 0.05, max_scans: int = 1500,
                     max_read: int = 20_000, turn: float = 0.5, turn_travel: float = 1.0, tol: float = 0.03,
                     tol_max: float = 0.1, tol_sigmas: float = 3.0) -> list[BeamConstancy]:
    """Steps 1 and 2 of the module docstring's rule and each beam's shares, for every laser of ``scans`` (an
    iterable of ``Scan``: ranges, angle_min, angle_increment, max_range, odom, kind), in one pass: fused lasers
    (an AGV's front and rear) each have their own body in view. A laser is its ``kind`` (a bag's topic) with the
    geometry of its first scan that has odometry; its scans of another geometry are not looked at. In the order the
    lasers first appear; empty without a scan that has odometry. A reading counts when it is finite and
    range_min < r < the no-return range (``range_max``, or the scan's own max_range when smaller)."""
    from mcl.sensors import no_return_range

    kept: dict[str, tuple] = {}  # kind -> (geometry, rows, poses, [last pose])
    full = 0  # lasers with max_scans kept
    for s in itertools.islice(scans, max_read):  # a bag's scans are read again: a robot parked for an hour, not all
        if s.odom is None:
            continue
        kind = getattr(s, "kind", "")
        if kind not in kept:
            kept[kind] = ((kind, np.asarray(s.ranges).shape[0], float(s.angle_min), float(s.angle_increment)),
                          [], [], [None])
        geometry, rows, poses, last = kept[kind]
        if len(rows) >= max_scans or not _same_geometry(s, *geometry):
            continue
        o = np.asarray(s.odom, dtype=np.float64)
        if last[0] is not None and math.hypot(o[0] - last[0][0], o[1] - last[0][1]) < step \
                and abs(math.remainder(o[2] - last[0][2], 2.0 * math.pi)) < step:
            continue
        r = np.asarray(s.ranges, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(r) & (r > range_min) & (r < no_return_range(range_max, s.max_range))
        rows.append(np.where(ok, r, np.nan).astype(np.float32))
        poses.append(o)
        last[0] = o
        full += len(rows) == max_scans
        if full == len(kept):
            break
    return [_constancy(np.stack(rows), np.stack(poses), geometry, turn, turn_travel, tol, tol_max, tol_sigmas)
            for geometry, rows, poses, _ in kept.values() if rows]


def _constancy(ranges: np.ndarray, pose: np.ndarray, geometry, turn: float, turn_travel: float, tol: float,
               tol_max: float, tol_sigmas: float) -> BeamConstancy:
    """One laser's shares from its kept scans' ``ranges`` (K, n; NaN where no reading counts) and odometry poses
    ``pose`` (K, 3)."""
    heading = np.unwrap(pose[:, 2])
    travel = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(pose[:, 0]), np.diff(pose[:, 1])))])
    # turning pairs: each kept scan with the first later one `turn` rad away in heading, within turn_travel m
    k = ranges.shape[0]
    partner = np.full(k, -1, dtype=np.int64)
    for g in range(1, k):  # gaps, not scans: stops once no pair is within turn_travel
        i = np.arange(k - g)
        close = travel[i + g] - travel[i] <= turn_travel
        if not close.any():
            break
        new = (partner[i] < 0) & close & (np.abs(heading[i + g] - heading[i]) >= turn)
        partner[i[new]] = i[new] + g
    a = np.flatnonzero(partner >= 0)
    median = _nanmedian(ranges)
    with np.errstate(invalid="ignore"):
        off = np.abs(ranges - median)
        # each beam's own noise: tol_sigmas robust standard deviations (1.4826 MAD), within tol..tol_max
        within = np.clip(tol_sigmas * 1.4826 * np.nan_to_num(_nanmedian(off), posinf=tol_max), tol, tol_max)
        near = off <= within  # NaN: False
    turned = (near[a] & near[partner[a]]).mean(axis=0) if a.size else np.zeros(ranges.shape[1])
    return BeamConstancy(median=median, share=near.mean(axis=0), turned=turned, geometry=geometry, scans=int(k),
                         turns=int(a.size))


MIN_SCANS, MIN_TURNS = 50, 20  # kept scans and turning pairs a verdict needs (step 4)


def detect_self_hits(scans, range_min: float, range_max: float, *, reach: float = 1.0, min_share: float = 0.5,
                     min_turned: float = 0.8, min_scans: int = MIN_SCANS, min_turns: int = MIN_TURNS,
                     **kw) -> SelfHits | None:
    """The beams that read the robot itself in ``scans``, or None (the module docstring's rule; ``kw`` goes to
    ``beam_constancy``)."""
    return self_hits_of(beam_constancy(scans, range_min, range_max, **kw), reach=reach, min_share=min_share,
                        min_turned=min_turned, min_scans=min_scans, min_turns=min_turns)


def self_hits_of(c: BeamConstancy | None, *, reach: float = 1.0, min_share: float = 0.5, min_turned: float = 0.8,
                 min_scans: int = MIN_SCANS, min_turns: int = MIN_TURNS) -> SelfHits | None:
    """Steps 3 and 4 of the rule on ``beam_constancy``'s figures."""
    if c is None or c.scans < min_scans or c.turns < min_turns:
        return None
    return _hits(c, (c.median <= reach) & (c.share >= min_share) & (c.turned >= min_turned))


def unconfirmed_self_hits(c: BeamConstancy | None, *, reach: float = 0.5, min_share: float = 0.9,
                          min_scans: int = MIN_SCANS, min_turns: int = MIN_TURNS) -> SelfHits | None:
    """When the robot moved (``min_scans``) but turned too little for a verdict (under ``min_turns`` pairs): the
    beams that look like the robot itself all the same, a median under ``reach`` m read on ``min_share`` of the
    scans, or None. Left in (a wall beside a robot driving straight reads as steadily), but worth a warning."""
    if c is None or c.scans < min_scans or c.turns >= min_turns:
        return None
    return _hits(c, (c.median <= reach) & (c.share >= min_share))


def _hits(c: BeamConstancy, body: np.ndarray) -> SelfHits | None:
    if not body.any() or 2 * int(body.sum()) >= body.size:
        return None
    beams = np.flatnonzero(body)
    kind, n, angle_min, angle_increment = c.geometry
    return SelfHits(beams=beams, ranges=c.median[beams].astype(np.float64), n=n, angle_min=angle_min,
                    angle_increment=angle_increment, share=float(c.share[beams].min()), scans=c.scans,
                    turns=c.turns, kind=kind)


def _nanmedian(ranges: np.ndarray) -> np.ndarray:
    """Per beam, the median of its readings that count; +inf for a beam with none."""
    out = np.full(ranges.shape[1], np.inf)
    some = ~np.isnan(ranges).all(axis=0)
    out[some] = np.nanmedian(ranges[:, some], axis=0)
    return out


def _same_geometry(s, kind: str, n: int, angle_min: float, angle_increment: float) -> bool:
    """Whether scan ``s`` is of laser ``kind`` with ``n`` beams from ``angle_min`` by ``angle_increment``."""
    return (getattr(s, "kind", "") == kind and np.asarray(s.ranges).shape[0] == n and math.isclose(s.angle_min, angle_min, abs_tol=1e-6)
            and math.isclose(s.angle_increment, angle_increment, rel_tol=1e-6, abs_tol=1e-9))


def without_self_hits(s, hits: SelfHits | list[SelfHits]):
    """Scan ``s`` with the readings of ``hits``' beams made 0 (no reading: every model and reader skips a reading
    of 0 or less, as a LaserScan's below range_min), when it has their laser and geometry; else ``s`` as it is.
    ``hits``: one laser's, or a list of several lasers' (fused lasers: each scan is masked by its own laser's)."""
    for h in ([hits] if isinstance(hits, SelfHits) else hits):
        if h.matches(s):
            r = np.array(s.ranges, dtype=np.float64)
            r[h.beams] = 0.0
            return dataclasses.replace(s, ranges=r)
    return s


def summary_of(hits: list[SelfHits]) -> dict | None:
    """For summary.json and ``mcl bag info``: the first laser's ``SelfHits.summary()``, with the other lasers' in
    ``other_lasers`` when several lasers read the robot; None when none does."""
    if not hits:
        return None
    return {**hits[0].summary(), **({"other_lasers": [h.summary() for h in hits[1:]]} if len(hits) > 1 else {})}
