"""scripts/skipped_returns.py: a skipped return laid on the map from the true pose is a false skip when it ends on a
mapped obstacle, and not when it ends in the open or off the map."""

from __future__ import annotations

import math
import sys

import numpy as np

from mcl.config import PROJECT_ROOT
from mcl.maps import load_map

sys.path.insert(0, str(PROJECT_ROOT / "scripts"))
from skipped_returns import classify, main  # noqa: E402

DEMO = PROJECT_ROOT / "data" / "demo"


def _robot_frame(pose, world):
    """(2, K) robot-frame points of the world points ``world`` (2, K) seen from ``pose``."""
    x, y, th = pose
    dx, dy = world[0] - x, world[1] - y
    c, s = math.cos(th), math.sin(th)
    return np.array([c * dx + s * dy, -s * dx + c * dy])


def test_a_return_on_a_mapped_wall_is_near_and_one_in_the_open_or_off_the_map_is_not():
    grid = load_map(DEMO / "map.yaml")
    dist = np.asarray(grid.distance)
    wall = np.argwhere(dist == 0.0)[len(np.argwhere(dist == 0.0)) // 2]  # an occupied cell (row, col)
    open_ = np.argwhere(dist > 1.0)[0]  # a cell a metre from every obstacle
    cell = lambda rc: [grid.origin[0] + (rc[1] + 0.5) * grid.resolution, grid.origin[1] + (rc[0] + 0.5) * grid.resolution]  # noqa: E731
    world = np.array([cell(wall), cell(open_), [grid.origin[0] - 5.0, grid.origin[1] - 5.0]]).T
    pose = (float(world[0, 1]) + 0.3, float(world[1, 1]) - 0.2, 2.1)  # any pose: the endpoints are laid from it
    got = classify(_robot_frame(pose, world), pose, grid, 0.15)
    assert got.tolist() == [True, False, False]
    # from a pose turned by 5 degrees the same robot-frame endpoints miss the wall: a false skip needs the truth
    turned = (pose[0], pose[1], pose[2] + math.radians(5.0))
    assert not classify(_robot_frame(pose, world), turned, grid, 0.15)[0]


def test_a_run_without_a_reference_is_refused_in_one_line(tmp_path, capsys):
    text = (PROJECT_ROOT / "configs" / "default.yaml").read_text()
    lines = [f"map: {DEMO / 'map.yaml'}" if ln.startswith("map:") else
             f"log: {DEMO / 'log.clf'}" if ln.startswith("log:") else
             "truth: null" if ln.startswith("truth:") else ln for ln in text.splitlines()]
    (tmp_path / "config.yaml").write_text("\n".join(lines) + "\n")
    assert main([str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "truth: null" in err[0] and str(tmp_path / "config.yaml") in err[0]
