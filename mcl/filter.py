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

from mcl.adaptive import BinCounter, Recovery, draw_injected, kld_quantile, kld_resample
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
    particles: int = 0  # N weighted in this update (KLD sampling changes it at resampling)
    injected: int = 0  # particles drawn from the recovery sampler at this resampling (augmented MCL)
    inject_p: float = 0.0  # max(0, 1 - w_fast / w_slow) after this update's scan
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
        fc = cfg.filter
        self.kld_counter = None
        if fc.kld:
            h, w = grid.occupancy.shape
            size = (w * grid.resolution, h * grid.resolution)
            self.kld_counter = BinCounter(grid.origin, size, fc.kld_bin_xy, fc.kld_bin_theta)
            self.kld_z = kld_quantile(fc.kld_delta)
        self.recovery = Recovery(fc.recovery_alpha_slow, fc.recovery_alpha_fast) if fc.recovery else None
        # Augmented MCL draws injected poses from this: sampler(n, rng, observation) -> (3, n). Uniform over
        # the free space the motion model allows unless replaced (e.g. by a landmark-based pose sampler).
        self.recovery_sampler = self.sample_uniform
        self._observation = None

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
        self._set(self.sample_uniform(self.cfg.filter.particles, self.rng))

    def sample_uniform(self, n: int, rng: np.random.Generator, observation=None) -> np.ndarray:
        """(3, n) poses uniform over free space, with the robot-radius clearance when map rejection is on."""
        clearance = self.cfg.motion.robot_radius if self.cfg.motion.map_rejection else 0.0
        return self.grid.sample_free(n, rng, clearance=clearance)

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
        loglik = self.sensor.log_likelihood(self.particles, observation)
        if self.recovery is not None:
            self.recovery.update(Recovery.log_mean_likelihood(self.logw, loglik))
        self._observation = observation
        self.logw += loglik

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
        """Resample when ESS / N < resample_threshold (the scheme named in filter.resampling).

        With KLD sampling the new set's size follows the occupied bins (``mcl.adaptive.kld_resample``);
        with recovery a Binomial(N, max(0, 1 - w_fast/w_slow)) of the new particles come from
        ``recovery_sampler`` instead of the weighted set (augmented MCL).
        """
        fc = self.cfg.filter
        p = self.recovery.inject_probability if self.recovery is not None else 0.0
        info.inject_p = p
        if info.ess >= fc.resample_threshold * self.n:
            return
        obs = self._observation
        if self.kld_counter is not None:
            new, info.injected, _ = kld_resample(
                self.particles, self.logw, self.rng, self.kld_counter, scheme=fc.resampling,
                min_particles=fc.min_particles, max_particles=fc.particles, epsilon=fc.kld_epsilon, z=self.kld_z,
                inject_p=p, sampler=lambda n: self.recovery_sampler(n, self.rng, obs),
            )
        else:
            n_inj = draw_injected(self.n, p, self.rng)
            idx = resample(fc.resampling, self.logw, self.rng, n=self.n - n_inj)
            new = self.particles[:, idx]
            if n_inj:
                new = np.concatenate([new, self.recovery_sampler(n_inj, self.rng, obs)], axis=1)
            info.injected = n_inj
        self._set(np.ascontiguousarray(new))
        info.resampled = True

    def estimate(self) -> tuple[np.ndarray, np.ndarray]:
        """Weighted mean pose (circular mean for theta) and covariance."""
        return estimate(self.particles, self.weights)

    def step(self, control: Control | None, observation) -> StepInfo:
        """One MCL update: predict -> correct -> normalise -> estimate -> resample. Returns what it did."""
        info = StepInfo(particles=self.n)
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
