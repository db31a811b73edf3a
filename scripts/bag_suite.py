"""Write a suite's datasets as ROS bags and a suite of those bags, to run a config on the bag path (laser
odometry: ``--set topics.odom=laser`` against the bags' own /odom).

    python scripts/bag_suite.py suites/real.yaml /tmp/bags --cache /tmp/WORLDS [--only fr079 mit_csail]
    mcl eval --suite /tmp/bags/suite.yaml --modes tracking --seeds 3 --jobs 2 --set topics.odom=laser

Each dataset's CARMEN log (a synthetic one generated into ``--cache`` first, as ``mcl eval`` does) becomes
``<out>/<name>.mcap`` through ``mcl convert`` (/scan, /odom, /tf and /tf_static), and ``<out>/suite.yaml`` lists
them with the same map, truth, start pose, lost bound and ``set`` keys, for tracking (a dataset's laser, from its
dataset config or its ``set``, is the one laser of the log written to the bag). The bags are written once (an
existing one is kept).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import yaml

from mcl.datasets.bagwrite import convert
from mcl.suite import _sim_kwargs, _truth_start, _world_dir, load_suite, make_world


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("suite", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/WORLDS"), help="folder of generated worlds")
    ap.add_argument("--only", nargs="*", default=None, help="dataset names")
    a = ap.parse_args(argv)
    suite = load_suite(a.suite)
    a.out.mkdir(parents=True, exist_ok=True)
    entries = []
    for d in suite.datasets:
        if a.only and d.name not in a.only:
            continue
        if d.simulate is not None:  # the tracking world, generated as mcl eval does
            w = Path(make_world(str(_world_dir(a.cache, d, False)), _sim_kwargs(d, False)))
            files = {"map": w / "map.yaml", "log": w / "log.clf", "truth": w / "truth.tum"}
        else:
            files = {k: (Path(v) if v else None) for k, v in (("map", d.map), ("log", d.log), ("truth", d.truth))}
        if d.bag is not None or files["log"] is None:
            continue
        bag = a.out / f"{d.name}.mcap"
        if not bag.exists():
            # the dataset's own laser (a dataset config's, or a hunt's set), alone in the bag
            convert(files["log"], bag, laser=d.laser or d.set.get("laser") or "auto")
            print(f"{bag}", file=sys.stderr)
        pose = d.initial_pose or _truth_start(str(files["truth"]))
        # absolute paths: the suite is read from its own folder (a relative --cache gave map and truth paths that
        # did not resolve from there)
        entries.append({"name": d.name, "map": str(Path(files["map"]).resolve()), "bag": str(bag.resolve()),
                        "truth": str(Path(files["truth"]).resolve()), "initial_pose": [float(v) for v in pose],
                        "lost_m": float(d.lost_m), "modes": ["tracking"]})
        own = {k: v for k, v in d.set.items() if k != "laser"}  # a hunt's range cut, say; the laser is the bag's
        if own:
            entries[-1]["set"] = own
    doc = {"name": f"{suite.name}-bags", "modes": ["tracking"], "datasets": entries}
    (a.out / "suite.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    print(f"{a.out / 'suite.yaml'}: {len(entries)} datasets")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
