"""Localization quality: how well the scan fits the map at the estimate, and whether the filter is lost.

At every update the scan is laid on the map from the estimate (one pose, K
beams, no particles involved), and each beam with a return is classed:

* **matched**: its endpoint lies within ``quality.distance`` of a mapped
  obstacle (the distance field the likelihood field already tabulates);
* **contradicting**: not matched, and the reading went *through* a mapped
  obstacle on its way (an exact ray walk from the laser to the endpoint);
* otherwise **short**: it ends in free space in front of the mapped surface,
  as a reading of a person or a box the map lacks does.

``match`` = matched / K is the quality signal, ``contradiction`` =
contradicting / K its complement for clutter: an unmapped obstacle lowers
``match`` but cannot make a reading contradict the map, so the lost test
weighs both: ``score = match - 2 contradiction``. Unlike the mean
likelihood of augmented MCL (Table 8.3), neither depends on the scene: open
halls and long corridors lower the likelihood at the true pose (fewer beams
return, the returns are farther), but the beams that do return still end on
mapped walls. Measured on the tracked updates of intel_lab, aces, fr101 and
belgioioso (0.3 m): ``match`` has a 1st percentile of 0.81-0.90 at the
estimate, against medians of 0.34-0.55 for poses 0.5 m away and 0.09-0.32
5 m away. Over single updates of the eight real logs and two cluttered
simulated worlds, ``score < 0.6`` flagged none of the updates at the
reference pose on the real logs and 2.3 % in the worst cluttered world,
and 94-100 % of the poses 1 m off (``match < 0.6`` alone: 81-99 %).

An update is **bad** when its score is below ``quality.lost_below`` (or,
when not one of its beams went through a mapped wall, its match below
``quality.occluded_below``: every unmatched reading ends short of the map,
as people crowding the robot make them, and nothing contradicts the place;
see :meth:`ScanQuality.bad`). Beams through a wall that end within
``quality.occluded_depth`` of a mapped obstacle do not count against the
occlusion rule: an estimate 0.2-0.3 m off, as people pulling at the cloud
leave it, sees a few walls 0.35-0.55 m farther than the map has them. The
filter believes it is **lost** once ``lost_after`` of the last
``2 lost_after - 1`` updates with a scan were bad, and no longer lost once
at most ``lost_after // 2`` of them were (3 of 5, and 1 of 5, by default; a window still filling after a
reset clears with 3 updates or more, at most half of them bad):
a window rather than a run, because a slipped track fits now and then. One
update whose score is below ``quality.lost_at_once_below`` (0 by default:
more beams through walls than twice the beams that match) calls it lost at
once: a kidnapped robot's first scan scores -0.9 to 0.3 in most generated
worlds, correct tracks never fell below 0.3 there nor below 0.5 on the real
logs, and on a log with a scan every 3 s three bad updates take 6 s more.
The default recovery (``filter.recovery: lost``) injects particles only
while the filter is lost.

After a lost episode the test doubts for ``doubt_updates`` updates from the lost call: an update is bad also when
its score is ``doubt_margin`` below the median score of the track held before the episode (its last
``DOUBT_HISTORY`` held updates). The place a kidnapped robot's recovery finds can fit above ``lost_below`` and
still worse than the track did (suites/synthetic.yaml ``office-short-range-01``: 0.74-0.87 against 0.95-1.0);
the margin is relative to the track, so a place that always fitted at 0.7 (clutter) is not doubted at 0.7.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from mcl.kernels.field import field_at
from mcl.kernels.raycast import segments_blocked
from mcl.maps import byte_mask
from mcl.sensors import cast_from_laser


DOUBT_HISTORY = 50  # held updates whose median score is the track's score before a lost episode


def endpoint_distances(dist, origin, resolution: float, pose, endpoints) -> np.ndarray:
    """(K,) float32: the distance field ``dist`` (m to the nearest mapped obstacle, row 0 at y = origin[1]) at the
    robot-frame ``endpoints`` (2, K) seen from ``pose`` (x, y, theta); NaN off the map (no comparison holds).
    One numba pass (``mcl.kernels.field.field_at``)."""
    e = np.ascontiguousarray(endpoints, dtype=np.float64)
    th = float(pose[2])
    out = np.empty(e.shape[1], dtype=np.float32)
    field_at(dist, float(origin[0]), float(origin[1]), float(resolution), float(pose[0]), float(pose[1]),
             math.cos(th), math.sin(th), e, out)
    return out


@dataclass(frozen=True)
class Fit:
    """The scan laid on the map at one pose."""

    beams: int  # beams with a return
    match: float  # fraction of them whose endpoint is within the distance of a mapped obstacle (nan: no beam)
    contradiction: float  # fraction that went through a mapped obstacle and end away from one (nan: no beam)
    deep: float | None = None  # fraction that went through one and end farther than quality.occluded_depth from
    #                            every mapped obstacle (ScanQuality.fit measures it; None: taken as contradiction)
    predicted: int | None = None  # of the scan's scored directions, those where the map shows an obstacle within
    #                               the laser's reach from the pose (ScanQuality.missing; None: not measured)
    missing: int | None = None  # ... of them, those whose reading shows no return or ends past it
    directions: int | None = None  # the scored directions cast (predicted and missing are out of them)

    @property
    def deep_through(self) -> float:
        """The fraction of beams that went through a mapped obstacle and end deeper than ``occluded_depth`` past
        the map (``contradiction`` when not measured)."""
        return self.contradiction if self.deep is None else self.deep

    @property
    def score(self) -> float:
        """match - 2 contradiction: what the lost test compares with ``quality.lost_below``."""
        return self.match - 2.0 * self.contradiction


class ScanQuality:
    """Scan-to-map fit at a pose (``fit``) and the lost belief over updates (``update``).

    ``grid`` needs ``distance``, ``occupied``, ``origin``, ``resolution``;
    ``cfg`` is the ``quality`` config section (distance, lost_below,
    lost_after).
    """

    view_share = 1.0  # the scans' field of view over 180 degrees, at most 1 (view); 1 until a scan says

    def __init__(self, grid, cfg, scored_beams: int | None = None):
        self.cfg = cfg
        # a held track's bar (held_min_beams), at most a quarter of the beams scored a scan (sensor.max_beams)
        held = int(cfg.held_min_beams)
        self.held_min_beams = min(held, scored_beams // 4) if scored_beams is not None else held
        self.dist = np.ascontiguousarray(grid.distance, dtype=np.float32)
        self.blocked = byte_mask(grid.occupied)
        self.origin = (float(grid.origin[0]), float(grid.origin[1]))
        self.resolution = float(grid.resolution)
        self.lost = False
        self.collapsed = False  # this update's lost call was a collapse (update)
        self.crept = False  # the lost episode began on a held track whose fit had crept down (update, refutes)
        # updates since the belief was last lost (None: not since the reset, or held again: quality.held_again)
        self.since_lost: int | None = None
        self._from_pose = True  # the reset started a track from a known pose (not a global search): held_again
        self._recent: deque[bool] = deque(maxlen=2 * cfg.lost_after - 1)  # bad or not, last updates with a scan
        self._scores: deque[float] = deque(maxlen=2 * cfg.lost_after - 1)  # their scores
        self._held: deque[float] = deque(maxlen=DOUBT_HISTORY)  # scores of the updates held (not lost, no doubt)
        self._before: float | None = None  # the held track's median score when the last lost episode began
        self._since_episode = 0  # updates since that episode began
        self._pool: list[Fit] = []  # a held track's sparse fits not yet counted (_pooled)

    def view(self, angles) -> None:
        """Take the field of view of the scans to come from their beam ``angles`` (laser frame, rad).

        With ``quality.narrow_view: scaled`` (the default), a scan narrower than 180 degrees has ``occluded_below`` and
        ``occlusion_match`` times its field of view over 180 degrees, ``occluded_depth`` times its square root
        (:attr:`occluded_depth`), and ``occluded_prior`` over it (:meth:`_creeping`): a person a metre away fills a
        third of a depth camera's 59-degree view and a tenth of a 180-degree laser's. People crowding a 59-degree, 4.5 m
        view left a correct track at match 0.29-0.43 with no beam through a wall; called lost and refuted at once, the
        spread's best pose 1.2 m away, where they line up with walls, took it (suites/depth-laser.yaml clutter-kinect,
        every seed of 6: docs/measurements.md, "Fifty-first session")."""
        share = 1.0
        if self.cfg.narrow_view == "scaled":
            a = np.asarray(angles, dtype=np.float64)
            # each beam covers one increment: 180 beams 1 degree apart (aces, intel_lab: 179 degrees first to last)
            # see 180 degrees, as 181 over 180 do
            fov = float(np.max(a) - np.min(a)) * a.size / (a.size - 1) if a.size > 1 else math.nan
            if 0.0 < fov < math.pi * (1.0 - 1e-9):  # NaN too: as given
                share = fov / math.pi
        self.view_share = share

    @property
    def occluded_below(self) -> float:
        """``quality.occluded_below`` for this scan's field of view (:meth:`view`)."""
        return self.cfg.occluded_below * self.view_share

    @property
    def occluded_depth(self) -> float:
        """``quality.occluded_depth`` for this scan's field of view (:meth:`view`): times the square root of its share
        of 180 degrees (a 59-degree depth camera's 1.0 m is 0.57 m). Among people, turned at 1.5 rad/s, a wide view's
        near misses on a correct track reach 0.6-1.0 m past walls (suites/heldout21.yaml clutter-stalls-turns: lost
        at 0.6 m, kept at 1.0); a narrow view's few beams through walls at a wrong place end about as shallow
        (suites/heldout.yaml clutter-kinect-h8: kept at 0.6 m, lost at 1.0)."""
        return self.cfg.occluded_depth * math.sqrt(self.view_share)

    @property
    def occlusion_match(self) -> float:
        """``quality.occlusion_match`` for this scan's field of view (:meth:`view`)."""
        return self.cfg.occlusion_match * self.view_share

    def fit(self, pose, endpoints, laser_xy=(0.0, 0.0)) -> Fit:
        """Class the beams of robot-frame ``endpoints`` (2, K) seen from ``pose`` (x, y, theta)."""
        e = np.ascontiguousarray(endpoints, dtype=np.float64)
        k = e.shape[1]
        if k == 0:
            return Fit(0, math.nan, math.nan)
        x, y, th = (float(v) for v in pose[:3])
        d = endpoint_distances(self.dist, self.origin, self.resolution, pose, e)
        matched = d <= self.cfg.distance
        rest = np.flatnonzero(~matched)
        through = np.zeros(rest.size, dtype=np.bool_)
        if rest.size:
            segments_blocked(x, y, th, float(laser_xy[0]), float(laser_xy[1]), np.ascontiguousarray(e[:, rest]),
                             self.blocked, self.origin[0], self.origin[1], self.resolution, through)
        # deep: through and not within occluded_depth of the map (NaN, off the map, is within none; with a depth of 0
        # every beam through is deep, as an unmatched endpoint lies farther than quality.distance from the map)
        deep = through & ~(d[rest] <= self.occluded_depth)
        return Fit(k, float(np.count_nonzero(matched)) / k, float(np.count_nonzero(through)) / k,
                   float(np.count_nonzero(deep)) / k)

    def occluded_call(self, fit: Fit | None) -> bool:
        """Whether :meth:`update` would call ``fit`` bad for its match alone (:meth:`_match_alone`, with the near
        misses exempt as :meth:`update` exempts them now) and ``occluded_missing`` is on: then :meth:`missing`
        tells occlusion from a wrong place. Asked before :meth:`update` folds ``fit`` in."""
        return (self.cfg.occluded_missing >= 0.0 and fit is not None and fit.beams >= self.cfg.min_beams
                and self._match_alone(fit, self._creeping())
                and fit.match < min(self.cfg.lost_below, self.occluded_below))

    def _match_alone(self, fit: Fit, near_misses: bool) -> bool:
        """No reading ended past a wall (with ``near_misses``, none deeper than ``occluded_depth``): the rest end
        short of the map, or just past a wall (the near misses of an estimate a little off), and only the match
        counts in :meth:`bad`."""
        return (fit.deep_through if near_misses else fit.contradiction) == 0.0

    def missing(self, pose, laser_pose, angles, returned, ranges, reach: float) -> tuple[int, int]:
        """(predicted, missing) over the directions ``angles`` (laser frame) of one scan, seen from the laser at
        ``laser_pose`` (robot frame) on ``pose``: the directions where the map shows an obstacle within ``reach``,
        and of those the ones whose reading (``ranges``, ``returned``: with a return) shows none or ends more
        than ``quality.distance`` past it. People hide what the map shows, they do not remove it: at the true
        pose among people nearly every predicted obstacle is read, or read short; at a wrong place the map's
        obstacles are where the laser saw none."""
        z = cast_from_laser(self.blocked, self.origin, self.resolution, pose, laser_pose, angles, reach)
        predicted = z < float(reach) - self.resolution
        gone = predicted & (~returned | (ranges > z + self.cfg.distance))
        return int(np.count_nonzero(predicted)), int(np.count_nonzero(gone))

    def _view_explains(self, fit: Fit) -> bool:
        """Whether ``Fit.predicted`` / ``missing`` (measured: :meth:`occluded_call`) explain a low match as people:
        in a sparse view (the map shows obstacles in at most half the directions) what it shows is there
        (matched) or hidden behind something nearer, at most ``occluded_missing`` of it missing, and the unmatched
        rest lies on open floor; or the map shows the laser fewer than ``min_beams`` obstacles, nothing to judge
        by. In a dense view a match this low is a wrong place: a robot kidnapped into a smaller room reads every
        wall short (the demo: 44 of 60 directions shown, none missing, match 0.13-0.21).

        Nor does a sparse view whose returns on open floor (neither matched nor through a wall) number more than
        ``occluded_open`` of the scored directions: people fill a few of them (the sparse hall's crowd at the true
        pose: 5-14 of 60), a wrong place's own walls most. aces, its filter kidnapped (seed 2): 36 and 50 of 60 on
        open floor, the map showing 12 and 22 obstacles all there; taken for people, the lost call came 25 s late.
        Where the map shows fewer than ``min_beams`` there is still nothing to judge by: a laser tilted onto the
        floor of an open hall puts 55-78 % of the directions' returns there at the true pose, 2-3 obstacles shown."""
        if fit.predicted is None:
            return False
        if fit.predicted < self.cfg.min_beams:
            return True
        if (fit.directions is not None
                and fit.beams * (1.0 - fit.match - fit.contradiction) > self.cfg.occluded_open * fit.directions):
            return False
        return (fit.directions is not None and 2 * fit.predicted <= fit.directions
                and fit.missing <= self.cfg.occluded_missing * fit.predicted)

    def bad(self, fit: Fit, near_misses: bool = False) -> bool:
        """Whether one update's fit says the estimate is wrong (no beam: no evidence either way, not bad).

        A scan with no beam through a mapped wall is bad only when its match is below ``occluded_below`` (when
        that is lower than ``lost_below``): its unmatched readings all end short of the map, as readings of people
        and furniture the map lacks do, and nothing it saw contradicts the place. Beams through a wall that end
        within ``occluded_depth`` of a mapped obstacle (``Fit.deep``) are near misses here, not contradictions;
        ``contradiction_above`` still counts them. With ``near_misses`` False (the default) every beam through a
        wall counts; :meth:`update` passes True only when its gates allow (``_creeping``). Below ``occluded_below``
        too, such a scan is no evidence when ``Fit.predicted`` / ``missing`` (:meth:`missing`, measured by the
        filter when :meth:`occluded_call`) say that what the map shows the laser is there or hidden: at most
        ``occluded_missing`` of it missing, or fewer than ``min_beams`` obstacles shown."""
        if fit.beams < self.cfg.min_beams:
            return False
        c = self.cfg.contradiction_above
        below = self.cfg.lost_below
        if self._match_alone(fit, near_misses):
            occluded = min(below, self.occluded_below)
            return (fit.match < occluded and not self._view_explains(fit)) or (c > 0.0 and fit.contradiction >= c)
        return fit.score < below or (c > 0.0 and fit.contradiction >= c)

    def refutes(self, fit: Fit | None) -> bool:
        """Whether one scan refutes the estimate rather than looking occluded: ``contradiction_above`` of its beams
        or more went through mapped walls, or under ``occlusion_match`` of them match the map (most end far from
        any wall, in front of it or past it). Lost recovery spreads poses at once on such a scan and waits
        (``filter.recovery_wait``) on the others: people in a depth camera's narrow view left a correct track at
        match 0.52 with 3-7 % through walls, while a kidnapped robot's first scans match 0-0.35. Fewer than
        ``min_beams`` beams: no evidence, not refuted."""
        if fit is None or fit.beams < self.cfg.min_beams:
            return False
        c = self.cfg.contradiction_above
        if c > 0.0 and fit.contradiction >= c:
            return True
        # A crowd closing round the robot over seconds takes a held track's match as low, nothing deeper than
        # occluded_depth through walls: in an episode that began on such a crept fit (``crept``) the match alone
        # refutes nothing, and the spread waits as for an occlusion. A kidnap drops a held 0.9-1.0 at once. (24
        # people round a robot in an office, the match 0.70 to 0.29 over 2 s: spread at once, the estimate went
        # 1.1 m off to a pose the crowd fitted at 0.60; generated world w4347 of the ninety-third session.)
        return fit.match < self.occlusion_match and not (self.lost and self.crept and fit.deep_through == 0.0)

    def _doubting(self) -> bool:
        """Within ``doubt_updates`` updates from the start of a lost episode, with a score from before it (bounded
        from the start, not the end: a correct track that fits worse than before, in a cluttered place, is not
        kept lost for ever)."""
        return (self._before is not None and self.cfg.doubt_margin > 0.0
                and self._since_episode < self.cfg.doubt_updates)

    def _bad_now(self, fit: Fit) -> bool:
        """:meth:`bad`, or, in doubt after a lost episode, a score ``doubt_margin`` below the track's before it: a
        place the recovery found that fits, but worse than the track fitted (a kidnapped robot's look-alike)."""
        return (self.bad(fit, self._creeping())
                or (self._doubting() and fit.score < self._before - self.cfg.doubt_margin))

    def _evidence_beams(self) -> int:
        """The returns a fit needs to count in the lost belief: ``min_beams``, or on a track from a known pose not yet
        believed lost (held from the start) ``held_min_beams`` if larger. A hall under a 12 m laser returns 3-14 of 60
        scored beams, people and unmapped boxes among them: such scans called correct tracks lost, and the re-seeds
        that followed settled 14-45 m away on places that fitted a few returns (suites/heldout15.yaml), where the
        baseline, never lost, drifted 1 m. After a lost call, and for a place a search found, ``min_beams`` holds: a
        search must leave a wrong place on the few returns there are (with the bar on every track held 50 updates,
        large-06's global searches left a wrong place 1-6 s later). The bar is at most a quarter of the beams a scan
        is scored on (``scored_beams``, sensor.max_beams: 15 of the default 60). A track from a known pose is held
        again ``held_again`` updates after its last lost call (:meth:`update`): one lost episode, right at the time,
        otherwise took the bar for good (a hall among unmapped furniture, 26 s later: 27 m away)."""
        held = self.since_lost is None  # not lost since a start from a known pose, or since held_again updates
        return self.held_bar if held else self.cfg.min_beams

    @property
    def held_bar(self) -> int:
        """The returns a held track's scan needs to count (``min_beams``, or ``held_min_beams`` if larger); a protected
        re-seed's scan needs as many to decide at once (``mcl.adaptive.ProtectedReseed``)."""
        return max(self.cfg.min_beams, self.held_min_beams)

    def _creeping(self) -> bool:
        """Whether the near misses of ``occluded_depth`` are exempt now: on a held track (not lost in the last
        ``doubt_updates`` updates; from a known pose, held from the start), and no score of the last
        ``2 lost_after - 1`` updates reached ``occluded_prior`` (the fit had already sunk). People close round a
        robot over seconds; a kidnap, or a slip to a wrong place, takes the score from a held track's 0.9-1.0 in
        one update. A place a search has just settled on is no held track: its scores were low all along.

        A narrow view (``quality.narrow_view: scaled``, :meth:`view`) has ``occluded_prior`` over its field of view's
        share of 180 degrees (above 1, so no gate, under 126 degrees): people walking into a 59-degree view fill it
        within a few scans. suites/depth-laser.yaml clutter-kinect at 29 s: 0.77, 0.74, 0.66, 0.5, 0.42, 0.34 at the
        true pose, 5-10 % of the beams just past walls (seed 2); with the gate, lost, and the spread took the track
        2.5 m away (the world lost on every seed of 6 with the thresholds scaled alone, kept on every seed now)."""
        if self.since_lost is not None and self.since_lost < self.cfg.doubt_updates:
            return False
        p = self.cfg.occluded_prior / self.view_share
        return p > 1.0 or (len(self._scores) > 0 and max(self._scores) < p)

    def _crept_down(self) -> bool:
        """:meth:`_creeping` where ``occluded_prior`` gates (a view of 126 degrees or more): on a held track, no score
        of the last ``2 lost_after - 1`` updates reached it. A narrow view, where it gates nothing, is never crept:
        a kidnapped depth camera's scans match 0-0.1, and only their match refutes them."""
        p = self.cfg.occluded_prior / self.view_share
        return p <= 1.0 and self._creeping()

    def pools(self, fit: Fit | None) -> bool:
        """Whether ``fit`` is a sparse scan on a held track, to be pooled (``held_pool_beams`` > 0): at least
        ``min_beams`` returns, fewer than ``held_min_beams`` (:meth:`_evidence_beams`). The filter measures
        ``Fit.predicted`` / ``missing`` on each, so that the pool can sum them."""
        return (self.cfg.held_pool_beams > 0 and fit is not None
                and self.cfg.min_beams <= fit.beams < self._evidence_beams())

    def _pooled(self, fit: Fit) -> Fit | None:
        """Add a sparse held fit (:meth:`pools`) to the pool; once the pool holds ``held_pool_beams`` returns (and at
        least the held bar), empty it and return its fit, the fractions weighted by returns (None until then). A
        scan of few returns is weak evidence, not none: a robot kidnapped in a hall under a 12 m laser read 2-11
        returns a scan, every one far from the map at the estimate, and with such scans ignored it was not called
        lost for 66 s (suites/heldout16.yaml hall-yaw-drift-long). The pool holds a full scan's worth (60): with 15,
        people and unmapped boxes in a sparse hall called a correct track lost over a few scans (heldout15.yaml
        hall-stale-both-people: 45-52 m off), as with no bar."""
        self._pool.append(fit)
        n = sum(f.beams for f in self._pool)
        if n < max(self.cfg.held_pool_beams, self._evidence_beams()):
            return None
        pool, self._pool = self._pool, []

        def share(frac):
            return sum(frac(f) * f.beams for f in pool) / n

        # the view's counts add up over scans (the filter measures them on every pooled scan: _with_missing)
        measured = all(f.predicted is not None and f.directions is not None for f in pool)
        return Fit(n, share(lambda f: f.match), share(lambda f: f.contradiction), share(lambda f: f.deep_through),
                   *((sum(f.predicted for f in pool), sum(f.missing for f in pool), sum(f.directions for f in pool))
                     if measured else (None, None, None)))

    def update(self, fit: Fit | None) -> bool:
        """Fold one update's fit into the lost belief (None or fewer than ``min_beams`` beams: no evidence, the
        belief stays) and count ``since_lost``; return the belief. A held track's sparse scans (:meth:`pools`) count
        together, once they hold ``held_pool_beams`` returns (:meth:`_pooled`); a scan of more returns empties the
        pool, being newer. ``collapsed`` says whether this update's lost call was a collapse: at once
        (``lost_at_once_below``) from a track whose last ``2 lost_after - 1`` scores were all at least
        ``collapse_from``."""
        self.collapsed = False
        crept = self._crept_down()  # as the track was before this scan (a lost call sets since_lost)
        if self.pools(fit):
            fit = self._pooled(fit)
        elif fit is not None and fit.beams >= self._evidence_beams():
            self._pool = []
        if fit is not None and fit.beams >= self._evidence_beams():
            at_once = fit.score < self.cfg.lost_at_once_below
            # a collapse is judged on the scores before this one joins them
            scores = self._scores
            collapse = at_once and len(scores) == scores.maxlen and min(scores) >= self.cfg.collapse_from
            self._recent.append(self._bad_now(fit))
            if not math.isnan(fit.score):
                self._scores.append(fit.score)
            n_bad = sum(self._recent)
            k = self.cfg.lost_after
            if not self.lost and (n_bad >= k or at_once):
                self.lost = True
                self.collapsed = collapse
                self.crept = crept
                if not self._doubting():  # a new episode: the track before it is the reference
                    self._before = float(np.median(self._held)) if len(self._held) >= DOUBT_HISTORY // 2 else None
                    self._since_episode = -1  # 0 after this update
            elif self.lost and len(self._recent) >= min(k, 3) and n_bad <= min(len(self._recent), k) // 2:
                # at most half the window bad; after a reset (a global start) the window is still filling: a large
                # lost_after (slower to call lost) kept a converged search "lost", re-seeding it, for k updates
                self.lost = False
            if not self.lost and not self._doubting() and not math.isnan(fit.score):
                self._held.append(fit.score)
        self._since_episode += 1
        if self.lost:
            self.since_lost = 0
        elif self.since_lost is not None:
            self.since_lost += 1
            if self._from_pose and 0 < self.cfg.held_again <= self.since_lost:
                self.since_lost = None  # held again (quality.held_again)
        return self.lost

    def reset(self, lost: bool) -> None:
        """Start over with a belief (lost after a global initialisation, not lost when tracking from a pose)."""
        self.lost = lost
        self.collapsed = False
        self.crept = False
        self.since_lost = 0 if lost else None
        self._from_pose = not lost
        self._recent.clear()
        self._scores.clear()
        self._held.clear()
        self._before = None
        self._since_episode = 0
        self._pool = []
