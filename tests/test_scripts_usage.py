"""The scripts' usage lines, and the README's and the suites' mentions of them, name only options the scripts take."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted((ROOT / "scripts").glob("*.py"))


def _options(script: Path) -> set[str]:
    """Every ``--option`` the script's argparse parser takes (read from its source, without running it)."""
    opts = {"--help"}
    for node in ast.walk(ast.parse(script.read_text())):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "add_argument":
            opts |= {a.value for a in node.args if isinstance(a, ast.Constant) and str(a.value).startswith("--")}
    return opts


def _mentions(text: str, script: Path) -> list[str]:
    """The ``--option`` words written after the script's name on the same line (up to a backtick or a ';')."""
    found = []
    for m in re.finditer(rf"\b{re.escape(script.name)}([^`;\n]*)", text):
        found += re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", m.group(1))
    return found


@pytest.mark.parametrize("script", SCRIPTS, ids=[s.name for s in SCRIPTS])
def test_a_scripts_usage_names_only_options_it_takes(script):
    # scripts/kidnap.py's usage offered --particles N, which the script refused ("unrecognized arguments")
    doc = ast.get_docstring(ast.parse(script.read_text())) or ""
    texts = {"docstring": doc, "README.md": (ROOT / "README.md").read_text()}
    texts |= {f"suites/{p.name}": p.read_text() for p in (ROOT / "suites").glob("*.yaml")}
    takes = _options(script)
    for where, text in texts.items():
        unknown = sorted(set(_mentions(text, script)) - takes)
        assert not unknown, f"{where}: {script.name} {unknown} (it takes {sorted(takes)})"
