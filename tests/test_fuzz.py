"""Hostile input: property-based fuzzing of the CARMEN reader, the map loader, the config loader and `mcl run`.

Each strategy builds *nearly valid* input (a valid file with one field, key or
byte range broken, or cut at a random point) so the fuzzing reaches the deep
checks, plus some pure random bytes. The properties:

- nothing but the project's own error type escapes (``DataError`` from the
  readers, ``ConfigError`` from the config loader);
- every message is one line that names the file, and the line number (CARMEN,
  YAML syntax) or the key (map YAML, config) that is wrong;
- an unbroken input loads, with the expected content.

Reproducible: every test is ``derandomize=True`` without an example database.
About 4,000 generated inputs in all, ~20 s on the 2-core CI machine.
"""

from __future__ import annotations

import contextlib
import gzip
import io
import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from mcl.cli import main
from mcl.config import Config, ConfigError, load_config, to_dict
from mcl.datasets.carmen import LASER_KINDS, _read_bytes, read_carmen
from mcl.errors import DataError, MclError
from mcl.maps import load_map

FUZZ = dict(database=None, derandomize=True, deadline=None,
            suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # libyaml's emitter: 3.6 ms a config against 15 ms


def one_line_naming(msg: str, name: str) -> None:
    assert msg, "empty message"
    assert "\n" not in msg and "\r" not in msg, f"multi-line message: {msg!r}"
    assert name in msg, f"message does not name {name}: {msg!r}"


# ============================================================================ CARMEN

num = st.one_of(st.floats(-50, 50, allow_nan=False).map(lambda v: f"{v:.4f}"),
                st.sampled_from(["1e308", "-1e308", "1.7976931348623157e308", "5e-324"]))
rng_ = st.floats(0, 40, allow_nan=False).map(lambda v: f"{v:.2f}")
HOSTILE_TOKENS = ["nan", "inf", "-inf", "1e999", "-1e999", "-1", "0", "", "x", "0x10", "1_0", "١٢", "9" * 40,
                  "\x00", "é", "-0", "+1", "1e-400", "NaN", "Infinity", "1,5", "--1", ".", "e5", "\x85", "\u2028"]
token = st.one_of(
    st.sampled_from(HOSTILE_TOKENS),
    st.text(alphabet=st.characters(blacklist_characters="\n", blacklist_categories=("Cs",)), max_size=8),
    st.integers(-(10**20), 10**20).map(str),
    st.floats().map(repr),
)


@st.composite
def carmen_line(draw, t: float) -> list[str]:
    kind = draw(st.sampled_from(["ODOM", "FLASER", "RLASER", "ROBOTLASER1", "RAWLASER1", "RAWLASER3",
                                 "PARAM", "#", "SYNC", ""]))
    ts = [f"{t:.6f}", draw(st.sampled_from(["host", "nohost"])), f"{t + 0.01:.6f}"]
    if kind == "ODOM":
        return ["ODOM", *draw(st.lists(num, min_size=6, max_size=6)), *ts]
    if kind in ("FLASER", "RLASER"):
        n = draw(st.integers(0, 8))
        return [kind, str(n), *draw(st.lists(rng_, min_size=n, max_size=n)), *draw(st.lists(num, min_size=6, max_size=6)), *ts]
    if kind.startswith(("ROBOTLASER", "RAWLASER")):
        n, m = draw(st.integers(0, 6)), draw(st.integers(0, 3))
        head = [kind, "0", "-1.5708", "3.1416", "0.0175", "81.9", "0.01", "0", str(n),
                *draw(st.lists(rng_, min_size=n, max_size=n)), str(m), *draw(st.lists(rng_, min_size=m, max_size=m))]
        if kind == "ROBOTLASER1":
            head += draw(st.lists(num, min_size=11, max_size=11))
        return head + ts
    if kind == "PARAM":
        return ["PARAM", draw(st.sampled_from(["robot_front_laser_max", "robot_rear_laser_max", "x"])),
                draw(st.sampled_from(["50", "nan", "-1", "x", "1e999"])), *ts]
    if kind == "#":
        return ["#", "comment", "ODOM", "1"]
    if kind == "SYNC":
        return ["SYNC", "1", *ts]
    return []  # a blank line


@st.composite
def carmen_log(draw) -> list[list[str]]:
    """A valid log: an ODOM line (so RAWLASER can be interpolated), a laser line, then anything valid."""
    k = draw(st.integers(0, 10))
    t = 1000.0
    lines = []
    for _ in range(k):
        t += 0.1
        lines.append(draw(carmen_line(t)))
    odom = ["ODOM", "0", "0", "0", "0", "0", "0", "999.0", "h", "999.0"]
    laser = ["FLASER", "2", "1.0", "2.0", "0", "0", "0", "0", "0", "0", "999.5", "h", "999.5"]
    lines.insert(draw(st.integers(0, len(lines))), odom)
    lines.insert(draw(st.integers(0, len(lines))), laser)
    return lines


def join_lines(lines: list[list[str]]) -> bytes:
    return "".join(" ".join(p) + "\n" for p in lines).encode("utf-8")


@st.composite
def mutated_log(draw):
    """(bytes, 1-based mutated line or None, gzipped, truncated) from a valid log with one line broken."""
    lines = draw(carmen_log())
    k = draw(st.integers(0, len(lines) - 1))
    parts = list(lines[k])
    how = draw(st.sampled_from(["replace", "delete", "insert", "cut", "word", "random", "bytes", "none"]))
    raw_line = None
    if how == "replace" and parts:
        parts[draw(st.integers(0, len(parts) - 1))] = draw(token)
    elif how == "delete" and parts:
        del parts[draw(st.integers(0, len(parts) - 1))]
    elif how == "insert":
        parts.insert(draw(st.integers(0, len(parts))), draw(token))
    elif how == "cut":
        text = " ".join(parts)
        parts = text[: draw(st.integers(0, len(text)))].split(" ")
    elif how == "word" and parts:
        parts[0] = draw(st.sampled_from(["ODOM", *LASER_KINDS, "PARAM", "odom", "FLASER\x00"]))
    elif how == "random":
        parts = [draw(token) for _ in range(draw(st.integers(0, 20)))]
    elif how == "bytes":
        raw_line = (" ".join(parts)).encode() + draw(st.binary(min_size=1, max_size=6).filter(lambda b: b"\n" not in b))
    elif how == "none":
        k = None
    if k is not None:
        lines[k] = parts
    data = join_lines(lines)
    if raw_line is not None:
        chunks = data.split(b"\n")
        chunks[k] = raw_line
        data = b"\n".join(chunks)
    truncated = draw(st.booleans())
    if truncated:
        data = data[: draw(st.integers(0, len(data)))]
    zipped = draw(st.booleans())
    if zipped:
        data = gzip.compress(data, mtime=0)
        if draw(st.booleans()):
            data = data[: draw(st.integers(0, len(data)))]
    return data, (None if k is None else k + 1), lines, truncated or zipped


def _first_word(raw: bytes) -> str | None:
    """A line's first word as the reader reads it, or None (not UTF-8, or blank)."""
    try:
        words = raw.decode("utf-8").split()
    except UnicodeDecodeError:
        return None
    return words[0] if words else None


def _check_log(log, path) -> None:
    assert log.scans, "a log without scans must be an error"
    # the file's lines as the reader sees them (gzip decompressed, a truncated stream as far as it goes)
    file_lines = _read_bytes(path, str(path), []).split(b"\n")
    lines = [s.line for s in log.scans]
    assert lines == sorted(set(lines)), lines  # one scan per laser line, in file order
    # the file's laser lines by number (from 1), each with its kind, its line split as the reader splits it:
    # UTF-8 text, any Unicode whitespace (U+0085 too)
    laser_lines = {i: kind for i, raw in enumerate(file_lines, 1) if (kind := _first_word(raw)) in LASER_KINDS}
    for s in log.scans:
        # each scan names a laser line of its own kind (a line 0, past the end or of another record: a reader bug)
        assert laser_lines.get(s.line) == s.kind, (s.line, s.kind, laser_lines.get(s.line))
        assert s.ranges.dtype == np.float64 and s.ranges.ndim == 1
        assert s.odom is not None and s.odom.shape == (3,) and np.isfinite(s.odom).all(), s
        assert np.isfinite(s.t)
    assert log.odometry.ndim == 2 and log.odometry.shape[1] == 6 and np.isfinite(log.odometry).all()


@settings(max_examples=1200, **FUZZ)
@given(case=mutated_log())
def test_fuzz_carmen_nearly_valid(tmp_path, case):
    data, bad_line, lines, cut = case
    path = tmp_path / "fuzz.clf"
    path.write_bytes(data)
    try:
        log = read_carmen(path)
    except DataError as e:
        msg = str(e)
        one_line_naming(msg, str(path))
        m = re.match(re.escape(str(path)) + r":(\d+): ", msg)
        extreme = "odometry interpolated" in msg or "offset not finite" in msg  # finite poses ~1e308 apart
        if bad_line is None and not cut:
            assert extreme, msg  # an unbroken log fails only on such extreme values
        if m and "no pose of its own" not in msg and not extreme:
            # Only the broken line can be wrong (a cut last line is skipped with a warning).
            assert bad_line is not None and int(m.group(1)) == bad_line, (msg, bad_line)
        return
    _check_log(log, path)
    if bad_line is None and not cut:
        lasers = [i + 1 for i, p in enumerate(lines) if p and p[0] in LASER_KINDS]  # their 1-based line numbers
        odoms = [p for p in lines if p and p[0] == "ODOM"]
        assert [s.line for s in log.scans] == lasers and log.odometry.shape[0] == len(odoms)


@settings(max_examples=300, **FUZZ)
@given(data=st.one_of(st.binary(max_size=300),
                      st.binary(max_size=200).map(lambda b: b"\x1f\x8b" + b),
                      st.lists(st.one_of(st.sampled_from(["FLASER", "ODOM", "ROBOTLASER1", "RAWLASER2", "\n", "3"]),
                                         token), max_size=40).map(lambda p: " ".join(p).encode("utf-8", "surrogatepass"))))
def test_fuzz_carmen_random_bytes(tmp_path, data):
    path = tmp_path / "random.clf"
    path.write_bytes(data)
    try:
        log = read_carmen(path)
    except DataError as e:
        one_line_naming(str(e), str(path))
        n = data.count(b"\n") + 1
        m = re.match(re.escape(str(path)) + r":(\d+): ", str(e))
        assert m is None or 1 <= int(m.group(1)) <= n
        return
    _check_log(log, path)


# ============================================================================ maps

MAP_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh", "mode")
HOSTILE_YAML = ["", "~", "null", "true", "no", "-1", "0", "0.0", "1", "2", "1e400", "1.0e+400", ".nan", ".inf", "-.inf",
                "9" * 400, "-" + "9" * 400, "[]", "[1]", "[1, 2, 3, 4]", "[.nan, 0, 0]", "[1, 2, 0.5]",
                "[" + "9" * 400 + ", 0, 0]", "[a, b, c]", "{}", "{a: 1}", "'m.pgm'", "missing.pgm", "/", ".", "..",
                 '"a\\nb.pgm"', '"a\\0b.pgm"', '"\\x00"', "!!binary aGVsbG8=", "&a [*a]", "*nope", "[", "{", "'",
                '"', "@", "`", "!!python/object:os.system x", "%TAG", "- 1", "? x", "0x10", "0o17", "1_000",
                "2001-12-14", "raw", "scale", "trinary", "Trinary", "0.65", "0.196", "1.5", "-0.5"]
KEY_HOSTILE = {
    "number": ["9" * 400, "-" + "9" * 400, ".nan", ".inf", "-.inf", "1.0e+400", "-1", "0", "2", "[1]", "{}", "x",
               "true", "null", "", "1e400", "0x10", "1_000", "0.5", "1", "'0.3'"],
    "origin": ["[" + "9" * 400 + ", 0, 0]", "[0, -" + "9" * 400 + "]", "[.nan, 0, 0]", "[1, 2, 0.5]", "[1]",
               "[a, b, c]", "&a [*a]", "[1, 2]", "[true, 0, 0]", "[1, 2, 0, 4]", "{x: 1}", "0", "[.inf, 0]"],
    "image": ['"a\\nb.pgm"', '"a\\0b.pgm"', '"a\\rb.pgm"', '"\\t"', "/", ".", "..", "missing.pgm", "[]", "1",
              "!!binary aGVsbG8=", "''", "' '", "/dev/null", "/etc", "img.png", "img.pgm", "fuzz.yaml"],
    "mode": ["Trinary", "raw", "scale", "1", "[]", "null", "trinary\t"],
}
KEY_KIND = {"resolution": "number", "negate": "number", "occupied_thresh": "number", "free_thresh": "number",
            "origin": "origin", "image": "image", "mode": "mode"}
yaml_value = st.one_of(st.sampled_from(HOSTILE_YAML), st.integers(-(10**30), 10**30).map(str),
                       st.floats().map(repr),
                       st.text(alphabet=st.characters(blacklist_characters="\n\r\x85\u2028\u2029",
                                                      blacklist_categories=("Cs",)), max_size=10))


@st.composite
def map_image(draw) -> tuple[bytes, str, tuple[int, int]]:
    """(image bytes, file suffix, (H, W)) in one of the formats map_server reads."""
    h, w = draw(st.integers(1, 9)), draw(st.integers(1, 9))
    pix = np.array(draw(st.lists(st.sampled_from([0, 254, 205, 100, 255, 1]), min_size=h * w, max_size=h * w)),
                   dtype=np.uint8).reshape(h, w)
    fmt = draw(st.sampled_from(["P5", "P2", "L", "LA", "RGB", "RGBA", "I;16", "P", "1"]))
    if fmt == "P5":
        return f"P5\n# c\n{w} {h}\n255\n".encode() + pix.tobytes(), ".pgm", (h, w)
    if fmt == "P2":
        return (f"P2\n{w} {h}\n255\n" + " ".join(map(str, pix.ravel())) + "\n").encode(), ".pgm", (h, w)
    img = Image.fromarray(pix, "L")
    if fmt == "I;16":
        img = Image.fromarray(pix.astype(np.uint16) * 257)
    elif fmt != "L":
        img = img.convert(fmt)
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue(), ".png", (h, w)


@st.composite
def mutated_map(draw):
    image, suffix, shape = draw(map_image())
    fields = {"image": f"img{suffix}", "resolution": "0.05", "origin": "[-1.5, 2.0, 0.0]", "negate": "0",
              "occupied_thresh": "0.65", "free_thresh": "0.196"}
    if draw(st.booleans()):
        fields["mode"] = draw(st.sampled_from(["trinary", "scale", "raw"]))
    how = draw(st.sampled_from(["value", "value", "value", "delete", "dup", "yaml_cut", "yaml_insert", "yaml_bytes",
                                "img_cut", "img_byte", "img_header", "img_random", "img_missing", "img_dir", "none"]))
    key = draw(st.sampled_from(MAP_KEYS))
    text_extra = None
    if how == "value":
        fields[key] = draw(st.sampled_from(KEY_HOSTILE[KEY_KIND[key]]) if draw(st.integers(0, 3)) else yaml_value)
    elif how == "delete":
        fields.pop(key, None)
    elif how == "dup":
        text_extra = f"{key}: {draw(yaml_value)}\n"
    yaml_text = "".join(f"{k}: {v}\n" for k, v in fields.items()) + (text_extra or "")
    yaml_bytes = yaml_text.encode("utf-8", "surrogatepass")
    if how == "yaml_cut":
        yaml_bytes = yaml_bytes[: draw(st.integers(0, len(yaml_bytes)))]
    elif how == "yaml_insert":
        i = draw(st.integers(0, len(yaml_bytes)))
        yaml_bytes = yaml_bytes[:i] + draw(yaml_value).encode("utf-8", "surrogatepass") + yaml_bytes[i:]
    elif how == "yaml_bytes":
        i = draw(st.integers(0, len(yaml_bytes)))
        yaml_bytes = yaml_bytes[:i] + draw(st.binary(min_size=1, max_size=8)) + yaml_bytes[i:]
    elif how == "img_cut":
        image = image[: draw(st.integers(0, len(image) - 1))]
    elif how == "img_byte":
        i = draw(st.integers(0, min(len(image) - 1, draw(st.sampled_from([20, 60, 10_000])))))
        image = image[:i] + bytes([draw(st.integers(0, 255))]) + image[i + 1:]
    elif how == "img_header":
        n = draw(st.integers(1, 16))
        image = draw(st.binary(min_size=n, max_size=n)) + image[n:]
    elif how == "img_random":
        image = draw(st.binary(max_size=100))
    return yaml_bytes, image, suffix, shape, how, key, fields


@settings(max_examples=900, **FUZZ)
@given(case=mutated_map())
def test_fuzz_map_nearly_valid(tmp_path, case):
    yaml_bytes, image, suffix, shape, how, key, fields = case
    for p in tmp_path.iterdir():  # hypothesis reuses tmp_path across examples
        p.rmdir() if p.is_dir() else p.unlink()
    ypath = tmp_path / "fuzz.yaml"
    ypath.write_bytes(yaml_bytes)
    img = tmp_path / f"img{suffix}"
    if how == "img_dir":
        img.mkdir()
    elif how != "img_missing":
        img.write_bytes(image)
    try:
        grid = load_map(ypath)
    except DataError as e:
        msg = str(e)
        one_line_naming(msg, str(ypath))
        if how in ("value", "delete", "dup"):
            # The broken key is named, or the YAML syntax error's line; a wrong image name fails on the image.
            assert (key in msg or re.match(re.escape(str(ypath)) + r":\d+: ", msg)
                    or "invalid YAML" in msg or (key in ("image", "mode", "negate") and "image" in msg)), (key, msg)
        elif how.startswith("img"):
            assert "image" in msg, msg
        elif how == "none":
            pytest.fail(f"a valid map failed to load: {msg}")
        return
    assert grid.occupancy.dtype == np.int8 and grid.occupancy.ndim == 2
    assert grid.occupancy.min() >= -1 and grid.occupancy.max() <= 100
    assert grid.resolution > 0 and np.isfinite(grid.origin).all()
    if not how.startswith("img"):
        # an origin turned by a quarter turn turns the array; any other yaw resamples it onto a larger grid
        origin = yaml.safe_load(yaml_bytes).get("origin")
        k = float(origin[2]) / (0.5 * math.pi) if len(origin) == 3 else 0.0
        if abs(k - round(k)) * 0.5 * math.pi < 1e-9:
            assert grid.occupancy.shape == (shape if round(k) % 2 == 0 else shape[::-1])
        else:
            assert grid.occupancy.size >= shape[0] * shape[1]


@settings(max_examples=200, **FUZZ)
@given(yaml_bytes=st.binary(max_size=200), image=st.binary(max_size=200),
       header=st.sampled_from([b"P5\n4 3\n255\n", b"P2\n4 3\n255\n", b"\x89PNG\r\n\x1a\n", b"P5\n99999 99999\n255\n",
                               b"P5\n4 3\n65535\n", b"P5\n-4 3\n255\n", b""]))
def test_fuzz_map_random_bytes(tmp_path, yaml_bytes, image, header):
    y = tmp_path / "rand.yaml"
    y.write_bytes(yaml_bytes)
    try:
        load_map(y)
    except DataError as e:
        one_line_naming(str(e), str(y))
    good = tmp_path / "good.yaml"
    good.write_text("image: r.pgm\nresolution: 0.1\norigin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n")
    (tmp_path / "r.pgm").write_bytes(header + image)
    try:
        grid = load_map(good)
    except DataError as e:
        one_line_naming(str(e), str(good))
        assert "image" in str(e)
        return
    assert grid.occupancy.size > 0


# ============================================================================ config

SECTIONS = {k: v for k, v in to_dict(Config()).items()}
DOTTED = [f"{s}.{k}" for s, v in SECTIONS.items() if isinstance(v, dict) for k in v] + \
         [k for k, v in SECTIONS.items() if not isinstance(v, dict)]

any_value = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-(10**6), 10**6), st.sampled_from([10**400, -(10**30), 2**63]),
              st.floats(), st.text(max_size=8),
              st.sampled_from(["systematic", "off", "save", "FLASER", "~nosuchuser/x", "a\x00b", "", "odometry"])),
    lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=6), c, max_size=3),
    max_leaves=8,
)


@st.composite
def mutated_config(draw):
    data = to_dict(Config())
    data["map"] = data["log"] = data["truth"] = None
    how = draw(st.sampled_from(["value", "value", "value", "unknown", "delete", "section", "none"]))
    key = draw(st.sampled_from(DOTTED))
    parts = key.split(".")
    node = data if len(parts) == 1 else data[parts[0]]
    if how == "value":
        node[parts[-1]] = draw(any_value)
    elif how == "unknown":
        key = draw(st.text(min_size=1, max_size=8).filter(lambda k: k not in node))
        node[key] = draw(any_value)
        key = key if len(parts) == 1 else f"{parts[0]}.{key}"
    elif how == "delete":
        del node[parts[-1]]
    elif how == "section":
        key = parts[0]
        data[key] = draw(any_value)
    return yaml.dump(data, Dumper=DUMPER, allow_unicode=draw(st.booleans())), how, key


def _key_named(msg: str, key: str) -> bool:
    if key in msg or repr(key)[1:-1] in msg or key.rsplit(".", 1)[-1] in msg:
        return True
    # the key as YAML reads it back (a NEL, \x85, in a plain key is a line break to YAML: it loads as a space)
    last = key.rsplit(".", 1)[-1]
    for unicode in (True, False):
        read = next(iter(yaml.safe_load(yaml.safe_dump({last: 0}, allow_unicode=unicode))))
        if str(read) in msg or repr(str(read))[1:-1] in msg:
            return True
    return False


@settings(max_examples=900, **FUZZ)
@given(case=mutated_config())
def test_fuzz_config_nearly_valid(tmp_path, case):
    text, how, key = case
    path = tmp_path / "fuzz.yaml"
    path.write_text(text, encoding="utf-8")
    try:
        cfg = load_config(path)
    except ConfigError as e:
        msg = str(e)
        one_line_naming(msg, str(path))
        assert how in ("value", "unknown", "section"), (how, msg)
        assert _key_named(msg, key), (key, msg)
        return
    assert isinstance(cfg, Config)
    assert how != "unknown", f"unknown key {key!r} accepted"


@settings(max_examples=300, **FUZZ)
@given(doc=st.one_of(any_value.map(lambda v: yaml.safe_dump(v).encode()),
                     st.binary(max_size=120),
                     st.lists(st.sampled_from(["filter:", "  particles: 3", "sensor:", "\t", "- x", "seed: [",
                                               "rerun: {mode: off}", "motion: !!binary aGk=", "a: &a [*a]", "? [1]",
                                               "map: ~nobody-here/x", "%YAML 1.1", "---", "...", "\x00", "é: 1"]),
                              max_size=8).map(lambda ls: "\n".join(ls).encode())))
def test_fuzz_config_random_documents(tmp_path, doc):
    path = tmp_path / "doc.yaml"
    path.write_bytes(doc)
    try:
        load_config(path)
    except ConfigError as e:
        one_line_naming(str(e), str(path))


override = st.one_of(
    st.tuples(st.sampled_from(DOTTED + ["filter", "sensor.x", "filter.particles.x", "seed.x", "..", "a."]),
              st.one_of(st.sampled_from(HOSTILE_YAML), st.text(max_size=10))).map(lambda kv: f"{kv[0]}={kv[1]}"),
    st.text(max_size=20),
)


@settings(max_examples=500, **FUZZ)
@given(overrides=st.lists(override, min_size=1, max_size=3))
def test_fuzz_config_overrides(tmp_path, overrides):
    path = tmp_path / "base.yaml"
    path.write_text("seed: 3\nfilter:\n  particles: 100\n")
    try:
        cfg = load_config(path, overrides)
    except ConfigError as e:
        msg = str(e)
        assert "\n" not in msg and "\r" not in msg, msg
        # A malformed --set names itself; a bad value names the file and the key.
        assert msg.startswith("--set ") or str(path) in msg, msg
        return
    assert isinstance(cfg, Config)


# ============================================================================ `mcl run`

LOG = ("ODOM 0 0 0 0 0 0 1.0 h 1.0\n"
       "FLASER 4 1.0 1.2 1.4 1.6 0 0 0 0 0 0 1.0 h 1.0\n"
       "ODOM 0.2 0 0 0 0 0 1.1 h 1.1\n"
       "FLASER 4 1.0 1.2 1.4 1.6 0.2 0 0 0.2 0 0 1.1 h 1.1\n")
MAP_YAML = "image: map.pgm\nresolution: 0.1\norigin: [-1.0, -1.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
CONFIG = ("map: map.yaml\nlog: log.clf\nseed: 1\nfilter:\n  particles: 50\n  initial_pose: [0, 0, 0]\n"
          "  global_localization: false\nrerun:\n  mode: off\n")


def _world(d: Path) -> Path:
    pix = np.full((20, 20), 254, dtype=np.uint8)
    pix[0, :] = pix[-1, :] = pix[:, 0] = pix[:, -1] = 0
    (d / "map.pgm").write_bytes(b"P5\n20 20\n255\n" + pix.tobytes())
    (d / "map.yaml").write_text(MAP_YAML)
    (d / "log.clf").write_text(LOG)
    (d / "run.yaml").write_text(CONFIG)
    return d / "run.yaml"


# Each case breaks one file for sure: (file, function of its text/bytes -> broken content).
CLI_BREAKS = st.one_of(
    st.tuples(st.just("run.yaml"), st.sampled_from(["filter:\n  particles: many\n", "seed: -1\n", "sensor: {beam: {sigma_hit: 0}}\n",
                                                   "rerun:\n  particles_every: 0\n", "filtre: {}\n", "motion: [\n",
                                                   "filter:\n  initial_pose: [1, 2]\n", "seed: " + "9" * 400 + "\n"])),
    st.tuples(st.just("map.yaml"), st.sampled_from([MAP_YAML.replace("0.1", "-0.1"), MAP_YAML.replace("map.pgm", "nope.pgm"),
                                                   MAP_YAML.replace("origin: [-1.0", "origin: [" + "9" * 400),
                                                   MAP_YAML.replace("image: map.pgm\n", ""), "image: [\n"])),
    st.tuples(st.just("map.pgm"), st.integers(0, 400)),  # truncated image (the full one has 413 bytes)
    st.tuples(st.just("log.clf"), st.sampled_from([LOG.replace("1.2", "one", 1), LOG.replace("FLASER 4", "FLASER 5", 1),
                                                  LOG.replace("ODOM 0.2", "ODOM nan", 1), LOG.replace("FLASER", "#"),
                                                  "\xff\n", ""])),
)


@settings(max_examples=25, **FUZZ)
@given(case=CLI_BREAKS)
def test_fuzz_cli_run_exits_2_with_one_line(tmp_path, case):
    for p in tmp_path.rglob("*"):
        if p.is_file():
            p.unlink()
    cfg = _world(tmp_path)
    name, broken = case
    target = tmp_path / name
    if isinstance(broken, int):
        target.write_bytes(target.read_bytes()[:broken])
    elif name == "run.yaml":
        target.write_text(CONFIG + broken)  # a repeated section or key replaces the first one
    else:
        target.write_bytes(b"\xff\n" if broken == "\xff\n" else broken.encode())
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["run", str(cfg), "--out", str(tmp_path / "out"), "--rerun", "off", "--no-progress"])
    lines = err.getvalue().splitlines()
    assert code == 2, (name, broken, err.getvalue())
    assert len(lines) == 1 and lines[0].startswith("mcl: error: "), lines
    assert "Traceback" not in err.getvalue()
    named = "map.yaml" if name == "map.pgm" else name  # an image problem names the map YAML and the image
    assert f"{tmp_path}/{named}" in lines[0], lines[0]


def test_cli_world_is_valid(tmp_path):
    # The unbroken world loads (so each break above is what fails); no filter run needed.
    cfg = load_config(_world(tmp_path))
    assert load_map(cfg.map).occupancy.shape == (20, 20)
    assert len(read_carmen(cfg.log).scans) == 2


def test_mcl_errors_are_one_class():
    assert issubclass(ConfigError, MclError) and issubclass(DataError, MclError)


# ============================================================================ the bugs the fuzzing found

BIG = "9" * 400  # a YAML integer beyond the float range


@pytest.mark.parametrize("text, key", [
    (f"sensor:\n  likelihood_field:\n    sigma_hit: {BIG}\n", "sensor.likelihood_field.sigma_hit"),                  # was OverflowError
    (f"filter:\n  initial_pose: [0, 0, {BIG}]\n", "filter.initial_pose"),   # was OverflowError
    ("map: ~no-such-user-mcl/map.yaml\n", "map"),                             # was RuntimeError
    ('log: "a\\0b.clf"\n', "log"),                                            # was ValueError
    ('"filter\\nx": 1\n', "filter\\nx"),                                      # was a two-line message
])
def test_config_regressions(tmp_path, text, key):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_config(path)
    one_line_naming(str(e.value), str(path))
    assert key in str(e.value)


def test_override_into_a_value_names_the_override():
    with pytest.raises(ConfigError, match=r"^--set filter.particles.x=1: filter.particles: is not a section$"):
        load_config(None, ["filter.particles=5", "filter.particles.x=1"])


@pytest.mark.parametrize("key, value", [
    ("resolution", BIG), ("origin", f"[{BIG}, 0, 0]"),  # were OverflowError
    ("image", '"a\\nb.pgm"'),                            # was a two-line message
])
def test_map_regressions(tmp_path, key, value):
    (tmp_path / "m.pgm").write_bytes(b"P5\n2 2\n255\n\x00\xfe\xfe\x00")
    fields = {"image": "m.pgm", "resolution": "0.1", "origin": "[0, 0, 0]", "occupied_thresh": "0.65",
              "free_thresh": "0.196", key: value}
    path = tmp_path / "m.yaml"
    path.write_text("".join(f"{k}: {v}\n" for k, v in fields.items()))
    with pytest.raises(DataError) as e:
        load_map(path)
    one_line_naming(str(e.value), str(path))
    assert key in str(e.value)


def test_carmen_regressions(tmp_path):
    path = tmp_path / "x.clf"
    # Headings -1e308 and 1e308: their difference overflowed and math.sin(inf) raised ValueError.
    # Each heading is wrapped first now: the offset is the exact wrapped difference.
    path.write_text("FLASER 1 1.0 0 0 -1e308 0 0 1e308 1.0 h 1.0\n")
    off = read_carmen(path).scans[0].laser_offset
    want = math.remainder(-1e308, math.tau) - math.remainder(1e308, math.tau)
    assert off[:2].tolist() == [0.0, 0.0] and off[2] == pytest.approx(math.atan2(math.sin(want), math.cos(want)))
    # Positions -1e308 and 1e308: the offset is not finite.
    path.write_text("FLASER 1 1.0 -1e308 0 0 1e308 0 0 1.0 h 1.0\n")
    with pytest.raises(DataError, match=r"x\.clf:1: FLASER: laser pose too far"):
        read_carmen(path)
    # Interpolating between ODOM x = -1e308 and 1e308 gave a scan an infinite odometry pose.
    path.write_text("ODOM -1e308 0 0 0 0 0 0.0 h 0.0\nODOM 1e308 0 0 0 0 0 2.0 h 2.0\n"
                    "RAWLASER1 0 -1.5 3.14 0.01 80 0.01 0 1 1.0 0 1.0 h 1.0\n")
    with pytest.raises(DataError, match=r"x\.clf:3: RAWLASER1: odometry interpolated at t=1.0 is not finite"):
        read_carmen(path)
