"""The whole recording chain over pseudo-terminals: three fake sensors at 100 Hz, the real
drivers, the recorder, and the flight log.

Bad input tried: unplugging one sensor's port for 1.5 s in the middle of a recording; the event
loop blocked for 1 s (the fake sensors' frames then come late, in a burst).
"""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

from agent.channels import SENSOR_CHANNELS
from agent.config import Recorder as RecorderConfig
from agent.logs import Logbook, LogWriter, config_hash, read_log, units_of
from agent.recorder import Recorder
from tests.drivers.rig import RATE, Rig

pytestmark = pytest.mark.usefixtures("no_leaked_tasks")
PERIOD = 1 / RATE
COUNTERS = {"vn200": "vn_time", "airdata": "adc_sample", "surfaces": "box_seq"}


async def _record(tmp_path, seconds: float, during=None):
    rig = Rig(tmp_path)
    writer = LogWriter(tmp_path / "logs")
    recorder = Recorder(RecorderConfig(), rig.clock)
    book = Logbook(
        writer, recorder.columns, units_of(recorder.columns, SENSOR_CHANNELS), config_hash("test")
    )
    recorder.sink = book.row
    try:
        await rig.start(sink=recorder.push)
        task = asyncio.create_task(recorder.run(), name="recorder")
        rig.tasks.append(task)
        if during is None:
            await asyncio.sleep(seconds)
        else:
            await during(rig)
    finally:
        await rig.stop()
        writer.close()
    return rig, recorder, writer, book


def _truth_errors(rig: Rig, recorder: Recorder, name: str, frames) -> np.ndarray:
    """Per frame: (time of the sample held for this sensor) − (when the device sampled it)."""
    counter, age = frames.values[COUNTERS[name]], frames.ages[COUNTERS[name]]
    ok = np.isfinite(counter)
    if name == "vn200":
        truth = rig.boot + counter[ok]
    else:
        table = dict(rig.emitters[name].truth)
        truth = np.array([table[int(c)] for c in counter[ok]])
    return (frames.time[ok] - age[ok]) - truth


async def test_twenty_seconds_of_three_sensors_lose_nothing_and_keep_time(tmp_path):
    # Twenty seconds: 2000 frames a sensor, each checked; hours of it are benchmarks/soak's.
    rig, recorder, writer, book = await _record(tmp_path, 20.0)
    for name in ("vn200", "airdata", "surfaces"):
        health = rig.drivers[name].health()
        assert len(rig.samples[name]) == rig.emitters[name].sent, name  # zero lost frames
        assert rig.emitters[name].sent >= 19 * RATE
        assert health.gaps == 0
        assert health.crc_errors == 0
    frames = recorder.window(-np.inf, np.inf)
    assert np.allclose(np.diff(frames.time), 1 / RecorderConfig().rate_hz)  # every frame
    settled = frames.time > frames.time[0] + 1.0
    for name in ("vn200", "airdata", "surfaces"):
        errors = _truth_errors(rig, recorder, name, frames)
        assert np.all(np.abs(errors) < PERIOD), f"{name}: worst {np.abs(errors).max():.4f} s"
        assert np.all(frames.ages[COUNTERS[name]][settled] < 2 * PERIOD)
    # The flight log holds every frame, each line whole.
    assert writer.dropped == 0
    header, rows = read_log(writer.path(book.flight))
    assert header == recorder.columns
    assert rows.shape[0] == len(frames.time)


async def test_unplugging_one_sensor_records_the_gap_and_never_stalls_the_others(tmp_path):
    async def unplug_airdata(rig: Rig) -> None:
        await asyncio.sleep(3.0)
        rig.ports["airdata"].unplug()
        await asyncio.sleep(1.5)
        rig.ports["airdata"].plug()
        await asyncio.sleep(3.0)

    rig, recorder, _, _ = await _record(tmp_path, 0, during=unplug_airdata)
    for name in ("vn200", "surfaces"):
        assert rig.drivers[name].health().gaps == 0
        assert len(rig.samples[name]) == rig.emitters[name].sent
    airdata = rig.drivers["airdata"].health()
    assert airdata.gaps == 1
    assert airdata.opens == 2
    frames = recorder.window(-np.inf, np.inf)
    assert np.allclose(np.diff(frames.time), 0.01)  # the recorder never stalled
    vt, vt_age = frames.values["Vt"], frames.ages["Vt"]
    missing = np.isnan(vt) & (frames.time > frames.time[0] + 1.0)
    assert 1.3 < missing.sum() * 0.01 < 2.1  # the gap is empty in the record, not held
    assert vt_age[missing].max() > 1.4
    assert np.isfinite(vt[-50:]).all()  # recording resumed
    assert np.isfinite(frames.values["p"][missing]).all()  # the INS kept recording


def _hold_up_the_loop(rig: Rig, seconds: float) -> None:
    """Block the event loop for `seconds` (a busy CPU) while the fake sensors go on sending,
    as devices with their own oscillators do: their bytes wait in the ports."""
    end = rig.clock.now() + seconds
    while (now := rig.clock.now()) < end:
        for emitter in rig.emitters.values():
            emitter.emit_owed(now)
        time.sleep(PERIOD / 2)


async def test_a_stalled_loop_loses_no_recorded_data(tmp_path):
    stalled = {}

    async def stall(rig: Rig) -> None:
        await asyncio.sleep(2.0)
        stalled["at"] = rig.clock.now()
        # Six times the recorder's delay, and longer than the drivers' silence watchdog (1 s).
        _hold_up_the_loop(rig, 1.5)
        await asyncio.sleep(3.0)

    rig, recorder, _, _ = await _record(tmp_path, 0, during=stall)
    frames = recorder.window(-np.inf, np.inf)
    assert np.allclose(np.diff(frames.time), 0.01)  # every frame
    settled = frames.time > frames.time[0] + 1.0
    around = settled & (frames.time > stalled["at"] - 1.0) & (frames.time < stalled["at"] + 2.5)
    assert around.sum() >= 340
    # The frames of the stall came late, in a burst after it: each recorded, none empty.
    for name in ("p", "Vt", "aileron", "vn_time", "adc_sample", "box_seq"):
        assert np.isfinite(frames.values[name][settled]).all(), name
    for name in ("vn200", "airdata", "surfaces"):
        assert len(rig.samples[name]) == rig.emitters[name].sent, name
        health = rig.drivers[name].health()
        assert (health.opens, health.silences) == (1, 0), name  # not taken for a silent device
        errors = _truth_errors(rig, recorder, name, frames)
        assert np.all(np.abs(errors[settled[np.isfinite(frames.values[COUNTERS[name]])]]) < PERIOD)
    assert recorder.counters["waited_frames"] >= 1
