"""KLD sampling and augmented MCL (mcl.adaptive): the bound, the bin count, the injection rate, determinism."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

from mcl.adaptive import (
    BinCounter,
    Recovery,
    bins_occupied,
    draw_injected,
    kld_bound,
    kld_quantile,
    kld_resample,
)
from mcl.config import PROJECT_ROOT, load_config


def test_quantile_is_the_upper_normal_quantile_of_one_minus_delta():
    assert kld_quantile(0.01) == pytest.approx(2.3263, abs=1e-4)
    assert kld_quantile(0.05) == pytest.approx(1.6449, abs=1e-4)
    assert kld_quantile(0.5) == pytest.approx(0.0, abs=1e-12)
    # AMCL's default kld_z = 0.99 is this quantile for delta = 0.161, not 0.01.
    assert kld_quantile(0.1611) == pytest.approx(0.99, abs=2e-3)
    with pytest.raises(ValueError):
        kld_quantile(1.0)


@pytest.mark.parametrize("eps,delta", [(0.05, 0.01), (0.01, 0.01), (0.1, 0.05)])
def test_bound_is_the_chi_square_quantile_over_two_eps(eps, delta):
    # Wilson-Hilferty vs the exact chi^2_{k-1}(1 - delta) / (2 eps): within 2 % for k >= 10
    # (the approximation's error shrinks with k), within 10 % from k = 3.
    z = kld_quantile(delta)
    for k in (3, 5, 10, 30, 100, 1000, 10_000):
        exact = stats.chi2.ppf(1.0 - delta, k - 1) / (2.0 * eps)
        tol = 0.02 if k >= 10 else 0.10
        assert kld_bound(k, eps, z) == pytest.approx(exact, rel=tol), k


def test_bound_known_values_and_edges():
    z = kld_quantile(0.01)
    # k = 2 (one degree of freedom): chi^2_1(0.99) = 6.635 -> 66.3 at eps = 0.05; W-H gives 68.1.
    assert kld_bound(2, 0.05, z) == pytest.approx(stats.chi2.ppf(0.99, 1) / 0.1, rel=0.05)
    # k = 101 at eps = 0.05, delta = 0.01: (100 / 0.1) * (1 - 2/900 + sqrt(2/900) * 2.3263)^3
    a = 2.0 / 900.0
    assert kld_bound(101, 0.05, z) == pytest.approx(1000.0 * (1 - a + math.sqrt(a) * z) ** 3, rel=1e-12)
    assert kld_bound(0, 0.05, z) == 0.0 and kld_bound(1, 0.05, z) == 0.0
    ks = np.arange(2, 500)
    assert np.all(np.diff(kld_bound(ks, 0.05, z)) > 0)  # more bins, more particles


def test_bin_counter_counts_distinct_bins_across_batches_and_resets():
    c = BinCounter((0.0, 0.0), (10.0, 10.0), 0.5, math.pi / 2)
    a = np.array([[0.1, 0.2, 0.6, 0.1], [0.1, 0.1, 0.1, 0.1], [0.0, 0.1, 0.0, 3.0]])
    assert list(c.add(a)) == [1, 1, 2, 3]  # the second pose shares the first's bin
    b = np.array([[0.3, 9.9], [0.3, 9.9], [0.05, -3.0]])
    assert list(c.add(b)) == [3, 4]
    c.reset()
    assert not c.flags.any() and c.k == 0
    assert list(c.add(b)) == [1, 2]
    assert bins_occupied(a, 0.5, math.pi / 2) == 3


def test_a_map_too_large_for_the_flag_array_counts_bins_in_a_hash_table_alike():
    # A 10 km map at 0.5 m and 10 degrees would need a 14 GB flag array: the hash table gives the same counts,
    # batch after batch, across its growth (the first table holds 32,768 bins) and a reset.
    rng = np.random.default_rng(4)
    dense = BinCounter((0.0, 0.0), (60.0, 60.0), 0.5, math.radians(10))
    hashed = BinCounter((0.0, 0.0), (60.0, 60.0), 0.5, math.radians(10), dense_max=0)
    assert hashed.flags is None and dense.table is None
    big = BinCounter((0.0, 0.0), (10_000.0, 10_000.0), 0.5, math.radians(10))
    assert big.flags is None  # not 14 GB
    for n, spread in ((1000, 0.3), (30_000, 20.0), (50_000, 40.0), (7, 0.0)):
        p = np.ascontiguousarray(np.vstack([30 + spread * rng.standard_normal(n), 30 + spread * rng.standard_normal(n),
                                            rng.uniform(-math.pi, math.pi, n)]))
        assert np.array_equal(hashed.add(p), dense.add(p))  # off-map poses clipped alike, too
    assert hashed.table.size >= 2 * hashed.k > 2 * 30_000
    hashed.reset()
    dense.reset()
    assert not hashed.table.any() and hashed.k == 0
    p = np.ascontiguousarray(rng.uniform(0, 60, (3, 500)))
    assert np.array_equal(hashed.add(p), dense.add(p))
    fresh = BinCounter((0.0, 0.0), (60.0, 60.0), 0.5, math.radians(10))
    assert np.array_equal(big.add(p), fresh.add(p))


def _cloud(rng, n, spread):
    # centred inside a bin (5.25, 5.25, 5 degrees), so a tight cloud occupies one bin
    p = np.vstack([5.25 + spread * rng.standard_normal(n), 5.25 + spread * rng.standard_normal(n),
                   np.clip(0.087 + 0.3 * spread * rng.standard_normal(n), -3.1, 3.1)])
    return np.ascontiguousarray(p)


@pytest.mark.parametrize("seed", [0, 1])
def test_particle_count_grows_with_occupied_bins_and_stays_in_bounds(seed):
    rng = np.random.default_rng(seed)
    counter = BinCounter((-20.0, -20.0), (50.0, 50.0), 0.5, math.radians(10))  # holds every pose drawn
    z = kld_quantile(0.01)
    sizes, ks = [], []
    for spread in (0.01, 0.2, 0.5, 1.0, 2.0):
        p = _cloud(rng, 20_000, spread)
        logw = np.zeros(p.shape[1])
        out, inj, k = kld_resample(p, logw, rng, counter, scheme="systematic", min_particles=100,
                                   max_particles=20_000, epsilon=0.05, z=z)
        assert not inj.any() and inj.size == out.shape[1] and out.shape[0] == 3 and out.flags.c_contiguous
        assert 100 <= out.shape[1] <= 20_000
        # The stopping rule: M >= bound(k) for the bins of the drawn set (or M at a bound).
        assert k == bins_occupied(out, 0.5, math.radians(10))  # k counts the bins of the set drawn
        assert out.shape[1] == 100 or out.shape[1] == 20_000 or out.shape[1] >= kld_bound(k, 0.05, z)
        # ... and the first M - 1 drew fewer than the bound asked for (it stopped at the first chance).
        if 100 < out.shape[1] < 20_000:
            assert out.shape[1] - 1 < kld_bound(k, 0.05, z) + 1e-9
        sizes.append(out.shape[1])
        ks.append(k)
    assert sizes[0] == 100  # a point mass: one bin, the minimum
    assert all(a < b for a, b in zip(ks, ks[1:])), ks
    assert all(a < b for a, b in zip(sizes[:-1], sizes[1:])) or sizes[-1] == 20_000, sizes
    assert sizes[-1] == 20_000  # 2 m spread over 10 m: thousands of bins, the maximum


def test_kld_resample_draws_from_the_weights():
    # Two clusters with weights 0.8 / 0.2: the drawn set splits in that ratio (binomial 4-sigma tolerance).
    rng = np.random.default_rng(3)
    n = 4000
    p = np.ascontiguousarray(np.vstack([np.r_[np.full(n // 2, 2.0), np.full(n // 2, 8.0)],
                                        np.full(n, 5.0) + 0.3 * rng.standard_normal(n), np.zeros(n)]))
    logw = np.log(np.r_[np.full(n // 2, 0.8), np.full(n // 2, 0.2)])
    counter = BinCounter((0.0, 0.0), (10.0, 10.0), 0.5, math.radians(10))
    out, _, _ = kld_resample(p, logw, rng, counter, scheme="systematic", min_particles=500, max_particles=n,
                             epsilon=0.05, z=kld_quantile(0.01))
    m = out.shape[1]
    frac = np.mean(out[0] < 5.0)
    assert abs(frac - 0.8) < 4 * math.sqrt(0.16 / m), (frac, m)


def test_injection_follows_the_binomial_and_counts_in_the_bins():
    rng = np.random.default_rng(4)
    p = _cloud(rng, 5000, 0.01)
    counter = BinCounter((0.0, 0.0), (10.0, 10.0), 0.5, math.radians(10))
    far = lambda n: np.vstack([rng.uniform(0, 10, n), rng.uniform(0, 10, n), rng.uniform(-3, 3, n)])  # noqa: E731
    out, mask, k = kld_resample(p, np.zeros(5000), rng, counter, scheme="systematic", min_particles=200,
                                max_particles=5000, epsilon=0.05, z=kld_quantile(0.01), inject_p=0.3, sampler=far)
    inj = int(mask.sum())
    assert np.all(np.hypot(out[0, ~mask] - 5.25, out[1, ~mask] - 5.25) < 0.2)  # the mask marks the sampler's poses
    # Injected poses spread over many bins, so the set grows well beyond the point mass's minimum.
    assert k > 50 and out.shape[1] > 1000
    m = out.shape[1]
    spread = np.count_nonzero(np.hypot(out[0] - 5.25, out[1] - 5.25) > 0.2)
    assert abs(inj - 0.3 * m) < 4 * math.sqrt(m * 0.21) and spread >= inj * 0.9


# ----------------------------------------------------------------------------- augmented MCL


def test_mean_likelihood_is_a_stable_log_sum_exp():
    lp = np.log(np.array([0.5, 0.25, 0.25]))
    ll = np.array([-1000.0, -1001.0, -2000.0])  # exp() underflows to 0 in linear space
    expect = -1000.0 + math.log(0.5 + 0.25 * math.exp(-1.0))
    assert Recovery.log_mean_likelihood(lp, ll) == pytest.approx(expect, abs=1e-12)
    # Unnormalised prior log weights are normalised first.
    assert Recovery.log_mean_likelihood(lp + 7.0, ll) == pytest.approx(expect, abs=1e-12)
    assert Recovery.log_mean_likelihood(lp, np.full(3, -np.inf)) == -np.inf


def test_averages_follow_the_book_recursion_in_log_space():
    r = Recovery(0.1, 0.5)
    xs = [1e-300, 3e-300, 2e-301, 5e-300]  # near the float floor: logs keep them exact
    ws = wf = 0.0  # the book's recursion from 0, read bias-corrected: w / (1 - (1 - alpha)^t)
    for t, x in enumerate(xs, start=1):
        r.update(math.log(x))
        ws += 0.1 * (x - ws)
        wf += 0.5 * (x - wf)
        assert math.exp(r.log_w_slow) == pytest.approx(ws / (1 - 0.9**t), rel=1e-9)
        assert math.exp(r.log_w_fast) == pytest.approx(wf / (1 - 0.5**t), rel=1e-9)
    cs, cf = ws / (1 - 0.9**4), wf / (1 - 0.5**4)
    assert r.inject_probability == pytest.approx(max(0.0, 1.0 - cf / cs), abs=1e-9)
    # corrected, a constant input reads back exactly (no lag from the start at 0)
    c = Recovery(0.001, 0.1)
    for _ in range(5):
        c.update(-123.0)
        assert c.log_w_slow == pytest.approx(-123.0, abs=1e-9) and c.inject_probability == pytest.approx(0.0, abs=1e-9)


def test_no_injection_while_w_fast_is_at_least_w_slow():
    r = Recovery(0.01, 0.3)
    for v in np.linspace(-500.0, -400.0, 50):  # likelihood improving: w_fast >= w_slow
        r.update(v)
        assert r.inject_probability == 0.0
    rng = np.random.default_rng(0)
    assert sum(draw_injected(1000, r.inject_probability, rng) for _ in range(100)) == 0


def test_injection_count_is_binomial_with_p_one_minus_ratio():
    r = Recovery(0.01, 0.3)
    for _ in range(50):
        r.update(-400.0)
    for _ in range(3):
        r.update(-400.0 + math.log(0.2))  # the scans suddenly explain 5x worse
    p = r.inject_probability
    ratio = math.exp(r.log_w_fast - r.log_w_slow)
    assert 0.2 < p < 0.8 and p == pytest.approx(1.0 - ratio, abs=1e-12)
    rng = np.random.default_rng(7)
    n, trials = 2000, 200
    counts = np.array([draw_injected(n, p, rng) for _ in range(trials)])
    # mean of 200 Binomial(2000, p) draws: within 4 standard errors of N p
    se = math.sqrt(n * p * (1 - p) / trials)
    assert abs(counts.mean() - n * p) < 4 * se
    assert counts.std() == pytest.approx(math.sqrt(n * p * (1 - p)), rel=0.2)


def test_filter_injects_from_the_hook_sampler():
    # A fixed filter (no KLD) with recovery: after a run of good scans, a scan nothing explains
    # triggers injection; every injected pose comes from the sampler set on the filter.
    from mcl.filter import ParticleFilter
    from mcl.maps import load_map

    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml",
                      ["rerun.mode=off", "filter.kld=false", "filter.particles=1000", "filter.resample_threshold=1.0",
                       "filter.recovery=augmented", "filter.recovery_alpha_slow=0.05", "filter.recovery_alpha_fast=0.5",
                       "sensor.beam_skip=false"])  # the stub sensor below has no beams to skip
    grid = load_map(cfg.map)
    pf = ParticleFilter(cfg, grid)
    pf.init_gaussian((2.0, 2.0, 0.0), (0.05, 0.05, 0.05))
    marker = np.array([[123.0], [456.0], [0.5]])
    pf.recovery_sampler = lambda n, rng, obs: np.repeat(marker, n, axis=1)
    near = np.array([[0.5, 0.0, -0.5], [0.0, 0.5, 0.0]])
    # stub: one value per scan
    pf.sensor.log_likelihood = lambda parts, obs, searching=False: np.full(parts.shape[1], float(obs))
    pf.sensor.endpoints = lambda obs: np.zeros((2, 0))  # ... and no beams for the quality signal
    for _ in range(20):
        info = pf.step(None, -10.0)
        assert info.injected == 0
    info = pf.step(None, -10.0 + math.log(0.1))  # 10x worse: w_fast drops by half of that
    assert info.inject_p > 0.3 and info.injected > 0
    got = np.count_nonzero(pf.particles[0] == 123.0)
    assert got == info.injected and pf.n == 1000
    del near


def test_kld_filter_is_deterministic_with_one_and_two_threads(tmp_path):
    # The global demo with KLD and recovery on: the same trajectory bytes whatever the thread count.
    code = (
        "import sys; from mcl.config import load_config; from mcl.runner import run; "
        "cfg = load_config(sys.argv[1], ['rerun.mode=off', 'filter.particles=4000', 'filter.min_particles=300']); "
        "s = run(cfg, sys.argv[2], progress=False, echo=lambda m: None); "
        "print(s['particles_min'], s['particles_max'], s['injected_particles'])"
    )
    outs = []
    for threads in (1, 2):
        out = tmp_path / f"t{threads}"
        env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
        r = subprocess.run([sys.executable, "-c", code, str(PROJECT_ROOT / "configs" / "default.yaml"), str(out)],
                           check=True, env=env, capture_output=True, text=True)
        outs.append(((out / "trajectory.tum").read_bytes(), r.stdout))
    assert outs[0] == outs[1]
    lo, hi, _ = (int(v) for v in outs[0][1].split())
    assert lo < hi  # the count really changed during the run


def test_a_fixed_size_resample_draws_the_same_set_without_counting_bins():
    # min_particles >= max_particles: the bound cannot change N, so kld_resample skips the bins (k = 0) and the
    # shuffle (no prefix of the batch is cut): the scheme's ancestors in its order, as a plain resample draws them,
    # then moved.
    from mcl.resampling import resample

    rng = np.random.default_rng(5)
    p = _cloud(rng, 3000, 0.5)
    logw = rng.normal(size=3000)
    counter = BinCounter((0.0, 0.0), (10.0, 10.0), 0.5, math.radians(10))
    shift = lambda b: b + np.array([[0.1], [0.0], [0.0]])  # noqa: E731
    out, mask, k = kld_resample(p, logw, np.random.default_rng(6), counter, scheme="systematic", min_particles=3000,
                                max_particles=3000, epsilon=0.05, z=kld_quantile(0.01), move=shift)
    ref_rng = np.random.default_rng(6)
    ref = p[:, resample("systematic", logw, ref_rng, n=3000)] + np.array([[0.1], [0.0], [0.0]])
    assert k == 0 and counter.k == 0 and not mask.any() and out.flags.c_contiguous
    np.testing.assert_array_equal(out, ref)


def test_the_bound_table_holds_the_bound_element_for_element():
    from mcl.adaptive import _bound_table

    z = kld_quantile(0.01)
    ks = np.array([0, 1, 2, 3, 50, 999, 5000, 70_000])
    table = _bound_table(0.05, z, int(ks.max()))
    np.testing.assert_array_equal(table[ks], kld_bound(ks, 0.05, z))
    assert table.size > ks.max()
