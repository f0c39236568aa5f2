"""The scripted operator's deadlines on a busy machine (`agent/sim/pace.py`), in virtual time:
the thread times, the simulated seconds flown and the loop's lateness are made up as functions
of the clock, so each wait's outcome is exact."""

from __future__ import annotations

import os
import threading

import pytest

from agent.clock import VirtualClock
from agent.sim import pace as pacing
from agent.sim.pace import MAX_SLOWDOWN, Overdue, Pace, Stopped, schedstat

BASE_S = 10.0
NS = 1e9


def stretched(clock: VirtualClock, stretch: float, pid: int | None = None):
    """Thread times of a process whose one thread is always ready to run and gets a CPU
    1 / `stretch` of the time (every other process, or only `pid`)."""

    def threads(asked: int):
        t = clock.now()
        if pid is not None and asked != pid:
            return {1: (int(t * NS), 0)}  # busy, never waiting
        return {1: (int(t / stretch * NS), int(t * (1 - 1 / stretch) * NS))}

    return threads


async def test_a_wait_stretches_with_the_cpu_its_threads_waited_for():
    clock = VirtualClock()
    pace = Pace(clock, threads=stretched(clock, 3.0))
    # Due at 25 s: past a quiet machine's 10 s, within 3 × 10 s.
    assert await pace.until(lambda: clock.now() >= 25.0, BASE_S) is True
    late = await pace.until(lambda: False, BASE_S)
    assert isinstance(late, Overdue)
    assert 30.0 < late.waited_s <= 30.0 + pacing.POLL_S
    message = late.message("no acknowledgement of arm")
    assert message.startswith("no acknowledgement of arm in 30 s (its 10 s deadline stretched 3.0×")
    assert "the flight's threads took 3.0× their CPU time, waiting for a free CPU" in message


async def test_a_simulation_behind_real_time_stretches_it_with_no_scheduler_statistics():
    clock = VirtualClock()
    pace = Pace(clock, flown=lambda: clock.now() / 2, threads=lambda pid: None, load=lambda: None)
    assert await pace.until(lambda: clock.now() >= 15.0, BASE_S) is True
    late = await pace.until(lambda: False, BASE_S, fixed_s=5.0)  # a plan's 5 s do not stretch
    assert isinstance(late, Overdue)
    assert 25.0 < late.waited_s <= 25.0 + pacing.POLL_S
    assert "the simulation ran at 0.50× real time" in late.message("no result")


async def test_where_the_kernel_does_not_say_the_load_average_per_cpu_stands_in():
    clock = VirtualClock()
    pace = Pace(clock, threads=lambda pid: None, load=lambda: 2.5)
    late = await pace.until(lambda: False, BASE_S)
    assert 25.0 < late.waited_s <= 25.0 + pacing.POLL_S
    assert "the load average was 2.5 per CPU" in late.message("no result")


async def test_on_a_quiet_machine_the_deadline_and_the_message_are_a_quiet_machines():
    clock = VirtualClock()
    pace = Pace(clock, flown=clock.now, threads=stretched(clock, 1.0))
    late = await pace.until(lambda: False, BASE_S)
    assert BASE_S < late.waited_s <= BASE_S + pacing.POLL_S
    assert late.message("no acknowledgement of arm") == "no acknowledgement of arm in 10 s"


async def test_an_idle_process_says_nothing_and_a_busy_one_stretches_the_deadline():
    clock = VirtualClock()
    idle = Pace(clock, pids=lambda: [4242], threads=lambda pid: _idle(clock, pid))
    assert (await idle.until(lambda: False, BASE_S)).slowness.factor == 1.0
    worker = Pace(clock, pids=lambda: [4242, None], threads=stretched(clock, 4.0, pid=4242))
    late = await worker.until(lambda: False, BASE_S)
    assert late.slowness.cpu_stretch == pytest.approx(4.0)
    assert 40.0 < late.waited_s <= 40.0 + pacing.POLL_S


def _idle(clock: VirtualClock, pid: int):
    """This process busy and never waiting; process 4242 woken now and then, each time
    waiting for a CPU much longer than it runs (below MIN_RUN_S of running in all)."""
    if pid == 4242:
        return {7: (int(0.001 * clock.now() * NS), int(0.05 * clock.now() * NS))}
    return {1: (int(clock.now() * NS), 0)}


async def test_past_the_cap_the_wait_says_the_machine_was_too_busy_and_what_it_measured():
    # A loop that woke 2.4 s late once, a simulation at 0.31× real time, threads getting a
    # CPU a twentieth of the time they were ready.
    clock = VirtualClock(lateness=lambda deadline: 2.4 if 5.0 < deadline <= 5.05 else 0.0)
    pace = Pace(clock, flown=lambda: 0.31 * clock.now(), threads=stretched(clock, 20.0))
    late = await pace.until(lambda: False, BASE_S)
    assert late.too_busy
    assert MAX_SLOWDOWN * BASE_S < late.waited_s <= MAX_SLOWDOWN * BASE_S + pacing.POLL_S
    message = late.message("no acknowledgement of arm")
    assert message == (
        f"no acknowledgement of arm in {MAX_SLOWDOWN * BASE_S:.0f} s: this machine was too "
        "busy to fly the simulation in real time (the simulation ran at 0.31× real time, "
        "the flight's threads took 20.0× their CPU time, waiting for a free CPU and the "
        f"event loop lagged up to 2.4 s; a deadline stretches at most {MAX_SLOWDOWN:g}×); "
        "close other programs or fly when the machine is quieter"
    )


@pytest.mark.skipif(schedstat(os.getpid()) is None, reason="no /proc/PID/task/TID/schedstat")
def test_the_kernels_thread_times_name_this_thread_and_grow_as_it_runs():
    before = schedstat(os.getpid())[threading.get_native_id()]
    sum(range(2_000_000))  # some CPU time
    after = schedstat(os.getpid())[threading.get_native_id()]
    assert after[0] > before[0]
    assert after[1] >= before[1]
    assert schedstat(2**22 + 1) is None  # above any pid_max: no such process


async def test_a_flight_that_cannot_go_on_ends_the_wait_at_once_with_why():
    # The simulated aircraft down: no deadline to wait out, and no busy machine to blame.
    clock = VirtualClock()
    pace = Pace(clock, flown=clock.now, threads=stretched(clock, 3.0))
    down = {"at": 4.0}
    pace.stopped = lambda: "it touched the ground" if clock.now() >= down["at"] else None
    found = await pace.until(lambda: False, BASE_S)
    assert found == Stopped("it touched the ground")
    assert clock.now() < down["at"] + 2 * pacing.POLL_S
