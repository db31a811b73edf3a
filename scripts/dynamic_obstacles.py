"""ATE with and without beam skipping on logs with obstacles the map does not show.

Beam skipping here is the config's (the default: rule ``short``, 0.25 m / 0.5;
``--set sensor.beam_skip_rule=amcl --set sensor.beam_skip_distance=0.5
--set sensor.beam_skip_threshold=0.3`` gives AMCL's).

Synthetic: ``mcl simulate --dynamic-obstacles N`` worlds (boxes near the path and
walking people that block the laser but are not in the saved map), tracked from
the true start pose with the default config, beam skipping off and on, and each
with augmented MCL (``filter.recovery=true``; the default is ``lost``, which this
script does not run) on and off: unexplained beams lower the measurement
likelihood, which augmented MCL reads as a kidnapping. The same
worlds without the obstacles are the reference. Real: ``../shared/data/fr079``
(people walking) with configs/fr079.yaml, beam skipping off and on.

    .venv/bin/python scripts/dynamic_obstacles.py [--seeds 5] [--obstacles 30] [--no-fr079]
"""

from __future__ import annotations

import argparse
import tempfile
import warnings
from pathlib import Path

import yaml

from mcl.config import PROJECT_ROOT, load_config
from mcl.runner import run
from mcl.simulate import simulate

SHARED = PROJECT_ROOT.parent / "shared" / "data"


def _quiet(*_a, **_k):
    pass


def track(config, overrides, out):
    cfg = load_config(config, ["rerun.mode=off", *overrides])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = run(cfg, out, progress=False, echo=_quiet)
    return s["eval"], s.get("skipped_beams", 0), s["updates"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--obstacles", type=int, default=30)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--particles", type=int, default=2000)
    ap.add_argument("--no-fr079", action="store_true")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="extra config overrides for every run, e.g. sensor.beam_skip_distance=0.25")
    args = ap.parse_args()

    default = PROJECT_ROOT / "configs" / "default.yaml"
    print(f"{'log':<26} {'recovery':>8} {'beam skip':>9} {'ATE RMSE':>9} {'ATE max':>8} {'skipped/upd':>11}")
    sums = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for seed in range(args.seeds):
            for n_obst in (0, args.obstacles):
                d = tmp / f"sim{seed}_{n_obst}"
                simulate(d, seed=seed, duration=args.duration, dynamic_obstacles=n_obst)
                start = yaml.safe_load((d / "sim.yaml").read_text())["start_pose"]
                base = [f"map={d / 'map.yaml'}", f"log={d / 'log.clf'}", f"truth={d / 'truth.tum'}",
                        "filter.global_localization=false", f"filter.initial_pose={start}",
                        "filter.initial_std=[0.05,0.05,0.05]", f"filter.particles={args.particles}", *args.set]
                for rec in ((True, False) if n_obst else (True,)):
                    for skip in (False, True):
                        ev, skipped, ups = track(default, base + [f"sensor.beam_skip={str(skip).lower()}",
                                                                  f"filter.recovery={str(rec).lower()}"],
                                                 tmp / f"run{seed}_{n_obst}_{skip}_{rec}")
                        name = f"sim seed {seed}, {n_obst} obstacles"
                        print(f"{name:<26} {('on' if rec else 'off'):>8} {('on' if skip else 'off'):>9} "
                              f"{ev['ate_rmse']:9.3f} {ev['ate_max']:8.3f} {skipped / max(ups, 1):11.1f}", flush=True)
                        sums.setdefault((n_obst, rec, skip), []).append(ev["ate_rmse"])
        for (n_obst, rec, skip), v in sorted(sums.items()):
            print(f"mean ATE RMSE over {len(v)} worlds, {n_obst} obstacles, recovery {'on' if rec else 'off'}, "
                  f"beam skip {'on' if skip else 'off'}: {sum(v) / len(v):.3f} m (worst {max(v):.3f}, "
                  f"lost (> 0.5 m) in {sum(x > 0.5 for x in v)})")
        if not args.no_fr079 and (SHARED / "fr079").is_dir():
            for skip in (False, True):
                ev, skipped, ups = track(PROJECT_ROOT / "configs" / "fr079.yaml",
                                         [f"sensor.beam_skip={str(skip).lower()}", *args.set], tmp / f"fr079_{skip}")
                print(f"{'fr079':<26} {'config':>8} {('on' if skip else 'off'):>9} {ev['ate_rmse']:9.3f} {ev['ate_max']:8.3f} "
                      f"{skipped / max(ups, 1):11.1f}", flush=True)


if __name__ == "__main__":
    main()
