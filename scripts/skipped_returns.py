#!/usr/bin/env python
"""Which returns did the filter leave out as unmapped objects, seen from the true pose?

``sensor.unmapped_skip`` drops the returns of small segments that end far from every mapped obstacle as seen from
the estimate moved by the update's odometry step (people, furniture the map lacks). This script runs a run folder of
``mcl eval`` (or any ``mcl run`` output whose config names a truth) again with the ``on_update`` hook of
``mcl.runner.run``, lays every skipped return on the map from the reference pose of its scan, and counts the ones
that end within ``--near`` m of a mapped obstacle there: returns the map explains, skipped only because the test pose
was off (``docs/measurements.md``, "Sixty-seventh session": the beams looking along a corridor grazing its walls 8-20
m away, skipped when the odometry step turned the test pose by a few degrees). Printed: the counts, the bearings
(robot frame) and ranges of those false skips, and the run's ATE. The new run's outputs go to a temporary folder.

Usage::

    .venv/bin/python scripts/skipped_returns.py RUN_DIR [--near M] [--set KEY=VALUE ...]

RUN_DIR holds ``config.yaml`` (map, log, truth: synthetic worlds must still be in the cache the evaluation used).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mcl.config import load_config  # noqa: E402
from mcl.errors import MclError  # noqa: E402
from mcl.maps import load_map  # noqa: E402
from mcl.runner import _to_world, run  # noqa: E402  (robot-frame points to the world frame)


def classify(endpoints: np.ndarray, truth_pose, grid, near: float) -> np.ndarray:
    """(K,) bool: the robot-frame ``endpoints`` (2, K), laid on ``grid`` from ``truth_pose``, within ``near`` m of a
    mapped obstacle (an endpoint off the map counts as not near)."""
    wx, wy = _to_world(np.asarray(truth_pose, dtype=np.float64), endpoints)
    ix, iy = grid.world_to_cell(wx, wy)
    inside = grid.contains(ix, iy)
    out = np.zeros(endpoints.shape[1], dtype=bool)
    out[inside] = np.asarray(grid.distance)[iy[inside], ix[inside]] <= near
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path, help="a run folder with config.yaml (e.g. an mcl eval run's seedN)")
    ap.add_argument("--near", type=float, default=0.15,
                    help="m: a skipped return this near a mapped obstacle, seen from the truth, is a false skip")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a config key for the re-run (repeatable)")
    args = ap.parse_args(argv)
    try:
        cfg = load_config(args.run_dir / "config.yaml", args.set)
        if cfg.truth is None:
            raise MclError(f"{args.run_dir / 'config.yaml'}: truth: null (the script needs a reference trajectory)")
        grid = load_map(cfg.map)
    except MclError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    totals = Counter()
    false_bearings: Counter = Counter()
    false_ranges: list[float] = []
    true_ranges: list[float] = []

    def on_update(t, pf, info, truth_pose):
        totals["updates"] += 1
        sk = info.skipped_endpoints
        if sk is None or truth_pose is None:
            return
        totals["updates with a skip"] += 1
        near = classify(sk, truth_pose, grid, args.near)
        totals["skipped"] += sk.shape[1]
        totals["near a mapped obstacle"] += int(near.sum())
        false_bearings.update(np.rint(np.degrees(np.arctan2(sk[1, near], sk[0, near]))).astype(int).tolist())
        false_ranges.extend(np.hypot(sk[0, near], sk[1, near]).tolist())
        true_ranges.extend(np.hypot(sk[0, ~near], sk[1, ~near]).tolist())

    with tempfile.TemporaryDirectory() as tmp:
        summary = run(cfg, Path(tmp), on_update=on_update)
    ev = summary.get("eval") or {}
    print(f"{args.run_dir}: ATE RMSE {ev.get('ate_rmse', float('nan')):.3f} m, max {ev.get('ate_max', float('nan')):.2f} m")
    print(f"updates {totals['updates']}, with a skip {totals['updates with a skip']}; skipped returns "
          f"{totals['skipped']}: within {args.near} m of a mapped obstacle at the truth {totals['near a mapped obstacle']}"
          f", off the map there {totals['skipped'] - totals['near a mapped obstacle']}")
    if false_ranges:
        print("false skips by bearing (deg, robot frame): " +
              ", ".join(f"{b}: {n}" for b, n in false_bearings.most_common(8)))
        q = np.percentile(false_ranges, [10, 50, 90])
        print(f"their ranges: 10 / 50 / 90 % {q[0]:.1f} / {q[1]:.1f} / {q[2]:.1f} m")
    if true_ranges:
        q = np.percentile(true_ranges, [10, 50, 90])
        print(f"the ranges of the skips off the map at the truth: 10 / 50 / 90 % {q[0]:.1f} / {q[1]:.1f} / {q[2]:.1f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
