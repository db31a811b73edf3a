"""Odometry motion model, plain and map-based (Prob. Rob. ch. 5).

``OdometryMotionModel.sample`` is ``sample_motion_model_odometry`` (Table 5.6)
for N particles at once, with the refinements of ROS AMCL's
``odometryUpdate`` (diff-drive model):

* the odometry step is split into rot1, trans, rot2 (``odometry_deltas``);
  when the robot moved less than 1 cm, rot1 = 0 (atan2 of a tiny vector is
  noise);
* the rotation noise uses the smaller of |rot| and |rot -+ pi|, so a robot
  driving backwards (rot1 ~ pi) gets small noise, not pi-sized noise;
* ``noise_form="variance"`` (book and AMCL):
      sigma_rot1^2  = alpha1 rot1^2 + alpha2 trans^2
      sigma_trans^2 = alpha3 trans^2 + alpha4 (rot1^2 + rot2^2)
      sigma_rot2^2  = alpha1 rot2^2 + alpha2 trans^2
  ``noise_form="std"`` (lecture slides):
      sigma_rot1  = alpha1 |rot1| + alpha2 trans, and so on.

Map-based motion model (seed section 5.5, ``sample_motion_model_with_map``):
with an ``allowed`` mask (``allowed_mask``: free cells farther than the robot
radius from any occupied cell), a particle whose new pose lands outside it
(or off the map) is sampled again with fresh noise, up to ``max_tries``
times. The loop runs over tries, never over particles. A particle that never
lands gets ``ok = False``; the filter gives it weight zero.

All random numbers come from the caller's ``numpy.random.Generator``
(standard normals, drawn outside the numba kernels), so one seed gives the
same particles whatever the numba thread count.
"""

from __future__ import annotations

import math

import numpy as np

from mcl.kernels import motion as _k

ROT1_MIN_TRANS = 0.01  # m: below this translation rot1 is set to 0 (AMCL)


def angle_diff(a: float, b: float) -> float:
    """a - b wrapped into (-pi, pi]."""
    return float(_k.wrap(float(a) - float(b)))


def odometry_deltas(odom_prev, odom_now) -> tuple[float, float, float]:
    """(rot1, trans, rot2) that take odometry pose odom_prev to odom_now (Table 5.6 lines 2-4).

    rot1 = atan2(dy, dx) - theta_prev, trans = hypot(dx, dy),
    rot2 = (theta_now - theta_prev) - rot1, angles wrapped into (-pi, pi].
    When trans < 1 cm, rot1 = 0 and rot2 carries the whole turn (AMCL).
    """
    x0, y0, t0 = (float(v) for v in odom_prev[:3])
    x1, y1, t1 = (float(v) for v in odom_now[:3])
    dx, dy = x1 - x0, y1 - y0
    trans = math.hypot(dx, dy)
    rot1 = 0.0 if trans < ROT1_MIN_TRANS else angle_diff(math.atan2(dy, dx), t0)
    rot2 = angle_diff(angle_diff(t1, t0), rot1)
    return rot1, trans, rot2


def _noise_angle(rot: float) -> float:
    """min(|rot|, |rot -+ pi|): the rotation a reversing robot really made, for the noise."""
    return min(abs(angle_diff(rot, 0.0)), abs(angle_diff(rot, math.pi)))


def noise_sigmas(rot1: float, trans: float, rot2: float, cfg) -> tuple[float, float, float]:
    """Standard deviations (sigma_rot1, sigma_trans, sigma_rot2) of the noise on the deltas.

    ``cfg`` needs alpha1..alpha4 and noise_form ("variance" or "std"); the
    rotations enter as min(|rot|, |rot -+ pi|) (see the module docstring).
    """
    a1, a2, a3, a4 = float(cfg.alpha1), float(cfg.alpha2), float(cfg.alpha3), float(cfg.alpha4)
    r1 = _noise_angle(rot1)
    r2 = _noise_angle(rot2)
    t = abs(float(trans))
    if cfg.noise_form == "variance":
        return (math.sqrt(a1 * r1 * r1 + a2 * t * t),
                math.sqrt(a3 * t * t + a4 * (r1 * r1 + r2 * r2)),
                math.sqrt(a1 * r2 * r2 + a2 * t * t))
    if cfg.noise_form == "std":
        return (a1 * r1 + a2 * t, a3 * t + a4 * (r1 + r2), a1 * r2 + a2 * t)
    raise ValueError(f"motion.noise_form: unknown value {cfg.noise_form!r} (expected 'variance' or 'std')")


def allowed_mask(grid, robot_radius: float) -> np.ndarray:
    """uint8 (H, W) mask of the cells a robot centre may occupy: free and distance > robot_radius.

    ``grid`` needs the bool ``free`` and float ``distance`` (metres to the
    nearest occupied cell centre) arrays of ``OccupancyGrid``. Unknown cells
    are not free, so they are never allowed. Compute once per map.
    """
    free = np.asarray(grid.free, dtype=bool)
    dist = np.asarray(grid.distance)
    return np.ascontiguousarray(free & (dist > float(robot_radius)), dtype=np.uint8)


class OdometryMotionModel:
    """Sample x_t ~ p(x_t | u_t, x_{t-1}[, m]) for a (3, N) particle array.

    ``cfg`` is read duck-typed: noise_form, alpha1..alpha4, max_tries
    (map_rejection and robot_radius are for whoever builds the mask).
    """

    def __init__(self, cfg):
        self.cfg = cfg
        if cfg.noise_form not in ("variance", "std"):
            raise ValueError(f"motion.noise_form: unknown value {cfg.noise_form!r} (expected 'variance' or 'std')")
        self.max_tries = int(getattr(cfg, "max_tries", 10))
        self._noise = np.empty((3, 0))
        self._all = np.empty(0, dtype=np.int64)

    def _buffers(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        if self._noise.shape[1] != n:
            self._noise = np.empty((3, n))
            self._all = np.arange(n, dtype=np.int64)
        return self._noise, self._all

    def sample_control(self, particles, control, rng, allowed=None, grid=None):
        """``sample`` for a :class:`mcl.filter.Control` (uses its odometry pair)."""
        return self.sample(particles, control.odom_prev, control.odom_now, rng, allowed=allowed, grid=grid)

    def sample(self, particles, odom_prev, odom_now, rng: np.random.Generator,
               allowed=None, grid=None, out=None):
        """Move every particle by the odometry step odom_prev -> odom_now, with noise.

        particles: (3, N) float64 (x, y, theta); odom_prev, odom_now: (x, y, theta).
        allowed: None, or an (H, W) mask from ``allowed_mask``; then ``grid``
        (anything with ``origin`` (x0, y0) and ``resolution``) places it in the world.
        out: optional (3, N) float64 C-contiguous array for the result (not ``particles``).

        Returns (new (3, N), ok (N,) bool, mean_tries): ok[i] is False when
        particle i never landed in an allowed cell in max_tries tries (its pose
        is then the last try); mean_tries = motion samples drawn / N (1.0
        without a map).
        """
        p = np.ascontiguousarray(particles, dtype=np.float64)
        if p.ndim != 2 or p.shape[0] != 3:
            raise ValueError(f"particles: expected shape (3, N), got {p.shape}")
        n = p.shape[1]
        if out is None:
            out = np.empty_like(p)
        elif out is p or np.shares_memory(out, p):
            raise ValueError("out must not share memory with particles")
        rot1, trans, rot2 = odometry_deltas(odom_prev, odom_now)
        s1, st, s2 = noise_sigmas(rot1, trans, rot2, self.cfg)
        noise, idx_all = self._buffers(n)
        rng.standard_normal(out=noise)

        if allowed is None:
            _k.sample_odometry(p, noise, rot1, trans, rot2, s1, st, s2, out)
            return out, np.ones(n, dtype=bool), 1.0

        if grid is None:
            raise ValueError("a map mask (allowed) needs grid (origin, resolution) to place it")
        mask = allowed if (allowed.dtype == np.uint8 and allowed.flags.c_contiguous) \
            else np.ascontiguousarray(allowed, dtype=np.uint8)
        ox, oy = float(grid.origin[0]), float(grid.origin[1])
        inv_res = 1.0 / float(grid.resolution)
        ok = np.empty(n, dtype=bool)
        n_ok = _k.sample_odometry_map(p, noise, idx_all, rot1, trans, rot2, s1, st, s2,
                                      mask, ox, oy, inv_res, out, ok)
        draws = n
        idx = None
        for _ in range(self.max_tries - 1):
            if n_ok == n:
                break
            # the particles still out: from the whole array once, then from the shrinking set
            idx = np.flatnonzero(~ok) if idx is None else idx[~ok[idx]]
            draws += idx.size
            fresh = rng.standard_normal((3, idx.size))
            n_ok += _k.sample_odometry_map(p, fresh, idx, rot1, trans, rot2, s1, st, s2,
                                           mask, ox, oy, inv_res, out, ok)
        return out, ok, draws / n if n else 0.0


def make_motion_model(cfg):
    """The motion model named by ``motion.model``."""
    if cfg.model == "odometry":
        return OdometryMotionModel(cfg)
    raise ValueError(f"motion.model: unknown model {cfg.model!r}")
