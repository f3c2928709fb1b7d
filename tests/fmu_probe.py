"""Checks of one FMU as a foreign host makes them, in a process of its own (tests/integration/
test_fmu_conformance.py runs it): the FMU knows nothing of our scenarios, and we use only fmpy.

    python tests/fmu_probe.py FMU.fmu CHECK[,CHECK...] [JSON]

CHECK is any of
- `alone`: `fmpy.simulate_fmu(FMU)` with nothing but its defaults (DefaultExperiment, start values);
- `steps`: the inputs held at their start values, with JSON's {"input name": value} on top, from
  0 to 1.2 s in communication steps of 0.1, 1, 16, 24, 48 and 50 ms; every output at the end;
- `refuse`: a step of 1 ms, then one of 2 ms (the second is refused unless the FMU says
  canHandleVariableCommunicationStepSize);
- `state` (JSON's inputs as for `steps`): fmi2GetFMUstate at 0.1 s, 0.1 s more, fmi2SetFMUstate back and the same 0.1 s again, then
  through fmi2SerializeFMUstate / fmi2DeSerializeFMUstate in a second instance.

It prints one JSON object, {check: what happened}, with the messages the FMU logged. The FMU is
extracted once and every check loads it from there, as a host that keeps its extracted FMUs does:
its compiled kernels are then compiled once (numba caches them beside the extracted sources),
where a fresh extraction a check compiled them again (7-12 s for the plant and the hand).
"""

from __future__ import annotations

import json
import shutil
import sys

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import (
    FMU2Slave,
    calloc,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    free,
)

from hoh_cosim.fmi import exit_fix

# pythonfmu 0.7.0 releases its interpreter state twice when a library is unloaded or the process
# exits (see hoh_cosim.fmi.exit_fix): any host's exit may abort. Not what the checks are about.
exit_fix.install()

STEPS_MS = (0.1, 1.0, 16.0, 24.0, 48.0, 50.0)
END_S = 1.2


class Host:
    """One instance, set up and initialised at t = 0, logging on."""

    def __init__(self, path: str, unzipped: str, inputs: dict[str, float] | None = None) -> None:
        self.md = read_model_description(path)
        self.messages: list[str] = []
        self.fmu = FMU2Slave(
            guid=self.md.guid,
            unzipDirectory=unzipped,
            modelIdentifier=self.md.coSimulation.modelIdentifier,
            instanceName="probe",
        )
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.fmu.instantiate(loggingOn=True, callbacks=self.callbacks)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.outputs = [v for v in self.md.modelVariables if v.causality == "output"]
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, value in (inputs or {}).items():
            self.fmu.setReal([self.vr[name]], [value])
        self.fmu.exitInitializationMode()
        self.t = 0.0

    def _log(self, env, instance, status, category, message) -> None:
        self.messages.append(message.decode(errors="replace"))

    def step(self, h: float) -> bool:
        """One communication step; False if the FMU did not complete it."""
        try:
            self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h)
        except Exception as exc:  # fmpy raises on Error and Fatal
            self.messages.append(f"{type(exc).__name__}: {exc}")
            return False
        self.t += h
        return True

    def close(self) -> None:
        """Terminated and freed: an instance left to the process's exit is freed, if at all, by
        pythonfmu's own clean-up racing the interpreter's, which was seen to corrupt the heap
        ("corrupted double-linked list", about one exit in 40 on a loaded machine)."""
        self.fmu.terminate()
        self.fmu.freeInstance()

    def read(self) -> dict[str, float]:
        values = self.fmu.getReal([v.valueReference for v in self.outputs])
        return {v.name: float(x) for v, x in zip(self.outputs, values, strict=True)}


def alone(path: str, unzipped: str) -> dict:
    messages: list[str] = []

    def logger(component, instance, status, category, message):
        messages.append(message.decode(errors="replace"))

    result = simulate_fmu(unzipped, debug_logging=True, logger=logger)
    names = [n for n in result.dtype.names if n != "time"]
    return {
        "stop_time": float(read_model_description(path).defaultExperiment.stopTime),
        "end": float(result["time"][-1]),
        "rows": len(result),
        "finite": bool(all(np.all(np.isfinite(result[n])) for n in names)),
        "messages": messages[-5:],
    }


def steps(path: str, unzipped: str, drive: dict[str, float]) -> dict:
    finals = {}
    for h_ms in STEPS_MS:
        host = Host(path, unzipped, drive)
        n = round(END_S / (h_ms * 1e-3))
        h = END_S / n
        completed = all(host.step(h) for _ in range(n))
        finals[str(h_ms)] = {"completed": completed, "outputs": host.read()}
        host.close()
    return {"finals": finals}


def refuse(path: str, unzipped: str) -> dict:
    host = Host(path, unzipped)
    first = host.step(1e-3)
    second = host.step(2e-3)
    messages = list(host.messages)
    host.close()
    return {
        "variable": bool(host.md.coSimulation.canHandleVariableCommunicationStepSize),
        "first": first,
        "second": second,
        "messages": messages,
    }


def state(path: str, unzipped: str, drive: dict[str, float]) -> dict:
    host = Host(path, unzipped, drive)
    for _ in range(100):
        host.step(1e-3)
    saved = host.fmu.getFMUstate()
    t_saved, at_save = host.t, host.read()
    for _ in range(100):
        host.step(1e-3)
    first = host.read()
    host.fmu.setFMUstate(saved)
    host.t = t_saved
    for _ in range(100):
        host.step(1e-3)
    again = host.read()
    data = host.fmu.serializeFMUstate(saved)
    host.fmu.freeFMUstate(saved)
    other = Host(path, unzipped, drive)
    copy = other.fmu.deSerializeFMUstate(data)
    other.fmu.setFMUstate(copy)
    other.fmu.freeFMUstate(copy)
    other.t = t_saved
    for _ in range(100):
        other.step(1e-3)
    restored = other.read()
    host.close()
    other.close()
    md = host.md.coSimulation
    return {
        "flags": [bool(md.canGetAndSetFMUstate), bool(md.canSerializeFMUstate)],
        "bytes": len(bytes(data)),
        "at_save": at_save,
        "first": first,
        "again": again,
        "restored": restored,
        "messages": host.messages + other.messages,
    }


def main(argv: list[str]) -> None:
    path, checks = argv[0], argv[1].split(",")
    drive = json.loads(argv[2]) if len(argv) > 2 else {}
    known = {
        "alone": lambda unzipped: alone(path, unzipped),
        "steps": lambda unzipped: steps(path, unzipped, drive),
        "refuse": lambda unzipped: refuse(path, unzipped),
        "state": lambda unzipped: state(path, unzipped, drive),
    }
    unknown = [c for c in checks if c not in known]
    if unknown:
        raise SystemExit(f"unknown check {unknown[0]!r}: expected some of {', '.join(known)}")
    unzipped = str(extract(path))
    try:
        print(json.dumps({check: known[check](unzipped) for check in checks}))
    finally:
        shutil.rmtree(unzipped, ignore_errors=True)


if __name__ == "__main__":
    main(sys.argv[1:])
