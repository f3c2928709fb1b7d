"""The fuzz targets: every parser and loader, the inputs it is given and the invariants it keeps.

Shared by the tests of this directory (a bounded, derandomized sample of inputs) and by the
time-boxed campaign `benchmarks/fuzz.py` (atheris' coverage-guided mutations where it is installed,
otherwise a large random sample). A `Target` has a hypothesis strategy of structured inputs, a
decoder that makes an input of raw bytes (what atheris mutates), seeds for atheris' corpus, and
`check(workspace, input)`, which raises `InvariantError`, or lets through whatever else the code under
test raised, when an invariant does not hold:

- the stream parsers (`ft150`, `fse103`, both framings and byte orders, given or detected): never
  raise; chunking changes neither the samples or frames nor the bad-frame count; the bytes held
  between feeds stay bounded; every valid sample or frame around the garbage comes back, in order;
- the UR controller emulator (`rtde`, `dashboard`), facing any client bytes: no thread of it dies;
  once the client has sent everything it closes the connection within the time bound, having
  answered in whole packages or lines (a dashboard line for each command); and a well-behaved
  client (the RTDE guide's, universal-robots-clients' dashboard client) is served next;
- the files (`scenario`, `sweep`, `rig` YAML, `poses` CSV, `calibration` JSON, `session` logs and
  their replay): loading gives a result or raises a `HohError` whose message is one line that starts
  with the file's path; within the workspace's time bound and `MEMORY_MB` more memory. A session
  log cut short or with a byte flipped gives, at most, a prefix of the original's messages.
"""

from __future__ import annotations

import ast
import contextlib
import copy
import functools
import itertools
import json
import math
import queue
import resource
import socket
import struct
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from hoh_cosim.errors import HohError, IdentificationError

ROOT = Path(__file__).resolve().parents[2]
HANG_S = 2.0
"""[s] An input that takes longer is a hang (the campaign's bound; the tests allow `TEST_HANG_S`)."""
TEST_HANG_S = 10.0
"""[s] The tests' bound: a loop without end is caught as surely, a loaded CI machine is not."""
MEMORY_MB = 500
"""[MB] How much the process's peak memory may grow while one input is handled."""


class InvariantError(AssertionError):
    """An input broke an invariant of its target."""


class HangError(InvariantError):
    """An input took longer than its time bound."""


def bounded(max_examples: int) -> settings:
    """Hypothesis settings for a fuzz test: the same `max_examples` inputs on every run."""
    return settings(
        max_examples=max_examples,
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=[
            HealthCheck.too_slow,
            HealthCheck.function_scoped_fixture,  # capsys: read and emptied at every example
            HealthCheck.filter_too_much,
            HealthCheck.data_too_large,
            HealthCheck.large_base_example,
        ],
    )


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


@contextlib.contextmanager
def within(what: str, seconds: float) -> Iterator[None]:
    """Raise `HangError` if the block took longer than `seconds`, `InvariantError` if it raised
    the peak memory by more than `MEMORY_MB`. Warnings are errors in the block, as in the tests."""
    start, peak = time.perf_counter(), _peak_mb()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # control.vectors.as_unit_vector squares a direction, which overflows from 1e154 on: its
        # own fault, not a loader's (what the loader then says of the file is checked all the same)
        warnings.filterwarnings(
            "ignore", "overflow encountered", RuntimeWarning, "hoh_cosim.control.vectors"
        )
        yield
    took = time.perf_counter() - start
    if took > seconds:
        raise HangError(f"{what} took {took:.1f} s (bound {seconds:g} s)")
    grown = _peak_mb() - peak
    if grown > MEMORY_MB:
        raise InvariantError(f"{what} raised the peak memory by {grown:.0f} MB")


def timed(check: Callable[[Workspace, Any], None]) -> Callable[[Workspace, Any], None]:
    """`check` within the workspace's time bound (see `within`)."""

    @functools.wraps(check)
    def bounded_check(ws: Workspace, value: Any) -> None:
        with within(check.__name__, ws.hang_s):
            check(ws, value)

    return bounded_check


def one_line_error(exc: HohError, path: Path) -> None:
    """The file's error says, in one line, which file; and no more than in proportion to it."""
    message = str(exc)
    if "\n" in message or "\r" in message:
        raise InvariantError(f"a message of more than one line: {message[:300]!r}")
    if not message.startswith(f"{path}: ") or len(message) <= len(f"{path}: "):
        raise InvariantError(f"the message does not start with the file's path: {message[:300]!r}")
    size = path.stat().st_size if path.exists() else 0
    if len(message) > 20 * size + 10_000:
        raise InvariantError(f"a message of {len(message)} characters about a file of {size} bytes")


def _chunks(data: bytes, sizes: Sequence[int]) -> Iterator[bytes]:
    """`data` cut into pieces of `sizes`, taken in turn (one piece when there are none)."""
    if not sizes:
        yield data
        return
    at = 0
    for size in itertools.cycle(sizes):
        if at >= len(data):
            return
        yield data[at : at + max(1, size)]
        at += max(1, size)


def _is_subsequence(wanted: Sequence[Any], got: Sequence[Any]) -> bool:
    rest = iter(got)
    return all(any(w == g for g in rest) for w in wanted)


def _length_prefixed(data: bytes) -> list[bytes]:
    """Pieces of `data`, each one length byte and then that many bytes (atheris' inputs)."""
    pieces, at = [], 0
    while at < len(data):
        n = data[at]
        pieces.append(data[at + 1 : at + 1 + n])
        at += 1 + n
    return pieces


# --- the workspace -----------------------------------------------------------------------------


class Workspace:
    """Where the checks run: a directory for the input files, the time bound and, made on first
    use, the emulated UR controller and a real session log (or the log given)."""

    def __init__(
        self, directory: Path, hang_s: float = HANG_S, session_seed: Path | None = None
    ) -> None:
        self.directory = Path(directory)
        self.hang_s = hang_s
        self._session_seed = session_seed
        self._controller: Controller | None = None

    @functools.cached_property
    def session_seed(self) -> Path:
        """A session log of 60 cycles and its parameters, written by the project's SessionLog."""
        if self._session_seed is None:
            from tests.integration.test_replay import make_log

            path = self.directory / "seed.mcap"
            path.unlink(missing_ok=True)  # a log that an earlier try left unfinished
            self._session_seed = make_log(path, rows=60, parameters=True)
        return self._session_seed

    @functools.cached_property
    def session_messages(self) -> dict[str, list[dict[str, Any]]]:
        from hoh_cosim.hardware.session_log import read_session

        return read_session(self.session_seed).messages

    @property
    def controller(self) -> Controller:
        if self._controller is None:
            self._controller = Controller()
        return self._controller

    def file(self, suffix: str, data: bytes) -> Path:
        path = self.directory / f"input{suffix}"
        path.write_bytes(data)
        return path

    def close(self) -> None:
        if self._controller is not None:
            self._controller.close()
            self._controller = None


# --- the FT-150 stream parser --------------------------------------------------------------------


def _ft_values(k: int) -> list[float]:
    """Sample k, as the daemon's format writes it (forces to 2 decimals, torques to 3)."""
    values = [k + 0.25, -k - 0.5, 9.75, 0.125 * (k % 8), -0.001 * k, 1.0]
    return [float(f"{x:.2f}") for x in values[:3]] + [float(f"{x:.3f}") for x in values[3:]]


@timed
def check_ft150(ws: Workspace, value: tuple[Sequence[bytes], Sequence[int]]) -> None:
    """Samples around garbage: `pieces` of garbage between the samples, fed in chunks of `sizes`."""
    from hoh_cosim.hardware.ft150 import MAX_FRAME_BYTES, FT150Parser, encode_sample

    pieces, sizes = value
    wanted = [_ft_values(k) for k in range(len(pieces) + 1)]
    stream = encode_sample(wanted[0]) + b"".join(
        piece + encode_sample(values) for piece, values in zip(pieces, wanted[1:], strict=True)
    )
    whole = FT150Parser()
    expected = [s.tolist() for s in whole.feed(stream)]
    parser = FT150Parser()
    got = []
    for chunk in _chunks(stream, sizes):
        samples = parser.feed(chunk)
        for sample in samples:
            if sample.shape != (6,) or sample.dtype != np.float64:
                raise InvariantError(f"a sample of shape {sample.shape} and type {sample.dtype}")
        got += [s.tolist() for s in samples]
        if not 0 <= parser.pending <= MAX_FRAME_BYTES:
            raise InvariantError(f"{parser.pending} bytes pending, more than {MAX_FRAME_BYTES}")
    if not np.array_equal(np.array(got), np.array(expected), equal_nan=True):
        raise InvariantError(f"chunks gave other samples than one feed: {got} != {expected}")
    if (parser.bad_frames, parser.frames) != (whole.bad_frames, whole.frames):
        raise InvariantError(
            f"bad frames {parser.bad_frames} in chunks, {whole.bad_frames} at once"
        )
    if parser.frames != len(got):
        raise InvariantError(f"frames counts {parser.frames}, {len(got)} were returned")
    if not _is_subsequence(wanted, got):
        raise InvariantError(f"the valid samples did not all come back in order: {got}")
    if not any(b"(" in p or b")" in p for p in pieces) and (got, parser.bad_frames) != (wanted, 0):
        raise InvariantError(f"garbage without brackets changed the samples: {got}")


def _ft150_strategy(ws: Workspace | None) -> st.SearchStrategy[Any]:
    token = st.one_of(
        st.binary(max_size=24),
        st.sampled_from([b"(", b")", b",", b" ", b"nan", b"-", b".", b"e", b"\r\n", b"\x00"]),
        st.lists(st.floats(width=32), min_size=5, max_size=7).map(
            lambda v: ("( " + " , ".join(map(str, v)) + " )").encode()
        ),
        st.integers(1, 1200).map(lambda n: b"(" + b"7" * n),
    )
    garbage = st.lists(token, max_size=5).map(b"".join)
    return st.tuples(
        st.lists(garbage, max_size=5), st.lists(st.integers(1, 80), max_size=6).map(tuple)
    ).map(lambda v: (tuple(v[0]), v[1]))


def _ft150_decode(data: bytes) -> tuple[tuple[bytes, ...], tuple[int, ...]]:
    step = data[0] % 64 + 1 if data else 1
    return tuple(_length_prefixed(data[1:])), (step,)


# --- the FSE103 frame parser ---------------------------------------------------------------------


def _fse_frames(n: int) -> list[Any]:
    """n plausible frames, float32 values and time stamps 20 ms apart, wrapping past 2**32."""
    from hoh_cosim.hardware.fse103 import ProbeFrame

    return [
        ProbeFrame(
            np.array([0.5 * k, -0.25 * k, 1.0 + k], dtype=np.float32), (2**32 - 90 + 20 * k) % 2**32
        )
        for k in range(n)
    ]


@timed
def check_fse103(ws: Workspace, value: tuple[Any, ...]) -> None:
    """Runs of valid frames (`LOCK_FRAMES` + `extra` each) with `pieces` of garbage between them,
    in `framing` and `byte_order`, parsed with those given (or detected: `auto`), fed in chunks of
    `sizes`."""
    from hoh_cosim.hardware.fse103 import LOCK_FRAMES, MAX_PENDING_BYTES, FSE103Parser, encode_frame

    pieces, sizes, framing, byte_order, auto, extra = value
    per_run = LOCK_FRAMES + extra
    wanted = _fse_frames(per_run * (len(pieces) + 1))
    runs = [
        b"".join(
            encode_frame(f.forces, f.timestamp_ms, framing=framing, byte_order=byte_order)
            for f in wanted[i * per_run : (i + 1) * per_run]
        )
        for i in range(len(pieces) + 1)
    ]
    stream = runs[0] + b"".join(p + r for p, r in zip(pieces, runs[1:], strict=True))

    def parser() -> FSE103Parser:
        return FSE103Parser() if auto else FSE103Parser(framing, byte_order)

    whole = parser()
    expected = whole.feed(stream)
    chunked = parser()
    got = []
    for chunk in _chunks(stream, sizes):
        got += chunked.feed(chunk)
        if not 0 <= chunked.pending_bytes <= MAX_PENDING_BYTES:
            raise InvariantError(
                f"{chunked.pending_bytes} bytes pending, more than {MAX_PENDING_BYTES}"
            )
    if got != expected or chunked.bad_frames != whole.bad_frames:
        raise InvariantError(
            f"chunks gave {len(got)} frames and {chunked.bad_frames} bad ones, "
            f"one feed {len(expected)} and {whole.bad_frames}"
        )
    # Garbage may cost the frames of a run up to its (LOCK_FRAMES + 1)-th: a frame cut short and
    # completed by the next frame's first bytes is taken in sync when the last of them is the end
    # byte, and the parser, then off by those bytes, synchronises again on LOCK_FRAMES frames.
    back = [f for f in got if f in wanted]
    lost = [
        f
        for i, f in enumerate(wanted)
        if f not in back and (i < per_run or i % per_run > LOCK_FRAMES)
    ]
    if back != sorted(back, key=wanted.index) or lost:
        stamps = [f.timestamp_ms for f in got]
        raise InvariantError(f"the valid frames did not come back in order: {stamps}")
    if (chunked.framing, chunked.byte_order) != (framing, byte_order):
        raise InvariantError(f"ended in {chunked.framing}, {chunked.byte_order}")
    if not any(pieces) and (got, chunked.bad_frames) != (wanted, 0):
        raise InvariantError("a stream without garbage did not give its frames exactly")


def _fse103_strategy(ws: Workspace | None) -> st.SearchStrategy[Any]:
    """Garbage of random bytes, the framings' start and end bytes, and whole or partial frames of
    the stream's own framing and byte order with any time stamp and force."""
    from hoh_cosim.hardware.fse103 import BYTE_ORDERS, FRAMINGS, encode_frame

    def inputs(kind: tuple[str, str]) -> st.SearchStrategy[Any]:
        framing, order = kind
        frame_part = st.tuples(st.integers(0, 2**32 - 1), st.integers(0, 20), st.floats(width=32))
        token = st.one_of(
            st.binary(max_size=24),
            st.sampled_from([b"\x00", b"\xff", b"\x0d\x14\x66", b"\x0d\x14\x72", b"\x0d\x14"]),
            frame_part.map(
                lambda a: encode_frame([a[2], 1.0, 2.0], a[0], framing=framing, byte_order=order)[
                    : a[1]
                ]
            ),
        )
        return st.tuples(
            st.lists(st.lists(token, max_size=5).map(b"".join), max_size=4).map(tuple),
            st.lists(st.integers(1, 64), max_size=6).map(tuple),
            st.just(framing),
            st.just(order),
            st.booleans(),
            st.integers(0, 5),
        )

    return st.tuples(st.sampled_from(FRAMINGS), st.sampled_from(BYTE_ORDERS)).flatmap(inputs)


def _fse103_decode(data: bytes) -> tuple[Any, ...]:
    flags = data[0] if data else 0
    step = data[1] % 64 + 1 if len(data) > 1 else 1
    return (
        tuple(_length_prefixed(data[2:])),
        (step,),
        ("seed18", "guide20")[flags & 1],
        ("little", "big")[flags >> 1 & 1],
        bool(flags & 4),
        (flags >> 3 & 7) % 6,
    )


# --- the UR controller emulator ------------------------------------------------------------------


def _free_ports(n: int) -> list[int]:
    sockets = [socket.socket() for _ in range(n)]
    try:
        for s in sockets:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in sockets]
    finally:
        for s in sockets:
            s.close()


@contextlib.contextmanager
def thread_exceptions() -> Iterator[list[threading.ExceptHookArgs]]:
    """What the threads that end with an exception within the block raised."""
    caught: list[threading.ExceptHookArgs] = []
    previous = threading.excepthook
    threading.excepthook = caught.append
    try:
        yield caught
    finally:
        threading.excepthook = previous


class Controller:
    """The emulated UR controller's servers in this process, so that an exception that ends one of
    its threads is seen: on free loopback ports, in front of an arm at rest (the rehearsal world's
    shared memory, the world itself not running)."""

    HANDLERS = ("ur-rtde", "ur-dashboard", "ur-script")  # its threads that serve a connection

    def __init__(self) -> None:
        from hoh_cosim.rehearsal.ur_controller import _Emulator, _SharedWorld
        from hoh_cosim.rehearsal.world import RehearsalWorld, SeqLock, WorldSetup

        world = RehearsalWorld(WorldSetup())  # for its shared memory: not started
        SeqLock(world.state).write(np.eye(3).reshape(9), slice(3, 12))  # R_BT: the arm at home
        self.host = "127.0.0.1"
        self.ports = dict(zip(("dashboard", "script", "rtde"), _free_ports(3), strict=True))
        self.events: queue.Queue[tuple[float, str]] = queue.Queue()
        self._emulator = _Emulator(
            _SharedWorld(world.state, world.command),
            self.host,
            self.ports,
            "e",
            True,
            events=self.events,
        )
        self._emulator.start()

    def threads_alive(self) -> bool:
        names = {t.name for t in threading.enumerate()}
        return {"ur-accept", "ur-control"} <= names

    def handlers(self) -> set[threading.Thread]:
        return {t for t in threading.enumerate() if t.name in self.HANDLERS}

    def close(self) -> None:
        self._emulator.stop()


def _exchange(ws: Workspace, port: int, data: bytes, sizes: Sequence[int]) -> tuple[bytes, bool]:
    """Send `data` in chunks, then shut our side: (all the server sent, whether it closed without
    a reset). A server that has not closed within the time bound is a `HangError`."""
    deadline = time.monotonic() + ws.hang_s
    received = b""
    with socket.create_connection((ws.controller.host, port), timeout=ws.hang_s) as sock:
        with contextlib.suppress(OSError):  # the server may close first: a refusal
            for chunk in _chunks(data, sizes):
                sock.sendall(chunk)
            sock.shutdown(socket.SHUT_WR)
        while True:
            sock.settimeout(max(0.01, deadline - time.monotonic()))
            try:
                part = sock.recv(65536)
            except TimeoutError:
                raise HangError(
                    f"the controller kept the connection open {ws.hang_s:g} s after the client "
                    "had sent everything"
                ) from None
            except ConnectionResetError:
                return received, False
            if not part:
                return received, True
            received += part


def _served(ws: Workspace, what: str, caught: list[threading.ExceptHookArgs], before: set) -> None:
    """After a fuzzed connection: its handler ended, without an exception, and the controller's
    own threads run."""
    for thread in ws.controller.handlers() - before:
        thread.join(ws.hang_s)
        if thread.is_alive():
            raise InvariantError(f"{what}: the connection's thread runs on after it was closed")
    if caught:
        args = caught[0]
        name = args.thread.name if args.thread else "?"
        raise InvariantError(
            f"{what}: thread {name} ended with {args.exc_type.__name__}: {args.exc_value}"
        )
    if not ws.controller.threads_alive():
        raise InvariantError(f"{what}: the controller's cycle or its listener has stopped")
    with contextlib.suppress(queue.Empty):  # its log, which nobody reads here
        while True:
            ws.controller.events.get_nowait()


_RTDE_KINDS = frozenset(b"VvOISPUM")


def check_rtde(ws: Workspace, value: tuple[bytes, Sequence[int]]) -> None:
    """A client sends `data` (in chunks of `sizes`) to the RTDE port and closes its side."""
    from hoh_cosim.rehearsal import rtde_protocol as rtde
    from tests.rtde_guide_client import GuideClient

    data, sizes = value
    controller = ws.controller
    before = controller.handlers()
    with thread_exceptions() as caught:
        replies, _ = _exchange(ws, controller.ports["rtde"], data, sizes)
        at = 0
        while at + rtde.HEADER.size <= len(replies):  # whole packages (the last may be cut short)
            size, kind = rtde.HEADER.unpack_from(replies, at)
            if size < rtde.HEADER.size or kind not in _RTDE_KINDS:
                raise InvariantError(f"a reply package of size {size} and type {kind}")
            at += size
        _served(ws, "rtde", caught, before)
        try:
            with GuideClient(controller.host, controller.ports["rtde"], ws.hang_s) as client:
                ok = client.request_version(2)
                recipe, types = client.setup_outputs(["timestamp", "actual_q"])
                ok = ok and recipe == 1 and types == ["DOUBLE", "VECTOR6D"] and client.start()
                ok = ok and len(client.outputs()) == 2
        except (OSError, struct.error, ValueError) as exc:
            raise InvariantError(f"rtde: the next client was not served: {exc!r}") from None
        if not ok:
            raise InvariantError("rtde: the next client was refused")
        _served(ws, "rtde, the next client", caught, before)


def _rtde_strategy(ws: Workspace | None) -> st.SearchStrategy[Any]:
    from hoh_cosim.rehearsal import rtde_protocol as rtde
    from hoh_cosim.rehearsal.ur_controller import NOT_EMULATED

    def listed(names: st.SearchStrategy[str], **kwargs: int) -> st.SearchStrategy[bytes]:
        return st.lists(names, **kwargs).map(lambda n: ",".join(n).encode(errors="surrogateescape"))

    names = st.one_of(  # recipes the controller takes, and any other
        listed(st.sampled_from(sorted(set(rtde.OUTPUTS) - NOT_EMULATED)), min_size=1, max_size=3),
        listed(st.sampled_from(sorted(rtde.INPUTS)), min_size=1, max_size=3),
        listed(st.sampled_from(sorted(rtde.OUTPUTS)) | st.text(max_size=12), max_size=6),
    )
    frequencies = st.one_of(
        st.sampled_from([5e-324, 1e-300, 0.0, -1.0, 125.0, 500.0, 500.1, math.nan, math.inf]),
        st.floats(),
    )
    doubles = frequencies.map(lambda f: struct.pack(">d", f))
    payloads = {
        "V": st.integers(0, 65535).map(lambda v: struct.pack(">H", v)) | st.binary(max_size=3),
        "v": st.just(b"") | st.binary(max_size=4),
        "O": st.tuples(doubles, names).map(b"".join) | names,
        "I": names,
        "S": st.just(b""),
        "P": st.just(b""),
        "U": st.tuples(st.integers(0, 255).map(lambda r: bytes([r])), st.binary(max_size=60)).map(
            b"".join
        ),
        "M": st.tuples(st.text(max_size=10), st.text(max_size=10), st.integers(0, 255)).map(
            lambda m: (
                bytes([len(m[0].encode())])
                + m[0].encode()
                + bytes([len(m[1].encode())])
                + m[1].encode()
                + bytes([m[2]])
            )
        )
        | st.binary(max_size=12),
    }
    package = st.one_of(
        st.sampled_from(sorted(payloads)).flatmap(
            lambda kind: payloads[kind].map(lambda p: rtde.pack(kind, p))
        ),
        st.tuples(st.integers(0, 255), st.binary(max_size=40)).map(
            lambda t: rtde.HEADER.pack(3 + len(t[1]), t[0]) + t[1]
        ),
        st.tuples(st.integers(0, 65535), st.integers(0, 255), st.binary(max_size=40)).map(
            lambda t: rtde.HEADER.pack(t[0], t[1]) + t[2]
        ),
        st.binary(max_size=16),
    )
    # most sessions begin as a client does: a version (the set-ups depend on it), the outputs
    version = st.sampled_from([b"", *(rtde.pack("V", struct.pack(">H", v)) for v in (1, 2, 2))])
    outputs = st.tuples(doubles, names).map(lambda o: rtde.pack("O", b"".join(o)))
    return st.tuples(
        st.tuples(version, st.just(b"") | outputs, st.lists(package, max_size=8).map(b"".join)).map(
            b"".join
        ),
        st.lists(st.integers(1, 64), max_size=4).map(tuple),
    )


def _rtde_corpus(ws: Workspace) -> list[bytes]:
    """A client as UR's guide describes one (version 2, outputs, start, pause), and one that
    writes a register."""
    from hoh_cosim.rehearsal import rtde_protocol as rtde

    return [
        rtde.pack("V", struct.pack(">H", 2))
        + rtde.pack("O", struct.pack(">d", 125.0) + b"timestamp,actual_q")
        + rtde.pack("S")
        + rtde.pack("P"),
        rtde.pack("I", b"input_int_register_0")
        + rtde.pack("S")
        + rtde.pack("U", b"\x01" + struct.pack(">i", 10))
        + rtde.pack("M", b"\x02hi\x01x\x03"),
    ]


def check_dashboard(ws: Workspace, value: tuple[bytes, Sequence[int]]) -> None:
    """A client sends `data` (in chunks of `sizes`) to the dashboard port and closes its side."""
    from universal_robots_clients.dashboard_client import send_command

    data, sizes = value
    controller = ws.controller
    before = controller.handlers()
    with thread_exceptions() as caught:
        replies, clean = _exchange(ws, controller.ports["dashboard"], data, sizes)
        commands = [c.decode(errors="replace").strip() for c in data.split(b"\n")[:-1]]
        if "quit" in commands:
            commands = commands[: commands.index("quit") + 1]
        lines = replies.split(b"\n")
        answered = len(lines) - 2  # the banner's line, and what follows the last line ending
        if clean and (lines[0] != b"Connected: Universal Robots Dashboard Server" or lines[-1]):
            raise InvariantError(f"dashboard: not the banner and whole lines: {replies[:200]!r}")
        if answered > len(commands) or (clean and answered != len(commands)):
            raise InvariantError(f"dashboard: {answered} replies to {len(commands)} commands")
        _served(ws, "dashboard", caught, before)
        try:
            model = send_command(
                controller.host, "get robot model", controller.ports["dashboard"], ws.hang_s
            )
        except (OSError, ValueError) as exc:
            raise InvariantError(f"dashboard: the next client was not served: {exc!r}") from None
        if model != "UR5":
            raise InvariantError(f"dashboard: the next client was told {model!r}")
        _served(ws, "dashboard, the next client", caught, before)


_DASHBOARD_COMMANDS = (
    "get robot model",
    "get loaded program",
    "isProgramSaved",
    "get operational mode",
    "clear operational mode",
    "PolyscopeVersion",
    "get serial number",
    "is in remote control",
    "robotmode",
    "safetystatus",
    "safetymode",
    "running",
    "programState",
    "power on",
    "power off",
    "brake release",
    "load /programs/a.urp",
    "load a.txt",
    "load ",
    "play",
    "pause",
    "stop",
    "unlock protective stop",
    "close safety popup",
    "shutdown",
    "quit",
)


def _dashboard_strategy(ws: Workspace | None) -> st.SearchStrategy[Any]:
    line = st.one_of(
        st.sampled_from(_DASHBOARD_COMMANDS).map(str.encode),
        st.text(max_size=30).map(lambda t: t.encode(errors="surrogateescape")),
        st.binary(max_size=30),
        st.integers(1, 20_000).map(lambda n: b"x" * n),
    )
    ending = st.sampled_from([b"\n", b"\r\n", b"", b"\r", b"\n\n"])
    return st.tuples(
        st.lists(st.tuples(line, ending).map(b"".join), max_size=8).map(b"".join),
        st.lists(st.integers(1, 64), max_size=4).map(tuple),
    )


def _whole_input(data: bytes) -> tuple[bytes, tuple[int, ...]]:
    return data, ()


# --- files ---------------------------------------------------------------------------------------

_RAW = "FUZZRAW{}X"  # stands for a raw fragment until the document is written out


def billion_laughs(levels: int) -> str:
    """A YAML flow sequence whose last item, expanded, is 10**levels strings (billion laughs)."""
    items = ["&l0 [" + ", ".join(["lol"] * 10) + "]"]
    items += [f"&l{i} [" + ", ".join([f"*l{i - 1}"] * 10) + "]" for i in range(1, levels)]
    return "[" + ", ".join(items) + "]"


NASTY_VALUES: list[Any] = [
    None,
    True,
    False,
    0,
    -1,
    1,
    2**31,
    2**63 - 1,
    -(2**63),
    2**64,
    10**30,
    0.0,
    -0.0,
    5e-324,
    1e-300,
    1e300,
    1.7976931348623157e308,
    math.nan,
    math.inf,
    -math.inf,
    "",
    " ",
    "x",
    "nan",
    "1e999",
    "0x10",
    "~",
    "\x00",
    "é",
    "a" * 300,
    [],
    {},
    [1, 2, 3],
    [[1, 2, 3]],
    [0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5],
    {"x": 1},
    ["a", "b"],
]
_values = st.one_of(
    st.sampled_from(NASTY_VALUES),
    st.integers(),
    st.floats(),
    st.text(max_size=16),
    st.lists(st.floats(allow_nan=False), max_size=4),
)
_YAML_FRAGMENTS = st.one_of(
    st.sampled_from(
        [
            billion_laughs(9),
            billion_laughs(3),
            "&self [*self]",
            "&m {a: *m}",
            "*undefined",
            "[" * 40 + "]" * 40,
            "{a: " * 40 + "1" + "}" * 40,
            "!!python/object/apply:os.system [echo]",
            "!!binary AAAA",
            "!!set {a, b}",
            "!!omap [a: 1, b: 2]",
            "2024-13-01",
            "9" * 5000,
            "0x" + "f" * 40,
            "-.inf",
            ".nan",
            "1e999",
            "{<<: [1, 2]}",
            "[1, 2",
            "'unterminated",
            "\t- tab",
            "|-\n  text",
        ]
    ),
    st.integers(30, 1200).map(lambda d: "[" * d + "]" * d),
)
_JSON_FRAGMENTS = st.one_of(
    st.sampled_from(
        [
            "9" * 5000,
            "1e999",
            "-1e999",
            "NaN",
            "-Infinity",
            "[1, 2",
            '"\\ud800"',
            '{"a": 1, "a": 2}',
            "[" * 40 + "]" * 40,
            "1" + "0" * 400,
        ]
    ),
    st.integers(30, 20_000).map(lambda d: "[" * d + "]" * d),
)
# edits of a document: (kind, path, argument)
_Edit = tuple[str, tuple[Any, ...], Any]


def _paths(value: Any, here: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [here]
    if isinstance(value, dict):
        for key, item in value.items():
            out += _paths(item, (*here, key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            out += _paths(item, (*here, i))
    return out


def _edit(document: Any, edit: _Edit, raws: list[str]) -> Any:
    """`document` with one edit; an edit whose path an earlier one removed changes nothing."""
    kind, path, arg = edit
    if not path and kind in ("set", "raw"):
        if kind == "raw":
            raws.append(arg)
            return _RAW.format(len(raws) - 1)
        return arg
    parent, node = None, document
    for key in path:
        parent = node
        if not isinstance(node, dict | list):
            return document
        if key not in (node if isinstance(node, dict) else range(len(node))):
            return document
        node = node[key]
    if kind == "add":
        if isinstance(node, dict):
            node[arg[0]] = arg[1]
        elif isinstance(node, list):
            node.append(arg[1])
        return document
    if parent is None:
        return document
    if kind == "drop":
        del parent[path[-1]]
    elif kind == "raw":
        raws.append(arg)
        parent[path[-1]] = _RAW.format(len(raws) - 1)
    else:
        parent[path[-1]] = arg
    return document


def _edits(document: Any, fragments: st.SearchStrategy[str]) -> st.SearchStrategy[list[_Edit]]:
    paths = _paths(document)
    names = sorted({p[-1] for p in paths if p and isinstance(p[-1], str)})
    keys = st.sampled_from(names) if names else st.text()
    edit = st.one_of(
        st.tuples(st.just("set"), st.sampled_from(paths), _values),
        st.tuples(st.just("drop"), st.sampled_from(paths[1:] or paths), st.none()),
        st.tuples(st.just("add"), st.sampled_from(paths), st.tuples(keys | st.text(), _values)),
        st.tuples(st.just("raw"), st.sampled_from(paths), fragments),
    )
    return st.lists(edit, min_size=1, max_size=3)


_damage = st.lists(
    st.tuples(
        st.integers(0, 2**20), st.sampled_from(["flip", "drop", "insert"]), st.integers(1, 255)
    ),
    max_size=2,
)


def _damaged(data: bytes, damage: Sequence[tuple[int, str, int]]) -> bytes:
    out = bytearray(data)
    for at, kind, byte in damage:
        if not out:
            break
        i = at % len(out)
        if kind == "flip":
            out[i] ^= byte
        elif kind == "drop":
            del out[i]
        else:
            out.insert(i, byte)
    return bytes(out)


def _render_yaml(document: Any, raws: list[str]) -> bytes:
    text = yaml.safe_dump(document, sort_keys=False, allow_unicode=True, width=1 << 20)
    for i, raw in enumerate(raws):
        text = text.replace(_RAW.format(i), raw)
    return text.encode("utf-8", errors="surrogateescape")


def _render_json(document: Any, raws: list[str]) -> bytes:
    text = json.dumps(document, indent=1)
    for i, raw in enumerate(raws):
        text = text.replace(json.dumps(_RAW.format(i)), raw)
    return text.encode("utf-8", errors="surrogateescape")


def _mutations(
    seeds: Sequence[Any],
    fragments: st.SearchStrategy[str],
    render: Callable[[Any, list[str]], bytes],
) -> st.SearchStrategy[bytes]:
    """Files made from a seed document by a few edits (a value of the wrong type, NaN, a huge
    number, a key missing or extra, a raw fragment: aliases, deep nesting), then perhaps a byte
    flipped, dropped or inserted."""

    def make(args: tuple[Any, list[_Edit], list[tuple[int, str, int]]]) -> bytes:
        seed, edits, damage = args
        document, raws = copy.deepcopy(seed), []
        for edit in edits:
            document = _edit(document, edit, raws)
        return _damaged(render(document, raws), damage)

    return st.sampled_from(list(seeds)).flatmap(
        lambda seed: st.tuples(st.just(seed), _edits(seed, fragments), _damage).map(make)
    )


@functools.cache
def scenario_seeds() -> tuple[Any, ...]:
    """The scenarios of scenarios/, as documents; `extends` made absolute (the files are written
    elsewhere)."""
    out = []
    for path in sorted((ROOT / "scenarios").glob("*.yaml")):
        document = yaml.safe_load(path.read_text(encoding="utf-8"))
        if "extends" in document:
            document["extends"] = str(path.parent / document["extends"])
        out.append(document)
    return tuple(out)


@functools.cache
def sweep_seeds() -> tuple[Any, ...]:
    """The sweeps of studies/ (scenario paths made absolute), and one of them as a random sample
    (the other kind of sweep)."""
    out = []
    for path in sorted((ROOT / "studies").glob("*.yaml")):
        document = yaml.safe_load(path.read_text(encoding="utf-8"))
        document["scenario"] = str((path.parent / document["scenario"]).resolve())
        out.append(document)
    sample = {k: v for k, v in out[0].items() if k != "grid"}
    sample["random"] = {
        "n": 3,
        "seed": 7,
        "params": {
            "controller.translation.slope": {"uniform": [0.008, 0.02]},
            "estimator.hand_force_kalman.q[1]": {"log_uniform": [1.0, 1000.0]},
            "estimator.filter": {"choice": ["kalman", "one_euro"]},
        },
    }
    return (*out, sample)


@functools.cache
def rig_seeds() -> tuple[Any, ...]:
    """The rig file of `hoh_cosim.hardware.config`'s docstring (its `{...}` sections empty), and
    the same without a probe sensor."""
    from hoh_cosim.hardware import config

    lines = [line[4:] for line in (config.__doc__ or "").splitlines() if line.startswith("    ")]
    document = yaml.safe_load("\n".join(lines).replace("{...}", "{}"))
    return (document, {**document, "probe": None})


def _load_result(
    ws: Workspace,
    suffix: str,
    data: bytes,
    load: Callable[[Path], Any],
    seconds: float | None = None,
) -> Any:
    """Load the file `data` with `load` (within `seconds`, by default the workspace's bound): its
    result, or None after a good `HohError`."""
    path = ws.file(suffix, data)
    try:
        with within(f"loading {path.name}", ws.hang_s if seconds is None else seconds):
            return load(path)
    except HohError as exc:
        one_line_error(exc, path)
        return None


def check_scenario(ws: Workspace, data: bytes) -> None:
    from hoh_cosim.cosim.scenario import load_scenario

    _load_result(ws, ".yaml", data, load_scenario)


SWEEP_VARIANT_S = 0.1
"""[s] What checking one variant of a sweep may take: a load of the scenario per varied key."""


def check_sweep(ws: Workspace, data: bytes) -> None:
    """A sweep is checked variant by variant before it runs: in time in proportion to them."""
    from hoh_cosim.study.sweep import load_sweep

    seconds = ws.hang_s + SWEEP_VARIANT_S * _variants(data)
    _load_result(ws, ".yaml", data, load_sweep, seconds)


def _variants(data: bytes) -> int:
    """How many variants a sweep file asks for, as far as its YAML tells (at most `MAX_RUNS`)."""
    from hoh_cosim.study.sweep import MAX_RUNS

    try:
        document = yaml.safe_load(data)
    except (yaml.YAMLError, ValueError, RecursionError):
        return 1
    if not isinstance(document, dict):
        return 1
    seeds = document.get("seeds")
    count = len(seeds) if isinstance(seeds, list) else 1
    grid, sample = document.get("grid"), document.get("random")
    if isinstance(grid, dict):
        count *= math.prod(len(v) if isinstance(v, list) else 1 for v in grid.values())
    elif isinstance(sample, dict) and isinstance(sample.get("n"), int):
        count *= max(1, sample["n"])
    return min(count, MAX_RUNS)


def check_rig(ws: Workspace, data: bytes) -> None:
    from hoh_cosim.hardware.config import load_config

    _load_result(ws, ".yaml", data, load_config)


# --- POSES.csv and calibration.json --------------------------------------------------------------

POSES = ROOT / "tests" / "data" / "poses_seed_tool.csv"
_NASTY_CELLS = [
    "",
    " ",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e999",
    "1e200",
    "-1e308",
    "1e-320",
    "x",
    '"',
    '"1"',
    "0x10",
    "1_0",
    "\x00",
    "9" * 400,
    "1" * 140_000,
    "é",
    " 1 ",
    "+1",
    "rx",
]


def _poses_strategy(ws: Workspace | None) -> st.SearchStrategy[bytes]:
    rows = [line.split(",") for line in POSES.read_text(encoding="utf-8").splitlines()]
    cells = st.sampled_from(_NASTY_CELLS) | st.floats().map(repr) | st.text(max_size=8)
    where = st.tuples(st.integers(0, len(rows) - 1), st.integers(0, 9))
    edit = st.one_of(
        st.tuples(st.just("cell"), where, cells),
        st.tuples(st.just("drop_row"), where, st.none()),
        st.tuples(st.just("copy_row"), where, st.none()),
        st.tuples(st.just("drop_cell"), where, st.none()),
        st.tuples(st.just("add_cell"), where, cells),
        st.tuples(st.just("keep_rows"), where, st.none()),
    )

    def make(args: tuple[list[tuple[str, tuple[int, int], Any]], str, str, list]) -> bytes:
        edits, ending, start, damage = args
        table = [list(r) for r in rows]
        for kind, (r, c), cell in edits:
            if not table:
                break
            row = table[r % len(table)]
            if kind == "cell" and row:
                row[c % len(row)] = cell
            elif kind == "drop_row":
                del table[r % len(table)]
            elif kind == "copy_row":
                table.insert(r % len(table), list(row))
            elif kind == "drop_cell" and row:
                del row[c % len(row)]
            elif kind == "add_cell":
                row.insert(c % (len(row) + 1), cell)
            elif kind == "keep_rows":
                del table[r % len(table) + 1 :]
        text = start + ending.join(",".join(row) for row in table) + ending
        return _damaged(text.encode("utf-8", errors="surrogateescape"), damage)

    return st.tuples(
        st.lists(edit, min_size=1, max_size=3),
        st.sampled_from(["\n", "\r\n", "\r", "\n\n"]),
        st.sampled_from(["", "\ufeff", "\n"]),
        _damage,
    ).map(make)


def check_poses(ws: Workspace, data: bytes) -> None:
    """The poses read back are finite rotations and wrenches; identifying the tool from them
    refuses with an IdentificationError at worst (identify-gravity names the file then)."""
    from hoh_cosim.calibration import read_poses_csv
    from hoh_cosim.control.gravity import identify_gravity

    poses = _load_result(ws, ".csv", data, read_poses_csv)
    if poses is None:
        return
    R_BS, wrench = poses
    n = len(wrench)
    if R_BS.shape != (n, 3, 3) or wrench.shape != (n, 6) or n == 0:
        raise InvariantError(f"poses of shapes {R_BS.shape} and {wrench.shape}")
    if not (np.all(np.isfinite(R_BS)) and np.all(np.isfinite(wrench))):
        raise InvariantError("poses that are not finite")
    with contextlib.suppress(IdentificationError), within("identifying", ws.hang_s):
        identify_gravity(R_BS, wrench)


@functools.cache
def calibration_seed() -> dict[str, Any]:
    """calibration.json as `identify-gravity` writes it for the reference poses."""
    from hoh_cosim.calibration import calibration_to_dict, read_poses_csv
    from hoh_cosim.control.gravity import identify_gravity

    return json.loads(json.dumps(calibration_to_dict(identify_gravity(*read_poses_csv(POSES)))))


def check_calibration(ws: Workspace, data: bytes) -> None:
    from hoh_cosim.calibration import read_calibration

    _load_result(ws, ".json", data, read_calibration)


# --- session logs and replay ---------------------------------------------------------------------


def check_session(ws: Workspace, data: bytes) -> None:
    """Read and replay a session log. One cut short, or with a byte flipped, of the workspace's
    seed gives a prefix of the seed's messages on every channel."""
    from hoh_cosim.hardware.replay import replay
    from hoh_cosim.hardware.session_log import read_session

    session = _load_result(ws, ".mcap", data, read_session)
    if session is None:
        return
    seed = ws.session_seed.read_bytes()
    cut = len(data) < len(seed) and seed.startswith(data)
    flipped = len(data) == len(seed) and sum(a != b for a, b in zip(data, seed, strict=True)) == 1
    if cut or flipped:
        for topic, messages in session.messages.items():
            original = ws.session_messages.get(topic, [])
            if messages != original[: len(messages)]:
                raise InvariantError(f"{topic}: messages that the seed log does not begin with")
        if cut and session.complete and len(data) < len(seed) - 8:  # 8: the closing magic
            raise InvariantError("a log cut short was read as complete")
    _load_result(ws, ".mcap", data, replay)


def session_cuts(ws: Workspace, count: int) -> list[int]:
    """Where to cut the seed log: the edges of every record (where a reader's state changes) and
    `count` offsets spread over the file."""
    from mcap.stream_reader import StreamReader

    data = ws.session_seed.read_bytes()
    edges = {0, 8, len(data) - 8, len(data) - 1}
    with ws.session_seed.open("rb") as stream:
        reader = StreamReader(stream, emit_chunks=True)
        for _ in reader.records:
            edges.add(stream.tell())
    near = {e + d for e in edges for d in (-1, 0, 1)}
    spread = set(np.linspace(0, len(data) - 1, count).astype(int).tolist())
    return sorted(x for x in near | spread if 0 <= x < len(data))


def _session_strategy(ws: Workspace) -> st.SearchStrategy[bytes]:
    data = ws.session_seed.read_bytes()
    cut = st.integers(0, len(data) - 1).map(lambda n: data[:n])
    flip = st.tuples(st.integers(0, len(data) - 1), st.integers(1, 255)).map(
        lambda f: data[: f[0]] + bytes([data[f[0]] ^ f[1]]) + data[f[0] + 1 :]
    )
    return cut | flip | _damage.map(lambda d: _damaged(data, d))


# --- the registry ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Target:
    """One thing to fuzz: its inputs (structured, raw) and its invariants (`check`)."""

    name: str
    what: str
    check: Callable[[Workspace, Any], None]
    strategy: Callable[[Any], st.SearchStrategy[Any]]  # given the workspace (some need none)
    decode: Callable[[bytes], Any]  # raw bytes (atheris) -> an input
    corpus: Callable[[Workspace], list[bytes]]  # atheris' first inputs, raw
    suffix: str  # a failing input is saved as a file of this kind; ".txt": a Python literal
    modules: tuple[str, ...]  # the code atheris instruments for its coverage
    tokens: tuple[bytes, ...] = field(default=())  # atheris' dictionary

    def save(self, value: Any) -> bytes:
        return repr(value).encode() if self.suffix == ".txt" else bytes(value)

    def load(self, data: bytes) -> Any:
        return ast.literal_eval(data.decode()) if self.suffix == ".txt" else data


def _file_target(
    name: str,
    what: str,
    check: Callable[[Workspace, Any], None],
    strategy: Callable[[Any], st.SearchStrategy[bytes]],
    corpus: Callable[[Workspace], list[bytes]],
    suffix: str,
    modules: tuple[str, ...],
    tokens: tuple[bytes, ...],
) -> Target:
    return Target(name, what, check, strategy, bytes, corpus, suffix, modules, tokens)


_YAML_TOKENS = (
    b"&a ",
    b"*a",
    b"<<: ",
    b"[",
    b"]",
    b"{",
    b"}",
    b".nan",
    b".inf",
    b"!!",
    b"- ",
    b": ",
)
TARGETS: dict[str, Target] = {
    t.name: t
    for t in (
        Target(
            "ft150",
            "FT-150 stream parser: samples around garbage, any chunking",
            check_ft150,
            _ft150_strategy,
            _ft150_decode,
            lambda ws: [b"\x05\x03abc\x02()", b"\x01\x0a( 1 , 2 , 3"],
            ".txt",
            ("hoh_cosim.hardware.ft150",),
            (b"(", b")", b",", b"nan", b"inf", b"e-"),
        ),
        Target(
            "fse103",
            "FSE103 frame parser: frames around garbage, both framings and byte orders",
            check_fse103,
            _fse103_strategy,
            _fse103_decode,
            lambda ws: [b"\x04\x07\x05\x00\xff\x0d\x14\x66", b"\x01\x13\x00"],
            ".txt",
            ("hoh_cosim.hardware.fse103",),
            (b"\x00", b"\xff", b"\x0d\x14\x66", b"\x0d\x14\x72"),
        ),
        Target(
            "rtde",
            "UR controller emulator, RTDE port: any client bytes",
            check_rtde,
            _rtde_strategy,
            _whole_input,
            _rtde_corpus,
            ".txt",
            ("hoh_cosim.rehearsal.rtde_protocol", "hoh_cosim.rehearsal.ur_controller"),
            tuple(bytes([k]) for k in b"VvOISPUM"),
        ),
        Target(
            "dashboard",
            "UR controller emulator, dashboard port: any client bytes",
            check_dashboard,
            _dashboard_strategy,
            _whole_input,
            lambda ws: [("\n".join(_DASHBOARD_COMMANDS[:-1]) + "\n").encode()],
            ".txt",
            ("hoh_cosim.rehearsal.ur_controller",),
            (*(c.encode() for c in _DASHBOARD_COMMANDS), b"\n", b"\r\n"),
        ),
        _file_target(
            "scenario",
            "scenario YAML (load_scenario)",
            check_scenario,
            lambda ws: _mutations(scenario_seeds(), _YAML_FRAGMENTS, _render_yaml),
            lambda ws: [_render_yaml(s, []) for s in scenario_seeds()],
            ".yaml",
            ("hoh_cosim.cosim.scenario", "hoh_cosim.yamlfile", "hoh_cosim.params", "yaml"),
            _YAML_TOKENS,
        ),
        _file_target(
            "sweep",
            "sweep YAML (load_sweep)",
            check_sweep,
            lambda ws: _mutations(sweep_seeds(), _YAML_FRAGMENTS, _render_yaml),
            lambda ws: [_render_yaml(s, []) for s in sweep_seeds()],
            ".yaml",
            ("hoh_cosim.study.sweep", "hoh_cosim.yamlfile", "yaml"),
            _YAML_TOKENS,
        ),
        _file_target(
            "rig",
            "rig YAML (load_config)",
            check_rig,
            lambda ws: _mutations(rig_seeds(), _YAML_FRAGMENTS, _render_yaml),
            lambda ws: [_render_yaml(s, []) for s in rig_seeds()],
            ".yaml",
            ("hoh_cosim.hardware.config", "hoh_cosim.yamlfile", "hoh_cosim.params", "yaml"),
            _YAML_TOKENS,
        ),
        _file_target(
            "poses",
            "static-pose CSV (read_poses_csv, identify_gravity)",
            check_poses,
            _poses_strategy,
            lambda ws: [POSES.read_bytes()],
            ".csv",
            ("hoh_cosim.calibration", "csv"),
            (b",", b"\n", b"nan", b"inf", b"e308", b'"', b"\xef\xbb\xbf"),
        ),
        _file_target(
            "calibration",
            "calibration.json (read_calibration)",
            check_calibration,
            lambda ws: _mutations([calibration_seed()], _JSON_FRAGMENTS, _render_json),
            lambda ws: [_render_json(calibration_seed(), [])],
            ".json",
            ("hoh_cosim.calibration", "json"),
            (b"[", b"{", b'"', b"NaN", b"Infinity", b"e999", b"null"),
        ),
        _file_target(
            "session",
            "MCAP session log (read_session, replay)",
            check_session,
            _session_strategy,
            lambda ws: [ws.session_seed.read_bytes()],
            ".mcap",
            ("hoh_cosim.hardware.session_log", "hoh_cosim.hardware.replay", "mcap"),
            (),
        ),
    )
}
