"""Degenerate input: no NaN reaches the particles, each kind warns once, the filter recovers, the summary counts.

Kinds (mcl.filter.EVENT_KINDS): every weight zero, NaN/inf ranges, zero-length scans, odometry jumps (and
non-finite odometry), time running backwards. Unit tests drive ParticleFilter directly on a walled square;
the end-to-end test feeds a doctored copy of the bundled demo log through the runner.
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from mcl.config import PROJECT_ROOT, load_config
from mcl.filter import EVENT_KINDS, Control, ParticleFilter
from mcl.maps import OccupancyGrid

DEMO = PROJECT_ROOT / "data" / "demo"


def _grid():
    occ = np.zeros((200, 200), dtype=np.int8)  # 10 m x 10 m, walls around, a pillar off-centre
    occ[:3, :] = occ[-3:, :] = occ[:, :3] = occ[:, -3:] = 100
    occ[120:140, 60:80] = 100
    return OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))


def _pf(*overrides, n=2000):
    cfg = load_config(None, [f"filter.particles={n}", "filter.kld=false", "filter.recovery=false",
                             "motion.robot_radius=0.1", *overrides])
    pf = ParticleFilter(cfg, _grid())
    pf.init_gaussian((5.0, 3.0, 0.2), (0.05, 0.05, 0.02))
    return pf


def _scan(ranges, t=1.0):
    r = np.asarray(ranges, dtype=np.float64)
    return SimpleNamespace(ranges=r, angles=np.linspace(-math.pi / 2, math.pi / 2, r.size), max_range=None, t=t)


def _true_scan(pf, pose=(5.0, 3.0, 0.2), n=181):
    from mcl.kernels.raycast import cast_rays

    angles = np.linspace(-math.pi / 2, math.pi / 2, n)
    out = np.empty((1, n))
    g = pf.grid
    cast_rays(np.array(pose, dtype=float).reshape(3, 1), angles, np.ascontiguousarray(g.occupied), g.origin[0],
              g.origin[1], g.resolution, 30.0, out)
    return _scan(out[0])


def _ok(pf):
    assert np.isfinite(pf.particles).all()
    assert not np.isnan(pf.logw).any() and np.isfinite(pf.weights).all()
    assert pf.weights.sum() == pytest.approx(1.0)


def test_all_weights_zero_respreads_around_the_last_estimate_and_warns_once():
    pf = _pf()
    obs = pf.prepare(_true_scan(pf), np.zeros(3))
    pf.step(None, obs)  # a good update: the estimate is near (5, 3)
    # a scan no pose explains
    pf.sensor.log_likelihood = lambda p, o, out=None, searching=False: np.full(p.shape[1], -np.inf)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        infos = [pf.step(None, obs) for _ in range(2)]
    assert all(i.degenerate for i in infos) and all("degenerate_weights" in i.events for i in infos)
    assert pf.events["degenerate_weights"] == 2
    assert sum("every particle weight is zero" in str(w.message) for w in rec) == 1  # once per kind
    _ok(pf)
    # re-spread (second time: twice respread_std = 1 m) around (5, 3), not reinitialised over the map
    mean = pf.particles[:2].mean(axis=1)
    np.testing.assert_allclose(mean, [5.0, 3.0], atol=0.15)  # 2000 draws, std 1 m: 4.5 standard errors
    assert 0.7 < pf.particles[0].std() < 1.3
    assert np.isfinite(infos[-1].mean).all()


def test_degenerate_three_times_in_a_row_reinitialises_globally():
    pf = _pf()
    pf.step(None, pf.prepare(_true_scan(pf), np.zeros(3)))
    pf.sensor.log_likelihood = lambda p, o, out=None, searching=False: np.full(p.shape[1], -np.inf)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(4):
            pf.step(None, np.zeros((2, 1)))
    _ok(pf)
    # uniform over the free 10 m x 10 m square: std of x about 10 / sqrt(12) = 2.8 m
    assert pf.particles[0].std() > 2.3 and pf.particles[1].std() > 2.3
    assert pf.events["degenerate_weights"] == 4


def test_real_likelihood_that_underflows_everywhere_recovers():
    # The beam model with z_hit alone: a scan 2.15 m or more short of every wall gives exp(-0.5 (2.15 / 0.05)^2)
    # = 0, log p = -inf, for every particle. (The likelihood field took z_rand = 0 here until its table took those
    # cells in log space: test_sensors.py, "stays finite far from walls".)
    pf = _pf("sensor.model=beam", "sensor.beam.z_hit=1.0", "sensor.beam.z_short=0.0", "sensor.beam.z_max=0.0",
             "sensor.beam.z_rand=0.0", "sensor.beam.sigma_hit=0.05")
    bad = pf.prepare(_scan(np.full(181, 0.7)), np.zeros(3))  # a 0.7 m circle: no wall there from (5, 3)
    assert np.isneginf(pf.sensor.log_likelihood(pf.particles, bad)).all()
    good = pf.prepare(_true_scan(pf), np.zeros(3))
    pf.step(None, good)  # an estimate to re-spread around
    with pytest.warns(RuntimeWarning, match="every particle weight is zero"):
        info = pf.step(None, bad)
    assert info.degenerate and pf.events["degenerate_weights"] == 1
    _ok(pf)
    # then good scans bring it back to the pose
    assert pf.particles[0].std() == pytest.approx(0.5, rel=0.1)  # re-spread with equal weights, not collapsed
    info = pf.step(None, good)
    # one sharp update (sigma_hit 0.05, no motion noise) picks the best of 2000 particles spread 0.5 m: within
    # 0.25 m (measured 0.17 with the beam model, which weighs the heading's error as much; 0.08 with the field)
    assert math.hypot(info.mean[0] - 5.0, info.mean[1] - 3.0) < 0.25


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_and_infinite_ranges_are_dropped_and_counted(bad):
    pf = _pf()
    scan = _true_scan(pf)
    scan.ranges[::3] = bad
    with pytest.warns(RuntimeWarning, match="NaN or infinite ranges"):
        obs = pf.prepare(scan, np.zeros(3))
    assert np.isfinite(obs).all() and 0 < obs.shape[1] < 60
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the second such scan does not warn again
        obs2 = pf.prepare(scan, np.zeros(3))
    assert pf.events["nan_ranges"] == 2
    info = pf.step(None, obs2)
    _ok(pf)
    assert math.hypot(info.mean[0] - 5.0, info.mean[1] - 3.0) < 0.1


@pytest.mark.parametrize("ranges", [[], [np.nan] * 181, [0.0] * 181])
def test_empty_scans_predict_only(ranges):
    pf = _pf()
    with pytest.warns(RuntimeWarning) as rec:
        obs = pf.prepare(_scan(ranges), np.zeros(3))
    assert sum("no usable reading" in str(w.message) for w in rec) == 1
    assert obs is None and pf.events["empty_scans"] == 1
    before = pf.particles.copy()
    info = pf.step(Control(np.zeros(3), np.array([0.3, 0.0, 0.0]), dt=0.2), obs)
    _ok(pf)
    assert info.events in (("empty_scans",), ("empty_scans", "nan_ranges"), ("nan_ranges", "empty_scans"))
    assert pf.particles[0].mean() - before[0].mean() == pytest.approx(0.3 * math.cos(0.2), abs=0.02)  # moved


def test_odometry_jump_hedges_half_the_particles_stay_and_the_scan_decides():
    # the book's noise for the 10 m step (motion.noise_step 0): with the default's 0.3 m random walk it is 0.4 m
    # along and 0.4 rad, and the whole moving half lands off this 10 m map (weight zero)
    pf = _pf("motion.noise_step=0")
    with pytest.warns(RuntimeWarning, match="odometry jumped 10.00 m"):
        info = pf.step(Control(np.zeros(3), np.array([10.0, 0.0, 0.0]), dt=0.2), None)
    assert pf.events["odometry_jumps"] == 1 and info.events == ("odometry_jumps",)
    _ok(pf)
    stay, moved = pf.particles[:, 0::2], pf.particles[:, 1::2]
    np.testing.assert_allclose(stay[:2].mean(axis=1), [5.0, 3.0], atol=0.05)  # 1000 particles, std 0.5 m: 3 s.e.
    assert 0.35 < stay[0].std() < 0.65  # re-spread by respread_std (0.5 m) where they were
    # the other half took the step, with the motion model's noise for 10 m (2.2 m along, 2.2 rad): most of it
    # lands off this 10 m map and gets weight zero; the half that stayed keeps its weights
    assert np.median(np.hypot(moved[0] - 5.0, moved[1] - 3.0)) > 3.0
    assert np.isneginf(pf.logw[1::2]).mean() > 0.5 and np.isfinite(pf.logw[0::2]).all()
    # the scan then decides. 0.25 m: the repeated scans move nothing, so the cloud does not diffuse and the estimate
    # is as good as the nearest of the ~1,000 poses spread over 0.5 m and 0.5 rad; the other half is 10 m off
    good = pf.prepare(_true_scan(pf), np.zeros(3))
    for _ in range(4):
        info = pf.step(None, good)
    assert math.hypot(info.mean[0] - 5.0, info.mean[1] - 3.0) < 0.25


def test_a_long_step_that_was_real_motion_is_followed():
    # a log with a scan every few metres: the 2.5 m step is over max_odom_step, so the filter hedges, and the
    # scan, taken where the robot went, picks the half that took the step
    pf = _pf("filter.max_odom_ratio=0")
    with pytest.warns(RuntimeWarning, match="odometry jumped 2.50 m"):
        pf.step(Control(np.array([5.0, 3.0, 0.2]), np.array([5.0 + 2.5 * math.cos(0.2), 3.0 + 2.5 * math.sin(0.2),
                                                             0.2]), dt=0.2), None)
    there = (5.0 + 2.5 * math.cos(0.2), 3.0 + 2.5 * math.sin(0.2), 0.2)
    obs = pf.prepare(_true_scan(pf, there), np.zeros(3))
    info = pf.step(None, obs)
    for _ in range(3):
        info = pf.step(None, obs)
    # 0.25 m as above (the half that stayed is 2.5 m off)
    assert math.hypot(info.mean[0] - there[0], info.mean[1] - there[1]) < 0.25, info.mean


def test_a_step_is_a_jump_only_when_longer_than_ratio_times_the_longest_recent_step():
    from mcl.degenerate import InputGuard

    def step(guard, length):
        return guard.check_control(Control(np.zeros(3), np.array([length, 0.0, 0.0]), dt=0.2))[1] is None

    g = InputGuard(max_odom_step=2.0, max_odom_ratio=3.0)
    assert g.jump_bound() == 2.0  # no history: the fixed bound
    assert not step(g, 1.2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert step(g, 3.7)  # over 3 x 1.2 m
        assert g.events["odometry_jumps"] == 1
        assert not step(g, 3.5)  # 3 x 1.2 = 3.6 m: motion; the longest step is now 3.5 m
    assert g.jump_bound() == pytest.approx(10.5)
    for _ in range(InputGuard.JUMP_HISTORY):  # the long steps leave the history: back to the fixed bound
        assert not step(g, 0.1)
    assert g.jump_bound() == 2.0
    fixed = InputGuard(max_odom_step=2.0, max_odom_ratio=0.0)
    assert not step(fixed, 1.2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert step(fixed, 2.1)


def test_a_long_step_at_the_robots_speed_is_motion_and_a_glitch_is_not():
    # A laser silent for 8 s: the next scan's odometry is 6 m on, at the 0.8 m/s the robot drove; a glitch moves
    # as far in one scan period (30 m/s). The time is the scan's since the previous scan, used or gated: a robot
    # that stood still (gated) for a minute and then jumps 6 m between two scans 0.2 s apart glitched.
    from mcl.degenerate import InputGuard

    def jump(guard, length, dt, dt_scan=None):
        c = Control(np.zeros(3), np.array([length, 0.0, 0.0]), dt=dt, dt_scan=dt_scan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return guard.check_control(c)[1] is None

    def driving(speed_limit=2.0, speed=0.8):
        g = InputGuard(max_odom_step=2.0, max_odom_ratio=3.0, max_odom_speed=speed_limit)
        for _ in range(10):
            assert not jump(g, speed * 0.2, 0.2)
        return g

    g = driving()
    assert not jump(g, 6.0, 8.0)
    assert g.jump_bound() == 2.0  # the long step's length stays out of the history (else 18 m)
    assert jump(g, 6.0, 0.2)
    assert jump(driving(), 6.0, 60.0, dt_scan=0.2)
    assert not jump(driving(), 6.0, 0.2, dt_scan=8.0)  # the time is the scan's
    assert jump(driving(speed_limit=0.0), 6.0, 8.0)  # off: the length bounds alone
    assert jump(driving(), 6.0, 8.0, dt_scan=0.01)  # stamps a few ms apart say nothing of a speed
    # a fast robot (1.5 m/s) silent for 3 s: 4.5 m at 1.5 m/s, within 3 x its own speed, though over 2 m/s
    fast = driving(speed=1.5)
    assert not jump(fast, 4.5, 3.0) and not jump(fast, 12.0, 3.0) and jump(fast, 14.0, 3.0)


def test_a_long_step_back_to_the_odometrys_origin_is_a_restart_whatever_its_speed():
    # A sparse log (a scan every 5 s) whose base driver restarted between two scans: the odometry goes from
    # (6.1, -4.9) back to 0 0 0, 7.8 m at 1.6 m/s, a speed the robot could drive, so the speed bound takes it as
    # motion (a hunt's intel_lab: 9.2 m off). Ending within RESTART_M of the origin makes it a jump; the same step
    # ending elsewhere stays motion, and a short step to the origin is motion too.
    from mcl.degenerate import InputGuard

    def jump(guard, start, end, dt=4.92):
        c = Control(np.array(start, dtype=float), np.array(end, dtype=float), dt=dt)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return guard.check_control(c)[1] is None

    def guard():
        g = InputGuard(max_odom_step=2.0, max_odom_ratio=3.0, max_odom_speed=2.0)
        for _ in range(10):
            assert not jump(g, [0.0, 0.0, 0.0], [0.3, 0.0, 0.0], dt=1.0)
        return g

    start = [6.09, -4.91, -2.58]
    assert jump(guard(), start, [0.0, 0.0, 0.0])
    assert jump(guard(), start, [0.3, 0.35, 0.5])  # the motion since the restart: 0.46 m from the origin
    assert not jump(guard(), start, [0.5, 0.4, 0.5])  # 0.64 m from it: a drive over a scan gap
    assert not jump(guard(), start, [12.0, -1.0, 0.0])  # as long (7.6 m), elsewhere: a drive
    assert not jump(guard(), [1.5, 0.0, 0.0], [0.0, 0.0, 0.0])  # within the length bound: a step like any other
    g = guard()
    with pytest.warns(RuntimeWarning, match="within 0.5 m of the odometry's origin"):
        g.check_control(Control(np.array(start), np.zeros(3), dt=4.92))


@pytest.mark.parametrize("odom", [[np.nan, 0.0, 0.0], [0.0, np.inf, 0.0], [0.1, 0.0, np.nan]])
def test_non_finite_odometry_counts_as_a_jump(odom):
    pf = _pf()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pf.step(Control(np.zeros(3), np.array(odom), dt=0.2), None)
    assert pf.events["odometry_jumps"] == 1
    _ok(pf)


@pytest.mark.parametrize("dt", [-0.5, np.nan])
def test_time_backwards_still_applies_the_odometry_step(dt):
    pf = _pf()
    x0 = pf.particles[0].mean()
    with pytest.warns(RuntimeWarning, match="time ran backwards"):
        info = pf.step(Control(np.array([1.0, 1.0, 0.0]), np.array([1.2, 1.0, 0.0]), dt=dt), None)
    assert pf.events["time_backwards"] == 1 and info.events == ("time_backwards",)
    _ok(pf)
    assert pf.particles[0].mean() - x0 == pytest.approx(0.2 * math.cos(0.2), abs=0.02)


def test_every_event_kind_is_counted_from_zero():
    pf = _pf()
    assert set(pf.events) == set(EVENT_KINDS) and not any(pf.events.values())


def _doctor_demo(src: Path, dst: Path) -> dict:
    """The demo log with one of each bad input, cut before the demo's kidnapping (scan 250, 50 s);
    returns what was injected."""
    lines = src.read_text().splitlines(keepends=True)
    out, k = [], -1
    shift = 0.0
    for line in lines:
        f = line.split()
        if f and f[0] in ("ODOM", "FLASER"):
            if f[0] == "FLASER":
                k += 1
                n = int(f[1])
                if k == 240:  # the robot is kidnapped at scan 250: a tracking test stops before
                    break
                if k == 60:  # NaN and inf readings
                    f[2:2 + n:4] = ["nan"] * len(f[2:2 + n:4])
                    f[3:2 + n:7] = ["inf"] * len(f[3:2 + n:7])
                if k == 110:  # a zero-length scan (poses and timestamps kept)
                    f = ["FLASER", "0"] + f[2 + n:]
                    n = 0
                if k == 160:  # time backwards by 0.5 s (as intel_lab's log, by less than a second)
                    f[-3] = f"{float(f[-3]) - 0.5:.6f}"
                    f[-1] = f"{float(f[-1]) - 0.5:.6f}"
                if k == 200:
                    shift = 10.0  # odometry resets 10 m away from here on
                xi = 2 + n
                for j in (xi, xi + 3):
                    f[j] = f"{float(f[j]) + shift:.6f}"
            else:
                f[1] = f"{float(f[1]) + shift:.6f}"
            line = " ".join(f) + "\n"
        out.append(line)
    dst.write_text("".join(out))
    return {"nan_ranges": 1, "empty_scans": 1, "time_backwards": 1, "odometry_jumps": 1, "degenerate_weights": 0}


@pytest.mark.skipif(not (DEMO / "log.clf").is_file(), reason="bundled demo data missing")
@pytest.mark.parametrize("ratio, speed, jumps, motion_jumps", [(3.0, 2.0, 0, "hedge"), (0.0, 2.0, 0, "hedge"),
                                                               (0.0, 0.0, 6, "hedge"), (0.0, 0.0, 6, "match")])
def test_a_log_with_a_scan_every_two_metres_is_tracked(tmp_path, ratio, speed, jumps, motion_jumps):
    # every 24th scan of the demo (before its kidnap at scan 250): 0.5-2.4 m of odometry between scans, as logs
    # with one scan per metre or two have. With max_odom_ratio 3 every step is within 3x the longest recent one
    # and taken as motion; so is every step at 0.5 m/s over the 4.8 s between scans (max_odom_speed 2 m/s); with
    # the fixed 2 m bound alone, the 6 steps over it are hedged and the scan picks the half that moved
    # (motion.jumps match only takes a jump faster than 5 m/s from scan matching).
    # (Re-spreading in place, the rule before the hedge, was lost at the first of them.)
    import yaml

    from mcl.runner import run
    from mcl.trajectory import read_tum

    lines, k = [], 0
    for line in (DEMO / "log.clf").read_text().splitlines(True):
        if line.startswith("FLASER"):
            if k % 24 == 0 and k < 240:
                lines.append(line)
            k += 1
        elif not line.startswith("ODOM"):
            lines.append(line)
    (tmp_path / "thin.clf").write_text("".join(lines))
    start = yaml.safe_load((DEMO / "sim.yaml").read_text())["start_pose"]
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"log={tmp_path / 'thin.clf'}", "rerun.mode=off", "filter.global_localization=false",
        f"filter.initial_pose={start}", "filter.particles=5000", f"filter.max_odom_ratio={ratio}",
        f"filter.max_odom_speed={speed}", f"motion.jumps={motion_jumps}"])
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        s = run(cfg, tmp_path / "out", progress=False, echo=lambda *_: None)
    matched = sum(w["cause"] == "jump" for w in s.get("odometry_stalls", []))
    assert s["updates"] == 10, s
    # a step at 0.5 m/s is not matched (motion.jumps match): no robot's, yet scans 4.8 s apart match 1-2 m off
    assert (s["events"]["odometry_jumps"], matched) == (jumps, 0), s["events"]
    t, est = read_tum(tmp_path / "out" / "trajectory.tum")
    tt, truth = read_tum(DEMO / "truth.tum")
    ref = truth[:, np.searchsorted(tt, t - 1e-6)]
    err = np.hypot(est[0] - ref[0], est[1] - ref[1])
    assert err.max() < 0.3, err.round(2)  # tracked: 0.03-0.14 m measured over seeds 1-3


def _restarted(line: str, at) -> str:
    """A FLASER line whose odometry restarted from 0 0 0 at the odometry pose ``at``: its laser pose and its
    odometry pose (the two x y theta after the ranges) taken into the new frame."""
    from mcl.estimate import compose, inverse

    f = line.split()
    n = int(f[1])
    for k in (2 + n, 2 + n + 3):
        pose = compose(inverse(np.asarray(at)), np.array([float(v) for v in f[k:k + 3]]))
        f[k:k + 3] = [f"{v:.6f}" for v in pose]
    return " ".join(f) + "\n"


@pytest.mark.skipif(not (DEMO / "log.clf").is_file(), reason="bundled demo data missing")
@pytest.mark.parametrize("restart_m", [0.5, 0.0])
def test_a_sparse_log_whose_odometry_restarts_is_tracked(tmp_path, monkeypatch, restart_m):
    # every 12th scan of the demo (2.4 s apart, up to 1.2 m of odometry between them), the base driver restarting
    # from 0 0 0 three scans (0.6 s) before the fifth: its odometry steps 2.7 m back to near the origin at about
    # 1 m/s, a speed the robot could drive. Taken as motion (RESTART_M 0, the rule before) the cloud is carried metres
    # off; as a restart (InputGuard.RESTART_M) the scans place the robot, matched from the velocity before it.
    import yaml

    from mcl.degenerate import InputGuard
    from mcl.runner import run
    from mcl.trajectory import read_tum

    monkeypatch.setattr(InputGuard, "RESTART_M", restart_m)
    raw = (DEMO / "log.clf").read_text().splitlines(True)
    scans = [line for line in raw if line.startswith("FLASER")]
    lines, at = [line for line in raw if not line.startswith(("FLASER", "ODOM"))], None
    for k, line in enumerate(scans[:240]):
        if k == 4 * 12 - 3:
            f = line.split()
            at = [float(v) for v in f[2 + int(f[1]) + 3:2 + int(f[1]) + 6]]
        if k % 12 == 0:
            lines.append(line if at is None else _restarted(line, at))
    (tmp_path / "thin.clf").write_text("".join(lines))
    start = yaml.safe_load((DEMO / "sim.yaml").read_text())["start_pose"]
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"log={tmp_path / 'thin.clf'}", "rerun.mode=off", "filter.global_localization=false",
        f"filter.initial_pose={start}", "filter.particles=5000"])
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        s = run(cfg, tmp_path / "out", progress=False, echo=lambda *_: None)
    assert s["updates"] == 20, s
    t, est = read_tum(tmp_path / "out" / "trajectory.tum")
    tt, truth = read_tum(DEMO / "truth.tum")
    ref = truth[:, np.searchsorted(tt, t - 1e-6)]
    err = np.hypot(est[0] - ref[0], est[1] - ref[1])
    if restart_m:
        # 0.04-0.07 m at every scan (seed 1); the step matched 1.18 m, as driven
        assert err.max() < 0.3, err.round(2)
        assert [w["cause"] for w in s["odometry_stalls"]] == ["jump"]
    else:
        assert err.max() > 1.0, err.round(2)  # 3.3-4.2 m for three scans


@pytest.mark.skipif(not (DEMO / "log.clf").is_file(), reason="bundled demo data missing")
@pytest.mark.parametrize("motion_jumps", ["hedge", "match"])
def test_runner_counts_every_event_and_keeps_tracking(tmp_path, motion_jumps):
    import yaml

    from mcl.runner import run
    from mcl.trajectory import read_tum

    expected = _doctor_demo(DEMO / "log.clf", tmp_path / "bad.clf")
    start = yaml.safe_load((DEMO / "sim.yaml").read_text())["start_pose"]
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"log={tmp_path / 'bad.clf'}", "rerun.mode=off", "filter.global_localization=false",
        f"filter.initial_pose={start}", "filter.initial_std=[0.05,0.05,0.05]", "filter.particles=2000",
        "filter.update_min_d=0.0", "filter.update_min_a=0.0", f"motion.jumps={motion_jumps}"])
    said: list[str] = []
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        s = run(cfg, tmp_path / "out", progress=False, echo=said.append)
    if motion_jumps == "match":  # the 10 m odometry reset is taken from scan matching: the filter sees no jump
        expected["odometry_jumps"] = 0
        (jump,) = s["odometry_stalls"]
        assert jump["cause"] == "jump" and jump["odometry"] > 9.5 and jump["matched"] < 0.3, jump
        assert sum("the odometry jumped 1 time " in m for m in said) == 1, said
    else:
        assert "odometry_stalls" not in s
    assert s["events"] == expected
    msgs = [str(w.message) for w in rec if issubclass(w.category, RuntimeWarning)]
    for kind in ("nan_ranges", "empty_scans", "time_backwards", "odometry_jumps"):
        assert sum(f"every {kind} event" in m for m in msgs) == (expected[kind] > 0), kind
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["events"] == expected
    t, poses = read_tum(tmp_path / "out" / "trajectory.tum")
    assert t.size == s["updates"] == s["scans"] and np.isfinite(poses).all()
    # tracked through all of it: the 10 m jump is hedged (the half that took it finds nothing) or matched, the bad
    # scans do not derail the filter
    assert s["eval"]["ate_max"] < 0.5, s["eval"]
    assert s["eval"]["ate_rmse"] < 0.1, s["eval"]


def test_motion_model_output_that_is_not_finite_never_reaches_the_particles():
    pf = _pf()
    real = pf.motion.sample_control

    def broken(particles, control, rng, allowed=None, grid=None, **kw):
        new, ok, tries = real(particles, control, rng, allowed=allowed, grid=grid, **kw)
        new = new.copy()
        new[:, ::7] = np.nan
        return new, ok, tries

    pf.motion.sample_control = broken
    info = pf.step(Control(np.zeros(3), np.array([0.2, 0.0, 0.0]), dt=0.2), pf.prepare(_true_scan(pf), np.zeros(3)))
    _ok(pf)
    assert np.isfinite(info.mean).all()


def test_a_corridor_whose_laser_falls_silent_is_followed_through_the_gaps(tmp_path):
    # A featureless corridor, the laser silent twice for 8 s (mcl simulate --scan-gaps): the next scan comes 6 m on.
    # Hedged as a jump, half the cloud stays behind, and a stretch of corridor that looks the same takes the track
    # (max 6.7 m with max_odom_speed 0); at the robot's speed the step is motion and the odometry carries the cloud
    # over the gap (max 0.44 m measured; 1 m leaves room for the drift along the corridor, which the scans after
    # the gap cannot correct).
    import yaml

    from mcl.runner import run
    from mcl.simulate import simulate
    from mcl.trajectory import read_tum

    world = tmp_path / "world"
    simulate(world, kind="corridor", seed=13, duration=90.0, scan_gaps=2, scan_gap_s=8.0)
    start = yaml.safe_load((world / "sim.yaml").read_text())["start_pose"]
    tt, truth = read_tum(world / "truth.tum")

    def max_error(speed):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
            f"map={world / 'map.yaml'}", f"log={world / 'log.clf'}", "truth=null", "rerun.mode=off",
            f"filter.initial_pose={start}", f"filter.max_odom_speed={speed}"])
        with warnings.catch_warnings(record=True):
            warnings.simplefilter("always")
            s = run(cfg, tmp_path / f"out{speed}", progress=False, echo=lambda *_: None)
        t, est = read_tum(tmp_path / f"out{speed}" / "trajectory.tum")
        assert np.array_equal(t, tt)  # one pose per scan, and no scan inside a gap
        return float(np.max(np.hypot(est[0] - truth[0], est[1] - truth[1]))), s["events"]["odometry_jumps"]

    err, jumps = max_error(2.0)
    assert jumps == 0 and err < 1.0
    err, jumps = max_error(0.0)
    assert jumps == 2 and err > 3.0


def test_a_start_that_is_no_pose_is_refused_before_any_draw():
    # init_gaussian([nan, 10, 0], ...) gave every estimate NaN without a word, init_gaussian(mean, 0.1) an
    # IndexError; the random stream is untouched by a refused start
    cfg = load_config(None, ["filter.particles=100", "filter.kld=false", "filter.recovery=false", "rerun.mode=off"])
    pf = ParticleFilter(cfg, _grid())
    state = pf.rng.bit_generator.state
    for mean, std, said in (([np.nan, 1.0, 0.0], [0.1] * 3, "mean: expected finite numbers"),
                            ([1.0, 1.0, 0.0], 0.1, r"std: expected shape \(3,\)"),
                            ([1.0, 1.0], [0.1] * 3, r"mean: expected shape \(3,\)"),
                            ([1.0, 1.0, 0.0], [0.1, -0.1, 0.1], "std: expected stds >= 0")):
        with pytest.raises(ValueError, match=said):
            pf.init_gaussian(mean, std)
    with pytest.raises(ValueError, match=r"cov: expected shape \(3, 3\)"):
        pf.init_gaussian_cov([1.0, 1.0, 0.0], np.eye(2))
    assert pf.rng.bit_generator.state == state
