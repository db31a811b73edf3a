"""Readers of logged data (CARMEN logs, ROS bags) into one stream of ``mcl.datasets.carmen.Scan`` records."""


class ScanMap:
    """A sized iterable of scans with ``fn`` applied to each as it is read: lazy, so a bag's scans still stream
    (``sensor.time_offset``'s new stamps, ``sensor.sweep_time``'s beam times)."""

    def __init__(self, scans, fn) -> None:
        self.scans, self.fn = scans, fn

    def __len__(self) -> int:
        return len(self.scans)

    def __iter__(self):
        return map(self.fn, self.scans)


def mirrored_scan(s):
    """Scan ``s`` as an upside-down laser's read upright: a beam at angle a points at -a, so its ranges reversed,
    its angles from -angle_max up by the same increment, and its beam times (a sweep's) reversed with them."""
    import dataclasses

    import numpy as np

    r = np.asarray(s.ranges)
    n = r.shape[0]
    last = s.angle_min + s.angle_increment * (n - 1)
    return dataclasses.replace(s, ranges=r[::-1].copy(), angle_min=-last,
                               beam_t0=s.beam_t0 + s.beam_dt * (n - 1), beam_dt=-s.beam_dt)
