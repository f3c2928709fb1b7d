"""A session in a child process (`hoh_cosim.hardware.isolation.in_child`): real forks, real signals."""

from __future__ import annotations

import faulthandler
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from hoh_cosim.errors import ConfigError, HohError, RunError
from hoh_cosim.hardware.isolation import in_child


def test_the_childs_status_is_the_status():
    assert in_child(lambda: 0) == 0
    assert in_child(lambda: 1) == 1
    assert in_child(lambda: 130) == 130


def test_work_runs_in_another_process():
    parent = os.getpid()
    assert in_child(lambda: 0 if os.getpid() != parent else 1) == 0


def _raised(work) -> HohError:
    with pytest.raises(HohError) as caught:
        in_child(work)
    return caught.value


def test_an_error_for_the_command_line_is_raised_in_the_parent_with_its_message():
    def refuse() -> int:
        raise RunError("UR controller at 10.0.0.2: connection refused")

    def bad_input() -> int:
        raise ConfigError("rig.yaml: robot.host: expected text, got 5")

    def cannot_write() -> int:
        raise PermissionError(13, "Permission denied", "/nope/session.mcap")

    refused = _raised(refuse)
    assert isinstance(refused, RunError)  # status 1 at the command line
    assert str(refused) == "UR controller at 10.0.0.2: connection refused"
    bad = _raised(bad_input)
    assert not isinstance(bad, RunError)  # status 2
    assert str(bad) == "rig.yaml: robot.host: expected text, got 5"
    unwritable = _raised(cannot_write)
    assert isinstance(unwritable, RunError)
    assert str(unwritable) == "/nope/session.mcap: Permission denied"


def test_a_crash_after_the_work_cannot_change_the_status():
    # a native thread that aborts the process a moment after the work is done: the child ends
    # with os._exit first, and the status is the work's
    def work() -> int:
        faulthandler.disable()  # pytest's: its dump is not what is tested
        threading.Timer(0.2, os.abort).start()
        return 1

    started = time.monotonic()
    assert in_child(work) == 1
    assert time.monotonic() - started < 0.2 + 1.0


def test_a_child_killed_before_reporting_is_one_line_and_status_1(capfd):
    def work() -> int:
        faulthandler.disable()
        os.kill(os.getpid(), signal.SIGABRT)
        time.sleep(5)
        return 0

    assert in_child(work) == 1
    err = capfd.readouterr().err
    assert "the session's process died of SIGABRT before the session ended" in err
    assert len(err.strip().splitlines()) == 1


def _script(body: str) -> list[str]:
    code = textwrap.dedent(
        """
        import os, sys, time
        from hoh_cosim.hardware.isolation import in_child
        """
    )
    return [sys.executable, "-c", code + textwrap.dedent(body)]


def _wait_for(path, timeout_s: float = 30.0) -> str:
    deadline = time.monotonic() + timeout_s
    while not (path.exists() and path.read_text().endswith("\n")):
        assert time.monotonic() < deadline, f"{path} never written"
        time.sleep(0.02)
    return path.read_text()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_a_sigkill_to_the_parent_ends_the_child_at_once(tmp_path):
    pid_file = tmp_path / "child.pid"
    body = f"""
        def work():
            open({str(pid_file)!r}, "w").write(f"{{os.getpid()}}\\n")
            time.sleep(60)
            return 0
        sys.exit(in_child(work))
    """
    parent = subprocess.Popen(_script(body))
    try:
        child = int(_wait_for(pid_file))
        parent.send_signal(signal.SIGKILL)
        parent.wait(10)
        deadline = time.monotonic() + 5.0
        while _alive(child) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not _alive(child)
    finally:
        parent.kill()
        parent.wait()


def test_ctrl_c_sent_to_the_parent_alone_reaches_the_work(tmp_path):
    pid_file = tmp_path / "child.pid"
    body = f"""
        def work():
            open({str(pid_file)!r}, "w").write(f"{{os.getpid()}}\\n")
            try:
                time.sleep(60)
            except KeyboardInterrupt:
                print("work interrupted", flush=True)
                return 130
            return 0
        sys.exit(in_child(work))
    """
    parent = subprocess.Popen(
        _script(body),
        stdout=subprocess.PIPE,
        text=True,
        # a child of a pytest-xdist worker inherits SIGINT ignored: Python's default again
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        _wait_for(pid_file)
        parent.send_signal(signal.SIGINT)
        out, _ = parent.communicate(timeout=10)
    finally:
        parent.kill()
        parent.wait()
    assert parent.returncode == 130
    assert out == "work interrupted\n"
