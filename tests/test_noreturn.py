"""No-return detection (mcl.datasets.noreturn): each marker of ../shared/data/README.md, and the real logs."""

import json
from pathlib import Path

import numpy as np
import pytest

from mcl.datasets.carmen import read_carmen
from mcl.datasets.noreturn import detect_no_return

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def _readings(rng, markers, share=0.03, n=60_000, top=None):
    """Real readings (a mixture of short indoor ranges and a long tail, all below the marker) plus ``share`` of
    no-return readings spread evenly over ``markers``."""
    top = top if top is not None else 0.985 * min(markers)  # real readings within 1 % of the marker are rare
    real = np.concatenate([rng.gamma(2.0, 1.2, size=int(0.8 * n)), rng.uniform(0.1, top, size=int(0.2 * n))])
    real = np.round(np.clip(real, 0.02, top), 2)  # loggers write centimetres
    k = int(share * n)
    marks = np.asarray(markers)[rng.integers(0, len(markers), size=k)]
    r = np.concatenate([real, marks])
    rng.shuffle(r)
    return r, real.max()


@pytest.mark.parametrize("markers", [
    [81.83],  # SICK (intel_lab)
    [81.91],  # SICK (mit_csail, fr079, fr101, belgioioso)
    [50.00],  # aces, part of acapulco
    [50.00, 51.14, 51.15],  # acapulco
    list(np.round(np.arange(51.00, 51.255, 0.01), 2)),  # a band 51.00-51.25 (infinite_corridor style), evenly spread
])
def test_each_marker_is_found(markers):
    rng = np.random.default_rng(7)
    r, real_max = _readings(rng, markers)
    nr = detect_no_return(r)
    assert nr is not None
    # every marker reading is at or above the threshold, every real reading below it
    assert nr.threshold <= min(markers)
    assert nr.threshold > real_max
    assert nr.count == int(np.count_nonzero(np.isin(r, markers)))
    assert min(markers) == pytest.approx(nr.spikes[0], abs=0.015)  # the band's lowest bin may have few


def test_a_marker_with_real_readings_just_below_it():
    # long real readings up to 49.45 m (a convention hall): the threshold stays above them (the 1 % margin)
    rng = np.random.default_rng(3)
    r, real_max = _readings(rng, [50.0], top=49.45)
    nr = detect_no_return(r)
    assert nr is not None and real_max < nr.threshold <= 50.0


def test_no_spike_no_marker():
    rng = np.random.default_rng(1)
    real = np.round(rng.gamma(2.0, 2.0, size=50_000), 2)
    assert detect_no_return(real) is None
    # a robot standing still in front of a wall repeats a short reading: not at the top of the range
    still = np.concatenate([real, np.full(5_000, 3.20)])
    assert detect_no_return(still) is None
    # every reading the same: nothing to tell a marker from
    assert detect_no_return(np.full(181, 1.0)) is None
    assert detect_no_return(np.array([np.nan, np.inf, -1.0])) is None


def test_reader_sets_the_flaser_max_range_and_says_so(tmp_path):
    rng = np.random.default_rng(5)
    lines = []
    for k in range(60):
        r = np.round(rng.uniform(0.5, 20.0, size=180), 2)
        r[rng.random(180) < 0.1] = 50.0
        lines.append(f"FLASER 180 {' '.join(f'{v:.2f}' for v in r)} 0 0 0 0 0 0 {k:.1f} host {k:.1f}\n")
    p = tmp_path / "nr.clf"
    p.write_text("".join(lines))
    log = read_carmen(p)
    assert all(s.max_range == pytest.approx(49.5) for s in log.scans)
    assert len(log.notes) == 1 and "50.00 m" in log.notes[0] and "49.50" in log.notes[0] and "FLASER" in log.notes[0]


# Each newer folder's meta.json gives the threshold measured for its log (readings >= it mean no return); the
# README gives the marker values of the others (81.83 m for intel_lab, 81.91 m for mit_csail and fr079).
REAL = {"intel_lab": 81.83, "mit_csail": 81.91, "fr079": 81.91}


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason=f"real datasets not found at {DATA}")
@pytest.mark.parametrize("name", ["intel_lab", "mit_csail", "fr079", "aces", "acapulco", "fr101", "belgioioso",
                                  "infinite_corridor"])
def test_real_logs(name):
    log = read_carmen(DATA / name / "log.clf")
    r = np.concatenate([s.ranges for s in log.scans])
    meta = DATA / name / "meta.json"
    marker = json.loads(meta.read_text())["no_return_m"] if meta.exists() else REAL[name]
    thr = {s.max_range for s in log.scans}
    assert len(thr) == 1
    thr = thr.pop()
    # the reader's threshold takes every reading the data set calls no-return, and at most 0.1 % more
    assert np.count_nonzero(r >= thr) >= np.count_nonzero(r >= marker)
    assert np.count_nonzero(r >= thr) - np.count_nonzero(r >= marker) <= 1e-3 * r.size


def test_absurd_readings_are_left_out_of_the_histogram():
    # a corrupt 1e40 m reading (found by tests/test_fuzz.py) overflowed the centimetre bins; readings above
    # 1 km are no laser's, and the marker is still found among the rest
    r = np.r_[np.full(200, 50.0), np.linspace(0.5, 40.0, 2000), 1e40, 5e3]
    nr = detect_no_return(r)
    assert nr is not None and nr.spikes == (50.0,) and nr.total == 2200


def test_a_log_s_scans_are_taken_a_block_at_a_time_with_the_same_answer(monkeypatch):
    # read_carmen joined every reading of a log into one array and took four float64 copies of it: a 93 MB log
    # (fr079 ten times) peaked at 1.03 GB. The histogram is now summed a block at a time; the marker, the threshold
    # and the counts must be those of the whole array, whatever the blocks (here 1,000 readings, scans of 181).
    import mcl.datasets.noreturn as nrmod

    rng = np.random.default_rng(3)
    r, _ = _readings(rng, [50.00, 51.14, 51.15])
    scans = [r[i:i + 181] for i in range(0, r.size, 181)]
    whole = detect_no_return(r)
    monkeypatch.setattr(nrmod, "_BLOCK", 1_000)
    blocked = detect_no_return(scans)
    assert whole is not None and blocked == whole
    assert detect_no_return([np.array([np.nan, np.inf, -1.0])]) is None and detect_no_return([]) is None


def test_reading_a_log_holds_about_its_scans_not_copies_of_its_text(tmp_path):
    # A log read whole held its bytes, its text and a list of its lines at once, and the no-return detection four
    # copies of every reading: tracemalloc's peak was 4.8 times what the read log holds (fr079 ten times: 832 MB
    # for 174 MB). Now the lines are taken one at a time and the text let go: 1.6 times (276 MB; 1.8 on this log,
    # whose text is a larger share of what it holds). The bound, 2.5, fails on either copy coming back.
    import tracemalloc

    demo = Path(__file__).resolve().parents[1] / "data" / "demo" / "log.clf"
    log = tmp_path / "long.clf"
    log.write_bytes(demo.read_bytes() * 12)  # 5.7 MB, 4,200 scans
    tracemalloc.start()
    try:
        read = read_carmen(log)
        held, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(read.scans) == 12 * len(read_carmen(demo).scans)
    assert peak <= 2.5 * held, (peak, held)


def test_a_marker_under_stray_readings_or_under_a_second_marker_is_found():
    # A 3 m laser marks a third of its beams 3.00 m. Two stray readings of 200 m set the top of the range, and the
    # spike, far under 90 % of it, was not taken: the no-returns scored as walls 3 m away (7.03 m RMSE). Mixed with a
    # 0.2 % of 65.53 m error codes, the codes alone were taken (64.87 m) and the 3.00 m no-returns were walls (0.46
    # m). A spike with (almost) no reading above it but other spikes' is at the top too.
    rng = np.random.default_rng(11)
    real = np.round(rng.uniform(0.3, 2.95, size=40_000), 2)
    marks = np.full(20_000, 3.00)
    stray = np.concatenate([real, marks, [200.0, 200.0]])
    nr = detect_no_return(stray)
    assert nr is not None and nr.threshold == pytest.approx(0.99 * 3.0) and nr.spikes[0] == 3.0
    codes = np.concatenate([real, marks, np.full(120, 65.53)])
    nr = detect_no_return(codes)
    assert nr is not None and nr.threshold == pytest.approx(0.99 * 3.0) and nr.spikes == (3.0, 65.53)
    assert nr.count == 20_120
    # a robot standing still repeats a short reading with most of the readings above it: still no marker
    still = np.concatenate([np.round(rng.uniform(0.3, 8.0, size=40_000), 2), np.full(5_000, 3.0), [200.0]])
    assert detect_no_return(still) is None
