"""Plane-feature kernels: depth rendering of a 2.5D grid world, the randomized Hough transform and RANSAC
plane detectors, the weighted plane fit, and the plane measurement model's log-likelihood for N poses.

Planes are ``n . p = rho`` with ``n = (sin t cos f, sin t sin f, cos t)`` (theta t, phi f; seed 003,
"Kinect Features (Plane)") and ``rho >= 0``. Random numbers come in as arrays of uniforms drawn by the
caller's ``np.random.Generator``: the kernels are serial and a seed gives the same planes everywhere.
"""

import math

import numpy as np
from numba import njit, prange


# ----------------------------------------------------------------------------- rendering (simulator)


@njit(cache=True, parallel=True)
def render_depth(rot, origin, fx, fy, cx, cy, heights, ox, oy, res, z_max, out):
    """out[v, u] = depth (optical z, m) of the first surface pixel (u, v) sees, 0 when none within z_max.

    rot (3, 3): world-from-optical rotation (optical: x right, y down, z forward); origin (3,) the camera
    centre in the world. The world is a 2.5D grid: ``heights[i, j] > 0`` is a column of that height standing
    on the floor z = 0 (cell (i, j) spans x in ox + [j, j+1] res, y in oy + [i, i+1] res). A ray hits a
    column's side face where it enters the cell below the top, its top face where it drops below the top
    inside the cell, or the floor. Walk: 2D DDA over the cells, parameterised by depth t (the ray is
    origin + t * rot @ (x_n, y_n, 1)). Each pixel is independent (parallel over rows).
    """
    hgt, wid = out.shape
    gh, gw = heights.shape
    for v in prange(hgt):
        for u in range(wid):
            xn = (u + 0.5 - cx) / fx
            yn = (v + 0.5 - cy) / fy
            dx = rot[0, 0] * xn + rot[0, 1] * yn + rot[0, 2]
            dy = rot[1, 0] * xn + rot[1, 1] * yn + rot[1, 2]
            dz = rot[2, 0] * xn + rot[2, 1] * yn + rot[2, 2]
            t_floor = -origin[2] / dz if dz < 0.0 else np.inf
            gx = (origin[0] - ox) / res
            gy = (origin[1] - oy) / res
            j = int(math.floor(gx))
            i = int(math.floor(gy))
            step_j = 1 if dx > 0 else -1
            step_i = 1 if dy > 0 else -1
            inf = np.inf
            tdx = abs(res / dx) if dx != 0.0 else inf
            tdy = abs(res / dy) if dy != 0.0 else inf
            tx = ((j + 1 - gx) if dx > 0 else (gx - j)) * tdx if dx != 0.0 else inf
            ty = ((i + 1 - gy) if dy > 0 else (gy - i)) * tdy if dy != 0.0 else inf
            t_in = 0.0
            hit = 0.0
            while t_in < z_max:
                t_out = min(tx, ty)
                if i < 0 or i >= gh or j < 0 or j >= gw:
                    break
                h = heights[i, j]
                if h > 0.0:
                    z_in = origin[2] + t_in * dz
                    if z_in <= h:
                        hit = t_in if z_in >= 0.0 else t_floor
                        break
                    z_out = origin[2] + t_out * dz
                    if z_out <= h:  # drops onto the top inside this cell
                        hit = (h - origin[2]) / dz
                        break
                if t_floor <= t_out:
                    hit = t_floor
                    break
                t_in = t_out
                if tx < ty:
                    tx += tdx
                    j += step_j
                else:
                    ty += tdy
                    i += step_i
            out[v, u] = hit if 0.0 < hit < z_max else 0.0
    return out


# ----------------------------------------------------------------------------- fitting


@njit(cache=True)
def fit_plane_weighted(pts, w, idx, n_idx, out):
    """Weighted total-least-squares plane through pts[idx[:n_idx]]: minimises sum w (n.p - rho)^2, |n| = 1.

    The weighted centroid c and the smallest eigenvector n of the weighted scatter; rho = n.c >= 0 (n
    flipped). out[:] = (nx, ny, nz, rho). Returns False when fewer than 3 points or no unique normal.
    """
    if n_idx < 3:
        return False
    sw = 0.0
    c0 = 0.0
    c1 = 0.0
    c2 = 0.0
    for k in range(n_idx):
        q = idx[k]
        sw += w[q]
        c0 += w[q] * pts[q, 0]
        c1 += w[q] * pts[q, 1]
        c2 += w[q] * pts[q, 2]
    if not sw > 0.0:
        return False
    c0 /= sw
    c1 /= sw
    c2 /= sw
    s = np.zeros((3, 3))
    for k in range(n_idx):
        q = idx[k]
        a = pts[q, 0] - c0
        b = pts[q, 1] - c1
        c = pts[q, 2] - c2
        s[0, 0] += w[q] * a * a
        s[0, 1] += w[q] * a * b
        s[0, 2] += w[q] * a * c
        s[1, 1] += w[q] * b * b
        s[1, 2] += w[q] * b * c
        s[2, 2] += w[q] * c * c
    s[1, 0] = s[0, 1]
    s[2, 0] = s[0, 2]
    s[2, 1] = s[1, 2]
    vals, vecs = np.linalg.eigh(s)
    if not vals[1] > 1e-12 * max(vals[2], 1e-300):
        return False
    nx, ny, nz = vecs[0, 0], vecs[1, 0], vecs[2, 0]
    rho = nx * c0 + ny * c1 + nz * c2
    if rho < 0.0:
        nx, ny, nz, rho = -nx, -ny, -nz, -rho
    out[0] = nx
    out[1] = ny
    out[2] = nz
    out[3] = rho
    return True


@njit(cache=True)
def residual_std(noise, ray_dot, rho):
    """Std of a point's residual n . p - rho on the plane (n, rho): the depth noise at the depth the plane
    predicts along the point's ray, z = rho / (n . ray), seen along the normal: sigma_z(z) |n . ray|.
    ``ray`` is the point over its depth (optical z = 1); noise = (sigma_a, sigma_b, z0, quantization^2 / 12).
    Computed from the plane, not the measured depth: weights from the measured depth favour the points
    the noise moved nearer, a bias of about one standard deviation of rho."""
    a = max(abs(ray_dot), 1e-6)
    z = rho / a
    sz = noise[0] + noise[1] * (z - noise[2]) ** 2
    return math.sqrt(sz * sz + noise[3]) * a


@njit(cache=True)
def _select(pts, rays, noise, active, plane, k_sigma, idx):
    """Indices (into idx) of the active points within k_sigma residual stds of the plane; returns the count."""
    m = 0
    nx, ny, nz, rho = plane[0], plane[1], plane[2], plane[3]
    for q in range(pts.shape[0]):
        if not active[q]:
            continue
        r = nx * pts[q, 0] + ny * pts[q, 1] + nz * pts[q, 2]
        s = residual_std(noise, nx * rays[q, 0] + ny * rays[q, 1] + nz * rays[q, 2], rho)
        if abs(r - rho) <= k_sigma * s:
            idx[m] = q
            m += 1
    return m


@njit(cache=True)
def _take_plane(idx, m, plane, found, active, labels, planes, alive):
    """Accept ``plane`` as plane number ``found`` with its m inliers idx[:m]: delete its points (the seed's
    "delete the points of that plane"), label them, store it; refill ``alive`` with the points left. Returns
    how many are left."""
    for k in range(m):
        active[idx[k]] = False
        labels[idx[k]] = found
    for q in range(4):
        planes[found, q] = plane[q]
    n_alive = 0
    for q in range(active.shape[0]):
        if active[q]:
            alive[n_alive] = q
            n_alive += 1
    return n_alive


@njit(cache=True)
def _refine(pts, rays, noise, active, plane, k_sigma, coarse, idx, w):
    """Inliers of a candidate plane and its weighted fit: points within ``coarse`` m first, then three rounds
    of (weighted fit, k_sigma selection). Returns the inlier count (0 when the fit fails)."""
    m = 0
    nx, ny, nz, rho = plane[0], plane[1], plane[2], plane[3]
    for q in range(pts.shape[0]):
        if active[q] and abs(nx * pts[q, 0] + ny * pts[q, 1] + nz * pts[q, 2] - rho) <= coarse:
            idx[m] = q
            m += 1
    for _ in range(3):
        for k in range(m):
            q = idx[k]
            s = residual_std(noise, plane[0] * rays[q, 0] + plane[1] * rays[q, 1] + plane[2] * rays[q, 2],
                             plane[3])
            w[q] = 1.0 / (s * s)
        if not fit_plane_weighted(pts, w, idx, m, plane):
            return 0
        m = _select(pts, rays, noise, active, plane, k_sigma, idx)
    return m


# ----------------------------------------------------------------------------- randomized Hough transform


@njit(cache=True)
def rht_detect(pts, rays, noise, pix, grid, uniforms, max_planes, min_points, min_inliers, votes,
               region_px, n_theta, n_phi, rho_step, n_rho, k_sigma, coarse, labels, planes):
    """The seed's randomized Hough transform (seed 003, "Kinect Features (Plane)").

    While fewer than ``max_planes`` planes are found, more than ``min_points`` points remain and trials
    remain (one row of ``uniforms`` (T, 5) per trial): pick P1 among the remaining points and P2, P3 in
    the disk of ``region_px`` pixels around it (the random circular region; ``pix`` (M, 2) are the points'
    pixel (row, col) in ``grid``, which holds point indices or -1); the plane through them votes in the
    (theta, phi, rho) accumulator; a cell reaching ``votes`` is the local maximum: its plane (the mean of
    its votes) is refined on the points near it, and when it has ``min_inliers`` those points are deleted
    (labelled with the plane's index); the accumulator is reset either way.

    labels (M,) int64 out (-1: no plane); planes (max_planes, 4) out (nx, ny, nz, rho).
    Returns (planes found, trials used).
    """
    m_pts = pts.shape[0]
    active = np.ones(m_pts, dtype=np.bool_)
    labels[:] = -1
    alive = np.arange(m_pts)
    n_alive = m_pts
    acc = np.zeros(n_theta * n_phi * n_rho, dtype=np.int32)
    n_trials = uniforms.shape[0]
    vote_cell = np.empty(n_trials, dtype=np.int64)
    vote_plane = np.empty((n_trials, 4))
    n_votes = 0
    idx = np.empty(m_pts, dtype=np.int64)
    w = np.empty(m_pts)
    cand = np.empty(4)
    gh, gw = grid.shape
    d_theta = math.pi / n_theta
    d_phi = 2.0 * math.pi / n_phi
    found = 0
    trial = 0
    while found < max_planes and n_alive > min_points and trial < n_trials:
        u = uniforms[trial]
        trial += 1
        a = alive[min(int(u[0] * n_alive), n_alive - 1)]
        r1 = region_px * math.sqrt(u[1])
        a1 = 2.0 * math.pi * u[2]
        r2 = region_px * math.sqrt(u[3])
        a2 = 2.0 * math.pi * u[4]
        i1 = pix[a, 0] + int(round(r1 * math.sin(a1)))
        j1 = pix[a, 1] + int(round(r1 * math.cos(a1)))
        i2 = pix[a, 0] + int(round(r2 * math.sin(a2)))
        j2 = pix[a, 1] + int(round(r2 * math.cos(a2)))
        if i1 < 0 or i1 >= gh or j1 < 0 or j1 >= gw or i2 < 0 or i2 >= gh or j2 < 0 or j2 >= gw:
            continue
        b = grid[i1, j1]
        c = grid[i2, j2]
        if b < 0 or c < 0 or b == a or c == a or b == c or not active[b] or not active[c]:
            continue
        e0 = pts[b, 0] - pts[a, 0]
        e1 = pts[b, 1] - pts[a, 1]
        e2 = pts[b, 2] - pts[a, 2]
        f0 = pts[c, 0] - pts[a, 0]
        f1 = pts[c, 1] - pts[a, 1]
        f2 = pts[c, 2] - pts[a, 2]
        nx = e1 * f2 - e2 * f1
        ny = e2 * f0 - e0 * f2
        nz = e0 * f1 - e1 * f0
        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
        ee = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        ff = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        if not nn > 0.2 * ee * ff:  # nearly collinear: no plane
            continue
        nx /= nn
        ny /= nn
        nz /= nn
        rho = nx * pts[a, 0] + ny * pts[a, 1] + nz * pts[a, 2]
        if rho < 0.0:
            nx, ny, nz, rho = -nx, -ny, -nz, -rho
        it = min(int(math.acos(max(-1.0, min(1.0, nz))) / d_theta), n_theta - 1)
        ip = 0
        if 0 < it < n_theta - 1:  # at the poles phi is undefined: one phi cell
            ip = min(int((math.atan2(ny, nx) + math.pi) / d_phi), n_phi - 1)
        ir = int(rho / rho_step)
        if ir >= n_rho:
            continue
        cell = (it * n_phi + ip) * n_rho + ir
        acc[cell] += 1
        vote_cell[n_votes] = cell
        vote_plane[n_votes, 0] = nx
        vote_plane[n_votes, 1] = ny
        vote_plane[n_votes, 2] = nz
        vote_plane[n_votes, 3] = rho
        n_votes += 1
        if acc[cell] < votes:
            continue
        # a local maximum: the mean plane of the cell's votes
        cand[:] = 0.0
        for k in range(n_votes):
            if vote_cell[k] == cell:
                for q in range(4):
                    cand[q] += vote_plane[k, q]
        nrm = math.sqrt(cand[0] ** 2 + cand[1] ** 2 + cand[2] ** 2)
        for q in range(3):
            cand[q] /= nrm
        cand[3] /= acc[cell]
        m = _refine(pts, rays, noise, active, cand, k_sigma, coarse, idx, w)
        if m >= min_inliers:
            n_alive = _take_plane(idx, m, cand, found, active, labels, planes, alive)
            found += 1
        for k in range(n_votes):  # reset the Hough space
            acc[vote_cell[k]] = 0
        n_votes = 0
    return found, trial


@njit(cache=True)
def finish_planes(pts, rays, noise, pix, grid, planes, k_sigma, erode, z_lo, z_hi, labels):
    """Final inliers and fits of the K detected planes (K, 4), in place; labels (M,) out (-1: none).

    Twice: each point within k_sigma residual stds of exactly one plane is that plane's (a point near
    two, at a wall's foot or in a corner, is left out), and each plane is fitted again on its points.
    Points whose depth on the plane, rho / (n . ray), is outside [z_lo, z_hi] are left out: near the
    camera's range limits the noise decides whether a point has a reading at all, and keeping only the
    readings inside the range would keep the ones the noise moved nearer (a bias in rho and in the
    angles of an oblique wall). The plane, not the reading, decides, so this is no selection on the noise.
    Then the border band of ``erode`` pixels of each plane's image region is left out (points of a
    neighbouring surface within k_sigma of the plane lie there; pixels with no reading do not count as
    border) and the planes are fitted a last time.
    """
    m_pts = pts.shape[0]
    k = planes.shape[0]
    idx = np.empty(m_pts, dtype=np.int64)
    w = np.empty(m_pts)
    gh, gw = grid.shape
    for rnd in range(2):
        for q in range(m_pts):
            lab = -1
            for j in range(k):
                r = planes[j, 0] * pts[q, 0] + planes[j, 1] * pts[q, 1] + planes[j, 2] * pts[q, 2] - planes[j, 3]
                d = planes[j, 0] * rays[q, 0] + planes[j, 1] * rays[q, 1] + planes[j, 2] * rays[q, 2]
                s = residual_std(noise, d, planes[j, 3])
                if abs(r) <= k_sigma * s:
                    zp = planes[j, 3] / max(abs(d), 1e-9)
                    if zp < z_lo or zp > z_hi:
                        lab = -2
                        break
                    if lab == -1:
                        lab = j
                        w[q] = 1.0 / (s * s)
                    else:
                        lab = -2
                        break
            labels[q] = lab if lab >= 0 else -1
        if rnd == 1 and erode > 0:
            keep = np.ones(m_pts, dtype=np.bool_)
            for q in range(m_pts):
                j = labels[q]
                if j < 0:
                    continue
                r0 = pix[q, 0]
                c0 = pix[q, 1]
                for di in range(-erode, erode + 1):
                    for dj in range(-erode, erode + 1):
                        ii = r0 + di
                        jj = c0 + dj
                        if ii < 0 or ii >= gh or jj < 0 or jj >= gw:
                            continue
                        o = grid[ii, jj]
                        if o >= 0 and labels[o] != j:
                            keep[q] = False
            for q in range(m_pts):
                if not keep[q]:
                    labels[q] = -1
        for j in range(k):
            m = 0
            for q in range(m_pts):
                if labels[q] == j:
                    idx[m] = q
                    m += 1
            fit_plane_weighted(pts, w, idx, m, planes[j])
    return labels


@njit(cache=True)
def _tangents(nx, ny, nz):
    hx, hy = -ny, nx
    hn = math.sqrt(hx * hx + hy * hy)
    if hn < 1e-6:
        hx, hy, hn = 1.0, 0.0, 1.0
    hx /= hn
    hy /= hn
    # v = n x h (h has no z)
    return hx, hy, 0.0, ny * 0.0 - nz * hy, nz * hx - nx * 0.0, nx * hy - ny * hx


@njit(cache=True)
def depth_fit(depth, rays, idx, n_idx, noise, plane, iterations, info):
    """Maximum likelihood plane under depth noise, in place: Gauss-Newton on the depth residuals
    (z_i - rho / (n . d_i)) / sigma_z(rho / (n . d_i)) of the points idx[:n_idx], n moving in its tangent
    plane (no pole at the floor). info (3, 3) out: the information matrix sum J J^T of (theta, phi, rho)
    at the result, J = (rho n_theta . d, rho n_phi . d, -(n . d)) / ((n . d)^2 sigma_z).
    """
    jtj = np.empty((3, 3))
    jtr = np.empty(3)
    for it in range(iterations + 1):
        nx, ny, nz, rho = plane[0], plane[1], plane[2], plane[3]
        last = it == iterations
        if last:
            th = math.acos(max(-1.0, min(1.0, nz)))
            ph = math.atan2(ny, nx)
            ct, st, cp, sp = math.cos(th), math.sin(th), math.cos(ph), math.sin(ph)
            ax, ay, az = ct * cp, ct * sp, -st
            bx, by, bz = -st * sp, st * cp, 0.0
        else:
            ax, ay, az, bx, by, bz = _tangents(nx, ny, nz)
        jtj[:, :] = 0.0
        jtr[:] = 0.0
        for k in range(n_idx):
            q = idx[k]
            nd = max(nx * rays[q, 0] + ny * rays[q, 1] + nz * rays[q, 2], 1e-9)
            zp = rho / nd
            sz = noise[0] + noise[1] * (zp - noise[2]) ** 2
            sz = math.sqrt(sz * sz + noise[3])
            r = (depth[q] - zp) / sz
            f = rho / (nd * nd * sz)
            j0 = f * (ax * rays[q, 0] + ay * rays[q, 1] + az * rays[q, 2])
            j1 = f * (bx * rays[q, 0] + by * rays[q, 1] + bz * rays[q, 2])
            j2 = -1.0 / (nd * sz)
            jtj[0, 0] += j0 * j0
            jtj[0, 1] += j0 * j1
            jtj[0, 2] += j0 * j2
            jtj[1, 1] += j1 * j1
            jtj[1, 2] += j1 * j2
            jtj[2, 2] += j2 * j2
            jtr[0] += j0 * r
            jtr[1] += j1 * r
            jtr[2] += j2 * r
        jtj[1, 0] = jtj[0, 1]
        jtj[2, 0] = jtj[0, 2]
        jtj[2, 1] = jtj[1, 2]
        if last:
            info[:, :] = jtj
            return True
        if abs(np.linalg.det(jtj)) < 1e-300:
            return False
        step = np.linalg.solve(jtj, -jtr)
        mx = nx + step[0] * ax + step[1] * bx
        my = ny + step[0] * ay + step[1] * by
        mz = nz + step[0] * az + step[1] * bz
        mn = math.sqrt(mx * mx + my * my + mz * mz)
        plane[0] = mx / mn
        plane[1] = my / mn
        plane[2] = mz / mn
        plane[3] = rho + step[2]
    return True


# ----------------------------------------------------------------------------- RANSAC


@njit(cache=True)
def ransac_detect(pts, rays, noise, uniforms, iterations, max_planes, min_points, min_inliers, k_sigma,
                  coarse, labels, planes):
    """Sequential RANSAC (Fischler & Bolles): for each plane, ``iterations`` triples drawn from all the
    remaining points (rows of ``uniforms`` (T, 3)), the plane with the most points within ``coarse`` m
    wins; refined like the RHT's; its inliers are deleted. Stops at ``max_planes``, when ``min_points`` or
    fewer remain, when the best plane has fewer than ``min_inliers`` points, or out of uniforms.
    Returns (planes found, triples used)."""
    m_pts = pts.shape[0]
    active = np.ones(m_pts, dtype=np.bool_)
    labels[:] = -1
    alive = np.arange(m_pts)
    n_alive = m_pts
    idx = np.empty(m_pts, dtype=np.int64)
    w = np.empty(m_pts)
    best = np.empty(4)
    found = 0
    used = 0
    n_rows = uniforms.shape[0]
    while found < max_planes and n_alive > min_points and used + iterations <= n_rows:
        best_count = -1
        for _ in range(iterations):
            u = uniforms[used]
            used += 1
            a = alive[min(int(u[0] * n_alive), n_alive - 1)]
            b = alive[min(int(u[1] * n_alive), n_alive - 1)]
            c = alive[min(int(u[2] * n_alive), n_alive - 1)]
            e0 = pts[b, 0] - pts[a, 0]
            e1 = pts[b, 1] - pts[a, 1]
            e2 = pts[b, 2] - pts[a, 2]
            f0 = pts[c, 0] - pts[a, 0]
            f1 = pts[c, 1] - pts[a, 1]
            f2 = pts[c, 2] - pts[a, 2]
            nx = e1 * f2 - e2 * f1
            ny = e2 * f0 - e0 * f2
            nz = e0 * f1 - e1 * f0
            nn = math.sqrt(nx * nx + ny * ny + nz * nz)
            if not nn > 1e-9:
                continue
            nx /= nn
            ny /= nn
            nz /= nn
            rho = nx * pts[a, 0] + ny * pts[a, 1] + nz * pts[a, 2]
            count = 0
            for k in range(n_alive):
                q = alive[k]
                if abs(nx * pts[q, 0] + ny * pts[q, 1] + nz * pts[q, 2] - rho) <= coarse:
                    count += 1
            if count > best_count:
                best_count = count
                if rho < 0.0:
                    nx, ny, nz, rho = -nx, -ny, -nz, -rho
                best[0] = nx
                best[1] = ny
                best[2] = nz
                best[3] = rho
        if best_count < min_inliers:
            break
        m = _refine(pts, rays, noise, active, best, k_sigma, coarse, idx, w)
        if m < min_inliers:
            break
        n_alive = _take_plane(idx, m, best, found, active, labels, planes, alive)
        found += 1
    return found, used


# ----------------------------------------------------------------------------- measurement model


@njit(cache=True)
def planes_loglik(particles, obs, faces, cam_x, cam_y, gate2, log_zdet, log_c, margin, out):
    """out[n] = sum_j log(z_det p_det(j | x_n) + z_fp p_uniform) for vertical plane observations.

    particles (3, N); obs (J, 7) rows (phi, rho, S_pp, S_pr, S_rr, c_x, c_y): the plane's (phi, rho) in the
    level camera frame, the innovation covariance S and the patch centre (m, horizontal, same frame).
    faces (F, 7) rows (n_x, n_y, d, a_x, a_y, b_x, b_y): map faces n . x = d seen from the side n points to,
    a -> b their horizontal extent. The camera sits at (cam_x, cam_y) in the robot frame. For each pose and
    observation the face nearest in Mahalanobis distance (phi, rho) among those the camera is in front of
    and whose extent (+- margin) holds the patch centre is the association; beyond ``gate2`` (squared
    Mahalanobis distance) p_det = 0.
    """
    n = particles.shape[1]
    nobs = obs.shape[0]
    nf = faces.shape[0]
    two_pi = 2.0 * math.pi
    for i in range(n):
        x = particles[0, i]
        y = particles[1, i]
        th = particles[2, i]
        c = math.cos(th)
        s = math.sin(th)
        px = x + c * cam_x - s * cam_y
        py = y + s * cam_x + c * cam_y
        acc = 0.0
        for j in range(nobs):
            spp = obs[j, 2]
            spr = obs[j, 3]
            srr = obs[j, 4]
            det = spp * srr - spr * spr
            qx = px + c * obs[j, 5] - s * obs[j, 6]
            qy = py + s * obs[j, 5] + c * obs[j, 6]
            best = np.inf
            for f in range(nf):
                nx = faces[f, 0]
                ny = faces[f, 1]
                rho_hat = nx * px + ny * py - faces[f, 2]
                if rho_hat <= 0.0:
                    continue
                ax = faces[f, 3]
                ay = faces[f, 4]
                bx = faces[f, 5] - ax
                by = faces[f, 6] - ay
                ln = math.sqrt(bx * bx + by * by)
                along = ((qx - ax) * bx + (qy - ay) * by) / ln
                if along < -margin or along > ln + margin:
                    continue
                e = obs[j, 0] - (math.atan2(-ny, -nx) - th)
                e -= two_pi * math.floor((e + math.pi) / two_pi)
                er = obs[j, 1] - rho_hat
                d2 = (srr * e * e - 2.0 * spr * e * er + spp * er * er) / det
                if d2 < best:
                    best = d2
            if best < gate2:
                a = log_zdet - math.log(two_pi * math.sqrt(det)) - 0.5 * best
                if log_c == -np.inf:
                    acc += a
                elif a > log_c:
                    acc += a + math.log1p(math.exp(log_c - a))
                else:
                    acc += log_c + math.log1p(math.exp(a - log_c))
            else:
                acc += log_c
        out[i] = acc
    return out
