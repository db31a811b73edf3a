"""Exact ray casting on an occupancy grid (Amanatides & Woo, 1987).

A ray is walked cell by cell through every grid cell it passes, in order,
so the first blocked cell is never skipped (a fixed-step ray march can jump
over a one-cell wall corner). The cost is one step per cell crossed.

Grid conventions are the package's: ``blocked`` is a bool/uint8 ``(H, W)``
array indexed ``[iy, ix]`` with row 0 at the bottom (world ``y = oy``), and
``ix = floor((x - ox) / res)``. Ranges are measured from the ray's origin.

- A ray that starts in a blocked cell returns 0.
- A ray that leaves the grid without hitting anything returns ``max_range``
  (it sees nothing); so does a ray whose first hit is farther than
  ``max_range``. A ray that starts outside the grid is clipped to the grid
  box first and can still hit a cell inside it.

Only this module's functions live here; they are pure and allocate nothing
in their loops.
"""

import math

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True)
def _dda_axis(d, i, g):
    """One axis of the traversal: (cell step, ray parameter of the next cell boundary, parameter
    between boundaries) for direction component d from position g in cell i (cell units)."""
    if d > 0.0:
        return 1, (i + 1 - g) / d, 1.0 / d
    if d < 0.0:
        return -1, (i - g) / d, -1.0 / d
    return 0, np.inf, np.inf


@njit(cache=True, nogil=True)
def _slab(g, d, size, t_enter, t_exit):
    """One axis of the slab clip: [t_enter, t_exit] narrowed to where g + t*d lies in [0, size]
    (empty, t_enter > t_exit, when the ray runs parallel to the axis outside that range)."""
    if d != 0.0:
        ta = (0.0 - g) / d
        tb = (size - g) / d
        if ta > tb:
            ta, tb = tb, ta
        return max(t_enter, ta), min(t_exit, tb)
    if g < 0.0 or g >= size:
        return np.inf, -np.inf
    return t_enter, t_exit


@njit(cache=True, nogil=True)
def cast_ray(x, y, angle, blocked, ox, oy, res, max_range):
    """Range from ``(x, y)`` along world ``angle`` to the first blocked cell.

    Returns the distance to the cell boundary where the ray enters the first
    blocked cell, ``0.0`` if it starts in one, or ``max_range`` if there is
    no hit within ``max_range`` (or inside the grid).
    """
    h = blocked.shape[0]
    w = blocked.shape[1]
    # Work in cell units: the grid box is [0, w] x [0, h].
    gx = (x - ox) / res
    gy = (y - oy) / res
    dx = math.cos(angle)
    dy = math.sin(angle)
    t_limit = max_range / res

    # Clip the ray to the grid box (slab method) so that a start outside the
    # grid still works. t is the ray parameter in cell units.
    t_enter, t_exit = _slab(gx, dx, w, 0.0, t_limit)
    t_enter, t_exit = _slab(gy, dy, h, t_enter, t_exit)
    if t_enter > t_exit:
        return max_range

    px = gx + t_enter * dx
    py = gy + t_enter * dy
    ix = int(math.floor(px))
    iy = int(math.floor(py))
    # A point on the box's far edge floors to w or h: pull it inside.
    if ix >= w:
        ix = w - 1
    if ix < 0:
        ix = 0
    if iy >= h:
        iy = h - 1
    if iy < 0:
        iy = 0
    if blocked[iy, ix]:
        return t_enter * res

    # Ray parameter at which the ray crosses the next vertical / horizontal
    # cell boundary, and the parameter step between successive crossings.
    step_x, t_max_x, t_delta_x = _dda_axis(dx, ix, gx)
    step_y, t_max_y, t_delta_y = _dda_axis(dy, iy, gy)

    while True:
        if t_max_x < t_max_y:
            t = t_max_x
            ix += step_x
            t_max_x += t_delta_x
        else:
            t = t_max_y
            iy += step_y
            t_max_y += t_delta_y
        if t >= t_limit:
            return max_range
        if ix < 0 or ix >= w or iy < 0 or iy >= h:
            return max_range
        if blocked[iy, ix]:
            return t * res


@njit(cache=True, parallel=True)
def cast_rays(poses, angles, blocked, ox, oy, res, max_range, out):
    """Cast ``K`` rays from each of ``N`` poses into ``out`` ``(N, K)``.

    ``poses`` is ``(3, N)`` (x, y, theta); ray ``k`` of pose ``n`` points at
    ``theta_n + angles[k]`` (counter-clockwise). Parallel over poses; each
    ray is an independent :func:`cast_ray`, so the result does not depend on
    the thread count. Returns ``out``.
    """
    n = poses.shape[1]
    k = angles.shape[0]
    for i in prange(n):
        x = poses[0, i]
        y = poses[1, i]
        th = poses[2, i]
        for j in range(k):
            out[i, j] = cast_ray(x, y, th + angles[j], blocked, ox, oy, res, max_range)
    return out


@njit(cache=True)
def segments_blocked(x, y, theta, lx, ly, endpoints, blocked, ox, oy, res, out):
    """out[k] = True when the segment from the laser to beam k's endpoint crosses a blocked cell.

    Seen from the robot pose ``(x, y, theta)``: the laser sits at ``(lx, ly)``
    and ``endpoints`` ``(2, K)`` are the beam endpoints, both in the robot
    frame (m). The segment is walked with :func:`cast_ray` up to its own
    length, so a crossing is a blocked cell met before the endpoint (a
    reading that went through a mapped obstacle, or that ends inside one).
    Serial: K is one scan's beams. Returns ``out``.
    """
    c = math.cos(theta)
    s = math.sin(theta)
    sx = x + c * lx - s * ly
    sy = y + s * lx + c * ly
    for j in range(endpoints.shape[1]):
        ex = x + c * endpoints[0, j] - s * endpoints[1, j]
        ey = y + s * endpoints[0, j] + c * endpoints[1, j]
        length = math.hypot(ex - sx, ey - sy)
        if not length > 0.0:
            out[j] = False
            continue
        out[j] = cast_ray(sx, sy, math.atan2(ey - sy, ex - sx), blocked, ox, oy, res, length) < length
    return out


@njit(cache=True)
def cast_rays_serial(poses, angles, blocked, ox, oy, res, max_range, out):
    """Serial twin of :func:`cast_rays` (same rays, same result): for a few poses per call, where waking
    the parallel threads would cost more than the rays (``mcl.simulate`` casts one scan at a time
    among moving people)."""
    for i in range(poses.shape[1]):
        for j in range(angles.shape[0]):
            out[i, j] = cast_ray(poses[0, i], poses[1, i], poses[2, i] + angles[j], blocked, ox, oy, res, max_range)
    return out
