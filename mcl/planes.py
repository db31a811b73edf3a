"""Plane features from a depth camera (seed 003, "Kinect Features (Plane)") as a sensor for MCL.

A plane is ``p_x sin(theta) cos(phi) + p_y sin(theta) sin(phi) + p_z cos(theta) = rho`` with ``rho >= 0``
(the normal points from the camera to the plane), in the camera's **level frame**: origin at the camera
centre, axes those of the robot base (x forward, y left, z up). A vertical wall has theta = pi/2, phi the
bearing of its normal from the robot's heading and rho the camera's distance to it; the floor has theta =
pi and rho the camera's height.

Camera (:class:`DepthCamera`): a pinhole depth image (Kinect-like: 640 x 480, 57 x 43 degrees, 0.5-4.5 m)
mounted at ``mount = (x, y, z, roll, pitch, yaw)`` on the robot. Depth noise is axial (along the optical
axis), sigma_z(z) = sigma_a + sigma_b (z - z0)^2 (Nguyen, Izadi & Lovell 2012: 0.0012 + 0.0019 (z - 0.4)^2),
plus the depth's quantization (q^2 / 12); a point is ``z (x_n, y_n, 1)`` so its noise lies along its ray.

Extraction (:func:`extract_planes`), the seed's loop::

    Do until DetectedPlanes < 8 and TotalPoints > MinPoints
        randomly select (P1, P2, P3) from a random circular region; calculate the plane;
        transform it to Hough space; if a local maximum is found: delete the points of that plane,
        calculate its boundaries, reset Hough space

Taken literally ("until" both hold) the loop would stop at once: it starts with 0 < 8 planes and all the
points. Its evident intent is *while* DetectedPlanes < max_planes (8) *and* the points left > min_points,
which is what runs here, with a trial budget (``max_trials``) so a cloud with no plane ends. The random
circular region is a disk of ``region_px`` pixels of the (subsampled) image around P1; the Hough space is
a (theta, phi, rho) accumulator (one phi cell at the poles, where phi is undefined); a local maximum is a
cell reaching ``votes`` votes (the randomized Hough transform's threshold, Xu & Oja 1993; Borrmann et al.
2011). Its plane is refined on the points near it (weighted total least squares). ``method: ransac`` runs a
plain sequential RANSAC instead on the same points.

Each plane then gets its final inliers: the points within ``k_sigma`` of their residual std
s_i = sigma_z(z_i) |n . d_i| (d_i the pixel's ray at unit depth, z_i = rho / (n . d_i) the depth the plane
predicts: the measured depth would favour the points the noise moved nearer), leaving out points as near
another detected plane (a wall's foot on the floor), points whose depth on the plane is within k_sigma
depth stds of the camera's range limits (there the noise decides which readings exist) and a border of
``erode`` pixels (a neighbouring surface's points within k_sigma lie there). Its fit is the maximum
likelihood under depth noise: Gauss-Newton on the depth residuals (z_i - rho / (n . d_i)) / sigma_z from
the weighted total-least-squares plane, which ray-direction noise biases by about a third of a std on a
15,000-point wall. Its covariance is ``C = (sum_i J_i J_i^T)^-1``, J_i = (rho n_theta . d_i, rho n_phi . d_i,
-(n . d_i)) / ((n . d_i)^2 sigma_z(z_i)) (at the poles phi's variance is inf), and its boundary is the
inliers' extent along the plane's horizontal and in-plane vertical axes: a rectangle patch.

Measurement model (:class:`PlaneModel`), like the landmark model (Prob. Rob. Table 6.4 with the lecture's
false-positive mixture): each observed vertical plane (|theta - pi/2| < ``vertical_tol``) is associated,
for each particle, with the map face nearest in Mahalanobis distance of (phi, rho) among the faces the
camera is in front of whose extent holds the observed patch's centre; within ``gate``::

    p(z | x, m) = z_det N((phi, rho) - (phi_hat, rho_hat); S) + z_fp / (2 pi range_max),
    S = C_(phi, rho) + diag(sigma_phi^2, sigma_rho^2)

and beyond the gate only the false-positive term. Observations are independent: log-likelihoods add.

Plane map (:class:`PlaneMap`): vertical faces ``n . x = d`` (n the unit normal pointing into free space)
with a horizontal extent a -> b, from the occupancy grid (:meth:`PlaneMap.from_grid`: the runs of cell
edges between occupied and free cells, exact for rectilinear maps; a diagonal wall becomes a staircase) or
from a YAML file (:func:`load_plane_map`)::

    planes:
      - {x0: 0.0, y0: 0.0, x1: 5.0, y1: 0.0}    # free space to the left of (x0, y0) -> (x1, y1)
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mcl.errors import DataError
from mcl.yamlfile import finite_number, read_yaml

__all__ = [
    "DepthCamera", "Cloud", "Planes", "PlaneMap", "PlaneModel", "DepthFrame",
    "cloud_from_depth", "extract_planes", "angles_of", "normal_of",
    "load_plane_map", "save_plane_map", "load_depth_folder", "read_depth_frame", "write_depth_frame",
    "rotation_rpy",
]

CAMERA_FILE = "camera.yaml"


def rotation_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw),
                              math.sin(yaw))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


# optical frame (x right, y down, z forward) in a body frame (x forward, y left, z up)
_BODY_FROM_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


FOV_MAX = math.radians(170.0)  # rad: a pinhole camera's widest field of view taken


@dataclass(frozen=True, slots=True, kw_only=True)
class DepthCamera:
    """A pinhole depth camera and its mounting pose on the robot (Kinect v1 defaults)."""

    width: int = 640
    height: int = 480
    fov_x: float = math.radians(57.0)
    fov_y: float = math.radians(43.0)
    z_min: float = 0.5  # m: no reading nearer
    z_max: float = 4.5  # m: no reading farther
    sigma_a: float = 0.0012  # sigma_z(z) = sigma_a + sigma_b (z - z0)^2 (m)
    sigma_b: float = 0.0019
    z0: float = 0.4
    quantization: float = 0.001  # m: depth stored as whole millimetres
    p_dropout: float = 0.02  # probability a pixel has no reading
    mount: tuple[float, float, float, float, float, float] = (0.1, 0.0, 0.6, 0.0, 0.0, 0.0)  # x y z roll pitch yaw

    @property
    def fx(self) -> float:
        return 0.5 * self.width / math.tan(0.5 * self.fov_x)

    @property
    def fy(self) -> float:
        return 0.5 * self.height / math.tan(0.5 * self.fov_y)

    @property
    def level_from_optical(self) -> np.ndarray:
        """Rotation of the optical frame into the level frame (robot axes)."""
        r, p, y = self.mount[3:]
        return rotation_rpy(r, p, y) @ _BODY_FROM_OPTICAL

    def sigma_depth(self, z) -> np.ndarray:
        """Std (m) of a depth reading at depth z: the axial noise and the quantization."""
        z = np.asarray(z, dtype=np.float64)
        s = self.sigma_a + self.sigma_b * (z - self.z0) ** 2
        return np.sqrt(s * s + self.quantization ** 2 / 12.0)

    def to_dict(self) -> dict:
        return {"width": self.width, "height": self.height, "fov_x": self.fov_x, "fov_y": self.fov_y,
                "z_min": self.z_min, "z_max": self.z_max, "sigma_a": self.sigma_a, "sigma_b": self.sigma_b,
                "z0": self.z0, "quantization": self.quantization, "p_dropout": self.p_dropout,
                "mount": [float(v) for v in self.mount]}

    @classmethod
    def from_dict(cls, d, where: str) -> "DepthCamera":
        if not isinstance(d, dict):
            raise DataError(f"{where}: expected a mapping of camera parameters")
        names = set(cls.__dataclass_fields__)
        kw = {}
        for k, v in d.items():
            if k not in names:
                raise DataError(f"{where}: {k}: unknown key (expected {', '.join(sorted(names))})")
            if k == "mount":
                if not isinstance(v, list) or len(v) != 6:
                    raise DataError(f"{where}: mount: expected [x, y, z, roll, pitch, yaw]")
                kw[k] = tuple(finite_number(x, f"{where}: mount", DataError) for x in v)
            elif k in ("width", "height"):
                if isinstance(v, bool) or not isinstance(v, int) or v < 2:
                    raise DataError(f"{where}: {k}: expected an integer >= 2, got {v!r}")
                kw[k] = v
            else:
                kw[k] = finite_number(v, f"{where}: {k}", DataError)
        cam = cls(**kw)
        # values that made a run predict only (no plane in any frame) or a traceback, without a word
        for k in ("fov_x", "fov_y"):  # a pinhole's: near pi, tan(fov / 2) puts every pixel at infinity
            if not 0.0 < getattr(cam, k) <= FOV_MAX:
                raise DataError(f"{where}: {k}: expected an angle in (0, {FOV_MAX:.3f}] rad (170 degrees), got "
                                f"{getattr(cam, k)!r}")
        if not 0.0 <= cam.z_min < cam.z_max:
            raise DataError(f"{where}: z_min: expected 0 <= z_min < z_max, got {cam.z_min!r} and {cam.z_max!r}")
        for k in ("sigma_a", "sigma_b", "quantization"):
            if getattr(cam, k) < 0.0 or (k == "quantization" and cam.quantization == 0.0):
                raise DataError(f"{where}: {k}: expected a number {'> 0' if k == 'quantization' else '>= 0'}, got "
                                f"{getattr(cam, k)!r}")
        if not 0.0 <= cam.p_dropout <= 1.0:
            raise DataError(f"{where}: p_dropout: expected a probability in [0, 1], got {cam.p_dropout!r}")
        return cam


# ----------------------------------------------------------------------------- clouds


@dataclass(frozen=True, eq=False)
class Cloud:
    """Points of a depth image in the level frame: ``points`` (M, 3), their ``depth`` (M,), ``rays`` (M, 3)
    = points / depth (the pixel's ray at optical z = 1), ``pix`` (M, 2) their (row, col) in the subsampled
    image, ``grid`` (H', W') point index or -1, ``noise`` the camera's (sigma_a, sigma_b, z0, q^2 / 12)."""

    points: np.ndarray
    depth: np.ndarray
    rays: np.ndarray
    pix: np.ndarray
    grid: np.ndarray
    noise: np.ndarray
    z_range: tuple[float, float] = (0.0, math.inf)  # the camera's z_min, z_max


def cloud_from_depth(depth: np.ndarray, cam: DepthCamera, stride: int = 1) -> Cloud:
    """The points of a depth image (m, 0 or NaN: no reading), every ``stride``-th row and column."""
    d = np.asarray(depth, dtype=np.float64)[::stride, ::stride]
    h, w = d.shape
    v = np.arange(0, cam.height, stride)[:h] + 0.5
    u = np.arange(0, cam.width, stride)[:w] + 0.5
    ok = np.isfinite(d) & (d >= cam.z_min) & (d <= cam.z_max)
    rows, cols = np.nonzero(ok)
    z = d[rows, cols]
    xn = (u[cols] - 0.5 * cam.width) / cam.fx
    yn = (v[rows] - 0.5 * cam.height) / cam.fy
    opt = np.stack([xn * z, yn * z, z], axis=1)
    pts = np.ascontiguousarray(opt @ cam.level_from_optical.T)
    grid = np.full((h, w), -1, dtype=np.int64)
    grid[rows, cols] = np.arange(rows.size)
    noise = np.array([cam.sigma_a, cam.sigma_b, cam.z0, cam.quantization ** 2 / 12.0])
    return Cloud(pts, z, np.ascontiguousarray(pts / z[:, None]), np.ascontiguousarray(np.stack([rows, cols], axis=1)),
                 grid, noise, (float(cam.z_min), float(cam.z_max)))


# ----------------------------------------------------------------------------- planes


def normal_of(theta, phi) -> np.ndarray:
    """(..., 3) unit normals of (theta, phi)."""
    theta = np.asarray(theta, dtype=np.float64)
    phi = np.asarray(phi, dtype=np.float64)
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)


def angles_of(n) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) of unit normals (..., 3)."""
    n = np.asarray(n, dtype=np.float64)
    return np.arccos(np.clip(n[..., 2], -1.0, 1.0)), np.arctan2(n[..., 1], n[..., 0])


@dataclass(eq=False)
class Planes:
    """Planes found in one cloud (K of them), in the level frame.

    ``theta, phi, rho`` (K,); ``normal`` (K, 3); ``cov`` (K, 3, 3) of (theta, phi, rho); ``inliers`` (K,)
    point counts; ``corners`` (K, 4, 3) the boundary rectangle; ``centre`` (K, 3) its centre; ``labels``
    (M,) the plane of each cloud point (-1: none); ``trials`` used and ``seconds`` taken.
    """

    theta: np.ndarray
    phi: np.ndarray
    rho: np.ndarray
    normal: np.ndarray
    cov: np.ndarray
    inliers: np.ndarray
    corners: np.ndarray
    centre: np.ndarray
    labels: np.ndarray
    trials: int = 0
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.rho.size)

    def vertical(self, tol: float) -> np.ndarray:
        """Indices of the planes within ``tol`` rad of vertical (walls)."""
        return np.flatnonzero(np.abs(self.theta - 0.5 * math.pi) < tol)


def _plane_axes(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two in-plane unit axes: the horizontal one first (any, at the poles), then n x h."""
    h = np.array([-n[1], n[0], 0.0])
    if np.linalg.norm(h) < 1e-6:
        h = np.array([1.0, 0.0, 0.0])
    h /= np.linalg.norm(h)
    return h, np.cross(n, h)


def _invert_info(info: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Covariance from the information matrix of (theta, phi, rho); at the poles phi has none (inf). None
    when the points do not determine the plane (all on one line)."""
    try:
        if math.hypot(n[0], n[1]) < 1e-6:
            cov = np.zeros((3, 3))
            cov[np.ix_([0, 2], [0, 2])] = np.linalg.inv(info[np.ix_([0, 2], [0, 2])])
            cov[1, 1] = np.inf
            return cov
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return None
    return cov if np.all(np.isfinite(cov)) and np.all(np.diag(cov) > 0) else None


def _finish(cloud: Cloud, raw: np.ndarray, k_sigma: float, erode: int) -> tuple[list, np.ndarray]:
    """Final inliers and fit (mcl.kernels.planes.finish_planes), covariance and boundary of each plane."""
    from mcl.kernels.planes import depth_fit, finish_planes

    pts = cloud.points
    labels = np.full(pts.shape[0], -1, dtype=np.int64)
    k = raw.shape[0]
    if k == 0:
        return [], labels
    planes = np.ascontiguousarray(raw)
    # the depths inside the range by k_sigma depth stds (kernel docstring)
    z_lo, z_hi = cloud.z_range
    a, b, z0, q2 = cloud.noise
    z_lo = z_lo + k_sigma * math.sqrt((a + b * (z_lo - z0) ** 2) ** 2 + q2) if z_lo > 0 else 0.0
    z_hi = z_hi - k_sigma * math.sqrt((a + b * (z_hi - z0) ** 2) ** 2 + q2) if math.isfinite(z_hi) else math.inf
    finish_planes(pts, cloud.rays, cloud.noise, cloud.pix, cloud.grid, planes, k_sigma, int(erode), z_lo, z_hi,
                  labels)
    out = []
    for j in range(k):
        idx = np.flatnonzero(labels == j)
        # Maximum likelihood under depth noise (mcl.kernels.planes.depth_fit): the noise lies along each
        # point's ray, not along the normal, so the total-least-squares plane, even weighted, is biased by
        # O(sigma^2) per point (its expected cost's term sum w_i sigma_i^2 (n . d_i)^2 depends on n and
        # tilts it); that bias does not shrink with the number of points while the std does (about a
        # third of a std on a 15,000-point wall before this step).
        info = np.zeros((3, 3))
        ok = idx.size >= 3 and depth_fit(cloud.depth, cloud.rays, idx, idx.size, cloud.noise, planes[j], 3, info)
        cov = _invert_info(info, planes[j, :3]) if ok else None
        if cov is None:  # dropped (fewer than min_inliers)
            labels[idx] = -1
            out.append((planes[j, :3].copy(), planes[j, 3], np.full((3, 3), np.inf), 0, np.zeros((4, 3)),
                        np.zeros(3)))
            continue
        if planes[j, 3] < 0:
            planes[j] = -planes[j]
        n, rho = planes[j, :3], planes[j, 3]
        h, v = _plane_axes(n)
        a = pts[idx] @ h
        b = pts[idx] @ v
        a0, a1, b0, b1 = a.min(), a.max(), b.min(), b.max()
        base = rho * n
        corners = np.array([base + a0 * h + b0 * v, base + a1 * h + b0 * v, base + a1 * h + b1 * v,
                            base + a0 * h + b1 * v])
        out.append((n.copy(), rho, cov, idx.size, corners, corners.mean(axis=0)))
    return out, labels


def extract_planes(cloud: Cloud, cfg, rng: np.random.Generator, method: str | None = None,
                   rho_max: float = 5.0) -> Planes:
    """Planes in a cloud by the randomized Hough transform (``method`` "rht", the seed's) or RANSAC.

    ``cfg`` is read duck-typed (mcl.config.PlaneConfig): max_planes, min_points, min_inliers, votes,
    region_px, theta_bins, phi_bins, rho_step, k_sigma, coarse, max_trials, ransac_iterations, method.
    ``rho_max`` bounds the accumulator (the camera's z_max is enough). Planes with fewer than
    ``min_inliers`` final inliers are dropped.
    """
    import time

    from mcl.kernels.planes import ransac_detect, rht_detect

    t0 = time.perf_counter()
    method = method or cfg.method
    m = cloud.points.shape[0]
    raw = np.zeros((int(cfg.max_planes), 4))
    labels = np.empty(m, dtype=np.int64)
    if m < 3:
        found, trials = 0, 0
    elif method == "rht":
        u = rng.random((int(cfg.max_trials), 5))
        n_rho = int(math.ceil(float(rho_max) / float(cfg.rho_step))) + 1
        found, trials = rht_detect(cloud.points, cloud.rays, cloud.noise, cloud.pix, cloud.grid, u,
                                   int(cfg.max_planes), int(cfg.min_points), int(cfg.min_inliers), int(cfg.votes),
                                   float(cfg.region_px), int(cfg.theta_bins), int(cfg.phi_bins),
                                   float(cfg.rho_step), n_rho, float(cfg.k_sigma), float(cfg.coarse), labels, raw)
    elif method == "ransac":
        it = int(cfg.ransac_iterations)
        u = rng.random((it * int(cfg.max_planes), 3))
        found, trials = ransac_detect(cloud.points, cloud.rays, cloud.noise, u, it, int(cfg.max_planes),
                                      int(cfg.min_points), int(cfg.min_inliers), float(cfg.k_sigma),
                                      float(cfg.coarse), labels, raw)
    else:
        raise ValueError(f"method: expected rht or ransac, got {method!r}")
    fin, labels = _finish(cloud, raw[:found], float(cfg.k_sigma), int(cfg.erode))
    keep = [j for j, f in enumerate(fin) if f[3] >= int(cfg.min_inliers)]
    remap = np.full(max(len(fin), 1), -1, dtype=np.int64)
    remap[keep] = np.arange(len(keep))
    labels = np.where(labels >= 0, remap[np.maximum(labels, 0)], -1)
    fin = [fin[j] for j in keep]
    k = len(fin)
    normal = np.array([f[0] for f in fin]).reshape(k, 3)
    theta, phi = angles_of(normal)
    return Planes(theta=theta, phi=phi, rho=np.array([f[1] for f in fin], dtype=np.float64),
                  normal=normal, cov=np.array([f[2] for f in fin]).reshape(k, 3, 3),
                  inliers=np.array([f[3] for f in fin], dtype=np.int64),
                  corners=np.array([f[4] for f in fin]).reshape(k, 4, 3),
                  centre=np.array([f[5] for f in fin]).reshape(k, 3), labels=labels, trials=int(trials),
                  seconds=time.perf_counter() - t0)


# ----------------------------------------------------------------------------- the map


@dataclass(frozen=True, eq=False)
class PlaneMap:
    """Vertical faces: ``faces`` (F, 7) rows (n_x, n_y, d, a_x, a_y, b_x, b_y), ``n . x = d`` with n the
    unit normal into free space, a -> b the face's horizontal extent (free space on its left)."""

    faces: np.ndarray
    path: str | None = None

    def __len__(self) -> int:
        return int(self.faces.shape[0])

    @classmethod
    def from_segments(cls, seg, path: str | None = None) -> "PlaneMap":
        """From (F, 4) rows (x0, y0, x1, y1), free space on the left of each."""
        seg = np.asarray(seg, dtype=np.float64).reshape(-1, 4)
        dx = seg[:, 2] - seg[:, 0]
        dy = seg[:, 3] - seg[:, 1]
        ln = np.hypot(dx, dy)
        nx, ny = -dy / ln, dx / ln  # left of a -> b
        d = nx * seg[:, 0] + ny * seg[:, 1]
        return cls(np.ascontiguousarray(np.column_stack([nx, ny, d, seg])), path)

    @classmethod
    def from_grid(cls, grid, min_length: float = 0.2) -> "PlaneMap":
        """The faces between occupied and free cells of an occupancy grid: maximal runs of cell edges with an
        occupied cell on one side and a free one on the other, at least ``min_length`` long."""
        occ = np.asarray(grid.occupied)
        free = np.asarray(grid.free)
        res = float(grid.resolution)
        ox, oy = float(grid.origin[0]), float(grid.origin[1])
        segs = []
        min_cells = max(int(math.ceil(min_length / res - 1e-9)), 1)

        def runs(mask):
            # (row, start, stop) of the True runs along axis 1
            m = np.pad(mask, ((0, 0), (1, 1)))
            d = np.diff(m.astype(np.int8), axis=1)
            r0, c0 = np.nonzero(d == 1)
            r1, c1 = np.nonzero(d == -1)
            return r0, c0, c1

        # edges between rows i-1 and i (horizontal faces): y = oy + i res
        below_occ = occ[:-1] & free[1:]  # occupied below, free above: normal +y
        above_occ = free[:-1] & occ[1:]  # free below, occupied above: normal -y
        for mask, up in ((below_occ, True), (above_occ, False)):
            r, c0, c1 = runs(mask)
            keep = (c1 - c0) >= min_cells
            for i, a, b in zip(r[keep], c0[keep], c1[keep]):
                y = oy + (i + 1) * res
                xa, xb = ox + a * res, ox + b * res
                segs.append((xa, y, xb, y) if up else (xb, y, xa, y))
        # edges between columns j-1 and j (vertical faces): x = ox + j res
        left_occ = (occ[:, :-1] & free[:, 1:]).T  # occupied left, free right: normal +x
        right_occ = (free[:, :-1] & occ[:, 1:]).T  # normal -x
        for mask, right in ((left_occ, True), (right_occ, False)):
            r, c0, c1 = runs(mask)
            keep = (c1 - c0) >= min_cells
            for j, a, b in zip(r[keep], c0[keep], c1[keep]):
                x = ox + (j + 1) * res
                ya, yb = oy + a * res, oy + b * res
                segs.append((x, yb, x, ya) if right else (x, ya, x, yb))
        return cls.from_segments(np.array(segs).reshape(-1, 4), path=getattr(grid, "path", None))

    def near(self, xy_min, xy_max, reach: float) -> np.ndarray:
        """Rows of the faces whose extent comes within ``reach`` of the box [xy_min, xy_max]."""
        f = self.faces
        lo = np.minimum(f[:, [3, 4]], f[:, [5, 6]])
        hi = np.maximum(f[:, [3, 4]], f[:, [5, 6]])
        gap = np.maximum(0.0, np.maximum(lo - np.asarray(xy_max), np.asarray(xy_min) - hi))
        return np.ascontiguousarray(f[np.hypot(gap[:, 0], gap[:, 1]) <= reach])


def load_plane_map(path: str | os.PathLike) -> PlaneMap:
    """Read a plane map YAML (module docstring); DataError naming the file and key on any problem."""
    name = str(path)
    doc = read_yaml(path, DataError)
    if not isinstance(doc, dict) or not isinstance(doc.get("planes"), list):
        raise DataError(f"{name}: planes: missing (expected a mapping with a 'planes' list)")
    extra = sorted(str(k) for k in doc if k != "planes")
    if extra:
        raise DataError(f"{name}: {extra[0]}: unknown key (expected only 'planes')")
    rows = []
    for k, item in enumerate(doc["planes"]):
        where = f"{name}: planes[{k}]"
        if not isinstance(item, dict):
            raise DataError(f"{where}: expected a mapping {{x0, y0, x1, y1}}")
        for key in item:
            if key not in ("x0", "y0", "x1", "y1"):
                raise DataError(f"{where}.{key}: unknown key (expected x0, y0, x1, y1)")
        row = []
        for key in ("x0", "y0", "x1", "y1"):
            if key not in item:
                raise DataError(f"{where}.{key}: missing")
            row.append(finite_number(item[key], f"{where}.{key}", DataError))
        if math.hypot(row[2] - row[0], row[3] - row[1]) <= 0.0:
            raise DataError(f"{where}: the two ends are the same point")
        rows.append(row)
    if not rows:
        raise DataError(f"{name}: planes: the list is empty")
    return PlaneMap.from_segments(np.array(rows), path=name)


def save_plane_map(path: str | os.PathLike, plane_map: PlaneMap) -> None:
    """Write a plane map YAML (atomic)."""
    from mcl.trajectory import atomic_write_text

    lines = ["# mcl plane map: vertical faces, free space on the left of (x0, y0) -> (x1, y1)\n", "planes:\n"]
    for f in plane_map.faces:
        lines.append(f"  - {{x0: {f[3]:.4f}, y0: {f[4]:.4f}, x1: {f[5]:.4f}, y1: {f[6]:.4f}}}\n")
    atomic_write_text(Path(path), "".join(lines))


# ----------------------------------------------------------------------------- the model


class PlaneModel:
    """The plane measurement model over a :class:`PlaneMap` (module docstring).

    ``cfg`` is read duck-typed (mcl.config.PlaneConfig): sigma_phi, sigma_rho, z_det, z_fp, gate,
    range_max, vertical_tol, extent_margin. ``camera_xy`` is the camera's (x, y) on the robot.
    """

    def __init__(self, plane_map: PlaneMap, cfg, camera_xy=(0.0, 0.0)):
        self.map = plane_map
        self.cfg = cfg
        self.camera_xy = (float(camera_xy[0]), float(camera_xy[1]))
        self.log_zdet = math.log(cfg.z_det) if cfg.z_det > 0 else -math.inf
        c = float(cfg.z_fp) / (2.0 * math.pi * float(cfg.range_max))
        self.log_c = math.log(c) if c > 0 else -math.inf

    def prepare(self, planes: Planes) -> np.ndarray | None:
        """(J, 7) rows (phi, rho, S_pp, S_pr, S_rr, c_x, c_y) of the vertical planes; None if none."""
        v = planes.vertical(float(self.cfg.vertical_tol))
        if v.size == 0:
            return None
        c = planes.cov[v]
        out = np.empty((v.size, 7))
        out[:, 0] = planes.phi[v]
        out[:, 1] = planes.rho[v]
        out[:, 2] = c[:, 1, 1] + float(self.cfg.sigma_phi) ** 2
        out[:, 3] = c[:, 1, 2]
        out[:, 4] = c[:, 2, 2] + float(self.cfg.sigma_rho) ** 2
        out[:, 5] = planes.centre[v, 0]
        out[:, 6] = planes.centre[v, 1]
        return out

    def log_likelihood(self, particles, prepared, out=None) -> np.ndarray:
        """(N,) float64: sum over the observed planes of log(z_det p_det + z_fp p_uniform)."""
        from mcl.kernels.planes import planes_loglik

        p = np.ascontiguousarray(particles, dtype=np.float64)
        if out is None:
            out = np.empty(p.shape[1])
        if prepared is None or p.shape[1] == 0:
            out[:] = 0.0
            return out
        reach = float(self.cfg.range_max) + float(self.cfg.extent_margin) + math.hypot(*self.camera_xy)
        faces = self.map.near(p[:2].min(axis=1), p[:2].max(axis=1), reach)
        gate = float(self.cfg.gate)
        planes_loglik(p, np.ascontiguousarray(prepared), faces, self.camera_xy[0], self.camera_xy[1], gate * gate,
                      self.log_zdet, self.log_c, float(self.cfg.extent_margin), out)
        return out


# ----------------------------------------------------------------------------- depth folders


@dataclass(frozen=True, eq=False)
class DepthFrame:
    """One depth image of a depth folder: its time, file and (filled by the runner) the odometry pose at t."""

    t: float
    path: str
    odom: np.ndarray | None = None
    tv: float = 0.0
    rv: float = 0.0


def write_depth_frame(folder: Path, t: float, depth_m: np.ndarray, quantization: float = 0.001) -> Path:
    """Write a depth image (m; 0: no reading) as ``<t>.npz`` holding uint16 ``depth`` in units of
    ``quantization`` (Kinect's raw millimetres), compressed; atomic. Returns the path."""
    import io

    from mcl.trajectory import atomic_write_bytes

    q = np.clip(np.rint(np.nan_to_num(depth_m, nan=0.0) / quantization), 0, 65535).astype(np.uint16)
    buf = io.BytesIO()
    np.savez_compressed(buf, depth=q, scale=np.float64(quantization))
    path = Path(folder) / f"{t:012.6f}.npz"
    atomic_write_bytes(path, buf.getvalue())
    return path


def read_depth_frame(path: str | os.PathLike, shape: tuple[int, int] | None = None) -> np.ndarray:
    """A depth frame as float64 metres (0: no reading); DataError naming the file when unreadable (a cut or
    corrupt .npz was a zipfile or EOF traceback), or when not an image of ``shape`` (height, width: the camera's)."""
    import zipfile

    try:
        with np.load(path) as z:
            depth = z["depth"].astype(np.float64) * float(z["scale"])
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise DataError(f"{path}: not a depth frame ({type(e).__name__})") from None
    if depth.ndim != 2 or (shape is not None and depth.shape != tuple(shape)):
        want = f"{shape[0]} x {shape[1]} (camera.yaml's height x width)" if shape is not None else "2-D"
        raise DataError(f"{path}: a depth frame of shape {' x '.join(map(str, depth.shape))}, expected {want}")
    return depth


def load_depth_folder(folder: str | os.PathLike) -> tuple[DepthCamera, list[DepthFrame]]:
    """The camera (``camera.yaml``) and the frames (``<t>.npz``, by time) of a depth folder."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: not a depth folder (mcl simulate --depth writes one)")
    cam_path = folder / CAMERA_FILE
    cam = DepthCamera.from_dict(read_yaml(cam_path, DataError), str(cam_path))
    frames = []
    for p in sorted(folder.glob("*.npz")):
        try:
            t = float(p.stem)
        except ValueError:
            raise DataError(f"{p}: a depth frame's name must be its time in seconds") from None
        frames.append(DepthFrame(t, str(p)))
    if not frames:
        raise DataError(f"{folder}: no depth frames (<t>.npz)")
    frames.sort(key=lambda f: f.t)
    return cam, frames


class PlaneSensor:
    """The depth camera as a sensor of a run (mcl.runner): its frames joined to the filter updates, the
    planes extracted from each and the measurement model.

    Extraction draws its random triples from its own generator, a child of the run's seed, so adding
    planes to a run leaves the filter's random stream as it was.
    """

    def __init__(self, cfg, grid, odometry: np.ndarray, seed: int):
        pc = cfg.planes
        self.cfg = pc
        self.camera, self.frames = load_depth_folder(pc.depth)
        plane_map = load_plane_map(pc.map) if pc.map is not None else PlaneMap.from_grid(grid)
        self.model = PlaneModel(plane_map, pc, camera_xy=self.camera.mount[:2])
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x504C414E]))  # "PLAN"
        if odometry.shape[0] == 0:
            raise DataError(f"{pc.depth}: no ODOM lines in the log to place the depth frames")
        from mcl.datasets.carmen import interpolate_odometry

        od = interpolate_odometry(odometry, np.array([f.t for f in self.frames]))
        self.frames = [DepthFrame(f.t, f.path, od[:, k].copy()) for k, f in enumerate(self.frames)]
        self._of: dict[int, DepthFrame] = {}
        self.planes_seen = 0
        self.walls_seen = 0
        self.observed = 0
        self.seconds = 0.0
        self.last_cloud: Cloud | None = None

    def attach(self, updates: list[tuple]) -> list[tuple]:
        """The updates with the frames joined: a frame within 1 ms of an update joins it, any other is an
        update of its own, ``(frame, None)``; in time order. ``updates``: a list, or the runner's lazy
        ``(scan, None)`` pairs of a log without landmarks (indexed here, so made a list: it was a TypeError)."""
        updates = list(updates)
        ut = np.array([u[0].t for u in updates])
        taken: set[int] = set()
        out = list(updates)
        for f in self.frames:
            i = int(np.searchsorted(ut, f.t)) if ut.size else 0
            near = [j for j in (i - 1, i) if 0 <= j < ut.size and abs(ut[j] - f.t) <= 1e-3 and j not in taken]
            if near:
                j = min(near, key=lambda j: abs(ut[j] - f.t))
                taken.add(j)
                self._of[id(updates[j][0])] = f
            else:
                out.append((f, None))
                self._of[id(f)] = f
        out.sort(key=lambda u: u[0].t)
        return out

    def frame_of(self, record) -> DepthFrame | None:
        """The depth frame of an update (given its first element), or None."""
        return self._of.get(id(record))

    def observe(self, frame: DepthFrame) -> Planes:
        """The planes of a depth frame."""
        import time

        t0 = time.perf_counter()
        cloud = cloud_from_depth(read_depth_frame(frame.path, (self.camera.height, self.camera.width)), self.camera,
                                 int(self.cfg.stride))
        planes = extract_planes(cloud, self.cfg, self.rng, rho_max=self.camera.z_max)
        self.seconds += time.perf_counter() - t0
        self.last_cloud = cloud
        self.observed += 1
        self.planes_seen += len(planes)
        self.walls_seen += int(planes.vertical(float(self.cfg.vertical_tol)).size)
        return planes

    def summary(self) -> dict:
        n = max(self.observed, 1)
        return {"frames": len(self.frames), "observed": self.observed, "planes_per_frame": self.planes_seen / n,
                "walls_per_frame": self.walls_seen / n, "ms_per_frame": 1e3 * self.seconds / n,
                "method": self.cfg.method, "map_faces": len(self.model.map)}


def associate(model: PlaneModel, pose, prepared: np.ndarray | None) -> np.ndarray:
    """For one pose: the map face (row of ``model.map.faces``) each prepared observation is associated
    with, -1 beyond the gate (the kernel's rule, in NumPy, for the recording and the tests)."""
    if prepared is None:
        return np.zeros(0, dtype=np.int64)
    f = model.map.faces
    x, y, th = (float(v) for v in pose)
    c, s = math.cos(th), math.sin(th)
    mx, my = model.camera_xy
    px, py = x + c * mx - s * my, y + s * mx + c * my
    rho_hat = f[:, 0] * px + f[:, 1] * py - f[:, 2]
    phi_hat = np.arctan2(-f[:, 1], -f[:, 0]) - th
    ab = f[:, 5:7] - f[:, 3:5]
    ln = np.hypot(ab[:, 0], ab[:, 1])
    out = np.full(prepared.shape[0], -1, dtype=np.int64)
    for j, (phi, rho, spp, spr, srr, cx, cy) in enumerate(prepared):
        qx, qy = px + c * cx - s * cy, py + s * cx + c * cy
        along = ((qx - f[:, 3]) * ab[:, 0] + (qy - f[:, 4]) * ab[:, 1]) / ln
        e = np.arctan2(np.sin(phi - phi_hat), np.cos(phi - phi_hat))
        er = rho - rho_hat
        d2 = (srr * e * e - 2 * spr * e * er + spp * er * er) / (spp * srr - spr * spr)
        ok = (rho_hat > 0) & (along >= -model.cfg.extent_margin) & (along <= ln + model.cfg.extent_margin)
        d2 = np.where(ok, d2, np.inf)
        k = int(np.argmin(d2))
        if d2[k] < float(model.cfg.gate) ** 2:
            out[j] = k
    return out


def level_to_world(pose, camera: DepthCamera, pts: np.ndarray) -> np.ndarray:
    """(K, 3) level-frame points to the world frame for a robot pose (x, y, theta)."""
    x, y, th = (float(v) for v in pose)
    c, s = math.cos(th), math.sin(th)
    mx, my, mz = camera.mount[:3]
    p = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
    out = np.empty_like(p)
    out[:, 0] = x + c * (mx + p[:, 0]) - s * (my + p[:, 1])
    out[:, 1] = y + s * (mx + p[:, 0]) + c * (my + p[:, 1])
    out[:, 2] = mz + p[:, 2]
    return out
