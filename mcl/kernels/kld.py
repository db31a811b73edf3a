"""Numba kernel for KLD sampling's bin count (Prob. Rob. Table 8.4: "if x falls into an empty bin b").

One serial pass: each pose's (x, y, theta) bin is looked up in a dense flag
array over the map; a bin seen for the first time is flagged, remembered (to
clear it later) and counted. O(N), no sort, and nothing proportional to the
map but the flag array allocated once. A map too large for the flag array (a
10 km campus at 0.5 m bins: 14 GB) keeps its bins in a hash table instead
(``mark_bins_hashed``): the same counts.
"""

import math

import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: 2^64 / golden ratio


@njit(cache=True, inline="always")
def _bin_key(px, py, pt, x0, y0, bin_xy, bin_theta, nx, ny, nt):
    ix = min(max(int(math.floor((px - x0) / bin_xy)), 0), nx - 1)
    iy = min(max(int(math.floor((py - y0) / bin_xy)), 0), ny - 1)
    it = int(math.floor((pt + math.pi) / bin_theta)) % nt
    if it < 0:
        it += nt
    return (iy * nx + ix) * nt + it


@njit(cache=True)
def mark_bins(particles, x0, y0, bin_xy, bin_theta, nx, ny, nt, flags, touched, n_touched, k0, counts):
    """counts[i] = k0 + the number of distinct bins among poses 0..i not flagged before; flags them.

    particles (3, N); flags (nx * ny * nt,) bool; touched (capacity,) int64 receives each newly flagged
    bin from position n_touched on. Poses off the map count in its border bins. Returns the new n_touched.
    """
    k = k0
    for i in range(particles.shape[1]):
        key = _bin_key(particles[0, i], particles[1, i], particles[2, i], x0, y0, bin_xy, bin_theta, nx, ny, nt)
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


@njit(cache=True)
def _slot(table, key, shift):
    """The slot holding ``key`` in the open-addressing table (key + 1; 0: empty), else the empty slot where its
    probe ends (linear probing from the Fibonacci hash's top bits)."""
    mask = table.shape[0] - 1
    h = np.int64((np.uint64(key) * _GOLDEN) >> np.uint64(shift))  # int64: uint64 + int would be a float
    while table[h] != 0 and table[h] != key + 1:
        h = (h + 1) & mask
    return h


@njit(cache=True)
def mark_bins_hashed(particles, x0, y0, bin_xy, bin_theta, nx, ny, nt, table, shift, slots, n_touched, k0,
                     counts):
    """``mark_bins`` with the flags in a hash table: table (2^b,) int64 holding key + 1 (0: empty), shift = 64 - b,
    at most half full after this batch (the caller grows it); slots receives each new bin's slot from n_touched
    on. Returns the new n_touched."""
    k = k0
    for i in range(particles.shape[1]):
        key = _bin_key(particles[0, i], particles[1, i], particles[2, i], x0, y0, bin_xy, bin_theta, nx, ny, nt)
        h = _slot(table, key, shift)
        if table[h] == 0:
            table[h] = key + 1
            slots[n_touched] = h
            n_touched += 1
            k += 1
        counts[i] = k
    return n_touched


@njit(cache=True)
def rehash(old, slots, n_touched, table, shift):
    """The bins of ``old`` (at ``slots[:n_touched]``) into the empty, larger ``table``; slots rewritten."""
    for j in range(n_touched):
        key = old[slots[j]] - 1
        h = _slot(table, key, shift)
        table[h] = key + 1
        slots[j] = h
