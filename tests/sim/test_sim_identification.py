"""A whole open-loop excitation through the real parts: the scheduler plays the lateral preset
through MAVSDK → the emulated ArduPlane → JSBSim; the response comes back as VN-200, µADC and
surface-box bytes on pseudo-terminals through the real drivers into the recorder; the
identification core finds the Dutch roll, compared with JSBSim's validated linear model
(agent.sim.truth)."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from agent.config import (
    AirDataPort,
    Config,
    Sensors,
    SurfacePort,
    VectorNav,
)
from agent.config import (
    Recorder as RecorderConfig,
)
from agent.excitation.plan import preset
from agent.excitation.scheduler import Scheduler, Window
from agent.ident import Experiment, Settings, identify
from agent.recorder import Recorder
from agent.sim.truth import linear_truth
from drivers.airdata.driver import make_driver as airdata_driver
from drivers.surfaces.driver import make_driver as surfaces_driver
from drivers.vectornav.driver import make_driver as vn200_driver
from tests.sim.flight import flight

pytestmark = pytest.mark.usefixtures("no_leaked_tasks")
OUTPUTS = ("beta", "p", "r", "phi")


def _dutch_roll(options) -> complex:
    """JSBSim's Dutch roll at this trim, from the validated truth (agent.sim.truth)."""
    truth = linear_truth(options.aircraft, options.speed_kts, altitude_ft=options.altitude_ft)
    (dutch,) = truth.modes()["Dutch roll"]
    return dutch


async def test_lateral_preset_through_the_whole_chain_finds_the_dutch_roll(tmp_path):
    config = Config()
    async with flight(tmp_path) as f:
        clock = f.clock
        sensors = Sensors(
            vn200=VectorNav(port=str(tmp_path / "vn200")),
            airdata=AirDataPort(port=str(tmp_path / "airdata")),
            surfaces=SurfacePort(port=str(tmp_path / "surfaces")),
        )
        recorder = Recorder(config.recorder, clock)
        scheduler = Scheduler(config.excitation, f.link, clock)
        f.on_switch = scheduler.update_switch
        f.on_state = scheduler.update_state
        f.on_servos = scheduler.update_servos
        windows: list[Window] = []
        scheduler.subscribe(lambda e: windows.append(e) if isinstance(e, Window) else None)
        for make in (vn200_driver, airdata_driver, surfaces_driver):
            f.tasks.append(
                asyncio.create_task(make(sensors, clock, recorder.push).run(), name="drv")
            )
        f.tasks.append(asyncio.create_task(recorder.run(), name="recorder"))
        f.tasks.append(asyncio.create_task(scheduler.run(), name="scheduler"))
        await asyncio.sleep(1.5)  # trimmed flight, telemetry and sensors settle
        scheduler.arm(preset("lateral"))
        f.aircraft.pilot.set_switch(True)
        for _ in range(300):
            if windows:
                break
            await asyncio.sleep(0.1)
        await asyncio.sleep(0.2)
        window = windows[0]
        frames = recorder.window(window.start - 0.5, window.end)
        truth = _dutch_roll(f.aircraft.options)
    assert window.outcome == "finished"
    u = np.column_stack([frames.values["aileron"], frames.values["rudder"]])
    y = np.column_stack([frames.values[c] for c in OUTPUTS])
    assert np.isfinite(u).all()
    assert np.isfinite(y).all()
    trim = slice(0, 50)
    experiment = Experiment(u - u[trim].mean(axis=0), y - y[trim].mean(axis=0))
    # The surface pots sample continuously moving surfaces: not held inputs.
    result = identify(experiment, 0.01, output_roles=OUTPUTS, settings=Settings(held_inputs=False))
    dutch = [m for m in result.modes if m.name == "Dutch roll"]
    assert dutch, [(m.name, m.eigenvalue) for m in result.modes]
    error = abs(dutch[0].eigenvalue - truth) / abs(truth)
    print(f"Dutch roll {dutch[0].eigenvalue:.3f} vs JSBSim {truth:.3f}: {error:.1%}")
    assert error < 0.10, f"Dutch roll {dutch[0].eigenvalue:.3f} vs JSBSim {truth:.3f}"


async def test_sensors_at_400_hz_subdivide_the_autopilot_tick(tmp_path):
    # The VN-200's IMU rate: JSBSim integrates at 400 Hz, the autopilot still ticks at 100 Hz,
    # and each of the three devices writes a frame every 2.5 ms, stamped with its own time,
    # through the real drivers into a 400 Hz recorder.
    async with flight(tmp_path, sensor_rate_hz=400.0) as f:
        clock, aircraft = f.clock, f.aircraft
        sensors = Sensors(
            vn200=VectorNav(port=str(tmp_path / "vn200"), rate_hz=400.0),
            airdata=AirDataPort(port=str(tmp_path / "airdata"), rate_hz=400.0),
            surfaces=SurfacePort(port=str(tmp_path / "surfaces"), rate_hz=400.0),
        )
        recorder = Recorder(RecorderConfig(rate_hz=400.0), clock)
        drivers = [
            make(sensors, clock, recorder.push)
            for make in (vn200_driver, airdata_driver, surfaces_driver)
        ]
        f.tasks += [asyncio.create_task(d.run(), name=d.name) for d in drivers]
        f.tasks.append(asyncio.create_task(recorder.run(), name="recorder"))
        await asyncio.sleep(1.0)
        ticks, sent = aircraft.ticks, {n: e.sent for n, e in aircraft.emitters.items()}
        start = clock.now()
        await asyncio.sleep(2.0)
        ticks, sent = (
            aircraft.ticks - ticks,
            {n: e.sent - sent[n] for n, e in aircraft.emitters.items()},
        )
        stamps = {n: [t for _, t in e.truth][-400:] for n, e in aircraft.emitters.items()}
        now = clock.now()
        health = [d.health() for d in drivers]
        recent = {
            n: sum(now - 1.0 < t <= now for _, t in e.truth) for n, e in aircraft.emitters.items()
        }
        frames = recorder.window(start, start + 1.0)
    assert aircraft.plant.dt == pytest.approx(1 / 400)
    # Counted against each other, not against the wall clock: on a busy machine the world can
    # fall behind the clock for a moment and catch up, but every tick gives four frames.
    assert ticks > 100
    for name, count in sent.items():
        assert count == pytest.approx(4 * ticks, abs=4), name
        assert np.diff(stamps[name]) == pytest.approx(0.0025, abs=1e-9), name
    for h in health:
        # The rate shown is the device's own: its frames of the last second, by their stamps.
        assert h.rate_hz == pytest.approx(recent[h.name], abs=4), h
        assert (h.gaps, h.crc_errors, h.bytes_skipped) == (0, 0, 0), h
    assert len(frames.time) == pytest.approx(400, abs=1)
    for channel in ("p", "beta", "aileron"):
        assert np.isfinite(frames.values[channel]).all(), channel
