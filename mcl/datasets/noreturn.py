"""Find a laser log's no-return value from its readings.

Old CARMEN ``FLASER`` lines do not say the sensor's maximum range, and logs
mark a beam without an echo by a fixed value near the sensor's maximum:
81.83 or 81.91 m (SICK), 50.00 m, or a narrow band such as 51.05-51.16 m. A
reader that takes these for real readings scores phantom walls 50 m away.

A no-return value shows as a *spike* in the histogram of readings: thousands
of beams share one centimetre value at the top of the log's range, where real
readings are few and spread out (a real reading never repeats to the
centimetre that often: the sensor's noise spreads it). So:

1. histogram the finite positive readings up to ``_MAX_M`` (1 km: no 2D laser
   reaches that; a corrupt 1e40 would ask for an impossible histogram) in
   1 cm bins;
2. a bin is a spike when it holds at least ``min_share`` of all readings
   (and at least ``min_count``) and ``spike_ratio`` times more than the
   median bin of the 2 m around it (the median, so that a band of
   neighbouring spikes such as 51.05-51.25 m does not hide itself);
3. only spikes at the top of the range count (at or above ``top_fraction`` of
   the largest reading, or with at most ``stray_share`` of the readings above
   them outside other spikes): a robot standing still in front of a wall
   repeats a short reading, never one near the sensor's maximum. The second
   form keeps a 3 m laser's spike at 3.00 m when two stray readings of 200 m
   lie above it, or a log's second marker at 65.53 m (its longest real reading
   then set the top, and the 3 m no-returns scored as walls: 7 m off);
4. there must be real readings to tell the marker from (5 % of all at least);
5. readings at or above ``(1 - margin)`` times the lowest such spike are no
   return (the 1 % margin takes in the stray readings just below the marker
   that some logs have, e.g. 81.83 m beside 81.91 m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["NoReturn", "detect_no_return"]

_MAX_M = 1000.0  # readings above this are left out of the histogram (1e5 bins at most)


@dataclass(frozen=True)
class NoReturn:
    """A log's no-return marker: readings >= ``threshold`` mean no echo."""

    threshold: float  # m
    spikes: tuple[float, ...]  # the spike values found (m, 1 cm bins), ascending
    count: int  # readings >= threshold
    total: int  # finite positive readings looked at

    def describe(self) -> str:
        """e.g. 'a no-return marker at 50.00 m and 51.14-51.15 m: readings >= 49.50 m (13,213 of 155,841, 8.5 %) are
        taken as no return'. The count is of every reading at or past the threshold: the marker's and the few real
        readings within the 1 % margin below it (aces: 631, of which 620 read 50.00 m)."""
        lo = self.spikes[0]
        if len(self.spikes) == 1:
            at = f"{lo:.2f} m"
        else:
            # consecutive centimetre bins read as a band
            groups, start, prev = [], self.spikes[0], self.spikes[0]
            for v in self.spikes[1:]:
                if v - prev > 0.015:
                    groups.append((start, prev))
                    start = v
                prev = v
            groups.append((start, prev))
            at = " and ".join(f"{a:.2f} m" if a == b else f"{a:.2f}-{b:.2f} m" for a, b in groups)
        share = 100.0 * self.count / max(self.total, 1)
        return (f"a no-return marker at {at}: readings >= {self.threshold:.2f} m ({self.count:,} of {self.total:,}, "
                f"{share:.1f} %) are taken as no return")


_BLOCK = 1 << 20  # readings a block: 8 MB of float64


def _blocks(ranges):
    """The finite readings in (0, _MAX_M] of ``ranges`` (an array, or a list of arrays joined up to _BLOCK readings
    at a time), a float64 block at a time: only one block's copies alive at once."""

    def kept(r):
        r = np.asarray(r, dtype=np.float64).ravel()
        with np.errstate(invalid="ignore"):
            return r[np.isfinite(r) & (r > 0.0) & (r <= _MAX_M)]

    if isinstance(ranges, np.ndarray):
        yield kept(ranges)
        return
    group, size = [], 0
    for r in ranges:
        group.append(np.ravel(r))
        size += group[-1].size
        if size >= _BLOCK:
            yield kept(np.concatenate(group))
            group, size = [], 0
    if group:
        yield kept(np.concatenate(group))


def detect_no_return(ranges, *, min_share: float = 1e-3, min_count: int = 20, spike_ratio: float = 20.0,
                     top_fraction: float = 0.9, margin: float = 0.01, stray_share: float = 1e-3) -> NoReturn | None:
    """The no-return marker of a set of readings (an array of any shape, metres, or a list of such arrays: a log's
    scans, taken a block at a time), or None when there is no spike.

    See the module docstring for the rule and its parameters.
    """
    hist, total, top = np.zeros(0), 0, 0
    for r in _blocks(ranges):  # the centimetre histogram, a block at a time: a long log's readings are not copied whole
        if r.size:
            cm = np.rint(r * 100.0).astype(np.int64)
            h = np.bincount(cm)
            if h.size > hist.size:
                hist = np.concatenate([hist, np.zeros(h.size - hist.size)])
            hist[:h.size] += h
            total += int(r.size)
            top = max(top, int(cm.max()))
    if total == 0:
        return None
    cand = np.flatnonzero(hist >= max(min_count, min_share * total))  # at most 1 / min_share bins
    if cand.size == 0:
        return None
    # the median bin of the 2 m around each candidate: robust to a band of spikes narrower than the window
    around = np.array([np.median(hist[max(v - 100, 0):v + 101]) for v in cand])  # a few candidates, not beams
    spikes = cand[hist[cand] >= spike_ratio * np.maximum(around, 1.0)]
    if spikes.size == 0:
        return None
    # at the top: near the largest reading, or with (almost) no reading above but other spikes' (step 3)
    rest = hist.copy()
    rest[spikes] = 0
    above = np.cumsum(rest[::-1])[::-1] - rest  # readings in the bins above each bin, spikes left out
    spikes = spikes[(spikes >= top_fraction * top) | (above[spikes] <= stray_share * total)]
    if spikes.size == 0:
        return None
    threshold = (1.0 - margin) * spikes[0] / 100.0
    count = sum(int(np.count_nonzero(r >= threshold)) for r in _blocks(ranges))  # a second pass
    if total - count < max(min_count, 0.05 * total):  # hardly any real reading: nothing to tell the marker from
        return None
    return NoReturn(float(threshold), tuple(float(v) / 100.0 for v in spikes), count, total)
