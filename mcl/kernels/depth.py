"""Numba kernel: the depth of an obstacle's interior cells, by a search in square rings around each.

Used by ``mcl.maps.OccupancyGrid._surface_patches`` (the likelihood field's ``interior: depth``): a building's
walls are a few cells thick, so the handful of cells deeper than one cell find their nearest non-occupied cell
within a ring or two, where a distance transform per tile walked every cell of 151 tiles of 128 x 128
(infinite_corridor's 250 m map: 556 such cells). Pure function over arrays; serial.
"""

import numpy as np
from numba import njit


@njit(cache=True)
def ring_depths(occupied, ys, xs, radius, out):
    """out[j] = squared distance, in cells, from cell (ys[j], xs[j]) to the nearest cell of ``occupied`` (H, W)
    that is 0 (not occupied), or -1 when none lies within ``radius`` cells (Chebyshev) of it.

    Off the map counts as occupied (``mcl.maps._edt_squared``'s convention). Rings r = 1, 2, ... are searched
    until the best found is no farther than any cell of the next ring can be ((r + 1)^2): the result is then
    exact, the same integer as the Euclidean transform's.
    """
    h, w = occupied.shape
    for j in range(ys.shape[0]):
        y, x = ys[j], xs[j]
        best = np.iinfo(np.int64).max
        done = False
        for r in range(1, radius + 1):
            for dy in range(-r, r + 1):
                yy = y + dy
                if yy < 0 or yy >= h:
                    continue
                edge = dy == -r or dy == r
                step = 1 if edge else 2 * r  # a ring's top and bottom rows whole, its sides at -r and +r only
                for dx in range(-r, r + 1, step):
                    xx = x + dx
                    if xx < 0 or xx >= w or occupied[yy, xx]:
                        continue
                    d = dy * dy + dx * dx
                    if d < best:
                        best = d
            if best <= (r + 1) * (r + 1):
                done = True
                break
        out[j] = best if done else -1


@njit(cache=True)
def interior_cells(occupied):
    """(ys, xs) int64, row-major (``np.nonzero``'s order): the cells of ``occupied`` (H, W) whose four neighbours are
    occupied too, off the map counting as occupied: the only cells deeper than one cell, whose depth
    :func:`ring_depths` then finds. Two passes (count, fill) over the map instead of a copy, four masked ANDs and
    ``np.nonzero`` of a map-sized array (infinite_corridor's 25 M cells: 60 ms to 17 ms)."""
    h, w = occupied.shape
    # the test is written out in both passes: as a helper function (even inline="always") the kernel ran 20x slower
    n = 0
    for y in range(h):
        for x in range(w):
            if (occupied[y, x] and (y == 0 or occupied[y - 1, x]) and (y == h - 1 or occupied[y + 1, x])
                    and (x == 0 or occupied[y, x - 1]) and (x == w - 1 or occupied[y, x + 1])):
                n += 1
    ys = np.empty(n, dtype=np.int64)
    xs = np.empty(n, dtype=np.int64)
    k = 0
    for y in range(h):
        for x in range(w):
            if (occupied[y, x] and (y == 0 or occupied[y - 1, x]) and (y == h - 1 or occupied[y + 1, x])
                    and (x == 0 or occupied[y, x - 1]) and (x == w - 1 or occupied[y, x + 1])):
                ys[k] = y
                xs[k] = x
                k += 1
    return ys, xs
