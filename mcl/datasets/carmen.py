"""CARMEN log reader (plain or gzip) -> :class:`Log` of laser scans and odometry.

Messages read (everything else is skipped and counted in ``Log.skipped``):

* ``ODOM x y theta tv rv accel ipc_timestamp hostname logger_timestamp``
* ``FLASER``/``RLASER`` (old format)
  ``n r_1..r_n x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp``;
  the first pose is the laser's, the second the robot's, both in the odometry
  frame. Beam i points at ``-pi/2 + i*d`` (counter-clockwise, beam 0 on the
  right) with d = pi/180 for 180 or 181 beams, pi/360 for 360 or 361 beams,
  otherwise pi/(n-1) for odd n (a 180-degree fan with both ends included) and
  pi/n for even n (a fan with the left end excluded). ``max_range`` comes from
  the log's ``PARAM robot_front_laser_max`` (``robot_rear_laser_max`` for
  RLASER) when it has one, else None: the config's ``sensor.range_max`` decides.
* ``ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode
  n r_1..r_n n_rem rem_1..rem_m laser_x laser_y laser_theta robot_x robot_y robot_theta
  tv rv forward_safety side_safety turn_axis ipc_timestamp hostname logger_timestamp``;
  ``ROBOTLASER2`` the same for CARMEN's second (rear) laser
* ``RAWLASER1``..``RAWLASER4``: as ROBOTLASER1 without the poses and the velocities.
* ``LANDMARK n id_1 range_1 bearing_1 ... id_n range_n bearing_n ipc_timestamp hostname logger_timestamp``
  (an mcl extension, not a CARMEN message): n >= 0 range-bearing observations of
  landmarks with known correspondences, ids integers >= 0 of the landmark map,
  ranges in m from the robot centre, bearings in rad counter-clockwise from the
  robot's heading. -> ``Log.landmarks`` (:class:`Landmarks`), ``odom`` from the
  ODOM lines interpolated at ``t``. A log may have landmarks and no laser.

``Scan.laser_offset`` is the laser's mounting in the robot frame,
``robot_pose^-1 ∘ laser_pose``. Scans without a pose of their own (RAWLASER)
get ``odom`` by interpolating the ODOM lines at their timestamp (linear in x, y,
shortest angle difference in theta, clamped before the first / after the last).

A malformed line raises :class:`DataError` naming ``file:line`` and the message
type, except a truncated last line (no final newline), which is skipped with a
note in ``Log.warnings``.
"""

from __future__ import annotations

import math
import os
import zlib
import dataclasses
from dataclasses import dataclass, field

import numpy as np

from mcl.errors import DataError
from mcl.estimate import wrap_angle

__all__ = ["Scan", "Landmarks", "Log", "read_carmen", "interpolate_odometry", "flaser_angle_increment", "LASER_KINDS",
           "FRONT_REAR"]

LASER_KINDS = ("FLASER", "RLASER", "ROBOTLASER1", "ROBOTLASER2", "RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4")
_USED = (*LASER_KINDS, "ODOM", "LANDMARK")  # the messages mcl reads
_OTHERS = ("RAWLASER5",)  # another CARMEN message one character off those (a fifth laser)
# a front laser's stream and its rear laser's, in the two formats: ``laser_stream("auto")`` fuses each pair
FRONT_REAR = (("FLASER", "RLASER"), ("ROBOTLASER1", "ROBOTLASER2"))


def _one_edit(a: str, b: str) -> bool:
    """Whether ``a`` and ``b`` differ by at most one character inserted, deleted or replaced."""
    if abs(len(a) - len(b)) > 1:
        return False
    if len(a) > len(b):
        a, b = b, a
    i = next((k for k, (x, y) in enumerate(zip(a, b)) if x != y), len(a))
    return a[i + (len(a) == len(b)):] == b[i + 1:]


def _damaged(word: str) -> bool:
    """A message name that is not one (CARMEN's are upper case, digits and _), or one of mcl's messages in another
    case or one character off (FLASR, flaser): a damaged line, not another sensor's message."""
    if not all(c.isupper() or c.isdigit() or c in "_-" for c in word):
        return True
    return word not in _OTHERS and any(_one_edit(word, k) for k in _USED)


def _printable_word(word: str) -> str:
    return word if word.isprintable() and len(word) <= 40 else repr(word[:40])[1:-1]
_AUTO_ORDER = ("FLASER", "ROBOTLASER1", "RAWLASER1")


@dataclass(frozen=True, slots=True, eq=False)
class Scan:
    """One laser scan. Angles in the laser frame, poses as (x, y, theta)."""

    t: float  # ipc timestamp
    ranges: np.ndarray  # float64 (n,)
    angle_min: float
    angle_increment: float
    max_range: float | None  # None: the config decides
    odom: np.ndarray | None  # (3,) robot pose in the odometry frame
    laser_offset: np.ndarray | None  # (3,) laser pose in the robot frame; None: unknown
    tv: float = 0.0
    rv: float = 0.0
    kind: str = "FLASER"
    line: int = 0  # 1-based line number in the log
    # When each beam was taken (a spinning laser's sweep): beam j at t + beam_t0 + j * beam_dt (s). A bag's
    # LaserScan time_increment; 0 in a CARMEN log (it does not say; sensor.sweep_time can)
    beam_t0: float = 0.0
    beam_dt: float = 0.0
    # (vx, vy, omega) the robot's velocity over the sweep in its frame at t, from the odometry (mcl.runner sets it
    # when sensor.sweep_time applies); None: the beams are taken as all measured at t
    twist: np.ndarray | None = None
    # the odometry into this scan was taken from scan matching by the stall fill (mcl.odomstall), not the log's
    filled: bool = False

    @property
    def angles(self) -> np.ndarray:
        """Beam angles (n,) in the laser frame."""
        return self.angle_min + self.angle_increment * np.arange(self.ranges.shape[0], dtype=np.float64)


@dataclass(frozen=True, slots=True, eq=False)
class Landmarks:
    """One LANDMARK line: range-bearing observations of landmarks by id (mcl extension).

    ``odom`` is the robot pose in the odometry frame interpolated from ODOM at
    ``t``; ``tv``/``rv`` are 0 (the line carries no velocities), as RAWLASER.
    """

    t: float
    ids: np.ndarray  # int64 (n,)
    ranges: np.ndarray  # float64 (n,), m
    bearings: np.ndarray  # float64 (n,), rad
    line: int = 0
    odom: np.ndarray | None = None
    tv: float = 0.0
    rv: float = 0.0


@dataclass(eq=False)
class Log:
    """A parsed CARMEN log."""

    path: str
    scans: list[Scan]
    odometry: np.ndarray  # (M, 6) float64: t, x, y, theta, tv, rv (file order)
    skipped: dict[str, int] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    landmarks: list[Landmarks] = field(default_factory=list)  # LANDMARK lines in file order
    notes: list[str] = field(default_factory=list)  # what the reader found by itself (e.g. the no-return value)

    def scans_of(self, kind: str) -> list[Scan]:
        """Scans of one message type, in file order."""
        return [s for s in self.scans if s.kind == kind]

    def kinds(self) -> dict[str, int]:
        """Laser message types present -> count."""
        out: dict[str, int] = {}
        for s in self.scans:
            out[s.kind] = out.get(s.kind, 0) + 1
        return out

    def default_kind(self) -> str:
        """The laser stream ``"auto"`` picks: FLASER if present, else ROBOTLASER1, else RAWLASER1."""
        kinds = self.kinds()
        for k in _AUTO_ORDER:
            if k in kinds:
                return k
        found = ", ".join(sorted(kinds)) or "none"
        raise DataError(f"{self.path}: no FLASER, ROBOTLASER1 or RAWLASER1 messages "
                        f"(found: {found}); choose the laser stream explicitly")

    def laser_stream(self, kind: str = "auto") -> list[Scan]:
        """The scans a run reads (config key ``laser``), in file order; DataError if there are none.

        ``kind``: one message type; several fused, comma-separated (``"FLASER,RLASER"``: each on the mounting its
        lines give; not one laser written in two formats, which a log may hold both of); or ``"auto"``: a front and a
        rear laser fused when the log has both (FLASER and RLASER, else ROBOTLASER1 and ROBOTLASER2; said in
        ``notes``), else :meth:`default_kind`, else the first laser stream the log has (a rear one alone, RAWLASER2)."""
        kinds = self.kinds()
        if kind == "auto":
            pair = next((p for p in FRONT_REAR if p[0] in kinds and p[1] in kinds), None)
            if pair is None:
                first = next((k for k in (*_AUTO_ORDER, *LASER_KINDS) if k in kinds), None)
                if first is None:
                    raise DataError(f"{self.path}: no laser messages")
                return self.scans_of(first)
            note = (f"{self.path}: {pair[0]} and {pair[1]} (a front and a rear laser): fused, each on the mounting "
                    f"its lines give (laser: {pair[0]} reads the front one alone)")
            if note not in self.notes:  # said once, however often the stream is read
                self.notes.append(note)
            kind = ",".join(pair)
        wanted = kind.split(",")
        for k in wanted:
            if k not in kinds:
                found = ", ".join(sorted(kinds)) or "none"
                raise DataError(f"{self.path}: no {k} messages (found: {found})")
        return [s for s in self.scans if s.kind in wanted]


def flaser_angle_increment(n: int) -> float:
    """Beam spacing of an old-format FLASER/RLASER with ``n`` beams (see the module doc)."""
    if n in (180, 181):
        return math.pi / 180.0
    if n in (360, 361):
        return math.pi / 360.0
    if n <= 1:
        return math.pi  # at most one beam: the spacing is never used
    return math.pi / (n - 1) if n % 2 else math.pi / n


class _Bad(Exception):
    """A malformed line (message without the file:line prefix)."""


def _floats(parts: list[str], what: str, kind: str) -> np.ndarray:
    try:
        return np.array(parts, dtype=np.float64)
    except ValueError:
        bad = next((p for p in parts if not _is_float(p)), "?")
        raise _Bad(f"{kind}: non-numeric {what} {bad[:30]!r}") from None


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _count(s: str, what: str, kind: str) -> int:
    try:
        n = int(s)
    except ValueError:
        raise _Bad(f"{kind}: {what} is not an integer: {s[:30]!r}") from None
    if n < 0:
        raise _Bad(f"{kind}: negative {what} {n}")
    if n > 2 ** 63 - 1:  # (an OverflowError traceback as an int64 landmark id)
        raise _Bad(f"{kind}: {what} {s[:30]} is too large")
    return n


def _few_floats(parts: list[str], what: str, kind: str) -> list[float]:
    """``_floats`` for the few fields of a line (its poses, config, times) as a list of Python floats: the same
    values and the same error (numpy parses each str with Python's float), without an array's cost per call (a
    few us; seven calls a line were a sixth of reading a log)."""
    try:
        return [float(p) for p in parts]
    except ValueError:
        bad = next((p for p in parts if not _is_float(p)), "?")
        raise _Bad(f"{kind}: non-numeric {what} {bad[:30]!r}") from None


def _pose_check(v, what: str, kind: str) -> None:
    if not all(map(math.isfinite, v)):
        raise _Bad(f"{kind}: non-finite {what}")


def _timestamp(parts: list[str], kind: str) -> float:
    """ipc_timestamp hostname logger_timestamp (the last three fields)."""
    ts = _few_floats([parts[-3], parts[-1]], "timestamp", kind)
    if not (math.isfinite(ts[0]) and math.isfinite(ts[1])):
        raise _Bad(f"{kind}: non-finite timestamp")
    return ts[0]


MOUNT_JITTER = 1e-5  # m and rad: a laser's mountings that differ by no more are one mounting, printed round


def _steady_mounting(scans: list[Scan]) -> list[Scan]:
    """Each laser's mounting as one pose when its scans' mountings agree within ``MOUNT_JITTER``: a line's laser and
    robot poses are printed to a few decimals, so the mounting worked out from them jitters by about 1e-6 from scan to
    scan (151 mountings for one laser, 0.1 m off the centre), and a run then drifted up to 7.7 mm from the same world
    as a bag, whose /tf_static holds one. The median of each coordinate stands for them all; a mounting that does
    vary (a log whose laser poses are corrected ones) is left as it is."""
    out = scans
    for kind in {s.kind for s in scans if s.laser_offset is not None}:
        idx = [k for k, s in enumerate(scans) if s.kind == kind and s.laser_offset is not None]
        offs = np.array([scans[k].laser_offset for k in idx])
        if len(idx) < 2 or np.all(offs == offs[0]):
            continue
        # headings about the first's (a laser looking back jitters across +-pi, where a plain median is ~0)
        turn = wrap_angle(offs[:, 2] - offs[0, 2])
        heading = offs[0, 2] + np.median(turn)
        mid = np.array([*np.median(offs[:, :2], axis=0), heading if abs(heading) <= math.pi else wrap_angle(heading)])
        dev = np.abs(np.column_stack([offs[:, :2] - mid[:2], wrap_angle(offs[:, 2] - mid[2])]))
        if dev.max() > MOUNT_JITTER:
            continue
        if out is scans:
            out = list(scans)
        for k in idx:
            out[k] = dataclasses.replace(scans[k], laser_offset=mid.copy())
    return out


def _offset(laser, robot, kind: str) -> np.ndarray:
    """robot^-1 ∘ laser: the laser pose expressed in the robot frame."""
    # Python floats: finite poses ~1e308 apart overflow to inf quietly, caught below.
    dx, dy = float(laser[0]) - float(robot[0]), float(laser[1]) - float(robot[1])
    c, s = math.cos(robot[2]), math.sin(robot[2])
    # Wrap each heading first: the plain difference of two finite headings may overflow.
    dth = math.remainder(float(laser[2]), math.tau) - math.remainder(float(robot[2]), math.tau)
    out = np.array([c * dx + s * dy, -s * dx + c * dy, math.atan2(math.sin(dth), math.cos(dth))])
    if not np.isfinite(out).all():
        raise _Bad(f"{kind}: laser pose too far from the robot pose (offset not finite)")
    return out


def _parse_odom(parts: list[str]) -> list[float]:
    if len(parts) != 10:
        raise _Bad(f"ODOM: expected 10 fields, got {len(parts)}")
    v = _few_floats(parts[1:7], "field", "ODOM")
    _pose_check(v, "value", "ODOM")
    t = _timestamp(parts, "ODOM")
    return [t, v[0], v[1], v[2], v[3], v[4]]


def _parse_flaser(parts: list[str], kind: str, lineno: int) -> Scan:
    if len(parts) < 2:
        raise _Bad(f"{kind}: missing beam count")
    n = _count(parts[1], "beam count", kind)
    if len(parts) != n + 11:
        raise _Bad(f"{kind}: expected {n} ranges + 9 fields ({n + 11} in all), got {len(parts)} fields")
    ranges = _floats(parts[2:2 + n], "range", kind)
    poses = _few_floats(parts[2 + n:8 + n], "pose", kind)
    _pose_check(poses, "pose", kind)
    t = _timestamp(parts, kind)
    laser, robot = poses[:3], np.array(poses[3:])
    return Scan(t, ranges, -math.pi / 2, flaser_angle_increment(n), None, robot,
                _offset(laser, poses[3:], kind), 0.0, 0.0, kind, lineno)


def _parse_laser_config(parts: list[str], kind: str, extra: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Shared head of ROBOTLASER1/RAWLASER: config (7,), ranges (n,), index after remissions.

    ``extra`` is the number of fields after the remissions (poses etc. + 3 time fields).
    """
    if len(parts) < 9:
        raise _Bad(f"{kind}: too few fields ({len(parts)})")
    config = _few_floats(parts[1:8], "config field", kind)
    n = _count(parts[8], "beam count", kind)
    i_rem = 9 + n
    if len(parts) < i_rem + 1:
        raise _Bad(f"{kind}: expected {n} ranges, line ends after {len(parts) - 9}")
    m = _count(parts[i_rem], "remission count", kind)
    expect = i_rem + 1 + m + extra
    if len(parts) != expect:
        raise _Bad(f"{kind}: expected {n} ranges, {m} remissions and {extra} more fields "
                   f"({expect} in all), got {len(parts)} fields")
    ranges = _floats(parts[9:9 + n], "range", kind)
    if m:  # checked, not kept
        _floats(parts[i_rem + 1:i_rem + 1 + m], "remission", kind)
    if n > 1 and config[3] == 0.0:
        raise _Bad(f"{kind}: angular resolution 0 with {n} beams: where they point is unknown")
    return config, ranges, i_rem + 1 + m


def _parse_robotlaser(parts: list[str], kind: str, lineno: int) -> Scan:
    config, ranges, i = _parse_laser_config(parts, kind, 6 + 5 + 3)
    _pose_check(config[1:5], "beam geometry", kind)
    rest = _few_floats(parts[i:i + 11], "pose/velocity", kind)
    _pose_check(rest, "pose/velocity", kind)
    t = _timestamp(parts, kind)
    laser, robot = rest[0:3], np.array(rest[3:6])
    return Scan(t, ranges, config[1], config[3], _max_field(config[4]), robot,
                _offset(laser, rest[3:6], kind), rest[6], rest[7], kind, lineno)


def _max_field(v: float) -> float | None:
    """A ROBOTLASER / RAWLASER line's maximum range field: None (unknown: the config decides) when it is not
    positive. A driver that writes 0 there made every reading a no-return: the run only predicted, without a word."""
    return float(v) if v > 0.0 else None


def _parse_rawlaser(parts: list[str], kind: str, lineno: int) -> Scan:
    config, ranges, _ = _parse_laser_config(parts, kind, 3)
    _pose_check(config[1:5], "beam geometry", kind)
    t = _timestamp(parts, kind)
    return Scan(t, ranges, config[1], config[3], _max_field(config[4]), None, None,
                0.0, 0.0, kind, lineno)


def _parse_landmark(parts: list[str], lineno: int) -> Landmarks:
    kind = "LANDMARK"
    if len(parts) < 2:
        raise _Bad(f"{kind}: missing observation count")
    n = _count(parts[1], "observation count", kind)
    if len(parts) != 3 * n + 5:
        raise _Bad(f"{kind}: expected {n} (id range bearing) triples + 3 time fields ({3 * n + 5} in all), "
                   f"got {len(parts)} fields")
    ids = np.array([_count(p, "landmark id", kind) for p in parts[2:2 + 3 * n:3]], dtype=np.int64)
    v = _floats([p for k, p in enumerate(parts[2:2 + 3 * n]) if k % 3], "range/bearing", kind).reshape(n, 2)
    if not np.all(np.isfinite(v)):
        raise _Bad(f"{kind}: non-finite range or bearing")
    if np.any(v[:, 0] < 0):
        raise _Bad(f"{kind}: negative range {float(v[v[:, 0] < 0, 0][0])}")
    t = _timestamp(parts, kind)
    return Landmarks(t, ids, np.ascontiguousarray(v[:, 0]), np.ascontiguousarray(v[:, 1]), lineno)


_PARSERS = {
    "FLASER": _parse_flaser,
    "RLASER": _parse_flaser,
    "ROBOTLASER1": _parse_robotlaser,
    "ROBOTLASER2": _parse_robotlaser,
    "RAWLASER1": _parse_rawlaser,
    "RAWLASER2": _parse_rawlaser,
    "RAWLASER3": _parse_rawlaser,
    "RAWLASER4": _parse_rawlaser,
}


def _read_bytes(path: str | os.PathLike, name: str, warnings: list[str]) -> bytes:
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise DataError(f"{name}: cannot read: {e.strerror or type(e).__name__}") from None
    if data[:2] != b"\x1f\x8b":
        return data
    # gzip (possibly multi-member); a truncated stream keeps what was decompressed.
    out = []
    rest = data
    try:
        while rest[:2] == b"\x1f\x8b":
            d = zlib.decompressobj(wbits=31)
            out.append(d.decompress(rest))
            out.append(d.flush())
            if not d.eof:
                warnings.append(f"{name}: gzip stream is truncated; reading what was decompressed")
                break
            rest = d.unused_data
    except zlib.error as e:
        raise DataError(f"{name}: corrupt gzip data ({e})") from None
    return b"".join(out)


def _lines(text: str):
    """The lines of ``text`` one at a time (str.split would hold them all beside the text), without their
    newlines; a last line without one too."""
    start, end = 0, len(text)
    while start < end:
        stop = text.find("\n", start)
        if stop < 0:
            stop = end
        yield text[start:stop]
        start = stop + 1


def read_carmen(path: str | os.PathLike, *, need_laser: bool = True) -> Log:
    """Read a CARMEN log (plain or gzip, detected by magic bytes) into a :class:`Log`. ``need_laser`` False (``mcl
    calibrate motion``): ODOM lines alone are a log too."""
    name = str(path)
    warnings: list[str] = []
    data = _read_bytes(path, name, warnings)
    if not data or data.isspace():  # not data.strip(): that copied the whole log (0.16 s of 2.8 on 211 MB)
        raise DataError(f"{name}: empty file")
    ends_with_newline = data.endswith(b"\n")
    try:
        text = data.decode("utf-8-sig")  # a byte-order mark (Windows editors) is no record
    except UnicodeDecodeError as e:
        last_start = data.rfind(b"\n") + 1
        if ends_with_newline or e.start < last_start:
            line = data.count(b"\n", 0, e.start) + 1
            raise DataError(f"{name}:{line}: not UTF-8 text") from None
        # A truncated last line may end inside a multi-byte character: drop it.
        text = data[:last_start].decode("utf-8-sig")  # e.start is the first bad byte
        line = data.count(b"\n") + 1
        warnings.append(f"{name}:{line}: truncated last line skipped (not UTF-8)")
        ends_with_newline = True

    del data  # the decoded text alone from here (a log of hundreds of MB held three times over)
    # the number of the last line, a truncated one (no newline) being the only one it is asked about
    last = 0 if ends_with_newline else text.count("\n") + 1

    scans: list[Scan] = []
    odom_rows: list[list[float]] = []
    landmarks: list[Landmarks] = []
    skipped: dict[str, int] = {}
    params: dict[str, str] = {}
    damaged: list[tuple[int, str]] = []  # lines whose keyword looks like a known one damaged (skipped)
    parsers = _PARSERS
    logged: list[float] = []  # the ODOM lines' logger timestamps (the last field)
    scan_logged: list[float] = []  # the scans'
    for lineno, raw in enumerate(_lines(text), start=1):
        parts = raw.split()
        if not parts:
            skipped["(blank)"] = skipped.get("(blank)", 0) + 1
            continue
        word = parts[0]
        try:
            if word == "ODOM":
                odom_rows.append(_parse_odom(parts))
                logged.append(float(parts[-1]))
                continue
            if word == "LANDMARK":
                landmarks.append(_parse_landmark(parts, lineno))
                continue
            parser = parsers.get(word)
            if parser is None:
                if word == "PARAM" and len(parts) >= 3:
                    params[parts[1]] = parts[2]
                key = "#" if word.startswith("#") else word
                skipped[key] = skipped.get(key, 0) + 1
                if key != "#" and _damaged(word):
                    damaged.append((lineno, word))
                continue
            scans.append(parser(parts, word, lineno))
            scan_logged.append(float(parts[-1]))  # a number: the parser read it (_timestamp)
        except _Bad as e:
            if lineno == last and not ends_with_newline:
                warnings.append(f"{name}:{lineno}: truncated last line skipped ({e})")
                continue
            raise DataError(f"{name}:{lineno}: {e}") from None

    del text  # parsed: the scans hold what is needed
    if damaged:
        lineno, word = damaged[0]
        warnings.append(f"{name}:{lineno}: {len(damaged)} line{'s' if len(damaged) > 1 else ''} skipped whose "
                        f"message name looks damaged (the first: {_printable_word(word)!r}; a known one misspelt or "
                        "not a name at all)")
    if not scans and not landmarks and (need_laser or not odom_rows):
        raise DataError(f"{name}: no laser messages (FLASER, RLASER, ROBOTLASER1, ROBOTLASER2, RAWLASER1..4)"
                        + ("" if need_laser else " and no ODOM lines"))
    odometry = np.array(odom_rows, dtype=np.float64).reshape(-1, 6)
    notes: list[str] = []
    if len(scans) > 1 and len({s.t for s in scans}) == 1 and len(set(scan_logged)) > 1:
        # every ipc_timestamp the same (a logger that never set them, 0 throughout): the scans could not be timed
        # (every one at t = 0, one reference pose scored); the logger's own timestamps stand in
        notes.append(f"{name}: every laser line has the ipc_timestamp {scans[0].t:g}; the logger timestamps (the "
                     "last field) stand in for them, and for the ODOM lines'")
        scans = [dataclasses.replace(s, t=t) for s, t in zip(scans, scan_logged)]
        if odometry.shape[0]:
            odometry[:, 0] = logged
    scans = _fill_odom(scans, odometry, name)
    scans = _steady_mounting(scans)
    scans = _param_max_range(scans, params)
    scans = _detected_max_range(scans, name, notes)
    for kind in _MAX_RANGE_PARAMS:
        counts = sorted({s.ranges.size for s in scans if s.kind == kind} - {0, 1, 180, 181, 360, 361})
        if counts:  # read as a SICK's half turn whatever the laser (a UTM-30LX's 1081 over 270 degrees: lost)
            notes.append(f"{name}: {kind}: {counts[0]} beams a line: {kind} lines do not say their angles and are read "
                         "as a 180-degree fan (a SICK's); a laser of another field of view needs ROBOTLASER1 or "
                         "RAWLASER lines, which say it")
    landmarks = _landmark_odom(landmarks, odometry, name)
    return Log(name, scans, odometry, skipped, warnings, landmarks, notes)


def _landmark_odom(records: list[Landmarks], odometry: np.ndarray, name: str) -> list[Landmarks]:
    """Give each LANDMARK record the odometry pose interpolated at its time."""
    if not records:
        return records
    if odometry.shape[0] == 0:
        raise DataError(f"{name}:{records[0].line}: LANDMARK: no ODOM lines to interpolate the pose from")
    with np.errstate(over="ignore", invalid="ignore"):
        poses = interpolate_odometry(odometry, [r.t for r in records])
    bad = np.flatnonzero(~np.isfinite(poses).all(axis=0))
    if bad.size:
        r = records[bad[0]]
        raise DataError(f"{name}:{r.line}: LANDMARK: odometry interpolated at t={r.t} is not finite")
    return [dataclasses.replace(r, odom=np.ascontiguousarray(poses[:, k])) for k, r in enumerate(records)]


# FLASER/RLASER lines carry no maximum range; a log's PARAM lines may give it.
_MAX_RANGE_PARAMS = {"FLASER": "robot_front_laser_max", "RLASER": "robot_rear_laser_max"}


def _param_max_range(scans: list[Scan], params: dict[str, str]) -> list[Scan]:
    """Give FLASER/RLASER scans the ``PARAM robot_{front,rear}_laser_max`` of the log, when it has one."""
    limits = {}
    for kind, key in _MAX_RANGE_PARAMS.items():
        try:
            v = float(params[key])
        except (KeyError, ValueError):
            continue
        if math.isfinite(v) and v > 0:
            limits[kind] = v
    if not limits:
        return scans
    return [
        dataclasses.replace(s, max_range=limits[s.kind]) if (s.max_range is None and s.kind in limits) else s
        for s in scans
    ]


def _detected_max_range(scans: list[Scan], name: str, notes: list[str]) -> list[Scan]:
    """Give FLASER/RLASER scans still without a maximum range the no-return threshold found in their readings
    (``mcl.datasets.noreturn``), and say what was found in ``notes``."""
    from mcl.datasets.noreturn import detect_no_return

    out = scans
    for kind in _MAX_RANGE_PARAMS:
        idx = [k for k, s in enumerate(scans) if s.kind == kind and s.max_range is None]
        if not idx:
            continue
        nr = detect_no_return([scans[k].ranges for k in idx])  # a block at a time: not every reading copied
        if nr is None:
            notes.append(f"{name}: {kind}: no no-return value found in the readings; sensor.range_max decides")
            continue
        notes.append(f"{name}: {kind}: {nr.describe()}")
        if out is scans:
            out = list(scans)
        for k in idx:
            out[k] = dataclasses.replace(scans[k], max_range=nr.threshold)
    return out


def interpolate_odometry(odometry: np.ndarray, t) -> np.ndarray:
    """Robot pose (3, K) at times ``t`` (K,) from ODOM rows (M, 6), M >= 1.

    Linear in x and y, shortest angle difference in theta; times before the
    first / after the last ODOM clamp to it.
    """
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    order = np.argsort(odometry[:, 0], kind="stable")
    od = odometry[order]
    ot = od[:, 0]
    m = ot.shape[0]
    i = np.clip(np.searchsorted(ot, t, side="right") - 1, 0, m - 1)
    j = np.minimum(i + 1, m - 1)
    dt = ot[j] - ot[i]
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(dt > 0, (t - ot[i]) / np.where(dt > 0, dt, 1.0), 0.0)
    frac = np.clip(frac, 0.0, 1.0)
    out = np.empty((3, t.shape[0]), dtype=np.float64)
    out[0] = od[i, 1] + frac * (od[j, 1] - od[i, 1])
    out[1] = od[i, 2] + frac * (od[j, 2] - od[i, 2])
    dth = np.arctan2(np.sin(od[j, 3] - od[i, 3]), np.cos(od[j, 3] - od[i, 3]))
    th = od[i, 3] + frac * dth
    out[2] = np.arctan2(np.sin(th), np.cos(th))
    return out


def _fill_odom(scans: list[Scan], odometry: np.ndarray, name: str) -> list[Scan]:
    need = [k for k, s in enumerate(scans) if s.odom is None]
    if not need:
        return scans
    if odometry.shape[0] == 0:
        s = scans[need[0]]
        raise DataError(f"{name}:{s.line}: {s.kind}: no pose of its own and no ODOM lines to interpolate")
    with np.errstate(over="ignore", invalid="ignore"):
        poses = interpolate_odometry(odometry, [scans[k].t for k in need])
    bad = np.flatnonzero(~np.isfinite(poses).all(axis=0))
    if bad.size:  # finite ODOM values whose differences overflow (|x| near 1e308)
        s = scans[need[bad[0]]]
        raise DataError(f"{name}:{s.line}: {s.kind}: odometry interpolated at t={s.t} is not finite")
    out = list(scans)
    for col, k in enumerate(need):
        s = scans[k]
        out[k] = Scan(s.t, s.ranges, s.angle_min, s.angle_increment, s.max_range,
                      np.ascontiguousarray(poses[:, col]), s.laser_offset, s.tv, s.rv, s.kind, s.line)
    return out
