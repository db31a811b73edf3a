#!/usr/bin/env python
"""Was a failed run of ``mcl eval`` a miss, or could no scan have told the places apart?

For every lost run in an evaluation folder (``mcl eval --out DIR``), the scans of the 30 s the suite allows
(from the kidnap, or from the start in global mode; the first 2 s left out) are laid on the map twice with
``mcl.quality`` (the filter's quality signal: score = match - 2 contradiction), once at the reference pose
and once at the run's estimate, for the scans where the estimate is more than 1 m off. Printed per run:
the median score at each, and the share of those scans the estimate fits at least as well as the
reference does.

* **ambiguous**: the wrong estimate fits at least as well as the reference in half the scans or more, and
  its median score is within 0.02 of the reference's. Over that window the scans are as well explained
  from the wrong place (a featureless corridor's other end, an identical room): by the score, a filter that
  weighs scans against the map has no evidence to move on, whatever its policies (by the likelihood it may
  have a little, below).
* **miss**: the reference fits better; the filter stayed at a worse place (its quality signal was above
  ``quality.lost_below``, so no recovery ran), or searched and did not settle in time.

The likelihood is also summed over the scans since the estimate last jumped against the reference (its offset from
the reference changing by more than ``JUMP_M`` between two scans: a search settling, a re-seed): a sum of thousands
of nats can come all from a search's first, wandering scans, while the place it settled on gives the truth nothing
(``rooms-03`` global seed 2: 12,430 nats, none after 9 s).

Each such run also gets the filter's own laser log-likelihood at the reference against the estimate over the same
scans, each pose first moved to the best-scoring pose within 0.1 m and 0.05 rad of it (three rounds of a 5 x 5 x 5
grid, each a quarter of the last: the estimate is a cluster's mean, a few centimetres off the pose that fits its
place best, and that alone costs a few nats a scan at the truth's advantage). The quality score counts a beam as
matched within a tolerance; the likelihood also sees the centimetres within it, so a place the score finds as good
can still lose a nat or two a scan. These nats are shown, not used to classify: the beams of a scan are not
independent, and a map a few centimetres off costs as many.

A lost **tracking** run (maximum error above the dataset's ``lost_m``, which can be well under 1 m) is judged
on the scans where its error exceeds ``lost_m``, with the filter's own laser log-likelihood (the weight it
gives a pose): the reference's advantage over the estimate, summed over those scans.

* **ambiguous**: the scans favour the reference by less than ``LL_SAME`` nats in all (the weight of the two
  poses within a factor e^3 = 20 over the whole excursion): a long featureless corridor, where every pose
  along it explains the scans alike and the error is the odometry's drift since the last feature.
* **miss**: the scans favoured the reference and the filter did not follow.

Printed with it: how far the odometry alone is off at the scan where the estimate was farthest, started at the
reference on the last scan the estimate was within ``FIX_M`` of it (``dead_reckoning``). An estimate no farther off
than that has done what a filter can with no scan to pin it: followed the odometry from its last fix.

With ``--timeline`` each global or kidnapped run's judged scans are printed one a line (time, offset, gain, the two
scores): the evidence for the reference comes in bursts, where the robot passes something the two places do not
share (``corridor-05`` kidnapped seed 1: 20-53 nats a scan at 61 s and 70-76 s, none for seconds between).

Usage::

    .venv/bin/python scripts/ambiguity.py DIR [--only NAME,...] [--timeline]

Reads each run's ``config.yaml`` (map, log, truth: synthetic worlds must still be in the cache the
evaluation used), ``row.json`` and ``trajectory.tum``; writes nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mcl.config import load_config  # noqa: E402
from mcl.errors import MclError  # noqa: E402
from mcl.estimate import compose, inverse  # noqa: E402
from mcl.filter import ParticleFilter  # noqa: E402
from mcl.runner import _open_source  # noqa: E402  (the scans a run uses, from a CARMEN log or a bag)
from mcl.suite import WITHIN_S  # noqa: E402
from mcl.trajectory import read_tum  # noqa: E402

SKIP_S = 2.0  # the first scans after the kidnap or the start: every filter is still moving there
OFF_M = 1.0  # an estimate this far from the reference is a wrong place, not a noisy track
SAME = 0.02  # medians closer than this are the same fit
_REFINE = np.array(np.meshgrid(np.linspace(-0.1, 0.1, 5), np.linspace(-0.1, 0.1, 5), np.linspace(-0.05, 0.05, 5),
                               indexing="ij")).reshape(3, -1)  # the first round's offsets (x, y, theta)
JUMP_M = 0.5  # m: the estimate's offset from the reference changing this much from one scan to the next is a jump
LL_SAME = 3.0  # tracking: nats of evidence for the reference, over the whole excursion, below which it is ambiguous
FIX_M = 0.1  # tracking: the estimate this near the reference is a fix that dead reckoning is started from


def _at(t_ref: np.ndarray, t: float) -> int | None:
    i = int(np.searchsorted(t_ref, t))
    for j in (i - 1, i):
        if 0 <= j < t_ref.size and abs(t_ref[j] - t) <= 1e-3:
            return j
    return None


def _run(run_dir: Path, cache: dict):
    """(filter, scans, reference t, reference poses, estimate t, estimate poses) of a run folder; the filter, the
    scans and the reference are read once per dataset into ``cache``."""
    cfg = load_config(run_dir / "config.yaml", [])
    key = (cfg.map, cfg.log, cfg.bag)
    if key not in cache:
        _, grid, scans, _, truth, _ = _open_source(cfg, echo=lambda msg: None)
        cache[key] = (ParticleFilter(cfg, grid), scans, truth.t, truth.poses)
    te, pe = read_tum(run_dir / "trajectory.tum")
    return (*cache[key], te, pe)


def best_loglik(pf, pose: np.ndarray, obs) -> float:
    """The filter's laser log-likelihood at the best pose near ``pose`` (three rounds of ``_REFINE``, each a quarter
    of the last, around the best so far)."""
    best, ll = np.asarray(pose, dtype=np.float64), -np.inf
    for k in range(3):
        cand = best[:, None] + _REFINE / 4.0 ** k
        lik = pf.sensor.log_likelihood(np.ascontiguousarray(cand), obs)
        i = int(np.argmax(lik))
        if lik[i] > ll:
            best, ll = cand[:, i], float(lik[i])
    return ll


def classify(run_dir: Path, row: dict, cache: dict) -> dict | None:
    """The scores at the reference and at the estimate over the window, for one lost run (None: no scan)."""
    pf, scans, tt, tp, te, pe = _run(run_dir, cache)
    t0 = row.get("kidnap_t") if row["mode"] == "kidnapped" else te[0]
    ref, est, gain, offset, when, index = [], [], [], [], [], []
    for k, s in enumerate(scans):
        if not t0 + SKIP_S <= s.t <= t0 + WITHIN_S:
            continue
        i, j = _at(tt, s.t), _at(te, s.t)
        if i is None or j is None or np.hypot(*(pe[:2, j] - tp[:2, i])) <= OFF_M:
            continue
        laser = s.laser_offset if s.laser_offset is not None else np.zeros(3)
        obs = pf.prepare(s, laser)
        if obs is None:
            continue
        e = pf.sensor.endpoints(obs)
        fr, fe = pf.quality.fit(tp[:, i], e, laser[:2]), pf.quality.fit(pe[:, j], e, laser[:2])
        if fr.beams >= pf.cfg.quality.min_beams:
            ref.append(fr.score)
            est.append(fe.score)
            gain.append(best_loglik(pf, tp[:, i], obs) - best_loglik(pf, pe[:, j], obs))
            offset.append(pe[:2, j] - tp[:2, i])
            when.append(s.t)
            index.append(k)
    if not ref:
        return None
    ref, est = np.array(ref), np.array(est)
    m_ref, m_est, share = float(np.median(ref)), float(np.median(est)), float(np.mean(est >= ref - 1e-9))
    # the scans since the estimate last jumped against the reference (a search settling, a re-seed): what the place
    # the filter held gave the truth, apart from what a search's wandering first scans did
    # (between two scans that follow each other in the log: across scans left out, where the estimate came within
    # OFF_M, a mirror-image estimate moving against the robot changes its offset smoothly, not by a jump)
    step = np.hypot(*np.diff(np.array(offset), axis=0).T) if len(offset) > 1 else np.zeros(0)
    jumps = np.flatnonzero((step > JUMP_M) & (np.diff(index) == 1))
    held = int(jumps[-1]) + 1 if jumps.size else 0
    off = np.hypot(*np.array(offset).T)
    return {"scans": int(ref.size), "reference": m_ref, "estimate": m_est, "share": share,
            "gain": float(np.sum(gain)), "gain_median": float(np.median(gain)),
            "gain_held": float(np.sum(gain[held:])), "held_s": float(when[-1] - when[held]),
            "kind": "ambiguous" if share >= 0.5 and m_est >= m_ref - SAME else "miss",
            # per scan: log time, the estimate's distance from the reference (m), the reference's likelihood gain
            # (nats), the scores at the reference and at the estimate
            "timeline": list(zip(map(float, when), map(float, off), map(float, gain), map(float, ref),
                                 map(float, est)))}


def dead_reckoning(fix_pose, fix_odom, odom) -> np.ndarray:
    """(3,) the pose that the odometry alone gives at ``odom`` (x, y, theta in its frame), started from the
    reference ``fix_pose`` where the odometry read ``fix_odom``: fix_pose (+) (fix_odom^-1 (+) odom)."""
    return compose(fix_pose, compose(inverse(fix_odom), odom))


def classify_tracking(run_dir: Path, row: dict, cache: dict) -> dict | None:
    """The laser log-likelihood at the reference against the estimate, over the scans of a lost tracking run
    whose error exceeds its ``lost_m`` (None: no such scan has a reference).

    Also, for those scans, dead reckoning's own error: the odometry alone, started at the reference on the last scan
    the estimate was within ``FIX_M`` of it. An estimate as far off as dead reckoning has drifted since its last fix
    followed the odometry, as a filter must where no scan pins the pose (``dead_reckoning_at_worst``: at the scan
    where the estimate was farthest off; None: no fix before it, or a log with no odometry)."""
    pf, scans, tt, tp, te, pe = _run(run_dir, cache)
    gain, off, drift = [], [], []
    fix = None  # (reference pose, odometry) at the last scan the estimate was within FIX_M
    for s in scans:
        i, j = _at(tt, s.t), _at(te, s.t)
        if i is None or j is None:
            continue
        err = float(np.hypot(*(pe[:2, j] - tp[:2, i])))
        if err <= FIX_M and s.odom is not None:
            fix = (tp[:, i].copy(), np.asarray(s.odom, dtype=np.float64))
        if err <= row["lost_m"]:
            continue
        laser = s.laser_offset if s.laser_offset is not None else np.zeros(3)
        obs = pf.prepare(s, laser)
        if obs is None:
            continue
        ll = pf.sensor.log_likelihood(np.column_stack([tp[:, i], pe[:, j]]), obs)
        gain.append(float(ll[0] - ll[1]))
        off.append(err)
        dr = None if fix is None or s.odom is None else dead_reckoning(*fix, np.asarray(s.odom, dtype=np.float64))
        drift.append(None if dr is None else float(np.hypot(*(dr[:2] - tp[:2, i]))))
    if not gain:
        return None
    total = float(np.sum(gain))
    worst = int(np.argmax(off))
    return {"scans": len(gain), "gain": total, "per_scan_max": float(np.max(gain)), "max_err": float(off[worst]),
            "dead_reckoning_at_worst": drift[worst], "kind": "ambiguous" if total < LL_SAME else "miss"}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folder", type=Path, help="an mcl eval output folder (with runs/)")
    p.add_argument("--only", help="only these datasets (comma separated)")
    p.add_argument("--timeline", action="store_true",
                   help="also print each judged scan of a global or kidnapped run: time, the estimate's distance from "
                        "the reference, the reference's likelihood gain and the two scores (where the evidence came)")
    a = p.parse_args(argv)
    only = set(a.only.split(",")) if a.only else None
    cache: dict = {}
    kinds: Counter = Counter()
    for row_file in sorted(a.folder.glob("runs/*/*/*/seed*/row.json")):
        row = json.loads(row_file.read_text())
        if not row.get("lost") or (only and row["dataset"] not in only):
            continue
        tracking = row["mode"] == "tracking"
        try:
            c = (classify_tracking if tracking else classify)(row_file.parent, row, cache)
        except (MclError, OSError) as e:  # a synthetic world no longer in its cache, a moved log
            print(f"{row['dataset']:26s} {row['mode']:9s} {row['config']:9s} seed {row['seed']}: cannot read: {e}")
            kinds["unread"] += 1
            continue
        if c is None and tracking:
            print(f"{row['dataset']:26s} {row['mode']:9s} {row['config']:9s} seed {row['seed']}: no scan with a "
                  f"reference more than {row['lost_m']:g} m off")
            kinds["late"] += 1
            continue
        if c is None:
            print(f"{row['dataset']:26s} {row['mode']:9s} {row['config']:9s} seed {row['seed']}: no scan "
                  f"more than {OFF_M:g} m off in the window (lost later, or scored on the last poses)")
            kinds["late"] += 1
            continue
        kinds[c["kind"]] += 1
        if tracking:
            print(f"{row['dataset']:26s} {row['mode']:9s} {row['config']:9s} seed {row['seed']}: {c['kind']:9s} "
                  f"{c['scans']:4d} scans more than {row['lost_m']:g} m off (max {c['max_err']:.2f} m), the scans "
                  f"favour the reference by {c['gain']:.1f} nats in all (at most {c['per_scan_max']:.1f} in one)"
                  + ("" if c["dead_reckoning_at_worst"] is None else
                     f"; there, the odometry alone from the last fix within {FIX_M:g} m is "
                     f"{c['dead_reckoning_at_worst']:.2f} m off"))
            continue
        print(f"{row['dataset']:26s} {row['mode']:9s} {row['config']:9s} seed {row['seed']}: {c['kind']:9s} "
              f"{c['scans']:4d} scans, median score reference {c['reference']:.3f} estimate {c['estimate']:.3f}, "
              f"estimate fits as well in {c['share']:.0%}; likelihood for the reference {c['gain']:.0f} nats "
              f"(median {c['gain_median']:.2f} a scan), {c['gain_held']:.0f} of them over the last "
              f"{c['held_s']:.1f} s, since the estimate last jumped")
        if a.timeline:
            for t, off, g, r, e in c["timeline"]:
                print(f"    t {t:8.2f} s  {off:7.2f} m off  gain {g:9.2f} nats  "
                      f"score reference {r:.3f} estimate {e:.3f}")
    print("lost runs: " + ", ".join(f"{n} {k}" for k, n in sorted(kinds.items())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
