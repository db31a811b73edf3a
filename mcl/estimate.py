"""Pose estimate from a weighted particle set.

The estimate is the weighted mean of x and y and the circular mean of theta,
``atan2(sum w sin(theta), sum w cos(theta))``; the covariance uses angle
differences wrapped to (-pi, pi] around that mean.
"""

from __future__ import annotations

import numpy as np


def wrap_angle(a):
    """Normalise angles to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), 2.0 * np.pi)


def weighted_mean_pose(particles: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted mean (x, y) and circular mean theta of a (3, N) particle set with weights summing to 1."""
    x = float(np.dot(w, particles[0]))
    y = float(np.dot(w, particles[1]))
    th = particles[2]
    theta = float(np.arctan2(np.dot(w, np.sin(th)), np.dot(w, np.cos(th))))
    return np.array([x, y, theta])


def weighted_covariance(particles: np.ndarray, w: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """3x3 weighted covariance around `mean`, theta differences wrapped."""
    d = np.empty_like(particles)
    d[0] = particles[0] - mean[0]
    d[1] = particles[1] - mean[1]
    d[2] = wrap_angle(particles[2] - mean[2])
    return (d * w) @ d.T


def estimate(particles: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mean (3,), covariance (3, 3)) of the weighted particle set."""
    mean = weighted_mean_pose(particles, w)
    return mean, weighted_covariance(particles, w, mean)
