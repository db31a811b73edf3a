"""Reading a YAML file with one-line errors (config files, landmark maps, map YAML)."""

from __future__ import annotations

import math
import os
import re

import yaml

from mcl.errors import MclError

# libyaml's parser (in PyYAML's wheels) with PyYAML's own safe constructor and resolver: the same documents, 35 times
# faster than the pure-Python parser (the default config: 1.8 ms against 66 ms); the pure-Python one where PyYAML was
# built without libyaml
SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _DuplicateKey(yaml.YAMLError):
    def __init__(self, key, mark):
        super().__init__(f"duplicate key {key}")
        self.key, self.mark = key, mark


class _Loader(SAFE_LOADER):
    """SAFE_LOADER that rejects a key given twice in one mapping (PyYAML keeps the last, silently). The check is
    in flatten_mapping, Python-level even under libyaml, at its first call on a node: flattening rewrites the
    node's keys in place, and a merge key's (``<<``) keys may then repeat the node's own, which override them."""

    def __init__(self, stream):
        super().__init__(stream)
        self._checked: set = set()

    def flatten_mapping(self, node):
        if node in self._checked:
            return super().flatten_mapping(node)
        self._checked.add(node)
        own = [k for k, _ in node.value if k.tag != "tag:yaml.org,2002:merge"]
        super().flatten_mapping(node)  # first: a `=` key becomes a string here
        seen = set()
        for k in own:
            if isinstance(k, yaml.ScalarNode):
                key = self.construct_object(k)  # cached: construct_mapping reads it back
                if key in seen:
                    self.duplicate(key, k.start_mark)
                seen.add(key)

    def duplicate(self, key, mark) -> None:
        """A key given twice in one mapping: refused (a loader that keeps the last overrides this)."""
        raise _DuplicateKey(key, mark)


# An integer with leading zeros is decimal, as YAML 1.2 and the command line read it: YAML 1.1 (PyYAML) read
# `seed: 010` as octal 8 where `--seed 010` is 10, and refused `08` (neither octal nor a number). 0o, 0x, 0b keep
# their bases.
_LEADING_ZEROS = re.compile(r"^[-+]?0[0-9_]+$")


def _construct_int(loader, node):
    text = loader.construct_scalar(node)
    if ":" in text:  # YAML 1.1's base 60 (`1:30` was 90): a string, as YAML 1.2 and every user read it
        return text
    try:
        if _LEADING_ZEROS.match(text):
            value = int(text.replace("_", ""), 10)
        else:
            value = yaml.constructor.SafeConstructor.construct_yaml_int(loader, node)
    except ValueError:  # beyond Python's 4,300 decimal digits: a traceback before
        value = None
    if value is None or value.bit_length() > 14_000:  # (0x, 0b: read, but a traceback when printed in decimal)
        raise yaml.constructor.ConstructorError(None, None, f"an integer of {len(text)} digits",
                                                node.start_mark) from None
    return value


def _construct_float(loader, node):
    text = loader.construct_scalar(node)
    if ":" in text:  # base 60 (`1:30.5`): a string, as for integers
        return text
    return yaml.constructor.SafeConstructor.construct_yaml_float(loader, node)


_Loader.add_constructor("tag:yaml.org,2002:int", _construct_int)
_Loader.add_constructor("tag:yaml.org,2002:float", _construct_float)
_Loader.add_implicit_resolver("tag:yaml.org,2002:int", _LEADING_ZEROS, list("-+0"))


def load_text(text: str):
    """A YAML document from text, read as ``read_yaml`` reads a file (a ``--set`` value)."""
    return yaml.load(text, Loader=_Loader)


def read_yaml(path: str | os.PathLike, error: type[MclError]):
    """The parsed document of a YAML file. Any problem raises ``error`` with one line naming
    the file (and the line of a syntax error or a duplicate key): unreadable, not UTF-8, invalid YAML, a key given
    twice in one mapping."""
    name = str(path)
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except UnicodeDecodeError:  # before ValueError, its base class
        raise error(f"{name}: not a UTF-8 text file") from None
    except (OSError, ValueError) as e:  # ValueError: a NUL byte in the path
        raise error(f"{name}: cannot read: {getattr(e, 'strerror', None) or type(e).__name__}") from None
    return parse(_Loader(text), name, error)


def parse(loader: _Loader, name: str, error: type[MclError]):
    """The single document ``loader`` (a ``_Loader``, or a subclass, on the text) holds, as ``read_yaml`` reads a
    file: any problem is ``error`` with one line naming ``name`` and the line."""
    try:
        return loader.get_single_data()
    except _DuplicateKey as e:
        raise error(f"{name}:{e.mark.line + 1}: duplicate key {_printable(e.key)}") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f":{mark.line + 1}" if mark is not None else ""
        problem = (getattr(e, "problem", None) or "").replace("\n", " ")
        raise error(f"{name}{where}: invalid YAML" + (f": {problem}" if problem else "")) from None
    except (RecursionError, MemoryError) as e:  # hostile input: deeply nested or huge documents
        raise error(f"{name}: invalid YAML ({type(e).__name__})") from None
    finally:
        loader.dispose()


def _printable(k) -> str:
    """A key as it goes into a one-line message: control characters escaped, cut to 40 characters."""
    s = str(k)
    s = s if s.isprintable() else repr(s)[1:-1]
    return s if len(s) <= 40 else s[:37] + "..."


def short_repr(v, limit: int = 40) -> str:
    """``repr(v)`` on one line, cut to ``limit`` characters, for an error message."""
    s = repr(v).replace("\n", " ")
    return s if len(s) <= limit else s[: limit - 3] + "..."


# Exponent notation without a dot ("1e-5", "2E3"): a float in YAML 1.2 and to every user, a string to PyYAML's
# YAML 1.1 resolver (which wants "1.0e-5").
_EXPONENT_FLOAT = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)[eE][-+]?[0-9]+")


def finite_number(value, label: str, error: type[MclError]) -> float:
    """``value`` (a parsed YAML scalar) as a finite float, else ``error`` with one line starting ``label: ``.
    Booleans and other strings are not numbers, but exponent notation that YAML 1.1 leaves a string ("1e-5")
    is; an integer too large for a float is reported by its length."""
    if isinstance(value, str) and _EXPONENT_FLOAT.fullmatch(value.strip()):
        value = float(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise error(f"{label}: expected a number, got {short_repr(value)}")
    try:
        v = float(value)
    except OverflowError:  # a YAML integer beyond the float range
        raise error(f"{label}: expected a finite number, got an integer of {len(str(value))} digits") from None
    if not math.isfinite(v):
        raise error(f"{label}: expected a finite number, got {v!r}")
    return v


def key_line(path: str | os.PathLike, dotted: str) -> int | None:
    """The 1-based line of the key ``dotted`` (``filter.particles``; nested mappings) in the YAML file ``path``, or
    of its deepest section the file gives; None when the file gives none of it or cannot be read. For an error
    about a key (unknown, of the wrong type) to name its line, as a syntax error's does."""
    try:
        with open(path, encoding="utf-8") as f:
            node = yaml.compose(f.read(), Loader=SAFE_LOADER)
    except (OSError, ValueError, yaml.YAMLError):
        return None
    line = None
    for part in dotted.split("."):
        if not isinstance(node, yaml.MappingNode):
            break
        hit = next(((k, v) for k, v in node.value if isinstance(k, yaml.ScalarNode) and k.value == part), None)
        if hit is None:
            break
        line, node = hit[0].start_mark.line + 1, hit[1]
    return line
