"""A log of ``../shared/data`` run through ``scripts/degrade_laser.py`` (as ``scripts/hunt.py real`` makes its logs),
for tests that replay a hunt's degraded log."""

from __future__ import annotations

import sys
from pathlib import Path

import yaml

from mcl.config import PROJECT_ROOT

SHARED = PROJECT_ROOT.parent / "shared" / "data"


def degraded(tmp_path: Path, name: str, *options: str) -> Path:
    """The folder (map.yaml, log.clf, truth.tum) of ``../shared/data/NAME`` degraded with ``degrade_laser.py``'s
    ``options``, made under ``tmp_path``."""
    sys.path.insert(0, str(PROJECT_ROOT / "scripts"))
    try:
        from degrade_laser import main
    finally:
        sys.path.remove(str(PROJECT_ROOT / "scripts"))
    (tmp_path / "suite.yaml").write_text(yaml.safe_dump({
        "name": name, "root": str(SHARED / name), "modes": ["tracking"],
        "datasets": [{"name": name, "map": "map.yaml", "log": "log.clf", "truth": "truth.tum"}]}))
    out = tmp_path / "out"
    assert main([str(out), "--suite", str(tmp_path / "suite.yaml"), *options]) == 0
    (world,) = [p.parent for p in out.glob("*/log.clf")]
    return world


def replay(world: Path, out: Path, start, *overrides: str, seed: int = 1, turned: bool = False,
           log: Path | None = None) -> dict:
    """The summary of ``mcl.runner.run`` with the default config on a ``degraded`` world (its turned map and
    reference with ``turned``; ``log`` in place of its own), tracking from ``start`` (x, y, theta), with ``overrides``
    (``--set`` items) after the rest; outputs in ``out``."""
    from mcl.config import load_config
    from mcl.runner import run

    tag = "_turned" if turned else ""
    cfg = load_config(PROJECT_ROOT / "configs" / "default.yaml", [
        f"map={world / f'map{tag}.yaml'}", f"log={log or world / 'log.clf'}", f"truth={world / f'truth{tag}.tum'}",
        f"seed={seed}", "rerun.mode=off", f"filter.initial_pose=[{', '.join(str(v) for v in start)}]", *overrides])
    return run(cfg, out, progress=False, echo=lambda msg: None)
