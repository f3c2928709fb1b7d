"""The fault campaign: `hoh-cosim hw campaign` as a user runs it, and its checker caught lying.

Each run is the real `hoh-cosim hw run` through ur-rtde against the loopback UR controller, the
FT-150 stream and the FSE103 of the rehearsal world, with faults drawn from the run's seed.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from hoh_cosim.control.supervisor import STARVED_TEXT
from hoh_cosim.hardware import fse103, ft150
from hoh_cosim.hardware.session_log import SessionLog
from hoh_cosim.rehearsal import campaign
from tests.xdist_groups import REAL_TIME

pytestmark = REAL_TIME


def _campaign(
    runs: int,
    seed: int,
    out: Path,
    rig_stalls_allowed: bool = False,
    kinds: tuple[str, ...] = tuple(campaign.KINDS),
) -> tuple[subprocess.CompletedProcess, dict, list[dict]]:
    done = subprocess.run(
        [
            *(sys.executable, "-m", "hoh_cosim", "hw", "campaign", "--runs", str(runs)),
            *("--seed", str(seed), "--out", str(out), "--kinds", ",".join(kinds)),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    summary = json.loads((out / "summary.json").read_text())
    rows = list(csv.DictReader((out / "campaign.csv").read_text().splitlines()))
    failed = [r for r in rows if r["violations"]]
    if rig_stalls_allowed:  # only in runs whose emulated devices failed them
        failed = [r for r in failed if not (_rig_stalled(r) or _device_fell_silent(r))]
    else:
        assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert not failed, summary["failed_runs"]
    assert summary["violations"] == len([r for r in rows if r["violations"]])
    return done, summary, rows


def _again(seed: int, tmp_path: Path, kinds: tuple[str, ...]) -> dict:
    """The run of `seed` alone, up to twice, until it keeps every invariant and the machine
    neither stopped it nor held its emulated devices back; its row."""
    for attempt in range(2):
        where = tmp_path / f"again-{seed}-{attempt}"
        _, _, (again,) = _campaign(1, seed, where, rig_stalls_allowed=True, kinds=kinds)
        if not again["violations"] and again["machine_stop"] == "0":
            break
    assert not again["violations"], f"seed {seed}: {again['violations']}"
    assert again["machine_stop"] == "0", f"seed {seed}: {again['cause']}"
    return again


def _rig_stalled(row: dict) -> bool:
    return row["rig_stall_ms"] != "" and float(row["rig_stall_ms"]) >= 1e3 * campaign.RIG_STALL_S


# a stream's stale stop whose reader got no byte since its last sample, or less than a frame and
# nothing bad (a frame cut short by the silence), the streams named as the campaign's causes name
# them; bytes that made a bad frame, or a frame's worth that made no sample, are the parser's
_SILENT = re.compile(
    rf"^(?:(?P<ft>{campaign._FT})|{campaign._PROBE}): no new sample for \d+ ms "
    r"\(the stream stalled: (?:no byte read|(?P<bytes>\d+) bytes read) since its last sample"
    r"(?:, the last \d+ ms ago, 0 bad frames)?[;)]"
)


def _device_fell_silent(row: dict) -> bool:
    """Whether the run's one finding is an emulated device's stream falling silent with no fault
    of ours on that stream or on the machine: the runner stopped, as it must when a device goes
    quiet, and the device is the rig's. Seen in suite runs, always the FSE103's pseudo-terminal;
    in the first whose files were kept (seed 0) its frames stopped arriving 0.1 s into the session
    while the world's loop (1.2 ms at most between turns) and the FT-150's TCP stream kept time.
    The runner's stop says its reader read no byte since, or less than a frame and no bad one (the
    frame the silence cut): bytes that made a bad frame or a frame's worth without a sample would
    be our parser's finding, not the rig's."""
    match = _SILENT.match(row["cause"])
    if (
        match is None
        or row["violations"] != f"stopped though no fault called for it: {row['cause']!r}"
    ):
        return False
    prefix = "ft_" if match["ft"] else "probe_"
    frame = ft150.MAX_FRAME_BYTES if match["ft"] else max(fse103.FRAME_LENGTHS.values())
    if match["bytes"] is not None and int(match["bytes"]) >= frame:
        return False
    if prefix == "probe_" and row["probe_refused"] != "0":
        return False  # the terminal was full: the runner did not read it, which is the runner's
    return not any(k.startswith(prefix) or k == "cpu_hog" for k in row["injected"].split())


def test_only_a_device_silent_on_its_own_is_taken_for_the_rigs():
    def row(cause: str, injected: str = "", refused: str = "0", more: str = "") -> dict:
        found = f"stopped though no fault called for it: {cause!r}" + more
        return {"cause": cause, "violations": found, "injected": injected, "probe_refused": refused}

    quiet = "the stream stalled: no byte read since its last sample"
    probe = f"FSE103 on /dev/pts/0: no new sample for 250 ms ({quiet})"
    assert _device_fell_silent(row(probe))

    # bytes that made no sample: the parser's, not the rig's
    def read(text: str) -> str:
        return probe.replace("no byte read since its last sample", text)

    assert not _device_fell_silent(
        row(read("412 bytes read since its last sample, the last 3 ms ago, 22 bad frames"))
    )
    assert not _device_fell_silent(
        row(read("20 bytes read since its last sample, the last 3 ms ago, 0 bad frames"))
    )
    # a frame cut short by the silence: the rig's
    assert _device_fell_silent(
        row(read("7 bytes read since its last sample, the last 240 ms ago, 0 bad frames"))
    )
    assert _device_fell_silent(row(probe, "ft_garbage rtde_drop"))
    # with starved time in its cause (seen: seed 0), which repr quotes in double quotes
    starved = probe[:-1] + "; 1 ms of it with this machine's ordinary tasks starved)"
    assert _device_fell_silent(row(starved))
    # frames the terminal refused: it was full, so the runner did not read it
    assert not _device_fell_silent(row(probe, refused="3"))
    # a fault of ours on that stream, or on the machine, or a second finding: judged as they are
    assert not _device_fell_silent(row(probe, "probe_framing"))
    assert not _device_fell_silent(row(probe, "cpu_hog"))
    assert not _device_fell_silent(row(probe, more="; the log is cut"))
    ft = f"FT-150 stream at 127.0.0.1:5: no new sample for 250 ms ({quiet})"
    assert _device_fell_silent(row(ft, "probe_garbage"))
    assert not _device_fell_silent(row(ft, "ft_spike"))
    nan = "FT-150 stream at 127.0.0.1:5 sent a non-finite value"
    assert not _device_fell_silent(row(nan))


# the faults that a session of tests/integration/test_rehearsal.py injects too (the rehearsal's
# runner in process, its cause's exact words and the log checked there)
IN_REHEARSALS = frozenset(
    {"probe_unplug", "ft_stall", "ft_nan", "force_spike", "protective_stop"}
    | {"ft_garbage", "probe_garbage"}
)
ONLY_HERE = tuple(kind for kind in campaign.KINDS if kind not in IN_REHEARSALS)


def test_a_campaign_injects_its_faults_and_keeps_every_invariant(tmp_path):
    # the README's campaign cut to one run per fault kind that no other test's session injects:
    # seeds 0 to 7, whose first faults are each of those kinds once, each with up to two more of
    # them; one run at a time, as the real-time tests go, beside the rest of the suite on the other
    # core. The other seven kinds (IN_REHEARSALS) stop or spare a rehearsal's session in
    # test_rehearsal.py, which asserts their causes word for word; over every kind (15 runs) this
    # test took 97 s of the suite's 6 minutes, 8 of them about 50.
    assert set(campaign.KINDS) > IN_REHEARSALS
    rehearsals = (Path(__file__).parent / "test_rehearsal.py").read_text()
    assert all(f'"{kind}"' in rehearsals for kind in IN_REHEARSALS)  # still injected there
    out = tmp_path / "campaign"
    kinds = ONLY_HERE
    runs = len(kinds)
    done, summary, rows = _campaign(runs, 0, out, rig_stalls_allowed=True, kinds=kinds)
    assert summary["runs"] == runs
    firsts = sorted(campaign.draw_faults(seed, kinds)[0].kind for seed in range(runs))
    assert firsts == sorted(kinds)
    injected = {kind for r in rows for kind in r["injected"].split()}
    # A run that this machine stopped before its faults (a stream starved for the runner's 1 s
    # cap: seen in CI with the rest of the suite on both cores) did not inject them all; it is run
    # again alone from its seed, as the README tells a user, so that every kind is exercised.
    # A run with a violation is allowed only where the machine held the emulated devices (which
    # stand for hardware of their own) back for RIG_STALL_S or more, or where an emulated device's
    # stream fell silent with no fault of ours on it (`_device_fell_silent`); it too is run again,
    # and must then keep every invariant.
    for row in rows:
        drawn = {f.kind for f in campaign.draw_faults(int(row["seed"]), kinds)}
        machine_stopped = row["machine_stop"] == "1" and drawn - set(row["injected"].split())
        if row["violations"] or machine_stopped:
            again = _again(int(row["seed"]), tmp_path, kinds)
            row.update({key: value for key, value in again.items() if key != "run"})
            injected.update(again["injected"].split())
    assert injected == set(kinds)
    assert [int(r["run"]) for r in rows] == list(range(runs))
    # a run's faults are its seed's alone: what `--runs 1 --seed <seed>` would draw again
    for row in rows:
        drawn = campaign.draw_faults(int(row["seed"]), kinds)
        assert row["faults"] == " ".join(f.text() for f in drawn)
    # every stop was timed and kept its bound; the table says so
    stopped = [r for r in rows if r["expected"] == "stop"]
    assert stopped
    assert all(float(r["fault_to_standstill_ms"]) <= float(r["bound_ms"]) for r in stopped)
    assert "fault to standstill p50 / p99 / max" in done.stdout
    assert f"wrote {out / 'campaign.csv'}" in done.stdout


def test_the_checker_reports_a_run_that_does_not_do_what_its_fault_calls_for(tmp_path, monkeypatch):
    # garbage in the FT-150 stream calls for no stop: told that it does, the checker must object
    lying = dataclasses.replace(campaign.KINDS["ft_garbage"], stops=lambda duration_s: True)
    monkeypatch.setitem(campaign.KINDS, "ft_garbage", lying)
    # Run again once if the probe's stream ended the session: the fault is the FT-150's, so that
    # stop is no finding of this checker (seen once in a loaded suite: "FSE103 ...: no new sample
    # for 250 ms", the world's loop never more than 6 ms late). A second such stop fails.
    for attempt in range(2):
        where = tmp_path / f"attempt-{attempt}"
        (run,) = campaign.run_campaign(1, 7, 1, where, kinds=("ft_garbage",))
        if run.returncode == 0 or "FSE103" not in run.cause:
            break
    assert run.returncode == 0, run.cause
    assert any(v.startswith("no stop after ft_garbage") for v in run.violations), run.violations


class _Standstill:
    """The world's monitor as the judge reads it: when the arm stood still after a time."""

    def __init__(self, at: float) -> None:
        self.at = at

    def standstill_after(self, t: float) -> float:
        return max(t, self.at)

    def late(self, t: float) -> str:
        return "the world read no command to move after it"


def test_a_stop_is_timed_from_the_fault_its_cause_names(tmp_path):
    # a stall just past the stale limit may stop the session or not (a busy loop counts less of
    # it); survived, it must not make the later, named stop look late (seen in a loaded suite)
    stall = campaign.CampaignFault("ft_stall", 1.007, campaign.STALE_S + 0.005)
    stop = campaign.CampaignFault("program_stopped", 1.648)
    run = campaign.Run(0, 15, (stall, stop), injected=[(stall, 100.007), (stop, 100.648)])
    run.returncode = 1
    said = "stopping: x\nsession ended: UR controller at h (RTDE): the control program on the robot is not running\n"
    campaign._judge(run, said, tmp_path / "none.mcap", _Standstill(100.75), math.nan)
    assert run.first_kind == "program_stopped"
    assert run.standstill_s == pytest.approx(0.102)
    assert not [v for v in run.violations if "stood still" in v or "cause" in v], run.violations
    # and a stop whose cause names neither is still found out
    run = campaign.Run(0, 15, (stall, stop), injected=[(stall, 100.007), (stop, 100.648)])
    run.returncode = 1
    campaign._judge(
        run, "session ended: 3.5 s done\n", tmp_path / "none.mcap", _Standstill(100.75), math.nan
    )
    assert any(
        v.startswith("the cause does not name ft_stall/program_stopped") for v in run.violations
    )


def test_a_late_standstill_says_whether_the_command_or_the_arm_was_late(tmp_path):
    # the monitor's figures as the world left them: world time = monotonic - 50 s
    monitor = campaign._Monitor(world=None)
    monitor.offset_s = 50.0
    monitor.last_commanded_s = 50.3  # the last command to move read at 100.3 s monotonic
    assert monitor.late(100.0) == "the world read a command to move until 300.0 ms after it"
    assert monitor.late(100.4) == "the world read no command to move after it"
    monitor.last_commanded_s = math.nan
    assert monitor.late(100.0) == "the world never read a command to move"
    # and the judge puts it in the violation
    stop = campaign.CampaignFault("protective_stop", 1.0)
    run = campaign.Run(0, 15, (stop,), injected=[(stop, 100.0)])
    run.returncode = 1
    cause = "UR controller at h (RTDE): the robot is in a protective stop"
    monitor.moving_at_end, monitor.last_moving_s = False, 50.4
    monitor.last_commanded_s = 50.39
    campaign._judge(
        run,
        f"stopping: {cause}\nsession ended: {cause}\n",
        tmp_path / "none.mcap",
        monitor,
        math.nan,
    )
    (late,) = [v for v in run.violations if "stood still" in v]
    assert late.endswith("the world read a command to move until 390.0 ms after it)"), late


def test_faults_are_drawn_from_the_seed_alone():
    kinds = tuple(campaign.KINDS)
    assert campaign.draw_faults(41, kinds) == campaign.draw_faults(41, kinds)
    firsts = {campaign.draw_faults(seed, kinds)[0].kind for seed in range(100, 100 + len(kinds))}
    assert firsts == set(kinds)
    for seed in range(200):
        faults = campaign.draw_faults(seed, kinds)
        assert 1 <= len(faults) <= 3
        assert [f.at_s for f in faults] == sorted(f.at_s for f in faults)
        assert all(campaign.FIRST_S <= f.at_s <= campaign.LAST_S for f in faults)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--runs", "0"], "--runs: expected a whole number >= 1, got 0"),
        (["--kinds", "ft_stall,meteor"], "--kinds: expected some of ft_stall"),
    ],
)
def test_bad_options_get_one_line_and_status_2(tmp_path, args, message):
    done = subprocess.run(
        [sys.executable, "-m", "hoh_cosim", "hw", "campaign", "--out", str(tmp_path / "c"), *args],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "c" / "campaign.csv").exists()


def test_a_run_moves_to_another_address_when_its_own_is_taken_meanwhile(monkeypatch):
    # another program listens on the address after the lease looked at it (forced here: the lease
    # sees every address as free): the controller cannot listen, and the run takes the next one
    from hoh_cosim.rehearsal.world import WorldSetup

    hosts = campaign._Hosts()
    taken = hosts._candidates[0]
    monkeypatch.setattr(campaign, "_free", lambda host: True)
    with socket.socket() as squatter:
        squatter.bind((taken, 29999))
        squatter.listen()
        with campaign._rig(hosts, WorldSetup(task="circle", task_start_s=None)) as (host, _, ur):
            assert host != taken
            assert ur.said("^listening")
    assert taken not in hosts._candidates


def _log_with_events(path, *events):
    """A session log, by the runner's own writer, holding these (event, detail) pairs and its end."""
    log = SessionLog(path, {}).start()
    for k, (event, detail) in enumerate(events):
        log.event(k, 0.002 * k, event, detail)
    log.event(len(events), 0.002 * len(events), "end", "3.5 s done")
    log.close()
    return path


@pytest.mark.parametrize("starved", [False, True])
def test_a_stall_whose_silence_the_runner_did_not_count_may_go_on(tmp_path, starved):
    # a 400 ms stall calls for a stop, unless the runner says it left starved time of that very
    # stream out of its silence: then the stall may have ended the session or not
    stall = campaign.CampaignFault("ft_stall", 1.0, 0.4)
    detail = f"FT-150 stream at 127.0.0.1:5000: 230 {STARVED_TEXT}, not counted as its silence"
    other = f"FSE103 on /dev/pts/3: 230 {STARVED_TEXT}, not counted as its silence"
    log = _log_with_events(tmp_path / "s.mcap", ("starved", detail if starved else other))
    run = campaign.Run(0, 15, (stall,), injected=[(stall, 100.0)])
    run.returncode = 0
    campaign._judge(run, "session ended: 3.5 s done\n", log, _Standstill(math.inf), math.nan)
    missed = [v for v in run.violations if v.startswith("no stop after ft_stall")]
    assert run.expected == ("either" if starved else "stop")
    assert bool(missed) != starved, run.violations


def test_a_stop_that_discounted_starved_time_is_given_that_much_longer(tmp_path):
    stall = campaign.CampaignFault("ft_stall", 1.0, 0.8)
    run = campaign.Run(0, 15, (stall,), injected=[(stall, 100.0)])
    run.returncode = 1
    cause = (
        "FT-150 stream at 127.0.0.1:5000: no new sample for 480 ms (the stream stalled; "
        f"230 {STARVED_TEXT})"
    )
    log = _log_with_events(tmp_path / "s.mcap")
    # standstill 0.75 s after the stall: late by the plain bound (600 ms), in time by 600 + 230
    campaign._judge(
        run, f"stopping: {cause}\nsession ended: {cause}\n", log, _Standstill(100.75), math.nan
    )
    assert run.bound_s == pytest.approx(campaign.STALE_S + 0.05 + campaign.BRAKE_S + 0.23)
    assert not [v for v in run.violations if "stood still" in v], run.violations


def _log_with_probe_samples(path, received_s, cause):
    """A session log, by the runner's own writer, whose cycles used FSE103 samples received at
    these (monotonic) times, then its end with `cause`."""
    log = SessionLog(path, {}).start()
    count = 0
    for k, received in enumerate(received_s):
        log.row.start(k, 0.002 * k, False, True)
        count += k == 0 or received != received_s[k - 1]  # a message where the count moved
        log.row.set("/fse103.count", count)
        log.row.set("/fse103.received_s", received)
        log.cycle()
    log.event(len(received_s), 0.002 * len(received_s), "end", cause)
    log.close()
    return path


MACHINE_CAUSE = (
    "FSE103 on /dev/pts/0: no new sample for 1000 ms (the stream stalled; {starved} "
    f"{STARVED_TEXT})"
)


@pytest.mark.parametrize(
    ("spike_at", "starved_ms", "still_at", "machine"),
    [
        (101.0, 945, 100.6, True),  # seen in a loaded suite: silent before the spike came
        (100.4, 945, 100.6, False),  # the spike came first: the runner had to name it
        (101.0, 700, 100.6, False),  # 300 ms counted, past the stale limit: not the cap's stop
        (101.0, 945, 101.2, False),  # the machine's, but the arm moved on for 0.7 s
    ],
)
def test_a_stream_the_machine_starved_before_any_fault_is_the_machines_stop(
    tmp_path, spike_at, starved_ms, still_at, machine
):
    # the FSE103 fell silent at 100.5 (its last sample) with no fault of ours, ordinary tasks
    # starved nearly all of that second, and the runner ended the session at its 1 s cap; the force
    # spike injected meanwhile never reached it
    spike = campaign.CampaignFault("force_spike", 1.5, 0.2)
    run = campaign.Run(0, 23, (spike,), injected=[(spike, spike_at)])
    run.returncode = 1
    cause = MACHINE_CAUSE.format(starved=starved_ms)
    log = _log_with_probe_samples(tmp_path / "s.mcap", [100.46, 100.48, 100.5, 100.5], cause)
    said = f"stopping: {cause}\nsession ended: {cause}\n"
    campaign._judge(run, said, log, _Standstill(still_at), math.nan)
    assert run.machine_stop == (machine or still_at > 101.0)
    if machine:
        assert run.violations == []
        assert run.expected == "go on"  # the spike came after: not judged
        summary = campaign.summarise([run], 23)
        assert summary["machine_stops"] == 1
        assert summary["violations"] == 0
        assert "stopped by this machine before any fault" in campaign.table(summary)
    elif still_at > 101.0:
        assert any("after the fse103 fell silent" in v for v in run.violations), run.violations
    else:
        assert any(v.startswith("the cause does not name force_spike") for v in run.violations)
