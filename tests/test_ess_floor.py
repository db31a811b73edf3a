"""filter.ess_floor: a scan that would leave fewer than floor x N effective particles is tempered to leave that many.

Unit tests drive ParticleFilter.normalize (``_temper_to_floor``) on a walled square; the end-to-end test replays intel_lab degraded as
the hunt's r3750 (ninety-sixth to ninety-eighth sessions), where the default without the floor lost the track.
"""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest
import yaml

from mcl.config import PROJECT_ROOT, load_config
from mcl.filter import ParticleFilter
from mcl.maps import OccupancyGrid
from mcl.resampling import effective_sample_size, normalize_log_weights

SHARED = PROJECT_ROOT.parent / "shared" / "data"
INTEL = SHARED / "intel_lab"
FR079 = SHARED / "fr079"


def _pf(n=2000, floor=0.005):
    occ = np.zeros((200, 200), dtype=np.int8)  # 10 m x 10 m, walls around
    occ[:3, :] = occ[-3:, :] = occ[:, :3] = occ[:, -3:] = 100
    grid = OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))
    cfg = load_config(None, [f"filter.particles={n}", "filter.kld=false", "filter.recovery=false",
                             f"filter.ess_floor={floor}"])
    pf = ParticleFilter(cfg, grid, rng=np.random.default_rng(1))
    pf.init_gaussian((5.0, 5.0, 0.0), (0.3, 0.3, 0.1))
    return pf


def _corrected(pf, loglik):
    """The end of ParticleFilter.correct and normalize with ``loglik`` as the scan's log-likelihood."""
    from mcl.filter import StepInfo

    pf._floor_part = loglik if pf.cfg.filter.ess_floor > 0 else None
    pf.logw = pf.logw + loglik
    info = StepInfo(particles=pf.n)
    pf.normalize(info)
    return info


def test_a_scan_too_sharp_for_the_set_is_tempered_to_the_floor_and_no_further():
    pf = _pf()
    rng = np.random.default_rng(7)
    prior = pf.logw.copy()
    # a scan 3 cm sharp (60 beams) against a cloud 0.3 m wide: one particle would carry the set
    loglik = -0.5 * ((pf.particles[0] - 5.1) ** 2 + (pf.particles[1] - 4.9) ** 2) / 0.03 ** 2 * 60
    loglik += rng.normal(0.0, 1.0, pf.n)
    loglik[:3] = -np.inf  # particles no scan can explain stay weight zero
    w, _ = normalize_log_weights(prior + loglik)
    assert effective_sample_size(w) < 3.0
    info = _corrected(pf, loglik)
    floor = 0.005 * pf.n
    assert floor <= info.ess <= ParticleFilter.FLOOR_SLACK * floor  # a beta that keeps the floor, at most 1.05 times it
    assert info.ess == pytest.approx(effective_sample_size(pf.weights))
    assert np.exp(pf.logw) == pytest.approx(pf.weights) and pf.weights.sum() == pytest.approx(1.0)
    beta = (pf.logw - prior)[3:] - (pf.logw - prior)[3]  # one factor for the whole scan: logw - prior = beta loglik + c
    assert np.allclose(beta, (loglik[3:] - loglik[3]) * (beta[-1] / (loglik[-1] - loglik[3])))
    assert 0.0 < beta[-1] / (loglik[-1] - loglik[3]) < 0.2  # tempered hard: beta about 0.09 here
    assert np.all(pf.weights[:3] == 0.0) and pf.floor_tempered == 1


def test_a_scan_so_sharp_that_a_4096th_of_it_leaves_too_few_is_dropped_for_the_update():
    # 0.3 mm over 60 beams against a 0.3 m cloud: even beta = 1/4096 leaves under 10 effective particles of 2,000;
    # the update keeps the weights from before the scan (counted as tempered), as the ninety-eighth session's bisection
    pf = _pf()
    prior = pf.logw.copy()
    loglik = -0.5 * ((pf.particles[0] - 5.1) ** 2 + (pf.particles[1] - 4.9) ** 2) / 0.0003 ** 2 * 60
    w, _ = normalize_log_weights(prior + loglik / 4096.0)
    assert effective_sample_size(w) < 0.005 * pf.n
    info = _corrected(pf, loglik)
    assert pf.floor_tempered == 1 and np.allclose(pf.logw, prior) and info.ess == pytest.approx(pf.n)


def test_a_scan_the_set_can_hold_is_not_touched():
    pf = _pf()
    prior = pf.logw.copy()
    loglik = -0.5 * ((pf.particles[0] - 5.0) ** 2 / 0.3 ** 2)  # about as wide as the cloud
    _corrected(pf, loglik)
    w, norm = normalize_log_weights(prior + loglik)
    assert pf.floor_tempered == 0 and np.array_equal(pf.weights, w)
    # nor a set below the floor before the scan (nothing a factor on the scan could mend)
    pf = _pf()
    pf.logw = np.full(pf.n, -np.inf)
    pf.logw[:3] = 0.0
    _corrected(pf, -1e4 * (pf.particles[0] - 5.0) ** 2)
    assert pf.floor_tempered == 0
    # nor with the floor off (configs/baseline.yaml)
    pf = _pf(floor=0.0)
    info = _corrected(pf, -0.5 * ((pf.particles[0] - 5.1) ** 2) / 0.003 ** 2 * 60)
    assert pf.floor_tempered == 0 and info.ess < 0.005 * pf.n  # below the floor the default would keep


def test_a_narrow_cloud_is_not_tempered_and_a_wide_one_is_in_position_or_heading_alone():
    # filter.ess_floor_spread (0.08): the same scan, far sharper than the cloud in every case (ESS under 3 of 2,000)
    def tempered(std):
        pf = _pf()
        pf.init_gaussian((5.0, 5.0, 0.0), std)
        loglik = -0.5 * ((pf.particles[0] - 5.01) ** 2 + (pf.particles[1] - 4.99) ** 2) / 0.002 ** 2 * 60
        loglik -= 0.5 * (pf.particles[2] - 0.01) ** 2 / 0.002 ** 2 * 60
        w, _ = normalize_log_weights(pf.logw + loglik)
        assert effective_sample_size(w) < 3.0
        _corrected(pf, loglik)
        return pf.floor_tempered

    # a crowd's few walls on a cloud 5 cm and 0.05 rad wide (clutter-03 at 1.5 m/s: 0.044-0.053 m, 0.048-0.061 rad):
    # the scan is taken whole
    assert tempered((0.04, 0.04, 0.05)) == 0
    assert tempered((0.3, 0.3, 0.02)) == 1  # wide in position (spread 0.42 m)
    assert tempered((0.01, 0.01, 0.3)) == 1  # wide in heading alone


def test_a_scan_after_a_slips_proposal_is_not_tempered():
    # an odometry fault's or a slip's proposal (motion.slip_turn): its few far poses must be free to take the set
    # (tests/test_slip.py's rooms: heading 1.09 rad off when tempered); the same scan after the plain model's motion
    # is kept for the floor
    from types import SimpleNamespace

    from mcl.filter import Control, StepInfo
    from mcl.kernels.raycast import cast_rays

    angles = np.linspace(-np.pi / 2, np.pi / 2, 181)
    for slip in (0.0, 1.5):
        grid = _pf().grid
        cfg = load_config(None, ["filter.particles=2000", "filter.kld=false", "filter.recovery=false",
                                 "filter.ess_floor=0.005", "motion.fault_prob=0.001", f"motion.slip_turn={slip}"])
        pf = ParticleFilter(cfg, grid, rng=np.random.default_rng(1))
        pf.init_gaussian((5.0, 5.0, 0.0), (0.05, 0.05, 0.05))
        pf.predict(Control(np.zeros(3), np.array([0.1, 0.0, 0.5]), dt=0.5), StepInfo(particles=pf.n))
        ranges = np.empty((1, 181))
        cast_rays(np.array([[5.1], [5.0], [0.5]]), angles, np.ascontiguousarray(grid.occupied), grid.origin[0],
                  grid.origin[1], grid.resolution, 30.0, ranges)
        pf.correct(pf.prepare(SimpleNamespace(ranges=ranges[0], angles=angles, max_range=None, t=1.0), np.zeros(3)))
        assert (pf._floor_part is None) == (slip > 0.0), slip


@pytest.mark.slow
@pytest.mark.skipif(not (INTEL / "log.clf").is_file(), reason=f"intel_lab data set not found at {INTEL}")
def test_intel_lab_read_long_and_noisy_is_tracked_with_the_floor_and_lost_without(tmp_path):
    # The hunt's intel_lab-lat08-rs102-noise5-r3750: scans 0.08 s late, ranges 2 % long, 5 cm noise. At 1614.6 and
    # 1616.8 s (scans 4.7 and 2.2 s apart, a 1 rad turn between) the effective sample size after the correction
    # was 1.5 and 1.0 of 5,000, and the default went 1.48-4.86 m off on seeds 1-5 (the baseline 0.33 m but 1.19 m
    # on seed 3). With filter.ess_floor 0.005 (opt-in; ninety-ninth session): 0.25-0.27 m on seeds 1-3
    # (0.01: 0.24-0.27 m on seeds 1-5). Bound: the suite's 1 m for real logs.
    from mcl.runner import run

    suite = tmp_path / "one.yaml"
    suite.write_text(yaml.safe_dump({"name": "intel_lab", "datasets": [{
        "name": "intel_lab", "map": str(INTEL / "map.yaml"), "log": str(INTEL / "log.clf"),
        "truth": str(INTEL / "truth.tum")}]}))
    out = tmp_path / "degraded"
    subprocess.run([sys.executable, str(PROJECT_ROOT / "scripts" / "degrade_laser.py"), "--suite", str(suite),
                    "--seed", "3750", "--latency", "0.08", "--range-scale", "1.02", "--sigma", "0.05", str(out)],
                   check=True, stdout=subprocess.DEVNULL)
    made = yaml.safe_load((out / "suite.yaml").read_text())
    d = made["datasets"][0]
    root = made["root"]
    base = [f"map={root}/{d['map']}", f"log={root}/{d['log']}", f"truth={root}/{d['truth']}", "rerun.mode=off",
            "filter.initial_pose=[0.600266, -0.032033, -0.354665]"]
    maxima = {}
    for floor in (0.005, 0.0):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [*base, f"filter.ess_floor={floor}"])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            s = run(cfg, tmp_path / f"run{floor}", progress=False, echo=lambda *_: None)
        maxima[floor] = s["eval"]["ate_max"]
        assert (s["floor_tempered_updates"] > 0) == (floor > 0)
    assert maxima[0.005] < 1.0 < maxima[0.0], maxima


@pytest.mark.slow
@pytest.mark.skipif(not (FR079 / "log.clf").is_file(), reason=f"fr079 data set not found at {FR079}")
def test_fr079s_slip_is_held_with_the_floor_inside_the_fault_window(tmp_path):
    # fr079 at 305 s: the odometry reports 0.1 m forward a scan for 6 s while the robot reverses; the lost call opens
    # the odometry-fault window (motion.fault_*). Once the track holds again inside it the floor tempers as anywhere:
    # seed 2 within 1.13 m (its suite bound 1.5 m). Off inside the window, as after a slip's proposal, the same seed
    # was 2.60 m off (ninety-ninth session; without the floor at all, 0.98-1.03 m).
    from mcl.runner import run

    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={FR079 / 'map.yaml'}", f"log={FR079 / 'log.clf'}", f"truth={FR079 / 'truth.tum'}", "rerun.mode=off",
        "seed=2", "filter.initial_pose=[0.001236, -0.001068, 0.000029]", "filter.ess_floor=0.005"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        s = run(cfg, tmp_path / "fr079", progress=False, echo=lambda *_: None)
    assert s["fault_updates"] > 0 and s["floor_tempered_updates"] > 0
    assert s["eval"]["ate_max"] < 1.5, s["eval"]


def test_a_scan_left_from_an_update_that_corrected_nothing_is_not_tempered_again():
    # correct() with no observation (a blind update) clears the scan normalize would temper; a set whose size changed
    # since is not tempered with a scan of another size
    pf = _pf()
    pf._floor_part = np.zeros(pf.n)
    pf.correct(None)
    assert pf._floor_part is None
    from mcl.filter import StepInfo

    pf._floor_part = np.full(pf.n + 1, -1e4)
    pf.logw = np.full(pf.n, -np.inf)
    pf.logw[:2] = 0.0
    info = StepInfo(particles=pf.n)
    pf.normalize(info)
    assert pf.floor_tempered == 0 and info.ess == pytest.approx(2.0)
