"""Every message of an MCAP file checked against its channel's JSON schema with `jsonschema`, the
reference validator, reading the file with the `mcap` package: as a foreign reader would. (jsonschema
comes with the `hardware` extra.)"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["invalid_messages"]


def invalid_messages(path: str | Path) -> tuple[int, list[str]]:
    """(messages read, one line per message that its schema rejects or that is not strict JSON)."""
    from jsonschema import Draft202012Validator
    from mcap.reader import make_reader

    problems: list[str] = []
    count = 0
    validators: dict[int, Any] = {}
    with Path(path).open("rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            count += 1
            if schema.id not in validators:
                document = json.loads(schema.data)
                Draft202012Validator.check_schema(document)
                validators[schema.id] = Draft202012Validator(document)
            try:
                # strict JSON, as a browser parses it: no NaN, no Infinity
                data = json.loads(message.data, parse_constant=_refuse)
            except ValueError as exc:
                problems.append(f"{channel.topic} at {message.log_time}: {exc}")
                continue
            for error in validators[schema.id].iter_errors(data):
                problems.append(f"{channel.topic} k={data.get('k')}: {error.message}")
    return count, problems


def _refuse(constant: str) -> None:
    raise ValueError(f"{constant} is not JSON")
