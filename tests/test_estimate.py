"""Estimates: weighted circular mean, heaviest-cluster mean on multi-modal clouds, the full set's spread."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mcl.clusters import cluster_estimate, cluster_labels
from mcl.estimate import estimate, wrap_angle


def _blob(rng, centre, std, n):
    p = rng.standard_normal((3, n)) * np.asarray(std)[:, None] + np.asarray(centre, dtype=float)[:, None]
    p[2] = wrap_angle(p[2])
    return p


def _bimodal(seed=0, n_a=3000, n_b=2000, a=(1.0, 2.0, 0.3), b=(6.0, -1.0, -2.0)):
    rng = np.random.default_rng(seed)
    p = np.ascontiguousarray(np.hstack([_blob(rng, a, (0.1, 0.1, 0.05), n_a), _blob(rng, b, (0.1, 0.1, 0.05), n_b)]))
    return p, np.full(p.shape[1], 1.0 / p.shape[1])


def test_heavier_mode_wins_not_the_midpoint():
    p, w = _bimodal()
    est = cluster_estimate(p, w, 0.5, math.pi / 6)
    assert est.n_clusters == 2
    assert est.weight == pytest.approx(0.6, abs=1e-12)
    # the heavier mode's mean within 4 standard errors (0.1 / sqrt(3000) = 0.0018 m)
    np.testing.assert_allclose(est.mean[:2], [1.0, 2.0], atol=0.01)
    assert abs(wrap_angle(est.mean[2] - 0.3)) < 0.01
    # the whole set's mean is near the weighted midpoint, 3 m away from either mode
    np.testing.assert_allclose(est.full_mean[:2], [0.6 * 1 + 0.4 * 6, 0.6 * 2 - 0.4 * 1], atol=0.02)
    assert math.hypot(*(est.mean[:2] - est.full_mean[:2])) > 1.5
    # the cluster's covariance is the blob's (0.1^2), the full set's spread is metres
    assert est.cov[0, 0] == pytest.approx(0.01, rel=0.1) and est.cov[1, 1] == pytest.approx(0.01, rel=0.1)
    assert est.full_cov[0, 0] > 5.0


def test_weights_not_counts_decide_the_heaviest_cluster():
    p, w = _bimodal(n_a=3000, n_b=2000)
    w = np.where(np.arange(p.shape[1]) < 3000, 1.0, 2.0)
    w /= w.sum()  # mode b: 4000 / 7000 of the weight with fewer particles
    est = cluster_estimate(p, w, 0.5, math.pi / 6)
    np.testing.assert_allclose(est.mean[:2], [6.0, -1.0], atol=0.01)
    assert est.weight == pytest.approx(4000 / 7000, rel=1e-12)


def test_unimodal_cloud_gives_the_plain_weighted_mean():
    rng = np.random.default_rng(1)
    p = _blob(rng, (3.0, 4.0, 1.0), (0.2, 0.2, 0.1), 5000)
    w = rng.random(5000)
    w /= w.sum()
    est = cluster_estimate(p, w, 0.5, math.pi / 6)
    mean, cov = estimate(p, w)
    assert est.n_clusters == 1 and est.weight == 1.0
    np.testing.assert_array_equal(est.mean, mean)
    np.testing.assert_array_equal(est.cov, cov)


def test_theta_seam_joins_one_cluster_and_the_circular_mean_is_pi():
    # Headings around +-pi straddle the histogram's first and last theta cells: still one cluster.
    rng = np.random.default_rng(2)
    p = _blob(rng, (0.0, 0.0, math.pi), (0.1, 0.1, 0.1), 4000)
    assert (p[2] > 3.0).any() and (p[2] < -3.0).any()
    labels, n = cluster_labels(p, 0.5, math.pi / 6)
    assert n == 1 and (labels == 0).all()
    est = cluster_estimate(p, np.full(4000, 1 / 4000), 0.5, math.pi / 6)
    assert abs(wrap_angle(est.mean[2] - math.pi)) < 0.01
    assert est.cov[2, 2] == pytest.approx(0.01, rel=0.1)  # wrapped differences, not 2*pi jumps


def test_same_place_opposite_headings_are_two_clusters():
    rng = np.random.default_rng(3)
    p = np.ascontiguousarray(np.hstack([_blob(rng, (0, 0, 0.0), (0.1, 0.1, 0.05), 1000),
                                        _blob(rng, (0, 0, math.pi), (0.1, 0.1, 0.05), 600)]))
    w = np.full(1600, 1 / 1600)
    est = cluster_estimate(p, w, 0.5, math.pi / 6)
    assert est.n_clusters == 2
    assert abs(est.mean[2]) < 0.02 and est.weight == pytest.approx(1000 / 1600)


def test_labels_match_a_numpy_flood_fill_oracle():
    # Random sparse clouds: the clusters are the connected components (26-neighbourhood, theta periodic) of the
    # occupied histogram cells, computed here with a plain breadth-first search over cells.
    rng = np.random.default_rng(4)
    for trial in range(20):
        n = int(rng.integers(5, 200))
        p = np.vstack([rng.uniform(-3, 3, n), rng.uniform(-3, 3, n), rng.uniform(-math.pi, math.pi, n)])
        labels, n_c = cluster_labels(p, 0.5, math.pi / 6)
        oracle, k = _flood_fill_labels(p, 0.5, 12)
        assert n_c == k, trial
        # same partition (label numbering may differ)
        pairs = set(zip(labels.tolist(), oracle.tolist()))
        assert len(pairs) == k == len({a for a, _ in pairs}) == len({b for _, b in pairs}), trial


def _flood_fill_labels(p, cell_xy, n_th):
    """Each particle's component among the occupied (x, y, theta) cells (26-neighbourhood, theta periodic), by a
    breadth-first search over a set of cells, numbered in the order of each component's first cell (x, y, theta)."""
    cells = np.stack([np.floor(p[0] / cell_xy), np.floor(p[1] / cell_xy),
                      np.floor((p[2] + math.pi) / (2 * math.pi / n_th)) % n_th]).astype(int).T
    occ = {tuple(c) for c in cells}
    comp, k = {}, 0
    for c in sorted(occ):
        if c in comp:
            continue
        stack, comp[c] = [c], k
        while stack:
            x, y, t = stack.pop()
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    for dt in (-1, 0, 1):
                        q = (x + dx, y + dy, (t + dt) % n_th)
                        if q in occ and q not in comp:
                            comp[q] = k
                            stack.append(q)
        k += 1
    return np.array([comp[tuple(c)] for c in cells]), k


@pytest.mark.parametrize("n_th", [1, 2, 3, 12, 63])
@pytest.mark.parametrize("span", [1.5, 4.0, 12.0])
def test_labels_are_the_flood_fills_numbered_alike_at_any_theta_resolution(n_th, span):
    # mcl.kernels.clusters.label_cells walks each neighbouring row of the sorted cells with a pointer (only the rows
    # after a cell's own; theta + 1 in its own row, wrapping): the components and their numbering must be the flood
    # fill's for one theta cell (every heading one), two (theta - 1 = theta + 1), three, and fine ones, in clouds
    # dense enough that most cells have neighbours in every direction (1.5 m) and sparse ones (12 m).
    rng = np.random.default_rng(n_th * 100 + int(span))
    n = 3000
    p = np.vstack([rng.uniform(-span, span, n), rng.uniform(-span, span, n), rng.uniform(-math.pi, math.pi, n)])
    labels, n_c = cluster_labels(p, 0.5, 2 * math.pi / n_th)
    oracle, k = _flood_fill_labels(p, 0.5, n_th)
    assert n_c == k
    np.testing.assert_array_equal(labels, oracle)


def test_occupied_cells_counted_or_sorted_equal_numpys_unique():
    # A compact cloud's cell keys are counted (no sort), a spread one's sorted: both must be np.unique's
    # (sorted distinct keys, each key's index), so the labels do not depend on the path.
    # (mcl.kernels.clusters.occupied_cells, the step of particle_clusters that finds them)
    from mcl.kernels.clusters import occupied_cells

    rng = np.random.default_rng(6)
    for n, span in ((5000, 600), (5000, 20_000), (300, 10**9), (1, 1)):
        keys = rng.integers(0, span, n).astype(np.int64)
        cells, inverse = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
        cells = cells[:occupied_cells(keys, span, cells, inverse)]
        u, inv = np.unique(keys, return_inverse=True)
        assert np.array_equal(cells, u) and np.array_equal(inverse, inv.ravel()), (n, span)


@pytest.mark.parametrize("span", [1, 2, 2048, 2049, 1 << 22, (1 << 22) + 1, 10**12])
def test_the_radix_sort_of_cell_keys_is_numpys_stable_argsort(span):
    # A spread cloud's keys are sorted by 11-bit digits (mcl.kernels.clusters._radix_order), a pass a digit: the
    # order, ties included, must be NumPy's stable argsort's, for key ranges of one pass, one pass and a bit, two
    # passes and a bit, and four (repeated keys, so ties matter).
    from mcl.kernels.clusters import _radix_order

    rng = np.random.default_rng(span % 1000)
    keys = rng.integers(0, span, 20_000).astype(np.int64)
    keys[:5] = span - 1  # the largest key, so every digit pass is needed
    np.testing.assert_array_equal(_radix_order(keys, span), np.argsort(keys, kind="stable"))


def test_uniform_draws_come_in_cache_order_the_same_poses_each_once():
    # A filter's uniform draws over free space (a global start, a re-seed, a search's oversampled candidates) are put
    # in cache order (mcl.filter.in_cache_order): the same poses, each once, by 4 m block of the map row by row and
    # then by heading bin, ties in draw order. Small draws (under 4,096) stay in draw order.
    from mcl.config import Config
    from mcl.filter import _CACHE_ORDER_MIN, ParticleFilter, in_cache_order
    from mcl.maps import OccupancyGrid

    occ = np.zeros((900, 1300), dtype=np.int8)  # 65 m x 45 m: 17 x 12 blocks of 4 m
    occ[[0, -1], :] = 100
    occ[:, [0, -1]] = 100
    grid = OccupancyGrid.from_occupancy(occ, 0.05, (-20.0, 3.0))
    drawn = grid.sample_free(50_000, np.random.default_rng(3))
    got = in_cache_order(drawn, grid)
    assert got.shape == drawn.shape and got.flags.c_contiguous
    bx = np.floor((drawn[0] + 20.0) / 4.0).astype(np.int64)
    by = np.floor((drawn[1] - 3.0) / 4.0).astype(np.int64)
    th = np.floor((drawn[2] + np.pi) * (256 / (2 * np.pi))).astype(np.int64) % 256
    order = np.lexsort((np.arange(drawn.shape[1]), th, bx, by))  # block row, block, heading; then draw order
    np.testing.assert_array_equal(got, drawn[:, order])
    assert len(np.unique(by[order])) == 12 and len(np.unique(bx)) == 17  # every block row and column is used

    cfg = Config()
    pf = ParticleFilter(cfg, grid, rng=np.random.default_rng(1))
    big = pf.sample_uniform(_CACHE_ORDER_MIN, np.random.default_rng(4))
    again = grid.sample_free(_CACHE_ORDER_MIN, np.random.default_rng(4), clearance=cfg.motion.robot_radius)
    np.testing.assert_array_equal(big, in_cache_order(again, grid))
    assert not np.array_equal(big, again)
    small = pf.sample_uniform(_CACHE_ORDER_MIN - 1, np.random.default_rng(4))
    np.testing.assert_array_equal(small, grid.sample_free(_CACHE_ORDER_MIN - 1, np.random.default_rng(4),
                                                          clearance=cfg.motion.robot_radius))


def test_huge_spread_keeps_full_resolution_without_a_dense_grid():
    # 1,000 particles over 10 km: 200,000 x 200,000 x 63 cells at full resolution (a dense grid could not be
    # allocated); only the occupied cells are stored, so every particle is its own cluster, and two particles
    # in neighbouring cells across the grid are one.
    rng = np.random.default_rng(5)
    p = np.vstack([rng.uniform(-5000, 5000, 1000), rng.uniform(-5000, 5000, 1000), rng.uniform(-3, 3, 1000)])
    p[:, 1] = p[:, 0] + [0.03, -0.03, 0.05]  # at most one cell over from particle 0 in x, y and theta
    labels, n = cluster_labels(p, 0.05, 0.1)
    assert n == 999 and labels[0] == labels[1] and len(set(labels.tolist())) == 999


def test_filter_estimate_uses_the_heaviest_cluster(tmp_path):
    from mcl.config import load_config
    from mcl.filter import ParticleFilter
    from mcl.maps import OccupancyGrid

    occ = np.zeros((200, 200), dtype=np.int8)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 100
    grid = OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))
    p, w = _bimodal(a=(3.0, 3.0, 0.3), b=(7.0, 6.0, -2.0))
    for mode, expect in (("cluster", (3.0, 3.0)), ("mean", (0.6 * 3 + 0.4 * 7, 0.6 * 3 + 0.4 * 6))):
        cfg = load_config(None, [f"filter.estimate={mode}", "filter.particles=5000", "filter.kld=false"])
        pf = ParticleFilter(cfg, grid)
        pf.particles, pf.weights, pf.logw = p.copy(), w.copy(), np.log(w)
        info = pf.step(None, None)
        np.testing.assert_allclose(info.mean[:2], expect, atol=0.02)
        np.testing.assert_allclose(info.full_mean[:2], [0.6 * 3 + 0.4 * 7, 0.6 * 3 + 0.4 * 6], atol=0.02)
        assert info.clusters == (2 if mode == "cluster" else 1)
        assert info.full_cov[0, 0] > 3.0


def test_the_kernel_gives_the_books_mean_and_covariance_of_the_set_and_of_one_cluster():
    # mcl.kernels.moments against weighted_mean_pose / weighted_covariance (numpy, the formulas as written): clouds
    # anywhere on the circle, some straddling the +-pi seam, some spread over every heading; a cluster's
    # moments are those of its particles with their weights renormalised. 1e-12: summation order only.
    from mcl.estimate import moments, weighted_covariance, weighted_mean_pose

    rng = np.random.default_rng(7)
    for trial in range(200):
        n = int(rng.integers(1, 4000))
        centre = (rng.uniform(-50, 50), rng.uniform(-50, 50), rng.choice([math.pi, rng.uniform(-math.pi, math.pi)]))
        p = _blob(rng, centre, (rng.uniform(0.01, 2.0), rng.uniform(0.01, 2.0),
                                rng.choice([0.05, 0.5, 3.0])), n)
        w = rng.random(n)
        w /= w.sum()
        mean, cov = estimate(p, w)
        want = weighted_mean_pose(p, w)
        np.testing.assert_allclose(mean, want, rtol=0, atol=1e-10, err_msg=f"trial {trial}")
        np.testing.assert_allclose(cov, weighted_covariance(p, w, want), rtol=1e-9, atol=1e-12,
                                   err_msg=f"trial {trial}")
        labels = rng.integers(0, 3, n)
        sel = labels == 1
        if not sel.any():
            continue
        total = float(w[sel].sum())
        mean1, cov1 = moments(p, w, labels, 1, 1.0 / total)
        want1 = weighted_mean_pose(p[:, sel], w[sel] / total)
        np.testing.assert_allclose(mean1, want1, rtol=0, atol=1e-10, err_msg=f"trial {trial}")
        np.testing.assert_allclose(cov1, weighted_covariance(p[:, sel], w[sel] / total, want1), rtol=1e-9,
                                   atol=1e-12, err_msg=f"trial {trial}")


def test_weighted_mean_pose_does_not_change_with_the_blas_thread_count():
    # np.dot over 100,000 weights is split over OpenBLAS's threads: its last digits differed between
    # OPENBLAS_NUM_THREADS=1 and 2. Two processes, one BLAS thread and two: the same bits.
    from tests.blas import outputs_by_blas_threads

    got = outputs_by_blas_threads(
        "import numpy as np; from mcl.estimate import weighted_mean_pose as f; r = np.random.default_rng(1); "
        "p = r.normal(0, 30, (3, 100000)); w = r.random(100000); w /= w.sum(); print(f(p, w).tobytes().hex())")
    assert len(got) == 1, got
