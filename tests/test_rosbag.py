"""ROS bags (issue 9): the same records as the CARMEN log they came from, each storage kind, each odometry source,
the map / initial pose / truth inside the bag, conversion both ways, and each bad input as one line and exit 2.

Every bag is written on the fly by the rosbags library's writers (mcl.datasets.bagwrite.BagOut) from a short
synthetic world (mcl simulate, 8 s, 41 scans)."""

from __future__ import annotations

import dataclasses
import math
import types
from pathlib import Path

import numpy as np
import pytest

from mcl.cli import main
from mcl.config import load_config
from mcl.datasets.bagwrite import BagOut, convert, write_scans
from mcl.datasets.carmen import read_carmen
from mcl.datasets.rosbag import bag_info, odometry_at, open_bag
from mcl.estimate import compose, inverse
from mcl.errors import ConfigError
from mcl.maps import load_map
from mcl.runner import run
from mcl.simulate import simulate
from mcl.trajectory import read_tum
from tests.bagmsgs import laser as _laser
from tests.bagmsgs import multi_echo as _echoes
from tests.bagmsgs import odom as _odom
from tests.bagmsgs import tilted as _tilted

KINDS = {"bag1": "bag", "db3": "db3", "mcap": "mcap"}


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    d = tmp_path_factory.mktemp("world")
    simulate(d, seed=3, duration=8.0)
    return d


@pytest.fixture(scope="module")
def scans(world):
    return read_carmen(world / "log.clf").laser_stream()


def _quiet(*_a, **_k):
    pass


def _run(tmp_path, name, **data):
    overrides = ["rerun.mode=off", "filter.particles=400", "filter.kld=false", "truth=null", "log=null"]
    overrides += [f"{k}={v}" for k, v in data.items()]
    cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / "default.yaml", overrides)
    out = tmp_path / name
    return run(cfg, out, progress=False, echo=_quiet), out


def _same_records(a, b, *, offset_tol=0.0):
    assert a.t == b.t
    assert np.array_equal(a.ranges, b.ranges)
    assert (a.angle_min, a.angle_increment, a.max_range) == (b.angle_min, b.angle_increment, b.max_range)
    assert np.array_equal(a.odom, b.odom)
    assert (a.tv, a.rv) == (b.tv, b.rv)
    oa = np.zeros(3) if a.laser_offset is None else a.laser_offset
    ob = np.zeros(3) if b.laser_offset is None else b.laser_offset
    assert np.allclose(oa, ob, rtol=0, atol=offset_tol)


# ----------------------------------------------------------------------------- same data, same trajectory


@pytest.mark.parametrize("kind", list(KINDS))
def test_each_storage_kind_reads_the_logs_records_and_gives_a_byte_identical_trajectory(world, scans, tmp_path, kind):
    bag = tmp_path / f"log.{KINDS[kind]}"
    assert write_scans(bag, scans) == len(scans)
    src = open_bag(bag)
    got = list(src.scans)
    assert len(got) == len(src.scans) == len(scans)
    for a, b in zip(scans, got):
        _same_records(a, b)
    s_clf, o_clf = _run(tmp_path, "clf", map=world / "map.yaml", log=world / "log.clf")
    s_bag, o_bag = _run(tmp_path, "bag", map=world / "map.yaml", bag=bag)
    assert s_bag["updates"] == s_clf["updates"] > 30
    assert (o_bag / "trajectory.tum").read_bytes() == (o_clf / "trajectory.tum").read_bytes()


def test_a_laser_off_the_robots_centre_gives_the_same_trajectory_as_a_bag(tmp_path):
    # A FLASER line prints its laser and robot poses to 6 decimals, so the mounting worked out from them jittered by
    # ~1e-6 from scan to scan (151 mountings for one laser), where a bag's /tf_static holds one: 147 of 151 poses
    # differed, by up to 7.7 mm. The log's mountings that agree within MOUNT_JITTER are one now (their median).
    w = tmp_path / "w"
    simulate(w, seed=9, duration=12.0, laser_pose=(0.1, 0.0, 0.05))
    scans = read_carmen(w / "log.clf").laser_stream()
    assert len({tuple(s.laser_offset) for s in scans}) == 1
    np.testing.assert_allclose(scans[0].laser_offset, [0.1, 0.0, 0.05], atol=2e-6)
    bag = tmp_path / "w.mcap"
    write_scans(bag, scans)
    _, o_clf = _run(tmp_path, "clf", map=w / "map.yaml", log=w / "log.clf")
    _, o_bag = _run(tmp_path, "bag", map=w / "map.yaml", bag=bag)
    assert (o_bag / "trajectory.tum").read_bytes() == (o_clf / "trajectory.tum").read_bytes()


def test_a_mounting_that_varies_is_left_as_it_is():
    from mcl.datasets.carmen import Scan, _steady_mounting

    def scan(off):
        return Scan(0.0, np.ones(3), -1.0, 1.0, 5.0, np.zeros(3), np.array(off), 0.0, 0.0, "FLASER", 1)

    jitter = _steady_mounting([scan([0.1, 0.0, 0.05]), scan([0.100001, 0.0, 0.05]), scan([0.099999, 0.0, 0.05])])
    assert all(np.array_equal(s.laser_offset, [0.1, 0.0, 0.05]) for s in jitter)
    moving = _steady_mounting([scan([0.1, 0.0, 0.05]), scan([0.2, 0.0, 0.05])])
    assert [s.laser_offset[0] for s in moving] == [0.1, 0.2]


def test_a_bag_run_writes_its_recording_with_a_scan_per_update(world, scans, tmp_path):
    # A bag's scans are a stream (BagScans): the recording's setup once sliced them and every bag run with a
    # recording (the default rerun.mode) stopped on a TypeError. Read back: one /world/scan row per update.
    import pyarrow as pa
    from rerun.chunk import RrdReader

    bag = tmp_path / "log.mcap"
    write_scans(bag, scans)
    s, out = _run(tmp_path, "rec", map=world / "map.yaml", bag=bag, **{"rerun.mode": "save"})
    steps = []
    for c in RrdReader(out / "recording.rrd").stream().to_chunks():
        if c.entity_path == "/world/scan" and not c.is_static and "step" in c.timeline_names:
            steps += c.to_record_batch().column("step").cast(pa.int64()).to_pylist()
    assert sorted(steps) == list(range(s["updates"])) and s["updates"] > 30


def test_odometry_from_tf_is_interpolated_at_each_scan_stamp(scans, tmp_path):
    # /tf carries odom -> base_link at every other scan only: the scans between get the linear interpolation of
    # their two neighbours (x, y exactly the midpoint within float rounding; the motion between is small).
    bag = tmp_path / "tf.mcap"
    with BagOut(bag) as b:
        for k, s in enumerate(scans):
            if k == 0:
                b.write("/tf_static", "tf2_msgs/msg/TFMessage", s.t,
                        b.msg("tf2_msgs/msg/TFMessage", transforms=[b.transform(s.t, "base_link", "laser", (0, 0, 0))]))
            if k % 2 == 0:
                b.write("/tf", "tf2_msgs/msg/TFMessage", s.t,
                        b.msg("tf2_msgs/msg/TFMessage", transforms=[b.transform(s.t, "odom", "base_link", s.odom)]))
            _laser(b, "/scan", s)
    src = open_bag(bag)
    assert src.odom_source == "/tf odom -> base_link"
    got = list(src.scans)
    for k in range(1, len(scans) - 1, 2):
        a, c = scans[k - 1], scans[k + 1]
        f = (scans[k].t - a.t) / (c.t - a.t)
        expect = a.odom[:2] + f * (c.odom[:2] - a.odom[:2])
        assert np.allclose(got[k].odom[:2], expect, atol=1e-12)
    for k in range(0, len(scans), 2):
        assert np.array_equal(got[k].odom, scans[k].odom)  # a stamp with its own transform: that pose exactly


def test_a_topic_stamped_0_throughout_is_timed_by_the_record_times(scans, tmp_path, capsys):
    # Some drivers never set header.stamp. A topic whose every stamp is 0 reads the bag's record times (here the
    # log's stamps, as a recorder would have seen them), with a note; the records are those of the stamped bag.
    # Odometry from /tf stamped 0 the same. A few zero stamps among real ones (a simulator's first messages, before
    # its clock) are stamps, not a sign: kept as 0, no note.
    def bag(name, scan_zero, odom):
        path = tmp_path / f"{name}.mcap"
        with BagOut(path) as b:
            for k, s in enumerate(scans):
                zero = 0.0 if odom in ("zero", "tf-zero") or (odom == "first-zero" and k < 2) else None
                if odom.startswith("tf"):
                    b.write("/tf", "tf2_msgs/msg/TFMessage", s.t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
                        b.transform(s.t if zero is None else zero, "odom", "base_link", s.odom)]))
                else:
                    _odom(b, s, stamp=zero)
                _laser(b, "/scan", s, frame="base_link", stamp=0.0 if scan_zero else None)
                P = "geometry_msgs/msg/PoseStamped"  # a truth topic, stamped as the scans
                b.write("/truth", P, s.t, b.msg(P, header=b.header(0.0 if scan_zero else s.t, "map"),
                                                pose=b.pose(*s.odom)))
        return open_bag(path, load_config(None, ["topics.truth=/truth"]).topics)

    assert scans[1].t > 0
    ref = bag("stamped", False, "stamped")
    assert not any("stamp is 0" in n for n in ref.notes), ref.notes
    for name, scan_zero, odom, said in (("scans", True, "stamped", ["/scan", "/truth"]),
                                        ("odom", False, "zero", ["/odom"]),
                                        ("both", True, "zero", ["/scan", "/odom", "/truth"]),
                                        ("tf", True, "tf-zero", ["/scan", "/tf odom -> base_link", "/truth"])):
        src = bag(name, scan_zero, odom)
        noted = [n.split(": ")[1] for n in src.notes if "every header stamp is 0" in n]
        assert sorted(noted) == sorted(said), (name, src.notes)
        assert np.array_equal(src.scan_stamps, ref.scan_stamps), name
        assert np.array_equal(src.truth[0], ref.truth[0]) and np.array_equal(src.truth[1], ref.truth[1]), name
        for a, g in zip(ref.scans, src.scans):
            assert a.t == g.t and np.array_equal(a.odom, g.odom), name
    few = bag("few", False, "first-zero")
    assert not any("stamp is 0" in n for n in few.notes), few.notes
    assert list(few.odometry[:3, 0]) == [0.0, 0.0, scans[2].t]
    assert main(["bag", "info", str(tmp_path / "both.mcap")]) == 0
    assert "/scan: every header stamp is 0; the bag's record times stand in for them" in capsys.readouterr().out


def _old_style_bag(path, scans, tf_type: str) -> None:
    """A ROS 1 bag as recorded before tf2: every transform on /tf (no /tf_static), the laser's mounting among them
    at every scan, frames with a leading '/', typed ``tf_type``."""
    from rosbags.typesys import get_types_from_msg

    with BagOut(path) as b:
        if tf_type not in b.ts.types:
            b.ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", tf_type))
        for s in scans:
            b.write("/tf", tf_type, s.t, b.msg(tf_type, transforms=[
                b.transform(s.t, "/odom", "/base_link", s.odom), b.transform(s.t, "/base_link", "/laser", (0.1, 0, 0))]))
            _laser(b, "/scan", s, frame="/laser")


def test_a_ros1_bag_with_tf_tfmessage_reads_as_one_with_tf2(scans, tmp_path, capsys):
    # Bags recorded before ROS Hydro (2013) carry /tf as tf/tfMessage, which has the same fields as
    # tf2_msgs/TFMessage; the reader refused them ("/tf is tf/msg/tfMessage, expected tf2_msgs/TFMessage").
    old, new = tmp_path / "old.bag", tmp_path / "new.bag"
    _old_style_bag(old, scans, "tf/msg/tfMessage")
    _old_style_bag(new, scans, "tf2_msgs/msg/TFMessage")
    a, b = open_bag(old), open_bag(new)
    assert a.odom_source == b.odom_source == "/tf odom -> base_link"
    got_a, got_b = list(a.scans), list(b.scans)
    assert len(got_a) == len(got_b) == len(scans) > 30
    for x, y, s in zip(got_a, got_b, scans):
        _same_records(x, y)
        assert np.array_equal(x.odom, s.odom) and np.allclose(x.laser_offset, (0.1, 0.0, 0.0), rtol=0, atol=1e-12)
    assert main(["bag", "info", str(old)]) == 0
    out = capsys.readouterr().out
    assert "frames in /tf: base_link -> laser, odom -> base_link" in out and "odometry:     /tf odom -> base_link" in out


def test_odometry_from_a_pose_topic_named_as_the_odometry(world, scans, tmp_path, capsys):
    # A robot_pose_ekf's odom_combined (PoseWithCovarianceStamped), no nav_msgs/Odometry and no /tf: an error that
    # names the pose topic, then the same records as odometry on /tf (the pose, no velocities) once it is named
    bag, ref = tmp_path / "ekf.mcap", tmp_path / "tf.mcap"
    topic = "/robot_pose_ekf/odom_combined"
    with BagOut(bag) as b:
        for s in scans:
            pw = b.msg("geometry_msgs/msg/PoseWithCovariance", pose=b.pose(*s.odom), covariance=np.zeros(36))
            b.write(topic, "geometry_msgs/msg/PoseWithCovarianceStamped", s.t, b.msg(
                "geometry_msgs/msg/PoseWithCovarianceStamped", header=b.header(s.t, "odom_combined"), pose=pw))
            _laser(b, "/scan", s)
    write_scans(ref, scans, odom="tf")
    _fails(capsys, tmp_path, bag, match=f"a pose topic in the odometry frame can be named with --odom-topic: {topic}")
    src = open_bag(bag, load_config(None, [f"topics.odom={topic}"]).topics)
    assert src.odom_source == f"{topic} (geometry_msgs/PoseWithCovarianceStamped)"
    for x, y in zip(src.scans, open_bag(ref).scans):
        assert np.array_equal(x.odom, y.odom) and (x.tv, x.rv) == (y.tv, y.rv) == (0.0, 0.0)
    assert main(["run", "--bag", str(bag), "--odom-topic", topic, "--map", str(world / "map.yaml"), "--out",
                 str(tmp_path / "o"), "--rerun", "off", "--no-progress", "--particles", "500"]) == 0


def test_odometry_topic_and_tf_give_the_same_records(scans, tmp_path):
    write_scans(tmp_path / "a.db3", scans, odom="topic")
    write_scans(tmp_path / "b.db3", scans, odom="tf")
    a, b = open_bag(tmp_path / "a.db3"), open_bag(tmp_path / "b.db3")
    assert a.odom_source.startswith("/odom") and b.odom_source.startswith("/tf")
    for x, y in zip(a.scans, b.scans):
        assert np.array_equal(x.odom, y.odom)


def test_laser_mounting_from_tf_static_gives_the_same_laser_poses(scans, tmp_path):
    # The laser 0.3 m ahead, 0.1 m left, turned 0.2 rad on a new base frame: the base's odometry moves, the
    # laser's own pose in the odometry frame (base ∘ mount) stays what the log says (robot ∘ its offset = robot).
    from mcl.runner import compose

    mount = (0.3, 0.1, 0.2)
    write_scans(tmp_path / "m.mcap", scans, mount=mount)
    src = open_bag(tmp_path / "m.mcap")
    got = list(src.scans)
    assert np.allclose(src.laser_offsets["/scan"], mount, atol=1e-12)
    for a, b in zip(scans, got):
        assert np.allclose(compose(b.odom, b.laser_offset), a.odom, atol=1e-9)
        assert not np.allclose(b.odom[:2], a.odom[:2], atol=0.05)


def test_an_upside_down_laser_reads_the_same_beams_as_an_upright_one(scans, tmp_path):
    # A laser rolled by pi (z down, as AMCL allows) at (0.1, -0.05) turned 0.4 rad on the base: its beam at angle a
    # points at -a, so it reports the log's scan reversed (the log's beams are symmetric about 0). Read back, each
    # record must be the log's: the same ranges and angles, and the laser's pose (odometry ∘ mounting) the same.
    from mcl.datasets.bagwrite import _compose, _inverse
    from mcl.runner import compose

    mx, my, psi = 0.1, -0.05, 0.4
    assert math.isclose(scans[0].angle_min, -(scans[0].angle_min + scans[0].angle_increment * (scans[0].ranges.size - 1)))
    bag = tmp_path / "flipped.mcap"
    with BagOut(bag) as b:
        q = b.msg("geometry_msgs/msg/Quaternion", x=math.cos(psi / 2), y=math.sin(psi / 2), z=0.0, w=0.0)  # Rz Rx(pi)
        tr = b.msg("geometry_msgs/msg/Transform", translation=b.msg("geometry_msgs/msg/Vector3", x=mx, y=my, z=0.3),
                   rotation=q)
        b.write("/tf_static", "tf2_msgs/msg/TFMessage", scans[0].t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
            b.msg("geometry_msgs/msg/TransformStamped", header=b.header(scans[0].t, "base_link"),
                  child_frame_id="laser", transform=tr)]))
        for s in scans:
            base = _compose(tuple(s.odom), _inverse((mx, my, psi)))
            _odom(b, types.SimpleNamespace(t=s.t, odom=base))
            _laser(b, "/scan", s, ranges=np.asarray(s.ranges)[::-1])
    src = open_bag(bag)
    assert any("upside down" in n for n in src.notes)
    assert np.allclose(src.laser_offsets["/scan"], (mx, my, psi), atol=1e-12)
    for a, g in zip(scans, src.scans):
        np.testing.assert_array_equal(g.ranges, a.ranges)
        assert math.isclose(g.angle_min, a.angle_min, abs_tol=1e-12) and g.angle_increment == a.angle_increment
        assert np.allclose(compose(g.odom, g.laser_offset), a.odom, atol=1e-9)


def test_nav2_frames_base_footprint_without_base_link_are_found_with_a_note(scans, tmp_path):
    # nav2 robots move base_footprint: odometry on /tf as odom -> base_footprint and the laser hanging off it, no
    # base_link at all. With the default frames (base_link) the bag is read through base_footprint, saying so; the
    # records are the log's (same odometry, the laser 0.2 m ahead composed back to the log's pose).
    from mcl.datasets.bagwrite import _compose, _inverse
    from mcl.runner import compose

    mount = (0.2, 0.0, 0.0)
    for odom in ("tf", "topic"):
        bag = tmp_path / f"nav2-{odom}.mcap"
        with BagOut(bag) as b:
            b.write("/tf_static", "tf2_msgs/msg/TFMessage", scans[0].t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
                b.transform(scans[0].t, "base_footprint", "base_scan", mount)]))
            for s in scans:
                base = _compose(tuple(s.odom), _inverse(mount))
                if odom == "tf":
                    b.write("/tf", "tf2_msgs/msg/TFMessage", s.t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
                        b.transform(s.t, "odom", "base_footprint", base)]))
                else:
                    _odom(b, s, child="base_footprint", pose=base)
                _laser(b, "/scan", s, frame="base_scan")
        src = open_bag(bag)
        assert any("base_footprint" in n for n in src.notes), src.notes
        assert src.odom_source == ("/tf odom -> base_footprint" if odom == "tf" else "/odom (nav_msgs/Odometry)")
        assert np.allclose(src.laser_offsets["/scan"], mount, atol=1e-12), odom
        for a, g in zip(scans, src.scans):
            assert np.allclose(compose(g.odom, g.laser_offset), a.odom, atol=1e-9)


def test_odometry_under_another_name_is_the_transform_that_moves_the_laser(scans, tmp_path, capsys):
    # A robot_pose_ekf robot of the tf era: /tf holds map -> odom_combined (a localizer's correction, moving too),
    # odom_combined -> base_footprint (the odometry), and the fixed links base_footprint -> base_link ->
    # base_laser_link repeated on /tf (no /tf_static before ROS Indigo). No odom frame: with the default frames the
    # lowest moving link above the laser is the odometry, with a note; the records are the log's.
    from mcl.datasets.bagwrite import _compose, _inverse
    from mcl.runner import compose

    up, mount = (0.0, 0.0, 0.0), (0.25, -0.05, 0.1)
    bag = tmp_path / "ekf.mcap"
    with BagOut(bag) as b:
        for k, s in enumerate(scans):
            base = _compose(tuple(s.odom), _inverse(mount))
            b.write("/tf", "tf2_msgs/msg/TFMessage", s.t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
                b.transform(s.t, "map", "odom_combined", (0.01 * k, 0.0, 0.002 * k)),
                b.transform(s.t, "odom_combined", "base_footprint", base),
                b.transform(s.t, "base_footprint", "base_link", up),
                b.transform(s.t, "base_link", "base_laser_link", mount)]))
            _laser(b, "/base_scan", s, frame="base_laser_link")
    src = open_bag(bag)
    assert src.odom_source == "/tf odom_combined -> base_footprint"
    assert any("the odometry is odom_combined -> base_footprint, the transform that moves base_laser_link" in n
               for n in src.notes), src.notes
    assert np.allclose(src.laser_offsets["/base_scan"], mount, atol=1e-12)
    for a, g in zip(scans, src.scans):
        assert np.allclose(compose(g.odom, g.laser_offset), a.odom, atol=1e-9)
    # A frame the user names is not second-guessed.
    _fails(capsys, tmp_path, bag, "--base-frame", "base_footprint",
           match="/tf: the transform odom -> base_footprint never appears")


def _namespaced_bag(path, scans, robots, mount=(0.2, 0.0, 0.0)):
    """Odometry on /tf as R/odom -> R/base_link for each robot R of ``robots`` (multi-robot namespaces), the laser
    R/laser on /tf_static, the scans from the first robot's laser."""
    from mcl.datasets.bagwrite import _compose, _inverse

    with BagOut(path) as b:
        b.write("/tf_static", "tf2_msgs/msg/TFMessage", scans[0].t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
            b.transform(scans[0].t, f"{r}/base_link", f"{r}/laser", mount) for r in robots]))
        for s in scans:
            base = _compose(tuple(s.odom), _inverse(mount))
            b.write("/tf", "tf2_msgs/msg/TFMessage", s.t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
                b.transform(s.t, f"{r}/odom", f"{r}/base_link", base) for r in robots]))
            _laser(b, "/scan", s, frame=f"{robots[0]}/laser")


def test_namespaced_frames_of_one_robot_are_found_with_a_note(scans, tmp_path, capsys):
    # A multi-robot namespace (robot1/odom -> robot1/base_link, robot1/laser): with the default frames the bag was
    # refused ("the transform odom -> base_link never appears"); one robot's namespaced pair is used, saying so, and
    # the records are the log's. Two robots: which one is not guessed, the one line lists the transforms.
    from mcl.runner import compose

    bag = tmp_path / "ns.mcap"
    _namespaced_bag(bag, scans, ["robot1"])
    src = open_bag(bag)
    assert src.odom_source == "/tf robot1/odom -> robot1/base_link"
    assert any("the odometry is robot1/odom -> robot1/base_link" in n for n in src.notes), src.notes
    assert np.allclose(src.laser_offsets["/scan"], (0.2, 0.0, 0.0), atol=1e-12)
    for a, g in zip(scans, src.scans):
        assert np.allclose(compose(g.odom, g.laser_offset), a.odom, atol=1e-9)
    two = tmp_path / "two.mcap"
    _namespaced_bag(two, scans, ["robot1", "robot2"])
    _fails(capsys, tmp_path, two, match="the transform odom -> base_link never appears (it has: robot1/odom -> "
                                        "robot1/base_link, robot2/odom -> robot2/base_link)")
    src = open_bag(two, frames=load_config(None, ["frames.odom=robot2/odom", "frames.base=robot2/base_link"]).frames)
    assert src.odom_source == "/tf robot2/odom -> robot2/base_link"


def _tf_into_namespace(plain, moved) -> None:
    """``plain`` copied into the rosbag2 folder ``moved`` with /tf and /tf_static remapped to /robot1/tf and
    /robot1/tf_static, as a multi-robot recording has them."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer

    with AnyReader([plain]) as r:
        w = Writer(moved, version=9, storage_plugin=StoragePlugin.MCAP)
        w.open()
        conns = {c.id: w.add_connection("/robot1" + c.topic if c.topic.startswith("/tf") else c.topic, c.msgtype,
                                        typestore=r.typestore) for c in r.connections}
        for c, t, raw in r.messages():
            w.write(conns[c.id], t, raw)
        w.close()


def test_transform_topics_remapped_into_a_namespace_are_read(scans, tmp_path, capsys):
    # A multi-robot recording remaps /tf and /tf_static into the robot's namespace (/robot1/tf): they were not
    # read (no odometry, no mounting). One namespace's are read as /tf and /tf_static, with a note.
    plain, moved = tmp_path / "plain.mcap", tmp_path / "moved"
    write_scans(plain, scans, odom="tf", mount=(0.2, 0.0, 0.0))
    _tf_into_namespace(plain, moved)
    a, b = open_bag(plain), open_bag(moved)
    assert b.odom_source == "/robot1/tf odom -> base_link" and a.odom_source == "/tf odom -> base_link"
    assert any("the transforms are on /robot1/tf and /robot1/tf_static" in n for n in b.notes), b.notes
    for x, y in zip(a.scans, b.scans):
        _same_records(x, y)
    assert main(["bag", "info", str(moved)]) == 0
    assert "frames in /tf: odom -> base_link" in capsys.readouterr().out
    assert b.tf_topic == "/robot1/tf" and a.tf_topic == "/tf"


def test_the_estimate_bag_of_a_namespaced_recording_publishes_in_its_namespace(world, scans, tmp_path):
    # transforms on /robot1/tf (a multi-robot recording): --write-bag wrote /tf, /amcl_pose and /particlecloud at
    # the root, where an RViz set up for /robot1/tf sees nothing; a namespaced AMCL publishes them under /robot1
    from rosbags.highlevel import AnyReader

    plain, moved = tmp_path / "plain.mcap", tmp_path / "moved"
    write_scans(plain, scans, odom="tf", mount=(0.2, 0.0, 0.0))
    _tf_into_namespace(plain, moved)
    topics = {}
    for name, bag in (("root", plain), ("ns", moved)):
        out = tmp_path / name
        cfg = load_config(None, ["rerun.mode=off", "filter.particles=300", f"map={world / 'map.yaml'}", "log=null",
                                 f"bag={bag}", "truth=null"])
        run(cfg, out, progress=False, echo=_quiet, write_bag=True)
        with AnyReader([next(out.glob("estimate.*"))]) as r:
            topics[name] = sorted(c.topic for c in r.connections)
    assert topics["root"] == ["/amcl_pose", "/particlecloud", "/tf"]
    assert topics["ns"] == ["/robot1/amcl_pose", "/robot1/particlecloud", "/robot1/tf"]


def test_among_several_namespaces_transform_topics_the_scan_topics_robot_is_read(scans, tmp_path, capsys):
    # Two robots, each with its own remapped /robotN/tf and /robotN/tf_static and no /tf: none was read (no
    # odometry). The scan topic chosen (/robot2/scan) picks its namespace; with nothing to choose by, one line
    # names the namespaces.
    from mcl.datasets.bagwrite import _compose, _inverse

    mount = (0.2, 0.0, 0.0)

    def write(path, scan_topics):
        with BagOut(path) as b:
            for r in ("robot1", "robot2"):
                b.write(f"/{r}/tf_static", "tf2_msgs/msg/TFMessage", scans[0].t,
                        b.msg("tf2_msgs/msg/TFMessage", transforms=[b.transform(scans[0].t, "base_link", "laser",
                                                                                mount)]))
            for s in scans:
                base = _compose(tuple(s.odom), _inverse(mount))
                for r, dx in (("robot1", 0.0), ("robot2", 1.0)):  # robot2's odometry 1 m further along x
                    b.write(f"/{r}/tf", "tf2_msgs/msg/TFMessage", s.t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
                        b.transform(s.t, "odom", "base_link", (base[0] + dx, base[1], base[2]))]))
                for topic in scan_topics:
                    _laser(b, topic, s)

    two = tmp_path / "two.mcap"
    write(two, ["/robot1/scan", "/robot2/scan"])
    src = open_bag(two, topics=load_config(None, ["topics.scan=/robot2/scan"]).topics)
    assert src.odom_source == "/robot2/tf odom -> base_link"
    assert np.allclose(src.laser_offsets["/robot2/scan"], mount, atol=1e-12)
    first = open_bag(two, topics=load_config(None, ["topics.scan=/robot1/scan"]).topics)
    assert first.odom_source == "/robot1/tf odom -> base_link"
    for a, b in zip(first.scans, src.scans):
        assert np.allclose(np.subtract(b.odom[:2], a.odom[:2]), (1.0, 0.0), atol=1e-9)
    shared = tmp_path / "shared.mcap"
    write(shared, ["/scan"])
    _fails(capsys, tmp_path, shared, match="no /tf, and transforms of several namespaces (/robot1, /robot2): "
                                           "choose the robot")
    assert main(["bag", "info", str(two)]) == 0
    assert "frames in /tf: odom -> base_link" in capsys.readouterr().out


def test_a_laser_without_transform_falls_back_with_a_warning(scans, tmp_path):
    bag = tmp_path / "nostatic.bag"
    with BagOut(bag) as b:
        for s in scans:
            _odom(b, s)
            _laser(b, "/scan", s)
    src = open_bag(bag)
    assert src.laser_offsets["/scan"] is None
    assert any("base_link -> laser" in w and "robot centre" in w and "sensor.laser_pose" in w for w in src.warnings)
    src = open_bag(bag, laser_pose=(0.1, 0.0, 3.14))  # given: a note that it is used
    assert any("base_link -> laser" in n and "sensor.laser_pose [0.1, 0.0, 3.14]" in n for n in src.notes)


def test_several_lasers_fused_each_with_its_mounting(scans, tmp_path):
    bag = tmp_path / "two.mcap"
    with BagOut(bag) as b:
        b.write("/tf_static", "tf2_msgs/msg/TFMessage", scans[0].t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
            b.transform(scans[0].t, "base_link", "front", (0.2, 0.0, 0.0)),
            b.transform(scans[0].t, "base_link", "mount", (-0.2, 0.0, 0.0)),
            b.transform(scans[0].t, "mount", "rear", (0.0, 0.1, 3.0))]))
        for s in scans:
            _odom(b, s)
            _laser(b, "/front/scan", s, frame="front")
            _laser(b, "/rear/scan", s, frame="rear")
    # auto: two lasers mounted level and fixed at one height (an AGV's front and rear) are fused, with a note, as
    # topics.scan: all does
    auto = open_bag(bag)
    assert auto.scans.topics == ["/front/scan", "/rear/scan"] and len(auto.scans) == 2 * len(scans)
    assert any("/front/scan, /rear/scan are mounted level and fixed at one height: fused" in n for n in auto.notes)
    cfg = load_config(None, ["topics.scan=all"])
    src = open_bag(bag, cfg.topics, cfg.frames)
    assert not any("fused" in n for n in src.notes)
    got = list(src.scans)
    assert len(got) == 2 * len(scans)
    front = [g for g in got if g.kind == "/front/scan"]
    rear = [g for g in got if g.kind == "/rear/scan"]
    assert len(front) == len(rear) == len(scans)
    assert np.allclose(front[0].laser_offset, (0.2, 0, 0))
    assert np.allclose(rear[0].laser_offset, (-0.2, 0.1, 3.0))  # through the chain base_link -> mount -> rear
    one = open_bag(bag, load_config(None, ["topics.scan=/rear/scan"]).topics)
    assert one.scans.topics == ["/rear/scan"] and len(one.scans) == len(scans)


def test_fused_lasers_each_update_once_the_robot_has_moved(world, scans, tmp_path):
    # Update gating per laser, as AMCL's flags: once the robot has moved, each laser updates once. The rear scan,
    # stamped with the front's, saw no motion since the front's update, and was always gated (it never weighed in).
    bag = tmp_path / "two.mcap"
    with BagOut(bag) as b:
        b.write("/tf_static", "tf2_msgs/msg/TFMessage", scans[0].t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
            b.transform(scans[0].t, "base_link", "front", (0.0, 0.0, 0.0)),
            b.transform(scans[0].t, "base_link", "rear", (0.0, 0.0, 0.0))]))
        for s in scans:
            _odom(b, s)
            _laser(b, "/front/scan", s, frame="front")
            _laser(b, "/rear/scan", s, frame="rear")
    one, _ = _run(tmp_path, "one", map=world / "map.yaml", bag=bag, **{"topics.scan": "/front/scan"})
    both, out = _run(tmp_path, "both", map=world / "map.yaml", bag=bag, **{"topics.scan": "all"})
    assert 10 < one["updates"] < len(scans)  # the gating skips some scans of the one laser
    assert both["updates"] == 2 * one["updates"]
    assert len((out / "trajectory.tum").read_text().splitlines()) == 2 * len(scans)  # still one pose per scan


@pytest.mark.parametrize("source", ["tf", "topic"])
def test_the_mounting_is_on_the_frame_the_odometry_moves(scans, tmp_path, source):
    # The odometry moves base_footprint (on /tf, or an Odometry whose child_frame_id says so), and the laser hangs
    # off base_link 0.15 m ahead of it: the laser is 0.25 m ahead of the pose the odometry gives, not 0.1 m (the
    # base_link -> laser link alone, which the reader took).
    bag = tmp_path / f"footprint-{source}.mcap"
    TF = "tf2_msgs/msg/TFMessage"
    with BagOut(bag) as b:
        b.write("/tf_static", TF, scans[0].t, b.msg(TF, transforms=[
            b.transform(scans[0].t, "base_footprint", "base_link", (0.15, 0.0, 0.0)),
            b.transform(scans[0].t, "base_link", "laser", (0.1, 0.0, 0.0))]))
        for s in scans:
            if source == "tf":
                b.write("/tf", TF, s.t, b.msg(TF, transforms=[b.transform(s.t, "odom", "base_footprint", s.odom)]))
            else:
                _odom(b, s, child="base_footprint")
            _laser(b, "/scan", s, frame="laser")
    src = open_bag(bag)
    assert np.allclose(src.scans.offsets["/scan"], (0.25, 0.0, 0.0), rtol=0, atol=1e-9)
    assert any("mounted as base_footprint -> laser (the frame the odometry moves)" in n for n in src.notes)


def test_a_gap_in_the_odometry_is_filled_by_matching_the_scans(world, scans, tmp_path):
    # /odom stops for 4 s while the scans go on (a driver that died and came back). Interpolated, the odometry ran a
    # straight line across, 0.46 m off the robot's path mid-turn; the scans inside are matched one to the next from
    # the last scan before the gap, and the odometry after it keeps its own steps.
    t0 = scans[0].t
    gone = [2.0 <= s.t - t0 <= 6.0 for s in scans]
    bag = tmp_path / "gap.mcap"
    with BagOut(bag) as b:
        for s, g in zip(scans, gone):
            if not g:
                _odom(b, s)
            _laser(b, "/scan", s, frame="base_link")
    src = open_bag(bag)
    assert any("stops while the scans go on, 1 time, for up to 4.4 s" in w and "21 scans of /scan" in w
               and "laser odometry" in w for w in src.warnings)
    tt, tp = read_tum(world / "truth.tum")
    truth = {round(t, 6): tp[:, i] for i, t in enumerate(tt)}
    kept = np.array([(s.t, *s.odom, 0.0, 0.0) for s, g in zip(scans, gone) if not g])
    k0 = gone.index(True) - 1  # the last scan before the gap
    base, base_truth = odometry_at(src.odometry, scans[k0].t)[0], truth[round(scans[k0].t, 6)]
    filled, straight = [], []
    for s in [s for s, g in zip(scans, gone) if g]:
        want = compose(inverse(base_truth), truth[round(s.t, 6)])
        filled.append(np.hypot(*(compose(inverse(base), odometry_at(src.odometry, s.t)[0]) - want)[:2]))
        straight.append(np.hypot(*(compose(inverse(scans[k0].odom), odometry_at(kept, s.t)[0]) - want)[:2]))
    # measured 0.076 m at most (the wheel odometry itself: 0.090 m); the straight line 0.46 m
    assert max(filled) < 0.12 and max(straight) > 0.3
    # after the gap, the odometry's own steps
    after = [s for s in scans if s.t - t0 > 6.2]
    for s in after[1:]:
        got = compose(inverse(odometry_at(src.odometry, after[0].t)[0]), odometry_at(src.odometry, s.t)[0])
        assert np.allclose(got, compose(inverse(after[0].odom), s.odom), rtol=0, atol=1e-9)


def test_among_several_lasers_the_level_fixed_one_is_read(world, scans, tmp_path, capsys):
    # A PR2: /base_scan on a fixed level mount, /tilt_scan on a frame that pitches up and down on /tf (a tilting
    # laser sweeps the floor and over the walls); and a laser fixed looking 30 degrees down at the floor. With no
    # /scan, auto reads /base_scan alone, with a note naming why the others are not read; the run matches one
    # with --scan-topic /base_scan to the byte.
    bag = tmp_path / "pr2.bag"
    with BagOut(bag) as b:
        t0 = scans[0].t
        b.write("/tf_static", "tf2_msgs/msg/TFMessage", t0, b.msg("tf2_msgs/msg/TFMessage", transforms=[
            _tilted(b, t0, "base_link", "base_laser_link", (0.1, 0.0, 0.3), 0.0),
            _tilted(b, t0, "base_link", "floor_laser", (0.2, 0.0, 0.5), math.radians(30.0))]))
        for k, s in enumerate(scans):
            _odom(b, s)
            b.write("/tf", "tf2_msgs/msg/TFMessage", s.t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
                _tilted(b, s.t, "base_link", "tilt_mount", (0.0, 0.0, 1.0), 0.0),
                _tilted(b, s.t, "tilt_mount", "laser_tilt_link", (0.1, 0.0, 0.0), 0.6 * math.sin(k))]))
            _laser(b, "/base_scan", s, frame="base_laser_link")
            _laser(b, "/tilt_scan", s, frame="laser_tilt_link")
            _laser(b, "/floor_scan", s, frame="floor_laser")
    src = open_bag(bag)
    assert src.scans.topics == ["/base_scan"] and len(src.scans) == len(scans)
    assert np.allclose(src.laser_offsets["/base_scan"], (0.1, 0.0, 0.0))
    note = next(n for n in src.notes if "several laser topics" in n)
    assert "/base_scan is the one mounted level and fixed" in note
    assert "/tilt_scan: laser_tilt_link moves on /tf" in note and "/floor_scan: tilted 30 deg from level" in note
    s_auto, o_auto = _run(tmp_path, "auto", map=world / "map.yaml", bag=bag)
    s_one, o_one = _run(tmp_path, "one", map=world / "map.yaml", bag=bag, **{"topics.scan": "/base_scan"})
    assert s_auto["updates"] == s_one["updates"] > 30
    assert (o_auto / "trajectory.tum").read_bytes() == (o_one / "trajectory.tum").read_bytes()


def test_a_mounting_quaternion_of_norm_0_is_read_as_no_rotation(scans, tmp_path):
    # A broken robot description's zero quaternion on one of several lasers' links raised scipy's ValueError (a
    # traceback) while the lasers were told apart; it is read as no rotation, as the planar mounting reads it.
    bag = tmp_path / "zeroq.mcap"
    with BagOut(bag) as b:
        zero = _tilted(b, scans[0].t, "base_link", "rear", (-0.2, 0.0, 0.2), 0.0)
        zero.transform.rotation.w = 0.0
        b.write("/tf_static", "tf2_msgs/msg/TFMessage", scans[0].t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
            _tilted(b, scans[0].t, "base_link", "front", (0.2, 0.0, 0.2), 0.0), zero]))
        for s in scans[:3]:
            _odom(b, s)
            _laser(b, "/front/scan", s, frame="front")
            _laser(b, "/rear/scan", s, frame="rear")
    assert open_bag(bag).scans.topics == ["/front/scan", "/rear/scan"]


def test_several_lasers_on_one_frame_stop_with_one_line_asking_to_choose(scans, tmp_path, capsys):
    # The same laser's raw and filtered scans (one frame): no way to tell which to read.
    bag = tmp_path / "rawfiltered.mcap"
    with BagOut(bag) as b:
        for s in scans[:3]:
            _odom(b, s)
            _laser(b, "/base_scan_raw", s, frame="base_link")
            _laser(b, "/base_scan", s, frame="base_link")
    err = _fails(capsys, tmp_path, bag, match="several scan topics (/base_scan: level; /base_scan_raw: level); "
                                              "choose one with --scan-topic")
    assert "topics.scan: all" in err


def test_laser_scan_no_return_and_invalid_readings(scans, tmp_path):
    # REP 117: +inf is no return -> range_max (a no-return reading, as in a CARMEN log); NaN, -inf and readings
    # below range_min are not readings -> 0 (never valid).
    s = scans[0]
    bag = tmp_path / "inf.mcap"
    r = np.array([1.5, np.inf, np.nan, -np.inf, 0.05, 2.25], dtype=np.float32)
    with BagOut(bag) as b:
        _odom(b, s)
        _laser(b, "/scan", s, ranges=r, range_min=0.1)
    (got,) = list(open_bag(bag).scans)
    assert got.ranges.tolist() == [1.5, s.max_range, 0.0, 0.0, 0.0, 2.25]
    # A range_min that is not a number says nothing: every reading above 0 counts (it dropped every reading).
    nan_min = tmp_path / "nanmin.mcap"
    with BagOut(nan_min) as b:
        _odom(b, s)
        _laser(b, "/scan", s, ranges=r, range_min=math.nan)
    (got,) = list(open_bag(nan_min).scans)
    assert got.ranges.tolist() == [1.5, s.max_range, 0.0, 0.0, 0.05, 2.25]


def test_a_laser_mounting_that_is_not_finite_stops_with_one_line(scans, tmp_path, capsys):
    bag = tmp_path / "nanmount.mcap"
    with BagOut(bag) as b:
        b.write("/tf_static", "tf2_msgs/msg/TFMessage", scans[0].t, b.msg("tf2_msgs/msg/TFMessage", transforms=[
            b.transform(scans[0].t, "base_link", "laser", (math.nan, 0.0, 0.0))]))
        for s in scans[:3]:
            _odom(b, s)
            _laser(b, "/scan", s)
    _fails(capsys, tmp_path, bag, match="/scan: the transform base_link -> laser is not finite")


def test_a_scan_that_does_not_say_where_its_beams_point(world, scans, tmp_path, capsys):
    # A broken driver's message: angle_increment 0 (every beam one way) or a NaN angle. One such scan among good
    # ones is read without a reading (the update only predicts, one pose per scan kept), with a warning counting
    # them; a topic of nothing else stops with one line.
    def bag(name, bad):
        path = tmp_path / f"{name}.mcap"
        with BagOut(path) as b:
            for k, s in enumerate(scans):
                _odom(b, s)
                g = s
                if bad(k):  # every beam one way, or a NaN first angle
                    g = dataclasses.replace(s, **({"angle_min": math.nan} if k % 2 else {"angle_increment": 0.0}))
                _laser(b, "/scan", g, frame="base_link")
        return path

    some = bag("some", lambda k: k in (5, 6))
    src = open_bag(some)
    assert src.warnings == [f"{some}: /scan: 2 of {len(scans)} scans do not say where their beams point (angle_min "
                            "or angle_increment not finite, or angle_increment 0): read without a reading, the "
                            "update only predicts"]
    got = list(src.scans)
    assert [k for k, g in enumerate(got) if not np.any(g.ranges > 0)] == [5, 6]
    assert np.array_equal(got[7].ranges, scans[7].ranges)
    summary, _ = _run(tmp_path, "r", map=world / "map.yaml", bag=some)
    assert summary["scans"] == len(scans) and summary["events"]["empty_scans"] == 2
    _fails(capsys, tmp_path, bag("all", lambda k: True), match="/scan: no message says where its beams point")


@pytest.mark.parametrize("kind", ["bag1", "mcap"])
def test_a_multi_echo_laser_reads_one_echo_per_beam(world, scans, tmp_path, kind):
    # A SICK LMS5xx's or Hokuyo UTM-30LX-EW's driver: sensor_msgs/MultiEchoLaserScan, each beam's returns nearest
    # first. Here each beam's first echo is the log's reading, every third beam has a second one 2.5 m farther (the
    # wall behind a pane of glass), every tenth none (not a reading). The only laser topic, named /echoes, is found;
    # topics.echo: first (the default) reads exactly what a LaserScan of the first echoes reads, to the trajectory;
    # last reads the far returns.
    n = scans[0].ranges.size
    far, none = np.arange(n) % 3 == 0, np.arange(n) % 10 == 0
    plain, multi = tmp_path / f"plain.{KINDS[kind]}", tmp_path / f"multi.{KINDS[kind]}"
    with BagOut(plain) as a, BagOut(multi) as b:
        for s in scans:
            first = np.where(none, np.nan, s.ranges).astype(np.float32)
            _odom(a, s)
            _laser(a, "/scan", s, ranges=first)
            _odom(b, s)
            _echoes(b, "/echoes", s, [[] if no else ([r, r + 2.5] if f else [r])
                                      for r, f, no in zip(s.ranges.astype(np.float32), far, none)])
    want = list(open_bag(plain).scans)
    src = open_bag(multi)
    assert src.scans.topics == ["/echoes"]
    got = list(src.scans)
    assert len(got) == len(want) == len(scans)
    for g, w in zip(got, want):
        _same_records(g, w)
    assert not np.any(got[0].ranges[none]) and np.all(got[0].ranges[~none] > 0)
    last = list(open_bag(multi, load_config(None, ["topics.echo=last"]).topics).scans)
    for g, s in zip(last, scans):
        assert np.array_equal(g.ranges[~far & ~none], s.ranges[~far & ~none])
        assert np.allclose(g.ranges[far & ~none], s.ranges[far & ~none] + 2.5, rtol=0, atol=1e-5)
    s_plain, o_plain = _run(tmp_path, "plain", map=world / "map.yaml", bag=plain)
    s_multi, o_multi = _run(tmp_path, "multi", map=world / "map.yaml", bag=multi)
    assert s_multi["updates"] == s_plain["updates"] > 30
    assert (o_multi / "trajectory.tum").read_bytes() == (o_plain / "trajectory.tum").read_bytes()


def test_pointcloud_is_projected_within_the_height_band(scans, tmp_path):
    s = scans[0]
    pts = np.array([[2.0, 0.0, 0.0], [1.0, 0.0, 0.05], [0.0, 3.0, 0.0], [0.0, 0.5, 1.0], [-1.0, -1.0, -0.05]],
                   dtype=np.float32)  # the nearest in-band point per bearing; (0, 0.5) lies above the band
    bag = tmp_path / "cloud.mcap"
    with BagOut(bag) as b:
        _odom(b, s)
        F = "sensor_msgs/msg/PointField"
        fields = [b.msg(F, name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]
        b.write("/points", "sensor_msgs/msg/PointCloud2", s.t, b.msg(
            "sensor_msgs/msg/PointCloud2", header=b.header(s.t, "base_link"), height=1, width=len(pts),
            fields=fields, is_bigendian=False, point_step=12, row_step=12 * len(pts),
            data=np.frombuffer(pts.tobytes(), dtype=np.uint8), is_dense=True))
    cfg = load_config(None, ["topics.cloud_beams=8"])
    (got,) = list(open_bag(bag, cfg.topics).scans)
    # each beam at its bin's centre (at the bin's lower edge the headings were half a bin off)
    assert got.angle_min == pytest.approx(-math.pi + math.pi / 8) and got.angle_increment == pytest.approx(math.pi / 4)
    # bins of 45 degrees from -180: 0 deg -> bin 4, 90 deg -> bin 6, -135 deg -> bin 1
    expect = np.zeros(8)
    expect[4], expect[6], expect[1] = 1.0, 3.0, round(math.sqrt(2.0), 5)
    assert np.allclose(got.ranges, expect, atol=1e-6)


# ----------------------------------------------------------------------------- map, initial pose, truth


def test_map_initial_pose_and_truth_from_the_bag(world, scans, tmp_path):
    grid = load_map(world / "map.yaml")
    truth = read_tum(world / "truth.tum")
    start = truth[1][:, 0]
    cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.0], [0.0, 0.0, 0.0025]])
    bag = tmp_path / "all.mcap"
    write_scans(bag, scans, grid=grid, initial=(start, cov), truth=truth)
    src = open_bag(bag, load_config(None, ["topics.truth=/ground_truth"]).topics)
    assert np.array_equal(src.grid.occupancy, grid.occupancy)
    assert (src.grid.resolution, src.grid.origin) == (grid.resolution, grid.origin)
    assert np.allclose(src.initial_pose[0], start, atol=1e-12) and np.allclose(src.initial_pose[1], cov)
    assert np.array_equal(src.truth[0], truth[0]) and np.allclose(src.truth[1], truth[1], atol=1e-12)
    # A run with no --map and no --initial-pose: the bag's map, tracking from /initialpose, scored on its truth.
    summary, _ = _run(tmp_path, "r", map="null", bag=bag, **{"topics.truth": "/ground_truth"})
    assert summary["mode"] == "tracking"
    assert summary["eval"]["ate_rmse"] < 0.15  # 8 s of tracking from the true pose; measured 0.05


@pytest.mark.parametrize("ext", ["mcap", "bag"])
def test_the_truth_is_recorded_at_its_own_times_among_the_scans(world, scans, tmp_path, ext):
    # /ground_truth was written after every scan: a bag's record times only go forward, so each pose was recorded at
    # the bag's end (`ros2 bag play` would send them all at once). Now each at its stamp, among the scans.
    from rosbags.highlevel import AnyReader

    truth = read_tum(world / "truth.tum")
    bag = tmp_path / f"t.{ext}"
    write_scans(bag, scans, truth=truth)
    with AnyReader([bag]) as r:
        conn = [c for c in r.connections if c.topic == "/ground_truth"]
        rows = [(ts, r.deserialize(raw, c.msgtype).header.stamp) for c, ts, raw in r.messages(connections=conn)]
    assert len(rows) == truth[0].size
    for ts, st in rows:  # (a ROS 1 bag records nothing before ros::TIME_MIN, 1 ns: the pose at t = 0 there)
        assert ts == max(st.sec * 10**9 + st.nanosec, 1 if ext == "bag" else 0), (ts, st)


@pytest.mark.parametrize("ext", ["bag", "mcap", "db3"])
def test_map_and_tf_static_are_written_latched(world, scans, tmp_path, ext):
    # no topic was marked latched (ROS 1) or transient-local (ROS 2): played back, the one /map and /tf_static
    # message reached only the subscribers of that instant (amcl or RViz started later never got the map)
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import QosDurability

    bag = tmp_path / f"l.{ext}"
    write_scans(bag, scans, grid=load_map(world / "map.yaml"))
    with AnyReader([bag]) as r:
        ext_of = {c.topic: c.ext for c in r.connections}
    for topic in ("/map", "/tf_static", "/scan"):
        e = ext_of[topic]
        kept = (e.latching == 1 if ext == "bag" else
                bool(e.offered_qos_profiles) and e.offered_qos_profiles[0].durability == QosDurability.TRANSIENT_LOCAL)
        assert kept == (topic != "/scan"), (topic, e)


@pytest.mark.parametrize("ext", ["mcap", "db3"])
def test_a_ros2_bags_own_metadata_names_its_file(scans, tmp_path, ext):
    # the rosbag2 metadata a written .mcap / .db3 carries listed `out.mcap` (the temporary name) as its file
    bag = tmp_path / f"run-7.{ext}"
    write_scans(bag, scans)
    data = bag.read_bytes()
    assert f"run-7.{ext}".encode() in data and f"out.{ext}".encode() not in data


def test_a_bag_recorded_while_mapping_gives_its_last_map(world, scans, tmp_path):
    # SLAM (gmapping, slam_toolbox) publishes /map again as it grows: the first is a corner of the building, the
    # last the whole of it. The last is used, with a note.
    from mcl.datasets.bagwrite import _write_grid
    from mcl.maps import OccupancyGrid

    grid = load_map(world / "map.yaml")
    h, w = grid.occupancy.shape
    part = OccupancyGrid.from_occupancy(grid.occupancy[: h // 2, : w // 3].copy(), grid.resolution, grid.origin)
    bag = tmp_path / "slam.mcap"
    with BagOut(bag) as b:
        for k, s in enumerate(scans):
            if k in (0, 20):
                _write_grid(b, part, s.t)
            if k == 30:
                _write_grid(b, grid, s.t)
            _odom(b, s)
            _laser(b, "/scan", s, frame="base_link")
    src = open_bag(bag)
    assert np.array_equal(src.grid.occupancy, grid.occupancy)
    assert f"/map: 3 maps (one being built?); the last, {w} x {h} cells, is used" in " ".join(src.notes)


def test_a_bag_map_with_a_rotated_origin_is_turned_onto_the_axes(world, scans, tmp_path):
    # /map's origin turned by a quarter turn about its first cell: the grid read is the array turned (exactly), its
    # corner where the turn puts it; it was refused ("a rotated map origin is not supported")
    grid = load_map(world / "map.yaml")
    h, w = grid.occupancy.shape
    bag = tmp_path / "turned.mcap"
    with BagOut(bag) as b:
        s = scans[0]
        info = b.msg("nav_msgs/msg/MapMetaData", map_load_time=b.header(s.t, "map").stamp,
                     resolution=float(grid.resolution), width=w, height=h, origin=b.pose(1.0, 2.0, math.pi / 2))
        b.write("/map", "nav_msgs/msg/OccupancyGrid", s.t, b.msg(
            "nav_msgs/msg/OccupancyGrid", header=b.header(s.t, "map"), info=info,
            data=np.ascontiguousarray(grid.occupancy, dtype=np.int8).ravel()))
        for s in scans:
            b.write("/odom", "nav_msgs/msg/Odometry", s.t, b.msg(
                "nav_msgs/msg/Odometry", header=b.header(s.t, "odom"), child_frame_id="base_link",
                pose=b.msg("geometry_msgs/msg/PoseWithCovariance", pose=b.pose(*s.odom), covariance=np.zeros(36)),
                twist=b.msg("geometry_msgs/msg/TwistWithCovariance", twist=b.msg(
                    "geometry_msgs/msg/Twist", linear=b.msg("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0),
                    angular=b.msg("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0)), covariance=np.zeros(36))))
            _laser(b, "/scan", s)
    src = open_bag(bag)
    got = src.grid
    assert any(f"/map: origin yaw {math.pi / 2:g} rad: the map is turned about its first cell" in n for n in src.notes)
    # a quarter turn counter-clockwise: cell (row i, column j) goes to (j, h - 1 - i); the corner to (1 - h res, 2)
    np.testing.assert_array_equal(got.occupancy, np.rot90(grid.occupancy, -1))
    assert got.occupancy[3, h - 1 - 5] == grid.occupancy[5, 3]
    assert got.origin == pytest.approx((1.0 - h * grid.resolution, 2.0), abs=1e-9)


def test_an_initial_pose_in_another_frame_than_the_maps_is_not_used(world, scans, tmp_path):
    # RViz publishes /initialpose in its Fixed Frame, often odom before localization runs: such a pose is no place on
    # the map, and was taken as one (the filter started wherever the odometry's origin lies). As AMCL: not used, a
    # warning naming the frame. In "map", or with no frame (a hand-made message), it is used; with a /map in the bag,
    # that map's frame is the map frame.
    grid = load_map(world / "map.yaml")
    start = (5.0, 5.0, 0.0)
    for frame, grid_in_bag, used in (("odom", None, False), ("/base_link", None, False), ("map", None, True),
                                     ("/map", None, True), ("", None, True), ("world", grid, False)):
        bag = tmp_path / f"i{len(frame)}{grid_in_bag is not None}.mcap"
        write_scans(bag, scans, grid=grid_in_bag, initial=(start, np.eye(3) * 0.01), initial_frame=frame)
        src = open_bag(bag)
        assert (src.initial_pose is not None) == used, frame
        said = [w for w in src.warnings if "/initialpose" in w]
        if used:
            assert not said and np.allclose(src.initial_pose[0], start)
        else:
            assert len(said) == 1 and f"in frame {frame.lstrip('/')!r}, not the map's ('map'): not used" in said[0]


def test_initial_pose_covariance_shapes_the_particles(world):
    # N(mean, cov) with a full covariance: the sample covariance of 20,000 particles is within 5 % of cov
    # (the standard error of a variance estimate at N=20,000 is sqrt(2/N) = 1 %).
    from mcl.filter import ParticleFilter

    cfg = load_config(None, ["filter.particles=20000", "seed=4"])
    pf = ParticleFilter(cfg, load_map(world / "map.yaml"))
    cov = np.array([[0.04, 0.015, 0.0], [0.015, 0.09, 0.0], [0.0, 0.0, 0.01]])
    pf.init_gaussian_cov((5.0, 5.0, 0.0), cov)
    got = np.cov(pf.particles)
    assert np.allclose(got, cov, atol=0.05 * 0.09)
    assert abs(got[0, 1] / math.sqrt(got[0, 0] * got[1, 1]) - 0.25) < 0.03  # the correlation is kept


def test_command_line_initial_pose_overrides_the_bags(world, scans, tmp_path, capsys):
    bag = tmp_path / "init.bag"
    write_scans(bag, scans, initial=((1.0, 1.0, 0.0), np.eye(3) * 0.01))
    out = tmp_path / "g"
    assert main(["run", "--map", str(world / "map.yaml"), "--bag", str(bag), "--global", "--out", str(out),
                 "--rerun", "off", "--particles", "300", "--no-progress", "--json"]) == 0
    import json

    assert json.loads((out / "summary.json").read_text())["mode"] == "global"


def test_a_configured_start_overrides_the_bags_initial_pose_and_a_suite_gives_its_own(world, scans, tmp_path, capsys):
    # A bag's /initialpose (here 1 m off the truth's start) starts the run unless the start is configured: a --set of
    # filter.global_localization or filter.initial_pose, a config that tracks from its own filter.initial_pose, or a
    # suite's mode. Each was overridden by the bag (the suite's global rows were tracking runs from /initialpose).
    import json

    truth = read_tum(world / "truth.tum")
    start = [float(v) for v in truth[1][:, 0]]
    bag = tmp_path / "init.mcap"
    write_scans(bag, scans, initial=((start[0] + 1.0, start[1], start[2]), np.eye(3) * 0.0001), truth=truth)
    base = ["run", "--map", str(world / "map.yaml"), "--bag", str(bag), "--rerun", "off", "--particles", "300",
            "--no-progress", "--seed", "2"]

    def first_x(out):
        return float((out / "trajectory.tum").read_text().split()[1])

    assert main([*base, "--out", str(tmp_path / "bag")]) == 0  # the bag's pose: tracking from 1 m off
    assert "tracking from /initialpose" in capsys.readouterr().err and first_x(tmp_path / "bag") > start[0] + 0.7
    assert main([*base, "--out", str(tmp_path / "g"), "--set", "filter.global_localization=true"]) == 0
    assert json.loads((tmp_path / "g" / "summary.json").read_text())["mode"] == "global"
    assert "/initialpose not used: global localization as the command line says" in capsys.readouterr().err
    own = tmp_path / "own.yaml"
    own.write_text(f"filter:\n  global_localization: false\n  initial_pose: [{start[0]!r}, {start[1]!r}, {start[2]!r}]\n")
    assert main([*base, "--config", str(own), "--out", str(tmp_path / "own")]) == 0
    assert "/initialpose not used: tracking from filter.initial_pose as the config says" in capsys.readouterr().err
    assert abs(first_x(tmp_path / "own") - start[0]) < 0.3  # the config's pose (initial_std 0.1 m)
    # --set filter.initial_pose alone tracks from it (global_localization false by default: a null pose is global)
    pose = f"filter.initial_pose=[{start[0]!r}, {start[1]!r}, {start[2]!r}]"
    assert main([*base, "--out", str(tmp_path / "p"), "--set", pose]) == 0
    assert "/initialpose not used: tracking from filter.initial_pose as the command line says" in capsys.readouterr().err
    assert abs(first_x(tmp_path / "p") - start[0]) < 0.3
    # --global with a pose: global, and a note says the pose is unused
    assert main([*base, "--out", str(tmp_path / "q"), "--global", "--set", pose]) == 0
    err = capsys.readouterr().err
    assert "filter.global_localization is true, so filter.initial_pose" in err and "is not used" in err
    assert json.loads((tmp_path / "q" / "summary.json").read_text())["mode"] == "global"
    # a suite's global mode on the bag is a global run
    import yaml

    suite = tmp_path / "s.yaml"
    suite.write_text(yaml.safe_dump({"name": "s", "modes": ["global", "tracking"], "datasets": [
        {"name": "b", "bag": str(bag), "map": str(world / "map.yaml"), "truth": str(world / "truth.tum")}]}))
    assert main(["eval", "--suite", str(suite), "--out", str(tmp_path / "ev"), "--jobs", "1", "--no-baseline",
                 "--no-progress", "--set", "filter.particles=300"]) == 0
    runs = tmp_path / "ev" / "runs" / "b"
    assert json.loads((runs / "global" / "default" / "seed1" / "summary.json").read_text())["mode"] == "global"
    assert abs(first_x(runs / "tracking" / "default" / "seed1") - start[0]) < 0.3  # the truth's start, not the bag's


def test_a_bag_given_as_the_log_is_read_as_a_bag(world, scans, tmp_path, capsys):
    # `mcl run --map M --log x.mcap` reads the bag (it said "x.mcap:1: not UTF-8 text"): the same trajectory as
    # --bag. A config's `log:` naming a bag is one line that says to give it as bag.
    bag = tmp_path / "b.mcap"
    write_scans(bag, scans)
    trajs = []
    for flag in ("--bag", "--log"):
        out = tmp_path / flag.strip("-")
        assert main(["run", "--map", str(world / "map.yaml"), flag, str(bag), "--out", str(out), "--rerun", "off",
                     "--particles", "300", "--no-progress"]) == 0
        trajs.append((out / "trajectory.tum").read_bytes())
    assert trajs[0] == trajs[1] and len(trajs[0]) > 1000
    with pytest.raises(ConfigError, match=r"--set log=.*b\.mcap: log: .*b\.mcap is a ROS bag: give it as bag"):
        load_config(Path(__file__).resolve().parents[1] / "configs" / "default.yaml", [f"log={bag}"])


# ----------------------------------------------------------------------------- convert, write-bag, info


def test_convert_round_trip_keeps_what_mcl_uses(world, scans, tmp_path):
    # clf -> mcap (laser off-centre) -> clf -> bag -> read: every record as the log's, the offset to 1e-12. The
    # FLASER records carry no velocities: the bag's /odom takes the last ODOM line's (its twist was zero throughout)
    from mcl.datasets.bagwrite import _with_odometry_velocities

    log = read_carmen(world / "log.clf")
    scans = _with_odometry_velocities(scans, log.odometry)
    assert sum(s.tv != 0.0 for s in scans) > 0.9 * len(scans)
    t = log.odometry[:, 0]
    j = int(np.searchsorted(t, scans[10].t, side="right")) - 1
    assert (scans[10].tv, scans[10].rv) == (log.odometry[j, 4], log.odometry[j, 5]) and t[j] <= scans[10].t
    assert main(["convert", str(world / "log.clf"), str(tmp_path / "a.mcap")]) == 0
    assert main(["convert", str(tmp_path / "a.mcap"), str(tmp_path / "b.clf")]) == 0
    back = read_carmen(tmp_path / "b.clf").laser_stream()
    assert len(back) == len(scans)
    for a, b in zip(scans, back):
        _same_records(a, b, offset_tol=1e-12)
    assert convert(tmp_path / "b.clf", tmp_path / "c.bag") == len(scans)
    for a, b in zip(scans, open_bag(tmp_path / "c.bag").scans):
        _same_records(a, b, offset_tol=1e-12)


def test_simulate_writes_bags(tmp_path, capsys):
    assert main(["simulate", str(tmp_path / "s"), "--duration", "4", "--format", "db3"]) == 0
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == ["log.db3", "map.pgm", "map.yaml", "sim.yaml",
                                                                 "truth.tum"]
    src = open_bag(tmp_path / "s" / "log.db3", load_config(None, ["topics.truth=/ground_truth"]).topics)
    t, _ = read_tum(tmp_path / "s" / "truth.tum")
    assert len(src.scans) == t.size and np.array_equal(src.truth[0], t)


def _odometry_messages(bag):
    """(sec, nanosec, parent, child, x, y, qz, qw) of each /odom message, and of each /tf transform, in order."""
    from rosbags.highlevel import AnyReader

    odom, tf = [], []
    with AnyReader([bag]) as r:
        for c, _, raw in r.messages([c for c in r.connections if c.topic in ("/odom", "/tf")]):
            m = r.deserialize(raw, c.msgtype)
            if c.topic == "/odom":
                p = m.pose.pose
                odom.append((m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id, m.child_frame_id,
                             p.position.x, p.position.y, p.orientation.z, p.orientation.w))
            else:
                tf += [(ts.header.stamp.sec, ts.header.stamp.nanosec, ts.header.frame_id, ts.child_frame_id,
                        ts.transform.translation.x, ts.transform.translation.y, ts.transform.rotation.z,
                        ts.transform.rotation.w) for ts in m.transforms]
    return odom, tf


def test_simulated_and_converted_bags_carry_odom_to_base_link_on_tf(world, tmp_path):
    # A ROS robot's bag always has odom -> base_link on /tf (REP 105): ROS AMCL or RViz playing mcl's bag could not
    # place the laser, which had the odometry on /odom only. Now by default both, the same pose at the same stamp;
    # --odom topic and --odom tf still write one of them.
    assert main(["simulate", str(tmp_path / "s"), "--duration", "3", "--format", "bag1"]) == 0
    assert main(["convert", str(world / "log.clf"), str(tmp_path / "c.mcap")]) == 0
    for bag, n in ((tmp_path / "s" / "log.bag", 16), (tmp_path / "c.mcap", len(read_carmen(world / "log.clf").scans))):
        odom, tf = _odometry_messages(bag)
        assert len(odom) == n and tf == odom, bag
        assert {r[2:4] for r in tf} == {("odom", "base_link")}
    assert main(["convert", str(world / "log.clf"), str(tmp_path / "t.mcap"), "--odom", "topic"]) == 0
    assert main(["convert", str(world / "log.clf"), str(tmp_path / "f.mcap"), "--odom", "tf"]) == 0
    odom, tf = _odometry_messages(tmp_path / "c.mcap")
    assert _odometry_messages(tmp_path / "t.mcap") == (odom, [])
    assert _odometry_messages(tmp_path / "f.mcap") == ([], tf)


def test_write_scans_and_convert_refuse_an_unknown_odom_value(world, scans, tmp_path):
    # write_scans(odom="odometry") (the API; the command line restricts --odom) wrote a bag without any odometry,
    # which mcl then read by laser odometry: one line naming the output, the value and the choices, nothing written
    for bad in ("odometry", "Topic", None):
        out = tmp_path / "o" / "x.mcap"
        with pytest.raises(ConfigError) as e:
            write_scans(out, scans, odom=bad)
        msg = str(e.value)
        assert str(out) in msg and repr(bad) in msg and "both, topic, tf" in msg and "\n" not in msg, msg
        assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
    for ext in ("mcap", "clf"):
        with pytest.raises(ConfigError, match="odom 'odometry': expected one of both, topic, tf"):
            convert(world / "log.clf", tmp_path / f"c.{ext}", odom="odometry", echo=_quiet)
        assert not (tmp_path / f"c.{ext}").exists()


def test_a_bag_with_both_odometry_sources_reads_as_the_odom_topic_alone(scans, tmp_path, capsys):
    # The default bag has /odom and /tf odom -> base_link: read from /odom as a bag of /odom alone, the same bytes,
    # with no note or warning about two sources
    both, topic = tmp_path / "both.mcap", tmp_path / "topic.mcap"
    write_scans(both, scans)
    write_scans(topic, scans, odom="topic")
    a, b = open_bag(both), open_bag(topic)
    assert a.odom_source == b.odom_source == "/odom (nav_msgs/Odometry)"
    assert a.odometry.tobytes() == b.odometry.tobytes()
    for x, y in zip(a.scans, b.scans):
        assert x.odom.tobytes() == y.odom.tobytes() and (x.tv, x.rv) == (y.tv, y.rv)
    assert (a.notes, a.warnings) == (b.notes, b.warnings) == ([], [])
    ia, ib = bag_info(both), bag_info(topic)
    assert (ia["frames"]["/tf"], ib["frames"]["/tf"]) == (["odom -> base_link"], [])
    assert str(ia["mcl_uses"]).replace("both.mcap", "topic.mcap") == str(ib["mcl_uses"])
    assert main(["bag", "info", str(both)]) == 0
    text = capsys.readouterr().out
    assert "frames in /tf: odom -> base_link" in text and "odometry:     /odom (nav_msgs/Odometry)" in text
    assert "note" not in text and "warning" not in text


def test_write_bag_holds_the_estimate(world, scans, tmp_path):
    bag = tmp_path / "in.bag"
    write_scans(bag, scans)
    cfg = load_config(None, ["rerun.mode=off", "filter.particles=300", f"map={world / 'map.yaml'}", "log=null",
                             f"bag={bag}", "truth=null", "rerun.particles_max=50"])
    summary = run(cfg, tmp_path / "r", progress=False, echo=_quiet, write_bag=True)
    est = tmp_path / "r" / "estimate.bag"
    assert summary["outputs"]["bag"] == str(est)
    from rosbags.highlevel import AnyReader

    with AnyReader([est]) as r:
        counts = {c.topic: c.msgcount for c in r.connections}
        assert counts == {"/amcl_pose": summary["updates"], "/tf": summary["updates"],
                          "/particlecloud": summary["updates"]}
        conn = [c for c in r.connections if c.topic == "/amcl_pose"]
        poses = [r.deserialize(raw, c.msgtype) for c, _, raw in r.messages(conn)]
        conn = [c for c in r.connections if c.topic == "/particlecloud"]
        cloud = [r.deserialize(raw, c.msgtype) for c, _, raw in r.messages(conn)]
        conn = [c for c in r.connections if c.topic == "/tf"]
        m2o = [r.deserialize(raw, c.msgtype).transforms[0] for c, _, raw in r.messages(conn)]
    t, p = read_tum(tmp_path / "r" / "trajectory.tum")
    last = poses[-1].pose.pose.position
    assert (last.x, last.y) == pytest.approx((p[0, -1], p[1, -1]), abs=1e-9)
    assert 0 < len(cloud[0].poses) <= 50
    # map -> odom (the estimate's) then odom -> base_link (the input bag's /tf, written by default) at the last
    # update's stamp: the tree RViz follows places base_link at /amcl_pose
    assert (m2o[-1].header.frame_id, m2o[-1].child_frame_id) == ("map", "odom")
    stamp = (m2o[-1].header.stamp.sec, m2o[-1].header.stamp.nanosec)
    o2b = [r for r in _odometry_messages(bag)[1] if r[:2] == stamp]
    assert len(o2b) == 1 and o2b[0][2:4] == ("odom", "base_link")
    pose2 = lambda x, y, qz, qw: np.array([x, y, 2.0 * math.atan2(qz, qw)])  # noqa: E731
    tr = m2o[-1].transform
    base = compose(pose2(tr.translation.x, tr.translation.y, tr.rotation.z, tr.rotation.w), pose2(*o2b[0][4:]))
    q = poses[-1].pose.pose.orientation
    want = pose2(last.x, last.y, q.z, q.w)
    assert base[:2] == pytest.approx(want[:2], abs=1e-9) and abs(math.remainder(base[2] - want[2], math.tau)) < 1e-9


def _yaw_pose(x, y, qz, qw):
    return np.array([x, y, 2.0 * math.atan2(qz, qw)])


def _recorded_odometry(bag, frame: str, topic: str = "/tf") -> dict:
    """{(sec, nanosec): (x, y, theta)} of the odometry in ``frame`` the input ``bag`` records: its /tf transforms
    from ``frame``, or the messages on ``topic`` (Odometry, pose topics) stamped in it."""
    from rosbags.highlevel import AnyReader

    out = {}
    with AnyReader([bag]) as r:
        for c, _, raw in r.messages([c for c in r.connections if c.topic == topic]):
            m = r.deserialize(raw, c.msgtype)
            if topic == "/tf":
                for ts in m.transforms:
                    if ts.header.frame_id == frame:
                        tr = ts.transform
                        out[(ts.header.stamp.sec, ts.header.stamp.nanosec)] = _yaw_pose(
                            tr.translation.x, tr.translation.y, tr.rotation.z, tr.rotation.w)
            elif m.header.frame_id == frame:
                p = m.pose.pose if hasattr(m.pose, "pose") else m.pose
                out[(m.header.stamp.sec, m.header.stamp.nanosec)] = _yaw_pose(
                    p.position.x, p.position.y, p.orientation.z, p.orientation.w)
    return out


def _estimate_joins(world, bag, out, *overrides) -> tuple[str, list]:
    """Run ``bag`` with --write-bag; (the odometry frame of its map -> X on /tf, and for each update the base pose
    that map -> X composed with the input's odometry pose ``X -> base`` at the update's stamp gives, next to
    /amcl_pose's pose: [(stamp, composed, amcl)]) — X read from the estimate bag itself."""
    from rosbags.highlevel import AnyReader

    cfg = load_config(None, ["rerun.mode=off", "filter.particles=300", f"map={world / 'map.yaml'}", "log=null",
                             f"bag={bag}", "truth=null", *overrides])
    run(cfg, out, progress=False, echo=_quiet, write_bag=True)
    est = next(out.glob("estimate.*"))
    with AnyReader([est]) as r:
        amcl, m2o = {}, {}
        for c, _, raw in r.messages([c for c in r.connections if c.topic in ("/amcl_pose", "/tf")]):
            m = r.deserialize(raw, c.msgtype)
            if c.topic == "/amcl_pose":
                assert m.header.frame_id == "map"
                p = m.pose.pose
                amcl[(m.header.stamp.sec, m.header.stamp.nanosec)] = _yaw_pose(p.position.x, p.position.y,
                                                                               p.orientation.z, p.orientation.w)
            else:
                (ts,) = m.transforms
                tr = ts.transform
                m2o[(ts.header.stamp.sec, ts.header.stamp.nanosec)] = (
                    ts.header.frame_id, ts.child_frame_id,
                    _yaw_pose(tr.translation.x, tr.translation.y, tr.rotation.z, tr.rotation.w))
    assert m2o.keys() == amcl.keys() and len(amcl) > 10
    assert {v[0] for v in m2o.values()} == {"map"}
    (frame,) = {v[1] for v in m2o.values()}
    return frame, [(k, m2o[k][2], amcl[k]) for k in sorted(amcl)]


def _joined(rows, odometry: dict) -> int:
    """How many of ``rows`` (``_estimate_joins``) have the input's odometry at their stamp; each must compose to
    /amcl_pose within 1e-6."""
    n = 0
    for stamp, m2o, amcl in rows:
        if stamp in odometry:
            got = compose(m2o, odometry[stamp])
            assert got[:2] == pytest.approx(amcl[:2], abs=1e-6), stamp
            assert abs(math.remainder(got[2] - amcl[2], math.tau)) < 1e-6, stamp
            n += 1
    return n


def _frames_bag(path, scans, case: str) -> tuple[str, str, list]:
    """A bag whose odometry is not odom -> base_link: (the odometry frame, the topic it is on, config overrides)."""
    from mcl.datasets.bagwrite import _compose, _inverse

    TF, PWCS = "tf2_msgs/msg/TFMessage", "geometry_msgs/msg/PoseWithCovarianceStamped"
    if case == "namespaced":
        _namespaced_bag(path, scans, ["robot1"])
        return "robot1/odom", "/tf", []
    mount = (0.2, 0.0, 0.0)
    with BagOut(path) as b:
        b.write("/tf_static", TF, scans[0].t, b.msg(TF, transforms=[
            b.transform(scans[0].t, "base_link" if case in ("odometry-topic", "ekf-beside-wheels") else "base_footprint",
                        "laser", mount)]))
        for k, s in enumerate(scans):
            base = _compose(tuple(s.odom), _inverse(mount))
            if case == "nav2":
                b.write("/tf", TF, s.t, b.msg(TF, transforms=[b.transform(s.t, "odom", "base_footprint", base)]))
            elif case == "ekf":  # with a localizer's map -> odom_combined above it, as recorded
                b.write("/tf", TF, s.t, b.msg(TF, transforms=[
                    b.transform(s.t, "map", "odom_combined", (0.01 * k, 0.0, 0.002 * k)),
                    b.transform(s.t, "odom_combined", "base_footprint", base)]))
            elif case == "odometry-topic":
                _odom(b, s, pose=base, frame="odom_wheel")
            elif case == "ekf-beside-wheels":  # the wheels' /odom, and an EKF's odom -> base_link on /tf drifting off it
                _odom(b, s, pose=base)
                b.write("/tf", TF, s.t, b.msg(TF, transforms=[
                    b.transform(s.t, "odom", "base_link", _compose(base, (0.03 * k, 0.01 * k, 0.004 * k)))]))
            elif case == "pose-topic":
                pw = b.msg("geometry_msgs/msg/PoseWithCovariance", pose=b.pose(*base), covariance=np.zeros(36))
                b.write("/ekf/odom_combined", PWCS, s.t, b.msg(PWCS, header=b.header(s.t, "odom_combined"), pose=pw))
            _laser(b, "/scan", s, frame="laser")
    return {"nav2": ("odom", "/tf", []), "ekf": ("odom_combined", "/tf", []),
            "odometry-topic": ("odom_wheel", "/odom", []), "ekf-beside-wheels": ("odom", "/tf", []),
            "pose-topic": ("odom_combined", "/ekf/odom_combined", ["topics.odom=/ekf/odom_combined"])}[case]


@pytest.mark.parametrize("case", ["namespaced", "nav2", "ekf", "odometry-topic", "pose-topic", "ekf-beside-wheels"])
def test_write_bag_map_to_odom_names_the_odometry_frame_the_bag_was_read_in(world, scans, tmp_path, case):
    # The estimate bag's map -> odom was always named frames.odom ("odom"): with a bag whose odometry is
    # robot1/odom -> robot1/base_link, robot_pose_ekf's odom_combined -> base_footprint, an Odometry in odom_wheel
    # or a pose topic in odom_combined, RViz playing both bags had two trees, map -> odom and the robot's. Now map ->
    # the frame the reader read the odometry in; composed with the input's own odometry pose at each update's stamp
    # (of the frame the odometry moves: base_footprint, robot1/base_link) it places the robot at /amcl_pose.
    # ekf-beside-wheels: the run reads the wheels' /odom, but /tf's odom -> base_link is an EKF's, up to 1.2 m off
    # it: map -> odom is computed from /tf's link, the tree it joins (from /odom it placed the robot 1.2 m away).
    bag = tmp_path / f"{case}.bag"
    frame, topic, overrides = _frames_bag(bag, scans, case)
    cfg = load_config(None, overrides)
    assert open_bag(bag, cfg.topics, cfg.frames).odom_frame == frame
    got, rows = _estimate_joins(world, bag, tmp_path / "r", *overrides)
    assert got == frame
    assert _joined(rows, _recorded_odometry(bag, frame, topic)) == len(rows)


def test_write_bag_with_laser_odometry_names_frames_odom(world, scans, tmp_path):
    # no odometry frame in the bag (scans alone: laser odometry): map -> frames.odom, whatever it is named
    bag = tmp_path / "scans.mcap"
    with BagOut(bag) as b:
        for s in scans:
            _laser(b, "/scan", s, frame="base_link")
    assert open_bag(bag).odom_frame is None
    frame, _ = _estimate_joins(world, bag, tmp_path / "r", "topics.odom=laser", "frames.odom=scan_odom")
    assert frame == "scan_odom"


def test_write_bag_map_to_odom_joins_the_recorded_odometry_after_a_gap(world, scans, tmp_path):
    # /odom stops for 4 s and the gap is filled by laser odometry, which moves the odometry after it rigidly: map ->
    # odom taken from those moved poses placed the robot off /amcl_pose by that move (the input bag's /odom is not
    # moved) for every update after the gap. From the odometry as recorded, they compose.
    t0 = scans[0].t
    bag = tmp_path / "gap.mcap"
    with BagOut(bag) as b:
        for s in scans:
            if not 2.0 <= s.t - t0 <= 6.0:
                _odom(b, s)
            _laser(b, "/scan", s, frame="base_link")
    assert any("stops while the scans go on" in w for w in open_bag(bag).warnings)
    frame, rows = _estimate_joins(world, bag, tmp_path / "r")
    assert frame == "odom"
    after = sum(1 for k, _, _ in rows if k[0] + 1e-9 * k[1] - t0 > 6.0)
    assert after > 3 and _joined(rows, _recorded_odometry(bag, "odom", "/odom")) >= after


@pytest.mark.parametrize("ext", ["bag", "mcap", "db3"])
def test_particlecloud_bytes_built_with_numpy_are_the_serializers(tmp_path, ext):
    # /particlecloud was a Python object per pose (2.6 ms an update for 1000); built with numpy it must be the very
    # bytes the rosbags serializer gives for the message of BagOut.pose's: ROS 1 and CDR, frames whose length moves
    # the CDR alignment of the poses, 0, 1 and many poses, headings of either sign, past pi and -0.0
    from rosbags.highlevel import AnyReader

    from mcl.datasets.bagwrite import EstimateBag

    PA = "geometry_msgs/msg/PoseArray"
    rng = np.random.default_rng(5)
    p = np.vstack([rng.uniform(-50, 50, 5001), rng.uniform(-50, 50, 5001), rng.uniform(-7, 7, 5001)])
    p[:, 0] = (-0.0, 0.0, -0.0)
    p[2, 1] = math.pi
    ref, new = BagOut(tmp_path / f"ref.{ext}"), BagOut(tmp_path / f"new.{ext}")
    try:
        for frame in ("map", "m", "ma", "mapx", "world_frame"):
            for n in (0, 1, 2, 5001):
                q = p[:, :n]
                want = ref.serialize(ref.msg(PA, header=ref.header(7.25, frame),
                                             poses=[ref.pose(*q[:, k]) for k in range(n)]), PA)
                _same_pose_array(new.pose_array(7.25, frame, q), bytes(want), n, ext)
    finally:
        ref.abort()
        new.abort()
    # and in the estimate bag: an even stride through the set (5001 particles, at most 2000: every third)
    kind = {"bag": "bag1", "mcap": "mcap", "db3": "db3"}[ext]
    e = EstimateBag(tmp_path / f"est.{ext}", kind, 2000)
    e.update(3.5, (1.0, 2.0, 0.5), np.eye(3) * 0.01, (0.0, 0.0, 0.0), p)
    e.close()
    with AnyReader([tmp_path / f"est.{ext}"]) as r:
        (raw,) = [bytes(raw) for c, _, raw in r.messages([c for c in r.connections if c.topic == "/particlecloud"])]
    b = BagOut(tmp_path / f"ref2.{ext}")
    try:
        b.header(0.0, "")  # the estimate's /amcl_pose and /tf headers came first (ROS 1's seq)
        b.header(0.0, "")
        want = b.serialize(b.msg(PA, header=b.header(3.5, "map"), poses=[b.pose(*p[:, k]) for k in range(0, 5001, 3)]),
                           PA)
    finally:
        b.abort()
    _same_pose_array(raw, bytes(want), len(range(0, 5001, 3)), ext)


def _same_pose_array(got: bytes, want: bytes, n: int, ext: str) -> None:
    """``got`` is ``want`` byte for byte, but for the quaternions' sin and cos of the half yaw, which numpy's
    vectorised sin/cos and the serializer's math.sin/cos may round apart in the last bit on some CPUs: within 1
    ulp there (measured on this machine: identical)."""
    assert len(got) == len(want)
    k = n * 56  # n poses of 7 float64 at the end of the message
    assert got[: len(got) - k] == want[: len(want) - k]
    end = "<" if ext == "bag" or want[1] == 1 else ">"
    a, b = (np.frombuffer(x[len(x) - k:], dtype=f"{end}f8").reshape(n, 7) for x in (got, want))
    np.testing.assert_array_equal(a[:, :5], b[:, :5])
    np.testing.assert_array_max_ulp(a[:, 5:], b[:, 5:], maxulp=1)


def test_bag_info_names_what_mcl_would_use(scans, tmp_path, capsys):
    bag = tmp_path / "i.mcap"
    write_scans(bag, scans, odom="tf", mount=(0.1, 0.0, 0.0))
    info = bag_info(bag)
    assert info["topics"]["/scan"] == {"type": "sensor_msgs/LaserScan", "count": len(scans)}
    assert info["frames"] == {"/tf": ["odom -> base_link"], "/tf_static": ["base_link -> laser"]}
    assert info["mcl_uses"]["odometry"] == "/tf odom -> base_link"
    assert info["mcl_uses"]["laser_pose"]["/scan"] == [0.1, 0.0, 0.0]
    # the beam geometry a run reads (a generated FLASER world: 181 beams over 180 degrees; its no-return reading)
    beams = info["mcl_uses"]["beams"]["/scan"]
    assert (beams["beams"], beams["fov_deg"], beams["angle_min_deg"]) == (181, 180.0, -90.0)
    assert beams["scans"] == len(scans) and beams["max_range"] == pytest.approx(scans[0].max_range)
    assert info["mcl_uses"]["scan_span_s"] == [scans[0].t, scans[-1].t] == info["mcl_uses"]["odometry_span_s"]
    assert info["mcl_uses"]["warnings"] == []
    assert info["mcl_uses"]["references"] == []
    assert main(["bag", "info", str(bag)]) == 0
    text = capsys.readouterr().out
    assert "mcl would use:" in text and "/tf odom -> base_link" in text
    assert f"beams:        /scan: 181 beams over 180 degrees from -90, no return at {scans[0].max_range:g} m" in text
    assert "reference:    no pose topic besides the odometry (--truth T.tum scores against a file)" in text
    assert f"stamps:       scans {scans[0].t:.3f}..{scans[-1].t:.3f} s, odometry {scans[0].t:.3f}..{scans[-1].t:.3f} s" in text


def test_bag_info_names_the_topics_a_run_could_score_against(scans, tmp_path, capsys):
    # A simulated bag's /ground_truth (PoseStamped) is offered as a reference, the /odom it reads as odometry and an
    # /initialpose are not: a user running `mcl run --bag` on it otherwise gets no ATE and no hint why.
    bag = tmp_path / "r.mcap"
    t = np.array([s.t for s in scans])
    write_scans(bag, scans, odom="both", truth=(t, np.array([s.odom for s in scans]).T),
                initial=((0.0, 0.0, 0.0), np.eye(3) * 0.01))
    info = bag_info(bag)
    assert info["mcl_uses"]["odometry"].startswith("/odom ")
    assert info["mcl_uses"]["references"] == ["/ground_truth"]
    assert main(["bag", "info", str(bag)]) == 0
    assert (f"reference:    /ground_truth (geometry_msgs/PoseStamped, {len(scans)}): score a run against one with "
            "--truth-topic TOPIC") in capsys.readouterr().out
    # a run with no reference says which topic would score it; given it, scored and no such line
    world = tmp_path / "w"
    from mcl.maps import OccupancyGrid, save_map

    world.mkdir()
    occupancy = np.zeros((400, 400), np.int8)
    occupancy[0] = 100  # a wall (a map with none is refused: nothing for the laser to match)
    save_map(OccupancyGrid.from_occupancy(occupancy, 0.05, (-10.0, -10.0)), world / "map.yaml")
    common = ["run", "--map", str(world / "map.yaml"), "--bag", str(bag), "--rerun", "off", "--particles", "300",
              "--no-progress", "--initial-pose", "0", "0", "0"]
    assert main([*common, "--out", str(tmp_path / "a")]) == 0
    text = "".join(capsys.readouterr())
    assert f"{bag}: not scored: no reference given; the bag has /ground_truth (--truth-topic /ground_truth" in text
    assert "ATE" not in text
    assert main([*common, "--out", str(tmp_path / "b"), "--truth-topic", "/ground_truth"]) == 0
    text = "".join(capsys.readouterr())
    assert "not scored" not in text and "ATE RMSE" in text


# ----------------------------------------------------------------------------- bad input: one line, exit 2


def _fails(capsys, tmp_path, bag, *extra, match):
    out = tmp_path / "out"
    code = main(["run", "--bag", str(bag), "--out", str(out), "--rerun", "off", "--no-progress", *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and str(bag) in err, err
    assert match in err, err
    assert not out.exists()  # nothing written, not even the folder
    return err


def _shifted_odometry_bag(path, scans, shift: float, upto: int | None = None) -> None:
    """/scan at the scans' stamps, /odom stamped ``shift`` s later (another clock), for the first ``upto`` scans."""
    with BagOut(path) as b:
        for k, s in enumerate(scans):
            if upto is None or k < upto:
                pw = b.msg("geometry_msgs/msg/PoseWithCovariance", pose=b.pose(*s.odom), covariance=np.zeros(36))
                tw = b.msg("geometry_msgs/msg/TwistWithCovariance", twist=b.msg(
                    "geometry_msgs/msg/Twist", linear=b.msg("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0),
                    angular=b.msg("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0)), covariance=np.zeros(36))
                b.write("/odom", "nav_msgs/msg/Odometry", s.t + shift, b.msg(
                    "nav_msgs/msg/Odometry", header=b.header(s.t + shift, "odom"), child_frame_id="base_link",
                    pose=pw, twist=tw))
            _laser(b, "/scan", s)


def test_scans_and_odometry_on_two_clocks_stop_with_one_line_and_a_time_offset_pairs_them(world, scans, tmp_path,
                                                                                          capsys):
    # Odometry stamped 1000 s after the scans (a driver on its own clock): every scan was paired with the first
    # odometry pose, the robot stood still, and the run went on without a word.
    bag = tmp_path / "clocks.mcap"
    _shifted_odometry_bag(bag, scans, 1000.0)
    err = _fails(capsys, tmp_path, bag, match="no scan is stamped within the odometry's time span")
    assert "odometry (/odom (nav_msgs/Odometry)) 1000.000..1008.000 s" in err and "sensor.time_offset=1000.000 would pair" in err
    assert main(["bag", "info", str(bag)]) == 0  # what mcl would use: nothing, and why
    assert "nothing: " + err.removeprefix("mcl: error: ") in capsys.readouterr().out
    # sensor.time_offset +1000 pairs each scan with its own odometry message again: the same poses as the bag
    # on one clock (the trajectory's stamps are the scans' own)
    same = tmp_path / "same.mcap"
    write_scans(same, scans)
    s_off, o_off = _run(tmp_path, "off", map=world / "map.yaml", bag=bag, **{"sensor.time_offset": 1000.0})
    s_one, o_one = _run(tmp_path, "one", map=world / "map.yaml", bag=same)
    a, b = read_tum(o_off / "trajectory.tum"), read_tum(o_one / "trajectory.tum")
    assert s_off["updates"] == s_one["updates"] > 30 and np.allclose(a[1], b[1], rtol=0, atol=1e-9)


def test_scans_past_the_odometrys_end_are_named_in_a_warning(world, scans, tmp_path, capsys):
    bag = tmp_path / "short.mcap"
    _shifted_odometry_bag(bag, scans, 0.0, upto=20)  # odometry for 0..3.8 s, scans until 8 s: 4.4..8 s past the slack (0.5 s)
    out = tmp_path / "out"
    code = main(["run", "--bag", str(bag), "--map", str(world / "map.yaml"), "--out", str(out), "--rerun", "off",
                 "--no-progress", "--particles", "500"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    text = captured.out + captured.err
    assert ("19 of 41 scans are stamped after the odometry's time span (0.000..3.800 s), by up to 4.20 s: their "
            "odometry is held at the last pose") in text
    assert "before the odometry" not in text
    # mcl bag info names it too (on a bag with no /tf or /tf_static at all, which it once read whole as transforms:
    # an AttributeError traceback)
    assert main(["bag", "info", str(bag)]) == 0
    assert "  warning: " + f"{bag}: 19 of 41 scans are stamped after" in capsys.readouterr().out


def test_missing_topic_lists_the_scan_like_topics(scans, tmp_path, capsys):
    bag = tmp_path / "b.mcap"
    write_scans(bag, scans)
    _fails(capsys, tmp_path, bag, "--scan-topic", "/base_scan", match="no topic /base_scan (scan-like topics: /scan)")


def test_unknown_message_type_on_the_scan_topic(scans, tmp_path, capsys):
    from rosbags.typesys import get_types_from_msg

    bag = tmp_path / "u.mcap"
    with BagOut(bag) as b:
        b.ts.register(get_types_from_msg("float64[] values", "acme_msgs/msg/Blob"))
        for s in scans:
            _odom(b, s)
            _laser(b, "/scan", s)
            b.write("/sonar", "acme_msgs/msg/Blob", s.t, b.msg("acme_msgs/msg/Blob", values=np.zeros(3)))
    _fails(capsys, tmp_path, bag, "--scan-topic", "/sonar", match="/sonar is acme_msgs/msg/Blob, not a LaserScan")


def test_transform_that_never_appears(scans, tmp_path, capsys):
    bag = tmp_path / "t.bag"
    write_scans(bag, scans, odom="tf")
    _fails(capsys, tmp_path, bag, "--base-frame", "base_footprint",
           match="/tf: the transform odom -> base_footprint never appears (it has: odom -> base_link)")


def test_messages_out_of_order(scans, tmp_path, capsys):
    bag = tmp_path / "o.db3"
    with BagOut(bag) as b:
        for k, s in enumerate(scans):
            _odom(b, s)
            _laser(b, "/scan", s, t=s.t - 5.0 if k == 10 else s.t)
    _fails(capsys, tmp_path, bag, match="/scan: messages out of order: message 11")


def _odometry_bag(path, scans, broken=(), twist_nan=()) -> None:
    """/odom and /scan (the laser at the robot's centre) of ``scans``; the Odometry of each scan index in ``broken`` with x NaN, of each in
    ``twist_nan`` with angular z NaN."""
    nan = math.nan
    with BagOut(path) as b:
        for k, s in enumerate(scans):
            pose = (nan, s.odom[1], s.odom[2]) if k in broken else None
            _odom(b, s, pose=pose, twist=(0.0, nan) if k in twist_nan else (0.0, 0.0))
            _laser(b, "/scan", s, frame="base_link")


def test_non_finite_odometry_messages_are_mended_not_refused(scans, tmp_path):
    # An EKF publishes NaN poses until its first input, a driver a NaN twist now and then: one such message refused
    # the whole bag ("/odom: non-finite odometry", naming nothing). Now a pose that is not finite is left out (a
    # warning naming the field, the count and the first stamp; the scan there takes the odometry interpolated
    # between its neighbours) and a velocity read as 0 (a note: the velocities only deskew the scans); every other
    # record is the clean bag's to the byte.
    clean, broken = tmp_path / "clean.mcap", tmp_path / "broken.mcap"
    _odometry_bag(clean, scans)
    _odometry_bag(broken, scans, broken={7}, twist_nan={0, 5, 10})
    a, b = open_bag(clean), open_bag(broken)
    n = len(a.odometry)
    assert b.odometry.tobytes() == a.odometry[np.arange(n) != 7].tobytes()
    (warning,) = b.warnings
    assert f"/odom: 1 of {n} poses are not finite (x; the first stamped {scans[7].t:.3f})" in warning
    assert any(f"/odom: 3 of {n} messages carry a non-finite velocity" in note for note in b.notes)
    for k, (x, y) in enumerate(zip(a.scans, b.scans)):
        if k == 7:  # between its neighbours' poses (the robot drives on between them)
            assert np.isfinite(y.odom).all() and 0.0 < np.linalg.norm(y.odom[:2] - x.odom[:2]) < 0.1
        else:
            assert y.odom.tobytes() == x.odom.tobytes() and (y.tv, y.rv) == (x.tv, x.rv)


def test_odometry_with_no_finite_pose_stops_with_one_line_naming_the_field(scans, tmp_path, capsys):
    bag = tmp_path / "nan.mcap"
    _odometry_bag(bag, scans, broken=set(range(len(scans))))
    _fails(capsys, tmp_path, bag, match=f"/odom: none of its {len(scans)} poses is finite (x)")


def test_scans_recorded_out_of_stamp_order_are_read_in_stamp_order(scans, tmp_path):
    # Each pair of scans recorded swapped (a late message behind a newer one, stamps kept): read in record order,
    # the filter stepped the odometry back and forth and trajectory.tum went back in time at every pair. Now the
    # scans come in stamp order, each the clean bag's to the byte.
    clean, swapped = tmp_path / "clean.mcap", tmp_path / "swapped.mcap"
    n = 2 * (len(scans) // 2)
    with BagOut(clean) as b:
        for s in scans[:n]:
            _odom(b, s)
            _laser(b, "/scan", s, frame="base_link")
    with BagOut(swapped) as b:
        for s in scans[:n]:
            _odom(b, s)
        for k in range(0, n, 2):
            for s, rec in ((scans[k + 1], scans[k].t), (scans[k], scans[k + 1].t)):
                _laser(b, "/scan", s, frame="base_link", t=rec, stamp=s.t)
    a, b = list(open_bag(clean).scans), list(open_bag(swapped).scans)
    assert len(a) == len(b) == n
    assert [s.t for s in b] == sorted(s.t for s in b)
    for x, y in zip(a, b):
        assert (x.t, x.odom.tobytes(), x.ranges.tobytes()) == (y.t, y.odom.tobytes(), y.ranges.tobytes())


def _recompress(src: Path, folder: Path, storage: str, mode: str) -> None:
    """Rewrite the ROS 2 bag ``src`` as the rosbag2 folder ``folder``, compressed as ``ros2 bag record
    --compression-mode MODE --compression-format zstd`` does (mode storage: MCAP's own zstd chunks)."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    w = Writer(folder, version=9, storage_plugin=plugin)
    w.set_compression(CompressionMode[mode.upper()], CompressionFormat.ZSTD)
    with AnyReader([src]) as r:
        w.open()
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=r.typestore) for c in r.connections}
        for c, t, raw in r.messages():
            w.write(conns[c.id], t, raw)
        w.close()


@pytest.mark.parametrize("storage, mode", [("db3", "message"), ("db3", "file"), ("mcap", "message"),
                                           ("mcap", "storage")])
def test_a_compressed_rosbag2_recording_reads_through_its_folder(scans, tmp_path, capsys, storage, mode):
    # Only the folder's metadata.yaml says a message-compressed .db3 or .mcap holds zstd frames, not messages,
    # and a file-compressed recording's one file is a .db3.zstd: given the folder or the file in it, mcl reads the
    # folder. Records compared with the uncompressed bag's, one by one.
    plain = tmp_path / f"plain.{storage}"
    write_scans(plain, scans)
    folder = tmp_path / "rec"
    _recompress(plain, folder, storage, mode)
    (inner,) = [p for p in folder.iterdir() if p.name != "metadata.yaml"]
    assert inner.name.endswith(".zstd") == (mode == "file")
    for given in (folder, inner):
        got = list(open_bag(given).scans)
        assert len(got) == len(scans) > 30
        for a, b in zip(scans, got):
            _same_records(a, b)
    if mode == "message":  # the file alone, without its metadata.yaml: one line that says why
        lone = tmp_path / f"lone.{storage}"
        lone.write_bytes(inner.read_bytes())
        _fails(capsys, tmp_path, lone, match="recorded with message compression reads only through its folder")


@pytest.mark.parametrize("fmt", ["BZ2", "LZ4"])
def test_a_ros1_bag_with_compressed_chunks_reads_the_same_records(scans, tmp_path, fmt):
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer

    plain, packed = tmp_path / "plain.bag", tmp_path / "packed.bag"
    write_scans(plain, scans)
    w = Writer(packed)
    w.set_compression(getattr(Writer.CompressionFormat, fmt))
    with AnyReader([plain]) as r:
        w.open()
        conns = {c.id: w.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
                 for c in r.connections}
        for c, t, raw in r.messages():
            w.write(conns[c.id], t, raw)
        w.close()
    assert packed.read_bytes() != plain.read_bytes()
    got = list(open_bag(packed).scans)
    assert len(got) == len(scans) > 30
    for a, b in zip(scans, got):
        _same_records(a, b)


@pytest.mark.parametrize("kind", list(KINDS))
def test_truncated_bag(scans, tmp_path, capsys, kind):
    bag = tmp_path / f"full.{KINDS[kind]}"
    write_scans(bag, scans)
    data = bag.read_bytes()
    cut = tmp_path / f"cut.{KINDS[kind]}"
    cut.write_bytes(data[: len(data) // 2])
    _fails(capsys, tmp_path, cut, match="truncated or corrupt")


@pytest.mark.parametrize("kind", list(KINDS))
def test_corrupt_bag(scans, tmp_path, capsys, kind):
    # 512 random bytes at each eighth of the file: broken records (bag1), chunks (mcap), database pages (db3).
    # (Bytes changed only inside a message's float payload decode as other floats: no format can tell.)
    bag = tmp_path / f"c.{KINDS[kind]}"
    write_scans(bag, scans)
    data = bytearray(bag.read_bytes())
    rng = np.random.default_rng(0)
    for k in range(1, 8):
        at = k * len(data) // 8
        data[at:at + 512] = rng.integers(0, 256, 512, dtype=np.uint8).tobytes()
    bag.write_bytes(bytes(data))
    _fails(capsys, tmp_path, bag, match="truncated or corrupt")


def test_an_mcap_of_ros1_messages_is_named_not_called_corrupt(tmp_path, capsys):
    # `mcap convert in.bag out.mcap` (Foxglove's advice) writes profile ros1, which rosbags does not read: it was
    # reported as "truncated or corrupt?". The smallest such file: magic, a Header of profile ros1, an empty
    # DataEnd, a Footer, magic.
    import struct

    def record(op, body):
        return bytes([op]) + struct.pack("<Q", len(body)) + body

    def text(x):
        return struct.pack("<I", len(x)) + x.encode()

    magic = b"\x89MCAP0\r\n"
    bag = tmp_path / "converted.mcap"
    bag.write_bytes(magic + record(0x01, text("ros1") + text("test")) + record(0x0F, struct.pack("<I", 0))
                    + record(0x02, struct.pack("<QQI", 0, 0, 0)) + magic)
    err = _fails(capsys, tmp_path, bag, match="an MCAP file of ROS 1 messages (profile ros1")
    assert "give the .bag itself" in err and "corrupt" not in err


def test_bag_without_map_needs_map(scans, tmp_path, capsys):
    bag = tmp_path / "nomap.mcap"
    write_scans(bag, scans)
    out = tmp_path / "out"
    assert main(["run", "--bag", str(bag), "--out", str(out), "--rerun", "off"]) == 2
    err = capsys.readouterr().err.strip()
    assert "no /map in" in err and str(bag) in err and not out.exists()


def test_convert_never_leaves_a_half_written_output(scans, tmp_path, capsys):
    bad = tmp_path / "bad.clf"
    bad.write_text("FLASER 3 1 2 3 0 0 0 0 0 0 1.0 h 1.0\nFLASER 3 1 2 x 0 0 0 0 0 0 2.0 h 2.0\n")
    assert main(["convert", str(bad), str(tmp_path / "o.mcap")]) == 2
    assert "bad.clf:2" in capsys.readouterr().err
    # A failure while the bag is being written (here: an exception after 5 scans) leaves neither the bag nor
    # the writer's temporary folder.
    with pytest.raises(RuntimeError):
        write_scans(tmp_path / "p.bag", _explode_after(scans, 5))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.clf"]


def _explode_after(items, n):
    for k, s in enumerate(items):
        if k == n:
            raise RuntimeError("stop")
        yield s


# ----------------------------------------------------------------------------- helpers writing raw messages


@pytest.mark.parametrize("suffix", ["mcap", "clf"])
def test_convert_stopped_by_sigterm_leaves_nothing(tmp_path, suffix):
    # SIGTERM (kill, timeout) killed `mcl convert` at once: no line, and a .partial file or a hidden temporary bag
    # folder left behind. Now it stops as Ctrl-C does (exit 130, "mcl: interrupted") and removes what it wrote.
    # The signal is sent by the process to itself at the 20th scan written.
    import subprocess
    import sys

    demo = Path(__file__).resolve().parents[1] / "data" / "demo" / "log.clf"
    src = demo
    if suffix == "clf":  # a bag to convert back
        src = tmp_path / "in.mcap"
        assert main(["convert", str(demo), str(src)]) == 0
    out = tmp_path / "out" / f"x.{suffix}"
    out.parent.mkdir()
    hook = ("_clf_line_of" if suffix == "clf" else "BagOut.write")
    code = f"""
import os, signal, sys
import mcl.datasets.bagwrite as bw
from mcl.cli import main
owner, name = (bw.BagOut, "write") if "{hook}" == "BagOut.write" else (bw, "_clf_line_of")
real, n = getattr(owner, name), [0]
def counted(*a, **k):
    n[0] += 1
    if n[0] == 20:
        os.kill(os.getpid(), signal.SIGTERM)
    return real(*a, **k)
setattr(owner, name, counted)
sys.exit(main(["convert", {str(src)!r}, {str(out)!r}]))
"""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 130 and p.stderr.strip().endswith("mcl: interrupted"), p.stderr
    assert list(out.parent.iterdir()) == []


def test_an_initial_pose_given_after_the_robot_moved_is_carried_back_to_the_first_scan(world, scans, tmp_path):
    # RViz's 2D Pose Estimate some way into a recording says where the robot was then; it was applied at the first
    # scan, metres from where the robot was (a TurtleBot bag: ATE 1.4 m, max 6.6 m). It is now carried back through
    # the odometry to the first scan (AMCL applies it at its own stamp, which a replay from the start cannot), with
    # a note. Bound: the generated odometry's error over the gap (6 s, about 3 m of path; its heading noise is
    # about 0.08 rad in 5 s): measured 0.19 m and 0.12 rad; 0.3 m and 0.2 rad, against over a metre used as given.
    from mcl.datasets.bagwrite import BagOut

    t_ref, ref = read_tum(world / "truth.tum")
    k = 30  # the pose given at the 31st scan
    at = np.array([np.interp(scans[k].t, t_ref, ref[i]) for i in range(3)])
    first = ref[:, np.argmin(np.abs(t_ref - scans[0].t))]
    assert math.hypot(*(at[:2] - first[:2])) > 1.0  # used as it is, the start would be over a metre off
    bag = tmp_path / "late.mcap"
    with BagOut(bag) as b:
        for i, s in enumerate(scans):
            _odom(b, s)
            _laser(b, "/scan", s)
            if i == k:
                cov = b.msg("geometry_msgs/msg/PoseWithCovariance", pose=b.pose(*at), covariance=np.eye(6).ravel() * 0.01)
                b.write("/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped", s.t,
                        b.msg("geometry_msgs/msg/PoseWithCovarianceStamped", header=b.header(s.t, "map"), pose=cov))
    src = open_bag(bag)
    got = src.initial_pose[0]
    assert math.hypot(got[0] - first[0], got[1] - first[1]) < 0.3
    assert abs(math.remainder(got[2] - first[2], 2 * math.pi)) < 0.2
    assert any("/initialpose: stamped" in n and "carried back" in n for n in src.notes), src.notes


def test_a_zero_stamped_initial_pose_in_a_simulators_bag_is_timed_on_the_scans_clock(world, scans, tmp_path):
    # A simulator's bag (`ros2 bag record` without --use-sim-time): header stamps from 0 on the simulated clock,
    # record times on the wall clock. `ros2 topic pub /initialpose` sends stamp 0, and its record time was taken as its
    # stamp: 1.7e9 s "after the first scan", carried back through the odometry clamped at its end (a start 9.8 m
    # off, or off the map). Its record time is now moved onto the scans' clock by their lag, and carried back as a
    # stamped one is (the same bound as the test above). A pose stamped on another clock than the odometry's is
    # taken at the first scan, with a warning.
    wall = 1.7e9
    t_ref, ref = read_tum(world / "truth.tum")
    k = 30
    at = np.array([np.interp(scans[k].t, t_ref, ref[i]) for i in range(3)])
    first = ref[:, np.argmin(np.abs(t_ref - scans[0].t))]
    assert math.hypot(*(at[:2] - first[:2])) > 1.0
    for stamp, name in ((0.0, "zero"), (scans[k].t + wall, "wall")):
        bag = tmp_path / f"sim-{name}.mcap"
        with BagOut(bag) as b:
            for i, s in enumerate(scans):
                _odom(b, types.SimpleNamespace(t=s.t + wall, odom=s.odom), stamp=s.t)
                _laser(b, "/scan", s, t=s.t + wall, stamp=s.t)
                if i == k:
                    cov = b.msg("geometry_msgs/msg/PoseWithCovariance", pose=b.pose(*at),
                                covariance=np.eye(6).ravel() * 0.01)
                    b.write("/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped", s.t + wall,
                            b.msg("geometry_msgs/msg/PoseWithCovarianceStamped", header=b.header(stamp, "map"),
                                  pose=cov))
        src = open_bag(bag)
        got = src.initial_pose[0]
        if name == "zero":
            assert math.hypot(got[0] - first[0], got[1] - first[1]) < 0.3
            assert abs(math.remainder(got[2] - first[2], 2 * math.pi)) < 0.2
            assert any("/initialpose: stamped" in n and "carried back" in n for n in src.notes), src.notes
        else:
            np.testing.assert_allclose(got, at)
            assert any("/initialpose: stamped" in w and "outside the odometry's" in w and "another clock" in w
                       for w in src.warnings), src.warnings


def test_a_truth_topic_in_another_frame_is_warned_about_and_the_summary_names_the_topic(world, scans, tmp_path):
    # `--truth-topic /odom` scored the run against the odometry's frame (17 m) without a word, and summary.json said
    # "truth": null for a run scored against a topic. Now a reference in a frame other than the map's is a warning,
    # and the summary names the bag and the topic.
    t, poses = read_tum(world / "truth.tum")
    bag = tmp_path / "t.mcap"
    write_scans(bag, scans, truth=(t, poses), truth_topic="/ground_truth")
    topics = lambda name: load_config(None, [f"topics.truth={name}"]).topics  # noqa: E731
    assert not [w for w in open_bag(bag, topics("/ground_truth")).warnings if "reference poses" in w]
    said = [w for w in open_bag(bag, topics("/odom")).warnings if "reference poses" in w]
    assert len(said) == 1 and "/odom: the reference poses are in frame 'odom', not the map's ('map')" in said[0]
    s, _ = _run(tmp_path, "scored", bag=bag, **{"topics.truth": "/ground_truth"})
    assert s["truth"] == f"{bag}: /ground_truth" and "ate_rmse" in s["eval"]


def test_a_ros1_bag_records_nothing_before_ros_time_min(world, tmp_path):
    # mcl simulate's log starts at t = 0, and its first scan, odometry and the one /tf_static were recorded at 0 in a
    # .bag: ROS 1 has no such record time (rosbag's Bag::write refuses it; rosbag play and rqt_bag read from
    # ros::TIME_MIN = 1 ns and skipped them, so the laser had no mounting). Record times are now at least 1 ns; the
    # header stamps stay the log's, and mcl reads the same records.
    from rosbags.highlevel import AnyReader

    log = read_carmen(world / "log.clf").laser_stream()
    assert log[0].t == 0.0
    bag = tmp_path / "sim.bag"
    write_scans(bag, log)
    with AnyReader([bag]) as r:
        rows = [(c.topic, t, r.deserialize(raw, c.msgtype)) for c, t, raw in r.messages()]
    assert min(t for _, t, _ in rows) >= 1
    first = {topic: m for topic, _, m in reversed(rows)}
    stamp = lambda h: (h.stamp.sec, h.stamp.nanosec)  # noqa: E731
    assert stamp(first["/scan"].header) == (0, 0) and stamp(first["/odom"].header) == (0, 0)
    assert stamp(first["/tf_static"].transforms[0].header) == (0, 0)
    for a, b in zip(log, open_bag(bag).scans):
        _same_records(a, b)


@pytest.mark.parametrize("case", ["ekf", "nav2"])
def test_write_bag_says_when_the_input_holds_a_localizers_map_to_odom_already(world, scans, tmp_path, case):
    # robot_pose_ekf's bag recorded a localizer's map -> odom_combined on /tf: beside the estimate bag's own
    # map -> odom_combined, RViz gets two parents of odom_combined. Said in one line; a bag without one says nothing.
    bag = tmp_path / f"{case}.bag"
    _frames_bag(bag, scans, case)
    said = []
    cfg = load_config(None, ["rerun.mode=off", "filter.particles=300", f"map={world / 'map.yaml'}", "log=null",
                             f"bag={bag}", "truth=null"])
    run(cfg, tmp_path / "r", progress=False, echo=said.append, write_bag=True)
    notes = [m for m in said if "already holds" in m]
    if case == "ekf":
        assert notes == [f"{bag}: /tf already holds map -> odom_combined (a localizer's, recorded): played beside "
                         "estimate.bag, RViz receives two parents of odom_combined and shows each in turn"]
    else:
        assert notes == []


def test_the_same_odometry_on_odom_and_tf_with_a_repeated_stamp_is_not_called_an_ekfs():
    # One message stamped 0.5 s early lands on an earlier one's stamp, on /odom and on /tf alike. Interpolating /tf's
    # link at that stamp gives one of the two poses, and the other topic row was 0.24 m from it: a note said /tf's
    # link "(an EKF's?) differs from /odom", and an estimate bag's map -> odom would have been computed from /tf.
    # Each row is now compared with the nearest pose /tf holds at its stamp. A link that really differs still does.
    from mcl.datasets.rosbag import _tf_beside

    t = 0.1 * np.arange(20)
    t[10] = t[5]  # the early stamp
    rows = np.column_stack([t, 0.05 * np.arange(20), np.zeros(20), 0.01 * np.arange(20), np.zeros(20), np.zeros(20),
                            100.0 + 0.1 * np.arange(20)])
    odometry = rows[np.argsort(rows[:, 0], kind="stable"), :6]
    assert np.ptp(rows[[5, 10], 1]) > 0.2
    assert _tf_beside([tuple(r) for r in rows], odometry, "odom -> base_link", "b.bag") is None
    drifted = rows.copy()
    drifted[:, 1] += 0.002 * np.arange(20) ** 2  # an EKF's link drifting off the wheels' (up to 0.72 m)
    got = _tf_beside([tuple(r) for r in drifted], odometry, "odom -> base_link", "b.bag")
    assert got is not None and got[1] == pytest.approx(0.722, abs=1e-9)
