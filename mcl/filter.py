"""The particle filter: Monte Carlo localization (Prob. Rob. Table 8.2, MCL).

``ParticleFilter.step`` reads as the algorithm::

    predict    x_t ~ p(x_t | u_t, x_{t-1}, m)     motion model, poses off free space sampled again
    correct    w_t = w_{t-1} p(z_t | x_t, m)       sensor model (and landmarks), in log space
    normalise  log-sum-exp; recover when no particle explains the scan
    estimate   the heaviest cluster's mean and covariance
    assess     the scan laid on the map at the estimate: the quality signal, lost or not
    resample   low variance when ESS / N is low; KLD sizes the new set; recovery injects

The policies are small objects the loop calls, each in its own module:
``InputGuard`` and ``ZeroWeights`` (mcl.degenerate: odometry jumps, time
running backwards, NaN ranges, empty scans; every weight zero),
``KLDSampling`` and the recovery policies ``LostRecovery`` /
``AugmentedMCL`` with the ``GlobalSearch`` state they read, and beside them
``ProtectedReseed`` (a re-seed of a trusted track settled by log-odds,
``protect``), ``ProbationChallenge``, ``StallCheck`` and ``FaultWindow``
(mcl.adaptive), ``BeamSkipping`` and ``UnmappedObjects``
(mcl.sensors) and ``ScanQuality`` (mcl.quality). The filter owns the one
random generator, seeded from the config, so a seed gives the same
trajectory whatever the numba thread count. It does no I/O.

When every weight is zero after a correction (no pose explains the scan) the
particles are re-spread around the last estimate moved by the odometry step,
twice wider each consecutive time; after three consecutive failures, or with
no estimate yet, the filter reinitialises globally. The fresh particles get
equal weights: the scan that explained nothing is not scored again (that
would collapse the new cloud onto the few poses that happen to fit a bad
scan). Re-spreading rather than reinitialising first: a scan no pose explains
is far more often a bad scan or a short glitch than a kidnapping (recovery
handles that), and a global reinitialisation throws away a good track.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from mcl.adaptive import (FaultWindow, GlobalSearch, KLDSampling, OdometryScale, ProbationChallenge, ProtectedReseed,
                          StallCheck, draw_injected, kld_resample, make_recovery, measurement_count)
from mcl.clusters import ClusterEstimate, cluster_estimate
from mcl.config import Config
from mcl.degenerate import EVENT_KINDS, InputGuard, ZeroWeights
from mcl.deskew import SweepOrder
from mcl.estimate import compose, estimate, inverse, moments, wrap_angle
from mcl.kernels.clusters import cache_order
from mcl.kernels.likelihood import refine_poses, refine_poses_serial
from mcl.kernels.raycast import segments_blocked
from mcl.landmarks import LandmarkModel, sample_poses_from_landmark
from mcl.maps import byte_mask
from mcl.motion import allowed_mask, allowed_masks, make_motion_model
from mcl.parallel import choose
from mcl.quality import Fit, ScanQuality
from mcl.resampling import effective_sample_size, normalize_log_weights, resample, temper_to_ess
from mcl.sensors import (BeamSkipping, UnmappedObjects, make_sensor_model, scored_view, sweep_of,
                         valid_returns)

__all__ = ["Control", "StepInfo", "ParticleFilter", "EVENT_KINDS"]


# Uniform draws of at least _CACHE_ORDER_MIN poses are put in cache order (``in_cache_order``): 4 m blocks, then
# 256 heading bins. The poses are the same i.i.d. draws in another order; the systematic resample, which is not
# blind to order, then draws its ancestors stratified over the map (runs differ from draw order's; over the generated
# worlds, seeds 1-6, the global and kidnapped counts within the seeds' noise: fifty-fourth session).
_CACHE_ORDER_MIN = 4096
_CACHE_BLOCK = 4.0
_CACHE_HEADINGS = 256


def in_cache_order(poses: np.ndarray, grid) -> np.ndarray:
    """``poses`` (3, N) reordered by 4 m block of ``grid`` and then by heading (``cache_order``). Scored in draw
    order, poses uniform over a big map send every beam's endpoint to a random cell of a table larger than the
    cache; in this order neighbours gather nearby cells: 2 million poses over a generated large building (a 28 MB
    table), 58 beams, 3.4 s -> 0.5 s, plus 0.2 s of ordering (`scripts/bench.py --section kernels`): a search's
    oversampled candidates (``filter.global_density``), a global start's first update, a re-seed's fresh poses."""
    size = grid.resolution * np.array([grid.width, grid.height], dtype=np.float64)
    nbx, nby = (int(v) for v in np.ceil(size / _CACHE_BLOCK).astype(np.int64) + 1)
    order = cache_order(poses, float(grid.origin[0]), float(grid.origin[1]), 1.0 / _CACHE_BLOCK, nbx, nby,
                        _CACHE_HEADINGS)
    return np.ascontiguousarray(np.take(poses, order, axis=1))


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
    # s since the previous scan, used or gated (None: ``dt``): how long the odometry step took, for the jump test
    # (gated scans stood still, so a step after a long stop is not slow)
    dt_scan: float | None = None
    # the step (or a scan's since the last update) came from the stall fill's scan matching: its travel is uncertain
    # (motion.fill_spread)
    filled: bool = False

    def velocities(self) -> tuple[float, float, float]:
        """(v, w, dt) for a velocity model: as given, or, where v and w are both 0 (a log without tv / rv, a Control
        made from the odometry pair alone, as the README's loop does), from the odometry pair
        (``mcl.motion.velocities_from_odometry``: before, such a step moved no particle)."""
        if self.v == 0.0 and self.w == 0.0:
            from mcl.motion import velocities_from_odometry

            return velocities_from_odometry(self.odom_prev, self.odom_now, self.dt)
        return float(self.v), float(self.w), float(self.dt)


SCALE_PIN = 0.8  # motion.scale_window: a correction that leaves this much of the spread along the travel pins nothing


@dataclass
class StepInfo:
    """What one filter update did, for the logs and the summary."""

    ess: float = 0.0  # effective sample size after the correction, before resampling
    resampled: bool = False
    tries: float = 0.0  # mean motion samples per particle (map-based motion model)
    rejected: int = 0  # particles that never landed in free space (weight zero)
    degenerate: bool = False  # every weight was zero; weights were reset to uniform
    particles: int = 0  # N weighted in this update (KLD sampling changes it at resampling)
    injected: int = 0  # particles drawn from the recovery sampler at this resampling
    reseeded: bool = False  # lost recovery re-seeded globally at this resampling (filter._reseed)
    confirmed: bool = False  # a protected re-seed's search lost to the track it kept, and was dropped (filter.protect)
    switched: bool = False  # a protected re-seed's search won over the track it kept, which was dropped
    stalled: bool = False  # the estimate of a place a search found did not follow the odometry (filter.stall_*)
    inject_p: float = 0.0  # the recovery policy's injection probability after this update
    mean: np.ndarray | None = None  # the estimate (x, y, theta), from the weighted set before resampling
    cov: np.ndarray | None = None  # its 3x3 covariance
    full_mean: np.ndarray | None = None  # the whole weighted set's mean (= mean when the cloud is one cluster)
    full_cov: np.ndarray | None = None  # the whole set's 3x3 covariance: its spread
    clusters: int = 1  # clusters in the cloud (filter.estimate = cluster)
    cluster_weight: float = 1.0  # weight of the heaviest cluster, whose mean is the estimate
    fit: Fit | None = None  # the scan laid on the map at the estimate (mcl.quality); None without a laser scan
    lost: bool = False  # the filter believes it is lost (mcl.quality)
    faults: bool = False  # the motion of this update was in an odometry-fault window (motion.fault_*, FaultWindow)
    skipped_beams: int = 0  # beams ignored by beam skipping
    skipped_endpoints: np.ndarray | None = None  # (2, skipped_beams) their robot-frame endpoints (None: none skipped)
    events: tuple[str, ...] = ()  # degenerate-input events of this update (kinds of ParticleFilter.events)
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage
    # the set as this update weighted it (particles, weights), kept when this update's resampling replaced it (a
    # re-seed, a protected re-seed's resample, a fixed-N resample): what the recording draws
    weighted: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def quality(self) -> float:
        """The quality signal: the fraction of beams that match the map at the estimate (nan without a scan)."""
        return self.fit.match if self.fit is not None else math.nan


_MAX_OVERSAMPLE = 20  # global_density: at most this many candidates per fresh pose (2 million for 100,000)
# search_refine_candidates: the best this many candidates per fresh pose (as drawn) are matched. 1 against 2
# (fifty-eighth session): one more generated world's global run in, none out on the corpora measured, the worst
# kidnapped run on a 200 m building 71 -> 39 s of CPU (docs/measurements.md, "Fifty-eighth session")
_MATCHED_PER_FRESH = 1


def top_k(values: np.ndarray, k: int) -> np.ndarray:
    """Indices of the ``k`` largest ``values`` (0 < k < size; no NaN, as ``_laser_loglik`` gives: -inf for a pose it
    rules out), in index order; of equal values at the cut, the first.

    Not ``np.argpartition``: which of several equal values it picks depends on the SIMD code numpy runs (AVX-512 or
    not), and a global search's candidates often tie (every beam off the map); one candidate more or less moved a
    search on one machine and not on the other. The k-th largest value itself is the same everywhere."""
    kth = np.partition(values, values.size - k)[values.size - k]
    above = np.flatnonzero(values > kth)
    return np.sort(np.concatenate([above, np.flatnonzero(values == kth)[: k - above.size]]))



def _start_array(name: str, value, shape: tuple) -> np.ndarray:
    """A start pose's mean, std or covariance as float64 of ``shape``; ValueError naming it otherwise, or when it is
    not finite (a NaN start gave every estimate NaN, and ``init_gaussian(mean, 0.1)`` an IndexError)."""
    a = np.asarray(value, dtype=np.float64)
    if a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: expected finite numbers, got {a.tolist()}")
    return a

class ParticleFilter:
    """MCL over a (3, N) particle array with log weights."""

    def __init__(self, cfg: Config, grid, *, rng: np.random.Generator | None = None, landmark_map=None,
                 plane_model=None):
        self.cfg = cfg
        self.grid = grid
        self.rng = rng if rng is not None else np.random.default_rng(cfg.seed)
        fc = cfg.filter
        self.motion = make_motion_model(cfg.motion)
        mu = cfg.motion.map_unknown
        self.allowed = self._fallback = None
        if cfg.motion.map_rejection:
            # the free cells clear of walls (with map_unknown: free, the unknown ones too); and where a particle that
            # never landed on free space may stay (map_unknown: fallback): an unknown cell clear of walls
            if mu == "fallback":
                self.allowed, self._fallback = allowed_masks(grid, cfg.motion.robot_radius, (False, True))
            else:
                self.allowed = allowed_mask(grid, cfg.motion.robot_radius, mu == "free")
        self.sensor = make_sensor_model(grid, cfg.sensor)
        # the policies
        self.guard = InputGuard(fc.max_odom_step, fc.max_odom_ratio, fc.max_odom_speed)
        self.kld = KLDSampling(fc, grid) if fc.kld else None
        # a global start or re-seed until one place is left
        self.search = GlobalSearch(settled_std=fc.search_settled_std, probation_from=fc.recovery_probation_from)
        # odometry faults allowed only around a lost call on a track that had held (motion.fault_*)
        self.faults = FaultWindow(cfg.motion, self.search) if cfg.motion.fault_prob > 0.0 else None
        # a place a search found whose estimate does not follow the odometry is re-seeded (filter.stall_*)
        self.stall = (StallCheck(fc.stall_ratio, fc.stall_window, fc.stall_travel, fc.stall_active, self.search)
                      if fc.stall_ratio > 0.0 else None)
        # a place a search found that fits poorly on probation is challenged once (filter.probation_fit), only where
        # a re-seed runs protected (reseed_odds > 0; and lost recovery with recovery_reseed, checked as it runs)
        self.challenge = (ProbationChallenge(fc.probation_fit, self.search)
                          if fc.probation_fit > 0.0 and fc.reseed_odds > 0.0 else None)
        self._odom = None  # this update's odometry pose (x, y, theta), None without motion (the stall test)
        # the odometry's translation scale learnt online (motion.scale_window); this update's step for it
        mc = cfg.motion
        self.odom_scale = (OdometryScale(mc.scale_window, mc.scale_prior, mc.scale_limit)
                           if mc.scale_window > 0.0 else None)
        self._scale_step = None  # (direction of travel on the map (2,), odometry step m, scale used)
        self.recovery = self._make_recovery(True)  # set again by init_gaussian / init_global
        self._fresh = None  # (N,) bool: uniform poses of a global start or re-seed not yet scored (global_oversample)
        self._match_mask = None  # cells the search's scan matching may move a particle into (search_refine)
        self._known = None  # uint8 mask of the known cells (free or occupied), made on first use (unmapped_unknown)
        self.skipping = (BeamSkipping(self.sensor, cfg.sensor)
                         if cfg.sensor.beam_skip and hasattr(self.sensor, "skip_mask") else None)
        self.quality = ScanQuality(grid, cfg.quality, cfg.sensor.max_beams)
        self.unmapped = (UnmappedObjects(grid, cfg.sensor, dist=self.quality.dist)
                         if cfg.sensor.unmapped_skip and cfg.sensor.model == "likelihood_field" else None)
        self._unmapped_candidates = None  # (observation, (K,) bool, scan) of the scan last prepared
        # which way a deskewed scan's beams run in time (mcl.deskew; the likelihood field alone moves endpoints)
        self.sweep_order = SweepOrder() if cfg.sensor.model == "likelihood_field" else None
        self._sweep_candidates = None  # (as stamped, at once, reversed) observations of the scan last prepared
        self.blind_updates = 0  # updates whose every return was skipped with nothing mapped in view (unmapped_blind)
        # Recovery draws injected poses from this: sampler(n, rng, observation) -> (3, n). Uniform over the free
        # space the motion model allows unless replaced (a landmark-based pose sampler when landmarks are used).
        self.recovery_sampler = self.sample_uniform
        n = fc.particles
        self.particles = np.zeros((3, n))
        self.logw = np.full(n, -np.log(n))
        self.weights = np.full(n, 1.0 / n)
        self.degenerate_events = 0
        self.zero_weights = ZeroWeights(fc.respread_std)  # every weight zero: re-spread, then start again
        self._delta = None  # this update's odometry step in the robot frame, for re-spreading
        self._dt = 0.0  # this update's log time since the previous one (lost recovery's clock)
        self.last_estimate: ClusterEstimate | None = None
        self._observation = None  # the last scan's observation (the recovery sampler may use it)
        self._scan_observation = None  # this update's full observation, before beam skipping (for the quality)
        self.floor_tempered = 0  # updates whose scan filter.ess_floor tempered (_temper_to_floor)
        self._slip_moved = False  # this update's motion drew from a slip's proposal (predict, _weigh_motion)
        self._floor_part = None  # this update's laser log-likelihood while ess_floor may temper it (correct)
        self._prepared_scan = None  # the scan last prepared (prepare)
        self._laser_pose = np.zeros(3)  # of the scan last prepared (beam skipping and the quality walk from there)
        self._injected = None  # (N,) bool: particles injected at the last resample (left out of w_avg)
        # a protected re-seed while it runs (filter.reseed_odds; its track mask selects the kept track), else None
        self.protected: ProtectedReseed | None = None
        # (mean, cov) of the old estimate an unprotected re-seed kept, its mean moved by the odometry, reported until
        # the filter is no longer lost (filter.reseed_hold_pose, _report_held)
        self._held: tuple[np.ndarray, np.ndarray] | None = None
        # Landmarks (cfg.landmarks, mcl.landmarks): a model when a landmark map is given; injections then come
        # from the latest landmark observation (Prob. Rob. Table 6.5) when it has a known id.
        self.landmarks = LandmarkModel(landmark_map, cfg.landmarks) if landmark_map is not None else None
        self._marks = None
        if self.landmarks is not None:
            self.recovery_sampler = self.sample_from_landmarks
        self.planes = plane_model  # mcl.planes.PlaneModel (cfg.planes), or None

    # ------------------------------------------------------------------ state

    @property
    def n(self) -> int:
        return self.particles.shape[1]

    @property
    def events(self) -> dict[str, int]:
        """Degenerate-input events per kind (mcl.degenerate)."""
        return self.guard.events

    @property
    def converged(self) -> bool:
        """Beam skipping's test: the heaviest cluster holds the weight and is tight (False without skipping)."""
        return self.skipping is not None and self.skipping.converged

    @property
    def lost(self) -> bool:
        """Whether the filter believes it is lost (mcl.quality)."""
        return self.quality.lost

    def _set(self, particles: np.ndarray) -> None:
        self._injected = None
        self._fresh = None
        self.protected = None
        self.particles = particles
        n = particles.shape[1]
        self.logw = np.full(n, -np.log(n))
        self.weights = np.full(n, 1.0 / n)

    # ------------------------------------------------------------------ initialisation

    def init_gaussian(self, mean, std) -> None:
        """Particles drawn from N(mean, diag(std^2)): tracking from a known pose."""
        mean, std = _start_array("mean", mean, (3,)), _start_array("std", std, (3,))
        if np.any(std < 0.0):
            raise ValueError(f"std: expected stds >= 0, got {std.tolist()}")
        n = self.cfg.filter.particles
        p = self.rng.standard_normal((3, n)) * std[:, None]
        p += mean[:, None]
        p[2] = wrap_angle(p[2])
        self._set(np.ascontiguousarray(p))
        self._start_tracking()

    def _start_tracking(self) -> None:
        """The policies start afresh for a track from a known pose: not lost, no search, nothing on probation."""
        self._held = None
        self.recovery = self._make_recovery(False)
        self.search.reset()
        self.quality.reset(lost=False)
        for policy in (self.faults, self.stall, self.challenge):
            if policy is not None:
                policy.reset()

    def kidnap(self, mean, std) -> None:
        """Particles replaced by N(mean, diag(std^2)) with the policies untouched (recovery averages, lost
        belief): the filter is not told. The kidnapping test of ``mcl eval --suite`` on real logs. The estimate
        is the cloud's, so there is none until the next update makes it: the one from before would still be the
        true pose, and the policies that look from the estimate (beam skipping, unmapped objects) would judge the
        scan from where the particles no longer are."""
        p = self.rng.standard_normal((3, self.n)) * np.asarray(std, dtype=np.float64)[:, None]
        p += np.asarray(mean, dtype=np.float64)[:, None]
        p[2] = wrap_angle(p[2])
        self._set(np.ascontiguousarray(p))
        self.last_estimate = None

    def init_gaussian_cov(self, mean, cov) -> None:
        """Particles drawn from N(mean, cov) with a full 3x3 covariance (x, y, theta), e.g. a ROS /initialpose:
        mean + S z with S S^T = cov (symmetric square root, so a singular cov is fine)."""
        mean, c = _start_array("mean", mean, (3,)), _start_array("cov", cov, (3, 3))
        c = 0.5 * (c + c.T)
        w, v = np.linalg.eigh(c)
        root = (v * np.sqrt(np.clip(w, 0.0, None))) @ v.T
        n = self.cfg.filter.particles
        p = root @ self.rng.standard_normal((3, n)) + mean[:, None]
        p[2] = wrap_angle(p[2])
        self._set(np.ascontiguousarray(p))
        self._start_tracking()

    def init_global(self) -> None:
        """Particles uniform over the poses the map allows (global localization)."""
        self._set(self.sample_uniform(self.cfg.filter.particles, self.rng))
        self._fresh = np.ones(self.n, dtype=bool)
        self._start_global()

    def _start_global(self) -> None:
        self._held = None
        if self.cfg.filter.recovery == "auto" and self.recovery is None:
            self.recovery = self._make_recovery(True)
        self.search.start()
        if hasattr(self.sensor, "search_table"):  # the search's field, made now (a map-sized table) and not
            self.sensor.search_table()  # inside the first update's correction
        if self.recovery is not None and hasattr(self.recovery, "start_search"):
            self.recovery.start_search()
        # lost until the scans fit: without a laser (landmarks or planes alone) no scan ever could, so the search
        # is not called lost (a landmark-only run stayed lost throughout: 125 re-seeds, 200,000 particles held)
        self.quality.reset(lost=bool(self.cfg.sensor.use))

    def _make_recovery(self, global_start: bool):
        return make_recovery(self.cfg.filter, global_start, self.cfg.quality.lost_after, search=self.search,
                             stall=self.stall)

    def sample_uniform(self, n: int, rng: np.random.Generator, observation=None) -> np.ndarray:
        """(3, n) poses uniform over free space, with the robot-radius clearance when map rejection is on."""
        clearance = self.cfg.motion.robot_radius if self.cfg.motion.map_rejection else 0.0
        poses = self.grid.sample_free(n, rng, clearance=clearance)
        return in_cache_order(poses, self.grid) if n >= _CACHE_ORDER_MIN else poses

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
        bad = np.flatnonzero(~self._allowed_at(p) | ~self._free_at(p))
        if bad.size:  # never allowed (a landmark mistyped off the map, a huge sigma_range): uniform over free space,
            # not kept where they fell (a global start's estimate began 700 m off a 20 m map)
            p[:, bad] = self.sample_uniform(bad.size, rng, observation)
        return np.ascontiguousarray(p)

    def init_from_landmarks(self, marks) -> bool:
        """Global localization seeded by landmarks: particles drawn from the observations of ``marks`` (a
        ``Landmarks`` record), shared evenly over those with known ids. False (nothing drawn) if none is known."""
        if self.landmarks is None or not np.any(self.landmarks.map.index_of(marks.ids) >= 0):
            return False
        self._set(self.sample_from_landmarks(self.cfg.filter.particles, self.rng, marks=marks))
        self._start_global()
        return True

    # ------------------------------------------------------------------ inputs

    def prepare(self, scan, laser_pose):
        """The sensor model's observation for a scan, or None when the scan has no usable reading
        (counted: ``nan_ranges``, ``empty_scans``)."""
        if not self.guard.usable_scan(scan):
            return None
        self._laser_pose = np.asarray(laser_pose, dtype=np.float64)
        self._prepared_scan = scan  # the quality signal's missing test reads its readings (_with_missing)
        self.quality.view(scan.angles)  # a narrow view's occlusion thresholds (quality.narrow_view)
        self._sweep_candidates = None
        if self.sweep_order is not None and sweep_of(scan) is not None:
            # a deskewed scan (mcl.deskew): as read until the beams' timing is decided, three readings weighed
            scan, orders = self.sweep_order.choose(scan)
            if orders is not None:  # (as stamped, as read, reversed): the second is the observation used
                self._sweep_candidates = tuple(self.sensor.prepare(o, laser_pose) for o in orders)
        observation = (self._sweep_candidates[1] if self._sweep_candidates is not None
                       else self.sensor.prepare(scan, laser_pose))
        if self.unmapped is not None:
            self._unmapped_candidates = (observation, self.unmapped.candidates(scan), scan)
        return observation

    def time_backwards(self, dt: float) -> None:
        """Count (and warn once about) time running backwards between updates."""
        self.guard.time_backwards(dt)

    # ------------------------------------------------------------------ the loop

    def step(self, control: Control | None, observation, landmarks=None, planes=None) -> StepInfo:
        """One MCL update: predict -> correct -> normalise -> estimate -> assess -> resample."""
        info = StepInfo(particles=self.n)
        clock = [time.perf_counter()]

        def lap():
            clock.append(time.perf_counter())
            return clock[-1] - clock[-2]

        self.predict(control, info)
        info.particles = self.n
        prior = self._along(self.logw) if self._scale_step is not None else None
        t_predict = lap()
        self.correct(observation, info)
        self.correct_landmarks(landmarks, info)
        self.correct_planes(planes, info)
        t_correct = lap()
        self.normalize(info)
        self.protect(info)
        t_normalize = lap()
        self.estimate(info)
        self.assess(info)
        self._report_held(info)
        if prior is not None:
            self._learn_scale(prior, info)
        info.events = self.guard.take_step_events()
        t_estimate = lap()
        self.resample(info)
        t_resample = lap()
        info.timings = {"predict": t_predict, "correct": t_correct, "estimate": t_estimate,
                        "resample": t_resample + t_normalize}
        if control is None:  # the first update moves nothing: no prediction ran, none is timed
            del info.timings["predict"]
        return info

    def predict(self, control: Control | None, info: StepInfo) -> None:
        """x_t ~ p(x_t | u_t, x_{t-1}, m): sample the motion model, rejecting poses off free space.

        A scheduled KLD resample is drawn here, with this motion (Table 8.4).
        An odometry jump is not applied (the particles are re-spread instead);
        a negative dt becomes 0; particles the motion model made non-finite
        keep their previous pose with weight zero. ``control`` None (the first
        update) moves nothing.
        """
        self._delta = None
        self._slip_moved = False  # this update's motion drew from a slip's proposal (motion.slip_turn, _weigh_motion)
        self._dt = float(control.dt) if control is not None else 0.0  # log time since the last update (recovery)
        self._odom = None
        self._scale_step = None
        if control is not None:
            control, self._delta = self.guard.check_control(control)
            if self._delta is None:  # a jump: not motion to trust (no odometry pose for the stall test either)
                self._delta = np.zeros(3)
                if self.kld is not None and self.kld.pending is not None:
                    self._kld_draw(None, info)
                self._hedge_jump(control, info)
                return
        moved = control
        if self.odom_scale is not None and control is not None:
            moved = self.odom_scale.scaled(control)
            self._scale_step = self._travel(control)
        if self.kld is not None and self.kld.pending is not None:
            new, ok, tries, lw = self._kld_draw(moved, info)
            if control is None:
                return
        elif control is None:
            return
        else:
            new, ok, tries, lw = self._move(self.particles, moved)
        self._odom = control.odom_now
        self.particles = new
        info.tries = float(tries)
        self._weigh_motion(self.logw, ok, lw, info)

    def _travel(self, control: Control):
        """(direction of travel on the map (2,), odometry step in m, the scale it is stretched by) of an odometry
        step, for ``OdometryScale``: the step in the odometry's frame at its start, turned by the last estimate's
        heading. None without an estimate or without translation."""
        if self.last_estimate is None:
            return None
        prev = np.asarray(control.odom_prev, dtype=np.float64)
        step = compose(inverse(prev), np.asarray(control.odom_now, dtype=np.float64))  # in the robot's frame at its start
        d = math.hypot(step[0], step[1])
        if not d > 1e-4:
            return None
        on_map = compose(np.array([0.0, 0.0, float(self.last_estimate.mean[2])]), step)
        return on_map[:2] / d, d, self.odom_scale.k

    def _along(self, logw: np.ndarray) -> tuple[float, float] | None:
        """The set's weighted mean and variance (m, m2) along this update's direction of travel (``_scale_step``)
        under log-weights ``logw`` (None: no finite weight)."""
        w, log_norm = normalize_log_weights(logw)
        if not math.isfinite(log_norm):
            return None
        # einsum, not BLAS: a sum over N whose order does not change with the thread count (effective_sample_size)
        a = np.einsum("i,in->n", self._scale_step[0], self.particles[:2])
        mean = float(np.einsum("n,n->", a, w))
        return mean, float(np.einsum("n,n->", (a - mean) ** 2, w))

    def _learn_scale(self, prior: tuple[float, float], info: StepInfo) -> None:
        """Feed ``OdometryScale`` this update's shift of the mean along the direction of travel (the correction's
        doing: ``prior`` is the mean and variance along it after the prediction), on a track the filter trusts (not
        lost, scored, no search, no probation, no protected re-seed, no odometry-fault window) and only where the
        scan pinned the pose along the direction of travel: the correction shrank the cloud's spread along it below
        ``SCALE_PIN`` of the prediction's. Along a featureless corridor it does not, and the few centimetres the
        mean moves there are resampling's noise, not the odometry's error."""
        fit = info.fit
        trusted = (not info.lost and fit is not None and fit.beams >= self.cfg.quality.min_beams
                   and not self.search.tempering and not self.search.holding and self.protected is None
                   and not getattr(self.recovery, "on_probation", False)
                   and (self.faults is None or not self.faults.open))
        post = self._along(self.logw) if trusted else None
        if post is None or not post[1] < SCALE_PIN * prior[1]:
            return
        _, d, k = self._scale_step
        self.odom_scale.observe(post[0] - prior[0], d, k)

    def _weigh_motion(self, logw: np.ndarray, ok, lw, info: StepInfo) -> None:
        """Fold a motion's outcome into the log-weights ``logw`` of the particles it moved (in place: the set's, or
        a view of its moved part): the odometry-fault proposal's importance weights ``lw``, and weight zero where
        the map rejected every try (``ok`` False)."""
        if lw is not None:
            logw += lw
            self._slip_moved = self._slip_moved or not self.faults.open  # a slip's proposal (outside a window)
            info.faults = info.faults or self.faults.open  # a window (a slip outside it is not counted)
        if ok is not None and not ok.all():
            bad = ~ok
            info.rejected = int(np.count_nonzero(bad))
            logw[bad] = -np.inf

    def _hedge_jump(self, control: Control | None, info: StepInfo) -> None:
        """An odometry jump: a glitch (the robot did not move so) or real motion (a log with a scan every few
        metres). Every other particle takes the step ``control`` (None: non-finite odometry, none does), the
        others are re-spread by ``respread_std`` where they were; the scan then weighs the two halves."""
        std = np.asarray(self.cfg.filter.respread_std)
        if control is None:
            self.particles = self._draw_around(self.particles, std)
            return
        stay, go = self.particles[:, 0::2], np.ascontiguousarray(self.particles[:, 1::2])
        new = np.empty_like(self.particles)
        new[:, 0::2] = self._draw_around(stay, std, stay.shape[1])
        new[:, 1::2], ok, _, lw = self._move(go, control)
        self._weigh_motion(self.logw[1::2], ok, lw, info)  # a view: the moving half's weights
        self.particles = new

    def _move(self, particles: np.ndarray, control: Control):
        """(moved (3, N), ok (N,) bool | None, mean tries, log-weights (N,) | None): the motion model applied to
        ``particles``, with the odometry-fault proposal while ``faults`` allows it (then the particles' importance
        log-weights, else None); a non-finite sample keeps its ancestor's pose and is not ok (weight zero)."""
        fault = self.faults.proposal(float(control.dt)) if self.faults is not None else None
        lw = np.empty(particles.shape[1]) if fault is not None else None
        new, ok, tries = self.motion.sample_control(particles, control, self.rng, allowed=self.allowed,
                                                    grid=self.grid, fault=fault, log_weight=lw,
                                                    fallback=self._fallback)
        fin = np.isfinite(new).all(axis=0)
        if not fin.all():
            new[:, ~fin] = particles[:, ~fin]
            ok = fin if ok is None else ok & fin
        return new, ok, tries, lw

    def _kld_draw(self, control: Control | None, info: StepInfo):
        """Draw the scheduled KLD resample (moved by ``control`` when there is one); the new set replaces the
        particles with equal weights. Returns (particles, ok, tries, log-weights | None) of the motion."""
        move = (lambda batch: self._move(batch, control)) if control is not None else None
        new, fresh, ok, tries, lw = self.kld.draw(self.particles, self.logw, self.rng, move=move)
        self._set(new)
        info.injected = int(np.count_nonzero(fresh))
        self._injected = fresh if info.injected else None
        return new, ok, tries, lw

    def correct(self, observation, info: StepInfo | None = None) -> None:
        """w_t = w_{t-1} * p(z_t | x_t, m), in log space. ``observation`` comes from :meth:`prepare`.

        With beam skipping and a converged filter, the beams most particles
        cannot explain are dropped first. A NaN or +inf log-likelihood counts
        as weight zero.
        """
        self._scan_observation = observation
        self._floor_part = None
        if observation is None:
            return
        self._weigh_sweep_orders()
        if self._tracking_unmapped(observation):
            observation, skipped, self._scan_observation = self._skip_unmapped(observation)
            if skipped is not None and info is not None:
                info.skipped_beams = skipped.shape[1]
                info.skipped_endpoints = skipped
        if self.skipping is not None and self.last_estimate is not None:
            observation, skipped = self.skipping.select(self.particles, self.weights, observation,
                                                        self._moved_estimate(), self._laser_pose[:2])
            if skipped is not None and info is not None:
                info.skipped_beams += skipped.shape[1]
                info.skipped_endpoints = (skipped if info.skipped_endpoints is None
                                          else np.hstack([info.skipped_endpoints, skipped]))
        fc = self.cfg.filter
        fresh = self._fresh if self._fresh is not None and self._fresh.size == self.n else None
        # the fresh poses of a global start or re-seed that _oversample_fresh draws anew from scored candidates: not
        # matched or scored here (a big map's first search update spent 64-80 % of its time on them)
        anew = fresh is not None and fresh.any() and self._oversample_count(int(fresh.sum())) > 1
        rest = np.flatnonzero(~fresh) if anew else None
        matching = bool(fc.search_refine and self.search.tempering)
        if matching and fc.search_refine_scope == "tempering" and (rest is None or rest.size):
            self._match_scan(observation, rest)
        elif matching and fresh is not None and not anew:  # scope "fresh": the fresh poses as they are
            self._match_scan(observation, np.flatnonzero(fresh))
        if rest is None:
            loglik = self._laser_loglik(self.particles, observation)
        else:
            loglik = np.full(self.n, -np.inf)
            if rest.size:
                loglik[rest] = self._laser_loglik(self.particles[:, rest], observation)
        if self._fresh is not None:
            drawn = self._oversample_fresh(observation, loglik)
            if drawn is None:  # no candidate scored: the fresh poses matched and scored as they are, as without
                idx = np.flatnonzero(fresh)
                if matching and fc.search_refine_scope == "tempering":
                    self._match_scan(observation, idx)
                loglik[idx] = self._laser_loglik(self.particles[:, idx], observation)
            else:
                loglik = drawn
        if self.recovery is not None:
            self.recovery.observe_likelihood(self.logw, loglik / max(measurement_count(observation), 1),
                                             self._injected)
        self._observation = observation
        # filter.ess_floor: normalize tempers this scan if it leaves too few effective particles (not while a search
        # runs, nor from a lost call until the filter is no longer lost: _laser_searching; nor after a motion with a
        # slip's proposal, whose few turned poses must be free to take the set at the first scan that tells)
        self._floor_part = (loglik if fc.ess_floor > 0.0 and not self._laser_searching() and not self._slip_moved
                            else None)
        self.logw += loglik

    SWEEP_MATCH_STEPS = 10  # Gauss-Newton steps fitting each reading of a deskewed scan to the map (mcl.deskew)
    MATCH_STEP_XY = 0.15  # m: the most one scan-matching step moves a particle (search_refine)
    MATCH_STEP_THETA = 0.08  # rad

    def _match_scan(self, observation, idx: np.ndarray | None = None) -> None:
        """``filter.search_refine``: while a global search tempers, every particle takes that many Gauss-Newton
        steps that fit the scan's endpoints to the map's distance field (``refine_poses``) before the scan weighs
        it. A search's poses are sparse (100,000 over a 150 m corridor: one per 0.3 m x 0.3 m x 6 degrees), so a
        place's weight says as much about how near to its best pose a particle happened to fall as about the
        place; matched, each place is weighed at its best pose (the scan-matched proposal of Grisetti et al.'s
        GMapping, without its weight correction: a search heuristic, like the tempering). With
        ``search_refine_scope: fresh`` only the fresh uniform poses of a global start or re-seed are matched (``idx``),
        once, before their first scan: a kept track is not moved, and the cost is one matching per search."""
        out = self._refined(self.particles if idx is None else self.particles[:, idx], observation,
                            int(self.cfg.filter.search_refine))
        if idx is None:
            self.particles = out
        else:
            self.particles[:, idx] = out

    def _refined(self, poses: np.ndarray, observation, steps: int) -> np.ndarray:
        """(3, N) ``poses`` after ``steps`` Gauss-Newton steps fitting ``observation``'s endpoints to the map's
        distance field (``refine_poses``; endpoints farther than ``filter.search_refine_dist`` from a wall left out;
        under 3 endpoints move nothing)."""
        if self._match_mask is None:  # where a search may move a hypothesis: free cells (clear of walls under rejection)
            self._match_mask = (byte_mask(self.grid.free) if self.allowed is None
                                else self.allowed if self.cfg.motion.map_unknown != "free"
                                else allowed_mask(self.grid, self.cfg.motion.robot_radius))
        e = np.asarray(self.sensor.endpoints(observation), dtype=np.float64)  # (2, K)
        inv_res = 1.0 / float(self.grid.resolution)
        poses = np.ascontiguousarray(poses)
        out = np.empty_like(poses)
        kernel = choose(refine_poses, refine_poses_serial, poses.shape[1] * e.shape[1] * steps)
        kernel(poses, np.ascontiguousarray(e * inv_res), self.grid.distance,
               float(self.grid.origin[0]), float(self.grid.origin[1]), inv_res,
               float(self.cfg.filter.search_refine_dist), steps, self.MATCH_STEP_XY, self.MATCH_STEP_THETA,
               self._match_mask, out)
        return out

    def _weigh_sweep_orders(self) -> None:
        """``mcl.deskew.SweepOrder``: while a tracked set (an estimate, no search, not lost) waits for the scan's
        beams' timing, each reading's laser log-likelihood at its own best pose: the estimate moved by the odometry,
        then ``SWEEP_MATCH_STEPS`` Gauss-Newton steps fitting that reading to the map (``refine_poses``). Weighed at
        the particles instead, the reading the set was corrected with wins: the set has fitted it."""
        orders, self._sweep_candidates = self._sweep_candidates, None
        if orders is None or self.last_estimate is None or self._laser_searching() or self.quality.lost:
            return
        start = self._moved_estimate().reshape(3, 1)
        self.sweep_order.weigh([float(self.sensor.log_likelihood(self._refined(start, o, self.SWEEP_MATCH_STEPS), o)[0])
                                for o in orders])

    def _tracking_unmapped(self, observation) -> bool:
        """Whether ``unmapped`` skips beams of this observation: on, prepared by :meth:`prepare`, and tracking (an
        estimate, no global search under way, not lost, and not lost in the last ``sensor.unmapped_after`` updates;
        a track started from a known pose counts as held)."""
        if not (self.unmapped is not None and self.last_estimate is not None
                and self._unmapped_candidates is not None and self._unmapped_candidates[0] is observation
                and not self._laser_searching() and not self.quality.lost):
            return False
        # Not within unmapped_after updates of a lost call (a kidnap, a global search, a slip): the place found since
        # has fit a few scans only, and at a look-alike room the walls fit while the furniture does not; skipping the
        # furniture's beams (small segments off the map) would throw away what tells the rooms apart
        since = self.quality.since_lost
        return since is None or since >= self.cfg.sensor.unmapped_after

    def _skip_unmapped(self, observation):
        """``unmapped.select`` from the estimate moved by this update's odometry, if the rest of the scan fits the
        map there: the kept beams' quality score (``mcl.quality``: match - 2 contradiction) at least
        ``sensor.unmapped_fit``. At the true pose the rest fits (real logs and corridor-05: score >= 0.87 in 99 % of
        the scans with a skip, >= 0.96 in 95 %); at a look-alike place a global search settled on it does not
        (intel_lab: 0.56-0.91), and skipping what does not fit there would help the filter stay (intel_lab's global
        run converged at 251 s instead of 92 s); after a kidnap neither fits. First, ``sensor.unmapped_unknown``:
        the beams that run over unknown cells only (``_on_unknown``: a region the map never saw, whose walls are no
        misfit) go, and leave the quality signal's view, when the rest fits as well. Returns (the observation to
        score, the skipped endpoints or None, the observation the quality signal weighs: the whole scan, less the
        beams on unknown cells, and on a blind update (``sensor.unmapped_blind``, below, or every beam on unknown
        cells) the scored beams alone: no person either)."""
        _, candidates, scan = self._unmapped_candidates
        if observation.shape[1] == 0:
            return observation, None, observation
        pose = self._moved_estimate()
        unknown, beams = None, None  # the beams skipped on unknown cells; the scan's beams left ((K,) bool, None: all)
        if self.cfg.sensor.unmapped_unknown:
            on = self._on_unknown(observation, pose)
            rest = np.require(observation[:, ~on], requirements="C") if on.any() else None
            # skipped when the rest fits the map at the estimate (or nothing is left): at a wrong place the rest does
            # not, and the whole scan stays in the quality signal's view to call it lost
            if rest is not None and (rest.shape[1] == 0 or self.quality.fit(pose, rest, self._laser_pose[:2]).score
                                     >= self.cfg.sensor.unmapped_fit):
                unknown, observation, beams = observation[:, on], rest, ~on
                if observation.shape[1] == 0:
                    self.blind_updates += 1
                    return observation, unknown, observation
        kept, skipped, blind = (self._skip_unmapped_of(observation, candidates, scan, pose, beams)
                                if candidates is not None else (observation, None, False))
        if unknown is not None:
            skipped = unknown if skipped is None else np.hstack([unknown, skipped])
        return kept, skipped, (kept if blind else observation)

    def _on_unknown(self, observation, pose) -> np.ndarray:
        """(K,) bool: the beams of ``observation`` that, seen from ``pose``, run from the laser to their endpoint over
        unknown map cells only: the laser stands in a region the map never saw, and so does what it hit. A beam that
        crosses a known cell says something the map can weigh and is kept: through a mapped wall into the grey beyond
        it (an estimate a little off: the evidence that corrects it), or along a mapped corridor into the grey at its
        end (a junction's opening, which places the robot along the corridor; infinite_corridor at 25 s)."""
        g = self.grid
        x, y, th = (float(v) for v in pose[:3])
        lx, ly = float(self._laser_pose[0]), float(self._laser_pose[1])
        # a laser on a known cell (a robot on mapped floor: every shared log) starts every beam on one: none qualifies
        c, s = math.cos(th), math.sin(th)
        # the laser's cell (mcl.estimate.compose written out: this runs every tracked update)
        fx = (x + c * lx - s * ly - g.origin[0]) / g.resolution
        fy = (y + s * lx + c * ly - g.origin[1]) / g.resolution
        if not (0.0 <= fx < g.width and 0.0 <= fy < g.height) or g.free[int(fy), int(fx)] \
                or g.occupied[int(fy), int(fx)]:  # off the map (or NaN): no region to speak of
            return np.zeros(observation.shape[1], dtype=bool)
        on = g.mask_at(g.unknown, x + c * observation[0] - s * observation[1],
                       y + s * observation[0] + c * observation[1])
        if on.any():
            if self._known is None:
                self._known = byte_mask(~g.unknown)
            idx = np.flatnonzero(on)
            crosses = np.zeros(idx.size, dtype=np.bool_)
            segments_blocked(x, y, th, lx, ly, np.ascontiguousarray(observation[:, idx]), self._known,
                             float(g.origin[0]), float(g.origin[1]), float(g.resolution), crosses)
            on[idx[crosses]] = False
        return on

    def _skip_unmapped_of(self, observation, candidates, scan, pose, beams=None):
        """``_skip_unmapped``'s small segments off the map from ``pose``: ``observation`` holds the ``beams`` ((K,)
        bool, None: all) of the prepared scan, ``candidates`` is over all of them."""
        if candidates is None or observation.shape[1] == 0:
            return observation, None, False
        if beams is not None:
            candidates = candidates[beams]
        # ``sensor.unmapped_blind``: with no mapped obstacle in the laser's view from the estimate (open floor, a
        # short-range laser in a hall), the returns off the map are people or furniture whatever their share of the
        # scan, and there is no rest to fit: matched to the map anyway, they pull the cloud to wherever they line up
        # with a wall or a pillar. They are skipped; with nothing left the update only predicts (dead reckoning),
        # and the quality signal has no evidence for or against the place. The cast is made only when a return
        # lies that far off the map.
        far = max(self.cfg.sensor.unmapped_distance, self.unmapped.BLIND_DISTANCE)
        blind = (self.cfg.sensor.unmapped_blind and self.unmapped.any_far(observation, pose, far)
                 and self.unmapped.blind(pose, self._laser_pose, scan, self.quality.blocked,
                                         self.cfg.quality.min_beams))
        if blind:
            # then a return off the map is an object the map lacks, a person close by or a group too (segments up to
            # BLIND_WIDTH); a longer one is a wall, which says the estimate is wrong, and is kept
            candidates = self.unmapped.candidates(scan, self.unmapped.BLIND_WIDTH)
            if beams is not None and candidates is not None:
                candidates = candidates[beams]  # the beams left after those on unknown cells (they were over all)
        elif not candidates.any():
            return observation, None, False
        kept, skipped = self.unmapped.select(
            observation, candidates, pose, lambda: self._unmapped_shifts(pose), whole=blind,
            distance=self._blind_distance(observation, pose, far) if blind else self._turn_distance(observation))
        if skipped is None:
            return observation, None, False
        if blind:
            self.blind_updates += 1
            return kept, skipped, True
        if self.quality.fit(pose, kept, self._laser_pose[:2]).score < self.cfg.sensor.unmapped_fit:
            return observation, None, False
        return kept, skipped, False

    def _turn_distance(self, observation):
        """``sensor.unmapped_turn_sigmas``: a function giving how far from every mapped obstacle each endpoint of
        ``observation`` must lie to be skipped on this update (``unmapped_distance``, or that many std of the heading
        noise this update's odometry turn adds times the endpoint's range, when larger); None on a step that does not
        turn, under the velocity model, or with the key 0. The turn's heading noise is the motion model's
        (``turn_heading_std``: alpha1's terms, the translation left out): what a turn can leave of heading error. Not
        the predicted cloud's whole spread, nor this step's whole heading noise: the travel's (alpha2) would excuse
        people ahead on a straight corridor (``corridor-05``: lost 67 m under it; ``infinite_corridor``'s junction,
        sixty-seventh session), where the track's heading has held.

        Under ``unmapped_distance`` alone, a turn the odometry overshot by 2-3 degrees put the far walls' returns
        (9-20 m ahead at a grazing angle, a reading or two per segment) 0.4-0.8 m off the map from the estimate;
        skipped as people, they took with them what turns the estimate back and places it along the corridor, and the
        rest of the scan fitted a pose 0.8 m back (infinite_corridor with its odometry 5 % short and its turns 7 %
        long, the map turned 30 degrees: 20 m off at a corner on 2 seeds of 5, 1.02 m on a third; half a std of the
        turn's noise, the default, keeps 0.36-0.42 m)."""
        k = float(self.cfg.sensor.unmapped_turn_sigmas)
        turn_std = getattr(self.motion, "turn_heading_std", None)  # (the velocity model's controls are no such step)
        if k <= 0.0 or self._delta is None or turn_std is None:
            return None
        sigma = float(turn_std(self._delta))
        if sigma == 0.0:
            return None
        least = float(self.cfg.sensor.unmapped_distance)
        return lambda: np.maximum(k * sigma * np.hypot(observation[0], observation[1]), least)

    def _blind_distance(self, observation, pose, far) -> np.ndarray:
        """:meth:`UnmappedObjects.blind_distance` of ``observation`` seen from ``pose`` under the larger spread of
        the last estimate's and this update's predicted cloud (the motion applied, the scan not yet weighed): a
        turn's heading error is in the predicted cloud only. The odometry turned a hall robot 0.22 rad too far
        while 3-8 of its 31 returns met mapped obstacles 6.5 m off; from the estimate they lay 1.4 m off the map
        and were skipped with the people, under the last estimate's 0.01 rad, and the filter went on turned
        (suites/heldout25.yaml hall-short-5pc-people-h32 at range scale 1, tracking: RMSE 20.5-22.7 m, now 0.083 m;
        the baseline, which scores every beam, 0.114 m)."""
        w, _ = normalize_log_weights(self.logw)
        last = self.unmapped.blind_distance(observation, pose, self.last_estimate.cov, far)
        return np.maximum(last, self.unmapped.blind_distance(observation, pose, estimate(self.particles, w)[1], far))

    def _unmapped_shifts(self, moved):
        """``sensor.unmapped_spread``: offsets of the estimate along the cloud's major axis, forward (the way this
        update's odometry moves the robot: from the estimate to ``moved``, ``_moved_estimate``) out to that many
        of its std (0.1 m steps, at most 16), from which a skipped run of endpoints must be off the map too; None
        when 0 or not moving along the axis.

        Forward only: a cloud behind the robot sees the walls ahead short of the map, and a shift forward puts
        them back on it; a cloud ahead sees readings end inside walls, which are never skipped. People at a
        junction's opening fit the walls beside it from a pose *behind* (corridor-05, infinite_corridor at 25 s):
        a backward shift would keep their beams."""
        k = self.cfg.sensor.unmapped_spread
        if k <= 0.0:
            return None
        cov = self.last_estimate.cov
        a, b, c = float(cov[0, 0]), float(cov[0, 1]), float(cov[1, 1])
        # the 2x2 covariance's larger eigenvalue and its unit eigenvector (closed form)
        lam = 0.5 * (a + c) + math.hypot(0.5 * (a - c), b)
        ux, uy = (lam - c, b) if b != 0.0 else ((1.0, 0.0) if a >= c else (0.0, 1.0))
        reach = k * math.sqrt(max(lam, 0.0))
        n = min(int(math.ceil(reach / 0.1)), 16)  # suites' tracking clouds: std up to 0.68 m, 14 steps
        mean = self.last_estimate.mean
        # the odometry step in the world frame, projected on the axis: which way is forward
        along = (float(moved[0]) - float(mean[0])) * ux + (float(moved[1]) - float(mean[1])) * uy
        if n == 0 or along == 0.0:
            return None
        u = math.copysign(1.0, along) / math.hypot(ux, uy) * np.array([ux, uy])
        return np.linspace(reach / n, reach, n)[:, None] * u[None, :]

    def _laser_loglik(self, particles: np.ndarray, observation) -> np.ndarray:
        """(N,) log p(z | x, m) of the laser at ``particles``, tempered by ``_laser_exponent``; a NaN or +inf
        counts as weight zero (-inf)."""
        searching = self._laser_searching()
        loglik = self.sensor.log_likelihood(particles, observation, searching=searching)
        exponent = self._laser_exponent()
        if exponent != 1.0:
            loglik *= exponent  # tempered while a global search is under way, or while lost
        if not np.isfinite(loglik).all():
            loglik = np.where(np.isnan(loglik) | (loglik == np.inf), -np.inf, loglik)
        return loglik

    def _laser_exponent(self) -> float:
        """The factor on the laser log-likelihood this update: ``search_exponent`` during a global search,
        ``lost_exponent`` while lost recovery spreads poses around the estimate (one scan must not hand the whole
        set to a single injected pose: it must out-score the tracked cloud over several updates), else 1."""
        fc = self.cfg.filter
        if self.search.tempering:
            return fc.search_exponent
        if getattr(self.recovery, "spreading", False):
            return fc.lost_exponent
        return 1.0

    def _laser_searching(self) -> bool:
        """A global search is under way or lost recovery runs (it spreads poses, the updates ``_laser_exponent``
        tempers, or waits to): the likelihood field then scores with ``search_interior``'s field."""
        return self.search.tempering or bool(getattr(self.recovery, "lost_updates", 0))

    def _oversample_count(self, fresh: int) -> int:
        """k, the uniform candidates per fresh pose that ``filter.global_density`` asks for (1 or less: none)."""
        return min(math.ceil(self.cfg.filter.global_density * self.grid.free_area / max(fresh, 1)), _MAX_OVERSAMPLE)

    def _oversample_fresh(self, observation, loglik: np.ndarray) -> np.ndarray:
        """The uniform poses of a global start or re-seed, drawn better on a big map: when they are sparser than
        ``filter.global_density`` poses per m² of free space, k = density x area / count (at most
        _MAX_OVERSAMPLE) uniform candidates per fresh particle are scored with this scan, and the fresh
        particles are drawn from them in proportion to that likelihood (importance resampling, as if the search
        had started with k times the particles and resampled once). They then carry, instead of their own
        likelihood, the mean likelihood of all the candidates (the fresh component's evidence), so the scan is
        counted once and the old cloud of a re-seed keeps its fair share. With ``search_refine_candidates`` (the
        default) the best ``_MATCHED_PER_FRESH`` candidates per fresh pose first take the search's ``search_refine``
        matching steps, and the fresh poses are drawn from those by their matched fit: scored as drawn, the draw
        follows the few candidates that happened to fall aligned with the scan (with a 30 m laser, every fresh pose
        on a hall's mirror image). Returns ``loglik`` with the fresh entries replaced (``correct`` neither matched
        nor scored them), or None when no candidate scored."""
        fresh, self._fresh = self._fresh, None
        idx = np.flatnonzero(fresh) if fresh.size == loglik.size else np.zeros(0, dtype=np.int64)
        k = self._oversample_count(idx.size)
        if k <= 1 or idx.size == 0:
            return loglik
        fc = self.cfg.filter
        cand = self.sample_uniform(k * idx.size, self.rng)
        lc = self._laser_loglik(cand, observation)
        top = float(lc.max())
        if not np.isfinite(top):
            return None  # the caller scores the fresh poses as they are
        # the fresh component's evidence: the mean likelihood of the candidates as drawn (uniform poses), so that a
        # protected re-seed weighs the search against the track on the same terms as before matching
        evidence = top + math.log(np.mean(np.exp(lc - top)))
        matched = False
        if fc.search_refine and fc.search_refine_candidates:  # each drawn by its fit at its best pose near where it fell
            # only the best _MATCHED_PER_FRESH per fresh pose as drawn: matching all k (up to 20) cost 4x the
            # CPU of a kidnapped run on a 200 m building for the same result, the best 2 twice the best one's;
            # kept in the cache order they were drawn in (out of it, the matching's lookups into a big map's
            # field ran 3x slower)
            n_match = _MATCHED_PER_FRESH * idx.size
            best = cand if n_match >= lc.size else np.ascontiguousarray(cand[:, top_k(lc, n_match)])
            moved = self._refined(best, observation, int(fc.search_refine))
            lm = self._laser_loglik(moved, observation)
            matched = bool(np.isfinite(lm.max()))  # (no finite fit matched: drawn as they were)
            if matched:
                cand, lc = moved, lm
        pick = resample(fc.resampling, lc, self.rng, n=idx.size)
        self.particles[:, idx] = cand[:, pick]
        if fc.search_refine and fc.search_refine_scope == "fresh" and not matched:
            self._match_scan(observation, idx)  # the drawn poses, matched as the fresh ones were (for the next scan)
        loglik = loglik.copy()
        loglik[idx] = evidence
        return loglik

    def correct_landmarks(self, marks, info: StepInfo | None = None) -> None:
        """w_t *= p(z_t | x_t, m) for a ``Landmarks`` record (mcl.landmarks.LandmarkModel), in log space."""
        self._marks = marks
        if marks is not None and self.landmarks is not None:
            # landmark-only runs: the landmarks drive the recovery averages
            self._correct_features(self.landmarks, marks, per=1, drives=not self.cfg.sensor.use)

    def correct_planes(self, planes, info: StepInfo | None = None) -> None:
        """w_t *= p(z_t | x_t, m) for the planes extracted from a depth frame (mcl.planes.PlaneModel)."""
        if planes is not None and self.planes is not None:
            self._correct_features(self.planes, planes, per=0,
                                   drives=not self.cfg.sensor.use and not self.cfg.landmarks.use)

    def _correct_features(self, model, record, per: int, drives: bool) -> None:
        """logw += log p(record | x, m) under a feature model (``prepare`` then ``log_likelihood``); when this
        model is the run's only sensor (``drives``), its mean log-likelihood per feature (``prepared.shape[per]``
        features) feeds the recovery averages."""
        prepared = model.prepare(record)
        if prepared is None:
            return
        loglik = model.log_likelihood(self.particles, prepared)
        if drives and self.recovery is not None:
            self.recovery.observe_likelihood(self.logw, loglik / prepared.shape[per], self._injected)
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
        part, self._floor_part = self._floor_part, None
        if (not info.degenerate and part is not None and part.size == self.n
                and info.ess < self.cfg.filter.ess_floor * self.n):
            self._temper_to_floor(part, info)
        if info.degenerate:
            self.recover_degenerate(info)
        else:
            self.zero_weights.ok()

    def _temper_to_floor(self, loglik: np.ndarray, info: StepInfo) -> None:
        """``filter.ess_floor``: this update's scan (``loglik``, already in the normalised weights) taken again times
        the beta of :func:`mcl.resampling.temper_to_ess`, which leaves ``ess_floor`` x N effective particles to
        ``FLOOR_SLACK`` times that (0, the weights before the scan, when even 1/4096 of it leaves too few); nothing
        when the weights before the scan were below the floor already, or the cloud is narrow (:meth:`_wide`).

        A scan far sharper than the cloud's spread (beams a few cm sharp, scans seconds and a turn apart) hands the
        whole weight to one or two particles, and the resample that follows keeps copies of one pose: on
        ``intel_lab`` read 2 % long with 5 cm noise the effective sample size was 1.0 of 5,000, and the track went
        1.5-4.9 m off. Tempered, the scan moves the set as far as that many particles can carry it, and the next
        scans finish the job: the book's advice to overestimate the measurement noise (Prob. Rob. 6.3.4), taken only
        where the set cannot hold the scan as it is."""
        floor = self.cfg.filter.ess_floor * self.n
        fin = np.isfinite(loglik)
        part = np.where(fin, loglik, 0.0)
        prior = np.where(fin, self.logw - part, -np.inf)  # the weights before the scan (a -inf stays weight zero)
        w0, norm0 = normalize_log_weights(prior)
        if not math.isfinite(norm0) or effective_sample_size(w0) < floor or not self._wide(w0):
            return
        beta = temper_to_ess(prior, part, floor, info.ess, self.FLOOR_SLACK)
        w, norm = normalize_log_weights(prior + beta * part)
        self.logw = prior + beta * part - norm
        self.weights = w
        info.ess = float(effective_sample_size(w))
        self.floor_tempered += 1

    FLOOR_SLACK = 1.05  # ess_floor: a tempered scan leaves at most this many times the floor's effective sample size

    def _wide(self, w: np.ndarray) -> bool:
        """Whether the cloud weighted by ``w`` (normalised) is as wide as ``filter.ess_floor_spread``: its position
        spread (the weighted RMS distance from its mean, m) or its heading spread (the weighted RMS of the headings'
        wrapped differences from their circular mean, rad) at least that (``mcl.estimate.moments``).

        A narrow cloud that a scan narrows to a particle or two loses nothing the next prediction does not spread
        again: people crowding a robot in clutter leave a few walls that pin the pose to 2 of 5,000 particles of a
        cloud 5 cm and 0.06 rad wide, and tempered that scan let the track drift and be called lost (9.4 m off). The
        scans the floor is for fall on a cloud a turn and seconds without a scan spread: 0.12-0.39 m and 0.11-0.31
        rad on intel_lab read 2 % long."""
        _, cov = moments(self.particles, w)
        spread = self.cfg.filter.ess_floor_spread
        return cov[0, 0] + cov[1, 1] >= spread * spread or cov[2, 2] >= spread * spread

    def protect(self, info: StepInfo) -> None:
        """Settle a protected re-seed (``filter.reseed_odds``, ``mcl.adaptive.ProtectedReseed``) once one side
        leads by the odds: the loser is dropped, and a track that wins is not put on probation. Until then the
        weights carry the odds that counted, and the estimate stays on the track."""
        p = self.protected
        if p is None or info.degenerate:
            return
        if p.track.size != self.n:  # pragma: no cover - every change of the set goes through _set or _resample_apart
            self.protected = None
            return
        track = p.track
        log_track, log_search = (normalize_log_weights(self.logw[side])[1] for side in (track, ~track))
        search = ~track
        # each side's heaviest cluster (search first), worked out once this update if a rule asks for it
        estimates = functools.cache(lambda: (self._side_estimate(search), self._side_estimate(track)))
        scores = (None if self._scan_observation is None
                  else lambda: self._side_fits(*estimates()))
        if not p.local and self._scan_observation is not None and self._search_concurs(*estimates()):
            p.concur()
        odds = p.weigh(log_track, log_search, scores)
        raw = log_search - log_track
        if not p.settled:
            if odds != raw:  # the weights carry the odds that counted: shift the search side's mass
                self.logw[~track] += odds - raw
                self.weights, log_norm = normalize_log_weights(self.logw)
                self.logw -= log_norm
            return
        won = p.track_won  # the track (a tie after MAX_UPDATES updates goes to the track)
        self._keep_side(track if won else ~track)
        info.ess = float(effective_sample_size(self.weights))
        info.particles = self.n
        if p.local:  # a protected spread: the filter is still lost until a scan fits (its count goes on)
            return
        if won:
            info.confirmed = True
            self.search.confirm()
            self.recovery.start_search()  # the lost count starts again
        else:
            info.switched = True

    def _keep_side(self, keep: np.ndarray) -> None:
        """End a protected re-seed or spread: the particles ``keep`` selects stay, with their weights
        (normalised)."""
        idx = np.flatnonzero(keep)
        logw = self.logw[idx]
        self._set(np.ascontiguousarray(self.particles[:, idx]))
        self.weights, log_norm = normalize_log_weights(logw)
        self.logw = logw - log_norm

    def _side_fits(self, search: ClusterEstimate | None,
                   track: ClusterEstimate | None) -> tuple[float, float, float, float, int]:
        """This update's scan at the heaviest clusters of the sides (``_side_estimate``): (score, score,
        contradiction, contradiction), search first (``_side_fit``), and the scan's beams with a return (a count
        the pose does not change)."""
        (s_search, c_search, _), (s_track, c_track, beams) = self._side_fit(search), self._side_fit(track)
        return s_search, s_track, c_search, c_track, beams

    def _side_estimate(self, side: np.ndarray) -> ClusterEstimate | None:
        """The heaviest cluster of the particles the mask ``side`` selects (None without weight)."""
        w = self.weights[side]
        total = float(w.sum())
        if not total > 0.0:
            return None
        fc = self.cfg.filter
        return cluster_estimate(np.ascontiguousarray(self.particles[:, side]), w / total,
                                fc.cluster_size, fc.cluster_angle)

    def _side_fit(self, est: ClusterEstimate | None) -> tuple[float, float, int]:
        """The quality score (mcl.quality: match - 2 contradiction), the share of beams through mapped walls and the
        beams with a return of this update's scan at a side's heaviest cluster ``est``; (-inf, 1, 0) without weight
        (None), nan without beams."""
        if est is None:
            return -math.inf, 1.0, 0
        f = self._scan_fit(est.mean)
        return f.score, f.contradiction, f.beams

    def _search_concurs(self, search: ClusterEstimate | None, track: ClusterEstimate | None) -> bool:
        """A protected re-seed's search has gathered where the track is: its heaviest cluster ``search`` holds what
        settles a search (``GlobalSearch.settles``) and lies within a cluster cell (``filter.cluster_size``,
        ``cluster_angle``) of the track's heaviest cluster ``track``. It found no other place, so the scans can no
        longer tell the two sides apart and the track is kept. With the search's fresh poses matched before they
        are drawn (``filter.search_refine_candidates``) they can sit on a correct track's place from the first
        scan, fit it as well as the track does, and leave the odds where the prior put them until
        ``ProtectedReseed.MAX_UPDATES`` ran out."""
        if search is None or track is None or not self.search.settles(search.weight, search.cov):
            return False
        fc = self.cfg.filter
        return (math.hypot(search.mean[0] - track.mean[0], search.mean[1] - track.mean[1]) <= fc.cluster_size
                and abs(wrap_angle(search.mean[2] - track.mean[2])) <= fc.cluster_angle)

    def _scan_fit(self, pose):
        """This update's scan laid on the map at ``pose`` (mcl.quality.Fit)."""
        return self.quality.fit(pose, self.sensor.endpoints(self._scan_observation), self._laser_pose[:2])

    def _scan_score(self, pose) -> float:
        """The quality score (mcl.quality: match - 2 contradiction) of this update's scan at ``pose``."""
        return self._scan_fit(pose).score

    def estimate(self, info: StepInfo | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The pose estimate and its covariance: of the heaviest cluster (``filter.estimate = cluster``) or of the
        whole weighted set (``mean``; circular mean for theta). Keeps both in ``last_estimate``, which the quality
        signal, the recovery and the stall check read. While a protected re-seed runs (``protect``), of the kept
        track's particles only. The pose reported (returned, and ``info.mean``: the trajectory) is that one, or
        while lost recovery's fresh poses are on trial (``filter.recovery_trial``) ``_trial_estimate``'s."""
        particles, weights = self.particles, self.weights
        if self.protected is not None:
            track = self.protected.track
            particles = np.ascontiguousarray(particles[:, track])
            weights = weights[track] / max(float(weights[track].sum()), 1e-300)
        est = self._estimate_of(particles, weights)
        self.last_estimate = est
        if self.skipping is not None:
            self.skipping.observe_estimate(est)
        shown = self._trial_estimate(est) if self.protected is None and self._on_trial() else est
        if info is not None:
            info.mean, info.cov = shown.mean, shown.cov
            info.full_mean, info.full_cov = est.full_mean, est.full_cov
            info.clusters, info.cluster_weight = est.n_clusters, est.weight
        return shown.mean, shown.cov

    def _estimate_of(self, particles: np.ndarray, weights: np.ndarray) -> ClusterEstimate:
        """The estimate (``filter.estimate``) of ``particles`` with normalised ``weights``."""
        fc = self.cfg.filter
        if fc.estimate == "cluster":
            return cluster_estimate(particles, weights, fc.cluster_size, fc.cluster_angle)
        mean, cov = estimate(particles, weights)
        return ClusterEstimate(mean, cov, mean, cov, 1, 1.0)

    def _trial_estimate(self, est: ClusterEstimate) -> ClusterEstimate:
        """The pose reported while the poses lost recovery spread at the last resample are on trial: ``est`` (of
        the whole set) or that of the older particles alone, whichever this scan fits better at (the quality
        score). A few lucky fresh poses 1-2 m off can take half the weight and pull the cluster's mean to a place
        between them and the track where no particle is (suites/heldout2.yaml clutter-map10cm-h9: 0.82 m off,
        fitting at -0.25 against the track's 0.49); fresh poses that found the robot again (fr079's slip at 305 s)
        fit better than the track and keep the estimate, which waiting one update for them would hold back (1.40 m
        there against 0.99 m). Only the pose reported: the filter goes on from ``est`` (its lost call, recovery and
        stall check), so the choice cannot end a lost episode sooner. Choosing for them too called fewer updates
        lost and lost 3 kidnapped runs of 335 net across the corpora (docs/measurements.md, "Tenth session")."""
        obs = self._scan_observation
        older = ~self._injected
        kept = float(self.weights[older].sum())
        if obs is None or kept <= 1e-12:
            return est
        alt = self._estimate_of(np.ascontiguousarray(self.particles[:, older]), self.weights[older] / kept)
        return alt if self._scan_score(alt.mean) > self._scan_score(est.mean) else est

    def _on_trial(self) -> bool:
        """``filter.recovery_trial``: lost recovery spread poses around the estimate at the last resample (not a
        re-seed's global search), and some of the set is older."""
        inj = self._injected
        return (self.cfg.filter.recovery_trial and inj is not None and inj.size == self.n and not inj.all()
                and not self.search.tempering and bool(getattr(self.recovery, "spreading", False)))

    def _with_missing(self, fit):
        """``fit`` with ``predicted`` / ``missing`` (``ScanQuality.missing``) over the scan's scored directions from
        the estimate: whether a low match with nothing through a wall is occlusion or a wrong place."""
        scan = self._prepared_scan
        idx, reach = scored_view(scan, self.cfg.sensor)
        r = np.asarray(scan.ranges, dtype=np.float64)[idx]
        returned = valid_returns(r, getattr(scan, "max_range", None), self.cfg.sensor)
        predicted, missing = self.quality.missing(self.last_estimate.mean, self._laser_pose,
                                                  np.asarray(scan.angles, dtype=np.float64)[idx], returned, r, reach)
        return dataclasses.replace(fit, predicted=predicted, missing=missing, directions=int(idx.size))

    def assess(self, info: StepInfo) -> None:
        """Lay this update's scan on the map at the estimate (mcl.quality): the quality signal and the lost
        belief, which the recovery policy reads."""
        obs = self._scan_observation
        fit = None
        if obs is not None:
            fit = self.quality.fit(self.last_estimate.mean, self.sensor.endpoints(obs), self._laser_pose[:2])
            if ((self.quality.occluded_call(fit) or self.quality.pools(fit))
                    and self._prepared_scan is not None):
                fit = self._with_missing(fit)
        info.fit = fit
        info.lost = self.quality.update(fit)
        # a protected re-seed's search settles by the odds (protect), not by the track's cluster
        self.search.observe(info.lost, info.cluster_weight if self.protected is None else 0.0, self.last_estimate.cov,
                           self._dt)
        if self.faults is not None:
            c = fit.contradiction if fit is not None and fit.beams else 0.0
            cov = info.full_cov if self.faults.slip is not None else None  # the spread gates a wheel's slip alone
            spread = math.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)) if cov is not None else 0.0
            self.faults.observe(info.lost, c if c == c else 0.0, spread, self._dt)
        if self.recovery is not None:
            self.recovery.observe_lost(info.lost, info.cluster_weight, self._dt, self.quality.refutes(fit),
                                       self.quality.collapsed)
        if self.stall is not None:
            self.stall.observe(self._dt, self.last_estimate.mean, self.last_estimate.cov, self._odom)
            info.stalled = self.stall.stalled
        if self.challenge is not None and self.protected is None and getattr(self.recovery, "reseed", False):
            self.challenge.observe(fit, self.recovery.on_probation)

    def resample(self, info: StepInfo) -> None:
        """Resample when ESS / N < resample_threshold (the scheme named in filter.resampling).

        With KLD sampling the new set's size follows the occupied bins (drawn
        with the next motion, Table 8.4); with recovery a Binomial(N, p) of the
        new particles come from ``recovery_sampler`` instead of the weighted set.
        """
        fc = self.cfg.filter
        info.weighted = (self.particles, self.weights)  # (the arrays are replaced, not written, by what follows)
        challenged = self.challenge is not None and self.challenge.due
        reseed_due = self.recovery is not None and (getattr(self.recovery, "reseed_due", False) or challenged)
        if self.protected is not None:
            p = self.protected
            # a global re-seed due while the spread leads unsettled waits while the track's scans still fit
            # (filter.reseed_wait_fit): on a stale map a spread pose 1.2 m off led a correct track for 3 s before the
            # scans settled it the other way, and the re-seed kept it (heldout14 hall-stale-both-ways-h21)
            if not (p.local and reseed_due) or p.defers_reseed(fc.reseed_wait_fit):
                self._resample_apart(info)
                return
            # the global re-seed is due while a protected spread runs: the side that leads is the track it keeps
            self._keep_side(p.track if p.track_won else ~p.track)
        if reseed_due:
            self._reseed(info)
            return
        p = self.recovery.inject_probability if self.recovery is not None else 0.0
        info.inject_p = p
        if p > 0.0 and self._protects_spread():
            if not self._fits_as_tracked(info.fit):
                self._spread_protected(info)
                return
            p = info.inject_p = 0.0  # a spread would sit idle (_spread_protected)
        # Recovery resamples whenever it injects: a lost filter whose particles all explain the scan
        # equally badly has a high ESS and would otherwise never inject.
        if info.ess >= fc.resample_threshold * self.n and p == 0.0:
            return
        info.resampled = True
        inject = self._injection_sampler()
        if self.kld is not None:
            self.kld.schedule(p, inject)
            return
        # a fixed N again: a re-seed doubled the set (_reseed), and without KLD sampling nothing else draws it back
        # (a global run with --particles 2000 and kld off kept 4,000 for 297 of its 299 updates)
        n_total = min(self.n, fc.particles)
        n_inj = draw_injected(n_total, p, self.rng)
        idx = resample(fc.resampling, self.logw, self.rng, n=n_total - n_inj)
        new = np.take(self.particles, idx, axis=1)  # a quarter of fancy indexing's time
        if n_inj:
            new = np.concatenate([new, inject(n_inj)], axis=1)
        fresh = np.arange(new.shape[1]) >= new.shape[1] - n_inj
        info.injected = n_inj
        self._set(np.ascontiguousarray(new))
        self._injected = fresh if n_inj else None

    maybe_resample = resample  # the name of earlier versions

    def _resample_apart(self, info: StepInfo) -> None:
        """A protected re-seed's resample: the kept track and the search each drawn from its own particles, each
        keeping its share of the weight (spread evenly over its particles). The track keeps its count; the search
        draws as many as KLD sampling asks (with ``filter.kld``), at most the count it has. Nothing is injected."""
        fc = self.cfg.filter
        parts, logw, track = [], [], []
        for side in (True, False):
            sel = np.flatnonzero(self.protected.track == side)
            if side or self.kld is None or sel.size <= self.kld.min_particles:
                new = self.particles[:, sel[resample(fc.resampling, self.logw[sel], self.rng, n=sel.size)]]
            else:
                # the search's poses by KLD sampling, at most as many as it has: its 100,000 fresh poses gather on
                # a few places within a scan or two, and scoring them all for up to MAX_UPDATES updates took a
                # campus run 13-16 s instead of 11-14 s (bins counted on the drawn ancestors, not moved)
                new, _, _ = kld_resample(self.particles[:, sel], self.logw[sel], self.rng, self.kld.counter,
                                         scheme=fc.resampling, min_particles=self.kld.min_particles,
                                         max_particles=sel.size, epsilon=self.kld.epsilon, z=self.kld.z)
            m = new.shape[1]
            parts.append(new)
            logw.append(np.full(m, normalize_log_weights(self.logw[sel])[1] - math.log(m)))
            track.append(np.full(m, side))
        self.particles = np.ascontiguousarray(np.concatenate(parts, axis=1))
        self.logw = np.concatenate(logw)
        self.weights = np.exp(self.logw)
        self.protected.track = np.concatenate(track)
        self._injected = None
        self._fresh = None
        info.resampled = True

    def _reseed(self, info: StepInfo) -> None:
        """Global re-seed of a filter lost for a while: the tracked cloud (resampled, equal weights) plus as many
        poses from ``recovery_sampler`` (uniform over free space) as fill the set up to ``filter.particles`` (at
        least as many as the cloud has), as a mixture prior:
        the old cloud keeps ``recovery_reseed_keep`` of the mass, so a look-alike pose must out-score a track that
        was right all along, and then a global search starts (no injection until it settles, laser likelihood
        tempered by ``search_exponent``). A few per cent of uniform poses a step almost never lands near the
        true pose on a building-sized map; a whole set does. A re-seed on a stalled estimate (``info.stalled``:
        the odometry drove on while the place the last search found held the cloud back) keeps nothing of the old
        cloud: the motion has already ruled that place out, and its scans fit as well as anywhere else's."""
        fc = self.cfg.filter
        keep = 0.0 if info.stalled else fc.recovery_reseed_keep
        # a track, not a place a search just found, nor one that collapsed (a kidnap: the old place kept by odds
        # against the search would fit again once turned as the robot was, and win); or a place found that is
        # challenged (ProbationChallenge)
        trusted = not getattr(self.recovery, "on_probation", True) and not getattr(self.recovery, "collapsed", False)
        if self.challenge is not None and self.challenge.due:
            trusted, self.challenge.due = True, False
        n = min(self.n, fc.particles) if keep > 0.0 else 0  # a set grown by an earlier re-seed is drawn back down
        idx = resample(fc.resampling, self.logw, self.rng, n=n)
        m = max(fc.particles - n, n)
        self._kept_and_fresh(self.particles[:, idx], self.recovery_sampler(m, self.rng, self._observation), keep)
        self._fresh = self._injected.copy()
        if keep > 0.0 and n > 0 and trusted and fc.reseed_odds > 0.0:
            self.protected = ProtectedReseed(~self._injected, keep, fc.reseed_odds, self.cfg.quality.lost_below,
                                             min_beams=self.quality.held_bar)
        elif n > 0 and fc.reseed_hold_pose and self._held is None and self.last_estimate is not None:
            # (a re-seed before the estimate fitted again keeps the pose held since the first one)
            self._held = (np.array(self.last_estimate.mean, dtype=np.float64),
                          np.array(self.last_estimate.cov, dtype=np.float64))
        if self.kld is not None:
            self.kld.pending = None
        info.resampled = True
        info.injected = m
        info.reseeded = True
        self.search.start()
        self.recovery.start_search()

    def _report_held(self, info: StepInfo) -> None:
        """``filter.reseed_hold_pose``: after a re-seed that kept the old cloud without protecting it (a place on
        probation, a collapse), and until the filter is no longer lost (this update's ``assess``), the pose reported
        is the estimate from before the re-seed moved by the odometry since. A search that has fitted nothing yet
        reports the heaviest cluster of 100,000 uniform poses, or a place it settled on that fits no better, or one
        that fits a single scan (freiburg-campus, the laser on the ground: 129-185 m off for nine scans while the
        track was within 0.2 m; one place 184 m off fitted a scan at 0.78). Only the pose reported (``info.mean``):
        the filter goes on from its own estimate, as with ``_trial_estimate``. The covariance reported with it
        (``info.cov``) is the one that estimate had at the re-seed, not the search's heaviest cluster's."""
        if self._held is None:
            return
        if not info.lost or self.protected is not None:
            self._held = None
            return
        mean, cov = self._held
        mean = self._moved(mean)
        self._held = (mean, cov)
        info.mean = mean.copy()
        info.cov = cov.copy()  # the held estimate's own (the recording's ellipse, --write-bag)

    def _kept_and_fresh(self, kept: np.ndarray, fresh: np.ndarray, keep: float) -> None:
        """The set becomes ``kept`` (resampled particles, ``keep`` of the mass) then ``fresh`` (the rest), each
        side's mass spread evenly over it; ``_injected`` marks the fresh ones (a re-seed, a protected spread)."""
        n, m = kept.shape[1], fresh.shape[1]
        self._set(np.ascontiguousarray(np.concatenate([kept, fresh], axis=1)))
        self.logw = np.concatenate([np.full(n, math.log(keep / n) if n else 0.0),
                                    np.full(m, math.log(1.0 - keep) - math.log(m) if keep < 1.0 else -np.inf)])
        self.weights = np.exp(self.logw)
        self._injected = np.arange(n + m) >= n

    def _protects_spread(self) -> bool:
        """``filter.recovery_protect``: lost recovery spreads poses around the estimate only (no global share), no
        global search is under way, and protected re-seeds are on (``reseed_odds``, ``recovery_reseed_keep``)."""
        fc = self.cfg.filter
        rec = self.recovery
        return (fc.recovery_protect and fc.reseed_odds > 0.0 and 0.0 < fc.recovery_reseed_keep < 1.0
                and self.last_estimate is not None and not self.search.tempering
                and getattr(rec, "local_std", None) is not None and getattr(rec, "global_share", 1.0) == 0.0)

    def _fits_as_tracked(self, fit) -> bool:
        """Whether this update's scan fits the map at the estimate as a tracked scan does (quality score
        ``quality.lost_below`` or better, on at least ``quality.min_beams`` beams)."""
        qc = self.cfg.quality
        return fit is not None and fit.beams >= qc.min_beams and fit.score >= qc.lost_below

    def _spread_protected(self, info: StepInfo) -> None:
        """Lost recovery's spread around the estimate, protected (``filter.recovery_protect``): the track
        (resampled, ``recovery_reseed_keep`` of the mass) and as many poses drawn around the estimate with the
        policy's ``local_std`` (the rest of the mass), resampled apart and settled by log-odds as a protected
        re-seed (``ProtectedReseed``; the estimate stays on the track meanwhile). Mixed into the set, a spread pose
        that fits one scan takes the estimate at once: two seconds of scans that fit no pose near the track (a
        laser tilted onto the ground, ``mcl simulate --ground-hits``) handed the track to spread poses where they
        met walls (an open hall: 20.6 m off; the campus log at 203-205 s); kept apart, they must out-score the
        track over scans that fit the map there. The set doubles for the episode (the track keeps its count).
        No spread starts on a scan that fits the estimate as a tracked scan does (``_fits_as_tracked``), though the
        lost belief holds: such a scan is no evidence for a spread (``ProtectedReseed.weigh``). After a spread won,
        the lost belief's tail started a new one at once around the same pose, where no scan counts for either
        side, and the set stayed doubled for up to ``ProtectedReseed.MAX_UPDATES`` updates (heldout2 kidnapped:
        a third of the CPU time)."""
        fc = self.cfg.filter
        keep = fc.recovery_reseed_keep
        n = self.n
        idx = resample(fc.resampling, self.logw, self.rng, n=n)
        self._kept_and_fresh(self.particles[:, idx], self._draw_around(self.last_estimate.mean,
                                                                       self.recovery.local_std, n), keep)
        self.protected = ProtectedReseed(~self._injected, keep, fc.reseed_odds, self.cfg.quality.lost_below,
                                         local=True)
        if self.kld is not None:
            self.kld.pending = None
        info.resampled = True
        info.injected = n

    def _injection_sampler(self):
        """sampler(n) -> (3, n): the poses recovery injects now. The policy's ``global_share`` of them (a binomial
        draw) from ``recovery_sampler`` (uniform over free space, or from landmarks), the rest around this update's
        estimate with the policy's ``local_std`` (LostRecovery spreads locally before it searches the map)."""
        obs = self._observation
        share = float(getattr(self.recovery, "global_share", 1.0)) if self.recovery is not None else 1.0
        std = getattr(self.recovery, "local_std", None) if self.recovery is not None else None
        centre = self.last_estimate.mean if self.last_estimate is not None else None

        def sample(n: int) -> np.ndarray:
            if std is None or centre is None or share >= 1.0:
                return self.recovery_sampler(n, self.rng, obs)
            n_glob = int(self.rng.binomial(n, share)) if share > 0.0 else 0
            local = self._draw_around(centre, std, n - n_glob)
            if n_glob == 0:
                return local
            return np.ascontiguousarray(np.concatenate([local, self.recovery_sampler(n_glob, self.rng, obs)], axis=1))

        return sample

    # ------------------------------------------------------------------ degenerate weights

    def recover_degenerate(self, info: StepInfo) -> None:
        """Every weight was zero: re-spread around the last estimate (moved by the odometry step), or reinitialise
        globally after ``ZeroWeights.MAX_RUN`` consecutive failures; the new particles get equal weights."""
        self.guard.event("degenerate_weights", "every particle weight is zero (no pose explains the scan); the "
                         "particles are re-spread around the last estimate")
        std = self.zero_weights.respread()
        if self.last_estimate is None or std is None:
            self.init_global()
            self.zero_weights.ok()
        else:
            self._set(self._draw_around(self._moved_estimate(), std))
        # Equal weights: the scan that explained nothing is not scored again (re-scoring a bad scan would
        # collapse the fresh cloud onto the few poses that happen to fit it); the next scan decides.
        info.ess = float(self.n)

    # ------------------------------------------------------------------ helpers

    def _allowed_at(self, p: np.ndarray) -> np.ndarray:
        """(N,) bool: the poses the motion model allows (all True without map rejection)."""
        if self.allowed is None:
            return np.ones(p.shape[1], dtype=bool)
        return self.grid.mask_at(self.allowed, p[0], p[1])

    def _free_at(self, p: np.ndarray) -> np.ndarray:
        """(N,) bool: poses on free cells of the map (off the map: False)."""
        return self.grid.mask_at(np.asarray(self.grid.free), p[0], p[1])

    def _draw_around(self, centres: np.ndarray, std: np.ndarray, n: int | None = None) -> np.ndarray:
        """(3, n) poses ~ N(centres, diag(std^2)) (centres (3,) or (3, n); n defaults to N), drawn again (up to
        max_tries) where the map does not allow them; those never allowed keep the last draw. Always finite."""
        n = self.n if n is None else int(n)
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

    def _moved(self, pose) -> np.ndarray:
        """``pose`` (x, y, theta) moved by this update's odometry step; a copy of it when the update had none."""
        m = np.asarray(pose, dtype=np.float64)
        return compose(m, self._delta) if self._delta is not None else m.copy()

    def _moved_estimate(self) -> np.ndarray:
        """The last estimate moved by this update's odometry step (the estimate itself before any motion)."""
        return self._moved(self.last_estimate.mean)
