"""fr079 (Freiburg building 079: noisy odometry, people walking) tracked through the whole log.

Issue 4: from the dataset's start pose with configs/fr079.yaml, ATE RMSE <= 0.08 m and never more than
0.5 m off. Skips when ../shared/data/fr079 is absent (a user's clone); runs in CI.
"""

from __future__ import annotations

import warnings

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
    # Issue 8: configs/default.yaml with no dataset config, tracked from the start pose, within 1.5 m of the
    # reference on fr079. At 303-309 s the log's odometry reports 0.1 m forward per scan while the robot reverses:
    # with the odometry-fault mixture (motion.fault_prob, open from the lost call at 303.6 s) the filter follows
    # the scans, max error 1.28 m with seed 1 (seeds 1-5: 1.02-1.38 m with the protected spread and no spread on a
    # scan that fits, fifteenth session; 0.93-0.99 m with the spread mixed in); without either the cloud, a few
    # centimetres wide, drifts until the next lost call, 1.84 m (seeds 1-5: 1.84-9.46 m; 2.24-2.44 m with the
    # spread mixed in). The wall rule alone calls that slip lost sooner (1.36 m, seed 1, twelfth session), so the
    # plain model here goes without both. Bounds: the 1.5 m, and 1.6 m for the plain model, between the
    # default's worst seed and the plain model's best.
    def track(*sets):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [f"map={FR079 / 'map.yaml'}", f"log={FR079 / 'log.clf'}",
                                 f"truth={FR079 / 'truth.tum'}", "filter.initial_pose=[0.001236, -0.001068, 0.000029]",
                                 "filter.global_localization=false", "rerun.mode=off", *sets])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return run(cfg, tmp_path / str(len(sets)), progress=False, echo=lambda *_: None)

    s = track()
    assert s["eval"]["ate_max"] <= 1.5, s["eval"]
    assert s["fault_updates"] > 0
    plain = track("motion.fault_prob=0", "quality.contradiction_above=0")
    assert plain["eval"]["ate_max"] > 1.6, plain["eval"]
    assert plain["fault_updates"] == 0
