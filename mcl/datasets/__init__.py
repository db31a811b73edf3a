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
