#!/usr/bin/env python
"""How near the reference is the motion the odometry fill took from scan matching, window by window?

``motion.stalls: fill``, ``jumps: match`` and ``slips: match`` (:class:`mcl.odomstall.StallFill`) replace the
odometry over a window (a hold, a hold that ended in a jump, a jump, a slip) with the motion scan matching found.
A run's error says whether the filter kept the track; this says whether each fill was right. For every dataset of a
suite with a reference (``truth``), every window filled is laid against the reference: the robot's motion from the
scan before the window to its last scan (in the robot's frame at the first) as the reference has it, and the error
of the odometry as it came and of the fill, in position (m) and heading (rad). The totals count, per cause, the
windows whose fill is nearer the reference than the odometry was (by more than ``BETTER_M`` or ``BETTER_A``) and
those farther.

Usage::

    .venv/bin/python scripts/fill_accuracy.py SUITE.yaml [--cache DIR] [--only NAME,...] [--config C] [--set k=v]

``SUITE.yaml``: a suite file (``suites/``, or a ``scripts/hunt.py`` folder's ``suite.yaml``); its generated worlds
are made in ``--cache`` (or found there: ``mcl eval``'s). The config (default ``configs/default.yaml``) gives the
laser's mounting and the jump guard's bounds; the fill runs with holds, jumps and slips on whatever it sets. A
dataset without a reference, or a bag whose reference is a topic, is left out. Writes nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

import numpy as np

from mcl.config import default_config, load_config
from mcl.errors import MclError
from mcl.estimate import compose, inverse, wrap_angle
from mcl.evaluate import interpolate_poses
from mcl.odomcheck import run_mount
from mcl.odomstall import StallFill
from mcl.runner import _open_source
from mcl.suite import _sim_kwargs, _world_dir, load_suite, make_world
from mcl.trajectory import read_tum

BETTER_M = 0.05  # m: a fill nearer the reference than the odometry by more than this is better (farther: worse)
BETTER_A = 0.05  # rad: ... in heading
SPACING = 1.5  # a window's end between two reference poses this many times their median spacing apart (or less)
# takes the pose interpolated between them; across a longer gap of the reference the window is left out
CAUSES = ("hold", "hold+jump", "jump", "slip")


def _pose_at(t_ref: np.ndarray, poses: np.ndarray, t: float, gap: float) -> np.ndarray | None:
    """The reference pose (3,) at ``t``, interpolated between the two around it, or None outside the reference or
    in a gap of it (the two over ``gap`` s apart)."""
    k = int(np.searchsorted(t_ref, t))
    if k < len(t_ref) and t_ref[k] == t:
        return poses[:, k]
    if k == 0 or k == len(t_ref) or t_ref[k] - t_ref[k - 1] > gap:
        return None
    return interpolate_poses(t_ref, poses, np.array([t]))[:, 0]


def windows(cfg, truth: str) -> list[dict]:
    """One dict per window the fill took from scan matching on ``cfg``'s data: cause, t0, duration, the reference's
    travel and turn over it, the odometry's and the fill's errors (``odo_m``, ``odo_a``, ``fill_m``, ``fill_a``)."""
    _, _, scans, _, _, _ = _open_source(_as_it_came(cfg), lambda *a: None)
    scans = list(scans)
    f = cfg.filter
    fill = StallFill(scans, lambda s: run_mount(s, cfg.sensor.laser_pose), holds=True,
                     jumps=(f.max_odom_step, f.max_odom_ratio, f.max_odom_speed), slips=True)
    filled = list(fill)
    raw = {(s.kind, s.t): s.odom for s in scans}
    new = {(s.kind, s.t): s.odom for s in filled}
    t_ref, poses = read_tum(truth)
    gap = SPACING * float(np.median(np.diff(t_ref))) if len(t_ref) > 1 else 0.0
    kind = scans[0].kind if scans else None
    out = []
    for st in fill.stalls:
        k0, k1 = (kind, st.t0), (kind, st.t1)
        a, b = _pose_at(t_ref, poses, st.t0, gap), _pose_at(t_ref, poses, st.t1, gap)
        if k0 not in raw or k1 not in raw or a is None or b is None:
            continue
        ref = compose(inverse(a), b)
        odo = compose(inverse(raw[k0]), raw[k1])
        got = compose(inverse(new[k0]), new[k1])
        out.append(dict(cause=st.cause, t0=st.t0, dt=st.t1 - st.t0, ref_m=math.hypot(ref[0], ref[1]),
                        ref_a=float(ref[2]), odo_m=math.hypot(*(odo[:2] - ref[:2])),
                        odo_a=abs(float(wrap_angle(odo[2] - ref[2]))),
                        fill_m=math.hypot(*(got[:2] - ref[:2])), fill_a=abs(float(wrap_angle(got[2] - ref[2])))))
    return out


def _as_it_came(cfg):
    """``cfg`` with the fill off (``motion.stalls`` keep, ``jumps`` hedge, ``slips`` keep): the scans as they came."""
    return dataclasses.replace(cfg, motion=dataclasses.replace(cfg.motion, stalls="keep", jumps="hedge", slips="keep"))


def summarize(rows: list[dict]) -> dict:
    """Per cause: windows, and how many fills are nearer the reference than the odometry (better) or farther
    (worse), in position and in heading."""
    out = {}
    for c in CAUSES:
        r = [x for x in rows if x["cause"] == c]
        if r:
            out[c] = dict(
                windows=len(r),
                position_better=sum(x["fill_m"] < x["odo_m"] - BETTER_M for x in r),
                position_worse=sum(x["fill_m"] > x["odo_m"] + BETTER_M for x in r),
                heading_better=sum(x["fill_a"] < x["odo_a"] - BETTER_A for x in r),
                heading_worse=sum(x["fill_a"] > x["odo_a"] + BETTER_A for x in r),
                median_odo_m=float(np.median([x["odo_m"] for x in r])),
                median_fill_m=float(np.median([x["fill_m"] for x in r])))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("suite", help="suite file (suites/*.yaml, or a hunt folder's suite.yaml)")
    ap.add_argument("--cache", default=None, help="folder of the suite's generated worlds (made there if missing)")
    ap.add_argument("--only", default=None, metavar="NAME,...", help="only these datasets")
    ap.add_argument("--config", default=None, help="config (default: configs/default.yaml)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a key (repeatable)")
    a = ap.parse_args(argv)
    try:
        suite = load_suite(a.suite)
        only = set(a.only.split(",")) if a.only else None
        rows = []
        for d in suite.datasets:
            if only is not None and d.name not in only:
                continue
            if d.simulate is not None:
                if a.cache is None:
                    print(f"{d.name}: a generated world (give --cache)", file=sys.stderr)
                    continue
                # the tracking world, as mcl eval makes and caches it (a kidnap_at of the suite's left out)
                world = Path(make_world(str(_world_dir(Path(a.cache), d, False)), _sim_kwargs(d, False)))
                data = [f"map={world / 'map.yaml'}", f"log={world / 'log.clf'}"]
                truth = str(world / "truth.tum")
            elif d.truth is not None and (d.log is not None or d.bag is not None):
                data = [f"map={d.map}"] if d.map else []
                data.append(f"log={d.log}" if d.log is not None else f"bag={d.bag}")
                truth = d.truth
            else:
                print(f"{d.name}: no reference file", file=sys.stderr)
                continue
            sets = [f"{k}={v}" for k, v in d.set.items()] + list(a.set)
            cfg = load_config(a.config, data + sets) if a.config else default_config(data + sets)
            for w in windows(cfg, truth):
                rows.append(w)
                print(f"{d.name[:48]:48s} {w['cause']:9s} t={w['t0']:9.2f} {w['dt']:5.1f} s  reference "
                      f"{w['ref_m']:5.2f} m {w['ref_a']:+.2f} rad | odometry off {w['odo_m']:5.2f} m "
                      f"{w['odo_a']:.2f} rad | fill off {w['fill_m']:5.2f} m {w['fill_a']:.2f} rad", flush=True)
    except MclError as e:
        print(f"fill_accuracy: {e}", file=sys.stderr)
        return 2
    for c, s in summarize(rows).items():
        print(f"{c}: {s['windows']} windows; position: fill nearer {s['position_better']}, farther "
              f"{s['position_worse']} (median off {s['median_odo_m']:.2f} m -> {s['median_fill_m']:.2f} m); "
              f"heading: nearer {s['heading_better']}, farther {s['heading_worse']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
