"""Tuning a config over a suite: ``mcl tune SUITE.yaml --space space.yaml``.

A *trial* is a config (the base config with the space's keys set to sampled values) evaluated over the
suite's datasets, modes and seeds with :mod:`mcl.suite`'s plan and runs (``plan``, ``run_job``), and scored
from their rows (:func:`objective_values`). Optuna proposes the values: TPE (Bergstra et al. 2011) for one
objective, its multi-objective form for several (``--objective rmse,particles``: a Pareto front).

Determinism. Trials are asked in batches of ``batch`` (a setting of the study, not of ``--jobs``); every run
of a batch is evaluated in parallel (worker processes or Ray tasks) and the trials are told in order, each as
soon as it and those before it are done (the next batch is asked once the whole batch is told). The
sampler of each batch is seeded from (``--seed``, the number of trials asked before it), and every run has a
fixed seed (1..``seeds``), so a study's trials are the same whatever ``--jobs``, with or without Ray, and
whether it was stopped and resumed: the trials of a batch cut by Ctrl-C stay in the journal as running, and
``--resume`` evaluates them first (their finished runs are not run again: ``row.json`` with the config's
fingerprint, as ``mcl eval --suite``). The last batch is always asked whole; trials past ``--trials`` wait
in the journal for a resume with more trials.

Scoring. A run that loses track (``mcl.suite.score``: tracking error above the dataset's ``lost_m``; global
or kidnapped: not converged within ``WITHIN_S``) or fails counts ``LOST_PENALTY`` x ``lost_m`` as its RMSE,
more than any run that kept track: it is penalised, not dropped. Per dataset x mode the median over seeds,
then the mean over the datasets x modes (see :data:`OBJECTIVES`).

Study folder: ``study.json`` (the settings, and the suite's and base config's :func:`fingerprint`: --resume
refuses a changed one), ``journal.log`` (Optuna's JournalStorage: every ask and tell), ``trials/NNNNN/runs/...``
(each trial's runs), ``worlds/`` (synthetic worlds), ``trials.csv``, ``best.yaml``, ``plots/`` (history,
importances, Pareto front), ``heldout/`` and ``summary.txt``.
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import fnmatch
import io
import json
import math
import os
import signal
import statistics
import sys
import typing
import warnings
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

from mcl.errors import ConfigError, MclError
from mcl.suite import PER_RUN_KEYS

LOST_PENALTY = 3.0  # a lost run's RMSE counts this many times its dataset's lost_m
NEVER_S = 60.0  # s: the convergence time of a run that never converged (twice mcl.suite.WITHIN_S)
OBJECTIVES = {
    "rmse": "mean over datasets x modes of the median over seeds of the RMSE (m); a lost run counts "
            f"{LOST_PENALTY:g} x lost_m",
    "lost": "fraction of runs lost (ties broken by 0.001 x rmse)",
    "convergence": f"mean convergence time (s; never converged: {NEVER_S:g} s)",
    "weighted": "rmse + lost + convergence / 30 s",
    "particles": "mean particle count (KLD sampling draws fewer where it can)",
    "wall": "median wall time of a run (s); not reproducible: the Pareto front differs between runs",
}
SPEC_KEYS = ("low", "high", "log", "step", "choices")
# keys the suite sets per dataset, or that do not change the filter
FIXED = PER_RUN_KEYS + ("laser", "landmarks.map", "planes.depth", "planes.map")  # (a dataset's own, or a run's)
NOT_TUNED_SECTIONS = ("rerun", "topics", "frames", "eval")
STUDY_NAME = "mcl-tune"
STATE_FILE = "study.json"


# ----------------------------------------------------------------------------- the search space


@dataclass(frozen=True)
class Param:
    """One tuned key: a float or int range (``log`` scale, ``step``) or a list of ``choices``."""

    key: str
    kind: str  # float, int, categorical
    low: float | int | None = None
    high: float | int | None = None
    log: bool = False
    step: float | int | None = None
    choices: tuple | None = None

    def distribution(self):
        from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

        if self.kind == "categorical":
            return CategoricalDistribution(list(self.choices))
        if self.kind == "int":
            return IntDistribution(self.low, self.high, log=self.log, step=self.step or 1)
        return FloatDistribution(self.low, self.high, log=self.log, step=self.step)

    def contains(self, value) -> bool:
        if self.kind == "categorical":
            return any(type(value) is type(c) and value == c for c in self.choices)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not self.low <= value <= self.high:
            return False
        return self.step is None or math.isclose((value - self.low) / self.step, round((value - self.low) / self.step))

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("low", "high", "log", "step") if getattr(self, k) not in (None, False)}
        if self.choices is not None:
            d = {"choices": list(self.choices)}
        return d


def _leaf_keys(cls, prefix: str = "") -> dict[str, tuple]:
    """Every dotted leaf key of the config schema -> (type annotation, field metadata)."""
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp):
            out.update(_leaf_keys(tp, f"{prefix}{f.name}."))
        else:
            out[f"{prefix}{f.name}"] = (tp, f.metadata)
    return out


def _flatten(doc: dict, path: Path, prefix: str = "", out: dict | None = None) -> dict[str, dict]:
    """``{sensor: {likelihood_field: {sigma_hit: {...}}}}`` and ``{sensor.likelihood_field.sigma_hit: {...}}`` alike
    -> {dotted key: spec}; ConfigError for a key given both ways."""
    out = {} if out is None else out
    for k, v in doc.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and v and not any(s in v for s in SPEC_KEYS):  # a section
            _flatten(v, path, key + ".", out)
        elif key in out:
            raise ConfigError(f"{path}: {key}: given twice (nested under its section and dotted)")
        else:
            out[key] = v
    return out


def _number(v, where: str, integer: bool):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(f"{where}: expected {'an integer' if integer else 'a number'}, got {v!r}")
    if integer and not float(v).is_integer():
        raise ConfigError(f"{where}: expected an integer, got {v!r}")
    return int(v) if integer else float(v)


def load_space(path: str | os.PathLike) -> list[Param]:
    """Read and check a space file against the config schema (mcl.config): every key a known, tunable key,
    every bound and choice a value the key accepts. ConfigError naming the file and the key."""
    from mcl.config import Config, _check_range, _coerce
    from mcl.yamlfile import read_yaml

    path = Path(path)
    doc = read_yaml(path, ConfigError)
    if not isinstance(doc, dict) or not doc:
        raise ConfigError(f"{path}: expected a mapping of config keys, e.g. sensor.likelihood_field.sigma_hit: {{low: 0.05, high: 0.5}}")
    schema = _leaf_keys(Config)
    params = []
    for key, spec in _flatten(doc, path).items():
        where = f"{path}: {key}"
        parent, _, last = key.rpartition(".")
        if key not in schema and parent in schema:  # sensor.likelihood_field.sigma_hit: {lo: ..}: a misspelt spec key
            hint = difflib.get_close_matches(last, SPEC_KEYS, n=1)
            raise ConfigError(f"{path}: {key}: unknown key" + (f" (did you mean {hint[0]}?)" if hint else ""))
        if key not in schema:
            hint = difflib.get_close_matches(key, list(schema), n=1)
            raise ConfigError(f"{where}: unknown key" + (f" (did you mean {hint[0]}?)" if hint else ""))
        if key in FIXED or key.split(".")[0] in NOT_TUNED_SECTIONS:
            raise ConfigError(f"{where}: not tunable (the suite sets it per dataset, or it does not change the filter)")
        tp, meta = schema[key]
        if not isinstance(spec, dict):
            raise ConfigError(f"{where}: expected {{low: .., high: ..}} or {{choices: [..]}}, got {spec!r}")
        for k in spec:
            if k not in SPEC_KEYS:
                hint = difflib.get_close_matches(str(k), SPEC_KEYS, n=1)
                raise ConfigError(f"{where}.{k}: unknown key" + (f" (did you mean {hint[0]}?)" if hint else ""))

        def check(v, label):
            try:
                v = _coerce(v, tp, key)
                _check_range(v, meta, key)
            except ConfigError as e:
                raise ConfigError(f"{where}: {label}: {str(e).split(': ', 1)[1]}") from None
            return v

        if "choices" in spec:
            if set(spec) - {"choices"}:
                raise ConfigError(f"{where}: choices: not with {', '.join(sorted(set(spec) - {'choices'}))}")
            ch = spec["choices"]
            if not isinstance(ch, list) or not ch:
                raise ConfigError(f"{where}: choices: expected a non-empty list, got {ch!r}")
            values = []
            for i, c in enumerate(ch):
                if c is not None and not isinstance(c, (bool, int, float, str)):
                    raise ConfigError(f"{where}: choices[{i}]: expected a single value, got {c!r}")
                v = check(c, f"choices[{i}]")
                if v in values:
                    raise ConfigError(f"{where}: choices[{i}]: {c!r} appears twice")
                values.append(v)
            params.append(Param(key, "categorical", choices=tuple(values)))
            continue
        if tp not in (int, float):
            raise ConfigError(f"{where}: not a number: give choices: [..] (the key takes {_type_text(tp)})")
        integer = tp is int
        for k in ("low", "high"):
            if k not in spec:
                raise ConfigError(f"{where}: {k}: missing (a range needs low and high)")
        low = check(_number(spec["low"], f"{where}: low", integer), "low")
        high = check(_number(spec["high"], f"{where}: high", integer), "high")
        if not low < high:
            raise ConfigError(f"{where}: low ({low}) must be below high ({high})")
        log = spec.get("log", False)
        if not isinstance(log, bool):
            raise ConfigError(f"{where}: log: expected true or false, got {log!r}")
        if log and not low > 0:
            raise ConfigError(f"{where}: log: needs low > 0, got {low}")
        step = spec.get("step")
        if step is not None:
            step = _number(step, f"{where}: step", integer)
            if not step > 0:
                raise ConfigError(f"{where}: step: must be positive, got {step}")
            if log:
                raise ConfigError(f"{where}: step: not with log: true")
            if integer and (high - low) % step:  # optuna shrank the range to a multiple, with a warning alone
                raise ConfigError(f"{where}: step: high - low ({high - low}) is not a multiple of {step}")
            if not integer and not math.isclose((high - low) / step, round((high - low) / step)):
                raise ConfigError(f"{where}: step: high - low ({high - low:g}) is not a multiple of {step:g}")
        params.append(Param(key, "int" if integer else "float", low=low, high=high, log=log,
                            step=step if (step is not None or integer) else None))
    return params


def _type_text(tp) -> str:
    from mcl.config import _type_name

    return _type_name(tp)


def param_overrides(params: dict) -> list[str]:
    """``--set`` texts of a trial's values."""
    from mcl.suite import _value_text

    return [f"{k}={_value_text(v)}" for k, v in params.items()]


# ----------------------------------------------------------------------------- objectives


def parse_objectives(text: str) -> list[str]:
    names = [n.strip().lower() for n in str(text).split(",") if n.strip()]  # RMSE as rmse
    if not names:
        raise MclError("--objective: expected one or more of " + ", ".join(OBJECTIVES))
    for n in names:
        if n not in OBJECTIVES:
            hint = difflib.get_close_matches(n, list(OBJECTIVES), n=1)
            raise MclError(f"--objective: unknown objective {n!r}" + (f" (did you mean {hint[0]}?)" if hint else "")
                           + f"; one or more of {', '.join(OBJECTIVES)}")
    if len(set(names)) != len(names):
        raise MclError(f"--objective: {text!r} names an objective twice")
    return names


def objective_values(rows: list[dict]) -> dict:
    """A trial's figures from its runs' rows (``mcl.suite.run_job``; a row with ``error`` counts as lost):
    per dataset x mode the median over seeds, then the mean over the datasets x modes. ``particles`` and ``wall``
    are over the runs that did not fail, None when every run of a dataset x mode failed; ``errors`` names the
    failed runs and why."""
    from mcl.suite import LOST_M

    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["dataset"], r["mode"]), []).append(r)
    per = {k: [] for k in ("rmse", "lost", "convergence", "particles", "wall")}
    raw = []
    for rs in groups.values():
        def lost(r):
            return "error" in r or bool(r.get("lost")) or r.get("rmse") is None

        lm = [r.get("lost_m", LOST_M) for r in rs]
        per["rmse"].append(statistics.median(LOST_PENALTY * m if lost(r) else r["rmse"] for r, m in zip(rs, lm)))
        per["lost"].append(sum(lost(r) for r in rs) / len(rs))
        per["convergence"].append(statistics.median(
            NEVER_S if lost(r) or r.get("conv_s") is None else r["conv_s"] for r in rs))
        for k, col in (("particles", "particles"), ("wall", "wall_s")):  # runs that failed: no figure
            have = [r[col] for r in rs if r.get(col) is not None]
            per[k].append(statistics.median(have) if have else None)
        raw += [r["rmse"] for r in rs if r.get("rmse") is not None]
    v = {k: None if None in x else float(statistics.fmean(x)) for k, x in per.items()}
    v["lost"] = v["lost"] + 1e-3 * v["rmse"]
    v["weighted"] = v["rmse"] + v["lost"] + v["convergence"] / 30.0
    v["lost_runs"] = sum(("error" in r or bool(r.get("lost")) or r.get("rmse") is None) for r in rows)
    v["runs"] = len(rows)
    v["errors"] = [f"{r['dataset']}/{r['mode']}/seed{r['seed']}: {r['error']}" for r in rows if "error" in r]
    v["warnings"] = sorted({w for r in rows for w in r.get("warnings", ())})  # the runs' own (said once a study)
    v["failed_runs"] = len(v["errors"])
    v["rmse_median"] = float(statistics.median(raw)) if raw else None  # raw RMSE over the runs, lost ones too
    return v


# ----------------------------------------------------------------------------- running the runs


@contextmanager
def _sigint_deferred():
    """Ctrl-C (or SIGTERM) is held while Optuna writes to the journal, and raised after."""
    caught = []
    old = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            old[sig] = signal.signal(sig, lambda *a: caught.append(1))
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
    if caught:
        raise KeyboardInterrupt


class _Local:
    """Runs in this process (jobs 1) or in ``jobs`` spawned worker processes, one numba thread each."""

    def __init__(self, jobs: int):
        self.jobs = jobs
        self.pool = None

    def __enter__(self):
        if self.jobs > 1:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            from mcl.suite import _worker_init

            self.pool = ProcessPoolExecutor(max_workers=self.jobs, mp_context=multiprocessing.get_context("spawn"),
                                            initializer=_worker_init)
        return self

    def __exit__(self, *exc):
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)

    def imap(self, fn, items: list):
        """fn over items, the results yielded in order as they come; KeyboardInterrupt when interrupted (a run
        returning ``interrupted`` included)."""
        if self.pool is None:
            results = (fn(it) for it in items)
        else:
            from mcl.suite import interrupt_workers

            futures = [self.pool.submit(fn, it) for it in items]
            results = _in_order(futures, lambda f: f.result(), lambda f: f.cancel(), on_interrupt=interrupt_workers)
        for r in results:
            if isinstance(r, dict) and r.get("interrupted"):
                raise KeyboardInterrupt
            yield r

    def map(self, fn, items: list) -> list:
        return list(self.imap(fn, items))


def _in_order(handles: list, get, cancel, on_interrupt=None):
    """Each handle's result in order; every handle cancelled when interrupted (and ``on_interrupt()`` called on
    Ctrl-C: the local pool's workers stop their runs, ``mcl.suite.interrupt_workers``)."""
    try:
        for h in handles:
            yield get(h)
    except BaseException as e:  # KeyboardInterrupt, or the generator closed early
        for h in handles:
            cancel(h)
        if on_interrupt is not None and isinstance(e, KeyboardInterrupt):
            on_interrupt()
        raise


def _ray_call(fn, item):
    """A Ray task: one numba thread (the tasks are the parallelism), then ``fn(item)``."""
    import numba

    numba.set_num_threads(1)
    return fn(item)


RAY_CONNECT_S = 5.0  # s: a --ray HOST:PORT that takes longer to accept a connection is not reached


def _reachable(address: str) -> None:
    """A --ray HOST:PORT (a cluster's head) that accepts no TCP connection within RAY_CONNECT_S: one error line at
    once (ray.init retried for 14 minutes, printing 61 lines of its log). Other forms (ray://, auto) go to Ray."""
    import socket

    host, sep, port = address.rpartition(":")
    if "://" in address or not sep or not port.isdigit():
        return
    try:
        socket.create_connection((host or "127.0.0.1", int(port)), timeout=RAY_CONNECT_S).close()
    except OSError as e:
        raise MclError(f"--ray {address}: cannot connect: nothing answers there ({e.strerror or e})") from None


class _Ray:
    """Runs as Ray tasks (one CPU each) on the cluster at ``address`` (auto: the one this machine belongs to,
    else a local one started here). Datasets and the study folder are read and written by path: on a cluster
    of several machines they must be on storage every node mounts at the same path."""

    def __init__(self, address: str):
        self.address = address
        self.started = False

    def __enter__(self):
        try:
            import ray
        except ImportError:
            raise MclError("--ray: Ray is not installed; install the cluster extra: pip install 'mcl[cluster]'") from None
        self.ray = ray
        if not ray.is_initialized():
            kw = dict(log_to_driver=False, include_dashboard=False)
            try:
                if self.address == "auto":
                    try:
                        ray.init(address="auto", **kw)
                    except ConnectionError:
                        ray.init(**kw)
                else:
                    _reachable(self.address)
                    ray.init(address=self.address, **kw)
            except Exception as e:  # noqa: BLE001 - ray's own errors: one line
                raise MclError(f"--ray {self.address}: cannot connect: {str(e).splitlines()[0] if str(e) else type(e).__name__}") from None
            self.started = True
        self.remote = ray.remote(num_cpus=1)(_ray_call)
        return self

    def __exit__(self, *exc):
        if self.started:
            self.ray.shutdown()

    def imap(self, fn, items: list):
        refs = [self.remote.remote(fn, it) for it in items]
        for r in _in_order(refs, self.ray.get, lambda ref: self.ray.cancel(ref, force=True)):
            if isinstance(r, dict) and r.get("interrupted"):
                raise KeyboardInterrupt
            yield r

    def map(self, fn, items: list) -> list:
        return list(self.imap(fn, items))


def _run_job(job) -> dict:
    """mcl.suite.run_job, with a row naming the lost_m even when the run failed."""
    from mcl.suite import run_job

    row = run_job(job)
    row.setdefault("lost_m", job.lost_m)
    return row


def _evaluate(executor, plans: list[list]):
    """Run every job of several plans at once (finished runs are read back, not run again); yield each plan's
    rows, in the order of the plans, as soon as its runs (and those of the plans before it) are done."""
    from mcl.suite import _finished

    flat = [(i, j) for i, jobs in enumerate(plans) for j in jobs]
    rows: list[dict | None] = [_finished(j) for _, j in flat]
    todo = [k for k, r in enumerate(rows) if r is None]
    results = iter(executor.imap(_run_job, [flat[k][1] for k in todo]))
    pending = iter(todo)
    nxt = next(pending, None)
    k = 0
    for i, jobs in enumerate(plans):
        out = []
        for _ in jobs:
            if k == nxt:
                rows[k] = next(results)
                nxt = next(pending, None)
            out.append(rows[k])
            k += 1
        yield out


# ----------------------------------------------------------------------------- the study


@dataclass
class Settings:
    """What a study was started with (study.json): --resume and --report read it back."""

    suite: str
    space: list[dict]  # [{key, kind, low, high, log, step, choices}]
    config: str | None
    sets: list[str]
    objectives: list[str]
    seeds: int | list[int]  # K: seeds 1..K; [A, B]: seeds A..B (--seeds A-B)
    modes: list[str] | None
    batch: int
    seed: int
    trials: int
    cache: str
    held_out: list[str] = dataclasses.field(default_factory=list)  # --held-out, besides the suite's held_out: true
    only: list[str] = dataclasses.field(default_factory=list)  # --only: these datasets of the suite (empty: all)
    fingerprint: dict = dataclasses.field(default_factory=dict)  # the suite's and the base config's: see fingerprint()

    def seed_range(self) -> range:
        return range(self.seeds[0], self.seeds[1] + 1) if isinstance(self.seeds, list) else range(1, self.seeds + 1)

    def params(self) -> list[Param]:
        return [Param(**{**p, "choices": tuple(p["choices"]) if p.get("choices") is not None else None})
                for p in self.space]


def _check_journal(path: Path) -> None:
    """A journal whose last record was cut short (a full disk, a kill mid-write) loses that record, with a warning:
    optuna appended the next records onto the cut line and could then read the study no more. A record that is not
    JSON elsewhere is one error naming the line."""
    if not path.is_file():
        return
    from optuna.storages.journal import JournalFileSymlinkLock

    lock = JournalFileSymlinkLock(str(path))  # optuna's own writers' lock: a record being written is not cut
    lock.acquire()
    try:
        data = path.read_bytes()
        if data and not data.endswith(b"\n"):
            cut = data.rfind(b"\n") + 1
            with open(path, "r+b") as f:
                f.truncate(cut)
            print(f"mcl: warning: {path}: its last record was cut short (a full disk, or a process killed while "
                  f"writing it): dropped ({len(data) - cut} bytes)", file=sys.stderr)
            data = data[:cut]
    finally:
        lock.release()
    for n, line in enumerate(data.splitlines(), start=1):
        if line.strip():
            try:
                json.loads(line)
            except ValueError:
                raise ConfigError(f"{path}:{n}: not a journal record (JSON): the study cannot be read; move the "
                                  "file away to start the study afresh") from None


def _open_study(study_dir: Path, s: Settings, create: bool):
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    journal = study_dir / "journal.log"
    no_study = ConfigError(f"{journal}: holds no study (empty or removed): start a new one with --study")
    if not create and not journal.is_file():  # (optuna's backend would make an empty one)
        raise no_study
    _check_journal(journal)
    storage = JournalStorage(JournalFileBackend(str(journal)))
    directions = ["minimize"] * len(s.objectives)
    if create:
        return optuna.create_study(storage=storage, study_name=STUDY_NAME, directions=directions, load_if_exists=False)
    try:
        return optuna.load_study(storage=storage, study_name=STUDY_NAME)
    except KeyError:  # an emptied journal.log (the advice of _check_journal, taken): no study to go on with
        raise no_study from None


def _sampler(s: Settings, asked: int):
    """The batch's sampler: TPE seeded from (--seed, trials asked before the batch)."""
    import numpy as np
    import optuna

    seed = int(np.random.SeedSequence([s.seed, asked]).generate_state(1)[0])
    return optuna.samplers.TPESampler(seed=seed)


class Tuner:
    """One study: its folder, settings, suite, and the plan of a trial."""

    def __init__(self, study_dir: Path, s: Settings):
        from mcl.suite import load_suite

        self.dir = Path(study_dir)
        self.s = s
        self.suite = load_suite(s.suite)
        self.params = s.params()
        names = [d.name for d in self.suite.datasets]
        for opt, given in (("--only", s.only), ("--held-out", s.held_out)):
            for n in given:  # a name or a shell pattern ('corridor-*'), as mcl eval --only takes
                if not any(fnmatch.fnmatchcase(name, n) for name in names):
                    hint = difflib.get_close_matches(n, names, n=1)
                    raise ConfigError(f"{opt}: no dataset {n!r} in {self.suite.path}"
                                      + (f" (did you mean {hint[0]}?)" if hint else ""))

        def named(name: str, given: list[str]) -> bool:
            return any(fnmatch.fnmatchcase(name, n) for n in given)

        datasets = [d for d in self.suite.datasets if not s.only or named(d.name, s.only)]
        self.all = [d.name for d in datasets]
        self.tuning = [d.name for d in datasets if not (d.held_out or named(d.name, s.held_out))]
        self.held_out = [d.name for d in datasets if d.held_out or named(d.name, s.held_out)]
        if not self.tuning:
            raise ConfigError(f"{self.suite.path}: every dataset is held_out: nothing left to tune on")
        self.modes = tuple(s.modes) if s.modes else None

    def plan(self, params: dict, out: Path, only: list[str], label: str | None = None):
        from mcl.suite import plan

        jobs = plan(self.suite, config=self.s.config, sets=self.s.sets + param_overrides(params),
                    seeds=self.s.seed_range(), out=out, cache=Path(self.s.cache), modes=self.modes, only=only,
                    baseline=False)
        if label is not None:
            for j in jobs:
                j.config = label
                j.run_dir = str(Path(j.run_dir).parent.parent / label / Path(j.run_dir).name)
        return jobs

    def trial_dir(self, number: int) -> Path:
        return self.dir / "trials" / f"{number:05d}"

    def base_values(self) -> dict:
        """The base config's values of the tuned keys that lie in the space (trial 0 tries them)."""
        from mcl.config import PROJECT_ROOT, load_config, to_dict

        cfg = to_dict(load_config(self.s.config or PROJECT_ROOT / "configs" / "default.yaml", self.s.sets))
        out = {}
        for p in self.params:
            node = cfg
            for part in p.key.split("."):
                node = node[part]
            if p.contains(node):
                out[p.key] = node
        return out

    def make_worlds(self, executor, echo) -> None:
        jobs = self.plan({}, self.dir / "trials" / "base", self.all)
        worlds = {j.world[0]: j.world[1] for j in jobs if j.world is not None and not Path(j.world[0], "sim.yaml").is_file()}
        if worlds:
            echo(f"generating {len(worlds)} synthetic world(s) into {self.s.cache}")
            try:
                executor.map(_make_world, list(worlds.items()))
            except MclError as e:  # mcl.suite.make_world's: the world named
                raise MclError(f"{self.suite.path}: {e}") from None

    def evaluate_trials(self, executor, trials: list[tuple[int, dict]]):
        """Yield (figures, None) or (None, the config error) per trial, in order, as each is done."""
        from mcl.suite import _finish_plan

        plans, errors = [], []
        for number, params in trials:
            try:
                jobs = self.plan(params, self.trial_dir(number), self.tuning)
                _finish_plan(jobs)
                errors.append(None)
            except ConfigError as e:
                jobs = []
                errors.append(str(e))
            plans.append(jobs)
        for rows, e in zip(_evaluate(executor, plans), errors):
            yield (None, e) if e else (objective_values(rows), None)


def _make_world(item):
    from mcl.suite import make_world

    return make_world(*item)


def _executor(jobs: int, ray: str | None):
    return _Ray(ray) if ray else _Local(jobs)


def _trial(study, frozen):
    """A live Trial (user attributes, tell) for a trial asked in this process or before a resume."""
    from optuna.trial import Trial

    return Trial(study, frozen._trial_id)  # noqa: SLF001 - FrozenTrial keeps its storage id private


def optimise(tuner: Tuner, *, trials: int, executor, progress=None, echo=print) -> None:
    """Ask, evaluate and tell batches until ``trials`` trials are finished (see the module doc)."""
    from optuna.trial import TrialState
    from tqdm import tqdm

    s = tuner.s
    study = _open_study(tuner.dir, s, create=False)
    space = {p.key: p.distribution() for p in tuner.params}

    def states():
        return study.get_trials(deepcopy=False)

    def n_finished():
        return sum(t.state.is_finished() for t in states())

    said: set[str] = set()  # the runs' warnings said so far (tqdm.write: a trial that starves the laser)
    bar = tqdm(total=trials, initial=min(n_finished(), trials), unit="trial", dynamic_ncols=True,
               disable=(None if progress is None else not progress))
    bar.set_postfix_str(_best_text(study, s))
    try:
        while True:
            running = sorted((t for t in states() if t.state == TrialState.RUNNING), key=lambda t: t.number)
            if not running:
                if n_finished() >= trials:
                    break
                asked = sum(t.state != TrialState.WAITING for t in states())
                with _sigint_deferred():  # Ctrl-C waits until the whole batch is in the journal
                    if asked == 0:
                        base = tuner.base_values()
                        if base:
                            study.enqueue_trial(base)
                    study.sampler = _sampler(s, asked)
                    for _ in range(s.batch):
                        study.ask(space)  # fixed distributions: every value is drawn (and journaled) now
                continue
            todo = [t for t in running if t.number < trials]
            if not todo:
                break
            results = tuner.evaluate_trials(executor, [(t.number, t.params) for t in todo])
            for t, (fig, err) in zip(todo, results):  # told in order, each as soon as it and those before are done
                with _sigint_deferred():
                    live = _trial(study, t)
                    if err is not None:
                        live.set_user_attr("error", err)
                        study.tell(live, state=TrialState.FAIL)
                        tqdm.write(f"trial {t.number}: {err}", file=sys.stderr)
                    else:
                        for w in fig.get("warnings", ()):  # a trial whose values starve the laser is said, once
                            if w not in said:
                                said.add(w)
                                tqdm.write(f"trial {t.number}: warning: {w}", file=sys.stderr)
                        for k in FIGURES:
                            live.set_user_attr(k, fig[k])
                        values = [fig[o] for o in s.objectives]
                        missing = [o for o, v in zip(s.objectives, values) if v is None]
                        if fig["errors"]:  # failed runs count as lost; why, in trials.csv's error column
                            err = (f"{len(fig['errors'])} run(s) failed: " + "; ".join(fig["errors"][:3])
                                   + (f"; {len(fig['errors']) - 3} more" if len(fig["errors"]) > 3 else ""))
                            if missing:  # particles or wall of a dataset x mode whose every run failed
                                err = f"no {', '.join(missing)} figure: {err}"
                            live.set_user_attr("error", err)
                            tqdm.write(f"trial {t.number}: {err}", file=sys.stderr)
                        if missing:
                            study.tell(live, state=TrialState.FAIL)
                        else:
                            study.tell(live, values)
                bar.update(1)
                bar.set_postfix_str(_best_text(study, s))
    finally:
        bar.close()


FIGURES = ("rmse", "lost", "convergence", "weighted", "particles", "wall", "lost_runs", "failed_runs", "runs",
           "rmse_median")


def _complete(study):
    from optuna.trial import TrialState

    return [t for t in study.get_trials(deepcopy=False) if t.state == TrialState.COMPLETE]


def best_trial(study, s: Settings):
    """The best trial (several objectives: the Pareto trial best in the first); lowest number on ties."""
    done = _complete(study)
    if not done:
        return None
    pool = study.best_trials if len(s.objectives) > 1 else done
    return min(pool, key=lambda t: (t.values[0], t.number))


def _best_text(study, s: Settings) -> str:
    b = best_trial(study, s)
    if b is None:
        return "best -"
    if len(s.objectives) > 1:
        return f"Pareto front {len(study.best_trials)}, best {s.objectives[0]} {b.values[0]:.4g} (#{b.number})"
    return f"best {b.value:.4g} (#{b.number})"


# ----------------------------------------------------------------------------- outputs


def _trials_csv(study, s: Settings, params: list[Param]) -> str:
    head = (["number", "state"] + [f"value_{o}" for o in s.objectives] + [p.key for p in params]
            + list(FIGURES) + ["error"])
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head)
    for t in sorted(study.get_trials(deepcopy=False), key=lambda t: t.number):
        values = list(t.values) if t.values is not None else [None] * len(s.objectives)
        state = "queued" if t.state.name in ("RUNNING", "WAITING") else t.state.name.lower()
        w.writerow([t.number, state] + values + [t.params.get(p.key) for p in params]
                   + [t.user_attrs.get(k) for k in FIGURES] + [t.user_attrs.get("error")])
    return buf.getvalue()


def best_config_text(tuner: Tuner, trial) -> str:
    """best.yaml: the base config with the best trial's values, through mcl.config (so it loads again)."""
    from mcl.config import PROJECT_ROOT, dump_config, load_config

    base = tuner.s.config or str(PROJECT_ROOT / "configs" / "default.yaml")
    cfg = load_config(base, tuner.s.sets + param_overrides(trial.params))
    values = ", ".join(f"{o} {v:.6g}" for o, v in zip(tuner.s.objectives, trial.values))
    head = [f"# mcl tune: trial {trial.number} of {tuner.dir} ({values}) on {tuner.suite.path}",
            f"# base config: {base}" + (f" with --set {' '.join(tuner.s.sets)}" if tuner.s.sets else ""),
            "# tuned: " + ", ".join(f"{k}={v!r}" for k, v in trial.params.items())]
    return "\n".join(head) + "\n" + dump_config(cfg)


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=90)
    return buf.getvalue()


def write_plots(study, s: Settings, params: list[Param], out: Path) -> list[Path]:
    """plots/history.png; plots/importances.png (two or more tuned keys and five finished trials);
    plots/pareto.png (two or three objectives)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from optuna.visualization import matplotlib as ov

    from mcl.trajectory import atomic_write_bytes

    done = _complete(study)
    if not done:
        return []
    multi = len(s.objectives) > 1
    target = (lambda t: t.values[0]) if multi else None
    name = s.objectives[0]
    written = []
    (out / "plots").mkdir(parents=True, exist_ok=True)

    def save(fname, draw):
        try:
            ax = draw()
        except (ValueError, RuntimeError, ZeroDivisionError) as e:  # e.g. every value the same: no importances
            warnings.warn(f"{fname}: not drawn: {e}", stacklevel=2)
            plt.close("all")
            return
        fig = ax.figure if hasattr(ax, "figure") else ax.flat[0].figure
        p = out / "plots" / fname
        atomic_write_bytes(p, _png(fig))
        plt.close("all")
        written.append(p)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # optuna.exceptions.ExperimentalWarning on every plot
        save("history.png", lambda: ov.plot_optimization_history(study, target=target, target_name=name))
        if len(params) >= 2 and len(done) >= 5:
            save("importances.png", lambda: ov.plot_param_importances(study, target=target, target_name=name))
        if multi and len(s.objectives) <= 3:
            save("pareto.png", lambda: ov.plot_pareto_front(study, target_names=s.objectives))
    return written


def held_out(tuner: Tuner, executor, trial) -> dict | None:
    """The best trial's config and the base config over the held-out datasets (runs in heldout/, kept)."""
    from mcl.suite import _finish_plan, aggregate, format_table
    from mcl.trajectory import atomic_write_text

    if not tuner.held_out or trial is None:
        return None
    out = tuner.dir / "heldout"
    plans = [tuner.plan(trial.params, out, tuner.held_out, label="best"), tuner.plan({}, out, tuner.held_out, label="base")]
    for jobs in plans:
        _finish_plan(jobs)
    best_rows, base_rows = _evaluate(executor, plans)
    doc = {"datasets": tuner.held_out, "trial": trial.number, "params": trial.params,
           "best": objective_values(best_rows), "base": objective_values(base_rows)}
    table = format_table(aggregate(best_rows + base_rows))
    atomic_write_text(out / "heldout.json", json.dumps(doc, indent=1) + "\n")
    atomic_write_text(out / "table.txt", table + "\n")
    doc["table"] = table
    return doc


def summary_text(tuner: Tuner, study, trial, ho: dict | None) -> str:
    """The one-paragraph summary."""
    from optuna.trial import TrialState

    s = tuner.s
    ts = study.get_trials(deepcopy=False)
    n_done = sum(t.state == TrialState.COMPLETE for t in ts)
    n_fail = sum(t.state == TrialState.FAIL for t in ts)
    modes = ",".join(s.modes) if s.modes else "each dataset's modes"
    seeds = s.seed_range()
    text = (f"Study {tuner.dir}: {n_done} trials done"
            + (f" ({n_fail} failed: the error column of trials.csv says why)" if n_fail else "")
            + f" on {len(tuner.tuning)} dataset(s) of suite {tuner.suite.name} ({modes}, seeds {seeds.start}.."
            f"{seeds.stop - 1}), "
            f"objective {','.join(s.objectives)}, seed {s.seed}.")
    if trial is None:
        return text + " No trial finished yet."
    ua = trial.user_attrs
    values = ", ".join(f"{o} {v:.4g}" for o, v in zip(s.objectives, trial.values))
    text += (f" Best: trial {trial.number} ({values}; RMSE score {ua['rmse']:.4f} m, {ua['lost_runs']} of "
             f"{ua['runs']} runs lost{_failed_text(ua)}) with "
             + ", ".join(f"{k} = {_short(v)}" for k, v in trial.params.items()) + ".")
    base = next((t for t in ts if t.number == 0 and t.state == TrialState.COMPLETE), None)
    if base is not None and base.params == tuner.base_values() and len(base.params) == len(tuner.params):
        text += f" The base config (trial 0) scored {', '.join(f'{o} {v:.4g}' for o, v in zip(s.objectives, base.values))}."
    if len(s.objectives) > 1:
        text += f" Pareto front: {len(study.best_trials)} trials (plots/pareto.png)."
    if ho is not None:
        def line(d):
            med = "-" if d["rmse_median"] is None else f"{d['rmse_median']:.4f} m"
            return (f"median RMSE {med}, RMSE score {d['rmse']:.4f} m, {d['lost_runs']} of {d['runs']} runs "
                    f"lost{_failed_text(d)}")

        text += (f" Held out ({', '.join(ho['datasets'])}; never seen while tuning): best config {line(ho['best'])}; "
                 f"base config {line(ho['base'])}.")
    elif tuner.held_out:
        text += " Held-out datasets not evaluated yet (the study was interrupted)."
    else:
        text += " No held-out dataset: the score is on the tuning data itself (see README, 'Tuning a config')."
    return text + " Files: best.yaml, trials.csv, plots/."


def _failed_text(figures) -> str:
    n = figures.get("failed_runs")
    return f" ({n} failed)" if n else ""


def _short(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def write_outputs(tuner: Tuner, executor, *, heldout: bool = True, echo=print) -> int:
    """trials.csv, best.yaml, plots/, held-out figures and summary.txt; print the summary."""
    from mcl.trajectory import atomic_write_text

    s = tuner.s
    study = _open_study(tuner.dir, s, create=False)
    atomic_write_text(tuner.dir / "trials.csv", _trials_csv(study, s, tuner.params))
    trial = best_trial(study, s)
    if trial is not None:
        atomic_write_text(tuner.dir / "best.yaml", best_config_text(tuner, trial))
    if len(s.objectives) > 1 and trial is not None:
        front = sorted(study.best_trials, key=lambda t: t.number)
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["number"] + s.objectives + [p.key for p in tuner.params])
        for t in front:
            w.writerow([t.number] + list(t.values) + [t.params.get(p.key) for p in tuner.params])
        atomic_write_text(tuner.dir / "pareto.csv", buf.getvalue())
    write_plots(study, s, tuner.params, tuner.dir)
    ho = held_out(tuner, executor, trial) if heldout else None
    text = summary_text(tuner, study, trial, ho)
    atomic_write_text(tuner.dir / "summary.txt", text + "\n" + (f"\nheld out:\n{ho['table']}\n" if ho else ""))
    if ho:
        echo(ho["table"])
    echo(text)
    return 0


# ----------------------------------------------------------------------------- the command


def add_arguments(p) -> None:
    p.add_argument("suite", nargs="?", metavar="SUITE.yaml", help="suite file (see suites/): the datasets to tune on; "
                   "entries with held_out: true are kept for the end")
    p.add_argument("--space", metavar="SPACE.yaml", help="the keys to tune, with ranges or choices (see "
                   "suites/tune-space.yaml)")
    p.add_argument("--config", help="base config (default: configs/default.yaml)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a key of the base config (repeatable)")
    p.add_argument("--trials", type=int, metavar="N", help="trials in the study, those done before a --resume "
                   "included (default 100)")
    p.add_argument("--objective", metavar="NAME[,NAME]",
                   help="what to minimise: " + "; ".join(f"{k}: {v}" for k, v in OBJECTIVES.items())
                   + ". Two or more (e.g. rmse,particles): a Pareto front (default rmse)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, metavar="J", help="worker processes (default: the cores)")
    p.add_argument("--batch", type=int, metavar="B", help="trials asked together and evaluated in parallel "
                   "(a setting of the study: the same --seed gives the same trials whatever --jobs; default 4)")
    p.add_argument("--seeds", metavar="K|A-B", help="run seeds 1..K (or A..B) per dataset and mode "
                   "(default 1)")
    p.add_argument("--modes", metavar="M,...", help="only these modes: tracking,global,kidnapped")
    p.add_argument("--only", metavar="NAME,...", help="only these datasets of the suite (tuned on and held out)")
    p.add_argument("--held-out", metavar="NAME,...", help="also hold these datasets out (as held_out: true in the "
                   "suite): never tuned on; the best and the base config are scored on them at the end")
    p.add_argument("--seed", type=int, help="the sampler's seed (default 0)")
    p.add_argument("--study", metavar="DIR", help="study folder (default runs/tune-SUITE)")
    p.add_argument("--cache", help="folder of the generated synthetic worlds (default STUDY/worlds)")
    p.add_argument("--ray", metavar="auto|ADDRESS", help="run the trials' runs as Ray tasks: auto (the cluster of "
                   "this machine, else a local one) or a cluster address; needs pip install 'mcl[cluster]'")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--resume", metavar="DIR", help="go on with an interrupted study (with --trials: up to N trials)")
    g.add_argument("--report", metavar="DIR", help="write best.yaml, trials.csv, the plots and the summary again")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _names(text: str | None) -> list[str]:
    return [n.strip() for n in text.split(",") if n.strip()] if text else []


def fingerprint(s: Settings) -> dict:
    """Hashes of the suite file's text and of the base config as loaded (with its --set): stored in study.json,
    --resume refuses a study whose suite or base config changed since (its trials would be scored on other data)."""
    import hashlib

    from mcl.config import PROJECT_ROOT, dump_config, load_config

    try:
        suite = Path(s.suite).read_bytes()
    except OSError as e:
        raise MclError(f"{s.suite}: {e.strerror or e}") from None
    base = dump_config(load_config(s.config or PROJECT_ROOT / "configs" / "default.yaml", s.sets))
    return {"suite": hashlib.sha1(suite).hexdigest(), "config": hashlib.sha1(base.encode()).hexdigest()}


def _load_settings(study_dir: Path) -> Settings:
    path = study_dir / STATE_FILE
    try:
        doc = json.loads(path.read_text())
        return Settings(**doc)
    except FileNotFoundError:
        raise MclError(f"{study_dir}: not a study folder (no {STATE_FILE})") from None
    except (ValueError, TypeError) as e:
        raise MclError(f"{path}: not a study file of this mcl version: {e}") from None


def run_from_args(args) -> int:
    """``mcl tune`` from the parsed command line (mcl.cli). The study folder is locked while the study runs (two
    --resume of one study at once told the same trials twice)."""
    with ExitStack() as held:  # the --study lock, once taken
        return _run_from_args(args, held)


def _lock_study(study_dir: Path, held: ExitStack) -> None:
    from mcl.runner import folder_lock

    held.enter_context(folder_lock(study_dir, f"--study {study_dir}: another mcl tune is working on this study now: "
                                              "wait for it to end (two at once told the same trials twice)"))


def _run_from_args(args, held: ExitStack) -> int:
    from mcl.suite import make_dir, seed_range
    from mcl.trajectory import atomic_write_text

    for name in ("jobs", "batch"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            raise MclError(f"--{name}: expected >= 1, got {getattr(args, name)}")
    if args.trials is not None and args.trials < 1:
        raise MclError(f"--trials: expected >= 1, got {args.trials}")
    if getattr(args, "seed", None) is not None and args.seed < 0:  # the sampler's seed: a traceback after study.json
        raise MclError(f"--seed: expected >= 0, got {args.seed}")
    echo = print
    existing = args.resume or args.report
    if existing:
        given = [o for o, v in (("SUITE", args.suite), ("--space", args.space), ("--config", args.config),
                                ("--set", args.set), ("--modes", args.modes), ("--study", args.study),
                                ("--held-out", args.held_out), ("--only", args.only),
                                ("--cache", args.cache), ("--objective", args.objective),
                                ("--batch", args.batch is not None), ("--seeds", args.seeds),
                                ("--seed", args.seed is not None)) if v]
        if given:
            raise MclError(f"{'--resume' if args.resume else '--report'}: the study's settings are in "
                           f"{existing}/{STATE_FILE}; not with {', '.join(given)}")
        study_dir = Path(existing)
        s = _load_settings(study_dir)
        _lock_study(study_dir, held)
        if s.fingerprint:
            now = fingerprint(s)  # the suite gone: one error line naming it (--report reads it too)
            changed = [f"the suite file {s.suite}" if k == "suite" else
                       f"the base config {s.config or 'configs/default.yaml'}" + (" (with its --set)" if s.sets else "")
                       for k in ("suite", "config") if s.fingerprint.get(k) != now[k]]
            if changed and args.resume:
                raise MclError(f"--resume {study_dir}: {' and '.join(changed)} changed since the study began (its "
                               "trials were scored on the old one): restore it, or start a new --study")
            if changed:  # --report writes what the trials measured, on the files as they were
                print(f"mcl: warning: --report {study_dir}: {' and '.join(changed)} changed since the study began: "
                      "the report is of the trials as they were scored, on the old one", file=sys.stderr)
        if args.trials is not None:
            s.trials = args.trials
            atomic_write_text(study_dir / STATE_FILE, json.dumps(dataclasses.asdict(s), indent=1) + "\n")
    else:
        if args.suite is None or args.space is None:
            raise MclError("tune: expected SUITE.yaml --space SPACE.yaml (or --resume / --report DIR)")
        from mcl.suite import check_sets, load_suite, parse_modes

        check_sets(args.set)

        seeds = seed_range(args.seeds or "1")
        params = load_space(args.space)
        objectives = parse_objectives(args.objective or "rmse")
        suite = load_suite(args.suite)
        for d in suite.datasets:  # a trial's value would replace the dataset's own without a word
            both = sorted({p.key for p in params} & set(d.set))
            if both:
                raise ConfigError(f"{args.space}: {both[0]}: not tunable on {suite.path}: its dataset {d.name} sets it "
                                  "(set:), and a trial's value would replace that")
        modes = list(parse_modes(args.modes)) if args.modes else None
        study_dir = Path(args.study) if args.study else Path.cwd() / "runs" / f"tune-{suite.name}"
        if (study_dir / STATE_FILE).exists():
            raise MclError(f"--study {study_dir}: a study is there already: --resume {study_dir} goes on with it "
                           "(or give another --study)")
        _check_study_dir(study_dir)
        if args.config is not None and not Path(args.config).is_file():
            raise ConfigError(f"--config: no such file {args.config}")
        s = Settings(suite=str(Path(args.suite).resolve()),
                     space=[{"key": p.key, "kind": p.kind, "low": p.low, "high": p.high, "log": p.log, "step": p.step,
                             "choices": list(p.choices) if p.choices is not None else None} for p in params],
                     config=str(Path(args.config).resolve()) if args.config else None, sets=list(args.set),
                     objectives=objectives, modes=modes, batch=args.batch or 4,
                     seed=args.seed if args.seed is not None else 0,
                     seeds=seeds.stop - 1 if seeds.start == 1 else [seeds.start, seeds.stop - 1],
                     trials=args.trials if args.trials is not None else 100,
                     cache=str(Path(args.cache).resolve() if args.cache else (study_dir / "worlds").resolve()),
                     held_out=_names(args.held_out), only=_names(args.only))
        tuner = Tuner(study_dir, s)
        jobs = tuner.plan({}, study_dir / "trials" / "base", tuner.tuning)  # the base config checks too
        if not jobs:
            raise ConfigError(f"{tuner.suite.path}: no run to tune on (modes {args.modes} not in any tuned dataset)")
        if modes:
            missing = [m for m in modes if m not in {j.mode for j in jobs}]
            if missing:  # as mcl eval says it
                echo(f"mcl: note: --modes {','.join(missing)}: not run (no tuned dataset names it)", file=sys.stderr)
        s.fingerprint = fingerprint(s)
    tuner = Tuner(study_dir, s)
    progress = False if args.no_progress else None
    with _executor(args.jobs, args.ray) as executor:
        if not existing:  # made once the executor is up: a --ray that fails leaves no empty study behind
            make_dir(study_dir, "--study")  # first: a --study that cannot be made is said as --study
            _lock_study(study_dir, held)
            if any(d.simulate is not None for d in tuner.suite.datasets):
                make_dir(Path(s.cache), "--cache")
            atomic_write_text(study_dir / STATE_FILE, json.dumps(dataclasses.asdict(s), indent=1) + "\n")
            _open_study(study_dir, s, create=True)
        interrupted, cut = _study(tuner, executor, args, s, progress, echo)
    return _ending(study_dir, s, interrupted, cut, echo)


def _study(tuner: Tuner, executor, args, s: Settings, progress, echo) -> tuple[bool, bool]:
    """The worlds, the trials (unless --report) and the outputs: (the trials interrupted, the outputs cut)."""
    from mcl.suite import TermAsInterrupt

    interrupted = cut = False
    tuner.make_worlds(executor, echo)
    try:
        with TermAsInterrupt():  # SIGTERM (kill, timeout, a batch scheduler) stops the study as Ctrl-C does
            if not args.report:
                try:
                    optimise(tuner, trials=s.trials, executor=executor, progress=progress, echo=echo)
                except KeyboardInterrupt:
                    interrupted = True
            write_outputs(tuner, executor, heldout=not interrupted, echo=echo)
    except KeyboardInterrupt:  # the held-out runs, plots, best.yaml: cut, and said
        cut = True
    return interrupted, cut


def _ending(study_dir: Path, s: Settings, interrupted: bool, cut: bool, echo) -> int:
    """The exit status, and the line that says how to go on after an interruption."""
    study = _open_study(study_dir, s, create=False)
    n = sum(t.state.is_finished() for t in study.get_trials(deepcopy=False))
    if cut:
        echo(f"interrupted while writing the study's outputs (held-out runs, best.yaml, summary.txt): mcl tune "
             f"--report {study_dir} writes them again" + ("" if interrupted or n >= s.trials else
                                                            f"; --resume {study_dir} goes on with the trials"))
        return 130
    if interrupted:
        echo(f"interrupted after {n} trials: mcl tune --resume {study_dir} goes on where it stopped")
        return 130
    if best_trial(study, s) is None or all(t.user_attrs.get("failed_runs", 0) >= t.user_attrs.get("runs", 1) > 0
                                           for t in _complete(study)):
        raise MclError(f"--study {study_dir}: every trial failed (trials.csv's error column says why)")
    return 0


def _check_study_dir(study_dir: Path) -> None:
    """A --study folder that holds files a study did not write (a user's own best.yaml or trials.csv, which the
    study would replace), or a study's journal without its study.json (appended to, it mixed two studies' trials):
    one error line before anything is written."""
    if not study_dir.is_dir():
        return
    if (study_dir / "journal.log").exists():
        raise MclError(f"--study {study_dir}: holds a journal.log without its {STATE_FILE} (a study's, half "
                       "removed?): give another --study, or remove the folder")
    ours = {"best.yaml", "trials.csv", "summary.txt", "pareto.csv", "plots", "trials", "worlds", "heldout"}
    theirs = sorted(p.name for p in study_dir.iterdir() if p.name in ours)
    if theirs:
        raise MclError(f"--study {study_dir}: holds {', '.join(theirs)} of no study (a study writes these): give "
                       "another --study, or an empty folder")
