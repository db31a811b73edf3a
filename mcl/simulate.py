"""Synthetic indoor world, robot drive, noisy CARMEN log and exact truth.

``simulate(outdir, seed=...)`` writes a complete data set, deterministic for
a seed:

``map.yaml`` + ``map.pgm``
    The floor plan of ``kind`` (``mcl.worlds``: office, rooms, corridor,
    hall, clutter, large, warehouse). The default office (0.05 m cells): outer walls around a building of about
    20 m x 15 m with a corner cut off, a main corridor and a side corridor,
    rooms from a random binary space partition joined by doorways (a random
    spanning tree of the room adjacency graph plus extra doors), furniture
    and pillars. Unknown (205) outside the outer walls.
``log.clf``
    CARMEN: ``ODOM`` lines at 10 Hz and ``FLASER`` lines at 5 Hz (181 beams
    over pi, beam i at -pi/2 + i*pi/180, counter-clockwise, laser at the
    robot centre). Geometries that FLASER cannot express are written as
    ``ROBOTLASER1``, which carries its own start angle and resolution.
    Poses are in the odometry frame, which starts at (0, 0, 0).
``truth.tum``
    The true pose in the map frame at every scan timestamp.
``sim.yaml``
    Every parameter used, the true start pose (for tracking configs) and the
    kidnapping, if any.

The random streams of the world, the drive, the odometry noise and the
sensor noise are independent children of one ``SeedSequence(seed)``, so
changing, say, the sensor noise leaves the world and the path unchanged.

Odometry noise is the sample_motion_model_odometry of Probabilistic
Robotics (Table 5.6), in its variance form: each tick's true motion
(rot1, trans, rot2) is perturbed with variances ``a1*rot^2 + a2*trans^2``
(rotations) and ``a3*trans^2 + a4*(rot1^2 + rot2^2)`` (translation), then a
systematic drift is applied (a scale on translation and a yaw bias per
metre), as real wheel odometry has. As in the filter's model (and ROS AMCL's),
each rot in a variance is min(|rot|, |rot -+ pi|): a step backwards reads
rot1 ~ pi, and the book's formula as printed would give it pi-sized heading
noise that no wheel odometry has.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import math
import os
import sys
from pathlib import Path

import numpy as np

from mcl.errors import ConfigError
__all__ = ["simulate", "make_world", "World", "add_arguments", "run_from_args", "simulator_stamp"]

from mcl.worlds import (  # noqa: F401  (RESOLUTION, make_world, World: importable from here as before)
    KIND_DEFAULTS, KINDS, RESOLUTION, World, _components, generate, make_world,
)

_ODOM_RATE = 10.0  # Hz, truth and ODOM: the lowest rate, and the rate at the default 5 Hz scan rate
_SIM_DT = 0.01  # integration step, s
_NOISE_BLOCK = 1 << 20  # readings a block of the laser's noise draws (8 MB a float array)
_LOG_BLOCK_LINES = 2000  # log lines formatted before they are written


# The sources whose code decides a generated world's bytes (the floor plan, the drive, the readings, the files).
_WORLD_SOURCES = ("simulate.py", "worlds.py", "depthsim.py", "kernels/raycast.py", "datasets/bagwrite.py")


def simulator_stamp() -> str:
    """A short hash of the code that makes a world (``_WORLD_SOURCES``), for caches of generated worlds (``mcl eval
    --suite``'s, the scripts'): keyed on the keywords alone, a cache kept serving worlds of an older simulator."""
    global _STAMP
    if _STAMP is None:
        h = hashlib.sha1()
        root = Path(__file__).resolve().parent
        for name in _WORLD_SOURCES:
            h.update(name.encode() + b"\0" + (root / name).read_bytes())
        _STAMP = h.hexdigest()[:8]
    return _STAMP


_STAMP: str | None = None


def _rates(scan_rate: float) -> tuple[float, int, float]:
    """(odometry rate Hz, odometry ticks per scan, integration step s) for a laser at ``scan_rate`` Hz: the odometry
    at 10 Hz or more and a whole multiple of the scan rate, the step about 10 ms and a whole fraction of a tick. At
    5 Hz these are the module's constants (10 Hz, 2, 10 ms), so the default worlds stay what they were."""
    every = max(1, math.ceil(_ODOM_RATE / scan_rate - 1e-9))
    odom = scan_rate * every
    per_tick = max(1, int(round(1.0 / (odom * _SIM_DT))))
    return odom, every, 1.0 / (odom * per_tick)


# --------------------------------------------------------------------------
# Drive
# --------------------------------------------------------------------------

class _Planner:
    """Shortest paths over reachable cells (8-connected) that keep away from walls."""

    def __init__(self, world: World):
        from scipy.sparse import csr_matrix

        self.world = world
        reach = world.reachable
        h, w = reach.shape
        self.node = np.full(reach.shape, -1, dtype=np.int64)
        iy, ix = np.nonzero(reach)
        self.iy, self.ix = iy, ix
        self.node[iy, ix] = np.arange(iy.size)
        d = world.distance
        rows, cols, vals = [], [], []
        for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
            jy, jx = iy + dy, ix + dx
            ok = (jy >= 0) & (jy < h) & (jx >= 0) & (jx < w)
            ok[ok] &= reach[jy[ok], jx[ok]]
            a = self.node[iy[ok], ix[ok]]
            b = self.node[jy[ok], jx[ok]]
            dm = 0.5 * (d[iy[ok], ix[ok]] + d[jy[ok], jx[ok]])
            # prefer the middle of corridors and doorways: up to 4x cost near walls
            cost = math.hypot(dx, dy) * world.resolution * (1.0 + 3.0 * np.clip(1.0 - dm, 0.0, None))
            rows += [a, b]
            cols += [b, a]
            vals += [cost, cost]
        n = iy.size
        self.graph = csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                shape=(n, n))

    def xy(self, nodes):
        ox, oy = self.world.origin
        r = self.world.resolution
        return np.column_stack([ox + (self.ix[nodes] + 0.5) * r, oy + (self.iy[nodes] + 0.5) * r])

    def tree(self, src, limit=None):
        from scipy.sparse.csgraph import dijkstra

        if limit is None:
            return dijkstra(self.graph, indices=src, return_predecessors=True)
        return dijkstra(self.graph, indices=src, return_predecessors=True, limit=limit)

    def nearest_node(self, x, y):
        pts = self.xy(np.arange(self.iy.size))
        return int(np.argmin((pts[:, 0] - x) ** 2 + (pts[:, 1] - y) ** 2))


def _smooth(path: np.ndarray, world: World) -> np.ndarray:
    """Resample a polyline at 0.05 m and smooth it, keeping its clearance."""
    seg = np.hypot(*np.diff(path, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] < 1e-9:
        return path[:1]
    si = np.linspace(0.0, s[-1], max(int(s[-1] / 0.05), 1) + 1)
    p = np.column_stack([np.interp(si, s, path[:, 0]), np.interp(si, s, path[:, 1])])
    for win in (11, 7, 3, 1):
        q = p.copy()
        if win > 1:
            k = np.ones(win) / win
            for _ in range(2):
                pad = np.pad(q, ((win // 2, win // 2), (0, 0)), mode="edge")
                q = np.column_stack([np.convolve(pad[:, 0], k, "valid"), np.convolve(pad[:, 1], k, "valid")])
        if _clear(q, world).min() >= world.clearance - 0.06:
            return q
    return p


def _clear(xy: np.ndarray, world: World) -> np.ndarray:
    ox, oy = world.origin
    ix = np.clip(np.floor((xy[:, 0] - ox) / world.resolution).astype(int), 0, world.distance.shape[1] - 1)
    iy = np.clip(np.floor((xy[:, 1] - oy) / world.resolution).astype(int), 0, world.distance.shape[0] - 1)
    return world.distance[iy, ix]


def _plan_route(planner: _Planner, world: World, start_node: int, length: float, rng,
                fine: World | None = None, leg_max: float | None = None) -> np.ndarray:
    """A route from ``start_node`` through goals in rarely visited rooms, at least ``length`` long.

    ``world`` is the planner's (maybe coarse) world, ``fine`` the full one the
    route is smoothed against; ``leg_max`` bounds the path length to each goal
    (rooms farther away count as unreachable for that leg, unless none is near).
    """
    goal_ok = world.reachable & (world.distance >= 0.55)
    rid = world.room_id[planner.iy, planner.ix]
    goal_mask = goal_ok[planner.iy, planner.ix]
    rooms = np.unique(rid[goal_mask])
    visits = {int(r): 0 for r in rooms}
    cur = start_node
    visits[int(rid[cur])] = visits.get(int(rid[cur]), 0) + 1
    pieces = []
    total = 0.0
    misses = 0
    tree_of = None
    while total < length:
        if tree_of != (cur, misses < 50):  # a miss draws another room from the same place
            tree_of = (cur, misses < 50)
            dist, pred = planner.tree(cur, leg_max if misses < 50 else None)
        here = int(rid[cur])
        cand_rooms = [r for r in visits if r != here]
        wts = np.array([1.0 / (1 + visits[r]) ** 2 for r in cand_rooms])
        room = cand_rooms[int(rng.choice(len(cand_rooms), p=wts / wts.sum()))]
        cells = np.flatnonzero(goal_mask & (rid == room) & np.isfinite(dist))
        if cells.size == 0:
            visits[room] += 10
            misses += 1
            continue
        misses = 0
        goal = int(cells[rng.integers(cells.size)])
        nodes = [goal]
        while nodes[-1] != cur:
            nodes.append(int(pred[nodes[-1]]))
        nodes.reverse()
        leg = planner.xy(np.array(nodes))
        pieces.append(leg if not pieces else leg[1:])
        total += float(np.hypot(*np.diff(leg, axis=0).T).sum())
        visits[room] += 1
        cur = goal
    return _smooth(np.vstack(pieces), fine if fine is not None else world)


def _wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


class _Robot:
    """Pure-pursuit path follower with speed, turn-rate and acceleration limits."""

    def __init__(self, path, pose, v_max, w_max, lookahead=0.5, a_max=0.6, alpha_max=2.0):
        self.path = path
        self.pose = np.array(pose, dtype=np.float64)
        self.v = self.w = 0.0
        self.idx = 0
        self.v_max, self.w_max = v_max, w_max
        self.look = lookahead
        self.a_max, self.alpha_max = a_max, alpha_max

    def step(self, dt):
        x, y, th = self.pose
        p = self.path
        hi = min(self.idx + 40, len(p))
        j = self.idx + int(np.argmin((p[self.idx:hi, 0] - x) ** 2 + (p[self.idx:hi, 1] - y) ** 2))
        self.idx = j
        tgt = min(j + int(round(self.look / 0.05)), len(p) - 1)
        dx, dy = p[tgt, 0] - x, p[tgt, 1] - y
        dist = math.hypot(dx, dy)
        alpha = _wrap(math.atan2(dy, dx) - th) if dist > 1e-6 else 0.0
        if abs(alpha) > 0.7:  # turn on the spot towards the path
            v_cmd, w_cmd = 0.0, math.copysign(self.w_max, alpha)
        else:
            kappa = 2.0 * math.sin(alpha) / max(dist, 1e-6)
            v_cmd = self.v_max if abs(kappa) < 1e-9 else min(self.v_max, self.w_max / abs(kappa))
            v_cmd = min(v_cmd, 0.3 + dist)  # slow down near the end
            w_cmd = v_cmd * kappa
        self.v += float(np.clip(v_cmd - self.v, -self.a_max * dt, self.a_max * dt))
        self.w += float(np.clip(w_cmd - self.w, -self.alpha_max * dt, self.alpha_max * dt))
        self.w = float(np.clip(self.w, -self.w_max, self.w_max))
        v, w = self.v, self.w
        if abs(w) > 1e-9:
            r = v / w
            self.pose[0] += r * (math.sin(th + w * dt) - math.sin(th))
            self.pose[1] += -r * (math.cos(th + w * dt) - math.cos(th))
        else:
            self.pose[0] += v * dt * math.cos(th)
            self.pose[1] += v * dt * math.sin(th)
        self.pose[2] = _wrap(th + w * dt)

    @property
    def remaining(self):
        return len(self.path) - 1 - self.idx


def _coarse(world: World, stride: int) -> World:
    """The planner's view of a big world: every ``stride``-th cell, the largest connected part.

    Coarse cell i is fine cell i*stride (same centre), so a route through
    coarse cells passes through reachable fine cells.
    """
    s = stride
    reach = world.reachable[::s, ::s]
    lab, _ = _components(reach)
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    r = world.resolution
    origin = (world.origin[0] + 0.5 * r - 0.5 * s * r, world.origin[1] + 0.5 * r - 0.5 * s * r)
    return World(world.occupancy[::s, ::s], r * s, origin, world.distance[::s, ::s], lab == np.argmax(sizes),
                 world.room_id[::s, ::s], world.clearance)


def _reversal_plan(rng, n_ticks, reversals):
    """{tick: back-up distance (m), 0.5-3} for ``reversals`` manoeuvres spread over the run: one per equal share
    of it, at a random tick in its share's middle half (``_drive``)."""
    plan = {}
    if not reversals:
        return plan
    share = (n_ticks - 1) / reversals
    for i in range(reversals):
        k = int(share * i + share * rng.uniform(0.25, 0.75)) + 1
        plan[k] = float(rng.uniform(0.5, 3.0))
    return plan


GROUND_HIT_S = 2.0  # s: how long each of simulate(ground_hits=G)'s episodes lasts


def _mounted(poses: np.ndarray, mount: np.ndarray) -> np.ndarray:
    """(M, 3) poses ∘ mount: where a laser mounted at ``mount`` (robot frame) is when the robot is at ``poses``."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    return np.stack([poses[:, 0] + c * mount[0] - s * mount[1], poses[:, 1] + s * mount[0] + c * mount[1],
                     poses[:, 2] + mount[2]], axis=1)


def _swept(truth, pre, t, scan_ticks, angles, sweep: float, world, range_max: float,
           kidnap_tick: int | None, mount: np.ndarray | None = None) -> np.ndarray:
    """Ranges (S, B) of scans taken while the robot moves: beam ``j`` of the scan stamped at tick ``k`` is cast
    from the true pose at ``t[k] + j / (B - 1) * sweep`` (linear between ticks, the heading unwrapped), as a
    spinning laser sweeps its beams in angle order after the stamp (ROS LaserScan ``time_increment`` > 0); a
    negative ``sweep`` takes them the other way (the last beam at the stamp). A scan stamped before a kidnap is
    swept along the pose before the teleport (``pre``). ``mount``: the laser's pose on the robot (None: its centre)."""
    from mcl.kernels.raycast import cast_rays

    b = angles.size
    order = np.arange(b) if sweep > 0 else np.arange(b)[::-1]  # a negative sweep takes the last beam first
    tb = t[scan_ticks][:, None] + order[None, :] * (abs(sweep) / max(b - 1, 1))
    before = (scan_ticks < kidnap_tick)[:, None] if kidnap_tick is not None else np.zeros((scan_ticks.size, 1), bool)

    def at(col: int) -> np.ndarray:  # x, y or the unwrapped heading at each beam's time
        a, b = (pre[:, col], truth[:, col]) if col < 2 else (np.unwrap(pre[:, 2]), np.unwrap(truth[:, 2]))
        return np.where(before, np.interp(tb, t, a), np.interp(tb, t, b)).ravel()

    robot = np.stack([at(0), at(1), at(2)], axis=1)
    laser = _mounted(robot, mount) if mount is not None else robot
    rays = np.vstack([laser[:, 0], laser[:, 1], laser[:, 2] + np.tile(angles, scan_ticks.size)])
    out = np.empty((rays.shape[1], 1))
    cast_rays(np.ascontiguousarray(rays), np.zeros(1), world.blocked, world.origin[0], world.origin[1],
              world.resolution, range_max, out)
    return out.reshape(scan_ticks.size, b)


def _ground_hits(rng, t, angles, episodes: int, duration: float, exact) -> list[tuple[float, float]]:
    """Tilt the laser onto the ground ``episodes`` times, one in each equal share of the run at a random place in
    it, for ``GROUND_HIT_S``: in each scan of an episode (rows of ``exact``, the ranges cast at times ``t``) a flat
    floor seen by a laser pitched and rolled a little is a straight line, here at a distance of 1.5-5 m with its
    normal within 0.6 rad of straight ahead, new every scan (the robot rocks); a beam within 70 degrees of that
    normal reads the line where it is nearer than what the beam saw. In place; returns the (start, end) windows."""
    share = duration / episodes
    windows = []
    for i in range(episodes):
        # centred at a random place in the share, kept inside the run (only at the most episodes the check allows)
        a = min(max((i + rng.uniform(0.2, 0.8)) * share - GROUND_HIT_S / 2, 0.0), duration - GROUND_HIT_S)
        windows.append((a, a + GROUND_HIT_S))
        for k in np.flatnonzero((t >= a) & (t < a + GROUND_HIT_S)):
            dist, normal = rng.uniform(1.5, 5.0), rng.uniform(-0.6, 0.6)
            c = np.cos(angles - normal)
            on = c > 0.35
            exact[k, on] = np.minimum(exact[k, on], dist / c[on])
    return windows


def _noisy_ranges(exact: np.ndarray, rng, range_sigma: float, p_short: float, p_max: float,
                  range_max: float) -> np.ndarray:
    """The laser's readings of the true ranges ``exact`` (scans, beams): Gaussian noise ``range_sigma``, a share
    ``p_short`` short (uniform over 5-100 % of the true range), a share ``p_max`` no-return (``range_max``).

    The draws come in blocks of rows, in the order of whole-array draws (every normal, then every uniform, then
    every fraction: a Generator's draws split into consecutive blocks are the same numbers), so a long run needs
    about two floats a reading instead of five."""
    ranges = np.empty_like(exact)
    short = np.empty(exact.shape, dtype=bool)
    maxed = np.empty(exact.shape, dtype=bool)
    rows = max(1, _NOISE_BLOCK // max(1, exact.shape[1]))
    blocks = [slice(a, a + rows) for a in range(0, exact.shape[0], rows)]
    for b in blocks:
        ranges[b] = exact[b] + range_sigma * rng.standard_normal(exact[b].shape)
    for b in blocks:
        u = rng.random(exact[b].shape)
        short[b] = u < p_short
        maxed[b] = (u >= p_short) & (u < p_short + p_max)
    for b in blocks:
        frac = rng.uniform(0.05, 1.0, exact[b].shape)
        s = short[b]
        ranges[b][s] = exact[b][s] * frac[s]
    ranges[maxed] = range_max
    ranges[exact >= range_max] = range_max
    np.clip(ranges, 0.0, range_max, out=ranges)
    return ranges


def _drive(world, rng, n_ticks, speed, turn_rate, kidnap_tick, plan_stride=1, leg_max=None, reversals=None,
           odom_rate=_ODOM_RATE, sim_dt=_SIM_DT):
    """Truth poses (n_ticks, 3) at ``odom_rate`` Hz (robot steps of ``sim_dt`` s, ``_rates``), the pre-teleport
    poses, start and kidnap poses.

    ``plan_stride`` > 1 plans on a coarse lattice (big maps); ``leg_max`` bounds each leg of the route.
    ``reversals`` ({tick: metres}, ``_reversal_plan``): at each such tick the robot backs up that far along its
    own track (the ticks it came by, replayed backwards: the heading it had there, moving tail first), then
    drives forward over them again and goes on. A track it drove is free, so the manoeuvre needs no planning.
    """
    fine = world
    if plan_stride > 1:
        world = _coarse(world, plan_stride)
    planner = _Planner(world)
    per_tick = int(round(1.0 / (odom_rate * sim_dt)))
    route_len = speed * n_ticks / odom_rate * 1.3 + 5.0

    def start_at(node, theta=None):
        path = _plan_route(planner, world, node, route_len, rng, fine, leg_max)
        if theta is None:
            k = min(10, len(path) - 1)
            theta = math.atan2(path[k, 1] - path[0, 1], path[k, 0] - path[0, 0])
        return _Robot(path, (path[0, 0], path[0, 1], theta), speed, turn_rate)

    goal_nodes = np.flatnonzero(world.distance[planner.iy, planner.ix] >= 0.6)
    robot = start_at(int(goal_nodes[rng.integers(goal_nodes.size)]))
    truth = np.empty((n_ticks, 3))
    pre = np.empty((n_ticks, 3))
    truth[0] = pre[0] = robot.pose
    start = robot.pose.copy()
    kidnap = None
    length = 0.0
    replay = []  # poses of a reversal still to drive (backwards, then forwards again)
    since = 0  # the first tick a reversal may retrace back to (after a kidnap: the new place only)
    for k in range(1, n_ticks):
        if reversals and k in reversals and not replay:
            back, j = 0.0, k - 1
            while j > since and back < reversals[k]:
                back += math.hypot(*(truth[j, :2] - truth[j - 1, :2]))
                j -= 1
            replay = [truth[i].copy() for i in range(k - 2, j - 1, -1)] + [truth[i].copy() for i in range(j + 1, k)]
            if kidnap_tick is not None and k <= kidnap_tick < k + len(replay) + 10:
                replay = []  # not across the kidnap (nor right before it)
        if replay:
            before = truth[k - 1, :2]
            pre[k] = truth[k] = replay.pop(0)
            length += math.hypot(*(truth[k, :2] - before))
            continue
        for _ in range(per_tick):
            before = robot.pose[:2].copy()
            robot.step(sim_dt)
            length += math.hypot(*(robot.pose[:2] - before))
        if robot.remaining < 5:  # route used up (slow driving): extend from here
            robot = _Robot(np.vstack([robot.path[robot.idx:],
                                      _plan_route(planner, world, planner.nearest_node(*robot.pose[:2]),
                                                  route_len, rng, fine, leg_max)]),
                           robot.pose, speed, turn_rate)
        pre[k] = truth[k] = robot.pose
        if k == kidnap_tick:
            far = goal_nodes[np.hypot(*(planner.xy(goal_nodes) - robot.pose[:2]).T) > 5.0]
            node = int(far[rng.integers(far.size)])
            theta = float(rng.uniform(-math.pi, math.pi))
            robot = start_at(node, theta)
            truth[k] = robot.pose
            since = k
            kidnap = {"t": k / odom_rate, "from": _pose_list(pre[k]), "to": _pose_list(truth[k])}
    return truth, pre, start, kidnap, length


def _pose_list(p):
    return [round(float(p[0]), 6), round(float(p[1]), 6), round(float(p[2]), 6)]


# --------------------------------------------------------------------------
# Odometry and laser
# --------------------------------------------------------------------------

def _odometry(truth, pre, rng, alphas, scale, yaw_drift, min_trans=1e-6, odom_rate=_ODOM_RATE):
    """Noisy odometry poses (n, 3) starting at (0, 0, 0), and measured tv, rv (n,).

    A step shorter than ``min_trans`` (m) is read as a turn on the spot (rot1 = 0): the simulator's robot turns on
    the spot exactly (trans 0); a replayed SLAM path (scripts/radish_dataset.py) jitters by millimetres in any
    direction, and the direction of such a step, taken for rot1, would give it a rotation's noise it never made
    (it passes ``mcl.motion.ROT1_MIN_TRANS``, 1 cm: the filter's and AMCL's rule)."""
    from mcl.motion import noise_rotations  # here: numba, which the parser of `mcl --help` need not import

    a1, a2, a3, a4 = alphas

    def step(z, x0, y0, t0, x1, y1, t1, trans, odom):
        rot1 = 0.0 if trans < min_trans else _wrap(math.atan2(y1 - y0, x1 - x0) - t0)
        rot2 = _wrap(t1 - t0 - rot1)
        # the noise scales with the rotation the robot really made: a backward step reads rot1 ~ pi, rot2 ~ -pi
        # (the filter's motion model reads them the same way, mcl.motion.noise_rotations)
        n1, n2 = noise_rotations(rot1, rot2)
        r1 = rot1 - z[0] * math.sqrt(a1 * n1 ** 2 + a2 * trans ** 2)
        tr = trans - z[1] * math.sqrt(a3 * trans ** 2 + a4 * (n1 ** 2 + n2 ** 2))
        r2 = rot2 - z[2] * math.sqrt(a1 * n2 ** 2 + a2 * trans ** 2)
        tr *= scale
        r1 += 0.5 * yaw_drift * trans
        r2 += 0.5 * yaw_drift * trans
        ox, oy, ot = odom
        # the wheels' velocities: negative tv on a step backwards (rot1 ~ pi), and the heading change itself
        # (rot1 + rot2 is it only up to 2 pi then)
        return ((ox + tr * math.cos(ot + r1), oy + tr * math.sin(ot + r1), _wrap(ot + r1 + r2)),
                -tr if abs(rot1) > 0.5 * math.pi else tr, _wrap(r1 + r2))

    return _odometry_chain(truth, pre, rng, odom_rate, step)


def _odometry_chain(truth, pre, rng, odom_rate, step):
    """(odometry poses (n, 3) from (0, 0, 0), tv, rv (n,)) of a drive: ``step(z, x0, y0, t0, x1, y1, t1, trans,
    odom)`` gives each tick's odometry pose, its travel and its turn from the truth's step (truth[k - 1] to
    pre[k], ``trans`` long), three standard normals ``z`` (all drawn first, one row a tick) and the last pose."""
    n = truth.shape[0]
    z = rng.standard_normal((n, 3))
    odom = np.zeros((n, 3))
    tv = np.zeros(n)
    rv = np.zeros(n)
    dt = 1.0 / odom_rate
    for k in range(1, n):
        x0, y0, t0 = truth[k - 1]
        x1, y1, t1 = pre[k]
        odom[k], travel, turn = step(z[k], x0, y0, t0, x1, y1, t1, math.hypot(x1 - x0, y1 - y0), odom[k - 1])
        tv[k] = travel / dt
        rv[k] = turn / dt
    return odom, tv, rv


def _holonomic_offsets(rng, t: np.ndarray, amplitude: float) -> np.ndarray:
    """The heading's offset from the direction of travel at times ``t`` (s) of an omnidirectional base:
    ``amplitude`` (rad) times 0.6 sin(2 pi t / 23 s + p1) + 0.4 sin(2 pi t / 9 s + p2), random phases; it turns at
    most 0.44 ``amplitude`` rad/s on top of the path's own turns."""
    p1, p2 = rng.uniform(0.0, 2.0 * math.pi, 2)
    return amplitude * (0.6 * np.sin(2.0 * math.pi * t / 23.0 + p1) + 0.4 * np.sin(2.0 * math.pi * t / 9.0 + p2))


def _odometry_omni(truth, pre, rng, alphas, scale, yaw_drift, odom_rate=_ODOM_RATE):
    """``_odometry`` of an omnidirectional base: each step's travel (trans, in its own direction), its drift
    across that direction (strafe, nominally 0) and its turn each get independent noise, the variance form of ROS
    AMCL's omni model: sigma_trans^2 = sigma_strafe^2 = a3 trans^2 + a4 turn^2, sigma_turn^2 = a1 turn^2 + a2
    trans^2. The heading does not enter the noise of the travel (a strafing step is no turn)."""
    a1, a2, a3, a4 = alphas

    def step(z, x0, y0, t0, x1, y1, t1, trans, odom):
        bearing = _wrap(math.atan2(y1 - y0, x1 - x0) - t0) if trans > 1e-6 else 0.0
        turn = _wrap(t1 - t0)
        s_tr = math.sqrt(a3 * trans ** 2 + a4 * turn ** 2)
        tr = (trans - z[0] * s_tr) * scale
        strafe = -z[1] * s_tr
        rot = turn - z[2] * math.sqrt(a1 * turn ** 2 + a2 * trans ** 2) + yaw_drift * trans
        ox, oy, ot = odom
        b = ot + bearing
        # tv: the body's forward speed (a bag's twist.linear.x)
        return ((ox + tr * math.cos(b) + strafe * math.sin(b), oy + tr * math.sin(b) - strafe * math.cos(b),
                 _wrap(ot + rot)), tr * math.cos(bearing), rot)

    return _odometry_chain(truth, pre, rng, odom_rate, step)


# sim.yaml's units, stated at its top: its numbers carry none of their own.
SIM_YAML_HEADER = (
    "# mcl simulate: the world's parameters. Units: metres, seconds and radians throughout;\n"
    "# poses are [x m, y m, theta rad] in the map's frame (odom_start_pose in the odometry's);\n"
    "# laser.fov and laser.angle_min rad, robot.turn_rate rad/s, robot.speed m/s,\n"
    "# odometry.yaw_drift_per_m rad/m, map_rotation rad;\n"
    "# time windows are [start s, end s] on the log's clock (0 at the drive's start).\n"
)


def beam_angles(n_beams: int, fov: float) -> np.ndarray:
    """Beam i at -fov/2 + i*fov/(n-1), counter-clockwise from the robot's heading."""
    return -fov / 2 + np.arange(n_beams) * (fov / (n_beams - 1))


def _flaser_ok(n_beams, fov):
    """FLASER has no geometry: readers assume pi/180 (180/181 beams) or pi/360 (360/361)."""
    return abs(fov - math.pi) < 1e-12 and n_beams in (181, 361)


# --------------------------------------------------------------------------
# Landmarks (mcl extension: LANDMARK lines, landmarks.yaml)
# --------------------------------------------------------------------------

def _place_landmarks(world: World, k: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """ids 1..k and (2, k) positions: cell centres of free cells 0.15-0.3 m from a wall (a beacon on a
    wall, a pillar or in a corner), corners preferred (more occupied cells within 0.5 m), at least
    2 m apart (1 m, then any, if the building has too few such places)."""
    from scipy.ndimage import uniform_filter

    cand = (world.occupancy == 0) & (world.distance >= 0.15) & (world.distance <= 0.3)
    iy, ix = np.nonzero(cand)
    score = uniform_filter(world.blocked.astype(np.float64), size=21, mode="constant")[iy, ix]
    w = score ** 2
    x = world.origin[0] + (ix + 0.5) * world.resolution
    y = world.origin[1] + (iy + 0.5) * world.resolution
    chosen: list[int] = []
    for sep in (2.0, 1.0, 0.0):
        alive = np.ones(x.size, dtype=bool)
        for c in chosen:
            alive &= np.hypot(x - x[c], y - y[c]) >= sep
        while len(chosen) < k and np.any(alive & (w > 0)):
            p = np.where(alive, w, 0.0)
            c = int(rng.choice(x.size, p=p / p.sum()))
            chosen.append(c)
            alive &= np.hypot(x - x[c], y - y[c]) >= max(sep, 1e-9)
        if len(chosen) == k:
            break
    c = np.array(chosen, dtype=np.int64)
    return np.arange(1, c.size + 1, dtype=np.int64), np.vstack([x[c], y[c]])


def _landmark_observations(world: World, poses: np.ndarray, ids: np.ndarray, xy: np.ndarray,
                           rng: np.random.Generator, range_max: float, sigma: tuple[float, float],
                           p_miss: float, p_fp: float) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(ids, ranges, bearings) seen from each pose of ``poses`` (S, 3).

    A landmark is seen when it is within ``range_max`` and the ray cast from
    the pose towards it meets no occupied cell before it
    (``mcl.kernels.raycast.cast_rays``); each seen one is missed with
    probability ``p_miss``; its range and bearing get Gaussian noise
    ``sigma`` = (m, rad). With probability ``p_fp`` a pose also reports a
    false positive: a random id of the map at a range uniform in
    [0.5, range_max] and a bearing uniform in [-pi, pi).
    """
    from mcl.kernels.raycast import cast_rays

    s = poses.shape[0]
    k = ids.size
    dx = xy[0][None, :] - poses[:, 0:1]
    dy = xy[1][None, :] - poses[:, 1:2]
    d = np.hypot(dx, dy)
    heading = np.arctan2(dy, dx)
    hit = np.empty((s, k))
    for j in range(k):  # one parallel cast over all poses per landmark
        rays = np.ascontiguousarray(np.vstack([poses[:, 0], poses[:, 1], heading[:, j]]))
        col = np.empty((s, 1))
        cast_rays(rays, np.zeros(1), world.blocked, world.origin[0], world.origin[1], world.resolution,
                  range_max, col)
        hit[:, j] = col[:, 0]
    seen = (d <= range_max) & (hit >= d)
    seen &= rng.random((s, k)) >= p_miss
    r = d + sigma[0] * rng.standard_normal((s, k))
    b = _wrap(heading - poses[:, 2:3] + sigma[1] * rng.standard_normal((s, k)))
    fp = rng.random(s) < p_fp
    fp_id = ids[rng.integers(0, k, s)]
    fp_r = rng.uniform(0.5, range_max, s)
    fp_b = rng.uniform(-math.pi, math.pi, s)
    out = []
    for i in range(s):
        m = seen[i]
        oi, orr, ob = ids[m], np.abs(r[i, m]), b[i, m]
        if fp[i]:
            oi, orr, ob = np.append(oi, fp_id[i]), np.append(orr, fp_r[i]), np.append(ob, fp_b[i])
        out.append((oi, orr, ob))
    return out


def _landmark_line(obs: tuple[np.ndarray, np.ndarray, np.ndarray], ts: str) -> str:
    ids, r, b = obs
    body = "".join(f" {int(i)} {rr:.4f} {bb:.5f}" for i, rr, bb in zip(ids, r, b))
    return f"LANDMARK {ids.size}{body} {ts}\n"


# --------------------------------------------------------------------------
# Entry point
# --------------------------------------------------------------------------

def resample_occupancy(occupancy: np.ndarray, resolution: float, new_resolution: float) -> np.ndarray:
    """The grid ``occupancy`` (-1 unknown, 0 free, 100 occupied; ``resolution`` m cells, row 0 at the bottom) drawn
    with ``new_resolution`` m cells over the same origin, as a mapper would: a new cell is occupied when any
    world cell it overlaps is, else free when any is free, else unknown. Coarser cells thicken walls by up to one
    new cell; finer ones repeat the world's cells."""
    rank = np.where(occupancy > 0, 2, np.where(occupancy == 0, 1, 0)).astype(np.int8)

    def pooled(rank: np.ndarray, axis: int) -> np.ndarray:
        # new cell i overlaps world cells first[i] .. last[i]; reduceat takes [first[i], first[i+1]) (first[i]
        # alone when a new cell lies inside one world cell), and last[i] adds a partly overlapped last cell
        n = rank.shape[axis]
        n_new = max(int(math.ceil(n * resolution / new_resolution - 1e-9)), 1)
        edges = np.arange(n_new + 1) * (new_resolution / resolution)
        first = np.minimum(np.floor(edges[:-1] + 1e-9).astype(np.int64), n - 1)
        last = np.minimum(np.ceil(edges[1:] - 1e-9).astype(np.int64) - 1, n - 1)
        return np.maximum(np.maximum.reduceat(rank, first, axis=axis), np.take(rank, last, axis=axis))

    rank = pooled(pooled(rank, 0), 1)
    return np.array([-1, 0, 100], dtype=np.int8)[rank]


DRIVE_ATTEMPTS = 8  # drives drawn before a world whose follower keeps cutting into walls is an error


def _check(cond, key, msg):
    if not cond:
        raise ConfigError(f"simulate: {key}: {msg}")


def _real(v) -> bool:
    """Whether ``v`` is a finite real number (an int, float or NumPy number; not a bool)."""
    return isinstance(v, (int, float, np.number)) and not isinstance(v, bool) and math.isfinite(v)


def simulate(outdir, *, kind: str = "office", seed: int = 0, duration: float = 60.0, n_beams: int = 181,
             fov: float = math.pi,
             range_max: float = 12.0, range_sigma: float = 0.02, p_short: float = 0.03, p_max: float = 0.01,
             odom_alphas=(0.05, 0.05, 0.05, 0.02), odom_scale: float = 1.01, odom_yaw_drift: float = 0.01,
             kidnap_at: float | None = None, speed: float | None = None, turn_rate: float = 0.6,
             robot_radius: float = 0.2, dynamic_obstacles: int | None = None,
             unmapped_furniture: int | None = None, landmarks: int = 0,
             landmark_range: float = 8.0, landmark_sigma=(0.05, 0.02), landmark_miss: float = 0.05,
             landmark_fp: float = 0.03, depth: bool = False, depth_every: int = 1, depth_camera=None,
             map_resolution: float | None = None, reversals: int = 0, ground_hits: int = 0,
             scan_rate: float = 5.0, scan_sweep: float = 0.0, phantom_furniture: int = 0,
             unknown_floor: int = 0, laser_pose=(0.0, 0.0, 0.0), body=(), holonomic: float = 0.0,
             doubled_walls: int = 0, map_scale: float = 1.0, map_rotation: float = 0.0, scan_gaps: int = 0,
             scan_gap_s: float = 5.0, odom_stalls: int = 0, odom_stall_s: float = 3.0, odom_resets: int = 0,
             odom_reset_s: float = 0.0, odom_slips: int = 0, odom_slip_s: float = 2.0, range_scale: float = 1.0,
             range_bias: float = 0.0, _check_only: bool = False) -> dict | None:
    """Generate a world, drive it and write map, log, truth and parameters to ``outdir``.

    Deterministic for a given ``seed`` and parameters. ``kind`` picks the
    world generator (``mcl.worlds.KINDS``: office, rooms, corridor, hall,
    clutter, large, warehouse); ``speed``, ``dynamic_obstacles`` and
    ``unmapped_furniture`` left at None take the kind's defaults
    (``mcl.worlds.KIND_DEFAULTS``). ``range_sigma``,
    ``p_short`` (short readings from unexpected obstacles) and ``p_max``
    (max-range dropouts) set the laser noise; set all three to 0 for exact
    ranges. ``odom_alphas`` are (a1, a2, a3, a4) of the odometry motion model
    (variance form); ``odom_scale`` multiplies every translation and
    ``odom_yaw_drift`` adds rad per metre travelled. ``kidnap_at`` teleports
    the robot at that time (rounded to the 10 Hz tick) to a free pose at
    least 5 m away; the odometry does not see the jump. ``dynamic_obstacles``
    adds that many obstacles the saved map does not show (``_unmapped_obstacles``):
    half of them boxes standing near the path, half people walking to and fro;
    the laser sees them, the map does not. The world, path and noise stay those
    of the same seed without them. ``unmapped_furniture`` = N adds N static
    boxes (0.3-0.9 m: chairs, crates, carts) the map does not show, standing
    near walls within 6 m of the path and clear of it. ``landmarks`` = K > 0 places K point
    landmarks near walls (``landmarks.yaml``) and writes a ``LANDMARK`` line
    after each scan: the landmarks within ``landmark_range`` in line of sight,
    range/bearing noise ``landmark_sigma`` (m, rad), missed with probability
    ``landmark_miss``, plus a false positive (random id) with probability
    ``landmark_fp``. K = 0 leaves every output byte-identical. ``depth`` renders a Kinect-like depth
    image (mcl.depthsim; ``depth_camera`` a mcl.planes.DepthCamera, default Kinect v1 on a 0.6 m mount) at
    every ``depth_every``-th scan into ``depth/<t>.npz`` with ``depth/camera.yaml``; without it every output
    is byte-identical. ``map_resolution`` (m) writes the map at another cell size than the world's 0.05 m, as a
    mapping run at that resolution would have drawn it (``resample_occupancy``); the laser still sees the world.
    ``reversals`` = R backs the robot up R times, spread over the run, 0.5-3 m along its own track each time, then
    forward over it again (``_drive``): a robot that reverses out of a dead end or a docking station. Its odometry
    reads rot1 ~ pi on those steps. R = 0 leaves every output byte-identical.
    ``scan_rate`` (Hz, default 5) is the laser's; the odometry (and the truth) runs at 10 Hz or at the scan rate
    when that is higher, and the robot's motion is integrated in steps of about 10 ms that divide a tick (at 40 Hz,
    12.5 ms). At 5 Hz the world, path and every number are as before the option.
    ``ground_hits`` = G tilts the laser onto the ground G times, spread over the run, for ``GROUND_HIT_S`` (2 s)
    each (``_ground_hits``): a robot pitching on a ramp or braking hard, whose scan then reads a line of returns
    1.5-5 m ahead that moves every scan and is on no map. G = 0 leaves every output byte-identical.
    ``laser_pose`` = (x, y, theta) mounts the laser off the robot's centre (m, m, rad in the robot frame; within
    ``robot_radius`` of it): every scan is cast from truth ∘ laser_pose, the log's FLASER/ROBOTLASER1 lines carry
    the laser's pose beside the robot's (a bag's ``/tf_static`` the mounting), and truth.tum stays the robot's, as a
    real robot's laser sits ahead of, behind or beside ``base_link``. (0, 0, 0) leaves every output byte-identical.
    ``body`` = [[a0, a1, r], ...] puts the robot itself in the laser's view: every beam between a0 and a1 rad (laser
    frame, -pi..pi) meets it at r m, on every scan wherever the robot is (a wheel, a bumper's corner, a mast's post),
    before the noise; sim.yaml lists it. [] leaves every output byte-identical.
    ``holonomic`` = A (rad, 0..pi) drives an omnidirectional base (mecanum wheels, a Ridgeback, a PR2): the robot
    keeps to the same path, but its heading leaves the direction of travel by up to A (``_holonomic_offsets``: two
    slow sinusoids), so it strafes and crabs, and its odometry is noisy along the travel, across it and in the turn
    (``_odometry_omni``: the omni model of ROS AMCL) instead of in rot1, trans, rot2. 0 leaves every output
    byte-identical.
    ``doubled_walls`` = N draws the map's walls twice in N squares along the drive (``double_walls``), the second copy
    0.1-0.3 m off, as a SLAM map whose loop did not quite close shows them; the laser sees the world's walls once.
    0 leaves every output byte-identical.
    ``map_scale`` = S draws the map S times the world's size (its cells S x the world's, its origin scaled about
    the frame's zero): a floor plan or a map whose scale is off by a percent or two. The laser and the odometry
    measure the world; truth.tum and sim.yaml's poses (start, kidnap, ``doubled_walls``' squares) are given in the
    map's frame, the world's x, y times S, where the map shows the robot's surroundings. 1 leaves every output
    byte-identical.
    ``map_rotation`` = A (rad, -pi..pi) draws the map turned by A about the frame's zero (``rotate_map``): a SLAM
    map whose frame started at the robot's heading, not along the building, so its walls run across the cells
    as staircases. The laser and the odometry are the same bytes; truth.tum and sim.yaml's poses are in the map's
    frame (turned by A, then scaled by ``map_scale``). 0 leaves every output byte-identical.
    ``scan_gaps`` = N drops the laser for ``scan_gap_s`` seconds N times, evenly spread over the run (at most half
    the time between them): a driver that restarts, a USB reset, a bag whose scan topic stalled. The odometry goes
    on; the log has no scan line there and truth.tum no pose (the reference is the scans'), and ``sim.yaml`` lists
    the windows. The scans kept are the same bytes as without. 0 leaves every output byte-identical.
    ``odom_stalls`` = N stalls the odometry for ``odom_stall_s`` seconds N times, evenly spread (``_stalled``): an
    encoder driver that hangs while the robot drives on. The odometry (ODOM lines, the scan lines' poses) holds its
    pose and reads no velocity there, then goes on from it: the motion in the stall is lost. The laser and the truth
    are the same bytes as without; ``sim.yaml`` lists the windows. 0 leaves every output byte-identical.
    ``odom_resets`` = N restarts the odometry N times, evenly spread (``_reset``): a base driver that restarts, its
    pose starting again from (0, 0, 0) where the robot then is. With ``odom_reset_s`` = S > 0 the driver is down for
    S seconds first: the odometry holds its pose there (as ``odom_stalls``), the motion in it lost. The laser and
    the truth are the same bytes as without; ``sim.yaml`` lists the windows. 0 leaves every output byte-identical.
    ``odom_slips`` = N makes the right wheel slip N times for ``odom_slip_s`` seconds, evenly spread (``_slipped``): a
    wheel spinning on a wet or dusty floor reads twice the robot's travel, so the odometry there reads 1.5 times the
    translation and a turn of the travel over ``SLIP_BASE`` (its wheel base) on top of the true one, then goes on
    rigidly from where that left it. The laser and the truth are the same bytes as without; ``sim.yaml`` lists the
    windows. 0 leaves every output byte-identical.
    ``range_scale`` = K and ``range_bias`` = B make the laser read K r + B m for a return at r m (before the noise;
    the robot's own ``body`` too; a reading pushed to ``range_max`` or past it reads no return): a laser calibrated
    against another range than the map was drawn with (a cheap lidar's few per cent, a scan made from a depth
    camera, a range offset left in a driver). The odometry, the map and the truth are the same bytes; ``sim.yaml``
    gives both. 1 and 0 leave every output byte-identical.

    Returns a summary: scans, duration, path length, start pose, kidnap. ``_check_only``: check the parameters
    (ConfigError naming the keyword) and return None, making nothing (``mcl eval --suite`` checks a suite's worlds
    before any run).
    """
    from mcl.kernels.raycast import cast_rays
    from mcl.maps import OccupancyGrid, save_map
    from mcl.trajectory import atomic_write_text, atomic_writer, write_tum

    _check(kind in KINDS, "kind", f"expected one of {', '.join(KINDS)}, got {kind!r}")
    defaults = KIND_DEFAULTS[kind]
    speed = defaults["speed"] if speed is None else speed
    dynamic_obstacles = defaults["dynamic_obstacles"] if dynamic_obstacles is None else dynamic_obstacles
    unmapped_furniture = defaults["unmapped_furniture"] if unmapped_furniture is None else unmapped_furniture
    _check(isinstance(seed, (int, np.integer)) and seed >= 0, "seed", f"expected an integer >= 0, got {seed!r}")
    _check(math.isfinite(duration) and 1.0 <= duration <= 3600.0, "duration", f"expected 1..3600 s, got {duration}")
    _check(isinstance(n_beams, (int, np.integer)) and 2 <= n_beams <= 4096, "n_beams", f"expected 2..4096, got {n_beams}")
    _check(0.0 < fov <= 2 * math.pi, "fov", f"expected 0 < fov <= 2 pi rad (360 degrees), got {fov:g} rad ({math.degrees(fov):g} degrees)")
    _check(math.isfinite(range_max) and 0.5 <= range_max <= 100.0, "range_max", f"expected 0.5..100 m, got {range_max}")
    _check(math.isfinite(range_sigma) and 0 <= range_sigma <= 1.0, "range_sigma", f"expected 0..1 m, got {range_sigma}")
    _check(0 <= p_short <= 1, "p_short", f"expected 0..1, got {p_short}")
    _check(0 <= p_max <= 1 and p_short + p_max <= 1, "p_max", f"expected 0..1 with p_short + p_max <= 1, got {p_max} "
           f"(p_short {p_short})")
    _check(len(odom_alphas) == 4 and all(math.isfinite(a) and 0 <= a <= 100 for a in odom_alphas), "odom_alphas",
           f"expected four values in 0..100, got {list(odom_alphas)}")
    _check(0.5 <= odom_scale <= 1.5, "odom_scale", f"expected 0.5..1.5, got {odom_scale}")
    _check(math.isfinite(odom_yaw_drift) and abs(odom_yaw_drift) <= 0.5, "odom_yaw_drift",
           f"expected -0.5..0.5 rad per metre, got {odom_yaw_drift}")
    _check(0.1 <= speed <= 2.0, "speed", f"expected 0.1..2 m/s, got {speed}")
    _check(0.1 <= turn_rate <= 3.0, "turn_rate", f"expected 0.1..3 rad/s, got {turn_rate}")
    _check(isinstance(dynamic_obstacles, (int, np.integer)) and 0 <= dynamic_obstacles <= 200, "dynamic_obstacles",
           f"expected 0..200, got {dynamic_obstacles!r}")
    _check(isinstance(unmapped_furniture, (int, np.integer)) and 0 <= unmapped_furniture <= 500,
           "unmapped_furniture", f"expected 0..500, got {unmapped_furniture!r}")
    _check(isinstance(landmarks, (int, np.integer)) and 0 <= landmarks <= 1000, "landmarks",
           f"expected 0..1000, got {landmarks!r}")
    _check(math.isfinite(landmark_range) and 0.5 <= landmark_range <= 100.0, "landmark_range",
           f"expected 0.5..100 m, got {landmark_range}")
    _check(len(landmark_sigma) == 2 and all(v >= 0 for v in landmark_sigma) and 0 <= landmark_miss <= 1
           and 0 <= landmark_fp <= 1, "landmark_sigma/landmark_miss/landmark_fp",
           "noise must be >= 0 and the probabilities in [0, 1]")
    _check(isinstance(depth_every, (int, np.integer)) and depth_every >= 1, "depth_every",
           f"expected an integer >= 1, got {depth_every!r}")
    _check(map_resolution is None or (math.isfinite(map_resolution) and 0.01 <= map_resolution <= 0.5),
           "map_resolution", f"expected 0.01..0.5 m, got {map_resolution}")
    _check(isinstance(scan_rate, (int, float, np.number)) and math.isfinite(scan_rate) and 0.5 <= scan_rate <= 100.0,
           "scan_rate", f"expected 0.5..100 Hz, got {scan_rate!r}")
    _check(isinstance(reversals, (int, np.integer)) and 0 <= reversals <= 1000, "reversals",
           f"expected 0..1000, got {reversals!r}")
    _check(isinstance(ground_hits, (int, np.integer)) and 0 <= ground_hits <= duration / (2 * GROUND_HIT_S),
           "ground_hits", f"expected 0..{int(duration / (2 * GROUND_HIT_S))} for {duration:g} s, got {ground_hits!r}")
    _check(isinstance(scan_sweep, (int, float, np.number)) and math.isfinite(scan_sweep)
           and abs(scan_sweep) <= 1.0 / scan_rate + 1e-12, "scan_sweep",
           f"expected -{1.0 / scan_rate:g}..{1.0 / scan_rate:g} s (one scan period), got {scan_sweep!r}")
    _check(not scan_sweep or not (dynamic_obstacles or unmapped_furniture), "scan_sweep",
           "a sweeping scan is cast against the mapped world only: set dynamic_obstacles and unmapped_furniture to 0")
    _check(isinstance(phantom_furniture, (int, np.integer)) and 0 <= phantom_furniture <= 500, "phantom_furniture",
           f"expected 0..500, got {phantom_furniture!r}")
    _check(isinstance(unknown_floor, (int, np.integer)) and 0 <= unknown_floor <= 20, "unknown_floor",
           f"expected 0..20, got {unknown_floor!r}")
    _check(isinstance(doubled_walls, (int, np.integer)) and not isinstance(doubled_walls, bool)
           and 0 <= doubled_walls <= 20, "doubled_walls", f"expected 0..20, got {doubled_walls!r}")
    _check(_real(map_scale) and 0.9 <= map_scale <= 1.1, "map_scale",
           f"expected 0.9..1.1, got {map_scale!r}")
    _check(map_scale == 1.0 or not (landmarks or depth), "map_scale",
           "a scaled map is made without landmarks and depth frames: set landmarks to 0 and depth to false")
    _check(_real(map_rotation) and abs(map_rotation) <= math.pi, "map_rotation",
           f"expected -pi..pi rad, got {map_rotation!r}")
    _check(_real(range_scale) and 0.5 <= range_scale <= 1.5, "range_scale",
           f"expected 0.5..1.5, got {range_scale!r}")
    _check(_real(range_bias) and abs(range_bias) <= 1.0, "range_bias",
           f"expected -1..1 m, got {range_bias!r}")
    # windows of the log's faults: how many (0..20) and how long each
    for key, n, key_s, seconds, lo in (("scan_gaps", scan_gaps, "scan_gap_s", scan_gap_s, 0.5),
                                       ("odom_stalls", odom_stalls, "odom_stall_s", odom_stall_s, 0.5),
                                       ("odom_resets", odom_resets, "odom_reset_s", odom_reset_s, 0.0),
                                       ("odom_slips", odom_slips, "odom_slip_s", odom_slip_s, 0.5)):
        _check(isinstance(n, (int, np.integer)) and not isinstance(n, bool) and 0 <= n <= 20, key,
               f"expected 0..20, got {n!r}")
        _check(_real(seconds) and lo <= seconds <= 60.0, key_s, f"expected {lo:g}..60 s, got {seconds!r}")
    _check(scan_gaps == 0 or not depth, "scan_gaps",
           "scan gaps are made without depth frames: set depth to false")
    _check(map_rotation == 0.0 or not (landmarks or depth), "map_rotation",
           "a turned map is made without landmarks and depth frames: set landmarks to 0 and depth to false")
    _check(isinstance(laser_pose, (list, tuple, np.ndarray)) and len(laser_pose) == 3
           and all(_real(v) for v in laser_pose)
           and math.hypot(laser_pose[0], laser_pose[1]) <= robot_radius + 1e-12, "laser_pose",
           f"expected [x, y, theta] with the laser within the robot's {robot_radius:g} m radius, got {laser_pose!r}")
    _check(isinstance(body, (list, tuple)) and all(
        isinstance(b, (list, tuple)) and len(b) == 3
        and all(_real(v) for v in b)
        and -math.pi <= b[0] < b[1] <= math.pi and 0.0 < b[2] < range_max for b in body), "body",
        f"expected [[a0, a1, r], ...] with -pi <= a0 < a1 <= pi rad and 0 < r < range_max ({range_max:g} m), "
        f"got {body!r}")
    _check(_real(holonomic) and 0.0 <= holonomic <= math.pi, "holonomic",
           f"expected 0..pi rad, got {holonomic!r}")
    mount = np.array([float(v) for v in laser_pose])
    mounted = bool(np.any(mount != 0.0))
    odom_rate, scan_every, sim_dt = _rates(float(scan_rate))
    n_ticks = int(round(duration * odom_rate)) + 1
    kidnap_tick = None
    if kidnap_at is not None:
        # (NaN or inf was a traceback in int(round()); the last tick is where the drive ends, not the duration)
        last = (n_ticks - 2) / odom_rate
        _check(_real(kidnap_at) and 0.0 < kidnap_at, "kidnap_at", f"must lie inside (0, {last:g}] s, got {kidnap_at}")
        kidnap_tick = int(round(kidnap_at * odom_rate))
        _check(0 < kidnap_tick < n_ticks - 1, "kidnap_at", f"must lie inside (0, {last:g}] s, got {kidnap_at}")
    if _check_only:
        return None

    seeds = np.random.SeedSequence(int(seed)).spawn(4)
    rng_world, rng_drive, rng_odom, rng_laser = (np.random.default_rng(s) for s in seeds)
    world = generate(kind, rng_world)
    plan = None
    if reversals:
        # An eighth child stream: the others are unchanged.
        rng_rev = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(8)[7])
        plan = _reversal_plan(rng_rev, n_ticks, int(reversals))
    for attempt in range(DRIVE_ATTEMPTS):
        if attempt:
            # The follower cut a corner into a wall (pure pursuit across a route's cusp: clutter seed 3653 came
            # 0.22 m close at 78 s): draw the drive again from a stream of its own. A drive that passes the first
            # time is the only one drawn, so every world that passed before is byte for byte the same.
            rng_drive = np.random.default_rng(np.random.SeedSequence([int(seed), attempt]))
        truth, pre, start, kidnap, length = _drive(world, rng_drive, n_ticks, speed, turn_rate, kidnap_tick,
                                                   defaults["plan_stride"], defaults["leg_max"], plan, odom_rate,
                                                   sim_dt)
        clear = _clear(truth[:, :2], world).min()
        if clear >= robot_radius + world.resolution:
            break
    else:
        raise RuntimeError(f"simulate: seed {seed}: {DRIVE_ATTEMPTS} drives came {clear:.3f} m close to a wall "
                           "(a bug)")
    if holonomic:
        # A ninth child stream: the others are unchanged.
        rng_hol = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(9)[8])
        off = _holonomic_offsets(rng_hol, np.arange(n_ticks) / odom_rate, float(holonomic))
        truth[:, 2] = _wrap(truth[:, 2] + off)
        pre[:, 2] = _wrap(pre[:, 2] + off)
        start = truth[0].copy()
        if kidnap is not None:
            kidnap["from"], kidnap["to"] = _pose_list(pre[kidnap_tick]), _pose_list(truth[kidnap_tick])
        odom, tv, rv = _odometry_omni(truth, pre, rng_odom, tuple(map(float, odom_alphas)),
                                      odom_scale, odom_yaw_drift, odom_rate=odom_rate)
    else:
        odom, tv, rv = _odometry(truth, pre, rng_odom, tuple(map(float, odom_alphas)),
                                 odom_scale, odom_yaw_drift, odom_rate=odom_rate)

    # --- laser
    t = np.round(np.arange(n_ticks) / odom_rate, 6)
    stalls = _grey_windows(t, int(odom_stalls), float(duration), float(odom_stall_s)) if odom_stalls else []
    _say_cut(stalls, float(odom_stall_s), "--odom-stall-s")
    if stalls:
        odom, tv, rv = _stalled(odom, tv, rv, t, stalls)
    resets = _grey_windows(t, int(odom_resets), float(duration), float(odom_reset_s)) if odom_resets else []
    _say_cut(resets, float(odom_reset_s), "--odom-reset-s")
    if resets:
        odom, tv, rv = _reset(odom, tv, rv, t, resets)
    slips = _grey_windows(t, int(odom_slips), float(duration), float(odom_slip_s)) if odom_slips else []
    _say_cut(slips, float(odom_slip_s), "--odom-slip-s")
    if slips:
        odom, tv, rv = _slipped(odom, tv, rv, t, slips)
    scan_ticks = np.arange(0, n_ticks, scan_every)
    angles = beam_angles(int(n_beams), fov)
    blocked = world.blocked
    _check_memory(scan_ticks.size, angles.size)
    exact = np.empty((scan_ticks.size, angles.size))
    at_laser = _mounted(truth, mount) if mounted else truth  # where each scan is taken from (the robot's truth)
    cast_rays(np.ascontiguousarray(at_laser[scan_ticks].T), angles, blocked, world.origin[0], world.origin[1],
              world.resolution, range_max, exact)
    if scan_sweep:
        exact = _swept(truth, pre, t, scan_ticks, angles, float(scan_sweep), world, range_max, kidnap_tick,
                       mount if mounted else None)
    furniture = []
    if unmapped_furniture:
        # A seventh child stream: the others are unchanged.
        rng_furn = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(7)[6])
        furniture = _unmapped_furniture(world, truth[:, :2], int(unmapped_furniture), robot_radius, rng_furn)
    if dynamic_obstacles or furniture:
        # A fifth child stream: the first four (world, drive, odometry, laser) are unchanged.
        rng_obst = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(5)[4])
        _cast_with_unmapped(world, truth[scan_ticks], t[scan_ticks], angles, range_max, int(dynamic_obstacles),
                            rng_obst, exact, furniture, cast_from=at_laser[scan_ticks] if mounted else None)
    hit_windows = []
    if ground_hits:
        # The ninth child stream (a child depends on its index alone: the others are unchanged), the holonomic
        # offsets' too: with both on, the twelfth (the two drew the same numbers; each alone is the world it was)
        rng_ground = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(12)[11 if holonomic else 8])
        hit_windows = _ground_hits(rng_ground, t[scan_ticks], angles, int(ground_hits), float(duration), exact)
    for a0, a1, reach in body:  # the robot itself, nearer than anything else along those beams
        sector = (angles >= a0) & (angles <= a1)
        exact[:, sector] = np.minimum(exact[:, sector], float(reach))
    if range_scale != 1.0 or range_bias != 0.0:  # the laser's own calibration: K r + B for every return
        hit = exact < range_max
        exact[hit] = np.maximum(exact[hit] * float(range_scale) + float(range_bias), 0.01)
    ranges = _noisy_ranges(exact, rng_laser, range_sigma, p_short, p_max, range_max)
    lm_obs = None
    if landmarks:
        # A sixth child stream: the others (world, drive, odometry, laser, obstacles) are unchanged.
        rng_lm = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(6)[5])
        lm_ids, lm_xy = _place_landmarks(world, int(landmarks), rng_lm)
        lm_obs = _landmark_observations(world, truth[scan_ticks], lm_ids, lm_xy, rng_lm, float(landmark_range),
                                        tuple(map(float, landmark_sigma)), float(landmark_miss), float(landmark_fp))

    # --- write
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    occupancy, map_res = world.occupancy, world.resolution
    phantoms = []
    if phantom_furniture:
        # A tenth child stream: the others are unchanged. Boxes the map shows and the world no longer has (a map
        # made before furniture, pallets or boxes were moved away): the laser sees through them.
        rng_ph = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(10)[9])
        phantoms = _unmapped_furniture(world, truth[:, :2], int(phantom_furniture), robot_radius, rng_ph)
        occupancy = _painted(occupancy, phantoms, world.origin, world.resolution)
    grey = []
    if unknown_floor:
        # Floor the map never saw (a room behind a door closed while mapping, the floor under furniture moved since):
        # N stretches of the drive, evenly spread, with the free cells within GREY_RADIUS of the path made unknown.
        grey = _grey_windows(t, int(unknown_floor), float(duration))
        occupancy = _greyed(occupancy, truth, t, grey, world.origin, world.resolution)
    doubled = []
    if doubled_walls:
        # An eleventh child stream: the others are unchanged. A mapping run whose loop did not quite close: in N
        # patches along the drive the map draws the walls twice, the second copy shifted a little.
        rng_dbl = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(11)[10])
        occupancy, doubled = double_walls(occupancy, truth, int(doubled_walls), rng_dbl, world.origin, world.resolution)
    world_origin = world.origin
    if map_rotation:
        occupancy, world_origin = rotate_map(occupancy, world.resolution, world.origin, float(map_rotation))
    if map_resolution is not None and abs(map_resolution - world.resolution) > 1e-12:
        map_res = float(map_resolution)
        occupancy = resample_occupancy(occupancy, world.resolution, map_res)
    map_res = round(map_res * map_scale, 12)  # the map's cells, as the mapper drew them
    map_origin = (round(world_origin[0] * map_scale, 12), round(world_origin[1] * map_scale, 12))
    grid = OccupancyGrid.from_occupancy(occupancy, map_res, map_origin)
    if map_resolution is not None and map_rotation == 0.0 and map_scale == 1.0:
        # coarse cells thicken walls by up to a cell: a doorway narrower than that closes, and the robot drives
        # through a wall of the map (0.5 m cells: 8 of 301 reference poses in walls, a run lost twice), unsaid
        ix, iy = grid.world_to_cell(truth[:, 0], truth[:, 1])
        inside = grid.contains(ix, iy)
        walled = int(np.count_nonzero(grid.occupied[iy[inside], ix[inside]]))
        if walled:
            import warnings

            from mcl.errors import MclWarning

            warnings.warn(f"--map-resolution {map_res:g}: {walled} of the drive's {len(truth)} poses (every "
                          f"{1.0 / odom_rate:g} s) lie in the map's walls (cells this coarse close a doorway): a filter on this map cannot follow the "
                          "drive there", MclWarning, stacklevel=2)
    save_map(grid, out / "map.yaml")

    host = "sim"
    flaser = _flaser_ok(int(n_beams), fov)
    lines = [f"# mcl simulate seed={int(seed)} duration={duration:g} beams={int(n_beams)} "
             f"fov={fov:.6f} range_max={range_max:g}; poses in the odometry frame\n",
             f"PARAM robot_front_laser_max {range_max:g} {0.0:.6f} {host} {0.0:.6f}\n"]
    gaps = _grey_windows(t, int(scan_gaps), float(duration), float(scan_gap_s)) if scan_gaps else []
    _say_cut(gaps, float(scan_gap_s), "--scan-gap-s")
    # the scans the log keeps: all but those inside a gap (the laser silent, the odometry going on)
    kept = np.ones(scan_ticks.size, dtype=bool)
    for a, b in gaps:
        kept &= ~((t[scan_ticks] >= a) & (t[scan_ticks] < b))
    scan_row = {int(k): i for i, k in enumerate(scan_ticks) if kept[i]}
    # Written as it is formatted, a block of lines at a time: an hour of 2,880-beam scans is 360 MB of text.
    laser_odom = _mounted(odom, mount) if mounted else None  # the laser's pose in the odometry frame, each tick
    with atomic_writer(out / "log.clf", "w", encoding="utf-8") as f:
        for k in range(n_ticks):
            ts = f"{t[k]:.6f} {host} {t[k]:.6f}"
            x, y, th = odom[k]
            lines.append(f"ODOM {x:.6f} {y:.6f} {th:.6f} {tv[k]:.6f} {rv[k]:.6f} 0.000000 {ts}\n")
            i = scan_row.get(k)
            if i is not None:
                rs = " ".join(f"{r:.3f}" for r in ranges[i])
                pose = f"{x:.6f} {y:.6f} {th:.6f}"
                at = pose  # the laser's pose in the odometry frame, then the robot's (CARMEN's order)
                if mounted:
                    lx, ly, lth = laser_odom[k]
                    at = f"{lx:.6f} {ly:.6f} {math.remainder(lth, 2 * math.pi):.6f}"
                if flaser:
                    lines.append(f"FLASER {angles.size} {rs} {at} {pose} {ts}\n")
                else:
                    lines.append(f"ROBOTLASER1 0 {angles[0]:.9f} {fov:.9f} {fov / (angles.size - 1):.9f} "
                                 f"{range_max:g} 0.01 0 {angles.size} {rs} 0 {at} {pose} "
                                 f"{tv[k]:.6f} {rv[k]:.6f} 0.0 0.0 0.0 {ts}\n")
                if lm_obs is not None:
                    lines.append(_landmark_line(lm_obs[i], ts))
            if len(lines) >= _LOG_BLOCK_LINES:
                f.write("".join(lines))
                lines.clear()
        f.write("".join(lines))
    if lm_obs is not None:
        from mcl.landmarks import save_landmarks

        save_landmarks(out / "landmarks.yaml", lm_ids, lm_xy)
    write_tum(out / "truth.tum", t[scan_ticks[kept]],
              map_frame_poses(truth[scan_ticks[kept]], map_rotation, map_scale).T)
    n_depth = 0
    if depth:
        from mcl.depthsim import write_depth_folder
        from mcl.planes import DepthCamera

        # The seventh child stream, the unmapped furniture's too: with both on, the thirteenth (as above)
        rng_depth = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(13)[12 if unmapped_furniture else 6])
        cam = depth_camera if depth_camera is not None else DepthCamera()
        ticks = scan_ticks[:: int(depth_every)]
        n_depth = write_depth_folder(out, world, truth[ticks], t[ticks], rng_depth, cam)

    import yaml

    if map_scale != 1.0 or map_rotation:  # sim.yaml's poses in the map's frame, as truth.tum's
        def in_map(pose):
            return map_frame_poses(np.array(pose, dtype=float)[None], map_rotation, map_scale)[0]

        start = in_map(start)
        if kidnap:
            kidnap = {**kidnap, **{k: _pose_list(in_map(kidnap[k])) for k in ("from", "to")}}
        # a square's centre as a point, its shift as a direction (turned and scaled, not moved)
        doubled = [[round(float(v), 3) for v in (*in_map([x, y, 0.0])[:2], *in_map([dx, dy, 0.0])[:2])]
                   for x, y, dx, dy in doubled]
    params = {
        "kind": kind,
        "seed": int(seed),
        "duration": float(duration),
        "start_pose": _pose_list(start),
        "odom_start_pose": [0.0, 0.0, 0.0],
        "kidnap": kidnap,
        "laser": {"message": "FLASER" if flaser else "ROBOTLASER1", "n_beams": int(n_beams), "fov": float(fov),
                  "angle_min": float(angles[0]), "range_max": float(range_max),
                  "range_sigma": float(range_sigma), "p_short": float(p_short), "p_max": float(p_max),
                  "rate_hz": odom_rate / scan_every},
        "odometry": {"model": "odometry (Probabilistic Robotics Table 5.6, variance form)",
                     "alphas": [float(a) for a in odom_alphas], "scale": float(odom_scale),
                     "yaw_drift_per_m": float(odom_yaw_drift), "rate_hz": odom_rate},
        "robot": {"radius": float(robot_radius), "speed": float(speed), "turn_rate": float(turn_rate)},
        "map": {"resolution": map_res, "origin": [float(grid.origin[0]), float(grid.origin[1])],
                "width": int(occupancy.shape[1]), "height": int(occupancy.shape[0])},
        "scans": int(np.count_nonzero(kept)),
        "path_length": round(length, 3),
        "dynamic_obstacles": int(dynamic_obstacles),
        "unmapped_furniture": len(furniture),
    }
    if reversals:
        params["reversals"] = int(reversals)
    if holonomic:
        params["holonomic"] = float(holonomic)
        params["odometry"]["model"] = "omni (ROS AMCL's omni model, variance form: along, across, turn)"
    if body:
        params["laser"]["body"] = [[float(v) for v in b] for b in body]
    if scan_sweep:
        params["laser"]["sweep_s"] = float(scan_sweep)
    if mounted:
        params["laser"]["pose"] = [float(v) for v in mount]
    if phantoms:
        params["phantom_furniture"] = len(phantoms)
    if doubled:
        params["doubled_walls"] = doubled
    if map_scale != 1.0:
        params["map_scale"] = float(map_scale)
    if map_rotation:
        params["map_rotation"] = float(map_rotation)
    if gaps:
        params["scan_gaps"] = [[round(a, 3), round(b, 3)] for a, b in gaps]
    if stalls:
        params["odom_stalls"] = [[round(a, 3), round(b, 3)] for a, b in stalls]
    if range_scale != 1.0:
        params["range_scale"] = float(range_scale)
    if range_bias != 0.0:
        params["range_bias"] = float(range_bias)
    if slips:
        params["odom_slips"] = [[round(a, 3), round(b, 3)] for a, b in slips]
    if resets:
        params["odom_resets"] = [[round(a, 3), round(b, 3)] for a, b in resets]
    if grey:
        params["unknown_floor"] = [[round(a, 3), round(b, 3)] for a, b in grey]
    if hit_windows:
        params["ground_hits"] = [[round(a, 3), round(b, 3)] for a, b in hit_windows]
    if lm_obs is not None:
        params["landmarks"] = {"count": int(lm_ids.size), "range_max": float(landmark_range),
                               "sigma_range": float(landmark_sigma[0]), "sigma_bearing": float(landmark_sigma[1]),
                               "p_miss": float(landmark_miss), "p_false_positive": float(landmark_fp),
                               "observations": int(sum(o[0].size for o in lm_obs))}
    if depth:
        params["depth"] = {"folder": "depth", "frames": n_depth, "every_scans": int(depth_every),
                           "camera": cam.to_dict()}
    atomic_write_text(out / "sim.yaml", SIM_YAML_HEADER + yaml.safe_dump(params, sort_keys=False))
    return {"outdir": str(out), "scans": int(np.count_nonzero(kept)), "duration": float(t[-1]),
            "path_length": round(length, 3), "start_pose": _pose_list(start), "kidnap": kidnap}


def _unmapped_obstacles(world: World, path_xy: np.ndarray, n: int, rng: np.random.Generator):
    """n obstacles missing from the map: (boxes, people).

    boxes: list of (x0, y0, x1, y1), 0.3-0.8 m sides, centres on reachable
    cells 0.8-3 m from the path (never on it). people: list of (a (2,), b (2,),
    speed m/s, phase): a 0.25 m-radius disc walking from a to b and back, a
    on a reachable cell 0.5-3 m from the path, b 2-5 m away in a random direction.
    """
    from scipy.spatial import cKDTree

    # only cells near the path's bounding box can be within 3 m of it (the same cells, in the same order)
    r = world.resolution
    ix0, iy0 = (np.maximum(((path_xy.min(axis=0) - 3.5 - world.origin) / r).astype(int), 0))
    ix1, iy1 = ((path_xy.max(axis=0) + 3.5 - world.origin) / r).astype(int) + 1
    iy, ix = np.nonzero(world.reachable[iy0:iy1, ix0:ix1])
    cells = np.column_stack([world.origin[0] + (ix + ix0 + 0.5) * world.resolution,
                             world.origin[1] + (iy + iy0 + 0.5) * world.resolution])
    d, _ = cKDTree(path_xy).query(cells)
    n_box = (n + 1) // 2
    box_ok = cells[(d >= 0.8) & (d <= 3.0)]
    walk_ok = cells[(d >= 0.5) & (d <= 3.0)]
    boxes, people = [], []
    for _ in range(n_box):
        if box_ok.size == 0:
            break
        cx, cy = box_ok[rng.integers(box_ok.shape[0])]
        hw, hh = rng.uniform(0.15, 0.4, 2)
        boxes.append((cx - hw, cy - hh, cx + hw, cy + hh))
    for _ in range(n - n_box):
        if walk_ok.size == 0:
            break
        a = walk_ok[rng.integers(walk_ok.shape[0])]
        ang = rng.uniform(-math.pi, math.pi)
        b = a + rng.uniform(2.0, 5.0) * np.array([math.cos(ang), math.sin(ang)])
        people.append((a, b, float(rng.uniform(0.4, 1.0)), float(rng.uniform(0.0, 1.0))))
    return boxes, people


def _unmapped_furniture(world: World, path_xy: np.ndarray, n: int, radius: float,
                        rng: np.random.Generator) -> list[tuple[float, float, float, float]]:
    """n static boxes missing from the map, as (x0, y0, x1, y1): 0.3-0.9 m sides, centres on free cells
    0.3-1.5 m from a wall (furniture stands by walls) and 6 m at most from the path, the whole box
    farther than ``radius`` + 0.1 m from every path point (the drive never touches it)."""
    from scipy.spatial import cKDTree

    ox, oy = world.origin
    r = world.resolution
    lo, hi = path_xy.min(axis=0) - 6.0, path_xy.max(axis=0) + 6.0
    ix0, iy0 = max(int((lo[0] - ox) / r), 0), max(int((lo[1] - oy) / r), 0)
    ix1, iy1 = int((hi[0] - ox) / r) + 1, int((hi[1] - oy) / r) + 1
    sub = (slice(iy0, iy1), slice(ix0, ix1))
    iy, ix = np.nonzero((world.occupancy[sub] == 0) & (world.distance[sub] >= 0.3) & (world.distance[sub] <= 1.5))
    cells = np.column_stack([ox + (ix + ix0 + 0.5) * r, oy + (iy + iy0 + 0.5) * r])
    tree = cKDTree(path_xy)
    d, _ = tree.query(cells)
    cells = cells[(d > 0.75 + radius) & (d <= 6.0)]  # 0.75: a box's half-diagonal (0.64) plus a margin
    boxes = []
    for _ in range(n):
        if cells.shape[0] == 0:
            break
        cx, cy = cells[rng.integers(cells.shape[0])]
        hw, hh = rng.uniform(0.15, 0.45, 2)
        boxes.append((float(cx - hw), float(cy - hh), float(cx + hw), float(cy + hh)))
    return boxes


def _box_cells(box, origin, resolution: float) -> tuple[slice, slice]:
    """(rows, columns) of the cells a box (x0, y0, x1, y1) covers on a grid at ``origin``."""
    x0, y0, x1, y1 = box
    return (slice(max(int((y0 - origin[1]) / resolution), 0), max(int(math.ceil((y1 - origin[1]) / resolution)), 0)),
            slice(max(int((x0 - origin[0]) / resolution), 0), max(int(math.ceil((x1 - origin[0]) / resolution)), 0)))


GREY_RADIUS = 1.5  # m: --unknown-floor makes the free cells this near the path unknown
GREY_SECONDS = 10.0  # s of drive per unknown stretch


def _grey_windows(t: np.ndarray, n: int, duration: float, seconds: float = GREY_SECONDS) -> list:
    """``spread_windows`` over a run of ``duration`` s from 0 (``t`` its ticks): the unknown floor's stretches, the
    laser's gaps."""
    return spread_windows(n, seconds, 0.0, duration, float(t[-1]))


def _say_cut(windows: list, seconds: float, option: str) -> None:
    """A warning when ``spread_windows`` made the windows shorter than ``option`` asked (they may fill at most half
    the time between their centres): `--scan-gaps 1 --scan-gap-s 60` in a 60 s drive made a 15 s gap, unsaid."""
    if windows and max(b - a for a, b in windows) < seconds - 1e-6:
        import warnings

        from mcl.errors import MclWarning

        made = max(b - a for a, b in windows)
        warnings.warn(f"{option} {seconds:g}: each window is {made:.1f} s (at most half the time between their "
                      "centres, and within the drive); sim.yaml lists them", MclWarning, stacklevel=3)


def spread_windows(n: int, seconds: float, start: float, duration: float, end: float | None = None) -> list:
    """``n`` windows (a, b) of ``seconds`` (at most half the time between their centres) centred at k / (n + 1) of
    the span of ``duration`` s from ``start``, k = 1..n, clipped to [start, ``end``] (default start + duration)."""
    end = start + duration if end is None else end
    half = 0.5 * min(seconds, duration / (2.0 * (n + 1)))
    return [(max(c - half, start), min(c + half, end)) for c in
            (start + duration * (k + 1) / (n + 1) for k in range(n))]


def _greyed(occupancy: np.ndarray, truth: np.ndarray, t: np.ndarray, windows, origin, resolution: float) -> np.ndarray:
    """A copy of ``occupancy`` with its free cells within GREY_RADIUS of the path (``truth`` (T, 3) at times ``t``)
    over each window made unknown (-1); walls and the rest stay."""
    out = occupancy.copy()
    h, w = out.shape
    r = int(math.ceil(GREY_RADIUS / resolution))
    dy, dx = np.mgrid[-r:r + 1, -r:r + 1]
    disc = (dx * dx + dy * dy) * resolution * resolution <= GREY_RADIUS * GREY_RADIUS
    for a, b in windows:
        pts = truth[(t >= a) & (t <= b), :2]
        last = None
        for x, y in pts:
            if last is not None and math.hypot(x - last[0], y - last[1]) < 0.25:
                continue
            last = (x, y)
            cx, cy = int((x - origin[0]) / resolution), int((y - origin[1]) / resolution)
            ys, xs = cy + dy[disc], cx + dx[disc]
            ok = (ys >= 0) & (ys < h) & (xs >= 0) & (xs < w)
            ys, xs = ys[ok], xs[ok]
            free = out[ys, xs] == 0
            out[ys[free], xs[free]] = -1
    return out


DOUBLED_SIDE = 10.0  # m: --doubled-walls draws the walls twice in squares this wide
DOUBLED_SHIFT = (0.1, 0.3)  # m: how far the second copy lies from the walls


def double_walls(occupancy: np.ndarray, truth: np.ndarray, n: int, rng: np.random.Generator, origin,
             resolution: float) -> tuple[np.ndarray, list]:
    """A copy of ``occupancy`` whose walls in ``n`` squares of DOUBLED_SIDE, centred on the path (``truth`` (T, 3))
    at k / (n + 1) of the drive, k = 1..n, are drawn a second time, shifted DOUBLED_SHIFT in a direction drawn
    from ``rng``: the doubled walls of a SLAM map whose loop closure left a part of the building misplaced. The copy
    is drawn on free and unknown cells only (it may narrow a corridor or a door). Returns the map and, per square,
    [x, y, dx, dy] (its centre and the copy's shift, m)."""
    out = occupancy.copy()
    wall = occupancy == 100
    h, w = out.shape
    half = int(round(0.5 * DOUBLED_SIDE / resolution))
    squares = []
    for k in range(n):
        x, y = truth[int(round((k + 1) / (n + 1) * (len(truth) - 1))), :2]
        shift = rng.uniform(*DOUBLED_SHIFT)
        angle = rng.uniform(-math.pi, math.pi)
        sx, sy = int(round(shift * math.cos(angle) / resolution)), int(round(shift * math.sin(angle) / resolution))
        cx, cy = int((x - origin[0]) / resolution), int((y - origin[1]) / resolution)
        r0, r1 = max(cy - half, 0), min(cy + half, h)
        c0, c1 = max(cx - half, 0), min(cx + half, w)
        rows, cols = np.nonzero(wall[r0:r1, c0:c1])
        rows, cols = rows + r0 + sy, cols + c0 + sx
        ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        out[rows[ok], cols[ok]] = 100
        squares.append([round(float(x), 3), round(float(y), 3), round(sx * resolution, 3), round(sy * resolution, 3)])
    return out, squares


def _stalled(odom: np.ndarray, tv: np.ndarray, rv: np.ndarray, t: np.ndarray, windows) -> tuple:
    """(odometry poses, tv, rv) with the odometry stalled over each window [a, b) of ``t``: it holds the pose it had
    before a and reads no velocity, and from b on it goes on from the held pose with the steps it measured (each
    later pose p becomes held ∘ last^-1 ∘ p, ``last`` the pose reached at the window's end): the motion inside the
    window is lost, as when an encoder driver hangs."""
    from mcl.estimate import compose, inverse

    odom, tv, rv = odom.copy(), tv.copy(), rv.copy()
    for a, b in windows:
        ka, kb = int(np.searchsorted(t, a)), int(np.searchsorted(t, b))
        if ka == 0 or ka >= kb:
            continue
        fix = compose(odom[ka - 1], inverse(odom[kb - 1]))
        odom[ka:kb] = odom[ka - 1]
        tv[ka:kb] = 0.0
        rv[ka:kb] = 0.0
        odom[kb:] = _composed(fix, odom[kb:])
    return odom, tv, rv


def _composed(fix: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """fix ∘ p for each pose p of ``poses`` (K, 3): odometry moved rigidly."""
    c, s = math.cos(fix[2]), math.sin(fix[2])
    x, y = poses[:, 0], poses[:, 1]
    return np.column_stack([fix[0] + c * x - s * y, fix[1] + s * x + c * y, _wrap(poses[:, 2] + fix[2])])


def _reset(odom: np.ndarray, tv: np.ndarray, rv: np.ndarray, t: np.ndarray, windows) -> tuple:
    """(odometry poses, tv, rv) with the odometry restarted at the end b of each window [a, b) of ``t``: it holds
    its pose over the window (``_stalled``; none when a == b) and from b on reads the robot's motion since b, from
    (0, 0, 0): each later pose p becomes at_b^-1 ∘ p, as when a base driver restarts."""
    odom, tv, rv = _stalled(odom, tv, rv, t, [(a, b) for a, b in windows if b > a])
    for _, b in windows:
        kb = int(np.searchsorted(t, b))
        if kb == 0 or kb >= t.size:
            continue
        x0, y0, th0 = odom[kb]
        c, s = math.cos(th0), math.sin(th0)
        dx, dy = odom[kb:, 0] - x0, odom[kb:, 1] - y0
        odom[kb:, 0], odom[kb:, 1] = c * dx + s * dy, -s * dx + c * dy
        odom[kb:, 2] = _wrap(odom[kb:, 2] - th0)
    return odom, tv, rv


SLIP_BASE = 0.4  # m: the wheel base of ``_slipped``'s differential drive


def _slipped(odom: np.ndarray, tv: np.ndarray, rv: np.ndarray, t: np.ndarray, windows) -> tuple:
    """(odometry poses, tv, rv) with the right wheel slipping over each window [a, b) of ``t``: it reads twice its
    travel, so each odometry step there (translation d along (dx, dy), turn dth) reads (1.5 dx, 1.5 dy,
    dth + d / SLIP_BASE) and tv, rv the same; after the window every pose goes on rigidly from where the slip left
    it (each later pose p becomes slipped_end ∘ end^-1 ∘ p)."""
    from mcl.estimate import compose, inverse

    odom, tv, rv = odom.copy(), tv.copy(), rv.copy()
    for a, b in windows:
        ka, kb = int(np.searchsorted(t, a)), int(np.searchsorted(t, b))
        if ka == 0 or ka >= kb:
            continue
        orig = odom.copy()
        for k in range(ka, kb):
            step = compose(inverse(orig[k - 1]), orig[k])
            d = math.copysign(math.hypot(step[0], step[1]), step[0])
            odom[k] = compose(odom[k - 1], np.array([1.5 * step[0], 1.5 * step[1], step[2] + d / SLIP_BASE]))
        tv[ka:kb] *= 1.5
        rv[ka:kb] += tv[ka:kb] / 1.5 / SLIP_BASE
        if kb < t.size:
            odom[kb:] = _composed(compose(odom[kb - 1], inverse(orig[kb - 1])), orig[kb:])
    return odom, tv, rv


def map_frame_poses(poses: np.ndarray, rotation: float, scale: float) -> np.ndarray:
    """World poses (N, 3) in the frame of a map turned by ``rotation`` rad about the frame's zero, then drawn
    ``scale`` times the world's size (``rotate_map``, ``map_scale``). Without a rotation the headings are the same
    numbers."""
    if not rotation:
        return poses * [scale, scale, 1.0]
    c, s = math.cos(rotation), math.sin(rotation)
    x, y = poses[:, 0], poses[:, 1]
    return np.column_stack([scale * (c * x - s * y), scale * (s * x + c * y),
                            np.remainder(poses[:, 2] + rotation + math.pi, 2 * math.pi) - math.pi])


def rotate_map(occupancy: np.ndarray, resolution: float, origin, angle: float):
    """The grid ``occupancy`` (-1 unknown, 0 free, 100 occupied; row 0 at the bottom, its corner at ``origin``)
    turned by ``angle`` rad about the frame's zero and drawn again on cells of the same size along the new axes, as
    a mapper whose frame is turned against the building draws it: its corner moves to R(angle) ``origin`` and the
    image turns about it, which is a map_server map with ``origin: [x, y, angle]``, so ``mcl.maps.axis_aligned``
    draws it, as the map loader does such a map: each new cell takes the old cell under its centre (off the old
    grid: unknown). A wall across the cells becomes a staircase whose cells touch at their corners; a ray cast from
    cell to cell still cannot pass between them. Returns the grid and its origin (x, y)."""
    from mcl.maps import axis_aligned

    c, s = math.cos(angle), math.sin(angle)
    ox, oy = float(origin[0]), float(origin[1])
    out, corner = axis_aligned(occupancy, resolution, (c * ox - s * oy, s * ox + c * oy), angle)
    return out, (round(corner[0], 12), round(corner[1], 12))


def _painted(occupancy: np.ndarray, boxes, origin, resolution: float) -> np.ndarray:
    """A copy of ``occupancy`` with the ``boxes`` (x0, y0, x1, y1) drawn occupied (100)."""
    out = occupancy.copy()
    for box in boxes:
        out[_box_cells(box, origin, resolution)] = 100
    return out


def _cast_with_unmapped(world: World, poses: np.ndarray, times: np.ndarray, angles: np.ndarray, range_max: float,
                        n: int, rng: np.random.Generator, out: np.ndarray, furniture=(), cast_from=None) -> None:
    """Cast every scan (poses (M, 3)) into ``out`` (M, B) against the world plus ``n`` unmapped obstacles
    and the unmapped ``furniture`` boxes. ``cast_from`` (M, 3): the laser's poses when it is not at the robot's
    centre (the obstacles are placed by the robot's ``poses`` either way).

    Obstacles are painted on free cells only. A person within 0.6 m of the
    robot steps aside (is not drawn); boxes stand at least 0.8 m from the path.
    """
    from mcl.kernels.raycast import cast_rays, cast_rays_serial

    boxes, people = _unmapped_obstacles(world, poses[:, :2], n, rng) if n else ([], [])
    laser = poses if cast_from is None else cast_from  # where each scan is cast from
    boxes = boxes + list(furniture)
    res = world.resolution
    ox, oy = world.origin
    h, w = world.occupancy.shape
    sub = (slice(None), slice(None))
    if h * w > 2_000_000:  # a big map: cast inside the box no ray of range_max can leave
        ix0, iy0 = np.maximum(((laser[:, :2].min(axis=0) - range_max - 1.0 - world.origin) / res).astype(int), 0)
        ix1, iy1 = ((laser[:, :2].max(axis=0) + range_max + 1.0 - world.origin) / res).astype(int) + 1
        sub = (slice(iy0, iy1), slice(ix0, ix1))
        ox, oy = ox + ix0 * res, oy + iy0 * res
    base = np.ascontiguousarray(world.blocked[sub])
    free = world.occupancy[sub] == 0
    h, w = base.shape
    static = np.zeros_like(base)
    for box in boxes:
        static[_box_cells(box, (ox, oy), res)] = True
    if not people:  # static only: one cast of every scan
        cast_rays(np.ascontiguousarray(laser.T), angles, np.ascontiguousarray(base | (static & free)), ox, oy, res,
                  range_max, out)
        return
    yy = oy + (np.arange(h) + 0.5) * res
    xx = ox + (np.arange(w) + 0.5) * res
    for m in range(poses.shape[0]):
        rx, ry = poses[m, 0], poses[m, 1]
        grid = base | (static & free)
        for a, b, speed, phase in people:
            length = float(np.hypot(*(b - a)))
            s = (phase * 2 * length + speed * times[m]) % (2 * length)
            c = a + (b - a) * (min(s, 2 * length - s) / length)
            if math.hypot(c[0] - rx, c[1] - ry) < 0.6 + 0.25:
                continue
            j0, j1 = np.searchsorted(xx, [c[0] - 0.25, c[0] + 0.25])
            i0, i1 = np.searchsorted(yy, [c[1] - 0.25, c[1] + 0.25])
            disc = (xx[None, j0:j1] - c[0]) ** 2 + (yy[i0:i1, None] - c[1]) ** 2 <= 0.25 ** 2
            grid[i0:i1, j0:j1] |= disc & free[i0:i1, j0:j1]
        cast_rays_serial(np.ascontiguousarray(laser[m : m + 1].T), angles, np.ascontiguousarray(grid), ox, oy, res,
                         range_max, out[m : m + 1])


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mcl simulate``."""
    parser.add_argument("outdir", help="folder to write map.yaml, map.pgm, log.clf (or a bag), truth.tum, sim.yaml; "
                        "an earlier world there is replaced once the new one is whole")
    parser.add_argument("--kind", choices=KINDS, default="office",
                        help="world layout: office (default; the demo's ~20x15 m building), rooms (identical rooms "
                        "off a corridor: ambiguous), corridor (60-150 m, featureless), hall (40-80 m open hall, "
                        "sparse pillars), clutter (office full of small furniture, people and furniture the map "
                        "lacks), large (150-200 m building), warehouse (40-70 m: rows of pallet racks, aisles "
                        "alike)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (world, path, noise); default 0")
    parser.add_argument("--duration", type=float, default=60.0, help="seconds of driving, 1-3600; default 60")
    parser.add_argument("--range-max", type=float, default=12.0,
                        help="laser maximum range in m, 0.5-100; default 12 (hall: 20-30 m reaches its walls)")
    parser.add_argument("--beams", type=int, default=181,
                        help="beams over the field of view, 2-4096; default 181 (FLASER at 180 degrees; other "
                        "geometries write ROBOTLASER1)")
    parser.add_argument("--fov", type=float, default=180.0, metavar="DEG",
                        help="laser field of view in degrees; default 180 (a short-range URG-like laser: "
                        "--range-max 5.6 --fov 240)")
    parser.add_argument("--speed", type=float, default=None, metavar="V",
                        help="the robot's cruise speed in m/s; default the kind's (office and rooms 0.5, clutter "
                        "0.4, corridor, hall and warehouse 0.8, large 1.0). The path follower's 0.5 m lookahead keeps the "
                        "drive under about 0.8 m/s whatever the cruise speed")
    parser.add_argument("--kidnap-at", type=float, default=None, metavar="T",
                        help="teleport the robot at time T s, before the drive's end (odometry does not see it); "
                        "default none")
    parser.add_argument("--dynamic-obstacles", type=int, default=None, metavar="N",
                        help="N obstacles the map does not show (boxes near the path, walking people); default 0 "
                        "(clutter: 10)")
    parser.add_argument("--unmapped-furniture", type=int, default=None, metavar="N",
                        help="N static boxes by the walls that the map does not show; default 0 (clutter: 12)")
    parser.add_argument("--landmarks", type=int, default=0, metavar="K",
                        help="K point landmarks near walls: landmarks.yaml and a LANDMARK line per scan; default 0")
    parser.add_argument("--landmark-range", type=float, default=8.0, metavar="M",
                        help="range of the landmark detector in m; default 8")
    parser.add_argument("--depth", action="store_true",
                        help="a Kinect-like depth camera (640x480, 57x43 deg, 0.5-4.5 m) in a 2.5D world: depth/")
    parser.add_argument("--depth-every", type=int, default=1, metavar="K",
                        help="a depth frame every K-th scan; default 1")
    parser.add_argument("--format", choices=["clf", "bag1", "db3", "mcap"], default="clf",
                        help="the log as a CARMEN log.clf (default) or a ROS bag: log.bag (ROS 1), log.db3 or "
                        "log.mcap (ROS 2), with /scan, the odometry as /odom and as odom -> base_link on /tf, "
                        "/tf_static and the truth as /ground_truth")
    parser.add_argument("--map-resolution", type=float, default=None, metavar="M",
                        help="write the map with M metre cells (0.01-0.5) instead of the world's 0.05 m, as a "
                        "mapper at that resolution would (walls thicken on coarser maps); the laser still sees "
                        "the world")
    parser.add_argument("--reversals", type=int, default=0, metavar="R",
                        help="back the robot up R times over the run, 0.5-3 m along its own track each time "
                        "(its odometry then reads steps backwards); default 0")
    parser.add_argument("--holonomic", type=float, default=0.0, metavar="DEG",
                        help="an omnidirectional base: its heading leaves the direction of travel by up to DEG "
                        "degrees (0-180), so it strafes, and its odometry is noisy along, across and in the turn "
                        "(AMCL's omni model); default 0 (a differential drive)")
    parser.add_argument("--scan-rate", type=float, default=5.0, metavar="HZ",
                        help="laser scans per second, 0.5-100; default 5. The odometry's ODOM lines run at 10 Hz "
                        "or at the scan rate when that is higher (ROS robots' lasers: 10-40 Hz); a bag's /odom, /tf "
                        "and /ground_truth hold one pose per scan, at its stamp")
    parser.add_argument("--phantom-furniture", type=int, default=0, metavar="N",
                        help="N boxes (0.3-0.9 m) the map shows near walls within 6 m of the path that the world "
                        "no longer has (furniture moved away since the map was made): the laser sees through "
                        "them; default 0")
    parser.add_argument("--unknown-floor", type=int, default=0, metavar="N",
                        help="N stretches of the drive (10 s each, evenly spread) over floor the map never saw: its "
                        "free cells within 1.5 m of the path are unknown on the map (a room behind a door closed "
                        "while mapping, the floor under furniture moved since); default 0")
    parser.add_argument("--doubled-walls", type=int, default=0, metavar="N",
                        help="N squares of 10 m along the drive (evenly spread) where the map draws the walls twice, "
                        "the second copy shifted 0.1-0.3 m (a SLAM map whose loop did not quite close; the copy may "
                        "narrow a corridor or a door); the laser sees the walls once; default 0")
    parser.add_argument("--map-scale", type=float, default=1.0, metavar="S",
                        help="draw the map S times the world's size (0.9-1.1: a floor plan whose scale is off by a "
                        "percent or two); the laser and the odometry measure the world, truth.tum is in the map's "
                        "frame; default 1")
    parser.add_argument("--map-rotation", type=float, default=0.0, metavar="DEG",
                        help="draw the map turned by DEG degrees (-180..180: a SLAM map whose frame started at the "
                        "robot's heading, so its walls run across the cells as staircases); the laser and the "
                        "odometry are the same, truth.tum is in the map's frame; default 0")
    parser.add_argument("--scan-gaps", type=int, default=0, metavar="N",
                        help="the laser silent N times over the run (evenly spread) for --scan-gap-s each, the "
                        "odometry going on (a driver restart, a USB reset, a stalled scan topic); default 0")
    parser.add_argument("--scan-gap-s", type=float, default=5.0, metavar="S",
                        help="seconds of each --scan-gaps gap (0.5-60); default 5")
    parser.add_argument("--odom-stalls", type=int, default=0, metavar="N",
                        help="the odometry stalled N times over the run (evenly spread) for --odom-stall-s each: it "
                        "holds its pose while the robot drives on, then goes on from there (an encoder driver that "
                        "hangs; the motion in the stall is lost); default 0")
    parser.add_argument("--odom-stall-s", type=float, default=3.0, metavar="S",
                        help="seconds of each --odom-stalls stall (0.5-60); default 3")
    parser.add_argument("--odom-resets", type=int, default=0, metavar="N",
                        help="the odometry restarted N times over the run (evenly spread): its pose starts again "
                        "from 0 0 0 where the robot is (a base driver that restarts); default 0")
    parser.add_argument("--odom-reset-s", type=float, default=0.0, metavar="S",
                        help="seconds each --odom-resets driver is down before it restarts, the odometry holding "
                        "its pose (0-60); default 0")
    parser.add_argument("--odom-slips", type=int, default=0, metavar="N",
                        help="a wheel slipping N times over the run (evenly spread) for --odom-slip-s each: the "
                        "odometry reads 1.5 times the travel and a turn the robot did not make; default 0")
    parser.add_argument("--odom-slip-s", type=float, default=2.0, metavar="S",
                        help="seconds of each --odom-slips slip (0.5-60); default 2")
    parser.add_argument("--range-scale", type=float, default=1.0, metavar="K",
                        help="the laser reads K r + --range-bias m for a return at r m (a laser calibrated against "
                        "another range than the map's: a cheap lidar's few per cent; 0.5-1.5); default 1")
    parser.add_argument("--range-bias", type=float, default=0.0, metavar="B",
                        help="metres added to every return before the noise (-1..1); default 0")
    parser.add_argument("--scan-sweep", type=float, default=0.0, metavar="S",
                        help="the laser takes S seconds from its first beam to its last (a spinning lidar: 0.1-0.2 "
                        "s a turn), beams in angle order from the stamp, while the robot moves (negative: the last "
                        "beam first); at most one scan period, needs --dynamic-obstacles 0 --unmapped-furniture 0. "
                        "A bag (--format) carries |S| as LaserScan time_increment; default 0 (every beam at the "
                        "stamp)")
    parser.add_argument("--laser-pose", nargs=3, type=float, default=None, metavar=("X", "Y", "THETA"),
                        help="mount the laser at (X, Y, THETA) on the robot (m, m, rad; within the robot's 0.2 m "
                        "radius), e.g. 0.15 0 0 ahead of the centre or -0.15 0 3.1416 at the back looking back: the "
                        "log carries the laser's pose beside the robot's (a bag: base_link -> laser on /tf_static), "
                        "truth.tum the robot's; default 0 0 0")
    parser.add_argument("--body", nargs=3, type=float, action="append", default=None, metavar=("A0", "A1", "R"),
                        help="the robot itself in the laser's view: the beams between A0 and A1 degrees (laser "
                        "frame, 0 ahead, -180..180) read R m on every scan (a wheel, a bumper's corner, a mast's "
                        "post); repeatable, e.g. --body -135 -120 0.25 --body 120 135 0.25; default none")
    noise = parser.add_argument_group(
        "noise", "the laser's and the odometry's (default: the values below, as suites/synthetic.yaml's worlds have)")
    noise.add_argument("--range-sigma", type=float, default=None, metavar="M",
                       help="std of a hit's range error (sigma_hit); default 0.02 m")
    noise.add_argument("--p-short", type=float, default=None, metavar="P",
                       help="share of beams ending short, uniformly before the wall; default 0.03")
    noise.add_argument("--p-max", type=float, default=None, metavar="P",
                       help="share of beams returning nothing (written as the maximum range); default 0.01")
    noise.add_argument("--odom-alphas", default=None, metavar="A1,A2,A3,A4",
                       help="the odometry motion model's alpha1..alpha4, variance form (Table 5.6: the variance of "
                       "rot1 is alpha1 rot1^2 + alpha2 trans^2, ...); default 0.05,0.05,0.05,0.02. Drawn at every "
                       "odometry step (10 Hz, or the scan rate when faster): a faster --scan-rate takes shorter steps, "
                       "and the same drive's odometry is less noisy (at 40 Hz about half the error of 5 Hz)")
    noise.add_argument("--odom-scale", type=float, default=None, metavar="S",
                       help="every odometry translation times S (a wheel radius off), 0.5-1.5; default 1.01")
    noise.add_argument("--odom-yaw-drift", type=float, default=None, metavar="R",
                       help="rad of heading error per metre travelled; default 0.01. Set --odom-scale 1 "
                       "--odom-yaw-drift 0 for odometry with the motion model's noise only (to check mcl calibrate)")
    parser.add_argument("--ground-hits", type=int, default=0, metavar="G",
                        help="tilt the laser onto the ground G times over the run, 2 s each: a line of returns "
                        "1.5-5 m ahead, moving every scan, on no map (a robot rocking on a ramp); default 0")


def write_log_as_bag(outdir, fmt: str, sweep: float = 0.0) -> Path:
    """Replace ``outdir/log.clf`` by the same data as a ROS bag (``log.bag``, ``log.db3`` or ``log.mcap``,
    mcl.datasets.bagwrite): /scan, the odometry as /odom and as odom -> base_link on /tf (a ROS robot's bag has
    both, REP 105), /tf_static, and truth.tum as /ground_truth. ``sweep`` (the world's ``scan_sweep``) gives each
    LaserScan its time_increment, |sweep| / (beams - 1): positive for a negative sweep too, as ``rplidar_ros``
    writes beams taken against their order."""
    from mcl.datasets.bagwrite import convert
    from mcl.trajectory import read_tum

    out = Path(outdir)
    bag = out / ("log." + {"bag1": "bag", "db3": "db3", "mcap": "mcap"}[fmt])
    if bag.exists():
        bag.unlink()
    convert(out / "log.clf", bag, odom="both", truth=read_tum(out / "truth.tum"), echo=lambda m: None,
            sweep=abs(sweep))
    (out / "log.clf").unlink()
    return bag


def _simulate_from_args(args: argparse.Namespace) -> dict:
    noise = {k: getattr(args, k, None) for k in ("range_sigma", "p_short", "p_max", "odom_scale", "odom_yaw_drift")}
    if getattr(args, "odom_alphas", None) is not None:
        try:
            noise["odom_alphas"] = tuple(float(v) for v in args.odom_alphas.split(","))
        except ValueError:
            raise ConfigError(f"--odom-alphas: expected four numbers A1,A2,A3,A4, got {args.odom_alphas!r}") from None
    noise = {k: v for k, v in noise.items() if v is not None}  # the options not given keep simulate()'s defaults
    holonomic = getattr(args, "holonomic", 0.0) or 0.0
    if not 0.0 <= holonomic <= 180.0:  # said in the option's degrees, not simulate()'s radians
        raise ConfigError(f"--holonomic: expected 0..180 degrees, got {holonomic:g}")
    map_rotation = getattr(args, "map_rotation", 0.0) or 0.0
    if not (math.isfinite(map_rotation) and -180.0 <= map_rotation <= 180.0):
        raise ConfigError(f"--map-rotation: expected -180..180 degrees, got {map_rotation:g}")
    for a0, a1, r in getattr(args, "body", None) or []:
        if not (-180.0 <= a0 < a1 <= 180.0 and 0.0 < r < args.range_max):
            raise ConfigError(f"--body {a0:g} {a1:g} {r:g}: expected A0 A1 R with -180 <= A0 < A1 <= 180 degrees and "
                              f"0 < R < the range maximum ({args.range_max:g} m)")
    return simulate(args.outdir, **noise, kind=args.kind, seed=args.seed, duration=args.duration,
                    range_max=args.range_max, n_beams=args.beams, fov=math.radians(args.fov), speed=args.speed,
                    kidnap_at=args.kidnap_at,
                    dynamic_obstacles=args.dynamic_obstacles, unmapped_furniture=args.unmapped_furniture,
                    landmarks=args.landmarks, landmark_range=args.landmark_range, depth=args.depth,
                    depth_every=args.depth_every, map_resolution=args.map_resolution,
                    reversals=args.reversals, ground_hits=args.ground_hits, scan_rate=args.scan_rate,
                    scan_sweep=args.scan_sweep, phantom_furniture=args.phantom_furniture,
                    unknown_floor=args.unknown_floor, doubled_walls=args.doubled_walls, map_scale=args.map_scale,
                    map_rotation=math.radians(map_rotation), scan_gaps=args.scan_gaps, scan_gap_s=args.scan_gap_s,
                    odom_stalls=args.odom_stalls, odom_stall_s=args.odom_stall_s,
                    odom_resets=args.odom_resets, odom_reset_s=args.odom_reset_s,
                    odom_slips=args.odom_slips, odom_slip_s=args.odom_slip_s,
                    range_scale=args.range_scale, range_bias=args.range_bias,
                    laser_pose=tuple(args.laser_pose) if getattr(args, "laser_pose", None) else (0.0, 0.0, 0.0),
                    body=[[math.radians(a0), math.radians(a1), r] for a0, a1, r in (getattr(args, "body", None) or [])],
                    holonomic=math.radians(holonomic))


# What ``mcl simulate`` writes into its folder: an earlier world's are replaced whole, anything else is kept
WORLD_OUTPUTS = ("map.yaml", "map.pgm", "log.clf", "log.bag", "log.db3", "log.mcap", "truth.tum", "sim.yaml",
                 "landmarks.yaml", "depth")


def _check_memory(scans: int, beams: int) -> None:
    """ConfigError before the ranges are cast when they cannot fit: the exact ranges, the noisy ones and their text
    take about 3 x 8 bytes a reading (an hour at 100 Hz of 4,096 beams asked for 11 GB, a traceback)."""
    from mcl.maps import available_memory

    need, free = 24 * scans * beams, available_memory()
    if free is not None and need > free:
        def size(b: float) -> str:
            return f"{b / 1e9:.1f} GB" if b >= 1e9 else f"{b / 1e6:.0f} MB"

        raise ConfigError(f"simulate: {scans:,} scans of {beams:,} beams need about {size(need)}, and {size(free)} "
                          "are free: a shorter --duration, a lower --scan-rate or fewer --beams")


_MAKING = ".mcl-world."  # the prefix of the folder inside OUTDIR a world is made in, before it is moved in place


def _is_world_record(path: Path) -> bool:
    """Whether ``path`` is a sim.yaml mcl simulate wrote (its kind, seed and start pose), not a file of that name."""
    from mcl.yamlfile import read_yaml

    try:
        doc = read_yaml(path, ConfigError)
    except ConfigError:
        return False
    return isinstance(doc, dict) and doc.get("kind") in KINDS and {"seed", "duration", "start_pose"} <= set(doc)


def _check_world_folder(out: Path) -> None:
    """ConfigError unless ``out`` is new, empty, or an earlier world (the sim.yaml mcl simulate writes): a folder of
    other files would get a world's files among its own (a map.yaml of the user's overwritten; a sim.yaml of
    another simulator's was taken for one of ours)."""
    if not out.is_dir():
        return
    entries = sorted(p.name for p in out.iterdir() if not p.name.startswith(_MAKING))
    if entries and not (out / "sim.yaml").is_file():
        shown = ", ".join(entries[:3]) + (", ..." if len(entries) > 3 else "")
        raise ConfigError(f"OUTDIR {out}: holds files ({shown}) and no sim.yaml: not an earlier world; choose a "
                          "new or empty folder")
    if entries and not _is_world_record(out / "sim.yaml"):
        raise ConfigError(f"OUTDIR {out}: its sim.yaml is not one mcl simulate wrote (no kind, seed, duration and "
                          "start_pose): not an earlier world; choose a new or empty folder")


def _swap_world(tmp: Path, out: Path) -> None:
    """The world made in ``tmp`` put in place of ``out``'s earlier one: every file an earlier world had goes (a
    bag, landmarks or depth frames of another run stayed beside the new map and log), others (a README) stay."""
    import shutil

    def remove(old: Path) -> None:
        if old.is_dir() and not old.is_symlink():
            shutil.rmtree(old)
        elif old.exists() or old.is_symlink():
            old.unlink()

    made = {p.name for p in tmp.iterdir()}
    for name in sorted(made):  # each file over the earlier one's (``tmp`` is inside ``out``: one file system)
        if (out / name).is_dir():
            remove(out / name)
        os.replace(tmp / name, out / name)
    for name in WORLD_OUTPUTS:  # the earlier world's files this one has not
        if name not in made:
            remove(out / name)
    tmp.rmdir()


def run_from_args(args: argparse.Namespace) -> int:
    """Run ``mcl simulate`` from parsed arguments; prints a one-line summary. The world is made in a folder inside
    OUTDIR and moved in when whole: an error or Ctrl-C leaves OUTDIR as it was."""
    import shutil
    import tempfile

    from mcl.runner import folder_lock
    from mcl.trajectory import check_writable_folder

    out = Path(args.outdir)
    check_writable_folder(out, f"OUTDIR {args.outdir}")
    _check_world_folder(out)
    # the world is made inside OUTDIR, on its file system (beside it, a mount point's world could not be moved in,
    # and a read-only parent refused a writable OUTDIR); folders made here go again if the world is not made
    made = [p for p in (out.resolve(), *out.resolve().parents) if not p.exists()]
    out.mkdir(parents=True, exist_ok=True)
    done = False
    try:
        # one simulate at a time in a folder: a second removed the first's working folder as stale
        with folder_lock(out, f"OUTDIR {out}: another mcl simulate is writing a world there"):
            for stale in out.glob(f"{_MAKING}*"):  # of a run that was killed
                shutil.rmtree(stale, ignore_errors=True)
            tmp = Path(tempfile.mkdtemp(dir=out, prefix=_MAKING))
            try:
                s = _make_in(args, tmp)
                _swap_world(tmp, out)
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
        done = True
    finally:
        if not done:  # deepest first: `mcl simulate new/a/w --duration -5` left new/a behind
            for p in made:
                with contextlib.suppress(OSError):
                    p.rmdir()
    s["outdir"] = str(out)
    x, y, th = s["start_pose"]
    msg = (f"{s['outdir']}: {s['scans']} scans, {s['duration']:.1f} s, path {s['path_length']:.1f} m, "
           f"start pose {x:.3f} {y:.3f} {th:.3f}")
    if s["kidnap"]:
        msg += f", kidnapped at {s['kidnap']['t']:.1f} s"
    print(msg)
    return 0


def _make_in(args: argparse.Namespace, tmp: Path) -> dict:
    """The world of ``args`` made in ``tmp`` (a bag too, with ``--format``); its summary. An error in a parameter
    names the option as the command line spells it ("simulate: n_beams" -> "--beams")."""
    try:
        s = _simulate_from_args(argparse.Namespace(**{**vars(args), "outdir": str(tmp)}))
    except ConfigError as e:
        key, _, msg = str(e).removeprefix("simulate: ").partition(": ")
        option = {"n_beams": "beams"}.get(key, key)
        if not hasattr(args, option):
            raise
        raise ConfigError(f"--{option.replace('_', '-')}: {msg}") from None
    fmt = getattr(args, "format", "clf")
    if fmt != "clf":
        write_log_as_bag(tmp, fmt, sweep=args.scan_sweep)
        if getattr(args, "landmarks", 0):  # the bag holds no LANDMARK lines: said, not dropped in silence
            print(f"mcl: note: --landmarks with --format {fmt}: the detections are not in the bag (no bag message "
                  "carries them); landmarks.yaml is written, and --format clf keeps them in the log",
                  file=sys.stderr)
    return s
