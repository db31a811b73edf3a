"""One error line, nothing written, for bad input to mcl convert, mcl explore and mcl eval (exit status 2)."""

from __future__ import annotations

import numpy as np
import pytest

from mcl.cli import main
from mcl.simulate import simulate
from mcl.trajectory import write_tum


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    d = tmp_path_factory.mktemp("world")
    simulate(d, seed=3, duration=8.0)
    return d


def _one_error(capsys) -> str:
    err = capsys.readouterr().err.splitlines()
    lines = [ln for ln in err if ln.startswith("mcl: error:")]
    assert len(lines) == 1 and not any("Traceback" in ln for ln in err), err
    return lines[0]


@pytest.mark.parametrize("extra,out,msg", [
    ([], "missing/x.mcap", "the folder {tmp}/missing does not exist"),  # a mistyped folder is not made
    (["--map", "{world}/map.yaml"], "x.clf", "--map: written into a bag only; a CARMEN log (x.clf) holds no map"),
    (["--initial-pose", "nan", "0", "0"], "x.mcap", "--initial-pose: expected finite X Y THETA, got nan 0.0 0.0"),
    # a NaN mounting wrote a bag mcl itself then refused; --mount and --odom into a CARMEN log were ignored
    (["--mount", "nan", "0", "0"], "x.mcap", "--mount: expected finite X Y THETA, got nan 0.0 0.0"),
    (["--mount", "0.1", "0", "0", "--odom", "tf"], "x.clf", "--mount, --odom: written into a bag only"),
    # a reference on another clock was written without a word (the run then said "not scored")
    (["--truth", "{world}/late.tum"], "x.mcap", "{world}/late.tum: no pose lies within the scans' time span"),
    (["--map", "{world}/map.yaml", "--initial-pose", "1000", "1000", "0"], "x.mcap",
     "--initial-pose: (1000, 1000) lies outside the map"),
])
def test_convert_checks_its_output_and_its_extra_inputs_first(world, tmp_path, capsys, extra, out, msg):
    from mcl.trajectory import read_tum

    t, p = read_tum(world / "truth.tum")
    write_tum(world / "late.tum", t + 1.7e9, p)
    extra = [e.format(world=world) for e in extra]
    assert main(["convert", str(world / "log.clf"), str(tmp_path / out), *extra]) == 2
    assert msg.format(tmp=tmp_path, world=world) in _one_error(capsys)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("dt", ["0", "-1", "nan"])
def test_explore_velocity_needs_a_positive_dt(tmp_path, capsys, dt):
    assert main(["explore", "motion", "--velocity", "1", "0.5", dt, "--out", str(tmp_path / "m.png")]) == 2
    assert "--velocity: expected finite V W and DT > 0 (s)" in _one_error(capsys)
    assert not (tmp_path / "m.png").exists()


@pytest.mark.parametrize("args,msg", [
    (["--pose", "0", "0", "inf"], "--pose: expected finite numbers, got 0 0 inf"),  # was a traceback (math.cos)
    (["--pose", "nan", "0", "0"], "--pose: expected finite numbers, got nan 0 0"),  # was an empty panel
    (["--odom", "0", "0", "0", "nan", "0", "0"], "--odom: expected finite numbers, got 0 0 0 nan 0 0"),
])
def test_explore_motion_needs_a_finite_pose_and_odometry(tmp_path, capsys, args, msg):
    assert main(["explore", "motion", *args, "--out", str(tmp_path / "m.png")]) == 2
    assert msg in _one_error(capsys)
    assert not (tmp_path / "m.png").exists()


def test_explore_omni_takes_an_odometry_pair_and_refuses_a_velocity(tmp_path, capsys):
    assert main(["explore", "motion", "--model", "omni", "--velocity", "1", "0.5", "1", "--out",
                 str(tmp_path / "m.png")]) == 2
    assert "--velocity needs --model velocity" in _one_error(capsys) and not (tmp_path / "m.png").exists()
    assert main(["explore", "motion", "--model", "velocity", "--odom", "0", "0", "0", "0", "0.5", "0", "--out",
                 str(tmp_path / "m.png")]) == 2
    assert "--odom needs --model odometry or omni" in _one_error(capsys)
    # a step of 0.5 m sideways (default alphas): the omni cloud's std is 0.11 m across it and 0.11 rad in heading,
    # Table 5.6's 0.25 m and 0.52 rad (rot1 = pi/2 and its noise); 2,000 samples: 3 % sampling error
    from mcl.explore import sample_clouds

    spans = {}
    for model in ("omni", "odometry"):
        ((_, (cloud,)),) = sample_clouds((0.0, 0.0, 0.0), model=model, odom=(0, 0, 0, 0, 0.5, 0), samples=2000)
        spans[model] = (float(np.std(cloud[0])), float(np.std(cloud[2])))
    (ox, oh), (dx, dh) = spans["omni"], spans["odometry"]
    assert ox < 0.13 and oh < 0.13 and dx > 0.22 and dh > 0.45, spans
    assert main(["explore", "motion", "--model", "omni", "--odom", "0", "0", "0", "0", "0.5", "0", "--samples", "200",
                 "--out", str(tmp_path / "m.png")]) == 0 and (tmp_path / "m.png").stat().st_size > 0


@pytest.mark.parametrize("name", ["m.png", "m.rrd"])
def test_explore_output_missing_folder_and_failed_write(tmp_path, capsys, monkeypatch, name):
    # --out nodir/m.rrd was a traceback (after sampling); a failed write (a full disk) cut an earlier good PNG in
    # place, and the recording's untimed flush could hang. Now the folder is checked first, and a failed write is
    # one line that keeps the earlier file whole.
    assert main(["explore", "motion", "--samples", "200", "--out", str(tmp_path / "nodir" / name)]) == 2
    assert _one_error(capsys) == f"mcl: error: --out {tmp_path / 'nodir' / name}: the folder {tmp_path / 'nodir'} does not exist"
    good = tmp_path / name
    assert main(["explore", "motion", "--samples", "200", "--out", str(good)]) == 0
    before = good.read_bytes()
    if name.endswith(".rrd"):  # whole under its own name (written as .partial, renamed after the flush)
        from rerun.chunk import RrdReader

        assert "/motion/0/samples" in {str(c.entity_path) for c in RrdReader(good).stream().to_chunks()}
    capsys.readouterr()
    import mcl.trajectory
    import mcl.viz

    def full(*_a, **_k):
        raise OSError(28, "No space left on device")

    if name.endswith(".png"):
        monkeypatch.setattr(mcl.trajectory.os, "replace", full)
    else:
        monkeypatch.setattr(mcl.viz.os, "replace", full)
    assert main(["explore", "motion", "--samples", "200", "--seed", "3", "--out", str(good)]) == 2
    monkeypatch.undo()
    assert _one_error(capsys) == f"mcl: error: --out {good}: cannot write: No space left on device"
    assert good.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # no temporary file left


def test_eval_of_trajectories_on_two_clocks_names_both_and_their_spans(tmp_path, capsys):
    import numpy as np

    est, ref = tmp_path / "est.tum", tmp_path / "ref.tum"
    write_tum(est, np.arange(5.0), np.zeros((3, 5)))
    write_tum(ref, 1000.0 + np.arange(5.0), np.zeros((3, 5)))
    assert main(["eval", str(est), str(ref)]) == 2
    assert _one_error(capsys) == (f"mcl: error: {ref}: no pose lies within the time span of {est} (reference "
                                  "1000.000..1004.000 s, estimate 0.000..4.000 s): another clock or another dataset?")


def test_eval_warns_of_times_that_go_back_or_repeat_with_another_position(tmp_path, capsys):
    # two poses at t = 1 (x 1 and x 5) and a time going back were scored silently (one of the two chosen)
    import numpy as np

    ref = tmp_path / "ref.tum"
    write_tum(ref, np.arange(5.0), np.zeros((3, 5)))
    est = tmp_path / "est.tum"
    est.write_text("0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n1 5 0 0 0 0 0 1\n3 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n4 0 0 0 0 0 0 1\n")
    assert main(["eval", str(est), str(ref)]) == 0
    err = capsys.readouterr().err
    assert f"mcl: warning: {est}: the time goes back 1 time(s)" in err
    assert f"mcl: warning: {est}: 1 time(s) given twice with other positions (the first at t = 1.000000 s)" in err
    assert str(ref) not in err  # a clean file: no line
    write_tum(est, np.arange(5.0), np.zeros((3, 5)))
    assert main(["eval", str(est), str(ref)]) == 0 and "warning" not in capsys.readouterr().err


@pytest.mark.parametrize("option", [["--json"], ["--converged-within", "0.01"]])
def test_eval_suite_refuses_the_options_of_a_single_trajectory(tmp_path, capsys, option):
    # both were ignored without a word with --suite (the plain table printed, the convergence unchanged)
    assert main(["eval", "--suite", str(tmp_path / "s.yaml"), *option, "--out", str(tmp_path / "o")]) == 2
    assert f"eval: {option[0]}: for ESTIMATE REFERENCE, not with --suite" in _one_error(capsys)
    assert not (tmp_path / "o").exists()


def test_eval_suite_refuses_a_start_offset_that_is_not_a_number(tmp_path, capsys):
    from mcl.config import PROJECT_ROOT

    assert main(["eval", "--suite", str(PROJECT_ROOT / "suites" / "smoke.yaml"), "--start-offset", "nan", "0", "0",
                 "--out", str(tmp_path / "o")]) == 2
    assert "--start-offset: expected three finite numbers, got nan 0.0 0.0" in _one_error(capsys)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("setting,msg", [
    # every scan moved off the odometry's span: the robot would look still (a bag's stamps were checked, a log's not)
    ("sensor.time_offset=2000", "sensor.time_offset: +2000 s moves every scan of"),
    # map rejection with nowhere to stand: failed after a few updates, naming no key
    ("motion.robot_radius=1e12", "motion.robot_radius: no cell of"),
    ("quality.min_beams=100", "quality.min_beams: 100 is more than sensor.max_beams (60)"),
    ("filter.cluster_size=1e-9", "filter.cluster_size: 1e-09 is out of range (must be >= 0.001)"),  # a traceback
])
def test_a_setting_no_run_can_use_is_refused_before_the_run(world, tmp_path, capsys, setting, msg):
    out = tmp_path / "run"
    assert main(["run", "--map", str(world / "map.yaml"), "--log", str(world / "log.clf"), "--particles", "300",
                 "--rerun", "off", "--no-progress", "--out", str(out), "--set", setting]) == 2
    assert msg in _one_error(capsys)
    assert not out.exists()


def test_the_recording_budget_counts_the_particles_the_filter_has(world, tmp_path, capsys):
    # rerun.particles_max above the filter's count: the budget counted particles_max (a cloud on one update in 98
    # for a 10-million maximum), not the 300 particles logged
    assert main(["run", "--map", str(world / "map.yaml"), "--log", str(world / "log.clf"), "--particles", "300",
                 "--rerun", "save", "--no-progress", "--out", str(tmp_path / "r"),
                 "--set", "rerun.particles_max=10000000", "--set", "rerun.budget_mb=1"]) == 0
    assert "the particle cloud on one update in" not in capsys.readouterr().err


def test_a_set_that_overrides_an_option_says_so(world, tmp_path, capsys):
    assert main(["run", "--map", str(world / "map.yaml"), "--log", str(world / "log.clf"), "--particles", "300",
                 "--initial-pose", "1", "2", "0", "--rerun", "off", "--no-progress", "--out", str(tmp_path / "r"),
                 "--set", "filter.particles=200", "--set", "filter.global_localization=true"]) == 0
    err = capsys.readouterr().err
    assert "mcl: warning: --set filter.particles=200 overrides --particles 300" in err
    assert "mcl: warning: --set filter.global_localization=true overrides --initial-pose 1.0 2.0 0.0" in err


def test_beam_weights_that_leave_no_room_for_unexplained_readings_are_warned_about(world, tmp_path, capsys):
    # legal (the weights sum to 1) but every no-return reading zeroes every particle: the run crawled through
    # re-spreads with only "every particle weight is zero" to say why
    assert main(["run", "--map", str(world / "map.yaml"), "--log", str(world / "log.clf"), "--particles", "200",
                 "--rerun", "off", "--no-progress", "--out", str(tmp_path / "r"), "--set", "sensor.model=beam",
                 "--set", "sensor.beam.z_hit=0.9", "--set", "sensor.beam.z_short=0.1", "--set", "sensor.beam.z_max=0",
                 "--set", "sensor.beam.z_rand=0"]) == 0
    assert "mcl: warning: sensor.beam: z_max and z_rand are both 0" in capsys.readouterr().err


def test_a_range_window_that_leaves_the_laser_nothing_to_score_warns_naming_the_key():
    # sensor.range_max 0.05 on a 5 m laser ran the demo on dead reckoning without a word (ATE 6.4 m); so did a
    # range_min above every reading. Returns at the scan's own no-return value (open floor) are no returns: no
    # warning; nor under the defaults; a few stray centimetre readings (the demo's: 5 of 31,435) count as none.
    from types import SimpleNamespace

    import numpy as np

    from mcl.config import SensorConfig
    from mcl.runner import _check_first_scans

    r = np.array([2.6, 0.04, 5.0, 3.1, 4.9])
    scans = [SimpleNamespace(ranges=r, max_range=5.0)] + [SimpleNamespace(ranges=r[[0, 2, 3, 4]], max_range=5.0)] * 60

    def said(**keys):
        out = []
        _check_first_scans(scans, SensorConfig(**keys), out.append)
        return out

    assert said() == []
    (line,) = said(range_max=0.05)
    assert line.startswith("mcl: warning: sensor.range_max (0..0.05 m) leaves 1 of the first scans' 184 returns "
                           "to score (they lie at 0.04..4.90 m)"), line
    (line,) = said(range_min=40.0, range_max=80.0)
    assert line.startswith("mcl: warning: sensor.range_min (40..80 m) leaves 0 of"), line
    empty = [SimpleNamespace(ranges=np.full(5, 5.0), max_range=5.0)] * 10
    out = []
    _check_first_scans(empty, SensorConfig(range_max=0.05), out.append)
    assert out == []
    # readings in millimetres under a maximum range in metres (a log's PARAM 12, a line's max field): every one a
    # no-return, and the run predicted without a word (0.30 m, the odometry's). Now two warnings say why.
    # a Hokuyo URG driver's error codes (0-19 mm) written as metres, a third of the beams: scored as returns at the
    # laser (a global search 6.7 m off). 1 % or more under 2 cm: taken as no returns, said in a note; the demo's 5
    # stray centimetre readings of 31,435 are no error codes (above: no line, no floor).
    codes = [SimpleNamespace(ranges=np.array([2.6, 0.004, 3.1, 0.011, 4.9, 2.2]), max_range=5.0)] * 50
    out = []
    assert _check_first_scans(codes, SensorConfig(), out.append) == 0.02
    assert out == ["100 of the first scans' 300 readings lie under 2 cm (a laser's error codes, as a Hokuyo URG driver "
                   "writes them): taken as no returns (sensor.range_min 0.02)"]
    assert _check_first_scans(codes, SensorConfig(range_min=0.05), []) is None  # the user's own floor stands
    assert _check_first_scans(scans, SensorConfig(), []) is None
    # a 100 m lidar under the default range_max (80 m): its far returns were dropped without a word
    far = [SimpleNamespace(ranges=np.array([2.6, 85.0, 3.1, 92.5]), max_range=100.0)] * 30
    out = []
    _check_first_scans(far, SensorConfig(), out.append)
    assert out == ["60 of the first scans' 120 returns lie at or beyond sensor.range_max (80 m; they reach 92.50 m): "
                   "left out (a larger sensor.range_max scores them)"]
    mm = [SimpleNamespace(ranges=r[[0, 2, 3, 4]] * 1000.0, max_range=12.0)] * 60
    out = []
    _check_first_scans(mm, SensorConfig(), out.append)
    assert out == ["mcl: warning: the first scans' readings lie at 4000 m (median): a laser in a building reads metres; "
                   "readings in millimetres? (mcl reads ranges in metres)",
                   "mcl: warning: 0 of the first scans' 240 readings lie under the laser's own no-return range (12 m, "
                   "as the log gives it): the rest are no returns and the filter predicts (readings in millimetres?)"]



def test_a_laser_mounted_metres_from_the_robot_warns_naming_where_the_mounting_came_from():
    # a mounting from a tf chain through the wrong frame, or a pose typed in the map frame, put every endpoint
    # metres off: 3 m from the robot's centre is no robot's laser (real logs: 0 m; bags: 0.1-0.3 m)
    from types import SimpleNamespace

    import numpy as np

    from mcl.config import SensorConfig
    from mcl.runner import _check_first_scans

    r = np.full(5, 2.0)
    near = [SimpleNamespace(ranges=r, max_range=5.0, laser_offset=np.array([0.25, 0.0, 0.0]))] * 3
    far = near + [SimpleNamespace(ranges=r, max_range=5.0, laser_offset=np.array([12.0, -5.0, 0.0]))]
    out = []
    _check_first_scans(near, SensorConfig(), out.append)
    assert out == []
    _check_first_scans(far, SensorConfig(), out.append)
    assert out == ["mcl: warning: the log's laser mounting puts the laser 13.00 m from the robot's centre (12.000, "
                   "-5.000): a robot's laser sits within a metre or two; check the frames (a tf chain through the "
                   "wrong frame, a pose in the map frame)"], out
    out.clear()
    _check_first_scans(near, SensorConfig(laser_pose=(0.0, 4.0, 0.0)), out.append)
    assert len(out) == 1 and out[0].startswith("mcl: warning: sensor.laser_pose puts the laser 4.00 m"), out


@pytest.mark.parametrize("options, said", [
    (["--scan-gaps", "2", "--scan-gap-s", "0.1"], "--scan-gap-s: expected 0.5..60 s, got 0.1"),
    (["--scan-gaps", "21"], "--scan-gaps: expected 0..20, got 21"),
    (["--odom-stalls", "1", "--odom-stall-s", "100"], "--odom-stall-s: expected 0.5..60 s, got 100.0")])
def test_simulate_scan_gaps_out_of_range_name_the_option(tmp_path, capsys, options, said):
    assert main(["simulate", str(tmp_path / "w"), *options]) == 2
    assert _one_error(capsys) == f"mcl: error: {said}"
    assert not (tmp_path / "w").exists()


@pytest.mark.parametrize("value", ["200", "-181", "nan"])
def test_simulate_map_rotation_is_said_in_degrees(tmp_path, capsys, value):
    assert main(["simulate", str(tmp_path / "w"), "--map-rotation", value]) == 2
    assert _one_error(capsys) == f"mcl: error: --map-rotation: expected -180..180 degrees, got {float(value):g}"
    assert not (tmp_path / "w").exists()


@pytest.mark.parametrize("value", ["400", "-5", "nan"])
def test_simulate_holonomic_is_said_in_degrees(tmp_path, capsys, value):
    # the option is degrees; the error named the keyword's radians ("expected 0..pi rad, got 6.98")
    assert main(["simulate", str(tmp_path / "w"), "--holonomic", value]) == 2
    assert _one_error(capsys) == f"mcl: error: --holonomic: expected 0..180 degrees, got {float(value):g}"
    assert not (tmp_path / "w").exists()


@pytest.mark.parametrize("option", [["--config", "nosuch.yaml"], ["--set", "filter.partcles=1"], ["--seeds", "3"],
                                    ["--only", "x"], ["--out", "o"], ["--no-baseline"]])
def test_eval_of_two_trajectories_refuses_the_options_of_a_suite(tmp_path, capsys, option):
    # scoring two files runs no config: a missing --config, a misspelt --set or --seeds were ignored without a word
    est = tmp_path / "est.tum"
    write_tum(est, np.arange(5.0), np.zeros((3, 5)))
    assert main(["eval", str(est), str(est), *option]) == 2
    assert f"eval: {option[0]}: for --suite, not with ESTIMATE REFERENCE" in _one_error(capsys)
    assert not (tmp_path / "o").exists()


def test_eval_scores_each_run_between_clocks_set_back_against_the_references_run(tmp_path, capsys):
    # A log whose clock was set back 3 s, its reference stamped by the same clock: sorted together, the two runs
    # over the same seconds were interpolated into one another (0.77 m for a track 0.05 m from its reference). Now
    # the k-th run of each is scored against the other's k-th: the track's own 0.05 m, and a note says so.
    t = np.concatenate([np.arange(0.0, 5.0, 0.2), np.arange(2.0, 7.0, 0.2)])  # back 3 s at the 26th pose
    ref = np.vstack([np.arange(t.size) * 0.2, np.zeros(t.size), np.zeros(t.size)])  # driving on at 1 m/s
    est = ref + np.array([[0.0], [0.05], [0.0]])
    a, b = tmp_path / "est.tum", tmp_path / "ref.tum"
    write_tum(a, t, est)
    write_tum(b, t, ref)
    assert main(["eval", str(a), str(b), "--json"]) == 0
    out = capsys.readouterr()
    import json

    r = json.loads(out.out)
    assert r["ate_max"] == pytest.approx(0.05, abs=1e-9) and r["scored"] == t.size
    assert "both trajectories' times go back 1 time(s)" in out.err and "warning" not in out.err


def test_eval_suite_refuses_an_out_folder_it_did_not_make(tmp_path, capsys):
    # an evaluation into a folder of the user's overwrote its results.csv and deleted the PNGs in its plots/
    from mcl.config import PROJECT_ROOT

    out = tmp_path / "o"
    (out / "plots").mkdir(parents=True)
    (out / "plots" / "mine.png").write_bytes(b"png")
    (out / "results.csv").write_text("mine\n")
    suite = str(PROJECT_ROOT / "suites" / "smoke.yaml")
    assert main(["eval", "--suite", suite, "--out", str(out), "--no-progress"]) == 2
    assert "but no results.json, runs/ or worlds/: not an mcl evaluation's folder" in _one_error(capsys)
    (out / "notes.txt").write_text("mine\n")
    assert main(["eval", "--suite", suite, "--out", str(out), "--no-progress"]) == 2
    assert "the folder holds files that are not an evaluation's outputs (notes.txt)" in _one_error(capsys)
    assert (out / "plots" / "mine.png").read_bytes() == b"png" and (out / "results.csv").read_text() == "mine\n"


def test_a_set_of_another_log_drops_the_configs_reference(world, tmp_path, capsys):
    # --set log=... kept the default config's truth (the demo's): the run was scored 13.9 m off against it
    assert main(["run", "--set", f"map={world / 'map.yaml'}", "--set", f"log={world / 'log.clf'}", "--particles",
                 "300", "--initial-pose", "1", "2", "0", "--rerun", "off", "--no-progress", "--out",
                 str(tmp_path / "r")]) == 0
    import yaml

    assert yaml.safe_load((tmp_path / "r" / "config.yaml").read_text())["truth"] is None


def test_another_log_drops_the_configs_start_pose_too_and_config_show_says_what_run_uses(world, tmp_path, capsys):
    # configs/intel_lab.yaml --set log=<the demo's> --set map=<the demo's> started from intel_lab's pose on the
    # demo's map (an unknown cell: lost in 344 of 350 updates); and `mcl config show` with the same --set kept the
    # config's truth, which the run drops. The start pose lies in the config's map: with a new map and log it goes
    # unless given; a new log alone keeps it (a shortened copy of the log, another recording from the same dock).
    import yaml

    log = tmp_path / "other.clf"
    log.write_text((world / "log.clf").read_text())
    other_map = tmp_path / "map.yaml"
    other_map.write_text(yaml.safe_dump({**yaml.safe_load((world / "map.yaml").read_text()),
                                         "image": str(world / "map.pgm")}))
    mine = tmp_path / "mine.yaml"
    mine.write_text(yaml.safe_dump({"map": str(world / "map.yaml"), "log": str(world / "log.clf"),
                                    "truth": str(world / "truth.tum"), "filter": {"initial_pose": [1.0, 2.0, 0.0]}}))
    common = ["--set", f"log={log}", "--set", f"map={other_map}", "--particles", "300", "--rerun", "off",
              "--no-progress"]
    assert main(["run", str(mine), *common, "--out", str(tmp_path / "r")]) == 0
    saved = yaml.safe_load((tmp_path / "r" / "config.yaml").read_text())
    assert saved["truth"] is None and saved["filter"]["initial_pose"] is None
    assert "the config's filter.initial_pose lies in its map" in capsys.readouterr().err
    assert main(["config", "show", str(mine), "--set", f"log={log}", "--set", f"map={other_map}"]) == 0
    shown = yaml.safe_load(capsys.readouterr().out)
    assert shown["truth"] is None and shown["filter"]["initial_pose"] is None
    assert main(["run", str(mine), *common, "--initial-pose", "1", "2", "0.5", "--out", str(tmp_path / "p")]) == 0
    assert yaml.safe_load((tmp_path / "p" / "config.yaml").read_text())["filter"]["initial_pose"] == [1, 2, 0.5]
    assert "lies in its map" not in capsys.readouterr().err
    assert main(["run", str(mine), *common[4:], "--set", f"log={log}", "--out", str(tmp_path / "l")]) == 0
    saved = yaml.safe_load((tmp_path / "l" / "config.yaml").read_text())  # a new log alone: the pose kept
    assert saved["truth"] is None and saved["filter"]["initial_pose"] == [1, 2, 0]
    assert main(["run", str(mine), "--particles", "300", "--rerun", "off", "--no-progress", "--out",
                 str(tmp_path / "same")]) == 0  # its own log: its pose and truth kept
    saved = yaml.safe_load((tmp_path / "same" / "config.yaml").read_text())
    assert saved["filter"]["initial_pose"] == [1, 2, 0] and saved["truth"] == str(world / "truth.tum")


def test_a_malformed_set_is_one_error_line_without_a_warning_before_it(world, tmp_path, capsys):
    assert main(["run", "--map", str(world / "map.yaml"), "--log", str(world / "log.clf"), "--particles", "300",
                 "--rerun", "off", "--no-progress", "--out", str(tmp_path / "r"), "--set", "filter.particles"]) == 2
    err = capsys.readouterr().err
    assert err == "mcl: error: --set filter.particles: expected section.key=value\n"  # no "overrides" warning first


def test_summary_json_writes_a_value_that_is_not_finite_as_null(world, tmp_path, capsys):
    # a log of two scans has no odometry interval to measure (NaN): summary.json held NaN, which JSON has not
    import json

    log = tmp_path / "short.clf"
    log.write_text("".join((world / "log.clf").read_text().splitlines(keepends=True)[:9]))
    assert main(["run", "--map", str(world / "map.yaml"), "--log", str(log), "--particles", "300",
                 "--initial-pose", "1", "2", "0", "--rerun", "off", "--no-progress", "--out", str(tmp_path / "r")]) == 0
    text = (tmp_path / "r" / "summary.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert json.loads(text)["time_offset_check"]["odometry_interval"] is None


def test_a_set_path_is_relative_to_where_it_was_typed(world, tmp_path, capsys, monkeypatch):
    # --set log=w/x.clf was looked for in, and named from, the default config's folder (configs/w/x.clf)
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--map", str(world / "map.yaml"), "--log", str(world / "log.clf"), "--set", "log=w/x.clf",
                 "--rerun", "off", "--no-progress", "--out", str(tmp_path / "r")]) == 2
    assert _one_error(capsys) == f"mcl: error: {tmp_path / 'w' / 'x.clf'}: cannot read: No such file or directory"


@pytest.mark.parametrize("only", ["", " , "])
def test_eval_suite_refuses_an_only_that_names_nothing(tmp_path, capsys, only):
    # --only '' ran every dataset of the suite
    from mcl.config import PROJECT_ROOT

    assert main(["eval", "--suite", str(PROJECT_ROOT / "suites" / "smoke.yaml"), "--only", only,
                 "--out", str(tmp_path / "o")]) == 2
    assert "--only: names no dataset" in _one_error(capsys)
    assert not (tmp_path / "o").exists()


def test_eval_suite_says_when_jobs_outnumber_the_cores(tmp_path, capsys):
    # --jobs 99 on two cores was taken without a word: 99 runs sharing two cores, each one's wall time the load's
    import os

    from mcl.config import PROJECT_ROOT

    jobs = (os.cpu_count() or 1) + 1
    assert main(["eval", "--suite", str(PROJECT_ROOT / "suites" / "smoke.yaml"), "--jobs", str(jobs), "--only",
                 "nosuch", "--out", str(tmp_path / "o")]) == 2
    assert f"mcl: warning: --jobs {jobs} on {os.cpu_count() or 1} cores: the runs share them" in capsys.readouterr().err


def test_a_map_read_into_nothing_a_laser_can_match_is_refused_or_warned_of(world, tmp_path, capsys):
    # ROS map_server reads both of these as they are, and so did mcl, without a word: the demo's image with
    # `mode: raw` (0 is free there, so no cell is occupied) ran lost at 5.6 m ATE; the image inverted (negate the wrong
    # way round: the walls free, the floor occupied) at 9.5 m. The first is one error line before anything is written;
    # the second a warning (a floor plan's black outside also has more occupied cells than free, but an open floor).
    from PIL import Image

    text = (world / "map.yaml").read_text()
    raw = tmp_path / "raw.yaml"
    raw.write_text(text.replace("map.pgm", str(world / "map.pgm")) + "mode: raw\n")
    out = tmp_path / "out"
    assert main(["run", "--map", str(raw), "--log", str(world / "log.clf"), "--out", str(out), "--rerun", "off",
                 "--no-progress", "--particles", "500"]) == 2
    assert (f"{raw}: no occupied cell (" in (err := _one_error(capsys))
            and "nothing for the laser to match (check mode, negate and occupied_thresh" in err)
    assert not out.exists()
    pixels = np.asarray(Image.open(world / "map.pgm"))
    Image.fromarray((255 - pixels).astype(np.uint8)).save(tmp_path / "inverted.pgm")
    inverted = tmp_path / "inverted.yaml"
    inverted.write_text(text.replace("map.pgm", "inverted.pgm"))
    for yaml_path, warned in ((inverted, True), (world / "map.yaml", False)):
        assert main(["run", "--map", str(yaml_path), "--log", str(world / "log.clf"), "--out", str(tmp_path / "o"),
                     "--rerun", "off", "--no-progress", "--particles", "500"]) == 0
        said = [ln for ln in capsys.readouterr().err.splitlines() if "the free space is thin strips" in ln]
        assert len(said) == int(warned), said
        if warned:
            assert said[0].startswith(f"mcl: warning: {inverted}: ") and "walls read as free? (negate" in said[0]


def test_explore_recording_draws_y_up_as_a_runs_recording_does(tmp_path):
    # A 2D view draws y down: without the y flip a run's recording has on `world`, a left turn's samples showed
    # below the start arrow, as a right turn. The samples of a turn to the left lie at y > 0 and the flip is there.
    from rerun.chunk import RrdReader

    from mcl.cli import main

    out = tmp_path / "v.rrd"
    assert main(["explore", "motion", "--velocity", "1", "0.5", "1", "--steps", "3", "--samples", "200",
                 "--out", str(out)]) == 0
    chunks = list(RrdReader(out).stream().to_chunks())
    flips = [c.to_record_batch().column("Transform3D:scale").to_pylist() for c in chunks
             if str(c.entity_path) == "/motion" and "Transform3D:scale" in c.to_record_batch().schema.names]
    assert flips == [[[[1.0, -1.0, 1.0]]]], flips  # one static row of one scale
    ys = [p[1] for c in chunks if str(c.entity_path) == "/motion/0/samples"
          for row in c.to_record_batch().column("Points2D:positions").to_pylist() for p in row]
    assert np.mean(ys) > 0.1  # a left turn's samples, in the map frame's y up


def test_an_unknown_option_is_named_in_its_commands_usage_with_a_suggestion(capsys):
    # argparse 3.11 printed `mcl`'s top-level usage and no suggestion; `--partciles 5` took 5 as the config
    for argv, said in ((["run", "--partciles", "5"], "mcl run: error: unrecognized arguments: --partciles (did you "
                                                     "mean --particles?)"),
                       (["eval", "--jsn"], "mcl eval: error: unrecognized arguments: --jsn (did you mean --json?)"),
                       (["calibrate", "sensor", "--mapp", "x"], "mcl calibrate sensor: error: unrecognized arguments: "
                                                                "--mapp x (did you mean --map?)")):
        with pytest.raises(SystemExit) as e:
            main(argv)
        err = capsys.readouterr().err
        assert e.value.code == 2 and err.splitlines()[-1] == said, err
        assert err.startswith(f"usage: mcl {argv[0]}")  # the command's usage, not mcl's
    with pytest.raises(SystemExit):  # an unknown option before the command is mcl's own
        main(["--bogus", "run"])
    assert capsys.readouterr().err.splitlines()[-1] == "mcl: error: unrecognized arguments: --bogus"


@pytest.mark.parametrize("argv", [["run", "--log", ""], ["run", "--out", " "], ["eval", "", "x.tum"],
                                  ["simulate", ""], ["config", "show", ""]])
def test_an_empty_path_is_refused_by_its_option(capsys, argv):
    # `--log ''` read the current folder as the log ("cannot read: Is a directory"); `--out ''` was no --out
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2 and capsys.readouterr().err.splitlines()[-1].endswith(": an empty path")


def test_a_tilde_in_an_options_path_is_the_home_folder(world, tmp_path, capsys, monkeypatch):
    # bash leaves `~` alone after `--map=`: it was looked for as ./~/..., and `--out=~/x` made a folder named ~
    home = tmp_path / "home"
    (home / "w").mkdir(parents=True)
    for name in ("map.yaml", "map.pgm", "log.clf"):
        (home / "w" / name).write_bytes((world / name).read_bytes())
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--map=~/w/map.yaml", "--log=~/w/log.clf", "--out=~/out", "--particles", "300",
                 "--rerun", "off", "--no-progress"]) == 0
    assert (home / "out" / "trajectory.tum").is_file() and not (tmp_path / "~").exists()


def test_eval_refuses_an_infinite_convergence_bound(tmp_path, capsys):
    t = np.arange(5.0)
    write_tum(tmp_path / "a.tum", t, np.zeros((3, 5)))
    assert main(["eval", str(tmp_path / "a.tum"), str(tmp_path / "a.tum"), "--converged-within", "inf"]) == 2
    assert _one_error(capsys) == "mcl: error: --converged-within: must be a positive number of metres, got inf"


def test_every_commands_help_fits_in_100_columns(capsys, monkeypatch):
    from mcl.cli import _leaf_parsers, build_parser

    monkeypatch.setenv("COLUMNS", "80")  # argparse fills the options to the terminal's width

    widest = {}
    for leaf in _leaf_parsers(build_parser()):
        text = leaf.format_help()
        # the examples of an epilog are kept as written; the description and the options are wrapped
        body = text.split("\nexamples:", 1)[0]
        widest[leaf.prog] = max(len(line) for line in body.splitlines())
    assert max(widest.values()) <= 100, {k: v for k, v in widest.items() if v > 100}


def test_ctrl_c_while_the_parser_is_built_is_one_line(capsys, monkeypatch):
    import mcl.cli

    def interrupted():
        raise KeyboardInterrupt

    monkeypatch.setattr(mcl.cli, "build_parser", interrupted)
    assert main(["run"]) == 130 and capsys.readouterr().err == "mcl: interrupted\n"


def test_the_parser_imports_no_numba(tmp_path):
    # `mcl --help` took 1.1 s: building the parser imported mcl.simulate, which imported numba with mcl.motion
    import subprocess
    import sys

    code = "import sys; from mcl.cli import build_parser; build_parser(); print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_a_start_pose_off_the_map_is_credited_to_the_set_that_gave_it(world, tmp_path, capsys):
    # --initial-pose 1 2 0 with a --set of the pose: the error named the option, whose pose was fine
    for item in ("filter.initial_pose=[1000, 12, 0]", "filter={initial_pose: [1000, 12, 0]}"):
        assert main(["run", "--map", str(world / "map.yaml"), "--log", str(world / "log.clf"), "--initial-pose", "1",
                     "2", "0", "--set", item, "--rerun", "off", "--no-progress", "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert f"mcl: warning: --set {item} overrides --initial-pose 1.0 2.0 0.0" in err  # a whole section too
        assert "mcl: error: filter.initial_pose: (1000.000, 12.000) lies outside the map" in err


def test_a_second_simulate_into_a_folder_one_is_writing_in_is_refused(tmp_path, capsys):
    from mcl.runner import lock_folder

    w = tmp_path / "w"
    w.mkdir()
    fd = lock_folder(w, "held")  # another mcl simulate at work there (it removed the first's working folder)
    try:
        assert main(["simulate", str(w), "--duration", "3"]) == 2
        assert _one_error(capsys) == f"mcl: error: OUTDIR {w}: another mcl simulate is writing a world there"
    finally:
        import os

        os.close(fd)
    assert main(["simulate", str(w), "--duration", "3"]) == 0
