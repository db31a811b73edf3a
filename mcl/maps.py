"""Occupancy grids: ROS map_server YAML + PGM/PNG, world<->cell, distance field, free sampling.

Grid arrays are indexed ``[iy, ix]`` with row 0 at the *bottom* (world
y = origin_y): the image flipped vertically. ``ix = floor((x - x0) / res)``.

Pixel semantics follow ROS 1 map_server (``image_loader.cpp``; ``mode`` key):

* v is the mean of the pixel's channels, a float (SDL_image's layout: grey 1 channel, grey + alpha as RGBA). In
  ``trinary`` mode an alpha channel is averaged in with the colours (ROS 1 and nav2 alike: opaque grey 205 gives
  (3 * 205 + 255) / 4 = 217.5, free); in the other modes it is left out.
* p = (255 - v) / 255, or v / 255 when ``negate``.
* ``trinary`` (default): p > occupied_thresh -> 100, p < free_thresh -> 0, else -1.
* ``scale``: as trinary, but in-between values become ``int(1 + 98 * (p - free) / (occ - free))`` (1..99), or -1
  where alpha is 0 (ROS 1; nav2 gives ``rint(100 * ratio)`` and -1 for any pixel not fully opaque).
* ``raw``: occupancy = int(v) (truncated, as ROS 1) when v <= 100, else -1; ``negate`` ignored (as nav2; ROS 1
  negates, and casts 101..255 into the int8 as they are).
* A palette image is read by its colours (nav2; ROS 1 reads the palette indices). A PGM with maxval < 255 is
  scaled as SDL_image scales it, v * 255 // maxval; a 16-bit image (PNG, or PGM with maxval > 255) to
  v * 255 / maxval rounded (ROS 1 keeps a PNG's high byte and refuses such a PGM; nav2 reads both unrounded).

Any problem with a map file raises :class:`DataError` with one line naming
the file and the YAML key; nothing else escapes :func:`load_map`.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from mcl.errors import DataError
from mcl.trajectory import atomic_write_bytes, atomic_write_text
from mcl.yamlfile import finite_number, read_yaml, short_repr

__all__ = ["OccupancyGrid", "load_map", "save_map"]

_MODES = ("trinary", "scale", "raw")

# Memory a localization needs per map cell: the distance field, the likelihood table and the map-rejection mask
# take 17-20 bytes a cell tracking; a global start, or a search after the track is lost (which any run with recovery
# may start), adds the search's tables: 28-30 (2026-12-07, 100 M and 208 M cells with a recording: 19.5 / 17.4
# tracking, 29.8 / 28.2 global; a map checked at 17 passed at 1.7 times what the machine had). A map whose cells
# need more than the machine has is refused before its image is decoded.
BYTES_PER_CELL = 30


def available_memory() -> int | None:
    """Bytes this process can still take, RAM and swap (Linux /proc/meminfo: MemAvailable + SwapFree); None where
    that is not known."""
    try:
        with open("/proc/meminfo") as f:
            info = {k: v for k, v in (line.split(":", 1) for line in f if ":" in line)}
        return 1024 * (int(info["MemAvailable"].split()[0]) + int(info.get("SwapFree", "0 kB").split()[0]))
    except (OSError, KeyError, ValueError, IndexError):
        return None


def _check_memory(label: str, width: int, height: int) -> None:
    """One line, before the image is decoded, when the map's tables cannot fit in this machine's memory."""
    need, have = BYTES_PER_CELL * width * height, available_memory()
    if have is not None and need > have:
        def size(b: int) -> str:
            return f"{b / 1e9:.1f} GB" if b >= 1e9 else f"{b / 1e6:.0f} MB"

        raise DataError(f"{label}: {width} x {height} cells need about {size(need)} to localize in "
                        f"({BYTES_PER_CELL} bytes a cell: distance field, likelihood tables, rejection mask, a "
                        "search's tables); "
                        f"{size(have)} of memory is available: crop the map to where the robot drives, or "
                        "coarsen its resolution")


@dataclass(eq=False)
class OccupancyGrid:
    """A 2D occupancy grid with ROS OccupancyGrid values (-1 unknown, 0..100)."""

    occupancy: np.ndarray  # int8 (H, W), row 0 = bottom
    resolution: float  # metres per cell
    origin: tuple[float, float]  # world (x0, y0) of the lower-left corner of cell (0, 0)
    path: str = "<memory>"
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    notes: tuple[str, ...] = ()  # what loading it did that a user of another tool would not expect (mcl run prints)

    @classmethod
    def from_occupancy(cls, occupancy, resolution: float, origin, path: str = "<memory>",
                       occupied_thresh: float = 0.65, free_thresh: float = 0.196) -> "OccupancyGrid":
        """Build a grid in memory from an (H, W) array of ROS occupancy values (-1 unknown, 0..100 the occupancy in
        per cent, as a nav_msgs/OccupancyGrid) whose row 0 is the bottom; copied, so a later change of the caller's
        array does not leave the cached fields stale. Any other value is a ValueError: a bool wall mask, a float
        probability grid or an image's 0/254 pixels were cast to int8 as they came (walls free, 254 unknown)."""
        a = np.asarray(occupancy)
        if a.dtype == np.bool_ or not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
            raise ValueError(f"{path}: occupancy must hold numbers -1..100 (a ROS OccupancyGrid's), got dtype {a.dtype}"
                             " (a wall mask: np.where(mask, 100, 0))")
        if a.size and (not np.all(np.isfinite(a)) or a.min() < -1 or a.max() > 100 or np.any(a != np.round(a))):
            raise ValueError(f"{path}: occupancy must hold whole numbers -1..100 (a ROS OccupancyGrid's), got "
                             f"values in {a.min().item()!r}..{a.max().item()!r} (an image: load_map reads its map.yaml)")
        occ = np.array(a, dtype=np.int8, order="C")  # a copy
        if occ.ndim != 2 or occ.shape[0] == 0 or occ.shape[1] == 0:
            raise ValueError(f"{path}: occupancy must be a non-empty 2D array, got shape {occ.shape}")
        if not (math.isfinite(resolution) and resolution > 0):
            raise ValueError(f"{path}: resolution must be positive, got {resolution}")
        x0, y0 = float(origin[0]), float(origin[1])
        return cls(occ, float(resolution), (x0, y0), path, float(occupied_thresh), float(free_thresh))

    # --- shape -----------------------------------------------------------
    @property
    def width(self) -> int:
        return int(self.occupancy.shape[1])

    @property
    def height(self) -> int:
        return int(self.occupancy.shape[0])

    # --- classified cells (cached) --------------------------------------
    @cached_property
    def occupied(self) -> np.ndarray:
        o = self.occupancy
        return (o >= 0) & (o > self.occupied_thresh * 100.0)

    @cached_property
    def free(self) -> np.ndarray:
        o = self.occupancy
        return (o >= 0) & (o < self.free_thresh * 100.0)

    @cached_property
    def solid_share(self) -> float:
        """The share of the occupied cells that lie deeper than one cell (their four neighbours occupied; off the map
        counts as occupied): how the walls were drawn. A map made by SLAM marks the cells its returns fell in, so its
        walls are the surfaces the laser saw, one or two cells thick (the shared logs' maps: 0.01-0.05, fr079 0.20);
        a map drawn from geometry (a floor plan, CAD, ``mcl simulate``) fills each wall's whole thickness (the
        generated worlds: 0.33-0.63). 0 without occupied cells."""
        n = int(np.count_nonzero(self.occupied))
        return self._interior_cells[0].size / n if n else 0.0

    @cached_property
    def _interior_cells(self) -> tuple[np.ndarray, np.ndarray]:
        """(ys, xs): the occupied cells whose four neighbours are occupied (off the map: occupied), the only cells
        deeper than one cell (``mcl.kernels.depth.interior_cells``), found once for ``solid_share`` and every
        tolerance's ``surface_patches``."""
        from mcl.kernels.depth import interior_cells

        return interior_cells(byte_mask(self.occupied))

    @cached_property
    def free_area(self) -> float:
        """m² of free space."""
        return float(np.count_nonzero(self.free)) * self.resolution ** 2

    @cached_property
    def unknown(self) -> np.ndarray:
        return ~(self.occupied | self.free)

    @cached_property
    def distance(self) -> np.ndarray:
        """float32 (H, W): metres from each cell centre to the nearest occupied cell centre.

        0 on occupied cells; the map diagonal everywhere when nothing is occupied. The exact transform of the
        ``edt`` package (Felzenszwalb-Huttenlocher, multi-threaded): on a 250 m map (25 M cells) 0.3 s against
        scipy.ndimage's 1.9 s, and a quarter of its memory; the same values to the bit.
        """
        occ = self.occupied
        if not occ.any():
            diag = math.hypot(self.width, self.height) * self.resolution
            return np.full(occ.shape, diag, dtype=np.float32)
        return _metres(_edt_squared(~occ), self.resolution)

    def surface_distance(self, tolerance: float = 0.0) -> np.ndarray:
        """float32 (H, W): metres from each cell centre to the nearest obstacle *surface* (cached per tolerance).

        ``distance`` off the obstacles; on an occupied cell its depth, the distance to the nearest
        non-occupied cell centre less one cell (0 on a wall's face, 0.05 one cell in at 5 cm) and less
        ``tolerance`` metres (at least 0). A laser return lies on a surface, so an endpoint deep inside a
        desk or a thick wall (seen through a thin wall from the wrong side) is as unlikely as one that far
        out in free space: with depth 0 there (``distance``, AMCL's field), a pose 0.3 m too far forward put
        the far wall's returns into the furniture behind it and scored *better* than the true pose
        (suites/synthetic.yaml large-02). Used by the likelihood field with ``interior: depth``.
        """
        cache = self.__dict__.setdefault("_surface_cache", {})
        key = float(tolerance)
        if key not in cache:
            cache[key] = self._patched(self.surface_patches(key))
        return cache[key]

    def _surface_distance(self, extra_cells: float, tile: int = 128, margin: int = 16) -> np.ndarray:
        """``surface_distance`` with ``extra_cells`` of tolerance, made afresh with other tile sizes (tests)."""
        return self._patched(self._surface_patches(extra_cells, tile, margin))

    def _patched(self, patches: list) -> np.ndarray:
        d = np.array(self.distance, dtype=np.float32)
        for y0, y1, x0, x1, mine, metres in patches:
            d[y0:y1, x0:x1][mine] = metres
        return d

    def solid_regions(self, depth: float) -> np.ndarray | None:
        """(H, W) bool: the occupied cells of the obstacles' parts at least 2 ``depth`` m wide (the morphological
        opening of the occupied cells by a disc of radius ``depth``: within ``depth`` of a cell that deep inside), or
        None when no cell is that deep. Not a wall or furniture but a region the laser never sees into: a floor plan's
        black outside, unknown space painted occupied. One transform of the map when there is such a cell."""
        core = None
        for y0, y1, x0, x1, mine, metres in self.surface_patches(0.0):
            deep = metres >= depth
            if deep.any():
                if core is None:
                    core = np.zeros(self.occupancy.shape, dtype=bool)
                core[y0:y1, x0:x1][mine] = deep
        if core is None:
            return None
        reach = depth / self.resolution + 1.0  # cells: the depth counts from the face cell (less one cell)
        return (_edt_squared(~core) <= reach * reach) & self.occupied

    def surface_patches(self, tolerance: float = 0.0) -> list:
        """Where ``surface_distance(tolerance)`` differs from ``distance``: (y0, y1, x0, x1, mine, metres) per tile,
        ``mine`` the (y1 - y0, x1 - x0) bool mask of the tile's cells set to the float32 ``metres`` (cached per
        tolerance). The likelihood field builds its ``interior: depth`` table from ``distance`` and these, without a
        copy of the whole map (250 m map: 100 MB less to allocate and fill)."""
        cache = self.__dict__.setdefault("_surface_patches_cache", {})
        key = float(tolerance)
        if key not in cache:
            cache[key] = self._surface_patches(key / self.resolution)
        return cache[key]

    def _surface_patches(self, extra_cells: float, tile: int = 128, margin: int = 16) -> list:
        occ = self.occupied
        # only cells whose four neighbours are occupied lie deeper than one cell; the depth transform runs on
        # the tiles holding such cells, each in a window ``margin`` cells wider (250 m map: 0.17 s, against 0.6 s
        # for scipy.ndimage's labelling and import and 1.2 s for a whole-map transform; the same values)
        from mcl.kernels.depth import ring_depths

        ys, xs = self._interior_cells  # occupied with its four neighbours occupied (off the map: occupied)
        if ys.size == 0:
            return []
        occ8 = byte_mask(occ)
        h, w = occ.shape
        per_row = -(-w // tile)
        tile_of = (ys // tile) * per_row + xs // tile
        # each such cell's depth by a search in rings out to ``margin`` cells (mcl.kernels.depth): walls a few cells
        # thick resolve at once; a tile with a cell deeper than that takes the transforms below
        ring = np.empty(ys.size, dtype=np.int64)
        ring_depths(occ8, ys, xs, int(margin), ring)
        deep = set(np.unique(tile_of[ring < 0]).tolist())
        order = np.argsort(tile_of, kind="stable")  # per tile, its cells in row-major order (as a mask assigns)
        tiles, starts = np.unique(tile_of[order], return_index=True)
        whole = None  # the whole map's transform, made once when windows do not do (see below)
        widened = 0
        patches = []
        for t, lo, hi in zip(tiles.tolist(), starts.tolist(), [*starts[1:].tolist(), order.size]):
            ty, tx = divmod(int(t), per_row)
            y0, y1, x0, x1 = ty * tile, min(ty * tile + tile, h), tx * tile, min(tx * tile + tile, w)
            if t not in deep:  # only the cells deeper than one cell differ from ``distance`` (the others are 0 there)
                cells = order[lo:hi]
                mine = np.zeros((y1 - y0, x1 - x0), dtype=bool)
                mine[ys[cells] - y0, xs[cells] - x0] = True
                depth = np.sqrt(ring[cells].astype(np.float64))
                metres = (np.maximum(depth - 1.0 - extra_cells, 0.0) * self.resolution).astype(np.float32)
                patches.append((y0, y1, x0, x1, mine, metres))
                continue
            sq, m = None, margin
            while whole is None and m <= tile and widened <= _MAX_WIDENED:
                wy0, wy1, wx0, wx1 = max(y0 - m, 0), min(y1 + m, h), max(x0 - m, 0), min(x1 + m, w)
                sq = _edt_squared(occ[wy0:wy1, wx0:wx1])[y0 - wy0:y1 - wy0, x0 - wx0:x1 - wx0]
                # exact wherever it is <= m: a non-occupied cell that near lies inside the window
                if float(sq.max()) <= m * m or (wy0, wy1, wx0, wx1) == (0, h, 0, w):
                    break
                sq, m, widened = None, 2 * m, widened + 1
            if sq is None:  # deeper than a tile, or windows widened on many tiles (a map painted solid outside
                if whole is None:  # its walls): from here on one transform of the whole map serves every tile
                    whole = _edt_squared(occ)
                sq = whole[y0:y1, x0:x1]
            mine = occ[y0:y1, x0:x1] & np.isfinite(sq)  # inf: no non-occupied cell on the map, depth 0 as before
            depth = np.sqrt(sq[mine], dtype=np.float64)
            metres = (np.maximum(depth - 1.0 - extra_cells, 0.0) * self.resolution).astype(np.float32)
            patches.append((y0, y1, x0, x1, mine, metres))
        return patches

    # --- coordinates -----------------------------------------------------
    def world_to_cell(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Cell indices (ix, iy), int64, of world points (no bounds check: see :meth:`contains`)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        ix = np.floor((x - self.origin[0]) / self.resolution).astype(np.int64)
        iy = np.floor((y - self.origin[1]) / self.resolution).astype(np.int64)
        return ix, iy

    def cell_to_world(self, ix, iy) -> tuple[np.ndarray, np.ndarray]:
        """World coordinates of cell centres."""
        ix = np.asarray(ix, dtype=np.float64)
        iy = np.asarray(iy, dtype=np.float64)
        return (self.origin[0] + (ix + 0.5) * self.resolution,
                self.origin[1] + (iy + 0.5) * self.resolution)

    def contains(self, ix, iy) -> np.ndarray:
        """Boolean mask: cell indices inside the grid."""
        ix = np.asarray(ix)
        iy = np.asarray(iy)
        return (ix >= 0) & (ix < self.width) & (iy >= 0) & (iy < self.height)

    def mask_at(self, mask: np.ndarray, x, y) -> np.ndarray:
        """bool per world point (x, y): ``mask`` (an (H, W) per-cell array, True/nonzero = set) at the point's
        cell; False off the map and for non-finite coordinates."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            fx = np.floor((x - self.origin[0]) / self.resolution)
            fy = np.floor((y - self.origin[1]) / self.resolution)
        h, w = mask.shape
        inside = (fx >= 0) & (fx < w) & (fy >= 0) & (fy < h)  # NaN fails every comparison
        out = np.zeros(x.shape, dtype=bool)
        out[inside] = mask[fy[inside].astype(np.int64), fx[inside].astype(np.int64)] != 0
        return out

    # --- sampling --------------------------------------------------------
    def free_cells(self, clearance: float = 0.0) -> np.ndarray:
        """Flat indices (int64, ascending) of the free cells farther than ``clearance`` from obstacles.

        Computed once per clearance and kept: on a 250 m map (25 M cells) the scan of the whole grid takes
        about 50 ms, far too long to repeat at every recovery injection.
        """
        cache = self.__dict__.setdefault("_free_cells", {})
        key = float(clearance)
        if key not in cache:
            cache[key] = np.flatnonzero(self.free & (self.distance > key))
        return cache[key]

    def sample_free(self, n: int, rng: np.random.Generator, clearance: float = 0.0) -> np.ndarray:
        """(3, n) float64 poses uniform over free cells farther than ``clearance`` from obstacles.

        Position uniform inside the chosen cell, theta uniform in [-pi, pi).
        """
        cells = self.free_cells(clearance)
        if cells.size == 0:
            raise DataError(f"{self.path}: no free cell with clearance > {clearance} m to sample from")
        pick = cells[rng.integers(0, cells.size, size=n)]
        iy, ix = np.divmod(pick, self.width)
        out = np.empty((3, n), dtype=np.float64)
        out[0] = self.origin[0] + (ix + rng.random(n)) * self.resolution
        out[1] = self.origin[1] + (iy + rng.random(n)) * self.resolution
        out[2] = rng.uniform(-math.pi, math.pi, size=n)
        return out


# --- loading ------------------------------------------------------------

# A number in quotes: yaml-cpp (ROS's YAML reader) converts any scalar, so ``resolution: "0.05"`` is 0.05 to ROS.
_DECIMAL = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")

# The finest resolution taken: below it world -> cell indices overflow int64 for ordinary coordinates (1e-20 m:
# NumPy's "invalid value encountered in cast" and a map of no size)
_MIN_RESOLUTION = 1e-6


def _number(value, label: str) -> float:
    """``value`` as a finite float (:func:`finite_number`), a number in quotes too."""
    if isinstance(value, str) and _DECIMAL.fullmatch(value.strip()):
        value = float(value)
    return finite_number(value, label, DataError)


def _num(doc: dict, key: str, where: str) -> float:
    return _number(doc[key], f"{where}: {key}")


_MAX_WIDENED = 64  # window widenings in OccupancyGrid._surface_patches before the whole map's transform


def byte_mask(mask) -> np.ndarray:
    """``mask`` as a C-contiguous uint8 (H, W) array (0 / 1) for the kernels: a view of a contiguous bool array (no
    copy: on a 250 m map 25 MB less to allocate and fill), else a converted copy."""
    if isinstance(mask, np.ndarray) and mask.dtype == np.bool_ and mask.flags.c_contiguous:
        return mask.view(np.uint8)
    return np.ascontiguousarray(mask, dtype=np.uint8)


def _edt_squared(mask: np.ndarray) -> np.ndarray:
    """float32 (H, W): squared Euclidean distance, in cells, from each True cell to the nearest False one (0 on
    the False cells; nothing beyond the border counts as False). Integers, exact in float32 below 2^24."""
    import edt
    import numba

    return edt.edtsq(np.ascontiguousarray(mask), black_border=False, parallel=max(1, numba.get_num_threads()))


def _metres(squared_cells: np.ndarray, resolution: float) -> np.ndarray:
    """float32 sqrt(squared_cells) * resolution, computed in float64 (as scipy.ndimage did) in row blocks that
    stay in cache (0.04 s against 0.3 s whole on 25 M cells)."""
    out = np.empty(squared_cells.shape, dtype=np.float32)
    step = max(1, (1 << 16) // max(squared_cells.shape[1], 1))
    for r in range(0, squared_cells.shape[0], step):
        block = np.sqrt(squared_cells[r:r + step], dtype=np.float64)
        block *= resolution
        out[r:r + step] = block
    return out


def _printable(s: str) -> str:
    """``s`` for a one-line message: control characters (a newline in a file name) escaped."""
    return s if s.isprintable() else repr(s)[1:-1]


# Pillow modes read as another: to grey, RGB or RGBA (a palette: see _read_image)
_CONVERT = {"1": "L", "La": "LA", "RGBa": "RGBA", "PA": "RGBA", "RGBX": "RGB", "CMYK": "RGB", "YCbCr": "RGB",
            "LAB": "RGB", "HSV": "RGB"}
_PNM_NUMBER = re.compile(rb"(?:\s|#[^\r\n]*)*([0-9]{1,9})")  # a PNM header's next number, past comments


def _pgm_maxval(data: bytes) -> int | None:
    """The maxval of a PGM's header (P2, P5); None for any other file."""
    if data[:2] not in (b"P2", b"P5"):
        return None
    pos = 2
    for _ in range(3):  # width, height, maxval
        m = _PNM_NUMBER.match(data, pos)
        if m is None:
            return None
        pos = m.end()
    return int(m.group(1)) or None


def _read_image(img_path: Path, where: str) -> tuple[np.ndarray, int, np.ndarray | None]:
    """Return (colour, n, alpha), image row 0 = top: ``colour`` the (H, W) sum of the pixel's ``n`` colour channels
    (uint8 for grey, n = 1; uint16 for colour, n = 3, a grey + alpha image as RGBA as SDL_image loads it), ``alpha``
    the (H, W) uint8 alpha channel or None."""
    from PIL import Image, UnidentifiedImageError

    label = f"{where}: image: {_printable(str(img_path))}"
    f = None
    try:  # opened, not read: a map too big for the memory is refused from its header (reading a 2.5 GB image
        # first took 13 s and 2.6 GB to say so)
        f = open(img_path, "rb")
        head = f.read(1 << 16)  # a PGM's header, for its maxval
        f.seek(0)
    except (OSError, ValueError) as e:
        if f is not None:
            f.close()
        reason = getattr(e, "strerror", None) or type(e).__name__
        raise DataError(f"{label}: cannot read image: {reason}") from None
    if not head:
        f.close()
        raise DataError(f"{label}: empty file")
    # Pillow's decompression-bomb guard (a warning above 89 M pixels, an error above 179 M) is for images from the
    # web; a map is the user's own file, and a 500 m building at 5 cm has 100 M cells.
    bomb_limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
    try:
        with f, Image.open(f) as im:
            _check_memory(label, *im.size)  # the header's size, before the pixels are decoded
            im.load()
            fmt, mode = im.format, im.mode
            if mode == "P":  # by its colours; alpha only where the palette has transparency (PNG tRNS)
                mode = "RGBA" if "transparency" in im.info else "RGB"
            mode = _CONVERT.get(mode, mode)
            if mode != im.mode:
                im = im.convert(mode)
            arr = np.asarray(im)
    except DataError:
        raise
    except UnidentifiedImageError:
        raise DataError(f"{label}: not an image file (PGM, PNG or another format Pillow reads)") from None
    except Exception as e:  # Pillow raises many types on corrupt input; none may escape
        msg = str(e).replace("\n", " ") or type(e).__name__
        raise DataError(f"{label}: truncated or corrupt image ({msg})") from None
    finally:
        Image.MAX_IMAGE_PIXELS = bomb_limit
    alpha = None
    if arr.ndim == 2:
        n = 1
        # Pillow scales a PGM by its maxval, rounded: to 0..255 (maxval <= 255) or 0..65535 (mode I)
        maxval = _pgm_maxval(head) if fmt == "PPM" else None
        if mode == "L":
            colour = arr
            if maxval is not None and maxval < 255:  # SDL_image (ROS 1): v * 255 // maxval, truncated
                v = np.rint(np.arange(256) * (maxval / 255.0))  # the file's values, from Pillow's
                colour = ((v * 255) // maxval).astype(np.uint8)[arr]
        else:  # 16 or 32 bits a pixel: to 0..255, rounded
            raw = arr.astype(np.float64)
            if fmt == "PPM":
                top = float(maxval or 65535)
                raw = np.rint(raw * (top / 65535.0))  # the file's values, from Pillow's
            elif fmt == "PNG" or mode.startswith("I;16"):
                top = 65535.0
            else:  # a format whose range is not known (TIFF, float): a guess from the values
                top = 65535.0 if (arr.size and arr.max() > 255) else 255.0
            colour = np.clip(np.rint(np.nan_to_num(raw * (255.0 / top))), 0, 255).astype(np.uint8)
    elif arr.ndim == 3 and arr.shape[2] == 2:  # grey + alpha: RGBA to SDL_image, three equal colours
        colour, n, alpha = arr[:, :, 0].astype(np.uint16) * 3, 3, arr[:, :, 1]
    elif arr.ndim == 3 and arr.shape[2] in (3, 4):
        colour, n = arr[:, :, :3].sum(axis=2, dtype=np.uint16), 3
        alpha = arr[:, :, 3] if arr.shape[2] == 4 else None
    else:
        raise DataError(f"{label}: unsupported image layout {arr.shape} (mode {mode})")
    if colour.size == 0:
        raise DataError(f"{label}: empty image")
    return colour, n, alpha


UNKNOWN_GREY = 205  # map_saver's pixel for an unknown cell (ROS 1 and nav2)
# what --map given an image instead of its YAML starts with
_IMAGE_MAGIC = ((b"P2", "PGM"), (b"P5", "PGM"), (b"\x89PNG", "PNG"), (b"\xff\xd8\xff", "JPEG"), (b"BM", "BMP"),
                (b"II*\x00", "TIFF"), (b"MM\x00*", "TIFF"))


def load_map(path: str | os.PathLike) -> OccupancyGrid:
    """Load a ROS map_server map (YAML + PGM/PNG) into an :class:`OccupancyGrid`."""
    where = str(path)
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError:
        head = b""  # read_yaml says why
    kind = next((k for magic, k in _IMAGE_MAGIC if head.startswith(magic)), None)
    if kind is not None:  # it said "not a UTF-8 text file" or "invalid YAML" of the image's bytes
        raise DataError(f"{where}: a {kind} image, not a map: give the map_server YAML that names it (image:, "
                        "resolution:, origin:, ...)")
    doc = read_yaml(path, DataError)
    if not isinstance(doc, dict):
        raise DataError(f"{where}: expected a YAML mapping with keys image, resolution, origin, ...")
    for key in ("image", "resolution", "origin", "occupied_thresh", "free_thresh"):
        if key not in doc:  # a misspelled key named: "resolution: missing key" beside a `resolutoin:` said nothing
            import difflib

            typo = difflib.get_close_matches(key, [str(k) for k in doc], n=1)
            raise DataError(f"{where}: {key}: missing key" + (f" (is {short_repr(typo[0])[1:-1]}: meant?)"
                                                              if typo else ""))

    image = doc["image"]
    if not isinstance(image, str) or not image.strip():
        raise DataError(f"{where}: image: expected a file name, got {short_repr(image)}")
    resolution = _num(doc, "resolution", where)
    if resolution <= 0:
        raise DataError(f"{where}: resolution: must be positive, got {resolution}")
    if resolution < _MIN_RESOLUTION:
        raise DataError(f"{where}: resolution: must be at least {_MIN_RESOLUTION:g} m a cell, got {resolution:g}")

    origin = doc["origin"]
    if not isinstance(origin, list) or len(origin) not in (2, 3):
        raise DataError(f"{where}: origin: expected [x, y, yaw], got {short_repr(origin)}")
    try:
        vals = [_number(v, "origin") for v in origin]
    except DataError:
        raise DataError(f"{where}: origin: expected finite numbers [x, y, yaw], got {short_repr(origin)}") from None
    yaw = vals[2] if len(vals) == 3 else 0.0

    occ_th = _num(doc, "occupied_thresh", where)
    free_th = _num(doc, "free_thresh", where)
    for key, v in (("occupied_thresh", occ_th), ("free_thresh", free_th)):
        if not 0.0 <= v <= 1.0:
            raise DataError(f"{where}: {key}: must be in [0, 1], got {v}")
    if free_th >= occ_th:
        raise DataError(f"{where}: free_thresh: must be below occupied_thresh ({free_th} >= {occ_th})")

    negate = doc.get("negate", 0)
    if isinstance(negate, bool):
        negate = int(negate)
    elif isinstance(negate, str) and _DECIMAL.fullmatch(negate.strip()):
        negate = float(negate)
    if not isinstance(negate, (int, float)) or negate not in (0, 1):
        raise DataError(f"{where}: negate: expected 0 or 1, got {short_repr(doc.get('negate'))}")

    mode = doc.get("mode", "trinary")
    if not isinstance(mode, str) or mode not in _MODES:
        raise DataError(f"{where}: mode: expected one of {', '.join(_MODES)}, got {short_repr(mode)}")

    try:
        img_path = Path(path).parent / image
    except (ValueError, TypeError):
        raise DataError(f"{where}: image: invalid file name {short_repr(image)}") from None
    colour, n, alpha = _read_image(img_path, where)

    occupancy = _classify(colour, n, alpha, mode, bool(negate), occ_th, free_th)
    # map_saver's unknown grey read as free (below): counted as classified, an opaque alpha channel averaged in
    grey = (int(np.count_nonzero((colour == UNKNOWN_GREY * n) & (occupancy == 0)))
            if mode != "raw" and not negate else 0)
    # Image row 0 is the top; the grid's row 0 is the bottom.
    occupancy = np.ascontiguousarray(occupancy[::-1])
    occupancy, corner = axis_aligned(occupancy, resolution, (vals[0], vals[1]), yaw, label=where)
    notes = ()
    if yaw != 0.0:
        notes = (f"{where}: origin yaw {yaw:g} rad: the map is turned about its lower-left corner, as ROS "
                 "map_server defines the origin (AMCL ignores the yaw)",)
    if grey >= 0.01 * colour.size:
        # map_saver writes unknown cells grey 205 (p = 0.196); nav2's saves free_thresh 0.25 beside them, and
        # map_server (AMCL's too) then reads them free: a global search spread over every unknown cell. An opaque
        # alpha channel, averaged in as trinary mode does, makes them 217.5 (p = 0.147): free under 0.196 too
        if alpha is not None and mode == "trinary":
            notes += (f"{where}: {100.0 * grey / colour.size:.0f}% of the image is grey {UNKNOWN_GREY}, map_saver's "
                      "unknown, read as free: trinary mode averages the alpha channel in (as map_server does), so "
                      "an opaque grey 205 is 217.5: if those cells are unknown, save the image without alpha",)
        else:
            notes += (f"{where}: {100.0 * grey / colour.size:.0f}% of the image is grey {UNKNOWN_GREY}, map_saver's "
                      f"unknown, read as free under free_thresh {free_th:g} (as map_server reads it; nav2's "
                      "map_saver writes 0.25): if those cells are unknown, set free_thresh: 0.196",)
    if mode == "scale":  # 1..99 are the pixels between the thresholds: neither free nor occupied (AMCL's reading)
        return OccupancyGrid(occupancy, resolution, corner, where, 0.99, 0.01, notes)
    return OccupancyGrid(occupancy, resolution, corner, where, occ_th, free_th, notes)


def axis_aligned(occupancy: np.ndarray, resolution: float, origin, yaw: float, label: str | None = None):
    """(occupancy, origin) of a map whose lower-left cell sits at ``origin`` turned by ``yaw`` (map_server's
    ``origin: [x, y, yaw]``: the image rotated counter-clockwise about its lower-left corner), on an axis-aligned
    grid of the same resolution that holds it: each new cell takes the value of the map cell under its centre
    (nearest cell), unknown (-1) outside the map. A yaw of a quarter turn (0, pi/2, pi, 3 pi/2, to 1e-9 rad) is an
    exact turn of the array. The filter's kernels index an axis-aligned grid; resampling once at load keeps them
    so. With ``label``, a turned grid too large for this machine's memory is one line naming it (as the image
    itself is before it is decoded)."""
    x0, y0 = float(origin[0]), float(origin[1])
    k = yaw / (0.5 * math.pi)
    if abs(k - round(k)) * 0.5 * math.pi < 1e-9:  # a quarter turn: exact
        q = int(round(k)) % 4
        h, w = occupancy.shape
        size = {0: (0.0, 0.0), 1: (-h, 0.0), 2: (-w, -h), 3: (0.0, -w)}[q]  # the new lower-left corner, in cells
        return (np.ascontiguousarray(np.rot90(occupancy, -q)),  # rows run up (y), columns right (x)
                (x0 + size[0] * resolution, y0 + size[1] * resolution))
    h, w = occupancy.shape
    c, s_ = math.cos(yaw), math.sin(yaw)
    cx = np.array([0.0, w, 0.0, w]) * resolution
    cy = np.array([0.0, 0.0, h, h]) * resolution
    wx, wy = x0 + c * cx - s_ * cy, y0 + s_ * cx + c * cy  # the image's corners in the world
    left, bottom = float(wx.min()), float(wy.min())
    nw = int(math.ceil((float(wx.max()) - left) / resolution - 1e-9))
    nh = int(math.ceil((float(wy.max()) - bottom) / resolution - 1e-9))
    if label is not None:
        _check_memory(f"{label} (turned by its origin's yaw {yaw:g} rad)", nw, nh)
    out = np.full((nh, nw), -1, dtype=np.int8)
    px = left + (np.arange(nw) + 0.5) * resolution - x0
    for r0 in range(0, nh, 512):  # bounded memory on huge maps: a band of rows at a time
        py = (bottom + (np.arange(r0, min(r0 + 512, nh)) + 0.5) * resolution - y0)[:, None]
        # the new cell centres in the image's own frame (the inverse rotation), in cells
        u = np.floor((c * px[None, :] + s_ * py) / resolution).astype(np.int64)
        v = np.floor((-s_ * px[None, :] + c * py) / resolution).astype(np.int64)
        inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
        band = out[r0:r0 + py.shape[0]]
        band[inside] = occupancy[v[inside], u[inside]]
    return out, (left, bottom)


def _classify(colour: np.ndarray, n: int, alpha: np.ndarray | None, mode: str, negate: bool,
              occ_th: float, free_th: float) -> np.ndarray:
    """Pixels (the sum of ``n`` colour channels, alpha) -> int8 occupancy, exactly as ROS 1 map_server.

    Through a table with an entry per channel sum (a 250 m map's 25 M pixels: one gather instead of float64 arrays
    of the whole image)."""
    sums, k = colour, n
    if mode == "trinary" and alpha is not None:  # alpha averaged in (ROS 1's and nav2's trinary mode)
        sums, k = colour + alpha.astype(np.uint16), n + 1
    out = _classify_values(np.arange(255 * k + 1), k, mode, negate, occ_th, free_th)[sums]
    if mode == "scale" and alpha is not None:  # ROS 1: in-between and alpha 0 (nav2: any pixel not opaque)
        out[(alpha == 0) & (out > 0) & (out < 100)] = -1
    return out


def _classify_values(sums: np.ndarray, k: int, mode: str, negate: bool, occ_th: float, free_th: float) -> np.ndarray:
    """map_server's rule for pixels whose ``k`` averaged channels sum to ``sums`` (scale mode's alpha aside)."""
    if mode == "raw":
        v = sums // k  # the mean truncated, as ROS 1 casts it
        return np.where(v <= 100, v, -1).astype(np.int8)
    v = sums / k  # a double, as ROS 1's color_avg
    if negate:
        v = 255.0 - v
    p = (255.0 - v) / 255.0
    out = np.full(sums.shape, -1, dtype=np.int8)
    occ = p > occ_th
    free = p < free_th
    if mode == "scale":
        between = ~(occ | free)
        ratio = (p[between] - free_th) / (occ_th - free_th)
        out[between] = (1.0 + 98.0 * ratio).astype(np.int8)  # ROS 1's 1 + 98 * ratio, truncated (1..99)
    out[occ] = 100
    out[free] = 0
    return out


# --- saving -------------------------------------------------------------

def save_map(grid: OccupancyGrid, yaml_path: str | os.PathLike) -> None:
    """Write ``grid`` as a trinary P5 PGM (0 occupied, 254 free, 205 unknown) + YAML beside it.

    The image is named after the YAML's stem; both files are written atomically.
    """
    yaml_path = Path(yaml_path)
    pgm_path = yaml_path.with_suffix(".pgm")
    img = np.full(grid.occupancy.shape, 205, dtype=np.uint8)
    img[grid.free] = 254
    img[grid.occupied] = 0
    img = img[::-1]  # grid row 0 = bottom; PGM row 0 = top
    header = f"P5\n# written by mcl\n{grid.width} {grid.height}\n255\n".encode("ascii")
    atomic_write_bytes(pgm_path, header + np.ascontiguousarray(img).tobytes())
    text = (
        f"image: {json.dumps(pgm_path.name)}\n"
        f"resolution: {float(grid.resolution)!r}\n"
        f"origin: [{float(grid.origin[0])!r}, {float(grid.origin[1])!r}, 0.0]\n"
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
    )
    atomic_write_text(yaml_path, text)
