"""Numba kernels of the odometry motion model (Prob. Rob. Table 5.6) and of its omnidirectional variant.

Pure functions over arrays. The caller draws the standard normal noise with
its ``numpy.random.Generator`` and passes it in, so a kernel's result does not
depend on the numba thread count. Angles come out in (-pi, pi]. Serial: one
motion step is a few arithmetic operations per particle (0.1 us), far below what
waking threads costs.
"""

import math

from numba import njit

_TWO_PI = 2.0 * math.pi


@njit(cache=True)
def wrap(a):
    """Angle a mapped into (-pi, pi] (a - 2 pi * ceil((a - pi) / 2 pi))."""
    return a - _TWO_PI * math.ceil((a - math.pi) / _TWO_PI)


@njit(cache=True)
def allowed_at(allowed, x, y, ox, oy, inv_res):
    """Whether world point (x, y) falls in a nonzero cell of the (H, W) mask ``allowed``.

    Row 0 at world y = oy; ix = floor((x - ox) * inv_res), iy likewise.
    Off-map (and NaN) points are not allowed. Shared by every motion model's
    map check (odometry, velocity).
    """
    fx = (x - ox) * inv_res
    fy = (y - oy) * inv_res
    # fx >= 0 makes int() (truncation) equal floor; NaN fails every comparison.
    if fx >= 0.0 and fx < allowed.shape[1] and fy >= 0.0 and fy < allowed.shape[0]:
        return allowed[int(fy), int(fx)] != 0
    return False


@njit(cache=True)
def sample_odometry(particles, noise, drot1, dtrans, drot2, s_rot1, s_trans, s_rot2, out):
    """Apply one noisy odometry step to every particle.

    particles, out: (3, N) float64 (x, y, theta); out may not alias particles.
    noise: (3, N) standard normals (rows rot1, trans, rot2), scaled here by
    the sigmas s_rot1, s_trans, s_rot2:
        rot1_hat = drot1 + s_rot1 * noise[0]   (the book subtracts; the noise is symmetric)
        x' = x + trans_hat * cos(theta + rot1_hat)
        y' = y + trans_hat * sin(theta + rot1_hat)
        theta' = wrap(theta + rot1_hat + rot2_hat)
    """
    n = particles.shape[1]
    for i in range(n):
        r1 = drot1 + s_rot1 * noise[0, i]
        tr = dtrans + s_trans * noise[1, i]
        r2 = drot2 + s_rot2 * noise[2, i]
        th = particles[2, i]
        h = th + r1
        out[0, i] = particles[0, i] + tr * math.cos(h)
        out[1, i] = particles[1, i] + tr * math.sin(h)
        out[2, i] = wrap(h + r2)


@njit(cache=True)
def sample_odometry_map(particles, noise, idx, drot1, dtrans, drot2, s_rot1, s_trans, s_rot2,
                        allowed, ox, oy, inv_res, out, ok):
    """Noisy odometry step for the particles idx, plus the map check, in one pass.

    For j in range(len(idx)), particle i = idx[j] moves with noise[:, j]
    (same formulas as sample_odometry) into out[:, i], and ok[i] is set to
    whether the new pose's cell is inside the (H, W) mask ``allowed``
    (nonzero = allowed; row 0 at world y = oy) with
    ix = floor((x' - ox) * inv_res), iy = floor((y' - oy) * inv_res).
    Off-map (and NaN) poses are not allowed. Returns the number of particles
    of idx that landed in an allowed cell.
    """
    m = idx.shape[0]
    n_ok = 0
    for j in range(m):
        i = idx[j]
        r1 = drot1 + s_rot1 * noise[0, j]
        tr = dtrans + s_trans * noise[1, j]
        r2 = drot2 + s_rot2 * noise[2, j]
        h = particles[2, i] + r1
        x = particles[0, i] + tr * math.cos(h)
        y = particles[1, i] + tr * math.sin(h)
        out[0, i] = x
        out[1, i] = y
        out[2, i] = wrap(h + r2)
        good = allowed_at(allowed, x, y, ox, oy, inv_res)
        ok[i] = good
        if good:
            n_ok += 1
    return n_ok


@njit(cache=True)
def sample_omni(particles, noise, bearing, dtrans, drot, s_trans, s_strafe, s_rot, out):
    """Apply one noisy step of the omnidirectional odometry model (ROS AMCL's omni model) to every particle.

    particles, out: (3, N) float64; out may not alias particles. noise: (3, N) standard normals (rows trans,
    strafe, rot). The step leaves each particle's heading at the odometry's ``bearing`` (its direction of travel in
    the robot's frame, noise-free); the travel along it, the drift across it and the turn are noisy:
        b = theta + bearing
        x' = x + trans_hat cos(b) + strafe_hat sin(b)
        y' = y + trans_hat sin(b) - strafe_hat cos(b)
        theta' = wrap(theta + rot_hat)
    """
    n = particles.shape[1]
    for i in range(n):
        tr = dtrans + s_trans * noise[0, i]
        st = s_strafe * noise[1, i]
        b = particles[2, i] + bearing
        c = math.cos(b)
        s = math.sin(b)
        out[0, i] = particles[0, i] + tr * c + st * s
        out[1, i] = particles[1, i] + tr * s - st * c
        out[2, i] = wrap(particles[2, i] + drot + s_rot * noise[2, i])


@njit(cache=True)
def sample_omni_map(particles, noise, idx, bearing, dtrans, drot, s_trans, s_strafe, s_rot,
                    allowed, ox, oy, inv_res, out, ok):
    """``sample_omni`` for the particles idx (noise[:, j] for particle idx[j]) plus the map check, in one pass;
    the contract of ``sample_odometry_map``. Returns how many landed in an allowed cell."""
    m = idx.shape[0]
    n_ok = 0
    for j in range(m):
        i = idx[j]
        tr = dtrans + s_trans * noise[0, j]
        st = s_strafe * noise[1, j]
        b = particles[2, i] + bearing
        c = math.cos(b)
        s = math.sin(b)
        x = particles[0, i] + tr * c + st * s
        y = particles[1, i] + tr * s - st * c
        out[0, i] = x
        out[1, i] = y
        out[2, i] = wrap(particles[2, i] + drot + s_rot * noise[2, j])
        good = allowed_at(allowed, x, y, ox, oy, inv_res)
        ok[i] = good
        if good:
            n_ok += 1
    return n_ok
