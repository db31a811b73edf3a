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
