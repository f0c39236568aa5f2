"""The excitation scheduler against a fake surface sink: timing, trim, start rules, and every
way a run ends (each must command trim within one command period, then release).

Bad input tried: the switch dropping mid-run, an operator abort, a 50° bank, 10 m/s airspeed,
14° angle of attack, 50 m of height lost, a NaN bank angle, RC telemetry stopping, sensors
stopping, an autopilot link that raises on every command (trim included), a shutdown
(cancellation) mid-run, a start in a 50° bank, a start with no servo outputs to take trim from,
a plan beyond the envelope, a listener that raises, and wake-ups late by up to 8 ms or 105 ms.
"""

from __future__ import annotations

import asyncio
import random

import numpy as np
import pytest

from agent.clock import LoopClock, VirtualClock
from agent.config import Config
from agent.excitation.plan import Doublet, Multisine, Plan, PlanRefused, Segment, preset, render
from agent.excitation.scheduler import Event, FlightState, Scheduler, Window
from tests.waiting import until

pytestmark = pytest.mark.usefixtures("no_leaked_tasks")

CONFIG = Config().excitation
DT = 1 / CONFIG.rate_hz
AIL, RUD = CONFIG.surfaces["aileron"].channel, CONFIG.surfaces["rudder"].channel
TRIM = {AIL: 1520, RUD: 1480, 2: 1500, 3: 1300}
LOW, HIGH = 1100, 1900
CRUISE = FlightState(0.0, bank_deg=2.0, pitch_deg=1.0, airspeed=22.0, alpha_deg=4.0, altitude_m=120)


class FakeAutopilot:
    """The sink: records every call with the clock's time and, like the real autopilot, keeps
    the scheduler's telemetry fresh on every command. `script(t)` may change the world."""

    def __init__(self, clock, scheduler_ref, script=None):
        self.clock, self.ref, self.script = clock, scheduler_ref, script
        self.calls: list[tuple[float, str, object]] = []
        self.switch, self.state, self.telemetry, self.sensors = HIGH, CRUISE, True, True
        self.fail_command_at: float | None = None
        self.slow_release, self.releasing = False, asyncio.Event()

    async def command(self, pwm):
        now = self.clock.now()
        self.calls.append((now, "command", dict(pwm)))
        if self.fail_command_at is not None and now >= self.fail_command_at:
            raise ConnectionError("autopilot link lost")
        if self.script:
            self.script(self, now)
        if self.telemetry:
            feed(self.ref[0], now, self.switch, self.state if self.sensors else None)

    async def release(self, channels):
        self.calls.append((self.clock.now(), "release", list(channels)))
        if self.slow_release:
            self.releasing.set()
            await asyncio.sleep(0.05)  # a slow link
            self.calls.append((self.clock.now(), "released", list(channels)))

    def commands(self):
        return [(t, p) for t, kind, p in self.calls if kind == "command"]


def feed(s: Scheduler, now: float, switch=HIGH, state=CRUISE) -> None:
    s.update_switch(switch, now)
    if state is None:  # the sensors went quiet
        return
    s.update_state(
        FlightState(
            now, state.bank_deg, state.pitch_deg, state.airspeed, state.alpha_deg, state.altitude_m
        )
    )


def make(clock, script=None, config=CONFIG, servos=True):
    ref: list[Scheduler] = []
    sink = FakeAutopilot(clock, ref, script)
    s = Scheduler(config, sink, clock)
    ref.append(s)
    events: list[Event | Window] = []
    s.subscribe(events.append)
    # Trimmed flight before the run: servo outputs (unless `servos` is false) and telemetry,
    # switch low.
    for i in range(25 if servos else 0):
        s.update_servos(clock.now() - 0.5 + i * 0.02, TRIM)
    feed(s, clock.now(), LOW)
    return s, sink, events


def _ends(s: Scheduler) -> int:
    return s.counters["finished"] + s.counters["aborted"] + s.counters["refused"]


async def fly(s: Scheduler, sink, plan: Plan, *, timeout=5.0, state=CRUISE):
    """Arm, flip the switch high, and serve until the run ends or is refused."""
    task = asyncio.create_task(s.run(), name="scheduler")
    try:
        s.arm(plan)
        before = _ends(s)
        feed(s, sink.clock.now(), HIGH, state)
        # Until the run ends or is refused: an event, bounded by the test's budget only (a
        # fixed count of loop turns was a wall-clock margin in disguise: on a quiet machine a
        # million turns passed before a 2 s plan on the real clock had played).
        await until(lambda: _ends(s) > before, "the run's end", pause=lambda _: asyncio.sleep(0))
    finally:
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await asyncio.wait_for(task, timeout)


def long_plan(seconds: float = 60.0) -> Plan:
    sine = Multisine(harmonics=(3, 6, 9, 12), period_s=20.0, periods=seconds / 20.0, amplitude=3.0)
    return Plan(id="long", axes="lateral", segments=(Segment(signals={"aileron": sine}),), lead_s=0)


async def test_no_drift_against_absolute_deadlines_with_late_wakeups():
    rng = random.Random(7)
    # Every wake-up is 0–8 ms late (a busy loop at 50 Hz): relative sleeps would drift by ~4 ms
    # per command, 12 s over 60 s; absolute deadlines keep every command inside its period.
    clock = VirtualClock(100.0, lateness=lambda _: rng.uniform(0.0, 0.008))
    s, sink, events = make(clock)
    await fly(s, sink, long_plan())
    played = sink.commands()[:-1]  # the last command is the trim at the end
    start = next(e.time for e in events if isinstance(e, Event) and e.kind == "started")
    ideal = start + np.arange(len(played)) * DT
    times = np.array([t for t, _ in played])
    assert len(played) == round(60.0 * CONFIG.rate_hz) + 1
    assert np.all(times - ideal >= -1e-9)
    assert np.all(times - ideal < DT)
    assert times[-1] - (start + 60.0) < DT


async def test_a_stalled_loop_skips_samples_instead_of_bursting():
    stall = {"done": False}

    def lateness(deadline):
        if deadline > 110.0 and not stall["done"]:
            stall["done"] = True
            return 0.105  # the loop was blocked for five periods
        return 0.0

    clock = VirtualClock(100.0, lateness=lateness)
    s, sink, _ = make(clock)
    await fly(s, sink, long_plan(20.0))
    times = np.array([t for t, _ in sink.commands()])
    assert s.counters["late_samples"] == 5
    gaps = np.sort(np.diff(times))
    assert gaps[-1] == pytest.approx(DT + 0.105)  # the stall
    assert gaps[0] == pytest.approx(DT - 0.005)  # back on the grid at the next deadline
    assert np.allclose(gaps[1:-1], DT)  # no burst of catch-up commands


async def test_real_clock_timing_holds_on_this_loop():
    clock = LoopClock()
    plan = long_plan(2.0)
    s, sink, events = make(clock)
    await fly(s, sink, plan)
    start = next(e.time for e in events if isinstance(e, Event) and e.kind == "started")
    times = np.array([t for t, _ in sink.commands()[:-1]])
    # Every sample goes out once or is skipped as late, never twice, and never before its
    # deadline: the k-th command waits at least for the k-th deadline (skips only move it
    # later). How late a wake-up may be is the machine's, not a property of the scheduler,
    # and is not asserted here: the period a command is seen in is not one either (the sink's
    # clock is read after the scheduler's decision; on a loaded machine a preemption between
    # the two put a command in the next period, beside that period's own).
    # test_no_drift_against_absolute_deadlines_with_late_wakeups injects 10 ms of lateness per
    # command on a virtual clock: no drift.
    count = render(plan, CONFIG.rate_hz).count
    assert len(times) == s.counters["commands"]
    assert s.counters["commands"] + s.counters["late_samples"] == count
    k = np.arange(len(times))
    assert np.all(times >= start + k * DT - 1e-6)


async def test_trim_is_captured_and_commands_are_trim_plus_plan():
    clock = VirtualClock(50.0)
    s, sink, events = make(clock)
    # A noisy servo history: trim is its median, not the last sample.
    s.update_servos(clock.now(), {AIL: 1600, RUD: 1400})
    plan = preset("lateral")
    await fly(s, sink, plan)
    commands = sink.commands()
    ail = np.array([p[AIL] for _, p in commands])
    values = CONFIG.surfaces["aileron"].us_per_unit * 4.0  # 4° doublet at 20 µs/°
    assert set(np.unique(ail)) == {1520, round(1520 + values), round(1520 - values)}
    assert commands[-1][1] == {AIL: TRIM[AIL], RUD: TRIM[RUD]}
    assert sink.calls[-1][1:] == ("release", [AIL, RUD])
    kinds = [e.kind for e in events if isinstance(e, Event)]
    assert kinds[0] == "armed"
    assert "started" in kinds
    assert kinds[-1] == "finished"
    window = events[-1]
    assert isinstance(window, Window)
    assert window.outcome == "finished"
    assert window.end - window.start == pytest.approx(15.02, abs=DT)


async def test_arming_never_starts_a_run_without_a_switch_flip():
    clock = VirtualClock(10.0)
    s, sink, events = make(clock)
    feed(s, clock.now(), HIGH)  # switch already high when the operator arms
    task = asyncio.create_task(s.run(), name="scheduler")
    try:
        s.arm(preset("lateral"))
        for _ in range(20):
            await asyncio.sleep(0)
        assert s.status == "armed"
        assert not sink.calls
        feed(s, clock.now(), LOW)
        feed(s, clock.now(), HIGH)  # the pilot's low → high flip starts it
        for _ in range(20):
            await asyncio.sleep(0)
        assert s.status == "running"
    finally:
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
    # Cancelled mid-run (agent shutdown): trim, then release, still happen.
    assert sink.calls[-2][1] == "command"
    assert sink.calls[-1][1] == "release"
    assert events[-1].outcome == "aborted"
    assert events[-1].reason == "agent shutting down"


def _at(t0: float, action):
    fired = {"t": None}

    def script(sink, now):
        if fired["t"] is None and now >= t0:
            fired["t"] = now
            action(sink)

    return script, fired


ABORTS = {
    "pilot switch low": lambda sink: setattr(sink, "switch", LOW),
    "operator abort": lambda sink: sink.ref[0].abort(),
    "envelope: bank": lambda sink: setattr(sink, "state", FlightState(0, 50.0, 1, 22, 4, 120)),
    "envelope: airspeed": lambda sink: setattr(sink, "state", FlightState(0, 2, 1, 10.0, 4, 120)),
    "envelope: angle of attack": lambda sink: setattr(
        sink, "state", FlightState(0, 2, 1, 22, 14.0, 120)
    ),
    "envelope: lost": lambda sink: setattr(sink, "state", FlightState(0, 2, 1, 22, 4, 70.0)),
    "envelope: flight state is not finite": lambda sink: setattr(
        sink, "state", FlightState(0, float("nan"), 1, 22, 4, 120)
    ),
    "stale RC switch data": lambda sink: setattr(sink, "telemetry", False),
    "stale flight state": lambda sink: setattr(sink, "sensors", False),
}


@pytest.mark.parametrize("reason", list(ABORTS))
async def test_every_abort_commands_trim_within_one_period_then_releases(reason):
    clock = VirtualClock(0.0)
    script, fired = _at(5.0, ABORTS[reason])
    s, sink, events = make(clock, script)
    await fly(s, sink, preset("lateral"))
    commands = sink.commands()
    assert commands[-1][1] == {AIL: TRIM[AIL], RUD: TRIM[RUD]}
    assert sink.calls[-1][1:] == ("release", [AIL, RUD])
    limit = CONFIG.stale_s if reason.startswith("stale") else 0.0
    assert commands[-1][0] - fired["t"] <= limit + DT + 1e-9
    aborted = [e for e in events if isinstance(e, Event) and e.kind == "aborted"]
    assert len(aborted) == 1
    assert reason.split(":")[-1].strip() in aborted[0].detail
    assert events[-1].outcome == "aborted"
    assert s.status == "idle"


async def test_a_failing_autopilot_link_aborts_and_still_tries_trim_and_release():
    clock = VirtualClock(0.0)
    s, sink, events = make(clock)
    sink.fail_command_at = 3.0  # every command from 3 s on raises, trim included
    await fly(s, sink, preset("lateral"))
    assert "internal error" in events[-1].reason
    assert "autopilot link lost" in events[-1].reason
    assert sink.calls[-1][1] == "release"
    assert s.counters["sink_errors"] == 1  # the trim command failed too; release was tried


async def test_start_is_refused_outside_the_envelope_or_without_trim():
    # Bad input tried: starting in a 50° bank; starting with no servo outputs to take trim from.
    clock = VirtualClock(0.0)
    s, sink, events = make(clock)
    await fly(s, sink, preset("lateral"), state=FlightState(0, 50.0, 1, 22, 4, 120))
    assert not sink.calls
    refused = [e for e in events if isinstance(e, Event) and e.kind == "refused"]
    assert "not started: envelope: bank 50.0°" in refused[0].detail
    s2, sink2, events2 = make(VirtualClock(1000.0), servos=False)
    await fly(s2, sink2, preset("lateral"))
    assert not sink2.calls
    assert "no servo output on channel 1 (aileron)" in events2[-1].detail


async def test_plan_outside_the_envelope_is_refused_at_arming():
    # Bad input tried: an aileron doublet of 15° against a 10° max_amplitude.
    clock = VirtualClock(0.0)
    s, _, events = make(clock)
    big = Plan(
        id="big",
        axes="lateral",
        segments=(Segment(signals={"aileron": Doublet(pulse_s=1.0, amplitude=15.0)}),),
    )
    with pytest.raises(PlanRefused, match="exceeds its max_amplitude of 10 deg"):
        s.arm(big)
    assert s.status == "idle"
    assert events[-1].kind == "refused"
    assert s.counters["refused"] == 1


async def test_a_faulty_listener_does_not_stop_the_run():
    clock = VirtualClock(0.0)
    s, sink, events = make(clock)

    def broken(_):
        raise RuntimeError("console crashed")

    s.subscribe(broken)
    await fly(s, sink, preset("lateral"))
    assert events[-1].outcome == "finished"
    assert s.counters["listener_errors"] > 0


async def test_shutdown_during_the_release_still_completes_it():
    clock = VirtualClock(0.0)
    script, _ = _at(2.0, ABORTS["operator abort"])
    s, sink, events = make(clock, script)
    sink.slow_release = True
    task = asyncio.create_task(s.run(), name="scheduler")
    s.arm(preset("lateral"))
    feed(s, clock.now(), HIGH)
    await asyncio.wait_for(sink.releasing.wait(), 5.0)
    task.cancel()  # the agent shuts down while the override is being released
    with pytest.raises(asyncio.CancelledError):
        await task
    assert sink.calls[-1][1] == "released"
    assert events[-1].outcome == "aborted"


async def test_a_refused_start_waits_for_the_pilot_to_cycle_the_switch():
    """Bad input tried: the switch held high through a refusal (a 50° bank) while the aircraft
    rolls back into the envelope: the plan must not start by itself."""
    clock = VirtualClock(0.0)
    s, sink, events = make(clock)
    task = asyncio.create_task(s.run(), name="scheduler")
    try:
        s.arm(preset("lateral"))
        feed(s, clock.now(), HIGH, FlightState(0, 50.0, 1, 22, 4, 120))
        for _ in range(100):
            await asyncio.sleep(0)
        assert s.counters["refused"] == 1
        for _ in range(50):  # 1 s of RC_CHANNELS at 50 Hz, switch high, back in the envelope
            clock.advance(0.02)
            s.update_servos(clock.now(), TRIM)
            feed(s, clock.now(), HIGH, CRUISE)
            await asyncio.sleep(0)
        assert s.counters["refused"] == 1  # one flip, one attempt
        assert not sink.calls  # and nothing started
        feed(s, clock.now(), LOW, CRUISE)  # the pilot cycles the switch
        clock.advance(0.02)
        feed(s, clock.now(), HIGH, CRUISE)
        for _ in range(200):
            await asyncio.sleep(0)
            if sink.calls:
                break
        assert sink.calls, events[-1]  # now it starts
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        s.abort("test over")


async def test_in_fbwa_the_plan_plays_on_the_sticks_trimmed_at_the_pilots():
    """In a stabilised mode an override is the pilot's stick, not the surface: trim is the RC
    inputs' median (the servos', an attitude demand there, would bank the aircraft), and a
    mode change mid-run aborts it. Bad input tried: a start in AUTO (refused: plans play in
    MANUAL or FBWA), no RC input in FBWA to take trim from (refused), the pilot switching to
    FBWA mid-run (aborted, trim and release commanded)."""
    clock = VirtualClock(0.0)
    s, sink, events = make(clock)
    sticks = {AIL: 1500, RUD: 1500, 2: 1500, 3: 1300}
    for i in range(25):
        s.update_sticks(clock.now() - 0.5 + i * 0.02, sticks)
    sink.flight_mode = "FBWA"
    await fly(s, sink, preset("lateral"))
    commands = sink.commands()
    ail = np.array([p[AIL] for _, p in commands])
    values = CONFIG.surfaces["aileron"].us_per_unit * 4.0
    assert set(np.unique(ail)) == {1500, round(1500 + values), round(1500 - values)}
    started = next(e for e in events if isinstance(e, Event) and e.kind == "started")
    assert "the sticks': FBWA" in started.detail
    assert events[-1].outcome == "finished"
    assert s.played.on_sticks  # its surfaces followed the laws: no linkage measured from it
    assert events[-1].closed_loop  # its window: identified as a closed-loop record

    s2, sink2, events2 = make(VirtualClock(100.0))
    sink2.flight_mode = "AUTO"
    await fly(s2, sink2, preset("lateral"))
    assert not sink2.calls
    assert "the autopilot is in AUTO; plans play in MANUAL" in events2[-1].detail
    s3, sink3, events3 = make(VirtualClock(200.0))  # servo outputs, but no RC input
    sink3.flight_mode = "FBWA"
    await fly(s3, sink3, preset("lateral"))
    assert not sink3.calls
    assert "no RC input on channel 1 (aileron)" in events3[-1].detail

    def to_fbwa(sink, now):
        if now > 1.0:
            sink.flight_mode = "FBWA"

    clock4 = VirtualClock(300.0)
    s4, sink4, events4 = make(clock4, script=lambda k, now: to_fbwa(k, now - 300.0))
    sink4.flight_mode = "MANUAL"
    await fly(s4, sink4, long_plan(5.0))
    assert events4[-1].outcome == "aborted"
    assert "flight mode changed from MANUAL to FBWA" in events4[-1].reason
    assert not s4.played.on_sticks
    assert not events4[-1].closed_loop
    assert sink4.commands()[-1][1] == {AIL: TRIM[AIL]}
    assert sink4.calls[-1][1:] == ("release", [AIL])
