"""Bag replay speed and memory (issue 9): a 10-minute recording with a 40 Hz laser, as CARMEN and as bags.

A synthetic world (mcl.simulate) driven for DURATION s with odometry and a 1081-beam, 270-degree laser at 40 Hz
(24,000 scans) is written as a CARMEN log and converted to MCAP, ROS 1 and db3 bags. In a fresh process each (so
the peak resident memory is its own):

* read, each of the four: every scan record produced (CARMEN: read_carmen; bag: open_bag + the scan stream);
* run, the CARMEN log and the MCAP bag: ``mcl run`` end to end (300 particles, rerun off, one thread) on the world's
  map.

Prints wall time and peak RSS of each, and whether the runs' trajectories are byte-identical.

    python scripts/bench_bag.py [--duration 600] [--out runs/bench_bag] [--no-run]
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def make(out: Path, duration: float) -> None:
    import mcl.simulate as sim
    from mcl.datasets.bagwrite import convert

    t0 = time.perf_counter()
    sim.simulate(out, seed=1, duration=duration, n_beams=1081, fov=math.radians(270.0), range_max=30.0,
                 scan_rate=40.0)  # 40 Hz laser and odometry
    print(f"simulated {duration:.0f} s in {time.perf_counter() - t0:.0f} s", flush=True)
    for ext in ("mcap", "bag", "db3"):
        t0 = time.perf_counter()
        n = convert(out / "log.clf", out / f"log.{ext}", echo=lambda m: None)
        print(f"log.{ext}: {n} scans, {(out / f'log.{ext}').stat().st_size / 1e6:.0f} MB, written in "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
    print(f"log.clf: {(out / 'log.clf').stat().st_size / 1e6:.0f} MB", flush=True)


def child_read(path: str) -> dict:
    t0 = time.perf_counter()
    n, beams = 0, 0
    if path.endswith(".clf"):
        from mcl.datasets.carmen import read_carmen

        for s in read_carmen(path).laser_stream():
            n += 1
            beams += s.ranges.size
    else:
        from mcl.datasets.rosbag import open_bag

        for s in open_bag(path).scans:
            n += 1
            beams += s.ranges.size
    return {"scans": n, "beams": beams, "wall_s": time.perf_counter() - t0}


def child_run(path: str, out: str) -> dict:
    import numba

    from mcl.config import load_config
    from mcl.runner import run

    numba.set_num_threads(1)
    d = Path(path).parent
    key = "log" if path.endswith(".clf") else "bag"
    over = [f"map={d / 'map.yaml'}", "log=null", f"{key}={path}", "truth=null", "rerun.mode=off",
            "filter.particles=300", "filter.kld=false", "filter.initial_pose=null", "filter.global_localization=false"]
    cfg = load_config(ROOT / "configs" / "default.yaml", over)
    sim = (d / "sim.yaml").read_text()
    import yaml

    start = yaml.safe_load(sim)["start_pose"]
    cfg = load_config(ROOT / "configs" / "default.yaml", over + [f"filter.initial_pose={start}"])
    t0 = time.perf_counter()
    s = run(cfg, Path(out), progress=False, echo=lambda m: None)
    return {"updates": s["updates"], "wall_s": time.perf_counter() - t0, "load_s": s["wall_time_s"]["load"],
            "loop_s": s["wall_time_s"]["loop"]}


def peak_rss_mb() -> float:
    """This process's peak resident memory (VmHWM: unlike ru_maxrss, not inherited from the parent)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def in_child(*args: str) -> dict:
    r = subprocess.run([sys.executable, __file__, "--child", *args], capture_output=True, text=True, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench_bag"))
    ap.add_argument("--no-run", action="store_true", help="only the read benchmark")
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        what, *rest = args.child
        r = child_read(*rest) if what == "read" else child_run(*rest)
        r["peak_rss_mb"] = peak_rss_mb()
        print(json.dumps(r))
        return 0
    out = Path(args.out)
    if not (out / "log.db3").exists():
        out.mkdir(parents=True, exist_ok=True)
        make(out, args.duration)
    logs = [out / "log.clf", out / "log.mcap", out / "log.bag", out / "log.db3"]
    for p in logs:
        r = in_child("read", str(p))
        print(f"read {p.name:9s} {r['scans']} scans in {r['wall_s']:6.1f} s, peak RSS {r['peak_rss_mb']:6.0f} MB",
              flush=True)
    if not args.no_run:
        for p in logs[:2]:
            r = in_child("run", str(p), str(out / f"run-{p.suffix[1:]}"))
            print(f"run  {p.name:9s} {r['updates']} updates in {r['wall_s']:6.1f} s (load {r['load_s']:.1f} s, "
                  f"loop {r['loop_s']:.1f} s), peak RSS {r['peak_rss_mb']:6.0f} MB", flush=True)
        same = (out / "run-clf" / "trajectory.tum").read_bytes() == (out / "run-mcap" / "trajectory.tum").read_bytes()
        print(f"trajectories byte-identical: {same}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
