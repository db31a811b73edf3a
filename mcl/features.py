"""Line features from a laser scan: split-and-merge, polar TLS fit, propagated covariance.

Seed 003, "Laser Scanner Features (Line)" (Siegwart & Nourbakhsh, *Introduction to
Autonomous Mobile Robots*, sec. 4.7 / 5.6). A line is ``x cos(alpha) + y sin(alpha) = r``
in the sensor frame, with ``r >= 0`` and ``alpha`` in (-pi, pi]. Each beam gives a
point ``(rho_i cos theta_i, rho_i sin theta_i)``; only the range ``rho_i`` is noisy
(variance ``sigma_r**2``, independent), the beam angles ``theta_i`` are exact.

Pipeline (:func:`extract_lines`):

1. valid beams only (finite, > 0, below ``max_range``), in beam order; a new chain
   starts wherever two consecutive valid points are more than ``max_gap`` apart.
   In a 360-degree scan the last beam's point may continue the first beam's chain.
2. split: recursively cut a chain at the point farthest from the chord joining its
   first and last point while that distance exceeds ``split_threshold``;
3. merge: join neighbouring segments of one chain while the total-least-squares
   line through their union has every point within ``merge_threshold``;
4. boundary refinement: a point at the border of two touching segments goes to the
   line it is nearer to (the farthest-from-chord split point at a corner can land
   on the wrong side, and one point off a wall biases that wall's fit);
5. drop segments with fewer than ``min_points`` points, fit the rest.

Fit (seed, closed form, with ``xbar, ybar`` the centroid of the segment):

    alpha = 1/2 atan2(-2 sum (ybar - y_i)(xbar - x_i), sum (ybar - y_i)^2 - (xbar - x_i)^2)
    r     = xbar cos(alpha) + ybar sin(alpha)      (then r < 0 -> r = -r, alpha += pi)

Covariance (seed): ``P_alpha_r = sum_i J_i sigma_rho_i^2 J_i^T`` with
``J_i = [d alpha / d rho_i, d r / d rho_i]``. The seed names these partial
derivatives but does not write them out, so they are derived here for the same
closed form (``tests/test_features.py`` checks them against finite differences).
With ``c_i = cos theta_i``, ``s_i = sin theta_i``, ``dx_i = x_i - xbar``,
``dy_i = y_i - ybar``, ``N = -2 Sxy``, ``D = Syy - Sxx`` (``Sxy = sum dx dy`` etc.):

    dSxx/drho_i = 2 c_i dx_i,  dSyy/drho_i = 2 s_i dy_i,  dSxy/drho_i = c_i dy_i + s_i dx_i
    (the centroid terms vanish because sum dx = sum dy = 0)
    d alpha/drho_i = 1/2 (D dN_i - N dD_i) / (N^2 + D^2)
    d r/drho_i     = cos(theta_i - alpha) / n + (ybar cos alpha - xbar sin alpha) d alpha/drho_i

(the second is evaluated with the final, sign-corrected alpha, so the r >= 0 flip
needs no special case). ``N^2 + D^2 = (lambda_1 - lambda_2)^2`` for the eigenvalues of
the points' scatter matrix: it is zero when the points have no preferred direction
(all identical, or an isotropic cloud). Such a segment has no line:
:func:`fit_line` returns None and :func:`extract_lines` leaves it out. Two distinct
points give their exact line with a finite covariance.

No rerun here: :func:`line_segments_world` returns ``(M, 2, 2)`` endpoint pairs that
``mcl.viz`` can pass to ``rr.LineStrips2D``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mcl.errors import ConfigError

__all__ = [
    "LineConfig",
    "Lines",
    "extract_lines",
    "extract_scan_lines",
    "fit_line",
    "line_jacobian",
    "split_and_merge",
    "lines_to_world",
    "line_segments_world",
]

# Relative size of |lambda_1 - lambda_2| / (lambda_1 + lambda_2) below which a point set
# has no direction (see the module docstring); points spread less than 1e-9 of their
# distance from the sensor count as identical.
_DEGENERATE = 1e-9


@dataclass(frozen=True, slots=True, kw_only=True)
class LineConfig:
    """Split-and-merge line extraction (Siegwart & Nourbakhsh sec. 4.7.1.4; seed 003)."""

    split_threshold: float = 0.05  # m: split while a point is farther than this from the chord
    merge_threshold: float = 0.05  # m: merge neighbours while their joint TLS line fits every point this well
    min_points: int = 8  # segments with fewer points are dropped (>= 2)
    max_gap: float = 0.3  # m: consecutive points farther apart start a new segment
    sigma_r: float = 0.01  # m: range noise std (independent per beam), for P_alpha_r

    def __post_init__(self) -> None:
        for key in ("split_threshold", "merge_threshold", "max_gap", "sigma_r"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"lines.{key}: {v!r} is out of range (must be a finite number > 0)")
        if not isinstance(self.min_points, int) or isinstance(self.min_points, bool) or self.min_points < 2:
            raise ConfigError(f"lines.min_points: {self.min_points!r} is out of range (must be an integer >= 2)")


@dataclass(frozen=True, slots=True, eq=False)
class Lines:
    """M lines in one frame (the sensor's, or the world's after :func:`lines_to_world`).

    ``alpha (M,)`` in (-pi, pi], ``r (M,) >= 0``, ``cov (M, 2, 2)`` the covariance of
    (alpha, r), ``endpoints (M, 2, 2)`` = [line, end, (x, y)] the first and last point
    of the segment projected onto the line, ``beams`` the indices (into the scan's
    ranges) of the beams each line was fitted to, ``rms (M,)`` the root mean square
    orthogonal distance of those points to the line (m).
    """

    alpha: np.ndarray
    r: np.ndarray
    cov: np.ndarray
    endpoints: np.ndarray
    beams: tuple[np.ndarray, ...]
    rms: np.ndarray

    def __len__(self) -> int:
        return int(self.alpha.shape[0])

    @property
    def sigma(self) -> np.ndarray:
        """(M, 2) standard deviations of alpha and r."""
        return np.sqrt(np.stack([self.cov[:, 0, 0], self.cov[:, 1, 1]], axis=1))

    @property
    def length(self) -> np.ndarray:
        """(M,) segment lengths (m)."""
        return np.hypot(*(self.endpoints[:, 1] - self.endpoints[:, 0]).T)

    @staticmethod
    def empty() -> Lines:
        return Lines(np.zeros(0), np.zeros(0), np.zeros((0, 2, 2)), np.zeros((0, 2, 2)), (), np.zeros(0))


# ----------------------------------------------------------------------------- fit


def _wrap(a: float) -> float:
    """Angle in (-pi, pi]."""
    a = math.remainder(a, 2.0 * math.pi)
    return math.pi if a == -math.pi else a


def _tls(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float, float, float, float] | None:
    """Seed closed form on Cartesian points -> (alpha, r, xbar, ybar, N, D), or None if degenerate."""
    xm, ym = x.mean(), y.mean()
    dx, dy = x - xm, y - ym
    sxx, syy, sxy = dx @ dx, dy @ dy, dx @ dy
    num, den = -2.0 * sxy, syy - sxx
    # points spread less than ~1e-9 of their distance (rounding of the centroid) or no direction
    scale = max(1.0, abs(xm), abs(ym))
    if not (sxx + syy > x.shape[0] * (1e-9 * scale) ** 2 and math.hypot(num, den) > _DEGENERATE * (sxx + syy)):
        return None  # the negated form also catches NaN
    alpha = 0.5 * math.atan2(num, den)
    r = xm * math.cos(alpha) + ym * math.sin(alpha)
    if r < 0.0:
        r, alpha = -r, alpha + math.pi
    return _wrap(alpha), r, xm, ym, num, den


def _max_dist(x: np.ndarray, y: np.ndarray) -> float:
    """Largest orthogonal distance of the points to their TLS line (inf if there is none)."""
    f = _tls(x, y)
    if f is None:
        return 0.0 if np.ptp(x) == 0.0 and np.ptp(y) == 0.0 else math.inf
    alpha, r = f[0], f[1]
    return float(np.max(np.abs(x * math.cos(alpha) + y * math.sin(alpha) - r)))


def line_jacobian(rho: np.ndarray, theta: np.ndarray) -> tuple[float, float, np.ndarray] | None:
    """(alpha, r, J) with J (2, n) = [d alpha/d rho_i; d r/d rho_i], or None if degenerate."""
    rho = np.asarray(rho, dtype=np.float64)
    theta = np.asarray(theta, dtype=np.float64)
    c, s = np.cos(theta), np.sin(theta)
    x, y = rho * c, rho * s
    f = _tls(x, y)
    if f is None:
        return None
    alpha, r, xm, ym, num, den = f
    dx, dy = x - xm, y - ym
    d_num = -2.0 * (c * dy + s * dx)
    d_den = 2.0 * (s * dy - c * dx)
    d_alpha = 0.5 * (den * d_num - num * d_den) / (num * num + den * den)
    ca, sa = math.cos(alpha), math.sin(alpha)
    d_r = (c * ca + s * sa) / rho.shape[0] + (ym * ca - xm * sa) * d_alpha
    return alpha, r, np.stack([d_alpha, d_r])


def fit_line(rho: np.ndarray, theta: np.ndarray, sigma_r: float) -> tuple[float, float, np.ndarray] | None:
    """TLS line (alpha, r) through beams (rho_i, theta_i) and its 2x2 covariance P_alpha_r.

    None when the points have no direction (all identical, fewer than 2, or isotropic).
    """
    if np.shape(rho)[0] < 2:
        return None
    res = line_jacobian(rho, theta)
    if res is None:
        return None
    alpha, r, jac = res
    return alpha, r, (sigma_r * sigma_r) * (jac @ jac.T)


# ----------------------------------------------------------------------------- segmentation


def _split(x: np.ndarray, y: np.ndarray, a: int, b: int, thr: float, out: list[int]) -> None:
    """Append split indices of points [a, b) (iterative, left to right) to `out`."""
    stack = [(a, b)]
    cuts: list[int] = []
    while stack:
        lo, hi = stack.pop()
        if hi - lo < 3:
            continue
        x0, y0, x1, y1 = x[lo], y[lo], x[hi - 1], y[hi - 1]
        ex, ey = x1 - x0, y1 - y0
        norm = math.hypot(ex, ey)
        px, py = x[lo + 1 : hi - 1] - x0, y[lo + 1 : hi - 1] - y0
        d = np.abs(px * ey - py * ex) / norm if norm > 0.0 else np.hypot(px, py)
        k = int(np.argmax(d))
        if d[k] > thr:
            m = lo + 1 + k  # the farthest point starts the right part; refinement may move it
            cuts.append(m)
            stack.append((lo, m + 1))  # left chord ends at the split point
            stack.append((m, hi))
    out.extend(sorted(cuts))


def split_and_merge(x: np.ndarray, y: np.ndarray, cfg: LineConfig) -> list[tuple[int, int]]:
    """Segments [start, stop) of the points (in scan order), before the min_points filter."""
    n = x.shape[0]
    if n == 0:
        return []
    gaps = np.flatnonzero(np.hypot(np.diff(x), np.diff(y)) > cfg.max_gap) + 1
    chain_bounds = np.concatenate([[0], gaps, [n]])
    segments: list[tuple[int, int]] = []
    for a, b in zip(chain_bounds[:-1].tolist(), chain_bounds[1:].tolist()):
        cuts: list[int] = []
        _split(x, y, a, b, cfg.split_threshold, cuts)
        bounds = [a, *cuts, b]
        segs = [(bounds[i], bounds[i + 1]) for i in range(len(bounds) - 1)]
        # merge collinear neighbours (greedy, left to right)
        merged = [segs[0]]
        for s in segs[1:]:
            lo, _ = merged[-1]
            if _max_dist(x[lo : s[1]], y[lo : s[1]]) <= cfg.merge_threshold:
                merged[-1] = (lo, s[1])
            else:
                merged.append(s)
        segments.extend(_refine(x, y, merged))
    return segments


def _dist(x: float, y: float, f: tuple | None) -> float:
    if f is None:
        return math.inf
    return abs(x * math.cos(f[0]) + y * math.sin(f[0]) - f[1])


def _refine(x: np.ndarray, y: np.ndarray, segs: list[tuple[int, int]], max_moves: int = 4) -> list[tuple[int, int]]:
    """Move each border point between touching segments to the line it is nearer to."""
    bounds = [segs[0][0]] + [s[1] for s in segs]
    for j in range(1, len(bounds) - 1):
        for _ in range(max_moves):
            lo, m, hi = bounds[j - 1], bounds[j], bounds[j + 1]
            if m - lo < 3 or hi - m < 3:
                break
            fl, fr = _tls(x[lo:m], y[lo:m]), _tls(x[m:hi], y[m:hi])
            if _dist(x[m - 1], y[m - 1], fr) < _dist(x[m - 1], y[m - 1], fl):
                bounds[j] = m - 1
            elif _dist(x[m], y[m], fl) < _dist(x[m], y[m], fr):
                bounds[j] = m + 1
            else:
                break
    return [(bounds[i], bounds[i + 1]) for i in range(len(bounds) - 1)]


# ----------------------------------------------------------------------------- extraction


def extract_lines(
    ranges: np.ndarray, angles: np.ndarray, cfg: LineConfig = LineConfig(), max_range: float | None = None
) -> Lines:
    """Lines (sensor frame) in one scan: beams ``ranges (n,)`` at ``angles (n,)`` (rad).

    Beams that are not finite, <= 0, or >= ``max_range`` (if given) are skipped.
    """
    ranges = np.asarray(ranges, dtype=np.float64)
    angles = np.asarray(angles, dtype=np.float64)
    if ranges.shape != angles.shape or ranges.ndim != 1:
        raise ValueError(f"ranges {ranges.shape} and angles {angles.shape} must be equal 1-D shapes")
    ok = np.isfinite(ranges) & np.isfinite(angles) & (ranges > 0.0)
    if max_range is not None:
        ok &= ranges < max_range
    idx = np.flatnonzero(ok)
    rho, theta = ranges[idx], angles[idx]
    c, s = np.cos(theta), np.sin(theta)
    x, y = rho * c, rho * s
    if idx.shape[0] > 2 and _full_circle(angles):
        # a 360-degree scan: start at a gap (or, in a closed loop, at the farthest point,
        # usually a corner) so that a wall seen across the last-to-first beam stays one piece
        gaps = np.hypot(np.diff(x, append=x[0]), np.diff(y, append=y[0])) > cfg.max_gap
        start = (int(np.argmax(gaps)) + 1) % idx.shape[0] if gaps.any() else int(np.argmax(rho))
        if start:
            idx, rho, theta, x, y = (np.roll(v, -start) for v in (idx, rho, theta, x, y))

    alphas, rs, covs, ends, beams, rms = [], [], [], [], [], []
    for a, b in split_and_merge(x, y, cfg):
        if b - a < cfg.min_points:
            continue
        fit = fit_line(rho[a:b], theta[a:b], cfg.sigma_r)
        if fit is None:
            continue
        alpha, r, cov = fit
        ca, sa = math.cos(alpha), math.sin(alpha)
        resid = x[a:b] * ca + y[a:b] * sa - r
        p = np.array([[x[a], y[a]], [x[b - 1], y[b - 1]]])
        p -= np.outer(p @ np.array([ca, sa]) - r, [ca, sa])  # project onto the line
        alphas.append(alpha)
        rs.append(r)
        covs.append(cov)
        ends.append(p)
        beams.append(idx[a:b])
        rms.append(math.sqrt(float(resid @ resid) / (b - a)))
    if not alphas:
        return Lines.empty()
    return Lines(np.array(alphas), np.array(rs), np.array(covs), np.array(ends), tuple(beams), np.array(rms))


def _full_circle(angles: np.ndarray) -> bool:
    """Do the beams cover the whole circle (the last beam is the first's neighbour)?"""
    n = angles.shape[0]
    if n < 3:
        return False
    step = float(np.median(np.diff(angles)))
    return step != 0.0 and abs(n * abs(step) - 2.0 * math.pi) < 0.5 * abs(step)


def extract_scan_lines(scan, cfg: LineConfig = LineConfig(), max_range: float | None = None) -> Lines:
    """:func:`extract_lines` on a :class:`mcl.datasets.carmen.Scan` (sensor frame).

    ``max_range`` defaults to the scan's own (None in FLASER: then only non-finite and
    non-positive ranges are skipped; pass the config's ``sensor.range_max``).
    """
    if max_range is None:
        max_range = scan.max_range
    return extract_lines(scan.ranges, scan.angles, cfg, max_range)


# ----------------------------------------------------------------------------- frames


def _compose(pose: np.ndarray, laser_offset: np.ndarray | None) -> tuple[float, float, float]:
    px, py, pt = (float(v) for v in np.asarray(pose, dtype=np.float64).reshape(3))
    if laser_offset is None:
        return px, py, pt
    ox, oy, ot = (float(v) for v in np.asarray(laser_offset, dtype=np.float64).reshape(3))
    c, s = math.cos(pt), math.sin(pt)
    return px + c * ox - s * oy, py + s * ox + c * oy, pt + ot


def lines_to_world(lines: Lines, pose: np.ndarray, laser_offset: np.ndarray | None = None) -> Lines:
    """The same lines in the world frame, seen from robot ``pose`` (x, y, theta).

    ``laser_offset`` is the laser's mounting in the robot frame (None: the pose is
    the sensor's). The pose is taken as exact: the covariance is mapped through the
    Jacobian of ``alpha_w = alpha + theta``, ``r_w = r + x cos alpha_w + y sin alpha_w``
    (and the sign flip that keeps ``r_w >= 0``).
    """
    if len(lines) == 0:
        return lines
    px, py, pt = _compose(pose, laser_offset)
    aw = lines.alpha + pt
    rw = lines.r + px * np.cos(aw) + py * np.sin(aw)
    jac = np.zeros((len(lines), 2, 2))
    jac[:, 0, 0] = 1.0
    jac[:, 1, 1] = 1.0
    jac[:, 1, 0] = -px * np.sin(aw) + py * np.cos(aw)
    flip = rw < 0.0
    rw = np.where(flip, -rw, rw)
    aw = np.where(flip, aw + np.pi, aw)
    jac[flip, 1, :] *= -1.0
    aw = np.array([_wrap(a) for a in aw])
    cov = jac @ lines.cov @ np.transpose(jac, (0, 2, 1))
    return Lines(aw, rw, cov, line_segments_world(lines, (px, py, pt)), lines.beams, lines.rms)


def line_segments_world(lines: Lines, pose: np.ndarray, laser_offset: np.ndarray | None = None) -> np.ndarray:
    """(M, 2, 2) segment endpoints in the world frame, for ``rr.LineStrips2D``.

    ``pose`` is the robot's (x, y, theta); ``laser_offset`` its laser mounting (None:
    the pose is the sensor's).
    """
    px, py, pt = _compose(pose, laser_offset)
    c, s = math.cos(pt), math.sin(pt)
    rot = np.array([[c, -s], [s, c]])
    return lines.endpoints @ rot.T + np.array([px, py])
