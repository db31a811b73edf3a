"""Numba kernel: the beams of a scan that belong to small segments of it (people, chairs, lone readings).

Used by ``mcl.sensors.UnmappedObjects`` (``sensor.unmapped_skip``). Pure function over arrays.
"""

import math

from numba import njit


@njit(cache=True)
def small_segments(ranges, angles, valid, jump, width, out, ends=False):
    """out[b] = True when beam b belongs to a small segment of the scan.

    ranges, angles: (B,) float64 readings (m) and beam angles (rad) in scan order; valid: (B,) bool, the
    readings with a return. A *segment* is a maximal run of valid consecutive beams whose neighbouring
    readings differ by at most ``jump`` (m). It is *small* when the distance between its first and last
    endpoints is below ``width`` (m). Segments at either end of the scan are never marked (their extent is
    not seen), unless ``ends``: then by the part seen. One pass, O(B).

    A wall seen at a grazing angle, whose readings step by more than ``jump`` from beam to beam, falls apart
    into one-beam segments: those are small too (the caller keeps the ones that fit the map). An adaptive
    breakpoint distance (Borges & Aldon 2004) would keep such a wall whole, but it also joins a person to the
    slanted wall beside them at a few metres (suites/synthetic.yaml corridor-05 was lost again with it).
    """
    b = ranges.shape[0]
    for k in range(b):
        out[k] = False
    i = 0
    while i < b:
        if not valid[i]:
            i += 1
            continue
        j = i
        while j + 1 < b and valid[j + 1] and abs(ranges[j + 1] - ranges[j]) <= jump:
            j += 1
        if ends or (i > 0 and j < b - 1):
            dx = ranges[i] * math.cos(angles[i]) - ranges[j] * math.cos(angles[j])
            dy = ranges[i] * math.sin(angles[i]) - ranges[j] * math.sin(angles[j])
            if dx * dx + dy * dy < width * width:
                for k in range(i, j + 1):
                    out[k] = True
        i = j + 1
