"""The exported FMUs in a host that never installed hoh-cosim (`hoh-cosim export ... --check`).

A clean virtual environment gets only what the FMUs declare (the union of their
`resources/requirements.txt`, `hoh_cosim.fmi.host`) and the importer, fmpy at this environment's
version. There each FMU runs alone with `fmpy.simulate_fmu`'s defaults (the FMU's own start values
and default experiment, up to `stop_time`), in a process of its own; the same script then runs
it in this environment (hoh-cosim, numba's compiled kernels and pinocchio installed) and the
two are compared output by output. A row per FMU says whether it ran, how far, and the worst
difference relative to each output's peak.

The environments live in the FMU cache (`hosts/<hash of what they hold>`) and are reused: pip
takes the wheels from its own cache, so a second check costs the runs only.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import importlib.metadata
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hoh_cosim.errors import RunError
from hoh_cosim.fmi.host import REQUIREMENTS

__all__ = [
    "AloneRun",
    "CheckRow",
    "check_export",
    "declared_requirements",
    "fmi_version",
    "host_python",
    "run_alone",
]

_ALONE = """
import sys
import numpy as np
import fmpy
path, out, stop = sys.argv[1], sys.argv[2], float(sys.argv[3])
if sys.argv[4:] == ["installed"]:  # this environment's own code, before the FMU's copy
    import hoh_cosim.kinds
result = fmpy.simulate_fmu(path, stop_time=stop)
np.save(out, result)
"""
"""Runs one FMU alone with fmpy's defaults and saves its result (numpy and fmpy only). With
`installed`, the project's code as installed here is imported first, so that the FMU runs it rather
than the copy in its resources (the same code; but numba's compiled kernels are cached for the
installed files, not for a copy unpacked in a new place each run)."""

_TIMEOUT_S = 600.0


def declared_requirements(fmus: Iterable[Path], strict: bool = True) -> list[str]:
    """The union of the FMUs' `resources/requirements.txt` lines (no comments), in order; an FMU
    without the file (not built by this project, or built to run only where it is installed) is an
    error, or with `strict` False passed over."""
    lines: list[str] = []
    for fmu in fmus:
        try:
            with zipfile.ZipFile(fmu) as archive:
                text = archive.read(f"resources/{REQUIREMENTS}").decode()
        except KeyError:
            if not strict:
                continue
            raise RunError(
                f"{fmu}: has no resources/{REQUIREMENTS}: it was built without the project's "
                "code and runs only where hoh-cosim is installed"
            ) from None
        except (OSError, zipfile.BadZipFile) as exc:
            raise RunError(f"{fmu}: cannot read the FMU: {exc}") from None
        for line in text.splitlines():
            line = line.strip()
            if line and not line.startswith("#") and line not in lines:
                lines.append(line)
    return lines


def _importer() -> str:
    return f"fmpy=={importlib.metadata.version('fmpy')}"


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    """One process at a time makes an environment (parallel test workers share the cache)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def host_python(packages: Sequence[str], root: Path) -> Path:
    """The Python of a clean virtual environment under `root` holding `packages` (pip
    requirement lines) and what they need, made once and reused."""
    key = hashlib.sha256("\n".join([sys.version, *sorted(packages)]).encode()).hexdigest()[:16]
    where = root / key
    python = where / "bin" / "python"
    ready = where / ".ready"
    with _locked(root / f"{key}.lock"):
        if ready.is_file():
            return python
        shutil.rmtree(where, ignore_errors=True)
        base = getattr(sys, "_base_executable", sys.executable)
        _run([base, "-m", "venv", str(where)], f"making the environment {where}")
        _run(
            [
                str(python),
                "-m",
                "pip",
                "install",
                "--quiet",
                "--disable-pip-version-check",
                *packages,
            ],
            f"installing {' '.join(packages)} into {where}",
        )
        ready.write_text("\n".join(packages) + "\n")
    return python


def _run(command: list[str], what: str) -> None:
    done = subprocess.run(command, capture_output=True, text=True, timeout=_TIMEOUT_S)
    if done.returncode != 0:
        said = " ".join((done.stderr or done.stdout).split())[-400:]
        raise RunError(f"{what} failed (exit {done.returncode}): {said}")


@dataclass(frozen=True)
class AloneRun:
    """One FMU run alone: its result (a structured array, time first), or the error line."""

    fmu: Path
    result: np.ndarray | None
    error: str | None

    @property
    def reached_s(self) -> float:
        return float(self.result["time"][-1]) if self.result is not None else float("nan")


def run_alone(python: Path | str, fmu: Path, stop_time: float, installed: bool = False) -> AloneRun:
    """`fmpy.simulate_fmu(fmu, stop_time=...)` in the Python `python`, in a process of its own;
    `installed`: with the project's code installed there (see `_ALONE`)."""
    with tempfile.TemporaryDirectory(prefix="hoh-alone-") as tmp:
        out = Path(tmp) / "result.npy"
        # a clean environment: nothing of this one's (its path, its kernels' switch) leaks in
        env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "HOH_COSIM"))}
        done = subprocess.run(
            [str(python), "-c", _ALONE, str(fmu), str(out), repr(stop_time)]
            + (["installed"] if installed else []),
            capture_output=True,
            text=True,
            timeout=_TIMEOUT_S,
            cwd=tmp,
            env=env,
        )
        if done.returncode != 0 or not out.is_file():
            return AloneRun(fmu, None, _first_line(done.stderr, done.stdout, done.returncode))
        return AloneRun(fmu, np.load(out), None)


def _first_line(stderr: str, stdout: str, code: int) -> str:
    """What a failed run said first: the FMU's own line when it wrote one, else fmpy's last."""
    lines = [line.strip() for line in (stderr + "\n" + stdout).splitlines() if line.strip()]
    if not lines:
        return f"exit {code}, nothing said"
    if lines[0].startswith("Traceback"):
        return lines[-1]
    return lines[0]


def worst_difference(a: np.ndarray, b: np.ndarray) -> float:
    """The largest |a - b| relative to the peak of b's signal, over every output both have (time
    aligned). A signal is a port: `R_BT[1]` … `R_BT[9]` share the peak of R_BT, so that an
    element that is zero but for rounding is measured against its port's scale, not its own."""
    if len(a) != len(b) or not np.array_equal(a["time"], b["time"]):
        return float("inf")
    names = [n for n in b.dtype.names or () if n != "time" and n in (a.dtype.names or ())]
    peaks: dict[str, float] = {}
    for name in names:
        port = name.split("[")[0]
        peaks[port] = max(peaks.get(port, 0.0), float(np.max(np.abs(b[name]), initial=0.0)))
    worst = 0.0
    for name in names:
        difference = np.abs(np.asarray(a[name], float) - np.asarray(b[name], float))
        worst = max(
            worst, float(np.max(difference, initial=0.0)) / (peaks[name.split("[")[0]] or 1.0)
        )
    return worst


@dataclass(frozen=True)
class CheckRow:
    importer: str
    fmu: str
    fmi: str
    ok: bool
    what: str
    worst: float
    skipped: bool = False  # the importer cannot load this FMU at all (said in `what`)

    def line(self) -> str:
        worst = f"{self.worst:.1e}" if np.isfinite(self.worst) else "-"
        status = "skip" if self.skipped else "ok" if self.ok else "FAILED"
        return (
            f"{self.importer:<9} {self.fmu:<16} {self.fmi:<4} {worst:>9}  {status:<6} {self.what}"
        )


HEADER = f"{'importer':<9} {'FMU':<16} {'FMI':<4} {'worst':>9}  result"


def fmi_version(fmu: Path) -> str:
    from fmpy import read_model_description

    return read_model_description(str(fmu)).fmiVersion


def check_export(
    fmus: Sequence[Path], cache: Path, stop_time: float = 1.0, tolerance: float = 1e-9
) -> list[CheckRow]:
    """Each FMU of `fmus` alone in a clean environment with its declared requirements and fmpy,
    against the same run here: a row each (`ok` when it ran to `stop_time` with every output
    within `tolerance` of its peak)."""
    packages = [*declared_requirements(fmus), _importer()]
    python = host_python(packages, cache / "hosts")
    rows = []
    for fmu in fmus:
        there = run_alone(python, fmu, stop_time)
        name, fmi = fmu.stem, fmi_version(fmu)
        if there.error is not None:
            rows.append(CheckRow("fmpy", name, fmi, False, there.error, float("nan")))
            continue
        here = run_alone(sys.executable, fmu, stop_time, installed=True)
        if here.error is not None:
            rows.append(CheckRow("fmpy", name, fmi, False, f"here: {here.error}", float("nan")))
            continue
        worst = worst_difference(there.result, here.result)  # type: ignore[arg-type]
        reached = there.reached_s
        ok = worst <= tolerance and abs(reached - stop_time) < 1e-9
        what = f"ran to {reached:g} s, {len(there.result)} samples"  # type: ignore[arg-type]
        rows.append(CheckRow("fmpy", name, fmi, ok, what, worst))
    return rows
