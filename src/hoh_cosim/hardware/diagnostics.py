"""`hoh-cosim hw sensors`: read the streams for a while and say what they look like.

The first thing to run on a new rig: per stream the measured rate, mean and standard deviation per
axis, the frame and bad-frame counts, and for the FSE103 the framing and byte order it was found to
use. `--json` prints one object:

    {"ft": {"rate_hz": ..., "mean": [6], "std": [6], "frames": n, "bad_frames": n},
     "probe": {"rate_hz": ..., "mean": [3], "std": [3], "frames": n, "bad_frames": n,
               "framing": "...", "byte_order": "..."}}

with a stream's `error` (the last reason it went down) where there was one.
"""

from __future__ import annotations

import math
import time
from typing import Any

from hoh_cosim.hardware.streams import Mailbox

__all__ = ["describe_streams", "read_streams", "silent_streams"]


def _figures(mailbox: Mailbox) -> dict[str, Any]:
    stats = mailbox.stats
    rate = stats.rate_hz
    out: dict[str, Any] = {
        "rate_hz": None if math.isnan(rate) else rate,
        "mean": [None if math.isnan(x) else float(x) for x in stats.mean],
        "std": [None if math.isnan(x) else float(x) for x in stats.std],
        "frames": stats.frames,
        "bad_frames": stats.bad_frames,
    }
    if stats.nonfinite:
        out["nonfinite_frames"] = stats.nonfinite
    if mailbox.last_error is not None:
        out["error"] = mailbox.last_error
    return out


def read_streams(
    ft: Any | None, probe: Any | None, seconds: float, poll_s: float = 0.05
) -> dict[str, Any]:
    """Run the given streams for `seconds` and return their figures (keys "ft", "probe").

    Ends early when no stream has given a sample and every one has failed (a refused connection,
    a missing device): waiting longer would only repeat the failure."""
    sources = {name: s for name, s in (("ft", ft), ("probe", probe)) if s is not None}
    for source in sources.values():
        source.start()
    try:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            time.sleep(min(poll_s, max(0.0, deadline - time.monotonic())))
            if all(
                s.mailbox.stats.frames == 0 and s.mailbox.last_error is not None
                for s in sources.values()
            ):
                break
    finally:
        for source in sources.values():
            source.stop()
    out = {name: _figures(source.mailbox) for name, source in sources.items()}
    if probe is not None:
        out["probe"]["framing"] = probe.parser.framing
        out["probe"]["byte_order"] = probe.parser.byte_order
    return out


def silent_streams(figures: dict[str, Any], names: dict[str, str]) -> list[str]:
    """One line per stream that gave no sample: its name and why, for a pre-session check."""
    lines = []
    for key in ("ft", "probe"):
        f = figures.get(key)
        if f is not None and f["frames"] == 0:
            why = f.get("error") or "nothing arrived"
            lines.append(f"{names[key]}: no data ({why})")
    return lines


def describe_streams(figures: dict[str, Any], names: dict[str, str]) -> str:
    """The figures as lines for a person."""

    def row(values: list[float | None], digits: int) -> str:
        return " ".join("     n/a" if v is None else f"{v:8.{digits}f}" for v in values)

    lines = []
    for key, label, axes in (
        ("ft", "FT-150", "Fx Fy Fz Mx My Mz"),
        ("probe", "FSE103", "Fx Fy Fz"),
    ):
        if key not in figures:
            continue
        f = figures[key]
        rate = (
            "no rate (fewer than two samples)" if f["rate_hz"] is None else f"{f['rate_hz']:.1f} Hz"
        )
        lines.append(f"{label} ({names[key]}): {rate}, {f['frames']} frames, {f['bad_frames']} bad")
        if key == "probe":
            lines.append(
                f"  framing {f['framing'] or 'not detected'}, byte order "
                f"{f['byte_order'] or 'not detected'}"
            )
        if f["frames"]:
            lines.append(f"  axes  {axes}")
            lines.append(f"  mean  {row(f['mean'], 4)}")
            lines.append(f"  std   {row(f['std'], 4)}")
        if "error" in f:
            lines.append(f"  last error: {f['error']}")
    return "\n".join(lines)
