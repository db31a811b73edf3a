"""Numba kernels: a distance field read at robot-frame endpoints seen from one pose (and shifts of it).

Used by ``mcl.quality.endpoint_distances`` (the quality signal, a few calls per update) and
``mcl.sensors.UnmappedObjects.select`` (``sensor.unmapped_skip``): one pass instead of a dozen numpy
temporaries. Grid conventions are the package's (row 0 at world ``y = oy``, ``ix = floor((x - ox) / res)``).
Pure functions over arrays; serial (a scan's beams are few).
"""

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _at(dist, wx, wy, res):
    """dist at the map-frame point (wx, wy) (metres from the map's origin); NaN off the map."""
    fx = np.floor(wx / res)  # a float: NaN and huge values stay comparable
    fy = np.floor(wy / res)
    if fx >= 0 and fx < dist.shape[1] and fy >= 0 and fy < dist.shape[0]:
        return dist[int(fy), int(fx)]
    return math.nan


@njit(cache=True, nogil=True)
def field_at(dist, ox, oy, res, x, y, c, s, e, out):
    """out[k] = dist at endpoint e[:, k] seen from the pose (x, y, heading with cos c and sin s); NaN off the
    map. The arithmetic is x + c ex - s ey - ox, floor of / res (``OccupancyGrid.world_to_cell``)."""
    for k in range(e.shape[1]):
        out[k] = _at(dist, x + c * e[0, k] - s * e[1, k] - ox, y + s * e[0, k] + c * e[1, k] - oy, res)


@njit(cache=True, nogil=True)
def far_runs(dist, ox, oy, res, x, y, c, s, e, idx, sx, sy, dmax, far):
    """The candidates of ``UnmappedObjects.select`` far from the map; returns how many.

    far[j] = the field at endpoint e[:, k], k = idx[j], seen from the pose exceeds ``dmax[k]`` (off the map: not
    far; ``dmax`` holds a distance per endpoint). With shifts (sx, sy of length M > 0: world-frame offsets of the
    pose), a run of consecutive indices in ``idx`` with a far member is cleared when one shift puts every endpoint
    k of the run within ``dmax[k]`` of the map (or off it)."""
    n = idx.shape[0]
    count = 0
    for j in range(n):
        k = idx[j]
        far[j] = _at(dist, x + c * e[0, k] - s * e[1, k] - ox, y + s * e[0, k] + c * e[1, k] - oy, res) > dmax[k]
    j = 0
    while j < n:
        last = j
        while last + 1 < n and idx[last + 1] == idx[last] + 1:
            last += 1
        hit = False
        for q in range(j, last + 1):
            hit = hit or far[q]
        if hit and sx.shape[0] > 0:
            for m in range(sx.shape[0]):
                fits = True
                for q in range(j, last + 1):
                    k = idx[q]
                    wx = x + c * e[0, k] - s * e[1, k] - ox + sx[m]
                    wy = y + s * e[0, k] + c * e[1, k] - oy + sy[m]
                    if _at(dist, wx, wy, res) > dmax[k]:
                        fits = False
                        break
                if fits:
                    for q in range(j, last + 1):
                        far[q] = False
                    break
        for q in range(j, last + 1):
            if far[q]:
                count += 1
        j = last + 1
    return count
