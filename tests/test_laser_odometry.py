"""Laser odometry (mcl.laser_odometry): the motion from the scans of a bag without wheel odometry.

One generated world (mcl simulate, seed 5, 60 s at 5 Hz: a corridor, turns, a 12 m laser), its scans written to
bags with and without odometry."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mcl.config import load_config
from mcl.datasets.bagwrite import BagOut
from mcl.datasets.carmen import read_carmen
from mcl.datasets.rosbag import bag_info, open_bag
from mcl.estimate import compose, inverse
from mcl.laser_odometry import laser_odometry
from mcl.runner import run
from mcl.simulate import simulate
from mcl.trajectory import read_tum


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    d = tmp_path_factory.mktemp("lo")
    simulate(d, seed=5, duration=60.0)
    scans = read_carmen(d / "log.clf").laser_stream()
    t, poses = read_tum(d / "truth.tum")[:2]
    poses = np.asarray(poses)
    return d, scans, np.asarray(t), (poses if poses.shape[0] == 3 else poses.T)


def _step_errors(rows, scans, t, truth, gap=5):
    """m: |(pose k -> pose k+gap) - the same by the truth| over the scans (a relative-pose error, drift-free)."""
    idx = np.clip(np.searchsorted(t, [s.t for s in scans]), 0, t.size - 1)
    out = []
    for k in range(0, len(scans) - gap, gap):
        want = compose(inverse(truth[:, idx[k]]), truth[:, idx[k + gap]])
        got = compose(inverse(rows[k, 1:4]), rows[k + gap, 1:4])
        out.append(math.hypot(got[0] - want[0], got[1] - want[1]))
    return np.array(out)


def test_the_scans_give_the_motion_about_as_well_as_the_wheels(world):
    # Over 1 s (5 scans, 0.5 m of travel) the simulated wheel odometry errs by 0.027 m (median) / 0.075 m (95th
    # percentile); the scans matched give 0.013 / 0.133 m (measured; 0.012 / 0.052 m with the guess unsmoothed,
    # which the 40 Hz test below needs). The bounds, 0.02 and 0.2 m, fail a matcher that stalls along the corridor
    # (0.05 / 0.5 m before the prior at the guess) or mistakes the turn's sign.
    d, scans, t, truth = world
    rows, failed = laser_odometry(scans, scans[0].laser_offset)
    assert failed == 0 and rows.shape == (len(scans), 6)
    assert np.array_equal(rows[:, 0], [s.t for s in scans]) and np.all(rows[0, 1:] == 0.0)
    err = _step_errors(rows, scans, t, truth)
    assert np.median(err) < 0.02 and np.percentile(err, 95) < 0.2, (np.median(err), np.percentile(err, 95))


def test_at_40_hz_the_guess_is_a_smoothed_velocity(tmp_path):
    # A 40 Hz, 1081-beam, 270 degree, 30 m laser (a UTM-30LX's), 40 s: over 1 s (40 scans) the matched motion errs
    # by 0.007 m (median) / 0.052 m (95th percentile) with the guess smoothed over SMOOTH = 0.5 s; with the last
    # step as the guess, 0.008 / 0.92 m: along the corridor each step is the matcher's noise and the guess
    # random-walked. Bound 0.1 m at the 95th percentile.
    simulate(tmp_path, seed=1, duration=40.0, n_beams=1081, fov=math.radians(270.0), range_max=30.0,
             scan_rate=40.0)
    scans = read_carmen(tmp_path / "log.clf").laser_stream()
    t, poses = read_tum(tmp_path / "truth.tum")[:2]
    poses = np.asarray(poses)
    rows, failed = laser_odometry(scans, scans[0].laser_offset)
    err = _step_errors(rows, scans, np.asarray(t), poses if poses.shape[0] == 3 else poses.T, gap=40)
    assert failed == 0 and np.median(err) < 0.02 and np.percentile(err, 95) < 0.1, (np.median(err),
                                                                                   np.percentile(err, 95))


def _scan_only_bag(path: Path, scans, blank=()) -> None:
    """/scan alone; the scans whose index is in ``blank`` without a return (every beam +inf)."""
    L = "sensor_msgs/msg/LaserScan"
    with BagOut(path) as b:
        for k, s in enumerate(scans):
            r = np.asarray(s.ranges, dtype=np.float32)
            if k in blank:
                r = np.full_like(r, np.inf)
            b.write("/scan", L, s.t, b.msg(L, header=b.header(s.t, "base_link"), angle_min=s.angle_min,
                                           angle_max=s.angle_min + s.angle_increment * (r.size - 1),
                                           angle_increment=s.angle_increment, time_increment=0.0, scan_time=0.0,
                                           range_min=0.0, range_max=s.max_range, ranges=r,
                                           intensities=np.zeros(0, dtype=np.float32)))


def test_the_matching_shows_its_progress_when_asked(world, tmp_path, capsys):
    # A long bag's matching takes minutes (3 ms a scan): mcl run shows a bar over it, as over the run.
    d, scans, t, truth = world
    bag = tmp_path / "scans.mcap"
    _scan_only_bag(bag, scans[:40])
    open_bag(bag)
    assert "laser odometry" not in capsys.readouterr().err
    open_bag(bag, progress=True)
    err = capsys.readouterr().err
    assert "laser odometry" in err and "/40 " in err


def test_a_bag_without_odometry_is_tracked_on_the_scans_motion(world, tmp_path):
    # No Odometry topic, no /tf: the motion comes from the scans, with a note (it was one line asking for
    # odometry). Tracking from the true start, default config: RMSE 0.066 m, max 0.26 m (the CARMEN log with its
    # wheel odometry: 0.058 / 0.12 m). Bounds 0.1 / 0.4 m: a run without motion (every scan at the first pose) is
    # metres off by 10 s.
    d, scans, t, truth = world
    bag = tmp_path / "scans.mcap"
    _scan_only_bag(bag, scans)
    src = open_bag(bag)
    assert src.odom_source == "laser odometry (scan matching of /scan)"
    assert any("no odometry (no nav_msgs/Odometry topic, no /tf); the motion comes from the scans" in n
               for n in src.notes)
    assert bag_info(bag)["mcl_uses"]["odometry"] == "laser odometry (scan matching of /scan)"
    x, y, th = truth[:, 0]
    cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / "default.yaml",
                      ["rerun.mode=off", "log=null", f"bag={bag}", f"map={d / 'map.yaml'}",
                       f"truth={d / 'truth.tum'}", f"filter.initial_pose=[{x}, {y}, {th}]",
                       "filter.global_localization=false"])
    summary = run(cfg, tmp_path / "out", progress=False, echo=lambda *a, **k: None)
    ev = summary["eval"]
    assert summary["scans"] == len(scans)
    assert ev["ate_rmse"] < 0.1 and ev["ate_max"] < 0.4, ev
    # the scans' motion jitters across the heading (a 20 Hz corridor reads 0.19 of its travel sideways): the share
    # is not measured on it, and the configured model is run
    assert summary["motion_model"] == "odometry" and "odometry_sideways" not in summary
    assert bag_info(bag)["mcl_uses"]["odometry_sideways"] is None


def test_topics_odom_laser_replaces_the_bags_odometry(world, tmp_path):
    # A bag with /odom: auto reads it; topics.odom: laser takes the scans' motion instead (a robot whose wheels
    # slip), the same rows as the scan-only bag's.
    from mcl.datasets.bagwrite import write_scans

    d, scans, t, truth = world
    bag, bare = tmp_path / "full.mcap", tmp_path / "bare.mcap"
    write_scans(bag, scans, mount=(0.0, 0.0, 0.0))
    _scan_only_bag(bare, scans)
    wheel = open_bag(bag)
    assert wheel.odom_source.startswith("/odom")
    laser = open_bag(bag, load_config(None, ["topics.odom=laser"]).topics)
    assert laser.odom_source == "laser odometry (scan matching of /scan)"
    assert np.array_equal(laser.odometry, open_bag(bare).odometry)
    assert not np.allclose(laser.odometry[:, 1:4], wheel.odometry[:, 1:4], atol=0.05)


def test_scans_without_returns_are_counted_in_a_warning_and_one_scan_is_one_line(world, tmp_path, capsys):
    # Every fourth scan without a return (a laser facing open space) cannot be matched: a warning counts them
    # (here 75 of 301); each takes the guess (the smoothed velocity) and the scans around them still give the
    # motion: the 1 s error is 0.121 m at the 95th percentile against 0.133 m with every scan; 0.56 m when a miss
    # stopped the motion. Bound 0.2 m. A bag of one scan has nothing to match: one line, exit 2.
    from mcl.cli import main

    d, scans, t, truth = world
    bag = tmp_path / "holes.mcap"
    blank = set(range(3, len(scans), 4))
    _scan_only_bag(bag, scans, blank)
    src = open_bag(bag)
    assert any(f"laser odometry: {len(blank)} of {len(scans)} scans of /scan matched no earlier one" in w
               for w in src.warnings), src.warnings
    err = _step_errors(src.odometry, scans, t, truth)
    assert np.percentile(err, 95) < 0.2, np.percentile(err, 95)
    one = tmp_path / "one.mcap"
    _scan_only_bag(one, scans[:1])
    out = tmp_path / "out"
    assert main(["run", "--bag", str(one), "--map", str(d / "map.yaml"), "--out", str(out), "--rerun", "off",
                 "--no-progress"]) == 2
    e = capsys.readouterr().err.strip()
    assert len(e.splitlines()) == 1 and "no odometry, and /scan has 1 scan: nothing to match" in e and not out.exists()


def test_a_backpack_bag_multi_echo_lasers_no_odometry_runs_as_its_level_laser_alone(world, tmp_path):
    # The shape of cartographer's public backpack bags: two MultiEchoLaserScan topics, one level, one turned 90
    # degrees up (its plane vertical), fixed links on /tf_static, no odometry at all. auto reads the level laser's
    # first echoes and matches them for the motion: the same trajectory, to the byte, as the LaserScan-only bag.
    from tests.bagmsgs import multi_echo as _echoes
    from tests.bagmsgs import tilted as _tilted

    d, scans, t, truth = world
    pack, bare = tmp_path / "backpack.bag", tmp_path / "bare.bag"
    _scan_only_bag(bare, scans)
    with BagOut(pack) as b:
        b.write("/tf_static", "tf2_msgs/msg/TFMessage", scans[0].t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
            _tilted(b, scans[0].t, "base_link", "horizontal_laser_link", (0.0, 0.0, 0.0), 0.0),
            _tilted(b, scans[0].t, "base_link", "vertical_laser_link", (0.1, 0.0, 0.3), -math.pi / 2)]))
        for s in scans:
            _echoes(b, "/horizontal_laser_2d", s, [[r, r + 1.0] for r in s.ranges.astype(np.float32)],
                    frame="horizontal_laser_link")
            _echoes(b, "/vertical_laser_2d", s, [[1.5]] * s.ranges.size, frame="vertical_laser_link")
    src = open_bag(pack)
    assert src.scans.topics == ["/horizontal_laser_2d"]
    assert src.odom_source == "laser odometry (scan matching of /horizontal_laser_2d)"
    assert any("/vertical_laser_2d: tilted 90 deg from level" in n for n in src.notes), src.notes
    assert np.array_equal(src.odometry, open_bag(bare).odometry)
    x, y, th = truth[:, 0]
    outs = []
    for bag in (pack, bare):
        cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / "default.yaml",
                          ["rerun.mode=off", "log=null", f"bag={bag}", f"map={d / 'map.yaml'}", "truth=null",
                           f"filter.initial_pose=[{x}, {y}, {th}]", "filter.global_localization=false"])
        out = tmp_path / bag.stem
        run(cfg, out, progress=False, echo=lambda *a, **k: None)
        outs.append((out / "trajectory.tum").read_bytes())
    assert outs[0] == outs[1]


def test_the_configured_laser_pose_turns_the_lasers_motion_into_the_robots(world, tmp_path):
    # The run puts the laser at sensor.laser_pose when the config gives one (over the bag's mounting); the
    # odometry made from the scans uses the same mounting, so the two agree (a laser 0.3 m ahead of the centre:
    # the robot's turns in place are the laser's arcs, not its own).
    d, scans, t, truth = world
    bag = tmp_path / "scans.mcap"
    _scan_only_bag(bag, scans)
    ahead = open_bag(bag, laser_pose=(0.3, 0.0, 0.0))
    centre = open_bag(bag)
    assert np.array_equal(ahead.odometry, laser_odometry(list(centre.scans), (0.3, 0.0, 0.0))[0])
    assert not np.allclose(ahead.odometry[:, 1:3], centre.odometry[:, 1:3], atol=0.05)
