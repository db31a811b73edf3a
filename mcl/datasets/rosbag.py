"""ROS bag reader (ROS 1 ``.bag``, ROS 2 ``.db3`` / ``.mcap`` or a rosbag2 folder) -> the records of a CARMEN log.

Reading goes through the ``rosbags`` library (``rosbags.highlevel.AnyReader``: one reader for the three storage
kinds, message definitions from the bag itself, else the ROS 2 Humble type store); no bag or CDR parsing here.

What a bag gives mcl (topics and frames from ``topics:`` / ``frames:`` of the config, REP 105 names by default):

* **scans**: ``sensor_msgs/LaserScan`` (angle_min, angle_increment, range_min, range_max from each message;
  +inf, the REP 117 no-return, becomes range_max, a no-return reading as in a CARMEN log; below range_min,
  -inf and NaN are dropped as beams); ``sensor_msgs/PointCloud2`` projected to the plane: points whose z (in
  the cloud's frame) lies in ``topics.cloud_z`` binned by bearing into ``topics.cloud_beams`` beams, the
  nearest point per beam (as pointcloud_to_laserscan / Beluga); ``sensor_msgs/MultiEchoLaserScan`` (a SICK
  LMS5xx's or a Hokuyo UTM-30LX-EW's several returns per beam) as a LaserScan of one echo per beam,
  ``topics.echo``: ``first`` (the nearest, as cartographer_ros reads it; default) or ``last``. One topic, or
  every scan topic fused (``topics.scan: all``), each with its own mounting pose. ``auto``: /scan, else the only
  laser topic, else of several those mounted level and fixed (``_level_lasers``).
* **odometry**: ``nav_msgs/Odometry`` on a topic, or the ``frames.odom -> frames.base`` transform of ``/tf``, or a
  ``PoseStamped`` / ``PoseWithCovarianceStamped`` topic in the odometry frame named as ``topics.odom``;
  interpolated at each scan's header stamp (linear in x, y, shortest angle in theta; an exact stamp gives the
  message's own pose). Velocities from the Odometry twist (0 from /tf: the runner derives them). With the
  default frames and no such transform: the only ``odom -> X`` (nav2's base_footprint), else the lowest /tf link
  above the laser that moves (``_moving_link``: robot_pose_ekf's ``odom_combined -> base_footprint``), with a note;
  with none of these (or ``topics.odom: laser``), the scans' own motion (:mod:`mcl.laser_odometry`), with a note.
* **transforms**: ``tf2_msgs/TFMessage`` on ``/tf`` and ``/tf_static``, or ROS 1's older ``tf/tfMessage`` (the same
  fields; bags recorded before tf2 put the static links on ``/tf`` too); a frame's leading '/' is dropped.
* **laser mounting**: ``frames.base -> scan frame`` from ``/tf_static`` (or the first ``/tf`` that has it),
  through any chain of frames; None when absent (the runner then uses ``sensor.laser_pose`` or the centre).
  A laser mounted upside down (the frame's z axis pointing down: rolled or pitched by pi, as AMCL allows)
  sees the plane mirrored, a beam at angle a pointing at -a: its ranges are reversed and its angle_min
  mirrored, so the records hold the beams counter-clockwise in an upright frame with the mounting's yaw.
* **map** (the last ``nav_msgs/OccupancyGrid`` on ``topics.map``: a bag recorded while mapping holds the map
  as it grew), **initial pose** (the first
  ``PoseWithCovarianceStamped`` on ``topics.initial_pose``, with its x, y, yaw covariance) and **truth**
  (``PoseStamped``, ``PoseWithCovarianceStamped`` or ``Odometry`` on ``topics.truth``).
* **stamps**: each message's header stamp; a topic (or the ``/tf`` odometry link) whose stamps are all 0, a
  driver that never sets them, is timed by the bag's record times instead, with a note.

Streaming: :func:`open_bag` makes one pass over the bag that checks every message (order, decoding) and keeps
only the small ones (odometry, transforms, map, initial pose, truth); :class:`BagScans` then reads the scans
again, one message at a time, so memory stays flat however long the bag. Any problem is a :class:`DataError`
naming the bag and the topic or frame, raised before a run writes anything.

Numbers: LaserScan ranges are float32; they are read to 10 micrometres (``round(r, 5)``), which removes the
float32 noise and gives back the decimal a CARMEN log holds (so a log and the bag made from it read the same
numbers). Stamps are read as the exact decimal ``sec.nanosec``; headings to 1e-12 rad; float32 angles that are
the float32 of a simple fraction of pi (-pi/2, pi/180) as that fraction; other float32 fields (range_max,
range_min, a map's resolution) as the shortest decimal of the float32.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from mcl.datasets.carmen import Scan
from mcl.datasets.loginfo import beams_text, check_lines, laser_geometry, scan_checks
from mcl.errors import DataError

__all__ = ["BAG_SUFFIXES", "is_bag", "bag_kind", "open_bag", "BagSource", "BagScans", "bag_info", "format_info",
           "SCAN_TYPES", "stamp_seconds", "yaw_of"]

BAG_SUFFIXES = {".bag": "bag1", ".db3": "db3", ".mcap": "mcap"}
LASER = "sensor_msgs/msg/LaserScan"
ECHOES = "sensor_msgs/msg/MultiEchoLaserScan"
LASERS = (LASER, ECHOES)  # read as a LaserScan (a multi-echo one through ``one_echo``)
CLOUD = "sensor_msgs/msg/PointCloud2"
SCAN_TYPES = (LASER, ECHOES, CLOUD)
ODOM = "nav_msgs/msg/Odometry"
GRID = "nav_msgs/msg/OccupancyGrid"
PWCS = "geometry_msgs/msg/PoseWithCovarianceStamped"
ODOM_SPAN_SLACK = 1.0  # s: an /initialpose stamped farther outside the odometry's span is on another clock
POSE = "geometry_msgs/msg/PoseStamped"
TF = "tf2_msgs/msg/TFMessage"
# ROS 1 before Hydro (2013) published transforms as tf/tfMessage: the same fields (TransformStamped[] transforms)
TF_TYPES = (TF, "tf/msg/tfMessage")
TRUTH_TYPES = (POSE, PWCS, ODOM)
# odometry: nav_msgs/Odometry, or, named as topics.odom, a pose topic in the odometry frame (a robot_pose_ekf's
# odom_combined is a PoseWithCovarianceStamped): the pose alone, no velocities
ODOM_TYPES = (ODOM, POSE, PWCS)
# Header stamps on one topic may step back this much (s) without being "out of order": recorders jitter, and
# CARMEN logs converted to bags keep their own small backward steps (intel_lab: 4, all < 1 s).
REORDER_TOLERANCE = 1.0
# A scan stamped up to this long (s) outside the odometry's time span is paired with the end pose silently (a
# recording's first and last odometry message come a period or so after or before the laser's).
ODOM_GAP_MIN = 1.0  # s: a pause in the odometry this long, and ODOM_GAP_PERIODS of its median period, is a gap
ODOM_GAP_PERIODS = 10
ODOM_GAP_ANCHOR = 5.0  # s: the scans before and after a gap that anchor its laser odometry lie this close to it
ODOM_SPAN_SLACK = 0.5


def rosbag2_folder(path) -> Path | None:
    """The rosbag2 folder a storage file belongs to: its parent, when the parent's ``metadata.yaml`` lists the
    file (None otherwise). Only the folder says how the messages were compressed (``ros2 bag record
    --compression-mode message`` leaves each message compressed in a plain-looking .db3 or .mcap; ``file`` leaves
    a ``.db3.zstd``), and which split files make up the recording, so such a file is read through its folder."""
    p = Path(path)
    meta = p.parent / "metadata.yaml"
    if not p.is_file() or not meta.is_file():
        return None
    try:
        info = yaml.safe_load(meta.read_text(errors="replace"))["rosbag2_bagfile_information"]
        files = {Path(str(f)).name for f in info.get("relative_file_paths") or ()}
    except Exception:  # not a rosbag2 metadata file: the file is read alone
        return None
    return p.parent if p.name in files else None


def _storage(path) -> Path:
    """The path to open: a storage file's rosbag2 folder (``rosbag2_folder``), else the path itself."""
    return rosbag2_folder(path) or Path(path)


def is_bag(path) -> bool:
    """A ROS bag by its name: .bag, .db3, .mcap, a folder with a rosbag2 metadata.yaml, or a file that folder
    lists (a split file, a compressed ``.db3.zstd``)."""
    p = Path(path)
    return (p.suffix in BAG_SUFFIXES or (p.is_dir() and (p / "metadata.yaml").exists())
            or rosbag2_folder(p) is not None)


def bag_kind(path) -> str:
    """bag1, db3 or mcap (a rosbag2 folder: from its storage files)."""
    p = _storage(path)
    if p.suffix in BAG_SUFFIXES:
        return BAG_SUFFIXES[p.suffix]
    if p.is_dir():
        return "mcap" if any(p.glob("*.mcap")) else "db3"
    raise DataError(f"{p}: not a ROS bag (.bag, .db3, .mcap or a rosbag2 folder)")


def stamp_seconds(stamp) -> float:
    """A ROS time as float seconds: the exact decimal sec.nanosec, correctly rounded."""
    return float(f"{int(stamp.sec)}.{int(stamp.nanosec):09d}")


def record_seconds(t_ns: int) -> float:
    """A bag's record time (integer nanoseconds) as float seconds, rounded as ``stamp_seconds`` rounds."""
    t_ns = int(t_ns)
    return float(f"{t_ns // 1_000_000_000}.{t_ns % 1_000_000_000:09d}")


UNSTAMPED = "every header stamp is 0; the bag's record times stand in for them"


def _record_timed(rows: np.ndarray, what: str, path, notes: list) -> np.ndarray:
    """``rows`` (t, ..., record time) without their last column; when every stamp t is 0 (a driver that never sets
    them) the record times stand in, with a note naming ``what``."""
    if not rows[:, 0].any():
        rows[:, 0] = rows[:, -1]
        notes.append(f"{path}: {what}: {UNSTAMPED}")
    return rows[:, :-1]


def _finite_odometry(odometry: np.ndarray, what: str, path, warnings: list, notes: list) -> np.ndarray:
    """``odometry`` (rows t, x, y, theta, tv, rv) with what is not finite mended: a velocity read as 0 (a note; the
    velocities only deskew the scans), a pose left out (a warning; the poses around it are interpolated, and a long
    run of them is a gap the scans fill). An EKF publishes NaN until its first input, a driver a NaN twist now and
    then: one such message refused the whole bag. DataError, naming the fields, when no pose is finite."""
    moving = ~np.isfinite(odometry[:, 4:6])
    if moving.any():
        rows = moving.any(axis=1)
        notes.append(f"{path}: {what}: {int(np.count_nonzero(rows))} of {len(odometry)} messages carry a non-finite "
                     f"velocity (the first stamped {odometry[rows, 0][0]:.3f}), read as 0 (the velocities only deskew "
                     "the scans)")
        odometry[:, 4:6] = np.where(moving, 0.0, odometry[:, 4:6])
    bad = ~np.isfinite(odometry[:, :4]).all(axis=1)
    if not bad.any():
        return odometry
    fields = ", ".join(name for k, name in enumerate(("stamp", "x", "y", "heading"))
                       if not np.isfinite(odometry[:, k]).all())
    if bad.all():
        raise DataError(f"{path}: {what}: none of its {len(odometry)} poses is finite ({fields})")
    warnings.append(f"{path}: {what}: {int(np.count_nonzero(bad))} of {len(odometry)} poses are not finite ({fields}; "
                    f"the first stamped {odometry[bad, 0][0]:.3f}): left out, the odometry between the poses around "
                    "them interpolated")
    return odometry[~bad]


def _tf_beside(rows: list | None, odometry: np.ndarray, what: str, path) -> tuple | None:
    """(rows t, x, y, theta, tv, rv of /tf's link ``what``, the largest distance and turn between it and the
    odometry topic's ``odometry`` at the topic's stamps within the link's span) when /tf holds the odometry's link
    too and it differs by over 1 cm or 0.01 rad: a robot_localization EKF publishes odom -> base_link on /tf while
    the wheels' Odometry goes on /odom. The run follows the topic, but tools place the robot through /tf, so an
    estimate bag's map -> odom must be computed from /tf's link (estimate ∘ link⁻¹) to join that tree (1 m off
    otherwise). None when /tf has no such link, or it agrees."""
    from mcl.datasets.carmen import interpolate_odometry
    from mcl.estimate import wrap_angle

    if not rows:
        return None
    link = _record_timed(np.array(rows, dtype=np.float64), what, path, [])
    link = link[np.argsort(link[:, 0], kind="stable")]
    link = link[np.isfinite(link[:, :4]).all(axis=1)]
    t = odometry[:, 0]
    inside = (t >= link[0, 0]) & (t <= link[-1, 0]) if len(link) else np.zeros(t.shape, dtype=bool)
    if not inside.any():
        return None
    at = interpolate_odometry(link, t[inside])  # /tf's pose at the topic's stamps
    rows_in = odometry[inside]
    dist = np.hypot(at[0] - rows_in[:, 1], at[1] - rows_in[:, 2])
    dturn = np.abs(wrap_angle(at[2] - rows_in[:, 3]))
    # a stamp /tf holds twice (a message stamped early onto an earlier one's): interpolation gives one of its poses;
    # each topic row is compared with the nearest of them (the same message on both was called an EKF's)
    lo = np.searchsorted(link[:, 0], rows_in[:, 0], side="left")
    hi = np.searchsorted(link[:, 0], rows_in[:, 0], side="right")
    for i in np.flatnonzero(hi - lo > 1):
        same = link[lo[i]:hi[i]]
        d = np.hypot(same[:, 1] - rows_in[i, 1], same[:, 2] - rows_in[i, 2])
        j = int(np.argmin(d + np.abs(wrap_angle(same[:, 3] - rows_in[i, 3]))))
        dist[i], dturn[i] = d[j], abs(float(wrap_angle(same[j, 3] - rows_in[i, 3])))
    off, turn = float(np.max(dist)), float(np.max(dturn))
    return (link, off, turn) if off > 0.01 or turn > 0.01 else None


def yaw_of(q) -> float:
    """Heading (rad) of a quaternion: the rotation about z of its planar part, to 1e-12 rad (which removes the
    last-bit noise of the quaternion round trip: a heading written as a quaternion reads back the same)."""
    return round(math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z)), 12)


def _frame(name: str) -> str:
    return name.lstrip("/")  # ROS 1 frames may start with '/'


def _tf_spaces(topics: dict) -> list[str]:
    """The namespaces whose remapped transform topics the bag has (/robot1/tf, /robot1/tf_static: /robot1)."""
    return sorted({n[: -len(suffix)] for n, i in topics.items() for suffix in ("/tf", "/tf_static")
                   if n.endswith(suffix) and n != suffix and i.msgtype in TF_TYPES})


def _tf_names(topics: dict, prefer=()) -> tuple[str, str]:
    """The bag's (dynamic, static) transform topics: /tf and /tf_static, else one namespace's (a multi-robot
    recording remaps them: /robot1/tf, /robot1/tf_static). Among several namespaces, the one that a name in
    ``prefer`` (the scan and odometry topics, /robot2/scan; the odometry frame, robot2/odom) lies in; /tf and
    /tf_static when none does or there are no such topics."""
    if "/tf" in topics or "/tf_static" in topics:
        return "/tf", "/tf_static"
    spaces = _tf_spaces(topics)
    if len(spaces) > 1:
        spaces = [ns for ns in spaces if any(("/" + p.lstrip("/")).startswith(ns + "/") for p in prefer if p)]
    if len(spaces) == 1:
        ns = spaces[0]
        return f"{ns}/tf", f"{ns}/tf_static"
    return "/tf", "/tf_static"


def _basename(frame: str) -> str:
    """A frame's name without its namespace: robot1/base_link -> base_link."""
    return frame.rsplit("/", 1)[-1]


def _compose(a, b):
    """a ∘ b of planar transforms (x, y, theta[, m]), m = -1 for one that mirrors the plane (y -> -y before the
    rotation: a frame upside down), +1 or absent otherwise; the result has m when either has."""
    ma = a[3] if len(a) > 3 else 1
    mb = b[3] if len(b) > 3 else 1
    c, s = math.cos(a[2]), math.sin(a[2])
    th = a[2] + ma * b[2]
    by = ma * b[1]
    out = (a[0] + c * b[0] - s * by, a[1] + s * b[0] + c * by, math.atan2(math.sin(th), math.cos(th)))
    return out + (ma * mb,) if len(a) > 3 or len(b) > 3 else out


def _tf_pose(tr) -> tuple[float, float, float]:
    return (float(tr.translation.x), float(tr.translation.y), yaw_of(tr.rotation))


def _tf_mount(tr) -> tuple[float, float, float, int]:
    """(x, y, theta, m) of a transform in the plane: m = -1 when it turns the z axis down (rolled or pitched by
    about pi: the plane seen mirrored), theta then the yaw that maps the mirrored x axis (the rotation's ZYX yaw)."""
    q = tr.rotation
    z_up = 1.0 - 2.0 * (float(q.x) ** 2 + float(q.y) ** 2)  # z component of the rotated z axis
    return (*_tf_pose(tr), -1 if z_up < 0.0 else 1)


def _open_reader(path: Path):
    """An open AnyReader (DataError for a missing, truncated or corrupt bag)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    if not path.exists():
        raise DataError(f"{path}: no such bag")
    if not is_bag(path):
        raise DataError(f"{path}: not a ROS bag (.bag, .db3, .mcap or a rosbag2 folder)")
    try:
        reader = AnyReader([_storage(path)], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as e:  # the library's readers raise many kinds for a damaged file
        why = _why(e)
        if "profile is not ros2" in why.lower():  # `mcap convert` of a ROS 1 bag: rosbags reads ROS 2 MCAP only
            raise DataError(f"{path}: an MCAP file of ROS 1 messages (profile ros1, as `mcap convert` writes a .bag): "
                            "not read; give the .bag itself") from None
        raise DataError(f"{path}: cannot read the bag (truncated or corrupt?): {why}") from None
    return reader


def _why(e: Exception) -> str:
    text = " ".join(str(e).split())
    return (text[:160] or type(e).__name__)


def _messages(reader, path, connections):
    """(connection, record time in s, deserialized message) in time order; DataError naming the topic on damage.
    No connections: nothing (the library reads every message for an empty list)."""
    if not connections:
        return
    it = reader.messages(connections=connections)
    conn = None
    while True:
        try:
            conn, t_ns, raw = next(it)
            msg = reader.deserialize(raw, conn.msgtype)
        except StopIteration:
            return
        except Exception as e:
            where = f" on {conn.topic}" if conn is not None else ""
            hint = ""
            if Path(path).suffix in (".db3", ".mcap") and rosbag2_folder(path) is None:
                hint = ("; a rosbag2 file recorded with message compression reads only through its folder, with the "
                        "metadata.yaml that says so")
            raise DataError(f"{path}: cannot read a message{where} (truncated or corrupt?): "
                            f"{_why(e).rstrip('.')}{hint}") from None
        yield conn, record_seconds(t_ns), msg


@dataclass
class _Topics:
    scan: str = "auto"
    odom: str = "auto"
    map: str | None = "/map"
    initial_pose: str | None = "/initialpose"
    truth: str | None = None
    cloud_z: tuple[float, float] = (-0.1, 0.1)
    cloud_beams: int = 720
    echo: str = "first"


@dataclass
class _Frames:
    odom: str = "odom"
    base: str = "base_link"


def outside_span(t: np.ndarray, odometry_t: np.ndarray):
    """(early, late, (o0, o1)): which stamps ``t`` lie more than ``ODOM_SPAN_SLACK`` before or after the
    odometry's time span o0..o1 (time-sorted ``odometry_t``): their odometry is held at that end."""
    o0, o1 = float(odometry_t[0]), float(odometry_t[-1])
    return t < o0 - ODOM_SPAN_SLACK, t > o1 + ODOM_SPAN_SLACK, (o0, o1)


@dataclass(eq=False)
class BagSource:
    """What a bag holds for a run: the scan stream and the small records read in the first pass."""

    path: str
    kind: str
    scans: "BagScans"
    odom_source: str  # "/odom (nav_msgs/Odometry)" or "/tf odom -> base_link"
    odometry: np.ndarray  # (M, 6): t, x, y, theta, tv, rv, time-sorted
    laser_offsets: dict  # scan topic -> (3,) array or None
    grid: object | None = None  # mcl.maps.OccupancyGrid from topics.map
    initial_pose: tuple[np.ndarray, np.ndarray] | None = None  # mean (3,), cov (3, 3)
    truth: tuple[np.ndarray, np.ndarray] | None = None  # t (K,), poses (3, K)
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    skipped: dict[str, int] = field(default_factory=dict)
    landmarks: list = field(default_factory=list)
    scan_stamps: np.ndarray = field(default_factory=lambda: np.zeros(0))  # every scan's header stamp (s)
    sweeps: dict = field(default_factory=dict)  # LaserScan topic -> its first message's sweep (s; 0: no beam times)
    # pose and odometry topics a run could score against (--truth-topic): all but the odometry read, the initial pose
    # and the truth topic in use (a simulator's /ground_truth, a motion-capture topic, a localizer's /amcl_pose)
    references: list = field(default_factory=list)
    # the transform topic read (/tf, or one namespace's /robot1/tf in a multi-robot recording): the estimate bag
    # publishes in that namespace too
    tf_topic: str = "/tf"
    tf_links: list = field(default_factory=list)  # every (parent, child) on that topic, sorted
    # The frame the odometry is in, as the bag names it: the parent of the /tf odometry link read (robot1/odom,
    # odom_combined), an Odometry's or a pose topic's header.frame_id (odom_wheel); None for laser odometry.
    odom_frame: str | None = None
    # The odometry as the bag records it (rows as ``odometry``), before any gap is filled by laser odometry (which
    # moves the poses after the gap): the pose of the frame the odometry moves in ``odom_frame`` at each stamp, as
    # the bag's own /tf places it; None for laser odometry.
    odom_recorded: np.ndarray | None = None

    @property
    def wheel_odometry(self) -> bool:
        """Whether the odometry is the robot's own (a topic or /tf), not laser odometry made of the scans."""
        return not self.odom_source.startswith("laser odometry")

    def stamps_checked(self, offset: float = 0.0) -> list[str]:
        """The scans' stamps (plus ``sensor.time_offset``) against the odometry's time span: DataError when none
        lies within it (no scan can be paired: two clocks, e.g. a driver stamping with its own), else a warning for
        each end where scans lie more than ``ODOM_SPAN_SLACK`` outside (their odometry is held at that end: the
        robot looks still there). Returns the warnings."""
        t = self.scan_stamps + float(offset)
        if t.size == 0:
            return []
        early, late, (o0, o1) = outside_span(t, self.odometry[:, 0])
        shifted = f" (with sensor.time_offset {offset:+g} s)" if offset else ""
        if (early | late).all():
            raise DataError(f"{self.path}: no scan is stamped within the odometry's time span{shifted}: scans "
                            f"{t.min():.3f}..{t.max():.3f} s, odometry ({self.odom_source}) {o0:.3f}..{o1:.3f} s "
                            f"(two clocks? sensor.time_offset={o0 - self.scan_stamps.min():.3f} would pair the "
                            "first scan with the first odometry)")
        out = []
        for mask, where, gap in ((early, "before", o0 - t.min()), (late, "after", t.max() - o1)):
            k = int(np.count_nonzero(mask))
            if k:
                out.append(f"{self.path}: {k} of {t.size} scans are stamped {where} the odometry's time span "
                           f"({o0:.3f}..{o1:.3f} s{shifted}), by up to {gap:.2f} s: their odometry is held at the "
                           f"{'first' if where == 'before' else 'last'} pose, as if the robot stood still")
        return out


class BagScans:
    """The scans of a bag as a sized iterable of :class:`mcl.datasets.carmen.Scan`: each pass reads the bag again,
    one message at a time (odometry interpolated at each stamp, the mounting pose of its topic)."""

    def __init__(self, path: Path, topics: list[str], count: int, odometry: np.ndarray, offsets: dict,
                 cloud_z, cloud_beams: int, has_twist: bool, mirrored=frozenset(), unstamped=frozenset(),
                 echo: str = "first"):
        self.path, self.topics, self.count = path, topics, count
        self.mirrored = frozenset(mirrored)  # topics whose frame is upside down
        self.unstamped = frozenset(unstamped)  # topics whose header stamps are all 0: their record times
        self.odometry, self.offsets = odometry, offsets
        self.cloud_z, self.cloud_beams, self.has_twist = cloud_z, int(cloud_beams), has_twist
        self.echo = echo  # which return of a MultiEchoLaserScan's beam: first or last

    def __len__(self) -> int:
        return self.count

    def __iter__(self):
        reader = _open_reader(self.path)
        try:
            conns = [c for c in reader.connections if c.topic in self.topics]
            index: dict[str, int] = {}
            # In stamp order: a bag holds messages as they arrived, a second laser's or a late one's behind newer
            # scans, and the filter would step the odometry back and forth. A stamp never lies more than
            # REORDER_TOLERANCE before a newer one of its topic (the first pass refused such a bag), so a scan is
            # let go once a scan that much newer has come: at most that much of the log is held.
            pending: list[tuple] = []  # heap of (stamp, arrival, scan)
            newest = -math.inf
            for seq, (conn, rec, msg) in enumerate(_messages(reader, self.path, conns)):
                k = index[conn.topic] = index.get(conn.topic, 0) + 1
                scan = self._scan(conn, msg, k, rec)
                newest = max(newest, scan.t)
                heapq.heappush(pending, (scan.t, seq, scan))
                while pending[0][0] < newest - REORDER_TOLERANCE:
                    yield heapq.heappop(pending)[2]
            while pending:
                yield heapq.heappop(pending)[2]
        finally:
            reader.close()

    def _scan(self, conn, msg, k: int, rec: float) -> Scan:
        t = rec if conn.topic in self.unstamped else stamp_seconds(msg.header.stamp)
        flip = conn.topic in self.mirrored
        t0 = dt = 0.0
        if conn.msgtype in LASERS:
            if conn.msgtype == ECHOES:
                msg = one_echo(msg, self.echo)
            ranges, amin, inc, rmax = laser_ranges(msg)
            t0, dt = beam_times(msg.time_increment, ranges.size)
            if flip:  # beam i at angle a points at -a: reversed, the beams run counter-clockwise again
                ranges = np.ascontiguousarray(ranges[::-1])
                amin = -(amin + inc * (ranges.size - 1))
                t0, dt = t0 + dt * (ranges.size - 1), -dt
        else:
            ranges, amin, inc, rmax = cloud_ranges(msg, self.cloud_z, self.cloud_beams, flip)
        odom, tv, rv = odometry_at(self.odometry, t)
        if not self.has_twist:
            tv = rv = 0.0
        return Scan(t, ranges, amin, inc, rmax, odom, self.offsets.get(conn.topic), tv, rv, conn.topic, k,
                    beam_t0=t0, beam_dt=dt)


MAX_SWEEP = 1.0  # s: a LaserScan whose time_increment spreads its beams over longer is not a sweep (ignored)


def beam_times(time_increment, n: int) -> tuple[float, float]:
    """(beam_t0, beam_dt) of a LaserScan of ``n`` beams: beam i taken at the stamp + i * time_increment (REP 117's
    header stamp is the first beam's). (0, 0) when it says nothing usable: 0, not finite, or a sweep over 1 s."""
    ti = float(time_increment)
    if n < 2 or not math.isfinite(ti) or ti == 0.0 or abs(ti) * (n - 1) > MAX_SWEEP:
        return 0.0, 0.0
    return 0.0, ti


def beams_directed(msg) -> bool:
    """Whether a LaserScan says where its beams point: angle_min and angle_increment finite, and the increment not
    0 when there are several beams (a broken driver's message)."""
    amin, inc = float(msg.angle_min), float(msg.angle_increment)
    return math.isfinite(amin) and math.isfinite(inc) and (inc != 0.0 or len(msg.ranges) < 2)


def one_echo(msg, which: str = "first"):
    """A ``sensor_msgs/MultiEchoLaserScan`` as a LaserScan (the fields ``laser_ranges`` reads): per beam its
    first echo (the nearest return: dust, rain or glass before the wall; what cartographer_ros reads) or its
    ``last`` (the farthest), NaN (not a reading) for a beam without one. The per-beam echo lists are Python
    objects once the bag library has decoded them; taking one of each is the decoding's cost, once per scan."""
    pick = 0 if which == "first" else -1
    echoes = [e.echoes for e in msg.ranges]
    r = np.fromiter((e[pick] if len(e) else math.nan for e in echoes), dtype=np.float32, count=len(echoes))
    return _Echo(msg.angle_min, msg.angle_increment, msg.time_increment, msg.range_min, msg.range_max, r)


@dataclass(frozen=True)
class _Echo:
    """The LaserScan fields of a MultiEchoLaserScan with one echo per beam (``one_echo``)."""

    angle_min: float
    angle_increment: float
    time_increment: float
    range_min: float
    range_max: float
    ranges: np.ndarray


def laser_ranges(msg):
    """(ranges float64, angle_min, angle_increment, max_range or None) of a LaserScan (see the module doc). One
    that does not say where its beams point (``beams_directed``) has no reading (0 for every beam): the update only
    predicts."""
    if not beams_directed(msg):
        return np.zeros(len(msg.ranges)), 0.0, 0.0, None
    r = np.round(np.asarray(msg.ranges, dtype=np.float64), 5)
    rmax = f32(msg.range_max)
    rmax = rmax if math.isfinite(rmax) and rmax > 0 else None
    rmin = f32(msg.range_min)
    rmin = rmin if math.isfinite(rmin) and rmin > 0 else 0.0  # not given: every reading above 0 counts
    with np.errstate(invalid="ignore"):
        if rmax is not None:
            r[np.isposinf(r)] = rmax  # REP 117: +inf is no return
        # Too close, -inf or NaN: not a reading. 0 is never a valid range (valid: r > sensor.range_min >= 0).
        r[~(r >= rmin) | np.isneginf(r) | np.isnan(r)] = 0.0
    return r, snap_pi(msg.angle_min), snap_pi(msg.angle_increment), rmax


def f32(v: float) -> float:
    """A float32 field as the shortest decimal that float32 stands for (81.83, not 81.83000183)."""
    v = float(v)
    return float(str(np.float32(v))) if math.isfinite(v) else v


def snap_pi(v: float) -> float:
    """A float32 angle as float64: p*pi/q when the float32 is exactly that simple fraction of pi (a driver's
    -pi/2 or pi/180, stored as float32), else the float32 value itself."""
    v = float(v)
    f = np.float32(v)
    qs = list(range(1, 9))
    if v != 0.0 and 1.0 <= math.pi / abs(v) <= 1e5:
        qs.append(round(math.pi / abs(v)))
    for q in qs:
        p = round(v * q / math.pi)
        cand = p * math.pi / q
        if p != 0 and np.float32(cand) == f:
            return cand
    return v


def cloud_ranges(msg, z_band, beams: int, mirrored: bool = False):
    """A PointCloud2 as a planar scan: points with z_band[0] <= z <= z_band[1], nearest per bearing bin; beam k
    points at its bin's centre, -pi + (k + 1/2) * 2 pi / beams (at the bin's edge, every heading would be half a bin
    off). ``mirrored``: the cloud's frame is upside down; its y and z are negated first (z_band is then upward)."""
    names = {f.name: f for f in msg.fields}
    if not all(n in names for n in "xyz"):
        raise DataError(f"PointCloud2 without x, y, z fields (has {', '.join(names)})")
    types = {7: "f4", 8: "f8"}  # sensor_msgs/PointField FLOAT32, FLOAT64
    order = ">" if msg.is_bigendian else "<"
    try:
        dt = np.dtype({"names": list("xyz"), "formats": [order + types[names[n].datatype] for n in "xyz"],
                       "offsets": [names[n].offset for n in "xyz"], "itemsize": int(msg.point_step)})
    except KeyError:
        raise DataError("PointCloud2: x, y, z must be FLOAT32 or FLOAT64") from None
    n = int(msg.width) * int(msg.height)
    data = np.asarray(msg.data, dtype=np.uint8)
    if n * int(msg.point_step) > data.size or n == 0:
        pts = np.zeros(0, dtype=dt)
    else:
        rows = data[: n * int(msg.point_step)]
        pts = np.frombuffer(rows.tobytes(), dtype=dt, count=n)
    x, y, z = (pts[c].astype(np.float64) for c in "xyz")
    if mirrored:
        y, z = -y, -z
    keep = np.isfinite(x) & np.isfinite(y) & (z >= z_band[0]) & (z <= z_band[1])
    x, y = x[keep], y[keep]
    inc = 2.0 * math.pi / beams
    out = np.zeros(beams)  # 0: no point in that bin (not a reading)
    if x.size:
        r = np.hypot(x, y)
        b = np.minimum(((np.arctan2(y, x) + math.pi) / inc).astype(np.int64), beams - 1)
        o = np.lexsort((r, b))
        first = np.unique(b[o], return_index=True)
        out[first[0]] = r[o][first[1]]
    return np.round(out, 5), -math.pi + 0.5 * inc, inc, None


def odometry_at(odometry: np.ndarray, t: float):
    """Robot pose (3,), tv, rv interpolated at ``t`` from time-sorted rows t, x, y, theta, tv, rv (clamped at the
    ends; a row stamped exactly ``t`` is returned as is)."""
    ot = odometry[:, 0]
    m = ot.shape[0]
    i = int(np.searchsorted(ot, t, side="right")) - 1
    if i >= 0 and ot[i] == t:
        row = odometry[i]
        return row[1:4].copy(), float(row[4]), float(row[5])
    i = min(max(i, 0), m - 1)
    j = min(i + 1, m - 1)
    dt = ot[j] - ot[i]
    f = min(max((t - ot[i]) / dt, 0.0), 1.0) if dt > 0 else 0.0
    a, b = odometry[i], odometry[j]
    dth = math.atan2(math.sin(b[3] - a[3]), math.cos(b[3] - a[3]))
    th = a[3] + f * dth
    pose = np.array([a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]), math.atan2(math.sin(th), math.cos(th))])
    return pose, float(a[4] + f * (b[4] - a[4])), float(a[5] + f * (b[5] - a[5]))


def _scan_like(topics: dict) -> list[str]:
    return sorted(n for n, i in topics.items() if i.msgtype in SCAN_TYPES)


def _listing(names: list[str]) -> str:
    return ", ".join(names) if names else "none"


def _choose_scan_topics(path, topics: dict, want: str) -> list[str]:
    scan_like = _scan_like(topics)
    if want == "all":
        if not scan_like:
            raise DataError(f"{path}: no LaserScan, MultiEchoLaserScan or PointCloud2 topic "
                            f"(topics: {_listing(sorted(topics))})")
        return scan_like
    if want == "auto":
        lasers = [n for n in scan_like if topics[n].msgtype in LASERS]
        if "/scan" in scan_like:
            return ["/scan"]
        if len(lasers) == 1:
            return lasers
        if not lasers and len(scan_like) == 1:
            return scan_like
        if not scan_like:
            raise DataError(f"{path}: no LaserScan, MultiEchoLaserScan or PointCloud2 topic "
                            f"(topics: {_listing(sorted(topics))})")
        if len(lasers) > 1:
            return lasers  # several lasers: the first pass decides by their mountings (``_level_lasers``)
        raise DataError(f"{path}: {_SEVERAL.format(_listing(scan_like))}")
    if want not in topics:
        raise DataError(f"{path}: no topic {want} (scan-like topics: {_listing(scan_like)})")
    if topics[want].msgtype not in SCAN_TYPES:
        raise DataError(f"{path}: {want} is {topics[want].msgtype}, not a LaserScan, MultiEchoLaserScan or "
                        f"PointCloud2 (scan-like topics: {_listing(scan_like)})")
    return [want]


_SEVERAL = "several scan topics ({}); choose one with --scan-topic (topics.scan) or fuse them with topics.scan: all"
LEVEL_TILT = math.radians(10.0)  # a laser whose scan plane tilts more than this sees the floor or over the walls
LEVEL_HEIGHT = 0.2  # m: level lasers mounted within this of each other's height see the same walls


def _level_lasers(path, lasers: list[str], scan_frames: dict, links: dict, moved: set, base: str, odom: str,
                  notes: list):
    """The laser topics ``topics.scan: auto`` reads when a bag has several and no /scan: those mounted level and
    fixed on ``base`` (every link from ``base`` to the scan frame fixed, the scan plane within ``LEVEL_TILT`` of
    level): a PR2's base_scan and not its tilt_scan (its frame pitches on /tf), nor a laser looking down at the
    floor. One such: that one; several on distinct frames within ``LEVEL_HEIGHT`` of each other's height (an AGV's
    front and rear lasers): all, fused; else (the same frame's raw and filtered scans, lasers at other heights, no
    transforms) one line asking to choose. ``links``: child -> (parent, (x, y, z, qx, qy, qz, qw)) of the first
    transform of each link (a quaternion of norm 0 or not finite counts as no rotation); ``moved``: the children
    whose /tf transform changes over the bag. The walk up from a scan frame ends at ``base``, or at a frame hung from
    ``odom`` (nav2's base_footprint with no base_link)."""
    from scipy.spatial.transform import Rotation

    why: dict[str, str] = {}
    height: dict[str, float] = {}
    for t in lasers:
        f = scan_frames[t]
        rot, tr, seen, moving = Rotation.identity(), np.zeros(3), set(), []
        while f != base and f in links and f not in seen and links[f][0] != odom:
            seen.add(f)
            parent, p = links[f]
            q = np.array(p[3:])
            r = Rotation.from_quat(q) if np.isfinite(q).all() and q.any() else Rotation.identity()
            rot, tr = r * rot, r.apply(tr) + np.array(p[:3])
            if f in moved:
                moving.append(f)
            f = parent
        if f != base and not (f in links and links[f][0] == odom):
            why[t] = f"no transform {base} -> {scan_frames[t]}"
        elif moving:
            why[t] = f"{moving[0]} moves on /tf"
        else:
            tilt = math.acos(min(1.0, abs(float(rot.apply((0.0, 0.0, 1.0))[2]))))
            if tilt > LEVEL_TILT:
                why[t] = f"tilted {math.degrees(tilt):.0f} deg from level"
            height[t] = float(tr[2])
    level = [t for t in lasers if t not in why]
    frames = {scan_frames[t] for t in level}
    if level and len(frames) == len(level) and max(height[t] for t in level) - min(height[t] for t in level) \
            <= LEVEL_HEIGHT:
        left = "; ".join(f"{t}: {w}" for t, w in why.items())
        what = (f"{level[0]} is the one mounted level and fixed" if len(level) == 1 else
                f"{', '.join(level)} are mounted level and fixed at one height: fused")
        notes.append(f"{path}: several laser topics ({', '.join(lasers)}); {what}{f' ({left})' if left else ''} "
                     "(--scan-topic chooses)")
        return level
    detail = "; ".join(f"{t}: {why.get(t, 'level')}" for t in lasers)
    raise DataError(f"{path}: {_SEVERAL.format(detail)}")


def _choose_odom(path, topics: dict, want: str) -> str | None:
    """The odometry topic to use (an Odometry, or a pose topic named), or None for /tf."""
    odoms = sorted(n for n, i in topics.items() if i.msgtype == ODOM)
    if want in ("tf", "laser"):
        return None
    if want == "auto":
        if "/odom" in odoms:
            return "/odom"
        return odoms[0] if len(odoms) == 1 else None
    if want not in topics:
        raise DataError(f"{path}: no topic {want} (Odometry topics: {_listing(odoms)}; or topics.odom: tf)")
    if topics[want].msgtype not in ODOM_TYPES:
        raise DataError(f"{path}: {want} is {topics[want].msgtype}, not nav_msgs/Odometry (or a PoseStamped or "
                        "PoseWithCovarianceStamped in the odometry frame)")
    return want


def _check_type(path, topics: dict, name: str | None, types: tuple, what: str) -> str | None:
    if name is None or name not in topics:
        return None
    if topics[name].msgtype not in types:
        raise DataError(f"{path}: {name} ({what}) is {topics[name].msgtype}, expected "
                        f"{' or '.join(t.replace('/msg/', '/') for t in types)}")
    return name


class _Order:
    """Header stamps per topic must not step back more than REORDER_TOLERANCE."""

    def __init__(self, path):
        self.path, self.last, self.count = path, {}, {}

    def see(self, topic: str, t: float, what: str = "") -> None:
        k = self.count[topic] = self.count.get(topic, 0) + 1
        key = topic + what
        prev = self.last.get(key)
        if prev is not None and t < prev - REORDER_TOLERANCE:
            raise DataError(f"{self.path}: {topic}{what}: messages out of order: message {k} is stamped "
                            f"{t:.3f} s, {prev - t:.3f} s before the one before it")
        if not math.isfinite(t):
            raise DataError(f"{self.path}: {topic}: message {k} has a non-finite stamp")
        self.last[key] = t if prev is None else max(prev, t)


def _cov3(c) -> np.ndarray:
    """x, y, yaw block of a 6x6 row-major ROS covariance."""
    c = np.asarray(c, dtype=np.float64).reshape(6, 6)
    idx = [0, 1, 5]
    return c[np.ix_(idx, idx)].copy()


def _pose_msg(msg) -> tuple[float, float, float]:
    """(x, y, yaw) of a PoseStamped, PoseWithCovarianceStamped or Odometry."""
    p = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
    return float(p.position.x), float(p.position.y), yaw_of(p.orientation)


def _grid_from_msg(path, topic, msg):
    from mcl.maps import OccupancyGrid, axis_aligned

    info = msg.info
    w, h = int(info.width), int(info.height)
    # values off ROS's -1..100 (a publisher's -2 or 101..127) read as a map_server does: negative unknown, over 100
    # occupied
    data = np.clip(np.asarray(msg.data, dtype=np.int8), -1, 100)
    if w <= 0 or h <= 0 or data.size != w * h:
        raise DataError(f"{path}: {topic}: OccupancyGrid of {w} x {h} cells holds {data.size} values")
    res = f32(info.resolution)
    try:
        if not res > 0.0:
            raise ValueError(f"resolution must be positive, got {res}")
        # a rotated origin (the grid turned about its first cell): resampled onto an axis-aligned grid
        occ, corner = axis_aligned(data.reshape(h, w), res, (float(info.origin.position.x),
                                                             float(info.origin.position.y)),
                                   yaw_of(info.origin.orientation))
        return OccupancyGrid.from_occupancy(occ, res, corner, path=f"{path}:{topic}")
    except ValueError as e:
        raise DataError(f"{path}: {topic}: {e}") from None


def _static_chain(static: dict, base: str, frame: str):
    """Pose of ``frame`` in ``base`` through the parent links of ``static`` (child -> (parent, pose)), or None."""
    pose = (0.0, 0.0, 0.0, 1)
    f, seen = frame, set()
    while f != base:
        if f in seen or f not in static:
            return None
        seen.add(f)
        parent, p = static[f]
        pose = _compose(p, pose)
        f = parent
    return pose


MOVED = 1e-3  # m or rad: a /tf link whose pose changes more than this over the bag moves


def _moved(a: tuple, b: tuple) -> bool:
    """Whether two transforms (x, y, z, qx, qy, qz, qw) differ by more than MOVED (m, or rad of rotation)."""
    if max(abs(a[i] - b[i]) for i in range(3)) > MOVED:
        return True
    dot = abs(sum(a[i] * b[i] for i in range(3, 7)))
    na = math.sqrt(sum(v * v for v in a[3:])) * math.sqrt(sum(v * v for v in b[3:]))
    return na > 0 and 2.0 * math.acos(min(1.0, dot / na)) > MOVED


def _moving_link(reader, path, tf_topic: str, static: dict, frame: str):
    """((parent, child), odometry rows) of the lowest /tf link above ``frame`` (a laser's) that moves over the bag,
    or None: the robot's odometry when it is not named ``odom -> base_link`` (a robot_pose_ekf's
    ``odom_combined -> base_footprint``). The chain is walked through ``static`` (child -> (parent, pose): the
    first pose of each link); a second pass over ``tf_topic`` reads the chain's links."""
    chain, f = [], frame
    while f in static and len(chain) < 64:
        chain.append((static[f][0], f))
        f = static[f][0]
    if not chain:
        return None
    rows: dict[tuple, list] = {e: [] for e in chain}
    for _, rec, msg in _messages(reader, path, [c for c in reader.connections if c.topic == tf_topic]):
        for ts in msg.transforms:
            e = (_frame(ts.header.frame_id), _frame(ts.child_frame_id))
            if e in rows:
                rows[e].append((stamp_seconds(ts.header.stamp), *_tf_pose(ts.transform), 0.0, 0.0, rec))
    for e in chain:  # from the laser up: the first that moves (not map -> odom above it)
        if len(rows[e]) > 1:
            a = np.array(rows[e])[:, 1:4]
            if max(np.ptp(a[:, 0]), np.ptp(a[:, 1]), np.ptp(np.unwrap(a[:, 2]))) > MOVED:
                return e, rows[e]
    return None


def open_bag(path, topics=None, frames=None, progress: bool | None = False, laser_pose=None) -> BagSource:
    """Read a bag's small records and set up its scan stream (see the module doc).

    ``topics`` and ``frames`` are the config sections (or any objects with the same attributes; None: the
    defaults). DataError naming the bag and the topic or frame for every problem found. ``progress``: a progress
    bar over the scans while laser odometry matches them (None: on a terminal only). ``laser_pose``: the config's
    ``sensor.laser_pose`` (x, y, theta), which the run uses in place of the bag's mounting: laser odometry turns
    the laser's motion into the robot's with it too.
    """
    path = Path(path)
    tp = topics or _Topics()
    fr = frames or _Frames()
    reader = _open_reader(path)
    try:
        return _first_pass(path, reader, tp, fr, progress, laser_pose)
    finally:
        reader.close()


def _first_pass(path: Path, reader, tp, fr, progress: bool | None = False, laser_pose=None) -> BagSource:
    topics = reader.topics
    for name, info in topics.items():
        if info.msgtype is None:
            raise DataError(f"{path}: {name}: several message types on one topic")
    scan_topics = _choose_scan_topics(path, topics, tp.scan)
    odom_topic = _choose_odom(path, topics, tp.odom)
    map_topic = _check_type(path, topics, tp.map, (GRID,), "map")
    init_topic = _check_type(path, topics, tp.initial_pose, (PWCS,), "initial pose")
    truth_topic = tp.truth
    if truth_topic is not None:
        if truth_topic not in topics:
            poses = sorted(n for n, i in topics.items() if i.msgtype in TRUTH_TYPES)
            raise DataError(f"{path}: no truth topic {truth_topic} (pose and odometry topics: {_listing(poses)})")
        _check_type(path, topics, truth_topic, TRUTH_TYPES, "truth")
    odom_frame, base_frame = _frame(fr.odom), _frame(fr.base)
    tf_dyn, tf_static = _tf_names(topics, [*scan_topics, odom_topic, odom_frame])
    if tf_dyn not in topics and tf_static not in topics and len(_tf_spaces(topics)) > 1:
        raise DataError(f"{path}: no /tf, and transforms of several namespaces ({_listing(_tf_spaces(topics))}): "
                        "choose the robot with --scan-topic (topics.scan) or frames.odom in its namespace")
    tf_topics = [n for n in (tf_dyn, tf_static) if n in topics]
    for n in tf_topics:
        if topics[n].msgtype not in TF_TYPES:
            raise DataError(f"{path}: {n} is {topics[n].msgtype}, expected tf2_msgs/TFMessage (or ROS 1's "
                            "tf/tfMessage)")
    default_odom = odom_frame == _frame(_Frames().odom)  # a namespaced one (robot1/odom) may stand in for it
    from_scans = tp.odom == "laser"  # the motion from scan matching (mcl.laser_odometry); auto: when none is found
    poses = sorted(n for n, i in topics.items() if i.msgtype in (POSE, PWCS) and n not in (init_topic, truth_topic))
    odoms = sorted(n for n, i in topics.items() if i.msgtype == ODOM)
    if odom_topic is None and tf_dyn not in topics and (tp.odom == "tf" or (tp.odom == "auto" and (poses or odoms))):
        # Odometry topics to choose among, or a pose topic that may be the odometry (robot_pose_ekf's): named, not
        # passed over for the scans' motion
        hint = (f"; a pose topic in the odometry frame can be named with --odom-topic: {_listing(poses)}"
                if poses else "")
        raise DataError(f"{path}: no odometry: no nav_msgs/Odometry topic{'' if not odoms else ' chosen'} "
                        f"(Odometry topics: {_listing(odoms)}) and no /tf for {odom_frame} -> {base_frame}{hint}")

    wanted = set(scan_topics) | set(tf_topics) | {t for t in (odom_topic, map_topic, init_topic, truth_topic) if t}
    conns = [c for c in reader.connections if c.topic in wanted]
    order = _Order(path)
    odom_rows: list[tuple] = []
    static: dict[str, tuple] = {}  # child -> (parent, pose): /tf_static, and the first /tf of a non-odometry link
    tf_frames: set[str] = set()
    scan_frames: dict[str, str] = {}
    sweeps: dict[str, float] = {}  # LaserScan topic -> s from its first message's first beam to its last (0: unknown)
    counts: dict[str, int] = {t: 0 for t in scan_topics}
    undirected: dict[str, int] = {}  # LaserScan topic -> messages that do not say where their beams point
    scan_t: list[float] = []
    scan_rec: list[float] = []  # each scan's record time, and its topic (for a topic whose stamps are all 0)
    scan_of: list[str] = []
    grid = initial = map_msg = None
    init_t = init_rec = None
    init_frame = truth_frame = ""
    n_maps = 0
    truth_rows: list[tuple] = []
    other_rows: dict[tuple, list] = {}  # (parent, child) -> /tf rows from an odometry frame other than odom -> base
    # with an odometry topic: (parent, child) -> /tf rows of the links into base_frame or from an odometry frame (an
    # EKF's odom -> base_link beside the wheels' /odom), the tree an estimate bag's map -> odom must join
    tf_beside: dict[tuple, list] = {}
    odom_child = None  # the Odometry topic's child_frame_id
    odom_parent_frame = None  # the odometry topic's header.frame_id (an Odometry's, a pose topic's)
    several = tp.scan == "auto" and len(scan_topics) > 1  # lasers to choose among by their mountings
    links: dict[str, tuple] = {}  # child -> (parent, (x, y, z, qx, qy, qz, qw)): each link's first transform
    moved: set[str] = set()  # children whose /tf transform changes
    seen: dict[str, int] = {}
    # Odometry and truth rows carry their record time last, for a source whose header stamps are all 0.
    for conn, rec, msg in _messages(reader, path, conns):
        topic = conn.topic
        seen[topic] = seen.get(topic, 0) + 1
        if topic in counts:
            counts[topic] += 1
            scan_t.append(stamp_seconds(msg.header.stamp))
            scan_rec.append(rec)
            scan_of.append(topic)
            order.see(topic, scan_t[-1])
            if conn.msgtype in LASERS and not beams_directed(msg):
                undirected[topic] = undirected.get(topic, 0) + 1
            elif topic not in sweeps and conn.msgtype in LASERS:
                t0, dt = beam_times(msg.time_increment, len(msg.ranges))
                sweeps[topic] = abs(dt) * (len(msg.ranges) - 1)
            scan_frames.setdefault(topic, _frame(msg.header.frame_id))
        elif topic in (tf_dyn, tf_static):
            for ts in msg.transforms:
                parent, child = _frame(ts.header.frame_id), _frame(ts.child_frame_id)
                if topic == tf_dyn:
                    tf_frames.add(f"{parent} -> {child}")
                    if odom_topic is not None and (child == base_frame or "odom" in parent):
                        tf_beside.setdefault((parent, child), []).append(
                            (stamp_seconds(ts.header.stamp), *_tf_pose(ts.transform), 0.0, 0.0, rec))
                if topic == tf_dyn and odom_topic is None and parent == odom_frame and child == base_frame:
                    t = stamp_seconds(ts.header.stamp)
                    order.see(topic, t, f" {odom_frame} -> {base_frame}")
                    odom_rows.append((t, *_tf_pose(ts.transform), 0.0, 0.0, rec))
                elif topic == tf_dyn and odom_topic is None and not odom_rows and (
                        parent == odom_frame or (default_odom and _basename(parent) == odom_frame)):
                    # odom -> another frame (nav2's base_footprint), or a namespaced odom (robot1/odom): kept in case
                    # frames.odom -> frames.base never appears
                    other_rows.setdefault((parent, child), []).append((stamp_seconds(ts.header.stamp),
                                                                       *_tf_pose(ts.transform), 0.0, 0.0, rec))
                elif topic == tf_static or child not in static:
                    if parent != odom_frame or child != base_frame:
                        static[child] = (parent, _tf_mount(ts.transform))
                if several:  # the mountings of the lasers to choose among (``_level_lasers``)
                    x = ts.transform.translation
                    q = ts.transform.rotation
                    pose = (float(x.x), float(x.y), float(x.z), float(q.x), float(q.y), float(q.z), float(q.w))
                    if child not in links or topic == tf_static:
                        links[child] = (parent, pose)
                    elif topic == tf_dyn and child not in moved and _moved(links[child][1], pose):
                        moved.add(child)
        elif topic == odom_topic:
            t = stamp_seconds(msg.header.stamp)
            order.see(topic, t)
            if odom_parent_frame is None:
                odom_parent_frame = _frame(msg.header.frame_id)
            if hasattr(msg, "twist"):
                if odom_child is None:
                    odom_child = _frame(msg.child_frame_id)
                odom_rows.append((t, *_pose_msg(msg), float(msg.twist.twist.linear.x),
                                  float(msg.twist.twist.angular.z), rec))
            else:  # a pose topic (ODOM_TYPES): no child frame, no velocities
                odom_rows.append((t, *_pose_msg(msg), 0.0, 0.0, rec))
        if topic == map_topic:  # the last one: a bag recorded while mapping holds the map as it grew
            map_msg, n_maps = msg, n_maps + 1
        if topic == init_topic and initial is None:
            initial = (np.array(_pose_msg(msg)), _cov3(msg.pose.covariance))
            init_frame = _frame(msg.header.frame_id)
            # RViz stamps it; a zero stamp (``ros2 topic pub /initialpose``): when it was recorded, on the scans'
            # clock (below)
            init_t = stamp_seconds(msg.header.stamp) or None
            init_rec = rec
        if topic == truth_topic:
            if not truth_rows:
                truth_frame = _frame(msg.header.frame_id)
            truth_rows.append((stamp_seconds(msg.header.stamp), *_pose_msg(msg), rec))

    for t in sorted(wanted):
        if seen.get(t, 0) != topics[t].msgcount:
            raise DataError(f"{path}: {t}: {seen.get(t, 0)} messages read of the {topics[t].msgcount} the bag lists "
                            "(truncated or corrupt?)")
    warnings: list[str] = []
    notes: list[str] = []
    map_frame = _frame(map_msg.header.frame_id) if map_msg is not None and map_msg.header.frame_id else "map"
    if initial is not None and init_frame not in ("", map_frame):
        # a pose in the odometry's or the robot's frame is not a place on the map (RViz sends its Fixed Frame's): as
        # AMCL, not used
        warnings.append(f"{path}: {init_topic}: the initial pose is in frame {init_frame!r}, not the map's "
                        f"({map_frame!r}): not used (give the start with --initial-pose)")
        initial = None
    if map_msg is not None:
        grid = _grid_from_msg(path, map_topic, map_msg)
        yaw = yaw_of(map_msg.info.origin.orientation)
        if yaw != 0.0:  # as a map yaml's origin yaw says (mcl.maps.load_map)
            notes.append(f"{path}: {map_topic}: origin yaw {yaw:g} rad: the map is turned about its first cell, as "
                         "map_server defines the origin (AMCL ignores the yaw)")
        if n_maps > 1:
            notes.append(f"{path}: {map_topic}: {n_maps} maps (one being built?); the last, "
                         f"{map_msg.info.width} x {map_msg.info.height} cells, is used")
    if several:
        scan_topics = _level_lasers(path, scan_topics, scan_frames, links, moved, base_frame, odom_frame, notes)
        keep = [o in scan_topics for o in scan_of]
        scan_t, scan_rec, scan_of = ([v for v, k in zip(a, keep) if k] for a in (scan_t, scan_rec, scan_of))
        counts = {t: counts[t] for t in scan_topics}
        undirected = {t: k for t, k in undirected.items() if t in counts}
        sweeps = {t: v for t, v in sweeps.items() if t in counts}
    empty = [t for t in scan_topics if counts[t] == 0]
    if empty:
        raise DataError(f"{path}: {empty[0]}: no messages")
    for t, k in undirected.items():
        why = "angle_min or angle_increment not finite, or angle_increment 0"
        if k == counts[t]:
            raise DataError(f"{path}: {t}: no message says where its beams point ({why})")
        warnings.append(f"{path}: {t}: {k} of {counts[t]} scans do not say where their beams point ({why}): read "
                        "without a reading, the update only predicts")
    # A topic whose header stamps are all 0 (a driver that never sets them) is timed by the bag's record times;
    # a few zero stamps among real ones (a simulator's first messages, before its clock runs) are kept.
    unstamped = set(scan_topics) - {o for v, o in zip(scan_t, scan_of) if v}
    for t in sorted(unstamped):
        notes.append(f"{path}: {t}: {UNSTAMPED}")
    scan_t = [r if o in unstamped else v for v, r, o in zip(scan_t, scan_rec, scan_of)]
    if initial is not None and init_t is None:
        # a zero stamp: its record time moved onto the scans' stamps by their median lag behind them (a simulator's
        # bag: header stamps from 0 on its clock, record times on the wall clock)
        lag = [r - v for v, r in zip(scan_t, scan_rec) if v]
        init_t = init_rec - (float(np.median(lag)) if lag else 0.0)
    if from_scans:
        odom_rows, other_rows = [], {}
    pick = None
    if not odom_rows and odom_topic is None and other_rows and base_frame == _frame(_Frames().base):
        # frames.base (the default) never appears under the odometry frame. One namespaced pair (robot1/odom ->
        # robot1/base_link), else the only transform from an odometry frame (nav2: odom -> base_footprint): that
        # one. A frame the user named is not second-guessed, nor is a choice among several robots made.
        named = [k for k in other_rows if _basename(k[1]) == base_frame]
        pick = named[0] if len(named) == 1 else (next(iter(other_rows)) if len(other_rows) == 1 else None)
    if pick is not None:
        (odom_parent, odom_child), odom_rows = pick, other_rows[pick]
        for row in odom_rows:
            order.see(tf_dyn, row[0], f" {odom_parent} -> {odom_child}")
        notes.append(f"{path}: {tf_dyn}: no {odom_frame} -> {base_frame}; the odometry is {odom_parent} -> "
                     f"{odom_child}, the only such transform (frames.odom and frames.base choose)")
        odom_frame = odom_parent
    if (not odom_rows and odom_topic is None and tf_dyn in topics and default_odom and not from_scans
            and base_frame == _frame(_Frames().base)):
        # Neither odom -> base_link nor any odom -> X: the link that moves the first laser (robot_pose_ekf's
        # odom_combined -> base_footprint; a bag recorded before tf_static repeats the fixed links on /tf).
        found = _moving_link(reader, path, tf_dyn, static, scan_frames[scan_topics[0]])
        if found is not None:
            (odom_frame, odom_child), odom_rows = found
            for row in odom_rows:
                order.see(tf_dyn, row[0], f" {odom_frame} -> {odom_child}")
            notes.append(f"{path}: {tf_dyn}: no {_frame(_Frames().odom)} -> {base_frame}; the odometry is "
                         f"{odom_frame} -> {odom_child}, the transform that moves {scan_frames[scan_topics[0]]} "
                         "(frames.odom and frames.base choose)")
            base_frame = odom_child
    if (not odom_rows and odom_topic is None and tp.odom == "auto" and not other_rows and default_odom
            and base_frame == _frame(_Frames().base)):
        # nothing that could be odometry (frames you name, or several robots' odom links, stay one line)
        from_scans = True
        where = (f"no {odom_frame} -> {base_frame} on {tf_dyn}" if tf_dyn in topics else "no /tf")
        notes.append(f"{path}: no odometry (no nav_msgs/Odometry topic, {where}); the motion comes from the scans "
                     f"(laser odometry: scan matching of {scan_topics[0]}; topics.odom / frames.odom name another "
                     "source)")
    if not odom_rows and not from_scans:
        if odom_topic is not None:
            raise DataError(f"{path}: {odom_topic}: no messages")
        seen = sorted(tf_frames)
        raise DataError(f"{path}: /tf: the transform {odom_frame} -> {base_frame} never appears (it has: "
                        f"{_listing(seen[:12])}{', ...' if len(seen) > 12 else ''}); set frames.odom / frames.base "
                        "or --odom-topic")
    tf_odom = f"{tf_dyn} {odom_frame} -> {odom_child or base_frame}"
    if from_scans:  # a stand-in until the scans are matched, below (times only)
        span = [min(scan_t), max(scan_t)]
        odom_rows = [(t, 0.0, 0.0, 0.0, 0.0, 0.0, t) for t in span]
    odometry = _record_timed(np.array(odom_rows, dtype=np.float64), odom_topic or tf_odom, path, notes)
    odometry = odometry[np.argsort(odometry[:, 0], kind="stable")]
    if not from_scans:
        odometry = _finite_odometry(odometry, odom_topic or tf_odom, path, warnings, notes)
    offsets: dict[str, np.ndarray | None] = {}
    mirrored: set[str] = set()
    for t in scan_topics:
        f = scan_frames[t]
        pose = (0.0, 0.0, 0.0, 1) if f == base_frame else _static_chain(static, base_frame, f)
        if odom_child and odom_child != base_frame and pose is not None:
            # The odometry moves odom_child (an Odometry's child_frame_id, nav2's base_footprint): the laser's
            # mounting is on that frame, through base_link when it hangs below it (base_footprint -> base_link ->
            # laser); the base_link chain alone would leave out the link between the two.
            on_child = (0.0, 0.0, 0.0, 1) if f == odom_child else _static_chain(static, odom_child, f)
            if on_child is not None and not np.allclose(on_child[:3], pose[:3], rtol=0.0, atol=1e-9):
                notes.append(f"{path}: {t}: mounted as {odom_child} -> {f} (the frame the odometry moves), not "
                             f"{base_frame} -> {f}")
                pose = on_child
        if pose is None and odom_child and odom_child != base_frame:
            # no frames.base -> scan frame chain: the frame the odometry moves, if the scan frame hangs off it
            pose = (0.0, 0.0, 0.0, 1) if f == odom_child else _static_chain(static, odom_child, f)
            if pose is not None:
                notes.append(f"{path}: {t}: no transform {base_frame} -> {f}; mounted on {odom_child}, the frame "
                             "the odometry moves")
        if pose is None:
            offsets[t] = None
            frames_tried = base_frame if not odom_child or odom_child == base_frame else f"{odom_child} or {base_frame}"
            if laser_pose is not None:
                notes.append(f"{path}: {t}: no transform {frames_tried} -> {f} in /tf_static or /tf; the laser pose "
                             f"is sensor.laser_pose {list(laser_pose)}")
            else:  # a heading wrong by the laser's yaw (a TurtleBot's laser mounted backwards: pi) loses the track
                warnings.append(f"{path}: {t}: no transform {frames_tried} -> {f} in /tf_static or /tf (a recording "
                                "that missed /tf_static?): the laser is taken at the robot centre, facing forward; "
                                "give its mounting with --set sensor.laser_pose=[x,y,theta]")
        else:
            if not all(math.isfinite(v) for v in pose[:3]):
                raise DataError(f"{path}: {t}: the transform {base_frame} -> {f} is not finite ({pose[:3]})")
            offsets[t] = np.array(pose[:3], dtype=np.float64)
            if pose[3] < 0:
                mirrored.add(t)
                notes.append(f"{path}: {t}: frame {f} is mounted upside down ({base_frame} -> {f} turns z down); "
                             "its beams are read mirrored")
    truth = None
    if truth_topic is not None:
        if not truth_rows:
            raise DataError(f"{path}: {truth_topic}: no messages")
        a = _record_timed(np.array(truth_rows, dtype=np.float64), truth_topic, path, notes)
        if truth_frame not in ("", map_frame):  # /odom given as the truth scores the odometry's frame (17 m)
            warnings.append(f"{path}: {truth_topic}: the reference poses are in frame {truth_frame!r}, not the map's "
                            f"({map_frame!r}): the run is scored against them as if they were")
        truth = (a[:, 0].copy(), np.ascontiguousarray(a[:, 1:].T))
    odom_type = topics[odom_topic].msgtype if odom_topic else None
    src_name = f"{odom_topic} ({odom_type.replace('/msg/', '/')})" if odom_topic else tf_odom
    if tf_dyn != "/tf":
        notes.append(f"{path}: the transforms are on {tf_dyn} and {tf_static} (no /tf, one namespace's)")
    scans = BagScans(path, scan_topics, sum(counts.values()), odometry, offsets, tuple(tp.cloud_z), tp.cloud_beams,
                     has_twist=odom_type == ODOM, mirrored=mirrored, unstamped=unstamped,
                     echo=getattr(tp, "echo", "first"))
    recorded = None if from_scans else odometry
    if from_scans:
        frame_of_odometry = None
    elif odom_topic is not None:  # a topic's own frame (an empty frame_id: frames.odom)
        frame_of_odometry = odom_parent_frame or odom_frame
        link = (frame_of_odometry, odom_child or base_frame)
        beside = _tf_beside(tf_beside.get(link), odometry, f"{tf_dyn} {link[0]} -> {link[1]}", path)
        if beside is not None:
            recorded, off, turn = beside
            notes.append(f"{path}: {tf_dyn} {link[0]} -> {link[1]} (an EKF's?) differs from {odom_topic} by up to "
                         f"{off:.2f} m and {math.degrees(turn):.1f} deg: the run follows {odom_topic}; an estimate "
                         f"bag's map -> {link[0]} is made to join /tf's tree")
    else:  # the /tf link read: frames.odom, or the namespaced / other odometry frame found above
        frame_of_odometry = odom_frame
    gaps = [] if from_scans else odometry_gaps(odometry, np.array(scan_t, dtype=np.float64))
    if gaps:  # the odometry stops for a while, the scans go on: the gaps filled by matching the scans
        mount = offsets[scan_topics[0]] if laser_pose is None else np.asarray(laser_pose, dtype=np.float64)
        odometry = _fill_gaps(path, scans, scan_topics[0], mount, odometry, gaps, src_name, warnings)
        scans.odometry = odometry
    if from_scans:
        mount = offsets[scan_topics[0]] if laser_pose is None else np.asarray(laser_pose, dtype=np.float64)
        odometry = _scan_odometry(path, scans, scan_topics[0], mount, warnings, counts, progress)
        scans.odometry = odometry
        src_name = f"laser odometry (scan matching of {scan_topics[0]})"
    if initial is not None and scan_t and odometry.shape[0] >= 2:
        # The first /initialpose is the start, but an operator may give it after the robot has moved (RViz's
        # 2D Pose Estimate some way into the recording): it says where the robot was at its own time. Carried back
        # to the first scan through the odometry, as the filter would have moved it forward.
        from mcl.estimate import compose, inverse
        t_first = float(min(scan_t))
        a, b = odometry_at(odometry, init_t)[0], odometry_at(odometry, t_first)[0]
        d = compose(inverse(a), b)
        span = (float(odometry[0, 0]), float(odometry[-1, 0]))
        if not span[0] - ODOM_SPAN_SLACK <= init_t <= span[1] + ODOM_SPAN_SLACK:
            # on another clock than the odometry (a wall-clock stamp in a simulator's bag): where the robot was then
            # is unknown, so it is taken as where the robot was at the first scan
            warnings.append(f"{path}: {init_topic}: stamped {init_t:.3f} s, outside the odometry's "
                            f"{span[0]:.3f}-{span[1]:.3f} s (another clock?): taken as the pose at the first scan")
        elif math.hypot(float(d[0]), float(d[1])) > 0.05 or abs(float(d[2])) > 0.05:
            start = compose(initial[0], d)
            gap = init_t - t_first
            notes.append(f"{path}: {init_topic}: stamped {abs(gap):.1f} s {'after' if gap > 0 else 'before'} the "
                         f"first scan, {math.hypot(float(d[0]), float(d[1])):.2f} m and "
                         f"{abs(math.degrees(float(d[2]))):.0f} deg from where the odometry puts the robot at that "
                         f"scan: carried {'back' if gap > 0 else 'forward'} to it through the odometry "
                         f"({start[0]:.3f}, {start[1]:.3f}, {start[2]:.3f})")
            initial = (np.asarray(start, dtype=np.float64), initial[1])
    skipped = {n: i.msgcount for n, i in topics.items() if n not in wanted}
    return BagSource(str(path), bag_kind(path), scans, src_name, odometry, offsets, grid, initial, truth,
                     warnings, notes, skipped, scan_stamps=np.array(scan_t, dtype=np.float64), sweeps=sweeps,
                     odom_frame=frame_of_odometry, odom_recorded=recorded,
                     tf_topic=tf_dyn if tf_dyn in topics else "/tf",
                     tf_links=sorted(tuple(f.split(" -> ", 1)) for f in tf_frames),
                     references=sorted(n for n, i in topics.items() if i.msgtype in TRUTH_TYPES
                                       and n not in (src_name.split(" ", 1)[0], init_topic, truth_topic)))


def odometry_gaps(odometry: np.ndarray, scan_stamps: np.ndarray) -> list[tuple[float, float, int]]:
    """Where the odometry stops while the scans go on (a driver that died and came back, a topic dropped for a
    while): (start, end, scans inside) of each pause between two odometry stamps longer than ``ODOM_GAP_MIN`` s and
    ``ODOM_GAP_PERIODS`` median periods with a scan stamped inside, in time order. Interpolated across it, the
    odometry would run a straight line from one end to the other."""
    ot = odometry[:, 0]
    if ot.size < 3:
        return []
    step = np.diff(ot)
    bound = max(ODOM_GAP_MIN, ODOM_GAP_PERIODS * float(np.median(step)))
    t = np.sort(np.asarray(scan_stamps, dtype=np.float64))
    out = []
    for i in np.flatnonzero(step > bound):
        a, b = float(ot[i]), float(ot[i + 1])
        k = int(np.searchsorted(t, b, side="left") - np.searchsorted(t, a, side="right"))
        if k:
            out.append((a, b, k))
    return out


def _fill_gaps(path, scans: "BagScans", topic: str, mount, odometry: np.ndarray, gaps: list, src: str,
               warnings: list) -> np.ndarray:
    """``odometry`` with each of its ``gaps`` (``odometry_gaps``) filled by laser odometry: the scans of ``topic``
    inside it matched one to the next (:func:`mcl.laser_odometry.laser_odometry`) from the last scan before it,
    where the odometry is known, to the first after it; the odometry after the gap is moved rigidly to go on from
    where the matching ended (the filter only uses its steps). A gap without such scans on both sides stays
    interpolated, with a warning. One more pass over the bag's scans."""
    from mcl.estimate import compose, inverse
    from mcl.laser_odometry import laser_odometry

    near: list[list] = [[] for _ in gaps]  # the scans of topic within ODOM_GAP_ANCHOR s of each gap
    for s in scans:
        if s.kind == topic:
            for g, (a, b, _) in zip(near, gaps):
                if a - ODOM_GAP_ANCHOR <= s.t <= b + ODOM_GAP_ANCHOR:
                    g.append(s)
    odometry = odometry.copy()
    filled, left, failed = [], [], 0
    for (a, b, k), group in zip(gaps, near):
        before = [s for s in group if s.t <= a]
        inside = [s for s in group if a < s.t < b]
        after = [s for s in group if s.t >= b]
        if not before or not after or not inside:
            left.append((a, b, k))
            continue
        chain = [before[-1], *inside, after[0]]
        rows, bad = laser_odometry(chain, mount)
        failed += bad
        start = odometry_at(odometry, chain[0].t)[0]  # the robot's odometry pose at the first scan: the anchor
        placed = [compose(start, r[1:4]) for r in rows]  # laser_odometry's first pose is the origin
        # after the gap: the odometry's own poses, moved so that the first scan after it is where matching put it
        move = compose(placed[-1], inverse(odometry_at(odometry, chain[-1].t)[0]))
        later = odometry[:, 0] >= b
        c, sn = math.cos(move[2]), math.sin(move[2])
        x, y = odometry[later, 1].copy(), odometry[later, 2].copy()
        odometry[later, 1] = move[0] + c * x - sn * y
        odometry[later, 2] = move[1] + sn * x + c * y
        odometry[later, 3] = np.arctan2(np.sin(odometry[later, 3] + move[2]), np.cos(odometry[later, 3] + move[2]))
        new = np.array([(s.t, *p, 0.0, 0.0) for s, p in zip(inside, placed[1:-1])], dtype=np.float64)
        odometry = np.concatenate([odometry, new])
        odometry = odometry[np.argsort(odometry[:, 0], kind="stable")]
        filled.append((a, b, len(inside)))
    longest = max(gaps, key=lambda g: g[1] - g[0])
    what = (f"{path}: the odometry ({src}) stops while the scans go on, {len(gaps)} time{'s' if len(gaps) > 1 else ''}"
            f", for up to {longest[1] - longest[0]:.1f} s ({longest[0]:.3f}..{longest[1]:.3f} s)")
    if filled:
        warnings.append(f"{what}: the {sum(g[2] for g in filled)} scans of {topic} in {len(filled)} of them are "
                        f"placed by laser odometry (scan matching){f', {failed} not matched' if failed else ''}")
    if left:
        warnings.append(f"{what}: in {len(left)} of them ({sum(g[2] for g in left)} scans) no scan of {topic} on "
                        "both sides to match from: the odometry runs a straight line across")
    return odometry


def _scan_odometry(path, scans: "BagScans", topic: str, mount, warnings: list, counts: dict,
                   progress: bool | None) -> np.ndarray:
    """Odometry rows (t, x, y, theta, 0, 0) from the scans of ``topic`` matched one to the next
    (:func:`mcl.laser_odometry.laser_odometry`), with a warning when many did not match."""
    from tqdm import tqdm

    from mcl.laser_odometry import laser_odometry

    with tqdm(total=counts[topic], unit="scan", desc="laser odometry", leave=False, dynamic_ncols=True,
              disable=(None if progress is None else not progress)) as bar:
        def stream():
            for s in scans:
                if s.kind == topic:
                    bar.update()
                    yield s

        rows, failed = laser_odometry(stream(), mount)
    if rows.shape[0] < 2:
        raise DataError(f"{path}: no odometry, and {topic} has {rows.shape[0]} scan: nothing to match")
    if failed > 0.05 * rows.shape[0]:
        warnings.append(f"{path}: laser odometry: {failed} of {rows.shape[0]} scans of {topic} matched no "
                        "earlier one (too few returns, or moved too far): their motion is the last step's, or none")
    return rows[np.argsort(rows[:, 0], kind="stable")]


# ----------------------------------------------------------------------------- mcl bag info


def bag_info(path, topics=None, frames=None, sensor=None) -> dict:
    """Topics (type, count), duration, frames in /tf and /tf_static, and what mcl would use (or why not), with the
    run's two checks of the scans (``sensor``: a SensorConfig, for range_min/range_max and laser_pose): the beams
    that read the robot itself (``mcl.datasets.selfhits``) and the odometry's sign and the laser's mounting
    (``mcl.odomcheck``)."""
    path = Path(path)
    reader = _open_reader(path)
    try:
        tps = reader.topics
        info = {
            "path": str(path),
            "kind": bag_kind(path),
            "duration_s": reader.duration * 1e-9 if reader.message_count else 0.0,
            "messages": reader.message_count,
            "topics": {n: {"type": i.msgtype.replace("/msg/", "/") if i.msgtype else "(mixed)",
                           "count": i.msgcount} for n, i in sorted(tps.items())},
        }
        frames_seen: dict[str, set] = {"/tf": set(), "/tf_static": set()}
        label = {"/tf": "/tf", "/tf_static": "/tf_static"}
        if "/tf" not in tps and "/tf_static" not in tps:  # remapped into namespaces: /robot1/tf is listed as /tf
            for ns in _tf_spaces(tps):
                label.update({f"{ns}/tf": "/tf", f"{ns}/tf_static": "/tf_static"})
        conns = [c for c in reader.connections if c.topic in label and c.msgtype in TF_TYPES]
        for conn, _, msg in _messages(reader, path, conns):
            for ts in msg.transforms:
                frames_seen[label[conn.topic]].add(f"{_frame(ts.header.frame_id)} -> {_frame(ts.child_frame_id)}")
        info["frames"] = {k: sorted(v) for k, v in frames_seen.items()}
    finally:
        reader.close()
    try:
        src = open_bag(path, topics, frames)
        stamp_warnings = src.stamps_checked()  # scans and odometry on two clocks: the error below
        info["mcl_uses"] = {
            "scan_topics": src.scans.topics,
            "scans": len(src.scans),
            "odometry": src.odom_source,
            "scan_span_s": [round(float(src.scan_stamps.min()), 6), round(float(src.scan_stamps.max()), 6)],
            "odometry_span_s": [round(float(src.odometry[0, 0]), 6), round(float(src.odometry[-1, 0]), 6)],
            "warnings": src.warnings + stamp_warnings,
            "laser_pose": {t: (None if o is None else [round(float(v), 6) for v in o])
                           for t, o in src.laser_offsets.items()},
            "beams": _beam_geometry(src, info["topics"]),
            "sweep_s": {t: round(float(v), 6) for t, v in src.sweeps.items()},
            "map": "from the bag" if src.grid is not None else "needs --map",
            "initial_pose": (None if src.initial_pose is None
                             else [round(float(v), 6) for v in src.initial_pose[0]]),
            "references": src.references,
            "notes": src.notes,
            **_scan_checks(src, sensor),
        }
    except DataError as e:
        info["mcl_uses"] = {"error": str(e)}
    return info


def _beam_geometry(src: "BagSource", topics: dict) -> dict:
    """{scan topic: ``mcl.datasets.loginfo.laser_geometry``} from each topic's first scan as a run reads it (a
    LaserScan's beams, range_max and mounting; a point cloud's beams as binned), the topic's message count beside
    it. Reads the bag only up to the last topic's first scan."""
    first: dict = {}
    for s in src.scans:
        first.setdefault(s.kind, s)
        if len(first) == len(src.scans.topics):
            break
    return {t: laser_geometry(s, topics.get(t, {}).get("count", 0), [int(s.ranges.size)])
            for t, s in sorted(first.items(), key=lambda kv: src.scans.topics.index(kv[0]))}


def _scan_checks(src: "BagSource", sensor) -> dict:
    """``bag_info``'s checks of the scans (``mcl.datasets.loginfo.scan_checks``): the bag's odometry stream, none
    for laser odometry."""
    return scan_checks(src.scans, src.odometry, sensor, src.wheel_odometry)


def format_info(info: dict) -> str:
    lines = [f"{info['path']}: {info['kind']}, {info['messages']} messages, {info['duration_s']:.1f} s"]
    lines.append("topics:")
    w = max((len(n) for n in info["topics"]), default=0)
    for n, t in info["topics"].items():
        lines.append(f"  {n:<{w}}  {t['type']:<40} {t['count']:>8}")
    for k in ("/tf", "/tf_static"):
        lines.append(f"frames in {k}: {', '.join(info['frames'][k]) or 'none'}")
    u = info["mcl_uses"]
    lines.append("mcl would use:")
    if "error" in u:
        lines.append(f"  nothing: {u['error']}")
    else:
        lines.append(f"  scans:        {', '.join(u['scan_topics'])} ({u['scans']} messages)")
        lines.append(f"  odometry:     {u['odometry']}")
        (a, b), (c, d) = u["scan_span_s"], u["odometry_span_s"]
        lines.append(f"  stamps:       scans {a:.3f}..{b:.3f} s, odometry {c:.3f}..{d:.3f} s")
        for t, g in u.get("beams", {}).items():
            lines.append(f"  beams:        {t}: {beams_text(g)}")
        for t, p in u["laser_pose"].items():
            lines.append(f"  laser pose:   {t}: {p if p is not None else 'not in /tf_static or /tf (sensor.laser_pose)'}")
        for t, v in u.get("sweep_s", {}).items():
            lines.append(f"  beam times:   {t}: " + (f"{v:.4g} s from the first beam to the last (time_increment): "
                                                     "deskewed (sensor.sweep_time auto)" if v else
                                                     "none (time_increment 0): not deskewed unless sensor.sweep_time "
                                                     "says how long a sweep takes"))
        lines.append(f"  map:          {u['map']}")
        lines.append(f"  initial pose: {u['initial_pose'] if u['initial_pose'] is not None else 'none in the bag'}")
        refs = [f"{n} ({info['topics'][n]['type']}, {info['topics'][n]['count']})" for n in u["references"]]
        lines.append("  reference:    " + (", ".join(refs) + ": score a run against one with --truth-topic TOPIC" if refs
                                          else "no pose topic besides the odometry (--truth T.tum scores against a file)"))
        lines += check_lines(u)
        lines += [f"  note: {n}" for n in u.get("notes", [])]
        lines += [f"  warning: {w}" for w in u["warnings"]]
    return "\n".join(lines)
