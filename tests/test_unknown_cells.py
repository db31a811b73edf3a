"""Unknown map cells under the map-based motion model (``motion.map_unknown``): a map's unexplored floor (grey in
the PGM: a room behind a door closed while mapping, the floor under furniture moved since) is no wall. Rejecting
every pose there gave each particle weight zero while the robot drove over such a patch, and the default config lost
every generated world so edited (docs/measurements.md, "Thirty-third session")."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from mcl.config import PROJECT_ROOT, load_config
from mcl.maps import OccupancyGrid, load_map
from mcl.motion import allowed_mask
from mcl.runner import run
from mcl.simulate import simulate


def test_allowed_mask_takes_unknown_cells_clear_of_walls_only_when_asked():
    # one row: wall, free, free, unknown, unknown, unknown, free; cells 0.1 m
    occ = np.array([[100, 0, 0, -1, -1, -1, 0]], dtype=np.int8)
    g = OccupancyGrid.from_occupancy(occ, 0.1, (0.0, 0.0))
    assert allowed_mask(g, 0.15, "reject").tolist() == [[0, 0, 1, 0, 0, 0, 1]]
    assert allowed_mask(g, 0.15, "allow").tolist() == [[0, 0, 1, 1, 1, 1, 1]]
    assert allowed_mask(g, 0.15).tolist() == allowed_mask(g, 0.15, "reject").tolist()  # the function's default
    with pytest.raises(ValueError, match="map_unknown"):
        allowed_mask(g, 0.15, "maybe")


@pytest.fixture(scope="module")
def grey_world(tmp_path_factory):
    """A generated office whose map has the floor within 1.2 m of the robot's path from 10 to 16 s made unknown
    (walls kept), as a SLAM map's unexplored patch."""
    d = tmp_path_factory.mktemp("grey")
    simulate(d, seed=3, duration=24.0)
    meta = yaml.safe_load((d / "map.yaml").read_text())
    im = np.array(Image.open(d / meta["image"]))
    res, (ox, oy) = meta["resolution"], meta["origin"][:2]
    truth = np.loadtxt(d / "truth.tum")
    h, w = im.shape
    yy, xx = np.mgrid[0:h, 0:w]
    cx, cy = ox + (xx + 0.5) * res, oy + (h - 1 - yy + 0.5) * res
    near = np.zeros(im.shape, dtype=bool)
    for x, y in truth[(truth[:, 0] >= 10.0) & (truth[:, 0] <= 16.0), 1:3]:
        near |= (cx - x) ** 2 + (cy - y) ** 2 < 1.2 ** 2
    im[near & (im > 250)] = 128  # free -> unknown (p = 0.5)
    Image.fromarray(im).save(d / meta["image"])
    grid = load_map(d / "map.yaml")
    assert np.count_nonzero(grid.occupancy == -1) > np.count_nonzero(near) // 2  # the patch is on the map, unknown
    return d


def _track(d: Path, out: Path, *extra):
    start = yaml.safe_load((d / "sim.yaml").read_text())["start_pose"]
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml",
                      [f"map={d / 'map.yaml'}", f"log={d / 'log.clf'}", f"truth={d / 'truth.tum'}",
                       f"filter.initial_pose={list(start)}", "seed=1", "rerun.mode=off", *extra])
    summary = run(cfg, out, progress=False, echo=lambda *a, **k: None)
    return summary["eval"]["ate_max"]


def test_a_robot_driving_over_unknown_floor_keeps_its_track(grey_world, tmp_path):
    # Seed 1, a fixed trajectory. Allowed (the default): within 0.3 m all the way (measured 0.085 m). Rejected (the
    # default before): every particle on the patch gets weight zero and the track is lost (measured 7.4 m).
    kept = _track(grey_world, tmp_path / "allow")
    lost = _track(grey_world, tmp_path / "reject", "motion.map_unknown=reject")
    assert kept < 0.3, kept
    assert lost > 1.0, lost
