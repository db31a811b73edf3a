"""``mcl tune``: the space file, a tiny study that finds a planted optimum, the same trials whatever --jobs,
on Ray, and after a resume (--trials k then --resume; a real SIGINT), held-out datasets, several objectives.

The tiny world: mcl.simulate office, 15 s, range noise sigma 0.1 m and noisy odometry; the filter tracks it
with 300 particles (no KLD) from a base config whose sigma_hit is 2.0 m, twenty times the simulator's noise.
Swept once (seed 1): sigma_hit 0.01 -> RMSE 0.13 m, 0.036 -> 0.073, 0.14 -> 0.067, 0.24 -> 0.079, 2.0 -> 0.11.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from mcl.cli import main
from mcl.config import load_config
from mcl.errors import ConfigError, MclError
from mcl.tune import LOST_PENALTY, load_space, objective_values

RANGE_SIGMA = 0.1
SUITE = {
    "name": "tiny",
    "modes": ["tracking"],
    "datasets": [
        {"name": "office", "simulate": {"kind": "office", "seed": 3, "duration": 15, "range_sigma": RANGE_SIGMA,
                                        "odom_alphas": [0.2, 0.2, 0.2, 0.1]}},
        {"name": "office-held", "held_out": True,
         "simulate": {"kind": "office", "seed": 4, "duration": 10, "range_sigma": RANGE_SIGMA}},
    ],
}
# interior: zero, AMCL's field, pinned: with the default depth field the RMSE of this short log is flat from
# sigma_hit 0.014 to 0.2 m (0.036 -> 0.0671, 0.138 -> 0.0672), so which of the two wins says nothing of the tuner
# the plain likelihood field: AMCL's field, and every beam scored (with sensor.unmapped_skip the lone short readings
# the simulator plants are not scored while tracking, and a sigma_hit of 0.036 m, a third of the noise, won)
BASE = {"filter": {"particles": 300, "kld": False},
        "sensor": {"likelihood_field": {"sigma_hit": 2.0, "interior": "zero"}, "unmapped_skip": False}}
SPACE = {"sensor.likelihood_field.sigma_hit": {"low": 0.005, "high": 3.0, "log": True}}
TRIALS = 8


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("tune")
    (d / "suite.yaml").write_text(yaml.safe_dump(SUITE))
    (d / "base.yaml").write_text(yaml.safe_dump(BASE))
    (d / "space.yaml").write_text(yaml.safe_dump(SPACE))
    return d


def _args(files: Path, study: Path, *extra) -> list[str]:
    return ["tune", str(files / "suite.yaml"), "--space", str(files / "space.yaml"), "--config",
            str(files / "base.yaml"), "--study", str(study), "--cache", str(files / "worlds"), "--seed", "1",
            "--no-progress", *extra]


def _trials(study: Path) -> list[dict]:
    with open(study / "trials.csv") as f:
        return list(csv.DictReader(f))


def _same_trials(a: Path, b: Path) -> None:
    """Same sampled values and the same scores, trial by trial (the runs are deterministic for a seed)."""
    ta, tb = _trials(a), _trials(b)
    assert [(r["number"], r["state"], r["sensor.likelihood_field.sigma_hit"]) for r in ta] == \
           [(r["number"], r["state"], r["sensor.likelihood_field.sigma_hit"]) for r in tb]
    assert [float(r["value_rmse"]) for r in ta] == pytest.approx([float(r["value_rmse"]) for r in tb], rel=1e-9)


@pytest.fixture(scope="module")
def serial(files):
    """The reference study: --jobs 1, 8 trials, seed 1."""
    study = files / "serial"
    assert main(_args(files, study, "--trials", str(TRIALS), "--jobs", "1")) == 0
    return study


# ----------------------------------------------------------------------------- the space file


BAD_SPACES = [
    ({"sensor.likelihood_field.sigma_hti": {"low": 0.05, "high": 0.5}}, ["sensor.likelihood_field.sigma_hti", "unknown key", "did you mean sensor.likelihood_field.sigma_hit"]),
    ({"sensor": {"likelihood_field": {"sigma_hti": {"low": 0.05, "high": 0.5}}}}, ["sensor.likelihood_field.sigma_hti", "did you mean sensor.likelihood_field.sigma_hit"]),
    ({"sensor.likelihood_field.sigma_hit": {"low": -0.1, "high": 0.5}}, ["sensor.likelihood_field.sigma_hit", "low", "out of range"]),
    ({"sensor.likelihood_field.z_hit": {"low": 0.5, "high": 1.5}}, ["sensor.likelihood_field.z_hit", "high", "out of range"]),
    ({"sensor.likelihood_field.sigma_hit": {"low": 0.5, "high": 0.1}}, ["sensor.likelihood_field.sigma_hit", "must be below high"]),
    ({"motion.alpha1": {"low": 0.0, "high": 0.5, "log": True}}, ["motion.alpha1", "log", "low > 0"]),
    ({"sensor.likelihood_field.sigma_hit": {"low": 0.05, "hihg": 0.5}}, ["sensor.likelihood_field.sigma_hit.hihg", "did you mean high"]),
    ({"sensor.likelihood_field.sigma_hit": {"lo": 0.05, "high": 0.5}}, ["sensor.likelihood_field.sigma_hit.lo", "did you mean low"]),
    ({"sensor": {"likelihood_field": {"sigma_hit": 0.1}}}, ["sensor.likelihood_field.sigma_hit", "expected {low"]),
    ({"filter.particles": {"choices": [1000, "many"]}}, ["filter.particles", "choices[1]", "integer"]),
    ({"filter.particles": {"low": 100.5, "high": 1000}}, ["filter.particles", "low", "integer"]),
    ({"filter.resampling": {"choices": ["systematic", "sistematic"]}}, ["filter.resampling", "choices[1]",
                                                                         "did you mean systematic"]),
    ({"sensor.model": {"low": 0, "high": 1}}, ["sensor.model", "not a number", "choices"]),
    ({"map": {"choices": ["a.yaml"]}}, ["map", "not tunable"]),
    ({"filter.initial_std": {"low": 0.1, "high": 0.2}}, ["filter.initial_std", "not a number"]),
    ({"filter": {"particles": {"choices": [1000]}}, "filter.particles": {"choices": [2000]}},
     ["filter.particles", "given twice"]),  # nested and dotted: the last one once won silently
    # an int step that does not divide the range: optuna shrank it to [30, 30] with a warning, the key never tuned
    ({"sensor.max_beams": {"low": 30, "high": 40, "step": 100}}, ["sensor.max_beams", "step", "not a multiple of 100"]),
]


@pytest.mark.parametrize("space, words", BAD_SPACES, ids=[next(iter(s)) + "-" + w[-1] for s, w in BAD_SPACES])
def test_space_errors_exit_2_naming_the_key(files, tmp_path, capsys, space, words):
    path = tmp_path / "space.yaml"
    path.write_text(yaml.safe_dump(space))
    study = tmp_path / "study"
    rc = main(["tune", str(files / "suite.yaml"), "--space", str(path), "--study", str(study), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert err.count("\n") == 0 and str(path) in err, err
    for w in words:
        assert w in err, err
    assert not study.exists()  # nothing half-written


def test_a_key_a_dataset_sets_is_not_tunable_on_that_suite(files, tmp_path, capsys):
    # A dataset's set: gave sigma_hit 0.3; a study tuning sigma_hit replaced it in every trial without a word (and
    # trial 0, "the base config", was not what mcl eval --suite runs)
    suite = dict(SUITE, datasets=[dict(SUITE["datasets"][0], set={"sensor.likelihood_field.sigma_hit": 0.3})])
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(suite))
    study = tmp_path / "study"
    rc = main(["tune", str(tmp_path / "s.yaml"), "--space", str(files / "space.yaml"), "--study", str(study),
               "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.count("\n") == 0, err
    assert "sensor.likelihood_field.sigma_hit: not tunable on" in err and "its dataset office sets it (set:)" in err
    assert not study.exists()


def test_space_file_forms():
    """Dotted and nested keys alike; a float range, an int range with a step, choices."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s.yaml"
        p.write_text(yaml.safe_dump({"sensor": {"likelihood_field": {"sigma_hit": {"low": 0.05, "high": 0.5, "log": True}}},
                                     "filter.particles": {"choices": [1000, 2000]},
                                     "sensor.max_beams": {"low": 30, "high": 90, "step": 30},
                                     "filter.recovery": {"choices": [False, "lost"]}}))
        ps = {q.key: q for q in load_space(p)}
    assert ps["sensor.likelihood_field.sigma_hit"].kind == "float" and ps["sensor.likelihood_field.sigma_hit"].log
    assert ps["filter.particles"].choices == (1000, 2000)
    assert ps["sensor.max_beams"].kind == "int" and ps["sensor.max_beams"].step == 30
    assert ps["filter.recovery"].choices == (False, "lost")
    assert ps["sensor.max_beams"].contains(60) and not ps["sensor.max_beams"].contains(45)
    from mcl.config import PROJECT_ROOT

    space = {q.key: q for q in load_space(PROJECT_ROOT / "suites" / "tune-space.yaml")}  # the README's example checks
    assert len(space) == 7 and space["sensor.likelihood_field.surface"].choices == ("centre", "face")


def test_bad_objective_held_out_and_missing_ray(files, tmp_path, capsys, monkeypatch):
    assert main(_args(files, tmp_path / "a", "--objective", "rmse,partcles")) == 2
    assert "did you mean particles" in capsys.readouterr().err
    assert main(_args(files, tmp_path / "a", "--held-out", "ofice")) == 2
    assert "--held-out: no dataset 'ofice'" in capsys.readouterr().err
    assert main(_args(files, tmp_path / "a", "--held-out", "office")) == 2  # both held out: nothing to tune on
    assert "nothing left to tune on" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    assert main(_args(files, tmp_path / "b", "--trials", "1", "--ray", "auto")) == 2
    err = capsys.readouterr().err
    assert "--ray" in err and "pip install 'mcl[cluster]'" in err and err.count("\n") == 1
    # no empty study is left behind (the same command, without --ray, was then refused: "a study is there")
    assert not (tmp_path / "b").exists()


def test_lost_runs_are_penalised_not_dropped():
    def row(ds, rmse, lost, seed=1):
        return {"dataset": ds, "mode": "tracking", "seed": seed, "rmse": rmse, "lost": lost, "lost_m": 1.0,
                "conv_s": 0.0, "particles": 300.0, "wall_s": 1.0}

    ok = objective_values([row("a", 0.1, False), row("b", 0.3, False)])
    assert ok["rmse"] == pytest.approx(0.2) and ok["lost_runs"] == 0
    lost = objective_values([row("a", 0.1, False), row("b", 0.4, True)])
    assert lost["rmse"] == pytest.approx((0.1 + LOST_PENALTY) / 2) and lost["lost_runs"] == 1
    failed = objective_values([row("a", 0.1, False), {"dataset": "b", "mode": "tracking", "seed": 1, "error": "x"}])
    assert failed["rmse"] == pytest.approx(lost["rmse"]) and failed["lost"] > 0.5
    # no particle count or wall time for b, whose every run failed: None (empty in trials.csv), not inf
    assert failed["particles"] is None and failed["wall"] is None
    assert failed["errors"] == ["b/tracking/seed1: x"] and failed["failed_runs"] == 1


# ----------------------------------------------------------------------------- studies


def test_tiny_study_finds_the_planted_sigma(serial, files):
    """The best sigma_hit lies within a factor 2.5 of the simulator's range noise (0.1 m), and beats the base
    config's 2.0 m (trial 0, the base values) by at least 20 % (the sweep in the module doc: 0.067 vs 0.11).
    Factor 2.5, not 2: the RMSE is flat between 0.1 and 0.25 m on a 15 s log (with the corpus-chosen defaults the
    best of 8 trials was 0.239 m), while the base's 2.0 m is 20 times off."""
    rows = _trials(serial)
    assert len(rows) == TRIALS and all(r["state"] == "complete" for r in rows)
    assert float(rows[0]["sensor.likelihood_field.sigma_hit"]) == 2.0
    best = min(rows, key=lambda r: float(r["value_rmse"]))
    sigma = float(best["sensor.likelihood_field.sigma_hit"])
    assert RANGE_SIGMA / 2.5 <= sigma <= RANGE_SIGMA * 2.5, rows
    assert float(best["value_rmse"]) < 0.8 * float(rows[0]["value_rmse"])
    cfg = load_config(serial / "best.yaml")  # a full config mcl run takes
    assert cfg.sensor.likelihood_field.sigma_hit == pytest.approx(sigma) and cfg.filter.particles == 300
    assert (serial / "plots" / "history.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the held-out dataset: never run while tuning, scored at the end for the best and the base config
    assert not list((serial / "trials").glob("*/runs/office-held"))
    ho = json.loads((serial / "heldout" / "heldout.json").read_text())
    assert ho["datasets"] == ["office-held"] and ho["trial"] == int(best["number"])
    assert ho["best"]["runs"] == 1 and ho["base"]["runs"] == 1
    summary = (serial / "summary.txt").read_text()
    assert "Held out (office-held" in summary and f"trial {best['number']}" in summary


def test_jobs_2_gives_the_same_trials(serial, files):
    study = files / "jobs2"
    assert main(_args(files, study, "--trials", str(TRIALS), "--jobs", "2")) == 0
    _same_trials(serial, study)
    assert (study / "best.yaml").read_text().split("\n", 1)[1] == (serial / "best.yaml").read_text().split("\n", 1)[1]


def test_resume_after_k_trials_reaches_the_same_best(serial, files, capsys):
    """--trials 3 (not a whole batch of 4: trial 3 is asked and waits, queued), then --resume up to 8."""
    study = files / "resumed"
    assert main(_args(files, study, "--trials", "3", "--jobs", "1")) == 0
    rows = _trials(study)
    assert [r["state"] for r in rows] == ["complete"] * 3 + ["queued"]
    assert main(["tune", "--resume", str(study), "--trials", str(TRIALS), "--jobs", "1", "--no-progress"]) == 0
    _same_trials(serial, study)
    assert main(["tune", "--report", str(study), "--jobs", "1", "--no-progress"]) == 0
    assert "trial" in capsys.readouterr().out
    # a new study in a study folder is refused
    assert main(_args(files, study, "--trials", "1")) == 2
    # a setting of the study given again with --resume is refused in one line (--objective, --batch, --seeds and
    # --seed were ignored without a word: they had defaults, so giving them could not be told apart)
    capsys.readouterr()
    for option in (["--objective", "lost"], ["--batch", "2"], ["--seeds", "2"], ["--seed", "3"]):
        assert main(["tune", "--resume", str(study), *option, "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert f"the study's settings are in {study}/study.json; not with {option[0]}" in err, err


def test_a_negative_seed_is_refused_before_the_study_is_made(files, tmp_path, capsys):
    # --seed -1 crashed in the sampler after study.json was written, and --resume crashed the same way for good
    study = tmp_path / "neg"
    assert main(_args(files, study, "--seed", "-1")) == 2
    assert "--seed: expected >= 0, got -1" in capsys.readouterr().err
    assert not study.exists()


def test_a_journal_cut_short_resumes_and_a_corrupt_one_is_one_line(files, capsys):
    # A full disk cut the journal's last record; --resume appended onto the cut line and crashed (JSONDecodeError),
    # and --resume and --report failed for good. Now the cut record is dropped with a warning and the study goes on;
    # a record that is not JSON elsewhere is one error naming the line.
    study = files / "cut"
    assert main(_args(files, study, "--trials", "3", "--jobs", "1")) == 0
    journal = study / "journal.log"
    lines = journal.read_bytes().splitlines(keepends=True)
    journal.write_bytes(b"".join(lines[:-1]) + lines[-1][: len(lines[-1]) // 2])
    capsys.readouterr()
    assert main(["tune", "--resume", str(study), "--trials", "4", "--jobs", "1", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert f"{journal}: its last record was cut short" in err, err
    assert journal.read_bytes().endswith(b"\n")
    assert sum(r["state"] == "complete" for r in _trials(study)) == 4
    good = journal.read_bytes().splitlines(keepends=True)
    journal.write_bytes(b"".join(good[:2]) + b"{not json\n" + b"".join(good[2:]))
    assert main(["tune", "--report", str(study), "--no-progress"]) == 2
    assert f"mcl: error: {journal}:3: not a journal record (JSON)" in capsys.readouterr().err
    # its advice taken (the file moved away, or emptied): one line, not optuna's KeyError
    for emptied in (True, False):
        journal.write_bytes(b"") if emptied else journal.unlink()
        assert main(["tune", "--resume", str(study), "--no-progress"]) == 2
        assert f"mcl: error: {journal}: holds no study (empty or removed)" in capsys.readouterr().err
    assert not journal.exists()  # not made again, empty


@pytest.mark.parametrize("sig, jobs", [("SIGINT", "1"), ("SIGTERM", "2")])
def test_sigint_then_resume_reaches_the_same_best(serial, files, sig, jobs):
    """A real Ctrl-C to `python -m mcl tune` once two runs are written: exit 130 with the finished trials kept
    (told in order as they finish); --resume evaluates the rest of the cut batch first and ends with the trials
    of the uninterrupted study. SIGTERM (kill, timeout, a batch scheduler) to the tuning process alone, with its
    runs in two workers, does the same (it used to end the process at once, exit -15, the workers orphaned)."""
    study = files / sig.lower()
    cmd = [sys.executable, "-m", "mcl", *_args(files, study, "--trials", str(TRIALS), "--jobs", jobs)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "NUMBA_NUM_THREADS": "1"})
    deadline = time.monotonic() + 120
    while len(list(study.glob("trials/*/runs/*/*/*/*/row.json"))) < 2:
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    proc.send_signal(getattr(signal, sig))
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, (out, err)
    assert "interrupted after" in out
    k = int(out.split("interrupted after ")[1].split()[0])
    # cut inside the study: some trials kept, some left for --resume (with two workers the two runs' trials may
    # not be told yet when the signal lands: their rows are read back by --resume, checked below)
    assert (1 if jobs == "1" else 0) <= k < TRIALS
    assert sum(r["state"] == "complete" for r in _trials(study)) == k
    done = {p: p.stat().st_mtime_ns for p in study.glob("trials/*/runs/*/*/*/*/row.json")}
    assert main(["tune", "--resume", str(study), "--jobs", "1", "--no-progress"]) == 0
    _same_trials(serial, study)
    assert {p: p.stat().st_mtime_ns for p in done} == done  # the finished runs were not run again


def test_a_failed_run_says_why_and_resume_refuses_a_changed_suite(files, tmp_path, capsys):
    """--seeds A-B as mcl eval takes it. A run that fails (a log that is no log) counts as lost and trials.csv's
    error column says why (particles and wall empty: no figure for that dataset; they were inf). --resume refuses
    a study whose suite file or base config changed since it began (the trials were scored on the old ones)."""
    from mcl.config import PROJECT_ROOT

    demo = PROJECT_ROOT / "data" / "demo"
    doc = {**SUITE, "datasets": SUITE["datasets"][:1] + [
        {"name": "nolog", "map": str(demo / "map.yaml"), "log": str(demo / "map.yaml"), "truth": str(demo / "truth.tum")}]}
    suite, base, study = tmp_path / "suite.yaml", tmp_path / "base.yaml", tmp_path / "study"
    suite.write_text(yaml.safe_dump(doc))
    base.write_text(yaml.safe_dump(BASE))
    args = ["tune", str(suite), "--space", str(files / "space.yaml"), "--config", str(base), "--study", str(study),
            "--cache", str(files / "worlds"), "--trials", "1", "--batch", "1", "--jobs", "1", "--no-progress"]
    assert main(args + ["--seeds", "0"]) == 2
    assert capsys.readouterr().err.startswith("mcl: error: --seeds 0: ")
    assert main(args + ["--seeds", "2-2"]) == 0
    assert "trial 0: 1 run(s) failed: nolog/tracking/seed2: " in capsys.readouterr().err
    (row,) = _trials(study)
    assert (row["state"], row["lost_runs"], row["failed_runs"], row["runs"]) == ("complete", "1", "1", "2")
    assert row["error"].startswith("1 run(s) failed: nolog/tracking/seed2: ") and "no laser messages" in row["error"]
    assert row["particles"] == row["wall"] == ""
    assert [p.name for p in study.glob("trials/*/runs/office/tracking/*/*")] == ["seed2"]
    resume = ["tune", "--resume", str(study), "--trials", "2", "--jobs", "1", "--no-progress"]
    suite.write_text(yaml.safe_dump(SUITE))  # nolog dropped, office-held added
    assert main(resume) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"the suite file {suite} changed since the study began" in err
    suite.write_text(yaml.safe_dump(doc))
    base.write_text(yaml.safe_dump({**BASE, "filter": {"particles": 200, "kld": False}}))
    assert main(resume) == 2
    assert f"the base config {base} changed since the study began" in capsys.readouterr().err
    assert json.loads((study / "study.json").read_text())["trials"] == 1  # nothing written
    assert len(_trials(study)) == 1
    # --report writes what the trials measured: it goes on, and says that the base config changed
    assert main(["tune", "--report", str(study)]) == 0
    err = capsys.readouterr().err
    assert f"mcl: warning: --report {study}: the base config {base} changed since the study began" in err, err


# The study runs in a child process: when Ray's own daemons die (the raylet, the GCS), Ray ends its driver with
# _exit(1), which in this process would end the whole test session with no report (seen once in CI, never here).
_RAY_CHILD = """
import sys, ray
from mcl.cli import main
ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
try:
    rc = main(sys.argv[1:])
finally:
    ray.shutdown()
print("main returned", rc, flush=True)
sys.exit(rc)
"""


def _ray_study(files: Path, study: Path) -> tuple[int | None, str, str]:
    """(exit code, None after a timeout; stdout; stderr) of the child running the study on Ray. The child has a
    session of its own, so a timeout ends Ray's daemons with it."""
    child = subprocess.Popen([sys.executable, "-c", _RAY_CHILD, *_args(files, study, "--trials", str(TRIALS),
                                                                     "--ray", "auto")],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = child.communicate(timeout=120)  # about 10 s here
        return child.returncode, out, err
    except subprocess.TimeoutExpired:
        os.killpg(child.pid, signal.SIGKILL)
        out, err = child.communicate()
        return None, out, err


RAY_ATTEMPTS = 3  # a child that Ray itself ended is run again, at most this many times in all


def test_ray_gives_the_same_trials(serial, files):
    """The study on a local Ray cluster gives the serial study's trials. A child that Ray itself ended (no
    traceback, main never returned) or whose Ray never started within the timeout is run again, up to
    RAY_ATTEMPTS in all: once, CI saw Ray's daemons die and Ray end its driver with _exit(1). Anything else fails
    at once: a nonzero return of mcl tune, a Python traceback, a study that hangs after Ray started, different
    trials; and so does Ray failing on every attempt."""
    pytest.importorskip("ray", reason="Ray is not installed (pip install 'mcl[cluster]')")
    for attempt in range(1, RAY_ATTEMPTS + 1):
        study = files / f"ray{attempt}"
        code, out, err = _ray_study(files, study)
        returned = "main returned" in out
        if returned or "Traceback (most recent call last)" in err or (code is None and "Started a local Ray" in err):
            break
    tail = "\n".join((out + err).splitlines()[-15:])
    assert code == 0 and returned, f"attempt {attempt} of {RAY_ATTEMPTS}, exit {code}:\n{tail}"
    _same_trials(serial, study)


def test_two_objectives_give_a_pareto_front(files, tmp_path):
    """rmse against particles: pareto.csv holds exactly the trials no other complete trial dominates."""
    space = tmp_path / "space.yaml"
    space.write_text(yaml.safe_dump({**SPACE, "filter.particles": {"choices": [50, 300]}}))
    study = tmp_path / "pareto"
    args = _args(files, study, "--trials", "8", "--jobs", "1", "--objective", "rmse,particles")
    args[args.index("--space") + 1] = str(space)
    assert main(args) == 0
    rows = [r for r in _trials(study) if r["state"] == "complete"]
    pts = {int(r["number"]): (float(r["value_rmse"]), float(r["value_particles"])) for r in rows}
    assert {v[1] for v in pts.values()} == {50.0, 300.0}

    def dominated(a):
        return any(b[0] <= a[0] and b[1] <= a[1] and b != a for b in pts.values())

    with open(study / "pareto.csv") as f:
        front = {int(r["number"]) for r in csv.DictReader(f)}
    assert front == {n for n, v in pts.items() if not dominated(v)}
    assert (study / "plots" / "pareto.png").is_file() and (study / "plots" / "importances.png").is_file()


def test_suite_held_out_key(tmp_path):
    from mcl.errors import ConfigError
    from mcl.suite import load_suite

    doc = {"datasets": [{"name": "a", "simulate": {"duration": 5}, "held_out": True},
                        {"name": "b", "simulate": {"duration": 5}}]}
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump(doc))
    assert [d.held_out for d in load_suite(p).datasets] == [True, False]
    doc["datasets"][1]["held_out"] = "yes"
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=r"datasets\[1\] \(b\): held_out: expected true or false"):
        load_suite(p)


def test_a_study_whose_every_trial_fails_exits_2(files, tmp_path, capsys):
    # Every trial failing (here every run: the one dataset's log is no log) exited 0 with "No trial finished yet"
    # or a best.yaml scored on the penalty alone. The outputs are written (trials.csv says why), then one error line.
    from mcl.config import PROJECT_ROOT

    demo = PROJECT_ROOT / "data" / "demo"
    suite = tmp_path / "suite.yaml"
    suite.write_text(yaml.safe_dump({**SUITE, "datasets": [
        {"name": "nolog", "map": str(demo / "map.yaml"), "log": str(demo / "map.yaml"), "truth": str(demo / "truth.tum")}]}))
    study = tmp_path / "study"
    assert main(["tune", str(suite), "--space", str(files / "space.yaml"), "--config", str(files / "base.yaml"),
                 "--study", str(study), "--trials", "1", "--batch", "1", "--jobs", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == f"mcl: error: --study {study}: every trial failed (trials.csv's error column says why)"
    (row,) = _trials(study)
    assert row["failed_runs"] == row["runs"] == "1" and "no laser messages" in row["error"]


def test_a_study_folder_is_checked_before_anything_is_written(files, tmp_path, capsys):
    # --study over a user's own best.yaml replaced it without a word (mcl eval --out refuses such a folder); a
    # journal.log left without its study.json took the new study's trials beside the old ones'. One line each.
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "best.yaml").write_text("seed: 7\n")
    assert main(_args(files, mine, "--trials", "1")) == 2
    assert f"--study {mine}: holds best.yaml of no study" in capsys.readouterr().err
    assert (mine / "best.yaml").read_text() == "seed: 7\n" and sorted(p.name for p in mine.iterdir()) == ["best.yaml"]
    half = tmp_path / "half"
    half.mkdir()
    (half / "journal.log").write_text("")
    assert main(_args(files, half, "--trials", "1")) == 2
    assert f"--study {half}: holds a journal.log without its study.json" in capsys.readouterr().err
    assert sorted(p.name for p in half.iterdir()) == ["journal.log"]


def test_only_and_held_out_take_patterns_and_an_unreachable_ray_head_is_one_line(files, tmp_path, capsys):
    from mcl.tune import Settings, Tuner, _reachable

    def settings(**kw):
        return Settings(suite=str(files / "suite.yaml"), space=[], config=None, sets=[], objectives=["rmse"], seeds=1,
                        modes=None, batch=1, seed=0, trials=1, cache=str(files / "worlds"), **kw)

    t = Tuner(tmp_path / "t", settings(only=["off*"], held_out=["*-held"]))
    assert t.tuning == ["office"] and t.held_out == ["office-held"]
    with pytest.raises(ConfigError, match=r"--only: no dataset 'hall\*'"):
        Tuner(tmp_path / "t", settings(only=["hall*"]))
    # nothing listens on port 1: ray.init retried for 14 minutes; now one line within RAY_CONNECT_S
    with pytest.raises(MclError, match="--ray 127.0.0.1:1: cannot connect: nothing answers there"):
        _reachable("127.0.0.1:1")
    _reachable("ray://127.0.0.1:1")  # Ray's client protocol and auto go to Ray as before
    _reachable("auto")


def test_a_ctrl_c_while_the_outputs_are_written_says_so(files, tmp_path, capsys, monkeypatch):
    # Ctrl-C during the held-out runs or the plots (after the last trial) printed "mcl: interrupted" alone, with no
    # summary.txt and sometimes no best.yaml. It now says the outputs were cut and how to write them: --report.
    import mcl.tune

    real = mcl.tune.write_outputs
    calls = []

    def cut(*a, **kw):
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return real(*a, **kw)

    monkeypatch.setattr(mcl.tune, "write_outputs", cut)
    study = tmp_path / "study"
    assert main(_args(files, study, "--trials", "1", "--batch", "1", "--jobs", "1")) == 130
    out = capsys.readouterr().out
    assert f"interrupted while writing the study's outputs (held-out runs, best.yaml, summary.txt): mcl tune --report {study} writes them again" in out
    assert not (study / "summary.txt").exists()
    assert main(["tune", "--report", str(study)]) == 0
    assert (study / "summary.txt").is_file() and (study / "best.yaml").is_file()


def test_two_resumes_of_one_study_at_once_are_refused(serial, files, tmp_path, capsys):
    # Two `--resume` of one study at once told the same trials twice: one crashed with a traceback, the other
    # recorded a trial scored on the first's locked run folders. The study folder is locked while a study runs.
    import shutil

    from mcl.runner import lock_folder

    study = tmp_path / "study"
    shutil.copytree(serial, study)
    before = (study / "journal.log").read_bytes(), (study / "study.json").read_bytes()
    fd = lock_folder(study, "held")
    try:
        assert main(["tune", "--resume", str(study), "--trials", str(TRIALS + 1), "--jobs", "1", "--no-progress"]) == 2
    finally:
        os.close(fd)
    assert capsys.readouterr().err.strip().splitlines() == [
        f"mcl: error: --study {study}: another mcl tune is working on this study now: wait for it to end (two at "
        "once told the same trials twice)"]
    assert ((study / "journal.log").read_bytes(), (study / "study.json").read_bytes()) == before  # nothing written


def test_objective_names_are_read_in_any_case():
    # `--objective RMSE` was "unknown objective 'RMSE'" with no hint (difflib is case-sensitive)
    from mcl.tune import parse_objectives

    assert parse_objectives("RMSE, Particles") == ["rmse", "particles"]
    with pytest.raises(MclError, match="names an objective twice"):
        parse_objectives("rmse,RMSE")
