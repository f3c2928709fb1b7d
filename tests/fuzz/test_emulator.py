"""The emulated UR controller as a server facing any client bytes, RTDE and dashboard: no thread
of it dies, it answers in whole packages or lines and closes the connection once the client is
done, and serves a well-behaved client next (`tests.fuzz.targets`). The controller runs in this
process, in front of an arm at rest, so that an exception in one of its threads is seen."""

from __future__ import annotations

import os
import socket
import struct
import time

from hypothesis import example, given
from universal_robots_clients.dashboard_client import send_command

from hoh_cosim.rehearsal import rtde_protocol as rtde
from tests.fuzz.targets import TARGETS, bounded, within
from tests.rtde_guide_client import GuideClient

RTDE = TARGETS["rtde"]
DASHBOARD = TARGETS["dashboard"]
V2 = rtde.pack("V", struct.pack(">H", 2))


@bounded(100)
@given(value=RTDE.strategy(None))
# the smallest double as an output frequency: floor(rate / f) overflowed and ended the thread
@example(value=(V2 + rtde.pack("O", struct.pack(">d", 5e-324) + b"timestamp"), ()))
@example(value=(V2 + rtde.pack("O", struct.pack(">d", 125.0) + b"a," * 30000), (7,)))
@example(value=(struct.pack(">HB", 65535, ord("U")) + b"\x01", ()))  # a huge size, cut short
@example(value=(b"".join(rtde.pack("I", b"input_int_register_1") for _ in range(300)), ()))
def test_rtde_survives_any_client(workspace, value):
    RTDE.check(workspace, value)


@bounded(100)
@given(value=DASHBOARD.strategy(None))
@example(value=(b"", ()))  # the client closes at once: so must the server
@example(value=(b"robotmode\nquit\nrobotmode\n", ()))  # nothing is answered after quit
@example(value=(b"\xff\xfe\n\r\n" + b"x" * 5000 + b"\n", (3,)))
def test_dashboard_survives_any_client(workspace, value):
    DASHBOARD.check(workspace, value)


def test_a_dashboard_line_without_end_costs_bounded_memory_and_time(workspace):
    """50 MB without a line ending, then one: a single unknown command, answered at once (the
    server kept the whole line, and copied it at every read)."""
    controller = workspace.controller
    with (
        within("a 50 MB line", workspace.hang_s),
        socket.create_connection((controller.host, controller.ports["dashboard"])) as sock,
    ):
        reader = sock.makefile("rb")
        assert reader.readline() == b"Connected: Universal Robots Dashboard Server\n"
        for _ in range(800):
            sock.sendall(b"x" * 65536)
        sock.sendall(b"\nget robot model\n")
        reply = reader.readline()
        assert reply.startswith(b"could not understand: 'xxxx")
        assert len(reply) < 5000
        assert reader.readline() == b"UR5\n"


def test_every_connection_ends_closed_leaving_no_descriptor_behind(workspace):
    """100 clients of each port come and go: the controller holds no socket of theirs after."""
    controller = workspace.controller
    host, ports = controller.host, controller.ports

    def descriptors() -> int:
        return len(os.listdir("/proc/self/fd"))

    send_command(host, "get robot model", ports["dashboard"])  # the first use: imports, threads
    with GuideClient(host, ports["rtde"]) as client:
        assert client.request_version(2)
    before = descriptors()
    for _ in range(100):
        assert send_command(host, "get robot model", ports["dashboard"]) == "UR5"
        with GuideClient(host, ports["rtde"]) as client:
            assert client.request_version(2)
        with socket.create_connection((host, ports["script"])) as script:
            script.sendall(b"textmsg(1)\n")
    # the last clients' handlers end; one just accepted may still be starting, and a thread that
    # another thread started is listed before join() accepts it: wait until none is listed
    deadline = time.monotonic() + workspace.hang_s
    while controller.handlers() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert descriptors() <= before + 2
