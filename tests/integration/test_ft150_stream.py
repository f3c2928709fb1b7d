"""The FT-150 stream and zero command over real loopback TCP (src/hoh_cosim/hardware/ft150.py).

Each test runs a small server thread on 127.0.0.1 (a free port the OS picks) that plays the URCap's
daemon: it serves one client at a time and sends `encode_sample` bytes, split mid-sample, mixed with
garbage, stalled, or cut off. The mailbox records every sample and every error the reader reports,
so the checks see the whole sequence, not only the latest sample.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from hoh_cosim.errors import ConfigError, HohError, RunError
from hoh_cosim.hardware.ft150 import ZERO_HOLD_S, FT150Stream, encode_sample, zero_sensor
from hoh_cosim.hardware.streams import Mailbox, Sample

HOST = "127.0.0.1"
RETRY_S = 0.05
PERIOD_S = 1 / 200  # the emulated daemon's sample period

Script = Callable[[socket.socket, threading.Event], None]


class RecordingMailbox(Mailbox):
    """A mailbox that also keeps every sample and every error it was given, in order."""

    def __init__(self) -> None:
        super().__init__()
        self.samples: list[Sample] = []
        self.errors: list[str] = []

    def publish(self, sample: Sample) -> None:
        super().publish(sample)
        self.samples.append(sample)

    def set_error(self, error: str | None) -> None:
        super().set_error(error)
        if error is not None:
            self.errors.append(error)


class LoopbackServer:
    """One client at a time, as the daemon: accept, run the next script on the connection, close it,
    accept the next. After the last script it accepts no more; later clients wait in the backlog."""

    def __init__(self, scripts: list[Script]) -> None:
        self.listener = socket.create_server((HOST, 0), backlog=1)
        self.listener.settimeout(0.02)
        self.port = self.listener.getsockname()[1]
        self.halt = threading.Event()
        self.accepted = 0
        self.thread = threading.Thread(target=self._serve, args=(scripts,), daemon=True)
        self.thread.start()

    def _serve(self, scripts: list[Script]) -> None:
        for script in scripts:
            conn = self._accept()
            if conn is None:
                return
            self.accepted += 1
            with conn:
                conn.settimeout(1.0)
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                with contextlib.suppress(OSError):  # the client left: next one
                    script(conn, self.halt)

    def _accept(self) -> socket.socket | None:
        while not self.halt.is_set():
            with contextlib.suppress(TimeoutError):
                return self.listener.accept()[0]
        return None

    def close(self) -> None:
        self.halt.set()
        self.thread.join(2.0)
        self.listener.close()


@pytest.fixture
def serve() -> Iterator[Callable[..., LoopbackServer]]:
    servers: list[LoopbackServer] = []

    def start(*scripts: Script) -> LoopbackServer:
        servers.append(LoopbackServer(list(scripts)))
        return servers[-1]

    yield start
    for server in servers:
        server.close()


def send(chunks: list[bytes], *, then: str = "hold") -> Script:
    """Send the chunks PERIOD_S apart, then hold the connection open (stall) or close it."""

    def script(conn: socket.socket, halt: threading.Event) -> None:
        for chunk in chunks:
            if halt.is_set():
                return
            conn.sendall(chunk)
            time.sleep(PERIOD_S)
        if then == "hold":
            halt.wait()

    return script


def until_client_leaves(tag: float) -> Script:
    """Stream samples (k, tag, 0, 0, 0, 0) until a send fails because the client has gone."""

    def script(conn: socket.socket, halt: threading.Event) -> None:
        k = 0
        while not halt.is_set():
            k += 1
            conn.sendall(encode_sample([k, tag, 0, 0, 0, 0]))
            time.sleep(PERIOD_S)

    return script


def values(k: int) -> list[float]:
    """Sample number k; each value is the double nearest its 2- or 3-decimal text: reads back exact."""
    return [float(k), -k / 4, 0.5 * k, k / 1000, -k / 500, 3 * k / 1000]


def split_halves(k: int) -> list[bytes]:
    payload = encode_sample(values(k))
    return [payload[:9], payload[9:]]  # inside the second number


def wait_until(condition: Callable[[], bool], timeout_s: float = 1.5) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.002)
    return condition()


def count(stream: FT150Stream) -> int:
    return stream.mailbox.latest()[1]


def closed_port() -> int:
    with socket.socket() as s:
        s.bind((HOST, 0))
        return s.getsockname()[1]


def test_samples_arrive_in_order_with_a_growing_counter_and_receipt_times(serve):
    n = 40
    chunks = [c for k in range(1, n + 1) for c in split_halves(k)]
    server = serve(send(chunks))
    mailbox = RecordingMailbox()
    with FT150Stream(HOST, server.port, mailbox=mailbox, retry_s=RETRY_S) as stream:
        seen = []
        deadline = time.monotonic() + 2.0
        while count(stream) < n and time.monotonic() < deadline:
            seen.append(stream.mailbox.latest())
            time.sleep(0.001)
        assert count(stream) == n
        assert stream.connected
    got = np.array([s.values for s in mailbox.samples])
    np.testing.assert_array_equal(got, [values(k) for k in range(1, n + 1)])
    times = np.array([s.received_s for s in mailbox.samples])
    assert np.all(np.diff(times) >= 0)
    assert times[-1] - times[0] > 0.5 * (2 * n - 2) * PERIOD_S  # stamped on receipt, not at once
    # what the control loop sees: the counter never goes back, and it names the latest sample
    counters = [c for sample, c in seen if sample is not None]
    assert counters == sorted(counters)
    for sample, c in seen:
        if sample is not None:
            assert sample.values[0] == c
    stats = mailbox.stats
    assert (stats.frames, stats.bad_frames, stats.reconnects) == (n, 0, 0)
    assert stats.bytes == sum(len(c) for c in chunks)
    assert mailbox.error is None
    assert mailbox.errors == []


def test_garbage_split_writes_and_a_bad_frame(serve):
    s1, s2, s3 = (encode_sample(values(k)) for k in (1, 2, 3))
    chunks = [
        b"\x00\xff garbage \r\n",
        s1[:3],
        s1[3:] + b" junk ) ",
        b"( 1.00 , 2.00 , 3.00 )",  # three numbers: a bad frame
        s2 + s3[:20],
        s3[20:],
    ]
    server = serve(send(chunks))
    mailbox = RecordingMailbox()
    with FT150Stream(HOST, server.port, mailbox=mailbox, retry_s=RETRY_S) as stream:
        assert wait_until(lambda: count(stream) == 3)
        assert wait_until(lambda: mailbox.stats.bytes == sum(len(c) for c in chunks))
    np.testing.assert_array_equal(
        [s.values for s in mailbox.samples], [values(k) for k in (1, 2, 3)]
    )
    assert mailbox.stats.bad_frames == 1
    assert mailbox.error is None


def test_non_finite_samples_are_published(serve):
    server = serve(send([encode_sample([np.nan, np.inf, -np.inf, 0, 0, 0])]))
    with FT150Stream(HOST, server.port, retry_s=RETRY_S) as stream:
        assert wait_until(lambda: count(stream) == 1)
        sample, _ = stream.mailbox.latest()
    assert sample is not None
    np.testing.assert_array_equal(sample.values, [np.nan, np.inf, -np.inf, 0, 0, 0])


def test_a_closed_connection_is_recorded_and_the_stream_reconnects(serve):
    first = [encode_sample(values(k)) for k in range(1, 6)] + [b"( 99.00 , 1"]
    # glued to the first connection's half sample, this would complete a six-number sample
    second = [b".00 , 2.00 , 3.00 , 4.00 , 5.000 )"] + [
        encode_sample(values(k)) for k in range(6, 11)
    ]
    server = serve(send(first, then="close"), send(second))
    mailbox = RecordingMailbox()
    with FT150Stream(HOST, server.port, mailbox=mailbox, retry_s=RETRY_S) as stream:
        assert wait_until(lambda: count(stream) == 10)
        assert stream.connected
        time.sleep(2 * PERIOD_S)
    assert server.accepted == 2
    assert [s.values[0] for s in mailbox.samples] == list(range(1, 11))
    assert mailbox.errors == ["ConnectionError: the device closed the connection"]
    assert mailbox.error is None  # cleared by the new connection
    assert mailbox.stats.reconnects == 1
    assert mailbox.stats.bad_frames == 1  # the half sample the first connection ended with


def test_without_reconnect_the_stream_gives_up(serve):
    server = serve(send([encode_sample(values(1))], then="close"), send([encode_sample(values(2))]))
    mailbox = RecordingMailbox()
    with FT150Stream(
        HOST, server.port, mailbox=mailbox, reconnect=False, retry_s=RETRY_S
    ) as stream:
        assert wait_until(lambda: mailbox.error is not None)
        time.sleep(4 * RETRY_S)
        assert not stream.connected
    assert server.accepted == 1
    assert [s.values[0] for s in mailbox.samples] == [1.0]
    assert mailbox.error == "ConnectionError: the device closed the connection"


def test_a_refused_connection_is_recorded_and_retried():
    port = closed_port()
    with FT150Stream(HOST, port, retry_s=RETRY_S) as stream:
        assert wait_until(lambda: stream.mailbox.stats.losses >= 2)  # tried again and again
        assert stream.mailbox.stats.reconnects == 0  # and never got through
        assert not stream.connected
        error = stream.mailbox.error
    assert error is not None
    assert error.startswith("ConnectionRefusedError:")
    assert count(stream) == 0


@pytest.mark.parametrize("timeout_s", [0.2, 5.0])  # 5 s: stop() must not wait for the read timeout
def test_a_stalled_server_gives_no_samples_and_no_error_and_stop_is_prompt(serve, timeout_s):
    server = serve(send([encode_sample(values(k)) for k in (1, 2, 3)]))
    stream = FT150Stream(HOST, server.port, retry_s=RETRY_S, timeout_s=timeout_s)
    stream.start()
    try:
        assert wait_until(lambda: count(stream) == 3)
        time.sleep(0.3)
        assert count(stream) == 3
        assert stream.mailbox.error is None
        assert stream.connected
    finally:
        t0 = time.monotonic()
        stream.stop()
        elapsed = time.monotonic() - t0
    assert elapsed < 0.5
    assert not stream.connected
    assert stream.mailbox.error is None  # stopping is not a failure


def test_the_server_serves_one_client_at_a_time(serve):
    server = serve(until_client_leaves(1.0), until_client_leaves(2.0))
    with FT150Stream(HOST, server.port, retry_s=RETRY_S) as a:
        assert wait_until(lambda: count(a) >= 5)
        b = FT150Stream(HOST, server.port, retry_s=RETRY_S)
        b.start()
        try:
            # the kernel completes b's connection, the server never reads it: a stall, not an error
            assert wait_until(lambda: b.connected)
            time.sleep(0.2)
            assert count(b) == 0
            assert b.mailbox.error is None
            a.stop()
            assert wait_until(lambda: count(b) >= 5)
            sample, _ = b.mailbox.latest()
        finally:
            b.stop()
    assert sample is not None
    assert sample.values[1] == 2.0  # from the second connection's script
    assert server.accepted == 2
    assert a.mailbox.error is None


def test_start_twice_is_an_error(serve):
    server = serve(send([]))
    stream = FT150Stream(HOST, server.port)
    with stream, pytest.raises(RunError, match=rf"^FT-150 stream at {HOST}:{server.port}: already"):
        stream.start()


def test_describe_and_parameters():
    assert FT150Stream(HOST, 63351).describe() == "FT-150 stream at 127.0.0.1:63351"
    with pytest.raises(ConfigError, match=r"^timeout_s must be > 0"):
        FT150Stream(HOST, timeout_s=0)
    with pytest.raises(ConfigError, match=r"^retry_s must be >= 0"):
        FT150Stream(HOST, retry_s=-1)
    FT150Stream(HOST).stop()  # never started: nothing to do


def test_zero_sensor_sends_the_command_and_holds_the_connection(serve):
    received: list[tuple[float, bytes]] = []

    def record(conn: socket.socket, halt: threading.Event) -> None:
        while data := conn.recv(64):
            received.append((time.monotonic(), data))
        received.append((time.monotonic(), b""))  # the client closed

    server = serve(record)
    t0 = time.monotonic()
    zero_sensor(HOST, server.port)
    assert time.monotonic() - t0 < 1.0
    assert wait_until(lambda: received and received[-1][1] == b"")
    assert b"".join(data for _, data in received) == b"SET ZRO"
    assert received[-1][0] - received[0][0] >= 0.8 * ZERO_HOLD_S


def test_zero_sensor_to_a_closed_port_is_a_one_line_error():
    port = closed_port()
    with pytest.raises(
        RunError, match=rf"^FT-150 command port {HOST}:{port}: .*Connection refused$"
    ):
        zero_sensor(HOST, port, timeout_s=0.5)
    with pytest.raises(HohError) as info:
        zero_sensor(HOST, port, timeout_s=0.5)
    assert "\n" not in str(info.value)
