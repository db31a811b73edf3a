"""Compare what two Rerun recordings (.rrd) show: every entity and component, static and at every step.

Usage: python scripts/compare_recordings.py A.rrd B.rrd [--ignore /stats/time_ms] [--max-report N]

Two recordings of the same run written by different code (the chunking, row ids, recording ids and the
`log_time` wall clock differ) should show the same thing: for each (entity, component), the static value, and
the rows on the `step` timeline, each with its `time` and value, sorted by step (rows at one step kept in their
order). `--ignore PREFIX` leaves out the entities under a path (repeatable): the measured timings
(`/stats/time_ms`, `/warmup`) differ between any two runs. Exits 0 when they are the same, 1 with the differences listed otherwise. The blueprint is not compared.
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict

import pyarrow as pa
from rerun.chunk import RrdReader

IGNORED = {"rerun.controls.RowId", "log_time", "log_tick"}
IGNORED_ENTITIES = {"/__properties"}  # the recording's start time


def read(path: str) -> tuple[dict, dict]:
    """({(entity, component): [value, ...]} static, {(entity, component): [(step, time, value), ...]} temporal)."""
    static: dict = defaultdict(list)
    temporal: dict = defaultdict(list)
    for c in RrdReader(path).stream().to_chunks():
        if c.entity_path in IGNORED_ENTITIES:
            continue
        batch = c.to_record_batch()
        names = [n for n in batch.schema.names if n not in IGNORED]
        comps = [n for n in names if ":" in n]
        if c.is_static:
            for n in comps:
                static[(c.entity_path, n)] += batch.column(n).to_pylist()
            continue
        if "step" not in names:
            raise SystemExit(f"{path}: {c.entity_path} has rows off the step timeline ({names})")
        steps = batch.column("step").cast(pa.int64()).to_pylist()
        times = batch.column("time").cast(pa.int64()).to_pylist() if "time" in names else [None] * c.num_rows
        rowids = batch.column("rerun.controls.RowId").to_pylist()
        for n in comps:
            for s, t, r, v in zip(steps, times, rowids, batch.column(n).to_pylist()):
                if v is not None:  # a component the row does not log (a chunk's other archetypes)
                    temporal[(c.entity_path, n)].append((s, t, str(r), v))
    for key, rows in temporal.items():
        rows.sort(key=lambda r: (r[0], r[2]))  # by step, then in logging order (row ids grow)
        temporal[key] = [(s, t, v) for s, t, _, v in rows]
    return dict(static), dict(temporal)


def _same(a, b) -> bool:
    return repr(a) == repr(b)  # nan == nan, and -0.0 != 0.0


def compare(a: str, b: str, max_report: int = 20, ignore: tuple[str, ...] = ()) -> list[str]:
    def keep(d: dict) -> dict:
        return {k: v for k, v in d.items() if not any(k[0] == p or k[0].startswith(p.rstrip("/") + "/")
                                                       for p in ignore)}

    sa, ta = (keep(d) for d in read(a))
    sb, tb = (keep(d) for d in read(b))
    out: list[str] = []
    for kind, xa, xb in (("static", sa, sb), ("temporal", ta, tb)):
        for key in sorted(set(xa) | set(xb)):
            if key not in xa or key not in xb:
                out.append(f"{kind} {key[0]} {key[1]}: only in {'B' if key not in xa else 'A'}")
                continue
            ra, rb = xa[key], xb[key]
            if len(ra) != len(rb):
                out.append(f"{kind} {key[0]} {key[1]}: {len(ra)} rows in A, {len(rb)} in B")
            bad = [i for i, (p, q) in enumerate(zip(ra, rb)) if not _same(p, q)]
            if bad:
                i = bad[0]
                out.append(f"{kind} {key[0]} {key[1]}: {len(bad)} of {len(ra)} rows differ; first at row {i}: "
                           f"{repr(ra[i])[:200]} vs {repr(rb[i])[:200]}")
    n_rows = sum(len(v) for v in ta.values())
    print(f"{a}: {len(sa)} static and {len(ta)} temporal (entity, component) pairs, {n_rows} temporal rows",
          file=sys.stderr)
    return out[:max_report] + ([f"... {len(out) - max_report} more"] if len(out) > max_report else [])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--ignore", action="append", default=[], metavar="PREFIX",
                    help="leave out the entities under this path (repeatable)")
    ap.add_argument("--max-report", type=int, default=20, help="differences listed at most (default 20)")
    args = ap.parse_args(argv)
    diffs = compare(args.a, args.b, args.max_report, tuple(args.ignore))
    for d in diffs:
        print(d)
    print("same" if not diffs else f"DIFFERENT ({len(diffs)} lines above)")
    return 0 if not diffs else 1


if __name__ == "__main__":
    sys.exit(main())
