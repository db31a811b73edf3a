"""``mcl log info``: a CARMEN log's messages, lasers and what a run would take from it, with the run's checks
(mcl.datasets.loginfo); and the line that sends a log to it from ``mcl bag info`` (and a bag back)."""

from __future__ import annotations

import json

import numpy as np

from mcl.cli import main
from mcl.datasets.loginfo import format_log_info, log_info
from tests.bagmsgs import DEMO, fused_log


def test_the_demo_log_s_messages_laser_and_checks(capsys):
    # every count as the file has it (the comment line not a message), the laser's geometry and PARAM maximum range,
    # and the run's checks: no body in view, the odometry as recorded, no time offset to act on
    lines = (DEMO / "log.clf").read_text().splitlines()
    assert main(["log", "info", str(DEMO / "log.clf")]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"{DEMO / 'log.clf'}: CARMEN log, {len(lines) - 1} messages, 70.0 s\nmessages:\n"), text
    for kind in ("FLASER", "ODOM", "PARAM"):
        n = sum(ln.startswith(kind + " ") for ln in lines)
        assert f"\n  {kind:<6}  {n:>8}\n" in text, (kind, n, text)
    assert "\nlaser FLASER: 351 scans, 181 beams over 180 degrees from -90, no return at 5 m and beyond, laser pose " \
           "[0.0, 0.0, 0.0]\n" in text, text
    # the ODOM lines' span beside the scans', as bag info gives them (the README said so; it was not printed)
    assert "\n  scans:        FLASER (351 scans)\n  odometry:     ODOM lines (701)\n  stamps:       scans " \
           "0.000..70.000 s, odometry 0.000..70.000 s\n  robot itself: no beam reads it (sensor.self_hit_skip)\n  sideways:     0.1% of the " \
           "odometry's 30.6 m goes across the robot's heading: a differential drive's (motion.model odometry)\n" \
           "  odometry check: the scans " \
           "fit the odometry as recorded (52 of 60 pairs of scans); the laser's yaw +0.4 +- 0.3 degrees from its " \
           "mounting (sensor.mount_yaw fits 2 or more)\n  scan timing:  " in text, text
    assert "warning" not in text
    assert main(["log", "info", str(DEMO / "log.clf"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["mcl_uses"]["odometry_check"]["verdict"] is None and info["mcl_uses"]["self_hits"] is None
    assert info["mcl_uses"]["odometry_sideways"] == {"share": 0.0013, "travel_m": 30.6, "omni": False}
    assert info["lasers"]["FLASER"]["max_range"] == 5.0 and info["duration_s"] == 70.0


def test_a_fused_log_s_rear_laser_at_fault_is_named_with_the_advice_for_a_log(tmp_path):
    # the demo with a rear laser (RLASER) whose lines say it looks back while its scans look ahead: both lasers
    # listed, read fused (the note), the rear one's mounting found at fault and said as a run says it, with a log's
    # remedy (its lines, `laser`), not a bag's (its /tf, topics.scan)
    log = fused_log(tmp_path, np.pi)
    info = log_info(log)
    assert list(info["lasers"]) == ["FLASER", "RLASER"] and info["messages"]["RLASER"] == 351
    assert info["lasers"]["RLASER"]["laser_pose"] == [0.0, 0.0, -3.141592]  # pi, its lines to 6 decimals
    u = info["mcl_uses"]
    assert u["lasers"] == ["FLASER", "RLASER"] and u["scans"] == 702
    assert any("FLASER and RLASER (a front and a rear laser): fused" in n for n in u["notes"]), u["notes"]
    c = u["odometry_check"]
    assert c["laser"] == "FLASER" and c["verdict"] is None
    (rear,) = c["other_lasers"]
    assert rear["laser"] == "RLASER" and rear["verdict"] == "half", rear
    assert "left out of the run (sensor.misfit_laser: keep weighs it)" in rear["text"]
    assert rear["text"].endswith("fix its lines' laser pose, or read it alone, mounted there: --set laser=RLASER "
                                 '--set "sensor.laser_pose=[0, 0, 0]"'), rear["text"]
    assert "time_offset_check" in u  # the first laser fits: its stamps are checked
    text = format_log_info(info)
    assert "\n  odometry check: FLASER: the scans fit the odometry as recorded (" in text
    assert "\n  odometry check: RLASER: the scans fit the odometry's motion best with the laser turned half a turn" \
        in text, text
    # laser: FLASER reads the front one alone: no note, one check
    alone = log_info(log, "FLASER")["mcl_uses"]
    assert alone["lasers"] == ["FLASER"] and "other_lasers" not in alone["odometry_check"]
    assert not any("a front and a rear laser" in n for n in alone["notes"])


def test_a_log_without_odom_lines_is_checked_on_its_lines_own_poses(tmp_path, capsys):
    # mit_csail's kind of log: FLASER lines alone; their robot poses are the odometry the checks use
    log = tmp_path / "flaser.clf"
    log.write_text("".join(ln for ln in (DEMO / "log.clf").read_text().splitlines(True) if ln.startswith("FLASER")))
    info = log_info(log)
    u = info["mcl_uses"]
    assert u["odometry"] == "the laser lines' own poses (no ODOM lines)" and "ODOM" not in info["messages"]
    assert u["odometry_check"]["verdict"] is None and u["odometry_check"]["pairs"] == 60, u["odometry_check"]


def test_what_mcl_log_info_refuses_or_cannot_use(tmp_path, capsys):
    # a stream the log lacks: listed as what mcl cannot use (as mcl bag info does), the log still described;
    # a bag: sent to mcl bag info; a log given to mcl bag info: sent here; a malformed line: file:line
    assert main(["log", "info", str(DEMO / "log.clf"), "--laser", "RLASER"]) == 0
    text = capsys.readouterr().out
    assert text.endswith(f"mcl would use:\n  nothing: {DEMO / 'log.clf'}: no RLASER messages (found: FLASER)\n"), text
    assert "\nlaser FLASER: 351 scans" in text
    assert main(["bag", "info", str(DEMO / "log.clf")]) == 2
    assert capsys.readouterr().err.strip() == (f"mcl: error: {DEMO / 'log.clf'}: not a ROS bag (.bag, .db3, .mcap "
                                               f"or a rosbag2 folder); a CARMEN log? mcl log info {DEMO / 'log.clf'}")
    bag = tmp_path / "x.mcap"
    bag.write_bytes(b"")
    assert main(["log", "info", str(bag)]) == 2
    assert capsys.readouterr().err.strip() == f"mcl: error: {bag}: a ROS bag, not a CARMEN log: mcl bag info {bag}"
    odo = tmp_path / "odo.clf"  # ODOM lines alone (a log for mcl calibrate motion): described, nothing to run
    odo.write_text("ODOM 0 0 0 0 0 0 1.0 host 1.0\nODOM 1 0 0 0 0 0 2.0 host 2.0\n")
    assert main(["log", "info", str(odo)]) == 0
    text = capsys.readouterr().out
    assert "\n  ODOM         2\n" in text and text.endswith(f"  nothing: {odo}: no laser messages\n"), text
    bad = tmp_path / "bad.clf"
    bad.write_text("ODOM 0 0 0 0 0 0 1.0 host 1.0\nFLASER 3 1 2\n")
    assert main(["log", "info", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"mcl: error: {bad}:2: FLASER: ") and err.count("\n") == 1, err


def test_a_reader_that_leaves_early_ends_the_command_quietly():
    # `mcl log info L | head -1` printed "mcl: error: Broken pipe" and exited 2 (when head left before the output
    # was written). Now quiet, with cat's and grep's 141. The read end is closed before the command prints.
    import subprocess
    import sys
    from pathlib import Path

    import os

    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # stdout buffered, as a user's is
    p = subprocess.Popen([sys.executable, "-m", "mcl", "log", "info", str(DEMO / "log.clf")], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, cwd=Path(__file__).resolve().parents[1], env=env)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141, err
    assert err == ""
