"""Numba kernels of the beam range finder model (Prob. Rob. Table 6.1, beam_range_finder_model).

Per beam, the expected range z* comes from an exact DDA ray cast
(:func:`mcl.kernels.raycast.cast_ray`) from the particle's laser pose, or from
a precomputed (y, x, theta-bin) table of ranges; the reading z is then scored
by the mixture

    p(z | z*) = z_hit * p_hit + z_short * p_short + z_max * p_max + z_rand * p_rand

with (all on [0, zmax], zmax the sensor's maximum range)

    p_hit   = N(z; z*, sigma^2) / (Phi((zmax - z*)/sigma) - Phi(-z*/sigma))   for 0 <= z <= zmax
    p_short = lam * exp(-lam z) / (1 - exp(-lam z*))                          for 0 <= z <= z*
    p_max   = 1                                                               for z >= zmax (no return)
    p_rand  = 1 / zmax                                                        for 0 <= z < zmax

``params`` is the float64 array (z_hit, z_short, z_max, z_rand, sigma_hit,
lambda_short). Each particle's log-likelihood is summed in float64 in beam
order, so the result does not depend on the thread count. Pure functions
over arrays; no randomness.
"""

import math

import numpy as np
from numba import njit, prange

from mcl.kernels import serial_twin
from mcl.kernels.raycast import cast_ray

_SQRT2 = math.sqrt(2.0)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
_TWO_PI = 2.0 * math.pi

# The mixture weights in ``params``.
HIT, SHORT, MAX, RAND, SIGMA, LAMBDA = 0, 1, 2, 3, 4, 5


@njit(cache=True, nogil=True)
def beam_prob(z, zs, zmax, params):
    """p(z | z*) of one beam: the four-component mixture above (a density plus the p_max atom at zmax). At z* = 0
    (the laser inside an obstacle) p_short is a point mass at 0 and is left out: the mixture's mass there is
    1 - z_short, a pose inside a wall scoring that much lower."""
    z_hit = params[0]
    z_short = params[1]
    z_max = params[2]
    z_rand = params[3]
    sigma = params[4]
    lam = params[5]
    p = 0.0
    if z_hit > 0.0 and z >= 0.0 and z <= zmax:
        u = (z - zs) / sigma
        # eta = Phi((zmax - z*)/sigma) - Phi(-z*/sigma); it differs from 1 by < 1e-15 when z* is over
        # 8.3 sigma inside [0, zmax] (the common case), so the two erf calls are skipped there.
        if zs > 8.3 * sigma and zmax - zs > 8.3 * sigma:
            eta = 1.0
        else:
            eta = 0.5 * (math.erf((zmax - zs) / (sigma * _SQRT2)) - math.erf(-zs / (sigma * _SQRT2)))
        if eta > 0.0:
            p += z_hit * _INV_SQRT_2PI / sigma * math.exp(-0.5 * u * u) / eta
    if z_short > 0.0 and z >= 0.0 and z <= zs and zs > 0.0:
        p += z_short * lam * math.exp(-lam * z) / -math.expm1(-lam * zs)
    if z >= zmax:
        p += z_max
    elif z >= 0.0:
        p += z_rand / zmax
    return p


@njit(cache=True, parallel=True)
def beam_loglik(particles, ranges, angles, lx, ly, lth, blocked, ox, oy, res, zmax, params, scale, out):
    """out[i] = scale * sum_k log p(ranges[k] | z*_ik), z*_ik cast from particle i's laser pose.

    particles: (3, N) world poses; ranges, angles: (K,) readings (no-return
    readings set to zmax) and beam angles in the laser frame; (lx, ly, lth):
    laser pose in the robot frame; blocked: (H, W) bool/uint8 occupied cells,
    row 0 at world y = oy; res: cell size (m); zmax: maximum range (m).
    One ray cast per particle and beam.
    """
    n = particles.shape[1]
    k = ranges.shape[0]
    for i in prange(n):
        th = particles[2, i]
        c = math.cos(th)
        s = math.sin(th)
        x = particles[0, i] + c * lx - s * ly
        y = particles[1, i] + s * lx + c * ly
        a0 = th + lth
        acc = 0.0
        for j in range(k):
            zs = cast_ray(x, y, a0 + angles[j], blocked, ox, oy, res, zmax)
            acc += math.log(beam_prob(ranges[j], zs, zmax, params))
        out[i] = scale * acc


@njit(cache=True, parallel=True)
def build_range_table(blocked, ox, oy, res, max_range, unit, out):
    """out[iy, ix, b] = range cast from the centre of cell (ix, iy) at world angle b * 2 pi / B, in `unit` m.

    out: (H, W, B) uint16; ranges are rounded to the nearest multiple of
    `unit` (choose unit >= max_range / 65535). Occupied cells hold 0.
    Parallel over rows; each entry is one independent cast.
    """
    h = out.shape[0]
    w = out.shape[1]
    nb = out.shape[2]
    step = _TWO_PI / nb
    for iy in prange(h):
        y = oy + (iy + 0.5) * res
        for ix in range(w):
            if blocked[iy, ix]:
                for b in range(nb):
                    out[iy, ix, b] = 0
                continue
            x = ox + (ix + 0.5) * res
            for b in range(nb):
                z = cast_ray(x, y, b * step, blocked, ox, oy, res, max_range)
                out[iy, ix, b] = np.uint16(math.floor(z / unit + 0.5))


@njit(cache=True, parallel=True)
def beam_loglik_lut(particles, ranges, angles, lx, ly, lth, table, unit, ox, oy, res, zmax, params, scale, out):
    """``beam_loglik`` with z* gathered from ``build_range_table``'s table instead of cast.

    The laser's cell is floor((x - ox) / res), floor((y - oy) / res); the
    angle bin is the nearest multiple of 2 pi / B. A laser outside the table
    expects no return (z* = zmax). z* = min(table * unit, zmax).
    """
    n = particles.shape[1]
    k = ranges.shape[0]
    h = table.shape[0]
    w = table.shape[1]
    nb = table.shape[2]
    inv_step = nb / _TWO_PI
    inv_res = 1.0 / res
    for i in prange(n):
        th = particles[2, i]
        c = math.cos(th)
        s = math.sin(th)
        fx = (particles[0, i] + c * lx - s * ly - ox) * inv_res
        fy = (particles[1, i] + s * lx + c * ly - oy) * inv_res
        a0 = th + lth
        inside = fx >= 0.0 and fx < w and fy >= 0.0 and fy < h
        ix = int(fx) if inside else 0
        iy = int(fy) if inside else 0
        acc = 0.0
        for j in range(k):
            if inside:
                b = int(math.floor((a0 + angles[j]) * inv_step + 0.5)) % nb
                zs = min(table[iy, ix, b] * unit, zmax)
            else:
                zs = zmax
            acc += math.log(beam_prob(ranges[j], zs, zmax, params))
        out[i] = scale * acc


beam_loglik_serial = serial_twin(beam_loglik)
beam_loglik_lut_serial = serial_twin(beam_loglik_lut)
