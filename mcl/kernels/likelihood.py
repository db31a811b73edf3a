"""Numba kernels of the likelihood field range finder model (Prob. Rob. Table 6.3), and a scan matcher on its
distance field.

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


@njit(cache=True, nogil=True)
def _bilinear(dist, fx, fy):
    """(d, dd/dfx, dd/dfy) of ``dist`` (values at cell centres) at (fx, fy) in cell units; d = -1 off the table."""
    h = dist.shape[0]
    w = dist.shape[1]
    gx = fx - 0.5
    gy = fy - 0.5
    if not (gx >= 0.0 and gx < w - 1 and gy >= 0.0 and gy < h - 1):
        return -1.0, 0.0, 0.0
    ix = int(gx)
    iy = int(gy)
    ax = gx - ix
    ay = gy - iy
    d00 = dist[iy, ix]
    d01 = dist[iy, ix + 1]
    d10 = dist[iy + 1, ix]
    d11 = dist[iy + 1, ix + 1]
    d = (1 - ay) * ((1 - ax) * d00 + ax * d01) + ay * ((1 - ax) * d10 + ax * d11)
    ddx = (1 - ay) * (d01 - d00) + ay * (d11 - d10)
    ddy = (1 - ax) * (d10 - d00) + ax * (d11 - d01)
    return d, ddx, ddy


@njit(cache=True, parallel=True)
def refine_poses(particles, endpoints_cells, dist, ox, oy, inv_res, max_d, iters, max_xy, max_th, allowed, out):
    """Scan matching on the distance field: out[:, i] is particle i's pose after ``iters`` Gauss-Newton steps on
    sum_k d(e_k)^2, d the distance (m, bilinear over cell centres) from beam k's endpoint e_k to the nearest wall.

    particles: (3, N) world poses; endpoints_cells: (2, K) robot-frame endpoints in cell units (as
    ``likelihood_field_loglik``); dist: (H, W) float64 metres, row 0 at world y = oy. Endpoints off the table or
    farther than ``max_d`` from a wall (unmapped objects, the wrong place) are left out of a step; fewer than 3
    left ends the matching. Each step solves the 3x3 normal equations (J^T J) delta = -J^T d, with
    J_k = (dd/dx, dd/dy, dd/dtheta) = (gx, gy, gx * de_x/dtheta + gy * de_y/dtheta), capped at ``max_xy`` m and
    ``max_th`` rad; a step that would leave the ``allowed`` cells (nonzero = free) is not taken and ends it.
    Hector SLAM matches its scans to the map the same way (Kohlbrecher et al. 2011).
    """
    n = particles.shape[1]
    k = endpoints_cells.shape[1]
    h = allowed.shape[0]
    w = allowed.shape[1]
    for i in prange(n):
        x = (particles[0, i] - ox) * inv_res
        y = (particles[1, i] - oy) * inv_res
        th = particles[2, i]
        for _ in range(iters):
            c = math.cos(th)
            s = math.sin(th)
            h00 = 0.0
            h01 = 0.0
            h02 = 0.0
            h11 = 0.0
            h12 = 0.0
            h22 = 0.0
            g0 = 0.0
            g1 = 0.0
            g2 = 0.0
            m = 0
            for j in range(k):
                bx = endpoints_cells[0, j]
                by = endpoints_cells[1, j]
                d, dx, dy = _bilinear(dist, x + c * bx - s * by, y + s * bx + c * by)
                if d < 0.0 or d > max_d:
                    continue
                # residual d (m); Jacobian in (cells, cells, rad)
                jt = dx * (-s * bx - c * by) + dy * (c * bx - s * by)
                h00 += dx * dx
                h01 += dx * dy
                h02 += dx * jt
                h11 += dy * dy
                h12 += dy * jt
                h22 += jt * jt
                g0 += dx * d
                g1 += dy * d
                g2 += jt * d
                m += 1
            if m < 3:
                break
            lam = 1e-6 * (h00 + h11 + h22) + 1e-12  # a touch of damping: a straight wall leaves H singular
            h00 += lam
            h11 += lam
            h22 += lam
            # solve H delta = -g (3x3, Cramer's rule)
            c00 = h11 * h22 - h12 * h12
            c01 = h02 * h12 - h01 * h22
            c02 = h01 * h12 - h02 * h11
            det = h00 * c00 + h01 * c01 + h02 * c02
            if not (abs(det) > 0.0):
                break
            c11 = h00 * h22 - h02 * h02
            c12 = h01 * h02 - h00 * h12
            c22 = h00 * h11 - h01 * h01
            d0 = -(c00 * g0 + c01 * g1 + c02 * g2) / det
            d1 = -(c01 * g0 + c11 * g1 + c12 * g2) / det
            d2 = -(c02 * g0 + c12 * g1 + c22 * g2) / det
            step = math.hypot(d0, d1) / inv_res
            if step > max_xy:
                d0 *= max_xy / step
                d1 *= max_xy / step
            if d2 > max_th:
                d2 = max_th
            elif d2 < -max_th:
                d2 = -max_th
            nx = x + d0
            ny = y + d1
            if not (nx >= 0.0 and nx < w and ny >= 0.0 and ny < h) or allowed[int(ny), int(nx)] == 0:
                break
            x = nx
            y = ny
            th += d2
        out[0, i] = x / inv_res + ox
        out[1, i] = y / inv_res + oy
        out[2, i] = th


refine_poses_serial = serial_twin(refine_poses)


@njit(cache=True, parallel=True)
def free_ray_loglik(particles, rays, dist, ox, oy, inv_res, reach, log_miss, scale, out):
    """out[i] += scale * log_miss * (the number of no-return rays that meet a mapped obstacle within ``reach`` m
    seen from particle i): the negative information of readings with no return, which the likelihood field
    (Prob. Rob. Table 6.3) leaves out.

    rays: (4, R) float64, per ray the laser's position (x, y, m) and the beam's unit direction (ux, uy), in the
    robot frame. dist: (H, W) float32 metres from each cell to the nearest occupied cell (``OccupancyGrid.
    distance``). Each ray is marched by sphere tracing on ``dist``: from a point ``d`` m from every obstacle the
    ray can advance ``d`` less a cell without meeting one, so open space is crossed in a few long steps. A point
    within one cell of an obstacle is a meeting; a ray that leaves the map meets nothing.
    """
    n = particles.shape[1]
    r = rays.shape[1]
    h_cells = dist.shape[0]
    w_cells = dist.shape[1]
    res = 1.0 / inv_res
    for i in prange(n):
        th = particles[2, i]
        c = math.cos(th)
        s = math.sin(th)
        met = 0
        for j in range(r):
            sx = particles[0, i] + c * rays[0, j] - s * rays[1, j]
            sy = particles[1, i] + s * rays[0, j] + c * rays[1, j]
            dx = c * rays[2, j] - s * rays[3, j]
            dy = s * rays[2, j] + c * rays[3, j]
            t = 0.0
            while t < reach:
                fx = (sx + t * dx - ox) * inv_res
                fy = (sy + t * dy - oy) * inv_res
                if not (fx >= 0.0 and fx < w_cells and fy >= 0.0 and fy < h_cells):
                    break
                d = dist[int(fy), int(fx)]
                if d <= res:
                    met += 1
                    break
                t += max(d - res, 0.5 * res)
        out[i] += scale * log_miss * met


free_ray_loglik_serial = serial_twin(free_ray_loglik)
