"""A time-boxed fuzzing campaign over every parser and loader (the targets of tests/fuzz/targets.py).

    python benchmarks/fuzz.py --minutes N [--target NAME ...] [--out DIR] [--engine atheris|hypothesis]
    python benchmarks/fuzz.py --reproduce DIR/TARGET-failure-1.yaml

The minutes are split evenly among the targets, fuzzed one after the other, each in a process of
its own. With atheris (`pip install ".[fuzz]"`) the inputs are libFuzzer's coverage-guided mutations
of raw bytes, starting from the real files (scenarios/, studies/, the rig example, the reference
poses, a calibration and a session log) and a dictionary of each format's tokens; without it,
hypothesis draws inputs without end from the strategies the tests use. Every input goes through the
target's invariants: one that breaks them is a failure, one that takes longer than its bound
(tests/fuzz/targets.py's HANG_S, 2 s; a sweep 0.1 s more per variant), or never returns, a hang. Each is saved under --out (default: a new temporary directory) as
TARGET-failure-N or TARGET-hang-N (the first KEEP of each kind), which `--reproduce` runs again.

Prints per target the inputs tried, failures (and how many distinct: exception and place), hangs,
then the distinct failures; the last line is the figures as one JSON object. Exit status 1 if any
input failed or hung.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import resource
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the targets live with the tests
    sys.path.insert(0, str(ROOT))

STUCK_S = 30.0  # [s] an input still running then is stopped and counted as a hang
MEMORY_LIMIT = 8 << 30  # [bytes] of address space for a target's process: a runaway is an error
STARTUP_S = 60.0  # [s] what a target's process may take beyond its share (imports, instrumenting)
RESTARTS = 5  # a target's process that ends early (a hang, out of memory) is restarted this often
KEEP = 10  # inputs kept of each kind of failure, and of hangs
INSTRUMENTED = ["hoh_cosim", "yaml", "mcap"]  # the code whose coverage guides atheris


def _engine(requested: str) -> str:
    if requested != "auto":
        return requested
    try:
        import atheris  # noqa: F401
    except ImportError:
        return "hypothesis"
    return "atheris"


# --- a target's process ----------------------------------------------------------------------------


class Tally:
    """A target's figures, written to a JSON file now and then (libFuzzer ends the process
    itself)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.figures: dict[str, Any] = {
            "inputs": 0,
            "failures": 0,
            "hangs": 0,
            "distinct": {},  # a kind of failure: its first message and input
            "seen": {},  # how many inputs of each kind (hangs: "")
        }
        if path.exists():  # a restarted process goes on counting
            self.figures = json.loads(path.read_text())
        self._written = 0.0

    def write(self, force: bool = False) -> None:
        now = time.monotonic()
        if force or now - self._written > 0.05:
            self.path.write_text(json.dumps(self.figures))
            self._written = now


class _Stuck(BaseException):
    """An input ran past STUCK_S (a BaseException: no `except Exception` of the code under test
    swallows it)."""


def _signature(exc: BaseException) -> str:
    """A failure's kind: the exception and the last place in the project's code it went through."""
    frames = traceback.extract_tb(exc.__traceback__)
    ours = [f for f in frames if "hoh_cosim" in f.filename or "tests" in f.filename] or frames
    place = f" at {Path(ours[-1].filename).name}:{ours[-1].lineno}" if ours else ""
    return f"{type(exc).__name__}{place}"


def run_one(target: Any, ws: Any, value: Any, tally: Tally, out: Path) -> None:
    """One input through the target's invariants; a failure or a hang is counted and saved."""
    from tests.fuzz.targets import HangError

    figures = tally.figures
    figures["inputs"] += 1
    kind, failure = "", None
    try:
        target.check(ws, value)  # the targets bound their own time (HANG_S, a sweep more)
    except (HangError, _Stuck):
        kind = "hang"
    except Exception as exc:  # whatever escaped is what the campaign looks for
        kind, failure = "failure", exc
    if kind:
        figures[f"{kind}s"] += 1
        path = out / f"{target.name}-{kind}-{figures[f'{kind}s']}{target.suffix}"
        signature = _signature(failure) if failure is not None else ""
        seen = figures["seen"].get(signature, 0)
        figures["seen"][signature] = seen + 1
        if seen < KEEP:
            path.write_bytes(target.save(value))
        if failure is not None and not seen:
            text = (str(failure).splitlines() or [""])[0][:120]
            figures["distinct"][signature] = f"{text!r}, e.g. {path.name}"
    tally.write(force=bool(kind))


def _stuck(*_: Any) -> None:
    raise _Stuck()


def _guarded(target: Any, ws: Any, value: Any, tally: Tally, out: Path) -> None:
    """`run_one`, stopped after STUCK_S (a loop in Python; libFuzzer's own -timeout under atheris)."""
    signal.setitimer(signal.ITIMER_REAL, STUCK_S)
    try:
        run_one(target, ws, value, tally, out)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)


def worker(name: str, seconds: float, out: Path, engine: str) -> None:
    """Fuzz one target for `seconds` in this process."""
    started = time.monotonic()
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    signal.signal(signal.SIGALRM, _stuck)
    if engine == "atheris":
        import atheris

        with atheris.instrument_imports(include=INSTRUMENTED):
            from tests.fuzz import targets

            for module in targets.TARGETS[name].modules:
                importlib.import_module(module)
    from tests.fuzz import targets

    target = targets.TARGETS[name]
    ws = targets.Workspace(out / f"work-{name}", session_seed=out / "session-seed.mcap")
    ws.directory.mkdir(exist_ok=True)
    tally = Tally(out / f"{name}.json")
    left = max(1.0, seconds - (time.monotonic() - started))
    try:
        if engine == "atheris":
            _atheris(target, ws, tally, out, left)
        else:
            _hypothesis(target, ws, tally, out, left)
    finally:
        tally.write(force=True)
        ws.close()


def _atheris(target: Any, ws: Any, tally: Tally, out: Path, seconds: float) -> None:
    import atheris

    corpus = out / f"corpus-{target.name}"
    corpus.mkdir(exist_ok=True)
    seeds = target.corpus(ws)
    for i, data in enumerate(seeds):
        (corpus / f"seed-{i}").write_bytes(data)
    options = [
        f"-max_total_time={max(1, round(seconds))}",
        f"-timeout={round(STUCK_S)}",
        "-rss_limit_mb=4096",
        f"-max_len={max(4096, 2 * max(map(len, seeds)))}",
        f"-artifact_prefix={out}/{target.name}-libfuzzer-",
    ]
    if target.tokens:  # libFuzzer's dictionary: one quoted token a line
        tokens = out / f"{target.name}.dict"
        tokens.write_text("".join(f'"{_escaped(token)}"\n' for token in target.tokens))
        options.append(f"-dict={tokens}")

    def one(data: bytes) -> None:
        run_one(target, ws, target.decode(data), tally, out)

    atheris.Setup([sys.argv[0], *options, str(corpus)], one)
    atheris.Fuzz()  # ends the process when the time is up


def _escaped(token: bytes) -> str:
    return "".join(f"\\x{b:02x}" for b in token)


def _hypothesis(target: Any, ws: Any, tally: Tally, out: Path, seconds: float) -> None:
    from hypothesis import HealthCheck, Phase, given, settings

    deadline = time.monotonic() + seconds
    tried = [0]

    @settings(
        max_examples=200,
        database=None,
        deadline=None,
        phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    @given(target.strategy(ws))
    def batch(value: Any) -> None:
        # at least one input, however long the start-up took on a busy machine
        if time.monotonic() < deadline or not tried[0]:
            tried[0] += 1
            _guarded(target, ws, value, tally, out)

    batch()
    while time.monotonic() < deadline:
        batch()


# --- the campaign ----------------------------------------------------------------------------------


def campaign(names: list[str], minutes: float, out: Path, engine: str) -> dict[str, Any]:
    """Every target in its own process for its share of the time; the figures per target."""
    from tests.fuzz.targets import TARGETS, Workspace

    if "session" in names:  # the real log the session target starts from, written once
        Workspace(out).session_seed.rename(out / "session-seed.mcap")
    share = 60.0 * minutes / len(names)
    results = {}
    for name in names:
        deadline = time.monotonic() + share
        tally = Tally(out / f"{name}.json")
        for _ in range(RESTARTS + 1):
            left = deadline - time.monotonic()
            if left < 1.0:
                break
            before = set(out.glob(f"{name}-libfuzzer-*"))
            command = [sys.executable, __file__, "--worker", name, "--seconds", f"{left:.1f}"]
            command += ["--out", str(out), "--engine", engine]
            with (out / f"{name}.log").open("a") as log:
                process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
                try:
                    process.wait(left + STARTUP_S)
                except subprocess.TimeoutExpired:  # stuck where no timer reaches (C code)
                    process.kill()
                    process.wait()
            if process.returncode == 0:
                break
            # ended early: libFuzzer's timeout or memory limit (it saved the input), or killed
            tally = Tally(tally.path)
            saved = sorted(set(out.glob(f"{name}-libfuzzer-*")) - before)
            if any("-oom-" in p.name or "-crash-" in p.name for p in saved):
                tally.figures["failures"] += 1
                for p in saved:
                    tally.figures["distinct"].setdefault(f"libFuzzer: {p.name}", p.name)
            else:
                tally.figures["hangs"] += 1
            tally.write(force=True)
        figures = Tally(tally.path).figures
        results[name] = {
            "inputs": figures.get("inputs", 0),
            "failures": figures.get("failures", 0),
            "distinct": figures.get("distinct", {}),
            "hangs": figures.get("hangs", 0),
            "what": TARGETS[name].what,
        }
    return results


def reproduce(path: Path) -> int:
    """Run one saved input through its target's invariants, with the traceback if it fails."""
    from tests.fuzz.targets import TARGETS, Workspace

    target = TARGETS[path.name.split("-")[0]]
    seed = path.parent / "session-seed.mcap"
    with tempfile.TemporaryDirectory() as directory:
        ws = Workspace(Path(directory), session_seed=seed if seed.exists() else None)
        try:
            target.check(ws, target.load(path.read_bytes()))
        finally:
            ws.close()
    print(f"{path}: the invariants of {target.name} hold")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, help="the campaign's length, all targets together")
    parser.add_argument("--target", action="append", help="a target (default: all); repeatable")
    parser.add_argument("--out", type=Path, help="where failing inputs go (default: a temp dir)")
    parser.add_argument("--engine", choices=("auto", "atheris", "hypothesis"), default="auto")
    parser.add_argument("--reproduce", type=Path, metavar="FILE", help="run one saved input")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--seconds", type=float, help=argparse.SUPPRESS)
    args = parser.parse_args()

    if args.reproduce:
        return reproduce(args.reproduce)
    if args.worker:
        worker(args.worker, args.seconds, args.out, args.engine)
        return 0
    from tests.fuzz.targets import HANG_S, TARGETS

    if args.minutes is None or args.minutes <= 0:
        parser.error("--minutes: expected a positive number")
    names = args.target or list(TARGETS)
    unknown = [n for n in names if n not in TARGETS]
    if unknown:
        parser.error(f"--target {unknown[0]}: expected one of {', '.join(TARGETS)}")
    engine = _engine(args.engine)
    out = args.out or Path(tempfile.mkdtemp(prefix="hoh-fuzz-"))
    out.mkdir(parents=True, exist_ok=True)
    version = ""
    if engine == "atheris":
        from importlib.metadata import version as installed

        version = f" {installed('atheris')}"
    print(
        f"{args.minutes:g} min over {len(names)} targets ({60 * args.minutes / len(names):.0f} s "
        f"each), {engine}{version}, hang: over {HANG_S:g} s; python {platform.python_version()}, "
        f"{os.cpu_count()} cores; inputs that fail are kept in {out}"
    )
    results = campaign(names, args.minutes, out, engine)

    print(f"{'target':<12} {'inputs':>9} {'failures':>9} {'distinct':>9} {'hangs':>6}  what")
    for name, r in results.items():
        print(
            f"{name:<12} {r['inputs']:>9} {r['failures']:>9} {len(r['distinct']):>9} "
            f"{r['hangs']:>6}  {r['what']}"
        )
    for name, r in results.items():
        for signature, example in r["distinct"].items():
            print(f"  {name}: {signature}: {example}")
    figures = {
        "minutes": args.minutes,
        "engine": engine,
        "hang_s": HANG_S,
        "failures": sum(r["failures"] for r in results.values()),
        "hangs": sum(r["hangs"] for r in results.values()),
        "targets": {
            name: {k: (len(v) if k == "distinct" else v) for k, v in r.items() if k != "what"}
            for name, r in results.items()
        },
        "out": str(out),
    }
    print(json.dumps(figures))
    return 1 if figures["failures"] or figures["hangs"] else 0


if __name__ == "__main__":
    sys.exit(main())
