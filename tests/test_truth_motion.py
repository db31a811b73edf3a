"""A reference trajectory of another run (its clock overlapping this log's) is said, not scored silently."""

from __future__ import annotations

import numpy as np

from mcl.config import PROJECT_ROOT, load_config
from mcl.evaluate import motion_disagreement
from mcl.runner import _open_source
from mcl.trajectory import read_tum, write_tum

DEMO = PROJECT_ROOT / "data" / "demo"


def _warnings(truth_path) -> list[str]:
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [f"truth={truth_path}"])
    said: list[str] = []
    _open_source(cfg, echo=said.append)
    return [m for m in said if "does not move as the odometry" in m]


def test_the_demo_own_reference_passes_and_another_runs_is_said(tmp_path):
    t, poses = read_tum(DEMO / "truth.tum")
    assert _warnings(DEMO / "truth.tum") == []
    # another run on the same clock: the demo's path driven backwards in time (the same places, other motion)
    other = tmp_path / "other.tum"
    write_tum(other, t, np.ascontiguousarray(poses[:, ::-1]))
    said = _warnings(other)
    assert len(said) == 1 and str(other) in said[0]
    # the same run's reference in another map frame (shifted and turned): the motion is the same, nothing said
    c, s = np.cos(1.0), np.sin(1.0)
    moved = np.vstack([5 + c * poses[0] - s * poses[1], -3 + s * poses[0] + c * poses[1], poses[2] + 1.0])
    write_tum(tmp_path / "moved.tum", t, moved)
    assert _warnings(tmp_path / "moved.tum") == []


def test_stretches_are_judged_by_chord_and_turn_in_their_own_frame():
    t = np.arange(0.0, 100.0, 0.1)
    # odometry: a straight drive at 0.5 m/s, then turning on the spot for the last 20 s
    th = np.where(t < 80, 0.0, 0.3 * (t - 80))
    odo = np.vstack([0.5 * np.minimum(t, 80), np.zeros_like(t), th])
    # the same motion in another frame, with 10 % more travel (odometry scale error) is not a disagreement
    ref = np.vstack([1.1 * odo[1] + 2, 1.1 * odo[0] - 1, odo[2] + np.pi / 2])
    assert motion_disagreement(t, odo, t, ref) == (0, 19)
    # the reference standing still for its first 30 s: 6 stretches of 5 s disagree, of the 19 (0..95 s) where either moved
    late = np.vstack([0.5 * np.clip(t - 30, 0, 50), np.zeros_like(t), th])
    assert motion_disagreement(t, odo, t, late) == (6, 19)
    # clocks sharing less than two stretches: nothing to judge
    assert motion_disagreement(t, odo, t + 95.5, ref) == (0, 0)
