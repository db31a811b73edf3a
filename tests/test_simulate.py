"""Simulator: determinism, a collision-free drive, exact scans, odometry noise statistics, log format."""

import argparse
import math
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from scipy.ndimage import binary_dilation

from mcl.datasets.carmen import read_carmen
from mcl.errors import ConfigError
from mcl.kernels.raycast import cast_rays
from mcl.maps import load_map
from mcl.simulate import _odometry, add_arguments, beam_angles, resample_occupancy, run_from_args, simulate
from mcl.trajectory import read_tum

NOISE_FREE = dict(range_sigma=0.0, p_short=0.0, p_max=0.0)


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    summary = simulate(out, seed=4, duration=40.0)
    return out, summary


@pytest.fixture(scope="module")
def exact(tmp_path_factory):
    out = tmp_path_factory.mktemp("exact")
    simulate(out, seed=4, duration=40.0, **NOISE_FREE)
    return out


def test_same_seed_gives_byte_identical_files(sim, tmp_path):
    out, _ = sim
    simulate(tmp_path, seed=4, duration=40.0)
    for name in ("log.clf", "truth.tum", "map.pgm", "map.yaml", "sim.yaml"):
        assert (tmp_path / name).read_bytes() == (out / name).read_bytes(), name


def test_the_noise_drawn_in_blocks_and_the_log_written_in_blocks_are_the_whole_array_draws(sim, tmp_path,
                                                                                            monkeypatch):
    """Blocks of a few readings and a few lines give the log of whole-array draws, byte for byte (the blocks only
    bound the memory of a long run)."""
    import mcl.simulate as s

    exact = np.random.default_rng(0).uniform(0.0, 14.0, (23, 9))
    exact[3, 4] = 20.0  # beyond range_max: a no-return
    ref_rng = np.random.default_rng(5)
    noise, u = ref_rng.standard_normal(exact.shape), ref_rng.random(exact.shape)
    frac = ref_rng.uniform(0.05, 1.0, exact.shape)
    want = exact + 0.02 * noise
    want[u < 0.2] = (exact * frac)[u < 0.2]
    want[(u >= 0.2) & (u < 0.3)] = 12.0
    want[exact >= 12.0] = 12.0
    want = np.clip(want, 0.0, 12.0)
    monkeypatch.setattr(s, "_NOISE_BLOCK", 20)  # two rows a block, the last one short
    got = s._noisy_ranges(exact, np.random.default_rng(5), 0.02, 0.2, 0.1, 12.0)
    assert np.array_equal(got, want)
    monkeypatch.setattr(s, "_NOISE_BLOCK", 1 << 20)
    assert np.array_equal(s._noisy_ranges(exact, np.random.default_rng(5), 0.02, 0.2, 0.1, 12.0), want)

    monkeypatch.setattr(s, "_NOISE_BLOCK", 500)
    monkeypatch.setattr(s, "_LOG_BLOCK_LINES", 3)
    simulate(tmp_path, seed=4, duration=40.0)
    assert (tmp_path / "log.clf").read_bytes() == (sim[0] / "log.clf").read_bytes()


def test_different_seeds_give_different_worlds(sim, tmp_path):
    out, _ = sim
    simulate(tmp_path, seed=5, duration=2.0)
    a = load_map(out / "map.yaml").occupancy
    b = load_map(tmp_path / "map.yaml").occupancy
    assert a.shape == b.shape
    assert np.mean(a != b) > 0.02


def test_world_is_an_asymmetric_walled_floor_plan(sim):
    out, _ = sim
    g = load_map(out / "map.yaml")
    assert g.resolution == 0.05
    assert 18.0 <= g.width * g.resolution <= 26.0 and 13.0 <= g.height * g.resolution <= 20.0
    # unknown all around the outside, walls between unknown and free
    assert g.unknown[0].all() and g.unknown[-1].all() and g.unknown[:, 0].all() and g.unknown[:, -1].all()
    free, unk = g.free, g.unknown
    touch = (free[1:] & unk[:-1]) | (free[:-1] & unk[1:])
    touch2 = (free[:, 1:] & unk[:, :-1]) | (free[:, :-1] & unk[:, 1:])
    assert not touch.any() and not touch2.any()
    assert 0.4 < free.mean() < 0.9
    # no mirror or half-turn symmetry: global localization can tell places apart
    for f in (free[::-1], free[:, ::-1], free[::-1, ::-1]):
        assert np.mean(f != free) > 0.05


def test_truth_path_stays_clear_of_walls(sim):
    out, summary = sim
    g = load_map(out / "map.yaml")
    params = yaml.safe_load((out / "sim.yaml").read_text())
    radius = params["robot"]["radius"]
    t, p = read_tum(out / "truth.tum")
    # check between scan poses too (they are <= 0.1 m apart at 0.5 m/s)
    s = np.linspace(0, 1, 6)[:-1]
    x = (p[0, :-1, None] * (1 - s) + p[0, 1:, None] * s).ravel()
    y = (p[1, :-1, None] * (1 - s) + p[1, 1:, None] * s).ravel()
    ix, iy = g.world_to_cell(x, y)
    assert g.contains(ix, iy).all()
    assert g.free[iy, ix].all()
    # distance is to occupied cell centres: the body is clear if it exceeds radius + half a cell
    assert g.distance[iy, ix].min() >= radius + g.resolution / 2
    steps = np.hypot(np.diff(p[0]), np.diff(p[1]))
    assert steps.max() <= 0.5 * 0.2 + 1e-6  # never faster than 0.5 m/s
    assert np.abs(_wrap(np.diff(p[2]))).max() <= 0.6 * 0.2 + 1e-6  # never turns faster than 0.6 rad/s
    assert summary["path_length"] > 10.0  # it really drove
    assert len({(int(a), int(b)) for a, b in zip(x // 3, y // 3)}) > 5  # through several places


def test_a_drive_that_cuts_into_a_wall_is_drawn_again(tmp_path, monkeypatch):
    """clutter seed 3653's first drive cuts a route's cusp 0.22 m from a wall at 78 s (the simulator's own check
    wants the radius, 0.2 m, and a cell): the world is written all the same, from a drive redrawn clear of
    walls. With one attempt allowed it is the error it was."""
    import mcl.simulate as sim_mod

    simulate(tmp_path / "w", kind="clutter", seed=3653, duration=90.0)
    g = load_map(tmp_path / "w" / "map.yaml")
    t, p = read_tum(tmp_path / "w" / "truth.tum")
    assert t[-1] - t[0] > 89.0
    ix, iy = g.world_to_cell(p[0], p[1])
    assert g.distance[iy, ix].min() >= 0.2 + g.resolution / 2
    monkeypatch.setattr(sim_mod, "DRIVE_ATTEMPTS", 1)
    with pytest.raises(RuntimeError, match="close to a wall"):
        simulate(tmp_path / "w1", kind="clutter", seed=3653, duration=90.0)


def test_log_parses_and_matches_truth_timing(sim):
    out, summary = sim
    log = read_carmen(out / "log.clf")
    t, p = read_tum(out / "truth.tum")
    assert len(log.scans) == summary["scans"] == t.size == 201
    assert set(log.skipped) <= {"#", "PARAM"}
    np.testing.assert_allclose([s.t for s in log.scans], t, atol=1e-9)
    assert log.odometry.shape == (401, 6)
    np.testing.assert_allclose(np.diff(log.odometry[:, 0]), 0.1, atol=1e-6)
    s0 = log.scans[0]
    assert s0.kind == "FLASER" and s0.ranges.size == 181
    assert s0.angle_min == pytest.approx(-math.pi / 2) and s0.angle_increment == pytest.approx(math.pi / 180)
    # odometry frame starts at the origin; the truth does not
    np.testing.assert_allclose(log.odometry[0, 1:4], 0.0)
    np.testing.assert_allclose(s0.odom, 0.0)
    text = (out / "sim.yaml").read_text()
    params = yaml.safe_load(text)
    np.testing.assert_allclose(params["start_pose"], p[:, 0], atol=1e-6)
    # the file states its units (the numbers carry none): the fov is radians, as the header says
    assert text.startswith("# mcl simulate") and "laser.fov and laser.angle_min rad" in text.splitlines()[2]
    assert params["laser"]["fov"] == pytest.approx(s0.angle_increment * (s0.ranges.size - 1))
    assert math.hypot(*params["start_pose"][:2]) > 1.0
    # scan pose = ODOM pose at the same timestamp (laser at the robot centre)
    for s in log.scans[::17]:
        k = int(np.argmin(np.abs(log.odometry[:, 0] - s.t)))
        np.testing.assert_allclose(s.odom, log.odometry[k, 1:4], atol=1e-9)


def test_noise_free_ranges_equal_ray_casting_from_truth(exact):
    g = load_map(exact / "map.yaml")
    log = read_carmen(exact / "log.clf")
    t, p = read_tum(exact / "truth.tum")
    angles = np.array([log.scans[0].angle_min + i * log.scans[0].angle_increment for i in range(181)])
    np.testing.assert_allclose(angles, beam_angles(181, math.pi), atol=1e-12)
    ref = np.empty((t.size, angles.size))
    cast_rays(np.ascontiguousarray(p), angles, g.occupied, g.origin[0], g.origin[1], g.resolution, 12.0, ref)
    got = np.vstack([s.ranges for s in log.scans])
    err = np.abs(got - ref)
    # ranges are written with 3 decimals; a ray grazing a cell corner may flip
    # with the 1e-9 rounding of the truth pose
    assert np.mean(err <= 0.0005 + 1e-9) > 0.995
    assert np.median(ref) > 1.0 and ref.min() > 0.2


def test_sensor_noise_statistics(sim, exact):
    out, _ = sim
    noisy = np.vstack([s.ranges for s in read_carmen(out / "log.clf").scans])
    clean = np.vstack([s.ranges for s in read_carmen(exact / "log.clf").scans])
    hit = clean < 12.0
    d = noisy[hit] - clean[hit]
    dropouts = np.mean(noisy[hit] == 12.0)
    short = np.mean(d < -0.15)
    core = d[np.abs(d) < 0.1]
    assert 0.005 < dropouts < 0.02  # p_max = 0.01
    assert 0.015 < short < 0.04  # p_short = 0.03, most of them far shorter than 0.15 m
    assert np.std(core) == pytest.approx(0.02, rel=0.1)  # sigma = 0.02
    assert abs(np.mean(core)) < 0.002
    assert noisy.max() == 12.0 and noisy.min() >= 0.0


def _arc_truth(n, v, w, dt=0.1):
    th = 0.5 + np.arange(n) * w * dt
    x = np.concatenate([[0.0], np.cumsum(v * dt * np.cos(th[:-1] + w * dt / 2))])
    y = np.concatenate([[0.0], np.cumsum(v * dt * np.sin(th[:-1] + w * dt / 2))])
    return np.column_stack([x + 3.0, y - 2.0, _wrap(th)])


def _odom_deltas(odom):
    d = np.diff(odom, axis=0)
    trans = np.hypot(d[:, 0], d[:, 1])
    rot1 = _wrap(np.arctan2(d[:, 1], d[:, 0]) - odom[:-1, 2])
    rot2 = _wrap(d[:, 2] - rot1)
    return rot1, trans, rot2


def test_odometry_noise_matches_motion_model_variances():
    # Oracle: recover each tick's (rot1, trans, rot2) from the odometry and
    # standardise the errors by the model's variances: N(0, 1) each.
    a = (0.08, 0.05, 0.06, 0.03)
    truth = _arc_truth(20001, v=0.4, w=0.3)
    odom, tv, rv = _odometry(truth, truth, np.random.default_rng(3), a, 1.0, 0.0)
    r1, tr, r2 = _odom_deltas(truth)
    o1, ot, o2 = _odom_deltas(odom)
    # a noisy translation can come out negative (the model allows it); its
    # (rot1, trans, rot2) then reads back as a turn by pi: undo that
    back = np.abs(_wrap(o1 - r1)) > np.pi / 2
    assert back.mean() < 0.001
    o1, ot, o2 = np.where(back, _wrap(o1 - np.pi), o1), np.where(back, -ot, ot), np.where(back, _wrap(o2 + np.pi), o2)
    s1 = np.sqrt(a[0] * r1**2 + a[1] * tr**2)
    st = np.sqrt(a[2] * tr**2 + a[3] * (r1**2 + r2**2))
    s2 = np.sqrt(a[0] * r2**2 + a[1] * tr**2)
    for z in (_wrap(o1 - r1) / s1, (ot - tr) / st, _wrap(o2 - r2) / s2):
        assert abs(z.mean()) < 0.03  # 20000 samples: sd of the mean 0.007
        assert z.std() == pytest.approx(1.0, abs=0.03)
    np.testing.assert_allclose(odom[0], 0.0)
    np.testing.assert_allclose(tv[1:], ot / 0.1, rtol=1e-9)


def test_reversing_odometry_gets_the_noise_of_the_turn_it_made():
    # A robot reversing along an arc reads rot1 ~ pi and rot2 ~ -pi each tick. Its rotation noise must be that of
    # the turn it made (min(|rot|, |rot -+ pi|), as the filter's model and AMCL fold it), not pi-sized: the book's
    # formula as printed gives a heading error of sqrt(2 * 0.05) * pi ~ 1 rad a tick. Oracle: the folded model's
    # per-tick heading sd, sqrt(2 (a1 n^2 + a2 trans^2)) = 0.014 rad here; 5000 ticks put the sample sd within
    # 3 % of it (the tolerance, 0.1, is far from both 1 rad and a wrong fold).
    a = (0.05, 0.05, 0.05, 0.02)
    truth = _arc_truth(5001, v=-0.4, w=0.15)
    odom, tv, rv = _odometry(truth, truth, np.random.default_rng(5), a, 1.0, 0.0)
    r1, tr, r2 = _odom_deltas(truth)
    assert np.all(np.abs(r1) > 3.0)  # every tick backwards
    n1, n2 = np.pi - np.abs(r1), np.pi - np.abs(r2)
    sd = np.sqrt(a[0] * (n1**2 + n2**2) + 2 * a[1] * tr**2)
    heading_err = _wrap(np.diff(odom[:, 2]) - np.diff(truth[:, 2]))
    assert (heading_err / sd).std() == pytest.approx(1.0, abs=0.1)
    # and the path is driven backwards, as truth is: the odometry's displacement points behind its heading,
    # and the wheels' velocities say so (tv < 0; rv the heading change, not it plus 2 pi)
    o1, ot, _ = _odom_deltas(odom)
    np.testing.assert_allclose(ot, tr, atol=0.05)
    assert np.all(np.abs(o1) > np.pi / 2)
    np.testing.assert_allclose(tv[1:], -ot / 0.1, rtol=1e-9)
    np.testing.assert_allclose(rv[1:], _wrap(np.diff(odom[:, 2])) / 0.1, atol=1e-9)


def test_odometry_systematic_drift_is_exact_without_noise():
    truth = _arc_truth(501, v=0.5, w=-0.2)
    odom, _, _ = _odometry(truth, truth, np.random.default_rng(0), (0.0, 0.0, 0.0, 0.0), 1.02, 0.03)
    _, tr, _ = _odom_deltas(truth)
    _, ot, _ = _odom_deltas(odom)
    np.testing.assert_allclose(ot, 1.02 * tr, rtol=1e-9)
    turned = np.sum(_wrap(np.diff(odom[:, 2])))
    assert turned == pytest.approx(np.sum(_wrap(np.diff(truth[:, 2]))) + 0.03 * tr.sum(), abs=1e-9)


def test_logged_odometry_error_per_scan_interval(sim):
    # End to end: between scans (two ticks), on straight stretches, the
    # translation error is ~N(scale-1, a3/2) relative, the heading error
    # ~N(drift*d, a2*d^2) (two ticks of a1*rot^2 + a2*(d/2)^2 on each of rot1, rot2).
    out, _ = sim
    params = yaml.safe_load((out / "sim.yaml").read_text())
    a1, a2, a3, a4 = params["odometry"]["alphas"]
    scale, drift = params["odometry"]["scale"], params["odometry"]["yaw_drift_per_m"]
    _, p = read_tum(out / "truth.tum")
    o = np.vstack([s.odom for s in read_carmen(out / "log.clf").scans])
    dt_true = np.hypot(np.diff(p[0]), np.diff(p[1]))
    dt_odom = np.hypot(np.diff(o[:, 0]), np.diff(o[:, 1]))
    dth_true = _wrap(np.diff(p[2]))
    dth_odom = _wrap(np.diff(o[:, 2]))
    straight = (dt_true > 0.06) & (np.abs(dth_true) < 0.02)
    assert straight.sum() > 60
    rel = dt_odom[straight] / dt_true[straight] - scale
    assert abs(rel.mean()) < 0.05
    assert rel.std() == pytest.approx(math.sqrt(a3 / 2), rel=0.3)
    d = dt_true[straight]
    z = (dth_odom[straight] - dth_true[straight] - drift * d) / (math.sqrt(a2) * d)
    assert abs(z.mean()) < 0.35
    assert z.std() == pytest.approx(1.0, rel=0.3)


def test_reversals_back_up_along_the_track_and_back(sim, tmp_path):
    # reversals=3: three manoeuvres, each a run of ticks backwards (the displacement behind the heading) that
    # retraces poses the robot held before, then the same poses forwards; reversals=0 is the default's bytes.
    out, _ = sim
    simulate(tmp_path / "r0", seed=4, duration=40.0, reversals=0)
    for name in ("log.clf", "truth.tum", "map.pgm", "sim.yaml"):
        assert (tmp_path / "r0" / name).read_bytes() == (out / name).read_bytes()
    simulate(tmp_path / "r3", seed=4, duration=40.0, reversals=3)
    _, p = read_tum(tmp_path / "r3" / "truth.tum")
    d = np.diff(p[:2], axis=1)
    moved = np.hypot(*d) > 1e-3
    back = moved & (np.abs(_wrap(np.arctan2(d[1], d[0]) - p[2, :-1])) > np.pi / 2)
    runs = np.flatnonzero(np.diff(back.astype(int)) == 1)  # starts of backward stretches
    assert len(runs) + back[0] == 3
    assert 0.5 * 3 <= np.hypot(*d[:, back]).sum() <= 3.0 * 3 + 0.1
    for k in np.flatnonzero(back):  # every pose reached backwards is one the robot held earlier
        assert np.min(np.abs(p[:, :k + 1] - p[:, k + 1:k + 2]).sum(axis=0)) < 1e-9
    assert yaml.safe_load((tmp_path / "r3" / "sim.yaml").read_text())["reversals"] == 3
    odom = read_carmen(tmp_path / "r3" / "log.clf").odometry  # the ODOM lines: t, x, y, theta, tv, rv
    do = np.diff(odom[:, 1:3], axis=0)
    o_back = np.abs(_wrap(np.arctan2(do[:, 1], do[:, 0]) - odom[:-1, 3])) > np.pi / 2
    o_back &= np.hypot(*do.T) > 1e-3
    assert o_back.sum() >= 2 * back.sum() - 3  # ODOM at 10 Hz, the reference at the scans' 5 Hz
    np.testing.assert_array_equal(odom[1:, 4] < 0, o_back)  # tv < 0 exactly on the steps backwards


def test_ground_hits_put_a_line_of_returns_ahead_in_each_window_and_nothing_else_changes(sim, tmp_path):
    # ground_hits=2: two 2 s windows, one in each half of the run (sim.yaml lists them); inside them every scan has a
    # run of beams cut short onto one straight line 1.5-5 m ahead, a new line each scan; outside them the ranges are
    # those of the same seed without ground hits, and ground_hits=0 is the default's bytes
    out, _ = sim
    simulate(tmp_path / "g0", seed=4, duration=40.0, ground_hits=0)
    for name in ("log.clf", "truth.tum", "map.pgm", "sim.yaml"):
        assert (tmp_path / "g0" / name).read_bytes() == (out / name).read_bytes()
    simulate(tmp_path / "g2", seed=4, duration=40.0, ground_hits=2, range_sigma=0.0, p_short=0.0, p_max=0.0)
    simulate(tmp_path / "c", seed=4, duration=40.0, range_sigma=0.0, p_short=0.0, p_max=0.0)
    windows = yaml.safe_load((tmp_path / "g2" / "sim.yaml").read_text())["ground_hits"]
    assert len(windows) == 2 and all(b - a == pytest.approx(2.0) for a, b in windows)
    assert 0.0 <= windows[0][0] and windows[0][1] <= 20.0 + 1.0 and 20.0 - 1.0 <= windows[1][0] <= 40.0
    hit, clean = read_carmen(tmp_path / "g2" / "log.clf").scans, read_carmen(tmp_path / "c" / "log.clf").scans
    # each scan's line as the simulator drew it: its ground-hit stream (the ninth child of the seed), per window the
    # window's place, then per scan in it the line's distance and its normal's angle (sim.yaml records the windows)
    rng = np.random.default_rng(np.random.SeedSequence(4).spawn(9)[8])
    drawn = {}
    for w0, w1 in windows:
        rng.uniform(0.2, 0.8)
        for i, a in enumerate(hit):
            if w0 <= a.t < w1:
                drawn[i] = rng.uniform(1.5, 5.0), rng.uniform(-0.6, 0.6)
    lines, inside_scans = [], 0
    for i, (a, b) in enumerate(zip(hit, clean)):
        if not any(w0 <= a.t < w1 for w0, w1 in windows):
            np.testing.assert_array_equal(a.ranges, b.ranges)
            continue
        inside_scans += 1
        assert (a.ranges <= b.ranges + 1e-6).all()  # the line only ever cuts a beam short
        short = a.ranges < b.ranges - 1e-6
        if short.sum() < 5:  # walls nearer than the line on (almost) every beam
            continue
        xy = np.vstack([a.ranges[short] * np.cos(a.angles[short]), a.ranges[short] * np.sin(a.angles[short])])
        val, vec = np.linalg.eigh(np.cov(xy))
        assert val[0] < 1e-5  # one straight line (residuals at the file's 1 mm rounding)
        normal = vec[:, 0] if vec[:, 0] @ xy.mean(axis=1) > 0 else -vec[:, 0]  # pointing away from the laser
        d = float(normal @ xy.mean(axis=1))  # its distance from the laser
        # the drawn line, to within what the file's 1 mm rounding of the ranges leaves of a fit over a few beams
        # (measured: 0.1 mm and 2 mrad at most)
        assert d == pytest.approx(drawn[i][0], abs=0.002) and 1.5 <= drawn[i][0] <= 5.0
        assert math.atan2(normal[1], normal[0]) == pytest.approx(drawn[i][1], abs=0.01)
        lines.append(round(d, 2))
    assert inside_scans == 20 and len(lines) >= 10
    assert len(set(lines)) > len(lines) // 2  # 5 scans a second, a new line each scan


def test_ground_hit_windows_stay_inside_the_run_at_the_most_episodes_allowed(tmp_path):
    # 20 s allow 5 episodes (one per 4 s share); each 2 s window lies within [0, 20] s (seed 1's first would start
    # at -0.15 s unclamped), and 6 are refused in one line
    simulate(tmp_path / "g", seed=1, duration=20.0, ground_hits=5)
    windows = yaml.safe_load((tmp_path / "g" / "sim.yaml").read_text())["ground_hits"]
    assert len(windows) == 5 and all(0.0 <= a and b <= 20.0 for a, b in windows)
    with pytest.raises(Exception, match="ground_hits: expected 0..5 for 20 s, got 6"):
        simulate(tmp_path / "h", seed=1, duration=20.0, ground_hits=6)
    assert not (tmp_path / "h").exists()


def test_reversals_never_retrace_across_a_kidnap(tmp_path):
    # With a kidnap and reversals, the reference still jumps once (at the kidnap, by more than 5 m), the odometry
    # never, and the robot still backs up: no manoeuvre retraces the track from before the kidnap after it.
    s = simulate(tmp_path, seed=2, duration=40.0, kidnap_at=20.0, reversals=6)
    t, p = read_tum(tmp_path / "truth.tum")
    jumps = np.hypot(np.diff(p[0]), np.diff(p[1]))
    assert jumps.max() > 5.0 and np.sort(jumps)[-2] <= 0.2
    assert t[int(np.argmax(jumps)) + 1] == pytest.approx(s["kidnap"]["t"])
    o = read_carmen(tmp_path / "log.clf").odometry
    assert np.hypot(np.diff(o[:, 1]), np.diff(o[:, 2])).max() < 0.1
    assert (o[:, 4] < 0).sum() > 10  # steps backwards (tv < 0)


def test_kidnapping_moves_truth_but_not_odometry(tmp_path):
    s = simulate(tmp_path, seed=2, duration=20.0, kidnap_at=10.0)
    assert s["kidnap"]["t"] == pytest.approx(10.0)
    t, p = read_tum(tmp_path / "truth.tum")
    jumps = np.hypot(np.diff(p[0]), np.diff(p[1]))
    k = int(np.argmax(jumps))
    assert jumps[k] > 5.0 and t[k + 1] == pytest.approx(10.0)
    assert np.sort(jumps)[-2] <= 0.1 + 1e-6  # only one jump
    np.testing.assert_allclose(p[:, k + 1], s["kidnap"]["to"], atol=1e-6)
    o = read_carmen(tmp_path / "log.clf").odometry
    assert np.hypot(np.diff(o[:, 1]), np.diff(o[:, 2])).max() < 0.1
    assert yaml.safe_load((tmp_path / "sim.yaml").read_text())["kidnap"]["t"] == pytest.approx(10.0)


def test_short_range_and_robotlaser_geometry_via_cli_arguments(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args([str(tmp_path), "--seed", "1", "--duration", "6", "--range-max", "5",
                              "--beams", "91"])
    assert run_from_args(args) == 0
    assert "31 scans" in capsys.readouterr().out
    log = read_carmen(tmp_path / "log.clf")
    s = log.scans[0]
    assert s.kind == "ROBOTLASER1" and s.ranges.size == 91
    assert s.angle_min == pytest.approx(-math.pi / 2, abs=1e-8)
    assert s.angle_increment == pytest.approx(math.pi / 90, abs=1e-8)
    r = np.vstack([x.ranges for x in log.scans])
    assert r.max() == 5.0 and np.mean(r == 5.0) > 0.05
    assert "PARAM robot_front_laser_max 5 " in (tmp_path / "log.clf").read_text()


@pytest.mark.parametrize("rate, odom_hz", [(40.0, 40.0), (20.0, 20.0), (2.0, 10.0)])
def test_scan_rate_sets_the_lasers_and_odometrys_clocks_and_keeps_the_drive(sim, tmp_path, rate, odom_hz):
    # The same seed at another scan rate: the same world and route, driven at the same speed (the motion is
    # integrated in steps that divide the odometry's tick: 12.5 ms at 40 Hz; with 10 ms steps a 25 ms tick took two,
    # and the robot drove at 0.8 times its speed). Path length within 3 % of the 5 Hz drive's (the controller's step
    # differs; measured: within 0.02 %), scans, reference poses and ODOM lines on their clocks, sim.yaml saying so.
    out, s5 = sim
    s = simulate(tmp_path, seed=4, duration=40.0, scan_rate=rate)
    assert (tmp_path / "map.pgm").read_bytes() == (out / "map.pgm").read_bytes()
    assert s["scans"] == int(40.0 * rate) + 1
    assert s["path_length"] == pytest.approx(s5["path_length"], rel=0.03)
    log = read_carmen(tmp_path / "log.clf")
    t_scan = np.array([x.t for x in log.laser_stream()])
    np.testing.assert_allclose(np.diff(t_scan), 1.0 / rate, atol=2e-6)
    n_odom = sum(1 for line in (tmp_path / "log.clf").read_text().splitlines() if line.startswith("ODOM "))
    assert n_odom == int(round(40.0 * odom_hz)) + 1
    meta = yaml.safe_load((tmp_path / "sim.yaml").read_text())
    assert meta["laser"]["rate_hz"] == rate and meta["odometry"]["rate_hz"] == odom_hz
    t_truth, _ = read_tum(tmp_path / "truth.tum")  # a reference pose per scan
    np.testing.assert_allclose(t_truth, t_scan, atol=2e-6)


@pytest.mark.parametrize("kw, key", [
    (dict(kidnap_at=100.0), "kidnap_at"),
    (dict(kidnap_at=float("nan")), "kidnap_at"),  # was a ValueError traceback in int(round())
    (dict(kidnap_at=float("inf")), "kidnap_at"),  # was an OverflowError traceback
    (dict(duration=-1.0), "duration"),
    (dict(n_beams=1), "n_beams"),
    (dict(range_max=0.0), "range_max"),
    (dict(map_resolution=0.001), "map_resolution"),
    (dict(reversals=-1), "reversals"),
    (dict(reversals=2.5), "reversals"),
    (dict(scan_rate=0.1), "scan_rate"),
    (dict(scan_rate=float("nan")), "scan_rate"),
    (dict(phantom_furniture=-1), "phantom_furniture"),
    (dict(unknown_floor=21), "unknown_floor"),
    (dict(doubled_walls=-1), "doubled_walls"),
    (dict(doubled_walls=True), "doubled_walls"),
    (dict(map_scale=1.2), "map_scale"),
    (dict(map_scale=float("nan")), "map_scale"),
    (dict(map_scale=1.01, landmarks=5), "map_scale"),
    (dict(map_rotation=3.5), "map_rotation"),
    (dict(scan_gaps=-1), "scan_gaps"),
    (dict(odom_stalls=21), "odom_stalls"),
    (dict(odom_stalls=1, odom_stall_s=0.2), "odom_stall_s"),
    (dict(odom_resets=True), "odom_resets"),
    (dict(odom_resets=1, odom_reset_s=-1.0), "odom_reset_s"),
    (dict(odom_slips=-1), "odom_slips"),
    (dict(odom_slips=1, odom_slip_s=0.1), "odom_slip_s"),
    (dict(range_scale=1.6), "range_scale"),
    (dict(range_scale=float("nan")), "range_scale"),
    (dict(range_bias=-1.5), "range_bias"),
    (dict(range_bias=True), "range_bias"),
    (dict(scan_gaps=2, scan_gap_s=0.1), "scan_gap_s"),
    (dict(scan_gaps=1, depth=True), "scan_gaps"),
    (dict(map_rotation=float("inf")), "map_rotation"),
    (dict(map_rotation=0.3, depth=True), "map_rotation"),
    (dict(scan_sweep=0.3), "scan_sweep"),
    (dict(laser_pose=(0.25, 0.0, 0.0)), "laser_pose"),  # off the robot's 0.2 m body: it could stand in a wall
    (dict(laser_pose=(0.1, 0.0)), "laser_pose"),
    (dict(laser_pose=(0.1, 0.0, float("nan"))), "laser_pose"),
    (dict(laser_pose=0.1), "laser_pose"),
])
def test_bad_options_raise_config_error(tmp_path, kw, key):
    with pytest.raises(ConfigError, match=key):
        simulate(tmp_path, **kw)
    assert not (tmp_path / "log.clf").exists()


# -1 unknown, 0 free, 100 occupied; row 0 at the bottom
GRID = np.array([[0, 0, 100, 0],
                 [0, -1, -1, 0],
                 [-1, -1, -1, -1]], dtype=np.int8)


@pytest.mark.parametrize("new_res, expected", [
    # 0.1 m: each new cell pools 2x2 world cells (the last row alone): occupied > free > unknown
    (0.1, [[0, 100], [-1, -1]]),
    # 0.075 m: new cells overlap world cells partly; every cell a new one touches counts
    (0.075, [[0, 100, 0], [0, -1, 0]]),
    # 0.025 m: each world cell repeated 2x2
    (0.025, np.repeat(np.repeat(GRID, 2, axis=0), 2, axis=1)),
])
def test_resample_occupancy_draws_the_grid_as_a_mapper_at_another_resolution(new_res, expected):
    np.testing.assert_array_equal(resample_occupancy(GRID, 0.05, new_res), np.asarray(expected, dtype=np.int8))


def test_map_resolution_changes_only_the_map(sim, tmp_path):
    """--map-resolution writes the map with other cells; the world, drive, laser and odometry stay the same."""
    out, _ = sim
    simulate(tmp_path, seed=4, duration=40.0, map_resolution=0.1)
    for name in ("log.clf", "truth.tum"):
        assert (tmp_path / name).read_bytes() == (out / name).read_bytes(), name
    fine, coarse = load_map(out / "map.yaml"), load_map(tmp_path / "map.yaml")
    assert coarse.resolution == 0.1 and coarse.origin == fine.origin
    assert coarse.occupancy.shape == tuple(math.ceil(n / 2) for n in fine.occupancy.shape)
    np.testing.assert_array_equal(coarse.occupancy, resample_occupancy(fine.occupancy, 0.05, 0.1))
    # every wall cell of the world is inside a wall cell of the coarse map
    iy, ix = np.nonzero(fine.occupancy > 0)
    assert np.all(coarse.occupancy[iy // 2, ix // 2] > 0)
    meta = yaml.safe_load((tmp_path / "sim.yaml").read_text())["map"]
    assert meta["resolution"] == 0.1 and [meta["height"], meta["width"]] == list(coarse.occupancy.shape)


def test_bundled_demo_is_consistent():
    from pathlib import Path

    demo = Path(__file__).resolve().parent.parent / "data" / "demo"
    params = yaml.safe_load((demo / "sim.yaml").read_text())
    assert params["seed"] == 7 and params["duration"] == 70.0 and params["kidnap"]["t"] == 50.0
    assert params["laser"]["range_max"] == 5.0 and params["dynamic_obstacles"] == 4
    assert ("--seed 7 --duration 70 --range-max 5 --kidnap-at 50 --dynamic-obstacles 4"
            in (demo / "README.md").read_text())
    g = load_map(demo / "map.yaml")
    log = read_carmen(demo / "log.clf")
    t, p = read_tum(demo / "truth.tum")
    assert len(log.scans) == t.size == params["scans"] == 351
    # the kidnapping: truth jumps by more than 5 m between the scans around 50 s, as sim.yaml says
    k = int(np.searchsorted(t, 50.0))
    assert np.hypot(*(p[:2, k] - p[:2, k - 1])) > 5.0
    np.testing.assert_allclose(p[:, k], params["kidnap"]["to"], atol=1e-6)
    np.testing.assert_allclose(p[:, 0], params["start_pose"], atol=1e-6)
    ix, iy = g.world_to_cell(p[0], p[1])
    assert g.distance[iy, ix].min() >= params["robot"]["radius"] + g.resolution / 2
    assert sum(f.stat().st_size for f in demo.iterdir()) < 3_000_000


def _map_only(tmp_path, duration: float, **option):
    """The office world (seed 6) without and with a map-only ``option``: the laser, the drive and the truth must be
    the same bytes; returns the two maps (tmp_path / "a", tmp_path / "b")."""
    from mcl.maps import load_map

    simulate(tmp_path / "a", kind="office", seed=6, duration=duration)
    simulate(tmp_path / "b", kind="office", seed=6, duration=duration, **option)
    for f in ("log.clf", "truth.tum"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()
    return load_map(tmp_path / "a" / "map.yaml"), load_map(tmp_path / "b" / "map.yaml")


def test_phantom_furniture_is_on_the_map_only(tmp_path):
    # Boxes the map shows and the world no longer has: the laser, the drive and the truth are the world's (the
    # same bytes as without), the map gains occupied cells on free ones only, none on the robot's path.
    a, b = _map_only(tmp_path, 20.0, phantom_furniture=12)
    added = (b.occupancy == 100) & (a.occupancy != 100)
    assert added.sum() > 12 * 36  # 12 boxes of at least 0.3 m x 0.3 m: 36 cells of 5 cm each
    assert np.all(a.occupancy[added] == 0)  # drawn on free cells only
    assert np.array_equal(b.occupancy[~added], a.occupancy[~added])
    t, poses = read_tum(tmp_path / "b" / "truth.tum")
    ix = ((poses[0] - b.origin[0]) / b.resolution).astype(int)
    iy = ((poses[1] - b.origin[1]) / b.resolution).astype(int)
    assert not added[iy, ix].any()
    assert yaml.safe_load((tmp_path / "b" / "sim.yaml").read_text())["phantom_furniture"] == 12


def test_unknown_floor_is_on_the_map_only(tmp_path):
    # Stretches of floor the map never saw: the laser, the drive and the truth are the world's (the same bytes as
    # without); the map turns free cells unknown only, and those are the cells within 1.5 m of the path over each
    # window (every pose of the path in a window stands on one; none outside the windows' reach).
    a, b = _map_only(tmp_path, 30.0, unknown_floor=2)
    grey = (b.occupancy == -1) & (a.occupancy != -1)
    assert grey.sum() > 1000 and np.all(a.occupancy[grey] == 0)  # free cells only
    assert np.array_equal(b.occupancy[~grey], a.occupancy[~grey])
    windows = yaml.safe_load((tmp_path / "b" / "sim.yaml").read_text())["unknown_floor"]
    # two, centred at a third and two thirds of the run, each half the time between them (5 s; 10 s at most)
    assert windows == [[7.5, 12.5], [17.5, 22.5]]
    t, poses = read_tum(tmp_path / "b" / "truth.tum")
    ix = ((poses[0] - b.origin[0]) / b.resolution).astype(int)
    iy = ((poses[1] - b.origin[1]) / b.resolution).astype(int)
    w = ((t >= 7.5) & (t <= 12.5)) | ((t >= 17.5) & (t <= 22.5))
    inside = ((t >= 7.7) & (t <= 12.3)) | ((t >= 17.7) & (t <= 22.3))
    assert grey[iy[inside], ix[inside]].all()
    far = ~grey & (a.occupancy == 0)  # free floor left free: more than 1.5 m from the windows' path
    ys, xs = np.nonzero(grey)
    gx, gy = b.origin[0] + (xs + 0.5) * b.resolution, b.origin[1] + (ys + 0.5) * b.resolution
    d = np.min(np.hypot(gx[:, None] - poses[0, w][None, :], gy[:, None] - poses[1, w][None, :]), axis=1)
    assert d.max() < 1.5 + 2 * b.resolution and far.any()


def test_doubled_walls_are_on_the_map_only(tmp_path):
    # A SLAM map whose loop did not quite close: the laser, the drive and the truth are the world's (the same bytes
    # as without); the map gains occupied cells only, each a wall cell of the same square moved by that square's
    # shift (0.1-0.3 m), inside the squares of 10 m centred on the path at k / (n + 1) of the drive.
    a, b = _map_only(tmp_path, 30.0, doubled_walls=2)
    added = (b.occupancy == 100) & (a.occupancy != 100)
    assert added.sum() > 100
    assert np.array_equal(b.occupancy[~added], a.occupancy[~added])  # nothing else changes
    squares = yaml.safe_load((tmp_path / "b" / "sim.yaml").read_text())["doubled_walls"]
    assert len(squares) == 2
    t, poses = read_tum(tmp_path / "b" / "truth.tum")
    ys, xs = np.nonzero(added)
    explained = np.zeros(ys.size, bool)
    for k, (x, y, dx, dy) in enumerate(squares):
        i = int(round((k + 1) / 3 * (len(t) - 1)))
        assert (x, y) == pytest.approx((poses[0, i], poses[1, i]), abs=1e-3)
        assert 0.1 - b.resolution <= np.hypot(dx, dy) <= 0.3 + b.resolution
        sy, sx = int(round(dy / b.resolution)), int(round(dx / b.resolution))
        src_y, src_x = ys - sy, xs - sx  # where each added cell came from, were it this square's copy
        ok = (src_y >= 0) & (src_y < a.occupancy.shape[0]) & (src_x >= 0) & (src_x < a.occupancy.shape[1])
        cx, cy = b.origin[0] + (src_x + 0.5) * b.resolution, b.origin[1] + (src_y + 0.5) * b.resolution
        inside = ok & (np.abs(cx - x) <= 5.0 + b.resolution) & (np.abs(cy - y) <= 5.0 + b.resolution)
        explained |= inside & (a.occupancy[np.clip(src_y, 0, None), np.clip(src_x, 0, None)] == 100)
    assert explained.all()


def test_a_scaled_map_is_the_same_image_with_bigger_cells_and_the_truth_in_its_frame(tmp_path):
    # A floor plan 2 % too big: the laser and the odometry measure the world (the log's bytes as without), the map
    # is the same image with cells 2 % bigger and its origin scaled, and the reference (truth.tum, sim.yaml's start
    # and kidnap poses) is where the map shows the robot: the world's x, y times 1.02, the heading unchanged.
    simulate(tmp_path / "a", kind="office", seed=6, duration=20.0, kidnap_at=10.0)
    simulate(tmp_path / "b", kind="office", seed=6, duration=20.0, kidnap_at=10.0, map_scale=1.02)
    for f in ("log.clf", "map.pgm"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()
    ma, mb = (yaml.safe_load((tmp_path / w / "map.yaml").read_text()) for w in "ab")
    assert mb["resolution"] == pytest.approx(ma["resolution"] * 1.02, abs=1e-12)
    assert mb["origin"][:2] == pytest.approx([v * 1.02 for v in ma["origin"][:2]], abs=1e-12)
    (ta, pa), (tb, pb) = read_tum(tmp_path / "a" / "truth.tum"), read_tum(tmp_path / "b" / "truth.tum")
    np.testing.assert_array_equal(ta, tb)
    np.testing.assert_allclose(pb[:2], 1.02 * pa[:2], atol=2e-6)  # TUM's 6 decimals
    np.testing.assert_allclose(pb[2], pa[2], atol=1e-6)
    sa, sb = (yaml.safe_load((tmp_path / w / "sim.yaml").read_text()) for w in "ab")
    assert sb["map_scale"] == 1.02 and "map_scale" not in sa
    for pose_a, pose_b in ((sa["start_pose"], sb["start_pose"]), (sa["kidnap"]["to"], sb["kidnap"]["to"])):
        assert pose_b == pytest.approx([1.02 * pose_a[0], 1.02 * pose_a[1], pose_a[2]], abs=2e-6)


def test_a_turned_map_shows_the_world_turned_and_the_truth_in_its_frame(tmp_path):
    # A SLAM map whose frame started at the robot's heading: the laser and the odometry are the world's (the log's
    # bytes as without), the map is the world turned by 30 degrees about the frame's zero, and the reference
    # (truth.tum, sim.yaml's start and kidnap poses) is turned with it.
    angle = math.radians(30.0)
    simulate(tmp_path / "a", kind="office", seed=6, duration=20.0, kidnap_at=10.0)
    simulate(tmp_path / "b", kind="office", seed=6, duration=20.0, kidnap_at=10.0, map_rotation=angle)
    assert (tmp_path / "a" / "log.clf").read_bytes() == (tmp_path / "b" / "log.clf").read_bytes()
    a, b = load_map(tmp_path / "a" / "map.yaml"), load_map(tmp_path / "b" / "map.yaml")
    assert b.resolution == a.resolution
    c, s = math.cos(angle), math.sin(angle)

    def cell_of(grid, x, y):  # each point's cell value on a grid, -1 off it
        col = np.floor((x - grid.origin[0]) / grid.resolution).astype(int)
        row = np.floor((y - grid.origin[1]) / grid.resolution).astype(int)
        ok = (col >= 0) & (col < grid.occupancy.shape[1]) & (row >= 0) & (row < grid.occupancy.shape[0])
        return np.where(ok, grid.occupancy[np.clip(row, 0, None) * ok, np.clip(col, 0, None) * ok], -1)

    # every world cell's centre, turned, lands on a map cell of the same kind: a wall cell on or beside a map wall
    # (the map's walls are closed), free and unknown ones on their own kind unless they touch a wall (the map's
    # walls are a little thicker)
    rows, cols = np.indices(a.occupancy.shape)
    wx, wy = a.origin[0] + (cols.ravel() + 0.5) * a.resolution, a.origin[1] + (rows.ravel() + 0.5) * a.resolution
    mx, my = c * wx - s * wy, s * wx + c * wy
    seen = cell_of(b, mx, my)
    world = a.occupancy.ravel()
    square = np.ones((3, 3), bool)
    wall_beside = cell_of(SimpleNamespace(occupancy=np.where(binary_dilation(b.occupancy == 100, structure=square),
                                                             100, 0), origin=b.origin, resolution=b.resolution),
                          mx, my)
    assert np.all(wall_beside[world == 100] == 100)
    assert np.mean(seen[world == 100] == 100) > 0.9
    near_wall = binary_dilation(a.occupancy == 100, structure=square).ravel()
    for kind in (0, -1):
        assert np.all(seen[(world == kind) & ~near_wall] == kind)
    # the map holds no other walls: its wall cells' centres turned back land on or beside the world's walls
    rows, cols = np.nonzero(b.occupancy == 100)
    mx, my = b.origin[0] + (cols + 0.5) * b.resolution, b.origin[1] + (rows + 0.5) * b.resolution
    back = cell_of(a, c * mx + s * my, -s * mx + c * my)
    assert np.mean(back == 100) > 0.6
    assert np.all(np.isin(back[back != 100], (0, -1)))
    qx, qy = c * mx + s * my, -s * mx + c * my
    wall_near = np.zeros(qx.size, bool)
    for dx in (-0.5, 0.0, 0.5):
        for dy in (-0.5, 0.0, 0.5):
            wall_near |= cell_of(a, qx + dx * a.resolution, qy + dy * a.resolution) == 100
    assert wall_near.all()
    (ta, pa), (tb, pb) = read_tum(tmp_path / "a" / "truth.tum"), read_tum(tmp_path / "b" / "truth.tum")
    # the turned map seen from the turned truth is the world seen from the truth: a lidar's rays cast on both agree
    # within a staircase step but where a ray grazes a wall or a narrow gap (measured: 96 % within 0.1 m)
    angles = beam_angles(360, 2 * math.pi)
    ra, rb = np.empty((ta.size, 360)), np.empty((ta.size, 360))
    cast_rays(np.ascontiguousarray(pa), angles, a.occupied, a.origin[0], a.origin[1], a.resolution, 12.0, ra)
    cast_rays(np.ascontiguousarray(pb), angles, b.occupied, b.origin[0], b.origin[1], b.resolution, 12.0, rb)
    assert np.mean(np.abs(rb - ra) < 0.1) > 0.93
    assert np.median(np.abs(rb - ra)) < 0.02
    np.testing.assert_array_equal(ta, tb)
    np.testing.assert_allclose(pb[0], c * pa[0] - s * pa[1], atol=2e-6)  # TUM's 6 decimals
    np.testing.assert_allclose(pb[1], s * pa[0] + c * pa[1], atol=2e-6)
    np.testing.assert_allclose(np.cos(pb[2] - pa[2] - angle), 1.0, atol=1e-9)
    sa, sb = (yaml.safe_load((tmp_path / w / "sim.yaml").read_text()) for w in "ab")
    assert sb["map_rotation"] == pytest.approx(angle) and "map_rotation" not in sa
    for pose_a, pose_b in ((sa["start_pose"], sb["start_pose"]), (sa["kidnap"]["to"], sb["kidnap"]["to"])):
        assert pose_b[:2] == pytest.approx([c * pose_a[0] - s * pose_a[1], s * pose_a[0] + c * pose_a[1]], abs=2e-6)
        assert math.cos(pose_b[2] - pose_a[2] - angle) == pytest.approx(1.0, abs=1e-9)


def test_a_turned_and_doubled_map_turns_the_squares(tmp_path):
    # sim.yaml's doubled squares are in the map's frame too: a centre on the turned path, a shift turned with it.
    angle = math.radians(-75.0)
    simulate(tmp_path / "a", kind="office", seed=6, duration=30.0, doubled_walls=2)
    simulate(tmp_path / "b", kind="office", seed=6, duration=30.0, doubled_walls=2, map_rotation=angle)
    sa, sb = (yaml.safe_load((tmp_path / w / "sim.yaml").read_text())["doubled_walls"] for w in "ab")
    c, s = math.cos(angle), math.sin(angle)
    for (x, y, dx, dy), square in zip(sa, sb):
        assert square == pytest.approx([c * x - s * y, s * x + c * y, c * dx - s * dy, s * dx + c * dy], abs=2e-3)


def test_a_turned_map_from_the_command_line(tmp_path, capsys):
    from mcl.cli import main

    assert main(["simulate", str(tmp_path / "w"), "--duration", "10", "--seed", "6", "--map-rotation", "-45"]) == 0
    assert yaml.safe_load((tmp_path / "w" / "sim.yaml").read_text())["map_rotation"] == pytest.approx(-math.pi / 4)
    capsys.readouterr()


def test_scan_gaps_drop_the_scans_and_their_reference_only(tmp_path):
    # The laser silent three times for 4 s (a driver restart): the log keeps every ODOM line and every other scan line
    # as it was, byte for byte, and truth.tum drops the poses of the scans that are gone; sim.yaml lists the windows,
    # evenly spread.
    simulate(tmp_path / "a", kind="office", seed=6, duration=40.0)
    simulate(tmp_path / "b", kind="office", seed=6, duration=40.0, scan_gaps=3, scan_gap_s=4.0)
    la, lb = ((tmp_path / w / "log.clf").read_text().splitlines() for w in "ab")
    gaps = yaml.safe_load((tmp_path / "b" / "sim.yaml").read_text())["scan_gaps"]
    assert gaps == [[8.0, 12.0], [18.0, 22.0], [28.0, 32.0]]
    stamp = lambda line: float(line.split()[-1])  # noqa: E731

    def in_gap(line):
        return any(a <= stamp(line) < b for a, b in gaps)

    assert lb == [line for line in la if not (line.startswith("FLASER") and in_gap(line))]
    dropped = [line for line in la if line.startswith("FLASER") and in_gap(line)]
    assert len(dropped) == 3 * 20  # 4 s at 5 Hz, three times
    (ta, pa), (tb, pb) = read_tum(tmp_path / "a" / "truth.tum"), read_tum(tmp_path / "b" / "truth.tum")
    keep = ~np.any([(ta >= a) & (ta < b) for a, b in gaps], axis=0)
    np.testing.assert_array_equal(tb, ta[keep])
    np.testing.assert_array_equal(pb, pa[:, keep])
    assert yaml.safe_load((tmp_path / "b" / "sim.yaml").read_text())["scans"] == int(keep.sum())


def test_scan_gaps_from_the_command_line(tmp_path):
    from mcl.cli import main

    assert main(["simulate", str(tmp_path), "--duration", "30", "--seed", "6", "--scan-gaps", "2",
                 "--scan-gap-s", "3"]) == 0
    assert yaml.safe_load((tmp_path / "sim.yaml").read_text())["scan_gaps"] == [[8.5, 11.5], [18.5, 21.5]]


def _odom_lines(world):
    """(ipc_timestamps, x y theta tv rv (T, 5)) of the ODOM lines of ``world``'s log.clf."""
    rows = [line.split() for line in (world / "log.clf").read_text().splitlines() if line.startswith("ODOM")]
    return np.array([float(r[-3]) for r in rows]), np.array([[float(v) for v in r[1:6]] for r in rows])


def test_odometry_stalls_hold_the_pose_and_lose_the_motion_only(tmp_path):
    # An encoder driver that hangs twice for 3 s: the laser and the truth are the same bytes; the odometry holds its
    # pose (no velocity) inside each window and afterwards goes on with the same steps from the held pose.
    from mcl.runner import compose, inverse

    simulate(tmp_path / "a", kind="office", seed=6, duration=30.0)
    simulate(tmp_path / "b", kind="office", seed=6, duration=30.0, odom_stalls=2, odom_stall_s=3.0)
    assert (tmp_path / "a" / "truth.tum").read_bytes() == (tmp_path / "b" / "truth.tum").read_bytes()
    stalls = yaml.safe_load((tmp_path / "b" / "sim.yaml").read_text())["odom_stalls"]
    assert stalls == [[8.5, 11.5], [18.5, 21.5]]

    (t, a), (tb, b) = _odom_lines(tmp_path / "a"), _odom_lines(tmp_path / "b")
    np.testing.assert_array_equal(t, tb)
    inside = np.any([(t >= w0) & (t < w1) for w0, w1 in stalls], axis=0)
    for w0, w1 in stalls:
        k = np.flatnonzero((t >= w0) & (t < w1))
        np.testing.assert_allclose(b[k, :3], np.broadcast_to(b[k[0] - 1, :3], (k.size, 3)), atol=1e-6)  # held
        assert not b[k, 3:].any()  # no velocity
    assert np.abs(a[inside, 3]).max() > 0.1  # the robot drove on
    # outside the windows each step is the same motion (relative poses, to the log's 6 decimals)
    steps = [k for k in range(1, t.size) if not inside[k] and not inside[k - 1]]
    for k in steps[::7]:
        np.testing.assert_allclose(compose(inverse(b[k - 1, :3]), b[k, :3]),
                                   compose(inverse(a[k - 1, :3]), a[k, :3]), atol=2e-5)
    la, lb = ((tmp_path / w / "log.clf").read_text().splitlines() for w in "ab")
    ranges = lambda lines: [line.split()[2:2 + int(line.split()[1])] for line in lines if line.startswith("FLASER")]  # noqa: E731
    assert ranges(la) == ranges(lb)


def test_odometry_resets_restart_from_zero_and_keep_every_other_step(tmp_path):
    # A base driver that restarts twice, each time after 2 s down: the laser and the truth are the same bytes;
    # the odometry reads 0 0 0 where each restart ends and the same steps as before everywhere else.
    from mcl.cli import main
    from mcl.runner import compose, inverse

    simulate(tmp_path / "a", kind="office", seed=6, duration=30.0)
    assert main(["simulate", str(tmp_path / "b"), "--kind", "office", "--seed", "6", "--duration", "30",
                 "--odom-resets", "2", "--odom-reset-s", "2"]) == 0
    assert (tmp_path / "a" / "truth.tum").read_bytes() == (tmp_path / "b" / "truth.tum").read_bytes()
    resets = yaml.safe_load((tmp_path / "b" / "sim.yaml").read_text())["odom_resets"]
    assert resets == [[9.0, 11.0], [19.0, 21.0]]

    (t, a), (_, b) = _odom_lines(tmp_path / "a"), _odom_lines(tmp_path / "b")
    a, b = a[:, :3], b[:, :3]
    ends = [int(np.searchsorted(t, w1)) for _, w1 in resets]
    for k in ends:
        np.testing.assert_array_equal(b[k], [0.0, 0.0, 0.0])  # restarted
        assert np.hypot(*b[k - 1, :2]) > 2.0  # from far off: a jump
    held = np.flatnonzero((t >= resets[0][0]) & (t < resets[0][1]))
    np.testing.assert_allclose(b[held], np.broadcast_to(b[held[0] - 1], (held.size, 3)), atol=1e-6)
    inside = np.any([(t >= w0) & (t <= w1) for w0, w1 in resets], axis=0)
    for k in [k for k in range(1, t.size) if not inside[k] and not inside[k - 1]][::7]:
        np.testing.assert_allclose(compose(inverse(b[k - 1]), b[k]), compose(inverse(a[k - 1]), a[k]), atol=2e-5)


def test_a_slipping_wheel_reads_more_travel_and_a_turn_the_robot_did_not_make(tmp_path):
    # The right wheel slips twice for 2 s: the laser and the truth are the same bytes; inside each window every
    # odometry step reads 1.5 times its translation and its turn plus the travel over SLIP_BASE; outside, the same
    # steps as without.
    from mcl.cli import main
    from mcl.runner import compose, inverse
    from mcl.simulate import SLIP_BASE

    simulate(tmp_path / "a", kind="office", seed=6, duration=30.0)
    assert main(["simulate", str(tmp_path / "b"), "--kind", "office", "--seed", "6", "--duration", "30",
                 "--odom-slips", "2"]) == 0
    assert (tmp_path / "a" / "truth.tum").read_bytes() == (tmp_path / "b" / "truth.tum").read_bytes()
    slips = yaml.safe_load((tmp_path / "b" / "sim.yaml").read_text())["odom_slips"]
    assert slips == [[9.0, 11.0], [19.0, 21.0]]
    (t, a), (_, b) = _odom_lines(tmp_path / "a"), _odom_lines(tmp_path / "b")
    inside = np.any([(t >= w0) & (t < w1) for w0, w1 in slips], axis=0)
    turned = 0.0
    for k in range(1, t.size):
        sa, sb = compose(inverse(a[k - 1, :3]), a[k, :3]), compose(inverse(b[k - 1, :3]), b[k, :3])
        if inside[k]:
            d = np.copysign(np.hypot(sa[0], sa[1]), sa[0])
            np.testing.assert_allclose(sb, [1.5 * sa[0], 1.5 * sa[1], sa[2] + d / SLIP_BASE], atol=3e-5)
            turned += d / SLIP_BASE
        else:
            np.testing.assert_allclose(sb, sa, atol=3e-5)
    assert turned > 2.0  # the turns the robot did not make: 1 rad/s and more


def test_a_laser_off_scale_reads_k_r_plus_b_and_changes_nothing_else(tmp_path):
    # --range-scale 1.03 --range-bias 0.05 with no noise: every return reads 1.03 r + 0.05 (both logged to the
    # millimetre: within 2 mm), a no-return stays one, and a return pushed to the laser's 6 m or past it reads none;
    # the odometry, the map and the truth are the same bytes, and sim.yaml gives both. 1 and 0 give the log as
    # without them, and no entry in sim.yaml.
    from mcl.cli import main

    exact = dict(range_sigma=0.0, p_short=0.0, p_max=0.0)
    simulate(tmp_path / "a", kind="office", seed=6, duration=10.0, range_max=6.0, **exact)
    assert main(["simulate", str(tmp_path / "b"), "--kind", "office", "--seed", "6", "--duration", "10",
                 "--range-max", "6", "--range-sigma", "0", "--p-short", "0", "--p-max", "0",
                 "--range-scale", "1.03", "--range-bias", "0.05"]) == 0
    simulate(tmp_path / "c", kind="office", seed=6, duration=10.0, range_max=6.0, range_scale=1.0, range_bias=0.0,
             **exact)
    for f in ("truth.tum", "map.pgm", "map.yaml"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()
    assert (tmp_path / "a" / "log.clf").read_bytes() == (tmp_path / "c" / "log.clf").read_bytes()
    params = yaml.safe_load((tmp_path / "b" / "sim.yaml").read_text())
    assert params["range_scale"] == 1.03 and params["range_bias"] == 0.05
    assert "range_scale" not in yaml.safe_load((tmp_path / "c" / "sim.yaml").read_text())
    la, lb = read_carmen(tmp_path / "a" / "log.clf"), read_carmen(tmp_path / "b" / "log.clf")
    np.testing.assert_array_equal([s.odom for s in la.scans], [s.odom for s in lb.scans])
    ra, rb = np.array([s.ranges for s in la.scans]), np.array([s.ranges for s in lb.scans])
    hit = ra < 6.0
    inside = hit & (1.03 * ra + 0.05 < 5.99)  # clear of the log's rounding at the laser's range
    out = hit & (1.03 * ra + 0.05 > 6.01)
    np.testing.assert_allclose(rb[inside], 1.03 * ra[inside] + 0.05, atol=0.002)
    assert np.all(rb[~hit] == 6.0) and np.all(rb[out] == 6.0)
    assert inside.sum() > 1000 and out.sum() > 10


def test_doubled_walls_from_the_command_line(tmp_path):
    from mcl.cli import main

    assert main(["simulate", str(tmp_path), "--duration", "10", "--seed", "6", "--doubled-walls", "3"]) == 0
    assert len(yaml.safe_load((tmp_path / "sim.yaml").read_text())["doubled_walls"]) == 3


def test_the_noise_is_set_from_the_command_line(tmp_path, capsys):
    # The noise could be set from Python only (a student checking `mcl calibrate` had no way to make odometry with
    # the motion model's noise alone: scale 1.01 and a yaw drift of 0.01 rad/m were always on). Now each is an
    # option, written to sim.yaml; noise-free odometry then follows the truth's relative motion exactly, and a
    # scale of 1.2 reads 1.2 times the truth's travel.
    from mcl.cli import main

    def drive(name, *opts):
        assert main(["simulate", str(tmp_path / name), "--duration", "20", "--seed", "3", *opts]) == 0
        log = read_carmen(tmp_path / name / "log.clf")
        t, truth = read_tum(tmp_path / name / "truth.tum")
        odo = np.array([s.odom for s in log.scans]).T
        ref = np.array([np.interp([s.t for s in log.scans], t, truth[k]) for k in range(2)])
        travel = lambda p: float(np.sum(np.hypot(np.diff(p[0]), np.diff(p[1]))))  # noqa: E731
        return yaml.safe_load((tmp_path / name / "sim.yaml").read_text()), travel(odo), travel(ref)

    sim, odo, ref = drive("exact", "--odom-alphas", "0,0,0,0", "--odom-scale", "1", "--odom-yaw-drift", "0",
                          "--range-sigma", "0.05", "--p-short", "0", "--p-max", "0.1")
    assert sim["odometry"]["alphas"] == [0.0, 0.0, 0.0, 0.0] and sim["odometry"]["scale"] == 1.0
    assert sim["odometry"]["yaw_drift_per_m"] == 0.0
    assert (sim["laser"]["range_sigma"], sim["laser"]["p_short"], sim["laser"]["p_max"]) == (0.05, 0.0, 0.1)
    assert odo == pytest.approx(ref, rel=1e-5)  # the poses are written to 1e-6 m
    _, odo12, ref12 = drive("scaled", "--odom-alphas", "0,0,0,0", "--odom-scale", "1.2", "--odom-yaw-drift", "0")
    assert odo12 == pytest.approx(1.2 * ref12, rel=1e-4)
    capsys.readouterr()
    assert main(["simulate", str(tmp_path / "bad"), "--odom-alphas", "0.1,0.1"]) == 2
    assert "--odom-alphas: expected four values in 0..100" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()


def test_a_world_made_again_replaces_the_earlier_whole_and_a_stopped_one_leaves_it(tmp_path, capsys, monkeypatch):
    # Into an earlier world's folder, seed 0's bag, landmarks and depth frames stayed beside seed 3's map and log;
    # Ctrl-C mid-way left a half-swapped world; a user's own map.yaml was overwritten. Now the world is made beside
    # the folder and moved in whole: an earlier world's files all go (a README stays), a folder of other files is
    # refused, and a stopped run leaves the folder as it was (the world is made inside it since session 97).
    import mcl.simulate as sim
    from mcl.cli import main

    w = tmp_path / "w"
    assert main(["simulate", str(w), "--duration", "4", "--landmarks", "3", "--format", "mcap"]) == 0
    (w / "README.md").write_text("mine\n")
    assert {"landmarks.yaml", "log.mcap"} <= {p.name for p in w.iterdir()}
    assert main(["simulate", str(w), "--duration", "4", "--seed", "3"]) == 0
    assert sorted(p.name for p in w.iterdir()) == ["README.md", "log.clf", "map.pgm", "map.yaml", "sim.yaml",
                                                   "truth.tum"]
    before = {p.name: p.read_bytes() for p in w.iterdir()}

    def stopped(*_a, **_k):
        raise KeyboardInterrupt

    import mcl.trajectory

    monkeypatch.setattr(mcl.trajectory, "write_tum", stopped)  # Ctrl-C while the new world is being written
    with pytest.raises(KeyboardInterrupt):
        sim.run_from_args(_parsed(["simulate", str(w), "--seed", "5", "--duration", "4"]))
    monkeypatch.undo()
    assert {p.name: p.read_bytes() for p in w.iterdir()} == before
    assert [p.name for p in tmp_path.iterdir()] == ["w"]  # no temporary folder left beside it
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "map.yaml").write_text("my map\n")
    capsys.readouterr()
    assert main(["simulate", str(mine), "--duration", "4"]) == 2
    assert "holds files (map.yaml) and no sim.yaml: not an earlier world" in capsys.readouterr().err
    assert (mine / "map.yaml").read_text() == "my map\n"


def test_a_world_is_made_on_outdirs_own_file_system_and_a_failed_one_leaves_no_folders(tmp_path, capsys,
                                                                                      monkeypatch):
    # Made in a folder beside OUTDIR, a world could not be moved onto a mount point (a volume, a USB stick:
    # "Invalid cross-device link") after the earlier world was deleted, and a read-only parent refused a writable
    # OUTDIR. It is made inside OUTDIR now. Bad options left OUTDIR's missing parents behind.
    import os

    import mcl.simulate as sim
    from mcl.cli import main

    w = tmp_path / "w"
    assert main(["simulate", str(w), "--duration", "3"]) == 0
    before = {p.name: p.read_bytes() for p in w.iterdir()}
    real = os.replace

    def one_device(src, dst):  # a move between folders is a move across devices unless both are inside w
        if os.path.dirname(os.path.dirname(os.fspath(src))) != os.fspath(w) and os.path.dirname(os.fspath(src)) != \
                os.fspath(w):
            raise OSError(18, "Invalid cross-device link", os.fspath(src))
        return real(src, dst)

    monkeypatch.setattr(sim.os, "replace", one_device)
    assert main(["simulate", str(w), "--duration", "3", "--seed", "4"]) == 0
    monkeypatch.undo()
    after = {p.name: p.read_bytes() for p in w.iterdir()}
    assert sorted(after) == sorted(before) and after["log.clf"] != before["log.clf"]
    capsys.readouterr()
    assert main(["simulate", str(tmp_path / "new" / "a" / "w"), "--duration", "-5"]) == 2
    assert "--duration" in capsys.readouterr().err and not (tmp_path / "new").exists()


def test_a_sim_yaml_of_another_tool_is_not_taken_for_an_earlier_world(tmp_path, capsys):
    from mcl.cli import main

    mine = tmp_path / "myrobot"
    mine.mkdir()
    (mine / "sim.yaml").write_text("gazebo: {}\n")
    (mine / "map.yaml").write_text("image: lab.pgm\n")
    assert main(["simulate", str(mine), "--duration", "3"]) == 2
    assert "its sim.yaml is not one mcl simulate wrote" in capsys.readouterr().err
    assert (mine / "map.yaml").read_text() == "image: lab.pgm\n"


def test_a_world_too_large_for_memory_is_one_line_before_its_ranges_are_cast(tmp_path, capsys, monkeypatch):
    import mcl.maps
    from mcl.cli import main

    # an hour at 100 Hz of 4,096 beams asked numpy for 11 GB: a traceback (a machine swapping first)
    monkeypatch.setattr(mcl.maps, "available_memory", lambda: 5_000_000)  # 5 MB
    assert main(["simulate", str(tmp_path / "w"), "--duration", "60", "--beams", "1000"]) == 2
    assert capsys.readouterr().err == ("mcl: error: simulate: 301 scans of 1,000 beams need about 7 MB, and 5 MB are "
                                       "free: a shorter --duration, a lower --scan-rate or fewer --beams\n")
    assert not (tmp_path / "w").exists()


def test_windows_cut_shorter_than_asked_and_a_map_that_walls_the_drive_are_warned_of(tmp_path, capsys):
    from mcl.cli import main

    assert main(["simulate", str(tmp_path / "a"), "--duration", "60", "--scan-gaps", "1", "--scan-gap-s", "60",
                 "--odom-stalls", "2", "--odom-stall-s", "60"]) == 0
    err = capsys.readouterr().err
    assert "--scan-gap-s 60: each window is 15.0 s" in err and "--odom-stall-s 60: each window is 10.0 s" in err
    assert main(["simulate", str(tmp_path / "b"), "--duration", "60", "--scan-gaps", "1"]) == 0
    assert "warning" not in capsys.readouterr().err  # 5 s gaps fit: nothing said
    assert main(["simulate", str(tmp_path / "c"), "--duration", "60", "--map-resolution", "0.5"]) == 0
    assert "--map-resolution 0.5: 16 of the drive's 601 poses (every 0.1 s) lie in the map's walls" in \
        capsys.readouterr().err
    assert main(["simulate", str(tmp_path / "d"), "--duration", "60", "--map-resolution", "0.1"]) == 0
    assert "warning" not in capsys.readouterr().err


def _parsed(argv):
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="command")
    add_arguments(sub.add_parser("simulate"))
    return p.parse_args(argv)


MOUNT = (-0.15, 0.05, math.pi)  # 0.16 m behind the centre and to the left, looking back


def test_a_mounted_laser_scans_from_its_mounting_and_the_log_says_where_it_sits(sim, exact, tmp_path):
    # laser_pose: every scan cast from truth ∘ mount; the log's laser pose is odom ∘ mount, so the reader's
    # laser_offset (robot^-1 ∘ laser) gives the mounting back to the 6-decimal rounding of the file (1e-6, and
    # theta wrapped); truth.tum, the map and the odometry are the robot's, as without it; (0, 0, 0) is the
    # default's bytes.
    from mcl.estimate import compose

    simulate(tmp_path / "zero", seed=4, duration=40.0, laser_pose=(0.0, 0.0, 0.0))
    for name in ("log.clf", "truth.tum", "map.pgm", "sim.yaml"):
        assert (tmp_path / "zero" / name).read_bytes() == (sim[0] / name).read_bytes(), name
    out = tmp_path / "m"
    simulate(out, seed=4, duration=40.0, laser_pose=MOUNT, **NOISE_FREE)
    for name in ("truth.tum", "map.pgm"):
        assert (out / name).read_bytes() == (exact / name).read_bytes(), name
    assert yaml.safe_load((out / "sim.yaml").read_text())["laser"]["pose"] == list(MOUNT)
    log, centred = read_carmen(out / "log.clf"), read_carmen(exact / "log.clf")
    np.testing.assert_array_equal(np.array([s.odom for s in log.scans]), np.array([s.odom for s in centred.scans]))
    off = np.array([s.laser_offset for s in log.scans])
    np.testing.assert_allclose(off[:, :2], np.tile(MOUNT[:2], (len(off), 1)), atol=2e-6)
    np.testing.assert_allclose(np.abs(_wrap(off[:, 2] - MOUNT[2])), 0.0, atol=2e-6)
    g = load_map(out / "map.yaml")
    t, p = read_tum(out / "truth.tum")
    at = np.array([compose(p[:, i], np.array(MOUNT)) for i in range(t.size)]).T
    angles = beam_angles(181, math.pi)
    ref, from_centre = np.empty((t.size, 181)), np.empty((t.size, 181))
    cast_rays(np.ascontiguousarray(at), angles, g.occupied, g.origin[0], g.origin[1], g.resolution, 12.0, ref)
    cast_rays(np.ascontiguousarray(p), angles, g.occupied, g.origin[0], g.origin[1], g.resolution, 12.0, from_centre)
    got = np.vstack([s.ranges for s in log.scans])
    # 3-decimal ranges; a ray grazing a cell corner may flip (as test_noise_free_ranges_equal_ray_casting_from_truth)
    assert np.mean(np.abs(got - ref) <= 0.0005 + 1e-9) > 0.995
    assert np.mean(np.abs(got - from_centre) <= 0.0005 + 1e-9) < 0.2  # looking back from elsewhere: other ranges


def test_a_mounted_lasers_bag_carries_the_mounting_on_tf_static(tmp_path):
    from mcl.datasets.rosbag import open_bag
    from mcl.simulate import write_log_as_bag

    simulate(tmp_path, seed=4, duration=10.0, laser_pose=MOUNT)
    src = open_bag(write_log_as_bag(tmp_path, "mcap"))
    off = np.asarray(src.laser_offsets["/scan"], dtype=float)
    np.testing.assert_allclose(off[:2], MOUNT[:2], atol=2e-6)
    assert abs(_wrap(off[2] - MOUNT[2])) < 2e-6


def test_landmarks_left_out_of_a_bag_are_said(tmp_path, capsys):
    # A bag has no message for LANDMARK detections: `mcl simulate --landmarks 5 --format mcap` and `mcl convert` of
    # a log with LANDMARK lines dropped them in silence (a run with landmarks.use on the bag was then refused).
    from mcl.cli import main

    assert main(["simulate", str(tmp_path / "b"), "--duration", "4", "--landmarks", "5", "--format", "mcap"]) == 0
    assert "--landmarks with --format mcap: the detections are not in the bag" in capsys.readouterr().err
    assert main(["simulate", str(tmp_path / "c"), "--duration", "4", "--landmarks", "5"]) == 0
    capsys.readouterr()
    assert main(["convert", str(tmp_path / "c" / "log.clf"), str(tmp_path / "c.mcap")]) == 0
    err = capsys.readouterr().err
    assert "LANDMARK lines not written: a bag has no message for them" in err


def test_ground_hits_beside_a_holonomic_drive_draw_numbers_of_their_own(tmp_path):
    # The ground hits and the holonomic offsets both drew from child stream 8 (the unmapped furniture and the depth
    # frames both from 6): with both on, the windows' times were made of the offsets' numbers. With the holonomic
    # drive on, the hits now draw from a stream of their own; alone, each is the world it was.
    import yaml

    def windows(name, **kw):
        simulate(tmp_path / name, seed=4, duration=40.0, ground_hits=2, **kw)
        return yaml.safe_load((tmp_path / name / "sim.yaml").read_text())["ground_hits"]

    assert windows("hol", holonomic=0.3) != windows("plain")  # before: the same windows, from the same numbers


def test_depth_frames_beside_unmapped_furniture_draw_numbers_of_their_own(tmp_path, monkeypatch):
    # The depth frames' noise and the unmapped furniture both drew from child stream 6: with both on, the same
    # numbers. The streams each is handed, compared by their first draws: distinct with both on; the depth frames'
    # alone is the stream it was (child 6).
    import mcl.depthsim
    import mcl.simulate as sim

    first: dict = {}
    furniture, depth = sim._unmapped_furniture, mcl.depthsim.write_depth_folder

    def furniture_spy(world, xy, n, radius, rng):
        first["furniture"] = rng.bit_generator.state["state"]["state"]
        return furniture(world, xy, n, radius, rng)

    def depth_spy(out, world, poses, times, rng, *a, **kw):
        first["depth"] = rng.bit_generator.state["state"]["state"]
        return depth(out, world, poses, times, rng, *a, **kw)

    monkeypatch.setattr(sim, "_unmapped_furniture", furniture_spy)
    monkeypatch.setattr(mcl.depthsim, "write_depth_folder", depth_spy)
    simulate(tmp_path / "both", seed=3, duration=6.0, depth=True, unmapped_furniture=2)
    assert first["furniture"] != first["depth"]
    simulate(tmp_path / "alone", seed=3, duration=6.0, depth=True)
    child6 = np.random.default_rng(np.random.SeedSequence(3).spawn(7)[6]).bit_generator.state["state"]["state"]
    assert first["depth"] == child6
