"""Learning the range sensor's intrinsic parameters: ``mcl calibrate sensor``.

Prob. Rob. Table 6.2 (learn_intrinsic_parameters) is expectation-maximisation
over readings whose expected value is known. The reference poses (truth
timestamps matched to scans within 1 ms) give each reading its expectation:

Beam model (``fit_beam``)
    z* by ray casting (``cast_ray``, the filter's own caster) from the laser
    pose. The mixture is the filter's (``mcl.kernels.beam``): truncated
    Gaussian p_hit, exponential p_short on [0, z*], the p_max atom at zmax,
    uniform p_rand. E-step: responsibilities e_c = z_c p_c / sum. M-step:
    z_c = mean e_c; sigma_hit^2 = sum e_hit (z - z*)^2 / sum e_hit (the
    book's, which ignores the truncation: exact when z* is several sigma
    inside [0, zmax]); lambda_short is the exact weighted maximum likelihood
    of the *normalised* exponential (one concave 1-D equation, solved by
    bisection; the book's sum e_short / sum e_short z ignores the 1/(1 -
    exp(-lambda z*)) normaliser and is biased when z* is small). Beams whose
    ray expects no return (z* = zmax) are left out: their readings say
    nothing about hit noise or short readings (a no-return reading there
    would be credited to p_hit with zero error). Readings >= zmax are
    no-return readings (z = zmax), NaN and <= range_min are dropped.

Likelihood field (``fit_likelihood_field``)
    d = the distance field at the endpoint's cell (as the filter reads it;
    endpoints off the map count as D), clipped to D = likelihood_max_dist;
    no-return readings are left out (the filter skips them). Fitted density
    on [0, D]:  q(d) = w_hit * 2 N(d; 0, sigma^2) / (2 Phi(D / sigma) - 1)
    + w_rand / D  (a half-normal and a uniform). The filter scores
    z_hit N(d; 0, sigma^2) + z_rand / range_max, which is proportional to q
    when z_hit : z_rand = 2 w_hit / c : w_rand range_max / D (c the
    half-normal's truncation mass); the printed z_hit, z_rand are that
    ratio normalised to sum 1 (only the ratio matters to the filter).

Checks (EM fits whatever it is given): a truth of which fewer than half the
poses inside the scans' span match a scan is refused (another log's, on an
overlapping clock); when fewer than half the readings lie within ``NEAR`` of
the map's prediction, or sigma_hit exceeds ``SIGMA_HIT_MAX``, the fit warns
(another building's map, a truth in another frame); a parameter EM left on
its bound is flagged (``FitResult.bounds``, a warning and a comment in the
YAML).
"""

from __future__ import annotations

import math
import sys
import warnings
from dataclasses import dataclass, field

import numpy as np

from mcl.errors import DataError, MclWarning


def erf(x):
    """scipy.special.erf, imported on first use (scipy.special takes a second to import: not at mcl's startup)."""
    from scipy.special import erf as _erf

    return _erf(x)

BEAM_KEYS = ("z_hit", "z_short", "z_max", "z_rand", "sigma_hit", "lambda_short")
_LAMBDA_MIN, _LAMBDA_MAX = 1e-3, 1e3
_SIGMA_MIN = 1e-6  # m: EM's floor on sigma_hit
NEAR = 0.2  # m: a reading fits the map when |z - z*| (beam) or d (likelihood field) is below this
NEAR_MIN = 0.5  # warned below this share of readings that fit (the logs: 0.73-0.92 beam, 0.93-0.99 field; another
                # building's map: 0.03-0.11)
SIGMA_HIT_MAX = 0.5  # m: a sigma_hit above this is warned about too (the "hits" scatter; the logs' fits: 0.02-0.06)


@dataclass
class FitResult:
    """What EM fitted, with what it fitted it on."""

    model: str
    params: dict[str, float]  # the config keys, ready to paste
    n: int  # readings used
    loglik: float  # mean log-likelihood per reading at the fit
    iterations: int
    converged: bool
    extra: dict[str, float] = field(default_factory=dict)  # model-specific figures (e.g. the raw LF weights)
    scans: int = 0
    bounds: dict[str, str] = field(default_factory=dict)  # parameter -> "lower"/"upper": it landed on its bound


# ----------------------------------------------------------------------------- beam model


def beam_component_densities(z, zs, zmax, sigma, lam):
    """(4, M) float64: p_hit, p_short, p_max, p_rand of readings z given z* (NumPy, the kernel's formulas)."""
    z = np.asarray(z, dtype=np.float64)
    zs = np.asarray(zs, dtype=np.float64)
    zmax = np.broadcast_to(np.asarray(zmax, dtype=np.float64), z.shape)
    out = np.zeros((4,) + z.shape)
    s2 = sigma * math.sqrt(2.0)
    eta = 0.5 * (erf((zmax - zs) / s2) - erf(-zs / s2))
    inside = (z >= 0) & (z <= zmax) & (eta > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.exp(-0.5 * ((z - zs) / sigma) ** 2) / (math.sqrt(2 * math.pi) * sigma) / eta
        out[0] = np.where(inside, g, 0.0)
        sh = (z >= 0) & (z <= zs) & (zs > 0)
        out[1] = np.where(sh, lam * np.exp(-lam * z) / -np.expm1(-lam * zs), 0.0)
    out[2] = (z >= zmax).astype(np.float64)
    out[3] = np.where((z >= 0) & (z < zmax), 1.0 / zmax, 0.0)
    return out


def _fit_lambda(r, z, zs, lam0):
    """Weighted ML rate of the exponential normalised on [0, z*]: root of S/lam - sum r z - sum r z*/(e^{lam z*} - 1)."""
    s = r.sum()
    if s <= 0:
        return lam0
    rz = float(np.dot(r, z))

    def g(lam):  # z*/(e^{lam z*} - 1) -> 1/lam as z* -> 0 (a ray cast from inside a wall): no 0/0
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            return s / lam - rz - float(np.dot(r, np.where(zs > 0, zs / np.expm1(lam * zs), 1.0 / lam)))

    lo, hi = _LAMBDA_MIN, _LAMBDA_MAX
    if g(lo) <= 0:
        return lo
    if g(hi) >= 0:
        return hi
    for _ in range(200):  # bisection on log lambda: g is decreasing (the log-likelihood is concave)
        mid = math.sqrt(lo * hi)
        if g(mid) > 0:
            lo = mid
        else:
            hi = mid
        if hi / lo < 1 + 1e-10:
            break
    return math.sqrt(lo * hi)


def _check_readings(**arrays) -> None:
    """ValueError naming an input that holds a NaN, an infinity or a negative value: one such reading made every
    weight of the fit NaN without a word (``collect`` leaves them out; the fits are public)."""
    for name, a in arrays.items():
        bad = ~np.isfinite(a) | (a < 0.0)
        if np.any(bad):
            raise ValueError(f"{name}: {int(np.count_nonzero(bad))} of {a.size} values are not finite and >= 0 (the "
                             f"first: {float(a[bad][0])!r}): leave out readings without a return")


def fit_beam(z, zs, zmax, *, init=None, max_iter=1000, tol=1e-10) -> FitResult:
    """EM for (z_hit, z_short, z_max, z_rand, sigma_hit, lambda_short) from readings z with expectations z*.

    z, zs: (M,) readings and expected ranges (m); zmax: scalar or (M,).
    Readings with z* >= zmax should be left out by the caller (see the
    module docstring). Stops when the mean log-likelihood gains < tol.
    """
    z = np.asarray(z, dtype=np.float64)
    zs = np.asarray(zs, dtype=np.float64)
    zmax = np.broadcast_to(np.asarray(zmax, dtype=np.float64), z.shape)
    _check_readings(z=z, zs=zs, zmax=zmax)
    if z.size < 10:
        raise DataError(f"calibrate sensor: only {z.size} usable readings (need at least 10)")
    p = dict(z_hit=0.7, z_short=0.1, z_max=0.1, z_rand=0.1, sigma_hit=0.2, lambda_short=0.5)
    if init:
        p.update(init)
    w = np.array([p["z_hit"], p["z_short"], p["z_max"], p["z_rand"]], dtype=np.float64)
    sigma, lam = float(p["sigma_hit"]), float(p["lambda_short"])
    prev = -np.inf
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        dens = beam_component_densities(z, zs, zmax, sigma, lam)
        joint = w[:, None] * dens
        tot = joint.sum(axis=0)
        ll = float(np.mean(np.log(tot)))
        resp = joint / tot
        w = resp.mean(axis=1)
        rh = resp[0]
        if rh.sum() > 0:
            sigma = max(math.sqrt(float(np.dot(rh, (z - zs) ** 2)) / float(rh.sum())), _SIGMA_MIN)
        lam = _fit_lambda(resp[1], z, zs, lam)
        if abs(ll - prev) < tol:
            converged = True
            break
        prev = ll
    params = dict(z_hit=w[0], z_short=w[1], z_max=w[2], z_rand=w[3], sigma_hit=sigma, lambda_short=lam)
    return FitResult("beam", {k: float(v) for k, v in params.items()}, int(z.size), ll, it, converged)


def sample_beam(rng, zs, zmax, params):
    """One reading per expected range in zs (M,), drawn from the beam mixture (for tests and synthetic checks).

    Components by ``rng.choice``; hit and short by inverse CDF of the truncated normal / exponential.
    """
    zs = np.asarray(zs, dtype=np.float64).ravel()
    m = zs.size
    w = np.array([params["z_hit"], params["z_short"], params["z_max"], params["z_rand"]], dtype=np.float64)
    comp = rng.choice(4, size=m, p=w / w.sum())
    z = np.empty(m)
    sigma, lam = params["sigma_hit"], params["lambda_short"]
    # hit: truncated normal on [0, zmax] by inverse CDF
    from scipy.special import ndtr, ndtri

    a, b = ndtr(-zs / sigma), ndtr((zmax - zs) / sigma)
    u = rng.random(m)
    hit = zs + sigma * ndtri(a + u * (b - a))
    # short: truncated exponential on [0, zs] by inverse CDF
    v = rng.random(m)
    short = -np.log1p(v * np.expm1(-lam * zs)) / lam
    rand = rng.random(m) * zmax
    z[:] = np.select([comp == 0, comp == 1, comp == 2], [np.clip(hit, 0, zmax), short, np.full(m, zmax)], rand)
    return z


# ----------------------------------------------------------------------------- likelihood field


def fit_likelihood_field(d, dmax, *, init=None, max_iter=1000, tol=1e-10) -> tuple[float, float, float, int, float, bool]:
    """EM for q(d) = w_hit * truncated half-normal(d; sigma, [0, dmax]) + w_rand / dmax.

    The M-step's sigma maximises sum_i r_i log(truncated half-normal(d_i; sigma)), which depends on the data through
    R = sum r_i and S = sum r_i d_i^2 only: -R log sigma - S / (2 sigma^2) - R log erf(dmax / (sigma sqrt 2)), a
    bounded scalar search. The untruncated sqrt(S / R) is that maximum only when sigma << dmax; at sigma = dmax / 2
    it came out 0.72 for a true 1.0 (and w_hit 0.59 for 0.9).

    Returns (w_hit, w_rand, sigma, iterations, mean log-likelihood, converged).
    """
    d = np.asarray(d, dtype=np.float64)
    _check_readings(d=d)
    d = np.minimum(d, dmax)
    if d.size < 10:
        raise DataError(f"calibrate sensor: only {d.size} usable readings (need at least 10)")
    p = dict(w_hit=0.8, sigma=0.2)
    if init:
        p.update(init)
    w_hit, sigma = float(p["w_hit"]), float(p["sigma"])
    prev, ll, converged, it = -np.inf, -np.inf, False, 0
    for it in range(1, max_iter + 1):
        c = float(erf(dmax / (sigma * math.sqrt(2.0))))
        hit = 2.0 * np.exp(-0.5 * (d / sigma) ** 2) / (math.sqrt(2 * math.pi) * sigma) / c
        jh = w_hit * hit
        jr = (1.0 - w_hit) / dmax
        tot = jh + jr
        ll = float(np.mean(np.log(tot)))
        r = jh / tot
        w_hit = float(r.mean())
        if r.sum() > 0:
            sigma = _truncated_sigma(float(r.sum()), float(np.dot(r, d * d)), dmax)
        if abs(ll - prev) < tol:
            converged = True
            break
        prev = ll
    return w_hit, 1.0 - w_hit, sigma, it, ll, converged


def _truncated_sigma(rsum: float, sq: float, dmax: float) -> float:
    """The sigma maximising -R log sigma - S / (2 sigma^2) - R log erf(dmax / (sigma sqrt 2)) (``fit_likelihood_field``'s
    M-step), at least _SIGMA_MIN; up to 100 dmax (the truncated half-normal is then uniform over [0, dmax])."""
    from scipy.optimize import minimize_scalar

    plain = max(math.sqrt(sq / rsum), _SIGMA_MIN)
    if plain < 0.2 * dmax:  # erf(5 / sqrt 2) = 1 - 6e-7: the truncation moves sigma by less than 1e-6 of it
        return plain

    def neg(sigma: float) -> float:
        return rsum * math.log(sigma) + sq / (2.0 * sigma * sigma) + rsum * math.log(erf(dmax / (sigma * math.sqrt(2.0))))

    res = minimize_scalar(neg, bounds=(_SIGMA_MIN, 100.0 * dmax), method="bounded", options={"xatol": 1e-9 * dmax})
    return float(res.x) if neg(float(res.x)) <= neg(plain) else plain


def lf_config_weights(w_hit, w_rand, sigma, dmax, range_max):
    """(z_hit, z_rand) summing to 1 whose filter score z_hit N(d;0,sigma^2) + z_rand/range_max is proportional to q(d)."""
    c = float(erf(dmax / (sigma * math.sqrt(2.0))))
    a = 2.0 * w_hit / c
    b = w_rand * range_max / dmax
    return a / (a + b), b / (a + b)


# ----------------------------------------------------------------------------- data from a log


def collect(cfg, *, model: str):
    """Readings with their expectation from the log's scans at reference poses.

    Returns (values, expected, zmax, scans): for the beam model the readings
    z (no-return as zmax), z* and zmax per reading (beams with z* >= zmax
    left out); for the likelihood field the clipped distances d (and None).
    """
    from mcl.datasets.carmen import read_carmen
    from mcl.kernels.raycast import cast_rays
    from mcl.maps import load_map
    from mcl.runner import Truth, _choose_scans
    from mcl.sensors import field_distance
    from mcl.trajectory import read_tum

    from mcl.calibrate_motion import DENSE_REFERENCE, bag_message
    from mcl.errors import ConfigError

    if cfg.log is None and cfg.bag is not None:
        raise DataError(bag_message(cfg.bag))
    for key in ("map", "log", "truth"):
        if getattr(cfg, key) is None:
            raise ConfigError(f"{key}: calibrate sensor needs a {key} (set it in the config or pass --{key})")
    s = cfg.sensor
    grid = load_map(cfg.map)
    log = read_carmen(cfg.log)
    truth = Truth(*read_tum(cfg.truth))
    scans = _choose_scans(log, cfg.laser)
    ox, oy, res = float(grid.origin[0]), float(grid.origin[1]), float(grid.resolution)
    rays_x, rays_y, rays_a, zs_list, zmax_list, used = [], [], [], [], [], 0
    scan_t = np.unique([sc.t for sc in scans])
    scan_dt = float(np.median(np.diff(scan_t))) if scan_t.size > 2 else 0.0
    # a reference denser than the scans (motion capture on its own clock): interpolated at each scan; its stamps
    # never met the scans' within 1 ms and it was refused
    dense = 0.0 < truth.spacing <= DENSE_REFERENCE * scan_dt
    if dense:
        warnings.warn(f"{cfg.truth}: its poses are {truth.spacing:.3g} s apart, denser than the scans of {cfg.log}: "
                      "taken at each scan, interpolated", MclWarning, stacklevel=2)
    for scan in scans:
        ref = truth.near(scan.t) if dense else truth.at(scan.t)
        if ref is None:
            continue
        used += 1
        lp = s.laser_pose if s.laser_pose is not None else (scan.laser_offset if scan.laser_offset is not None else (0, 0, 0))
        lx, ly, lth = (float(v) for v in lp)
        c, sn = math.cos(ref[2]), math.sin(ref[2])
        x, y = ref[0] + c * lx - sn * ly, ref[1] + sn * lx + c * ly
        r = np.asarray(scan.ranges, dtype=np.float64)
        a = np.asarray(scan.angles, dtype=np.float64)
        zmax = float(s.range_max)
        if scan.max_range is not None and 0 < float(scan.max_range) < zmax:
            zmax = float(scan.max_range)
        with np.errstate(invalid="ignore"):
            keep = ~np.isnan(r) & (r > float(s.range_min))
        r, a = np.minimum(r[keep], zmax), a[keep]
        rays_x.append(np.full(r.size, x))
        rays_y.append(np.full(r.size, y))
        rays_a.append(ref[2] + lth + a)
        zs_list.append(r)
        zmax_list.append(np.full(r.size, zmax))
    if used == 0:
        raise DataError(f"{cfg.truth}: no reference pose matches a scan time of {cfg.log} (within 1 ms)")
    if dense:  # the scans inside the reference's span, each of which found a pose unless in a gap of it
        span = int(np.count_nonzero((scan_t >= truth.t[0]) & (scan_t <= truth.t[-1])))
    else:
        span = int(np.count_nonzero((truth.t >= scans[0].t - 1e-3) & (truth.t <= scans[-1].t + 1e-3))) if scans else 0
    if used < 0.5 * span:  # a truth on another clock that overlaps the log's: a few stamps match by chance
        raise DataError(f"{cfg.truth}: only {used} of its {span} reference poses inside the scans' time span match a "
                        f"scan time of {cfg.log} (within 1 ms): is it this log's truth?")
    _check_lag(log, scans, truth, cfg.truth)
    X, Y, A = (np.concatenate(v) for v in (rays_x, rays_y, rays_a))
    z, zmax = np.concatenate(zs_list), np.concatenate(zmax_list)
    if model == "beam":
        # one "pose" per ray, heading = the ray's world angle, one beam at 0
        zcast = np.empty((z.size, 1))
        cast_rays(np.ascontiguousarray(np.stack([X, Y, A])), np.zeros(1), np.ascontiguousarray(grid.occupied),
                  ox, oy, res, float(s.range_max), zcast)
        zstar = np.minimum(zcast[:, 0], zmax)
        ok = zstar < zmax
        return z[ok], zstar[ok], zmax[ok], used
    # likelihood field: endpoints of the returns, distance field at their cells
    ret = z < zmax
    ex, ey = X[ret] + z[ret] * np.cos(A[ret]), Y[ret] + z[ret] * np.sin(A[ret])
    ix = np.floor((ex - ox) / res).astype(np.int64)
    iy = np.floor((ey - oy) / res).astype(np.int64)
    dmax = float(s.likelihood_field.likelihood_max_dist)
    inside = (ix >= 0) & (ix < grid.width) & (iy >= 0) & (iy < grid.height)
    d = np.full(ex.size, dmax)
    d[inside] = field_distance(grid, s)[iy[inside], ix[inside]]  # the d the model scores (interior: zero or depth)
    return np.minimum(d, dmax), None, None, used


def _check_lag(log, scans, truth, truth_path) -> None:
    """Warn when the reference matches the log's odometry better shifted by a scan period or two
    (``calibrate_motion.check_lag``): a truth a frame late fitted sigma_hit 2x too large without a word."""
    from mcl.calibrate_motion import check_lag, log_odometry

    odo = log_odometry(log)
    scan_t = np.unique([s.t for s in scans])
    if odo.shape[0] < 2 or scan_t.size < 3:
        return
    keep = (truth.t >= odo[0, 0]) & (truth.t <= odo[-1, 0])
    if np.count_nonzero(keep) > 10:
        check_lag(odo, truth.t[keep], truth.poses[:, keep], float(np.median(np.diff(scan_t))), truth_path,
                  fitted="The sensor model is")


def calibrate_sensor(cfg, model: str | None = None) -> FitResult:
    """Fit the sensor model named by ``model`` (default ``cfg.sensor.model``) on cfg's map, log and truth."""
    model = model or cfg.sensor.model
    s = cfg.sensor
    if model == "beam":
        z, zs, zmax, used = collect(cfg, model="beam")
        fit = fit_beam(z, zs, zmax)
        fit.scans = used
        near = float(np.mean(np.abs(z - zs) < NEAR))
    elif model == "likelihood_field":
        d, _, _, used = collect(cfg, model="likelihood_field")
        dmax = float(s.likelihood_field.likelihood_max_dist)
        w_hit, w_rand, sigma, it, ll, conv = fit_likelihood_field(d, dmax)
        z_hit, z_rand = lf_config_weights(w_hit, w_rand, sigma, dmax, float(s.range_max))
        fit = FitResult("likelihood_field", dict(z_hit=z_hit, z_rand=z_rand, sigma_hit=sigma), int(d.size), ll, it,
                        conv, extra=dict(w_hit=w_hit, w_rand=w_rand, likelihood_max_dist=dmax,
                                         range_max=float(s.range_max)), scans=used)
        near = float(np.mean(d < NEAR))
    else:
        raise ValueError(f"calibrate sensor: unknown model {model!r}")
    _check_fit(fit, near, cfg)
    return fit


def _check_fit(fit: FitResult, near: float, cfg) -> None:
    """Warn (``MclWarning``) when most readings do not fit the map at the reference poses (share ``near`` within
    ``NEAR``), and flag (``fit.bounds``, a warning but for lambda_short at its lower bound) a parameter EM left on its bound."""
    sigma = fit.params["sigma_hit"]
    if near < NEAR_MIN or sigma > SIGMA_HIT_MAX:
        warnings.warn(f"calibrate sensor: the readings do not fit the map at the reference poses (only {near:.0%} "
                      f"within {NEAR:g} m of the map's prediction, sigma_hit {sigma:.3g} m): is {cfg.map} the map of "
                      f"{cfg.log}, and {cfg.truth} in its frame?", MclWarning, stacklevel=3)
    if sigma <= _SIGMA_MIN:
        fit.bounds["sigma_hit"] = "lower"
    dmax = fit.extra.get("likelihood_max_dist") if fit.extra else None
    if dmax is not None and sigma >= 100.0 * dmax * (1.0 - 1e-6):  # _truncated_sigma's upper bound: a flat field
        fit.bounds["sigma_hit"] = "upper"
    lam = fit.params.get("lambda_short")
    if lam is not None and lam <= _LAMBDA_MIN:
        fit.bounds["lambda_short"] = "lower"  # g(0+) = sum r (z*/2 - z) <= 0: short readings past z*/2 on average
    elif lam is not None and lam >= _LAMBDA_MAX:
        fit.bounds["lambda_short"] = "upper"
    for k, side in fit.bounds.items():
        if k == "lambda_short" and side == "lower":
            # the short readings lie past z*/2 on average: the exponential flattens to a uniform on [0, z*], a
            # result (every real log here gives it), not a failed fit: the YAML's comment says so, no warning
            continue
        warnings.warn(f"calibrate sensor: {k} landed on its {side} bound {fit.params[k]:g}", MclWarning,
                      stacklevel=3)


def format_yaml(fit: FitResult) -> str:
    """The fit as a commented ``sensor:`` block ready to paste into a config."""
    lines = [f"# mcl calibrate sensor: {fit.model} model, EM (Prob. Rob. Table 6.2) on {fit.n} readings from "
             f"{fit.scans} scans at reference poses; mean log-likelihood {fit.loglik:.4f} per reading, "
             f"{fit.iterations} iterations{'' if fit.converged else ' (NOT converged)'}"]
    if fit.model == "likelihood_field":
        e = fit.extra
        lines += [f"# fitted p(d) = {e['w_hit']:.4f} * half-normal(d; sigma_hit) + {e['w_rand']:.4f} * uniform[0, "
                  f"{e['likelihood_max_dist']:g}]; z_hit/z_rand give the filter's form z_hit*N(d;0,sigma^2) + "
                  f"z_rand/range_max (range_max {e['range_max']:g}) the same shape"]
    lines.append("sensor:")
    lines.append(f"  model: {fit.model}")
    lines.append(f"  {fit.model}:")  # each model has its own block (sensor.likelihood_field, sensor.beam)
    for k, v in fit.params.items():
        lines.append(f"    {k}: {v:.6g}" + (f"  # on its {fit.bounds[k]} bound" if k in fit.bounds else ""))
    return "\n".join(lines) + "\n"


def add_arguments(p) -> None:
    """Options of ``mcl calibrate sensor``."""
    p.add_argument("--map", help="ROS map_server YAML of the occupancy grid")
    p.add_argument("--log", help="CARMEN log (.clf, plain or gzip)")
    p.add_argument("--truth", help="reference trajectory (TUM) whose timestamps match the scans")
    p.add_argument("--model", choices=["beam", "likelihood_field"], help="model to fit (default: the config's sensor.model)")
    p.add_argument("--config", help="YAML config for range_max, range_min, likelihood_field.likelihood_max_dist, laser, laser_pose, "
                   "and map/log/truth if not given")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a config key (repeatable)")


def run_from_args(args) -> int:
    """``mcl calibrate sensor``: print the fitted ``sensor:`` block on stdout."""
    from pathlib import Path

    from mcl.config import load_config

    from mcl.calibrate_motion import bag_message
    from mcl.datasets.rosbag import is_bag
    from mcl.errors import ConfigError

    if args.log is not None and is_bag(args.log):
        raise DataError(bag_message(args.log))
    overrides = [f"{k}={Path(v).resolve()}" for k, v in (("map", args.map), ("log", args.log), ("truth", args.truth))
                 if v is not None]
    try:
        cfg = load_config(args.config, overrides + list(args.set))
    except ConfigError as e:  # the config's log is a bag: the run's advice (give it as bag) does not apply here
        if "is a ROS bag" not in str(e):
            raise
        raise DataError(bag_message(str(e).split(" is a ROS bag")[0].split("log: ")[-1])) from None
    fit = calibrate_sensor(cfg, args.model)
    sys.stdout.write(format_yaml(fit))
    return 0
