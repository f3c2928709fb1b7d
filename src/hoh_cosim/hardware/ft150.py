"""The Robotiq FT-150 wrist sensor as the UR controller's URCap serves it: parser, stream, zeroing.

The URCap's daemon on the controller serves the sensor on two TCP ports, one client at a time each:

- `STREAM_PORT` (63351) sends every sample as ASCII `( Fx , Fy , Fz , Mx , My , Mz )` [N, N·m], with
  nothing between samples, no line ending and no time stamp. A sample may arrive split across reads
  anywhere, even inside a number.
- `COMMAND_PORT` (63350) takes `SET ZRO`: the daemon zeroes the sensor against its next sample.

`FT150Parser` turns bytes into samples and never blocks or raises; `FT150Stream` reads the stream
port in a `ReaderThread` and publishes into a `Mailbox` (see `hoh_cosim.hardware.streams`);
`zero_sensor` sends the zero command. `encode_sample` writes the daemon's format, for emulators and
tests.
"""

from __future__ import annotations

import contextlib
import re
import socket
import threading
import time
from collections.abc import Sequence

import numpy as np

from hoh_cosim.control.vectors import Vec, as_scalar
from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.hardware.streams import Mailbox, ReaderThread, Sample, now

__all__ = [
    "COMMAND_PORT",
    "CONNECT_TIMEOUT_S",
    "MAX_FRAME_BYTES",
    "STREAM_PORT",
    "ZERO_COMMAND",
    "ZERO_HOLD_S",
    "FT150Parser",
    "FT150Stream",
    "encode_sample",
    "zero_sensor",
]

STREAM_PORT = 63351
COMMAND_PORT = 63350

MAX_FRAME_BYTES = 512
"""A `(` with no `)` within this many bytes is dropped as a bad frame, so junk cannot grow the buffer.
A real sample is under 100 bytes; 512 is the daemon's own buffer size (Robotiq's socket driver)."""

CONNECT_TIMEOUT_S = 1.0
"""[s] How long a connection attempt may take. `FT150Stream.stop()` may wait this long if it comes
while a connection attempt to an unreachable host is under way."""

ZERO_COMMAND = b"SET ZRO"
"""The zero command as sent: no line ending, like the URCap's own `rq_set_zero()` script function
(`socket_send_string("SET ZRO")`, which, unlike `socket_send_line`, adds none). See `zero_sensor`."""

ZERO_HOLD_S = 0.1
"""[s] How long `zero_sensor` keeps the command connection open after sending, as `rq_set_zero()`
does (`sleep(0.1)` before `socket_close`). See `zero_sensor` for why closing at once can lose it."""

_RECV_BYTES = 4096
_NUMBER = rb"\s*([+-]?(?:(?:\d+(?:\.\d*)?|\.\d+)(?:e[+-]?\d+)?|nan|inf(?:inity)?))\s*"
_FRAME = re.compile(rb"\(([^()]*)\)")  # a `(`, no other bracket, a `)`: the innermost bracket pair
_SIX_NUMBERS = re.compile(rb",".join([_NUMBER] * 6), re.IGNORECASE)


class FT150Parser:
    """Samples from the FT-150 stream's bytes, fed in pieces as they arrive; no I/O, never raises.

    `feed(data)` returns the samples completed by `data` (float arrays of 6: Fx, Fy, Fz [N], Mx, My,
    Mz [N·m]) and keeps an unfinished one for the next call. Bytes outside brackets are skipped. A
    bracketed frame that is not exactly six numbers, a `(` that a later `(` overtakes before any `)`,
    and a `(` with no `)` within `MAX_FRAME_BYTES` are bad frames: counted in `bad_frames`, dropped,
    and the parser goes on at the next `(`. Numbers may be like `-0.39`, `1e-3`, `+2`; `nan` and `inf`
    give non-finite floats and are passed on, so the estimator can reject the packet itself.
    """

    def __init__(self) -> None:
        self.frames = 0  # good samples returned so far
        self.bad_frames = 0
        self._pending = (
            b""  # an unfinished frame: empty, or `(` and fewer than MAX_FRAME_BYTES more
        )

    @property
    def pending(self) -> int:
        """Bytes of an unfinished frame held for the next `feed` (at most `MAX_FRAME_BYTES`)."""
        return len(self._pending)

    def feed(self, data: bytes) -> list[Vec]:
        """The samples completed by `data`, in order."""
        if not data:
            return []
        buffer = self._pending + bytes(data)
        samples: list[Vec] = []
        end = 0
        for frame in _FRAME.finditer(buffer):
            # every `(` in the gap since the last frame was a frame start that never closed
            self.bad_frames += buffer.count(b"(", end, frame.start())
            end = frame.end()
            numbers = _SIX_NUMBERS.fullmatch(frame.group(1))
            if numbers is None or end - frame.start() > MAX_FRAME_BYTES:
                self.bad_frames += 1
                continue
            samples.append(np.array([float(x) for x in numbers.groups()]))
        self.frames += len(samples)
        start = buffer.rfind(b"(", end)
        if start < 0:
            self._pending = b""
            return samples
        self.bad_frames += buffer.count(b"(", end, start)
        if len(buffer) - start > MAX_FRAME_BYTES:
            self.bad_frames += 1
            self._pending = b""
        else:
            self._pending = buffer[start:]
        return samples


def encode_sample(values: Sequence[float] | Vec) -> bytes:
    """One sample in the daemon's format: forces to 2 decimals, torques to 3; `nan`, `inf`, `-inf`.

    e.g. `b"( -0.39 , 1.46 , -1.25 , 0.007 , -0.011 , 0.002 )"`.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size != 6:
        raise ConfigError(
            f"encode_sample: expected 6 values (Fx, Fy, Fz, Mx, My, Mz), got {v.size}"
        )
    # Python formats non-finite floats as nan, inf, -inf whatever the precision
    fields = [f"{x:.2f}" for x in v[:3]] + [f"{x:.3f}" for x in v[3:]]
    return ("( " + " , ".join(fields) + " )").encode("ascii")


class FT150Stream:
    """The FT-150 stream port read by a thread of its own, every sample published into a mailbox.

    `start()` starts a `ReaderThread` that connects (within `CONNECT_TIMEOUT_S`), reads with a
    `timeout_s` socket timeout (so it sees `stop()` promptly), parses and publishes each sample as
    `Sample(values, received_s=now())`; bad frames go to `mailbox.count_bad`. When the connection is
    lost it records why in `mailbox.error`, waits `retry_s` and connects again (`reconnect=False`: it
    gives up). Each connection gets a fresh parser, so half a sample left by the old connection is
    never glued to the new one's bytes; it counts as one bad frame.

    The stream carries no time stamps: `received_s` is the host's receipt time, taken once per read.
    Samples that arrive together in one read share it; that is acceptable, since the control loop
    reads the latest sample and the counter, not the spacing of samples within a read.

    The daemon serves one client at a time: a second client's connection is accepted by the kernel
    but gets no bytes, which looks like a stalled stream (no samples, no error). A stream starts
    once; make a new one to start again. Usable as a context manager (start, then stop on exit).
    """

    rate_band_hz = (50.0, 250.0)
    """Packet rates a rebias accepts: the sensor has been seen at 62.5, 100 and 200 Hz (notes,
    seed 3.B: a packet every 5 ms), with a fifth to spare."""

    def __init__(
        self,
        host: str,
        port: int = STREAM_PORT,
        *,
        mailbox: Mailbox | None = None,
        reconnect: bool = True,
        retry_s: float = 0.5,
        timeout_s: float = 0.2,
    ) -> None:
        self.host = host
        self.port = int(port)
        self.timeout_s = as_scalar(timeout_s, "timeout_s", low=0.0, low_open=True)
        retry_s = as_scalar(retry_s, "retry_s", low=0.0)
        self._mailbox = mailbox if mailbox is not None else Mailbox()
        self._parser = FT150Parser()
        self._sock: socket.socket | None = None
        self._sock_lock = threading.Lock()  # the reader opens the socket, stop() may close it
        self._reader = ReaderThread(
            f"FT-150 reader {self.host}:{self.port}",
            self._mailbox,
            self._connect,
            self._read,
            self._handle,
            self._close,
            reconnect=reconnect,
            retry_s=retry_s,
        )

    @property
    def mailbox(self) -> Mailbox:
        return self._mailbox

    @property
    def connected(self) -> bool:
        """True while the reader holds a connection."""
        return self._reader.connected.is_set()

    def describe(self) -> str:
        return f"FT-150 stream at {self.host}:{self.port}"

    def start(self) -> None:
        if self._reader.ident is not None:
            raise RunError(f"{self.describe()}: already started; a stream starts once")
        self._reader.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop the reader and close the connection; returns when the thread has ended (or after
        `timeout_s`). A stream that never started is left as it is."""
        if self._reader.ident is not None:
            self._reader.stop(timeout_s)

    def __enter__(self) -> FT150Stream:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # the transport, called by the reader thread (and `_close` by `stop()` too)

    def _connect(self) -> None:
        if self._parser.pending:
            self._mailbox.count_bad(1)  # the old connection ended inside a sample
        self._parser = FT150Parser()
        sock = socket.create_connection((self.host, self.port), timeout=CONNECT_TIMEOUT_S)
        sock.settimeout(self.timeout_s)
        with self._sock_lock:
            self._sock = sock

    def _read(self) -> bytes | None:
        sock = self._sock
        if sock is None:
            raise ConnectionError("the connection was closed")
        try:
            return sock.recv(_RECV_BYTES)
        except TimeoutError:
            return None

    def _handle(self, data: bytes) -> None:
        received_s = now()
        parser = self._parser
        bad_before = parser.bad_frames
        for values in parser.feed(data):
            self._mailbox.publish(Sample(values, received_s=received_s))
        self._mailbox.count_bad(parser.bad_frames - bad_before)

    def _close(self) -> None:
        with self._sock_lock:
            sock, self._sock = self._sock, None
        if sock is not None:
            # shutdown wakes a reader blocked in recv at once; close alone may not
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            sock.close()


def zero_sensor(host: str, port: int = COMMAND_PORT, timeout_s: float = 2.0) -> None:
    """Make the daemon zero the sensor against its next sample: send `ZERO_COMMAND` to port 63350.

    Framing: `SET ZRO` with no line ending in one send, the connection held open `ZERO_HOLD_S`,
    then closed, as the URCap's own `rq_set_zero()` script function does. Robotiq's BSD-licensed
    socket driver for the same two ports (`rq_sensor_socket.c` and its `main.c`, 2014) explains the
    hold: its accessor thread stores each `recv` (up to 511 bytes) as the message, and an end of
    connection stores an empty one; its main loop looks at the message once per sensor sample and
    zeroes when `strstr(message, "SET ZRO")` matches (so a line ending would do no harm there). A
    client that closes at once can have its command erased before the main loop sees it.

    Not confirmed: that the URCap's daemon (closed source, on the controller) behaves like that
    driver; whether it would accept a line ending; how soon zeroed samples appear on the stream.
    The daemon answers nothing, so success cannot be seen here. The command port, too, serves one
    client at a time: while another client holds it, our bytes wait unread in the kernel and the
    sensor is not zeroed, with no error. Check the stream after zeroing, or zero on our side by
    averaging.

    Raises `RunError` (one line naming host:port and the reason) if it cannot connect or send.
    """
    timeout_s = as_scalar(timeout_s, "timeout_s", low=0.0, low_open=True)
    try:
        with socket.create_connection((host, port), timeout=timeout_s) as sock:
            sock.sendall(ZERO_COMMAND)
            time.sleep(ZERO_HOLD_S)
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise RunError(
            f"FT-150 command port {host}:{port}: cannot send {ZERO_COMMAND.decode()}: {reason}"
        ) from None
