"""Odometry motion model (Prob. Rob. Table 5.6) and the map-based model (section 5.5)."""

import dataclasses
import math
from types import SimpleNamespace

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from mcl.kernels import motion as km
from mcl.maps import OccupancyGrid
from mcl.motion import OdometryMotionModel, allowed_mask, noise_sigmas, odometry_deltas


def motion_cfg(noise_form="variance", alphas=(0.1, 0.05, 0.2, 0.03), max_tries=10):
    a1, a2, a3, a4 = alphas
    return SimpleNamespace(model="odometry", noise_form=noise_form, alpha1=a1, alpha2=a2, alpha3=a3,
                           alpha4=a4, map_rejection=True, max_tries=max_tries, robot_radius=0.0)


def wrap_np(a):
    """(-pi, pi], written independently of the kernel's formula."""
    w = np.arctan2(np.sin(a), np.cos(a))
    return np.where(w <= -np.pi, w + 2 * np.pi, w)


def random_particles(rng, n, spread=2.0):
    p = np.empty((3, n))
    p[0:2] = rng.uniform(-spread, spread, size=(2, n))
    p[2] = rng.uniform(-np.pi, np.pi, size=n)
    return p


def numpy_motion(p, noise, deltas, sigmas):
    """Table 5.6 lines 5-10 in NumPy, with the noise added: the oracle for the kernels."""
    r1 = deltas[0] + sigmas[0] * noise[0]
    tr = deltas[1] + sigmas[1] * noise[1]
    r2 = deltas[2] + sigmas[2] * noise[2]
    return np.stack([p[0] + tr * np.cos(p[2] + r1), p[1] + tr * np.sin(p[2] + r1), wrap_np(p[2] + r1 + r2)])


# ---------------------------------------------------------------- deltas and sigmas

def test_odometry_deltas_forward_turn_and_in_place():
    r1, t, r2 = odometry_deltas((1.0, 2.0, 0.5), (1.0 + math.cos(1.0), 2.0 + math.sin(1.0), 0.2))
    assert r1 == pytest.approx(0.5) and t == pytest.approx(1.0) and r2 == pytest.approx(0.2 - 1.0)
    # under 1 cm, rot1 = 0 and rot2 carries the whole turn (AMCL)
    r1, t, r2 = odometry_deltas((0.0, 0.0, 3.0), (0.005, 0.005, -3.0))
    assert r1 == 0.0 and t == pytest.approx(math.hypot(0.005, 0.005))
    assert r2 == pytest.approx(-6.0 + 2 * math.pi)  # wrapped through +-pi


def test_an_odometry_pose_must_be_x_y_theta():
    # a log's odometry row (t, x, y, theta, v, w) was read as its first three: t taken as x, without a word
    with pytest.raises(ValueError, match=r"odom_prev: expected an odometry pose \(x, y, theta\), got shape \(6,\)"):
        odometry_deltas((0.1, 1.0, 2.0, 0.0, 0.3, 0.0), (1.0, 2.0, 0.1))
    with pytest.raises(ValueError, match=r"odom_now: .* got shape \(2,\)"):
        odometry_deltas((1.0, 2.0, 0.1), (1.0, 2.0))


def test_noise_sigmas_both_forms():
    cfg_v, cfg_s = motion_cfg("variance"), motion_cfg("std")
    a1, a2, a3, a4 = 0.1, 0.05, 0.2, 0.03
    r1, t, r2 = 0.3, 0.5, -0.2
    s = noise_sigmas(r1, t, r2, cfg_v)
    assert s == pytest.approx((math.sqrt(a1 * r1**2 + a2 * t**2), math.sqrt(a3 * t**2 + a4 * (r1**2 + r2**2)),
                               math.sqrt(a1 * r2**2 + a2 * t**2)), rel=1e-12)
    s = noise_sigmas(r1, t, r2, cfg_s)
    assert s == pytest.approx((a1 * abs(r1) + a2 * t, a3 * t + a4 * (abs(r1) + abs(r2)), a1 * abs(r2) + a2 * t),
                              rel=1e-12)
    with pytest.raises(ValueError, match="noise_form"):
        noise_sigmas(r1, t, r2, SimpleNamespace(**{**vars(cfg_v), "noise_form": "bogus"}))


def test_reversing_robot_gets_small_noise():
    """Driving backwards: rot1 ~ pi, but the noise uses min(|rot|, |rot - pi|) ~ 0."""
    cfg = motion_cfg()
    back = odometry_deltas((0.0, 0.0, 0.3), (-0.5 * math.cos(0.3), -0.5 * math.sin(0.3), 0.3))
    fwd = odometry_deltas((0.0, 0.0, 0.3), (0.5 * math.cos(0.3), 0.5 * math.sin(0.3), 0.3))
    assert abs(back[0]) == pytest.approx(math.pi) and back[1] == pytest.approx(0.5)
    assert noise_sigmas(*back, cfg) == pytest.approx(noise_sigmas(*fwd, cfg), abs=1e-9)
    # and the sampled headings stay near the start heading (not spread by ~pi)
    rng = np.random.default_rng(7)
    p = np.zeros((3, 20_000))
    p[2] = 0.3
    new, ok, _ = OdometryMotionModel(cfg).sample(p, (0.0, 0.0, 0.3), (-0.5 * math.cos(0.3), -0.5 * math.sin(0.3), 0.3), rng)
    dth = wrap_np(new[2] - 0.3)
    # sigma_rot1 = sigma_rot2 = sqrt(alpha2) * 0.5 ~ 0.11 rad: heading std ~ 0.16 rad
    assert np.std(dth) < 0.25
    assert np.mean(new[0]) == pytest.approx(-0.5 * math.cos(0.3), abs=0.01)


@pytest.mark.parametrize("turn", [1.5, 3.0, math.pi, -2.5])
def test_a_turn_on_the_spot_gets_the_noise_of_its_turn_however_large(turn):
    # Below 1 cm of travel rot1 = 0 and rot2 is the whole turn. AMCL's fold min(|rot|, |rot -+ pi|), meant for a
    # step backwards, folded that turn too: a half turn on the spot (a scan gap, an odometry stall) got no noise at
    # all (sigma_rot2 7e-16 for pi, 0.03 for 3 rad, against 0.70 and 0.67 for sqrt(alpha1) |turn|, Table 5.6).
    cfg = motion_cfg()
    a1, a4 = 0.1, 0.03
    r1, t, r2 = odometry_deltas((0.0, 0.0, 0.2), (0.0, 0.0, 0.2 + turn))
    assert r1 == 0.0 and t == 0.0 and abs(r2) == pytest.approx(abs(turn), abs=1e-12)
    s1, st, s2 = noise_sigmas(r1, t, r2, cfg)
    assert s1 == 0.0 and s2 == pytest.approx(math.sqrt(a1) * abs(turn), rel=1e-9)
    assert st == pytest.approx(math.sqrt(a4) * abs(turn), rel=1e-9)
    rng = np.random.default_rng(3)  # and the sampled headings spread by it (20,000 draws: the std within 2 %)
    p = np.zeros((3, 20_000))
    p[2] = 0.2
    new, _, _ = OdometryMotionModel(cfg).sample(p, (0.0, 0.0, 0.2), (0.0, 0.0, 0.2 + turn), rng)
    spread = np.std(wrap_np(new[2] - 0.2 - r2))
    assert spread == pytest.approx(math.sqrt(a1) * abs(turn), rel=0.02)


# ---------------------------------------------------------------- kernels against NumPy

@pytest.mark.parametrize("form", ["variance", "std"])
def test_kernel_matches_numpy_on_same_noise(form):
    rng = np.random.default_rng(1)
    n = 5000
    p = random_particles(rng, n)
    noise = rng.standard_normal((3, n))
    deltas = odometry_deltas((0.2, -0.1, 0.4), (0.5, 0.3, 1.2))
    sig = noise_sigmas(*deltas, motion_cfg(form))
    out = np.empty_like(p)
    km.sample_odometry(p, noise, *deltas, *sig, out)
    np.testing.assert_allclose(out[:2], numpy_motion(p, noise, deltas, sig)[:2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(wrap_np(out[2] - numpy_motion(p, noise, deltas, sig)[2]), 0.0, atol=1e-12)
    assert np.all(out[2] > -np.pi) and np.all(out[2] <= np.pi)


@pytest.mark.parametrize("odom_now", [(0.7, 0.2, 0.5), (-0.4, 0.1, 0.05), (0.3, -0.6, -2.9), (0.1, 0.0, 2.0)])
def test_zero_alphas_apply_the_odometry_delta_in_the_particle_frame(odom_now):
    """No noise: each particle moves by odom_prev^-1 * odom_now composed onto its own pose."""
    odom_prev = (0.1, 0.0, 0.3)
    rng = np.random.default_rng(2)
    p = random_particles(rng, 1000)
    new, ok, tries = OdometryMotionModel(motion_cfg(alphas=(0, 0, 0, 0))).sample(p, odom_prev, odom_now, rng)
    c, s = math.cos(odom_prev[2]), math.sin(odom_prev[2])
    dx, dy = odom_now[0] - odom_prev[0], odom_now[1] - odom_prev[1]
    lx, ly = c * dx + s * dy, -s * dx + c * dy  # the step in the odometry frame
    dth = odom_now[2] - odom_prev[2]
    exp_x = p[0] + np.cos(p[2]) * lx - np.sin(p[2]) * ly
    exp_y = p[1] + np.sin(p[2]) * lx + np.cos(p[2]) * ly
    np.testing.assert_allclose(new[0], exp_x, atol=1e-12)
    np.testing.assert_allclose(new[1], exp_y, atol=1e-12)
    np.testing.assert_allclose(wrap_np(new[2] - (p[2] + dth)), 0.0, atol=1e-12)
    assert ok.all() and tries == 1.0


@pytest.mark.parametrize("form", ["variance", "std"])
def test_sampled_noise_matches_closed_form_variances(form):
    """Recover (rot1, trans, rot2) from 200,000 moved particles; compare moments with the sigmas.

    Tolerance: the standard error of a sample variance of N normals is
    sigma^2 * sqrt(2 / (N - 1)) (0.32 % at N = 200,000); we allow 5 SE. Means
    within 5 sigma / sqrt(N). A KS test of the standardised noise at p > 1e-3.
    """
    cfg = motion_cfg(form, alphas=(0.1, 0.05, 0.01, 0.03))  # small alpha3: trans_hat stays > 0 (6 sigma)
    deltas = (0.3, 0.5, -0.2)
    odom_now = (0.5 * math.cos(0.3), 0.5 * math.sin(0.3), 0.1)  # from (0, 0, 0)
    assert odometry_deltas((0, 0, 0), odom_now) == pytest.approx(deltas)
    sig = noise_sigmas(*deltas, cfg)
    n = 200_000
    rng = np.random.default_rng(12345)
    new, _, _ = OdometryMotionModel(cfg).sample(np.zeros((3, n)), (0.0, 0.0, 0.0), odom_now, rng)
    trans = np.hypot(new[0], new[1])
    rot1 = np.arctan2(new[1], new[0])
    assert np.abs(rot1 - deltas[0]).max() < 1.0  # no trans_hat < 0 (that would flip rot1 by pi)
    rot2 = wrap_np(new[2] - rot1)
    for sample, mean, sd in ((rot1, deltas[0], sig[0]), (trans, deltas[1], sig[1]), (rot2, deltas[2], sig[2])):
        err = sample - mean
        assert abs(err.mean()) < 5 * sd / math.sqrt(n)
        assert err.var(ddof=1) == pytest.approx(sd**2, rel=5 * math.sqrt(2 / (n - 1)))
        assert stats.kstest(err / sd, "norm").pvalue > 1e-3


@given(st.floats(-1e3, 1e3, allow_nan=False))
@settings(max_examples=300, deadline=None)
def test_wrap_is_in_half_open_interval(a):
    w = km.wrap(a)
    assert -math.pi < w <= math.pi
    k = (a - w) / (2 * math.pi)
    assert abs(k - round(k)) < 1e-9


# ---------------------------------------------------------------- map-based motion model

def corridor_grid():
    """20 x 100 cells of 0.1 m, origin (-5, -1): a free corridor in rows 8..11 (y in [-0.2, 0.2)), walls elsewhere."""
    occ = np.full((20, 100), 100, dtype=np.int8)
    occ[8:12, :] = 0
    occ[8:12, 60:65] = -1  # an unknown patch inside the corridor: not allowed
    return OccupancyGrid.from_occupancy(occ, 0.1, (-5.0, -1.0))


def numpy_allowed(grid, mask, x, y):
    ix = np.floor((x - grid.origin[0]) / grid.resolution).astype(np.int64)
    iy = np.floor((y - grid.origin[1]) / grid.resolution).astype(np.int64)
    inside = (ix >= 0) & (ix < mask.shape[1]) & (iy >= 0) & (iy < mask.shape[0])
    res = np.zeros(x.shape, dtype=bool)
    res[inside] = mask[iy[inside], ix[inside]] != 0
    return res


def test_allowed_mask_is_free_and_clear_of_walls():
    g = corridor_grid()
    m0 = allowed_mask(g, 0.0)
    assert m0.dtype == np.uint8
    np.testing.assert_array_equal(m0 != 0, g.free)
    m1 = allowed_mask(g, 0.15)  # only the two middle rows are more than 0.15 m from a wall cell centre
    assert not m1[8].any() and not m1[11].any() and m1[9, 0:60].all() and m1[10, 0:60].all()
    assert not m1[9:11, 60:65].any()


def test_map_kernel_matches_numpy_on_same_noise():
    g = corridor_grid()
    mask = allowed_mask(g, 0.0)
    rng = np.random.default_rng(3)
    n = 4000
    p = np.stack([rng.uniform(-5.5, 5.5, n), rng.uniform(-1.2, 1.2, n), rng.uniform(-np.pi, np.pi, n)])
    noise = rng.standard_normal((3, n))
    idx = np.sort(rng.choice(n, size=n // 2, replace=False)).astype(np.int64)
    deltas, sig = (0.1, 0.3, -0.05), (0.2, 0.1, 0.05)
    out = np.full_like(p, np.nan)
    ok = np.zeros(n, dtype=bool)
    n_ok = km.sample_odometry_map(p, noise[:, :idx.size], idx, *deltas, *sig, mask,
                                  g.origin[0], g.origin[1], 1.0 / g.resolution, out, ok)
    ref = numpy_motion(p[:, idx], noise[:, :idx.size], deltas, sig)
    np.testing.assert_allclose(out[:2, idx], ref[:2], atol=1e-12)
    exp_ok = numpy_allowed(g, mask, ref[0], ref[1])
    np.testing.assert_array_equal(ok[idx], exp_ok)
    assert n_ok == exp_ok.sum() and 0 < n_ok < idx.size
    untouched = np.setdiff1d(np.arange(n), idx)
    assert np.isnan(out[:, untouched]).all() and not ok[untouched].any()


def test_map_rejection_matches_numpy_retry_loop():
    """The whole sample() with a map against a NumPy retry loop drawing from the same seed."""
    g = corridor_grid()
    mask = allowed_mask(g, 0.0)
    cfg = motion_cfg(alphas=(0.5, 0.5, 0.5, 0.5), max_tries=6)
    n = 3000
    rng0 = np.random.default_rng(4)
    p = np.stack([rng0.uniform(-4, 4, n), rng0.uniform(-0.19, 0.19, n), rng0.normal(0, 0.2, n)])
    odom_prev, odom_now = (0.0, 0.0, 0.0), (0.3, 0.05, 0.2)
    new, ok, tries = OdometryMotionModel(cfg).sample(p, odom_prev, odom_now, np.random.default_rng(99),
                                                     allowed=mask, grid=g)
    rng = np.random.default_rng(99)
    deltas = odometry_deltas(odom_prev, odom_now)
    sig = noise_sigmas(*deltas, cfg)
    ref = numpy_motion(p, rng.standard_normal((3, n)), deltas, sig)
    ref_ok = numpy_allowed(g, mask, ref[0], ref[1])
    draws = n
    for _ in range(cfg.max_tries - 1):
        idx = np.flatnonzero(~ref_ok)
        if idx.size == 0:
            break
        draws += idx.size
        ref[:, idx] = numpy_motion(p[:, idx], rng.standard_normal((3, idx.size)), deltas, sig)
        ref_ok[idx] = numpy_allowed(g, mask, ref[0, idx], ref[1, idx])
    np.testing.assert_allclose(new[:2], ref[:2], atol=1e-12)
    np.testing.assert_array_equal(ok, ref_ok)
    assert tries == pytest.approx(draws / n) and tries > 1.2  # the corridor rejects a good share


def test_map_rejection_leaves_no_particle_outside_free_space():
    """Noisy motion in a 0.4 m corridor: with enough tries every particle lands on an allowed cell."""
    g = corridor_grid()
    mask = allowed_mask(g, 0.0)
    cfg = motion_cfg(alphas=(0.3, 0.3, 0.3, 0.3), max_tries=100)
    rng = np.random.default_rng(5)
    n = 20_000
    p = np.stack([rng.uniform(-4, 0, n), rng.uniform(-0.15, 0.15, n), rng.normal(0, 0.1, n)])
    new, ok, tries = OdometryMotionModel(cfg).sample(p, (0, 0, 0), (0.5, 0.0, 0.0), rng, allowed=mask, grid=g)
    assert ok.all()
    assert numpy_allowed(g, mask, new[0], new[1]).all()
    assert tries > 1.0  # some first tries hit the walls or the unknown patch
    # without the map the same motion puts many particles into the walls
    free, _, _ = OdometryMotionModel(cfg).sample(p, (0, 0, 0), (0.5, 0.0, 0.0), np.random.default_rng(5))
    assert (~numpy_allowed(g, mask, free[0], free[1])).mean() > 0.05


def test_particle_that_cannot_reach_free_space_is_not_ok():
    g = corridor_grid()
    mask = allowed_mask(g, 0.0)
    cfg = motion_cfg(alphas=(0.001, 0.001, 0.001, 0.001), max_tries=5)
    p = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, math.pi / 2]])  # the second faces the wall
    rng = np.random.default_rng(6)
    new, ok, tries = OdometryMotionModel(cfg).sample(p, (0, 0, 0), (0.5, 0.0, 0.0), rng, allowed=mask, grid=g)
    assert ok.tolist() == [True, False]
    assert tries == pytest.approx((1 + 5) / 2)  # the first lands at once, the second uses all 5 tries
    assert new[1, 1] > 0.2  # its last try, inside the wall (y >= 0.2 is occupied)


def test_map_without_grid_is_an_error():
    with pytest.raises(ValueError, match="grid"):
        OdometryMotionModel(motion_cfg()).sample(np.zeros((3, 2)), (0, 0, 0), (1, 0, 0),
                                                  np.random.default_rng(0), allowed=np.ones((2, 2), np.uint8))


def test_same_result_with_one_and_two_threads():
    g = corridor_grid()
    mask = allowed_mask(g, 0.0)
    cfg = motion_cfg(alphas=(0.3, 0.3, 0.3, 0.3))
    p = np.stack([np.linspace(-4, 4, 50_000), np.zeros(50_000), np.zeros(50_000)])
    results = []
    saved = numba.get_num_threads()
    try:
        for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(threads)
            m = OdometryMotionModel(cfg)
            a = m.sample(p, (0, 0, 0), (0.4, 0.1, 0.3), np.random.default_rng(8), allowed=mask, grid=g)
            b = m.sample(p, (0, 0, 0), (0.4, 0.1, 0.3), np.random.default_rng(8))
            results.append((a[0].copy(), a[1].copy(), a[2], b[0].copy()))
    finally:
        numba.set_num_threads(saved)
    (a0, ok0, t0, b0), (a1, ok1, t1, b1) = results
    assert np.array_equal(a0, a1) and np.array_equal(ok0, ok1) and t0 == t1 and np.array_equal(b0, b1)


def test_the_odometry_scale_learns_what_the_scans_keep_adding():
    # motion.scale_window: the odometry reads 5 % short (the robot goes 1.05 d); a scan that pins the pose shifts the
    # cloud by what the scaled step missed, (1.05 - k) d, so the scale the scans see is 1.05 and k goes there. Along a
    # featureless stretch (no shift) k holds; it never leaves 1 +- scale_limit.
    from mcl.adaptive import OdometryScale
    from mcl.filter import Control

    s = OdometryScale(window=50.0, prior=10.0, limit=0.15)
    for _ in range(1000):  # 100 m in 0.1 m steps
        s.observe((1.05 - s.k) * 0.1, 0.1, s.k)
    assert s.k == pytest.approx(1.05, abs=0.002)  # the prior's 10 m at scale 1 forgotten over the 50 m window
    held = s.k
    for _ in range(500):
        s.observe(0.0, 0.1, s.k)  # a featureless corridor: the scans shift nothing along it
    assert s.k == pytest.approx(held, abs=1e-9)
    young = OdometryScale(window=50.0, prior=10.0, limit=0.15)
    bare = OdometryScale(window=50.0, prior=0.0, limit=0.15)
    for _ in range(50):  # 5 m: the prior's 10 m (9.05 m left after forgetting) still weigh nearly twice the travel
        young.observe((1.05 - young.k) * 0.1, 0.1, young.k)
        bare.observe((1.05 - bare.k) * 0.1, 0.1, bare.k)
    # 1.0172 (computed; a prior left out gives 1.05, one never forgotten 1.0167, a sign error under 1)
    assert young.k == pytest.approx(1.0172, abs=0.0003)
    assert bare.k == pytest.approx(1.05)  # no prior: the scans' scale from the first step
    capped = OdometryScale(window=50.0, prior=10.0, limit=0.15)
    for _ in range(2000):
        capped.observe((1.4 - capped.k) * 0.1, 0.1, capped.k)
    assert capped.k == pytest.approx(1.15)
    # the motion model gets the step stretched in x, y (not the rotations) and v
    s.k = 1.1
    c = s.scaled(Control(np.array([1.0, 2.0, 0.3]), np.array([2.0, 4.0, 0.5]), dt=0.2, v=1.0, w=0.1))
    assert c.odom_prev.tolist() == [1.0, 2.0, 0.3] and c.odom_now == pytest.approx([2.1, 4.2, 0.5])
    assert c.v == pytest.approx(1.1) and c.w == 0.1 and c.dt == 0.2


def test_noise_step_makes_a_long_step_a_random_walk_of_short_ones():
    """motion.noise_step: one straight 1 m step gives the heading and the travel the variance of five 0.2 m steps.

    Table 5.6's variance grows as dtrans^2, so one 1 m step has five times the heading variance of five 0.2 m steps
    (2 alpha2 dtrans^2 against 5 x 2 alpha2 0.2^2). With noise_step 0.2 both are 2 alpha2 x 0.2. 100,000 particles,
    N(0, 1) noise: a sample variance's standard error is sqrt(2 / N) = 0.45 %; we allow 5 SE, and the book's single
    step (5x the variance) must be outside it.
    """
    alphas = (0.1, 0.05, 0.01, 0.03)
    walk = motion_cfg(alphas=alphas)
    walk.noise_step = 0.2
    book = motion_cfg(alphas=alphas)
    n = 100_000
    tol = 5 * math.sqrt(2 / n)

    def moved(cfg, steps):
        rng = np.random.default_rng(7)
        p = np.zeros((3, n))
        model = OdometryMotionModel(cfg)
        for k in range(steps):
            p, _, _ = model.sample(p, (k / steps, 0.0, 0.0), ((k + 1) / steps, 0.0, 0.0), rng)
        return p

    one, five, one_book = moved(walk, 1), moved(walk, 5), moved(book, 1)
    assert noise_sigmas(0.0, 1.0, 0.0, walk)[0] == pytest.approx(math.sqrt(alphas[1] * 0.2))
    assert noise_sigmas(0.0, 0.2, 0.0, walk) == noise_sigmas(0.0, 0.2, 0.0, book)  # short steps: the book's
    heading = 2 * alphas[1] * 0.2  # rot1 and rot2, each alpha2 * 0.2 m * 1 m
    for p in (one, five):
        assert wrap_np(p[2]).var() == pytest.approx(heading, rel=tol)
        assert np.hypot(p[0], p[1]).var() == pytest.approx(alphas[2] * 0.2, rel=0.05)  # travel; heading adds ~1 %
    assert wrap_np(one_book[2]).var() == pytest.approx(5 * heading, rel=tol)


@pytest.mark.parametrize("model", ["odometry", "omni", "velocity"])
def test_a_filled_step_has_its_travel_widened_by_fill_spread(model):
    """A step the stall fill took from scan matching (``Control.filled``) moves with its travel's std widened to
    hypot(sigma, fill_spread * travel); the heading noise is the model's own. 200,000 particles from one seed
    each way: the travel's std within 5 standard errors of the sample std (5 * sigma / sqrt(2 (N - 1)), 0.8 %); the
    same noise draws give the same headings to the last bit. Without the flag (or with fill_spread 0) the step is
    the plain model's."""
    from mcl.filter import Control
    from mcl.motion import VelocityMotionModel, velocity_sigmas

    n, spread = 200_000, 0.2  # a travel of 1 m never drawn below 0 (4.5 sigma): its hypot is its size
    if model == "odometry":
        cfg = motion_cfg("variance", alphas=(0.1, 0.05, 0.01, 0.03))
        mm, control = OdometryMotionModel(cfg), Control(np.zeros(3), np.array([1.0, 0.0, 0.0]))
        sigma = noise_sigmas(*odometry_deltas((0, 0, 0), (1.0, 0.0, 0.0)), cfg)[1]
    elif model == "omni":  # the travel along x: its std is sigma_trans; sigma_strafe (across, y) stays
        from mcl.motion import OmniMotionModel, omni_sigmas

        cfg = motion_cfg("variance", alphas=(0.1, 0.05, 0.01, 0.03))
        cfg.alpha_strafe = 0.01
        mm, control = OmniMotionModel(cfg), Control(np.zeros(3), np.array([1.0, 0.0, 0.0]))
        sigma = omni_sigmas(1.0, 0.0, cfg)[0]
    else:
        cfg = SimpleNamespace(model="velocity", noise_form="variance", noise="normal", max_tries=10,
                              alpha1=0.01, alpha2=0.0, alpha3=0.0, alpha4=0.0, alpha5=0.0, alpha6=0.0)
        control = Control(np.zeros(3), np.array([1.0, 0.0, 0.0]), dt=1.0, v=1.0, w=0.0)
        mm, sigma = VelocityMotionModel(cfg), velocity_sigmas(1.0, 0.0, cfg)[0]
    cfg.fill_spread = spread

    def moved(filled):
        new, _, _ = mm.sample_control(np.zeros((3, n)), dataclasses.replace(control, filled=filled),
                                      np.random.default_rng(7))
        return new

    plain, filled = moved(False), moved(True)
    want = math.hypot(sigma, spread * 1.0)
    for new, sd in ((plain, sigma), (filled, want)):
        travel = new[0] if model == "omni" else np.hypot(new[0], new[1])  # omni: y is the strafe's
        assert travel.std(ddof=1) == pytest.approx(sd, rel=5 / math.sqrt(2 * (n - 1)))
    np.testing.assert_array_equal(filled[2], plain[2])
    if model == "omni":  # across the travel: the strafe's noise alone, drawn the same
        np.testing.assert_array_equal(filled[1], plain[1])
    cfg.fill_spread = 0.0
    np.testing.assert_array_equal(moved(True), plain)


def test_an_out_buffer_of_another_shape_is_refused_not_written_past():
    # mm.sample(P, u0, u1, rng, out=np.empty((3, 10))) for 20,000 particles wrote past the buffer: a segfault
    model = OdometryMotionModel(motion_cfg())
    p = random_particles(np.random.default_rng(0), 200)
    u0, u1 = (0.0, 0.0, 0.0), (0.3, 0.0, 0.1)
    for bad in (np.empty((3, 10)), np.empty((3, 200), dtype=np.float32), np.empty((200, 3)).T):
        with pytest.raises(ValueError, match=r"^out: expected a writeable C-contiguous float64 array of shape \(3, 200\)"):
            model.sample(p, u0, u1, np.random.default_rng(1), out=bad)
    out = np.empty((3, 200))
    new, ok, _ = model.sample(p, u0, u1, np.random.default_rng(1), out=out)
    assert new is out and ok.all()


def test_a_velocity_model_given_only_the_odometry_pair_moves_by_it():
    """The README's Python loop makes ``Control(prev.odom, scan.odom, dt=...)`` (no v, w): with
    ``motion.model=velocity`` that moved no particle at all (v = w = 0), and the run drifted 0.5 rad off without a
    word. The velocities now come from the odometry pair as a log without tv / rv gives them (an arc of the pair's
    length and turn). Noise-free model: the particle ends where the odometry did, 0.5 m ahead along 0.1 rad turning
    0.2 rad, within 1 mm (an arc of length 0.5 m ends 0.8 mm short of its chord's 0.5 m) and its heading within
    1e-9."""
    from mcl.filter import Control
    from mcl.motion import VelocityMotionModel, velocities_from_odometry

    cfg = SimpleNamespace(model="velocity", noise_form="variance", noise="normal", max_tries=10, alpha1=0.0,
                          alpha2=0.0, alpha3=0.0, alpha4=0.0, alpha5=0.0, alpha6=0.0)
    end = np.array([0.5 * np.cos(0.1), 0.5 * np.sin(0.1), 0.2])
    u = Control(np.zeros(3), end, dt=0.2)
    assert u.velocities() == pytest.approx(velocities_from_odometry(np.zeros(3), end, 0.2))
    new, ok, _ = VelocityMotionModel(cfg).sample_control(np.zeros((3, 4)), u, np.random.default_rng(0))
    assert ok.all()
    np.testing.assert_allclose(new[0], end[0], atol=1e-3)  # the arc's end vs the chord's: 0.5 * (1 - sinc) ~ 1e-4
    np.testing.assert_allclose(new[1], end[1], atol=1e-3)
    np.testing.assert_allclose(new[2], 0.2, atol=1e-9)
    # given velocities are used as given
    assert Control(np.zeros(3), end, dt=0.2, v=1.0, w=0.0).velocities() == (1.0, 0.0, 0.2)


@pytest.mark.parametrize("form", ["variance", "std"])
def test_the_heading_noise_a_turn_adds_is_alpha1s_alone(form):
    # sensor.unmapped_turn_sigmas reads it: Table 5.6's sigma_rot1 and sigma_rot2 with the translation left out. A turn
    # on the spot of 0.4 rad (rot1 0, rot2 0.4): sqrt(alpha1) 0.4 (variance) or alpha1 0.4 (std); a straight step
    # none, however long (alpha2's heading noise is the travel's); an arc of 0.4 rad over 1 m splits the turn into
    # rot1 = rot2 = 0.2. The omni model: its sigma_rot of the turn alone, none on a strafing step, which the
    # differential-drive model reads as rot1 = pi/2, rot2 = -pi/2.
    from mcl.motion import OmniMotionModel

    cfg = SimpleNamespace(alpha1=0.05, alpha2=0.2, alpha3=0.1, alpha4=0.1, alpha_strafe=0.1, noise_form=form,
                          noise_step=0.3, max_tries=10)
    odo, omni = OdometryMotionModel(cfg), OmniMotionModel(cfg)
    one = (lambda r: math.sqrt(0.05) * r) if form == "variance" else (lambda r: 0.05 * r)
    assert odo.turn_heading_std(np.array([0.0, 0.0, 0.4])) == pytest.approx(one(0.4))
    assert odo.turn_heading_std(np.array([1.0, 0.0, 0.0])) == 0.0
    arc = np.array([math.sin(0.4) / 0.4, (1.0 - math.cos(0.4)) / 0.4, 0.4])  # 1 m along a 0.4 rad arc
    assert odo.turn_heading_std(arc) == pytest.approx(math.hypot(one(0.2), one(0.2)))
    assert omni.turn_heading_std(np.array([0.3, 0.2, -0.4])) == pytest.approx(one(0.4))
    assert omni.turn_heading_std(np.array([0.0, 1.0, 0.0])) == 0.0
    assert odo.turn_heading_std(np.array([0.0, 1.0, 0.0])) == pytest.approx(math.hypot(one(math.pi / 2),
                                                                                          one(math.pi / 2)))
