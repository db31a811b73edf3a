"""Scans stamped late: infinite_corridor's first 45 s with every scan paired with the odometry 0.1 s after it
(scripts/degrade_laser.py --latency), as a driver that stamps its scans late does. Skips when ../shared/data is
absent; runs in CI."""

from __future__ import annotations

import sys
import warnings

import pytest

from mcl.config import PROJECT_ROOT, load_config
from mcl.runner import run

sys.path.insert(0, str(PROJECT_ROOT / "scripts"))
from degrade_laser import delay_line, odometry_stream  # noqa: E402

CORRIDOR = PROJECT_ROOT.parent / "shared" / "data" / "infinite_corridor"


@pytest.mark.slow
@pytest.mark.skipif(not (CORRIDOR / "log.clf").is_file(), reason=f"infinite_corridor not found at {CORRIDOR}")
@pytest.mark.xfail(strict=True, reason="open defect (sixteenth session): the odometry-fault window runs the track "
                   "down the corridor when the scans are stamped late; strict, so a fix makes this fail until the "
                   "mark goes")
def test_a_late_scan_stamp_at_the_junction_does_not_send_the_track_down_the_corridor(tmp_path):
    # At 25.8 s the robot turns at a T-junction where a person stands; with the scans 0.1 s late the scans misfit
    # the turn and the filter calls itself lost. The odometry-fault mixture then opens (motion.fault_*): with its
    # sigmas 10 times the model's (the default), fault poses far along the corridor fitted the misfit scans better
    # each update, and the estimate ran down the corridor at 5 m/s: 16.3 and 15.6 m off with seeds 1 and 2 (seeds
    # 1-10 over the whole log: 9 lost, worst 66 m). With 5 times: 0.33 and 0.30 m (seeds 1-5 in these 45 s: at
    # most 1.41 m), but 5 costs recoveries elsewhere (docs/measurements.md, "Odometry faults"), so the default
    # stays at 10 and this test is a strict xfail until a fix that costs nothing. The baseline: 0.53-0.62 m over the
    # whole log. Bound: 3 m, twice the worst of the five seeds with 5, far under the runaway's 16 m.
    lines = []
    for line in (CORRIDOR / "log.clf").read_text().splitlines(keepends=True):
        p = line.split()
        if p and p[0] in ("ODOM", "FLASER") and float(p[7] if p[0] == "ODOM" else p[2 + int(p[1]) + 6]) > 45.0:
            break
        lines.append(line)
    stream = odometry_stream(lines)
    log = tmp_path / "late.clf"
    log.write_text("".join(delay_line(line, stream, 0.1) for line in lines))
    for seed in (1, 2):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
            f"map={CORRIDOR / 'map.yaml'}", f"log={log}", f"truth={CORRIDOR / 'truth.tum'}",
            "filter.initial_pose=[1.008240, -0.016781, 0.005957]", "filter.global_localization=false",
            "rerun.mode=off", f"seed={seed}"])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            s = run(cfg, tmp_path / f"seed{seed}", progress=False, echo=lambda *_: None)
        assert s["eval"]["scored"] >= 200 and s["fault_updates"] > 0, s  # the junction's lost call opened faults
        assert s["eval"]["ate_max"] <= 3.0, (seed, s["eval"])
