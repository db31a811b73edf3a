"""Draw one world of every ``mcl simulate --kind`` into a PNG each (pillow; no matplotlib).

    python scripts/worlds_gallery.py [OUTDIR] [--seed S] [--duration D]

Simulates each kind into OUTDIR/<kind>/ (map, log, truth) and writes
OUTDIR/<kind>.png: free space white, walls black, unknown grey, the true path
red, the start a green square, and the unmapped obstacles the laser saw
(scan endpoints far from every mapped wall) in blue. Maps larger than 1600
pixels are drawn shrunk.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw


def draw(outdir: Path, png: Path, max_side: int = 1600) -> None:
    from mcl.datasets.carmen import read_carmen
    from mcl.maps import load_map
    from mcl.trajectory import read_tum

    g = load_map(outdir / "map.yaml")
    rgb = np.full(g.occupancy.shape + (3,), 160, dtype=np.uint8)
    rgb[g.free] = 255
    rgb[g.occupied] = 0
    _, p = read_tum(outdir / "truth.tum")
    log = read_carmen(outdir / "log.clf")
    # endpoints of the beams that hit something the map does not have (blue)
    dist = g.distance
    for s, (x, y, th) in zip(log.scans, p.T):
        a = s.angle_min + np.arange(s.ranges.size) * s.angle_increment
        hit = s.ranges < (s.max_range or 12.0) - 1e-6
        ex, ey = x + s.ranges[hit] * np.cos(th + a[hit]), y + s.ranges[hit] * np.sin(th + a[hit])
        ix, iy = g.world_to_cell(ex, ey)
        ok = g.contains(ix, iy)
        ix, iy = ix[ok], iy[ok]
        far = dist[iy, ix] > 0.15
        rgb[iy[far], ix[far]] = (40, 90, 255)
    img = Image.fromarray(rgb[::-1])
    scale = min(1.0, max_side / max(img.size))
    img = img.resize((max(1, int(img.width * scale)), max(1, int(img.height * scale))), Image.NEAREST)
    d = ImageDraw.Draw(img)
    ix, iy = g.world_to_cell(p[0], p[1])
    pts = [(float(i) * scale, float(g.height - 1 - j) * scale) for i, j in zip(ix, iy)]
    d.line(pts, fill=(220, 0, 0), width=max(1, int(3 * scale)))
    x0, y0 = pts[0]
    d.rectangle([x0 - 5, y0 - 5, x0 + 5, y0 + 5], outline=(0, 170, 0), width=2)
    img.save(png)


def main() -> int:
    from mcl.simulate import KINDS, simulate

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outdir", nargs="?", default="runs/worlds_gallery")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=90.0)
    ap.add_argument("--kinds", default=",".join(KINDS))
    a = ap.parse_args()
    out = Path(a.outdir)
    for kind in a.kinds.split(","):
        t = time.perf_counter()
        s = simulate(out / kind, kind=kind, seed=a.seed, duration=a.duration)
        took = time.perf_counter() - t
        draw(out / kind, out / f"{kind}.png")
        print(f"{kind:9s} {s['scans']} scans, path {s['path_length']:.0f} m, generated in {took:.1f} s -> "
              f"{out / (kind + '.png')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
