"""``mcl calibrate mount``: the laser's pose on the robot (x, y, yaw) from a log alone, by planar hand-eye calibration.

No reference trajectory is needed: the odometry check's pairs of scans (``mcl.odomcheck.check_each_laser``: 60
pairs 0.2-1 m or rad apart) give, for each pair, the robot's motion d from the odometry and the laser's motion L
from the scans (ICP, next to no prior). With the laser at (m, psi) on the robot, L = M^-1 d M, so

    R(psi) t_L = t_d + (R(theta_d) - I) m ,

two equations a pair, linear in (cos psi, sin psi, m_x, m_y): solved by least squares, pairs whose residual is over
three robust sigmas dropped and the fit made again (three rounds). psi = atan2(sin, cos); the norm of (cos, sin)
is the scans' distance over the odometry's (1 for odometry of the right scale). The yaw needs the robot to drive, the
lever m needs it to turn: the standard errors (the larger of the residuals' RMS through the normal equations and the
sandwich over the pairs, ``_standard_errors``) say how well each is pinned. They cover the matches' noise, not their
bias: along a corridor the matches can read x or y 0.2-0.45 m off, 5-12 standard errors (docs/measurements.md,
"Hundredth session").

Measured (2026-12-01, 60 pairs each; the standard errors of 2026-12-07): the demo (laser at the centre) reads
(-0.002, 0.016) m and 0.4 degrees, +- 0.011 and 0.016 m and 0.46 degrees; a generated office drive whose laser is
0.2 m ahead, told it is at the centre, (0.169, -0.047) m +- 0.010 (with the robust sigma's standard errors, as the
two halls below). The shared CARMEN logs, whose lines put the laser at the robot's centre, read -0.05..0.10 m ahead
(intel_lab 0.095 +- 0.001) and within 1.7 degrees: where their odometry's reference point lies is not known, so a
run does not move the laser by this; it fits the yaw alone (``sensor.mount_yaw``). In open halls and along
corridors the matches are unsure and x and y can be far off: a generated hall whose laser sits at the centre read
(-0.25, 0.29) m +- 0.064, from 20 of 60 pairs (said: "only 20 of 60 pairs agree"); another (-0.21, 0.06) +- 0.035
from 42.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from mcl.errors import DataError, MclError

MIN_PAIRS = 20  # pairs matched, for a fit
DROP = 3.0  # robust sigmas: a pair with a larger residual is left out of the next round
DOUBT = 2.0 / 3.0  # fewer pairs than this share of those matched agree: the fit is said to be unsure


def hand_eye(motions, rounds: int = 3) -> dict:
    """The laser's mounting fitted to ``motions`` ((d, L) pairs, ``OdometryCheck.motions``): {"laser_pose": [x,
    y, yaw], "se": [x, y, yaw], "pairs": used, "matched": given, "scale": the norm of (cos, sin)}. DataError under
    ``MIN_PAIRS``."""
    if len(motions) < MIN_PAIRS:
        raise DataError(f"{len(motions)} pairs of scans matched, {MIN_PAIRS} needed: the robot must drive and turn "
                        "where the laser sees walls")
    rows, rhs = [], []
    for d, laser in motions:
        c, s = math.cos(d[2]), math.sin(d[2])
        rows += [[laser[0], -laser[1], 1.0 - c, s], [laser[1], laser[0], -s, 1.0 - c]]
        rhs += [d[0], d[1]]
    a, b = np.array(rows), np.array(rhs)
    keep = np.ones(len(motions), dtype=bool)
    for _ in range(rounds):
        rows_kept = np.repeat(keep, 2)
        u, *_ = np.linalg.lstsq(a[rows_kept], b[rows_kept], rcond=None)
        r = (a @ u - b).reshape(-1, 2)
        sigma = max(1.4826 * float(np.median(np.abs(r[keep]))), 1e-4)
        keep = (np.abs(r) <= DROP * sigma).all(axis=1)
        if keep.sum() < MIN_PAIRS // 2:
            keep[:] = True
    rows_kept = np.repeat(keep, 2)  # the fit and its standard errors over the pairs the last round kept
    a_k, b_k = a[rows_kept], b[rows_kept]
    u, *_ = np.linalg.lstsq(a_k, b_k, rcond=None)
    se = _standard_errors(a_k, a_k @ u - b_k)
    scale = math.hypot(u[0], u[1])
    yaw_se = math.hypot(u[0] * se[1], u[1] * se[0]) / max(scale * scale, 1e-12)  # of atan2(s, c)
    return {"laser_pose": [float(u[2]), float(u[3]), math.atan2(u[1], u[0])],
            "se": [float(se[2]), float(se[3]), yaw_se], "pairs": int(keep.sum()), "matched": len(motions),
            "scale": scale}


def _standard_errors(a: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The least-squares fit's standard errors (4,) from its rows ``a`` (2 per pair) and residuals ``r``: the larger of
    the plain one (the residuals' RMS over the degrees of freedom) and the sandwich over the pairs (each pair's
    a_i^T r_i; it holds where the pairs' errors differ in size, a far turn's match against a near one's). The
    residuals' robust sigma, which the rounds drop pairs by, read 1.2-1.6 times too small on generated drives (mean
    squared z-score of x and y 1.36 and 2.49 over 12 worlds; this: 1.00 and 1.22). Dropping pairs by their residual
    keeps the ones that agree with the fit, which no formula of the kept residuals sees: on drawn pairs whose
    matches err 10 times more on far turns, 2.0-2.7 with the rounds, 1.0-1.1 without (3-5 with the robust sigma)."""
    bread = np.linalg.pinv(a.T @ a)
    k = r.size // 2
    plain = max(float(r @ r) / max(r.size - 4, 1), 1e-8) * np.diag(bread)
    g = np.einsum("pji,pj->pi", a.reshape(-1, 2, 4), r.reshape(-1, 2))  # per pair a_i^T r_i
    sandwich = np.diag(bread @ (g.T @ g) @ bread) * k / max(k - 4, 1)
    return np.sqrt(np.maximum(np.maximum(plain, sandwich), 0.0))


def calibrate(scans, laser_pose=None) -> dict:
    """{laser: (OdometryCheck, hand_eye result or the DataError's text)} for each laser of ``scans`` (fused lasers
    each on their own), the check's pairs taken with each laser where a run puts it (``laser_pose``: the config's
    ``sensor.laser_pose``)."""
    from mcl.estimate import compose
    from mcl.odomcheck import YAW, check_each_laser, run_mount

    out = {}
    for laser, check in check_each_laser(scans, lambda s: run_mount(s, laser_pose)).items():
        measured = check
        if check.verdict in YAW:
            # a laser turned a quarter or half turn from its mounting (one mounted backwards, its log silent on it):
            # what this command is for. The pairs are matched again with the laser turned so (matched as given,
            # their motions are wrong: the fit read a scale of 0.02 and a yaw of -20 +- 102 degrees)
            turn = np.array([0.0, 0.0, YAW[check.verdict]])
            again = check_each_laser(scans, lambda s: compose(run_mount(s, laser_pose), turn)).get(laser)
            if again is not None and again.verdict is None:
                measured = again
        if measured.verdict is not None:
            out[laser] = (check, f"{check.describe()}: the scans fit another motion than the odometry's; mend that "
                                 "first (mcl run says how)")
            continue
        try:
            out[laser] = (check, hand_eye(measured.motions))
        except DataError as e:
            out[laser] = (check, str(e))
    return out


def _rounded(p) -> list[float]:
    return [round(float(v), 4) + 0.0 for v in p]


def format_yaml(results: dict, source: str) -> str:
    """The fit as a config block (one laser: ``sensor.laser_pose`` ready to paste; several fused: a comment per laser,
    whose transform is where its mounting is given)."""
    lines = [f"# mcl calibrate mount: {source}; the laser's pose on the robot from the odometry and the scans "
             "(hand-eye, no reference)"]
    fits = {k: v for k, v in results.items() if isinstance(v[1], dict)}
    for laser, (check, fit) in results.items():
        given = _rounded(check.mount)
        if not isinstance(fit, dict):
            lines.append(f"# {laser}: no fit: {fit}")
            continue
        x, y, th = fit["laser_pose"]
        sx, sy, sth = fit["se"]
        lines.append(f"# {laser}: given {given}; fitted x {x:.3f} +- {sx:.3f} m, y {y:.3f} +- {sy:.3f} m, yaw "
                     f"{math.degrees(th):.2f} +- {math.degrees(sth):.2f} degrees ({fit['pairs']} pairs of scans; "
                     f"the scans' distances {fit['scale']:.3f} times the odometry's)")
        if fit["pairs"] < DOUBT * fit["matched"]:
            lines.append(f"# {laser}: only {fit['pairs']} of {fit['matched']} pairs agree: the matches are unsure "
                         "(an open hall, a corridor); distrust x and y")
    if len(results) == 1 and fits:
        (check, fit), = fits.values()
        lines += ["sensor:", f"  laser_pose: {_rounded(fit['laser_pose'])}"]
    elif fits:
        lines.append("# several lasers: sensor.laser_pose would mount them all alike; give each its own mounting in "
                     "the bag's /tf (or the log's lines)")
    return "\n".join(lines)


def add_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--log", help="CARMEN log with the odometry (ODOM lines or the laser lines' own poses)")
    src.add_argument("--bag", help="ROS bag (.bag, .db3, .mcap or a rosbag2 folder) with wheel odometry")
    p.add_argument("--config", help="config whose laser:, topics:, frames: and sensor: settings apply (default: the "
                   "defaults)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="config override, e.g. topics.scan=/front/scan or sensor.laser_pose=[0.2,0,0]")
    p.add_argument("--json", action="store_true", help="print the fit as JSON instead of YAML")


def run_from_args(args) -> int:
    from mcl.config import load_config

    cfg = load_config(args.config, list(args.set))
    if args.log:
        from mcl.datasets.carmen import read_carmen
        from mcl.datasets.rosbag import is_bag

        if is_bag(args.log):  # ("log.bag:2: not UTF-8 text" before)
            raise DataError(f"{args.log}: a ROS bag: give it with --bag")
        source = args.log
        scans = read_carmen(args.log).laser_stream(cfg.laser)
    else:
        from mcl.datasets.rosbag import open_bag

        source = args.bag
        bag = open_bag(args.bag, cfg.topics, cfg.frames, laser_pose=cfg.sensor.laser_pose)
        if not bag.wheel_odometry:
            raise MclError(f"{args.bag}: no wheel odometry (the run would take the scans' own motion): nothing to "
                           "calibrate the mounting against")
        scans = bag.scans
    results = calibrate(scans, cfg.sensor.laser_pose)
    if args.json:
        print(json.dumps({laser: {"given": _rounded(c.mount), **(fit if isinstance(fit, dict) else {"error": fit})}
                          for laser, (c, fit) in results.items()}, indent=2))
    else:
        print(format_yaml(results, source))
    if not any(isinstance(fit, dict) for _, fit in results.values()):
        print(f"mcl: error: {source}: no laser's mounting could be fitted", file=sys.stderr)
        return 1
    return 0
