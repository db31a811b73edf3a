"""The particle filter: Monte Carlo localization (Prob. Rob. Table 8.2, MCL).

``ParticleFilter.step`` reads as the algorithm: predict every particle with the
motion model (map-based: poses that land off free space are sampled again),
correct the log weights with the sensor model, resample when the effective
sample size falls below a fraction of N, and estimate. The filter owns the one
random generator, seeded from the config, so a seed gives the same trajectory
whatever the numba thread count. It does no I/O.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from mcl.config import Config
from mcl.estimate import estimate, wrap_angle
from mcl.motion import allowed_mask, make_motion_model
from mcl.resampling import effective_sample_size, normalize_log_weights, resample
from mcl.sensors import make_sensor_model


@dataclass(frozen=True)
class Control:
    """u_t for the motion model: the odometry pair, and the velocities with their duration.

    The odometry model reads ``odom_prev`` and ``odom_now`` (robot poses in the
    odometry frame); a velocity model reads ``v``, ``w`` and ``dt``.
    """

    odom_prev: np.ndarray
    odom_now: np.ndarray
    dt: float = 0.0
    v: float = 0.0
    w: float = 0.0


@dataclass
class StepInfo:
    """What one filter update did, for the logs and the summary."""

    ess: float = 0.0  # effective sample size after the correction, before resampling
    resampled: bool = False
    tries: float = 0.0  # mean motion samples per particle (map-based motion model)
    rejected: int = 0  # particles that never landed in free space (weight zero)
    degenerate: bool = False  # every weight was zero; weights were reset to uniform
    mean: np.ndarray | None = None  # the estimate (x, y, theta), from the weighted set before resampling
    cov: np.ndarray | None = None  # its 3x3 covariance
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage


class ParticleFilter:
    """MCL over a (3, N) particle array with log weights."""

    def __init__(self, cfg: Config, grid, *, rng: np.random.Generator | None = None):
        self.cfg = cfg
        self.grid = grid
        self.rng = rng if rng is not None else np.random.default_rng(cfg.seed)
        self.motion = make_motion_model(cfg.motion)
        self.allowed = allowed_mask(grid, cfg.motion.robot_radius) if cfg.motion.map_rejection else None
        self.sensor = make_sensor_model(grid, cfg.sensor)
        n = cfg.filter.particles
        self.particles = np.zeros((3, n))
        self.logw = np.full(n, -np.log(n))
        self.weights = np.full(n, 1.0 / n)
        self.degenerate_events = 0

    # ------------------------------------------------------------------ initialisation

    @property
    def n(self) -> int:
        return self.particles.shape[1]

    def init_gaussian(self, mean, std) -> None:
        """Particles drawn from N(mean, diag(std^2))."""
        n = self.cfg.filter.particles
        p = self.rng.standard_normal((3, n)) * np.asarray(std, dtype=np.float64)[:, None]
        p += np.asarray(mean, dtype=np.float64)[:, None]
        p[2] = wrap_angle(p[2])
        self._set(np.ascontiguousarray(p))

    def init_global(self) -> None:
        """Particles uniform over the poses the map allows (global localization)."""
        clearance = self.cfg.motion.robot_radius if self.cfg.motion.map_rejection else 0.0
        self._set(self.grid.sample_free(self.cfg.filter.particles, self.rng, clearance=clearance))

    def _set(self, particles: np.ndarray) -> None:
        self.particles = particles
        n = particles.shape[1]
        self.logw = np.full(n, -np.log(n))
        self.weights = np.full(n, 1.0 / n)

    # ------------------------------------------------------------------ the loop

    def predict(self, control: Control, info: StepInfo) -> None:
        """x_t ~ p(x_t | u_t, x_{t-1}, m): sample the motion model, rejecting poses off free space."""
        new, ok, tries = self.motion.sample_control(self.particles, control, self.rng, allowed=self.allowed, grid=self.grid)
        self.particles = new
        info.tries = float(tries)
        if ok is not None:
            bad = ~ok
            info.rejected = int(np.count_nonzero(bad))
            if info.rejected:
                self.logw[bad] = -np.inf

    def correct(self, observation) -> None:
        """w_t = w_{t-1} * p(z_t | x_t, m), in log space. `observation` comes from ``self.sensor.prepare``."""
        if observation is None:
            return
        self.logw += self.sensor.log_likelihood(self.particles, observation)

    def normalize(self, info: StepInfo) -> None:
        """Normalise the log weights (log-sum-exp); recover when no particle explains the scan."""
        w, log_norm = normalize_log_weights(self.logw)
        if not np.isfinite(log_norm):
            # Every weight is zero: keep the particles, forget the weights.
            info.degenerate = True
            self.degenerate_events += 1
            if self.degenerate_events == 1:
                warnings.warn("every particle weight is zero (no pose explains the scan); weights reset to uniform", stacklevel=2)
            w = np.full(self.n, 1.0 / self.n)
            self.logw = np.full(self.n, -np.log(self.n))
        else:
            self.logw -= log_norm
        self.weights = w
        info.ess = float(effective_sample_size(w))

    def maybe_resample(self, info: StepInfo) -> None:
        """Resample when ESS / N < resample_threshold (the scheme named in filter.resampling)."""
        if info.ess >= self.cfg.filter.resample_threshold * self.n:
            return
        idx = resample(self.cfg.filter.resampling, self.logw, self.rng)
        self.particles = np.ascontiguousarray(self.particles[:, idx])
        self._set(self.particles)
        info.resampled = True

    def estimate(self) -> tuple[np.ndarray, np.ndarray]:
        """Weighted mean pose (circular mean for theta) and covariance."""
        return estimate(self.particles, self.weights)

    def step(self, control: Control | None, observation) -> StepInfo:
        """One MCL update: predict -> correct -> normalise -> estimate -> resample. Returns what it did."""
        info = StepInfo()
        t0 = time.perf_counter()
        if control is not None:
            self.predict(control, info)
        t1 = time.perf_counter()
        self.correct(observation)
        t2 = time.perf_counter()
        self.normalize(info)
        t3 = time.perf_counter()
        info.mean, info.cov = self.estimate()
        t4 = time.perf_counter()
        self.maybe_resample(info)
        t5 = time.perf_counter()
        info.timings = {"predict": t1 - t0, "correct": t2 - t1, "estimate": t4 - t3, "resample": (t5 - t4) + (t3 - t2)}
        return info
