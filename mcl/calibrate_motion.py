"""``mcl calibrate motion``: fit the odometry model's alpha1..alpha4 by maximum likelihood.

The seeds ask "how can we determine the model parameters?". With reference
poses (a truth trajectory) and the log's odometry, each pair of consecutive
reference times t_i, t_{i+1} gives one observation of the odometry model:

    x_{i}, x_{i+1}            reference poses (the hypotheses of Table 5.5)
    u_i = (o(t_i), o(t_{i+1})) odometry poses at the same times (ODOM lines
                              interpolated, else the scans' own odometry)

and the alphas maximise sum_i log p(x_{i+1} | u_i, x_i) of the closed-form
odometry density (``mcl.motion.log_motion_model_odometry``'s terms, the book's
Table 5.5: noise stds from the reference motion, angle differences wrapped).
The pose-space Jacobian does not depend on the alphas and is left out. The
optimiser is L-BFGS-B on log-alphas (so they stay positive) with bounds
[1e-9, 100].

What the fitted alphas mean: they describe the odometry error *over the
reference spacing*. Noise accumulates along the odometry chain, so fitting
pairs 2 ticks apart gives roughly half the per-tick alphas of the variance
form (the filter, which updates every few scans, wants the alphas at its own
update spacing). Reference poses that are themselves noisy (SLAM-corrected
logs jitter by centimetres) inflate the fitted alphas, alpha2 and alpha3 most.
Pairs where neither the reference nor the odometry moved (less than 1 mm and
1 mrad) carry no information and are skipped.
"""

from __future__ import annotations

import argparse
import math
from types import SimpleNamespace

import numpy as np

from mcl.errors import DataError

ALPHA_BOUNDS = (1e-9, 100.0)
STILL_TRANS = 1e-3  # m
STILL_ROT = 1e-3  # rad


def pairs_from_log(log_path, truth_path):
    """(odom_prev, odom_now, x_prev, x_now, t) for consecutive truth times: four (3, M) arrays and (M,) times.

    Odometry comes from the log's ODOM lines interpolated at the truth times
    (``interpolate_odometry``), or, for logs without ODOM lines (mit_csail),
    from the scans' own odometry poses interpolated the same way.
    """
    from mcl.datasets.carmen import interpolate_odometry, read_carmen
    from mcl.trajectory import read_tum

    t, poses = read_tum(truth_path)
    order = np.argsort(t, kind="stable")
    t, poses = t[order], poses[:, order]
    log = read_carmen(log_path)
    odo = np.asarray(log.odometry, dtype=np.float64)
    if odo.size == 0:
        rows = [(s.t, *s.odom[:3]) for s in log.scans if s.odom is not None]
        if not rows:
            raise DataError(f"{log_path}: no odometry (no ODOM lines and no scan poses)")
        odo = np.array([(r[0], r[1], r[2], r[3], 0.0, 0.0) for r in rows])
    t0, t1 = odo[:, 0].min(), odo[:, 0].max()
    keep = (t >= t0) & (t <= t1)
    t, poses = t[keep], poses[:, keep]
    if t.size < 2:
        raise DataError(f"{truth_path}: fewer than 2 reference poses inside the log's odometry time span")
    odom = interpolate_odometry(odo, t)
    return odom[:, :-1], odom[:, 1:], poses[:, :-1], poses[:, 1:], t[:-1]


def _still(a, b):
    from mcl.motion import _wrap_np

    return (np.hypot(b[0] - a[0], b[1] - a[1]) < STILL_TRANS) & (np.abs(_wrap_np(b[2] - a[2])) < STILL_ROT)


SIGMA_FLOOR = 1e-3  # m or rad: no noise std below this in the fit (logged poses are rounded, see fit_odometry_alphas)


def pair_log_likelihood(alphas, odom_prev, odom_now, x_prev, x_now, noise_form="variance", noise="normal",
                        sigma_floor=SIGMA_FLOOR, min_trans=None):
    """sum over pairs of log p(x_now | (odom_prev, odom_now), x_prev), Table 5.5 without the Jacobian."""
    from mcl.motion import SIGMA_MIN, noise_sigmas_array, odometry_deltas_array, odometry_residuals
    from mcl.noise import log_density

    cfg = SimpleNamespace(alpha1=alphas[0], alpha2=alphas[1], alpha3=alphas[2], alpha4=alphas[3],
                          noise_form=noise_form)
    from mcl.motion import ROT1_MIN_TRANS

    mt = ROT1_MIN_TRANS if min_trans is None else float(min_trans)
    r1, tr, r2 = odometry_deltas_array(odom_prev, odom_now, mt)
    h1, ht, h2 = odometry_deltas_array(x_prev, x_now, mt)
    s1, st, s2 = noise_sigmas_array(h1, ht, h2, cfg)
    d1, dtr, d2 = odometry_residuals(r1, tr, r2, h1, ht, h2)
    f = max(float(sigma_floor), SIGMA_MIN)
    ll = (log_density(noise, d1, np.maximum(s1, f))
          + log_density(noise, dtr, np.maximum(st, f))
          + log_density(noise, d2, np.maximum(s2, f)))
    return float(np.sum(ll))


def fit_odometry_alphas(odom_prev, odom_now, x_prev, x_now, *, noise_form="variance", noise="normal",
                        x0=(0.05, 0.05, 0.05, 0.05), min_trans=None) -> dict:
    """Maximum-likelihood alpha1..alpha4 of the odometry model from matched pairs (see the module docstring).

    Returns {"alphas": [a1..a4], "log_likelihood", "pairs" (used), "skipped" (still), "converged", "message"}.
    With triangular noise the likelihood is -inf wherever one pair falls
    outside the support; the fit then starts from alphas large enough to
    cover every pair.

    The noise stds are floored at ``SIGMA_FLOOR`` (1 mm / 1 mrad): logs print
    poses to about 1e-6 m, so the direction of a 1 cm step is known to only
    about 1e-4 rad, and a turn on the spot (zero modelled rot1 noise) would
    otherwise make one rounding error outweigh the whole log.

    min_trans (default the filter's 1 cm, ``ROT1_MIN_TRANS``): below this
    translation rot1 = 0 and rot2 carries the turn, for the odometry and the
    reference alike. With a reference that jitters by centimetres (intel_lab),
    a reference step of 2-5 cm where the odometry turned on the spot reads as
    rot1 = +-pi/2 and inflates alpha1/alpha2; raise min_trans above the jitter.
    """
    from scipy.optimize import minimize

    op, on, xp, xn = (np.asarray(a, dtype=np.float64) for a in (odom_prev, odom_now, x_prev, x_now))
    still = _still(xp, xn) & _still(op, on)
    use = ~still
    op, on, xp, xn = op[:, use], on[:, use], xp[:, use], xn[:, use]
    m = op.shape[1]
    if m < 4:
        raise DataError(f"calibrate motion: only {m} pairs with motion; need at least 4")
    lo, hi = (math.log(b) for b in ALPHA_BOUNDS)

    def nll(z):
        v = -pair_log_likelihood(np.exp(z), op, on, xp, xn, noise_form, noise, min_trans=min_trans) / m
        return v if np.isfinite(v) else 1e300

    z0 = np.log(np.asarray(x0, dtype=np.float64))
    if noise != "normal":
        while nll(z0) >= 1e300 and z0.max() < hi:
            z0 = z0 + math.log(2.0)
    # Nelder-Mead first (robust to the flat start), then L-BFGS-B to polish.
    r0 = minimize(nll, z0, method="Nelder-Mead", options={"xatol": 1e-4, "fatol": 1e-10, "maxiter": 4000})
    r = minimize(nll, r0.x, method="L-BFGS-B", bounds=[(lo, hi)] * 4)
    best = r if r.fun <= r0.fun else r0
    alphas = np.exp(best.x)
    return {"alphas": [float(a) for a in alphas], "log_likelihood": float(-best.fun * m), "pairs": int(m),
            "skipped": int(np.count_nonzero(still)), "converged": bool(r.success or r0.success),
            "message": str(best.message)}


def format_yaml(result: dict, noise_form: str, noise: str, source: str = "") -> str:
    """The fitted alphas as a YAML block ready to paste into a config."""
    a = result["alphas"]
    head = f"# mcl calibrate motion{': ' + source if source else ''}\n" \
           f"# {result['pairs']} pairs ({result['skipped']} still pairs skipped), " \
           f"log-likelihood {result['log_likelihood']:.1f}{'' if result['converged'] else ', NOT converged'}\n"
    body = "motion:\n" f"  noise_form: {noise_form}\n" f"  noise: {noise}\n" + \
        "".join(f"  alpha{k + 1}: {a[k]:.6g}\n" for k in range(4))
    return head + body


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``mcl calibrate motion``."""
    p.add_argument("--log", required=True, help="CARMEN log with the odometry (ODOM lines or scan poses)")
    p.add_argument("--truth", required=True, help="reference trajectory (TUM) at (a subset of) the log's times")
    p.add_argument("--config", help="config whose motion.noise_form and motion.noise the fit uses (default: the defaults)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="config override, e.g. motion.noise_form=std")
    p.add_argument("--min-trans", type=float, default=None, metavar="M",
                   help="below this step (m) rot1 = 0 for odometry and reference (default 0.01, the filter's); "
                        "raise it above the reference's jitter")
    p.add_argument("--json", action="store_true", help="print the fit as JSON instead of YAML")


def run_from_args(args) -> int:
    import json

    from mcl.config import load_config

    cfg = load_config(args.config, list(args.set))
    pairs = pairs_from_log(args.log, args.truth)
    res = fit_odometry_alphas(*pairs[:4], noise_form=cfg.motion.noise_form, noise=cfg.motion.noise,
                              min_trans=args.min_trans)
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        print(format_yaml(res, cfg.motion.noise_form, cfg.motion.noise, source=f"{args.log} vs {args.truth}"), end="")
    return 0
