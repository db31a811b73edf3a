"""Numba kernel of the likelihood field range finder model (Prob. Rob. Table 6.3).

The per-cell log-likelihood table is precomputed per map (``mcl.sensors``);
the kernel only rotates the scan's endpoints into each particle's frame and
gathers table values. Pure function over arrays.
"""

import math

from numba import njit, prange

from mcl.kernels import serial_twin


@njit(cache=True, parallel=True)
def likelihood_field_loglik(particles, endpoints_cells, table, ox, oy, inv_res, offmap, scale, out):
    """out[i] = scale * sum_k table[cell of endpoint k seen from particle i].

    particles: (3, N) float64 world poses (x, y, theta) in metres.
    endpoints_cells: (2, K) float64 beam endpoints in the robot frame,
    already multiplied by inv_res (cell units).
    table: (H, W) float32 per-cell log-likelihoods, row 0 at world y = oy.
    ox, oy: map origin (m); inv_res: 1 / cell size (1/m).
    offmap: the value added for an endpoint outside the table.

    One cos/sin per particle; per beam, in cell units,
        fx = (x - ox) * inv_res + c*bx - s*by,  fy = (y - oy) * inv_res + s*bx + c*by,
    and the cell (floor(fy), floor(fx)) is gathered when inside the table.
    Each particle's sum runs in float64 in beam order, so the result does
    not depend on the thread count.
    """
    n = particles.shape[1]
    k = endpoints_cells.shape[1]
    h_cells = table.shape[0]
    w_cells = table.shape[1]
    for i in prange(n):
        th = particles[2, i]
        c = math.cos(th)
        s = math.sin(th)
        px = (particles[0, i] - ox) * inv_res
        py = (particles[1, i] - oy) * inv_res
        acc = 0.0
        for j in range(k):
            bx = endpoints_cells[0, j]
            by = endpoints_cells[1, j]
            fx = px + (c * bx - s * by)
            fy = py + (s * bx + c * by)
            # fx >= 0 makes int() (truncation) equal floor; NaN fails every comparison.
            if fx >= 0.0 and fx < w_cells and fy >= 0.0 and fy < h_cells:
                acc += table[int(fy), int(fx)]
            else:
                acc += offmap
        out[i] = scale * acc


likelihood_field_loglik_serial = serial_twin(likelihood_field_loglik)


@njit(cache=True)
def beam_explained_weight(px, py, cos_th, sin_th, weights, endpoints_cells, dist, max_d, out):
    """out[k] = sum of weights[i] over the particles i whose endpoint k lies within max_d of an obstacle.

    The per-beam statistic of beam skipping (AMCL ``likelihood_field_prob``):
    how much of the particle set explains beam k. px, py (N,): particle
    positions in cell units relative to the map origin ((x - ox) * inv_res);
    cos_th, sin_th (N,): of the particle headings; weights (N,) float64;
    endpoints_cells (2, K): robot-frame endpoints in cell units (as
    ``likelihood_field_loglik``); dist (H, W) float32 metres to the nearest
    occupied cell centre, row 0 at the origin. Endpoints off the map are not
    explained. Serial: it sees at most 2,000 particles (``mcl.sensors``), too
    little work to pay for waking threads.
    """
    n = px.shape[0]
    k = endpoints_cells.shape[1]
    h_cells = dist.shape[0]
    w_cells = dist.shape[1]
    for j in range(k):
        bx = endpoints_cells[0, j]
        by = endpoints_cells[1, j]
        acc = 0.0
        for i in range(n):
            c = cos_th[i]
            s = sin_th[i]
            fx = px[i] + (c * bx - s * by)
            fy = py[i] + (s * bx + c * by)
            if fx >= 0.0 and fx < w_cells and fy >= 0.0 and fy < h_cells:
                if dist[int(fy), int(fx)] < max_d:
                    acc += weights[i]
        out[j] = acc
