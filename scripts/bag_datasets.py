"""Every real dataset as an MCAP bag, tracked like its CARMEN log (issue 9).

For each folder of ../shared/data (every one; ``--track`` picks those tracked) the CARMEN log becomes
``OUT/<name>.mcap`` with ``mcl convert`` (mcl.datasets.bagwrite): /scan, /odom and /tf_static, except

* ``intel_lab``: the odometry as ``odom -> base_link`` on ``/tf`` (no odometry topic);
* ``mit_csail``: the laser mounted off-centre, ``base_link -> laser`` = MOUNT on ``/tf_static``: the odometry
  is then the new base frame's (base = robot ∘ MOUNT⁻¹) and so are the reference (``<name>.base.tum``) and the
  bag's start pose (the config's, moved by MOUNT⁻¹: the log's pose, 0.25 m away, went unnoticed only because
  mit_csail's truth starts 13 s into the log).

Then ``mcl run`` tracks the CARMEN log and the bag with the same config and seeds, and prints the ATE RMSE of
both (mean over the seeds) and whether the two trajectories are byte-identical. Configs: ``configs/<name>.yaml``
when there is one, else the defaults with the dataset's map, log, truth and start pose (meta.json).

    python scripts/bag_datasets.py                     # convert all, track intel_lab mit_csail fr101 aces, seed 1
    python scripts/bag_datasets.py --track all --seeds 1 2 3
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mcl.config import load_config  # noqa: E402
from mcl.datasets.bagwrite import convert  # noqa: E402
from mcl.runner import compose, inverse, run  # noqa: E402
from mcl.trajectory import read_tum, write_tum  # noqa: E402

DATA = ROOT.parent / "shared" / "data"
MOUNT = (0.25, -0.05, 0.1)  # x, y (m), theta (rad) of the laser on mit_csail's new base frame
VARIANT = {"intel_lab": "tf", "mit_csail": "mount"}
START = {"mit_csail": [-0.0578, 0.0208, -0.2048]}  # README: no meta.json


def base_truth(truth: Path, out: Path) -> Path:
    """The reference of the base frame: truth ∘ MOUNT⁻¹ (the log's laser sits at the robot's centre)."""
    t, p = read_tum(truth)
    inv = inverse(np.array(MOUNT))
    q = np.array([compose(p[:, k], inv) for k in range(t.size)]).T
    write_tum(out, t, q)
    return out


def config_overrides(name: str) -> tuple[Path, list[str]]:
    d = DATA / name
    cfg = ROOT / "configs" / f"{name}.yaml"
    if cfg.exists():
        return cfg, []
    meta = json.loads((d / "meta.json").read_text()) if (d / "meta.json").exists() else {}
    start = meta.get("start", START.get(name))
    over = [f"map={d / 'map.yaml'}", f"log={d / 'log.clf'}", f"truth={d / 'truth.tum'}",
            f"filter.initial_pose={list(start)}", "filter.global_localization=false"]
    return ROOT / "configs" / "default.yaml", over


def track(name: str, bag: Path, truth_bag: Path | None, seeds, out: Path, particles: int | None) -> dict:
    path, over = config_overrides(name)
    over = over + ["rerun.mode=off"] + ([f"filter.particles={particles}"] if particles else [])
    res = {"clf": [], "mcap": [], "identical": [], "time_clf": 0.0, "time_mcap": 0.0}
    for seed in seeds:
        for kind in ("clf", "mcap"):
            extra = [f"seed={seed}"]
            if kind == "mcap":
                extra += ["log=null", f"bag={bag}"] + ([f"truth={truth_bag}"] if truth_bag else [])
                if VARIANT.get(name) == "mount":  # the base frame's start, as its odometry and reference are
                    start = np.array(load_config(path, over).filter.initial_pose, dtype=float)
                    extra.append(f"filter.initial_pose={[float(v) for v in compose(start, inverse(np.array(MOUNT)))]}")
            cfg = load_config(path, over + extra)
            t0 = time.perf_counter()
            s = run(cfg, out / f"{name}-{kind}-{seed}", progress=False, echo=lambda m: None)
            res[f"time_{kind}"] += time.perf_counter() - t0
            res[kind].append(s["eval"]["ate_rmse"])
        a = (out / f"{name}-clf-{seed}" / "trajectory.tum").read_bytes()
        b = (out / f"{name}-mcap-{seed}" / "trajectory.tum").read_bytes()
        res["identical"].append(a == b)
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(ROOT / "runs" / "bags"), help="folder for the bags and runs (runs/bags)")
    ap.add_argument("--track", nargs="*", default=["intel_lab", "mit_csail", "fr101", "aces"],
                    help="datasets to track (all: every one); default intel_lab mit_csail fr101 aces")
    ap.add_argument("--seeds", nargs="*", type=int, default=[1])
    ap.add_argument("--particles", type=int, help="filter.particles for every run (default: the configs')")
    args = ap.parse_args(argv)
    if not DATA.is_dir():
        print(f"no datasets at {DATA}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    names = sorted(p.name for p in DATA.iterdir() if (p / "log.clf").exists())
    wanted = names if args.track == ["all"] else args.track
    for name in names:
        bag = out / f"{name}.mcap"
        variant = VARIANT.get(name, "topic")
        if bag.exists():
            bag.unlink()
        t0 = time.perf_counter()
        n = convert(DATA / name / "log.clf", bag, odom="tf" if variant == "tf" else "topic",
                    mount=MOUNT if variant == "mount" else None, echo=lambda m: None)
        dt = time.perf_counter() - t0
        truth_bag = base_truth(DATA / name / "truth.tum", out / f"{name}.base.tum") if variant == "mount" else None
        line = (f"{name:18s} {variant:6s} {n:5d} scans -> {bag.name} ({bag.stat().st_size / 1e6:.1f} MB "
                f"vs {(DATA / name / 'log.clf').stat().st_size / 1e6:.1f} MB clf, {dt:.1f} s)")
        if name in wanted:
            r = track(name, bag, truth_bag, args.seeds, out, args.particles)
            line += (f"  ATE clf {np.mean(r['clf']):.4f} m, mcap {np.mean(r['mcap']):.4f} m "
                     f"(seeds {' '.join(map(str, args.seeds))}; per seed clf {r['clf']}, mcap {r['mcap']}); "
                     f"identical trajectories: {sum(r['identical'])}/{len(r['identical'])}; "
                     f"run time clf {r['time_clf']:.0f} s, mcap {r['time_mcap']:.0f} s")
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
