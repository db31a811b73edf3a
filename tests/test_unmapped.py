"""Unmapped objects (sensor.unmapped_skip, mcl.sensors.UnmappedObjects): the beams of small segments of the scan
that end off the map, seen from the estimate, are not scored while tracking."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from mcl.config import PROJECT_ROOT
from mcl.kernels.segments import small_segments
from mcl.maps import OccupancyGrid
from mcl.sensors import UnmappedObjects, beam_endpoints, beam_selection


def _segments_reference(r, a, valid, jump, width, ends=False):
    """The rule written out: maximal runs of valid beams with steps <= jump, not touching the scan's ends (unless
    ``ends``), whose end points are closer than width."""
    out = np.zeros(r.size, dtype=bool)
    runs, cur = [], []
    for k in range(r.size):
        if valid[k] and cur and abs(r[k] - r[cur[-1]]) <= jump:
            cur.append(k)
            continue
        if cur:
            runs.append(cur)
        cur = [k] if valid[k] else []
    if cur:
        runs.append(cur)
    for run in runs:
        i, j = run[0], run[-1]
        if not ends and (i == 0 or j == r.size - 1):
            continue
        p = np.array([r[i] * math.cos(a[i]), r[i] * math.sin(a[i])])
        q = np.array([r[j] * math.cos(a[j]), r[j] * math.sin(a[j])])
        if np.linalg.norm(p - q) < width:
            out[i:j + 1] = True
    return out


def test_small_segments_marks_a_person_in_front_of_a_wall_and_not_the_wall():
    a = np.radians(np.arange(-90.0, 90.5, 1.0))
    r = 5.0 / np.cos(a.clip(-0.8, 0.8))  # a wall 5 m ahead (readings constant beyond 46 degrees)
    r[100:106] = 2.0  # a person: 6 beams at 2 m, about 0.2 m wide
    r[20:22] = 1.0  # a chair leg nearer still
    valid = np.ones(r.size, dtype=bool)
    out = np.empty(r.size, dtype=bool)
    small_segments(r, a, valid, 0.3, 1.2, out)
    assert np.flatnonzero(out).tolist() == list(range(20, 22)) + list(range(100, 106))
    # a 2 m wide object is no small object; nor is a segment at the scan's edge (its extent is not seen)
    r2 = r.copy()
    r2[60:120] = 2.0  # 60 degrees at 2 m: 2 m wide
    r2[:3] = 0.5
    small_segments(r2, a, valid, 0.3, 1.2, out)
    assert not out[60:120].any() and not out[:3].any() and out[20:22].all()
    # a wall at a grazing angle steps by more than `jump` from beam to beam: its beams are one-beam segments
    r3 = 5.0 / np.cos(a.clip(-1.45, 1.45))  # out to 83 degrees: steps up to 1.4 m a degree
    small_segments(r3, a, valid, 0.3, 1.2, out)
    steps = np.abs(np.diff(r3)) > 0.3
    assert out[1:-1].tolist() == (steps[:-1] & steps[1:]).tolist() and out.any()


def test_small_segments_agrees_with_the_rule_written_out_on_random_scans():
    rng = np.random.default_rng(3)
    for trial in range(200):
        b = int(rng.integers(3, 120))
        a = np.sort(rng.uniform(-2.0, 2.0, b))
        # piecewise-constant ranges with noise, so that runs of many lengths occur
        r = np.repeat(rng.uniform(0.5, 8.0, b), rng.integers(1, 8, b))[:b] + rng.normal(0, 0.05, b)
        valid = rng.random(b) > 0.1
        out = np.empty(b, dtype=bool)
        small_segments(r, a, valid, 0.3, 1.2, out)
        np.testing.assert_array_equal(out, _segments_reference(r, a, valid, 0.3, 1.2), err_msg=f"trial {trial}")
        # with ends (unmapped_blind's segments), a run touching the scan's first or last beam is judged by the part seen
        small_segments(r, a, valid, 0.3, 2.5, out, True)
        np.testing.assert_array_equal(out, _segments_reference(r, a, valid, 0.3, 2.5, True), err_msg=f"ends {trial}")


def _select_reference(dist, origin, res, d_max, observation, candidates, pose, shifts):
    """``UnmappedObjects.select``'s rule written out in numpy: the skip mask, or None when nothing is skipped."""
    def field(px, py):
        fx, fy = np.floor((px - origin[0]) / res), np.floor((py - origin[1]) / res)
        inside = (fx >= 0) & (fx < dist.shape[1]) & (fy >= 0) & (fy < dist.shape[0])
        out = np.full(px.shape, np.nan, dtype=np.float32)
        out[inside] = dist[fy[inside].astype(int), fx[inside].astype(int)]
        return out

    idx = np.flatnonzero(candidates)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    e = observation[:, idx]
    wx, wy = pose[0] + c * e[0] - s * e[1], pose[1] + s * e[0] + c * e[1]
    d = np.float32(d_max) if np.ndim(d_max) == 0 else np.asarray(d_max, dtype=np.float32)[idx]  # or one per endpoint
    far = field(wx, wy) > d
    if shifts is not None and far.any():
        runs = np.split(np.arange(idx.size), np.flatnonzero(np.diff(idx) != 1) + 1)
        for run in runs:
            dr = d if np.ndim(d) == 0 else d[run]
            if any(not (field(wx[run] + dx, wy[run] + dy) > dr).any() for dx, dy in shifts):
                far[run] = False
    if not far.any() or 2 * np.count_nonzero(far) >= observation.shape[1]:
        return None
    skip = np.zeros(observation.shape[1], dtype=bool)
    skip[idx[far]] = True
    return skip



def _random_trial(rng, trial: int):
    """A random select case: (endpoints (2, K), candidates, pose, shifts or None on every third trial)."""
    k = int(rng.integers(3, 90))
    obs = np.vstack([rng.uniform(-3.0, 8.0, k), rng.uniform(-5.0, 5.0, k)])
    cand = rng.random(k) < rng.uniform(0.05, 0.9)
    pose = (rng.uniform(0.0, 7.0), rng.uniform(0.0, 4.0), rng.uniform(-3.2, 3.2))
    shifts = None if trial % 3 == 0 else rng.normal(0.0, 0.5, (int(rng.integers(1, 17)), 2))
    return obs, cand, pose, shifts

def test_select_agrees_with_the_rule_written_out_on_random_scans_and_shifts():
    # the kernel (mcl.kernels.field.far_runs) against the rule in numpy: fields holding many distances equal to
    # unmapped_distance (0.3 = 6 cells of 0.05 m: compared in float32, as the float32 field is), runs of many
    # lengths, shifts that clear some runs and not others, endpoints off the map
    rng = np.random.default_rng(11)
    dist = (np.sqrt(rng.integers(0, 120, (120, 160)).astype(float)) * 0.05).astype(np.float32)
    dist[rng.random(dist.shape) < 0.2] = np.float32(0.3)
    grid = SimpleNamespace(origin=(-1.0, -2.0), resolution=0.05)
    unmapped = UnmappedObjects(grid, _cfg(), dist=dist)
    skipped_some = cleared_some = 0
    for trial in range(1500):
        obs, cand, pose, shifts = _random_trial(rng, trial)
        want = _select_reference(dist, grid.origin, 0.05, 0.3, obs, cand, pose, shifts)
        kept, skipped = unmapped.select(obs, cand, pose, (lambda sh=shifts: sh) if trial % 2 else shifts)
        if want is None:
            assert skipped is None and kept is obs, trial
        else:
            np.testing.assert_array_equal(skipped, obs[:, want], err_msg=f"trial {trial}")
            np.testing.assert_array_equal(kept, obs[:, ~want], err_msg=f"trial {trial}")
            skipped_some += 1
        unshifted = _select_reference(dist, grid.origin, 0.05, 0.3, obs, cand, pose, None)
        if unshifted is not None and (want is None or np.count_nonzero(want) < np.count_nonzero(unshifted)):
            cleared_some += 1  # a shift kept a run the pose alone would skip
    assert skipped_some > 500 and cleared_some > 500  # both branches exercised (740 and 785 of 1500)



def test_select_with_a_distance_function_agrees_with_the_rule_and_calls_it_only_when_one_is_far():
    # sensor.unmapped_turn_sigmas hands select a function of the per-endpoint distances (never under
    # unmapped_distance): called only when a candidate lies farther than unmapped_distance from the pose, since no
    # candidate can lie farther than a larger distance otherwise; its distances then decide, the shifts as before
    rng = np.random.default_rng(12)
    dist = (np.sqrt(rng.integers(0, 120, (120, 160)).astype(float)) * 0.05).astype(np.float32)
    grid = SimpleNamespace(origin=(-1.0, -2.0), resolution=0.05)
    unmapped = UnmappedObjects(grid, _cfg(), dist=dist)
    calls = due = spared = 0
    for trial in range(600):
        obs, cand, pose, shifts = _random_trial(rng, trial)
        d = 0.3 + rng.exponential(0.3, obs.shape[1])

        def distances(d=d):
            nonlocal calls
            calls += 1
            return d

        kept, skipped = unmapped.select(obs, cand, pose, shifts, distance=distances)
        want = _select_reference(dist, grid.origin, 0.05, d, obs, cand, pose, shifts)
        if want is None:
            assert skipped is None and kept is obs, trial
        else:
            np.testing.assert_array_equal(skipped, obs[:, want], err_msg=f"trial {trial}")
        floor = _select_reference(dist, grid.origin, 0.05, 0.3, obs, cand, pose, None)
        due += floor is not None or _far_at(dist, grid.origin, 0.05, 0.3, obs, cand, pose)
        spared += floor is not None and want is None  # the larger distances kept what the floor would skip
    assert calls == due and 0 < calls < 600 and spared > 50, (calls, due, spared)  # 517, 517, 318


def _far_at(dist, origin, res, d_max, observation, candidates, pose) -> bool:
    """Whether some candidate's endpoint lies farther than ``d_max`` from the map seen from ``pose``."""
    idx = np.flatnonzero(candidates)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    e = observation[:, idx]
    fx = np.floor((pose[0] + c * e[0] - s * e[1] - origin[0]) / res)
    fy = np.floor((pose[1] + s * e[0] + c * e[1] - origin[1]) / res)
    inside = (fx >= 0) & (fx < dist.shape[1]) & (fy >= 0) & (fy < dist.shape[0])
    return bool((dist[fy[inside].astype(int), fx[inside].astype(int)] > np.float32(d_max)).any())

def _corridor():
    """A 20 m x 2 m corridor (walls at y = 0 and y = 2) with a mapped pillar at x = 12; 0.05 m cells."""
    occ = np.zeros((60, 440), dtype=np.int8)
    occ[:10, :] = occ[50:, :] = 100  # walls: y < 0 and y >= 2 (origin y = -0.5)
    occ[:, :10] = occ[:, 430:] = 100
    occ[25:35, 250:260] = 100  # a 0.5 m pillar at x 12.0-12.5, y 0.75-1.25
    return OccupancyGrid.from_occupancy(occ, 0.05, (-0.5, -0.5))


def _cfg(**kw):
    keys = dict(max_beams=181, range_min=0.0, range_max=30.0, unmapped_jump=0.3, unmapped_width=1.2,
                unmapped_distance=0.3)
    return SimpleNamespace(**(keys | kw))


def _scan(pose, grid, people=()):
    """A 181-beam scan cast in ``grid`` from ``pose``, then shortened by discs ``people`` ((x, y, radius))."""
    from mcl.kernels.raycast import cast_rays

    a = np.radians(np.arange(-90.0, 90.5, 1.0))
    out = np.empty((1, a.size))
    cast_rays(np.array(pose, dtype=float).reshape(3, 1), a, np.ascontiguousarray(grid.occupied, dtype=np.uint8),
              grid.origin[0], grid.origin[1], grid.resolution, 30.0, out)
    r = out[0].copy()
    for px, py, pr in people:
        for k, ang in enumerate(a + pose[2]):  # ray-disc intersection
            dx, dy = px - pose[0], py - pose[1]
            t = dx * math.cos(ang) + dy * math.sin(ang)
            h2 = dx * dx + dy * dy - t * t
            if t > 0 and h2 < pr * pr:
                r[k] = min(r[k], t - math.sqrt(pr * pr - h2))
    return SimpleNamespace(ranges=r, angles=a, max_range=None)


def test_the_beams_on_a_person_are_skipped_and_the_mapped_pillar_and_walls_are_kept():
    grid = _corridor()
    cfg = _cfg()
    pose = (9.0, 1.0, 0.0)
    scan = _scan(pose, grid, people=[(10.5, 1.35, 0.2)])
    obs = beam_endpoints(scan.ranges, scan.angles, None, cfg)
    u = UnmappedObjects(grid, cfg)
    cand = u.candidates(scan)
    assert cand.shape == (obs.shape[1],)
    kept, skipped = u.select(obs, cand, pose)
    assert skipped is not None
    # every skipped endpoint is on the person (within its radius plus a cell), and every beam on the person is gone
    world = np.array(pose[:2])[:, None] + skipped
    assert np.all(np.hypot(world[0] - 10.5, world[1] - 1.35) < 0.25)
    on_person = np.hypot(obs[0] + pose[0] - 10.5, obs[1] + pose[1] - 1.35) < 0.25
    assert skipped.shape[1] == np.count_nonzero(on_person) >= 3
    assert kept.shape[1] == obs.shape[1] - skipped.shape[1]
    # the pillar is a small segment too, but it is on the map: kept
    pillar = np.hypot(obs[0] + pose[0] - 12.25, obs[1] + pose[1] - 1.0) < 0.4
    assert pillar.any() and cand[pillar].any()
    assert not np.isin(obs[:, pillar].T.tolist(), skipped.T.tolist()).all(axis=1).any()
    # an observation that carries the scan's no-return rays (sensor.likelihood_field.no_return_miss) keeps them
    from mcl.sensors import Endpoints

    free = np.zeros((4, 2))
    kept, _ = u.select(Endpoints(obs, free, 9.0), cand, pose)
    assert kept.free is free and kept.reach == 9.0 and kept.flags["C_CONTIGUOUS"]


def test_nothing_is_skipped_without_people_and_nothing_when_half_the_scan_would_go():
    grid = _corridor()
    cfg = _cfg()
    pose = (9.0, 1.0, 0.0)
    scan = _scan(pose, grid)
    u = UnmappedObjects(grid, cfg)
    obs = beam_endpoints(scan.ranges, scan.angles, None, cfg)
    kept, skipped = u.select(obs, u.candidates(scan), pose)
    assert skipped is None and kept is obs
    # seen from a pose 3 m off, the candidates would take half the scan: the estimate is wrong, none is skipped
    cand = np.zeros(obs.shape[1], dtype=bool)
    cand[: obs.shape[1] // 2 + 1] = True
    _, skipped = u.select(obs, cand, (pose[0], pose[1] + 30.0, 0.0))  # every endpoint far off the map's walls
    assert skipped is None


def test_candidates_follow_the_models_beam_selection_and_a_fused_scan_has_none():
    grid = _corridor()
    cfg = _cfg(max_beams=60)
    scan = _scan((9.0, 1.0, 0.0), grid, people=[(10.5, 1.35, 0.2)])
    scan.ranges[7] = np.nan  # an invalid reading among the chosen beams changes K
    u = UnmappedObjects(grid, cfg)
    cand = u.candidates(scan)
    assert cand.shape[0] == beam_selection(scan.ranges, scan.angles, None, cfg).size
    assert cand.shape[0] == beam_endpoints(scan.ranges, scan.angles, None, cfg).shape[1]
    fused = SimpleNamespace(ranges=scan.ranges, angles=scan.angles[::-1].copy(), max_range=None)
    assert u.candidates(fused) is None


@pytest.fixture(scope="module")
def people_corridor(tmp_path_factory):
    from mcl.simulate import simulate

    out = tmp_path_factory.mktemp("corridor05")
    return out, simulate(out, kind="corridor", seed=305, duration=120.0, dynamic_obstacles=6)


def test_people_at_a_junction_no_longer_carry_the_track_off(people_corridor, tmp_path):
    # suites/synthetic.yaml corridor-05: people stand where the map has the side corridor's opening, and from
    # 16 s on a pose 2-3 m back along the corridor fits their readings better than the true pose. Without the
    # skip the default drifts off and is lost for good (over 10 m, every seed); with it the track holds. Seed 1
    # is fixed; 0.5 m is the suite's tracking bound.
    from mcl.config import load_config
    from mcl.runner import run

    data, sim = people_corridor
    x, y, th = sim["start_pose"]

    def track(flag: str):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
            f"map={data / 'map.yaml'}", f"log={data / 'log.clf'}", f"truth={data / 'truth.tum'}", "rerun.mode=off",
            "filter.global_localization=false", f"filter.initial_pose=[{x}, {y}, {th}]", "seed=1",
            f"sensor.unmapped_skip={flag}"])
        return run(cfg, tmp_path / flag, progress=False, echo=lambda m: None)

    on = track("true")
    assert on["eval"]["ate_max"] < 0.5, on["eval"]
    assert on["skipped_beams"] > 0
    off = track("false")
    assert off["eval"]["ate_max"] > 2.0, off["eval"]


def _junction():
    """A 31 m x 2 m corridor (walls at y = 0 and y = 2) with a side corridor x 15-17 m going up to y = 7."""
    occ = np.zeros((160, 640), dtype=np.int8)  # origin (-0.5, -0.5), 0.05 m cells
    occ[:10, :] = 100  # y < 0
    occ[50:, :] = 100  # y >= 2 ...
    occ[50:150, 310:350] = 0  # ... but for the side corridor
    occ[150:, :] = 100
    occ[:, :10] = occ[:, 630:] = 100
    return OccupancyGrid.from_occupancy(occ, 0.05, (-0.5, -0.5))


def test_a_lagging_clouds_view_through_an_opening_is_the_maps_and_a_person_is_still_skipped():
    # corridor-02 and infinite_corridor: the cloud lags 0.5-1 m behind the robot along a corridor, and the side
    # corridor's far wall, seen through the junction's opening, is a small segment that ends 0.6 m short of that
    # wall as seen from the estimate: without the shifts it is skipped as an unmapped object, the very beams that
    # would pull the cloud forward. Shifted along the corridor (sensor.unmapped_spread), one pose puts the whole
    # segment on the wall: kept. A person in the corridor stays off the map from every shift: still skipped.
    grid = _junction()
    cfg = _cfg()
    truth, lagging = (11.0, 1.0, 0.0), (10.4, 1.0, 0.0)
    scan = _scan(truth, grid, people=[(13.0, 0.6, 0.2)])
    obs = beam_endpoints(scan.ranges, scan.angles, None, cfg)
    u = UnmappedObjects(grid, cfg)
    cand = u.candidates(scan)

    def skipped_world(shifts):
        _, sk = u.select(obs, cand, lagging, shifts)
        return np.array(lagging[:2])[:, None] + sk

    on_person = lambda w: np.hypot(w[0] - 12.4, w[1] - 0.6) < 0.3  # noqa: E731 (seen 0.6 m back)
    far_wall = lambda w: (w[1] > 2.0) & (np.abs(w[0] - 16.4) < 0.1)  # noqa: E731 (x = 17 seen 0.6 m back)
    plain = skipped_world(None)
    assert np.count_nonzero(far_wall(plain)) >= 3 and np.count_nonzero(on_person(plain)) >= 3
    forward = np.linspace(0.1, 0.6, 6)[:, None] * np.array([[1.0, 0.0]])
    shifted = skipped_world(forward)
    assert not far_wall(shifted).any()
    assert np.count_nonzero(on_person(shifted)) == np.count_nonzero(on_person(plain))
    assert shifted.shape[1] == np.count_nonzero(on_person(shifted))
    # shifts backward, across the corridor, or too short to reach the wall leave the far wall skipped
    assert np.count_nonzero(far_wall(skipped_world(-forward))) >= 3
    assert np.count_nonzero(far_wall(skipped_world(forward[:, ::-1]))) >= 3
    assert np.count_nonzero(far_wall(skipped_world(forward * 0.5))) >= 3


def test_the_shifts_go_forward_along_the_clouds_major_axis_out_to_unmapped_spread_std():
    # ParticleFilter._unmapped_shifts: a cloud spread along a corridor (std 0.3 m along x, 0.03 m across), moving
    # forward along +x: shifts along +x out to 2 std = 0.6 m in 0.1 m steps; reversing, or driving forward facing
    # -x: along -x; not moving, or unmapped_spread 0: none.
    from mcl.config import load_config
    from mcl.filter import ParticleFilter

    pf = ParticleFilter(load_config(None, ["filter.particles=100", "filter.kld=false",
                                           "sensor.unmapped_spread=2.0"]), _corridor())
    pf.last_estimate = SimpleNamespace(mean=np.array([9.0, 1.0, 0.0]), cov=np.diag([0.09, 0.0009, 0.001]))
    pf._delta = np.array([0.2, 0.0, 0.0])
    fwd = pf._unmapped_shifts(pf._moved_estimate())
    assert fwd.shape == (6, 2)
    np.testing.assert_allclose(np.abs(fwd[:, 1]), 0.0, atol=1e-9)
    np.testing.assert_allclose(fwd[:, 0], np.linspace(0.1, 0.6, 6), atol=1e-9)
    pf._delta = np.array([-0.2, 0.0, 0.0])
    np.testing.assert_allclose(pf._unmapped_shifts(pf._moved_estimate()), -fwd, atol=1e-9)
    pf.last_estimate.mean[2] = math.pi  # facing -x, driving forward in its own frame: -x in the world
    pf._delta = np.array([0.2, 0.0, 0.0])
    np.testing.assert_allclose(pf._unmapped_shifts(pf._moved_estimate()), -fwd, atol=1e-9)
    pf.last_estimate.mean[2] = 0.0
    pf._delta = np.zeros(3)
    assert pf._unmapped_shifts(pf._moved_estimate()) is None
    off = ParticleFilter(load_config(None, ["filter.particles=100", "filter.kld=false",
                                            "sensor.unmapped_spread=0"]), _corridor())
    off.last_estimate, off._delta = pf.last_estimate, np.array([0.2, 0.0, 0.0])
    assert off._unmapped_shifts(off._moved_estimate()) is None


DATA = PROJECT_ROOT.parent / "shared" / "data"


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "infinite_corridor").is_dir(), reason=f"real datasets not found at {DATA}")
def test_infinite_corridor_seed_3_keeps_within_1_m_with_the_shifts(tmp_path):
    # The real tracking bound (1 m) had one miss: infinite_corridor seed 3 lagged 1.18 m at 175 s, the
    # beams that tell (small segments on walls ahead, 0.5-1 m short of them seen from the lagging cloud) skipped as
    # unmapped objects. With the estimate shifted forward along the cloud's major axis (2 std) they are kept:
    # 0.64 m. Seed 3 is fixed; over seeds 1-20 the default stays within 0.89 m with the shifts, and two seeds
    # exceed 1 m without them (docs/measurements.md, "Eleventh session"). The test replays the log's first 200 s
    # (1,001 of 1,941 scans: the same runs up to there, half the CI time): 0.51 m with the shifts, 1.18 m without.
    # Measured with sensor.unmapped_unknown off, as the shifts were made: with it on (the default since the
    # thirty-fifth session) seed 3 stays within 0.41 m without the shifts too, so it would tell them apart no more;
    # and with the book's odometry noise (motion.noise_step 0): at the default's 0.3 m the noise of these 1 m steps
    # is narrower and the cloud lags no more (0.29 m without the shifts). The ESS floor is pinned off (filter.ess_floor
    # 0, the default), as the shifts were made: with it (0.005) seed 3 keeps within 0.29 m without the shifts. And
    # without sensor.unmapped_turn_sigmas, made later: with it seed 3 keeps within 0.32 m without the shifts (the
    # lag began at a turn).
    from mcl.config import load_config
    from mcl.runner import run

    lines = (DATA / "infinite_corridor" / "log.clf").read_text().splitlines(keepends=True)
    log = tmp_path / "log.clf"
    log.write_text("".join(line for line in lines if not line.startswith("#") and float(line.split()[-3]) <= 200.0))

    def track(spread: str):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
            f"map={DATA / 'infinite_corridor' / 'map.yaml'}", f"log={log}",
            f"truth={DATA / 'infinite_corridor' / 'truth.tum'}", "rerun.mode=off", "seed=3",
            "filter.global_localization=false",
            "filter.initial_pose=[1.00824, -0.016781, 0.005957]",
            f"sensor.unmapped_spread={spread}", "sensor.unmapped_unknown=false", "motion.noise_step=0",
            "filter.ess_floor=0", "sensor.unmapped_turn_sigmas=0"])
        return run(cfg, tmp_path / spread, progress=False, echo=lambda m: None)

    shifted = track("2.0")["eval"]
    assert shifted["scored"] >= 1000 and shifted["ate_max"] < 0.8, shifted
    assert track("0")["eval"]["ate_max"] > 1.0



def test_a_turn_the_odometry_overshot_keeps_the_far_walls_that_turn_the_estimate_back(tmp_path):
    # Hunt r4330: infinite_corridor with its odometry 5 % short, its turns 7 % long and the map turned 30 degrees.
    # At a 110-degree corner taken at 5 m/s (16.6-17.2 s) each step's odometry turned 2-3 degrees too far, and the
    # far walls ahead (9-20 m, at a grazing angle: a reading or two per segment) lay 0.4-0.8 m off the map from the
    # estimate. Skipped as people, they took with them what turns the estimate back and places it along the
    # corridor; the rest of the scan fitted a pose 0.8 m back, and seed 4 was lost, 20 m off by 21 s (seeds 1-5:
    # 1.02 / 0.69 / 0.82 / 20.8 / 20.7 m; the baseline, which skips nothing, 0.55-0.92 m). Within half a std of the
    # heading noise the turn adds times their range (sensor.unmapped_turn_sigmas 0.5) they are kept: 0.36-0.42 m over
    # the whole log, seeds 1-5. The log's first 25 s hold it all (seeds 1-5: 0.21-0.23 m with it, 0.64-20.8 m
    # without); seed 4: under 0.6 m with it, over 1 m without (measured 0.23 / 20.8 m).
    from tests.degraded import degraded, replay

    world = degraded(tmp_path, "infinite_corridor", "--odom-scale", "0.95", "--turn-scale", "1.07",
                     "--map-rotation", "30", "--fov", "180", "--sigma", "0", "--drop", "0", "--seed", "4330")
    lines = (world / "log.clf").read_text().splitlines(keepends=True)
    log = tmp_path / "log.clf"
    log.write_text("".join(ln for ln in lines if not ln.startswith("#") and float(ln.split()[-3]) <= 25.0))
    errors = {}
    for sigmas in (None, 0.0):  # the default's, and none
        s = replay(world, tmp_path / f"run-{sigmas}", (0.881552, 0.489587, 0.529556),
                   *([] if sigmas is None else [f"sensor.unmapped_turn_sigmas={sigmas}"]), seed=4, turned=True, log=log)
        assert s["eval"]["scored"] >= 120, s["eval"]
        errors[sigmas] = s["eval"]["ate_max"]
    assert errors[None] < 0.6 and errors[0.0] > 1.0, errors


def _open_hall():
    """A 40 m x 40 m hall (walls at its edges, origin (0, 0), 0.05 m cells) with one 0.4 m pillar at (24.4, 20)."""
    occ = np.zeros((800, 800), dtype=np.int8)
    occ[:4, :] = occ[-4:, :] = 100
    occ[:, :4] = occ[:, -4:] = 100
    occ[396:404, 484:492] = 100  # x 24.2-24.6, y 19.8-20.2: its west face 4.2 m ahead of (20, 20)
    return OccupancyGrid.from_occupancy(occ, 0.05, (0.0, 0.0))


def test_blind_when_the_map_shows_the_laser_fewer_than_min_beams_obstacles():
    grid = _open_hall()
    cfg = _cfg(max_beams=60)
    u = UnmappedObjects(grid, cfg)
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    scan = SimpleNamespace(ranges=np.full(181, 8.0), angles=angles, max_range=8.0)
    view = u.view(scan)
    assert view[1] == 8.0 and view[0].size == 60
    blocked = np.ascontiguousarray(grid.occupied, dtype=np.uint8)
    laser = (0.0, 0.0, 0.0)
    # facing the pillar 4.2 m ahead: 2 of the 60 directions meet it (blind under 5, not under 2); facing the west
    # wall 20 m away, beyond the laser's 8 m: none; 3 m from the south wall, facing it: most directions
    assert u.blind((20.0, 20.0, 0.0), laser, scan, blocked, 5)
    assert not u.blind((20.0, 20.0, 0.0), laser, scan, blocked, 2)
    assert u.blind((20.0, 20.0, math.pi), laser, scan, blocked, 1)
    assert not u.blind((20.0, 3.0, -math.pi / 2), laser, scan, blocked, 5)
    # the laser mounted 0.5 m ahead, turned to face back: from (20, 3.7) facing north it looks south at the wall
    assert not u.blind((20.0, 3.7, math.pi / 2), (0.5, 0.0, math.pi), scan, blocked, 5)
    assert u.blind((20.0, 3.7, math.pi / 2), laser, scan, blocked, 5)
    assert not u.blind((20.0, 20.0, 0.0), laser, None, blocked, 5)  # no scan: never blind


@pytest.mark.parametrize("blind", ["true", "false"])
def test_a_person_in_an_open_hall_does_not_pull_a_correct_track_onto_a_pillar(blind):
    # The robot stands in an open hall; its 8 m laser sees one person 3 m ahead and nothing else (the pillar behind
    # the person hides from it, the walls are out of reach). From a pose 1.2 m ahead the person's readings end on
    # the pillar's face, and the likelihood field pulls the cloud there: about 1 m in ten updates. With
    # unmapped_blind (default) the map shows the laser nothing from the estimate, the person's beams (1.2 m from
    # the pillar, more than BLIND_DISTANCE) are skipped and the updates only predict: the estimate stays within
    # the resampling's noise (0.1 m with this cloud) of the pose.
    from mcl.config import load_config
    from mcl.filter import ParticleFilter

    grid = _open_hall()
    cfg = load_config(None, ["filter.particles=2000", "filter.kld=false", "seed=1",
                             f"sensor.unmapped_blind={blind}"])
    pf = ParticleFilter(cfg, grid)
    pose = np.array([20.0, 20.0, 0.0])
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    r = np.full(181, 8.0)
    r[np.abs(angles) < 0.05] = 3.0  # a person 3 m ahead, 0.3 m wide
    scan = SimpleNamespace(ranges=r, angles=angles, max_range=8.0, t=0.0)
    pf.init_gaussian(tuple(pose), (0.8, 0.1, 0.02))
    pf.estimate()
    for _ in range(10):
        obs = pf.prepare(scan, np.zeros(3))
        pf.step(None, obs)
    err = float(np.hypot(*(pf.last_estimate.mean[:2] - pose[:2])))
    if blind == "true":
        assert pf.blind_updates == 10 and err < 0.1, (pf.blind_updates, err)
    else:
        assert pf.blind_updates == 0 and err > 0.6, err


def test_blind_distance_is_three_std_of_the_endpoints_offset_across_its_ray():
    # The closed form (n' S_xy n + 2 r n.S_xtheta + r^2 S_thetatheta) against poses drawn from the covariance: the
    # std of each endpoint's offset across its ray. 200,000 draws give the std to 0.2 % (1 / sqrt(2 N)); with a
    # 0.02 rad heading std the rotation is linear to 0.01 %, so 1 % tells a wrong term apart (dropping the
    # cross-covariance term moves these by 4-30 %).
    u = UnmappedObjects(_open_hall(), _cfg())
    pose = np.array([20.0, 20.0, 0.7])
    cov = np.array([[0.04, 0.012, 0.001], [0.012, 0.02, -0.0015], [0.001, -0.0015, 0.0004]])
    obs = np.array([[3.0, 0.5, -4.0, 8.0], [0.0, 6.0, 1.0, -8.0]])
    got = u.blind_distance(obs, pose, cov, 0.0)
    rng = np.random.default_rng(5)
    d = rng.multivariate_normal(np.zeros(3), cov, 200_000)
    for k in range(obs.shape[1]):
        def world(p):
            c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
            return np.stack([p[..., 0] + c * obs[0, k] - s * obs[1, k], p[..., 1] + s * obs[0, k] + c * obs[1, k]], -1)
        w0 = world(pose)
        ray = (w0 - pose[:2]) / np.linalg.norm(w0 - pose[:2])
        across = (world(pose + d) - w0) @ np.array([-ray[1], ray[0]])
        assert got[k] == pytest.approx(3.0 * across.std(), rel=0.01), (k, got[k], 3.0 * across.std())
    # never under the floor: a sharp cloud keeps BLIND_DISTANCE
    assert np.all(u.blind_distance(obs, pose, cov * 1e-6, 1.0) == 1.0)


def test_a_blind_update_keeps_a_far_pillar_that_an_uncertain_heading_moves_off_the_map():
    # The robot stands 10 m west of the hall's pillar (12 m laser, the walls beyond reach: blind) and sees it; the
    # cloud, after dead reckoning, is 0.2 rad off in heading with 0.2 rad of std. From the estimate the pillar's
    # returns lie 2 m off every mapped obstacle, more than BLIND_DISTANCE: skipped as a person before (10 blind
    # updates of 10, the heading still 0.199 rad off). 2 m is under 3 std of their offset across the ray (10 m x
    # 0.2 rad): kept (no blind update), and they turn the cloud onto the truth (0.001 rad off after ten updates).
    from mcl.config import load_config
    from mcl.filter import ParticleFilter

    grid = _open_hall()
    # every beam scored (sensor.max_beams): the pillar spans 3 of the 181
    cfg = load_config(None, ["filter.particles=2000", "filter.kld=false", "seed=1", "sensor.max_beams=181"])
    pf = ParticleFilter(cfg, grid)
    pose = np.array([14.2, 20.0, 0.0])
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    r = np.full(181, 12.0)
    # the pillar's west face 10 m ahead, 0.4 m wide: bearings within +-0.02 rad
    r[np.abs(angles) < 0.02] = 10.0
    scan = SimpleNamespace(ranges=r, angles=angles, max_range=12.0, t=0.0)
    pf.init_gaussian((14.2, 20.0, 0.2), (0.1, 0.1, 0.2))
    pf.estimate()
    for _ in range(10):
        obs = pf.prepare(scan, np.zeros(3))
        pf.step(None, obs)
    err = abs(float(pf.last_estimate.mean[2]) - pose[2])
    assert pf.blind_updates == 0 and err < 0.03, (pf.blind_updates, err)


@pytest.mark.parametrize("turn, blind_updates", [(1.2, 0), (0.0, 1)])
def test_a_blind_update_right_after_a_turn_keeps_the_pillar_the_turns_error_moves_off_the_map(turn, blind_updates):
    # The robot faced 1 rad right of the hall's pillar, the cloud sharp there (0.01 rad of heading std), and turned
    # 1 rad to face it, 10 m ahead; the odometry read 1.2 rad, so the predicted cloud is 0.2 rad off, with
    # sqrt(alpha1) x 1.2 = 0.27 rad of std (motion.alpha1 0.05). From the estimate the pillar's returns lie 2 m off
    # the map: under the last estimate's spread (3 std: 0.3 m, floor BLIND_DISTANCE 1 m) they were skipped as a
    # person, the update only predicted, and the cloud went on 0.2 rad off (measured 0.195 rad; the hall of
    # suites/heldout25.yaml hall-short-5pc-people-h32 at range scale 1 was lost so). Under the predicted cloud's
    # spread (3 std: 8 m) they are kept and turn it onto the truth in the one update (measured 0.009 rad; bound
    # 0.05 rad, a quarter of the error). Without the turn (the cloud as sharp as before, its estimate 0.2 rad off:
    # a heading no turn explains) they are still skipped (0.200 rad off).
    from mcl.config import load_config
    from mcl.filter import Control, ParticleFilter

    grid = _open_hall()
    cfg = load_config(None, ["filter.particles=2000", "filter.kld=false", "seed=1", "sensor.max_beams=181"])
    pf = ParticleFilter(cfg, grid)
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    r = np.full(181, 12.0)
    r[np.abs(angles) < 0.02] = 10.0  # the pillar's west face 10 m ahead of (14.2, 20), facing east
    scan = SimpleNamespace(ranges=r, angles=angles, max_range=12.0, t=0.2)
    pf.init_gaussian((14.2, 20.0, 0.2 - turn), (0.05, 0.05, 0.01))
    pf.estimate()
    obs = pf.prepare(scan, np.zeros(3))
    pf.step(Control(np.zeros(3), np.array([0.0, 0.0, turn]), dt=0.2), obs)
    err = abs(float(pf.last_estimate.mean[2]))
    assert pf.blind_updates == blind_updates, pf.blind_updates
    if blind_updates:
        assert err > 0.15, err
    else:
        assert err < 0.05, err
