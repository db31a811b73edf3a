"""World kinds of ``mcl simulate --kind``: drivable, deterministic, and each with the property it is made for;
the synthetic suite's entries are accepted by the simulator."""

import inspect
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from mcl.datasets.carmen import read_carmen
from mcl.errors import ConfigError
from mcl.kernels.raycast import cast_rays
from mcl.maps import load_map
from mcl.simulate import simulate
from mcl.trajectory import read_tum
from mcl.worlds import KIND_DEFAULTS, KINDS, _components, generate

ROOT = Path(__file__).resolve().parent.parent
NOISE_FREE = dict(range_sigma=0.0, p_short=0.0, p_max=0.0)
SEED = 11
DURATION = 14.0


def _world_rng(seed):
    """The world's random stream inside simulate(): the first child of SeedSequence(seed)."""
    return np.random.default_rng(np.random.SeedSequence(seed).spawn(4)[0])


@pytest.fixture(scope="module")
def sims(tmp_path_factory):
    """One noise-free 14 s drive per kind, kidnapped half way (the suite's kidnapped mode does that to every kind)."""
    out = {}
    for kind in KINDS:
        d = tmp_path_factory.mktemp(kind)
        out[kind] = (d, simulate(d, kind=kind, seed=SEED, duration=DURATION, kidnap_at=DURATION / 2, **NOISE_FREE))
    return out


@pytest.fixture(scope="module")
def worlds():
    return {kind: generate(kind, _world_rng(SEED)) for kind in KINDS}


@pytest.mark.parametrize("kind", KINDS)
def test_truth_stays_in_free_space_clear_of_walls(sims, worlds, kind):
    out, summary = sims[kind]
    w = worlds[kind]  # the saved map (test below); its distance field is ready
    params = yaml.safe_load((out / "sim.yaml").read_text())
    assert params["kind"] == kind and summary["kidnap"] is not None
    t, p = read_tum(out / "truth.tum")
    jump = int(np.argmax(np.hypot(np.diff(p[0]), np.diff(p[1]))))  # the kidnapping; no body between the poses
    s = np.linspace(0, 1, 6)[:-1]
    x = np.concatenate([(p[0, a:b - 1, None] * (1 - s) + p[0, a + 1:b, None] * s).ravel()
                        for a, b in ((0, jump + 1), (jump + 1, t.size))])
    y = np.concatenate([(p[1, a:b - 1, None] * (1 - s) + p[1, a + 1:b, None] * s).ravel()
                        for a, b in ((0, jump + 1), (jump + 1, t.size))])
    ix = np.floor((x - w.origin[0]) / w.resolution).astype(int)
    iy = np.floor((y - w.origin[1]) / w.resolution).astype(int)
    h, wd = w.occupancy.shape
    assert ((ix >= 0) & (ix < wd) & (iy >= 0) & (iy < h)).all()
    assert (w.occupancy[iy, ix] == 0).all()
    # distance is to occupied cell centres: the body is clear if it exceeds radius + half a cell
    assert w.distance[iy, ix].min() >= params["robot"]["radius"] + w.resolution / 2
    speed = KIND_DEFAULTS[kind]["speed"]
    assert params["robot"]["speed"] == speed
    # it really drove (two starts from rest, turns on the spot: about half the top speed on average)
    assert summary["path_length"] > 0.3 * speed * DURATION
    steps = np.hypot(np.diff(p[0]), np.diff(p[1]))
    assert np.sort(steps)[-2] <= speed * 0.2 + 1e-6  # one jump (the kidnapping), else never faster


@pytest.mark.parametrize("kind", KINDS)
def test_saved_map_is_the_generated_world_and_its_rooms_are_connected(sims, worlds, kind):
    w = worlds[kind]
    g = load_map(sims[kind][0] / "map.yaml")
    np.testing.assert_array_equal(g.occupied, w.occupancy == 100)
    np.testing.assert_array_equal(g.free, w.occupancy == 0)
    free = w.occupancy == 0
    _, n = _components(free)
    assert n == 1  # one free space: nothing walled off
    _, n = _components(w.reachable)
    assert n == 1
    # every room (zone of an open space) with room for the robot is reachable from every other one
    roomy = np.unique(w.room_id[free & (w.room_id >= 0) & (w.distance >= 0.6)])
    assert np.isin(roomy, np.unique(w.room_id[w.reachable])).all()
    assert roomy.size >= 8


@pytest.mark.parametrize("kind", KINDS)
def test_worlds_are_deterministic_for_a_seed(worlds, kind):
    a = worlds[kind]
    b = generate(kind, _world_rng(SEED))
    np.testing.assert_array_equal(a.occupancy, b.occupancy)
    np.testing.assert_array_equal(a.room_id, b.room_id)
    if kind == "large":  # a third large world costs seconds; the office-like kinds show seeds matter
        return
    c = generate(kind, _world_rng(SEED + 1))
    assert a.occupancy.shape != c.occupancy.shape or np.mean(a.occupancy != c.occupancy) > 0.01


def test_office_is_byte_identical_to_the_bundled_demo(tmp_path):
    demo = ROOT / "data" / "demo"
    params = yaml.safe_load((demo / "sim.yaml").read_text())
    simulate(tmp_path, seed=params["seed"], duration=params["duration"], range_max=params["laser"]["range_max"],
             kidnap_at=params["kidnap"]["t"], dynamic_obstacles=params["dynamic_obstacles"])
    for name in ("log.clf", "truth.tum", "map.pgm", "map.yaml"):
        assert (tmp_path / name).read_bytes() == (demo / name).read_bytes(), name


def test_rooms_are_identical_cell_for_cell(worlds):
    w = worlds["rooms"]
    blocks = w.meta["room_blocks"]
    n = w.meta["rooms_per_row"]
    assert len(blocks) == 2 * n and 5 <= n <= 8
    (y0, y1, x0, x1), _ = blocks[0]
    ref = w.occupancy[y0:y1, x0:x1]
    assert 0.5 < np.mean(ref == 0) < 0.95  # a room: mostly free, with walls and furniture
    for (y0, y1, x0, x1), turned in blocks:
        block = w.occupancy[y0:y1, x0:x1]
        np.testing.assert_array_equal(block, ref[::-1, ::-1] if turned else ref)
    # ... and the building as a whole is not: the lobby tells the ends apart
    occ = w.occupancy
    assert np.mean(occ != occ[::-1, ::-1]) > 0.01 and np.mean(occ != occ[:, ::-1]) > 0.01
    # every room is reachable: 2n rooms, the corridor, the lobby
    ids = np.unique(w.room_id[w.reachable])
    assert ids[ids >= 0].size == 2 * n + 2


def test_corridor_is_long_and_narrow(worlds, sims):
    g = load_map(sims["corridor"][0] / "map.yaml")
    free = g.free
    cols = np.flatnonzero(free.any(axis=0))
    length = (cols[-1] - cols[0] + 1) * g.resolution
    width = np.median(free.sum(axis=0)[cols]) * g.resolution  # most columns cross the main corridor only
    assert 60.0 <= length <= 150.0
    # the map's corridor is the generator's (drawn in 1.8-2.4 m), to within the rasterisation of its two walls
    assert width == pytest.approx(worlds["corridor"].meta["width"], abs=2 * g.resolution)
    assert length / width >= 24.0
    assert free.mean() < 0.25  # mostly unknown around it: few features
    assert length == pytest.approx(worlds["corridor"].meta["length"], abs=0.1)


def test_hall_is_open_most_beams_reach_max_range(sims):
    out, _ = sims["hall"]
    g = load_map(out / "map.yaml")
    assert 40.0 <= g.width * g.resolution - 2.0 <= 80.0 and 30.0 <= g.height * g.resolution - 2.0 <= 60.0
    r = np.vstack([s.ranges for s in read_carmen(out / "log.clf").scans])
    office = np.vstack([s.ranges for s in read_carmen(sims["office"][0] / "log.clf").scans])
    # noise-free logs: a reading of 12.0 is a ray that met nothing within range
    assert np.mean(r == 12.0) > 0.4
    assert np.mean(office == 12.0) < 0.1


def test_large_map_extent_and_rooms(worlds):
    w = worlds["large"]
    h, wd = w.occupancy.shape
    assert wd * w.resolution >= 150.0 and h * w.resolution >= 90.0
    assert w.meta["rooms"] >= 100


def test_clutter_unmapped_obstacles_are_seen_but_not_in_the_map(sims):
    out, _ = sims["clutter"]
    params = yaml.safe_load((out / "sim.yaml").read_text())
    assert params["dynamic_obstacles"] == KIND_DEFAULTS["clutter"]["dynamic_obstacles"] > 0
    assert params["unmapped_furniture"] == KIND_DEFAULTS["clutter"]["unmapped_furniture"] > 0
    g = load_map(out / "map.yaml")
    log = read_carmen(out / "log.clf")
    _, p = read_tum(out / "truth.tum")
    got = np.vstack([s.ranges for s in log.scans])
    ref = np.empty_like(got)
    cast_rays(np.ascontiguousarray(p), log.scans[0].angles, g.occupied, g.origin[0], g.origin[1], g.resolution,
              12.0, ref)
    # noise-free: every reading well short of the map's is an obstacle the map lacks
    assert np.mean(got < ref - 0.1) > 0.03
    assert np.mean(got > ref + 0.1) < 0.002  # and nothing in the map is missing from the world
    # the mapped furniture: the clutter map has more occupied cells than the office of the same seed
    office = load_map(sims["office"][0] / "map.yaml")
    assert g.occupied.sum() > 1.15 * office.occupied.sum()


def test_unmapped_furniture_changes_only_the_laser(tmp_path):
    a = simulate(tmp_path / "a", seed=3, duration=10.0, **NOISE_FREE)
    b = simulate(tmp_path / "b", seed=3, duration=10.0, unmapped_furniture=10, **NOISE_FREE)
    for name in ("map.pgm", "truth.tum"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    assert a["path_length"] == b["path_length"]
    ra = np.vstack([s.ranges for s in read_carmen(tmp_path / "a" / "log.clf").scans])
    rb = np.vstack([s.ranges for s in read_carmen(tmp_path / "b" / "log.clf").scans])
    assert np.all(rb <= ra + 1e-9) and np.mean(rb < ra - 0.1) > 0.005
    assert yaml.safe_load((tmp_path / "b" / "sim.yaml").read_text())["unmapped_furniture"] == 10


def test_unknown_kind_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="kind"):
        simulate(tmp_path, kind="castle")
    assert not (tmp_path / "log.clf").exists()


def test_cli_kind_fov_speed_options(tmp_path, capsys):
    import argparse

    from mcl.simulate import add_arguments, run_from_args

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args([str(tmp_path), "--kind", "corridor", "--seed", "2", "--duration", "5", "--fov", "240",
                              "--range-max", "5.6", "--beams", "241", "--speed", "1.2", "--unmapped-furniture", "3"])
    assert run_from_args(args) == 0
    params = yaml.safe_load((tmp_path / "sim.yaml").read_text())
    assert params["kind"] == "corridor" and params["robot"]["speed"] == 1.2 and params["unmapped_furniture"] == 3
    assert params["laser"]["fov"] == pytest.approx(math.radians(240))
    s = read_carmen(tmp_path / "log.clf").scans[0]
    assert s.kind == "ROBOTLASER1" and s.ranges.size == 241
    assert s.angle_min == pytest.approx(-math.radians(120), abs=1e-8)
    with pytest.raises(SystemExit):
        parser.parse_args([str(tmp_path), "--kind", "castle"])


# --------------------------------------------------------------------------
# suites/synthetic.yaml
# --------------------------------------------------------------------------

@pytest.fixture(scope="module")
def suite():
    return yaml.safe_load((ROOT / "suites" / "synthetic.yaml").read_text())


def test_suite_lists_at_least_40_worlds_across_the_kinds(suite):
    assert suite["name"] == "synthetic"
    assert suite["modes"] == ["tracking", "global", "kidnapped"]
    entries = suite["datasets"]
    assert len(entries) >= 40
    names = [e["name"] for e in entries]
    assert len(set(names)) == len(names)
    kinds = [e["simulate"]["kind"] for e in entries]
    # the kinds; the warehouse came later and has its own suite (test below)
    counts = {k: kinds.count(k) for k in KINDS if k != "warehouse"}
    assert min(counts.values()) >= 6 and max(counts.values()) <= 9, counts  # roughly even
    short = [e for e in entries if e["simulate"].get("range_max", 12.0) <= 6.0]
    assert 7 <= len(short) <= 12
    assert sum(1 for e in entries if e["simulate"].get("dynamic_obstacles") or
               e["simulate"].get("unmapped_furniture")) >= 6
    params = inspect.signature(simulate).parameters
    for e in entries:
        assert set(e) <= {"name", "simulate", "modes"}, e["name"]
        kw = e["simulate"]
        assert "kidnap_at" not in kw and "outdir" not in kw, e["name"]
        assert set(kw) <= set(params), (e["name"], set(kw) - set(params))
        assert 60 <= kw["duration"] <= 120, e["name"]
        assert set(e.get("modes", suite["modes"])) <= {"tracking", "global", "kidnapped"}, e["name"]
        inspect.signature(simulate).bind("out", **kw)


def test_the_warehouse_suite_is_warehouses_of_seeds_no_other_suite_uses():
    wh = yaml.safe_load((ROOT / "suites" / "warehouse.yaml").read_text())
    params = inspect.signature(simulate).parameters
    worlds = [(e["simulate"]["kind"], e["simulate"]["seed"]) for e in wh["datasets"]]
    assert len(set(worlds)) == len(worlds) >= 12 and {k for k, _ in worlds} == {"warehouse"}
    for e in wh["datasets"]:
        assert set(e["simulate"]) <= set(params) and "kidnap_at" not in e["simulate"], e["name"]
    seeds = {s for _, s in worlds}
    for other in (ROOT / "suites").glob("*.yaml"):
        if other.name != "warehouse.yaml":
            used = {e.get("simulate", {}).get("seed") for e in (yaml.safe_load(other.read_text()).get("datasets") or [])}
            assert not seeds & used, other.name


@pytest.mark.parametrize("kind", KINDS)
def test_suite_entries_generate(suite, kind, tmp_path):
    # one entry per kind (the one with the most options), shortened: its values pass the simulator's checks
    if kind == "warehouse":
        suite = yaml.safe_load((ROOT / "suites" / "warehouse.yaml").read_text())
    entries = [e for e in suite["datasets"] if e["simulate"]["kind"] == kind]
    e = max(entries, key=lambda e: len(e["simulate"]))
    kw = dict(e["simulate"], duration=6.0)
    s = simulate(tmp_path, **kw, kidnap_at=3.0)
    assert s["scans"] == 31 and s["kidnap"] is not None
    assert yaml.safe_load((tmp_path / "sim.yaml").read_text())["kind"] == kind


def test_the_held_out_suite_has_every_kind_and_no_world_of_the_tuning_suite(suite):
    # suites/heldout.yaml checks that a default chosen on suites/synthetic.yaml carries over to other worlds:
    # that holds only if no (kind, seed) of it is a world the defaults were chosen on.
    from mcl.suite import load_suite

    held = yaml.safe_load((ROOT / "suites" / "heldout.yaml").read_text())
    tuned = {(e["simulate"]["kind"], e["simulate"]["seed"]) for e in suite["datasets"]}
    worlds = [(e["simulate"]["kind"], e["simulate"]["seed"]) for e in held["datasets"]]
    assert len(set(worlds)) == len(worlds) >= 18
    assert not set(worlds) & tuned
    assert {k for k, _ in worlds} == set(KINDS) - {"warehouse"}  # the six (the warehouse: its own suite)
    assert held["lost_m"] == suite["lost_m"] and held["modes"] == suite["modes"]
    assert len(load_suite(ROOT / "suites" / "heldout.yaml").datasets) == len(worlds)


def test_warehouse_aisles_alike_and_the_robot_stays_out_of_the_racks(sims, worlds):
    """Rows of racks in bays full or empty, aisles a robot drives; it never drives into a rack (``keep_out``)."""
    w = worlds["warehouse"]
    racks = np.array(w.meta["racks"])
    assert len(racks) >= 8 and 2.8 <= w.meta["aisle"] <= 3.4
    assert 0.65 <= w.meta["full_bays"] / w.meta["bays"] <= 1.0  # drawn at 0.75-1 a world
    res, (ox, oy) = w.resolution, w.origin
    inside = np.zeros_like(w.reachable)
    for x0, y0, x1, y1 in racks:
        sl = (slice(int(np.ceil((y0 - oy) / res - 0.5)), int(np.floor((y1 - oy) / res - 0.5)) + 1),
              slice(int(np.ceil((x0 - ox) / res - 0.5)), int(np.floor((x1 - ox) / res - 0.5)) + 1))
        inside[sl] = True
    # a rack: pallets and uprights, and empty bays a beam passes into (free, but no place for the robot)
    assert 0.3 < np.mean(w.occupancy[inside] == 100) < 0.9
    assert np.mean(w.occupancy[inside] == 0) > 0.1
    assert not (w.reachable & inside).any()
    # every row is the same rack in x: the same count of occupied columns within each rack's own block
    cols = [int(np.count_nonzero((w.occupancy[int((y0 - oy) / res):int((y1 - oy) / res),
                                              int((x0 - ox) / res):int((x1 - ox) / res)] == 100).any(axis=0)))
            for x0, y0, x1, y1 in racks]
    assert max(cols) - min(cols) <= 1
    _, p = read_tum(sims["warehouse"][0] / "truth.tum")
    for x0, y0, x1, y1 in racks:
        assert not ((p[0] > x0) & (p[0] < x1) & (p[1] > y0) & (p[1] < y1)).any()
