"""RerunLogger: write small recordings and read them back with rerun.chunk.RrdReader."""

from __future__ import annotations

import io
import math
import os
import re
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import yaml

rr = pytest.importorskip("rerun")
import pyarrow as pa  # noqa: E402  (a dependency of rerun-sdk)
from rerun.chunk import RrdReader  # noqa: E402
import rerun.blueprint as rrb  # noqa: E402

from mcl import viz  # noqa: E402
from mcl.viz import RerunLogger  # noqa: E402

STEPS = 10
N = 500
RES, ORIGIN = 0.1, (-1.0, -2.0)


# --- helpers ------------------------------------------------------------------------------
def make_occupancy() -> np.ndarray:
    occ = np.zeros((20, 30), dtype=np.int8)  # row 0 = bottom
    occ[0, :] = 100  # bottom wall
    occ[:, 0] = 100  # left wall
    occ[15:, 20:] = -1  # unknown top-right block
    return occ


def make_grid():
    occ = make_occupancy()
    try:
        from mcl.maps import OccupancyGrid

        return OccupancyGrid.from_occupancy(occ, RES, ORIGIN)
    except (ImportError, AttributeError):
        return types.SimpleNamespace(
            occupancy=occ,
            resolution=RES,
            origin=ORIGIN,
            width=occ.shape[1],
            height=occ.shape[0],
            occupied=occ >= 65,
            free=(occ >= 0) & (occ <= 19),
            unknown=occ < 0,
        )


def step_stats(k: int) -> dict[str, float]:
    return {
        "ess": 100.0 + k,
        "particles": float(N),
        "time_ms/predict": 0.5 * k,
        "error_xy": 0.01 * k,
        "tries": float(k % 3),
    }


def tiny_step(log: RerunLogger, step: int, t: float) -> None:
    four = np.full(4, 0.25)
    log.log_step(step, t, particles=np.zeros((3, 4)), weights=four, estimate=np.zeros(3), cov=np.eye(3), stats={"ess": 4.0})


def write_run(path: Path, n_steps: int = STEPS, **kwargs) -> list[dict[str, float]]:
    rng = np.random.default_rng(0)
    logged = []
    with RerunLogger("save", path, **kwargs) as log:
        log.log_map(make_grid())
        log.log_truth_path(np.stack([np.linspace(0, 2, 50), np.zeros(50), np.zeros(50)]))
        for k in range(n_steps):
            particles = rng.normal(size=(3, N))
            w = rng.random(N)
            stats = step_stats(k)
            log.log_step(
                k,
                10.0 + 0.5 * k,
                particles=particles,
                weights=w / w.sum(),
                estimate=np.array([0.1 * k, 0.0, 0.2]),
                cov=np.diag([0.04, 0.01, 0.001]),
                scan_world=rng.normal(size=(2, 30)),
                odom_pose=np.array([0.1 * k, 0.05, 0.0]),
                truth_pose=np.array([0.1 * k, 0.0, 0.0]),
                stats=stats,
            )
            logged.append(stats)
    return logged


def chunks(path: Path):
    return RrdReader(path).stream().to_chunks()


def rows(path: Path, entity: str, timeline: str | None) -> list[tuple[int | None, dict]]:
    """(time on `timeline`, {component: value}) per row of `entity`; timeline None = static rows."""
    out = []
    for c in chunks(path):
        if c.entity_path != entity:
            continue
        if timeline is None:
            if not c.is_static:
                continue
        elif c.is_static or timeline not in c.timeline_names:
            continue
        batch = c.to_record_batch()
        # index columns as int64: sequence numbers, or nanoseconds for timestamp/duration
        times = batch.column(timeline).cast(pa.int64()).to_pylist() if timeline else [None] * c.num_rows
        data = {k: batch.column(k).to_pylist() for k in batch.schema.names if ":" in k}
        for i in range(c.num_rows):
            out.append((times[i], {k: v[i] for k, v in data.items()}))
    return sorted(out, key=lambda r: (r[0] is None, r[0]))


def count_rows(path: Path, entity: str, timeline: str | None) -> int:
    return len(rows(path, entity, timeline))


# --- recordings read back ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def run_every1(tmp_path_factory):
    path = tmp_path_factory.mktemp("viz") / "run.rrd"
    logged = write_run(path, particles_max=200)
    return path, logged


def test_particles_one_row_per_step_and_subsampled(run_every1):
    path, _ = run_every1
    r = rows(path, "/world/particles", "step")
    assert [t for t, _ in r] == list(range(STEPS))
    for _, comps in r:
        assert len(comps["Points2D:positions"]) == 200  # min(N, particles_max)
        assert len(comps["Points2D:colors"]) == 200
        # issue 13: the radius grows with the weight, per particle and per step (three sizes, UI points)
        radii = -np.asarray(comps["Points2D:radii"], dtype=np.float64)
        assert radii.size == 200 and set(np.unique(radii)) <= set(viz._RADII.tolist())
    # draw order is a static style, never per step
    assert all("Points2D:draw_order" not in comps for _, comps in r)
    assert any("Points2D:draw_order" in comps for _, comps in rows(path, "/world/particles", None))


def test_particles_every_third_step(tmp_path):
    path = tmp_path / "every3.rrd"
    write_run(path, particles_max=1000, particles_every=3)
    r = rows(path, "/world/particles", "step")
    assert [t for t, _ in r] == [0, 3, 6, 9]  # ceil(10 / 3) rows
    assert all(len(c["Points2D:positions"]) == N for _, c in r)  # N < particles_max: all of them
    # other entities still log every step
    assert count_rows(path, "/world/estimate", "step") == STEPS


def test_particles_max_zero_logs_no_particles(tmp_path):
    path = tmp_path / "none.rrd"
    write_run(path, n_steps=3, particles_max=0)
    assert count_rows(path, "/world/particles", "step") == 0
    assert count_rows(path, "/world/estimate", "step") == 3


def test_map_is_static_image_placed_in_world(run_every1):
    path, _ = run_every1
    assert count_rows(path, "/world/map", "step") == 0
    static = {}
    for _, comps in rows(path, "/world/map", None):
        static.update({k: v for k, v in comps.items() if v is not None})
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(bytes(static["EncodedImage:blob"][0]))))
    occ = make_occupancy()
    assert img.shape == occ.shape
    # image row 0 is the top of the map = grid row H-1
    assert (img[-1] == 0).all()  # bottom wall, occupied -> black
    assert (img[:, 0] == 0).all()  # left wall
    assert img[0, 25] == viz._UNKNOWN and img[-3, 25] == viz._FREE
    h = occ.shape[0]
    np.testing.assert_allclose(static["Transform3D:translation"][0], [ORIGIN[0], ORIGIN[1] + h * RES, 0.0], atol=1e-6)
    np.testing.assert_allclose(static["Transform3D:scale"][0], [RES, -RES, 1.0], atol=1e-6)


def test_the_likelihood_layer_is_the_whole_field_pooled_made_in_bands():
    # The recording's likelihood-field layer takes the field in bands of rows (distance plus the interior: depth
    # patches laid on a copy of each band), pooled k x k: the same values as the whole field pooled, for any band
    # height (997 cells: bands of 2 of the demo map's 440-cell rows, or of one pooled row at k = 3), without the whole
    # field's copy that ``surface_distance`` keeps in the grid (576 MB on a 600 m map at 5 cm); surface: face too.
    from mcl.config import load_config
    from mcl.maps import load_map
    from mcl.sensors import field_distance

    root = Path(__file__).resolve().parents[1]
    for interior, surface in (("depth", "centre"), ("zero", "centre"), ("depth", "face"), ("zero", "face")):
        cfg = load_config(root / "configs" / "default.yaml", [f"sensor.likelihood_field.interior={interior}",
                                                              f"sensor.likelihood_field.surface={surface}"]).sensor
        grid = load_map(root / "data" / "demo" / "map.yaml")
        for k in (1, 3):
            for cells in (1 << 22, 997):
                bands = list(viz._field_bands(grid, cfg, k, cells))
                assert (len(bands) > 1) == (cells == 997)
                assert "_surface_cache" not in grid.__dict__
                whole = viz._pool(np.asarray(field_distance(load_map(root / "data" / "demo" / "map.yaml"), cfg)),
                                  k, np.min, np.inf)
                assert np.array_equal(np.concatenate(bands), whole)
        if interior == "depth":  # the demo's thick walls: the patches change 315 cells, so the test sees them
            assert (np.asarray(field_distance(grid, cfg)) != np.asarray(grid.distance)).sum() > 100


def test_a_map_larger_than_a_texture_is_drawn_at_k_cells_per_pixel(tmp_path, monkeypatch):
    # A viewer draws the map as one GPU texture (at most MAP_IMAGE_MAX_SIDE pixels a side): a larger grid is pooled
    # k x k, a block occupied if any of its cells is, else free if any is, and placed with k times the cell size.
    # Here the 20 x 30 grid with a limit of 16 pixels: k = 2, a 10 x 15 image covering the same 2 x 3 m.
    assert viz.map_image_factor((8192, 100)) == 1 and viz.map_image_factor((100, 8193)) == 2
    monkeypatch.setattr(viz, "MAP_IMAGE_MAX_SIDE", 16)
    occ = make_occupancy()
    occ[7, 11] = 100  # one occupied cell inside free space: its block must show it
    from mcl.maps import OccupancyGrid

    path = tmp_path / "big.rrd"
    with RerunLogger("save", path) as log:
        log.log_map(OccupancyGrid.from_occupancy(occ, RES, ORIGIN))
    static = {}
    for _, comps in rows(path, "/world/map", None):
        static.update({k: v for k, v in comps.items() if v is not None})
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(bytes(static["EncodedImage:blob"][0]))))
    assert img.shape == (10, 15)
    assert (img[-1] == 0).all() and (img[:, 0] == 0).all()  # the walls survive the pooling
    assert img[10 - 1 - 7 // 2, 11 // 2] == 0  # the lone obstacle too
    assert img[0, 12] == viz._UNKNOWN and img[-3, 12] == viz._FREE
    np.testing.assert_allclose(static["Transform3D:translation"][0], [ORIGIN[0], ORIGIN[1] + 20 * RES, 0.0], atol=1e-6)
    np.testing.assert_allclose(static["Transform3D:scale"][0], [2 * RES, -2 * RES, 1.0], atol=1e-6)


def test_stats_series_values(run_every1):
    path, logged = run_every1
    for name in logged[0]:
        r = rows(path, f"/stats/{name}", "step")
        # issue 13: a timing's first value (its kernels' compile or load) goes to warmup/, whatever its size
        # (time_ms/predict is 0 at step 0 here), and the plotted series starts at step 1
        first = 1 if viz.stat_group(name) == "timings" else 0
        assert [t for t, _ in r] == list(range(first, STEPS)), name
        values = [c["Scalars:scalars"][0] for _, c in r]
        np.testing.assert_allclose(values, [s[name] for s in logged[first:]], err_msg=name)
        if first:
            w = rows(path, f"/warmup/{name}", "step")
            assert [t for t, _ in w] == [0]
            np.testing.assert_allclose([c["Scalars:scalars"][0] for _, c in w], [s[name] for s in logged[:1]])


def test_time_timeline_from_log(run_every1):
    path, _ = run_every1
    r = rows(path, "/stats/ess", "time")
    got = [t * 1e-9 for t, _ in r]  # duration timeline in nanoseconds
    np.testing.assert_allclose(got, [10.0 + 0.5 * k for k in range(STEPS)])


def test_buffered_rows_over_several_flushes_keep_every_step_and_time(tmp_path):
    # The small per-step entities go out as columns every COLUMN_FLUSH_STEPS steps and at close: over 2.5 flushes,
    # with the first steps' times not finite (no time yet), every step is there once, with its own time or none,
    # and its values; the same as one rr.log per step wrote (the demo's recording was compared row by row).
    path = tmp_path / "flushes.rrd"
    n = int(2.5 * viz.COLUMN_FLUSH_STEPS)
    with RerunLogger("save", path) as log:
        for k in range(n):
            log.log_step(k, math.nan if k < 3 else 10.0 + 0.5 * k, particles=np.zeros((3, 4)),
                         weights=np.full(4, 0.25), estimate=np.array([0.1 * k, 0.0, 0.2]),
                         cov=np.diag([0.04, 0.01, 0.001]), truth_pose=np.array([0.1 * k, 1.0, 0.0]),
                         stats={"ess": float(k)})
    r = rows(path, "/stats/ess", "step")
    assert [t for t, _ in r] == list(range(n))
    assert [c["Scalars:scalars"][0] for _, c in r] == [float(k) for k in range(n)]
    timed = rows(path, "/stats/ess", "time")
    np.testing.assert_allclose([t * 1e-9 for t, _ in timed], [10.0 + 0.5 * k for k in range(3, n)])
    est = rows(path, "/world/estimate", "step")
    assert [t for t, _ in est] == list(range(n))
    np.testing.assert_allclose([c["Points2D:positions"][0][0] for _, c in est], [0.1 * k for k in range(n)], atol=1e-6)
    assert all(len(c["LineStrips2D:strips"][0]) == 49 and c["Arrows2D:vectors"] for _, c in est)
    trail = rows(path, "/world/truth/trail", "step")
    assert [t for t, _ in trail] == list(range(1, n))  # a segment from the previous pose: none at step 0


def test_estimate_trails_truth_and_blueprint(run_every1):
    path, _ = run_every1
    est = rows(path, "/world/estimate", "step")
    assert len(est) == STEPS
    comps = est[0][1]
    assert len(comps["Points2D:positions"]) == 1
    assert len(comps["Arrows2D:vectors"]) == 1
    ellipse = np.asarray(comps["LineStrips2D:strips"][0])
    d = ellipse - np.array([0.0, 0.0])
    mahal = d[:, 0] ** 2 / 0.04 + d[:, 1] ** 2 / 0.01
    np.testing.assert_allclose(mahal, 4.0, rtol=1e-5)  # 2-sigma ellipse
    # linear size: one 2-point segment per step after the first
    trail = rows(path, "/world/odometry/trail", "step")
    assert len(trail) == STEPS - 1 and all(len(c["LineStrips2D:strips"][0]) == 2 for _, c in trail)
    # a static truth path was given, so no per-step truth trail; current truth point per step
    assert count_rows(path, "/world/truth/trail", "step") == 0
    assert count_rows(path, "/world/truth", "step") == STEPS
    assert any("LineStrips2D:strips" in c for _, c in rows(path, "/world/truth", None))


def test_blueprint_world_view_and_stats_views(run_every1):
    path, logged = run_every1
    reader = RrdReader(path)
    assert len(reader.blueprints()) == 1  # sent once, when the stats names were first seen
    origins, queries, overrides = [], [], []
    for c in reader.stream(store=reader.blueprints()[0]).to_chunks():
        batch = c.to_record_batch()
        names = batch.schema.names
        if "ViewBlueprint:space_origin" in names:
            origins += batch.column("ViewBlueprint:space_origin").to_pylist()[0]
        if "ViewContents:query" in names:
            queries += batch.column("ViewContents:query").to_pylist()[0]
        if "VisibleTimeRanges:ranges" in names:
            overrides.append(c.entity_path)
    assert "/" in origins and "+ /world/**" in queries
    for name in logged[0]:
        assert f"+ /stats/{name}" in queries, name
    assert any(p.endswith("/overrides/world/odometry/trail/visualizers") for p in overrides)


def test_no_component_both_static_and_temporal(run_every1):
    path, _ = run_every1
    static, temporal = set(), set()
    for c in chunks(path):
        names = {(c.entity_path, k) for k in c.to_record_batch().schema.names if ":" in k}
        (static if c.is_static else temporal).update(names)
    assert temporal, "no temporal data read back"
    assert static & temporal == set()


def test_off_mode_writes_nothing(tmp_path):
    path = tmp_path / "off.rrd"
    with RerunLogger("off", path) as log:
        log.log_map(make_grid())
        tiny_step(log, 0, 0.0)
        assert not log.enabled
    log.close()
    assert list(tmp_path.iterdir()) == []


def test_spawn_without_display_falls_back_to_save(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    path = tmp_path / "spawned.rrd"
    with RerunLogger("spawn", path) as log:
        assert log.mode == "save"
        tiny_step(log, 3, 1.0)
    err = capsys.readouterr().err
    assert "no display" in err and str(path) in err
    assert rows(path, "/stats/ess", "step")[0][0] == 3


def test_a_display_variable_with_no_server_behind_it_is_no_display(tmp_path, monkeypatch, capsys):
    # DISPLAY left set by ssh or a container with no X server: the viewer died and the run hung in the stream's
    # flush for good (SIGINT and SIGTERM too). No server answers: save, as without a display.
    import socket

    from mcl.viz import has_display

    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setenv("DISPLAY", ":987")  # no /tmp/.X11-unix/X987
    assert not has_display()
    with socket.socket() as listener:  # a "remote" server: something listens on 6000 + N
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = listener.getsockname()[1]
        if port > 6000:
            monkeypatch.setenv("DISPLAY", f"127.0.0.1:{port - 6000}.0")
            assert has_display()
    monkeypatch.setenv("DISPLAY", "127.0.0.1:1")  # port 6001: nothing (on this machine) listens
    if not _listening(6001):
        assert not has_display()
    monkeypatch.setenv("DISPLAY", ":987")
    path = tmp_path / "spawned.rrd"
    with RerunLogger("spawn", path) as log:
        assert log.mode == "save"
        tiny_step(log, 3, 1.0)
    assert "no display (no X server answers at DISPLAY" in capsys.readouterr().err


def test_the_viewer_is_found_beside_this_python_without_an_activated_venv(monkeypatch):
    # `.venv/bin/mcl run --rerun spawn` with the venv not activated: `rerun` is not on PATH (a traceback before)
    from pathlib import Path

    from mcl.viz import viewer_executable

    monkeypatch.setenv("PATH", "/nonexistent")
    beside = Path(sys.executable).parent / "rerun"
    assert viewer_executable() == (str(beside) if beside.exists() else None)


def test_serve_keeps_serving_after_the_run_on_a_free_port_until_ctrl_c(tmp_path):
    # The servers died with the process the moment the run ended (nobody could look), and with Rerun's port taken
    # (a second run, an open viewer) the run ended in a traceback with no summary.
    import signal
    import socket
    import subprocess
    import time

    from mcl.simulate import simulate

    simulate(tmp_path / "w", seed=3, duration=5.0)
    with socket.socket() as taken:
        try:
            taken.bind(("0.0.0.0", 9876))
            taken.listen()
        except OSError:
            pass  # already held by something else: the case under test all the same
        env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
        # started with SIGINT ignored, as a background job of a non-interactive shell is (a CI script's `cmd &`):
        # Python then installs no Ctrl-C handler, and the served run waited for ever
        proc = subprocess.Popen(
            [sys.executable, "-m", "mcl", "run", "--map", str(tmp_path / "w" / "map.yaml"), "--log",
             str(tmp_path / "w" / "log.clf"), "--particles", "300", "--rerun", "serve", "--no-progress", "--out",
             str(tmp_path / "out")], stderr=subprocess.PIPE, text=True, env=env,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
        err = []
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            line = proc.stderr.readline()
            err.append(line)
            if "serving its recording until Ctrl-C" in line or not line:
                break
        assert "serving its recording until Ctrl-C" in err[-1], "".join(err)
        served = next(ln for ln in err if "Rerun gRPC server at" in ln)
        assert "rerun+http://127.0.0.1:9876" not in served  # the taken port was not used
        time.sleep(1.0)
        assert proc.poll() is None  # still serving
        # the data server too: it closed when the run returned (the stream dropped with its logger), so the web
        # viewer, still up, had nothing to show
        port = int(re.search(r"rerun\+http://[^:]+:(\d+)", served).group(1))
        assert _listening(port), served
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 0
    assert (tmp_path / "out" / "summary.json").is_file()


def _listening(port: int) -> bool:
    import socket

    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


def test_the_world_view_opens_on_the_maps_known_cells():
    # Without bounds the view fitted whatever each step drew (the ellipse, the particles, the scan): the map jumped
    # and zoomed at every step. The blueprint frames the known cells (a map's wide unknown margin left out), 5 % of
    # the larger side around; y is minus the world's in the view (the flip on `world`).
    occ = np.full((40, 60), -1, dtype=np.int8)
    occ[10:20, 5:25] = 0  # known cells: rows 10-19, columns 5-24
    occ[10, 5:25] = 100
    from mcl.maps import OccupancyGrid

    (x0, x1), (y0, y1) = viz.known_bounds(OccupancyGrid.from_occupancy(occ, RES, ORIGIN))
    pad = 0.05 * 2.0  # the larger side: 20 cells = 2 m
    assert (x0, x1) == pytest.approx((ORIGIN[0] + 0.5 - pad, ORIGIN[0] + 2.5 + pad))
    assert (y0, y1) == pytest.approx((ORIGIN[1] + 1.0 - pad, ORIGIN[1] + 2.0 + pad))
    view = viz.build_blueprint(["ess"], ((x0, x1), (y0, y1))).root_container.contents[0]  # a 2 m map: no Robot view
    assert view.name == "World"
    got = view.properties["VisualBounds2D"].range.as_arrow_array().to_pylist()[0]
    assert got["x_range"] == pytest.approx([x0, x1]) and got["y_range"] == pytest.approx([-y1, -y0])
    assert viz.known_bounds(OccupancyGrid.from_occupancy(np.full((5, 5), -1, dtype=np.int8), RES, ORIGIN)) is None
    # the time panel on the step timeline: on `time` the panels opened on a window of the run
    assert viz.build_blueprint(["ess"]).time_panel.timeline == "step"


def test_the_plots_a_user_reads_first_are_stacked_and_the_rest_in_tabs():
    # Six stacked panels left each about 150 px tall at 1080p (legends over the curves), and "Other" drew the
    # injection share (0..1) on the scale of the skipped-beam count (hundreds): a flat line at 0. Now the error, the
    # quality, the particles and the weights are stacked; the timings, spread, tries, recovery share and counts are
    # tabs, the share alone in its panel; the time panel opens as its scrubber and the selection panel closed.
    names = ["ess", "particles", "inject_p", "clusters", "skipped_beams", "time_ms/predict", "error/position",
             "quality/match", "spread/full", "tries"]
    b = viz.build_blueprint(names, ((0.0, 22.0), (0.0, 17.0)))  # the demo's map: the World view alone
    right = b.root_container.contents[1]
    stacked, tabs = right.contents[:-1], right.contents[-1]
    assert [v.name.split(":")[0] for v in stacked] == ["Error vs truth", "Quality", "Particles", "Particle weights"]
    assert [v.name for v in tabs.contents] == ["About this recording", "Time per update (ms)", "Spread (m)",
                                               "Map rejection tries", "Recovery (share)", "Counts"]
    assert max(len(v.name) for v in tabs.contents) <= 25  # a tab's title is cut at about 50 characters
    # every plot over the whole run: without a range, a run of over 2,000 updates showed a window that followed
    # the cursor (fr079, 4,110 updates: at step 0 the left half empty, the run's end off screen)
    plots = [v for v in [*stacked, *tabs.contents] if isinstance(v, rrb.TimeSeriesView)]
    assert len(plots) == 8 and all("TimeAxis" in v.properties for v in plots)
    assert viz.stat_group("inject_p") == "recovery" and viz.stat_group("skipped_beams") == "other"
    assert str(b.time_panel.state).lower().endswith("collapsed")
    assert str(b.selection_panel.state).lower().endswith("collapsed")


def test_a_view_follows_the_estimate_on_a_big_map(tmp_path):
    # On a 250 m map (infinite_corridor) the whole-map view draws the cloud, the scan and the expected scan in a few
    # pixels: the "Robot" view is drawn in the frame of world/follow, which holds the estimate's position (y flipped
    # as on `world`, so the map reads as in the World view), and opens on a square around it.
    b = viz.build_blueprint(["ess"], ((0.0, 250.0), (0.0, 245.0)))
    robot = b.root_container.contents[0]
    assert [v.name for v in b.root_container.contents[:2]] == [robot.name, "World"]
    # a map 60 m across or less (the demo's 22 m, intel_lab's 43 m) shows the robot as large in World: no second view
    small = viz.build_blueprint(["ess"], ((0.0, 43.0), (0.0, 40.0))).root_container.contents
    assert small[0].name == "World" and not any((getattr(v, "name", None) or "").startswith("Robot") for v in small)
    assert robot.name.startswith("Robot") and str(robot.origin) == "/" + viz.FOLLOW_ENTITY
    got = robot.properties["VisualBounds2D"].range.as_arrow_array().to_pylist()[0]
    h = viz.FOLLOW_HALF_M
    assert got["x_range"] == pytest.approx([-h, h]) and got["y_range"] == pytest.approx([-h, h])
    path = tmp_path / "f.rrd"
    with RerunLogger("save", path, particles_max=0) as log:
        for i in range(3):
            log.log_step(i, 0.1 * i, particles=np.zeros((3, 4)), weights=np.full(4, 0.25),
                         estimate=np.array([10.0 + i, -5.0, 0.3]), cov=np.eye(3) * 0.01)
        rows = log._pending[viz.FOLLOW_ENTITY][2]
        assert rows[("Transform3D", "translation")] == [[10.0 + i, -5.0, 0.0] for i in range(3)]
        assert rows[("Transform3D", "scale")] == [[1.0, -1.0, 1.0]] * 3
    assert path.stat().st_size > 0


def test_the_true_path_is_broken_where_the_robot_jumps(tmp_path):
    # A kidnap carried the robot 12 m: one line through the walls read as a path. The strip is cut at a step over
    # 10 median steps (and 1 m); a path without jumps stays one strip.
    path = tmp_path / "t.rrd"
    x = np.concatenate([np.linspace(0, 2, 30), 12.0 + np.linspace(0, 2, 30)])
    with RerunLogger("save", path) as log:
        log.log_truth_path(np.stack([x, np.zeros(60), np.zeros(60)]))
    strips = rows(path, "/world/truth", None)[0][1]["LineStrips2D:strips"]
    assert [len(s) for s in strips] == [30, 30]
    with RerunLogger("save", path) as log:
        log.log_truth_path(np.stack([np.linspace(0, 2, 50), np.zeros(50), np.zeros(50)]))
    assert [len(s) for s in rows(path, "/world/truth", None)[0][1]["LineStrips2D:strips"]] == [50]
    # with times: a scan gap of 2.2 s that drove 1.1 m at the robot's speed is no jump (it was cut); a kidnap is
    t = np.concatenate([0.1 * np.arange(30), 5.2 + 0.1 * np.arange(30)])
    gap = np.concatenate([0.05 * np.arange(30), 1.45 + 1.1 + 0.05 * np.arange(30)])
    with RerunLogger("save", path) as log:
        log.log_truth_path(np.stack([gap, np.zeros(60), np.zeros(60)]), t)
    assert [len(s) for s in rows(path, "/world/truth", None)[0][1]["LineStrips2D:strips"]] == [60]
    with RerunLogger("save", path) as log:
        log.log_truth_path(np.stack([x, np.zeros(60), np.zeros(60)]), 0.1 * np.arange(60))
    assert [len(s) for s in rows(path, "/world/truth", None)[0][1]["LineStrips2D:strips"]] == [30, 30]


def test_close_is_idempotent_and_rejects_logging_after(tmp_path):
    log = RerunLogger("save", tmp_path / "c.rrd")
    log.close()
    log.close()
    with pytest.raises(RuntimeError):
        log.log_map(make_grid())


def test_bad_arguments():
    with pytest.raises(ValueError, match="mode"):
        RerunLogger("sve", None)
    with pytest.raises(ValueError, match="needs a path"):
        RerunLogger("save", None)
    with pytest.raises(ValueError, match="particles_every"):
        RerunLogger("off", None, particles_every=0)
    with pytest.raises(ValueError, match="particles_max"):
        RerunLogger("off", None, particles_max=-1)


# --- pure helpers -----------------------------------------------------------------------------
def test_subsample_is_even_and_deterministic():
    idx = viz.subsample_indices(20000, 2000)
    assert idx.size == 2000 and np.unique(idx).size == 2000
    assert idx[0] == 0 and np.all(np.diff(idx) == 10)
    np.testing.assert_array_equal(viz.subsample_indices(5, 10), np.arange(5))


def test_weight_colors_heaviest_is_top_of_colormap():
    w = np.array([1.0, 1e-2, 1e-9, 0.0]) / 1.01
    c = viz.weight_colors(w)
    np.testing.assert_array_equal(c[0], viz._VIRIDIS[-1].astype(np.uint8))
    np.testing.assert_array_equal(c[2], viz._VIRIDIS[0].astype(np.uint8))  # > 3 decades below: bottom
    np.testing.assert_array_equal(c[3], viz._VIRIDIS[0].astype(np.uint8))
    assert 0 < c[1].astype(int).sum() and not np.array_equal(c[1], c[0])


def test_covariance_ellipse_rotated():
    theta = 0.3
    r = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    cov = r @ np.diag([0.09, 0.01]) @ r.T
    pts = viz.covariance_ellipse(np.array([1.0, 2.0]), cov)
    d = pts - [1.0, 2.0]
    np.testing.assert_allclose(np.einsum("ni,ij,nj->n", d, np.linalg.inv(cov), d), 4.0, rtol=1e-9)
    np.testing.assert_allclose(pts[0], pts[-1])


def test_stat_groups():
    assert viz.stat_group("ess") == "ess"
    assert viz.stat_group("particles") == "ess"
    assert viz.stat_group("time_ms/predict") == "timings"
    assert viz.stat_group("motion/foo") == "motion"
    assert viz.stat_group("predict_ms") == "timings"
    assert viz.stat_group("error_xy") == "error"
    assert viz.stat_group("tries") == "tries"
    assert viz.stat_group("foo") == "other"


def test_skipped_beams_are_drawn_over_the_scan_and_cleared_when_none(tmp_path):
    path = tmp_path / "skip.rrd"
    skipped = {1: np.array([[1.0, 2.0, 3.0], [0.5, 0.5, 0.5]]), 2: np.array([[4.0], [1.0]])}
    with RerunLogger("save", path) as log:
        for k in range(5):
            log.log_step(k, 1.0 + k, particles=np.zeros((3, 4)), weights=np.full(4, 0.25), estimate=np.zeros(3),
                         cov=np.eye(3), scan_world=np.zeros((2, 6)), skipped_world=skipped.get(k))
    r = rows(path, "/world/scan/skipped", "step")
    # nothing before skipping first shows; the step after the last skipped one clears; then nothing more
    assert [(t, len(c["Points2D:positions"])) for t, c in r] == [(1, 3), (2, 1), (3, 0)]
    assert r[0][1]["Points2D:positions"][2] == pytest.approx([3.0, 0.5])
    style = rows(path, "/world/scan/skipped", None)
    assert style and style[0][1]["Points2D:colors"] == [0x005AFFFF]  # blue: not the heaviest particles' yellow


def test_particles_every_within_a_budget():
    from mcl.viz import particles_every_within

    # an hour at 10 Hz, 181 beams, 1,000 particles: 119 MB of estimates and scans, 12.5 kB a cloud: one in 2 fits 500 MB
    assert particles_every_within(500, 36_000, 181, 1000) == 2
    assert particles_every_within(500, 3_600, 181, 1000) == 1  # six minutes: every cloud fits
    assert particles_every_within(500, 72_000, 181, 1000) == 4  # 238 MB of the rest: 20,934 clouds fit
    assert particles_every_within(0, 72_000, 181, 1000) == 1  # no budget
    assert particles_every_within(500, 36_000, 181, 1000, particles_every=7) == 7  # never lowered
    assert particles_every_within(500, 36_000, 181, 0) == 1  # no cloud logged
    assert particles_every_within(1, 1_000, 181, 1000) == 1_000  # the rest alone is over: the first cloud only
    # the bound holds exactly: the chosen stride fits, one less does not
    for u in (1_000, 2_000, 3_001):  # 5.1-15.3 MB of estimates and scans
        k = particles_every_within(20, u, 360, 2000)
        per = viz.recording_floor_mb(1, 360) * 1e6
        assert per * u + viz.CLOUD_POINT_BYTES * 2000 * math.ceil(u / k) <= 20e6
        assert per * u + viz.CLOUD_POINT_BYTES * 2000 * math.ceil(u / (k - 1)) > 20e6


def test_a_run_past_its_recording_budget_logs_the_cloud_on_fewer_updates(tmp_path):
    # A 20 s world (101 scans of 181 beams) with room for 26 clouds of 1,000 particles beyond the estimates and
    # scans: the cloud on one update in 4, said on stderr and in summary.json. The clouds' bytes, measured against
    # the same run with no cloud, are within the 12.5 bytes a point the stride is computed with (measured: 12.3;
    # 11.1 since a saved recording is cut into chunks by size alone, and no longer with the machine's load).
    from mcl.config import PROJECT_ROOT, load_config
    from mcl.runner import run
    from mcl.simulate import simulate

    simulate(tmp_path / "w", kind="office", seed=3, duration=20.0)
    per = viz.recording_floor_mb(1, 181) * 1e6
    budget = (per * 101 + viz.CLOUD_POINT_BYTES * 1000 * 26 + 500) / 1e6  # (+500 B: not at the edge of a float)
    said: list[str] = []

    start = yaml.safe_load((tmp_path / "w" / "sim.yaml").read_text())["start_pose"]

    def go(name, *sets):
        # tracking from the start pose: 5,000 particles, each cloud logged as 1,000 (a global search's 100,000 took twice
        # the time for the same recording)
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
            f"map={tmp_path / 'w' / 'map.yaml'}", f"log={tmp_path / 'w' / 'log.clf'}", "rerun.mode=save",
            "rerun.particles_max=1000", f"filter.initial_pose={list(start)}", *sets])
        s = run(cfg, tmp_path / name, progress=False, echo=said.append)
        return s, tmp_path / name / "recording.rrd"

    s, rrd = go("budget", f"rerun.budget_mb={budget}")
    assert s["recording_particles_every"] == 4
    steps = [t for t, _ in rows(rrd, "/world/estimate", "step")]
    assert len(steps) >= 100
    assert [t for t, _ in rows(rrd, "/world/particles", "step")] == steps[::4]
    assert any("one update in 4" in m and "rerun.budget_mb" in m for m in said), said
    said.clear()
    s0, rrd0 = go("none", "rerun.particles_max=0")
    clouds = rrd.stat().st_size - rrd0.stat().st_size
    logged = len(steps[::4]) * 1000
    assert 0.8 * logged * viz.CLOUD_POINT_BYTES <= clouds <= logged * viz.CLOUD_POINT_BYTES, clouds
    s1, _ = go("unbounded", "rerun.budget_mb=0")
    assert s1["recording_particles_every"] == 1 and not any("budget" in m for m in said), said

    # a budget the estimates and scans alone pass: no stride keeps it, and the line says so (it said "to keep")
    said.clear()
    s2, _ = go("under", f"rerun.budget_mb={per * 101 / 2e6}")
    assert s2["recording_particles_every"] == 101
    assert any("alone take about" in m and "over rerun.budget_mb" in m for m in said), said
    assert not any("to keep" in m for m in said), said


def test_the_scan_cost_per_beam_falls_with_the_beam_count(tmp_path):
    # The budget charged 10 B a beam, as measured at 181 beams; scans of 1,440 and 2,880 beams compress to about
    # 5.8 B a beam, so an hour of a 2,880-beam laser was given one cloud in all (18,001 updates) in 311 MB of a
    # 500 MB budget. The model is now 700 B + 5.8 B a beam: the scans' measured bytes (this run with and without
    # them) must lie within it and above 80 % of it (a model far above the cost thins the cloud for nothing).
    from mcl.config import PROJECT_ROOT, load_config
    from mcl.runner import run
    from mcl.simulate import simulate

    simulate(tmp_path / "w", kind="office", seed=3, duration=12.0, n_beams=1440, fov=2 * math.pi, range_max=30.0)

    def size(name, scan):
        cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
            f"map={tmp_path / 'w' / 'map.yaml'}", f"log={tmp_path / 'w' / 'log.clf'}", "rerun.mode=save",
            "rerun.particles_max=0", f"rerun.scan={str(scan).lower()}"])
        s = run(cfg, tmp_path / name, progress=False, echo=lambda m: None)
        return (tmp_path / name / "recording.rrd").stat().st_size, s["updates"]

    with_scan, updates = size("scan", True)
    without, _ = size("noscan", False)
    per_scan = (with_scan - without) / updates
    model = viz.recording_floor_mb(1, 1440) * 1e6 - viz.STEP_BYTES
    assert 0.8 * model <= per_scan <= model, (per_scan, model)


def test_the_clouds_kernels_give_numpys_values_to_the_bit():
    # The cloud's colours and radii (mcl.kernels.style.cloud_style) and the histogram's counts (histogram_counts)
    # replaced numpy expressions in the recording: the same values, weights of many decades, zero, equal, none
    # positive; values on the histogram's edges and next to them.
    from mcl.kernels.style import cloud_style, histogram_counts

    rng = np.random.default_rng(5)
    cases = [10.0 ** rng.uniform(-12, 0, 3000), np.r_[10.0 ** -rng.uniform(0, 4, 500), 0.0, 0.0], np.full(9, 0.1),
             np.zeros(4), np.r_[rng.random(20), np.nan], np.exp(-rng.exponential(200.0, 2000)), np.zeros(0)]
    for w in cases:
        u = viz.weight_scale(w)
        colors, radii = np.empty((w.size, 3), dtype=np.uint8), np.empty(w.size, dtype=np.float32)
        cloud_style(viz._log_relative(w), viz._WEIGHT_DECADES, viz._VIRIDIS, float(viz._FREE), True, viz._RADII,
                    viz._RADII_AT, colors, radii)
        np.testing.assert_array_equal(colors, viz.scale_colors(u, faded=True))
        np.testing.assert_array_equal(radii, rr.Radius.ui_points(viz._RADII[np.searchsorted(viz._RADII_AT, u)]))
        assert radii.dtype == np.float32
        for span in (6.0, 12.0, 48.0, 6.0 * 2.0 ** 40):
            edges = np.linspace(-span, 0.0, viz._HIST_BINS + 1)
            with np.errstate(divide="ignore", invalid="ignore"):
                rel = np.log10(np.where(w > 0, w / max(np.nanmax(w, initial=0.0), 1e-300), 0.0))
            rel = np.clip(np.nan_to_num(rel, nan=-span, neginf=-span), -span, 0.0)
            rel = np.r_[rel, edges, np.clip(np.nextafter(edges, -np.inf), -span, 0.0),
                        np.clip(np.nextafter(edges, np.inf), -span, 0.0)]
            np.testing.assert_array_equal(histogram_counts(rel, edges, np.empty(viz._HIST_BINS, dtype=np.int64)),
                                          np.histogram(rel, bins=edges)[0])


def test_a_column_of_tensors_is_what_rerun_logs_for_each():
    # rerun 0.41 converts one tensor at a time ("Tensors do not support batches"): the histogram's column of
    # TensorData is built in one go, the same arrow data as rerun's converter gives each tensor.
    rows = [np.arange(24, dtype=np.float32) * k for k in range(5)]
    ref = pa.concat_arrays([rr.components.TensorDataBatch(r).as_arrow_array() for r in rows])
    got = viz._TensorColumn(rows).as_arrow_array()
    assert got.type == ref.type and got.equals(ref)
    f64 = [np.linspace(-6.0, 0.0, 24)]
    assert viz._TensorColumn(f64).as_arrow_array().equals(rr.components.TensorDataBatch(f64[0]).as_arrow_array())


def test_a_live_viewer_waits_at_most_live_flush_s_for_the_buffered_steps_a_saved_file_goes_by_steps(tmp_path,
                                                                                                   monkeypatch):
    # every step's rows are sent as columns every COLUMN_FLUSH_STEPS steps: a live viewer (spawn, serve) then saw a
    # run at 5 Hz in jumps of 13 s; it is now sent once LIVE_FLUSH_S of wall time has passed too. A saved file's
    # chunks follow the steps alone (its layout must not follow the machine's load).
    import mcl.viz as viz

    clock = [100.0]
    monkeypatch.setattr(viz.time, "monotonic", lambda: clock[0])
    four = np.full(4, 0.25)
    for mode, want in (("save", [0]), ("spawn", list(range(10)))):
        with RerunLogger("save", tmp_path / f"{mode}.rrd") as log:
            log.mode = mode  # as a live logger decides, without a viewer to start
            flushed, real = [], log._flush_columns
            monkeypatch.setattr(log, "_flush_columns", lambda rec: (flushed.append(log._calls - 1), real(rec)))
            for k in range(10):
                clock[0] += 0.3  # each step longer than LIVE_FLUSH_S
                log.log_step(k, 0.2 * k, particles=np.zeros((3, 4)), weights=four, estimate=np.zeros(3),
                             cov=np.eye(3), stats={"ess": 4.0})
            assert sorted(set(flushed)) == want, mode  # (the first step flushes twice: its time kind is decided)
            log.mode = "save"


def test_a_stream_with_no_file_that_fails_is_one_error_naming_the_recording_not_a_traceback(tmp_path):
    # a live viewer's stream has no path: its failure went through path.name (an AttributeError)
    with RerunLogger("save", tmp_path / "r.rrd") as log:
        path, log.path = log.path, None
        with pytest.raises(OSError) as e:
            log._cut_short("the viewer went away")
        log.path = path
    assert e.value.filename == "the recording" and "could not be sent (the viewer went away)" in str(e.value)


def test_a_spawned_viewer_gone_before_the_end_loses_nothing_the_file_has_it_all(tmp_path, capsys):
    # A viewer that died (its display gone) timed the gRPC flush out: the run exited 2, "cannot write", with a whole
    # recording renamed recording.partial.rrd. The file sink has it all: now a note, the file kept under its name.
    path = tmp_path / "recording.rrd"
    log = RerunLogger("save", path)
    log.log_step(0, 1.0, particles=np.zeros((3, 4)), weights=np.full(4, 0.25), estimate=np.zeros(3), cov=np.eye(3))

    class _ViewerGone:  # the stream, whose flush to the viewer times out
        def __init__(self, rec):
            self._rec = rec

        def flush(self, **_kw):
            self._rec.flush()
            raise RuntimeError("Flush timed out")

        def __getattr__(self, name):
            return getattr(self._rec, name)

    log.mode, log._rec = "spawn", _ViewerGone(log._rec)
    log.close()
    assert path.is_file() and viz.recording_is_whole(path) and not viz.partial_recording(path).exists()
    err = capsys.readouterr().err
    assert "the Rerun viewer did not take the recording's end (Flush timed out)" in err and str(path) in err
    assert len(rows(path, "/world/estimate", "step")) == 1  # the step is in the file


def test_a_step_without_returns_clears_the_last_scan(tmp_path):
    # A hall under a 3 m laser: steps 53-98 of 99 had no returns, and step 52's scan (drawn from step 52's pose)
    # stayed on screen to the end. A step without one clears the scan and the expected scan; none before the
    # first scan logs nothing.
    path = tmp_path / "noreturn.rrd"
    scans = {1: np.ones((2, 6)), 3: np.ones((2, 4))}
    with RerunLogger("save", path) as log:
        for k in range(6):
            s = scans.get(k)
            log.log_step(k, 1.0 + k, particles=np.zeros((3, 4)), weights=np.full(4, 0.25), estimate=np.zeros(3),
                         cov=np.eye(3), scan_world=s, expected_world=s)
    for entity in ("/world/scan", "/world/scan/expected"):
        r = rows(path, entity, "step")
        assert [(t, len(c["Points2D:positions"])) for t, c in r] == [(1, 6), (2, 0), (3, 4), (4, 0)], entity
