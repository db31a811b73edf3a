"""Writing ROS bags (ROS 1 ``.bag``, ROS 2 ``.db3`` / ``.mcap``) with the ``rosbags`` writers, and ``mcl convert``.

:class:`BagOut` writes messages into a bag that appears under its final name only when closed (a half-written bag
is never left: the writers work in a temporary file or folder next to it). :func:`write_scans` writes a stream of
:class:`mcl.datasets.carmen.Scan` records as a bag mcl reads back unchanged: ``/scan`` (LaserScan, frame
``laser``), the odometry as ``/odom`` (nav_msgs/Odometry) and as ``odom -> base_link`` on ``/tf`` (by default both,
as a ROS robot's bag has them, REP 105: ROS AMCL and RViz place the laser through /tf; or either alone), the laser
mounting ``base_link -> laser`` on ``/tf_static``, and optionally ``/map``, ``/initialpose`` and a truth topic.
:func:`convert` turns a bag into a CARMEN log (ROBOTLASER1 + ODOM lines, every number in round-trip precision)
and a CARMEN log into a bag. A fused stream's lasers are each kept: a bag's two as ROBOTLASER1 and ROBOTLASER2 (a
CARMEN log holds no more), a log's front and rear lasers on ``/front/scan`` and ``/rear/scan``.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from decimal import Decimal
from pathlib import Path

import numpy as np

from mcl.datasets.rosbag import BAG_SUFFIXES, is_bag
from mcl.errors import ConfigError, DataError

__all__ = ["BagOut", "write_scans", "convert", "kind_of_output"]


def kind_of_output(path) -> str:
    """bag1, db3, mcap or clf from an output name."""
    p = Path(path)
    if p.suffix in BAG_SUFFIXES:
        return BAG_SUFFIXES[p.suffix]
    if p.suffix in (".clf", ".log", ".gz"):
        return "clf"
    raise DataError(f"{p}: unknown output kind (use .clf, .bag, .db3 or .mcap)")


def _stamp(t: float) -> tuple[int, int]:
    """float seconds -> (sec, nanosec) from the shortest decimal of ``t`` (read back exactly by stamp_seconds)."""
    d = Decimal(repr(float(t)))
    sec = int(d.to_integral_value(rounding="ROUND_FLOOR"))
    ns = int(((d - sec) * 1_000_000_000).to_integral_value())
    if ns >= 1_000_000_000:
        sec, ns = sec + 1, ns - 1_000_000_000
    return sec, ns


def _quat(yaw: float):
    return 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)


class BagOut:
    """A bag being written: ``write(topic, msgtype, t, **fields)``; :meth:`close` publishes it, :meth:`abort`
    removes it. ``kind``: bag1, db3 or mcap."""

    def __init__(self, path, kind: str | None = None):
        from rosbags.typesys import Stores, get_typestore, get_types_from_msg

        self.path = Path(path)
        self.kind = kind or BAG_SUFFIXES.get(self.path.suffix)
        if self.kind not in ("bag1", "db3", "mcap"):
            raise DataError(f"{self.path}: a bag's name ends in .bag, .db3 or .mcap")
        self.ros1 = self.kind == "bag1"
        if self.ros1:
            self.ts = get_typestore(Stores.ROS1_NOETIC)
            self.ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
        else:
            self.ts = get_typestore(Stores.ROS2_HUMBLE)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", dir=self.path.parent))
        try:
            if self.ros1:
                from rosbags.rosbag1 import Writer

                self._file = self._tmp / "out.bag"
                self.writer = Writer(self._file)
            else:
                from rosbags.rosbag2 import StoragePlugin, Writer

                plugin = StoragePlugin.MCAP if self.kind == "mcap" else StoragePlugin.SQLITE3
                # the folder named as the file will be: rosbag2 names its file after it, and the metadata the file
                # carries lists that name (it said out.mcap for every bag)
                stem = self.path.stem
                self._file = self._tmp / stem / f"{stem}.{'mcap' if self.kind == 'mcap' else 'db3'}"
                self.writer = Writer(self._tmp / stem, version=9, storage_plugin=plugin)
            self.writer.open()
        except BaseException:
            shutil.rmtree(self._tmp, ignore_errors=True)
            raise
        self._conns: dict[str, object] = {}
        self._last_ns = 0
        self._seq = 0

    # --- message building
    def msg(self, msgtype: str, **fields):
        return self.ts.types[msgtype](**fields)

    def header(self, t: float, frame: str):
        sec, ns = _stamp(t)
        stamp = self.msg("builtin_interfaces/msg/Time", sec=sec, nanosec=ns)
        if self.ros1:
            self._seq += 1
            return self.msg("std_msgs/msg/Header", seq=self._seq, stamp=stamp, frame_id=frame)
        return self.msg("std_msgs/msg/Header", stamp=stamp, frame_id=frame)

    def pose(self, x: float, y: float, yaw: float):
        qx, qy, qz, qw = _quat(yaw)
        return self.msg("geometry_msgs/msg/Pose",
                        position=self.msg("geometry_msgs/msg/Point", x=float(x), y=float(y), z=0.0),
                        orientation=self.msg("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw))

    def transform(self, t: float, parent: str, child: str, p):
        qx, qy, qz, qw = _quat(float(p[2]))
        tr = self.msg("geometry_msgs/msg/Transform",
                      translation=self.msg("geometry_msgs/msg/Vector3", x=float(p[0]), y=float(p[1]), z=0.0),
                      rotation=self.msg("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw))
        return self.msg("geometry_msgs/msg/TransformStamped", header=self.header(t, parent), child_frame_id=child,
                        transform=tr)

    def cov36(self, cov3=None):
        c = np.zeros(36)
        if cov3 is not None:
            idx = [0, 1, 5]
            for a in range(3):
                for b in range(3):
                    c[idx[a] * 6 + idx[b]] = cov3[a][b]
        return c

    def serialize(self, message, msgtype: str):
        """``message``'s bytes in the bag's encoding (ROS 1, or CDR with its 4-byte encapsulation header)."""
        return self.ts.serialize_ros1(message, msgtype) if self.ros1 else self.ts.serialize_cdr(message, msgtype)

    POSE_ARRAY = "geometry_msgs/msg/PoseArray"

    def pose_array(self, t: float, frame: str, poses) -> bytes:
        """The serialized PoseArray of planar ``poses`` ((3, N): x, y, theta; z 0, the quaternion of the yaw, as
        :meth:`pose`), built with numpy: the bytes :meth:`serialize` gives for the message of N :meth:`pose` s
        (tests/test_rosbag.py), at a fraction of the cost (a Python object per pose cost 2.6 ms for 1000).
        The header and the uint32 count as the serializer writes them; then N x 7 float64 (position x, y, z,
        orientation x, y, z, w), ROS 1 unaligned, CDR's first aligned to 8 from the end of the encapsulation header."""
        p = np.asarray(poses, dtype=np.float64).reshape(3, -1)
        head = bytes(self.serialize(self.msg(self.POSE_ARRAY, header=self.header(t, frame), poses=[]),
                                    self.POSE_ARRAY))
        # the empty message ends with the poses' count, 0: replaced by N
        little = self.ros1 or head[1] == 1  # CDR encapsulation 0x0001: little-endian, 0x0000: big
        end = "<" if little else ">"
        n = p.shape[1]
        out = [head[:-4], np.array(n, dtype=f"{end}u4").tobytes()]
        if not self.ros1 and n:  # the first float64 aligned to 8 in the body (no padding without one)
            out.append(b"\0" * ((-(len(head) - 4)) % 8))
        a = np.zeros((n, 7), dtype=f"{end}f8")
        a[:, 0], a[:, 1] = p[0], p[1]
        half = 0.5 * p[2]
        a[:, 5], a[:, 6] = np.sin(half), np.cos(half)
        out.append(a.tobytes())
        return b"".join(out)

    # --- writing
    def write(self, topic: str, msgtype: str, t: float, message) -> None:
        """Write ``message`` on ``topic``, logged at its stamp ``t`` (kept non-decreasing, as a recorder's clock)."""
        self.write_raw(topic, msgtype, t, self.serialize(message, msgtype))

    def write_raw(self, topic: str, msgtype: str, t: float, data) -> None:
        """Write ``data``, a ``msgtype`` already serialized in the bag's encoding, as :meth:`write` does."""
        conn = self._conns.get(topic)
        if conn is None:
            conn = self._conns[topic] = self.writer.add_connection(topic, msgtype, typestore=self.ts,
                                                                   **self._latched(topic))
        sec, ns = _stamp(t)
        # ROS 1 has no record time 0: rosbag's C++ API (rosbag play, rqt_bag) reads from ros::TIME_MIN = 1 ns and
        # skipped a log's messages at t = 0 (mcl simulate's first scan, odometry and the only /tf_static); the header
        # stamps stay the log's
        log_ns = max(sec * 1_000_000_000 + ns, self._last_ns, 1 if self.ros1 else 0)
        self._last_ns = log_ns
        self.writer.write(conn, log_ns, data)

    LATCHED = ("/map", "/tf_static")  # published once, kept for late subscribers (map_server, the static broadcaster)

    def _latched(self, topic: str) -> dict:
        """add_connection's keywords for a latched topic: ROS 1 ``latching``, ROS 2 a transient-local QoS, as
        map_server and tf2's static broadcaster offer them (without, `rosbag play` / `ros2 bag play` replays the one
        /map and /tf_static message to the subscribers there at that instant only: amcl or RViz started later,
        or tf2's transient-local static listener, never get them)."""
        if topic not in self.LATCHED:
            return {}
        if self.ros1:
            return {"latching": 1}
        from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

        never = QosTime(9223372036, 854775807)  # rclcpp's infinite duration
        return {"offered_qos_profiles": [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE,
                                             QosDurability.TRANSIENT_LOCAL, never, never, QosLiveliness.AUTOMATIC,
                                             never, False)]}

    def close(self) -> None:
        """Finish the bag and move it to its final name."""
        if self.writer is None:
            return
        w, self.writer = self.writer, None
        try:
            w.close()
            os.replace(self._file, self.path)
        finally:
            shutil.rmtree(self._tmp, ignore_errors=True)

    def abort(self) -> None:
        """Drop the bag being written."""
        if self.writer is not None:
            w, self.writer = self.writer, None
            try:
                w.close()
            except Exception:
                pass
        shutil.rmtree(self._tmp, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def _compose(a, b):
    c, s = math.cos(a[2]), math.sin(a[2])
    th = a[2] + b[2]
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], math.atan2(math.sin(th), math.cos(th)))


def _inverse(a):
    c, s = math.cos(a[2]), math.sin(a[2])
    return (-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2])


def _lasers_of(scans) -> tuple[list[str], dict]:
    """The lasers of a scan stream in order (``Scan.kind``: a bag's topic, a CARMEN message type) and each one's
    mounting (its first scan's ``laser_offset``; None: unknown). A bag's stream says them (``topics``,
    ``offsets``) without a pass over its messages."""
    if hasattr(scans, "topics") and hasattr(scans, "offsets"):
        return list(scans.topics), {t: scans.offsets.get(t) for t in scans.topics}
    offsets: dict = {}
    for s in scans:
        offsets.setdefault(s.kind, s.laser_offset)
    return list(offsets), offsets


_FRONT, _REAR = ("FLASER", "ROBOTLASER1"), ("RLASER", "ROBOTLASER2")


def laser_names(lasers: list[str]) -> dict[str, tuple[str, str]]:
    """Each laser's (topic, frame) in a bag written. One laser: ``/scan`` in frame ``laser``. Several (fused): a
    bag's own topics; a CARMEN log's front laser (FLASER, ROBOTLASER1) on ``/front/scan`` in ``front_laser``, its
    rear one (RLASER, ROBOTLASER2) on ``/rear/scan`` in ``rear_laser``, RAWLASERk on ``/rawlaserk/scan``; none on
    /scan, which ``topics.scan: auto`` would read alone. Each frame is named after its topic (``/rear/scan``:
    ``rear_laser``)."""
    if len(lasers) == 1:
        return {lasers[0]: ("/scan", "laser")}
    out: dict[str, tuple[str, str]] = {}
    for k in lasers:
        topic = k if k.startswith("/") else (
            "/front/scan" if k in _FRONT else "/rear/scan" if k in _REAR else f"/{k.lower()}/scan")
        name = topic.strip("/")
        frame = (name[:-len("/scan")] if name.endswith("/scan") else name).replace("/", "_") + "_laser"
        i = 2
        while topic in (t for t, _ in out.values()) or frame in (f for _, f in out.values()):  # two formats of one
            topic, frame, i = f"{topic.rstrip('0123456789_')}_{i}", f"{frame}_{i}", i + 1     # laser (a list's)
        out[k] = (topic, frame)
    return out


ODOM_CHOICES = ("both", "topic", "tf")  # write_scans / convert ``odom``: where the odometry goes


def _check_odom(out, odom) -> None:
    if odom not in ODOM_CHOICES:
        raise ConfigError(f"{out}: odom {odom!r}: expected one of {', '.join(ODOM_CHOICES)} (where the odometry is "
                          "written: /odom and /tf, /odom alone, /tf alone)")


def write_scans(out, scans, *, odom: str = "both", mount=None, grid=None, initial=None, initial_frame: str = "map",
                truth=None, truth_topic: str = "/ground_truth", kind: str | None = None, sweep: float = 0.0) -> int:
    """Write ``scans`` (Scan records) as a bag (see the module doc); returns the number of scans written.

    odom: ``both`` (default: /odom, and odom -> base_link on /tf at the same stamps with the same poses, as a ROS
    robot records them), ``topic`` (/odom only) or ``tf`` (/tf only); another value is a ConfigError. mount:
    (x, y, theta) of the laser in a new base frame: the odometry is then that of base = robot ∘ laser_offset ∘
    mount⁻¹ (same laser poses, a laser off the base's centre; with several lasers, the first one's, the others kept
    where they are on the robot). Several lasers (a fused stream: ``Scan.kind`` tells them apart) go on topics and
    frames of their own (:func:`laser_names`), their mountings in the one ``/tf_static`` message.
    grid: an OccupancyGrid for /map; initial: ((x, y, theta), 3x3 cov) for /initialpose (in ``initial_frame``); truth: (t (K,), poses (3, K)) as PoseStamped on ``truth_topic``, each
    recorded at its time among the scans. Each LaserScan's time_increment is the scan's own beam time step
    (``Scan.beam_dt``, when its first beam is at the stamp), else ``sweep`` / (beams - 1): s from the first beam to
    the last (0: none).
    """
    _check_odom(out, odom)  # an unknown value wrote no odometry at all
    if not (isinstance(scans, list) or hasattr(scans, "topics")):
        scans = list(scans)  # a one-pass iterable: read twice below
    lasers, offsets = _lasers_of(scans)
    names = laser_names(lasers) if lasers else {}
    zero = (0.0, 0.0, 0.0)
    offsets = {k: zero if o is None else tuple(float(v) for v in o) for k, o in offsets.items()}
    # each laser's pose on base_link: as recorded; with ``mount``, in the new base B = robot ∘ T with
    # T = first laser's offset ∘ mount⁻¹ (the first laser at ``mount``, the others where they are on the robot)
    mnt = None if mount is None else tuple(float(v) for v in mount)
    T = None if mnt is None or not lasers else _compose(offsets[lasers[0]], _inverse(mnt))
    static = {k: o if T is None else _compose(_inverse(T), o) for k, o in offsets.items()}
    n = 0
    if truth is not None:  # in time order, each written among the scans at its own time (a bag's record times only
        tt, pp = truth     # go forward: written after the scans, every pose was recorded at the bag's end)
        order = np.argsort(np.asarray(tt, dtype=np.float64), kind="stable")
        tt, pp = np.asarray(tt, dtype=np.float64)[order], np.asarray(pp)[:, order]
    k = 0

    def truth_until(b: BagOut, t: float) -> None:
        nonlocal k
        while truth is not None and k < len(tt) and tt[k] <= t:
            b.write(truth_topic, "geometry_msgs/msg/PoseStamped", float(tt[k]),
                    b.msg("geometry_msgs/msg/PoseStamped", header=b.header(float(tt[k]), "map"), pose=b.pose(*pp[:, k])))
            k += 1

    with BagOut(out, kind) as b:
        L = "sensor_msgs/msg/LaserScan"
        first_t = None
        for s in scans:
            truth_until(b, s.t)
            if first_t is None:
                first_t = s.t
                if grid is not None:
                    _write_grid(b, grid, s.t)
                if initial is not None:
                    mean, cov = initial
                    pw = b.msg("geometry_msgs/msg/PoseWithCovariance", pose=b.pose(*mean), covariance=b.cov36(cov))
                    b.write("/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped", s.t,
                            b.msg("geometry_msgs/msg/PoseWithCovarianceStamped", header=b.header(s.t, initial_frame),
                                  pose=pw))
                # one message with every laser: a latched topic keeps the last message only
                b.write("/tf_static", "tf2_msgs/msg/TFMessage", s.t, b.msg(
                    "tf2_msgs/msg/TFMessage",
                    transforms=[b.transform(s.t, "base_link", names[las][1], static[las]) for las in lasers]))
            topic, frame = names[s.kind]
            off = zero if s.laser_offset is None else tuple(float(v) for v in s.laser_offset)
            # one laser: each scan's own mounting (its laser pose kept exactly); several: one rigid base for all
            # (the odometry at one stamp is one pose, whichever laser's scan it comes with)
            base = (tuple(float(v) for v in s.odom) if T is None else
                    _compose(_compose(s.odom, off), _inverse(static[s.kind])) if len(lasers) == 1 else
                    _compose(s.odom, T))
            if odom in ("topic", "both"):
                cov = b.msg("geometry_msgs/msg/PoseWithCovariance", pose=b.pose(*base), covariance=np.zeros(36))
                tw = b.msg("geometry_msgs/msg/TwistWithCovariance",
                           twist=b.msg("geometry_msgs/msg/Twist",
                                       linear=b.msg("geometry_msgs/msg/Vector3", x=float(s.tv), y=0.0, z=0.0),
                                       angular=b.msg("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=float(s.rv))),
                           covariance=np.zeros(36))
                b.write("/odom", "nav_msgs/msg/Odometry", s.t,
                        b.msg("nav_msgs/msg/Odometry", header=b.header(s.t, "odom"), child_frame_id="base_link",
                              pose=cov, twist=tw))
            if odom in ("tf", "both"):
                b.write("/tf", "tf2_msgs/msg/TFMessage", s.t,
                        b.msg("tf2_msgs/msg/TFMessage", transforms=[b.transform(s.t, "odom", "base_link", base)]))
            r = np.asarray(s.ranges, dtype=np.float32)
            ti = float(s.beam_dt) if s.beam_dt and s.beam_t0 == 0.0 else (sweep / (r.size - 1) if r.size > 1 else 0.0)
            rmax = float(s.max_range) if s.max_range is not None else math.inf
            b.write(topic, L, s.t, b.msg(
                L, header=b.header(s.t, frame), angle_min=float(s.angle_min),
                angle_max=float(s.angle_min + s.angle_increment * max(r.size - 1, 0)),
                angle_increment=float(s.angle_increment), time_increment=ti, scan_time=0.0, range_min=0.0,
                range_max=rmax, ranges=r, intensities=np.zeros(0, dtype=np.float32)))
            n += 1
        truth_until(b, math.inf)
        if n == 0:
            raise DataError(f"{out}: no scans to write")
    return n


def _with_odometry_velocities(scans: list, odometry) -> list:
    """``scans`` whose record carries no velocities (FLASER: tv = rv = 0) with those of the log's last ODOM line at
    or before each scan, as a ROS /odom message holds them (a bag's /odom twist was zero throughout)."""
    import dataclasses

    odo = np.asarray(odometry, dtype=np.float64).reshape(-1, 6)
    if not odo.shape[0] or not np.any(odo[:, 4:6]):
        return scans
    odo = odo[np.argsort(odo[:, 0], kind="stable")]
    last = np.searchsorted(odo[:, 0], np.array([s.t for s in scans], dtype=np.float64), side="right") - 1
    return [dataclasses.replace(s, tv=float(odo[j, 4]), rv=float(odo[j, 5])) if j >= 0 and s.tv == 0.0 and s.rv == 0.0
            else s for s, j in zip(scans, last)]


def _write_grid(b: BagOut, grid, t: float) -> None:
    h, w = grid.occupancy.shape
    info = b.msg("nav_msgs/msg/MapMetaData", map_load_time=b.header(t, "map").stamp, resolution=float(grid.resolution),
                 width=int(w), height=int(h), origin=b.pose(grid.origin[0], grid.origin[1], 0.0))
    b.write("/map", "nav_msgs/msg/OccupancyGrid", t,
            b.msg("nav_msgs/msg/OccupancyGrid", header=b.header(t, "map"), info=info,
                  data=np.ascontiguousarray(grid.occupancy, dtype=np.int8).ravel()))


def _clf_line_of(s, name: str = "ROBOTLASER1") -> str:
    """One scan as ``name`` (ROBOTLASER1, a second laser's ROBOTLASER2) + ODOM lines (numbers in shortest round-trip
    form)."""
    r = np.asarray(s.ranges, dtype=np.float64)
    off = (0.0, 0.0, 0.0) if s.laser_offset is None else tuple(float(v) for v in s.laser_offset)
    robot = tuple(float(v) for v in s.odom)
    laser = _compose(robot, off)
    rmax = repr(float(s.max_range)) if s.max_range is not None else "1e9"
    n = r.size
    ts = f"{float(s.t)!r} mcl {float(s.t)!r}"
    fov = float(s.angle_increment) * max(n - 1, 0)
    rs = " ".join(map(repr, r.tolist()))
    pose = lambda p: " ".join(repr(float(v)) for v in p)  # noqa: E731
    return (f"ODOM {pose(robot)} {float(s.tv)!r} {float(s.rv)!r} 0.0 {ts}\n"
            f"{name} 0 {float(s.angle_min)!r} {fov!r} {float(s.angle_increment)!r} {rmax} 0.01 0 {n} {rs} 0 "
            f"{pose(laser)} {pose(robot)} {float(s.tv)!r} {float(s.rv)!r} 0.0 0.0 0.0 {ts}\n")


def convert(src, out, *, topics=None, frames=None, odom: str = "both", mount=None, grid=None, initial=None,
            truth=None, laser: str = "auto", echo=print, sweep: float = 0.0, truth_name: str = "truth") -> int:
    """``mcl convert``: a bag to a CARMEN log, a CARMEN log (or a bag) to a bag. Returns the scans written.
    A ``truth`` given with a CARMEN log (named ``truth_name`` in an error) must have a pose within its scans' span."""
    from mcl.trajectory import LineWriter

    src, out = Path(src), Path(out)
    out_kind = kind_of_output(out)
    _check_odom(out, odom)  # before the source is read
    if is_bag(src):
        from mcl.datasets.rosbag import open_bag

        source = open_bag(src, topics, frames)
        for note in source.notes:
            echo(note)
        scans = source.scans
        if grid is None and source.grid is not None:
            grid = source.grid
        if initial is None and source.initial_pose is not None:
            initial = source.initial_pose
    else:
        from mcl.datasets.carmen import read_carmen

        log = read_carmen(src)
        for w in log.warnings:
            echo(f"mcl: warning: {w}")
        scans = _with_odometry_velocities(log.laser_stream(laser), log.odometry)
        for note in log.notes:
            echo(note)
        if log.landmarks and out_kind != "clf":  # no bag message carries them: said, not dropped in silence
            echo(f"mcl: note: {src}: {len(log.landmarks)} LANDMARK lines not written: a bag has no message for them "
                 "(a run with landmarks.use needs the CARMEN log)")
    if truth is not None and isinstance(scans, list) and scans and len(truth[0]):  # a log's scans (a bag's: mcl run)
        t0, t1 = scans[0].t, scans[-1].t
        if not np.any((truth[0] >= t0) & (truth[0] <= t1)):  # written, it would score nothing: another clock
            raise DataError(f"{truth_name}: no pose lies within the scans' time span ({t0:.3f}..{t1:.3f} s; the "
                            f"reference {truth[0].min():.3f}..{truth[0].max():.3f} s): another clock or another log?")
    if is_bag(src) and truth is None and source.truth is not None:
        truth = source.truth
    if out_kind != "clf":
        return write_scans(out, scans, odom=odom, mount=mount, grid=grid, initial=initial, truth=truth,
                           kind=out_kind, sweep=sweep)
    lasers = _lasers_of(scans)[0]
    if len(lasers) > 2:  # before anything is written
        raise DataError(f"{src}: {len(lasers)} lasers fused ({', '.join(lasers)}); a CARMEN log holds two "
                        "(ROBOTLASER1, ROBOTLASER2): choose them with --scan-topic (topics.scan)")
    line_of = dict(zip(lasers, ("ROBOTLASER1", "ROBOTLASER2")))
    w = LineWriter(out, header=f"# mcl convert {src.name}: {' and '.join(line_of.values())} + ODOM per scan; poses "
                   "in the odometry frame")
    n = 0
    try:
        for s in scans:
            w.write_line(_clf_line_of(s, line_of[s.kind]).rstrip("\n"))
            n += 1
    except BaseException:
        try:
            w._f.close()  # noqa: SLF001 - drop the partial file: nothing half-written
        except OSError:  # its buffered tail could not be written either (a full disk): dropped all the same
            pass
        os.unlink(w.partial)
        raise
    w.close()
    return n


class EstimateBag:
    """``mcl run --write-bag``: the filter's output as ROS messages, to play next to the input bag: ``/amcl_pose``
    (PoseWithCovarianceStamped, frame map), ``map -> odom_frame`` on ``/tf`` (estimate ∘ odometry⁻¹, as AMCL
    publishes) and ``/particlecloud`` (PoseArray, at most ``particles_max`` poses, an even stride through the set).

    ``odom_frame``: the frame the input's odometry is in. ``odometry``: the input's odometry as recorded (rows t, x,
    y, theta, ...; time-sorted), interpolated at each update's stamp for map -> odom; None: the pose ``update`` is
    given (the filter's, which differs from the recording's after a gap filled by laser odometry). ``namespace``:
    the input's robot namespace when its transforms are on ``/robot1/tf`` (a multi-robot recording): the three
    topics go there too (``/robot1/amcl_pose``, ``/robot1/tf``, ``/robot1/particlecloud``), as a namespaced AMCL
    publishes them."""

    def __init__(self, path, kind: str, particles_max: int = 2000, odom_frame: str = "odom", odometry=None,
                 namespace: str = ""):
        self.out = BagOut(path, kind)
        self.particles_max, self.odom_frame = int(particles_max), odom_frame
        self.ns = namespace.rstrip("/")
        self.odometry = None if odometry is None else np.asarray(odometry, dtype=np.float64)

    def update(self, t: float, mean, cov, odom, particles) -> None:
        b = self.out
        pw = b.msg("geometry_msgs/msg/PoseWithCovariance", pose=b.pose(*mean), covariance=b.cov36(cov))
        b.write(f"{self.ns}/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped", t,
                b.msg("geometry_msgs/msg/PoseWithCovarianceStamped", header=b.header(t, "map"), pose=pw))
        if self.odometry is not None:
            from mcl.datasets.rosbag import odometry_at

            odom = odometry_at(self.odometry, t)[0]
        m2o = _compose(tuple(float(v) for v in mean), _inverse(tuple(float(v) for v in odom)))
        b.write(f"{self.ns}/tf", "tf2_msgs/msg/TFMessage", t,
                b.msg("tf2_msgs/msg/TFMessage", transforms=[b.transform(t, "map", self.odom_frame, m2o)]))
        p = np.asarray(particles)
        if self.particles_max > 0:
            step = max(1, -(-p.shape[1] // self.particles_max))
            b.write_raw(f"{self.ns}/particlecloud", b.POSE_ARRAY, t, b.pose_array(t, "map", p[:3, ::step]))

    def close(self) -> None:
        self.out.close()

    def abort(self) -> None:
        self.out.abort()
