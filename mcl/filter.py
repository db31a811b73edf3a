"""The particle filter: Monte Carlo localization (Prob. Rob. Table 8.2, MCL).

``ParticleFilter.step`` reads as the algorithm: predict every particle with the
motion model (map-based: poses that land off free space are sampled again),
correct the log weights with the sensor model, resample when the effective
sample size falls below a fraction of N, and estimate. The filter owns the one
random generator, seeded from the config, so a seed gives the same trajectory
whatever the numba thread count. It does no I/O.

Degenerate input never puts a NaN into the particles. Each kind warns once
(``RuntimeWarning``) and is counted in ``ParticleFilter.events``:

* ``nan_ranges``: a scan with NaN or infinite readings (those beams are dropped);
* ``empty_scans``: a scan with no usable reading (zero beams, or none finite
  and positive): the update only predicts;
* ``time_backwards``: a control with dt < 0 (or not finite): dt is taken as 0;
  the odometry step itself is still applied (the odometry model does not use dt);
* ``odometry_jumps``: an odometry step longer than ``filter.max_odom_step`` or
  not finite: the step is a glitch, not motion; it is not applied and the
  particles are re-spread by ``filter.respread_std`` where they were (poses off
  the allowed map are drawn again), so the scan decides;
* ``degenerate_weights``: every weight is zero after the correction (no pose
  explains the scan): the particles are re-spread by ``respread_std`` around
  the last estimate moved by the odometry step, twice wider each consecutive
  time; after three consecutive failures, or with no estimate yet, the
  filter reinitialises globally. The fresh particles get equal weights: the
  scan that explained nothing is not scored again (that would collapse the
  new cloud onto the few poses that happen to fit a bad scan).

Re-spreading rather than reinitialising first: a scan no pose explains is
far more often a bad scan or a short glitch than a kidnapping (augmented MCL
handles that), and a global reinitialisation throws away a good track.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from mcl.adaptive import BinCounter, Recovery, draw_injected, kld_quantile, kld_resample, measurement_count
from mcl.config import Config
from mcl.clusters import ClusterEstimate, cluster_estimate
from mcl.estimate import estimate, wrap_angle
from mcl.landmarks import LandmarkModel, sample_poses_from_landmark
from mcl.motion import allowed_mask, make_motion_model
from mcl.resampling import effective_sample_size, normalize_log_weights, resample
from mcl.sensors import make_sensor_model


EVENT_KINDS = ("degenerate_weights", "nan_ranges", "odometry_jumps", "time_backwards", "empty_scans")
_MAX_DEGENERATE_RUN = 3  # consecutive all-zero updates before a global reinitialisation


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
    kld_moved: tuple | None = None  # (moved, ok, tries) of a KLD resample done with this update's motion
    mean: np.ndarray | None = None  # the estimate (x, y, theta), from the weighted set before resampling
    cov: np.ndarray | None = None  # its 3x3 covariance
    full_mean: np.ndarray | None = None  # the whole weighted set's mean (= mean when the cloud is one cluster)
    full_cov: np.ndarray | None = None  # the whole set's 3x3 covariance: its spread
    clusters: int = 1  # clusters in the cloud (filter.estimate = cluster)
    cluster_weight: float = 1.0  # weight of the heaviest cluster, whose mean is the estimate
    skipped_beams: int = 0  # beams ignored by beam skipping
    skipped_endpoints: np.ndarray | None = None  # (2, skipped_beams) their robot-frame endpoints (None: none skipped)
    events: tuple[str, ...] = ()  # degenerate-input events of this update (kinds of ParticleFilter.events)
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage


class ParticleFilter:
    """MCL over a (3, N) particle array with log weights."""

    def __init__(self, cfg: Config, grid, *, rng: np.random.Generator | None = None, landmark_map=None):
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
        # Degenerate input: counts per kind (summary.json "events"); each kind warns once.
        self.events = dict.fromkeys(EVENT_KINDS, 0)
        self._warned: set[str] = set()
        self._step_events: list[str] = []
        self._degenerate_run = 0  # consecutive updates where every weight was zero
        self._delta = None  # this update's odometry step in the robot frame, for re-spreading
        self.last_estimate: ClusterEstimate | None = None
        self.converged = False  # for beam skipping: the heaviest cluster holds the weight and is tight
        fc = cfg.filter
        self.kld_counter = None
        if fc.kld:
            h, w = grid.occupancy.shape
            size = (w * grid.resolution, h * grid.resolution)
            self.kld_counter = BinCounter(grid.origin, size, fc.kld_bin_xy, fc.kld_bin_theta)
            self.kld_z = kld_quantile(fc.kld_delta)
        self.recovery = Recovery(fc.recovery_alpha_slow, fc.recovery_alpha_fast) if fc.recovery is True else None
        # Augmented MCL draws injected poses from this: sampler(n, rng, observation) -> (3, n). Uniform over
        # the free space the motion model allows unless replaced (e.g. by a landmark-based pose sampler).
        self.recovery_sampler = self.sample_uniform
        self._observation = None
        self._laser_pose = np.zeros(3)  # of the scan last prepared (beam skipping walks its beams from there)
        self._injected = None  # (N,) bool: particles injected at the last resample (left out of w_avg)
        self._kld_pending = None  # (inject_p, observation) of a KLD resample deferred to the next motion
        # Landmarks (cfg.landmarks, mcl.landmarks): a model when a landmark map is given; injections then come
        # from the latest landmark observation (Prob. Rob. Table 6.5) when it has a known id.
        self.landmarks = LandmarkModel(landmark_map, cfg.landmarks) if landmark_map is not None else None
        self._marks = None
        if self.landmarks is not None:
            self.recovery_sampler = self.sample_from_landmarks

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
        if self.cfg.filter.recovery == "auto":
            self.recovery = None  # tracking from a known pose: no injections

    def init_global(self) -> None:
        """Particles uniform over the poses the map allows (global localization)."""
        self._set(self.sample_uniform(self.cfg.filter.particles, self.rng))
        self._auto_recovery()

    def _auto_recovery(self) -> None:
        """``filter.recovery: auto`` turns augmented MCL on for global localization."""
        fc = self.cfg.filter
        if fc.recovery == "auto" and self.recovery is None:
            self.recovery = Recovery(fc.recovery_alpha_slow, fc.recovery_alpha_fast)

    def sample_uniform(self, n: int, rng: np.random.Generator, observation=None) -> np.ndarray:
        """(3, n) poses uniform over free space, with the robot-radius clearance when map rejection is on."""
        clearance = self.cfg.motion.robot_radius if self.cfg.motion.map_rejection else 0.0
        return self.grid.sample_free(n, rng, clearance=clearance)

    def sample_from_landmarks(self, n: int, rng: np.random.Generator, observation=None, marks=None) -> np.ndarray:
        """(3, n) poses drawn from the landmark observation ``marks`` (default: the latest one) with
        ``sample_poses_from_landmark``, drawn again (up to motion.max_tries) where the map does not allow them;
        uniform over free space when there is no observation of a known landmark."""
        marks = self._marks if marks is None else marks
        lm = self.landmarks
        if lm is None or marks is None or not np.any(lm.map.index_of(marks.ids) >= 0):
            return self.sample_uniform(n, rng, observation)
        p = sample_poses_from_landmark(marks, lm.map, n, rng, self.cfg.landmarks)
        for _ in range(max(self.cfg.motion.max_tries - 1, 0)):
            bad = np.flatnonzero(~self._allowed_at(p) | ~self._free_at(p))
            if bad.size == 0:
                break
            # a fresh draw of all n keeps pose k on observation k mod J (the even share)
            q = sample_poses_from_landmark(marks, lm.map, n, rng, self.cfg.landmarks)
            p[:, bad] = q[:, bad]
        return np.ascontiguousarray(p)

    def _free_at(self, p: np.ndarray) -> np.ndarray:
        """(N,) bool: poses on free cells of the map (off the map: False)."""
        return self.grid.mask_at(np.asarray(self.grid.free), p[0], p[1])

    def init_from_landmarks(self, marks) -> bool:
        """Global localization seeded by landmarks: particles drawn from the observations of ``marks`` (a
        ``Landmarks`` record), shared evenly over those with known ids. False (nothing drawn) if none is known."""
        if self.landmarks is None or not np.any(self.landmarks.map.index_of(marks.ids) >= 0):
            return False
        self._set(self.sample_from_landmarks(self.cfg.filter.particles, self.rng, marks=marks))
        self._auto_recovery()
        return True

    def correct_landmarks(self, marks, info: StepInfo | None = None) -> None:
        """w_t *= p(z_t | x_t, m) for a ``Landmarks`` record (mcl.landmarks.LandmarkModel), in log space."""
        self._marks = marks
        if marks is None or self.landmarks is None:
            return
        prepared = self.landmarks.prepare(marks)
        if prepared is None:
            return
        loglik = self.landmarks.log_likelihood(self.particles, prepared)
        if self.recovery is not None and self._observation is None:  # landmark-only: they drive w_slow / w_fast
            self._update_recovery(loglik / prepared.shape[1])
        self.logw += loglik

    def _kld_draw(self, control: Control | None, info: StepInfo) -> None:
        """The deferred KLD resample: draw ancestors (and injected poses) batch by batch, move each batch
        with ``control`` when there is one, and count the bins of the moved poses (Prob. Rob. Table 8.4)."""
        fc = self.cfg.filter
        p, obs = self._kld_pending
        self._kld_pending = None
        moves: list = []

        def move(batch):
            new, ok, tries = self.motion.sample_control(batch, control, self.rng, allowed=self.allowed, grid=self.grid)
            fin = np.isfinite(new).all(axis=0)
            if not fin.all():  # keep the ancestor's pose, weight zero (as predict does)
                new[:, ~fin] = batch[:, ~fin]
                ok = fin if ok is None else ok & fin
            moves.append((ok, tries, batch.shape[1]))
            return new

        new, fresh, _ = kld_resample(
            self.particles, self.logw, self.rng, self.kld_counter, scheme=fc.resampling,
            min_particles=min(fc.min_particles, fc.particles), max_particles=fc.particles, epsilon=fc.kld_epsilon, z=self.kld_z,
            inject_p=p, sampler=lambda n: self.recovery_sampler(n, self.rng, obs),
            move=move if control is not None else None,
        )
        info.injected = int(np.count_nonzero(fresh))
        if control is not None:
            m = new.shape[1]
            ok = None
            if any(o is not None for o, _, _ in moves):
                ok = np.concatenate([np.ones(n, bool) if o is None else o for o, _, n in moves])[:m]
            tries = sum(t * n for _, t, n in moves) / max(sum(n for _, _, n in moves), 1)
            info.kld_moved = (new, ok, tries)
            # The motion is applied: predict keeps these poses (particles hold the pre-motion ancestors
            # only to supply the fallback pose of non-finite motion samples).
            self._set(np.ascontiguousarray(new))
        else:
            self._set(np.ascontiguousarray(new))
        self._injected = fresh if info.injected else None

    def _update_recovery(self, loglik_per_beam: np.ndarray) -> None:
        """Augmented MCL: fold the per-beam mean likelihood of the tracked particles into w_slow, w_fast.

        The particles injected at the last resample are left out (see mcl.adaptive); if every
        particle was injected, all count.
        """
        keep = self._injected
        if keep is not None and keep.size == loglik_per_beam.size and not keep.all():
            keep = ~keep
            self.recovery.update(Recovery.log_mean_likelihood(self.logw[keep], loglik_per_beam[keep]))
        else:
            self.recovery.update(Recovery.log_mean_likelihood(self.logw, loglik_per_beam))

    def _set(self, particles: np.ndarray) -> None:
        self._injected = None
        self.particles = particles
        n = particles.shape[1]
        self.logw = np.full(n, -np.log(n))
        self.weights = np.full(n, 1.0 / n)

    # ------------------------------------------------------------------ the loop

    def predict(self, control: Control, info: StepInfo) -> None:
        """x_t ~ p(x_t | u_t, x_{t-1}, m): sample the motion model, rejecting poses off free space.

        An odometry jump is not applied (the particles are re-spread instead);
        a negative dt becomes 0; particles the motion model made non-finite
        keep their previous pose with weight zero.
        """
        control = self._check_control(control)
        if control is None and self._kld_pending is not None:
            self._kld_draw(None, info)
        if control is None:
            self._delta = np.zeros(3)
            self.particles = self._draw_around(self.particles, np.asarray(self.cfg.filter.respread_std))
            return
        if self._kld_pending is not None:  # KLD sampling draws and moves in one loop (Table 8.4)
            self._kld_draw(control, info)
        prev = self.particles
        if info.kld_moved is not None:
            new, ok, tries = info.kld_moved
        else:
            new, ok, tries = self.motion.sample_control(self.particles, control, self.rng, allowed=self.allowed, grid=self.grid)
        finite = np.isfinite(new).all(axis=0)
        if not finite.all():  # weight zero; any finite pose will do (the previous one when it is known)
            new[:, ~finite] = prev[:, ~finite] if prev.shape == new.shape else 0.0
            self.logw[~finite] = -np.inf
        self.particles = new
        info.tries = float(tries)
        if ok is not None:
            bad = ~ok
            info.rejected = int(np.count_nonzero(bad))
            if info.rejected:
                self.logw[bad] = -np.inf

    def correct(self, observation, info: StepInfo | None = None) -> None:
        """w_t = w_{t-1} * p(z_t | x_t, m), in log space. `observation` comes from ``self.sensor.prepare``.

        With ``sensor.beam_skip`` and a converged filter, the beams most
        particles cannot explain are dropped first (``skip_mask`` of the sensor
        model). A NaN or +inf log-likelihood counts as weight zero.
        """
        if observation is None:
            return
        if self.cfg.sensor.beam_skip and self.converged and hasattr(self.sensor, "skip_mask"):
            skip = self.sensor.skip_mask(self.particles, self.weights, observation,
                                         pose=self._moved_estimate(), laser_xy=self._laser_pose[:2])
            if skip.any():
                if info is not None:
                    info.skipped_beams = int(np.count_nonzero(skip))
                    info.skipped_endpoints = observation[:, skip]
                observation = np.ascontiguousarray(observation[:, ~skip])
        loglik = self.sensor.log_likelihood(self.particles, observation)
        if not np.isfinite(loglik).all():
            loglik = np.where(np.isnan(loglik) | (loglik == np.inf), -np.inf, loglik)
        if self.recovery is not None:
            self._update_recovery(loglik / max(measurement_count(observation), 1))
        self._observation = observation
        self.logw += loglik

    def normalize(self, info: StepInfo) -> None:
        """Normalise the log weights (log-sum-exp); recover when no particle explains the scan."""
        w, log_norm = normalize_log_weights(self.logw)
        if not np.isfinite(log_norm):
            # Every weight is zero: keep the particles, forget the weights.
            info.degenerate = True
            self.degenerate_events += 1
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
        # Recovery resamples whenever it injects: a lost filter whose particles all explain the scan
        # equally badly has a high ESS and would otherwise never inject.
        if info.ess >= fc.resample_threshold * self.n and p == 0.0:
            return
        obs = self._observation
        if self.kld_counter is not None:
            # Table 8.4 bins each particle after its motion update: the resample waits for the next control.
            self._kld_pending = (p, obs)
            info.resampled = True
            return
        else:
            n_inj = draw_injected(self.n, p, self.rng)
            idx = resample(fc.resampling, self.logw, self.rng, n=self.n - n_inj)
            new = self.particles[:, idx]
            if n_inj:
                new = np.concatenate([new, self.recovery_sampler(n_inj, self.rng, obs)], axis=1)
            fresh = np.arange(new.shape[1]) >= new.shape[1] - n_inj
        info.injected = int(np.count_nonzero(fresh))
        self._set(np.ascontiguousarray(new))
        self._injected = fresh if info.injected else None
        info.resampled = True

    def estimate(self) -> tuple[np.ndarray, np.ndarray]:
        """The pose estimate and its covariance: of the heaviest cluster (``filter.estimate = cluster``) or of the
        whole weighted set (``mean``; circular mean for theta). Keeps both in ``last_estimate``."""
        fc = self.cfg.filter
        if fc.estimate == "cluster":
            est = cluster_estimate(self.particles, self.weights, fc.cluster_size, fc.cluster_angle)
        else:
            mean, cov = estimate(self.particles, self.weights)
            est = ClusterEstimate(mean, cov, mean, cov, 1, 1.0)
        self.last_estimate = est
        spread = math.sqrt(max(est.cov[0, 0], est.cov[1, 1], 0.0))
        self.converged = est.weight >= 0.5 and spread < self.cfg.sensor.beam_skip_distance
        return est.mean, est.cov

    # ------------------------------------------------------------------ degenerate input

    def _event(self, kind: str, message: str) -> None:
        """Count one degenerate-input event; warn the first time of each kind."""
        self.events[kind] += 1
        self._step_events.append(kind)
        if kind not in self._warned:
            self._warned.add(kind)
            warnings.warn(f"{message} (warned once; summary.json counts every {kind} event)", RuntimeWarning,
                          stacklevel=3)

    def prepare(self, scan, laser_pose):
        """The sensor model's observation for a scan, or None when the scan has no usable reading.

        Counts ``nan_ranges`` (NaN or infinite readings; the sensor model drops
        them) and ``empty_scans``.
        """
        r = np.asarray(scan.ranges, dtype=np.float64)
        finite = np.isfinite(r)
        if not finite.all():
            self._event("nan_ranges", f"a scan at t={scan.t} has NaN or infinite ranges; those beams are ignored")
        if not np.any(finite & (r > 0.0)):
            self._event("empty_scans", f"a scan at t={scan.t} has no usable reading; the update only predicts")
            return None
        self._laser_pose = np.asarray(laser_pose, dtype=np.float64)
        return self.sensor.prepare(scan, laser_pose)

    def time_backwards(self, dt: float) -> None:
        """Count (and warn once about) time running backwards between updates, dt < 0 or not finite."""
        self._event("time_backwards", f"time ran backwards (dt = {dt:.3f} s); dt taken as 0, the odometry step "
                    "still applied")

    def _check_control(self, control: Control) -> Control | None:
        """The control to apply: dt < 0 made 0; None for an odometry jump (or non-finite odometry)."""
        a = np.asarray(control.odom_prev, dtype=np.float64)[:3]
        b = np.asarray(control.odom_now, dtype=np.float64)[:3]
        if not (np.isfinite(a).all() and np.isfinite(b).all()):
            self._event("odometry_jumps", "odometry is not finite; the step is not applied, the particles are re-spread")
            return None
        step = math.hypot(b[0] - a[0], b[1] - a[1])
        if step > self.cfg.filter.max_odom_step:
            self._event("odometry_jumps", f"odometry jumped {step:.2f} m in one update (> filter.max_odom_step = "
                        f"{self.cfg.filter.max_odom_step} m); the step is not applied, the particles are re-spread")
            return None
        if not control.dt >= 0.0:
            self.time_backwards(control.dt)
            control = dataclasses.replace(control, dt=0.0)
        c, s_ = math.cos(a[2]), math.sin(a[2])
        dx, dy = b[0] - a[0], b[1] - a[1]
        self._delta = np.array([c * dx + s_ * dy, -s_ * dx + c * dy, float(wrap_angle(b[2] - a[2]))])
        return control

    def _allowed_at(self, p: np.ndarray) -> np.ndarray:
        """(N,) bool: the poses the motion model allows (all True without map rejection)."""
        if self.allowed is None:
            return np.ones(p.shape[1], dtype=bool)
        return self.grid.mask_at(self.allowed, p[0], p[1])

    def _draw_around(self, centres: np.ndarray, std: np.ndarray) -> np.ndarray:
        """(3, N) poses ~ N(centres, diag(std^2)) (centres (3,) or (3, N)), drawn again (up to max_tries) where
        the map does not allow them; those never allowed keep the last draw. Always finite."""
        n = self.n
        c = np.broadcast_to(np.asarray(centres, dtype=np.float64).reshape(3, -1), (3, n))
        std = np.asarray(std, dtype=np.float64)[:, None]
        p = c + self.rng.standard_normal((3, n)) * std
        for _ in range(max(self.cfg.motion.max_tries - 1, 0)):
            bad = np.flatnonzero(~self._allowed_at(p))
            if bad.size == 0:
                break
            p[:, bad] = c[:, bad] + self.rng.standard_normal((3, bad.size)) * std
        p[2] = wrap_angle(p[2])
        return np.ascontiguousarray(p)

    def _moved_estimate(self) -> np.ndarray:
        """The last estimate moved by this update's odometry step (the estimate itself before any motion)."""
        m = np.asarray(self.last_estimate.mean, dtype=np.float64)
        d = self._delta if self._delta is not None else np.zeros(3)
        c, s_ = math.cos(m[2]), math.sin(m[2])
        return np.array([m[0] + c * d[0] - s_ * d[1], m[1] + s_ * d[0] + c * d[1], m[2] + d[2]])

    def recover_degenerate(self, info: StepInfo) -> None:
        """Every weight was zero: re-spread around the last estimate (moved by the odometry step), or reinitialise
        globally after _MAX_DEGENERATE_RUN consecutive failures; the new particles get equal weights."""
        self._event("degenerate_weights", "every particle weight is zero (no pose explains the scan); the "
                    "particles are re-spread around the last estimate")
        self._degenerate_run += 1
        k = self._degenerate_run
        if self.last_estimate is None or k > _MAX_DEGENERATE_RUN:
            self.init_global()
            self._degenerate_run = 0
        else:
            centre = self._moved_estimate()
            self._set(self._draw_around(centre, np.asarray(self.cfg.filter.respread_std) * 2.0 ** (k - 1)))
        # Equal weights: the scan that explained nothing is not scored again (re-scoring a bad scan would
        # collapse the fresh cloud onto the few poses that happen to fit it); the next scan decides.
        info.ess = float(self.n)

    def step(self, control: Control | None, observation, landmarks=None) -> StepInfo:
        """One MCL update: predict -> correct -> normalise -> estimate -> resample. Returns what it did."""
        info = StepInfo(particles=self.n)
        self._delta = None
        t0 = time.perf_counter()
        if control is None and self._kld_pending is not None:
            self._kld_draw(None, info)
        if control is not None:
            self.predict(control, info)
        info.particles = self.n
        t1 = time.perf_counter()
        self.correct(observation, info)
        self.correct_landmarks(landmarks, info)
        t2 = time.perf_counter()
        self.normalize(info)
        if info.degenerate:
            self.recover_degenerate(info)
        else:
            self._degenerate_run = 0
        t3 = time.perf_counter()
        info.mean, info.cov = self.estimate()
        est = self.last_estimate
        info.full_mean, info.full_cov = est.full_mean, est.full_cov
        info.clusters, info.cluster_weight = est.n_clusters, est.weight
        info.events, self._step_events = tuple(self._step_events), []
        t4 = time.perf_counter()
        self.maybe_resample(info)
        t5 = time.perf_counter()
        info.timings = {"predict": t1 - t0, "correct": t2 - t1, "estimate": t4 - t3, "resample": (t5 - t4) + (t3 - t2)}
        return info
