"""Numba kernel for KLD sampling's bin count (Prob. Rob. Table 8.4: "if x falls into an empty bin b").

One serial pass: each pose's (x, y, theta) bin is looked up in a dense flag
array over the map; a bin seen for the first time is flagged, remembered (to
clear it later) and counted. O(N), no sort, and nothing proportional to the
map but the flag array allocated once.
"""

import math

from numba import njit


@njit(cache=True)
def mark_bins(particles, x0, y0, bin_xy, bin_theta, nx, ny, nt, flags, touched, n_touched, k0, counts):
    """counts[i] = k0 + the number of distinct bins among poses 0..i not flagged before; flags them.

    particles (3, N); flags (nx * ny * nt,) bool; touched (capacity,) int64 receives each newly flagged
    bin from position n_touched on. Poses off the map count in its border bins. Returns the new n_touched.
    """
    k = k0
    for i in range(particles.shape[1]):
        ix = int(math.floor((particles[0, i] - x0) / bin_xy))
        iy = int(math.floor((particles[1, i] - y0) / bin_xy))
        ix = min(max(ix, 0), nx - 1)
        iy = min(max(iy, 0), ny - 1)
        it = int(math.floor((particles[2, i] + math.pi) / bin_theta)) % nt
        if it < 0:
            it += nt
        key = (iy * nx + ix) * nt + it
        if not flags[key]:
            flags[key] = True
            touched[n_touched] = key
            n_touched += 1
            k += 1
        counts[i] = k
    return n_touched


@njit(cache=True)
def clear_bins(flags, touched, n_touched):
    for j in range(n_touched):
        flags[touched[j]] = False
