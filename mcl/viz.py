"""Rerun logging of a localization run: the only module in ``mcl`` that imports rerun.

Entity paths name things, not steps::

    world                 static Transform3D flipping y, so the 2D view shows y up
    world/map             static: the occupancy grid as a PNG image placed in metres
    world/likelihood_field static: the likelihood field p(endpoint | map) as an image (hidden by default)
    world/particles       Points2D, at most ``particles_max`` (evenly strided), coloured and sized by weight
    world/estimate        Points2D + Arrows2D (heading) + LineStrips2D (2-sigma ellipse of x, y)
    world/follow          Transform3D per step: the estimate's position (y flipped): the "Robot" view's frame
    world/scan            Points2D, scan endpoints in the world frame
    world/scan/skipped    Points2D, the endpoints beam skipping ignored at this step (empty when none)
    world/scan/expected   Points2D, where the scan's beams would end if the estimate were right (ray cast)
    world/truth           Points2D (current true pose); optional static LineStrips2D full path
    world/truth/trail     LineStrips2D, one segment per step (only when no static path was logged)
    world/odometry        Points2D (current odometry pose, in the map frame)
    world/odometry/trail  LineStrips2D, one segment per step
    stats/<name>          Scalars, one per entry of the ``stats`` dict; a ``time_ms/*`` stage from after its first
                          real run on (that one compiles or loads the numba kernels: ``warmup/time_ms/*`` holds it)
    weights/histogram     BarChart per step: how many particles have each log10(w / w_max) (all N, not the subsample)
    about                 TextDocument: what each panel shows

Timelines: ``step`` (sequence, from the loop) and ``time`` (from the log: a timestamp
when ``t`` looks like Unix seconds, otherwise a duration in seconds).

Trails are kept linear in recording size: each step logs one 2-point segment and the
blueprint gives the trail entities a visible time range from -inf to the cursor, so the
viewer accumulates them.  The particle cloud dominates the size: about 24 KB per logged
step with 2000 particles (12 bytes a point: f32 x, y + RGBA colour; random positions do
not compress), about 2 KB per step for everything else with a 181-beam scan.  Lower
``particles_max`` or raise ``particles_every`` for long runs; ``mcl run`` raises
``particles_every`` by itself when the log is long enough to take the recording past
``rerun.budget_mb`` (:func:`particles_every_within`).
"""

from __future__ import annotations

import errno
import functools
import math
import os
import sys
import time
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Mapping
from urllib.parse import quote

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from rerun.time import to_nanos, to_nanos_since_epoch

from mcl.kernels.style import cloud_style, histogram_counts

__all__ = ["RerunLogger", "MODES", "has_display", "stat_group"]

MODES = ("save", "spawn", "serve", "off")
_SERVED: list = []  # the served recordings (``serve``): their gRPC servers live as long as the process

# Map colours (grey levels): free light, occupied black, unknown mid grey.
_FREE, _OCCUPIED, _UNKNOWN = 235, 0, 150

# Viridis anchors (matplotlib's, sampled at 0, 1/8, ..., 1) for the weight colormap.
_VIRIDIS = np.array(
    [
        [68, 1, 84],
        [71, 45, 123],
        [59, 82, 139],
        [44, 114, 142],
        [33, 145, 140],
        [39, 173, 129],
        [92, 200, 99],
        [170, 220, 50],
        [253, 231, 37],
    ],
    dtype=np.float64,
)

# Weights are shown on a log scale spanning this many decades below the heaviest.
_WEIGHT_DECADES = 3.0

# Time-series groups (see stat_group) and the panel titles a newcomer reads, in panel order; the tabs' titles are
# short (a tab shows about 50 characters) and the About text says what each one holds.
_STAT_GROUPS = (
    ("error", "Error vs truth: position (m), heading (rad)"),
    ("quality", "Quality: scan vs map at the estimate (match 1 = fits, lost 1 = lost)"),
    ("ess", "Particles: count and effective sample size (ESS)"),
    ("timings", "Time per update (ms)"),
    ("spread", "Spread (m)"),
    ("tries", "Map rejection tries"),
    ("recovery", "Recovery (share)"),
    ("other", "Counts"),
)
# shown stacked with the weight histogram; the others in tabs under them (six stacked panels left each one too
# short to read at 1080p)
_MAIN_GROUPS = ("error", "quality", "ess")
# Each panel's series in these colours, in the order they first appear (Tableau 10): the viewer's own picks gave
# two series of one panel near-identical hues (position and heading both magenta)
_SERIES_COLOURS = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75),
                   (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207))

# Particle radii (UI points) by weight_scale: below _RADII_AT[0], up to _RADII_AT[1], above.
_RADII = np.array([1.0, 2.0, 3.5], dtype=np.float32)
_RADII_AT = np.array([0.5, 0.9])

# Weight histogram: _HIST_BINS bins of log10(w / w_max) over [-span, 0], span >= _HIST_DECADES (weight_histogram).
_HIST_DECADES, _HIST_BINS = 6.0, 24
_HIST_COLOR = np.array([[92, 200, 99]], dtype=np.uint8)

ABOUT = """\
# What this recording shows

**World** (the whole map): the map (grey), the particles (coloured, sized and faded by weight: yellow and large = heavy;
pale purple, small = light), the estimate (magenta: point, heading, 2-sigma ellipse), the scan laid at the estimate
(red), where the beams would end if the estimate were right (cyan, `world/scan/expected`), beams not scored (blue:
unmapped objects, or beam skipping), the true pose and path (green; broken where the robot was carried off) and
dead-reckoned odometry (orange). The view opens on the map's known cells.
**Robot** (far left, on a map over 60 m across): the same layers in a square of about 24 m that follows the
estimate (north stays up): on a building-sized map the cloud and the scans are a few pixels in World.
Layer `world/likelihood_field` (hidden: open the blueprint panel from the top bar and tick it) is the sensor
model's likelihood field, p(endpoint | map) of an endpoint at each cell: bright next to walls, falling off with
`sensor.likelihood_field.sigma_hit`.

**Error vs truth**: distance from the estimate to the reference pose (only when a truth file is given).
**Quality**: the scan laid on the map at the estimate, without truth: `match` = fraction of beams ending near a
mapped obstacle, `contradiction` = fraction that pass through one, `lost` = 1 while the filter believes it is lost.
**Particles**: how many particles (KLD sampling shrinks the set once it converges) and the effective sample size.
**Particle weights**: histogram of log10(w / w_max) over all particles at this step (the x range fits the step:
one scan can put hundreds of decades between poses): one bar at 0 = every particle alike (no evidence yet, or just
resampled); most particles far left and a few at 0 = the scan singled out a few poses.
In the tabs under them: **Time per update**: milliseconds per filter stage. A stage's first real run compiles or
loads its numba kernels (often over a second): that value is at `warmup/time_ms/*`, left out of the plot so the
scale reads. Later peaks are real: a global search or a recovery weighs up to `filter.particles` (100,000 by
default) instead of a few thousand. **Spread**: the particles' spread (m) over the whole set and the estimate's
cluster. **Map rejection tries**: the mean draws per particle of the map-based motion model. **Recovery**: the share
of the particles drawn anew at the next resample. **Counts**: the clusters and the beams not scored.
The time panel (bottom), the blueprint panel and the selection panel open from the viewer's top bar.
"""

# The frame the "Robot" view is drawn in: the estimate's position at each step (see _log_estimate), and the half
# width (m) of the square that view shows around it: on a building-sized map the cloud, the scan and the expected
# scan are a few pixels in the whole-map view
FOLLOW_ENTITY = "world/follow"
FOLLOW_HALF_M = 12.0
# The Robot view is shown when the known map's larger side exceeds this (m): on a smaller map (the demo's 22 m,
# intel_lab's 43 m, fr079's 49 m) the World view draws the robot as large, and a second view of it wasted a third
# of the screen; mit_csail (93 m), aces (63 m) and the larger maps get it
FOLLOW_MIN_SIDE_M = 60.0

_DRAW_ORDER = {"map": -100.0, "trail": 5.0, "particles": 10.0, "scan": 20.0, "truth": 30.0, "estimate": 40.0}

_TIMESTAMP_THRESHOLD = 1e8  # seconds: larger t is taken as Unix time (1973 onwards)
# Everything a step logs (the stats, the estimate, the truth and odometry poses, the cloud, the scans, the weight
# histogram) is buffered and sent as columns every this many steps and at close: one rr.log costs 25-100 us of Python
# per archetype (the histogram's tensor 0.45 ms), a column of 64 rows about as much as one. A live viewer sees the
# run in batches of this many steps, or of LIVE_FLUSH_S of wall time if that comes first (spawn, serve).
COLUMN_FLUSH_STEPS = 64
LIVE_FLUSH_S = 0.2  # s: the longest a live viewer waits for the steps buffered so far (a saved file: steps alone)


def _save_batcher() -> rr.ChunkBatcherConfig:
    """The batcher of a saved recording: Rerun's default thresholds without its 200 ms tick (a week instead)."""
    d = rr.ChunkBatcherConfig.DEFAULT()
    return rr.ChunkBatcherConfig(flush_tick=7 * 24 * 3600.0, flush_num_bytes=d.flush_num_bytes,
                                 flush_num_rows=d.flush_num_rows)


_COLUMN_DTYPES = {"colors": np.uint8, "radii": np.float32, "draw_order": np.float32, "translation": np.float32,
                  "scale": np.float32}
# The archetype fields that are tensors (rerun.components.TensorData): rerun 0.41 converts one tensor at a time
# ("Tensors do not support batches"), so a column of them is built here (_TensorColumn); and BarChart's other
# fields, which its .columns() takes only with values (its converter fails on values=None): their component batch
_TENSOR_FIELDS = {("BarChart", "values"), ("BarChart", "abscissa")}
_FIELD_BATCHES = {("BarChart", "widths"): "LengthBatch", ("BarChart", "color"): "ColorBatch"}


class _TensorColumn:
    """K 1-D tensors (numpy arrays of one dtype) as one column of rerun.components.TensorData, a row each: the
    arrow array rerun's own converter builds for each tensor alone (rr.BarChart(values)), built for the K at once
    (its converter took 0.45 ms a tensor). For rr.ComponentColumn: ``as_arrow_array``."""

    _type: Any = None

    def __init__(self, rows: list[np.ndarray]) -> None:
        self.rows = rows

    @classmethod
    def arrow_type(cls) -> Any:
        if cls._type is None:  # rerun's own TensorData type
            cls._type = rr.components.TensorDataBatch._ARROW_DATATYPE
        return cls._type

    def as_arrow_array(self) -> Any:
        import pyarrow as pa

        from rerun.encodings.tensor_data_ext import DTYPE_MAP

        data_type = self.arrow_type()
        union = data_type.field("buffer").type
        k = len(self.rows)
        flat = np.concatenate([np.ravel(r) for r in self.rows]) if k else np.zeros(0, dtype=np.float32)
        lengths = np.array([np.size(r) for r in self.rows], dtype=np.int64)
        offsets = np.zeros(k + 1, dtype=np.int32)
        np.cumsum(lengths, out=offsets[1:])
        shape = pa.ListArray.from_arrays(pa.array(np.arange(k + 1, dtype=np.int32)), pa.array(lengths.astype(np.uint64)),
                                         type=data_type.field("shape").type)
        names = pa.nulls(k, type=data_type.field("names").type)
        idx = [f.name for f in union].index(DTYPE_MAP[flat.dtype.type])
        # typed as rerun's (non-null items): no cast, which imports pyarrow.compute (30 ms, once)
        child = pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat), type=union[idx].type)
        children = [pa.nulls(0, type=f.type) for f in union]
        children[idx] = child
        buffer = pa.Array.from_buffers(type=union, length=k,
                                       buffers=[None, pa.array(np.full(k, idx, dtype=np.int8)).buffers()[1],
                                                pa.array(np.arange(k, dtype=np.int32)).buffers()[1]],
                                       children=children)
        return pa.StructArray.from_arrays([shape, names, buffer], fields=list(data_type))


SPAWN_FLUSH_S = 30.0  # s a spawned viewer has to take the rest of the recording at the end (the .rrd has it all)


def has_display() -> bool:
    """True when a native viewer window can open (always on macOS/Windows): a Wayland socket, or an X server that
    answers at $DISPLAY. A DISPLAY left set with no server behind it (a stale ssh or container variable) is none:
    the viewer would die and the recording stream wait on it for good."""
    if not sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return True
    wayland = os.environ.get("WAYLAND_DISPLAY")
    if wayland:
        runtime = Path(os.environ.get("XDG_RUNTIME_DIR", "/nonexistent"))
        sock = Path(wayland) if os.path.isabs(wayland) else runtime / wayland
        if sock.exists():
            return True
    display = os.environ.get("DISPLAY")
    return bool(display) and _x_server_answers(display)


def _x_server_answers(display: str) -> bool:
    """Whether an X server listens at ``display`` (``:N``, ``unix:N``, ``host:N[.S]``): its socket file, or a TCP
    connection to port 6000 + N within half a second (ssh's forwarded ``localhost:10.0``)."""
    import socket

    host, _, rest = display.rpartition(":")
    number = rest.split(".", 1)[0]
    if not number.isdigit():
        return False
    if host in ("", "unix"):  # a local server: its socket file
        return Path(f"/tmp/.X11-unix/X{number}").exists()
    try:
        with socket.create_connection((host, 6000 + int(number)), timeout=0.5):
            return True
    except OSError:
        return False


def _free_port(preferred: int) -> int:
    """``preferred`` if nothing listens on it here, else a port the system has free."""
    import socket

    for port in (preferred, 0):
        with socket.socket() as s:
            try:
                s.bind(("0.0.0.0", port))
            except OSError:
                continue
            return int(s.getsockname()[1])
    raise OSError("no free TCP port for the Rerun server")


def viewer_executable() -> str | None:
    """The ``rerun`` viewer: on PATH, else beside this Python (a venv used without being activated)."""
    import shutil

    found = shutil.which("rerun")
    if found:
        return found
    beside = Path(sys.executable).parent / "rerun"
    return str(beside) if beside.exists() else None


def stat_group(name: str) -> str:
    """Time-series group of a stats entry, by keyword (of the part before a ``/`` if any).

    ``ess``, ``timings``, ``error``, ``tries``, ``recovery``; else the prefix before ``/``, else ``other``.
    """
    if "/" in name:
        prefix = name.split("/", 1)[0]
        group = stat_group(prefix)
        return prefix if group == "other" else group
    low = name.lower()
    if "ess" in low or "particle" in low or "neff" in low or "n_eff" in low:
        return "ess"
    if low.endswith("_ms") or low.startswith(("t_", "time", "ms_")) or "timing" in low:
        return "timings"
    if "err" in low or "rmse" in low or "ate" == low:
        return "error"
    if "tries" in low or "reject" in low or "retry" in low:
        return "tries"
    if "inject" in low:  # a share (0..1): not on the counts' scale
        return "recovery"
    return "other"


def _log_relative(w: np.ndarray) -> np.ndarray:
    """log10(w / w_max) of float64 weights (-inf for a zero weight; all -inf when the heaviest is not a positive
    number): what weight_scale, weight_histogram and the cloud's colours (_log_particles) are drawn from."""
    wmax = w.max() if w.size else 0.0
    if not np.isfinite(wmax) or wmax <= 0.0:
        return np.full(w.shape, -np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log10(np.where(w > 0, w / wmax, 0.0))


def weight_scale(weights: np.ndarray) -> np.ndarray:
    """(N,) in [0, 1]: linear weights on a log scale, 1 the heaviest, 0 at ``_WEIGHT_DECADES`` below or lighter."""
    rel = np.nan_to_num(_log_relative(np.asarray(weights, dtype=np.float64)), nan=-_WEIGHT_DECADES,
                        neginf=-_WEIGHT_DECADES)  # all -inf without a positive heaviest weight: all 0
    return np.clip(1.0 + rel / _WEIGHT_DECADES, 0.0, 1.0)


def weight_histogram(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(counts (B,), bin centres (B,), bin width) of log10(w / w_max) over [-span, 0], ``_HIST_BINS`` bins.

    span = the lightest non-zero weight's decades below the heaviest, rounded up to ``_HIST_DECADES`` times a power
    of two (6, 12, 24, ... decades): one scan can set hundreds of decades between poses (60 beams of a few nats
    each), so a fixed range would put nearly every particle in one bin. Zero weights count in the first bin;
    equal weights put every particle in the last."""
    rel = _log_relative(np.asarray(weights, dtype=np.float64))
    finite = rel[np.isfinite(rel)]  # none without a positive heaviest weight (it is 0 here when there is one)
    span = _HIST_DECADES
    if finite.size:
        # a power-of-two multiple of _HIST_DECADES: the bins change only now and then (see _log_histogram)
        span = _HIST_DECADES * 2.0 ** max(0.0, math.ceil(math.log2(max(-float(finite.min()), 1e-9) / _HIST_DECADES)))
    edges = np.linspace(-span, 0.0, _HIST_BINS + 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    if not finite.size:
        return np.zeros(_HIST_BINS), centres, span / _HIST_BINS
    rel = np.clip(np.nan_to_num(rel, nan=-span, neginf=-span), -span, 0.0)
    # np.histogram(rel, bins=edges)'s counts (it sorts the values: 20 us at 5,000 weights, 4 here)
    counts = histogram_counts(rel, edges, np.empty(_HIST_BINS, dtype=np.int64))
    return counts.astype(np.float64), centres, span / _HIST_BINS


def weight_colors(weights: np.ndarray, faded: bool = False) -> np.ndarray:
    """(N, 3) uint8 viridis colours of linear weights on a log scale relative to the heaviest.

    ``faded``: the lighter the weight the more the colour is mixed with the map's free grey (a quarter of the
    colour for the lightest, all of it for the heaviest), so the light particles recede and the heavy ones stand
    out. Rerun (0.41) draws points with an alpha below 255 darker, not see-through: the lightest, at alpha 60, were
    near-black specks that read as obstacles on the map."""
    return scale_colors(weight_scale(weights), faded)


def scale_colors(u: np.ndarray, faded: bool = False) -> np.ndarray:
    """:func:`weight_colors` of weights whose :func:`weight_scale` is ``u`` (computed once for the colours and
    the radii of a cloud)."""
    pos = u * (len(_VIRIDIS) - 1)
    i0 = np.minimum(pos.astype(np.intp), len(_VIRIDIS) - 2)
    f = (pos - i0)[:, None]
    rgb = _VIRIDIS[i0] * (1.0 - f) + _VIRIDIS[i0 + 1] * f
    if faded:
        a = (60.0 + 195.0 * u[:, None]) / 255.0
        rgb = rgb * a + float(_FREE) * (1.0 - a)
    return np.rint(rgb).astype(np.uint8)


# m: a map reaching farther than this from (0, 0) is recorded in a frame of its own (``recording_offset``): Rerun
# stores positions as float32, whose step is 1 mm at 8 km, 0.5 m at a UTM northing (5.4e6 m), where a particle cloud
# collapsed onto a line
LOCAL_FRAME_FROM = 10_000.0


def recording_offset(grid: Any) -> np.ndarray:
    """(2,) metres subtracted from every position the recording holds: (0, 0) for a map within
    ``LOCAL_FRAME_FROM`` of the origin, else its origin rounded to the kilometre (positions then stay within a few
    km of 0, their float32 step under a millimetre)."""
    x0, y0 = (float(v) for v in grid.origin[:2])
    res = float(grid.resolution)
    far = max(abs(x0), abs(y0), abs(x0 + grid.width * res), abs(y0 + grid.height * res))
    if not far > LOCAL_FRAME_FROM:
        return np.zeros(2)
    return np.round(np.array([x0, y0]) / 1000.0) * 1000.0


def _xy32(points: np.ndarray) -> np.ndarray:
    """(K, 2) float32 points (a new array) of (2+, K) float64 ones: the positions of a Points2D."""
    return np.ascontiguousarray(points[:2].T, dtype=np.float32)


def subsample_indices(n: int, m: int) -> np.ndarray:
    """At most ``m`` indices evenly strided over ``range(n)`` (deterministic, unbiased)."""
    if n <= m:
        return np.arange(n)
    return (np.arange(m, dtype=np.int64) * n) // m


@functools.lru_cache(maxsize=8)
def _unit_circle(n: int) -> np.ndarray:
    """(2, n+1) cos, sin of n + 1 angles from 0 to 2 pi (read-only; made once: a third of an ellipse's time)."""
    a = np.linspace(0.0, 2.0 * np.pi, n + 1)
    circle = np.stack([np.cos(a), np.sin(a)])
    circle.setflags(write=False)
    return circle


def covariance_ellipse(mean_xy: np.ndarray, cov_xy: np.ndarray, k: float = 2.0, n: int = 48) -> np.ndarray:
    """(n+1, 2) closed polyline of the k-sigma ellipse of a 2x2 covariance."""
    c = 0.5 * (np.asarray(cov_xy, dtype=np.float64) + np.asarray(cov_xy, dtype=np.float64).T)
    vals, vecs = np.linalg.eigh(c)
    vals = np.clip(np.nan_to_num(vals, nan=0.0), 0.0, None)
    pts = vecs @ (k * np.sqrt(vals)[:, None] * _unit_circle(n))
    pts[:, -1] = pts[:, 0]
    return (pts + np.asarray(mean_xy, dtype=np.float64)[:, None]).T


def _png(image: np.ndarray, mode: str) -> bytes | None:
    try:
        from io import BytesIO

        from PIL import Image as PILImage
    except ImportError:  # pillow is a dependency, but stay usable without it
        return None
    buf = BytesIO()
    # zlib level 1: a 25 M-cell map's layers encode in about 60 % of the default level's time, at a few % more bytes
    PILImage.fromarray(image, mode=mode).save(buf, format="PNG", optimize=False, compress_level=1)
    return buf.getvalue()


# The map layers' largest side in pixels: a viewer draws an image as one GPU texture, and 8192 is the size every
# wgpu adapter supports. A larger map is shown at 2, 3, ... cells per pixel (``_pool``).
MAP_IMAGE_MAX_SIDE = 8192


def map_image_factor(shape: tuple[int, ...]) -> int:
    """Cells per map-image pixel along each axis: 1 unless the grid's larger side exceeds MAP_IMAGE_MAX_SIDE."""
    return max(1, -(-max(int(shape[0]), int(shape[1])) // MAP_IMAGE_MAX_SIDE))


def _pool(a: np.ndarray, k: int, reduce, pad) -> np.ndarray:
    """(ceil(H/k), ceil(W/k)) blocks of k x k cells of ``a`` reduced by ``reduce`` (np.any, np.min, ...) over each
    block; the last rows and columns padded with ``pad`` (grid rows: the padding lies beyond the map's top edge)."""
    if k == 1:
        return a
    h, w = a.shape
    hp, wp = -(-h // k) * k, -(-w // k) * k
    if (hp, wp) != (h, w):
        full = np.full((hp, wp), pad, dtype=a.dtype)
        full[:h, :w] = a
        a = full
    # the k x k strided views folded pairwise (the same values as reduce over the blocks' axes, which strides
    # badly: 100 M cells, k = 2: 3 s -> 0.3 s)
    pair = {np.any: np.logical_or, np.min: np.minimum, np.max: np.maximum}[reduce]
    out = a[0::k, 0::k].copy()
    for i in range(k):
        for j in range(k):
            if i or j:
                pair(out, a[i::k, j::k], out=out)
    return out


def _field_bands(grid: Any, sensor_cfg: Any, k: int, cells: int = 1 << 22):
    """The d the likelihood field scores (``mcl.sensors.field_distance``) in bands of rows, bottom first, each pooled
    by ``_pool(..., k, np.min, np.inf)``: the field's rows (``mcl.sensors.field_rows``: ``grid.distance``, or with
    ``surface: face`` shifted to the faces) with the ``interior: depth`` patches laid on a copy of each band of
    about ``cells`` cells, instead of a copy of the whole field (576 MB on a 600 m map at 5 cm)."""
    from mcl.sensors import field_rows

    rows, patches = field_rows(grid, sensor_cfg)
    h, w = np.shape(grid.distance)
    patches = sorted(patches, key=lambda p: p[0])
    step = k * max(1, cells // max(w * k, 1))  # a whole number of pooled rows per band
    for r0 in range(0, h, step):
        r1 = min(r0 + step, h)
        d = rows(r0, r1)
        if patches:
            d = np.array(d, dtype=np.float32)
        for y0, y1, x0, x1, mine, metres in patches:
            if y0 >= r1:
                break
            if y1 <= r0:
                continue
            a, b = max(y0, r0) - y0, min(y1, r1) - y0  # the patch's rows in this band
            per_row = mine.sum(axis=1)  # ``metres`` follows the mask's cells in row-major order
            i0 = int(per_row[:a].sum())
            d[a + y0 - r0:b + y0 - r0, x0:x1][mine[a:b]] = metres[i0:i0 + int(per_row[a:b].sum())]
        yield _pool(d, k, np.min, np.inf)


def _log_grid_image(rec: Any, path: str, grid: Any, img: np.ndarray, mode: str, draw_order: float,
                    k: int = 1, offset: np.ndarray | None = None) -> None:
    """Static image ``img`` (row 0 the top, one pixel per ``k`` x ``k`` grid cells; ``mode`` L or RGBA) laid over
    the grid at ``path``, its bottom-left corner on the grid's origin: PNG-encoded when pillow is there, raw
    otherwise."""
    h = img.shape[0]
    res = float(grid.resolution) * k
    o = np.zeros(2) if offset is None else offset  # the recording's frame (recording_offset)
    x0, y0 = (float(v) - float(d) for v, d in zip(grid.origin[:2], o))
    # pixel (u, v) -> world (x0 + u res, y0 + h res - v res): with the y flip on `world`
    # the image is drawn unmirrored with its top row at the top.
    rec.log(path, rr.Transform3D(translation=[x0, y0 + h * res, 0.0], scale=[res, -res, 1.0]), static=True)
    png = _png(img, mode)
    image: Any = (rr.EncodedImage(contents=png, media_type="image/png", draw_order=draw_order)
                  if png is not None else rr.Image(img, color_model=mode, draw_order=draw_order))
    rec.log(path, image, static=True)


# Bytes a recording takes per update, measured on generated worlds (rerun-sdk 0.41, 181-beam scan, 150 updates):
CLOUD_POINT_BYTES = 12.5  # a logged particle (f32 x, y, RGBA colour, radius; the weight histogram with them): 11.6-12.3
# The scan (world/scan and world/scan/expected, f32 x, y each) compresses better the more beams it has: 9.1 B a beam
# at 181 beams, 5.8 at 1,440, 5.6 at 2,880 (3,000 updates of each): a fixed part and a per-beam part, not 10 B a beam
SCAN_FIXED_BYTES = 700.0
SCAN_POINT_BYTES = 5.8
STEP_BYTES = 1500.0  # the estimate, its ellipse, the trails and the stats: 1,350


def recording_floor_mb(updates: int, beams: int, log_scan: bool = True) -> float:
    """MB (10^6 bytes) the estimates and scans of ``updates`` updates take: what no ``particles_every`` thins."""
    per_update = STEP_BYTES + ((SCAN_FIXED_BYTES + SCAN_POINT_BYTES * beams) if log_scan and beams else 0.0)
    return per_update * max(int(updates), 0) / 1e6


def particles_every_within(budget_mb: float, updates: int, beams: int, particles_max: int,
                           particles_every: int = 1, log_scan: bool = True) -> int:
    """The ``particles_every`` that keeps a recording of ``updates`` updates within ``budget_mb`` MB (10^6 bytes):
    ``particles_every`` itself if the cloud fits on those updates, else the smallest stride that does (at most
    ``updates``: the cloud of the first update only). The map layers, written once, come on top of the budget;
    so do the estimate and scan of every update, which are never thinned. ``budget_mb`` 0: no budget."""
    every = max(int(particles_every), 1)
    if budget_mb <= 0.0 or particles_max <= 0 or updates <= 0:
        return every
    fits = int((budget_mb - recording_floor_mb(updates, beams, log_scan)) * 1e6
               // (CLOUD_POINT_BYTES * particles_max))  # clouds in budget
    if -(-updates // every) <= fits:  # ceil(updates / every) clouds
        return every
    if fits <= 1:
        return max(every, int(updates))
    return max(every, -(-updates // fits))


class RerunLogger:
    """Logs a localization run to Rerun (file, native viewer, or web viewer).

    ``mode``: ``"save"`` writes an ``.rrd`` to ``path``; ``"spawn"`` opens the native
    viewer (and also writes ``path`` if given), falling back to ``"save"`` with a
    message on stderr when there is no display; ``"serve"`` hosts a gRPC server plus
    the web viewer (alive while the process runs); ``"off"`` makes every method a no-op.

    Particles are logged on every ``particles_every``-th call of :meth:`log_step`
    (calls 0, every, 2 every, ...), at most ``particles_max`` of them evenly strided
    over the set (``particles_max=0``: never).
    """

    def __init__(
        self,
        mode: str,
        path: str | Path | None,
        *,
        particles_max: int = 2000,
        particles_every: int = 1,
        app_id: str = "mcl",
        recording_id: str | None = None,
        log_scan: bool = True,
        heading_length: float = 0.5,
    ) -> None:
        if mode not in MODES:
            raise ValueError(f"rerun mode {mode!r}: expected one of {', '.join(MODES)}")
        if particles_max < 0:
            raise ValueError(f"particles_max must be >= 0 (0: no particles), got {particles_max}")
        if particles_every < 1:
            raise ValueError(f"particles_every must be >= 1, got {particles_every}")
        self.mode = mode
        self.path: Path | None = Path(path) if path is not None else None
        self._file: Path | None = None  # the file being written (_writing)
        self.particles_max = int(particles_max)
        self.particles_every = int(particles_every)
        self.log_scan = bool(log_scan)
        self.heading_length = float(heading_length)
        self.url: str | None = None
        self._rec: rr.RecordingStream | None = None
        self._closed = False
        self._calls = 0
        self._flushed_at = 0.0  # time.monotonic() of the last flush of the buffered columns (live modes)
        self._skipped_shown = False  # world/scan/skipped holds points (a step without must clear them)
        self._scan_shown = False  # world/scan holds points (a step without returns must clear them)
        self._time_kind: str | None = None
        self._stat_names: list[str] = []
        self._bounds = None  # the world view's frame, from the map (log_map)
        self.offset = np.zeros(2)  # m: subtracted from every position recorded (recording_offset, from log_map)
        self._warm: set[str] = set()
        self._hist_width: float | None = None  # timings whose warm-up (first real run) is over
        self._blueprint_key: tuple[str, ...] | None = None
        self._truth_path_logged = False
        self._prev_truth: np.ndarray | None = None
        self._prev_odom: np.ndarray | None = None
        # rows waiting to be sent as columns: (entity path, archetype) -> (steps, times, {field: [one row each]})
        self._pending: dict[str, tuple[list, list, dict[tuple[str, str], list]]] = {}
        # rows of any number of instances (the cloud, the scans, the histogram), the same way (_buffer_rows):
        # (entity path, archetype, fields) -> (steps, times, {field: [one array per row]})
        self._pending_rows: dict[tuple[str, str, tuple[str, ...]], tuple[list, list, dict[str, list]]] = {}
        self._step_now = 0
        self._t_now: int | None = None  # the time timeline's value at the current step, ns (None: never set)
        self._groups: dict[str, str] = {}  # stat_group of each stats name
        if mode == "off":
            return

        viewer = viewer_executable() if mode == "spawn" else None
        display = mode == "spawn" and has_display()  # once: it may wait half a second on a remote X server
        if mode == "spawn" and (not display or viewer is None):
            self.path = self.path or Path(f"{app_id}.rrd")
            why = ("no display (no X server answers at DISPLAY, no Wayland socket)" if not display
                   else "no `rerun` viewer on PATH or beside this Python")
            print(
                f"mcl: {why}, cannot spawn the Rerun viewer; "
                f"saving the recording to {self.path} instead (open it with `rerun {self.path}`)",
                file=sys.stderr,
            )
            mode = "save"
            self.mode = "save"
        # a saved recording is cut into chunks by size alone (the default batcher also flushes every 200 ms, so the
        # file's layout, and its size, followed the machine's load): the same run gives the same file
        rec = rr.RecordingStream(app_id, recording_id=recording_id or uuid.uuid4(),
                                 batcher_config=_save_batcher() if mode == "save" else None)
        if mode == "save":
            if self.path is None:
                raise ValueError("rerun mode 'save' needs a path for the .rrd file")
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with self._opening():
                rec.save(self._writing())
        elif mode == "spawn":
            rr.spawn(connect=False, executable_path=viewer, recording=rec)
            sinks: list[Any] = [rr.GrpcSink()]
            if self.path is not None:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                sinks.append(rr.FileSink(self._writing()))
            with self._opening():
                rec.set_sinks(*sinks)
        else:  # serve
            # Rerun's own ports (9876, 9090) when free, else free ones: a second run or an open viewer holds them,
            # and the server thread then died at the run's end (a traceback, no summary)
            grpc_port, web_port = _free_port(9876), _free_port(9090)
            self.url = rec.serve_grpc(grpc_port=grpc_port)
            rr.serve_web_viewer(web_port=web_port, connect_to=self.url, open_browser=False)
            print(
                f"mcl: Rerun gRPC server at {self.url}; web viewer at "
                f"http://localhost:{web_port}/?url={quote(self.url, safe='')} (native: `rerun {self.url}`); "
                "both stop when this process exits (mcl run serves on after the run until Ctrl-C)",
                file=sys.stderr,
            )
        self._rec = rec
        # The world frame is y-up; 2D views draw y down, so flip y once for everything under world.
        rec.log("world", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
        rec.log(
            "world/particles",
            rr.Points2D.from_fields(draw_order=_DRAW_ORDER["particles"]),  # radii per step, by weight
            static=True,
        )
        rec.log(
            "world/scan",
            rr.Points2D.from_fields(
                radii=rr.Radius.ui_points(2.0), colors=[230, 60, 60], draw_order=_DRAW_ORDER["scan"]
            ),
            static=True,
        )
        rec.log(
            "world/scan/skipped",
            rr.Points2D.from_fields(
                # blue: yellow is the heaviest particles', orange the odometry's
                radii=rr.Radius.ui_points(3.0), colors=[0, 90, 255], draw_order=_DRAW_ORDER["scan"] + 0.5
            ),
            static=True,
        )
        rec.log(
            "world/scan/expected",
            rr.Points2D.from_fields(
                radii=rr.Radius.ui_points(1.5), colors=[60, 220, 240], draw_order=_DRAW_ORDER["scan"] - 0.5
            ),
            static=True,
        )
        rec.log("about", rr.TextDocument(ABOUT, media_type=rr.MediaType.MARKDOWN), static=True)

    # -- context manager ---------------------------------------------------------------
    def __enter__(self) -> RerunLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def enabled(self) -> bool:
        return self._rec is not None and not self._closed

    # -- static things -----------------------------------------------------------------
    def log_map(self, grid: Any) -> None:
        """Static image of the occupancy grid, placed so one pixel is one cell in metres (on a map over
        MAP_IMAGE_MAX_SIDE cells, k x k cells: occupied if any is, else free if any is)."""
        rec = self._live()
        if rec is None:
            return
        k = map_image_factor(np.shape(grid.occupied))
        occupied = _pool(np.asarray(grid.occupied, dtype=bool), k, np.any, False)
        free = _pool(np.asarray(grid.free, dtype=bool), k, np.any, False)
        img = np.full(occupied.shape, _UNKNOWN, dtype=np.uint8)
        img[free] = _FREE
        img[occupied] = _OCCUPIED
        img = np.ascontiguousarray(img[::-1])  # grid row 0 is the bottom; image row 0 is the top
        self.offset = recording_offset(grid)
        if self.offset.any():
            rec.log("about", rr.TextDocument(ABOUT + self.frame_note(), media_type=rr.MediaType.MARKDOWN),
                    static=True)
        _log_grid_image(rec, "world/map", grid, img, "L", _DRAW_ORDER["map"], k, self.offset)
        b = known_bounds(grid)  # the world view's frame (build_blueprint)
        ox, oy = (float(v) for v in self.offset)
        self._bounds = None if b is None else ((b[0][0] - ox, b[0][1] - ox), (b[1][0] - oy, b[1][1] - oy))

    def frame_note(self) -> str:
        """What the recording's positions are relative to, when not the map frame ("" when they are)."""
        if not self.offset.any():
            return ""
        ox, oy = (float(v) for v in self.offset)
        return (f"recording: positions are relative to ({ox:.0f}, {oy:.0f}) m in the map frame (Rerun keeps them "
                "as float32, which would round them to centimetres or more this far out); the trajectory and "
                "summary keep the map frame")

    def local(self, a: Any) -> np.ndarray:
        """``a`` (an x, y[, theta] pose or a (2|3, N) array) in the recording's frame: x, y less ``offset``."""
        if not self.offset.any():  # (every map within 10 km of the origin: no copy)
            return np.asarray(a, dtype=np.float64)
        b = np.array(a, dtype=np.float64)
        b[:2] -= self.offset.reshape((2,) + (1,) * (b.ndim - 1))
        return b

    def log_likelihood_field(self, grid: Any, sensor_cfg: Any) -> None:
        """Static image of the likelihood field (Prob. Rob. Table 6.3): p(endpoint | map) of an endpoint in each
        cell, z_hit N(d; 0, sigma_hit^2) + z_rand / range_max with d the distance to the nearest obstacle, scaled
        to [0, 1] by its value on an obstacle and drawn with the weight colormap (semi-transparent) over the map.
        At ``world/likelihood_field``; the blueprint hides it (tick it in the viewer's blueprint tree)."""
        rec = self._live()
        if rec is None:
            return
        from mcl.config import sensor_model_view
        from mcl.sensors import point_log_likelihood

        p_top = float(np.exp(point_log_likelihood(0.0, sensor_cfg)))

        def colours(dist: np.ndarray) -> np.ndarray:
            # with d = 0 (u = 1) first, as the whole field has on its obstacles: weight_scale(...) == u, the colours
            u = np.clip(np.exp(point_log_likelihood(np.concatenate([[0.0], dist]), sensor_cfg)) / p_top, 0.0, 1.0)
            return weight_colors(10.0 ** (_WEIGHT_DECADES * (u - 1.0)))[1:]

        # Every cell takes its colour from a table of distances to the millimetre (a colour moves by at most one
        # level of 255 per mm), the last entry for likelihood_max_dist and beyond: the chain of exponentials runs on
        # a few thousand distances, not on every cell (250 m map: 3.3 s -> 1.4 s with the PNG encoding)
        top_mm = int(round(float(sensor_model_view(sensor_cfg, "likelihood_field").likelihood_max_dist) * 1000.0))
        table = np.empty((top_mm + 1, 4), dtype=np.uint8)
        table[:, :3] = colours(np.append(np.arange(top_mm) / 1000.0, np.inf))
        table[:, 3] = 200
        k = map_image_factor(np.shape(grid.distance))
        bands = [table[np.rint(np.minimum(d[::-1], top_mm / 1000.0) * 1000.0).astype(np.int32)]  # image row 0: top
                 for d in _field_bands(grid, sensor_cfg, k)]  # a block shows its most likely cell
        img = np.concatenate(bands[::-1]) if len(bands) > 1 else bands[0]
        _log_grid_image(rec, "world/likelihood_field", grid, img, "RGBA", _DRAW_ORDER["map"] + 1.0, k, self.offset)

    def log_truth_path(self, poses: np.ndarray, t: np.ndarray | None = None) -> None:
        """Static full true path (3, M), at times ``t`` (M,) if given; per-step truth trails are then not logged."""
        rec = self._live()
        if rec is None:
            return
        p = self.local(poses)
        # broken where the robot jumps (a kidnap): one line across the map through its walls read as a path. A step
        # over 10 median steps (and 1 m); with times, only when it is as fast too: a scan gap of 2 s drove 1.1 m at
        # the robot's own speed, and the path was cut there
        step = np.hypot(*np.diff(p[:2], axis=1)) if p.shape[1] > 1 else np.zeros(0)
        jump = max(1.0, 10.0 * float(np.median(step))) if step.size else np.inf
        far = step > jump
        if t is not None and step.size:
            dt = np.diff(np.asarray(t, dtype=np.float64))
            with np.errstate(divide="ignore", invalid="ignore"):
                speed = np.where(dt > 0.0, step / np.where(dt > 0.0, dt, 1.0), np.inf)
            moving = speed[np.isfinite(speed) & (step > 0.0)]
            far &= speed > 10.0 * (float(np.median(moving)) if moving.size else 0.0)
        cuts = np.flatnonzero(far) + 1
        strips = [np.ascontiguousarray(q[:2].T, dtype=np.float32) for q in np.split(p, cuts, axis=1)]
        rec.log(
            "world/truth",
            rr.LineStrips2D(
                strips,
                colors=[40, 170, 40],  # opaque: Rerun draws an alpha below 255 darker, not see-through
                radii=rr.Radius.ui_points(1.0),
                draw_order=_DRAW_ORDER["trail"],
            ),
            static=True,
        )
        self._truth_path_logged = True

    # -- per step ----------------------------------------------------------------------
    def log_step(
        self,
        step: int,
        t: float,
        *,
        particles: np.ndarray,
        weights: np.ndarray,
        estimate: np.ndarray,
        cov: np.ndarray,
        scan_world: np.ndarray | None = None,
        skipped_world: np.ndarray | None = None,
        expected_world: np.ndarray | None = None,
        odom_pose: np.ndarray | None = None,
        truth_pose: np.ndarray | None = None,
        stats: Mapping[str, float] | None = None,
    ) -> None:
        """Log one filter step. ``weights`` are normalized linear weights (N,).

        ``skipped_world`` (2, S): the endpoints not scored (unmapped objects, beam skipping), in blue over the
        scan; a step without any clears the previous step's (only once skipping has shown something, to keep
        recordings small).
        ``expected_world`` (2, E): where the beams would end if the estimate were right (see ``expected_scan``).
        The histogram of the weights (all N) is logged at every update, the cloud every ``particles_every``-th.
        """
        rec = self._live()
        if rec is None:
            return
        call = self._calls
        self._calls += 1
        live = self.mode in ("spawn", "serve")
        if call % COLUMN_FLUSH_STEPS == 0 or (live and time.monotonic() - self._flushed_at > LIVE_FLUSH_S):
            # a saved file by steps alone: its layout does not follow the machine's load
            self._flush_columns(rec)
            self._flushed_at = time.monotonic()
        rec.set_time("step", sequence=int(step))
        self._step_now = int(step)
        self._set_time(rec, float(t))
        estimate = self.local(estimate)  # the recording's frame (recording_offset); the particles' in _log_particles
        scan_world, skipped_world, expected_world, odom_pose, truth_pose = (
            None if a is None else self.local(a) for a in (scan_world, skipped_world, expected_world, odom_pose,
                                                          truth_pose))

        if self.particles_max > 0 and call % self.particles_every == 0:
            self._log_particles(rec, particles, weights)
        self._log_histogram(weights)  # every update, all N: 24 bars (a thinned or hidden cloud thinned it too)
        self._log_estimate(rec, estimate, cov)
        if self.log_scan and (scan_world is not None or self._scan_shown):
            # a step without returns (all beyond range, an update from landmarks alone) clears the last scan: it
            # was drawn from another pose, and stayed on screen for the rest of the run
            s = np.asarray(scan_world, dtype=np.float64) if scan_world is not None else np.zeros((2, 0))
            self._buffer_rows("world/scan", "Points2D", dict(positions=_xy32(s)))
            self._scan_shown = s.shape[1] > 0
            if expected_world is None:
                self._buffer_rows("world/scan/expected", "Points2D", dict(positions=_xy32(np.zeros((2, 0)))))
        if self.log_scan and (skipped_world is not None or self._skipped_shown):
            k = np.asarray(skipped_world, dtype=np.float64) if skipped_world is not None else np.zeros((2, 0))
            self._buffer_rows("world/scan/skipped", "Points2D", dict(positions=_xy32(k)))
            self._skipped_shown = k.shape[1] > 0
        if self.log_scan and expected_world is not None:
            x = np.asarray(expected_world, dtype=np.float64)
            self._buffer_rows("world/scan/expected", "Points2D", dict(positions=_xy32(x)))
        if truth_pose is not None:
            self._prev_truth = self._log_pose(
                rec, "world/truth", truth_pose, self._prev_truth, [40, 170, 40], trail=not self._truth_path_logged
            )
        elif self._prev_truth is not None:  # a reference gap not bridged: the last true pose is not this step's
            rec.log("world/truth", rr.Points2D(np.zeros((0, 2), dtype=np.float32)))  # (rows of this step's time)
            self._prev_truth = None
        if odom_pose is not None:
            self._prev_odom = self._log_pose(rec, "world/odometry", odom_pose, self._prev_odom, [240, 150, 30])
        if stats:
            self._log_stats(rec, stats)
        self._send_blueprint()

    def close(self) -> None:
        """Flush and close the sinks (idempotent). The .rrd is complete afterwards.

        In ``serve`` mode the server keeps serving the buffered recording until the
        process exits.
        """
        if self._closed:
            return
        self._closed = True
        rec, self._rec = self._rec, None
        if rec is None:
            return
        self._flush_columns(rec)
        if self._blueprint_key is None:
            self._send_blueprint_to(rec)
        missed = None  # why a spawned viewer did not take the recording's end
        try:
            if self.mode == "spawn":  # a viewer that died (closed, its display gone) must not hold the run for good
                rec.flush(timeout_sec=SPAWN_FLUSH_S)
            else:
                rec.flush()
        except RuntimeError as e:  # the file sink failed (a full disk): one error naming the recording
            if self.mode != "spawn" or self.path is None:
                self._cut_short(str(e))
            # the viewer's sink timed out, or the file's failed: the file, checked whole below, tells which
            missed = str(e)
        if self.mode == "serve":
            # Disconnecting, or dropping the stream with this logger when the run returns, shuts the gRPC server
            # down before a viewer could read the buffered data: keep the stream for the rest of the process.
            _SERVED.append(rec)
            return
        rec.disconnect()
        # The file sink writes its last buffer and the footer when disconnected, and a failure there (a file size
        # limit, a full disk) is only logged by rerun: the run ended with exit 0 and "Open the recording with" a
        # recording.rrd cut short (`rerun rrd verify`: "Missing RRD footer")
        file = self._file
        if file is not None and file.exists() and not recording_is_whole(file):
            self._cut_short(missed or "its end could not be written")
        if missed is not None and file is not None and not file.exists():
            self._cut_short(missed)
        if file is not None and file.exists():  # whole: under its final name only now
            os.replace(file, self.path)
        if missed is not None:  # a viewer gone before the run's end lost nothing: the .rrd has it all
            print(f"mcl: note: the Rerun viewer did not take the recording's end ({missed}); {self.path} holds all "
                  f"of it (rerun {self.path})", file=sys.stderr)

    def _writing(self) -> Path:
        """The file the recording is written to while the run goes on: ``recording.partial.rrd`` (``partial_recording``),
        renamed to ``recording.rrd`` by :meth:`close` once whole. Written under its final name, a run killed (kill
        -9, out of memory) left a ``recording.rrd`` without its footer, which no reader opens."""
        if self.path.is_dir():  # it could never be renamed there
            raise OSError(errno.EISDIR, "cannot open the recording (a folder has its name)", str(self.path))
        self._file = partial_recording(self.path)
        self._file.unlink(missing_ok=True)  # an earlier run's, cut short
        return self._file

    @contextmanager
    def _opening(self):
        """Rerun's failure to open the file sink ("Failed to create file: Is a directory") as one OSError naming the
        recording, not a RuntimeError traceback."""
        try:
            yield
        except RuntimeError as e:
            raise OSError(errno.EIO, f"cannot open the recording ({e})", str(self.path)) from None

    def _cut_short(self, why: str) -> None:
        """The recording could not be written whole: leave it as ``recording.partial.rrd`` and raise OSError."""
        if self.path is None:  # a stream with no file (a live viewer's): nothing is left behind
            raise OSError(errno.EIO, f"the recording could not be sent ({why})", "the recording") from None
        cut = partial_recording(self.path)  # the file written all along (_writing): it keeps that name
        raise OSError(errno.EIO, f"the recording could not be written ({why}); what was written is in "
                      f"{cut.name} (rerun {cut.name} shows it)", str(self.path)) from None

    def expected_scan(self, grid: Any, pose: np.ndarray, laser_pose: np.ndarray, angles: np.ndarray,
                      range_max: float) -> np.ndarray:
        """(2, E) world endpoints of the beams at ``angles`` (laser frame) cast on ``grid`` from the laser at
        ``pose``: the scan the beam model expects (z*, Prob. Rob. 6.3) if the estimate were right. Rays that
        hit nothing within ``range_max`` are left out."""
        from mcl.estimate import compose
        from mcl.sensors import cast_from_laser

        if getattr(self, "_blocked_of", None) is not grid:
            self._blocked_of = grid
            self._blocked = np.ascontiguousarray(grid.occupied, dtype=np.bool_)
        at = compose(np.asarray(pose, dtype=np.float64), np.asarray(laser_pose, dtype=np.float64))
        z = cast_from_laser(self._blocked, grid.origin, grid.resolution, pose, laser_pose, angles, range_max)
        keep = z < range_max
        ang = at[2] + np.asarray(angles, dtype=np.float64)[keep]
        return np.vstack([at[0] + z[keep] * np.cos(ang), at[1] + z[keep] * np.sin(ang)])

    # -- helpers -----------------------------------------------------------------------
    def _live(self) -> rr.RecordingStream | None:
        if self._closed:
            if self.mode == "off":
                return None
            raise RuntimeError("RerunLogger is closed")
        return self._rec

    def _set_time(self, rec: rr.RecordingStream, t: float) -> None:
        if not np.isfinite(t):
            return
        if self._time_kind is None:
            self._time_kind = "timestamp" if t > _TIMESTAMP_THRESHOLD else "duration"
            self._flush_columns(rec)  # the rows so far have no time: sent apart
        # the buffered rows' time in nanoseconds, as set_time takes it (a column of floats was converted per row)
        self._t_now = to_nanos_since_epoch(t) if self._time_kind == "timestamp" else to_nanos(t)
        if self._time_kind == "timestamp":
            rec.set_time("time", timestamp=t)
        else:
            rec.set_time("time", duration=t)

    def _log_particles(self, rec: rr.RecordingStream, particles: np.ndarray, weights: np.ndarray) -> None:
        p = np.asarray(particles)
        idx = subsample_indices(p.shape[1], self.particles_max)
        xy = np.empty((idx.size, 2), dtype=np.float32)
        xy[:, 0] = p[0, idx] - self.offset[0]
        xy[:, 1] = p[1, idx] - self.offset[1]
        w = np.asarray(weights, dtype=np.float64)[idx]
        # Size and fading by weight too: among thousands of points of similar colour the heavy ones still stand out.
        # Three sizes (1, 2, 3.5 UI points: below 1.5 decades under the heaviest, within it, within 0.3 decades):
        # few distinct values keep the recording small (they compress), and still read at a glance.
        # weight_scale, scale_colors(faded) and rr.Radius.ui_points(_RADII[np.searchsorted(_RADII_AT, u)]) in one
        # kernel (the same values; tests/test_viz.py), the logarithms as weight_scale takes them
        colors = np.empty((idx.size, 3), dtype=np.uint8)
        radii = np.empty(idx.size, dtype=np.float32)
        cloud_style(_log_relative(w), _WEIGHT_DECADES, _VIRIDIS, float(_FREE), True, _RADII, _RADII_AT, colors, radii)
        self._buffer_rows("world/particles", "Points2D", dict(positions=xy, colors=colors, radii=radii))

    def _log_histogram(self, weights: np.ndarray) -> None:
        counts, centres, width = weight_histogram(weights)
        if width != self._hist_width:  # the bins only when they change (the viewer takes the latest): ~2 ms saved
            self._hist_width = width
            # a bar spans [abscissa, abscissa + width] in the viewer: the bins' left edges, not their centres
            self._buffer_rows("weights/histogram", "BarChart",
                              dict(abscissa=centres - 0.5 * width, widths=np.full(centres.size, width),
                                   color=_HIST_COLOR))
        self._buffer_rows("weights/histogram", "BarChart", dict(values=counts.astype(np.float32)))

    def _log_estimate(self, rec: rr.RecordingStream, estimate: np.ndarray, cov: np.ndarray) -> None:
        e = np.asarray(estimate, dtype=np.float64)
        c = np.asarray(cov, dtype=np.float64)
        color = [220, 40, 200]
        heading = self.heading_length * np.array([np.cos(e[2]), np.sin(e[2])])
        order = _DRAW_ORDER["estimate"]
        self._buffer("world/estimate", {
            "Points2D": dict(positions=e[:2], colors=color, radii=-4.0, draw_order=order),
            "Arrows2D": dict(origins=e[:2], vectors=heading, colors=color, radii=-1.5, draw_order=order),
            "LineStrips2D": dict(strips=covariance_ellipse(e[:2], c[:2, :2]).astype(np.float32), colors=color,
                                 radii=-1.0, draw_order=order),
        })
        # the "Robot" view's frame: the estimate's position (not its heading: the map stays north-up), y flipped
        # as on `world` (a view drawn from this origin does not see the flip on its ancestor)
        self._buffer(FOLLOW_ENTITY, {"Transform3D": dict(translation=[e[0], e[1], 0.0], scale=[1.0, -1.0, 1.0])})

    def _log_pose(
        self,
        rec: rr.RecordingStream,
        entity: str,
        pose: np.ndarray,
        prev: np.ndarray | None,
        color: list[int],
        *,
        trail: bool = True,
    ) -> np.ndarray:
        xy = np.asarray(pose, dtype=np.float64)[:2].copy()
        self._buffer(entity, {"Points2D": dict(positions=xy, colors=color, radii=-4.0,
                                               draw_order=_DRAW_ORDER["truth"])})
        if trail and prev is not None:
            self._buffer(f"{entity}/trail", {"LineStrips2D": dict(strips=np.stack([prev, xy]).astype(np.float32),
                                                                  colors=color, radii=-1.0,
                                                                  draw_order=_DRAW_ORDER["trail"])})
        return xy

    def _log_stats(self, rec: rr.RecordingStream, stats: Mapping[str, float]) -> None:
        for name, value in stats.items():
            if value is None:
                continue
            group = self._groups.get(name)
            if group is None:  # its panel from the start, even while its values go to warmup/
                group = self._groups[name] = stat_group(name)
                i = sum(stat_group(n) == group for n in self._stat_names)  # its place in its panel
                rec.log(f"stats/{name}", rr.SeriesLines(colors=[_SERIES_COLOURS[i % len(_SERIES_COLOURS)]],
                                                        names=[name]), static=True)
                self._stat_names.append(name)
            if group == "timings" and name not in self._warm:
                # A stage's first run (the filter times only stages that ran: no prediction at the first update)
                # compiles or loads its numba kernels: that time goes apart, to warmup/, so the plot's scale reads.
                # Not a threshold on the value: kernels another run in this process loaded are fast at once.
                rec.log(f"warmup/{name}", rr.Scalars(float(value)))
                self._warm.add(name)
                continue
            self._buffer(f"stats/{name}", {"Scalars": {"scalars": float(value)}})

    def _buffer(self, path: str, row: dict[str, dict[str, Any]]) -> None:
        """One row at ``path`` for the current step, {archetype: {field: value}} (each field one instance; a
        UI-points radius negative, as Rerun stores it), sent with the path's other rows by _flush_columns. A path
        takes the same archetypes and fields at every step."""
        steps, times, columns = self._pending.setdefault(path, ([], [], {}))
        steps.append(self._step_now)
        times.append(self._t_now)
        for archetype, fields in row.items():
            for name, value in fields.items():
                columns.setdefault((archetype, name), []).append(value)

    def _buffer_rows(self, path: str, archetype: str, fields: dict[str, Any]) -> None:
        """One row of ``archetype`` at ``path`` for the current step, each field a batch of any number of instances
        (an (n, ...) array; a tensor field (_TENSOR_FIELDS): one tensor), sent with the other rows of the same path
        and fields by _flush_columns: as ``rec.log(path, archetype(**fields))`` at this step would have logged it.
        The arrays are kept: pass ones nothing changes afterwards."""
        steps, times, columns = self._pending_rows.setdefault((path, archetype, tuple(fields)), ([], [], {}))
        steps.append(self._step_now)
        times.append(self._t_now)
        for name, value in fields.items():
            columns.setdefault(name, []).append(value)

    def _indexes(self, steps: list, times: list) -> list:
        """The step and time columns of buffered rows (``times``: nanoseconds, or None before any time)."""
        indexes = [rr.TimeColumn("step", sequence=steps)]
        if times[0] is not None:
            unit = "datetime64[ns]" if self._time_kind == "timestamp" else "timedelta64[ns]"
            indexes.append(rr.TimeColumn("time", **{self._time_kind: np.array(times, dtype=np.int64).astype(unit)}))
        return indexes

    def _flush_columns(self, rec: rr.RecordingStream) -> None:
        """Send the buffered rows as columns, one chunk per path (and set of fields): each row as one rr.log of its
        archetypes at its step and time would have logged it."""
        pending_rows, self._pending_rows = self._pending_rows, {}
        for (path, archetype, _), (steps, times, columns) in pending_rows.items():
            kind = getattr(rr, archetype)
            cols: list[Any] = []
            for name, values in columns.items():
                if (archetype, name) in _TENSOR_FIELDS:
                    cols.append(rr.ComponentColumn(getattr(kind, f"descriptor_{name}")(), _TensorColumn(values)))
                elif (archetype, name) in _FIELD_BATCHES:
                    batch = getattr(rr.components, _FIELD_BATCHES[archetype, name])(np.concatenate(values))
                    cols.append(rr.ComponentColumn(getattr(kind, f"descriptor_{name}")(), batch,
                                                   lengths=[len(v) for v in values]))
                else:
                    cols += kind.columns(**{name: np.concatenate(values)}).partition([len(v) for v in values])
            rec.send_columns(path, indexes=self._indexes(steps, times), columns=cols)
        pending, self._pending = self._pending, {}
        for path, (steps, times, columns) in pending.items():
            indexes = self._indexes(steps, times)
            per_arch: dict[str, dict[str, Any]] = {}
            for (archetype, name), values in columns.items():
                if name == "strips":  # one strip a row: (K, points, 2) when all have as many points (faster)
                    same = all(len(v) == len(values[0]) for v in values)
                    per_arch.setdefault(archetype, {})[name] = np.asarray(values) if same else values
                    continue
                per_arch.setdefault(archetype, {})[name] = np.asarray(values, dtype=_COLUMN_DTYPES.get(name))
            cols = [c for archetype, fields in per_arch.items()
                    for c in getattr(rr, archetype).columns(**fields).partition([1] * len(steps))]
            rec.send_columns(path, indexes=indexes, columns=cols)

    def _send_blueprint(self) -> None:
        """(Re)send the layout when new stats names appeared (usually once, at step 1)."""
        if self._rec is not None and tuple(self._stat_names) != self._blueprint_key:
            self._send_blueprint_to(self._rec)

    def _send_blueprint_to(self, rec: rr.RecordingStream) -> None:
        self._blueprint_key = tuple(self._stat_names)
        rec.send_blueprint(build_blueprint(self._stat_names, self._bounds))


def known_bounds(grid: Any, margin: float = 0.05) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """((x0, x1), (y0, y1)) world metres around the map's known cells (free or occupied), ``margin`` of the larger
    side added all round; None when no cell is known. A map's wide unknown margin is left out of the view."""
    known = ~np.asarray(grid.unknown)
    rows, cols = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
    if rows.size == 0:
        return None
    res = float(grid.resolution)
    x0, y0 = (float(v) for v in grid.origin[:2])
    xs = (x0 + cols[0] * res, x0 + (cols[-1] + 1) * res)
    ys = (y0 + rows[0] * res, y0 + (rows[-1] + 1) * res)
    pad = margin * max(xs[1] - xs[0], ys[1] - ys[0])
    return (xs[0] - pad, xs[1] + pad), (ys[0] - pad, ys[1] + pad)


def build_blueprint(stat_names: list[str] | tuple[str, ...] = (), bounds=None) -> rrb.Blueprint:
    """The Robot view (following the estimate: origin ``world/follow``; on a map over ``FOLLOW_MIN_SIDE_M`` across)
    and the World view (the whole map) on the left; one time-series view per stats group on the right, each over
    the whole run. ``bounds`` ((x0, x1),
    (y0, y1)) in world metres (``known_bounds``): the world view opens on them and keeps them while the time runs
    (fitted to what each step draws, the map jumped and zoomed at every step)."""
    trail_range = [
        rrb.VisibleTimeRange(
            timeline, start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.cursor_relative()
        )
        for timeline in ("step", "time")
    ]
    # every series over the whole run: without a range the plots showed a window of about 2,500 steps that
    # followed the cursor (fr079, 4,110 updates: at step 0 the left half empty, the run's end off screen)
    whole_run = rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                                                        end=rrb.TimeRangeBoundary.infinite()))
    trail_overrides = {
        "world/truth/trail": rrb.VisibleTimeRanges(trail_range),
        "world/odometry/trail": rrb.VisibleTimeRanges(trail_range),
        "world/likelihood_field": rrb.EntityBehavior(visible=False),
    }
    follow = bounds is None or max(bounds[0][1] - bounds[0][0], bounds[1][1] - bounds[1][0]) > FOLLOW_MIN_SIDE_M
    robot = rrb.Spatial2DView(
        name=f"Robot: {2 * FOLLOW_HALF_M:g} m around the estimate",
        origin=f"/{FOLLOW_ENTITY}",
        contents=["+ /world/**"],
        background=[30, 30, 30],
        visual_bounds=rrb.VisualBounds2D(x_range=[-FOLLOW_HALF_M, FOLLOW_HALF_M],
                                         y_range=[-FOLLOW_HALF_M, FOLLOW_HALF_M]),
        overrides=dict(trail_overrides),
    )
    world = rrb.Spatial2DView(
        name="World",
        origin="/",
        contents=["+ /world/**"],
        background=[30, 30, 30],
        # y flipped on `world` (drawn y up): the view's y is minus the world's
        visual_bounds=(None if bounds is None else
                       rrb.VisualBounds2D(x_range=list(bounds[0]), y_range=[-bounds[1][1], -bounds[1][0]])),
        overrides=dict(trail_overrides),
    )
    groups: dict[str, list[str]] = {}
    for name in stat_names:
        groups.setdefault(stat_group(name), []).append(name)
    titles = dict(_STAT_GROUPS)
    order = [g for g, _ in _STAT_GROUPS] + sorted(set(groups) - set(titles))
    views = [
        rrb.TimeSeriesView(
            name=titles.get(g, g),
            origin="/stats",
            contents=[f"+ /stats/{n}" for n in groups[g]] + ([f"+ /stats/{g}/**"] if g not in titles else []),
            axis_x=whole_run,
        )
        for g in order
        if g in groups
    ]
    if not views:
        views = [rrb.TimeSeriesView(name="Stats", origin="/stats")]
    main = [v for g, v in zip([g for g in order if g in groups], views) if g in _MAIN_GROUPS] if groups else views
    rest = [v for v in views if all(v is not m for m in main)]
    weights = rrb.BarChartView(name="Particle weights: how many particles per log10(w / w_max) bin, this step",
                               origin="/weights", contents=["+ /weights/histogram"])
    about = rrb.TextDocumentView(name="About this recording", origin="/about", contents=["+ /about"])
    main.insert(min(3, len(main)), weights)
    if any(stat_group(n) == "planes" for n in stat_names):  # plane features: a 3D view of the depth cloud
        rest = [rrb.Spatial3DView(name="Depth", origin="/", contents=["+ /depth/**"])] + rest
    right = rrb.Vertical(*main, rrb.Tabs(about, *rest, active_tab=0))
    return rrb.Blueprint(
        (rrb.Horizontal(robot, world, right, column_shares=[2, 2, 2]) if follow else
         rrb.Horizontal(world, right, column_shares=[3, 2])),
        # the step timeline: every panel spans the whole run (on `time` the plots opened on a window of it); the
        # time panel collapsed to its scrubber and the selection panel closed: the views get the screen (both
        # open from the viewer's top bar)
        rrb.TimePanel(timeline="step", state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),  # its 200 px to the views
        collapse_panels=False,
    )


# -- landmarks (mcl.landmarks) ---------------------------------------------------------------
#   world/landmarks           static Points2D: the landmark map, labelled with the ids
#   world/landmarks/observed  LineStrips2D per step: from the estimate to where each observation
#                             (range, bearing) puts its landmark; empty when the update had none

_LANDMARK_COLOR = [250, 200, 40]
_OBSERVED_COLOR = [255, 120, 30]


def log_landmark_map(logger: RerunLogger, landmark_map: Any) -> None:
    """Static points of the landmark map (``ids`` (K,), ``xy`` (2, K)) with the ids as labels."""
    rec = logger._live()
    if rec is None:
        return
    xy = np.ascontiguousarray(logger.local(landmark_map.xy).T, dtype=np.float32)
    rec.log(
        "world/landmarks",
        rr.Points2D(
            xy,
            labels=[str(int(i)) for i in np.asarray(landmark_map.ids)],
            colors=[_LANDMARK_COLOR],
            radii=rr.Radius.ui_points(5.0),
            draw_order=_DRAW_ORDER["estimate"] + 1.0,
        ),
        static=True,
    )


def landmark_rays(estimate: np.ndarray, ranges: np.ndarray, bearings: np.ndarray) -> np.ndarray:
    """(J, 2, 2) segments from the estimate (x, y, theta) to estimate + range at heading theta + bearing."""
    e = np.asarray(estimate, dtype=np.float64)
    r = np.asarray(ranges, dtype=np.float64).ravel()
    a = e[2] + np.asarray(bearings, dtype=np.float64).ravel()
    seg = np.empty((r.size, 2, 2))
    seg[:, 0, 0], seg[:, 0, 1] = e[0], e[1]
    seg[:, 1, 0] = e[0] + r * np.cos(a)
    seg[:, 1, 1] = e[1] + r * np.sin(a)
    return seg


def log_landmark_observations(logger: RerunLogger, estimate: np.ndarray, marks: Any, landmark_map: Any = None) -> None:
    """This step's landmark observations (``marks``: ids, ranges, bearings; None: none) as rays from the
    estimate, labelled with the ids. Call after ``log_step`` (it uses that step's time)."""
    rec = logger._live()
    if rec is None:
        return
    if marks is None or len(marks.ids) == 0:
        rec.log("world/landmarks/observed", rr.LineStrips2D(np.zeros((0, 2, 2), dtype=np.float32)))
        return
    seg = landmark_rays(logger.local(estimate), marks.ranges, marks.bearings).astype(np.float32)
    rec.log(
        "world/landmarks/observed",
        rr.LineStrips2D(
            list(seg),
            labels=[str(int(i)) for i in np.asarray(marks.ids)],
            colors=[_OBSERVED_COLOR],
            radii=rr.Radius.ui_points(1.0),
            draw_order=_DRAW_ORDER["scan"],
        ),
    )


def log_line_features(logger: RerunLogger, segments: np.ndarray) -> None:
    """This step's line features (``mcl.features``: (M, 2, 2) world-frame segments) at ``world/lines``.
    Call after ``log_step`` (it uses that step's time)."""
    rec = logger._live()
    if rec is None:
        return
    rec.log(
        "world/lines",
        rr.LineStrips2D(_less(np.reshape(segments, (-1, 2)), logger.offset).reshape(-1, 2, 2), colors=[[220, 40, 200]],
                        radii=rr.Radius.ui_points(2.0), draw_order=_DRAW_ORDER["scan"]),
    )


EXPLORE_FLUSH_S = 120.0  # s: the longest a motion-sample recording's write may take before it is given up


def recording_is_whole(path: str | os.PathLike) -> bool:
    """Whether the .rrd at ``path`` ends in its footer (rerun's reader finds its manifest): a file sink that failed
    while ending the stream leaves it without one."""
    import warnings

    try:
        from rerun.chunk import RrdReader
    except ImportError:  # no reader to ask
        return True
    try:
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            RrdReader(path).recordings()
    except Exception:
        return False
    # "RRD file has no footer/manifest" is a warning; another warning (a newer rerun's) says nothing of the end
    return not any("footer" in str(w.message).lower() or "manifest" in str(w.message).lower() for w in said)


def partial_recording(path: str | os.PathLike) -> Path:
    """Where a recording cut short (a full disk) is left: ``recording.partial.rrd`` for ``recording.rrd``. The
    Rerun viewer chooses its importer by the extension: ``recording.rrd.partial`` was "No importer support"."""
    path = Path(path)
    return path.with_name(f"{path.stem}.partial{path.suffix}")


def log_motion_samples(path: str | os.PathLike, pose: np.ndarray, panels: list) -> None:
    """Write samples of a motion model (``mcl explore motion``) to a Rerun recording at ``path``.

    panels: [(label, [cloud (3, N) per step])]. Each alpha setting goes under
    ``motion/<k>``, offset along x so the panels sit side by side; the
    start pose is ``motion/<k>/start``; one ``step`` per application.
    """
    path = Path(path)
    partial = path.with_name(path.name + ".partial")  # renamed when whole: a failed write keeps an earlier file
    rec = rr.RecordingStream("mcl_explore_motion", recording_id=str(uuid.uuid4()))
    rec.save(str(partial))
    allp = np.concatenate([c for _, clouds in panels for c in clouds], axis=1)
    span = float(max(np.ptp(allp[0]), np.ptp(allp[1]), 1e-3)) * 1.3
    # y up, as in a run's recording (a 2D view draws y down: a left turn showed as a right turn)
    rec.log("motion", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
    for k, (label, clouds) in enumerate(panels):
        dx = k * span
        rec.log(f"motion/{k}", rr.TextDocument(label), static=True)
        rec.log(f"motion/{k}/start", rr.Arrows2D(origins=[[pose[0] + dx, pose[1]]],
                                                 vectors=[[0.1 * span * np.cos(pose[2]), 0.1 * span * np.sin(pose[2])]],
                                                 colors=[[220, 0, 0]], labels=[label]), static=True)
        for j, c in enumerate(clouds):
            rec.set_time("step", sequence=j)
            rec.log(f"motion/{k}/samples", rr.Points2D(np.stack([c[0] + dx, c[1]], axis=1), radii=0.003 * span,
                                                       colors=[[40, 40, 160]]))
    try:
        rec.flush(timeout_sec=EXPLORE_FLUSH_S)  # a file sink that failed (a full disk) hung an untimed flush
        rec.disconnect()
    except RuntimeError as e:
        partial.unlink(missing_ok=True)
        raise OSError(errno.EIO, f"the recording could not be written ({e})", str(path)) from None
    if not partial.exists() or partial.stat().st_size == 0:
        partial.unlink(missing_ok=True)
        raise OSError(errno.EIO, "the recording could not be written", str(path))
    try:
        os.replace(partial, path)
    except OSError:
        partial.unlink(missing_ok=True)
        raise


# -- plane features (mcl.planes) ----------------------------------------------------------------
#   depth/cloud            Points3D per step: the depth cloud (at most 5,000 points) in the world frame at the
#                          estimate, coloured by the plane each point belongs to (grey: none)
#   depth/planes           Mesh3D per step: each extracted plane's boundary rectangle, as two triangles
#   world/planes/observed  LineStrips2D per step: the wall patches' horizontal extents at the estimate
#   world/planes/matched   LineStrips2D per step: the map faces they are associated with at the estimate

_PLANE_COLORS = np.array([[230, 25, 75], [60, 180, 75], [255, 225, 25], [0, 130, 200], [245, 130, 48],
                          [145, 30, 180], [70, 240, 240], [240, 50, 230]], dtype=np.uint8)


def _less(points: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """float32 (M, 2 or 3) points with their x, y less ``offset`` (the recording's frame)."""
    p = np.array(points, dtype=np.float64)
    p[:, :2] -= offset
    return p.astype(np.float32)


def log_planes(logger: RerunLogger, estimate: np.ndarray, sensor: Any, planes: Any, max_points: int = 5000) -> None:
    """This step's depth cloud, extracted planes (patches) and their matches (``sensor``: a
    mcl.planes.PlaneSensor whose ``last_cloud`` the planes came from). Call after ``log_step``."""
    from mcl.planes import associate, level_to_world

    rec = logger._live()
    if rec is None:
        return
    cam = sensor.camera
    cloud = sensor.last_cloud
    if cloud is not None and cloud.points.shape[0]:
        idx = subsample_indices(cloud.points.shape[0], max_points)
        lab = planes.labels[idx]
        colors = np.where(lab[:, None] >= 0, _PLANE_COLORS[np.maximum(lab, 0) % len(_PLANE_COLORS)], 150)
        rec.log("depth/cloud", rr.Points3D(_less(level_to_world(estimate, cam, cloud.points[idx]), logger.offset),
                                           colors=colors.astype(np.uint8), radii=0.01))
    k = len(planes)
    if k:
        verts = _less(level_to_world(estimate, cam, planes.corners.reshape(-1, 3)), logger.offset)
        tri = np.array([[4 * j, 4 * j + 1, 4 * j + 2] for j in range(k)] + [[4 * j, 4 * j + 2, 4 * j + 3]
                                                                           for j in range(k)], dtype=np.uint32)
        vcol = np.repeat(_PLANE_COLORS[np.arange(k) % len(_PLANE_COLORS)], 4, axis=0)
        rec.log("depth/planes", rr.Mesh3D(vertex_positions=verts, triangle_indices=tri, vertex_colors=vcol))
    else:
        rec.log("depth/planes", rr.Clear(recursive=False))
    model = sensor.model
    walls = planes.vertical(float(sensor.cfg.vertical_tol))
    seg_obs = [level_to_world(estimate, cam, planes.corners[j, :2])[:, :2] for j in walls]
    rec.log("world/planes/observed", rr.LineStrips2D([_less(s, logger.offset) for s in seg_obs],
                                                     colors=[[0, 200, 255]], radii=rr.Radius.ui_points(3.0),
                                                     draw_order=_DRAW_ORDER["scan"] + 1.0))
    match = associate(model, estimate, model.prepare(planes))
    faces = model.map.faces[match[match >= 0]]
    rec.log("world/planes/matched", rr.LineStrips2D([_less(f[3:7].reshape(2, 2), logger.offset) for f in faces],
                                                    colors=[[255, 255, 255]], radii=rr.Radius.ui_points(1.5),
                                                    draw_order=_DRAW_ORDER["scan"] + 0.5))
