"""Numba kernel for the particle clusters: connected components of sparse histogram cells.

Only the occupied cells exist (at most one per particle), sorted by their
key, so the cost grows with the number of particles and never with the map
or with the spread of the cloud. Pure function over arrays; serial (a
union-find is sequential, and at 100,000 particles it takes a few ms).
"""

import numpy as np
from numba import njit


@njit(cache=True)
def _find(parent, a):
    while parent[a] != a:
        parent[a] = parent[parent[a]]  # path halving
        a = parent[a]
    return a


@njit(cache=True)
def label_cells(keys, ny, n_th, out):
    """Label the 26-connected components of occupied cells, theta periodic; return their number.

    keys: (M,) int64 sorted distinct cell keys ``(ix * ny + iy) * n_th + it`` with
    1 <= ix, 1 <= iy <= ny - 2 (a free border, so ix +- 1 and iy +- 1 never
    wrap into another row) and 0 <= it < n_th.
    out: (M,) int64, receives each cell's component, numbered 0, 1, ... in
    the order of each component's first cell (the order ``scipy.ndimage.label``
    meets them in a C-order scan).
    """
    m = keys.shape[0]
    parent = np.arange(m)
    for a in range(m):
        k = keys[a]
        it = k % n_th
        row = k // n_th  # ix * ny + iy
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                nrow = row + dx * ny + dy
                for dt in range(-1, 2):
                    if dx == 0 and dy == 0 and dt == 0:
                        continue
                    nt = (it + dt) % n_th
                    nk = nrow * n_th + nt
                    b = np.searchsorted(keys, nk)
                    if b < m and keys[b] == nk:
                        ra = _find(parent, a)
                        rb = _find(parent, b)
                        if ra != rb:
                            if ra < rb:
                                parent[rb] = ra
                            else:
                                parent[ra] = rb
    count = 0
    label_of_root = np.full(m, -1, dtype=np.int64)
    for a in range(m):
        r = _find(parent, a)
        if label_of_root[r] < 0:
            label_of_root[r] = count
            count += 1
        out[a] = label_of_root[r]
    return count
