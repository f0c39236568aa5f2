"""The scripted operator's deadlines on a busy machine: each wait's deadline stretches with how
much slower than real time the machine let the flight run while it waited.

A laptop running `sysid sim` is often doing other things. The simulated aircraft is cheap and
keeps real time, but the agent's own work slows down: arming the full preset renders its
multisines on a thread, and the identification runs in a worker process at a lower priority.
On a busy machine that work waits for a CPU, so a deadline fixed for a quiet machine runs out
while nothing is wrong. A wait here measures, over its own span:

- the CPU stretch of each watched process: (time its threads ran + time they were ready to
  run but waited for a CPU) / time they ran, from the kernel's per-thread scheduler
  statistics (Linux `/proc/PID/task/TID/schedstat`: ns on a CPU, ns waiting on a run queue;
  Documentation/scheduler/sched-stats.rst). That is how much longer CPU-bound work took than
  on an idle machine. Where the kernel does not say (not Linux), the 1-minute load average
  per CPU stands in for it, more coarsely (it counts our own threads too);
- the simulation's real-time ratio: simulated seconds flown per wall second;
- the loop's lag: how late the wait's own sleeps woke.

The slowdown factor is the larger of the CPU stretch and 1 / the real-time ratio. The
deadline is `fixed_s + base_s × factor`, the factor at most MAX_SLOWDOWN; past that the wait
reports that the machine was too busy to fly in real time, with what it measured.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agent.clock import Clock

# The most a deadline stretches. A laptop busy with a build or a video call slows the agent's
# work a few times; at ten times, the 90 s a result may take after its plan would be a quarter
# of an hour, and the operator is better told to fly when the machine is quieter.
MAX_SLOWDOWN = 10.0
# A process that ran less than this (s of CPU) during a wait is left out of the CPU stretch:
# a thread woken a few times can wait longer than it ran on any machine, and an idle worker
# says nothing about how slow the work is.
MIN_RUN_S = 0.05
# How often a wait looks at its event (s): well under the link's and the operator's times.
POLL_S = 0.05
# Slowdowns below this are a quiet machine's noise, not worth a word in a message.
NOTABLE = 1.1

ThreadTimes = dict[int, tuple[int, int]]
"""Each thread's (ns running, ns waiting for a CPU), by thread id."""


def schedstat(pid: int) -> ThreadTimes | None:
    """The process's threads' (ns on a CPU, ns waiting on a run queue), from the kernel's
    /proc/PID/task/TID/schedstat; None where there is no such file (not Linux, or no such
    process). A thread that ends while it is read is left out."""
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return None
    times: ThreadTimes = {}
    for tid in tids:
        try:
            run, wait = Path(f"/proc/{pid}/task/{tid}/schedstat").read_text().split()[:2]
        except (OSError, ValueError):
            continue
        times[int(tid)] = (int(run), int(wait))
    return times


def load_per_cpu() -> float | None:
    """The 1-minute load average per CPU (None where the system does not say)."""
    try:
        return os.getloadavg()[0] / (os.cpu_count() or 1)
    except (OSError, AttributeError):
        return None


@dataclass(frozen=True, kw_only=True)
class Slowness:
    """How slow the machine let the flight run over one wait."""

    cpu_stretch: float | None
    """The busiest watched process's (running + waiting for a CPU) / running; None: not
    measured (no scheduler statistics, or no process did enough work)."""
    load_per_cpu: float | None = None
    """The load average per CPU, where there are no scheduler statistics."""
    realtime: float | None
    """Simulated seconds per wall second; None: no simulator, or it did not step."""
    worst_lag_s: float
    """The latest the waiting loop woke (s)."""

    @property
    def factor(self) -> float:
        """How many times longer than on a quiet machine things took (at least 1)."""
        cpu = self.cpu_stretch if self.cpu_stretch is not None else self.load_per_cpu
        behind = 1 / self.realtime if self.realtime else 1.0
        return max(1.0, cpu or 1.0, behind)

    def describe(self) -> str:
        """What was measured, in words."""
        parts = []
        if self.realtime is not None:
            parts.append(f"the simulation ran at {self.realtime:.2f}× real time")
        if self.cpu_stretch is not None:
            parts.append(
                f"the flight's threads took {self.cpu_stretch:.1f}× their CPU time, "
                "waiting for a free CPU"
            )
        elif self.load_per_cpu is not None:
            parts.append(f"the load average was {self.load_per_cpu:.1f} per CPU")
        lag = self.worst_lag_s
        parts.append(
            f"the event loop lagged up to {lag:.1f} s"
            if lag >= 1
            else f"the event loop lagged up to {1000 * lag:.0f} ms"
        )
        return " and ".join([", ".join(parts[:-1]), parts[-1]] if len(parts) > 1 else parts)


@dataclass(frozen=True, kw_only=True)
class Overdue:
    """A wait whose deadline passed: how long it waited, its base and what it measured."""

    waited_s: float
    base_s: float
    fixed_s: float
    slowness: Slowness

    @property
    def too_busy(self) -> bool:
        """The deadline had stretched as far as it may: the machine was too slow for it."""
        return self.slowness.factor >= MAX_SLOWDOWN

    def message(self, failure: str) -> str:
        """`failure` ("no acknowledgement of arm") in N s, with the machine's slowness where
        it mattered."""
        waited, slow = f"{failure} in {self.waited_s:.0f} s", self.slowness
        if self.too_busy:
            return (
                f"{waited}: this machine was too busy to fly the simulation in real time "
                f"({slow.describe()}; a deadline stretches at most {MAX_SLOWDOWN:g}×); "
                "close other programs or fly when the machine is quieter"
            )
        if slow.factor >= NOTABLE:
            return (
                f"{waited} (its {self.base_s:g} s deadline stretched {slow.factor:.1f}× for a "
                f"busy machine: {slow.describe()})"
            )
        return waited


class Span:
    """One wait's measurements, from its start."""

    def __init__(self, pace: Pace):
        self._pace = pace
        self.start = pace.clock.now()
        self._flown = pace.flown()
        self._cpu = pace.cpu()
        self.worst_lag_s = 0.0

    def lagged(self, lag_s: float) -> None:
        self.worst_lag_s = max(self.worst_lag_s, lag_s)

    def slowness(self) -> Slowness:
        """What the machine did since the wait began."""
        pace, now, flown = self._pace, self._pace.clock.now(), self._pace.flown()
        realtime = None
        if self._flown is not None and flown is not None and flown > self._flown:
            realtime = (flown - self._flown) / max(now - self.start, 1e-9)
        cpu = pace.cpu()
        stretch = _stretch(self._cpu, cpu) if cpu is not None and self._cpu is not None else None
        return Slowness(
            cpu_stretch=stretch,
            load_per_cpu=pace.load() if cpu is None else None,
            realtime=realtime,
            worst_lag_s=self.worst_lag_s,
        )


def _stretch(before: dict[int, ThreadTimes], after: dict[int, ThreadTimes]) -> float | None:
    """The largest (run + wait) / run over the processes that ran MIN_RUN_S or more."""
    stretches = []
    for pid, threads in after.items():
        start = before.get(pid, {})
        run = wait = 0
        for tid, (r, w) in threads.items():
            r0, w0 = start.get(tid, (0, 0))
            run, wait = run + max(0, r - r0), wait + max(0, w - w0)
        if run >= MIN_RUN_S * 1e9:
            stretches.append((run + wait) / run)
    return max(stretches, default=None)


@dataclass(frozen=True)
class Stopped:
    """A wait ended because the flight cannot go on (`Pace.stopped`)."""

    reason: str


class Pace:
    """The measurements waits use: the clock, the simulated seconds flown so far (None: no
    simulator), the processes whose CPU waits count (this one always), and where thread times
    and the load average come from (the kernel's, unless a test gives its own)."""

    def __init__(
        self,
        clock: Clock,
        *,
        flown: Callable[[], float] | None = None,
        pids: Callable[[], Iterable[int | None]] = lambda: (),
        threads: Callable[[int], ThreadTimes | None] = schedstat,
        load: Callable[[], float | None] = load_per_cpu,
    ):
        self.clock = clock
        self._flown, self._pids, self._threads, self.load = flown, pids, threads, load
        # Why the flight cannot go on (None: it can): a wait ends at once with it, not at a
        # deadline blamed on a busy machine (the simulated aircraft hit the ground).
        self.stopped: Callable[[], str | None] = lambda: None

    def flown(self) -> float | None:
        return None if self._flown is None else self._flown()

    def cpu(self) -> dict[int, ThreadTimes] | None:
        """Each watched process's thread times now; None where this process's are unknown."""
        own = os.getpid()
        mine = self._threads(own)
        if mine is None:
            return None
        times = {own: mine}
        for pid in self._pids():
            if pid is not None and pid != own and (theirs := self._threads(pid)) is not None:
                times[pid] = theirs
        return times

    async def until(
        self, predicate: Callable[[], Any], base_s: float, fixed_s: float = 0.0
    ) -> Any | Overdue:
        """predicate()'s first truthy value, looked at every POLL_S; an Overdue once
        `fixed_s + base_s ×` the slowdown measured during the wait (at most MAX_SLOWDOWN) has
        passed. `fixed_s` is time that does not stretch (a plan plays in real time)."""
        span = Span(self)
        while not (found := predicate()):
            if (reason := self.stopped()) is not None:
                return Stopped(reason)
            waited = self.clock.now() - span.start
            if waited > fixed_s + base_s:  # late for a quiet machine: how slow was this one?
                slow = span.slowness()
                if waited > fixed_s + base_s * min(slow.factor, MAX_SLOWDOWN):
                    return Overdue(waited_s=waited, base_s=base_s, fixed_s=fixed_s, slowness=slow)
            wake = self.clock.now() + POLL_S
            await self.clock.sleep_until(wake)
            span.lagged(self.clock.now() - wake)
        return found
