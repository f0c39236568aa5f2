"""`sysid sim` on a busy machine: the flight's process pinned to one CPU with CPU hogs beside
it, so the agent's CPU-bound work there runs several times slower, as on a laptop doing other
things — the kernel shares the CPU, no wall-clock margin makes it slow.

The work is arming a multisine (its low-peak phases are optimised on a thread, about a second
of CPU). Each test arms it first with the CPU to itself, then sets the operator's quiet-machine
deadline from that time, so the proportions hold on any machine: with HOGS beside it the arm
takes several times as long (at most HOGS + 1, the CPU's fair share), well past that deadline
(BASE × the quiet time).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import subprocess
import sys

import pytest

from agent.excitation import signals
from agent.excitation.plan import Multisine, Plan, Segment
from agent.link import messages
from agent.sim import flight
from agent.sim import pace as pacing
from agent.sim.flight import SimError, SimFlight, SimOptions, one_run, simulated
from agent.sim.pace import Overdue, Slowness, Span, schedstat

pytestmark = [
    pytest.mark.alone,  # its hogs starve whatever else runs beside it (Makefile: test)
    pytest.mark.usefixtures("no_leaked_tasks"),
    pytest.mark.timeout(180),
    pytest.mark.skipif(
        not hasattr(os, "sched_setaffinity") or schedstat(os.getpid()) is None,
        reason="needs Linux's CPU affinity and scheduler statistics",
    ),
]

# CPU-bound processes beside the flight on its CPU: work there gets about 1 / (HOGS + 1) of it.
HOGS = 5
# Beside the lateral run that follows the arm: the whole flight (simulated world, sensors,
# radios and agent, one process) needs about a quarter of a CPU to fly in real time (a lateral
# run: 4.5 s of CPU in 17.9 s, measured here), so under HOGS it got too little to fly at all
# (its sensors starved); with one hog it has half a CPU: busy, and still a machine that can fly.
RUN_HOGS = 1
# The quiet-machine deadline, as a multiple of the arm's time with the CPU to itself: the
# busy arm (several times as long) is well past it, and the stretch the operator measures
# (several times too) scales it past the busy arm.
BASE = 2.0
HARMONICS = (3, 5, 7, 9, 11, 13)


def heavy(plan_id: str) -> Plan:
    """A lateral multisine whose arming is CPU-bound: its phases are optimised afresh (the
    optimiser's cache cleared), about a second of CPU."""
    signals.forget_phases()
    sine = Multisine(harmonics=HARMONICS, period_s=20.0, periods=1.0, amplitude=2.0)
    return Plan(id=plan_id, axes="lateral", segments=(Segment(signals={"aileron": sine}),))


def _threads() -> list[int]:
    return [int(tid) for tid in os.listdir("/proc/self/task")]


@contextlib.contextmanager
def one_cpu():
    """This process's threads (and what they start later) on one CPU; yields it. The
    identification worker, started with the agent, keeps every CPU."""
    before = os.sched_getaffinity(0)
    cpu = {max(before)}
    for tid in _threads():
        with contextlib.suppress(OSError):  # a thread that just ended
            os.sched_setaffinity(tid, cpu)
    try:
        yield cpu
    finally:
        for tid in _threads():
            with contextlib.suppress(OSError):
                os.sched_setaffinity(tid, before)


# A hog spins until its parent is gone, too: pytest-timeout's thread method ends a stuck test's
# process with os._exit, past the `finally` that kills them, and hogs left spinning would slow
# every later test of the run.
HOG = (
    "import os\nparent = os.getppid()\n"
    "while os.getppid() == parent:\n    for _ in range(100_000):\n        pass\n"
)


@contextlib.contextmanager
def hogs(cpu: set[int], count: int = HOGS):
    """`count` processes spinning on `cpu` until the block ends (or this process does)."""
    spinning = [subprocess.Popen([sys.executable, "-c", HOG]) for _ in range(count)]
    try:
        for hog in spinning:
            os.sched_setaffinity(hog.pid, cpu)
        yield
    finally:
        for hog in spinning:
            hog.kill()
        for hog in spinning:
            hog.wait()


async def arm(sim: SimFlight, plan_id: str) -> tuple[float, Slowness]:
    """Arm the heavy plan; how long its acknowledgement took (s) and the slowness meanwhile."""
    span = Span(sim.ground.pace)
    ack = await sim.ground.command(messages.Arm(plan=heavy(plan_id)))
    assert ack.ok, ack.reason
    return sim.clock.now() - span.start, span.slowness()


async def test_on_a_busy_cpu_the_arm_is_acknowledged_late_and_the_flight_flies(
    tmp_path, monkeypatch
):
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        with one_cpu() as cpu:
            quiet, _ = await arm(sim, "quiet")
            monkeypatch.setattr(flight, "ACK_S", BASE * quiet)
            with hogs(cpu):
                busy, slowness = await arm(sim, "busy")
            with hogs(cpu, RUN_HOGS):
                outcome = await one_run(
                    SimOptions(preset="lateral"), sim.aircraft, sim.ground, 0, lambda text: None
                )
    # A quiet machine's deadline had passed when the acknowledgement came: the operator
    # waited on because it measured the CPU's slowness.
    assert busy > flight.ACK_S, (quiet, busy, slowness)
    assert slowness.cpu_stretch > BASE, slowness
    assert busy <= flight.ACK_S * slowness.factor
    # The lateral run was armed, played and identified on the busy CPU.
    assert outcome["events"] == ["started", "finished"]
    assert "result" in outcome, outcome


async def test_past_the_cap_the_operator_says_the_machine_was_too_busy(tmp_path, monkeypatch):
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        with one_cpu() as cpu:
            quiet, _ = await arm(sim, "quiet")
            monkeypatch.setattr(flight, "ACK_S", quiet)
            # No stretch allowed: the busy arm (several times the quiet one) is past the cap
            # however roughly the stretch is measured over it.
            monkeypatch.setattr(pacing, "MAX_SLOWDOWN", 1.0)
            with hogs(cpu), pytest.raises(SimError) as caught:
                await arm(sim, "busy")
    message = str(caught.value)
    assert message.startswith("no acknowledgement of arm in "), message
    assert "this machine was too busy to fly the simulation in real time" in message
    # What was measured over the wait: the CPU stretch only when the flight's process ran at
    # least MIN_RUN_S in it (tests/sim/test_pace.py checks that phrase); these two always.
    assert re.search(r"the simulation ran at \d+\.\d\d× real time", message), message
    assert re.search(r"the event loop lagged up to \d+(\.\d s| ms)", message), message


def test_under_json_the_too_busy_failure_is_one_object(monkeypatch, capsys):
    from agent.cli import main

    slow = Slowness(cpu_stretch=12.0, realtime=0.31, worst_lag_s=2.4)
    late = Overdue(waited_s=100.0, base_s=10.0, fixed_s=0.0, slowness=slow)
    text = late.message("no acknowledgement of arm")

    async def too_busy(options):
        raise SimError(text)

    monkeypatch.setattr(flight, "fly", too_busy)
    assert main(["sim", "--json"]) == 1
    out = capsys.readouterr().out
    assert out.count("\n") == 1
    assert json.loads(out) == {"error": {"kind": "error", "message": text, "exit": 1}}
