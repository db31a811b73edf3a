"""Landmarks: map loader, LANDMARK lines, the Table 6.4 model against its closed form and samples, the
Table 6.5 pose sampler, the simulator's landmarks, and landmark-only tracking / global localization."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from mcl.config import LandmarkConfig, load_config
from mcl.datasets.carmen import Landmarks, read_carmen
from mcl.errors import ConfigError, DataError
from mcl.landmarks import (
    LandmarkMap,
    LandmarkModel,
    landmark_log_likelihood_numpy,
    load_landmarks,
    sample_observation,
    sample_poses_from_landmark,
    save_landmarks,
)


def lmap(ids=(1, 2, 5), xy=((0.0, 4.0, -3.0), (0.0, 1.0, 2.5))):
    return LandmarkMap(np.array(ids, dtype=np.int64), np.array(xy, dtype=np.float64), np.full(len(ids), np.nan))


def obs(ids, ranges, bearings, t=0.0):
    return Landmarks(t, np.array(ids, dtype=np.int64), np.array(ranges, float), np.array(bearings, float))


# ----------------------------------------------------------------------------- map loader


def test_map_roundtrip_and_lookup(tmp_path):
    p = tmp_path / "lm.yaml"
    save_landmarks(p, [3, 9, 4], [[1.0, 2.5, -1.25], [0.5, 7.0, 3.0]])
    m = load_landmarks(p)
    assert m.ids.tolist() == [3, 9, 4]
    np.testing.assert_allclose(m.xy, [[1.0, 2.5, -1.25], [0.5, 7.0, 3.0]])
    assert m.index_of([4, 3, 7, 9]).tolist() == [2, 0, -1, 1]
    (tmp_path / "s.yaml").write_text("landmarks:\n  - {id: 0, x: 1, y: 2, signature: 0.5}\n")
    assert load_landmarks(tmp_path / "s.yaml").signatures.tolist() == [0.5]


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("landmarks:\n  - {id: 1, x: 1.0}\n", "landmarks[0].y: missing"),
        ("landmarks:\n  - {id: 1, x: 1, y: 2}\n  - {id: 1, x: 3, y: 4}\n", "landmarks[1].id: duplicate id 1"),
        ("landmarks:\n  - {id: -2, x: 1, y: 2}\n", "landmarks[0].id: expected an integer >= 0"),
        ("landmarks:\n  - {id: 1.5, x: 1, y: 2}\n", "landmarks[0].id: expected an integer"),
        ("landmarks:\n  - {id: 1, x: abc, y: 2}\n", "landmarks[0].x: expected a number"),
        ("landmarks:\n  - {id: 1, x: .nan, y: 2}\n", "landmarks[0].x: expected a finite number"),
        ("landmarks:\n  - {id: 1, x: 1, y: 2, colour: red}\n", "landmarks[0].colour: unknown key"),
        ("landmarks:\n  - [1, 2, 3]\n", "landmarks[0]: expected a mapping"),
        ("landmarks: {id: 1}\n", "landmarks: expected a list"),
        ("landmarks: []\n", "landmarks: the list is empty"),
        ("beacons: []\n", "landmarks: missing"),
        ("landmarks: []\nextra: 1\n", "extra: unknown key"),
        ("landmarks: [\n", "lm.yaml:"),
    ],
)
def test_map_loader_errors_name_file_and_key(tmp_path, text, fragment):
    p = tmp_path / "lm.yaml"
    p.write_text(text)
    with pytest.raises(DataError) as e:
        load_landmarks(p)
    assert str(p) in str(e.value) and fragment in str(e.value)


def test_map_loader_missing_file(tmp_path):
    with pytest.raises(DataError, match="nope.yaml: cannot read"):
        load_landmarks(tmp_path / "nope.yaml")


# ----------------------------------------------------------------------------- LANDMARK lines

ODOM = "ODOM 0 0 0 0 0 0 0.0 h 0.0\nODOM 2 0 1 0 0 0 2.0 h 2.0\n"


def test_landmark_lines_parse_with_interpolated_odometry(tmp_path):
    p = tmp_path / "l.clf"
    p.write_text(ODOM + "LANDMARK 2 3 1.5 0.25 7 2.0 -1.0 1.0 h 1.0\nLANDMARK 0 1.5 h 1.5\n")
    log = read_carmen(p)  # no laser: a landmark-only log is valid
    assert log.scans == [] and len(log.landmarks) == 2
    a, b = log.landmarks
    assert a.t == 1.0 and a.line == 3 and a.ids.tolist() == [3, 7]
    np.testing.assert_allclose(a.ranges, [1.5, 2.0])
    np.testing.assert_allclose(a.bearings, [0.25, -1.0])
    np.testing.assert_allclose(a.odom, [1.0, 0.0, 0.5])
    assert b.ids.size == 0 and b.line == 4


@pytest.mark.parametrize(
    "line, fragment",
    [
        ("LANDMARK 2 3 1.5 0.25 1.0 h 1.0", "LANDMARK: expected 2 (id range bearing) triples"),
        ("LANDMARK x 1.0 h 1.0", "LANDMARK: observation count is not an integer"),
        ("LANDMARK -1 1.0 h 1.0", "LANDMARK: negative observation count"),
        ("LANDMARK 1 a 1.5 0.2 1.0 h 1.0", "LANDMARK: landmark id is not an integer"),
        ("LANDMARK 1 3 -1.5 0.2 1.0 h 1.0", "LANDMARK: negative range"),
        ("LANDMARK 1 3 nan 0.2 1.0 h 1.0", "LANDMARK: non-finite range or bearing"),
        ("LANDMARK 1 3 1.5 zz 1.0 h 1.0", "LANDMARK: non-numeric range/bearing"),
        ("LANDMARK", "LANDMARK: missing observation count"),
    ],
)
def test_malformed_landmark_lines_name_file_and_line(tmp_path, line, fragment):
    p = tmp_path / "bad.clf"
    p.write_text(ODOM + line + "\n")
    with pytest.raises(DataError) as e:
        read_carmen(p)
    assert f"{p}:3: {fragment}" in str(e.value)


def test_landmark_lines_need_odometry(tmp_path):
    p = tmp_path / "l.clf"
    p.write_text("LANDMARK 1 3 1.5 0.25 1.0 h 1.0\n")
    with pytest.raises(DataError, match=r"l.clf:1: LANDMARK: no ODOM"):
        read_carmen(p)


# ----------------------------------------------------------------------------- the model

CFG = LandmarkConfig(sigma_range=0.2, sigma_bearing=0.1, z_det=0.9, z_fp=0.1, range_max=10.0)


def test_kernel_matches_the_numpy_oracle_and_the_closed_form():
    rng = np.random.default_rng(0)
    m = lmap()
    model = LandmarkModel(m, CFG)
    z = obs([1, 5, 99, 2], [2.0, 3.5, 1.0, 4.4], [3.1, -3.1, 0.0, 0.4])  # id 99 is not in the map: dropped
    prep = model.prepare(z)
    assert prep.shape == (4, 3)
    p = np.vstack([rng.uniform(-5, 5, (2, 3000)), rng.uniform(-math.pi, math.pi, 3000)])
    got = model.log_likelihood(p, prep)
    ref = landmark_log_likelihood_numpy(p, *prep, 0.2, 0.1, 0.9, model.c_fp)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)
    # closed form for one particle, written out with scipy's normal density
    x, y, th = p[:, 7]
    total = 0.0
    for i, d, phi in [(1, 2.0, 3.1), (5, 3.5, -3.1), (2, 4.4, 0.4)]:
        mx, my = m.xy[:, m.index_of([i])[0]]
        eb = (phi - (math.atan2(my - y, mx - x) - th) + math.pi) % (2 * math.pi) - math.pi
        pdet = stats.norm.pdf(d - math.hypot(mx - x, my - y), 0, 0.2) * stats.norm.pdf(eb, 0, 0.1)
        total += math.log(0.9 * pdet + 0.1 / (10.0 * 2 * math.pi))
    assert got[7] == pytest.approx(total, rel=1e-10)
    # no known id: no information
    assert model.prepare(obs([42], [1.0], [0.0])) is None
    np.testing.assert_array_equal(model.log_likelihood(p, None), 0.0)


def test_density_integrates_to_one():
    # z_det + z_fp = 1: the mixture integrates to 1 over [0, range_max] x [-pi, pi) (within 1 %). The closed
    # form is integrated on a 2001 x 1001 grid; the model equals it on every 50th x 25th grid point.
    model = LandmarkModel(lmap(), CFG)
    pose = np.array([[1.0], [-0.5], [0.3]])
    mx, my = 4.0, 1.0
    d = np.linspace(0.0, 10.0, 2001)
    phi = np.linspace(-math.pi, math.pi, 1001)
    dd, pp = np.meshgrid(d, phi, indexing="ij")
    dhat = math.hypot(mx - 1.0, my + 0.5)
    phat = math.atan2(my + 0.5, mx - 1.0) - 0.3
    eb = (pp - phat + math.pi) % (2 * math.pi) - math.pi
    dens = 0.9 * stats.norm.pdf(dd - dhat, 0, 0.2) * stats.norm.pdf(eb, 0, 0.1) + 0.1 / (10 * 2 * math.pi)
    for a in range(0, d.size, 50):
        for b in range(0, phi.size, 25):
            col = np.array([[mx], [my], [d[a]], [phi[b]]])
            assert model.log_likelihood(pose, col)[0] == pytest.approx(math.log(dens[a, b]), rel=1e-10)
    integral = np.trapezoid(np.trapezoid(dens, phi, axis=1), d)
    assert integral == pytest.approx(1.0, abs=0.01)


def test_samples_agree_with_the_density_chi_square():
    # 10^6 draws of the generative model (detection with prob z_det: Gaussian range and bearing around the
    # truth; else a false positive uniform over [0, range_max] x [-pi, pi)); each marginal's histogram against
    # the closed form integrated over the same bins. Reject at p < 1e-3 (fixed seed).
    rng = np.random.default_rng(12)
    n = 1_000_000
    pose = (1.0, -0.5, 0.3)
    m_xy = np.array([[4.0], [1.0]])
    r, b = sample_observation(pose, m_xy, 0.2, 0.1, rng, size=n)
    r, b = r[:, 0], b[:, 0]
    fp = rng.random(n) >= 0.9
    r[fp] = rng.uniform(0.0, 10.0, fp.sum())
    b[fp] = rng.uniform(-math.pi, math.pi, fp.sum())
    dhat = math.hypot(3.0, 1.5)
    phat = math.atan2(1.5, 3.0) - 0.3
    edges_r = np.linspace(0.0, 10.0, 101)
    cdf_r = 0.9 * stats.norm.cdf(edges_r, dhat, 0.2) + 0.1 * edges_r / 10.0
    edges_b = np.linspace(-math.pi, math.pi, 101)
    cdf_b = 0.9 * stats.norm.cdf(edges_b, phat, 0.1) + 0.1 * (edges_b + math.pi) / (2 * math.pi)
    for x, edges, cdf in ((r, edges_r, cdf_r), (b, edges_b, cdf_b)):
        obs_counts, _ = np.histogram(x, edges)
        exp_counts = n * np.diff(cdf)
        keep = exp_counts >= 5
        chi2 = float((((obs_counts - exp_counts) ** 2 / exp_counts)[keep]).sum())
        p = stats.chi2.sf(chi2, keep.sum() - 1)
        assert p > 1e-3, (chi2, p)


# ----------------------------------------------------------------------------- the pose sampler


def test_sampler_without_noise_reproduces_the_observation_exactly():
    m = lmap()
    rng = np.random.default_rng(3)
    z = obs([2, 5, 77], [3.0, 1.5, 2.0], [0.7, -2.9, 0.1])  # id 77 unknown: not used
    exact = SimpleNamespace(sigma_range=0.0, sigma_bearing=0.0)
    p = sample_poses_from_landmark(z, m, 1000, rng, exact)
    which = np.arange(1000) % 2  # shared evenly over the two known observations
    mx, my = m.xy[0, [1, 2]][which], m.xy[1, [1, 2]][which]
    np.testing.assert_allclose(np.hypot(mx - p[0], my - p[1]), np.array([3.0, 1.5])[which], atol=1e-12)
    bearing = np.arctan2(my - p[1], mx - p[0]) - p[2]
    err = (bearing - np.array([0.7, -2.9])[which] + math.pi) % (2 * math.pi) - math.pi
    np.testing.assert_allclose(err, 0.0, atol=1e-12)
    # a single (id, range, bearing) triple works too; an unknown id raises
    q = sample_poses_from_landmark((1, 2.0, 0.0), m, 10, rng, exact)
    np.testing.assert_allclose(np.hypot(q[0], q[1]), 2.0, atol=1e-12)
    with pytest.raises(ValueError, match="no observation with an id in the landmark map"):
        sample_poses_from_landmark((9, 1.0, 0.0), m, 10, rng, exact)


def test_sampler_noise_and_ring_are_distributed_as_stated():
    # gamma uniform on the circle; the sampled range is d + N(0, sigma_range^2): KS tests at p > 1e-3
    m = lmap()
    rng = np.random.default_rng(5)
    cfg = SimpleNamespace(sigma_range=0.3, sigma_bearing=0.05)
    p = sample_poses_from_landmark((2, 3.0, 0.4), m, 20000, rng, cfg)
    dx, dy = p[0] - 4.0, p[1] - 1.0
    assert stats.kstest((np.hypot(dx, dy) - 3.0) / 0.3, "norm").pvalue > 1e-3
    gamma = np.arctan2(dy, dx)
    assert stats.kstest(gamma, stats.uniform(-math.pi, 2 * math.pi).cdf).pvalue > 1e-3
    phi_err = ((np.arctan2(-dy, -dx) - p[2]) - 0.4 + math.pi) % (2 * math.pi) - math.pi
    assert stats.kstest(phi_err / 0.05, "norm").pvalue > 1e-3


# ----------------------------------------------------------------------------- config


def test_config_landmarks_section(tmp_path):
    (tmp_path / "lm.yaml").write_text("landmarks:\n  - {id: 1, x: 0, y: 0}\n")
    p = tmp_path / "c.yaml"
    p.write_text("sensor:\n  use: false\nlandmarks:\n  use: true\n  map: lm.yaml\n")
    cfg = load_config(p)
    assert cfg.landmarks.map == str((tmp_path / "lm.yaml").resolve()) and not cfg.sensor.use
    with pytest.raises(ConfigError, match="landmarks.map: landmarks.use is true but no landmark map"):
        load_config(None, ["landmarks.use=true"])
    with pytest.raises(ConfigError, match="sensor.use: false needs landmarks.use: true or planes.use: true"):
        load_config(None, ["sensor.use=false"])
    with pytest.raises(ConfigError, match="landmarks.sigma_range"):
        load_config(None, ["landmarks.sigma_range=0"])


def test_updates_merge_scans_and_landmarks_in_time_order():
    from mcl.runner import _updates

    scans = [SimpleNamespace(t=t) for t in (0.0, 0.2, 0.4)]
    marks = [SimpleNamespace(t=t) for t in (0.2, 0.3, 0.40005)]
    u = _updates(scans, marks)
    assert [(a.t, None if b is None else b.t) for a, b in u] == [(0.0, None), (0.2, 0.2), (0.3, 0.3), (0.4, 0.40005)]
    assert u[2][0] is u[2][1]  # a landmark-only update
    assert [a.t for a, _ in _updates([], marks)] == [0.2, 0.3, 0.40005]


# ----------------------------------------------------------------------------- simulation and end to end


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    from mcl.simulate import simulate

    out = tmp_path_factory.mktemp("lmsim")
    simulate(out, seed=3, duration=60.0, landmarks=20)
    return out


def test_simulated_landmarks_leave_the_rest_unchanged(sim, tmp_path):
    from mcl.simulate import simulate

    simulate(tmp_path, seed=3, duration=60.0)
    for name in ("map.pgm", "map.yaml", "truth.tum"):
        assert (tmp_path / name).read_bytes() == (sim / name).read_bytes(), name
    with_lm = [ln for ln in (sim / "log.clf").read_text().splitlines() if not ln.startswith("LANDMARK")]
    assert with_lm == (tmp_path / "log.clf").read_text().splitlines()
    assert not (tmp_path / "landmarks.yaml").exists()
    log = read_carmen(sim / "log.clf")
    assert len(log.landmarks) == len(log.scans) and all(m.t == s.t for m, s in zip(log.landmarks, log.scans))
    assert len(load_landmarks(sim / "landmarks.yaml")) == 20


def test_noise_free_landmark_observations_are_exact_and_in_sight(tmp_path):
    from mcl.kernels.raycast import cast_ray
    from mcl.maps import load_map
    from mcl.simulate import simulate
    from mcl.trajectory import read_tum

    simulate(tmp_path, seed=3, duration=20.0, landmarks=20, landmark_sigma=(0.0, 0.0), landmark_miss=0.0,
             landmark_fp=0.0)
    m = load_landmarks(tmp_path / "landmarks.yaml")
    grid = load_map(tmp_path / "map.yaml")
    blocked = np.ascontiguousarray(grid.occupied)
    t, truth = read_tum(tmp_path / "truth.tum")
    log = read_carmen(tmp_path / "log.clf")
    n_seen = 0
    for k, rec in enumerate(log.landmarks):
        x, y, th = truth[:, k]
        d = np.hypot(m.xy[0] - x, m.xy[1] - y)
        ang = np.arctan2(m.xy[1] - y, m.xy[0] - x)
        hits = np.array([cast_ray(x, y, a, blocked, grid.origin[0], grid.origin[1], grid.resolution, 8.0) for a in ang])
        visible = set(m.ids[(d <= 8.0) & (hits >= d)].tolist())
        assert set(rec.ids.tolist()) == visible, k
        c = m.index_of(rec.ids)
        np.testing.assert_allclose(rec.ranges, d[c], atol=1e-4)  # 4 decimals in the log
        err = (rec.bearings - (ang[c] - th) + math.pi) % (2 * math.pi) - math.pi
        np.testing.assert_allclose(err, 0.0, atol=2e-5)
        n_seen += rec.ids.size
    assert n_seen > len(log.landmarks)  # more than one landmark a scan on average


def _run(sim, tmp_path, *overrides, rerun="off"):
    from mcl.runner import run

    import yaml

    sp = yaml.safe_load((sim / "sim.yaml").read_text())["start_pose"]
    cfg = load_config(None, [
        f"map={sim / 'map.yaml'}", f"log={sim / 'log.clf'}", f"truth={sim / 'truth.tum'}",
        "filter.particles=2000", f"filter.initial_pose={sp}", "filter.global_localization=false",
        "landmarks.use=true", f"landmarks.map={sim / 'landmarks.yaml'}", f"rerun.mode={rerun}", "seed=4",
        *overrides,
    ])
    return run(cfg, tmp_path / "out", progress=False, echo=lambda m: None)


def test_landmark_only_tracking_within_15_cm(sim, tmp_path):
    s = _run(sim, tmp_path, "sensor.use=false", rerun="save")
    assert s["scans"] == 0 and s["landmark_lines"] == 301 and s["updates"] > 250
    assert s["eval"]["ate_rmse"] < 0.15, s["eval"]
    from rerun.chunk import RrdReader

    static, per_step = set(), set()
    for c in RrdReader(tmp_path / "out" / "recording.rrd").stream().to_chunks():
        (static if c.is_static else per_step).add(c.entity_path)
    assert "/world/landmarks" in static and "/world/landmarks/observed" in per_step
    assert "/world/landmarks" not in per_step and "/world/scan" not in per_step


def test_landmark_only_global_localization_converges(sim, tmp_path):
    s = _run(sim, tmp_path, "sensor.use=false", "filter.global_localization=true", "filter.particles=5000")
    ev = s["eval"]
    assert s["mode"] == "global"
    assert ev["convergence_time"] is not None and ev["convergence_time"] < 20.0, ev


def test_laser_and_landmarks_fused(sim, tmp_path):
    s = _run(sim, tmp_path)
    assert s["scans"] == 301 and s["updates"] > 250
    assert s["eval"]["ate_rmse"] < 0.15, s["eval"]


def test_a_late_landmark_does_not_redraw_a_cloud_the_laser_has_localized(tmp_path):
    # Global localization with the laser and landmarks: the cloud was drawn again from the first LANDMARK line with
    # an observation, however late; here the laser settles the search at the first scan and that line (a false
    # positive, which the model allows for) put the set metres off: ATE 2.53 m, max 15.9 m, 7 re-seeds. Now the
    # landmarks seed the particles only while the search is under way: 0.052 m, max 0.09 m (bound 0.5 m).
    from mcl.config import PROJECT_ROOT, load_config
    from mcl.runner import run
    from mcl.simulate import simulate

    simulate(tmp_path / "w", kind="office", seed=3, duration=15.0, landmarks=8)
    w = tmp_path / "w"
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={w / 'map.yaml'}", f"log={w / 'log.clf'}", f"truth={w / 'truth.tum'}", "rerun.mode=off",
        "landmarks.use=true", f"landmarks.map={w / 'landmarks.yaml'}"])
    s = run(cfg, tmp_path / "out", progress=False, echo=lambda *a: None)
    assert s["mode"] == "global" and s["eval"]["ate_max"] < 0.5, s["eval"]


def test_a_landmark_only_global_run_is_not_called_lost_for_want_of_scans(tmp_path):
    # With no laser (sensor.use: false) the quality signal has no evidence, and a global start was marked lost for
    # good: every update lost, 125 re-seeds, 200,000 particles held, ATE 0.219 m (19 s) on a 30 s world where
    # tracking scores 0.024 m (0.025 m now). Here, 15 s and 30 landmarks: 0.46 m before; now under 0.1 m, no re-seed.
    from mcl.config import PROJECT_ROOT, load_config
    from mcl.runner import run
    from mcl.simulate import simulate

    w = tmp_path / "w"
    simulate(w, kind="office", seed=3, duration=15.0, landmarks=30)
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={w / 'map.yaml'}", f"log={w / 'log.clf'}", f"truth={w / 'truth.tum'}", "rerun.mode=off",
        "landmarks.use=true", f"landmarks.map={w / 'landmarks.yaml'}", "sensor.use=false"])
    s = run(cfg, tmp_path / "out", progress=False, echo=lambda *a: None)
    assert s["mode"] == "global" and s["eval"]["ate_rmse"] < 0.1, s["eval"]
    assert s["reseeds"] == 0
    assert s["text"].startswith(f"Localized {s['updates']} updates (global,"), s["text"]  # was "of 0 scans"
    # every predicted particle takes one try or more; the first update predicts nothing (it said 0.99 tries)
    assert s["mean_tries"] >= 1.0 and s["mean_tries"] < 1.5, s["mean_tries"]


def test_a_landmark_map_of_other_ids_or_off_the_map_is_said_and_the_start_stays_on_the_map(sim, tmp_path):
    # An audit's landmark maps: every id +100 ran as odometry alone (5.2 m off) without a word; one landmark mistyped
    # at (500, 500) drew the global start's particles there and the estimate began 700 m off a 20 m map. Now both
    # are warned of, and a landmark seed's poses the map never allows are drawn uniform over free space instead.
    import yaml

    from mcl.runner import run

    lm = yaml.safe_load((sim / "landmarks.yaml").read_text())

    def go(name, items):
        (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump({"landmarks": items}))
        said: list = []
        cfg = load_config(None, [f"map={sim / 'map.yaml'}", f"log={sim / 'log.clf'}", f"truth={sim / 'truth.tum'}",
                                 "landmarks.use=true", f"landmarks.map={tmp_path / f'{name}.yaml'}", "sensor.use=false",
                                 "rerun.mode=off", "filter.particles=2000"])
        s = run(cfg, tmp_path / name, progress=False, echo=said.append)
        return s, said

    _, said = go("other", [{**d, "id": d["id"] + 100} for d in lm["landmarks"]])
    assert sum("the landmarks correct nothing" in m for m in said) == 1, said
    moved = [dict(d) for d in lm["landmarks"]]
    moved[6].update(x=500.0, y=500.0)
    s, said = go("moved", moved)
    assert sum("landmark(s) off the map (id" in m for m in said) == 1, said
    from mcl.trajectory import read_tum

    _, p = read_tum(tmp_path / "moved" / "trajectory.tum")
    assert np.abs(p[:2]).max() < 100.0  # on (or by) a map of about 20 m, never 500 m off
    with pytest.raises(ConfigError, match=r"landmarks.z_det: 0 makes every pose score alike"):
        load_config(None, ["landmarks.use=true", "landmarks.map=x.yaml", "landmarks.z_det=0"])


def test_landmark_files_take_large_ids_and_exponents_as_one_line_or_numbers(tmp_path):
    (tmp_path / "big.yaml").write_text("landmarks:\n  - {id: 99999999999999999999999, x: 1, y: 2}\n")
    with pytest.raises(DataError, match=r"big\.yaml: landmarks\[0\]\.id: expected an integer up to"):
        load_landmarks(tmp_path / "big.yaml")
    (tmp_path / "exp.yaml").write_text("landmarks:\n  - {id: 3, x: 1e2, y: -2e1}\n")  # YAML 1.1 strings
    assert load_landmarks(tmp_path / "exp.yaml").xy[:, 0].tolist() == [100.0, -20.0]
    log = tmp_path / "l.clf"
    log.write_text("ODOM 0 0 0 0 0 0 0 h 0\nLANDMARK 1 99999999999999999999 1.0 0.1 1.0 h 1.0\n"
                   "ODOM 0 0 0 0 0 0 2 h 2\n")
    with pytest.raises(DataError, match=r"l\.clf:2: LANDMARK: landmark id 99999999999999999999 is too large"):
        read_carmen(log)
