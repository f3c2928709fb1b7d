"""A serial line between two UARTs set to different baud rates, for rehearsing a baud mismatch.

A pseudo-terminal has no baud rate: whatever is written arrives as written. A real line carries
bits, and a receiver set to another rate than the sender's samples them at its own times. This
turns the bytes a device sends into the bytes a receiver at `read_baud` would read, 8N1 both sides:
the line idles high; the receiver waits for a falling edge (a start bit), samples it in the middle
of its own bit time and, if it is still low, reads eight data bits (least significant first) at
its own bit times after it, then the stop bit; then it waits for the next falling edge. A byte
whose stop bit reads low (a framing error) is delivered all the same, as a Linux tty in raw mode
does with its default settings.
"""

from __future__ import annotations

import math

__all__ = ["as_read_at"]


def _bits(data: bytes) -> list[int]:
    bits: list[int] = []
    for byte in data:
        bits.append(0)  # start
        bits.extend((byte >> i) & 1 for i in range(8))
        bits.append(1)  # stop
    return bits


def as_read_at(data: bytes, *, sent_baud: float, read_baud: float) -> bytes:
    """The bytes a UART at `read_baud` reads from `data` sent at `sent_baud` (8N1, no gaps)."""
    bits = _bits(data)
    t_sent, t_read = 1.0 / sent_baud, 1.0 / read_baud

    def level(t: float) -> int:
        i = math.floor(t / t_sent + 1e-9)
        return bits[i] if 0 <= i < len(bits) else 1

    out = bytearray()
    end = len(bits) * t_sent
    # the receiver looks for edges at the sender's bit boundaries (where the level can change)
    i = 0
    while i < len(bits):
        if bits[i] != 0 or (i > 0 and bits[i - 1] == 0):
            i += 1
            continue
        t0 = i * t_sent  # a falling edge
        if level(t0 + 0.5 * t_read) != 0:  # a glitch, not a start bit
            i += 1
            continue
        value = 0
        for k in range(8):
            value |= level(t0 + (1.5 + k) * t_read) << k
        out.append(value)
        t_stop = t0 + 9.5 * t_read
        if t_stop >= end:
            break
        i = math.floor(t_stop / t_sent + 1e-9) + 1  # the next edge after the stop bit's sample
    return bytes(out)
