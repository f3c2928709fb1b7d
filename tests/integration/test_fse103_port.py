"""The FSE103 serial port on real pseudo-terminals: frames, the zero command, unplugging, reconnecting.

Each test opens a pty pair, puts both ends in raw mode (otherwise the line discipline turns 0x0D
into 0x0A) and plays the sensor on the master side from a thread; the port opens the slave by name.
Closing the master is an unplug. A port that retries after an unplug opens a symbolic link in
tmp_path, pointed away from the dead pty: the kernel hands a freed /dev/pts number to the next pty
opened on this machine, and the test must not read someone else's terminal.
"""

from __future__ import annotations

import contextlib
import os
import re
import select
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.hardware.fse103 import FSE103Port, encode_frame
from hoh_cosim.hardware.streams import Mailbox, Sample

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs POSIX pseudo-terminals")
pytest.importorskip("serial")

import pty  # noqa: E402  (POSIX only)
import tty  # noqa: E402

T0_MS = 5000
STEP_MS = 10


@dataclass
class Pty:
    master: int
    slave: int
    name: str
    open: bool = True

    def unplug(self) -> None:
        if self.open:
            self.open = False
            os.close(self.master)
            os.close(self.slave)


@contextlib.contextmanager
def open_pty() -> Iterator[Pty]:
    master, slave = pty.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    p = Pty(master, slave, os.ttyname(slave))
    try:
        yield p
    finally:
        p.unplug()


def forces(k: int) -> list[float]:
    return [float(k), -0.5, 2.0]  # Fx carries the frame number


class Sensor(threading.Thread):
    """The FSE103 on the master side: frame k has forces(k) and time stamp T0_MS + k·STEP_MS;
    `garbage` is written once, before frame `garbage_at`."""

    def __init__(
        self,
        fd: int,
        framing: str,
        byte_order: str,
        *,
        rate_hz: float = 100.0,
        garbage_at: int = -1,
        garbage: bytes = b"",
    ) -> None:
        super().__init__(daemon=True)
        self.fd, self.framing, self.byte_order = fd, framing, byte_order
        self.period_s = 1.0 / rate_hz
        self.garbage_at, self.garbage = garbage_at, garbage
        self.sent = 0
        self._halt = threading.Event()

    def run(self) -> None:
        due = time.monotonic()
        k = 0
        while not self._halt.is_set():
            frame = encode_frame(
                forces(k), T0_MS + k * STEP_MS, framing=self.framing, byte_order=self.byte_order
            )
            try:
                if k == self.garbage_at:
                    os.write(self.fd, self.garbage)
                os.write(self.fd, frame)
            except OSError:
                return
            k += 1
            self.sent = k
            due += self.period_s
            self._halt.wait(max(0.0, due - time.monotonic()))

    def halt(self) -> None:
        self._halt.set()
        self.join(1.0)


@contextlib.contextmanager
def running(*threads: Sensor | FSE103Port) -> Iterator[None]:
    for t in threads:
        t.start()
    try:
        yield
    finally:
        for t in reversed(threads):
            if isinstance(t, FSE103Port):
                t.stop()
            else:
                t.halt()


def wait_for(condition: Callable[[], bool], timeout_s: float = 1.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.002)
    return condition()


def watch(mailbox: Mailbox, count: int, timeout_s: float = 1.0) -> list[tuple[int, Sample]]:
    """Every (counter, sample) seen while polling until the counter reaches `count`."""
    seen: list[tuple[int, Sample]] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        sample, n = mailbox.latest()
        if sample is not None and (not seen or n != seen[-1][0]):
            seen.append((n, sample))
        if n >= count:
            break
        time.sleep(0.001)
    return seen


def check_in_order(seen: list[tuple[int, Sample]]) -> None:
    """Counters and device times grow together, and the n-th sample is frame n - 1."""
    assert seen
    counters = [n for n, _ in seen]
    assert counters == sorted(set(counters))
    for n, sample in seen:
        k = int(sample.values[0])
        assert sample.values.tolist() == forces(k)
        assert sample.device_ms == T0_MS + k * STEP_MS
        assert n == k + 1  # no frame lost: the port was open before the first byte
    received = [s.received_s for _, s in seen]
    assert received == sorted(received)


@pytest.mark.parametrize(
    ("framing", "byte_order"),
    [("seed18", "little"), ("seed18", "big"), ("guide20", "little"), ("guide20", "big")],
)
def test_frames_arrive_in_order_with_counter_and_device_time(framing, byte_order):
    with open_pty() as p:
        port = FSE103Port(p.name)
        sensor = Sensor(p.master, framing, byte_order)
        with running(port):
            assert wait_for(lambda: port.connected)
            with running(sensor):
                seen = watch(port.mailbox, 20)
            assert seen[-1][0] >= 20
            check_in_order(seen)
            assert (port.parser.framing, port.parser.byte_order) == (framing, byte_order)
            stats = port.mailbox.stats
            assert stats.frames == port.mailbox.latest()[1]
            assert stats.bad_frames == 0
            assert port.mailbox.error is None
            assert port.describe() == f"FSE103 on {p.name}"


def test_zero_sends_z_to_the_device():
    with open_pty() as p:
        port = FSE103Port(p.name)
        message = rf"^FSE103 on {re.escape(p.name)}: not connected, cannot send b'z'$"
        with pytest.raises(RunError, match=message):
            port.zero()
        with running(port):
            assert wait_for(lambda: port.connected)
            port.zero()
            ready, _, _ = select.select([p.master], [], [], 1.0)
            assert ready
            assert os.read(p.master, 100) == b"z"


def test_garbage_mid_stream_is_counted_and_the_stream_goes_on():
    with open_pty() as p:
        port = FSE103Port(p.name)
        garbage = b"\x00\xff\x0d\x14\x66junk\xff"
        sensor = Sensor(
            p.master, "guide20", "little", rate_hz=200.0, garbage_at=10, garbage=garbage
        )
        with running(port):
            assert wait_for(lambda: port.connected)
            with running(sensor):
                assert wait_for(lambda: port.mailbox.stats.bad_frames > 0)
                seen = watch(port.mailbox, 25)
            assert seen[-1][0] >= 25  # frames after the garbage arrived
            check_in_order(seen)
            assert port.mailbox.stats.bad_frames == 1  # 10 bytes < one 20-byte frame
            stats = port.mailbox.stats
            assert wait_for(lambda: stats.bytes == 20 * stats.frames + len(garbage))


def test_a_quiet_stream_says_whether_its_bytes_stopped_or_made_no_sample():
    with open_pty() as p:
        port = FSE103Port(p.name)
        with running(port):
            assert wait_for(lambda: port.connected)
            for k in range(3):
                frame = encode_frame(forces(k), T0_MS + k, framing="seed18", byte_order="little")
                os.write(p.master, frame)
            assert wait_for(lambda: port.mailbox.latest()[1] == 3)
            assert port.mailbox.since_latest(time.monotonic()) == (
                "no byte read since its last sample"
            )
            garbage = b"junk!" * 12  # 60 bytes without a start byte
            sent = time.monotonic()
            os.write(p.master, garbage)
            assert wait_for(lambda: port.mailbox.stats.bytes == 3 * 18 + len(garbage))
            time.sleep(0.05)
            quiet = port.mailbox.since_latest(time.monotonic())
            match = re.fullmatch(
                r"60 bytes read since its last sample, the last (\d+) ms ago, (\d+) bad frames",
                quiet,
            )
            assert match, quiet
            assert 50 <= int(match[1]) <= 1e3 * (time.monotonic() - sent) + 1
            # 60 bytes discarded at the 18-byte frame length: 4 bad frames, however they came in
            assert int(match[2]) == port.mailbox.stats.bad_frames == 4
            assert port.mailbox.latest()[1] == 3


def test_raw_frames_are_counted_not_published():
    with open_pty() as p:
        port = FSE103Port(p.name)
        with running(port):
            assert wait_for(lambda: port.connected)
            for k in range(12):  # every third frame raw, as after the `r` command
                kind = "raw" if k % 3 == 2 else "forces"
                os.write(
                    p.master,
                    encode_frame(
                        forces(k), T0_MS + k, framing="guide20", byte_order="big", kind=kind
                    ),
                )
            assert wait_for(lambda: port.raw_frames == 4)
            sample, count = port.mailbox.latest()
            assert count == 8
            assert sample.values.tolist() == forces(10)
            assert port.mailbox.stats.frames == 8
            assert port.mailbox.stats.bad_frames == 0


def test_unplugging_records_the_device_and_stop_is_prompt():
    with open_pty() as p:
        # a long read timeout: stop() must cancel the blocked read, not wait it out
        port = FSE103Port(p.name, reconnect=False, timeout_s=1.0)
        sensor = Sensor(p.master, "seed18", "big")
        with running(port):
            assert wait_for(lambda: port.connected)
            with running(sensor):
                assert wait_for(lambda: port.mailbox.latest()[1] >= 5)
            p.unplug()
            assert wait_for(lambda: port.mailbox.error is not None)
            error = port.mailbox.error
            assert error.startswith(f"ConnectionError: FSE103 on {p.name}: connection lost:")
            assert not port.connected
            before = time.monotonic()
            port.stop()
            assert time.monotonic() - before < 0.3
            assert port.mailbox.error == error
            assert port.mailbox.stats.losses == 1  # no retry


def test_stop_cancels_a_blocked_read_at_once():
    with open_pty() as p:
        port = FSE103Port(p.name, timeout_s=1.0)
        with running(port):
            assert wait_for(lambda: port.connected)
            time.sleep(0.05)  # the reader now waits in a read that times out after 1 s
            before = time.monotonic()
            port.stop()
            assert time.monotonic() - before < 0.3
            assert not port.connected
        with pytest.raises(RunError, match="not connected"):
            port.zero()


def test_while_unplugged_the_port_keeps_retrying(tmp_path: Path):
    link = tmp_path / "fse103"
    with open_pty() as p:
        link.symlink_to(p.name)
        port = FSE103Port(str(link), retry_s=0.05)
        with running(port):
            assert wait_for(lambda: port.connected)
            os.replace(_link_to(tmp_path, tmp_path / "unplugged"), link)
            p.unplug()
            # every failed try to open the device again is a loss; none is a reconnection
            assert wait_for(lambda: port.mailbox.stats.losses >= 4)
            assert port.mailbox.stats.reconnects == 0
            assert not port.connected
            assert port.mailbox.error.startswith(f"ConnectionError: FSE103 on {link}: cannot open:")
            before = time.monotonic()
        assert time.monotonic() - before < 0.3


def test_reconnects_to_the_device_plugged_in_again(tmp_path: Path):
    link = tmp_path / "fse103"
    with open_pty() as first:
        link.symlink_to(first.name)
        port = FSE103Port(str(link), retry_s=0.05)
        with running(port):
            assert wait_for(lambda: port.connected)
            with running(Sensor(first.master, "guide20", "big", rate_hz=200.0)):
                assert wait_for(lambda: port.mailbox.latest()[1] >= 5)
            os.replace(_link_to(tmp_path, tmp_path / "unplugged"), link)
            first.unplug()
            assert wait_for(lambda: port.mailbox.error is not None)
            assert str(link) in port.mailbox.error
            counted = port.mailbox.latest()[1]
            with open_pty() as second:
                os.replace(_link_to(tmp_path, Path(second.name)), link)
                assert wait_for(lambda: port.connected)
                assert port.mailbox.error is None
                # the device restarts its clock and sends from frame 0 again
                with running(Sensor(second.master, "guide20", "big", rate_hz=200.0)):
                    seen = watch(port.mailbox, counted + 10)
                assert seen[-1][0] >= counted + 10
                after = [(n, int(s.values[0])) for n, s in seen if n > counted]
                assert after
                assert all(n == counted + k + 1 for n, k in after)
                assert port.mailbox.stats.reconnects == 1
                assert port.mailbox.last_error.startswith(f"ConnectionError: FSE103 on {link}:")
                port.stop()


def _link_to(tmp_path: Path, target: Path) -> Path:
    """A new symbolic link to `target`, to be renamed over the port's link in one step."""
    new = tmp_path / f"link-{time.monotonic_ns()}"
    new.symlink_to(target)
    return new


def test_opens_pyserial_urls():
    port = FSE103Port("loop://", retry_s=0.05)
    assert port.describe() == "FSE103 on loop://"
    with running(port):
        assert wait_for(lambda: port.connected)
        port.zero()  # loops back: one byte that is no frame
        assert wait_for(lambda: port.mailbox.stats.bytes == 1)
        assert wait_for(lambda: port.mailbox.stats.bad_frames == 1)
        assert port.mailbox.latest() == (None, 0)
        assert port.mailbox.error is None


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"timeout_s": 0.0}, r"^timeout_s must be > 0.0, got 0.0$"),
        ({"retry_s": -1}, r"^retry_s must be >= 0.0, got -1.0$"),
        ({"baudrate": 0}, r"^baudrate: expected a positive integer, got 0$"),
        ({"framing": "guide18"}, r"^framing: expected one of 'auto', 'seed18', 'guide20', got"),
    ],
)
def test_port_settings_are_checked(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        FSE103Port("/dev/ttyACM0", **kwargs)
