"""Reading a YAML file with one-line errors (config files, landmark maps)."""

from __future__ import annotations

import os

import yaml

from mcl.errors import MclError


def read_yaml(path: str | os.PathLike, error: type[MclError]):
    """The parsed document of a YAML file. Any problem raises ``error`` with one line naming
    the file (and the line of a syntax error): unreadable, not UTF-8, invalid YAML."""
    name = str(path)
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except (OSError, ValueError) as e:  # ValueError: a NUL byte in the path
        raise error(f"{name}: cannot read: {getattr(e, 'strerror', None) or type(e).__name__}") from None
    except UnicodeDecodeError:
        raise error(f"{name}: not a UTF-8 text file") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f":{mark.line + 1}" if mark is not None else ""
        raise error(f"{name}{where}: {getattr(e, 'problem', None) or 'invalid YAML'}") from None
