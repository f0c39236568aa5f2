"""The agent's wiring: it builds the parts, connects their callbacks, and runs each under
`supervised` in one TaskGroup."""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import os
import signal
import sys
from collections import Counter
from collections.abc import Awaitable, Callable
from concurrent.futures import Executor
from pathlib import Path

import numpy as np

from agent.channels import SENSOR_CHANNELS
from agent.clock import Clock, LoopClock
from agent.config import Config, to_toml
from agent.excitation.follow import following
from agent.excitation.scheduler import Event, Scheduler, Window
from agent.link import messages
from agent.link.codec import AIRCRAFT
from agent.link.endpoint import build_endpoint
from agent.logs import Logbook, LogWriter, config_hash, units_of
from agent.models import ModelStore
from agent.recorder import Recorder
from agent.runtime.commands import Commands
from agent.runtime.downlink import Downlink
from agent.runtime.gains import GainTuner
from agent.runtime.health import Health
from agent.runtime.identification import Identifier
from agent.runtime.live import Live
from agent.runtime.sizer import Sizer
from agent.runtime.status import Status
from agent.runtime.worker import new_worker
from drivers.airdata.driver import make_driver as airdata
from drivers.autopilot.driver import AutopilotLink
from drivers.surfaces.driver import make_driver as surfaces
from drivers.vectornav.driver import make_driver as vn200

log = logging.getLogger(__name__)

# Restart backoff of a failed component: first wait, doubling to at most this.
RESTART_S, RESTART_MAX_S = 0.5, 10.0
SWITCH_INTERVAL_S = 0.00025
SENSORS = {"vn200": vn200, "airdata": airdata, "surfaces": surfaces}


class Agent:
    """The onboard agent; `run()` serves until cancelled. An agent that never runs is
    released with `close()`."""

    def __init__(
        self,
        config: Config,
        *,
        base: Path = Path("."),
        clock: Clock | None = None,
        config_text: str | None = None,
        worker: Callable[[], Executor] = new_worker,
    ):
        self.config, self.base = config, Path(base)
        self.clock = clock or LoopClock()
        self.counters: Counter[str] = Counter()  # the agent's own, in every health record
        self.downlink = Downlink()
        self.radio = None
        self.writer = LogWriter(self.base / config.recorder.log_dir)
        self.recorder = Recorder(config.recorder, self.clock, on_excitation=self._on_window)
        self.logbook = Logbook(
            self.writer,
            self.recorder.columns,
            units_of(self.recorder.columns, SENSOR_CHANNELS),
            # No file text (an agent built in-process, as `sysid sim` does): the hash of the
            # settings themselves, which is what `sysid agent` reads from the file it writes.
            config_hash(to_toml(config) if config_text is None else config_text),
            config.recorder.rate_hz,
        )
        self.recorder.sink = self.logbook.row
        excitation = config.excitation
        self.autopilot = AutopilotLink(
            config.autopilot,
            self.clock,
            switch_channel=excitation.switch_channel,
            on_switch=lambda pwm, t: self.scheduler.update_switch(pwm, t),
            on_state=lambda s: self.scheduler.update_state(s),
            on_servos=lambda t, p: self.scheduler.update_servos(t, p),
            on_sticks=lambda t, p: self.scheduler.update_sticks(t, p),
            on_sample=self.recorder.push,
            on_link=self._on_autopilot_link,
        )
        self.scheduler = Scheduler(excitation, self.autopilot, self.clock)
        self.scheduler.subscribe(self._on_scheduler)
        self.models = ModelStore(self.base / "models")
        self.identification = Identifier(
            config=config,
            clock=self.clock,
            recorder=self.recorder,
            models=self.models,
            writer=self.writer,
            downlink=self.downlink,
            counters=self.counters,
            worker=worker,
        )
        self.sizer = Sizer(
            config=config, identification=self.identification, flight=lambda: self.scheduler.state
        )
        self.gains = GainTuner(
            config=config,
            identification=self.identification,
            autopilot=self.autopilot,
            status=lambda: self.scheduler.status,
            downlink=self.downlink,
            logbook=self.logbook,
            counters=self.counters,
        )
        self.commands = Commands(
            scheduler=self.scheduler,
            identification=self.identification,
            sizer=self.sizer,
            gains=self.gains,
            downlink=self.downlink,
            counters=self.counters,
        )
        self.health = Health(
            clock=self.clock,
            counters=self.counters,
            busy=lambda: self.identification.busy,
            sections=self._health_sections,
        )
        self.live = Live(
            config=config,
            clock=self.clock,
            scheduler=self.scheduler,
            recorder=self.recorder,
            identification=self.identification,
            downlink=self.downlink,
            counters=self.counters,
        )
        self._log_handler = None  # the execution log's handler while running
        sensors = config.sensors
        self.drivers = [
            make(sensors, self.clock, self.recorder.push)
            for name, make in SENSORS.items()
            if getattr(sensors, name).enabled
        ]
        self.status = Status(
            clock=self.clock,
            autopilot=self.autopilot,
            scheduler=self.scheduler,
            drivers=self.drivers,
            recorder=self.recorder,
            writer=self.writer,
            models=self.models,
            identification=self.identification,
            health=self.health,
            downlink=self.downlink,
        )

    @property
    def session(self):
        """The link session (None: no link)."""
        return self.downlink.session

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
        # in benchmarks/README.md, *The agent's resource use* (benchmarks/bench_agent.py).
        switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        handler = self._log_handler = self.logbook.handler(self.clock)
        logging.getLogger().addHandler(handler)
        self.identification.start_worker()
        restore = realtime(self.config.runtime.realtime_priority, self.counters)
        try:
            self._build_link()
            # Everything built so far lives as long as the agent: moved out of the collector's
            # way, so a full collection (which walked it and stalled the loop for up to 0.8 s
            # in the simulator) only looks at what the flight allocates.
            gc.collect()
            gc.freeze()
            async with asyncio.TaskGroup() as group:
                for driver in self.drivers:
                    group.create_task(
                        supervised(driver.name, driver.run, self.counters), name=driver.name
                    )
                named = {
                    "lag": self.health.probe,
                    "health": self.health.write_records,
                    "autopilot": self.autopilot.run,
                    "recorder": self.recorder.run,
                    "scheduler": self.scheduler.run,
                    "status": self.status.run,
                    "live": self.live.run,
                    "periodic": self.identification.periodic,
                    "identification": self.identification.run,
                    "commands": self.commands.run,
                    "gains": self.gains.run,
                }
                if self.session is not None:
                    named["link"] = self.session.run
                    named["radio"] = self.radio.watch
                for name, factory in named.items():
                    group.create_task(supervised(name, factory, self.counters), name=name)
                log.info(
                    "agent started: %s", ", ".join([d.name for d in self.drivers] + list(named))
                )
        finally:
            if restore is not None:
                os.sched_setscheduler(0, *restore)
            sys.setswitchinterval(switch)
            logging.getLogger().removeHandler(handler)
            try:
                await self.identification.stop()
                if self.radio is not None:
                    await self.radio.close()
            finally:  # cancelled again while stopping: the logs are still flushed and closed
                self.writer.close()

    def close(self) -> None:
        """Release what the constructor opened, for an agent that never ran (`run` releases
        its own)."""
        self.identification.close()
        self.writer.close()

    def _build_link(self) -> None:
        if self.config.link.peer is None:
            log.info("link: no [link] peer configured, radio not started")
            return
        # Built, not opened: the radio's watch task opens it beside the drivers, so a module
        # that does not answer at power-up leaves the aircraft recording without a link.
        try:
            self.radio, self.downlink.session = build_endpoint(
                self.config.link,
                AIRCRAFT,
                self.base,
                self.clock,
                self.commands.receive,
                guard=self.commands,
            )
        except (ValueError, OSError) as exc:  # the link refused, not the agent: it records
            self.counters["link_refused"] += 1
            log.error("link refused, flying without it: %s", exc)

    def _health_sections(self) -> dict:
        """The other parts' counters in each health record."""
        return {
            "recorder": dict(self.recorder.counters),
            # The radio's failed opens, losses and reopens, and the link's drops: a flight whose
            # radio never answered shows it here, not only in warning lines.
            "radio": dict(self.radio.counters) if self.radio is not None else None,
            "link": dict(self.session.counters) if self.session is not None else None,
            "downlink": dict(self.downlink.counters),
            "logs": {
                "errors": self.writer.errors,
                "dropped": self.writer.dropped,
                "lost_lines": self.writer.lost_lines,
                "unformattable": getattr(self._log_handler, "unformattable", 0),
                "failures": self.writer.failures[-3:],
            },
        }

    # -- callbacks between the parts ----------------------------------------------------------

    def _on_scheduler(self, item: Event | Window) -> None:
        self.recorder.mark(item)
        if isinstance(item, Event) and item.kind != "progress":
            self.downlink.send(
                messages.ExcitationEvent(
                    event=item.kind, plan_id=item.plan_id, time=item.time, detail=item.detail
                )
            )

    def _on_autopilot_link(self, up: bool, reason: str) -> None:
        if not up:
            self.scheduler.abort(f"autopilot link lost: {reason}")

    def _on_window(self, window: Window, rows: np.ndarray) -> None:
        """The recorder has the window and its margin: log it, queue its identification, then
        check that its surfaces followed their commands (last: the record and the job first)."""
        self.logbook.excitation(window, rows, batch=self.identification.settings.batch)
        if window.outcome != "finished":
            text = f"{window.plan_id} aborted ({window.reason}): not identified"
            self.downlink.send(messages.Notice(text=text))
        elif not self.identification.submit(window, rows):
            self.downlink.send(messages.Notice(text="identification queue full: window dropped"))
        self._check_following(window, rows)

    def _check_following(self, window: Window, rows: np.ndarray) -> None:
        """A surface that moved against its command, or not at all, is told to the ground:
        the direction or a calibration is set up the wrong way (agent.excitation.follow)."""
        played = self.scheduler.played
        if window.outcome != "finished":  # an aborted run's commands may never have arrived
            return
        if played is None or played.plan.id != window.plan_id or len(rows) == 0:
            return
        if played.on_sticks:
            # Closed loop: the surfaces moved as the autopilot's laws asked, not as the plan's
            # stick commands; their linkage (sizing's, the gains design's) is not measured.
            return
        frames = self.recorder.frames(rows)
        followed = following(played.timeline, played.start, frames.time, frames.values)
        # Logged for `sysid tune` (the linkage and the servo's lag the gains are designed with).
        self.logbook.linkage(window.plan_id, [f for f in followed if f.verdict == "follows"])
        for f in followed:
            if f.verdict == "follows":
                # Its linkage sizes the next plans (agent/runtime/sizer.py) and, with its lag,
                # the gains designed onboard (agent/runtime/gains.py).
                self.sizer.linkage[f.control] = (f.gain, f.even, f.knee)
                self.gains.linkage[f.control] = {
                    "gain": f.gain,
                    "lag_s": f.lag_s,
                    "even": f.even,
                    "knee": f.knee,
                }
                continue
            self.counters[f"surface_{f.verdict.replace(' ', '_')}"] += 1
            log.warning("%s: %s", window.plan_id, f.text())
            self.downlink.send(messages.Notice(text=f"{window.plan_id}: {f.text()}"))


async def supervised(
    name: str, factory: Callable[[], Awaitable[None]], counters: Counter[str]
) -> None:
    """Run a component; one that fails is logged, counted and restarted after a backoff, so
    it never takes the others down."""
    delay = RESTART_S
    while True:
        try:
            await factory()
            return
        except asyncio.CancelledError:
            raise
        except Exception:  # one component's fault must not stop the others: log, restart
            counters[f"{name}_restarts"] += 1
            log.exception("%s failed; restarting in %.1f s", name, delay)
            await asyncio.sleep(delay)
            delay = min(delay * 2, RESTART_MAX_S)


def realtime(priority: int | None, counters: Counter[str]) -> tuple[int, os.sched_param] | None:
    """The loop's thread to SCHED_FIFO `priority` ([runtime] realtime_priority), with
    SCHED_RESET_ON_FORK so threads and processes started from it run normally; the policy to
    restore, or None. Not permitted: a warning, counted, and normal scheduling."""
    if priority is None:
        return None
    previous = (os.sched_getscheduler(0), os.sched_getparam(0))
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        counters["realtime_refused"] += 1
        log.warning("realtime_priority %d not set (%s): normal scheduling", priority, exc)
        return None
    log.info("event loop thread at SCHED_FIFO %d", priority)
    return previous


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
