"""scripts/bag_suite.py: a suite's logs written as bags, each with its dataset's own laser and keys."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import yaml
from rosbags.highlevel import AnyReader

from mcl.config import PROJECT_ROOT
from mcl.suite import load_suite

from bagmsgs import DEMO, fused_log

sys.path.insert(0, str(PROJECT_ROOT / "scripts"))
from bag_suite import main  # noqa: E402


def _scan_topics(bag):
    with AnyReader([Path(bag)]) as reader:
        return sorted(c.topic for c in reader.connections if c.msgtype == "sensor_msgs/msg/LaserScan")


def test_a_bag_keeps_its_datasets_laser_and_set_keys(tmp_path):
    # a log with a front and a rear laser: "auto" fuses both into the bag; the dataset names the front one alone, and
    # its range cut (a real hunt's rng8) must reach the bag's suite entry, or the bag runs another experiment
    log = fused_log(tmp_path, math.pi)
    cfg = tmp_path / "front.yaml"
    cfg.write_text(yaml.safe_dump({"map": str(DEMO / "map.yaml"), "log": str(log), "truth": str(DEMO / "truth.tum"),
                                   "laser": "FLASER"}))
    entry = {"map": str(DEMO / "map.yaml"), "log": str(log), "truth": str(DEMO / "truth.tum"),
             "initial_pose": [0.0, 0.0, 0.0]}
    src = tmp_path / "src.yaml"
    src.write_text(yaml.safe_dump({"name": "fused", "datasets": [
        {"name": "front", "config": str(cfg), "initial_pose": [0.0, 0.0, 0.0], "set": {"sensor.range_max": 8.0}},
        {"name": "hunted", **entry, "set": {"laser": "FLASER"}},  # a hunt suite's form of the same
        {"name": "both", **entry}]}))
    out = tmp_path / "bags"
    assert main([str(src), str(out)]) == 0
    front, hunted, both = load_suite(out / "suite.yaml").datasets
    assert front.set == {"sensor.range_max": 8.0} and hunted.set == {} and both.set == {}
    assert [len(_scan_topics(d.bag)) for d in (front, hunted, both)] == [1, 1, 2]


def test_a_relative_cache_gives_a_suite_that_reads_from_its_own_folder(tmp_path, monkeypatch):
    # `bag_suite.py S bags --cache ev/worlds`: the bag's path was made absolute, the map's and truth's not, and the
    # suite (read from bags/) named files that are not there
    src = tmp_path / "sim.yaml"
    src.write_text(yaml.safe_dump({"name": "sim", "datasets": [{"name": "w", "simulate": {"seed": 7, "duration": 5}}]}))
    monkeypatch.chdir(tmp_path)
    assert main([str(src), "bags", "--cache", "ev/worlds"]) == 0
    (d,) = load_suite(tmp_path / "bags" / "suite.yaml").datasets
    assert Path(d.map).is_absolute() and Path(d.map).is_file() and Path(d.truth).is_file() and Path(d.bag).is_file()
