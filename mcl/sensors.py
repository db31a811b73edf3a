"""Likelihood field range finder model (Prob. Rob. Table 6.3, likelihood_field_range_finder_model).

A scan is turned once into beam endpoints in the robot frame
(``beam_endpoints``); ``LikelihoodField.log_likelihood`` then scores N poses:

    log p(z | x, m) = exponent * sum_k log(z_hit * N(d_k; 0, sigma_hit^2) + z_rand / range_max)

where d_k = min(distance from endpoint k (seen from pose x) to the nearest
occupied cell centre, likelihood_max_dist). The per-cell term is tabulated
once per map as float32, so scoring is one rotation per particle and one
table gather per beam (``mcl.kernels.likelihood``).

* Endpoints that fall off the map score the value at d = likelihood_max_dist.
* Endpoints in unknown cells use the distance field like any other cell.
* Beams without a return (>= range_max, >= the scan's own max_range, NaN,
  inf, <= range_min) are skipped: the book's "if z_t^k != z_max".
* ``exponent`` (0 < e <= 1) tempers the product of beams, which treats the
  beams as independent and is overconfident; 1.0 is the plain product.
"""

from __future__ import annotations

import math

import numpy as np

from mcl.kernels.likelihood import likelihood_field_loglik


def beam_endpoints(ranges, angles, max_range, cfg, laser_pose=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(2, K) float64 endpoints, in the robot frame, of the valid beams of one scan.

    ranges, angles: (B,) readings (m) and beam angles in the laser frame (rad).
    max_range: the scan's own no-return value, or None.
    cfg: reads range_min, range_max, max_beams.
    laser_pose: (x, y, theta) of the laser in the robot frame.

    Subsampling follows AMCL: first up to ``max_beams`` beams evenly spaced
    over *all* B beams (indices round(linspace(0, B-1, max_beams))), then the
    invalid ones among them are dropped, so K <= max_beams and the chosen
    directions do not depend on which beams happen to have returns.
    A beam is valid when range_min < r < range_max, r < max_range (if
    given), and r is finite.
    """
    r = np.asarray(ranges, dtype=np.float64).ravel()
    a = np.asarray(angles, dtype=np.float64).ravel()
    if r.shape != a.shape:
        raise ValueError(f"ranges and angles differ in length: {r.size} vs {a.size}")
    b = r.size
    max_beams = int(cfg.max_beams)
    if max_beams < 1:
        raise ValueError(f"sensor.max_beams: must be >= 1, got {max_beams}")
    if b > max_beams:
        sel = np.unique(np.rint(np.linspace(0.0, b - 1, max_beams)).astype(np.int64))
        r, a = r[sel], a[sel]
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(r) & (r > float(cfg.range_min)) & (r < float(cfg.range_max))
        if max_range is not None:
            valid &= r < float(max_range)
    r, a = r[valid], a[valid]
    lx, ly, lth = (float(v) for v in laser_pose)
    ang = a + lth
    out = np.empty((2, r.size))
    out[0] = lx + r * np.cos(ang)
    out[1] = ly + r * np.sin(ang)
    return out


def scan_endpoints(scan, cfg, laser_pose=None) -> np.ndarray:
    """``beam_endpoints`` for a ``Scan`` record (ranges, angle_min, angle_increment, max_range, laser_offset).

    The laser pose is the argument if given, else ``cfg.laser_pose`` if set,
    else the scan's own ``laser_offset``, else the robot origin.
    """
    ranges = np.asarray(scan.ranges, dtype=np.float64)
    angles = getattr(scan, "angles", None)
    if angles is None:
        angles = float(scan.angle_min) + float(scan.angle_increment) * np.arange(ranges.size)
    if laser_pose is None:
        laser_pose = getattr(cfg, "laser_pose", None)
    if laser_pose is None:
        laser_pose = getattr(scan, "laser_offset", None)
    if laser_pose is None:
        laser_pose = (0.0, 0.0, 0.0)
    return beam_endpoints(ranges, angles, getattr(scan, "max_range", None), cfg, laser_pose)


def point_log_likelihood(d, cfg) -> np.ndarray:
    """log(z_hit * N(min(d, likelihood_max_dist); 0, sigma_hit^2) + z_rand / range_max), float64."""
    sigma = float(cfg.sigma_hit)
    d = np.minimum(np.asarray(d, dtype=np.float64), float(cfg.likelihood_max_dist))
    gauss = np.exp(-0.5 * (d / sigma) ** 2) / (math.sqrt(2.0 * math.pi) * sigma)
    with np.errstate(divide="ignore"):
        return np.log(float(cfg.z_hit) * gauss + float(cfg.z_rand) / float(cfg.range_max))


class LikelihoodField:
    """Likelihood field sensor model over an ``OccupancyGrid``.

    ``grid`` needs ``distance`` (float (H, W), metres to the nearest occupied
    cell centre, row 0 at the bottom), ``origin`` (x0, y0) and ``resolution``.
    ``cfg`` is read duck-typed: z_hit, z_rand, sigma_hit, likelihood_max_dist,
    range_max, exponent.
    """

    def __init__(self, grid, cfg):
        self.cfg = cfg
        self.table = np.ascontiguousarray(point_log_likelihood(grid.distance, cfg), dtype=np.float32)
        # off-map endpoints: the value at likelihood_max_dist (float32 like the table)
        self.offmap = float(np.float32(point_log_likelihood(float(cfg.likelihood_max_dist), cfg)))
        self.origin = (float(grid.origin[0]), float(grid.origin[1]))
        self.resolution = float(grid.resolution)
        self.inv_res = 1.0 / self.resolution
        self.exponent = float(getattr(cfg, "exponent", 1.0))

    def prepare(self, scan, laser_pose) -> np.ndarray:
        """The observation this model scores, made once per scan: robot-frame beam endpoints (2, K)."""
        return beam_endpoints(scan.ranges, scan.angles, scan.max_range, self.cfg, laser_pose)

    def log_likelihood(self, particles, endpoints, out=None) -> np.ndarray:
        """(N,) float64: exponent * sum over beams of the table value at each rotated endpoint.

        particles: (3, N) float64 world poses; endpoints: (2, K) robot-frame
        endpoints from ``beam_endpoints``. K = 0 gives zeros (no information).
        """
        p = np.ascontiguousarray(particles, dtype=np.float64)
        if p.ndim != 2 or p.shape[0] != 3:
            raise ValueError(f"particles: expected shape (3, N), got {p.shape}")
        e = np.asarray(endpoints, dtype=np.float64)
        if e.ndim != 2 or e.shape[0] != 2:
            raise ValueError(f"endpoints: expected shape (2, K), got {e.shape}")
        e_cells = np.ascontiguousarray(e * self.inv_res)
        if out is None:
            out = np.empty(p.shape[1])
        likelihood_field_loglik(p, e_cells, self.table, self.origin[0], self.origin[1],
                                self.inv_res, self.offmap, self.exponent, out)
        return out


def make_sensor_model(grid, cfg):
    """The range sensor model named by ``sensor.model``."""
    if cfg.model == "likelihood_field":
        return LikelihoodField(grid, cfg)
    raise ValueError(f"sensor.model: unknown model {cfg.model!r}")
