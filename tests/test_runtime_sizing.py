"""The plans' sizing onboard: the ground's size request answered with the sizing, from the build-up
with no model to the model the agent identified; an arm whose predicted response leaves the
envelope refused before anything is armed.

The agent is real (its command handlers, its identification with the worker's jobs on a
thread, its model store); the record is the thesis's A.2 lateral flight.

Bad input tried: a size request before any model (the build-up, no prediction); a plan on a
control the aircraft does not have (refused with the reason, no sizing sent); an arm whose
plan the model predicts past the envelope's bank limit (refused, nothing armed); the same plan
with no model to predict it (armed: no prediction, no refusal).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import pytest

from agent.config import Config, Envelope, Excitation, IdentificationConfig, Recorder
from agent.excitation.plan import preset
from agent.excitation.scheduler import Window
from agent.link import messages
from agent.runtime import Agent
from drivers.values import FlightState
from tests.a2 import a2_rows


def make_agent(tmp_path, envelope: Envelope | None = None) -> Agent:
    config = Config(
        recorder=Recorder(log_dir=str(tmp_path / "logs"), rate_hz=50.0),
        identification=IdentificationConfig(axes="lateral", refine=False),
        excitation=Excitation(envelope=envelope or Envelope()),
    )
    agent = Agent(
        config, base=tmp_path, worker=lambda: ThreadPoolExecutor(1, thread_name_prefix="worker")
    )
    agent.sent = []
    agent.downlink.subscribe(agent.sent.append)
    # Level flight at the A.2 record's airspeed, as the autopilot reports it.
    agent.scheduler.update_state(FlightState(0.0, 0.0, 2.0, 25.0, 4.0, 300.0))
    return agent


async def command(agent, message, seq: int) -> messages.Ack:
    await agent.commands.handle(message, seq)
    return next(m for m in agent.sent if isinstance(m, messages.Ack) and m.ref == seq)


def sizings(agent) -> list[messages.Sizing]:
    return [m for m in agent.sent if isinstance(m, messages.Sizing)]


async def identify_a2(agent) -> messages.Result:
    plan = preset("lateral")
    rows = a2_rows(agent.recorder.channels)
    window = Window(plan.id, plan.axes, rows[0, 0], rows[-1, 0], "finished")
    await agent.identification.identify(window, rows)
    return [m for m in agent.sent if isinstance(m, messages.Result)][-1]


@pytest.fixture
def agent(tmp_path):
    a = make_agent(tmp_path)
    yield a
    a.close()


async def test_size_requests_build_up_then_follow_the_identified_model(agent):
    plan = preset("lateral")
    ack = await command(agent, messages.SizeRequest(plan=plan), 1)
    assert ack.ok, ack.reason
    first = sizings(agent)[-1]
    assert first.source.startswith("build-up")
    assert first.build_up
    assert first.predicted == {}
    build_up = agent.config.excitation.sizing.build_up
    assert {c.control: c.factor for c in first.controls} == {
        "aileron": build_up,
        "rudder": build_up,
    }
    # The plan to arm is the sized one, and it crosses the link as it is.
    wire = messages.from_dict(messages.to_dict(first))
    assert wire == first

    result = await identify_a2(agent)
    assert result.checks["stability"]
    assert result.checks["fit"]
    ack = await command(agent, messages.SizeRequest(plan=plan), 2)
    assert ack.ok, ack.reason
    second = sizings(agent)[-1]
    assert result.model_id in second.source
    assert "not yet accepted" in second.source
    assert not second.build_up
    targets = agent.config.excitation.sizing
    assert 0 < second.predicted["bank_deg"] <= targets.bank_deg * 1.01
    assert second.predicted["beta_deg"] <= targets.beta_deg * 1.01
    assert not second.refusals

    ack = await command(agent, messages.Decision(model_id=result.model_id, accept=True), 3)
    assert ack.ok, ack.reason
    await command(agent, messages.SizeRequest(plan=plan), 4)
    assert sizings(agent)[-1].source == f"nominal model {result.model_id}"


async def test_a_plan_on_a_control_the_aircraft_lacks_is_not_sized(tmp_path):
    agent = make_agent(tmp_path)
    try:
        surfaces = {k: v for k, v in agent.config.excitation.surfaces.items() if k != "rudder"}
        agent.config = agent.config.model_copy(
            update={"excitation": agent.config.excitation.model_copy(update={"surfaces": surfaces})}
        )
        agent.sizer.config = agent.config
        ack = await command(agent, messages.SizeRequest(plan=preset("lateral")), 1)
        assert not ack.ok
        assert "rudder" in ack.reason
        assert sizings(agent) == []
    finally:
        agent.close()


async def test_a_plan_arming_would_refuse_is_refused_unsized(agent):
    """A plan from the radio with a multisine harmonic far above the command rate's Nyquist
    frequency (a typo): refused from its parameters with the reason, nothing rendered, no
    sizing sent; the next request is answered."""
    from agent.excitation.plan import Multisine, Plan, Segment

    typo = Multisine(harmonics=(1, 10**6), period_s=10.0, amplitude=2.0)
    plan = Plan(id="typo", axes="lateral", segments=(Segment(signals={"aileron": typo}),))
    ack = await command(agent, messages.SizeRequest(plan=plan), 1)
    assert not ack.ok
    assert "Nyquist" in ack.reason
    assert sizings(agent) == []
    ack = await command(agent, messages.SizeRequest(plan=preset("lateral")), 2)
    assert ack.ok, ack.reason
    # With a model to predict it, the arm of the same typo is refused the same way: checked
    # before it is predicted, never rendered.
    await identify_a2(agent)
    ack = await command(agent, messages.Arm(plan=plan), 3)
    assert not ack.ok
    assert "Nyquist" in ack.reason


async def test_an_arm_the_prediction_takes_out_of_the_envelope_is_refused(tmp_path):
    agent = make_agent(tmp_path, Envelope(max_bank_deg=3.0))
    try:
        plan = preset("lateral")
        # No model yet: nothing predicts the run, so the plan is armed as given.
        ack = await command(agent, messages.Arm(plan=plan), 1)
        assert ack.ok, ack.reason
        agent.scheduler.disarm()
        await identify_a2(agent)
        ack = await command(agent, messages.Arm(plan=plan), 2)
        assert not ack.ok
        assert "predicted bank" in ack.reason
        assert "3°" in ack.reason
        assert agent.scheduler.status != "armed"
        assert agent.counters["refused_by_prediction"] == 1
        # Sized, the same plan aims inside the envelope's bank, and arms.
        await command(agent, messages.SizeRequest(plan=plan), 3)
        sized = sizings(agent)[-1]
        assert not sized.refusals
        assert sized.predicted["bank_deg"] <= 0.9 * 3.0 * 1.01
        ack = await command(agent, messages.Arm(plan=sized.plan), 4)
        assert ack.ok, ack.reason
    finally:
        agent.close()


async def test_a_model_missing_a_mode_sizes_nothing(agent):
    """Bad input tried: a model of too low an order for the record (3 states for the lateral
    axes: stable, fitting its data, but no roll, Dutch roll nor spiral named). It predicts the
    response from what stands in for the modes: the plan is sized as a build-up from what the
    last run flew. The next run's model, with its modes, sizes the plan, checked against the
    flight's other records of the axes (both kept)."""
    plan = preset("lateral")
    await command(agent, messages.IdentSettings(axes="lateral", order=3), 1)
    lacking = await identify_a2(agent)
    assert lacking.checks["stability"]
    assert lacking.checks["fit"]
    assert not lacking.checks["modes"]
    await command(agent, messages.SizeRequest(plan=plan), 2)
    assert sizings(agent)[-1].source.startswith("build-up from the last run")

    await command(agent, messages.IdentSettings(axes="lateral"), 3)
    whole = await identify_a2(agent)
    assert whole.checks["modes"]
    await command(agent, messages.SizeRequest(plan=plan), 4)
    assert whole.model_id in sizings(agent)[-1].source
    kept = [c.model_id for c in agent.identification.recent["lateral"]]
    assert kept == [lacking.model_id, whole.model_id]


async def test_the_repeat_is_judged_against_the_last_model_with_every_mode(agent):
    """Step 3's repeat (models._fit_step) compares a run's model with the axes' last one that
    has every mode they must have. Bad input tried: a run whose model lacks its modes (3
    states for the lateral axes) after one that has them: it does not become what the next
    run is compared with; a run with them again does."""
    compared = []  # what each suggestion was given to repeat (the call goes through)
    suggest_with = agent.identification._compare

    async def recording(candidate, samples, earlier):
        compared.append(earlier.model_id if earlier else None)
        return await suggest_with(candidate, samples, earlier)

    agent.identification._compare = recording
    await command(agent, messages.IdentSettings(axes="lateral"), 1)
    first = await identify_a2(agent)
    assert first.checks["modes"]
    assert agent.identification.complete["lateral"].model_id == first.model_id
    await command(agent, messages.IdentSettings(axes="lateral", order=3), 2)
    lacking = await identify_a2(agent)
    assert not lacking.checks["modes"]
    assert agent.identification.latest["lateral"].model_id == lacking.model_id
    assert agent.identification.complete["lateral"].model_id == first.model_id
    await command(agent, messages.IdentSettings(axes="lateral"), 3)
    again = await identify_a2(agent)
    assert again.checks["modes"]
    assert agent.identification.complete["lateral"].model_id == again.model_id
    assert compared == [None, first.model_id, first.model_id]
