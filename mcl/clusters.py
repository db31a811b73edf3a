"""Clusters of a particle cloud and the estimate of the heaviest one.

When the cloud is multi-modal (global localization, symmetric corridors, after
a kidnapping) the weighted mean of the whole set lies between the modes, often
inside a wall. Like AMCL (``pf_cluster_stats``), the filter reports the mean
and covariance of the heaviest cluster instead, and the whole set's too.

Clusters are the connected components of the occupied cells of a histogram
over (x, y, theta): cells of ``cell_xy`` metres by ``cell_theta`` radians,
26-connected (cells that share a face, an edge or a corner), with theta
periodic (the first and last theta slices are neighbours). Everything is
vectorised: one dense boolean grid over the cloud's bounding box,
``scipy.ndimage.label`` for the components, and a small graph over the labels
that meet across the theta seam (``scipy.sparse.csgraph``). No loop over
particles.

The bounding box grows with the spread of the cloud; if it would need more
than ``MAX_CELLS`` cells the cell size is doubled until it fits (a cloud spread
over a huge map gets coarser clusters, never a huge allocation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mcl.estimate import estimate

MAX_CELLS = 4_000_000
_STRUCT = np.ones((3, 3, 3), dtype=bool)  # 26-connectivity


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

    Labels are numbered in the order ``scipy.ndimage.label`` meets the
    components (deterministic for given particles).
    """
    p = np.asarray(particles, dtype=np.float64)
    n = p.shape[1]
    if n == 0:
        return np.zeros(0, dtype=np.int64), 0
    if not (cell_xy > 0 and cell_theta > 0):
        raise ValueError(f"cluster cell sizes must be > 0, got {cell_xy}, {cell_theta}")
    from scipy import ndimage
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n_th = max(1, int(round(2.0 * math.pi / cell_theta)))
    th_cell = 2.0 * math.pi / n_th
    it = np.floor((p[2] + math.pi) / th_cell).astype(np.int64) % n_th
    size = float(cell_xy)
    while True:
        ix = np.floor(p[0] / size).astype(np.int64)
        iy = np.floor(p[1] / size).astype(np.int64)
        ix -= ix.min()
        iy -= iy.min()
        shape = (int(ix.max()) + 1, int(iy.max()) + 1, n_th)
        if shape[0] * shape[1] * shape[2] <= MAX_CELLS:
            break
        size *= 2.0
    occ = np.zeros(shape, dtype=bool)
    occ[ix, iy, it] = True
    labels, n_lab = ndimage.label(occ, structure=_STRUCT)
    if n_th > 2 and n_lab > 1:
        # Theta is periodic: label the two seam slices (last, first) side by side; every seam
        # component joins the original labels it touches.
        seam = np.ascontiguousarray(labels[:, :, [-1, 0]])
        seam_lab, n_seam = ndimage.label(seam > 0, structure=_STRUCT)
        nz = seam_lab > 0
        a = seam[nz]  # original labels 1..n_lab
        b = seam_lab[nz] + n_lab  # seam components n_lab+1..
        m = n_lab + n_seam + 1
        g = coo_matrix((np.ones(a.size, dtype=np.int8), (a, b)), shape=(m, m))
        _, comp = connected_components(g, directed=False)
        # renumber the components of labels 1..n_lab densely, in first-label order
        uniq, first = np.unique(comp[1 : n_lab + 1], return_index=True)
        order = np.argsort(first, kind="stable")
        remap = np.empty(comp.max() + 1, dtype=np.int64)
        remap[uniq[order]] = np.arange(uniq.size)
        lab_map = np.concatenate([[-1], remap[comp[1 : n_lab + 1]]])
        n_clusters = int(uniq.size)
    else:
        lab_map = np.arange(-1, n_lab, dtype=np.int64)
        n_clusters = int(n_lab)
    return lab_map[labels[ix, iy, it]], n_clusters


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
    sel = labels == best
    total = float(cw[best])
    if not total > 0.0:  # pragma: no cover - weights sum to 1, so some cluster has weight
        return ClusterEstimate(full_mean, full_cov, full_mean, full_cov, n_c, 0.0)
    sub = np.ascontiguousarray(particles[:, sel])
    mean, cov = estimate(sub, w[sel] / total)
    return ClusterEstimate(mean, cov, full_mean, full_cov, n_c, total)
