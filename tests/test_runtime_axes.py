"""Which axes a run is identified on: its plan's, unless the operator chose some in the
ground's settings; and the status tells the ground the settings in effect.

The agent is real (its command handlers, its identification with the worker's jobs on a
thread, its status); the record is the thesis's A.2 lateral flight, which moves the aileron
and the rudder only.

Bad input tried: a configuration whose default axes are "full" (as `sysid sim` sets for the
full preset) with a lateral plan armed; the operator's explicit "full" on a lateral plan (armed,
with a notice naming the controls it leaves at trim, then a failure); a status and settings as
an older peer sends them (no `settings`, no `axes`).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import pytest

from agent.config import Config, IdentificationConfig, Recorder
from agent.excitation.plan import preset
from agent.excitation.scheduler import Window
from agent.link import messages
from agent.runtime import Agent
from tests.a2 import a2_rows


@pytest.fixture
def flight(tmp_path):
    """An agent configured for "full" by default, and the A.2 lateral record as its rows."""
    config = Config(
        recorder=Recorder(log_dir=str(tmp_path / "logs"), rate_hz=50.0),
        identification=IdentificationConfig(axes="full", refine=False),
    )
    agent = Agent(
        config,
        base=tmp_path,
        worker=lambda: ThreadPoolExecutor(1, thread_name_prefix="worker"),
    )
    agent.sent = []
    agent.downlink.subscribe(agent.sent.append)
    yield agent, a2_rows(agent.recorder.channels)
    agent.close()


async def fly(agent, rows, seq: int) -> messages.Result | messages.Failure:
    """Arm the lateral preset (acknowledged), then identify the window its run leaves (the
    scheduler's: the plan's id and axes); the result or failure sent down."""
    plan = preset("lateral")
    await agent.commands.handle(messages.Arm(plan=plan), seq)
    ack = next(m for m in agent.sent if isinstance(m, messages.Ack) and m.ref == seq)
    assert ack.ok, ack.reason
    window = Window(plan.id, plan.axes, rows[0, 0], rows[-1, 0], "finished")
    await agent.identification.identify(window, rows)
    return [m for m in agent.sent if isinstance(m, messages.Result | messages.Failure)][-1]


async def settle(agent, settings: messages.IdentSettings, seq: int) -> None:
    await agent.commands.handle(settings, seq)
    ack = next(m for m in agent.sent if isinstance(m, messages.Ack) and m.ref == seq)
    assert ack.ok, ack.reason


def notices(agent) -> list[str]:
    return [m.text for m in agent.sent if isinstance(m, messages.Notice)]


async def test_a_run_is_identified_on_its_plans_axes_until_the_operator_chooses(flight):
    agent, rows = flight
    # No settings sent: the configured "full" does not override the lateral plan.
    assert agent.status.message().settings == messages.IdentSettings()
    first = await fly(agent, rows, 1)
    assert isinstance(first, messages.Result), first
    assert first.axes == "lateral"
    assert first.model_id.startswith("lat-")
    assert first.inputs == ["aileron", "rudder"]
    assert not notices(agent)
    # The operator chooses "full" explicitly: that wins. Arming says the run will not
    # identify (the plan leaves the throttle and elevator at trim), and it does not.
    await settle(agent, messages.IdentSettings(axes="full"), 2)
    assert agent.status.message().settings.axes == "full"
    second = await fly(agent, rows, 3)
    assert isinstance(second, messages.Failure), second
    assert second.axes == "full"
    assert second.model_id.startswith("ful-")
    assert notices(agent) == [
        "lateral: identified as full (the ground's settings), which needs throttle, elevator "
        "moved; the plan does not move them: send settings with each plan's own axes, or arm "
        "a plan that moves them"
    ]
    # Settings without axes: each plan's own again.
    await settle(agent, messages.IdentSettings(batch=False), 4)
    third = await fly(agent, rows, 5)
    assert isinstance(third, messages.Result), third
    assert third.axes == "lateral"


async def test_the_status_reports_p_and_order_as_they_will_be_used(tmp_path):
    config = Config(
        recorder=Recorder(log_dir=str(tmp_path / "logs")),
        identification=IdentificationConfig(markov=12),
    )
    agent = Agent(config, base=tmp_path, worker=lambda: ThreadPoolExecutor(1))
    try:
        # "auto" from the ground leaves the configuration's p; its explicit order is used.
        await agent.commands.handle(messages.IdentSettings(order=6, update_period_s=30.0), 1)
        reported = agent.status.message().settings
    finally:
        agent.close()
    assert reported == messages.IdentSettings(markov=12, order=6, update_period_s=30.0)
    assert reported.axes is None


def test_older_peers_still_parse():
    # An older aircraft's status has no settings: not known, rather than a made-up default.
    status = messages.from_dict({"kind": "status", "v": 1, "time": 3.0})
    assert status.settings is None
    # An older ground's settings leave "lateral", its default, off the wire: each plan's own.
    assert messages.from_dict({"kind": "settings", "v": 1, "batch": True}).axes is None
    # The settings ride in the status in a few bytes, defaults left out.
    full = messages.Status(time=3.0, settings=messages.IdentSettings(axes="full", markov=12))
    data = messages.to_dict(full)
    assert data["settings"] == {"axes": "full", "markov": 12}
    assert messages.from_dict(data) == full
