"""Landmark maps and the range-bearing landmark model with known correspondences.

A landmark map is a YAML file (``mcl simulate --landmarks K`` writes one)::

    landmarks:
      - {id: 1, x: 3.25, y: 7.80}
      - {id: 2, x: 10.05, y: 1.40, signature: 0.7}   # signature: optional number

``id`` is a unique integer >= 0 (the correspondence the detector reports),
``x``, ``y`` metres in the map frame. A ``signature`` is read and kept, not
scored: an observation (a LANDMARK line, a bag's landmarks) carries id,
range and bearing only, so Table 6.4's third factor prob(s - s_j, sigma_s^2)
has no measured signature to compare and is left out (a factor 1).

An observation ``z = <i, d, phi>`` is the landmark's id, its range (m) and its
bearing (rad, counter-clockwise from the robot's heading), all from the robot
centre. The model is Prob. Rob. Table 6.4, landmark_model_known_correspondence,
with the lecture's false-positive mixture (seed chapter 6, "Probabilistic
Model")::

    d_hat   = sqrt((m_x(i) - x)^2 + (m_y(i) - y)^2)
    phi_hat = atan2(m_y(i) - y, m_x(i) - x) - theta
    p_det   = N(d - d_hat; 0, sigma_range^2) * N(wrap(phi - phi_hat); 0, sigma_bearing^2)
    p(z | x, m) = z_det * p_det + z_fp * p_uniform,   p_uniform = 1 / (range_max * 2 pi)

``p_uniform`` is the density of a false positive spread uniformly over the
detector's measurement space ``[0, range_max] x [-pi, pi)``, so with
``z_det + z_fp = 1`` the mixture integrates to 1 over that space (up to the
Gaussian's tail below d = 0, which is not truncated). Observations are
treated as independent: log-likelihoods add. An id that is not in the map
has no p_det: it contributes only the constant ``z_fp * p_uniform``, which
does not change the weights, so it is dropped.

The sampler ``sample_poses_from_landmark`` is Prob. Rob. Table 6.5
(sample_landmark_model_known_correspondence): poses on the ring the
observation allows, used to seed global localization and for injections.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mcl.errors import DataError
from mcl.parallel import check_out
from mcl.yamlfile import finite_number, read_yaml

__all__ = [
    "LandmarkMap",
    "LandmarkModel",
    "load_landmarks",
    "save_landmarks",
    "landmark_log_likelihood_numpy",
    "sample_poses_from_landmark",
    "sample_observation",
]


@dataclass(frozen=True, eq=False)
class LandmarkMap:
    """Landmarks by id: ``ids`` (K,) int64, ``xy`` (2, K) float64, ``signatures`` (K,) float64 (NaN: none)."""

    ids: np.ndarray
    xy: np.ndarray
    signatures: np.ndarray
    path: str | None = None

    def __len__(self) -> int:
        return int(self.ids.size)

    def index_of(self, ids) -> np.ndarray:
        """Column of each id in ``xy`` (int64), -1 for ids not in the map."""
        ids = np.asarray(ids, dtype=np.int64).ravel()
        order = np.argsort(self.ids, kind="stable")
        sorted_ids = self.ids[order]
        pos = np.clip(np.searchsorted(sorted_ids, ids), 0, max(sorted_ids.size - 1, 0))
        if sorted_ids.size == 0:
            return np.full(ids.shape, -1, dtype=np.int64)
        found = sorted_ids[pos] == ids
        return np.where(found, order[pos], -1).astype(np.int64)


_ID_MAX = 2 ** 63 - 1  # ids are int64


def _num(v, where: str, *, integer: bool = False):
    if isinstance(v, str) and not integer:  # YAML 1.1 reads 1e6 (no dot) as a string; a config file's reader takes it
        try:
            v = float(v)
        except ValueError:
            pass
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise DataError(f"{where}: expected {'an integer' if integer else 'a number'}, got {v!r}"[:200])
    if integer:
        if isinstance(v, float) and not v.is_integer():
            raise DataError(f"{where}: expected an integer, got {v!r}")
        v = int(v)
        if v < 0:
            raise DataError(f"{where}: expected an integer >= 0, got {v}")
        if v > _ID_MAX:  # (an OverflowError traceback)
            raise DataError(f"{where}: expected an integer up to {_ID_MAX} (int64), got {v}"[:200])
        return v
    return finite_number(v, where, DataError)


def load_landmarks(path: str | os.PathLike) -> LandmarkMap:
    """Read a landmark map YAML; DataError naming the file and the key on any problem."""
    name = str(path)
    doc = read_yaml(path, DataError)
    if not isinstance(doc, dict) or "landmarks" not in doc:
        raise DataError(f"{name}: landmarks: missing (expected a mapping with a 'landmarks' list)")
    unknown = sorted(str(k) for k in doc if k != "landmarks")
    if unknown:
        raise DataError(f"{name}: {unknown[0]}: unknown key (expected only 'landmarks')")
    items = doc["landmarks"]
    if not isinstance(items, list):
        raise DataError(f"{name}: landmarks: expected a list of {{id, x, y}}, got {type(items).__name__}")
    ids, xs, ys, sig = [], [], [], []
    seen: dict[int, int] = {}
    for k, item in enumerate(items):
        where = f"{name}: landmarks[{k}]"
        if not isinstance(item, dict):
            raise DataError(f"{where}: expected a mapping {{id, x, y}}, got {item!r}"[:200])
        for key in ("id", "x", "y"):
            if key not in item:
                raise DataError(f"{where}.{key}: missing")
        extra = sorted(str(key) for key in item if key not in ("id", "x", "y", "signature"))
        if extra:
            raise DataError(f"{where}.{extra[0]}: unknown key (expected id, x, y, signature)")
        i = _num(item["id"], f"{where}.id", integer=True)
        if i in seen:
            raise DataError(f"{where}.id: duplicate id {i} (also landmarks[{seen[i]}])")
        seen[i] = k
        ids.append(i)
        xs.append(_num(item["x"], f"{where}.x"))
        ys.append(_num(item["y"], f"{where}.y"))
        s = item.get("signature")
        sig.append(float("nan") if s is None else _num(s, f"{where}.signature"))
    if not ids:
        raise DataError(f"{name}: landmarks: the list is empty")
    return LandmarkMap(
        np.array(ids, dtype=np.int64), np.array([xs, ys], dtype=np.float64), np.array(sig, dtype=np.float64), name
    )


def save_landmarks(path: str | os.PathLike, ids, xy, signatures=None) -> None:
    """Write a landmark map YAML (atomic), one flow mapping per landmark."""
    from mcl.trajectory import atomic_write_text

    ids = np.asarray(ids, dtype=np.int64).ravel()
    xy = np.asarray(xy, dtype=np.float64).reshape(2, -1)
    lines = ["# mcl landmark map: id (unique integer), x, y (m, map frame), optional signature\n", "landmarks:\n"]
    for k in range(ids.size):
        s = "" if signatures is None else f", signature: {float(signatures[k]):.6g}"
        lines.append(f"  - {{id: {int(ids[k])}, x: {xy[0, k]:.4f}, y: {xy[1, k]:.4f}{s}}}\n")
    atomic_write_text(Path(path), "".join(lines))


# ----------------------------------------------------------------------------- the model


def _wrap(a):
    return np.arctan2(np.sin(a), np.cos(a))


def landmark_log_likelihood_numpy(particles, mx, my, ranges, bearings, sigma_r, sigma_b, z_det, c_fp) -> np.ndarray:
    """NumPy version of the model (the kernel's oracle): (N,) sum over observations of
    log(z_det * p_det + c_fp), ``c_fp = z_fp * p_uniform``. ``mx, my`` are the observed
    landmarks' positions (one per observation, all known ids)."""
    p = np.asarray(particles, dtype=np.float64)
    out = np.zeros(p.shape[1])
    log_norm = -math.log(2.0 * math.pi * sigma_r * sigma_b)
    log_zdet = math.log(z_det) if z_det > 0 else -np.inf
    log_c = math.log(c_fp) if c_fp > 0 else -np.inf
    for j in range(len(ranges)):
        dx = mx[j] - p[0]
        dy = my[j] - p[1]
        er = ranges[j] - np.hypot(dx, dy)
        eb = _wrap(bearings[j] - (np.arctan2(dy, dx) - p[2]))
        log_det = log_norm - 0.5 * ((er / sigma_r) ** 2 + (eb / sigma_b) ** 2)
        out += np.logaddexp(log_zdet + log_det, log_c)
    return out


class LandmarkModel:
    """Prob. Rob. Table 6.4 with a false-positive mixture, over a :class:`LandmarkMap`.

    ``cfg`` is read duck-typed: sigma_range, sigma_bearing, z_det, z_fp, range_max.
    """

    def __init__(self, landmark_map: LandmarkMap, cfg):
        self.map = landmark_map
        self.cfg = cfg
        self.sigma_r = float(cfg.sigma_range)
        self.sigma_b = float(cfg.sigma_bearing)
        self.z_det = float(cfg.z_det)
        self.c_fp = float(cfg.z_fp) / (float(cfg.range_max) * 2.0 * math.pi)

    def prepare(self, obs) -> np.ndarray | None:
        """(4, J) rows m_x, m_y, range, bearing of the observations with known ids; None if none."""
        ids = np.asarray(obs.ids, dtype=np.int64)
        col = self.map.index_of(ids)
        keep = col >= 0
        if not np.any(keep):
            return None
        c = col[keep]
        return np.ascontiguousarray(
            np.vstack([self.map.xy[0, c], self.map.xy[1, c],
                       np.asarray(obs.ranges, dtype=np.float64)[keep],
                       np.asarray(obs.bearings, dtype=np.float64)[keep]])
        )

    def log_likelihood(self, particles, prepared, out=None) -> np.ndarray:
        """(N,) float64: sum over the observations of log(z_det p_det + z_fp p_uniform)."""
        from mcl.kernels.landmark import landmark_loglik

        p = np.ascontiguousarray(particles, dtype=np.float64)
        if p.ndim != 2 or p.shape[0] != 3:
            raise ValueError(f"particles: expected shape (3, N), got {p.shape}")
        if out is None:
            out = np.empty(p.shape[1])
        else:
            check_out(out, (p.shape[1],))
        if prepared is None:
            out[:] = 0.0
            return out
        landmark_loglik(p, prepared, self.sigma_r, self.sigma_b, self.z_det, self.c_fp, out)
        return out


# ----------------------------------------------------------------------------- samplers


def sample_observation(pose, m_xy, sigma_range, sigma_bearing, rng, size=None):
    """Noisy (range, bearing) of landmarks at ``m_xy`` (2, K) seen from ``pose`` (x, y, theta).

    The generative side of the model's p_det: Gaussian noise on the exact range
    and bearing; the bearing wrapped to (-pi, pi] (arctan2's; only its square
    enters the model). ``size`` adds a leading axis of independent draws.
    Returns (ranges, bearings).
    """
    m = np.asarray(m_xy, dtype=np.float64).reshape(2, -1)
    x, y, th = (float(v) for v in pose)
    d = np.hypot(m[0] - x, m[1] - y)
    phi = np.arctan2(m[1] - y, m[0] - x) - th
    shape = (m.shape[1],) if size is None else (int(size), m.shape[1])
    r = d + sigma_range * rng.standard_normal(shape)
    b = _wrap(phi + sigma_bearing * rng.standard_normal(shape))
    return r, b


def sample_poses_from_landmark(obs, landmark_map: LandmarkMap, n: int, rng, cfg) -> np.ndarray:
    """(3, n) poses drawn from p(x | z, m) for one landmark observation (Prob. Rob. Table 6.5).

    ``obs`` is one observation ``(id, range, bearing)`` or a record with
    ``ids``, ``ranges``, ``bearings`` (a ``Landmarks`` line of the log): then
    the n poses are shared out evenly over its observations with known ids
    (a false positive then misleads only its share). For each pose::

        gamma ~ U[-pi, pi);  d' = d + N(0, sigma_range^2);  phi' = phi + N(0, sigma_bearing^2)
        x = m_x + d' cos(gamma);  y = m_y + d' sin(gamma);  theta = gamma - pi - phi'

    ``cfg`` gives sigma_range and sigma_bearing (0: exact rings). Raises
    ValueError when no observation has a known id.
    """
    if hasattr(obs, "ids"):
        ids = np.asarray(obs.ids, dtype=np.int64).ravel()
        ranges = np.asarray(obs.ranges, dtype=np.float64).ravel()
        bearings = np.asarray(obs.bearings, dtype=np.float64).ravel()
    else:
        i, d, phi = obs
        ids = np.array([int(i)], dtype=np.int64)
        ranges = np.array([float(d)])
        bearings = np.array([float(phi)])
    col = landmark_map.index_of(ids)
    keep = np.flatnonzero(col >= 0)
    if keep.size == 0:
        raise ValueError(f"no observation with an id in the landmark map (ids {ids.tolist()})")
    n = int(n)
    which = keep[np.arange(n) % keep.size]  # observation of each pose, evenly shared
    c = col[which]
    gamma = rng.uniform(-math.pi, math.pi, n)
    d = ranges[which] + float(cfg.sigma_range) * rng.standard_normal(n)
    phi = bearings[which] + float(cfg.sigma_bearing) * rng.standard_normal(n)
    out = np.empty((3, n))
    out[0] = landmark_map.xy[0, c] + d * np.cos(gamma)
    out[1] = landmark_map.xy[1, c] + d * np.sin(gamma)
    out[2] = _wrap(gamma - math.pi - phi)
    return out
