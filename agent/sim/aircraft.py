"""The hardware-free aircraft: JSBSim, the emulated ArduPlane on UDP, the scripted pilot and
the three sensors on pseudo-terminals, stepped together in real time on the event loop.

Physics runs at JSBSim's 200 Hz, two steps per 100 Hz tick of the autopilot (servo outputs in,
telemetry out). The sensors sample the state of each tick, with white noise at the
instruments' levels (thesis chapter 3) and the µADC's ±20° probe limit; their frames carry the
simulated time of the state they hold. Sensors faster than the tick (`sensor_rate_hz` 400: the
VN-200's IMU rate) subdivide it: JSBSim then integrates at the sensor rate (at least 200 Hz),
the autopilot still acts every 10 ms, and each sample is written at its own time.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import os
import random
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from agent.clock import Clock
from agent.config import SurfacePort
from agent.sim import devices
from agent.sim.ardupilot import (
    FBWA,
    MANUAL,
    OUTPUTS,
    EmulatedArduPlane,
    Params,
    normalised_to_pwm,
    setup,
)
from agent.sim.dataflash import DataFlashWriter
from agent.sim.pilot import ScriptedPilot, departed
from agent.sim.plant import Plant, PlantError

log = logging.getLogger(__name__)

TICK_HZ = 100.0
DEG = math.pi / 180
# 1-σ sensor noise (VN-200 and µADC data sheets via the thesis's chapter 3; pots ±0.5 %).
NOISE = {
    "phi": 0.05 * DEG,
    "theta": 0.05 * DEG,
    "psi": 0.1 * DEG,
    "p": 0.02 * DEG,
    "q": 0.02 * DEG,
    "r": 0.02 * DEG,
    "ax": 0.01,
    "ay": 0.01,
    "az": 0.01,
    "Vt": 0.1,
    "alpha": 0.2 * DEG,
    "beta": 0.2 * DEG,
    "aileron_left": 0.1,
    "aileron_right": 0.1,
    "elevator": 0.1,
    "rudder": 0.1,
    "vn": 0.05,
    "ve": 0.05,
    "vd": 0.05,
}


# The JSBSim aircraft this project flies in its benchmarks (benchmarks/bench_jsbsim.py), each
# with the speed (kt) and height above the ground (ft) it is trimmed at there, and what it is.
# Any other aircraft JSBSim has flies too, at a speed the user gives (`flown_at`).
FLOWN: dict[str, tuple[float, float, str]] = {
    "J3Cub": (60.0, 1000.0, "light piston, tailwheel"),
    "c182": (90.0, 1000.0, "piston single"),
    "pa28": (90.0, 1000.0, "piston single, low wing"),
    "c172r": (95.0, 1000.0, "four-seat trainer"),
    "t6texan2": (150.0, 1000.0, "turbine trainer, direct thrust"),
    "sgs126": (50.0, 3000.0, "glider, unpowered"),
}


def jsbsim_aircraft() -> list[str]:
    """The aircraft JSBSim's package holds (a folder with its NAME.xml), sorted."""
    import jsbsim

    root = Path(jsbsim.get_default_root_dir()) / "aircraft"
    return sorted(d.name for d in root.iterdir() if d.is_dir() and (d / f"{d.name}.xml").is_file())


def flown_at(
    aircraft: str, speed_kts: float | None, altitude_ft: float | None
) -> tuple[float, float]:
    """The speed and height to fly `aircraft` at: as given, else FLOWN's; a ValueError for
    an aircraft JSBSim does not have, or one not in FLOWN with no speed given (a speed is the
    aircraft's own: 60 kt stalls a turboprop and overspeeds a glider)."""
    known = FLOWN.get(aircraft)
    if known is None and aircraft not in jsbsim_aircraft():
        raise ValueError(f"JSBSim has no aircraft {aircraft!r} (sysid sim --list-aircraft)")
    if speed_kts is None and known is None:
        raise ValueError(
            f"give --speed-kts for {aircraft}: its trim speed is known here only for "
            f"{', '.join(FLOWN)} (sysid sim --list-aircraft)"
        )
    speed = speed_kts if speed_kts is not None else known[0]
    height = altitude_ft if altitude_ft is not None else (known or FLOWN["J3Cub"])[1]
    return speed, height


# Shaped like drivers/serialio.py's LinkStats only: how to fly, not what a link has seen.
@dataclass
class AircraftOptions:
    aircraft: str = "J3Cub"
    speed_kts: float = 60.0
    altitude_ft: float = 1000.0
    turbulence: float = 0.0
    seed: int = 0
    noise: bool = True
    vanes: bool = True  # the air data measure α and β (false: airspeed only)
    mode: int = 0  # the emulated ArduPlane's flight mode at the start (0 MANUAL, 5 FBWA)
    mavlink_host: str = "127.0.0.1"
    mavlink_port: int = 0
    """UDP port the emulated autopilot listens on (0: any free port)."""
    gcs: tuple[str, int] | None = None
    """Where to send telemetry before any GCS has spoken (like ArduPilot's --out)."""
    params: Params = field(default_factory=Params)
    sensor_rate_hz: float = 100.0
    dataflash: Path | None = None
    """Where the emulated ArduPlane writes its onboard DataFlash log (.bin); None: no log."""


def noisy(state: Callable[[], dict[str, float]], seed: int, enabled: bool):
    rng = random.Random(seed)

    def sample(_t: float) -> dict[str, float]:
        s = dict(state())
        if enabled:
            for name, sigma in NOISE.items():
                if name in s:
                    s[name] += rng.gauss(0.0, sigma)
        return s

    return sample


def check_sensor_rate(hz: float) -> None:
    """The sensors sample whole ticks or whole subdivisions of one: 100 Hz divided or
    multiplied by a whole number (50, 100, 200, 400…, at most 1000)."""
    ratio = hz / TICK_HZ if hz >= TICK_HZ else TICK_HZ / hz if hz > 0 else 0.0
    if not 0 < hz <= 1000 or abs(ratio - round(ratio)) > 1e-9:
        raise ValueError(
            f"sensor rate {hz:g} Hz: must be {TICK_HZ:g} Hz divided or multiplied by a whole "
            "number, at most 1000 Hz (for example 50, 100, 200 or 400)"
        )


class SimAircraft:
    """Owns the plant, the autopilot emulation, the pilot and the sensor ports."""

    def __init__(self, options: AircraftOptions, clock: Clock, directory: Path):
        check_sensor_rate(options.sensor_rate_hz)
        self.options, self._clock = options, clock
        self.directory = Path(directory)
        self.per_tick = max(1, round(options.sensor_rate_hz / TICK_HZ))
        """Sensor samples per autopilot tick."""
        self.plant = Plant(
            options.aircraft,
            airspeed_kts=options.speed_kts,
            altitude_ft=options.altitude_ft,
            turbulence=options.turbulence,
            seed=options.seed,
            linearise=False,
            integration_hz=max(200.0, TICK_HZ * self.per_tick),
        )
        sticks = {ch: normalised_to_pwm(ch, self.plant.trim[name]) for ch, name in OUTPUTS.items()}
        self.pilot = ScriptedPilot(sticks, options.params.switch_channel)
        # ArduPlane set up for this aircraft as its pilot would (ardupilot.setup), under
        # whatever the options give.
        state = self.plant.state()
        params = replace(options.params, fbwa=setup(state) | options.params.fbwa)
        self.autopilot = EmulatedArduPlane(
            params,
            self.pilot,
            dt=1.0 / TICK_HZ,
            trim=self.plant.trim,
            gcs=options.gcs,
            clock=clock.now,
            dataflash=DataFlashWriter(options.dataflash) if options.dataflash else None,
        )
        if options.mode and not self.autopilot.set_mode(options.mode):
            raise ValueError(f"the emulated ArduPlane does not fly mode {options.mode}")
        self.truth = self.plant.state()
        self.trimmed = dict(self.truth)  # the flight a departure is judged from (`departed`)
        if not self.plant.engines:  # a glider's height goes by design: no departure
            self.trimmed.pop("agl")
        self.recoveries: list[tuple[float, str]] = []  # (s into the flight, why)
        self.ports = {
            n: devices.PtyPort(self.directory / n) for n in ("vn200", "airdata", "surfaces")
        }
        self.emitters: dict[str, devices.Emitter] = {}
        self.mavlink_address: tuple[str, int] | None = None
        self.ticks = 0
        self._due: float | None = None  # the clock time the next sample is simulated at

    def behind(self) -> float:
        """How far the simulated world is behind the clock, s (0 before it flies): a process
        starved of CPU runs the samples it owes back to back, its sensors' frames late."""
        return 0.0 if self._due is None else max(0.0, self._clock.now() - self._due)

    def _state(self) -> dict[str, float]:
        return self.truth

    async def run(self) -> None:
        """Fly until cancelled."""
        loop = asyncio.get_running_loop()
        transport, _ = await loop.create_datagram_endpoint(
            lambda: self.autopilot,
            local_addr=(self.options.mavlink_host, self.options.mavlink_port),
        )
        self.mavlink_address = transport.get_extra_info("sockname")[:2]
        boot = self._clock.now()
        seed, noise, rate = self.options.seed, self.options.noise, self.options.sensor_rate_hz
        calibration = SurfacePort(port="sim").calibration
        encoders = {
            "vn200": devices.vn200_binary(noisy(self._state, seed + 1, noise), boot),
            "airdata": devices.airdata(noisy(self._state, seed + 2, noise), self.options.vanes),
            "surfaces": devices.surfaces(noisy(self._state, seed + 3, noise), calibration, boot),
        }
        try:
            for name, port in self.ports.items():
                port.plug()
                self.emitters[name] = devices.Emitter(port, encoders[name], rate, self._clock)
            await self._physics()
        finally:
            transport.close()
            if self.autopilot.dataflash is not None:
                self.autopilot.dataflash.close()
            for port in self.ports.values():
                if port.plugged:
                    port.unplug()

    async def _physics(self) -> None:
        """Sample s is simulated time start + s·h (h = 1/(TICK_HZ·per_tick)): at each tick
        the autopilot acts, then JSBSim steps to the sample's end and the sensors sample that
        very state. A late loop runs the samples it owes back to back, so the data stay true to
        their time stamps and only their delivery is late."""
        dt = 1.0 / TICK_HZ
        h = dt / self.per_tick
        steps = round(h / self.plant.dt)
        rate = TICK_HZ * self.per_tick
        every = {name: max(1, round(rate / e.rate_hz)) for name, e in self.emitters.items()}
        start = self._clock.now()
        sample = 0
        while True:
            t = start + sample * h
            if sample % self.per_tick == 0:
                commands = self.autopilot.tick(t, self.truth)
                self.plant.set_normalised(commands, steps * self.per_tick)
                self.ticks += 1
            for _ in range(steps):
                self.plant.step()
            self.truth = self.plant.state()
            if self.autopilot.mode == MANUAL and (why := departed(self.truth, self.trimmed)):
                # The safety pilot flips to FBWA, sticks centred: its laws level the wings and
                # the pitch, and the flight goes on stabilised (the agent's next runs then
                # excite closed loop, as a flight-test engineer flies an unstable aircraft).
                self.autopilot.set_mode(FBWA)
                self.recoveries.append((t + h - start, why))
            if self.plant.on_ground:  # no flight to identify: end it, say why
                raise PlantError(
                    f"it touched the ground {t + h - start:.1f} s into the flight, "
                    f"{self.truth['Vt']:.1f} m/s, pitch {math.degrees(self.truth['theta']):.0f}°"
                )
            for name, emitter in self.emitters.items():
                if sample % every[name] == 0:
                    emitter.emit(t + h, sample // every[name])
            sample += 1
            self._due = start + sample * h
            await self._clock.sleep_until(self._due)


async def serve(
    options: AircraftOptions,
    directory: Path,
    duration: float | None,
    switch_at: tuple[float, ...] = (),
    announce=print,
) -> None:
    """`sysid sim-aircraft`: fly, say where to connect, flip the switch as asked (the
    schedule, or SIGUSR1 to toggle), stop after `duration` s or when cancelled."""
    import signal

    from agent.clock import LoopClock

    clock = LoopClock()
    directory.mkdir(parents=True, exist_ok=True)
    aircraft = SimAircraft(options, clock, directory)
    task = asyncio.create_task(aircraft.run(), name="sim-aircraft")
    try:
        while aircraft.mavlink_address is None and not task.done():
            await asyncio.sleep(0.01)
        if task.done():
            await task  # raises what stopped it
        host, port = aircraft.mavlink_address
        start = clock.now()
        for k, at in enumerate(switch_at):
            aircraft.pilot.schedule(start + at, high=k % 2 == 0)
        loop = asyncio.get_running_loop()
        loop.add_signal_handler(
            signal.SIGUSR1, lambda: aircraft.pilot.set_switch(not aircraft.pilot.switch_high)
        )
        trim = ", ".join(f"{k} {v:+.3f}" for k, v in aircraft.plant.trim.items())
        hz, ports = options.sensor_rate_hz, aircraft.ports
        announce(
            f"simulated {options.aircraft} trimmed at {options.speed_kts:g} kt, "
            f"{options.altitude_ft:g} ft (normalised trim: {trim})\n"
            f'MAVLink (emulated ArduPlane, system 1): [autopilot] url = "udpout://{host}:{port}"\n'
            f'VN-200 (binary, {hz:g} Hz): [sensors.vn200] port = "{ports["vn200"].path}"\n'
            f"µADC ({hz:g} Hz{'' if options.vanes else ', airspeed only'}): [sensors.airdata] "
            f'port = "{ports["airdata"].path}"{"" if options.vanes else ", vanes = false"}\n'
            f'surface box ({hz:g} Hz): [sensors.surfaces] port = "{ports["surfaces"].path}"\n'
            f"excitation switch: RC channel {options.params.switch_channel}, low; "
            f"kill -USR1 {os.getpid()} toggles it"
        )
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(duration):
                await asyncio.shield(task)
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
