"""Odometry motion model, plain and map-based (Prob. Rob. ch. 5).

``OdometryMotionModel.sample`` is ``sample_motion_model_odometry`` (Table 5.6)
for N particles at once, with the refinements of ROS AMCL's
``odometryUpdate`` (diff-drive model):

* the odometry step is split into rot1, trans, rot2 (``odometry_deltas``);
  when the robot moved less than 1 cm, rot1 = 0 (atan2 of a tiny vector is
  noise);
* a step backwards (|rot1| > pi/2) is read forwards for the noise, as the
  same motion (rot1 -+ pi, -trans, rot2 +- pi) (``noise_rotations``), so a
  robot driving backwards (rot1 ~ pi) gets small noise, not pi-sized noise.
  AMCL folds each rotation alone (min(|rot|, |rot -+ pi|)), which gives a
  turn on the spot by pi (rot1 = 0, rot2 = pi, as after a scan gap or an
  odometry stall) no noise at all;
* ``noise_form="variance"`` (book and AMCL):
      sigma_rot1^2  = alpha1 rot1^2 + alpha2 trans^2
      sigma_trans^2 = alpha3 trans^2 + alpha4 (rot1^2 + rot2^2)
      sigma_rot2^2  = alpha1 rot2^2 + alpha2 trans^2
  ``noise_form="std"`` (lecture slides):
      sigma_rot1  = alpha1 |rot1| + alpha2 trans, and so on.
  With ``noise_step`` > 0 (``MotionConfig``'s default 0.3 m) a step longer
  than noise_step has the translation-driven noise of a random walk of such
  steps: trans^2 -> trans * min(trans, noise_step) above (``noise_trans``);
  ``noise_step=0`` is the book's formulas exactly.

Map-based motion model (seed section 5.5, ``sample_motion_model_with_map``):
with an ``allowed`` mask (``allowed_mask``: free cells farther than the robot
radius from any occupied cell), a particle whose new pose lands outside it
(or off the map) is sampled again with fresh noise, up to ``max_tries``
times. The loop runs over tries, never over particles. A particle that never
lands gets ``ok = False``; the filter gives it weight zero.

Odometry faults (an mcl extension; ``FaultProposal``): a wheel that slips,
a bump or a bad encoder moves the robot far from where its odometry says, for
seconds at a time (fr079 at 305 s reports 0.1 m forward per scan for 6 s
while the robot reverses). The motion model is then the mixture

    p_f(x' | u, x) = (1 - prob) p(x' | u, x) + prob p_k(x' | u, x),

p_k the same model with every sigma times ``scale``. It is sampled with a
``share`` of the particles drawn from p_k (a proposal q with the mixture
weight ``share`` instead of ``prob``, so the wide component is explored
although it is rare) and each particle carries the importance weight
p_f / q of its noise (``fault_log_weights``): a pose off the ordinary cloud
must out-score it by log(share / prob) before it is believed.

A wheel's slip (``turn_rel``, ``motion.slip_turn``): one wheel spinning on a
wet floor reads travel the robot did not make, and the odometry turns the
robot that did not turn (1-2 rad/s for a 0.4 m wheel base). Its p_k widens
the heading alone, to ``turn_rel`` times the step's own turn: the turn may be
the wheel's, not the robot's, and a step without a turn has none to doubt.

All random numbers come from the caller's ``numpy.random.Generator``
(standard normals, drawn outside the numba kernels), so one seed gives the
same particles whatever the numba thread count.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mcl.kernels import motion as _k
from mcl.maps import byte_mask
from mcl.noise import log_density, standard_noise
from mcl.parallel import check_out

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
    for name, pose in (("odom_prev", odom_prev), ("odom_now", odom_now)):
        if np.shape(pose) != (3,):  # a log's odometry row (t, x, y, theta, v, w) read t as x
            raise ValueError(f"{name}: expected an odometry pose (x, y, theta), got shape {np.shape(pose)}")
    x0, y0, t0 = (float(v) for v in odom_prev)
    x1, y1, t1 = (float(v) for v in odom_now)
    dx, dy = x1 - x0, y1 - y0
    trans = math.hypot(dx, dy)
    rot1 = 0.0 if trans < ROT1_MIN_TRANS else angle_diff(math.atan2(dy, dx), t0)
    rot2 = angle_diff(angle_diff(t1, t0), rot1)
    return rot1, trans, rot2


def noise_rotations(rot1: float, rot2: float) -> tuple[float, float]:
    """(|rot1|, |rot2|) as the noise sees them: the turns the robot really made. A step backwards (|rot1| > pi/2)
    is the same motion as (rot1 -+ pi, -trans, rot2 +- pi), whose rotations are pi - |rot1| and pi - |rot2|, so a
    reversing robot (rot1 ~ pi, rot2 ~ -pi) gets small noise, not pi-sized noise. AMCL folds each rotation alone,
    min(|rot|, |rot -+ pi|), which also folds a turn on the spot (rot1 = 0): a turn by pi got no noise at all."""
    r1, r2 = abs(angle_diff(rot1, 0.0)), abs(angle_diff(rot2, 0.0))
    if r1 > 0.5 * math.pi:
        return math.pi - r1, math.pi - r2
    return r1, r2


def noise_trans(trans, cfg):
    """|dtrans| as the translation-driven noise terms see it: sqrt(|dtrans| * min(|dtrans|, noise_step)).

    Table 5.6 draws the noise once per control, with a variance that grows as dtrans^2: a log with a scan every metre
    gets 20 times the heading variance per metre of travel of one read every 5 cm. Odometry errors accrue along the
    path, so beyond ``motion.noise_step`` a step counts as a random walk of steps that long (variance linear in the
    distance); shorter steps, and ``noise_step`` 0, are the book's. Floats or arrays.
    """
    step = float(getattr(cfg, "noise_step", 0.0))
    t = np.abs(np.asarray(trans, dtype=np.float64))
    if step > 0.0:
        t = np.sqrt(t * np.minimum(t, step))
    return float(t) if t.ndim == 0 else t


def noise_sigmas(rot1: float, trans: float, rot2: float, cfg) -> tuple[float, float, float]:
    """Standard deviations (sigma_rot1, sigma_trans, sigma_rot2) of the noise on the deltas.

    ``cfg`` needs alpha1..alpha4, noise_form ("variance" or "std") and noise_step (0: the book's trans^2; a
    MotionConfig's default 0.3 m: a longer step's trans^2 is trans * 0.3, ``noise_trans``); the rotations enter
    as ``noise_rotations`` reads them (a step backwards read forwards).
    """
    a1, a2, a3, a4 = float(cfg.alpha1), float(cfg.alpha2), float(cfg.alpha3), float(cfg.alpha4)
    r1, r2 = noise_rotations(rot1, rot2)
    t = noise_trans(trans, cfg)
    if cfg.noise_form == "variance":
        return (math.sqrt(a1 * r1 * r1 + a2 * t * t),
                math.sqrt(a3 * t * t + a4 * (r1 * r1 + r2 * r2)),
                math.sqrt(a1 * r2 * r2 + a2 * t * t))
    if cfg.noise_form == "std":
        return (a1 * r1 + a2 * t, a3 * t + a4 * (r1 + r2), a1 * r2 + a2 * t)
    raise ValueError(f"motion.noise_form: unknown value {cfg.noise_form!r} (expected 'variance' or 'std')")


@dataclass(frozen=True)
class FaultProposal:
    """The odometry-fault mixture of one update: model weight ``prob`` of p_k (sigmas times ``scale``), proposal
    weight ``share`` (see the module docstring; built from the motion config by ``mcl.adaptive.FaultWindow``).
    ``turn_max`` (rad) and ``shift_max`` (m) cap p_k's heading and translation stds (never below the model's own;
    0: no cap). Without them a fast robot's p_k is metres wide: 5 m/s, 1 m a scan, gives a translation std of
    2.2 m, and a turn's heading std can reach pi (infinite_corridor with late scans: the estimate turned around
    and ran 16 m down the corridor). ``mcl.adaptive.FaultWindow`` caps a window's first lost updates only."""

    prob: float
    share: float
    scale: float
    turn_max: float = 0.0
    shift_max: float = 0.0
    turn_rel: float = 0.0

    def scales(self, sigmas, turns=(0, 2), shifts=(1,), dt: float = 1.0, turned=None) -> list:
        """The fault component's multiplier of each noise dimension (3 values, or arrays shaped like
        ``sigmas``' items): ``scale``, but at most ``turn_max`` / (sigma dt) for the heading dimensions ``turns``
        and ``shift_max`` / (sigma dt) for the translation ones ``shifts`` (dt converts a rate's sigma to an angle
        or a distance; a cap of 0 is none), and at least 1. A slip's (``turn_rel`` > 0): ``turn_rel`` |turned_d| /
        sigma_d for the heading dimensions, ``turned`` the step's own turn in each dimension (within 1 and
        ``scale``), 1 for the others; without ``turned`` (a density, not a step) it is the plain model."""
        if self.turn_rel > 0.0:
            k = [np.float64(1.0)] * 3
            if turned is not None:
                for d in turns:
                    sg = np.asarray(sigmas[d], dtype=np.float64)
                    want = self.turn_rel * np.abs(np.asarray(turned[d], dtype=np.float64))
                    with np.errstate(divide="ignore", invalid="ignore"):
                        k[d] = np.where(sg > 0.0, np.clip(want / sg, 1.0, self.scale), 1.0)
            return k
        k = [np.float64(self.scale)] * 3
        for dims, cap in ((turns, self.turn_max), (shifts, self.shift_max)):
            if cap > 0.0:
                for d in dims:
                    step = np.asarray(sigmas[d], dtype=np.float64) * dt
                    with np.errstate(divide="ignore"):
                        k[d] = np.where(step > 0.0, np.clip(cap / step, 1.0, self.scale), self.scale)
        return k


def _fill_spread(control, cfg) -> float:
    """``motion.fill_spread`` for a step the stall fill took from scan matching (``control.filled``), else 0."""
    return float(cfg.fill_spread) if control.filled else 0.0


def fault_scales(n: int, fault: FaultProposal | None, k, rng: np.random.Generator) -> np.ndarray | None:
    """(3, n) noise multipliers: the fault component's ``k`` (3,) (``FaultProposal.scales``) for the particles
    drawn from p_k (each with probability ``fault.share``) and 1 for the others; None without a fault proposal."""
    if fault is None or n == 0:
        return None
    drawn = rng.random(n) < fault.share
    return np.where(drawn[None, :], np.asarray(k, dtype=np.float64)[:, None], 1.0)


def fault_log_weights(noise: np.ndarray, sigmas, kind: str, fault: FaultProposal, k) -> np.ndarray:
    """(N,) log p_f / q of each particle's motion noise ``noise`` (3, N), in units of the ordinary sigmas (the
    standard noise times the particle's multiplier): p_f = (1 - prob) f(u) + prob f_k(u), q = (1 - share) f(u) +
    share f_k(u), with f the product of the noise densities over the dimensions whose sigma is not zero and
    f_k(u) = prod_d f(u_d / k_d) / k_d, ``k`` the fault component's multipliers. A particle far out in the wide
    component weighs prob / share."""
    dims = [d for d in range(3) if sigmas[d] > 0.0]
    k = np.asarray(k, dtype=np.float64)
    if not dims or np.all(k[dims] == 1.0):
        return np.zeros(noise.shape[1])
    u = noise[dims]
    kd = k[dims][:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        log_f = log_density(kind, u, 1.0).sum(axis=0)
        log_fk = (log_density(kind, u / kd, 1.0) - np.log(kd)).sum(axis=0)
    return _mixture_log(log_f, log_fk, fault.prob) - _mixture_log(log_f, log_fk, fault.share)


def _mixture_log(log_f, log_fk, weight: float):
    """log((1 - weight) f + weight f_k) from log f and log f_k."""
    if weight <= 0.0:
        return log_f
    return np.logaddexp(math.log1p(-weight) + log_f, math.log(weight) + log_fk)


def allowed_mask(grid, robot_radius: float, unknown: bool = False) -> np.ndarray:
    """uint8 (H, W) mask of the cells a robot centre may occupy: distance > robot_radius from every occupied cell,
    and free (``unknown``: free or unknown, i.e. not occupied: ``motion.map_unknown``'s fallback).

    ``grid`` needs the bool ``free`` and ``occupied`` and float ``distance`` (metres to the nearest occupied cell
    centre) arrays of ``OccupancyGrid``. Compute once per map.
    """
    return allowed_masks(grid, robot_radius, (unknown,))[0]


def allowed_masks(grid, robot_radius: float, unknown: tuple[bool, ...]) -> tuple[np.ndarray, ...]:
    """``allowed_mask(grid, robot_radius, u)`` for each ``u`` of ``unknown``, the clearance test made once (the
    map-based motion model's mask and its fallback: a map-sized float comparison less at set-up)."""
    clear = np.asarray(grid.distance) > float(robot_radius)
    out = []
    for u in unknown:
        if u:  # not occupied: a fresh array, cleared in place
            space = ~np.asarray(grid.occupied, dtype=bool)
            space &= clear
        else:  # the grid's own free mask: never written to
            space = np.asarray(grid.free, dtype=bool) & clear
        out.append(byte_mask(space))
    return tuple(out)


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

    def sample_control(self, particles, control, rng, allowed=None, grid=None, fault=None, log_weight=None,
                       fallback=None):
        """``sample`` for a :class:`mcl.filter.Control` (uses its odometry pair; a filled step's travel with
        ``fill_spread``)."""
        return self.sample(particles, control.odom_prev, control.odom_now, rng, allowed=allowed, grid=grid,
                           fault=fault, log_weight=log_weight, fallback=fallback, spread=_fill_spread(control, self.cfg))

    def sample(self, particles, odom_prev, odom_now, rng: np.random.Generator,
               allowed=None, grid=None, out=None, fault: FaultProposal | None = None, log_weight=None,
               fallback=None, spread: float = 0.0):
        """Move every particle by the odometry step odom_prev -> odom_now, with noise.

        particles: (3, N) float64 (x, y, theta); odom_prev, odom_now: (x, y, theta).
        allowed: None, or an (H, W) mask from ``allowed_mask``; then ``grid``
        (anything with ``origin`` (x0, y0) and ``resolution``) places it in the world.
        out: optional (3, N) float64 C-contiguous array for the result (not ``particles``).

        fault: a ``FaultProposal``: a share of the particles takes the fault component's noise; then
        log_weight, an (N,) float64 array, receives their importance weights (``fault_log_weights``).
        fallback: None, or a mask like ``allowed`` (``allowed_mask(grid, r, unknown=True)``): a particle whose
        every try missed ``allowed`` but whose last try lies in ``fallback`` is kept there (``motion.map_unknown``).
        spread: the translation's std gets ``spread`` times the travel more, in quadrature (a step the stall fill
        took from scan matching: ``motion.fill_spread``).

        Returns (new (3, N), ok (N,) bool, mean_tries): ok[i] is False when
        particle i never landed in an allowed cell in max_tries tries (its pose
        is then the last try); mean_tries = motion samples drawn / N (1.0
        without a map).
        """
        p, out = _particles_and_out(particles, out)
        n = p.shape[1]
        deltas, sigmas, dims, kernel, kernel_map = self._step(odom_prev, odom_now)
        if spread > 0.0:
            extra = spread * abs(float(deltas[1]))  # deltas[1]: the travel (trans), in both models
            sigmas = tuple(math.hypot(float(sg), extra) if d in self._TRAVEL else sg for d, sg in enumerate(sigmas))
        noise, idx_all = self._buffers(n)
        kind = getattr(self.cfg, "noise", "normal")
        standard_noise(kind, rng, out=noise)  # normal: rng.standard_normal
        k = fault.scales(sigmas, **dims, turned=self._turned(deltas)) if fault is not None else None
        scales = fault_scales(n, fault, k, rng)
        if scales is not None:
            noise *= scales

        def move(nz, o):
            kernel(p, nz, *deltas, *sigmas, o)

        def move_map(nz, idx, mask, ox, oy, inv_res, o, ok):
            return kernel_map(p, nz, idx, *deltas, *sigmas, mask, ox, oy, inv_res, o, ok)

        result = _sample_with_map(move, move_map, n, noise, idx_all, rng, kind, self.max_tries, allowed, grid, out,
                                  scales, fallback)
        if fault is not None and log_weight is not None:
            log_weight[:] = fault_log_weights(noise, sigmas, kind, fault, k)
        return result

    @staticmethod
    def _turned(deltas):
        """The step's turn in each noise dimension, as the noise sees it (a reversing robot's rot1 near pi turned
        by its difference from pi: ``noise_rotations``; ``FaultProposal.scales``)."""
        r1, r2 = noise_rotations(deltas[0], deltas[2])
        return r1, 0.0, r2

    _TRAVEL = (1,)  # the noise stds of the travel, in ``_step``'s order (``fill_spread`` widens them)

    def _step(self, odom_prev, odom_now):
        """(the step's deltas, their noise stds, the fault caps' dimensions for ``FaultProposal.scales``, the kernel,
        the kernel with the map check): Table 5.6's rot1, trans, rot2 (heading noise in rot1 and rot2)."""
        rot1, trans, rot2 = odometry_deltas(odom_prev, odom_now)
        return ((rot1, trans, rot2), noise_sigmas(rot1, trans, rot2, self.cfg), {}, _k.sample_odometry,
                _k.sample_odometry_map)

    def turn_heading_std(self, step) -> float:
        """The std (rad) of the heading noise the turn of an odometry ``step`` (x, y, theta in the robot's frame)
        adds: sigma_rot1 and sigma_rot2 of Table 5.6 with the translation left out (alpha1's terms), 0 on a step
        that does not turn. (The translation's heading noise, alpha2's, is the travel's, not the turn's.)"""
        rot1, _, rot2 = odometry_deltas(np.zeros(3), step)
        s1, _, s2 = noise_sigmas(rot1, 0.0, rot2, self.cfg)
        return math.hypot(s1, s2)


def omni_deltas(odom_prev, odom_now) -> tuple[float, float, float]:
    """(bearing, trans, rot) of an odometry step of an omnidirectional base: the direction of travel in the robot's
    frame at ``odom_prev`` (0 when it moved less than 1 cm, as rot1), the distance and the turn, wrapped."""
    x0, y0, t0 = (float(v) for v in odom_prev[:3])
    x1, y1, t1 = (float(v) for v in odom_now[:3])
    dx, dy = x1 - x0, y1 - y0
    trans = math.hypot(dx, dy)
    bearing = 0.0 if trans < ROT1_MIN_TRANS else angle_diff(math.atan2(dy, dx), t0)
    return bearing, trans, angle_diff(t1, t0)


def omni_sigmas(trans, rot, cfg):
    """Stds (sigma_trans, sigma_strafe, sigma_rot) of the omni model's noise (floats, or arrays of like shape).

    variance form: sigma_trans^2 = alpha3 trans^2 + alpha4 rot^2, sigma_strafe^2 = alpha_strafe trans^2 +
    alpha4 rot^2, sigma_rot^2 = alpha1 rot^2 + alpha2 trans^2; std form: the same sums of alpha |delta|. These are
    ROS AMCL's omni model's with the book's names (AMCL's omni swaps alpha1 and alpha4, and calls alpha_strafe
    alpha5). ``rot`` is the whole turn: a strafing step turns nothing, whatever its direction.
    """
    a1, a2, a3, a4 = float(cfg.alpha1), float(cfg.alpha2), float(cfg.alpha3), float(cfg.alpha4)
    a_s = float(cfg.alpha_strafe)
    t = np.asarray(noise_trans(trans, cfg), dtype=np.float64)
    r = np.abs(np.asarray(rot, dtype=np.float64))
    if cfg.noise_form == "variance":
        out = (np.sqrt(a3 * t * t + a4 * r * r), np.sqrt(a_s * t * t + a4 * r * r), np.sqrt(a1 * r * r + a2 * t * t))
    elif cfg.noise_form == "std":
        out = (a3 * t + a4 * r, a_s * t + a4 * r, a1 * r + a2 * t)
    else:
        raise ValueError(f"motion.noise_form: unknown value {cfg.noise_form!r} (expected 'variance' or 'std')")
    return tuple(float(v) for v in out) if t.ndim == 0 and r.ndim == 0 else out


class OmniMotionModel(OdometryMotionModel):
    """The odometry motion model of an omnidirectional base (mecanum wheels, a PR2, a Ridgeback): ROS AMCL's omni
    model in the book's names, nav2's ``OmniMotionModel`` alpha for alpha (ROS 1's ``omni-corrected`` is the same
    model with alpha1 and alpha4 swapped).

    Table 5.6 moves a particle along its own heading turned by rot1, and rot1's noise grows with rot1: right for a
    differential drive, whose steps go along its heading (rot1 near 0 or pi). A base that strafes makes steps at any
    rot1, and a step sideways (rot1 = pi/2) would turn the particle by 0.35 rad of noise each way. Here the step
    keeps its direction in the robot's frame (``omni_deltas``' bearing, noise-free); the travel, a drift across it
    and the turn are noisy (``omni_sigmas``)::

        b = theta + bearing
        x' = x + (trans + e_trans) cos b + e_strafe sin b
        y' = y + (trans + e_trans) sin b - e_strafe cos b
        theta' = theta + rot + e_rot

    ``cfg`` as ``OdometryMotionModel``'s, and ``alpha_strafe``.
    """

    @staticmethod
    def _turned(deltas):
        """The step's turn in each noise dimension (its heading's alone)."""
        return 0.0, 0.0, abs(deltas[2])

    _TRAVEL = (0,)  # sigma_trans, along the travel (sigma_strafe, across it, stays the model's)

    def _step(self, odom_prev, odom_now):
        """``OdometryMotionModel._step`` of this model: bearing, trans, rot; the heading's noise is the turn's, the
        travel's and the strafe's are translations."""
        bearing, trans, rot = omni_deltas(odom_prev, odom_now)
        return ((bearing, trans, rot), omni_sigmas(trans, rot, self.cfg), {"turns": (2,), "shifts": (0, 1)},
                _k.sample_omni, _k.sample_omni_map)

    def turn_heading_std(self, step) -> float:
        """``OdometryMotionModel.turn_heading_std`` of this model: sigma_rot with the travel left out (a strafing
        step turns nothing, whatever its direction)."""
        return omni_sigmas(0.0, omni_deltas(np.zeros(3), step)[2], self.cfg)[2]


SIDEWAYS_OMNI = 0.1  # share of the odometry's travel across the heading above which the base is omnidirectional
SIDEWAYS_MIN_TRAVEL = 5.0  # m of odometry travel the share needs
SIDEWAYS_CHORD = 0.05  # m: the odometry is read in chords this long (a 50 Hz /odom moves millimetres a message)
SIDEWAYS_JUMP = 2.0  # m: a step between two odometry readings longer than this is a reset or a glitch, not travel


def sideways_share(poses) -> tuple[float, float]:
    """(share, travel): how much of the odometry's travel goes across the robot's heading, and the travel (m).

    ``poses``: (M, 3) odometry poses (x, y, theta) in time order, read in chords of ``SIDEWAYS_CHORD`` m of path.
    A differential drive's chord lies between the headings at its ends, forwards or backwards, whatever it turned
    in between; each chord's angle outside that interval (its ``deviation``) weighs by |sin(deviation)| times its
    length. The shared logs read 0.002-0.014, and omnidirectional bases crabbing within 20 degrees of their
    travel read 0.19 or more (``mcl simulate --holonomic``): over ``SIDEWAYS_OMNI`` a run takes the omni model
    (``motion.sideways``). An odometry frame off the axle reads a turn on the spot as a short sideways chord (0.2 m
    ahead: 0.6 m a full turn). A step over ``SIDEWAYS_JUMP`` between two readings (the odometry reset, a glitch)
    counts as no travel, and no chord spans it. Share 0 under ``SIDEWAYS_MIN_TRAVEL`` m of travel or 2 poses."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    if p.shape[0] < 2:
        return 0.0, 0.0
    steps = np.hypot(*np.diff(p[:, :2], axis=0).T)
    jump = steps > SIDEWAYS_JUMP  # an odometry reset or glitch: no travel, and no chord across it
    path = np.concatenate(([0.0], np.cumsum(np.where(jump, 0.0, steps))))
    if path[-1] < SIDEWAYS_MIN_TRAVEL:
        return 0.0, float(path[-1])
    keep = np.unique(np.append(np.searchsorted(path, np.arange(0.0, path[-1], SIDEWAYS_CHORD)), p.shape[0] - 1))
    piece = np.concatenate(([0], np.cumsum(jump)))[keep]
    q = p[keep]
    d = np.diff(q, axis=0)
    d = d[piece[1:] == piece[:-1]]
    q = q[:-1][piece[1:] == piece[:-1]]
    chord = np.hypot(d[:, 0], d[:, 1])
    if not chord.sum() > 0.0:
        return 0.0, float(path[-1])
    turn = _wrap_np(d[:, 2])
    lo, hi = np.minimum(turn, 0.0), np.maximum(turn, 0.0)

    def outside(direction):  # the chord's angle outside [theta0 + lo, theta0 + hi], 0 inside
        rel = _wrap_np(direction - q[:, 2])
        return np.where(rel < lo, lo - rel, np.where(rel > hi, rel - hi, 0.0))

    ahead = np.arctan2(d[:, 1], d[:, 0])
    deviation = np.minimum(np.abs(_wrap_np(outside(ahead))), np.abs(_wrap_np(outside(ahead + np.pi))))
    return float((chord * np.sin(np.minimum(deviation, 0.5 * np.pi))).sum() / chord.sum()), float(path[-1])


def make_motion_model(cfg):
    """The motion model named by ``motion.model``."""
    if cfg.model == "odometry":
        return OdometryMotionModel(cfg)
    if cfg.model == "omni":
        return OmniMotionModel(cfg)
    if cfg.model == "velocity":
        return VelocityMotionModel(cfg)
    raise ValueError(f"motion.model: unknown model {cfg.model!r}")


# =============================================================================
# Closed-form densities, the velocity model and the map-based density
# (issue 3). Conventions for every density below:
#
# * ``x_new`` is (3, N) hypotheses x_t (or (3,)), ``x_prev`` is (3, N) or (3,)
#   (broadcast); the result is (N,).
# * The noise distribution is ``cfg.noise`` (mcl.noise: normal,
#   normal_twelve, triangular), its std given by ``cfg.noise_form`` and the
#   alphas exactly as in the samplers.
# * ``jacobian=True`` (default) returns a density over poses (x', y', theta'),
#   which integrates to 1 over (x', y', theta'). The book's algorithms
#   (motion_model_odometry, Table 5.5; motion_model_velocity, Table 5.1)
#   return the product of the noise densities p1 p2 p3, a density over the
#   *motion parameters* (rot1, trans, rot2) or (v, w, gamma); over poses it
#   integrates to about the travelled distance (odometry) or to 1 / |J| of the
#   velocity map, not to 1. The two differ by the Jacobian of the map from
#   the motion parameters to the pose: dtrans_hat for odometry,
#   |v_hat| dt^4 sinc(w_hat dt / 2)^2 / 2 for velocity. ``jacobian=False``
#   returns the book's value. For maximum likelihood over the alphas the
#   factor is a constant, so calibration gets the same answer either way.
# =============================================================================

SIGMA_MIN = 1e-9  # floor on a noise std in the densities (a zero std is a delta: density 0 or inf)


def _wrap_np(a):
    """a wrapped into (-pi, pi] (the kernels' formula, vectorised)."""
    a = np.asarray(a, dtype=np.float64)
    return a - 2.0 * np.pi * np.ceil((a - np.pi) / (2.0 * np.pi))


def _poses(x, name: str) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] != 3:
        raise ValueError(f"{name}: expected shape (3,) or (3, N), got {x.shape}")
    return x


def odometry_deltas_array(x_prev, x_new, min_trans: float = ROT1_MIN_TRANS):
    """Vectorised ``odometry_deltas``: (rot1, trans, rot2) arrays taking x_prev to x_new (Table 5.5 lines 5-7).

    Same rules: angles wrapped into (-pi, pi], rot1 = 0 when trans < min_trans.
    """
    a, b = _poses(x_prev, "x_prev"), _poses(x_new, "x_new")
    dx, dy = b[0] - a[0], b[1] - a[1]
    trans = np.hypot(dx, dy)
    rot1 = np.where(trans < min_trans, 0.0, _wrap_np(np.arctan2(dy, dx) - a[2]))
    rot2 = _wrap_np(_wrap_np(b[2] - a[2]) - rot1)
    return rot1, trans, rot2


def noise_rotations_array(rot1, rot2):
    """Vectorised ``noise_rotations``."""
    r1, r2 = np.abs(_wrap_np(rot1)), np.abs(_wrap_np(rot2))
    back = r1 > 0.5 * np.pi
    return np.where(back, np.pi - r1, r1), np.where(back, np.pi - r2, r2)


def noise_sigmas_array(rot1, trans, rot2, cfg):
    """Vectorised ``noise_sigmas``: (sigma_rot1, sigma_trans, sigma_rot2) arrays, same rules."""
    a1, a2, a3, a4 = float(cfg.alpha1), float(cfg.alpha2), float(cfg.alpha3), float(cfg.alpha4)
    (r1, r2), t = noise_rotations_array(rot1, rot2), np.asarray(noise_trans(trans, cfg), dtype=np.float64)
    if cfg.noise_form == "variance":
        return (np.sqrt(a1 * r1 * r1 + a2 * t * t), np.sqrt(a3 * t * t + a4 * (r1 * r1 + r2 * r2)),
                np.sqrt(a1 * r2 * r2 + a2 * t * t))
    if cfg.noise_form == "std":
        return a1 * r1 + a2 * t, a3 * t + a4 * (r1 + r2), a1 * r2 + a2 * t
    raise ValueError(f"motion.noise_form: unknown value {cfg.noise_form!r} (expected 'variance' or 'std')")


def odometry_residuals(r1, tr, r2, h1, ht, h2):
    """delta - delta_hat for the odometry deltas (r1, tr, r2) against the hypothesis' (h1, ht, h2).

    Angle differences wrapped into (-pi, pi]. (rot1, trans, rot2) and
    (rot1 + pi, -trans, rot2 - pi) are the same motion; the sampler reaches the
    second when its translation noise flips the sign of a short step (a robot
    turning on the spot whose odometry creeps 1 cm backwards reads rot1 = pi).
    So the odometry deltas are taken in the form whose rot1 is nearer the
    hypothesis' (|rot1 - rot1_hat| <= pi/2), and a backward creep costs a
    translation error, not a rotation error of pi.
    """
    r1 = np.asarray(r1, dtype=np.float64)
    tr = np.asarray(tr, dtype=np.float64)
    r2 = np.asarray(r2, dtype=np.float64)
    d1 = _wrap_np(r1 - h1)
    flip = np.abs(d1) > 0.5 * np.pi
    d1 = np.where(flip, _wrap_np(d1 - np.pi), d1)
    dt = np.where(flip, -tr, tr) - ht
    d2 = _wrap_np(np.where(flip, r2 + np.pi, r2) - h2)
    return d1, dt, d2


def _odometry_pair(u):
    if hasattr(u, "odom_prev"):
        return u.odom_prev, u.odom_now
    odom_prev, odom_now = u
    return odom_prev, odom_now


def log_motion_model_odometry(x_new, u, x_prev, cfg, *, sigma_from: str = "odometry",
                              jacobian: bool = True, min_trans: float = 0.0,
                              fault: FaultProposal | None = None) -> np.ndarray:
    """log p(x_new | u, x_prev) of the odometry model (Prob. Rob. Table 5.5, motion_model_odometry), (N,).

    u: the odometry pair (odom_prev, odom_now), or a ``Control``. The deltas
    of u and of each hypothesis (x_prev -> x_new) follow ``odometry_deltas``;
    the differences delta - delta_hat are wrapped into (-pi, pi]
    (``odometry_residuals``, which also folds a backward creep).
    sigma_from: "odometry" (default) takes the noise stds from the
    odometry's deltas (the Spanish slides, seed 002): exactly the density the
    sampler ``OdometryMotionModel`` draws from, which integrates to 1 over
    poses. "hypothesis" takes them from each hypothesis' deltas (the book's
    Table 5.5: the true motion makes the noise, as in ``mcl.simulate``); that
    is a density of the odometry *reading* given the true motion (normalised
    over the odometry deltas, what ``mcl calibrate motion`` maximises), but
    over poses it integrates only to about 1 (1.17 for the variance form in
    tests/test_motion_density.py). ``sigma_from="hypothesis", jacobian=False``
    is Table 5.5 literally. jacobian: see the section comment. fault: the
    odometry-fault mixture (1 - prob) p + prob p_k (``fault.share`` is the
    sampler's business and plays no part here). min_trans: the rule rot1 = 0
    below it for the hypotheses' deltas (default 0: a hypothesis lies where it
    lies; the reading's deltas keep the filter's 1 cm rule, as the sampler
    does). With the rule on them too, every pose within 1 cm of x_prev had
    rot1_hat 0 whatever its direction: a turn on the spot gave a pose 5 mm to
    the side the density of one 5 mm ahead, where the sampler never goes.
    """
    rot1, trans, rot2 = odometry_deltas(*_odometry_pair(u))
    h1, ht, h2 = odometry_deltas_array(x_prev, x_new, min_trans)
    if sigma_from == "hypothesis":
        s1, st, s2 = noise_sigmas_array(h1, ht, h2, cfg)
    elif sigma_from == "odometry":
        s1, st, s2 = (np.full(h1.shape, s) for s in noise_sigmas(rot1, trans, rot2, cfg))
    else:
        raise ValueError(f"sigma_from: expected 'hypothesis' or 'odometry', got {sigma_from!r}")
    kind = getattr(cfg, "noise", "normal")
    d1, dtr, d2 = odometry_residuals(rot1, trans, rot2, h1, ht, h2)
    out = _noise_log_density(kind, (d1, dtr, d2), (s1, st, s2), fault)
    if jacobian:
        out = _over_jacobian(out, ht)
    return out


def _over_jacobian(log_density, jac):
    """log(density / |jac|), and -inf where the density is 0 whatever the Jacobian: a pose outside a bounded noise's
    support where the Jacobian vanishes too (a turn on the spot) gave -inf - (-inf) = NaN."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.isneginf(log_density), -np.inf, log_density - np.log(jac))


def _noise_log_density(kind: str, residuals, sigmas, fault: FaultProposal | None, **caps) -> np.ndarray:
    """sum_d log f(residual_d; sigma_d), or of the fault mixture (1 - prob) f(.; sigma) + prob f(.; k sigma), k the
    fault component's multipliers (``FaultProposal.scales`` with ``caps``: its dimensions and dt)."""
    def log_f(ks):
        return sum(log_density(kind, r, np.maximum(np.asarray(sg, dtype=np.float64) * k, SIGMA_MIN))
                   for r, sg, k in zip(residuals, sigmas, ks))

    if fault is None or fault.prob <= 0.0:
        return log_f((1.0, 1.0, 1.0))
    return _mixture_log(log_f((1.0, 1.0, 1.0)), log_f(fault.scales(sigmas, **caps)), fault.prob)


def log_motion_model_omni(x_new, u, x_prev, cfg, *, fault: FaultProposal | None = None) -> np.ndarray:
    """log p(x_new | u, x_prev) of the omni model (``OmniMotionModel``), (N,): the density its sampler draws from.

    Each hypothesis' displacement is read in the frame of the odometry's direction of travel at x_prev (heading
    theta_prev + bearing): its part along that direction less trans, its part across it, and its turn less rot
    (wrapped) are the three noises, with the odometry's stds (``omni_sigmas``). That map from the noises to the pose
    is a rotation and a shift, so this is a density over poses (x', y', theta') without a Jacobian. ``fault``: the
    odometry-fault mixture, as for ``log_motion_model_odometry``.
    """
    odom_prev, odom_now = _odometry_pair(u)
    residuals, (trans, rot), _ = omni_residuals(odom_prev, odom_now, x_prev, x_new)
    shape = np.broadcast_shapes(*(r.shape for r in residuals))
    sig = tuple(np.full(shape, s) for s in omni_sigmas(trans.item(), rot.item(), cfg))  # one odometry step
    return _noise_log_density(getattr(cfg, "noise", "normal"), residuals, sig, fault, turns=(2,), shifts=(0, 1))


def omni_residuals(odom_prev, odom_now, x_prev, x_new):
    """(the three noises (along - trans, across, turn - rot), the odometry's (trans, rot), the hypotheses' (trans,
    turn)) of the omni model, vectorised: each hypothesis' displacement read in the frame of the odometry's direction
    of travel at x_prev (heading theta_prev + bearing, ``omni_deltas``' rule: bearing 0 under 1 cm). The odometry
    poses are (3,) or (3, N) (one reading per hypothesis, ``mcl calibrate motion``), as are the hypotheses."""
    op, on = _poses(odom_prev, "odom_prev"), _poses(odom_now, "odom_now")
    a, b = _poses(x_prev, "x_prev"), _poses(x_new, "x_new")
    d = on - op
    trans = np.hypot(d[0], d[1])
    bearing = np.where(trans < ROT1_MIN_TRANS, 0.0, _wrap_np(np.arctan2(d[1], d[0]) - op[2]))
    rot = _wrap_np(d[2])
    head = a[2] + bearing
    e = b - a
    turn = _wrap_np(e[2])
    along = e[0] * np.cos(head) + e[1] * np.sin(head)
    across = e[0] * np.sin(head) - e[1] * np.cos(head)
    return (along - trans, across, _wrap_np(turn - rot)), (trans, rot), (np.hypot(e[0], e[1]), turn)


def motion_model_omni(x_new, u, x_prev, cfg, **kw) -> np.ndarray:
    """p(x_new | u, x_prev) of the omni model, (N,): exp of ``log_motion_model_omni``."""
    return np.exp(log_motion_model_omni(x_new, u, x_prev, cfg, **kw))


def motion_model_odometry(x_new, u, x_prev, cfg, **kw) -> np.ndarray:
    """p(x_new | u, x_prev) of the odometry model, (N,): exp of ``log_motion_model_odometry`` (same options)."""
    return np.exp(log_motion_model_odometry(x_new, u, x_prev, cfg, **kw))


# ----------------------------------------------------------------------------- velocity model


def velocity_sigmas(v: float, w: float, cfg) -> tuple[float, float, float]:
    """Stds (sigma_v, sigma_w, sigma_gamma) of the velocity model's noise (Table 5.3 lines 2-4).

    variance form (book): sigma_v^2 = a1 v^2 + a2 w^2, sigma_w^2 = a3 v^2 + a4 w^2,
    sigma_g^2 = a5 v^2 + a6 w^2; std form (slides): sigma_v = a1 |v| + a2 |w|, and so on.
    """
    a = [float(getattr(cfg, f"alpha{k}")) for k in range(1, 7)]
    v, w = abs(float(v)), abs(float(w))
    if cfg.noise_form == "variance":
        return (math.sqrt(a[0] * v * v + a[1] * w * w), math.sqrt(a[2] * v * v + a[3] * w * w),
                math.sqrt(a[4] * v * v + a[5] * w * w))
    if cfg.noise_form == "std":
        return a[0] * v + a[1] * w, a[2] * v + a[3] * w, a[4] * v + a[5] * w
    raise ValueError(f"motion.noise_form: unknown value {cfg.noise_form!r} (expected 'variance' or 'std')")


def _sinc(u):
    u = np.asarray(u, dtype=np.float64)
    small = np.abs(u) < 1e-12
    return np.where(small, 1.0, np.sin(u) / np.where(small, 1.0, u))


def velocity_inverse(x_prev, x_new, dt: float):
    """(v_hat, w_hat, gamma_hat) arrays that take x_prev to x_new in dt (Table 5.1 lines 2-9).

    The book's circle-centre construction: the centre (x*, y*) lies on the
    normal to the heading at x_prev and on the bisector of x_prev x_new,
    mu = 1/2 ((x-x') cos th + (y-y') sin th) / ((y-y') cos th - (x-x') sin th),
    r* the radius, dtheta the angle swept, v = dtheta r* / dt, w = dtheta / dt,
    gamma = (th' - th) / dt - w. It is computed here in the robot frame,
    where it reduces to the inscribed-angle theorem: with (f, l) the forward
    and left displacement and d = hypot(f, l), the swept angle is
    dtheta = wrap(2 atan2(l, f)) and the arc length is
    v dt = sign(f) d (dtheta/2) / sin(dtheta/2). This has no division by the
    book's vanishing denominator (x_new on the heading line: dtheta = 0, v dt =
    f, the straight line) and gives v the sign of the motion (forward > 0);
    the book's v = dtheta r* / dt (r* >= 0) has the sign of dtheta instead,
    wrong for a forward right turn and a backward left turn.
    """
    a, b = _poses(x_prev, "x_prev"), _poses(x_new, "x_new")
    dt = float(dt)
    if not dt > 0:
        raise ValueError(f"dt: the velocity model needs a positive duration, got {dt}")
    dx, dy = b[0] - a[0], b[1] - a[1]
    c, s = np.cos(a[2]), np.sin(a[2])
    f = c * dx + s * dy
    l = -s * dx + c * dy
    d = np.hypot(f, l)
    dth = _wrap_np(2.0 * np.arctan2(l, f))
    arc = np.where(f >= 0, 1.0, -1.0) * d / _sinc(0.5 * dth)
    w_hat = dth / dt
    v_hat = arc / dt
    g_hat = _wrap_np(b[2] - a[2] - dth) / dt
    return v_hat, w_hat, g_hat


def _velocity_control(u):
    if hasattr(u, "velocities"):  # a Control
        return u.velocities()
    v, w, dt = u
    return float(v), float(w), float(dt)


def log_motion_model_velocity(x_new, u, x_prev, cfg, *, jacobian: bool = True,
                              fault: FaultProposal | None = None) -> np.ndarray:
    """log p(x_new | u, x_prev) of the velocity model (Prob. Rob. Table 5.1, motion_model_velocity), (N,).

    u: (v, w, dt) or a ``Control``. The noise stds come from the commanded
    (v, w) (``velocity_sigmas``), so this is exactly the density that
    ``VelocityMotionModel`` samples from, where the arc swept is at most half a
    turn (|w_hat dt| <= pi): two poses are joined by arcs of every number of
    turns, and Table 5.1 (``velocity_inverse``) scores the shortest, as the
    book does; a sampler drawing |w dt| > pi (31 rad/s at 10 Hz) reaches poses
    this density does not give. jacobian=True divides by
    |d(x', y', theta') / d(v, w, gamma)| = |v_hat| dt^4 sinc(w_hat dt / 2)^2 / 2
    to give a density over poses; it is infinite where v_hat = 0 (turning on
    the spot maps a 2-D set of controls onto one point). fault: the
    odometry-fault mixture, as in ``log_motion_model_odometry``.
    """
    v, w, dt = _velocity_control(u)
    v_hat, w_hat, g_hat = velocity_inverse(x_prev, x_new, dt)
    kind = getattr(cfg, "noise", "normal")
    out = _noise_log_density(kind, (v - v_hat, w - w_hat, g_hat), velocity_sigmas(v, w, cfg), fault,
                              turns=(1, 2), shifts=(0,), dt=dt)
    if jacobian:
        out = _over_jacobian(out, np.abs(v_hat) * dt ** 4 * 0.5 * _sinc(0.5 * w_hat * dt) ** 2)
    return out


def motion_model_velocity(x_new, u, x_prev, cfg, **kw) -> np.ndarray:
    """p(x_new | u, x_prev) of the velocity model, (N,): exp of ``log_motion_model_velocity``."""
    return np.exp(log_motion_model_velocity(x_new, u, x_prev, cfg, **kw))


def velocities_from_odometry(odom_prev, odom_now, dt: float) -> tuple[float, float, float]:
    """(v, w, dt) from two odometry poses, for a velocity model fed by a log without tv/rv.

    v = trans / dt, negative when the robot moved backwards (the displacement
    points behind the old heading); w = wrap(theta_now - theta_prev) / dt.
    When dt <= 0 (equal timestamps) dt = 1 s is used: the velocity model's
    motion and noise depend on v dt and w dt only (both noise forms scale
    with dt), so the duration chosen does not matter.

    The approximation: an arc with w dt = dtheta and length trans ends at the
    odometry's final heading but not exactly at its final position unless
    rot1 = dtheta / 2 (the arc's chord direction). The residual, the odometry's
    rot1 - dtheta/2 and the matching final rotation, is not a command of the
    velocity model; the sampler covers it only through its noise (the gamma
    term on the heading, the v and w noise on the position), an error of
    about trans * |rot1 - dtheta/2| per update.
    """
    x0, y0, t0 = (float(q) for q in odom_prev[:3])
    x1, y1, t1 = (float(q) for q in odom_now[:3])
    dt = float(dt) if dt > 0 else 1.0
    dx, dy = x1 - x0, y1 - y0
    trans = math.hypot(dx, dy)
    sign = -1.0 if dx * math.cos(t0) + dy * math.sin(t0) < 0 else 1.0
    return sign * trans / dt, angle_diff(t1, t0) / dt, dt


def _particles_and_out(particles, out):
    """(3, N) float64 C-contiguous particles, and an output array of the same shape not sharing their memory."""
    p = np.ascontiguousarray(particles, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] != 3:
        raise ValueError(f"particles: expected shape (3, N), got {p.shape}")
    if out is None:
        out = np.empty_like(p)
    else:
        check_out(out, p.shape)
        if out is p or np.shares_memory(out, p):
            raise ValueError("out must not share memory with particles")
    return p, out


def _sample_with_map(move, move_map, n, noise, idx_all, rng, kind, max_tries, allowed, grid, out, scales=None,
                     fallback=None):
    """Map-based sampling (seed 5.5) shared by the models: move all, then redraw the rejected.

    move(noise, out) moves every particle; move_map(noise, idx, mask, ox, oy,
    inv_res, out, ok) moves the particles idx and checks the map, returning
    how many landed. Same semantics as ``OdometryMotionModel.sample``. With
    ``scales`` (a fault proposal's (3, n) multipliers) a redraw keeps
    its particle's multiplier, and ``noise`` ends holding the noise each
    particle last moved with (for its importance weight). With ``fallback`` (a mask like ``allowed``), a
    particle whose every try missed ``allowed`` is kept (ok) where its last try landed when that is in ``fallback``:
    no more draws, so the random stream is the one without it.
    """
    if allowed is None:
        move(noise, out)
        return out, np.ones(n, dtype=bool), 1.0
    if grid is None:
        raise ValueError("a map mask (allowed) needs grid (origin, resolution) to place it")
    mask = allowed if (allowed.dtype == np.uint8 and allowed.flags.c_contiguous) \
        else np.ascontiguousarray(allowed, dtype=np.uint8)
    ox, oy = float(grid.origin[0]), float(grid.origin[1])
    inv_res = 1.0 / float(grid.resolution)
    ok = np.empty(n, dtype=bool)
    n_ok = move_map(noise, idx_all, mask, ox, oy, inv_res, out, ok)
    draws = n
    idx = None
    for _ in range(max_tries - 1):
        if n_ok == n:
            break
        idx = np.flatnonzero(~ok) if idx is None else idx[~ok[idx]]
        draws += idx.size
        fresh = standard_noise(kind, rng, (3, idx.size))
        if scales is not None:
            fresh *= scales[:, idx]
            noise[:, idx] = fresh
        n_ok += move_map(fresh, idx, mask, ox, oy, inv_res, out, ok)
    if fallback is not None and n_ok < n:
        idx = np.flatnonzero(~ok) if idx is None else idx[~ok[idx]]
        ok[idx[grid.mask_at(fallback, out[0, idx], out[1, idx])]] = True
    return out, ok, draws / n if n else 0.0


class VelocityMotionModel:
    """Sample x_t ~ p(x_t | u_t, x_{t-1}[, m]) with the velocity model (Prob. Rob. Table 5.3).

    ``cfg`` is read duck-typed: noise_form, noise, alpha1..alpha6, max_tries.
    The map rejection is the odometry model's (``_sample_with_map``, kernel
    check ``kernels.motion.allowed_at``).
    """

    def __init__(self, cfg):
        self.cfg = cfg
        if cfg.noise_form not in ("variance", "std"):
            raise ValueError(f"motion.noise_form: unknown value {cfg.noise_form!r} (expected 'variance' or 'std')")
        self.noise_kind = getattr(cfg, "noise", "normal")
        self.max_tries = int(getattr(cfg, "max_tries", 10))
        self._noise = np.empty((3, 0))
        self._all = np.empty(0, dtype=np.int64)

    def sample_control(self, particles, control, rng, allowed=None, grid=None, fault=None, log_weight=None,
                       fallback=None):
        """``sample`` for a :class:`mcl.filter.Control` (its ``velocities()``: v, w, dt, or from its odometry pair
        where v and w are 0; a filled step's with ``fill_spread``)."""
        v, w, dt = control.velocities()
        return self.sample(particles, v, w, dt, rng, allowed=allowed, grid=grid,
                           fault=fault, log_weight=log_weight, fallback=fallback, spread=_fill_spread(control, self.cfg))

    def sample(self, particles, v, w, dt, rng: np.random.Generator, allowed=None, grid=None, out=None,
               fault: FaultProposal | None = None, log_weight=None, fallback=None, spread: float = 0.0):
        """Move every particle by the command (v, w) for dt, with noise. Returns (new, ok, mean_tries); ``fault``,
        ``log_weight`` and ``spread`` (v's std gets ``spread`` |v| more, in quadrature) as for
        ``OdometryMotionModel.sample``."""
        from mcl.kernels import velocity as _kv

        p, out = _particles_and_out(particles, out)
        n = p.shape[1]
        v, w, dt = float(v), float(w), max(float(dt), 0.0)
        sv, sw, sg = velocity_sigmas(v, w, self.cfg)
        if spread > 0.0:
            sv = math.hypot(sv, spread * abs(v))
        if self._noise.shape[1] != n:
            self._noise = np.empty((3, n))
            self._all = np.arange(n, dtype=np.int64)
        noise = standard_noise(self.noise_kind, rng, out=self._noise)
        # the heading noise: w and the final rotation gamma over dt; the translation: v over dt
        k = (fault.scales((sv, sw, sg), turns=(1, 2), shifts=(0,), dt=dt, turned=(0.0, w, 0.0))
             if fault is not None else None)
        scales = fault_scales(n, fault, k, rng)
        if scales is not None:
            noise *= scales

        def move(nz, o):
            _kv.sample_velocity(p, nz, v, w, dt, sv, sw, sg, o)

        def move_map(nz, idx, mask, ox, oy, inv_res, o, ok):
            return _kv.sample_velocity_map(p, nz, idx, v, w, dt, sv, sw, sg, mask, ox, oy, inv_res, o, ok)

        result = _sample_with_map(move, move_map, n, noise, self._all, rng, self.noise_kind, self.max_tries,
                                  allowed, grid, out, scales, fallback)
        if fault is not None and log_weight is not None:
            log_weight[:] = fault_log_weights(noise, (sv, sw, sg), self.noise_kind, fault, k)
        return result


# ----------------------------------------------------------------------------- map-based density


def motion_model_with_map(x_new, u, x_prev, grid, cfg, allowed=None, *, normalize: bool = True,
                          **kw) -> np.ndarray:
    """p(x_t | u_t, x_{t-1}, m) = eta p(x_t | u_t, x_{t-1}) p(x_t | m) over N hypotheses (seed 5.5), (N,).

    ``normalize=False`` is the seed's ``motion_model_with_map`` literally: the product p(x_t | u_t, x_{t-1})
    p(x_t | m), p(x_t | m) taken as 1 on allowed cells and 0 elsewhere (the seed's constant, left unnormalised), so
    each hypothesis' value is its own, whatever the others. The default normalises over the given set, as below.

    p(x_t | m) is 0 for a hypothesis whose cell is not in ``allowed`` (default
    ``allowed_mask(grid, cfg.robot_radius)``, unknown cells too when
    ``cfg.map_unknown`` is "free"; off the map counts as not allowed) and a
    constant otherwise (the sampler's fallback onto unknown cells is a last
    resort of the sampling, not a density). eta normalises over the given set of
    hypotheses: the result sums to 1 over x_new, a discrete posterior over the
    candidates (the constant p(x|m) and the continuous normaliser cancel). It is
    the book's approximation, good for motions shorter than about half the
    robot's size: it checks the end pose only, not the path. The free-space
    density is ``motion_model_odometry``, ``motion_model_omni`` or ``motion_model_velocity`` by
    ``cfg.model`` (keyword options go through). When no hypothesis is
    allowed, the result is all zeros (eta is undefined).
    """
    xn = _poses(x_new, "x_new")
    if cfg.model == "velocity":
        logp = log_motion_model_velocity(xn, u, x_prev, cfg, **kw)
    elif cfg.model == "omni":
        logp = log_motion_model_omni(xn, u, x_prev, cfg, **kw)
    else:
        logp = log_motion_model_odometry(xn, u, x_prev, cfg, **kw)
    if allowed is None:
        allowed = allowed_mask(grid, float(getattr(cfg, "robot_radius", 0.0)),
                               getattr(cfg, "map_unknown", "reject") == "free")
    mask = np.ascontiguousarray(allowed, dtype=np.uint8)
    ix = np.floor((xn[0] - float(grid.origin[0])) / float(grid.resolution))
    iy = np.floor((xn[1] - float(grid.origin[1])) / float(grid.resolution))
    inside = (ix >= 0) & (ix < mask.shape[1]) & (iy >= 0) & (iy < mask.shape[0])
    free = np.zeros(xn.shape[1], dtype=bool)
    free[inside] = mask[iy[inside].astype(np.int64), ix[inside].astype(np.int64)] != 0
    logp = np.where(free, logp, -np.inf)
    if not normalize:
        return np.exp(logp)
    top = np.max(logp) if logp.size else -np.inf
    if not np.isfinite(top):
        return np.zeros(xn.shape[1])
    p = np.exp(logp - top)
    return p / p.sum()
