"""Map loading (ROS map_server semantics), geometry, distance field, free sampling, saving."""

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image
from scipy import stats

from mcl.errors import DataError
from mcl.maps import OccupancyGrid, load_map, save_map

DATA = Path(__file__).parents[2] / "shared" / "data"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"real datasets not found at {DATA}")

YAML = """image: {image}
resolution: {resolution}
origin: {origin}
negate: {negate}
occupied_thresh: {occ}
free_thresh: {free}
"""


def write_map(tmp_path, pixels, fmt="pgm", name="m", mode=None, negate=0, origin="[1.0, 2.0, 0.0]",
              resolution=0.5, occ=0.65, free=0.196, pil_mode=None):
    """Write an image (row 0 = top) and its YAML; returns the YAML path."""
    img_name = f"{name}.{fmt}"
    pixels = np.asarray(pixels, dtype=np.uint8)
    if fmt == "p2":
        img_name = f"{name}.pgm"
        h, w = pixels.shape
        body = "\n".join(" ".join(str(v) for v in row) for row in pixels)
        (tmp_path / img_name).write_text(f"P2\n# plain pgm\n{w} {h}\n255\n{body}\n")
    else:
        Image.fromarray(pixels, mode=pil_mode).save(tmp_path / img_name)
    text = YAML.format(image=img_name, resolution=resolution, origin=origin, negate=negate, occ=occ, free=free)
    if mode is not None:
        text += f"mode: {mode}\n"
    y = tmp_path / f"{name}.yaml"
    y.write_text(text)
    return y


PIX = np.array([[0, 254, 205], [100, 128, 255]], dtype=np.uint8)  # image row 0 = top


def ros_expected(v, mode, negate=False, occ=0.65, free=0.196):
    """Straight transcription of ROS map_server for one grey value."""
    return ros1_pixel([v], False, mode, negate, occ, free)


def ros1_pixel(channels, has_alpha, mode, negate=False, occ_th=0.65, free_th=0.196):
    """ROS 1 map_server's loop (navigation/map_server/src/image_loader.cpp) for one pixel as SDL_image lays it out
    (grey: 1 channel; grey + alpha: RGBA; RGB; RGBA). Where mcl departs from it: raw mode is nav2's (no negate,
    -1 above 100), and an RGB pixel has no alpha (ROS 1 reads its blue byte as the alpha)."""
    n = len(channels)
    avg_channels = n if (mode == "trinary" or not has_alpha) else n - 1
    color_avg = sum(int(c) for c in channels[:avg_channels]) / float(avg_channels)
    alpha = int(channels[-1]) if has_alpha else 1
    if mode == "raw":
        return int(color_avg) if color_avg <= 100 else -1
    if negate:
        color_avg = 255 - color_avg
    occ = (255 - color_avg) / 255.0
    if occ > occ_th:
        return 100
    if occ < free_th:
        return 0
    if mode == "trinary" or alpha < 1.0:
        return -1
    return int(1 + 98 * (occ - free_th) / (occ_th - free_th))  # the C++ cast into an unsigned char: truncation


@pytest.mark.parametrize("fmt", ["pgm", "p2", "png"])
@pytest.mark.parametrize("mode", ["trinary", "scale", "raw"])
@pytest.mark.parametrize("negate", [0, 1])
def test_modes_formats_negate(tmp_path, fmt, mode, negate):
    grid = load_map(write_map(tmp_path, PIX, fmt=fmt, mode=mode, negate=negate))
    expected = np.array([[ros_expected(int(v), mode, bool(negate)) for v in row] for row in PIX[::-1]])
    assert grid.occupancy.dtype == np.int8 and grid.occupancy.shape == (2, 3)
    np.testing.assert_array_equal(grid.occupancy, expected)
    assert grid.resolution == 0.5 and grid.origin == (1.0, 2.0)
    assert grid.width == 3 and grid.height == 2


def test_trinary_values_explicitly(tmp_path):
    grid = load_map(write_map(tmp_path, PIX))
    # bottom row first: image row 1 = [100, 128, 255], row 0 = [0, 254, 205]
    np.testing.assert_array_equal(grid.occupancy, [[-1, -1, 0], [100, 0, -1]])
    np.testing.assert_array_equal(grid.occupied, [[False, False, False], [True, False, False]])
    np.testing.assert_array_equal(grid.free, [[False, False, True], [False, True, False]])
    np.testing.assert_array_equal(grid.unknown, ~(grid.occupied | grid.free))


def test_scale_value_and_alpha(tmp_path):
    rgba = np.zeros((1, 3, 4), dtype=np.uint8)
    rgba[0, :, :3] = 128
    rgba[0, :, 3] = [255, 0, 255]
    rgba[0, 2, :3] = 0  # black, opaque: occupied
    grid = load_map(write_map(tmp_path, rgba, fmt="png", mode="scale"))
    ratio = ((255 - 128) / 255 - 0.196) / (0.65 - 0.196)
    assert grid.occupancy[0, 0] == int(1 + 98 * ratio) == 66  # ROS 1's rule (it was int(99 * ratio) = 65)
    assert grid.occupancy[0, 1] == -1  # alpha 0 -> unknown in scale mode
    assert grid.occupancy[0, 2] == 100


def test_scale_mode_keeps_the_in_between_pixels_off_the_free_cells(tmp_path):
    # ROS 1: 1 + 98 * ratio, so map_saver's unknown grey 205 (just above free_thresh) is 1, not 0 (free); and 1..99
    # are neither free nor occupied, as AMCL reads them (205 and 200 were free cells before: 0, and 4 < 19.6)
    grid = load_map(write_map(tmp_path, np.array([[0, 205, 254, 128, 200]], np.uint8), mode="scale"))
    assert grid.occupancy[0].tolist() == [100, 1, 0, 66, 5]
    assert grid.free[0].tolist() == [False, False, True, False, False]
    assert grid.occupied[0].tolist() == [True, False, False, False, False]
    # alpha 0 makes only an in-between pixel unknown (ROS 1): transparent black and white stay occupied and free
    rgba = np.array([[[0, 0, 0, 0], [255, 255, 255, 0], [205, 205, 205, 0], [205, 205, 205, 255]]], np.uint8)
    grid = load_map(write_map(tmp_path, rgba, fmt="png", mode="scale", name="a"))
    assert grid.occupancy[0].tolist() == [100, 0, -1, 1]


def test_trinary_mode_averages_the_alpha_in_as_a_double(tmp_path):
    # ROS 1 and nav2 average the alpha channel in with the colours in trinary mode, as a double: transparent white
    # (mean 191.25) is unknown, opaque grey 205 (217.5) free; an RGB mean of 205.33 is free (205 was unknown)
    rgba = np.array([[[255, 255, 255, 0], [205, 205, 205, 255], [254, 254, 254, 255], [0, 0, 0, 255],
                      [205, 205, 206, 255]]], np.uint8)
    assert load_map(write_map(tmp_path, rgba, fmt="png")).occupancy[0].tolist() == [-1, 0, 0, 100, 0]
    rgb = np.ascontiguousarray(rgba[..., :3])
    assert load_map(write_map(tmp_path, rgb, fmt="png", name="rgb")).occupancy[0].tolist() == [0, -1, 0, 100, 0]
    # grey + alpha is RGBA to SDL_image: (3 v + a) / 4; opaque black 63.75 is still occupied, opaque 205 free,
    # transparent 205 (153.75) unknown (205 alone was unknown every time: the alpha was dropped)
    la = np.array([[[0, 255], [205, 255], [205, 0], [254, 255]]], np.uint8)
    assert load_map(write_map(tmp_path, la, fmt="png", name="la")).occupancy[0].tolist() == [100, 0, -1, 0]
    # in scale and raw modes the alpha is left out
    assert load_map(write_map(tmp_path, la, fmt="png", name="las", mode="scale")).occupancy[0].tolist() == \
        [100, 1, -1, 0]


def test_a_palette_image_is_read_by_its_colours_with_alpha_only_where_it_has_transparency(tmp_path):
    grey = np.array([[0, 205, 254]], np.uint8)
    Image.fromarray(grey).convert("P").save(tmp_path / "p.png")  # no transparency: no alpha to average in
    y = write_map(tmp_path, grey, fmt="png")
    y.write_text(y.read_text().replace("m.png", "p.png"))
    assert load_map(y).occupancy[0].tolist() == [100, -1, 0]
    im = Image.fromarray(grey).convert("P")
    im.info["transparency"] = int(np.asarray(im)[0, 2])  # the free pixel's index transparent: alpha 0
    im.save(tmp_path / "p.png", transparency=im.info["transparency"])
    assert load_map(y).occupancy[0].tolist() == [100, 0, -1]  # (0+0+0+255)/4 = 63.75; 205 opaque; 254 * 3 / 4


def test_colour_channels_are_averaged(tmp_path):
    rgb = np.array([[[255, 0, 0], [0, 255, 255], [254, 254, 254]]], dtype=np.uint8)
    grid = load_map(write_map(tmp_path, rgb, fmt="png"))
    # means 85 (p=0.667 -> occupied), 170 (p=0.333 -> unknown), 254 (free)
    np.testing.assert_array_equal(grid.occupancy, [[100, -1, 0]])


def test_row_flip_top_left_pixel_lands_at_top_left_corner(tmp_path):
    img = np.full((4, 5), 254, dtype=np.uint8)
    img[0, 0] = 0
    grid = load_map(write_map(tmp_path, img, origin="[10.0, 20.0, 0]", resolution=0.5))
    x_left, y_top = 10.0, 20.0 + 4 * 0.5
    ix, iy = grid.world_to_cell(x_left + 0.1, y_top - 0.1)
    assert (int(ix), int(iy)) == (0, 3)
    assert grid.occupancy[iy, ix] == 100
    assert grid.occupied.sum() == 1 and grid.occupancy[3, 0] == 100


def test_world_cell_round_trip():
    grid = OccupancyGrid.from_occupancy(np.zeros((30, 40), np.int8), 0.05, (-1.3, 2.7))
    ix, iy = np.meshgrid(np.arange(40), np.arange(30))
    x, y = grid.cell_to_world(ix, iy)
    ix2, iy2 = grid.world_to_cell(x, y)
    np.testing.assert_array_equal(ix2, ix)
    np.testing.assert_array_equal(iy2, iy)
    assert ix2.dtype == np.int64
    # floor semantics at and outside the edges
    ix3, iy3 = grid.world_to_cell([-1.3, -1.3 - 1e-9, -1.3 + 40 * 0.05 + 1e-9], [2.7, 2.7, 2.7])
    np.testing.assert_array_equal(ix3, [0, -1, 40])
    np.testing.assert_array_equal(grid.contains(ix3, iy3), [True, False, False])


def test_distance_field_against_brute_force():
    rng = np.random.default_rng(3)
    occ = np.where(rng.random((7, 9)) < 0.15, 100, 0).astype(np.int8)
    occ[0, 0] = 100
    occ[3, 4] = -1
    grid = OccupancyGrid.from_occupancy(occ, 0.1, (0.0, 0.0))
    oy, ox = np.nonzero(occ == 100)
    iy, ix = np.mgrid[0:7, 0:9]
    brute = np.min(np.hypot(ix[..., None] - ox, iy[..., None] - oy), axis=-1) * 0.1
    assert grid.distance.dtype == np.float32 and grid.distance.shape == (7, 9)
    np.testing.assert_allclose(grid.distance, brute, rtol=1e-6)
    assert np.all(grid.distance[occ == 100] == 0)


def test_surface_distance_is_depth_inside_obstacles_against_brute_force():
    """Off the obstacles the same as ``distance``; on an occupied cell the distance to the nearest non-occupied
    cell centre less one cell, so a wall's face is 0 and a block's interior grows by one cell per cell."""
    rng = np.random.default_rng(4)
    occ = np.where(rng.random((12, 14)) < 0.15, 100, 0).astype(np.int8)
    occ[2:10, 1:10] = 0
    occ[3:9, 2:9] = 100  # a 6 x 7 block in free space: depth up to 2 cells
    occ[10, 10] = -1
    grid = OccupancyGrid.from_occupancy(occ, 0.1, (0.0, 0.0))
    sd = grid.surface_distance()
    assert sd.dtype == np.float32 and sd.shape == occ.shape
    off = occ != 100
    np.testing.assert_array_equal(sd[off], grid.distance[off])
    ny, nx = np.nonzero(off)
    iy, ix = np.mgrid[0:12, 0:14]
    brute = (np.min(np.hypot(ix[..., None] - nx, iy[..., None] - ny), axis=-1) - 1.0) * 0.1
    np.testing.assert_allclose(sd[~off], np.maximum(brute[~off], 0.0), rtol=1e-6, atol=1e-7)
    assert sd[5, 5] == pytest.approx(0.2) and sd[3, 5] == 0.0  # the block's centre 2 cells in; its face 0
    # a tolerance takes that much off every depth (not below 0), and only on the obstacles
    st = grid.surface_distance(0.15)
    np.testing.assert_array_equal(st[off], sd[off])
    np.testing.assert_allclose(st[~off], np.maximum(sd[~off] - 0.15, 0.0), atol=1e-6)
    assert st[5, 5] == pytest.approx(0.05) and grid.surface_distance() is sd  # cached per tolerance


def test_surface_distance_by_tiles_is_exact_when_obstacles_are_deeper_than_the_window():
    """A cell within ``margin`` cells of a non-occupied one takes its depth from the ring search; a tile with a
    deeper cell runs the transform in a window ``margin`` cells wider, and from the first tile whose obstacle is
    deeper than that window on, the whole map's transform: each way the reference (scipy.ndimage's exact transform
    to the nearest non-occupied cell)."""
    from scipy.ndimage import distance_transform_edt

    rng = np.random.default_rng(7)
    occ = np.where(rng.random((120, 150)) < 0.2, 100, 0).astype(np.int8)
    occ[5:30, 8:38] = 100  # 25 x 30 cells: depth up to 13 cells, past a margin of 2
    occ[60:66, 100:106] = 100  # 6 x 6: depth 3, within a margin of 3 only
    occ[0:3, :] = 100  # along the map's edge: off the map is not a free cell
    occ[100, 140] = -1
    grid = OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))
    brute = np.maximum(distance_transform_edt(occ == 100) - 1.0 - 0.5, 0.0) * 0.05
    on = occ == 100
    # (8, 2): windows, then the whole map from the big block's first tile on; (8, 3): windows exact for the
    # small block too; (4, 1) and (128, 16): other tile and window sizes
    for tile, margin in ((8, 2), (8, 3), (4, 1), (128, 16)):
        sd = grid._surface_distance(0.5, tile=tile, margin=margin)
        np.testing.assert_allclose(sd[on], brute[on], rtol=1e-6, atol=1e-7)
        np.testing.assert_array_equal(sd[~on], grid.distance[~on])
    assert sd[17, 22] == pytest.approx((13 - 1.5) * 0.05)  # 13 cells from row 4 and row 30
    # a map with no non-occupied cell: no depth to measure, 0 everywhere as AMCL's field has it
    full = OccupancyGrid.from_occupancy(np.full((6, 7), 100, np.int8), 0.05, (0.0, 0.0))
    assert np.all(full._surface_distance(0.0, tile=4, margin=1) == 0.0)
    assert np.all(full._surface_distance(0.0, tile=2, margin=1) == 0.0)


def test_distance_is_scipys_euclidean_transform_to_the_bit():
    # The edt package replaced scipy.ndimage.distance_transform_edt (7x faster on a 250 m map): the likelihood
    # table, and so every trajectory, must stay what it was. A random grid with a thick block and map edges.
    from scipy.ndimage import distance_transform_edt

    rng = np.random.default_rng(7)
    occ = np.where(rng.random((300, 257)) < 0.01, 100, 0).astype(np.int8)
    occ[100:160, 50:120] = 100
    grid = OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))
    scipy_d = (distance_transform_edt(occ != 100) * 0.05).astype(np.float32)
    np.testing.assert_array_equal(grid.distance, scipy_d)


def test_a_map_image_over_pillows_bomb_limit_loads_and_the_limit_is_restored(tmp_path, monkeypatch):
    # Pillow warns above 89 M pixels and refuses above 179 M (its guard against images from the web); a 500 m map
    # at 5 cm has 100 M. Here the limit is lowered to 100 pixels for a 20 x 30 map (600: "bomb" error territory).
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 100)
    occ = np.zeros((20, 30), np.int8)
    occ[0] = 100
    save_map(OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0)), tmp_path / "m.yaml")
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        grid = load_map(tmp_path / "m.yaml")
    np.testing.assert_array_equal(grid.occupancy, occ)
    assert Image.MAX_IMAGE_PIXELS == 100


def test_distance_without_obstacles_is_large():
    grid = OccupancyGrid.from_occupancy(np.zeros((3, 4), np.int8), 0.5, (0, 0))
    assert np.all(grid.distance >= math.hypot(3, 4) * 0.5)


def two_region_grid():
    occ = np.full((10, 20), -1, np.int8)
    occ[:, 0:5] = 0      # 50 free cells
    occ[:, 5] = 100
    occ[:, 10:20] = 0    # 100 free cells
    return OccupancyGrid.from_occupancy(occ, 0.1, (-1.0, 0.5))


def test_sample_free_only_free_cells_and_uniform():
    grid = two_region_grid()
    rng = np.random.default_rng(42)
    n = 30000
    s = grid.sample_free(n, rng)
    assert s.shape == (3, n) and s.dtype == np.float64
    ix, iy = grid.world_to_cell(s[0], s[1])
    assert grid.contains(ix, iy).all()
    assert grid.free[iy, ix].all()
    assert s[2].min() >= -math.pi and s[2].max() < math.pi
    left = int((ix < 5).sum())
    # Chi-square on the two regions (1:2 by cell count); fixed seed, reject only at p < 0.001.
    res = stats.chisquare([left, n - left], [n / 3, 2 * n / 3])
    assert res.pvalue > 1e-3, (left, res)
    # Within cells: positions uniform (fractional part of the cell coordinate), KS at p > 0.001.
    frac = (s[0] - grid.origin[0]) / grid.resolution % 1.0
    assert stats.kstest(frac, "uniform").pvalue > 1e-3
    # and every free cell gets visited
    hits = np.zeros(grid.occupancy.shape, bool)
    hits[iy, ix] = True
    np.testing.assert_array_equal(hits, grid.free)


def test_sample_free_clearance_and_no_cell():
    grid = two_region_grid()
    s = grid.sample_free(2000, np.random.default_rng(1), clearance=0.25)
    ix, iy = grid.world_to_cell(s[0], s[1])
    assert np.all(grid.distance[iy, ix] > 0.25)
    # the wall is column 5: columns 3, 4, 6, 7 are within 0.2 m of it
    assert ((ix <= 2) | (ix >= 8)).all()
    assert (ix <= 2).any() and (ix >= 8).any()
    with pytest.raises(DataError, match="no free cell"):
        grid.sample_free(10, np.random.default_rng(1), clearance=100.0)


def test_save_map_round_trip(tmp_path):
    occ = np.array([[100, 0, -1, 0], [0, 0, 100, -1], [-1, -1, 0, 0]], np.int8)
    grid = OccupancyGrid.from_occupancy(occ, 0.05, (-3.25, 1.125))
    save_map(grid, tmp_path / "out.yaml")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.pgm", "out.yaml"]
    raw = (tmp_path / "out.pgm").read_bytes()
    assert raw.startswith(b"P5")
    img = np.asarray(Image.open(tmp_path / "out.pgm"))
    np.testing.assert_array_equal(img[0], [205, 205, 254, 254])  # image row 0 = top = grid row 2
    back = load_map(tmp_path / "out.yaml")
    np.testing.assert_array_equal(back.occupancy, occ)
    assert back.resolution == 0.05 and back.origin == (-3.25, 1.125)


# --- malformed files ---------------------------------------------------------

def test_missing_key(tmp_path):
    y = write_map(tmp_path, PIX)
    y.write_text("\n".join(l for l in y.read_text().splitlines() if not l.startswith("resolution")))
    with pytest.raises(DataError, match=r"m\.yaml: resolution: missing"):
        load_map(y)


def _world_of_cells(h, w, res, origin, yaw):
    """World centres (x, y) of every cell (i, j) of an (h, w) map whose lower-left cell sits at ``origin`` turned by
    ``yaw`` (map_server's origin: [x, y, yaw])."""
    i, j = np.mgrid[0:h, 0:w]
    lx, ly = (j + 0.5) * res, (i + 0.5) * res
    c, s = math.cos(yaw), math.sin(yaw)
    return origin[0] + c * lx - s * ly, origin[1] + s * lx + c * ly


@pytest.mark.parametrize("yaw", [math.pi / 2, math.pi, -math.pi / 2, 0.3, -2.0, 2.5])
def test_a_rotated_origin_puts_each_cell_where_map_server_says(tmp_path, yaw):
    # map_server's origin [x, y, yaw] turns the image about its lower-left corner; the map was refused before.
    # Blocks of 4 x 4 pixels, each its own value: the centre of every block lands on that block's value (a quarter
    # turn is exact: every cell); the nearest-cell resampling may move a block's edge by one cell, never its centre.
    rng = np.random.default_rng(3)
    blocks = rng.choice(np.array([0, 254, 205], dtype=np.uint8), size=(5, 7))
    pixels = np.kron(blocks, np.ones((4, 4), dtype=np.uint8))
    g = load_map(write_map(tmp_path, pixels, origin=f"[1.0, 2.0, {yaw!r}]", resolution=0.1))
    flat = load_map(write_map(tmp_path, pixels, name="flat", resolution=0.1))
    expect = flat.occupancy  # the same image unturned, row 0 at the bottom
    h, w = expect.shape
    x, y = _world_of_cells(h, w, 0.1, (1.0, 2.0), yaw)
    ix, iy = g.world_to_cell(x, y)
    assert g.contains(ix, iy).all()
    # a user coming from AMCL (which ignores the yaw) hears of it; mcl run prints the grid's notes
    assert g.notes == (f"{g.path}: origin yaw {yaw:g} rad: the map is turned about its lower-left corner, as ROS "
                       "map_server defines the origin (AMCL ignores the yaw)",) and flat.notes == ()
    got = g.occupancy[iy, ix]
    quarter = abs(yaw / (math.pi / 2) - round(yaw / (math.pi / 2))) < 1e-12
    centre = np.zeros((h, w), dtype=bool)
    centre[1::4, 1::4] = centre[2::4, 2::4] = True  # two cells about each block's centre
    if quarter:
        np.testing.assert_array_equal(got, expect)
        assert g.occupancy.size == expect.size
    else:
        np.testing.assert_array_equal(got[centre], expect[centre])
        assert np.mean(got == expect) > 0.9
        # outside the turned image every cell is unknown
        assert np.count_nonzero(g.occupancy != -1) <= expect.size * 1.05


@pytest.mark.parametrize("occ,free,key", [(1.5, 0.196, "occupied_thresh"), (0.65, -0.1, "free_thresh"),
                                          (0.3, 0.5, "free_thresh"), ("high", 0.1, "occupied_thresh")])
def test_bad_thresholds(tmp_path, occ, free, key):
    y = write_map(tmp_path, PIX, occ=occ, free=free)
    with pytest.raises(DataError, match=rf"m\.yaml: {key}: "):
        load_map(y)


def test_truncated_image(tmp_path):
    y = write_map(tmp_path, np.full((50, 60), 254, np.uint8))
    img = tmp_path / "m.pgm"
    img.write_bytes(img.read_bytes()[:500])
    with pytest.raises(DataError, match=r"m\.yaml: image: .*m\.pgm") as e:
        load_map(y)
    assert "\n" not in str(e.value)


def test_corrupt_image(tmp_path):
    y = write_map(tmp_path, PIX, fmt="png")
    (tmp_path / "m.png").write_bytes(b"\x89PNG\r\n\x1a\nnot really a png")
    with pytest.raises(DataError, match=r"m\.yaml: image: .*m\.png"):
        load_map(y)


def test_missing_image(tmp_path):
    y = write_map(tmp_path, PIX)
    (tmp_path / "m.pgm").unlink()
    with pytest.raises(DataError, match=r"m\.yaml: image: .*m\.pgm"):
        load_map(y)


@pytest.mark.parametrize("text,key", [
    ("- a\n- b\n", "mapping"),
    ("image: [\n", "m.yaml:"),
    ("image: m.pgm\nresolution: -1\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.1\n", "resolution"),
    ("image: m.pgm\nresolution: 0.1\norigin: [0, a, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.1\n", "origin"),
    ("image: m.pgm\nresolution: 0.1\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.1\nmode: bogus\n",
     "mode"),
    ("image: m.pgm\nresolution: 0.1\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.1\nnegate: 2\n",
     "negate"),
    ("image: 3\nresolution: 0.1\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.1\n", "image"),
])
def test_bad_yaml(tmp_path, text, key):
    write_map(tmp_path, PIX)
    y = tmp_path / "m.yaml"
    y.write_text(text)
    with pytest.raises(DataError, match="m.yaml") as e:
        load_map(y)
    assert key in str(e.value) and "\n" not in str(e.value)


def test_an_empty_or_non_image_file_is_one_line_naming_it(tmp_path):
    y = write_map(tmp_path, PIX)
    (tmp_path / "m.pgm").write_bytes(b"")
    with pytest.raises(DataError, match=r"m\.yaml: image: .*m\.pgm: empty file$"):
        load_map(y)
    (tmp_path / "m.pgm").write_text("image: m.pgm\n")
    with pytest.raises(DataError, match=r"m\.yaml: image: .*m\.pgm: not an image file") as e:
        load_map(y)
    assert "BytesIO" not in str(e.value)  # was "cannot identify image file <_io.BytesIO object at 0x...>"


def test_a_resolution_too_fine_to_index_is_refused_by_name_without_numpy_warnings(tmp_path):
    import warnings

    for res in ("1e-300", "1.0e-20", "9e-7"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(DataError, match=r"m\.yaml: resolution: must be at least 1e-06 m a cell, got "):
                load_map(write_map(tmp_path, PIX, resolution=res))
    assert load_map(write_map(tmp_path, PIX, resolution="1e-6")).resolution == 1e-6


def test_numbers_in_quotes_are_numbers_as_ros_reads_them(tmp_path):
    # yaml-cpp converts any scalar: resolution: "0.05" is 0.05 to map_server; it was refused while "5e-2" was not
    y = write_map(tmp_path, PIX, resolution='"0.05"', occ='"0.65"', free="'0.196'", origin='["1.5", "-2", "0"]',
                  negate='"1"')
    g = load_map(y)
    want = load_map(write_map(tmp_path, PIX, name="plain", resolution=0.05, origin="[1.5, -2, 0]", negate=1))
    assert (g.resolution, g.origin) == (0.05, (1.5, -2.0))
    np.testing.assert_array_equal(g.occupancy, want.occupancy)
    assert load_map(write_map(tmp_path, PIX, resolution='"5e-2"')).resolution == 0.05
    for key, bad in (("resolution", '"abc"'), ("resolution", '"nan"'), ("occ", '"inf"'), ("free", '"1_0"'),
                     ("origin", '["1", "x", 0]'), ("negate", '"2"'), ("negate", '"yes"')):
        with pytest.raises(DataError, match=r"m\.yaml: (resolution|occupied_thresh|free_thresh|origin|negate): "):
            load_map(write_map(tmp_path, PIX, **{key: bad}))


@pytest.mark.parametrize("fmt", ["P5", "P2"])
def test_a_pgm_is_scaled_by_the_maxval_of_its_header(tmp_path, fmt):
    # 16 bits: v * 255 / maxval rounded, whatever the pixels' values (a dark image of values <= 255 out of 65535
    # was taken as 8-bit and came out mixed); maxval < 255: v * 255 // maxval as SDL_image (ROS 1) has it (Pillow
    # rounds: 50 of 62 is 205.6, unknown to ROS 1, free when rounded to 206)
    def pgm(maxval, values):
        y = write_map(tmp_path, PIX, name=f"g{maxval}")
        v = np.array([values], dtype=">u2" if maxval > 255 else np.uint8)
        body = (" ".join(map(str, v.ravel())) + "\n").encode() if fmt == "P2" else v.tobytes()
        (tmp_path / f"g{maxval}.pgm").write_bytes(f"{fmt}\n# c\n{v.shape[1]} 1\n{maxval}\n".encode() + body)
        return load_map(y).occupancy[0].tolist()

    assert pgm(65535, [0, 200, 254, 255]) == [100, 100, 100, 100]
    assert pgm(65535, [0, 205 * 257, 254 * 257, 65535]) == [100, -1, 0, 0]
    assert pgm(1023, [0, 822, 1019, 1023]) == [100, -1, 0, 0]  # 204.9 -> 205, 254.0
    assert pgm(62, [0, 50, 62, 31]) == [100, -1, 0, -1]
    assert pgm(255, [0, 205, 254, 50]) == [100, -1, 0, 100]
    # a 16-bit PNG: v * 255 / 65535 rounded, dark values too
    Image.fromarray(np.array([[0, 200, 254 * 257, 65535]], dtype=np.uint16)).save(tmp_path / "w.png")
    y = write_map(tmp_path, PIX, name="w")
    y.write_text(y.read_text().replace("w.pgm", "w.png"))
    assert load_map(y).occupancy[0].tolist() == [100, 100, 0, 0]


def test_missing_yaml(tmp_path):
    with pytest.raises(DataError, match="nothere.yaml"):
        load_map(tmp_path / "nothere.yaml")


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(yaml_bytes=st.binary(max_size=200), image_bytes=st.binary(max_size=200))
def test_fuzz_only_dataerror(tmp_path, yaml_bytes, image_bytes):
    y = tmp_path / "f.yaml"
    y.write_bytes(yaml_bytes)
    try:
        load_map(y)
    except DataError:
        pass
    write_map(tmp_path, PIX, name="g")
    (tmp_path / "g.pgm").write_bytes(b"P5\n3 2\n255\n" + image_bytes)
    try:
        grid = load_map(tmp_path / "g.yaml")
        assert grid.occupancy.shape == (2, 3)
    except DataError as e:
        assert "g.yaml" in str(e) and "\n" not in str(e)


# --- real map -------------------------------------------------------------------

@needs_data
def test_real_intel_lab_map():
    grid = load_map(DATA / "intel_lab" / "map.yaml")
    assert grid.occupancy.shape == (800, 854)
    assert grid.resolution == 0.05 and grid.origin == (-21.892, -25.203)
    assert grid.occupied.any() and grid.free.sum() > grid.occupied.sum()
    # The start pose from the data README lies in free space.
    ix, iy = grid.world_to_cell(0.600266, -0.032033)
    assert grid.free[iy, ix]
    assert grid.distance.max() > 1.0


def test_mask_at_reads_the_cell_of_each_world_point_and_is_false_off_the_map():
    occ = np.zeros((4, 5), dtype=np.int8)
    grid = OccupancyGrid.from_occupancy(occ, 0.5, (-1.0, 2.0))
    mask = np.zeros((4, 5), dtype=np.uint8)
    mask[1, 3] = 1  # x in [0.5, 1.0), y in [2.5, 3.0)
    x = np.array([0.5, 0.99, 0.49, 0.7, -1.01, 1.5, np.nan, 0.7])
    y = np.array([2.5, 2.99, 2.7, 3.0, 2.2, 2.2, 2.7, np.inf])
    assert grid.mask_at(mask, x, y).tolist() == [True, True, False, False, False, False, False, False]


@pytest.mark.parametrize("mode", ["trinary", "scale", "raw"])
@pytest.mark.parametrize("negate", [False, True])
def test_the_tables_classify_every_pixel_as_ros_1s_loop(tmp_path, mode, negate):
    # Pixels go through a table with an entry per channel sum; every grey value, and random RGB, RGBA and grey +
    # alpha pixels (alpha 0, 255 or between), with thresholds between pixel steps and on them, must give what ROS 1's
    # loop gives pixel by pixel.
    from mcl.maps import _classify

    rng = np.random.default_rng(8)
    grey = np.concatenate([np.arange(256), rng.integers(0, 256, 500)]).astype(np.uint8).reshape(-1, 12)
    rgba = rng.integers(0, 256, (40, 12, 4)).astype(np.uint8)
    rgba[:, :4, :3] = rgba[:, :4, :1]  # some grey
    rgba[:, ::3, 3] = rng.choice([0, 255], (40, 4))
    for occ_th, free_th in ((0.65, 0.196), (100 / 255, 50 / 255), (0.9, 0.0)):
        cases = [(grey, 1, None, [[[v] for v in row] for row in grey], False),
                 (rgba[..., :3].sum(axis=2, dtype=np.uint16), 3, None, rgba[..., :3].tolist(), False),
                 (rgba[..., :3].sum(axis=2, dtype=np.uint16), 3, rgba[..., 3], rgba.tolist(), True),
                 (rgba[..., 0].astype(np.uint16) * 3, 3, rgba[..., 3],
                  [[[p[0], p[0], p[0], p[3]] for p in row] for row in rgba.tolist()], True)]
        for colour, n, alpha, pixels, has_alpha in cases:
            got = _classify(colour, n, alpha, mode, negate, occ_th, free_th)
            want = [[ros1_pixel(p, has_alpha, mode, negate, occ_th, free_th) for p in row] for row in pixels]
            assert got.dtype == np.int8
            np.testing.assert_array_equal(got, want)


def test_the_map_tables_are_built_without_numpys_huge_page_advice_and_the_advice_comes_back():
    # mcl.runner.small_pages turns NumPy's madvise(MADV_HUGEPAGE) off while the filter builds its map tables
    # (compaction stalls on a 250 m map) and restores whatever was set, even when the block raises.
    from numpy._core import multiarray

    from mcl.runner import small_pages

    before = multiarray._set_madvise_hugepage(True)
    try:
        with small_pages():
            assert multiarray._get_madvise_hugepage() is False
        assert multiarray._get_madvise_hugepage() is True
        with pytest.raises(RuntimeError), small_pages():
            raise RuntimeError
        assert multiarray._get_madvise_hugepage() is True
    finally:
        multiarray._set_madvise_hugepage(before)


def test_a_run_keeps_the_huge_page_advice_off_in_its_loop_too_and_gives_it_back(tmp_path):
    # The map-sized masks made on first use in the loop (the known-cell mask of sensor.unmapped_unknown, the search
    # table) stalled in compaction like the set-up's (147 ms against 25 ms on infinite_corridor), so run() holds
    # small_pages over the whole run; before, only the filter's construction was inside it.
    from numpy._core import multiarray

    from mcl.config import load_config
    from mcl.runner import run

    demo = Path(__file__).resolve().parents[1] / "data" / "demo"
    cfg = load_config(None, [f"map={demo / 'map.yaml'}", f"log={demo / 'log.clf'}", "truth=null", "rerun.mode=off",
                             "filter.particles=500"])
    seen = []

    def on_update(t, pf, info, truth):
        if len(seen) < 5:
            seen.append(multiarray._get_madvise_hugepage())

    before = multiarray._set_madvise_hugepage(True)
    try:
        s = run(cfg, tmp_path / "out", progress=False, echo=lambda *_: None, on_update=on_update)
        assert multiarray._get_madvise_hugepage() is True
    finally:
        multiarray._set_madvise_hugepage(before)
    assert s["updates"] > 5 and seen == [False] * 5


def test_a_map_too_big_for_the_memory_is_refused_without_reading_its_image(tmp_path, monkeypatch):
    # The image was read whole before its header was looked at: a 2.5 GB PGM took 13 s and 2.6 GB of memory to be
    # refused. A 200 MB sparse file (its header says 14142 x 14142): refused with under 1 MB allocated.
    import tracemalloc

    import mcl.maps as maps

    img = tmp_path / "big.pgm"
    with open(img, "wb") as f:
        f.write(b"P5\n14142 14142\n255\n")
        f.truncate(200_000_000)
    (tmp_path / "big.yaml").write_text("image: big.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n"
                                       "occupied_thresh: 0.65\nfree_thresh: 0.196\nnegate: 0\n")
    monkeypatch.setattr(maps, "available_memory", lambda: 1_000_000_000)
    tracemalloc.start()
    try:
        with pytest.raises(DataError, match=r"14142 x 14142 cells need about 6\.0 GB"):
            load_map(tmp_path / "big.yaml")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000, peak


def test_a_map_too_big_for_the_memory_is_one_line_before_its_pixels_are_decoded(tmp_path, monkeypatch, capsys):
    # BYTES_PER_CELL (30) per cell against the memory available: 1000 x 600 cells need 18 MB. With 8 MB
    # available the map is refused, naming the file, the cells and what to do; with 20 MB it loads.
    import mcl.maps as maps
    from mcl.cli import main

    y = write_map(tmp_path, np.full((600, 1000), 254, dtype=np.uint8), fmt="png")
    monkeypatch.setattr(maps, "available_memory", lambda: 8_000_000)
    from PIL import ImageFile

    decoded = []
    load = ImageFile.ImageFile.load
    monkeypatch.setattr(ImageFile.ImageFile, "load", lambda im: decoded.append(1) or load(im))
    with pytest.raises(DataError, match=r"m\.yaml: image: .*m\.png: 1000 x 600 cells need about 18 MB to localize "
                                        r"in \(30 bytes a cell.*\); 8 MB of memory is available: crop the map"):
        load_map(y)
    assert not decoded  # refused from the header, before the pixels
    assert main(["run", "--map", str(y), "--log", str(tmp_path / "none.clf"), "--rerun", "off"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "1000 x 600 cells need about 18 MB" in err[0], err
    monkeypatch.setattr(maps, "available_memory", lambda: 20_000_000)
    assert load_map(y).occupancy.shape == (600, 1000) and decoded
    monkeypatch.setattr(maps, "available_memory", lambda: None)  # not known (not Linux): no check
    assert load_map(y).occupancy.shape == (600, 1000)


def test_interior_cells_are_the_occupied_cells_with_four_occupied_neighbours_in_nonzeros_order():
    """``mcl.kernels.depth.interior_cells`` (``_surface_patches``' cells deeper than one cell): the rule written out
    with shifted masks, off the map counting as occupied (blocks against every edge), in ``np.nonzero``'s row-major
    order; none on an empty map, every cell on a full one."""
    from mcl.kernels.depth import interior_cells

    rng = np.random.default_rng(4)
    for shape in ((1, 1), (1, 7), (6, 1), (40, 53)):
        for p in (0.0, 0.5, 0.9, 1.0):
            occ = rng.random(shape) < p
            if shape == (40, 53):
                occ[:5, :] = occ[:, -4:] = True  # a block along the top and right edges
                occ[20:30, 10:25] = True
            pad = np.pad(occ, 1, constant_values=True)
            inner = occ & pad[:-2, 1:-1] & pad[2:, 1:-1] & pad[1:-1, :-2] & pad[1:-1, 2:]
            ys, xs = interior_cells(np.ascontiguousarray(occ, dtype=np.uint8))
            want = np.nonzero(inner)
            np.testing.assert_array_equal(ys, want[0])
            np.testing.assert_array_equal(xs, want[1])
            if p == 1.0:
                assert ys.size == occ.size
            if p == 0.0 and shape != (40, 53):
                assert ys.size == 0


def test_ring_depths_are_the_exact_transform_within_the_radius_and_minus_one_beyond():
    """``mcl.kernels.depth.ring_depths`` (the interior cells' depth, ``_surface_patches``): the squared distance to
    the nearest non-occupied cell, the integer scipy.ndimage's exact transform gives, wherever that cell lies within
    the radius (Chebyshev); -1 beyond it. Off the map counts as occupied: blocks against the map's edges."""
    from scipy.ndimage import distance_transform_edt

    from mcl.kernels.depth import ring_depths

    rng = np.random.default_rng(9)
    occ = rng.random((60, 70)) < 0.3
    occ[5:25, 10:40] = True  # depth up to 10 cells
    occ[40:60, 50:70] = True  # in the map's corner: nearest free cells only inward
    occ[0:4, :] = True
    ref = distance_transform_edt(occ) ** 2
    ys, xs = np.nonzero(occ)
    for radius in (1, 3, 8, 40):
        out = np.empty(ys.size, dtype=np.int64)
        ring_depths(occ.view(np.uint8), ys, xs, radius, out)
        within = np.sqrt(ref[ys, xs]) <= radius  # nearest free cell within the radius in Euclidean distance ...
        found = out >= 0
        np.testing.assert_array_equal(out[found], np.rint(ref[ys, xs][found]).astype(np.int64))
        assert found[within].all()  # ... is always found (it lies within the radius in Chebyshev distance too)
        assert not found.all() or radius == 40  # the deep block's centre lies beyond the smaller radii
    # the nearest free cell can lie on a later ring than the first one found: (3, 3) on ring 3 is 18 away, (4, 0) on
    # ring 4 only 16
    block = np.ones((11, 11), dtype=np.uint8)
    block[5 + 3, 5 + 3] = 0
    block[5, 5 + 4] = 0
    out = np.empty(1, dtype=np.int64)
    ring_depths(block, np.array([5]), np.array([5]), 10, out)
    assert out[0] == 16
    # no free cell at all: nothing found at any radius
    full = np.ones((5, 6), dtype=np.uint8)
    out = np.empty(30, dtype=np.int64)
    ring_depths(full, *np.nonzero(full), 10, out)
    assert (out == -1).all()


@needs_data
def test_the_shared_slam_maps_are_not_drawn_solid_and_a_generated_world_is(tmp_path):
    # the shared logs' maps were drawn by returns (SLAM): at most 0.20 of their occupied cells lie deeper than one cell
    # (fr079), so interior_tolerance null keeps 0.05 m there and every real run is the one it was; mcl simulate draws
    # walls solid (0.33-0.63 over suites/synthetic.yaml), where null is 0 (mcl.sensors.drawn_solid)
    from mcl.sensors import SOLID_SHARE, drawn_solid
    from mcl.simulate import simulate

    shares = {p.parent.name: load_map(p).solid_share for p in sorted(DATA.glob("*/map.yaml"))}
    assert len(shares) >= 8, shares
    assert max(shares.values()) <= 0.21 < SOLID_SHARE, shares
    assert not any(drawn_solid(load_map(p)) for p in DATA.glob("*/map.yaml"))
    for kind, seed in (("office", 3), ("corridor", 4)):
        simulate(tmp_path / kind, kind=kind, seed=seed, duration=2.0)
        g = load_map(tmp_path / kind / "map.yaml")
        assert g.solid_share >= 0.33 and drawn_solid(g), (kind, g.solid_share)


@pytest.mark.parametrize("free,noted", [(0.25, True), (0.196, False)])
def test_map_savers_unknown_grey_read_as_free_is_noted(tmp_path, free, noted):
    # nav2's map_saver writes free_thresh 0.25 beside its unknown grey 205 (p = 0.196): map_server reads those cells
    # free, and so does mcl, but without a word a global search spread over every unknown cell (a map padded with
    # unknown: 5.05 m off on seed 2, 0.05 m with 0.196)
    pixels = np.full((20, 20), 205, dtype=np.uint8)
    pixels[5:15, 5:15] = 254
    grid = load_map(write_map(tmp_path, pixels, free=free))
    assert int(np.count_nonzero(grid.unknown)) == (0 if noted else 300)
    assert [n for n in grid.notes if "grey 205" in n] == (
        [f"{tmp_path / 'm.yaml'}: 75% of the image is grey 205, map_saver's unknown, read as free under free_thresh "
         "0.25 (as map_server reads it; nav2's map_saver writes 0.25): if those cells are unknown, set free_thresh: "
         "0.196"] if noted else [])


def test_an_opaque_alpha_channels_unknown_grey_read_as_free_is_noted(tmp_path):
    # An RGBA PNG (GIMP, a web tool) of map_saver's grey 205, opaque: trinary mode averages the alpha in (217.5, p =
    # 0.147), so under the default free_thresh 0.196 every unknown cell is free, as map_server reads it; the note's
    # test looked at 205 alone and said nothing. A transparent 205 (153.75) is unknown and is not noted.
    pixels = np.full((20, 20, 4), 205, dtype=np.uint8)
    pixels[..., 3] = 255
    pixels[5:15, 5:15, :3] = 254
    grid = load_map(write_map(tmp_path, pixels, fmt="png"))
    assert int(np.count_nonzero(grid.unknown)) == 0
    assert [n for n in grid.notes if "grey 205" in n] == [
        f"{tmp_path / 'm.yaml'}: 75% of the image is grey 205, map_saver's unknown, read as free: trinary mode "
        "averages the alpha channel in (as map_server does), so an opaque grey 205 is 217.5: if those cells are "
        "unknown, save the image without alpha"]
    pixels[..., 3] = 0
    pixels[5:15, 5:15, 3] = 255
    grid = load_map(write_map(tmp_path, pixels, fmt="png", name="t"))
    assert int(np.count_nonzero(grid.unknown)) == 300 and not [n for n in grid.notes if "grey 205" in n]


@pytest.mark.parametrize("fmt,kind", [("pgm", "PGM"), ("p2", "PGM"), ("png", "PNG")])
def test_an_image_given_as_the_map_says_to_give_its_yaml(tmp_path, fmt, kind):
    # --map map.pgm said "not a UTF-8 text file" (a P2 image: "invalid YAML" at its third line)
    write_map(tmp_path, PIX, fmt=fmt)
    image = tmp_path / ("m.pgm" if fmt == "p2" else f"m.{fmt}")
    with pytest.raises(DataError) as e:
        load_map(image)
    assert str(e.value) == (f"{image}: a {kind} image, not a map: give the map_server YAML that names it (image:, "
                            "resolution:, origin:, ...)")


def test_an_occupancy_that_is_no_ros_grid_is_refused_and_the_callers_array_is_copied():
    # A bool wall mask gave 0 occupied cells, a uint8 image's 0/254 walls free and free space unknown (254 -> -2), a
    # float probability grid 0 occupied: cast to int8 as they came. And the grid kept the caller's array, so a
    # later change of it left the cached distance field stale.
    from mcl.maps import OccupancyGrid

    walls = np.zeros((20, 30), dtype=bool)
    walls[0, :] = True
    for bad, what in ((walls, "dtype bool"), (np.where(walls, 0, 254).astype(np.uint8), "0..254"),
                      (np.where(walls, 0.9, 0.1), "0.1..0.9"), (np.full((20, 30), np.nan), "nan")):
        with pytest.raises(ValueError, match=what):
            OccupancyGrid.from_occupancy(bad, 0.1, (0.0, 0.0))
    occ = np.where(walls, 100, 0).astype(np.int16)
    g = OccupancyGrid.from_occupancy(occ, 0.1, (0.0, 0.0))
    assert g.occupied.sum() == 30 and g.occupancy.dtype == np.int8
    occ[5, 5] = 100
    assert g.occupancy[5, 5] == 0  # a copy


def test_a_misspelled_key_of_a_map_yaml_is_named(tmp_path):
    # `resolutoin:` gave "resolution: missing key", with no word of the key beside it
    (tmp_path / "m.pgm").write_bytes(b"P5\n2 2\n255\n" + bytes([254, 0, 254, 254]))
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolutoin: 0.05\norigin: [0, 0, 0]\noccupied_thresh: 0.65\n"
                                     "free_thresh: 0.196\n")
    with pytest.raises(DataError) as e:
        load_map(tmp_path / "m.yaml")
    assert str(e.value) == f"{tmp_path / 'm.yaml'}: resolution: missing key (is resolutoin: meant?)"
