"""Dynamic (unmapped) obstacles: beam skipping (after AMCL likelihood_field_prob, with its `amcl` rule and the
default `short` rule) and the simulator's unmapped obstacles."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from mcl.config import PROJECT_ROOT, SensorConfig, load_config
from mcl.kernels.likelihood import beam_explained_weight
from mcl.maps import OccupancyGrid
from mcl.sensors import LikelihoodField, beam_endpoints


def _grid():
    occ = np.zeros((200, 240), dtype=np.int8)  # 12 m x 10 m room, walls around, a pillar
    occ[:3, :] = occ[-3:, :] = occ[:, :3] = occ[:, -3:] = 100
    occ[120:140, 60:80] = 100
    return OccupancyGrid.from_occupancy(occ, 0.05, (-1.0, -2.0))


def _support_numpy(p, w, e, dist, ox, oy, res, max_d):
    c, s = np.cos(p[2])[:, None], np.sin(p[2])[:, None]
    fx = (p[0][:, None] - ox) / res + (c * e[0] / res - s * e[1] / res)
    fy = (p[1][:, None] - oy) / res + (s * e[0] / res + c * e[1] / res)
    inside = (fx >= 0) & (fx < dist.shape[1]) & (fy >= 0) & (fy < dist.shape[0])
    ix = np.where(inside, fx, 0).astype(int)
    iy = np.where(inside, fy, 0).astype(int)
    ok = inside & (dist[iy, ix] < max_d)
    return (ok * w[:, None]).sum(axis=0)


def test_support_kernel_matches_numpy_oracle_with_off_map_endpoints():
    g = _grid()
    rng = np.random.default_rng(0)
    n, k = 700, 90
    p = np.vstack([rng.uniform(-2, 12, n), rng.uniform(-3, 9, n), rng.uniform(-math.pi, math.pi, n)])
    w = rng.random(n)
    w /= w.sum()
    e = rng.uniform(-8, 8, (2, k))  # many endpoints fall off the 12 x 10 m map
    dist = np.ascontiguousarray(g.distance, dtype=np.float32)
    out = np.empty(k)
    beam_explained_weight(np.ascontiguousarray((p[0] + 1.0) / 0.05), np.ascontiguousarray((p[1] + 2.0) / 0.05),
                          np.cos(p[2]), np.sin(p[2]), w, np.ascontiguousarray(e / 0.05), dist, 0.5, out)
    ref = _support_numpy(p, w, e, dist, -1.0, -2.0, 0.05, 0.5)
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)
    assert 0 < out.min() < out.max() < 1  # the test exercises both explained and unexplained beams


def _cast(grid_occupied, pose, angles, origin, res):
    from mcl.kernels.raycast import cast_rays

    out = np.empty((1, angles.size))
    cast_rays(np.array(pose, dtype=float).reshape(3, 1), angles, np.ascontiguousarray(grid_occupied), origin[0],
              origin[1], res, 30.0, out)
    return out[0]


AMCL_SKIP = {"beam_skip_distance": 0.5, "beam_skip_threshold": 0.3, "beam_skip_rule": "amcl"}  # AMCL's settings


def _skip_beams(model, particles, weights, endpoints, **kw):
    """(the endpoints the filter scores, how many were skipped): ``skip_mask`` applied as the filter does."""
    skip = model.skip_mask(particles, weights, endpoints, **kw)
    return np.ascontiguousarray(endpoints[:, ~skip]), int(np.count_nonzero(skip))


def _model(**kw):
    cfg = SensorConfig(max_beams=181, beam_skip=True, **(AMCL_SKIP | kw))
    return LikelihoodField(_grid(), cfg), cfg


def test_beams_hitting_an_unmapped_box_are_skipped_and_the_rest_kept():
    g = _grid()
    model, cfg = _model()
    pose = (5.0, 3.0, 0.0)
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    world = g.occupied.copy()
    # a 0.6 m box 2 m ahead of the robot, 4 m from the far wall: not in the map
    world[98:110, 150:162] = True  # x 6.5..7.1, y 2.9..3.5
    ranges = _cast(world, pose, angles, g.origin, g.resolution)
    clean = _cast(g.occupied, pose, angles, g.origin, g.resolution)
    blocked = ranges < clean - 0.5
    assert 5 < blocked.sum() < 30
    e = beam_endpoints(ranges, angles, None, cfg)
    rng = np.random.default_rng(1)
    n = 2000
    p = np.array(pose)[:, None] + rng.standard_normal((3, n)) * np.array([0.05, 0.05, 0.02])[:, None]
    w = np.full(n, 1 / n)
    support = model.beam_support(p, w, e)
    # long beams (7.5 m) move 0.15 m with 0.02 rad of heading noise: support >= 0.85 (measured 0.866)
    assert (support[blocked] < 0.3).all() and (support[~blocked] > 0.8).all()
    kept, skipped = _skip_beams(model, p, w, e)
    assert skipped == blocked.sum() and kept.shape[1] == 181 - skipped
    np.testing.assert_array_equal(kept, e[:, ~blocked])


def test_too_many_unexplained_beams_means_the_filter_is_wrong_so_all_are_kept():
    model, cfg = _model(beam_skip_error_threshold=0.5)
    rng = np.random.default_rng(2)
    e = rng.uniform(-1.2, 1.2, (2, 100))  # a scan of a small room that is not where the particles are
    p = np.array([5.0, 3.0, 0.0])[:, None] + rng.standard_normal((3, 500)) * 0.02
    w = np.full(500, 1 / 500)
    assert (model.beam_support(p, w, e) <= 0.3).mean() >= 0.5
    kept, skipped = _skip_beams(model, p, w, e)
    assert skipped == 0 and kept.shape == e.shape


def test_filter_skips_beams_only_once_converged():
    from mcl.filter import ParticleFilter

    g = _grid()
    cfg = load_config(None, ["filter.particles=2000", "filter.kld=false", "filter.recovery=false",
                             "sensor.beam_skip=true", "sensor.max_beams=181"])
    pf = ParticleFilter(cfg, g)
    pose = (5.0, 3.0, 0.0)
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    world = g.occupied.copy()
    world[98:110, 150:162] = True
    ranges = _cast(world, pose, angles, g.origin, g.resolution)
    e = beam_endpoints(ranges, angles, None, cfg.sensor)
    pf.init_gaussian(pose, (1.0, 1.0, 0.3))  # spread 1 m > beam_skip_distance: not converged
    pf.estimate()
    assert not pf.converged
    info = pf.step(None, e)
    assert info.skipped_beams == 0
    pf.init_gaussian(pose, (0.05, 0.05, 0.02))
    pf.estimate()
    assert pf.converged
    info = pf.step(None, e)
    assert 5 < info.skipped_beams < 30
    # the skipped beams are the ones the unmapped box shortened (2 m ahead, the map's wall is 5.85 m ahead)
    assert info.skipped_endpoints.shape == (2, info.skipped_beams)
    assert (np.hypot(*info.skipped_endpoints) < 2.6).all()
    on = load_config(None, ["filter.particles=2000", "filter.kld=false", "filter.recovery=false",
                            "sensor.max_beams=181", "sensor.beam_skip=true"])
    pf2 = ParticleFilter(on, g)
    pf2.init_gaussian(pose, (0.05, 0.05, 0.02))
    pf2.estimate()
    assert pf2.step(None, e).skipped_beams == 22  # the same step with beam skipping on (rule short by default)
    off = load_config(None, ["filter.particles=2000", "filter.kld=false", "filter.recovery=false",
                             "sensor.max_beams=181", "sensor.beam_skip=false"])
    pf3 = ParticleFilter(off, g)
    pf3.init_gaussian(pose, (0.05, 0.05, 0.02))
    pf3.estimate()
    assert pf3.step(None, e).skipped_beams == 0  # beam_skip: false never skips


def test_segments_blocked_finds_mapped_obstacles_between_the_laser_and_the_endpoint():
    from mcl.kernels.raycast import segments_blocked

    g = _grid()  # pillar at x 2..3, y 4..5; walls at the map's edges (x -1..-0.85 and 10.85..11, ...)
    blocked = np.ascontiguousarray(g.occupied, dtype=np.uint8)
    # robot at (1, 4.5) facing +x, laser 0.2 m ahead of its centre; endpoints in the robot frame
    e = np.array([[0.7, 1.5, 2.5, -1.5, 12.0, 0.1],
                  [0.0, 0.0, 0.0, 0.0, 0.0, 3.0]])
    out = np.zeros(e.shape[1], dtype=np.bool_)
    segments_blocked(1.0, 4.5, 0.0, 0.2, 0.0, e, blocked, g.origin[0], g.origin[1], g.resolution, out)
    # ends before the pillar; ends inside it; passes through it; ends 0.35 m short of the west wall (x = -0.85)
    # from a laser 0.2 m ahead; passes through the pillar and off the map; goes up (y 4.5 -> 7.5) in free space
    assert out.tolist() == [False, True, True, False, True, False]
    # the same segments seen from the robot turned by pi (laser at x = 0.8, pointing -x): x = 0.3 and x = -0.5
    # stop before the west wall, x = -1.5 crosses it, the fourth (x = 2.5) now ends in the pillar
    segments_blocked(1.0, 4.5, math.pi, 0.2, 0.0, e, blocked, g.origin[0], g.origin[1], g.resolution, out)
    assert out.tolist() == [False, False, True, True, True, False]


def test_short_rule_scores_readings_through_mapped_walls_that_amcl_rule_skips():
    # The particles sit 0.6 m east of the true pose (a wrong, converged cloud). Seen from them, the beams that
    # point east end 0.6 m beyond the east wall (through it), those that point west end 0.6 m before the west
    # wall: both are unexplained. An unmapped obstacle can only shorten a reading, so rule `short` keeps the
    # through-wall beams (they say the pose is wrong) and skips only the short ones; rule `amcl` skips all.
    g = _grid()
    true_pose = (5.0, 3.0, 0.0)
    angles = np.linspace(-math.pi, math.pi, 181, endpoint=False)
    ranges = _cast(g.occupied, true_pose, angles, g.origin, g.resolution)
    rng = np.random.default_rng(3)
    n = 1000
    p = np.array([5.6, 3.0, 0.0])[:, None] + rng.standard_normal((3, n)) * np.array([0.03, 0.03, 0.005])[:, None]
    w = np.full(n, 1 / n)
    east = np.abs(angles) < 0.2  # the east wall is 5.85 m away: these end 0.6 m beyond it
    west = np.abs(np.abs(angles) - math.pi) < 0.2  # the west wall: 0.6 m short of it (and clear of the pillar)
    res = {}
    for rule in ("amcl", "short"):
        model, cfg = _model(beam_skip_rule=rule, beam_skip_error_threshold=1.0)
        e = beam_endpoints(ranges, angles, None, cfg)
        support = model.beam_support(p, w, e)
        assert (support[east] < 0.3).all() and (support[west] < 0.3).all()
        kept, skipped = _skip_beams(model, p, w, e, pose=(5.6, 3.0, 0.0), laser_xy=(0.0, 0.0))
        kept_set = {tuple(np.round(c, 9)) for c in kept.T}
        res[rule] = (np.array([tuple(np.round(c, 9)) in kept_set for c in e.T]), skipped)
    amcl_kept, short_kept = res["amcl"][0], res["short"][0]
    assert not amcl_kept[east].any() and not amcl_kept[west].any()
    assert short_kept[east].all() and not short_kept[west].any()
    assert res["short"][1] < res["amcl"][1]
    # without a pose the short rule cannot tell and falls back to AMCL's
    model, cfg = _model(beam_skip_rule="short", beam_skip_error_threshold=1.0)
    e = beam_endpoints(ranges, angles, None, cfg)
    assert _skip_beams(model, p, w, e)[1] == res["amcl"][1]


def test_every_beam_skip_key_is_documented_in_default_yaml():
    text = (PROJECT_ROOT / "configs" / "default.yaml").read_text()
    for key in ("beam_skip", "beam_skip_distance", "beam_skip_threshold", "beam_skip_error_threshold",
                "beam_skip_rule", "estimate", "cluster_size", "cluster_angle", "max_odom_step", "respread_std"):
        assert re.search(rf"^\s+{key}:[^#\n]+#", text, re.M), key
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml")
    # off by default (it hid the beams that correct an along-corridor lag on infinite_corridor); rule short when on
    assert cfg.sensor.beam_skip is False and cfg.sensor.beam_skip_rule == "short"
    assert cfg.sensor == SensorConfig()  # default.yaml shows the dataclass defaults


def test_simulated_unmapped_obstacles_only_shorten_beams_and_leave_map_and_truth(tmp_path):
    from mcl.datasets.carmen import read_carmen
    from mcl.simulate import simulate

    for n in (0, 12):
        simulate(tmp_path / str(n), seed=3, duration=15.0, dynamic_obstacles=n,
                 range_sigma=0.0, p_short=0.0, p_max=0.0)
    for f in ("map.pgm", "map.yaml", "truth.tum"):
        assert (tmp_path / "0" / f).read_bytes() == (tmp_path / "12" / f).read_bytes(), f
    a = np.array([s.ranges for s in read_carmen(tmp_path / "0" / "log.clf").scans])
    b = np.array([s.ranges for s in read_carmen(tmp_path / "12" / "log.clf").scans])
    assert (b <= a + 1e-3).all()  # obstacles only block
    frac = (b < a - 0.05).mean()
    assert 0.005 < frac < 0.5, frac
    # people move: the set of blocked beams changes between scans in the same place
    assert len({tuple(np.flatnonzero(r)) for r in (b < a - 0.05)}) > 10


@pytest.mark.slow
def test_beam_skipping_keeps_augmented_mcl_on_track_through_unmapped_clutter(tmp_path):
    # A 60 s world (seed 0) with 30 unmapped obstacles (boxes near the path, walking people), tracked from the
    # true start pose with augmented MCL (the default before the corpus chose `lost`) and a fixed 2,000 particles. Without beam skipping the
    # cluttered scans fit poses up to 1 m off better than the true one, the likelihood drops, augmented MCL
    # injects, and an injected pose that fits the clutter takes the weight: lost (measured 4.2 m ATE RMSE).
    # With the default beam skipping (rule short, 0.25 m / 0.5) it keeps track (measured 0.130 m, max 0.41 m,
    # in scripts/dynamic_obstacles.py). Bounds: 0.25 m RMSE and 0.5 m max for on, > 1 m for off.
    import warnings

    import yaml

    from mcl.runner import run
    from mcl.simulate import simulate

    d = tmp_path / "sim"
    simulate(d, seed=0, duration=60.0, dynamic_obstacles=30)
    start = yaml.safe_load((d / "sim.yaml").read_text())["start_pose"]
    res = {}
    for skip in (False, True):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
            f"map={d / 'map.yaml'}", f"log={d / 'log.clf'}", f"truth={d / 'truth.tum'}", "rerun.mode=off",
            "filter.global_localization=false", f"filter.initial_pose={start}",
            "filter.initial_std=[0.05,0.05,0.05]", "filter.particles=2000", f"sensor.beam_skip={str(skip).lower()}",
            "filter.recovery=augmented", "sensor.unmapped_skip=false"])  # beam skipping alone
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res[skip] = run(cfg, tmp_path / f"run{skip}", progress=False, echo=lambda *_: None)
    on, off = res[True], res[False]
    assert off["skipped_beams"] == 0 and on["skipped_beams"] > 2 * on["updates"]
    assert on["eval"]["ate_rmse"] < 0.25 and on["eval"]["ate_max"] < 0.5, on["eval"]
    assert off["eval"]["ate_rmse"] > 1.0, off["eval"]


def test_support_from_a_subsample_above_the_cap_is_within_its_standard_error():
    from mcl.sensors import SKIP_SUPPORT_PARTICLES

    g = _grid()
    model, cfg = _model()
    rng = np.random.default_rng(6)
    n = 10 * SKIP_SUPPORT_PARTICLES
    p = np.vstack([rng.uniform(0, 10, n), rng.uniform(-1, 7, n), rng.uniform(-math.pi, math.pi, n)])
    w = rng.random(n)
    w /= w.sum()
    e = rng.uniform(-3, 3, (2, 40))
    full = _support_numpy(p, w, e, np.asarray(g.distance, dtype=np.float32), -1.0, -2.0, 0.05, 0.5)
    sub = model.beam_support(p, w, e)
    # every 10th particle: a 500-sample weighted proportion, standard error <= 0.5 * sqrt(1.33 / 500) = 0.026
    # (the weights' second moment adds a third); 4 standard errors
    assert np.abs(sub - full).max() < 0.105
    assert 0.03 < full.min() and full.max() < 0.97  # proportions away from 0 and 1 (measured 0.044..0.14)


def test_recording_shows_exactly_the_skipped_beams(tmp_path):
    # A 20 s world with 20 unmapped obstacles, tracked from the start with the default config and a recording:
    # world/scan/skipped holds, step by step, as many points as the summary counts skipped beams.
    import warnings

    import yaml
    from rerun.chunk import RrdReader

    from mcl.runner import run
    from mcl.simulate import simulate

    d = tmp_path / "sim"
    simulate(d, seed=1, duration=20.0, dynamic_obstacles=20)
    start = yaml.safe_load((d / "sim.yaml").read_text())["start_pose"]
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={d / 'map.yaml'}", f"log={d / 'log.clf'}", f"truth={d / 'truth.tum'}", "rerun.particles_max=10",
        "filter.global_localization=false", f"filter.initial_pose={start}", "filter.initial_std=[0.05,0.05,0.05]",
        "filter.particles=1000", "sensor.beam_skip=true"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = run(cfg, tmp_path / "out", progress=False, echo=lambda *_: None)
    shown = 0
    for c in RrdReader(tmp_path / "out" / "recording.rrd").stream().to_chunks():
        if c.entity_path == "/world/scan/skipped" and not c.is_static:
            col = c.to_record_batch().column("Points2D:positions").to_pylist()
            shown += sum(len(v) for v in col if v is not None)
    assert s["skipped_beams"] > 20 and shown == s["skipped_beams"]
