"""The simulated aircraft and the real MAVSDK driver, connected over UDP loopback."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from agent.clock import LoopClock
from agent.config import Autopilot as AutopilotConfig
from agent.sim.aircraft import AircraftOptions, SimAircraft
from agent.sim.ardupilot import Params
from drivers.autopilot.driver import AutopilotLink
from drivers.values import FlightState

SWITCH = 7


@dataclass
class Flight:
    aircraft: SimAircraft
    link: AutopilotLink
    clock: LoopClock
    tasks: list[asyncio.Task] = field(default_factory=list)
    switch: list[tuple[int, float]] = field(default_factory=list)
    links: list[tuple[bool, str, float]] = field(default_factory=list)
    states: list = field(default_factory=list)
    # The driver's callbacks, after the recording above: a test sets them to wire its own
    # consumer (a scheduler) to the link, as the agent does at construction.
    on_switch: Callable[[int, float], None] | None = None
    on_state: Callable[[FlightState], None] | None = None
    on_servos: Callable[[float, dict[int, int]], None] | None = None
    on_sticks: Callable[[float, dict[int, int]], None] | None = None
    on_link: Callable[[bool, str], None] | None = None

    def switched(self, pwm: int, t: float) -> None:
        self.switch.append((pwm, t))
        if self.on_switch is not None:
            self.on_switch(pwm, t)

    def state(self, state: FlightState) -> None:
        self.states.append(state)
        if self.on_state is not None:
            self.on_state(state)

    def servos(self, t: float, pwm: dict[int, int]) -> None:
        if self.on_servos is not None:
            self.on_servos(t, pwm)

    def sticks(self, t: float, pwm: dict[int, int]) -> None:
        if self.on_sticks is not None:
            self.on_sticks(t, pwm)

    def linked(self, up: bool, why: str) -> None:
        self.links.append((up, why, self.clock.now()))
        if self.on_link is not None:
            self.on_link(up, why)


@contextlib.asynccontextmanager
async def flight(
    tmp_path: Path,
    *,
    params: Params | None = None,
    system_id: int = 255,
    noise: bool = True,
    sensor_rate_hz: float = 100.0,
    **link_options,
):
    clock = LoopClock()
    options = AircraftOptions(
        params=params or Params(switch_channel=SWITCH), noise=noise, sensor_rate_hz=sensor_rate_hz
    )
    aircraft = SimAircraft(options, clock, tmp_path)
    sim_task = asyncio.create_task(aircraft.run(), name="sim-aircraft")
    while aircraft.mavlink_address is None:
        await asyncio.sleep(0.01)
    host, port = aircraft.mavlink_address
    config = AutopilotConfig(url=f"udpout://{host}:{port}", system_id=system_id, **link_options)
    holder: list[Flight] = []
    link = AutopilotLink(
        config,
        clock,
        switch_channel=SWITCH,
        on_switch=lambda pwm, t: holder[0].switched(pwm, t),
        on_state=lambda s: holder[0].state(s),
        on_servos=lambda t, pwm: holder[0].servos(t, pwm),
        on_sticks=lambda t, pwm: holder[0].sticks(t, pwm),
        on_link=lambda up, why: holder[0].linked(up, why),
    )
    f = Flight(aircraft, link, clock, [sim_task])
    holder.append(f)
    f.tasks.append(asyncio.create_task(link.run(), name="autopilot-link"))
    try:
        for _ in range(500):
            if link.connected:
                break
            await asyncio.sleep(0.01)
        yield f
    finally:
        for task in reversed(f.tasks):
            task.cancel()
        await asyncio.gather(*f.tasks, return_exceptions=True)
