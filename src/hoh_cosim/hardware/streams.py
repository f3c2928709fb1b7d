"""What the sensor drivers share: samples, the latest-sample mailbox, statistics, reader threads.

A driver is a pure parser (bytes in, samples out, never blocking, never raising on bad bytes) plus a
thin transport (a socket or a serial port) read by a thread of its own. The thread publishes every
sample into a `Mailbox`; the control loop takes the latest sample and a counter that grows with every
sample, so it never waits for I/O and the estimator can tell a new packet from an old one (its
`ft_counter` / `probe_counter` inputs).

Time stamps are `time.monotonic()` at receipt: the FT-150 stream carries none, and the FSE103's own
millisecond counter is kept beside it (`device_ms`) but never mixed with host time.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from hoh_cosim.control.vectors import Vec

__all__ = ["Mailbox", "RateCheck", "ReaderThread", "Sample", "StreamStats", "now", "robust_period"]


@dataclass(frozen=True)
class Sample:
    """One reading: `values` in SI units (N, N·m), received at `received_s` (monotonic clock)."""

    values: Vec
    received_s: float
    device_ms: int | None = None  # the device's own time stamp, where it sends one


@dataclass
class StreamStats:
    """Counts and timing of one stream, for diagnostics and the end-of-session report."""

    frames: int = 0
    bad_frames: int = 0
    nonfinite: int = 0  # samples with a NaN or an infinity (kept out of mean and std)
    bytes: int = 0
    last_bytes_s: float = math.nan  # when the last read that brought bytes returned (monotonic)
    losses: int = 0  # failures: connections lost, devices gone, attempts refused
    reconnects: int = 0  # successful connections after the first
    first_s: float = math.nan
    last_s: float = math.nan
    sums: Vec = field(default_factory=lambda: np.zeros(0))
    sums_sq: Vec = field(default_factory=lambda: np.zeros(0))

    def add(self, sample: Sample) -> None:
        if self.frames == 0:
            self.first_s = sample.received_s
            self.sums = np.zeros_like(sample.values)
            self.sums_sq = np.zeros_like(sample.values)
        self.frames += 1
        self.last_s = sample.received_s
        if np.all(np.isfinite(sample.values)):
            self.sums += sample.values
            self.sums_sq += sample.values * sample.values
        else:
            self.nonfinite += 1

    @property
    def rate_hz(self) -> float:
        """Samples per second between the first and the last (NaN with fewer than two)."""
        if self.frames < 2 or self.last_s <= self.first_s:
            return math.nan
        return (self.frames - 1) / (self.last_s - self.first_s)

    @property
    def mean(self) -> Vec:
        """Mean of the finite samples."""
        n = self.frames - self.nonfinite
        return self.sums / n if n else np.full_like(self.sums, math.nan)

    @property
    def std(self) -> Vec:
        """Sample standard deviation of the finite samples."""
        n = self.frames - self.nonfinite
        if n < 2:
            return np.full_like(self.sums, math.nan)
        mean = self.sums / n
        variance = (self.sums_sq - n * mean * mean) / (n - 1)
        return np.sqrt(np.maximum(variance, 0.0))


class Mailbox:
    """The latest sample of one stream and how many have arrived; safe across threads."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._latest: Sample | None = None
        self._count = 0
        self.stats = StreamStats()
        self.error: str | None = None  # why the stream is down, while it is
        self.last_error: str | None = None  # the latest reason it went down, kept after recovery
        self._bytes_at_latest = 0  # stats.bytes and stats.bad_frames when the latest sample came
        self._bad_at_latest = 0

    def received(self, n: int) -> None:
        """Count `n` bytes the reader has just read (before it parses them)."""
        with self._lock:
            self.stats.bytes += n
            self.stats.last_bytes_s = now()

    def publish(self, sample: Sample) -> None:
        with self._lock:
            self._latest = sample
            self._count += 1
            self.stats.add(sample)
            self._bytes_at_latest = self.stats.bytes
            self._bad_at_latest = self.stats.bad_frames

    def since_latest(self, t: float) -> str:
        """What the reader got after the read that brought the latest sample, at time `t`
        (monotonic): for a stream gone quiet, whether its bytes stopped (the device, the line, the
        kernel's delivery) or came and made no sample (the framing, garbage)."""
        with self._lock:
            n = self.stats.bytes - self._bytes_at_latest
            bad = self.stats.bad_frames - self._bad_at_latest
            last = self.stats.last_bytes_s
        if n == 0:
            return "no byte read since its last sample"
        return (
            f"{n} bytes read since its last sample, the last {1e3 * (t - last):.0f} ms ago, "
            f"{bad} bad frames"
        )

    def latest(self) -> tuple[Sample | None, int]:
        """(the newest sample or None, how many samples have arrived so far)."""
        with self._lock:
            return self._latest, self._count

    def count_bad(self, n: int) -> None:
        if n:
            with self._lock:
                self.stats.bad_frames += n

    def set_error(self, error: str | None) -> None:
        with self._lock:
            self.error = error
            if error is not None:
                self.last_error = error
                self.stats.losses += 1


class ReaderThread(threading.Thread):
    """Reads a transport until stopped: `connect()` opens it, `read()` returns bytes (b"" when the
    other side closed, None when nothing came within its timeout), `handle(data)` parses and
    publishes. On a failure it records the reason in
    the mailbox, closes, waits `retry_s` and connects again (`reconnect=False`: it gives up)."""

    def __init__(
        self,
        name: str,
        mailbox: Mailbox,
        connect: Callable[[], None],
        read: Callable[[], bytes | None],
        handle: Callable[[bytes], None],
        close: Callable[[], None],
        *,
        reconnect: bool = True,
        retry_s: float = 0.5,
    ) -> None:
        super().__init__(name=name, daemon=True)
        self.mailbox = mailbox
        self._connect, self._read, self._handle, self._close = connect, read, handle, close
        self.reconnect = reconnect
        self.retry_s = retry_s
        self._halt = threading.Event()
        self.connected = threading.Event()

    def stop(self, timeout: float = 2.0) -> None:
        self._halt.set()
        self._close_quietly()
        if self.is_alive() and threading.current_thread() is not self:
            self.join(timeout)

    def _close_quietly(self) -> None:
        with contextlib.suppress(OSError):
            self._close()

    def run(self) -> None:
        connected_before = False
        while not self._halt.is_set():
            try:
                self._connect()
                if connected_before:
                    self.mailbox.stats.reconnects += 1
                connected_before = True
                self.connected.set()
                self.mailbox.set_error(None)
                while not self._halt.is_set():
                    data = self._read()
                    if data is None:  # nothing yet (a read timeout): look at the stop flag again
                        continue
                    if not data:
                        raise ConnectionError("the device closed the connection")
                    self.mailbox.received(len(data))
                    self._handle(data)
            except Exception as exc:  # a reader must never die silently: say why, then retry
                if self._halt.is_set():
                    break
                self.connected.clear()
                self.mailbox.set_error(f"{type(exc).__name__}: {exc}".rstrip(": "))
                self._close_quietly()
                if not self.reconnect:
                    break
                self._halt.wait(self.retry_s)
        self.connected.clear()
        self._close_quietly()


def robust_period(counts: Sequence[int], times_s: Sequence[float]) -> float:
    """A stream's packet period [s] from (sample count, time) pairs, as its sender kept it.

    A sample can reach us late (a stall: the machine busy, a kernel worker starved, a buffer), never
    early. So the sender's schedule is the line under the points, not through them: the lower
    convex hull of (count, time), whose chord across the middle half of the window gives the
    period. A stall
    followed by a burst, or by a backlog drained one sample per cycle, only lifts points above
    that line (the median spacing of receipt times took such a drain for a 500 Hz stream; a
    regression through the points is pulled by it as well). NaN with fewer than 3 points.
    """
    n = len(counts)
    if n < 3 or len(times_s) != n:
        return math.nan
    x = np.asarray(counts, dtype=float)
    y = np.asarray(times_s, dtype=float)
    if not (np.all(np.isfinite(y)) and np.all(np.diff(x) > 0)):
        return math.nan
    hull: list[int] = []  # Andrew's monotone chain, lower half
    for i in range(n):
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            if (x[b] - x[a]) * (y[i] - y[a]) - (y[b] - y[a]) * (x[i] - x[a]) > 0:
                break  # a left turn: b stays on the lower hull
            hull.pop()
        hull.append(i)
    # the hull's chord from its last corner in the first quarter to its first in the last
    # quarter: at least half the window long, so the small delays of those two least-delayed
    # samples move it by little (a single edge over the middle can be two samples short)
    span = x[-1] - x[0]
    a = max(i for i in hull if x[i] <= x[0] + 0.25 * span)
    b = min(i for i in hull if x[i] >= x[-1] - 0.25 * span)
    return float((y[b] - y[a]) / (x[b] - x[a]))


@dataclass(frozen=True)
class RateCheck:
    """A stream's measured rate against the rates its datasheet (and the seed's rig) allow."""

    name: str
    period_s: float  # measured; NaN: too few samples to tell (the configured period stands)
    band_hz: tuple[float, float]
    clock: str  # what the times were: "device time stamps" or "receipt times"

    @property
    def rate_hz(self) -> float:
        return 1.0 / self.period_s if self.period_s > 0 else math.nan

    def problem(self) -> str | None:
        """Why the rate cannot be handed to the filters, or None (also when unmeasured)."""
        low, high = self.band_hz
        if math.isnan(self.period_s):
            return None
        if not low <= self.rate_hz <= high:
            return (
                f"{self.name} measured at {self.rate_hz:.1f} Hz ({self.clock}), outside the "
                f"{low:g}-{high:g} Hz its datasheet allows: a stream that stalls and bursts, or "
                "another device"
            )
        return None


def now() -> float:
    """The receipt clock."""
    return time.monotonic()
