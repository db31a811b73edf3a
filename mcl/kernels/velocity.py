"""Numba kernels of the velocity motion model (Prob. Rob. Table 5.3, sample_motion_model_velocity).

Pure functions over arrays. The caller draws the unit-std noise with its
``numpy.random.Generator`` (rows v, omega, gamma) and passes it in, so a
kernel's result does not depend on the numba thread count. Serial: one motion
step is a few arithmetic operations per particle (0.1 us), far below what waking
threads costs.

The arc (book lines 5-6)

    x' = x - v/w sin(theta) + v/w sin(theta + w dt)
    y' = y + v/w cos(theta) - v/w cos(theta + w dt)

is evaluated in the equivalent sum-to-product form

    x' = x + v dt * cos(theta + w dt / 2) * sinc(w dt / 2)
    y' = y + v dt * sin(theta + w dt / 2) * sinc(w dt / 2),   sinc(u) = sin(u) / u,

which has no v/w: straight-line motion (|w| < 1e-9) takes sinc = 1 and
nothing is divided by zero, and a tiny but nonzero w loses no precision to
the cancellation of two nearly equal sines.
"""

import math

from numba import njit

from mcl.kernels.motion import allowed_at, wrap

W_STRAIGHT = 1e-9  # rad/s: below this |w_hat| the motion is a straight line


@njit(cache=True)
def _move(x, y, th, v_hat, w_hat, g_hat, dt):
    half = 0.5 * w_hat * dt
    if abs(w_hat) < W_STRAIGHT or half == 0.0:  # a straight line, or no time (dt = 0: no motion, not 0 / 0)
        s = 1.0
    else:
        s = math.sin(half) / half
    d = v_hat * dt * s
    h = th + half
    return x + d * math.cos(h), y + d * math.sin(h), wrap(th + w_hat * dt + g_hat * dt)


@njit(cache=True)
def sample_velocity(particles, noise, v, w, dt, s_v, s_w, s_g, out):
    """Apply one noisy velocity command (v, w) for dt to every particle.

    particles, out: (3, N) float64 (x, y, theta); out may not alias particles.
    noise: (3, N) unit-std noise (rows v, w, gamma) scaled here by the sigmas:
        v_hat = v + s_v * noise[0],  w_hat = w + s_w * noise[1],  g_hat = s_g * noise[2]
        theta' = wrap(theta + w_hat dt + g_hat dt)
    """
    n = particles.shape[1]
    for i in range(n):
        x, y, th = _move(particles[0, i], particles[1, i], particles[2, i],
                         v + s_v * noise[0, i], w + s_w * noise[1, i], s_g * noise[2, i], dt)
        out[0, i] = x
        out[1, i] = y
        out[2, i] = th


@njit(cache=True)
def sample_velocity_map(particles, noise, idx, v, w, dt, s_v, s_w, s_g, allowed, ox, oy, inv_res, out, ok):
    """sample_velocity for the particles idx (noise[:, j] moves particle idx[j]) plus the map check.

    Same contract as ``kernels.motion.sample_odometry_map``: ok[i] says whether
    the new pose's cell is allowed (``allowed_at``); returns how many landed.
    """
    m = idx.shape[0]
    n_ok = 0
    for j in range(m):
        i = idx[j]
        x, y, th = _move(particles[0, i], particles[1, i], particles[2, i],
                         v + s_v * noise[0, j], w + s_w * noise[1, j], s_g * noise[2, j], dt)
        out[0, i] = x
        out[1, i] = y
        out[2, i] = th
        good = allowed_at(allowed, x, y, ox, oy, inv_res)
        ok[i] = good
        if good:
            n_ok += 1
    return n_ok
