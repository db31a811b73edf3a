"""``mcl calibrate mount``: the laser's pose on the robot from the odometry and the scans alone (planar hand-eye,
mcl.calibrate_mount)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import yaml

from mcl.calibrate_mount import calibrate, hand_eye
from mcl.cli import main
from mcl.datasets.carmen import read_carmen
from mcl.errors import DataError
from mcl.estimate import compose, inverse
from tests.bagmsgs import DEMO

# Tolerances: 0.03 m and 1 degree, three times the fit's standard errors on the demo (0.010 m, 0.45 degrees)


def _moved(scans, mount):
    """The demo as a robot whose laser sits at ``mount`` on its base: the same laser poses, the odometry the base's
    (laser pose ∘ mount⁻¹), each scan's own mounting ``mount``."""
    m = np.asarray(mount, dtype=np.float64)
    return [dataclasses.replace(s, odom=compose(np.asarray(s.odom), inverse(m)), laser_offset=m) for s in scans]


def test_the_demo_s_laser_is_found_at_the_centre_whatever_the_mounting_given():
    scans = read_carmen(DEMO / "log.clf").scans
    for given in (None, (0.2, 0.1, 0.1)):
        (check, fit), = calibrate(scans, given).values()
        x, y, th = fit["laser_pose"]
        assert abs(x) < 0.03 and abs(y) < 0.03 and abs(math.degrees(th)) < 1.0, (given, fit)
        assert fit["pairs"] >= 40 and abs(fit["scale"] - 1.0) < 0.02 and max(fit["se"][:2]) < 0.02, fit


def test_a_laser_off_the_centre_and_turned_is_found_where_it_is():
    # the laser 0.2 m ahead, 0.1 m to the right, turned 0.15 rad; the run told it sits at the centre
    mount = (0.2, -0.1, 0.15)
    (check, fit), = calibrate(_moved(read_carmen(DEMO / "log.clf").scans, mount), (0.0, 0.0, 0.0)).values()
    assert check.mount == (0.0, 0.0, 0.0)
    got = fit["laser_pose"]
    assert abs(got[0] - 0.2) < 0.03 and abs(got[1] + 0.1) < 0.03 and abs(math.degrees(got[2] - 0.15)) < 1.0, fit


def test_the_command_prints_a_config_block_and_json(tmp_path, capsys):
    moved = _moved(read_carmen(DEMO / "log.clf").scans, (0.15, 0.0, -0.1))
    from mcl.datasets.bagwrite import write_scans

    bag = tmp_path / "moved.mcap"
    write_scans(bag, moved)  # /tf_static says base_link -> laser (0.15, 0, -0.1): the run's guess is right
    assert main(["calibrate", "mount", "--bag", str(bag), "--set", "sensor.laser_pose=[0, 0, 0]"]) == 0
    text = capsys.readouterr().out
    pose = yaml.safe_load(text)["sensor"]["laser_pose"]
    assert abs(pose[0] - 0.15) < 0.03 and abs(pose[1]) < 0.03 and abs(math.degrees(pose[2] + 0.1)) < 1.0, text
    assert text.startswith(f"# mcl calibrate mount: {bag}; the laser's pose on the robot") and \
        "\n# /scan: given [0.0, 0.0, 0.0]; fitted x 0.1" in text, text
    assert main(["calibrate", "mount", "--log", str(DEMO / "log.clf"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert list(out) == ["FLASER"] and out["FLASER"]["given"] == [0.0, 0.0, 0.0] and out["FLASER"]["pairs"] >= 40


def test_a_robot_that_never_moves_gives_no_fit(tmp_path, capsys):
    still = tmp_path / "still.clf"
    lines = [ln for ln in (DEMO / "log.clf").read_text().splitlines(True) if not ln.startswith("ODOM")]
    out = []
    for ln in lines:  # every laser line's two poses at the origin
        f = ln.split()
        if f and f[0] == "FLASER":
            n = int(f[1])
            f[n + 2:n + 8] = ["0"] * 6
        out.append(" ".join(f) + "\n")
    still.write_text("".join(out))
    assert main(["calibrate", "mount", "--log", str(still)]) == 1
    cap = capsys.readouterr()
    assert "# FLASER: no fit: 0 pairs of scans matched, 20 needed: the robot must drive and turn" in cap.out, cap.out
    assert cap.err.strip() == f"mcl: error: {still}: no laser's mounting could be fitted"
    with pytest.raises(DataError, match="5 pairs of scans matched, 20 needed"):  # the fit itself refuses
        hand_eye([(np.zeros(3), np.zeros(3))] * 5)


def test_the_hand_eye_fit_is_exact_on_exact_motions_and_says_when_pairs_disagree():
    # 60 robot motions d and the laser's L = M^-1 d M for M = (0.3, -0.2, 0.4): the mounting comes back to 1e-9.
    # With 15 of them wild (failed matches), the 45 that agree still give it; a fit where only 30 of 60 agreed is
    # said in the config block
    from mcl.calibrate_mount import format_yaml
    from mcl.odomcheck import OdometryCheck

    rng = np.random.default_rng(5)
    m = np.array([0.3, -0.2, 0.4])
    d = np.column_stack((rng.uniform(-0.5, 1.0, 60), rng.uniform(-0.2, 0.2, 60), rng.uniform(-1.0, 1.0, 60)))
    motions = [(di, compose(compose(inverse(m), di), m)) for di in d]
    fit = hand_eye(motions)
    np.testing.assert_allclose(fit["laser_pose"], m, atol=1e-9)
    assert fit["pairs"] == fit["matched"] == 60 and abs(fit["scale"] - 1.0) < 1e-9
    wild = [(di, laser + rng.normal(0.0, 0.5, 3)) if k % 4 == 1 else (di, laser)
            for k, (di, laser) in enumerate(motions)]
    fit = hand_eye(wild)
    np.testing.assert_allclose(fit["laser_pose"], m, atol=1e-6)
    assert fit["pairs"] == 45 and "only" not in format_yaml({"FLASER": (OdometryCheck(60), fit)}, "x.clf"), fit
    text = format_yaml({"FLASER": (OdometryCheck(60), {**fit, "pairs": 30})}, "x.clf")
    assert "\n# FLASER: only 30 of 60 pairs agree: the matches are unsure (an open hall, a corridor); distrust x and " \
           "y\n" in text, text


def test_the_standard_errors_hold_where_the_matches_err_more_on_far_turns():
    # 200 drives of 60 pairs, the laser's matched motion off by a noise of 3 mm plus 3 cm per radian the pair turns
    # (a far turn's match is worse): the fit's errors over its standard errors are z-scores whose mean square is 1
    # when the SEs are right. The residuals' robust sigma, the SE before, read 3.3 / 2.9 here (the small-turn pairs
    # set it); the sandwich over the pairs 1.13 / 0.97 (x / y). Tolerance: 200 draws give the mean square a spread
    # of about 0.1, so 0.7-1.5 is 3-4 spreads either side. No pair is dropped (rounds=0): dropping by residual
    # picks the pairs that agree with the fit, which no formula of the kept residuals sees.
    m = np.array([0.2, -0.1, 0.3])
    zs = []
    for k in range(200):
        rng = np.random.default_rng(k)
        d = np.column_stack((rng.uniform(-0.5, 1.0, 60), rng.uniform(-0.2, 0.2, 60), rng.uniform(-1.0, 1.0, 60)))
        motions = []
        for di in d:
            s = 0.003 + 0.03 * abs(di[2])
            motions.append((di, compose(compose(inverse(m), di), m) + np.r_[s * rng.standard_normal(2),
                                                                              0.002 * rng.standard_normal()]))
        fit = hand_eye(motions, rounds=0)
        zs.append((np.array(fit["laser_pose"][:2]) - m[:2]) / np.array(fit["se"][:2]))
    msq = np.mean(np.square(zs), axis=0)
    assert np.all((msq > 0.7) & (msq < 1.5)), msq


@pytest.mark.parametrize("mount", [(-0.2, 0.0, math.pi), (0.1, 0.05, math.pi / 2)])
def test_a_laser_mounted_backwards_or_sideways_is_found_where_it_is(mount):
    # The odometry check says the laser is turned half (a quarter) turn from its mounting: the command refused
    # ("mend that first"), though finding that mounting is what it is for. Now it matches the pairs again with the
    # laser turned so, and fits; tolerances as above.
    (check, fit), = calibrate(_moved(read_carmen(DEMO / "log.clf").scans, mount), (0.0, 0.0, 0.0)).values()
    assert check.verdict == ("half" if mount[2] == math.pi else "left")
    assert isinstance(fit, dict), fit
    got = fit["laser_pose"]
    assert abs(got[0] - mount[0]) < 0.03 and abs(got[1] - mount[1]) < 0.03, fit
    assert abs(math.degrees(math.remainder(got[2] - mount[2], math.tau))) < 1.0, fit


def test_a_bag_given_as_the_log_is_named(tmp_path, capsys):
    # `calibrate mount --log run.bag` said "run.bag:2: not UTF-8 text", as if a CARMEN log were damaged
    from mcl.datasets.bagwrite import convert

    bag = tmp_path / "run.mcap"
    convert(DEMO / "log.clf", bag, echo=lambda *_: None)
    assert main(["calibrate", "mount", "--log", str(bag)]) == 2
    assert capsys.readouterr().err.strip() == f"mcl: error: {bag}: a ROS bag: give it with --bag"
