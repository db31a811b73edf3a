"""The omnidirectional odometry model (``motion.model: omni``, ROS AMCL's omni model) and the run's choice of it
(``motion.sideways``): sampler against closed form, what a step sideways does to each model, and the odometry's
sideways share."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from mcl.motion import (SIDEWAYS_OMNI, FaultProposal, OdometryMotionModel, OmniMotionModel, log_motion_model_omni,
                        motion_model_omni, motion_model_with_map, omni_deltas, omni_sigmas, sideways_share)
from tests.test_motion_density import X0, box_grid, chi2_samples_vs_density


def cfg(noise_form="variance", noise="normal", alphas=(0.05, 0.02, 0.05, 0.02), strafe=0.03, model="omni"):
    return SimpleNamespace(model=model, noise_form=noise_form, noise=noise, max_tries=10, robot_radius=0.0,
                           map_rejection=False, alpha_strafe=strafe, **{f"alpha{k + 1}": a for k, a in enumerate(alphas)})


# a step of 0.25 m at 70 degrees left of the heading, turning 0.15 rad: a base crabbing while it turns
ODOM = (np.array([1.0, 2.0, 0.3]), np.array([1.0 + 0.25 * math.cos(0.3 + 1.22), 2.0 + 0.25 * math.sin(0.3 + 1.22),
                                             0.45]))


def ideal():
    bearing, trans, rot = omni_deltas(*ODOM)
    h = X0[2] + bearing
    return np.array([X0[0] + trans * math.cos(h), X0[1] + trans * math.sin(h), X0[2] + rot])


def test_deltas_and_sigmas():
    bearing, trans, rot = omni_deltas(*ODOM)
    assert (bearing, trans, rot) == pytest.approx((1.22, 0.25, 0.15))
    # under 1 cm the direction of travel is noise: bearing 0, as rot1 (ROT1_MIN_TRANS)
    assert omni_deltas((0, 0, 0.2), (0.005, 0.005, 0.5))[0] == 0.0
    st, ss, sr = omni_sigmas(0.25, 0.15, cfg())
    assert st == pytest.approx(math.sqrt(0.05 * 0.25 ** 2 + 0.02 * 0.15 ** 2))
    assert ss == pytest.approx(math.sqrt(0.03 * 0.25 ** 2 + 0.02 * 0.15 ** 2))
    assert sr == pytest.approx(math.sqrt(0.05 * 0.15 ** 2 + 0.02 * 0.25 ** 2))
    assert omni_sigmas(0.25, -0.15, cfg("std")) == pytest.approx((0.05 * 0.25 + 0.02 * 0.15, 0.03 * 0.25 + 0.02 * 0.15,
                                                                  0.05 * 0.15 + 0.02 * 0.25))


@pytest.mark.parametrize("noise", ["normal", "triangular"])
@pytest.mark.parametrize("noise_form", ["variance", "std"])
def test_omni_density_integrates_to_one_over_poses(noise, noise_form):
    # the noises map onto the pose by a rotation and a shift: no Jacobian (a grid sum; 1 % covers the grid)
    c = cfg(noise_form, noise, alphas=(0.05, 0.02, 0.05, 0.02) if noise_form == "variance" else (0.1, 0.08, 0.1, 0.05),
            strafe=0.03 if noise_form == "variance" else 0.1)
    pts, vol = box_grid(ideal(), (0.3, 0.3, 0.35), 161)
    total = motion_model_omni(pts, ODOM, X0, c).sum() * vol
    assert total == pytest.approx(1.0, abs=0.01), total


@pytest.mark.parametrize("noise_form", ["variance", "std"])
def test_omni_sampler_matches_the_closed_form(noise_form):
    c = cfg(noise_form, alphas=(0.05, 0.02, 0.05, 0.02) if noise_form == "variance" else (0.1, 0.08, 0.1, 0.05),
            strafe=0.03 if noise_form == "variance" else 0.1)
    n = 1_000_000
    s, ok, _ = OmniMotionModel(c).sample(np.tile(X0[:, None], (1, n)), *ODOM, np.random.default_rng(42))
    p, _ = chi2_samples_vs_density(s, lambda pts: log_motion_model_omni(pts, ODOM, X0, c), ideal())
    assert p > 1e-3, p
    # the same test catches a density whose strafe noise is 10 % off (so it can fail)
    c2 = cfg(noise_form, alphas=tuple(getattr(c, f"alpha{k}") for k in range(1, 5)), strafe=1.21 * c.alpha_strafe)
    p2, _ = chi2_samples_vs_density(s, lambda pts: log_motion_model_omni(pts, ODOM, X0, c2), ideal())
    assert p2 < 1e-10, p2


def test_a_step_sideways_turns_the_omni_particles_little_and_the_odometry_models_much():
    # A base strafing 0.2 m to its left without turning. Table 5.6 reads rot1 = pi/2 and draws its rotation noise
    # from it (sigma_rot1 = sqrt(alpha1 (pi/2)^2 + alpha2 t^2), and rot2 = -pi/2 again): each particle's heading gets
    # about sqrt(2) x 0.35 rad. The omni model's heading noise is sqrt(alpha2) t. 100,000 draws: the stds are
    # within 1 % of these (their sampling error is 0.2 %).
    step = (np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.2, 0.0]))
    c = cfg(alphas=(0.05, 0.05, 0.05, 0.05), strafe=0.05)
    x = np.zeros((3, 100_000))
    omni, _, _ = OmniMotionModel(c).sample(x, *step, np.random.default_rng(1))
    odo, _, _ = OdometryMotionModel(cfg(model="odometry", alphas=(0.05, 0.05, 0.05, 0.05))).sample(
        x, *step, np.random.default_rng(1))
    assert np.std(omni[2]) == pytest.approx(math.sqrt(0.05) * 0.2, rel=0.01)
    rot1_sigma = math.sqrt(0.05 * (math.pi / 2) ** 2 + 0.05 * 0.2 ** 2)
    assert np.std(odo[2]) == pytest.approx(math.sqrt(2) * rot1_sigma, rel=0.01)
    # both move the cloud 0.2 m to the left on average; across the step (x) the omni cloud spreads by the strafe std
    assert np.mean(omni[1]) == pytest.approx(0.2, abs=0.002) and np.std(omni[0]) == pytest.approx(
        math.sqrt(0.05) * 0.2, rel=0.01)


def test_the_map_kernel_moves_as_the_plain_one_and_rejects_off_the_free_space():
    from mcl.maps import OccupancyGrid

    occ = np.zeros((40, 40), dtype=np.int8)
    occ[:, 25:] = 100  # a wall from x = 1.25 m on
    grid = OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))
    c = cfg()
    model = OmniMotionModel(c)
    x = np.tile(np.array([[0.9], [1.0], [0.0]]), (1, 5000))
    step = (np.zeros(3), np.array([0.0, -0.25, 0.1]))  # to its right, turning a little
    plain, _, _ = model.sample(x, *step, np.random.default_rng(3))
    everywhere = np.ones_like(occ, dtype=np.uint8)
    mapped, ok, tries = model.sample(x, *step, np.random.default_rng(3), allowed=everywhere, grid=grid)
    np.testing.assert_array_equal(mapped, plain)
    assert ok.all() and tries == 1.0
    # a step sideways into the wall's side: every pose that landed is left of x = 1.25 m, some redrawn
    step = (np.array([0.0, 0.0, math.pi / 2]), np.array([0.3, 0.0, math.pi / 2]))  # facing +y, strafing to +x
    x = np.tile(np.array([[1.0], [1.0], [math.pi / 2]]), (1, 5000))
    free = (occ == 0).astype(np.uint8)
    moved, ok, tries = model.sample(x, *step, np.random.default_rng(4), allowed=free, grid=grid)
    assert tries > 1.0 and ok.mean() > 0.5
    assert np.all(moved[0, ok] < 1.25)
    # the density with the map: zero beyond the wall
    p = motion_model_with_map(moved[:, :200], step, x[:, 0], grid, cfg(), allowed=free)
    assert np.all(p[moved[0, :200] >= 1.25] == 0.0) and p.sum() == pytest.approx(1.0)


def test_fault_weights_are_the_ratio_of_the_mixture_densities():
    # as tests/test_motion_density.py's for the other models: the sampler's importance weight of each particle is
    # p_f / q from the closed form, to rounding (capped: the translation dimensions are trans and strafe, the turn
    # the heading's)
    c = cfg()
    st, ss, sr = omni_sigmas(*omni_deltas(*ODOM)[1:], c)
    for fault in (FaultProposal(prob=1e-3, share=0.05, scale=10.0),
                  FaultProposal(prob=1e-3, share=0.05, scale=10.0, turn_max=3 * sr, shift_max=3 * st)):
        n = 20_000
        lw = np.empty(n)
        s, _, _ = OmniMotionModel(c).sample(np.tile(X0[:, None], (1, n)), *ODOM, np.random.default_rng(5), fault=fault,
                                            log_weight=lw)
        expected = (log_motion_model_omni(s, ODOM, X0, c, fault=fault)
                    - log_motion_model_omni(s, ODOM, X0, c, fault=FaultProposal(fault.share, fault.share, fault.scale,
                                                                                  fault.turn_max, fault.shift_max)))
        np.testing.assert_allclose(lw, expected, atol=1e-6)
        if not fault.turn_max:  # uncapped: about share of the draws are far out in the 10x component, at prob / share
            far = lw < math.log(0.1)
            assert 0.035 < far.mean() < 0.065, far.mean()
            np.testing.assert_allclose(np.median(lw[far]), math.log(fault.prob / fault.share), atol=0.05)


# ----------------------------------------------------------------------------- sideways share


def _arcs(rng, n=400, step=0.1):
    """A differential drive's odometry: arcs of random curvature, turns on the spot and stretches backwards."""
    poses = [np.zeros(3)]
    for k in range(n):
        x, y, th = poses[-1]
        v = step * (-1.0 if (k // 50) % 4 == 3 else 1.0)
        w = rng.uniform(-0.8, 0.8) if k % 30 else 2.0  # now and then a turn on the spot (v 0 below)
        if k % 30 == 0:
            v = 0.0
        poses.append(np.array([x + v * math.cos(th + w / 2), y + v * math.sin(th + w / 2), th + w]))
    return np.array(poses)


def test_sideways_share_tells_a_differential_drive_from_an_omnidirectional_base():
    rng = np.random.default_rng(0)
    diff = _arcs(rng)
    share, travel = sideways_share(diff)
    assert share < 0.01 and travel == pytest.approx(np.hypot(*np.diff(diff[:, :2], axis=0).T).sum())
    # the same path, 50 Hz and a heading that leaves it by 30 degrees and more: an omnidirectional base
    crab = diff.copy()
    crab[:, 2] += 0.6 * np.sin(np.arange(crab.shape[0]) / 15.0) + 0.3
    assert sideways_share(crab)[0] > 2 * SIDEWAYS_OMNI
    # a base strafing straight sideways reads 1, at 50 Hz (2 mm a message) as at 5 Hz
    side = np.zeros((3000, 3))
    side[:, 1] = np.arange(3000) * 0.002
    assert sideways_share(side)[0] == pytest.approx(1.0)
    # an odometry reset (back to 0, 0, 0 from 30 m away) or a glitch is no travel, and no chord spans it
    reset = np.vstack([diff, diff])  # the same drive again from the origin
    assert np.hypot(*(diff[-1, :2] - diff[0, :2])) > 5.0
    assert sideways_share(reset)[0] < 0.01 and sideways_share(reset)[1] == pytest.approx(2 * travel, rel=0.01)
    # too little travel to tell: 0
    assert sideways_share(side[:1000]) == (0.0, pytest.approx(1.998))


# ----------------------------------------------------------------------------- the run's choice (motion.sideways)


def test_a_run_takes_the_omni_model_for_an_odometry_that_moves_sideways(tmp_path):
    # A generated corridor (40 s, seed 3) driven by an omnidirectional base whose heading leaves its travel by up to
    # 90 degrees (mcl simulate --holonomic 90), tracked from its start, seed 1. The default sees 54 % of the travel
    # go sideways and runs the omni model: 0.13 m RMSE. Kept on Table 5.6 (motion.sideways: keep, the baseline's),
    # every sideways step turns the cloud by rot1's noise and the run is lost down the corridor (6.4 m). Bounds: the
    # omni run under 0.25 m and max 0.6 m; the kept one over 1 m.
    from mcl.config import PROJECT_ROOT, load_config
    from mcl.runner import run
    from mcl.simulate import simulate
    from mcl.trajectory import read_tum

    simulate(tmp_path / "w", kind="corridor", seed=3, duration=40, holonomic=math.pi / 2)
    t, poses = read_tum(tmp_path / "w" / "truth.tum")
    sets = [f"map={tmp_path / 'w' / 'map.yaml'}", f"log={tmp_path / 'w' / 'log.clf'}",
            f"truth={tmp_path / 'w' / 'truth.tum'}", "rerun.mode=off",
            f"filter.initial_pose=[{poses[0, 0]},{poses[1, 0]},{poses[2, 0]}]"]
    said = []
    omni = run(load_config(PROJECT_ROOT / "configs" / "default.yaml", sets), tmp_path / "omni", progress=False,
               echo=said.append)
    warn = [m for m in said if "goes across the robot's heading" in m]
    assert len(warn) == 1 and warn[0].startswith(f"mcl: warning: {tmp_path / 'w' / 'log.clf'}: 54% of the odometry's "
                                                 "33 m goes across the robot's heading: an omnidirectional base (or an "
                                                 "odometry that jitters across it, as laser or visual odometry does), "
                                                 "run with motion.model omni"), said
    assert omni["motion_model"] == "omni" and omni["odometry_sideways"] > 0.5
    assert "model: omni" in (tmp_path / "omni" / "config.yaml").read_text()  # the run as it was made
    keep = run(load_config(PROJECT_ROOT / "configs" / "default.yaml", [*sets, "motion.sideways=keep"]),
               tmp_path / "keep", progress=False, echo=lambda *_: None)
    assert keep["motion_model"] == "odometry"
    said = []
    run(load_config(PROJECT_ROOT / "configs" / "default.yaml", [*sets, "motion.model=velocity", "filter.particles=500",
                                                                 "filter.kld=false"]),
        tmp_path / "velocity", progress=False, echo=said.append)
    assert any("the velocity model moves along the heading and has no strafe" in m for m in said), said
    assert omni["eval"]["ate_rmse"] < 0.25 and omni["eval"]["ate_max"] < 0.6, omni["eval"]
    assert keep["eval"]["ate_rmse"] > 1.0, keep["eval"]
    # the same drive as a bag (its /odom at the scans): the same choice
    from mcl.datasets.bagwrite import write_scans
    from mcl.datasets.carmen import read_carmen

    write_scans(tmp_path / "w.mcap", read_carmen(tmp_path / "w" / "log.clf").scans)
    bag = run(load_config(PROJECT_ROOT / "configs" / "default.yaml", [*sets[:1], f"bag={tmp_path / 'w.mcap'}",
                                                                       "log=null", *sets[2:]]),
              tmp_path / "bag", progress=False, echo=lambda *_: None)
    assert bag["motion_model"] == "omni" and bag["eval"]["ate_rmse"] < 0.25, bag["eval"]


def test_simulate_holonomic_drives_the_same_path_with_the_heading_off_the_travel(tmp_path):
    from mcl.datasets.carmen import read_carmen
    from mcl.simulate import simulate
    from mcl.trajectory import read_tum

    simulate(tmp_path / "d", kind="office", seed=5, duration=30)
    simulate(tmp_path / "h", kind="office", seed=5, duration=30, holonomic=math.radians(45))
    (_, d), (_, h) = read_tum(tmp_path / "d" / "truth.tum"), read_tum(tmp_path / "h" / "truth.tum")
    np.testing.assert_array_equal(h[:2], d[:2])  # the same path
    off = np.abs((h[2] - d[2] + np.pi) % (2 * np.pi) - np.pi)
    assert 0.3 < off.max() <= math.radians(45) + 1e-9, off.max()
    # the odometry moves sideways as the truth does; the differential drive's does not
    assert sideways_share(h.T)[0] > 0.2 and sideways_share(read_carmen(tmp_path / "h" / "log.clf").odometry[:, 1:4])[
        0] > 0.2
    assert sideways_share(read_carmen(tmp_path / "d" / "log.clf").odometry[:, 1:4])[0] < 0.01


SHARED = __import__("pathlib").Path(__file__).parents[2] / "shared" / "data"


@pytest.mark.skipif(not SHARED.is_dir(), reason=f"{SHARED} absent (see ../shared/data/README)")
def test_no_shared_log_reads_as_an_omnidirectional_base():
    # differential drives all (Pioneers, a B21r): 0.002-0.014 of their travel reads sideways (odometry noise and a
    # turn between two readings), a seventh of SIDEWAYS_OMNI at most; a run keeps Table 5.6 on each
    from mcl.datasets.carmen import read_carmen

    logs = sorted(SHARED.glob("*/log.clf"))
    assert len(logs) >= 8
    for path in logs:
        log = read_carmen(path)
        odo = log.odometry[:, 1:4] if len(log.odometry) else np.array([s.odom for s in log.scans])
        share, travel = sideways_share(odo)
        assert travel > 100 and share < 0.02, (path, share, travel)
