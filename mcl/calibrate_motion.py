"""``mcl calibrate motion``: fit the odometry model's alpha1..alpha4 by maximum likelihood (with ``motion.model:
omni``, the omni model's alpha1..alpha4 and alpha_strafe: ``fit_omni_alphas``).

The seeds ask "how can we determine the model parameters?". With reference
poses (a truth trajectory) and the log's odometry, each pair of consecutive
reference times t_i, t_{i+1} gives one observation of the odometry model:

    x_{i}, x_{i+1}            reference poses (the hypotheses of Table 5.5)
    u_i = (o(t_i), o(t_{i+1})) odometry poses at the same times (ODOM lines
                              interpolated, else the scans' own odometry)

and the alphas maximise sum_i log p(x_{i+1} | u_i, x_i) of the closed-form
odometry density (``mcl.motion.log_motion_model_odometry``'s terms, the book's
Table 5.5: noise stds from the reference motion, angle differences wrapped).
The pose-space Jacobian does not depend on the alphas and is left out.

The split of a pair's turn into rot1 and rot2 is the direction of its step,
which the data often do not show: below min_trans the filter's rule sets
rot1 = 0 (for the odometry and the reference alike), and a step of a few
centimetres (a turn on the spot whose odometry creeps, a reference that
jitters, a curved path between distant reference times) points anywhere.
Such a pair, scored by Table 5.5, has a rot1 residual of up to pi/2 against a
sigma_rot1 of a few mrad, and that one pair sets the alphas (fr101 gave
alpha2 = 189, and the filter lost track). So each pair's density is

    (1 - p_turn) * Table 5.5  +  p_turn * p(turn) p(trans) / 2 pi

where the turn-only density compares the total turn rot1 + rot2 (noise
eps_rot1 + eps_rot2: variance sigma_rot1^2 + sigma_rot2^2, with rot1 = 0 and
rot2 = the whole turn as below min_trans) and the translation (folded at 0:
with the direction free, so is the step's sign), and the split is uniform on
the circle. Pairs below min_trans (either step) take the
turn-only density alone (its noise from the reference's rot1 and rot2 where
the reference moved min_trans or more and its split is observed, a share
1 - p_turn; from (0, the turn) for the rest). p_turn, the share of pairs whose split is not
observed, is fitted with the alphas (at most 0.5); fr101, belgioioso and
intel_lab give 0.22-0.30. The optimiser is Nelder-Mead, then L-BFGS-B, on log-alphas (so they
stay positive) with bounds [1e-9, 100].

What the fitted alphas mean: they describe the odometry error *over the
reference spacing*. Noise accumulates along the odometry chain, so fitting
pairs 2 ticks apart gives roughly half the per-tick alphas of the variance
form (the filter, which updates every few scans, wants the alphas at its own
update spacing). Reference poses that are themselves noisy (SLAM-corrected
logs jitter by centimetres) inflate the fitted alphas, alpha2 and alpha3 most.
Pairs where neither the reference nor the odometry moved (less than 1 mm and
1 mrad) carry no information and are skipped. An alpha above 1 (a turn's or
a step's noise as large as itself) is implausible: the fit warns.

The fit is in the config's ``motion.noise_step`` form (the block it prints
says which): with the default 0.3 m, pairs a metre apart are scored as a
random walk of 0.3 m steps, as the filter will draw them.
"""

from __future__ import annotations

import argparse
import math
import warnings
from types import SimpleNamespace

import numpy as np

from mcl.errors import ConfigError, DataError, MclWarning

ALPHA_BOUNDS = (1e-9, 100.0)
P_TURN_MAX = 0.5  # the turn-only share of the pairs (module docstring) is fitted in (0, P_TURN_MAX]
ALPHA_PLAUSIBLE = 1.0  # fitted alphas above this are warned about
STAMP_TOL = 1e-3  # s: a reference pose matches a log stamp within this (as calibrate sensor matches scans)
STILL_TRANS = 1e-3  # m
STILL_ROT = 1e-3  # rad


# a shift of the reference fits the odometry's steps (their translation and signed turn, the mean misfit over the
# pairs) this much better than as stamped: warned. Measured: a generated world's truth a frame late 0.91 (its own
# truth, and each of the eight shared logs' (mit_csail's odometry lagging its scans included): best as stamped)
LAG_RATIO = 0.95


def pairs_from_log(log_path, truth_path):
    """(odom_prev, odom_now, x_prev, x_now, t) for consecutive truth times: four (3, M) arrays and (M,) times.

    Odometry comes from the log's ODOM lines interpolated at the truth times
    (``interpolate_odometry``), or, for logs without ODOM lines (mit_csail),
    from the scans' own odometry poses interpolated the same way.
    """
    from mcl.datasets.carmen import interpolate_odometry, read_carmen
    from mcl.datasets.rosbag import is_bag
    from mcl.trajectory import read_tum

    if is_bag(log_path):
        raise DataError(bag_message(log_path))
    t, poses = read_tum(truth_path)
    order = np.argsort(t, kind="stable")
    t, poses = t[order], poses[:, order]
    log = read_carmen(log_path, need_laser=False)  # ODOM lines are enough
    odo = log_odometry(log)
    if odo.size == 0:
        raise DataError(f"{log_path}: no odometry (no ODOM lines and no scan poses)")
    t0, t1 = odo[:, 0].min(), odo[:, 0].max()
    keep = (t >= t0) & (t <= t1)
    t, poses = t[keep], poses[:, keep]
    if t.size < 2:
        raise DataError(f"{truth_path}: fewer than 2 reference poses inside the log's odometry time span")
    scan_t = np.unique([s.t for s in log.scans])
    scan_dt = float(np.median(np.diff(scan_t))) if scan_t.size > 2 else 0.0
    ref_dt = float(np.median(np.diff(t))) if t.size > 2 else 0.0
    # the reference must be this log's: stamped at its ODOM lines or scans (a truth on another clock can overlap it)
    stamps = np.unique(np.concatenate([odo[:, 0], [s.t for s in log.scans]]))
    i = np.clip(np.searchsorted(stamps, t), 1, stamps.size - 1) if stamps.size > 1 else np.zeros(t.size, int)
    gap = np.minimum(np.abs(stamps[i] - t), np.abs(stamps[np.maximum(i - 1, 0)] - t))
    matched = int(np.count_nonzero(gap <= STAMP_TOL))
    if matched < 0.5 * t.size and 0.0 < ref_dt <= DENSE_REFERENCE * scan_dt:
        # a reference denser than the scans on its own clock (motion capture): taken at the scans (a reference
        # stamped at the log's ODOM lines keeps its own spacing: the alphas are over it)
        t, poses = _at_scans(t, poses, scan_t, ref_dt, truth_path, log_path)
    elif matched < 0.5 * t.size:
        raise DataError(f"{truth_path}: only {matched} of its {t.size} reference poses inside the odometry's time "
                        f"span are stamped within 1 ms of an ODOM line or scan of {log_path}: is it this log's truth?")
    if scan_dt > 0.0 and t.size > 2:
        ref_dt = float(np.median(np.diff(t)))
        if ref_dt > 1.5 * scan_dt:
            # the alphas are the odometry's error over the reference spacing (module doc): a 1 Hz reference of a
            # 5 Hz log gave alpha1 0.033 where its 5 Hz reference gave 0.164, ready to paste without a word
            warnings.warn(f"{truth_path}: its poses are {ref_dt:.3g} s apart, the scans of {log_path} {scan_dt:.3g} s: "
                          f"the alphas describe the odometry's error over {ref_dt:.3g} s, and a filter that updates "
                          "every scan wants larger ones (a reference at the scans' rate gives them)", MclWarning,
                          stacklevel=2)
    if scan_dt > 0.0 and t.size > 10:
        check_lag(odo, t, poses, scan_dt, truth_path)
    odom = interpolate_odometry(odo, t)
    return odom[:, :-1], odom[:, 1:], poses[:, :-1], poses[:, 1:], t[:-1]


# a reference on its own clock whose poses come this many scan periods apart or closer (motion capture at 100 Hz
# beside a 40 Hz laser and slower) is taken at the scans; a sparser one must be stamped at the log's: a truth of
# twice the scans' rate 50 ms late is another clock, refused
DENSE_REFERENCE = 0.4


def _at_scans(t, poses, scan_t, ref_dt: float, truth_path, log_path):
    """(t, poses) of a reference denser than the scans (a motion-capture system at 50-200 Hz on its own clock)
    taken at the scans' stamps inside its span, interpolated between its two poses around each (none across a gap
    over 1.5 of its spacing): the pairs a filter updating every scan sees. Its stamps never met the log's within
    1 ms, and it was refused as "is it this log's truth?". Said in a warning."""
    from mcl.evaluate import interpolate_poses

    inside = scan_t[(scan_t >= t[0]) & (scan_t <= t[-1])]
    i = np.clip(np.searchsorted(t, inside), 1, t.size - 1)
    inside = inside[t[i] - t[i - 1] <= 1.5 * ref_dt]
    if inside.size < 2:
        raise DataError(f"{truth_path}: fewer than 2 scans of {log_path} inside its poses' time span")
    warnings.warn(f"{truth_path}: its poses are {ref_dt:.3g} s apart, denser than the scans of {log_path}: taken at "
                  f"the {inside.size} scans inside its span, interpolated", MclWarning, stacklevel=3)
    return inside, interpolate_poses(t, poses, inside)


def log_odometry(log) -> np.ndarray:
    """A CARMEN log's odometry as (K, 6) rows (t, x, y, theta, v, omega): its ODOM lines, or, for logs without
    them (mit_csail), its scans' own odometry poses with zero velocities; (0, 6) when it has neither."""
    odo = np.asarray(log.odometry, dtype=np.float64)
    if odo.size == 0:
        odo = np.array([(s.t, *s.odom[:3], 0.0, 0.0) for s in log.scans if s.odom is not None],
                       dtype=np.float64).reshape(-1, 6)
    return odo


def _steps(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each consecutive pair's translation (m) and signed turn (rad): the motion, in any frame."""
    from mcl.estimate import wrap_angle

    d = np.diff(poses, axis=1)
    return np.hypot(d[0], d[1]), wrap_angle(d[2])


def check_lag(odo: np.ndarray, t: np.ndarray, poses: np.ndarray, period: float, truth_path,
              fitted: str = "The alphas are") -> None:
    """Warn when the reference moves as the odometry does only shifted in time by a scan period or two: a truth
    stamped a frame late fitted alpha3 4x too large without a word (and calibrate sensor's sigma_hit 2x). The pairs'
    motions (translation and signed turn) are compared with the odometry's over the same times, and over times
    shifted by -2..2 periods. ``fitted`` names what the caller fits, for the warning."""
    from mcl.datasets.carmen import interpolate_odometry

    trans, turn = _steps(poses)
    inside = (t >= odo[0, 0] + 2.5 * period) & (t <= odo[-1, 0] - 2.5 * period)
    keep = inside[:-1] & inside[1:]
    if np.count_nonzero(keep) < 10:
        return

    def misfit_at(k: int) -> float:
        o_trans, o_turn = _steps(interpolate_odometry(odo, t + k * period))
        return float(np.mean((np.abs(o_trans - trans) + np.abs(o_turn - turn))[keep]))

    misfit = {k: misfit_at(k) for k in (-2, -1, 0, 1, 2)}
    best = min(misfit, key=misfit.get)
    if best != 0 and misfit[best] < LAG_RATIO * misfit[0]:
        warnings.warn(f"{truth_path}: its poses move as the odometry does {abs(best) * period:.3g} s "
                      f"{'later' if best > 0 else 'earlier'} (the steps' mean misfit {misfit[best]:.3g} against "
                      f"{misfit[0]:.3g} as stamped): is the reference stamped {'early' if best > 0 else 'late'}? "
                      f"{fitted} fitted as stamped", MclWarning, stacklevel=3)


def bag_message(path) -> str:
    """The one line for a ROS bag given where a CARMEN log is needed."""
    from pathlib import Path

    return (f"{path}: a ROS bag; calibrate motion and calibrate sensor read CARMEN logs: convert it first with "
            f"`mcl convert {path} {Path(path).with_suffix('.clf')}`")


def _still(a, b):
    from mcl.motion import _wrap_np

    return (np.hypot(b[0] - a[0], b[1] - a[1]) < STILL_TRANS) & (np.abs(_wrap_np(b[2] - a[2])) < STILL_ROT)


SIGMA_FLOOR = 1e-3  # m or rad: no noise std below this in the fit (logged poses are rounded, see fit_odometry_alphas)


def pair_log_likelihoods(alphas, odom_prev, odom_now, x_prev, x_now, noise_form="variance", noise="normal",
                         sigma_floor=SIGMA_FLOOR, min_trans=None, p_turn=0.0, noise_step=0.0) -> np.ndarray:
    """(M,) log p(x_now | (odom_prev, odom_now), x_prev) of each pair: Table 5.5 without the Jacobian, mixed with the
    turn-only density (weight p_turn; alone below min_trans), see the module docstring."""
    from mcl.motion import ROT1_MIN_TRANS, SIGMA_MIN, _wrap_np, noise_sigmas_array, odometry_deltas_array, \
        odometry_residuals
    from mcl.noise import log_density

    cfg = SimpleNamespace(alpha1=alphas[0], alpha2=alphas[1], alpha3=alphas[2], alpha4=alphas[3],
                          noise_form=noise_form, noise_step=noise_step)
    mt = ROT1_MIN_TRANS if min_trans is None else float(min_trans)
    f = max(float(sigma_floor), SIGMA_MIN)

    def log_f(r, sigma):
        return log_density(noise, r, np.maximum(sigma, f))

    r1, tr, r2 = odometry_deltas_array(odom_prev, odom_now, mt)
    h1, ht, h2 = odometry_deltas_array(x_prev, x_now, mt)
    s1, st, s2 = noise_sigmas_array(h1, ht, h2, cfg)
    # turn only: rot1 = 0, rot2 = the whole turn (the filter's rule below min_trans), noise eps_rot1 + eps_rot2;
    # the step's direction is free, so its sign is too: the translation's density is folded at 0
    turn = _wrap_np(h1 + h2)
    t1, tt, t2 = noise_sigmas_array(np.zeros_like(turn), ht, turn, cfg)

    def turn_only(sig_turn, sig_trans):
        return (log_f(_wrap_np(r1 + r2 - turn), sig_turn)
                + np.logaddexp(log_f(tr - ht, sig_trans), log_f(tr + ht, sig_trans)))

    ll_turn = turn_only(np.hypot(t1, t2), tt)
    d1, dtr, d2 = odometry_residuals(r1, tr, r2, h1, ht, h2)
    ll = log_f(d1, s1) + log_f(dtr, st) + log_f(d2, s2)
    # an odometry step under min_trans has no direction to compare: the turn and the step alone, their noise from
    # the hypothesis's split where its step shows one (a pose that moved 15 cm turning 0.35 then -0.33 rad, its
    # odometry reading 6 mm: turn noise sigma 0.1, not the 0.02 of (0, the net turn), which put alpha3 at 0.074
    # for 0.05 on the model's own draws), of (0, the turn) for the share p_turn whose split is not observed
    ll_short = turn_only(np.hypot(s1, s2), st)
    if p_turn > 0:  # the split uniform on the circle: 1 / 2 pi
        ll = np.logaddexp(math.log1p(-p_turn) + ll, math.log(p_turn / (2 * math.pi)) + ll_turn)
        ll_short = np.logaddexp(math.log1p(-p_turn) + ll_short, math.log(p_turn) + ll_turn)
    # a hypothesis step under min_trans has rot1 = 0 (odometry_deltas_array): ll_short is ll_turn there
    return np.where(ht < mt, ll_turn, np.where(tr < mt, ll_short, ll))


def pair_log_likelihood(alphas, *pairs, **kw) -> float:
    """sum over pairs of ``pair_log_likelihoods`` (same arguments)."""
    return float(np.sum(pair_log_likelihoods(alphas, *pairs, **kw)))


def check_min_trans(min_trans) -> None:
    """min_trans (None: the default) must be a finite number >= 0."""
    if min_trans is not None and not (math.isfinite(min_trans) and min_trans >= 0):
        raise ConfigError(f"--min-trans: must be a number >= 0 (m), got {min_trans}")


OUTLIER_NATS = 25.0  # a pair this far (or 10 robust spreads) below the median pair's log-likelihood is no noise
OUTLIER_SHARE = 0.05  # ... and at most this share of the pairs is left out as such


def fit_odometry_alphas(odom_prev, odom_now, x_prev, x_now, *, noise_form="variance", noise="normal",
                        x0=(0.05, 0.05, 0.05, 0.05), min_trans=None, p_turn=None, t=None, noise_step=0.0,
                        trim: bool = True) -> dict:
    """``_fit_odometry_alphas``, with the pairs no noise explains left out (``trim``): fitted on every pair, a pair
    whose log-likelihood lies ``OUTLIER_NATS`` (or 10 robust spreads) below the median pair's is a kidnap, an
    odometry reset or slip, not noise, and the fit is made again without such pairs when they are at most
    ``OUTLIER_SHARE`` of them (said in a warning naming the worst pair's time; ``left_out`` in the result). One
    kidnap pair in the demo's log made alpha4 0.125 instead of 0.0073; one odometry reset in a generated drive made
    alpha3 21 and alpha1 a sixth of its value, and the calibrated config tracked worse than the default.

    ``noise_step`` 0 (this function's default) fits the book's Table 5.5/5.6 noise; alphas for a config pass its
    ``motion.noise_step`` (``MotionConfig``'s default is 0.3 m, as ``mcl calibrate motion`` does), else steps over
    0.3 m were fitted with another noise than the filter then samples."""
    op, on, xp, xn = (np.asarray(a, dtype=np.float64) for a in (odom_prev, odom_now, x_prev, x_now))
    kw = dict(noise_form=noise_form, noise=noise, x0=x0, min_trans=min_trans, p_turn=p_turn, noise_step=noise_step)
    if not trim:
        return _public(_fit_odometry_alphas(op, on, xp, xn, t=t, **kw))
    with warnings.catch_warnings():  # the first fit's warnings may be the outliers' doing: the final fit says its own
        warnings.simplefilter("ignore", MclWarning)
        first = _fit_odometry_alphas(op, on, xp, xn, t=t, **kw)
    ll, used = first.pop("_pair_ll"), first.pop("_used")
    med = float(np.median(ll))
    spread = 1.4826 * float(np.median(np.abs(ll - med)))
    bad = ~(ll >= med - max(OUTLIER_NATS, 10.0 * spread))  # (a pair of density 0 too)
    if not bad.any() or bad.sum() > OUTLIER_SHARE * ll.size:  # none, or too many to be faults: the fit as it is
        return _said(first)
    drop = np.flatnonzero(used)[bad]
    keep = np.ones(op.shape[1], dtype=bool)
    keep[drop] = False
    worst = int(drop[int(np.argmin(ll[bad]))])
    when = f" (the worst at t = {float(np.asarray(t)[worst]):.3f} s)" if t is not None else ""
    note = (f"calibrate motion: {drop.size} of {ll.size} pairs left out: no noise explains them (a kidnap, an odometry "
            f"reset or slip; {med - float(np.min(ll)):.0f} nats below the median pair){when}")
    warnings.warn(note, MclWarning, stacklevel=2)
    out = _fit_odometry_alphas(op[:, keep], on[:, keep], xp[:, keep], xn[:, keep],
                               t=None if t is None else np.asarray(t)[keep], **kw)
    out = _public(out)
    out["left_out"] = int(drop.size)
    out["warnings"] = [note] + out["warnings"]
    return out


def _public(result: dict) -> dict:
    """``result`` without the per-pair figures the trimming reads."""
    result.pop("_pair_ll", None)
    result.pop("_used", None)
    return result


def _said(result: dict) -> dict:
    """``result`` of a fit made with its warnings silenced: said now (no pair was left out)."""
    for n in result["warnings"]:
        warnings.warn(n, MclWarning, stacklevel=3)
    return result


def _fit_odometry_alphas(odom_prev, odom_now, x_prev, x_now, *, noise_form="variance", noise="normal",
                         x0=(0.05, 0.05, 0.05, 0.05), min_trans=None, p_turn=None, t=None, noise_step=0.0) -> dict:
    """Maximum-likelihood alpha1..alpha4 of the odometry model from matched pairs (see the module docstring).

    Returns {"alphas": [a1..a4], "p_turn", "log_likelihood", "pairs" (used), "skipped" (still), "converged",
    "message", "warnings"}. p_turn: None fits it with the alphas, a number fixes it (0: Table 5.5 alone).
    t (M,): the pairs' times, to name a pair in errors. Warns (``MclWarning``) about alphas above 1.

    With triangular noise (bounded support) the density is zero wherever a
    residual lies outside the support; a pair no alphas within the bounds
    cover is an error naming it, and the fit starts from alphas large enough
    to cover every pair.

    The noise stds are floored at ``SIGMA_FLOOR`` (1 mm / 1 mrad): logs print
    poses to about 1e-6 m, so the direction of a 1 cm step is known to only
    about 1e-4 rad, and a turn on the spot (zero modelled rot1 noise) would
    otherwise make one rounding error outweigh the whole log.

    min_trans (default the filter's 1 cm, ``ROT1_MIN_TRANS``): below this
    translation (odometry or reference) rot1 = 0 and rot2 carries the turn:
    the pair is scored on its turn and translation only.

    noise_step: ``motion.noise_step`` of the model fitted (0: the book's dtrans^2 for every step length).
    """
    from scipy.special import expit

    check_min_trans(min_trans)
    op, on, xp, xn = (np.asarray(a, dtype=np.float64) for a in (odom_prev, odom_now, x_prev, x_now))
    still = _still(xp, xn) & _still(op, on)
    use = ~still
    op, on, xp, xn = op[:, use], on[:, use], xp[:, use], xn[:, use]
    m = op.shape[1]
    if m < 4:
        raise DataError(f"calibrate motion: only {m} pairs with motion; need at least 4")
    hi = math.log(ALPHA_BOUNDS[1])
    fit_p = p_turn is None

    def unpack(z):  # log-alphas, and p_turn = P_TURN_MAX * logistic(z[4])
        # (Nelder-Mead is unbounded: exp(-z) overflowed past z = -710; scipy's logistic does not)
        return np.exp(z[:4]), (P_TURN_MAX * float(expit(z[4])) if fit_p else float(p_turn))

    def lls(z):
        a, p = unpack(z)
        return pair_log_likelihoods(a, op, on, xp, xn, noise_form, noise, min_trans=min_trans, p_turn=p,
                                    noise_step=noise_step)

    def nll(z):
        v = -float(np.sum(lls(z))) / m
        return v if np.isfinite(v) else 1e300  # outside a bounded support: a wall for the optimiser

    z0 = np.r_[np.log(np.asarray(x0, dtype=np.float64)), -2.0]
    if noise != "normal":
        # the widest supports (every alpha at its bound) must cover every pair, or no alphas do
        bad = np.flatnonzero(~np.isfinite(lls(np.r_[np.full(4, hi), 12.0])))
        if bad.size:
            k = int(bad[0])
            tk = np.asarray(t, dtype=np.float64)[use][k] if t is not None else None
            from mcl.motion import ROT1_MIN_TRANS, odometry_deltas_array

            mt = ROT1_MIN_TRANS if min_trans is None else min_trans
            o = [float(v[0]) for v in odometry_deltas_array(op[:, k], on[:, k], mt)]
            r = [float(v[0]) for v in odometry_deltas_array(xp[:, k], xn[:, k], mt)]
            raise DataError(
                f"calibrate motion: motion.noise={noise} has a bounded support, and no alphas up to "
                f"{ALPHA_BOUNDS[1]:g} give pair {k}{f' (t = {tk:.3f})' if tk is not None else ''} a nonzero density: "
                f"odometry (rot1, trans, rot2) = ({o[0]:.4f}, {o[1]:.4f}, {o[2]:.4f}), reference "
                f"({r[0]:.4f}, {r[1]:.4f}, {r[2]:.4f}) ({bad.size} such pairs); fit with motion.noise=normal")
        while nll(z0) >= 1e300 and z0[:4].max() < hi:
            z0[:4] += math.log(2.0)
    best, z_best, converged, loose, notes, se = _maximise(lls, nll, z0, 4, [(-12.0, 12.0)], ALPHA_NAMES)
    alphas, p = unpack(z_best)
    alphas = np.clip(alphas, *ALPHA_BOUNDS)  # exp(log(100)) is 100.00000000000004
    return {"alphas": [float(a) for a in alphas], "alphas_se": se, "p_turn": float(p),
            "log_likelihood": float(-best.fun * m),
            "pairs": int(m), "skipped": int(np.count_nonzero(still)), "converged": converged,
            "message": str(best.message), "undetermined": [ALPHA_NAMES[k] for k in loose], "noise_form": noise_form,
            "noise": noise, "noise_step": float(noise_step), "warnings": notes,
            "_pair_ll": np.asarray(lls(z_best), dtype=np.float64), "_used": use}


ALPHA_NAMES = ("alpha1", "alpha2", "alpha3", "alpha4", "alpha_strafe")


def _maximise(lls, nll, z0, n_alpha: int, extra_bounds: list, names) -> tuple:
    """(best result, its parameters, converged, the undetermined alphas' indices, the warnings said) of the fit of
    ``nll`` over z0 (log-alphas first, ``n_alpha`` of them, then parameters bounded by ``extra_bounds``): Nelder-Mead
    first (robust to the flat start), then L-BFGS-B to polish. ``lls(z)``: the pairs' log-likelihoods."""
    from scipy.optimize import minimize

    lo, hi = (math.log(b) for b in ALPHA_BOUNDS)
    r0 = minimize(nll, z0, method="Nelder-Mead", options={"xatol": 1e-4, "fatol": 1e-10, "maxiter": 8000})
    r = minimize(nll, r0.x, method="L-BFGS-B", bounds=[(lo, hi)] * n_alpha + list(extra_bounds))
    best = r if r.fun <= r0.fun else r0
    z_best = best.x.copy()
    z_best[:n_alpha] = np.clip(z_best[:n_alpha], lo, hi)  # Nelder-Mead is unbounded: keep the documented bounds
    notes = []
    # An alpha the data do not constrain (no turn: alpha1, alpha4; no translation: alpha2, alpha3) drifts anywhere
    # on a flat likelihood: say so instead of printing it as a fit.
    base = float(np.sum(lls(z_best)))
    loose = []
    for k in range(n_alpha):
        zk = z_best.copy()
        zk[k] = min(z_best[k] + math.log(4.0), hi) if z_best[k] < hi - 1e-9 else z_best[k] - math.log(4.0)
        if abs(float(np.sum(lls(zk))) - base) < 2.0:  # a 4x change moves the log-likelihood by < 2: undetermined
            loose.append(k)
    if loose:
        notes.append(f"calibrate motion: {', '.join(names[k] for k in loose)} not determined by this log "
                     f"(a 4x change moves the log-likelihood by less than 2: the reference hardly turns or "
                     f"translates); keep your config's value")
    alphas = np.clip(np.exp(z_best[:n_alpha]), *ALPHA_BOUNDS)
    big = [f"{names[k]} = {a:.3g}" for k, a in enumerate(alphas) if a > ALPHA_PLAUSIBLE and k not in loose]
    if big:
        notes.append(f"calibrate motion: {', '.join(big)} above {ALPHA_PLAUSIBLE:g} is implausible (a noise as large "
                     f"as the motion itself): check that the reference is this log's, in step with its odometry")
    for n in notes:
        warnings.warn(n, MclWarning, stacklevel=3)
    se = _alpha_se(lls, z_best, n_alpha, (lo, hi), extra_bounds, loose)
    return best, z_best, bool((r.success or r0.success) and best.fun < 1e300), loose, notes, se


SE_STEP = 1e-3  # the finite-difference step of the Hessian, in log-alpha (a 0.1 % change of an alpha)


def _alpha_se(lls, z, n_alpha: int, alpha_bounds, extra_bounds: list, loose) -> list:
    """Standard errors of the fitted alphas (a list of ``n_alpha``, None where not given): the inverse of the observed
    information, the Hessian of the negative log-likelihood ``-sum(lls(z))`` at the fit ``z`` by central differences
    in the parameters the fit moves (log-alphas, then the extra ones). An alpha the log does not determine
    (``loose``) or that sits on a bound has none, and is held fixed; a Hessian that is not positive definite (a flat
    or bounded likelihood, triangular noise at its support's edge) gives none at all. By the delta method, the SE of
    alpha is alpha times the SE of its log. The pairs are taken as independent (the model's noise is drawn per step); a
    reference whose own errors are correlated along the log makes these too small."""
    lo, hi = alpha_bounds
    bounds = [(lo, hi)] * n_alpha + list(extra_bounds)
    free = [k for k in range(z.size) if k not in loose
            and bounds[k][0] + SE_STEP < z[k] < bounds[k][1] - SE_STEP]
    out = [None] * n_alpha
    if not free:
        return out
    h = SE_STEP

    def f(dz):
        zz = z.copy()
        zz[free] += dz
        return -float(np.sum(lls(zz)))

    n = len(free)
    f0, e = f(np.zeros(n)), np.eye(n) * h
    hess = np.empty((n, n))
    for i in range(n):
        hess[i, i] = (f(e[i]) - 2.0 * f0 + f(-e[i])) / (h * h)
        for j in range(i):
            hess[i, j] = hess[j, i] = (f(e[i] + e[j]) - f(e[i] - e[j]) - f(e[j] - e[i]) + f(-e[i] - e[j])) / (4 * h * h)
    if not np.isfinite(hess).all():
        return out
    try:
        l_inv = np.linalg.inv(np.linalg.cholesky(hess))  # H = L L^T: positive definite, or no standard errors
    except np.linalg.LinAlgError:
        return out
    var = np.einsum("ij,ij->j", l_inv, l_inv)  # diag(H^-1) = column sums of squares of L^-1
    for i, k in enumerate(free):
        if k < n_alpha:
            out[k] = float(math.exp(z[k]) * math.sqrt(var[i]))
    return out


def omni_pair_log_likelihoods(alphas, odom_prev, odom_now, x_prev, x_now, noise_form="variance", noise="normal",
                              sigma_floor=SIGMA_FLOOR, noise_step=0.0) -> np.ndarray:
    """(M,) log p(x_now | (odom_prev, odom_now), x_prev) of each pair under the omni model (``mcl.motion``'s
    ``log_motion_model_omni``, each pair with its own odometry), the noise stds from the reference's motion (as
    Table 5.5 takes them from the hypothesis). ``alphas``: alpha1..alpha4, alpha_strafe."""
    from mcl.motion import SIGMA_MIN, omni_residuals, omni_sigmas
    from mcl.noise import log_density

    cfg = SimpleNamespace(alpha1=alphas[0], alpha2=alphas[1], alpha3=alphas[2], alpha4=alphas[3],
                          alpha_strafe=alphas[4], noise_form=noise_form, noise_step=noise_step)
    f = max(float(sigma_floor), SIGMA_MIN)
    residuals, _, (trans, turn) = omni_residuals(odom_prev, odom_now, x_prev, x_now)
    return sum(log_density(noise, r, np.maximum(sg, f)) for r, sg in zip(residuals, omni_sigmas(trans, turn, cfg)))


def fit_omni_alphas(odom_prev, odom_now, x_prev, x_now, *, noise_form="variance", noise="normal",
                    x0=(0.05, 0.05, 0.05, 0.05, 0.05), noise_step=0.0) -> dict:
    """Maximum-likelihood alpha1..alpha4 and alpha_strafe of the omni model (``mcl.motion.OmniMotionModel``) from
    matched pairs, as ``fit_odometry_alphas`` (its "alphas" hold the five; no p_turn: the omni model does not split
    a step's turn). Normal noise only (a bounded support needs the odometry model's start search)."""
    op, on, xp, xn = (np.asarray(a, dtype=np.float64) for a in (odom_prev, odom_now, x_prev, x_now))
    if noise != "normal":
        raise ConfigError(f"calibrate motion: the omni model is fitted with motion.noise=normal, not {noise}")
    still = _still(xp, xn) & _still(op, on)
    op, on, xp, xn = op[:, ~still], on[:, ~still], xp[:, ~still], xn[:, ~still]
    m = op.shape[1]
    if m < 5:
        raise DataError(f"calibrate motion: only {m} pairs with motion; need at least 5")

    def lls(z):
        return omni_pair_log_likelihoods(np.exp(z), op, on, xp, xn, noise_form, noise, noise_step=noise_step)

    def nll(z):
        v = -float(np.sum(lls(z))) / m
        return v if np.isfinite(v) else 1e300

    best, z_best, converged, loose, notes, se = _maximise(lls, nll, np.log(np.asarray(x0, dtype=np.float64)), 5,
                                                          [], ALPHA_NAMES)
    alphas = np.clip(np.exp(z_best), *ALPHA_BOUNDS)
    return {"alphas": [float(a) for a in alphas], "alphas_se": se, "log_likelihood": float(-best.fun * m),
            "pairs": int(m),
            "skipped": int(np.count_nonzero(still)), "converged": converged, "message": str(best.message),
            "undetermined": [ALPHA_NAMES[k] for k in loose], "noise_form": noise_form, "noise": noise,
            "noise_step": float(noise_step), "model": "omni", "warnings": notes}


def format_yaml(result: dict, noise_form: str, noise: str, source: str = "") -> str:
    """The fitted alphas as a YAML block ready to paste into a config (the odometry model's, or the omni model's
    with alpha_strafe)."""
    a = result["alphas"]
    omni = result.get("model") == "omni"
    head = f"# mcl calibrate motion{': ' + source if source else ''}\n" \
           f"# {result['pairs']} pairs ({result['skipped']} still pairs skipped), " \
           f"log-likelihood {result['log_likelihood']:.1f}{'' if result['converged'] else ', NOT converged'}" + \
           ("\n" if omni else f"; turn split not observed in a share p_turn = {result.get('p_turn', 0.0):.3f} of the "
            "pairs\n")
    if result.get("left_out"):
        head += (f"# {result['left_out']} pairs left out: no noise explains them (a kidnap, an odometry reset or "
                 "slip)\n")
    und = set(result.get("undetermined", ()))

    def line(k):  # an undetermined alpha is left out (commented), so pasting keeps the config's own value
        name = ALPHA_NAMES[k]
        if name in und:
            return f"  # {name}: not determined by this log (the fit drifted to {a[k]:.3g}); keep your own\n"
        notes = ["implausible (> 1)"] if a[k] > ALPHA_PLAUSIBLE else []
        se = (result.get("alphas_se") or [None] * len(a))[k]
        if se is not None:  # the standard error, and as a share of the alpha
            notes.append(f"+- {se:.2g} ({100.0 * se / a[k]:.0f} %)" if a[k] > 0 else f"+- {se:.2g}")
        return f"  {name}: {a[k]:.6g}{'  # ' + '; '.join(notes) if notes else ''}\n"
    # model: odometry -- the alphas are the odometry model's (a velocity config's alpha1..4 mean something else)
    body = (f"motion:\n  model: {'omni' if omni else 'odometry'}\n  noise_form: {noise_form}\n"
            f"  noise_step: {result.get('noise_step', 0.0):g}\n  noise: {noise}\n")
    body += "".join(line(k) for k in range(len(a)))
    return head + body


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``mcl calibrate motion``."""
    p.add_argument("--log", required=True, help="CARMEN log with the odometry (ODOM lines or scan poses)")
    p.add_argument("--truth", required=True, help="reference trajectory (TUM) at (a subset of) the log's times")
    p.add_argument("--config", help="config whose motion.model (odometry or omni), motion.noise_form, "
                   "motion.noise_step and motion.noise the fit uses (default: the defaults)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="config override, e.g. motion.noise_form=std")
    p.add_argument("--min-trans", type=float, default=None, metavar="M",
                   help="below this step (m, >= 0) rot1 = 0 for odometry and reference and the pair is scored on its "
                        "turn and translation only (default 0.01, the filter's)")
    p.add_argument("--json", action="store_true", help="print the fit as JSON instead of YAML")


def run_from_args(args) -> int:
    import json

    from mcl.config import load_config

    check_min_trans(args.min_trans)
    cfg = load_config(args.config, list(args.set))
    if cfg.motion.model == "velocity":
        warnings.warn("calibrate motion: fits the odometry and omni models, not motion.model=velocity: the "
                      "block sets model: odometry", MclWarning, stacklevel=2)
    pairs = pairs_from_log(args.log, args.truth)
    if cfg.motion.model == "omni":
        res = fit_omni_alphas(*pairs[:4], noise_form=cfg.motion.noise_form, noise=cfg.motion.noise,
                              noise_step=cfg.motion.noise_step)
    else:
        res = fit_odometry_alphas(*pairs[:4], noise_form=cfg.motion.noise_form, noise=cfg.motion.noise,
                                  noise_step=cfg.motion.noise_step,
                                  min_trans=args.min_trans, t=pairs[4])
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        print(format_yaml(res, cfg.motion.noise_form, cfg.motion.noise, source=f"{args.log} vs {args.truth}"), end="")
    return 0
