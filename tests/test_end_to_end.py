"""End-to-end: real logs tracked within the accuracy issue 1 asks, outputs, determinism, the CLI."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from mcl.cli import main
from mcl.config import PROJECT_ROOT, load_config
from mcl.runner import run
from mcl.trajectory import read_tum

SHARED = PROJECT_ROOT.parent / "shared" / "data"
CONFIGS = PROJECT_ROOT / "configs"
DEMO = PROJECT_ROOT / "data" / "demo"

needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason=f"real datasets not found at {SHARED}")


def _quiet(*_a, **_k):
    pass


@needs_shared
@pytest.mark.slow
@pytest.mark.parametrize("name", ["intel_lab", "mit_csail"])
@pytest.mark.parametrize("kld", [False, True], ids=["fixed5000", "kld"])
def test_tracking_accuracy_on_real_logs(tmp_path, name, kld):
    # Issue 1: ATE RMSE <= 0.06 m with the dataset config, seed 1 and a fixed 5,000 particles
    # (measured 0.057 on intel_lab, 0.041 on mit_csail, 2026-11-30). Issue 3: with KLD sampling on, as the
    # dataset configs have it, the same bound holds while the mean particle count drops at least
    # 3x from the maximum (measured intel_lab 0.0595 at 2,009 of 10,000; mit_csail, whose config takes default.yaml's
    # filter since 2026-11-30, 0.041 at 5,051 of 100,000).
    overrides = ["rerun.mode=off"] + ([] if kld else ["filter.kld=false", "filter.particles=5000"])
    cfg = load_config(CONFIGS / f"{name}.yaml", overrides)
    assert cfg.seed == 1 and cfg.filter.kld == kld
    s = run(cfg, tmp_path, progress=False, echo=_quiet)
    assert not s["interrupted"]
    ev = s["eval"]
    assert ev["ate_rmse"] <= 0.06, ev
    assert ev["ate_max"] < 0.5, ev  # never lost
    if kld:
        assert s["particles_mean"] <= cfg.filter.particles / 3, s["particles_mean"]
    else:
        assert s["particles_mean"] == 5000
    if name == "mit_csail":
        assert ev["scored"] == 406  # the truth covers 406 scans, all inside the run


@needs_shared
@pytest.mark.slow
def test_global_localization_with_kld_on_intel_lab(tmp_path):
    # Issue 3: `mcl run configs/intel_lab.yaml --global` is within 0.5 m before the end of the first
    # 25 % of the log (662 s of 2651 s) and stays (measured: 2.2 s with seed 1, recovery auto -> on; 67.7 s before a
    # config's missing keys took default.yaml's values).
    cfg = load_config(CONFIGS / "intel_lab.yaml", ["rerun.mode=off", "filter.global_localization=true",
                                                     "eval.converged_within=0.5"])
    s = run(cfg, tmp_path, progress=False, echo=_quiet)
    ev = s["eval"]
    assert ev["convergence_time"] is not None and ev["convergence_time"] < 0.25 * 2651.0, ev
    assert s["particles_max"] == 10000 and s["particles_mean"] < 10000


@needs_shared
def test_run_writes_every_output_and_a_recording_with_one_row_per_update(tmp_path):
    # A short run (the first 150 scans of mit_csail) with a recording, read back with RrdReader.
    from mcl.datasets.carmen import read_carmen

    log = read_carmen(SHARED / "mit_csail" / "log.clf")
    short = tmp_path / "short.clf"
    lines = (SHARED / "mit_csail" / "log.clf").read_text().splitlines(keepends=True)
    short.write_text("".join(lines[: log.scans[150].line]))
    out = tmp_path / "run"
    code = main(
        ["run", str(CONFIGS / "mit_csail.yaml"), "--log", str(short), "--out", str(out), "--particles", "500",
         "--no-progress", "--set", "rerun.particles_max=100"]
    )
    assert code == 0
    for f in ("trajectory.tum", "quality.csv", "recording.rrd", "config.yaml", "summary.json"):
        assert (out / f).is_file(), f
    assert not list(out.glob("*.partial")) and not list(out.glob("*.tmp*"))
    summary = json.loads((out / "summary.json").read_text())
    t, poses = read_tum(out / "trajectory.tum")
    # one pose per scan: the filter's updates and the scans update gating skipped (predicted by odometry)
    assert t.size == summary["scans"] == summary["updates"] + summary["predicted_poses"] == 151
    assert summary["predicted_poses"] > 0
    q = np.genfromtxt(out / "quality.csv", delimiter=",", names=True)
    np.testing.assert_array_equal(q["t"], np.round(t, 6))
    assert int(q["updated"].sum()) == summary["updates"]
    assert np.isnan(q["match"][q["updated"] == 0]).all() and (q["match"][q["updated"] == 1] > 0.5).all()
    assert summary["particles_max"] == 500  # the most KLD sampling may use (mit_csail has it on)
    assert summary["particles_min"] <= summary["particles_mean"] <= 500
    for stage in ("predict", "correct", "resample", "estimate", "viz"):
        assert summary["wall_time_s"][stage] >= 0
    # the time between the data's load and the first update (the filter's and the recording's tables) has a field of
    # its own: "load" + "loop" left 39 of 50 s out on a 208 M-cell map
    assert summary["wall_time_s"]["setup"] > 0
    # what the arithmetic ran on: another machine's numpy SIMD paths can give another trajectory for the same seed
    assert summary["platform"]["numpy"] == np.__version__ and isinstance(summary["platform"]["numpy_simd"], list)
    # The resolved config repeats the run: same trajectory, byte for byte.
    out2 = tmp_path / "again"
    assert main(["run", str(out / "config.yaml"), "--out", str(out2), "--no-progress", "--rerun", "off"]) == 0
    assert (out2 / "trajectory.tum").read_bytes() == (out / "trajectory.tum").read_bytes()

    from rerun.chunk import RrdReader

    import pyarrow as pa

    rows_per_step: dict[int, int] = {}
    for c in RrdReader(out / "recording.rrd").stream().to_chunks():
        if c.entity_path != "/world/particles" or c.is_static or "step" not in c.timeline_names:
            continue
        for s in c.to_record_batch().column("step").cast(pa.int64()).to_pylist():
            rows_per_step[s] = rows_per_step.get(s, 0) + 1
    assert sorted(rows_per_step) == list(range(summary["updates"]))
    assert set(rows_per_step.values()) == {1}


@needs_shared
def test_same_seed_same_trajectory_with_one_and_two_threads(tmp_path):
    # Randomness is drawn outside the parallel kernels, so the thread count cannot change a result.
    outs = []
    for threads in (1, 2):
        out = tmp_path / f"t{threads}"
        env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
        subprocess.run(
            [sys.executable, "-m", "mcl", "run", str(CONFIGS / "intel_lab.yaml"), "--out", str(out), "--rerun", "off",
             "--no-progress", "--particles", "2000"],
            check=True, env=env, capture_output=True,
        )
        outs.append((out / "trajectory.tum").read_bytes())
    assert outs[0] == outs[1]
    assert len(outs[0]) > 10_000


def test_bad_config_is_one_line_and_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("filter:\n  particels: 10\n")
    assert main(["run", str(bad), "--rerun", "off"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "bad.yaml" in err and "filter.particels: unknown key (did you mean particles?)" in err


def test_run_takes_the_config_as_the_other_commands_do_with_config_and_one_config_only(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("filter:\n  particels: 10\n")
    # --config reads the file the positional reads: the same one-line error names it
    assert main(["run", "--config", str(bad), "--rerun", "off"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "bad.yaml" in err and "filter.particels: unknown key" in err
    # two different configs: one line naming both, nothing run or written
    other = tmp_path / "other.yaml"
    other.write_text("filter:\n  particles: 10\n")
    out = tmp_path / "o"
    assert main(["run", str(other), "--config", str(bad), "--out", str(out), "--rerun", "off"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "two configs given" in err and "other.yaml" in err and "bad.yaml" in err
    assert not out.exists()


def test_a_bad_option_value_names_the_option_typed_not_the_key_it_sets(tmp_path, capsys):
    base = ["run", "--map", str(DEMO / "map.yaml"), "--log", str(DEMO / "log.clf"), "--rerun", "off",
            "--out", str(tmp_path / "o")]
    for extra, said in ((["--particles", "0"], "--particles 0: filter.particles: 0 is out of range (must be >= 1)"),
                        (["--seed", "-3"], "--seed -3: seed: -3 is out of range (must be >= 0)"),
                        (["--set", "filter.particles=0"], "--set filter.particles=0: filter.particles: 0 is out")):
        assert main(base + extra) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and said in err
    assert not (tmp_path / "o").exists()


def test_missing_map_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["run", "--map", str(tmp_path / "nope.yaml"), "--log", str(tmp_path / "x.clf"), "--rerun", "off",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "nope.yaml" in err


def test_a_start_pose_off_the_map_is_one_line_and_nothing_written(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["run", "--map", str(DEMO / "map.yaml"), "--log", str(DEMO / "log.clf"), "--out", str(out),
                 "--rerun", "off", "--no-progress", "--initial-pose", "1000", "12", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    # named as typed (it said filter.initial_pose, a key the user never wrote)
    assert "error: --initial-pose 1000 12 0: (1000.000, 12.000) lies outside the map" in err
    assert "map.yaml (x -1.00..21.00 m" in err
    assert not out.exists()
    assert main(["run", "--map", str(DEMO / "map.yaml"), "--log", str(DEMO / "log.clf"), "--out", str(out),
                 "--rerun", "off", "--no-progress", "--set", "filter.initial_pose=[1000, 12, 0]",
                 "--set", "filter.global_localization=false"]) == 2
    assert "error: filter.initial_pose: (1000.000, 12.000) lies outside" in capsys.readouterr().err


def test_a_start_pose_on_a_cell_that_is_not_free_is_a_warning():
    from mcl.maps import load_map
    from mcl.runner import _check_start_pose

    grid = load_map(DEMO / "map.yaml")
    said = []
    _check_start_pose(grid, (-0.9, -0.9, 0.0), "filter.initial_pose", said.append)  # the unknown border
    import yaml

    start = yaml.safe_load((DEMO / "sim.yaml").read_text())["start_pose"]  # free: the robot starts there
    _check_start_pose(grid, start, "filter.initial_pose", said.append)
    assert len(said) == 1 and "(-0.900, -0.900) lies on an unknown cell" in said[0]


@needs_shared
def test_eval_command(tmp_path, capsys):
    truth = SHARED / "intel_lab" / "truth.tum"
    assert main(["eval", str(truth), str(truth), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["ate_rmse"] == 0.0 and r["scored"] == 910 and r["convergence_time"] == 0.0


# The corpus-chosen defaults (particles 100,000 as the KLD maximum, `lost` recovery, a 5,000 floor, no beam
# skipping), given explicitly so the test keeps its meaning if configs/default.yaml changes them.
_NEW_DEFAULTS = ["filter.particles=100000", "filter.recovery=lost", "filter.min_particles=5000",
                 "sensor.beam_skip=false"]


def test_global_localization_on_the_bundled_demo(tmp_path):
    # Issues 1 and 13: data/demo (seed 7, 5 m laser, kidnapped at 50 s) shows global localization taking
    # seconds, then tracking, then a kidnapping and its recovery. With the defaults above (filter seed 1):
    # - not localized by the first scan alone (error > 0.3 m at step 0; measured 0.75 m with the default's
    #   scan-matched search, filter.search_refine 3 and search_settled_std 1; 7.5 m without it);
    # - within 0.3 m after step 0 and by 20 s, and staying there until the kidnapping (measured 0.4 s; 0.8 s
    #   without the matching: the search settles on a place the first scan contradicts, and on probation that
    #   re-seeds at once, at step 1; 13.8 s without recovery_probation and lost_exponent either);
    # - tracking after that with position RMSE < 0.15 m (measured 0.058 m);
    # - back within 0.3 m by 60 s (measured 52.8 s on 2026-11-29 with the matching, 55.0 s on 2026-11-26, 57.2 s earlier; 53.4 s without sensor.unmapped_skip, that config's luckiest
    #   seed: over filter seeds 1-8 both take 57.2-65.2 s, median 57.6 s; 63.4 s with the likelihood field's
    #   interior: zero while tracking, after a re-seed at 62.8 s) and RMSE < 0.15 m from there.
    # One seed: the bounds leave a margin of seconds / 2x on the measured values.
    # The run also writes the recording `mcl run` makes: under 10 MB (measured 6-7 MB).
    from mcl.trajectory import read_tum

    cfg = load_config(CONFIGS / "default.yaml", ["rerun.mode=save"] + _NEW_DEFAULTS)
    assert cfg.filter.initial_pose is None  # global localization: no start pose
    s = run(cfg, tmp_path, progress=False, echo=_quiet)
    assert s["mode"] == "global"
    assert s["eval"]["scored"] >= 340
    assert 1_000_000 < (tmp_path / "recording.rrd").stat().st_size < 10_000_000
    te, pe = read_tum(tmp_path / "trajectory.tum")
    tt, pt = read_tum(DEMO / "truth.tum")
    i = np.clip(np.searchsorted(tt, te - 1e-6), 0, tt.size - 1)
    assert np.allclose(tt[i], te)
    err = np.hypot(pe[0] - pt[0, i], pe[1] - pt[1, i])
    assert err[0] > 0.3, err[0]
    before = te < 50.0
    bad = np.flatnonzero(before & (err >= 0.3))
    conv = te[bad[-1] + 1]
    assert te[0] < conv <= 20.0, conv
    track = before & (te >= conv)
    assert np.sqrt(np.mean(err[track] ** 2)) < 0.15
    after = te >= 60.0
    assert err[after].max() < 0.3, err[after].max()
    assert np.sqrt(np.mean(err[after] ** 2)) < 0.15


def _demo_start() -> list[float]:
    import yaml

    return yaml.safe_load((DEMO / "sim.yaml").read_text())["start_pose"]


def test_a_map_stored_turned_with_a_yaw_origin_tracks_as_the_plain_one(tmp_path):
    # A generated world's map drawn again on a lattice turned by 0.4 rad (each lattice cell takes the map cell under its
    # centre) and saved with origin [x, y, 0.4]: the same world, so its log and truth still fit it. Such a
    # map was refused ("non-zero yaw not supported"); read with the yaw ignored, as AMCL does, the walls are 0.4 rad
    # off and the track is lost (measured: RMSE 7.4 m, against 0.051 m turned and 0.050 m plain).
    from PIL import Image

    from mcl.maps import load_map
    from mcl.simulate import simulate

    world = tmp_path / "w"
    x, y, th = simulate(world, seed=2, duration=30.0)["start_pose"]
    flat = load_map(world / "map.yaml")
    yaw, res = 0.4, flat.resolution
    c, s = math.cos(yaw), math.sin(yaw)
    # the map's corners in the turned lattice's frame give its extent
    cx = flat.origin[0] + np.array([0, flat.width, 0, flat.width]) * res
    cy = flat.origin[1] + np.array([0, 0, flat.height, flat.height]) * res
    lx, ly = c * cx + s * cy, -s * cx + c * cy
    w, h = int(np.ceil((lx.max() - lx.min()) / res)), int(np.ceil((ly.max() - ly.min()) / res))
    origin = (float(c * lx.min() - s * ly.min()), float(s * lx.min() + c * ly.min()))  # the lattice's lower-left corner, world
    i, j = np.mgrid[0:h, 0:w]
    px, py = (j + 0.5) * res, (i + 0.5) * res
    ix, iy = flat.world_to_cell(origin[0] + c * px - s * py, origin[1] + s * px + c * py)
    inside = flat.contains(ix, iy)
    occ = np.full((h, w), -1, dtype=np.int8)
    occ[inside] = flat.occupancy[iy[inside], ix[inside]]
    pixels = np.where(occ == -1, 205, np.where(occ >= 65, 0, 254)).astype(np.uint8)[::-1]  # image row 0: top
    Image.fromarray(pixels).save(tmp_path / "turned.pgm")
    (tmp_path / "turned.yaml").write_text(f"image: turned.pgm\nresolution: {res!r}\norigin: [{origin[0]!r}, "
                                          f"{origin[1]!r}, {yaw!r}]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
                                          "negate: 0\n")
    common = ["--log", str(world / "log.clf"), "--truth", str(world / "truth.tum"), "--initial-pose", str(x), str(y),
              str(th), "--particles", "2000", "--rerun", "off", "--no-progress", "--set", "filter.kld=false"]
    assert main(["run", "--map", str(tmp_path / "turned.yaml"), "--out", str(tmp_path / "turned"), *common]) == 0
    assert main(["run", "--map", str(world / "map.yaml"), "--out", str(tmp_path / "flat"), *common]) == 0
    # the yaw ignored, as AMCL does: the same image and corner, unturned
    (tmp_path / "ignored.yaml").write_text((tmp_path / "turned.yaml").read_text().replace(f"{yaw!r}]", "0.0]"))
    assert main(["run", "--map", str(tmp_path / "ignored.yaml"), "--out", str(tmp_path / "ignored"), *common]) == 0
    turned, plain, ignored = (json.loads((tmp_path / k / "summary.json").read_text())["eval"]
                              for k in ("turned", "flat", "ignored"))
    # two nearest-cell resamplings move a wall by up to a cell (5 cm): within 2 cm of the plain map's RMSE
    assert turned["ate_rmse"] < plain["ate_rmse"] + 0.02 and turned["ate_max"] < 0.3
    assert ignored["ate_max"] > 1.0


def test_line_features_are_drawn_in_the_recording(tmp_path):
    # rerun.lines: the split-and-merge lines of every scan, at world/lines, one row per update,
    # lying on the map's walls (the demo world is made of straight walls).
    import pyarrow as pa
    from rerun.chunk import RrdReader

    from mcl.maps import load_map

    out = tmp_path / "run"
    assert main(["run", "--no-progress", "--out", str(out), "--particles", "300", "--set", "filter.kld=false",
                 "--set", "rerun.lines=true", "--set", "rerun.particles_max=10", "--set", f"filter.initial_pose={_demo_start()}",
                 "--set", "filter.global_localization=false"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    grid = load_map(DEMO / "map.yaml")
    steps, points = [], []
    for c in RrdReader(out / "recording.rrd").stream().to_chunks():
        if c.entity_path != "/world/lines" or c.is_static:
            continue
        batch = c.to_record_batch()
        steps += batch.column("step").cast(pa.int64()).to_pylist()
        for strips in batch.column("LineStrips2D:strips").to_pylist():
            for strip in strips or []:
                points += [p for p in strip]
    assert sorted(steps) == list(range(summary["updates"]))
    pts = np.array(points, dtype=np.float64)
    assert len(pts) > 2 * summary["updates"]  # several lines per scan
    ix, iy = grid.world_to_cell(pts[:, 0], pts[:, 1])
    ok = grid.contains(ix, iy)
    d = grid.distance[iy[ok], ix[ok]]
    assert ok.mean() > 0.99 and np.median(d) < 0.1, (ok.mean(), np.median(d))


def test_map_and_log_without_a_config_use_the_documented_defaults(tmp_path, capsys):
    # `mcl run --map M --log L` takes configs/default.yaml's values (not the demo's truth file).
    out = tmp_path / "o"
    assert main(["run", "--map", str(DEMO / "map.yaml"), "--log", str(DEMO / "log.clf"), "--out", str(out),
                 "--rerun", "off", "--no-progress", "--particles", "800"]) == 0
    cfg = load_config(out / "config.yaml")
    default = load_config(CONFIGS / "default.yaml")
    assert cfg.truth is None and "eval" not in json.loads((out / "summary.json").read_text())
    assert cfg.filter.kld == default.filter.kld and cfg.filter.recovery == default.filter.recovery
    assert cfg.motion == default.motion and cfg.sensor == default.sensor
    assert main(["run", "--map", str(DEMO / "map.yaml"), "--rerun", "off"]) == 2
    assert "--map and --log go together" in capsys.readouterr().err


def test_a_log_given_on_the_command_line_drops_the_config_files_truth(tmp_path):
    # configs/baseline.yaml names the demo's truth; `--log` another log without `--truth` must not score that log
    # against it (it did: infinite_corridor scored "ATE 65 m" against the demo's reference poses).
    from mcl.simulate import simulate

    sim = simulate(tmp_path / "w", seed=2, duration=6.0)
    x, y, th = sim["start_pose"]
    common = ["run", str(CONFIGS / "baseline.yaml"), "--map", str(tmp_path / "w" / "map.yaml"), "--log",
              str(tmp_path / "w" / "log.clf"), "--initial-pose", str(x), str(y), str(th), "--particles", "300",
              "--rerun", "off", "--no-progress"]
    assert main([*common, "--out", str(tmp_path / "a")]) == 0
    assert load_config(tmp_path / "a" / "config.yaml").truth is None
    assert "eval" not in json.loads((tmp_path / "a" / "summary.json").read_text())
    assert main([*common, "--truth", str(tmp_path / "w" / "truth.tum"), "--out", str(tmp_path / "b")]) == 0
    assert json.loads((tmp_path / "b" / "summary.json").read_text())["eval"]["ate_rmse"] < 0.3


def test_a_truth_on_another_clock_is_a_warning_before_the_run_and_not_scored_after(tmp_path, capsys):
    # A reference stamped 1000 s after the log: the run said nothing and summary.json held an error no one reads.
    truth = tmp_path / "late.tum"
    rows = [line.split() for line in (DEMO / "truth.tum").read_text().splitlines() if not line.startswith("#")]
    truth.write_text("".join(" ".join([f"{float(r[0]) + 1000:.6f}", *r[1:]]) + "\n" for r in rows))
    out = tmp_path / "o"
    assert main(["run", "--truth", str(truth), "--out", str(out), "--rerun", "off", "--no-progress",
                 "--particles", "800"]) == 0
    said = capsys.readouterr()
    text = said.out + said.err
    assert (f"mcl: warning: {truth}: no reference pose is stamped within the scans' time span (reference "
            "1000.000..1070.000 s, scans 0.000..70.000 s): the run will not be scored") in text
    assert "Not scored: evaluation: no reference timestamp lies inside" in text and "ATE RMSE" not in text
    assert "error" in json.loads((out / "summary.json").read_text())["eval"]


@pytest.mark.parametrize("model", ["odometry", "velocity"])
def test_a_robot_that_backs_up_is_tracked(tmp_path, model):
    # `mcl simulate --reversals 6`: the robot backs up 0.5-3 m six times in 40 s (its odometry reads rot1 ~ pi on
    # those steps, and tv < 0). Both motion models must follow it: within 0.3 m throughout, seed 1 (measured:
    # 0.076 m max with the odometry model, 0.083 m with the velocity model). The velocity model reads the log's
    # velocities, which a 241-beam laser's ROBOTLASER1 lines carry (FLASER lines carry none): with a tv that said
    # forwards while the robot backs up, it was 0.87 m off.
    from mcl.simulate import simulate

    w = tmp_path / "w"
    s = simulate(w, kind="office", seed=7, duration=40.0, reversals=6, n_beams=241, fov=4.18879)
    assert "ROBOTLASER1" in (w / "log.clf").read_text()
    out = tmp_path / "o"
    assert main(["run", "--map", str(w / "map.yaml"), "--log", str(w / "log.clf"), "--truth", str(w / "truth.tum"),
                 "--initial-pose", *map(str, s["start_pose"]), "--out", str(out), "--rerun", "off",
                 "--no-progress", "--seed", "1", "--set", f"motion.model={model}"]) == 0
    ev = json.loads((out / "summary.json").read_text())["eval"]
    assert ev["ate_max"] < 0.3, ev


def test_the_online_odometry_scale_finds_a_wheel_five_per_cent_off(tmp_path):
    # motion.scale_window on an office world whose odometry reads every step 5 % short (mcl simulate odom_scale 0.95;
    # features in every view, so the scans pin the pose along the direction of travel): the learnt scale is the
    # truth's 1 / 0.95 = 1.053 within 0.015 (measured 1.052 over the 40 m drive; a sign error goes the other way,
    # to 0.95 or the 0.85 floor), reported in summary.json; off, the key is absent.
    from mcl.simulate import simulate

    w = tmp_path / "w"
    s = simulate(w, kind="office", seed=11, duration=90.0, odom_scale=0.95)
    common = ["run", "--map", str(w / "map.yaml"), "--log", str(w / "log.clf"), "--truth", str(w / "truth.tum"),
              "--initial-pose", *map(str, s["start_pose"]), "--rerun", "off", "--no-progress", "--seed", "1"]
    assert main([*common, "--out", str(tmp_path / "on"), "--set", "motion.scale_window=50"]) == 0
    on = json.loads((tmp_path / "on" / "summary.json").read_text())
    assert on["odometry_scale"] == pytest.approx(1.0 / 0.95, abs=0.015)
    assert main([*common, "--out", str(tmp_path / "off")]) == 0
    off = json.loads((tmp_path / "off" / "summary.json").read_text())
    assert "odometry_scale" not in off
    assert on["eval"]["ate_max"] < 0.3 and off["eval"]["ate_max"] < 0.3


def test_a_laser_mounted_behind_and_looking_back_is_tracked_and_its_mounting_matters(tmp_path):
    # A world whose laser sits 0.16 m behind and beside the centre, looking back (mcl simulate laser_pose): the log
    # says where (FLASER's laser pose), and every computation must cast from there. Tracked within 0.2 m, seed 1
    # (measured: RMSE 0.057 m, max 0.111 m); the same log read as if the laser were at the centre
    # (sensor.laser_pose [0, 0, 0]: looking forward) is lost, so the bound tests the mounting, not only the world.
    # The control runs without recovery, the mounting alone (measured: RMSE 6.04 m, max 7.59 m, 3.7 s): with it the
    # filter finds the mirrored pose again and again, 73 searches of 100,000-200,000 particles in 35 s of CPU
    # (RMSE 0.74 m, max 2.26 m).
    from mcl.simulate import simulate

    w = tmp_path / "w"
    s = simulate(w, kind="office", seed=7, duration=40.0, laser_pose=(-0.15, 0.05, math.pi))
    common = ["run", "--map", str(w / "map.yaml"), "--log", str(w / "log.clf"), "--truth", str(w / "truth.tum"),
              "--initial-pose", *map(str, s["start_pose"]), "--rerun", "off", "--no-progress", "--seed", "1"]
    assert main([*common, "--out", str(tmp_path / "on")]) == 0
    on = json.loads((tmp_path / "on" / "summary.json").read_text())["eval"]
    assert on["ate_max"] < 0.2, on
    assert main([*common, "--out", str(tmp_path / "off"), "--set", "sensor.laser_pose=[0, 0, 0]",
                 "--set", "filter.recovery=false"]) == 0
    off = json.loads((tmp_path / "off" / "summary.json").read_text())["eval"]
    assert off["ate_max"] > 1.0, off


def test_a_rough_start_pose_is_corrected_at_once_with_the_initial_std_it_deserves(tmp_path):
    # A start pose 0.7 m and 0.3 rad off (a pose clicked on a map), office world seed 103: the default's initial cloud
    # (std 0.1 m, 0.1 rad) holds no particle near the truth and follows a wrong pose for seconds (measured: max
    # 1.55 m, within 0.3 m after 9.0 s, seed 1); `--initial-std 0.3 0.3 0.2` covers it and is within 0.3 m at the
    # first scan (measured: max 0.110 m). Bounds: 1.0 m and 0.2 m, each far from the other run's figure. The ESS floor
    # is pinned off (filter.ess_floor 0, the default), as measured: with it (0.005) the narrow cloud's tempered scans
    # follow the wrong pose less far (max 0.99 m), and the narrow run would no longer tell the two apart.
    from mcl.simulate import simulate

    w = tmp_path / "w"
    x, y, th = simulate(w, kind="office", seed=103, duration=30.0)["start_pose"]
    common = ["run", "--map", str(w / "map.yaml"), "--log", str(w / "log.clf"), "--truth", str(w / "truth.tum"),
              "--initial-pose", str(x + 0.7), str(y), str(th + 0.3), "--rerun", "off", "--no-progress", "--seed", "1",
              "--set", "filter.ess_floor=0"]
    assert main([*common, "--out", str(tmp_path / "narrow")]) == 0
    narrow = json.loads((tmp_path / "narrow" / "summary.json").read_text())
    assert narrow["eval"]["ate_max"] > 1.0, narrow["eval"]
    assert main([*common, "--out", str(tmp_path / "wide"), "--initial-std", "0.3", "0.3", "0.2"]) == 0
    wide = json.loads((tmp_path / "wide" / "summary.json").read_text())["eval"]
    assert wide["ate_max"] < 0.2 and wide["convergence_time"] == 0.0, wide
    import yaml

    assert yaml.safe_load((tmp_path / "wide" / "config.yaml").read_text())["filter"]["initial_std"] == [0.3, 0.3, 0.2]


def test_an_initial_std_on_a_global_start_is_a_note(tmp_path, capsys):
    # --initial-std with no start pose: the run is global and the option does nothing, which is said (one line)
    demo = DEMO
    assert main(["run", "--map", str(demo / "map.yaml"), "--log", str(demo / "log.clf"), "--initial-std", "0.3",
                 "0.3", "0.2", "--rerun", "off", "--no-progress", "--out", str(tmp_path / "o"),
                 "--set", "filter.particles=2000", "--set", "filter.kld=false"]) == 0
    err = capsys.readouterr().err
    assert "mcl: note: --initial-std is not used: the run starts globally" in err
