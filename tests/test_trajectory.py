"""TUM trajectory files and atomic writes."""

import math

import numpy as np
import pytest

from mcl.errors import DataError
from mcl.trajectory import TumWriter, atomic_write_bytes, atomic_write_text, atomic_writer, read_tum, write_tum


def test_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    t = np.sort(rng.uniform(0, 1000, 50))
    poses = np.vstack([rng.uniform(-50, 50, 50), rng.uniform(-50, 50, 50), rng.uniform(-math.pi, math.pi, 50)])
    p = tmp_path / "traj.tum"
    write_tum(p, t, poses)
    t2, poses2 = read_tum(p)
    np.testing.assert_allclose(t2, t, atol=1e-6)
    np.testing.assert_allclose(poses2[:2], poses[:2], atol=1e-8)
    dth = np.angle(np.exp(1j * (poses2[2] - poses[2])))
    np.testing.assert_allclose(dth, 0, atol=1e-7)
    assert poses2.shape == (3, 50) and poses2.flags.c_contiguous
    first = p.read_text().splitlines()[0].split()
    assert len(first) == 8 and first[3:6] == ["0", "0", "0"]
    assert float(first[6]) == pytest.approx(math.sin(poses[2, 0] / 2), abs=1e-9)
    assert not [q for q in tmp_path.iterdir() if q.name != "traj.tum"]  # no temp file left


def test_read_skips_comments_and_blank_lines_and_wraps_yaw(tmp_path):
    p = tmp_path / "t.tum"
    # qz=-1, qw=0 is yaw -pi, reported as pi (theta in (-pi, pi]); qz=sin(1.5), qw=cos(1.5): yaw 3.0
    p.write_text(f"# header\n\n1.0 1 2 0 0 0 -1 0\n  \n2.5 3 4 0 0 0 {math.sin(1.5)} {math.cos(1.5)}\n")
    t, poses = read_tum(p)
    np.testing.assert_array_equal(t, [1.0, 2.5])
    np.testing.assert_allclose(poses, [[1, 3], [2, 4], [math.pi, 3.0]], atol=1e-12)
    # a byte-order mark (a file saved by a Windows editor) is read past: it was "TUM: non-numeric field"
    b = tmp_path / "bom.tum"
    b.write_bytes(b"\xef\xbb\xbf" + p.read_bytes().split(b"\n", 2)[2])
    t2, poses2 = read_tum(b)
    np.testing.assert_array_equal(t2, t)
    np.testing.assert_array_equal(poses2, poses)


@pytest.mark.parametrize("bad", ["1 2 3 0 0 0 0", "1 2 x 0 0 0 0 1", "nan 2 3 0 0 0 0 1", "1 2 3 0 0 0 0 0"])
def test_malformed_line_names_file_and_line(tmp_path, bad):
    p = tmp_path / "bad.tum"
    p.write_text(f"# c\n0 0 0 0 0 0 0 1\n{bad}\n")
    with pytest.raises(DataError, match=r"bad\.tum:3: ") as e:
        read_tum(p)
    assert "\n" not in str(e.value)


def test_missing_file(tmp_path):
    with pytest.raises(DataError, match="nope.tum"):
        read_tum(tmp_path / "nope.tum")


def test_empty_file_gives_empty_arrays(tmp_path):
    p = tmp_path / "e.tum"
    p.write_text("# nothing\n")
    t, poses = read_tum(p)
    assert t.shape == (0,) and poses.shape == (3, 0)


def test_tum_writer_partial_then_final(tmp_path):
    p = tmp_path / "est.tum"
    w = TumWriter(p)
    w.append(1.0, 1.0, 2.0, 0.5)
    w.append(2.0, 3.0, 4.0, -0.5)
    partial = tmp_path / "est.tum.partial"
    assert partial.exists() and not p.exists()
    assert len(partial.read_text().splitlines()) == 2  # flushed after each append
    w.close()
    assert p.exists() and not partial.exists()
    t, poses = read_tum(p)
    np.testing.assert_allclose(t, [1, 2])
    np.testing.assert_allclose(poses, [[1, 3], [2, 4], [0.5, -0.5]], atol=1e-9)
    w.close()  # idempotent
    with pytest.raises(ValueError):
        w.append(3.0, 0, 0, 0)


def test_tum_writer_context_manager_keeps_poses_after_exception(tmp_path):
    p = tmp_path / "run.tum"
    with pytest.raises(KeyboardInterrupt):
        with TumWriter(p) as w:
            for k in range(5):
                w.append(k, k, -k, 0.0)
            raise KeyboardInterrupt
    assert not (tmp_path / "run.tum.partial").exists()
    t, poses = read_tum(p)
    np.testing.assert_allclose(t, np.arange(5))
    np.testing.assert_allclose(poses[1], -np.arange(5))


def test_tum_writer_does_not_touch_final_name_before_close(tmp_path):
    p = tmp_path / "run.tum"
    p.write_text("0 9 9 0 0 0 0 1\n")  # an older complete result
    w = TumWriter(p)
    w.append(1.0, 1.0, 1.0, 0.0)
    assert read_tum(p)[1][0, 0] == 9.0  # still the old file
    w.close()
    assert read_tum(p)[1][0, 0] == 1.0


def test_atomic_write_helpers(tmp_path):
    p = tmp_path / "a.txt"
    atomic_write_text(p, "hello\n")
    assert p.read_text() == "hello\n"
    atomic_write_bytes(p, b"\x00\x01")
    assert p.read_bytes() == b"\x00\x01"
    assert [q.name for q in tmp_path.iterdir()] == ["a.txt"]


def test_atomic_writer_shows_the_file_only_when_its_block_ends_and_keeps_the_old_one_on_an_error(tmp_path):
    p = tmp_path / "log.clf"
    p.write_text("old\n")
    with atomic_writer(p, "w", encoding="utf-8") as f:
        f.write("new 1\n")
        f.flush()
        assert p.read_text() == "old\n"  # written in pieces under a temp name
        f.write("new 2\n")
    assert p.read_text() == "new 1\nnew 2\n"
    with pytest.raises(KeyboardInterrupt):
        with atomic_writer(p, "w", encoding="utf-8") as f:
            f.write("cut")
            raise KeyboardInterrupt
    assert p.read_text() == "new 1\nnew 2\n"
    with pytest.raises(OSError) as e:  # a write error is said of the file, not of its temp name
        with atomic_writer(p, "w", encoding="utf-8") as f:
            raise OSError(28, "No space left on device")
    assert e.value.filename == str(p) and p.read_text() == "new 1\nnew 2\n"
    assert [q.name for q in tmp_path.iterdir()] == ["log.clf"]


def test_write_tum_rejects_bad_shapes(tmp_path):
    with pytest.raises(ValueError):
        write_tum(tmp_path / "x.tum", np.zeros(3), np.zeros((2, 3)))
    assert not (tmp_path / "x.tum").exists()
