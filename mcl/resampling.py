"""Resampling schemes by name, log-weight normalisation and effective sample size.

``resample(name, logw, rng)`` returns N ancestor indices, in increasing order,
drawn with probability proportional to exp(logw):

* ``systematic`` (low variance, Prob. Rob. Table 4.4; the default): one
  uniform u, positions (i + u) / N;
* ``stratified``: one uniform per stratum, positions (i + u_i) / N;
* ``residual``: floor(N w_i) copies of each particle, then the remaining
  R = N - sum floor(N w_i) drawn multinomially from the residuals N w_i - floor(N w_i);
* ``multinomial``: N independent draws, as N sorted uniforms (cumulative sums
  of N + 1 exponentials, divided by their total: O(N), no sort).

Each is one O(N) merge of sorted positions against the cumulative weights
(``mcl.kernels.resample``). Zero weights (logw = -inf) are never chosen; if
every weight is zero the weights are treated as equal.
"""

from __future__ import annotations

import math

import numpy as np

from mcl.kernels import resample as _k

SCHEMES = ("systematic", "stratified", "residual", "multinomial")


def _check(logw) -> np.ndarray:
    lw = np.asarray(logw, dtype=np.float64)
    if lw.ndim != 1:
        raise ValueError(f"log weights: expected shape (N,), got {lw.shape}")
    return lw


def normalize_log_weights(logw) -> tuple[np.ndarray, float]:
    """(w, log_norm): w = exp(logw - log_norm) sums to 1, log_norm = logsumexp(logw).

    If every weight is zero (all -inf, or N = 0) returns uniform weights and
    log_norm = -inf; the caller decides what that means. NaN or +inf log
    weights raise ValueError.
    """
    lw = _check(logw)
    n = lw.size
    if n == 0:
        return np.empty(0), -np.inf
    m = float(lw.max())
    if np.isnan(m) or m == np.inf:
        raise ValueError(f"log weights contain {'NaN' if np.isnan(m) else '+inf'}")
    if m == -np.inf:
        return np.full(n, 1.0 / n), -np.inf
    w = np.exp(lw - m)
    s = float(w.sum())
    w /= s
    return w, m + float(np.log(s))


def effective_sample_size(w) -> float:
    """1 / sum(w^2) for normalised weights w: N for equal weights, 1 for one-hot.

    numpy's own loop (einsum), not np.dot: above 10,000 weights OpenBLAS splits the dot product over its threads,
    so the sum's last digits changed with the thread count (the ESS is compared with resample_threshold N: a
    borderline resample could flip), and with the other core busy it waited for it (7.7 ms an update at 100,000)."""
    w = np.asarray(w, dtype=np.float64)
    return float(1.0 / np.einsum("i,i->", w, w))


def _unnormalised(lw: np.ndarray) -> np.ndarray:
    """exp(logw - max): positive weights of any scale; all ones if every weight is zero."""
    m = float(lw.max())
    if np.isnan(m) or m == np.inf:
        raise ValueError(f"log weights contain {'NaN' if np.isnan(m) else '+inf'}")
    if m == -np.inf:
        return np.ones(lw.size)
    return np.exp(lw - m)


def temper_to_ess(prior: np.ndarray, loglik: np.ndarray, ess_floor: float, full_ess: float,
                  slack: float = 1.05) -> float:
    """The factor beta for ``loglik`` (N,) on the log-weights ``prior`` (N,) that leaves an effective sample size of
    ``ess_floor`` to ``slack`` times that: prior + beta loglik, beta in [1/4096, 1), or 0 when even 1/4096 leaves
    too few. ``full_ess`` is the ESS with beta = 1 (below the floor; the caller has it); the prior's ESS must be at
    or above it. ``loglik`` is finite wherever ``prior`` is.

    log ESS falls about linearly in log beta once the scan is sharper than the cloud (a Gaussian scan on a Gaussian
    cloud in d dimensions: ESS ~ beta^(-d/2)), so the root is sought in u = log beta by regula falsi (Illinois
    variant), the first try that line's root for d = 3 through ``full_ess``: 4-8 ESS evaluations as a rule (14 the
    most a fuzz of 3,000 scans took), capped at 64."""
    log_floor = math.log(ess_floor)

    def excess(beta: float) -> float:  # log ESS(beta) - log floor
        e = _unnormalised(prior + beta * loglik)
        return 2.0 * math.log(float(np.einsum("i->", e))) - math.log(float(np.einsum("i,i->", e, e))) - log_floor

    u_min = math.log(1.0 / 4096.0)
    u_lo, u_hi, f_hi = u_min, 0.0, math.log(full_ess) - log_floor
    u = max(f_hi / 1.5, u_min)
    f_lo = excess(math.exp(u))
    if f_lo >= 0.0:
        u_lo = u
    else:
        u_hi, f_hi = u, f_lo
        f_lo = excess(1.0 / 4096.0) if u > u_min else f_lo
        if not f_lo >= 0.0:  # even 1/4096 of the scan leaves too few: the weights before it
            return 0.0
    side, at_lo = 0, f_lo  # at_lo: u_lo's own excess (f_lo is halved by the Illinois rule)
    for _ in range(64):
        if not (u_hi - u_lo > 1e-3 and at_lo > math.log(slack)):
            break
        u = (u_lo * f_hi - u_hi * f_lo) / (f_hi - f_lo)
        u = min(max(u, u_lo + 1e-4), u_hi - 1e-4)
        f = excess(math.exp(u))
        if f >= 0.0:
            u_lo, f_lo, at_lo = u, f, f
            if side == 1:
                f_hi *= 0.5  # Illinois: an end kept twice running counts half
            side = 1
        else:
            u_hi, f_hi = u, f
            if side == -1:
                f_lo *= 0.5
            side = -1
    return math.exp(u_lo)


def resample(name: str, logw, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    """Indices (n,) int64, sorted, of the particles chosen by scheme ``name`` (n defaults to N)."""
    if name not in SCHEMES:
        raise ValueError(f"unknown resampling scheme {name!r} (expected one of {', '.join(SCHEMES)})")
    lw = _check(logw)
    n_in = lw.size
    n_out = n_in if n is None else int(n)
    out = np.empty(n_out, dtype=np.int64)
    if n_in == 0 or n_out == 0:
        if n_out:
            raise ValueError("cannot resample from zero particles")
        return out
    w = _unnormalised(lw)
    if name == "systematic":
        _k.merge_positions(w, np.array([rng.random()]), 0, out)
    elif name == "stratified":
        _k.merge_positions(w, rng.random(n_out), 1, out)
    elif name == "multinomial":
        _k.merge_positions(w, _sorted_uniforms(rng, n_out), 2, out)
    else:  # residual
        counts = np.empty(n_in, dtype=np.int64)
        resid = np.empty(n_in)
        r = max(int(_k.residual_counts(w, n_out, counts, resid)), 0)
        if r and not resid.sum() > 0.0:  # rounding left draws but no residual mass
            resid = w
        _k.residual_merge(counts, resid, _sorted_uniforms(rng, r), out)
    return out


def _sorted_uniforms(rng: np.random.Generator, n: int) -> np.ndarray:
    """n sorted uniforms on [0, 1) in O(n): cumsum of n + 1 exponentials over their total."""
    e = rng.standard_exponential(n + 1)
    c = np.cumsum(e)
    return c[:-1] / c[-1]
