"""Random hunts: suites of generated worlds or degraded real logs, each with conditions drawn at random, for finding
where the default config loses track on data it was never tuned on (docs/measurements.md, the hunts of the
eighty-first session on).

    python scripts/hunt.py synthetic SEED N OUT.yaml [--fast] [--modes tracking,global,kidnapped]
    python scripts/hunt.py real SEED N OUT_DIR [--conditions 2|3] [--no-range-cut] [--suite suites/real.yaml]
                                               [--modes ...]
    mcl eval --suite OUT.yaml --seeds 1 --jobs 2 --cache WORLDS        # then: the default against the baseline

``synthetic``: world k of SEED..SEED+N-1 is a ``mcl simulate`` world of a random kind with three conditions drawn
from ``CONDITIONS`` (people, other lasers, scan rates, speeds, noisy or scaled odometry, coarse or fine maps,
unmapped and phantom furniture, ground hits, unknown floor, the laser mounted elsewhere, a swept scan, doubled
walls, a turned or rescaled map, range scale or bias, reversals, slips, restarts, gaps and stalls), named
``KIND-C1-C2-C3-wK``; ``--fast`` leaves the scan rates out and scans at 15, 20 or 30 Hz. The draws are
``random.Random(k * 7919)``'s, so a world of the measurements (``corridor-doubled-2hz-mscale-w3726``) is made again
from its seed (hunts 17 on; the hunts before drew from fewer conditions). Modes tracking and kidnapped
(``--modes tracking,global,kidnapped`` adds global), ``lost_m`` 0.5.

``real``: log k of SEED..SEED+N-1 is one dataset of ``--suite`` (``suites/real.yaml``: the logs of ../shared/data)
run through ``scripts/degrade_laser.py`` with two or three conditions drawn from ``REAL_CONDITIONS``, into
``OUT_DIR/NAME``; ``OUT_DIR/suite.yaml`` lists them (absolute paths). ``rng8`` is no degradation but the laser read
to 8 m (``sensor.range_max``, for both configs); ``--no-range-cut`` leaves it out of the draw (the hunts r100-r423
drew without it, r600 on with it). Without a view, noise or dropout condition the laser is kept as it was (the
degrader's own defaults narrow it). Two conditions of one option may be drawn together (``rs98`` and ``rs102``,
``fov120`` and ``fov90``, ``ts95`` and ``ts107``, ``os95`` and ``os105``, ``rb+5`` and ``rb-5``): the name lists both,
the later one in the name is the one applied (argparse keeps an option's last value). The draws are left so, as the
measurements name their logs. Modes tracking and kidnapped (``--modes`` as for ``synthetic``; a dataset its suite
runs in fewer modes keeps to those, and one in none of them is left out), each dataset's ``lost_m`` as in the
suite.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import subprocess
import sys
from pathlib import Path

import yaml

from mcl.errors import MclError
from mcl.suite import load_suite, parse_modes

HERE = Path(__file__).resolve().parent
KINDS = ["office", "rooms", "corridor", "hall", "clutter", "large"]
HUNT_MODES = ("tracking", "kidnapped")  # the hunts' modes unless --modes says otherwise (global: the eighty-eighth on)

# name: mcl simulate keywords (None: drawn per world, see _synthetic)
CONDITIONS = {
    "p8": {"dynamic_obstacles": 8}, "p24": {"dynamic_obstacles": 24},
    "l270": {"fov": 3 * math.pi / 2, "n_beams": 541, "range_max": 25.0},
    "l360": {"fov": 2 * math.pi, "n_beams": 720, "range_max": 12.0},
    "r8": {"range_max": 8.0}, "r5": {"range_max": 5.0},
    "2hz": {"scan_rate": 2.0}, "10hz": {"scan_rate": 10.0}, "15hz": {"scan_rate": 15.0},
    "v1.5": {"speed": 1.5}, "slow": {"speed": 0.3},
    "turns": {"turn_rate": 1.5}, "noisy": {"odom_alphas": [0.15, 0.15, 0.15, 0.15]},
    "res10": {"map_resolution": 0.1}, "res2": {"map_resolution": 0.025},
    "furn": {"unmapped_furniture": 10}, "phantom": {"phantom_furniture": 8},
    "ground": {"ground_hits": 3}, "floor": {"unknown_floor": 2},
    "mountb": {"laser_pose": [-0.18, 0.0, math.pi]}, "mount": {"laser_pose": [0.15, 0.1, 0.0]},
    "sweep": {"scan_sweep": 0.1}, "doubled": {"doubled_walls": 6},
    "rot": None, "body": {"body": [[0.7, 0.8, 0.12], [2.3, 2.4, 0.12]]},
    "holo": {"holonomic": 1.0472, "odom_alphas": [0.1, 0.1, 0.1, 0.1]},
    "yawdrift": {"odom_yaw_drift": 0.04}, "oscale": {"odom_scale": 1.04},
    "pmax": {"p_max": 0.2}, "pshort": {"p_short": 0.2}, "rsig": {"range_sigma": 0.05},
    "rev": {"reversals": 6}, "slips": {"odom_slips": 3, "odom_slip_s": 2.0},
    "resets": {"odom_resets": 3, "odom_reset_s": 2.0}, "gaps": {"scan_gaps": 4, "scan_gap_s": 5.0},
    "stalls": {"odom_stalls": 3, "odom_stall_s": 3.0},
    "rscale": None, "res20": {"map_resolution": 0.2},
    "l90": {"fov": math.pi / 2, "n_beams": 160, "range_max": 8.0},
    "urg": {"fov": 4 * math.pi / 3, "n_beams": 682, "range_max": 5.6},
    "b45": {"n_beams": 45}, "v2": {"speed": 2.0}, "mscale": None, "rbias": None,
}

# name: scripts/degrade_laser.py arguments ("rng8": sensor.range_max 8 instead)
REAL_CONDITIONS = {
    "fov120": ["--fov", "120"], "fov90": ["--fov", "90"], "noise5": ["--sigma", "0.05"], "drop30": ["--drop", "0.3"],
    "rs98": ["--range-scale", "0.98"], "rs102": ["--range-scale", "1.02"],
    "rb+5": ["--range-bias", "0.05"], "rb-5": ["--range-bias", "-0.05"],
    "os95": ["--odom-scale", "0.95"], "os105": ["--odom-scale", "1.05"],
    "ts95": ["--turn-scale", "0.95"], "ts107": ["--turn-scale", "1.07"],
    "lat08": ["--latency", "0.08"], "late05": ["--stamp-late", "0.05"],
    "body": ["--body=80:100@0.25", "--body=-100:-80@0.25"],
    "dbl4": ["--doubled-walls", "4"], "rot30": ["--map-rotation", "30"], "gaps3": ["--scan-gaps", "3"],
    "stalls3": ["--odom-stalls", "3"], "rng8": [], "resets3": ["--odom-resets", "3", "--odom-reset-s", "2"],
}


def synthetic_world(k: int, fast: bool = False, kinds=KINDS) -> dict:
    """World ``k``'s suite entry: a random kind (of ``kinds``) with three random conditions (see the module doc)."""
    rng = random.Random(k * 7919)
    kind = rng.choice(list(kinds))
    pool = sorted(c for c in CONDITIONS if not (fast and c.endswith("hz")))
    conds = rng.sample(pool, 3)
    sim: dict = {"kind": kind, "seed": k, "duration": 90}
    for c in conds:
        if c == "rot":
            sim["map_rotation"] = round(rng.uniform(0.2, 3.0), 4)
        elif c == "rscale":
            sim["range_scale"] = round(rng.choice([0.97, 0.98, 1.02, 1.03]), 3)
        elif c == "mscale":
            sim["map_scale"] = rng.choice([0.98, 0.99, 1.01, 1.02])
        elif c == "rbias":
            sim["range_bias"] = rng.choice([-0.06, -0.04, 0.04, 0.06])
        else:
            for key, v in CONDITIONS[c].items():
                if key == "odom_alphas" and key in sim:  # noisy and holo: the first drawn
                    continue
                sim[key] = v
    if fast:
        sim["scan_rate"] = rng.choice([15.0, 20.0, 30.0])
        conds.append(f"{int(sim['scan_rate'])}hz")
    if "scan_sweep" in sim:  # a sweep within one scan period, and nothing moving through it
        sim["scan_sweep"] = math.floor(min(0.1, 1.0 / sim.get("scan_rate", 5.0)) * 1e4) / 1e4
        sim["dynamic_obstacles"] = 0
        sim["unmapped_furniture"] = 0
    return {"name": f"{kind}-{'-'.join(conds)}-w{k}", "simulate": sim}


def synthetic(seed: int, n: int, out: Path, fast: bool = False, modes=HUNT_MODES, kinds=KINDS) -> list[str]:
    """Write the suite of worlds ``seed``..``seed + n - 1`` (of ``kinds``) to ``out``, run in ``modes``; return their
    names."""
    datasets = [synthetic_world(k, fast, kinds) for k in range(seed, seed + n)]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(yaml.safe_dump({"name": f"hunt{seed}", "modes": list(modes), "lost_m": 0.5,
                                   "datasets": datasets}, sort_keys=False, width=200))
    return [d["name"] for d in datasets]


def real_draw(k: int, datasets: list, conditions: int = 3, range_cut: bool = True) -> tuple[dict, list[str]]:
    """Log ``k``'s dataset (one of ``datasets``, as they come) and its conditions (see the module doc)."""
    rng = random.Random(k * 7919)
    d = rng.choice(datasets)
    pool = sorted(c for c in REAL_CONDITIONS if range_cut or c != "rng8")
    return d, rng.sample(pool, conditions)


def real(seed: int, n: int, out: Path, suite: Path, conditions: int = 3, range_cut: bool = True,
         modes=HUNT_MODES) -> list[str]:
    """Degrade logs ``seed``..``seed + n - 1`` into ``out`` and write ``out/suite.yaml``; return their names. A bad
    ``suite`` raises ``mcl.suite.load_suite``'s error; a log the degrader refuses, SystemExit naming it."""
    datasets = load_suite(suite).datasets  # the paths resolved against the suite's root
    entries = []
    for k in range(seed, seed + n):
        d, conds = real_draw(k, datasets, conditions, range_cut)
        # the modes asked for, as far as the source suite runs the dataset (suites/real.yaml: infinite_corridor has
        # no global run)
        own_modes = [m for m in modes if m in d.modes]
        if not own_modes:
            print(f"hunt.py: r{k}: {d.name} left out: its suite runs it in {', '.join(d.modes)} only", file=sys.stderr)
            continue
        args = [a for c in conds for a in REAL_CONDITIONS[c]]
        if not any(c.startswith(("fov", "noise", "drop")) for c in conds):
            args += ["--fov", "180", "--sigma", "0", "--drop", "0"]  # the laser as it was
        name = f"{d.name}-{'-'.join(conds)}-r{k}"
        folder = out / name
        folder.mkdir(parents=True, exist_ok=True)
        one = folder.with_name(name + ".suite.yaml")
        # the dataset's own keys; a dataset config's laser is a config key too (a suite entry has no laser key)
        own = {**({"laser": d.laser} if d.laser is not None else {}), **d.set}
        entry = {"name": d.name, "map": d.map, "log": d.log, "truth": d.truth, "lost_m": d.lost_m,
                 **({"initial_pose": list(d.initial_pose)} if d.initial_pose is not None else {}),
                 **({"set": own} if own else {})}
        one.write_text(yaml.safe_dump({"name": d.name, "datasets": [entry]}, sort_keys=False))
        done = subprocess.run([sys.executable, str(HERE / "degrade_laser.py"), "--suite", str(one), "--seed", str(k),
                               *args, str(folder)], stdout=subprocess.DEVNULL)
        if done.returncode != 0:  # its own error line is above
            raise SystemExit(f"hunt.py: {one}: scripts/degrade_laser.py failed (exit {done.returncode})")
        made = yaml.safe_load((folder / "suite.yaml").read_text())
        for x in made["datasets"]:
            for key in ("map", "log", "truth"):
                if key in x and not os.path.isabs(x[key]):
                    x[key] = os.path.join(made["root"], x[key])
            x["name"] = name
            if "rng8" in conds:  # beside the dataset's own settings
                x["set"] = {**x.get("set", {}), "sensor.range_max": 8.0}
            if own_modes != list(modes):
                x["modes"] = own_modes
            entries.append(x)
    if not entries:
        raise SystemExit(f"hunt.py: {suite}: no dataset of draws {seed}..{seed + n - 1} runs in {', '.join(modes)}")
    (out / "suite.yaml").write_text(yaml.safe_dump({"name": f"realhunt{seed}", "root": "/",
                                                    "modes": list(modes), "datasets": entries},
                                                   sort_keys=False, width=200))
    return [x["name"] for x in entries]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    s = sub.add_parser("synthetic", help="a suite of generated worlds, three random conditions each")
    s.add_argument("seed", type=int, help="the first world's seed")
    s.add_argument("n", type=int, help="how many worlds")
    s.add_argument("out", type=Path, help="the suite file to write")
    s.add_argument("--fast", action="store_true", help="no scan-rate condition; every world at 15, 20 or 30 Hz")
    s.add_argument("--kinds", default=",".join(KINDS), metavar="K,...",
                   help=f"the world kinds drawn from (default {','.join(KINDS)}; mcl simulate --kind has "
                   "warehouse too)")
    r = sub.add_parser("real", help="a suite of real logs degraded with random conditions")
    r.add_argument("seed", type=int, help="the first log's draw")
    r.add_argument("n", type=int, help="how many logs")
    r.add_argument("out", type=Path, help="the folder to write the logs and suite.yaml into")
    r.add_argument("--conditions", type=int, choices=(2, 3), default=3, help="conditions per log (default 3)")
    r.add_argument("--no-range-cut", action="store_true", help="leave rng8 (the laser read to 8 m) out of the draw")
    r.add_argument("--suite", type=Path, default=HERE.parent / "suites" / "real.yaml",
                   help="the suite whose datasets are drawn from (default suites/real.yaml)")
    for p in (s, r):
        p.add_argument("--modes", default=",".join(HUNT_MODES), metavar="M,...",
                       help=f"the modes the suite names: tracking, global, kidnapped (default {','.join(HUNT_MODES)})")
    a = ap.parse_args(argv)
    if a.n < 1:
        ap.error(f"n: expected at least 1, got {a.n}")
    try:
        modes = parse_modes(a.modes)
    except MclError as e:
        ap.error(str(e))
    if a.what == "synthetic":
        from mcl.worlds import KINDS as ALL_KINDS

        kinds = [k.strip() for k in a.kinds.split(",") if k.strip()]
        bad = [k for k in kinds if k not in ALL_KINDS]
        if bad or not kinds:
            ap.error(f"--kinds: expected some of {', '.join(ALL_KINDS)}, got {a.kinds!r}")
        names = synthetic(a.seed, a.n, a.out, a.fast, modes, kinds)
        print(f"{a.out}: {len(names)} worlds")
    else:
        try:
            names = real(a.seed, a.n, a.out, a.suite, a.conditions, not a.no_range_cut, modes)
        except MclError as e:
            ap.error(str(e))  # names the file and the entry
        print(f"{a.out / 'suite.yaml'}: {len(names)} logs")
    for name in names:
        print(" ", name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
