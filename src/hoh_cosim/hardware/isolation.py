"""A session in a child process, so that a native library's crash cannot take our exit status.

After a lost link, ur-rtde (1.6) starts reconnecting on threads of its own; racing our shutdown, or
in its destructors at the interpreter's exit, one of them can throw where nothing catches it, and
the C++ runtime aborts the whole process (SIGABRT; once in 30 dropped-link runs of `hw campaign`,
SIGSEGV in earlier ones), after the session has stopped, named its cause and closed its log. The
process then ends with a signal instead of the session's status, and a lab script that runs
sessions reads a crash.

`in_child` runs the session in a fork of this process. The child does all the work (the robot, the
sensors, the log) and, once done, reports its status through a pipe and ends at once with
`os._exit`, leaving ur-rtde's threads and destructors no interpreter exit to crash in. The parent
waits for it:

- a status reported: the process exits with it, whatever ended the child afterwards (said in a
  note when it was a signal);
- an exception that the command line reports (a `HohError`, Ctrl-C before the session began): sent
  to the parent and raised there, so the message and status are the command line's own;
- the child killed before reporting: one line naming the signal, status 1 (the robot's watchdog
  stops the arm; the log's writer closes the log with an `end` event of its own).

The child dies with its parent (`PR_SET_PDEATHSIG`): a SIGKILL to the process that a user or a
script started still ends the session at once, as it would without the fork. Ctrl-C at a terminal
reaches both (they share the process group): the child stops its session, the parent ignores it;
a SIGINT or SIGTERM sent to the parent alone (by `kill`) is passed on to the child.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import traceback
from collections.abc import Callable

from hoh_cosim.errors import HohError, RunError, io_failure

__all__ = ["ends_without_cleanup", "in_child"]

_PR_SET_PDEATHSIG = 1
_SI_KERNEL = 0x80  # si_code of a signal the kernel sent: a terminal's Ctrl-C
_FORWARDED = {signal.SIGINT, signal.SIGTERM}
_STATUS = b"S"  # then the status in decimal
# then the message: what the command line reports of each as it would have in this process
_RAISED = {b"R": RunError, b"H": HohError, b"K": KeyboardInterrupt}
_in_child = False  # this process is a child of in_child: it ends with os._exit


def ends_without_cleanup() -> bool:
    """Whether this process is `in_child`'s child, which ends with `os._exit` once its work is
    done: what it leaves open (a socket, a native library's object) goes with the process, without
    a destructor or an interpreter exit to run."""
    return _in_child


def in_child(work: Callable[[], int]) -> int:
    """`work()` in a forked child; its status, or its reportable exception raised here."""
    if not hasattr(os, "fork"):
        return work()
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    report_r, report_w = os.pipe()
    parent = os.getpid()
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, _FORWARDED)
    pid = os.fork()
    if pid == 0:  # the child: never returns
        os.close(report_r)
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        _die_with_parent(parent)
        _child(work, report_w)
    os.close(report_w)
    try:
        wait_status = _wait(pid)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
    with os.fdopen(report_r, "rb") as report:
        kind, payload = report.read(1), report.read()
    died = os.WIFSIGNALED(wait_status)
    if kind in _RAISED:
        raise _RAISED[kind](payload.decode("utf-8", "replace"))
    if kind == _STATUS:
        status = int(payload)
        if died:
            print(
                f"note: the session's process ended with {_signal_name(wait_status)} after the "
                f"session had ended (ur-rtde's threads); the session's status {status} stands",
                file=sys.stderr,
            )
        return status
    if died:
        print(
            f"hoh-cosim: the session's process died of {_signal_name(wait_status)} before the "
            "session ended (the robot's watchdog stops the arm; the log is closed by its writer)",
            file=sys.stderr,
        )
        return 1
    return os.waitstatus_to_exitcode(wait_status)


def _child(work: Callable[[], int], report_w: int) -> None:
    global _in_child
    _in_child = True
    report, status = b"S1", 1
    try:
        status = work()
        report = _STATUS + str(status).encode()
    except (HohError, OSError, KeyboardInterrupt) as exc:  # the command line's to report
        if isinstance(exc, OSError):
            exc = io_failure(exc)
        kind = b"R" if isinstance(exc, RunError) else b"H" if isinstance(exc, HohError) else b"K"
        report = kind + str(exc).encode("utf-8", "replace")[:4000]  # within a pipe's atomic write
    except BaseException:  # a bug: its traceback here, where it happened
        traceback.print_exc()
    finally:
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
        with contextlib.suppress(OSError):
            os.write(report_w, report)
        os._exit(status)


def _wait(pid: int) -> int:
    """Wait for the child, passing on what was sent to this process alone."""
    while True:
        info = signal.sigtimedwait(_FORWARDED, 0.05)
        if info is not None and info.si_code != _SI_KERNEL:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, info.si_signo)
        done, wait_status = os.waitpid(pid, os.WNOHANG)
        if done:
            return wait_status


def _die_with_parent(parent: int) -> None:
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:  # the parent died before the call
        os._exit(1)


def _signal_name(wait_status: int) -> str:
    number = os.WTERMSIG(wait_status)
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"
