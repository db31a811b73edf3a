"""Odometry that stands still or jumps while the scans move: the motion lost, found by scan matching.

An encoder driver that hangs, a base controller that stops publishing and a bridge that re-sends its last message all
leave the odometry holding one pose, with no velocity, while the robot drives on and the laser goes on scanning.
The filter then sees no motion: every scan is gated (``filter.update_min_d``, as AMCL) and the estimate stays where
the stall began, 2.9 m behind after a 6 s stall at 0.5 m/s; in a corridor the lost motion cannot be seen at all
afterwards and the track is gone (``suites/heldout21.yaml``: 0 of 24 runs within 0.5 m, the default and the
baseline alike). Some odometry instead catches up when it comes back (mit_csail's: held for 0.9 s, then one step of
0.86 m): then nothing was lost.

:class:`StallFill` (``motion.stalls: fill``) watches the run's scans. Where the odometry of the first laser's scans
holds the same pose from one scan to the next, the scans are held back until it moves again (at most ``MAX_HOLD``
s), then matched one to the next from the last scan before the stall to the first after it
(:func:`mcl.laser_odometry.laser_odometry`, point-to-line ICP). When the odometry's own motion over the window is
shorter than the matched motion by more than ``LOST_M`` m, or turns less by more than ``LOST_A`` rad, the odometry
lost motion: each scan in the window takes the matched pose, and the odometry after it is moved rigidly to go on from
where the matching ended (the filter uses only its steps), as ``mcl.datasets.rosbag`` fills a gap in a bag's
odometry. Otherwise the scans pass as they were: a robot that stood still, or odometry that caught up (its step out
of the hold ``CATCH_UP`` times as fast as its step into it and faster than ``CATCH_UP_V`` m/s or ``CATCH_UP_W``
rad/s, turning over the window within ``CATCH_UP_TURN`` rad of the scans: a catch-up delivers the motion they saw).

The matching needs a guess, and where the scene does not constrain the motion (along a corridor) the guess decides:
the odometry's velocity just before the hold (the faster of its last two steps: a hold that began between two scans
leaves the last one short). Each scan is matched from it, from the same without its turn and from no motion, the
best match kept; a scan with too few returns to match (an open hall) drives on straight at that speed. A hold that
began *abruptly* (faster than ``ABRUPT_V`` m/s or ``ABRUPT_W`` rad/s: no wheeled robot brakes from there to a
standstill in one scan period) is matched whole; one that began gently is checked every ``STILL_CHECK`` s: a scan
that matches the one before the hold at no motion (within ``STILL_M`` m and ``STILL_A`` rad) shows a robot standing
still, and the scans pass as they came, without matching, until the odometry moves (a robot parked for minutes costs
a match or a few). A robot that stopped dead in a corridor is taken to drive on.

Measured on the eight shared logs: only mit_csail's odometry holds a pose while the scans go on (7 windows of
0.4-6.8 s; each a standstill or a catch-up, left as it was).

The scans a hold's fill placed say so (``Scan.filled``): the filter widens their steps' travel by
``motion.fill_spread`` of it (``mcl.motion``), since where the scans do not pin the motion the guess decided it
(fr101 with a 90-degree laser, two scans 5.6 s apart along a corridor: 2.84 m filled, 0.82 m driven).

A base driver that restarts starts its odometry again from 0 0 0 wherever the robot is, often after it was down
for seconds (the odometry holding its pose there): the filter sees a step of metres in one scan period, and hedges
it (``mcl.degenerate.InputGuard``: half the particles take it, the others are re-spread where they were), which
keeps an instant restart but not the seconds lost before it (``suites/heldout22.yaml``: 7 of 24 runs within
0.5 m). With ``jumps`` (``motion.jumps: match``), a step of the first laser's odometry that the filter's guard
would call a jump and that is faster than ``JUMP_V``, or slower but with the scans not overlapping at it
(``JUMP_OVERLAP``: a restart between scans seconds apart), is taken from scan matching the two scans instead (from
the velocity before it and from the odometry's own step, or from standing still where the step ends at the
odometry's origin, since after a restart it says where the robot was, not how it moved; a match that agrees with the
odometry's own step leaves it; scans over ``MAX_HOLD`` s apart are left to the filter, the odometry passed on as
it came from there, so that its guard sees a restart at the origin), and the odometry after it goes on from there;
and a hold that ends in such a jump is filled from the scans, however its step out compares (it is no catch-up).
So is a hold whose fast step out turns the robot over ``CATCH_UP_TURN`` rad more or less than the scans did over it:
a driver that restarted a metre or two from where its odometry held (the odometry had come back near its origin)
jumps too short for the guard, and as fast as a catch-up.
Scans of other lasers between the two lie between the first laser's poses around them, by their time (held with the
slip check's span; with ``slips`` off they keep the odometry as it came).

A wheel that slips (spins on a wet or dusty floor) reads travel the robot did not make: the odometry turns the robot
1-2 rad/s that did not turn (``suites/heldout23.yaml``), and the cloud turns with it. With ``slips``
(``motion.slips: match``), a step of the first laser's odometry that turns ``SLIP_TURN`` rad or more between scans
at most ``SLIP_DT`` s apart, and that the scans say turned less (``_slipped``), is taken from scan matching as a
jump's is, and the odometry after it goes on from there. The shared logs' odometry turns up to a few per cent more
than their scans on fast turns, and a simulated one's by up to 0.13 rad a step: the bounds leave those alone (no
step of ``suites/synthetic.yaml``'s worlds is taken, one of belgioioso's: the odometry -0.24 rad, the scans -0.06,
the reference -0.065). A laser at a ROS robot's rate (10-40 Hz) cuts a slip into steps of a few hundredths of a
radian each, under the bounds: the check then spans the scans of about ``SLIP_SPAN`` s (2 at 10 Hz, 8 at 40 Hz), holds
them back until it is done, and a slip's scans take the poses matched from the span's first (``suites/heldout24.yaml``:
at 40 Hz no step was taken before). At 5 Hz and slower a span is one step, as before. A match that corrects the
turn by under ``SLIP_OFF`` and changes the odometry's travel by more than a slipping wheel could for that turn
(``SLIP_LEVER``) slid along the scene, and the step is left as it came. One that drives against the odometry's
travel by more than that (``_reversed``: a slip at a reversal, matched from the velocity before it along a scene
that repeats) takes the scans' turn and the odometry's travel.
"""

from __future__ import annotations

import collections
import dataclasses
import math
import statistics

import numpy as np

from mcl.degenerate import InputGuard
from mcl.estimate import compose, inverse, wrap_angle
from mcl.laser_odometry import MIN_PAIRS, Key, far_points, icp, laser_odometry, scan_points
from mcl.odomcheck import MIN_RANGE, YAW_WEIGHT, score_motions

ABRUPT_V = 0.2  # m/s: the odometry's last step before it held faster than this: a stall, not a stop ...
ABRUPT_W = 0.3  # rad/s ... or turning faster than this
STILL_CHECK = 1.0  # s: a gentle hold is checked against the scan before it every this many seconds
STILL_M = 0.05  # m: ... and is a standstill when that scan matches within this ...
STILL_A = 0.03  # rad ... and this
LOST_M = 0.25  # m: the odometry lost motion over a window when it moved this much less than the scans matched ...
LOST_A = 0.15  # rad ... or turned this much less
CATCH_UP = 2.0  # the step out of a hold faster than this times the step into it ...
CATCH_UP_V = 1.0  # m/s ... and than this ...
CATCH_UP_W = 1.0  # rad/s ... or turning so: the odometry caught up (mit_csail: 0.86-0.94 m in 0.21 s, 4-4.5 m/s)
# rad: ... and its turn over the window within this of the scans' (a catch-up delivers the motion they saw: mit_csail's
# three within 0.35 rad). A step out that turns more or less is a driver that restarted from 0 0 0 a metre or two from
# where its odometry held (a jump too short for the guard): the robot's pose turned by the heading it had there
CATCH_UP_TURN = 0.7
# ... and at least this share of the travel they saw (mit_csail's three: 86-107 %). A step out that is fast only
# because the robot turns on the spot there delivers none of it: it held, and lost the travel (belgioioso with three
# 3 s stalls and its scans paired with the odometry 0.08 s late: 0.002 m of the 4.1 m the scans saw)
CATCH_UP_TRAVEL = 0.5
# s: scans held back at most this long; a longer hold passes as it was: a hung driver is restarted within seconds,
# and a robot stopped dead along a corridor (whose scans cannot tell it stands) is taken to drive on only so long
MAX_HOLD = 20.0
JUMP_V = 5.0  # m/s: an odometry jump faster than this is matched (no wheeled robot indoors drives so) ...
JUMP_OVERLAP = 0.1  # ... and a slower one that leaves under this share of the scan's points near the one before's
OVERLAP_M = 0.15  # m: a point this near a point of the scan before overlaps it
HELD = 1e-9  # m and rad: two odometry poses this close are the same pose
# A wheel that slips (``slips``, ``_slipped``): a step of the first laser's odometry that turns SLIP_TURN rad or more
# between scans at most SLIP_DT s apart is checked against the scans. Where the step with its turn halved or left
# out lies under SLIP_FIT times as far from them as the step itself (a real turn's scans fit the step), the scans are
# matched by ICP from the step with next to no prior: a slip when their turn differs from the odometry's by more than
# SLIP_OFF plus SLIP_SHARE times their own (the shared logs' odometry turns a few per cent more than their scans on
# fast turns), with SLIP_PAIRED of the points paired and the match under SLIP_FIT times as far as the step
SLIP_DT = 0.6  # s: scans farther apart are not checked (aces, 1.5 s apart: matched 0.45 m where the robot drove 0.95)
SLIP_TURN = 0.15  # rad
SLIP_OFF = 0.15  # rad
# ... and within SLIP_AFTER s of a slip found (a slip lasts seconds; its first and last steps are partial, and a
# step of it that turned under SLIP_TURN let 0.1-0.13 rad through) SLIP_TURN_AFTER and SLIP_OFF_AFTER instead
SLIP_AFTER = 1.0  # s
SLIP_TURN_AFTER = 0.05  # rad
SLIP_OFF_AFTER = 0.05  # rad
# A wheel that slips by s metres turns a differential drive's odometry by s / b (b its wheel base) and moves it by
# s / 2: a slip's matched step that corrects the turn by less than SLIP_OFF (the steps the finer bound after a slip
# lets through: noise-sized for sloppy odometry) may change the odometry's travel by at most SLIP_LEVER times that
# turn (half of a 1 m wheel base), plus SLIP_TRAVEL for the matching's own error. A match that changes the travel
# more has slid along a corridor: odometry with alphas 0.15 (heldout6's large-sloppy-long-odometry-h13) turned
# 0.06-0.09 rad from its scans step after step, and the matches, each guessed from the last, drove 0.21-0.29 m a step
# where the robot drove 0.16 (0.72-0.83 m off, the baseline 0.25 m). A larger correction is a slip's whatever the
# travel: a 40 Hz slip's last span corrected 0.31 rad and 0.22 m, and without it the track ended 0.72 m off.
SLIP_LEVER = 0.5  # m per rad
SLIP_TRAVEL = 0.03  # m
SLIP_SHARE = 0.5
SLIP_PAIRED = 0.5
SLIP_FIT = 0.7
SLIP_POINTS = 120  # the distances are measured over about this many of the second scan's points
# A laser at a ROS robot's rate (10-40 Hz) turns a slip into steps of a few hundredths of a radian, under every bound:
# the check spans as many scans as come in about SLIP_SPAN s (the median period of the last SLIP_PERIODS steps), its
# scans held back until it is done (one scan at 5 Hz and slower, as the bounds were chosen: suites/heldout23.yaml)
SLIP_SPAN = 0.2  # s
SLIP_PERIODS = 20


@dataclasses.dataclass
class Stall:
    """One window the odometry held its pose in while the scans showed motion, filled by scan matching."""

    t0: float  # s: the scan before the hold
    t1: float  # s: the first scan after it (the last in the window when the log ended held)
    scans: int  # scans of the first laser matched (after the one before the hold; the first after it included)
    matched: float  # m: the motion over the window by scan matching
    odometry: float  # m: ... by the odometry
    # "hold"; "jump": the odometry jumped from one scan to the next (a driver that restarted from 0 0 0, a glitch);
    # "hold+jump": it held, then jumped (the driver was down a while before it restarted); "slip": the odometry's step
    # turned more than the scans did (a wheel that slips)
    cause: str = "hold"
    # "slip": the odometry's step turned (rad) ``odometry_turn``, the scans' ``matched_turn`` (0 for the others)
    odometry_turn: float = 0.0
    matched_turn: float = 0.0

    def summary(self) -> dict:
        """summary.json's ``odometry_stalls`` entry: the fields, a slip's turns only for a slip."""
        entry = dataclasses.asdict(self)
        if self.cause != "slip":
            del entry["odometry_turn"], entry["matched_turn"]
        return entry


class StallFill:
    """``scans`` (a sized iterable of ``mcl.datasets.carmen.Scan`` records, as a run reads them) with the odometry of
    each stall filled by scan matching (see the module doc); lazy, so a bag's scans still stream. ``mount_of(scan)``:
    the laser's pose on the robot as the run takes it. ``holds``: fill the holds (``motion.stalls: fill``);
    ``jumps``: ``filter``'s (max_odom_step, max_odom_ratio, max_odom_speed), to match the odometry's jumps as
    ``mcl.degenerate.InputGuard`` tells them (``motion.jumps: match``), or None to leave them to the filter;
    ``slips``: take the steps a wheel's slip turned from the scans (``motion.slips: match``).
    ``stalls`` lists the windows filled by the last pass."""

    def __init__(self, scans, mount_of, holds: bool = True, jumps: tuple | None = None, slips: bool = False) -> None:
        self.scans, self.mount_of = scans, mount_of
        self.holds, self.jumps, self.slips = holds, jumps, slips
        self._slipped: dict = {}  # each turning step's slip check, by its two scans: later passes reuse them
        self._slip_at = -math.inf  # the time of the last slip found (this pass)
        self.stalls: list[Stall] = []
        self._list: list | None = None
        self._matched: dict = {}  # each hold's matches, by its first and last scan: later passes reuse them

    def __len__(self) -> int:
        return len(self.scans)

    def __getitem__(self, k):
        """Scan ``k`` (or a slice) as filled: the first such access reads every scan once and keeps them (an
        instrument's random access to a CARMEN log's scans; a run streams them)."""
        if self._list is None:
            self._list = list(self)
        return self._list[k]

    def __iter__(self):
        self.stalls = []
        self._slip_at = -math.inf
        return self._filled()

    def _filled(self):
        kind = None  # the first laser: the one whose odometry is watched and whose scans are matched
        fix = np.zeros(3)  # the correction: a scan's odometry is compose(fix, its own)
        prev = None  # the last scan of that laser read, as it came (its own odometry)
        step_rate = np.zeros((2, 3))  # the odometry's velocity before it: its last two steps per second, faster first
        rate = np.zeros(3)  # the last step's
        held: list = []  # scans held back while the odometry holds (the first laser's and the others')
        anchor = anchor_out = None  # the scan before the hold, and its odometry as passed on
        entry = np.zeros((2, 3))  # step_rate as the hold began
        abrupt = False  # the hold began at speed (a stall by its look), not after the robot slowed
        parked = False  # the hold was checked: the robot stands still; pass the scans until the odometry moves
        next_check = STILL_CHECK  # s into a gentle hold of its next standstill check
        guard = InputGuard(*self.jumps) if self.jumps is not None else None  # tells the odometry's jumps
        span: list = []  # scans held back for the slip check (the first laser's and the others'), after span_from
        span_from = None  # the first laser's scan passed on that the slip check's span starts at
        periods: collections.deque = collections.deque(maxlen=SLIP_PERIODS)  # the first laser's last scan periods
        for s in self.scans:
            if kind is None:
                kind = s.kind
            if s.kind != kind:
                if held:
                    held.append(s)
                elif self.slips and span_from is not None:  # held with the span: a slip's fill places it too
                    span.append(s)
                else:
                    yield self._moved(s, fix)
                continue
            same = prev is not None and _same(s.odom, prev.odom)
            own = compose(inverse(prev.odom), s.odom) if prev is not None else None  # the odometry's step
            step = None  # the robot's step from prev to s, when not the odometry's own
            if held:
                held.append(s)
                if same:
                    wait = s.t - anchor.t
                    if not abrupt and wait >= next_check:  # once a second: people walking by can spoil one
                        next_check = wait + STILL_CHECK
                        if _standing(anchor, s, self.mount_of(s)):
                            parked = True
                    if parked or wait > MAX_HOLD:  # a standstill (or too long to hold): as it was
                        parked = True
                        yield from (self._moved(h, fix) for h in held)
                        held = []
                    continue
                fix, step = yield from self._resolve(anchor, anchor_out, held, entry, fix, guard)
                held = []
            elif same and not parked and self.holds:
                # the span up to prev passes on; another laser's scans after prev are held with the hold
                before, after = _split(span, prev)
                yield from (self._moved(h, fix) for h in before)
                anchor, anchor_out = prev, compose(fix, prev.odom)
                v, w = math.hypot(step_rate[0, 0], step_rate[0, 1]), float(np.abs(step_rate[:, 2]).max())
                entry = step_rate.copy()
                abrupt = v > ABRUPT_V or w > ABRUPT_W
                held, next_check = [*after, s], STILL_CHECK
                span = []
                continue
            else:
                after_jump = fix
                if not same:
                    parked = False
                    if guard is not None and own is not None:
                        after_jump, step = self._jump(prev, s, own, step_rate, fix, guard)
                # (a jump left to the filter with the correction dropped ends the span: the scans before it keep theirs)
                if self.slips and step is None and after_jump is fix and not same and span_from is not None:
                    span.append(s)
                    firsts = sum(h.kind == kind for h in span)
                    # the span's scans: as many as come in SLIP_SPAN s at the median period (one at 5 Hz and slower)
                    n = max(1, round(SLIP_SPAN / statistics.median(periods))) if periods else 1
                    if firsts >= n or s.t - span_from.t >= SLIP_SPAN:
                        fix, step = yield from self._slip(span_from, span, step_rate, fix)
                        span = []
                else:
                    # passed on with the correction before a jump; after a jump matched, another laser's scans after
                    # prev lie between prev's pose and s's (their odometry may have restarted with it)
                    before, after = _split(span, prev)
                    yield from (self._moved(h, fix) for h in (span if step is None else before))
                    if step is not None:
                        yield from _placed([prev, s], [compose(fix, prev.odom), compose(after_jump, s.odom)], after)
                    span = []
                    fix = after_jump
                    yield self._moved(s, fix)
            if prev is not None and not same:
                dt = s.t - prev.t
                if dt > 0.0:
                    periods.append(dt)
                    # the last two steps, the faster first: a hold that began between two scans leaves the last short
                    rate, last_rate = (step if step is not None else own) / dt, rate
                    step_rate = np.array(sorted((rate, last_rate), key=lambda r: -math.hypot(r[0], r[1])))
            prev = s
            if not span:
                span_from = s
        if held:
            yield from self._resolve(anchor, anchor_out, held, entry, fix, guard)
        yield from (self._moved(h, fix) for h in span)  # the log's last fraction of a second, unchecked

    def _jump(self, prev, s, own, entry, fix, guard):
        """(the correction after scan ``s``, the robot's step into it or None: the odometry's own ``own``). Where the
        odometry's step from ``prev`` jumped (``_jumped``: a driver that restarted from 0 0 0, a glitch), the step is
        the scans' (guessed from the rates ``entry`` and from ``own``) and the odometry after it goes on from there;
        unless the scans match best at the odometry's own step (a long step that is motion)."""
        if not _jumped(guard, own, s.t - prev.t, prev, s, self.mount_of(s)):
            return fix, None
        if s.t - prev.t > MAX_HOLD:
            # scans so far apart are not matched: the filter hedges the jump, and its guard sees the odometry as it
            # came from here on (a restart at its origin, not where an earlier fill's correction moves it)
            return np.zeros(3), None
        # after a restart from 0 0 0 the odometry's step is where the robot was, not how it moved: no guess from it,
        # only the velocity before and standing still (laser_odometry's own); from the step, the demo thinned to a
        # scan every 2.4 s matched 1.41 m where the robot drove 1.18 m, 2.3 m off
        step = self._match([prev, s], entry, None if guard.at_origin(s.odom) else own)[-1, 1:4]
        if _agree(step, own):
            return fix, None
        self.stalls.append(Stall(float(prev.t), float(s.t), 1, float(math.hypot(step[0], step[1])),
                                 float(math.hypot(own[0], own[1])), "jump"))
        return compose(compose(compose(fix, prev.odom), step), inverse(s.odom)), step

    def _slip(self, start, span: list, entry, fix):
        """Yield the scans ``span`` (the first laser's scans after ``start``, with other lasers' between them) and
        return (the correction after the last, the robot's step into it or None: the odometry's own). Where the
        odometry's step from ``start`` to the last turned more than the scans did (``_slipped``: a wheel that slips),
        the first laser's scans take the poses matched from ``start`` (as a jump's step is matched) and the odometry
        after goes on from there; unless the match agrees with the odometry's step (``_agree``), outside a slip's
        ``SLIP_AFTER`` s (inside them the bound is finer). Other lasers' scans in the span take the poses between the
        first laser's around them, by their time (``_between``)."""
        s = span[-1]
        own = compose(inverse(start.odom), s.odom)
        after = s.t - self._slip_at <= SLIP_AFTER
        key = (s.kind, float(start.t), float(s.t), after)
        if key not in self._slipped:
            self._slipped[key] = _slipped(start, s, own, self.mount_of(s), *(
                (SLIP_TURN_AFTER, SLIP_OFF_AFTER) if after else (SLIP_TURN, SLIP_OFF)))
        chain = [start, *(h for h in span if h.kind == s.kind)]
        rows = self._match(chain, entry, own) if self._slipped[key] else None
        if rows is not None and (_too_far(rows[-1, 1:4], own, s.t - start.t) or _slid(rows[-1, 1:4], own)):
            rows = None  # a wrong match, not a slip
        if rows is not None and _reversed(rows[-1, 1:4], own):
            # the scans pin the turn but not the travel along a scene that repeats: the odometry's travel, their turn
            rows = rows.copy()  # (the matches are kept for the run's later passes)
            for k, h in enumerate(chain):
                rows[k, 1:3] = compose(inverse(start.odom), h.odom)[:2]
        if rows is None or (not after and _agree(rows[-1, 1:4], own)):
            yield from (self._moved(h, fix) for h in span)
            return fix, None
        step = rows[-1, 1:4]
        self._slip_at = float(s.t)
        self.stalls.append(Stall(float(start.t), float(s.t), len(chain) - 1, float(math.hypot(step[0], step[1])),
                                 float(math.hypot(own[0], own[1])), "slip", float(own[2]), float(step[2])))
        at = compose(fix, start.odom)  # the start's odometry as passed on
        yield from _placed(chain, [compose(at, r[1:4]) for r in rows], span[:-1])
        fix = compose(compose(at, step), inverse(s.odom))
        yield self._moved(s, fix)
        return fix, (step if len(chain) == 2 else compose(inverse(rows[-2, 1:4]), step))

    @staticmethod
    def _moved(s, fix):
        """``s`` with its odometry moved by the correction ``fix`` (as it was when that is none)."""
        if not fix.any():
            return s
        return dataclasses.replace(s, odom=compose(fix, s.odom))

    def _match(self, chain: list, entry, own=None) -> np.ndarray:
        """``laser_odometry``'s rows for the scans ``chain`` of one laser (the robot's poses in its frame at the first),
        guessed from the robot's rates ``entry`` (2, 3) before them, and for a pair from the odometry's own step
        ``own`` between them too; kept for the run's later passes."""
        mount = self.mount_of(chain[0])
        if own is not None:
            entry = np.vstack([entry, np.asarray(own) / max(float(chain[-1].t - chain[0].t), 1e-3)])
        key = (chain[0].kind, float(chain[0].t), float(chain[-1].t), len(chain))  # a run reads its scans more than once
        if key not in self._matched:
            # the robot's rates in the laser's frame (the matching's first guesses): the laser's step is
            # inverse(mount) (+) the robot's (+) mount; over 0.1 s, per second
            laser_rate = np.array([compose(inverse(mount), compose(r * 0.1, mount)) / 0.1 for r in entry])
            # a scan that cannot be matched (too few returns: an open hall) moves at the last rate, however many in a
            # row
            self._matched[key] = laser_odometry(chain, mount, rate0=laser_rate, max_misses=len(chain),
                                                thorough=True)[0]
        return self._matched[key]

    def _resolve(self, anchor, anchor_out, held: list, entry, fix, guard):
        """Yield the ``held`` scans (the hold after ``anchor``, ending with the first scan whose odometry moved or
        with the log's end), filled when the matching finds motion the odometry lost or when the odometry jumped out
        of the hold (``guard``, an ``InputGuard``, tells; None: no jumps); return the correction after and the robot's
        step into the last scan of the window (None: the odometry's own)."""
        kind = anchor.kind
        chain = [anchor, *(h for h in held if h.kind == kind)]
        rows = self._match(chain, entry)
        matched = rows[-1, 1:4]  # the robot's motion over the window, in its frame at the anchor
        own = compose(inverse(anchor.odom), chain[-1].odom)
        lost_m = math.hypot(matched[0], matched[1]) - math.hypot(own[0], own[1])
        lost_a = abs(float(matched[2])) - abs(float(wrap_angle(own[2])))
        # the odometry's step into the first scan after the hold (all of its motion over the window): much faster
        # than before the hold, it delivered the held motion late (a catch-up), and lost none; unless it jumped
        # (a driver that restarted from 0 0 0 after it was down), far (the guard) or near, turning where the scans
        # did not, or it brought under CATCH_UP_TRAVEL of the travel they saw (a turn on the spot after a stall)
        dt = chain[-1].t - chain[-2].t if len(chain) > 1 else 0.0
        fast = dt > 0.0 and (
            math.hypot(own[0], own[1]) / dt > max(CATCH_UP * math.hypot(entry[0, 0], entry[0, 1]), CATCH_UP_V)
            or abs(float(wrap_angle(own[2]))) / dt > max(CATCH_UP * float(np.abs(entry[:, 2]).max()), CATCH_UP_W))
        jumped = guard is not None and dt > 0.0 and (
            _jumped(guard, own, dt, anchor, chain[-1], self.mount_of(anchor))
            or (fast and abs(float(wrap_angle(own[2] - matched[2]))) > CATCH_UP_TURN))
        travel = math.hypot(matched[0], matched[1])
        caught_up = fast and not jumped and lost_m <= max(LOST_M, (1.0 - CATCH_UP_TRAVEL) * travel)
        if caught_up or (not jumped and lost_m <= LOST_M and lost_a <= LOST_A):
            for h in held:  # a standstill, or odometry that caught up: as it was
                yield self._moved(h, fix)
            return fix, None
        placed = [compose(anchor_out, r[1:4]) for r in rows]
        yield from _placed(chain, placed, held, tv=0.0, rv=0.0, filled=True)
        self.stalls.append(Stall(float(anchor.t), float(chain[-1].t), len(chain) - 1,
                                 float(math.hypot(matched[0], matched[1])), float(math.hypot(own[0], own[1])),
                                 "hold+jump" if jumped else "hold"))
        return compose(placed[-1], inverse(chain[-1].odom)), compose(inverse(rows[-2, 1:4]), rows[-1, 1:4])


def _split(span: list, prev) -> tuple[list, list]:
    """(``span`` up to and with the scan ``prev``, the scans after it; all of them when ``prev`` is not in it)."""
    k = next((k for k in range(len(span) - 1, -1, -1) if span[k] is prev), -1)
    return span[:k + 1], span[k + 1:]


def _placed(chain: list, poses: list, scans, **fields):
    """``scans`` with their odometry: a scan of the first laser's ``chain`` its pose in ``poses``, another laser's
    the pose between those around it by its time (``_between``); ``fields`` replaced too."""
    at = {id(c): p for c, p in zip(chain, poses)}
    times = np.array([c.t for c in chain], dtype=np.float64)
    for h in scans:
        yield dataclasses.replace(h, odom=at[id(h)] if id(h) in at else _between(poses, times, h.t), **fields)


def _between(poses: list, times: np.ndarray, t: float) -> np.ndarray:
    """The pose at time ``t`` between the two of ``poses`` (at ``times``, ascending) around it: the first's composed
    with the share of the step from it to the second that ``t`` lies along (at either end, that end's)."""
    k = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(poses) - 2))
    share = float(np.clip((t - times[k]) / max(times[k + 1] - times[k], 1e-9), 0.0, 1.0))
    return compose(poses[k], share * compose(inverse(poses[k]), poses[k + 1]))


def _jumped(guard, step, dt: float, a, b, mount) -> bool:
    """The odometry's ``step`` over ``dt`` s from scan ``a`` to scan ``b`` a jump to match: one that ``guard`` (an
    ``InputGuard``, which it feeds) calls a jump, and either faster than ``JUMP_V`` or one that puts under
    ``JUMP_OVERLAP`` of ``b``'s points near ``a``'s. A slow jump that the scans agree with may be motion between
    scans too far apart to match well (a log thinned to a scan every 5 s: matched 1-2 m off) and is left to the
    filter; a driver that restarted while the scans were that far apart leaves none of them near (0.00 on the
    shared logs' thinned four, 0.13-0.58 for the thinned demo's true steps). Scans with too few points to tell
    leave a slow jump to the filter. A step the guard takes for motion (at the robot's speed over a gap between
    scans) is not checked: over seconds of travel the odometry's own error leaves the scans as far apart
    (heldout20's gaps: 57 of its logs' true steps under 10 % overlap)."""
    d = math.hypot(step[0], step[1])
    if not guard.observe(d, dt, b.odom):
        return False
    if dt <= 0.0 or d / dt > JUMP_V:
        return True
    share = _overlap(a, b, step, mount)
    return share is not None and share < JUMP_OVERLAP


def _too_far(matched, own, dt: float) -> bool:
    """A slip's matched step ``matched`` drove farther than the odometry's ``own`` by more than any robot drives in
    ``dt`` s (``JUMP_V``): a wrong match (a 90-degree turn on the spot was matched 1.22 m away in 0.2 s, and the
    estimate followed it 1.4-2.7 m off, where the plain baseline kept 0.20 m)."""
    return math.hypot(matched[0], matched[1]) > math.hypot(own[0], own[1]) + JUMP_V * dt


def _slid(matched, own) -> bool:
    """A slip's matched step ``matched`` corrects the turn of the odometry's ``own`` by under ``SLIP_OFF`` (a step the
    finer bound after a slip let through, or one near the bound) and changes its travel by more than a slipping wheel
    could for that turn (``_slip_reach``): the match slid along the scene."""
    turn, reach = _slip_reach(matched, own)
    if turn >= SLIP_OFF:  # a turn corrected by this much is a slip's, whatever the match made of the travel
        return False
    return abs(math.hypot(matched[0], matched[1]) - math.hypot(own[0], own[1])) > reach


def _slip_reach(matched, own) -> tuple[float, float]:
    """(the turn (rad) a slip's matched step ``matched`` corrects in the odometry's ``own``, how far (m) a slipping
    wheel could move the odometry's travel for it): a wheel that slips by s turns a differential drive's odometry by
    s / b and moves it by s / 2, so ``SLIP_LEVER`` m per radian (a 1 m wheel base), plus ``SLIP_TRAVEL``."""
    turn = abs(float(wrap_angle(own[2] - matched[2])))
    return turn, SLIP_LEVER * turn + SLIP_TRAVEL


def _reversed(matched, own) -> bool:
    """A slip's matched step ``matched`` drives against the odometry's ``own`` (their travels point apart) and lies
    farther from it than a slipping wheel could put it for the turn corrected (``_slip_reach``): the match's travel
    is wrong, as a wheel that slips adds travel on its own side and does not turn the robot's travel round; its turn,
    which the scans' walls pin in any direction, is kept. Along a warehouse's racks, which repeat every few tenths of
    a metre, a slip at a reversal was matched from the velocity before it: 0.15 m forward where the robot backed 0.15
    m, four steps in a row, and the estimate 1.19 m off (the plain baseline 0.68 m). "Against" is backwards along the
    odometry's travel by more than ``SLIP_TRAVEL``: a match that stood still where a 40 Hz corridor slip's odometry
    drove 0.24 m (the robot 0.16 m) is left to the checks above (with the odometry's travel it tracked 0.29-0.44 m
    over seeds 1-3, against 0.22-0.34 m)."""
    travel = math.hypot(own[0], own[1])
    # backwards along the odometry's travel by more than SLIP_TRAVEL: a match that stood still is not turned round
    if travel == 0.0 or float(matched[0] * own[0] + matched[1] * own[1]) / travel >= -SLIP_TRAVEL:
        return False
    return math.hypot(matched[0] - own[0], matched[1] - own[1]) > _slip_reach(matched, own)[1]


def _slipped(a, b, step, mount, turn_min: float = SLIP_TURN, off: float = SLIP_OFF) -> bool:
    """The odometry's ``step`` from scan ``a`` to scan ``b`` turned more than the scans did: a wheel that slips
    (see ``SLIP_TURN``; ``turn_min`` and ``off`` its bounds). Scans with too few points to match (an open hall)
    leave it as it was."""
    if abs(float(wrap_angle(step[2]))) < turn_min or not 0.0 < b.t - a.t <= SLIP_DT:
        return False
    pa, pb = far_points(a, MIN_RANGE), far_points(b, MIN_RANGE)
    if pa.shape[1] < MIN_PAIRS or pb.shape[1] < MIN_PAIRS:
        return False
    key = Key(pa)
    few = pb[:, ::max(1, pb.shape[1] // SLIP_POINTS)]  # the distances are means: a few points tell them
    # the laser's step by the odometry, then with its turn left out and halved
    laser, *reduced = (compose(compose(inverse(mount), np.array([step[0], step[1], k * step[2]])), mount)
                       for k in (1.0, 0.0, 0.5))
    at_step, *at_reduced = score_motions(a, key, few, [laser, *reduced])
    # first, without a match: a reduced turn must lie nearer the scans (a real turn's scans fit the odometry's step:
    # infinite_corridor's 391 steps that turn 0.15 rad or more took 1.3 s matched)
    if min(at_reduced) >= SLIP_FIT * at_step:
        return False
    pose, at_pose = _matched(a, key, few, laser)
    if at_pose > min(at_reduced):
        # ICP stopped short of a reduced turn that fits better: from the step as reported a far wall lies metres off,
        # past its pairing (a 25 m lidar's 0.4 rad slip), or it settled half way. Again from that turn, the nearer kept
        again = _matched(a, key, few, reduced[int(np.argmin(at_reduced))])
        pose, at_pose = min((pose, at_pose), again, key=lambda m: m[1])
    if pose is None:
        return False
    turn = float(compose(compose(mount, pose), inverse(mount))[2])  # the robot's, by the scans
    if abs(float(wrap_angle(step[2] - turn))) <= off + SLIP_SHARE * abs(turn):
        return False
    return at_pose < SLIP_FIT * at_step


def _matched(a, key, few, start) -> tuple:
    """(the laser's step matched by ICP from ``start``, ``score_motions`` there), or (None, inf) when under
    ``SLIP_PAIRED`` of the points ``few`` paired."""
    pose, paired, _ = icp(key, few, start, weight=YAW_WEIGHT)
    if paired < SLIP_PAIRED * few.shape[1]:
        return None, math.inf
    return pose, score_motions(a, key, few, [pose])[0]


def _overlap(a, b, step, mount) -> float | None:
    """The share of scan ``b``'s points within ``OVERLAP_M`` of scan ``a``'s when the robot moved ``step`` from
    ``a`` to ``b`` (None when either has under ``MIN_PAIRS`` points)."""
    pa = scan_points(a.ranges, a.angles, a.max_range)
    pb = scan_points(b.ranges, b.angles, b.max_range)
    if pa.shape[1] < MIN_PAIRS or pb.shape[1] < MIN_PAIRS:
        return None
    x, y, th = compose(compose(inverse(mount), step), mount)  # the laser's step
    c, s = math.cos(th), math.sin(th)
    near, _ = Key(pa).tree.query(np.column_stack((c * pb[0] - s * pb[1] + x, s * pb[0] + c * pb[1] + y)),
                                 distance_upper_bound=OVERLAP_M)
    return float(np.mean(np.isfinite(near)))


def _agree(a, b) -> bool:
    """Two steps of the robot the same within ``LOST_M`` m and ``LOST_A`` rad."""
    return math.hypot(a[0] - b[0], a[1] - b[1]) <= LOST_M and abs(float(wrap_angle(a[2] - b[2]))) <= LOST_A


def _same(a, b) -> bool:
    """Two odometry poses the same (the odometry held)."""
    return abs(a[0] - b[0]) < HELD and abs(a[1] - b[1]) < HELD and abs(float(wrap_angle(a[2] - b[2]))) < HELD


def _standing(anchor, s, mount) -> bool:
    """Scan ``s`` matches ``anchor`` (the scan before a hold) at no motion: the robot stood still."""
    key_pts = scan_points(anchor.ranges, anchor.angles, anchor.max_range)
    pts = scan_points(s.ranges, s.angles, s.max_range)
    if key_pts.shape[1] < MIN_PAIRS or pts.shape[1] < MIN_PAIRS:
        return False
    pose, pairs, _ = icp(Key(key_pts), pts, np.zeros(3))
    if pairs < 0.5 * pts.shape[1]:
        return False
    robot = compose(compose(mount, pose), inverse(mount))
    return math.hypot(robot[0], robot[1]) <= STILL_M and abs(float(robot[2])) <= STILL_A
