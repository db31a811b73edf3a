"""Zero-mean noise of the motion models: densities and samplers (Prob. Rob. Tables 5.2, 5.4).

**Convention: every function here takes the standard deviation ``sigma``**
(not the variance). The seeds disagree with each other, so this module picks
one convention and documents what each seed's formula means in it:

* ``prob_normal(a, b)``: the book (Table 5.2) and seed 000 pass the variance
  b and return ``exp(-a^2 / 2b) / sqrt(2 pi b)``; the Spanish slides (seed 002)
  pass the standard deviation but print ``1 / (sqrt(2 pi) b^2)`` as the
  normaliser, a typo (it must be ``1 / (sqrt(2 pi) b)``). Here:
  ``prob_normal(a, sigma) = exp(-a^2 / 2 sigma^2) / (sqrt(2 pi) sigma)``.
* ``prob_triangular(a, sigma)``: a triangle on [-sqrt(6) sigma, sqrt(6) sigma]
  (that half-width gives variance sigma^2), height 1 / (sqrt(6) sigma):
  ``max(0, 1/(sqrt(6) sigma) - |a| / (6 sigma^2))``, seed 002's formula.
  Seed 000 prints ``(sqrt(6) b - |a|) / (6 b)``, which is the book's
  variance form with the square root over ``6b`` lost in transcription.
* ``sample_normal_twelve``: seed 002 (and the book) return
  ``1/2 * sum_12 rand(-b, b)``: each term has variance b^2/3, so the sum has
  variance 12 b^2/3 / 4 = b^2, std b: correct for b = sigma. Seed 000 writes
  ``b/6 * sum_12 rand(-1, 1)``, whose variance is b^2/36 * 12/3 = b^2/9, i.e.
  std b/3: three times too narrow. Here: ``sigma/2 * sum_12 rand(-1, 1)``.
  The sum of twelve uniforms is not exactly normal: it is the Irwin-Hall
  distribution (support +-6 sigma, excess kurtosis -0.1), whose exact density
  is ``prob_normal_twelve``.
* ``sample_triangular``: seed 002 returns ``sqrt(6)/2 * (rand(-b, b) + rand(-b, b))``:
  the sum of two uniforms on [-b, b] is a triangle on [-2b, 2b] with variance
  2b^2/3; times sqrt(6)/2 it has variance b^2 and support sqrt(6) b: correct
  for b = sigma. Seed 000 returns ``b * rand(-1, 1) * rand(-1, 1)``: a
  *product* of uniforms is not triangular at all (its density is
  -log|x/b| / 2b, peaked at 0) and its std is b/3.
* ``sample_distribution(f, b, rng, n)``: the seeds' rejection sampler
  (uniform x on [-b, b], uniform y on [0, max f], keep x when y <= f(x)),
  vectorised: each round draws a batch and keeps the accepted ones.

``motion.noise`` in the config names the noise of the motion models:
``normal`` (NumPy's exact normal, the default), ``normal_twelve`` (sum of
twelve uniforms) or ``triangular``. The samplers draw *standard* noise
(``standard_noise``), which the models scale by their sigmas; the closed forms
use the matching density (``log_density``).
"""

from __future__ import annotations

import functools
import math
from typing import Callable

import numpy as np

NOISE_KINDS = ("normal", "normal_twelve", "triangular")

_SQRT6 = math.sqrt(6.0)
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


def _check_kind(kind: str) -> None:
    if kind not in NOISE_KINDS:
        raise ValueError(f"motion.noise: unknown value {kind!r} (expected one of {', '.join(NOISE_KINDS)})")


# --------------------------------------------------------------------------- densities


def _positive(sigma) -> np.ndarray:
    """sigma as float64, ValueError where it is not > 0: a density of std 0 was NaN everywhere, and one of std -1 a
    negative density (callers that may reach 0 floor it first, as the motion densities do with SIGMA_MIN)."""
    sigma = np.asarray(sigma, dtype=np.float64)
    if np.any(sigma <= 0.0):
        raise ValueError(f"sigma must be > 0, got {float(np.min(sigma))!r}")
    return sigma


def _non_negative(sigma) -> np.ndarray:
    """sigma as float64 for a sampler, ValueError where it is negative (std 0 samples 0)."""
    sigma = np.asarray(sigma, dtype=np.float64)
    if np.any(sigma < 0.0):
        raise ValueError(f"sigma must be >= 0, got {float(np.min(sigma))!r}")
    return sigma


def prob_normal(a, sigma):
    """Density at a of the zero-mean normal with standard deviation sigma (> 0)."""
    a = np.asarray(a, dtype=np.float64)
    sigma = _positive(sigma)
    return np.exp(-0.5 * (a / sigma) ** 2) / (math.sqrt(2.0 * math.pi) * sigma)


def log_prob_normal(a, sigma):
    """log prob_normal(a, sigma), without underflow in the tails."""
    a = np.asarray(a, dtype=np.float64)
    sigma = _positive(sigma)
    return -0.5 * (a / sigma) ** 2 - np.log(sigma) - _LOG_SQRT_2PI


def prob_triangular(a, sigma):
    """Density at a of the zero-mean triangular distribution with std sigma: support |a| <= sqrt(6) sigma."""
    a = np.asarray(a, dtype=np.float64)
    sigma = _positive(sigma)
    return np.maximum(0.0, 1.0 / (_SQRT6 * sigma) - np.abs(a) / (6.0 * sigma * sigma))


def log_prob_triangular(a, sigma):
    """log prob_triangular(a, sigma); -inf outside the support."""
    with np.errstate(divide="ignore"):
        return np.log(prob_triangular(a, sigma))


@functools.cache
def _irwin_hall(n: int = 12):
    """The density of the sum of n uniforms on [0, 1] (Irwin-Hall) and its CDF, as scipy B-splines: the density is
    the cardinal B-spline of degree n - 1 on the knots 0..n (nan outside them). Twice as fast as the alternating
    sum of powers, and free of its cancellation; scipy.stats.irwinhall takes 100 times longer."""
    from scipy.interpolate import BSpline

    pdf = BSpline.basis_element(np.arange(n + 1.0), extrapolate=False)
    return pdf, pdf.antiderivative()


def _irwin_hall_cdf(x, n: int = 12):
    """CDF of the sum of n uniforms on [0, 1] (Irwin-Hall), x an array."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, float(n))
    return np.clip(_irwin_hall(n)[1](x), 0.0, 1.0)


def _irwin_hall_pdf(x, n: int = 12):
    """Density of the sum of n uniforms on [0, 1] (Irwin-Hall), x an array; zero outside [0, n]."""
    out = _irwin_hall(n)[0](np.asarray(x, dtype=np.float64))
    return np.where(np.isnan(out), 0.0, np.maximum(out, 0.0))


def prob_normal_twelve(a, sigma):
    """Exact density of ``sample_normal_twelve(sigma)``: Irwin-Hall(12), centred, scaled to std sigma.

    sigma/2 * sum_12 U(-1, 1) = sigma * (S - 6) with S ~ Irwin-Hall(12), so the
    density is f_S(a / sigma + 6) / sigma; zero for |a| > 6 sigma.
    """
    a = np.asarray(a, dtype=np.float64)
    sigma = _positive(sigma)
    return _irwin_hall_pdf(a / sigma + 6.0) / sigma


def cdf(kind: str, a, sigma):
    """CDF of the zero-mean noise ``kind`` with std sigma (for binning tests and plots)."""
    _check_kind(kind)
    z = np.asarray(a, dtype=np.float64) / _positive(sigma)
    if kind == "normal":
        from scipy.special import ndtr

        return ndtr(z)
    if kind == "normal_twelve":
        return _irwin_hall_cdf(z + 6.0)
    c = _SQRT6  # triangular on [-c, c] in standard units
    zc = np.clip(z, -c, c)
    return np.where(zc <= 0, (c + zc) ** 2 / (2 * c * c), 1.0 - (c - zc) ** 2 / (2 * c * c))


def density(kind: str, a, sigma):
    """Density of the zero-mean noise ``kind`` (normal, normal_twelve, triangular) with std sigma."""
    _check_kind(kind)
    if kind == "normal":
        return prob_normal(a, sigma)
    if kind == "normal_twelve":
        return prob_normal_twelve(a, sigma)
    return prob_triangular(a, sigma)


def log_density(kind: str, a, sigma):
    """log density(kind, a, sigma); -inf where the density is zero."""
    _check_kind(kind)
    if kind == "normal":
        return log_prob_normal(a, sigma)
    with np.errstate(divide="ignore"):
        return np.log(density(kind, a, sigma))


# --------------------------------------------------------------------------- samplers


def sample_normal_exact(sigma, rng: np.random.Generator, size=None):
    """Normal noise with std sigma from NumPy's exact sampler (the default)."""
    return _non_negative(sigma) * rng.standard_normal(size)


def sample_normal_twelve(sigma, rng: np.random.Generator, size=None):
    """sigma/2 * sum of 12 rand(-1, 1): approximately normal with std exactly sigma (seed 002's form)."""
    z = np.zeros(size) if size is not None else 0.0
    for _ in range(12):
        z = z + rng.uniform(-1.0, 1.0, size)
    return _non_negative(sigma) * 0.5 * z


def sample_triangular(sigma, rng: np.random.Generator, size=None):
    """sqrt(6)/2 * (rand(-sigma, sigma) + rand(-sigma, sigma)): triangular with std sigma (seed 002)."""
    s = _non_negative(sigma)
    return 0.5 * _SQRT6 * (s * rng.uniform(-1.0, 1.0, size) + s * rng.uniform(-1.0, 1.0, size))


def standard_noise(kind: str, rng: np.random.Generator, shape=None, out: np.ndarray | None = None) -> np.ndarray:
    """Unit-std zero-mean noise of ``kind``, into ``out`` if given (float64 C-contiguous).

    ``normal`` draws ``rng.standard_normal`` directly into ``out``, so the
    default keeps the random stream it always had.
    """
    _check_kind(kind)
    if out is None:
        out = np.empty(shape, dtype=np.float64)
    if kind == "normal":
        rng.standard_normal(out=out)
    elif kind == "normal_twelve":
        out[...] = 0.0
        buf = np.empty(out.shape)
        for _ in range(12):
            rng.random(out=buf)
            out += buf
        out -= 6.0  # sum of 12 U(0,1) - 6 = 1/2 * sum of 12 U(-1,1): std 1
    else:
        buf = np.empty(out.shape)
        rng.random(out=out)
        rng.random(out=buf)
        out += buf
        out -= 1.0  # (U1 + U2 - 1) is triangular on [-1, 1] with std 1/sqrt(6)
        out *= _SQRT6
    return out


def sample_distribution(f: Callable[[np.ndarray], np.ndarray], b: float, rng: np.random.Generator, n: int,
                        f_max: float | None = None, batch: int | None = None) -> np.ndarray:
    """n samples of the density proportional to f on [-b, b] by rejection (seed 002, ``sample_distribution``).

    f is vectorised (array in, array out, values >= 0). ``f_max`` is the
    seeds' max{f(x) | x in [-b, b]}; when None it is taken from f on a
    10,001-point grid times 1.01 (a margin for peaks between grid points;
    an f_max below the true maximum would clip the density's peak). Each round
    draws a batch of (x, y) pairs and keeps x where y <= f(x); no Python loop
    over samples. The expected acceptance rate is (integral of f) / (2 b f_max).
    """
    if not (b > 0 and math.isfinite(b)):
        raise ValueError(f"sample_distribution: b must be positive and finite, got {b}")
    n = int(n)
    if f_max is None:
        grid = np.linspace(-b, b, 10_001)
        f_max = 1.01 * float(np.max(f(grid)))
    if not (f_max > 0 and math.isfinite(f_max)):
        raise ValueError(f"sample_distribution: max f on [-b, b] must be positive and finite, got {f_max}")
    out = np.empty(n)
    filled = 0
    batch = int(batch) if batch else max(1024, 2 * n)
    while filled < n:
        x = rng.uniform(-b, b, batch)
        y = rng.uniform(0.0, f_max, batch)
        keep = x[y <= f(x)]
        take = min(keep.size, n - filled)
        out[filled:filled + take] = keep[:take]
        filled += take
    return out
