"""A bounded feed of the runner's cycles to a process of its own (the live view), which never costs
the robot a cycle.

    runner, every cycle        offer(record, row): one due every `1/rate_hz` of session time is
                               copied into a ring of `capacity` rows in shared memory and counted;
                               the others return at once
    the consumer's process     takes the rows written since it last looked (`FeedReader.take`);
                               when it fell more than a ring behind, the oldest were overwritten:
                               dropped and counted, never waited for

A due cycle costs the loop one copy of its row (the session log's `CycleRow` layout, which the log
has just filled: no encoding, no lock, no system call, no thread of the loop's process woken); a
consumer that is slow, stopped, or serving a viewer nobody opened changes nothing on the loop's
side. (The session log hands its rows to its writer the same way; its writer must not lose one, so
its ring is large; the view's is small and drops.) The runner's events (the rebias, the mode's
announcements, a stop's cause) go through a bounded queue, put without waiting, dropped when full.

The consumer is a function `consumer(reader, *args)`, given by whoever starts the feed (the command
line gives the view's, `hoh_cosim.view.session`: this package never imports it), run in a spawned
process scheduled only when a core is idle (SCHED_IDLE; elsewhere nice 10) that ignores Ctrl-C (the
terminal's SIGINT reaches the whole process group; the session ends it) and ends when told or when the process that started it is gone. It says
`reader.ready(text)` once it can take rows (or `reader.refuse(text)`), which `RowFeed.start` waits
for: a port in use is refused before anything runs.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import queue
import signal
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.hardware.session_log import ROW_SIZE, CycleRow

if TYPE_CHECKING:
    from hoh_cosim.hardware.session_log import CycleRecord

__all__ = ["CycleObserver", "FeedReader", "RowFeed"]


class CycleObserver(Protocol):
    """What the runner tells an observer of its cycles; neither call may block or take long."""

    def offer(self, record: CycleRecord, row: CycleRow | None = None) -> None:
        """One cycle (`row`: the log's row of it, already filled, if there is a log)."""

    def event(self, k: int, t: float, event: str, detail: str) -> None:
        """One of the session log's events."""


_READY, _REFUSED, _FAILED, _FINISHED = "ready", "refused", "failed", "finished"


class FeedReader:
    """The consumer's side of a `RowFeed`, in the consumer's process."""

    def __init__(
        self,
        ring: Any,
        written: Any,
        capacity: int,
        events: Any,
        end: Any,
        stop: Any,
        replies: Any,
        parent: int,
    ) -> None:
        self._rows = np.frombuffer(ring, dtype=np.float64).reshape(capacity, ROW_SIZE)
        self._written = written
        self.capacity = capacity
        self._events = events
        self._end = end
        self._stop = stop
        self._replies = replies
        self._parent = parent
        self._done = 0  # rows delivered or dropped
        self.received = 0
        self.dropped = 0

    # --- replies to the process that started the feed -------------------------------------------

    def ready(self, text: str = "") -> None:
        """The consumer takes rows now; `text` is `RowFeed.start`'s result (e.g. an address)."""
        self._replies.put((_READY, text))

    def refuse(self, text: str) -> None:
        """The consumer cannot start because of its input (a port in use): one line."""
        self._replies.put((_REFUSED, text))

    def fail(self, text: str) -> None:
        """The consumer failed."""
        self._replies.put((_FAILED, text))

    def finished(self, text: str = "") -> None:
        """Everything the runner handed over is done with (e.g. a recording written)."""
        self._replies.put((_FINISHED, text))

    # --- rows and events -----------------------------------------------------------------------

    @property
    def orphaned(self) -> bool:
        return os.getppid() != self._parent

    @property
    def ending(self) -> bool:
        """Told to stop, or the runner's side is done (or gone) and every row it wrote has been
        taken."""
        if self._stop.is_set():
            return True
        return (self._end.is_set() or self.orphaned) and self._done >= self._written.value

    @property
    def abandoned(self) -> bool:
        """Told to stop before the runner's side said it was done: what was made is dropped."""
        return self._stop.is_set() and not self._end.is_set()

    def take(self, timeout_s: float = 0.1) -> np.ndarray:
        """The rows (n, ROW_SIZE) written since the last call, waiting up to `timeout_s` for one;
        rows overwritten before they were taken are counted in `dropped`."""
        deadline = time.monotonic() + timeout_s
        while (
            self._written.value <= self._done
            and not (self._end.is_set() or self.orphaned)
            and time.monotonic() < deadline
        ):
            time.sleep(0.005)
        # The producer writes row n into slot n % capacity, then counts it: while it may still
        # write, rows from head - capacity + 1 on are intact; copy them, then look again, since
        # whatever it reached meanwhile may have overwritten the oldest of the copies (the session
        # log's writer reads its ring alike).
        margin = 0 if self._end.is_set() else 1
        head = self._written.value
        first = max(self._done, head - self.capacity + margin)
        block = self._rows[np.arange(first, head) % self.capacity].copy()
        intact = min(head, max(first, self._written.value - self.capacity + margin))
        self.dropped += intact - self._done
        self._done = head
        taken = block[intact - first :]
        self.received += len(taken)
        return taken

    def pause(self, seconds: float) -> None:
        """Sleep `seconds`, or less if the runner's side says it is done or told to stop: a
        consumer that takes rows in blocks wakes a few times a second, not at every row."""
        if not self._stop.is_set():
            self._end.wait(seconds)

    def events(self) -> list[tuple[int, float, str, str]]:
        """The events put since the last call."""
        out = []
        while True:
            try:
                out.append(self._events.get_nowait())
            except (queue.Empty, OSError, ValueError):
                return out

    def wait_stop(self) -> None:
        """Wait until told to stop, or until the process that started the feed is gone."""
        while not self._stop.wait(0.2) and not self.orphaned:
            pass


def _feed_main(consumer: Callable[..., None], channels: tuple[Any, ...], args: tuple) -> None:
    """The consumer's process."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # the loop and the devices come first: the consumer runs only on a core nothing else wants
    # (SCHED_IDLE, Linux), else at nice 10
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (OSError, AttributeError):
        with contextlib.suppress(OSError):
            os.nice(10)
    reader = FeedReader(*channels)
    try:
        consumer(reader, *args)
    except BaseException as exc:
        reader.fail(f"{type(exc).__name__}: {exc}")
        raise


class RowFeed:
    """The runner's side of the feed (`CycleObserver`): started by the caller before the session,
    offered every cycle by the runner, finished and closed by the caller after it."""

    def __init__(
        self,
        consumer: Callable[..., None],
        args: tuple = (),
        *,
        rate_hz: float = 50.0,
        capacity: int = 256,
    ) -> None:
        self.consumer, self.args = consumer, args
        self.every_s = 1.0 / rate_hz
        self.capacity = capacity
        self._context = mp.get_context("spawn")
        self._process: Any = None
        self._row = CycleRow()
        self._due_s = -np.inf
        self._n = 0  # rows written
        self.events_dropped = 0

    def start(self, timeout_s: float = 60.0) -> str:
        """Start the consumer and wait until it takes rows: its `ready` text. A refusal is a
        `ConfigError` (one line, before the session), a failure a `RunError`."""
        ctx = self._context
        self._ring = ctx.RawArray("d", self.capacity * ROW_SIZE)
        self._rows = np.frombuffer(self._ring, dtype=np.float64).reshape(self.capacity, ROW_SIZE)
        self._written = ctx.RawValue("q", 0)
        self._events = ctx.Queue(maxsize=64)
        self._end, self._stop = ctx.Event(), ctx.Event()
        self._replies = ctx.Queue()
        channels = (
            self._ring,
            self._written,
            self.capacity,
            self._events,
            self._end,
            self._stop,
            self._replies,
            os.getpid(),
        )
        self._process = ctx.Process(
            target=_feed_main,
            args=(self.consumer, channels, self.args),
            name="cycle-feed",
            daemon=True,
        )
        self._process.start()
        kind, text = self._reply(timeout_s, "start")
        if kind != _READY:
            self.close()
            raise (ConfigError if kind == _REFUSED else RunError)(text)
        return text

    def _reply(self, timeout_s: float, what: str) -> tuple[str, str]:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                return self._replies.get(timeout=0.2)
            except queue.Empty:
                if not self._process.is_alive():
                    return _FAILED, f"the feed's process ended before it would {what}"
        return _FAILED, f"the feed's process did not {what} within {timeout_s:g} s"

    def offer(self, record: CycleRecord, row: CycleRow | None = None) -> None:
        """The runner's cycle: copied if one is due (`row`, if the log filled it; else filled
        here), otherwise nothing."""
        if record.t < self._due_s:
            return
        self._due_s = record.t + self.every_s - 1e-9
        if row is None:
            record.fill(self._row)
            row = self._row
        n = self._n
        self._rows[n % self.capacity] = row.values
        self._n = n + 1
        self._written.value = n + 1

    def event(self, k: int, t: float, event: str, detail: str) -> None:
        try:
            self._events.put_nowait((k, t, event, detail))
        except queue.Full:
            self.events_dropped += 1

    @property
    def written(self) -> int:
        """Rows handed over so far."""
        return self._n

    def finish(self, timeout_s: float = 60.0) -> str:
        """No more rows: let the consumer take the rest and finish (its `finished` text)."""
        if self._process is None:
            return ""
        self._end.set()
        kind, text = self._reply(timeout_s, "finish")
        if kind == _FAILED:
            raise RunError(text)
        return text

    def close(self) -> None:
        """Stop the consumer (a live view ends); before `finish`, what it made is abandoned."""
        if self._process is None:
            return
        self._stop.set()
        self._process.join(10.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join(5.0)
        self._process = None
        # released now: a session's process ends with os._exit (hardware.isolation), which runs
        # no finalizer, and multiprocessing's resource tracker would report them leaked
        for channel in (self._events, self._replies):
            channel.close()
            channel.join_thread()
        del self._events, self._replies, self._end, self._stop, self._rows, self._ring
