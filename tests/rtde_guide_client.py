"""A minimal RTDE client written from Universal Robots' RTDE guide alone, for testing the emulated
controller against a client that shares no code with it.

From the guide: port 30004; every package is `>HB` (size including the 3-byte header, type) and a
payload; 'V' asks for a protocol version (uint16; answer uint8 accepted); 'O' sets up the outputs
(version 2: double frequency, then the comma-separated names; version 1: the names only; answer:
version 2 uint8 recipe id then the types, version 1 the types only); 'S' starts and 'P' pauses
(answer uint8 accepted); 'U' carries data (version 2 outputs: uint8 recipe id first; version 1
outputs: none); 'M' is a text message (from the controller in version 2: uint8 length + message,
uint8 length + source, uint8 level; in version 1: uint8 level + message; from a client: the
version 2 layout).
"""

from __future__ import annotations

import socket
import struct
import time
from typing import Any

TYPE_FORMATS = {
    "BOOL": "?",
    "UINT8": "B",
    "UINT32": "I",
    "UINT64": "Q",
    "INT32": "i",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}


class GuideClient:
    def __init__(self, host: str, port: int = 30004, timeout_s: float = 5.0) -> None:
        self.sock = socket.create_connection((host, port), timeout=timeout_s)
        self.version = 1
        self.types: list[str] = []
        self.messages: list[tuple[Any, ...]] = []  # text messages seen while waiting

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> GuideClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- packages ---

    def send(self, kind: str, payload: bytes = b"") -> None:
        self.sock.sendall(struct.pack(">HB", 3 + len(payload), ord(kind)) + payload)

    def _exact(self, n: int) -> bytes:
        data = b""
        while len(data) < n:
            chunk = self.sock.recv(n - len(data))
            if not chunk:
                raise ConnectionError("the controller closed the connection")
            data += chunk
        return data

    def receive(self) -> tuple[str, bytes]:
        size, kind = struct.unpack(">HB", self._exact(3))
        return chr(kind), self._exact(size - 3)

    def answer(self, kind: str) -> bytes:
        """The next package of `kind`; text messages on the way are kept in `messages`."""
        while True:
            got, payload = self.receive()
            if got == kind:
                return payload
            if got == "M":
                self.messages.append(self.parse_text(payload))

    def parse_text(self, payload: bytes) -> tuple[Any, ...]:
        if self.version == 1:
            return (payload[0], payload[1:].decode())
        n = payload[0]
        message = payload[1 : 1 + n].decode()
        m = payload[1 + n]
        source = payload[2 + n : 2 + n + m].decode()
        return (message, source, payload[2 + n + m])

    # --- the guide's requests ---

    def request_version(self, version: int) -> bool:
        self.send("V", struct.pack(">H", version))
        accepted = self.answer("V")[0] == 1
        if accepted:
            self.version = version
        return accepted

    def setup_outputs(self, names: list[str], frequency: float = 125.0) -> tuple[int | None, list]:
        """(recipe id, or None in version 1; the types the controller gave)."""
        text = ",".join(names).encode()
        self.send("O", (struct.pack(">d", frequency) + text) if self.version == 2 else text)
        reply = self.answer("O")
        recipe, types = (reply[0], reply[1:]) if self.version == 2 else (None, reply)
        self.types = types.decode().split(",")
        return recipe, self.types

    def start(self) -> bool:
        self.send("S")
        return self.answer("S")[0] == 1

    def pause(self) -> bool:
        self.send("P")
        return self.answer("P")[0] == 1

    def text(self, message: str, source: str = "guide client", level: int = 3) -> None:
        m, s = message.encode(), source.encode()
        self.send("M", bytes([len(m)]) + m + bytes([len(s)]) + s + bytes([level]))

    def latest(self, seconds: float) -> list[Any]:
        """The values of the last output data package received over `seconds`."""
        deadline = time.monotonic() + seconds
        values = self.outputs()
        while time.monotonic() < deadline:
            values = self.outputs()
        return values

    def outputs(self) -> list[Any]:
        """The values of the next output data package, vectors as lists."""
        payload = self.answer("U")
        if self.version == 2:
            payload = payload[1:]
        layout = ">" + "".join(TYPE_FORMATS[t] for t in self.types)
        flat = list(struct.unpack(layout, payload))
        values: list[Any] = []
        for t in self.types:
            n = int(TYPE_FORMATS[t][:-1] or 1)
            values.append(flat[0] if n == 1 else flat[:n])
            del flat[:n]
        return values
