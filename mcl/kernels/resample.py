"""Numba kernels for resampling: O(N) merges of sorted positions against the cumulative weights.

Weights here are nonnegative and need not sum to one (the caller passes
exp(logw - max logw)); each kernel scales its positions by the total, so
equal weights give exactly representable cumulative sums. Serial: a merge is
a sequential scan, and at 100,000 particles it costs well under 1 ms.
The uniforms come from the caller's Generator.
"""

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _last_positive(w):
    """Index of the last strictly positive weight (0 if none)."""
    for j in range(w.shape[0] - 1, -1, -1):
        if w[j] > 0.0:
            return j
    return 0


@njit(cache=True)
def merge_positions(w, u, mode, out):
    """Fill out[i] with the index j such that cum[j-1] <= p_i < cum[j], cum = cumsum(w).

    Positions p_i, increasing in i, in units of the total weight T = sum(w):
      mode 0 (systematic):  p_i = (i + u[0]) * T / N
      mode 1 (stratified):  p_i = (i + u[i]) * T / N
      mode 2 (sorted, e.g. multinomial): p_i = u[i] * T, u sorted in [0, 1)
    Zero weights are never chosen (the merge steps over them); a position
    that rounds up to T picks the last positive weight.
    """
    n_out = out.shape[0]
    n = w.shape[0]
    total = 0.0
    for j in range(n):
        total += w[j]
    cap = _last_positive(w)
    step = total / n_out
    j = 0
    c = w[0]
    for i in range(n_out):
        if mode == 0:
            p = (i + u[0]) * step
        elif mode == 1:
            p = (i + u[i]) * step
        else:
            p = u[i] * total
        while p >= c and j < cap:
            j += 1
            c += w[j]
        out[i] = j


@njit(cache=True)
def residual_counts(w, n_out, counts, resid):
    """counts[j] = floor(n_out * w_j / T); resid[j] = the remainder. Returns n_out - sum(counts)."""
    n = w.shape[0]
    total = 0.0
    for j in range(n):
        total += w[j]
    scale = n_out / total
    used = 0
    for j in range(n):
        x = w[j] * scale
        f = math.floor(x)
        counts[j] = np.int64(f)
        resid[j] = x - f
        used += counts[j]
    return n_out - used


@njit(cache=True)
def residual_merge(counts, resid, u_sorted, out):
    """Sorted indices: counts[j] copies of j plus one j per sorted uniform u in resid's cumulative bins.

    u_sorted: (R,) sorted uniforms in [0, 1) (multinomial draws on the
    residual weights). Output is in increasing index order, truncated at
    len(out) if rounding gave more than len(out) copies.
    """
    n = counts.shape[0]
    n_out = out.shape[0]
    r = u_sorted.shape[0]
    total = 0.0
    for j in range(n):
        total += resid[j]
    cap = _last_positive(resid)
    # residual picks per index, by merging the sorted positions
    extra = np.zeros(n, dtype=np.int64)
    if r > 0:
        j = 0
        c = resid[0]
        for i in range(r):
            p = u_sorted[i] * total
            while p >= c and j < cap:
                j += 1
                c += resid[j]
            extra[j] += 1
    k = 0
    for j in range(n):
        m = counts[j] + extra[j]
        for _ in range(m):
            if k < n_out:
                out[k] = j
                k += 1
    return k
