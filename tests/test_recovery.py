"""Recovery: augmented MCL recovers from a kidnapping (scripts/kidnap.py on a small subset); the default `lost`
recovery injects nothing during a correct track, spreads locally, then re-seeds globally."""

from __future__ import annotations

import importlib.util
import math
from dataclasses import replace

import numpy as np
import pytest

from mcl.config import PROJECT_ROOT


def _kidnap_module():
    spec = importlib.util.spec_from_file_location("kidnap_script", PROJECT_ROOT / "scripts" / "kidnap.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.slow
def test_recovery_after_a_kidnap_on_three_worlds(tmp_path):
    # Seeds 0-2, kidnapped at 20 s of a 50 s log, the default config with at most 5,000 particles.
    # With recovery: back within 0.5 m (and staying) in < 30 s in all three worlds (measured 1.6-3 s
    # with the full 20,000 in scripts/kidnap.py); without: not recovered in < 30 s in at least one of them
    # (measured: in none of two out of three). Tracking before the jump is the same to 5 mm either way.
    k = _kidnap_module()
    rows = k.experiment([0, 1, 2], kidnap_at=20.0, duration=50.0, overrides=["filter.particles=5000"],
                        root=tmp_path, echo=lambda *_: None)
    assert all(r["recovered"] for r in rows), rows
    assert sum(r["recovery_off"] is not None and r["recovery_off"] < 30.0 for r in rows) < 3, rows
    for r in rows:
        assert r["ate_before_on"] <= r["ate_before_off"] + 0.005, r
        assert r["ate_before_on"] < 0.15, r


def test_recovery_time_rule():
    import numpy as np

    k = _kidnap_module()
    t = np.arange(10.0)
    err = np.array([0.1, 0.1, 5, 5, 0.4, 0.6, 0.3, 0.2, 0.1, 0.1])
    assert k.recovery_time(t, err, 2.0, 0.5) == pytest.approx(4.0)  # below from t = 6 on
    assert k.recovery_time(t, np.r_[err[:-1], 1.0], 2.0, 0.5) is None  # off again at the end
    assert k.recovery_time(t, np.full(10, 0.1), 2.0, 0.5) == 0.0


@pytest.fixture(scope="module")
def rooms_world(tmp_path_factory):
    from mcl.simulate import simulate

    out = tmp_path_factory.mktemp("rooms")
    return out, simulate(out, kind="rooms", seed=5, duration=45.0)


def _track(data, sim, out, *sets):
    from mcl.config import load_config
    from mcl.runner import run

    x, y, th = sim["start_pose"]
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={data / 'map.yaml'}", f"log={data / 'log.clf'}", f"truth={data / 'truth.tum'}", "rerun.mode=off",
        "filter.global_localization=false", f"filter.initial_pose=[{x}, {y}, {th}]", *sets])
    return run(cfg, out, progress=False, echo=lambda m: None)


def _tracked_and_mend_off(tmp_path_factory, tmp_path, off: str, **world):
    """The evaluations (``summary["eval"]``) of tracking a world ``mcl simulate`` makes with the keywords ``world``
    from its start pose: with the default config, then with the setting ``off`` (a mend switched off)."""
    from mcl.simulate import simulate

    data = tmp_path_factory.mktemp(f"{world['kind']}-{world['seed']}")
    sim = simulate(data, **world)
    return (_track(data, sim, tmp_path / "default")["eval"], _track(data, sim, tmp_path / "off", off)["eval"])


def test_default_recovery_does_not_inject_while_the_track_is_correct_on_repeated_rooms(rooms_world, tmp_path):
    # Identical rooms off a corridor: a pose in the next room fits the scan as well as the true one, so
    # any particle drawn there can take the estimate away. The default (`lost` recovery) must draw none
    # while tracking from the true start pose; the book's augmented MCL (the old default) reacts to the
    # scene's likelihood swings and injects anyway, which is what this test exists to catch.
    data, sim = rooms_world
    s = _track(data, sim, tmp_path / "default")
    assert s["eval"]["ate_max"] < 0.5, s["eval"]
    assert s["quality"]["lost_updates"] == 0, s["quality"]
    assert s["injected_particles"] == 0
    a = _track(data, sim, tmp_path / "augmented", "filter.recovery=augmented")
    assert a["injected_particles"] > 0


def test_lost_recovery_waits_while_the_lost_scans_look_occluded_and_spreads_at_once_when_one_refutes_the_pose():
    # wait = 4: four lost updates on scans that fit as an occlusion draw nothing; the fifth spreads poses. A lost
    # update whose scan refutes the estimate (through walls, or matching below quality.occlusion_match) spreads at
    # once, and the episode remembers it until the filter fits again.
    from mcl.adaptive import LostRecovery

    def recovery():
        return LostRecovery(0.1, (0.5, 0.5, 0.3), global_after=10, lost_after=3, wait=4)

    r = recovery()
    spread = []
    for _ in range(6):
        r.observe_lost(True)
        spread.append(r.inject_probability)
    assert spread == [0.0] * 4 + [0.1, 0.1]
    r.observe_lost(False)
    assert not r.spreading and not r.refuted
    r.observe_lost(True, refuted=True)
    assert r.spreading and r.inject_probability == 0.1
    r.observe_lost(True)  # an occluded-looking scan later in the same episode does not stop the spread
    assert r.spreading
    r.observe_lost(False)
    r.observe_lost(True)  # a new episode waits again
    assert not r.spreading and r.lost_updates == 1
    for _ in range(8):
        r.observe_lost(True)
    assert not r.global_due
    r.observe_lost(True)
    assert r.global_due  # the wait does not delay the global re-seed: 10 lost updates, as without it


def test_a_scan_refutes_the_estimate_when_it_goes_through_walls_or_matches_below_the_occlusion_match():
    from types import SimpleNamespace

    from mcl.quality import Fit, ScanQuality

    q = ScanQuality.__new__(ScanQuality)
    q.cfg = SimpleNamespace(contradiction_above=0.1, occlusion_match=0.45, min_beams=5)
    q.lost, q.crept = True, False  # an episode that began on a held fit (a crept one: test_quality.py)
    assert not q.refutes(Fit(60, 0.52, 0.05))  # people in a narrow view (clutter-kinect-h8 at 58 s)
    assert q.refutes(Fit(60, 0.30, 0.08))  # a kidnapped robot's first scan (rooms-h2 at 45 s)
    assert q.refutes(Fit(60, 0.90, 0.10))  # through walls
    assert not q.refutes(Fit(3, 0.0, 0.0))  # too few beams: no evidence
    assert not q.refutes(None)
    q.cfg.occlusion_match = 0.0
    assert not q.refutes(Fit(60, 0.30, 0.08))


def _lost_recovery(reseed: bool, probation: int = 0):
    from mcl.adaptive import GlobalSearch, LostRecovery

    return LostRecovery(0.1, (0.5, 0.5, 0.3), global_after=10, lost_after=3, reseed=reseed, probation=probation,
                        search=GlobalSearch())


def _start(r) -> None:
    """A global search starts, as ParticleFilter._start_global does it."""
    r.search.start()
    r.start_search()


def _observe(r, lost: bool, cluster_weight: float = 1.0) -> None:
    """One update's lost belief, as ParticleFilter.assess passes it on: to the search, then to the policy."""
    r.search.observe(lost, cluster_weight)
    r.observe_lost(lost, cluster_weight)


def test_the_reseed_comes_after_global_after_updates_or_global_after_s_seconds_whichever_first():
    # global_after 10 updates or 10 s of log time (after lost_after = 3 updates). A log with a scan every 3 s
    # (intel_lab) re-seeds at the 5th lost update (12 s from the first), not the 10th (27 s); one at 5 Hz at the
    # 10th (1.8 s): the clock never comes first there. A good update starts both counts again.
    from mcl.adaptive import GlobalSearch, LostRecovery

    def due_at(dt, seconds):
        r = LostRecovery(0.1, (0.5, 0.5, 0.3), global_after=10, lost_after=3, reseed=True, search=GlobalSearch(),
                         global_after_s=seconds)
        for k in range(1, 30):
            r.search.observe(True, 1.0)
            r.observe_lost(True, 1.0, dt)
            if r.reseed_due:
                return k
        return None

    assert due_at(3.0, 10.0) == 5
    assert due_at(3.0, 0.0) == 10  # the clock off: updates only
    assert due_at(0.2, 10.0) == 10
    assert due_at(30.0, 10.0) == 3  # never before lost_after updates, however sparse the log
    r = LostRecovery(0.1, (0.5, 0.5, 0.3), global_after=10, lost_after=3, reseed=True, search=GlobalSearch(),
                     global_after_s=10.0)
    for lost in (True, True, True, False, True, True, True):
        r.search.observe(lost, 1.0)
        r.observe_lost(lost, 1.0, 4.0)
    assert r.lost_updates == 3 and r.lost_time == 8.0 and not r.reseed_due


def test_a_global_search_stops_tempering_once_settled_and_stops_holding_once_settled_or_fitting():
    from mcl.adaptive import GlobalSearch

    s = GlobalSearch()
    assert not s.tempering and not s.holding and s.since_end is None
    s.start()
    s.observe(True, 0.5)  # lost, several hypotheses: both go on
    assert s.tempering and s.holding and s.since_end is None
    s.observe(False, 0.5)  # the scan fits at the estimate: injections may resume, the laser stays tempered
    assert s.tempering and not s.holding and s.since_end == 1
    s.observe(True, 0.9)  # one cluster holds 90 % of the weight: settled
    assert not s.tempering and not s.holding and s.since_end == 2
    s.start()
    s.observe(True, 0.95)  # settled while lost: both end at once
    assert not s.tempering and not s.holding and s.since_end == 1
    wide = np.diag([12.0 ** 2, 1.0, 0.1])  # one cluster 12 m wide: a dense set whose weight sits on several places
    s.start()
    s.observe(True, 1.0, wide)  # settled_std = 0 (the old rule): settled by weight alone
    assert not s.tempering and not s.holding
    s.reset()
    assert s.since_end is None
    s = GlobalSearch(settled_std=1.0)
    s.start()
    s.observe(True, 1.0, wide)
    assert s.tempering and s.holding
    s.observe(True, 1.0, np.diag([0.9 ** 2, 0.9 ** 2, 0.1]))  # x and y std under 1 m: a place
    assert not s.tempering and not s.holding and s.since_end == 1

def test_the_probation_counts_from_the_settling_with_probation_from_settled():
    # filter.recovery_probation_from: a search whose estimate fits at its first update (holding ends) and that
    # settles 4 updates later; "fit" counts the probation from the fit, "settled" starts it again at the settling
    from mcl.adaptive import GlobalSearch

    counts = {}
    for probation_from in ("fit", "settled"):
        s = GlobalSearch(probation_from=probation_from)
        s.start()
        s.observe(False, 0.3)  # fits at the estimate, several places: holding ends, tempering goes on
        for _ in range(3):
            s.observe(False, 0.5)
        assert s.tempering and s.since_end == 4
        s.observe(False, 0.95)  # settled
        assert not s.tempering
        counts[probation_from] = s.since_end
        s.start()
        s.observe(True, 0.95)  # settled and fitting in the same update: the same either way
        assert s.since_end == 1
    assert counts == {"fit": 5, "settled": 1}
    with pytest.raises(ValueError, match="probation_from"):
        GlobalSearch(probation_from="settle")



def test_a_place_a_search_found_that_wins_its_protected_reseed_leaves_probation():
    # heldout3 hall-people-dropouts-h10 global: the search found the robot at 24.6 s; people and dropouts kept its
    # fit at 0.4-0.6, so it was challenged and won its protected re-seed. Put back on probation (the twenty-ninth
    # session's rule), the next lost call re-seeded it at once, unprotected, and a place 10.7 m off held the
    # estimate from 45 to 50 s: lost on every seed (heldout3 global 26/36 against 29/36; heldout2 gained one run).
    # A place that has won its protected re-seed is trusted as a track is: off probation, a lost call re-seeds it
    # only after recovery_global_after lost updates, and protected.
    from mcl.adaptive import GlobalSearch

    s = GlobalSearch()
    s.start()
    s.observe(True, 0.95)  # the search settles on a place: on probation
    assert s.since_end == 1 and not s.holding
    s.start()  # the challenge's protected re-seed
    s.observe(False, 0.0)
    s.confirm()  # the place kept wins
    assert s.since_end is None and not s.holding and not s.tempering
    s.observe(True, 1.0)
    assert s.since_end is None  # and stays off probation


def test_a_dense_set_weighted_at_two_far_places_settles_a_search_by_weight_unless_search_settled_std():
    # Clusters are the occupied cells whatever their weight: 100,000 uniform poses on a 10 m box fill every cell,
    # so they are one cluster that holds all the weight even when only the poses near two far corners carry it.
    # Settled by weight alone (filter.search_settled_std = 0, the old default), the search ends at its first update
    # and, lost at the mean between the places, re-seeds at the next (with search_refine:
    # corridor-fast-reversing-h10 re-seeded 175 times); with search_settled_std it goes on.
    pf = _dense_set_weighted_at_two_corners("filter.search_settled_std=1.0")
    assert pf.search.tempering and pf.search.holding and not pf.recovery.reseed_due
    pf = _dense_set_weighted_at_two_corners("filter.search_settled_std=0")
    assert not pf.search.tempering and not pf.search.holding and pf.recovery.on_probation


def _dense_set_weighted_at_two_corners(*sets):
    """A filter on the 10 m box after one update of a global search (100,000 poses) whose weight sits at
    (2, 2) and (8, 8), estimated and assessed with no scan."""
    from mcl.filter import StepInfo

    pf = _filter_on_a_box("filter.particles=100000", "filter.recovery_reseed=true", *sets)
    pf.init_global()
    assert pf.search.tempering and pf.search.holding
    x, y = pf.particles[0], pf.particles[1]
    near = (np.hypot(x - 2.0, y - 2.0) < 0.5) | (np.hypot(x - 8.0, y - 8.0) < 0.5)
    pf.logw = np.where(near, 0.0, -50.0)
    pf._scan_observation = None
    info = StepInfo(particles=pf.n, ess=float(pf.n))
    pf.normalize(info)
    pf.estimate(info)
    assert info.clusters == 1 and info.cluster_weight == 1.0  # one cluster, all the weight ...
    assert np.hypot(*info.mean[:2] - 5.0) < 0.5  # ... its mean between the two places
    pf.assess(info)
    return pf


def test_odometry_faults_are_allowed_from_a_lost_call_on_a_held_track_for_the_window():
    from types import SimpleNamespace

    from mcl.adaptive import FaultWindow, GlobalSearch

    s = GlobalSearch()
    f = FaultWindow(SimpleNamespace(fault_prob=1e-3, fault_share=0.05, fault_scale=10.0, fault_window=3,
                                    fault_window_s=0.0, fault_contradiction=0.1, fault_turn_max=0.0,
                                    fault_shift_max=0.0, fault_widen_after=0, fault_held_turn_max=0.0, slip_turn=0.0), s)

    def upd(lost, cluster_weight=1.0, contradiction=0.2):
        s.observe(lost, cluster_weight)
        f.observe(lost, contradiction)

    upd(False)
    assert f.proposal(0.2) is None  # a track that fits: the plain motion model
    upd(True, contradiction=0.05)  # lost, but no beam through a wall to speak of (people, furniture): nothing
    assert f.proposal(0.2) is None
    for _ in range(3):
        upd(False)
    upd(True)  # a lost call whose scan goes through mapped walls, on a track that held: faults allowed ...
    assert f.proposal(0.2) is not None and f.proposal(0.2).prob == 1e-3 and f.proposal(0.2).share == 0.05
    upd(True)
    for _ in range(3):  # ... while lost and 3 updates after
        upd(False)
        assert f.proposal(0.2) is not None
    upd(False)
    assert f.proposal(0.2) is None
    upd(True)  # lost again after 4 good updates: opens again
    assert f.proposal(0.2) is not None
    s.start()  # a global search: a lost call means a wrong hypothesis, not a slipping one; it closes the window
    upd(True, 0.5)
    assert f.proposal(0.2) is None
    upd(False, 0.95)  # settled and fits
    upd(False)
    upd(True)  # lost after 2 good updates: not a held track yet
    assert f.proposal(0.2) is None
    for _ in range(3):
        upd(False)
    upd(True)  # after 3: it had held for the window
    assert f.proposal(0.2) is not None
    f.reset()
    assert f.proposal(0.2) is None


def _fault_window(**motion):
    """A ``FaultWindow`` on the fault keys below with ``motion``'s replaced, and two helpers: ``upd(lost)`` observes
    one update (its scan 20 % through mapped walls, the search settled) and ``caps(dt)`` gives the next proposal's
    (turn_max, shift_max) over ``dt`` s, None while the window is closed."""
    from types import SimpleNamespace

    from mcl.adaptive import FaultWindow, GlobalSearch

    keys = dict(fault_prob=1e-3, fault_share=0.05, fault_scale=10.0, fault_window=2, fault_window_s=0.0,
                fault_contradiction=0.1, fault_turn_max=0.0, fault_shift_max=0.0, fault_widen_after=0,
                fault_held_turn_max=0.0, slip_turn=0.0)
    s = GlobalSearch()
    f = FaultWindow(SimpleNamespace(**{**keys, **motion}), s)

    def upd(lost, dt=0.2):
        s.observe(lost, 1.0)
        f.observe(lost, 0.2, 0.0, dt)

    def caps(dt=0.2):
        p = f.proposal(dt)
        return None if p is None else (round(p.turn_max, 9), round(p.shift_max, 9))

    return f, upd, caps


def test_the_fault_caps_hold_for_a_windows_first_lost_updates_then_it_widens():
    # motion.fault_widen_after = 2: the window's first two lost updates move with the capped fault component (a
    # slip is short: scans stamped late at a junction, infinite_corridor), the third on at full width (a kidnap: the
    # wide fault poses are a search), until the window closes; a new window starts capped again. The caps are
    # rates: fault_shift_max 1.5 m/s is 0.3 m over a 0.2 s update and 3.9 m over a sparse log's 2.6 s.
    f, upd, caps = _fault_window(fault_window=2, fault_turn_max=0.5, fault_shift_max=1.5, fault_widen_after=2)
    seen = []
    for lost in (True, True, False, True, True, False, False, False, True, True, True):
        upd(lost)
        seen.append(caps())
    capped, wide = (0.1, 0.3), (0.0, 0.0)
    # closed 3 good updates after its last lost one; the next lost call (the track had held 3 >= 2) opens a new
    # window, capped again for its first two lost updates
    assert seen == [capped, capped, capped, wide, wide, wide, wide, None, capped, capped, wide]
    f.reset()
    for _ in range(2):
        upd(False)
    upd(True)
    assert caps(2.6) == (1.3, 3.9) and caps(0.0) == wide  # no log time: no cap


def test_the_fault_window_closes_after_its_seconds_when_they_come_before_its_updates():
    # motion.fault_window_s = 20: the window closes 50 updates or 20 s of log time after its last lost update,
    # whichever is first. At 5 Hz the 50 updates come first (10 s); with a scan every 3 s (intel_lab, aces) the
    # seconds do: 7 updates, where 50 held the fault component (as wide as a search over 3 s) for 150 s
    for dt, open_for in ((0.2, 50), (3.0, 6), (4.0, 5)):
        f, upd, caps = _fault_window(fault_window=50, fault_window_s=20.0)
        for _ in range(50):
            upd(False, dt)
        upd(True, dt)  # opens
        n = 0
        while True:
            upd(False, dt)
            if caps() is None:
                break
            n += 1
        assert n == open_for, (dt, n)
        # with no bound in seconds (0) the updates alone close it
        f, upd, caps = _fault_window(fault_window=50, fault_window_s=0.0)
        for _ in range(50):
            upd(False, dt)
        upd(True, dt)
        for _ in range(50):
            upd(False, dt)
            assert caps() is not None
        upd(False, dt)
        assert caps() is None


INTEL = PROJECT_ROOT.parent / "shared" / "data" / "intel_lab"


@pytest.mark.slow
@pytest.mark.skipif(not (INTEL / "log.clf").is_file(), reason=f"intel_lab not found at {INTEL}")
def test_a_sparse_logs_fault_window_does_not_stay_open_for_minutes(tmp_path):
    # intel_lab (a scan every 1-5 s) with a 90-degree laser, 5 cm range noise and a tenth of the readings dropped
    # (the real hunt's log r3015). A lost call at 2202.8 s, 18 beams with a third through mapped walls, opens the
    # fault window. Its 50 updates spanned 150 s of this log, and a fault pose (caps: rates times a 3.5 s update, as
    # wide as a search) 1 m off and turned 12 degrees out-fitted the track at 2262.9 s, 60 s after the call: max
    # 1.28 m measured at seed 1 (seeds 1-3: 0.62 m median), the baseline 0.32 m. With the window bounded by
    # motion.fault_window_s (20 s) too: 0.40 m measured (seeds 1-3: at most 0.48 m). Bound: 1 m, the hunts' and the
    # issue's bound for a real log. Both runs pin the ESS floor off (filter.ess_floor 0, the default): with it, seed 1
    # is 0.33 m with the bound and without (ninety-ninth session), and the control would tell nothing.
    from tests.degraded import degraded, replay

    world = degraded(tmp_path, "intel_lab", "--fov", "90", "--sigma", "0.05", "--seed", "3015")
    worst = {}
    for name, sets in (("bound", []), ("none", ["motion.fault_window_s=0"])):
        s = replay(world, tmp_path / name, (0.600266, -0.032033, -0.354665), "filter.ess_floor=0", *sets)
        worst[name] = s["eval"]["ate_max"]
    assert worst["bound"] < 1.0 < worst["none"], worst


def test_a_track_held_again_inside_the_window_has_the_fault_heading_capped():
    # motion.fault_held_turn_max = 0.5 rad/s: the window's lost updates move as before (the first fault_widen_after
    # capped with no heading cap, fault_turn_max 0, then at full width: a search), but once the track holds again
    # the fault poses turn at most 0.1 rad (std) over a 0.2 s update and shift at most fault_shift_max's 0.3 m; a
    # lost update widens it again
    f, upd, caps = _fault_window(fault_window=3, fault_shift_max=1.5, fault_widen_after=1, fault_held_turn_max=0.5)
    for _ in range(3):
        upd(False)
    seen = []
    for lost in (True, True, False, False, True, False, False, False, False):
        upd(lost)
        seen.append(caps())
    lost_capped, wide, held = (0.0, 0.3), (0.0, 0.0), (0.1, 0.3)
    assert seen == [lost_capped, wide, held, held, wide, held, held, held, None]
    upd(True)  # a new window (the track held 4 updates): its first lost update capped as before
    assert caps() == lost_capped
    upd(False)
    assert caps(2.6) == (1.3, 3.9) and caps(0.0) == wide  # no log time: no cap


def test_lost_recovery_reseeds_once_the_local_spread_failed():
    # Without reseed: 10 % of N a step, half of them uniform once lost for global_after = 10 updates (the old rule).
    r = _lost_recovery(False)
    for _ in range(10):
        r.observe_lost(True)
    assert r.inject_probability == 0.1 and r.global_share == 0.5 and not r.reseed_due
    # With reseed: local only (global_share 0) until the 10th lost update, then one re-seed is due ...
    r = _lost_recovery(True)
    for k in range(1, 11):
        assert not r.reseed_due and r.global_share == 0.0
        r.observe_lost(True)
        assert r.inject_probability == 0.1, k
    assert r.reseed_due
    # ... which starts a search: nothing injected, no second re-seed, while the cloud is multi-modal and lost
    _start(r)
    for _ in range(20):
        _observe(r, True, cluster_weight=0.5)
        assert r.inject_probability == 0.0 and not r.reseed_due
    # the search ends when one cluster holds 90 % of the weight; lost still, that update is the first of a new count
    _observe(r, True, cluster_weight=0.95)
    assert not r.search.holding and r.lost_updates == 1 and r.inject_probability == 0.1 and not r.reseed_due
    # or when the filter is no longer lost
    _start(r)
    _observe(r, False, cluster_weight=0.2)
    assert not r.search.holding and r.lost_updates == 0


def _filter_on_a_box(*sets):
    from mcl.config import load_config
    from mcl.filter import ParticleFilter
    from mcl.maps import OccupancyGrid

    occ = np.zeros((100, 100), dtype=np.int8)  # 10 m x 10 m at 0.1 m, walls (100 = occupied) on the border
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 100
    grid = OccupancyGrid.from_occupancy(occ, resolution=0.1, origin=(0.0, 0.0))
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        "rerun.mode=off", "filter.particles=4000", "filter.min_particles=500", "filter.recovery=lost", *sets])
    return ParticleFilter(cfg, grid, rng=np.random.default_rng(3))


def test_a_start_from_a_known_pose_resets_every_policy_whichever_form_the_pose_takes():
    # init_gaussian (--initial-pose) and init_gaussian_cov (a ROS /initialpose) start the same kind of track: no
    # search, not lost, nothing on probation, no challenge or stall pending from what the filter did before
    for start in (lambda pf: pf.init_gaussian([5.0, 5.0, 0.0], [0.1, 0.1, 0.1]),
                  lambda pf: pf.init_gaussian_cov([5.0, 5.0, 0.0], np.diag([0.01, 0.01, 0.01]))):
        pf = _filter_on_a_box()
        pf.init_global()
        assert pf.search.tempering and pf.search.starts == 1
        pf.challenge.due, pf.stall.stalled, pf.stall.run = True, True, 3
        calls = []  # the odometry-fault window must be reset too
        pf.faults.reset = lambda: calls.append(1)
        start(pf)
        assert not pf.search.tempering and not pf.search.holding and pf.search.starts == 0
        assert pf.search.since_end is None and not pf.quality.lost
        assert not pf.challenge.due and pf.challenge.scores is None
        assert not pf.stall.stalled and pf.stall.run == 0
        assert calls == [1]


def test_reseed_adds_a_whole_global_set_with_the_old_cloud_keeping_its_share_of_the_mass():
    from mcl.filter import StepInfo

    pf = _filter_on_a_box("filter.recovery_reseed=true", "filter.recovery_reseed_keep=0.5")
    pf.init_gaussian([5.0, 5.0, 0.0], [0.1, 0.1, 0.1])
    pf.logw = np.log(np.full(pf.n, 1.0 / pf.n))
    n_old = pf.n
    for _ in range(10):
        pf.recovery.observe_lost(True, dt=0.2)  # a 5 Hz log (filter.recovery_global_min_s)
    info = StepInfo(particles=pf.n, ess=float(pf.n))
    pf.resample(info)
    # filled up to filter.particles, and at least doubled (here N was already 4,000: 4,000 more)
    assert info.resampled and info.injected == max(4000 - n_old, n_old) == 4000 and pf.n == 8000
    w = np.exp(pf.logw)
    old = np.arange(pf.n) < n_old
    assert w.sum() == pytest.approx(1.0) and w[old].sum() == pytest.approx(0.5)
    # the old cloud is where it was; the new poses cover the box (free space, away from the walls)
    assert np.abs(pf.particles[:2, old] - 5.0).max() < 1.0
    new = pf.particles[:, ~old]
    assert new[0].min() < 2.0 and new[0].max() > 8.0 and new[1].min() < 2.0 and new[1].max() > 8.0
    assert pf.search.tempering and pf.search.holding and pf.recovery.search is pf.search
    assert not pf.recovery.reseed_due
    # without reseed the same lost filter injects its 10 % (half uniform) and keeps N
    pf = _filter_on_a_box("filter.recovery_reseed=false", "filter.kld=false")
    pf.init_gaussian([5.0, 5.0, 0.0], [0.1, 0.1, 0.1])
    for _ in range(10):
        pf.recovery.observe_lost(True, dt=0.2)  # a 5 Hz log (filter.recovery_global_min_s)
    info = StepInfo(particles=pf.n, ess=float(pf.n))
    pf.resample(info)
    assert pf.n == 4000 and 300 <= info.injected <= 500 and not pf.search.tempering


def test_a_collapse_re_seeds_at_the_first_lost_update_unprotected():
    # quality.collapse_from: a lost call at once on a held track (ScanQuality.collapsed) makes the re-seed due at
    # once, and it runs unprotected (the old cloud keeps its share of the mass as a mixture prior, no odds): a
    # kidnapped robot's old place, turned as the robot was, fits again in a corridor and would win the odds.
    # Any other lost update of a trusted track first spreads around it, and its re-seed is protected.
    from mcl.filter import StepInfo

    pf = _filter_on_a_box("filter.recovery_reseed=true")
    pf.init_gaussian([5.0, 5.0, 0.0], [0.1, 0.1, 0.1])
    pf.recovery.observe_lost(True, collapsed=True)
    assert pf.recovery.collapsed and pf.recovery.reseed_due and pf.recovery.lost_updates == 1
    info = StepInfo(particles=pf.n, ess=float(pf.n))
    pf.resample(info)
    assert info.reseeded and pf.protected is None and pf.search.tempering
    assert not pf.recovery.collapsed  # the search it started clears it
    # the same lost update without the collapse: no re-seed yet
    pf = _filter_on_a_box("filter.recovery_reseed=true")
    pf.init_gaussian([5.0, 5.0, 0.0], [0.1, 0.1, 0.1])
    pf.recovery.observe_lost(True, dt=0.2)  # a 5 Hz log (filter.recovery_global_min_s)
    assert not pf.recovery.reseed_due
    # ... and the re-seed it comes to (global_after lost updates later) is protected: a trusted track
    for _ in range(9):
        pf.recovery.observe_lost(True, dt=0.2)  # a 5 Hz log (filter.recovery_global_min_s)
    info = StepInfo(particles=pf.n, ess=float(pf.n))
    pf.resample(info)
    assert info.reseeded and pf.protected is not None and not pf.protected.local
    # a collapse is forgotten once an update is not lost
    from mcl.adaptive import LostRecovery

    r = LostRecovery(0.1, (0.5, 0.5, 0.3), global_after=10, lost_after=3, reseed=True)
    r.observe_lost(True, collapsed=True)
    r.observe_lost(False)
    r.observe_lost(True)
    assert not r.collapsed and not r.reseed_due


def test_a_lost_call_soon_after_an_episode_ended_without_a_reseed_re_seeds_at_once_and_protected():
    # filter.recovery_relapse_s: a robot kidnapped 11.9 m along an office corridor (synthetic.yaml
    # office-short-range-01 kidnapped seed 1) was lost for three updates, then the old place fitted again at 0.65-0.85
    # (the truth at 0.98, 60-100 nats a scan better), lost again 7 s later for three updates, and so on: four short
    # episodes, none long enough for the re-seed, 30.4 s to come back. A lost call within relapse_s (log time) of an
    # episode that ended without a re-seed re-seeds at once.
    from mcl.adaptive import GlobalSearch, LostRecovery
    from mcl.filter import StepInfo

    def feed(r, pattern, dt=0.2):
        due = []
        for lost in pattern:
            r.search.observe(lost, 1.0)
            r.observe_lost(lost, 1.0, dt)
            due.append(r.reseed_due)
        return due

    def recovery(relapse_s):
        return LostRecovery(0.1, (0.5, 0.5, 0.3), global_after=10, lost_after=3, reseed=True, search=GlobalSearch(),
                            relapse_s=relapse_s)

    episode, quiet = [True] * 3, [False] * 30  # 3 lost updates, then 6 s of log (30 updates at 0.2 s) that fit
    r = recovery(10.0)
    assert not any(feed(r, episode + quiet))  # the first episode: no re-seed (global_after is 10 updates)
    assert r.since_episode == pytest.approx(29 * 0.2)  # counted from the update that ended it
    assert feed(r, [True]) == [True] and r.relapsed  # lost again 6 s after: at once
    assert not any(feed(recovery(0.0), episode + quiet + [True]))  # off: the second call waits as the first did
    late = recovery(5.0)
    assert not any(feed(late, episode + quiet + [True]))  # 6 s after: past a 5 s bound
    assert not late.relapsed
    # a good update forgets the relapse, and a search started since clears the episode (nothing ended without one)
    r = recovery(10.0)
    feed(r, episode + quiet + [True, False])
    assert not r.relapsed and not r.reseed_due
    r = recovery(10.0)
    feed(r, episode + quiet)
    r.search.start()
    r.start_search()
    r.search.reset()
    assert r.since_episode is None and not any(feed(r, [True]))
    # nor does an episode a re-seed ran in: it did not end by the track fitting again (suites/sparse-hall.yaml
    # hall-fast-people-914 tracking seed 1: counted, the call 1.2 s after it re-seeded, and a place 28 m off where
    # the people fitted at 1.0 took the track, 34 m max against 1.7)
    r = recovery(10.0)
    feed(r, episode)
    r.search.start()
    r.start_search()
    r.search.reset()
    feed(r, episode + quiet)
    assert r.since_episode is None and not any(feed(r, [True]))
    # in the filter: a track from a known pose is trusted, so the re-seed a relapse makes is protected
    pf = _filter_on_a_box("filter.recovery_reseed=true", "filter.recovery_relapse_s=10")
    pf.init_gaussian([5.0, 5.0, 0.0], [0.1, 0.1, 0.1])
    feed(pf.recovery, episode + quiet + [True])
    assert pf.recovery.reseed_due
    info = StepInfo(particles=pf.n, ess=float(pf.n))
    pf.resample(info)
    assert info.reseeded and pf.protected is not None and not pf.protected.local
    assert not pf.recovery.relapsed and pf.recovery.since_episode is None  # the search it started clears both


def test_a_second_reseed_draws_the_grown_set_back_down_so_the_set_stays_within_twice_the_particles():
    # A re-seed doubles a full set; a filter that is lost again before any resample shrank it (kld off, or
    # probation re-seeding at once) was re-seeded from 8,000 to 16,000, 32,000, ...: the 100,000-particle global
    # search of a large world grew until it was killed for memory (24 GB). The old cloud is drawn down to
    # `particles` first.
    from mcl.filter import StepInfo

    # (reseed_odds 0: a protected re-seed resamples its two sides apart until one leads, and is not re-seeded)
    pf = _filter_on_a_box("filter.recovery_reseed=true", "filter.kld=false", "filter.reseed_odds=0")
    pf.init_gaussian([5.0, 5.0, 0.0], [0.1, 0.1, 0.1])
    for _ in range(3):
        pf.search.holding = False
        for _ in range(10):
            pf.recovery.observe_lost(True, dt=0.2)  # a 5 Hz log (filter.recovery_global_min_s)
        info = StepInfo(particles=pf.n, ess=float(pf.n))
        pf.resample(info)
        assert info.reseeded and pf.n == 8000 and info.injected == 4000
        w = np.exp(pf.logw)
        assert w[:4000].sum() == pytest.approx(0.5)


def test_a_fast_lasers_probation_lasts_the_seconds_fifty_updates_span_at_5_hz():
    # filter.recovery_probation_min_s: 50 updates after a search are 10 s at 5 Hz but 1.7 s at 30 Hz. With the floor
    # (10 s) a lost call 60 updates (2 s) after a 30 Hz search re-seeds at once; without it, it is past the probation.
    # At 5 Hz the count alone decides, as before: off probation at the 51st update, 10.0 s after the search ended.
    from mcl.adaptive import GlobalSearch, LostRecovery

    def after_search(min_s: float, dt: float, fitting: int):
        r = LostRecovery(0.1, (0.5, 0.5, 0.3), global_after=10, lost_after=3, reseed=True, probation=50,
                         search=GlobalSearch(), probation_min_s=min_s)
        _start(r)
        for _ in range(fitting):  # the search ends at its first fitting update, then the place fits on
            r.search.observe(False, 1.0, None, dt)
            r.observe_lost(False, 1.0, dt)
        return r

    assert after_search(10.0, 1 / 30, 60).on_probation
    assert not after_search(0.0, 1 / 30, 60).on_probation
    assert after_search(10.0, 1 / 30, 300).on_probation  # 299 x 1/30 s: 9.97 s
    assert not after_search(10.0, 1 / 30, 302).on_probation  # 10.03 s
    for min_s in (0.0, 10.0):
        assert after_search(min_s, 0.2, 50).on_probation
        assert not after_search(min_s, 0.2, 51).on_probation
    r = after_search(10.0, 1 / 30, 60)
    r.search.observe(True, 1.0, None, 1 / 30)
    r.observe_lost(True, 1.0, 1 / 30)
    assert r.reseed_due  # the first lost call re-seeds
    r = _lost_recovery(True, probation=0)  # probation off: the floor is inert
    r.probation_min_s = 10.0
    _start(r)
    _observe(r, False)
    assert not r.on_probation


def test_probation_reseeds_at_the_first_lost_call_after_a_search_and_only_then():
    r = _lost_recovery(True, probation=5)
    _observe(r, True)  # a track that never searched: the usual 10 lost updates
    assert not r.reseed_due and not r.on_probation
    _start(r)
    _observe(r, True, cluster_weight=0.95)  # settles, and is lost at once: re-seed now
    assert not r.search.holding and r.on_probation and r.reseed_due
    _start(r)
    _observe(r, False)  # settles and fits ...
    for _ in range(5):
        _observe(r, False)
    _observe(r, True)  # ... lost 6 updates after the search: probation is over, the usual count again
    assert not r.on_probation and not r.reseed_due
    for _ in range(9):
        _observe(r, True)
    assert r.reseed_due
    off = _lost_recovery(True, probation=0)
    _start(off)
    _observe(off, True, cluster_weight=0.95)
    assert not off.reseed_due  # probation 0: off (the update that ends the search is the 0th)


def _spread_around(track, trial: bool):
    """A filter tracking ``track`` in the room with a wall, lost on a refuting scan and resampled once: the set
    holds its older particles and the poses lost recovery spread around the estimate (``pf._injected``)."""
    from mcl.config import load_config
    from mcl.filter import ParticleFilter, StepInfo

    grid = _room_with_a_wall()
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        "rerun.mode=off", "filter.particles=4000", "filter.kld=false", "filter.recovery=lost",
        f"filter.recovery_trial={str(trial).lower()}", "filter.recovery_protect=false"])
    pf = ParticleFilter(cfg, grid, rng=np.random.default_rng(5))
    pf.init_gaussian(track, [0.05, 0.05, 0.02])
    pf.recovery.observe_lost(True, refuted=True)  # a lost scan that refutes the pose: spread at once
    assert pf.recovery.spreading
    pf.resample(StepInfo(particles=pf.n, ess=float(pf.n)))
    assert pf._injected is not None and 200 < pf._injected.sum() < 600  # recovery_fraction 0.1 of 4,000
    return pf, grid


def _weigh(pf, grid, heavy, scan_at) -> None:
    """This update's scan, cast at ``scan_at``; the particles ``heavy`` hold 95 % of the weight."""
    from mcl.filter import StepInfo

    pf._scan_observation = pf.prepare(_cast_scan(grid, scan_at), np.zeros(3))
    pf.logw = np.full(pf.n, -np.log(pf.n))
    pf.logw[heavy] += np.log(0.95 / 0.05 * (pf.n - heavy.size) / heavy.size)
    pf.normalize(StepInfo(particles=pf.n))
    assert abs(pf.weights[heavy].sum() - 0.95) < 1e-9


def test_a_few_lucky_spread_poses_do_not_pull_the_estimate_off_a_track_the_scan_fits_better():
    # suites/heldout2.yaml clutter-map10cm-h9 seed 1: at the first spread, 6 of 537 fresh poses 1-2 m off took half
    # the weight; the heaviest cluster (0.5 m cells, joined by the spread) had its mean 0.85 m off, where no
    # particle was and the scan fitted at -0.25, against 0.49 at the track, which was within 0.3 m.
    from mcl.filter import StepInfo

    track = np.array(TRUE_POSE)
    est = {}
    for trial in (True, False):
        pf, grid = _spread_around(track, trial)
        fresh = np.flatnonzero(pf._injected)
        far = fresh[np.argsort(-np.hypot(*(pf.particles[:2, fresh] - track[:2, None])))[:3]]
        assert np.hypot(*(pf.particles[:2, far] - track[:2, None])).min() > 1.0
        _weigh(pf, grid, far, scan_at=track)
        est[trial] = pf.estimate(StepInfo(particles=pf.n))[0]
    assert np.hypot(*(est[True][:2] - track[:2])) < 0.05  # the older particles' mean: the track
    assert np.hypot(*(est[False][:2] - track[:2])) > 0.3  # the whole set's heaviest cluster, pulled off


def test_spread_poses_that_found_the_robot_move_the_estimate_at_once():
    # the other side of the rule above: where the fresh poses fit the scan better than the track (fr079's odometry
    # slip at 305 s), the estimate goes with them in this update; waiting for their descendants took that log's
    # worst error from 0.99 to 1.40 m
    from mcl.filter import StepInfo

    truth = np.array(TRUE_POSE)
    pf, grid = _spread_around(truth + [1.2, 0.0, 0.0], trial=True)  # the track slipped 1.2 m
    fresh = np.flatnonzero(pf._injected)[:40]
    pf.particles[:, fresh] = truth[:, None] + pf.rng.normal(0.0, [[0.03], [0.03], [0.01]], (3, fresh.size))
    _weigh(pf, grid, fresh, scan_at=truth)
    mean = pf.estimate(StepInfo(particles=pf.n))[0]
    assert np.hypot(*(mean[:2] - truth[:2])) < 0.15


def test_the_laser_likelihood_is_tempered_while_lost_recovery_spreads_poses():
    scan = _scan(4.0)
    gains = {}
    for e in (1.0, 0.3):
        pf = _filter_on_a_box(f"filter.lost_exponent={e}", "filter.search_exponent=1.0")
        pf.init_gaussian([5.0, 5.0, 0.0], [1.0, 1.0, 1.0])
        obs = pf.prepare(scan, np.zeros(3))
        for state in ("fits", "waits", "spreads"):
            # a lost update whose scan looks occluded: the recovery waits, the scan counts in full; one that
            # refutes the estimate: poses are spread and the scan tempered
            pf.recovery.observe_lost(state != "fits", refuted=state == "spreads")
            assert pf.recovery.spreading == (state == "spreads")
            gains[e, state] = _correction_gain(pf, obs)
    np.testing.assert_allclose(gains[0.3, "spreads"], 0.3 * gains[1.0, "spreads"], rtol=1e-12)
    for state in ("fits", "waits"):
        np.testing.assert_allclose(gains[0.3, state], gains[1.0, state], rtol=1e-12)
    assert np.ptp(gains[1.0, "fits"]) > 10.0


def _scan(r: float):
    """181 readings of r metres over 180 degrees, the laser at the robot centre."""
    from mcl.datasets.carmen import Scan

    return Scan(t=0.0, ranges=np.full(181, r), angle_min=-np.pi / 2, angle_increment=np.pi / 180,
                max_range=None, odom=np.zeros(3), laser_offset=None)


def _correction_gain(pf, obs) -> np.ndarray:
    """(N,) what one correction with ``obs`` adds to the log weights."""
    from mcl.filter import StepInfo

    before = pf.logw.copy()
    pf.correct(obs, StepInfo(particles=pf.n))
    return pf.logw - before


def test_the_laser_likelihood_is_tempered_only_while_a_global_search_is_under_way():
    scan = _scan(4.0)
    gains = {}
    for e in (1.0, 0.2):
        pf = _filter_on_a_box(f"filter.search_exponent={e}", "filter.global_density=0")
        pf.init_global()
        assert pf.search.tempering
        obs = pf.prepare(scan, np.zeros(3))
        gains[e] = _correction_gain(pf, obs)
        # settled (a cluster holds 90 % of the weight): the full likelihood again
        pf.search.tempering = False
        gains[e, "settled"] = _correction_gain(pf, obs)
    np.testing.assert_allclose(gains[0.2], 0.2 * gains[1.0], rtol=1e-12)
    np.testing.assert_allclose(gains[0.2, "settled"], gains[1.0], rtol=1e-12)
    assert np.ptp(gains[1.0]) > 10.0  # the scan does tell the poses apart


def test_global_density_draws_the_fresh_poses_where_the_scan_fits_and_counts_the_scan_once():
    from mcl.filter import StepInfo

    # a 10 m box and a scan of 2 m readings over 180 degrees: poses facing a wall 2 m away fit some of it
    scan = _scan(2.0)
    own = {}
    for k in (1, 10):
        # 4,000 particles over the box's 96 m2 of free space: 41.6 per m2, so a density of 40 per m2 draws no
        # candidates (k = 1) and one of 400 draws ceil(400 x 96 / 4,000) = 10 per particle
        # search_refine off: the scan matching would move the poses too, and this is about the draw alone
        pf = _filter_on_a_box(f"filter.global_density={40 * k}", "filter.search_exponent=1.0", "filter.search_refine=0")
        pf.init_global()
        obs = pf.prepare(scan, np.zeros(3))
        before = pf.particles.copy()
        pf.correct(obs, StepInfo(particles=pf.n))
        gain = pf.logw - np.log(1.0 / pf.n)
        own[k] = pf.sensor.log_likelihood(pf.particles, obs)
        if k == 1:
            np.testing.assert_array_equal(pf.particles, before)  # off: nothing drawn again
            np.testing.assert_allclose(gain, own[1])
        else:
            assert not np.array_equal(pf.particles, before)
            # every fresh pose carries the same evidence, the candidates' mean likelihood: between the mean
            # log-likelihood of uniform poses (Jensen) and the best of the poses drawn
            assert np.ptp(gain) == 0.0
            assert own[1].mean() < gain[0] < own[10].max()
    # drawn in proportion to the likelihood of 10x as many candidates: the poses fit the scan far better
    assert np.median(own[10]) > np.median(own[1]) + 20.0, (np.median(own[10]), np.median(own[1]))


def test_fresh_poses_drawn_anew_from_candidates_are_neither_matched_nor_scored_first():
    # On a big map a global start's fresh poses are drawn anew from k candidates each (filter.global_density): the
    # poses themselves were scan-matched and scored first, then replaced (64-80 % of such an update's time on
    # infinite_corridor). Now only the candidates are scored; a re-seed's old cloud is matched and scored as before.
    from mcl.filter import StepInfo

    # With search_refine_candidates (the default) the best candidate per fresh pose as drawn is matched and
    # scored again (filter._MATCHED_PER_FRESH; all 10 cost 4x the CPU of a kidnapped run on a big building).
    scan = _scan(2.0)
    for cands, expect_scored, expect_matched in (("false", [10], []), ("true", [10, 1], [1])):
        pf = _filter_on_a_box("filter.global_density=400", "filter.search_exponent=1.0",  # k = 10 (the test above)
                              f"filter.search_refine_candidates={cands}")
        scored, matched = [], []
        score, refine = pf.sensor.log_likelihood, pf._refined
        pf.sensor.log_likelihood = lambda p, o, out=None, searching=False: (scored.append(p.shape[1]),
                                                                             score(p, o, out, searching=searching))[1]
        pf._refined = lambda poses, o, steps: (matched.append(poses.shape[1]), refine(poses, o, steps))[1]
        pf.init_global()
        obs = pf.prepare(scan, np.zeros(3))
        pf.correct(obs, StepInfo(particles=pf.n))
        assert scored == [m * pf.n for m in expect_scored], (cands, scored)
        assert matched == [m * pf.n for m in expect_matched], (cands, matched)
        assert np.isfinite(pf.logw).all()


def test_the_likelihood_field_scores_with_the_search_field_exactly_while_the_laser_is_tempered():
    # sensor.likelihood_field.search_interior applies while a global search runs or lost recovery spreads poses
    # (the updates search_exponent / lost_exponent temper), and the interior field otherwise.
    scan = _scan(4.0)
    pf = _filter_on_a_box("filter.global_density=0")
    seen = []
    score = pf.sensor.log_likelihood

    def spy(particles, observation, out=None, searching=False):
        seen.append(searching)
        return score(particles, observation, out, searching=searching)

    pf.sensor.log_likelihood = spy
    pf.init_gaussian([5.0, 5.0, 0.0], [0.2, 0.2, 0.1])
    obs = pf.prepare(scan, np.zeros(3))
    _correction_gain(pf, obs)  # tracking
    pf.recovery.observe_lost(True, dt=0.2)  # a 5 Hz log (filter.recovery_global_min_s)
    _correction_gain(pf, obs)  # lost: poses spread around the estimate
    pf.recovery.observe_lost(False)
    _correction_gain(pf, obs)
    pf.init_global()
    _correction_gain(pf, obs)  # a global search
    pf.search.tempering = False
    _correction_gain(pf, obs)  # settled
    assert seen == [False, True, False, True, False]


def test_a_global_start_builds_the_search_field_before_the_first_update_and_tracking_does_not():
    # The search field (search_interior's table, map-sized) is made when a global search starts, so its cost is
    # the start's and not the first update's; a track started from a known pose builds it only if it gets lost.
    pf = _filter_on_a_box("sensor.likelihood_field.interior=depth", "sensor.likelihood_field.search_interior=zero")
    pf.init_gaussian([5.0, 5.0, 0.0], [0.1, 0.1, 0.1])
    assert pf.sensor._search_table is None
    pf.init_global()
    assert pf.sensor._search_table is not None and pf.sensor._search_table is not pf.sensor.table


def _stall_setup(active: float = 60.0):
    from mcl.adaptive import GlobalSearch, LostRecovery, StallCheck

    search = GlobalSearch()
    stall = StallCheck(0.6, window=3.0, min_travel=1.5, active=active, search=search)
    r = LostRecovery(0.1, (0.5, 0.5, 0.3), global_after=10, lost_after=3, reseed=True, probation=0,
                     search=search, stall=stall)
    return r, stall


class _Drive:
    """A robot driving along x at 0.8 m/s, one update every 0.2 s; the estimate moves ``follows`` as far."""

    def __init__(self, r, stall):
        self.r, self.stall, self.odo, self.est = r, stall, 0.0, 10.0

    def run(self, seconds: float, follows: float, speed: float = 0.8, std: float = 0.1) -> list[bool]:
        out = []
        cov = np.diag([std**2, std**2, 0.01])
        for _ in range(round(seconds / 0.2)):
            self.odo += speed * 0.2
            self.est += follows * speed * 0.2
            _observe(self.r, False)
            self.stall.observe(0.2, (self.est, 3.0, 0.0), cov, (self.odo, -7.0, 1.0))
            out.append(self.r.reseed_due)
        return out


def test_a_place_a_search_found_is_re_seeded_when_its_estimate_stalls_while_the_odometry_drives_on():
    # suites/synthetic.yaml corridor-02 global: the search settles in a dead-end corridor whose walls fit the scans
    # as well as the true one's; the robot drives 40 m while the map pulls the estimate back at every scan. Ratio
    # 0.6 over 3 s, at least 1.5 m of odometry: a correct track moved 0.87 times as far as the truth or more in
    # 99.9 % of the synthetic suite's 3 s windows and never under 0.6, so a stop is no drift.
    r, stall = _stall_setup()
    d = _Drive(r, stall)
    assert not any(d.run(20.0, follows=0.0))  # a track from a known pose is never tested (fr079's odometry
    _start(r)  # reports 1.9 m over 5 s where the robot moved 0.14 m, on a correct track)
    _observe(r, False, cluster_weight=0.95)  # the search settles
    assert not any(d.run(20.0, follows=0.95))  # the place follows the odometry: no stall
    due = d.run(10.0, follows=0.0)  # ... then stops while the odometry drives on
    first = due.index(True)
    # from the 6th stopped update the window's 15 updates hold 9 moving ones (1.37 m < 0.6 x 2.4 m); 3 in a row
    assert first == 7 and stall.stalled
    assert r.reseed_due and not r.lost_updates  # the re-seed comes without a lost call

    # a new search starts the test again: no stall until a whole window of the new place is seen
    _start(r)
    assert not r.reseed_due
    _observe(r, False, cluster_weight=0.95)
    assert not any(d.run(3.2, follows=0.0))  # 15 updates to span the window, the 16th to 18th short
    assert any(d.run(0.6, follows=0.0))

    # one update's jump of the estimate (a cloud that still has two modes) does not make the next window short
    r, stall = _stall_setup()
    d = _Drive(r, stall)
    _start(r)
    _observe(r, False, cluster_weight=0.95)
    assert not any(d.run(10.0, follows=1.0))
    d.est += 2.4  # ahead, as corridor-01's estimate 1 s after its search; the 3 s from there come up 2.4 m short
    assert not any(d.run(0.2, follows=1.0))
    d.est -= 2.4
    assert not any(d.run(10.0, follows=1.0))
    assert stall.run == 0

    # a slow robot (1 m in 5 s) is no evidence; a spread cloud (x std 2 m) is no place yet
    for kwargs in ({"speed": 0.2}, {"std": 2.0}):
        r, stall = _stall_setup()
        d = _Drive(r, stall)
        _start(r)
        _observe(r, False, cluster_weight=0.95)
        assert not any(d.run(15.0, follows=0.0, **kwargs)), kwargs

    # a place that has held for `active` seconds is no longer tested
    r, stall = _stall_setup(active=20.0)
    d = _Drive(r, stall)
    _start(r)
    _observe(r, False, cluster_weight=0.95)
    assert not any(d.run(20.0, follows=1.0))
    assert not any(d.run(10.0, follows=0.0))


def test_a_stall_window_across_a_jump_of_the_estimate_is_short_only_if_the_new_place_does_not_follow_either():
    # suites/heldout2.yaml corridor-noisy-laser-h9 global seed 2: the search's estimate, its heading flipped in the
    # corridor, drove the wrong way for a second, then jumped to the true pose and tracked it within 0.15 m; the 3 s
    # window across the jump saw 0.2 m of estimate against 2.4 m of odometry, and the correct track was re-seeded.
    r, stall = _stall_setup()
    d = _Drive(r, stall)
    _start(r)
    _observe(r, False, cluster_weight=0.95)
    assert not any(d.run(1.0, follows=-1.0))  # 0.8 m the wrong way
    d.est -= 1.6  # to the true pose, 1.6 m behind
    # the windows across the jump hold 0.8 m of estimate against 2.4 m of odometry (short, 3 in a row by 2.6 s)
    assert not any(d.run(6.0, follows=1.0))
    assert stall.run == 0
    assert any(d.run(4.0, follows=0.0))  # the new place stalls in its turn

    # a jump to another stretch of a wrong corridor, after which the estimate still does not follow: the stall
    # comes when it would have without the jump (restarting the window at the jump would hold such a place a
    # whole window longer)
    firsts = []
    for jump in (0.0, -1.5):
        r, stall = _stall_setup()
        d = _Drive(r, stall)
        _start(r)
        _observe(r, False, cluster_weight=0.95)
        due = d.run(1.0, follows=0.4)
        d.est += jump
        due += d.run(5.0, follows=0.4)
        firsts.append(due.index(True))
    assert firsts[0] == firsts[1] == 17  # the same update


def test_a_reseed_on_a_stalled_estimate_keeps_nothing_of_the_old_cloud():
    from mcl.filter import StepInfo

    pf = _filter_on_a_box("filter.recovery_reseed=true", "filter.stall_ratio=0.5")
    assert pf.stall is not None and pf.recovery.stall is pf.stall
    assert _filter_on_a_box("filter.stall_ratio=0").stall is None  # 0: off
    pf.init_gaussian([5.0, 5.0, 0.0], [0.1, 0.1, 0.1])
    pf.stall.stalled = True
    info = StepInfo(particles=pf.n, ess=float(pf.n), stalled=True)
    pf.resample(info)
    # the whole set is new, uniform over the box, and a search is under way
    assert info.reseeded and info.injected == pf.n == 4000
    assert np.all(np.isfinite(pf.logw)) and np.exp(pf.logw).sum() == pytest.approx(1.0)
    p = pf.particles
    assert p[0].min() < 2.0 and p[0].max() > 8.0 and p[1].min() < 2.0 and p[1].max() > 8.0
    assert np.mean(np.hypot(p[0] - 5.0, p[1] - 5.0) < 1.0) < 0.1  # nothing left of the cloud at (5, 5)
    assert pf.search.tempering and pf.search.holding


FR101 = PROJECT_ROOT.parent / "shared" / "data" / "fr101"


@pytest.mark.slow
@pytest.mark.skipif(not (FR101 / "log.clf").is_file(), reason=f"fr101 data set not found at {FR101}")
def test_a_sparse_log_kidnapped_is_called_lost_at_its_first_scan_and_back_sooner(tmp_path):
    # fr101 has a scan every 2.6 s. Kidnapped as `mcl eval` kidnaps a real log (the filter's particles moved at
    # mid-truth, 620.9 s, to a cloud 6.4 m away), seed 1, the default config: its first scan after the kidnap
    # scores -0.77 (0.27 match, 0.52 of the beams through walls), so quality.lost_at_once_below (0) calls it lost
    # at once and the global re-seed follows 3 lost updates and recovery_global_after_s (3 s) later: back within
    # 0.5 m after 7.6 s (seeds 1-5: 7.6 s each). With the rules before (3 bad of 5 scans, then 10 s lost):
    # 30.4 s (seeds 1-5: 26.3-32.0 s; the log also has 17 s without a scan after the kidnap). Bounds 15 and
    # 20 s: each clear of its measured values by more than 5 s.
    from mcl.config import load_config
    from mcl.evaluate import position_errors, settle_time
    from mcl.runner import run
    from mcl.suite import KIDNAP_M, SETTLE_M, _mid_truth
    from mcl.trajectory import read_tum

    def kidnapped(*sets):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
            f"map={FR101 / 'map.yaml'}", f"log={FR101 / 'log.clf'}", f"truth={FR101 / 'truth.tum'}",
            "filter.initial_pose=[0.108623, -0.034410, 0.552197]", "filter.global_localization=false",
            "rerun.mode=off", *sets])
        out = tmp_path / str(len(sets))
        s = run(cfg, out, progress=False, echo=lambda *_: None, kidnap_filter_at=(_mid_truth(cfg.truth), KIDNAP_M))
        t, e, _ = position_errors(*read_tum(out / "trajectory.tum"), *read_tum(cfg.truth))
        k = s["kidnap"]["t"]
        assert e[t < k].max() < 0.5  # tracked before the kidnap
        return settle_time(t[t >= k], e[t >= k], k, SETTLE_M, stay=1.0)

    # (the protected re-seed, filter.reseed_odds, lets this first scan decide: it fits the true place at 0.96 and
    # the kidnapped track at 0.34; had it waited for a second scan, that came 17 s later: back after 24.8 s)
    now = kidnapped()
    assert now is not None and now <= 15.0, now
    before = kidnapped("filter.reseed_odds=0", "quality.lost_at_once_below=-2", "filter.recovery_global_after_s=10")
    assert before is None or before >= 20.0, before


def test_people_crowding_the_robot_do_not_make_a_correct_track_lost_and_hijacked(tmp_path_factory, tmp_path):
    # suites/heldout.yaml hall-h2 (a 30 m laser in an open hall, 8 people walking): at 85 s the people close round
    # the robot, match falls to 0.41-0.55 at the true pose with no beam through a wall, and with quality.lost_below
    # alone that is "lost" for 10 updates: the re-seed that follows lands 55 m away (a place where the crowded scan
    # matches 0.82 with 18 % of the beams through walls), on every seed. quality.occluded_below (0.4) reads a scan
    # that contradicts nothing as an occlusion: the track is never called lost and ends within 0.16 m. (The
    # protected re-seed, filter.reseed_odds, also keeps this track by itself: the place 55 m away fits the crowded
    # scans worse by the quality score, so its likelihood never counts. The control turns off both, and
    # quality.occluded_missing, which reads a sparse view's low match as occlusion, and filter.reseed_hold_pose,
    # which reports the track moved by the odometry while the unprotected re-seed's search is lost, too.)
    from mcl.simulate import simulate

    data = tmp_path_factory.mktemp("crowd")
    sim = simulate(data, kind="hall", seed=422, duration=90.0, dynamic_obstacles=8, range_max=30.0)
    s = _track(data, sim, tmp_path / "default")
    assert s["eval"]["ate_max"] < 0.5, s["eval"]
    assert s["quality"]["lost_updates"] == 0, s["quality"]
    before = _track(data, sim, tmp_path / "before", "quality.occluded_below=1.0", "quality.occluded_missing=-1",
                    "filter.reseed_odds=0", "filter.reseed_hold_pose=false")
    assert before["eval"]["ate_max"] > 5.0, before["eval"]
    assert before["quality"]["lost_updates"] > 0, before["quality"]


def test_a_few_returns_in_a_crowd_do_not_hand_a_track_to_a_search(tmp_path_factory, tmp_path):
    # A hall with 24 people walking, a 12 m laser with a fifth of its readings at maximum range (a hunt's world, seed
    # 3631): the scans hold 5-30 returns, most of them people, and the correct track is called lost again and again.
    # At 67 s a protected re-seed's search found a place 38 m away that fitted a scan of nine returns at 0.9 while the
    # track fitted none: decisive, that one scan took the estimate, and the run ended 47.6-48.4 m off (seeds 1-3; the
    # baseline, which never re-seeds, 1.3-1.8 m). A scan decides at once only with quality.held_min_beams (15) returns
    # or more: 1.41-1.45 m measured (the people pull the estimate off; 3 m allowed); with the bar at 0, 48.4 m.
    kept, off = _tracked_and_mend_off(tmp_path_factory, tmp_path, "quality.held_min_beams=0", kind="hall", seed=3631,
                                      duration=90.0, dynamic_obstacles=24, map_resolution=0.025, p_max=0.2)
    assert kept["ate_max"] < 3.0, kept
    assert off["ate_max"] > 20.0, off


def test_a_track_held_again_after_a_lost_call_is_not_turned_by_the_fault_poses(tmp_path_factory, tmp_path):
    # A clutter world whose map draws six squares of walls twice, turned and 1 % small (a hunt's world, seed 3676):
    # at 36 s the walls drawn twice send a tenth of a correct track's beams through mapped walls, it is called lost,
    # and the fault window opens. The track holds again at 37 s, but the window's fault poses kept their full
    # heading width, and at 42.4 s one turned 52 degrees, in a square whose doubled walls it fits as well, took the
    # estimate: 1.95 m off (seeds 1 and 3: 1.95 and 5.25 m; the baseline 0.41-0.44 m). With the heading capped
    # once the track holds again (motion.fault_held_turn_max 0.5 rad/s): 0.42 m measured (0.5 m allowed).
    kept, wide = _tracked_and_mend_off(tmp_path_factory, tmp_path, "motion.fault_held_turn_max=0", kind="clutter",
                                       seed=3676, duration=90.0, map_scale=0.99, map_rotation=1.0584, doubled_walls=6)
    assert kept["ate_max"] < 0.5, kept
    assert wide["ate_max"] > 1.5, wide


def test_a_crowd_that_pulls_the_estimate_a_little_off_is_no_lost_track(tmp_path_factory, tmp_path):
    # suites/synthetic.yaml clutter-03 driven at 1.5 m/s (mcl eval --world speed=1.5): from 46 s people hide half
    # the walls for 5 s and pull the estimate 0.2-0.3 m off. At the estimate 2-8 % of the beams then end 0.35-0.55 m
    # past a wall, the occlusion rule (quality.occluded_below) no longer applied, the track was called lost, and the
    # re-seed took a place 13 m away that fits the crowded scans at 0.8-1.0: lost on every seed of 5, while the
    # baseline kept every one. quality.occluded_depth reads those near misses as occlusion on a held track whose fit
    # had sunk (occluded_prior): within 0.5 m on every seed (0.33-0.37 m measured).
    kept, before = _tracked_and_mend_off(tmp_path_factory, tmp_path, "quality.occluded_depth=0", kind="clutter",
                                         seed=503, duration=60.0, speed=1.5)
    assert kept["ate_max"] < 0.5, kept
    assert before["ate_max"] > 5.0, before


def test_a_robot_kidnapped_in_a_corridor_is_searched_for_not_spread_onto_the_old_stretch(tmp_path_factory, tmp_path):
    # suites/synthetic.yaml corridor-04, kidnapped (at 45 s, 9.7 m along the corridor and turned by 2.15 rad): the
    # first scan after the kidnap goes through walls at the held track. Lost recovery spread poses around the old
    # place, where the corridor, turned as the robot was, fits again: 53 m off to the end (seeds 2 and 3), never
    # called lost again. quality.collapse_from reads a held track lost at once as a kidnap and re-seeds globally at
    # once, unprotected: back within 0.5 m 0.6 s after the kidnap (seed 3). The control, collapse_from 2 (never),
    # is the old behaviour: never back. (Which look-alike a search in a corridor settles on is a coin toss: seed 1
    # went the other way; over the suite's kidnapped runs the rule keeps 100 of 117 against 99, README.)
    from mcl.evaluate import position_errors, settle_time
    from mcl.simulate import simulate
    from mcl.suite import SETTLE_M
    from mcl.trajectory import read_tum

    data = tmp_path_factory.mktemp("corridor-kidnap")
    sim = simulate(data, kind="corridor", seed=304, duration=90.0, speed=1.2, kidnap_at=45.0)

    def back_after(out, *sets):
        _track(data, sim, out, "seed=3", *sets)
        t, e, _ = position_errors(*read_tum(out / "trajectory.tum"), *read_tum(data / "truth.tum"))
        assert e[t < 45.0].max() < 0.5  # tracked before the kidnap
        return settle_time(t[t >= 45.0], e[t >= 45.0], 45.0, SETTLE_M, stay=0.5)

    now = back_after(tmp_path / "default", "filter.ess_floor=0")
    assert now is not None and now <= 5.0, now
    # The control pins the unmatched search: with the default's scan matching (filter.search_refine 3,
    # search_settled_std 1) the matched search finds the robot without the rule too. Since uniform draws come in
    # cache order (fifty-fourth session), the systematic resample of a search is stratified over the map, and the
    # control's late global re-seed found the robot on seed 3 (never before): seeds 1-8 in cache order, the default
    # back after 0.6-1.0 s on every seed, the control after 2.2-4.4 s on 7 and never on seed 7. The bar: the rule
    # brings it back at least a second sooner (seed 3: 1.0 against 2.4 s). Both pin the ESS floor off
    # (filter.ess_floor 0, the default): with it the rule is back after 1.4 s and the control after 2.2 s, under the bar
    # (ninety-ninth session).
    before = back_after(tmp_path / "before", "quality.collapse_from=2", "filter.search_refine=0",
                        "filter.search_settled_std=0", "filter.ess_floor=0")
    assert before is None or before >= now + 1.0, (now, before)


@pytest.mark.slow
def test_people_in_a_depth_cameras_narrow_view_do_not_hand_a_correct_track_to_a_fresh_pose(tmp_path_factory,
                                                                                           tmp_path):
    # suites/heldout.yaml clutter-kinect-h8: a 58-degree, 320-beam, 8 m scan in a cluttered office with people. At
    # 58 s they fill the view and match falls to 0.52 at the true pose with 3-7 % of the beams through mapped items
    # (a 2-4 degree heading drift): lost, and a pose spread 0.5-1 m away, where the people look like walls, took
    # the track on every seed (max 6.7-11.9 m; the baseline's 0.20 m). The recovery now waits filter.recovery_wait
    # updates on scans that look occluded: within 0.5 m (0.20-0.22 m measured on seeds 1-3). The control spreads at
    # once, as before (seed 2: 8.9 m). Both with the depth tolerance a SLAM map takes (0.05 m): this world's map is
    # drawn solid, where the default takes none (mcl.sensors.drawn_solid), and with that the control holds too
    # (0.22 m: the fresh poses' fit no longer beats the track's), so the default run is checked on its own as well.
    from mcl.simulate import simulate

    data = tmp_path_factory.mktemp("kinect")
    sim = simulate(data, kind="clutter", seed=541, duration=90.0, fov=1.0123, n_beams=320, range_max=8.0)
    slam = "sensor.likelihood_field.interior_tolerance=0.05"
    s = _track(data, sim, tmp_path / "wait", "seed=2", slam)
    assert s["eval"]["ate_max"] < 0.5, s["eval"]
    assert s["quality"]["lost_updates"] > 0, s["quality"]  # the scene does make it lost: the wait is what held
    before = _track(data, sim, tmp_path / "before", "seed=2", "filter.recovery_wait=0", slam)
    assert before["eval"]["ate_max"] > 3.0, before["eval"]
    d = _track(data, sim, tmp_path / "default", "seed=2")
    assert d["eval"]["ate_max"] < 0.5 and d["quality"]["lost_updates"] > 0, (d["eval"], d["quality"])


def test_people_crowding_a_depth_cameras_short_view_leave_a_correct_track_held(tmp_path_factory, tmp_path):
    # suites/depth-laser.yaml clutter-kinect: a 59-degree, 640-beam, 4.5 m scan at 15 Hz in a cluttered office. At
    # 2-3 s people fill the view: match 0.29-0.43 at the true pose, no beam through a wall. With a 180-degree
    # laser's occlusion thresholds the track was called lost, the scan refuted it (match < 0.45), and the spread's
    # best pose 1.2 m away, where the people line up with walls, took it: max error 1.23-1.53 m over the first
    # 10 s on seeds 1-4 (17.5 m over the whole run, every seed of 6). quality.narrow_view: scaled (the default)
    # scales them by the view's 59 / 180 degrees: 0.10-0.11 m on seeds 1-4. Bounds: under 0.3 m; over 1 m.
    from mcl.simulate import simulate

    data = tmp_path_factory.mktemp("depth")
    sim = simulate(data, kind="clutter", seed=1109, duration=90.0, fov=1.0297, n_beams=640, range_max=4.5,
                   scan_rate=15.0, range_sigma=0.03)
    # the first 10 s of the log are enough (the crowd at 2-3 s), and a sixth of the run's time
    lines = (data / "log.clf").read_text().splitlines(keepends=True)
    (data / "log.clf").write_text("".join(line for line in lines
                                          if line.startswith(("#", "PARAM")) or float(line.split()[-1]) < 10.0))
    s = _track(data, sim, tmp_path / "default", "seed=2")
    assert s["eval"]["ate_max"] < 0.3, s["eval"]
    same = _track(data, sim, tmp_path / "same", "seed=2", "quality.narrow_view=same")
    assert same["eval"]["ate_max"] > 1.0, same["eval"]


def _room_with_a_wall():
    """A 10 m x 10 m box with a 3 m wall inside, off centre: no other pose sees what one pose sees."""
    from mcl.maps import OccupancyGrid

    occ = np.zeros((100, 100), dtype=np.int8)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 100
    occ[60:62, 20:50] = 100  # rows are y: a wall along x from 2 m to 5 m at y = 6 m
    return OccupancyGrid.from_occupancy(occ, resolution=0.1, origin=(0.0, 0.0))


def _cast_scan(grid, pose):
    """The 181 beams over 180 degrees a laser at ``pose`` reads on ``grid`` (no noise, 8 m max range)."""
    from mcl.datasets.carmen import Scan
    from mcl.kernels.raycast import cast_rays_serial

    angles = np.linspace(-np.pi / 2, np.pi / 2, 181)
    out = np.zeros((1, 181))
    cast_rays_serial(np.asarray(pose, dtype=np.float64).reshape(3, 1), angles,
                     np.ascontiguousarray(grid.occupied, dtype=np.uint8), float(grid.origin[0]),
                     float(grid.origin[1]), float(grid.resolution), 8.0, out)
    return Scan(t=0.0, ranges=out[0], angle_min=-np.pi / 2, angle_increment=np.pi / 180, max_range=8.0,
                odom=np.zeros(3), laser_offset=None)


def _reseeded(track, *sets):
    """A filter tracking around ``track`` from a known pose, re-seeded (lost for global_after updates)."""
    from mcl.config import load_config
    from mcl.filter import ParticleFilter, StepInfo

    grid = _room_with_a_wall()
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        "rerun.mode=off", "filter.particles=4000", "filter.kld=false", "filter.recovery=lost",
        "filter.recovery_reseed=true", *sets])
    pf = ParticleFilter(cfg, grid, rng=np.random.default_rng(5))
    pf.init_gaussian(track, [0.05, 0.05, 0.02])
    for _ in range(cfg.filter.recovery_global_after):
        pf.recovery.observe_lost(True, dt=0.2)  # a 5 Hz log (filter.recovery_global_min_s)
    info = StepInfo(particles=pf.n, ess=float(pf.n))
    pf.resample(info)
    assert info.reseeded and pf.n == 8000 and pf.search.tempering
    return pf, grid


TRUE_POSE = [3.5, 4.5, 1.2]


def test_protected_reseed_odds_count_a_scan_only_where_the_fit_agrees_and_by_three_nats_at_most():
    """mcl.adaptive.ProtectedReseed.weigh on its own: the masses are log masses of (track, search); the scores
    (search's, track's, then the shares through walls: 5 % at the track's where the search is to gain, as at a
    wrong place; a scan the track explains as occlusion has its own test) as the filter gives them."""
    from mcl.adaptive import ProtectedReseed

    def fresh():
        return ProtectedReseed(np.ones(4, dtype=bool), keep=0.5, reseed_odds=4.6, lost_below=0.6)

    p = fresh()
    assert p.odds == 0.0 and not p.settled
    assert p.weigh(0.0, 10.0, lambda: (0.8, 0.7, 0.0, 0.05, 60)) == 3.0 and not p.settled  # agreed, capped at STEP
    assert p.weigh(0.0, 13.0, lambda: (0.8, 0.7, 0.0, 0.05, 60)) == 6.0 and p.settled and not p.track_won
    p = fresh()
    # the likelihood favours the search, the fit the track
    assert p.weigh(0.0, 10.0, lambda: (0.5, 0.7, 0.0, 0.0, 60)) == 0.0
    assert p.weigh(0.0, -8.0, lambda: (0.5, 0.7, 0.0, 0.0, 60)) == -3.0  # both favour the track: capped
    # a spread around the estimate (local): the fit agrees, but the scan fits neither side as a tracked scan does
    # (below lost_below 0.6), so it is no evidence (ground hits of a tilted laser fit no pose near the track); a
    # global search counts it (after a kidnap the search's place fits poorly for many scans while it converges)
    p = ProtectedReseed(np.ones(4, dtype=bool), keep=0.5, reseed_odds=4.6, lost_below=0.6, local=True)
    assert p.weigh(0.0, 10.0, lambda: (0.5, 0.3, 0.0, 0.0, 60)) == 0.0
    assert p.weigh(0.0, -10.0, lambda: (0.3, 0.5, 0.0, 0.0, 60)) == 0.0
    assert p.weigh(0.0, 10.0, lambda: (0.7, 0.3, 0.0, 0.0, 60)) == 3.0
    assert fresh().weigh(0.0, 10.0, lambda: (0.5, 0.3, 0.0, 0.05, 60)) == 3.0
    # a spread's best pose of thousands fitted people filling a narrow view better (0.95) than the correct track
    # did (0.75): a scan counts for a spread only while the track fits it as a lost scan does, and none decides;
    # for the track, a scan that fits it as tracked still counts
    def spread():
        return ProtectedReseed(np.ones(4, dtype=bool), keep=0.5, reseed_odds=4.6, lost_below=0.6, local=True)

    p = spread()
    assert p.weigh(0.0, 10.0, lambda: (0.95, 0.75, 0.0, 0.0, 60)) == 0.0
    assert p.weigh(0.0, 10.0, lambda: (0.95, 0.3, 0.0, 0.0, 60)) == 3.0
    assert not p.settled and spread().weigh(0.0, -10.0, lambda: (0.5, 0.75, 0.0, 0.0, 60)) == -3.0
    assert fresh().weigh(0.0, 10.0, lambda: (0.95, 0.75, 0.0, 0.0, 60)) == 3.0  # a global search counts it
    p = fresh()
    # decisive: fits as tracked vs as lost
    assert p.weigh(0.0, 10.0, lambda: (0.95, 0.3, 0.0, 0.0, 60)) == 10.0 and p.settled
    # ... with returns enough to tell (quality.held_min_beams, 15 in the default): nine returns, all of them people
    # in a hall, fitted a place 38 m away at 0.9 and the correct track at 0; with nothing through a wall at the
    # track they count for nothing, and with a wall crossed they count as any scan does (capped at STEP)
    def few(returns):
        p = ProtectedReseed(np.ones(4, dtype=bool), keep=0.5, reseed_odds=4.6, lost_below=0.6, min_beams=15)
        return p.weigh(0.0, 10.0, lambda: (0.95, 0.0, 0.0, 0.0, returns))

    assert few(9) == 0.0 and few(15) == 10.0 and few(14) == 0.0
    p = ProtectedReseed(np.ones(4, dtype=bool), keep=0.5, reseed_odds=4.6, lost_below=0.6, min_beams=15)
    assert p.weigh(0.0, 10.0, lambda: (0.95, 0.0, 0.0, 0.05, 9)) == 3.0 and not p.settled
    assert fresh().weigh(0.0, -math.inf, lambda: (0.0, 0.0, 0.0, 0.0, 60)) == -math.inf  # the search has no weight left
    assert fresh().weigh(-math.inf, 0.0, None) == math.inf  # nor the track
    p = fresh()
    for _ in range(ProtectedReseed.MAX_UPDATES - 1):
        p.weigh(0.0, 0.0, None)  # no scan: no evidence
    assert not p.settled
    p.weigh(0.0, 0.0, None)
    assert p.settled and p.track_won  # a tie after MAX_UPDATES goes to the track


def test_protected_reseed_counts_no_scan_the_track_explains_as_occlusion_unless_the_search_fits_it_as_tracked():
    """A scan the track explains as occlusion (no beam through a mapped wall) is no evidence for the search, unless
    it fits there as a tracked scan does: people end readings short of walls and never make them go through one,
    and a place elsewhere that lays some of them on its walls fits better without being right. Scores and shares
    through walls as in hall-people-dropouts-h10 with scans 0.1 s late, where such scans handed a place 10.7 m away
    the estimate, and heldout9 hall-360-crowd-h16, where a place 12.4 m away with nothing through walls either took
    it (search first: score, score, through walls, through walls)."""
    from mcl.adaptive import ProtectedReseed

    def fresh(local=False):
        return ProtectedReseed(np.ones(4, dtype=bool), keep=0.5, reseed_odds=4.6, lost_below=0.6, local=local)

    p = fresh()
    for _ in range(5):
        assert p.weigh(0.0, 10.0, lambda: (0.62, 0.48, 0.034, 0.0, 60)) == 0.0
    assert not p.settled
    # neither through walls (hall-360-crowd-h16 at 59.6-61 s: 0.68-0.73 against 0.32-0.50): no evidence either;
    # this line read 3.0 before the sixty-first session
    for _ in range(5):
        assert p.weigh(0.0, 10.0, lambda: (0.68, 0.32, 0.0, 0.0, 60)) == 0.0
    assert not p.settled
    assert fresh().weigh(0.0, 10.0, lambda: (0.62, 0.48, 0.05, 0.02, 60)) == 3.0  # the track through walls too
    assert fresh().weigh(0.0, 10.0, lambda: (0.89, 0.8, 0.02, 0.0, 60)) == 0.0  # just below DECISIVE_FIT
    # a place that fits as a tracked scan does (DECISIVE_FIT 0.9) is not discredited by one stray beam through a
    # corner (the demo's recovery from its kidnapping: 0.89-0.96 with one such beam, against the track's 0.8)
    assert fresh().weigh(0.0, 10.0, lambda: (0.93, 0.83, 0.02, 0.0, 60)) == 3.0
    assert fresh().weigh(0.0, 10.0, lambda: (0.95, 0.3, 0.02, 0.0, 60)) == 10.0  # decisive: fits as tracked vs lost
    assert fresh().weigh(0.0, -10.0, lambda: (0.3, 0.5, 0.2, 0.0, 60)) == -3.0  # evidence for the track counts
    assert fresh().weigh(0.0, -10.0, lambda: (0.3, 0.5, 0.0, 0.0, 60)) == -3.0  # ... occluded at both or not
    assert fresh().weigh(0.0, 10.0, lambda: (0.95, 0.7, 0.0, 0.0, 60)) == 3.0  # a search's place that fits as tracked
    assert fresh(local=True).weigh(0.0, 10.0, lambda: (0.7, 0.3, 0.05, 0.0, 60)) == 3.0  # a spread: its own rules


def test_a_protected_reseed_keeps_a_correct_track_and_drops_the_search_without_probation():
    # freiburg-campus, tracking with gentle odometry: a correct track fits poorly outdoors for seconds at a time;
    # re-seeded, one scan that a place 170 m away fitted better handed it the whole set at the next resample, and
    # the estimate jumped there (RMSE 15 m). The track now stays its own component until one side leads by
    # reseed_odds, or the search gathers on the track's own place; here the scan is exact and the track right.
    for matched in ("true", "false"):
        pf, grid = _reseeded(TRUE_POSE, f"filter.search_refine_candidates={matched}")
        assert pf.protected is not None and pf.protected.track.sum() == 4000
        obs = pf.prepare(_cast_scan(grid, TRUE_POSE), np.zeros(3))
        # one exact scan gathers the search's fresh poses (drawn from 40,000 candidates) on the track's place: it
        # found nothing else, and the search is dropped at once (no scan decides by the odds: STEP 3 < 4.6)
        info = pf.step(None, obs)
        assert pf.protected is None and info.confirmed and not info.switched, matched
        assert pf.n == 4000 and np.hypot(*(info.mean[:2] - TRUE_POSE[:2])) < 0.1, matched
        assert not pf.search.tempering and not pf.search.holding and pf.search.since_end is None
        assert not pf.recovery.on_probation


def test_a_search_that_gathers_on_the_track_confirms_it_and_one_that_does_not_leaves_the_odds_to_decide():
    """ParticleFilter._search_concurs: with the search's candidates matched (filter.search_refine_candidates) its
    fresh poses sit on a correct track's place from the first scan and fit it as well as the track does, so the
    scans no longer move the odds: without the rule the re-seed ran its 25 updates (ProtectedReseed.MAX_UPDATES) on
    twice the particles, the odds stuck at -2.9 nats."""
    pf, grid = _reseeded(TRUE_POSE)
    pf._search_concurs = lambda search, track: False  # the rule off
    obs = pf.prepare(_cast_scan(grid, TRUE_POSE), np.zeros(3))
    odds = []
    for _ in range(5):
        info = pf.step(None, obs)
        odds.append(pf.protected.odds)
        assert not info.confirmed and not info.switched and pf.n == 8000
        assert np.hypot(*(info.mean[:2] - TRUE_POSE[:2])) < 0.1
    assert max(odds) < 0.0 and min(odds) > -4.6, odds  # the track ahead, never by reseed_odds
    # the search's poses put on the track's (0.05 m, 0.02 rad std): gathered there; then half of them 2 m away (the
    # heaviest cluster under 90 % of the search's weight), and all of them 1 m away (two cluster cells): not
    pf, grid = _reseeded(TRUE_POSE)
    track = pf.protected.track
    search = ~track
    pf.particles[:, search] = pf.particles[:, track]
    pf.weights = np.full(pf.n, 1.0 / pf.n)

    def concurs():
        return pf._search_concurs(pf._side_estimate(search), pf._side_estimate(track))

    assert concurs()
    half = np.flatnonzero(search)[::2]
    pf.particles[:2, half] += np.array([[2.0], [0.0]])
    assert not concurs()
    pf.particles[:2, half] -= np.array([[2.0], [0.0]])
    pf.particles[0, search] += 1.0
    assert not concurs()


def test_a_protected_reseed_of_a_wrong_track_switches_to_the_search():
    # the candidates as drawn (search_refine_candidates false): the search's heaviest cluster, a blend after one
    # scan, fits 0.75, and the estimate stays on the track for that scan
    pf, grid = _reseeded([6.0, 3.0, -0.5], "filter.search_refine_candidates=false")  # 3 m off and turned
    obs = pf.prepare(_cast_scan(grid, TRUE_POSE), np.zeros(3))
    info = pf.step(None, obs)
    assert not info.switched and pf.protected.odds == 3.0 and np.hypot(*(info.mean[:2] - [6.0, 3.0])) < 0.1
    info = pf.step(None, obs)  # (still lost by the quality window, the place it found is re-seeded on probation)
    assert info.switched and not info.confirmed and info.particles == 4000 and pf.protected is None
    assert np.hypot(*(info.mean[:2] - TRUE_POSE[:2])) < 0.3
    # matched (the default), the search's place fits the scan as a tracked scan does (ProtectedReseed.DECISIVE_FIT)
    # and the track's as a lost one: the first scan decides
    pf, grid = _reseeded([6.0, 3.0, -0.5])
    info = pf.step(None, obs)
    assert info.switched and pf.protected is None and np.hypot(*(info.mean[:2] - TRUE_POSE[:2])) < 0.3


def test_while_neither_side_leads_the_estimate_stays_on_the_track_and_each_side_keeps_its_particles():
    pf, grid = _reseeded([6.0, 3.0, -0.5])
    for k in range(24):  # no scan: no evidence either way, the odds stay at 0
        info = pf.step(None, None)
        assert not info.confirmed and not info.switched, k
        assert pf.n == 8000 and pf.protected.track.sum() == 4000 and info.resampled
        assert np.hypot(*(info.mean[:2] - [6.0, 3.0])) < 0.1  # the track, though the search holds half the weight
        assert np.exp(pf.logw[pf.protected.track]).sum() == pytest.approx(0.5)
    info = pf.step(None, None)  # the 25th update: a tie goes to the track
    assert info.confirmed and pf.n == 4000


def test_with_kld_a_protected_search_shrinks_to_what_its_places_need_and_keeps_its_mass():
    # On the campus the search side kept its 100,000 fresh poses for every update of a protected re-seed, though a
    # scan or two gathers them on a few places. With KLD sampling it now draws what its occupied bins ask for: here
    # one exact scan puts the search's weight on one place, so it drops to min_particles, the track keeps its 4,000,
    # and each side keeps its mass (the odds after one scan, 3 nats: e^3 / (1 + e^3) on the search).
    # (the candidates as drawn: matched, the first scan decides, test_a_protected_reseed_of_a_wrong_track_...)
    pf, grid = _reseeded([6.0, 3.0, -0.5], "filter.kld=true", "filter.min_particles=500",
                         "filter.search_refine_candidates=false")
    obs = pf.prepare(_cast_scan(grid, TRUE_POSE), np.zeros(3))
    info = pf.step(None, obs)
    assert not info.switched and pf.protected.odds == 3.0
    assert pf.protected.track.sum() == 4000 and (~pf.protected.track).sum() == 500 and pf.n == 4500
    assert np.exp(pf.logw[~pf.protected.track]).sum() == pytest.approx(np.exp(3.0) / (1.0 + np.exp(3.0)))
    assert np.hypot(*(info.mean[:2] - [6.0, 3.0])) < 0.1  # the estimate still on the track
    info = pf.step(None, obs)
    assert info.switched and np.hypot(*(info.mean[:2] - TRUE_POSE[:2])) < 0.3


def _found_place(fit_score: float, *sets):
    """A filter at TRUE_POSE as if a global search had just found it (on probation), every scan laid on the map
    there fitting at ``fit_score`` (the quality signal stubbed: above quality.lost_below, so never lost)."""
    from mcl.quality import Fit

    grid = _room_with_a_wall()
    from mcl.config import load_config
    from mcl.filter import ParticleFilter

    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        "rerun.mode=off", "filter.particles=4000", "filter.kld=false", *sets])
    pf = ParticleFilter(cfg, grid, rng=np.random.default_rng(5))
    pf.init_gaussian(TRUE_POSE, [0.05, 0.05, 0.02])
    pf.search.start()  # a search ...
    pf.search.observe(False, 1.0)  # ... that has settled here
    assert pf.recovery.on_probation
    pf.quality.fit = lambda pose, endpoints, origin: Fit(beams=100, match=fit_score, contradiction=0.0)
    return pf, pf.prepare(_cast_scan(grid, TRUE_POSE), np.zeros(3))


def test_a_place_a_search_found_fitting_poorly_on_probation_is_challenged_once_by_a_protected_reseed():
    # large-03 seed 1 (synthetic, global): the search settled 98 m off at 1.6 s, and the place fitted the scans at
    # 0.65-0.82 for 15 s without being lost for recovery_global_after updates; held for 40 s. Ten scans in a row at
    # a median under probation_fit (0.7) now start a protected re-seed: the place keeps its cloud, and a place
    # found anew must out-score it by reseed_odds.
    pf, obs = _found_place(0.65)
    for k in range(9):
        info = pf.step(None, obs)
        assert not info.lost and not info.reseeded, k
    info = pf.step(None, obs)  # the tenth
    assert info.reseeded and pf.protected is not None and pf.protected.track.sum() == 4000
    assert pf.challenge.scores is None  # once: the place is not challenged again on this probation
    # a place fitting at 0.75, or the rule off (probation_fit 0): no challenge in 40 updates
    for score, sets in ((0.75, ()), (0.65, ("filter.probation_fit=0",)), (0.65, ("filter.reseed_odds=0",)),
                        (0.65, ("filter.recovery_reseed=false",))):
        pf, obs = _found_place(score, *sets)
        assert not any(pf.step(None, obs).reseeded for _ in range(40)), (score, sets)


def test_a_reseed_of_a_place_a_search_just_found_is_not_protected_nor_with_reseed_odds_0():
    pf, _ = _reseeded(TRUE_POSE, "filter.reseed_odds=0")
    assert pf.protected is None
    from mcl.filter import StepInfo

    pf, _ = _reseeded(TRUE_POSE)
    pf.protected = None
    pf.search.since_end = 3  # the search that found this place ended 3 updates ago: on probation
    pf.search.tempering = pf.search.holding = False
    assert pf.recovery.on_probation
    pf.recovery.observe_lost(True, dt=0.2)  # a 5 Hz log (filter.recovery_global_min_s)
    info = StepInfo(particles=pf.n, ess=float(pf.n))
    pf.resample(info)
    assert info.reseeded and pf.protected is None


def test_a_scan_counts_for_a_protected_reseed_only_if_its_quality_score_agrees_with_its_likelihood():
    # The gate: the likelihood field does not see readings through walls, so on the campus a place 176 m away won
    # the likelihood of scans it fitted at -0.23 (a third of the beams through walls) against the track's 0.02. Here
    # the scan favours the search (the track is 3 m off), but the quality score is made to favour the track: the
    # odds do not move, the estimate stays on the track, and after 25 updates the tie goes to the track.
    pf, grid = _reseeded([6.0, 3.0, -0.5])
    pf._side_fits = lambda search, track: (0.1, 0.9, 0.0, 0.0, 60)  # scores search, track; contradictions; returns
    obs = pf.prepare(_cast_scan(grid, TRUE_POSE), np.zeros(3))
    for k in range(24):
        info = pf.step(None, obs)
        assert not info.switched and pf.protected.odds == 0.0, k
        assert np.hypot(*(info.mean[:2] - [6.0, 3.0])) < 0.5, k
    assert pf.step(None, obs).confirmed
    # the same scans with the score agreeing (0.7 against 0.5, 5 % of the beams through walls at the track's 3 m
    # off): the odds move 3 nats a scan, the search wins on the second; and with the scan fitting the search's place
    # as a tracked scan does (0.9) and the track's as a lost one (below quality.lost_below 0.6), on the first (a
    # sparse log's next scan can be 17 s away)
    pf, grid = _reseeded([6.0, 3.0, -0.5])
    pf._side_fits = lambda search, track: (0.7, 0.5, 0.0, 0.05, 60)
    assert not pf.step(None, obs).switched and pf.protected.odds == 3.0 and pf.step(None, obs).switched
    pf, grid = _reseeded([6.0, 3.0, -0.5])
    pf._side_fits = lambda search, track: (0.9, 0.5, 0.0, 0.0, 60)
    assert pf.step(None, obs).switched


def test_two_seconds_of_ground_hits_do_not_hand_a_correct_track_to_spread_poses(tmp_path_factory, tmp_path):
    # A laser tilted onto the ground for 2 s (mcl simulate --ground-hits: a line of returns 1.5-5 m ahead, moving
    # every scan; the campus log of suites/heldout-real-gentle.yaml has such a stretch at 203-205 s). In an open
    # hall no pose fits those scans, so the filter is called lost and lost recovery spreads poses around the
    # estimate. Mixed into the set, spread poses where the line met a wall took the track (20.6 m off);
    # protected (filter.recovery_protect, the default), they must out-score the track on scans that fit the map where
    # they are, which these do not: 0.23 m (the baseline, with no recovery: 0.26 m). Since quality.occluded_missing
    # (thirty-eighth session) those scans are no lost call at all: the walls the map shows are there, the ground's
    # returns lie on open floor; the protection is measured with it off.
    from mcl.simulate import simulate

    data = tmp_path_factory.mktemp("ground")
    sim = simulate(data, kind="hall", seed=0, duration=45.0, ground_hits=1)
    s = _track(data, sim, tmp_path / "default")
    assert s["quality"]["lost_updates"] == 0 and s["eval"]["ate_max"] < 0.5, (s["quality"], s["eval"])
    p = _track(data, sim, tmp_path / "protected", "quality.occluded_missing=-1")
    assert p["quality"]["lost_updates"] > 0, p["quality"]  # the scans do make it lost: the protection is what held
    assert p["eval"]["ate_max"] < 0.5, p["eval"]
    mixed = _track(data, sim, tmp_path / "mixed", "quality.occluded_missing=-1", "filter.recovery_protect=false")
    assert mixed["eval"]["ate_max"] > 2.0, mixed["eval"]


def _tracking_protected(track):
    """A filter tracking ``track`` in the room with a wall (an estimate made), with lost recovery's spread
    protected (filter.recovery_protect)."""
    from mcl.config import load_config
    from mcl.filter import ParticleFilter, StepInfo

    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        "rerun.mode=off", "filter.particles=4000", "filter.kld=false", "filter.recovery=lost",
        "filter.recovery_protect=true"])
    pf = ParticleFilter(cfg, _room_with_a_wall(), rng=np.random.default_rng(5))
    pf.init_gaussian(track, [0.05, 0.05, 0.02])
    pf.estimate(StepInfo(particles=pf.n))
    return pf


def _spread_protected(track, scan_at):
    """``_tracking_protected``, lost on a refuting scan cast at ``scan_at`` and resampled: lost recovery's spread
    starts."""
    from mcl.filter import StepInfo

    pf = _tracking_protected(track)
    grid = pf.grid
    pf.recovery.observe_lost(True, refuted=True)
    info = StepInfo(particles=pf.n, ess=float(pf.n))
    pf.resample(info)
    obs = pf.prepare(_cast_scan(grid, scan_at), np.zeros(3))
    return pf, obs, info


def test_lost_recovery_spreads_as_a_protected_side_and_the_estimate_stays_on_the_track():
    # The spread is a second component of as many poses around the estimate, half the mass, resampled apart: no
    # global search, the lost count goes on, and the estimate is the track's while neither side leads
    track = np.array(TRUE_POSE)
    pf, obs, info = _spread_protected(track, scan_at=track)
    assert pf.protected is not None and pf.protected.local and not info.reseeded
    assert pf.n == 8000 and pf._injected.sum() == 4000 and not pf.search.tempering
    fresh = pf.particles[:, pf._injected]
    assert 0.3 < np.std(fresh[0]) < 0.7 and np.hypot(*(fresh[:2].mean(axis=1) - track[:2])) < 0.05  # std 0.5 m
    # the scans fit neither side as a tracked scan does: no evidence
    pf._side_fits = lambda search, track: (0.3, 0.3, 0.0, 0.0, 60)
    for k in range(5):
        info = pf.step(None, obs)
        assert pf.protected is not None and pf.protected.odds == 0.0, k
        assert np.hypot(*(info.mean[:2] - track[:2])) < 0.1, k
        assert pf.n == 8000 and pf.protected.track.sum() == 4000, k  # each side resampled within itself


def test_a_protected_spread_that_found_the_slipped_robot_takes_the_estimate_within_two_scans():
    # fr079 at 305 s: the track slipped 1-1.5 m and the spread finds the robot; the spread side fits the scan as a
    # track does, the track as a lost one: each scan moves the odds by ProtectedReseed.STEP (3 nats, no scan decides
    # a spread alone), so the second passes reseed_odds (4.6) and the estimate goes to the spread side, and stays
    truth = np.array(TRUE_POSE)
    pf, obs, _ = _spread_protected(truth + [0.8, 0.0, 0.0], scan_at=truth)
    assert pf.protected is not None and pf.protected.local
    errors = []
    for k in range(3):
        info = pf.step(None, obs)
        errors.append(float(np.hypot(*(info.mean[:2] - truth[:2]))))
        if k == 0:
            assert pf.protected.odds == 3.0  # one scan: capped, undecided
    assert errors[0] > 0.6 and max(errors[1:]) < 0.15, errors  # the track's estimate for one scan, then the robot's
    # the lost belief held through the update the spread won in, but its scan fits the new track: no new spread
    # started there (one would have sat on the same pose, no scan counting for either side, for 25 updates)
    assert pf.protected is None and pf.n == 4000


def test_no_spread_starts_on_a_scan_that_fits_the_track_while_the_lost_belief_holds():
    # After a spread won, the lost belief holds for a few updates while the new track fits. A spread started then
    # sat on the track's own pose, where no scan counts for either side (ProtectedReseed.weigh: a scan that fits
    # the track as tracked is no evidence for a spread), and doubled the set for nothing
    truth = np.array(TRUE_POSE)
    for scan_at, spreads in ((truth, False), (truth + [0.8, 0.0, 0.0], True)):
        pf = _tracking_protected(truth)
        pf.quality.reset(lost=True)  # lost, and lost recovery past its wait
        for _ in range(pf.cfg.filter.recovery_wait + 1):
            pf.recovery.observe_lost(True, dt=0.2)  # a 5 Hz log (filter.recovery_global_min_s)
        info = pf.step(None, pf.prepare(_cast_scan(pf.grid, scan_at), np.zeros(3)))
        assert pf.quality.lost and pf.recovery.spreading, scan_at  # the belief holds either way
        assert (pf.protected is not None) == spreads and pf.n == (8000 if spreads else 4000), scan_at
        assert (info.injected > 0) == spreads, scan_at


def test_a_global_reseed_due_during_a_protected_spread_keeps_the_leading_side_as_its_track():
    from mcl.filter import StepInfo

    track = np.array(TRUE_POSE)
    pf, obs, _ = _spread_protected(track, scan_at=track)
    pf.protected.odds = -1.0  # the track leads
    kept = pf.particles[:, ~pf._injected].copy()
    for _ in range(pf.cfg.filter.recovery_global_after):
        pf.recovery.observe_lost(True, dt=0.2)  # a 5 Hz log (filter.recovery_global_min_s)
    info = StepInfo(particles=pf.n, ess=float(pf.n))
    pf.resample(info)
    assert info.reseeded and pf.search.tempering and pf.protected is not None and not pf.protected.local
    old = pf.particles[:, pf.protected.track]
    assert old.shape[1] == 4000 and np.isin(old[0], kept[0]).all()  # the track side, resampled


def test_the_probation_challenge_judges_a_place_by_its_median_over_ten_scans():
    # filter.probation_fit: 10 updates in a row on probation at a median score under the bar -> one challenge (a
    # protected re-seed); over it, or fewer than 10 scores, none; once challenged, not again.
    from types import SimpleNamespace

    from mcl.adaptive import GlobalSearch, ProbationChallenge

    def run(scores):
        search = GlobalSearch()
        search.start()
        search.observe(False)  # the search settles: the place it found is on probation
        c = ProbationChallenge(0.7, search)
        dues = []
        for score in scores:
            c.observe(SimpleNamespace(beams=50, score=score), True)
            dues.append(c.due)
            c.due = False  # the filter takes the challenge (ParticleFilter.resample)
        return dues

    assert run([0.65] * 10)[-1] and not any(run([0.65] * 9))
    assert not any(run([0.75] * 20))
    # the median, not the mean: four scans at -1 among six at 0.9 leave the place unchallenged
    assert not any(run([0.9, -1.0] * 4 + [0.9, 0.9]))
    assert run([0.5] * 30) == [False] * 9 + [True] + [False] * 20  # at the 10th scan, and once only


def test_while_an_unprotected_reseeds_search_holds_the_pose_reported_is_the_old_estimate_moved_by_the_odometry():
    # freiburg-campus (suites/heldout-real.yaml) tracking seed 2, 202-205 s: a place on probation called lost
    # re-seeds at once and unprotected; until the search's estimate fits, its heaviest cluster is any of
    # 100,000-200,000 uniform poses (129-185 m off for nine scans while the kept track was within 0.2 m).
    # filter.reseed_hold_pose reports the estimate from before the re-seed, moved by the odometry, until the filter
    # is no longer lost; the filter's own estimate is untouched. Exact comparisons: the held pose is composed, the
    # cluster mean averaged.
    from mcl.estimate import compose
    from mcl.filter import Control

    step = np.array([0.3, 0.0, 0.1])
    # the same step every update: a first step after standing still would be an odometry jump (max_odom_ratio)
    move = Control(np.zeros(3), compose(np.zeros(3), step), dt=0.2)
    for hold in (True, False):
        pf, obs = _found_place(0.3, f"filter.reseed_hold_pose={str(hold).lower()}")  # every scan fits at 0.3: lost
        info = _until_reseeded(pf, obs, move)
        assert pf.protected is None and pf.search.holding  # on probation: unprotected
        before = np.array(info.mean)  # the estimate of the update that re-seeded (its resample came after it)
        before_cov = np.array(info.cov)
        # in this small room the kept cloud takes 90 % of the weight at once and the search settles; on a campus
        # 100,000 uniform poses do not: no cluster settles the search here either
        pf.search.settles = lambda weight, cov=None: False
        info = pf.step(move, obs)
        assert pf.search.holding  # the search has fitted nothing (every scan at 0.3)
        if hold:
            np.testing.assert_array_equal(info.mean, compose(before, step))
            assert not np.array_equal(info.mean, pf.last_estimate.mean)
            # reported with the covariance it had (the recording's ellipse, --write-bag), not the search's
            np.testing.assert_array_equal(info.cov, before_cov)
            assert not np.array_equal(info.cov, pf.last_estimate.cov)
        else:
            np.testing.assert_array_equal(info.mean, pf.last_estimate.mean)
            np.testing.assert_array_equal(info.cov, pf.last_estimate.cov)
    # once the filter is no longer lost (its estimate fits: holding ends in that update's assess), its own estimate
    # is reported
    pf, obs = _found_place(0.3)
    _until_reseeded(pf, obs, move)
    assert pf._held is not None
    pf.search.settles = lambda weight, cov=None: False
    from mcl.quality import Fit

    pf.quality.fit = lambda pose, endpoints, origin: Fit(beams=100, match=0.95, contradiction=0.0)
    for _ in range(10):  # the lost belief clears after quality.lost_after good scans or fewer
        info = pf.step(move, obs)
        if not pf.search.holding:
            break
    assert not pf.search.holding and pf._held is None
    np.testing.assert_array_equal(info.mean, pf.last_estimate.mean)


def _until_reseeded(pf, obs, control=None, most: int = 10):
    """Step ``pf`` (by ``control`` each update) until an update re-seeds (the lost call takes quality.lost_after
    updates)."""
    for _ in range(most):
        info = pf.step(control, obs)
        if info.reseeded:
            return info
    raise AssertionError(f"no re-seed in {most} updates")


def test_a_protected_reseed_holds_no_pose_of_its_own():
    pf, _ = _reseeded(TRUE_POSE)
    assert pf.protected is not None and pf._held is None  # the protected estimate stays on the track already


def test_a_global_reseed_due_while_the_spread_leads_waits_while_the_track_still_fits():
    # filter.reseed_wait_fit: the spread leads (3 nats, unsettled) when the global re-seed falls due. While the
    # track's last scan scores at least reseed_wait_fit the re-seed waits (the spread and the track go on, resampled
    # apart); once it scores below, or with the rule off, the re-seed comes at once and keeps the leading side
    from mcl.filter import StepInfo

    track = np.array(TRUE_POSE)
    for track_score, wait_fit, waits in ((0.4, 0.25, True), (0.1, 0.25, False), (0.4, 0.0, False)):
        pf, obs, _ = _spread_protected(track, scan_at=track)
        pf.cfg = replace(pf.cfg, filter=replace(pf.cfg.filter, reseed_wait_fit=wait_fit))
        p = pf.protected
        p.odds, p.updates, p.track_score = 3.0, 4, track_score  # the spread leads, not settled (reseed_odds 4.6)
        spread = pf.particles[:, pf._injected].copy()
        for _ in range(pf.cfg.filter.recovery_global_after):
            pf.recovery.observe_lost(True, dt=0.2)  # a 5 Hz log (filter.recovery_global_min_s)
        info = StepInfo(particles=pf.n, ess=float(pf.n))
        pf.resample(info)
        case = (track_score, wait_fit)
        assert info.reseeded != waits, case
        assert pf.protected is not None and pf.protected.local == waits, case
        if not waits:  # the re-seed kept the spread side as its track
            old = pf.particles[:, pf.protected.track]
            assert old.shape[1] == 4000 and np.isin(old[0], spread[0]).all(), case


def test_defers_reseed_only_for_a_spread_that_leads_unsettled_on_a_track_that_fits():
    from mcl.adaptive import ProtectedReseed

    p = ProtectedReseed(np.ones(4, dtype=bool), keep=0.5, reseed_odds=4.6, lost_below=0.6, local=True)
    assert not p.defers_reseed(0.25)  # no scan counted yet (the prior odds; no track score): a kidnap waits for nothing
    p.odds, p.track_score = 3.0, 0.3
    assert p.defers_reseed(0.25) and not p.defers_reseed(0.0)  # 0: off
    p.track_score = 0.2
    assert not p.defers_reseed(0.25)  # the track's scans no longer fit: a kidnapped track
    p.track_score, p.odds = 0.3, -1.0
    assert not p.defers_reseed(0.25)  # the track leads
    p.odds = 4.6
    assert not p.defers_reseed(0.25)  # settled for the spread
    g = ProtectedReseed(np.ones(4, dtype=bool), keep=0.5, reseed_odds=4.6, lost_below=0.6, local=False)
    g.odds, g.track_score = 3.0, 0.3
    assert not g.defers_reseed(0.25)  # a global search's contest is not lost recovery's spread


def test_a_global_reseed_waits_for_a_spread_that_leads_on_a_stale_map(tmp_path_factory, tmp_path):
    # suites/heldout14.yaml hall-stale-both-ways-h21: a hall whose map shows 8 boxes that are gone and lacks 6 that
    # stand there. At 40 s the true pose's scan reads through mapped boxes and ends short at unmapped ones; the
    # correct track (0.15 m) is called lost, and lost recovery's protected spread finds a pose 1.2 m off that lays
    # the readings on the stale map better: it leads by 3 nats, not settled, when the global re-seed falls due 1.8 s
    # later, with the track's scans at 0.31-0.57. Keeping the side that leads at once, the re-seed took that pose
    # (1.68 m off); waiting (filter.reseed_wait_fit 0.25, the default), the scans settle it for the track (0.26 m).
    # The baseline, with no recovery, keeps 0.33-0.37 m
    from mcl.simulate import simulate

    data = tmp_path_factory.mktemp("stale")
    sim = simulate(data, kind="hall", seed=2010, duration=90.0, phantom_furniture=8, unmapped_furniture=6)
    s = _track(data, sim, tmp_path / "default")
    assert s["quality"]["lost_updates"] > 0, s["quality"]  # the false lost call the rule is about
    assert s["eval"]["ate_max"] < 0.5, s["eval"]
    kept = _track(data, sim, tmp_path / "kept", "filter.reseed_wait_fit=0")
    assert kept["eval"]["ate_max"] > 0.6, kept["eval"]


def test_a_fast_lasers_lost_updates_re_seed_only_once_they_span_the_floor():
    # filter.recovery_global_min_s: recovery_global_after (10) lost updates re-seed only once they span this much log
    # time, as ten do at 5 Hz (1.8 s). At 15 Hz ten are 0.67 s: a correct track lost while its laser saw the ground for
    # 2 s was re-seeded inside them onto a look-alike 28 m away (a generated building under an 8 m laser, seeds 2-3).
    from mcl.adaptive import GlobalSearch, LostRecovery

    def due_after(n, dt, floor):
        r = LostRecovery(0.1, (0.5, 0.5, 0.3), global_after=10, lost_after=3, reseed=True, search=GlobalSearch(),
                         global_after_s=3.0, global_min_s=floor)
        for _ in range(n):
            r.observe_lost(True, 1.0, dt)
        return r.reseed_due

    assert not due_after(9, 0.2, 1.8) and due_after(10, 0.2, 1.8)  # 5 Hz: ten updates, as without the floor
    assert due_after(10, 1 / 15, 0.0)  # 15 Hz without the floor: 0.6 s in
    assert not due_after(10, 1 / 15, 1.8) and not due_after(27, 1 / 15, 1.8)  # 0.6 s, 1.73 s
    assert due_after(28, 1 / 15, 1.8)  # 1.8 s
    assert due_after(4, 1.0, 1.8)  # a sparse log: recovery_global_after_s (3 s) first, as before


def test_without_kld_sampling_a_global_search_keeps_a_fixed_n_after_its_reseed(tmp_path):
    # A global re-seed doubles the set (the kept cloud and as many fresh poses); KLD sampling draws it back, and
    # without it nothing did: a global run with filter.particles 2000 and kld off kept 4,000 for 38 of its 40
    # updates. Now the next resample draws it back to filter.particles; the run still localizes.
    import collections

    from mcl.config import load_config
    from mcl.runner import run
    from mcl.simulate import simulate

    data = tmp_path / "w"
    simulate(data, seed=3, duration=8.0)
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={data / 'map.yaml'}", f"log={data / 'log.clf'}", f"truth={data / 'truth.tum'}", "rerun.mode=off",
        "filter.global_localization=true", "filter.particles=2000", "filter.kld=false", "seed=1"])
    summary = run(cfg, tmp_path / "r", progress=False, echo=lambda m: None)
    rows = (tmp_path / "r" / "quality.csv").read_text().splitlines()[1:]
    counts = collections.Counter(int(r.split(",")[6]) for r in rows if r.split(",")[1] == "1")
    assert summary["reseeds"] >= 1  # the set was doubled once at least
    assert set(counts) <= {2000, 4000} and counts[4000] <= 3, counts  # the doubled set for the re-seed's updates
    assert summary["eval"]["ate_max"] < 0.3


def test_a_crowd_closing_round_a_correct_track_does_not_hand_it_to_a_spread_at_once(tmp_path):
    # Hunt world w4347 (ninety-third session): an office, 24 people, a fifth of the readings no return, a 10 cm map.
    # At 87.4-89.6 s the crowd takes the true pose's match from 0.70 to 0.29, nothing through walls; lost, and the
    # low match refuted the estimate: the spread started at once, and at 89.8 s a pose 1.1 m off that the crowd
    # fitted at 0.60 took it (max 1.12 m; the baseline 0.22 m). The episode began on a crept fit, so the match alone
    # no longer refutes: 0.16 m. The bound is the suite's lost_m.
    from mcl.config import load_config
    from mcl.runner import run
    from mcl.simulate import simulate

    data = tmp_path / "w"
    sim = simulate(data, kind="office", seed=4347, duration=90.0, dynamic_obstacles=24, p_max=0.2,
                   map_resolution=0.1)
    x, y, th = sim["start_pose"]
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={data / 'map.yaml'}", f"log={data / 'log.clf'}", f"truth={data / 'truth.tum'}", "rerun.mode=off",
        "filter.global_localization=false", f"filter.initial_pose=[{x}, {y}, {th}]", "seed=1"])
    summary = run(cfg, tmp_path / "r", progress=False, echo=lambda m: None)
    assert summary["eval"]["ate_max"] < 0.5, summary["eval"]


def test_a_floor_plan_with_its_outside_painted_black_is_searched_by_the_depth_of_the_black(tmp_path):
    # CAD and floor-plan maps paint everything outside the building occupied. AMCL's field (search_interior zero)
    # scores a return anywhere inside that black as a perfect hit, so a search settled where the scan fell into it:
    # the demo's map with its unknown grey painted black, the demo's log searched from the start (no start pose: a
    # new map and log) and kidnapped at 50 s, was 4-9 m off from 55 to 70 s on every seed, against 0.04 m on the map
    # as drawn. sensor.likelihood_field.search_solid scores such regions by their depth while searching: 0.04 m on
    # seeds 1-4. Bound: 0.3 m after 55 s (the kidnap is at 50 s; the demo's bound for "back").
    from PIL import Image

    from mcl.cli import main
    from mcl.trajectory import read_tum

    demo = PROJECT_ROOT / "data" / "demo"
    pixels = np.asarray(Image.open(demo / "map.pgm")).copy()
    pixels[pixels == 205] = 0
    Image.fromarray(pixels).save(tmp_path / "black.pgm")
    (tmp_path / "black.yaml").write_text((demo / "map.yaml").read_text().replace("map.pgm", "black.pgm"))
    t_ref, ref = read_tum(demo / "truth.tum")
    for seed, solid in ((1, 1.5), (2, 1.5), (1, 0.0)):
        out = tmp_path / f"s{seed}-{solid}"
        assert main(["run", "--map", str(tmp_path / "black.yaml"), "--log", str(demo / "log.clf"), "--particles",
                     "2000", "--seed", str(seed), "--rerun", "off", "--no-progress", "--out", str(out),
                     "--set", f"sensor.likelihood_field.search_solid={solid}"]) == 0
        t, est = read_tum(out / "trajectory.tum")
        late = t >= 55.0
        err = np.hypot(est[0, late] - np.interp(t[late], t_ref, ref[0]), est[1, late] - np.interp(t[late], t_ref, ref[1]))
        assert late.sum() > 50
        assert (err.max() <= 0.3) == (solid > 0.0), (seed, solid, err.max())
