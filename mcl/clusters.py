"""Clusters of a particle cloud and the estimate of the heaviest one.

When the cloud is multi-modal (global localization, symmetric corridors, after
a kidnapping) the weighted mean of the whole set lies between the modes, often
inside a wall. Like AMCL (``pf_cluster_stats``), the filter reports the mean
and covariance of the heaviest cluster instead, and the whole set's too.

Clusters are the connected components of the occupied cells of a histogram
over (x, y, theta): cells of ``cell_xy`` metres by ``cell_theta`` radians,
26-connected (cells that share a face, an edge or a corner), with theta
periodic (the first and last theta slices are neighbours). Only the occupied
cells are stored (``np.unique`` of the particles' cell keys, at most N), and
a union-find over them (``mcl.kernels.clusters``) joins neighbours found by
walking the sorted cells (a pointer for each neighbouring row), so the cost
grows with N alone: never with the map's size or
the cloud's spread (a dense grid over the cloud's bounding box took 30 ms per
update on a 250 m map once recovery had spread particles over it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mcl.estimate import estimate, moments
from mcl.kernels.clusters import particle_clusters



@dataclass(frozen=True)
class ClusterEstimate:
    """The heaviest cluster's (mean, cov) and the full set's, with the cluster count and weight."""

    mean: np.ndarray  # (3,) x, y, circular-mean theta of the heaviest cluster
    cov: np.ndarray  # (3, 3)
    full_mean: np.ndarray  # (3,) of the whole weighted set
    full_cov: np.ndarray  # (3, 3)
    n_clusters: int
    weight: float  # total weight of the heaviest cluster (1.0: unimodal)


def cluster_labels(particles: np.ndarray, cell_xy: float, cell_theta: float) -> tuple[np.ndarray, int]:
    """(labels (N,) int64 in 0..C-1, C): the histogram cluster each particle belongs to.

    Labels are numbered in the order a C-order scan of the (x, y, theta) cells
    meets the components (deterministic for given particles).
    """
    p = np.asarray(particles, dtype=np.float64)
    n = p.shape[1]
    if n == 0:
        return np.zeros(0, dtype=np.int64), 0
    if not (cell_xy > 0 and cell_theta > 0):
        raise ValueError(f"cluster cell sizes must be > 0, got {cell_xy}, {cell_theta}")
    n_th = max(1, int(round(2.0 * math.pi / cell_theta)))
    labels = np.empty(n, dtype=np.int64)
    n_clusters = particle_clusters(np.ascontiguousarray(p), float(cell_xy), n_th, labels)
    return labels, int(n_clusters)


def cluster_estimate(particles: np.ndarray, w: np.ndarray, cell_xy: float = 0.5,
                     cell_theta: float = math.pi / 6) -> ClusterEstimate:
    """Mean and covariance of the heaviest cluster (weights renormalised within it), and of the whole set.

    ``w`` are normalised weights (N,). With one cluster both estimates are the same.
    """
    full_mean, full_cov = estimate(particles, w)
    labels, n_c = cluster_labels(particles, cell_xy, cell_theta)
    if n_c <= 1:
        return ClusterEstimate(full_mean, full_cov, full_mean, full_cov, max(n_c, 1), 1.0)
    cw = np.bincount(labels, weights=w, minlength=n_c)
    best = int(np.argmax(cw))
    total = float(cw[best])
    if not total > 0.0:  # pragma: no cover - weights sum to 1, so some cluster has weight
        return ClusterEstimate(full_mean, full_cov, full_mean, full_cov, n_c, 0.0)
    mean, cov = moments(particles, w, labels, best, 1.0 / total)
    return ClusterEstimate(mean, cov, full_mean, full_cov, n_c, total)
