"""The real drivers against fake devices writing real bytes into pseudo-terminals.

Bad input tried: a port that does not exist yet, a port unplugged mid-stream and plugged back,
a device that falls silent, and a stream with 10 % of its frames corrupted.
"""

from __future__ import annotations

import asyncio
import itertools

import numpy as np
import pytest

from agent.clock import VirtualClock
from drivers.surfaces.codec import LENGTH
from tests.drivers.rig import RATE, Rig
from tests.waiting import until

pytestmark = pytest.mark.usefixtures("no_leaked_tasks")
PERIOD = 1 / RATE


async def test_each_driver_decodes_every_frame_on_time(tmp_path):
    rig = Rig(tmp_path)
    await rig.start()
    try:
        await asyncio.sleep(2.0)
    finally:
        await rig.stop()
    for name in ("vn200", "airdata", "surfaces"):
        samples = rig.samples[name]
        health = rig.drivers[name].health()
        assert len(samples) == rig.emitters[name].sent  # every frame written came out
        assert health.crc_errors == 0
        assert health.gaps == 0
        errors = np.array([s.time - rig.truth(name, s) for s in samples])
        assert np.all(np.abs(errors) < PERIOD), f"{name}: {np.abs(errors).max():.4f} s"


async def test_corrupted_frames_are_counted_and_the_rest_delivered(tmp_path):
    rig = Rig(tmp_path)
    await rig.start(names=("surfaces",), emit=False)
    rig.emitters["surfaces"].corrupt = 0.1
    rig.tasks.append(asyncio.create_task(rig.emitters["surfaces"].run(), name="emitter"))
    try:
        await asyncio.sleep(1.5)
    finally:
        await rig.stop()
    emitter, health = rig.emitters["surfaces"], rig.drivers["surfaces"].health()
    assert emitter.corrupted > 5
    # Each spoilt frame is skipped whole; a flipped sync byte is a resync, not a CRC error.
    assert health.bytes_skipped == emitter.corrupted * LENGTH
    assert emitter.corrupted - 3 <= health.crc_errors + health.rejected <= emitter.corrupted
    assert len(rig.samples["surfaces"]) == emitter.sent - emitter.corrupted
    assert 1 <= health.gaps <= emitter.corrupted  # a lost frame is a gap in the samples


async def test_unplugged_port_reconnects_and_records_the_gap(tmp_path):
    rig = Rig(tmp_path)
    await rig.start(names=("airdata",))
    try:
        await asyncio.sleep(0.6)
        rig.ports["airdata"].unplug()
        await asyncio.sleep(1.0)
        rig.ports["airdata"].plug()
        await asyncio.sleep(1.0)
    finally:
        await rig.stop()
    health = rig.drivers["airdata"].health()
    assert health.opens == 2
    assert health.disconnects == 1
    assert health.gaps == 1
    (start, end) = health.gap_log[0]
    # Unplugged for 1 s; the driver notices at the next retry (backoff at most 0.4 s here).
    assert 0.95 < end - start < 1.0 + 0.4 + 0.1
    after = [s for s in rig.samples["airdata"] if s.time > end]
    assert len(after) > 50  # recording resumed


async def test_missing_port_is_retried_with_capped_backoff(tmp_path):
    rig = Rig(tmp_path)
    await rig.start(names=("surfaces",), emit=False)
    rig.ports["surfaces"].unplug()  # the device is not there when the agent starts
    try:
        await asyncio.sleep(1.2)
        failures = rig.drivers["surfaces"].link.stats.open_failures
        # 0.05, 0.1, 0.2, 0.4, 0.4 …: five or six attempts in 1.2 s, not a busy loop.
        assert 3 <= failures <= 8
        rig.ports["surfaces"].plug()
        rig.tasks.append(asyncio.create_task(rig.emitters["surfaces"].run(), name="emitter"))
        await asyncio.sleep(0.8)
    finally:
        await rig.stop()
    assert len(rig.samples["surfaces"]) > 20
    assert "cannot open" in rig.drivers["surfaces"].link.stats.last_error


async def test_silent_device_is_reopened(tmp_path):
    rig = Rig(tmp_path)
    await rig.start(names=("vn200",), vn200={"silence_s": 0.3})
    try:
        await asyncio.sleep(0.5)
        rig.tasks[-1].cancel()  # the emitter stops: the port stays, the bytes stop
        await asyncio.sleep(0.8)
    finally:
        await rig.stop()
    stats = rig.drivers["vn200"].link.stats
    assert stats.silences >= 1
    assert stats.opens >= 2


async def test_vn200_output_register_is_written_on_connect(tmp_path):
    rig = Rig(tmp_path)
    await rig.start(names=("vn200",), emit=False, vn200={"configure": True})
    try:
        await asyncio.sleep(0.2)
        received = rig.ports["vn200"].read_commands()
    finally:
        await rig.stop()
    assert received.startswith(b"$VNWRG,75,3,8,01,")
    assert received.endswith(b"\r\n")


async def test_dropouts_show_as_gaps(tmp_path):
    rig = Rig(tmp_path)
    await rig.start(names=("airdata",), emit=False)
    rig.emitters["airdata"].dropout = 0.05
    rig.tasks.append(asyncio.create_task(rig.emitters["airdata"].run(), name="emitter"))
    try:
        await asyncio.sleep(1.5)
    finally:
        await rig.stop()
    emitter, health = rig.emitters["airdata"], rig.drivers["airdata"].health()
    assert emitter.dropped >= 3
    assert len(rig.samples["airdata"]) == emitter.sent
    assert 1 <= health.gaps <= emitter.dropped
    assert health.crc_errors == 0


async def test_vn200_ascii_protocol(tmp_path):
    rig = Rig(tmp_path)
    await rig.start(names=("vn200",), vn200={"protocol": "ascii"})
    try:
        await asyncio.sleep(0.8)
    finally:
        await rig.stop()
    samples = rig.samples["vn200"]
    emitter = rig.emitters["vn200"]
    assert len(samples) == emitter.sent
    # $VNYMR has no time stamp: the arrival time is used, so each sample is stamped at or after
    # the moment it was taken (how long after is the machine's latency, not asserted here),
    # in order, with the values of that moment.
    from tests.drivers.rig import state

    for s, (_, taken) in zip(samples, emitter.truth, strict=True):
        assert s.time >= taken
        assert s.values["phi"] == pytest.approx(state(taken)["phi"], abs=1e-4)
    assert all(a.time <= b.time for a, b in itertools.pairwise(samples))


async def test_the_rate_shown_is_the_sensors_own_when_frames_arrive_in_bursts(tmp_path):
    """Bad input tried: the µADC's frames held back for 0.3 s (a USB adapter's buffer, a busy
    reader) and then delivered at once. Counted by arrival, the last second then held 126
    frames of a 100 Hz sensor; counted by the sensor's own sample times it holds 100."""
    clock = VirtualClock(100.0)
    rig = Rig(tmp_path, clock=clock)
    await rig.start(names=("airdata",), emit=False)
    emitter, samples = rig.emitters["airdata"], rig.samples["airdata"]
    start = clock.now()

    async def deliver(frames: range, arrival: float) -> None:
        """Frames sampled at start + k/RATE, arriving 2 ms after `arrival`."""
        clock.advance(arrival + 0.002 - clock.now())
        for k in frames:
            emitter.emit(start + k / RATE, k)
        await until(lambda: len(samples) == frames.stop, f"frame {frames.stop - 1}")

    try:
        for k in range(100):  # a second on time
            await deliver(range(k, k + 1), start + k / RATE)
        await deliver(range(100, 130), start + 1.30)  # 0.3 s held back, then at once
        for k in range(130, 226):
            await deliver(range(k, k + 1), start + k / RATE)
        health = rig.drivers["airdata"].health()
    finally:
        await rig.stop()
    arrivals = [s for s in samples if s.time > clock.now() - 1.0]
    assert health.rate_hz == pytest.approx(RATE, abs=1)
    assert len(arrivals) == pytest.approx(RATE, abs=1)  # the samples' own times, spaced 10 ms
