"""scripts/degrade_laser.py: a suite's logs with a narrower, noisier laser, read back through mcl's own reader."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import yaml

from mcl.config import PROJECT_ROOT
from mcl.datasets.carmen import read_carmen
from mcl.simulate import simulate

sys.path.insert(0, str(PROJECT_ROOT / "scripts"))
from degrade_laser import main  # noqa: E402


def _suite_of(tmp_path):
    """tmp_path / "suite.yaml": a suite of the one world in tmp_path / "world" (map, log, truth)."""
    (tmp_path / "suite.yaml").write_text(yaml.safe_dump({
        "name": "w", "root": "world", "modes": ["tracking"],
        "datasets": [{"name": "w", "map": "map.yaml", "log": "log.clf", "truth": "truth.tum"}]}))


def _laser_as_it_is(tmp_path, duration: float, *options):
    """A world of ``duration`` s (seed 5) run through the script with the laser left as it is and ``options``;
    returns (the world's folder, the output folder)."""
    world = tmp_path / "world"
    simulate(world, seed=5, duration=duration)
    _suite_of(tmp_path)
    out = tmp_path / "out"
    assert main([str(out), "--suite", str(tmp_path / "suite.yaml"), "--fov", "180", "--sigma", "0", "--drop", "0",
                 *options]) == 0
    return world, out


def test_the_degraded_log_keeps_the_central_field_of_view_and_the_no_returns_and_nothing_else(tmp_path):
    world = tmp_path / "world"
    simulate(world, seed=5, duration=8, n_beams=181)  # a FLASER log of 181 beams over 180 degrees
    lines = (world / "log.clf").read_text().splitlines()
    k = next(i for i, s in enumerate(lines) if s.startswith("FLASER"))
    p = lines[k].split()
    p[2 + 90] = "50.00"  # the middle beam: a no-return reading, as aces logs them
    lines[k] = " ".join(p)
    (world / "log.clf").write_text("\n".join(lines) + "\n")
    _suite_of(tmp_path)
    out = tmp_path / "out"
    assert main([str(out), "--suite", str(tmp_path / "suite.yaml"), "--fov", "90", "--sigma", "0.05",
                 "--drop", "0.2"]) == 0

    suite = yaml.safe_load((out / "suite.yaml").read_text())
    assert suite["root"] == str(out.resolve()) and suite["datasets"][0]["log"] == "w/log.clf"
    assert (out / "w" / "map.yaml").is_symlink() and (out / "w" / "truth.tum").is_symlink()
    before, after = read_carmen(world / "log.clf"), read_carmen(out / "w" / "log.clf")
    assert len(after.scans) == len(before.scans) > 30
    r0 = np.array([s.ranges for s in before.scans])
    r1 = np.array([s.ranges for s in after.scans])
    angle = np.degrees(before.scans[0].angle_min + before.scans[0].angle_increment * np.arange(r0.shape[1]))
    inside = np.abs(angle) <= 45.0 + 1e-6
    assert np.all(r1[:, ~inside] == 0.0)  # outside the 90 degrees: no reading at all
    assert r1[0, 90] == 50.0  # the no-return reading is left as it is
    kept = r1[:, inside] > 0.0
    # 20 % dropped of 91 x scans readings: the share within 0.17-0.23 (more than 5 std of a binomial share)
    assert 0.77 < kept.mean() < 0.83
    diff = (r1[:, inside] - r0[:, inside])[kept & (r0[:, inside] < 49.9)]
    # N(0, 0.05) noise rounded to 1 cm: the std of thousands of differences within 10 %, the mean within 0.005 m
    assert 0.045 < diff.std() < 0.055 and abs(diff.mean()) < 0.005
    # the rest of the log is the original's: the odometry and each scan's time and pose
    assert np.array_equal(after.odometry, before.odometry)
    assert all(a.t == b.t and np.array_equal(a.odom, b.odom) for a, b in zip(after.scans, before.scans))


def test_a_range_scale_and_bias_change_every_return_and_nothing_else(tmp_path):
    # --range-scale 0.97 --range-bias 0.05: every return r reads 0.97 r + 0.05 m (to the log's 1 cm), the no-return
    # reading (50.00 m) and the readings of 0 stay as they are, and so does the rest of the log.
    world = tmp_path / "world"
    simulate(world, seed=5, duration=8, n_beams=181)
    lines = (world / "log.clf").read_text().splitlines()
    k = next(i for i, s in enumerate(lines) if s.startswith("FLASER"))
    p = lines[k].split()
    p[2 + 90], p[2 + 10] = "50.00", "0.00"
    lines[k] = " ".join(p)
    (world / "log.clf").write_text("\n".join(lines) + "\n")
    _suite_of(tmp_path)
    out = tmp_path / "out"
    assert main([str(out), "--suite", str(tmp_path / "suite.yaml"), "--fov", "180", "--sigma", "0", "--drop", "0",
                 "--range-scale", "0.97", "--range-bias", "0.05"]) == 0
    assert yaml.safe_load((out / "suite.yaml").read_text())["name"].endswith("-range0.97x+0.05")
    before, after = read_carmen(world / "log.clf"), read_carmen(out / "w" / "log.clf")
    r0 = np.array([s.ranges for s in before.scans])
    r1 = np.array([s.ranges for s in after.scans])
    assert r1[0, 90] == 50.0 and r1[0, 10] == 0.0
    ret = (r0 > 0.0) & (r0 < 49.9)
    assert ret.sum() > 1000 and np.abs(r1[ret] - (0.97 * r0[ret] + 0.05)).max() <= 0.005 + 1e-9
    assert np.array_equal(r1[~ret], r0[~ret])
    assert np.array_equal(after.odometry, before.odometry)
    assert all(a.t == b.t and np.array_equal(a.odom, b.odom) for a, b in zip(after.scans, before.scans))


def test_the_rescaled_odometry_reports_the_steps_scaled_and_keeps_the_laser_on_the_robot(tmp_path):
    world = tmp_path / "world"
    simulate(world, seed=5, duration=8)
    lines = []
    for line in (world / "log.clf").read_text().splitlines():
        if line.startswith("FLASER"):  # the laser mounted 0.2 m ahead, 0.05 m left, turned 0.1 rad
            p = line.split()
            k = 2 + int(p[1])
            rx, ry, rt = map(float, p[k + 3:k + 6])
            c, s = np.cos(rt), np.sin(rt)
            p[k:k + 3] = [f"{v:.6f}" for v in (rx + 0.2 * c - 0.05 * s, ry + 0.2 * s + 0.05 * c, rt + 0.1)]
            line = " ".join(p)
        lines.append(line)
    (world / "log.clf").write_text("\n".join(lines) + "\n")
    _suite_of(tmp_path)
    out = tmp_path / "out"
    assert main([str(out), "--suite", str(tmp_path / "suite.yaml"), "--fov", "180", "--sigma", "0", "--drop", "0",
                 "--odom-scale", "1.05", "--turn-scale", "1.1"]) == 0
    before, after = read_carmen(world / "log.clf"), read_carmen(out / "w" / "log.clf")

    def steps(log):
        o = np.array([s.odom for s in log.scans])
        d = np.diff(o, axis=0)
        c, s = np.cos(o[:-1, 2]), np.sin(o[:-1, 2])
        return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1],
                                (d[:, 2] + np.pi) % (2 * np.pi) - np.pi])

    a, b = steps(before), steps(after)
    assert np.abs(a[:, 2]).sum() > 1.0 and np.hypot(a[:, 0], a[:, 1]).sum() > 3.0  # the robot drives and turns
    # every step in the robot frame: translation x 1.05, rotation x 1.1 (to the 1e-6 the log's decimals carry)
    np.testing.assert_allclose(b[:, :2], 1.05 * a[:, :2], atol=2e-5)
    np.testing.assert_allclose(b[:, 2], 1.1 * a[:, 2], atol=2e-5)
    assert np.allclose(after.scans[0].odom, before.scans[0].odom)  # integrated from the same first pose
    for x, y in zip(before.scans, after.scans):  # the laser keeps its mounting, the ranges are untouched
        assert np.allclose(x.laser_offset, [0.2, 0.05, 0.1], atol=1e-5)
        assert np.allclose(y.laser_offset, [0.2, 0.05, 0.1], atol=1e-5) and np.array_equal(x.ranges, y.ranges)


def test_a_latency_pairs_each_scan_with_the_odometry_that_much_later(tmp_path):
    from mcl.datasets.carmen import interpolate_odometry

    world, out = _laser_as_it_is(tmp_path, 8.0, "--latency", "0.25")
    assert yaml.safe_load((out / "suite.yaml").read_text())["name"] == "w-fov180-latency0.25"
    before, after = read_carmen(world / "log.clf"), read_carmen(out / "w" / "log.clf")
    t = np.array([s.t for s in before.scans])
    late = interpolate_odometry(before.odometry, t + 0.25).T
    got = np.array([s.odom for s in after.scans])
    np.testing.assert_allclose(got, late, atol=2e-6)  # the pose 0.25 s later, to the log's 6 decimals
    moved = np.hypot(*(got[:, :2] - np.array([s.odom for s in before.scans])[:, :2]).T)
    assert np.median(moved) > 0.05  # the robot drives: a quarter second later is somewhere else
    assert np.array_equal(after.odometry, before.odometry)  # the ODOM lines are left as they are


def test_doubled_walls_redraw_the_map_only(tmp_path):
    # --doubled-walls N with the laser left alone: the log is the original's byte for byte, the reference linked,
    # and the suite points at a new map that adds occupied cells (the walls' copies) and changes nothing else
    from mcl.maps import load_map

    world, out = _laser_as_it_is(tmp_path, 20.0, "--doubled-walls", "2")
    suite = yaml.safe_load((out / "suite.yaml").read_text())
    assert suite["datasets"][0]["map"] == "w/map_doubled.yaml" and suite["name"].endswith("-doubled2")
    assert (out / "w" / "log.clf").read_bytes() == (world / "log.clf").read_bytes()
    a, b = load_map(world / "map.yaml"), load_map(out / "w" / "map_doubled.yaml")
    added = (b.occupancy == 100) & (a.occupancy != 100)
    assert added.sum() > 100 and np.array_equal(b.occupancy[~added], a.occupancy[~added])
    assert b.resolution == a.resolution and tuple(b.origin) == tuple(a.origin)


def test_a_turned_map_is_the_simulators_and_the_reference_and_start_pose_turn_with_it(tmp_path):
    # --map-rotation DEG with the laser left alone: the log is the original's byte for byte; the map is the one
    # `mcl simulate --map-rotation` draws of the same world, and the reference and the suite's start pose are that
    # world's (turned about the frame's zero), so a run is scored where the turned map shows the robot.
    import math

    from mcl.trajectory import read_tum

    world = tmp_path / "world"
    simulate(world, seed=5, duration=20.0)
    start = yaml.safe_load((world / "sim.yaml").read_text())["start_pose"]
    (tmp_path / "suite.yaml").write_text(yaml.safe_dump({
        "name": "w", "root": "world", "modes": ["tracking"],
        "datasets": [{"name": "w", "map": "map.yaml", "log": "log.clf", "truth": "truth.tum",
                      "initial_pose": start}]}))
    out = tmp_path / "out"
    assert main([str(out), "--suite", str(tmp_path / "suite.yaml"), "--fov", "180", "--sigma", "0", "--drop", "0",
                 "--map-rotation", "-120"]) == 0
    simulate(tmp_path / "turned", seed=5, duration=20.0, map_rotation=math.radians(-120.0))
    d = yaml.safe_load((out / "suite.yaml").read_text())["datasets"][0]
    assert (d["map"], d["truth"]) == ("w/map_turned.yaml", "w/truth_turned.tum")
    assert (out / "w" / "log.clf").read_bytes() == (world / "log.clf").read_bytes()
    assert (out / "w" / "map_turned.pgm").read_bytes() == (tmp_path / "turned" / "map.pgm").read_bytes()
    assert yaml.safe_load((out / "w" / "map_turned.yaml").read_text())["origin"] == \
        yaml.safe_load((tmp_path / "turned" / "map.yaml").read_text())["origin"]
    (ta, pa), (tb, pb) = read_tum(out / "w" / "truth_turned.tum"), read_tum(tmp_path / "turned" / "truth.tum")
    np.testing.assert_array_equal(ta, tb)
    np.testing.assert_allclose(pa[:2], pb[:2], atol=3e-6)  # turned from TUM's 6 decimals, then written to 6
    np.testing.assert_allclose(np.cos(pa[2] - pb[2]), 1.0, atol=1e-10)
    turned_start = yaml.safe_load((tmp_path / "turned" / "sim.yaml").read_text())["start_pose"]
    np.testing.assert_allclose(d["initial_pose"][:2], turned_start[:2], atol=2e-6)
    assert math.cos(d["initial_pose"][2] - turned_start[2]) == pytest.approx(1.0, abs=1e-10)


@pytest.mark.parametrize("option, value, said", [
    ("--map-rotation", "270", "expected -180..180 degrees, got 270"),
    ("--map-rotation", "nan", "expected -180..180 degrees, got nan"),
    ("--doubled-walls", "-1", "expected 0..20, got -1"),
    ("--scan-gaps", "30", "expected 0..20, got 30"),
    ("--scan-gap-s", "0.2", "expected 0.5..60 s, got 0.2"),
    ("--odom-stalls", "-3", "expected 0..20, got -3"),
    ("--odom-stall-s", "90", "expected 0.5..60 s, got 90")])
def test_a_map_change_out_of_range_is_one_error_line_and_nothing_written(tmp_path, capsys, option, value, said):
    _suite_of(tmp_path)
    with pytest.raises(SystemExit) as e:
        main([str(tmp_path / "out"), "--suite", str(tmp_path / "suite.yaml"), option, value])
    assert e.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].endswith(f"error: {option}: {said}")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("entry, said", [
    ({"simulate": {"kind": "office", "seed": 1}}, "datasets[0] (w): no log: this script degrades the CARMEN logs"),
    ({"lgo": "log.clf"}, "datasets[0] (w): lgo: unknown key (did you mean log?)")])
def test_a_suite_entry_without_a_log_is_one_error_line_and_nothing_written(tmp_path, capsys, entry, said):
    # a generated world's entry raised a KeyError traceback
    (tmp_path / "suite.yaml").write_text(yaml.safe_dump({"name": "w", "datasets": [{"name": "w", **entry}]}))
    with pytest.raises(SystemExit) as e:
        main([str(tmp_path / "out"), "--suite", str(tmp_path / "suite.yaml")])
    assert e.value.code == 2
    assert f"error: {tmp_path / 'suite.yaml'}: {said}" in capsys.readouterr().err.strip().splitlines()[-1]
    assert not (tmp_path / "out").exists()


def test_scan_gaps_drop_the_scans_and_the_reference_as_the_simulator_does(tmp_path):
    # --scan-gaps N with the laser left alone: the log is the simulator's own with the same gaps (the windows spread
    # over the scans' span, which is the run's there), byte for byte, and the reference loses the same poses.
    from mcl.trajectory import read_tum

    world, out = _laser_as_it_is(tmp_path, 40.0, "--scan-gaps", "3", "--scan-gap-s", "4")
    simulate(tmp_path / "gapped", seed=5, duration=40.0, scan_gaps=3, scan_gap_s=4.0)
    d = yaml.safe_load((out / "suite.yaml").read_text())["datasets"][0]
    assert d["truth"] == "w/truth_gapped.tum"
    assert (out / "w" / "log.clf").read_bytes() == (tmp_path / "gapped" / "log.clf").read_bytes()
    assert (out / "w" / "log.clf").read_bytes() != (world / "log.clf").read_bytes()
    (ta, pa), (tb, pb) = read_tum(out / "w" / "truth_gapped.tum"), read_tum(tmp_path / "gapped" / "truth.tum")
    np.testing.assert_array_equal(ta, tb)
    np.testing.assert_allclose(pa, pb, atol=1e-6)


@pytest.mark.parametrize("args, kw", [
    (("--odom-stalls", "2", "--odom-stall-s", "3"), dict(odom_stalls=2, odom_stall_s=3.0)),
    (("--odom-resets", "2", "--odom-reset-s", "3"), dict(odom_resets=2, odom_reset_s=3.0)),
    (("--odom-resets", "3"), dict(odom_resets=3))])
def test_odometry_stalls_and_restarts_are_the_simulators(tmp_path, args, kw):
    # --odom-stalls N (--odom-resets N) with the laser left alone: the odometry (ODOM lines, the FLASER lines'
    # poses) is the one `mcl simulate --odom-stalls` (--odom-resets) writes for the same world (its windows spread
    # over the scans' span, the run's there), to the log's 6 decimals; the scans and the reference are the original's.
    from mcl.datasets.carmen import read_carmen

    world, out = _laser_as_it_is(tmp_path, 30.0, *args)
    simulate(tmp_path / "stalled", seed=5, duration=30.0, **kw)
    d = yaml.safe_load((out / "suite.yaml").read_text())["datasets"][0]
    assert d["truth"] == "w/truth.tum"  # the reference as it was

    def odometry(path):
        rows = [line.split() for line in path.read_text().splitlines() if line.startswith("ODOM")]
        return np.array([[float(v) for v in r[1:6]] for r in rows])

    got, want = odometry(out / "w" / "log.clf"), odometry(tmp_path / "stalled" / "log.clf")
    assert np.abs(odometry(world / "log.clf") - want).max() > 0.5  # the stalls moved the odometry
    np.testing.assert_allclose(got[:, :2], want[:, :2], atol=5e-6)
    np.testing.assert_allclose(np.cos(got[:, 2] - want[:, 2]), 1.0, atol=1e-9)
    np.testing.assert_allclose(got[:, 3:], want[:, 3:], atol=1e-9)
    a, b = read_carmen(out / "w" / "log.clf"), read_carmen(tmp_path / "stalled" / "log.clf")
    assert [s.ranges.tolist() for s in a.scans] == [s.ranges.tolist() for s in b.scans]
    np.testing.assert_allclose([s.odom[:2] for s in a.scans], [s.odom[:2] for s in b.scans], atol=5e-6)
