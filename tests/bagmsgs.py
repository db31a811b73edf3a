"""Message helpers shared by the bag tests (tests/test_rosbag.py, tests/test_laser_odometry.py,
tests/test_fused_checks.py): an Odometry, a LaserScan, a tilted laser mounting on /tf and a MultiEchoLaserScan,
written with mcl.datasets.bagwrite.BagOut; and the demo as a CARMEN log of a front and a rear laser."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from mcl.datasets.bagwrite import BagOut

DEMO = Path(__file__).resolve().parents[1] / "data" / "demo"


def tilted(b: BagOut, t: float, parent: str, child: str, xyz, pitch: float):
    """A TransformStamped parent -> child at ``xyz`` pitched by ``pitch`` (rad, about y)."""
    tr = b.msg("geometry_msgs/msg/Transform",
               translation=b.msg("geometry_msgs/msg/Vector3", x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
               rotation=b.msg("geometry_msgs/msg/Quaternion", x=0.0, y=math.sin(pitch / 2), z=0.0,
                              w=math.cos(pitch / 2)))
    return b.msg("geometry_msgs/msg/TransformStamped", header=b.header(t, parent), child_frame_id=child, transform=tr)


def multi_echo(b: BagOut, topic: str, s, echoes, *, frame="laser") -> None:
    """A MultiEchoLaserScan of ``s``'s geometry whose beam i holds the returns ``echoes[i]`` (m)."""
    E, M = "sensor_msgs/msg/LaserEcho", "sensor_msgs/msg/MultiEchoLaserScan"
    beams = [b.msg(E, echoes=np.asarray(e, dtype=np.float32)) for e in echoes]
    b.write(topic, M, s.t, b.msg(M, header=b.header(s.t, frame), angle_min=s.angle_min,
                                 angle_max=s.angle_min + s.angle_increment * (len(beams) - 1),
                                 angle_increment=s.angle_increment, time_increment=0.0, scan_time=0.0, range_min=0.0,
                                 range_max=s.max_range, ranges=beams, intensities=[]))


def odom(b: BagOut, s, stamp=None, child="base_link", pose=None, frame="odom", twist=(0.0, 0.0)) -> None:
    """An Odometry on /odom at scan ``s``: its odometry pose (or ``pose``) of ``child`` in ``frame``, velocities
    ``twist`` (linear x, angular z; none by default)."""
    cov = b.msg("geometry_msgs/msg/PoseWithCovariance", pose=b.pose(*(s.odom if pose is None else pose)),
                covariance=np.zeros(36))
    v3 = lambda x, z: b.msg("geometry_msgs/msg/Vector3", x=x, y=0.0, z=z)  # noqa: E731
    tw = b.msg("geometry_msgs/msg/TwistWithCovariance",
               twist=b.msg("geometry_msgs/msg/Twist", linear=v3(float(twist[0]), 0.0),
                           angular=v3(0.0, float(twist[1]))),
               covariance=np.zeros(36))
    h = b.header(s.t if stamp is None else stamp, frame)
    b.write("/odom", "nav_msgs/msg/Odometry", s.t, b.msg("nav_msgs/msg/Odometry", header=h,
                                                        child_frame_id=child, pose=cov, twist=tw))


def laser(b: BagOut, topic: str, s, *, frame="laser", ranges=None, range_min=0.0, t=None, stamp=None) -> None:
    """A LaserScan on ``topic`` of scan ``s``'s geometry and readings (or ``ranges``) in ``frame``, written at ``t``
    (default ``s.t``) and stamped ``stamp`` (default ``t``)."""
    r = np.asarray(s.ranges if ranges is None else ranges, dtype=np.float32)
    t = s.t if t is None else t
    L = "sensor_msgs/msg/LaserScan"
    b.write(topic, L, t, b.msg(L, header=b.header(t if stamp is None else stamp, frame), angle_min=s.angle_min,
                                angle_max=s.angle_min + s.angle_increment * (r.size - 1),
                                angle_increment=s.angle_increment, time_increment=0.0, scan_time=0.0,
                                range_min=range_min, range_max=s.max_range, ranges=r,
                                intensities=np.zeros(0, dtype=np.float32)))


def fused_log(tmp_path, rear_yaw: float):
    """The demo's log with each FLASER line repeated as an RLASER line of the same readings, its laser pose the
    robot's turned by ``rear_yaw`` (pi: declared looking back while its scans look ahead, the mounting at fault)."""
    out = []
    for line in (DEMO / "log.clf").read_text().splitlines(keepends=True):
        out.append(line)
        if line.startswith("FLASER"):
            f = line.split()
            n = int(f[1])
            ox, oy, oth = (float(v) for v in f[n + 5:n + 8])
            th = math.atan2(math.sin(oth + rear_yaw), math.cos(oth + rear_yaw))
            out.append(" ".join(["RLASER", *f[1:n + 2], f"{ox:.6f}", f"{oy:.6f}", f"{th:.6f}", *f[n + 5:]]) + "\n")
    path = tmp_path / f"fused-{rear_yaw:g}.clf"
    path.write_text("".join(out))
    return path
