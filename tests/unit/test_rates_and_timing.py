"""What the runner measures of the streams and of itself: packet rates a burst cannot fool, cycle
timing in fixed memory, the machine's CPU pressure, and the time ordinary tasks were starved."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.hardware.pressure import Canary, CpuPressure
from hoh_cosim.hardware.runner import CycleTiming, LatencyHistogram
from hoh_cosim.hardware.streams import RateCheck, robust_period


def arrivals(period_s, n, rng, *, stall_at=None, stall_s=0.0, drain_s=0.0, jitter_s=2e-4):
    """(count, receipt time) as a 500 Hz loop sees a stream: the newest sample each cycle. A
    stall holds every sample from `stall_at` back for `stall_s`; the backlog then arrives at once
    (`drain_s` 0) or one sample per `drain_s`, until it has caught up."""
    send = np.arange(1, n + 1) * period_s
    receive = send + rng.uniform(0.0, jitter_s, n)
    if stall_at is not None:
        held = (send >= stall_at) & (send < stall_at + stall_s)
        receive[held] = stall_at + stall_s
        for i in range(1, n):
            if receive[i] >= stall_at + stall_s:
                receive[i] = max(receive[i], receive[i - 1] + drain_s)
    receive = np.maximum.accumulate(receive)
    cycles = np.ceil(receive / 0.002)  # the cycle that first sees each sample
    last = np.r_[cycles[1:] != cycles[:-1], True]  # the newest per cycle
    counts = np.arange(1, n + 1)[last]
    return counts, (cycles * 0.002)[last]


def median_spacing(counts, times):
    return float(np.median(np.diff(times)))  # the rebias's former estimate


@pytest.mark.parametrize("period_s", [0.005, 0.01, 0.016, 0.02])
def test_a_steady_streams_period_is_found(period_s, rng):
    counts, times = arrivals(period_s, 300, rng)
    assert robust_period(counts, times) == pytest.approx(period_s, rel=0.02)


@pytest.mark.parametrize("drain_s", [0.0, 0.002])
@pytest.mark.parametrize(("stall_at", "stall_s"), [(0.3, 0.1), (0.2, 0.25), (1.0, 0.3)])
def test_a_stall_and_a_burst_do_not_change_the_period(stall_at, stall_s, drain_s, rng):
    counts, times = arrivals(0.005, 300, rng, stall_at=stall_at, stall_s=stall_s, drain_s=drain_s)
    assert robust_period(counts, times) == pytest.approx(0.005, rel=0.02)


def test_the_former_median_spacing_took_a_drained_backlog_for_a_fast_stream(rng):
    # the failure this measurement replaces: 200 Hz read as 500 Hz, the backlog of a 0.3 s stall
    # drained a sample per 2 ms cycle over most of a 100-sample rebias
    counts, times = arrivals(0.005, 100, rng, stall_at=0.05, stall_s=0.3, drain_s=0.002)
    assert 1.0 / median_spacing(counts, times) > 400.0
    # still draining at the window's end: the last point is late, the rate a little low
    assert 180.0 <= 1.0 / robust_period(counts, times) <= 201.0


def test_spread_delays_move_the_period_by_at_most_the_delay_over_the_window(rng):
    # up to 4 ms late over a 1 s window: at most 0.4 %
    counts, times = arrivals(0.005, 200, rng, jitter_s=0.004)
    assert robust_period(counts, times) == pytest.approx(0.005, rel=0.004 + 0.002)


def test_too_few_points_measure_nothing():
    assert math.isnan(robust_period([1, 2], [0.0, 0.005]))
    assert math.isnan(robust_period([], []))


@pytest.mark.parametrize(
    ("period_s", "problem"),
    [
        (0.005, None),
        (math.nan, None),  # unmeasured: the configured period stands
        (0.002, "FT-150 at h:1 measured at 500.0 Hz (receipt times), outside the 50-250 Hz"),
        (0.05, "FT-150 at h:1 measured at 20.0 Hz (receipt times), outside the 50-250 Hz"),
    ],
)
def test_a_rate_outside_the_datasheets_band_is_refused(period_s, problem):
    found = RateCheck("FT-150 at h:1", period_s, (50.0, 250.0), "receipt times").problem()
    if problem is None:
        assert found is None
    else:
        assert found.startswith(problem)


def test_the_histograms_percentiles_match_numpys_within_a_bin(rng):
    values = rng.lognormal(np.log(3e-4), 0.6, 20000)
    values[:5] = [0.2, 0.5, 0.0, -1e-6, 0.09]  # above the range, zero, negative, near the top
    histogram = LatencyHistogram(limit_s=0.1)
    for v in values:
        histogram.add(float(v))
    assert histogram.n == len(values)
    assert histogram.max_s == values.max()
    for q in (50, 90, 99, 99.9):
        exact = np.percentile(values, q, method="inverted_cdf")
        assert exact <= histogram.percentile_s(q) <= exact + 1e-6 + 1e-12
    assert histogram.percentile_s(100) == values.max()


def test_cycle_timing_keeps_its_size_however_long_the_session():
    timing = CycleTiming()
    size = timing.compute.counts.nbytes + timing.late.counts.nbytes
    for k in range(50000):
        timing.add(1e-4 + 1e-9 * k, 1e-5)
    assert timing.cycles == 50000
    assert timing.compute.counts.nbytes + timing.late.counts.nbytes == size
    summary = timing.summary()
    assert summary["cycles"] == 50000
    assert 0.1 <= summary["compute_p50_ms"] <= 0.126
    assert summary["compute_max_ms"] == pytest.approx(0.1 + 1e-6 * 49999)


def psi(tmp_path, total_us):
    path = tmp_path / "cpu"
    path.write_text(
        f"some avg10=1.00 avg60=2.00 avg300=3.00 total={total_us}\n"
        "full avg10=0.00 avg60=0.00 avg300=0.00 total=0\n"
    )
    return path


def test_cpu_pressure_reads_the_kernels_some_total(tmp_path):
    pressure = CpuPressure(str(psi(tmp_path, 6801770460)))
    assert pressure.available
    assert pressure.waited_s() == pytest.approx(6801.77046)
    pressure.close()


def test_a_window_during_which_tasks_always_waited_is_overloaded(tmp_path):
    path = psi(tmp_path, 1_000_000)
    pressure = CpuPressure(str(path))
    pressure.start()
    # the file is read afresh each time: a second of waiting added at once exceeds any window
    psi(tmp_path, 2_000_000)
    text = pressure.overload()
    assert text is not None
    assert text.startswith("this machine was overloaded: tasks waited for")
    assert "100 %" in text
    pressure.stop()
    assert pressure.overload() is None
    pressure.close()


def test_an_idle_window_is_not_overloaded(tmp_path):
    pressure = CpuPressure(str(psi(tmp_path, 1_000_000)))
    pressure.start()
    assert pressure.overload() is None  # no waiting added
    pressure.close()


def test_without_the_kernels_file_nothing_is_measured(tmp_path):
    pressure = CpuPressure(str(tmp_path / "missing"))
    assert not pressure.available
    assert pressure.waited_s() is None
    pressure.start()
    assert pressure.overload() is None


def test_the_canary_counts_the_time_it_could_not_run():
    # a stopped process is the starvation the canary stands for: it cannot tick
    canary = Canary(tick_s=0.005, allowance_s=0.02)
    try:
        time.sleep(0.3)  # started, and ticking
        assert canary.since((0.0,) * len(canary.cores)) < 0.1  # ticks at most 100 ms late
        before = canary.starved_s()
        os.kill(canary._process.pid, signal.SIGSTOP)
        time.sleep(0.4)
        overdue = canary.since(before)  # read while it is stopped: counted already
        os.kill(canary._process.pid, signal.SIGCONT)
        time.sleep(0.1)
        after = canary.since(before)  # and once it ticked again
    finally:
        canary.close()
    # 400 ms stopped, less the 20 ms allowance; a busy machine may add, never take away
    assert 0.37 <= overdue <= 0.8
    assert 0.37 <= after <= 0.9
    assert after >= overdue - 0.005


PINNED_FIFO_HOG = """
import os, sys, time
os.sched_setaffinity(0, {int(sys.argv[1])})
os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(40))
end = time.monotonic() + float(sys.argv[2])
while time.monotonic() < end:
    pass
"""


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two cores")
def test_the_canary_sees_one_core_starved_while_the_other_is_free():
    # Real-time work on one core starves that core's ordinary tasks (such as the kernel worker
    # queued there with a serial port's bytes) while the other core runs ordinary tasks freely:
    # a canary free to run anywhere moves to the free core and sees nothing of it.
    canary = Canary(tick_s=0.005, allowance_s=0.02)
    hog_s = 0.4
    try:
        time.sleep(0.3)
        core = canary.cores[-1]
        before = canary.starved_s()
        hog = subprocess.run(
            [sys.executable, "-S", "-c", PINNED_FIFO_HOG, str(core), str(hog_s)],
            capture_output=True,
            text=True,
        )
        time.sleep(0.05)
        starved = canary.since(before)
        per_core = dict(zip(canary.cores, np.subtract(canary.starved_s(), before), strict=True))
    finally:
        canary.close()
    if hog.returncode != 0:
        pytest.skip(f"no real-time priority for the hog here: {hog.stderr.strip()[-200:]}")
    # 400 ms on that core, less the allowance; a busy machine may add to it
    assert 0.3 <= starved <= 1.0, per_core
    assert per_core[core] == pytest.approx(starved), per_core


def test_the_canary_ends_with_its_parent():
    code = (
        "from hoh_cosim.hardware.pressure import Canary; import os, time; "
        "c = Canary(); time.sleep(0.3); print(c._process.pid, flush=True); os._exit(0)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    pid = int(done.stdout.split()[0])
    stat = Path(f"/proc/{pid}/stat")

    def alive() -> bool:  # a zombie has ended: only its reaping is left, to init
        try:
            return stat.read_text().rsplit(")", 1)[1].split()[0] != "Z"
        except OSError:
            return False

    deadline = time.monotonic() + 5.0
    while alive() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not alive()
