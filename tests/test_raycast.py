"""Ray casting kernel: exact known walls, and a brute-force ray march oracle."""

import math

import numpy as np
import pytest

from mcl.kernels.raycast import cast_ray, cast_rays

RES = 0.05


def _march(x, y, angle, blocked, ox, oy, res, max_range, step):
    """Oracle: walk the ray in small fixed steps; first blocked cell wins."""
    h, w = blocked.shape
    c, s = math.cos(angle), math.sin(angle)
    n = int(max_range / step) + 1
    for i in range(n + 1):
        t = min(i * step, max_range)
        ix = math.floor((x + t * c - ox) / res)
        iy = math.floor((y + t * s - oy) / res)
        if not (0 <= ix < w and 0 <= iy < h):
            return max_range
        if blocked[iy, ix]:
            return t
        if t >= max_range:
            break
    return max_range


def _room(h=100, w=120):
    """Empty grid with a one-cell wall on its border."""
    b = np.zeros((h, w), dtype=np.bool_)
    b[0, :] = b[-1, :] = True
    b[:, 0] = b[:, -1] = True
    return b


@pytest.mark.parametrize(
    "angle, expected",
    [
        # start at cell (20.3, 30.6) in cell units, inside a box of walls:
        # interior faces at x = 1 and 119, y = 1 and 99 (cell units).
        (0.0, (119 - 20.3) * RES),
        (math.pi, (20.3 - 1) * RES),
        (math.pi / 2, (99 - 30.6) * RES),
        (-math.pi / 2, (30.6 - 1) * RES),
        # diagonal: toward +x +y the ray meets y = 99 first (68.4 < 98.7)
        (math.pi / 4, (99 - 30.6) * math.sqrt(2) * RES),
        # toward -x -y it meets x = 1 first (19.3 < 29.6)
        (-3 * math.pi / 4, (20.3 - 1) * math.sqrt(2) * RES),
        # toward +x -y it meets y = 1 first (29.6 < 98.7)
        (-math.pi / 4, (30.6 - 1) * math.sqrt(2) * RES),
    ],
)
def test_known_walls(angle, expected):
    b = _room()
    ox, oy = -1.0, 2.0
    x, y = ox + 20.3 * RES, oy + 30.6 * RES
    r = cast_ray(x, y, angle, b, ox, oy, RES, 100.0)
    assert r == pytest.approx(expected, abs=1e-9)


def test_single_wall_along_axes_and_pillar():
    b = np.zeros((50, 50), dtype=np.uint8)
    b[:, 40] = 1  # wall at x in [2.0, 2.05) with ox = 0
    b[10, 5] = 1  # a pillar cell at x in [0.25, 0.30), y in [0.5, 0.55)
    # along +x from x = 0.512 -> face at 2.0
    assert cast_ray(0.512, 1.0, 0.0, b, 0.0, 0.0, RES, 10.0) == pytest.approx(1.488, abs=1e-12)
    # along -x: nothing -> leaves the grid -> max_range
    assert cast_ray(0.512, 1.0, math.pi, b, 0.0, 0.0, RES, 10.0) == 10.0
    # along -x at the pillar's height: hits its right face x = 0.30
    assert cast_ray(0.512, 0.52, math.pi, b, 0.0, 0.0, RES, 10.0) == pytest.approx(0.212, abs=1e-12)
    # max range shorter than the wall distance
    assert cast_ray(0.512, 1.0, 0.0, b, 0.0, 0.0, RES, 1.0) == 1.0
    # starting inside a blocked cell
    assert cast_ray(2.01, 1.0, 0.3, b, 0.0, 0.0, RES, 10.0) == 0.0


def test_start_outside_grid_enters_and_hits():
    b = np.zeros((20, 20), dtype=np.bool_)
    b[:, 10] = True  # x in [0.5, 0.55)
    # from x = -1 toward +x: enters the grid at 0 and hits the wall face at 0.5
    assert cast_ray(-1.0, 0.3, 0.0, b, 0.0, 0.0, RES, 10.0) == pytest.approx(1.5, abs=1e-12)
    # pointing away from the grid: nothing
    assert cast_ray(-1.0, 0.3, math.pi, b, 0.0, 0.0, RES, 10.0) == 10.0
    # passing beside the grid: nothing
    assert cast_ray(-1.0, 5.0, 0.0, b, 0.0, 0.0, RES, 10.0) == 10.0


def test_does_not_skip_a_corner_cell():
    # A ray grazing one blocked cell's corner region: a coarse march can miss
    # it, the exact traversal must not.
    b = np.zeros((10, 10), dtype=np.bool_)
    b[5, 5] = True  # [0.25, 0.30) x [0.25, 0.30)
    # from (0.0, 0.051) through the point (0.299, 0.251), just inside the cell corner
    ang = math.atan2(0.251 - 0.051, 0.299 - 0.0)
    r = cast_ray(0.0, 0.051, ang, b, 0.0, 0.0, RES, 10.0)
    assert r < 10.0
    # the hit is where the ray crosses y = 0.25 (it enters through the bottom face)
    assert r == pytest.approx((0.25 - 0.051) / math.sin(ang), abs=1e-9)


def _slab_oracle(x, y, angle, blocked, ox, oy, res, max_range):
    """Oracle: exact ray/box intersection against every blocked cell.

    Returns (range, chord): the entry distance into the nearest blocked cell
    the ray passes through, and the length of the ray inside that cell.
    """
    iy, ix = np.nonzero(blocked)
    c, s = math.cos(angle), math.sin(angle)
    with np.errstate(divide="ignore", invalid="ignore"):
        x0 = (ox + ix * res - x) / c
        x1 = (ox + (ix + 1) * res - x) / c
        y0 = (oy + iy * res - y) / s
        y1 = (oy + (iy + 1) * res - y) / s
    if c == 0.0:
        inside = (ox + ix * res <= x) & (x < ox + (ix + 1) * res)
        x0 = np.where(inside, -np.inf, np.inf)
        x1 = np.where(inside, np.inf, -np.inf)
    if s == 0.0:
        inside = (oy + iy * res <= y) & (y < oy + (iy + 1) * res)
        y0 = np.where(inside, -np.inf, np.inf)
        y1 = np.where(inside, np.inf, -np.inf)
    t_in = np.maximum(np.maximum(np.minimum(x0, x1), np.minimum(y0, y1)), 0.0)
    t_out = np.minimum(np.maximum(x0, x1), np.maximum(y0, y1))
    ok = t_out > t_in
    if not ok.any():
        return max_range, 0.0
    j = np.argmin(np.where(ok, t_in, np.inf))
    if t_in[j] >= max_range:
        return max_range, 0.0
    return t_in[j], t_out[j] - t_in[j]


def _random_case(seed, n=40):
    rng = np.random.default_rng(seed)
    h, w = 60, 80
    b = rng.random((h, w)) < 0.04
    b[20:24, 30:50] = True
    ox, oy = -1.3, 0.7
    free = np.argwhere(~b)
    pick = free[rng.integers(0, len(free), n)]
    poses = np.empty((3, n))
    poses[0] = ox + (pick[:, 1] + rng.random(n)) * RES
    poses[1] = oy + (pick[:, 0] + rng.random(n)) * RES
    poses[2] = rng.uniform(-math.pi, math.pi, n)
    angles = np.linspace(-math.pi / 2, math.pi / 2, 37)
    return b, ox, oy, poses, angles


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_against_exact_box_intersection(seed):
    b, ox, oy, poses, angles = _random_case(seed)
    max_range = 3.0
    out = cast_rays(poses, angles, b, ox, oy, RES, max_range, np.empty((poses.shape[1], angles.size)))
    hits = 0
    for i in range(poses.shape[1]):
        for k in range(angles.size):
            a = poses[2, i] + angles[k]
            ref, chord = _slab_oracle(poses[0, i], poses[1, i], a, b, ox, oy, RES, max_range)
            if chord > 1e-9 or ref == max_range:
                assert out[i, k] == pytest.approx(ref, abs=1e-9), (i, k)
            else:  # the ray only touches a cell corner: either answer is right
                assert out[i, k] >= ref - 1e-9
            hits += out[i, k] < max_range
    assert hits > angles.size * poses.shape[1] // 2  # real hits were exercised


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_against_brute_force_march(seed):
    b, ox, oy, poses, angles = _random_case(seed)
    max_range = 3.0
    n = poses.shape[1]
    out = np.empty((n, angles.size))
    cast_rays(poses, angles, b, ox, oy, RES, max_range, out)
    far = 0
    for i in range(n):
        for k in range(angles.size):
            a = poses[2, i] + angles[k]
            ref = _march(poses[0, i], poses[1, i], a, b, ox, oy, RES, max_range, RES / 20)
            # the exact traversal sees every cell, so it never hits later
            assert out[i, k] <= ref + 1e-9
            far += ref - out[i, k] > RES
    # the march only misses cells whose corner the ray clips by less than a
    # step; that is rare, so nearly every ray agrees within one cell
    assert far <= 0.02 * n * angles.size


def test_batched_matches_single_and_thread_independent():
    rng = np.random.default_rng(7)
    b = _room(80, 80)
    b[30:50, 40] = True
    poses = np.vstack([rng.uniform(0.2, 3.8, 50), rng.uniform(0.2, 3.8, 50), rng.uniform(-3, 3, 50)])
    angles = np.linspace(-1.0, 1.0, 11)
    out = cast_rays(poses, angles, b, 0.0, 0.0, RES, 5.0, np.empty((50, 11)))
    ref = np.array([[cast_ray(poses[0, i], poses[1, i], poses[2, i] + a, b, 0.0, 0.0, RES, 5.0)
                     for a in angles] for i in range(50)])
    np.testing.assert_array_equal(out, ref)
