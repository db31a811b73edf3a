"""Numba kernels of the recording's particle cloud (``mcl.viz``): each particle's colour and radius by weight, and
the weight histogram's counts.

The same arithmetic as the numpy expressions they replace, operation for operation (no fastmath: no fused or
reordered operations), so the same values to the bit: ``viz.weight_scale``, ``viz.scale_colors`` and the radii
by ``np.searchsorted`` took 60 us for 1,000 particles, and ``np.histogram`` 20 us for 5,000 weights (it sorts
them). The logarithms stay in numpy (its log10 need not be the C library's). Serial, no allocation.
"""

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def cloud_style(rel, decades, viridis, free, faded, radii_of, radii_at, colors, radii):
    """Colour ``colors`` (N, 3) uint8 and radius ``radii`` (N,) float32 (UI points: negative) of particles whose
    log10(w / w_max) is ``rel`` (N,) (-inf for a zero weight; no NaN): u = clip(1 + rel / decades, 0, 1); the
    colour interpolated in ``viridis`` (K, 3) at u (K - 1), with ``faded`` mixed with the grey ``free`` by alpha
    (60 + 195 u) / 255, rounded half to even; the radius ``radii_of[j]``, j the number of ``radii_at`` below u."""
    top = viridis.shape[0] - 1
    for i in range(rel.shape[0]):
        u = 1.0 + rel[i] / decades
        if not u > 0.0:  # np.clip's 0 (a NaN too: weight_scale's nan_to_num makes it 0)
            u = 0.0
        elif u > 1.0:
            u = 1.0
        pos = u * top
        i0 = min(int(pos), top - 1)
        f = pos - i0
        a = (60.0 + 195.0 * u) / 255.0
        for c in range(3):
            v = viridis[i0, c] * (1.0 - f) + viridis[i0 + 1, c] * f
            if faded:
                v = v * a + free * (1.0 - a)
            colors[i, c] = np.uint8(np.rint(v))
        j = 0
        while j < radii_at.shape[0] and radii_at[j] < u:
            j += 1
        radii[i] = -abs(radii_of[j])


@njit(cache=True, nogil=True)
def histogram_counts(rel, edges, counts):
    """``counts`` (B,) of the values ``rel`` (N,) in the bins of the uniform ``edges`` (B + 1,) as np.histogram
    counts them: bin b holds edges[b] <= r < edges[b + 1], the last bin edges[B - 1] <= r <= edges[B]; ``rel``
    within [edges[0], edges[B]]. Each value's bin is guessed from the spacing and settled on the edges."""
    nb = counts.shape[0]
    lo = edges[0]
    scale = nb / (edges[nb] - lo)
    counts[:] = 0
    for i in range(rel.shape[0]):
        r = rel[i]
        b = int((r - lo) * scale)
        b = min(max(b, 0), nb - 1)
        while b > 0 and r < edges[b]:
            b -= 1
        while b < nb - 1 and r >= edges[b + 1]:
            b += 1
        counts[b] += 1
    return counts
