"""Samples kept over a span of time, (time, value) in time order: the hold, the follow and the
release detector each keep the last fraction of a second to look back at."""

from __future__ import annotations

from collections import deque
from typing import Any

__all__ = ["keep_span", "sample_at"]


def keep_span(history: deque[tuple[float, Any]], t: float, span: float) -> None:
    """Drop the oldest samples while the next one is at least `span` older than `t`: the oldest
    kept is the newest at least `span` old, and two are always kept."""
    while len(history) > 2 and t - history[1][0] >= span:
        history.popleft()


def sample_at(history: deque[tuple[float, Any]], when: float) -> Any:
    """The value at time `when`, linear between the two samples around it; the oldest value before
    them all. Values may be floats or arrays."""
    t1, z1 = history[-1]
    for t0, z0 in reversed(history):
        if t0 <= when:
            return z0 if t1 <= t0 else z0 + (z1 - z0) * (when - t0) / (t1 - t0)
        t1, z1 = t0, z0
    return history[0][1]
