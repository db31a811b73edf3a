"""Adaptive particle counts (KLD sampling), recovery (augmented MCL, lost recovery) and the global search.

KLD sampling (Fox 2003; Prob. Rob. Table 8.4)
---------------------------------------------
While resampling, particles are drawn and the histogram bins they fall into
(``kld_bin_xy`` metres by ``kld_bin_theta`` radians) are counted; drawing
stops once the number drawn M reaches

    M_chi = (k - 1) / (2 eps) * (1 - 2/(9(k-1)) + sqrt(2/(9(k-1))) z_{1-delta})^3

for k occupied bins (the Wilson-Hilferty approximation of chi^2_{k-1, 1-delta}
/ (2 eps)), clamped to [min_particles, max_particles]. With that many samples
the KL divergence between the sample-based (binned) estimate and the true
posterior is below ``eps`` (``kld_epsilon``) with probability 1 - delta
(``kld_delta``, a probability such as 0.01). ``z_{1-delta}`` is the upper
1 - delta quantile of the standard normal (2.326 for delta = 0.01).

Note on ROS AMCL: its ``kld_z`` / ``pf_z`` parameter *is* that quantile z, yet
its documented default is 0.99 -- a probability passed where a quantile such
as 2.33 is meant. z = 0.99 corresponds to delta = 0.161, i.e. a far weaker
guarantee (and fewer particles) than the "99 %" the value suggests. Here the
user gives delta and the quantile is computed from it.

Drawing is vectorised in batches: each batch is a low-variance (systematic)
resample of the current set, shuffled by the filter's generator so that any
prefix of it is an unbiased draw; the running number of distinct bins over
the batch comes from one ``np.unique`` and a cumulative sum, and the first
position where M >= M_chi(k) ends the draw. Batches double in size, so a
resample takes O(log(max/min)) batches and no Python loop over particles.

Augmented MCL (Prob. Rob. Table 8.3)
------------------------------------
Short- and long-term averages of the measurement likelihood,

    w_slow += alpha_slow (w_avg - w_slow),   w_fast += alpha_fast (w_avg - w_fast),

where w_avg = sum_i w_{t-1,i} p(z_t | x_t^i)^(1/K) is the mean (prior-weighted)
*unnormalised* likelihood of the scan, per beam: the K-th root (geometric mean
over the K beams used) rather than the book's raw product. With the raw
product of 60 beams, ordinary scan-to-scan variation of a few nats already
gives w_fast/w_slow ~ e^-1 and injects 60 % of the set while tracking well
(measured on the bundled demo); the root also makes scans with different
numbers of valid beams comparable (short-range lasers drop many). The filter
passes loglik / K (``measurement_count``), and leaves out of w_avg the
particles injected at the last resample: they are the recovery hypothesis,
not the tracked one, and counting their (low) likelihood pulls w_fast down,
which injects more, which pulls it further -- on intel_lab that loop held
80-90 % of the set random while tracking was fine (measured). Likelihoods are far outside the
float range, so everything is kept in log space: log w_avg is a log-sum-exp,
and each update is ``logaddexp(log(1 - alpha) + log w, log alpha + log w_avg)``.
Both averages start at 0 as in the book but are read bias-corrected,
w / (1 - (1 - alpha)^t) after t scans (as Adam's moment estimates): the book's
raw w_slow lags for ~1/alpha_slow updates (1,000 with AMCL's 0.001), which
blocks recovery early; starting both at the first w_avg instead anchors w_slow
on one scan (on intel_lab the first scans fit better than the log's average,
and the filter injected all along). Corrected, w_slow is the running mean of
every scan so far until t ~ 1/alpha_slow, then the exponential average.
At resampling time each new particle is, with probability
p = max(0, 1 - w_fast / w_slow), drawn from the recovery sampler instead of
from the weighted set: the number injected is Binomial(N, p), drawn by the
filter's generator. The default sampler is uniform over the free space the
motion model allows (``grid.sample_free`` with the robot-radius clearance);
any callable ``sampler(n, rng, observation) -> (3, n)`` can replace it (e.g.
poses from landmarks).
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from statistics import NormalDist
from typing import Callable

import numpy as np

from mcl.resampling import resample

Sampler = Callable[[int, np.random.Generator, object], np.ndarray]


def measurement_count(observation) -> int:
    """K, the number of measurements in a sensor model's observation (for the per-beam likelihood).

    An array is (.., K) (likelihood field endpoints (2, K)); a tuple's first
    element is (K,) (the beam model's ranges); anything else counts as 1.
    """
    if isinstance(observation, np.ndarray):
        return int(observation.shape[-1]) if observation.ndim else 1
    if isinstance(observation, tuple) and observation and isinstance(observation[0], np.ndarray):
        return int(observation[0].shape[-1]) if observation[0].ndim else 1
    return 1


def kld_quantile(delta: float) -> float:
    """z_{1-delta}: the upper 1 - delta quantile of the standard normal (2.326 for delta = 0.01)."""
    if not 0.0 < delta < 1.0:
        raise ValueError(f"kld_delta must lie in (0, 1), got {delta}")
    return NormalDist().inv_cdf(1.0 - delta)


_BOUND_TABLES: dict[tuple[float, float], np.ndarray] = {}


def _bound_table(epsilon: float, z: float, k_max: int) -> np.ndarray:
    """M_chi(k) for k = 0..k_max (at least), computed once per (epsilon, z) and grown by doubling: a resample
    looks the bound up for each drawn pose instead of evaluating it (the same values, element for element)."""
    table = _BOUND_TABLES.get((epsilon, z))
    if table is None or table.size <= k_max:
        size = max(2 * (table.size if table is not None else 0), k_max + 1, 1024)
        table = kld_bound(np.arange(size), epsilon, z)
        _BOUND_TABLES[(epsilon, z)] = table
    return table


def kld_bound(k, epsilon: float, z: float) -> np.ndarray:
    """M_chi(k): particles needed for k occupied bins (Fox 2003, Wilson-Hilferty). 0 for k <= 1.

    ``k`` may be an array; the result has its shape (float64).
    """
    k = np.asarray(k, dtype=np.float64)
    km1 = np.maximum(k - 1.0, 1.0)
    a = 2.0 / (9.0 * km1)
    m = km1 / (2.0 * epsilon) * (1.0 - a + np.sqrt(a) * z) ** 3
    return np.where(k > 1.0, m, 0.0)


class BinCounter:
    """Occupied (x, y, theta) histogram bins over a map's extent, as a dense flag array, or as a hash table when
    that array would pass ``DENSE_MAX`` bins (its pages are only touched where the cloud is, but a 10 km map's
    14 GB is more than a machine lends).

    ``add(particles)`` returns, for each particle in order, the number of
    distinct bins occupied so far (including earlier batches). ``reset()``
    clears only the bins touched. One serial numba pass each (``mcl.kernels.kld``).
    """

    DENSE_MAX = 1 << 30  # bins (bytes) of the dense array: a 5.4 km square map at 0.5 m and 10 degrees

    def __init__(self, origin, size, bin_xy: float, bin_theta: float, dense_max: int | None = None):
        self.x0, self.y0 = float(origin[0]), float(origin[1])
        self.bin_xy = float(bin_xy)
        self.bin_theta = float(bin_theta)
        self.nx = max(1, int(math.ceil(size[0] / self.bin_xy)))
        self.ny = max(1, int(math.ceil(size[1] / self.bin_xy)))
        self.nt = max(1, int(math.ceil(2.0 * math.pi / self.bin_theta)))
        if self.nx * self.ny * self.nt <= (self.DENSE_MAX if dense_max is None else dense_max):
            self.flags, self.table = np.zeros(self.nx * self.ny * self.nt, dtype=np.bool_), None
        else:  # open addressing, key + 1 (0: empty); grown to stay at most half full (add)
            self.flags, self.table, self._shift = None, np.zeros(1 << 16, dtype=np.int64), 64 - 16
        self._touched = np.empty(1024, dtype=np.int64)  # the flagged bins (table: their slots), to clear only those
        self._n_touched = 0
        self.k = 0

    def keys(self, particles: np.ndarray) -> np.ndarray:
        """Flat bin index of each pose (poses off the map are clipped to its border bins)."""
        ix = np.clip(np.floor((particles[0] - self.x0) / self.bin_xy), 0, self.nx - 1).astype(np.int64)
        iy = np.clip(np.floor((particles[1] - self.y0) / self.bin_xy), 0, self.ny - 1).astype(np.int64)
        it = np.floor((particles[2] + math.pi) / self.bin_theta).astype(np.int64) % self.nt
        return (iy * self.nx + ix) * self.nt + it

    def add(self, particles: np.ndarray) -> np.ndarray:
        """Flag the bins of ``particles`` (3, M); (M,) the count of distinct bins so far after each pose."""
        from mcl.kernels.kld import mark_bins

        p = np.ascontiguousarray(particles, dtype=np.float64)
        m = p.shape[1]
        if self._n_touched + m > self._touched.size:
            grown = np.empty(max(2 * self._touched.size, self._n_touched + m), dtype=np.int64)
            grown[: self._n_touched] = self._touched[: self._n_touched]
            self._touched = grown
        counts = np.empty(m, dtype=np.int64)
        if self.table is None:
            self._n_touched = mark_bins(p, self.x0, self.y0, self.bin_xy, self.bin_theta, self.nx, self.ny,
                                        self.nt, self.flags, self._touched, self._n_touched, self.k, counts)
        else:
            from mcl.kernels.kld import mark_bins_hashed, rehash

            if 2 * (self._n_touched + m) > self.table.size:  # at most half full: short probes
                bits = max(16, int(2 * (self._n_touched + m) - 1).bit_length())
                table = np.zeros(1 << bits, dtype=np.int64)
                rehash(self.table, self._touched, self._n_touched, table, 64 - bits)
                self.table, self._shift = table, 64 - bits
            self._n_touched = mark_bins_hashed(p, self.x0, self.y0, self.bin_xy, self.bin_theta, self.nx, self.ny,
                                               self.nt, self.table, self._shift, self._touched, self._n_touched,
                                               self.k, counts)
        if m:
            self.k = int(counts[-1])
        return counts

    def reset(self) -> None:
        if self._n_touched:
            from mcl.kernels.kld import clear_bins

            clear_bins(self.flags if self.table is None else self.table, self._touched, self._n_touched)
        self._n_touched = 0
        self.k = 0


def bins_occupied(particles: np.ndarray, bin_xy: float, bin_theta: float) -> int:
    """Number of distinct (x, y, theta) bins a (3, N) set occupies (for tests and reports)."""
    ix = np.floor(particles[0] / bin_xy).astype(np.int64)
    iy = np.floor(particles[1] / bin_xy).astype(np.int64)
    it = np.floor((particles[2] + math.pi) / bin_theta).astype(np.int64)
    return int(np.unique(np.vstack([ix, iy, it]), axis=1).shape[1])


class Recovery:
    """Augmented MCL's two averages of the measurement likelihood, in log space, bias-corrected."""

    def __init__(self, alpha_slow: float, alpha_fast: float):
        if not 0.0 < alpha_slow < alpha_fast <= 1.0:
            raise ValueError(f"need 0 < alpha_slow < alpha_fast <= 1, got {alpha_slow}, {alpha_fast}")
        self.alpha_slow = float(alpha_slow)
        self.alpha_fast = float(alpha_fast)
        self._log_slow = -np.inf  # the book's raw averages, started at 0
        self._log_fast = -np.inf
        self.t = 0  # scans folded in

    @staticmethod
    def log_mean_likelihood(logw_prior: np.ndarray, loglik: np.ndarray) -> float:
        """log sum_i w_i p(z | x_i) with w = normalised prior weights (log-sum-exp, never overflows)."""
        top = float(np.max(logw_prior)) if logw_prior.size else -np.inf
        if not np.isfinite(top):  # no prior weight left (or none at all): no information
            return -np.inf
        lp = logw_prior - (top + float(np.log(np.sum(np.exp(logw_prior - top)))))
        s = lp + loglik
        m = float(np.max(s)) if s.size else -np.inf
        if not np.isfinite(m):  # every particle has zero likelihood (or NaN crept in): no information
            return -np.inf
        return m + float(np.log(np.sum(np.exp(s - m))))

    def update(self, log_w_avg: float) -> None:
        """Fold one scan's log mean likelihood into both averages (NaN: ignored; -inf: w_avg = 0)."""
        if np.isnan(log_w_avg) or log_w_avg == np.inf:
            return
        self.t += 1
        self._log_slow = _ema_log(self._log_slow, log_w_avg, self.alpha_slow)
        self._log_fast = _ema_log(self._log_fast, log_w_avg, self.alpha_fast)

    def _corrected(self, log_w: float, alpha: float) -> float:
        if self.t == 0:
            return -np.inf
        # log(1 - (1 - alpha)^t), stable for small alpha * t
        return log_w - math.log(-math.expm1(self.t * math.log1p(-alpha))) if alpha < 1.0 else log_w

    @property
    def log_w_slow(self) -> float:
        """log w_slow, bias-corrected (-inf before the first scan)."""
        return self._corrected(self._log_slow, self.alpha_slow)

    @property
    def log_w_fast(self) -> float:
        """log w_fast, bias-corrected (-inf before the first scan)."""
        return self._corrected(self._log_fast, self.alpha_fast)

    @property
    def inject_probability(self) -> float:
        """max(0, 1 - w_fast / w_slow)."""
        ls, lf = self.log_w_slow, self.log_w_fast
        if ls == -np.inf:
            return 0.0
        return max(0.0, 1.0 - math.exp(min(lf - ls, 0.0)))


def _ema_log(log_w: float, log_x: float, alpha: float) -> float:
    """log((1 - alpha) w + alpha x) from log w and log x."""
    if alpha >= 1.0:
        return float(log_x)
    if log_w == -np.inf and log_x == -np.inf:
        return -np.inf
    return float(np.logaddexp(math.log1p(-alpha) + log_w, math.log(alpha) + log_x))


def draw_injected(n: int, p: float, rng: np.random.Generator) -> int:
    """How many of n new particles come from the recovery sampler: Binomial(n, p)."""
    if p <= 0.0 or n <= 0:
        return 0
    return int(rng.binomial(n, min(p, 1.0)))


def kld_resample(
    particles: np.ndarray,
    logw: np.ndarray,
    rng: np.random.Generator,
    counter: BinCounter,
    *,
    scheme: str,
    min_particles: int,
    max_particles: int,
    epsilon: float,
    z: float,
    inject_p: float = 0.0,
    sampler: Callable[[int], np.ndarray] | None = None,
    move: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """KLD-sampling resample (with optional injection): (new particles (3, M), injected (M,) bool, bins k).

    Batch b draws ``b`` ancestors with ``scheme`` from ``logw`` and shuffles
    them; with ``inject_p > 0`` a Binomial(b, inject_p) of the batch's slots,
    at random positions, take poses from ``sampler(n)`` instead. Injected
    poses count in the bins too (as in AMCL): a lost filter grows its set.
    ``move(batch) -> moved`` (the motion model) is applied to each batch before
    its poses are binned, as Table 8.4 does: without it, bins are counted on
    the resampled ancestors, which after a peaked correction are copies of a
    few poses (AMCL does this, and its sets shrink to the minimum too early).

    With ``min_particles >= max_particles`` the size is fixed: one batch of
    ``max_particles``, no bins counted (k = 0) and no shuffle (a whole batch
    has no prefix to cut): the ancestors in the scheme's order, the draws of a
    plain resample (53 us of 5,000 a resample saved).
    """
    counter.reset()
    if min_particles >= max_particles:  # N fixed (e.g. --particles at or below min_particles): nothing to count
        batch, mask = _kld_batch(particles, logw, rng, max(int(max_particles), 1), scheme, inject_p, sampler,
                                 shuffle=False)
        if move is not None:
            batch = move(batch)
        return np.ascontiguousarray(batch), mask, 0
    k = 0
    total = 0
    batches: list[np.ndarray] = []
    masks: list[np.ndarray] = []
    b = max(int(min_particles), 1)
    while total < max_particles:
        b = min(b, max_particles - total)
        batch, mask = _kld_batch(particles, logw, rng, b, scheme, inject_p, sampler)
        if move is not None:
            batch = move(batch)
        ks = counter.add(batch)
        drawn = total + np.arange(1, b + 1)
        need = np.clip(_bound_table(epsilon, z, int(ks[-1]))[ks], min_particles, max_particles)
        done = np.flatnonzero(drawn >= need)
        if done.size:
            stop = int(done[0]) + 1
            k = int(ks[stop - 1])
            batches.append(batch[:, :stop])
            masks.append(mask[:stop])
            total += stop
            break
        k = int(ks[-1])
        batches.append(batch)
        masks.append(mask)
        total += b
        b = total  # double
    out = np.ascontiguousarray(np.concatenate(batches, axis=1))
    return out, np.concatenate(masks), k


def _kld_batch(particles, logw, rng, b: int, scheme: str, inject_p: float, sampler, shuffle: bool = True):
    """One batch of ``kld_resample``: (b ancestors drawn with ``scheme`` and shuffled (so that any prefix is an
    unbiased draw), with a Binomial(b, inject_p) of its slots taken by ``sampler``; the injected mask)."""
    idx = resample(scheme, logw, rng, n=b)
    if shuffle:
        rng.shuffle(idx)  # the draws of rng.permutation(idx), without its copy
    batch = np.take(particles, idx, axis=1)  # a quarter of particles[:, idx]'s time
    n_inj = draw_injected(b, inject_p, rng) if sampler is not None else 0
    mask = np.zeros(b, dtype=bool)
    if n_inj:
        slots = rng.choice(b, size=n_inj, replace=False)
        batch[:, slots] = sampler(n_inj)
        mask[slots] = True
    return batch, mask


# ----------------------------------------------------------------------------- the filter's policies


class KLDSampling:
    """KLD-sampling resampling as a policy of the filter (Prob. Rob. Table 8.4).

    Table 8.4 bins each particle *after* its motion update, so a resample is
    only scheduled (``schedule``) after the correction and drawn
    (``draw``) with the next control: ancestors drawn batch by batch, moved
    by ``move`` and binned until M_chi(k) is reached (``kld_resample``).
    """

    def __init__(self, fc, grid):
        h, w = grid.occupancy.shape
        size = (w * grid.resolution, h * grid.resolution)
        self.counter = BinCounter(grid.origin, size, fc.kld_bin_xy, fc.kld_bin_theta)
        self.z = kld_quantile(fc.kld_delta)
        self.epsilon = fc.kld_epsilon
        self.scheme = fc.resampling
        self.min_particles = min(fc.min_particles, fc.particles)
        self.max_particles = fc.particles
        self.pending = None  # (inject_p, sampler) of the resample waiting for the next motion

    def schedule(self, inject_p: float, sampler: Callable[[int], np.ndarray]) -> None:
        self.pending = (inject_p, sampler)

    def draw(self, particles, logw, rng, move=None):
        """The scheduled resample: (new (3, M), injected (M,) bool, ok (M,) bool | None, mean tries,
        motion log-weights (M,) | None).

        ``move(batch) -> (moved, ok | None, tries, log_weight | None)`` applies the motion model to each batch
        before it is binned (None: no motion, the ancestors are binned); log_weight is the motion's importance
        weight (an odometry-fault proposal), None when it is 1.
        """
        inject_p, sampler = self.pending
        self.pending = None
        moves: list = []

        def moved(batch):
            new, ok, tries, lw = move(batch)
            moves.append((ok, tries, batch.shape[1], lw))
            return new

        new, fresh, _ = kld_resample(
            particles, logw, rng, self.counter, scheme=self.scheme, min_particles=self.min_particles,
            max_particles=self.max_particles, epsilon=self.epsilon, z=self.z, inject_p=inject_p, sampler=sampler,
            move=moved if move is not None else None,
        )
        m = new.shape[1]
        ok = None
        if any(o is not None for o, _, _, _ in moves):
            ok = np.concatenate([np.ones(n, bool) if o is None else o for o, _, n, _ in moves])[:m]
        lw = None
        if any(w is not None for _, _, _, w in moves):
            lw = np.concatenate([np.zeros(n) if w is None else w for _, _, n, w in moves])[:m]
        tries = sum(t * n for _, t, n, _ in moves) / max(sum(n for _, _, n, _ in moves), 1) if moves else 1.0
        return np.ascontiguousarray(new), fresh, ok, tries, lw


class AugmentedMCL:
    """The book's recovery (Prob. Rob. Table 8.3): inject with p = max(0, 1 - w_fast / w_slow).

    ``observe_likelihood`` folds the per-beam mean likelihood of the tracked
    particles into w_slow and w_fast (``Recovery``); the particles injected at
    the last resample are left out (if every particle was injected, all count).
    """

    name = "augmented"

    def __init__(self, alpha_slow: float, alpha_fast: float):
        self.averages = Recovery(alpha_slow, alpha_fast)

    def observe_likelihood(self, logw_prior: np.ndarray, loglik_per_beam: np.ndarray, injected) -> None:
        keep = injected
        if keep is not None and keep.size == loglik_per_beam.size and not keep.all():
            keep = ~keep
            self.averages.update(Recovery.log_mean_likelihood(logw_prior[keep], loglik_per_beam[keep]))
        else:
            self.averages.update(Recovery.log_mean_likelihood(logw_prior, loglik_per_beam))

    def observe_lost(self, lost: bool, cluster_weight: float = 1.0, dt: float = 0.0, refuted: bool = False,
                     collapsed: bool = False) -> None:
        pass

    @property
    def inject_probability(self) -> float:
        return self.averages.inject_probability

    global_share = 1.0  # every injected pose from the recovery sampler (uniform over free space)
    local_std = None


SETTLED_WEIGHT = 0.9  # a global search has settled once the heaviest cluster holds this much of the weight


def within_std(cov, std: float) -> bool:
    """Whether a cluster with covariance ``cov`` (3x3: x, y, theta) is a place: its x and y std both under ``std``."""
    return max(cov[0][0], cov[1][1]) <= std ** 2


class GlobalSearch:
    """A global search under way: from a global start or a re-seed (``start``) until one hypothesis is left.

    The filter owns one and feeds it every update (``observe``); the search ends in two steps, each with its own
    test, because the two things it suspends answer different questions:

    - ``tempering``, the laser log-likelihood times ``filter.search_exponent``, lasts until the heaviest cluster
      holds ``settled_weight`` of the weight (and, with ``settled_std`` > 0, its x and y std are under that): a
      scan must not pick among hypotheses that are still competing. Clusters are the connected cells the
      particles occupy, whatever their weight, so a dense set (100,000 poses on a small map) is one cluster that
      holds all the weight, with its mean between the places that carry it: settled by weight alone at its
      first update. Without scan matching that works as a string of fresh re-seeds until a place fits (see
      ``filter.search_settled_std`` in configs/default.yaml for the figures); with it, every matched re-seed
      costs a matching of 100,000 poses (``corridor-fast-reversing-h10``: 175 re-seeds, 109 times the CPU);
    - ``holding``, lost recovery neither injecting nor counting lost updates, lasts until then *or* until the
      scan fits the map at the estimate (not lost), whichever is first: a filter that fits needs no injection,
      and one that is still lost once a single cluster is left is lost in the ordinary sense.

    ``since_end`` counts the updates since ``holding`` last ended (None before the first search): the probation
    of ``LostRecovery``. With ``probation_from`` "settled" it starts again when ``tempering`` ends after that: a
    matched search's estimate often fits the scan at its first update, while its cloud is still spread over many
    places, and the place it then settles on has fit only a few scans of its own (``large-06`` global: holding
    ended at 16.2 s, settled 79 m off at 20.4 s, lost at 28.2 s, after a probation of 50 updates from 16.2 s).
    """

    def __init__(self, settled_weight: float = SETTLED_WEIGHT, settled_std: float = 0.0, probation_from: str = "fit"):
        self.settled_weight = float(settled_weight)
        self.settled_std = float(settled_std)
        if probation_from not in ("fit", "settled"):
            raise ValueError(f"probation_from must be 'fit' or 'settled', not {probation_from!r}")
        self.probation_from = probation_from
        self.reset()

    def reset(self) -> None:
        """No search, none before (tracking from a known pose)."""
        self.tempering = False
        self.holding = False
        self.since_end = None
        self.since_end_s = 0.0  # log s from the update ``since_end`` counts from to the latest
        self.starts = 0  # searches started so far

    def start(self) -> None:
        self.tempering = True
        self.holding = True
        self.starts += 1

    def confirm(self) -> None:
        """The search a re-seed started lost to the track it kept (``ParticleFilter.protect``): it ends now, and the
        track is not on probation (it is not a place a search just found)."""
        self.tempering = False
        self.holding = False
        self.since_end = None

    def settles(self, cluster_weight: float, cov=None) -> bool:
        """Whether a heaviest cluster of this weight and covariance (``cov`` None: a place) ends a search's
        tempering: ``settled_weight`` of the weight, and with ``settled_std`` > 0 x and y std under that."""
        compact = self.settled_std <= 0.0 or cov is None or within_std(cov, self.settled_std)
        return cluster_weight >= self.settled_weight and compact

    def observe(self, lost: bool, cluster_weight: float = 1.0, cov=None, dt: float = 0.0) -> None:
        """This update's lost belief, and the heaviest cluster's weight and covariance (after the estimate;
        ``cov`` None: a place); ``dt`` the log time since the previous update."""
        settled = self.settles(cluster_weight, cov)
        if self.tempering and settled:
            self.tempering = False
            if self.probation_from == "settled" and not self.holding and self.since_end is not None:
                self.since_end = 0  # the probation counts from the place the search settled on
        if self.holding and (not lost or settled):
            self.holding = False
            self.since_end = 0
        if not self.holding and self.since_end is not None:
            # the update the count starts from is 0 s into it, each later one dt further
            self.since_end_s = 0.0 if self.since_end == 0 else self.since_end_s + max(float(dt), 0.0)
            self.since_end += 1


class StallCheck:
    """After a global search: does the estimate follow the odometry?

    A search can settle on a place that fits the scans well enough never to be called lost (0.84-0.91 in the
    synthetic corridor worlds, against 0.98 at the true pose) and there the map stops the cloud: the robot drives
    40 m down a corridor while the estimate, in a dead-end corridor the walls of which fit as well, is pulled back
    by every scan and moves 1 m. Odometry drifts, but a correct track's estimate moves with it: over 3 s it went
    0.87 times as far as the truth or more in 99.9 % of the synthetic suite's windows, and never under 0.6. The
    distance between two poses does not depend on the frame, so the odometry's own poses give the distance the
    robot drove, whatever the odometry frame.

    ``stalled`` is True when, over the last ``window`` seconds of log time, the odometry moved at least
    ``min_travel`` and the estimate less than ``ratio`` times as far, at ``CONSECUTIVE`` updates in a row (only a
    compact cluster's estimate counts). An estimate that jumps farther than ``COMPACT`` m beyond the odometry's own
    step in one update has moved to another place: a window that holds such a jump is short only if the part
    since the jump is short too (with no minimum travel). The test runs only for ``active`` seconds after a global
    search ended (from a global start or a re-seed): a track from a known pose is never tested, and neither is a
    place that has held that long. Some real odometry over-reports motion for seconds at a time
    (fr079: 1.9 m reported over 5 s while the robot moved 0.14 m, on a correct track), so a stall means "the place
    the search found is wrong" only while that place is new. Lost recovery re-seeds on it (``LostRecovery``).
    """

    COMPACT = 1.0  # m: an estimate whose cluster is wider than this (x or y std) is not yet a place
    CONSECUTIVE = 3  # updates in a row whose window comes up short: the estimate of a cloud that still has two
    # modes jumps between them for an update (corridor-01: 2.2 m for one scan, 1 s after the search)

    def __init__(self, ratio: float, window: float, min_travel: float, active: float, search: GlobalSearch):
        self.ratio = float(ratio)
        self.window = float(window)
        self.min_travel = float(min_travel)
        self.active = float(active)
        self.search = search
        self.reset()

    def reset(self) -> None:
        self.clock = 0.0  # log seconds since the filter started
        self.since = None  # log time the last search ended (None: none ended yet)
        self.starts = 0  # the search's count of starts when ``since`` was set
        self.history: deque = deque()  # (t, estimate x, y, odometry x, y) since then, covering one window
        self.run = 0  # consecutive updates whose window came up short
        self.jump = None
        self.stalled = False

    def _forget(self) -> None:
        """The window starts again."""
        self.history.clear()
        self.run = 0
        self.jump = None  # the first entry after the estimate's last jump to another place

    def _short(self, a, b, min_travel: float) -> bool:
        """From history entry ``a`` to ``b`` the odometry moved at least ``min_travel`` and the estimate less
        than ``ratio`` times as far."""
        travel = math.hypot(b[3] - a[3], b[4] - a[4])
        return travel >= min_travel and math.hypot(b[1] - a[1], b[2] - a[2]) < self.ratio * travel

    def observe(self, dt: float, estimate, cov, odom) -> None:
        """This update's log time step, estimate (x, y, ...) and its covariance (3x3), and odometry pose (x, y, ...)
        or None (no motion, or an odometry jump: the window starts again). Only a compact estimate (x and y std
        under ``COMPACT`` m) is a place: the mean of a cloud still spread over the map moves for no reason."""
        self.clock += max(float(dt), 0.0)
        self.stalled = False
        search = self.search
        no_place = search.holding or search.since_end is None  # a track from a pose, or a search under way
        if no_place or search.starts != self.starts:  # ... or a new search ended (perhaps in this very update)
            self.since = None
        compact = cov is not None and within_std(cov, self.COMPACT)
        if no_place or odom is None or not compact:
            self._forget()
            return
        if self.since is None:  # the new search's place: a window of its own
            self._forget()
            self.since, self.starts = self.clock, search.starts
        if self.clock - self.since > self.active:
            self._forget()
            return
        h = self.history
        entry = (self.clock, float(estimate[0]), float(estimate[1]), float(odom[0]), float(odom[1]))
        if h and (math.hypot(entry[1] - h[-1][1], entry[2] - h[-1][2])
                  > self.COMPACT + math.hypot(entry[3] - h[-1][3], entry[4] - h[-1][4])):
            self.jump = entry  # the estimate left its place in one update: it is at another place from here
        h.append(entry)
        start = self.clock - self.window
        while len(h) >= 2 and h[1][0] <= start:  # keep the last entry at or before the window's start
            h.popleft()
        if h[0][0] > start:
            return
        short = self._short(h[0], entry, self.min_travel)
        if short and self.jump is not None and self.jump[0] > start:
            # the window holds two places: it is short only if the estimate has not followed the odometry since
            # the jump either. A search whose heading had flipped in a corridor drove the wrong way for a second,
            # then jumped to the true pose and tracked it; the window across the jump came up short, and the
            # correct track was re-seeded (suites/heldout2.yaml corridor-noisy-laser-h9)
            short = self._short(self.jump, entry, 0.0)
        self.run = self.run + 1 if short else 0
        self.stalled = self.run >= self.CONSECUTIVE


class ProbationChallenge:
    """``filter.probation_fit``: a place a search found that fits ``WINDOW`` scans in a row on probation at a median
    quality score (``mcl.quality``: match - 2 contradiction) below ``fit`` is challenged once: ``due`` asks the filter
    for a protected re-seed (``ParticleFilter.protect``), in which the place keeps its cloud and a place found anew
    must out-score it by ``reseed_odds``. A wrong place on a big map fits 0.65-0.75 for many seconds without ever
    staying lost for ``recovery_global_after`` updates (large-03: held 98 m off for 40 s); a right one with people or
    clutter around fits as low, and keeps itself in the protected search.
    """

    WINDOW = 10  # updates in a row whose median score is judged

    def __init__(self, fit: float, search: GlobalSearch):
        self.fit = float(fit)
        self.search = search
        self.reset()

    def reset(self) -> None:
        self.starts = 0  # the search's count of starts when the scores were last reset
        self.scores: deque | None = None  # the place's last scores on probation (None: no place, or challenged)
        self.due = False

    def observe(self, fit, on_probation: bool) -> None:
        """This update's scan fit at the estimate (``mcl.quality.Fit`` or None) and whether the place a search found
        is on probation (``LostRecovery.on_probation``)."""
        if self.starts != self.search.starts:  # a search since: the place it finds is judged afresh
            self.starts = self.search.starts
            self.scores = deque(maxlen=self.WINDOW)
        if self.scores is None or self.search.holding or not on_probation:
            return
        if fit is not None and fit.beams and math.isfinite(fit.score):
            self.scores.append(fit.score)
        if len(self.scores) == self.WINDOW and float(np.median(self.scores)) < self.fit:
            self.due = True
            self.scores = None  # challenged once


class ProtectedReseed:
    """``filter.reseed_odds``: a re-seed of a trusted track (one started from a known pose, or held past the probation
    of the search that found it, or a place ``ProbationChallenge`` challenges) run as two components, the kept track
    (``track``, a (N,) bool mask of the set) and the search. The filter resamples them apart (each keeps its
    particles and its share of the weight) and hands this object each update's two log masses; ``odds`` is the
    log-odds of the search against the track that counted: the prior ``log((1 - keep) / keep)`` plus the evidence
    of every scan that also fits the map better (the quality score) at the estimate of the side it favours. One scan
    moves it by ``STEP`` nats at most, unless it fits the search's place at ``DECISIVE_FIT`` or better and the
    track's below ``quality.lost_below``. A scan with no beam through a mapped wall at the track's estimate (it looks
    occluded there) counts for a global search only if the search's place fits it at ``DECISIVE_FIT``. With
    ``local`` the other side is not a global search but lost recovery's
    spread around the estimate (``filter.recovery_protect``), and a scan counts only if it also fits the side it
    favours as a tracked scan does (at ``quality.lost_below`` or better): one that fits neither is no evidence. For
    the spread it must also fit the track as a lost scan does (below ``quality.lost_below``), and no one scan decides
    a spread: its best pose of thousands near the track can fit a cluttered scan better by chance. The
    re-seed is ``settled`` once one side leads by ``reseed_odds`` nats, or after ``MAX_UPDATES`` updates (the
    heavier side, a tie to the track). Outdoors a correct track fits poorly for seconds (freiburg-campus: match
    0.2-0.7); on one scan a place 170 m away fitted better, took the whole set at the
    next resample, and the estimate jumped there (RMSE 15 m).
    """

    MAX_UPDATES = 25  # updates a protected re-seed may last; then the heavier side wins
    STEP = 3.0  # nats: the most one scan may move the log-odds (with reseed_odds 4.6, two scans decide)
    DECISIVE_FIT = 0.9  # ... unless the search's place fits it at least this well (quality score) and the track is bad

    def __init__(self, track: np.ndarray, keep: float, reseed_odds: float, lost_below: float, local: bool = False,
                 min_beams: int = 0):
        self.track = track
        # a scan with fewer returns than this decides nothing at once (the held track's bar, quality.held_min_beams
        # as mcl.quality.ScanQuality takes it): nine people's returns in a hall fitted a place 38 m away at 0.9 and
        # the correct track at 0 (a hunt's hall-p24-res2-pmax-w3631)
        self.min_beams = int(min_beams)
        self.local = bool(local)  # the other side is lost recovery's spread around the estimate, not a global search
        self.reseed_odds = float(reseed_odds)
        self.lost_below = float(lost_below)
        self.odds = math.log(1.0 - keep) - math.log(keep) if keep < 1.0 else -math.inf
        self.prior = self.odds  # the odds before any scan counted
        self.track_score = math.nan  # the quality score at the track's estimate of the last scan that moved the masses
        self.updates = 0
        self.concurred = False  # the search gathered on the track's place (concur): the track wins

    def weigh(self, log_track: float, log_search: float,
              scores: Callable[[], tuple[float, float, float, float]] | None) -> float:
        """This update's log masses of the two sides (log-sum-exp: a side can hold e^-50 of the weight and still
        come back) -> the odds that counted. ``scores()`` gives this scan's quality score at the search's and at
        the track's estimate, then the share of its beams through mapped walls at each (only the track's is read
        since the sixty-first session's occlusion rule), then its beams with a return, asked only when the masses
        moved; None when the update had no scan."""
        raw = log_search - log_track
        odds = raw
        if not (math.isfinite(log_track) and math.isfinite(log_search)):  # a side with no weight at all lost
            odds = -math.inf if math.isfinite(log_track) else math.inf
        elif raw != self.odds and scores is not None:
            # this scan's evidence counts only if the scan also fits the map better at the side it favours:
            # outdoors one scan that fits the true pose badly (a third of its beams through mapped walls) gave a
            # place 176 m away e^50 the likelihood while fitting worse still there (-0.23 against 0.02: the
            # likelihood field does not see readings through walls)
            s_search, s_track, _, c_track, returns = scores()  # (the search's share through walls: no rule reads it)
            self.track_score = s_track
            # a scan fits the search's place as a tracked scan does (decisive) only with returns enough to tell
            decisive = s_search >= self.DECISIVE_FIT and returns >= self.min_beams
            step = raw - self.odds if (raw - self.odds) * (s_search - s_track) >= 0.0 else 0.0
            # nor, for a global search, a scan the track explains as occlusion (no beam through a mapped wall),
            # unless it fits the search's place as a tracked scan does (DECISIVE_FIT): people end readings short of
            # walls, and a place elsewhere that lays some of them on its walls fits the scan better without being
            # right. People crowding the robot in a hall left a correct track at 0.45-0.53 (scans 0.1 s late), and a
            # place 10.7 m away fitted them at 0.48-0.62 with 3-7 % through walls and took the estimate
            # (hall-people-dropouts-h10); fifteen people round a 360-degree 12 m lidar in a hall (11-19 returns of
            # 60 directions) left the track at 0.28-0.45 with nothing through walls, and a place 12.4 m away, with
            # nothing through walls either, fitted them at 0.44-0.73 and took the estimate (heldout9
            # hall-360-crowd-h16: 12-31 m off for 4 s, every seed). A right place that fits at 0.89-0.96 can still
            # have one stray beam through a corner: held back by it, the demo's recovery from its kidnapping took a
            # second longer
            if step > 0.0 and not self.local and c_track == 0.0 and not decisive:
                step = 0.0
            # and, for a spread around the estimate (local), only if the scan fits the side it favours as a tracked
            # scan does: two seconds of a tilted laser's ground hits fit no pose near the track, and spread poses
            # where the line met a wall fitted them better than the track and won. For the spread, the scan must
            # also fit the track as a lost scan does: people filling a depth camera's 58-degree view fitted the
            # best of 5,000 spread poses 0.5-1 m away at 0.93-0.98 and the correct track at 0.67-0.82, and two such
            # scans handed the spread the estimate (heldout clutter-kinect-h8: 3 of 3 seeds lost). Not for a
            # global search: after a kidnap its place fits poorly for many scans while it converges
            # (heldout-real-gentle fhw: -1.1 to 0.3 against the track's -1.7 to 0.2), and held apart for 25
            # updates it starved (kidnapped 0 of 3)
            if self.local:
                favoured = s_search if step > 0.0 else s_track
                if favoured < self.lost_below or (step > 0.0 and s_track >= self.lost_below):
                    step = 0.0
            # and no one scan decides: on the campus a scan fitted the true pose at -0.04 and a place 205 m away at
            # 0.60 (both signals agreed), and the scans after it fitted the track at 0.29-0.95 and far places below
            # -1; unless the scan fits the search's place as a tracked scan does and the track's as a lost one: on
            # a log with a scan every 3 s (fr101, kidnapped: 0.96 against 0.34) the second scan came 17 s later.
            # Never for a spread, whose best pose of thousands near the track fits a cluttered scan best by chance
            if self.local or not (decisive and s_track < self.lost_below):
                step = min(max(step, -self.STEP), self.STEP)
            odds = self.odds + step
        self.odds = odds
        self.updates += 1
        return odds

    def concur(self) -> None:
        """The search gathered on the track's own place (``ParticleFilter._search_concurs``): the track wins."""
        self.concurred = True

    @property
    def settled(self) -> bool:
        return self.concurred or abs(self.odds) >= self.reseed_odds or self.updates >= self.MAX_UPDATES

    @property
    def track_won(self) -> bool:
        return self.concurred or self.odds <= 0.0

    def defers_reseed(self, wait_fit: float) -> bool:
        """Whether a global re-seed that falls due now waits (``filter.reseed_wait_fit``; 0: never): this is lost
        recovery's spread (local), scans have counted for it and it leads, it has not settled, and the track's last
        scan still scored ``wait_fit`` or better. The re-seed keeps the side that leads, and a spread pose that fits a
        stale map better than the correct track can lead for a while before the scans settle it the other way. A
        kidnapped track's scans fall off (intel_lab: 0.33, 0.28, 0.17, -0.10), and its re-seed is not held back long.
        """
        return (self.local and wait_fit > 0.0 and not self.settled and self.odds > self.prior
                and self.track_score >= wait_fit)


SLIP_SPREAD = 1.0  # m: the whole set's position spread up to which a wheel's slip is doubted (one cloud)


class FaultWindow:
    """When the motion model allows odometry faults (``mcl.motion.FaultProposal``, ``motion.fault_*``).

    A track that slips because the odometry is wrong (fr079 at 305 s: 0.1 m forward per scan reported for 6 s
    while the robot reverses) drifts 0.2 m a scan from a cloud a few centimetres wide: the scan pulls it back, but
    no particle is where the robot is, and the lost call comes 2 m late. Allowing faults all the time lets a few
    scans that fit a pose a metre or two away (a person next to the robot at a corridor junction, on
    infinite_corridor) carry the track off. So faults are allowed only where the quality signal has shown that one
    may be under way: from a lost call that ends at least ``fault_window`` updates of good tracking (not lost, no
    global search) and whose scan contradicts the map at the estimate (at least ``fault_contradiction`` of the
    beams went through a mapped wall: people and furniture the map lacks only shorten readings, so a lost call
    they cause opens nothing), while the filter stays lost and for ``fault_window`` updates after, or
    ``fault_window_s`` seconds of log time if that comes first (a sparse log's 50 updates span 150 s, and with its
    scans 3 s apart the fault component's caps, rates times the update's duration, are as wide as a search: a
    90-degree laser on intel_lab took a fault pose 1 m off 60 s after the lost call). A lost call
    during or just after a global search means a wrong hypothesis, not a slipping one; the search's re-seeds
    handle it, and a search closes the window.

    For the window's first ``fault_widen_after`` lost updates the fault component is capped (``fault_shift_max``,
    ``fault_turn_max``): a short episode is a slip or a glitch, and a fast robot's full-width component (2.2 m at
    1 m a scan) let scans stamped late at a junction turn the cloud around (infinite_corridor). After that it has
    its full width, which is a search as well: a kidnapped fast robot's wide fault poses find it within seconds.
    Once the track holds again (an update not lost, after the window's last lost one) the search is over: the
    component is capped at ``fault_shift_max`` and its heading at ``fault_held_turn_max`` until the window closes or
    the filter is lost again. A square room whose walls the map draws twice fitted a pose turned 60-90 degrees as
    well as the held track, and the full-width heading put fault poses there (hunt world w3676: 1.95 m off).

    With ``motion.slip_turn`` > 0 (off by default) one fault stays allowed outside the window, on every update: a
    wheel's slip, a turn the odometry reports and the robot did not make. Its component widens the heading alone,
    in proportion to the step's own turn, so a straight step is the plain model (a heading 10 times the model's
    on every step let a 270-degree lidar's cloud turn round in a corridor and run 36 m; widening the translation
    too ran infinite_corridor off). Only while the whole set is one cloud (its position spread within
    ``SLIP_SPREAD``): where a search or a re-seed holds hypotheses metres apart, the turn the robot makes at a
    junction is what tells them apart (suites/synthetic.yaml global 110/126 without this gate, 115/126 with no
    slip at all, 111/126 with it).
    """

    def __init__(self, mc, search: GlobalSearch):
        from mcl.motion import FaultProposal

        self.window = int(mc.fault_window)
        self.window_s = float(mc.fault_window_s)
        self.contradiction = float(mc.fault_contradiction)
        self.search = search
        self.wide = FaultProposal(float(mc.fault_prob), float(mc.fault_share), float(mc.fault_scale))
        self.turn_rate, self.shift_rate = float(mc.fault_turn_max), float(mc.fault_shift_max)  # per second
        self.widen_after = int(mc.fault_widen_after)
        self.held_turn_rate = float(mc.fault_held_turn_max)  # per second, once the track holds again
        slip = float(mc.slip_turn)
        self.slip = (FaultProposal(float(mc.fault_prob), float(mc.fault_share), float(mc.fault_scale), turn_rel=slip)
                     if slip > 0.0 else None)
        self.reset()

    def reset(self) -> None:
        """Closed; a track from a known pose starts here (it has held since the start)."""
        self.held = self.window  # consecutive updates of good tracking before this one
        self.compact = True  # the whole set's position spread within SLIP_SPREAD at the last update
        self.since_lost = None  # updates since the window's last lost update (None: closed)
        self.since_lost_s = 0.0  # ... and the log time they span
        self.lost_run = 0  # lost updates of the window so far

    def observe(self, lost: bool, contradiction: float = 1.0, spread: float = 0.0, dt: float = 0.0) -> None:
        """This update's lost belief (after the filter's ``search`` has seen it), the fraction of its beams that
        contradict the map at the estimate (``mcl.quality.Fit.contradiction``), the whole set's position spread
        (m, the root of its x and y variances) and the log time since the previous update (s)."""
        self.compact = spread <= SLIP_SPREAD
        if self.search.holding:
            self.held, self.since_lost = 0, None
        elif lost:
            if self.since_lost is not None or (self.held >= self.window and contradiction >= self.contradiction):
                self.lost_run = self.lost_run + 1 if self.since_lost is not None else 1
                self.since_lost, self.since_lost_s = 0, 0.0
            self.held = 0
        else:
            self.held += 1
            if self.since_lost is not None:
                self.since_lost += 1
                self.since_lost_s += max(float(dt), 0.0)
                # closed after `window` updates, or `window_s` s: a scan every 3 s keeps 50 updates open for 150 s,
                # with the fault component's caps (rates times the update's dt) as wide as the search's
                if self.since_lost > self.window or 0.0 < self.window_s < self.since_lost_s:
                    self.since_lost = None

    @property
    def open(self) -> bool:
        """The window is open: the motion model is the fault mixture (from a lost call until ``window`` updates,
        or ``window_s`` seconds, after the last lost one)."""
        return self.since_lost is not None

    def proposal(self, dt: float):
        """The ``FaultProposal`` for the next motion update, which spans ``dt`` s of the log: for the window's first
        ``fault_widen_after`` lost updates with its stds capped at ``fault_shift_max`` and ``fault_turn_max`` times
        ``dt`` (a slip accrues with time: a sparse log's update may hold a larger one), at full width after; once
        the track holds again inside the window, capped at ``fault_shift_max`` and ``fault_held_turn_max`` times
        ``dt`` (``fault_held_turn_max`` 0: as while lost); while the window is closed, a wheel's slip
        (``motion.slip_turn``) while the set is one compact cloud, or None (the plain motion model)."""
        if not self.open:
            return self.slip if self.compact else None
        # held again: no search, and a fault pose turned far off need only out-fit the track once to take it
        held = bool(self.since_lost) and self.held_turn_rate > 0.0
        if dt <= 0.0 or (self.lost_run > self.widen_after and not held):
            return self.wide
        turn_rate = self.held_turn_rate if held else self.turn_rate
        return dataclasses.replace(self.wide, turn_max=turn_rate * dt, shift_max=self.shift_rate * dt)


def _spans(seconds: float, floor: float) -> bool:
    """Whether log time summed over updates reaches a floor of seconds, the sum's rounding forgiven: the floors are
    what a count of updates spans at 5 Hz, and nine steps of 0.2 s sum to 1.7999... s."""
    return seconds >= floor - 1e-9


class LostRecovery:
    """Recovery only when lost, local before global.

    While the quality signal (``mcl.quality``) says the filter is lost, a
    ``fraction`` of N is drawn at each resample instead of from the weighted
    set: first around the estimate, from a Gaussian whose std starts at
    ``local_std`` and doubles every ``lost_after`` lost updates (up to 8x),
    then, once the filter has been lost for ``global_after`` updates, half of
    them uniformly over free space. None while it is not lost.

    The spread around the estimate (and the tempered scan that goes with it,
    ``ParticleFilter._laser_exponent``) waits ``wait`` lost updates while the
    lost scans look like an occlusion, and starts at once when one of the
    episode refutes the estimate (``ScanQuality.refutes``: it went through
    mapped walls, or most of it ends far from any). People filling a depth
    camera's narrow view took a correct track's score under
    ``quality.lost_below`` (match 0.52, 3-7 % through mapped items after a
    2-4 degree heading drift), and a pose spread 0.5-1 m away, where they
    look like walls, won at the next scan (suites/heldout.yaml
    clutter-kinect-h8, every seed). A kidnapped robot's first scans match
    0-0.35 and a track that slipped (fr079 at 305 s) reads through walls:
    both are spread at once, as before.

    The w_fast / w_slow ratio of augmented MCL reacts to the scene as much as
    to being lost (open halls, long corridors and many no-return beams lower
    the mean likelihood at the true pose), and injected poses in look-alike
    places then hijack a correct track. The quality signal asks instead
    whether the scan fits the map at the estimate, which does not depend on
    the scene. And a track that slipped is far more often a few metres off
    than kidnapped: a uniform draw over a 250 m map of similar corridors finds
    a look-alike pose that fits one scan better than the slipped cloud does
    (measured on infinite_corridor: the estimate jumped 134 m), while a local
    spread finds the true pose within a few updates.
    """

    name = "lost"

    def __init__(self, fraction: float, local_std, global_after: int, lost_after: int,
                 reseed: bool = False, probation: int = 0, search: GlobalSearch | None = None,
                 global_after_s: float = 0.0, stall: StallCheck | None = None, wait: int = 0,
                 relapse_s: float = 0.0, global_min_s: float = 0.0, probation_min_s: float = 0.0):
        self.reseed = bool(reseed)
        self.stall = stall  # the filter's (read only here): a new place whose estimate does not follow the odometry
        self.probation = int(probation)
        self.probation_min_s = float(probation_min_s)  # log s the probation lasts at least (with probation on)
        # the filter's search (read only here); a policy used on its own gets one that never starts
        self.search = search if search is not None else GlobalSearch()
        self.fraction = float(fraction)
        self.base_std = np.asarray(local_std, dtype=np.float64)
        self.global_after = int(global_after)
        self.global_after_s = float(global_after_s)
        self.global_min_s = float(global_min_s)  # log s the global_after updates must span
        self.lost_after = max(int(lost_after), 1)
        self.lost_updates = 0  # consecutive updates the filter has believed it is lost
        self.lost_time = 0.0  # log seconds from the first of them to the last
        self.wait = int(wait)  # lost updates before the spread around the estimate, unless refuted
        self.refuted = False  # a scan of this lost episode refuted the estimate
        self.collapsed = False  # this lost episode began with a collapse (mcl.quality.ScanQuality.update)
        self.relapse_s = float(relapse_s)
        self.since_episode: float | None = None  # log s since the last episode ended without a re-seed (None: none)
        self.relapsed = False  # this lost episode began within relapse_s of such an end
        self.searched = False  # a search started since the last update that was not lost (start_search)

    def start_search(self) -> None:
        """Global localization starts (the filter has started ``search``): the set is already spread over the
        map, so nothing is injected (and nothing forces a resample) while ``search.holding``. Injecting around
        the estimate of a still multi-modal cloud feeds whichever mode leads by chance and ends the search
        early. The lost count starts again."""
        self.lost_updates = 0
        self.lost_time = 0.0
        self.collapsed = False
        self.since_episode = None
        self.relapsed = False
        self.searched = True

    def observe_likelihood(self, logw_prior, loglik_per_beam, injected) -> None:
        pass

    def observe_lost(self, lost: bool, cluster_weight: float = 1.0, dt: float = 0.0, refuted: bool = False,
                     collapsed: bool = False) -> None:
        """This update's lost belief, after the filter's ``search`` has seen it (``cluster_weight`` is the
        search's business); ``dt`` the log time since the previous update; ``refuted``: its scan refutes the
        estimate (``ScanQuality.refutes``; remembered until an update is not lost, through a global search);
        ``collapsed``: its lost call was a collapse (``ScanQuality.update``; remembered until the re-seed, or until
        an update is not lost)."""
        self.refuted = self.refuted or bool(refuted)
        if self.search.holding:
            return
        if not lost:
            if self.lost_updates:  # an episode ended; without a re-seed in it (a re-seed starts a search) it counts
                self.since_episode = None if self.searched else 0.0
            elif self.since_episode is not None:
                self.since_episode += max(float(dt), 0.0)
            self.searched = False
            self.lost_updates, self.lost_time = 0, 0.0
            self.refuted = False
            self.collapsed = False
            self.relapsed = False
            return
        if not self.lost_updates:
            self.relapsed = (self.relapse_s > 0.0 and self.since_episode is not None
                             and self.since_episode + max(float(dt), 0.0) <= self.relapse_s)
        self.collapsed = self.collapsed or bool(collapsed)
        if self.lost_updates:
            self.lost_time += max(float(dt), 0.0)
        self.lost_updates += 1

    @property
    def global_due(self) -> bool:
        """Lost for ``global_after`` updates spanning at least ``global_min_s`` log seconds, or for
        ``global_after_s`` log seconds over at least ``lost_after`` updates (the local spread has had its first
        round): the local spread did not find the pose. The floor keeps a fast laser's count from being a fraction of
        a second: at 15 Hz ten updates are 0.67 s, and a correct track called lost while its laser saw the ground for
        2 s was re-seeded inside them, a look-alike 28 m away fitting the ground hits' scans at 0.92 (a generated
        building under an 8 m laser, seeds 2-3 lost 64-71 m off; the baseline 0.26 m)."""
        if self.lost_updates >= self.global_after and _spans(self.lost_time, self.global_min_s):
            return True
        return (self.global_after_s > 0.0 and self.lost_updates >= self.lost_after
                and self.lost_time >= self.global_after_s)

    @property
    def on_probation(self) -> bool:
        """A global search ended less than ``probation`` updates ago: the hypothesis it settled on has fit only a
        few scans, and on a big map of look-alike places a wrong one often fits them (measured on the large
        synthetic worlds: settled 33 m off after 2 s, then lost and found again for 20 s without ever staying
        lost for ``global_after`` updates). A lost call then re-seeds at once. The probation lasts at least
        ``probation_min_s`` of log time, what its updates span at 5 Hz, where the count was chosen: at 30 Hz fifty
        updates are about 3 s, and a global search that settled 46 m off in a generated hall held there, fitting at
        0.95, past the probation (back at 61.0 s; with 10 s its place was challenged on probation: 16.7 s)."""
        since = self.search.since_end
        if since is None or self.probation <= 0:
            return False
        return since <= self.probation or not _spans(self.search.since_end_s, self.probation_min_s)

    @property
    def inject_probability(self) -> float:
        return self.fraction if self.spreading else 0.0

    @property
    def spreading(self) -> bool:
        """Lost, and past the ``wait`` or refuted: poses are drawn around the estimate, the scan tempered."""
        return bool(self.lost_updates) and (self.lost_updates > self.wait or self.refuted)

    @property
    def reseed_due(self) -> bool:
        """With ``reseed``: ``global_due`` (the local spread did not find the pose), so the next resample adds a
        whole global set and starts a search (``start_search``). So does a place a search found, lost or not,
        when its estimate stalls while the odometry drives on (``StallCheck``), and a lost episode that began with a
        collapse (``quality.collapse_from``), at once: a held track whose scan went through walls in one update
        was kidnapped, or slipped to a place no spread around it finds for sure. A spread around the old place
        finds a look-alike there in a corridor: the kidnapped robot turns, and the old stretch, turned as much,
        fits again (``corridor-01`` kidnapped: 40 m off for the rest of the run on every seed). And so does a
        relapse (``relapsed``): a lost call within ``relapse_s`` of log time after an episode that ended without a
        re-seed in it (the track, or a spread pose near it, fitting again): a kidnapped robot's old place in a row
        of look-alike offices fits again at 0.65-0.85 for seconds at a time, between short lost episodes that never
        reach ``global_due`` (``office-short-range-01`` kidnapped seed 1: four, 30.4 s to come back; 8.6 s)."""
        if not self.reseed or self.search.holding:
            return False
        if self.stall is not None and self.stall.stalled:
            return True
        if not self.lost_updates:
            return False
        return self.global_due or self.on_probation or self.collapsed or self.relapsed

    @property
    def global_share(self) -> float:
        """The share of the injected poses drawn uniformly over free space (the rest around the estimate)."""
        return 0.5 if self.global_due and not self.reseed else 0.0

    @property
    def local_std(self) -> np.ndarray:
        """Std (x, y, theta) of the poses drawn around the estimate: doubling every lost_after lost updates."""
        k = max(self.lost_updates - 1, 0) // self.lost_after
        return self.base_std * 2.0 ** min(k, 3)


def make_recovery(fc, global_start: bool, lost_after: int = 3, search: GlobalSearch | None = None,
                  stall: StallCheck | None = None):
    """The recovery policy ``filter.recovery`` names (None: no recovery) for a run that starts globally or not;
    ``lost_after`` is the quality section's (the local spread doubles at that pace); ``search`` the filter's
    global search and ``stall`` its stall test, which lost recovery reads."""
    mode = fc.recovery
    if mode == "auto":
        mode = "augmented" if global_start else False
    if mode is True or mode == "augmented":
        return AugmentedMCL(fc.recovery_alpha_slow, fc.recovery_alpha_fast)
    if mode == "lost":
        return LostRecovery(fc.recovery_fraction, fc.recovery_local_std, fc.recovery_global_after, lost_after,
                            reseed=fc.recovery_reseed, probation=fc.recovery_probation, search=search,
                            global_after_s=fc.recovery_global_after_s, stall=stall, wait=fc.recovery_wait,
                            relapse_s=fc.recovery_relapse_s, global_min_s=fc.recovery_global_min_s,
                            probation_min_s=fc.recovery_probation_min_s)
    return None


class OdometryScale:
    """``motion.scale_window``: an online estimate ``k`` of the odometry's translation scale (a wheel radius set a few
    per cent off, worn tyres), by which the motion model then stretches every odometry step.

    After the correction of a held track, the shift the scan gave the cloud's mean along the direction of travel
    (``shift``) is what the scaled step missed: the robot went k d + shift where the odometry read d. So the scale
    the scans saw is the distance-weighted mean of (k d + shift) / d over recent travel (forgetting over ``window``
    metres), starting from ``prior`` metres of travel at scale 1 (forgotten as the rest) and held within
    1 +- ``limit``. Along a featureless corridor the scans shift nothing along it and ``k`` holds; where the odometry
    keeps falling short, the scans keep pulling the cloud forward and ``k`` grows until they need not (the filter
    feeds only updates whose scan pinned the pose along the travel: ``mcl.filter.SCALE_PIN``). A step the filter
    does not trust (lost, searching, on probation, a protected re-seed, an odometry-fault window) is not counted.
    """

    def __init__(self, window: float, prior: float, limit: float):
        self.window = float(window)
        self.prior = float(prior)
        self.limit = float(limit)
        self.reset()

    def reset(self) -> None:
        self.k = 1.0
        # the prior's metres at scale 1, then each step's (k d + shift) and d, all forgotten over the window's travel
        self._seen = self.prior
        self._travel = self.prior

    def scaled(self, control):
        """``control`` (``mcl.filter.Control``) with its translation times ``k``: the odometry pair's step in x, y
        (the rotations as read) and the velocity v."""
        if self.k == 1.0:
            return control
        prev, now = np.asarray(control.odom_prev, dtype=np.float64), np.asarray(control.odom_now, dtype=np.float64)
        stretched = now.copy()
        stretched[:2] = prev[:2] + self.k * (now[:2] - prev[:2])
        return dataclasses.replace(control, odom_now=stretched, v=self.k * float(control.v))

    def observe(self, shift: float, d: float, k_used: float) -> None:
        """One trusted update: the scan's shift of the mean (m) along the direction of an odometry step of ``d`` m
        (unscaled) that the motion model stretched by ``k_used``."""
        if not (d > 0.0 and math.isfinite(shift)):
            return
        keep = math.exp(-d / self.window)
        self._seen = keep * self._seen + k_used * d + shift
        self._travel = keep * self._travel + d
        if self._travel > 0.0:
            self.k = min(max(self._seen / self._travel, 1.0 - self.limit), 1.0 + self.limit)
