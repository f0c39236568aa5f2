"""The vehicle status sent to the ground every STATUS_S (best effort, the newest replacing
any not yet on air), and the ground told once when the logs stop — and start again — being
written."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Sequence

from agent.channels import AXIS_SETS
from agent.clock import Clock
from agent.excitation.scheduler import Scheduler
from agent.link import messages
from agent.logs import LogWriter
from agent.models import ModelStore
from agent.recorder import Recorder
from agent.runtime.downlink import Downlink
from agent.runtime.health import Health
from agent.runtime.identification import Identifier
from drivers.autopilot.driver import AutopilotLink

log = logging.getLogger(__name__)

STATUS_S = 1.0


class Status:
    def __init__(
        self,
        *,
        clock: Clock,
        autopilot: AutopilotLink,
        scheduler: Scheduler,
        drivers: Sequence,
        recorder: Recorder,
        writer: LogWriter,
        models: ModelStore,
        identification: Identifier,
        health: Health,
        downlink: Downlink,
    ):
        self.clock, self.autopilot, self.scheduler = clock, autopilot, scheduler
        self.drivers, self.recorder, self.writer = drivers, recorder, writer
        self.models, self.identification, self.health = models, identification, health
        self.downlink = downlink
        self._logs_failing = False

    async def run(self) -> None:
        while True:
            await asyncio.sleep(STATUS_S)
            self.watch_logs()
            self.downlink.send(self.message(), reliable=False)

    def watch_logs(self) -> None:
        """Tell the ground once when the logs stop being written (disk full or failing) and
        once when they are written again; recording to memory and identification go on."""
        failing = self.writer.failing
        if failing is not None and not self._logs_failing:
            text = (
                f"logs not written: {failing}; {self.writer.lost_lines} lines lost so far; "
                "recording in memory and identification go on"
            )
            log.error(text)
            self.downlink.send(messages.Notice(text=text[:200]))
        elif failing is None and self._logs_failing:
            text = f"logs written again after {self.writer.lost_lines} lines lost"
            log.warning(text)
            self.downlink.send(messages.Notice(text=text))
        self._logs_failing = failing is not None

    def message(self) -> messages.Status:
        """The status now; its loop lag is the worst since the last one."""
        t = self.autopilot.telemetry
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
        return messages.Status(
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
            identifying=self.identification.busy,
            loop_lag_ms=round(self.health.take_worst() * 1000, 2),
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
            link_fault=self._link_fault(),
            settings=self.identification.in_effect(),
        )

    def _link_fault(self) -> str | None:
        session = self.downlink.session
        fault = None if session is None else session.persist_error
        return None if fault is None else fault[:200]
