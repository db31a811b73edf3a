"""Closed-form motion densities (Prob. Rob. Tables 5.1, 5.5, section 5.5) against their samplers.

* Normalisation: the pose densities (``jacobian=True``) integrate to 1 within
  1 % over a grid in (x', y', theta') around a small motion (the issue's
  requirement); the midpoint rule on these grids is accurate to about 0.1 %.
* Sampler vs density: 10^6 samples of the sampler binned into 6 x 6 x 6 boxes
  (in whitened coordinates, see ``chi2_samples_vs_density``) plus one
  "outside" bin; expected counts from the density integrated over each box
  (7^3 midpoints per box: with 5^3 the quadrature error alone, about 1 %,
  already fails the test at this sample size). Chi-square, fixed seed,
  threshold p > 1e-3; the same test rejects alphas 10 % off with p < 1e-10.
* The book's value (``jacobian=False``) against a literal scalar transcription
  of Table 5.5.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from mcl.maps import OccupancyGrid
from mcl.motion import (OdometryMotionModel, VelocityMotionModel, allowed_mask, log_motion_model_odometry,
                        log_motion_model_velocity, motion_model_odometry, motion_model_velocity,
                        motion_model_with_map)
from mcl.noise import prob_normal


def cfg(model="odometry", noise_form="variance", noise="normal", alphas=(0.05, 0.02, 0.05, 0.02, 0.01, 0.005)):
    return SimpleNamespace(model=model, noise_form=noise_form, noise=noise, max_tries=10, robot_radius=0.0,
                           map_rejection=False, **{f"alpha{k + 1}": a for k, a in enumerate(alphas)})


ODOM = (np.array([1.0, 2.0, 0.3]), np.array([1.0 + 0.25 * math.cos(0.35), 2.0 + 0.25 * math.sin(0.35), 0.45]))
X0 = np.array([-0.5, 0.4, 1.2])  # the particle: the odometry step is applied in its frame
VEL = (0.5, 0.3, 1.0)  # v, w, dt


def box_grid(center, half, n):
    axes = [np.linspace(c - h, c + h, n) for c, h in zip(center, half)]
    step = [a[1] - a[0] for a in axes]
    g = np.meshgrid(*axes, indexing="ij")
    return np.stack([x.ravel() for x in g]), float(np.prod(step))


def ideal_odometry():
    rot1 = math.atan2(ODOM[1][1] - ODOM[0][1], ODOM[1][0] - ODOM[0][0]) - ODOM[0][2]
    trans = math.hypot(ODOM[1][0] - ODOM[0][0], ODOM[1][1] - ODOM[0][1])
    h = X0[2] + rot1
    return np.array([X0[0] + trans * math.cos(h), X0[1] + trans * math.sin(h), X0[2] + ODOM[1][2] - ODOM[0][2]])


def ideal_velocity():
    v, w, dt = VEL
    r = v / w
    return np.array([X0[0] - r * math.sin(X0[2]) + r * math.sin(X0[2] + w * dt),
                     X0[1] + r * math.cos(X0[2]) - r * math.cos(X0[2] + w * dt), X0[2] + w * dt])


# ----------------------------------------------------------------------- normalisation


@pytest.mark.parametrize("noise", ["normal", "normal_twelve", "triangular"])
@pytest.mark.parametrize("noise_form", ["variance", "std"])
def test_odometry_density_integrates_to_one(noise, noise_form):
    c = cfg(noise_form=noise_form, noise=noise, alphas=(0.05, 0.02, 0.05, 0.02, 0, 0) if noise_form == "variance"
            else (0.1, 0.08, 0.1, 0.05, 0, 0))
    # 101^3 poses: the integrals below agree with 161^3 to 0.0026 (triangular's kinks) and under 0.0003 otherwise, at
    # a fifth of the time (normal_twelve took 8 s a case at 161^3)
    pts, vol = box_grid(ideal_odometry(), (0.3, 0.3, 0.35), 101)
    p = motion_model_odometry(pts, ODOM, X0, c)
    total = p.sum() * vol
    assert total == pytest.approx(1.0, abs=0.01), total
    # the book's value (no Jacobian) integrates to about the travelled distance instead
    q = motion_model_odometry(pts, ODOM, X0, c, jacobian=False)
    assert q.sum() * vol == pytest.approx(0.25, rel=0.05)
    # With the stds from the hypothesis (Table 5.5) the value is a density of the odometry reading,
    # not of x': over poses it integrates to 1.17-1.18 (variance) / 1.034-1.037 (std) here, not to 1
    # (a deterministic grid sum: the tolerance only covers the three noise kinds).
    h = motion_model_odometry(pts, ODOM, X0, c, sigma_from="hypothesis").sum() * vol
    assert h == pytest.approx(1.175 if noise_form == "variance" else 1.035, abs=0.01), h


@pytest.mark.parametrize("noise", ["normal", "normal_twelve", "triangular"])
@pytest.mark.parametrize("noise_form", ["variance", "std"])
def test_velocity_density_integrates_to_one(noise, noise_form):
    alphas = (0.01, 0.005, 0.01, 0.005, 0.002, 0.001) if noise_form == "variance" else (0.1, 0.05, 0.1, 0.05, 0.04, 0.02)
    c = cfg("velocity", noise_form, noise, alphas)
    pts, vol = box_grid(ideal_velocity(), (0.2, 0.2, 0.3), 121)
    total = motion_model_velocity(pts, VEL, X0, c).sum() * vol
    assert total == pytest.approx(1.0, abs=0.01), total


# ----------------------------------------------------------------------- samplers vs densities


def chi2_samples_vs_density(samples, logpdf, center, nb=6, sub=7, half=2.0):
    """Chi-square p of samples (3, n) against a pose density, and the expected fraction outside the boxes.

    The clouds are thin and curved (theta' is strongly correlated with the
    lateral position), so the boxes are laid out in whitened coordinates
    z = L^-1 (x - center), L the Cholesky factor of the sample covariance:
    nb^3 boxes over [-half, half]^3 in z plus one bin for everything outside;
    the density of z is the pose density times det L.
    """
    L = np.linalg.cholesky(np.cov(samples))
    z = np.linalg.solve(L, samples - center[:, None])
    edges = np.linspace(-half, half, nb + 1)
    idx = [np.digitize(z[k], edges) - 1 for k in range(3)]
    inside = np.all([(i >= 0) & (i < nb) for i in idx], axis=0)
    flat = (idx[0] * nb + idx[1]) * nb + idx[2]
    counts = np.bincount(flat[inside], minlength=nb ** 3).astype(float)
    w = edges[1] - edges[0]
    fine = (edges[:-1, None] + (np.arange(sub) + 0.5)[None, :] * w / sub).ravel()  # midpoints, box-major
    g = np.meshgrid(fine, fine, fine, indexing="ij")
    zf = np.stack([x.ravel() for x in g])
    dens = np.exp(logpdf(center[:, None] + L @ zf)) * np.linalg.det(L)
    probs = dens.reshape(nb, sub, nb, sub, nb, sub).sum(axis=(1, 3, 5)).ravel() * (w / sub) ** 3
    n = samples.shape[1]
    obs = np.append(counts, n - counts.sum())
    exp = np.append(probs, 1.0 - probs.sum()) * n
    assert np.all(exp > 5), exp.min()
    return stats.chisquare(obs, exp * n / exp.sum()).pvalue, exp[-1] / n


@pytest.mark.parametrize("noise_form", ["variance", "std"])
def test_odometry_sampler_matches_the_closed_form(noise_form):
    c = cfg(noise_form=noise_form, alphas=(0.05, 0.02, 0.05, 0.02, 0, 0) if noise_form == "variance"
            else (0.1, 0.08, 0.1, 0.05, 0, 0))
    n = 1_000_000
    x = np.tile(X0[:, None], (1, n))
    s, ok, _ = OdometryMotionModel(c).sample(x, *ODOM, np.random.default_rng(42))
    mean = ideal_odometry()
    p, outside = chi2_samples_vs_density(
        s, lambda pts: log_motion_model_odometry(pts, ODOM, X0, c, sigma_from="odometry"), mean)
    assert p > 1e-3, p
    # the same test detects a density with 10 % wrong alphas (so it can fail)
    c2 = cfg(noise_form=noise_form, alphas=tuple(1.1 * getattr(c, f"alpha{k}") for k in range(1, 7)))
    p2, _ = chi2_samples_vs_density(
        s, lambda pts: log_motion_model_odometry(pts, ODOM, X0, c2, sigma_from="odometry"), mean)
    assert p2 < 1e-10


def test_odometry_density_of_a_turn_on_the_spot_is_the_samplers():
    # The odometry reads a 1 rad turn with 5 mm of creep (under the filter's 1 cm rule: rot1 = 0, the creep along the
    # heading). The sampler moves every particle along its heading, never sideways; the density gave a pose 5 mm to
    # the side as much as one 5 mm ahead (the rule applied to the hypotheses too). Now: the sideways pose ~0, and the
    # probability of a box around the samples' median is the sampler's fraction (300,000 samples; a fraction of
    # ~0.006 has a standard error of 2.5 %, so 15 % is a wide margin; the defect gave 3-9 times the fraction).
    c = cfg(alphas=(0.05, 0.05, 0.05, 0.05, 0, 0))
    z = np.zeros(3)
    now = np.array([0.005, 0.0, 1.0])
    ahead, side = np.array([[0.005], [0.0], [1.0]]), np.array([[0.0], [0.005], [1.0]])
    p_ahead = math.exp(log_motion_model_odometry(ahead, (z, now), z, c)[0])
    p_side = math.exp(log_motion_model_odometry(side, (z, now), z, c)[0])
    assert p_ahead > 1e4 and p_side < 1e-6 * p_ahead, (p_ahead, p_side)
    rng = np.random.default_rng(3)
    n = 300_000
    s, _, _ = OdometryMotionModel(c).sample(np.zeros((3, n)), z, now, rng)
    assert np.abs(s[1]).max() < 0.004  # never 5 mm to the side
    m, h = np.median(s, axis=1), 0.1 * s.std(axis=1)
    sampled = np.all(np.abs(s - m[:, None]) < h[:, None], axis=0).mean()
    u = m[:, None] + h[:, None] * rng.uniform(-1.0, 1.0, (3, n))  # Monte Carlo integral of the density over the box
    integral = np.exp(log_motion_model_odometry(u, (z, now), z, c)).mean() * np.prod(2.0 * h)
    assert abs(integral / sampled - 1.0) < 0.15, (integral, sampled)


def test_velocity_sampler_matches_the_closed_form():
    c = cfg("velocity", alphas=(0.01, 0.005, 0.01, 0.005, 0.002, 0.001))
    n = 1_000_000
    x = np.tile(X0[:, None], (1, n))
    s, ok, _ = VelocityMotionModel(c).sample(x, *VEL, np.random.default_rng(43))
    p, _ = chi2_samples_vs_density(s, lambda pts: log_motion_model_velocity(pts, VEL, X0, c), ideal_velocity())
    assert p > 1e-3, p
    c2 = cfg("velocity", alphas=(0.011, 0.0055, 0.011, 0.0055, 0.0022, 0.0011))
    p2, _ = chi2_samples_vs_density(s, lambda pts: log_motion_model_velocity(pts, VEL, X0, c2), ideal_velocity())
    assert p2 < 1e-10


# ----------------------------------------------------------------------- the book's value, angles, options


def book_table_5_5(xn, u, xp, a):
    """Table 5.5 for one hypothesis, literally (variance form, stds from the hypothesis), normal noise."""
    (ox, oy, ot), (ox2, oy2, ot2) = u

    def wrap(q):
        return math.atan2(math.sin(q), math.cos(q))

    r1 = wrap(math.atan2(oy2 - oy, ox2 - ox) - ot)
    tr = math.hypot(ox - ox2, oy - oy2)
    r2 = wrap(ot2 - ot - r1)
    h1 = wrap(math.atan2(xn[1] - xp[1], xn[0] - xp[0]) - xp[2])
    ht = math.hypot(xp[0] - xn[0], xp[1] - xn[1])
    h2 = wrap(xn[2] - xp[2] - h1)
    p1 = prob_normal(wrap(r1 - h1), math.sqrt(a[0] * h1 ** 2 + a[1] * ht ** 2))
    p2 = prob_normal(tr - ht, math.sqrt(a[2] * ht ** 2 + a[3] * (h1 ** 2 + h2 ** 2)))
    p3 = prob_normal(wrap(r2 - h2), math.sqrt(a[0] * h2 ** 2 + a[1] * ht ** 2))
    return p1 * p2 * p3


def test_book_value_against_a_literal_transcription():
    c = cfg()
    rng = np.random.default_rng(5)
    hyp = ideal_odometry()[:, None] + rng.normal(0, [[0.03], [0.03], [0.05]], (3, 200))
    got = motion_model_odometry(hyp, ODOM, X0, c, sigma_from="hypothesis", jacobian=False)
    ref = [book_table_5_5(hyp[:, i], ODOM, X0, (0.05, 0.02, 0.05, 0.02)) for i in range(200)]
    np.testing.assert_allclose(got, ref, rtol=1e-10)
    # the pose density is the book's value over the hypothesised translation
    trans = np.hypot(hyp[0] - X0[0], hyp[1] - X0[1])
    np.testing.assert_allclose(motion_model_odometry(hyp, ODOM, X0, c, sigma_from="hypothesis"), np.array(ref) / trans,
                               rtol=1e-10)


def test_angles_are_wrapped():
    c = cfg()
    h = ideal_odometry()[:, None] + np.array([[0.01], [-0.01], [0.02]])
    base = log_motion_model_odometry(h, ODOM, X0, c)
    for k in (-1, 1, 3):
        shifted = h + np.array([[0.0], [0.0], [2 * math.pi * k]])
        np.testing.assert_allclose(log_motion_model_odometry(shifted, ODOM, X0 + [0, 0, -2 * math.pi * k], c), base,
                                   rtol=1e-9)
    hv = ideal_velocity()[:, None] + np.array([[0.01], [-0.01], [0.02]])
    np.testing.assert_allclose(log_motion_model_velocity(hv + [[0], [0], [2 * math.pi]], VEL, X0, c),
                               log_motion_model_velocity(hv, VEL, X0, c), rtol=1e-9)


def test_backward_creep_costs_translation_not_pi():
    # turning on the spot; odometry crept 1.5 cm backwards, so its rot1 reads pi
    c = cfg()
    u = (np.zeros(3), np.array([-0.015, 0.0, 0.3]))
    hyp = np.array([[0.0], [0.0], [0.3]])
    lp = log_motion_model_odometry(hyp, u, np.zeros(3), c, jacobian=False)
    assert np.isfinite(lp[0]) and lp[0] > -50


def test_vectorised_equals_one_by_one_and_log_equals_log_of_density():
    c = cfg()
    rng = np.random.default_rng(8)
    hyp = ideal_odometry()[:, None] + rng.normal(0, 0.05, (3, 50))
    xp = X0[:, None] + rng.normal(0, 0.01, (3, 50))
    allv = log_motion_model_odometry(hyp, ODOM, xp, c)
    one = [log_motion_model_odometry(hyp[:, i], ODOM, xp[:, i], c)[0] for i in range(50)]
    np.testing.assert_allclose(allv, one, rtol=1e-12)
    np.testing.assert_allclose(np.exp(allv), motion_model_odometry(hyp, ODOM, xp, c), rtol=1e-12)


def test_map_based_density():
    occ = np.zeros((60, 60), dtype=np.int8)
    occ[:, 35:] = 100  # wall from x = 1.75 m
    grid = OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))
    c = cfg()
    u = (np.zeros(3), np.array([0.5, 0.0, 0.0]))
    xp = np.array([1.3, 1.5, 0.0])
    hyp = np.array([[1.6, 1.8, 1.7, 1.85, 10.0], [1.5, 1.5, 1.52, 1.5, 1.5], [0.0, 0.0, 0.05, 0.0, 0.0]])
    p = motion_model_with_map(hyp, u, xp, grid, c)
    assert p.sum() == pytest.approx(1.0)
    assert p[1] == 0.0 and p[3] == 0.0 and p[4] == 0.0  # in the wall, and off the map
    free = motion_model_odometry(hyp[:, [0, 2]], u, xp, c)
    np.testing.assert_allclose(p[[0, 2]], free / free.sum(), rtol=1e-12)
    # a robot radius shrinks the free space; nothing allowed -> all zeros
    mask = allowed_mask(grid, 1.0)
    assert np.all(motion_model_with_map(hyp[:, :2], u, xp, grid, c, allowed=np.zeros_like(mask)) == 0.0)
    pv = motion_model_with_map(hyp, (0.5, 0.0, 1.0), xp, grid, cfg("velocity"))
    assert pv.sum() == pytest.approx(1.0) and pv[1] == 0.0
    # normalize=False: the seed's algorithm literally, p(x | u, x') p(x | m) with p(x | m) the free indicator: each
    # hypothesis' own value, whatever the others (normalised, one hypothesis alone was 1 wherever it lay)
    raw = motion_model_with_map(hyp, u, xp, grid, c, normalize=False)
    np.testing.assert_allclose(raw[[0, 2]], free, rtol=1e-12)
    assert raw[1] == 0.0 and raw[3] == 0.0 and raw[4] == 0.0
    alone = motion_model_with_map(hyp[:, [2]], u, xp, grid, c, normalize=False)
    assert alone[0] == pytest.approx(free[1], rel=1e-12)  # a density over poses, not 1


def test_a_density_is_minus_infinity_outside_a_bounded_noise_never_nan():
    # At x_new = x_prev the Jacobian vanishes (log 0 = -inf); where a bounded noise's density is 0 there too, the
    # log density was -inf - (-inf) = NaN. A pose outside the noise's support has density 0 whatever the Jacobian.
    tri = cfg(noise="triangular", alphas=(0.05, 0.02, 0.01, 0.001))  # sigma_trans 0.1 m: support 0.245 m
    out = log_motion_model_odometry(np.zeros(3), (np.zeros(3), np.array([1.0, 0.0, 0.0])), np.zeros(3), tri)
    assert out.tolist() == [-np.inf]
    twelve = cfg("velocity", noise="normal_twelve")
    assert log_motion_model_velocity(np.array([0.0, 0.0, 1.0]), (0.0, 1.0, 1.0), np.zeros(3), twelve) == -np.inf


# ----------------------------------------------------------------------- odometry faults (FaultProposal)


@pytest.mark.parametrize("capped", [False, True])
@pytest.mark.parametrize("model", ["odometry", "velocity"])
def test_fault_weights_are_the_ratio_of_the_mixture_densities(model, capped):
    # The importance weight of a particle is p_f / q: the fault mixture with weight prob over the same mixture
    # with weight share (the proposal), both from the closed form at the pose the particle reached. Exact to
    # rounding: the sampler's noise and the density's residuals are the same numbers computed two ways. Capped:
    # turn_max and shift_max at 3 times the model's stds here, so p_k is 3 times as wide as the model, not 10
    # (the sampler and the closed form must cap alike, or the weights miss by up to log(10 / 3)^3 = 3.6 nats).
    from mcl.motion import FaultProposal, noise_sigmas, odometry_deltas, velocity_sigmas

    if not capped:
        fault = FaultProposal(prob=1e-3, share=0.05, scale=10.0)
    elif model == "odometry":
        s1, st, _ = noise_sigmas(*odometry_deltas(*ODOM), cfg(alphas=(0.05, 0.02, 0.05, 0.02, 0, 0)))
        fault = FaultProposal(prob=1e-3, share=0.05, scale=10.0, turn_max=3 * s1, shift_max=3 * st)
    else:
        sv, sw, _ = velocity_sigmas(VEL[0], VEL[1], cfg("velocity", alphas=(0.01, 0.005, 0.01, 0.005, 0.002, 0.001)))
        fault = FaultProposal(prob=1e-3, share=0.05, scale=10.0, turn_max=3 * sw * VEL[2], shift_max=3 * sv * VEL[2])
    n = 20_000
    x = np.tile(X0[:, None], (1, n))
    lw = np.empty(n)
    if model == "odometry":
        c = cfg(alphas=(0.05, 0.02, 0.05, 0.02, 0, 0))
        s, _, _ = OdometryMotionModel(c).sample(x, *ODOM, np.random.default_rng(5), fault=fault, log_weight=lw)

        def dens(f):
            return log_motion_model_odometry(s, ODOM, X0, c, fault=f)
    else:
        c = cfg("velocity", alphas=(0.01, 0.005, 0.01, 0.005, 0.002, 0.001))
        s, _, _ = VelocityMotionModel(c).sample(x, *VEL, np.random.default_rng(5), fault=fault, log_weight=lw)

        def dens(f):
            return log_motion_model_velocity(s, VEL, X0, c, fault=f)
    expected = dens(fault) - dens(FaultProposal(fault.share, fault.share, fault.scale, fault.turn_max, fault.shift_max))
    # Exact but for a few wide draws whose translation noise all but cancelled the step: under 1 cm the closed
    # form reads rot1 as 0 (``ROT1_MIN_TRANS``, as AMCL), another split of the same motion
    close = np.abs(lw - expected) < 1e-6
    assert close.mean() > 0.999, close.mean()
    if model == "odometry":
        from mcl.motion import ROT1_MIN_TRANS

        rot1, trans, _ = odometry_deltas(*ODOM)
        step = np.hypot(s[0] - X0[0], s[1] - X0[1])
        assert (close | (step < ROT1_MIN_TRANS)).all()
        if capped:  # the widest translation: about 3.3 x 3 sigmas (15 catches 10 sigmas uncapped, 33)
            spread = np.abs(step - trans).max() / st
            assert 6.0 < spread < 15.0, spread
    if capped:
        return  # the tail checks below are the 10x component's
    assert np.abs(lw - expected).max() < 0.1
    # the wide draws (about share of them) carry prob / share, the ordinary ones about (1 - prob) / (1 - share)
    far = lw < math.log(0.1)
    assert 0.035 < far.mean() < 0.065, far.mean()
    np.testing.assert_allclose(np.median(lw[far]), math.log(fault.prob / fault.share), atol=0.05)
    np.testing.assert_allclose(np.median(lw[~far]), math.log((1 - fault.prob) / (1 - fault.share)), atol=0.01)


def test_fault_proposal_importance_weights_estimate_the_mixture():
    # Expectations under the mixture p_f (prob 0.2, scale 4) from two samples of 400,000: one drawn from p_f itself
    # (share = prob: every weight 1) and one drawn with share 0.6 and importance-weighted. The translation's
    # second moment and its 3-sigma tail agree within 3 % (their Monte Carlo errors are about 0.5 %); without
    # the weights the tail is off by a factor of two, which the same check catches.
    from mcl.motion import FaultProposal

    c = cfg(alphas=(0.05, 0.02, 0.05, 0.02, 0, 0))
    n = 400_000
    x = np.tile(X0[:, None], (1, n))
    mean = ideal_odometry()

    plain, _, _ = OdometryMotionModel(c).sample(x, *ODOM, np.random.default_rng(0))
    tail = 9.0 * np.median((plain[0] - mean[0]) ** 2 + (plain[1] - mean[1]) ** 2)  # 3x the ordinary median

    def moments(share, weighted, seed):
        lw = np.empty(n)
        s, _, _ = OdometryMotionModel(c).sample(x, *ODOM, np.random.default_rng(seed),
                                                fault=FaultProposal(0.2, share, 4.0), log_weight=lw)
        w = np.exp(lw) if weighted else np.ones(n)
        w /= w.sum()
        d2 = (s[0] - mean[0]) ** 2 + (s[1] - mean[1]) ** 2
        return float(np.sum(w * d2)), float(np.sum(w * (d2 > tail)))

    ref = moments(0.2, False, 1)
    est = moments(0.6, True, 2)
    raw = moments(0.6, False, 2)
    np.testing.assert_allclose(est, ref, rtol=0.03)
    assert raw[1] > 1.5 * ref[1], (raw, ref)
