"""`sysid agent`: the flight agent — one event loop and one TaskGroup owning the sensor
drivers, the autopilot link, the recorder, the excitation scheduler, the radio link session,
the identification job runner and the health monitor (thesis chapter 5.1, algorithm 1).

Every component runs under `_supervised`: a component that fails is logged, counted and
restarted after a backoff; it never takes the others down. Identification runs in a worker
process started (and warmed up) with the agent, so the loop never waits on numerics. On
SIGINT/SIGTERM a running excitation is aborted (trim, then release), logs are flushed and
closed, the worker is stopped.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import json
import logging
import multiprocessing
import os
import resource
import signal
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Awaitable, Callable
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import numpy as np

from agent.channels import AXIS_SETS, SENSOR_CHANNELS
from agent.clock import Clock, LoopClock
from agent.config import Config
from agent.excitation.plan import PlanRefused
from agent.excitation.scheduler import Event, Scheduler, Window
from agent.health import GcWatch
from agent.ident import Settings
from agent.ident import job as jobs
from agent.ident.job import settings_from
from agent.link import messages
from agent.link.codec import AIRCRAFT
from agent.link.endpoint import build_endpoint
from agent.logs import Logbook, LogWriter, config_hash, log_name, units_of
from agent.models import SELF_CHECK_RATIO, Candidate, ModelStore, suggest
from agent.recorder import Recorder
from drivers.airdata.driver import make_driver as airdata
from drivers.autopilot.driver import AutopilotLink
from drivers.surfaces.driver import make_driver as surfaces
from drivers.vectornav.driver import make_driver as vn200

log = logging.getLogger(__name__)

# Restart backoff of a failed component: first wait, doubling to at most this.
RESTART_S, RESTART_MAX_S = 0.5, 10.0
# Identification jobs waiting (more are dropped and counted: the operator can re-fly).
JOB_QUEUE = 4
# Ground commands waiting to be handled (more are refused as busy).
COMMAND_QUEUE = 16
STATUS_S = 1.0
LAG_PERIOD_S = 0.01
LAG_WARN_S = 0.1
GC_WARN_S = 0.02
SWITCH_INTERVAL_S = 0.00025
# At shutdown, how long an identification in the worker may go on before the worker is killed.
WORKER_STOP_S = 2.0
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
RESULTS_KEPT = 100


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


class Agent:
    """The onboard agent; `run()` serves until cancelled."""

    def __init__(
        self,
        config: Config,
        *,
        base: Path = Path("."),
        clock: Clock | None = None,
        config_text: str = "",
    ):
        self.config, self.base = config, Path(base)
        self.clock = clock or LoopClock()
        self.counters: Counter[str] = Counter()
        self.writer = LogWriter(self.base / config.recorder.log_dir)
        self.recorder = Recorder(config.recorder, self.clock, on_excitation=self._on_window_logged)
        self.logbook = Logbook(
            self.writer,
            self.recorder.columns,
            units_of(self.recorder.columns, SENSOR_CHANNELS),
            config_hash(config_text),
            config.recorder.rate_hz,
        )
        self.recorder.sink = self.logbook.row
        # The result log: one JSON object per identification (thesis 2.2.1).
        self._results = self.writer.open(log_name(self.writer.next_number(), "results", "jsonl"))
        excitation = config.excitation
        self.autopilot = AutopilotLink(
            config.autopilot,
            self.clock,
            switch_channel=excitation.switch_channel,
            on_switch=lambda pwm, t: self.scheduler.update_switch(pwm, t),
            on_state=lambda s: self.scheduler.update_state(s),
            on_servos=lambda t, p: self.scheduler.update_servos(t, p),
            on_sample=self.recorder.push,
            on_link=self._on_autopilot_link,
        )
        self.scheduler = Scheduler(excitation, self.autopilot, self.clock)
        self.scheduler.subscribe(self._on_scheduler)
        self.models = ModelStore(self.base / "models")
        self.ident = messages.IdentSettings(axes=config.identification.axes)
        self._jobs: asyncio.Queue = asyncio.Queue(JOB_QUEUE)
        self._commands: asyncio.Queue = asyncio.Queue(COMMAND_QUEUE)
        # The model store's files are read and written on this one thread, in order: a save
        # (rename) can wait on the disk for a long time, and the loop must not.
        self._store = ThreadPoolExecutor(1, thread_name_prefix="model-store")
        self._batch: dict[str, list] = {}
        self._self_check: dict[str, str] = {}
        self._model_number = 0
        self.session = None
        self.radio = None
        # The latest results (all of them are in the result log).
        self.results: deque[dict] = deque(maxlen=RESULTS_KEPT)
        self.lags: deque[float] = deque(maxlen=LAG_SAMPLES)
        self._period_lags: list[tuple[float, bool]] = []  # since the last health record
        self.identifying = False  # a window is in the worker (lag while identifying)
        self._status_lag = 0.0  # the worst lag since the last status
        self._logs_failing = False
        self._pool: ProcessPoolExecutor | None = None  # the worker; replaced if it dies
        # Full collections, timed by a gc callback (which must neither log nor lock: see
        # agent/health.py) and reported by the lag monitor.
        self.gc_watch = GcWatch(GC_WARN_S)
        self._log_handler = None  # the execution log's handler while running
        self.health: list[dict] = []  # the health records written so far (latest last)
        self.drivers = self._drivers()

    def _drivers(self):

        sensors = self.config.sensors
        makers = {"vn200": vn200, "airdata": airdata, "surfaces": surfaces}
        return [
            make(sensors, self.clock, self.recorder.push)
            for name, make in makers.items()
            if getattr(sensors, name).enabled
        ]

    # -- running ----------------------------------------------------------------------------

    async def run(self) -> None:
        slow_ms = os.environ.get("SYSID_SLOW_CALLBACK_MS")
        if slow_ms:  # diagnosis of loop stalls: asyncio names every callback slower than this
            loop = asyncio.get_running_loop()
            loop.set_debug(True)
            loop.slow_callback_duration = float(slow_ms) / 1000
        # Threads hand the GIL over every 0.25 ms instead of 5: a thread that wants the GIL
        # waits up to this long for the holder to let go, and with the log writer formatting
        # an excitation log (as the worker starts identifying) the loop thread waited that long
        # at every wake-up, a convoy that stalled it for 50 ms and more. The measurements are
        # in docs/agent.md, *Measured resource use* (benchmarks/bench_agent.py).
        switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        handler = self._log_handler = self.logbook.handler(self.clock)
        logging.getLogger().addHandler(handler)
        self._pool = self._new_worker()
        restore = self._realtime(self.config.runtime.realtime_priority)
        try:
            self._build_link()
            # Everything built so far lives as long as the agent: moved out of the collector's
            # way, so a full collection (which walked it and stalled the loop for up to 0.8 s
            # in the simulator) only looks at what the flight allocates.
            gc.collect()
            gc.freeze()
            async with asyncio.TaskGroup() as group:
                for driver in self.drivers:
                    group.create_task(self._supervised(driver.name, driver.run), name=driver.name)
                named = {
                    "lag": self._lag_monitor,
                    "health": self._health_loop,
                    "autopilot": self.autopilot.run,
                    "recorder": self.recorder.run,
                    "scheduler": self.scheduler.run,
                    "status": self._status_loop,
                    "periodic": self._periodic_loop,
                    "identification": self._job_loop,
                    "commands": self._command_loop,
                }
                if self.session is not None:
                    named["link"] = self.session.run
                    named["radio"] = self.radio.watch
                for name, factory in named.items():
                    group.create_task(self._supervised(name, factory), name=name)
                log.info(
                    "agent started: %s", ", ".join([d.name for d in self.drivers] + list(named))
                )
        finally:
            if restore is not None:
                os.sched_setscheduler(0, *restore)
            sys.setswitchinterval(switch)
            logging.getLogger().removeHandler(handler)
            try:
                await _stop_worker(self._pool)
                self._store.shutdown(wait=True)
                if self.radio is not None:
                    await self.radio.close()
            finally:  # cancelled again while stopping: the logs are still flushed and closed
                self.writer.close()

    async def _supervised(self, name: str, factory: Callable[[], Awaitable[None]]) -> None:
        delay = RESTART_S
        while True:
            try:
                await factory()
                return
            except asyncio.CancelledError:
                raise
            except Exception:  # one component's fault must not stop the others: log, restart
                self.counters[f"{name}_restarts"] += 1
                log.exception("%s failed; restarting in %.1f s", name, delay)
                await asyncio.sleep(delay)
                delay = min(delay * 2, RESTART_MAX_S)

    def _build_link(self) -> None:
        if self.config.link.peer is None:
            log.info("link: no [link] peer configured, radio not started")
            return
        # Built, not opened: the radio's watch task opens it beside the drivers, so a module
        # that does not answer at power-up leaves the aircraft recording without a link.
        try:
            self.radio, self.session = build_endpoint(
                self.config.link, AIRCRAFT, self.base, self.clock, self._on_ground
            )
        except (ValueError, OSError) as exc:  # the link refused, not the agent: it records
            self.counters["link_refused"] += 1
            log.error("link refused, flying without it: %s", exc)

    # -- events -----------------------------------------------------------------------------

    def _downlink(self, message: messages.Message, reliable: bool = True) -> None:
        if self.session is not None:
            (self.session.send_reliable if reliable else self.session.send_status)(message)

    def _on_scheduler(self, item: Event | Window) -> None:
        self.recorder.mark(item)
        if isinstance(item, Event) and item.kind != "progress":
            self._downlink(
                messages.ExcitationEvent(
                    event=item.kind, plan_id=item.plan_id, time=item.time, detail=item.detail
                )
            )

    def _on_autopilot_link(self, up: bool, reason: str) -> None:
        if not up:
            self.scheduler.abort(f"autopilot link lost: {reason}")

    def _on_window_logged(self, window: Window, rows: np.ndarray) -> None:
        """The recorder has the window and its margin: log it and queue its identification."""
        self.logbook.excitation(window, rows, batch=self.ident.batch)
        if window.outcome != "finished":
            self._downlink(
                messages.Notice(text=f"{window.plan_id} aborted ({window.reason}): not identified")
            )
            return
        try:
            self._jobs.put_nowait((window, rows))
        except asyncio.QueueFull:
            self.counters["jobs_dropped"] += 1
            self._downlink(messages.Notice(text="identification queue full: window dropped"))

    def _on_ground(self, message: messages.Message, seq: int | None) -> None:
        """A command from the ground. An abort acts at once; the others are handled in order
        by the command task, which keeps rendering and model-store files off the loop."""
        if isinstance(message, messages.Abort):
            self.scheduler.abort(message.reason)
            self._cancel_queued_runs()
            if seq is not None:
                self._downlink(messages.Ack(ref=seq, ok=True))
            return
        try:
            self._commands.put_nowait((message, seq))
        except asyncio.QueueFull:
            self.counters["commands_dropped"] += 1
            if seq is not None:
                reason = "busy: too many commands waiting; send it again"
                self._downlink(messages.Ack(ref=seq, ok=False, reason=reason))

    def _cancel_queued_runs(self) -> None:
        """An abort also cancels an arm or start still waiting its turn (else a plan armed a
        moment before the abort would be armed after it)."""
        kept = []
        while not self._commands.empty():
            message, seq = self._commands.get_nowait()
            if isinstance(message, messages.Arm | messages.Start):
                self.counters["commands_cancelled"] += 1
                if seq is not None:
                    reason = "cancelled by an abort that arrived before it was carried out"
                    self._downlink(messages.Ack(ref=seq, ok=False, reason=reason))
            else:
                kept.append((message, seq))
        for item in kept:
            self._commands.put_nowait(item)

    async def _command_loop(self) -> None:
        while True:
            message, seq = await self._commands.get()
            await self.handle(message, seq)

    async def handle(self, message: messages.Message, seq: int | None) -> None:
        """Carry out one ground command and acknowledge it (or say why not)."""
        ok, reason = True, ""
        loop = asyncio.get_running_loop()
        try:
            if isinstance(message, messages.Arm):
                await self.scheduler.arm_checked(message.plan)
            elif isinstance(message, messages.Start):
                reason = self.scheduler.request_start()
                ok = not reason
            elif isinstance(message, messages.Abort):
                self.scheduler.abort(message.reason)
            elif isinstance(message, messages.IdentSettings):
                reason = _settings_refusal(self.config, message)
                ok = not reason
                if ok:
                    self.ident = message
            elif isinstance(message, messages.Decision):
                check = await loop.run_in_executor(self._store, self._decide, message)
                if check is not None:  # a new nominal replacing one: self-check it next run
                    self._self_check[check[0]] = check[1]
            elif isinstance(message, messages.Revert):
                await loop.run_in_executor(self._store, self.models.revert, self.ident.axes)
        except (PlanRefused, KeyError, LookupError) as exc:
            ok, reason = False, str(exc).strip("'")
        if seq is not None:
            self._downlink(messages.Ack(ref=seq, ok=ok, reason=reason))

    def _decide(self, decision: messages.Decision) -> tuple[str, str] | None:
        """On the model-store thread; (axes, model id) when the accepted model replaced a
        nominal, for the 6.3.1 self-check."""
        if not decision.accept:
            self.models.reject(decision.model_id)
            return None
        accepted = self.models.accept(decision.model_id)
        if self.models.previous(accepted.axes) is None:
            return None
        return accepted.axes, accepted.model_id

    async def _periodic_loop(self) -> None:
        """Thesis B.2 4.1: identify every update period set from the ground, on the data
        recorded over that period (nothing when no period is set)."""
        while True:
            period = self.ident.update_period_s
            await asyncio.sleep(period or STATUS_S)
            if period:
                self.periodic_window(self.clock.now(), period)

    def periodic_window(self, now: float, period: float) -> bool:
        """Queue the last `period` seconds of frames for identification; False if dropped."""
        end = now - self.config.recorder.delay_s
        rows = self.recorder.ring.between(end - period, end)
        if len(rows) < 2:
            return False
        window = Window(f"periodic@{end:.0f}", self.ident.axes, end - period, end, "finished")
        try:
            self._jobs.put_nowait((window, rows))
        except asyncio.QueueFull:
            self.counters["jobs_dropped"] += 1
            return False
        return True

    # -- identification ---------------------------------------------------------------------

    def _realtime(self, priority: int | None) -> tuple[int, os.sched_param] | None:
        """The loop's thread to SCHED_FIFO `priority` ([runtime] realtime_priority), with
        SCHED_RESET_ON_FORK so threads and processes started from it run normally; the policy
        to restore, or None. Not permitted: a warning, counted, and normal scheduling."""
        if priority is None:
            return None
        previous = (os.sched_getscheduler(0), os.sched_getparam(0))
        try:
            os.sched_setscheduler(
                0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority)
            )
        except (OSError, AttributeError) as exc:
            self.counters["realtime_refused"] += 1
            log.warning("realtime_priority %d not set (%s): normal scheduling", priority, exc)
            return None
        log.info("event loop thread at SCHED_FIFO %d", priority)
        return previous

    @staticmethod
    def _new_worker() -> ProcessPoolExecutor:
        """The identification worker: one process, spawned (no fork of a threaded process)."""
        context = multiprocessing.get_context("spawn")
        return ProcessPoolExecutor(1, mp_context=context, initializer=jobs.start_worker)

    async def _job_loop(self) -> None:
        loop = asyncio.get_running_loop()
        # The worker is up before the first window.
        await loop.run_in_executor(self._pool, jobs.warm)
        while True:
            window, rows = await self._jobs.get()
            self.identifying = True
            try:
                await self._identify(loop, self._pool, window, rows)
            except BrokenProcessPool as exc:  # the worker died (killed, out of memory): anew
                self.counters["worker_restarts"] += 1
                log.error("the identification worker died (%s); starting a new one", exc)
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = self._new_worker()
                self._failed(
                    f"{window.plan_id}",
                    self.ident.axes,
                    "the identification worker process died; a new one is started "
                    "for the next window",
                )
            except Exception as exc:  # a fault in one identification: a failure result, go on
                log.exception("identification of %s failed", window.plan_id)
                self._failed(f"{window.plan_id}", self.ident.axes, f"internal error: {exc!r}")
            finally:
                self.identifying = False

    async def _identify(self, loop, pool, window: Window, rows: np.ndarray) -> None:
        axes = self.ident.axes
        inputs, outputs = self.config.identification.channels.axis_set(axes)
        roles = AXIS_SETS[axes][1]
        # Numbered across boots (the model store's file): an id never names two models.
        self._model_number = await loop.run_in_executor(self._store, self.models.reserve_number)
        model_id = f"{axes[:3]}-{self._model_number}"
        navigation = self.config.identification.channels.navigation()
        needed = {*inputs, *outputs, *navigation}
        columns = {c: rows[:, 1 + k] for k, c in enumerate(self.recorder.channels) if c in needed}
        dt = 1.0 / self.config.recorder.rate_hz
        batch = self._batch.setdefault(axes, []) if self.ident.batch else []
        settings = _settings(self.config, self.ident)
        job = jobs.Job(
            model_id,
            axes,
            dt,
            inputs,
            outputs,
            roles,
            tuple(batch),
            settings,
            window=columns,
            trim_s=self.config.identification.trim_seconds,
            navigation=navigation,
        )
        outcome = await loop.run_in_executor(pool, jobs.run, job)
        if not outcome["ok"]:
            return self._failed(model_id, axes, outcome["reason"])
        experiment, trim = outcome["experiment"], outcome["trim"]
        if self.ident.batch:
            batch.append(experiment)
        experiments = (*job.experiments, experiment)
        candidate = Candidate(
            model_id,
            axes,
            dt,
            outcome["result"],
            outcome["preprocessing"],
            experiments,
            extra={"record_s": len(experiment[0]) * dt, "trim": trim},
        )
        nominal = await loop.run_in_executor(self._store, self.models.nominal, axes)
        tic_jn = tic_nj = None
        if nominal is not None:
            tic_jn = await loop.run_in_executor(
                pool,
                jobs.cross_tic,
                candidate.result,
                candidate.preprocessing,
                dt,
                nominal.experiments,
            )
            tic_nj = await loop.run_in_executor(
                pool,
                jobs.cross_tic,
                nominal.result,
                nominal.preprocessing,
                dt,
                candidate.experiments,
            )
            await self._check_new_nominal(axes, nominal, tic_nj, loop, pool, candidate)
        suggestion = suggest(candidate, nominal, tic_jn, tic_nj)
        await loop.run_in_executor(self._store, self.models.add, candidate)
        record = {
            "model_id": model_id,
            "axes": axes,
            "window": [window.start, window.end],
            "trim": trim,
            "suggestion": suggestion.__dict__,
            "result": outcome["result"],
        }
        self.results.append(record)
        self.counters["identifications"] += 1
        self.writer.write(self._results, (json.dumps(record) + "\n").encode())
        self._downlink(_result_message(candidate, suggestion))

    async def _check_new_nominal(self, axes, nominal, tic_nj, loop, pool, candidate) -> None:
        """Requirement 6.3.1: a just-accepted nominal predicting this new excitation much worse
        than the model it replaced is rolled back, and the ground is told."""
        if self._self_check.pop(axes, None) != nominal.model_id:
            return
        previous = await loop.run_in_executor(self._store, self.models.previous, axes)
        tic_previous = await loop.run_in_executor(
            pool,
            jobs.cross_tic,
            previous.result,
            previous.preprocessing,
            candidate.record_dt,
            candidate.experiments,
        )
        if tic_nj > SELF_CHECK_RATIO * tic_previous:
            await loop.run_in_executor(self._store, self.models.revert, axes)
            text = (
                f"self-check: nominal {nominal.model_id} predicts the new data with TIC "
                f"{tic_nj:.2f} against {tic_previous:.2f} for {previous.model_id}: reverted"
            )
            self._downlink(messages.Notice(text=text))

    def _failed(self, model_id: str, axes: str, reason: str) -> None:
        self.counters["identification_failures"] += 1
        log.warning("identification %s failed: %s", model_id, reason)
        self.results.append({"model_id": model_id, "axes": axes, "failure": reason})
        self.writer.write(self._results, (json.dumps(self.results[-1]) + "\n").encode())
        self._downlink(messages.Failure(model_id=model_id, axes=axes, reason=reason[:300]))

    async def _lag_monitor(self) -> None:
        """Event-loop lag: how late a 10 ms sleep wakes (kept for the benchmark; > 100 ms is
        logged, as it starves the 50–100 Hz command and recording deadlines)."""
        loop = asyncio.get_running_loop()
        gc.callbacks.append(self.gc_watch)
        try:
            await self._lag_loop(loop)
        finally:
            gc.callbacks.remove(self.gc_watch)

    async def _lag_loop(self, loop) -> None:
        tracer = None
        trace_ms = os.environ.get("SYSID_STALL_TRACE_MS")
        if trace_ms:  # diagnosis: where the loop thread is while it stalls (see StallTracer)
            tracer = StallTracer(float(trace_ms) / 1000, threading.get_ident())
            tracer.start()
        try:
            await self._probe(loop, tracer)
        finally:
            if tracer is not None:
                tracer.stop()

    async def _probe(self, loop, tracer) -> None:
        while True:
            if tracer is not None:
                tracer.beat()
            start = loop.time()
            await asyncio.sleep(LAG_PERIOD_S)
            lag = loop.time() - start - LAG_PERIOD_S
            self.lags.append(lag)
            self._period_lags.append((lag, self.identifying))
            self._status_lag = max(self._status_lag, lag)
            if lag > LAG_WARN_S:
                self.counters["loop_stalls"] += 1
                log.warning("event loop stalled for %.0f ms", lag * 1000)
            self._report_gc()

    def _report_gc(self) -> None:
        """Slow full collections, counted by the gc callback, logged here on the loop."""
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

    async def _health_loop(self) -> None:
        """Every HEALTH_S: one `health {json}` line in the execution log — loop lag
        percentiles (all, and while identifying), CPU, memory, threads, tasks, open files,
        counters — so a flight's (or a soak's) resource use can be read afterwards."""
        wall, cpu = time.monotonic(), time.process_time()
        while True:
            await asyncio.sleep(HEALTH_S)
            now_wall, now_cpu = time.monotonic(), time.process_time()
            record = self.health_record(now_wall - wall, now_cpu - cpu)
            wall, cpu = now_wall, now_cpu
            self.health.append(record)
            del self.health[:-HEALTH_KEPT]
            log.info("health %s", json.dumps(record))

    def health_record(self, wall_s: float, cpu_s: float) -> dict:
        lags, self._period_lags = self._period_lags, []
        every = np.array([lag for lag, _ in lags]) * 1000
        busy = np.array([lag for lag, identifying in lags if identifying]) * 1000

        def percentiles(ms: np.ndarray) -> dict:
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

        return {
            "t": self.clock.now(),
            "lag": percentiles(every),
            "lag_identifying": percentiles(busy),
            "cpu_percent": 100 * cpu_s / wall_s if wall_s > 0 else None,
            "rss_mb": _rss_bytes() / 2**20,
            "threads": threading.active_count(),
            "tasks": len(asyncio.all_tasks()),
            "open_files": _open_files(),
            "counters": dict(self.counters),
            "gc": {"full": self.gc_watch.full, "slow": self.gc_watch.slow},
            "recorder": dict(self.recorder.counters),
            # The radio's failed opens, losses and reopens, and the link's drops: a flight whose
            # radio never answered shows it here, not only in warning lines.
            "radio": dict(self.radio.counters) if self.radio is not None else None,
            "link": dict(self.session.counters) if self.session is not None else None,
            "logs": {
                "errors": self.writer.errors,
                "dropped": self.writer.dropped,
                "lost_lines": self.writer.lost_lines,
                "unformattable": getattr(self._log_handler, "unformattable", 0),
                "failures": self.writer.failures[-3:],
            },
        }

    # -- status -----------------------------------------------------------------------------

    def _watch_logs(self) -> None:
        """Tell the ground once when the logs stop being written (disk full or failing) and
        once when they are written again; recording to memory and identification go on."""
        failing = self.writer.failing
        if failing is not None and not self._logs_failing:
            text = (
                f"logs not written: {failing}; {self.writer.lost_lines} lines lost so far; "
                "recording in memory and identification go on"
            )
            log.error(text)
            self._downlink(messages.Notice(text=text[:200]))
        elif failing is None and self._logs_failing:
            text = f"logs written again after {self.writer.lost_lines} lines lost"
            log.warning(text)
            self._downlink(messages.Notice(text=text))
        self._logs_failing = failing is not None

    async def _status_loop(self) -> None:
        while True:
            await asyncio.sleep(STATUS_S)
            self._watch_logs()
            t = self.autopilot.telemetry
            lag, self._status_lag = self._status_lag, 0.0
            att, hud, aoa = t.get("ATTITUDE", {}), t.get("VFR_HUD", {}), t.get("AOA_SSA", {})
            sensors = {}
            for driver in self.drivers:
                h = driver.health()
                sensors[driver.name] = {
                    "state": h.state,
                    "rate_hz": h.rate_hz,
                    "gaps": h.gaps,
                    "crc_errors": h.crc_errors,
                    "age_s": h.last_sample_age,
                }
            self._downlink(
                messages.Status(
                    time=self.clock.now(),
                    flight_mode=self.autopilot.flight_mode,
                    airspeed=hud.get("airspeed"),
                    altitude=hud.get("alt"),
                    alpha=aoa.get("AOA"),
                    beta=aoa.get("SSA"),
                    roll=att.get("roll"),
                    pitch=att.get("pitch"),
                    yaw=att.get("yaw"),
                    excitation=self.scheduler.status,
                    identifying=self.identifying,
                    loop_lag_ms=round(lag * 1000, 2),
                    nominal={
                        axes: model_id
                        for axes in AXIS_SETS
                        if (model_id := self.models.nominal_id(axes)) is not None
                    },
                    recorder={
                        **{k: float(v) for k, v in self.recorder.counters.items()},
                        "log_lost_lines": float(self.writer.lost_lines),
                        "log_dropped": float(self.writer.dropped),
                    },
                    sensors=sensors,
                ),
                reliable=False,
            )


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
        import sys
        import traceback

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


async def _stop_worker(pool: ProcessPoolExecutor) -> None:
    """Stop the worker without waiting on it for ever: an idle worker exits at once; one still
    identifying (or starved of CPU on a busy machine) is killed after WORKER_STOP_S — its
    window is lost either way at shutdown, and the loop must not block on it. Then the pool's
    manager thread, which notices the exit, is given WORKER_STOP_S to end."""
    # Python < 3.14 has no public way to reach the processes or the manager thread.
    processes = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    loop = asyncio.get_running_loop()

    async def wait(done: Callable[[], bool]) -> None:
        deadline = loop.time() + WORKER_STOP_S
        while not done() and loop.time() < deadline:
            await asyncio.sleep(0.05)

    try:
        await wait(lambda: not any(p.is_alive() for p in processes))
    finally:  # the deadline, or cancelled while waiting
        for process in processes:
            if process.is_alive():
                process.kill()
                log.warning("the identification worker did not stop in time: killed")
    await wait(lambda: not any(p.is_alive() for p in processes))
    if manager is not None:
        await wait(lambda: not manager.is_alive())


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


def _settings_refusal(config: Config, ident: messages.IdentSettings) -> str:
    """Why settings from the ground may not be used onboard ("" when they may): an explicit p
    or order beyond the configured markov_max / order_max (the automatic search keeps within
    them; an explicit value skipped the bounds)."""
    cfg, reasons = config.identification, []
    if isinstance(ident.markov, int) and not 1 <= ident.markov <= cfg.markov_max:
        reasons.append(f"p {ident.markov} is outside 1…{cfg.markov_max} (markov_max)")
    if isinstance(ident.order, int) and not 1 <= ident.order <= cfg.order_max:
        reasons.append(f"order {ident.order} is outside 1…{cfg.order_max} (order_max)")
    return "; ".join(reasons)


def _settings(config: Config, ident: messages.IdentSettings) -> Settings:

    markov = None if ident.markov == "auto" else ident.markov
    order = None if ident.order == "auto" else ident.order
    settings = settings_from(config.identification, markov, order)
    # The surface pots sample continuously moving surfaces: not held inputs.
    return Settings(**{**settings.__dict__, "held_inputs": False})


def _result_message(c: Candidate, s) -> messages.Result:
    r = c.result
    modes = []
    for m in r["modes"]:
        re, im = m["eigenvalue"]
        modes.append(
            messages.ModeReport(
                name=m["name"],
                real=re,
                imag=im,
                frequency_hz=m["frequency_rad_s"] / (2 * np.pi),
                damping=m["damping"],
                time_constant_s=m["time_constant_s"],
                msv=m["msv"],
                mci=m["mci"],
                moi=m["moi"],
                emac=m["emac"],
                mpc=m["mpc"],
                cmi=m["cmi"],
            )
        )
    return messages.Result(
        model_id=c.model_id,
        axes=c.axes,
        dt=r["dt"],
        inputs=r["inputs"],
        outputs=r["outputs"],
        modes=modes,
        tic=[float(r["tic"][o]) for o in r["outputs"]],
        tic_avg=r["tic_avg"],
        stable=r["stable"],
        suggest_update=s.update,
        reasons=s.steps,
        checks=s.checks,
        tic_jn=s.tic_jn,
        tic_nn=s.tic_nn,
        tic_nj=s.tic_nj,
        A=r["A"],
        B=r["B"],
        C=r["C"],
        D=r["D"],
    )


async def serve(config: Config, config_text: str, base: Path) -> None:
    """`sysid agent`: run until SIGINT/SIGTERM, then abort any run and shut down cleanly."""
    agent = Agent(config, base=base, config_text=config_text)
    task = asyncio.create_task(agent.run(), name="agent")
    loop = asyncio.get_running_loop()

    def stop() -> None:
        agent.scheduler.abort("agent shutting down")
        task.cancel()

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop)
    with contextlib.suppress(asyncio.CancelledError):
        await task
