"""ArduPlane gains from the nominal model, through the operator: the agent's GainTuner
(agent/runtime/gains.py) with its real MAVSDK driver against the emulated ArduPlane over UDP
loopback, JSBSim's J-3 Cub behind it, the model JSBSim's validated linear Cub
(agent.sim.truth) accepted as nominal in the agent's own model store.

Bad input tried: an apply while a plan is armed (refused, nothing set); an apply of a
proposal that is not the latest (refused); every PARAM_SET lost on the way with the telemetry
flowing (failed, the autopilot's gains as they were, said so); a revert with nothing applied
(refused); gains that limit-cycle the roll loop in FBWA (P forty times ArduPlane's: reverted
by the tracking self-check, no command needed).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from concurrent.futures import ThreadPoolExecutor

import pytest

from agent.clock import LoopClock
from agent.config import Autopilot, Config, IdentificationConfig, Recorder, Tuning
from agent.excitation.plan import preset
from agent.fbwa import DEFAULTS
from agent.link import messages
from agent.models import Candidate
from agent.runtime import Agent
from agent.sim.aircraft import FLOWN, AircraftOptions, SimAircraft
from agent.sim.ardupilot import FBWA, Params
from agent.sim.steps import truth_design_inputs
from tests.documents import continuous_document

pytestmark = pytest.mark.usefixtures("no_leaked_tasks")

AIRCRAFT = "J3Cub"
SWITCH = 7


def truth_candidate(model_id: str = "ful-9-truth") -> tuple[Candidate, dict[str, dict]]:
    """JSBSim's validated linear Cub as a whole-aircraft model in output coordinates, and the
    linkage a finished run measures on it (agent.sim.steps.truth_design_inputs)."""
    speed, altitude = FLOWN[AIRCRAFT][:2]
    model, options = truth_design_inputs(AIRCRAFT, speed, altitude)
    candidate = Candidate(
        model_id=model_id,
        axes="full",
        record_dt=0.02,
        result=continuous_document(model.A, model.B, model.inputs, model.outputs),
        experiments=(),
        record_s=60.0,
        trim={"inputs": {}, "outputs": {o: model.trim[o] for o in model.outputs}},
    )
    return candidate, dict(options.measured)


@contextlib.asynccontextmanager
async def tuned_flight(tmp_path, **tuning):
    """The Cub flying with the emulated ArduPlane, and an agent whose autopilot driver and
    gain tuner run against it, the truth model nominal; yields (agent, aircraft)."""
    aircraft = SimAircraft(
        AircraftOptions(aircraft=AIRCRAFT, params=Params(switch_channel=SWITCH), noise=True),
        LoopClock(),
        tmp_path,
    )
    tasks = [asyncio.create_task(aircraft.run(), name="sim-aircraft")]
    agent = None
    try:
        while aircraft.mavlink_address is None:
            await asyncio.sleep(0.01)
        host, port = aircraft.mavlink_address
        config = Config(
            recorder=Recorder(log_dir=str(tmp_path / "logs")),
            identification=IdentificationConfig(axes="full"),
            autopilot=Autopilot(url=f"udpout://{host}:{port}"),
            tuning=Tuning(**tuning),
        )
        agent = Agent(
            config,
            base=tmp_path,
            worker=lambda: ThreadPoolExecutor(1, thread_name_prefix="worker"),
        )
        agent.sent = []
        agent.downlink.subscribe(agent.sent.append)
        candidate, linkage = await asyncio.to_thread(truth_candidate)
        agent.models.add(candidate)
        agent.models.accept(candidate.model_id)
        # The linkage a finished run measures (agent.excitation.follow), as its gains hold it.
        agent.gains.linkage.update(linkage)
        tasks.append(asyncio.create_task(agent.autopilot.run(), name="autopilot"))
        tasks.append(asyncio.create_task(agent.gains.run(), name="gains"))
        while not agent.autopilot.connected:
            await asyncio.sleep(0.01)
        yield agent, aircraft
    finally:
        for task in reversed(tasks):
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        if agent is not None:
            agent.close()


async def command(agent, message, seq: int) -> messages.Ack:
    await agent.commands.handle(message, seq)
    return next(m for m in agent.sent if isinstance(m, messages.Ack) and m.ref == seq)


def last(agent, kind):
    return [m for m in agent.sent if isinstance(m, kind)][-1]


async def until(predicate, what: str, seconds: float = 120.0):
    """Wait on an event (a message the agent sent), not on a margin: `seconds` only bounds a
    hang."""
    deadline = asyncio.get_running_loop().time() + seconds
    while not predicate():
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"no {what} within {seconds:g} s")
        await asyncio.sleep(0.05)


async def test_gains_are_proposed_applied_read_back_and_reverted_over_mavlink(tmp_path):
    async with tuned_flight(tmp_path) as (agent, aircraft):
        ap = aircraft.autopilot
        ack = await command(agent, messages.GainsRequest(), 1)
        assert ack.ok, ack.reason
        gains = last(agent, messages.Gains)
        assert gains.model_id == "ful-9-truth"
        rows = {r.name: r for r in gains.rows}
        assert rows["RLL_RATE_FF"].current == pytest.approx(DEFAULTS["RLL_RATE_FF"])
        assert rows["PTCH_RATE_P"].current == pytest.approx(DEFAULTS["PTCH_RATE_P"])
        # Each proposed gain within ×2 of the autopilot's (max_step), the loops predicted
        # for both sets, the proposed ones sound.
        for r in gains.rows:
            if r.proposed and r.current:
                assert 1 / 2.001 <= r.proposed / r.current <= 2.001, r
        proposed = {r.name: r.proposed for r in gains.rows if r.proposed is not None}
        held = {r.name: r.current for r in gains.rows}  # the autopilot's before any apply
        assert {"RLL_RATE_P", "PTCH_RATE_P", "SCALING_SPEED"} <= set(proposed)
        # The Cub's Dutch roll (ζ 0.28 open loop) gets the yaw damper, off at ArduPlane's
        # default: switched on at its design, its prediction in the notes.
        assert rows["YAW2SRV_DAMP"].current == 0.0
        assert proposed["YAW2SRV_DAMP"] == rows["YAW2SRV_DAMP"].designed > 0
        assert any(n.startswith("yaw damper (designed): Dutch roll") for n in gains.notes)
        loops = {(p.axis, p.gains): p for p in gains.loops}
        assert loops[("roll", "proposed")].sound
        assert loops[("pitch", "proposed")].sound
        assert ("roll", "current") in loops

        # Never while a plan is armed.
        await agent.scheduler.arm_checked(preset("lateral"))
        ack = await command(agent, messages.GainsApply(proposal=gains.proposal), 2)
        assert not ack.ok
        assert "armed" in ack.reason
        assert ap.fbwa.params["RLL_RATE_P"] == pytest.approx(DEFAULTS["RLL_RATE_P"])
        agent.scheduler.disarm()
        ack = await command(agent, messages.GainsApply(proposal="ful-1-g7"), 3)
        assert not ack.ok
        assert "no proposal ful-1-g7" in ack.reason

        ack = await command(agent, messages.GainsApply(proposal=gains.proposal), 4)
        assert ack.ok, ack.reason
        report = last(agent, messages.GainsReport)
        assert report.action == "applied"
        assert report.values == pytest.approx(proposed, rel=1e-5)
        for name, value in proposed.items():
            assert ap.fbwa.params[name] == pytest.approx(value, rel=1e-5), name

        ack = await command(agent, messages.GainsRevert(), 5)
        assert ack.ok, ack.reason
        assert last(agent, messages.GainsReport).action == "reverted"
        for name in proposed:
            assert ap.fbwa.params[name] == pytest.approx(held[name], rel=1e-5), name
        ack = await command(agent, messages.GainsRevert(), 6)
        assert not ack.ok
        assert "no applied gains" in ack.reason

        # Every PARAM_SET lost on the way: failed, and the autopilot holds what it held.
        ap.drop_param_sets = True
        ack = await command(agent, messages.GainsApply(proposal=gains.proposal), 7)
        ap.drop_param_sets = False
        assert not ack.ok
        assert "timeout" in ack.reason
        report = last(agent, messages.GainsReport)
        assert report.action == "failed"
        for name in proposed:
            assert ap.fbwa.params[name] == pytest.approx(held[name], rel=1e-5), name
            assert report.values[name] == pytest.approx(held[name], rel=1e-5), name
    logged = [
        json.loads(line)
        for path in (tmp_path / "logs").glob("*_exec_*.jsonl")
        for line in path.read_text().splitlines()
    ]
    actions = [e["action"] for e in logged if e.get("logger") == "agent.gains" and "action" in e]
    assert actions == ["applied", "reverted", "failed"]


async def test_gains_that_degrade_the_tracking_are_reverted_by_the_self_check(tmp_path):
    async with tuned_flight(tmp_path, track_window_s=5.0) as (agent, aircraft):
        ap = aircraft.autopilot
        assert ap.set_mode(FBWA)
        aircraft.pilot.set_switch(False)
        # The tracking before: a window of hands-off FBWA flight (sampled by the tuner).
        await until(lambda: agent.gains.tracking.rms() is not None, "tracking window", 60)
        before = agent.gains.tracking.rms()
        assert before[0] < 1.0  # the bank held within a degree
        ack = await command(agent, messages.GainsRequest(), 1)
        assert ack.ok, ack.reason
        # The designed gains fly: the self-check judges three windows and keeps them.
        ident, kept = agent.gains.proposal
        ack = await command(agent, messages.GainsApply(proposal=ident), 2)
        assert ack.ok, ack.reason
        await until(lambda: agent.gains.applied is None, "the self-check's verdict")
        assert [m.action for m in agent.sent if isinstance(m, messages.GainsReport)] == ["applied"]
        # The proposal's roll P forty times ArduPlane's: the roll loop limit-cycles (the
        # ailerons buzz; the bank hardly moves, the roll rate does).
        await command(agent, messages.GainsRequest(), 3)
        ident, values = agent.gains.proposal
        hot = {**values, "RLL_RATE_P": 40 * DEFAULTS["RLL_RATE_P"]}
        agent.gains.proposal = (ident, hot)
        ack = await command(agent, messages.GainsApply(proposal=ident), 4)
        assert ack.ok, ack.reason
        assert ap.fbwa.params["RLL_RATE_P"] == pytest.approx(hot["RLL_RATE_P"])

        def reverted():
            return any(
                isinstance(m, messages.GainsReport) and m.action == "reverted" for m in agent.sent
            )

        await until(reverted, "revert by the tracking self-check")
        report = last(agent, messages.GainsReport)
        assert "reverted" in report.reason
        assert "roll rate" in report.reason
        # Back to what the hot set replaced: the designed gains kept before it.
        assert ap.fbwa.params["RLL_RATE_P"] == pytest.approx(kept["RLL_RATE_P"], rel=1e-5)
        notices = [m.text for m in agent.sent if isinstance(m, messages.Notice)]
        assert any(ident in text for text in notices)
