"""Onboard identification: the queue of windows to identify, the worker that identifies them,
the result log, the model store and the nominal's self-check (thesis 5.3, requirement 6.3.1).

Each window is a job for the worker process (`agent.ident.job.run`): the loop only hands it
over and waits, so it never waits on numerics. The model store's files are read and written on
one thread of their own, in order: a save (rename) can wait on the disk for a long time, and
the loop must not.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections import Counter, deque
from collections.abc import Callable
from concurrent.futures import Executor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, replace

import numpy as np

from agent.channels import AXIS_SETS, OUTPUT_ROLES
from agent.clock import Clock
from agent.config import Config
from agent.excitation.scheduler import Window
from agent.ident import Settings
from agent.ident import job as jobs
from agent.ident.aircraft.airangles import Sources
from agent.ident.document import ResultDocument
from agent.ident.errors import DataError
from agent.link import messages
from agent.logs import LogWriter, log_name
from agent.models import SELF_CHECK_RATIO, Candidate, ModelStore, Suggestion, suggest
from agent.recorder import Recorder
from agent.runtime.downlink import Downlink
from agent.runtime.worker import new_worker, processes, stop_worker

log = logging.getLogger(__name__)

# Identification jobs waiting (more are dropped and counted: the operator can re-fly).
JOB_QUEUE = 4
# The latest results kept in memory (all of them are in the result log).
RESULTS_KEPT = 100
# A candidate sizes plans (agent/runtime/sizer.py) while no model is nominal when it is
# stable and fits its own data below this TIC: looser than the suggestion's 0.3, because a
# build-up run's small response stands less above the sensors' noise (the J-3 Cub's quarter-
# amplitude full preset fitted at 0.34 in calm air, its modes within 2.2 %), and a sizing needs
# the response's size, not a nominal model. A candidate that passed the suggestion's fit step
# sizes too: in turbulence no sensor measures, the whole record's TIC is the gust's, not the
# model's (agent.models: the fit step).
SIZING_TIC = 0.5
# Each axes' latest candidates kept for the sizing: their records, flown at other amplitudes,
# tell the gusts' excursion from a response the model misses (agent.sizing.checked).
RECORDS_KEPT = 4
# With no update period set, how often the periodic task looks again (s).
PERIODIC_IDLE_S = 1.0


class Identifier:
    """Identifies each finished excitation window (and, with an update period set from the
    ground, the data of every period) in the worker; sends each result or failure down."""

    def __init__(
        self,
        *,
        config: Config,
        clock: Clock,
        recorder: Recorder,
        models: ModelStore,
        writer: LogWriter,
        downlink: Downlink,
        counters: Counter[str],
        worker: Callable[[], Executor] = new_worker,
    ):
        self.config, self.clock, self.recorder = config, clock, recorder
        self.models, self.writer, self.downlink = models, writer, downlink
        self.counters = counters
        # The ground's settings; until it sends any, each run is identified on its plan's axes.
        self.settings = messages.IdentSettings()
        self.last_axes: str = config.identification.axes  # of the last window identified
        self.busy = False  # a window is in the worker
        self.ready = False  # the first worker is up and warmed
        # The stage a busy window is in: (name, since, expected seconds or None).
        self._stage: tuple[str, float, float | None] | None = None
        # By (axes, stage): how long the last one took (s) and on how many samples.
        self._took: dict[tuple[str, str], tuple[float, int]] = {}
        self._windows = 0  # windows waiting in the queue
        self.results: deque[ResultRecord] = deque(maxlen=RESULTS_KEPT)
        # The result log: one JSON object per identification (thesis 2.2.1).
        self._log = writer.open(log_name(writer.next_number(), "results", "jsonl"))
        # Windows to identify and frequency responses asked for: one worker, in order.
        self._queue: asyncio.Queue[tuple[Window, np.ndarray] | _FrfJob] = asyncio.Queue(JOB_QUEUE)
        self._store = ThreadPoolExecutor(1, thread_name_prefix="model-store")
        self._new_worker = worker
        self._pool: Executor | None = None  # the worker; replaced if it dies
        self._batch: dict[str, list] = {}  # by axes: the experiments of a batch so far
        # By axes: whether a run of the batch so far was flown on the sticks (closed loop).
        self._batch_closed: dict[str, bool] = {}
        self._self_check: dict[str, str] = {}  # by axes: a new nominal to check next run
        # By axes: the newest candidate that is stable and fits its own data to SIZING_TIC,
        # or passed the fit step (sizes plans while no model is nominal yet).
        self.newest: dict[str, Candidate] = {}
        # By axes: the latest candidate, good or not (what its run flew grows the build-up).
        self.latest: dict[str, Candidate] = {}
        # By axes: the latest candidate with every mode its axes must have (step 2b passed):
        # what step 3's repeat test compares the next one with.
        self.complete: dict[str, Candidate] = {}
        # By axes: the RECORDS_KEPT latest candidates, good or not, newest last.
        self.recent: dict[str, deque[Candidate]] = {}

    # -- windows in ----------------------------------------------------------------------

    def submit(self, window: Window, rows: np.ndarray) -> bool:
        """Queue a window for identification; False (counted, the ground told) when full."""
        try:
            self._queue.put_nowait((window, rows))
        except asyncio.QueueFull:
            self.counters["jobs_dropped"] += 1
            return False
        self._windows += 1
        return True

    def stage(self, now: float) -> tuple[str, float, float | None] | None:
        """What the identification is doing, for the live view: (stage, seconds in it, how
        long it should take or None) — "identifying" (the window in the worker), "comparing
        with nominal" (each model's TIC on the other's data, in the worker), or ("queued", 0,
        None) when a window waits; None when idle."""
        if self.busy and self._stage is not None:
            name, since, expected = self._stage
            return name, now - since, expected
        return ("queued", 0.0, None) if self._windows else None

    def expected(self, name: str, axes: str, samples: int) -> float | None:
        """How long stage `name` should take on a window of `samples` rows of these axes: the
        last such stage's time scaled by the samples (the numerics' cost grows about linearly
        with the record); None before the first."""
        last = self._took.get((axes, name))
        return None if last is None else last[0] * samples / max(last[1], 1)

    def _enter(self, name: str, axes: str, samples: int) -> None:
        self._stage = (name, self.clock.now(), self.expected(name, axes, samples))

    def _leave(self, axes: str, samples: int) -> None:
        """The stage entered last is over: remember how long it took."""
        if self._stage is not None:
            name, since, _ = self._stage
            self._took[(axes, name)] = (self.clock.now() - since, samples)

    def periodic_window(self, period: float) -> tuple[Window, np.ndarray] | None:
        """Queue the last `period` seconds of frames recorded for identification: the window and
        its rows, or None when there are none or the queue is full."""
        end = self.recorder.newest
        if end is None:
            return None
        rows = self.recorder.ring.between(end - period, end)
        if len(rows) < 2:
            return None
        axes = self.settings.axes or self.config.identification.axes
        window = Window(f"periodic@{end:.0f}", axes, end - period, end, "finished")
        return (window, rows) if self.submit(window, rows) else None

    async def periodic(self) -> None:
        """Thesis B.2 4.1: identify every update period set from the ground, on the data
        recorded over that period (nothing when no period is set)."""
        while True:
            period = self.settings.update_period_s
            await asyncio.sleep(period or PERIODIC_IDLE_S)
            if period:
                self.periodic_window(period)

    # -- the ground's settings and decisions -----------------------------------------------

    def apply(self, settings: messages.IdentSettings) -> str:
        """Use settings from the ground; why not ("" when used): an explicit p or order beyond
        the configured markov_max / order_max (the automatic search keeps within them; an
        explicit value skipped the bounds)."""
        cfg, reasons = self.config.identification, []
        if isinstance(settings.markov, int) and not 1 <= settings.markov <= cfg.markov_max:
            reasons.append(f"p {settings.markov} is outside 1…{cfg.markov_max} (markov_max)")
        if isinstance(settings.order, int) and not 1 <= settings.order <= cfg.order_max:
            reasons.append(f"order {settings.order} is outside 1…{cfg.order_max} (order_max)")
        if not reasons:
            self.settings = settings
        return "; ".join(reasons)

    def axes_for(self, window: Window) -> str:
        """The axes a window is identified on: the operator's, when the ground's settings
        chose some, else the window's own (its plan's, which its controls belong to)."""
        return self.settings.axes or window.axes

    def in_effect(self) -> messages.IdentSettings:
        """The settings as used now, for the ground to show: the ground's, with p and order
        the configuration's where the ground left them "auto" (axes None: each plan's own)."""
        cfg, s = self.config.identification, self.settings
        return s.model_copy(
            update={
                "markov": cfg.markov if s.markov == "auto" else s.markov,
                "order": cfg.order if s.order == "auto" else s.order,
            }
        )

    async def decide(self, decision: messages.Decision) -> None:
        """The operator accepts a model as nominal or rejects it (KeyError: no such model)."""
        accepted = await self._in_store(self._decide, decision)
        if accepted is not None:  # a new nominal replacing one: self-check it next run
            self._self_check[accepted[0]] = accepted[1]

    def _decide(self, decision: messages.Decision) -> tuple[str, str] | None:
        """On the model-store thread; (axes, model id) when the accepted model replaced a
        nominal, for the self-check."""
        if not decision.accept:
            self.models.reject(decision.model_id)
            return None
        accepted = self.models.accept(decision.model_id)
        if self.models.previous(accepted.axes) is None:
            return None
        return accepted.axes, accepted.model_id

    async def revert(self) -> None:
        """The previous nominal of the current axes (the operator's, else the last window's)
        is nominal again (LookupError: none)."""
        await self._in_store(self.models.revert, self.settings.axes or self.last_axes)

    async def sizing_model(self, axes: str) -> tuple[Candidate, str] | None:
        """The model a plan of `axes` is sized by, and how to name it: the nominal of those
        axes, else the full model's, else the newest candidate of this flight that is stable
        and has every mode it must have, and fits its own data below SIZING_TIC or passed the
        suggestion's fit step (`newest`), those axes' first. None: no model yet."""
        for wanted in dict.fromkeys((axes, "full")):
            nominal = await self._in_store(self.models.nominal, wanted)
            if nominal is not None:
                return nominal, f"nominal model {nominal.model_id}"
        for wanted in dict.fromkeys((axes, "full")):
            if wanted in self.newest:
                c = self.newest[wanted]
                return c, f"model {c.model_id} (identified this flight, not yet accepted)"
        return None

    async def tuning_model(self, model_id: str | None) -> Candidate:
        """The model gains are designed from (agent/runtime/gains.py): `model_id`'s, else the
        full nominal, else the lateral or longitudinal one. LookupError: none."""
        if model_id is not None:
            return await self._in_store(self.models.find, model_id)
        for axes in ("full", "lateral", "longitudinal"):
            nominal = await self._in_store(self.models.nominal, axes)
            if nominal is not None:
                return nominal
        raise LookupError("no nominal model to design gains from: accept one first")

    async def _in_store(self, function, *args):
        return await asyncio.get_running_loop().run_in_executor(self._store, function, *args)

    # -- the worker ------------------------------------------------------------------------

    def start_worker(self) -> None:
        """Start the worker (with the agent, so it is warm before the first window)."""
        if self._pool is None:
            self._pool = self._new_worker()

    @property
    def worker_pid(self) -> int | None:
        """The worker process's id (None: not started, or a thread pool)."""
        running = processes(self._pool) if self._pool is not None else []
        return running[0].pid if running else None

    async def run(self) -> None:
        """Identify each queued window in turn. A worker that dies is replaced and the window
        reported as failed; a fault in one identification is a failure result; both go on."""
        self.start_worker()
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(self._pool, jobs.warm)  # up before the first window
        self.ready = True
        while True:
            item = await self._queue.get()
            if isinstance(item, _FrfJob):
                await self._frequency_response(item)
                continue
            window, rows = item
            self._windows -= 1
            self.busy = True
            try:
                await self.identify(window, rows)
            except BrokenProcessPool as exc:  # the worker died (killed, out of memory): anew
                self.counters["worker_restarts"] += 1
                log.error("the identification worker died (%s); starting a new one", exc)
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = self._new_worker()
                self._failed(
                    window.plan_id,
                    self.axes_for(window),
                    "the identification worker process died; a new one is started "
                    "for the next window",
                )
            except Exception as exc:  # a fault in one identification: a failure result, go on
                log.exception("identification of %s failed", window.plan_id)
                self._failed(window.plan_id, self.axes_for(window), f"internal error: {exc!r}")
            finally:
                self.busy, self._stage = False, None

    async def stop(self) -> None:
        """Stop the worker (`stop_worker`) and the model-store thread."""
        try:
            if self._pool is not None:
                await stop_worker(self._pool)
        finally:
            self._store.shutdown(wait=True)

    def close(self) -> None:
        """Release without a loop (an agent that never ran): the worker, if one was started,
        is told to stop; the model-store thread ends."""
        if self._pool is not None:
            # A worker process may be busy: told to stop, not waited for (it is killed with
            # the agent). A thread worker cannot be killed and has nothing left to run once the
            # agent's jobs were awaited: waited for, so no thread outlives the agent.
            self._pool.shutdown(
                wait=isinstance(self._pool, ThreadPoolExecutor), cancel_futures=True
            )
        self._store.shutdown(wait=True)

    # -- a frequency response asked for --------------------------------------------------

    async def request_frf(self, request: messages.FrfRequest) -> str:
        """Queue a model's measured frequency response for one pair; why not ("" when queued:
        the FrfReport follows once the worker is free)."""
        candidate = await self._in_store(self.models.find, request.model_id)
        inputs, outputs = candidate.result.inputs, candidate.result.outputs
        if request.input not in inputs or request.output not in outputs:
            return (
                f"{request.model_id} has no pair {request.input} → {request.output} "
                f"(inputs {', '.join(inputs)}; outputs {', '.join(outputs)})"
            )
        i, j = inputs.index(request.input), outputs.index(request.output)
        job = _FrfJob(request=request, candidate=candidate, input_index=i, output_index=j)
        try:
            self._queue.put_nowait(job)
        except asyncio.QueueFull:
            return "busy: the identification queue is full; ask again after the next result"
        return ""

    async def _frequency_response(self, job: _FrfJob) -> None:
        c, r = job.candidate, job.request
        loop = asyncio.get_running_loop()
        try:
            answer = await loop.run_in_executor(
                self._pool,
                jobs.frequency_response,
                c.result.preprocessing,
                c.record_dt,
                c.experiments,
                job.input_index,
                job.output_index,
                messages.FRF_POINTS,
            )
        except BrokenProcessPool:
            raise  # the worker died: `run` replaces it
        except (ValueError, np.linalg.LinAlgError, DataError) as exc:
            self.counters["frf_failures"] += 1
            text = f"frequency response {r.model_id} {r.input} → {r.output} not computed: {exc}"
            self.downlink.send(messages.Notice(text=text[:200]))
            return
        self.downlink.send(
            messages.FrfReport(model_id=r.model_id, input=r.input, output=r.output, **answer)
        )

    # -- one identification ------------------------------------------------------------------

    async def identify(self, window: Window, rows: np.ndarray) -> None:
        """Identify one window in the worker, compare it with the nominal, store it, log it and
        send the result (or the failure, with its reason) down."""
        self.start_worker()
        loop = asyncio.get_running_loop()
        axes, ident = self.axes_for(window), self.settings
        self.last_axes = axes
        channels = self.config.identification.channels
        controls = self.config.excitation.surfaces  # the aircraft's: a glider has no throttle
        inputs, outputs = channels.axis_set(axes, controls)
        # Never given twice on this aircraft (the model store's numbering): an id never names
        # two models.
        model_id = await self._in_store(self.models.reserve_id, axes)
        navigation = channels.navigation()
        air = Sources.of(channels, self.config.identification.air_angles)
        # The aircraft's states a run's outputs leave out (a lateral run's airspeed and θ):
        # their kinematics.
        flight = tuple(
            (role, name)
            for role in OUTPUT_ROLES
            if (name := getattr(channels, role)) not in outputs
        )
        needed = {*inputs, *outputs, *navigation, *air.needed, *(n for _, n in flight)}
        columns = {c: v for c, v in self.recorder.frames(rows).values.items() if c in needed}
        dt = 1.0 / self.config.recorder.rate_hz
        batch = self._batch.setdefault(axes, []) if ident.batch else []
        closed = window.closed_loop or bool(batch and self._batch_closed.get(axes))
        job = jobs.Job(
            model_id=model_id,
            axes=axes,
            record_dt=dt,
            inputs=inputs,
            outputs=outputs,
            roles=AXIS_SETS[axes][1],
            input_roles=tuple(r for r in AXIS_SETS[axes][0] if r in controls),
            experiments=tuple(batch),
            # A run flown on the sticks (FBWA) is a closed-loop record: the lateral axis is
            # refined by prediction error (agent.ident.aircraft.predictor).
            settings=replace(
                onboard_settings(self.config, ident),
                closed_loop=closed,
            ),
            window=columns,
            trim_s=self.config.identification.trim_seconds,
            navigation=navigation,
            air_angles=air,
            flight=flight,
        )
        self._enter("identifying", axes, len(rows))
        outcome = await loop.run_in_executor(self._pool, jobs.run, job)
        self._leave(axes, len(rows))
        if not outcome.ok:
            return self._failed(model_id, axes, outcome.reason)
        if ident.batch:
            batch.append(outcome.experiment)
            self._batch_closed[axes] = closed
        candidate = Candidate(
            model_id=model_id,
            axes=axes,
            record_dt=dt,
            result=outcome.result,
            experiments=jobs.of_result(
                outcome.result, job.inputs, job.outputs, (*job.experiments, outcome.experiment)
            ),
            record_s=len(outcome.experiment[0]) * dt,
            trim=outcome.trim,
            fitted=outcome.fitted,
        )
        # Step 3's repeat test takes the axes' last model that has every mode they must have,
        # where its record is not also this one's (a batch holds the earlier records: not
        # independent). A run whose model lacks a mode (the gusts took its short period)
        # has nothing to repeat, and the run after it is judged against the last complete
        # one, as a test engineer compares a repeat with the last good run.
        earlier = None if ident.batch else self.complete.get(axes)
        suggestion = await self._compare(candidate, len(rows), earlier)
        await self._in_store(self.models.add, candidate)
        self.latest[axes] = candidate
        self.recent.setdefault(axes, deque(maxlen=RECORDS_KEPT)).append(candidate)
        # A model that misses a mode the aircraft has (step 2b) predicts that axis's response
        # from what stands in for it: it sizes nothing, and the last one that had them all
        # still does.
        checks = suggestion.checks
        if checks.get("modes"):
            self.complete[axes] = candidate
        if (
            checks.get("stability")
            and checks.get("modes", True)
            and (candidate.tic_jj < SIZING_TIC or checks.get("fit"))
        ):
            self.newest[axes] = candidate
        record = ResultRecord(
            model_id=model_id,
            axes=axes,
            window=(window.start, window.end),
            trim=outcome.trim,
            suggestion=suggestion,
            result=outcome.result,
        )
        self.results.append(record)
        self.counters["identifications"] += 1
        self.writer.write(self._log, record.line())
        self.downlink.send(result_message(candidate, suggestion))

    async def _compare(
        self, candidate: Candidate, samples: int, earlier: Candidate | None
    ) -> Suggestion:
        """The figure 5.2 suggestion: against the nominal (if any), each model's TIC on the
        other's data (TIC_jN, TIC_Nj), computed in the worker; `earlier`: the axes' model
        before this one (models.suggest)."""
        axes = candidate.axes
        nominal = await self._in_store(self.models.nominal, axes)
        if nominal is None:
            return suggest(candidate, None, None, None, earlier=earlier)
        uncompared = jobs.uncompared(candidate.result, nominal.result)
        if uncompared:
            return suggest(candidate, nominal, None, None, uncompared, earlier=earlier)
        self._enter("comparing with nominal", axes, samples)
        tic_jn = await self._cross_tic(candidate, nominal)
        tic_nj = await self._cross_tic(nominal, candidate)
        await self._check_new_nominal(axes, nominal, tic_nj, candidate)
        self._leave(axes, samples)
        return suggest(candidate, nominal, tic_jn, tic_nj, earlier=earlier)

    async def _cross_tic(self, model: Candidate, data: Candidate) -> float:
        """TIC_avg of `model` on `data`'s experiments."""
        return await asyncio.get_running_loop().run_in_executor(
            self._pool,
            jobs.cross_tic,
            model.result,
            data.record_dt,
            data.experiments,
        )

    async def _check_new_nominal(self, axes, nominal, tic_nj, candidate) -> None:
        """Requirement 6.3.1: a just-accepted nominal predicting this new excitation much worse
        than the model it replaced is rolled back, and the ground is told."""
        if self._self_check.pop(axes, None) != nominal.model_id:
            return
        previous = await self._in_store(self.models.previous, axes)
        tic_previous = await self._cross_tic(previous, candidate)
        if tic_nj > SELF_CHECK_RATIO * tic_previous:
            await self._in_store(self.models.revert, axes)
            text = (
                f"self-check: nominal {nominal.model_id} predicts the new data with TIC "
                f"{tic_nj:.2f} against {tic_previous:.2f} for {previous.model_id}: reverted"
            )
            self.downlink.send(messages.Notice(text=text))

    def _failed(self, model_id: str, axes: str, reason: str) -> None:
        self.counters["identification_failures"] += 1
        log.warning("identification %s failed: %s", model_id, reason)
        record = ResultRecord(model_id=model_id, axes=axes, failure=reason)
        self.results.append(record)
        self.writer.write(self._log, record.line())
        self.downlink.send(messages.Failure(model_id=model_id, axes=axes, reason=reason[:300]))


@dataclass(frozen=True, kw_only=True)
class _FrfJob:
    request: messages.FrfRequest
    candidate: Candidate
    input_index: int
    output_index: int


def onboard_settings(config: Config, ident: messages.IdentSettings) -> Settings:
    """The identification settings onboard: the config's, with the ground's p and order. The
    inputs are the surface pots' samples of moving surfaces (`held_inputs = "auto"`: not
    held)."""
    return Settings.from_config(
        config.identification,
        sampled_inputs=True,
        markov=None if ident.markov == "auto" else ident.markov,
        order=None if ident.order == "auto" else ident.order,
    )


def result_message(c: Candidate, s: Suggestion) -> messages.Result:
    """A result as the link carries it."""
    r = c.result
    return messages.Result(
        model_id=c.model_id,
        axes=c.axes,
        dt=r.dt,
        inputs=r.inputs,
        outputs=r.outputs,
        modes=r.modes,
        tic=[r.tic[o] for o in r.outputs],
        tic_avg=r.tic_avg,
        stable=r.stable,
        suggest_update=s.update,
        reasons=s.steps,
        checks=s.checks,
        tic_jn=s.tic_jn,
        tic_nn=s.tic_nn,
        tic_nj=s.tic_nj,
        A=r.A,
        B=r.B,
        C=r.C,
        D=r.D,
    )


@dataclass(frozen=True, kw_only=True)
class ResultRecord:
    """One line of the result log (thesis 2.2.1): an identification, or a failure and why."""

    model_id: str
    axes: str
    window: tuple[float, float] | None = None  # the excitation window's start and end (s)
    trim: dict[str, dict[str, float]] | None = None  # "inputs"/"outputs" by channel
    suggestion: Suggestion | None = None
    result: ResultDocument | None = None
    failure: str | None = None

    def line(self) -> bytes:
        """The record as one line of JSON (the failure's without the identification's keys)."""
        if self.failure is not None:
            document = {"model_id": self.model_id, "axes": self.axes, "failure": self.failure}
        else:
            document = {
                "model_id": self.model_id,
                "axes": self.axes,
                "window": list(self.window or ()),
                "trim": self.trim,
                "suggestion": None if self.suggestion is None else asdict(self.suggestion),
                "result": None if self.result is None else self.result.model_dump(mode="json"),
            }
        return (json.dumps(document) + "\n").encode()
