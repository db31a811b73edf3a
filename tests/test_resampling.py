"""Resampling schemes, log-weight normalisation and ESS."""


import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import stats
from scipy.special import logsumexp

from mcl.kernels import resample as kr
from mcl.resampling import SCHEMES, effective_sample_size, normalize_log_weights, resample


def random_logw(rng, n, zeros=0.2):
    lw = rng.normal(0.0, 1.5, n)
    lw[rng.random(n) < zeros] = -np.inf
    return lw


# ---------------------------------------------------------------- normalisation and ESS

def test_normalize_matches_logsumexp_and_survives_tiny_weights():
    rng = np.random.default_rng(0)
    lw = random_logw(rng, 1000) - 5000.0  # exp() of these underflows without the max shift
    w, log_norm = normalize_log_weights(lw)
    assert log_norm == pytest.approx(logsumexp(lw), rel=1e-14)
    np.testing.assert_allclose(w, np.exp(lw - logsumexp(lw)), rtol=1e-12)
    assert w.sum() == pytest.approx(1.0, abs=1e-12) and (w[np.isneginf(lw)] == 0).all()


def test_normalize_all_zero_weights_gives_uniform_and_minus_inf():
    w, log_norm = normalize_log_weights(np.full(7, -np.inf))
    assert log_norm == -np.inf
    np.testing.assert_array_equal(w, np.full(7, 1 / 7))
    with pytest.raises(ValueError, match="NaN"):
        normalize_log_weights(np.array([0.0, np.nan]))


def test_effective_sample_size():
    assert effective_sample_size(np.full(50, 0.02)) == pytest.approx(50)
    assert effective_sample_size(np.eye(1, 50, 3).ravel()) == pytest.approx(1)
    assert effective_sample_size([0.5, 0.5, 0.0, 0.0]) == pytest.approx(2)


# ---------------------------------------------------------------- exact cases

@pytest.mark.parametrize("name", SCHEMES)
def test_one_hot_weights_pick_one_index(name):
    lw = np.full(100, -np.inf)
    lw[37] = -3.0
    idx = resample(name, lw, np.random.default_rng(1))
    assert idx.dtype == np.int64 and idx.shape == (100,)
    assert (idx == 37).all()


@pytest.mark.parametrize("name", ["systematic", "stratified", "residual"])
@pytest.mark.parametrize("n", [1, 2, 7, 1000, 100_003])
def test_equal_weights_give_arange(name, n):
    """Equal weights: one position per stratum [i, i+1) (systematic, stratified), one copy each (residual)."""
    for seed in range(3):
        idx = resample(name, np.full(n, -2.5), np.random.default_rng(seed))
        np.testing.assert_array_equal(idx, np.arange(n))


@pytest.mark.parametrize("name", SCHEMES)
def test_all_zero_weights_resample_as_uniform(name):
    idx = resample(name, np.full(500, -np.inf), np.random.default_rng(2))
    assert idx.shape == (500,) and idx.min() >= 0 and idx.max() < 500
    if name != "multinomial":
        np.testing.assert_array_equal(idx, np.arange(500))


def test_unknown_scheme_lists_the_names():
    with pytest.raises(ValueError) as exc:
        resample("bogus", np.zeros(3), np.random.default_rng(0))
    for name in SCHEMES:
        assert name in str(exc.value)


# ---------------------------------------------------------------- kernels against NumPy

def test_merge_matches_searchsorted_on_the_same_uniforms():
    rng = np.random.default_rng(3)
    n = 20_000
    w = np.exp(random_logw(rng, n))
    cum = np.cumsum(w)  # sequential, as in the kernel
    total = cum[-1]
    i = np.arange(n)
    cases = {0: np.array([rng.random()]), 1: rng.random(n), 2: np.sort(rng.random(n))}
    for mode, u in cases.items():
        pos = {0: (i + u[0]) * (total / n), 1: (i + u) * (total / n), 2: u * total}[mode]
        ref = np.searchsorted(cum, pos, side="right")
        out = np.empty(n, dtype=np.int64)
        kr.merge_positions(w, u, mode, out)
        np.testing.assert_array_equal(out, ref)
        assert (w[out] > 0).all()


def test_residual_matches_numpy():
    rng = np.random.default_rng(4)
    n = 5000
    lw = random_logw(rng, n)
    w = np.exp(lw - lw.max())
    nw = w * (n / w.sum())
    floors = np.floor(nw).astype(np.int64)
    resid = nw - floors
    r = n - floors.sum()
    rng_a, rng_b = np.random.default_rng(9), np.random.default_rng(9)
    idx = resample("residual", lw, rng_a)
    e = np.cumsum(rng_b.standard_exponential(r + 1))
    u = e[:-1] / e[-1]
    extra = np.bincount(np.searchsorted(np.cumsum(resid), u * resid.sum(), side="right"), minlength=n)
    np.testing.assert_array_equal(idx, np.repeat(np.arange(n), floors + extra))


@pytest.mark.parametrize("seed", range(5))
def test_residual_keeps_at_least_floor_copies(seed):
    rng = np.random.default_rng(seed)
    n = 1000
    lw = random_logw(rng, n)
    w, _ = normalize_log_weights(lw)
    counts = np.bincount(resample("residual", lw, rng), minlength=n)
    assert (counts >= np.floor(n * w).astype(int)).all()
    assert (counts <= np.floor(n * w).astype(int) + n - np.floor(n * w).sum()).all()
    assert counts.sum() == n


# ---------------------------------------------------------------- statistics

@pytest.mark.parametrize("name", SCHEMES)
def test_chi_square_of_counts_against_expected(name):
    """Counts summed over R = 400 resamplings of N = 60 particles against R N w.

    Under multinomial resampling Pearson's statistic is chi-square with
    (positive weights - 1) degrees of freedom; the low-variance schemes give
    smaller statistics. We require p > 1e-3 (fixed seed, so the test is
    deterministic; a biased scheme, e.g. an off-by-one in the merge, gives
    p ~ 0). For multinomial we also check the statistic is not implausibly
    small (p < 0.999), i.e. that it has multinomial, not systematic, spread.
    """
    rng = np.random.default_rng(11)
    n, reps = 60, 400
    lw = random_logw(rng, n, zeros=0.15)
    w, _ = normalize_log_weights(lw)
    counts = np.zeros(n)
    for _ in range(reps):
        counts += np.bincount(resample(name, lw, rng), minlength=n)
    pos = w > 0
    assert counts[~pos].sum() == 0
    expected = reps * n * w[pos]
    chi2 = ((counts[pos] - expected) ** 2 / expected).sum()
    p = stats.chi2.sf(chi2, pos.sum() - 1)
    assert p > 1e-3
    if name == "multinomial":
        assert p < 0.999


@given(arrays(np.float64, st.integers(1, 300), elements=st.one_of(st.floats(-700, 50), st.just(-np.inf))),
       st.sampled_from(SCHEMES), st.integers(0, 2**32 - 1))
@settings(max_examples=200, deadline=None)
def test_indices_are_sorted_in_range_and_never_zero_weight(lw, name, seed):
    idx = resample(name, lw, np.random.default_rng(seed))
    assert idx.shape == lw.shape
    assert (np.diff(idx) >= 0).all() and idx.min() >= 0 and idx.max() < lw.size
    if np.isfinite(lw).any():
        assert np.isfinite(lw[idx]).all()


def test_effective_sample_size_does_not_change_with_the_blas_thread_count():
    # np.dot over 100,000 weights is split over OpenBLAS's threads: 1 / sum(w^2) differed in its last digits between
    # OPENBLAS_NUM_THREADS=1 and 2 (74978.83611698521 against ...519), and the ESS decides whether to resample, so
    # one seed's trajectory could depend on the machine. Two processes, one BLAS thread and two: the same bits.
    from tests.blas import outputs_by_blas_threads

    got = outputs_by_blas_threads("import numpy as np; from mcl.resampling import effective_sample_size as e; "
                                  "w = np.random.default_rng(1).random(100000); w /= w.sum(); print(repr(e(w)))")
    assert len(got) == 1, got
