"""The live view: while a plan plays and its window is recorded and identified, a `Live`
message every `[live] period_s` — the plan's progress, the identification's stage, and
strip-chart samples at `[live] rate_hz` of what the plan commands, the surfaces as measured and
the responses its axis identifies. It is best effort and goes last (`Downlink.send_live`):
the radio carries commands' answers and results first. And it is withheld while the radio is
busier than `[live] max_air_share`: the ground's commands share the same air (an abort from the
ground waits for whatever the aircraft is sending), so on a slow link the live view gives way.

The samples come from the recorder's frames (so they lag real time by the recorder's delay)
and the commanded deflections from the plan's own timeline at the same times. Each is a whole
number of tenths of its display unit (`messages.Live`).
"""

from __future__ import annotations

import asyncio
import math
from collections import Counter

import numpy as np

from agent.channels import SENSOR_CHANNELS
from agent.clock import Clock
from agent.config import Config
from agent.excitation.scheduler import Scheduler
from agent.link import messages
from agent.recorder import Recorder
from agent.runtime.downlink import Downlink
from agent.runtime.identification import Identifier

# A surface's trim for the live view: its mean over this long before the plan started.
TRIM_S = 0.5
# Withheld above `[live] max_air_share`, the live view resumes below this fraction of it.
RESUME_FRACTION = 0.8
# A channel's display unit: its recorded unit, angles in degrees.
TO_DISPLAY = {"rad": math.degrees(1.0), "rad/s": math.degrees(1.0)}


class Live:
    # Its constructor takes the parts it reads, as Commands' and Status' do: alike in shape,
    # each the wiring of its own part (agent.py builds them).
    def __init__(
        self,
        *,
        config: Config,
        clock: Clock,
        scheduler: Scheduler,
        recorder: Recorder,
        identification: Identifier,
        downlink: Downlink,
        counters: Counter[str],
    ):
        self.config, self.clock = config, clock
        self.scheduler, self.recorder = scheduler, recorder
        self.identification, self.downlink, self.counters = identification, downlink, counters
        self._axes = config.identification.axes  # of the last plan played
        self._withheld = False  # the live view is held back: the radio is busy
        self._trim: tuple[str, dict[str, float]] = ("", {})  # (plan id, surface → trim)

    async def run(self) -> None:
        period = self.config.live.period_s
        if period <= 0:
            return  # no live view configured
        while True:
            await asyncio.sleep(period)
            message = self.message(self.clock.now())
            if message is not None and self._air_allows():
                self.downlink.send_live(message)

    def _trim_of(self, playing) -> dict[str, float]:
        """The surfaces the plan commands, as measured over TRIM_S before it started: a surface
        is shown from its trim, as its command is (cached per plan)."""
        if playing is None:
            return self._trim[1] if self._trim[0] else {}
        if self._trim[0] != playing.plan.id:
            frames = self.recorder.window(playing.start - TRIM_S, playing.start)
            trim = {}
            for control in playing.plan.controls():
                values = frames.values.get(control)
                value = None if values is None else _trim_value(values)
                if value is not None:
                    trim[control] = value
            self._trim = (playing.plan.id, trim)
        return self._trim[1]

    def _air_allows(self) -> bool:
        """Whether the radio has air to spare for the live view; the ground is told when it
        stops (and starts again)."""
        share, limit = self.downlink.air_share(), self.config.live.max_air_share
        # Resumed only well below the limit, so a share near it does not flap (each change is
        # a notice to the ground).
        withheld = share > (RESUME_FRACTION * limit if self._withheld else limit)
        if withheld != self._withheld:
            self._withheld = withheld
            text = (
                f"live view withheld: the radio was {100 * share:.0f} % busy "
                f"(limit {100 * limit:.0f} %); commands and results go first"
                if withheld
                else "live view resumed"
            )
            self.downlink.send(messages.Notice(text=text))
        if withheld:
            self.counters["live_withheld"] += 1
        return not withheld

    def message(self, now: float) -> messages.Live | None:
        """The live view now, or None when there is nothing live to show."""
        playing = self.scheduler.playing
        if playing is not None:
            self._axes = playing.plan.axes
        waiting = self.recorder.waiting
        stage = self.identification.stage(now)
        if stage is None and waiting is not None:
            stage = (
                "recording margin",
                now - waiting.end,
                self.config.recorder.excitation_margin_s,
            )
        if playing is None and stage is None:
            return None
        live = self.config.live
        dt = 1.0 / live.rate_hz
        count = max(1, round(live.period_s * live.rate_hz))
        # Up to the newest frame recorded (`delay_s` behind, more while late samples are waited
        # for): a frame not yet assembled would show as missing.
        end = self.recorder.newest
        if end is None:
            end = now - self.config.recorder.delay_s
        times = end - dt * np.arange(count)[::-1]
        tenths: dict[str, list[int | None]] = {}
        if playing is not None:
            for control in playing.plan.controls():
                tenths[f"{control}_cmd"] = [
                    _tenths(playing.commanded(t)[control]) if t >= playing.start else None
                    for t in times
                ]
        inputs, outputs = self.config.identification.channels.axis_set(
            self._axes, self.config.excitation.surfaces
        )
        frames = self.recorder.window(times[0] - dt, times[-1])
        trim = self._trim_of(playing)
        for name in (*inputs, *outputs):
            values = frames.values.get(name)
            if values is None:
                continue
            scale = TO_DISPLAY.get(SENSOR_CHANNELS.get(name, ("", ""))[0], 1.0)
            offset = trim.get(name, 0.0)
            tenths[name] = [_nearest(frames.time, values, t, dt, scale, offset) for t in times]
        return messages.Live(
            time=float(times[0]),
            dt=dt,
            plan_id=None if playing is None else playing.plan.id,
            plan_fraction=None if playing is None else round(playing.fraction(now), 3),
            plan_s=None if playing is None else round(playing.timeline.duration, 1),
            stage="" if stage is None else stage[0],
            stage_s=None if stage is None else round(stage[1], 1),
            stage_expected_s=None if stage is None or stage[2] is None else round(stage[2], 1),
            tenths=tenths,
        )


def _trim_value(values: np.ndarray) -> float | None:
    values = values[np.isfinite(values)]
    return float(values.mean()) if values.size else None


def _tenths(value: float) -> int | None:
    return round(value * 10) if math.isfinite(value) else None


def _nearest(
    time: np.ndarray, values: np.ndarray, t: float, dt: float, scale: float, offset: float = 0.0
) -> int | None:
    """The channel's value less `offset` in the frame nearest `t` (within half a sample), in
    tenths of its display unit."""
    if not len(time):
        return None
    k = int(np.argmin(np.abs(time - t)))
    if abs(time[k] - t) > dt / 2:
        return None
    return _tenths((float(values[k]) - offset) * scale)
