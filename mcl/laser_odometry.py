"""Laser odometry: the robot's motion from its own scans, for a recording without wheel odometry.

A bag from a robot (or a hand-held rig) that recorded no ``nav_msgs/Odometry`` and no ``odom -> base`` transform
still gives the filter a control ``u_t``: the motion between consecutive scans found by scan matching, as ROS's
laser_scan_matcher does. Each scan is matched to a key scan by point-to-line ICP (Censi, "An ICP variant using a
point-to-line metric", ICRA 2008): the current scan's points are moved by the pose guess, paired with their nearest
key-scan point (``scipy.spatial.cKDTree``), and the pose is the Gauss-Newton step that minimises the distances to
the lines through those points,

    min over (t, theta)  sum_i ( n_j . (R(theta) p_i + t - q_j) )^2 ,

n_j the key scan's normal at q_j (from its neighbours along the scan). Pairs farther than ``max_pair`` are
dropped, as are residuals over three times the median. A direction the scene does not constrain (the axis of a
featureless corridor) has a near-zero eigenvalue in the normal equations; a weak prior at the guess, ``PRIOR``
pairs' worth, keeps the pose there at the guess: the previous step's velocity (constant velocity), the only
evidence there is (in a simulated corridor, without it the matches stuck at the key scan and the motion
decayed to 0 over ten scans). That velocity is smoothed over ``SMOOTH`` s (an exponential average of the
steps): at 40 Hz one scan's step along a corridor is mostly the matcher's noise, and a guess made of it
random-walked (a generated 40 Hz world: the motion over 1 s erred by 0.92 m at the 95th percentile, against
0.05 m smoothed). The key scan is renewed after ``KEY_DISTANCE`` m or ``KEY_ANGLE`` rad, which keeps a
slow robot from accumulating one small error per scan.

The result is in the odometry's form (rows t, x, y, theta, 0, 0 from the first scan at the origin), so the
motion model and its noise (``motion.alpha1..4``) apply unchanged: drift is what the filter corrects.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from mcl.estimate import compose, inverse

KEY_DISTANCE = 0.1  # m: the key scan is renewed once the robot moved this far from it ...
KEY_ANGLE = 0.1  # rad ... or turned this much
PRIOR = 5.0  # the guess weighs as much as this many pairs (per m^2 in x, y; per rad^2 in theta: a 1 m lever)
MAX_POINTS = 540  # a scan's points are thinned to about this many (every k-th)
COARSE = 4.0  # the first iteration pairs points up to COARSE x max_pair apart, the second half that, then max_pair
GOOD_PAIRS = 0.5  # a match pairing fewer of the scan's points is tried from a second start too
MIN_PAIRS = 20  # fewer paired points: the match fails and the step is the guess
MAX_ITERATIONS = 30
SMOOTH = 0.5  # s: the guess is the velocity smoothed over about this long (see the module doc)
SPARSE_DT = 0.5  # s: thorough matching of scans farther apart than this also starts from the turns below
TURNS = (-0.9, -0.6, -0.3, 0.3, 0.6, 0.9)  # rad
SPARSE_PRIOR = 0.5  # ... and the prior weighs this many pairs there
MAX_MISSES = 3  # scans in a row not matched before the constant-velocity guess stops


def scan_points(ranges, angles, max_range: float | None) -> np.ndarray:
    """(2, K) laser-frame points of the returns of a scan (a range above 0, finite, under ``max_range`` when known:
    no-return readings are not points), thinned to about ``MAX_POINTS``, in angular order."""
    r = np.asarray(ranges, dtype=np.float64)
    a = np.asarray(angles, dtype=np.float64)
    ok = np.isfinite(r) & (r > 0.0)
    if max_range is not None:
        ok &= r < float(max_range) - 1e-6
    idx = np.flatnonzero(ok)
    idx = idx[:: max(1, -(-idx.size // MAX_POINTS))]
    return np.vstack((r[idx] * np.cos(a[idx]), r[idx] * np.sin(a[idx])))


def far_points(scan, min_range: float) -> np.ndarray:
    """``scan_points`` of ``scan`` (a record with ranges, angles, max_range) at ``min_range`` m or more from the
    laser: a robot's own frame in view (``mcl.datasets.selfhits``) stays put from scan to scan and would favour the
    smallest motion in a match."""
    pts = scan_points(scan.ranges, scan.angles, scan.max_range)
    return pts[:, pts[0] * pts[0] + pts[1] * pts[1] >= min_range * min_range]


class Key:
    """A key scan: its points, a k-d tree over them, and unit normals (NaN where the neighbours give none)."""

    def __init__(self, pts: np.ndarray):
        self.pts = pts
        self.tree = cKDTree(pts.T)
        k = pts.shape[1]
        n = np.full((2, k), np.nan)
        if k >= 3:
            tang = pts[:, 2:] - pts[:, :-2]  # the line through each point's two neighbours along the scan
            length = np.hypot(tang[0], tang[1])
            rng = np.hypot(pts[0, 1:-1], pts[1, 1:-1])
            good = (length > 1e-9) & (length < np.maximum(0.3, 0.1 * rng))  # not across a gap between objects
            n[0, 1:-1] = np.where(good, -tang[1] / np.where(good, length, 1.0), np.nan)
            n[1, 1:-1] = np.where(good, tang[0] / np.where(good, length, 1.0), np.nan)
        self.normals = n


def icp(key: Key, pts: np.ndarray, guess, max_pair: float = 0.5, prior=None, weight: float = PRIOR):
    """(pose (3,) of the scan ``pts`` in the key scan's frame, paired points, cost) by point-to-line ICP from
    ``guess`` (see the module doc); the pose is ``guess`` and the count 0 when fewer than ``MIN_PAIRS`` pair. The
    cost (to compare starts) sums min(r^2, max_pair^2) over the points, an unpaired point counting max_pair^2,
    and the prior's term.
    ``prior``: where the weak prior sits (default ``guess``); ``weight``: how many pairs it weighs (a measurement of
    the guess's error wants next to none: the prior pulls the match towards the guess)."""
    x, y, th = (float(v) for v in guess)
    gx, gy, gth = (float(v) for v in (guess if prior is None else prior))
    pairs = 0
    for it in range(MAX_ITERATIONS):
        c, s = math.cos(th), math.sin(th)
        px = c * pts[0] - s * pts[1] + x
        py = s * pts[0] + c * pts[1] + y
        reach = max_pair * max(1.0, COARSE * 0.5 ** it)  # coarse to fine
        d, j = key.tree.query(np.column_stack((px, py)), distance_upper_bound=reach)
        m = np.isfinite(d)
        j = np.where(m, j, 0)
        nx, ny = key.normals[0, j], key.normals[1, j]
        m &= np.isfinite(nx)
        if np.count_nonzero(m) < MIN_PAIRS:
            return np.array(guess, dtype=np.float64), 0, math.inf
        nx, ny, jm = nx[m], ny[m], j[m]
        qx, qy, ax, ay = key.pts[0, jm], key.pts[1, jm], px[m], py[m]
        r = nx * (ax - qx) + ny * (ay - qy)
        keep = np.abs(r) <= 3.0 * max(float(np.median(np.abs(r))), 1e-3)
        if np.count_nonzero(keep) < MIN_PAIRS:
            return np.array(guess, dtype=np.float64), 0, math.inf
        nx, ny, ax, ay, r = nx[keep], ny[keep], ax[keep], ay[keep], r[keep]
        jac = np.vstack((nx, ny, nx * -(ay - y) + ny * (ax - x)))  # d r / d (x, y, theta)
        # a weak prior at the guess (PRIOR pairs' worth): it decides only where the scene does not
        h = jac @ jac.T + weight * np.eye(3)
        g = jac @ r + weight * np.array([x - gx, y - gy, math.remainder(th - gth, 2.0 * math.pi)])
        step = np.linalg.solve(h, -g)
        x, y, th = x + step[0], y + step[1], th + step[2]
        pairs = int(r.size)
        cost = (float(np.sum(np.minimum(r * r, max_pair ** 2))) + max_pair ** 2 * (pts.shape[1] - pairs)
                + weight * ((x - gx) ** 2 + (y - gy) ** 2 + math.remainder(th - gth, 2.0 * math.pi) ** 2))
        if it >= 2 and abs(step[0]) + abs(step[1]) < 1e-6 and abs(step[2]) < 1e-6:
            break
    return np.array([x, y, math.atan2(math.sin(th), math.cos(th))]), pairs, cost


def _start(key_pose, laser, step) -> np.ndarray:
    """A match's start (3,) in the key scan's frame (at ``key_pose``): the laser at ``laser`` moved by ``step``
    (x, y, theta in its own frame)."""
    return compose(inverse(key_pose), compose(laser, np.asarray(step, dtype=np.float64)))


def laser_odometry(scans, mount=None, rate0=None, max_misses: int = MAX_MISSES,
                   thorough: bool = False) -> tuple[np.ndarray, int]:
    """(rows (M, 6): t, x, y, theta, 0, 0 of the robot at each scan, the first at the origin; how many scans after
    the first were not matched: too few points, no pairs, or no scan with returns enough before them) for
    ``scans`` (records with t, ranges, angles, max_range, in time order; scans of one laser). ``mount``: the
    laser's pose (3,) on the robot (None: at its centre); the scans give the laser's motion, turned into the
    robot's. A scan not matched takes the last step again (``max_misses`` in a row: no motion). ``rate0``: the
    laser's velocity (3,) (m/s, m/s, rad/s, its own frame) at the first scan, the first match's guess and prior
    (the velocity after it is the matches'), or several (K, 3), the first so and the others more starts; the scans
    before the first with returns enough to match against drive on straight at the first's speed (None: at rest).
    ``thorough``: every scan is matched from three starts, the last step again, the same without its turn, and no
    motion, and the best match kept (a turn that did not go on led the match into a wrong place: a sparse hall
    scanned at 2 Hz); scans more than ``SPARSE_DT`` s apart also from ``TURNS``, standing and at the last step (a
    thinned log, a scan every 3-6 s: the match from no motion settled 1.8 m from where a start turned 0.4 rad did);
    a nearer scan whose best match pairs under ``GOOD_PAIRS`` of its points also from ``TURNS`` standing (a robot
    that braked and spun on the spot: the three starts all drove on)."""
    mount = np.zeros(3) if mount is None else np.asarray(mount, dtype=np.float64)
    mount_inv = inverse(mount)
    rows = []
    laser = np.zeros(3)  # the laser's pose in the odometry frame of the laser's first pose
    key, key_pose = None, np.zeros(3)
    velocity = np.zeros(3)  # the last step, in the laser's frame
    failed = misses = 0
    rate = np.zeros(3)  # smoothed velocity (m/s, m/s, rad/s) in the laser's frame
    t_prev, started = None, False
    rates0 = None if rate0 is None else np.atleast_2d(np.asarray(rate0, dtype=np.float64))
    for scan in scans:
        pts = scan_points(scan.ranges, scan.angles, scan.max_range)
        if key is None:  # no scan with returns enough yet: this one is not matched (and counts so after the first)
            failed += bool(rows)
            if rows and rates0 is not None:  # ... and drives on straight at the known speed
                laser = compose(laser, np.array([rates0[0, 0], rates0[0, 1], 0.0]) * (float(scan.t) - t_prev))
            if pts.shape[1] >= MIN_PAIRS:
                key, key_pose = Key(pts), laser.copy()
        else:
            # from the last step again (constant velocity); when under GOOD_PAIRS of the points pair, from no
            # motion too, the better match kept (a robot that stopped turning or reversed: the old velocity led
            # into a wrong match); the prior stays at constant velocity for both
            others = []
            if rates0 is not None:  # known velocities at the start: the first match's guess and prior, other starts
                velocity, *others = rates0 * (float(scan.t) - t_prev)
                rates0 = None
            guesses = [_start(key_pose, laser, v) for v in (velocity, *others, np.zeros(3))]
            rel, pairs = guesses[0], 0
            if pts.shape[1] >= MIN_PAIRS:
                sparse = thorough and float(scan.t) - t_prev > SPARSE_DT
                # scans far apart: the constant-velocity guess says little, and its prior only breaks ties
                weight = SPARSE_PRIOR if sparse else PRIOR

                def better(best, starts):
                    """The lowest-cost of ``best`` and the matches from ``starts`` (the first on ties), each with
                    its weak prior at the constant-velocity guess."""
                    return min([best, *(icp(key, pts, g, prior=guesses[0], weight=weight) for g in starts)],
                               key=lambda m: m[2])

                best = icp(key, pts, guesses[0], weight=weight)
                if thorough:
                    guesses.insert(1, _start(key_pose, laser, (velocity[0], velocity[1], 0.0)))  # without its turn
                if sparse:  # turned starts too, standing and at the last step
                    guesses += [_start(key_pose, laser, (x, y, a))
                                for a in TURNS for x, y in ((0.0, 0.0), (velocity[0], velocity[1]))]
                if thorough or best[1] < GOOD_PAIRS * pts.shape[1]:
                    best = better(best, guesses[1:])
                if thorough and not sparse and best[1] < GOOD_PAIRS * pts.shape[1]:
                    # none of the starts pairs half the points: the robot may have stopped and turned on the spot
                    # (belgioioso at 18.8 s: from 5 m/s to a spin of -3 rad/s), so turned starts from standing too
                    best = better(best, [_start(key_pose, laser, (0.0, 0.0, a)) for a in TURNS])
                rel, pairs, _ = best
            failed += pairs == 0
            misses = 0 if pairs else misses + 1
            new = compose(key_pose, rel)
            # a scan not matched took the last step again; after MAX_MISSES such in a row, no more guessing
            step = compose(inverse(laser), new)
            dt = float(scan.t) - t_prev
            if misses >= max_misses:
                velocity = np.zeros(3)
            elif SMOOTH > 0 and dt > 0:
                # the guess for the next scan: the velocity smoothed over about SMOOTH s, scaled to this step's dt
                w = 1.0 - math.exp(-dt / SMOOTH) if started else 1.0
                rate = (1.0 - w) * rate + w * step / dt
                started = True
                velocity = rate * dt
            else:
                velocity = step
            laser = new
            if pts.shape[1] >= MIN_PAIRS and (math.hypot(rel[0], rel[1]) > KEY_DISTANCE or abs(rel[2]) > KEY_ANGLE
                                             or pairs == 0):
                key, key_pose = Key(pts), laser.copy()
        t_prev = float(scan.t)
        robot = compose(compose(mount, laser), mount_inv)  # the robot's pose, its first at the origin
        rows.append((float(scan.t), *robot, 0.0, 0.0))
    return np.array(rows, dtype=np.float64).reshape(-1, 6), failed
