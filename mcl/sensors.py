"""Likelihood field range finder model (Prob. Rob. Table 6.3, likelihood_field_range_finder_model).

A scan is turned once into beam endpoints in the robot frame
(``beam_endpoints``); ``LikelihoodField.log_likelihood`` then scores N poses:

    log p(z | x, m) = exponent * sum_k log(z_hit * N(d_k; 0, sigma_hit^2) + z_rand / range_max)

where d_k = min(distance from endpoint k (seen from pose x) to the nearest
occupied cell centre, likelihood_max_dist). On an occupied cell d is the
cell's depth (``interior: depth``, the default, ``field_distance``; at most
``interior_cap``) or 0 (``interior: zero``, AMCL's field and the book's as
printed); while the filter
searches or is lost, ``search_interior`` chooses (default zero). The per-cell term
is tabulated once per map as float32, so scoring is one rotation per particle and one
table gather per beam (``mcl.kernels.likelihood``).

* Endpoints that fall off the map score the value at d = likelihood_max_dist.
* Endpoints in unknown cells use the distance field like any other cell (while tracking, the filter skips those
  its estimate puts in a region the map never saw: ``sensor.unmapped_unknown``, ``ParticleFilter._on_unknown``).
* Beams without a return (>= range_max, >= the scan's own max_range, NaN,
  inf, <= range_min) are skipped: the book's "if z_t^k != z_max".
* ``exponent`` (0 < e <= 1) tempers the product of beams, which treats the
  beams as independent and is overconfident; 1.0 is the plain product.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from mcl.kernels.field import far_runs
from mcl.kernels.likelihood import (beam_explained_weight, free_ray_loglik, free_ray_loglik_serial,
                                   likelihood_field_loglik, likelihood_field_loglik_serial)
from mcl.kernels.raycast import cast_rays_serial, segments_blocked
from mcl.kernels.segments import small_segments
from mcl.estimate import compose
from mcl.maps import byte_mask
from mcl.parallel import check_out, choose


def no_return_range(range_max: float, max_range) -> float:
    """The range at and beyond which a reading means no return: ``sensor.range_max``, or the scan's own
    ``max_range`` (None: unknown) when that is smaller."""
    if max_range is not None and 0.0 < float(max_range) < float(range_max):
        return float(max_range)
    return float(range_max)


def beam_selection(ranges, angles, max_range, cfg) -> np.ndarray:
    """(K,) int64 indices into the scan of the beams a model scores: up to ``max_beams`` evenly spaced over all
    B beams (AMCL: indices round(linspace(0, B-1, max_beams))), then those without a valid return dropped
    (range_min < r < range_max, r < max_range if given, finite), so the chosen directions do not depend on which
    beams happen to have returns."""
    r = np.asarray(ranges, dtype=np.float64).ravel()
    a = np.asarray(angles, dtype=np.float64).ravel()
    if r.shape != a.shape:
        raise ValueError(f"ranges and angles differ in length: {r.size} vs {a.size}")
    b = r.size
    max_beams = int(cfg.max_beams)
    if max_beams < 1:
        raise ValueError(f"sensor.max_beams: must be >= 1, got {max_beams}")
    sel = _evenly_spaced(b, max_beams)
    return sel[valid_returns(r[sel], max_range, cfg)]


def scored_view(scan, cfg) -> tuple[np.ndarray, float]:
    """(the indices of the beams a model scores, with or without a return: AMCL's ``max_beams`` evenly spaced; the
    laser's reach in m: ``no_return_range``) of ``scan``."""
    return _evenly_spaced(len(scan.angles), int(cfg.max_beams)), no_return_range(
        cfg.range_max, getattr(scan, "max_range", None))


def cast_from_laser(blocked, origin, resolution: float, pose, laser_pose, angles, reach: float) -> np.ndarray:
    """(A,) the ranges the map gives along ``angles`` (laser frame) from the laser at ``laser_pose`` (robot frame)
    on ``pose``, cast through ``blocked`` up to ``reach`` (``reach``: nothing met): the scan the map predicts."""
    at = compose(np.asarray(pose, dtype=np.float64), np.asarray(laser_pose, dtype=np.float64))[:, None]
    out = np.empty((1, len(angles)))
    cast_rays_serial(at, np.ascontiguousarray(angles, dtype=np.float64), blocked, float(origin[0]), float(origin[1]),
                     float(resolution), float(reach), out)
    return out[0]


@functools.lru_cache(maxsize=64)
def _evenly_spaced(b: int, max_beams: int) -> np.ndarray:
    """(K,) int64, read-only: round(linspace(0, b - 1, max_beams)) without repeats, or every beam when b <= max_beams.
    Made once per scan geometry: a log's scans all have the same beam count."""
    sel = (np.unique(np.rint(np.linspace(0.0, b - 1, max_beams)).astype(np.int64)) if b > max_beams
           else np.arange(b, dtype=np.int64))
    sel.setflags(write=False)
    return sel


def valid_returns(ranges, max_range, cfg) -> np.ndarray:
    """(B,) bool: the readings with a return, range_min < r < range_max, r < max_range (the scan's own no-return
    value, if given), finite."""
    r = np.asarray(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(r) & (r > float(cfg.range_min)) & (r < float(cfg.range_max))
        if max_range is not None:
            valid &= r < float(max_range)
    return valid


def beam_endpoints(ranges, angles, max_range, cfg, laser_pose=(0.0, 0.0, 0.0), sweep=None) -> np.ndarray:
    """(2, K) float64 endpoints, in the robot frame, of the valid beams of one scan.

    ranges, angles: (B,) readings (m) and beam angles in the laser frame (rad).
    max_range: the scan's own no-return value, or None.
    cfg: reads range_min, range_max, max_beams.
    laser_pose: (x, y, theta) of the laser in the robot frame.
    sweep: None, or (tau (B,), twist (3,)) from ``sweep_of``: beam j was taken tau[j] s after the scan's stamp
    while the robot moved at twist = (vx, vy, omega) in its own frame; its endpoint is then moved into the robot
    frame at the stamp (deskewed).

    The beams are ``beam_selection``'s (AMCL's subsampling: evenly spaced over *all* B beams, then the invalid
    ones among them dropped, so K <= max_beams).
    """
    r = np.asarray(ranges, dtype=np.float64).ravel()
    a = np.asarray(angles, dtype=np.float64).ravel()
    sel = beam_selection(r, a, max_range, cfg)
    r, a = r[sel], a[sel]
    lx, ly, lth = (float(v) for v in laser_pose)
    ang = a + lth
    out = np.empty((2, r.size))
    out[0] = lx + r * np.cos(ang)
    out[1] = ly + r * np.sin(ang)
    if sweep is not None:
        tau, twist = sweep
        out[0], out[1], _ = _at_stamp(out[0], out[1], np.asarray(tau, dtype=np.float64)[sel], twist)
    return out


def _at_stamp(x, y, tau, twist):
    """(x, y, turn): the points (x, y) of the robot frame at tau s after a scan's stamp, in the robot frame at the
    stamp, and the turn between the two frames, while the robot moves at twist = (vx, vy, omega) in its own frame:
    the robot at tau seen from the robot at the stamp is (vx tau, vy tau, omega tau) to first order."""
    vx, vy, w = twist
    turn = w * tau
    c, s = np.cos(turn), np.sin(turn)
    return vx * tau + c * x - s * y, vy * tau + s * x + c * y, turn


class Endpoints(np.ndarray):
    """(2, K) robot-frame endpoints (``beam_endpoints``) that also carry the scan's no-return beams: ``free`` (4, R),
    each one's laser position and unit direction in the robot frame (``no_return_rays``), and ``reach`` (m). A
    view or a selection of the endpoints keeps them (beams left out of a scan are beams with a return)."""

    def __new__(cls, endpoints, free, reach: float):
        obj = np.asarray(endpoints).view(cls)
        obj.free = free
        obj.reach = float(reach)
        return obj

    def __array_finalize__(self, obj):
        self.free = getattr(obj, "free", None)
        self.reach = getattr(obj, "reach", 0.0)


def no_return_rays(ranges, angles, max_range, cfg, laser_pose=(0.0, 0.0, 0.0), sweep=None) -> np.ndarray:
    """(4, R): the laser's position (x, y) and the unit direction (ux, uy) in the robot frame of each beam among
    the scored ones (``scored_view``: evenly spaced over all beams) that read no return (at or past the laser's
    no-return range, or +inf); ``sweep`` as ``beam_endpoints``' (each ray moved into the robot frame at the
    stamp)."""
    r = np.asarray(ranges, dtype=np.float64).ravel()
    a = np.asarray(angles, dtype=np.float64).ravel()
    sel = _evenly_spaced(r.size, int(cfg.max_beams))
    reach = no_return_range(cfg.range_max, max_range)
    with np.errstate(invalid="ignore"):
        none = r[sel] >= reach  # +inf too; NaN (invalid) is not a no-return
    lx, ly, lth = (float(v) for v in laser_pose)
    ang = a[sel][none] + lth
    out = np.empty((4, ang.size))
    out[0], out[1] = lx, ly
    if sweep is not None:
        tau, twist = sweep
        out[0], out[1], turn = _at_stamp(lx, ly, np.asarray(tau, dtype=np.float64)[sel][none], twist)
        ang = ang + turn
    out[2], out[3] = np.cos(ang), np.sin(ang)
    return out


def sweep_of(scan):
    """(tau (B,), twist (3,)) for ``beam_endpoints``' deskewing of a ``Scan`` whose beam times and robot velocity
    are known (``Scan.beam_dt``, ``Scan.twist``), else None."""
    twist = getattr(scan, "twist", None)
    dt = float(getattr(scan, "beam_dt", 0.0))
    if twist is None or dt == 0.0:
        return None
    n = np.asarray(scan.ranges).shape[0]
    return float(getattr(scan, "beam_t0", 0.0)) + dt * np.arange(n, dtype=np.float64), twist


def scan_endpoints(scan, cfg, laser_pose=None) -> np.ndarray:
    """``beam_endpoints`` for a ``Scan`` record (ranges, angle_min, angle_increment, max_range, laser_offset).

    The laser pose is the argument if given, else ``cfg.laser_pose`` if set,
    else the scan's own ``laser_offset``, else the robot origin.
    """
    ranges = np.asarray(scan.ranges, dtype=np.float64)
    angles = getattr(scan, "angles", None)
    if angles is None:
        angles = float(scan.angle_min) + float(scan.angle_increment) * np.arange(ranges.size)
    if laser_pose is None:
        laser_pose = getattr(cfg, "laser_pose", None)
    if laser_pose is None:
        laser_pose = getattr(scan, "laser_offset", None)
    if laser_pose is None:
        laser_pose = (0.0, 0.0, 0.0)
    return beam_endpoints(ranges, angles, getattr(scan, "max_range", None), cfg, laser_pose, sweep_of(scan))


def point_log_likelihood(d, cfg) -> np.ndarray:
    """log(z_hit * N(min(d, likelihood_max_dist); 0, sigma_hit^2) + z_rand / range_max), float64.

    ``cfg``: a SensorConfig (its likelihood_field block is read) or a namespace with the keys flat."""
    from mcl.config import sensor_model_view

    cfg = sensor_model_view(cfg, "likelihood_field")
    sigma = float(cfg.sigma_hit)
    d = np.minimum(np.asarray(d, dtype=np.float64), float(cfg.likelihood_max_dist))
    gauss = np.exp(-0.5 * (d / sigma) ** 2) / (math.sqrt(2.0 * math.pi) * sigma)
    with np.errstate(divide="ignore"):
        out = np.log(float(cfg.z_hit) * gauss + float(cfg.z_rand) / float(cfg.range_max))
    if float(cfg.z_rand) == 0.0 and float(cfg.z_hit) > 0.0:
        # exp(-(d/sigma)^2 / 2) underflows to 0 past d = 38.6 sigma: with z_rand 0 the log was -inf there (every
        # particle at weight 0 on a scan with one far endpoint) where the model's is finite: taken in log space
        out = np.where(np.isneginf(out), math.log(float(cfg.z_hit)) - 0.5 * (d / sigma) ** 2
                       - math.log(math.sqrt(2.0 * math.pi) * sigma), out)
    return out


def field_distance(grid, cfg, interior: str | None = None) -> np.ndarray:
    """The d the likelihood field scores, per cell: ``grid.distance`` (``interior: zero``: 0 on every occupied
    cell, AMCL's field and the book's as printed) or ``grid.surface_distance(interior_tolerance)`` (``interior:
    depth``: on an occupied cell its depth less the tolerance, as a map draws its walls a cell or so thicker than
    the surface the laser sees, and at most ``interior_cap``); with ``surface: face`` or a cap, a new array
    (``field_rows``).
    ``cfg``: a SensorConfig or a flat namespace; ``interior`` overrides its ``interior`` (the search field passes
    ``search_interior``)."""
    from mcl.config import sensor_model_view

    view = sensor_model_view(cfg, "likelihood_field")
    tolerance = _depth_tolerance(view, interior, grid)
    if surface_at_faces(view) or (tolerance is not None and _depth_cap(view) is not None):
        rows, patches = field_rows(grid, view, interior)
        d = np.empty(np.shape(grid.distance), dtype=np.float32)
        step = max(1, (1 << 20) // max(d.shape[1], 1))
        for r in range(0, d.shape[0], step):
            d[r:r + step] = rows(r, r + step)
        for y0, y1, x0, x1, mine, metres in patches:
            d[y0:y1, x0:x1][mine] = metres
        return d
    return grid.distance if tolerance is None else grid.surface_distance(tolerance)


def field_rows(grid, cfg, interior: str | None = None):
    """``field_distance`` without a copy of the whole map: ``(rows, patches)``. ``rows(r0, r1)`` gives the field's
    rows r0:r1 (float32, a view of ``grid.distance`` or a new array) before ``patches`` are laid on them:
    (y0, y1, x0, x1, mine, metres) per tile, ``mine`` the tile's bool mask of cells set to ``metres`` (the cells
    deeper than one cell under ``interior: depth``, ``grid.surface_patches``). The likelihood field's tables and
    the recording's field layer are made from these (a 144 M-cell map: 576 MB per whole copy). A grid without
    ``surface_patches`` (tests' stand-ins) gives rows of its ``surface_distance`` and no patches. ``interior_cap``
    bounds the depths (the patches'; the rows' occupied cells are at most half a cell deep, face, or 0, centre)."""
    from mcl.config import sensor_model_view

    view = sensor_model_view(cfg, "likelihood_field")
    tolerance = _depth_tolerance(view, interior, grid)
    cap = None if tolerance is None else _depth_cap(view)  # depth only
    top = np.float32(np.inf if cap is None else cap)
    surface_patches = getattr(grid, "surface_patches", None)
    dist = grid.distance
    if surface_at_faces(view):
        # d to the faces: on a free cell half a cell less than from its centre to the nearest occupied centre
        # (exact to a wall's face in line with the grid); on an occupied cell 0 (interior: zero) or its depth from
        # its centre to the nearest face less the tolerance: surface_distance(0), 0 on a face cell, plus half a cell
        half = np.float32(0.5 * float(grid.resolution))
        lift = None if tolerance is None else np.float32(0.5 * float(grid.resolution) - tolerance)
        if lift is not None and surface_patches is None:
            dist = grid.surface_distance(0.0)
        occupied = grid.occupied

        def face_rows(r0: int, r1: int) -> np.ndarray:
            base = dist[r0:r1]
            d = np.maximum(base - half, np.float32(0.0))
            occ = occupied[r0:r1]
            d[occ] = 0.0 if lift is None else np.clip(base[occ] + lift, np.float32(0.0), top)
            return d

        patches = ([] if lift is None or surface_patches is None else
                   [(y0, y1, x0, x1, mine, np.clip(metres + lift, np.float32(0.0), top))
                    for y0, y1, x0, x1, mine, metres in surface_patches(0.0)])
        return face_rows, patches
    if tolerance is not None and surface_patches is None:
        dist, patches = grid.surface_distance(tolerance), []
        if cap is not None:  # a stand-in's whole depth field: capped on its occupied cells, in a copy
            dist = np.where(grid.occupied, np.minimum(dist, top), dist).astype(np.float32)
    else:
        patches = [] if tolerance is None else surface_patches(tolerance)
        if cap is not None:
            patches = [(y0, y1, x0, x1, mine, np.minimum(metres, top)) for y0, y1, x0, x1, mine, metres in patches]
    return (lambda r0, r1: dist[r0:r1]), patches


def surface_at_faces(cfg) -> bool:
    """``surface: face`` in the likelihood field's view ``cfg`` (a flat namespace without the key: centre).
    On such maps ``centre`` puts the estimate half a cell or more ahead: a pose whose readings sink into the walls
    ahead fits best (4.5 cm at 5 cm: docs/measurements.md, "Forty-first session")."""
    return getattr(cfg, "surface", "centre") == "face"


DEPTH_TOLERANCE = 0.05  # m: ``interior_tolerance: null`` is this or one cell of the map, whichever is more


def _depth_cap(cfg) -> float | None:
    """``interior_cap`` of the likelihood field's view ``cfg`` (m; None: the depth is not bounded; a flat namespace
    without the key: None). An endpoint deeper inside a mapped obstacle than the cap scores as one the cap deep: a
    return from the wall behind furniture moved since the map was made lies inside the furniture the map still
    shows, at the true pose. Scored by its full depth (0.3 m: 4.5 nats under a hit, as bad as a reading 2 m from any
    wall), that one beam made a pose 0.6 m along a corridor, where it met the furniture's face, outscore the true one
    by 3-5 nats a scan, and the track followed (suites/heldout6.yaml corridor-270-moved-furniture-h13: max 0.70 and
    1.14 m; with a cap of 0.1 m, 0.29 and 0.43 m: docs/measurements.md, "Fifty-third session"). Below the cap the
    depth still scores: a pose too far forward sinks many returns into the walls ahead. Off by default: the large
    generated buildings' searches tell look-alike rooms apart by the full depth."""
    cap = getattr(cfg, "interior_cap", None)
    return None if cap is None else float(cap)


def _depth_tolerance(cfg, interior: str | None, grid=None) -> float | None:
    """The tolerance the depth field takes off (m) when the field scores depth inside obstacles (``interior``,
    else the config's ``interior``, is ``depth``); None for ``zero``. ``cfg``: the likelihood field's view of the
    sensor config. Its ``interior_tolerance`` when that is a number; null (the default) is 0 on a map drawn solid
    (``drawn_solid``: from geometry, 5 cm cells or finer), else DEPTH_TOLERANCE or one cell of ``grid``, whichever
    is more, so a map coarser than 5 cm gets the tolerance the 5 cm maps have in cells.
    With 0.05 m on a 10 cm map with clutter (suites/heldout2.yaml clutter-map10cm-h9) correct returns counted as
    readings inside walls: the filter's likelihood favoured places 4-8 m off by 13-16 nats a scan, and every global
    run was lost (docs/measurements.md, "Twenty-eighth session")."""
    if (interior or getattr(cfg, "interior", "zero")) == "zero":
        return None
    tolerance = getattr(cfg, "interior_tolerance", 0.0)
    if tolerance is None:
        if surface_at_faces(cfg) or drawn_solid(grid):  # a floor plan's walls are as thick as drawn
            return 0.0
        return max(DEPTH_TOLERANCE, float(getattr(grid, "resolution", 0.0)))
    return float(tolerance)


def solid_map_takes_tolerance_off(cfg, grid) -> bool:
    """Whether ``_depth_tolerance`` is 0 for the tracking field because ``grid`` is drawn solid (``drawn_solid``),
    not for a setting: the field scores depth (``interior: depth``), ``interior_tolerance`` is null and the
    surface is the centre. ``cfg``: the likelihood field's view of the sensor config. The run says so in a note."""
    return (getattr(cfg, "interior", "zero") == "depth" and getattr(cfg, "interior_tolerance", 0.0) is None
            and not surface_at_faces(cfg) and drawn_solid(grid))


SOLID_SHARE = 0.3  # a map whose occupied cells lie deeper than one cell this often or more was drawn from geometry


def drawn_solid(grid) -> bool:
    """Whether ``grid`` (5 cm cells or finer) has its walls drawn solid, from geometry (``OccupancyGrid.solid_share``
    at least ``SOLID_SHARE``): a floor plan, CAD or ``mcl simulate`` map, whose walls are exactly where the laser
    sees them, so ``interior_tolerance: null`` is 0 there. The 0.05 m tolerance is for maps drawn by returns (SLAM),
    whose walls are about a cell thicker than the surface (0.01-0.20 of their occupied cells lie deeper than one
    cell; the generated worlds' 0.33-0.63). On a solid map the tolerance makes a corridor the raster drew one cell
    narrower than another fit better: every return sinks into its walls within the tolerance while at the true
    place half of them fall one cell short in free space, 0.12 nats each (suites/synthetic.yaml corridor-04 global
    s2: a look-alike 19 m off out-scored the truth by 3 nats a scan). With 0 there: synthetic tracking 128/129
    within 0.5 m against 126, global 114/126 against 112, kidnapped 110/117 against 108, seeds 1-3; every shared
    log is the same run (docs/measurements.md, "Sixty-third session"). A coarser map keeps one cell: a mapping
    run at 10 cm draws a wall's surface up to a cell inside it (suites/heldout2.yaml clutter-map10cm-h9)."""
    share = getattr(grid, "solid_share", None)
    return (share is not None and float(getattr(grid, "resolution", 1.0)) <= DEPTH_TOLERANCE + 1e-9
            and share >= SOLID_SHARE)


SKIP_SUPPORT_PARTICLES = 500  # beam skipping estimates each beam's support from at most this many particles


class LikelihoodField:
    """Likelihood field sensor model over an ``OccupancyGrid``.

    ``grid`` needs ``distance`` (or ``surface_distance(tolerance)`` with ``interior:
    depth``; float (H, W), row 0 at the bottom, see ``field_distance``), ``origin``
    (x0, y0) and ``resolution``. ``cfg`` is read duck-typed: z_hit, z_rand, sigma_hit,
    likelihood_max_dist, interior, interior_tolerance, search_interior, range_max,
    exponent (a SensorConfig: its common keys and sensor.likelihood_field).

    Two tables when ``search_interior`` differs from ``interior``: ``log_likelihood(...,
    searching=True)`` reads the second, made on first use (a track that is never
    lost never builds it).
    """

    def __init__(self, grid, cfg):
        from mcl.config import sensor_model_view

        cfg = sensor_model_view(cfg, "likelihood_field")
        self.cfg = cfg
        self.table = self._make_table(grid, None)
        self._search_table = None  # the search_interior table, when it differs (made on first use)
        # off-map endpoints: the value at likelihood_max_dist (float32 like the table)
        self.offmap = float(np.float32(point_log_likelihood(float(cfg.likelihood_max_dist), cfg)))
        self.origin = (float(grid.origin[0]), float(grid.origin[1]))
        self.resolution = float(grid.resolution)
        self.inv_res = 1.0 / self.resolution
        self.exponent = float(getattr(cfg, "exponent", 1.0))
        self._grid = grid  # beam skipping (float32 distances, the occupied mask) and the search table, on first use
        self.dist = None
        self.blocked = None
        self.no_return_miss = float(getattr(cfg, "no_return_miss", 0.0))

    def prepare(self, scan, laser_pose) -> np.ndarray:
        """The observation this model scores, made once per scan: robot-frame beam endpoints (2, K); with
        ``no_return_miss``, an ``Endpoints`` that carries the no-return beams too."""
        sweep = sweep_of(scan)
        e = beam_endpoints(scan.ranges, scan.angles, scan.max_range, self.cfg, laser_pose, sweep)
        if self.no_return_miss > 0.0:
            free = no_return_rays(scan.ranges, scan.angles, scan.max_range, self.cfg, laser_pose, sweep)
            scored, limit = scored_view(scan, self.cfg)
            if free.shape[1] and free.shape[1] >= float(self.cfg.no_return_share) * scored.size:
                e = Endpoints(e, free, float(self.cfg.no_return_reach) * limit)
        return e

    @staticmethod
    def endpoints(observation) -> np.ndarray:
        """(2, K) robot-frame endpoints of the beams with a return (for the quality signal): the observation."""
        return observation

    def _make_table(self, grid, interior: str | None) -> np.ndarray:
        # from the field's rows and patches (``field_rows``): ``interior: depth`` is ``distance`` with the tiles where
        # the depth field differs rewritten, ``surface: face`` each block shifted by half a cell, and no copy of the
        # whole map is made to build the table from (the same values)
        rows, patches = field_rows(grid, self.cfg, interior)
        # in row blocks that stay in cache: the same values, 2.7 s -> 0.5 s on a 100 M-cell map, no float64 copy;
        # a cell at likelihood_max_dist or farther has the value there (the model clamps d), so the exponentials run
        # only on the cells nearer a wall (a building in a 500 m map of unknown cells: 3.0 s -> 0.5 s)
        table = np.empty(np.shape(grid.distance), dtype=np.float32)
        far_d = float(self.cfg.likelihood_max_dist)
        far = np.float32(point_log_likelihood(far_d, self.cfg))
        step = max(1, (1 << 15) // max(table.shape[1], 1))
        for r in range(0, table.shape[0], step):
            block, out = rows(r, r + step), table[r:r + step]
            near = block < far_d
            if near.all():
                out[:] = point_log_likelihood(block, self.cfg)
            else:
                out[:] = far
                out[near] = point_log_likelihood(block[near], self.cfg)
        for y0, y1, x0, x1, mine, metres in patches:
            table[y0:y1, x0:x1][mine] = point_log_likelihood(metres, self.cfg)
        return table

    def search_table(self) -> np.ndarray:
        """The table scored while the filter searches or is lost: ``search_interior``'s field."""
        if self._search_table is None:
            interior = getattr(self.cfg, "interior", "zero")
            search = getattr(self.cfg, "search_interior", interior)
            table = self.table if search == interior else self._make_table(self._grid, search)
            solid = float(getattr(self.cfg, "search_solid", 0.0) or 0.0)
            find = getattr(self._grid, "solid_regions", None)  # (tests' stand-in grids have none)
            regions = find(solid) if find is not None and search == "zero" and solid > 0.0 else None
            if regions is not None:
                # the solid regions' cells as the depth field has them (its tolerance): a search's pose that lays
                # returns metres deep into a floor plan's black outside is not a fit (AMCL's field: a perfect one)
                table = table.copy() if table is self.table else table
                _, patches = field_rows(self._grid, self.cfg, "depth")
                for y0, y1, x0, x1, mine, metres in patches:
                    inside = regions[y0:y1, x0:x1][mine]
                    if inside.any():
                        cells = table[y0:y1, x0:x1]
                        values = cells[mine]
                        values[inside] = point_log_likelihood(metres[inside], self.cfg)
                        cells[mine] = values
            self._search_table = table
        return self._search_table

    def log_likelihood(self, particles, endpoints, out=None, searching: bool = False) -> np.ndarray:
        """(N,) float64: exponent * sum over beams of the table value at each rotated endpoint.

        particles: (3, N) float64 world poses; endpoints: (2, K) robot-frame
        endpoints from ``beam_endpoints``. K = 0 gives zeros (no information).
        ``searching``: score with ``search_interior``'s field (``search_table``).
        """
        p = np.ascontiguousarray(particles, dtype=np.float64)
        if p.ndim != 2 or p.shape[0] != 3:
            raise ValueError(f"particles: expected shape (3, N), got {p.shape}")
        e = np.asarray(endpoints, dtype=np.float64)
        if e.ndim != 2 or e.shape[0] != 2:
            raise ValueError(f"endpoints: expected shape (2, K), got {e.shape}")
        e_cells = np.ascontiguousarray(e * self.inv_res)
        if out is None:
            out = np.empty(p.shape[1])
        else:
            check_out(out, (p.shape[1],))
        kernel = choose(likelihood_field_loglik, likelihood_field_loglik_serial, p.shape[1] * e_cells.shape[1])
        table = self.search_table() if searching else self.table
        kernel(p, e_cells, table, self.origin[0], self.origin[1], self.inv_res, self.offmap, self.exponent, out)
        free = getattr(endpoints, "free", None)
        if free is not None and free.shape[1] and self.no_return_miss > 0.0:
            if self.dist is None:
                self.dist = np.ascontiguousarray(self._grid.distance, dtype=np.float32)
            kernel = choose(free_ray_loglik, free_ray_loglik_serial, p.shape[1] * free.shape[1] * 8)
            kernel(p, free, self.dist, self.origin[0], self.origin[1], self.inv_res, float(endpoints.reach),
                   math.log(self.no_return_miss), self.exponent, out)
        return out

    def beam_support(self, particles, weights, endpoints) -> np.ndarray:
        """(K,) for each beam, the weight of the particles that explain it (endpoint within beam_skip_distance
        of a mapped obstacle). One serial numba kernel.

        Above SKIP_SUPPORT_PARTICLES particles, every k-th particle is used (weights renormalised): the
        fraction is then estimated to about 0.02 (standard error of a 500-sample proportion is at most
        0.022), enough for a threshold like 0.5, at a fixed cost whatever N (with 2,000 it cost as much as
        the 5,000-particle likelihood update itself).
        """
        p = np.asarray(particles, dtype=np.float64)
        n = p.shape[1]
        if n > SKIP_SUPPORT_PARTICLES:
            step = -(-n // SKIP_SUPPORT_PARTICLES)
            p = p[:, ::step]
            weights = np.asarray(weights, dtype=np.float64)[::step]
            total = float(weights.sum())
            weights = weights / total if total > 0 else np.full(p.shape[1], 1.0 / p.shape[1])
        e_cells = np.ascontiguousarray(np.asarray(endpoints, dtype=np.float64) * self.inv_res)
        out = np.empty(e_cells.shape[1])
        if self.dist is None:
            self.dist = np.ascontiguousarray(self._grid.distance, dtype=np.float32)
        beam_explained_weight(np.ascontiguousarray((p[0] - self.origin[0]) * self.inv_res),
                              np.ascontiguousarray((p[1] - self.origin[1]) * self.inv_res),
                              np.cos(p[2]), np.sin(p[2]), np.ascontiguousarray(weights, dtype=np.float64),
                              e_cells, self.dist, float(self.cfg.beam_skip_distance), out)
        return out

    def see_through(self, pose, laser_xy, endpoints) -> np.ndarray:
        """(K,) bool: seen from ``pose`` (x, y, theta), does beam k's reading cross a mapped obstacle before its
        endpoint? ``laser_xy``: the laser's position in the robot frame. One exact ray walk per beam."""
        if self.blocked is None:
            self.blocked = byte_mask(self._grid.occupied)
        e = np.ascontiguousarray(endpoints, dtype=np.float64)
        out = np.zeros(e.shape[1], dtype=np.bool_)
        segments_blocked(float(pose[0]), float(pose[1]), float(pose[2]), float(laser_xy[0]), float(laser_xy[1]), e,
                         self.blocked, self.origin[0], self.origin[1], self.resolution, out)
        return out

    def skip_mask(self, particles, weights, endpoints, pose=None, laser_xy=(0.0, 0.0)) -> np.ndarray:
        """Beam skipping (after AMCL ``likelihood_field_prob``): (K,) bool, True for the beams to ignore.

        A beam is *unexplained* when the particles whose view puts its endpoint
        within ``beam_skip_distance`` of a mapped obstacle weigh no more than
        ``beam_skip_threshold``. With ``beam_skip_rule: amcl`` every unexplained
        beam is skipped. With ``short`` (the default) only those that, seen from
        ``pose`` (the filter's estimate), end in free space in front of the
        mapped surface: an unmapped obstacle (a person, a box) can only make a
        reading *shorter*, so a reading that went through a mapped wall is
        evidence that the pose is wrong and is always scored. Without ``pose``
        the rule falls back to AMCL's. If the skipped beams would reach
        ``beam_skip_error_threshold`` of the scan, the filter (not the world) is
        probably wrong and no beam is skipped. Call only once the filter has converged.
        """
        e = np.asarray(endpoints, dtype=np.float64)
        k = e.shape[1]
        if k == 0:
            return np.zeros(0, dtype=bool)
        skip = self.beam_support(particles, weights, e) <= float(self.cfg.beam_skip_threshold)
        if skip.any() and pose is not None and getattr(self.cfg, "beam_skip_rule", "amcl") == "short":
            idx = np.flatnonzero(skip)
            skip[idx[self.see_through(pose, laser_xy, e[:, idx])]] = False
        if np.count_nonzero(skip) >= float(self.cfg.beam_skip_error_threshold) * k:
            skip[:] = False
        return skip

class BeamSkipping:
    """Beam skipping as a policy of the filter (``sensor.beam_skip``; ``LikelihoodField.skip_mask``).

    It acts only once the filter has converged: the heaviest cluster holds at
    least half the weight and its x/y spread is below ``beam_skip_distance``
    (``observe_estimate``, after each update's estimate).
    """

    def __init__(self, sensor, cfg):
        self.sensor = sensor
        self.cfg = cfg
        self.converged = False

    def observe_estimate(self, est) -> None:
        spread = math.sqrt(max(est.cov[0, 0], est.cov[1, 1], 0.0))
        self.converged = est.weight >= 0.5 and spread < self.cfg.beam_skip_distance

    def select(self, particles, weights, observation, pose, laser_xy):
        """(the observation to score, the skipped robot-frame endpoints (2, k) or None)."""
        if not self.converged:
            return observation, None
        skip = self.sensor.skip_mask(particles, weights, observation, pose=pose, laser_xy=laser_xy)
        if not skip.any():
            return observation, None
        return np.require(observation[:, ~skip], requirements="C"), observation[:, skip]


class UnmappedObjects:
    """Skip the beams that hit small objects the map lacks, while tracking (``sensor.unmapped_skip``).

    A person standing at a corridor's junction hides the junction's opening from a few beams; scored against
    the likelihood field, those short readings fit the junction's walls better from a pose 1-3 m along the
    corridor than from the true pose (suites/synthetic.yaml corridor-05: by 8-40 nats an update for seconds),
    and the cloud follows. A beam is skipped when

    * it belongs to a small segment of the whole scan (``mcl.kernels.segments.small_segments``: consecutive
      readings within ``unmapped_jump`` of each other, end to end narrower than ``unmapped_width``), and
    * seen from the estimate, its endpoint lies farther than ``unmapped_distance`` from every mapped obstacle
      (a mapped pillar or door post fits the map and is kept; an endpoint inside a wall says the pose is wrong
      and is kept; so is an endpoint off the map), and
    * no one of the shifts the filter passes (``ParticleFilter._unmapped_shifts``: the estimate moved forward
      along the cloud's major axis, out to ``unmapped_spread`` std) puts the whole run of neighbouring candidates
      on the map. A cloud lagging along a corridor sees walls ahead short of the map: the side corridor's far
      wall through the junction's opening is a small segment 0.5-1 m off the map from the estimate, and its
      beams correct the lag (infinite_corridor, corridor-02). A person in the corridor stays off the map from
      every shift.

    Unlike beam skipping it asks nothing of the particles, and it leaves a corridor's far wall alone when the
    cloud lags behind the robot (a wide segment). If it would skip half the beams or more, the estimate is
    more likely wrong than the world full of people: none is skipped. The filter decides when to call it
    (``ParticleFilter._tracking_unmapped``, ``_skip_unmapped``): from a wrong estimate the map test means nothing.
    """

    def __init__(self, grid, cfg, dist=None):
        self.cfg = cfg
        self.dist = dist if dist is not None else np.ascontiguousarray(grid.distance, dtype=np.float32)
        self.origin = (float(grid.origin[0]), float(grid.origin[1]))
        self.resolution = float(grid.resolution)

    BLIND_WIDTH = 2.5  # m: with nothing mapped in view (blind), a segment this long is a wall the map should show
    BLIND_MARGIN = 1.0  # m: "in view" reaches this far beyond the laser's range
    BLIND_DISTANCE = 1.0  # m: blind, an endpoint is skipped only this far from every mapped obstacle: a few readings
    # of a wall at the laser's limit, seen from an estimate a few decimetres off, are all the scan says (large-06)
    BLIND_SIGMAS = 3.0  # or this many std of the endpoint's offset across its ray, when larger (blind_distance)

    def candidates(self, scan, width: float | None = None) -> np.ndarray | None:
        """(K,) bool over the beams ``beam_endpoints`` keeps for ``scan``: those in a segment narrower than
        ``width`` (default ``unmapped_width``; with a width given, the segments at the scan's ends too, by the part
        seen); None when the scan's beams are not in angular order (a fused scan: no neighbours to compare)."""
        r = np.asarray(scan.ranges, dtype=np.float64).ravel()
        a = np.asarray(scan.angles, dtype=np.float64).ravel()
        if r.size < 3 or not np.all(np.diff(a) > 0.0):
            return None
        max_range = getattr(scan, "max_range", None)
        small = np.empty(r.size, dtype=np.bool_)
        small_segments(r, a, valid_returns(r, max_range, self.cfg), float(self.cfg.unmapped_jump),
                       float(self.cfg.unmapped_width if width is None else width), small, width is not None)
        return small[beam_selection(r, a, max_range, self.cfg)]

    def view(self, scan):
        """(the directions of the beams a model scores, with or without a return: (A,) rad; the laser's reach in m)
        of ``scan``, for :meth:`blind`."""
        idx, reach = scored_view(scan, self.cfg)
        return np.ascontiguousarray(np.asarray(scan.angles, dtype=np.float64).ravel()[idx]), reach

    def any_far(self, observation, pose, distance: float) -> bool:
        """Whether some endpoint of ``observation`` (robot frame, (2, K)), seen from ``pose``, lies farther than
        ``distance`` from every mapped obstacle (one field lookup each: :meth:`blind`'s cast is needed only then)."""
        if observation.shape[1] == 0:
            return False
        idx = np.arange(observation.shape[1])
        far = np.empty(idx.size, dtype=np.bool_)
        th = float(pose[2])
        return far_runs(self.dist, self.origin[0], self.origin[1], self.resolution, float(pose[0]), float(pose[1]),
                        math.cos(th), math.sin(th), np.ascontiguousarray(observation, dtype=np.float64), idx,
                        _NO_SHIFTS, _NO_SHIFTS, np.full(idx.size, distance, dtype=np.float32), far) > 0

    def blind_distance(self, observation, pose, cov, least: float) -> np.ndarray:
        """(K,) float32: how far from every mapped obstacle each endpoint of ``observation`` (robot frame, (2, K)),
        seen from ``pose``, must lie to be skipped on a blind update: ``least`` m, or ``BLIND_SIGMAS`` times
        the std of the endpoint's offset *across* its ray that the estimate's covariance ``cov`` (3x3: x, y,
        theta) gives, when that is larger.

        Dead reckoning over a stretch with no return makes the cloud's heading uncertain, and a rotation moves a
        far endpoint across its ray by range x angle: with 0.2 rad of heading std, the wall 12 m away that ends a
        blind stretch reads 2-4 m off the map from the estimate, and skipping it left the filter on dead reckoning
        for good (suites/sparse-hall.yaml hall-sweep-fast-911, seeds 1-3: max 2.01-2.05 m, with this margin
        0.28-0.29 m).
        Along its ray an offset is not excused: a return short of a mapped obstacle is what an object the map lacks
        makes (the beam model's z_short), a person in front of a pillar.

        For an endpoint e (range r = |e| from the robot's centre), d(world endpoint) = (dx, dy) + r n dtheta with n
        the unit normal to the ray in the world frame, so the offset across the ray is n.(dx, dy) + r dtheta, of
        variance n' S_xy n + 2 r n.S_xtheta + r^2 S_thetatheta."""
        e = np.asarray(observation, dtype=np.float64)
        r = np.hypot(e[0], e[1])
        c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
        # the ray's direction in the world frame, (c ex - s ey, s ex + c ey) / r, turned by 90 degrees
        with np.errstate(invalid="ignore", divide="ignore"):
            nx = np.nan_to_num(-(s * e[0] + c * e[1]) / r)
            ny = np.nan_to_num((c * e[0] - s * e[1]) / r)
        cov = np.asarray(cov, dtype=np.float64)
        var = (nx * nx * cov[0, 0] + 2.0 * nx * ny * cov[0, 1] + ny * ny * cov[1, 1]
               + 2.0 * r * (nx * cov[0, 2] + ny * cov[1, 2]) + r * r * cov[2, 2])
        return np.maximum(self.BLIND_SIGMAS * np.sqrt(np.maximum(var, 0.0)), least).astype(np.float32)

    def blind(self, pose, laser_pose, scan, blocked, min_beams: int) -> bool:
        """Whether the map shows the laser fewer than ``min_beams`` obstacles from ``pose``: of ``scan``'s scored
        directions (:meth:`view`), cast from the laser (``laser_pose`` in the robot frame) through ``blocked``,
        fewer than that many meet one within the laser's reach and ``BLIND_MARGIN`` beyond it (a wall just out of
        reach from an estimate a few decimetres off is in reach from the true pose: its few readings near the
        laser's limit are all the scan says, large-06)."""
        if scan is None:
            return False
        angles, reach = self.view(scan)
        reach += self.BLIND_MARGIN
        z = cast_from_laser(blocked, self.origin, self.resolution, pose, laser_pose, angles, reach)
        return int(np.count_nonzero(z < reach - self.resolution)) < min_beams

    def select(self, observation, candidates, pose, shifts=None, whole: bool = False, distance=None):
        """(the observation to score, the skipped robot-frame endpoints (2, k) or None) for the robot-frame
        endpoints ``observation`` (2, K), ``candidates`` from :meth:`candidates`, seen from ``pose``: a candidate
        is skipped when farther than ``distance`` (m, or (K,) one per endpoint, or a function returning them, called
        only when a candidate lies farther than ``unmapped_distance``, which it must never go under; default
        ``unmapped_distance``) from every mapped obstacle. With ``shifts`` ((M, 2) world-frame offsets of ``pose``,
        or a function returning them or None, called only when a candidate is far), a run of neighbouring candidates
        is kept whole when one shifted pose puts every endpoint of it within that distance of the map."""
        if candidates is None or candidates.shape[0] != observation.shape[1] or not candidates.any():
            return observation, None
        idx = np.flatnonzero(candidates)
        e = np.ascontiguousarray(observation, dtype=np.float64)
        far = np.empty(idx.size, dtype=np.bool_)
        th = float(pose[2])
        # far from the map seen from the pose (NaN off the map: not far); then, if some are, a run of neighbouring
        # candidates is the map's when one shift puts all of it on mapped obstacles (mcl.kernels.field.far_runs)
        args = (self.dist, self.origin[0], self.origin[1], self.resolution, float(pose[0]), float(pose[1]),
                math.cos(th), math.sin(th), e, idx)
        later = distance if callable(distance) else None
        d = np.asarray(self.cfg.unmapped_distance if distance is None or later else distance, dtype=np.float32)
        d = np.ascontiguousarray(np.broadcast_to(d, e.shape[1]))  # one per endpoint, in float32 as the field
        n_far = far_runs(*args, _NO_SHIFTS, _NO_SHIFTS, d, far)
        if n_far and later is not None:  # none is far at the floor: none is at distances above it
            d = np.ascontiguousarray(np.broadcast_to(np.asarray(later(), dtype=np.float32), e.shape[1]))
            n_far = far_runs(*args, _NO_SHIFTS, _NO_SHIFTS, d, far)
        if n_far and callable(shifts):
            shifts = shifts()  # computed only when a candidate is far from the map
        if n_far and shifts is not None:
            sh = np.asarray(shifts, dtype=np.float64)
            n_far = far_runs(*args, np.ascontiguousarray(sh[:, 0]), np.ascontiguousarray(sh[:, 1]), d, far)
        if n_far == 0 or (2 * n_far >= observation.shape[1] and not whole):
            return observation, None
        skip = np.zeros(observation.shape[1], dtype=bool)
        skip[idx[far]] = True
        return np.require(observation[:, ~skip], requirements="C"), observation[:, skip]


_NO_SHIFTS = np.zeros(0)


def make_sensor_model(grid, cfg):
    """The range sensor model named by ``sensor.model``."""
    if cfg.model == "likelihood_field":
        return LikelihoodField(grid, cfg)
    if cfg.model == "beam":
        return BeamModel(grid, cfg)
    raise ValueError(f"sensor.model: unknown model {cfg.model!r}")


# ----------------------------------------------------------------------------- beam model

# The lookup table option refuses maps whose table would exceed this many bytes.
BEAM_LUT_MAX_BYTES = 512 * 2**20


def beam_observation(ranges, angles, max_range, cfg, laser_pose=(0.0, 0.0, 0.0)):
    """What the beam model scores for one scan: ``(ranges (K,), angles (K,), laser_pose (3,), zmax)``.

    Beams are subsampled as in ``beam_endpoints`` (up to ``max_beams`` evenly
    spaced over all beams). zmax is ``range_max``, or the scan's own
    ``max_range`` when that is smaller. Readings >= zmax (no return) become
    exactly zmax and are *kept* (they are scored by p_max); NaN readings and
    readings <= range_min are dropped; +inf counts as no return.
    """
    r = np.asarray(ranges, dtype=np.float64).ravel()
    a = np.asarray(angles, dtype=np.float64).ravel()
    if r.shape != a.shape:
        raise ValueError(f"ranges and angles differ in length: {r.size} vs {a.size}")
    max_beams = int(cfg.max_beams)
    if r.size > max_beams:
        sel = _evenly_spaced(r.size, max_beams)
        r, a = r[sel], a[sel]
    zmax = no_return_range(cfg.range_max, max_range)
    with np.errstate(invalid="ignore"):
        keep = ~np.isnan(r) & (r > float(cfg.range_min))
    r, a = r[keep], a[keep]
    r = np.where(r >= zmax, zmax, r)
    return (np.ascontiguousarray(r), np.ascontiguousarray(a),
            np.asarray(laser_pose, dtype=np.float64).reshape(3), zmax)


def beam_params(cfg) -> np.ndarray:
    """(z_hit, z_short, z_max, z_rand, sigma_hit, lambda_short) as the float64 array the kernels take."""
    return np.array([cfg.z_hit, cfg.z_short, cfg.z_max, cfg.z_rand, cfg.sigma_hit, cfg.lambda_short],
                    dtype=np.float64)


class BeamModel:
    """Beam range finder model (Prob. Rob. Table 6.1) with exact ray casting or a range lookup table.

    log p(z | x, m) = exponent * sum_k log(z_hit p_hit + z_short p_short + z_max p_max + z_rand p_rand),
    the expected range z*_k cast (Amanatides-Woo DDA over ``grid.occupied``)
    from the particle's laser pose; see ``mcl.kernels.beam`` for the
    component densities. Unlike the likelihood field, no-return readings are
    scored (by p_max, and by p_hit when the ray also expects none).

    With ``cfg.beam_lut`` the ranges from every free cell centre at
    ``beam_lut_bins`` headings are cast once (uint16, ``range_max / 65535``
    m steps) and gathered per beam (nearest cell, nearest heading bin):
    much faster, slightly less exact; refused (ConfigError naming
    ``sensor.beam.beam_lut``) when the table would exceed 512 MiB.
    """

    def __init__(self, grid, cfg):
        from mcl.errors import ConfigError
        from mcl.config import sensor_model_view
        from mcl.kernels.beam import build_range_table

        cfg = sensor_model_view(cfg, "beam")  # a SensorConfig: its common keys and sensor.beam
        self.cfg = cfg
        self.blocked = np.ascontiguousarray(grid.occupied, dtype=np.bool_)
        self.origin = (float(grid.origin[0]), float(grid.origin[1]))
        self.resolution = float(grid.resolution)
        self.exponent = float(getattr(cfg, "exponent", 1.0))
        self.params = beam_params(cfg)
        self.table = None
        self.unit = float(cfg.range_max) / 65535.0
        if getattr(cfg, "beam_lut", False):
            bins = int(cfg.beam_lut_bins)
            h, w = self.blocked.shape
            nbytes = h * w * bins * 2
            if nbytes > BEAM_LUT_MAX_BYTES:
                raise ConfigError(
                    f"sensor.beam.beam_lut: the range table for this {w}x{h}-cell map with {bins} heading bins would take "
                    f"{nbytes / 2**20:.0f} MiB (limit {BEAM_LUT_MAX_BYTES / 2**20:.0f} MiB); use fewer "
                    "sensor.beam.beam_lut_bins or beam_lut: false")
            self.table = np.empty((h, w, bins), dtype=np.uint16)
            build_range_table(self.blocked, self.origin[0], self.origin[1], self.resolution, float(cfg.range_max),
                              self.unit, self.table)

    def prepare(self, scan, laser_pose):
        """The observation, made once per scan: ``beam_observation`` of the scan."""
        return beam_observation(scan.ranges, scan.angles, scan.max_range, self.cfg, laser_pose)

    @staticmethod
    def endpoints(observation) -> np.ndarray:
        """(2, K) robot-frame endpoints of the beams with a return (readings below zmax), for the quality signal."""
        ranges, angles, lp, zmax = observation
        keep = ranges < zmax
        r, a = ranges[keep], angles[keep] + lp[2]
        return np.vstack([lp[0] + r * np.cos(a), lp[1] + r * np.sin(a)])

    def log_likelihood(self, particles, observation, out=None, searching: bool = False) -> np.ndarray:
        """(N,) float64 log p(z | x, m) per particle; no beams gives zeros. ``searching`` changes nothing here
        (the likelihood field's search table)."""
        from mcl.kernels.beam import beam_loglik, beam_loglik_lut, beam_loglik_lut_serial, beam_loglik_serial

        p = np.ascontiguousarray(particles, dtype=np.float64)
        if p.ndim != 2 or p.shape[0] != 3:
            raise ValueError(f"particles: expected shape (3, N), got {p.shape}")
        ranges, angles, lp, zmax = observation
        if out is None:
            out = np.empty(p.shape[1])
        else:
            check_out(out, (p.shape[1],))
        ox, oy = self.origin
        work = p.shape[1] * ranges.shape[0]
        if self.table is not None:
            kernel = choose(beam_loglik_lut, beam_loglik_lut_serial, work)
            kernel(p, ranges, angles, lp[0], lp[1], lp[2], self.table, self.unit, ox, oy, self.resolution, zmax,
                   self.params, self.exponent, out)
        else:  # a ray cast walks some tens of cells: count it as 30 steps
            kernel = choose(beam_loglik, beam_loglik_serial, 30 * work)
            kernel(p, ranges, angles, lp[0], lp[1], lp[2], self.blocked, ox, oy, self.resolution, zmax, self.params,
                   self.exponent, out)
        return out
