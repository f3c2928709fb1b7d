"""The session log: every cycle's raw readings, estimates, commands and statuses, as MCAP.

Channels carry JSON messages with a JSON schema each (`channel_schema`: every field named, the
ones always present required, nothing else allowed; a non-finite value as text under `NONFINITE`),
so the file opens in Foxglove and in the `mcap` Python package alike:

    /robot      p_BT_B, rotvec_BT (the orientation as UR's rotation vector), twist_B, robot and
                safety mode, stops, program running
    /ft150      a new raw wrench in S, how many samples so far, its receipt time
    /fse103     a new raw probe force in P, how many samples so far, receipt and device times
    /estimate   the estimator's outputs
    /command    the controller's outputs (its mode among them) and the twist sent, with the
                status flags' names and the mode's
    /timing     the cycle's compute time and how late it started
    /events     what happened: the rebias, the parameters, a stop and its cause, the end

Every message carries the cycle number `k`; its record's log time is the cycle's start, `t` [s] of
session time after `t0_unix_ns` (in each channel's metadata), and `read_session` gives each message
that `t` back (older logs wrote it into every message). The command's `twist_law_B` and `sent_B`
are written only where they differ from `twist_B` (a clamp, a stop), and read back equal to it
where absent; in a session they are the same numbers nearly every cycle. The session's description
is a metadata record; the effective parameters, known after the rebias, are the `parameters`
event, so a log can be replayed with exactly the settings that produced it.

The control loop never writes the file, nor even encodes a message. It copies each cycle, as one row
of floats in a fixed layout (`CYCLE_LAYOUT`), into a ring buffer in shared memory, a few
microseconds; a writer process of its own turns rows into messages, writes them and flushes a chunk
every `flush_s` seconds (of wall time, and of the session's time, so that a writer that falls
behind on a busy machine still cuts its backlog into chunks of that length), so a killed runner
loses at most that much. (A writer thread was tried
first: its work, done under the interpreter's lock, delayed the 500 Hz loop by up to 8 ms every
second.) If the writer falls a whole ring behind, the rows it missed are reported as an event.
`read_session` reads a complete file or one that was cut off.

Size (a shift of 8 hours must fit; see docs/decisions/0017-session-log.md for the measurements).
Every number is written at a stated resolution (`RESOLUTION`, decimals), no finer than what produced
it: the FT-150's wrench as its daemon sends it (forces to 0.01 N, torques to 0.001 N·m: exact), the
FSE103's force as the float32 it is on the wire (its shortest decimal: exact), the robot's pose at
10 µm and 1e-5 rad, which the loop itself works with (`at_log_resolution`), so a replay of the log
feeds the blocks exactly what the session fed them; the hand's force to the FT-150's 0.01 N,
commands to 0.1 mm/s. A sensor's channel has a message when the sensor sent a new sample (its count
moved), not every cycle: the cycle's sample is the latest message at or before it. Chunks are
zstd-compressed; there is no per-message index (it alone was 130 MB an hour): readers find a time
through the chunk index.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import multiprocessing as mp
import queue
import struct
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hoh_cosim import __version__
from hoh_cosim.errors import InputFileError, RunError

if TYPE_CHECKING:  # the writer process imports this module: it needs none of them
    from hoh_cosim.control.cycle import Cycle
    from hoh_cosim.hardware.robot import RobotState
    from hoh_cosim.hardware.streams import Sample

__all__ = [
    "CHANNELS",
    "CYCLE_LAYOUT",
    "FLOAT32",
    "NONFINITE",
    "ORPHANED_CAUSE",
    "RESOLUTION",
    "T0_KEY",
    "ZSTD_LEVEL",
    "CycleRecord",
    "CycleRow",
    "Session",
    "SessionLog",
    "at_log_resolution",
    "channel_schema",
    "decode_message",
    "read_session",
]

_VECTOR = {"type": "array", "items": {"type": "number"}}
_INT = {"type": "integer"}
_NUM = {"type": "number"}
_BOOL = {"type": "boolean"}
_STR = {"type": "string"}

# (topic, field, size, JSON type): the cycle row, in order
CYCLE_LAYOUT: tuple[tuple[str, str, int, dict[str, Any]], ...] = (
    ("/robot", "p_BT_B", 3, _VECTOR),
    ("/robot", "rotvec_BT", 3, _VECTOR),
    ("/robot", "twist_B", 6, _VECTOR),
    ("/robot", "robot_mode", 1, _INT),
    ("/robot", "safety_mode", 1, _INT),
    ("/robot", "protective_stop", 1, _BOOL),
    ("/robot", "emergency_stop", 1, _BOOL),
    ("/robot", "program_running", 1, _BOOL),
    ("/ft150", "wrench_S", 6, _VECTOR),
    ("/ft150", "count", 1, _INT),
    ("/ft150", "received_s", 1, _NUM),
    ("/fse103", "force_P", 3, _VECTOR),
    ("/fse103", "count", 1, _INT),
    ("/fse103", "received_s", 1, _NUM),
    ("/fse103", "device_ms", 1, _INT),
    ("/estimate", "F_hand_B", 3, _VECTOR),
    ("/estimate", "tau_hand_B", 3, _VECTOR),
    ("/estimate", "F_probe_B", 3, _VECTOR),
    ("/estimate", "F_hand_meas_B", 3, _VECTOR),
    ("/estimate", "ft_age", 1, _NUM),
    ("/estimate", "probe_age", 1, _NUM),
    ("/estimate", "ready", 1, _NUM),
    ("/estimate", "rejected_packets", 1, _NUM),
    ("/estimate", "F_probe_meas_P", 3, _VECTOR),
    ("/estimate", "F_probe_corr_P", 3, _VECTOR),
    ("/estimate", "F_probe_meas_B", 3, _VECTOR),
    ("/estimate", "probe_check", 1, _NUM),
    ("/estimate", "probe_mismatch", 1, _NUM),
    ("/estimate", "probe_drift", 1, _NUM),
    ("/estimate", "tau_probe_B", 3, _VECTOR),
    ("/estimate", "probe_axis_B", 3, _VECTOR),
    ("/command", "twist_B", 6, _VECTOR),
    ("/command", "twist_law_B", 6, _VECTOR),
    ("/command", "status", 1, _INT),
    ("/command", "mode", 1, _INT),
    ("/command", "sent_B", 6, _VECTOR),
    ("/timing", "compute_s", 1, _NUM),
    ("/timing", "late_s", 1, _NUM),
)
FLOAT32 = "float32"
"""A `RESOLUTION` for values that are float32 on the wire: their shortest decimal, exact."""

RESOLUTION: dict[tuple[str, str], int | str] = {
    ("/robot", "p_BT_B"): 5,  # 10 µm: a tenth of the UR5's repeatability
    ("/robot", "rotvec_BT"): 5,  # 1e-5 rad
    ("/robot", "twist_B"): 4,  # 0.1 mm/s, 1e-4 rad/s: logged, not fed to the blocks
    ("/ft150", "wrench_S"): 3,  # the daemon's 2 and 3 decimals: exact
    ("/ft150", "received_s"): 5,  # 10 µs
    ("/fse103", "force_P"): FLOAT32,
    ("/fse103", "received_s"): 5,
    ("/estimate", "F_hand_B"): 2,  # the FT-150's resolution: 0.01 N, 0.001 N·m
    ("/estimate", "tau_hand_B"): 3,
    ("/estimate", "F_probe_B"): 3,  # 1 mN: the probe sensor's forces
    ("/estimate", "F_hand_meas_B"): 2,
    ("/estimate", "ft_age"): 6,
    ("/estimate", "probe_age"): 6,
    ("/estimate", "ready"): 3,
    ("/estimate", "rejected_packets"): 0,
    ("/estimate", "F_probe_meas_P"): 3,
    ("/estimate", "F_probe_corr_P"): 3,
    ("/estimate", "F_probe_meas_B"): 3,
    ("/estimate", "probe_check"): 3,
    ("/estimate", "probe_mismatch"): 3,
    ("/estimate", "probe_drift"): 3,
    ("/estimate", "tau_probe_B"): 4,  # 0.1 mN·m
    ("/estimate", "probe_axis_B"): 6,
    ("/command", "twist_B"): 4,  # 0.1 mm/s, 1e-4 rad/s, as the robot's measured twist
    ("/command", "twist_law_B"): 4,
    ("/command", "sent_B"): 4,
    ("/timing", "compute_s"): 5,  # 10 µs (the runner's own histogram reports to 1 µs)
    ("/timing", "late_s"): 5,
}
"""Decimals each float field is written with (see the module's docstring); log times to 1 ns."""

ZSTD_LEVEL = 17
"""The chunks' zstd level, chosen by measurement (docs/decisions/0017-session-log.md): level 3, the
mcap writer's own, writes a third more than 9; 12 and 15 gain nothing over 9; 17 a tenth less than 9
for about 5 s of the writer's CPU per minute of session (a twelfth of a core, at nice 5 beside a
real-time loop); 19 a little less again for a fifth of a core."""

T0_KEY = "t0_unix_ns"
"""The key of each channel's metadata that gives the log time of session time 0 [ns]."""

_SAME_AS_COMMAND = ("twist_law_B", "sent_B")
"""The /command fields that are left out where they equal `twist_B` (the module's docstring)."""

_MODES = frozenset(range(7))
"""The controller's modes' values (`hoh_cosim.control.guidance.modes.Mode`); another is logged as
its number, never a reason for the writer to fail."""

ORPHANED_CAUSE = "the runner process ended without closing the log"
"""The `end` event's detail the writer gives when its runner is gone before saying how it ended."""

# k, t, whether an FT-150 sample and a probe sample exist yet, then the layout
_HEAD = 4
ROW_SIZE = _HEAD + sum(size for _, _, size, _ in CYCLE_LAYOUT)

# every field of every channel: its JSON schema (a vector with its length)
CHANNELS: dict[str, dict[str, Any]] = {}
for _topic, _name, _size, _kind in CYCLE_LAYOUT:
    _field = {**_kind, "minItems": _size, "maxItems": _size} if _kind is _VECTOR else _kind
    CHANNELS.setdefault(_topic, {})[_name] = _field
CHANNELS["/command"]["status_text"] = _STR
CHANNELS["/command"]["mode_text"] = _STR
CHANNELS["/events"] = {"event": _STR, "detail": _STR}

NONFINITE = "nonfinite"
"""The field of a message that holds its non-finite numbers. JSON has no NaN, a schema that allows
null in a number field (`"type": ["number", "null"]`) makes Foxglove reject the whole channel, and
a null where the schema says number is invalid. So a field with a non-finite value (a sensor's NaN)
is left out and given here instead, as text, element by element: `"nonfinite": {"wrench_S": ["nan",
"1.5", "2.0", "0.1", "0.0", "0.0"]}`. `read_session` puts it back as NaN; a reader that does not
know the field sees the value missing (a gap in a plot), never a wrong number."""


class CycleRow:
    """One cycle's row, filled field by field by the loop (preallocated, reused every cycle)."""

    def __init__(self) -> None:
        self.values = np.zeros(ROW_SIZE)
        self.slices: dict[str, slice] = {}
        at = _HEAD
        for topic, name, size, _ in CYCLE_LAYOUT:
            self.slices[f"{topic}.{name}"] = slice(at, at + size)
            at += size

    def set(self, name: str, value: Any) -> None:
        self.values[self.slices[name]] = value

    def start(self, k: int, t: float, has_ft: bool, has_probe: bool) -> None:
        self.values[:_HEAD] = (k, t, 1.0 if has_ft else 0.0, 1.0 if has_probe else 0.0)


@dataclass(frozen=True)
class CycleRecord:
    """Everything the log keeps of one cycle of the runner."""

    k: int
    t: float  # [s] k times the period
    cycle: Cycle  # what the control cycle read, estimated, commanded and decided
    robot: RobotState  # the state the cycle read
    ft: Sample | None  # the FT-150 and FSE103 samples it used (None: none yet)
    probe: Sample | None
    compute_s: float  # [s] from the cycle's start to the command sent
    late_s: float  # [s] how late the cycle started

    def fill(self, row: CycleRow) -> None:
        """Write this record into a cycle row."""
        state, ft, probe = self.robot, self.ft, self.probe
        reading, verdict = self.cycle.reading, self.cycle.verdict
        row.start(self.k, self.t, ft is not None, probe is not None)
        row.set("/robot.p_BT_B", state.p_BT_B)
        rotvec = state.rotvec_BT
        if rotvec is None:
            from hoh_cosim.control.frames import matrix_to_rotvec  # see at_log_resolution

            rotvec = matrix_to_rotvec(state.R_BT)
        row.set("/robot.rotvec_BT", rotvec)
        row.set("/robot.twist_B", state.twist_B)
        row.set("/robot.robot_mode", state.robot_mode)
        row.set("/robot.safety_mode", state.safety_mode)
        row.set("/robot.protective_stop", state.protective_stop)
        row.set("/robot.emergency_stop", state.emergency_stop)
        row.set("/robot.program_running", state.program_running)
        if ft is not None:
            row.set("/ft150.wrench_S", ft.values)
            row.set("/ft150.count", reading.ft_count)
            row.set("/ft150.received_s", ft.received_s)
        if probe is not None:
            row.set("/fse103.force_P", probe.values)
            row.set("/fse103.count", reading.probe_count)
            row.set("/fse103.received_s", probe.received_s)
            row.set("/fse103.device_ms", -1 if probe.device_ms is None else probe.device_ms)
        for name, value in self.cycle.estimate.items():
            row.set(f"/estimate.{name}", value)
        row.set("/command.twist_B", self.cycle.command["twist_B"])
        row.set("/command.twist_law_B", self.cycle.command["twist_law_B"])
        row.set("/command.status", int(verdict.status))
        row.set("/command.mode", int(self.cycle.command["mode"][0]))
        row.set("/command.sent_B", verdict.twist_B)
        row.set("/timing.compute_s", self.compute_s)
        row.set("/timing.late_s", self.late_s)


def _is_float(kind: Mapping[str, Any]) -> bool:
    """Whether a field holds floats, which may be non-finite (then in `NONFINITE`)."""
    return kind["type"] == "number" or (kind["type"] == "array" and kind["items"] == _NUM)


def channel_schema(topic: str) -> dict[str, Any]:
    """The JSON schema of a channel's messages: every field named, nothing else allowed; the
    fields that hold floats may be absent only when `NONFINITE` gives them."""
    properties = {"k": _INT, **CHANNELS[topic]}
    floats = {
        name: (
            {
                "type": "array",
                "items": _STR,
                "minItems": kind["minItems"],
                "maxItems": kind["maxItems"],
            }
            if kind["type"] == "array"
            else _STR
        )
        for name, kind in CHANNELS[topic].items()
        if _is_float(kind)
    }
    schema: dict[str, Any] = {
        "title": f"hoh-cosim {topic}",
        "type": "object",
        "properties": properties,
        "required": ["k", *(n for n, kind in CHANNELS[topic].items() if not _is_float(kind))],
        "additionalProperties": False,
    }
    if floats:
        schema["properties"][NONFINITE] = {
            "type": "object",
            "properties": floats,
            "additionalProperties": False,
        }
    return schema


def _text(x: float) -> str:
    return repr(float(x)) if np.isfinite(x) else str(float(x))  # 'nan', 'inf', '-inf'


def _number(x: float, kind: dict[str, Any]) -> Any:
    if kind is _INT:
        return int(x)
    if kind is _BOOL:
        return bool(x)
    return float(x)


def _rounded(values: np.ndarray, decimals: int | str | None) -> list[float]:
    if decimals is None:
        return values.tolist()
    if decimals == FLOAT32:  # NaN and infinities too: str gives 'nan', 'inf'
        return [float(str(x)) for x in values.astype(np.float32)]
    return (np.round(values, int(decimals)) + 0.0).tolist()  # + 0.0: no "-0.0"


def _messages(
    row: np.ndarray, counts: dict[str, int] | None = None
) -> list[tuple[str, dict[str, Any]]]:
    """A cycle row as the messages of its channels, each number at its `RESOLUTION`. With
    `counts` (the sensor channels' last written sample counts, updated here), a sensor's message
    only when its sample is new."""
    k, has_ft, has_probe = int(row[0]), row[2] > 0.5, row[3] > 0.5
    out: dict[str, dict[str, Any]] = {}
    at = _HEAD
    skip: set[str] = set()
    if not has_ft:
        skip.add("/ft150")
    if not has_probe:
        skip.add("/fse103")
    for topic, name, size, kind in CYCLE_LAYOUT:
        values = row[at : at + size]
        at += size
        if topic in skip:
            continue
        if counts is not None and name == "count" and topic in ("/ft150", "/fse103"):
            count = int(values[0])
            if counts.get(topic) == count:
                skip.add(topic)
                out.pop(topic, None)
                continue
            counts[topic] = count
        message = out.setdefault(topic, {"k": k})
        if (kind is _VECTOR or kind is _NUM) and not np.all(np.isfinite(values)):
            text = [_text(x) for x in _rounded(values, RESOLUTION.get((topic, name)))]
            message.setdefault(NONFINITE, {})[name] = text if kind is _VECTOR else text[0]
        elif kind is _VECTOR:
            message[name] = _rounded(values, RESOLUTION.get((topic, name)))
        elif kind is _NUM:
            message[name] = _rounded(values, RESOLUTION.get((topic, name)))[0]
        else:
            message[name] = _number(values[0], kind)
    if "/command" in out:
        from hoh_cosim.control.guidance.modes import Mode
        from hoh_cosim.control.supervisor import Status

        command = out["/command"]
        for name in _SAME_AS_COMMAND:  # written where they differ (the module's docstring)
            if name in command and command[name] == command.get("twist_B"):
                del command[name]
        command["status_text"] = Status(command["status"]).describe()
        mode = command["mode"]
        command["mode_text"] = Mode(mode).label if mode in _MODES else f"mode {mode}"
    return list(out.items())


def at_log_resolution(state: RobotState) -> RobotState:
    """The robot's state as the log holds it: the position to `RESOLUTION`'s decimals, the
    orientation through its rotation vector at its decimals (the robot's own where it gives one:
    converting a matrix costs 50 µs). The loop works with this state, so that a replay of the log
    feeds the blocks exactly what the session fed them."""
    # here, not at the module's top: the log's writer process imports this module, and scipy's
    # rotations (0.2 s of imports) would hold up every session's start for it
    from hoh_cosim.control.frames import matrix_to_rotvec, rotvec_to_matrix

    p_decimals = int(RESOLUTION["/robot", "p_BT_B"])
    r_decimals = int(RESOLUTION["/robot", "rotvec_BT"])
    rotvec = state.rotvec_BT if state.rotvec_BT is not None else matrix_to_rotvec(state.R_BT)
    rotvec = np.round(rotvec, r_decimals) + 0.0
    return dataclasses.replace(
        state,
        p_BT_B=np.round(state.p_BT_B, p_decimals) + 0.0,
        R_BT=rotvec_to_matrix(rotvec),
        rotvec_BT=rotvec,
    )


def _jsonable(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


class _LevelledZstd:
    """What mcap's writer uses of the `zstandard` module, at a chosen level."""

    def __init__(self, module: Any, level: int) -> None:
        self._module = module
        self._compressor = module.ZstdCompressor(level=level)

    def compress(self, data: bytes) -> bytes:
        return self._compressor.compress(data)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._module, name)


def _writer_main(
    path: str,
    metadata: dict[str, Any],
    ring: Any,
    written: Any,
    capacity: int,
    events: Any,
    stop: Any,
    flush_s: float,
    t0_unix_ns: int,
    replies: Any,
) -> None:
    """The writer process: rows and events in, an MCAP file out. It finishes the file when told
    to, or when the runner that started it is gone (killed: it never will be told)."""
    import os

    parent = os.getppid()

    import mcap.writer
    import zstandard
    from mcap.writer import CompressionType, IndexType, Writer

    # mcap's writer compresses each chunk with zstandard's module-level `compress`, at level 3, and
    # has no setting for the level: give it a compressor at ours (what a reader decodes is the
    # same zstd either way)
    mcap.writer.zstandard = _LevelledZstd(zstandard, ZSTD_LEVEL)  # type: ignore[attr-defined]

    with contextlib.suppress(OSError):  # the loop comes first: the log may lag, it has a ring
        os.nice(5)
    try:
        stream = Path(path).open("xb")  # noqa: SIM115 - closed by the with below
    except OSError as exc:
        replies.put(f"{path}: cannot create the session log: {exc.strerror}")
        return
    replies.put("ready")
    rows = np.frombuffer(ring, dtype=np.float64).reshape(capacity, ROW_SIZE)
    with stream:
        writer = Writer(
            stream,
            compression=CompressionType.ZSTD,
            index_types=IndexType.ALL & ~IndexType.MESSAGE,
        )
        writer.start(profile="", library=f"hoh-cosim {__version__}")
        channels = {}
        for topic in CHANNELS:
            schema = writer.register_schema(
                name=f"hoh_cosim{topic.replace('/', '.')}",
                encoding="jsonschema",
                data=json.dumps(channel_schema(topic)).encode(),
            )
            channels[topic] = writer.register_channel(
                topic=topic,
                message_encoding="json",
                schema_id=schema,
                metadata={T0_KEY: str(t0_unix_ns)},  # in a chunk, under its CRC
            )
        writer.add_metadata("session", {k: json.dumps(v) for k, v in metadata.items()})
        writer.flush()

        def add(topic: str, t: float, message: dict[str, Any]) -> None:
            log_ns = t0_unix_ns + round(t * 1e9)
            # strict JSON, as browsers read, without spaces
            data = json.dumps(message, allow_nan=False, separators=(",", ":")).encode()
            writer.add_message(channels[topic], log_ns, data, log_ns)

        ended = False  # the runner's `end` event came

        def drain_events() -> None:
            nonlocal ended
            while True:
                try:
                    k, t, event, detail = events.get_nowait()
                except queue.Empty:
                    return
                ended = ended or event == "end"
                add("/events", t, {"k": k, "event": event, "detail": detail})

        def overflow(first: int, lost: int) -> None:
            detail = f"{lost} cycles were not logged"
            # at the last cycle written before them: the log's times only ever go forward
            add("/events", last[1], {"k": first, "event": "log_overflow", "detail": detail})

        done, last_flush = 0, time.monotonic()
        flushed_t = 0.0  # the session time [s] of the last cycle before the last flush
        counts: dict[str, int] = {}  # the sensor channels' last written sample counts
        finishing = orphaned = False
        last = (0, 0.0)  # the last cycle written: k, t
        while True:
            orphaned = orphaned or os.getppid() != parent
            finishing = finishing or stop.is_set() or orphaned
            head = written.value
            # The loop writes row `head` into the slot of row `head - capacity` before it counts
            # it: rows from `head - capacity + 1` on are intact now (from `head - capacity` on once
            # the loop has ended). Copy them, then look again: whatever the loop reached meanwhile
            # may have overwritten the oldest of the copies.
            margin = 0 if finishing else 1
            first = max(done, head - capacity + margin)
            block = rows[np.arange(first, head) % capacity].copy()
            intact = min(head, max(first, written.value - capacity + margin))
            if intact > done:
                overflow(done, intact - done)
            for row in block[intact - first :]:
                for topic, message in _messages(row, counts):
                    add(topic, float(row[1]), message)
                last = (int(row[0]), float(row[1]))
                # a chunk holds at most flush_s of the session's time too, however late the
                # writer got to it: a backlog drained at once is not one chunk of many seconds
                if last[1] - flushed_t >= flush_s:
                    writer.flush()
                    flushed_t, last_flush = last[1], time.monotonic()
            done = head
            drain_events()
            if finishing and done >= written.value:
                drain_events()
                if orphaned and not ended:  # killed: the log still says how the session ended
                    k, t = last
                    detail = f"{ORPHANED_CAUSE} (killed or crashed) after cycle {k}"
                    add("/events", t, {"k": k, "event": "end", "detail": detail})
                break
            if time.monotonic() - last_flush >= flush_s:
                writer.flush()
                stream.flush()
                flushed_t, last_flush = last[1], time.monotonic()
            if done >= written.value:
                time.sleep(0.02)
        writer.finish()


class SessionLog:
    """One session's MCAP file, written by a process of its own (see the module's docstring)."""

    def __init__(
        self,
        path: str | Path,
        metadata: Mapping[str, Any],
        flush_s: float = 1.0,
        capacity: int = 8192,
    ) -> None:
        self.path = Path(path)
        self.flush_s = flush_s
        self.capacity = capacity
        self._metadata = _jsonable(dict(metadata))
        self._context = mp.get_context("spawn")
        self._process: Any = None
        self.row = CycleRow()

    def start(self) -> SessionLog:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise RunError(f"{self.path}: cannot create the session log: {exc.strerror}") from None
        try:
            exists = self.path.exists()
        except OSError as exc:  # a name too long, say
            raise RunError(f"{self.path}: cannot create the session log: {exc.strerror}") from None
        if exists:
            raise RunError(f"{self.path}: cannot create the session log: it exists")
        ctx = self._context
        self._ring = ctx.RawArray("d", self.capacity * ROW_SIZE)
        self._rows = np.frombuffer(self._ring, dtype=np.float64).reshape(self.capacity, ROW_SIZE)
        self._written = ctx.RawValue("q", 0)
        self._events = ctx.Queue()
        self._stop = ctx.Event()
        replies = ctx.Queue()
        self._process = ctx.Process(
            target=_writer_main,
            args=(
                str(self.path),
                self._metadata,
                self._ring,
                self._written,
                self.capacity,
                self._events,
                self._stop,
                self.flush_s,
                time.time_ns(),
                replies,
            ),
            name="session-log-writer",
            daemon=True,
        )
        self._process.start()
        try:
            reply = replies.get(timeout=30.0)
        except queue.Empty:
            reply = "the log writer did not start"
        if reply != "ready":
            self._process.join(1.0)
            raise RunError(reply)
        return self

    def record(self, record: CycleRecord) -> None:
        """Log one cycle of the runner."""
        record.fill(self.row)
        self.cycle()

    def cycle(self) -> None:
        """Hand the filled `row` over: one copy into the ring."""
        n = self._written.value
        self._rows[n % self.capacity] = self.row.values
        self._written.value = n + 1

    def event(self, k: int, t: float, event: str, detail: str = "") -> None:
        if self._process is not None:  # after close, nothing more is written
            self._events.put((k, t, event, detail))

    def close(self) -> None:
        """Let the writer write everything handed over, the summary and the footer."""
        if self._process is None:
            return
        # the queue's own thread carries events to the pipe: wait until it has carried every one,
        # or the writer, told to finish, could find the pipe empty and lose the last (the `end`
        # event, a stop's cause; seen once in a loaded test run)
        self._events.close()
        self._events.join_thread()
        self._stop.set()
        self._process.join(30.0)
        if self._process.is_alive():
            self._process.kill()
        self._process = None


@dataclass
class Session:
    """A session log read back: messages per topic in order, the metadata, whether it is whole."""

    path: Path
    metadata: dict[str, Any]
    messages: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    complete: bool = True

    def series(self, topic: str, name: str) -> np.ndarray:
        """One field of one topic as an array (rows in message order; None, which older logs
        wrote for a non-finite value, as NaN)."""
        rows = [m[name] for m in self.messages.get(topic, [])]
        return np.array(
            [[np.nan if x is None else x for x in r] if isinstance(r, list) else r for r in rows],
            dtype=float,
        )


def decode_message(message: dict[str, Any]) -> dict[str, Any]:
    """A message as written, its `NONFINITE` values back in their fields as floats (NaN, inf)."""
    given = message.pop(NONFINITE, None)
    if isinstance(given, Mapping):
        for name, text in given.items():
            message[name] = [float(x) for x in text] if isinstance(text, list) else float(text)
    return message


def read_session(path: str | Path) -> Session:
    """Every message of a session log; a file cut off by a killed process is read up to the cut
    (`complete` is then False), and so is a damaged one: up to the first record that cannot be
    read, or whose chunk's CRC does not match, so that no damaged message is taken as data."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Footer, Message, Metadata
    from mcap.stream_reader import StreamReader
    from zstandard import ZstdError  # mcap's decompressor for its chunks (lz4's raise RuntimeError)

    path = Path(path)
    try:
        stream = path.open("rb")
    except OSError as exc:
        raise InputFileError(path, "", f"cannot read: {exc.strerror}") from None
    session = Session(path, {}, {topic: [] for topic in CHANNELS}, complete=False)
    topics: dict[int, str] = {}
    t0s: dict[int, int] = {}  # per channel: the log time of session time 0 [ns]
    with stream:
        try:
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Channel):
                    topics[record.id] = record.topic
                    t0s[record.id] = int(record.metadata.get(T0_KEY, "0"))
                elif isinstance(record, Message):
                    topic = topics.get(record.channel_id)
                    if topic is not None:
                        message = json.loads(record.data)
                        if not isinstance(message, dict):
                            raise ValueError(f"a {topic} message that is not a JSON object")
                        message = decode_message(message)
                        if "t" not in message:  # the session time of its record's log time
                            t0_ns = t0s[record.channel_id]
                            message["t"] = round((record.log_time - t0_ns) * 1e-9, 9)
                        if topic == "/command":
                            for name in _SAME_AS_COMMAND:  # left out where equal
                                if name not in message and "twist_B" in message:
                                    message[name] = list(message["twist_B"])
                        session.messages.setdefault(topic, []).append(message)
                elif isinstance(record, Metadata) and record.name == "session":
                    session.metadata = {k: json.loads(v) for k, v in record.metadata.items()}
                elif isinstance(record, Footer):
                    session.complete = True
        # cut off, damaged or not MCAP at all; a damaged length can ask for more memory than
        # there is (MemoryError) or than an index holds (OverflowError)
        except (
            McapError,
            ZstdError,
            RuntimeError,
            ValueError,
            struct.error,
            OverflowError,
            MemoryError,
        ) as exc:
            # A writer killed before its first chunk leaves the header and the metadata only
            if not topics and not session.metadata:
                reason = str(exc) or type(exc).__name__
                raise InputFileError(path, "", f"not a session log: {reason}") from None
    return session
