"""scripts/truth_mass.py: a replayed run is the run itself, and the weight near the reference follows a global
search from spread to converged."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from mcl.config import PROJECT_ROOT

sys.path.insert(0, str(PROJECT_ROOT / "scripts"))
from truth_mass import milestones, replay  # noqa: E402


@pytest.fixture(scope="module")
def office(tmp_path_factory):
    """A small generated office (20 s): (folder, simulate's summary)."""
    from mcl.simulate import simulate

    data = tmp_path_factory.mktemp("office")
    return data, simulate(data, kind="office", seed=11, duration=20.0)


def _run(data, out, *sets, **kwargs):
    """A run on ``data`` as ``mcl eval`` leaves it (config.yaml, trajectory.tum, summary.json); its summary."""
    from mcl.config import load_config
    from mcl.runner import run

    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={data / 'map.yaml'}", f"log={data / 'log.clf'}", f"truth={data / 'truth.tum'}", "rerun.mode=off",
        "seed=2", *sets])
    return run(cfg, out, progress=False, echo=lambda m: None, **kwargs)


def _errors(out):
    """The run's position error at each of its poses, by time (rounded to the microsecond)."""
    from mcl.config import load_config
    from mcl.evaluate import position_errors
    from mcl.trajectory import read_tum

    cfg = load_config(out / "config.yaml", [])
    t, e, _ = position_errors(*read_tum(out / "trajectory.tum"), *read_tum(cfg.truth))
    return dict(zip(np.round(t, 6), e)), e


@pytest.fixture(scope="module")
def global_run(office, tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    return out, _run(office[0], out, "filter.global_localization=true")


def test_the_replay_is_the_same_run_and_the_mass_gathers_at_the_reference(global_run):
    out, summary = global_run
    rows = replay(out)
    assert len(rows) == summary["updates"]  # every update has a reference pose in a generated world
    # the same seed, the same run: the replay's estimate errors are the run's own, update for update
    by_t, e = _errors(out)
    assert all(abs(by_t[round(r["t"], 6)] - r["error_m"]) < 1e-9 for r in rows)
    # a global start: after its first update the set is re-seeded (lost on probation), half of its weight on fresh
    # uniform poses, so at most about half lies near the reference (0.50 measured); converged, nearly all of it
    assert rows[0]["mass_near"] < 0.6, rows[0]
    assert rows[0]["tempering"]
    assert e[-1] < 0.3  # the run converged ...
    assert min(r["mass_near"] for r in rows[-10:]) > 0.9  # ... and the weight is there
    m = milestones(rows, 1e-6)
    assert m["below_floor"] is None and m["no_particle"] is None and m["last_half"] == rows[-1]["t"]


def test_a_kidnapped_run_is_kidnapped_again_at_the_same_scan(office, tmp_path):
    # mcl eval kidnaps a real log's filter (runner kidnap_filter_at); the replay reads when from summary.json and
    # must send the filter to the same place: the errors match the run's, the kidnap's jump included
    data, sim = office
    x, y, th = sim["start_pose"]
    out = tmp_path / "run"
    summary = _run(data, out, "filter.global_localization=false", f"filter.initial_pose=[{x}, {y}, {th}]",
                   kidnap_filter_at=(8.0, 5.0))
    assert summary["kidnap"]["distance_m"] >= 5.0
    rows = replay(out)
    by_t, _ = _errors(out)
    assert all(abs(by_t[round(r["t"], 6)] - r["error_m"]) < 1e-9 for r in rows)
    jump = [r["error_m"] for r in rows if r["t"] >= summary["kidnap"]["t"]][0]
    assert jump >= 4.0  # the replay was kidnapped too (the cloud lands at least 5 m off, 0.1 m std)


def test_milestones_read_the_rows():
    rows = [{"t": 0.0, "mass_near": 0.3, "count_near": 50}, {"t": 1.0, "mass_near": 0.6, "count_near": 80},
            {"t": 2.0, "mass_near": 1e-8, "count_near": 1}, {"t": 3.0, "mass_near": 0.0, "count_near": 0}]
    assert milestones(rows, 1e-6) == {"below_floor": 2.0, "no_particle": 3.0, "last_half": 1.0}
    assert milestones(rows[:2], 1e-6) == {"below_floor": None, "no_particle": None, "last_half": 1.0}
