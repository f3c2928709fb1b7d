"""The session log (hoh_cosim.hardware.session_log): a real SessionLog, its real writer process and a
real MCAP file in tmp_path, read back with read_session and with the `mcap` package's own reader.

Rows are filled as the runner fills them (CycleRow.start, CycleRow.set, SessionLog.cycle); the
expected messages are built here from the same values, field by field, not by the module's own
conversion.
"""

from __future__ import annotations

import io
import itertools
import json
import multiprocessing
import os
import re
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mcap")

from hoh_cosim.control.guidance.modes import Mode
from hoh_cosim.errors import InputFileError, RunError
from hoh_cosim.hardware.log_check import invalid_messages
from hoh_cosim.hardware.session_log import (
    CHANNELS,
    CYCLE_LAYOUT,
    FLOAT32,
    NONFINITE,
    RESOLUTION,
    T0_KEY,
    CycleRow,
    Session,
    SessionLog,
    channel_schema,
    decode_message,
    read_session,
)

ROWS = 40
DT = 0.002
CYCLE_TOPICS = ("/robot", "/ft150", "/fse103", "/estimate", "/command", "/timing")

# /command.status as the flags' values (supervisor.Status) and the status_text each must give
STATUSES = [
    (0, "ok"),
    (1, "speed clamped"),
    (1 | 1 << 10, "stale FT-150 data, speed clamped"),
    (1 << 4 | 1 << 8, "probe force above the stop limit (latched), virtual fixture engaged"),
    (1 << 12, "estimator not ready (rebiasing)"),
]
NAN_AT = {  # (row, field, element) set to NaN
    (5, "/ft150.wrench_S", 1),
    (6, "/estimate.F_hand_B", 2),
    (9, "/estimate.ft_age", 0),
    (13, "/command.sent_B", 4),
}


def has_ft(i: int) -> bool:
    return i % 3 != 0


def has_probe(i: int) -> bool:
    return i % 4 != 1


def probe_count(i: int) -> int:
    return 500 + i // 2  # a new probe sample every other row: the rows between repeat it


def probe_rows() -> list[int]:
    """The rows with an /fse103 message: a probe sample, and a new one (its count moved)."""
    rows, last = [], None
    for i in range(ROWS):
        if has_probe(i) and probe_count(i) != last:
            rows.append(i)
            last = probe_count(i)
    return rows


def at_resolution(topic: str, name: str, value: float) -> float:
    """A float as the log writes it: Python's own decimal rounding to the field's decimals, the
    shortest decimal of its float32 for a float32 field."""
    decimals = RESOLUTION.get((topic, name))
    if decimals is None:
        return float(value)
    if decimals == FLOAT32:
        return float(str(np.float32(value)))
    return round(float(value), int(decimals)) + 0.0


def kind_of(topic: str, name: str) -> str:
    for t, n, _, kind in CYCLE_LAYOUT:
        if (t, n) == (topic, name):
            return kind["type"]
    raise KeyError(f"{topic}.{name}")


def row_values(i: int) -> dict[str, Any]:
    """Row i's fields: full-precision floats, integers and booleans that differ row by row."""
    rng = np.random.default_rng(1000 + i)
    ints = {
        "/robot.robot_mode": 7,
        "/robot.safety_mode": 1 + i % 3,
        "/ft150.count": 1000 + i,
        "/fse103.count": probe_count(i),
        "/fse103.device_ms": -1 if i % 5 == 0 else 123456 + 10 * i,
        "/command.status": STATUSES[i % len(STATUSES)][0],
        "/command.mode": i % 7,
    }
    bools = {
        "/robot.protective_stop": i % 7 == 3,
        "/robot.emergency_stop": i == 11,
        "/robot.program_running": i % 2 == 0,
    }
    values: dict[str, Any] = {}
    for topic, name, size, kind in CYCLE_LAYOUT:
        key = f"{topic}.{name}"
        if kind["type"] == "array":
            values[key] = rng.normal(size=size) * 10.0 ** rng.integers(-6, 6)
        elif kind["type"] == "integer":
            values[key] = ints[key]
        elif kind["type"] == "boolean":
            values[key] = bools[key]
        else:
            values[key] = float(rng.normal()) * 1e-3
    for row, key, element in NAN_AT:
        if row == i:
            if isinstance(values[key], np.ndarray):
                values[key][element] = np.nan
            else:
                values[key] = np.nan
    return values


def expected_messages(i: int) -> dict[str, dict[str, Any]]:
    """Row i as `read_session` gives its messages back: NaN as NaN, each float at its field's
    resolution, /ft150 and /fse103 only when a new sample is there (compare them with `same`: NaN
    is not equal to itself)."""
    values = row_values(i)
    out: dict[str, dict[str, Any]] = {}
    for topic, name, _, _ in CYCLE_LAYOUT:
        if (topic == "/ft150" and not has_ft(i)) or (topic == "/fse103" and i not in probe_rows()):
            continue
        message = out.setdefault(topic, {"k": i, "t": round(i * DT, 9)})
        value = values[f"{topic}.{name}"]
        if isinstance(value, np.ndarray):
            message[name] = [at_resolution(topic, name, x) for x in value]
        elif isinstance(value, float):
            message[name] = at_resolution(topic, name, value)
        else:  # integers and booleans
            message[name] = value
    out["/command"]["status_text"] = STATUSES[i % len(STATUSES)][1]
    out["/command"]["mode_text"] = Mode(i % 7).label
    return out


def same(a: Any, b: Any) -> bool:
    """Equal, NaN counting as equal to NaN, an int never equal to a float (types matter in JSON)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float) and np.isnan(a) and np.isnan(b):
        return True
    return type(a) is type(b) and a == b


EVENTS = [
    (0, 0.0, "rebias", "FT-150 offset [1.766, -2.393] N, N·m, 199.9 Hz"),
    (2, 2 * DT, "parameters", json.dumps({"period_s": DT, "estimator": {"filter": "kalman"}})),
    (ROWS - 1, (ROWS - 1) * DT, "end", ""),
]
METADATA_IN = {
    "kind": "test",
    "period_s": DT,
    "R_TS": np.diag([1.0, -1.0, -1.0]),
    "config": Path("/rig/rig.yaml"),
    "world": {"seed": np.int64(3), "ratio": np.float64(0.25), "faults": [(1.5, "ft_stall")]},
    "note": "N·m, µ",
}
METADATA_OUT = {
    "kind": "test",
    "period_s": DT,
    "R_TS": [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
    "config": "/rig/rig.yaml",
    "world": {"seed": 3, "ratio": 0.25, "faults": [[1.5, "ft_stall"]]},
    "note": "N·m, µ",
}


def fill(row: CycleRow, i: int, values: dict[str, Any], ft: bool, probe: bool) -> None:
    row.start(i, i * DT, ft, probe)
    for name, value in values.items():
        row.set(name, value)


def fill_constant(row: CycleRow, i: int, sensors: bool = True) -> None:
    """Row i with every field i: a torn row (two rows mixed) shows as fields that differ."""
    row.start(i, float(i), sensors, sensors)
    for name in row.slices:
        row.set(name, i)


def assert_constant(message: dict[str, Any], topic: str) -> None:
    """A message of a fill_constant row: every field says the same k."""
    k = message["k"]
    assert message["t"] == float(k), message
    for name, value in message.items():
        if name in ("k", "t", "status_text", "mode_text"):
            continue
        kind = CHANNELS[topic][name]["type"]
        if kind == "array":
            assert value == [float(k)] * len(value), (topic, name, message)
        elif kind == "boolean":
            assert value is (k != 0), (topic, name, message)
        else:
            assert value == k, (topic, name, message)


def no_writer_left() -> bool:
    return not any(p.name == "session-log-writer" for p in multiprocessing.active_children())


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> Path:
    """A log of ROWS known rows and three events, closed as the runner closes it."""
    path = tmp_path_factory.mktemp("session") / "known.mcap"
    log = SessionLog(path, METADATA_IN).start()
    try:
        for i in range(ROWS):
            fill(log.row, i, row_values(i), has_ft(i), has_probe(i))
            log.cycle()
            if i in {e[0] for e in EVENTS}:
                for k, t, event, detail in EVENTS:
                    if k == i:
                        log.event(k, t, event, detail)
    finally:
        log.close()
    return path


@pytest.fixture(scope="module")
def session(written) -> Session:
    return read_session(written)


# --- a complete log ------------------------------------------------------------------------------


def test_a_closed_log_is_complete_with_every_channel(session, written):
    assert session.complete is True
    assert session.path == written
    assert set(session.messages) == set(CHANNELS)


def test_every_row_comes_back_with_exact_values(session):
    for topic in CYCLE_TOPICS:
        expected = [
            message
            for i in range(ROWS)
            for t, message in expected_messages(i).items()
            if t == topic
        ]
        assert same(session.messages[topic], expected), topic


def test_every_cycle_channel_has_a_message_per_row_with_k_and_t(session):
    for topic in ("/robot", "/estimate", "/command", "/timing"):
        messages = session.messages[topic]
        assert [m["k"] for m in messages] == list(range(ROWS)), topic
        assert [m["t"] for m in messages] == [round(i * DT, 9) for i in range(ROWS)], topic


def test_sensor_channels_only_for_rows_that_have_a_sample(session):
    assert [m["k"] for m in session.messages["/ft150"]] == [i for i in range(ROWS) if has_ft(i)]
    assert [m["k"] for m in session.messages["/fse103"]] == probe_rows()
    assert len(probe_rows()) < len([i for i in range(ROWS) if has_probe(i)])  # repeats left out
    assert 0 < len(session.messages["/ft150"]) < ROWS
    assert 0 < len(session.messages["/fse103"]) < ROWS


def test_a_non_finite_value_is_text_in_the_file_and_nan_when_read(session, written):
    ft_rows = [i for i in range(ROWS) if has_ft(i)]
    wrench = session.series("/ft150", "wrench_S")
    assert wrench.shape == (len(ft_rows), 6)
    expected = np.array(
        [
            [at_resolution("/ft150", "wrench_S", x) for x in row_values(i)["/ft150.wrench_S"]]
            for i in ft_rows
        ]
    )
    np.testing.assert_array_equal(wrench, expected)  # NaN where NaN, at its resolution elsewhere
    assert np.count_nonzero(np.isnan(wrench)) == 1
    assert np.isnan(session.messages["/ft150"][ft_rows.index(5)]["wrench_S"][1])
    assert np.isnan(session.messages["/estimate"][6]["F_hand_B"][2])
    assert np.isnan(session.messages["/estimate"][9]["ft_age"])
    ages = session.series("/estimate", "ft_age")
    assert ages.shape == (ROWS,)
    assert np.isnan(ages[9])
    assert np.count_nonzero(np.isnan(ages)) == 1
    # in the file: the field left out, its values as text in `nonfinite`, every other one a number
    raw = {(m["k"], topic): m for topic, m in _raw_messages(written)}
    ft = raw[(5, "/ft150")]
    assert "wrench_S" not in ft
    assert ft[NONFINITE]["wrench_S"][1] == "nan"
    assert float(ft[NONFINITE]["wrench_S"][0]) == at_resolution(
        "/ft150", "wrench_S", row_values(5)["/ft150.wrench_S"][0]
    )
    assert raw[(9, "/estimate")][NONFINITE] == {"ft_age": "nan"}
    assert NONFINITE not in raw[(8, "/estimate")]
    np.testing.assert_array_equal(
        session.series("/command", "sent_B")[13],
        [at_resolution("/command", "sent_B", x) for x in row_values(13)["/command.sent_B"]],
    )


def test_series_of_integers_and_booleans(session):
    np.testing.assert_array_equal(
        session.series("/robot", "protective_stop"), [float(i % 7 == 3) for i in range(ROWS)]
    )
    np.testing.assert_array_equal(
        session.series("/fse103", "device_ms"),
        [-1 if i % 5 == 0 else 123456 + 10 * i for i in probe_rows()],
    )
    assert session.series("/nothing", "x").shape == (0,)


def test_every_message_is_valid_against_its_channels_schema(written):
    count, problems = invalid_messages(written)
    assert count > 4 * ROWS
    assert problems == []


def _mutated(message: dict[str, Any], rng: np.random.Generator) -> Any:
    """A message with one thing changed at random: a value's type or integrality, a key dropped or
    added, a list longer or shorter, or the message not an object at all."""
    stand_ins = [0, 7, 1.0, 0.5, -2.25, 1e300, "0.5", "", True, False, None, [], {}, [1.0] * 3]
    changed = json.loads(json.dumps(message))
    key = list(changed)[rng.integers(len(changed))]
    what = rng.integers(7)
    if what == 0:
        changed[key] = stand_ins[rng.integers(len(stand_ins))]
    elif what == 1:
        del changed[key]
    elif what == 2:
        changed["extra"] = stand_ins[rng.integers(len(stand_ins))]
    elif what == 3 and isinstance(changed[key], list) and changed[key]:
        changed[key][rng.integers(len(changed[key]))] = stand_ins[rng.integers(len(stand_ins))]
    elif what == 4 and isinstance(changed[key], list):
        changed[key] = changed[key][: rng.integers(len(changed[key]) + 1)] + [0.5] * rng.integers(2)
    elif what == 5:
        changed[NONFINITE] = {key: ["nan"] * rng.integers(4) if rng.integers(2) else "inf"}
    else:
        return [changed] if rng.integers(2) else 3
    return changed


def test_messages_judged_by_their_shape_get_the_reference_validators_verdicts(written, tmp_path):
    """invalid_messages judges a shape once: on valid messages and on a thousand broken ones it
    reports exactly what jsonschema says of each message on its own."""
    from jsonschema import Draft202012Validator
    from mcap.writer import Writer

    from hoh_cosim.hardware import log_check

    # every channel's schema is judged by shape (or this test would prove nothing)
    assert all(log_check._structural(channel_schema(topic)) for topic in CHANNELS)
    rng = np.random.default_rng(5)
    originals = _raw_messages(written)
    messages = originals + [
        (topic, _mutated(m, rng))
        for topic, m in (originals[i] for i in rng.integers(len(originals), size=1000))
    ]
    path = tmp_path / "mutated.mcap"
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        channels = {}
        for topic in CHANNELS:
            schema = writer.register_schema(
                name=topic, encoding="jsonschema", data=json.dumps(channel_schema(topic)).encode()
            )
            channels[topic] = writer.register_channel(topic, "json", schema)
        for i, (topic, message) in enumerate(messages):
            writer.add_message(channels[topic], i, json.dumps(message).encode(), i)
        writer.finish()
    expected = []
    for topic, message in messages:
        validator = Draft202012Validator(channel_schema(topic))
        k = message.get("k") if isinstance(message, dict) else None
        expected += [f"{topic} k={k}: {error.message}" for error in validator.iter_errors(message)]
    count, problems = invalid_messages(path)
    assert count == len(messages)
    assert len(problems) > 500  # most mutations break the schema; some (a number for a number) not
    assert problems == expected


def test_the_schemas_refuse_what_they_should():
    from jsonschema import Draft202012Validator

    robot = Draft202012Validator(channel_schema("/robot"))
    good = {"k": 1, "p_BT_B": [0.1, 0.2, 0.3], "rotvec_BT": [1.0] * 3,
            "twist_B": [0.0] * 6, "robot_mode": 7, "safety_mode": 1, "protective_stop": False,
            "emergency_stop": False, "program_running": True}  # fmt: skip
    assert robot.is_valid(good)
    assert not robot.is_valid({**good, "extra": 1})  # no key the schema does not name
    assert not robot.is_valid({k: v for k, v in good.items() if k != "robot_mode"})  # required
    assert not robot.is_valid({**good, "p_BT_B": [0.1, None, 0.3]})  # null is not a number
    assert not robot.is_valid({**good, "p_BT_B": [0.1, 0.2]})  # the vector's length
    nonfinite = {k: v for k, v in good.items() if k != "p_BT_B"}
    assert robot.is_valid({**nonfinite, NONFINITE: {"p_BT_B": ["0.1", "nan", "0.3"]}})


def _raw_messages(path) -> list[tuple[str, dict[str, Any]]]:
    from mcap.reader import make_reader

    with path.open("rb") as stream:
        return [(c.topic, json.loads(m.data)) for _, c, m in make_reader(stream).iter_messages()]


def test_json_types_follow_the_schema(session):
    """Integers as integers, booleans as true/false, numbers and vectors as floats (NaN read back
    from `nonfinite`; the equality checks alone would take 1 for true and 1 for 1.0)."""
    for topic in CYCLE_TOPICS:
        for message in session.messages[topic]:
            assert type(message["k"]) is int
            assert type(message["t"]) is float
            for name, value in message.items():
                if name in ("k", "t"):
                    continue
                kind = CHANNELS[topic][name]["type"]
                if kind == "array":
                    assert all(type(x) is float for x in value), (topic, name)
                elif kind == "number":
                    assert type(value) is float, (topic, name)
                else:
                    expected = {"integer": int, "boolean": bool, "string": str}[kind]
                    assert type(value) is expected, (topic, name, value)


def test_mode_text_names_the_mode(session):
    modes = {message["mode"] for message in session.messages["/command"]}
    assert modes == set(range(7))
    for message in session.messages["/command"]:
        assert message["mode_text"] == Mode(message["mode"]).label


def test_status_text_names_the_flags(session):
    for i, message in enumerate(session.messages["/command"]):
        assert message["status"] == STATUSES[i % len(STATUSES)][0]
        assert message["status_text"] == STATUSES[i % len(STATUSES)][1]


def test_events_come_back_in_order(session):
    assert session.messages["/events"] == [
        {"k": k, "t": t, "event": event, "detail": detail} for k, t, event, detail in EVENTS
    ]


def test_metadata_round_trips(session):
    assert session.metadata == METADATA_OUT


def test_the_mcap_packages_own_reader_reads_the_same_messages(written, session):
    from mcap.reader import make_reader

    with written.open("rb") as stream:
        reader = make_reader(stream)
        records = list(reader.iter_messages())
        summary = reader.get_summary()
        metadata = [m for m in reader.iter_metadata() if m.name == "session"]

    total = sum(len(messages) for messages in session.messages.values())
    assert len(records) == total
    assert summary is not None
    assert summary.statistics is not None
    assert summary.statistics.message_count == total
    assert len(metadata) == 1
    by_topic: dict[str, list[dict[str, Any]]] = {}
    previous = 0
    for schema, channel, message in records:
        assert schema is not None
        assert schema.encoding == "jsonschema"
        assert channel.message_encoding == "json"
        data = json.loads(message.data)
        # the schema names every field of the message and requires the ones always there
        document = json.loads(schema.data)
        assert set(data) <= set(document["properties"]), channel.topic
        assert set(document["required"]) <= set(data), channel.topic
        # the session time is the record's log time after t0, and log times never go back
        assert "t" not in data
        assert message.log_time >= previous
        assert message.publish_time == message.log_time
        previous = message.log_time
        decoded = decode_message(data)
        t0_ns = int(channel.metadata[T0_KEY])  # each channel says when session time 0 was
        decoded["t"] = round((message.log_time - t0_ns) * 1e-9, 9)
        if channel.topic == "/command":  # written where they differ from the command
            for name in ("twist_law_B", "sent_B"):
                decoded.setdefault(name, decoded["twist_B"])
        by_topic.setdefault(channel.topic, []).append(decoded)
    assert same(by_topic, {t: m for t, m in session.messages.items() if m})


# --- a log cut off --------------------------------------------------------------------------------

FLUSH_S = 1.0
MARGIN_S = 0.25  # the writer checks its flush timer between batches, every 20 ms or so


def test_a_killed_writer_leaves_a_log_readable_up_to_the_cut(tmp_path):
    """Rows at about 180 Hz for 2.2 s, then SIGKILL: what was handed over more than flush_s
    before the kill is in the file. The rows are kept small (no sensor channels, about 400 kB in
    all) so that no chunk fills up to the writer's 1 MiB chunk size: only the periodic flush can
    have put them on disk."""
    path = tmp_path / "killed.mcap"
    log = SessionLog(path, {"kind": "kill"}, flush_s=FLUSH_S).start()
    process = log._process
    written_at: list[float] = []
    try:
        log.event(0, 0.0, "rebias", "before the rows")
        started = time.monotonic()
        i = 0
        while time.monotonic() - started < 2.2:
            fill_constant(log.row, i, sensors=False)
            log.cycle()
            written_at.append(time.monotonic())
            i += 1
            time.sleep(0.005)
        os.kill(process.pid, signal.SIGKILL)
        killed_at = time.monotonic()
        process.join(10.0)
        assert process.exitcode == -signal.SIGKILL
    finally:
        log.close()

    session = read_session(path)
    assert session.complete is False
    assert session.metadata == {"kind": "kill"}
    robot = session.messages["/robot"]
    ks = [m["k"] for m in robot]
    assert ks == list(range(len(ks)))  # the rows up to the cut, in order
    flushed = sum(1 for w in written_at if w < killed_at - FLUSH_S - MARGIN_S)
    assert flushed > 50
    assert len(ks) >= flushed, (len(ks), flushed, len(written_at))
    for m in robot:
        assert_constant(m, "/robot")
    for topic in ("/estimate", "/command", "/timing"):
        # a row's messages are cut at most at its last one
        assert len(ks) - 1 <= len(session.messages[topic]) <= len(ks), topic
    assert session.messages["/ft150"] == session.messages["/fse103"] == []
    assert [e["event"] for e in session.messages["/events"]] == ["rebias"]


@pytest.fixture(scope="module")
def chunked(tmp_path_factory) -> Path:
    """A log flushed after every batch of rows (flush_s=0), so it has many chunks."""
    path = tmp_path_factory.mktemp("chunked") / "chunked.mcap"
    log = SessionLog(path, {"kind": "chunked"}, flush_s=0.0).start()
    try:
        for i in range(150):
            fill_constant(log.row, i)
            log.cycle()
            time.sleep(0.002)
    finally:
        log.close()
    return path


def chunk_spans(path: Path) -> list[tuple[int, int]]:
    """Where each chunk of an MCAP file starts and ends (byte offsets)."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    stream = io.BytesIO(path.read_bytes())
    spans, at = [], 0
    for record in StreamReader(stream, emit_chunks=True).records:
        if isinstance(record, Chunk):
            spans.append((at, stream.tell()))
        at = stream.tell()
    return spans


def test_a_backlog_is_cut_into_chunks_of_the_sessions_time(tmp_path):
    # 2500 cycles of 2 ms (5 s of a session) handed over within a fraction of a second, as a
    # writer held back on a busy machine finds them: still a chunk per second of the session,
    # so a log cut off anywhere keeps all but about a second of what came before the cut
    path = tmp_path / "backlog.mcap"
    log = SessionLog(path, {"kind": "backlog"}, flush_s=1.0, capacity=4096).start()
    try:
        for i in range(2500):
            fill(log.row, i, {}, ft=False, probe=False)
            log.cycle()
    finally:
        log.close()
    assert read_session(path).messages["/robot"][-1]["k"] == 2499
    assert len(chunk_spans(path)) >= 5


@pytest.mark.parametrize("where", ["second-chunk", "middle-chunk", "last-chunk", "summary"])
def test_a_log_cut_off_is_read_up_to_the_cut(chunked, tmp_path, where):
    data = chunked.read_bytes()
    spans = chunk_spans(chunked)
    assert len(spans) >= 5
    whole = read_session(chunked)
    assert whole.complete is True
    assert len(whole.messages["/robot"]) == 150

    if where == "summary":  # after every chunk: all the messages, but no footer
        at = (spans[-1][1] + len(data)) // 2
    else:
        index = {"second-chunk": 1, "middle-chunk": len(spans) // 2, "last-chunk": -1}[where]
        at = sum(spans[index]) // 2
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:at])
    part = read_session(cut)
    assert part.complete is False
    assert part.metadata == {"kind": "chunked"}
    robot = part.messages["/robot"]
    if where == "summary":
        assert part.messages == whole.messages
    else:
        assert 0 < len(robot) < 150
    for topic, messages in part.messages.items():
        assert messages == whole.messages[topic][: len(messages)], topic
    assert [m["k"] for m in robot] == list(range(len(robot)))


def test_a_writer_killed_before_its_first_flush_leaves_an_incomplete_session(tmp_path):
    path = tmp_path / "early.mcap"
    log = SessionLog(path, {"kind": "early"}, flush_s=FLUSH_S).start()
    process = log._process
    try:
        for i in range(20):  # 40 ms of the session: no chunk is due on its clock either
            fill(log.row, i, {}, ft=False, probe=False)
            log.cycle()
        time.sleep(0.3)  # the writer has written its header and metadata, not yet a chunk
        os.kill(process.pid, signal.SIGKILL)
        process.join(10.0)
    finally:
        log.close()
    assert path.stat().st_size > 0
    session = read_session(path)
    assert session.complete is False
    assert session.metadata == {"kind": "early"}
    assert not any(session.messages.values())


# --- refusals -------------------------------------------------------------------------------------


def one_line_run_error(log: SessionLog) -> str:
    with pytest.raises(RunError) as info:
        log.start()
    message = str(info.value)
    assert "\n" not in message, message
    return message


@pytest.mark.parametrize("below", ["plain", "plain/sub"], ids=["in-a-file", "two-below-a-file"])
def test_a_path_under_a_regular_file_is_a_one_line_run_error(tmp_path, below):
    (tmp_path / "plain").write_text("not a directory\n", encoding="utf-8")
    path = tmp_path / below / "s.mcap"
    message = one_line_run_error(SessionLog(path, {}))
    assert message.startswith(f"{path}: cannot create the session log: "), message
    assert len(message) > len(f"{path}: cannot create the session log: ")
    assert (tmp_path / "plain").read_text(encoding="utf-8") == "not a directory\n"
    assert no_writer_left()


def test_a_path_the_writer_cannot_create_is_a_one_line_run_error(tmp_path):
    """A dangling symbolic link: it does not exist, yet creating the file exclusively fails
    (also for root), in the writer process."""
    path = tmp_path / "link.mcap"
    path.symlink_to(tmp_path / "target.mcap")
    log = SessionLog(path, {})
    message = one_line_run_error(log)
    assert message == f"{path}: cannot create the session log: File exists"
    assert not (tmp_path / "target.mcap").exists()
    log._process.join(5.0)
    assert not log._process.is_alive()


def test_a_file_name_too_long_is_a_one_line_run_error(tmp_path):
    path = tmp_path / ("x" * 300 + ".mcap")
    message = one_line_run_error(SessionLog(path, {}))
    assert message.startswith(f"{path}: cannot create the session log: "), message
    assert no_writer_left()


def test_an_existing_file_is_refused_not_overwritten(tmp_path):
    path = tmp_path / "s.mcap"
    path.write_bytes(b"yesterday's session")
    log = SessionLog(path, {})
    assert one_line_run_error(log) == f"{path}: cannot create the session log: it exists"
    assert path.read_bytes() == b"yesterday's session"
    assert log._process is None


@pytest.mark.parametrize(
    "content",
    [b"hello\nworld\n", b"", b"\x89MCAP0\r\n\x00\x00"],
    ids=["text", "empty", "magic-only"],
)
def test_reading_a_file_that_is_not_mcap_is_a_one_line_input_file_error(tmp_path, content):
    path = tmp_path / "notes.mcap"
    path.write_bytes(content)
    with pytest.raises(InputFileError) as info:
        read_session(path)
    message = str(info.value)
    assert "\n" not in message, message
    assert message.startswith(f"{path}: not a session log"), message
    assert info.value.path == str(path)


def test_reading_a_missing_file_is_a_one_line_input_file_error(tmp_path):
    path = tmp_path / "nowhere.mcap"
    with pytest.raises(InputFileError) as info:
        read_session(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: cannot read: "), message


# --- the ring overflowing -------------------------------------------------------------------------

LOST = re.compile(r"(\d+) cycles were not logged")


def overflow_log(path: Path, rows: int, pause_s: float) -> tuple[Session, int]:
    """`rows` constant rows into a 16-row ring, `pause_s` apart (busy waiting); the session and
    the cycles the overflow events say were lost."""
    log = SessionLog(path, {"kind": "overflow"}, capacity=16).start()
    try:
        for i in range(rows):
            fill_constant(log.row, i)
            log.cycle()
            if pause_s:
                until = time.perf_counter() + pause_s
                while time.perf_counter() < until:
                    pass
    finally:
        log.close()
    session = read_session(path)
    overflows = [e for e in session.messages["/events"] if e["event"] == "log_overflow"]
    lost = 0
    for event in overflows:
        match = LOST.fullmatch(event["detail"])
        assert match is not None, event
        assert int(match[1]) > 0, event
        lost += int(match[1])
    return session, lost if overflows else -1


def test_a_ring_overflow_is_reported_and_only_whole_rows_are_logged(tmp_path):
    rows = 5000
    session, lost = overflow_log(tmp_path / "burst.mcap", rows, 0.0)
    assert session.complete is True
    assert lost > 0, "no log_overflow event"
    robot = session.messages["/robot"]
    assert len(robot) + lost == rows
    assert len(robot) >= 16
    assert robot[-1]["k"] == rows - 1  # the last ring full is always written
    for topic in CYCLE_TOPICS:
        assert len(session.messages[topic]) == len(robot), topic
        for message in session.messages[topic]:
            assert_constant(message, topic)


def test_a_ring_overflow_while_the_writer_reads_logs_each_row_at_most_once(tmp_path):
    rows = 10000
    session, lost = overflow_log(tmp_path / "paced.mcap", rows, 20e-6)
    assert session.complete is True
    assert lost > 0, "no log_overflow event"
    ks = [m["k"] for m in session.messages["/robot"]]
    assert all(a < b for a, b in itertools.pairwise(ks)), "rows twice or out of order"
    assert len(ks) + lost == rows
    for topic in CYCLE_TOPICS:
        for message in session.messages[topic]:
            assert_constant(message, topic)


def test_events_handed_over_just_before_close_are_all_written(tmp_path):
    """The queue's thread carries events to the writer; close waits for it, so the last ones (the
    end, a stop's cause) are never lost to a writer told to finish first."""
    path = tmp_path / "burst.mcap"
    log = SessionLog(path, {"kind": "test"}).start()
    for i in range(2000):
        log.event(0, 0.0, "note", f"event {i}")
    log.close()
    log.event(0, 0.0, "late", "after close: not written, and no error")
    events = read_session(path).messages["/events"]
    assert [e["detail"] for e in events] == [f"event {i}" for i in range(2000)]
