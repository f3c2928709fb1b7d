"""Scenario, sweep and rig YAML, POSES.csv and calibration.json, mutated from the real files: a
value of the wrong type, NaN, infinity, a huge number, a key missing or extra, deep nesting,
aliases that expand without bound, a byte flipped. Loading gives a result or one line that starts
with the file's path, within the time bound and without a spike of memory (`tests.fuzz.targets`).

The examples pin inputs that once escaped as something else, or hung."""

from __future__ import annotations

import json

import yaml
from hypothesis import example, given

from tests.fuzz.targets import (
    TARGETS,
    billion_laughs,
    bounded,
    calibration_seed,
    rig_seeds,
    scenario_seeds,
    sweep_seeds,
)

SCENARIO, SWEEP, RIG = TARGETS["scenario"], TARGETS["sweep"], TARGETS["rig"]
POSES, CALIBRATION = TARGETS["poses"], TARGETS["calibration"]


def _yaml(document: object) -> bytes:
    return yaml.safe_dump(document, sort_keys=False).encode()


CIRCLES = scenario_seeds()[0]
RIG_DOC = rig_seeds()[0]


@bounded(120)
@given(data=SCENARIO.strategy(None))
@example(data=b"name: " + b"[" * 5000 + b"]" * 5000)  # RecursionError in PyYAML
@example(data=b"name: x\nduration_s: 1\nseed: " + b"9" * 5000)  # ValueError: 5000 digits
@example(data=f"name: {billion_laughs(9)}\nduration_s: 1\n".encode())  # 10**9 strings in a message
@example(data=b"name: x\nseed: 2024-13-01\n")  # ValueError: a date that does not exist
@example(data=b"name: a\x03b\nduration_s: 1\n")  # a control character: a two-line message
@example(data=_yaml({**CIRCLES, "components": 859}))  # TypeError: 'int' is not iterable
@example(data=_yaml({**CIRCLES, "seed": 2**70}))
def test_scenario_files(workspace, data):
    SCENARIO.check(workspace, data)


@bounded(40)
@given(data=SWEEP.strategy(None))
@example(data=_yaml({**sweep_seeds()[-1], "random": {**sweep_seeds()[-1]["random"], "n": 2**31}}))
@example(data=_yaml({**sweep_seeds()[0], "set": 5}))  # TypeError: 'int' is not iterable
@example(data=_yaml({**sweep_seeds()[0], "grid": {"a": list(range(200)), "b": list(range(200))}}))
def test_sweep_files(workspace, data):
    SWEEP.check(workspace, data)


@bounded(120)
@given(data=RIG.strategy(None))
# a direction of 1e300 overflows to zero, refused when the sensors are applied: without the file
@example(data=_yaml({**RIG_DOC, "controller": {"fixture_up_B": [1e300, 0, 0]}}))
@example(data=b"robot: {host: &h [*h]}\n")  # an alias that names itself
def test_rig_files(workspace, data):
    RIG.check(workspace, data)


ROWS = POSES.corpus(None)[0].decode().splitlines()


@bounded(150)
@given(data=POSES.strategy(None))
@example(data=("\n".join([*ROWS[:3], "1," + "2" * 140_000 + ",3,4,5,6,7,8,9"]) + "\n").encode())
@example(data=("\n".join([*ROWS[:2], "1e200,0,0,1,2,3,4,5,6", *ROWS[2:]]) + "\n").encode())
@example(data=("\n".join([*ROWS[:2], "0,0,0,1e300,2,3,4,5,6", *ROWS[2:]]) + "\n").encode())
def test_pose_files(workspace, data):
    POSES.check(workspace, data)


def _json(**changes: object) -> bytes:
    return json.dumps({**calibration_seed(), **changes}).encode()


@bounded(150)
@given(data=CALIBRATION.strategy(None))
@example(data=b"[" * 100_000 + b"]" * 100_000)  # RecursionError in json
@example(data=b'{"format": ' + b"9" * 5000 + b"}")  # ValueError: 5000 digits
@example(data=_json(mass_kg=10**400))  # OverflowError: an integer beyond any float
@example(data=_json(com_m=[10**400, 0, 0]))
@example(data=b'{"format": "\xff"}')  # UnicodeDecodeError
def test_calibration_files(workspace, data):
    CALIBRATION.check(workspace, data)
