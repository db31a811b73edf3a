#!/usr/bin/env python
"""Build a replay dataset (map, log, truth) from a SLAM-corrected Radish log, the way ../shared/data's were built.

The public corrected CARMEN logs (Radish, via github.com/acschaefer/ple ``data/carmen/*-corrected.log.gz``)
carry each scan at its SLAM-corrected pose in both FLASER pose slots. Their ODOM lines are no raw odometry: the
first ODOM line after each scan moves exactly as the corrected poses do (checked on aces, edmonton, fhw, seattle,
orebro and freiburg-campus), and orebro's and freiburg-campus's stamps are all 0. So the odometry is simulated,
as ``mcl simulate`` does it: the corrected path, cut into steps of at most 0.08 m, gets the odometry motion
model's noise (variance form, alphas 0.05, 0.05, 0.05, 0.02), a 1 % scale error and 0.01 rad of yaw drift per
metre (``--seed``). The scans, the map and the reference are real; the odometry error is not. This script makes
of one such log, into OUTDIR:

* ``truth.tum``: the corrected poses, one per scan (the reference; a few centimetres of SLAM error), stamped
  0.2 s apart where the log's stamps do not increase;
* ``log.clf``: the same scans at the simulated odometry poses, anchored at the first corrected pose;
* ``map.yaml`` / ``map.pgm``: an occupancy grid (0.05 m) drawn from the scans at the corrected poses: a cell
  is occupied when at least ``--min-hits`` readings ended in it and at least ``--hit-share`` of the rays
  that reached it ended there; free when a ray crossed it; unknown otherwise. No-return readings (at the
  top of the log's range, ``mcl.datasets.noreturn``) only clear cells, up to ``--free-range``.

Nothing it makes belongs in the repository (``data/`` holds only what the project makes itself; real logs are
never copied in): write into a scratch folder, and list it in a suite file to evaluate the default on buildings
it was never tuned on::

    .venv/bin/python scripts/radish_dataset.py seattle-corrected.log.gz /tmp/heldout-real/seattle
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
from numba import njit

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mcl.datasets.carmen import read_carmen  # noqa: E402
from mcl.datasets.noreturn import detect_no_return  # noqa: E402
from mcl.errors import MclError  # noqa: E402
from mcl.estimate import wrap_angle  # noqa: E402
from mcl.maps import OccupancyGrid, save_map  # noqa: E402
from mcl.motion import ROT1_MIN_TRANS  # noqa: E402
from mcl.trajectory import atomic_write_text, write_tum  # noqa: E402


def _compose(a, b):
    """a (+) b for a pose (3,) and poses (3, K) (mcl.runner.compose, for many poses at once)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap_angle(a[2] + b[2])])


def simulated_odometry(truth: np.ndarray, rng: np.random.Generator, step: float = 0.08,
                       noise: float = 1.0) -> np.ndarray:
    """(3, K) odometry poses for the corrected poses ``truth`` (3, K), anchored at the first: the path between
    scans cut into steps of at most ``step`` m (the simulator's 10 Hz ticks at 0.8 m/s), each moved with
    mcl.simulate's odometry noise (its alphas, scale error and yaw drift times ``noise``), then read at the scans."""
    from mcl.simulate import _odometry

    fine, at = [truth[:, :1]], [0]
    for k in range(1, truth.shape[1]):
        a, b = truth[:, k - 1], truth[:, k]
        m = max(1, int(math.ceil(math.hypot(b[0] - a[0], b[1] - a[1]) / step)))
        f = np.arange(1, m + 1) / m
        dth = wrap_angle(b[2] - a[2])
        fine.append(np.vstack([a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), wrap_angle(a[2] + f * dth)]))
        at.append(at[-1] + m)
    path = np.hstack(fine).T
    alphas = tuple(noise * a for a in (0.05, 0.05, 0.05, 0.02))
    odom, _, _ = _odometry(path, path, rng, alphas, 1.0 + noise * 0.01, noise * 0.01, min_trans=ROT1_MIN_TRANS)
    return _compose(truth[:, 0], odom[at].T)


@njit(cache=True)
def _trace(hits, rays, x0, y0, xs, ys, ends, res, ox, oy, stop):
    """Count, per cell, the rays from (x0[k], y0[k]) to (xs[k], ys[k]) that crossed it (``rays``, a ray stopping
    at a ``stop`` cell: readings seen through a wall, glass or a gap, do not clear the rooms behind it) and the
    ones that ended in it (``hits``, when ends[k])."""
    h, w = hits.shape
    for k in range(xs.shape[0]):
        ax, ay = (x0[k] - ox) / res, (y0[k] - oy) / res
        bx, by = (xs[k] - ox) / res, (ys[k] - oy) / res
        n = int(max(abs(bx - ax), abs(by - ay)) * 2.0) + 1
        last_i, last_j = -1, -1
        for m in range(n + 1):
            f = m / n
            i, j = int(math.floor(ay + f * (by - ay))), int(math.floor(ax + f * (bx - ax)))
            if (i == last_i and j == last_j) or i < 0 or j < 0 or i >= h or j >= w:
                continue
            last_i, last_j = i, j
            rays[i, j] += 1
            if stop[i, j] and m < n:
                break
        if ends[k]:
            i, j = int(math.floor(by)), int(math.floor(bx))
            if 0 <= i < h and 0 <= j < w:
                hits[i, j] += 1


def build(src: Path, out: Path, res: float = 0.05, min_hits: int = 2, hit_share: float = 0.25,
          free_range: float = 20.0, seed: int = 0, noise: float = 1.0) -> dict:
    log = read_carmen(src)
    scans = [s for s in log.scans if s.kind == "FLASER"]
    if not scans:
        raise SystemExit(f"{src}: no FLASER lines")
    t = np.array([s.t for s in scans])
    truth = np.array([s.odom for s in scans]).T  # the corrected poses (both slots)
    if not np.all(np.diff(t) > 0):  # no usable clock (freiburg-campus, orebro: every stamp 0; csail: %g)
        t = np.arange(len(scans)) * 0.2
    replay = simulated_odometry(truth, np.random.default_rng(seed), noise=noise)

    marker = detect_no_return(np.concatenate([s.ranges for s in scans]))
    no_return = marker.threshold if marker is not None else None
    top = no_return if no_return is not None else max(float(np.max(s.ranges)) for s in scans) + 1.0
    xs, ys, x0, y0, ends = [], [], [], [], []
    for s, p in zip(scans, truth.T):
        r = np.asarray(s.ranges, dtype=np.float64)
        a = s.angles + p[2]
        keep = r > 0.05
        hit = keep & (r < top - 1e-6)
        rr = np.where(hit, r, np.minimum(r, free_range))
        lx = p[0] + (s.laser_offset[0] if s.laser_offset is not None else 0.0)
        ly = p[1] + (s.laser_offset[1] if s.laser_offset is not None else 0.0)
        xs.append(lx + rr[keep] * np.cos(a[keep]))
        ys.append(ly + rr[keep] * np.sin(a[keep]))
        x0.append(np.full(keep.sum(), lx))
        y0.append(np.full(keep.sum(), ly))
        ends.append(hit[keep])
    xs, ys, x0, y0, ends = (np.concatenate(v) for v in (xs, ys, x0, y0, ends))
    lo = np.minimum(xs.min(), x0.min()) - 1.0, np.minimum(ys.min(), y0.min()) - 1.0
    hi = np.maximum(xs.max(), x0.max()) + 1.0, np.maximum(ys.max(), y0.max()) + 1.0
    w, h = int(math.ceil((hi[0] - lo[0]) / res)), int(math.ceil((hi[1] - lo[1]) / res))
    hits = np.zeros((h, w), dtype=np.int32)
    rays = np.zeros((h, w), dtype=np.int32)
    _trace(hits, rays, x0, y0, xs, ys, ends, res, lo[0], lo[1], np.zeros((h, w), dtype=np.bool_))
    walls = hits >= min_hits  # then again, the rays stopping at the walls the first pass found
    hits[:] = 0
    rays[:] = 0
    _trace(hits, rays, x0, y0, xs, ys, ends, res, lo[0], lo[1], walls)
    occ = np.full((h, w), -1, dtype=np.int8)
    occ[rays > 0] = 0
    occ[(hits >= min_hits) & (hits >= hit_share * np.maximum(rays, 1))] = 100

    out.mkdir(parents=True, exist_ok=True)
    save_map(OccupancyGrid.from_occupancy(occ, res, (float(lo[0]), float(lo[1]))), out / "map.yaml")
    write_tum(out / "truth.tum", t, truth)
    scaled = "" if noise == 1.0 else f", error x {noise:g}"  # (the default's header as before: the same bytes)
    lines = [f"# built by scripts/radish_dataset.py from {src.name}: simulated odometry (seed {seed}{scaled}) from the "
             "first corrected pose\n"]
    for s, p, tk in zip(scans, replay.T, t):
        rs = " ".join(f"{v:.3f}" for v in s.ranges)
        pose = f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f}"
        lines.append(f"FLASER {len(s.ranges)} {rs} {pose} {pose} {tk:.6f} replay {tk:.6f}\n")
    atomic_write_text(out / "log.clf", "".join(lines))
    return {"scans": len(scans), "cells": (w, h), "no_return": no_return, "start": truth[:, 0].tolist(),
            "duration_s": float(t[-1] - t[0])}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("src", type=Path, help="a corrected CARMEN log (.log or .log.gz)")
    ap.add_argument("out", type=Path, help="folder for map.yaml, map.pgm, log.clf, truth.tum")
    ap.add_argument("--min-hits", type=int, default=2)
    ap.add_argument("--hit-share", type=float, default=0.25)
    ap.add_argument("--free-range", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=0, help="the simulated odometry's noise")
    ap.add_argument("--odom-noise", type=float, default=1.0,
                    help="scale of the simulated odometry error: its alphas, scale error and yaw drift times this "
                         "(default 1: mcl simulate's; 0.1, suites/heldout-real-gentle.yaml's: a tenth, nearer the "
                         "real logs' odometry)")
    a = ap.parse_args(argv)
    if not a.odom_noise >= 0:
        ap.error(f"--odom-noise: {a.odom_noise} (expected a value >= 0)")
    try:
        info = build(a.src, a.out, min_hits=a.min_hits, hit_share=a.hit_share, free_range=a.free_range, seed=a.seed,
                     noise=a.odom_noise)
    except MclError as e:  # a missing or unreadable log: one line, as mcl's own commands say it
        print(f"radish_dataset.py: error: {e}", file=sys.stderr)
        return 2
    print(f"{a.out}: {info['scans']} scans over {info['duration_s']:.0f} s, map {info['cells'][0]} x "
          f"{info['cells'][1]} cells, no-return {info['no_return']}, start {info['start']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
