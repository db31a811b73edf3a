"""Do the scans move as the odometry says? A check of the odometry's sign and the laser's mounting, before a run.

A robot new to mcl can bring odometry whose turns have the wrong sign (a left-handed frame, a driver's convention),
or a laser whose mounting is off by a half or a quarter turn (a tf through the wrong frame, a laser mounted looking
back or upside down and not declared so). The filter then predicts every particle the wrong way and is lost from the
first turn, and nothing says why: intel_lab with its turns reversed (``scripts/degrade_laser.py --turn-scale -1``)
is "believed lost in 339 of 910 updates" and takes 79 s instead of 1.

The check: pairs of scans taken close together (the odometry moved ``step`` m or turned ``step`` rad from one to the
other, at most ``max_move`` m and ``max_turn`` rad: the two scans overlap), up to ``pairs`` of them among the first
``max_read`` scans. For each pair, the second scan's points are placed in the first's frame by the motion each
*hypothesis* gives, and scored by their mean squared distance (truncated at ``TRUNCATE`` m) to the first's points:

- as recorded: the odometry's motion, the laser on its mounting;
- the turns reversed: the motion mirrored, (dx, -dy, -dtheta) (a left-handed odometry, or an upside-down laser
  read as upright);
- the laser turned a half turn or a quarter turn either way from its mounting;
- the distances halved or doubled (a wheel's diameter taken for its radius, or the other way round: the odometry
  reports twice or half the distance driven).

A pair is won by the hypothesis that fits best, when that is "as recorded" or beats it by ``MARGIN``; else a tie.
An alternative is reported when it wins ``MIN_WINS`` pairs or more and twice as many as "as recorded".

Points nearer than ``MIN_RANGE`` are left out (a robot's own frame in view stays put and favours the smallest motion),
and the distance readings are weighed only on pairs whose first scan's surfaces face the motion (``_along``): along a
featureless corridor a distance and twice it fit alike.

Only the second scan's points that the first could have seen under a hypothesis are scored (within its beams'
angular span and its farthest point's range; under half of them: the worst score). Without that rule a laser looking
back, moving away from what it sees, lost the near ends of a corridor's walls from the first scan's view under the
true motion, and a correctly mounted rear laser was found "turned half a turn" in 2 of 3 corridor drives (25 and 19
pairs against 0 and 2); a laser looking ahead gained as much the other way.

Measured (2026-12-01, with that rule), 60 pairs a log, on the demo and the eight shared logs: as recorded, "as
recorded" wins 23-58 pairs and a fault at most 2; no verdict on 97 generated worlds (synthetic, laser-mount, smoke,
self-hits, heldout4, heldout5: a fault wins 15 pairs at most, against as many for the motion as recorded) nor on
either laser of 23 two-laser drives (front looking ahead, rear looking back). Turns reversed: "reversed" wins 34-59
on all nine. Laser declared looking back: "half" wins 22-60 on all nine. Odometry twice the distance: "halved" on 5
of the nine (30-53 pairs); half the distance: "doubled" on 4 (33-54); the others tie (no verdict). 20-40 ms a log.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from mcl.estimate import compose, inverse, wrap_angle
from mcl.laser_odometry import Key, far_points, icp

__all__ = ["OdometryCheck", "advice", "check_each_laser", "check_odometry", "findings", "misfits", "run_mount",
           "summary_of", "turn_advice"]

TRUNCATE = 0.5  # m: a point farther than this from the other scan's counts as this far
MARGIN = 0.7  # an alternative wins a pair when its score is under this times the recorded motion's
MIN_WINS = 15  # pairs an alternative must win to be reported ...
MIN_POINTS = 20  # points a scan needs to take part
MIN_RANGE = 0.5  # m: nearer points are left out (the robot's own frame)
MIN_MOVE = 0.1  # m the laser must move between two scans for the distance readings to be weighed ...
MIN_ALONG = 0.2  # ... and how much the first scan's surfaces must face that way (``_along``)

# (name, what it means for the user): the alternatives to the motion as recorded
ALTERNATIVES = {
    "reversed": "with the odometry's turns reversed",
    "half": "with the laser turned half a turn from its mounting",
    "left": "with the laser turned a quarter turn to the left of its mounting",
    "right": "with the laser turned a quarter turn to the right of its mounting",
    "long": "with the odometry's distances halved",
    "short": "with the odometry's distances doubled",
}
_SCALE = {"long": 0.5, "short": 2.0}  # the robot drove this times the odometry's distance
YAW = {"half": math.pi, "left": math.pi / 2, "right": -math.pi / 2}

# The laser's yaw on the robot, measured (``OdometryCheck.yaw``): each pair's laser motion L by ICP with next to no
# prior (the prior pulls the match towards the odometry's guess: with ``laser_odometry.PRIOR`` 10 degrees read 8)
# against the robot's d from the odometry. With the laser at (m, psi) on the robot, L = M^-1 d M, so
# R(psi) t_L = t_d + (R(theta_d) - I) m: the angle from t_L to the right side is the laser's yaw.
YAW_WEIGHT = 1e-3  # the ICP prior's weight (pairs): next to none, only to keep a featureless scene's match solvable
YAW_MIN_MOVE = 0.15  # m: a pair measures the yaw when the laser and the robot's lever-corrected point move this far
YAW_MIN_PAIRS = 20  # pairs that measured it, for a yaw to be reported ...
YAW_FIT = math.radians(2.0)  # ... and fitted: at least this far from the mounting ...
YAW_FIT_Z = 4.0  # ... and this many standard errors


@dataclass
class OdometryCheck:
    """How many pairs of scans each hypothesis fitted best (``wins``: "recorded", the ``ALTERNATIVES``, "tie") and
    the alternative the scans point to, if any (``verdict``)."""

    pairs: int
    wins: dict = field(default_factory=dict)
    verdict: str | None = None
    laser: str = ""  # the laser whose scans were paired (its kind: a bag's topic)
    mount: tuple = (0.0, 0.0, 0.0)  # its pose on the robot as the check took it
    # the laser's yaw from its mounting the pairs measure (rad, counter-clockwise; the median), its standard error
    # (1.4826 MAD / sqrt(n)) and the pairs that measured it; None under YAW_MIN_PAIRS
    yaw: float | None = None
    yaw_se: float = math.inf
    yaw_pairs: int = 0
    # (the robot's motion d from the odometry, the laser's L from the scans by ICP) of each pair matched: what
    # ``mcl calibrate mount`` fits the whole mounting to
    motions: list = field(default_factory=list, repr=False)

    @property
    def turned(self) -> float | None:
        """The yaw (rad) the laser's scans say it is turned from its mounting by, when they say so clearly: no
        verdict, ``YAW_FIT`` or more, and ``YAW_FIT_Z`` standard errors (else None). Measured (2026-12-01): the
        nine shared logs as recorded 1.4 degrees at most, 55 generated worlds 1.3; turned 2-10 degrees, 12 worlds of
        six kinds within 1 degree of the true error (0.9 at 10)."""
        if self.verdict is not None or self.yaw is None:
            return None
        return self.yaw if abs(self.yaw) >= YAW_FIT and abs(self.yaw) >= YAW_FIT_Z * self.yaw_se else None

    def summary(self) -> dict:
        out = {"laser": self.laser, "pairs": self.pairs, "wins": dict(self.wins), "verdict": self.verdict}
        if self.yaw is not None:
            out.update(yaw_deg=round(math.degrees(self.yaw), 2), yaw_se_deg=round(math.degrees(self.yaw_se), 2),
                       yaw_pairs=self.yaw_pairs)
        return out

    def describe_turn(self) -> str:
        """e.g. 'the scans fit the odometry best with the laser turned 5.8 degrees to the left of its mounting
        (counter-clockwise; +- 0.5 degrees over 58 pairs of scans)'."""
        deg = math.degrees(self.yaw)
        return (f"the scans fit the odometry best with the laser turned {abs(deg):.1f} degrees to the "
                f"{'left' if deg > 0 else 'right'} of its mounting ({'counter-' if deg > 0 else ''}clockwise; +- "
                f"{math.degrees(self.yaw_se):.1f} degrees over {self.yaw_pairs} pairs of scans)")

    def describe(self) -> str:
        """e.g. 'the scans fit the odometry's motion best with the odometry's turns reversed in 57 of 60 pairs of
        scans (as recorded in 1)'."""
        return (f"the scans fit the odometry's motion best {ALTERNATIVES[self.verdict]} in "
                f"{self.wins.get(self.verdict, 0)} of {self.pairs} pairs of scans (as recorded in "
                f"{self.wins.get('recorded', 0)})")


def _motions(d: np.ndarray, mount: np.ndarray) -> dict:
    """The laser's motion between two scans under each hypothesis, from the robot's ``d`` (odometry, robot frame)."""
    out = {"recorded": compose(compose(inverse(mount), d), mount),
           "reversed": compose(compose(inverse(mount), np.array([d[0], -d[1], -d[2]])), mount)}
    for name, yaw in YAW.items():
        m = compose(mount, np.array([0.0, 0.0, yaw]))
        out[name] = compose(compose(inverse(m), d), m)
    for name, k in _SCALE.items():
        out[name] = compose(compose(inverse(mount), np.array([k * d[0], k * d[1], d[2]])), mount)
    return out


def _laser_motion(key: Key, pts: np.ndarray, d: np.ndarray, mount: np.ndarray) -> np.ndarray | None:
    """The laser's motion (3,) between two scans, the second (``pts``) matched to the first (``key``) by ICP from
    the odometry's motion ``d`` with next to no prior (``YAW_WEIGHT``); None when the match fails."""
    pose, paired, _ = icp(key, pts, compose(compose(inverse(mount), d), mount), weight=YAW_WEIGHT)
    return pose if paired else None


def _yaw_of(d: np.ndarray, laser: np.ndarray, mount: np.ndarray) -> float | None:
    """The laser's yaw from its ``mount`` (rad) one pair measures (see ``YAW_WEIGHT``): the laser's motion
    ``laser`` against the robot's ``d``; None when the laser or the lever-corrected robot moves under
    ``YAW_MIN_MOVE`` (a turn on the spot says nothing of the yaw)."""
    c, s = math.cos(d[2]), math.sin(d[2])
    vx = d[0] + c * mount[0] - s * mount[1] - mount[0]
    vy = d[1] + s * mount[0] + c * mount[1] - mount[1]
    if math.hypot(laser[0], laser[1]) < YAW_MIN_MOVE or math.hypot(vx, vy) < YAW_MIN_MOVE:
        return None
    psi = math.atan2(laser[0] * vy - laser[1] * vx, laser[0] * vx + laser[1] * vy)
    return float(wrap_angle(psi - mount[2]))


def _along(key: Key, m: np.ndarray) -> float:
    """How much the surfaces of a scan (``key``: ``mcl.laser_odometry``'s key scan, its points' normals from their
    neighbours) face the direction of the laser's translation ``m``: the mean of (n . u)^2 over the normals n, u the
    unit translation; 0 for a translation under ``MIN_MOVE`` m. Along a corridor's walls it is near 0: there the
    scans cannot tell a distance from twice it."""
    t = math.hypot(m[0], m[1])
    if t < MIN_MOVE:
        return 0.0
    n = key.normals
    dot = (n[0] * m[0] + n[1] * m[1]) / t
    dot = dot[np.isfinite(dot)]
    return float(np.mean(dot * dot)) if dot.size else 0.0


def _view(scan, pts: np.ndarray) -> tuple[float, float, float]:
    """(first angle, last angle, reach) of what ``scan`` saw: its beams' angular span (rad, the laser frame) and the
    range of its farthest point among ``pts`` (m)."""
    a = scan.angles
    return float(np.min(a)), float(np.max(a)), float(np.sqrt(np.max(pts[0] * pts[0] + pts[1] * pts[1])))


def _score(tree: cKDTree, pts: np.ndarray, m: np.ndarray, view=None) -> float:
    """The mean squared distance (truncated at ``TRUNCATE``) of ``pts`` moved by ``m`` to the first scan's points
    (``tree``), over those the first scan could have seen (``view``: ``_view``'s span and reach; a point that falls
    outside it has nothing to pair with whatever the motion: a laser looking back, moving away from what it sees,
    loses the near ends of a corridor's walls from its view, and a laser looking ahead the far ends). When fewer than
    half the points fall inside, the motion scores ``TRUNCATE`` squared: the scans do not overlap under it."""
    c, s = math.cos(m[2]), math.sin(m[2])
    moved = np.vstack((c * pts[0] - s * pts[1] + m[0], s * pts[0] + c * pts[1] + m[1]))
    if view is not None:
        lo, hi, reach = view
        ang = np.mod(np.arctan2(moved[1], moved[0]) - lo, 2.0 * math.pi)  # from the first beam, 0..2 pi
        inside = (moved[0] * moved[0] + moved[1] * moved[1] <= reach * reach) & (ang <= hi - lo + 1e-9)
        if 2 * int(inside.sum()) < inside.size:
            return TRUNCATE * TRUNCATE
        moved = moved[:, inside]
    d, _ = tree.query(moved.T, distance_upper_bound=TRUNCATE)
    return float(np.mean(np.minimum(d, TRUNCATE) ** 2))


def score_motions(first, key: Key, pts: np.ndarray, motions) -> list[float]:
    """``_score`` of the points ``pts`` of a second scan moved by each of the laser's ``motions`` against the scan
    ``first`` (its ``key``), over what ``first`` could have seen: how far apart the two scans lie under each."""
    view = _view(first, key.pts)
    return [_score(key.tree, pts, m, view) for m in motions]


def run_mount(scan, laser_pose=None) -> np.ndarray:
    """(3,) the laser's pose on the robot as a run takes it: ``sensor.laser_pose`` when given, else ``scan``'s own
    mounting (a log's, a bag's /tf_static), else the robot's centre."""
    mount = laser_pose if laser_pose is not None else getattr(scan, "laser_offset", None)
    return np.zeros(3) if mount is None else np.asarray(mount, dtype=np.float64)


def advice(check: OdometryCheck, mount, laser_pose_given: bool, upside_down: bool, fused=(),
           left_out: bool = False) -> str:
    """What a ``check`` with a verdict means and what to do, after its ``describe()``: the laser at ``mount``
    (``sensor.laser_pose`` when ``laser_pose_given``, else the log's mounting), ``sensor.upside_down`` as set.
    ``fused``: every laser of a run that fuses several, when this one alone is at fault (``sensor.laser_pose`` and
    ``sensor.upside_down`` would apply to them all: the advice reads it alone, or fixes its transform);
    ``left_out``: the run leaves that laser out (``misfits``), which it says first."""
    bag = check.laser.startswith("/")
    alone = (f"--set {'topics.scan' if bag else 'laser'}={check.laser} " if len(fused) > 1 else "")
    source = _source(check.laser)
    head = "left out of the run (sensor.misfit_laser: keep weighs it); " if left_out else ""
    if check.verdict == "reversed":
        if alone:
            lost = "" if left_out else ", and its scans pull the cloud the wrong way at every turn"
            fix = "fix its transform in the bag's /tf, or read it alone" if bag else "read it alone"
            return (f"{head}{check.laser} alone turns the other way from the odometry: mounted upside down without "
                    f"its {'transform' if bag else 'lines'} saying so (a roll of half a turn){lost}; {fix}: "
                    f"{alone}--set sensor.upside_down={'false' if upside_down else 'true'}")
        return ("the odometry turns the other way from the scans (a left-handed odometry frame, or a laser mounted "
                "upside down without its mounting saying so), and the filter will be lost at every turn; check the "
                f"odometry's sign, or give --set sensor.upside_down={'false' if upside_down else 'true'} if the laser "
                f"is {'upright' if upside_down else 'upside down'}")
    if check.verdict in _SCALE:
        return (f"the odometry reports {'more' if check.verdict == 'long' else 'less'} distance than the scans show (a "
                "wheel's diameter taken for its radius or the other way round, other units), and the filter will be "
                "lost as soon as the robot drives; check the odometry's wheel size or units")
    mount = np.asarray(mount, dtype=np.float64)
    x, y, th = (round(float(v), 4) + 0.0 for v in compose(mount, np.array([0.0, 0.0, YAW[check.verdict]])))
    where = "sensor.laser_pose" if laser_pose_given else source if alone else "the log's mounting"
    pose = f"--set \"sensor.laser_pose=[{x:g}, {y:g}, {round(wrap_angle(th), 4) + 0.0:g}]\""
    if alone:  # sensor.laser_pose would mount every fused laser there
        fix = ((f"sensor.laser_pose mounts every fused laser alike: leave it unset to mount each by "
                f"{'the bag' + chr(39) + 's /tf' if bag else 'its lines'}" if laser_pose_given else f"fix {source}")
               + f", or read it alone, mounted there: {alone}{pose}")
    else:
        fix = f"if so, {pose} mounts it there"
    lost = "" if left_out else ", and the filter will be lost as soon as the robot moves"
    return (f"{head}the laser seems to look another way than {where} says ({math.degrees(mount[2]):.0f} "
            f"degrees){lost}; {fix}")


MOUNTING = ("reversed", "half", "left", "right")  # the verdicts a laser's own mounting can cause


def misfits(checks: list[OdometryCheck]) -> list[str]:
    """The lasers of a fused run (``checks``: ``check_each_laser``'s) whose scans fit the odometry only with their
    mounting turned or mirrored (a verdict in ``MOUNTING``) while another laser's fit it as recorded (``_sound``):
    the odometry is right and their mounting is not. Empty for a single laser, or when no laser fits as recorded
    (then the odometry may be the one at fault)."""
    if len(checks) < 2 or not any(_sound(c) for c in checks):
        return []
    return [c.laser for c in checks if c.verdict in MOUNTING]


MIN_SOUND = 5  # pairs the motion as recorded must win on a laser that vouches for the odometry ...


def _sound(c: OdometryCheck) -> bool:
    """Whether a laser's scans vouch for the odometry as recorded: no verdict, and the motion as recorded won
    ``MIN_SOUND`` pairs or more and twice as many as any fault (an open hall's laser ties most pairs: 9 won, 2 for
    the best fault, 49 ties)."""
    recorded = c.wins.get("recorded", 0)
    rival = max((v for k, v in c.wins.items() if k in ALTERNATIVES), default=0)
    return c.verdict is None and recorded >= MIN_SOUND and recorded >= 2 * rival


def findings(checks: list[OdometryCheck], sensor) -> tuple[set[str], bool, dict[str, str], dict[str, float]]:
    """What a run does with ``checks`` (``check_each_laser``'s) under ``sensor`` (a SensorConfig: laser_pose,
    upside_down, misfit_laser, mount_yaw): (the lasers it leaves out, ``misfits``; whether the lasers disagree, so
    that each one at fault is named, else the first one's fault is the odometry's, said once; {laser: ``describe()``
    and ``advice``} for every laser with a verdict, or turned a few degrees (``OdometryCheck.turned``); {laser: the
    yaw (rad) the run adds to its mounting}, when ``mount_yaw`` is ``fit``). ``mcl run`` and ``mcl bag info`` say the
    same."""
    fused = [c.laser for c in checks] if len({c.verdict for c in checks}) > 1 else []
    left_out = set(misfits(checks)) if sensor.misfit_laser == "leave_out" else set()
    texts = {c.laser: f"{c.describe()}: " + advice(c, c.mount, sensor.laser_pose is not None, sensor.upside_down,
                                                     fused, c.laser in left_out)
             for c in checks if c.verdict is not None}
    turned = {c.laser: c.turned for c in checks if c.turned is not None}
    texts.update({c.laser: f"{c.describe_turn()}: " + turn_advice(c, sensor.laser_pose is not None, len(checks) > 1,
                                                                  sensor.mount_yaw == "fit")
                  for c in checks if c.laser in turned})
    return left_out, bool(fused), texts, (turned if sensor.mount_yaw == "fit" else {})


def _source(laser: str) -> str:
    """Where a laser's mounting comes from: a bag's topic (/rear/scan) its transform, a CARMEN log's stream (RLASER)
    the laser pose its lines give."""
    return "its transform in the bag's /tf" if laser.startswith("/") else "its lines' laser pose"


def turn_advice(check: OdometryCheck, laser_pose_given: bool, fused: bool, fitted: bool) -> str:
    """What a laser turned a few degrees from its mounting (``check.turned``) means and what to do, after its
    ``describe_turn()``; ``fused``: the run fuses several lasers (``sensor.laser_pose`` would mount them all);
    ``fitted``: the run mounts it so (``sensor.mount_yaw: fit``)."""
    x, y, th = (round(float(v), 4) + 0.0 for v in check.mount)
    th = round(float(wrap_angle(th + check.turned)), 4) + 0.0
    pose = f"--set \"sensor.laser_pose=[{x:g}, {y:g}, {th:g}]\""
    source = "sensor.laser_pose" if laser_pose_given else _source(check.laser)
    fix = f"fix {source}" + ("" if fused and not laser_pose_given else f" ({pose})")
    if fitted:
        return f"mounted so for this run (sensor.mount_yaw: keep takes the mounting as given); to mount it so, {fix}"
    return (f"the filter's heading will be off by that much and its track worse; {fix}, or let the run mount it so "
            "(sensor.mount_yaw: fit)")


def summary_of(checks: list[OdometryCheck]) -> dict:
    """For summary.json and ``mcl bag info``: the first laser's ``OdometryCheck.summary()``, with the other
    lasers' in ``other_lasers`` when the run fuses several."""
    return {**checks[0].summary(), **({"other_lasers": [c.summary() for c in checks[1:]]} if len(checks) > 1 else {})}


def check_odometry(scans, mount=None, **kw) -> OdometryCheck:
    """The check of the module docstring on the first laser of ``scans`` (records with ranges, angles, max_range,
    odom, kind, in time order: the laser of the first scan with odometry), the laser at ``mount`` (3,) on the robot
    (None: at its centre); ``kw`` as ``check_each_laser``'s."""
    m = np.zeros(3) if mount is None else np.asarray(mount, dtype=np.float64)
    each = check_each_laser(scans, lambda _s: m, first_only=True, **kw)
    return next(iter(each.values()), OdometryCheck(0))


def check_each_laser(scans, mount_of, *, first_only: bool = False, step: float = 0.2, max_move: float = 1.0,
                     max_turn: float = 1.0, pairs: int = 60, max_read: int = 20_000) -> dict:
    """{laser: OdometryCheck}: the check of the module docstring for every laser of ``scans`` (its ``kind``, a bag's
    topic; fused lasers each have their own mounting, which may be the one at fault), in one pass, in the order the
    lasers first appear (``first_only``: the first alone). ``mount_of(scan)`` gives the laser's (3,) pose on the
    robot as the run takes it, from its first scan (``run_mount``). A laser's pairs are its own consecutive scans."""
    state: dict = {}  # kind -> [check, mount, anchor]
    done = 0
    for s in itertools.islice(scans, max_read):
        kind = getattr(s, "kind", None)
        if s.odom is None:
            continue
        if kind not in state:
            if first_only and state:
                continue
            mount = np.asarray(mount_of(s), dtype=np.float64)
            state[kind] = [OdometryCheck(0, laser=kind or "", mount=tuple(float(v) for v in mount)), mount, s]
            continue
        out, mount, anchor = state[kind]
        if out.pairs >= pairs:
            continue
        d = compose(inverse(np.asarray(anchor.odom, dtype=np.float64)), np.asarray(s.odom, dtype=np.float64))
        move, turn = math.hypot(d[0], d[1]), abs(d[2])
        if move < step and turn < step:
            continue
        if move <= max_move and turn <= max_turn:
            a, b = far_points(anchor, MIN_RANGE), far_points(s, MIN_RANGE)
            if a.shape[1] >= MIN_POINTS and b.shape[1] >= MIN_POINTS:
                key = Key(a)
                motions = _motions(d, mount)
                if _along(key, motions["recorded"]) < MIN_ALONG:  # the scene does not pin the distance: no scale
                    del motions["long"], motions["short"]
                view = _view(anchor, a)
                score = {k: _score(key.tree, b, m, view) for k, m in motions.items()}
                best = min(score, key=score.get)
                if best != "recorded" and score[best] > MARGIN * score["recorded"]:
                    best = "tie"
                out.wins[best] = out.wins.get(best, 0) + 1
                out.pairs += 1
                laser = _laser_motion(key, b, d, mount)
                if laser is not None:
                    out.motions.append((d, laser))
                if out.pairs >= pairs:
                    done += 1
                    if done == len(state):
                        break
        state[kind][2] = s
    for out, mount, _ in state.values():
        yaws = [y for d, laser in out.motions if (y := _yaw_of(d, laser, mount)) is not None]
        if len(yaws) >= YAW_MIN_PAIRS:
            y = np.asarray(yaws)
            out.yaw = float(np.median(y))
            out.yaw_se = 1.4826 * float(np.median(np.abs(y - out.yaw))) / math.sqrt(y.size)
            out.yaw_pairs = int(y.size)
        recorded = out.wins.get("recorded", 0)
        lead = max(ALTERNATIVES, key=lambda k: out.wins.get(k, 0))
        if out.wins.get(lead, 0) >= MIN_WINS and out.wins[lead] >= 2 * recorded:
            out.verdict = lead
    return {kind: v[0] for kind, v in state.items()}


# The odometry's units, from its rows alone (no scans): a ground robot's median speed between odometry poses is under
# 6 m/s (the eight shared logs and the demo: 0.18-5.2 m/s), and under 1 % of its turning steps turn over 1 rad
# (0-0.6 %, scans up to 2 s apart); in centimetres or millimetres its median speed is 36-470 m/s, and with its
# headings in degrees 60-64 % of its turning steps wrap to over 1 rad (2026-12-07, the demo and aces degraded so).
UNITS_SPEED = 25.0  # m/s (90 km/h: a car's odometry is metres still): a median speed above this is another unit
UNITS_TURN = 1.0  # rad ...
UNITS_TURN_SHARE = 0.2  # ... a share of turning steps over UNITS_TURN above this is headings in degrees


def odometry_units(rows: np.ndarray) -> list[str]:
    """What the odometry's rows (t, x, y, theta, ...; time-sorted) say of its units: [] when metres and radians fit,
    else one phrase each for a length unit (centimetres or millimetres: the median speed) and for headings in
    degrees. A log in either was lost by hundreds of metres, or blamed on a slipping wheel, an omnidirectional
    base or the reference."""
    rows = np.asarray(rows, dtype=np.float64)
    if rows.shape[0] < 10:
        return []
    dt = np.diff(rows[:, 0])
    step = np.hypot(np.diff(rows[:, 1]), np.diff(rows[:, 2]))
    turn = np.abs(np.angle(np.exp(1j * np.diff(rows[:, 3]))))
    out = []
    moving = (dt > 1e-3) & (step > 1e-4)
    if moving.sum() >= 10:
        speed = float(np.median(step[moving] / dt[moving]))
        if speed > UNITS_SPEED:
            out.append(f"the odometry moves at a median {speed:.0f} m/s ({3.6 * speed:.0f} km/h) between its poses: "
                       f"its positions in other units than metres? (centimetres: {speed / 100:.2g} m/s, "
                       f"millimetres: {speed / 1000:.2g})")
    turning = turn > 1e-3
    if turning.sum() >= 10 and (turn[turning] > UNITS_TURN).mean() > UNITS_TURN_SHARE:
        out.append(f"{(turn[turning] > UNITS_TURN).mean():.0%} of the odometry's turning steps turn over "
                   f"{UNITS_TURN:g} rad: its headings in degrees?")
    return out
