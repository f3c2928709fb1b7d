"""Reading the project's YAML files (scenarios, hardware configurations) with one-line errors.

Every mistake is a `ConfigError` whose message starts with the file and the YAML path of the value:
`scenarios/x.yaml: components.plant.every: expected an integer >= 1, got 0`.

A document is checked before any loader sees it: at most `MAX_DEPTH` levels deep, aliases that
multiply it at most `MAX_EXPANSION` times, integers that 64 bits hold. Loaders walk, merge and print
the values they are given; these bounds keep their time and memory in proportion to the file.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hoh_cosim.errors import ConfigError

__all__ = ["MAX_DEPTH", "MAX_EXPANSION", "Where", "parse_value", "read_yaml"]

MAX_DEPTH = 32
"""How deep a document may nest. The project's files nest six levels deep; an alias that names
itself nests without end."""

MAX_EXPANSION = 10
"""How much a document's aliases may multiply it. An alias costs PyYAML nothing (the value is
shared), but a loader that walks or prints the value pays for every repetition: nine levels of ten
aliases each make 10**9 values of a few hundred bytes of YAML (the "billion laughs"). Expanded, a
document may hold at most this many times its text's length in values and characters (plus
`_EXPANSION_SLACK`)."""

_EXPANSION_SLACK = 10_000
_INT64 = range(-(2**63), 2**63)


_PARSED: dict[str, Any] = {}
"""The last documents read, by their text: a study loads the same scenario file for each of its
hundreds of runs, and PyYAML's pure-Python parser takes 80 % of a load (5-20 ms of circles.yaml's).
The same text gives the same document, so a file is parsed again only when its text changed."""
_PARSED_KEPT = 16


def read_yaml(path: Path) -> Any:
    """The file's YAML document; a missing, unreadable, malformed or out-of-bounds file (see the
    module's docstring) is a one-line error. Each call gives a document of its own (a copy of the
    one parsed before when the text is the same), so a caller may change it."""
    w = Where(path)
    try:
        text = path.read_text(encoding="utf-8")
        if text in _PARSED:
            return copy.deepcopy(_PARSED[text])
        document = yaml.safe_load(text)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except yaml.reader.ReaderError as exc:  # a character YAML does not allow anywhere
        line = text.count("\n", 0, exc.position) + 1
        column = exc.position - text.rfind("\n", 0, exc.position)
        problem = f"the character #x{exc.character:04x} is not allowed"
        raise w.error(f"line {line}, column {column}", f"not valid YAML: {problem}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise w.error(where, f"not valid YAML: {problem}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    except RecursionError:  # PyYAML composes nested collections by recursion
        raise w.error("", f"nested more than {MAX_DEPTH} levels deep") from None
    except ValueError as exc:  # a value PyYAML matched but cannot build: 2024-13-01, 5000 digits
        raise w.error("", f"not valid YAML: {exc}") from None
    _check_bounds(document, len(text), w)
    if len(_PARSED) >= _PARSED_KEPT:
        del _PARSED[next(iter(_PARSED))]  # the oldest
    _PARSED[text] = copy.deepcopy(document)
    return document


def parse_value(option: str, text: str) -> Any:
    """The value of a `--set name=VALUE` option, read as YAML (`0.5`, `true`, `[1, 2, 3]`)."""
    name = option.partition("=")[0]
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or "not valid YAML"
        raise ConfigError(f"--set {name}: cannot read the value {text!r}: {problem}") from None
    except RecursionError:
        raise ConfigError(f"--set {name}: nested more than {MAX_DEPTH} levels deep") from None
    except ValueError as exc:
        raise ConfigError(f"--set {name}: cannot read the value {text!r}: {exc}") from None
    _check_bounds(value, len(text), Where(f"--set {name}"))
    return value


def _check_bounds(document: Any, text_size: int, w: Where) -> None:
    """Refuse a document nested deeper than `MAX_DEPTH`, one its aliases expand beyond
    `MAX_EXPANSION` times its text, and an integer that no 64-bit number holds (every number a
    loader keeps is an int64 or a float64). Each collection is measured once, however many
    aliases name it, so this takes time in proportion to the text."""
    limit = MAX_EXPANSION * text_size + _EXPANSION_SLACK
    sizes: dict[int, int] = {}  # id of a collection -> its size, expanded

    def size(value: Any, where: str, depth: int) -> int:
        if isinstance(value, str):
            return 1 + len(value)
        if isinstance(value, int) and not isinstance(value, bool) and value not in _INT64:
            raise w.error(where, f"an integer of {len(str(abs(value)))} digits, beyond 64 bits")
        if not isinstance(value, list | tuple | set | dict):
            return 1
        if id(value) in sizes:
            return sizes[id(value)]
        if depth >= MAX_DEPTH:
            raise w.error(where, f"nested more than {MAX_DEPTH} levels deep")
        if isinstance(value, dict):  # a key and its value
            items = [(f"{where}.{k}" if where else str(k), (k, v)) for k, v in value.items()]
        else:
            items = [(f"{where}[{i}]", (v,)) for i, v in enumerate(value)]
        total = 1
        for here, parts in items:
            total += sum(size(part, here, depth + 1) for part in parts)
            if total > limit:
                raise w.error(
                    where,
                    f"aliases expand the document beyond {MAX_EXPANSION} times its size "
                    f"(more than {limit} values and characters)",
                )
        sizes[id(value)] = total
        return total

    size(document, "", 0)


class Where:
    """One file: builds its errors and checks its values, each named by its YAML path."""

    def __init__(self, path: Path | str) -> None:
        self.file = str(path)

    def error(self, where: str, problem: str) -> ConfigError:
        # a key may hold any character: escaped where it would not print (a '\r' in a key would
        # otherwise break the one-line message)
        where = "".join(c if c.isprintable() else repr(c)[1:-1] for c in where)
        return ConfigError(
            f"{self.file}: {where}: {problem}" if where else f"{self.file}: {problem}"
        )

    def number(self, value: Any, where: str, *, positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
            raise self.error(where, f"expected a number, got {value!r}")
        if positive and value <= 0:
            raise self.error(where, f"expected a number > 0, got {value!r}")
        return float(value)

    def integer(self, value: Any, where: str, *, low: int = 0, high: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise self.error(where, f"expected an integer >= {low}, got {value!r}")
        if high is not None and value > high:
            raise self.error(where, f"expected an integer <= {high}, got {value!r}")
        return value

    def string(self, value: Any, where: str, *, choices: Sequence[str] = ()) -> str:
        if not isinstance(value, str) or not value:
            raise self.error(where, f"expected a non-empty string, got {value!r}")
        if choices and value not in choices:
            raise self.error(where, f"expected one of {', '.join(choices)}, got {value!r}")
        return value

    def boolean(self, value: Any, where: str) -> bool:
        if not isinstance(value, bool):
            raise self.error(where, f"expected true or false, got {value!r}")
        return value

    def mapping(self, value: Any, keys: Sequence[str], where: str) -> Mapping[str, Any]:
        """`value` as a mapping whose keys are all among `keys`."""
        if not isinstance(value, Mapping):
            raise self.error(where, f"expected a mapping, got {value!r}")
        for key in value:
            if key not in keys:
                raise self.error(
                    f"{where}.{key}" if where else str(key),
                    f"unknown key (expected one of: {', '.join(keys)})",
                )
        return value
