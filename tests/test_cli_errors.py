"""One error line, nothing written, for bad input to mcl convert, mcl explore and mcl eval (exit status 2)."""

from __future__ import annotations

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
    (["--map", "{world}/map.yaml", "--initial-pose", "1000", "1000", "0"], "x.mcap",
     "--initial-pose: (1000, 1000) lies outside the map"),
])
def test_convert_checks_its_output_and_its_extra_inputs_first(world, tmp_path, capsys, extra, out, msg):
    extra = [e.format(world=world) for e in extra]
    assert main(["convert", str(world / "log.clf"), str(tmp_path / out), *extra]) == 2
    assert msg.format(tmp=tmp_path) in _one_error(capsys)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("dt", ["0", "-1", "nan"])
def test_explore_velocity_needs_a_positive_dt(tmp_path, capsys, dt):
    assert main(["explore", "motion", "--velocity", "1", "0.5", dt, "--out", str(tmp_path / "m.png")]) == 2
    assert "--velocity: expected finite V W and DT > 0 (s)" in _one_error(capsys)
    assert not (tmp_path / "m.png").exists()


def test_eval_of_trajectories_on_two_clocks_names_both_and_their_spans(tmp_path, capsys):
    import numpy as np

    est, ref = tmp_path / "est.tum", tmp_path / "ref.tum"
    write_tum(est, np.arange(5.0), np.zeros((3, 5)))
    write_tum(ref, 1000.0 + np.arange(5.0), np.zeros((3, 5)))
    assert main(["eval", str(est), str(ref)]) == 2
    assert _one_error(capsys) == (f"mcl: error: {ref}: no pose lies within the time span of {est} (reference "
                                  "1000.000..1004.000 s, estimate 0.000..4.000 s): another clock or another dataset?")
