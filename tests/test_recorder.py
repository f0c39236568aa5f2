"""The recorder: frame sampling (interpolation, hold, age, gaps), cadence against the clock,
the ring buffer, and excitation input/output logs."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest

from agent.clock import VirtualClock
from agent.config import Recorder as RecorderConfig
from agent.excitation.scheduler import Event, Window
from agent.recorder import Recorder, Ring
from drivers.sensor import Sample

pytestmark = pytest.mark.usefixtures("no_leaked_tasks")


def make(**overrides):
    config = RecorderConfig(**{"capacity_s": 10.0, **overrides})
    return Recorder(config, VirtualClock(0.0), channels=["p", "ins_status", "Vt"])


def test_linear_channels_interpolate_and_flags_hold():
    rec = make()
    rec.push(Sample("vn200", 1.00, {"p": 0.10, "ins_status": 2.0}))
    rec.push(Sample("vn200", 1.01, {"p": 0.20, "ins_status": 3.0}))
    row = rec.frame(1.004)
    n = len(rec.channels)
    assert row[1] == pytest.approx(0.14)  # p, linear between the samples around 1.004
    assert row[2] == 2.0  # ins_status held, never interpolated
    assert row[1 + n] == pytest.approx(0.004)  # age of p's newest sample at the frame
    assert math.isnan(row[3])  # Vt: no sample yet
    # After the newest sample, hold it (and its age grows) until max_age_s.
    later = rec.frame(1.05)
    assert later[1] == pytest.approx(0.20)
    assert later[1 + n] == pytest.approx(0.04)
    stale = rec.frame(1.2)
    assert math.isnan(stale[1])  # 0.19 s old > max_age_s = 0.1: recorded empty
    assert stale[1 + n] == pytest.approx(0.19)  # the gap's length is still there


def test_late_and_foreign_samples_are_counted_not_recorded():
    # Bad input tried: a sample older than the newest one, a channel not recorded.
    rec = make()
    rec.push(Sample("vn200", 2.0, {"p": 1.0, "q": 2.0, "unknown": 5.0}))
    rec.push(Sample("vn200", 1.5, {"p": 9.0, "q": 8.0}))
    assert rec.counters["late_samples"] == 1  # one sample, however many channels it carries
    assert rec.frame(2.0)[1] == 1.0


async def test_frames_at_the_rate_with_catch_up_after_a_stall():
    stalls = {"n": 0}

    def lateness(deadline):
        if deadline > 5.0 and stalls["n"] == 0:
            stalls["n"] = 1
            return 0.25  # the loop was blocked for 25 frames
        return 0.0

    clock = VirtualClock(0.0, lateness=lateness)
    rows = []
    rec = Recorder(RecorderConfig(capacity_s=10.0), clock, channels=["p"], sink=rows.append)
    task = asyncio.create_task(rec.run(), name="recorder")
    k = 0
    while clock.now() <= 9.0:
        while k * 0.01 <= clock.now():  # the device's samples, on time: the loop was late
            rec.push(Sample("vn200", k * 0.01, {"p": k * 0.01}))
            k += 1
        await asyncio.sleep(0)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    times = np.array([r[0] for r in rows])
    assert np.allclose(np.diff(times), 0.01)  # no frame missing across the stall
    assert rec.counters["catch_up_frames"] >= 24
    window = rec.window(2.0, 3.0)
    assert len(window.time) == 101
    assert np.allclose(window.values["p"], window.time, atol=1e-9)


async def _recording(rec, clock, until, deliver):
    """Run `rec` on the virtual clock until `until`; before each of its wake-ups `deliver(now)`
    pushes what a device has delivered by then."""
    task = asyncio.create_task(rec.run(), name="recorder")
    try:
        while clock.now() <= until:
            deliver(clock.now())
            await asyncio.sleep(0)
    finally:
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task


async def test_samples_later_than_the_delay_are_waited_for_not_lost():
    # Bad input tried: a device's samples from 5.0 s to 6.5 s all delivered at once at 6.5 s
    # (a loop held up 1.5 s, or a backlog read after it), six times the assembly delay.
    clock = VirtualClock(0.0)
    rows = []
    rec = Recorder(RecorderConfig(capacity_s=20.0), clock, channels=["p"], sink=rows.append)
    sent = {"k": 0}

    def deliver(now):
        while (t := sent["k"] * 0.01) <= now and not (t >= 5.0 and now < 6.5):
            rec.push(Sample("vn200", t, {"p": np.sin(t)}))
            sent["k"] += 1

    await _recording(rec, clock, 9.0, deliver)
    frames = rec.window(-np.inf, np.inf)
    assert np.allclose(np.diff(frames.time), 0.01)  # every frame, in order
    settled = frames.time > 0.02
    assert np.isfinite(frames.values["p"][settled]).all()  # none recorded empty
    assert np.allclose(frames.values["p"][settled], np.sin(frames.time[settled]), atol=1e-3)
    assert rec.counters["waited_frames"] >= 1
    assert rec.counters["late_samples"] == 0


async def test_a_silent_channel_holds_the_frames_back_no_longer_than_hold_s():
    # Bad input tried: one of two sensors silent from 5 s on (unplugged), the other on time.
    clock = VirtualClock(0.0)
    config = RecorderConfig(capacity_s=20.0, hold_s=1.5)
    rec = Recorder(config, clock, channels=["p", "Vt"])
    newest = []
    sent = {"k": 0}

    def deliver(now):
        while (t := sent["k"] * 0.01) <= now:
            values = {"p": 1.0} if t > 5.0 else {"p": 1.0, "Vt": 20.0}
            rec.push(Sample("dev", t, values))
            sent["k"] += 1
        if rec.newest is not None:
            newest.append((now, rec.newest))

    await _recording(rec, clock, 12.0, deliver)
    lag = np.array([now - t for now, t in newest])
    assert lag.max() <= config.hold_s + 0.02  # waited for Vt while it might have been late
    assert lag.max() > 1.0
    assert lag[-100:].max() <= config.delay_s + 0.02  # then on time again, Vt or not
    frames = rec.window(-np.inf, np.inf)
    assert np.allclose(np.diff(frames.time), 0.01)
    assert np.isfinite(frames.values["p"][frames.time > 0.02]).all()
    gone = frames.time > 5.0 + config.max_age_s + 0.01
    assert np.isnan(frames.values["Vt"][gone]).all()  # the silence is a gap in the record


def test_ring_keeps_the_newest_rows():
    ring = Ring(5, 2)
    for k in range(8):
        ring.append(np.array([k, 10 * k]))
    assert ring.ordered()[:, 0].tolist() == [3, 4, 5, 6, 7]
    assert ring.between(4, 6)[:, 1].tolist() == [40, 50, 60]


def test_ring_windows_by_binary_search_equal_the_mask_at_every_fill_and_wrap():
    for appended in range(0, 16):
        ring = Ring(7, 2)
        for k in range(appended):
            ring.append(np.array([0.5 * k, k]))
        rows = ring.ordered()
        assert rows[:, 0].tolist() == [0.5 * k for k in range(max(0, appended - 7), appended)]
        for t0 in np.arange(-1.0, 9.0, 0.25):
            for t1 in np.arange(t0 - 0.5, 9.0, 0.75):
                keep = (rows[:, 0] >= t0) & (rows[:, 0] <= t1)
                window = ring.between(t0, t1)
                assert np.array_equal(window, rows[keep]), (appended, t0, t1)
        # A copy: the ring moving on (every slot written over) does not change a window.
        window = ring.between(-1.0, 9.0)
        kept = window.copy()
        for k in range(7):
            ring.append(np.array([100.0 + k, -1.0]))
        assert np.array_equal(window, kept)


async def test_excitation_window_goes_to_its_log_after_the_margin():
    clock = VirtualClock(0.0)
    logged = []
    config = RecorderConfig(capacity_s=60.0, excitation_margin_s=1.0, delay_s=0.05)
    rec = Recorder(
        config, clock, channels=["p"], on_excitation=lambda w, rows: logged.append((w, rows))
    )
    rec.mark(Event("started", "lat", 2.0))  # not a window: ignored
    rec.mark(Window("lat", "lateral", 2.0, 4.0, "finished"))
    task = asyncio.create_task(rec.run(), name="recorder")
    while clock.now() < 4.9:
        await asyncio.sleep(0)
    assert not logged  # the margin after the window is not recorded yet
    while clock.now() < 5.2:
        await asyncio.sleep(0)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    window, rows = logged[0]
    assert window.plan_id == "lat"
    assert rows[0, 0] == pytest.approx(1.0)
    assert rows[-1, 0] == pytest.approx(5.0)
