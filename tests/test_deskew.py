"""Deskewing a spinning laser's scan (``sensor.sweep_time``): each beam's endpoint moved into the robot frame at
the stamp by the robot's motion since then (mcl.sensors.beam_endpoints, mcl.deskew.deskewed)."""

from __future__ import annotations

import dataclasses
import math
import types
from pathlib import Path

import numpy as np
import pytest
import yaml

from mcl.config import load_config
from mcl.datasets.bagwrite import BagOut
from mcl.datasets.rosbag import beam_times, open_bag
from mcl.errors import ConfigError
from mcl.runner import run
from mcl.sensors import beam_endpoints, sweep_of
from mcl.simulate import simulate

CFG = types.SimpleNamespace(range_min=0.0, range_max=80.0, max_beams=1000)
N = 181
ANGLES = np.linspace(-1.2, 1.2, N)
TAU = np.arange(N) * (0.2 / (N - 1))  # a 0.2 s sweep, the first beam at the stamp


def test_a_turning_robots_scan_of_a_wall_is_straight_again_once_deskewed():
    # A wall x = 2 m ahead of the robot at the stamp; the robot turns at 1.5 rad/s while the laser sweeps, so beam j
    # (angle a in the robot frame of its own time tau) points at a + 1.5 tau in the stamp's frame: it reads
    # 2 / cos(a + 1.5 tau). Deskewed, every endpoint lies on x = 2 (pure rotation: the first-order model is exact);
    # as measured, up to 0.3 rad of shear bends the wall by decimetres.
    w = 1.5
    r = 2.0 / np.cos(ANGLES + w * TAU)
    raw = beam_endpoints(r, ANGLES, None, CFG)
    fixed = beam_endpoints(r, ANGLES, None, CFG, sweep=(TAU, np.array([0.0, 0.0, w])))
    np.testing.assert_allclose(fixed[0], 2.0, rtol=0, atol=1e-9)
    assert np.abs(raw[0] - 2.0).max() > 0.3


def test_a_driving_robots_scan_is_moved_back_to_the_stamp():
    # Driving at 1 m/s towards the wall x = 2: at time tau the wall is 2 - tau ahead, beam a reads (2 - tau) / cos a
    w_fwd = 1.0
    r = (2.0 - w_fwd * TAU) / np.cos(ANGLES)
    fixed = beam_endpoints(r, ANGLES, None, CFG, sweep=(TAU, np.array([w_fwd, 0.0, 0.0])))
    np.testing.assert_allclose(fixed[0], 2.0, rtol=0, atol=1e-9)
    # the laser off the robot's centre is turned with the robot: the same wall seen from a laser 0.3 m ahead
    r = (2.0 - 0.3 - w_fwd * TAU) / np.cos(ANGLES)
    fixed = beam_endpoints(r, ANGLES, None, CFG, (0.3, 0.0, 0.0), sweep=(TAU, np.array([w_fwd, 0.0, 0.0])))
    np.testing.assert_allclose(fixed[0], 2.0, rtol=0, atol=1e-9)


def test_beam_times_from_a_laserscans_time_increment():
    assert beam_times(0.001, 360) == (0.0, 0.001)
    assert beam_times(-0.001, 360) == (0.0, -0.001)  # beams taken in reverse array order
    for bad in (0.0, float("nan"), float("inf"), 0.01):  # 0.01 s x 359: a 3.6 s "sweep" is not one
        assert beam_times(bad, 360) == (0.0, 0.0)
    assert beam_times(0.001, 1) == (0.0, 0.0)
    assert sweep_of(types.SimpleNamespace(ranges=np.zeros(4), beam_t0=0.0, beam_dt=0.0, twist=np.zeros(3))) is None


def test_an_upside_down_lasers_beams_keep_their_times(tmp_path):
    # Rolled by pi, the laser's beams are read reversed: array beam j is the message's beam n-1-j, taken at
    # (n-1-j) * time_increment after the stamp.
    ti, n = 0.0005, 181
    bag = tmp_path / "flipped.mcap"
    with BagOut(bag) as b:
        q = b.msg("geometry_msgs/msg/Quaternion", x=1.0, y=0.0, z=0.0, w=0.0)
        tr = b.msg("geometry_msgs/msg/Transform", translation=b.msg("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.3),
                   rotation=q)
        b.write("/tf_static", "tf2_msgs/msg/TFMessage", 1.0, b.msg("tf2_msgs/msg/TFMessage", transforms=[
            b.msg("geometry_msgs/msg/TransformStamped", header=b.header(1.0, "base_link"), child_frame_id="laser",
                  transform=tr)]))
        for k in range(3):
            t = 1.0 + 0.2 * k
            b.write("/tf", "tf2_msgs/msg/TFMessage", t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
                b.transform(t, "odom", "base_link", (0.1 * k, 0.0, 0.0))]))
            L = "sensor_msgs/msg/LaserScan"
            b.write("/scan", L, t, b.msg(L, header=b.header(t, "laser"), angle_min=-math.pi / 2,
                                         angle_max=math.pi / 2, angle_increment=math.pi / (n - 1),
                                         time_increment=ti, scan_time=0.0, range_min=0.0, range_max=10.0,
                                         ranges=np.full(n, 2.0, dtype=np.float32),
                                         intensities=np.zeros(0, dtype=np.float32)))
    s = next(iter(open_bag(bag).scans))
    tau = s.beam_t0 + s.beam_dt * np.arange(n)
    np.testing.assert_allclose(tau, (n - 1 - np.arange(n)) * np.float32(ti), rtol=0, atol=1e-12)


TB3 = dict(kind="office", seed=191, duration=90.0, fov=2 * math.pi, n_beams=360, range_max=3.5, speed=0.22,
           turn_rate=1.5, dynamic_obstacles=0, unmapped_furniture=0)


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """A TurtleBot-like world (360 degree, 3.5 m laser, 0.2 s a turn) as a CARMEN log and as MCAP bags: its beams
    taken as stamped (bag), the other way round with a positive time_increment as rplidar_ros writes them
    (reversed), and all at once with a bag that says 0.2 s (at-once)."""
    from mcl.simulate import write_log_as_bag

    root = tmp_path_factory.mktemp("swept")
    simulate(root / "clf", scan_sweep=0.2, **TB3)
    for name, sweep, said in (("bag", 0.2, 0.2), ("reversed", -0.2, 0.2), ("at-once", 0.0, 0.2)):
        simulate(root / name, scan_sweep=sweep, **TB3)
        write_log_as_bag(root / name, "mcap", sweep=said)
    return root


def _track(world: Path, out: Path, **over):
    start = yaml.safe_load((world / "sim.yaml").read_text())["start_pose"]
    sets = ["rerun.mode=off", f"map={world / 'map.yaml'}", f"truth={world / 'truth.tum'}",
            f"filter.initial_pose={start}", "filter.global_localization=false", "seed=1"]
    if (world / "log.mcap").exists():
        sets += [f"bag={world / 'log.mcap'}", "log=null"]
    else:
        sets += [f"log={world / 'log.clf'}"]
    cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / "default.yaml",
                      sets + [f"{k}={v}" for k, v in over.items()])
    return run(cfg, out, progress=False, echo=lambda *a, **k: None), out


def test_a_bag_with_time_increment_is_deskewed_by_default(swept, tmp_path):
    # Seed 1 (measured): the beams' timing is decided "as stamped" at the 119th scan (44 taken while turning);
    # heading RMSE 0.75 deg against 1.39 deg as if every beam were taken at the stamp, position 0.030 against
    # 0.036 m. The
    # bounds fail if the sweep is ignored, applied the wrong way round, or the timing is decided wrongly.
    on, _ = _track(swept / "bag", tmp_path / "on")
    off, _ = _track(swept / "bag", tmp_path / "off", **{"sensor.sweep_time": 0})
    assert on["sweep_order"]["order"] == "as stamped" and on["sweep_order"]["decided_after_scans"] < 200
    assert "sweep_order" not in off
    assert on["eval"]["heading_rmse_deg"] < 0.8 * off["eval"]["heading_rmse_deg"]
    assert on["eval"]["ate_rmse"] < off["eval"]["ate_rmse"]


def test_beams_written_against_time_are_found_reversed(swept, tmp_path):
    # rplidar_ros's beams: taken from the last to the first, with a positive time_increment. Deskewed as stamped
    # the shear would double; the scans say which (decided at the 115th scan). Whether the stamp is the first beam
    # taken (rplidar_ros, as here) or the last (the LDS driver) the scans cannot say: the reversed times are
    # centred on the stamp, half a sweep off either way, as the scan read as is is on average (measured: heading
    # RMSE 1.48 against 1.53 deg as read). Told the stamp is 0.1 s early (sensor.time_offset), 0.43 deg.
    on, _ = _track(swept / "reversed", tmp_path / "on")
    off, _ = _track(swept / "reversed", tmp_path / "off", **{"sensor.sweep_time": 0})
    ev = on["sweep_order"]["log_evidence"]
    assert on["sweep_order"]["order"] == "reversed"
    assert ev["as stamped"] < ev["all at once"] - 40  # the doubled shear fits far worse than none
    assert on["eval"]["heading_rmse_deg"] <= 1.02 * off["eval"]["heading_rmse_deg"]
    told, _ = _track(swept / "reversed", tmp_path / "told", **{"sensor.time_offset": 0.1})
    assert told["sweep_order"]["order"] == "reversed"
    assert told["eval"]["heading_rmse_deg"] < 0.4 * off["eval"]["heading_rmse_deg"]


def test_a_bag_that_claims_a_sweep_its_scans_do_not_have_is_read_as_it_is(swept, tmp_path):
    # Beams taken all at once (a driver that deskews by itself) but time_increment says 0.2 s: the scans are used
    # as read until decided, and decided "all at once", so the run is the one with deskewing off, pose for pose.
    on, a = _track(swept / "at-once", tmp_path / "on")
    off, b = _track(swept / "at-once", tmp_path / "off", **{"sensor.sweep_time": 0})
    assert on["sweep_order"]["order"] == "all at once"
    assert (a / "trajectory.tum").read_bytes() == (b / "trajectory.tum").read_bytes()


def test_a_carmen_log_is_deskewed_only_when_told_the_sweep(swept, tmp_path):
    auto, a = _track(swept / "clf", tmp_path / "auto")
    off, b = _track(swept / "clf", tmp_path / "off", **{"sensor.sweep_time": 0})
    told, _ = _track(swept / "clf", tmp_path / "told", **{"sensor.sweep_time": 0.2})
    assert (a / "trajectory.tum").read_bytes() == (b / "trajectory.tum").read_bytes()  # auto: a log gives no times
    assert "sweep_order" not in auto
    assert told["sweep_order"]["order"] == "as stamped"
    assert told["eval"]["heading_rmse_deg"] < 0.8 * off["eval"]["heading_rmse_deg"]


@pytest.mark.parametrize("value, match", [(-0.1, "out of range"), (1.5, "out of range"), ("soon", "sweep_time")])
def test_bad_sweep_time_is_one_line_naming_the_key(value, match):
    with pytest.raises(ConfigError, match=match) as e:
        load_config(None, [f"sensor.sweep_time={value}"])
    assert "sensor.sweep_time" in str(e.value)


def test_a_swept_worlds_first_beam_is_the_unswept_worlds(tmp_path):
    # Beam 0 is taken at the stamp in both; the rest of a swept scan is cast from later poses, so it differs once
    # the robot moves. The noise streams are the same, so beam 0 matches to the digit.
    kw = dict(kind="office", seed=5, duration=10.0, dynamic_obstacles=0, unmapped_furniture=0)
    simulate(tmp_path / "a", **kw)
    simulate(tmp_path / "b", scan_sweep=0.15, **kw)

    def ranges(d):
        return np.array([[float(v) for v in ln.split()[2:183]] for ln in (d / "log.clf").read_text().splitlines()
                         if ln.startswith("FLASER")])

    a, b = ranges(tmp_path / "a"), ranges(tmp_path / "b")
    np.testing.assert_array_equal(a[:, 0], b[:, 0])
    assert np.mean(np.abs(a - b) > 0.01) > 0.3  # measured 0.46: the robot moves 7.5 cm in 0.15 s at 0.5 m/s
    assert yaml.safe_load((tmp_path / "b" / "sim.yaml").read_text())["laser"]["sweep_s"] == 0.15
    with pytest.raises(ConfigError, match="scan_sweep"):
        simulate(tmp_path / "c", kind="office", seed=5, duration=10.0, scan_sweep=0.15, dynamic_obstacles=3)  # not cast swept
    with pytest.raises(ConfigError, match="scan_sweep"):
        simulate(tmp_path / "d", kind="office", seed=5, duration=10.0, scan_sweep=0.5, dynamic_obstacles=0,
                 unmapped_furniture=0)  # longer than a scan period (5 Hz)


def test_bag_info_says_whether_the_scans_will_be_deskewed(swept, tmp_path):
    from mcl.datasets.rosbag import bag_info, format_info
    from mcl.simulate import write_log_as_bag

    info = bag_info(swept / "bag" / "log.mcap")
    assert info["mcl_uses"]["sweep_s"]["/scan"] == pytest.approx(0.2, abs=1e-6)  # float32 time_increment x 359
    assert "/scan: 0.2 s from the first beam to the last (time_increment): deskewed" in format_info(info)
    simulate(tmp_path, kind="office", seed=5, duration=4.0)
    text = format_info(bag_info(write_log_as_bag(tmp_path, "mcap")))
    assert "/scan: none (time_increment 0): not deskewed" in text


def test_mcl_run_says_it_deskews_a_bag(swept, tmp_path, capsys):
    from mcl.cli import main

    start = yaml.safe_load((swept / "bag" / "sim.yaml").read_text())["start_pose"]
    argv = ["run", "--map", str(swept / "bag" / "map.yaml"), "--bag", str(swept / "bag" / "log.mcap"),
            "--initial-pose", *map(str, start), "--rerun", "off", "--out"]
    assert main(argv + [str(tmp_path / "a")]) == 0
    assert "a laser sweep takes /scan 0.2 s (LaserScan time_increment): each scan deskewed" in capsys.readouterr().err
    assert main(argv + [str(tmp_path / "b"), "--set", "sensor.sweep_time=0"]) == 0
    assert "deskewed" not in capsys.readouterr().err


def test_the_spinning_lidar_suite_deskews_each_swept_world_by_its_own_sweep():
    # suites/spinning-lidar.yaml pairs each swept world with its twin scanned at once; a swept world's
    # sensor.sweep_time must be its scan_sweep (what a bag's time_increment would say), its twin's nothing.
    from mcl.suite import load_suite

    suite = load_suite(Path(__file__).resolve().parents[1] / "suites" / "spinning-lidar.yaml")
    swept = [d for d in suite.datasets if d.simulate.get("scan_sweep")]
    assert len(swept) == 4 and len(suite.datasets) == 8
    for d in suite.datasets:
        assert d.set.get("sensor.sweep_time") == d.simulate.get("scan_sweep")
        twin = d.name.replace("-swept", "-at-once")
        assert {k: v for k, v in d.simulate.items() if k != "scan_sweep"} == \
            next(e.simulate for e in suite.datasets if e.name == twin)


def test_mcl_simulate_scan_sweep_writes_time_increment_into_a_bag(tmp_path):
    from mcl.cli import main

    assert main(["simulate", str(tmp_path / "w"), "--duration", "4", "--scan-sweep", "0.1", "--format", "mcap",
                 "--dynamic-obstacles", "0", "--unmapped-furniture", "0"]) == 0
    src = open_bag(tmp_path / "w" / "log.mcap")
    assert src.sweeps["/scan"] == pytest.approx(0.1, abs=1e-6)
    s = next(iter(src.scans))
    assert s.beam_t0 == 0.0 and s.beam_dt * (s.ranges.size - 1) == pytest.approx(0.1, abs=1e-6)


def test_sweep_order_decides_when_one_reading_leads_by_the_margin():
    from mcl.deskew import SweepOrder

    o = SweepOrder(decide_nats=30.0)
    from mcl.datasets.carmen import Scan

    scan = Scan(0.0, np.ones(4), 0.0, 0.1, None, np.zeros(3), None, beam_dt=0.1, twist=np.ones(3))
    use, readings = o.choose(scan)
    assert use.twist is None and len(readings) == 3  # undecided: as read, three readings to weigh
    slow = dataclasses.replace(scan, twist=np.array([1.0, 0.0, 0.1]))  # 0.03 rad over the sweep: under MIN_TURN
    assert o.choose(slow)[1] is None
    assert readings[2].beam_t0 == pytest.approx(0.15) and readings[2].beam_dt == -0.1  # centred: 0.15, 0.05, -0.05, -0.15
    o.weigh([0.0, float("nan"), 0.0])  # not finite: not counted
    assert o.weighed == 0
    for _ in range(5):
        o.weigh([-1.0, 0.0, -7.5])  # "all at once" leads "as stamped" by 1 a scan
    assert o.order is None
    while o.order is None:
        o.weigh([-7.0, 0.0, -20.0])
    assert o.order == 0 and o.decided_at == o.weighed == 9  # the lead 5 + 4 x 7 = 33 >= 30 after the ninth
    use, readings = o.choose(scan)
    assert readings is None and use.twist is None  # decided "all at once": the scan as read, nothing to weigh
    o.weigh([100.0, 0.0, 0.0])  # decided: no more weighing
    assert o.weighed == 9 and o.summary()["order"] == "all at once"
