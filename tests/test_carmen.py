"""CARMEN log reader: every message type, gzip, odometry interpolation, errors, real logs."""

import gzip
import math
import time
from pathlib import Path

import numpy as np
import pytest

from mcl.datasets.carmen import Log, flaser_angle_increment, interpolate_odometry, read_carmen
from mcl.errors import DataError

DATA = Path(__file__).parents[2] / "shared" / "data"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"real datasets not found at {DATA}")

# robot at (1, 2, pi/2); front laser 0.1 m ahead of it, rear laser 0.2 m behind, facing backwards
FLASER = "FLASER 4 1.0 2.0 3.0 4.0 1 2.1 1.5707963267948966 1 2 1.5707963267948966 10.5 host 0.1"
RLASER = "RLASER 4 1.5 2.5 3.5 4.5 1 1.8 -1.5707963267948966 1 2 1.5707963267948966 10.6 host 0.2"
ROBOTLASER1 = ("ROBOTLASER1 0 -1.5 3.0 0.75 30.0 0.01 0 5 1 2 3 4 5 0 "
               "0.5 0.2 0.0 0.3 0.2 0.0 0.7 -0.2 0.5 0.5 0 10.7 host 0.3")
RAWLASER = "RAWLASER{k} 0 -1.0 2.0 0.5 20.0 0.01 1 5 5 4 3 2 1 2 7 8 {t} host 0.4"
ODOM_A = "ODOM 0 0 3.0 0.1 0.2 0 10 host 10"
ODOM_B = "ODOM 2 4 -2.9 0.3 0.4 0 12 host 12"


def write(tmp_path, lines, name="log.clf", end="\n"):
    p = tmp_path / name
    p.write_bytes(("\n".join(lines) + end).encode())
    return p


def angdiff(a, b):
    return math.remainder(a - b, 2 * math.pi)


def test_every_message_type(tmp_path):
    lines = [
        "# a comment", "PARAM robot_front_laser_max 81.9 host 0", "", ODOM_A, "SYNC 1 2 3", FLASER, RLASER,
        ROBOTLASER1, RAWLASER.format(k=1, t=11), RAWLASER.format(k=2, t=5), RAWLASER.format(k=3, t=20),
        RAWLASER.format(k=4, t=12), ODOM_B, "NEFF 1 2", "TRUEPOS 1 2 3 4 5 6 7 h 8", "PARAM x y h 0", "WHATEVER 1",
    ]
    log = read_carmen(write(tmp_path, lines))
    assert isinstance(log, Log)
    assert [s.kind for s in log.scans] == ["FLASER", "RLASER", "ROBOTLASER1", "RAWLASER1", "RAWLASER2",
                                          "RAWLASER3", "RAWLASER4"]
    assert [s.line for s in log.scans] == [6, 7, 8, 9, 10, 11, 12]
    assert log.skipped == {"#": 1, "PARAM": 2, "(blank)": 1, "SYNC": 1, "NEFF": 1, "TRUEPOS": 1, "WHATEVER": 1}
    assert log.warnings == []
    np.testing.assert_array_equal(log.odometry, [[10, 0, 0, 3.0, 0.1, 0.2], [12, 2, 4, -2.9, 0.3, 0.4]])

    f, r, rl, raw1 = log.scans[:4]
    # FLASER: own poses, geometry from the beam count, no max range of its own
    assert f.t == 10.5 and f.ranges.dtype == np.float64
    np.testing.assert_array_equal(f.ranges, [1, 2, 3, 4])
    assert f.angle_min == -math.pi / 2 and f.angle_increment == math.pi / 4
    np.testing.assert_allclose(f.angles, -math.pi / 2 + np.arange(4) * math.pi / 4)
    assert f.max_range == 81.9 and f.tv == 0 and f.rv == 0  # from PARAM robot_front_laser_max
    np.testing.assert_allclose(f.odom, [1, 2, math.pi / 2])
    np.testing.assert_allclose(f.laser_offset, [0.1, 0, 0], atol=1e-12)  # 0.1 m ahead, in the robot frame
    # RLASER: rear laser, 0.2 m behind, facing backwards
    np.testing.assert_allclose(r.laser_offset[:2], [-0.2, 0], atol=1e-12)
    assert abs(angdiff(r.laser_offset[2], math.pi)) < 1e-12
    # ROBOTLASER1 carries its own geometry, poses and velocities
    assert (rl.angle_min, rl.angle_increment, rl.max_range) == (-1.5, 0.75, 30.0)
    np.testing.assert_array_equal(rl.ranges, [1, 2, 3, 4, 5])
    np.testing.assert_allclose(rl.odom, [0.3, 0.2, 0.0])
    np.testing.assert_allclose(rl.laser_offset, [0.2, 0, 0], atol=1e-12)
    assert (rl.tv, rl.rv, rl.t) == (0.7, -0.2, 10.7)
    # RAWLASER: geometry of its own, no mounting, odom interpolated from ODOM
    assert (raw1.angle_min, raw1.angle_increment, raw1.max_range) == (-1.0, 0.5, 20.0)
    assert raw1.laser_offset is None
    np.testing.assert_array_equal(raw1.ranges, [5, 4, 3, 2, 1])


def test_a_damaged_message_name_is_a_warning_naming_its_line(tmp_path):
    # FLASR, flaser and bytes that are no name at all are damaged lines, not another sensor's messages: skipped as
    # before (counted), and one warning names the first; CARMEN's own other messages (a fifth laser's RAWLASER5,
    # SYNC, PARAM) are skipped without one.
    log = read_carmen(write(tmp_path, [FLASER, "SYNC 1 2 3", "RAWLASER5 0 0", FLASER.replace("FLASER", "FLASR"),
                                       FLASER, FLASER.lower(), "\x01\x7fJ 1 2", FLASER]))
    assert len(log.scans) == 3
    damaged = [w for w in log.warnings if "looks damaged" in w]
    assert damaged == [f"{tmp_path / 'log.clf'}:4: 3 lines skipped whose message name looks damaged (the first: "
                       "'FLASR'; a known one misspelt or not a name at all)"]
    assert log.skipped["FLASR"] == log.skipped["RAWLASER5"] == 1


def test_rawlaser_odometry_interpolation(tmp_path):
    lines = [ODOM_A, RAWLASER.format(k=1, t=11), RAWLASER.format(k=1, t=5), RAWLASER.format(k=1, t=20), ODOM_B]
    s_mid, s_before, s_after = read_carmen(write(tmp_path, lines)).scans
    # halfway: x, y linear; theta 3.0 -> -2.9 the short way (+0.383 through pi), half of it
    expected_th = math.remainder(3.0 + 0.5 * math.remainder(-2.9 - 3.0, 2 * math.pi), 2 * math.pi)
    assert expected_th == pytest.approx(-3.0916, abs=1e-3)
    np.testing.assert_allclose(s_mid.odom[:2], [1.0, 2.0], atol=1e-12)
    assert abs(angdiff(s_mid.odom[2], expected_th)) < 1e-12
    np.testing.assert_allclose(s_before.odom, [0, 0, 3.0])  # clamped to the first ODOM
    np.testing.assert_allclose(s_after.odom, [2, 4, -2.9])  # clamped to the last ODOM


def test_interpolate_unsorted_odometry():
    od = np.array([[2.0, 2, 0, 0, 0, 0], [0.0, 0, 0, 0, 0, 0], [1.0, 1, 1, 0.5, 0, 0]])
    out = interpolate_odometry(od, [0.5, 1.5])
    np.testing.assert_allclose(out, [[0.5, 1.5], [0.5, 0.5], [0.25, 0.25]])


def test_rawlaser_without_odometry_names_line(tmp_path):
    p = write(tmp_path, ["# c", FLASER, RAWLASER.format(k=1, t=11)])
    with pytest.raises(DataError, match=r"log\.clf:3: RAWLASER1"):
        read_carmen(p)


def test_gzip_detected_by_magic(tmp_path):
    text = "\n".join([ODOM_A, FLASER, ODOM_B]) + "\n"
    p = tmp_path / "log.clf"  # no .gz extension on purpose
    p.write_bytes(gzip.compress(text.encode()))
    log = read_carmen(p)
    assert len(log.scans) == 1 and log.odometry.shape == (2, 6) and log.warnings == []
    # a truncated gzip stream keeps what decompressed, with warnings
    big = "\n".join([ODOM_A] + [FLASER] * 2000) + "\n"
    q = tmp_path / "big.clf.gz"
    data = gzip.compress(big.encode())
    q.write_bytes(data[: len(data) // 2])
    log = read_carmen(q)
    assert 0 < len(log.scans) < 2000
    assert any("truncated" in w for w in log.warnings)


def test_corrupt_gzip(tmp_path):
    p = tmp_path / "log.clf.gz"
    p.write_bytes(b"\x1f\x8b\x08\x00" + b"\xff" * 40)
    with pytest.raises(DataError, match=r"log\.clf\.gz"):
        read_carmen(p)


@pytest.mark.parametrize("bad,kind", [
    ("FLASER 4 1 2 3 1 2 0 1 2 0 10.5 host 0.1", "FLASER"),            # n says 4, 3 ranges
    ("FLASER 4 1 2 x 4 1 2 0 1 2 0 10.5 host 0.1", "FLASER"),          # non-numeric range
    ("FLASER 4 1 2 3 4 1 2 0 1 2 0 nan host 0.1", "FLASER"),           # NaN timestamp
    ("FLASER -4 1 2 3 4 1 2 0 1 2 0 10.5 host 0.1", "FLASER"),         # negative count
    ("RLASER four 1 2 3 4 1 2 0 1 2 0 10.5 host 0.1", "RLASER"),       # count not an integer
    ("ODOM 0 0 0 0 0 0 10 host", "ODOM"),                             # missing field
    ("ODOM 0 0 zero 0 0 0 10 host 10", "ODOM"),
    (ROBOTLASER1.replace(" 5 1 2 3 4 5 0 ", " 6 1 2 3 4 5 0 "), "ROBOTLASER1"),
    ("RAWLASER2 0 -1.0 2.0 0.5 20.0 0.01 1 5 5 4 3 2 1 3 7 8 11 host 0.4", "RAWLASER2"),  # 3 remissions, 2 given
    (ROBOTLASER1.replace(" -1.5 3.0 0.75 ", " -1.5 3.0 0 "), "ROBOTLASER1: angular resolution 0"),  # 5 beams, 1 way
    (ROBOTLASER1.replace(" -1.5 3.0 0.75 ", " nan 3.0 0.75 "), "ROBOTLASER1: non-finite beam geometry"),
])
def test_malformed_line_names_file_line_and_type(tmp_path, bad, kind):
    p = write(tmp_path, [ODOM_A, FLASER, bad, FLASER])
    with pytest.raises(DataError, match=rf"log\.clf:3: {kind}") as e:
        read_carmen(p)
    assert "\n" not in str(e.value)


def test_truncated_last_line_is_a_warning(tmp_path):
    p = write(tmp_path, [ODOM_A, FLASER, FLASER[:30]], end="")
    log = read_carmen(p)
    assert len(log.scans) == 1
    assert len(log.warnings) == 1 and "log.clf:3" in log.warnings[0] and "truncated" in log.warnings[0]
    # the same line with a final newline is an error, not a truncation
    q = write(tmp_path, [ODOM_A, FLASER, FLASER[:30]], name="q.clf")
    with pytest.raises(DataError, match=r"q\.clf:3: FLASER"):
        read_carmen(q)


def test_complete_last_line_without_newline_is_read(tmp_path):
    log = read_carmen(write(tmp_path, [ODOM_A, FLASER, FLASER], end=""))
    assert len(log.scans) == 2 and log.warnings == []


def test_non_utf8(tmp_path):
    p = tmp_path / "log.clf"
    p.write_bytes((ODOM_A + "\n" + FLASER + "\n").encode() + b"PARAM \xff\xfe x\n" + (FLASER + "\n").encode())
    with pytest.raises(DataError, match=r"log\.clf:3: .*UTF-8"):
        read_carmen(p)
    # a last line cut inside a multi-byte character counts as truncated
    q = tmp_path / "cut.clf"
    q.write_bytes((ODOM_A + "\n" + FLASER + "\n# caf").encode() + "é".encode()[:1])
    log = read_carmen(q)
    assert len(log.scans) == 1 and "cut.clf:3" in log.warnings[0]


def test_a_byte_order_mark_is_no_part_of_the_first_record(tmp_path):
    # A log saved by a Windows editor starts with U+FEFF: its first record was not recognised ("\ufeffODOM")
    plain = read_carmen(write(tmp_path, [ODOM_A, FLASER, FLASER], name="plain.clf"))
    p = tmp_path / "bom.clf"
    p.write_bytes(b"\xef\xbb\xbf" + (tmp_path / "plain.clf").read_bytes())
    log = read_carmen(p)
    assert len(log.scans) == len(plain.scans) == 2 and log.warnings == plain.warnings
    assert all(np.array_equal(a.odom, b.odom) for a, b in zip(log.laser_stream(), plain.laser_stream()))


@pytest.mark.parametrize("content,msg", [("", "empty"), ("\n\n  \n", "empty"),
                                         (ODOM_A + "\nPARAM a b c 0\n", "no laser")])
def test_empty_or_no_laser(tmp_path, content, msg):
    p = tmp_path / "e.clf"
    p.write_text(content)
    with pytest.raises(DataError, match=rf"e\.clf: .*{msg}"):
        read_carmen(p)


def test_missing_file(tmp_path):
    with pytest.raises(DataError, match="absent.clf"):
        read_carmen(tmp_path / "absent.clf")


def test_flaser_angle_increment_rule():
    assert flaser_angle_increment(180) == flaser_angle_increment(181) == math.pi / 180
    assert flaser_angle_increment(360) == flaser_angle_increment(361) == math.pi / 360
    assert flaser_angle_increment(91) == math.pi / 90   # odd: both ends of the half circle
    assert flaser_angle_increment(90) == math.pi / 90   # even: left end excluded


def test_default_stream(tmp_path):
    log = read_carmen(write(tmp_path, [ODOM_A, RAWLASER.format(k=2, t=11), ROBOTLASER1, RLASER]))
    assert log.default_kind() == "ROBOTLASER1"
    assert [s.kind for s in log.laser_stream()] == ["ROBOTLASER1"]
    assert len(log.scans_of("RLASER")) == 1
    with pytest.raises(DataError, match=r"log\.clf: no FLASER messages"):
        log.laser_stream("FLASER")
    only_raw2 = read_carmen(write(tmp_path, [ODOM_A, RAWLASER.format(k=2, t=11)], name="r.clf"))
    with pytest.raises(DataError, match=r"r\.clf: .*RAWLASER2"):
        only_raw2.default_kind()
    assert [s.kind for s in only_raw2.laser_stream()] == ["RAWLASER2"]  # auto: the one laser it has
    assert not any("fused" in n for n in only_raw2.notes + log.notes)  # RLASER with ROBOTLASER1: not a pair


def test_a_front_and_a_rear_laser_are_fused_by_auto(tmp_path):
    # CARMEN's second laser: RLASER (old format) or ROBOTLASER2 (ROBOTLASER1's fields). auto fuses a log's front and
    # rear lasers when it has both, in file order, with a note; a list names the streams; one reads that alone
    rear = ROBOTLASER1.replace("ROBOTLASER1", "ROBOTLASER2")
    log = read_carmen(write(tmp_path, [ODOM_A, ROBOTLASER1, rear, RAWLASER.format(k=1, t=11)]))
    s = log.scans_of("ROBOTLASER2")[0]
    one = log.scans_of("ROBOTLASER1")[0]
    assert np.array_equal(s.ranges, one.ranges) and s.max_range == one.max_range and s.angle_min == one.angle_min
    assert np.array_equal(s.laser_offset, one.laser_offset) and s.line == 3
    assert [s.kind for s in log.laser_stream()] == ["ROBOTLASER1", "ROBOTLASER2"]
    assert log.notes == [f"{tmp_path / 'log.clf'}: ROBOTLASER1 and ROBOTLASER2 (a front and a rear laser): fused, "
                         "each on the mounting its lines give (laser: ROBOTLASER1 reads the front one alone)"]
    assert [s.kind for s in log.laser_stream("ROBOTLASER2")] == ["ROBOTLASER2"]
    assert [s.kind for s in log.laser_stream("RAWLASER1,ROBOTLASER2")] == ["ROBOTLASER2", "RAWLASER1"]
    # FLASER and RLASER come first: a log with both pairs (one laser in two formats) reads the old pair
    both = read_carmen(write(tmp_path, [ODOM_A, FLASER, RLASER, ROBOTLASER1, rear], name="b.clf"))
    assert [s.kind for s in both.laser_stream()] == ["FLASER", "RLASER"]
    with pytest.raises(DataError, match=r"log\.clf: no FLASER messages"):
        log.laser_stream("ROBOTLASER1,FLASER")


# --- real logs ---------------------------------------------------------------------

@needs_data
@pytest.mark.parametrize("name,scans,beams,odom_lines,duration", [("intel_lab", 910, 180, 910, 2651),
                                                                  ("mit_csail", 1988, 361, 0, 424),
                                                                  ("fr079", 4791, 360, 4791, 1061)])
def test_real_logs(name, scans, beams, odom_lines, duration):
    t0 = time.perf_counter()
    log = read_carmen(DATA / name / "log.clf")
    elapsed = time.perf_counter() - t0
    assert len(log.scans) == scans and log.default_kind() == "FLASER"
    assert all(s.ranges.shape == (beams,) and s.odom is not None for s in log.scans)
    assert log.odometry.shape == (odom_lines, 6)
    assert log.warnings == []
    ts = np.array([s.t for s in log.scans])
    assert ts.max() - ts.min() == pytest.approx(duration, abs=1.0)  # README durations
    # (intel_lab's timestamps step back by < 1 s at 4 scans: the reader keeps file order)
    assert (np.diff(ts) < 0).sum() <= 4
    assert elapsed < 5.0, f"parsing {name} took {elapsed:.2f} s"  # about 0.4 s for fr079 on a laptop


@needs_data
def test_real_intel_start_pose():
    log = read_carmen(DATA / "intel_lab" / "log.clf")
    np.testing.assert_allclose(log.scans[0].odom, [0.600266, -0.032033, -0.354665])
    np.testing.assert_allclose(log.scans[0].laser_offset, 0, atol=1e-12)
    assert log.scans[0].angle_increment == math.pi / 180


def test_param_lines_give_flaser_its_maximum_range(tmp_path):
    ranges = " ".join(["1.0"] * 181)
    p = tmp_path / "p.clf"
    p.write_text(
        "PARAM robot_front_laser_max 12.0 host 0\n"
        f"FLASER 181 {ranges} 0 0 0 0 0 0 1.0 host 1.0\n"
        f"RLASER 181 {ranges} 0 0 0 0 0 0 1.0 host 1.0\n"
    )
    log = read_carmen(p)
    assert log.scans_of("FLASER")[0].max_range == 12.0
    assert log.scans_of("RLASER")[0].max_range is None  # no robot_rear_laser_max given
    assert log.skipped["PARAM"] == 1


def test_the_few_fields_of_a_line_read_as_numpy_read_them(tmp_path):
    # poses, beam geometry and times are parsed with Python's float, the ranges with numpy: the same values (numpy
    # parses each string with Python's float), spellings float() alone takes included
    odd = ("ROBOTLASER1 0 -1.5_0 3.0 0.75 3_0.0 0.01 0 5 1 2 3 4 5 0 "
           "0.5 0.2 +0.0 0.3 0.2 -0.0 0.7 -0.2 0.5 0.5 0 1_0.7 host 0.3")
    log = read_carmen(write(tmp_path, [ODOM_A, FLASER, RLASER, odd, ODOM_B, RAWLASER.format(k=1, t=11.0)]))
    fl, rl, rb, raw = log.scans
    for s in log.scans:
        assert type(s.t) is float and type(s.angle_min) is float and type(s.angle_increment) is float
        assert isinstance(s.odom, np.ndarray) and s.odom.dtype == np.float64 and s.odom.shape == (3,)
    assert rb.angle_min == -1.5 and rb.max_range == 30.0 and rb.t == 10.7 and (rb.tv, rb.rv) == (0.7, -0.2)
    assert np.array_equal(rb.odom, np.array("0.3 0.2 -0.0".split(), dtype=np.float64))
    assert math.copysign(1.0, rb.odom[2]) == -1.0  # the sign of a -0.0 heading kept
    assert np.array_equal(fl.odom, np.array([1.0, 2.0, 1.5707963267948966]))
    assert np.allclose(fl.laser_offset, [0.1, 0.0, 0.0])
    assert np.allclose(rl.laser_offset[:2], [-0.2, 0.0]) and abs(rl.laser_offset[2]) == pytest.approx(math.pi)
    assert np.array_equal(log.odometry, np.array([ODOM_A.split()[1:7] + ["10"], ODOM_B.split()[1:7] + ["12"]],
                                                 dtype=np.float64)[:, [6, 0, 1, 2, 3, 4]])


@pytest.mark.parametrize("line,kind,msg", [
    ("ODOM 0 0 nan 0.1 0.2 0 10 host 10", "ODOM", "non-finite value"),
    ("ODOM 0 0 0 0.1 0.2 0 inf host 10", "ODOM", "non-finite timestamp"),
    (FLASER.replace(" 1 2.1 ", " 1 x2.1 "), "FLASER", "non-numeric pose 'x2.1'"),
    (ROBOTLASER1.replace(" 0.7 -0.2 ", " 0.7 -inf "), "ROBOTLASER1", "non-finite pose/velocity"),
    (ROBOTLASER1.replace(" 30.0 0.01 ", " 30.0 O.01 "), "ROBOTLASER1", "non-numeric config field 'O.01'"),
    (RAWLASER.format(k=1, t=11.0).replace(" 2 7 8 ", " 2 7 eight "), "RAWLASER1", "non-numeric remission 'eight'"),
])
def test_a_bad_small_field_is_named_as_before(tmp_path, line, kind, msg):
    with pytest.raises(DataError, match=rf"log\.clf:2: {kind}: {msg}"):
        read_carmen(write(tmp_path, [ODOM_A, line, FLASER]))


def test_a_log_whose_ipc_timestamps_are_all_the_same_is_timed_by_the_logger(tmp_path):
    # a logger that never set the ipc_timestamp (0 throughout): every scan was read at t = 0 (one reference pose
    # scored, 4 m "off"); the logger's own timestamps (the last field) now stand in, the ODOM lines' too, with a note
    flaser = "FLASER 4 1.0 2.0 3.0 4.0 {x} 0 0 {x} 0 0 0.0 host {t}"
    lines = ["ODOM 0 0 0 0 0 0 0.0 host 0.0", flaser.format(x=0.0, t=0.1), "ODOM 0.5 0 0 0 0 0 0.0 host 0.5",
             flaser.format(x=0.6, t=0.6), "ODOM 1.0 0 0 0 0 0 0.0 host 1.0", flaser.format(x=1.1, t=1.1)]
    log = read_carmen(write(tmp_path, lines))
    assert [s.t for s in log.laser_stream()] == [0.1, 0.6, 1.1]
    assert log.odometry[:, 0].tolist() == [0.0, 0.5, 1.0]
    assert any("every laser line has the ipc_timestamp 0; the logger timestamps" in n for n in log.notes)
    stamped = [ln.replace(" 0.0 host", f" {ln.split()[-1]} host") for ln in lines]  # ipc = logger: as before
    log = read_carmen(write(tmp_path, stamped, name="b.clf"))
    assert [s.t for s in log.laser_stream()] == [0.1, 0.6, 1.1] and not any("every laser line has" in n for n in log.notes)


def test_a_laser_lines_maximum_range_of_0_is_unknown_and_odd_flaser_fans_are_noted(tmp_path):
    # A ROBOTLASER1 whose max_range field is 0 made every reading a no-return: the run only predicted, without a
    # word (0.30 m and 8.5 deg off, the odometry's). Not positive is unknown now: the config decides. FLASER lines
    # do not say their angles: 1081 beams (a UTM-30LX over 270 degrees) were read as a 180-degree fan in silence.
    zero = ROBOTLASER1.replace(" 0.75 30.0 ", " 0.75 0 ")
    log = read_carmen(write(tmp_path, [zero]))
    assert log.scans[0].max_range is None
    assert read_carmen(write(tmp_path, [ROBOTLASER1], name="b.clf")).scans[0].max_range == 30.0
    ranges = " ".join(["2.0"] * 1081)
    path = write(tmp_path, [f"FLASER 1081 {ranges} 1 2 0 1 2 0 10.5 host 0.1"], name="utm.clf")
    assert [n for n in read_carmen(path).notes if "beams a line" in n] == [
        f"{path}: FLASER: 1081 beams a line: FLASER lines do not say their angles and are read as a 180-degree fan "
        "(a SICK's); a laser of another field of view needs ROBOTLASER1 or RAWLASER lines, which say it"]
    sick = " ".join(["2.0"] * 181)
    path = write(tmp_path, [f"FLASER 181 {sick} 1 2 0 1 2 0 10.5 host 0.1"], name="sick.clf")
    assert not [n for n in read_carmen(path).notes if "beams a line" in n]
