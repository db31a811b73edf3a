"""fr079 (Freiburg building 079: noisy odometry, people walking) tracked through the whole log.

Issue 4: from the dataset's start pose with configs/fr079.yaml, ATE RMSE <= 0.08 m and never more than
0.5 m off. Issue 8: configs/default.yaml through the log's odometry fault at 305 s (280-380 s of the log).
Skips when ../shared/data/fr079 is absent (a user's clone); runs in CI.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from mcl.config import PROJECT_ROOT, load_config
from mcl.runner import run

SHARED = PROJECT_ROOT.parent / "shared" / "data"
FR079 = SHARED / "fr079"


@pytest.mark.slow
@pytest.mark.skipif(not (FR079 / "log.clf").is_file(), reason=f"fr079 data set not found at {FR079}")
def test_fr079_tracked_through_the_whole_log(tmp_path):
    cfg = load_config(PROJECT_ROOT / "configs" / "fr079.yaml", ["rerun.mode=off"])
    assert cfg.seed == 1 and cfg.filter.initial_pose is not None and not cfg.filter.global_localization
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        s = run(cfg, tmp_path, progress=False, echo=lambda *_: None)
    assert not s["interrupted"]
    ev = s["eval"]
    assert ev["scored"] >= 4700, ev  # the whole log (4,791 scans; a few outside the estimate's span)
    assert ev["ate_rmse"] <= 0.08, ev
    assert ev["ate_max"] <= 0.5, ev
    assert not any(s["events"].values()), s["events"]  # a clean log: no degenerate-input event


@pytest.mark.slow
@pytest.mark.skipif(not (FR079 / "log.clf").is_file(), reason=f"fr079 data set not found at {FR079}")
def test_the_default_config_follows_the_scans_through_the_odometry_fault_at_305_s(tmp_path):
    # Issue 8: configs/default.yaml with no dataset config, tracked from the reference pose, within 1.5 m of the
    # reference on fr079. At 303-309 s the log's odometry reports 0.1 m forward per scan while the robot reverses:
    # with the odometry-fault mixture (motion.fault_prob, open from the lost call) the filter follows the scans;
    # without it and the contradiction rule, the cloud, a few centimetres wide, drifts until the next lost call.
    # The whole log took 79 s of the CI run for two runs, so the test replays 280-380 s of it (the fault and the
    # 70 s after), started from the reference pose at 280.1 s. Measured there, seeds 1-5 (twenty-ninth session):
    # the default 0.75-1.11 m (seed 1: 0.75), the plain model 1.83-2.81 m (seed 1: 2.76); on the whole log the
    # default's seeds 1-5 reached 1.02-1.38 m and the plain model's 1.84-9.46 m. Bounds: the 1.5 m, and
    # 1.6 m for the plain model, between the default's worst seed and the plain model's best on both.
    lines = [line for line in (FR079 / "log.clf").read_text().splitlines(keepends=True) if not line.startswith("#")]
    stamp = lambda line: float(line.split()[-3])  # noqa: E731 - the CARMEN line's ipc timestamp
    log = tmp_path / "log.clf"
    log.write_text("".join(line for line in lines if 280.0 <= stamp(line) <= 380.0))
    truth = np.loadtxt(FR079 / "truth.tum")
    ref = truth[np.argmin(np.abs(truth[:, 0] - 280.1))]  # the first scan kept
    assert abs(ref[0] - 280.1) < 0.15
    start = [float(ref[1]), float(ref[2]), 2.0 * math.atan2(ref[6], ref[7])]  # yaw of a rotation about z

    def track(*sets):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [f"map={FR079 / 'map.yaml'}", f"log={log}",
                                 f"truth={FR079 / 'truth.tum'}", f"filter.initial_pose={start}",
                                 "filter.global_localization=false", "rerun.mode=off", *sets])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return run(cfg, tmp_path / str(len(sets)), progress=False, echo=lambda *_: None)

    s = track()
    assert s["eval"]["scored"] >= 400, s["eval"]  # the 100 s kept: 443 scans
    assert s["eval"]["ate_max"] <= 1.5, s["eval"]
    assert s["fault_updates"] > 0
    plain = track("motion.fault_prob=0", "quality.contradiction_above=0")
    assert plain["eval"]["ate_max"] > 1.6, plain["eval"]
    assert plain["fault_updates"] == 0
