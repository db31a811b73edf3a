"""Evaluating a config over a corpus of datasets: ``mcl eval --suite SUITE.yaml``.

A suite file lists datasets (a map, a log and a truth; a ROS bag with a truth file or a truth topic of the
bag, and a map file or the bag's map; or a synthetic world ``mcl.simulate`` generates once into a cache folder)
and the modes to run each in:

- ``tracking``: from the start pose with the config's ``filter.initial_std``; scored by the ATE over the
  whole run; *lost* when the maximum error exceeds the dataset's ``lost_m`` (default 1 m);
- ``global``: global localization (particles uniform over free space); scored by the convergence time,
  from the first scored pose until the error falls below ``SETTLE_M`` and never again exceeds the larger of
  ``SETTLE_M`` and ``lost_m`` (the tracking run's bound: a later excursion a tracking run is allowed does not
  undo the convergence); *lost* unless it converged within ``WITHIN_S``; RMSE and max from the convergence on;
- ``kidnapped``: tracking, then the robot (a synthetic world made again with ``kidnap_at`` = half its
  duration) or the filter (a real log: the particles moved at mid-truth to a cloud around a free pose
  >= ``KIDNAP_M`` away: the run's ``eval.kidnap_at``, ``eval.kidnap_m``) is kidnapped; scored by the recovery time, from
  the kidnap until the error falls below ``SETTLE_M`` and stays within the same bound; *lost* unless it
  recovered within ``WITHIN_S`` (or the maximum error before the kidnap exceeds ``lost_m``); RMSE and max
  over the poses before the kidnap and after the recovery. A reference time between the filter's last pose
  before the kidnap and the kidnap itself is left out: the estimate there would be interpolated between the
  track and the kidnapped cloud (a reference at another rate than the scans, or scans stamped late).

``lost_m`` is the dataset's, else the suite's (``lost_m:`` at the top of the file), else ``LOST_M``.

A dataset marked ``held_out: true`` is evaluated like the others here; ``mcl tune`` (mcl.tune) never tunes on
it and scores its best and its base config on it at the end.

Every run goes through :func:`mcl.runner.run` in a worker process (``concurrent.futures``, one numba
thread each, no recording) with seeds 1..K (or A..B), for the config under test and, unless ``--no-baseline``, for
``configs/baseline.yaml`` (a plain fixed-N filter). Outputs in ``--out``: one folder per run
(``runs/DATASET/MODE/CONFIG/seedK``, with the runner's outputs, ``errors.csv`` and ``row.json``),
``results.json`` and ``results.csv`` (one row per run), ``table.csv`` and ``table.txt`` (the median and
the worst over seeds of each dataset x mode x config) and ``plots/DATASET.png`` (error over time). The
results are rewritten, atomically, after every run; a run whose ``row.json`` holds the same fingerprint (its
config, mcl's source (``code_digest``), and the size and time of each data file it reads) is not run again, so an interrupted evaluation resumes
where it stopped. A run that fails (its log
unreadable, its truth not overlapping the log) is a row with its ``error``, counted as lost, and the others go on.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import difflib
import fnmatch
import hashlib
import inspect
import io
import json
import math
import os
import signal
import statistics
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from mcl.errors import ConfigError, MclError

MODES = ("tracking", "global", "kidnapped")
SETTLE_M = 0.5  # m: converged / recovered once the error falls below this and stays
WITHIN_S = 30.0  # s: ... within this long (global: from the start; kidnapped: from the kidnap)
KIDNAP_M = 5.0  # m: a real log's filter is kidnapped at least this far from the truth
LOST_M = 1.0  # m: default lost threshold of a dataset (tracking: max error above it)

SUITE_KEYS = ("name", "root", "modes", "lost_m", "datasets")
DATASET_KEYS = ("name", "map", "config", "log", "bag", "truth", "truth_topic", "initial_pose", "lost_m", "set", "modes",
                "simulate", "held_out")
BASELINE = "baseline"


# ----------------------------------------------------------------------------- the suite file


@dataclass
class Dataset:
    """One entry of a suite: real files or a synthetic world (``simulate`` kwargs)."""

    name: str
    map: str | None = None  # None with a bag: the bag's map topic
    log: str | None = None
    bag: str | None = None  # a ROS bag instead of a CARMEN log
    truth: str | None = None
    truth_topic: str | None = None  # a bag's reference poses (written once as TUM into the cache)
    laser: str | None = None  # from a dataset config
    initial_pose: tuple[float, float, float] | None = None
    lost_m: float = LOST_M
    set: dict = field(default_factory=dict)
    modes: tuple[str, ...] = ("tracking",)
    simulate: dict | None = None
    held_out: bool = False  # mcl tune: never seen while tuning; the best and the base config are scored on it at the end


@dataclass
class Suite:
    name: str
    path: Path
    datasets: list[Dataset]
    world: dict = field(default_factory=dict)  # --world: simulate keywords set in every generated world


def _unknown(where: str, key, allowed) -> ConfigError:
    hint = difflib.get_close_matches(str(key), list(allowed), n=1)
    return ConfigError(f"{where}{key}: unknown key" + (f" (did you mean {hint[0]}?)" if hint else ""))


def _modes(value, where: str) -> tuple[str, ...]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{where}: expected a list of modes ({', '.join(MODES)}), got {value!r}")
    for m in value:
        if m not in MODES:
            hint = difflib.get_close_matches(str(m), MODES, n=1)
            raise ConfigError(f"{where}: unknown mode {m!r}" + (f" (did you mean {hint[0]}?)" if hint else ""))
    return tuple(dict.fromkeys(value))


def parse_modes(text: str, where: str = "--modes") -> tuple[str, ...]:
    """A command line's comma-separated modes (``tracking,global``), checked as a suite's ``modes`` are: a
    ConfigError names ``where`` and the unknown mode."""
    return _modes([m.strip() for m in text.split(",") if m.strip()], where)


def _lost_m(value, where: str) -> float:
    """A suite's or a dataset's ``lost_m``: a positive number of metres."""
    from mcl.yamlfile import finite_number

    v = finite_number(value, where, ConfigError)
    if not v > 0:
        raise ConfigError(f"{where}: must be positive, got {v}")
    return v


_SIM_TYPES = {"float": ("a number", lambda v: isinstance(v, (int, float)) and not isinstance(v, bool)),
              "int": ("a whole number", lambda v: isinstance(v, int) and not isinstance(v, bool)),
              "bool": ("true or false", lambda v: isinstance(v, bool)),
              "str": ("a string", lambda v: isinstance(v, str))}


def _sim_params() -> dict:
    """The keywords of :func:`mcl.simulate.simulate` a suite may give (its parameters but ``outdir``)."""
    from mcl.simulate import simulate

    return {k: p for k, p in inspect.signature(simulate).parameters.items() if k != "outdir" and k[0] != "_"}


def _sim_value(where: str, key: str, value):
    """A simulate keyword's value checked against the type :func:`mcl.simulate.simulate` declares for it (a
    keyword declared ``float | None`` may be null; one without a declared type is left to simulate); ConfigError
    naming ``where`` and the key otherwise, before any world is made."""
    kind = str(_sim_params()[key].annotation)
    optional = kind.endswith(" | None")
    kind = kind.removesuffix(" | None")
    if kind not in _SIM_TYPES or (optional and value is None):
        return value
    what, ok = _SIM_TYPES[kind]
    if not ok(value):
        raise ConfigError(f"{where}{key}: expected {what}{' or null' if optional else ''}, got {value!r}")
    return value


def _check_sim(where: str, kw: dict) -> None:
    """:func:`mcl.simulate.simulate`'s own checks of the keywords ``kw`` (``kind: spaceship``, ``duration: -5``),
    without making the world; ConfigError naming ``where`` and the key, before anything is written."""
    from mcl.simulate import simulate

    try:
        simulate(None, _check_only=True, **kw)
    except ConfigError as e:  # "simulate: KEY: message"
        raise ConfigError(f"{where}simulate.{str(e).removeprefix('simulate: ')}") from None
    except (TypeError, ValueError) as e:  # a keyword simulate declares no type for (odom_alphas: 3)
        raise ConfigError(f"{where}simulate: {e}") from None


def world_overrides(items) -> dict:
    """``mcl eval --world KEY=VALUE`` (repeatable): keywords of :func:`mcl.simulate.simulate` to set in every
    generated world of a suite, the value read as YAML (``scan_rate=40``, ``range_max=8``, ``fov=4.71``). ConfigError
    naming the option for a malformed item or an unknown keyword."""
    import yaml

    sim_keys = list(_sim_params())
    out = {}
    for item in items or ():
        key, sep, text = str(item).partition("=")
        key = key.strip()
        if not sep or not key:
            raise ConfigError(f"--world: expected KEY=VALUE (a keyword of mcl simulate), got {item!r}")
        if key not in sim_keys:
            raise _unknown("--world: ", key, sim_keys)
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            raise ConfigError(f"--world: {key}: cannot read the value {text!r}") from None
        out[key] = _sim_value("--world: ", key, value)
    return out


def _world_text(world: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in world.items())


def with_world(suite: Suite, world: dict) -> Suite:
    """The suite with ``world`` (``world_overrides``) set in every generated world's simulate keywords; the
    worlds are new ones (their cache folder is named by a hash of the keywords), the real datasets unchanged.
    ConfigError when the suite generates no world."""
    if not world:
        return suite
    if not any(d.simulate is not None for d in suite.datasets):
        raise ConfigError(f"--world: {suite.path} generates no world (no dataset has simulate:)")
    datasets = [dataclasses.replace(d, simulate={**d.simulate, **world}) if d.simulate is not None else d
                for d in suite.datasets]
    for i, d in enumerate(datasets):
        if d.simulate is not None:
            _check_sim(f"{suite.path}: datasets[{i}] ({d.name}) with --world {_world_text(world)}: ", d.simulate)
    return dataclasses.replace(suite, datasets=datasets, world={**suite.world, **world})


def _plain_name(value, where: str) -> str:
    """A suite's or a dataset's name: a folder name under --out (no '/', not hidden). ConfigError otherwise."""
    if not isinstance(value, str):  # YAML reads `name: 101` as a number
        hint = f' (quote it: name: "{value}")' if isinstance(value, (int, float)) else ""
        raise ConfigError(f"{where}: name: expected text, got {type(value).__name__} {value!r}{hint}")
    if not value or "/" in value or value.startswith("."):
        raise ConfigError(f"{where}: name: expected a plain name (no '/'), got {value!r}")
    return value


def load_suite(path: str | os.PathLike) -> Suite:
    """Read and check a suite file: every key known, every file present, every simulate keyword one of
    :func:`mcl.simulate.simulate`'s with a value it accepts. Errors name the file and the key (ConfigError)."""
    from mcl.config import load_config
    from mcl.yamlfile import finite_number, read_yaml

    path = Path(path)
    doc = read_yaml(path, ConfigError)
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: expected a mapping with datasets: [...]")
    for k in doc:
        if k not in SUITE_KEYS:
            raise _unknown(f"{path}: ", k, SUITE_KEYS)
    suite_name = _plain_name(doc["name"], str(path)) if doc.get("name") is not None else path.stem
    base = path.resolve().parent
    root = base / str(doc["root"]) if doc.get("root") is not None else base
    modes = _modes(doc["modes"], f"{path}: modes") if "modes" in doc else ("tracking",)
    lost_m = _lost_m(doc["lost_m"], f"{path}: lost_m") if "lost_m" in doc else LOST_M
    entries = doc.get("datasets")
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{path}: datasets: expected a non-empty list")
    sim_keys = list(_sim_params())
    out, names = [], set()
    for i, e in enumerate(entries):
        if not isinstance(e, dict):
            raise ConfigError(f"{path}: datasets[{i}]: expected a mapping, got {e!r}")
        label = f"{path}: datasets[{i}]" + (f" ({e['name']})" if isinstance(e.get("name"), str) else "")
        for k in e:
            if k not in DATASET_KEYS:
                raise _unknown(f"{label}: ", k, DATASET_KEYS)
        name = _plain_name(e.get("name"), label)
        if name in names:
            raise ConfigError(f"{label}: name: {name!r} appears twice")
        names.add(name)
        d = Dataset(name=name, modes=modes, lost_m=lost_m)
        if "modes" in e:
            d.modes = _modes(e["modes"], f"{label}: modes")
        if "lost_m" in e:
            d.lost_m = _lost_m(e["lost_m"], f"{label}: lost_m")
        if "held_out" in e:
            if not isinstance(e["held_out"], bool):
                raise ConfigError(f"{label}: held_out: expected true or false, got {e['held_out']!r}")
            d.held_out = e["held_out"]
        if "set" in e:
            if not isinstance(e["set"], dict):
                raise ConfigError(f"{label}: set: expected a mapping of config keys, got {e['set']!r}")
            d.set = {str(k): v for k, v in e["set"].items()}
        if "initial_pose" in e:
            p = e["initial_pose"]
            if not isinstance(p, list) or len(p) != 3:
                raise ConfigError(f"{label}: initial_pose: expected [x, y, theta], got {p!r}")
            d.initial_pose = tuple(finite_number(v, f"{label}: initial_pose[{j}]", ConfigError) for j, v in enumerate(p))
        if "simulate" in e:
            kw = e["simulate"] if e["simulate"] is not None else {}
            if not isinstance(kw, dict):
                raise ConfigError(f"{label}: simulate: expected a mapping of mcl.simulate keywords, got {kw!r}")
            for k in kw:
                if k not in sim_keys:
                    raise _unknown(f"{label}: simulate.", k, sim_keys)
                _sim_value(f"{label}: simulate.", k, kw[k])
            _check_sim(f"{label}: ", kw)
            for k in ("map", "log", "bag", "truth", "truth_topic", "config"):
                if k in e:
                    raise ConfigError(f"{label}: {k}: not with simulate (the world gives map, log and truth)")
            d.simulate = dict(kw)
        else:
            if "config" in e:  # the data of a dataset config (its tuned parameters are not used)
                cpath = base / str(e["config"])
                if not cpath.is_file():
                    raise ConfigError(f"{label}: config: no such file {cpath}")
                dc = load_config(cpath)
                d.map, d.log, d.bag, d.truth, d.laser = dc.map, dc.log, dc.bag, dc.truth, dc.laser
                if dc.bag is not None:  # a bag's topic and frame names describe the data: kept, as its paths are
                    if dc.truth is None:
                        d.truth_topic = dc.topics.truth
                    for sec in ("topics", "frames"):
                        for f in dataclasses.fields(getattr(dc, sec)):
                            if (sec, f.name) != ("topics", "truth"):
                                d.set.setdefault(f"{sec}.{f.name}", getattr(getattr(dc, sec), f.name))
                if d.initial_pose is None and dc.filter.initial_pose is not None:
                    d.initial_pose = tuple(dc.filter.initial_pose)
            if "log" in e and "bag" in e:
                raise ConfigError(f"{label}: bag: give a CARMEN log (log) or a ROS bag (bag), not both")
            if "truth" in e and "truth_topic" in e:
                raise ConfigError(f"{label}: truth_topic: give a truth file (truth) or a bag's topic (truth_topic), "
                                  "not both")
            for k in ("map", "log", "bag", "truth"):
                if k in e:
                    setattr(d, k, str((root / str(e[k])).resolve()))
            if "log" in e:
                d.bag = None
            if "bag" in e:
                d.log = None
            if "truth" in e:
                d.truth_topic = None
            if "truth_topic" in e:
                if not isinstance(e["truth_topic"], str) or not e["truth_topic"]:
                    raise ConfigError(f"{label}: truth_topic: expected a topic name, got {e['truth_topic']!r}")
                d.truth, d.truth_topic = None, e["truth_topic"]
            if d.bag is not None and d.truth_topic is None and d.truth is None:
                raise ConfigError(f"{label}: truth: missing (give a truth file, or truth_topic: a topic of the bag)")
            # a bag's map is optional (its map topic stands in), and a truth topic is checked when it is read
            need = ["log", "map"] if d.bag is None else ["bag"] + (["map"] if d.map is not None else [])
            if d.truth_topic is None:
                need.append("truth")
            for k in need:
                v = getattr(d, k)
                if v is None:
                    raise ConfigError(f"{label}: {k}: missing (give map, log and truth, a bag and its truth, a config "
                                      "or simulate)")
                if not (Path(v).exists() if k == "bag" else Path(v).is_file()):  # a rosbag2 bag may be a folder
                    raise ConfigError(f"{label}: {k}: no such file {v}")
        out.append(d)
    return Suite(name=suite_name, path=path, datasets=out)


# ----------------------------------------------------------------------------- synthetic worlds


def _world_dir(cache: Path, d: Dataset, kidnapped: bool) -> Path:
    """The world's folder in the cache: named by its keywords and the simulator's code (``simulator_stamp``), so a
    world made by an older simulator is made again, not served."""
    from mcl.simulate import simulator_stamp

    kw = _sim_kwargs(d, kidnapped)
    h = hashlib.sha1((json.dumps(kw, sort_keys=True) + simulator_stamp()).encode()).hexdigest()[:10]
    return cache / f"{d.name}-{'kidnap-' if kidnapped else ''}{h}"


def _sim_kwargs(d: Dataset, kidnapped: bool) -> dict:
    """The keywords of :func:`mcl.simulate.simulate` for ``d``'s world in a mode: ``kidnap_at`` (the suite's, or
    half the duration) only in the kidnapped mode; the tracking and global worlds are driven without a kidnap."""
    kw = dict(d.simulate)
    if not kidnapped:
        kw.pop("kidnap_at", None)
    elif kw.get("kidnap_at") is None:
        duration = kw.get("duration", _sim_params()["duration"].default)
        kw["kidnap_at"] = float(duration) / 2
    return kw


def make_world(outdir: str, kw: dict) -> str:
    """Generate one synthetic world into ``outdir`` (written beside it, then renamed: never half there); an
    error of simulate names the world's folder."""
    import shutil
    import tempfile

    from mcl.simulate import simulate

    out = Path(outdir)
    if (out / "sim.yaml").is_file():
        return str(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}."))
    # A pool worker ignores Ctrl-C between runs (_worker_init); a world can take a minute to make, so here it
    # hears it: the world is dropped (made again on the next evaluation) and the pool's shutdown waits for nothing
    old = signal.signal(signal.SIGINT, signal.default_int_handler) if _IN_WORKER else None
    try:
        simulate(tmp, **kw)
        try:
            os.replace(tmp, out)
        except OSError:
            if not (out / "sim.yaml").is_file():
                raise
            # another evaluation sharing the --cache made the same world first (it is the same: one seed, one
            # set of parameters): use theirs
            shutil.rmtree(tmp, ignore_errors=True)
    except (MclError, RuntimeError) as e:
        shutil.rmtree(tmp, ignore_errors=True)
        raise MclError(f"world {out.name}: {e}") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)
    return str(out)


# ----------------------------------------------------------------------------- the plan


@dataclass
class Job:
    """One run: a dataset in a mode with a config and a seed."""

    dataset: str
    mode: str
    config: str  # label: default, the --config file's (config_label), or baseline
    seed: int
    cfg: object  # mcl.config.Config
    run_dir: str
    lost_m: float
    world: tuple[str, dict] | None = None  # (folder, simulate kwargs) to generate first
    kidnap_t: float | None = None  # synthetic kidnap time (from sim.yaml, once generated)
    kidnap_filter: bool = False  # real log: kidnap the filter at mid-truth
    sim_start: bool = False  # track from the synthetic world's start pose (sim.yaml)
    start_offset: tuple[float, float, float] | None = None  # --start-offset: added to a synthetic world's start pose
    fingerprint: str = ""

    @property
    def key(self) -> str:
        return f"{self.dataset}/{self.mode}/{self.config}/seed{self.seed}"


def _value_text(v) -> str:
    import yaml

    return yaml.safe_dump(v, default_flow_style=True, width=10**9).strip().removesuffix("...").strip()


def _bag_truth(suite: Suite, d: Dataset, cache: Path) -> str:
    """A bag dataset's ``truth_topic`` as a TUM file in ``cache/truth`` (read from the bag once per bag file
    and topic), so that runs, kidnaps and scores read it like any truth file. Errors name the suite and the
    dataset."""
    from mcl.config import load_config, shipped
    from mcl.datasets.rosbag import open_bag
    from mcl.trajectory import write_tum

    bag = Path(d.bag)
    st = bag.stat()
    key = hashlib.sha1(f"{bag.resolve()}|{st.st_size}|{st.st_mtime_ns}|{d.truth_topic}".encode()).hexdigest()[:10]
    dest = cache / "truth" / f"{d.name}-{key}.tum"
    if not dest.is_file():
        names = [f"{k}={_value_text(v)}" for k, v in d.set.items() if k.startswith(("topics.", "frames."))]
        try:
            cfg = load_config(shipped("configs/default.yaml"),
                              ["log=null", f"bag={bag}", f"topics.truth={d.truth_topic}", *names])
            t, poses = open_bag(bag, cfg.topics, cfg.frames).truth
        except MclError as e:
            raise ConfigError(f"{suite.path}: {d.name}: {e}") from None
        make_dir(dest.parent, "--cache")
        write_tum(dest, t, poses)
    return str(dest)


def _truth_start(truth: str) -> tuple[float, float, float]:
    from mcl.trajectory import read_tum

    t, p = read_tum(truth)
    if t.size == 0:
        raise ConfigError(f"{truth}: empty truth: give initial_pose in the suite")
    i = int(t.argmin())
    return float(p[0, i]), float(p[1, i]), float(p[2, i])


def make_dir(path: Path, option: str) -> None:
    """mkdir -p ``path``; MclError naming the option that gave it when it cannot be made."""
    if Path(path).exists() and not Path(path).is_dir():
        raise MclError(f"{option} {path}: exists and is not a folder")
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise MclError(f"{option} {path}: {e.strerror or e}") from None


def config_label(config: str | None, sets=(), baseline: bool = True) -> str:
    """The label (run folders, table) of the config under test: ``default``, else the --config file's stem. A file
    named like the baseline (``baseline.yaml``) that is not configs/baseline.yaml as shipped is labelled by its
    folder (``config`` when that is no plain name either), so that it neither replaces nor pairs as the baseline."""
    from mcl.config import shipped

    if config is None:
        return "default"
    path = Path(config)
    if path.stem != BASELINE or not baseline:
        return path.stem
    if not sets and path.resolve() == shipped("configs/baseline.yaml").resolve():
        return BASELINE  # the baseline itself: run once
    folder = path.resolve().parent.name
    return folder if folder and not folder.startswith(".") and folder not in (BASELINE, "default") else "config"


def seed_range(text: str) -> range:
    """``--seeds``: "K" is seeds 1..K, "A-B" seeds A..B (to add seeds to a finished evaluation, or to split one
    over machines). MclError naming the option otherwise."""
    first, sep, last = str(text).strip().partition("-")
    try:
        a, b = (int(first), int(last)) if sep else (1, int(first))
    except ValueError:
        raise MclError(f"--seeds {text}: expected K (seeds 1..K) or A-B (seeds A..B)") from None
    if a < 0 or b < max(a, 1):
        raise MclError(f"--seeds {text}: expected K >= 1, or 0 <= A <= B with B >= 1")
    return range(a, b + 1)


def plan(suite: Suite, *, config: str | None, sets: list[str], seeds: int | range, out: Path, cache: Path,
         modes: tuple[str, ...] | None = None, only: list[str] | None = None, baseline: bool = True,
         start_offset=None) -> list[Job]:
    """Every run of the suite, each with its validated Config (ConfigError naming the suite, the dataset
    and the key when a dataset's ``set`` or a --set is wrong). ``seeds``: K (seeds 1..K) or a range.
    ``start_offset`` (dx, dy, dtheta): every tracking and kidnapped start pose moved by it (m, m in the map frame,
    rad), a start clicked on a map; the runs are scored against the truth as ever."""
    from mcl.config import load_config, shipped

    seeds = seeds if isinstance(seeds, range) else range(1, int(seeds) + 1)

    default_cfg = Path(config) if config else shipped("configs/default.yaml")
    if not default_cfg.is_file():
        raise ConfigError(f"--config: no such file {default_cfg}")
    label = config_label(config, sets, baseline)
    configs = [(label, default_cfg, list(sets))]
    if baseline and label != BASELINE:
        configs.append((BASELINE, shipped("configs/baseline.yaml"), []))
    datasets = suite.datasets
    if only:
        names = {d.name for d in datasets}
        for n in only:  # a name, or a shell pattern (corridor-*)
            if not fnmatch.filter(names, n):
                hint = difflib.get_close_matches(n, sorted(names), n=1)
                raise ConfigError(f"--only: no dataset {n!r} in {suite.path}" + (f" (did you mean {hint[0]}?)" if hint else ""))
        datasets = [d for d in datasets if any(fnmatch.fnmatchcase(d.name, n) for n in only)]
    jobs: list[Job] = []
    for d in datasets:
        for mode in (m for m in d.modes if modes is None or m in modes):
            world = None
            kidnap_t = None
            if d.simulate is not None:
                wdir = _world_dir(cache, d, mode == "kidnapped")
                world = (str(wdir), _sim_kwargs(d, mode == "kidnapped"))
                data = {"map": str(wdir / "map.yaml"), "log": str(wdir / "log.clf"), "truth": str(wdir / "truth.tum")}
                pose = d.initial_pose  # None: from sim.yaml once generated
            else:
                truth = d.truth if d.truth is not None else _bag_truth(suite, d, cache)
                data = {"map": d.map, "log": d.log, "truth": truth}
                if d.bag is not None:
                    # the mode's start, not the bag's /initialpose (also for `mcl run` of the run's config.yaml)
                    data.update({"bag": d.bag, "topics.initial_pose": None})
                pose = d.initial_pose or _truth_start(truth)
            # a real log's kidnap is set per run (_finish_plan), never taken from a config: one that carried it (a run
            # folder's config.yaml) kidnapped every mode
            data["eval.kidnap_at"] = None
            for clabel, cpath, extra in configs:
                overrides = [f"{k}={'null' if v is None else v}" for k, v in data.items()]
                if d.laser is not None:
                    overrides.append(f"laser={d.laser}")
                overrides += [f"{k}={_value_text(v)}" for k, v in d.set.items()]
                overrides += extra
                if mode == "global":
                    overrides.append("filter.global_localization=true")
                else:
                    p = pose if pose is not None else (0.0, 0.0, 0.0)
                    if start_offset is not None and pose is not None:
                        p = _offset(p, start_offset)
                    overrides += [f"filter.initial_pose=[{p[0]!r}, {p[1]!r}, {p[2]!r}]", "filter.global_localization=false"]
                overrides.append("rerun.mode=off")
                for seed in seeds:
                    try:
                        cfg = load_config(cpath, overrides + [f"seed={seed}"])
                    except ConfigError as e:
                        raise ConfigError(f"{suite.path}: {d.name} ({clabel}): {e}") from None
                    run_dir = out / "runs" / d.name / mode / clabel / f"seed{seed}"
                    jobs.append(Job(d.name, mode, clabel, seed, cfg, str(run_dir), d.lost_m, world=world,
                                    kidnap_t=kidnap_t, kidnap_filter=(mode == "kidnapped" and d.simulate is None),
                                    sim_start=pose is None,
                                    start_offset=start_offset if pose is None and mode != "global" else None))
    return jobs


def _offset(pose, offset) -> tuple[float, float, float]:
    """``pose`` moved by ``offset`` (dx, dy in the map frame, dtheta), the heading wrapped."""
    from mcl.estimate import wrap_angle

    x, y, th = (float(a) + float(b) for a, b in zip(pose, offset))
    return x, y, float(wrap_angle(th))


def _finish_plan(jobs: list[Job]) -> None:
    """Once the worlds exist: their start poses and kidnap times; then every job's fingerprint."""
    import dataclasses

    import yaml

    from mcl.config import dump_config

    stamps: dict = {}
    mids: dict = {}  # mid-truth by path: read once
    for j in jobs:
        if j.world is not None:
            sim = yaml.safe_load(Path(j.world[0], "sim.yaml").read_text())
            if j.mode != "global" and j.sim_start:
                start = tuple(float(v) for v in sim["start_pose"])
                if j.start_offset is not None:
                    start = _offset(start, j.start_offset)
                f = dataclasses.replace(j.cfg.filter, initial_pose=start)
                j.cfg = dataclasses.replace(j.cfg, filter=f)
            if j.mode == "kidnapped":
                j.kidnap_t = float(sim["kidnap"]["t"])
        if j.kidnap_filter:
            try:
                j.cfg = _filter_kidnapped(j.cfg, mids)
            except MclError:  # an unreadable truth: the run's row says so (run_job tries again)
                pass
        text = dump_config(j.cfg) + f"\nmode: {j.mode}\nlost_m: {j.lost_m}\nkidnap: {j.kidnap_t} {j.kidnap_filter}\n"
        text += _data_stamp(j.cfg, stamps)
        j.fingerprint = hashlib.sha1(text.encode()).hexdigest()


def code_digest(root: Path | None = None) -> str:
    """A digest of mcl's own source (every ``.py`` file of the package, or of ``root``, by path and content), for
    the fingerprint: the version alone (pyproject.toml's) is not bumped by every change, and a row made by other
    code must run again, not be kept."""
    root = Path(__file__).resolve().parent if root is None else Path(root)
    h = hashlib.sha1()
    for f in sorted(root.rglob("*.py")):
        h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()[:12]


def _data_stamp(cfg, memo: dict) -> str:
    """The size and modification time of each file a run reads (the map and the image it names, the log or bag,
    the truth), mcl's version, a digest of its source (``code_digest``) and the numeric platform
    (``mcl.parallel.numeric_platform``), for the fingerprint: a truth corrected, a map redrawn in place, the filter's
    code changed or the folder resumed on a machine with other math runs again (its old row was kept, scored on the
    old file or made by the old code or arithmetic). ``memo``: path -> line (and a map's image path), shared by the
    jobs."""
    import yaml

    from mcl import __version__

    paths = [p for p in (cfg.map, cfg.log, cfg.bag, cfg.truth) if p]
    if cfg.map:
        if ("image", cfg.map) not in memo:  # the map's image, as the yaml names it (read once for every job)
            try:
                image = (yaml.safe_load(Path(cfg.map).read_text()) or {}).get("image")
            except (OSError, yaml.YAMLError, AttributeError):
                image = None
            memo["image", cfg.map] = str(Path(cfg.map).parent / image) if isinstance(image, str) else None
        if memo["image", cfg.map] is not None:
            paths.append(memo["image", cfg.map])
    if "code" not in memo:
        memo["code"] = code_digest()
    if "platform" not in memo:
        from mcl.parallel import numeric_platform  # imports numba: not at start-up

        memo["platform"] = json.dumps(numeric_platform(), sort_keys=True)
    lines = [f"mcl {__version__} {memo['code']}", f"platform {memo['platform']}"]
    for p in paths:
        if p not in memo:
            files = sorted(Path(p).iterdir()) if Path(p).is_dir() else [Path(p)]  # a rosbag2 folder: its files
            try:
                memo[p] = " ".join(f"{f.name} {f.stat().st_size} {f.stat().st_mtime_ns}" for f in files)
            except OSError:
                memo[p] = "missing"
        lines.append(f"{p}: {memo[p]}")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- scoring


def score(mode: str, t, e, *, lost_m: float, kidnap_t: float | None = None, kidnap_from: float | None = None) -> dict:
    """A run's figures from its position errors e (m) at times t (see the module doc). ``kidnap_from``: the time of
    the filter's last pose before ``kidnap_t``; the errors after it and before the kidnap are left out."""
    import numpy as np

    from mcl.evaluate import settle_time  # here: numba (mcl.estimate), which the parser of `mcl --help` need not import

    t, e = np.asarray(t, dtype=float), np.asarray(e, dtype=float)
    if mode == "kidnapped" and kidnap_from is not None:
        # interpolated between the track and the kidnapped cloud: neither the track's error nor the recovery's
        # (mit_csail with its scans stamped 0.05 s late: 12 m "before the kidnap", the track lost)
        across = (t > kidnap_from) & (t < kidnap_t)
        t, e = t[~across], e[~across]
    if e.size == 0:
        return {"rmse": None, "max": None, "lost": True, "conv_s": None, "ok": False}
    keep = np.ones(e.size, bool)
    if mode == "tracking":
        conv = settle_time(t, e, t[0], SETTLE_M)
        ok = None
        lost = bool(e.max() > lost_m)
    elif mode == "global":
        conv = settle_time(t, e, t[0], SETTLE_M, stay=lost_m)
        ok = conv is not None and conv <= WITHIN_S
        if conv is not None:
            keep = t >= t[0] + conv
        lost = not ok
    elif mode == "kidnapped":
        before = t < kidnap_t
        conv = settle_time(t[~before], e[~before], kidnap_t, SETTLE_M, stay=lost_m) if (~before).any() else None
        ok = conv is not None and conv <= WITHIN_S
        keep = (before | (t >= kidnap_t + conv)) if conv is not None else keep  # never recovered: every pose
        lost = (not ok) or bool(before.any() and e[before].max() > lost_m)
    else:  # pragma: no cover
        raise ValueError(mode)
    ek = e[keep] if keep.any() else e
    return {"rmse": float(math.sqrt(np.mean(ek**2))), "max": float(ek.max()), "lost": bool(lost),
            "conv_s": conv, "ok": ok}


# ----------------------------------------------------------------------------- a run (in a worker)


_IN_WORKER = False  # this process is a pool worker (_worker_init), whose parent hears Ctrl-C itself


def _worker_init() -> None:
    """A worker: one numba thread (the runs are the parallelism), Ctrl-C left to the runs."""
    import signal

    import numba

    global _IN_WORKER
    _IN_WORKER = True
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # between runs; a run catches it (runner._Interrupts)
    numba.set_num_threads(1)


def run_job(job: Job) -> dict:
    """Run one job with :func:`mcl.runner.run`; return its row (``interrupted`` or ``error`` when not done)."""
    import numpy as np

    from mcl.evaluate import evaluate, position_errors
    from mcl.runner import run
    from mcl.trajectory import atomic_write_text, read_tum

    row = {"dataset": job.dataset, "mode": job.mode, "config": job.config, "seed": job.seed}
    out = Path(job.run_dir)
    t0, c0 = time.perf_counter(), time.process_time()
    said: list[str] = []  # the run's own warning lines (a range window that leaves the laser nothing to score)

    def echo(msg: str) -> None:
        if msg.startswith("mcl: warning: "):
            said.append(msg.removeprefix("mcl: warning: "))

    try:
        with warnings.catch_warnings(record=True) as caught:  # the log's warnings go into the row
            warnings.simplefilter("always")
            # (a Job made without plan(), or whose truth _finish_plan could not read: its error is this row's)
            cfg = _filter_kidnapped(job.cfg) if job.kidnap_filter and job.cfg.eval.kidnap_at is None else job.cfg
            summary = run(cfg, out, progress=False, echo=echo, initial_pose_override=True)  # the mode's start
    except KeyboardInterrupt:
        return {**row, "interrupted": True}
    except MclError as e:
        return {**row, "error": str(e)}
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if summary["interrupted"]:
        return {**row, "interrupted": True}
    try:
        te, pe = read_tum(out / "trajectory.tum")
        tr, pr = read_tum(job.cfg.truth)  # its errors name the file
    except MclError as e:
        return {**row, "error": str(e)}
    try:
        tq, e_pos, _ = position_errors(te, pe, tr, pr)
        ate = evaluate(te, pe, tr, pr)
    except MclError as e:  # a truth that does not overlap the log: this run's error, the others go on
        return {**row, "error": f"truth {job.cfg.truth}: {e}"}
    kidnap_t = job.kidnap_t if job.kidnap_t is not None else summary.get("kidnap", {}).get("t")
    if job.mode == "kidnapped" and kidnap_t is None:  # (a TypeError in the scoring, which stopped the evaluation)
        return {**row, "error": f"{job.cfg.log or job.cfg.bag}: no update at or after the kidnap time "
                                f"{cfg.eval.kidnap_at or 0.0:.1f} s (the middle of the reference {job.cfg.truth}): the log "
                                "ends before it"}
    atomic_write_text(out / "errors.csv", "t,error_m\n" + "".join(f"{a:.6f},{b:.6f}\n" for a, b in zip(tq, e_pos)))
    before = te[te < kidnap_t] if kidnap_t is not None else te[:0]
    s = score(job.mode, tq, e_pos, lost_m=job.lost_m, kidnap_t=kidnap_t,
              kidnap_from=float(before.max()) if before.size else None)
    row.update(s)
    row.update({
        "ate_rmse": ate["ate_rmse"], "ate_max": ate["ate_max"], "lost_m": job.lost_m, "kidnap_t": kidnap_t,
        "wall_s": wall, "cpu_s": cpu, "particles": float(summary["particles_mean"]), "updates": summary["updates"],
        "scans": summary["scans"], "scored": int(np.size(tq)), "run_dir": str(out), "fingerprint": job.fingerprint,
        "warnings": sorted({str(w.message) for w in caught} | set(said)),
    })
    atomic_write_text(out / "row.json", json.dumps(row, indent=1) + "\n")
    if summary.get("late_signal"):
        # Ctrl-C while the run closed its outputs: the row is kept (a resume reads it back), and the signal goes
        # on to this process's own handler: KeyboardInterrupt here with --jobs 1, ignored in a pool worker (the
        # parent process got the same Ctrl-C). A process started with SIGINT ignored (a background job of a
        # script) has no handler to hand it to, but the run heard it (its own handler takes SIGINT whatever the
        # process ignores), so it stops here too: CI once saw exit 0 instead of 130 that way
        if signal.getsignal(signal.SIGINT) is signal.SIG_IGN and not _IN_WORKER:
            raise KeyboardInterrupt
        signal.raise_signal(signal.SIGINT)
    return row


def _filter_kidnapped(cfg, mids: dict | None = None):
    """``cfg`` with a real log's kidnap (mid-truth, ``KIDNAP_M``) as its own keys, ``eval.kidnap_at`` and
    ``eval.kidnap_m``: the run folder's config.yaml repeats the run (given to the runner from outside, a
    ``mcl run`` of it ran a plain tracking run). ``mids``: the mid-truths read so far, by path."""
    import dataclasses

    mids = {} if mids is None else mids
    if cfg.truth not in mids:
        mids[cfg.truth] = _mid_truth(cfg.truth)
    ev = dataclasses.replace(cfg.eval, kidnap_at=mids[cfg.truth], kidnap_m=KIDNAP_M)
    return dataclasses.replace(cfg, eval=ev)


def _mid_truth(truth: str) -> float:
    from mcl.trajectory import read_tum

    t, _ = read_tum(truth)
    return float(0.5 * (t.min() + t.max()))


# ----------------------------------------------------------------------------- aggregation and outputs


RUN_FIELDS = ("dataset", "mode", "config", "seed", "rmse", "max", "lost", "conv_s", "ok", "ate_rmse", "ate_max",
              "lost_m", "kidnap_t", "wall_s", "cpu_s", "particles", "updates", "scans", "scored", "run_dir", "error")
TABLE_FIELDS = ("dataset", "mode", "config", "runs", "rmse_median", "rmse_worst", "max_median", "max_worst",
                "lost", "failed", "conv_median", "conv_worst", "wall_median", "wall_worst", "cpu_median", "cpu_worst",
                "particles_median",
                "particles_worst")


def _worst(values, none_is_worst: bool = True):
    if any(v is None for v in values):
        return None if none_is_worst else max((v for v in values if v is not None), default=None)
    return max(values)


def _median(values):
    """Median with None (never converged) counting as +infinity; None when the median is such a run."""
    v = sorted(values, key=lambda x: math.inf if x is None else x)
    n = len(v)
    if n == 0:
        return None
    lo, hi = v[(n - 1) // 2], v[n // 2]
    if lo is None or hi is None:
        return None
    return 0.5 * (lo + hi)


def _lost(row: dict) -> bool:
    return "error" in row or bool(row["lost"])


def aggregate(rows: list[dict]) -> list[dict]:
    """The table: one row per dataset x mode x config, the median and the worst over seeds (the worst
    convergence time of a set where a run never converged is None, 'never'); lost counts the lost runs, a failed
    run (``error``) among them; the figures are over the runs that did not fail (None when every run failed)."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["dataset"], r["mode"], r["config"]), []).append(r)
    table = []
    for (ds, mode, cfg), rs in groups.items():
        ok = [r for r in rs if "error" not in r]

        def col(k):
            return [r[k] for r in ok]

        def med(k, worst=None):
            return (worst or statistics.median)(col(k)) if ok else None

        table.append({
            "dataset": ds, "mode": mode, "config": cfg, "runs": len(rs),
            "rmse_median": _median(col("rmse")), "rmse_worst": med("rmse", _worst),
            "max_median": _median(col("max")), "max_worst": med("max", _worst),
            "lost": sum(_lost(r) for r in rs), "failed": len(rs) - len(ok),
            "conv_median": _median(col("conv_s")), "conv_worst": med("conv_s", _worst),
            "wall_median": med("wall_s"), "wall_worst": med("wall_s", max),
            "cpu_median": _median([r.get("cpu_s") for r in ok]),
            "cpu_worst": _worst([r.get("cpu_s") for r in ok]) if ok else None,
            "particles_median": med("particles"), "particles_worst": med("particles", max),
        })
    return table


def totals(rows: list[dict]) -> list[dict]:
    """Over the whole suite, one row per mode x config: the runs kept (not lost; a failed run is lost) out of the
    runs, the failed ones, and the median RMSE over the others (the suite's verdict in one line, as the README's
    corpus table gives it)."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["mode"], r["config"]), []).append(r)
    order = {m: i for i, m in enumerate(MODES)}
    return [{"mode": mode, "config": cfg, "runs": len(rs), "kept": sum(not _lost(r) for r in rs),
             "failed": sum("error" in r for r in rs),
             "rmse_median": _median([r["rmse"] for r in rs if "error" not in r])}
            for (mode, cfg), rs in sorted(groups.items(), key=lambda kv: (order.get(kv[0][0], 99), kv[0][0]))]


def format_totals(rows: list[dict]) -> str:
    """``totals`` for the terminal: ``tracking   default  118/126 kept (94 %), RMSE median 0.071 m``."""
    t = totals(rows)
    if not t:
        return ""
    kept = [f"{r['kept']}/{r['runs']}" for r in t]
    wm, wc, wk = (max(len(x) for x in col) for col in ([r["mode"] for r in t], [r["config"] for r in t], kept))
    return "\n".join(
        f"{r['mode']:<{wm}}  {r['config']:<{wc}}  {k:>{wk}} kept ({100 * r['kept'] / r['runs']:.0f} %), "
        + (f"{r['failed']} failed, " if r.get("failed") else "")
        + f"RMSE median {_f(r['rmse_median'], '.3f', '-')} m" for r, k in zip(t, kept))


def format_failed(rows: list[dict]) -> str:
    """The failed runs, a line each (the table and the totals count them as lost)."""
    return "\n".join(f"failed (counted as lost): {r['dataset']}/{r['mode']}/{r['config']}/seed{r['seed']}: "
                     f"{r['error']}" for r in rows if "error" in r)


def against_baseline(rows: list[dict]) -> list[dict]:
    """For each config under test and mode, its runs paired with the baseline's (the same dataset, mode and seed):
    how many each keeps that the other loses, and the runs the baseline alone keeps (the check that matters when a
    config adds rules to the plain filter: a rule must not lose what the plain filter keeps). Failed runs are not
    paired (``format_failed`` lists them)."""
    rows = [r for r in rows if "error" not in r]
    base = {(r["dataset"], r["mode"], r["seed"]): r for r in rows if r["config"] == BASELINE}
    groups: dict[tuple, list[tuple[dict, dict]]] = {}
    for r in rows:
        b = base.get((r["dataset"], r["mode"], r["seed"]))
        if r["config"] != BASELINE and b is not None:
            groups.setdefault((r["mode"], r["config"]), []).append((r, b))
    order = {m: i for i, m in enumerate(MODES)}
    out = []
    for (mode, cfg), pairs in sorted(groups.items(), key=lambda kv: (order.get(kv[0][0], 99), kv[0])):
        alone = [{"dataset": r["dataset"], "seed": r["seed"], "max": r["max"], "conv_s": r["conv_s"],
                  "baseline_max": b["max"], "baseline_conv_s": b["conv_s"]}
                 for r, b in pairs if r["lost"] and not b["lost"]]
        out.append({"mode": mode, "config": cfg, "paired": len(pairs),
                    "config_alone": sum(1 for r, b in pairs if b["lost"] and not r["lost"]), "baseline_alone": alone})
    return out


def format_against_baseline(rows: list[dict]) -> str:
    """``against_baseline`` for the terminal, one line per mode and config (empty without baseline runs):
    ``tracking  default, 69 runs paired with the baseline's: kept by default alone 5, by the baseline alone 1: aces
    seed 2 (max 42.77 m; baseline 0.86 m)``."""

    def when(t):
        return "never" if t is None else f"at {t:.1f} s"

    lines = []
    for g in against_baseline(rows):
        if g["mode"] == "tracking":
            runs = [f"{a['dataset']} seed {a['seed']} (max {a['max']:.2f} m; baseline {a['baseline_max']:.2f} m)"
                    for a in g["baseline_alone"]]
        else:
            runs = [f"{a['dataset']} seed {a['seed']} (within {SETTLE_M} m {when(a['conv_s'])}; baseline "
                    f"{when(a['baseline_conv_s'])})" for a in g["baseline_alone"]]
        paired = f"{g['paired']} run{'s' * (g['paired'] != 1)} paired with the baseline's"
        lines.append(f"{g['mode']}  {g['config']}, {paired}: kept by {g['config']} alone {g['config_alone']}, "
                     f"by the baseline alone {len(runs)}" + (": " + ", ".join(runs) if runs else ""))
    return "\n".join(lines)


def _f(v, fmt: str, none: str = "never") -> str:
    return none if v is None else format(v, fmt)


def format_table(table: list[dict]) -> str:
    """The table for the terminal: median / worst over seeds."""
    head = ["dataset", "mode", "config", "RMSE m", "max m", "lost", "conv s", "wall s", "cpu s", "particles"]
    lines = []
    for r in table:
        never = "-" if r.get("failed") == r["runs"] else "never"  # every run failed: no time at all
        lines.append([
            r["dataset"], r["mode"], r["config"],
            f"{_f(r['rmse_median'], '.3f', '-')} / {_f(r['rmse_worst'], '.3f', '-')}",
            f"{_f(r['max_median'], '.2f', '-')} / {_f(r['max_worst'], '.2f', '-')}",
            f"{r['lost']}/{r['runs']}",
            f"{_f(r['conv_median'], '.1f', never)} / {_f(r['conv_worst'], '.1f', never)}",
            f"{_f(r['wall_median'], '.1f', '-')} / {_f(r['wall_worst'], '.1f', '-')}",
            f"{_f(r.get('cpu_median'), '.1f', '-')} / {_f(r.get('cpu_worst'), '.1f', '-')}",
            f"{_f(r['particles_median'], '.0f', '-')} / {_f(r['particles_worst'], '.0f', '-')}",
        ])
    sub = ["", "", "", "med / worst", "med / worst", "runs"] + ["med / worst"] * 4
    widths = [max(len(x) for x in col) for col in zip(head, sub, *lines)]
    fmt = lambda cells: "  ".join(c.ljust(w) if i < 3 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))
    out = [fmt(head), fmt(sub), "  ".join("-" * w for w in widths)]
    out += [fmt(c) for c in lines]
    return "\n".join(out)


def _csv(rows: list[dict], fields) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(fields), extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in fields})
    return buf.getvalue()


def write_results(out: Path, suite: Suite, rows: list[dict], planned: int) -> list[dict]:
    """results.json, results.csv, table.csv, table.txt (each written atomically); returns the table."""
    from mcl.trajectory import atomic_write_text

    table = aggregate(rows)
    legend = (f"lost: tracking max error > lost_m; global / kidnapped: not below {SETTLE_M} m within "
              f"{WITHIN_S:g} s of the start / kidnap. conv: s until the error is below {SETTLE_M} m and stays "
              "below lost_m (kidnapped: from the kidnap).")
    doc = {"suite": suite.name, "suite_file": str(suite.path), "planned_runs": planned, "finished_runs": len(rows),
           "failed_runs": sum("error" in r for r in rows),
           "settle_m": SETTLE_M, "within_s": WITHIN_S, "runs": rows, "table": table, "totals": totals(rows),
           "against_baseline": against_baseline(rows)}
    if suite.world:
        doc["world"] = suite.world
    atomic_write_text(out / "results.json", json.dumps(doc, indent=1) + "\n")
    atomic_write_text(out / "results.csv", _csv(rows, RUN_FIELDS))
    atomic_write_text(out / "table.csv", _csv(table, TABLE_FIELDS))
    vs, failed = format_against_baseline(rows), format_failed(rows)
    atomic_write_text(out / "table.txt", format_table(table) + "\n" + (failed + "\n" if failed else "") + legend
                      + "\n\n" + format_totals(rows) + "\n" + (vs + "\n" if vs else ""))
    return table


def plot_errors(out: Path, rows: list[dict]) -> list[Path]:
    """plots/DATASET.png: the position error over time of every run (but the failed), one panel per mode; the
    plots of datasets not in ``rows`` (a previous evaluation's, another --only) are removed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from mcl.trajectory import atomic_write_bytes

    colors = {}
    written = []
    rows = [r for r in rows if "error" not in r]
    for ds in dict.fromkeys(r["dataset"] for r in rows):
        rs = [r for r in rows if r["dataset"] == ds]
        modes = list(dict.fromkeys(r["mode"] for r in rs))
        fig, axes = plt.subplots(len(modes), 1, figsize=(9, 2.8 * len(modes)), squeeze=False)
        for ax, mode in zip(axes[:, 0], modes):
            for r in (r for r in rs if r["mode"] == mode):
                path = Path(r["run_dir"]) / "errors.csv"
                if not path.is_file():
                    continue
                a = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
                c = colors.setdefault(r["config"], f"C{len(colors)}")
                ax.plot(a[:, 0], np.maximum(a[:, 1], 1e-3), color=c, lw=0.8, alpha=0.8,
                        label=f"{r['config']} seed {r['seed']}")
                if r.get("kidnap_t") is not None:
                    ax.axvline(r["kidnap_t"], color="k", ls=":", lw=0.8)
            ax.axhline(SETTLE_M, color="gray", ls="--", lw=0.6)
            ax.set_yscale("log")
            ax.set_ylabel("position error (m)")
            ax.set_title(f"{ds}: {mode}", fontsize=9)
            ax.legend(fontsize=6, ncol=4, loc="upper right")
        axes[-1, 0].set_xlabel("time (s)")
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=90)
        plt.close(fig)
        (out / "plots").mkdir(parents=True, exist_ok=True)
        p = out / "plots" / f"{ds}.png"
        atomic_write_bytes(p, buf.getvalue())
        written.append(p)
    for old in (out / "plots").glob("*.png"):
        if old not in written:
            old.unlink(missing_ok=True)
    return written


# ----------------------------------------------------------------------------- the command

EVAL_OUTPUTS = ("results.json", "results.csv", "table.csv", "table.txt", "plots", "runs", "worlds")


def check_eval_out_dir(out: Path) -> None:
    """Before any run: ``out`` must be new, empty, or an evaluation's folder (its runs, results or world cache in
    it, and nothing else: an evaluation again into it resumes or replaces them). ConfigError otherwise: an evaluation
    overwrote a user's results.csv and deleted the PNGs of a plots/ folder it had not made."""
    from mcl.trajectory import check_folder_holds

    names = check_folder_holds(out, "--out", lambda n: n in EVAL_OUTPUTS or (n.startswith(".") and n.endswith(".tmp")),
                               "an evaluation's outputs")
    if names and not {"results.json", "runs", "worlds"} & set(names):  # worlds: its cache, made before any run
        raise ConfigError(f"--out {out}: the folder holds {', '.join(names)} but no results.json, runs/ or "
                          "worlds/: not an mcl evaluation's folder; choose a new or empty folder")


def _finished(job: Job) -> dict | None:
    p = Path(job.run_dir) / "row.json"
    try:
        row = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    return row if row.get("fingerprint") == job.fingerprint else None


class TermAsInterrupt:
    """While an evaluation (or a ``mcl tune`` study) runs, SIGTERM to its process (``kill PID``, ``timeout``)
    stops it as Ctrl-C does: the finished rows kept, exit status 130. (Without this the process died at once and
    its pool's workers ran on, orphaned, each to the end of its run.) So does SIGINT in a process started with it
    ignored (a background job of a script: ``mcl eval ... &`` then ``kill -INT``), which Python would not see."""

    def __enter__(self):
        self._old_int = None
        try:
            self._old = signal.signal(signal.SIGTERM, self._handler)
            if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
                self._old_int = signal.signal(signal.SIGINT, signal.default_int_handler)
        except ValueError:  # not the main thread: the default handling stays
            self._old = None
        return self

    @staticmethod
    def _handler(signum, frame):
        raise KeyboardInterrupt

    def __exit__(self, *exc) -> None:
        if self._old is not None:
            signal.signal(signal.SIGTERM, self._old)
        if self._old_int is not None:
            signal.signal(signal.SIGINT, self._old_int)


def interrupt_workers() -> None:
    """Ctrl-C to this process's worker processes: each stops its run at the next update and returns it
    ``interrupted`` (an idle worker ignores it). A terminal's Ctrl-C reaches them already (a second one is only
    noted); a signal sent to this process alone (``kill -INT PID``, SIGTERM) reaches them only so, and the pool's
    shutdown would otherwise wait for every run in flight to finish."""
    import multiprocessing

    for child in multiprocessing.active_children():
        try:
            os.kill(child.pid, signal.SIGINT)
        except (ProcessLookupError, TypeError):  # gone already, or not started
            pass


def _stderr(msg: str) -> None:
    print(msg, file=sys.stderr)


def evaluate_suite(suite_path, *, config=None, sets=(), seeds=1, jobs=1, out=None, cache=None, modes=None,
                   only=None, baseline=True, world=None, progress=None, echo=print, warn=_stderr,
                   start_offset=None) -> int:
    """``mcl eval --suite``: plan, generate the worlds, run what is not finished, write and print the table (and
    ``warn`` the errors). A failed run is a row with its ``error`` (not saved in its folder: a resume runs it
    again), counted as lost. Returns the exit status (0, 130 interrupted, 2 when a run failed). ``--out`` is locked
    while it runs: two evaluations into one folder counted each other's runs as failed."""
    with contextlib.ExitStack() as held:  # the --out lock, once taken
        return _evaluate_suite(suite_path, config=config, sets=sets, seeds=seeds, jobs=jobs, out=out, cache=cache,
                               modes=modes, only=only, baseline=baseline, world=world, progress=progress, echo=echo,
                               warn=warn, start_offset=start_offset, held=held)


def _evaluate_suite(suite_path, *, config, sets, seeds, jobs, out, cache, modes, only, baseline, world, progress,
                    echo, warn, start_offset, held: contextlib.ExitStack) -> int:
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool
    import multiprocessing

    from tqdm import tqdm

    suite = with_world(load_suite(suite_path), world or {})
    # absolute: the runs' configs name the worlds' files, and a config's relative paths are its own folder's
    out = Path(out).absolute() if out else Path.cwd() / "runs" / f"suite-{suite.name}"
    cache = Path(cache).absolute() if cache else out / "worlds"
    job_list = plan(suite, config=config, sets=list(sets), seeds=seeds, out=out, cache=cache, modes=modes,
                    only=only, baseline=baseline, start_offset=start_offset)
    if not job_list:
        raise ConfigError(f"{suite.path}: no run left (modes {', '.join(modes or ())} not in any selected dataset)")
    missing = [m for m in (modes or ()) if all(j.mode != m for j in job_list)]
    if missing:  # asked for, and run nowhere: said rather than dropped
        echo(f"--modes: {', '.join(missing)}: in no selected dataset of {suite.path}: not run")
    label = job_list[0].config
    if config is not None and label != Path(config).stem:
        echo(f"the config under test is labelled {label!r} ({config} is not configs/baseline.yaml, which runs as "
             f"{BASELINE!r})")
    if suite.world:
        echo(f"every generated world with {_world_text(suite.world)} (--world)")
    if start_offset is not None:
        dx, dy, dth = start_offset
        echo(f"every tracking and kidnapped start moved by {dx:g} m, {dy:g} m, {dth:g} rad (--start-offset)")
    # the inputs are checked: now the folders (--out checked first: the default cache is in it, and a --cache that
    # cannot be made leaves no --out behind)
    from mcl.trajectory import check_writable_folder

    check_writable_folder(out, f"--out {out}")
    check_eval_out_dir(out)
    # the default cache, OUT/worlds, after --out: "--cache /proc/x/worlds" named an option never typed for an --out
    # that cannot be made
    inside = Path(cache).parent == Path(out)
    if inside:
        make_dir(out, "--out")
    if any(j.world is not None for j in job_list):
        make_dir(cache, "--cache")
    if not inside:
        make_dir(out, "--out")
    from mcl.runner import folder_lock

    held.enter_context(folder_lock(out, f"--out {out}: another mcl eval is writing in this folder now: wait for it "
                                        "to end, or choose another --out"))
    ctx = multiprocessing.get_context("spawn")  # fresh workers: no numba threads inherited from a fork
    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_worker_init) if jobs > 1 else None
    results: dict[str, dict] = {}
    errors: list[str] = []
    cut: list[Job] = []  # the runs of a broken pool
    interrupted = False
    term = TermAsInterrupt().__enter__()
    try:
        worlds = {j.world[0]: j.world[1] for j in job_list if j.world is not None}
        todo_worlds = {w: kw for w, kw in worlds.items() if not Path(w, "sim.yaml").is_file()}
        if todo_worlds:
            echo(f"generating {len(todo_worlds)} synthetic world(s) into {cache}")
            try:
                if pool is None:
                    for w, kw in todo_worlds.items():
                        make_world(w, kw)
                else:
                    list(pool.map(make_world, todo_worlds.keys(), todo_worlds.values()))
            except MclError as e:  # make_world's: the world named
                given = f" (with --world {_world_text(suite.world)})" if suite.world else ""
                raise MclError(f"{suite.path}{given}: {e}") from None
        _finish_plan(job_list)
        todo = []
        for j in job_list:
            row = _finished(j)
            if row is not None:
                results[j.key] = row
            else:
                todo.append(j)
        if results:
            echo(f"{len(results)} of {len(job_list)} runs already finished in {out}: not run again")
        order = {j.key: i for i, j in enumerate(job_list)}

        def save():
            rows = sorted(results.values(), key=lambda r: order[f"{r['dataset']}/{r['mode']}/{r['config']}/seed{r['seed']}"])
            return rows, write_results(out, suite, rows, len(job_list))

        bar = tqdm(total=len(todo), unit="run", disable=(None if progress is None else not progress), dynamic_ncols=True)

        def take(job: Job, row: dict) -> None:
            nonlocal interrupted
            if row.get("interrupted"):
                interrupted = True
                return
            if "error" in row:  # tabled as a lost run, and said on stderr
                errors.append(f"{job.key}: {row['error']}")
                row = {**row, "lost": True, "lost_m": job.lost_m, "run_dir": job.run_dir}
            results[job.key] = row
            save()
            bar.update(1)

        try:
            if pool is None:
                for j in todo:
                    take(j, run_job(j))
                    if interrupted:
                        break
            else:
                futures = {pool.submit(run_job, j): j for j in todo}
                pending = set(futures)
                try:
                    while pending:
                        done, pending = wait(pending, return_when=FIRST_COMPLETED)
                        dead = []
                        for f in done:
                            try:
                                row = f.result()
                            except BrokenProcessPool:
                                dead.append(futures[f].key)
                                continue
                            take(futures[f], row)
                        if dead:
                            # A worker was killed (the kernel's OOM killer, a signal): the pool is unusable and
                            # every run in flight is cut; their rows are read back once the pool is shut down
                            cut = [futures[f] for f in done if futures[f].key in dead] + [futures[f] for f in pending]
                            pending = set()
                except KeyboardInterrupt:
                    interrupted = True
                    for f in pending:
                        f.cancel()
                    interrupt_workers()
                    pool.shutdown(wait=True, cancel_futures=True)
                    for f in pending:
                        if f.done() and not f.cancelled() and f.exception() is None:
                            take(futures[f], f.result())
        except KeyboardInterrupt:
            interrupted = True
        finally:
            bar.close()
    except KeyboardInterrupt:  # while the worlds were made (no row yet)
        interrupted = True
        raise
    finally:
        if pool is not None:
            if interrupted:
                interrupt_workers()
            pool.shutdown(wait=True, cancel_futures=True)
        term.__exit__()
    if cut:
        # A cut run may have written its row.json before the pool broke, and a surviving worker goes on with the
        # runs queued to it until the shutdown: keep the finished rows and say which runs were cut.
        unfinished = []
        for j in sorted(cut, key=lambda j: order[j.key]):
            row = _finished(j)
            if row is not None:
                results[j.key] = row
            else:
                unfinished.append(j.key)
        if unfinished:
            errors.append(f"a worker process died abruptly (killed by the system, e.g. out of memory) with "
                          f"{len(unfinished)} run(s) unfinished, first {unfinished[0]}; the finished runs are saved, "
                          "run the same command again (with fewer --jobs) to resume")
    rows, table = save()
    plot_errors(out, rows)
    echo(format_table(table))
    failed = format_failed(rows)
    if failed:
        echo(failed)
    if rows:
        echo(format_totals(rows))
        vs = format_against_baseline(rows)
        if vs:
            echo(vs)
    n_failed = sum("error" in r for r in rows)
    echo(f"lost: tracking max error > lost_m; global / kidnapped: not below {SETTLE_M} m within {WITHIN_S:g} s. "
         f"{len(rows)} of {len(job_list)} runs" + (f" ({n_failed} failed)" if n_failed else "")
         + f"; results in {out} (results.json, results.csv, table.csv, plots/)")
    for e in errors:
        warn(f"error: {e}")
    if interrupted:
        echo("interrupted: the finished runs are saved; run the same command again to resume")
        return 130
    return 2 if errors else 0


PER_RUN_KEYS = ("map", "log", "bag", "truth", "seed", "filter.initial_pose", "filter.global_localization",
                "eval.kidnap_at", "eval.kidnap_m")


def check_sets(sets) -> None:
    """ConfigError for a ``--set`` of a key the suite sets for each run: the dataset's files, the mode's start, the
    seed (--seeds) and the recording (off). Taken as given, ``seed``, ``filter.initial_pose`` and ``rerun.mode`` were
    ignored without a word, and ``truth`` scored every dataset against one file."""
    for text in sets:
        key = str(text).split("=", 1)[0].strip()
        if key in PER_RUN_KEYS or key.split(".")[0] == "rerun":
            how = {"seed": "give --seeds", "filter.initial_pose": "each mode starts its own way",
                   "filter.global_localization": "each mode starts its own way",
                   "eval.kidnap_at": "the kidnapped mode kidnaps a real log's filter mid-way",
                   "eval.kidnap_m": f"the kidnapped mode kidnaps a real log's filter {KIDNAP_M:g} m away"}.get(
                key, "runs record nothing" if key.startswith("rerun") else "each dataset names its own")
            raise ConfigError(f"--set {key}: the suite sets it for each run ({how})")


def run_from_args(args) -> int:
    """``mcl eval --suite`` from the parsed command line (mcl.cli)."""
    check_sets(args.set)
    seeds = seed_range(args.seeds)
    cores = os.cpu_count() or 1
    jobs = cores if args.jobs is None else args.jobs
    if jobs < 1:
        raise MclError(f"--jobs: expected >= 1, got {jobs}")
    if jobs > cores:  # accepted (a run may wait on its disk), but said: the runs share the cores
        print(f"mcl: warning: --jobs {jobs} on {cores} cores: the runs share them, each slower (their wall "
              "and CPU figures then tell the machine's load, not the config's cost)", file=sys.stderr)
    modes = None
    if args.modes:
        modes = parse_modes(args.modes)
    only = [n.strip() for n in args.only.split(",") if n.strip()] if args.only is not None else None
    if only == []:  # --only '' selected every dataset
        raise ConfigError("--only: names no dataset (give NAME,... or a pattern such as 'corridor-*')")
    world = world_overrides(getattr(args, "world", None))
    offset = getattr(args, "start_offset", None)
    if offset is not None and not all(math.isfinite(v) for v in offset):
        raise MclError(f"--start-offset: expected three finite numbers, got {' '.join(map(str, offset))}")
    return evaluate_suite(args.suite, config=args.config, sets=args.set, seeds=seeds, jobs=jobs,
                          out=args.out, cache=args.cache, modes=modes, only=only, baseline=args.baseline, world=world,
                          progress=False if args.no_progress else None,
                          start_offset=tuple(offset) if offset is not None else None)
