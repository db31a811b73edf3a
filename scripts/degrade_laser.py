#!/usr/bin/env python
"""The real logs of a suite with another laser (a narrower field of view, range noise, dropouts) or other wheels.

A held-out check of the default config on real buildings with a laser or odometry it was not chosen on. Every
``FLASER`` line of each dataset's CARMEN log is rewritten:

* readings outside the central ``--fov`` degrees (the line's beams spread evenly over 180 degrees, as FLASER
  lays them) become 0, which no reader takes as a range (``sensor.range_min`` 0: a reading must be > 0);
* the rest get N(0, ``--sigma``) added (clipped at 0.01 m), except the log's no-return readings (``--no-return``
  m and more: 50.00 and 51.0-51.25 m in ``../shared/data``) and readings of 0 or less, which stay as they are;
* ``--drop`` of them become 0 too;
* with ``--body A0:A1@R`` (repeatable) the readings of the beams between A0 and A1 degrees (0 ahead, positive to
  the left) read R m (with N(0, 0.01 m) noise) before ``--sigma``'s, as where the robot's own frame, a wheel or a mast stands in the laser's
  view: returns at a fixed short range on every scan, wherever the robot is.

With ``--range-scale K`` and ``--range-bias B`` every return (not a no-return reading, not a reading of 0) reads
``K r + B`` m before the rest (clipped at 0.01 m): a laser calibrated against another range than the map was drawn
with (a cheap lidar's few per cent, a floor plan's map). The defaults, 1 and 0, leave the ranges as they are.

With ``--odom-scale S`` and ``--turn-scale R`` the odometry misreports the motion as wheels of the wrong size or a
skid-steer base do: every step between consecutive odometry poses (in the robot frame of the first) has its
translation multiplied by S and its rotation by R, and the poses are integrated again from the first. The ODOM
lines and the FLASER lines' robot poses are each redone so; a FLASER line's laser pose keeps its mounting on the
robot. The defaults, 1 and 1, leave the odometry as it is, byte for byte.

With ``--latency T`` each scan is paired with the odometry T seconds after it was taken, as a driver that stamps
its scans T late does: a FLASER line's robot pose becomes the odometry interpolated at its time + T (the ODOM
lines when the log has them, else the FLASER lines' own poses; ``mcl.datasets.carmen.interpolate_odometry``), its
laser pose kept on the robot. The rescaled odometry, when asked for too, is the one interpolated. (The ODOM lines
stay as they were: ``sensor.time_offset``, which pairs each scan with them, cannot undo this.)

With ``--stamp-late T`` each scan is stamped T late and paired with the odometry of its stamp, as a driver that stamps
late makes a log: a FLASER line's times become its time + T and its robot pose the odometry there (the ODOM lines
stay as they were). ``sensor.time_offset`` -T undoes it.

With ``--doubled-walls N`` each map is redrawn with its walls twice in N squares of 10 m centred on the reference
path at k / (N + 1) of it, the copy 0.1-0.3 m off (``mcl simulate --doubled-walls``'s ``double_walls``): a SLAM map
whose loop did not quite close, under the log's own scans. ``--fov 180 --sigma 0 --drop 0`` leaves the logs as
they are, byte for byte, so the map is the only change:

    .venv/bin/python scripts/degrade_laser.py /tmp/doubled --fov 180 --sigma 0 --drop 0 --doubled-walls 6

With ``--map-rotation DEG`` each map is redrawn turned by DEG degrees about its frame's zero (``mcl simulate
--map-rotation``'s ``rotate_map``: a SLAM map whose frame started at the robot's heading, its walls across the
cells as staircases), and the reference and the start pose are turned with it (``truth_turned.tum``). The log is
the same: the odometry has its own frame. After ``--doubled-walls`` when both are given.

With ``--scan-gaps N`` the laser falls silent N times for ``--scan-gap-s`` seconds (default 5), evenly spread over
the log's scans (``mcl simulate --scan-gaps``' windows): the FLASER lines inside are dropped, the ODOM lines kept,
and the reference loses its poses there too (``truth_gapped.tum``: a run is scored where it has scans). As a driver
that restarts or a USB reset leaves a log.

With ``--odom-stalls N`` the odometry stalls N times for ``--odom-stall-s`` seconds (default 3), evenly spread over
the log's scans, as an encoder driver that hangs while the robot drives on: the ODOM lines and the FLASER lines'
robot poses hold the pose they had at the stall's start, then go on from it with the steps they measured (the motion
in the stall lost; a FLASER line's laser pose keeps its mounting on the robot). The scans and the reference stay.
``--odom-resets N`` restarts the odometry from 0 0 0 N times (a base driver that restarts), each after holding its
pose for ``--odom-reset-s`` seconds (default 0).

The maps (but for ``--doubled-walls`` and ``--map-rotation``) and the references (but for ``--map-rotation``) are those of the originals (linked, not copied). Writes
``OUT/<name>/log.clf`` with links to the rest, and ``OUT/suite.yaml``: the suite with its root at ``OUT``.
Deterministic for a given ``--seed``. Then:

    .venv/bin/python scripts/degrade_laser.py /tmp/narrow --fov 120 --sigma 0.03 --drop 0.1
    .venv/bin/mcl eval --suite /tmp/narrow/suite.yaml --seeds 3 --jobs 2
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mcl.datasets.carmen import interpolate_odometry  # noqa: E402
from mcl.maps import OccupancyGrid, load_map, save_map  # noqa: E402
from mcl.simulate import double_walls, map_frame_poses, rotate_map, spread_windows  # noqa: E402
from mcl.trajectory import read_tum, write_tum  # noqa: E402
from mcl.runner import compose, inverse  # noqa: E402
from mcl.errors import MclError  # noqa: E402
from mcl.suite import load_suite  # noqa: E402


BODY_SIGMA = 0.01  # m: the range noise of a body reading (a laser's at short range)


def parse_body(text: str) -> tuple[float, float, float]:
    """``A0:A1@R`` -> (A0, A1, R): a sector of the laser's view (degrees) blocked at R m by the robot itself."""
    m = re.fullmatch(r"\s*(-?[\d.]+)\s*:\s*(-?[\d.]+)\s*@\s*([\d.]+)\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"--body {text!r}: expected A0:A1@R, degrees and metres (e.g. 80:90@0.2)")
    a0, a1, r = (float(v) for v in m.groups())
    return min(a0, a1), max(a0, a1), r


def degrade_line(line: str, rng: np.random.Generator, fov: float, sigma: float, drop: float,
                 no_return: float, body=(), range_scale: float = 1.0, range_bias: float = 0.0) -> str:
    """One FLASER line with the laser changed (see the module docstring); any other line as it is."""
    if not line.startswith("FLASER ") or (fov >= 180.0 and sigma == 0.0 and drop == 0.0 and not body
                                          and range_scale == 1.0 and range_bias == 0.0):
        return line
    p = line.split()
    n = int(p[1])
    r = np.array([float(x) for x in p[2:2 + n]])
    angle = np.linspace(-90.0, 90.0, n)
    for a0, a1, reach in body:
        hit = (angle >= a0) & (angle <= a1)
        r[hit] = np.maximum(reach + rng.normal(0.0, BODY_SIGMA, int(hit.sum())), 0.01)
    if range_scale != 1.0 or range_bias != 0.0:  # a miscalibrated laser: every return, not a no-return reading
        ret = (r > 0.0) & (r < no_return)
        r[ret] = np.maximum(r[ret] * range_scale + range_bias, 0.01)
    keep = np.abs(angle) <= fov / 2.0
    out = np.where((r >= no_return) | (r <= 0.0), r, np.maximum(r + rng.normal(0.0, sigma, n), 0.01))
    out = np.where(keep & (rng.random(n) >= drop), out, 0.0)
    p[2:2 + n] = [f"{x:.2f}" for x in out]
    return " ".join(p) + "\n"


class Rescaled:
    """One odometry stream integrated again with its steps scaled (translation by ``scale``, rotation by
    ``turn``): ``pose(x, y, theta)`` takes the stream's next original pose and gives the new one."""

    def __init__(self, scale: float, turn: float):
        self.scale, self.turn = scale, turn
        self.last = None  # (original pose, new pose)

    def pose(self, x: float, y: float, th: float) -> tuple[float, float, float]:
        if self.last is None:
            self.last = ((x, y, th), (x, y, th))
            return x, y, th
        old, new = self.last
        step = compose(inverse(np.array(old)), np.array([x, y, th]))  # the step in the robot frame
        new = tuple(float(v) for v in compose(np.array(new), step * [self.scale, self.scale, self.turn]))
        self.last = ((x, y, th), new)
        return new


def _with_robot_pose(p: list, k: int, robot) -> str:
    """A FLASER line (split, ``k`` the index of its laser pose) with its robot pose replaced and its laser pose
    moved along, so the laser keeps its mounting on the robot."""
    mount = compose(inverse(np.array([float(v) for v in p[k + 3:k + 6]])), np.array([float(v) for v in p[k:k + 3]]))
    robot = np.asarray(robot, dtype=np.float64)
    p[k:k + 6] = [f"{v:.6f}" for v in (*compose(robot, mount), *robot)]
    return " ".join(p) + "\n"


def rescale_line(line: str, odom: Rescaled, flaser: Rescaled) -> str:
    """An ODOM line's pose, or a FLASER line's robot pose (and its laser pose, kept on the robot), from the
    rescaled streams; any other line as it is."""
    if odom.scale == 1.0 and odom.turn == 1.0:
        return line
    p = line.split()
    if p and p[0] == "ODOM":
        p[1:4] = [f"{v:.6f}" for v in odom.pose(*map(float, p[1:4]))]
        return " ".join(p) + "\n"
    if p and p[0] == "FLASER":
        k = 2 + int(p[1])
        return _with_robot_pose(p, k, flaser.pose(*map(float, p[k + 3:k + 6])))
    return line


def odometry_stream(lines) -> np.ndarray:
    """(M, 6) rows t, x, y, theta, 0, 0 of a log's odometry: its ODOM lines, else its FLASER lines' robot poses."""
    odom, flaser = [], []
    for line in lines:
        p = line.split()
        if p and p[0] == "ODOM":
            odom.append((float(p[7]), *map(float, p[1:4]), 0.0, 0.0))
        elif p and p[0] == "FLASER":
            k = 2 + int(p[1])
            flaser.append((float(p[k + 6]), *map(float, p[k + 3:k + 6]), 0.0, 0.0))
    return np.array(odom or flaser, dtype=np.float64).reshape(-1, 6)


def delay_line(line: str, stream: np.ndarray, latency: float) -> str:
    """A FLASER line with its robot pose taken from ``stream`` at its time + ``latency`` (its laser pose kept on the
    robot); any other line as it is."""
    if latency == 0.0 or not line.startswith("FLASER ") or stream.shape[0] == 0:
        return line
    p = line.split()
    k = 2 + int(p[1])
    return _with_robot_pose(p, k, interpolate_odometry(stream, float(p[k + 6]) + latency)[:, 0])


def stamped_late(lines: list[str], lag: float) -> str:
    """A CARMEN log whose FLASER lines are stamped ``lag`` s late, as a driver that stamps its scans late makes
    them: each line's times (ipc and logger) and robot pose those of ``lag`` s after the scan was taken (its laser
    kept on the robot); the ODOM lines as they were."""
    stream = odometry_stream(lines)
    out = []
    for line in lines:
        if line.startswith("FLASER "):
            p = delay_line(line, stream, lag).split()
            k = 2 + int(p[1])
            p[k + 6] = f"{float(p[k + 6]) + lag:.6f}"  # ipc_timestamp
            p[k + 8] = f"{float(p[k + 8]) + lag:.6f}"  # logger_timestamp
            line = " ".join(p) + "\n"
        out.append(line)
    return "".join(out)


def _scan_windows(lines: list[str], n: int, seconds: float) -> list:
    """``n`` windows of ``seconds`` evenly spread over the span of the log's FLASER lines (ipc_timestamp,
    ``mcl.simulate.spread_windows``)."""
    times = [float(line.split()[-3]) for line in lines if line.startswith("FLASER ")]
    return spread_windows(n, seconds, times[0], times[-1] - times[0]) if times else []


def with_odometry_stalled(lines: list[str], n: int, seconds: float, restart: bool = False) -> tuple[str, list]:
    """(the CARMEN log ``lines`` with its odometry stalled over ``n`` windows of ``seconds`` evenly spread over the
    scans' span, the windows): inside a window each ODOM line and FLASER robot pose holds the last odometry pose
    before it (an ODOM line's velocities 0), as ``mcl simulate --odom-stalls`` does; after it, every pose p becomes
    held ∘ last^-1 ∘ p, ``last`` the pose the odometry had reached at the window's end (the motion in the window
    lost). ``restart``: after the window the odometry starts again from 0 0 0 instead, every pose p becoming
    first^-1 ∘ p, ``first`` the log's pose at the first line after it (``mcl simulate --odom-resets``; ``seconds`` 0:
    no hold). A FLASER line's laser pose is moved with its robot pose."""
    stalls = _scan_windows(lines, n, seconds)
    reset = False  # a window just ended: the odometry restarts at this line
    fix = np.zeros(3)  # the correction composed onto every odometry pose from here on
    held = last = None  # inside a window: the pose held, and the last pose the log had there
    before = None  # the last pose written before the window
    k = 0  # the next window
    out = []
    for line in lines:
        p = line.split()
        if not p or p[0] not in ("ODOM", "FLASER"):
            out.append(line)
            continue
        t = float(p[-3])
        while k < len(stalls) and t >= stalls[k][1]:  # past a window: go on from the pose it held
            if held is not None:
                fix = compose(held, inverse(last))
            held = last = None
            reset = restart
            k += 1
        i = 1 if p[0] == "ODOM" else 2 + int(p[1]) + 3  # the robot's pose (a FLASER line: after the laser's)
        robot = np.array([float(v) for v in p[i:i + 3]])
        if reset:  # the driver restarted: this pose is 0 0 0
            fix, reset = inverse(robot), False
        new = compose(fix, robot)
        if k < len(stalls) and t >= stalls[k][0] and before is not None:
            if held is None:
                held = before
            last, new = robot, held
            if p[0] == "ODOM":
                p[4] = p[5] = "0.000000"  # tv, rv
        if p[0] == "FLASER":  # the laser keeps its mounting on the robot
            j = 2 + int(p[1])
            mount = compose(inverse(robot), np.array([float(v) for v in p[j:j + 3]]))
            p[j:j + 3] = [f"{v:.6f}" for v in compose(new, mount)]
        p[i:i + 3] = [f"{v:.6f}" for v in new]
        if held is None:
            before = new
        out.append(" ".join(p) + "\n")
    return "".join(out), stalls


def without_scans_in_gaps(lines: list[str], n: int, seconds: float) -> tuple[str, list]:
    """(the CARMEN log ``lines`` without the FLASER lines whose ipc_timestamp falls inside one of ``n`` windows of
    ``seconds`` evenly spread over the scans' span (``mcl.simulate.spread_windows``), the windows)."""
    gaps = _scan_windows(lines, n, seconds)
    return "".join(line for line in lines if not (line.startswith("FLASER ")
                                                  and any(g0 <= float(line.split()[-3]) < g1 for g0, g1 in gaps))), gaps


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="output folder")
    ap.add_argument("--suite", type=Path, default=ROOT / "suites" / "real.yaml", help="suite of CARMEN logs")
    ap.add_argument("--fov", type=float, default=120.0, help="field of view kept, degrees (default 120)")
    ap.add_argument("--sigma", type=float, default=0.03, help="range noise std, m (default 0.03)")
    ap.add_argument("--drop", type=float, default=0.1, help="share of readings dropped (default 0.1)")
    ap.add_argument("--no-return", type=float, default=49.9, help="readings from this on are left alone (m)")
    ap.add_argument("--range-scale", type=float, default=1.0,
                    help="every return read this many times its range (a miscalibrated laser; default 1)")
    ap.add_argument("--range-bias", type=float, default=0.0,
                    help="... and this many m longer (after --range-scale; default 0)")
    ap.add_argument("--odom-scale", type=float, default=1.0, help="odometry translation factor (default 1)")
    ap.add_argument("--turn-scale", type=float, default=1.0, help="odometry rotation factor (default 1)")
    ap.add_argument("--latency", type=float, default=0.0,
                    help="pair each scan with the odometry this many s after it (default 0)")
    ap.add_argument("--stamp-late", type=float, default=0.0,
                    help="stamp each scan this many s late, its robot pose that of its stamp (default 0)")
    ap.add_argument("--body", type=parse_body, action="append", default=[], metavar="A0:A1@R",
                    help="beams between A0 and A1 degrees read R m (the robot's own frame in view); repeatable; "
                         "a negative A0 with '=': --body=-100:-80@0.25")
    ap.add_argument("--doubled-walls", type=int, default=0, metavar="N",
                    help="redraw each map with its walls twice in N squares of 10 m along the reference (default 0)")
    ap.add_argument("--map-rotation", type=float, default=0.0, metavar="DEG",
                    help="redraw each map turned by DEG degrees, the reference and start pose with it (default 0)")
    ap.add_argument("--scan-gaps", type=int, default=0, metavar="N",
                    help="drop the scans of N windows evenly spread over each log (default 0)")
    ap.add_argument("--scan-gap-s", type=float, default=5.0, metavar="S",
                    help="seconds of each --scan-gaps window (default 5)")
    ap.add_argument("--odom-stalls", type=int, default=0, metavar="N",
                    help="stall the odometry in N windows evenly spread over each log (default 0)")
    ap.add_argument("--odom-stall-s", type=float, default=3.0, metavar="S",
                    help="seconds of each --odom-stalls window (default 3)")
    ap.add_argument("--odom-resets", type=int, default=0, metavar="N",
                    help="restart the odometry from 0 0 0 at the end of N windows evenly spread over each log "
                    "(default 0)")
    ap.add_argument("--odom-reset-s", type=float, default=0.0, metavar="S",
                    help="seconds the odometry holds before each --odom-resets restart (default 0)")
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args(argv)
    for option, value, lo, hi, unit in (("--doubled-walls", a.doubled_walls, 0, 20, ""),
                                        ("--map-rotation", a.map_rotation, -180, 180, " degrees"),
                                        ("--scan-gaps", a.scan_gaps, 0, 20, ""),
                                        ("--scan-gap-s", a.scan_gap_s, 0.5, 60, " s"),
                                        ("--odom-stalls", a.odom_stalls, 0, 20, ""),
                                        ("--odom-stall-s", a.odom_stall_s, 0.5, 60, " s"),
                                        ("--odom-resets", a.odom_resets, 0, 20, ""),
                                        ("--odom-reset-s", a.odom_reset_s, 0, 60, " s")):
        if not (math.isfinite(value) and lo <= value <= hi):
            ap.error(f"{option}: expected {lo:g}..{hi:g}{unit}, got {value:g}")
    try:
        load_suite(a.suite)  # a missing or malformed suite: mcl's one error line, naming the file and the entry
    except MclError as e:
        ap.error(str(e))
    suite = yaml.safe_load(a.suite.read_text())
    for i, d in enumerate(suite["datasets"]):
        if not d.get("log"):
            ap.error(f"{a.suite}: datasets[{i}] ({d['name']}): no log: this script degrades the CARMEN logs a suite "
                     "names (a simulate: world or a config: entry is not read here; scripts/hunt.py real resolves "
                     "config: entries)")
    src = (a.suite.parent / str(suite.get("root", "."))).resolve()  # as mcl.suite: no root, the file's folder
    rng = np.random.default_rng(a.seed)
    for d in suite["datasets"]:
        folder = a.out / d["name"]
        folder.mkdir(parents=True, exist_ok=True)
        log = (src / d["log"]).resolve()
        for key in ("map", "truth"):
            if d.get(key):
                f = (src / d[key]).resolve()
                for g in f.parent.iterdir():  # the map's image and YAML, the reference, the metadata
                    if g.name != log.name and not (folder / g.name).exists():
                        os.symlink(g, folder / g.name)
                d[key] = f"{d['name']}/{f.name}"
        if a.doubled_walls:
            grid = load_map(folder / Path(d["map"]).name)
            _, ref = read_tum(folder / Path(d["truth"]).name)
            occupancy, squares = double_walls(grid.occupancy, ref[:3].T, a.doubled_walls, rng, grid.origin,
                                          grid.resolution)
            save_map(OccupancyGrid.from_occupancy(occupancy, grid.resolution, grid.origin),
                     folder / "map_doubled.yaml")
            d["map"] = f"{d['name']}/map_doubled.yaml"
            print(f"{d['name']}: walls doubled in {len(squares)} squares (x, y, dx, dy): {squares}")
        if a.map_rotation:
            angle = math.radians(a.map_rotation)
            grid = load_map(folder / Path(d["map"]).name)
            occupancy, origin = rotate_map(grid.occupancy, grid.resolution, grid.origin, angle)
            save_map(OccupancyGrid.from_occupancy(occupancy, grid.resolution, origin), folder / "map_turned.yaml")
            d["map"] = f"{d['name']}/map_turned.yaml"
            t, ref = read_tum(folder / Path(d["truth"]).name)
            write_tum(folder / "truth_turned.tum", t, map_frame_poses(ref[:3].T, angle, 1.0).T)
            d["truth"] = f"{d['name']}/truth_turned.tum"
            if d.get("initial_pose"):
                d["initial_pose"] = [round(float(v), 6) for v in map_frame_poses(
                    np.array([d["initial_pose"]], dtype=float), angle, 1.0)[0]]
            print(f"{d['name']}: map turned by {a.map_rotation:g} degrees")
        tmp = folder / (log.name + ".part")
        odom, flaser = Rescaled(a.odom_scale, a.turn_scale), Rescaled(a.odom_scale, a.turn_scale)
        with open(log, errors="replace") as fi, open(tmp, "w") as fo:
            for line in fi:
                fo.write(rescale_line(degrade_line(line, rng, a.fov, a.sigma, a.drop, a.no_return, a.body,
                                                   a.range_scale, a.range_bias), odom, flaser))
        if a.latency:
            lines = tmp.read_text().splitlines(keepends=True)
            stream = odometry_stream(lines)
            tmp.write_text("".join(delay_line(line, stream, a.latency) for line in lines))
        if a.stamp_late:
            tmp.write_text(stamped_late(tmp.read_text().splitlines(keepends=True), a.stamp_late))
        if a.odom_stalls:
            text, stalls = with_odometry_stalled(tmp.read_text().splitlines(keepends=True), a.odom_stalls,
                                                 a.odom_stall_s)
            tmp.write_text(text)
            print(f"{d['name']}: odometry stalled in {len(stalls)} windows of {a.odom_stall_s:g} s")
        if a.odom_resets:
            text, resets = with_odometry_stalled(tmp.read_text().splitlines(keepends=True), a.odom_resets,
                                                 a.odom_reset_s, restart=True)
            tmp.write_text(text)
            print(f"{d['name']}: odometry restarted from 0 0 0 after {len(resets)} windows of {a.odom_reset_s:g} s")
        if a.scan_gaps:
            text, gaps = without_scans_in_gaps(tmp.read_text().splitlines(keepends=True), a.scan_gaps, a.scan_gap_s)
            tmp.write_text(text)
            if d.get("truth"):
                t, ref = read_tum(folder / Path(d["truth"]).name)
                keep = ~np.any([(t >= g0) & (t < g1) for g0, g1 in gaps], axis=0)
                write_tum(folder / "truth_gapped.tum", t[keep], ref[:, keep])
                d["truth"] = f"{d['name']}/truth_gapped.tum"
            print(f"{d['name']}: no scans in {len(gaps)} windows of {a.scan_gap_s:g} s")
        tmp.replace(folder / log.name)
        d["log"] = f"{d['name']}/{log.name}"
    suite["root"] = str(a.out.resolve())
    suite["name"] = f"{suite.get('name', 'suite')}-fov{a.fov:g}" + (
        f"-odom{a.odom_scale:g}x{a.turn_scale:g}" if (a.odom_scale, a.turn_scale) != (1.0, 1.0) else "") + (
        f"-range{a.range_scale:g}x{a.range_bias:+g}" if (a.range_scale, a.range_bias) != (1.0, 0.0) else "") + (
        f"-latency{a.latency:g}" if a.latency else "") + (
        f"-late{a.stamp_late:g}" if a.stamp_late else "") + (
        "-body" if a.body else "") + (
        f"-doubled{a.doubled_walls}" if a.doubled_walls else "") + (
        f"-turned{a.map_rotation:g}" if a.map_rotation else "") + (
        f"-gaps{a.scan_gaps}x{a.scan_gap_s:g}" if a.scan_gaps else "") + (
        f"-stalls{a.odom_stalls}x{a.odom_stall_s:g}" if a.odom_stalls else "") + (
        f"-resets{a.odom_resets}x{a.odom_reset_s:g}" if a.odom_resets else "")
    (a.out / "suite.yaml").write_text(yaml.safe_dump(suite, sort_keys=False))
    print(f"{len(suite['datasets'])} logs in {a.out}; evaluate with: mcl eval --suite {a.out / 'suite.yaml'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
