"""The agent's health: event-loop lag, the collector's full passes, and a health record in
the execution log every HEALTH_S, so a flight's (or a soak's) resource use can be read
afterwards.

The gc callback (`GcWatch`) runs at arbitrary points: inside whatever allocation set the
collection off, on any thread, with that thread's locks held — a library thread in the middle
of logging, say, holding a handler's lock or a queue's mutex. A callback that logs or takes a
lock there can wait for a lock its own thread holds, forever. So it only reads the clock and
stores numbers in its own attributes (each store one atomic bytecode under the GIL); the loop
reads them with `take()` and does the logging.
"""

from __future__ import annotations

import asyncio
import gc
import json
import logging
import os
import resource
import sys
import threading
import time
import traceback
from collections import Counter, deque
from collections.abc import Callable
from pathlib import Path

import numpy as np

from agent.clock import Clock

log = logging.getLogger(__name__)

LAG_PERIOD_S = 0.01
LAG_WARN_S = 0.1
GC_WARN_S = 0.02
# Lag samples kept (10 min at 100 Hz).
LAG_SAMPLES = 60_000
# The health record in the execution log: this often (s).
HEALTH_S = 60.0
HEALTH_KEPT = 60
# Each health record also counts its lag samples in these bins (ms; 0.05 ms wide to 10 ms,
# 1 ms wide to 100 ms, then one open bin), so percentiles over a whole flight can be pooled
# from the records: `lag_percentile`.
LAG_EDGES_MS = np.round(
    np.concatenate([np.arange(0.0, 10.0, 0.05), np.arange(10.0, 100.5, 1.0)]), 2
)


def lag_histogram(ms: np.ndarray) -> dict[str, int]:
    """Lag samples (ms) counted by bin: {upper edge: count} for the bins that have any; the
    open bin above the last edge is "inf"."""
    bins = np.clip(np.searchsorted(LAG_EDGES_MS, ms, side="right"), 1, len(LAG_EDGES_MS))
    upper = [*(f"{e:g}" for e in LAG_EDGES_MS[1:]), "inf"]
    index, counts = np.unique(bins, return_counts=True)
    return {upper[i - 1]: int(c) for i, c in zip(index, counts, strict=True)}


def lag_percentile(histograms: list[dict[str, int]], q: float) -> float:
    """The q-th percentile (0-100) of the samples in several `lag_histogram`s together, as the
    upper edge of the bin it falls in (so never below the true value; inf if in the open bin)."""
    total: Counter[float] = Counter()
    for h in histograms:
        for edge, count in h.items():
            total[float(edge)] += count
    n = sum(total.values())
    if n == 0:
        raise ValueError("no lag samples")
    seen = 0
    for edge in sorted(total):
        seen += total[edge]
        if seen >= q / 100 * n:
            return edge
    return float("inf")


class GcWatch:
    """Times generation-2 (full) collections; register the instance in `gc.callbacks`."""

    def __init__(self, slow_s: float):
        self.slow_s = slow_s
        self.full = 0  # full passes seen
        self.slow = 0  # of those, slower than slow_s
        self.longest_s = 0.0  # the longest slow pass since the last take()
        self._start: float | None = None
        self._taken = 0

    def __call__(self, phase: str, info: dict) -> None:
        """The gc callback: no lock, no logging, nothing shared but its own numbers."""
        if info.get("generation") != 2:
            return
        now = time.perf_counter()
        if phase == "start":
            self._start = now
            return
        start, self._start = self._start, None
        if start is None:
            return
        took = now - start
        self.full += 1
        if took > self.slow_s:
            self.slow += 1
            self.longest_s = max(self.longest_s, took)

    @property
    def pending(self) -> bool:
        """Slow passes not yet taken."""
        return self.slow != self._taken

    def take(self) -> tuple[int, float]:
        """On the loop: (slow passes since the last take, the longest of them in s). A pass
        that ends on another thread during the take is counted at the next one."""
        slow = self.slow
        new, self._taken = slow - self._taken, slow
        longest, self.longest_s = self.longest_s, 0.0
        return new, longest


class Health:
    """The lag probe, the gc report and the health records. `busy` tells whether a window is
    being identified (its lag is also reported apart); `sections` gives the other parts'
    counters for each record (the agent's, the recorder's, the radio's, the link's, the
    logs')."""

    def __init__(
        self,
        *,
        clock: Clock,
        counters: Counter[str],
        busy: Callable[[], bool],
        sections: Callable[[], dict],
    ):
        self.clock, self.counters = clock, counters
        self._busy, self._sections = busy, sections
        self.lags: deque[float] = deque(maxlen=LAG_SAMPLES)
        self._period: list[tuple[float, bool]] = []  # since the last health record
        self._worst = 0.0  # the worst lag since `take_worst`
        self.gc_watch = GcWatch(GC_WARN_S)
        self.records: list[dict] = []  # the health records written so far (latest last)

    def add_lag(self, lag: float, identifying: bool) -> None:
        """One lag sample (s), and whether a window was being identified."""
        self.lags.append(lag)
        self._period.append((lag, identifying))
        self._worst = max(self._worst, lag)
        if lag > LAG_WARN_S:
            self.counters["loop_stalls"] += 1
            log.warning("event loop stalled for %.0f ms", lag * 1000)

    def take_worst(self) -> float:
        """The worst lag (s) since the last call."""
        worst, self._worst = self._worst, 0.0
        return worst

    async def probe(self) -> None:
        """Event-loop lag: how late a 10 ms sleep wakes (kept for the benchmark; > 100 ms is
        logged, as it starves the 50–100 Hz command and recording deadlines). Slow full
        collections are counted by the gc callback and logged here, on the loop."""
        loop = asyncio.get_running_loop()
        gc.callbacks.append(self.gc_watch)
        tracer = None
        trace_ms = os.environ.get("SYSID_STALL_TRACE_MS")
        if trace_ms:  # diagnosis: where the loop thread is while it stalls (see StallTracer)
            tracer = StallTracer(float(trace_ms) / 1000, threading.get_ident())
            tracer.start()
        try:
            while True:
                if tracer is not None:
                    tracer.beat()
                start = loop.time()
                await asyncio.sleep(LAG_PERIOD_S)
                self.add_lag(loop.time() - start - LAG_PERIOD_S, self._busy())
                self._report_gc()
        finally:
            gc.callbacks.remove(self.gc_watch)
            if tracer is not None:
                tracer.stop()

    def _report_gc(self) -> None:
        if not self.gc_watch.pending:
            return
        slow, longest = self.gc_watch.take()
        log.warning(
            "%d full garbage collection%s slower than %.0f ms, the longest %.0f ms",
            slow,
            "s" * (slow != 1),
            GC_WARN_S * 1000,
            longest * 1000,
        )

    async def write_records(self) -> None:
        """Every HEALTH_S: one `health {json}` line in the execution log — loop lag
        percentiles (all, and while identifying), CPU, memory, threads, tasks, open files,
        counters."""
        wall, cpu = time.monotonic(), time.process_time()
        while True:
            await asyncio.sleep(HEALTH_S)
            now_wall, now_cpu = time.monotonic(), time.process_time()
            record = self.record(now_wall - wall, now_cpu - cpu)
            wall, cpu = now_wall, now_cpu
            self.records.append(record)
            del self.records[:-HEALTH_KEPT]
            log.info("health %s", json.dumps(record))

    def record(self, wall_s: float, cpu_s: float) -> dict:
        """The health record of the period since the last one: `wall_s` long, with `cpu_s` of
        the process's CPU time."""
        lags, self._period = self._period, []
        every = np.array([lag for lag, _ in lags]) * 1000
        busy = np.array([lag for lag, identifying in lags if identifying]) * 1000
        return {
            "t": self.clock.now(),
            "lag": _percentiles(every),
            "lag_identifying": _percentiles(busy),
            "cpu_percent": 100 * cpu_s / wall_s if wall_s > 0 else None,
            "rss_mb": _rss_bytes() / 2**20,
            "threads": threading.active_count(),
            "tasks": len(asyncio.all_tasks()),
            "open_files": _open_files(),
            "counters": dict(self.counters),
            "gc": {"full": self.gc_watch.full, "slow": self.gc_watch.slow},
            **self._sections(),
        }


def _percentiles(ms: np.ndarray) -> dict:
    if not len(ms):
        return {"n": 0}
    p50, p99 = np.percentile(ms, [50, 99])
    return {
        "n": len(ms),
        "p50_ms": p50,
        "p99_ms": p99,
        "max_ms": float(ms.max()),
        "hist": lag_histogram(ms),
    }


class StallTracer(threading.Thread):
    """Diagnosis of event-loop stalls (SYSID_STALL_TRACE_MS=N): a thread that, when the lag
    probe has not run for N ms, logs where the loop thread is and what every other thread is
    doing, once per stall. If it cannot run during a stall either, another thread holds the
    GIL; if the loop thread is in select(), the process was not scheduled."""

    def __init__(self, threshold_s: float, loop_thread: int):
        super().__init__(name="stall-tracer", daemon=True)
        self.threshold_s, self.loop_thread = threshold_s, loop_thread
        self._beat = time.monotonic()
        self._stop = threading.Event()

    def beat(self) -> None:
        self._beat = time.monotonic()

    def stop(self) -> None:
        self._stop.set()

    def run(self) -> None:
        reported = False
        while not self._stop.wait(self.threshold_s / 4):
            age = time.monotonic() - self._beat
            if age <= self.threshold_s + LAG_PERIOD_S:
                reported = False
                continue
            if reported:
                continue
            reported = True
            frames = sys._current_frames()
            lines = [f"loop stalled {1000 * age:.0f} ms so far; loop thread at:"]
            loop_frame = frames.get(self.loop_thread)
            if loop_frame is not None:
                lines += [ln.rstrip() for ln in traceback.format_stack(loop_frame)[-6:]]
            names = {t.ident: t.name for t in threading.enumerate()}
            for ident, frame in frames.items():
                if ident in (self.loop_thread, threading.get_ident()):
                    continue
                top = traceback.extract_stack(frame)[-1]
                lines.append(
                    f"thread {names.get(ident, ident)}: {top.name} "
                    f"({Path(top.filename).name}:{top.lineno})"
                )
            log.warning("\n".join(lines))


def _rss_bytes() -> int:
    """Resident memory now (Linux /proc); elsewhere the peak, from getrusage."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _open_files() -> int | None:
    try:
        return len(os.listdir("/proc/self/fd"))
    except OSError:
        return None
