"""A reference trajectory of another run (its clock overlapping this log's) is said, not scored silently."""

from __future__ import annotations

import numpy as np
import pytest

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


def test_a_run_scores_a_clock_that_steps_back_as_mcl_eval_does(tmp_path):
    # The run sorted its reference by time before scoring, so a log whose clock steps back (its reference stamped by
    # the same clock) was paired across the two passes: 0.128 m where mcl eval, pairing the stretches in order,
    # gave 0.044 m on the same files. The demo's first 40 s with its clock set back 1 s at 20 s, log and reference:
    # the run's figures are mcl eval's.
    from mcl.evaluate import evaluate
    from mcl.runner import run

    demo = PROJECT_ROOT / "data" / "demo"
    lines = []
    for line in (demo / "log.clf").read_text().splitlines(keepends=True):
        p = line.split()
        if p and p[0] in ("FLASER", "ODOM"):
            t = float(p[-1])
            if t > 40.0:
                continue
            if t > 20.0:
                p[-3] = p[-1] = f"{t - 1.0:.6f}"
                line = " ".join(p) + "\n"
        lines.append(line)
    (tmp_path / "log.clf").write_text("".join(lines))
    t, poses = read_tum(demo / "truth.tum")
    keep = t <= 40.0
    t, poses = t[keep], poses[:, keep]
    write_tum(tmp_path / "truth.tum", np.where(t > 20.0, t - 1.0, t), poses)
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"log={tmp_path / 'log.clf'}", f"map={demo / 'map.yaml'}", f"truth={tmp_path / 'truth.tum'}",
        "rerun.mode=off", f"filter.initial_pose={poses[:, 0].tolist()}"])
    s = run(cfg, tmp_path / "out", progress=False, echo=lambda *_: None)
    te, pe = read_tum(tmp_path / "out" / "trajectory.tum")
    tr, pr = read_tum(tmp_path / "truth.tum")
    again = evaluate(te, pe, tr, pr)
    # (the file's 9 decimals against the run's own float64: equal to 1e-6)
    assert s["eval"]["ate_rmse"] == pytest.approx(again["ate_rmse"], rel=1e-6)
    assert s["eval"]["ate_max"] == pytest.approx(again["ate_max"], rel=1e-6)
    assert s["eval"]["ate_max"] < 0.3  # the track is not lost: each pass paired with its own


def test_a_run_says_when_its_scans_repeat_a_stamp(tmp_path):
    # Every other scan stamped as the one before it: the trajectory has two poses at those times, and the run
    # scored them against the reference by time without a word (0.62 m where each pose was 0.08 m off); mcl eval
    # said "given twice". The run now says it too.
    from mcl.runner import run

    demo = PROJECT_ROOT / "data" / "demo"
    lines, k, last = [], 0, None
    for line in (demo / "log.clf").read_text().splitlines(keepends=True):
        p = line.split()
        if p and p[0] in ("FLASER", "ODOM") and float(p[-1]) > 20.0:
            continue
        if p and p[0] == "FLASER":
            if k % 2 and last is not None:
                p[-3] = p[-1] = last
                line = " ".join(p) + "\n"
            last, k = p[-1], k + 1
        lines.append(line)
    (tmp_path / "log.clf").write_text("".join(lines))
    t, poses = read_tum(demo / "truth.tum")
    said: list = []
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"log={tmp_path / 'log.clf'}", f"map={demo / 'map.yaml'}", f"truth={demo / 'truth.tum'}",
        "rerun.mode=off", f"filter.initial_pose={poses[:, 0].tolist()}"])
    run(cfg, tmp_path / "out", progress=False, echo=said.append)
    assert sum("time(s) given twice with other positions" in m for m in said) == 1, said
