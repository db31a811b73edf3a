"""World generators for ``mcl simulate``: floor plans that stress a localization filter.

Each kind is a function of one random generator, deterministic for its seed,
returning a ``World`` (occupancy int8 with 100 occupied / 0 free / -1 unknown,
row 0 at the bottom, 0.05 m cells; the distance field; the cells the route
planner may use; a room/zone id per free cell for the planner's goals):

``office``
    The bundled demo's layout: a building of about 20 m x 15 m with a corner
    cut off, a main and a side corridor, rooms from a random binary space
    partition joined by doorways, furniture and pillars.
``rooms``
    A corridor with a row of identical rooms on either side (the south row is
    the north row turned by 180 degrees) and a lobby at one end: from inside a
    room every room looks the same, only a drive out to the lobby tells them
    apart (the symmetric, multi-modal case of Probabilistic Robotics 8.3).
``corridor``
    A 60-150 m corridor with one or two side corridors and a few door niches:
    along the corridor most scans look alike (a ridge of equal likelihood).
``hall``
    A 40-80 m x 30-60 m open hall with a sparse pillar grid (9-15 m apart,
    three in ten missing) and a few large objects: most beams of a 12 m laser
    return no echo (max range).
``clutter``
    The office with many small mapped items (chairs, bins, small tables);
    ``mcl.simulate`` adds people and furniture the map does not show.
``large``
    A 150-200 m x 90-130 m building: a grid of corridors, rows of rooms of
    random widths, a few open atria; for the per-update cost against map size.
``warehouse``
    A 40-70 m x 30-50 m warehouse: rows of pallet racks (uprights, bays full
    or empty) with aisles that look alike, cross aisles, a staging area with
    loose pallets, dock recesses and an office.

``KIND_DEFAULTS`` holds each kind's drive defaults (speed, the planner's cell
stride and longest leg) and its unmapped clutter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["KINDS", "KIND_DEFAULTS", "World", "make_world", "generate"]

RESOLUTION = 0.05
_MARGIN = 1.0  # metres of unknown around the building
_T_OUT = 0.15  # outer wall thickness
_T_IN = 0.10  # inner wall thickness
_MIN_ROOM = 3.0
_DOOR_MARGIN = 0.35  # from a door's edge to the nearest perpendicular wall


# --------------------------------------------------------------------------
# World
# --------------------------------------------------------------------------

@dataclass(eq=False)
class World:
    """A generated floor plan.

    ``occupancy`` is int8 (H, W), row 0 at the bottom: 100 occupied, 0 free,
    -1 unknown. ``distance`` is metres from each cell centre to the nearest
    occupied cell centre; ``reachable`` marks the free cells the robot's
    planner may use (clear of obstacles by ``clearance`` and connected).
    """

    occupancy: np.ndarray
    resolution: float
    origin: tuple[float, float]
    distance: np.ndarray
    reachable: np.ndarray
    room_id: np.ndarray  # int32 (H, W): index of the room/corridor a cell lies in, -1 elsewhere
    clearance: float
    meta: dict = field(default_factory=dict)  # kind-specific facts (sizes, the identical rooms' cell blocks)
    furniture: np.ndarray | None = None  # bool (H, W): occupied cells that are furniture, not walls (depth sim)

    @property
    def blocked(self) -> np.ndarray:
        return self.occupancy == 100


class _Raster:
    """World rectangles -> cell index ranges (a cell belongs if its centre is inside)."""

    def __init__(self, shape, origin, res):
        self.shape = shape
        self.ox, self.oy = origin
        self.res = res

    def slices(self, x0, y0, x1, y1):
        r = self.res
        ix0 = max(math.ceil((x0 - self.ox) / r - 0.5 - 1e-9), 0)
        ix1 = min(math.floor((x1 - self.ox) / r - 0.5 + 1e-9), self.shape[1] - 1)
        iy0 = max(math.ceil((y0 - self.oy) / r - 0.5 - 1e-9), 0)
        iy1 = min(math.floor((y1 - self.oy) / r - 0.5 + 1e-9), self.shape[0] - 1)
        return slice(iy0, max(iy1 + 1, iy0)), slice(ix0, max(ix1 + 1, ix0))


def _bsp(rect, rng, out):
    """Split ``rect`` (x0, y0, x1, y1) recursively into rooms."""
    x0, y0, x1, y1 = rect
    w, h = x1 - x0, y1 - y0
    longest = max(w, h)
    max_side = rng.uniform(4.5, 8.0)
    if longest < 2 * _MIN_ROOM or (longest <= max_side and rng.random() < 0.7):
        out.append(rect)
        return
    if w >= h:
        c = rng.uniform(x0 + _MIN_ROOM, x1 - _MIN_ROOM)
        _bsp((x0, y0, c, y1), rng, out)
        _bsp((c, y0, x1, y1), rng, out)
    else:
        c = rng.uniform(y0 + _MIN_ROOM, y1 - _MIN_ROOM)
        _bsp((x0, y0, x1, c), rng, out)
        _bsp((x0, c, x1, y1), rng, out)


def _shared_edge(a, b, need):
    """The wall segment rooms ``a`` and ``b`` share, as (axis, coord, lo, hi), or None.

    axis 0: a vertical wall at x = coord spanning y in [lo, hi]; axis 1: horizontal.
    Only segments long enough for a door (``need``) count.
    """
    eps = 1e-6
    for axis in (0, 1):
        lo_a, hi_a = (a[0], a[2]) if axis == 0 else (a[1], a[3])
        lo_b, hi_b = (b[0], b[2]) if axis == 0 else (b[1], b[3])
        if abs(hi_a - lo_b) < eps:
            coord = hi_a
        elif abs(hi_b - lo_a) < eps:
            coord = lo_a
        else:
            continue
        o = (1, 3) if axis == 0 else (0, 2)
        lo, hi = max(a[o[0]], b[o[0]]), min(a[o[1]], b[o[1]])
        if hi - lo >= need:
            return axis, coord, lo, hi
    return None


def _components(trav):
    from scipy.ndimage import label

    return label(trav, structure=np.ones((3, 3), dtype=bool))


def make_world(rng: np.random.Generator, *, width: float = 20.0, height: float = 15.0,
               clearance: float = 0.42, small_items: int = 0) -> World:
    """Generate the office floor plan; ``clearance`` is the planner's distance to obstacles.

    ``small_items`` > 0 (the ``clutter`` kind) adds that many chairs, bins and
    small tables after the usual furniture; 0 draws nothing more, so the
    office of a seed stays the same.
    """
    from scipy.ndimage import distance_transform_edt

    res = RESOLUTION
    W, H = width, height
    shape = (int(round((H + 2 * _MARGIN) / res)), int(round((W + 2 * _MARGIN) / res)))
    origin = (-_MARGIN, -_MARGIN)
    ras = _Raster(shape, origin, res)

    # --- layout: a main corridor across, a side corridor off it, room blocks
    cw = rng.uniform(1.6, 2.1)
    yc = rng.uniform(0.36, 0.52) * H
    cw2 = rng.uniform(1.4, 1.8)
    xv = rng.uniform(0.25, 0.65) * W
    south = rng.random() < 0.5  # side corridor below or above the main one
    corridors = [(0.0, yc, W, yc + cw)]
    if south:
        corridors.append((xv, 0.0, xv + cw2, yc))
        blocks = [(0.0, yc + cw, W, H), (0.0, 0.0, xv, yc), (xv + cw2, 0.0, W, yc)]
    else:
        corridors.append((xv, yc + cw, xv + cw2, H))
        blocks = [(0.0, 0.0, W, yc), (0.0, yc + cw, xv, H), (xv + cw2, yc + cw, W, H)]
    rooms: list[tuple] = []
    for b in blocks:
        _bsp(b, rng, rooms)

    door_need = 1.3 + 2 * _DOOR_MARGIN
    n_rooms = len(rooms)
    cnode = n_rooms  # all corridor pieces are one open space

    def edges_of(removed):
        e = []
        keep = [i for i in range(n_rooms) if i not in removed]
        for ii, i in enumerate(keep):
            for j in keep[ii + 1:]:
                s = _shared_edge(rooms[i], rooms[j], door_need)
                if s:
                    e.append((i, j, s))
            best = None
            for c in corridors:
                s = _shared_edge(rooms[i], c, door_need)
                if s and (best is None or s[3] - s[2] > best[3] - best[2]):
                    best = s
            if best:
                e.append((i, cnode, best))
        return keep, e

    def connected(nodes, edges):
        parent = {n: n for n in nodes}

        def find(a):
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        for i, j, _ in edges:
            parent[find(i)] = find(j)
        return len({find(n) for n in nodes}) == 1

    # --- cut one building corner off (asymmetry): a room holding a corner
    corners = [(0.0, 0.0), (W, 0.0), (0.0, H), (W, H)]
    removed: set[int] = set()
    for ci in rng.permutation(4):
        cx, cy = corners[ci]
        cand = [i for i, r in enumerate(rooms) if (r[0] == cx or r[2] == cx) and (r[1] == cy or r[3] == cy)]
        if not cand:
            continue
        i = cand[0]
        r = rooms[i]
        if (r[2] - r[0]) * (r[3] - r[1]) > 0.15 * W * H:
            continue
        keep, e = edges_of({i})
        if connected(keep + [cnode], e):
            removed = {i}
            break
    keep, edges = edges_of(removed)
    if not connected(keep + [cnode], edges):  # cannot happen with corridor-adjacent blocks; be safe
        raise RuntimeError("world generation produced disconnected rooms")

    # --- doors: a random spanning tree, plus extra doors onto the corridor and between rooms
    order = rng.permutation(len(edges))
    parent = {n: n for n in keep + [cnode]}

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    doors = []
    for k in order:
        i, j, s = edges[k]
        ri, rj = find(i), find(j)
        if ri != rj:
            parent[ri] = rj
            doors.append(s)
        elif rng.random() < (0.5 if j == cnode else 0.15):
            doors.append(s)

    # --- rasterise: interior free, inner walls, outer walls by dilation
    interior = np.zeros(shape, dtype=bool)
    room_id = np.full(shape, -1, dtype=np.int32)
    for i in keep:
        sl = ras.slices(*rooms[i])
        interior[sl] = True
        room_id[sl] = i
    for c in corridors:
        sl = ras.slices(*c)
        interior[sl] = True
        room_id[sl] = cnode
    walls = np.zeros(shape, dtype=bool)
    h2 = _T_IN / 2
    for i in keep:
        x0, y0, x1, y1 = rooms[i]
        for rect in ((x0 - h2, y0 - h2, x0 + h2, y1 + h2), (x1 - h2, y0 - h2, x1 + h2, y1 + h2),
                     (x0 - h2, y0 - h2, x1 + h2, y0 + h2), (x0 - h2, y1 - h2, x1 + h2, y1 + h2)):
            walls[ras.slices(*rect)] = True
    walls &= interior
    dist_out = distance_transform_edt(~interior) * res
    outer = ~interior & (dist_out <= _T_OUT + 1e-9)
    door_centres = []
    for axis, coord, lo, hi in doors:
        dw = rng.uniform(1.0, 1.3)
        c = rng.uniform(lo + _DOOR_MARGIN + dw / 2, hi - _DOOR_MARGIN - dw / 2)
        if axis == 0:
            walls[ras.slices(coord - _T_IN, c - dw / 2, coord + _T_IN, c + dw / 2)] = False
            door_centres.append((coord, c))
        else:
            walls[ras.slices(c - dw / 2, coord - _T_IN, c + dw / 2, coord + _T_IN)] = False
            door_centres.append((c, coord))
    occupied = walls | outer
    structure = occupied

    def trav_of(occ):
        d = distance_transform_edt(~occ) * res
        return d, interior & (d >= clearance)

    d, trav = trav_of(occupied)
    lab, n = _components(trav)
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    main = lab == np.argmax(sizes)

    # --- furniture: tables/cabinets, shelves against walls, pillars; never cutting off space
    dc = np.array(door_centres) if door_centres else np.zeros((0, 2))

    def try_place(rect):
        nonlocal occupied, main
        x0, y0, x1, y1 = rect
        if len(dc):
            qx = np.clip(dc[:, 0], x0, x1)
            qy = np.clip(dc[:, 1], y0, y1)
            if np.min(np.hypot(dc[:, 0] - qx, dc[:, 1] - qy)) < 1.0:
                return False
        cand = occupied.copy()
        cand[ras.slices(*rect)] = True
        _, tr = trav_of(cand)
        lab, _ = _components(tr)
        kept = lab[main & tr]
        if kept.size == 0:
            return False
        counts = np.bincount(kept)
        counts[0] = 0
        best = int(np.argmax(counts))
        if kept.size - counts[best] > 30:  # would cut off part of the reachable space
            return False
        occupied = cand
        main = lab == best
        return True

    for i in keep:
        x0, y0, x1, y1 = rooms[i]
        ix0, iy0, ix1, iy1 = x0 + h2, y0 + h2, x1 - h2, y1 - h2
        area = (x1 - x0) * (y1 - y0)
        n_items = int(rng.integers(0, 2 + int(area // 10)))
        for _ in range(n_items):
            for _attempt in range(6):
                kind = rng.random()
                if kind < 0.45:  # a table or cabinet anywhere
                    a, b = rng.uniform(0.5, 1.6), rng.uniform(0.5, 1.2)
                    if rng.random() < 0.5:
                        a, b = b, a
                    if ix1 - ix0 <= a or iy1 - iy0 <= b:
                        continue
                    fx, fy = rng.uniform(ix0, ix1 - a), rng.uniform(iy0, iy1 - b)
                    rect = (fx, fy, fx + a, fy + b)
                elif kind < 0.85:  # a shelf along one wall
                    ln, th = rng.uniform(1.0, 2.5), rng.uniform(0.3, 0.45)
                    side = int(rng.integers(4))
                    if side < 2:
                        if ix1 - ix0 <= ln:
                            continue
                        fx = rng.uniform(ix0, ix1 - ln)
                        fy = iy0 if side == 0 else iy1 - th
                        rect = (fx, fy, fx + ln, fy + th)
                    else:
                        if iy1 - iy0 <= ln:
                            continue
                        fy = rng.uniform(iy0, iy1 - ln)
                        fx = ix0 if side == 2 else ix1 - th
                        rect = (fx, fy, fx + th, fy + ln)
                else:  # a pillar
                    s = rng.uniform(0.25, 0.4)
                    fx, fy = rng.uniform(ix0 + 0.8, ix1 - 0.8 - s), rng.uniform(iy0 + 0.8, iy1 - 0.8 - s)
                    rect = (fx, fy, fx + s, fy + s)
                if try_place(rect):
                    break
    # a few pillars in the corridors, half set into a wall
    for c in corridors:
        for _ in range(int(rng.integers(1, 3))):
            s = rng.uniform(0.3, 0.4)
            if c[2] - c[0] > c[3] - c[1]:
                fx = rng.uniform(c[0] + 1.0, c[2] - 1.0 - s)
                fy = c[1] - s / 2 if rng.random() < 0.5 else c[3] - s / 2
            else:
                fy = rng.uniform(c[1] + 1.0, c[3] - 1.0 - s)
                fx = c[0] - s / 2 if rng.random() < 0.5 else c[2] - s / 2
            try_place((fx, fy, fx + s, fy + s))
    # clutter: chairs, bins and small tables anywhere in rooms and corridors
    spaces = [rooms[i] for i in keep] + corridors
    for _ in range(small_items):
        for _attempt in range(4):
            x0, y0, x1, y1 = spaces[int(rng.integers(len(spaces)))]
            a, b = rng.uniform(0.3, 0.8, 2)
            if x1 - x0 <= a + 0.3 or y1 - y0 <= b + 0.3:
                continue
            fx, fy = rng.uniform(x0 + 0.15, x1 - 0.15 - a), rng.uniform(y0 + 0.15, y1 - 0.15 - b)
            if try_place((fx, fy, fx + a, fy + b)):
                break

    distance, trav = trav_of(occupied)
    reachable = main & trav
    occ = np.where(occupied, 100, np.where(interior, 0, -1)).astype(np.int8)
    room_id[occupied] = -1
    return World(occ, res, origin, distance.astype(np.float64), reachable, room_id, clearance,
                 furniture=occupied & ~structure)



# --------------------------------------------------------------------------
# Shared finishing of the other kinds
# --------------------------------------------------------------------------

def _finish(interior: np.ndarray, occupied: np.ndarray, room_id: np.ndarray, origin, clearance: float,
            meta: dict, keep_out: np.ndarray | None = None) -> World:
    """Outer walls around ``interior``, the distance field, and the connected cells clear of obstacles (and out of
    ``keep_out``: free cells the route planner must not use, a pallet rack's empty bays)."""
    from scipy.ndimage import binary_dilation, distance_transform_edt

    res = RESOLUTION
    r = int(round(_T_OUT / res))
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    disk = xx ** 2 + yy ** 2 <= r * r  # the office's outer walls: unknown cells within _T_OUT of the interior
    occupied = occupied | (binary_dilation(interior, structure=disk) & ~interior)
    distance = distance_transform_edt(~occupied) * res
    trav = interior & ~occupied & (distance >= clearance)
    if keep_out is not None:
        trav &= ~keep_out
    lab, _ = _components(trav)
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    reachable = lab == np.argmax(sizes)
    occ = np.where(occupied, 100, np.where(interior, 0, -1)).astype(np.int8)
    room_id = room_id.copy()
    room_id[occupied] = -1
    return World(occ, res, (float(origin[0]), float(origin[1])), distance, reachable, room_id, clearance, meta)


def _canvas(width: float, height: float):
    """Empty arrays for a ``width`` x ``height`` m building with _MARGIN of unknown around it."""
    shape = (int(round((height + 2 * _MARGIN) / RESOLUTION)), int(round((width + 2 * _MARGIN) / RESOLUTION)))
    origin = (-_MARGIN, -_MARGIN)
    return (_Raster(shape, origin, RESOLUTION), np.zeros(shape, dtype=bool), np.zeros(shape, dtype=bool),
            np.full(shape, -1, dtype=np.int32), origin)


def _zones(room_id: np.ndarray, mask: np.ndarray, first: int, cells: int, offset: tuple = (0, 0)) -> int:
    """Give the cells of ``mask`` square zone ids (``cells`` a side) from ``first`` on; returns the next free id.

    Open spaces have no rooms; the route planner's goals go to rarely visited zones instead.
    """
    iy, ix = np.nonzero(mask)
    if iy.size == 0:
        return first
    zy, zx = (iy - offset[0]) // cells, (ix - offset[1]) // cells
    key = zy * (int(zx.max()) + 1) + zx
    _, z = np.unique(key, return_inverse=True)
    room_id[iy, ix] = first + z
    return first + int(z.max()) + 1


# --------------------------------------------------------------------------
# rooms: identical rooms off a corridor
# --------------------------------------------------------------------------

def _rooms_world(rng: np.random.Generator, clearance: float) -> World:
    """A lobby, then a corridor with ``n`` identical rooms on either side, built cell by cell.

    One room is drawn as a cell tile (its walls, door and furniture); the
    north row repeats it, the south row repeats it turned by 180 degrees, so
    the rooms are equal cell for cell and a scan from inside one fits all
    2n of them. Only the lobby at the west end breaks the symmetry.
    """
    from scipy.ndimage import distance_transform_edt

    res = RESOLUTION

    def c(m):
        return int(round(m / res))

    n = int(rng.integers(5, 9))  # rooms per row
    rw, rd = c(rng.uniform(3.6, 5.0)), c(rng.uniform(4.0, 5.5))  # room pitch (x) and depth (y), cells
    cw, lobby = c(rng.uniform(1.8, 2.4)), c(rng.uniform(4.5, 6.5))  # corridor width, lobby length
    W, H = lobby + n * rw, 2 * rd + cw
    m = c(_MARGIN)
    shape = (H + 2 * m, W + 2 * m)
    interior = np.zeros(shape, dtype=bool)
    interior[m:m + H, m:m + W] = True
    occupied = np.zeros(shape, dtype=bool)
    room_id = np.full(shape, -1, dtype=np.int32)

    # the tile: rows 0-1 the wall on the corridor (with the door), rows 2..rd the room, row rd+1 the outer wall;
    # columns 0-1 and rw..rw+1 the side walls (shared with the neighbours)
    for _attempt in range(20):
        tile = np.zeros((rd + 2, rw + 2), dtype=bool)
        tile[0:2] = tile[-1] = True
        tile[:, 0:2] = tile[:, -2:] = True
        dw = c(rng.uniform(1.0, 1.3))
        d0 = int(rng.integers(2 + c(0.35), rw - c(0.35) - dw + 1))
        tile[0:2, d0:d0 + dw] = False
        # furniture against the back and side walls, away from the door: a shelf, a desk, a cabinet
        back = rd  # last room row
        ln, th = c(rng.uniform(1.0, 2.0)), c(rng.uniform(0.3, 0.45))
        x = int(rng.integers(2, rw - ln + 1))
        tile[back - th + 1:back + 1, x:x + ln] = True
        a, b = c(rng.uniform(0.6, 0.9)), c(rng.uniform(1.2, 1.8))  # desk against a side wall
        y = int(rng.integers(2 + c(1.6), max(back - b - c(0.5), 2 + c(1.6)) + 1))
        if rng.random() < 0.5:
            tile[y:y + b, 2:2 + a] = True
        else:
            tile[y:y + b, rw - a:rw] = True
        s = c(rng.uniform(0.4, 0.6))  # a cabinet in a front corner, beside the door
        if d0 - 2 >= s + c(0.5):
            tile[2:2 + s, 2:2 + s] = True
        elif rw - (d0 + dw) >= s + c(0.5):
            tile[2:2 + s, rw - s:rw] = True
        # the room must be drivable from its door: one clear component touching the doorway
        inner = ~tile
        inner[-1] = False
        d = distance_transform_edt(inner) * res
        clear = (d >= clearance)[2:rd + 1, 2:rw]
        lab, k = _components(clear)
        if k == 1 and clear[0, d0 - 2:d0 - 2 + dw].any() and clear.mean() > 0.25:
            break
    else:  # pragma: no cover - the draws above always leave room
        raise RuntimeError("rooms: could not furnish the room tile")

    y_s, y_c, y_n = m, m + rd, m + rd + cw  # south rooms, corridor, north rooms (first rows)
    blocks = []
    for k in range(n):
        x0 = m + lobby + k * rw - 1  # the tile's first column: the left wall pair straddles x0, x0 + 1
        nb = (slice(y_n - 1, y_n + rd + 1), slice(x0, x0 + rw + 2))
        sb = (slice(y_c - rd - 1, y_c + 1), slice(x0, x0 + rw + 2))
        occupied[nb] |= tile
        occupied[sb] |= tile[::-1, ::-1]
        room_id[y_n + 1:y_n + rd, x0 + 2:x0 + rw] = 2 + k
        room_id[y_s:y_c - 1, x0 + 2:x0 + rw] = 2 + n + k
        blocks.append(((nb[0].start, nb[0].stop, nb[1].start, nb[1].stop), False))
        blocks.append(((sb[0].start, sb[0].stop, sb[1].start, sb[1].stop), True))
    room_id[y_c + 1:y_n - 1, m + lobby:m + W] = 1  # corridor
    room_id[m:m + H, m:m + lobby - 1] = 0  # lobby
    # the lobby: a reception desk and a pillar, at random places
    ras = _Raster(shape, (-_MARGIN, -_MARGIN), res)
    L, Hm = lobby * res, H * res
    dx, dy = rng.uniform(0.8, 1.4), rng.uniform(1.6, 2.4)
    fx, fy = rng.uniform(0.9, max(L - dx - 1.8, 1.0)), rng.uniform(0.9, Hm - dy - 0.9)
    occupied[ras.slices(fx, fy, fx + dx, fy + dy)] = True
    s = rng.uniform(0.35, 0.5)
    py = rng.uniform(0.9, Hm - 0.9 - s) if rng.random() < 0.5 else (0.9 if fy > Hm / 2 else Hm - 0.9 - s)
    occupied[ras.slices(L - 1.2 - s, py, L - 1.2, py + s)] = True
    meta = {"kind": "rooms", "rooms_per_row": n, "room_size": (rw * res, rd * res), "corridor_width": cw * res,
            "size": (W * res, H * res), "room_blocks": blocks}
    return _finish(interior, occupied, room_id, (-_MARGIN, -_MARGIN), clearance, meta)


# --------------------------------------------------------------------------
# corridor: long and featureless
# --------------------------------------------------------------------------

def _corridor_world(rng: np.random.Generator, clearance: float) -> World:
    """A 60-150 m main corridor, one or two side corridors, a few door niches and pillars."""
    L = rng.uniform(60.0, 150.0)
    cw = rng.uniform(1.8, 2.4)
    sides = []
    for _ in range(int(rng.integers(1, 3))):
        for _attempt in range(20):
            x = rng.uniform(8.0, L - 10.0)
            if all(abs(x - s[0]) > 12.0 for s in sides):
                sides.append((x, rng.uniform(1.6, 2.2), rng.uniform(8.0, 20.0), rng.random() < 0.5))
                break
    south = max([s[2] for s in sides if s[3]], default=0.0)
    north = max([s[2] for s in sides if not s[3]], default=0.0)
    depth = 0.4  # door niches
    H = south + cw + north + 2 * depth
    yc = south + depth
    ras, interior, occupied, room_id, origin = _canvas(L, H)
    main = ras.slices(0.0, yc, L, yc + cw)
    interior[main] = True
    zone = _zones(room_id, interior, 0, int(round(10.0 / RESOLUTION)), (main[0].start, 0))  # 10 m along it
    for x, w, ln, down in sides:
        rect = (x, yc - ln, x + w, yc) if down else (x, yc + cw, x + w, yc + cw + ln)
        sl = ras.slices(*rect)
        interior[sl] = True
        room_id[sl] = zone
        zone += 1
    n_niche = int(rng.integers(3, 7))
    for _ in range(n_niche):
        w = rng.uniform(0.9, 1.3)
        x = rng.uniform(1.0, L - 1.0 - w)
        if any(s[0] - 1.0 < x + w and x < s[0] + s[1] + 1.0 for s in sides):
            continue
        interior[ras.slices(x, yc - depth, x + w, yc) if rng.random() < 0.5 else
                 ras.slices(x, yc + cw, x + w, yc + cw + depth)] = True
    for _ in range(int(rng.integers(0, 3))):  # a pillar half set into a wall
        s = rng.uniform(0.3, 0.4)
        x = rng.uniform(2.0, L - 2.0)
        y = yc - s / 2 if rng.random() < 0.5 else yc + cw - s / 2
        occupied[ras.slices(x, y, x + s, y + s)] = True
    occupied &= interior
    meta = {"kind": "corridor", "length": L, "width": cw, "size": (L, H), "side_corridors": len(sides)}
    return _finish(interior, occupied, room_id, origin, clearance, meta)


# --------------------------------------------------------------------------
# hall: large and open
# --------------------------------------------------------------------------

def _apart(r, rects, gap) -> bool:
    """True when rectangle ``r`` keeps ``gap`` m from every one of ``rects``."""
    return all(r[0] - gap >= q[2] or q[0] - gap >= r[2] or r[1] - gap >= q[3] or q[1] - gap >= r[3] for q in rects)


def _place_apart(rng, rects, size, bounds, gap, tries=60):
    """A random (x0, y0, x1, y1) of ``size`` inside ``bounds``, ``gap`` m from every rect in ``rects``, or None.

    The gap (> twice the planner's clearance) keeps every space between objects drivable.
    """
    a, b = size
    x0, y0, x1, y1 = bounds
    for _ in range(tries):
        fx, fy = rng.uniform(x0, x1 - a), rng.uniform(y0, y1 - b)
        r = (fx, fy, fx + a, fy + b)
        if _apart(r, rects, gap):
            return r
    return None


def _hall_world(rng: np.random.Generator, clearance: float) -> World:
    """A 40-80 m x 30-60 m hall: a sparse pillar grid, 1-3 large objects (containers, shelving), an office in a
    corner."""
    W = rng.uniform(40.0, 80.0)
    H = rng.uniform(30.0, min(60.0, W))
    ras, interior, occupied, room_id, origin = _canvas(W, H)
    interior[ras.slices(0.0, 0.0, W, H)] = True
    # a small office in one corner (walls with a doorway): the hall's one asymmetric feature
    ow, oh = rng.uniform(4.0, 6.0), rng.uniform(3.0, 4.5)
    cx, cy = (0.0 if rng.random() < 0.5 else W - ow), (0.0 if rng.random() < 0.5 else H - oh)
    office = (cx, cy, cx + ow, cy + oh)
    wy = cy + oh if cy == 0.0 else cy  # its wall facing the hall, with a door
    wx = cx + ow if cx == 0.0 else cx
    h2 = _T_IN / 2
    occupied[ras.slices(cx, wy - h2, cx + ow, wy + h2)] = True
    occupied[ras.slices(wx - h2, cy, wx + h2, cy + oh)] = True
    dx = rng.uniform(cx + 0.8, cx + ow - 2.0)
    occupied[ras.slices(dx, wy - 2 * h2, dx + 1.2, wy + 2 * h2)] = False
    rects = [(office[0] - 0.1, office[1] - 0.1, office[2] + 0.1, office[3] + 0.1)]
    inner = (2.0, 2.0, W - 2.0, H - 2.0)
    for _ in range(int(rng.integers(1, 4))):  # containers, shelving
        a, b = rng.uniform(2.0, 6.0), rng.uniform(0.6, 2.5)
        r = _place_apart(rng, rects, (a, b) if rng.random() < 0.5 else (b, a), inner, 2.0)
        if r:
            rects.append(r)
            occupied[ras.slices(*r)] = True
    # a pillar grid every 9-15 m, three in ten pillars missing: a 12 m laser sees a few, often none
    sx, sy = rng.uniform(9.0, 15.0, 2)
    ps = rng.uniform(0.4, 0.7)
    for px in np.arange(rng.uniform(3.0, sx), W - 3.0, sx):
        for py in np.arange(rng.uniform(3.0, sy), H - 3.0, sy):
            r = (px, py, px + ps, py + ps)
            if rng.random() < 0.3 or not _apart(r, rects, 2.0):
                continue
            rects.append(r)
            occupied[ras.slices(*r)] = True
    occupied &= interior
    zone = _zones(room_id, interior, 0, int(round(8.0 / RESOLUTION)), (int(round(_MARGIN / RESOLUTION)),) * 2)
    room_id[ras.slices(cx + h2, cy + h2, cx + ow - h2, cy + oh - h2)] = zone
    meta = {"kind": "hall", "size": (W, H), "objects": len(rects) - 1}
    return _finish(interior, occupied, room_id, origin, clearance, meta)


# --------------------------------------------------------------------------
# large: a big building
# --------------------------------------------------------------------------

def _large_world(rng: np.random.Generator, clearance: float) -> World:
    """A 150-200 m x 90-130 m building: a grid of 2-3 m corridors, rows of rooms with doors onto them, atria.

    Horizontal corridors every 16-24 m with a row of rooms on either side;
    vertical corridors every 25-45 m cut the rows into blocks; one block in
    eight is an open atrium with pillars. Rooms are 3-8 m wide; each has a
    1.5-1.9 m door onto its corridor and a desk or shelf against its back wall.
    """
    W, H = rng.uniform(150.0, 200.0), rng.uniform(90.0, 130.0)
    ras, interior, occupied, room_id, origin = _canvas(W, H)
    interior[ras.slices(0.0, 0.0, W, H)] = True
    h2 = _T_IN / 2
    # corridor lines (lo, hi) across the building
    hc, y = [], rng.uniform(7.0, 10.0)
    while y < H - 9.0:
        w = rng.uniform(2.0, 3.0)
        hc.append((y, y + w))
        y += w + rng.uniform(14.0, 20.0)
    vc, x = [], rng.uniform(6.0, 20.0)
    while x < W - 8.0:
        w = rng.uniform(2.0, 3.0)
        vc.append((x, x + w))
        x += w + rng.uniform(25.0, 45.0)
    nid = 0
    for lo, hi in hc:
        sl = ras.slices(0.0, lo, W, hi)
        room_id[sl] = nid
        nid += 1
    for lo, hi in vc:
        sl = ras.slices(lo, 0.0, hi, H)
        room_id[sl] = nid
        nid += 1
    # row bands between horizontal corridors (and the outer walls)
    ys = [0.0] + [v for c in hc for v in c] + [H]
    bands = [(ys[i], ys[i + 1]) for i in range(0, len(ys), 2)]
    xs = [0.0] + [v for c in vc for v in c] + [W]
    cols = [(xs[i], xs[i + 1]) for i in range(0, len(xs), 2)]
    n_rooms = n_atria = 0
    for bi, (b0, b1) in enumerate(bands):
        corr_below, corr_above = bi > 0, bi < len(bands) - 1
        for c0, c1 in cols:
            walls = [(c0 - h2, b0 - h2, c0 + h2, b1 + h2), (c1 - h2, b0 - h2, c1 + h2, b1 + h2),
                     (c0 - h2, b0 - h2, c1 + h2, b0 + h2), (c0 - h2, b1 - h2, c1 + h2, b1 + h2)]
            if rng.random() < 0.125 and c1 - c0 > 12 and b1 - b0 > 10:  # an atrium: open onto its corridors
                for r in walls:
                    occupied[ras.slices(*r)] = True
                for lo, hi, yy in ((c0, c1, b0), (c0, c1, b1)):
                    if (yy == b0 and corr_below) or (yy == b1 and corr_above):
                        g = rng.uniform(3.0, min(6.0, hi - lo - 2.0))
                        gx = rng.uniform(lo + 1.0, hi - 1.0 - g)
                        occupied[ras.slices(gx, yy - _T_IN, gx + g, yy + _T_IN)] = False
                rects = []
                for _ in range(int(rng.integers(2, 6))):
                    s = rng.uniform(0.4, 0.7)
                    r = _place_apart(rng, rects, (s, s), (c0 + 2.0, b0 + 2.0, c1 - 2.0, b1 - 2.0), 3.0)
                    if r:
                        rects.append(r)
                        occupied[ras.slices(*r)] = True
                room_id[ras.slices(c0 + h2, b0 + h2, c1 - h2, b1 - h2)] = nid
                nid += 1
                n_atria += 1
                continue
            # one or two rows of rooms, each row facing a corridor
            rows = []
            if corr_below and corr_above and b1 - b0 >= 8.0:
                mid = rng.uniform(b0 + 0.4 * (b1 - b0), b0 + 0.6 * (b1 - b0))
                rows = [(b0, mid, b0), (mid, b1, b1)]
            else:
                rows = [(b0, b1, b0 if corr_below else b1)]
            for r0, r1, door_y in rows:
                x = c0
                while x < c1 - 0.1:
                    w = rng.uniform(3.0, 8.0)
                    x1 = c1 if c1 - (x + w) < 3.0 else x + w
                    for r in ((x - h2, r0 - h2, x + h2, r1 + h2), (x1 - h2, r0 - h2, x1 + h2, r1 + h2),
                              (x - h2, r0 - h2, x1 + h2, r0 + h2), (x - h2, r1 - h2, x1 + h2, r1 + h2)):
                        occupied[ras.slices(*r)] = True
                    dw = rng.uniform(1.5, 1.9)
                    dx = rng.uniform(x + 0.45, x1 - 0.45 - dw)
                    occupied[ras.slices(dx, door_y - _T_IN, dx + dw, door_y + _T_IN)] = False
                    # a desk or shelf against the back wall, clear of the door side
                    back = r1 if door_y == r0 else r0
                    ln, th = rng.uniform(1.0, min(2.5, x1 - x - 1.0)), rng.uniform(0.4, 0.8)
                    fx = rng.uniform(x + h2, x1 - h2 - ln)
                    fy = back - h2 - th if back == r1 else back + h2
                    if r1 - r0 - th > 2.5:
                        occupied[ras.slices(fx, fy, fx + ln, fy + th)] = True
                    room_id[ras.slices(x + h2, r0 + h2, x1 - h2, r1 - h2)] = nid
                    nid += 1
                    n_rooms += 1
                    x = x1
    # corridor crossings stay open: clear walls drawn into corridor space
    for lo, hi in hc:
        occupied[ras.slices(0.0, lo + h2 + 0.01, W, hi - h2 - 0.01)] = False
    for lo, hi in vc:
        occupied[ras.slices(lo + h2 + 0.01, 0.0, hi - h2 - 0.01, H)] = False
    occupied &= interior
    meta = {"kind": "large", "size": (W, H), "rooms": n_rooms, "atria": n_atria,
            "corridors": (len(hc), len(vc))}
    return _finish(interior, occupied, room_id, origin, clearance, meta)


# --------------------------------------------------------------------------
# warehouse: aisles of pallet racks
# --------------------------------------------------------------------------

_UPRIGHT = 0.1  # m: a rack upright's side


def _warehouse_world(rng: np.random.Generator, clearance: float) -> World:
    """A 40-70 m x 30-50 m warehouse: rows of pallet racks with 2.8-3.4 m aisles between them, cut by one or two
    cross aisles, a staging area along the dock wall with loose pallets and an office, a back aisle.

    A rack row is two racks back to back (0.9-1.2 m deep each, a 0.2 m flue between), in bays of about 2.7 m.
    An upright stands at every bay end on both faces of a rack; a bay holds a pallet at floor level (solid to a
    laser at its height) with probability 0.75-1 (one share a world), else it is empty and a beam passes
    between the uprights into the rack, and past an empty bay behind it into the next aisle. Aisle after aisle
    looks alike: the pattern of full and empty bays and the ends of the aisles are what tell the aisles, and the
    places along one, apart (a repeated world like ``rooms``, at a warehouse's scale). The robot drives the aisles,
    never into a rack (``_finish``'s ``keep_out``).
    """
    W, H = rng.uniform(40.0, 70.0), rng.uniform(30.0, 50.0)
    ras, interior, occupied, room_id, origin = _canvas(W, H)
    interior[ras.slices(0.0, 0.0, W, H)] = True
    h2 = _T_IN / 2
    stage = rng.uniform(7.0, 10.0)  # the staging area along the dock wall (y = 0)
    top = H - rng.uniform(3.0, 4.0)  # the racks end at the back aisle
    depth, flue, aisle = rng.uniform(0.9, 1.2), 0.2, rng.uniform(2.8, 3.4)
    full = rng.uniform(0.75, 1.0)
    row_w = 2 * depth + flue
    # cross aisles cut the rows into blocks at least 8 m long
    n_cross = int(rng.integers(1, 3))
    cw = rng.uniform(3.0, 3.6)
    while n_cross and top - stage < 8.0 * (n_cross + 1) + cw * n_cross:
        n_cross -= 1
    spare = top - stage - 8.0 * (n_cross + 1) - cw * n_cross
    cuts = np.sort(rng.uniform(0.0, spare, n_cross))
    blocks, y = [], stage
    for i in range(n_cross + 1):
        y1 = top if i == n_cross else stage + 8.0 * (i + 1) + cw * i + cuts[i]
        blocks.append((y, y1))
        y = y1 + cw
    racks = np.zeros_like(interior)
    rows, x = [], rng.uniform(3.0, 4.0)
    n_bays = n_full = 0
    while x + row_w <= W - 3.0:
        rows.append(x)
        for y0, y1 in blocks:
            racks[ras.slices(x, y0, x + row_w, y1)] = True
            nb = max(int((y1 - y0) / 2.7), 1)
            b = (y1 - y0) / nb
            for s0 in (x, x + depth + flue):  # the two racks of the row
                s1 = s0 + depth
                for k in range(nb + 1):  # the uprights at every bay end, on both faces
                    yk = min(max(y0 + k * b, y0 + _UPRIGHT / 2), y1 - _UPRIGHT / 2)
                    for fx in (s0, s1 - _UPRIGHT):
                        occupied[ras.slices(fx, yk - _UPRIGHT / 2, fx + _UPRIGHT, yk + _UPRIGHT / 2)] = True
                for k in range(nb):
                    n_bays += 1
                    if rng.random() < full:  # a pallet load between the uprights
                        n_full += 1
                        occupied[ras.slices(s0 + 0.05, y0 + k * b + 0.1, s1 - 0.05, y0 + (k + 1) * b - 0.1)] = True
        x += row_w + aisle
    # the staging area: an office in a corner on the dock wall, loose pallets, dock door recesses
    ow, oh = rng.uniform(5.0, 8.0), rng.uniform(3.5, stage - 3.0)
    cx = 0.0 if rng.random() < 0.5 else W - ow
    wx = cx + ow if cx == 0.0 else cx
    occupied[ras.slices(cx, oh - h2, cx + ow, oh + h2)] = True
    occupied[ras.slices(wx - h2, 0.0, wx + h2, oh)] = True
    dx = rng.uniform(cx + 0.8, cx + ow - 2.0)
    occupied[ras.slices(dx, oh - 2 * h2, dx + 1.2, oh + 2 * h2)] = False
    rects = [(cx - 0.1, -0.1, cx + ow + 0.1, oh + 0.1)]
    for _ in range(int(rng.integers(4, 11))):
        s = rng.uniform(1.0, 1.3)
        r = _place_apart(rng, rects, (s, s), (2.0, 1.5, W - 2.0, stage - 1.5), 1.2)
        if r:
            rects.append(r)
            occupied[ras.slices(*r)] = True
    docks = []
    for _ in range(int(rng.integers(3, 8))):
        d = rng.uniform(1.0, W - 4.0)
        if all(abs(d - e) > 4.0 for e in docks) and (d + 3.0 < cx - 0.5 or d > cx + ow + 0.5):
            docks.append(d)
            interior[ras.slices(d, -0.4, d + 3.0, 0.0)] = True
    occupied &= interior
    zone = _zones(room_id, interior & ~racks, 0, int(round(6.0 / RESOLUTION)),
                  (int(round(_MARGIN / RESOLUTION)),) * 2)
    room_id[ras.slices(cx + h2, h2, cx + ow - h2, oh - h2)] = zone
    meta = {"kind": "warehouse", "size": (W, H), "racks": [(x0, y0, x0 + row_w, y1) for x0 in rows for y0, y1 in blocks],
            "aisle": aisle, "bays": n_bays, "full_bays": n_full, "docks": len(docks)}
    return _finish(interior, occupied, room_id, origin, clearance, meta, keep_out=racks)


# --------------------------------------------------------------------------
# Kinds
# --------------------------------------------------------------------------

KINDS = ("office", "rooms", "corridor", "hall", "clutter", "large", "warehouse")

# Per kind: the robot's speed (m/s) when simulate() is given none; the route planner's cell stride (1 = every
# 0.05 m cell; 4 = a 0.2 m lattice, for big maps) and longest leg (m of path to the next goal, None = any);
# the unmapped obstacles (people and boxes) and unmapped furniture when simulate() is given none; and a
# description of the size.
KIND_DEFAULTS: dict[str, dict] = {
    "office": {"speed": 0.5, "plan_stride": 1, "leg_max": None, "dynamic_obstacles": 0, "unmapped_furniture": 0,
               "size": "20 m x 15 m"},
    "rooms": {"speed": 0.5, "plan_stride": 1, "leg_max": None, "dynamic_obstacles": 0, "unmapped_furniture": 0,
              "size": "23-48 m x 10-13 m: 5-8 rooms of 3.6-5 m x 4-5.5 m per row"},
    "corridor": {"speed": 0.8, "plan_stride": 2, "leg_max": None, "dynamic_obstacles": 0, "unmapped_furniture": 0,
                 "size": "60-150 m long, 1.8-2.4 m wide, side corridors 8-20 m"},
    "hall": {"speed": 0.8, "plan_stride": 4, "leg_max": 35.0, "dynamic_obstacles": 0, "unmapped_furniture": 0,
             "size": "40-80 m x 30-60 m"},
    "clutter": {"speed": 0.4, "plan_stride": 1, "leg_max": None, "dynamic_obstacles": 10,
                "unmapped_furniture": 12, "size": "20 m x 15 m, 40 extra small items"},
    "large": {"speed": 1.0, "plan_stride": 4, "leg_max": 40.0, "dynamic_obstacles": 0, "unmapped_furniture": 0,
              "size": "150-200 m x 90-130 m"},
    "warehouse": {"speed": 0.8, "plan_stride": 2, "leg_max": 40.0, "dynamic_obstacles": 0, "unmapped_furniture": 0,
                  "size": "40-70 m x 30-50 m: rows of pallet racks, 2.8-3.4 m aisles"},
}


def generate(kind: str, rng: np.random.Generator, *, clearance: float = 0.42) -> World:
    """The world of ``kind`` (one of ``KINDS``) drawn with ``rng``."""
    if kind == "office":
        return make_world(rng, clearance=clearance)
    if kind == "clutter":
        return make_world(rng, clearance=clearance, small_items=40)
    makers = {"rooms": _rooms_world, "corridor": _corridor_world, "hall": _hall_world, "large": _large_world,
              "warehouse": _warehouse_world}
    if kind not in makers:
        raise ValueError(f"unknown world kind {kind!r}; expected one of {', '.join(KINDS)}")
    return makers[kind](rng, clearance)
