"""The checks before a run (the robot itself in view, mcl.datasets.selfhits; the odometry and the mounting,
mcl.odomcheck) on each laser of a bag whose front and rear lasers are fused: each laser's findings, said and
written per laser; the laser whose mounting misfits left out (sensor.misfit_laser), and the advice that mends it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mcl.config import PROJECT_ROOT, load_config
from mcl.datasets.bagwrite import BagOut
from mcl.datasets.carmen import read_carmen
from mcl.datasets.rosbag import bag_info, format_info
from mcl.runner import run
from tests.bagmsgs import laser, odom

DEMO = PROJECT_ROOT / "data" / "demo"
TF = "tf2_msgs/msg/TFMessage"


@pytest.fixture(scope="module")
def agv(tmp_path_factory):
    """The demo as an AGV's bag: /front/scan, the demo's laser as logged, mounted at the robot's centre looking
    ahead; /rear/scan, the same readings with a cart's posts in view at beams 100-110 (0.3 m), its /tf_static saying
    it looks back (yaw pi) while its scans look ahead: its mounting is the fault. Both level at one height: fused."""
    rng = np.random.default_rng(11)
    scans = read_carmen(DEMO / "log.clf").scans
    bag = tmp_path_factory.mktemp("agv") / "agv.mcap"
    with BagOut(bag) as b:
        b.write("/tf_static", TF, scans[0].t, b.msg(TF, transforms=[
            b.transform(scans[0].t, "base_link", "front", (0.0, 0.0, 0.0)),
            b.transform(scans[0].t, "base_link", "rear", (0.0, 0.0, np.pi))]))
        for s in scans:
            odom(b, s)
            laser(b, "/front/scan", s, frame="front")
            r = np.array(s.ranges)
            r[100:111] = 0.3 + rng.normal(0.0, 0.01, 11)
            laser(b, "/rear/scan", dataclasses.replace(s, ranges=r), frame="rear")
    return bag


def test_bag_info_says_each_lasers_findings(agv):
    text = format_info(bag_info(agv))
    assert "\n  scans:        /front/scan, /rear/scan (" in text, text
    assert "\n  robot itself: /rear/scan: beams 100-110 of 181 (10.0..20.0 degrees) read 0.3" in text, text
    assert "robot itself: /front/scan" not in text
    assert "\n  odometry check: /front/scan: the scans fit the odometry as recorded (" in text, text
    rear = [ln for ln in text.splitlines() if ln.startswith("  odometry check: /rear/scan: ")]
    assert len(rear) == 1 and "with the laser turned half a turn from its mounting" in rear[0], text
    assert rear[0].endswith("fix its transform in the bag's /tf, or read it alone, mounted there: "
                            '--set topics.scan=/rear/scan --set "sensor.laser_pose=[0, 0, 0]"'), rear[0]


def test_a_run_leaves_the_laser_at_fault_out_says_so_and_its_advice_mends_it(agv, tmp_path):
    # The demo tracked from its start (kidnapped at 50 s), 2000 particles. The rear laser, weighed as its /tf mounts it,
    # keeps the filter from ever converging (sensor.misfit_laser: keep; within 0.3 m for good: never); left out,
    # the run is the front laser's (the demo's 52.8 s). The warning names /rear/scan alone; summary.json has each
    # laser's check, the laser left out and the rear's posts. The rear laser read alone where the advice mounts it:
    # no warning.
    sets = [f"bag={agv}", "log=null", f"map={DEMO / 'map.yaml'}", f"truth={DEMO / 'truth.tum'}", "rerun.mode=off",
            "filter.initial_pose=[2.062007,10.160616,-0.218311]", "filter.particles=2000", "filter.kld=false"]
    said = []
    s = run(load_config(PROJECT_ROOT / "configs" / "default.yaml", sets), tmp_path / "both", progress=False,
            echo=said.append)
    warn = [m for m in said if "the scans fit the odometry's motion best" in m]
    assert len(warn) == 1 and warn[0].startswith(f"mcl: warning: {agv}: /rear/scan: the scans fit the odometry's "
                                                 "motion best with the laser turned half a turn"), said
    assert ": left out of the run (sensor.misfit_laser: keep weighs it); the laser seems to look another way than " \
           "its transform in the bag's /tf says (-180 degrees); fix its transform" in warn[0], warn[0]
    assert s["left_out_lasers"] == ["/rear/scan"]
    assert s["eval"]["convergence_time"] is not None and s["eval"]["convergence_time"] <= 60.0, s["eval"]
    c = s["odometry_check"]
    assert c["laser"] == "/front/scan" and c["verdict"] is None and c["pairs"] == 60, c
    assert [(o["laser"], o["verdict"]) for o in c["other_lasers"]] == [("/rear/scan", "half")], c
    h = s["self_hits"]
    assert h["laser"] == "/rear/scan" and h["beams"] == list(range(100, 111)) and "other_lasers" not in h, h
    assert any(m.startswith(f"{agv}: /rear/scan: beams 100-110 of 181") for m in said), said
    said.clear()
    kept = run(load_config(PROJECT_ROOT / "configs" / "default.yaml", [*sets, "sensor.misfit_laser=keep"]),
               tmp_path / "kept", progress=False, echo=said.append)
    assert "left_out_lasers" not in kept and kept["eval"]["convergence_time"] is None, kept["eval"]
    assert [m for m in said if "and the filter will be lost as soon as the robot moves" in m], said
    said.clear()
    s = run(load_config(PROJECT_ROOT / "configs" / "default.yaml",
                        [*sets, "topics.scan=/rear/scan", "sensor.laser_pose=[0, 0, 0]"]), tmp_path / "rear",
            progress=False, echo=said.append)
    assert not [m for m in said if "odometry's motion" in m], said
    assert s["odometry_check"]["laser"] == "/rear/scan" and s["odometry_check"]["verdict"] is None
    assert "other_lasers" not in s["odometry_check"] and s["self_hits"]["laser"] == "/rear/scan"


def _fused_log(tmp_path, rear_yaw: float):
    """The demo's log with each FLASER line repeated as an RLASER line of the same readings, its laser pose the
    robot's turned by ``rear_yaw`` (pi: declared looking back while its scans look ahead, the mounting at fault)."""
    import math

    out = []
    for line in (DEMO / "log.clf").read_text().splitlines(keepends=True):
        out.append(line)
        if line.startswith("FLASER"):
            f = line.split()
            n = int(f[1])
            ox, oy, oth = (float(v) for v in f[n + 5:n + 8])
            th = math.atan2(math.sin(oth + rear_yaw), math.cos(oth + rear_yaw))
            out.append(" ".join(["RLASER", *f[1:n + 2], f"{ox:.6f}", f"{oy:.6f}", f"{th:.6f}", *f[n + 5:]]) + "\n")
    path = tmp_path / f"fused-{rear_yaw:g}.clf"
    path.write_text("".join(out))
    return path


def test_a_carmen_log_s_front_and_rear_lasers_are_fused_by_name(tmp_path):
    # laser: FLASER,RLASER reads both streams, each on its own mounting (a CARMEN log's RLASER line carries its
    # laser's pose): the rear laser declared looking back while its scans look ahead is found and left out (the
    # run then is the front laser's: the demo's 52.8 s); declared as it looks, both update (twice the updates),
    # and laser: auto fuses them too (laser: FLASER reads the front one alone)
    from mcl.errors import ConfigError

    sets = [f"map={DEMO / 'map.yaml'}", f"truth={DEMO / 'truth.tum'}", "rerun.mode=off", "filter.particles=2000",
            "filter.kld=false", "filter.initial_pose=[2.062007,10.160616,-0.218311]", "laser=FLASER,RLASER"]
    said = []
    s = run(load_config(PROJECT_ROOT / "configs" / "default.yaml", [*sets, f"log={_fused_log(tmp_path, np.pi)}"]),
            tmp_path / "wrong", progress=False, echo=said.append)
    warn = [m for m in said if "odometry's motion" in m]
    assert len(warn) == 1 and ": RLASER: the scans fit the odometry's motion best with the laser turned half a turn" \
        in warn[0] and "left out of the run" in warn[0], said
    assert s["left_out_lasers"] == ["RLASER"] and s["eval"]["convergence_time"] <= 60.0, s["eval"]
    front = run(load_config(PROJECT_ROOT / "configs" / "default.yaml", [*sets[:-1], f"log={DEMO / 'log.clf'}"]),
                tmp_path / "front", progress=False, echo=lambda *_: None)
    said.clear()
    s = run(load_config(PROJECT_ROOT / "configs" / "default.yaml", [*sets[:-1], f"log={_fused_log(tmp_path, 0.0)}"]),
            tmp_path / "both", progress=False, echo=said.append)  # laser: auto fuses a log's FLASER and RLASER
    assert any(m.endswith(": FLASER and RLASER (a front and a rear laser): fused, each on the mounting its lines give "
                          "(laser: FLASER reads the front one alone)") for m in said), said
    assert "left_out_lasers" not in s and s["odometry_check"]["other_lasers"][0]["laser"] == "RLASER"
    assert s["updates"] == 2 * front["updates"] and s["scans"] == 2 * front["scans"], (s["updates"], front["updates"])
    alone = run(load_config(PROJECT_ROOT / "configs" / "default.yaml",
                            [*sets[:-1], f"log={_fused_log(tmp_path, 0.0)}", "laser=FLASER"]),
                tmp_path / "alone", progress=False, echo=lambda *_: None)
    assert alone["updates"] == front["updates"] and "other_lasers" not in alone["odometry_check"]
    for bad in ("FLASER,FLASER", "FLASER,RLASER2", "auto,RLASER"):
        with pytest.raises(ConfigError, match="laser: expected one of auto, FLASER"):
            load_config(None, [f"laser={bad}"])
    with pytest.raises(ConfigError, match="has no RLASER messages"):
        run(load_config(PROJECT_ROOT / "configs" / "default.yaml", [*sets, f"log={DEMO / 'log.clf'}"]),
            tmp_path / "none", progress=False, echo=lambda *_: None)
