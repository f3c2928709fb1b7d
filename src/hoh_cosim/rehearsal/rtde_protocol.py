"""The RTDE wire format (protocol versions 1 and 2), as a UR controller speaks it on port 30004.

Every package is a big-endian header, uint16 size (header included) and uint8 type, then a payload
(version 2; where version 1 differs, in brackets):

    'V' request protocol version   client: uint16 version        controller: uint8 accepted
    'v' get controller version     client: -                     controller: 4 x uint32
    'O' set up outputs             client: double Hz + names     controller: uint8 recipe + types
                                   [v1: names]                   [v1: types]
    'I' set up inputs              client: names                 controller: uint8 recipe + types
    'S' start / 'P' pause          client: -                     controller: uint8 accepted
    'U' data package               uint8 recipe id + the recipe's values, both ways
                                   [v1: the controller's outputs without the recipe id]
    'M' text message               uint8 length + message, uint8 length + source, uint8 level
                                   [v1, from the controller: uint8 level + message]

Names and types are comma-separated ASCII. A type the controller does not have is NOT_FOUND; an
input another client already writes is IN_USE. Facts from UR's RTDE guide; the values each variable
carries are the emulator's (`hoh_cosim.rehearsal.ur_controller`).
"""

from __future__ import annotations

import struct
from typing import Any

__all__ = [
    "INPUTS",
    "OUTPUTS",
    "Package",
    "decode_values",
    "encode_values",
    "pack",
    "parse_text_message",
    "read_package",
    "text_message",
    "zero",
]

# type name -> struct format (big-endian, no padding)
FORMATS = {
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

OUTPUTS: dict[str, str] = {
    "timestamp": "DOUBLE",
    "target_q": "VECTOR6D",
    "target_qd": "VECTOR6D",
    "target_qdd": "VECTOR6D",
    "target_current": "VECTOR6D",
    "target_moment": "VECTOR6D",
    "actual_q": "VECTOR6D",
    "actual_qd": "VECTOR6D",
    "actual_current": "VECTOR6D",
    "joint_control_output": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D",
    "actual_TCP_speed": "VECTOR6D",
    "actual_TCP_force": "VECTOR6D",
    "target_TCP_pose": "VECTOR6D",
    "target_TCP_speed": "VECTOR6D",
    "actual_digital_input_bits": "UINT64",
    "joint_temperatures": "VECTOR6D",
    "actual_execution_time": "DOUBLE",
    "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32",
    "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D",
    "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE",
    "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE",
    "actual_joint_voltage": "VECTOR6D",
    "actual_digital_output_bits": "UINT64",
    "runtime_state": "UINT32",
    "elbow_position": "VECTOR3D",
    "elbow_velocity": "VECTOR3D",
    "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32",
    "analog_io_types": "UINT32",
    "standard_analog_input0": "DOUBLE",
    "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE",
    "standard_analog_output1": "DOUBLE",
    "io_current": "DOUBLE",
    "tool_mode": "UINT32",
    "tool_analog_input_types": "UINT32",
    "tool_analog_input0": "DOUBLE",
    "tool_analog_input1": "DOUBLE",
    "tool_output_voltage": "INT32",
    "tool_output_current": "DOUBLE",
    "tool_temperature": "DOUBLE",
    "tcp_force_scalar": "DOUBLE",
    "output_bit_registers0_to_31": "UINT32",
    "output_bit_registers32_to_63": "UINT32",
    "input_bit_registers0_to_31": "UINT32",
    "input_bit_registers32_to_63": "UINT32",
    "payload": "DOUBLE",
    "payload_cog": "VECTOR3D",
    "payload_inertia": "VECTOR6D",
    "actual_current_as_torque": "VECTOR6D",
    "script_control_line": "UINT32",
    "ft_raw_wrench": "VECTOR6D",
    "joint_position_deviation_ratio": "DOUBLE",
    "collision_detection_ratio": "DOUBLE",
}
INPUTS: dict[str, str] = {
    "speed_slider_mask": "UINT32",
    "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8",
    "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8",
    "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8",
    "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8",
    "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE",
    "standard_analog_output_1": "DOUBLE",
    "input_bit_registers0_to_31": "UINT32",
    "input_bit_registers32_to_63": "UINT32",
    "external_force_torque": "VECTOR6D",
}
for _i in range(48):
    OUTPUTS[f"output_int_register_{_i}"] = "INT32"
    OUTPUTS[f"output_double_register_{_i}"] = "DOUBLE"
    OUTPUTS[f"input_int_register_{_i}"] = "INT32"
    OUTPUTS[f"input_double_register_{_i}"] = "DOUBLE"
    INPUTS[f"input_int_register_{_i}"] = "INT32"
    INPUTS[f"input_double_register_{_i}"] = "DOUBLE"
for _i in range(64, 128):
    OUTPUTS[f"output_bit_register_{_i}"] = "BOOL"
    OUTPUTS[f"input_bit_register_{_i}"] = "BOOL"
    INPUTS[f"input_bit_register_{_i}"] = "BOOL"

COUNTS = {t: struct.calcsize(">" + f) // struct.calcsize(">" + f[-1]) for t, f in FORMATS.items()}
"""How many scalars a value of each type has (a VECTOR6D has 6)."""

HEADER = struct.Struct(">HB")


class Package:
    __slots__ = ("payload", "type")

    def __init__(self, type_: int, payload: bytes) -> None:
        self.type = type_
        self.payload = payload

    @property
    def kind(self) -> str:
        return chr(self.type)


def pack(kind: str, payload: bytes = b"") -> bytes:
    return HEADER.pack(HEADER.size + len(payload), ord(kind)) + payload


LEVELS = ("exception", "error", "warning", "info")  # a text message's level, from 0


def text_message(
    message: str, source: str = "hoh-cosim", level: int = 1, version: int = 2
) -> bytes:
    """An 'M' package from the controller; level 0 exception, 1 error, 2 warning, 3 info."""
    m, s = message.encode()[:255], source.encode()[:255]
    if version == 1:
        return pack("M", bytes([level]) + message.encode())
    return pack("M", bytes([len(m)]) + m + bytes([len(s)]) + s + bytes([level]))


def parse_text_message(payload: bytes) -> tuple[str, str, int]:
    """A client's 'M' package (the same in both versions): (message, source, level);
    ValueError if the lengths do not add up."""
    if not payload:
        raise ValueError("an empty text message")
    n = payload[0]
    message, rest = payload[1 : 1 + n], payload[1 + n :]
    if len(message) != n or not rest:
        raise ValueError("a text message shorter than its message length")
    m = rest[0]
    source, rest = rest[1 : 1 + m], rest[1 + m :]
    if len(source) != m or len(rest) != 1:
        raise ValueError("a text message whose source length or level does not fit")
    return message.decode(errors="replace"), source.decode(errors="replace"), rest[0]


def _exact(sock: Any, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = sock.recv(n - len(data))
        if not chunk:
            raise ConnectionError("the client closed the connection")
        data += chunk
    return data


def read_package(sock: Any) -> Package:
    """The next package from `sock` (blocking); ConnectionError when the peer has gone."""
    size, type_ = HEADER.unpack(_exact(sock, HEADER.size))
    if size < HEADER.size:
        raise ValueError(f"package of size {size} (less than its own header)")
    return Package(type_, _exact(sock, size - HEADER.size))


def recipe_format(types: list[str]) -> struct.Struct:
    return struct.Struct(">" + "".join(FORMATS[t] for t in types))


def encode_values(recipe_id: int | None, layout: struct.Struct, values: list[Any]) -> bytes:
    """A 'U' package; `recipe_id` None: without one (a version 1 controller's outputs)."""
    flat: list[Any] = []
    for value in values:
        if isinstance(value, list | tuple):
            flat.extend(value)
        else:
            flat.append(value)
    head = b"" if recipe_id is None else bytes([recipe_id])
    return pack("U", head + layout.pack(*flat))


def decode_values(types: list[str], layout: struct.Struct, data: bytes) -> list[Any]:
    """The values of one recipe, vectors as lists; ValueError if `data` has the wrong length."""
    if len(data) != layout.size:
        raise ValueError(f"expected {layout.size} bytes of data, got {len(data)}")
    flat = layout.unpack(data)
    out: list[Any] = []
    at = 0
    for t in types:
        n = COUNTS[t]
        out.append(flat[at] if n == 1 else list(flat[at : at + n]))
        at += n
    return out


def zero(type_name: str) -> Any:
    """A value of the type that is all zeros (False for a BOOL)."""
    scalar: Any = (
        False if FORMATS[type_name] == "?" else 0.0 if FORMATS[type_name][-1] == "d" else 0
    )
    return scalar if COUNTS[type_name] == 1 else [scalar] * COUNTS[type_name]
