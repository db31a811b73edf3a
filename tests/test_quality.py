"""The localization-quality signal (mcl.quality): scan-to-map fit and the lost belief."""

from __future__ import annotations

import csv
import math
from types import SimpleNamespace

import numpy as np
import pytest

from mcl.config import PROJECT_ROOT, load_config
from mcl.quality import Fit, ScanQuality, endpoint_distances


def _box_grid(size=10.0, res=0.05):
    """A closed 10 m x 10 m room (walls one cell thick) with its distance field."""
    from scipy.ndimage import distance_transform_edt

    n = int(round(size / res))
    occ = np.zeros((n, n), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    dist = distance_transform_edt(~occ) * res
    return SimpleNamespace(distance=dist, occupied=occ, origin=(0.0, 0.0), resolution=res)


def _scan_from(pose, grid, n=90):
    """Exact robot-frame endpoints (2, n) of a 360-degree scan from ``pose`` in the box room."""
    x, y, th = pose
    a = np.linspace(-np.pi, np.pi, n, endpoint=False)
    wx, wy = np.cos(a + th), np.sin(a + th)
    lo, hi = 0.05 + 1e-3, 10.0 - 0.05 - 1e-3  # inner faces of the walls
    with np.errstate(divide="ignore"):
        tx = np.where(wx > 0, (hi - x) / wx, (lo - x) / wx)
        ty = np.where(wy > 0, (hi - y) / wy, (lo - y) / wy)
    r = np.minimum(np.abs(tx), np.abs(ty))
    return np.vstack([r * np.cos(a), r * np.sin(a)])


T0 = 0.0  # the simulator's logs start at t = 0 (sim.yaml times are from there)
QCFG = SimpleNamespace(distance=0.3, lost_below=0.6, lost_after=3, min_beams=5, doubt_margin=0.0, doubt_updates=50,
                       contradiction_above=0.0, lost_at_once_below=-2.0, occluded_below=1.0, occluded_missing=-1.0,
                       occluded_open=1.0, occluded_depth=0.0, occluded_prior=2.0, collapse_from=2.0, narrow_view="same",
                       held_min_beams=0, held_pool_beams=0, held_again=0)


def test_fit_is_high_at_the_true_pose_and_low_away_from_it():
    g = _box_grid()
    q = ScanQuality(g, QCFG)
    truth = (3.0, 4.0, 0.3)
    e = _scan_from(truth, g)
    at = q.fit(truth, e)
    assert at.beams == 90 and at.match == pytest.approx(1.0) and at.contradiction == 0.0
    # 1.5 m off along x: the beams towards +x end beyond the east wall (through it), the rest short of walls.
    off = q.fit((4.5, 4.0, 0.3), e)
    assert off.match < 0.5 and off.contradiction > 0.1 and off.score < QCFG.lost_below
    assert q.bad(off) and not q.bad(at)


def test_no_beam_is_no_evidence():
    q = ScanQuality(_box_grid(), QCFG)
    f = q.fit((3.0, 3.0, 0.0), np.zeros((2, 0)))
    assert f.beams == 0 and np.isnan(f.match)
    q.update(Fit(10, 0.0, 1.0))
    q.update(Fit(10, 0.0, 1.0))
    assert not q.lost
    assert q.update(f) is False  # does not count as bad
    assert q.update(Fit(10, 0.0, 1.0)) is True


def test_since_lost_counts_every_update_after_the_last_lost_one_and_none_before_any():
    # sensor.unmapped_skip waits this many updates after a lost call; a track from a known pose has none (None)
    q = ScanQuality(_box_grid(), QCFG)
    good, bad = Fit(60, 0.95, 0.0), Fit(60, 0.2, 0.3)
    q.reset(lost=False)
    for _ in range(4):
        q.update(good)
    assert q.since_lost is None
    for f in (bad, bad, bad):
        q.update(f)
    assert q.lost and q.since_lost == 0
    seen = []
    for f in (good, good, good, None, good, good, None):  # an update without evidence still counts as one
        q.update(f)
        seen.append(q.since_lost)
    # lost until at most 1 of the last 5 fits is bad (the fourth good), then counting, the no-evidence update too
    assert seen == [0, 0, 0, 0, 1, 2, 3]
    q.reset(lost=True)  # a global start is a lost call
    assert q.since_lost == 0


def test_endpoint_distances_read_the_field_seen_from_the_pose_and_nan_off_the_map():
    g = _box_grid()
    d = np.ascontiguousarray(g.distance, dtype=np.float32)
    e = np.array([[1.0, 0.0, 20.0], [0.0, 2.0, 0.0]])  # robot frame
    out = endpoint_distances(d, g.origin, g.resolution, (3.0, 4.0, np.pi / 2), e)
    assert out.dtype == np.float32
    # turned by 90 degrees: (1, 0) lands at (3, 5), (0, 2) at (1, 4), (20, 0) at (3, 24), off the map
    assert out[0] == d[100, 60] and out[1] == d[80, 20] and np.isnan(out[2])


def test_lost_belief_needs_three_bad_of_five_and_clears_at_one_of_five():
    q = ScanQuality(_box_grid(), QCFG)
    good, bad = Fit(60, 0.95, 0.0), Fit(60, 0.2, 0.3)
    seq = [good, bad, good, bad, good]  # 2 bad of 5: not lost
    assert [q.update(f) for f in seq] == [False] * 5
    assert q.update(bad) is True  # bad, good, bad, good, bad: 3 of 5
    assert q.update(good) is True  # good, bad, good, bad, good: still 2 bad
    assert q.update(good) is True  # bad, good, bad, good, good: 2
    assert q.update(good) is False  # good, bad, good, good, good: 1 of 5 -> no longer lost


def test_a_scan_far_below_any_correct_track_calls_lost_at_once():
    # quality.lost_at_once_below: one update whose score is below it is enough (a kidnapped robot's first scan
    # scores -0.9 to 0.3 in most synthetic worlds; correct tracks never fell below 0.3 in the synthetic suite nor
    # below 0.5 on the real logs), where 3 bad of 5 take 7-10 s on a log with a scan every 2.5-3.5 s.
    at_once = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(QCFG), "lost_at_once_below": 0.0}))
    plain = ScanQuality(_box_grid(), QCFG)
    good, awful, poor = Fit(60, 0.95, 0.0), Fit(60, 0.3, 0.4), Fit(60, 0.3, 0.1)  # scores 0.95, -0.5, 0.1
    assert _feed(at_once, [good] * 5 + [awful]) == [False] * 5 + [True]
    assert _feed(plain, [good] * 5 + [awful]) == [False] * 6
    # a bad update above the threshold still needs 3 of 5
    q = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(QCFG), "lost_at_once_below": 0.0}))
    assert _feed(q, [good] * 5 + [poor, poor, poor]) == [False] * 7 + [True]
    # one awful scan in a good track is lost for that update only (1 bad of 5 clears it); a second keeps it lost
    q = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(QCFG), "lost_at_once_below": 0.0}))
    assert _feed(q, [good] * 5 + [awful, good, good]) == [False] * 5 + [True, False, False]
    q = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(QCFG), "lost_at_once_below": 0.0}))
    assert _feed(q, [good] * 5 + [awful, poor, good]) == [False] * 5 + [True, True, True]


def _collapses(q, fits):
    """ScanQuality.collapsed after each of ``fits``."""
    out = []
    for f in fits:
        q.update(f)
        out.append(q.collapsed)
    return out


def test_a_held_track_lost_at_once_is_a_collapse_and_a_track_that_sank_first_is_not():
    # quality.collapse_from: a lost call at once (lost_at_once_below) on a track whose last 5 scores were all at least
    # 0.8 is a collapse, a kidnap's signature; lost recovery then re-seeds globally at once (test_recovery.py).
    cfg = SimpleNamespace(**{**vars(QCFG), "lost_at_once_below": 0.0, "collapse_from": 0.8})
    good, fair, awful, poor = Fit(60, 0.95, 0.0), Fit(60, 0.75, 0.0), Fit(60, 0.3, 0.4), Fit(60, 0.3, 0.1)
    assert _collapses(ScanQuality(_box_grid(), cfg), [good] * 5 + [awful, awful]) == [False] * 5 + [True, False]
    # one score of the five under 0.8: the fit had sunk before (people, clutter), no collapse, though lost at once
    q = ScanQuality(_box_grid(), cfg)
    assert _collapses(q, [good, good, fair, good, good, awful]) == [False] * 6 and q.lost
    # fewer than five scores since the reset: no held track yet
    assert _collapses(ScanQuality(_box_grid(), cfg), [good] * 4 + [awful]) == [False] * 5
    # lost by 3 bad of 5, not at once: no collapse
    q = ScanQuality(_box_grid(), cfg)
    assert _collapses(q, [good] * 5 + [poor] * 3) == [False] * 8 and q.lost
    # collapse_from above 1: never
    off = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(cfg), "collapse_from": 2.0}))
    assert _collapses(off, [good] * 5 + [awful]) == [False] * 6 and off.lost


@pytest.fixture(scope="module")
def kidnapped_world(tmp_path_factory):
    from mcl.simulate import simulate

    out = tmp_path_factory.mktemp("kidnap")
    sim = simulate(out, seed=3, duration=40.0, kidnap_at=20.0)
    return out, sim


def _run(data, sim, out, *sets):
    from mcl.runner import run

    x, y, th = sim["start_pose"]
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={data / 'map.yaml'}", f"log={data / 'log.clf'}", f"truth={data / 'truth.tum'}", "rerun.mode=off",
        "filter.global_localization=false", f"filter.initial_pose=[{x}, {y}, {th}]", "filter.particles=3000", *sets])
    s = run(cfg, out, progress=False, echo=lambda m: None)
    with open(out / "quality.csv") as f:
        rows = [r for r in csv.DictReader(f)]
    return s, rows


def test_quality_drops_and_says_lost_when_the_robot_is_kidnapped(kidnapped_world, tmp_path):
    # Recovery and the odometry-fault mixture off, so the filter stays where it was while the robot is
    # elsewhere (the mixture's window opens at the lost call and would let it follow): the signal must
    # say so within a second of the jump (3 bad updates of 5 at 5 Hz), and never before it.
    data, sim = kidnapped_world
    t_jump = sim["kidnap"]["t"]
    s, rows = _run(data, sim, tmp_path / "off", "filter.recovery=false", "motion.fault_prob=0")
    rel = np.array([float(r["t"]) for r in rows]) - T0
    match = np.array([float(r["match"]) if r["match"] not in ("", "nan") else np.nan for r in rows])
    lost = np.array([int(r["lost"]) for r in rows])
    before, after = rel < t_jump - 0.01, (rel >= t_jump + 0.01) & (rel < t_jump + 10.0)
    assert lost[before].sum() == 0
    assert np.nanmean(match[before]) > 0.85
    first_lost = rel[(lost == 1) & (rel >= t_jump - 0.01)]
    assert first_lost.size and first_lost[0] - t_jump < 1.5, first_lost[:3]
    assert np.nanmedian(match[after]) < 0.5
    assert s["quality"]["lost_updates"] > 0


def test_a_fit_of_fewer_than_min_beams_returns_is_no_evidence():
    # An open hall: two returns off a pillar match wherever the pillar is; they must not make the filter lost.
    q = ScanQuality(_box_grid(), QCFG)
    few = Fit(QCFG.min_beams - 1, 0.0, 1.0)
    assert not q.bad(few)
    assert [q.update(few) for _ in range(6)] == [False] * 6
    assert q.bad(Fit(QCFG.min_beams, 0.0, 1.0))


def test_a_held_track_is_judged_only_on_scans_with_held_min_beams_returns():
    # quality.held_min_beams: a hall under a 12 m laser returns 3-14 of 60 scored beams, people and unmapped boxes
    # among them; such scans called correct tracks lost and the re-seeds settled 14-45 m away (suites/heldout15.yaml).
    # A track from a known pose is judged only on scans with 15 returns or more until it is first lost; then 5
    # suffice, so the same sparse scans that it ignored call it lost; and a search's place is judged on 5 from the
    # start
    sparse, full, good = Fit(10, 0.0, 1.0), Fit(15, 0.0, 1.0), Fit(10, 1.0, 0.0)
    q0 = ScanQuality(_box_grid(), QCFG)  # held_min_beams 0: min_beams (5) alone
    assert _feed(q0, [sparse] * 3) == [False, False, True]
    q = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(QCFG), "held_min_beams": 15}))
    assert _feed(q, [sparse] * 6) == [False] * 6  # held: no evidence
    assert _feed(q, [full] * 3) == [False, False, True]
    assert _feed(q, [good] * 4) == [True, True, True, False]  # lost: 10 returns count (the window clears)
    assert _feed(q, [sparse] * 3) == [False, False, True]  # lost once: sparse scans call it lost
    assert _feed(q, [good] * 60 + [sparse] * 3)[-3:] == [False, False, True]  # however long it held since
    g = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(QCFG), "held_min_beams": 15}))
    g.reset(lost=True)  # a global start: the place a search finds is judged on min_beams
    assert _feed(g, [good] * 60 + [sparse] * 3)[-3:] == [False, False, True]
    # the bar is at most a quarter of the beams scored (sensor.max_beams): 40 scored, 10 returns count on a held track
    q40 = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(QCFG), "held_min_beams": 15}), scored_beams=40)
    assert _feed(q40, [sparse] * 3) == [False, False, True]


def _feed(q, fits):
    return [q.update(f) for f in fits]


def test_a_track_from_a_known_pose_is_held_again_after_held_again_updates_without_a_lost_call():
    # quality.held_again: a hall under a 360-degree 12 m lidar, 20 pieces of furniture the map lacks: a lost episode
    # at 38 s (the track 0.4-0.5 m off, the baseline as far) took the held bar for good, and at 64 s scans of 7
    # returns, 3 of them on furniture near the walls, called the correct track lost; the re-seed settled 27 m away
    # (max 37.9 m; the baseline 0.63 m). Held again after 100 updates without a lost call, such scans are no
    # evidence once more (0.196 m). Not within them; never for a place a global search found; 0: never.
    sparse, full, good = Fit(10, 0.0, 1.0), Fit(15, 0.0, 1.0), Fit(15, 1.0, 0.0)
    cfg = SimpleNamespace(**{**vars(QCFG), "held_min_beams": 15, "held_again": 100})

    def lost_once(q):
        assert _feed(q, [full] * 3 + [good] * 4) == [False, False, True, True, True, True, False]
        return q

    assert _feed(lost_once(ScanQuality(_box_grid(), cfg)), [good] * 99 + [sparse] * 6)[-6:] == [False] * 6
    assert _feed(lost_once(ScanQuality(_box_grid(), cfg)), [good] * 50 + [sparse] * 3)[-3:] == [False, False, True]
    never = SimpleNamespace(**{**vars(cfg), "held_again": 0})
    assert _feed(lost_once(ScanQuality(_box_grid(), never)), [good] * 200 + [sparse] * 3)[-3:] == [False, False, True]
    g = ScanQuality(_box_grid(), cfg)
    g.reset(lost=True)  # a global start: the place a search finds is never held
    assert _feed(g, [good] * 200 + [sparse] * 3)[-3:] == [False, False, True]


def test_a_held_tracks_sparse_scans_count_together_once_they_hold_held_pool_beams_returns():
    # quality.held_pool_beams: a robot kidnapped in a hall under a 12 m laser read 2-11 returns a scan, none near the
    # map at the estimate; with scans under held_min_beams ignored the track was not called lost for 66 s
    # (suites/heldout16.yaml hall-yaw-drift-long). Pooled, 6 scans of 10 returns are one fit of 60: three such
    # fits (18 scans) call it lost, where held_pool_beams 0 never does; scans under min_beams stay no evidence
    cfg = SimpleNamespace(**{**vars(QCFG), "held_min_beams": 15, "held_pool_beams": 60})
    sparse, tiny, full_good = Fit(10, 0.0, 0.0), Fit(4, 0.0, 0.0), Fit(40, 1.0, 0.0)
    q = ScanQuality(_box_grid(), cfg)
    lost = _feed(q, [sparse] * 18)
    assert lost == [False] * 17 + [True]
    assert q.since_lost == 0  # a lost call: from here min_beams (5) holds and nothing is pooled
    off = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(cfg), "held_pool_beams": 0}))
    assert _feed(off, [sparse] * 60) == [False] * 60
    assert _feed(ScanQuality(_box_grid(), cfg), [tiny] * 60) == [False] * 60
    # the pooled fit weighs each scan by its returns: 5 returns at 0 and 55 at 1.0 match 0.92, a good fit
    mixed = ScanQuality(_box_grid(), cfg)
    assert _feed(mixed, ([Fit(5, 0.0, 0.0)] + [Fit(11, 1.0, 0.0)] * 5) * 10) == [False] * 60
    # a scan of held_min_beams returns or more is newer evidence: it empties the pool, so a bad pool never completes
    q2 = ScanQuality(_box_grid(), cfg)
    assert _feed(q2, ([sparse] * 5 + [full_good]) * 10) == [False] * 60
    assert q2._pool == []
    # the pooled fit sums the view's counts: 5 scans, each showing 4 of 20 directions with nothing missing, are a
    # sparse view that explains a low match (occluded_missing), where 60 returns with no view measured would not
    view = SimpleNamespace(**{**vars(cfg), "occluded_missing": 0.2, "occluded_below": 0.4})
    people = Fit(12, 0.2, 0.0, predicted=4, missing=0, directions=20)
    assert _feed(ScanQuality(_box_grid(), view), [people] * 30) == [False] * 30
    assert _feed(ScanQuality(_box_grid(), view), [Fit(12, 0.2, 0.0)] * 15)[-1] is True


def test_after_a_lost_episode_a_place_that_fits_worse_than_the_track_did_stays_lost_for_a_while():
    # A kidnapped robot: the track held at 0.98, three bad updates, then the recovery finds a place that fits at 0.7,
    # above lost_below (0.6) but 0.28 below the track's 0.98. With doubt_margin 0.25 it is still bad for
    # doubt_updates (20 here) updates from the episode's start, so the recovery goes on (and re-seeds); after that
    # the plain test rules again. Without the margin the belief clears after lost_after good-enough updates.
    cfg = SimpleNamespace(**{**vars(QCFG), "doubt_margin": 0.25, "doubt_updates": 20})
    held, bad, worse = Fit(60, 0.98, 0.0), Fit(60, 0.3, 0.2), Fit(60, 0.7, 0.0)
    q = ScanQuality(_box_grid(), cfg)
    q.reset(lost=False)
    assert _feed(q, [held] * 40 + [bad] * 2) == [False] * 42
    assert q.update(bad)  # the lost call: the episode starts here
    lost = _feed(q, [worse] * 30)
    assert lost[:19] == [True] * 19  # 19 more updates in doubt: 0.7 < 0.98 - 0.25
    assert lost[-5:] == [False] * 5  # doubt over: 0.7 >= lost_below, the belief clears within 2 lost_after - 1
    off = ScanQuality(_box_grid(), QCFG)  # doubt_margin 0
    off.reset(lost=False)
    _feed(off, [held] * 40 + [bad] * 3)
    assert _feed(off, [worse] * 5)[-1] is False
    def after_episode(track: Fit, n_track: int, then: Fit) -> bool:
        """The belief after n_track updates of ``track``, a lost episode (3 bad) and 5 updates of ``then``."""
        qq = ScanQuality(_box_grid(), cfg)
        qq.reset(lost=False)
        _feed(qq, [track] * n_track + [bad] * 3)
        return _feed(qq, [then] * 5)[-1]

    # the place the recovery found fits as well as the track did (0.8 >= 0.98 - 0.25): no doubt
    assert after_episode(held, 40, Fit(60, 0.8, 0.0)) is False
    # a track that always fitted at 0.7 (a cluttered place) is not doubted at 0.7 after an episode
    assert after_episode(worse, 40, worse) is False
    # too short a history before the episode (fewer than DOUBT_HISTORY // 2 held updates): no reference, no doubt
    assert after_episode(held, 10, worse) is False
    assert after_episode(held, 40, worse) is True  # (the same with enough history: doubted)
    # reset forgets the track
    q.reset(lost=False)
    _feed(q, [bad] * 3)
    assert _feed(q, [worse] * 5)[-1] is False


def test_a_scan_that_goes_through_mapped_walls_is_bad_even_when_the_rest_fits():
    # A look-alike place a search settled on (suites/synthetic.yaml large-02, large-05, rooms-03): 10-15 % of the
    # beams go through walls the map has there while the rest match, so the score (match - 2 contradiction) stays
    # at 0.7-0.8, above lost_below. Correct tracks: contradiction at most 0.083 in 61,049 synthetic updates and
    # 0.127 on the real logs (belgioioso, 0.4 % of its updates at 0.1 or more: one bad update is not lost).
    through = Fit(60, 0.98, 0.12)  # score 0.74
    assert through.score > QCFG.lost_below
    on = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(QCFG), "contradiction_above": 0.1}))
    off = ScanQuality(_box_grid(), QCFG)
    assert on.bad(through) and not off.bad(through)
    assert not on.bad(Fit(60, 0.95, 0.083))  # the most a correct synthetic track showed
    assert _feed(on, [through] * 3)[-1] is True and _feed(off, [through] * 3)[-1] is False
    # one such scan among good ones (belgioioso) is not lost
    q = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(QCFG), "contradiction_above": 0.1}))
    good = Fit(60, 0.97, 0.0)
    assert not any(_feed(q, [good] * 5 + [through] + [good] * 5))


def test_a_scan_short_of_the_map_but_through_no_wall_is_bad_only_below_occluded_below():
    # People crowding the robot (suites/heldout.yaml hall-h2, the synthetic suite's hall-04): the readings end on
    # them, in front of the mapped walls, and match falls to 0.4-0.55 at the true pose with no beam through a wall.
    # Over the synthetic and held-out suites' updates scoring under 0.6, 319 of the 358 at a correct estimate
    # (error < 0.3 m) had no beam through a wall, and 306 of those a match of 0.4 or more; of the 3,633 at a wrong
    # place (> 1 m off), 97 had both.
    cfg = SimpleNamespace(**{**vars(QCFG), "occluded_below": 0.4})
    on, off = ScanQuality(_box_grid(), cfg), ScanQuality(_box_grid(), QCFG)
    crowded = Fit(60, 0.5, 0.0)
    assert on.bad(crowded) is False and off.bad(crowded) is True
    assert on.bad(Fit(60, 0.41, 0.0)) is False and on.bad(Fit(60, 0.39, 0.0)) is True  # below 0.4: lost all the same
    # one beam through a wall and the scan is no occlusion: lost_below holds (suites/synthetic.yaml hall-05: a
    # search's wrong place in an open hall, match 0.55-0.6 with one of 36 beams through a wall, 50 m off)
    assert on.bad(Fit(36, 0.58, 1 / 36)) is True and on.bad(Fit(60, 0.55, 1 / 60)) is True
    assert on.bad(Fit(60, 0.7, 0.0)) is False  # above lost_below: good either way
    good = Fit(60, 0.95, 0.0)
    assert _feed(on, [good] * 5 + [crowded] * 10) == [False] * 15
    assert _feed(off, [good] * 5 + [crowded] * 3)[-1] is True


@pytest.mark.parametrize("fov_deg, beams, share", [
    (59.0, 640, 59.0 / 180.0 * 640 / 639),  # each beam covers one increment: 59.09 degrees
    (90.0, 640, 90.0 / 180.0 * 640 / 639),
    (179.0, 180, 1.0),  # aces, intel_lab, infinite_corridor: 180 beams 1 degree apart see 180 degrees, not 179
    (179.5, 360, 1.0),  # fr079, fr101
    (180.0, 181, 1.0), (270.0, 1081, 1.0), (360.0, 720, 1.0)])
def test_a_narrow_view_scales_the_occlusion_thresholds_by_its_field_of_view(fov_deg, beams, share):
    # quality.narrow_view: scaled (the default). A person a metre away fills a third of a depth camera's 59-degree
    # view: people crowding it left a correct track at match 0.29-0.43 with no beam through a wall
    # (suites/depth-laser.yaml clutter-kinect), which a 180-degree laser's 0.4 would call bad and 0.45 refute.
    # Scaled, the thresholds are 0.4 and 0.45 times 59 / 180 (0.131 and 0.148); 180 degrees and wider as given.
    cfg = SimpleNamespace(**{**vars(QCFG), "occluded_below": 0.4, "occlusion_match": 0.45, "narrow_view": "scaled"})
    q = ScanQuality(_box_grid(), cfg)
    q.view(np.linspace(-np.radians(fov_deg) / 2, np.radians(fov_deg) / 2, beams))
    assert q.view_share == pytest.approx(share)
    assert share < 1.0 or q.view_share == 1.0  # exactly: a wide laser's thresholds as given
    assert q.occluded_below == pytest.approx(0.4 * share) and q.occlusion_match == pytest.approx(0.45 * share)
    crowded = Fit(60, 0.35, 0.0)  # no beam through a wall: occlusion
    assert q.bad(crowded) is (share == 1.0) and q.refutes(crowded) is (share == 1.0)
    # a wrong place's scan, beams through walls, is bad and refutes at any width (lost_below, contradiction_above
    # are not scaled); nor a scan matching under the scaled share
    wrong = Fit(60, 0.35, 0.05)
    assert q.bad(wrong) is True
    assert q.bad(Fit(60, 0.1, 0.0)) is True and q.refutes(Fit(60, 0.1, 0.0)) is True
    same = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(cfg), "narrow_view": "same"}))
    same.view(np.linspace(-np.radians(fov_deg) / 2, np.radians(fov_deg) / 2, beams))
    assert same.view_share == 1.0 and same.bad(crowded) is True and same.refutes(crowded) is True


def test_near_misses_through_a_wall_count_as_occlusion_with_occluded_depth():
    # clutter-03 driven at 1.5 m/s (mcl eval --world speed=1.5): people hide half the walls for 5 s and pull the
    # estimate 0.2-0.3 m off; 2-8 % of its beams then end 0.35-0.55 m past a wall. With no such near miss exempt the
    # scans were bad (score 0.33-0.45 < lost_below), the track was called lost and a re-seed took a place 13 m away
    # on every seed (seeds 1-5); the baseline kept it. A beam through a wall that ends farther than occluded_depth
    # from every wall (a wrong place) still counts as before.
    from scipy.ndimage import distance_transform_edt

    box = _box_grid()
    occ = np.pad(box.occupied, 40)  # 2 m of free map round the room: endpoints past a wall stay on the map
    g = SimpleNamespace(distance=distance_transform_edt(~occ) * box.resolution, occupied=occ, origin=(-2.0, -2.0),
                        resolution=box.resolution)
    cfg = SimpleNamespace(**{**vars(QCFG), "occluded_below": 0.4, "occluded_depth": 0.6})
    on, off = ScanQuality(g, cfg), ScanQuality(g, SimpleNamespace(**{**vars(cfg), "occluded_depth": 0.0}))
    truth = (3.0, 4.0, 0.0)
    e = _scan_from(truth, box)
    near = on.fit((3.45, 4.0, 0.0), e)  # 0.45 m off: beams towards +x end 0.4 m past the east wall
    assert near.contradiction > 0.0 and near.deep == 0.0
    far = on.fit((4.5, 4.0, 0.0), e)  # 1.5 m off: they end 1.45 m past it
    assert far.deep == pytest.approx(far.contradiction) and far.deep > 0.1
    plain = off.fit((3.45, 4.0, 0.0), e)  # occluded_depth 0: every beam through is deep
    assert plain.deep == plain.contradiction > 0.0
    # half the beams on people in front of the walls, a few near misses: bad only with the exemption off (update
    # asks for it when its gates allow; bad() on its own counts every beam through a wall)
    crowd = Fit(60, 0.5, 0.05, 0.0)
    assert on.bad(crowd, near_misses=True) is False and off.bad(Fit(60, 0.5, 0.05)) is True
    assert on.bad(crowd) is True
    assert on.bad(Fit(60, 0.39, 0.05, 0.0), near_misses=True) is True  # below occluded_below: lost all the same
    assert on.bad(Fit(60, 0.5, 0.05, 1 / 60), near_misses=True) is True  # one beam deep past a wall: lost_below
    # contradiction_above still counts every beam through a wall, near misses too
    strict = ScanQuality(g, SimpleNamespace(**{**vars(cfg), "contradiction_above": 0.1}))
    assert strict.bad(Fit(60, 0.85, 0.1, 0.0), near_misses=True) is True
    assert strict.bad(Fit(60, 0.85, 0.05, 0.0), near_misses=True) is False


def test_a_narrow_view_takes_near_misses_only_as_deep_as_the_square_root_of_its_share():
    # quality.occluded_depth 1.0 m: a clutter world turned at 1.5 rad/s among people left a correct track's beams
    # 0.6-1.0 m past walls (heldout21 clutter-stalls-turns, lost at 0.6 m). A 59-degree depth camera's few beams
    # through walls at a wrong place end about as shallow (heldout.yaml clutter-kinect-h8, lost at 1.0 m): a narrow
    # view takes the depth times the square root of its share of 180 degrees, 0.57 m there.
    from scipy.ndimage import distance_transform_edt

    box = _box_grid()
    occ = np.pad(box.occupied, 40)
    g = SimpleNamespace(distance=distance_transform_edt(~occ) * box.resolution, occupied=occ, origin=(-2.0, -2.0),
                        resolution=box.resolution)
    cfg = SimpleNamespace(**{**vars(QCFG), "occluded_below": 0.4, "occluded_depth": 1.0, "narrow_view": "scaled"})
    e = _scan_from((3.0, 4.0, 0.0), box)
    at = (3.8, 4.0, 0.0)  # 0.8 m off: beams towards +x end 0.75 m past the east wall
    as_given = SimpleNamespace(**{**vars(cfg), "narrow_view": "same"})
    wide, narrow, same = (ScanQuality(g, c) for c in (cfg, cfg, as_given))
    for q, fov in ((wide, 180.0), (narrow, 59.0), (same, 59.0)):
        q.view(np.linspace(-np.radians(fov) / 2, np.radians(fov) / 2, 640))
    assert wide.occluded_depth == 1.0 and same.occluded_depth == 1.0
    assert narrow.occluded_depth == pytest.approx(math.sqrt(59.0 / 180.0 * 640 / 639))  # 0.573 m
    w, n = wide.fit(at, e), narrow.fit(at, e)
    assert w.contradiction == n.contradiction > 0.0
    assert w.deep == 0.0 and n.deep == pytest.approx(n.contradiction)  # near misses for the wide view only
    assert same.fit(at, e).deep == 0.0


def test_near_misses_are_exempt_only_once_the_fit_has_sunk_with_occluded_prior():
    # fr079 kidnapped seed 5 (suites/real.yaml): the kidnap puts the estimate 9.8 m from the robot, where a dense
    # office map has walls near every endpoint: match 0.56-0.59 with 7-10 % of the beams through walls, every one
    # of them within 0.5 m of a wall. With occluded_depth alone those scans were not bad and the lost call came 4 s
    # late (back within 0.5 m at 77 s instead of 12 s). The crowd in clutter-03 sank the fit over 2 s first (0.79 down
    # to 0.58 before the first near miss); the kidnap took it from 0.98 in one update.
    cfg = SimpleNamespace(**{**vars(QCFG), "occluded_below": 0.4, "occluded_depth": 0.6, "occluded_prior": 0.7})
    near = Fit(60, 0.57, 0.07, 0.0)  # score 0.43: bad by lost_below, exempt as near misses
    held = [Fit(60, 0.98, 0.0)] * 10
    sudden = ScanQuality(_box_grid(), cfg)
    assert _feed(sudden, held + [near] * 3)[-1] is True  # lost at the third, as without occluded_depth
    sinking = [Fit(60, m, 0.0) for m in (0.79, 0.75, 0.68, 0.62, 0.59, 0.58)]  # no beam through a wall: not bad
    crept = ScanQuality(_box_grid(), cfg)
    assert _feed(crept, held + sinking + [near] * 10) == [False] * 26  # people closing in: held through
    always = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(cfg), "occluded_prior": 2.0}))
    assert _feed(always, held + [near] * 3)[-1] is False  # no gate: the kidnap is exempt too
    # one score at 0.7 or above in the last 2 lost_after - 1 updates and the exemption is off
    mixed = ScanQuality(_box_grid(), cfg)
    assert _feed(mixed, held + sinking + [Fit(60, 0.72, 0.0)] + [near] * 3)[-1] is True
    # a place a global search has just settled on is no held track: its scores were low all along, so the gate
    # alone would exempt it (suites/heldout.yaml clutter-kinect-h8 global seed 2: a wrong place kept, 35 s instead
    # of 5 s). Within doubt_updates updates of a lost belief nothing is exempt.
    searched = ScanQuality(_box_grid(), cfg)
    searched.reset(lost=True)
    assert _feed(searched, sinking + [near] * 3)[-1] is True
    settled = ScanQuality(_box_grid(), cfg)
    settled.reset(lost=True)
    assert _feed(settled, sinking + [Fit(60, 0.59, 0.0)] * cfg.doubt_updates + [near] * 10)[-1] is False


def test_a_narrow_view_exempts_near_misses_without_waiting_for_the_fit_to_sink():
    # quality.narrow_view: scaled divides occluded_prior by the view's share of 180 degrees (over 1, no gate, under
    # 126 degrees). suites/depth-laser.yaml clutter-kinect at 29 s: people walked into the 59-degree view within
    # half a second (0.77, 0.74, 0.66, 0.5, 0.42, 0.34 at the true pose, 5-10 % of the beams just past walls); the
    # gate, made for a 180-degree laser whose fit sinks over seconds, called it lost and the spread took the track.
    cfg = SimpleNamespace(**{**vars(QCFG), "occluded_below": 0.4, "occluded_depth": 0.6, "occluded_prior": 0.7,
                             "narrow_view": "scaled"})
    near = Fit(60, 0.57, 0.07, 0.0)  # score 0.43: bad by lost_below, exempt as near misses
    held = [Fit(60, 0.98, 0.0)] * 10
    for fov_deg, exempt in ((59.0, True), (120.0, True), (150.0, False), (180.0, False), (360.0, False)):
        q = ScanQuality(_box_grid(), cfg)
        q.view(np.linspace(-np.radians(fov_deg) / 2, np.radians(fov_deg) / 2, 181))
        assert _feed(q, held + [near] * 3)[-1] is (not exempt), fov_deg
    # beams through walls deeper than occluded_depth, or contradiction_above of them, still count at any width
    q = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(cfg), "contradiction_above": 0.1}))
    q.view(np.linspace(-0.5, 0.5, 181))
    assert _feed(q, held + [Fit(60, 0.57, 0.07, 0.02)] * 3)[-1] is True
    wide = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(cfg), "contradiction_above": 0.1}))  # no view: 180
    assert _feed(wide, held + [Fit(60, 0.57, 0.12, 0.0)] * 3)[-1] is True
    q.reset(lost=False)
    assert _feed(q, held + [Fit(60, 0.57, 0.12, 0.0)] * 3)[-1] is True
    # nor within doubt_updates of a lost belief (a place a search just settled on)
    searched = ScanQuality(_box_grid(), cfg)
    searched.view(np.linspace(-0.5, 0.5, 181))
    searched.reset(lost=True)
    assert _feed(searched, [near] * 3)[-1] is True


def test_missing_counts_what_the_map_shows_the_laser_that_the_scan_does_not_read():
    # From (2, 5) facing the east wall (7.95 m away) in the box room: the directions whose ray meets a wall within
    # the 9 m reach are predicted; a reading at the wall or short of it (a person) is no absence, a direction with
    # no return or a reading past the wall is
    from mcl.quality import ScanQuality

    q = ScanQuality(_box_grid(), QCFG)
    angles = np.linspace(-0.3, 0.3, 7)
    pose, laser = (2.0, 5.0, 0.0), (0.0, 0.0, 0.0)
    wall = 7.95 / np.cos(angles)  # the inner face of the east wall, x = 9.95
    returned = np.ones(7, dtype=bool)
    assert q.missing(pose, laser, angles, returned, wall, 9.0) == (7, 0)
    people = wall.copy()
    people[[1, 3, 5]] = 2.0
    assert q.missing(pose, laser, angles, returned, people, 9.0) == (7, 0)
    gone = returned.copy()
    gone[[0, 6]] = False
    past = wall.copy()
    past[3] += 1.0
    assert q.missing(pose, laser, angles, gone, past, 9.0) == (7, 3)
    assert q.missing(pose, laser, angles, returned, wall, 7.0) == (0, 0)  # the wall beyond a 7 m reach: none
    # the laser mounted 1 m ahead, turned round: it looks west at the wall 3 m behind the robot's centre
    assert q.missing(pose, (1.0, 0.0, np.pi), angles, returned, 3.0 / np.cos(angles) - 0.05, 9.0) == (7, 0)


def test_an_occluded_scan_is_no_evidence_while_what_the_map_shows_is_there():
    # A sparse hall full of people (suites/sparse-hall.yaml hall-fast-people-916): at the true pose 2-6 of a
    # scan's 6-17 returns match a pillar, 1-3 end short of one (a person in front) and the rest lie on open floor:
    # match 0.29-0.40, nothing through a wall, under occluded_below, and the lost call that followed handed the
    # track to a place 12 m off. Of the 5-8 directions where the map shows the laser a pillar, 0-1 read nothing
    # there; at a wrong place the pillars the map shows are where the laser saw none.
    cfg = SimpleNamespace(**{**vars(QCFG), "occluded_below": 0.4, "occluded_missing": 0.2})
    q = ScanQuality(_box_grid(), cfg)
    people = Fit(13, 0.33, 0.0)
    assert q.occluded_call(people) and not q.occluded_call(Fit(13, 0.45, 0.0))
    off = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(cfg), "occluded_missing": -1.0}))
    assert not off.occluded_call(people)  # off: never measured, the match alone
    assert not q.occluded_call(Fit(13, 0.3, 1 / 13)) and not q.occluded_call(Fit(4, 0.0, 0.0))
    assert q.bad(people) is True  # not measured: the match alone, as before
    sparse = dict(directions=60)  # of the 60 scored directions, the map shows an obstacle in `predicted`
    assert q.bad(Fit(13, 0.33, 0.0, predicted=7, missing=1, **sparse)) is False  # 1 of 7 missing: occlusion
    assert q.bad(Fit(13, 0.33, 0.0, predicted=7, missing=2, **sparse)) is True  # 2 of 7 (over 0.2): a wrong place
    assert q.bad(Fit(13, 0.33, 0.0, predicted=4, missing=3, **sparse)) is False  # under min_beams shown: no evidence
    assert q.bad(Fit(13, 0.2, 0.0, predicted=10, missing=0, **sparse)) is False  # however low the match
    # a dense view is no occlusion: the demo's robot kidnapped into a smaller room reads every wall the map shows
    # from the old estimate short (44 of 60 directions, none missing, match 0.13-0.21): a wrong place, lost as before
    assert q.bad(Fit(60, 0.15, 0.0, predicted=44, missing=0, **sparse)) is True
    assert q.bad(Fit(60, 0.15, 0.0, predicted=30, missing=0, **sparse)) is False  # half: still sparse
    occluded = Fit(13, 0.33, 0.0, predicted=7, missing=1, **sparse)
    assert _feed(q, [Fit(13, 0.95, 0.0)] * 5 + [occluded] * 10) == [False] * 15


def test_a_view_whose_returns_mostly_lie_on_open_floor_is_no_crowd():
    # aces with its filter kidnapped (seed 2): from the old estimate the map shows 12 and 22 of the 60 scored
    # directions an obstacle, every one read, but 36 of 42 and 50 of 60 returns lie on open floor: the kidnapped
    # robot's own walls, not people. Taken for a crowd, the lost call came 25 s late (34.6 s to recover; 21.1 s
    # with the cap). The sparse hall's crowd at the true pose leaves 5-14 of 60 on open floor.
    cfg = SimpleNamespace(**{**vars(QCFG), "occluded_below": 0.4, "occluded_missing": 0.2, "occluded_open": 0.5})
    q = ScanQuality(_box_grid(), cfg)
    kidnapped = [Fit(42, 0.14, 0.0, predicted=12, missing=0, directions=60),
                 Fit(60, 0.17, 0.0, predicted=22, missing=0, directions=60)]
    assert [q.bad(f) for f in kidnapped] == [True, True]
    crowd = Fit(17, 0.24, 0.0, predicted=8, missing=1, directions=60)  # 13 of 60 on open floor
    assert q.bad(crowd) is False
    assert q.bad(Fit(36, 0.17, 0.0, predicted=8, missing=0, directions=60)) is False  # 30 of 60: at the cap
    assert q.bad(Fit(38, 0.17, 0.0, predicted=8, missing=0, directions=60)) is True  # 31.5 of 60: over it
    # pooled scans sum their directions: five of 12 returns, 4 of 20 directions shown, 48 of 100 on open floor
    pooled = SimpleNamespace(**{**vars(cfg), "held_pool_beams": 60, "held_min_beams": 15})
    assert _feed(ScanQuality(_box_grid(), pooled), [Fit(12, 0.2, 0.0, predicted=4, missing=0, directions=20)] * 30) \
        == [False] * 30
    off = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(cfg), "occluded_open": 1.0}))
    assert [off.bad(f) for f in kidnapped] == [False, False]  # without the cap: taken for people, as before
    # a laser tilted onto the floor of an open hall: 35-49 returns on the floor at the true pose, the map showing 2-3
    # obstacles (suites/ground-hits.yaml's kind): fewer than min_beams shown is nothing to judge by, cap or not
    assert q.bad(Fit(49, 0.061, 0.0, predicted=3, missing=0, directions=60)) is False


def test_people_in_a_sparse_hall_do_not_make_a_correct_track_lost(tmp_path):
    # The first 8 s of suites/sparse-hall.yaml hall-fast-people-916 (a 12 m laser at 1.5 m/s in a hall of sparse
    # pillars, 8 people): people make most of a scan's returns, the match falls to 0.29-0.40 at the true pose with
    # nothing through a wall. Called lost on that alone, the default re-seeded at 1.5 s and jumped to a place where
    # the people line up with pillars: 3 lost episodes, max 18 m, RMSE 7.7 m (the whole 60 s world: 30.8 m against
    # the plain filter's 0.36 m). What the map shows the laser is there or hidden behind people (ScanQuality.
    # missing): no lost call, max 0.13 m.
    from mcl.config import load_config
    from mcl.runner import run
    from mcl.simulate import simulate

    data = tmp_path / "hall"
    sim = simulate(data, kind="hall", seed=916, duration=8.0, scan_rate=10.0, speed=1.5, dynamic_obstacles=8)
    x, y, th = sim["start_pose"]
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={data / 'map.yaml'}", f"log={data / 'log.clf'}", f"truth={data / 'truth.tum'}", "rerun.mode=off",
        "filter.global_localization=false", f"filter.initial_pose=[{x}, {y}, {th}]", "seed=1"])
    s = run(cfg, tmp_path / "run", progress=False, echo=lambda m: None)
    assert s["quality"]["lost_episodes"] == 0 and s["reseeds"] == 0, s["quality"]
    assert s["eval"]["ate_max"] < 0.3, s["eval"]


def test_the_view_is_measured_for_a_scan_whose_only_beams_through_walls_are_near_misses():
    # bad() exempts beams that went just past a wall (within occluded_depth of it) once a held track's fit has sunk
    # (_creeping): people pulling the cloud 0.2-0.3 m off. Such a scan is judged by its match alone, so the filter
    # must measure what the map shows the laser (occluded_call) for it too, or a crowd in a sparse view is called
    # a wrong place for want of the measurement. Before the two shared one predicate, occluded_call looked at
    # every beam through a wall and left this scan unmeasured.
    cfg = SimpleNamespace(**{**vars(QCFG), "occluded_below": 0.4, "occluded_missing": 0.2, "occluded_depth": 0.6,
                             "occluded_prior": 0.7})
    q = ScanQuality(_box_grid(), cfg)
    q.reset(lost=False)  # tracking from a known pose: a held track
    crowd = Fit(13, 0.33, 1 / 13, deep=0.0)  # one beam just past a wall, none deep
    deep = Fit(13, 0.33, 1 / 13, deep=1 / 13)
    assert not q.occluded_call(crowd)  # the fit has not sunk: every beam through a wall counts
    for _ in range(5):
        q.update(Fit(13, 0.65, 0.0))  # scores under occluded_prior: the fit has sunk
    assert q.occluded_call(crowd) and not q.occluded_call(deep)
    sparse = dict(predicted=7, directions=60)
    assert q._bad_now(Fit(13, 0.33, 1 / 13, deep=0.0, missing=1, **sparse)) is False  # measured: occlusion
    assert q._bad_now(Fit(13, 0.33, 1 / 13, deep=0.0, missing=3, **sparse)) is True  # 3 of 7 gone: a wrong place


def test_a_large_lost_after_clears_a_global_start_once_its_window_holds_mostly_good_fits():
    # lost_after = 30 (slower to call a track lost) made a global start "lost" until 30 fits had come in: on the
    # demo 25 re-seeds over a search that had converged at 1 s (error 0.83 m over 1-50 s, against 0.06 m). The
    # window still filling after a reset now clears once it holds 3 fits or more, at most half of them bad; a full
    # window keeps its rule (at most lost_after // 2 bad of the last 2 lost_after - 1), and lost_after = 3 is as before.
    good, bad = Fit(60, 0.95, 0.0), Fit(60, 0.2, 0.3)
    q = ScanQuality(_box_grid(), SimpleNamespace(**{**vars(QCFG), "lost_after": 30}))
    q.reset(lost=True)
    assert [q.update(f) for f in (good, bad, good)] == [True, True, False]  # 1 bad of 3
    q.reset(lost=True)
    assert [q.update(f) for f in (bad, bad, good, good)] == [True, True, True, False]  # 2 of 3 bad, then 2 of 4
    # once lost from a track (30 bad fits), it clears only with at most 15 of the last 59 bad, as before
    q.reset(lost=False)
    for _ in range(30):
        q.update(bad)
    assert q.lost
    for _ in range(14):
        assert q.update(good) is True  # the window: 30 bad, then 14 good: 30 of 44 bad
    q3 = ScanQuality(_box_grid(), QCFG)  # lost_after 3: after a reset, three fits with at most one bad, as before
    q3.reset(lost=True)
    assert [q3.update(f) for f in (bad, good, good)] == [True, True, False]


def test_a_robot_kidnapped_in_a_sparse_hall_is_called_lost_on_its_pooled_scans(tmp_path):
    # A hall under a 12 m laser (its scans return a median 5 of 60 scored beams), the robot kidnapped at 40 s. Every
    # scan after the kidnap is under quality.held_min_beams (15), so with held_pool_beams 0 the track is never
    # called lost and the run ends 20 s later still at the old place; pooled (60 returns), the lost call comes 5 s
    # after the kidnap and the re-seed brings the estimate back within 0.5 m within 10 s (measured: 5.2 s and
    # 7.4 s; the bar of 10 s leaves room for another platform's last bits)
    from mcl.runner import run
    from mcl.simulate import simulate

    data = tmp_path / "hall"
    sim = simulate(data, kind="hall", seed=2208, duration=60.0, kidnap_at=40.0, range_max=12.0)
    x, y, th = sim["start_pose"]
    truth = np.loadtxt(data / "truth.tum")

    def after_kidnap(pool, *sets):
        out = tmp_path / f"run{pool}"
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
            f"map={data / 'map.yaml'}", f"log={data / 'log.clf'}", "rerun.mode=off", "seed=1",
            "filter.global_localization=false", f"filter.initial_pose=[{x}, {y}, {th}]",
            f"quality.held_pool_beams={pool}", *sets])
        run(cfg, out, progress=False, echo=lambda m: None)
        rows = list(csv.DictReader(open(out / "quality.csv")))
        t0 = float(rows[0]["t"])
        lost = [float(r["t"]) - t0 for r in rows if r["lost"] == "1"]
        est = np.loadtxt(out / "trajectory.tum")
        i = np.searchsorted(truth[:, 0], est[:, 0]).clip(0, len(truth) - 1)
        err = np.hypot(est[:, 1] - truth[i, 1], est[:, 2] - truth[i, 2])
        back = est[(est[:, 0] - t0 > 40.0) & (err < 0.5), 0] - t0
        return lost, back

    lost, back = after_kidnap(60)
    assert lost and 40.0 <= lost[0] < 47.0, lost[:3]
    assert back.size and back[0] < 50.0, back[:3]
    # the control: not pooled, and the few scans of 15 returns or more taken for people (quality.occluded_open off;
    # with it, those whose returns lie mostly on open floor call the kidnap lost at 40.4 s even unpooled)
    lost0, back0 = after_kidnap(0, "quality.occluded_open=1.0")
    assert lost0 == [] and back0.size == 0, (lost0[:3], back0[:3])


def test_a_low_match_refutes_a_kidnapped_track_but_not_one_a_crowd_crept_over():
    # occlusion_match: a lost scan matching under it refutes the estimate, and the spread starts at once. 24 people
    # closing round a robot in an office over 2 s took the match from 0.70 to 0.29, nothing through walls: refuted,
    # the spread took the estimate 1.1 m off (generated world w4347). In an episode that began on such a crept fit
    # (no score of the last five reached occluded_prior), the match alone refutes nothing; a held track whose fit
    # drops at once (a kidnap) is refuted as before, and so is a scan through walls.
    cfg = SimpleNamespace(**{**vars(QCFG), "occluded_below": 0.4, "occluded_prior": 0.7, "occlusion_match": 0.45,
                             "contradiction_above": 0.1, "occluded_depth": 1.0})
    crowd = ScanQuality(_box_grid(), cfg)
    crowd.reset(lost=False)
    crept = [Fit(60, m, 0.0, 0.0) for m in (0.69, 0.63, 0.53, 0.48, 0.32, 0.35, 0.30)]
    assert _feed(crowd, crept) == [False] * 6 + [True]
    assert not crowd.refutes(Fit(60, 0.29, 0.0, 0.0))
    assert crowd.refutes(Fit(60, 0.29, 0.12, 0.12))  # through walls: refuted whatever came before
    kidnap = ScanQuality(_box_grid(), cfg)
    kidnap.reset(lost=False)
    assert _feed(kidnap, [Fit(60, 0.95, 0.0, 0.0)] * 5 + [Fit(60, 0.30, 0.0, 0.0)] * 3)[-1]
    assert kidnap.refutes(Fit(60, 0.29, 0.0, 0.0))
