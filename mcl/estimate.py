"""Pose estimate from a weighted particle set.

The estimate is the weighted mean of x and y and the circular mean of theta,
``atan2(sum w sin(theta), sum w cos(theta))``; the covariance uses angle
differences wrapped to (-pi, pi] around that mean.
"""

from __future__ import annotations

import math

import numpy as np

from mcl.kernels.moments import pose_moments


def wrap_angle(a):
    """Normalise angles to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), 2.0 * np.pi)


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ⊕ b for planar poses (x, y, theta)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], float(wrap_angle(a[2] + b[2]))])


def inverse(a: np.ndarray) -> np.ndarray:
    """⊖a: the pose b with a ⊕ b = 0."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2]])


def weighted_mean_pose(particles: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted mean (x, y) and circular mean theta of a (3, N) particle set with weights summing to 1.

    numpy's own loop (einsum), not np.dot: above 10,000 weights OpenBLAS splits a dot product over its threads and
    the sum's last digits change with OPENBLAS_NUM_THREADS (as ``mcl.resampling.effective_sample_size``)."""
    x = float(np.einsum("n,n->", w, particles[0]))
    y = float(np.einsum("n,n->", w, particles[1]))
    th = particles[2]
    theta = float(np.arctan2(np.einsum("n,n->", w, np.sin(th)), np.einsum("n,n->", w, np.cos(th))))
    return np.array([x, y, theta])


def weighted_covariance(particles: np.ndarray, w: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """3x3 weighted covariance around `mean`, theta differences wrapped."""
    d = np.empty_like(particles)
    d[0] = particles[0] - mean[0]
    d[1] = particles[1] - mean[1]
    d[2] = wrap_angle(particles[2] - mean[2])
    return (d * w) @ d.T


def estimate(particles: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mean (3,), covariance (3, 3)) of the weighted particle set (``weighted_mean_pose`` and
    ``weighted_covariance`` in one numba pass, ``mcl.kernels.moments``)."""
    return moments(particles, w)


def moments(particles: np.ndarray, w: np.ndarray, labels: np.ndarray | None = None, which: int = -1,
            scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(mean (3,), covariance (3, 3)) of the particles with weights ``scale * w``: all of them, or with ``labels``
    those of cluster ``which`` only (its weights renormalised by ``scale``)."""
    p = np.ascontiguousarray(particles, dtype=np.float64)
    wt = np.ascontiguousarray(w, dtype=np.float64)
    mean = np.empty(3)
    cov = np.empty((3, 3))
    pose_moments(p, wt, _NO_LABELS if labels is None else labels, int(which), float(scale), mean, cov)
    return mean, cov


_NO_LABELS = np.zeros(0, dtype=np.int64)
