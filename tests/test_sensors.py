"""Likelihood field range finder model (Prob. Rob. Table 6.3) and scan -> endpoints."""

import math
from types import SimpleNamespace

import numba
import numpy as np
import pytest
from scipy import stats

from mcl.kernels.likelihood import likelihood_field_loglik
from mcl.maps import OccupancyGrid
from mcl.sensors import LikelihoodField, beam_endpoints, field_distance, point_log_likelihood, scan_endpoints


def sensor_cfg(**kw):
    base = dict(model="likelihood_field", z_hit=0.9, z_rand=0.1, sigma_hit=0.2, likelihood_max_dist=1.0,
                max_beams=1000, range_min=0.05, range_max=10.0, exponent=1.0, laser_pose=None)
    base.update(kw)
    return SimpleNamespace(**base)


def box_grid():
    """A 6 m x 4 m room (0.05 m cells) with 1-cell walls, an inner pillar and an unknown band outside x > 5.5."""
    occ = np.zeros((80, 120), dtype=np.int8)
    occ[0, :] = occ[-1, :] = 100
    occ[:, 0] = occ[:, 109] = 100
    occ[30:40, 40:50] = 100
    occ[:, 110:] = -1
    return OccupancyGrid.from_occupancy(occ, 0.05, (-1.0, -2.0))


def numpy_loglik(grid, table, offmap, exponent, particles, endpoints):
    """The same formula written out with NumPy, for every particle-beam pair."""
    x, y, th = (particles[i][:, None] for i in range(3))
    bx, by = endpoints[0][None, :], endpoints[1][None, :]
    ex = x + np.cos(th) * bx - np.sin(th) * by
    ey = y + np.sin(th) * bx + np.cos(th) * by
    ix = np.floor((ex - grid.origin[0]) / grid.resolution).astype(np.int64)
    iy = np.floor((ey - grid.origin[1]) / grid.resolution).astype(np.int64)
    inside = (ix >= 0) & (ix < table.shape[1]) & (iy >= 0) & (iy < table.shape[0])
    vals = np.full(ex.shape, offmap, dtype=np.float64)
    vals[inside] = table[iy[inside], ix[inside]]
    return exponent * vals.sum(axis=1)


# ---------------------------------------------------------------- the table

def test_table_is_log_of_hit_plus_random_at_clipped_distance():
    g = box_grid()
    cfg = sensor_cfg()
    lf = LikelihoodField(g, cfg)  # interior: zero (the default, AMCL's field): d = 0 on every occupied cell
    assert lf.table.dtype == np.float32 and lf.table.shape == g.occupancy.shape
    d = np.minimum(g.distance.astype(np.float64), cfg.likelihood_max_dist)
    expected = np.log(cfg.z_hit * stats.norm.pdf(d, 0.0, cfg.sigma_hit) + cfg.z_rand / cfg.range_max)
    np.testing.assert_allclose(lf.table, expected, rtol=1e-6)
    # interior: depth, d = the depth on occupied cells: the two differ only inside the pillar
    deep = LikelihoodField(g, sensor_cfg(interior="depth", interior_tolerance=0.0))
    dd = np.minimum(g.surface_distance().astype(np.float64), cfg.likelihood_max_dist)
    np.testing.assert_allclose(deep.table, np.log(cfg.z_hit * stats.norm.pdf(dd, 0.0, cfg.sigma_hit)
                                                  + cfg.z_rand / cfg.range_max), rtol=1e-6)
    differ = deep.table != lf.table
    assert differ.any() and g.occupied[differ].all()
    # interior_tolerance: that much of the depth is not counted, on occupied cells only
    tol = LikelihoodField(g, sensor_cfg(interior="depth", interior_tolerance=0.1))
    sd = g.surface_distance().astype(np.float64)
    dt = np.minimum(np.where(g.occupied, np.maximum(sd - 0.1, 0.0), sd), cfg.likelihood_max_dist)
    np.testing.assert_allclose(tol.table, np.log(cfg.z_hit * stats.norm.pdf(dt, 0.0, cfg.sigma_hit)
                                                 + cfg.z_rand / cfg.range_max), rtol=1e-6)
    assert (tol.table != deep.table).any() and (tol.table != lf.table).any()
    # interior_cap: occupied cells score at most that deep (the pillar's centre is 0.2 m deep); free cells as before
    capped = LikelihoodField(g, sensor_cfg(interior="depth", interior_tolerance=0.0, interior_cap=0.1))
    dc = np.minimum(np.where(g.occupied, np.minimum(sd, 0.1), sd), cfg.likelihood_max_dist)
    np.testing.assert_allclose(capped.table, np.log(cfg.z_hit * stats.norm.pdf(dc, 0.0, cfg.sigma_hit)
                                                    + cfg.z_rand / cfg.range_max), rtol=1e-6)
    assert (capped.table != deep.table).any() and (capped.table == deep.table)[~g.occupied].all()
    np.testing.assert_array_equal(field_distance(g, sensor_cfg(interior="depth", interior_tolerance=0.0,
                                                               interior_cap=0.1)),
                                  np.where(g.occupied, np.minimum(sd, 0.1), sd).astype(np.float32))
    # off-map: the value at likelihood_max_dist, which is also the table's minimum
    off = math.log(cfg.z_hit * stats.norm.pdf(1.0, 0.0, 0.2) + 0.1 / 10.0)
    assert lf.offmap == pytest.approx(off, rel=1e-6)
    assert lf.table.min() == pytest.approx(off, rel=1e-6)
    # occupied cells score the peak, unknown cells their own distance value
    assert lf.table[0, 5] == pytest.approx(math.log(0.9 / (math.sqrt(2 * math.pi) * 0.2) + 0.01), rel=1e-6)
    assert lf.table[40, 112] == pytest.approx(float(point_log_likelihood(g.distance[40, 112], cfg)), rel=1e-6)
    assert lf.table[40, 112] > lf.offmap  # 0.15 m from the wall at column 109


def thin_walled_grid(res: float) -> OccupancyGrid:
    """A 40 x 40 map drawn as SLAM draws one: thin walls (a border and two inner walls, one cell thick) and one block
    10 cells square, the only cells deeper than one cell but for 8 where the inner walls meet the border, off the map
    counting as occupied (72 of 332 occupied: ``solid_share`` 0.22)."""
    occ = np.zeros((40, 40), dtype=np.int8)
    occ[[0, 5, 33, 39], :] = 100
    occ[:, [0, 39]] = 100
    occ[15:25, 10:20] = 100
    return OccupancyGrid.from_occupancy(occ, res, (0.0, 0.0))


def solid_grid(res: float) -> OccupancyGrid:
    """A 40 x 40 map with a wall 20 cells thick, drawn solid as a floor plan draws it (``solid_share`` 0.9)."""
    occ = np.zeros((40, 40), dtype=np.int8)
    occ[:, 10:30] = 100
    return OccupancyGrid.from_occupancy(occ, res, (0.0, 0.0))


def test_interior_tolerance_null_is_five_centimetres_or_one_cell_whichever_is_more():
    # a map drawn by returns (thin walls, one thick block) on a 5 cm, a 10 cm and a 2.5 cm grid: with null the depth
    # field takes off one cell (0.1 m) on the 10 cm map, what the 5 cm map's 0.05 m is in cells, and 0.05 m on the
    # others; a number is taken as it is
    from mcl.config import PROJECT_ROOT, load_config

    for path in (None, PROJECT_ROOT / "configs" / "default.yaml"):  # the built-in defaults and the default config
        assert load_config(path).sensor.likelihood_field.interior_tolerance is None
    for res, expected in ((0.05, 0.05), (0.1, 0.1), (0.025, 0.05)):
        g = thin_walled_grid(res)
        assert g.solid_share == pytest.approx(72 / 332)
        null = LikelihoodField(g, sensor_cfg(interior="depth", interior_tolerance=None)).table
        same = LikelihoodField(g, sensor_cfg(interior="depth", interior_tolerance=expected)).table
        np.testing.assert_array_equal(null, same)
        other = 0.05 if expected != 0.05 else 0.1
        assert (LikelihoodField(g, sensor_cfg(interior="depth", interior_tolerance=other)).table != null).any()


def test_interior_tolerance_null_is_zero_on_a_map_drawn_solid_of_five_centimetres_or_finer():
    # walls drawn solid (a floor plan, mcl simulate): the laser sees them where they are drawn, and null takes
    # nothing off the depth on a 5 cm or 2.5 cm map; a 10 cm map keeps one cell (a mapping run at 10 cm draws the
    # surface up to a cell inside the wall); surface: face gives 0 as before
    from mcl.sensors import SOLID_SHARE, drawn_solid

    for res, expected in ((0.05, 0.0), (0.025, 0.0), (0.1, 0.1)):
        g = solid_grid(res)
        assert g.solid_share == pytest.approx(18 * 40 / 800)  # the wall's inner 18 columns
        assert drawn_solid(g) is (expected == 0.0)
        null = LikelihoodField(g, sensor_cfg(interior="depth", interior_tolerance=None)).table
        np.testing.assert_array_equal(null, LikelihoodField(g, sensor_cfg(interior="depth",
                                                                          interior_tolerance=expected)).table)
        assert (LikelihoodField(g, sensor_cfg(interior="depth", interior_tolerance=0.05 if expected == 0.0
                                              else 0.0)).table != null).any()
    # the share that decides, on either side of the bound; a map without occupied cells is not solid
    for share, solid in ((SOLID_SHARE - 0.01, False), (SOLID_SHARE, True)):
        assert drawn_solid(SimpleNamespace(resolution=0.05, solid_share=share)) is solid
    empty = OccupancyGrid.from_occupancy(np.zeros((5, 5), dtype=np.int8), 0.05, (0.0, 0.0))
    assert empty.solid_share == 0.0 and not drawn_solid(empty)
    assert not drawn_solid(SimpleNamespace(resolution=0.05))  # a stand-in grid without the share: as before


def test_surface_face_measures_to_the_cells_faces_on_both_sides():
    # sensor.likelihood_field.surface: face, a wall 3 cells thick (x cells 10-12) on a 5 cm map, along a row: the free
    # cell before the wall is half a cell from its face, the one before that 1.5 cells; inside, the face cell is half a
    # cell in and the middle cell 1.5 cells (interior: depth, interior_tolerance null: 0 with face); interior: zero,
    # 0 in every wall cell. With centre (the default) the free cell before the wall is one cell off and the wall's
    # face cell 0, so a reading a little short of the surface costs more than one a little past it.
    from mcl.sensors import field_distance

    res = 0.05
    occ = np.zeros((5, 25), dtype=np.int8)
    occ[:, 10:13] = 100
    g = OccupancyGrid.from_occupancy(occ, res, (0.0, 0.0))
    row = field_distance(g, sensor_cfg(interior="depth", interior_tolerance=None, surface="face"))[2]
    np.testing.assert_allclose(row[8:15], np.array([1.5, 0.5, 0.5, 1.5, 0.5, 0.5, 1.5]) * res, atol=1e-7)
    row = field_distance(g, sensor_cfg(interior="depth", interior_tolerance=0.03, surface="face"))[2]
    np.testing.assert_allclose(row[9:14], [0.025, 0.0, 0.045, 0.0, 0.025], atol=1e-7)  # the tolerance inside only
    row = field_distance(g, sensor_cfg(interior="zero", surface="face"))[2]
    np.testing.assert_allclose(row[8:15], np.array([1.5, 0.5, 0, 0, 0, 0.5, 1.5]) * res, atol=1e-7)
    row = field_distance(g, sensor_cfg(interior="depth", interior_tolerance=None))[2]  # centre
    # (the wall is drawn solid, a third of its cells deeper than one cell: null is 0 and the middle cell one cell deep)
    np.testing.assert_allclose(row[8:15], np.array([2, 1, 0, 1, 0, 1, 2]) * res, atol=1e-7)
    row = field_distance(g, sensor_cfg(interior="depth", interior_tolerance=0.05))[2]  # centre, as on a SLAM map
    np.testing.assert_allclose(row[8:15], np.array([2, 1, 0, 0, 0, 1, 2]) * res, atol=1e-7)
    # the model's table is the field's: the log-likelihood of each cell's d
    cfg = sensor_cfg(interior="depth", interior_tolerance=None, surface="face")
    d = field_distance(g, cfg)
    np.testing.assert_allclose(LikelihoodField(g, cfg).table, point_log_likelihood(np.minimum(d, 1.0), cfg),
                               rtol=1e-6)


def test_surface_face_field_and_table_are_made_in_rows_without_a_whole_copy():
    # surface: face's field is made from the field's rows and the interior: depth patches (mcl.sensors.field_rows),
    # as centre's is: on the demo map (walls several cells thick, so the patches matter: 315 cells) it equals the
    # definition written out whole from surface_distance(0) (free cells: distance less half a cell; occupied: 0, or
    # the depth plus half a cell less the tolerance), to the bit. The model's table is built without a whole copy of
    # the field: on the demo map tiled 4 x 4 (9.6 MB of table) numpy's peak while building it is under 1.25 tables
    # (1.16 measured, the blocks' float64 temporaries; 3.1 when the face field was made whole: 576 MB per copy on a
    # 144 M-cell map).
    import tracemalloc

    from mcl.config import PROJECT_ROOT
    from mcl.maps import load_map
    from mcl.sensors import field_distance

    def reference(grid, tolerance, cap):
        half = 0.5 * grid.resolution
        occ = grid.occupied
        if tolerance is None:
            d = np.array(grid.distance, dtype=np.float32)
            d[occ] = 0.0
        else:
            d = np.array(grid.surface_distance(0.0), dtype=np.float32)
            d[occ] = np.minimum(np.maximum(d[occ] + np.float32(half - tolerance), 0.0), np.float32(cap))
        d[~occ] = np.maximum(d[~occ] - np.float32(half), 0.0)
        return d

    for interior, tolerance, cap in (("depth", None, None), ("depth", 0.03, None), ("depth", 0.2, None),
                                     ("depth", None, 0.1), ("zero", None, 0.1)):
        cfg = sensor_cfg(interior=interior, interior_tolerance=tolerance, surface="face", interior_cap=cap)
        grid = load_map(PROJECT_ROOT / "data" / "demo" / "map.yaml")
        table = LikelihoodField(grid, cfg).table
        assert "_surface_cache" not in grid.__dict__
        field = field_distance(grid, cfg)
        expected = reference(load_map(PROJECT_ROOT / "data" / "demo" / "map.yaml"),
                             None if interior == "zero" else (tolerance or 0.0), np.inf if cap is None else cap)
        assert np.array_equal(field, expected)
        if cap is not None and interior == "depth":  # the demo's thick walls hold cells deeper than the cap
            assert (field[grid.occupied] == np.float32(cap)).sum() > 20
        np.testing.assert_array_equal(table, point_log_likelihood(field, cfg).astype(np.float32))
        inside = int(((field > 0) & grid.occupied).sum())  # scored by depth: the test sees the patches
        assert inside > 100 if interior == "depth" else inside == 0, inside
        big = OccupancyGrid.from_occupancy(np.tile(grid.occupancy, (4, 4)), grid.resolution, (0.0, 0.0))
        big.distance, big.occupied, big.surface_patches(0.0)  # cached in the grid before the model is made
        tracemalloc.start()
        try:
            table = LikelihoodField(big, cfg).table
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 1.25 * table.nbytes, peak / table.nbytes


def test_surface_face_puts_the_fields_peak_on_a_generated_worlds_truth(tmp_path):
    # mcl simulate's laser reads to the face of the first wall cell. Summed over a run's scans at the truth shifted
    # along its heading (5 mm steps), the field peaks 4.5 cm ahead with centre (docs/measurements.md, "Forty-first
    # session": the estimate tracks that far ahead; 4.0 cm since interior_tolerance null is 0 on a map drawn solid)
    # and 1.5 cm with face: asserted within 2 cm and at least 2 cm nearer than centre's (what is left: the distance
    # less half a cell is the face's only in line with the grid).
    from mcl.config import PROJECT_ROOT, load_config
    from mcl.datasets.carmen import read_carmen
    from mcl.maps import load_map
    from mcl.simulate import simulate

    simulate(tmp_path, kind="office", seed=11, duration=60.0)
    grid = load_map(tmp_path / "map.yaml")
    truth = np.loadtxt(tmp_path / "truth.tum")
    heading = 2.0 * np.arctan2(truth[:, 6], truth[:, 7])
    scans = read_carmen(tmp_path / "log.clf").scans
    shifts = np.arange(-0.1, 0.1001, 0.005)
    peaks = {}
    for surface in ("centre", "face"):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml",
                          [f"sensor.likelihood_field.surface={surface}"]).sensor
        model = LikelihoodField(grid, cfg)
        total = np.zeros(shifts.size)
        for i, scan in enumerate(scans):
            poses = np.empty((3, shifts.size))
            poses[0] = truth[i, 1] + shifts * math.cos(heading[i])
            poses[1] = truth[i, 2] + shifts * math.sin(heading[i])
            poses[2] = heading[i]
            total += model.log_likelihood(poses, model.prepare(scan, np.zeros(3)))
        peaks[surface] = round(float(shifts[np.argmax(total)]) * 1000.0)  # mm
    assert 35 <= peaks["centre"] <= 60, peaks
    assert abs(peaks["face"]) <= 20 and peaks["centre"] - abs(peaks["face"]) >= 20, peaks


def test_the_search_field_is_search_interiors_and_is_built_only_when_it_differs():
    g = box_grid()
    rng = np.random.default_rng(4)
    poses = np.vstack([rng.uniform(-0.5, 4.5, 300), rng.uniform(-1.5, 1.5, 300), rng.uniform(-np.pi, np.pi, 300)])
    e = np.vstack([rng.uniform(0.5, 3.0, 40), rng.uniform(-1.0, 1.0, 40)])
    zero = LikelihoodField(g, sensor_cfg(interior="zero", search_interior="zero"))
    deep = LikelihoodField(g, sensor_cfg(interior="depth", search_interior="depth", interior_tolerance=0.0))
    assert zero.search_table() is zero.table and deep.search_table() is deep.table
    # depth while tracking, zero while searching: each call scores with its own field
    mixed = LikelihoodField(g, sensor_cfg(interior="depth", search_interior="zero", interior_tolerance=0.0))
    assert mixed._search_table is None  # not built until a search needs it
    np.testing.assert_array_equal(mixed.log_likelihood(poses, e), deep.log_likelihood(poses, e))
    np.testing.assert_array_equal(mixed.log_likelihood(poses, e, searching=True), zero.log_likelihood(poses, e))
    assert (zero.log_likelihood(poses, e) != deep.log_likelihood(poses, e)).any()  # the pillar tells them apart
    np.testing.assert_array_equal(zero.log_likelihood(poses, e, searching=True), zero.log_likelihood(poses, e))


def test_solid_regions_are_the_obstacles_parts_at_least_twice_the_depth_wide():
    # The opening of the occupied cells by a disc: a 4 m block (the black outside a floor plan) is a solid region, a
    # 2 m pillar beside it (depth at most 0.95 m) and the 1-cell walls are not; with no cell 1.5 m deep, None.
    occ = np.zeros((200, 300), dtype=np.int8)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 100
    occ[50:90, 50:90] = 100  # 2 m x 2 m
    occ[20:180, 150:230] = 100  # 8 m x 4 m
    g = OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))
    r = g.solid_regions(1.5)
    assert r.dtype == bool and r.shape == occ.shape
    # the block but its corners (a disc of 1.5 m does not reach into a right angle), nothing else
    assert r[51:149, 150:230].all() and r[20:180, 181:199].all() and not r[20, 150] and not r[179, 229]
    assert not r[:, :150].any() and not r[:, 230:].any() and not r[:20].any() and not r[180:].any()
    assert g.solid_regions(1.5) is not None and g.solid_regions(2.1) is None  # the block is 2 m deep at most
    assert box_grid().solid_regions(1.5) is None


def test_the_search_field_scores_solid_regions_by_their_depth():
    # search_interior zero scored a return 3 m inside a floor plan's black outside as a perfect hit, so a global
    # search settled where the scan fell into it (the demo's map with its unknown painted black: 4-9 m off after the
    # kidnap on every seed). With search_solid, the solid region's cells take the depth field's values and every other
    # cell keeps AMCL's; with no solid region the search field is the zero field, cell for cell.
    occ = np.zeros((200, 300), dtype=np.int8)
    occ[:, 200:] = 100  # 5 m of black beside the room
    occ[0, :200] = occ[-1, :200] = occ[:, 0] = 100
    occ[90:110, 90:110] = 100  # a 1 m pillar
    g = OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))
    lf = LikelihoodField(g, sensor_cfg(interior="depth", search_interior="zero", interior_tolerance=0.0,
                                      search_solid=1.5))
    zero = LikelihoodField(g, sensor_cfg(interior="zero", search_interior="zero"))
    search = lf.search_table()
    solid = g.solid_regions(1.5)
    np.testing.assert_array_equal(search[~solid], zero.table[~solid])
    np.testing.assert_array_equal(search[solid], lf.table[solid])
    # 3 m in: as far from a surface as the field reaches (likelihood_max_dist), not a hit
    assert search[100, 260] == np.float32(point_log_likelihood(1.0, lf.cfg)) < zero.table[100, 260] - 5.0
    off = LikelihoodField(g, sensor_cfg(interior="depth", search_interior="zero", interior_tolerance=0.0,
                                       search_solid=0.0))
    np.testing.assert_array_equal(off.search_table(), zero.table)
    plain = LikelihoodField(box_grid(), sensor_cfg(interior="depth", search_interior="zero", interior_tolerance=0.0,
                                                   search_solid=1.5))
    np.testing.assert_array_equal(plain.search_table(), LikelihoodField(box_grid(), sensor_cfg()).table)


# ---------------------------------------------------------------- the kernel against NumPy

@pytest.mark.parametrize("exponent", [1.0, 0.3])
def test_kernel_matches_numpy_including_off_map(exponent):
    g = box_grid()
    lf = LikelihoodField(g, sensor_cfg(exponent=exponent))
    rng = np.random.default_rng(0)
    n, k = 2000, 37
    # particles inside and around the map (some endpoints fall off it, some particles are off it)
    p = np.stack([rng.uniform(-3, 8, n), rng.uniform(-4, 4, n), rng.uniform(-np.pi, np.pi, n)])
    p[0, :20] = 30.0  # far off the map: every endpoint is off-map
    ang = np.linspace(-np.pi, np.pi, k, endpoint=False)
    r = rng.uniform(0.1, 6.0, k)
    e = np.stack([0.1 + r * np.cos(ang), -0.05 + r * np.sin(ang)])
    got = lf.log_likelihood(p, e)
    ref = numpy_loglik(g, lf.table, lf.offmap, exponent, p, e)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(got[:20], exponent * k * lf.offmap, rtol=1e-12)
    # the mixed particles exercise both branches: some endpoints on, some off the map
    ex = p[0, 20:, None] + np.cos(p[2, 20:, None]) * e[0] - np.sin(p[2, 20:, None]) * e[1]
    off = (ex < -1.0) | (ex >= 5.0)
    assert 0.1 < off.mean() < 0.9


def test_off_map_endpoint_scores_value_at_max_dist_and_empty_scan_scores_zero():
    g = box_grid()
    lf = LikelihoodField(g, sensor_cfg())
    p = np.array([[0.0, 100.0, -50.0], [0.0, 0.0, -50.0], [0.0, 1.0, -2.0]])
    e = np.array([[0.5, -20.0], [0.0, 0.0]])  # the second endpoint is off-map for every particle
    ll = lf.log_likelihood(p, e)
    assert ll[1] == pytest.approx(2 * lf.offmap) and ll[2] == pytest.approx(2 * lf.offmap)
    ix, iy = g.world_to_cell(0.5, 0.0)
    assert ll[0] == pytest.approx(float(lf.table[iy, ix]) + lf.offmap)
    np.testing.assert_array_equal(lf.log_likelihood(p, np.empty((2, 0))), np.zeros(3))


def test_true_pose_scores_best_among_perturbed_poses():
    """Simulate a scan in the box by ray marching; the true pose beats every shifted/rotated pose."""
    g = box_grid()
    cfg = sensor_cfg(sigma_hit=0.1)
    lf = LikelihoodField(g, cfg)
    true = np.array([1.5, 0.3, 0.4])
    ang = np.linspace(-np.pi, np.pi, 90, endpoint=False)
    ranges = np.empty_like(ang)
    for i, a in enumerate(ang):  # march 1 cm steps until an occupied cell
        for r in np.arange(0.0, 10.0, 0.01):
            ix, iy = g.world_to_cell(true[0] + r * math.cos(true[2] + a), true[1] + r * math.sin(true[2] + a))
            if g.occupied[iy, ix]:
                break
        ranges[i] = r
    e = beam_endpoints(ranges, ang, None, cfg, (0.0, 0.0, 0.0))
    offsets = [(dx, dy, dth) for dx in (-0.2, 0, 0.2) for dy in (-0.2, 0, 0.2) for dth in (-0.1, 0, 0.1)]
    poses = np.array([true + np.array(o) for o in offsets]).T.copy()
    ll = lf.log_likelihood(poses, e)
    assert np.argmax(ll) == offsets.index((0, 0, 0))


def test_returns_seen_through_a_thin_wall_into_furniture_do_not_favour_a_pose_too_far_forward():
    """A 1-cell wall with a 0.6 m deep desk against its far side (suites/synthetic.yaml large-02). Facing the
    wall from 3 m, a pose 0.3 m too far forward puts the wall's returns 0.3 m into the desk: with AMCL's field
    (d = 0 on every occupied cell) that pose scores as well as the true one, so odometry noise carries the
    cloud forward unchecked. With the depth inside obstacles the returns land 0.3 m deep (6 cells from either
    face, less one) and the forward pose loses by 3.9 nats a beam (0.3^2 / 2 / 0.1^2 = 4.5 less the z_rand
    floor); with interior_tolerance 0.05 m (the config's), by 2.7 (0.25 m). The bound asks for 2, so it fails on
    d = 0; a pose 0.1 m forward (0.05 m deep, within the tolerance) loses only 0.12 a beam."""
    occ = np.zeros((80, 100), dtype=np.int8)
    occ[:, 60] = 100            # the wall at x = 3.0 (cell 60)
    occ[20:60, 61:73] = 100     # the desk behind it, x 3.05-3.65, y 1.0-3.0
    g = OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))
    cfg = sensor_cfg(sigma_hit=0.1, likelihood_max_dist=2.0, interior="depth")
    ang = np.linspace(-0.25, 0.25, 11)  # beams at the wall in front of the desk
    true = np.array([0.0, 2.0, 0.0])
    ranges = (3.0 + 0.025) / np.cos(ang)  # to the wall cell's centre
    e = beam_endpoints(ranges, ang, None, cfg, (0.0, 0.0, 0.0))
    poses = np.array([true, true + [0.3, 0.0, 0.0]]).T.copy()
    ll_depth = LikelihoodField(g, cfg).log_likelihood(poses, e)
    ll_tol = LikelihoodField(g, sensor_cfg(sigma_hit=0.1, likelihood_max_dist=2.0, interior="depth",
                                           interior_tolerance=0.05)).log_likelihood(poses, e)
    ll_zero = LikelihoodField(g, sensor_cfg(sigma_hit=0.1, likelihood_max_dist=2.0,
                                            interior="zero")).log_likelihood(poses, e)
    assert ll_zero[1] >= ll_zero[0] - 1e-6  # AMCL's field: the forward pose is no worse (the flaw)
    assert ll_depth[0] - ll_depth[1] > 2.0 * e.shape[1]  # depth: the true pose wins by > 2 nats a beam
    assert ll_depth[0] - ll_depth[1] > ll_tol[0] - ll_tol[1] > 2.0 * e.shape[1]  # the tolerance: less, still > 2


# ---------------------------------------------------------------- endpoints

def test_beam_endpoints_skip_invalid_and_apply_laser_pose():
    cfg = sensor_cfg(range_min=0.1, range_max=8.0)
    ranges = np.array([1.0, np.nan, 0.05, 8.0, 2.0, np.inf, 7.9, 5.0, -1.0])
    angles = np.linspace(-1.0, 1.0, ranges.size)
    e = beam_endpoints(ranges, angles, 6.0, cfg, (0.2, -0.1, 0.5))  # the scan's own max_range = 6
    keep = [0, 4, 7]  # 1.0, 2.0, 5.0; 7.9 >= the scan max 6
    r, a = ranges[keep], angles[keep] + 0.5
    np.testing.assert_allclose(e, np.stack([0.2 + r * np.cos(a), -0.1 + r * np.sin(a)]), atol=1e-12)
    e2 = beam_endpoints(ranges, angles, None, cfg, (0.0, 0.0, 0.0))
    assert e2.shape == (2, 4)  # without the scan's max_range, 7.9 < range_max is a return


def test_beam_endpoints_subsample_over_all_beams_then_drop_invalid():
    cfg = sensor_cfg(max_beams=60)
    ranges = np.full(180, 3.0)
    ranges[::2] = np.inf  # every even beam has no return
    angles = np.deg2rad(np.arange(180) - 90.0)
    e = beam_endpoints(ranges, angles, None, cfg, (0.0, 0.0, 0.0))
    chosen = np.unique(np.rint(np.linspace(0, 179, 60)).astype(int))
    assert chosen.size == 60 and chosen[0] == 0 and chosen[-1] == 179
    odd = chosen[chosen % 2 == 1]
    np.testing.assert_allclose(e, np.stack([3 * np.cos(angles[odd]), 3 * np.sin(angles[odd])]), atol=1e-12)
    assert beam_endpoints(np.full(40, 3.0), np.zeros(40), None, cfg, (0, 0, 0)).shape == (2, 40)


def test_scan_endpoints_uses_scan_fields():
    cfg = sensor_cfg()
    scan = SimpleNamespace(ranges=np.array([1.0, 2.0, 20.0]), angle_min=-0.5, angle_increment=0.5,
                           max_range=None, laser_offset=np.array([0.1, 0.0, 0.0]))
    e = scan_endpoints(scan, cfg)
    np.testing.assert_allclose(e, [[0.1 + math.cos(-0.5), 2.1], [math.sin(-0.5), 0.0]], atol=1e-12)
    e = scan_endpoints(scan, sensor_cfg(laser_pose=(0.0, 0.0, 0.0)))
    np.testing.assert_allclose(e[0], [math.cos(-0.5), 2.0], atol=1e-12)


def test_same_result_with_one_and_two_threads():
    g = box_grid()
    lf = LikelihoodField(g, sensor_cfg())
    rng = np.random.default_rng(3)
    n = 70_000  # x 61 beams: above PARALLEL_MIN_WORK, so two threads do run the parallel kernel
    p = np.stack([rng.uniform(-1, 5, n), rng.uniform(-2, 2, n), rng.uniform(-np.pi, np.pi, n)])
    e = np.stack([np.linspace(-3, 3, 61), np.linspace(2, -2, 61)])
    saved = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a = lf.log_likelihood(p, e).copy()
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        b = lf.log_likelihood(p, e).copy()
    finally:
        numba.set_num_threads(saved)
    assert np.array_equal(a, b)


def test_serial_twin_gives_the_parallel_kernels_result_and_choose_picks_by_work():
    from mcl.kernels.likelihood import likelihood_field_loglik_serial
    from mcl.parallel import PARALLEL_MIN_WORK, choose

    g = box_grid()
    lf = LikelihoodField(g, sensor_cfg())
    rng = np.random.default_rng(4)
    n = 5000
    p = np.ascontiguousarray(np.stack([rng.uniform(-1, 5, n), rng.uniform(-2, 2, n), rng.uniform(-np.pi, np.pi, n)]))
    e = np.ascontiguousarray(np.stack([np.linspace(-3, 3, 61), np.linspace(2, -2, 61)]) / g.resolution)
    a, b = np.empty(n), np.empty(n)
    args = (p, e, lf.table, g.origin[0], g.origin[1], lf.inv_res, lf.offmap, 1.0)
    likelihood_field_loglik(*args, a)
    likelihood_field_loglik_serial(*args, b)
    assert np.array_equal(a, b)
    assert not likelihood_field_loglik_serial.targetoptions.get("parallel")
    assert likelihood_field_loglik.targetoptions.get("parallel")
    saved = numba.get_num_threads()
    try:
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        big = choose(likelihood_field_loglik, likelihood_field_loglik_serial, PARALLEL_MIN_WORK)
        assert big is (likelihood_field_loglik if numba.get_num_threads() > 1 else likelihood_field_loglik_serial)
        assert choose(likelihood_field_loglik, likelihood_field_loglik_serial, PARALLEL_MIN_WORK - 1) \
            is likelihood_field_loglik_serial
        numba.set_num_threads(1)
        assert choose(likelihood_field_loglik, likelihood_field_loglik_serial, 10**12) is likelihood_field_loglik_serial
    finally:
        numba.set_num_threads(saved)


def test_kernel_direct_call_writes_out():
    table = np.arange(12, dtype=np.float32).reshape(3, 4)
    p = np.array([[0.5], [0.5], [0.0]])  # cell (0, 0) with origin (0, 0), 1 m cells
    e = np.array([[0.0, 1.0, 0.0, 5.0], [0.0, 0.0, 2.0, 0.0]])  # cells (0,0), (0,1), (2,0), off-map
    out = np.full(1, np.nan)
    likelihood_field_loglik(p, e, table, 0.0, 0.0, 1.0, -100.0, 0.5, out)
    assert out[0] == pytest.approx(0.5 * (0 + 1 + 8 - 100))


def test_a_return_from_behind_furniture_the_map_still_shows_pulls_a_corridor_track_only_as_far_as_the_cap():
    # Furniture moved since the map was made: the map shows a 0.8 m box against a corridor's end wall that the world
    # no longer has, so at the true pose the beam along the corridor ends on the end wall, 0.4 m inside the box the
    # map shows. Nothing else in a straight corridor says where along it the robot is. Scored by its full depth
    # (0.35 m less the tolerance: 4.5 nats under a hit), that one beam makes a pose along the corridor, where it
    # meets the box's face, fit better than the true one by about that much (suites/heldout6.yaml's corridor: the
    # track followed, 1.1 m off). With interior_cap 0.1 m it costs at most 0.5 nats ((0.1 / sigma_hit)^2 / 2 with
    # sigma_hit 0.1; the default config's model): the true pose is within 0.55 nats of the best, and no pose more
    # than 0.1 m off beats it by more than that.
    res = 0.05
    occ = np.full((80, 480), 100, dtype=np.int8)  # x -1.5..22.5, y -1..3, walls 1 m thick or more
    occ[20:60, 30:430] = 0  # the corridor: x 0..20, y 0..2
    world = occ.copy()
    occ[32:48, 414:430] = 100  # the box the map still shows: x 19.2..20, y 0.6..1.4
    grid = OccupancyGrid.from_occupancy(occ, res, (-1.5, -1.0))
    # the scan from (5, 1, 0) in the world without the box: 61 beams over 270 degrees, ranges to the corridor's walls
    # (the beam straight ahead meets the end wall 15 m away; its neighbours, 4.5 degrees off, meet the side walls)
    angles = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 61)
    c, s_ = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (20.0 - 5.0) / c, np.where(c < 0, (0.0 - 5.0) / c, np.inf))
        ty = np.where(s_ > 0, (2.0 - 1.0) / s_, np.where(s_ < 0, (0.0 - 1.0) / s_, np.inf))
    ranges = np.minimum(tx, ty)
    e = np.ascontiguousarray(np.stack([ranges * c, ranges * s_]))
    shifts = np.round(np.arange(-1.0, 1.0001, 0.05), 2)
    poses = np.stack([5.0 + shifts, np.ones_like(shifts), np.zeros_like(shifts)])
    truth = int(np.flatnonzero(shifts == 0.0)[0])
    model = dict(z_hit=0.95, z_rand=0.05, sigma_hit=0.1, likelihood_max_dist=2.0, range_max=25.0,
                 interior="depth", interior_tolerance=None)
    full = LikelihoodField(grid, sensor_cfg(**model)).log_likelihood(poses, e)
    capped = LikelihoodField(grid, sensor_cfg(**model, interior_cap=0.1)).log_likelihood(poses, e)
    # the map without the box scores the true pose best: the pull comes from the box alone
    clean = LikelihoodField(OccupancyGrid.from_occupancy(world, res, (-1.5, -1.0)),
                            sensor_cfg(**model)).log_likelihood(poses, e)
    assert clean.argmax() == truth or clean.max() - clean[truth] < 1e-3
    assert full.max() - full[truth] > 3.0 and abs(shifts[full.argmax()]) >= 0.3, (full.max() - full[truth])
    assert capped.max() - capped[truth] <= 0.55, capped.max() - capped[truth]
    far = np.abs(shifts) > 0.1
    assert (capped[far] - capped[truth]).max() <= 0.55


def test_the_depth_table_from_the_surface_patches_is_the_one_from_the_whole_depth_field_to_the_bit():
    # _make_table builds `interior: depth` from `distance` and rewrites only the tiles OccupancyGrid.surface_patches
    # lists (no copy of the whole map); a grid without surface_patches takes surface_distance whole. Thick blocks
    # over several 128-cell tiles, one wider than a tile, and a tolerance.
    rng = np.random.default_rng(12)
    occ = np.where(rng.random((300, 420)) < 0.05, 100, 0).astype(np.int8)
    occ[10:60, 20:300] = 100
    occ[150:170, 100:130] = 100
    occ[200:290, 380:420] = 100
    g = OccupancyGrid.from_occupancy(occ, 0.05, (-1.0, 2.0))

    class Whole:  # the grid without surface_patches
        def __getattr__(self, name):
            if name == "surface_patches":
                raise AttributeError(name)
            return getattr(g, name)

    for tol, cap in ((0.0, None), (0.05, None), (0.05, 0.1)):
        cfg = sensor_cfg(interior="depth", interior_tolerance=tol, interior_cap=cap)
        patched, whole = LikelihoodField(g, cfg).table, LikelihoodField(Whole(), cfg).table
        assert len(g.surface_patches(tol)) >= 4
        np.testing.assert_array_equal(patched, whole)
        assert (patched != LikelihoodField(g, sensor_cfg(interior="zero")).table).any()
        if cap is not None:  # the cap binds on the thick blocks
            assert (patched != LikelihoodField(g, sensor_cfg(interior="depth", interior_tolerance=tol)).table).any()


@pytest.mark.parametrize("model", ["likelihood_field", "beam"])
def test_a_scan_published_clockwise_scores_as_the_same_scan_counter_clockwise(model):
    """Some ROS drivers publish LaserScan with a negative angle_increment (beam 0 on the left, turning clockwise).
    The same readings in the other order must score the same at every pose, and fit the map the same."""
    import dataclasses

    from mcl.config import PROJECT_ROOT, load_config
    from mcl.filter import ParticleFilter
    from mcl.runner import _open_source

    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [f"sensor.model={model}"])
    _, grid, scans, _, truth, _ = _open_source(cfg, echo=lambda m: None)
    pf = ParticleFilter(cfg, grid)
    s = scans[100]
    n = s.ranges.size
    cw = dataclasses.replace(s, ranges=s.ranges[::-1].copy(), angle_min=s.angle_min + (n - 1) * s.angle_increment,
                             angle_increment=-s.angle_increment)
    i = int(np.argmin(np.abs(truth.t - s.t)))
    poses = np.ascontiguousarray(truth.poses[:, i:i + 1] + np.random.default_rng(0).normal(0.0, 0.2, (3, 200)))
    at = np.zeros(3)
    ccw_obs, cw_obs = pf.prepare(s, at), pf.prepare(cw, at)
    a, b = pf.sensor.log_likelihood(poses, ccw_obs), pf.sensor.log_likelihood(poses, cw_obs)
    assert np.ptp(a) > 10.0  # the poses are told apart (measured: tens of nats)
    np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-9)
    fa = pf.quality.fit(truth.poses[:, i], pf.sensor.endpoints(ccw_obs), at[:2])
    fb = pf.quality.fit(truth.poses[:, i], pf.sensor.endpoints(cw_obs), at[:2])
    assert (fa.beams, fa.match, fa.contradiction) == (fb.beams, fb.match, fb.contradiction) and fa.beams > 40


# ---------------------------------------------------------------- no-return readings (negative information)

def corridor_grid():
    """A corridor 30 m long and 2 m wide (0.05 m cells, walls at y = +-1.0 m, an end wall at x = 30 m)."""
    occ = np.zeros((44, 620), dtype=np.int8)
    occ[1, :601] = occ[42, :601] = 100
    occ[1:43, 0] = occ[1:43, 600] = 100
    return OccupancyGrid.from_occupancy(occ, 0.05, (0.0, -1.075))


def corridor_scan():
    """Facing down the corridor from its axis: three beams straight ahead read no return (12 m, the laser's
    maximum), the beams 30-90 degrees to either side return from the side walls; the rest invalid."""
    angles = np.deg2rad(np.array([-90.0, -60.0, -30.0, -2.0, 0.0, 2.0, 30.0, 60.0, 90.0, 10.0]))
    ranges = np.array([1.0, 1.0 / math.sin(math.radians(60.0)), 2.0, 12.0, 12.0, 12.0, 2.0,
                       1.0 / math.sin(math.radians(60.0)), 1.0, np.nan])
    return SimpleNamespace(ranges=ranges, angles=angles, max_range=12.0)


@pytest.mark.parametrize("share", [0.0, 0.3])
def test_no_returns_tell_apart_places_the_returns_cannot(share):
    # At x = 10 m the end wall is 20 m ahead, out of the laser's 12 m; at x = 22 m it is 8 m ahead. The side walls'
    # returns fit both places alike, so the likelihood field cannot tell them apart; the three no-returns straight
    # ahead say the end wall is not within reach (0.9 x 12 m): log(no_return_miss) each at x = 22 m.
    g = corridor_grid()
    p = np.array([[10.0, 22.0], [0.0, 0.0], [0.0, 0.0]])
    off = LikelihoodField(g, sensor_cfg(range_max=80.0, no_return_miss=0.0, no_return_reach=0.9,
                                        no_return_share=share))
    plain = off.log_likelihood(p, off.prepare(corridor_scan(), (0.0, 0.0, 0.0)))
    assert plain[0] == pytest.approx(plain[1], abs=1e-9)
    on = LikelihoodField(g, sensor_cfg(range_max=80.0, no_return_miss=0.1, no_return_reach=0.9,
                                       no_return_share=share))
    obs = on.prepare(corridor_scan(), (0.0, 0.0, 0.0))
    assert obs.free.shape == (4, 3) and obs.reach == pytest.approx(10.8)
    ll = on.log_likelihood(p, obs)
    assert ll[0] == pytest.approx(plain[0], abs=1e-9)  # nothing within reach ahead: the same score
    assert ll[1] - ll[0] == pytest.approx(3 * math.log(0.1), abs=1e-9)
    # a wall 11 m ahead is beyond the reach (10.8 m): no evidence
    assert on.log_likelihood(np.array([[19.0], [0.0], [0.0]]), obs)[0] == pytest.approx(plain[0], abs=1e-9)
    # the selection of endpoints (unmapped objects, beam skipping) keeps the no-return rays
    assert obs[:, :2].free is obs.free


def test_no_returns_are_scored_only_in_a_sparse_view():
    # 3 no-returns of the 10 scored beams: under no_return_share 0.5 the scan is scored by its returns alone
    on = LikelihoodField(corridor_grid(), sensor_cfg(range_max=80.0, no_return_miss=0.1, no_return_reach=0.9,
                                                     no_return_share=0.5))
    obs = on.prepare(corridor_scan(), (0.0, 0.0, 0.0))
    assert getattr(obs, "free", None) is None
    p = np.array([[10.0, 22.0], [0.0, 0.0], [0.0, 0.0]])
    ll = on.log_likelihood(p, obs)
    assert ll[0] == pytest.approx(ll[1], abs=1e-9)


def test_no_return_rays_follow_the_laser_mounting_and_the_sweep():
    from mcl.sensors import no_return_rays

    cfg = sensor_cfg(range_max=80.0)
    rays = no_return_rays(np.array([1.0, 12.0, np.inf, np.nan]), np.array([-0.5, 0.0, 0.5, 1.0]), 12.0, cfg,
                          (0.2, 0.1, 0.3))
    np.testing.assert_allclose(rays, [[0.2, 0.2], [0.1, 0.1], [math.cos(0.3), math.cos(0.8)],
                                      [math.sin(0.3), math.sin(0.8)]], atol=1e-12)
    # a sweep: beam j taken tau_j s after the stamp while the robot moved at (vx, vy, omega)
    tau = np.array([0.0, 0.05, 0.1, 0.15])
    rays = no_return_rays(np.array([1.0, 12.0, np.inf, np.nan]), np.array([-0.5, 0.0, 0.5, 1.0]), 12.0, cfg,
                          (0.0, 0.0, 0.0), (tau, (1.0, 0.0, 2.0)))
    np.testing.assert_allclose(rays, [[0.05, 0.1], [0.0, 0.0], [math.cos(0.1), math.cos(0.7)],
                                      [math.sin(0.1), math.sin(0.7)]], atol=1e-12)


def test_no_return_kernel_gives_the_same_with_one_and_two_threads():
    from mcl.kernels.likelihood import free_ray_loglik, free_ray_loglik_serial

    g = corridor_grid()
    dist = np.ascontiguousarray(g.distance, dtype=np.float32)
    rng = np.random.default_rng(5)
    n = 20_000
    p = np.stack([rng.uniform(0.5, 29.5, n), rng.uniform(-0.9, 0.9, n), rng.uniform(-np.pi, np.pi, n)])
    ang = np.linspace(-1.5, 1.5, 31)
    rays = np.ascontiguousarray(np.stack([np.full(31, 0.1), np.zeros(31), np.cos(ang), np.sin(ang)]))
    a, b = np.zeros(n), np.zeros(n)
    free_ray_loglik_serial(p, rays, dist, g.origin[0], g.origin[1], 1.0 / g.resolution, 10.8, -2.0, 1.0, a)
    saved = numba.get_num_threads()
    try:
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        free_ray_loglik(p, rays, dist, g.origin[0], g.origin[1], 1.0 / g.resolution, 10.8, -2.0, 1.0, b)
    finally:
        numba.set_num_threads(saved)
    assert np.array_equal(a, b)
    assert a.min() < -2.0 * 20 and a.max() <= 0.0  # most rays meet a wall within 10.8 m of a 2 m corridor


def test_the_field_with_no_random_readings_stays_finite_far_from_walls():
    # z_rand = 0 and a small sigma_hit: exp(-(d/sigma)^2 / 2) underflowed to 0 past 38.6 sigma, so the table held
    # -inf where the model's log-density is finite (-5e11 at 1 m for sigma 1 um): on the demo every update's weights
    # were all zero (350 degenerate updates, 88 re-seeds, 78 s). Now those cells take the log-space value; every
    # other cell, and every z_rand > 0 table, is the formula as before to the bit.
    import types

    from mcl.sensors import point_log_likelihood

    d = np.array([0.0, 1e-6, 1e-4, 0.05, 1.0, 5.0])
    cfg = types.SimpleNamespace(sigma_hit=1e-6, likelihood_max_dist=2.0, z_hit=1.0, z_rand=0.0, range_max=30.0)
    got = point_log_likelihood(d, cfg)
    dd = np.minimum(d, 2.0)
    want = -0.5 * (dd / 1e-6) ** 2 - math.log(math.sqrt(2 * math.pi) * 1e-6)
    assert np.all(np.isfinite(got)) and got == pytest.approx(want, rel=1e-12)
    assert np.all(np.diff(got) < 0)  # farther is always less likely: the ordering a filter needs
    cfg = types.SimpleNamespace(sigma_hit=0.2, likelihood_max_dist=2.0, z_hit=0.9, z_rand=0.1, range_max=30.0)
    gauss = np.exp(-0.5 * (dd / 0.2) ** 2) / (math.sqrt(2 * math.pi) * 0.2)
    assert np.array_equal(point_log_likelihood(d, cfg), np.log(0.9 * gauss + 0.1 / 30.0))


def test_a_run_says_when_a_map_drawn_solid_takes_the_depth_tolerance_off():
    # one note line naming the map and the share, only when null decides (the depth field, centre, no number)
    from mcl.config import PROJECT_ROOT, load_config
    from mcl.runner import _solid_map_note

    default = PROJECT_ROOT / "configs" / "default.yaml"
    cfg = load_config(default)
    solid, thin = solid_grid(0.05), thin_walled_grid(0.05)
    note = _solid_map_note(cfg, solid)
    assert note is not None and note.startswith("<memory>: walls drawn solid (90% ") and "interior_tolerance" in note
    assert _solid_map_note(cfg, thin) is None and _solid_map_note(cfg, solid_grid(0.1)) is None
    for key in ("interior_tolerance=0.05", "surface=face", "interior=zero"):
        assert _solid_map_note(load_config(default, [f"sensor.likelihood_field.{key}"]), solid) is None, key


def test_an_out_buffer_of_another_shape_is_refused_not_written_past():
    # A buffer reused after KLD sampling changed N: the kernel wrote N values into 3 (a segfault, or an array of
    # shape (-4577948489428762624,) first). Now a ValueError naming out; the right buffer is filled.
    lf = LikelihoodField(box_grid(), sensor_cfg())
    p = np.zeros((3, 50))
    p[0], p[1] = 1.0, 0.5
    e = np.array([[1.0, 0.5], [0.0, 0.3]])
    for bad in (np.empty(3), np.empty(50, dtype=np.float32), np.empty(100)[::2], np.empty((50, 1))):
        with pytest.raises(ValueError, match=r"^out: expected a writeable C-contiguous float64 array of shape \(50,\)"):
            lf.log_likelihood(p, e, out=bad)
    good = np.empty(50)
    assert lf.log_likelihood(p, e, out=good) is good
    np.testing.assert_allclose(good, lf.log_likelihood(p, e))
