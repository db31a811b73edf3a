"""Landmark model kernel: log p(z | x, m) of J range-bearing observations for N poses.

One serial pass over the particles (J is small: threads would not pay), the J observations in an inner loop,
all in registers: the NumPy version (``mcl.landmarks.landmark_log_likelihood_numpy``,
the oracle) makes about ten (N,) temporaries per observation.
"""

import math

import numpy as np
from numba import njit


@njit(cache=True)
def landmark_loglik(particles, obs, sigma_r, sigma_b, z_det, c_fp, out):
    """out[n] = sum_j log(z_det * N(er_nj; sigma_r) * N(eb_nj; sigma_b) + c_fp).

    particles: (3, N) x, y, theta. obs: (4, J) rows m_x, m_y, range, bearing.
    er = range - |m - x|, eb = wrap(bearing - (atan2(m_y - y, m_x - x) - theta)).
    Each particle is independent, so the result does not depend on the thread count.
    """
    n = particles.shape[1]
    nobs = obs.shape[1]
    log_norm = -math.log(2.0 * math.pi * sigma_r * sigma_b)
    log_zdet = math.log(z_det) if z_det > 0.0 else -np.inf
    log_c = math.log(c_fp) if c_fp > 0.0 else -np.inf
    inv_r = 1.0 / sigma_r
    inv_b = 1.0 / sigma_b
    two_pi = 2.0 * math.pi
    for i in range(n):
        x = particles[0, i]
        y = particles[1, i]
        th = particles[2, i]
        acc = 0.0
        for j in range(nobs):
            dx = obs[0, j] - x
            dy = obs[1, j] - y
            er = (obs[2, j] - math.sqrt(dx * dx + dy * dy)) * inv_r
            e = obs[3, j] - (math.atan2(dy, dx) - th)
            e -= two_pi * math.floor((e + math.pi) / two_pi)  # wrap to [-pi, pi)
            eb = e * inv_b
            a = log_zdet + log_norm - 0.5 * (er * er + eb * eb)
            # log(exp(a) + exp(log_c)), stable, with -inf handled
            if a == -np.inf:
                acc += log_c
            elif log_c == -np.inf:
                acc += a
            elif a > log_c:
                acc += a + math.log1p(math.exp(log_c - a))
            else:
                acc += log_c + math.log1p(math.exp(a - log_c))
        out[i] = acc
    return out
