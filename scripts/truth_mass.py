#!/usr/bin/env python
"""Where does a lost run's true place lose its particles? Replays one run of ``mcl eval`` and logs, at every filter
update, the weight of the particles near the reference pose.

A global or kidnapped run that ends at a look-alike place either never had particles at the true place or lost
them. Which, and when, decides what could mend it: if the scans of the first seconds favour the wrong place, no
rule that ranks places by those scans keeps the true one; if the true place had weight when a resample drew the
set down, a search that keeps runner-up hypotheses could (docs/measurements.md, "Twenty-third session").

The run is replayed from its folder (``config.yaml``; a real log's kidnapped run is kidnapped again at the scan its
``summary.json`` names, with the same seed: the same run) through :func:`mcl.runner.run`'s ``on_update`` hook, into a scratch folder,
with the recording off. Per update it writes a CSV row: time, particles, the weight and the count of particles
within ``--radius`` m and ``--angle`` rad of the reference, the estimate's error, the quality score, the lost
belief and whether a global search was tempering the scans. With KLD sampling (the default) the weights are those
of the corrected set before its resample is drawn (with the next motion); without, those after the resample (each
particle 1/N). Printed: the first update at which the mass near the reference fell below ``--floor``, the first
with no particle there, and the last at which it held half the weight.

Usage::

    .venv/bin/python scripts/truth_mass.py RUN_DIR [--radius 1.0] [--angle 0.5] [--floor 1e-6] [--out mass.csv]

``RUN_DIR`` is one run of an evaluation, e.g. ``runs/eval/runs/rooms-01/global/default/seed1`` (a synthetic world
must still be in the cache the evaluation used).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mcl.config import load_config  # noqa: E402
from mcl.estimate import wrap_angle  # noqa: E402
from mcl.runner import run  # noqa: E402

COLUMNS = ("t", "particles", "mass_near", "count_near", "error_m", "quality", "lost", "tempering")


def replay(run_dir: Path, radius: float = 1.0, angle: float = 0.5) -> list[dict]:
    """One row per filter update of the run in ``run_dir`` (``COLUMNS``); updates without a reference pose are
    left out."""
    from mcl.suite import KIDNAP_M

    cfg = load_config(run_dir / "config.yaml", ["rerun.mode=off"])
    if cfg.truth is None:
        raise SystemExit(f"{run_dir / 'config.yaml'}: no truth: nothing to measure against")
    # a real log's kidnapped run: the run kidnapped the filter and its summary says when (a synthetic world's log
    # holds its own kidnap); the same scan, seed and distance give the same place
    summary_file = run_dir / "summary.json"
    done = json.loads(summary_file.read_text()).get("kidnap") if summary_file.exists() else None
    kidnap = (float(done["t"]), KIDNAP_M) if done else None
    rows: list[dict] = []

    def on_update(t, pf, info, ref):
        if ref is None:
            return
        p, w = pf.particles, pf.weights
        near = (np.hypot(p[0] - ref[0], p[1] - ref[1]) <= radius) & (np.abs(wrap_angle(p[2] - ref[2])) <= angle)
        rows.append({"t": float(t), "particles": int(pf.n), "mass_near": float(w[near].sum()),
                     "count_near": int(near.sum()),
                     "error_m": float(math.hypot(info.mean[0] - ref[0], info.mean[1] - ref[1])),
                     "quality": info.quality, "lost": bool(info.lost), "tempering": bool(pf.search.tempering)})

    with tempfile.TemporaryDirectory(prefix="mcl-truth-mass-") as scratch:
        run(cfg, Path(scratch), progress=False, echo=lambda msg: None, kidnap_filter_at=kidnap, on_update=on_update)
    return rows


def milestones(rows: list[dict], floor: float) -> dict:
    """The times (None: never) at which the mass near the reference first fell below ``floor``, first had no
    particle, and last held half the weight."""
    below = next((r["t"] for r in rows if r["mass_near"] < floor), None)
    none = next((r["t"] for r in rows if r["count_near"] == 0), None)
    half = [r["t"] for r in rows if r["mass_near"] >= 0.5]
    return {"below_floor": below, "no_particle": none, "last_half": half[-1] if half else None}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path, help="one run's folder of an mcl eval output")
    ap.add_argument("--radius", type=float, default=1.0, help="m around the reference (default 1.0)")
    ap.add_argument("--angle", type=float, default=0.5, help="rad around the reference's heading (default 0.5)")
    ap.add_argument("--floor", type=float, default=1e-6, help="mass below which the place counts as dropped")
    ap.add_argument("--out", type=Path, default=None, help="CSV to write (default: none)")
    a = ap.parse_args(argv)
    rows = replay(a.run_dir, a.radius, a.angle)
    if a.out is not None:
        a.out.write_text(",".join(COLUMNS) + "\n" + "".join(
            ",".join(f"{r[c]:.6g}" if isinstance(r[c], float) else str(int(r[c])) for c in COLUMNS) + "\n"
            for r in rows))
    m = milestones(rows, a.floor)

    def fmt(v):
        return "never" if v is None else f"{v:.1f} s"

    print(f"{a.run_dir}: {len(rows)} updates; mass near the reference below {a.floor:g} from {fmt(m['below_floor'])}, "
          f"no particle there from {fmt(m['no_particle'])}, half the weight last at {fmt(m['last_half'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
