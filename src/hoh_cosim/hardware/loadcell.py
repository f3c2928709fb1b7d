"""The Honeywell Model 31 load cell on the probe, read from its Arduino Uno over USB serial.

The line format (ours: the seed's Arduino sent "a serial string", section 3.B.2, and its sketch is
not given). One ASCII line per reading, at 115200 baud, 8N1:

    LC,<ms>,<count>\\r\\n          e.g.  LC,48213,348\\r\\n

- `LC`: the device's tag, so that another device on the port (an FSE103, a modem, a console) is
  told apart from a load cell at its first lines;
- `<ms>`: the Uno's `millis()` when the ADC was read, decimal, a uint32 that wraps after 49.7 days
  (as the FSE103's time stamp): the rate is measured on the device's clock, and a lost line shows
  as a step of two periods;
- `<count>`: the ADC's reading, decimal, 0 to 1023 (ATmega328P: 10 bits, V_ref = AVcc = 5 V);
- `\\r\\n`: Arduino's `Serial.println`. A bare `\\n` is accepted too.

The rate, 200 lines a second. The Uno's ADC converts in 13 ADC clocks at 16 MHz / 128 = 125 kHz,
104 µs (ATmega328P data sheet, section 24), so the ADC would allow 9.6 kHz. The line limits it
first: the longest line is 20 bytes, 200 bits at 8N1, 1.74 ms at 115200 baud, at most 575 lines a
second. At 200 Hz (a timer tick every 5 ms) the line is 35 % busy, the 64-byte transmit buffer of
the Uno's serial port holds three lines (a late host never stalls the sketch), and the probe force
arrives at the FT-150's own rate (the seed's 200 Hz), which is what eq. 11-12 subtract it from.

`LoadCellParser` is pure (bytes in, readings out, never blocking, never raising on bad bytes);
`LoadCellPort` reads it from a serial port (the transport is `SerialSource`, the FSE103's) and
publishes each reading as a `LoadCellSample`: the force in the cell's frame L, (0, 0,
-compression) [N] (`hoh_cosim.control.loadcell`: counts to newtons and why the sign), the
Arduino's milliseconds and the raw count. `latest_count` holds the newest count too.

A device that sends lines, but not a load cell's, or bytes that are not lines at all (the port at
another baud rate than the device's: each byte is read from bits of two or three bytes sent, most
of them outside ASCII), is named in one line in `mailbox.error`, with what was expected and what
arrived, once LOCK_LINES lines went by without a good one; the runner's start then fails with it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from hoh_cosim.control.loadcell import (
    ADC_COUNTS,
    BAUDRATE,
    LINE_RATE_HZ,
    SEED_CHAIN,
    LoadCellChain,
    force_L,
)
from hoh_cosim.hardware.serial_source import SerialSource
from hoh_cosim.hardware.streams import Sample, now

__all__ = [
    "LINE_FORMAT",
    "LOCK_LINES",
    "MAX_LINE_BYTES",
    "LoadCellLine",
    "LoadCellParser",
    "LoadCellPort",
    "LoadCellSample",
    "encode_line",
]

LINE_FORMAT = "LC,<ms>,<count>"
MAX_LINE_BYTES = 64
"""A line longer than this (ours are at most 20 bytes with the \\r\\n) is garbage: it counts a bad
line every MAX_LINE_BYTES and the parser keeps no more than that."""
LOCK_LINES = 3
"""Bad lines in a row, with no good one since the start, after which the port says what arrived."""
_LINE = re.compile(rb"^LC,(\d{1,10}),(\d{1,4})\r?$")
_WRAP = 2**32


@dataclass(frozen=True)
class LoadCellLine:
    """One good line: the ADC's count and the Arduino's milliseconds (a wrapping uint32)."""

    count: int
    device_ms: int


@dataclass(frozen=True)
class LoadCellSample(Sample):
    """A load cell's reading: `values` the force in L [N], with the raw ADC count it came from."""

    count: int = -1


def encode_line(count: int, device_ms: int) -> bytes:
    """One line as the Arduino sends it, for emulators and tests (the count clipped to 0..1023,
    the milliseconds wrapped modulo 2**32)."""
    count = min(max(int(count), 0), ADC_COUNTS - 1)
    return b"LC,%d,%d\r\n" % (int(device_ms) % _WRAP, count)


def _printable(byte: int) -> bool:
    return 0x20 <= byte < 0x7F or byte in (0x0D, 0x0A)


class LoadCellParser:
    """Readings from the load cell's byte stream, whatever the chunking: `feed` bytes, get lines.

    A line ends at `\\n`. It is good when it reads `LC,<ms>,<count>` (an optional `\\r` before the
    `\\n`), ms below 2**32 and count below 1024; anything else between two `\\n` is one bad line,
    and so is every MAX_LINE_BYTES without a `\\n` (garbage, or the port at another baud rate), so
    the parser is back in step at the first `\\n` after garbage and keeps at most MAX_LINE_BYTES
    between calls. The bytes before the first `\\n` are a line begun before we listened: bad
    unless they make a whole good line. `bad_lines` and `good_lines` only grow; `bad_run` counts
    the bad lines since the last good one, `last_bad` keeps the latest (its first 40 bytes) and
    `text_share` the share of its bytes that are printable ASCII, which tells a device that speaks
    another language from a line read at the wrong baud rate.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.good_lines = 0
        self.bad_lines = 0
        self.bad_run = 0
        self.last_bad = b""
        self._cut = False  # inside a line longer than MAX_LINE_BYTES

    @property
    def pending_bytes(self) -> int:
        return len(self._buf)

    def reset(self) -> None:
        """Forget the pending bytes (after a reconnection); the counts are kept."""
        self._buf.clear()
        self._cut = False

    @property
    def text_share(self) -> float:
        """The share of printable ASCII (and CR, LF) in the latest bad line (1 with none)."""
        if not self.last_bad:
            return 1.0
        return sum(map(_printable, self.last_bad)) / len(self.last_bad)

    def feed(self, data: bytes | bytearray | memoryview) -> list[LoadCellLine]:
        """The good lines completed by `data`, in order; a partial line is kept for the next call."""
        buf = self._buf
        buf += data
        lines: list[LoadCellLine] = []
        start = 0
        while True:
            end = buf.find(b"\n", start, start + MAX_LINE_BYTES + 1)
            if end < 0:
                if len(buf) - start > MAX_LINE_BYTES:  # no line end where one must be
                    self._bad(bytes(buf[start : start + MAX_LINE_BYTES]))
                    self._cut = True
                    start += MAX_LINE_BYTES
                    continue
                break
            if self._cut:  # the rest of a line cut before: bad, and its start is what it showed
                self._bad(b"")
            else:
                line = self._parse(bytes(buf[start:end]))
                if line is not None:
                    lines.append(line)
            self._cut = False
            start = end + 1
        del buf[:start]
        return lines

    def _parse(self, text: bytes) -> LoadCellLine | None:
        match = _LINE.match(text)
        if match is not None:
            ms, count = int(match[1]), int(match[2])
            if ms < _WRAP and count < ADC_COUNTS:
                self.good_lines += 1
                self.bad_run = 0
                return LoadCellLine(count, ms)
        self._bad(text)
        return None

    def _bad(self, text: bytes) -> None:
        self.bad_lines += 1
        self.bad_run += 1
        if not self._cut:  # the start of a line cut in pieces is kept, not its later pieces
            self.last_bad = text[:40]

    def diagnosis(self, device: str, baudrate: int) -> str | None:
        """One line on what arrives instead of a load cell's lines, or None while nothing says so
        (a good line came, or fewer than LOCK_LINES bad ones since the start or the last good)."""
        if self.bad_run < LOCK_LINES:
            return None
        shown = self.last_bad.rstrip(b"\r")[:24]
        expected = f"expected lines '{LINE_FORMAT}' at {baudrate} baud"
        if self.text_share < 0.75:
            return (
                f"load cell on {device}: {expected}, got bytes that are not text "
                f"({shown!r}): the device's baud rate is another, or it is not a load cell"
            )
        text = shown.decode("ascii", "backslashreplace")
        return (
            f"load cell on {device}: {expected}, got {text!r}: the device on the port is not a "
            "load cell (its line format is another)"
        )


class LoadCellPort(SerialSource):
    """The load cell's Arduino on a serial port (or a pyserial URL), read by a thread.

    As `FSE103Port` (`SerialSource`: start, stop, reconnection, `mailbox.error`): each good line is
    published as `LoadCellSample(force_L(chain.newtons(count)), received_s=now(), device_ms=ms,
    count=count)`, bad lines go to `mailbox.count_bad`, and `latest_count` is the newest count
    (None before the first). While only bad lines arrive, `mailbox.error` says what they were
    (`LoadCellParser.diagnosis`).
    """

    rate_band_hz = (0.8 * LINE_RATE_HZ, 1.2 * LINE_RATE_HZ)
    """Line rates a rebias accepts: the sketch's 200 Hz, a fifth either side (on the Arduino's own
    milliseconds: only another sketch is that far off)."""

    def __init__(self, device: str, *, chain: LoadCellChain = SEED_CHAIN, **transport: Any) -> None:
        """`transport`: `SerialSource`'s baudrate (BAUDRATE), mailbox, reconnect, retry_s,
        timeout_s."""
        super().__init__(device, **{"baudrate": BAUDRATE, **transport})
        self.chain = chain
        self._parser = LoadCellParser()
        self._bad_reported = 0
        self._diagnosed: str | None = None
        self.latest_count: int | None = None

    @property
    def parser(self) -> LoadCellParser:
        return self._parser

    def describe(self) -> str:
        return f"load cell on {self.device}"

    def _handle(self, data: bytes) -> None:
        parser = self._parser
        lines = parser.feed(data)
        self._mailbox.count_bad(parser.bad_lines - self._bad_reported)
        self._bad_reported = parser.bad_lines
        for line in lines:
            self.latest_count = line.count
            self._mailbox.publish(
                LoadCellSample(
                    force_L(self.chain.newtons(line.count)),
                    received_s=now(),
                    device_ms=line.device_ms,
                    count=line.count,
                )
            )
        diagnosis = parser.diagnosis(self.device, self.baudrate)
        if diagnosis != self._diagnosed:
            self._diagnosed = diagnosis
            self._mailbox.set_error(diagnosis)
