"""scripts/hunt.py: random hunts, made again from their seeds, as suites mcl eval reads."""

from __future__ import annotations

import sys

import pytest
import yaml

from mcl.config import PROJECT_ROOT
from mcl.datasets.carmen import read_carmen
from mcl.suite import load_suite

sys.path.insert(0, str(PROJECT_ROOT / "scripts"))
from hunt import main, real_draw, synthetic_world  # noqa: E402


def test_a_hunt_world_is_made_again_from_its_seed(tmp_path):
    # docs/measurements.md names hunt worlds by their seed (hunt 17 on: the pool of conditions as it is now):
    # corridor-doubled-2hz-mscale-w3726 (the corridor drift the baseline alone kept in hunt 18) and
    # hall-p24-res2-slips-w3690 (hunt 17's hall whose laser sees mostly people)
    w = synthetic_world(3726)
    assert w["name"] == "corridor-doubled-2hz-mscale-w3726"
    assert w["simulate"]["kind"] == "corridor" and w["simulate"]["scan_rate"] == 2.0
    assert w["simulate"]["doubled_walls"] == 6 and w["simulate"]["map_scale"] in (0.98, 0.99, 1.01, 1.02)
    assert synthetic_world(3690) == {"name": "hall-p24-res2-slips-w3690", "simulate": {
        "kind": "hall", "seed": 3690, "duration": 90, "dynamic_obstacles": 24, "map_resolution": 0.025,
        "odom_slips": 3, "odom_slip_s": 2.0}}
    fast = synthetic_world(3800, fast=True)
    assert fast["simulate"]["scan_rate"] in (15.0, 20.0, 30.0) and fast["name"].endswith(
        f"-{int(fast['simulate']['scan_rate'])}hz-w3800")
    out = tmp_path / "hunt.yaml"
    assert main(["synthetic", "3705", "3", str(out)]) == 0
    suite = load_suite(out)
    assert [d.name for d in suite.datasets] == [synthetic_world(k)["name"] for k in (3705, 3706, 3707)]
    assert all(d.modes == ("tracking", "kidnapped") and d.lost_m == 0.5 for d in suite.datasets)


def test_a_real_hunt_log_is_drawn_again_and_degraded(tmp_path):
    # the real hunts' draws, as docs/measurements.md names them: r709 (the run the baseline alone kept, with the
    # range cut in the pool) and r402 (without it)
    real = yaml.safe_load((PROJECT_ROOT / "suites" / "real.yaml").read_text())["datasets"]
    d, conds = real_draw(709, real)
    assert d["name"] == "acapulco" and conds == ["rb+5", "gaps3", "stalls3"]
    d, conds = real_draw(402, real, range_cut=False)
    assert d["name"] == "infinite_corridor" and conds == ["rot30", "gaps3", "stalls3"]
    # degraded for real, on a suite of the bundled demo: 3 stalls and the laser to 8 m (r1001's draw is found below)
    base = tmp_path / "demo.yaml"
    base.write_text(yaml.safe_dump({"name": "demo", "root": str(PROJECT_ROOT / "data" / "demo"), "datasets": [
        {"name": "demo", "map": "map.yaml", "log": "log.clf", "truth": "truth.tum",
         "initial_pose": [0.0, 0.0, 0.0], "set": {"filter.particles": 3000}}]}))
    k = next(k for k in range(1000, 2000) if set(real_draw(k, [{"name": "demo"}])[1]) >= {"stalls3", "rng8"})
    conds = real_draw(k, [{"name": "demo"}])[1]
    out = tmp_path / "hunt"
    assert main(["real", str(k), "1", str(out), "--suite", str(base)]) == 0
    suite = load_suite(out / "suite.yaml")
    (d,) = suite.datasets
    assert d.name == f"demo-{'-'.join(conds)}-r{k}" and d.set == {"filter.particles": 3000, "sensor.range_max": 8.0}
    made = list(read_carmen(d.log).scans)
    held = sum(1 for a, b in zip(made, made[1:]) if (a.odom == b.odom).all())
    original = list(read_carmen(PROJECT_ROOT / "data" / "demo" / "log.clf").scans)
    assert len(made) == len(original) and held >= 3 * 10  # three 3 s stalls at 5 Hz, each 15 scans held


def test_a_real_hunt_keeps_a_dataset_configs_laser_as_a_config_key(tmp_path):
    # a suite entry made from a dataset config gets the config's laser; a suite entry has no laser key, so the hunt's
    # suite carries it in set (as a laser key, mcl eval refused the whole hunt suite)
    demo = PROJECT_ROOT / "data" / "demo"
    cfg = tmp_path / "demo-front.yaml"
    cfg.write_text(yaml.safe_dump({"map": str(demo / "map.yaml"), "log": str(demo / "log.clf"),
                                   "truth": str(demo / "truth.tum"), "laser": "FLASER"}))
    base = tmp_path / "demo.yaml"
    base.write_text(yaml.safe_dump({"name": "demo", "datasets": [
        {"name": "demo", "config": str(cfg), "initial_pose": [0.0, 0.0, 0.0]}]}))
    assert load_suite(base).datasets[0].laser == "FLASER"
    out = tmp_path / "hunt"
    assert main(["real", "1000", "1", str(out), "--suite", str(base), "--no-range-cut"]) == 0
    (d,) = load_suite(out / "suite.yaml").datasets
    assert d.set == {"laser": "FLASER"}


def test_a_hunt_names_the_modes_asked_for_and_refuses_an_unknown_one(tmp_path, capsys):
    out = tmp_path / "hunt.yaml"
    assert main(["synthetic", "3705", "2", str(out), "--modes", "tracking,global,kidnapped"]) == 0
    assert all(d.modes == ("tracking", "global", "kidnapped") for d in load_suite(out).datasets)
    with pytest.raises(SystemExit) as e:
        main(["synthetic", "3705", "2", str(tmp_path / "other.yaml"), "--modes", "tracking,globl"])
    assert e.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].endswith(
        "error: --modes: unknown mode 'globl' (did you mean global?)")
    assert not (tmp_path / "other.yaml").exists()


def test_a_real_hunt_keeps_a_dataset_to_the_modes_its_suite_runs_it_in(tmp_path, capsys):
    # suites/real.yaml runs infinite_corridor in tracking and kidnapped only (global over 250 m is a benchmark of its
    # own): a hunt asked for global as well keeps it to those two, and leaves it out of a global-only hunt
    demo = PROJECT_ROOT / "data" / "demo"
    base = tmp_path / "demo.yaml"
    base.write_text(yaml.safe_dump({"name": "demo", "modes": ["tracking", "global", "kidnapped"], "datasets": [
        {"name": "demo", "map": str(demo / "map.yaml"), "log": str(demo / "log.clf"), "truth": str(demo / "truth.tum"),
         "modes": ["tracking", "kidnapped"]}]}))
    out = tmp_path / "hunt"
    assert main(["real", "1000", "1", str(out), "--suite", str(base), "--modes", "tracking,global,kidnapped"]) == 0
    assert yaml.safe_load((out / "suite.yaml").read_text())["modes"] == ["tracking", "global", "kidnapped"]
    assert load_suite(out / "suite.yaml").datasets[0].modes == ("tracking", "kidnapped")
    with pytest.raises(SystemExit) as e:
        main(["real", "1000", "1", str(tmp_path / "g"), "--suite", str(base), "--modes", "global"])
    assert "no dataset of draws 1000..1000 runs in global" in str(e.value)
    assert "r1000: demo left out: its suite runs it in tracking, kidnapped only" in capsys.readouterr().err


def test_a_hunt_of_chosen_kinds(tmp_path, capsys):
    # --kinds draws from those kinds only (warehouse is not in the default draw, which stays as it was)
    out = tmp_path / "wh.yaml"
    assert main(["synthetic", "4529", "3", str(out), "--kinds", "warehouse"]) == 0
    assert [d.name.split("-")[0] for d in load_suite(out).datasets] == ["warehouse"] * 3
    assert synthetic_world(3690)["name"] == "hall-p24-res2-slips-w3690"
    with pytest.raises(SystemExit) as e:
        main(["synthetic", "4529", "3", str(tmp_path / "x.yaml"), "--kinds", "warehouse,barn"])
    assert e.value.code == 2 and "--kinds: expected some of" in capsys.readouterr().err
