"""Every message of an MCAP file checked against its channel's JSON schema with `jsonschema`, the
reference validator, reading the file with the `mcap` package: as a foreign reader would. (jsonschema
comes with the `hardware` extra.)

A session's schemas say only which keys, which JSON types and how many items (`STRUCTURAL`), so
whether a message is valid depends on its shape alone: its keys, its lists' lengths, and for each
value its JSON type, a number's being integral included (`integer` in JSON Schema: 1.0 is one). The
validator judges each shape once, on a stand-in message of that shape (`_shape`), and every message
of a known shape gets that verdict: a session has a handful of shapes in tens of thousands of
messages, and jsonschema takes about 0.2 ms a message. A schema with any other keyword (a range, a
pattern, an enum) has every message judged on its own values.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["STRUCTURAL", "invalid_messages"]

STRUCTURAL = frozenset(
    {
        "$schema", "title", "description", "type", "properties", "required",
        "additionalProperties", "items", "minItems", "maxItems",
    }
)  # fmt: skip
"""The schema keywords whose verdict depends on a message's shape alone (see the docstring)."""


def invalid_messages(path: str | Path) -> tuple[int, list[str]]:
    """(messages read, one line per message that its schema rejects or that is not strict JSON)."""
    from jsonschema import Draft202012Validator
    from mcap.reader import make_reader

    problems: list[str] = []
    count = 0
    validators: dict[int, Any] = {}
    by_shape: dict[int, dict[str, bool] | None] = {}  # per schema: shape -> valid, or None
    with Path(path).open("rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            count += 1
            if schema.id not in validators:
                document = json.loads(schema.data)
                Draft202012Validator.check_schema(document)
                validators[schema.id] = Draft202012Validator(document)
                by_shape[schema.id] = {} if _structural(document) else None
            try:
                # strict JSON, as a browser parses it: no NaN, no Infinity
                data = json.loads(message.data, parse_constant=_refuse)
            except ValueError as exc:
                problems.append(f"{channel.topic} at {message.log_time}: {exc}")
                continue
            validator, verdicts = validators[schema.id], by_shape[schema.id]
            if verdicts is not None:
                stand_in = _shape(data)
                key = json.dumps(stand_in)
                valid = verdicts.get(key)
                if valid is None:
                    valid = verdicts[key] = validator.is_valid(stand_in)
                if valid:
                    continue
            for error in validator.iter_errors(data):
                problems.append(f"{channel.topic} k={_k(data)}: {error.message}")
    return count, problems


def _structural(schema: Any) -> bool:
    """Whether a schema (and every schema within it) uses only `STRUCTURAL` keywords."""
    if isinstance(schema, bool):
        return True
    if not isinstance(schema, dict) or not set(schema) <= STRUCTURAL:
        return False
    nested = [*schema.get("properties", {}).values()]
    for keyword in ("items", "additionalProperties"):
        if keyword in schema:
            nested.append(schema[keyword])
    return all(_structural(s) for s in nested)


def _shape(value: Any) -> Any:
    """A stand-in of the same shape for a value as `json.loads` makes them: the same keys and
    lengths, each value replaced by one of its JSON type (an integral number by 0, any other by
    0.5, a string by "")."""
    kind = type(value)
    if kind is float:
        return 0 if value.is_integer() else 0.5
    if kind is list:
        return [_shape(v) for v in value]
    if kind is dict:
        return {k: _shape(v) for k, v in value.items()}
    if kind is int:
        return 0
    if kind is str:
        return ""
    return value  # true, false, null


def _k(data: Any) -> Any:
    return data.get("k") if isinstance(data, dict) else None


def _refuse(constant: str) -> None:
    raise ValueError(f"{constant} is not JSON")
