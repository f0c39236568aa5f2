"""The simulated aircraft and the real MAVSDK driver, connected over UDP loopback."""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass, field
from pathlib import Path

from agent.clock import LoopClock
from agent.config import Autopilot as AutopilotConfig
from agent.sim.aircraft import AircraftOptions, SimAircraft
from agent.sim.ardupilot import Params
from drivers.autopilot.driver import AutopilotLink

SWITCH = 7


@dataclass
class Flight:
    aircraft: SimAircraft
    link: AutopilotLink
    tasks: list[asyncio.Task] = field(default_factory=list)
    switch: list[tuple[int, float]] = field(default_factory=list)
    links: list[tuple[bool, str, float]] = field(default_factory=list)
    states: list = field(default_factory=list)


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
        on_switch=lambda pwm, t: holder[0].switch.append((pwm, t)),
        on_state=lambda s: holder[0].states.append(s),
        on_link=lambda up, why: holder[0].links.append((up, why, clock.now())),
    )
    f = Flight(aircraft, link, [sim_task])
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
