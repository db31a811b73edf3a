"""A wheel that slips (motion.slip_turn): the odometry turns the robot that did not turn, and a share of the
particles doubts each step's turn in proportion to it."""

import math
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from mcl.adaptive import FaultWindow, GlobalSearch
from mcl.config import PROJECT_ROOT, load_config
from mcl.motion import FaultProposal, OdometryMotionModel, noise_sigmas
from mcl.simulate import simulate
from mcl.trajectory import read_tum


def _motion(**kw):
    base = dict(fault_prob=1e-3, fault_share=0.05, fault_scale=10.0, fault_window=3, fault_window_s=0.0,
                fault_contradiction=0.1, fault_turn_max=0.0, fault_shift_max=0.0, fault_widen_after=0,
                fault_held_turn_max=0.0, slip_turn=1.5)
    return SimpleNamespace(**{**base, **kw})


def test_a_slip_doubts_the_turn_alone_and_in_proportion_to_it():
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", []).motion
    slip = FaultProposal(1e-3, 0.05, 10.0, turn_rel=1.5)
    # a turning step: 0.1 rad in rot1 and rot2 over 0.07 m; its heading stds become 1.5 x 0.1 rad, its translation
    # keeps the model's
    s = noise_sigmas(0.1, 0.07, 0.1, cfg)
    k = slip.scales(s, turned=(0.1, 0.0, 0.1))
    assert k[1] == 1.0
    assert k[0] * s[0] == pytest.approx(0.15) and k[2] * s[2] == pytest.approx(0.15)
    # a straight step has no turn to doubt: the plain model
    s = noise_sigmas(0.0, 0.07, 0.0, cfg)
    assert [float(v) for v in slip.scales(s, turned=(0.0, 0.0, 0.0))] == [1.0, 1.0, 1.0]
    # never wider than fault_scale times the model's: a 3 rad turn on the spot, doubted at 5 times its turn (its own
    # std is sqrt(alpha1) 3 = 0.67 rad: 1.5 times the turn is 6.7 of it, under the cap)
    s = noise_sigmas(0.0, 0.0, 3.0, cfg)
    assert float(slip.scales(s, turned=(0.0, 0.0, 3.0))[2]) == pytest.approx(1.5 * 3.0 / s[2])
    assert float(FaultProposal(1e-3, 0.05, 10.0, turn_rel=5.0).scales(s, turned=(0.0, 0.0, 3.0))[2]) == 10.0
    # a reversing robot's rot1 near pi turned by its difference from pi, as its noise (OdometryMotionModel._turned):
    # 0.07 m back, turning 0.1 rad, then 0.2 rad more (rot2 = -(pi - 0.2) as read)
    assert OdometryMotionModel._turned((math.pi - 0.1, 0.07, -(math.pi - 0.2))) == pytest.approx((0.1, 0.0, 0.2))
    # a density (no step's turn given) is the plain model's
    assert [float(v) for v in slip.scales(s)] == [1.0, 1.0, 1.0]


def test_a_slip_is_allowed_while_the_fault_window_is_closed_and_the_window_widens_it():
    s = GlobalSearch()
    f = FaultWindow(_motion(), s)
    assert f.proposal(0.1).turn_rel == 1.5  # closed: the wheel's slip
    s.observe(True, 1.0)
    f.observe(True, 0.2)  # a lost call on a held track through mapped walls: the window's wide component
    assert f.open and f.proposal(0.1).turn_rel == 0.0 and f.proposal(0.1).scale == 10.0
    assert FaultWindow(_motion(slip_turn=0.0), GlobalSearch()).proposal(0.1) is None  # off: the plain model


def _heading_error(world, out, slip_turn: float, slips: str = "keep"):
    """Max heading error (rad) against the world's truth of a default run from its start pose, with
    ``motion.slip_turn`` = ``slip_turn`` and ``motion.slips`` = ``slips``, and its summary."""
    from mcl.runner import run

    start = yaml.safe_load((world / "sim.yaml").read_text())["start_pose"]
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={world / 'map.yaml'}", f"log={world / 'log.clf'}", "truth=null", "rerun.mode=off",
        f"filter.initial_pose={start}", f"motion.slip_turn={slip_turn}", f"motion.slips={slips}"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = run(cfg, out, progress=False, echo=lambda m: None)
    tt, truth = read_tum(world / "truth.tum")
    t, est = read_tum(out / "trajectory.tum")
    th = np.interp(tt, t, np.unwrap(est[2]))
    return float(np.max(np.abs(np.angle(np.exp(1j * (th - truth[2])))))), s


def test_rooms_whose_wheel_slips_three_times_keep_their_heading(tmp_path):
    # Identical rooms seen at 2 Hz, the right wheel slipping three times for 2 s (heldout23's kind): the odometry
    # turns 0.5-1 rad a scan that the robot did not. Without the slip's doubt the cloud turns with it and is 1.46 rad
    # off (0.89 m; the fault window opens only on the lost call, too late); with it the heading stays within
    # 0.024 rad (max 0.15 m), the same run's heading without slips. Bounds: 0.1 and 0.5 rad, a factor 4 and 3 from
    # the measured figures. Both with the slips' steps as they came (motion.slips keep): the default takes them from
    # scan matching (tests/test_odomstall.py), which alone leaves 0.21 rad here (under 0.5 rad).
    world = tmp_path / "world"
    simulate(world, kind="rooms", seed=2902, duration=60.0, scan_rate=2.0, odom_slips=3, odom_slip_s=2.0)
    err, s = _heading_error(world, tmp_path / "slip", 1.5)
    assert err < 0.1
    assert s["fault_updates"] == 0  # the slip alone, no fault window
    err, _ = _heading_error(world, tmp_path / "plain", 0.0)
    assert err > 0.5
    err, _ = _heading_error(world, tmp_path / "matched", 0.0, "match")
    assert err < 0.5
