"""A long rehearsal: does the runner's memory stay flat, how big does its log grow, how many overruns?

    python benchmarks/soak.py [--minutes 30] [--every 60] [--rt-priority P]

Runs `hoh-cosim hw rehearse` (the real runner, drivers and session log against the emulated UR5,
FT-150 and FSE103, the operator drawing circles) for `--minutes` and reads, every `--every` seconds,
the runner's resident memory (VmRSS of its process), that of its child processes together (the
world, the log writer) and the log's size on disk. It prints one line per sample, then the growth of
the runner's memory after the first minute, the log's rate in MB per hour and the session's own
timing line (cycles, overruns, compute and jitter percentiles). Target: memory flat after the first
minute (growth within a fixed bound, not proportional to the time), the log at most 150 MB an hour.
The last line is the figures as one JSON object.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def rss_kb(pid: int) -> int | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(p) for p in text.split()]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--every", type=float, default=60.0, metavar="S")
    parser.add_argument("--rt-priority", type=int, default=None)
    args = parser.parse_args(argv)
    seconds = 60.0 * args.minutes
    with tempfile.TemporaryDirectory(prefix="hoh-soak-") as tmp:
        log = Path(tmp) / "soak.mcap"
        command = [
            sys.executable,
            "-m",
            "hoh_cosim",
            "hw",
            "rehearse",
            "--seconds",
            f"{seconds:g}",
            "--log",
            str(log),
        ]
        if args.rt_priority is not None:
            command += ["--rt-priority", str(args.rt_priority)]
        process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        samples: list[dict[str, float]] = []
        start = time.monotonic()
        print("     t [s]   runner RSS [MB]   children RSS [MB]   log [MB]")
        while process.poll() is None:
            time.sleep(min(args.every, 1.0))
            elapsed = time.monotonic() - start
            if samples and elapsed - samples[-1]["t_s"] < args.every:
                continue
            runner = rss_kb(process.pid)
            if runner is None:
                continue
            others = sum(rss_kb(c) or 0 for c in children(process.pid))
            size = log.stat().st_size if log.exists() else 0
            sample = {"t_s": elapsed, "runner_mb": runner / 1024, "children_mb": others / 1024,
                      "log_mb": size / 1e6}  # fmt: skip
            samples.append(sample)
            print(
                f"{elapsed:10.0f}   {sample['runner_mb']:15.1f}   {sample['children_mb']:17.1f}"
                f"   {sample['log_mb']:8.1f}",
                flush=True,
            )
        output = process.stdout.read() if process.stdout else ""
        final_size = log.stat().st_size if log.exists() else 0
    timing = re.search(r"^timing: .*$", output, re.MULTILINE)
    ended = re.search(r"^session ended: (.*)$", output, re.MULTILINE)
    overruns = re.search(r"(\d+) cycles, (\d+) overruns", output)
    after_first = [s for s in samples if s["t_s"] >= 60.0]
    growth = (
        after_first[-1]["runner_mb"] - after_first[0]["runner_mb"] if len(after_first) > 1 else None
    )
    per_hour = final_size / 1e6 / seconds * 3600.0
    print(f"session ended: {ended[1] if ended else output.strip()[-300:]}")
    print(timing[0] if timing else "no timing line")
    if growth is not None:
        span = after_first[-1]["t_s"] - after_first[0]["t_s"]
        print(f"runner memory after the first minute: {growth:+.1f} MB over {span / 60:.0f} min")
    print(f"log: {final_size / 1e6:.1f} MB for {seconds / 60:g} min = {per_hour:.0f} MB per hour")
    print(
        json.dumps(
            {
                "minutes": args.minutes,
                "ended": ended[1] if ended else None,
                "cycles": int(overruns[1]) if overruns else None,
                "overruns": int(overruns[2]) if overruns else None,
                "runner_mb": [round(s["runner_mb"], 1) for s in samples],
                "children_mb": [round(s["children_mb"], 1) for s in samples],
                "runner_growth_after_first_minute_mb": growth,
                "log_mb": round(final_size / 1e6, 2),
                "log_mb_per_hour": round(per_hour, 1),
            }
        )
    )
    return process.returncode or 0


if __name__ == "__main__":
    sys.exit(main())
