"""Consumers of the runner's feed (hoh_cosim.hardware.feed) for the tests: importable by name, so
that the feed's spawned process can run them."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any


def slow_counter(reader: Any, delay_s: float, out: str) -> None:
    """Take rows with a pause of `delay_s` after each take (a consumer far slower than the loop),
    and write what it got to `out` as JSON: each row's cycle number, the rows dropped."""
    reader.ready("slow")
    got: list[int] = []
    while not reader.ending:
        rows = reader.take(0.05)
        got.extend(int(k) for k in rows[:, 0])
        time.sleep(delay_s)
    Path(out).write_text(
        json.dumps({"k": got, "dropped": reader.dropped, "received": reader.received}),
        encoding="utf-8",
    )
    reader.finished(out)
