"""What the serial probe sensors share: a port (or a pyserial URL) read by a thread, reconnected.

`SerialSource` is the transport of `hoh_cosim.hardware.fse103.FSE103Port` and
`hoh_cosim.hardware.loadcell.LoadCellPort`: it opens the port in a `ReaderThread`, hands every
chunk read to the subclass's `_handle` (which parses it and publishes to the `Mailbox`), records why
the device went away in `mailbox.error` and, with `reconnect`, opens it again every `retry_s`.
`stop()` cancels a read in progress, so it returns at once whatever `timeout_s` is; a source can be
started again after `stop()` and is usable as a context manager.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Any, TypeVar

from hoh_cosim.control.vectors import as_scalar
from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.hardware.streams import Mailbox, ReaderThread

__all__ = ["SerialSource"]


_Source = TypeVar("_Source", bound="SerialSource")


class SerialSource:
    """A serial device read by a thread; subclasses give `describe` and `_handle`, and their parser
    (`_parser`, with `pending_bytes` and `reset()`) is reset on every new connection."""

    _parser: Any

    def __init__(
        self,
        device: str,
        *,
        baudrate: int = 115200,
        mailbox: Mailbox | None = None,
        reconnect: bool = True,
        retry_s: float = 0.5,
        timeout_s: float = 0.1,
    ) -> None:
        if not isinstance(device, str) or not device:
            raise ConfigError(f"device: expected a port name or pyserial URL, got {device!r}")
        if isinstance(baudrate, bool) or not isinstance(baudrate, int) or baudrate <= 0:
            raise ConfigError(f"baudrate: expected a positive integer, got {baudrate!r}")
        self.device = device
        self.baudrate = baudrate
        self.reconnect = reconnect
        self.retry_s = as_scalar(retry_s, "retry_s", low=0.0)
        self.timeout_s = as_scalar(timeout_s, "timeout_s", low=0.0, low_open=True)
        self._mailbox = mailbox if mailbox is not None else Mailbox()
        self._serial: Any = None
        # _lock guards the reference and short calls (write, cancel_read, close); _read_lock is held
        # for a whole read, so the port is never closed under a read in progress.
        self._lock = threading.Lock()
        self._read_lock = threading.Lock()
        self._thread: ReaderThread | None = None

    @property
    def mailbox(self) -> Mailbox:
        return self._mailbox

    @property
    def connected(self) -> bool:
        return self._thread is not None and self._thread.connected.is_set()

    def describe(self) -> str:
        raise NotImplementedError

    def _handle(self, data: bytes) -> None:
        """Parse `data` and publish what it completes."""
        raise NotImplementedError

    def _connected(self) -> None:
        """A new connection is open: the parser's state of the old one is stale, and a frame or
        line the old one left unfinished counts as one bad."""
        if self._parser.pending_bytes:
            self._mailbox.count_bad(1)
        self._parser.reset()

    def start(self) -> None:
        """Start reading in the background (a second call while running does nothing)."""
        if self._thread is not None and self._thread.is_alive():
            return
        try:
            import serial  # noqa: F401
        except ImportError:
            raise RunError(
                f"{self.describe()}: needs pyserial (pip install 'hoh-cosim[hardware]')"
            ) from None
        self._thread = ReaderThread(
            self.describe(),
            self._mailbox,
            self._connect,
            self._read,
            self._handle,
            self._close,
            reconnect=self.reconnect,
            retry_s=self.retry_s,
        )
        self._thread.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop reading and close the port; returns within about `timeout_s`."""
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.stop(timeout_s)
        self._close()

    def _send(self, command: bytes) -> None:
        import serial

        with self._lock:
            port = self._serial
            if port is None:
                raise RunError(f"{self.describe()}: not connected, cannot send {command!r}")
            try:
                port.write(command)
            except (serial.SerialException, OSError) as exc:
                raise RunError(f"{self.describe()}: cannot send {command!r}: {exc}") from None

    def __enter__(self: _Source) -> _Source:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    # The ReaderThread's callbacks.

    def _connect(self) -> None:
        import serial

        try:
            if "://" in self.device:
                port = serial.serial_for_url(
                    self.device,
                    baudrate=self.baudrate,
                    timeout=self.timeout_s,
                    write_timeout=self.timeout_s,
                )
            else:
                port = serial.Serial(
                    self.device,
                    self.baudrate,
                    timeout=self.timeout_s,
                    write_timeout=self.timeout_s,
                )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ConnectionError(f"{self.describe()}: cannot open: {exc}") from None
        self._connected()
        with self._lock:
            self._serial = port

    def _read(self) -> bytes | None:
        import serial

        with self._read_lock:
            port = self._serial
            if port is None:
                raise ConnectionError(f"{self.describe()}: the port is closed")
            try:
                waiting = port.in_waiting
                data = port.read(min(max(1, waiting), 4096))
            except (serial.SerialException, OSError) as exc:
                raise ConnectionError(f"{self.describe()}: connection lost: {exc}") from None
        return data or None  # nothing within the timeout, or the read was cancelled by stop()

    def _close(self) -> None:
        with self._lock:
            port = self._serial
            if port is not None and hasattr(port, "cancel_read"):
                with contextlib.suppress(OSError):
                    port.cancel_read()  # wakes a read blocked in the reader thread
        with self._read_lock, self._lock:
            port, self._serial = self._serial, None
            if port is not None:
                with contextlib.suppress(OSError):
                    port.close()
