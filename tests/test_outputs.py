"""Where a run writes: ``--out`` checked before any work, an earlier run's outputs replaced, a user's files never
overwritten, and a run stopped by a bad input mid-way says so in its folder (mcl.runner.check_out_dir, _run)."""

from __future__ import annotations

import json
import os
import stat

import pytest

from mcl.cli import main
from mcl.errors import DataError
from mcl.simulate import simulate


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    d = tmp_path_factory.mktemp("world")
    simulate(d, seed=3, duration=8.0)
    return d


def _run(world, out, *extra):
    return main(["run", "--map", str(world / "map.yaml"), "--log", str(world / "log.clf"), "--particles", "300",
                 "--rerun", "off", "--no-progress", "--out", str(out), *extra])


def _error_lines(capsys):
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("mcl: error:")]


def test_an_out_that_is_a_file_is_refused_in_one_line(world, tmp_path, capsys):
    f = tmp_path / "afile"
    f.write_text("mine\n")
    assert _run(world, f) == 2
    assert _error_lines(capsys) == [f"mcl: error: --out {f}: exists and is not a folder"]
    assert f.read_text() == "mine\n"
    assert _run(world, f / "x") == 2  # below a file (as /dev/null/x): no traceback either
    assert _error_lines(capsys) == [f"mcl: error: --out {f / 'x'}: {f} is not a folder"]


def test_an_out_in_a_read_only_folder_is_refused_before_the_run(world, tmp_path, capsys, monkeypatch):
    import mcl.trajectory

    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(stat.S_IRUSR | stat.S_IXUSR)
    if os.geteuid() == 0:  # root may write in it all the same: the check's answer as a user's
        real = os.access
        monkeypatch.setattr(mcl.trajectory.os, "access", lambda p, m: False if str(p) == str(ro) else real(p, m))
    try:
        assert _run(world, ro / "run") == 2
        assert _error_lines(capsys) == [f"mcl: error: --out {ro / 'run'}: cannot write in {ro} (permission denied)"]
        assert main(["simulate", str(ro / "sim"), "--duration", "5"]) == 2
        assert _error_lines(capsys) == [f"mcl: error: OUTDIR {ro / 'sim'}: cannot write in {ro} (permission denied)"]
    finally:
        ro.chmod(stat.S_IRWXU)


def test_an_os_error_while_writing_is_one_line(world, tmp_path, capsys, monkeypatch):
    # a full disk, a folder made read-only mid-run: one line naming the file, no traceback
    import mcl.runner

    def full(*_a, **_k):
        raise OSError(28, "No space left on device", str(tmp_path / "disk" / "trajectory.tum.partial"))

    monkeypatch.setattr(mcl.runner, "_clear_run_outputs", full)
    assert _run(world, tmp_path / "disk") == 2
    assert _error_lines(capsys) == [f"mcl: error: {tmp_path / 'disk'}: cannot write the run's outputs there: "
                                    "No space left on device"]


def test_a_folder_with_a_users_files_is_refused_and_left_as_it_is(world, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "trajectory.tum").write_text("my own\n")  # a run's file name, but no mcl run wrote it
    assert _run(world, out) == 2
    (line,) = _error_lines(capsys)
    assert "holds trajectory.tum but no config.yaml" in line
    (out / "notes.txt").write_text("x\n")
    assert _run(world, out) == 2
    (line,) = _error_lines(capsys)
    assert "holds files that are not a run's outputs (notes.txt)" in line
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "trajectory.tum"]
    assert (out / "trajectory.tum").read_text() == "my own\n"


def test_a_run_again_into_its_folder_replaces_the_earlier_runs_outputs(world, tmp_path):
    out = tmp_path / "again"
    assert _run(world, out, "--rerun", "save") == 0
    assert (out / "recording.rrd").is_file()
    assert _run(world, out, "--seed", "2") == 0  # --rerun off (after the one above): no recording of its own
    assert not (out / "recording.rrd").exists()  # run 1's recording does not sit beside run 2's trajectory
    assert json.loads((out / "summary.json").read_text())["seed"] == 2


def test_a_folder_named_as_an_output_is_refused_before_the_earlier_outputs_go(world, tmp_path, capsys):
    # An earlier run's folder holding a folder named recording.rrd: the earlier outputs were deleted, then the
    # recording could not be opened (a RuntimeError traceback, exit 1). Now it is refused first, in one line.
    out = tmp_path / "again"
    assert _run(world, out) == 0
    before = {q.name: q.read_bytes() for q in out.iterdir()}
    (out / "recording.rrd").mkdir()
    assert _run(world, out, "--rerun", "save", "--seed", "2") == 2
    (line,) = _error_lines(capsys)
    assert "holds files that are not a run's outputs (recording.rrd)" in line
    assert {q.name: q.read_bytes() for q in out.iterdir() if q.is_file()} == before


def test_a_recording_carries_its_final_name_only_once_whole(tmp_path):
    # The recording was written straight to recording.rrd: a run killed (kill -9, out of memory) left one without its
    # footer, which no reader opens, under the name of a whole one. It is written as recording.partial.rrd and renamed
    # when closed whole; an earlier run's partial file is replaced.
    import numpy as np

    from mcl.viz import RerunLogger, recording_is_whole

    path = tmp_path / "recording.rrd"
    partial = tmp_path / "recording.partial.rrd"
    partial.write_bytes(b"an earlier run's, cut short")
    logger = RerunLogger("save", path)
    logger.log_step(0, 0.0, particles=np.zeros((3, 10)), weights=np.full(10, 0.1), estimate=np.zeros(3),
                    cov=np.eye(3))
    assert not path.exists() and partial.exists()  # killed here: no recording.rrd
    logger.close()
    assert path.is_file() and recording_is_whole(path) and not partial.exists()


def test_a_recording_that_cannot_be_opened_is_one_os_error(tmp_path):
    from mcl.viz import RerunLogger

    (tmp_path / "recording.rrd").mkdir()
    with pytest.raises(OSError, match="cannot open the recording") as e:
        RerunLogger("save", tmp_path / "recording.rrd")
    assert e.value.filename == str(tmp_path / "recording.rrd")


def test_a_map_without_a_free_cell_is_refused_before_anything_is_written(world, tmp_path, capsys):
    import yaml

    spec = yaml.safe_load((world / "map.yaml").read_text())
    spec.update(image=str(world / spec["image"]), free_thresh=0.0, occupied_thresh=1.0)  # every cell unknown
    m = tmp_path / "map.yaml"
    m.write_text(yaml.safe_dump(spec))
    out = tmp_path / "nofree"
    assert main(["run", "--map", str(m), "--log", str(world / "log.clf"), "--rerun", "off", "--no-progress",
                 "--out", str(out), "--global"]) == 2
    (line,) = _error_lines(capsys)
    assert line.endswith("no free cell (occupied_thresh and free_thresh leave every cell occupied or unknown): "
                         "nowhere to localize")
    assert not out.exists()


def test_a_bad_input_found_mid_run_keeps_the_poses_and_the_summary_says_why(world, tmp_path, capsys, monkeypatch):
    from mcl.filter import ParticleFilter

    step, calls = ParticleFilter.step, []

    def failing(self, *a, **k):
        calls.append(1)
        if len(calls) == 11:
            raise DataError("log.clf:99: a bad reading")
        return step(self, *a, **k)

    monkeypatch.setattr(ParticleFilter, "step", failing)
    out = tmp_path / "stopped"
    assert _run(world, out) == 2
    (line,) = _error_lines(capsys)
    assert line.startswith("mcl: error: log.clf:99: a bad reading (stopped after 10 updates; the poses so far")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["error"] == "stopped after 10 updates: log.clf:99: a bad reading"
    assert summary["updates"] == 10 and not summary["interrupted"]
    poses = (out / "trajectory.tum").read_text().splitlines()
    assert len(poses) == summary["updates"] + summary["predicted_poses"] >= 10
    assert not list(out.glob("*.partial"))


def _stop_at(monkeypatch, update: int, raised: BaseException) -> None:
    from mcl.filter import ParticleFilter

    step, calls = ParticleFilter.step, []

    def stopping(self, *a, **k):
        calls.append(1)
        if len(calls) == update:
            raise raised
        return step(self, *a, **k)

    monkeypatch.setattr(ParticleFilter, "step", stopping)


def _files(out):
    return {q.name: q.read_bytes() for q in out.iterdir() if q.is_file()}


@pytest.mark.parametrize("stop", ["interrupt", "error"])
def test_a_rerun_that_does_not_finish_keeps_the_earlier_finished_run(world, tmp_path, capsys, monkeypatch, stop):
    # Ctrl-C (or a bad reading) in a second run into a folder holding a finished run: the finished run's outputs
    # were deleted as the second began, leaving a few updates of a run nobody wanted
    out = tmp_path / "again"
    assert _run(world, out, "--rerun", "save") == 0
    before = _files(out)
    _stop_at(monkeypatch, 5, KeyboardInterrupt() if stop == "interrupt" else DataError("log.clf:9: a bad reading"))
    capsys.readouterr()
    assert _run(world, out, "--seed", "2") == (130 if stop == "interrupt" else 2)
    err = capsys.readouterr().err
    assert f"the earlier finished run in {out} is kept (this run's outputs were discarded)" in err
    assert _files(out) == before and sorted(p.name for p in out.iterdir()) == sorted(before)
    monkeypatch.undo()
    assert _run(world, out, "--seed", "2") == 0  # and a rerun that finishes replaces it, leaving nothing aside
    assert json.loads((out / "summary.json").read_text())["seed"] == 2
    assert not (out / "recording.rrd").exists() and not (out / ".mcl-previous").exists()


def test_a_rerun_over_an_unfinished_run_replaces_it(world, tmp_path, monkeypatch):
    out = tmp_path / "again"
    _stop_at(monkeypatch, 5, KeyboardInterrupt())
    assert _run(world, out) == 130
    monkeypatch.undo()
    _stop_at(monkeypatch, 7, KeyboardInterrupt())
    assert _run(world, out, "--seed", "2") == 130  # the interrupted run was nothing to keep: the new one stands
    summary = json.loads((out / "summary.json").read_text())
    assert summary["seed"] == 2 and summary["updates"] == 6 and summary["interrupted"]
    assert not (out / ".mcl-previous").exists()


def _set_aside(out, names):
    """The files ``names`` of the run in ``out`` moved into out/.mcl-previous, as a rerun killed mid-way leaves them."""
    (out / ".mcl-previous").mkdir()
    for name in names:
        os.replace(out / name, out / ".mcl-previous" / name)


def test_a_finished_run_set_aside_by_a_killed_rerun_comes_back(world, tmp_path, monkeypatch):
    out = tmp_path / "again"
    assert _run(world, out) == 0
    before = _files(out)
    # kill -9 mid-rerun: the finished run aside, a few poses of the new one in the folder
    _set_aside(out, before)
    (out / "config.yaml").write_text("seed: 2\n")
    (out / "trajectory.tum.partial").write_text("1.0 0 0 0 0 0 0 1\n")
    _stop_at(monkeypatch, 3, KeyboardInterrupt())
    assert _run(world, out, "--seed", "3") == 130
    assert _files(out) == before and not (out / ".mcl-previous").exists()


def test_a_rerun_that_fails_before_its_loop_puts_the_earlier_run_back(world, tmp_path, capsys, monkeypatch):
    # quality.csv that cannot be opened: the error left the loop's handling out, and the finished run stayed hidden
    # in .mcl-previous
    import mcl.trajectory

    out = tmp_path / "again"
    assert _run(world, out) == 0
    before = _files(out)

    def full(*_a, **_k):
        raise OSError(28, "No space left on device", str(out / "quality.csv"))

    monkeypatch.setattr(mcl.trajectory, "LineWriter", full)
    assert _run(world, out, "--seed", "2") == 2
    assert _files(out) == before and not (out / ".mcl-previous").exists()


@pytest.mark.parametrize("moved", [
    ["summary.json"],  # killed part-way through the set-aside (summary.json goes first, config.yaml last) ...
    ["summary.json", "quality.csv", "trajectory.tum"],
    ["summary.json", "trajectory.tum"],  # ... or through the put-back (config.yaml first, summary.json last)
])
def test_a_run_killed_while_it_set_the_earlier_run_aside_or_put_it_back_gets_it_back(world, tmp_path, monkeypatch,
                                                                                    moved):
    # the folder is still one a run accepts (it held quality.csv and summary.json without config.yaml, refused),
    # and the next run puts the earlier run back whole before it sets it aside again (once summary.json was back,
    # the stash was deleted with the files still in it)
    out = tmp_path / "again"
    assert _run(world, out) == 0
    before = _files(out)
    _set_aside(out, moved)
    _stop_at(monkeypatch, 3, KeyboardInterrupt())
    assert _run(world, out, "--seed", "3") == 130
    assert _files(out) == before and not (out / ".mcl-previous").exists()


def test_an_input_where_the_run_writes_an_output_is_refused(world, tmp_path, capsys):
    # `mcl run proj/config.yaml --out proj` wrote the resolved config over the user's commented one; a --truth
    # inside the folder was replaced by the new estimate
    out = tmp_path / "proj"
    out.mkdir()
    config = out / "config.yaml"
    config.write_text(f"# mine\nmap: {world / 'map.yaml'}\nlog: {world / 'log.clf'}\n")
    assert main(["run", str(config), "--out", str(out), "--rerun", "off", "--no-progress"]) == 2
    assert _error_lines(capsys) == [f"mcl: error: --out {out}: the run would write over its own config, {config}; "
                                    "choose another folder"]
    assert config.read_text().startswith("# mine")
    r0 = tmp_path / "r0"
    assert _run(world, r0) == 0
    truth = (r0 / "trajectory.tum").read_bytes()
    assert _run(world, r0, "--truth", str(r0 / "trajectory.tum")) == 2
    (line,) = _error_lines(capsys)
    assert "the run would write over its own truth" in line and (r0 / "trajectory.tum").read_bytes() == truth


def test_a_full_disk_mid_run_keeps_the_whole_lines_and_says_which_file(world, tmp_path):
    # A file size limit (a full disk, as `ulimit -f` makes it) hit by the trajectory: the error was "File too
    # large" naming no file, the trajectory stayed as .partial with a line cut in half, the other outputs were never
    # closed and no summary.json was written. Now one line names the file and what was kept, the trajectory holds
    # its whole lines under its own name, and summary.json says the run stopped.
    import resource
    import subprocess
    import sys

    simulate(tmp_path / "w", seed=3, duration=30.0)  # 151 scans: a trajectory of about 10 kB
    out = tmp_path / "full"
    limit = 6_000  # bytes: config.yaml (4 kB) and summary.json (2.3 kB) fit, the trajectory does not

    def cap():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    w = tmp_path / "w"
    p = subprocess.run([sys.executable, "-m", "mcl", "run", "--map", str(w / "map.yaml"), "--log",
                        str(w / "log.clf"), "--particles", "300", "--rerun", "off", "--no-progress", "--out",
                        str(out)], preexec_fn=cap, capture_output=True, text=True, timeout=300)
    errors = [ln for ln in p.stderr.splitlines() if ln.startswith("mcl: error:")]
    assert p.returncode == 2 and len(errors) == 1, p.stderr
    assert "cannot write: File too large (stopped after" in errors[0] and str(out) in errors[0]
    assert errors[0].split(": ")[2].endswith((".tum", ".csv"))  # the file named, not a temporary one
    lines = (out / "trajectory.tum").read_text().splitlines()
    assert lines and all(len(ln.split()) == 8 for ln in lines)  # every line whole
    assert not list(out.glob("*.partial"))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["error"].startswith("stopped after ") and "trajectory.tum: cannot write: File too large" in \
        summary["error"], summary
    assert summary["updates"] + summary["predicted_poses"] == len(lines)  # the poses the trajectory kept


def test_a_second_run_into_a_folder_a_run_is_writing_in_is_refused(world, tmp_path, capsys):
    # Two runs into one --out at once deleted each other's recording and left one's config.yaml beside the other's
    # trajectory. The folder is locked while a run writes there (flock on the folder: released if the run dies).
    from mcl.runner import _lock_out_dir

    out = tmp_path / "busy"
    out.mkdir()
    fd = _lock_out_dir(out)
    try:
        assert _run(world, out) == 2
        assert _error_lines(capsys) == [f"mcl: error: --out {out}: another mcl run is writing in this folder now: "
                                        "wait for it to end, or choose another folder"]
        assert list(out.iterdir()) == []
    finally:
        os.close(fd)
    assert _run(world, out) == 0  # free again
    assert (out / "trajectory.tum").exists()


def test_a_likelihood_field_without_random_readings_is_warned_about(world, tmp_path, capsys):
    # z_rand 0 is accepted (tracking holds) but a global search settles wherever no beam misses the map (the demo:
    # 2.9 m off over 1-50 s): said before the run, as the beam model's z_max = z_rand = 0 is
    assert _run(world, tmp_path / "zr0", "--set", "sensor.likelihood_field.z_rand=0") == 0
    err = capsys.readouterr().err
    assert "mcl: warning: sensor.likelihood_field.z_rand is 0: an endpoint 2 m from every wall" in err
    assert "scores 200 nats below one on a wall" in err  # 0.5 (2 / 0.1)^2 with the default sigma_hit 0.1
    assert _run(world, tmp_path / "default") == 0
    assert "z_rand is 0" not in capsys.readouterr().err


def test_the_last_line_says_when_the_filter_believed_it_was_lost(world, tmp_path, capsys):
    # Without a reference nothing in the last line told a run that lost the robot from one that did not (a bag whose
    # laser mounting was missing: lost in 37 of 274 updates, and a clean "Localized ..." line). A global start is
    # lost while it searches: said as such.
    import yaml

    assert _run(world, tmp_path / "g") == 0
    said = capsys.readouterr()
    out = said.out + said.err
    assert "Believed lost in " in out and "a global search the first; quality.csv)" in out, out
    start = yaml.safe_load((world / "sim.yaml").read_text())["start_pose"]
    assert _run(world, tmp_path / "t", "--initial-pose", *map(str, start)) == 0
    said = capsys.readouterr()
    assert "Localized " in said.out + said.err and "Believed lost" not in said.out + said.err


def test_a_recording_cut_short_is_left_under_a_name_the_viewer_opens(world, tmp_path):
    # A file size limit hit by the recording left `recording.rrd.partial`: the viewer picks its importer by the
    # extension and said `No importer support for "recording.rrd.partial"`. Now it is `recording.partial.rrd`, which
    # the viewer loads (the steps up to the cut), and a run again into the folder clears it.
    import resource
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    out = tmp_path / "cut"
    limit = 500_000  # bytes: the trajectory and the other files fit, the recording (about 0.6 MB) does not

    def cap():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    p = subprocess.run([sys.executable, "-m", "mcl", "run", "--map", str(world / "map.yaml"), "--log",
                        str(world / "log.clf"), "--particles", "300", "--rerun", "save", "--no-progress", "--out",
                        str(out)], preexec_fn=cap, capture_output=True, text=True, timeout=300)
    errors = [ln for ln in p.stderr.splitlines() if ln.startswith("mcl: error:")]
    assert p.returncode == 2 and len(errors) == 1, p.stderr
    assert "recording.partial.rrd" in errors[0], errors[0]
    names = sorted(q.name for q in out.iterdir())
    assert "recording.partial.rrd" in names and not [n for n in names if n.endswith(".partial")], names
    viewer = Path(sys.executable).parent / "rerun"
    viewer = str(viewer) if viewer.exists() else shutil.which("rerun")
    if viewer:  # the viewer's importer takes it: re-saved whole, it holds the run's steps up to the cut
        saved = tmp_path / "saved.rrd"
        v = subprocess.run([viewer, "--save", str(saved), str(out / "recording.partial.rrd")], capture_output=True,
                           text=True, timeout=120)
        assert "No importer support" not in v.stderr and saved.is_file() and saved.stat().st_size > 0, v.stderr
    assert _run(world, out) == 0  # an earlier run's cut recording is one of its outputs: replaced, not refused
    assert not (out / "recording.partial.rrd").exists()


def test_the_summary_line_says_a_run_that_never_settled_in_words():
    # "converged within 0.3 m after never" read as a number left out
    from mcl.evaluate import format_eval

    r = dict(ate_rmse=1.2, ate_max=9.0, heading_rmse_deg=3.0, converged_within=0.3, scored=5, unscored=0)
    assert "never within 0.3 m for good (5 reference" in format_eval({**r, "convergence_time": None})
    assert "after never" not in format_eval({**r, "convergence_time": None})
    assert "converged within 0.3 m after 2.0 s (" in format_eval({**r, "convergence_time": 2.0})


def test_the_recordings_particle_count_is_quality_csvs(world, tmp_path):
    # A global run re-seeds on its first update: quality.csv and the summary counted the 5,000 particles weighted,
    # the recording's stats/particles the 10,000 the re-seed had grown the set to. Now both count those weighted.
    import csv

    import pyarrow as pa
    from rerun.chunk import RrdReader

    out = tmp_path / "global"
    assert main(["run", "--map", str(world / "map.yaml"), "--log", str(world / "log.clf"), "--global",
                 "--particles", "2000", "--threads", "1", "--rerun", "save", "--no-progress", "--out", str(out)]) == 0
    with open(out / "quality.csv") as f:
        want = [float(r["particles"]) for r in csv.DictReader(f) if r["updated"] == "1"]
    got = []
    for c in RrdReader(out / "recording.rrd").stream().to_chunks():
        if c.entity_path == "/stats/particles" and not c.is_static:
            b = c.to_record_batch()
            got += list(zip(b.column("step").cast(pa.int64()).to_pylist(),
                            [v[0] for v in b.column("Scalars:scalars").to_pylist()]))
    assert [v for _, v in sorted(got)] == want
    assert len(set(want)) > 1  # the set's size changed in the run, or the test would show nothing


def test_a_reference_off_the_scans_stamps_is_in_the_recording_interpolated(world, tmp_path):
    # A 10 Hz reference 0.05 s off the scans' stamps is scored (by interpolation), but the recording had no truth
    # pose and no error series at any step: it looked truth only up within 1 ms of each scan.
    import numpy as np
    import pyarrow as pa
    from rerun.chunk import RrdReader

    from mcl.trajectory import read_tum, write_tum

    t, poses = read_tum(world / "truth.tum")
    tq = np.arange(t[0] + 0.05, t[-1], 0.1)
    off = np.stack([np.interp(tq, t, poses[0]), np.interp(tq, t, poses[1]), np.interp(tq, t, np.unwrap(poses[2]))])
    write_tum(tmp_path / "off.tum", tq, off)

    def errors(truth, out):
        assert _run(world, out, "--truth", str(truth), "--rerun", "save") == 0
        e = {}
        for c in RrdReader(out / "recording.rrd").stream().to_chunks():
            if c.entity_path == "/stats/error/position" and not c.is_static:
                b = c.to_record_batch()
                e.update(zip(b.column("step").cast(pa.int64()).to_pylist(),
                             [v[0] for v in b.column("Scalars:scalars").to_pylist()]))
        return e

    at_scans, off_scans = errors(world / "truth.tum", tmp_path / "at"), errors(tmp_path / "off.tum", tmp_path / "off")
    # every update inside the reference's span (its first and last may not be), and the same errors as with the
    # reference at the scans (the same run: the reference plays no part in the filter) within the interpolation's
    # few millimetres
    assert len(off_scans) >= len(at_scans) - 2
    assert max(abs(v - at_scans[k]) for k, v in off_scans.items()) < 0.01


def test_a_run_without_out_takes_a_folder_of_its_own_even_when_another_started_in_the_same_second(world, tmp_path):
    # The default folder (runs/<time>) was named before the data loaded and made after: two runs started in the same
    # second both wrote into it, and the later deleted the earlier's outputs (both exited 0, both said "Outputs in"
    # the one folder). The default folder is made new when the outputs begin, or the next name is taken.
    from mcl.config import load_config
    from mcl.runner import run

    taken = tmp_path / "runs" / "20261206-224500"
    taken.mkdir(parents=True)
    (taken / "config.yaml").write_text("the other run's\n")
    cfg = load_config(None, [f"map={world / 'map.yaml'}", f"log={world / 'log.clf'}", "rerun.mode=off",
                             "filter.particles=300", "filter.kld=false"])
    summary = run(cfg, taken, progress=False, echo=lambda *_: None, fresh=True)
    assert (taken / "config.yaml").read_text() == "the other run's\n"
    second = tmp_path / "runs" / "20261206-224500-2"
    assert summary["outputs"]["trajectory"] == str(second / "trajectory.tum") and (second / "trajectory.tum").is_file()


def test_a_temporary_file_of_a_run_killed_while_it_wrote_is_cleared_by_the_next(world, tmp_path, capsys):
    # A run killed inside an atomic write leaves `.summary.json.XXXX.tmp`: every later run into that folder was
    # refused ("holds files that are not a run's outputs"). It is the run's own: the next run clears it. A user's
    # hidden file is still no run's.
    out = tmp_path / "killed"
    assert _run(world, out) == 0
    (out / ".summary.json.k3j9x2.tmp").write_text("{")
    assert _run(world, out, "--seed", "2") == 0
    assert not (out / ".summary.json.k3j9x2.tmp").exists() and json.loads((out / "summary.json").read_text())["seed"] == 2
    (out / ".notes.tmp").write_text("mine")
    assert _run(world, out) == 2
    assert "holds files that are not a run's outputs (.notes.tmp)" in _error_lines(capsys)[0]

