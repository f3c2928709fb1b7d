"""The Variense FSE103 probe force sensor over USB serial: frame parser, encoder and serial port.

The seed's author observed an 18-byte frame, the vendor's user guide describes a 20-byte one:

    seed18   0x00 | uint32 t [ms] | float32 Fx Fy Fz [N] | 0xFF                        18 bytes
    guide20  0x0D | 0x14 | type | uint32 t [ms] | float32 F1 F2 F3 | 0xFF            20 bytes
             type 0x66: forces [N], 0x72: raw readings

The byte order is not settled either: the guide reads as little-endian, public drivers decode
big-endian. Both framings and both byte orders are decoded, given or detected from the data. Start and end bytes can occur inside the floats, so frames
are found by their length and end byte and confirmed by a run of plausible frames, never by
searching for a delimiter. The device takes single-byte commands: `f` forces, `r` raw, `z` zero.

`FSE103Parser` is pure (bytes in, frames out, never blocking, never raising on bad bytes);
`FSE103Port` reads it from a serial port in a `ReaderThread` and publishes forces to a `Mailbox`.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from itertools import product
from typing import Any

import numpy as np
import numpy.typing as npt

from hoh_cosim.control.vectors import Vec, frozen
from hoh_cosim.errors import ConfigError
from hoh_cosim.hardware.serial_source import SerialSource
from hoh_cosim.hardware.streams import Sample, now

__all__ = [
    "BYTE_ORDERS",
    "COMMAND_FORCES",
    "COMMAND_RAW",
    "COMMAND_ZERO",
    "FRAME_LENGTHS",
    "FRAMINGS",
    "LOCK_FRAMES",
    "MAX_FORCE_N",
    "MAX_PENDING_BYTES",
    "MAX_STEP_MS",
    "RELOCK_BAD_FRAMES",
    "FSE103Parser",
    "FSE103Port",
    "ProbeFrame",
    "encode_frame",
]

FRAMINGS = ("seed18", "guide20")
BYTE_ORDERS = ("little", "big")
FRAME_LENGTHS = {"seed18": 18, "guide20": 20}
KINDS = ("forces", "raw")

LOCK_FRAMES = 3
"""Consecutive plausible frames, at one framing's stride, needed to (re)synchronise."""
MAX_STEP_MS = 1000
"""[ms] The largest time-stamp step between neighbouring frames taken as plausible."""
MAX_FORCE_N = 1000.0
"""[N] While synchronising, force frames with |F| at or above this are implausible (raw frames:
finite is enough). Frames in sync are passed on whatever their values."""
RELOCK_BAD_FRAMES = 5
"""Bad frames in one run after which an auto-detected framing or byte order is forgotten."""
MAX_PENDING_BYTES = LOCK_FRAMES * max(FRAME_LENGTHS.values()) - 1
"""The most bytes the parser keeps between calls to `feed`."""

COMMAND_FORCES = b"f"
COMMAND_RAW = b"r"
COMMAND_ZERO = b"z"

_SEED_START = 0x00
_GUIDE_START = 0x0D
_GUIDE_SIZE = 0x14
_TYPE_BYTES = {"forces": 0x66, "raw": 0x72}
_TYPE_KINDS = {byte: kind for kind, byte in _TYPE_BYTES.items()}
_END = 0xFF
_START_BYTES = {"seed18": _SEED_START, "guide20": _GUIDE_START}
_STRUCTS = {
    (framing, order): struct.Struct(
        {"little": "<", "big": ">"}[order] + {"seed18": "xIfffx", "guide20": "xxxIfffx"}[framing]
    )
    for framing, order in product(FRAMINGS, BYTE_ORDERS)
}
_WRAP = 2**32

# _chain verdicts
_NO, _MORE, _MATCH = "no", "more", "match"


@dataclass(frozen=True)
class ProbeFrame:
    """One decoded frame: `forces` [N] (or raw readings when `kind` is 'raw'), float32 values as
    float64, and the device's own time stamp [ms], a wrapping uint32."""

    forces: Vec
    timestamp_ms: int
    kind: str = "forces"

    def __post_init__(self) -> None:
        forces = frozen(self.forces)
        if forces.shape != (3,):
            raise ConfigError(f"forces: expected 3 values, got shape {forces.shape}")
        _choice(self.kind, "kind", KINDS)
        object.__setattr__(self, "forces", forces)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ProbeFrame):
            return NotImplemented
        return (
            self.timestamp_ms == other.timestamp_ms
            and self.kind == other.kind
            and np.array_equal(self.forces, other.forces, equal_nan=True)
        )

    def __hash__(self) -> int:
        return hash((self.timestamp_ms, self.kind))  # equal frames, equal hashes (0.0 == -0.0)


def _choice(value: object, name: str, allowed: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in allowed:
        raise ConfigError(f"{name}: expected one of {', '.join(map(repr, allowed))}, got {value!r}")
    return value


def encode_frame(
    forces: npt.ArrayLike,
    timestamp_ms: int,
    *,
    framing: str,
    byte_order: str,
    kind: str = "forces",
) -> bytes:
    """One frame as the device would send it, for emulators and tests.

    The forces are rounded to float32 (non-finite values pass through, to emulate broken frames);
    the time stamp wraps modulo 2**32. seed18 frames have no type byte: they carry forces only.
    """
    framing = _choice(framing, "framing", FRAMINGS)
    byte_order = _choice(byte_order, "byte_order", BYTE_ORDERS)
    kind = _choice(kind, "kind", KINDS)
    values = np.asarray(forces, dtype=np.float64)
    if values.shape != (3,):
        raise ConfigError(f"forces: expected 3 values, got shape {values.shape}")
    if framing == "seed18" and kind != "forces":
        raise ConfigError(f"kind: seed18 frames carry forces only, got {kind!r}")
    body = _STRUCTS[framing, byte_order].pack(int(timestamp_ms) % _WRAP, *values.tolist())
    if framing == "seed18":
        return bytes([_SEED_START]) + body[1:-1] + bytes([_END])
    return bytes([_GUIDE_START, _GUIDE_SIZE, _TYPE_BYTES[kind]]) + body[3:-1] + bytes([_END])


_Decoded = tuple[int, tuple[float, float, float], str]


def _decode(
    buf: bytearray, j: int, framing: str, byte_order: str, *, judge_values: bool
) -> _Decoded | None:
    """The frame of `framing` at buf[j:], if its fixed bytes match and, with `judge_values`, its
    values are plausible. The caller makes sure a whole frame's bytes are there."""
    if framing == "seed18":
        if buf[j] != _SEED_START or buf[j + 17] != _END:
            return None
        kind = "forces"
    else:
        if buf[j] != _GUIDE_START or buf[j + 1] != _GUIDE_SIZE or buf[j + 19] != _END:
            return None
        kind = _TYPE_KINDS.get(buf[j + 2], "")
        if not kind:
            return None
    timestamp, f1, f2, f3 = _STRUCTS[framing, byte_order].unpack_from(buf, j)
    if judge_values:
        if not (math.isfinite(f1) and math.isfinite(f2) and math.isfinite(f3)):
            return None
        if kind == "forces" and math.hypot(f1, f2, f3) >= MAX_FORCE_N:
            return None
    return timestamp, (f1, f2, f3), kind


def _header_mismatch(buf: bytearray, j: int, framing: str) -> bool:
    """Whether the bytes present of a frame starting at j already rule it out."""
    n = len(buf)
    if framing == "seed18":
        return j < n and buf[j] != _SEED_START
    return (
        (j < n and buf[j] != _GUIDE_START)
        or (j + 1 < n and buf[j + 1] != _GUIDE_SIZE)
        or (j + 2 < n and buf[j + 2] not in _TYPE_KINDS)
    )


def _step_ok(previous_ms: int, timestamp_ms: int, minimum: int) -> bool:
    return minimum <= (timestamp_ms - previous_ms) % _WRAP <= MAX_STEP_MS


def _chain(buf: bytearray, i: int, framing: str, byte_order: str) -> tuple[str, list[_Decoded]]:
    """(_MATCH, the frames) if LOCK_FRAMES plausible frames with time stamps stepping forward start
    at buf[i]; (_NO, []) if the bytes there rule that out; (_MORE, []) if it takes more bytes."""
    length = FRAME_LENGTHS[framing]
    frames: list[_Decoded] = []
    for k in range(LOCK_FRAMES):
        j = i + k * length
        if j + length > len(buf):
            return (_NO if _header_mismatch(buf, j, framing) else _MORE), []
        frame = _decode(buf, j, framing, byte_order, judge_values=True)
        if frame is None or (frames and not _step_ok(frames[-1][0], frame[0], 1)):
            return _NO, []
        frames.append(frame)
    return _MATCH, frames


class FSE103Parser:
    """Frames from the FSE103's byte stream, whatever the chunking: `feed` bytes, get frames.

    Synchronisation. A frame is plausible when its fixed bytes match (start byte, for guide20 the
    size byte and a known type byte, the end byte), its three floats are finite and, for force
    frames, |F| < MAX_FORCE_N. The parser synchronises at the first byte offset where LOCK_FRAMES
    plausible frames follow each other at one framing's stride with time stamps stepping forward by
    0 < step <= MAX_STEP_MS (modulo 2**32); at one offset, framing and byte order are tried in the
    order of FRAMINGS and BYTE_ORDERS and the decision waits until every earlier candidate is
    ruled in or out, so the result never depends on how the stream was cut into chunks. The
    synchronising frames are returned at once. While in sync, each further frame is taken when its
    fixed bytes match and its time stamp steps by 0 <= step <= MAX_STEP_MS from the last one; its
    values are not judged then, so a NaN or an absurd force from a device in sync is passed on for
    the estimator and the runner to reject, as the FT-150 parser does. Otherwise the parser falls
    out of sync and searches again from that frame's first byte (a device whose clock restarted is
    picked up again without losing a frame), sliding one byte at a time. Only the given framing and
    byte order are candidates; 'auto' allows both.

    Detection. `framing` and `byte_order` hold the given values, or for 'auto' None until the first
    synchronisation fixes them. Resynchronisation tries the detected values first, then the other
    allowed ones at the same offset: a device that switched framing or byte order (or was swapped)
    is found again at its first LOCK_FRAMES frames, as at the start. (Trying only the detected
    values until RELOCK_BAD_FRAMES bad frames had gone by cost those five frames too: about 200 ms
    of silence at 50 Hz, against a 250 ms stale limit that a loaded machine's late delivery
    crossed.) A run of discarded bytes reaching RELOCK_BAD_FRAMES bad frames still forgets the
    auto-detected values, which only changes how later discarded bytes are counted.

    Bad frames. Bytes skipped while searching are discarded. A bad frame is one frame length of
    consecutive discarded bytes, begun: a run of n bytes discarded between two accepted frames
    counts ceil(n / L), L being the frame length of the framing in force (while it is unknown, the
    longest candidate's: 20).
    So garbage between two frames counts at least one, a stream in the wrong framing about one per
    L bytes, and starting to listen mid-frame counts one. `bad_frames` only grows.

    The parser keeps at most MAX_PENDING_BYTES between calls (the unfinished frames), so memory
    stays bounded under endless garbage. No input bytes make it raise.
    """

    def __init__(self, framing: str = "auto", byte_order: str = "auto") -> None:
        framing = _choice(framing, "framing", ("auto", *FRAMINGS))
        byte_order = _choice(byte_order, "byte_order", ("auto", *BYTE_ORDERS))
        self._framings = FRAMINGS if framing == "auto" else (framing,)
        self._byte_orders = BYTE_ORDERS if byte_order == "auto" else (byte_order,)
        self._auto_framing = framing == "auto"
        self._auto_byte_order = byte_order == "auto"
        self._start_bytes = bytes(_START_BYTES[f] for f in self._framings)
        self.framing: str | None = None if self._auto_framing else framing
        self.byte_order: str | None = None if self._auto_byte_order else byte_order
        self.bad_frames = 0
        self._buf = bytearray()
        self.reset()

    def reset(self) -> None:
        """Forget the pending bytes and the synchronisation (after a reconnection, say); the
        detected framing and byte order and the `bad_frames` count are kept."""
        self._buf.clear()
        self._synced: tuple[str, str] | None = None  # (framing, byte order) while in sync
        self._last_ms = 0
        self._run = 0  # bytes discarded since the last accepted frame
        self._run_bad = 0  # bad frames counted for them

    @property
    def pending_bytes(self) -> int:
        """How many bytes wait for the rest of their frame."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[ProbeFrame]:
        """The frames completed by `data`, in order; partial frames are kept for the next call."""
        buf = self._buf
        buf += data
        frames: list[ProbeFrame] = []
        i = 0
        n = len(buf)
        while i < n:
            if self._synced is not None:
                length = FRAME_LENGTHS[self._synced[0]]
                if n - i < length:
                    break
                frame = _decode(buf, i, *self._synced, judge_values=False)
                if frame is not None and _step_ok(self._last_ms, frame[0], 0):
                    frames.append(self._accept(frame))
                    i += length
                    continue
                self._synced = None
            verdict, candidate, chain = self._search(buf, i)
            if verdict == _MORE:
                break
            if verdict == _MATCH:
                self.framing, self.byte_order = self._synced = candidate
                frames.extend(self._accept(frame) for frame in chain)
                i += LOCK_FRAMES * FRAME_LENGTHS[candidate[0]]
                continue
            skip = self._skippable(buf, i)
            self._discard(skip)
            i += skip
        del buf[:i]
        return frames

    def _candidates(self) -> list[tuple[str, str]]:
        """Every allowed (framing, byte order), the detected ones first: a device that changed
        framing is found again at its first LOCK_FRAMES frames, not after RELOCK_BAD_FRAMES more."""
        allowed = list(product(self._framings, self._byte_orders))
        detected = [
            c
            for c in allowed
            if c[0] == (self.framing or c[0]) and c[1] == (self.byte_order or c[1])
        ]
        return detected + [c for c in allowed if c not in detected]

    def _search(self, buf: bytearray, i: int) -> tuple[str, tuple[str, str], list[_Decoded]]:
        for candidate in self._candidates():
            verdict, chain = _chain(buf, i, *candidate)
            if verdict != _NO:
                return verdict, candidate, chain
        return _NO, ("", ""), []

    def _unit(self) -> int:
        if self.framing:
            return FRAME_LENGTHS[self.framing]
        return max(FRAME_LENGTHS[f] for f in self._framings)

    def _relock_armed(self) -> bool:
        return (self._auto_framing and self.framing is not None) or (
            self._auto_byte_order and self.byte_order is not None
        )

    def _skippable(self, buf: bytearray, i: int) -> int:
        """Bytes from i up to the next possible start byte (at least 1), but not past the point
        where the lock would be dropped, so the outcome does not depend on the chunking."""
        starts = [j for j in (buf.find(b, i + 1) for b in self._start_bytes) if j >= 0]
        skip = (min(starts) if starts else len(buf)) - i
        if self._relock_armed():
            skip = min(skip, max(1, RELOCK_BAD_FRAMES * self._unit() - self._run))
        return skip

    def _discard(self, n: int) -> None:
        self._run += n
        owed = -(-self._run // self._unit())
        if owed > self._run_bad:
            self.bad_frames += owed - self._run_bad
            self._run_bad = owed
        if self._relock_armed() and self._run >= RELOCK_BAD_FRAMES * self._unit():
            if self._auto_framing:
                self.framing = None
            if self._auto_byte_order:
                self.byte_order = None

    def _accept(self, frame: _Decoded) -> ProbeFrame:
        timestamp, forces, kind = frame
        self._last_ms = timestamp
        self._run = self._run_bad = 0
        return ProbeFrame(np.array(forces), timestamp, kind)


class FSE103Port(SerialSource):
    """The FSE103 on a serial port (or a pyserial URL such as `loop://`), read by a thread.

    `start()` opens the port in a `ReaderThread`, which feeds every chunk read to the parser and
    publishes each force frame as `Sample(forces, received_s=now(), device_ms=timestamp)`. Raw frames
    (type 0x72, after the `r` command) are not forces: they are counted in `raw_frames` and not
    published. Bad frames go to `mailbox.count_bad`. When the device goes away (a read fails, the
    port cannot be opened) the reason, naming the device, is in `mailbox.error` (each failed try
    counts in `mailbox.stats.losses`) and, with `reconnect`, opening is tried again every `retry_s`
    (each success after the first counts in `mailbox.stats.reconnects`). A new connection starts
    from a reset parser: a frame left unfinished by the old one counts as one bad frame, and the
    framing and byte order found before are kept (see `FSE103Parser` for when they are not).

    `stop()` cancels a read in progress, so it returns at once whatever `timeout_s` is. The port
    can be started again after `stop()`; it is usable as a context manager.
    """

    rate_band_hz = (40.0, 60.0)
    """Packet rates a rebias accepts: the seed's FSE103 sent 50 Hz (seed section 2), a fifth
    either side (measured on the device's own time stamps, so only another device or another
    setting of it is that far off)."""

    def __init__(
        self, device: str, *, framing: str = "auto", byte_order: str = "auto", **transport: Any
    ) -> None:
        """`transport`: `SerialSource`'s baudrate, mailbox, reconnect, retry_s, timeout_s."""
        super().__init__(device, **transport)
        self._parser = FSE103Parser(framing, byte_order)
        self.raw_frames = 0
        self._bad_reported = 0

    @property
    def parser(self) -> FSE103Parser:
        return self._parser

    def describe(self) -> str:
        return f"FSE103 on {self.device}"

    def zero(self) -> None:
        """Ask the sensor to zero itself (the `z` command)."""
        self._send(COMMAND_ZERO)

    def _handle(self, data: bytes) -> None:
        frames = self._parser.feed(data)
        bad = self._parser.bad_frames
        self._mailbox.count_bad(bad - self._bad_reported)
        self._bad_reported = bad
        for frame in frames:
            if frame.kind == "forces":
                self._mailbox.publish(
                    Sample(frame.forces, received_s=now(), device_ms=frame.timestamp_ms)
                )
            else:
                self.raw_frames += 1
