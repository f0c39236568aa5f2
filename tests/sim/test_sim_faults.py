"""Faults during a `sysid sim` flight: the whole chain (JSBSim aircraft, emulated ArduPlane on
MAVLink, sensor ptys, emulated radios, the real agent with its worker process, the scripted
ground) with one part made to fail mid-flight.

- the pilot drops the excitation switch mid-run → trim on the MAVLink wire within one command
  period of the switch report, then the override is released;
- the autopilot link is cut (both directions) mid-run → the run aborts, the ground is told, the
  agent reconnects when the link returns and accepts a new plan;
- a sensor's port disappears and comes back in trimmed flight, and the radio is out while the
  next run is identified → the driver reconnects, the gap is logged, the result reaches the
  ground after the outage;
- an identification fails (an order one Markov parameter cannot hold) → a failure
  result with the reason, and the agent goes on to identify the next run;
- the aileron servo is reversed in the autopilot (SERVO1_REVERSED) → after the first
  doublet the operator is told the aileron moved against its command.
"""

from __future__ import annotations

import asyncio
import json
import re
from pathlib import Path

import numpy as np
import pytest

from agent.excitation.plan import Doublet, Plan, Segment, preset
from agent.link import messages
from agent.logs import read_log
from agent.sim.ardupilot import RELEASE_LOW, Params
from agent.sim.flight import SimFlight, SimOptions, simulated
from drivers.autopilot.driver import RELEASE_REPEATS
from tests import waiting

pytestmark = [pytest.mark.usefixtures("no_leaked_tasks"), pytest.mark.timeout(180)]

# A message sent on the loopback reaches the other side in well under this (s): MAVSDK's
# receive thread, the hand-over to the loop, the UDP hop.
DELIVERY_S = 0.010


until = waiting.until


def received(sim: SimFlight, kind, since: int = 0, **fields) -> list:
    return [
        m
        for m in sim.ground.inbox[since:]
        if isinstance(m, kind) and all(getattr(m, k) == v for k, v in fields.items())
    ]


async def start_run(sim: SimFlight, plan_id: str, axes: str = "lateral") -> int:
    """Arm a preset, flip the switch, wait for the start; the inbox index before it."""
    seen = len(sim.ground.inbox)
    ack = await sim.ground.command(messages.Arm(plan=preset(axes, plan_id=plan_id)))
    assert ack.ok, ack.reason
    sim.aircraft.pilot.set_switch(True)
    await until(lambda: received(sim, messages.ExcitationEvent, seen, event="started"), "the start")
    return seen


async def play_doublet(sim: SimFlight, plan_id: str) -> int:
    """Arm a 4° aileron doublet as plan `plan_id` and flip the switch; the inbox index before."""
    doublet = Doublet(pulse_s=1.0, amplitude=4.0)
    plan = Plan(
        id=plan_id, axes="lateral", segments=(Segment(signals={"aileron": doublet}, free_s=1.0),)
    )
    seen = len(sim.ground.inbox)
    ack = await sim.ground.command(messages.Arm(plan=plan))
    assert ack.ok, ack.reason
    sim.aircraft.pilot.set_switch(True)
    return seen


async def answer(sim: SimFlight, since: int):
    def found():
        return received(sim, messages.Result, since) or received(sim, messages.Failure, since)

    return (await until(found, "an identification answer"))[0]


async def test_switch_dropped_mid_run_trims_within_one_period_then_releases(tmp_path):
    # ArduPilot's own kill (RCx_OPTION 46 ignoring overrides when the switch is low) is off,
    # so what the aircraft does after the drop is the agent's doing alone.
    params = Params(switch_channel=7, switch_option_46=False)
    async with simulated(SimOptions(preset="lateral", directory=tmp_path), params) as sim:
        ap, period = sim.aircraft.autopilot, 1.0 / sim.agent.config.excitation.rate_hz
        seen = await start_run(sim, "drop")
        started = received(sim, messages.ExcitationEvent, seen, event="started")[0]
        await asyncio.sleep(1.2)  # inside the aileron doublet
        dropped = sim.clock.now()
        sim.aircraft.pilot.set_switch(False)
        aborted = await until(
            lambda: received(sim, messages.ExcitationEvent, seen, event="aborted"), "abort"
        )
        await asyncio.sleep(0.5)  # anything the agent still sends after the release
        wire = list(ap.wire)
        overrides_held = ap.overrides
        rc, pilot = ap.rc_inputs(sim.clock.now()), sim.aircraft.pilot(sim.clock.now())

    assert "switch" in aborted[0].detail
    trim = {
        {"aileron": 1, "rudder": 4}[name]: int(us)
        for name, us in re.findall(r"(\w+) (\d+) µs", started.detail)
    }
    assert set(trim) == {1, 4}
    # The first report of the low switch to go out on the wire after the drop.
    reported = next(
        t for t, kind, *rest in wire if kind == "switch" and t >= dropped and rest[0] < 1500
    )
    after = [
        (t, values)
        for t, kind, values, accepted in (e for e in wire if e[1] == "override")
        if t >= reported
    ]
    trims = [k for k, (_, values) in enumerate(after) if values == trim]
    assert trims, f"no trim override after the switch report: {after[:5]}"
    first_trim = trims[0]
    # At most one excitation command was already on its way when the report arrived.
    assert first_trim <= 1, after[: first_trim + 1]
    latency = after[first_trim][0] - reported
    assert latency <= period + DELIVERY_S, f"trim {1000 * latency:.1f} ms after the report"
    # Then the release of exactly the excited channels (sent RELEASE_REPEATS times, as a
    # datagram can be lost), and nothing more.
    rest = [values for _, values in after[first_trim + 1 :]]
    assert rest == [{1: RELEASE_LOW, 4: RELEASE_LOW}] * RELEASE_REPEATS
    assert overrides_held == {}
    assert rc == pilot  # the pilot's sticks drive every channel again


async def test_autopilot_link_lost_mid_run_aborts_and_recovers(tmp_path):
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        ap, agent = sim.aircraft.autopilot, sim.agent
        seen = await start_run(sim, "cut")
        await asyncio.sleep(1.0)
        cut = sim.clock.now()
        ap.link_up = False  # both directions, as a broken cable
        aborted = await until(
            lambda: received(sim, messages.ExcitationEvent, seen, event="aborted"), "abort"
        )
        # Whichever notices first names it: the scheduler's staleness check on the switch
        # reports, or the link watchdog (both at link_timeout_s = 0.5 s).
        detail = aborted[0].detail
        assert "autopilot link lost" in detail or "stale RC switch data" in detail, detail
        await until(lambda: not agent.autopilot.connected, "the watchdog's report")
        # Told within the link timeout, the watchdog's look and one command period.
        cfg = agent.config
        assert aborted[0].time - cut <= cfg.autopilot.link_timeout_s + 0.25
        await until(lambda: received(sim, messages.Notice, seen), "the not-identified notice")
        assert "not identified" in received(sim, messages.Notice, seen)[0].text
        assert agent.scheduler.status == "idle"
        # The overrides the ArduPlane still held lapse after RC_OVERRIDE_TIME: the pilot's.
        await until(lambda: ap.counters["override_timeouts"] > 0, "override timeout")
        sim.aircraft.pilot.set_switch(False)
        frames_cut = agent.recorder.counters["frames"]
        ap.link_up = True
        await until(lambda: agent.autopilot.connected, "the autopilot link back")
        # Recording never depended on the autopilot link.
        assert agent.recorder.counters["frames"] > frames_cut
        ack = await sim.ground.command(messages.Arm(plan=preset("lateral", plan_id="again")))
        assert ack.ok, ack.reason
    assert ap.counters["cut_in"] > 0  # the agent kept trying while the link was down


async def test_sensor_replugged_and_result_delivered_after_radio_outage(tmp_path):
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        agent, port = sim.agent, sim.aircraft.ports["airdata"]
        airdata = next(d for d in agent.drivers if d.name == "airdata")
        opens = airdata.link.stats.opens
        port.unplug()  # the µADC's USB cable out for 1.5 s in trimmed flight
        await asyncio.sleep(1.5)
        port.plug()
        await until(lambda: airdata.link.stats.opens > opens, "the µADC reopened")
        await until(lambda: airdata.health().rate_hz > 90, "the µADC streaming")
        gaps = airdata.health().gaps
        assert gaps >= 1
        assert airdata.link.stats.disconnects >= 1

        seen = await start_run(sim, "outage")
        await until(lambda: received(sim, messages.ExcitationEvent, seen, event="finished"), "end")
        sim.channel.outage = True  # the radio is out while the worker identifies
        await until(lambda: agent.identification.results, "the identification")
        await asyncio.sleep(2.0)
        assert not received(sim, messages.Result, seen)  # nothing got through
        sim.channel.outage = False
        restored = sim.clock.now()
        result = await answer(sim, seen)
        assert isinstance(result, messages.Result), result
        assert result.model_id == agent.identification.results[-1].model_id
        delivered = sim.clock.now()
        retransmissions = agent.session.counters["retransmissions"]
    assert delivered >= restored
    assert retransmissions > 0
    # The airdata gap is in the flight log as missing values, not as invented ones.
    columns, rows = read_log(next((tmp_path / "logs").glob("*_flight_*")))
    beta = rows[:, columns.index("beta")]
    assert np.isnan(beta).sum() >= 50  # 1.5 s without the µADC at 100 Hz (less the hold)
    assert np.isfinite(beta[-100:]).all()


async def test_identification_failure_is_reported_and_the_next_run_identified(tmp_path):
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        # Within markov_max and order_max (the agent refuses beyond them), but an order that
        # one Markov parameter cannot hold: the worker's identification fails.
        ack = await sim.ground.command(messages.IdentSettings(axes="lateral", markov=1, order=20))
        assert ack.ok, ack.reason
        seen = await start_run(sim, "bad-settings")
        failure = await answer(sim, seen)
        assert isinstance(failure, messages.Failure), failure
        assert "order 20 requested but the Hankel matrix has rank" in failure.reason  # worker
        assert sim.agent.counters["identification_failures"] == 1
        sim.aircraft.pilot.set_switch(False)
        await asyncio.sleep(0.5)
        assert all(d.health().state == "open" for d in sim.agent.drivers)  # still flying

        await sim.ground.command(messages.IdentSettings(axes="lateral"))
        seen = await start_run(sim, "good-settings")
        result = await answer(sim, seen)
        assert isinstance(result, messages.Result), result
        assert sim.agent.counters["identification_failures"] == 1
    results = (next((tmp_path / "logs").glob("*_results_*"))).read_text().splitlines()
    assert '"failure"' in results[0]
    assert '"failure"' not in results[1]


async def test_an_aileron_reversed_in_the_autopilot_is_told_after_its_first_doublet(tmp_path):
    # An installation fault: SERVO1_REVERSED set, so a positive δA command moves the aileron
    # the other way. The identification alone cannot tell (B changes sign); the check can.
    params = Params(switch_channel=7, reversed={1: True})
    async with simulated(SimOptions(preset="lateral", directory=tmp_path), params) as sim:
        seen = await play_doublet(sim, "reversed")

        def told():
            return [
                m
                for m in received(sim, messages.Notice, seen)
                if "aileron moved against its command" in m.text
            ]

        (notice,) = await until(told, "the notice of the reversed aileron")
        assert notice.text.startswith("reversed: ")
        assert "direction in [excitation.surfaces]" in notice.text
        assert sim.agent.counters["surface_reversed"] == 1
        assert sim.agent.counters["surface_not_following"] == 0


async def test_a_run_in_fbwa_measures_no_linkage_the_next_manual_one_does(tmp_path):
    """In FBWA the plan plays on the sticks and ArduPlane's laws move the surfaces, so they
    do not follow the plan's commands through their linkage: a doublet flown there sets no
    linkage for the sizing or the gains design and logs no linkage line (had it been judged,
    its gain would be the loop's, not the linkage's); the same doublet flown next in MANUAL
    does both, and is the only one in the execution log."""
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        agent = sim.agent
        for plan_id, mode in (("stick", 5), ("surface", 0)):
            assert sim.aircraft.autopilot.set_mode(mode)
            name = "FBWA" if mode == 5 else "MANUAL"
            await until(lambda name=name: agent.scheduler.flight_mode() == name, name)
            seen = await play_doublet(sim, plan_id)
            await until(
                lambda seen=seen: received(sim, messages.ExcitationEvent, seen, event="finished"),
                f"{plan_id} finished",
            )
            sim.aircraft.pilot.set_switch(False)
            # The window handled (its identification answered): its surfaces judged then.
            await answer(sim, seen)
            if plan_id == "stick":
                assert agent.gains.linkage == {}
                assert agent.sizer.linkage == {}
        assert agent.gains.linkage["aileron"]["gain"] > 0
        assert agent.sizer.linkage["aileron"][0] > 0
        assert agent.counters["surface_not_following"] == 0

    events = [
        json.loads(line)
        for path in (tmp_path / "logs").glob("*_exec_*.jsonl")
        for line in path.read_text().splitlines()
    ]
    assert [e["plan"] for e in events if e.get("logger") == "agent.linkage"] == ["surface"]


async def test_a_flight_kept_in_a_relative_directory_comes_up(tmp_path, monkeypatch):
    """Bad input tried: `sysid sim --keep flight`, a directory relative to where it runs (the
    post-flight walkthrough's): the agent looked for its link key at flight/flight/link.key,
    flew without the link and the ground never heard it. It comes up, and its logs and key
    are where the walkthrough looks for them."""
    monkeypatch.chdir(tmp_path)
    async with simulated(SimOptions(preset="lateral", directory=Path("flight"))) as sim:
        assert sim.ground is not None
    assert (tmp_path / "flight" / "link.key").is_file()
    assert any((tmp_path / "flight" / "logs").glob("*_exec_*.jsonl"))
    assert not (tmp_path / "flight" / "flight").exists()


async def test_the_operator_takes_an_aborted_run_as_its_answer_and_flies_on(tmp_path):
    """The agent does not identify an aborted run, so no result follows it: the scripted
    operator waited out its deadline for one (a DHC-6 aborted for its bank then ended "no
    identification result for full-1 in 207 s", blaming a busy machine). An abort now ends
    the run's wait with its reason. Bad input tried: the pilot drops the switch mid-run."""
    from agent.sim.flight import one_run

    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:

        async def drop_after_start():
            seen = len(sim.ground.inbox)
            await until(
                lambda: received(sim, messages.ExcitationEvent, seen, event="started"), "start"
            )
            await asyncio.sleep(1.0)
            sim.aircraft.pilot.take_control()

        dropping = asyncio.create_task(drop_after_start())
        outcome = await one_run(
            SimOptions(preset="lateral", sizing=False), sim.aircraft, sim.ground, 0, lambda _: None
        )
        await dropping
    # Answered by the abort itself: a deadline would have raised SimError instead.
    assert outcome["failure"].startswith("lateral-1 aborted: ")
    assert "switch" in outcome["failure"]
    assert outcome["events"][-1] == "aborted"
    assert "result" not in outcome
