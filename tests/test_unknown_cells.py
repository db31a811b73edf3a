"""Unknown map cells under the map-based motion model (``motion.unknown_prior``): a map's unexplored floor (grey in
the PGM: a room behind a door closed while mapping, the floor under furniture moved since) is no wall. Rejecting
every pose there gave each particle weight zero while the robot drove over such a patch, and the default config lost
every generated world so edited (docs/measurements.md, "Thirty-third session"). Now a pose there is weighed by
p(x | m) = unknown_prior against a free cell's 1."""

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
    assert allowed_mask(g, 0.15).tolist() == [[0, 0, 1, 0, 0, 0, 1]]
    assert allowed_mask(g, 0.15, unknown=True).tolist() == [[0, 0, 1, 1, 1, 1, 1]]


def test_particles_on_unknown_cells_are_weighed_by_the_prior():
    # A corridor of free cells with an unknown strip: a cloud moved half onto the strip has that half's weights
    # times unknown_prior (log-weight + log 0.5), the rest untouched; with the whole cloud on it, every weight the
    # same (nothing to choose by); 1 weighs nothing; 0 never lets a particle stay there (weight zero).
    from mcl.filter import ParticleFilter

    occ = np.zeros((20, 40), dtype=np.int8)
    occ[0, :] = occ[-1, :] = 100
    occ[1:-1, 20:30] = -1
    g = OccupancyGrid.from_occupancy(occ, 0.1, (0.0, 0.0))
    pts = np.array([[1.0, 2.5], [1.0, 1.0], [0.0, 0.0]])  # x 1.0 m (free) and 2.5 m (unknown), y 1.0 m
    for q, expect in ((0.5, [0.0, np.log(0.5)]), (1.0, [0.0, 0.0])):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [f"motion.unknown_prior={q}"])
        pf = ParticleFilter(cfg, g)
        logw = np.zeros(2)
        pf._weigh_unknown(logw, pts)
        assert np.allclose(logw, expect), q
    assert ParticleFilter(load_config(PROJECT_ROOT / "configs" / "default.yaml",
                                      ["motion.unknown_prior=0"]), g).allowed[10, 25] == 0


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
    lost = _track(grey_world, tmp_path / "reject", "motion.unknown_prior=0")
    assert kept < 0.3, kept
    assert lost > 1.0, lost


def test_the_map_based_density_weighs_unknown_cells_by_the_prior():
    # Seed 5.5's p(x_t | u_t, x_{t-1}, m) with p(x | m) = 1 free, unknown_prior unknown, 0 in a wall: two hypotheses
    # at the same distance from the odometry's prediction, one on free floor and one on unknown, differ by that
    # factor; 0 gives the unknown one nothing.
    from mcl.motion import motion_model_odometry, motion_model_with_map

    occ = np.zeros((40, 60), dtype=np.int8)
    occ[:, 40:] = -1  # unknown from x = 2.0 m
    grid = OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))
    u = (np.zeros(3), np.array([0.5, 0.0, 0.0]))
    xp = np.array([1.5, 1.0, 0.0])
    hyp = np.array([[1.9, 2.1], [1.0, 1.0], [0.0, 0.0]])  # 0.1 m short of the prediction (2.0, 1.0), 0.1 m past
    for q in (0.5, 0.0):
        c = load_config(PROJECT_ROOT / "configs" / "default.yaml", [f"motion.unknown_prior={q}"]).motion
        free = motion_model_odometry(hyp, u, xp, c)
        p = motion_model_with_map(hyp, u, xp, grid, c)
        assert p.sum() == pytest.approx(1.0)
        assert p[1] / p[0] == pytest.approx(q * free[1] / free[0], rel=1e-9), q
