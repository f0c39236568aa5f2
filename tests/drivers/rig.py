"""A bench of fake sensors on pseudo-terminals and the real drivers reading them."""

from __future__ import annotations

import asyncio
import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from agent.clock import LoopClock
from agent.config import AirDataPort, Sensors, SurfacePort, VectorNav
from agent.sim import devices
from drivers.airdata.driver import make_driver as airdata_driver
from drivers.sensor import Sample, SensorDriver
from drivers.surfaces.driver import make_driver as surfaces_driver
from drivers.vectornav.driver import make_driver as vn200_driver

RATE = 100.0


def state(t: float) -> dict[str, float]:
    """A smooth flight state: every channel moves, so timing errors show up as value errors."""
    w = 2 * math.pi * 0.5
    return {
        "phi": 0.2 * math.sin(w * t),
        "theta": 0.05 + 0.02 * math.cos(w * t),
        "psi": 1.0 + 0.01 * t,
        "p": 0.2 * w * math.cos(w * t),
        "q": -0.02 * w * math.sin(w * t),
        "r": 0.01,
        "Vt": 22.0 + math.sin(w * t),
        "alpha": 0.05 + 0.01 * math.sin(w * t),
        "beta": 0.02 * math.cos(w * t),
        "aileron": 5.0 * math.sin(w * t),
        "elevator": -2.0,
        "rudder": 3.0 * math.cos(w * t),
        "alt": 120.0,
    }


@dataclass
class Rig:
    tmp: Path
    clock: LoopClock = field(default_factory=LoopClock)
    ports: dict[str, devices.PtyPort] = field(default_factory=dict)
    emitters: dict[str, devices.Emitter] = field(default_factory=dict)
    drivers: dict[str, SensorDriver] = field(default_factory=dict)
    samples: dict[str, list[Sample]] = field(default_factory=lambda: defaultdict(list))
    tasks: list[asyncio.Task] = field(default_factory=list)
    boot: float = 0.0

    def sensors(self, **overrides) -> Sensors:
        paths = {n: str(self.tmp / n) for n in ("vn200", "airdata", "surfaces")}
        return Sensors(
            vn200=VectorNav(port=paths["vn200"], rate_hz=RATE, **overrides.get("vn200", {})),
            airdata=AirDataPort(port=paths["airdata"], rate_hz=RATE),
            surfaces=SurfacePort(port=paths["surfaces"], rate_hz=RATE),
            backoff_initial_s=0.05,
            backoff_max_s=0.4,
        )

    def publish(self, sample: Sample) -> None:
        self.samples[sample.source].append(sample)

    async def start(self, names=("vn200", "airdata", "surfaces"), sink=None, emit=True, **over):
        sensors = self.sensors(**over)
        self.boot = self.clock.now() - 3.0
        encoders = {
            "vn200": devices.vn200_binary(state, self.boot)
            if sensors.vn200.protocol == "binary"
            else devices.vn200_ascii(state),
            "airdata": devices.airdata(state),
            "surfaces": devices.surfaces(state, sensors.surfaces.calibration, self.boot),
        }
        makers = {"vn200": vn200_driver, "airdata": airdata_driver, "surfaces": surfaces_driver}
        for name in names:
            port = devices.PtyPort(self.tmp / name)
            port.plug()
            self.ports[name] = port
            self.emitters[name] = devices.Emitter(port, encoders[name], RATE, self.clock)
            publish = self.publish if sink is None else (lambda s, f=sink: (self.publish(s), f(s)))
            self.drivers[name] = makers[name](sensors, self.clock, publish)
            self.tasks.append(asyncio.create_task(self.drivers[name].run(), name=f"{name}-driver"))
        await asyncio.sleep(0.05)  # drivers open their ports before the first frame
        if emit:
            for name in names:
                self.tasks.append(
                    asyncio.create_task(self.emitters[name].run(), name=f"{name}-emitter")
                )

    async def stop(self) -> None:
        # Emitters stop first and the drivers get a few periods to read what is already in the
        # pty: a frame written just before the stop is otherwise counted as sent but never read.
        emitters = [t for t in self.tasks if "emitter" in t.get_name()]
        for task in emitters:
            task.cancel()
        await asyncio.gather(*emitters, return_exceptions=True)
        await asyncio.sleep(5 / RATE)
        for task in self.tasks:
            task.cancel()
        await asyncio.gather(*self.tasks, return_exceptions=True)
        for port in self.ports.values():
            if port.plugged:
                port.unplug()

    def truth(self, name: str, sample: Sample) -> float:
        """The time the fake device sampled this reading."""
        if name == "vn200":
            return self.boot + sample.values["vn_time"]
        key = {"airdata": "adc_sample", "surfaces": "box_seq"}[name]
        frames = dict(self.emitters[name].truth)
        return frames[int(sample.values[key])]
