"""Issue 13: the recording shows the filter at work. A short global-localization run on the bundled demo,
read back with rerun.chunk.RrdReader: the weight histogram, particles sized by weight, the likelihood-field
layer, the expected scan, and timings without the first update's compile time."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

rr = pytest.importorskip("rerun")
import pyarrow as pa  # noqa: E402  (a dependency of rerun-sdk)
from rerun.chunk import RrdReader  # noqa: E402

from mcl.config import PROJECT_ROOT, load_config  # noqa: E402
from mcl.maps import load_map  # noqa: E402
from mcl.runner import run  # noqa: E402
from mcl.sensors import field_distance  # noqa: E402
from mcl.viz import _HIST_BINS, _VIRIDIS, weight_histogram  # noqa: E402

DEMO = PROJECT_ROOT / "data" / "demo"
SCANS = 40  # the first 8 s of the demo: global localization under way


def _head(src: Path, dst: Path, scans: int) -> Path:
    """The log up to (not including) its scans-th FLASER line."""
    out, k = [], 0
    for line in src.read_text().splitlines(keepends=True):
        if line.startswith("FLASER"):
            if k == scans:
                break
            k += 1
        out.append(line)
    dst.write_text("".join(out))
    return dst


def _rows(chunks, entity: str, column: str, static: bool = False) -> tuple[list[int], list]:
    steps, values = [], []
    for c in chunks:
        if str(c.entity_path) != entity or c.is_static != static:
            continue
        b = c.to_record_batch()
        if column not in b.schema.names:
            continue
        if not static:
            steps += b.column("step").cast(pa.int64()).to_pylist()
        values += b.column(column).to_pylist()
    return steps, values


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("demo_rec")
    log = _head(DEMO / "log.clf", tmp / "head.clf", SCANS)
    # global_density 0: the demo's 100,000 particles over its 259 m2 are 386 per m2, above the default density of
    # 50, so `mcl run` scores the first scan on the particles themselves; 3,000 would be drawn from 5x as many
    # candidates, all with the same weight at step 0. recovery_probation 0: with 3,000 particles the search settles
    # on the first scan, on a place that scan contradicts, and the probation re-seeds at that very step, so step 0
    # would show the re-seed's equal weights (`mcl run`'s 100,000 settle one step later: step 0 is scored)
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"log={log}", "filter.particles=3000", "filter.min_particles=500", "rerun.particles_max=1000",
        "filter.global_density=0", "filter.recovery_probation=0"])
    s = run(cfg, tmp / "out", progress=False, echo=lambda *_: None)
    chunks = list(RrdReader(tmp / "out" / "recording.rrd").stream().to_chunks())
    return s, chunks


def test_weight_histogram_counts_every_particle_at_every_step(recording):
    s, chunks = recording
    steps, values = _rows(chunks, "/weights/histogram", "BarChart:values")
    assert sorted(steps) == list(range(s["updates"]))
    counts = {k: np.asarray(v[0]["buffer"], dtype=np.float64) for k, v in zip(steps, values)}
    p_steps, p_vals = _rows(chunks, "/stats/particles", "Scalars:scalars")
    n = {k: v[0] for k, v in zip(p_steps, p_vals)}
    for k, c in counts.items():
        assert c.size == _HIST_BINS and c.sum() == n[k], (k, c.sum(), n[k])
    # step 0: particles uniform over the map, the first scan tells them apart: the weights spread over the
    # bins (not all in the top one, as equal weights would be), over more than the 6-decade minimum span
    _, lefts = _rows(chunks, "/weights/histogram", "BarChart:abscissa")
    _, widths = _rows(chunks, "/weights/histogram", "BarChart:widths")
    assert counts[0][-1] < 0.5 * n[0] and np.count_nonzero(counts[0]) >= 5, counts[0]
    left = np.asarray(lefts[0][0]["buffer"], dtype=np.float64)
    assert left.min() < -6.0
    # a bar spans [abscissa, abscissa + width] in the viewer: the top bin ends at log10(w / w_max) = 0, not past it
    assert abs(left[-1] + float(np.ravel(widths[0])[-1])) < 1e-6, (left[-1], widths[0])


def test_each_panels_series_have_colours_of_their_own(recording):
    # The viewer's own picks gave two series of one panel near-identical hues (the error panel's position and heading
    # both magenta, quality's lost and match both tan): each series is given a colour, distinct within its panel
    from mcl.viz import stat_group

    _, chunks = recording
    paths = sorted({str(c.entity_path) for c in chunks if str(c.entity_path).startswith("/stats/")})
    assert len(paths) >= 8
    by_group: dict = {}
    for path in paths:
        _, colors = _rows(chunks, path, "SeriesLines:colors", static=True)
        _, names = _rows(chunks, path, "SeriesLines:names", static=True)
        name = path[len("/stats/"):]
        assert len(colors) == 1 and names == [[name]], (path, colors, names)
        by_group.setdefault(stat_group(name), []).append(colors[0][0])
    assert len(by_group["error"]) >= 2 and len(by_group["quality"]) >= 2
    for group, colours in by_group.items():
        assert len(set(colours)) == len(colours), (group, colours)


def test_weight_histogram_bins():
    c, centres, width = weight_histogram(np.array([1.0, 1.0, 0.1, 1e-3, 0.0, 1e-4]))
    assert c.sum() == 6 and c[-1] == 2  # the two heaviest in the top bin (log10 = 0)
    assert c[0] == 1 and width == 6.0 / _HIST_BINS  # zero in the first bin; the span is the 6-decade minimum
    assert np.all(np.diff(centres) > 0) and centres[-1] < 0.0
    c, centres, width = weight_histogram(np.array([1.0, 1e-40, 0.0]))
    assert width == 48.0 / _HIST_BINS and c[0] == 1 and c[4] == 1 and c[-1] == 1  # span 6 x 2^3 >= 40 decades
    c, _, _ = weight_histogram(np.full(10, 0.1))
    assert c[-1] == 10  # equal weights: all in the top bin


def test_particles_are_sized_and_faded_by_weight(recording):
    # Rerun (0.41) draws a point with alpha below 255 darker, not see-through: the lightest particles (alpha 60) were
    # near-black specks like obstacles on the map. Every colour is opaque; the lighter, the nearer the free grey.
    _, chunks = recording
    _, radii = _rows(chunks, "/world/particles", "Points2D:radii")
    _, colors = _rows(chunks, "/world/particles", "Points2D:colors")
    r = -np.asarray(radii[0], dtype=np.float64)  # UI points are stored negative
    packed = np.asarray(colors[0], dtype=np.uint32)  # RGBA packed in a u32
    assert np.all(packed & 0xFF == 255)
    rgb = np.stack([(packed >> s) & 0xFF for s in (24, 16, 8)], axis=1).astype(int)
    grey = np.abs(rgb - 235).max(axis=1)  # how far from the map's free grey (the lightest: a quarter of the colour)
    assert np.all(r > 0) and len(np.unique(r)) >= 2
    assert r[np.argmin(grey)] < r[np.argmax(grey)]  # the faded ones are the light, small ones
    assert rgb[np.argmin(grey)].min() > 150 and grey.max() > 150, (rgb[np.argmin(grey)], grey.max())


def test_likelihood_field_layer_is_the_sensor_models(recording):
    from PIL import Image

    _, chunks = recording
    _, blobs = _rows(chunks, "/world/likelihood_field", "EncodedImage:blob", static=True)
    assert len(blobs) == 1
    img = np.asarray(Image.open(io.BytesIO(bytes(blobs[0][0]))))
    grid = load_map(DEMO / "map.yaml")
    assert img.shape == (grid.height, grid.width, 4)
    rows = img[::-1]  # image row 0 is the top, grid row 0 the bottom
    top, bottom = _VIRIDIS[-1], _VIRIDIS[0]
    # the d the model scores while tracking (interior: depth): 0 on a wall's faces, the depth inside a thick wall
    d = field_distance(grid, load_config(PROJECT_ROOT / "configs" / "default.yaml").sensor)
    on_face = rows[grid.occupied & (d == 0.0)]
    deep = rows[grid.occupied & (d >= 0.2)]  # 2 sigma_hit inside a wall (315 cells): 2 nats below the peak
    far = rows[d > 1.0]  # 10 sigma_hit from any wall's face: p is z_rand's floor
    assert np.abs(on_face[:, :3].astype(int) - top).max() <= 1
    assert len(deep) > 100 and (np.abs(deep[:, :3].astype(int) - top).max(axis=1) > 10).all()
    assert np.abs(far[:, :3].astype(int) - bottom).max() <= 1


def test_expected_scan_lies_on_the_map(recording):
    s, chunks = recording
    steps, pts = _rows(chunks, "/world/scan/expected", "Points2D:positions")
    assert sorted(steps) == list(range(s["updates"]))
    xy = np.array([p for row in pts for p in row], dtype=np.float64)
    grid = load_map(DEMO / "map.yaml")
    ix, iy = grid.world_to_cell(xy[:, 0], xy[:, 1])
    assert len(xy) > 20 * s["updates"]
    assert np.quantile(np.asarray(grid.distance)[iy, ix], 0.99) <= 0.08  # ray ends on an occupied cell


def test_timings_leave_the_compile_out(recording):
    s, chunks = recording
    for stage in ("correct", "estimate", "resample"):
        steps, vals = _rows(chunks, f"/stats/time_ms/{stage}", "Scalars:scalars")
        w_steps, w_vals = _rows(chunks, f"/warmup/time_ms/{stage}", "Scalars:scalars")
        assert w_steps and w_steps[0] == 0 and 0 not in steps, stage  # the first update goes apart
        assert set(steps) | set(w_steps) == set(range(s["updates"]))
        # the spike was > 1,000 ms; the rest of a 3,000-particle run takes a few ms per stage
        assert max(v[0] for v in vals) < 500.0, stage


def test_timings_warm_up_apart_when_the_kernels_are_already_loaded(recording, tmp_path):
    """A second run in the same process (as in a long test session) loads no kernel: its first update is fast,
    and still goes apart, so every stage has a plotted series from the second update on."""
    log = _head(DEMO / "log.clf", tmp_path / "head.clf", 10)
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"log={log}", "filter.particles=3000", "filter.min_particles=500", "rerun.particles_max=100"])
    s = run(cfg, tmp_path / "out", progress=False, echo=lambda *_: None)
    chunks = list(RrdReader(tmp_path / "out" / "recording.rrd").stream().to_chunks())
    for stage in ("correct", "estimate", "resample"):
        steps, _ = _rows(chunks, f"/stats/time_ms/{stage}", "Scalars:scalars")
        w_steps, _ = _rows(chunks, f"/warmup/time_ms/{stage}", "Scalars:scalars")
        assert w_steps == [0] and sorted(steps) == list(range(1, s["updates"])), stage
    steps, _ = _rows(chunks, "/stats/time_ms/predict", "Scalars:scalars")
    w_steps, _ = _rows(chunks, "/warmup/time_ms/predict", "Scalars:scalars")
    assert w_steps == [1] and sorted(steps) == list(range(2, s["updates"]))  # nothing to predict at step 0


def test_a_map_far_from_the_origin_is_recorded_in_a_frame_of_its_own(tmp_path):
    # A map in UTM-like coordinates (origin 500 km east, 5,400 km north): Rerun keeps positions as float32, whose
    # step there is 0.5 m, and every particle of a step was recorded on one y. The recording now holds positions
    # less the map's origin rounded to the km, and says so; the trajectory keeps the map frame. Tolerance 1 mm:
    # float32's step at the few hundred metres left is under 0.1 mm.
    import shutil

    from mcl.trajectory import read_tum
    from mcl.viz import recording_offset

    far = np.array([500_000.0, 5_400_000.0])
    shutil.copy(DEMO / "map.pgm", tmp_path / "map.pgm")
    (tmp_path / "map.yaml").write_text((DEMO / "map.yaml").read_text().replace(
        "origin: [-1.0, -1.0, 0.0]", f"origin: [{far[0] - 1.0}, {far[1] - 1.0}, 0.0]"))
    _, truth = read_tum(DEMO / "truth.tum")
    start = truth[:, 0] + np.array([*far, 0.0])
    log = _head(DEMO / "log.clf", tmp_path / "head.clf", 20)
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"log={log}", f"map={tmp_path / 'map.yaml'}", f"filter.initial_pose=[{start[0]}, {start[1]}, {start[2]}]",
        "filter.particles=2000", "filter.kld=false", "rerun.particles_max=2000"])
    said: list = []
    run(cfg, tmp_path / "out", progress=False, echo=lambda *a: said.append(" ".join(map(str, a))))
    offset = recording_offset(load_map(tmp_path / "map.yaml"))
    assert offset.tolist() == [500_000.0, 5_400_000.0]
    assert any("positions are relative to (500000, 5400000) m" in s for s in said), said
    t, est = read_tum(tmp_path / "out" / "trajectory.tum")
    chunks = list(RrdReader(tmp_path / "out" / "recording.rrd").stream().to_chunks())
    steps, pos = _rows(chunks, "/world/estimate", "Points2D:positions")
    rec = {k: np.asarray(v[0], dtype=np.float64) for k, v in zip(steps, pos)}
    assert len(rec) >= est.shape[1] - 1  # an update a scan (the first starts the filter)
    for k, xy in rec.items():  # each recorded estimate is one of the trajectory's poses, to 1 mm
        assert np.hypot(*(xy + offset)[:, None] - est[:2]).min() < 1e-3, (k, xy)
    _, clouds = _rows(chunks, "/world/particles", "Points2D:positions")
    ys = np.array([p[1] for p in clouds[-1]])
    assert np.unique(ys).size > 100  # a cloud (581 distinct y after resampling), not a line of one y


def test_a_reseeds_update_is_drawn_with_its_posterior_not_the_reseeds_prior(tmp_path):
    # The demo from 45 to 58 s, tracking from the reference at 45 s: the kidnap at 50 s is a re-seed a few updates
    # later. A re-seed resamples at once, and the recording drew its prior (the kept track's heavy particles among
    # equal fresh ones: the histogram counted 100,000 where the update weighted 5,000, its heavy points the wrong
    # track's). Now every step's histogram counts the particles that update weighted (stats/particles).
    from mcl.trajectory import read_tum

    lines = [ln for ln in (DEMO / "log.clf").read_text().splitlines(keepends=True)
             if not ln.startswith(("FLASER", "ODOM")) or 45.0 <= float(ln.split()[-1]) <= 58.0]
    (tmp_path / "cut.clf").write_text("".join(lines))
    t, truth = read_tum(DEMO / "truth.tum")
    x = truth[:, np.searchsorted(t, 45.0)]
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"log={tmp_path / 'cut.clf'}", f"filter.initial_pose=[{x[0]}, {x[1]}, {x[2]}]", "filter.particles=3000",
        "rerun.particles_max=500"])
    s = run(cfg, tmp_path / "out", progress=False, echo=lambda *_: None)
    assert s["reseeds"] >= 1
    chunks = list(RrdReader(tmp_path / "out" / "recording.rrd").stream().to_chunks())
    steps, values = _rows(chunks, "/weights/histogram", "BarChart:values")
    counts = {k: float(np.sum(v[0]["buffer"])) for k, v in zip(steps, values)}
    p_steps, p_vals = _rows(chunks, "/stats/particles", "Scalars:scalars")
    n = {k: v[0] for k, v in zip(p_steps, p_vals)}
    assert sorted(counts) == sorted(n) == list(range(s["updates"]))
    assert {k: c for k, c in counts.items() if c != n[k]} == {}


def test_the_histogram_without_a_cloud_and_the_truth_cleared_across_a_gap(tmp_path):
    # rerun.particles_max 0 dropped the weight histogram too (its panel stayed empty), and a thinned cloud thinned
    # it; a reference gap that is not bridged left the last true pose on screen for a second, 1 m from the robot,
    # while the error panel was blank. The demo's first 40 scans, its reference cut from 3 to 5 s.
    from mcl.trajectory import read_tum, write_tum

    t, truth = read_tum(DEMO / "truth.tum")
    keep = (t < 3.0) | (t > 5.0)
    write_tum(tmp_path / "gap.tum", t[keep], truth[:, keep])
    log = _head(DEMO / "log.clf", tmp_path / "head.clf", SCANS)
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"log={log}", f"truth={tmp_path / 'gap.tum'}", "filter.particles=3000", "rerun.particles_max=0",
        "filter.global_density=0"])
    s = run(cfg, tmp_path / "out", progress=False, echo=lambda *_: None)
    chunks = list(RrdReader(tmp_path / "out" / "recording.rrd").stream().to_chunks())
    steps, _ = _rows(chunks, "/weights/histogram", "BarChart:values")
    assert sorted(steps) == list(range(s["updates"]))
    assert not any(str(c.entity_path) == "/world/particles" and not c.is_static for c in chunks)
    # the truth's rows: a point at each step with a reference, none (cleared once) inside the gap
    rows = {}
    for c in chunks:
        if str(c.entity_path) == "/world/truth" and not c.is_static:
            b = c.to_record_batch()
            if "Points2D:positions" in b.schema.names:
                for k, tt, p in zip(b.column("step").cast(pa.int64()).to_pylist(), b.column("time").to_pylist(),
                                    b.column("Points2D:positions").to_pylist()):
                    rows[k] = (tt.total_seconds(), len(p))
    cleared = [k for k, (_, n) in rows.items() if n == 0]
    assert len(cleared) == 1 and 3.0 <= rows[cleared[0]][0] <= 5.0, rows
    assert all(n == 1 for k, (tt, n) in rows.items() if not 3.0 <= tt <= 5.0)
