"""Message helpers shared by the bag tests (tests/test_rosbag.py, tests/test_laser_odometry.py): a tilted
laser mounting on /tf and a MultiEchoLaserScan, written with mcl.datasets.bagwrite.BagOut."""

from __future__ import annotations

import math

import numpy as np

from mcl.datasets.bagwrite import BagOut


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
