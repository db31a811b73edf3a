"""Issue 11: mcl behaves like a real package (clean warnings, config files validated on their own, --version,
package data, first-run compile message, a user cache folder for numba)."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import pytest

from mcl.cli import main
from mcl.config import PROJECT_ROOT

DEMO = PROJECT_ROOT / "data" / "demo"


def _short_bad_log(dst: Path, scans: int = 40) -> None:
    """The demo's first `scans` scans, with NaN readings in scan 10 and time running backwards at scan 20."""
    out, k = [], -1
    for line in (DEMO / "log.clf").read_text().splitlines():
        f = line.split()
        if f and f[0] == "FLASER":
            k += 1
            if k == scans:
                break
            n = int(f[1])
            if k == 10:
                f[2:2 + n:5] = ["nan"] * len(f[2:2 + n:5])
            if k == 20:
                f[-3] = f"{float(f[-3]) - 5.0:.6f}"
                f[-1] = f"{float(f[-1]) - 5.0:.6f}"
            line = " ".join(f)
        out.append(line + "\n")
    dst.write_text("".join(out))


def test_cli_prints_each_warning_as_one_clean_line(tmp_path, capsys):
    # Today: "…/mcl/filter.py:263: RuntimeWarning: time ran backwards …" plus the source line.
    _short_bad_log(tmp_path / "bad.clf")
    rc = main(["run", "--map", str(DEMO / "map.yaml"), "--log", str(tmp_path / "bad.clf"), "--out",
               str(tmp_path / "out"), "--rerun", "off", "--no-progress", "--particles", "200",
               "--initial-pose", "2.062007", "10.160616", "-0.218311", "--set", "filter.update_min_d=0",
               "--set", "filter.update_min_a=0"])
    assert rc == 0
    err = capsys.readouterr().err.splitlines()
    warned = [line for line in err if line.startswith("mcl: warning: ")]
    assert len(warned) == 2, err  # one line each: NaN ranges, time backwards
    assert any("NaN or infinite ranges" in line for line in warned) and any("backwards" in line for line in warned)
    assert not any("RuntimeWarning" in line or ".py:" in line or "warnings.warn" in line for line in err), err


def test_library_callers_still_get_a_runtime_warning():
    from mcl.degenerate import InputGuard
    from mcl.errors import MclWarning

    with pytest.warns(RuntimeWarning, match="time ran backwards") as rec:
        InputGuard(2.0).event("time_backwards", "time ran backwards")
    assert rec[0].category is MclWarning
    with warnings.catch_warnings():
        warnings.simplefilter("error", MclWarning)
        with pytest.raises(MclWarning):
            InputGuard(2.0).event("nan_ranges", "NaN")


def test_a_bad_value_in_the_config_file_is_rejected_even_when_an_option_overrides_it(tmp_path, capsys):
    # Today `--particles 100` replaces `particles: lots` before validation and the bad file is accepted.
    bad = tmp_path / "bad.yaml"
    bad.write_text("filter:\n  particles: lots\n")
    rc = main(["run", str(bad), "--particles", "100", "--rerun", "off", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err == f"mcl: error: {bad}:2: filter.particles: expected an integer, got 'lots'", err
    assert not (tmp_path / "out").exists()
    from mcl.config import load_config
    from mcl.errors import ConfigError

    bad.write_text("filter:\n  particels: 100\n")
    with pytest.raises(ConfigError, match=r"bad.yaml:2: filter.particels: unknown key \(did you mean particles\?\)"):
        load_config(bad, ["filter.particels=200"])
    # a value the file leaves valid may still be replaced, and a bad --set still names the --set
    bad.write_text("filter:\n  particles: 300\n")
    assert load_config(bad, ["filter.particles=100"]).filter.particles == 100
    with pytest.raises(ConfigError, match=r"^--set filter.particles=x: filter.particles: expected an integer"):
        load_config(bad, ["filter.particles=x"])


def test_version_is_the_installed_distributions(capsys, monkeypatch):
    import importlib.metadata
    import tomllib

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    declared = tomllib.loads((PROJECT_ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert capsys.readouterr().out.strip() == f"mcl {declared}"
    # read from the metadata, not a copy in the code that can drift from pyproject.toml
    monkeypatch.setattr(importlib.metadata, "version", lambda name: "9.8.7" if name == "mcl" else "?")
    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.strip() == "mcl 9.8.7"


def _complete(line: str, tmp_path: Path) -> list[str]:
    """What the shell hook of `register-python-argcomplete mcl` would offer for `line` (a subprocess: argcomplete
    writes to file descriptors pytest uses)."""
    import os
    import subprocess
    import sys

    out = tmp_path / "completions"
    env = dict(os.environ, _ARGCOMPLETE="1", _ARGCOMPLETE_IFS="\n", COMP_LINE=line, COMP_POINT=str(len(line)),
               _ARGCOMPLETE_STDOUT_FILENAME=str(out))
    r = subprocess.run([sys.executable, "-m", "mcl"], env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return out.read_text().split()


def test_shell_completion_through_argcomplete(tmp_path):
    pytest.importorskip("argcomplete")
    assert _complete("mcl run --par", tmp_path) == ["--particles"]
    assert _complete("mcl ca", tmp_path) == ["calibrate"]
    assert _complete("mcl calibrate s", tmp_path) == ["sensor"]


def test_config_default_prints_the_commented_default_config_and_show_a_runs(tmp_path, capsys):
    assert main(["config", "default"]) == 0
    text = capsys.readouterr().out
    assert text == (PROJECT_ROOT / "configs" / "default.yaml").read_text()
    # a copy made anywhere still finds the demo (paths fall back to the default config's folder)
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "my.yaml").write_text(text)
    from mcl.config import dump_config, load_config

    cfg = load_config(tmp_path / "elsewhere" / "my.yaml")
    assert Path(cfg.map) == (DEMO / "map.yaml").resolve() and Path(cfg.log) == (DEMO / "log.clf").resolve()
    # show: a run folder's config.yaml, resolved (every key, absolute paths)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text(dump_config(load_config(None, ["filter.particles=123", "seed=7"])))
    assert main(["config", "show", str(run_dir)]) == 0
    shown = capsys.readouterr().out
    assert shown == dump_config(load_config(None, ["filter.particles=123", "seed=7"])) and "particles: 123" in shown
    assert main(["config", "show", str(tmp_path)]) == 2
    assert capsys.readouterr().err.strip() == f"mcl: error: {tmp_path}: no config.yaml (not a run folder?)"


def test_the_wheel_ships_the_default_config_and_the_demo(tmp_path):
    # pip wheel . builds what `pip install .` installs; the installed package must find the default config and
    # the demo with no repository beside it (today: `mcl run` from another folder says "map: no map given").
    import os
    import subprocess
    import sys
    import zipfile

    r = subprocess.run([sys.executable, "-m", "pip", "wheel", str(PROJECT_ROOT), "--no-deps", "-q", "-w",
                        str(tmp_path / "whl")], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    (wheel,) = (tmp_path / "whl").glob("mcl-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    demo = {f"mcl/_project/data/demo/{f.name}" for f in DEMO.iterdir() if f.is_file()}
    assert {"mcl/_project/configs/default.yaml", "mcl/_project/configs/baseline.yaml"} | demo <= names, sorted(names)
    assert {"mcl/_project/data/demo/map.yaml", "mcl/_project/data/demo/log.clf"} <= demo
    # unpacked alone (no repository beside it), from an empty folder: the default config and its demo paths
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    empty = tmp_path / "empty"
    empty.mkdir()
    code = ("import mcl.config as c; from mcl.cli import _project_default_config as d; p = d(); "
            "cfg = c.load_config(p); print(p); print(cfg.map); print(cfg.log)")
    r = subprocess.run([sys.executable, "-c", code], cwd=empty, capture_output=True, text=True, timeout=120,
                       env=dict(os.environ, PYTHONPATH=str(site)))
    assert r.returncode == 0, r.stderr
    cfg_path, map_path, log_path = r.stdout.split()
    assert cfg_path == str(site / "mcl" / "_project" / "configs" / "default.yaml")
    assert map_path == str(site / "mcl" / "_project" / "data" / "demo" / "map.yaml") and Path(map_path).is_file()
    assert Path(log_path).is_file()


def test_numba_cache_dir_is_a_user_folder_when_the_package_is_read_only(tmp_path, monkeypatch):
    from mcl import numba_cache as nc

    kernels = tmp_path / "site" / "mcl" / "kernels"
    kernels.mkdir(parents=True)
    home = str(Path.home())
    # writable package folder: numba's own in-tree cache (kernels/__pycache__)
    assert nc.choose_cache_dir({}, kernels, writable=lambda p: True) is None
    # read-only (a system site-packages): the user cache folder, XDG_CACHE_HOME first
    assert nc.choose_cache_dir({"XDG_CACHE_HOME": "/x/cache"}, kernels, writable=lambda p: False) == \
        Path("/x/cache/mcl/numba")
    assert nc.choose_cache_dir({"XDG_CACHE_HOME": ""}, kernels, writable=lambda p: False) == \
        Path(home) / ".cache" / "mcl" / "numba"
    # the user's own NUMBA_CACHE_DIR wins
    assert nc.choose_cache_dir({"NUMBA_CACHE_DIR": "/mine"}, kernels, writable=lambda p: False) == Path("/mine")
    # configure() sets it for numba, which reads it when imported (here into a copy of the environment)
    monkeypatch.setattr(nc, "_writable", lambda p: False)
    env = {"XDG_CACHE_HOME": str(tmp_path / "xdg")}
    nc.configure(env)
    assert env["NUMBA_CACHE_DIR"] == str(tmp_path / "xdg" / "mcl" / "numba")
    env = {"NUMBA_CACHE_DIR": "/mine"}
    nc.configure(env)
    assert env == {"NUMBA_CACHE_DIR": "/mine"}
    monkeypatch.setattr(nc, "_writable", lambda p: True)
    env = {}
    nc.configure(env)
    assert env == {}


def test_cold_cache_detection_uses_numbas_own_cache_layout(tmp_path):
    from numba.core.caching import _CacheLocator

    from mcl import numba_cache as nc

    kernels = tmp_path / "mcl" / "kernels"
    kernels.mkdir(parents=True)
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    folder = nc.kernels_cache_folder(env, kernels)
    # the subfolder numba's UserProvidedCacheLocator picks for a file in kernels/
    assert folder == tmp_path / "cache" / _CacheLocator.get_suitable_cache_subpath(str(kernels / "likelihood.py"))
    assert nc.kernels_cache_folder({}, kernels) == kernels / "__pycache__"
    assert nc.cache_is_cold(env, kernels)
    folder.mkdir(parents=True)
    for m in ("likelihood.likelihood_field_loglik_serial-15", "motion.sample_odometry-39"):
        (folder / f"{m}.py311.nbi").write_bytes(b"")
    assert nc.cache_is_cold(env, kernels)  # resample still to compile
    (folder / "resample.merge_positions-25.py311.nbi").write_bytes(b"")
    assert not nc.cache_is_cold(env, kernels)


def test_mcl_run_says_once_that_it_compiles_the_kernels_when_the_cache_is_cold(tmp_path, capsys, monkeypatch):
    from mcl import numba_cache as nc

    # numba read its cache folder at import (warm, in-tree, for this process); mcl looks into the one given here
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    _short_bad_log(tmp_path / "short.clf", scans=10)
    argv = ["run", "--map", str(DEMO / "map.yaml"), "--log", str(tmp_path / "short.clf"), "--rerun", "off",
            "--no-progress", "--particles", "100", "--initial-pose", "2.062007", "10.160616", "-0.218311"]
    assert main(argv + ["--out", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err.count("mcl: compiling kernels (once; cached for later runs)") == 1, err
    folder = nc.kernels_cache_folder()
    folder.mkdir(parents=True)
    for m in nc.RUN_KERNELS:
        (folder / f"{m}.k-1.py311.nbi").write_bytes(b"")
    assert main(argv + ["--out", str(tmp_path / "b")]) == 0
    assert not any("compiling" in line for line in capsys.readouterr().err.splitlines())


def test_switching_the_sensor_model_is_one_set():
    # Today `mcl run configs/mit_csail.yaml --set sensor.model=beam` stops: the likelihood field's z_hit 0.95 and
    # z_rand 0.05 plus the beam's z_short 0.1, z_max 0.05 do not sum to 1. Each model now has its own block.
    from mcl.config import load_config, sensor_model_view
    from mcl.errors import ConfigError

    cfg = load_config(PROJECT_ROOT / "configs" / "mit_csail.yaml", ["sensor.model=beam"])
    v = sensor_model_view(cfg.sensor)
    assert (v.model, v.z_hit, v.z_short, v.z_max, v.z_rand) == ("beam", 0.8, 0.1, 0.05, 0.05)
    lf = sensor_model_view(load_config(PROJECT_ROOT / "configs" / "intel_lab.yaml").sensor)
    assert (lf.model, lf.z_hit, lf.sigma_hit, lf.max_beams) == ("likelihood_field", 0.95, 0.2, 90)
    beam = load_config(PROJECT_ROOT / "configs" / "mit_csail_beam.yaml", ["sensor.model=likelihood_field"])
    assert beam.sensor.likelihood_field.z_hit == 0.95 and beam.sensor.beam.lambda_short == 0.1
    with pytest.raises(ConfigError, match=r"sensor.sigma_hit: moved to sensor.likelihood_field.sigma_hit or "
                                          r"sensor.beam.sigma_hit"):
        load_config(None, ["sensor.sigma_hit=0.2"])


def test_the_readmes_python_example_runs_and_tracks(monkeypatch):
    # README "From Python": a student's loop over the demo's first 200 scans. It must run as written (from the
    # repository root) and track: at 39.8 s the demo's reference is (7.397, 2.975); the example ends within 0.1 m
    # of it (measured 0.04 m; a filter whose step did not correct would be metres off by then).
    import contextlib
    import io
    import re

    from mcl.config import PROJECT_ROOT

    text = (PROJECT_ROOT / "README.md").read_text()
    section = text.split("## From Python", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    monkeypatch.chdir(PROJECT_ROOT)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "README.md (From Python)", "exec"), {})
    x, y = (float(v) for v in re.findall(r"[-\d.]+", out.getvalue())[:2])
    assert math.hypot(x - 7.397, y - 2.975) < 0.1, out.getvalue()
